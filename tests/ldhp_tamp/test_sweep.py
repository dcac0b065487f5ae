"""The sweep executor (:mod:`ldhp_tamp.sweep`) and the sweeps on it (bench, ablate): both
executors give the same results; a cell that crashes, hangs, raises or takes its Dask
worker down fails alone; a restarted sweep resumes.

The Dask tests run on a ``LocalCluster`` of two single-threaded workers made once for the
module (and one test on the cluster a sweep makes itself). A guard closes that cluster if
a test hangs, so the test fails instead of holding CI; every test checks that it left no
process behind (a cell's process, a Dask worker).
"""

from __future__ import annotations

import csv
import dataclasses
import faulthandler
import io
import json
import logging
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from ldhp_tamp import ablate as ablate_module
from ldhp_tamp import bench, resources
from ldhp_tamp.ablate import AblationOptions, ablate, read_csv
from ldhp_tamp.bench import BenchOptions, BenchStatus, plan_runs, run_all, run_bench
from ldhp_tamp.cli import EXIT_BAD_INPUT, main
from ldhp_tamp.errors import ExecutorError, InputError
from ldhp_tamp.sweep import SweepOptions, run_cells
from sweep_cells import TOY, crash_seed_1, crash_the_baseline, toy_run

distributed = pytest.importorskip("distributed")
psutil = pytest.importorskip("psutil")  # a dependency of distributed

PICK = resources.scenarios_dir() / "example_pick.toml"

#: A test that has not ended after this long is hung: its cluster is closed, then the
#: process dumps its stacks and exits (a guard against hanging CI, not a speed check).
HANG_GUARD_S = 600.0


# --------------------------------------------------------------------------- fixtures

def _ours() -> set[int]:
    """This process's descendants that a sweep may leave: not the forkserver (kept for
    the session) nor multiprocessing's resource tracker."""
    kids = set()
    for p in psutil.Process().children(recursive=True):
        try:
            cmd = " ".join(p.cmdline())
        except psutil.Error:
            continue
        if "forkserver" not in cmd and "resource_tracker" not in cmd:
            kids.add(p.pid)
    return kids


def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


@pytest.fixture(scope="module")
def cluster() -> Iterator[distributed.LocalCluster]:
    import dask

    # one cell per worker at a time; a task whose worker died twice is a KilledWorker
    with dask.config.set({"distributed.scheduler.worker-saturation": 1.0,
                          "distributed.scheduler.allowed-failures": 1}):
        c = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                     scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"})
    logging.getLogger("distributed").setLevel(logging.ERROR)
    try:
        yield c
    finally:
        workers = [n.pid for n in c.workers.values()]
        c.close()
        deadline = time.monotonic() + 30  # being reaped; not a speed check
        while (alive := [p for p in workers if p is not None and _alive(p)]) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not alive, f"the cluster's workers outlived it: {alive}"


