"""Planners by name: what ``ldhp-tamp bench --planners`` runs.

A planner is a callable ``(scenario, options) -> SolveResult`` (:class:`~ldhp_tamp.tamp.SolveOptions`
in, :class:`~ldhp_tamp.tamp.SolveResult` out): a failed solve is a result with a status,
never an exception. The registry :data:`PLANNERS` maps a name to a planner, as pyperplan's
``SEARCHES`` maps a name to a search; :func:`get_planner` looks a name up (and builds the
``cmd:`` planners); an unknown name is an :class:`~ldhp_tamp.errors.InputError` that lists
the known ones.

- ``ldhp``: :func:`ldhp_tamp.tamp.solve`, the paper's two-tier loop.
- ``ldhp-norefine``: the same without dichotomy refinement (``max_refinements = 0``): a
  failing tip or biplanar slide sends the loop to the next pose path at once.
- ``ldhp-nofeedback``: the same without feedback (``SolveOptions(feedback=False)``): a
  failure forbids nothing, and the symbolic tier re-plans blind (the streams draw other
  samples from the same seed's generator, so later iterations try other pose paths of the
  same contact-state plan).
- ``cmd:PROGRAM {scenario} {plan}``: an external program (see :class:`CommandPlanner`).

Other planners register themselves with :func:`register` (the ``contact-rrt`` baseline
does, from :mod:`ldhp_tamp.baselines.contact_rrt`, imported lazily by :func:`get_planner`).
Every planner's plan is judged the same way by the bench: validated, then simulated.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import logging
import os
import shlex
import signal
import subprocess
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from ldhp_tamp.errors import InputError, PlanFormatError
from ldhp_tamp.scenario import Scenario
from ldhp_tamp.tamp import SolveOptions, SolveResult, SolveStatus

__all__ = ["CMD_PREFIX", "CommandPlanner", "PLANNERS", "Planner", "get_planner", "planner_names", "register",
           "uses_engine"]

log = logging.getLogger(__name__)

Planner = Callable[[Scenario, SolveOptions], SolveResult]

#: Name -> planner. Filled below and by :func:`register`.
PLANNERS: dict[str, Planner] = {}

#: Planners that live in modules of their own, imported on first use (a heavy module
#: loads only when its planner is asked for): name -> module that registers it.
LAZY: dict[str, str] = {"contact-rrt": "ldhp_tamp.baselines.contact_rrt"}

#: The prefix of an external-command planner's name.
CMD_PREFIX = "cmd:"


def register(name: str) -> Callable[[Planner], Planner]:
    """Decorator: register a planner under ``name``."""

    def deco(fn: Planner) -> Planner:
        if name in PLANNERS and PLANNERS[name] is not fn:
            raise ValueError(f"planner {name!r} is registered twice")
        PLANNERS[name] = fn
        return fn

    return deco


@register("ldhp")
def ldhp(scenario: Scenario, options: SolveOptions) -> SolveResult:
    """The paper's two-tier loop."""
    from ldhp_tamp.tamp import solve

    return solve(scenario, options)


@register("ldhp-norefine")
def ldhp_norefine(scenario: Scenario, options: SolveOptions) -> SolveResult:
    """The two-tier loop without dichotomy refinement (L_max = 0)."""
    from ldhp_tamp.tamp import solve

    return solve(scenario, replace(options, max_refinements=0))


@register("ldhp-nofeedback")
def ldhp_nofeedback(scenario: Scenario, options: SolveOptions) -> SolveResult:
    """The two-tier loop without feedback: the symbolic tier re-plans blind."""
    from ldhp_tamp.tamp import solve

    return solve(scenario, replace(options, feedback=False))


#: The planners with a symbolic tier: the bench runs them once per engine.
WITH_ENGINE = frozenset({"ldhp", "ldhp-norefine", "ldhp-nofeedback"})


