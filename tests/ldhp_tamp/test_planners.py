"""Planners by name (:mod:`ldhp_tamp.planners`) and the bench over several of them: the
LDHP variants, external ``cmd:`` planners (a script that replays a stored plan, one that
writes garbage, one that never ends), unknown names."""

from __future__ import annotations

import csv
import os
import shlex
import sys
import time
from pathlib import Path

import pytest

from ldhp_tamp.bench import BenchOptions, BenchStatus, plan_runs, run_all
from ldhp_tamp.cli import EXIT_BAD_INPUT, EXIT_OK, main
from ldhp_tamp.errors import InputError
from ldhp_tamp.planners import CommandPlanner, get_planner, planner_names, uses_engine
from ldhp_tamp.plan import read_plan
from ldhp_tamp.resources import scenarios_dir
from ldhp_tamp.scenario import load_scenario
from ldhp_tamp.tamp import SolveOptions, SolveStatus

DATA = Path(__file__).resolve().parents[1] / "data" / "planners"
PICK = scenarios_dir() / "example_pick.toml"
STORED = DATA / "example_pick-plan.json"  # a solved plan of example_pick


def _cmd(script: str, *args: str) -> str:
    return "cmd:" + shlex.join([sys.executable, str(DATA / script), *args, "{scenario}", "{plan}"])


REPLAY = _cmd("replay_plan.py", str(STORED))
GARBAGE = _cmd("garbage_plan.py")


def test_the_registry_names_the_ldhp_variants() -> None:
    names = planner_names()
    assert {"ldhp", "ldhp-norefine", "ldhp-nofeedback"} <= set(names)
    assert all(uses_engine(n) for n in ("ldhp", "ldhp-norefine", "ldhp-nofeedback"))
    assert not uses_engine(REPLAY)


def test_an_unknown_planner_is_an_input_error_listing_the_known_ones() -> None:
    with pytest.raises(InputError, match=r"unknown planner 'nosuch'; known: .*ldhp-norefine.*cmd:"):
        get_planner("nosuch")


@pytest.mark.parametrize("template, problem", [("", "no program"), ("prog {scenario}", "{plan}"),
                                               ("prog 'unclosed {plan}", "cannot parse")])
def test_a_bad_command_template_is_an_input_error(template: str, problem: str) -> None:
    with pytest.raises(InputError, match=problem):
        get_planner("cmd:" + template)


def test_a_command_quoted_whole_is_split() -> None:
    assert CommandPlanner.parse("'prog -x {scenario} {plan}'").argv == ("prog", "-x", "{scenario}", "{plan}")


def test_an_external_planner_that_replays_a_stored_plan_solves() -> None:
    res = get_planner(REPLAY)(load_scenario(PICK), SolveOptions(timeout=120))
    assert res.status is SolveStatus.SOLVED, res.reason
    stored = read_plan(STORED)
    assert res.plan.steps == stored.steps
    assert res.plan.stats.time_s["total"] > 0  # the external run's own time


def test_an_external_planner_that_writes_garbage_fails_with_a_reason() -> None:
    res = get_planner(GARBAGE)(load_scenario(PICK), SolveOptions())
    assert res.status is SolveStatus.FAILED
    assert "garbage_plan.py" in res.reason and "no readable ldhp-plan/1 file" in res.reason
    assert res.plan.status.value == "failed" and res.plan.steps == ()


def test_an_external_plan_for_another_scenario_is_judged_invalid() -> None:
    other = scenarios_dir() / "cmgmp_cube_corner_pivot.toml"
    res = get_planner(REPLAY)(load_scenario(other), SolveOptions())
    assert res.status is SolveStatus.FAILED and "invalid" in res.reason


