"""The benchmark harness: ``ldhp-tamp bench``.

Every combination scenario x planner x engine x K (samples per edge) x seed is one *run*:
one call of the planner (:mod:`ldhp_tamp.planners`; ``ldhp`` is :func:`ldhp_tamp.tamp.solve`)
in a worker process of its own. Every planner's plan is judged the same way: the
validator decides ``solved`` for an external planner (``cmd:``), and every solved plan is
replayed in the physics simulation (``executes``) and measured (:mod:`ldhp_tamp.metrics`). Data flows through plain
functions over small values::

    runs = plan_runs(["scenarios/example_pick.toml"], BenchOptions(seeds=2, jobs=2))
    rows = run_all(runs, options)                  # BenchRow per run, in the order of runs
    files = write_results(rows, out_dir, options)  # runs.csv, runs.json, summary.md

or all three at once with :func:`run_bench`.

Isolation and time limits. Each run is a process of its own, in a process group of its
own, through :func:`ldhp_tamp.sweep.run_cells`: ``executor`` ``local`` (at most ``jobs``
processes forked from a forkserver that has imported the planner once) or ``dask`` (one
Dask task per run, on a ``LocalCluster`` of ``jobs`` workers or on ``scheduler``). A run
that crashes, or raises, or whose Dask worker dies, is an ``error`` row; the others carry
on. With ``timeout_s`` the run's solve gets ``SolveOptions(timeout=...)`` when the planner
has that option, and ``timeout_s + grace_s`` is a hard limit: the run's whole process
group (Fast Downward's planner process included) is terminated, and the run is a
``timeout`` row. Fast Downward writes files into its working directory;
:func:`ldhp_tamp.symbolic.solve` runs every engine call in a fresh ``tempfile``
directory, and a process's working directory is its own, so parallel runs never share one.

Resuming. ``run_bench(..., resume=True)`` (the CLI's default) keeps the rows of an
existing ``out_dir/runs.json`` whose status is final (``solved``, ``failed``,
``timeout``) and runs only the others; the file must come from a bench with the same
time limit and simulation setting (:func:`read_rows`).

Times. ``time_*_s`` are the solve's own wall time per tier (the plan's ``stats.time_s``);
``wall_s`` is the parent's wall time for the run, process start-up included. The summary
reports ``time_total_s`` over solved runs. With ``jobs`` > 1 the runs share the CPUs:
compare times taken with the same ``jobs`` only.
"""

from __future__ import annotations

import csv
import dataclasses
import enum
import io
import json
import logging
import math
import os
import platform
import re
import statistics
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ldhp_tamp.errors import EngineError, InputError
from ldhp_tamp.files import write_text_atomic
from ldhp_tamp.sweep import CellFailure, CellTask, SweepOptions, check_executor, run_cells

__all__ = [
    "BENCH_FORMAT",
    "BenchFiles",
    "BenchOptions",
    "BenchRow",
    "BenchStatus",
    "RunSpec",
    "COLUMNS",
    "format_csv",
    "format_json",
    "format_summary",
    "plan_runs",
    "read_rows",
    "run_all",
    "run_bench",
    "solve_run",
    "quartiles",
    "solver_has_timeout",
    "wilson_interval",
    "write_results",
]

log = logging.getLogger(__name__)

BENCH_FORMAT = "ldhp-bench/1"
CSV_NAME = "runs.csv"
JSON_NAME = "runs.json"
SUMMARY_NAME = "summary.md"

#: Seconds a terminated worker gets to clean up (SIGTERM) before it is killed (SIGKILL).
_TERM_WAIT_S = 2.0
#: Seconds to wait for a worker to exit after it has sent its row.
_EXIT_WAIT_S = 10.0


class BenchStatus(enum.Enum):
    SOLVED = "solved"
    FAILED = "failed"
    TIMEOUT = "timeout"
    ERROR = "error"