def uses_engine(name: str) -> bool:
    """Whether planner ``name`` plans with a symbolic engine (``--engines`` applies)."""
    return name in WITH_ENGINE


def planner_names() -> tuple[str, ...]:
    """The registered names (lazy ones whose module exists included), sorted, without the
    ``cmd:`` form."""
    lazy = {n for n, m in LAZY.items() if _module_exists(m)}
    return tuple(sorted(set(PLANNERS) | lazy))


def _module_exists(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a parent package is missing
        return False


def get_planner(name: str) -> Planner:
    """The planner called ``name``: a registered one, or ``cmd:PROGRAM {scenario} {plan}``.

    Raises
    ------
    InputError
        An unknown name (the message lists the known ones), a ``cmd:`` template that
        cannot be parsed or lacks ``{plan}``.
    """
    if name.startswith(CMD_PREFIX):
        return CommandPlanner.parse(name[len(CMD_PREFIX):])
    if name not in PLANNERS and name in LAZY and _module_exists(LAZY[name]):
        importlib.import_module(LAZY[name])  # registers it
    try:
        return PLANNERS[name]
    except KeyError:
        raise InputError(f"unknown planner {name!r}; known: {', '.join(planner_names())}, "
                         f"or {CMD_PREFIX}'PROGRAM {{scenario}} {{plan}}'") from None


#: Seconds a terminated external planner gets to exit (SIGTERM) before SIGKILL.
_TERM_WAIT_S = 2.0
#: Characters of an external planner's stderr kept in a failure's reason.
_STDERR_KEEP = 300


@dataclass(frozen=True)
class CommandPlanner:
    """An external program as a planner: ``PROGRAM ARGS...`` with ``{scenario}`` replaced
    by the scenario file's path, ``{plan}`` by the path of a plan file to write (an
    ``ldhp-plan/1`` file), and ``{seed}``, ``{timeout}`` by the solve's seed and time budget
    (seconds; empty when there is none).

    It runs in a process group of its own, under the solve's budget
    (``SolveOptions.timeout``): at the limit the group is terminated and the solve fails
    with a ``timeout`` reason. A program that exits non-zero, writes no plan, or writes one
    that cannot be read fails the solve with a reason that says so (never an exception).
    A plan it writes is returned as is, with ``status`` ``solved`` exactly when the file
    says ``solved`` and the plan passes the validator (:func:`ldhp_tamp.validate.validate_plan`);
    the bench then simulates it like any other planner's plan.
    """

    argv: tuple[str, ...]

    @classmethod
    def parse(cls, template: str) -> "CommandPlanner":
        try:
            argv = tuple(shlex.split(template))
        except ValueError as exc:
            raise InputError(f"planner {CMD_PREFIX}{template!r}: cannot parse the command: {exc}") from None
        if len(argv) == 1 and any(c.isspace() for c in argv[0]):
            return cls.parse(argv[0])  # the whole command quoted once more: cmd:'PROGRAM {scenario} {plan}'
        if not argv:
            raise InputError(f"planner {CMD_PREFIX}{template!r}: no program given")
        if not any("{plan}" in a for a in argv):
            raise InputError(f"planner {CMD_PREFIX}{template!r}: the command must name the plan file it "
                             "writes as {plan}")
        return cls(argv)

    @property
    def name(self) -> str:
        return CMD_PREFIX + shlex.join(self.argv)

    @property
    def label(self) -> str:
        """How a reason names the program: its command line (the template), files by
        their base name."""
        return "'" + " ".join(os.path.basename(a) if os.sep in a and "{" not in a else a for a in self.argv) + "'"

    def __call__(self, scenario: Scenario, options: SolveOptions) -> SolveResult:
        from ldhp_tamp import budget

        start = budget.clock() if options.started is None else options.started
        if scenario.path is None:
            raise InputError("an external planner needs a scenario read from a file")
        seed = scenario.settings.seed if options.seed is None else options.seed
        with tempfile.TemporaryDirectory(prefix="ldhp-cmd-") as tmp:
            plan_path = Path(tmp) / "plan.json"
            fields = {"scenario": str(scenario.path), "plan": str(plan_path), "seed": str(seed),
                      "timeout": "" if options.timeout is None else f"{options.timeout:g}"}
            argv = [a.format(**fields) for a in self.argv]
            limit = None if options.timeout is None else max(options.timeout - (budget.clock() - start), 0.0)
            log.info("running %s", shlex.join(argv))
            try:
                proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.PIPE, start_new_session=True, cwd=tmp)
            except OSError as exc:
                return self._failed(scenario, start, f"cannot run {self.label}: {exc.strerror or exc}")
            try:
                _, err = proc.communicate(timeout=limit)
            except subprocess.TimeoutExpired:
                _kill_group(proc)
                return self._failed(scenario, start, f"timeout: the {options.timeout:g} s budget ran out in the "
                                    f"external planner {self.label} (terminated)", timeout=True)
            finally:
                if proc.poll() is None:  # an exception (Ctrl-C, SIGTERM): the program goes too
                    _kill_group(proc)
            stderr = " ".join(err.decode("utf-8", "replace").split())[-_STDERR_KEEP:]
            if proc.returncode != 0:
                how = (f"killed by signal {-proc.returncode}" if proc.returncode < 0
                       else f"exit status {proc.returncode}")
                return self._failed(scenario, start, f"the external planner {self.label} failed ({how})"
                                    + (f": {stderr}" if stderr else ""))
            if not plan_path.exists():
                return self._failed(scenario, start, f"the external planner {self.label} wrote no plan file")
            from ldhp_tamp.plan import read_plan

            try:
                plan = read_plan(plan_path)
            except PlanFormatError as exc:
                text = str(exc).replace(str(plan_path), "its plan")
                return self._failed(scenario, start, f"the external planner {self.label} wrote no readable "
                                    f"ldhp-plan/1 file: {text}")
        elapsed = budget.clock() - start
        stats = replace(plan.stats, time_s=dict(plan.stats.time_s, total=round(elapsed, 4)))
        plan = replace(plan, stats=stats)
        if plan.status.value != "solved":
            return SolveResult(SolveStatus.FAILED, plan, plan.reason or "the external planner reports no plan")
        from ldhp_tamp.validate import format_violation, validate_plan

        report = validate_plan(plan, scenario)
        if not report.valid:
            first = min(report.violations, key=lambda v: v.sort_key())
            why = (f"the external planner's plan is invalid ({len(report.violations)} violation(s)): "
                   + format_violation(first, plan))
            return SolveResult(SolveStatus.FAILED, replace(plan, reason=why), why)
        return SolveResult(SolveStatus.SOLVED, plan)

    def _failed(self, scenario: Scenario, start: float, reason: str, timeout: bool = False) -> SolveResult:
        from ldhp_tamp import budget
        from ldhp_tamp.plan import PLAN_FORMAT, Failure, FailureCause, FailureTier, Plan, PlanStats, PlanStatus

        log.info("failed: %s", reason)
        failure = Failure(FailureTier.TIMEOUT, FailureCause.TIMEOUT, attempts=(reason,)) if timeout else None
        stats = PlanStats(engine=self.name, time_s={"total": round(budget.clock() - start, 4)})
        plan = Plan(PLAN_FORMAT, scenario.name, scenario.sha256, PlanStatus.FAILED, (), stats, reason, failure)
        return SolveResult(SolveStatus.FAILED, plan, reason)


def _kill_group(proc: subprocess.Popen[bytes]) -> None:
    """Terminate ``proc``'s process group: SIGTERM, then SIGKILL."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(proc.pid, sig)
        try:
            proc.wait(_TERM_WAIT_S)
            break
        except subprocess.TimeoutExpired:
            continue
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)  # what the group leader left behind
    with contextlib.suppress(Exception):
        proc.communicate(timeout=_TERM_WAIT_S)

