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

Isolation and time limits. Each run gets a fresh process (forked from a forkserver that
has imported the planner once, so a run costs no import time) in a process group of its
own; at most ``jobs`` run at once. A run that crashes, or raises, is an ``error`` row; the
others carry on. With ``timeout_s`` the run's solve gets ``SolveOptions(timeout=...)``
when the planner has that option, and the parent enforces ``timeout_s + grace_s`` as a
hard limit by terminating the whole process group (Fast Downward's planner process
included): that run is a ``timeout`` row. Fast Downward writes files into its working
directory; :func:`ldhp_tamp.symbolic.solve` runs every engine call in a fresh
``tempfile`` directory, and a process's working directory is its own, so parallel runs
never share one.

Why not :class:`concurrent.futures.ProcessPoolExecutor`: it cannot stop one task. Killing
a pool worker breaks the pool (``BrokenProcessPool`` fails every pending future), and a
task that hangs holds its worker forever. The scheduler here is the same idea (``jobs``
workers, results collected as they come) with one process per run, which it can kill.

Times. ``time_*_s`` are the solve's own wall time per tier (the plan's ``stats.time_s``);
``wall_s`` is the parent's wall time for the run, process start-up included. The summary
reports ``time_total_s`` over solved runs. With ``jobs`` > 1 the runs share the CPUs:
compare times taken with the same ``jobs`` only.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import enum
import io
import json
import logging
import math
import multiprocessing
import multiprocessing.connection
import os
import platform
import signal
import statistics
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ldhp_tamp.errors import EngineError, InputError
from ldhp_tamp.files import write_text_atomic

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

    def __post_init__(self) -> None:
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
                                             simulate=options.simulate, planner=planner))
    return tuple(specs)


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
                             "samples_per_edge": spec.samples_per_edge}
    if spec.timeout_s is not None and solver_has_timeout():
        knobs["timeout"] = spec.timeout_s
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


def _on_sigterm(signum: int, _frame: Any) -> None:
    raise SystemExit(128 + signum)  # unwinds: temporary directories are removed


def _worker(spec: RunSpec, conn: multiprocessing.connection.Connection) -> None:
    """Body of a worker process: one run, one row sent back through ``conn``."""
    os.setpgid(0, 0)  # a process group of its own: the parent stops the engine's children too
    signal.signal(signal.SIGTERM, _on_sigterm)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    start = time.perf_counter()
    try:
        row = solve_run(spec)
    except Exception as exc:  # any failure of one run is a row, not a crash of the bench
        last = traceback.extract_tb(exc.__traceback__)[-1:]
        where = f" (at {Path(last[0].filename).name}:{last[0].lineno})" if last else ""
        row = _row(spec, BenchStatus.ERROR, f"{type(exc).__name__}: {exc}{where}", time.perf_counter() - start)
    conn.send(row)
    conn.close()


@dataclass
class _Active:
    spec: RunSpec
    process: multiprocessing.process.BaseProcess
    conn: multiprocessing.connection.Connection
    start: float
    deadline: float | None