@dataclass(frozen=True)
class BenchOptions:
    """What to run and how. ``engines=None``: each scenario's own engine;
    ``samples=None``: each scenario's own K (``[planner] samples_per_edge``).

    Raises
    ------
    InputError
        On a value out of range (the message names the option).
    """

    engines: tuple[str, ...] | None = None
    planners: tuple[str, ...] = ("ldhp",)
    """Planner names (:func:`ldhp_tamp.planners.get_planner`), checked by :func:`plan_runs`."""
    seeds: int = 1
    samples: tuple[int, ...] | None = None
    timeout_s: float | None = None
    grace_s: float = 10.0
    jobs: int = 1
    simulate: bool = True
    """Replay every solved plan in the physics simulation (:mod:`ldhp_tamp.simulate`):
    the ``executes`` column."""
    judge_simulate: bool = False
    """Solve with the simulation judge (``SolveOptions(simulate=True)``, ``solve
    --simulate``): a plan that diverges is fed back and the search goes on, so a solved
    plan executes. The planners that take no such option ignore it."""
    executor: str = "local"
    """Where the runs go: ``local`` processes or ``dask`` (:mod:`ldhp_tamp.sweep`)."""
    scheduler: str | None = None
    """``dask``: a running scheduler, ``tcp://HOST:PORT``; ``None``: a ``LocalCluster``
    of ``jobs`` workers."""
    prior: str | None = None
    """A transition prior file (:mod:`ldhp_tamp.prior`) every solve is given, or ``None``."""
    keep_plans: bool = False
    """Write every run's plan (solved or failed) to ``OUT/plans/`` (:data:`PLANS_DIR`):
    what ``ldhp-tamp prior`` fits a prior from."""

    def __post_init__(self) -> None:
        check_executor(self.executor, self.scheduler)
        if self.engines is not None:
            object.__setattr__(self, "engines", tuple(self.engines))
            if not self.engines:
                raise InputError("--engines: give at least one engine")
        object.__setattr__(self, "planners", tuple(self.planners))
        if not self.planners:
            raise InputError("--planners: give at least one planner")
        if self.samples is not None:
            object.__setattr__(self, "samples", tuple(self.samples))
            if not self.samples or any(isinstance(k, bool) or not isinstance(k, int) or k < 1
                                       for k in self.samples):
                raise InputError(f"--samples: samples per edge must be integers >= 1, got {self.samples}")
        if self.seeds < 1:
            raise InputError(f"--seeds: need at least 1 seed, got {self.seeds}")
        if self.jobs < 1:
            raise InputError(f"--jobs: need at least 1 worker, got {self.jobs}")
        if self.timeout_s is not None and not (math.isfinite(self.timeout_s) and self.timeout_s > 0):
            raise InputError(f"--timeout: must be a positive number of seconds, got {self.timeout_s}")
        if not (math.isfinite(self.grace_s) and self.grace_s >= 0):
            raise InputError(f"--grace: must be >= 0 seconds, got {self.grace_s}")
        if self.prior is not None:  # read now: a bad file stops the bench before any run
            from ldhp_tamp.prior import read_prior

            read_prior(self.prior)
            object.__setattr__(self, "prior", str(Path(self.prior).resolve()))

    @property
    def hard_limit_s(self) -> float | None:
        """The parent's limit per run: ``timeout_s + grace_s``, or none."""
        return None if self.timeout_s is None else self.timeout_s + self.grace_s


@dataclass(frozen=True)
class RunSpec:
    """One run: what the worker needs (picklable, no heavy objects).

    ``plan_file``: where the worker writes the run's plan (solved or failed) with
    :func:`ldhp_tamp.plan.write_plan`; ``None`` (what :func:`plan_runs` makes) keeps no
    plan. A run stopped at the hard limit, or one that raises, writes none.
    """

    index: int
    scenario_file: str
    scenario: str
    engine: str
    seed: int
    samples_per_edge: int
    object_vertices: int
    timeout_s: float | None = None
    plan_file: str | None = None
    simulate: bool = True
    planner: str = "ldhp"
    judge_simulate: bool = False
    prior_file: str | None = None


