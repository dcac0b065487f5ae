"""``ldhp-tamp bench``: worker processes, time limits, CSV / JSON / Markdown, figures.

The runs are real solves in real worker processes (the pick example, ~1 s each); the
time limit is tested on task 1, which takes seconds, with a hard limit of 0.01 s.
"""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import json
import math
import time
import tomllib
from pathlib import Path

import pytest

from ldhp_tamp.bench import (
    BENCH_FORMAT,
    COLUMNS,
    BenchOptions,
    BenchRow,
    BenchStatus,
    RunSpec,
    format_csv,
    format_summary,
    plan_runs,
    run_all,
    run_bench,
)
from ldhp_tamp.bench_plots import SAMPLES, plot_scaling, write_plots
from ldhp_tamp.cli import EXIT_BAD_INPUT, EXIT_OK, main
from ldhp_tamp.errors import InputError
from ldhp_tamp.resources import scenarios_dir
from ldhp_tamp.scenario import load_scenario_string

REPO = Path(__file__).resolve().parents[2]
PICK = scenarios_dir() / "example_pick.toml"
TASK1 = scenarios_dir() / "task1_zero_mobility_lift.toml"


def test_bench_of_the_pick_example_two_seeds_two_jobs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench"
    assert main(["bench", str(PICK), "--seeds", "2", "--jobs", "2", "--out", str(out), "-q"]) == EXIT_OK
    stdout = capsys.readouterr().out
    with (out / "runs.csv").open(newline="", encoding="utf-8") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = [dict(zip(header, r)) for r in reader]
    assert tuple(header) == COLUMNS
    assert [(r["scenario"], r["engine"], r["seed"], r["samples_per_edge"]) for r in rows] == \
        [("example-pick", "pyperplan", "0", "100"), ("example-pick", "pyperplan", "1", "100")]
    assert all(r["status"] == "solved" and r["reason"] == "" for r in rows)
    for r in rows:
        assert int(r["steps"]) >= 2 and int(r["waypoints"]) > int(r["steps"])
        assert int(r["feasibility_checks"]) > 0 and int(r["grasp_graph_nodes"]) > 0
        assert int(r["object_vertices"]) == 4 and int(r["contact_state_nodes"]) > 0
        assert float(r["wall_s"]) >= float(r["time_total_s"]) >= float(r["time_grasp_graph_s"]) > 0
        # every solved plan is replayed in the physics simulation: the pick executes
        assert r["executes"] == "True" and r["diverges_at"] == "" and float(r["sim_wall_s"]) > 0

    doc = json.loads((out / "runs.json").read_text(encoding="utf-8"))
    assert doc["format"] == BENCH_FORMAT and doc["columns"] == list(COLUMNS)
    assert doc["options"]["jobs"] == 2 and doc["options"]["seeds"] == 2
    assert [r["seed"] for r in doc["rows"]] == [0, 1]
    assert all(r["status"] == "solved" and r["time_total_s"] > 0 for r in doc["rows"])
    assert doc["rows"][0]["time_total_s"] == pytest.approx(float(rows[0]["time_total_s"]), abs=1e-4)

    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "| example-pick | ldhp | pyperplan | 100 | 2 | 2 | 100% (34-100%) | 2/2 | 0 | 0 |" in summary
    assert "## Median time per tier" in summary and "Runs not solved" not in summary
    assert summary in stdout and "runs.csv" in stdout
    assert not list(out.glob(".*.tmp*")), "atomic writes leave no temporary files"


def test_a_run_over_the_hard_limit_is_a_timeout_row(tmp_path: Path) -> None:
    options = BenchOptions(timeout_s=0.01, grace_s=0.0)
    specs = plan_runs([TASK1], options)
    t0 = time.monotonic()
    (row,) = run_all(specs, options)
    elapsed = time.monotonic() - t0
    assert row.status is BenchStatus.TIMEOUT and "hard limit" in row.reason
    assert row.time_total_s is None and row.steps is None
    # task 1 takes seconds; the worker was stopped rather than left to finish (a hang
    # guard: the SIGTERM wait and the forkserver's start take longer on a busy machine)
    assert elapsed < 60
    rows, files = run_bench([TASK1], options, tmp_path)
    assert [r.status for r in rows] == [BenchStatus.TIMEOUT]
    assert "| task1-zero-mobility-lift | ldhp | pyperplan | 100 | 1 | 0 | 0% (0-79%) | - | 1 | 0 |" in files.summary.read_text()
    assert next(csv.DictReader(files.csv.open()))["status"] == "timeout"


