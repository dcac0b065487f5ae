"""The ablation of the primitive library: ``ldhp-tamp ablate`` (the paper's Table III).

The PDDL domain is the primitive library, so a primitive is removed the way a user would
remove it: by deleting its ``(:action ...)`` from a copy of the domain file. For each
action of the domain in turn (and for none, the baseline), :func:`ablate` writes such a
copy into a temporary directory, checks that it still loads and that the registry still
covers it, solves every scenario with it (``SolveOptions(domain=...)``), validates each
plan and records whether a valid plan was found. The planner itself knows nothing of the
ablation. Data flows through plain functions over small values::

    text = domain_without(pddl_text, {"tip"})            # PDDL text without (:action tip ...)
    path = write_domain_without("ldhp", {"tip"}, tmp)    # the same, as a checked file
    table = ablate(["scenarios/example_pick.toml"], AblationOptions(jobs=2))
    print(format_table(table))                           # Table III, Markdown
    write_csv(table, "ablation.csv")                     # removed,scenario,feasible,reason,...

A cell is feasible (``Y``) when the solve returns a plan that the validator accepts and
that uses only the actions of the ablated domain (with ``simulate``, one that executes in
the physics simulation too: the solve's judge replays every plan it finds and goes on
past those that diverge); anything else (no plan, a time limit, an error) is ``N``, with
the status and the reason kept in the cell.

Solves at once. With ``jobs`` 1 and the ``local`` executor the cells are solved in this
process, one after the other. Otherwise each cell is a process of its own through
:func:`ldhp_tamp.sweep.run_cells` (``local``: at most ``jobs`` forked processes;
``dask``: one Dask task per cell, on a ``LocalCluster`` or a ``scheduler``), under the hard
limit ``timeout_s + grace_s``: a cell whose process crashes is an ``error`` cell, one past
the limit a ``timeout`` cell, and the others go on.

Resuming. With ``csv``, :func:`ablate` rewrites that file as each cell ends; with
``resume`` it first reads the file and solves again only the cells it lacks or holds
with the status ``error`` (a crash says nothing about the primitive).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import logging
import math
import os
import re
import tempfile
import time
import traceback
from collections.abc import Callable, Collection, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ldhp_tamp.errors import DomainError, InputError
from ldhp_tamp.files import write_text_atomic
from ldhp_tamp.primitives.registry import Family
from ldhp_tamp.sweep import CellFailure, CellTask, SweepOptions, check_executor, run_cells

if TYPE_CHECKING:
    from ldhp_tamp.scenario import Scenario

__all__ = [
    "BASELINE",
    "CSV_COLUMNS",
    "AblationCell",
    "AblationOptions",
    "AblationRow",
    "AblationTable",
    "ablate",
    "domain_without",
    "format_csv",
    "format_sexpr",
    "format_table",
    "parse_sexprs",
    "read_csv",
    "write_csv",
    "write_domain_without",
]

log = logging.getLogger(__name__)

#: The ``removed`` label of the baseline row: the domain with nothing removed.
BASELINE = "none"

#: The columns of the CSV, in order: the table's three first, then why a cell is not
#: feasible (the solve's one-line reason; empty when feasible), the solve's wall time,
#: the cell's status and the plan's primitives (space-separated; empty when not feasible).
CSV_COLUMNS: tuple[str, ...] = ("removed", "scenario", "feasible", "reason", "time_s", "status", "primitives")

#: The statuses a resumed ablation keeps; an ``error`` cell is solved again.
FINAL_STATUSES = frozenset({"solved", "failed", "invalid", "timeout"})

#: An s-expression: an atom, or a list of s-expressions.
SExpr = str | list["SExpr"]


# --------------------------------------------------------------------------- options and results


@dataclass(frozen=True)
class AblationOptions:
    """What to ablate and how.

    Attributes
    ----------
    domain
        The domain to ablate: a shipped domain's name or a ``.pddl`` path. ``None``: the
        scenarios' own domain (they must all use the same one).
    remove
        The actions to remove, one at a time; ``None``: every action of the domain.
    timeout_s
        Seconds per solve, passed as ``SolveOptions(timeout=...)`` when the planner has
        that option (otherwise ignored, with a warning).
    grace_s
        Seconds added to ``timeout_s`` for the hard limit of a cell run in a process of
        its own (its process group is then terminated: a ``timeout`` cell).
    jobs
        Solves at once, each in a process of its own; 1 with the ``local`` executor
        solves in this process.
    keep_domains
        Write the domain copies into this directory and keep them; ``None``: a temporary
        directory, removed at the end.
    executor, scheduler
        ``local`` or ``dask``, and the ``dask`` scheduler's address (``tcp://HOST:PORT``;
        ``None``: a ``LocalCluster`` of ``jobs`` workers): :mod:`ldhp_tamp.sweep`.
    simulate
        Solve with the simulation judge (``SolveOptions(simulate=True)``): a cell is
        ``Y`` only for a plan that executes in the physics simulation.

    Raises
    ------
    InputError
        On a value out of range (the message names the option).
    """

    domain: str | Path | None = None
    remove: tuple[str, ...] | None = None
    timeout_s: float | None = None
    jobs: int = 1
    keep_domains: Path | None = None
    grace_s: float = 10.0
    executor: str = "local"
    scheduler: str | None = None
    simulate: bool = False

    def __post_init__(self) -> None:
        check_executor(self.executor, self.scheduler)
        if self.remove is not None:
            object.__setattr__(self, "remove", tuple(dict.fromkeys(a.lower() for a in self.remove)))
            if not self.remove:
                raise InputError("--remove: give at least one action")
        if self.jobs < 1:
            raise InputError(f"--jobs: need at least 1 worker, got {self.jobs}")
        if self.timeout_s is not None and not (math.isfinite(self.timeout_s) and self.timeout_s > 0):
            raise InputError(f"--timeout: must be a positive number of seconds, got {self.timeout_s}")
        if not (math.isfinite(self.grace_s) and self.grace_s >= 0):
            raise InputError(f"--grace: must be >= 0 seconds, got {self.grace_s}")

    @property
    def hard_limit_s(self) -> float | None:
        """The limit of a cell in a process of its own: ``timeout_s + grace_s``, or none."""
        return None if self.timeout_s is None else self.timeout_s + self.grace_s


@dataclass(frozen=True)
class AblationCell:
    """One solve: one scenario with one action removed.

    Attributes
    ----------
    removed
        The action removed, or :data:`BASELINE`.
    scenario, scenario_file
        The scenario's name (the table's column) and the file it was read from.
    feasible
        A valid plan was found with the actions left.
    status
        ``solved``, ``failed`` (the planner's status), ``timeout`` (the solve ran out of
        ``timeout_s``), ``invalid`` (a plan the validator or the domain check refused) or
        ``error`` (the solve raised).
    reason
        Why it is not feasible; empty when it is.
    time_s
        Wall time of the solve, in this process or the worker.
    primitives
        The plan's steps, in order (empty when not feasible).
    """

    removed: str
    scenario: str
    scenario_file: str
    feasible: bool
    status: str
    reason: str
    time_s: float
    primitives: tuple[str, ...] = ()

    @property
    def mark(self) -> str:
        """``Y`` or ``N``."""
        return "Y" if self.feasible else "N"


@dataclass(frozen=True)
class AblationRow:
    """A row of Table III: one action removed (or none), a cell per scenario in column order.

    ``family`` is the removed action's family; ``None`` for the baseline.
    """

    removed: str
    family: Family | None
    cells: tuple[AblationCell, ...]


@dataclass(frozen=True)
class AblationTable:
    """Table III: the baseline row first, then one row per removed action (MoveObject
    actions first, then AdjustGrasp, each in the domain's order); a column per scenario."""

    domain: str
    scenarios: tuple[str, ...]
    rows: tuple[AblationRow, ...]

    def cell(self, removed: str, scenario: str) -> AblationCell:
        """The cell of one row and column; :class:`KeyError` if there is none."""
        for row in self.rows:
            if row.removed == removed:
                for cell in row.cells:
                    if cell.scenario == scenario:
                        return cell
        raise KeyError((removed, scenario))

    def feasible(self, removed: str, scenario: str) -> bool:
        return self.cell(removed, scenario).feasible


# --------------------------------------------------------------------------- PDDL copies

_TOKEN = re.compile(r"\(|\)|;[^\n]*|[^\s();]+")


def parse_sexprs(text: str, source: str = "<string>") -> list[SExpr]:
    """Parse PDDL text into s-expressions (lists of lists and atoms); comments are dropped.

    >>> parse_sexprs("(define (domain d) ; a comment\\n (:types state))")
    [['define', ['domain', 'd'], [':types', 'state']]]

    Raises
    ------
    DomainError
        On an unbalanced parenthesis, naming ``source`` and the line.
    """
    stack: list[list[SExpr]] = [[]]
    opened: list[int] = []
    line = 1
    pos = 0
    for match in _TOKEN.finditer(text):
        line += text.count("\n", pos, match.start())
        pos = match.start()
        token = match.group()
        if token.startswith(";"):
            continue
        if token == "(":
            stack.append([])
            opened.append(line)
        elif token == ")":
            if len(stack) == 1:
                raise DomainError(f"{source}:{line}: PDDL error: ')' without a matching '('")
            done = stack.pop()
            opened.pop()
            stack[-1].append(done)
        else:
            stack[-1].append(token)
    if len(stack) > 1:
        raise DomainError(f"{source}:{opened[-1]}: PDDL error: '(' is never closed")
    return stack[0]


def _flat(form: SExpr) -> str:
    if isinstance(form, str):
        return form
    return "(" + " ".join(_flat(x) for x in form) + ")"


def _keyword(form: SExpr) -> bool:
    return isinstance(form, str) and form.startswith(":")


def format_sexpr(form: SExpr, indent: int = 0, width: int = 88) -> str:
    """Print an s-expression as PDDL: on one line when it fits in ``width`` columns,
    otherwise its head (and the atoms after it) on the first line and each further element
    on a line of its own, indented two columns, a ``:keyword`` with its value."""
    flat = _flat(form)
    if isinstance(form, str) or indent + len(flat) <= width:
        return flat
    head = [_flat(form[0])] if form else []
    i = 1
    while i < len(form) and isinstance(form[i], str) and not _keyword(form[i]):
        head.append(form[i])
        i += 1
    pad = " " * (indent + 2)
    lines = ["(" + " ".join(head)]
    while i < len(form):
        item = form[i]
        if _keyword(item) and i + 1 < len(form) and not _keyword(form[i + 1]):
            assert isinstance(item, str)
            lines.append(pad + item + " " + format_sexpr(form[i + 1], indent + 2, width))
            i += 2
        else:
            lines.append(pad + format_sexpr(item, indent + 2, width))
            i += 1
    return "\n".join(lines) + ")"


def _define(forms: list[SExpr], source: str) -> list[SExpr]:
    """The one ``(define (domain NAME) ...)`` form of a domain file."""
    define = forms[0] if len(forms) == 1 else None
    if not (isinstance(define, list) and len(define) >= 2
            and isinstance(define[0], str) and define[0].lower() == "define"
            and isinstance(define[1], list) and len(define[1]) == 2
            and isinstance(define[1][0], str) and define[1][0].lower() == "domain"):
        raise DomainError(f"{source}: PDDL error: a domain file holds exactly one "
                          f"(define (domain NAME) ...) form")
    return define


def _action_name(form: SExpr) -> str | None:
    """The lower-case name of an ``(:action NAME ...)`` form, else ``None``."""
    if (isinstance(form, list) and len(form) >= 2 and isinstance(form[0], str)
            and form[0].lower() == ":action" and isinstance(form[1], str)):
        return form[1].lower()
    return None


def domain_without(text: str, remove: Collection[str], source: str = "<string>") -> str:
    """PDDL domain text without the ``(:action NAME ...)`` forms of ``remove``.

    The text is parsed into s-expressions, the actions are dropped, and the rest is
    printed back unchanged but for its layout; comments are dropped. Names compare
    case-insensitively, as PDDL's do. An empty ``remove`` reprints the domain.

    >>> pddl = "(define (domain d) (:action a :parameters ()) (:action b :parameters ()))"
    >>> print(domain_without(pddl, {"A"}).split("\\n", 3)[3], end="")
    (define (domain d)
      (:action b :parameters ()))

    Raises
    ------
    InputError
        An action of ``remove`` that the domain does not declare (the message lists the
        ones it does).
    DomainError
        Text that is not one balanced ``(define (domain NAME) ...)`` form.
    """
    return _without(text, remove, source)[0]


def _without(text: str, remove: Collection[str], source: str) -> tuple[str, tuple[str, ...]]:
    """:func:`domain_without`, and the names of the actions the copy keeps."""
    define = _define(parse_sexprs(text, source), source)
    declared = [name for form in define if (name := _action_name(form)) is not None]
    wanted = {a.lower() for a in remove}
    unknown = sorted(wanted - set(declared))
    if unknown:
        raise InputError(f"{source}: no action {unknown[0]!r} to remove; the domain declares "
                         f"{', '.join(declared) or 'no action'}")
    kept = [form for form in define if _action_name(form) not in wanted]
    what = ", ".join(a for a in declared if a in wanted) or "nothing"
    header = (f";;; {Path(source).name} without: {what}\n"
              f";;; Written by ldhp-tamp ablate from {source}: the same domain with those\n"
              f";;; actions removed; comments dropped.\n")
    parts = [f"({_flat(kept[0])} {_flat(kept[1])}"] + ["  " + format_sexpr(form, 2) for form in kept[2:]]
    return header + "\n".join(parts) + ")\n", tuple(a for a in declared if a not in wanted)


def _copy_name(stem: str, remove: Collection[str]) -> str:
    if not remove:
        return f"{stem}-baseline.pddl"
    return f"{stem}-without-{'-'.join(sorted(a.lower() for a in remove))}.pddl"


def write_domain_without(domain: str | os.PathLike[str], remove: Collection[str],
                         out_dir: str | os.PathLike[str]) -> Path:
    """Write a copy of ``domain`` without the actions of ``remove`` into ``out_dir`` and
    check it: it loads (:func:`ldhp_tamp.symbolic.load_domain`) and declares exactly the
    original's actions minus ``remove``.

    Parameters
    ----------
    domain
        A shipped domain's name (``"ldhp"``) or a ``.pddl`` path.
    remove
        Action names; empty writes the domain reprinted (the baseline).
    out_dir
        An existing directory. The copy is ``<stem>-without-<actions>.pddl``, or
        ``<stem>-baseline.pddl`` when nothing is removed.

    Returns
    -------
    Path
        The copy.

    Raises
    ------
    InputError
        Unknown domain or action, a domain that does not parse, or a copy that does not
        load (the message names the file).
    """
    from ldhp_tamp import symbolic
    from ldhp_tamp.scenario import find_domain

    source = find_domain(str(domain))
    if source is None:
        raise DomainError(f"domain not found: {domain} (neither a shipped domain name nor an "
                          f"existing .pddl file)")
    try:
        text = source.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DomainError(f"{source}: cannot read domain: {exc}") from exc
    copy_text, expected = _without(text, remove, str(source))
    path = Path(out_dir) / _copy_name(source.stem, remove)
    write_text_atomic(path, copy_text)
    try:
        copy = symbolic.load_domain(path)
    except DomainError as exc:
        raise DomainError(f"{source} without {', '.join(sorted(remove)) or 'nothing'} does not load: "
                          f"{exc}") from exc
    if copy.info.names() != expected:  # a bug of the printer, not of the input
        raise DomainError(f"{path}: the copy declares {', '.join(copy.info.names())}, "
                          f"expected {', '.join(expected)}")
    return path


# --------------------------------------------------------------------------- solving


@dataclass(frozen=True)
class _Job:
    """One cell to solve (picklable: sent to worker processes)."""

    removed: str
    scenario: str
    scenario_file: str
    domain_file: str
    actions: tuple[str, ...]  # the ablated domain's actions
    timeout_s: float | None
    simulate: bool = False


def _solve_job(job: _Job) -> AblationCell:
    """Solve one cell. Never raises for a failed or broken solve: that is a cell."""
    start = time.perf_counter()
    try:
        return _solve(job, start)
    except Exception as exc:  # a crash of one solve is a cell, not the end of the ablation
        last = traceback.extract_tb(exc.__traceback__)[-1:]
        where = f" (at {Path(last[0].filename).name}:{last[0].lineno})" if last else ""
        log.error("without %s, %s: the solve raised %s: %s%s", job.removed, job.scenario,
                  type(exc).__name__, exc, where)
        return AblationCell(job.removed, job.scenario, job.scenario_file, False, "error",
                            f"{type(exc).__name__}: {exc}{where}", time.perf_counter() - start)


def _failed_cell(job: _Job, failure: CellFailure, reason: str, wall_s: float) -> AblationCell:
    """The cell of a solve whose process died (``error``) or passed the hard limit
    (``timeout``)."""
    return AblationCell(job.removed, job.scenario, job.scenario_file, False, failure.value, reason, wall_s)


#: How :func:`ldhp_tamp.sweep.run_cells` solves a cell. A cell's ``time_s`` stays the one
#: measured around the solve in its process (the process's start-up, which differs between
#: executors, is not counted).
_TASK: CellTask[_Job, AblationCell] = CellTask(run=_solve_job, failed=_failed_cell,
                                               preload=("ldhp_tamp.ablate", "ldhp_tamp.solver_preload"), name="ablate")


def _solve(job: _Job, start: float) -> AblationCell:
    from ldhp_tamp.bench import solver_has_timeout
    from ldhp_tamp.scenario import load_scenario
    from ldhp_tamp.tamp import SolveOptions, solve
    from ldhp_tamp.validate import validate_plan

    scenario = load_scenario(job.scenario_file)
    knobs: dict[str, object] = {"domain": Path(job.domain_file), "simulate": job.simulate}
    if job.timeout_s is not None and solver_has_timeout():
        knobs["timeout"] = job.timeout_s
    result = solve(scenario, SolveOptions(**knobs))  # type: ignore[arg-type]

    def cell(feasible: bool, status: str, reason: str, primitives: tuple[str, ...] = ()) -> AblationCell:
        return AblationCell(job.removed, job.scenario, job.scenario_file, feasible, status, reason,
                            time.perf_counter() - start, primitives)

    if not result.solved:
        reason = result.reason or result.plan.reason or ""
        # a solve that ran out of time proves nothing: its own status, noted under the table
        return cell(False, "timeout" if reason.startswith("timeout") else result.status.value, reason)
    used = tuple(step.primitive for step in result.plan.steps)
    foreign = sorted(set(used) - set(job.actions))
    if foreign:  # the planner used a primitive the domain no longer declares: a bug
        log.error("without %s, %s: the plan uses %s, which the domain does not declare",
                  job.removed, job.scenario, ", ".join(foreign))
        return cell(False, "invalid", f"the plan uses {', '.join(foreign)}, which the ablated "
                                      f"domain does not declare")
    report = validate_plan(result.plan, scenario)
    if not report.valid:
        what = "; ".join(v.message for v in report.violations[:3])
        log.error("without %s, %s: the plan does not validate: %s", job.removed, job.scenario, what)
        return cell(False, "invalid", f"the plan does not validate ({len(report.violations)} "
                                      f"violation(s): {what})")
    return cell(True, result.status.value, "", used)


def _run(jobs: Sequence[_Job], options: AblationOptions, on_cell: Callable[[AblationCell], None]
         ) -> list[AblationCell]:
    """Solve every job, in this process (``jobs`` 1, ``local``) or each in a process of its
    own (:func:`ldhp_tamp.sweep.run_cells`); cells in the order of ``jobs``."""
    if options.executor == "local" and (options.jobs == 1 or len(jobs) == 1):
        cells = []
        for job in jobs:
            cells.append(_solve_job(job))
            on_cell(cells[-1])
        return cells
    sweep = SweepOptions(executor=options.executor, jobs=min(options.jobs, len(jobs)),
                         scheduler=options.scheduler, hard_limit_s=options.hard_limit_s)
    return run_cells(jobs, _TASK, sweep, lambda _position, cell: on_cell(cell))


def _common_domain(scenarios: Sequence[tuple[Path, Scenario]]) -> Path:
    """The one domain every scenario uses; :class:`InputError` if they differ."""
    paths = {Path(sc.settings.domain_path or sc.settings.domain).resolve() for _, sc in scenarios}
    if len(paths) != 1:
        raise InputError("the scenarios use different domains (" + ", ".join(sorted(map(str, paths)))
                         + "): choose the one to ablate with --domain")
    return paths.pop()


def ablate(scenarios: Sequence[str | os.PathLike[str]], options: AblationOptions = AblationOptions(),
           progress: Callable[[str], None] | None = None, csv_path: str | os.PathLike[str] | None = None,
           resume: bool = False) -> AblationTable:
    """Remove one action of the domain at a time and solve every scenario without it.

    Every scenario is loaded and every domain copy written and checked (it loads, the
    registry covers it) before the first solve, so bad input fails fast.

    Parameters
    ----------
    scenarios
        Scenario files; their names are the table's columns and must differ.
    options
        See :class:`AblationOptions`.
    progress
        Called with one line per finished solve (and a few more).
    csv_path
        Write the table as CSV (:func:`format_csv`) here, rewritten as each cell ends:
        an interrupted ablation keeps the cells it solved.
    resume
        With ``csv_path``: keep the cells of an existing ``csv_path`` (:func:`read_csv`)
        whose status is final (not ``error``) and solve only the others.

    Returns
    -------
    AblationTable
        The baseline row, then a row per removed action.

    Raises
    ------
    InputError
        A scenario that cannot be loaded, two scenarios with the same name, an unknown
        domain or action, scenarios with different domains and no ``options.domain``, a
        ``csv_path`` to resume from that is not such a CSV (:func:`read_csv`).
    ExecutorError
        ``dask`` without the ``distributed`` package, or a scheduler that cannot be
        reached.
    """
    from ldhp_tamp import symbolic
    from ldhp_tamp.primitives import REGISTRY, check_against_domain
    from ldhp_tamp.scenario import find_domain, load_scenario

    say = progress or (lambda _msg: None)
    if options.timeout_s is not None:
        from ldhp_tamp.bench import solver_has_timeout

        if not solver_has_timeout():
            log.warning("the planner has no timeout option (SolveOptions.timeout): --timeout is ignored")
    if not scenarios:
        raise InputError("no scenario given")
    loaded = [(Path(p), load_scenario(p)) for p in scenarios]
    names = [sc.name for _, sc in loaded]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"two scenarios are named {twice[0]!r}: the table's columns need distinct names")
    if options.domain is not None:
        source = find_domain(str(options.domain))
        if source is None:
            raise DomainError(f"domain not found: {options.domain} (neither a shipped domain name "
                              f"nor an existing .pddl file)")
    else:
        source = _common_domain(loaded)
    info = symbolic.load_domain(source).info
    if BASELINE in info:
        raise InputError(f"{source}: an action is named {BASELINE!r}, the label of the baseline row")
    if options.remove is None:
        order = [*info.names(Family.MOVE_OBJECT), *info.names(Family.ADJUST_GRASP)]
    else:
        unknown = [a for a in options.remove if a not in info]
        if unknown:
            raise InputError(f"--remove: the domain {source} has no action {unknown[0]!r}; it "
                             f"declares {', '.join(info.names())}")
        order = [a for fam in (Family.MOVE_OBJECT, Family.ADJUST_GRASP)
                 for a in info.names(fam) if a in options.remove]

    with _domain_dir(options.keep_domains) as out_dir:
        copies: dict[str, tuple[Path, tuple[str, ...]]] = {}
        for removed in (BASELINE, *order):
            drop = () if removed == BASELINE else (removed,)
            path = write_domain_without(source, drop, out_dir)
            ablated = symbolic.load_domain(path).info
            check_against_domain(ablated, REGISTRY)
            copies[removed] = (path, ablated.names())
        jobs = [_Job(removed, sc.name, str(p), str(copies[removed][0]), copies[removed][1], options.timeout_s,
                     options.simulate)
                for removed in copies for p, sc in loaded]
        by_key: dict[tuple[str, str], AblationCell] = {}
        if csv_path is not None and resume and Path(csv_path).exists():
            wanted = {(j.removed, j.scenario): j for j in jobs}
            for kept in read_csv(csv_path):
                job = wanted.get((kept.removed, kept.scenario))
                if job is not None and kept.status in FINAL_STATUSES:
                    by_key[(kept.removed, kept.scenario)] = dataclasses.replace(kept, scenario_file=job.scenario_file)
        todo = [j for j in jobs if (j.removed, j.scenario) not in by_key]
        resumed = f" ({len(by_key)} already in {csv_path}, {len(todo)} to solve)" if by_key else ""
        say(f"{len(copies)} domains ({source.name} and one without each of {len(order)} action(s)) x "
            f"{len(loaded)} scenario(s): {len(jobs)} solves{resumed}, {options.jobs} at a time")

        def write(final: bool = False) -> None:
            if csv_path is not None and (todo or final):
                _write_cells(csv_path, [by_key[k] for j in jobs if (k := (j.removed, j.scenario)) in by_key])

        def on_cell(cell: AblationCell) -> None:
            by_key[(cell.removed, cell.scenario)] = cell
            label = "baseline" if cell.removed == BASELINE else f"without {cell.removed}"
            how = cell.status if cell.status in ("solved", "failed") else f"{cell.status}: {cell.reason}"
            say(f"[{len(by_key) - len(jobs) + len(todo)}/{len(todo)}] {label}, {cell.scenario}: {cell.mark} "
                f"({how}, {cell.time_s:.1f} s)")
            write()

        if todo:
            _run(todo, options, on_cell)
        write(final=True)
    rows = tuple(AblationRow(removed, None if removed == BASELINE else info.action(removed).family,
                             tuple(by_key[(removed, name)] for name in names))
                 for removed in copies)
    return AblationTable(domain=str(source), scenarios=tuple(names), rows=rows)