@pytest.fixture(autouse=True)
def no_leftovers(request: pytest.FixtureRequest) -> Iterator[None]:
    """Every test: a hang guard, and no process of ours left at the end (the module's
    cluster aside)."""
    cluster = request.getfixturevalue("cluster") if "cluster" in request.fixturenames else None
    before = _ours()
    timer = threading.Timer(HANG_GUARD_S, cluster.close) if cluster is not None else None
    if timer is not None:
        timer.daemon = True
        timer.start()
    faulthandler.dump_traceback_later(HANG_GUARD_S + 60, exit=True)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
        if timer is not None:
            timer.cancel()
    workers = {n.pid for n in cluster.workers.values()} if cluster is not None else set()  # restarted ones
    deadline = time.monotonic() + 30  # processes being reaped; not a speed check
    while (left := _ours() - before - workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not left, f"processes left behind: {[psutil.Process(p).cmdline() for p in left]}"


def _dask(cluster: distributed.LocalCluster, **kw) -> SweepOptions:
    return SweepOptions(executor="dask", scheduler=cluster.scheduler_address, **kw)


# --------------------------------------------------------------------------- the executor

CELLS = ["a", "crash", "raise", "b"]


def _expected() -> list[tuple[str, str]]:
    import inspect

    line = inspect.getsourcelines(toy_run)[1] + 6  # the raise
    return [("ok", "a"), ("error", "the cell's process died without a result (exit status 13)"),
            ("error", f"ValueError: boom (at sweep_cells.py:{line})"), ("ok", "b")]


HUNG = [("timeout", "hard limit: no result after 1 s; the cell's process was terminated"), ("ok", "a")]


def test_local_cells_fail_alone() -> None:
    seen: list[int] = []
    results = run_cells(CELLS, TOY, SweepOptions(jobs=2), lambda i, _r: seen.append(i))
    assert results == _expected()
    assert sorted(seen) == list(range(len(CELLS)))
    # a cell past the hard limit is stopped (the other only needs to start within it)
    assert run_cells(["hang"], TOY, SweepOptions(hard_limit_s=1.0)) == HUNG[:1]


def test_dask_cells_fail_alone(cluster: distributed.LocalCluster) -> None:
    seen: list[int] = []
    results = run_cells(CELLS, TOY, _dask(cluster), lambda i, _r: seen.append(i))
    assert results == _expected()
    assert sorted(seen) == list(range(len(CELLS)))
    assert run_cells(["hang"], TOY, _dask(cluster, hard_limit_s=1.0)) == HUNG[:1]


def test_a_dask_worker_that_dies_fails_its_cell_only(cluster: distributed.LocalCluster) -> None:
    results = run_cells(["a", "kill-worker", "b"], TOY, _dask(cluster, hard_limit_s=60.0))
    assert results[0] == ("ok", "a") and results[2] == ("ok", "b")
    status, reason = results[1]
    assert status == "error" and reason.startswith("the Dask worker running the cell failed: KilledWorker")
    cluster.wait_for_workers(2)  # the nannies restarted it


def test_sweep_options_are_checked() -> None:
    with pytest.raises(InputError, match="--executor"):
        SweepOptions(executor="ray")
    with pytest.raises(InputError, match="--scheduler: a scheduler address needs --executor dask"):
        SweepOptions(scheduler="tcp://localhost:8786")
    with pytest.raises(InputError, match="tcp://HOST:PORT"):
        SweepOptions(executor="dask", scheduler="localhost")
    with pytest.raises(InputError, match="--jobs"):
        SweepOptions(jobs=0)
    with pytest.raises(InputError, match="hard limit"):
        SweepOptions(hard_limit_s=0)
    assert run_cells([], TOY, SweepOptions(executor="dask")) == []  # nothing to run: no cluster


def test_dask_without_distributed_is_an_executor_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    with pytest.raises(ExecutorError, match=r"pip install 'ldhp-tamp\[dask\]'"):
        run_cells(["a"], TOY, SweepOptions(executor="dask"))


@pytest.mark.parametrize("argv, named", [
    (["--scheduler", "tcp://localhost:8786"], "--scheduler"),
    (["--executor", "dask", "--scheduler", "localhost"], "tcp://HOST:PORT"),
])
@pytest.mark.parametrize("command", ["bench", "ablate"])
def test_bad_executor_options_exit_2(command: str, argv: list[str], named: str, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    out = ["--out", str(tmp_path / "never")] if command == "bench" else ["--csv", str(tmp_path / "never.csv")]
    assert main([command, str(PICK), *argv, *out]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.startswith("error: ") and named in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


# --------------------------------------------------------------------------- bench

def _knobs(row: bench.BenchRow) -> dict:
    """A row without its times (which differ from run to run)."""
    return {k: v for k, v in row.as_dict().items() if not (k.startswith("time_") or k.endswith("wall_s"))}


def test_bench_on_its_own_local_cluster_gives_the_local_rows() -> None:
    options = BenchOptions(seeds=2, jobs=2, simulate=False, timeout_s=120, samples=(10,))
    specs = plan_runs([PICK], options)
    local = run_all(specs, options)
    on_dask = run_all(specs, dataclasses.replace(options, executor="dask"))  # a LocalCluster of 2 workers
    assert [r.status for r in local] == [BenchStatus.SOLVED] * 2
    assert [_knobs(r) for r in on_dask] == [_knobs(r) for r in local]
    assert all(r.wall_s >= r.time_total_s > 0 for r in on_dask)


def test_a_bench_run_that_crashes_fails_its_row_only(cluster: distributed.LocalCluster) -> None:
    options = BenchOptions(seeds=2, simulate=False, samples=(10,))
    task = dataclasses.replace(bench._TASK, run=crash_seed_1)
    rows = run_cells(plan_runs([PICK], options), task, _dask(cluster))
    assert rows[0].status is BenchStatus.SOLVED and rows[0].steps
    assert rows[1].status is BenchStatus.ERROR and rows[1].seed == 1
    assert rows[1].reason == "the cell's process died without a result (exit status 13)"


def test_a_restarted_bench_resumes(cluster: distributed.LocalCluster, tmp_path: Path) -> None:
    made: list[str] = []

    def progress(msg: str) -> None:
        if msg.startswith("["):
            made.append(msg)

    one = BenchOptions(seeds=1, simulate=False, samples=(10,), executor="dask",
                       scheduler=cluster.scheduler_address)
    (first,), _ = run_bench([PICK], one, tmp_path, progress, resume=True)
    assert len(made) == 1 and first.status is BenchStatus.SOLVED
    # restarted with one more seed: only that seed runs, the first row is kept as it was
    two = dataclasses.replace(one, seeds=2)
    made.clear()
    rows, files = run_bench([PICK], two, tmp_path, progress, resume=True)
    assert len(made) == 1 and "seed=1" in made[0]
    assert rows[0] == first and rows[1].seed == 1 and rows[1].status is BenchStatus.SOLVED
    # everything done: nothing runs
    made.clear()
    again, _ = run_bench([PICK], two, tmp_path, progress, resume=True)
    assert made == [] and again == rows
    # an error row (a crash) runs again
    doc = json.loads(files.json.read_text())
    doc["rows"][1].update(status="error", reason="the worker was lost")
    files.json.write_text(json.dumps(doc))
    made.clear()
    third, _ = run_bench([PICK], two, tmp_path, progress, resume=True)
    assert len(made) == 1 and "seed=1" in made[0] and third[1].status is BenchStatus.SOLVED
    assert third[0] == first
    # without resume every run is made again
    made.clear()
    run_bench([PICK], two, tmp_path, progress)
    assert len(made) == 2
    # runs of another configuration are not mixed in
    with pytest.raises(InputError, match="timeout_s"):
        run_bench([PICK], dataclasses.replace(two, timeout_s=30), tmp_path, progress, resume=True)


def test_cli_bench_refuses_to_resume_another_configuration(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "runs.json").write_text(json.dumps({"format": "ldhp-bench/1", "columns": ["x"], "rows": []}))
    assert main(["bench", str(PICK), "--out", str(tmp_path), "--no-simulate"]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "runs.json: cannot resume from it" in err and "--fresh" in err


# --------------------------------------------------------------------------- ablate

def test_an_ablation_cell_that_crashes_fails_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ablate_module, "_TASK", dataclasses.replace(ablate_module._TASK, run=crash_the_baseline))
    table = ablate([PICK], AblationOptions(remove=("slide",), jobs=2))
    base, slide = (row.cells[0] for row in table.rows)
    assert base.status == "error" and "exit status 13" in base.reason and not base.feasible
    assert slide.status == "solved" and slide.feasible


def test_ablation_on_dask_and_resumed(cluster: distributed.LocalCluster, tmp_path: Path) -> None:
    out = tmp_path / "table3.csv"
    made: list[str] = []

    def progress(msg: str) -> None:
        if msg.startswith("["):
            made.append(msg)

    options = AblationOptions(remove=("slide", "air-move"), executor="dask", scheduler=cluster.scheduler_address)
    table = ablate([PICK], options, progress, csv_path=out, resume=True)
    assert len(made) == 3
    assert [c.mark for row in table.rows for c in row.cells] == ["Y", "N", "Y"]
    assert read_csv(out) == tuple(dataclasses.replace(c, scenario_file="", time_s=round(c.time_s, 3),
                                                      reason=" ".join(c.reason.split()))
                                  for row in table.rows for c in row.cells)  # what a resume reads back
    # a CSV cut short (an interrupted ablation), and a cell that crashed: both solved again
    lines = out.read_text().splitlines()
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    rows[1][5] = "error"
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows[:3])
    out.write_text(buf.getvalue())
    made.clear()
    again = ablate([PICK], options, progress, csv_path=out, resume=True)
    assert len(made) == 2 and "baseline" in made[0] + made[1] and "without slide" in made[0] + made[1]
    assert [c.mark for row in again.rows for c in row.cells] == ["Y", "N", "Y"]
    assert out.read_text().splitlines()[1:] != [] and len(read_csv(out)) == 3
    made.clear()
    ablate([PICK], options, progress, csv_path=out, resume=True)
    assert made == []  # all done


def test_the_cli_offers_the_sweep_executors() -> None:
    """The parser names the executors without importing the sweep module."""
    from ldhp_tamp import cli
    from ldhp_tamp.sweep import EXECUTORS

    assert tuple(cli._EXECUTORS) == tuple(EXECUTORS)


def test_bench_and_ablate_workers_preload_the_planner_and_its_engines() -> None:
    """A cell's ``time_s`` counts no import: the forkserver has imported the planner and
    made the engines (``ldhp_tamp.solver_preload``), which a solve would otherwise make."""
    import subprocess
    import sys

    from ldhp_tamp import ablate, bench

    assert "ldhp_tamp.solver_preload" in bench._TASK.preload
    assert "ldhp_tamp.solver_preload" in ablate._TASK.preload
    code = ("import ldhp_tamp.solver_preload, sys; import unified_planning.environment as e; "
            "assert 'ldhp_tamp.tamp' in sys.modules and e.GLOBAL_ENVIRONMENT._factory is not None")
    subprocess.run([sys.executable, "-c", code], check=True)
