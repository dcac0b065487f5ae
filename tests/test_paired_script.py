"""``benchmarks/paired.py``: two trees' solves in pairs (here the same tree twice, on the
pick example: a few solves of a fraction of a second), the report, and a worker that
fails (exit 2, its error shown).

The script is not a module of the package: it is run by path (runpy).
"""

from __future__ import annotations

import os
import runpy
from pathlib import Path
from types import SimpleNamespace

import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "benchmarks" / "paired.py"
PICK = REPO / "scenarios" / "example_pick.toml"


paired = SimpleNamespace(**runpy.run_path(str(SCRIPT), run_name="ldhp_paired_script"))


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
    bad = tmp_path / "bad.toml"
    bad.write_text("this is not a scenario\n")
    assert paired.main([str(bad), "--a", str(REPO), "--b", str(REPO), "--seeds", "1", "--reps", "1"]) == 2
    err = capsys.readouterr().err
    assert "the worker of a failed at seed 0" in err and "bad.toml" in err


def test_bad_arguments_are_refused_before_any_worker(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert paired.main([str(PICK), "--a", str(tmp_path), "--b", str(REPO)]) == 2
    assert "--a" in capsys.readouterr().err
    assert paired.main([str(tmp_path / "missing.toml"), "--a", str(REPO), "--b", str(REPO)]) == 2
    assert "missing.toml: no such scenario file" in capsys.readouterr().err
