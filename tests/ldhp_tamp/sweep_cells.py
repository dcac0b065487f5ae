"""Cells for tests/ldhp_tamp/test_sweep.py, in a module of their own: a cell's process
imports the module of its functions, and this one is light (no pytest, no Dask)."""

from __future__ import annotations

import os
import signal
import time

from ldhp_tamp import ablate, bench
from ldhp_tamp.sweep import CellFailure, CellTask


def toy_run(cell: str) -> tuple[str, str]:
    if cell == "crash":
        os._exit(13)
    if cell == "hang":
        time.sleep(3600)
    if cell == "raise":
        raise ValueError("boom")
    if cell == "kill-worker":  # the Dask worker running this cell dies
        os.kill(os.getppid(), signal.SIGKILL)
        time.sleep(3600)
    return ("ok", cell)


def toy_failed(cell: str, failure: CellFailure, reason: str, wall_s: float) -> tuple[str, str]:
    assert wall_s >= 0
    return (failure.value, reason)


TOY = CellTask(run=toy_run, failed=toy_failed, name="toy")


def crash_seed_1(spec: bench.RunSpec) -> bench.BenchRow:
    """A bench run whose process dies for seed 1."""
    if spec.seed == 1:
        os._exit(13)
    return bench.solve_run(spec)


def crash_the_baseline(job: ablate._Job) -> ablate.AblationCell:
    """An ablation cell whose process dies for the baseline."""
    if job.removed == "none":
        os._exit(13)
    return ablate._solve_job(job)