@contextlib.contextmanager
def _domain_dir(keep: Path | None) -> Iterator[Path]:
    """The directory for the domain copies: ``keep`` (created if missing, kept), or a
    fresh temporary directory, removed on exit."""
    if keep is None:
        with tempfile.TemporaryDirectory(prefix="ldhp-ablate-") as tmp:
            yield Path(tmp)
        return
    out = Path(keep)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise InputError(f"{out}: --keep-domains must be a directory, and this is a file") from None
    except OSError as exc:
        raise InputError(f"{out}: cannot create the directory for the domain copies: "
                         f"{exc.strerror or exc}") from None
    yield out


# --------------------------------------------------------------------------- outputs


def format_table(table: AblationTable) -> str:
    """Table III as Markdown: a row per removed primitive, grouped by family, a column per
    scenario, ``Y`` or ``N``; then a note for every ``N`` that is not a plain failure to
    find a plan (a time limit, a refused plan, an error) and the total solve time."""
    header = ["primitive removed", *table.scenarios]
    lines = [
        f"Ablation of {table.domain}: Y = a valid plan was found, N = none.", "",
        "| " + " | ".join(header) + " |",
        "| --- |" + " :---: |" * len(table.scenarios),
    ]
    family: Family | None = None
    for row in table.rows:
        if row.family is not None and row.family is not family:
            family = row.family
            title = "MoveObject" if family is Family.MOVE_OBJECT else "AdjustGrasp"
            lines.append(f"| *{title}* |" + " |" * len(table.scenarios))
        label = "none (baseline)" if row.removed == BASELINE else row.removed
        lines.append(f"| {label} | " + " | ".join(c.mark for c in row.cells) + " |")
    notes = [c for row in table.rows for c in row.cells if c.status not in ("solved", "failed")]
    if notes:
        lines += ["", "Not a plain failure to find a plan:"]
        for c in notes:
            label = "baseline" if c.removed == BASELINE else f"without {c.removed}"
            reason = " ".join(c.reason.split())
            what = reason if reason.startswith(c.status) else f"{c.status}: {reason}"
            lines.append(f"- {label}, {c.scenario}: {what}")
    total = sum(c.time_s for row in table.rows for c in row.cells)
    lines += ["", f"{sum(len(r.cells) for r in table.rows)} solves, {total:.1f} s of solving in all."]
    return "\n".join(lines) + "\n"