@dataclass(frozen=True)
class BenchRow:
    """One run's outcome: a row of ``runs.csv`` and of ``runs.json``'s ``rows``.

    Counts and times are ``None`` when the run produced no plan (``timeout``, ``error``);
    the plan's measures (:mod:`ldhp_tamp.metrics`: ``regrasps``, ``finger_travel_mm``,
    ``object_path_mm``, ``object_rotation_rad``, ``support_margin``) only for solved runs.
    """

    scenario: str
    scenario_file: str
    engine: str
    seed: int
    samples_per_edge: int
    object_vertices: int
    status: BenchStatus
    reason: str
    wall_s: float
    time_total_s: float | None = None
    time_setup_s: float | None = None
    time_symbolic_s: float | None = None
    time_streams_s: float | None = None
    time_grasp_graph_s: float | None = None
    steps: int | None = None
    waypoints: int | None = None
    feasibility_checks: int | None = None
    contact_state_nodes: int | None = None
    grasp_graph_nodes: int | None = None
    grasp_graph_edges: int | None = None
    top_iterations: int | None = None
    refinements: int | None = None
    executes: bool | None = None
    """Solved plans: whether the plan executes in the physics simulation (``None``: not
    simulated)."""
    diverges_at: int | None = None
    sim_wall_s: float | None = None
    planner: str = "ldhp"
    regrasps: int | None = None
    finger_travel_mm: float | None = None
    object_path_mm: float | None = None
    object_rotation_rad: float | None = None
    support_margin: float | None = None

    def as_dict(self) -> dict[str, Any]:
        """Plain values, in column order (the status as its string)."""
        d = dataclasses.asdict(self)
        d["status"] = self.status.value
        return {c: d[c] for c in COLUMNS}


def _columns() -> tuple[str, ...]:
    names = [f.name for f in dataclasses.fields(BenchRow)]
    names.remove("planner")
    names.insert(names.index("scenario_file") + 1, "planner")
    return tuple(names)


#: The CSV header, in column order (``planner`` after ``scenario_file``).
COLUMNS: tuple[str, ...] = _columns()


@dataclass(frozen=True)
class BenchFiles:
    """The files :func:`write_results` wrote."""

    csv: Path
    json: Path
    summary: Path


# --------------------------------------------------------------------------- runs


def solver_has_timeout() -> bool:
    """Whether :class:`ldhp_tamp.tamp.SolveOptions` has a ``timeout`` field (seconds)."""
    from ldhp_tamp.tamp import SolveOptions

    return "timeout" in {f.name for f in dataclasses.fields(SolveOptions)}


def plan_runs(scenarios: Sequence[str | os.PathLike[str]], options: BenchOptions) -> tuple[RunSpec, ...]:
    """Load and check every scenario, planner and engine, then list the runs: scenario x
    planner x engine x K x seed (seeds ``0 .. seeds-1``), in that order. A planner without
    a symbolic tier (:func:`ldhp_tamp.planners.uses_engine`) runs once per K and seed,
    with the engine column empty.

    Raises
    ------
    InputError
        A scenario that cannot be loaded (the message names the file), an unknown planner
        (the message lists the known ones), an engine that is not installed (the message
        lists the installed ones), no scenario at all.
    """
    from ldhp_tamp.planners import get_planner, uses_engine
    from ldhp_tamp.scenario import load_scenario
    from ldhp_tamp.symbolic import available_engines

    if not scenarios:
        raise InputError("no scenario given")
    for name in options.planners:
        get_planner(name)
    loaded = [(Path(p), load_scenario(p)) for p in scenarios]
    installed = available_engines()
    wanted = options.engines or tuple(dict.fromkeys(s.settings.engine for _, s in loaded))
    unknown = [e for e in wanted if e not in installed]
    if unknown:
        raise EngineError(f"unknown planning engine {unknown[0]!r}; installed: {', '.join(installed)}")
    specs: list[RunSpec] = []
    for path, sc in loaded:
        ks = options.samples or (sc.settings.samples_per_edge,)
        for planner in options.planners:
            engines = (options.engines or (sc.settings.engine,)) if uses_engine(planner) else ("",)
            for engine in engines:
                for k in ks:
                    for seed in range(options.seeds):
                        specs.append(RunSpec(index=len(specs), scenario_file=str(path), scenario=sc.name,
                                             engine=engine, seed=seed, samples_per_edge=k,
                                             object_vertices=sc.world.object.n, timeout_s=options.timeout_s,
                                             simulate=options.simulate, planner=planner,
                                             judge_simulate=options.judge_simulate, prior_file=options.prior))
    return tuple(specs)


