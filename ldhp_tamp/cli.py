"""The ``ldhp-tamp`` command line. The only place that turns errors into exit codes.

Exit status: 0 solved (or valid), 1 no plan found (or invalid plan), 2 bad input or
usage, 70 an unexpected exception (a bug, reported with its traceback; never mapped to
0, 1 or 2). Logs go to stderr; results to stdout or files.
"""

from __future__ import annotations

import argparse
import atexit
import gc
import logging
import math
import os
import sys
import traceback
from typing import TYPE_CHECKING, Callable, Sequence

from ldhp_tamp import budget
from ldhp_tamp.errors import InputError

if TYPE_CHECKING:  # the commands import what they need when they run
    from ldhp_tamp.plan import Failure

log = logging.getLogger("ldhp_tamp")

EXIT_OK = 0
EXIT_NO_PLAN = 1
EXIT_BAD_INPUT = 2
EXIT_BUG = 70  #: EX_SOFTWARE of sysexits.h: an unexpected exception, i.e. a bug

EXIT_CODES_HELP = """exit status:
  0   solved (or the plan is valid)
  1   no plan found (or the plan is invalid)
  2   bad input or usage (the message names the file and the problem)
  70  a bug: an unexpected exception (its traceback is printed; please report it)
"""


class _Parser(argparse.ArgumentParser):
    """argparse that exits with status 2 and a one-line message on usage errors."""

    def error(self, message: str) -> None:  # pragma: no cover - exercised via CLI tests
        self.print_usage(sys.stderr)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def cmd_check(args: argparse.Namespace) -> int:
    """Load each scenario and make every check ``solve`` makes before searching (the
    domain loads, each of its actions is implemented, the engine can solve it); print a
    summary of each. Exit 2 if any is refused, naming the file and the problem.

    The engines are not imported (``load_engine=False``): their supported kinds are
    recorded (:func:`ldhp_tamp.symbolic.check_engine`). No garbage collection runs while
    it checks (a check makes little garbage; the collections its imports would trigger
    cost a tenth of its time), and the objects that exist at exit are left out of the
    interpreter's last collections (``gc.freeze`` at exit: they walk every object, 0.2 s)."""
    status = EXIT_OK
    atexit.unregister(gc.freeze)  # once, however many times main() runs in this process
    atexit.register(gc.freeze)
    gc.disable()
    try:
        for path in args.scenarios:
            status = max(status, _check_one(path, args.strict))
    finally:
        gc.enable()
    return status


