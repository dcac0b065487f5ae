"""benchmarks/comparison.py: the document's generated blocks come from the rows
(written here from a small runs.json, without running the bench)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from ldhp_tamp.bench import BenchOptions, BenchRow, BenchStatus, format_json
from ldhp_tamp.errors import InputError

REPO = Path(__file__).resolve().parents[1]


def _module():
    spec = importlib.util.spec_from_file_location("comparison", REPO / "benchmarks" / "comparison.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _row(scenario: str, planner: str, seed: int, solved: bool, t: float = 1.0, executes: bool = True) -> BenchRow:
    return BenchRow(scenario, f"scenarios/{scenario}.toml", "pyperplan" if planner.startswith("ldhp") else "",
                    seed, 100, 4, BenchStatus.SOLVED if solved else BenchStatus.FAILED,
                    "" if solved else "bottom tier, step 1: no grasp", wall_s=t + 1, time_total_s=t if solved else 2.0,
                    steps=3 if solved else 0, executes=executes if solved else None, planner=planner,
                    regrasps=1 if solved else None, finger_travel_mm=100.0 if solved else None,
                    support_margin=0.5 if solved else None)


def test_the_document_is_written_from_the_runs(tmp_path: Path) -> None:
    rows = [_row("a", "ldhp", s, True, 1.0 + s) for s in range(5)]
    rows += [_row("a", "contact-rrt", s, s < 2, 0.5, executes=s != 1) for s in range(5)]
    rows += [_row("b", "ldhp", s, s == 0) for s in range(5)] + [_row("b", "contact-rrt", s, False) for s in range(5)]
    runs = tmp_path / "runs.json"
    runs.write_text(format_json(rows, BenchOptions(planners=("ldhp", "contact-rrt"), seeds=5, timeout_s=60)))
    doc = tmp_path / "cmp.md"
    assert _module().main(["--from-runs", str(runs), "--doc", str(doc)]) == 0
    text = doc.read_text(encoding="utf-8")
    assert "| ldhp | 6/10 (31-83%) | 2/2 | 6/6 |" in text  # runs, scenarios, executing plans
    assert "| a | ldhp | 5/5 (57-100%) | 5/5 | 3.0 [2.0, 4.0] | 3.0 | 1.0 | 100 | 0.500 |" in text
    assert "| a | contact-rrt | 2/5 (12-77%) | 1/2 |" in text
    assert "Scenarios whose outcome depends on the seed: a (contact-rrt: 2/5), b (ldhp: 1/5)." in text
    assert "diverge in the physics simulation: 1 (a contact-rrt seed 1)" in text
    assert (tmp_path / "cmp" / "comparison.png").exists()
    # the prose around the blocks is kept when the document is written again
    doc.write_text(text.replace("# Planners compared", "# Planners compared\n\nProse.") , encoding="utf-8")
    assert _module().main(["--from-runs", str(runs), "--doc", str(doc)]) == 0
    assert "Prose." in doc.read_text(encoding="utf-8")


def test_a_document_without_a_block_is_refused() -> None:
    with pytest.raises(InputError, match="no block 'x'"):
        _module().replace_blocks("text\n", {"x": "body"})


def test_the_shipped_document_has_every_block() -> None:
    text = (REPO / "docs" / "comparison.md").read_text(encoding="utf-8")
    m = _module()
    for name in m.BLOCKS:
        assert m.begin(name) in text and m.end(name) in text
    assert json.loads((REPO / "docs" / "comparison" / "runs-2.json").read_text())["format"] == "ldhp-bench/1"