#: The folder of ``OUT`` that ``--plans`` writes the runs' plans into.
PLANS_DIR = "plans"


def plan_name(spec: RunSpec) -> str:
    """The file name of a run's plan under ``OUT/plans/``: scenario, planner, engine, K
    and seed (characters other than letters, digits, ``.``, ``_`` and ``-`` as ``_``)."""
    stem = "-".join([spec.scenario, spec.planner] + ([spec.engine] if spec.engine else [])
                    + [f"K{spec.samples_per_edge}", f"s{spec.seed}"])
    return re.sub(r"[^A-Za-z0-9._-]", "_", stem) + "-plan.json"


def _row(spec: RunSpec, status: BenchStatus, reason: str, wall_s: float, **counts: Any) -> BenchRow:
    return BenchRow(scenario=spec.scenario, scenario_file=spec.scenario_file, planner=spec.planner,
                    engine=spec.engine,
                    seed=spec.seed, samples_per_edge=spec.samples_per_edge,
                    object_vertices=spec.object_vertices, status=status, reason=reason,
                    wall_s=round(wall_s, 4), **counts)


def solve_run(spec: RunSpec) -> BenchRow:
    """Run one solve (``spec.planner``) in this process and describe it as a row; write
    its plan to ``spec.plan_file`` when that is set.

    Raises whatever the planner raises (the worker turns it into an ``error`` row).
    """
    from ldhp_tamp.planners import get_planner
    from ldhp_tamp.scenario import load_scenario
    from ldhp_tamp.tamp import SolveOptions

    start = time.perf_counter()
    scenario = load_scenario(spec.scenario_file)
    knobs: dict[str, Any] = {"engine": spec.engine or None, "seed": spec.seed,
                             "samples_per_edge": spec.samples_per_edge, "simulate": spec.judge_simulate}
    if spec.timeout_s is not None and solver_has_timeout():
        knobs["timeout"] = spec.timeout_s
    if spec.prior_file is not None:
        from ldhp_tamp.prior import read_prior

        knobs["prior"] = read_prior(spec.prior_file)
    result = get_planner(spec.planner)(scenario, SolveOptions(**knobs))
    plan = result.plan
    if spec.plan_file is not None:
        from ldhp_tamp.plan import write_plan

        write_plan(plan, spec.plan_file)
    stats = plan.stats
    times = stats.time_s
    status = _status(result.status.value, times.get("total"), spec.timeout_s)
    sim: dict[str, Any] = {}
    if spec.simulate and result.solved:
        from ldhp_tamp.simulate import simulate_plan

        t0 = time.perf_counter()
        report = simulate_plan(plan, scenario)
        sim = {"executes": report.executes, "diverges_at": report.diverged_step,
               "sim_wall_s": round(time.perf_counter() - t0, 4)}
    measures: dict[str, Any] = {}
    if result.solved:
        from ldhp_tamp.metrics import plan_metrics

        m = plan_metrics(plan, scenario)
        measures = {"regrasps": m.regrasps, "finger_travel_mm": m.finger_travel_mm,
                    "object_path_mm": m.object_path_mm, "object_rotation_rad": m.object_rotation_rad,
                    "support_margin": m.support_margin}
    return _row(spec, status, result.reason or (plan.reason or ""), time.perf_counter() - start, **sim, **measures,
                time_total_s=times.get("total"), time_setup_s=times.get("setup"),
                time_symbolic_s=times.get("symbolic"), time_streams_s=times.get("streams"),
                time_grasp_graph_s=times.get("grasp_graph"),
                steps=len(plan.steps), waypoints=sum(len(s.waypoints) for s in plan.steps),
                feasibility_checks=stats.feasibility_checks, contact_state_nodes=stats.contact_state_nodes,
                grasp_graph_nodes=stats.grasp_graph_nodes, grasp_graph_edges=stats.grasp_graph_edges,
                top_iterations=stats.top_iterations, refinements=stats.refinements)