def _check_one(path: str, strict: bool) -> int:
    """``check`` of one scenario: its summary on stdout (0), or its refusal on stderr (2)."""
    from ldhp_tamp import symbolic
    from ldhp_tamp.contact_graph import ContactPoseError, build_context
    from ldhp_tamp.errors import ScenarioError
    from ldhp_tamp.primitives import REGISTRY
    from ldhp_tamp.scenario import load_scenario, summarize

    try:
        scenario = load_scenario(path, strict=strict)
        settings = scenario.settings
        symbolic.load_checked_domain(settings.domain_path or settings.domain, settings.engine, REGISTRY,
                                     load_engine=False)
    except ScenarioError as exc:  # its message starts with the scenario file
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except InputError as exc:  # the domain's or engine's: its message names the domain file
        print(f"error: {path}: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        count: int | None = len(build_context(scenario.world, scenario.start, scenario.goal).states)
    except ContactPoseError as exc:
        log.warning("%s: no contact-state graph: %s", path, exc)
        count = None
    print(summarize(scenario, contact_states=count))
    return EXIT_OK


def cmd_validate(args: argparse.Namespace) -> int:
    """Check a plan file against its scenario (the rules of ``ldhp-plan/1``)."""
    from ldhp_tamp.plan import read_plan
    from ldhp_tamp.scenario import load_scenario
    from ldhp_tamp.validate import RULES, format_violation, validate_plan

    plan = read_plan(args.plan)
    scenario = load_scenario(args.scenario, check_planner=False, strict=args.strict)
    report = validate_plan(plan, scenario)
    for warning in report.warnings:
        print(f"warning: {warning}")
    for violation in report.violations:
        print(format_violation(violation, plan))
    checked = (f"{report.steps_checked} steps, {report.waypoints_checked} waypoints, "
               f"{report.contacts_checked} finger contacts, {report.support_checks} support checks")
    if report.valid:
        print(f"valid: {args.plan} against {args.scenario} ({checked})")
        return EXIT_OK
    rules = ", ".join(f"{r} ({RULES[r]})" for r in sorted(report.rules_broken))
    count = len(report.violations)
    print(f"invalid: {args.plan} against {args.scenario}: {count} violation{'s' if count != 1 else ''} "
          f"of rules {rules} ({checked})")
    return EXIT_NO_PLAN


def cmd_solve(args: argparse.Namespace) -> int:
    """Plan for a scenario; write the plan (solved or failed) and print a summary. The
    objects that exist at exit are left out of the interpreter's last collections, as for
    ``check`` (a solve leaves millions of them: 0.2-0.3 s of the command's wall time)."""
    from pathlib import Path

    atexit.unregister(gc.freeze)  # once, however many times main() runs in this process
    atexit.register(gc.freeze)

    from ldhp_tamp.scenario import load_scenario

    scenario = load_scenario(args.scenario, strict=args.strict)
    out = Path(args.out) if args.out else Path(f"{scenario.name}-plan.json")
    if not out.resolve().parent.is_dir():  # before the search, not after it
        raise InputError(f"{out}: --out: no such directory: {out.resolve().parent}")
    # the planner's imports (unified-planning, scipy, ...) only for a scenario that loads
    from ldhp_tamp.plan import write_plan
    from ldhp_tamp.tamp import SolveOptions, solve
    prior = None
    if args.prior is not None:
        from ldhp_tamp.prior import read_prior

        prior = read_prior(args.prior)
    options = SolveOptions(engine=args.engine, seed=args.seed, timeout=args.timeout,
                           started=getattr(args, "started", None),  # --timeout counts from main()
                           emit_pddl=Path(args.emit_pddl) if args.emit_pddl else None,
                           simulate=args.simulate, prior=prior)
    quiet = args.quiet

    def progress(msg: str) -> None:
        if not quiet:
            print(f"[ldhp-tamp] {msg}", file=sys.stderr, flush=True)

    if args.planner == "ldhp":
        result = solve(scenario, options, progress=progress)
    else:  # another planner of ldhp_tamp.planners (contact-rrt, a variant, cmd:...), judged alike
        from ldhp_tamp.planners import get_planner

        result = get_planner(args.planner)(scenario, options)
    try:
        write_plan(result.plan, out)
    except OSError as exc:
        raise InputError(f"{out}: --out: cannot write the plan: {exc.strerror or exc}") from exc
    stats = result.plan.stats
    times = ", ".join(f"{k} {v:.2f} s" for k, v in stats.time_s.items())
    print(f"{result.status.value}: {scenario.name} -> {out}")
    if result.solved:
        print("  primitives: " + " -> ".join(step.primitive for step in result.plan.steps))
        n = sum(len(step.waypoints) for step in result.plan.steps)
        print(f"  steps: {len(result.plan.steps)}, waypoints: {n} (validated"
              + (", executes in simulation)" if args.simulate else ")"))
    else:
        print(f"  reason: {result.reason}")
        if args.verbose and result.plan.failure is not None:  # -v: the whole failure
            _print_failure(result.plan.failure)
    print(f"  contact states: {stats.contact_state_nodes}, grasp graph: {stats.grasp_graph_nodes} nodes, "
          f"{stats.grasp_graph_edges} edges, top iterations: {stats.top_iterations}, "
          f"refinements: {stats.refinements}, feasibility checks: {stats.feasibility_checks}")
    print(f"  time: {times}")
    return EXIT_OK if result.solved else EXIT_NO_PLAN


def _print_failure(failure: Failure) -> None:
    """The failure of a failed plan, every attempt on a line of its own (``solve -v``)."""
    where = ", ".join(f"{k} {v}" for k, v in (("step", failure.step), ("segment", failure.segment),
                                                ("primitive", failure.primitive)) if v is not None)
    print(f"  failure: tier {failure.tier.value}, cause {failure.cause.value}" + (f", {where}" if where else ""))
    print("  counts: " + ", ".join(f"{k} {v}" for k, v in failure.counts.items()))
    total = failure.counts.get("attempts", len(failure.attempts))
    print(f"  attempts ({len(failure.attempts)}" + (f", the last of {total}" if total > len(failure.attempts) else "")
          + "):")
    for i, attempt in enumerate(failure.attempts, start=1):
        print(f"    {i}. {attempt}")


def _positive(what: str, positive: str) -> Callable[[str], float]:
    """An argparse type: a finite positive number (``what`` and ``positive`` word the refusal)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not math.isfinite(value) or value <= 0:
            raise argparse.ArgumentTypeError(f"expected {positive}, got {text!r}")
        return value

    return parse


_seconds = _positive("a number of seconds", "a positive number of seconds")
_speed = _positive("a speed in mm/s", "a positive speed in mm/s")


def _fraction(text: str) -> float:
    """An argparse type: a number in [0, 1]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], got {text!r}")
    return value