def _context() -> multiprocessing.context.BaseContext:
    """A forkserver that has imported the planner (a fork then costs no import time);
    ``spawn`` where there is no forkserver."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["ldhp_tamp.bench", "ldhp_tamp.tamp"])
        return ctx
    return multiprocessing.get_context("spawn")


def _start(ctx: multiprocessing.context.BaseContext, spec: RunSpec, hard_limit_s: float | None) -> _Active:
    reader, writer = ctx.Pipe(duplex=False)
    process = ctx.Process(target=_worker, args=(spec, writer), name=f"ldhp-bench-{spec.index}")
    process.start()  # the first start waits for the forkserver's imports: not the run's time
    start = time.monotonic()
    writer.close()  # the worker holds the only write end: EOF when it dies
    deadline = None if hard_limit_s is None else start + hard_limit_s
    return _Active(spec, process, reader, start, deadline)


def _stop(active: _Active) -> None:
    """Terminate a worker and its process group: SIGTERM, then SIGKILL."""
    proc = active.process
    pid = proc.pid
    for sig, wait_s in ((signal.SIGTERM, _TERM_WAIT_S), (signal.SIGKILL, _EXIT_WAIT_S)):
        if pid is None:
            break
        try:
            os.killpg(pid, sig)
        except (ProcessLookupError, PermissionError):
            # the worker has not made its group yet (or is gone): signal it alone
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, sig)
        proc.join(wait_s)
        if proc.exitcode is not None:
            # the group may outlive its leader (an engine's planner process)
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(pid, signal.SIGKILL)
            break
    active.conn.close()


def _collect(active: _Active) -> BenchRow:
    """The row of a worker whose pipe is readable: its row, or an error if it died."""
    wall = time.monotonic() - active.start
    try:
        row: BenchRow | None = active.conn.recv()
    except (EOFError, OSError):
        row = None
    active.process.join(_EXIT_WAIT_S)
    if active.process.exitcode is None:
        log.warning("run %d: the worker did not exit after its result; stopping it", active.spec.index)
        _stop(active)
    active.conn.close()
    if row is None:
        code = active.process.exitcode
        how = f"killed by signal {-code}" if code is not None and code < 0 else f"exit status {code}"
        return _row(active.spec, BenchStatus.ERROR, f"the worker process died without a result ({how})", wall)
    return dataclasses.replace(row, wall_s=round(wall, 4))


def run_all(specs: Sequence[RunSpec], options: BenchOptions,
            on_row: Callable[[int, BenchRow], None] | None = None) -> tuple[BenchRow, ...]:
    """Run every spec, at most ``options.jobs`` at once, each in its own process.

    ``on_row(done, row)`` is called as each run ends (``done`` counts finished runs). The
    rows come back in the order of ``specs``. On an exception (Ctrl-C) the running
    workers are stopped before it propagates.
    """
    ctx = _context()
    pending = deque(specs)
    active: list[_Active] = []
    rows: dict[int, BenchRow] = {}
    hard = options.hard_limit_s
    try:
        while pending or active:
            while pending and len(active) < options.jobs:
                active.append(_start(ctx, pending.popleft(), hard))
            deadlines = [a.deadline for a in active if a.deadline is not None]
            wait_s = max(0.0, min(deadlines) - time.monotonic()) if deadlines else None
            ready = multiprocessing.connection.wait([a.conn for a in active], timeout=wait_s)
            now = time.monotonic()
            for a in list(active):
                if a.conn in ready:
                    row = _collect(a)
                elif a.deadline is not None and now >= a.deadline:
                    _stop(a)
                    row = _row(a.spec, BenchStatus.TIMEOUT,
                               f"hard limit: no result after {hard:g} s (timeout {options.timeout_s:g} s "
                               f"+ grace {options.grace_s:g} s); the worker was terminated", now - a.start)
                else:
                    continue
                active.remove(a)
                rows[a.spec.index] = row
                if on_row is not None:
                    on_row(len(rows), row)
    finally:
        for a in active:
            _stop(a)
    return tuple(rows[s.index] for s in specs)


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


def run_bench(scenarios: Sequence[str | os.PathLike[str]], options: BenchOptions,
              out_dir: str | os.PathLike[str],
              progress: Callable[[str], None] | None = None) -> tuple[tuple[BenchRow, ...], BenchFiles]:
    """Check the input, run every combination, write the results.

    ``runs.csv`` and ``runs.json`` are rewritten as each run ends (so an interrupted bench
    keeps what it measured), ``summary.md`` once at the end.

    Raises
    ------
    InputError
        Before anything runs: a scenario that cannot be loaded, an unknown engine, an
        output directory that cannot be created.
    """
    specs = plan_runs(scenarios, options)
    _out_dir(out_dir)
    say = progress or (lambda _msg: None)
    say(f"{len(specs)} runs, {options.jobs} at a time"
        + (f", hard limit {options.hard_limit_s:g} s per run" if options.hard_limit_s is not None else ""))
    finished: list[BenchRow] = []  # in the order runs end

    def on_row(done: int, row: BenchRow) -> None:
        finished.append(row)
        t = f"{row.time_total_s:.2f} s" if row.time_total_s is not None else f"{row.wall_s:.2f} s wall"
        say(f"[{done}/{len(specs)}] {row.scenario} {row.planner}{' ' + row.engine if row.engine else ''} K={row.samples_per_edge} "
            f"seed={row.seed}: {row.status.value} ({t})")
        write_results(finished, out_dir, options, summary=False)

    rows = run_all(specs, options, on_row)
    files = write_results(rows, out_dir, options)
    return rows, files