def _status(solve_status: str, total_s: float | None, timeout_s: float | None) -> BenchStatus:
    """The row status of a solve that returned: its own (``solved``, ``failed``, or
    ``timeout`` if the planner has one); a failure at or past the time limit is a
    ``timeout`` (the planner gave up on its time budget, or would have been stopped)."""
    values = {s.value for s in BenchStatus}
    status = BenchStatus(solve_status) if solve_status in values else BenchStatus.FAILED
    if status is BenchStatus.FAILED and timeout_s is not None and total_s is not None and total_s >= timeout_s:
        return BenchStatus.TIMEOUT
    return status


def _failed_row(spec: RunSpec, failure: CellFailure, reason: str, wall_s: float) -> BenchRow:
    """The row of a run whose process raised or died (``error``) or passed the hard limit
    (``timeout``)."""
    return _row(spec, BenchStatus(failure.value), reason, wall_s)


def _with_wall(row: BenchRow, wall_s: float) -> BenchRow:
    """The row with the executor's wall time for the run (process start-up included)."""
    return dataclasses.replace(row, wall_s=round(wall_s, 4))


#: A bench run for :func:`ldhp_tamp.sweep.run_cells`: :func:`solve_run` in a process of its own.
_TASK: CellTask[RunSpec, BenchRow] = CellTask(run=solve_run, failed=_failed_row, with_wall=_with_wall,
                                              preload=("ldhp_tamp.bench", "ldhp_tamp.solver_preload"), name="bench")


def run_all(specs: Sequence[RunSpec], options: BenchOptions,
            on_row: Callable[[int, BenchRow], None] | None = None) -> tuple[BenchRow, ...]:
    """Run every spec, each in a process of its own under the hard limit, with
    ``options.executor`` (:func:`ldhp_tamp.sweep.run_cells`: at most ``options.jobs``
    local processes, or one Dask task per run).

    ``on_row(done, row)`` is called as each run ends (``done`` counts finished runs). The
    rows come back in the order of ``specs``. On an exception (Ctrl-C) the running
    runs are stopped before it propagates.
    """
    sweep = SweepOptions(executor=options.executor, jobs=options.jobs, scheduler=options.scheduler,
                         hard_limit_s=options.hard_limit_s)
    done = 0

    def on_result(_position: int, row: BenchRow) -> None:
        nonlocal done
        done += 1
        if on_row is not None:
            on_row(done, row)

    return tuple(run_cells(specs, _TASK, sweep, on_result))


# --------------------------------------------------------------------------- outputs


def _csv_value(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, enum.Enum):
        return str(value.value)
    if isinstance(value, float):
        return f"{value:.4f}"
    return str(value)


