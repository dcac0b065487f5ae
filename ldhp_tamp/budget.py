"""Time budgets: one deadline for a whole solve, checked cheaply wherever the search loops.

A deadline is a value of :data:`clock` (by default :func:`time.perf_counter`), or ``None``
for no limit. Stages that loop (the top-tier iterations, the streams, the grasp-graph
search) call :func:`check`, which raises :class:`~ldhp_tamp.errors.TimeBudgetExceeded` once it has passed; the TAMP
loop turns that into a failed result (reason ``timeout: ...``). The symbolic engine call
cannot be interrupted that way (pyperplan ignores unified-planning's timeout), so
:mod:`ldhp_tamp.symbolic` can run it in a child process and kill it at the deadline. The
vectorised geometry (contact-state enumeration, grasp enumeration) has no checks of its
own: :func:`alarm` is the backstop, a timer signal that raises the same exception from
whatever Python code runs :data:`ALARM_GRACE_S` after the deadline; while it is armed
(:func:`alarm_armed`) the TAMP loop runs a pure-Python engine in its own process, which
the signal interrupts like any other code.

Every reading of the time that a budget depends on goes through :data:`clock`: the checks,
:class:`Budget`, the solve's timings (:mod:`ldhp_tamp.tamp`) and the wait for the engine's
child process (:mod:`ldhp_tamp.symbolic`). A test replaces it
(``monkeypatch.setattr(budget, "clock", fake)``) to make a budget run out at a chosen point
of the solve, whatever the machine's load; :func:`alarm`, a real-time timer, is armed only
on the real clock.

>>> b = Budget.of(None)
>>> b.deadline is None and not b.expired() and b.remaining() is None
True
>>> Budget.of(0.0).expired()
True
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from dataclasses import dataclass, field
from types import FrameType
from typing import Callable, Iterator

from ldhp_tamp.errors import TimeBudgetExceeded

__all__ = ["ALARM_GRACE_S", "Budget", "alarm", "alarm_armed", "check", "clock", "expired", "remaining"]

#: The clock every deadline is read on: seconds, never decreasing. Read it as
#: ``budget.clock()`` (the module attribute, so that a replacement reaches every reader).
clock: Callable[[], float] = time.perf_counter

#: How long after the deadline :func:`alarm` interrupts: the cooperative checks, which
#: name their stage precisely, normally come first.
ALARM_GRACE_S = 0.25


def expired(deadline: float | None) -> bool:
    """Whether ``deadline`` (a :data:`clock` value, or ``None``) has passed."""
    return deadline is not None and clock() >= deadline


def remaining(deadline: float | None) -> float | None:
    """Seconds left until ``deadline`` (never negative), or ``None`` for no limit."""
    if deadline is None:
        return None
    return max(0.0, deadline - clock())


def check(deadline: float | None, where: str) -> None:
    """Raise :class:`TimeBudgetExceeded` naming ``where`` if ``deadline`` has passed.

    Costs one clock read; call it once per iteration of a loop, not per element.
    """
    if deadline is not None and clock() >= deadline:
        raise TimeBudgetExceeded(where)


@dataclass(frozen=True)
class Budget:
    """A time budget of ``seconds`` (``None``: unlimited) counted from ``start``.

    Attributes
    ----------
    seconds
        The budget as given (``--timeout``).
    start
        When it started, a :data:`clock` value (default: now).
    """

    seconds: float | None
    start: float = field(default_factory=lambda: clock())

    def __post_init__(self) -> None:
        if self.seconds is not None and not self.seconds >= 0:
            raise ValueError(f"a time budget must be a non-negative number of seconds, got {self.seconds}")

    @classmethod
    def of(cls, seconds: float | None) -> "Budget":
        """A budget of ``seconds`` starting now."""
        return cls(seconds)

    @property
    def deadline(self) -> float | None:
        """The :data:`clock` value at which the budget runs out."""
        return None if self.seconds is None else self.start + self.seconds

    def expired(self) -> bool:
        return expired(self.deadline)

    def remaining(self) -> float | None:
        return remaining(self.deadline)

    def check(self, where: str) -> None:
        check(self.deadline, where)


@contextlib.contextmanager
def alarm(deadline: float | None, grace: float = ALARM_GRACE_S) -> Iterator[None]:
    """Raise :class:`TimeBudgetExceeded` in the body at ``deadline + grace``, wherever it is.

    A backstop for stages without :func:`check` calls. It uses ``SIGALRM`` and a real-time
    interval timer, so it is active only in the main thread, where the platform has them
    and when no other ``SIGALRM`` handler is installed, and only on the real :data:`clock`
    (a timer cannot follow a test's fake one); otherwise the body runs without it.
    The previous handler is restored and the timer cleared on exit. (A forked child does
    not inherit the timer.) A long call into compiled code is interrupted when it returns.
    The timer fires again every ``grace`` seconds until the body exits: Python swallows an
    exception raised while a garbage-collector callback or a finaliser runs, and a
    one-shot alarm landing there would be lost. An alarm landing in library code that
    turns any exception into its own (numpy's ``norm`` reads ``axis`` under ``except
    Exception`` and raises a ``TypeError``) leaves the body as that exception, with the
    :class:`TimeBudgetExceeded` as its cause or context: it is raised again as that.
    """
    usable = (deadline is not None and clock is time.perf_counter and hasattr(signal, "setitimer")
              and threading.current_thread() is threading.main_thread()
              and signal.getsignal(signal.SIGALRM) in (signal.SIG_DFL, None))
    if not usable:
        yield
        return
    global _ALARMS

    def on_alarm(signum: int, frame: FrameType | None) -> None:
        raise TimeBudgetExceeded(f"{_innermost(frame)} (interrupted: it has no deadline checks of its own)")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    _ALARMS += 1
    try:
        signal.setitimer(signal.ITIMER_REAL, max(deadline + grace - time.perf_counter(), 1e-3), max(grace, 1e-2))
        yield
    except TimeBudgetExceeded:
        raise
    except Exception as exc:
        cause = _budget_cause(exc)
        if cause is None:
            raise
        raise cause from exc
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        _ALARMS -= 1


_ALARMS = 0  # alarm() bodies running with the signal armed


def _budget_cause(exc: BaseException) -> TimeBudgetExceeded | None:
    """The :class:`TimeBudgetExceeded` among the causes and contexts of ``exc``, if any."""
    seen: set[int] = set()
    todo: list[BaseException | None] = [exc.__cause__, exc.__context__]
    while todo:
        e = todo.pop()
        if e is None or id(e) in seen:
            continue
        if isinstance(e, TimeBudgetExceeded):
            return e
        seen.add(id(e))
        todo += [e.__cause__, e.__context__]
    return None


def alarm_armed() -> bool:
    """Whether an :func:`alarm` with its signal armed is running: pure-Python code that
    has no deadline checks of its own will be interrupted."""
    return _ALARMS > 0


def _innermost(frame: FrameType | None) -> str:
    """The innermost function of the project on the stack, as ``module.function``."""
    while frame is not None:
        module = frame.f_globals.get("__name__", "")
        if module.split(".")[0] in ("geometry", "ldhp_tamp") and module != __name__:
            return f"{module}.{frame.f_code.co_name}"
        frame = frame.f_back
    return "the solve"
