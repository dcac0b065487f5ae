"""``benchmarks/paired.py``: two trees' solves in pairs (here the same tree twice, on the
pick example: a few solves of a fraction of a second), the report, and a worker that
fails (exit 2, its error shown).

The script is not a module of the package: it is imported by path.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "benchmarks" / "paired.py"
PICK = REPO / "scenarios" / "example_pick.toml"


def _load() -> ModuleType:
    spec = importlib.util.spec_from_file_location("ldhp_paired_script", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


paired = _load()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="the workers fork a child per solve")
def test_pairs_alternate_and_the_report_compares_them() -> None:
    res = paired.paired(REPO, REPO, PICK, seeds=2, reps=1)
    assert [r["status"] for r in res["a"] + res["b"]] == ["solved"] * 4
    assert all(float(r["total"]) > 0 for r in res["a"] + res["b"])
    text = paired.report(res)
    assert "a: 2/2 solved" in text and "b: 2/2 solved" in text
    assert "b faster in" in text and "of 2" in text
    assert "the same outcome and number of steps in every pair" in text


def test_the_report_says_when_outcomes_differ() -> None:
    row = dict(total=1.0, setup=0.1, symbolic=0.1, streams=0.1, grasp_graph=0.5, status="solved", steps=5)
    res = {"a": [row, row], "b": [dict(row, total=0.8), dict(row, steps=6, total=1.3)]}
    text = paired.report(res)
    assert "paired b - a: median +0.050 s, mean +0.050 s, b faster in 1 of 2" in text
    assert "OUTCOMES DIFFER" in text


def test_a_failing_worker_is_reported(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "missing.toml"
    assert paired.main([str(bad), "--a", str(REPO), "--b", str(REPO), "--seeds", "1", "--reps", "1"]) == 2
    err = capsys.readouterr().err
    assert "the worker of a failed at seed 0" in err and "missing.toml" in err