def format_csv(rows: Iterable[BenchRow]) -> str:
    """``runs.csv``: a header of :data:`COLUMNS`, one line per run; empty cells for ``None``."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in rows:
        writer.writerow([_csv_value(getattr(row, c)) for c in COLUMNS])
    return buf.getvalue()


def _host() -> dict[str, Any]:
    from importlib.metadata import PackageNotFoundError, version

    try:
        ours = version("ldhp-tamp")
    except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        ours = None
    return {"python": platform.python_version(), "platform": platform.platform(),
            "cpus": os.cpu_count(), "ldhp_tamp": ours}


def format_json(rows: Sequence[BenchRow], options: BenchOptions, created: str | None = None) -> str:
    """``runs.json``: ``format``, ``created``, the options, the host and the rows."""
    doc = {
        "format": BENCH_FORMAT,
        "created": created or datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "options": {"planners": list(options.planners),
                    "engines": list(options.engines) if options.engines else None, "seeds": options.seeds,
                    "samples_per_edge": list(options.samples) if options.samples else None,
                    "timeout_s": options.timeout_s, "grace_s": options.grace_s,
                    "hard_limit_s": options.hard_limit_s, "jobs": options.jobs, "simulate": options.simulate,
                    "executor": options.executor, "scheduler": options.scheduler,
                    "prior": options.prior, "keep_plans": options.keep_plans,
                    "solver_timeout": options.timeout_s is not None and solver_has_timeout()},
        "host": _host(),
        "columns": list(COLUMNS),
        "rows": [r.as_dict() for r in rows],
    }
    return json.dumps(doc, indent=2) + "\n"


def _num(x: float | None, digits: int = 2) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


#: z of the two-sided 95 % interval.
_Z95 = 1.959963984540054


def wilson_interval(successes: int, n: int, z: float = _Z95) -> tuple[float, float]:
    """The Wilson score interval of a success rate (95 % by default), as fractions.

    >>> lo, hi = wilson_interval(5, 5)
    >>> round(lo, 3), hi
    (0.566, 1.0)
    >>> wilson_interval(0, 0)
    (0.0, 1.0)
    """
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def quartiles(values: Sequence[float]) -> tuple[float, float, float] | None:
    """First quartile, median, third quartile (inclusive method), or ``None`` for no value."""
    if not values:
        return None
    if len(values) == 1:
        return values[0], values[0], values[0]
    q1, q2, q3 = statistics.quantiles(values, n=4, method="inclusive")
    return q1, q2, q3


def _median(values: Sequence[float | int | None], digits: int = 1) -> str:
    vals = [v for v in values if v is not None]
    return _num(statistics.median(vals) if vals else None, digits)


def _group_key(r: BenchRow) -> tuple[str, str, str, int]:
    return (r.scenario, r.planner, r.engine, r.samples_per_edge)


def format_summary(rows: Sequence[BenchRow], options: BenchOptions) -> str:
    """``summary.md``: per scenario, planner, engine and K, the success rate with its 95 %
    Wilson interval over the seeds, how many solved plans execute in simulation, the
    solve time's median and quartiles over solved runs, the median measures of the
    solved plans (steps, regrasps, finger travel, object path, support margin), the
    median time per tier, and the reason of every run that was not solved."""
    groups: dict[tuple[str, str, str, int], list[BenchRow]] = {}
    for r in rows:
        groups.setdefault(_group_key(r), []).append(r)
    limit = ("none" if options.timeout_s is None else
             f"{options.timeout_s:g} s (hard limit {options.hard_limit_s:g} s; passed to the solver: "
             f"{'yes' if solver_has_timeout() else 'no, the planner has no timeout option'})")
    lines = [
        "# Benchmark summary", "",
        f"{len(rows)} runs, {options.jobs} at a time; timeout: {limit}.",
        "Success: solved runs over runs (seeds), with the 95 % Wilson interval. Times are the solver's own "
        "wall time (`stats.time_s` of the plan, worker start-up excluded), over solved runs: median "
        "[first quartile, third quartile]; with more than one job at a time runs share the CPUs.", "",
        "| scenario | planner | engine | K | runs | solved | success (95 % CI) | executes in simulation "
        "| timeout | error | time (s), median [Q1, Q3] | max time (s) |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    measure_lines = [
        "", "## Plans, medians over solved runs", "",
        "Regrasps: AdjustGrasp steps that change the grasp while the object is held; finger travel: "
        "the gripper's path (mm); object path: mm travelled and degrees turned; support margin: the "
        "plan's smallest (`stats.support_margin`). See docs/benchmarks.md.", "",
        "| scenario | planner | engine | K | steps | regrasps | finger travel (mm) | object path (mm) "
        "| object turn (deg) | support margin |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    tiers = ("setup", "symbolic", "streams", "grasp_graph")
    tier_lines = [
        "", "## Median time per tier, solved runs (s)", "",
        "| scenario | planner | engine | K | " + " | ".join(tiers) + " | total |",
        "| --- | --- | --- | ---: |" + " ---: |" * (len(tiers) + 1),
    ]
    for (scenario, planner, engine, k), rs in groups.items():
        head = f"| {scenario} | {planner} | {engine or '-'} | {k} "
        ok = [r for r in rs if r.status is BenchStatus.SOLVED]
        times = [r.time_total_s for r in ok if r.time_total_s is not None]
        count = {st: sum(r.status is st for r in rs) for st in BenchStatus}
        simulated = [r for r in ok if r.executes is not None]
        executes = f"{sum(bool(r.executes) for r in simulated)}/{len(simulated)}" if simulated else "-"
        lo, hi = wilson_interval(len(ok), len(rs))
        q = quartiles(times)
        time_cell = "-" if q is None else f"{q[1]:.2f} [{q[0]:.2f}, {q[2]:.2f}]"
        lines.append(
            head + f"| {len(rs)} | {len(ok)} | {100 * len(ok) / len(rs):.0f}% ({100 * lo:.0f}-{100 * hi:.0f}%) "
            f"| {executes} | {count[BenchStatus.TIMEOUT]} | {count[BenchStatus.ERROR]} "
            f"| {time_cell} | {_num(max(times) if times else None)} |")
        turn = [None if r.object_rotation_rad is None else math.degrees(r.object_rotation_rad) for r in ok]
        measure_lines.append(
            head + f"| {_median([r.steps for r in ok])} | {_median([r.regrasps for r in ok])} "
            f"| {_median([r.finger_travel_mm for r in ok], 0)} | {_median([r.object_path_mm for r in ok], 0)} "
            f"| {_median(turn, 0)} | {_median([r.support_margin for r in ok], 3)} |")
        medians = []
        for t in (*tiers, "total"):
            vals = [v for r in ok if (v := getattr(r, f"time_{t}_s")) is not None]
            medians.append(_num(statistics.median(vals) if vals else None))
        tier_lines.append(head + "| " + " | ".join(medians) + " |")
    lines += measure_lines + tier_lines
    unsolved = [r for r in rows if r.status is not BenchStatus.SOLVED]
    if unsolved:
        lines += ["", "## Runs not solved", ""]
        for r in unsolved:
            reason = " ".join(r.reason.split())
            if len(reason) > 300:
                reason = reason[:297] + "..."
            engine = f", {r.engine}" if r.engine else ""
            lines.append(f"- {r.scenario}, {r.planner}{engine}, K {r.samples_per_edge}, seed {r.seed}: "
                         f"**{r.status.value}**: {reason}")
    return "\n".join(lines) + "\n"


def write_results(rows: Sequence[BenchRow], out_dir: str | os.PathLike[str], options: BenchOptions,
                  summary: bool = True) -> BenchFiles:
    """Write ``runs.csv``, ``runs.json`` and (``summary``) ``summary.md`` into ``out_dir``,
    each atomically."""
    out = _out_dir(out_dir)
    files = BenchFiles(out / CSV_NAME, out / JSON_NAME, out / SUMMARY_NAME)
    write_text_atomic(files.csv, format_csv(rows))
    write_text_atomic(files.json, format_json(rows, options))
    if summary:
        write_text_atomic(files.summary, format_summary(rows, options))
    return files


def _out_dir(out_dir: str | os.PathLike[str]) -> Path:
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise InputError(f"{out}: --out must be a directory, and this is a file") from None
    except OSError as exc:
        raise InputError(f"{out}: cannot create the output directory: {exc.strerror or exc}") from None
    return out


#: Statuses a resumed bench keeps; an ``error`` run (a crash, a lost worker) runs again.
FINAL_STATUSES = frozenset({BenchStatus.SOLVED, BenchStatus.FAILED, BenchStatus.TIMEOUT})
#: Options whose change makes the stored rows of another configuration.
_RESUME_OPTIONS = ("timeout_s", "grace_s", "simulate", "prior")


def _run_key(values: Callable[[str], Any]) -> tuple[Any, ...]:
    """What identifies a run: every knob of :class:`RunSpec` that is also a column."""
    return tuple(values(name) for name in _KEY_FIELDS)


_KEY_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(RunSpec) if f.name in COLUMNS)


def read_rows(path: str | os.PathLike[str], options: BenchOptions) -> tuple[BenchRow, ...]:
    """The rows of a ``runs.json`` written by a bench of the same configuration.

    Raises
    ------
    InputError
        A file that cannot be read or is not ``ldhp-bench/1`` with this version's columns,
        or whose runs were made with another time limit, simulation setting or prior (the
        message names the file and the option).
    """
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: cannot resume from it: {exc}; use --fresh or another --out") from None
    if not isinstance(doc, dict) or doc.get("format") != BENCH_FORMAT or doc.get("columns") != list(COLUMNS):
        raise InputError(f"{path}: cannot resume from it: not {BENCH_FORMAT} with this version's columns; "
                         f"use --fresh or another --out")
    stored = doc.get("options") or {}
    for name in _RESUME_OPTIONS:
        if stored.get(name) != getattr(options, name):
            raise InputError(f"{path}: cannot resume from it: its runs were made with {name} = "
                             f"{stored.get(name)!r}, this bench has {getattr(options, name)!r}; use --fresh "
                             f"or another --out")
    try:
        return tuple(BenchRow(**{**r, "status": BenchStatus(r["status"])}) for r in doc.get("rows", []))
    except (TypeError, KeyError, ValueError) as exc:
        raise InputError(f"{path}: cannot resume from it: a malformed row ({exc}); use --fresh or "
                         f"another --out") from None


def _resumed(specs: Sequence[RunSpec], out_dir: str | os.PathLike[str],
             options: BenchOptions) -> dict[int, BenchRow]:
    """The stored rows of ``out_dir/runs.json`` with a final status, by the index of the
    spec they stand for."""
    path = Path(out_dir) / JSON_NAME
    if not path.exists():
        return {}
    by_key = {_run_key(lambda n, r=r: getattr(r, n)): r for r in read_rows(path, options)
              if r.status in FINAL_STATUSES}
    return {s.index: row for s in specs if (row := by_key.get(_run_key(lambda n, s=s: getattr(s, n)))) is not None}


def run_bench(scenarios: Sequence[str | os.PathLike[str]], options: BenchOptions,
              out_dir: str | os.PathLike[str],
              progress: Callable[[str], None] | None = None,
              resume: bool = False) -> tuple[tuple[BenchRow, ...], BenchFiles]:
    """Check the input, run every combination, write the results.

    ``runs.csv`` and ``runs.json`` are rewritten as each run ends (so an interrupted bench
    keeps what it measured), ``summary.md`` once at the end. With ``resume``, the runs
    already in ``out_dir/runs.json`` with a final status are not run again (their rows
    are kept as they are); the others run.

    Raises
    ------
    InputError
        Before anything runs: a scenario that cannot be loaded, an unknown engine, an
        output directory that cannot be created, a ``runs.json`` to resume from that
        does not match (:func:`read_rows`).
    ExecutorError
        ``dask`` without the ``distributed`` package, or a scheduler that cannot be
        reached.
    """
    all_specs = plan_runs(scenarios, options)
    _out_dir(out_dir)
    if options.keep_plans:
        plans = Path(out_dir) / PLANS_DIR
        try:
            plans.mkdir(exist_ok=True)
        except OSError as exc:
            raise InputError(f"{plans}: --plans: cannot create the directory: {exc.strerror or exc}") from None
        all_specs = tuple(dataclasses.replace(s, plan_file=str(plans / plan_name(s))) for s in all_specs)
    kept = _resumed(all_specs, out_dir, options) if resume else {}
    specs = tuple(s for s in all_specs if s.index not in kept)  # the runs to make
    say = progress or (lambda _msg: None)
    where = "local" if options.executor == "local" else f"dask, {options.scheduler or 'a LocalCluster'}"
    say(f"{len(all_specs)} runs"
        + (f" ({len(kept)} already in {Path(out_dir) / JSON_NAME}, {len(specs)} to run)" if kept else "")
        + (f", {options.jobs} at a time" if options.scheduler is None else "") + f" ({where})"
        + (f", hard limit {options.hard_limit_s:g} s per run" if options.hard_limit_s is not None else ""))
    finished: list[BenchRow] = list(kept.values())  # in the order runs end

    def on_row(done: int, row: BenchRow) -> None:
        finished.append(row)
        t = f"{row.time_total_s:.2f} s" if row.time_total_s is not None else f"{row.wall_s:.2f} s wall"
        say(f"[{done}/{len(specs)}] {row.scenario} {row.planner}{' ' + row.engine if row.engine else ''} K={row.samples_per_edge} "
            f"seed={row.seed}: {row.status.value} ({t})")
        write_results(finished, out_dir, options, summary=False)

    new = dict(zip((s.index for s in specs), run_all(specs, options, on_row)))
    rows = tuple(kept.get(s.index) or new[s.index] for s in all_specs)
    files = write_results(rows, out_dir, options)
    return rows, files
