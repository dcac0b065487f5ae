"""Time budgets: one deadline for a whole solve, checked cheaply wherever the search loops.

A deadline is a :func:`time.perf_counter` value, or ``None`` for no limit. Stages that
loop (the top-tier iterations, the streams, the grasp-graph search) call :func:`check`,
which raises :class:`~ldhp_tamp.errors.TimeBudgetExceeded` once it has passed; the TAMP
loop turns that into a failed result (reason ``timeout: ...``). The symbolic engine call
cannot be interrupted that way (pyperplan ignores unified-planning's timeout), so
:mod:`ldhp_tamp.symbolic` runs it in a child process and kills it at the deadline.

>>> b = Budget.of(None)
>>> b.deadline is None and not b.expired() and b.remaining() is None
True
>>> Budget.of(0.0).expired()
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from ldhp_tamp.errors import TimeBudgetExceeded

__all__ = ["Budget", "check", "expired", "remaining"]


def expired(deadline: float | None) -> bool:
    """Whether ``deadline`` (a :func:`time.perf_counter` value, or ``None``) has passed."""
    return deadline is not None and time.perf_counter() >= deadline


def remaining(deadline: float | None) -> float | None:
    """Seconds left until ``deadline`` (never negative), or ``None`` for no limit."""
    if deadline is None:
        return None
    return max(0.0, deadline - time.perf_counter())


def check(deadline: float | None, where: str) -> None:
    """Raise :class:`TimeBudgetExceeded` naming ``where`` if ``deadline`` has passed.

    Costs one clock read; call it once per iteration of a loop, not per element.
    """
    if deadline is not None and time.perf_counter() >= deadline:
        raise TimeBudgetExceeded(where)


@dataclass(frozen=True)
class Budget:
    """A time budget of ``seconds`` (``None``: unlimited) counted from ``start``.

    Attributes
    ----------
    seconds
        The budget as given (``--timeout``).
    start
        When it started, a :func:`time.perf_counter` value.
    """

    seconds: float | None
    start: float = field(default_factory=time.perf_counter)

    def __post_init__(self) -> None:
        if self.seconds is not None and not self.seconds >= 0:
            raise ValueError(f"a time budget must be a non-negative number of seconds, got {self.seconds}")

    @classmethod
    def of(cls, seconds: float | None) -> "Budget":
        """A budget of ``seconds`` starting now."""
        return cls(seconds)

    @property
    def deadline(self) -> float | None:
        """The :func:`time.perf_counter` value at which the budget runs out."""
        return None if self.seconds is None else self.start + self.seconds

    def expired(self) -> bool:
        return expired(self.deadline)

    def remaining(self) -> float | None:
        return remaining(self.deadline)

    def check(self, where: str) -> None:
        check(self.deadline, where)