def test_a_run_that_raises_is_an_error_row_and_the_others_run(tmp_path: Path) -> None:
    gone = tmp_path / "deleted.toml"
    specs = [RunSpec(0, str(gone), "deleted", "pyperplan", 0, 100, 4),
             RunSpec(1, str(PICK), "example-pick", "pyperplan", 0, 100, 4)]
    seen: list[int] = []
    rows = run_all(specs, BenchOptions(jobs=2), on_row=lambda done, _row: seen.append(done))
    assert [r.scenario for r in rows] == ["deleted", "example-pick"]  # the order of the specs
    assert rows[0].status is BenchStatus.ERROR
    assert "ScenarioError" in rows[0].reason and "deleted.toml" in rows[0].reason
    assert rows[1].status is BenchStatus.SOLVED
    assert seen == [1, 2]


def test_a_run_with_a_plan_file_keeps_its_plan(tmp_path: Path) -> None:
    from ldhp_tamp.plan import PlanStatus, read_plan

    (spec,) = plan_runs([PICK], BenchOptions())
    assert spec.plan_file is None  # the harness keeps no plan unless asked
    kept, never = tmp_path / "pick-plan.json", tmp_path / "deleted-plan.json"
    specs = [dataclasses.replace(spec, plan_file=str(kept)),
             RunSpec(1, str(tmp_path / "deleted.toml"), "deleted", "pyperplan", 0, 100, 4,
                     plan_file=str(never))]
    rows = run_all(specs, BenchOptions(jobs=2))
    assert [r.status for r in rows] == [BenchStatus.SOLVED, BenchStatus.ERROR]
    plan = read_plan(kept)
    assert plan.status is PlanStatus.SOLVED and plan.scenario == "example-pick"
    assert len(plan.steps) == rows[0].steps and plan.stats.feasibility_checks == rows[0].feasibility_checks
    assert not never.exists()  # a run that raised wrote no plan
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pick-plan.json"]  # no temporary file


def test_bench_keeps_the_plans_and_gives_the_solves_a_prior(tmp_path: Path) -> None:
    """``--plans`` writes every run's plan into OUT/plans/ (what ``ldhp-tamp prior`` fits
    from); ``--prior`` gives it to every solve (the plans say so)."""
    from ldhp_tamp.plan import read_plan
    from ldhp_tamp.prior import Outcomes, TransitionPrior, fit_prior, write_prior

    prior = write_prior(TransitionPrior({"air-move l1-e3->free": Outcomes(5, 0)}), tmp_path / "prior.json")
    out = tmp_path / "bench"
    assert main(["bench", str(PICK), "--seeds", "2", "--plans", "--prior", str(prior), "--no-simulate",
                 "--out", str(out), "-q"]) == EXIT_OK
    plans = sorted((out / "plans").iterdir())
    assert [p.name for p in plans] == ["example-pick-ldhp-pyperplan-K100-s0-plan.json",
                                       "example-pick-ldhp-pyperplan-K100-s1-plan.json"]
    assert all(read_plan(p).stats.extra["prior_deferred"] == 0 for p in plans)
    assert json.loads((out / "runs.json").read_text(encoding="utf-8"))["options"]["prior"] == str(prior.resolve())
    assert fit_prior(plans).plans == 2
    # the same --out without the prior is another bench: it is not resumed
    with pytest.raises(InputError, match="prior"):
        run_bench([PICK], BenchOptions(seeds=2, simulate=False), out, resume=True)