def test_an_external_planner_that_fails_or_writes_nothing_fails() -> None:
    res = get_planner("cmd:" + shlex.join([sys.executable, "-c", "import sys; sys.exit(3)", "{plan}"]))(
        load_scenario(PICK), SolveOptions())
    assert res.status is SolveStatus.FAILED and "exit status 3" in res.reason
    res = get_planner("cmd:" + shlex.join([sys.executable, "-c", "pass", "{plan}"]))(
        load_scenario(PICK), SolveOptions())
    assert res.status is SolveStatus.FAILED and "wrote no plan file" in res.reason


def test_an_external_planner_is_stopped_at_the_budget(tmp_path: Path) -> None:
    pidfile = tmp_path / "pid"
    res = get_planner(_cmd("sleep_plan.py", str(pidfile)))(load_scenario(PICK), SolveOptions(timeout=1.0))
    assert res.status is SolveStatus.FAILED and res.reason.startswith("timeout")
    assert res.plan.failure is not None and res.plan.failure.cause.value == "timeout"
    pid = int(pidfile.read_text())
    with pytest.raises(ProcessLookupError):  # reaped: it no longer exists
        os.kill(pid, 0)


def test_the_bench_judges_every_planner_the_same_way(tmp_path: Path) -> None:
    options = BenchOptions(planners=(REPLAY, GARBAGE), seeds=1, timeout_s=120)
    specs = plan_runs([PICK], options)
    assert [s.planner for s in specs] == [REPLAY, GARBAGE] and all(s.engine == "" for s in specs)
    replay, garbage = run_all(specs, options)
    assert replay.status is BenchStatus.SOLVED and replay.planner == REPLAY
    assert replay.executes is True  # simulated like the planner's own plans
    assert replay.steps == len(read_plan(STORED).steps) and replay.regrasps == 0
    assert replay.finger_travel_mm > 0 and replay.object_path_mm == pytest.approx(100.0, abs=0.1)
    assert replay.support_margin is not None
    assert garbage.status is BenchStatus.FAILED and "no readable" in garbage.reason
    assert garbage.executes is None and garbage.regrasps is None


def test_bench_cli_with_planners_writes_a_planner_column(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    assert main(["bench", str(PICK), "--planners", f"ldhp-norefine,{GARBAGE}", "--no-simulate",
                 "--out", str(out), "-q"]) == EXIT_OK
    with (out / "runs.csv").open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [(r["planner"], r["engine"], r["status"]) for r in rows] == \
        [("ldhp-norefine", "pyperplan", "solved"), (GARBAGE, "", "failed")]
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "| example-pick | ldhp-norefine | pyperplan | 100 | 1 | 1 | 100% (21-100%) |" in summary


def test_bench_cli_refuses_an_unknown_planner(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "never"
    assert main(["bench", str(PICK), "--planners", "ldhp,nosuch", "--out", str(out)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "nosuch" in err and "Traceback" not in err
    assert not out.exists()


def test_without_feedback_nothing_is_forbidden_and_the_symbolic_tier_replans_blind() -> None:
    sc = load_scenario(scenarios_dir() / "task1_zero_mobility_lift.toml")  # without refinement its first iterations fail
    with_feedback = get_planner("ldhp")(sc, SolveOptions(max_top_iterations=2, max_refinements=0))
    blind = get_planner("ldhp-nofeedback")(sc, SolveOptions(max_top_iterations=2, max_refinements=0))
    assert with_feedback.plan.failure is not None and blind.plan.failure is not None
    assert with_feedback.plan.failure.counts["forbidden"] > 0
    assert blind.plan.failure.counts["forbidden"] == 0 and blind.plan.stats.top_iterations == 2
    assert "after 2 top-tier iterations" in blind.reason


def test_without_refinement_no_segment_is_bisected() -> None:
    sc = load_scenario(scenarios_dir() / "inv_place_release.toml")  # its first pose path fails at a tip
    refined = get_planner("ldhp")(sc, SolveOptions(max_top_iterations=1))
    plain = get_planner("ldhp-norefine")(sc, SolveOptions(max_top_iterations=1))
    assert refined.plan.stats.refinements > 0
    assert plain.plan.stats.refinements == 0
