"""The project's exception tree. One root: :class:`LdhpError`.

Library code raises these for bad input; a failed solve is *not* an exception but a
result with a status and a reason. Only :mod:`ldhp_tamp.cli` turns errors into exit codes.
"""

from __future__ import annotations

from pathlib import Path


class LdhpError(Exception):
    """Root of every error the planner raises on purpose."""


class InputError(LdhpError):
    """Bad input of any kind: the CLI answers it with exit status 2."""


class ScenarioError(InputError):
    """A scenario file that does not follow ``ldhp-scenario/1``.

    The message names the file, the key and the problem: ``task.toml: object.vertices:
    self-intersecting polygon``.
    """

    def __init__(self, path: str | Path | None, key: str | None, problem: str):
        self.path = str(path) if path is not None else "<string>"
        self.key = key
        self.problem = problem
        where = f"{self.path}: {key}: " if key else f"{self.path}: "
        super().__init__(where + problem)


class DomainError(InputError):
    """A PDDL domain that cannot be used: syntax error, unsupported requirement, or an
    action with no registered geometric implementation."""


class EngineError(InputError):
    """An unknown or unusable planning engine."""


class PlanFormatError(InputError):
    """A plan file that does not follow ``ldhp-plan/1``."""


class TimeBudgetExceeded(LdhpError):
    """A solve's time budget ran out (``--timeout``); ``where`` says in which stage.

    Raised deep in the search (:mod:`ldhp_tamp.budget`), caught by
    :func:`ldhp_tamp.tamp.solve`, which answers with a failed result whose reason starts
    with ``timeout``. It is not an :class:`InputError` and never reaches the CLI.
    """

    def __init__(self, where: str):
        self.where = where
        super().__init__(f"time budget exceeded in {where}")


class ExecutorError(InputError):
    """A sweep executor that cannot be used (``--executor dask`` without the
    ``distributed`` package, a ``--scheduler`` that cannot be reached): the CLI answers
    it with exit status 2, before any cell has run."""