@pytest.mark.parametrize("argv, named", [
    (["missing.toml"], "missing.toml"),
    ([str(PICK), "--engines", "no-such-engine"], "no-such-engine"),
    ([str(PICK), "--samples", "0,10"], "--samples"),
    ([str(PICK), "--jobs", "0"], "--jobs"),
    ([str(PICK), "--timeout", "-1"], "--timeout"),
    ([str(PICK), "--prior", "missing-prior.json"], "missing-prior.json"),
])
def test_bad_input_exits_2_before_anything_runs(argv: list[str], named: str, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "never"
    assert main(["bench", *argv, "--out", str(out)]) == EXIT_BAD_INPUT
    captured = capsys.readouterr()
    assert captured.out == "" and "Traceback" not in captured.err
    assert captured.err.startswith("error: ") and named in captured.err
    assert not out.exists()


def test_bench_options_refuse_bad_values() -> None:
    with pytest.raises(InputError, match="--seeds"):
        BenchOptions(seeds=0)
    with pytest.raises(InputError, match="--grace"):
        BenchOptions(grace_s=math.nan)
    with pytest.raises(InputError, match="--engines"):
        BenchOptions(engines=())
    assert BenchOptions(timeout_s=5, grace_s=10).hard_limit_s == 15
    assert BenchOptions().hard_limit_s is None


def _row(k: int, seed: int, status: BenchStatus, total: float | None, checks: int | None = None,
         steps: int | None = None, reason: str = "") -> BenchRow:
    return BenchRow("s", "s.toml", "pyperplan", seed, k, 4, status, reason, wall_s=(total or 0.0) + 0.5,
                    time_total_s=total, time_setup_s=None if total is None else total / 4,
                    time_grasp_graph_s=None if total is None else total / 2,
                    steps=steps, feasibility_checks=checks)


def test_summary_counts_statuses_and_times_solved_runs_only() -> None:
    rows = [_row(10, 0, BenchStatus.SOLVED, 1.0, 100, 2), _row(10, 1, BenchStatus.SOLVED, 3.0, 300, 4),
            _row(10, 2, BenchStatus.FAILED, 9.0, 900, 0, reason="bottom tier: no grasp"),
            _row(10, 3, BenchStatus.TIMEOUT, None, reason="hard limit")]
    text = format_summary(rows, BenchOptions(seeds=4, timeout_s=5))
    # success 2/4 with its 95 % Wilson interval; time median [Q1, Q3] and max over solved runs
    assert "| s | ldhp | pyperplan | 10 | 4 | 2 | 50% (15-85%) | - | 1 | 0 | 2.00 [1.50, 2.50] | 3.00 |" in text
    assert "| s | ldhp | pyperplan | 10 | 3.0 | - | - | - | - | - |" in text  # median steps of solved runs
    assert "| s | ldhp | pyperplan | 10 | 0.50 | - | - | 1.00 | 2.00 |" in text  # per tier: setup, ..., total
    assert "seed 2: **failed**: bottom tier: no grasp" in text and "seed 3: **timeout**" in text
    lines = format_csv(rows).splitlines()
    assert lines[0] == ",".join(COLUMNS) and len(lines) == 5
    assert lines[4].split(",")[COLUMNS.index("time_total_s")] == ""  # None is an empty cell


def test_plots_against_k_are_written_as_png_and_svg(tmp_path: Path) -> None:
    rows = [_row(k, s, BenchStatus.SOLVED, 0.01 * k + s, 100 * k, 2) for k in (10, 50, 200) for s in (0, 1)]
    rows.append(_row(200, 2, BenchStatus.TIMEOUT, None))
    written = write_plots(rows, tmp_path, hard_limit_s=12.0)
    assert [p.name for p in written] == ["comparison.png", "comparison.svg",  # planners side by side
                                         "time_vs_samples.png", "time_vs_samples.svg"]  # one vertex count
    assert written[2].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "solved (%), 95 % Wilson interval" in written[1].read_text(encoding="utf-8")
    svg = written[3].read_text(encoding="utf-8")
    assert "<svg" in svg and "planning time (s)" in svg
    assert plot_scaling(rows[:2], SAMPLES, tmp_path / "none") is None  # a single K: no figure


def test_comparison_plot_of_ten_solved_runs_of_ten(tmp_path: Path) -> None:
    """The Wilson interval of 10/10 rounds its upper end to 1 - 1e-16, below the rate:
    the error bar's length is clipped at 0 (matplotlib refuses a negative one)."""
    rows = [_row(10, s, BenchStatus.SOLVED, 0.5 + 0.01 * s, 100, 2) for s in range(10)]
    assert [p.name for p in write_plots(rows, tmp_path, hard_limit_s=12.0)] == ["comparison.png", "comparison.svg"]


def _scaling_module():
    spec = importlib.util.spec_from_file_location("scaling", REPO / "benchmarks" / "scaling.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("n", [4, 5, 9, 12])
def test_scaling_polygons_are_regular_and_load_as_scenarios(n: int) -> None:
    scaling = _scaling_module()
    text = scaling.polygon_scenario(n)
    sc = load_scenario_string(text, name=f"polygon-{n}")
    assert sc.name == f"polygon-{n:02d}" and sc.world.object.n == n
    pts = scaling.regular_polygon(n)
    sides = [math.dist(pts[i], pts[(i + 1) % n]) for i in range(n)]
    assert max(sides) - min(sides) < 1e-3
    assert min(p[1] for p in pts) == 0 and pts[0][1] == pts[1][1] == 0  # resting on its first edge
    ours, pick = tomllib.loads(text), tomllib.loads(PICK.read_text(encoding="utf-8"))
    for table in ("environment", "gripper", "friction", "task"):  # only the object differs
        assert ours[table] == pick[table]


def test_scaling_growth_fits_the_exponent_of_time_against_graph_size() -> None:
    from ldhp_tamp.bench import BenchRow

    scaling = _scaling_module()

    def row(name: str, edges: int, t: float, status: BenchStatus = BenchStatus.SOLVED) -> BenchRow:
        return BenchRow(name, "x.toml", "pyperplan", 0, 100, 4, status, "", t, time_total_s=t, time_grasp_graph_s=t / 2,
                        grasp_graph_nodes=edges // 10, grasp_graph_edges=edges, feasibility_checks=edges)

    rows = [row("linear", e, 1e-4 * e) for e in (1000, 2000, 8000)]
    rows += [row("square", e, 1e-8 * e * e) for e in (1000, 4000)] + [row("square", 9000, 5.0, BenchStatus.FAILED)]
    text = scaling.growth(rows)
    assert "- linear: 3 solved runs, edges 1000-8000; time ~ edges^1.00 (grasp-graph tier ~ edges^1.00)" in text
    assert "- square: 2 solved runs, edges 1000-4000; time ~ edges^2.00" in text  # the failed run left out


def test_a_solve_that_fails_past_the_time_limit_counts_as_a_timeout() -> None:
    from ldhp_tamp.bench import _status

    assert _status("solved", 9.0, 5.0) is BenchStatus.SOLVED  # it made it: solved
    assert _status("failed", 9.0, 5.0) is BenchStatus.TIMEOUT
    assert _status("failed", 1.0, 5.0) is BenchStatus.FAILED
    assert _status("failed", 9.0, None) is BenchStatus.FAILED
    assert _status("timeout", 5.0, 5.0) is BenchStatus.TIMEOUT


def test_bench_plots_flag_draws_time_against_k(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "k"
    assert main(["bench", str(PICK), "--samples", "10,25", "--plots", "--out", str(out), "-q"]) == EXIT_OK
    stdout = capsys.readouterr().out
    assert "| example-pick | ldhp | pyperplan | 10 | 1 | 1 | 100% (21-100%) | 1/1 |" in stdout
    assert "| example-pick | ldhp | pyperplan | 25 | 1 | 1 | 100% (21-100%) | 1/1 |" in stdout
    for name in ("time_vs_samples.png", "time_vs_samples.svg", "comparison.png", "comparison.svg"):
        assert (out / name).stat().st_size > 1000 and name in stdout
    assert not (out / "time_vs_vertices.png").exists()  # one object: no vertex figure


def test_judge_simulate_solves_with_the_simulation_judge(tmp_path: Path) -> None:
    """``judge_simulate``: every run's solve has the physics replay as a judge (``solve
    --simulate``), whose time the plan's stats then show."""
    from ldhp_tamp.plan import read_plan

    (spec,) = plan_runs([PICK], BenchOptions(judge_simulate=True))
    assert spec.judge_simulate
    spec = dataclasses.replace(spec, plan_file=str(tmp_path / "pick-plan.json"))
    (row,) = run_all([spec], BenchOptions(judge_simulate=True))
    assert row.status is BenchStatus.SOLVED
    assert "simulation" in read_plan(tmp_path / "pick-plan.json").stats.time_s
    (plain,) = plan_runs([PICK], BenchOptions())
    assert not plain.judge_simulate