def format_csv(table: AblationTable) -> str:
    """The table as CSV with the columns :data:`CSV_COLUMNS`,
    ``removed,scenario,feasible,reason,time_s,status,primitives`` (``feasible`` is ``Y``
    or ``N``; the baseline's ``removed`` is :data:`BASELINE`; ``reason`` is empty for a
    feasible cell and on one line; ``time_s`` the solve's wall time in seconds, 3
    decimals; ``status`` the cell's; ``primitives`` the plan's steps, space-separated)."""
    return _csv_text(cell for row in table.rows for cell in row.cells)


def _csv_text(cells: Iterable[AblationCell]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for cell in cells:
        reason = "" if cell.feasible else " ".join(cell.reason.split())
        writer.writerow([cell.removed, cell.scenario, cell.mark, reason, f"{cell.time_s:.3f}", cell.status,
                         " ".join(cell.primitives)])
    return buf.getvalue()


def _write_cells(path: str | os.PathLike[str], cells: Iterable[AblationCell]) -> Path:
    try:
        return write_text_atomic(path, _csv_text(cells))
    except OSError as exc:
        raise InputError(f"{path}: cannot write the CSV: {exc.strerror or exc}") from None


def read_csv(path: str | os.PathLike[str]) -> tuple[AblationCell, ...]:
    """The cells of a CSV that :func:`format_csv` (or a running :func:`ablate`) wrote, in
    its order; ``scenario_file`` is empty (the CSV does not hold it).

    Raises
    ------
    InputError
        A file that cannot be read, or that is not such a CSV (other columns, a bad
        value): the message names the file and the line.
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the ablation CSV: {exc}") from None
    reader = csv.reader(io.StringIO(text))
    header = tuple(next(reader, ()))
    if header != CSV_COLUMNS:
        raise InputError(f"{path}: not an ablation CSV of this version: its columns are "
                         f"{','.join(header) or 'missing'}, expected {','.join(CSV_COLUMNS)}")
    cells = []
    for line, values in enumerate(reader, start=2):
        if len(values) != len(CSV_COLUMNS) or values[2] not in ("Y", "N"):
            raise InputError(f"{path}:{line}: expected {len(CSV_COLUMNS)} values with feasible Y or N, "
                             f"got {values}")
        removed, scenario, mark, reason, time_s, status, primitives = values
        try:
            seconds = float(time_s)
        except ValueError:
            raise InputError(f"{path}:{line}: time_s: not a number: {time_s!r}") from None
        cells.append(AblationCell(removed, scenario, "", mark == "Y", status, reason, seconds,
                                  tuple(primitives.split())))
    return tuple(cells)


def write_csv(table: AblationTable, path: str | os.PathLike[str]) -> Path:
    """Write :func:`format_csv` to ``path`` atomically."""
    return _write_cells(path, (cell for row in table.rows for cell in row.cells))