def _comma_names(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise argparse.ArgumentTypeError(f"expected comma-separated names, got {text!r}")
    return names


def _planner_names(text: str) -> tuple[str, ...]:
    """``--planners``: comma-separated names; a ``cmd:`` item takes the rest of the text,
    commas included (so it comes last)."""
    head, sep, cmd = text.partition("cmd:")
    names = [n.strip() for n in head.split(",") if n.strip()]
    if sep:
        if not cmd.strip():
            raise argparse.ArgumentTypeError("cmd: needs a command, e.g. cmd:'my-planner {scenario} {plan}'")
        names.append(sep + cmd.strip())
    if not names:
        raise argparse.ArgumentTypeError(f"expected comma-separated planner names, got {text!r}")
    return tuple(names)


def _comma_ints(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(n) for n in text.split(",") if n.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None


def cmd_bench(args: argparse.Namespace) -> int:
    """Run scenario x engine x K x seed in worker processes; write CSV, JSON, Markdown.
    Exit 0 when the bench ran, whatever the solves' outcomes (they are in the rows)."""
    from ldhp_tamp.bench import BenchOptions, run_bench

    options = BenchOptions(engines=args.engines, planners=args.planners, seeds=args.seeds, samples=args.samples,
                           timeout_s=args.timeout, grace_s=args.grace, jobs=args.jobs,
                           simulate=not args.no_simulate, executor=args.executor, scheduler=args.scheduler,
                           prior=args.prior, keep_plans=args.plans)
    quiet = args.quiet

    def progress(msg: str) -> None:
        if not quiet:
            print(f"[ldhp-tamp bench] {msg}", file=sys.stderr, flush=True)

    rows, files = run_bench(args.scenarios, options, args.out, progress=progress, resume=not args.fresh)
    written = [files.csv, files.json, files.summary]
    if args.plots:
        from ldhp_tamp.bench_plots import write_plots

        plots = write_plots(rows, args.out, options.hard_limit_s)
        if not plots:
            progress("--plots: no figure (the runs need two or more K values or vertex counts)")
        written += plots
    print(files.summary.read_text(encoding="utf-8"), end="")
    print("\nwrote " + ", ".join(str(p) for p in written))
    return EXIT_OK


#: :data:`ldhp_tamp.sweep.EXECUTORS`, named here so that building the parser (every
#: command, ``check`` and ``--help`` included) does not import the sweep module and
#: multiprocessing (a test keeps the two equal).
_EXECUTORS = ("local", "dask")


def _add_executor(p: argparse.ArgumentParser) -> None:
    """``--executor`` and ``--scheduler`` of bench and ablate (:mod:`ldhp_tamp.sweep`)."""
    p.add_argument("--executor", choices=_EXECUTORS, default="local",
                   help="where the cells run: 'local' processes (default) or 'dask' (one task per cell; "
                        "needs pip install 'ldhp-tamp[dask]'); see docs/benchmarks.md")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="with --executor dask: a running Dask scheduler (default: a LocalCluster of --jobs "
                        "workers on this machine)")


def cmd_prior(args: argparse.Namespace) -> int:
    """Fit a transition prior from plan files (``bench --plans`` keeps them) and write it."""
    from ldhp_tamp.prior import fit_prior, plan_files, write_prior

    files = plan_files(args.plans)
    prior = fit_prior(files, defer_below=args.defer_below)
    try:
        write_prior(prior, args.out)
    except OSError as exc:
        raise InputError(f"{args.out}: --out: cannot write the prior: {exc.strerror or exc}") from exc
    deferred = sorted(prior.deferred(prior.transitions))
    n = len(prior.transitions)
    print(f"prior: {n} transition{'' if n == 1 else 's'} from {prior.plans} plan(s) of "
          f"{', '.join(prior.fit_on)} -> {args.out}")
    print(f"  deferred (acceptance below {prior.defer_below:g}): {len(deferred)}")
    for label in deferred:
        seen = prior.transitions[label]
        print(f"    {label}: accepted {seen.accepted}, refused {seen.refused}")
    return EXIT_OK


def cmd_ablate(args: argparse.Namespace) -> int:
    """Remove one primitive at a time from a copy of the domain, solve every scenario with
    it; print Table III (Y/N), optionally write the CSV. Exit 0 when the ablation ran,
    whatever the cells say."""
    from pathlib import Path

    from ldhp_tamp.ablate import AblationOptions, ablate, format_table

    options = AblationOptions(domain=args.domain, remove=args.remove, timeout_s=args.timeout,
                              jobs=args.jobs, keep_domains=Path(args.keep_domains) if args.keep_domains else None,
                              grace_s=args.grace, executor=args.executor, scheduler=args.scheduler,
                              simulate=args.simulate)
    quiet = args.quiet

    def progress(msg: str) -> None:
        if not quiet:
            print(f"[ldhp-tamp ablate] {msg}", file=sys.stderr, flush=True)

    table = ablate(args.scenarios, options, progress=progress, csv_path=args.csv, resume=not args.fresh)
    print(format_table(table), end="")
    if args.csv:
        print(f"wrote {args.csv}")
    return EXIT_OK


def cmd_render(args: argparse.Namespace) -> int:
    """Draw a plan's figures (snapshots, animation, contact-state graph) into a folder.
    Exit 0 when the figures were written, also for a plan without steps (a failed solve:
    the task and the graph are drawn, without a path)."""
    from ldhp_tamp.render import RenderOptions, render_files

    try:
        options = RenderOptions(max_frames=args.max_frames, dpi=args.dpi)
    except ValueError as exc:
        raise InputError(f"render options: {exc}") from None
    figures = render_files(args.plan, args.scenario, args.out, options)
    if figures.task_only:
        print(f"note: {args.plan} has no waypoint: drew the task (start, goal) and the graph without a path",
              file=sys.stderr)
    print(f"wrote {figures.out_dir}: snapshots ({figures.panels} panel{'s' if figures.panels != 1 else ''}), "
          f"animation ({figures.frames} frame{'s' if figures.frames != 1 else ''}), contact-state graph")
    for path in figures.paths:
        print(f"  {path}")
    return EXIT_OK


def cmd_simulate(args: argparse.Namespace) -> int:
    """Replay a plan open-loop in the MuJoCo simulation; exit 0 when it executes, 1 when it
    diverges (or the plan is a failed plan), 2 on bad input."""
    from pathlib import Path

    from ldhp_tamp.plan import read_plan
    from ldhp_tamp.scenario import load_scenario
    from ldhp_tamp.simulate import SimOptions, format_verdict, simulate_plan, write_gif, write_report

    plan = read_plan(args.plan)
    scenario = load_scenario(args.scenario, check_planner=False, strict=args.strict)
    for flag, path in (("--out", args.out), ("--gif", args.gif)):
        if path and not Path(path).resolve().parent.is_dir():  # before the simulation, not after it
            raise InputError(f"{path}: {flag}: no such directory: {Path(path).resolve().parent}")
    options = SimOptions() if args.speed is None else SimOptions(speed_mm_s=args.speed)
    report = simulate_plan(plan, scenario, options)
    print(format_verdict(report))
    if report.records:
        print(f"  max error to the plan: {report.max_position_error_mm:.2f} mm, {report.max_angle_error_deg:.2f} deg "
              f"over {len(report.records)} waypoints")
        if report.final_position_error_mm is not None:
            print(f"  final error to the goal: {report.final_position_error_mm:.2f} mm, "
                  f"{report.final_angle_error_deg:.2f} deg")
        if report.max_force_n is None:
            force = "rigid fingers (fixed width)"
        else:
            force = f"finger force cap {report.max_force_n:g} N" + (
                " (default: the scenario gives no max_force)" if report.max_force_default else "")
        print(f"  simulated {report.simulated_s:.1f} s in {report.wall_s:.1f} s at {options.speed_mm_s:g} mm/s; "
              f"{force}")
    if args.out:
        print(f"wrote {write_report(report, args.out, args.plan, args.scenario, options)}")
    if args.gif:
        if report.records:
            frames = write_gif(report, plan, scenario, args.gif)
            print(f"wrote {args.gif} ({frames} frames)")
        else:
            print(f"note: {args.gif} not written: nothing was simulated", file=sys.stderr)
    return EXIT_OK if report.executes else EXIT_NO_PLAN


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "check": cmd_check, "validate": cmd_validate, "solve": cmd_solve, "bench": cmd_bench,
    "ablate": cmd_ablate, "render": cmd_render, "simulate": cmd_simulate, "prior": cmd_prior}


def _add_strict(p: argparse.ArgumentParser) -> None:
    p.add_argument("--strict", action="store_true",
                   help="refuse scenario keys that ldhp-scenario/1 does not define (exit 2, naming the "
                        "key) instead of warning and ignoring them: catches a misspelt optional key, "
                        "which would leave its default in force")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="ldhp-tamp",
        description="LDHP planner for non-prehensile manipulation with a parallel-jaw gripper.",
        epilog=EXIT_CODES_HELP,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more log output on stderr: -v the planner's progress in detail, -vv also the engines'")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("check", help="load scenarios and print a short summary of each",
                       epilog=EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO", help="scenario TOML files")
    _add_strict(p)

    p = sub.add_parser("validate", help="check a plan against its scenario (the rules of ldhp-plan/1)",
                       description="Check every rule of ldhp-plan/1 on every waypoint; print each "
                                   "violation (rule, step, waypoint, what) and a one-line verdict.",
                       epilog=EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("plan", metavar="PLAN", help="plan JSON file (ldhp-plan/1)")
    p.add_argument("--scenario", required=True, metavar="SCENARIO", help="the scenario TOML file")
    _add_strict(p)

    p = sub.add_parser("solve", help="plan for a scenario and write the plan JSON",
                       description="Run the two-tier LDHP planner on a scenario. The plan is validated "
                                   "before it is written; a failed solve writes a plan with status "
                                   "'failed' and the reason.",
                       epilog=EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenario", metavar="SCENARIO", help="scenario TOML file")
    p.add_argument("--out", metavar="PLAN", help="plan JSON to write (default: <scenario name>-plan.json)")
    p.add_argument("--engine", metavar="NAME", help="unified-planning engine (default: the scenario's, pyperplan)")
    p.add_argument("--planner", default="ldhp", metavar="NAME",
                   help="the planner (default ldhp): ldhp, ldhp-norefine, ldhp-nofeedback, contact-rrt, or "
                        "cmd:'PROGRAM {scenario} {plan}' (as bench --planners)")
    p.add_argument("--seed", type=int, metavar="N", help="random seed (default: the scenario's)")
    p.add_argument("--emit-pddl", metavar="DIR", help="write the domain and one problem per top-tier iteration")
    p.add_argument("--timeout", type=_seconds, metavar="SECONDS",
                   help="wall-time budget of the whole command, counted from its start (loading the "
                        "scenario, both tiers, every engine); when it runs "
                        "out the plan has status 'failed', a reason starting 'timeout' and the "
                        "statistics so far, and the exit status is 1 (default: no limit)")
    p.add_argument("--simulate", action="store_true",
                   help="judge every plan found in the physics simulation too (ldhp-tamp simulate): a plan "
                        "that diverges is fed back like one that fails validation and the search goes on")
    p.add_argument("--prior", metavar="FILE",
                   help="a transition prior (ldhp-tamp prior): the transitions it rates unlikely to pass the "
                        "bottom tier are left out of the plans until no plan is left without them")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages on stderr")
    p.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                   help="as 'ldhp-tamp -v solve': the planner's progress on stderr and, for a failed "
                        "solve, the whole failure (tier, cause, counts, every attempt)")
    _add_strict(p)

    p = sub.add_parser("bench", help="benchmark: every scenario x planner x engine x K x seed, in worker processes",
                       description="Solve every combination scenario x planner x engine x K x seed, each in a worker\n"
                                   "process of its own (at most --jobs at once), and write runs.csv,\n"
                                   "runs.json and summary.md (success rate, times, plan length) into --out;\n"
                                   "--plots adds time-against-K and time-against-vertex-count figures.\n"
                                   "Runs already in --out's runs.json (not 'error') are not run again.\n"
                                   "See docs/benchmarks.md.",
                       epilog="exit status:\n  0  the bench ran, whatever the solves' outcomes (see the "
                              "status column)\n  2  bad input or usage (the message names the file and "
                              "the problem); nothing was run\n",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO", help="scenario TOML files")
    p.add_argument("--planners", type=_planner_names, default=("ldhp",), metavar="P,Q",
                   help="comma-separated planners: ldhp, ldhp-norefine, ldhp-nofeedback, contact-rrt, or "
                        "cmd:'PROGRAM {scenario} {plan}' (an external program that writes an ldhp-plan/1 "
                        "file; last, it takes the rest of the text) (default: ldhp)")
    p.add_argument("--engines", type=_comma_names, metavar="A,B",
                   help="comma-separated engines, e.g. pyperplan,fast-downward (default: each scenario's); "
                        "for the planners with a symbolic tier")
    p.add_argument("--seeds", type=int, default=1, metavar="N", help="seeds 0..N-1 per combination (default 1)")
    p.add_argument("--samples", type=_comma_ints, metavar="K1,K2",
                   help="comma-separated K, grasp samples per edge (default: each scenario's)")
    p.add_argument("--timeout", type=float, metavar="S",
                   help="seconds per run; passed to the solver if it has a timeout option, and enforced "
                        "as a hard limit of S + --grace by terminating the worker (status 'timeout')")
    p.add_argument("--grace", type=float, default=10.0, metavar="S",
                   help="seconds added to --timeout for the hard limit (default 10)")
    p.add_argument("--jobs", type=int, default=1, metavar="J", help="worker processes at once (default 1)")
    _add_executor(p)
    p.add_argument("--out", default="bench-results", metavar="DIR",
                   help="output directory (default: bench-results); a runs.json there is resumed")
    p.add_argument("--fresh", action="store_true",
                   help="run every combination, ignoring the runs already in --out's runs.json")
    p.add_argument("--no-simulate", action="store_true",
                   help="do not replay the solved plans in the physics simulation (the executes column stays empty)")
    p.add_argument("--plots", action="store_true",
                   help="also draw time_vs_samples / time_vs_vertices .png and .svg when the runs vary K "
                        "or the vertex count")
    p.add_argument("--prior", metavar="FILE", help="give every solve this transition prior (as solve --prior)")
    p.add_argument("--plans", action="store_true",
                   help="keep every run's plan in OUT/plans/ (what 'ldhp-tamp prior' fits a prior from)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages on stderr")

    p = sub.add_parser("prior", help="fit a transition prior from plan files (bench --plans keeps them)",
                       description="Add up, over plan files, how often each contact-state transition was\n"
                                   "accepted by the bottom tier (a solved pose path took it) and refused (a\n"
                                   "pose path failed there), and write the counts as a prior (ldhp-prior/1)\n"
                                   "for solve --prior and bench --prior. State names come from the numbering\n"
                                   "of the object's and the environment's vertices and edges: fit a prior on\n"
                                   "the world you will use it on, or on variants of it numbered alike.\n"
                                   "See docs/formats/prior.md.",
                       epilog=EXIT_CODES_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("plans", nargs="+", metavar="PLAN",
                   help="plan JSON files, or directories (their *-plan.json files, recursively)")
    p.add_argument("--out", required=True, metavar="FILE", help="the prior file to write")
    p.add_argument("--defer-below", type=_fraction, default=0.25, metavar="P",
                   help="defer the transitions whose acceptance (accepted + 1) / (accepted + refused + 2) "
                        "is below P (default 0.25: refused three times and never accepted)")

    p = sub.add_parser("ablate", help="remove one primitive at a time and solve each scenario (Table III)",
                       description="For each action of the domain (and for none, the baseline), write a\n"
                                   "copy of the domain without it into a temporary directory, solve every\n"
                                   "scenario with that copy and validate the plan; print a table with a row\n"
                                   "per removed primitive, a column per scenario, Y (a valid plan) or N.",
                       epilog="exit status:\n  0  the ablation ran, whatever the cells say\n"
                              "  2  bad input or usage (the message names the file and the problem); "
                              "nothing was solved\n",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO", help="scenario TOML files (the table's columns)")
    p.add_argument("--domain", metavar="D",
                   help="domain to ablate: a name in domains/ or a .pddl file (default: the scenarios' own)")
    p.add_argument("--remove", type=_comma_names, metavar="A,B",
                   help="remove only these actions, one at a time (default: every action of the domain)")
    p.add_argument("--csv", metavar="FILE",
                   help="also write the table as CSV (removed,scenario,feasible,reason,time_s,status,primitives), "
                        "rewritten as each solve ends; an existing FILE is resumed: its cells are not solved "
                        "again, but for 'error' ones")
    p.add_argument("--fresh", action="store_true", help="solve every cell, ignoring what --csv FILE holds")
    p.add_argument("--timeout", type=float, metavar="S",
                   help="seconds per solve, if the planner has a timeout option (else ignored, with a warning); "
                        "a solve in a process of its own is stopped at S + --grace (status 'timeout')")
    p.add_argument("--grace", type=float, default=10.0, metavar="S",
                   help="seconds added to --timeout for the hard limit (default 10)")
    p.add_argument("--simulate", action="store_true",
                   help="Y only for a plan that executes in the physics simulation too (solve --simulate)")
    p.add_argument("--jobs", type=int, default=1, metavar="J",
                   help="solves at once, each in a process of its own (default 1: in this process)")
    _add_executor(p)
    p.add_argument("--keep-domains", metavar="DIR", help="write the domain copies here and keep them")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages on stderr")

    p = sub.add_parser("render", help="draw a plan's figures: snapshots, animation, contact-state graph",
                       description="Draw paper-style figures from a plan file and its scenario alone:\n"
                                   "snapshots.png/.svg (a panel per step), animation.gif (the whole plan)\n"
                                   "and contact_graph.png/.svg (the contact states, the admissible\n"
                                   "MoveObject transitions by primitive, the plan's path). A plan without\n"
                                   "steps (a failed solve) is drawn as the task. See docs/figures.md.",
                       epilog="exit status:\n  0  the figures were written (also for a failed plan)\n"
                              "  2  bad input or usage: unreadable or malformed plan or scenario, a plan "
                              "made for\n     another scenario, an unwritable folder; nothing is written\n",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("plan", metavar="PLAN", help="plan JSON file (ldhp-plan/1)")
    p.add_argument("--scenario", required=True, metavar="SCENARIO", help="the scenario TOML file")
    p.add_argument("--out", metavar="DIR", help="output folder (default: <plan stem>-figures next to the plan)")
    p.add_argument("--max-frames", type=int, default=150, metavar="N",
                   help="at most N animation frames (default 150)")
    p.add_argument("--dpi", type=int, default=150, metavar="N", help="resolution of the PNG figures (default 150)")

    p = sub.add_parser("simulate", help="replay a plan in a MuJoCo physics simulation: does it execute?",
                       description="Replay a plan open-loop in a MuJoCo simulation of its scenario: the hand\n"
                                   "follows the plan's gripper poses and widths slowly, the object is free.\n"
                                   "It executes when the object stays within 15 mm and 15 degrees of the\n"
                                   "planned pose at every waypoint and ends within 10 mm and 10 degrees of\n"
                                   "the goal; otherwise it diverges at the step of the first waypoint beyond.\n"
                                   "See docs/design/simulation.md.",
                       epilog="exit status:\n  0   the plan executes\n  1   it diverges (or the plan is a "
                              "failed plan)\n  2   bad input or usage (the message names the file and the "
                              "problem)\n  70  a bug\n",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("plan", metavar="PLAN", help="plan JSON file (ldhp-plan/1)")
    p.add_argument("--scenario", required=True, metavar="SCENARIO", help="the scenario TOML file")
    p.add_argument("--out", metavar="REPORT", help="write the simulation report (JSON, ldhp-sim-report/1)")
    p.add_argument("--gif", metavar="FILE", help="draw the simulated run as an animated GIF")
    p.add_argument("--speed", type=_speed, metavar="MM_PER_S",
                   help="speed of the fastest point of the hand (default 5 mm/s)")
    _add_strict(p)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    started = budget.clock()  # a solve's --timeout counts from here, loading included
    parser = build_parser()
    args = parser.parse_args(argv)
    args.started = started
    # -v: the planner's INFO records; -vv: its DEBUG records and the engines' own progress
    # (pyperplan logs on the root logger, a dozen lines per solve).
    logging.basicConfig(
        level=logging.INFO if args.verbose >= 2 else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    log.setLevel(logging.WARNING - 10 * min(args.verbose, 2))
    # Dask's distributed logs every event of a sweep's cluster at INFO: with -vv only.
    logging.getLogger("distributed").setLevel(logging.INFO if args.verbose >= 2 else logging.WARNING)
    try:
        return COMMANDS[args.command](args)
    except InputError as exc:
        if args.debug:
            traceback.print_exc()
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # stdout closed early (`| head`): not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except Exception as exc:  # a bug: never let it pass for "no plan" (1) or "bad input" (2)
        traceback.print_exc()
        print(f"ldhp-tamp: internal error (a bug): {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_BUG


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
