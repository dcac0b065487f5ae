"""``benchmarks/results.py``: the marker replacement, the sequence compression, the
comparison with the paper's Table III, bad input, and one small end-to-end run on the
pick example (about a second of solving).

The script is not a module of the package: it is imported by path.
"""

from __future__ import annotations

import doctest
import importlib.util
import logging
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest

from ldhp_tamp.ablate import BASELINE, AblationCell, AblationRow, AblationTable
from ldhp_tamp.plan import PlanStatus, read_plan
from ldhp_tamp.primitives.registry import Family

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "benchmarks" / "results.py"


def _load() -> ModuleType:
    spec = importlib.util.spec_from_file_location("ldhp_results_script", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


results = _load()

DOC = (
    "# Our results\r\n"  # a CRLF line and odd spacing outside the blocks must survive
    "Intro   with  spaces, ünïcode ≠ and a trailing tab\t\n"
    "<!-- BEGIN generated: suite -->\nold suite\nmore old\n<!-- END generated: suite -->\n"
    "\n_Commentary: the slot is narrower than the paper's._\n\n"
    "<!-- BEGIN generated: ablation --><!-- END generated: ablation -->"
    "no newline at the end"
)


# --------------------------------------------------------------------------- markers


def test_replace_blocks_changes_only_the_inside_of_the_markers() -> None:
    out = results.replace_blocks(DOC, {"suite": "NEW\nTABLE\n"})
    begin, end = "<!-- BEGIN generated: suite -->", "<!-- END generated: suite -->"
    assert "old suite" not in out and "NEW" in out
    # everything up to the end of BEGIN and from END on is the same bytes
    assert out[: out.index(begin) + len(begin)] == DOC[: DOC.index(begin) + len(begin)]
    assert out[out.index(end):] == DOC[DOC.index(end):]
    between = out[out.index(begin) + len(begin): out.index(end)]
    assert between.replace("\r\n", "\n") == "\nNEW\nTABLE\n"


def test_replace_blocks_with_two_blocks_and_an_empty_one() -> None:
    out = results.replace_blocks(DOC, {"ablation": "| a |", "suite": "S"})
    assert results.find_block(out, "ablation") != results.find_block(DOC, "ablation")
    start, end = results.find_block(out, "ablation")
    assert out[start:end].strip() == "| a |"
    start, end = results.find_block(out, "suite")
    assert out[start:end].strip() == "S"
    assert out.endswith("<!-- END generated: ablation -->no newline at the end")
    assert "_Commentary: the slot is narrower than the paper's._" in out


def test_replacing_with_the_same_content_twice_is_stable() -> None:
    once = results.replace_blocks(DOC, {"suite": "X"})
    assert results.replace_blocks(once, {"suite": "X"}) == once


def test_generated_text_takes_the_documents_line_ends() -> None:
    crlf = "a\r\n<!-- BEGIN generated: suite -->\r\nold\r\n<!-- END generated: suite -->\r\nb\r\n"
    out = results.replace_blocks(crlf, {"suite": "one\ntwo"})
    assert out == crlf.replace("old", "one\r\ntwo")


@pytest.mark.parametrize("text, named", [
    ("<!-- END generated: suite -->", "<!-- BEGIN generated: suite -->"),
    ("<!-- BEGIN generated: suite -->", "<!-- END generated: suite -->"),
    ("<!-- BEGIN generated: suite --><!-- BEGIN generated: suite --><!-- END generated: suite -->",
     "<!-- BEGIN generated: suite --> appears 2 times"),
    ("<!-- END generated: suite --><!-- BEGIN generated: suite -->", "comes before"),
])
def test_a_missing_or_broken_marker_is_an_error_naming_it(text: str, named: str) -> None:
    with pytest.raises(results.MarkerError, match="doc.md") as info:
        results.replace_blocks(text, {"suite": "x"}, "doc.md")
    assert named in str(info.value)


def test_read_document_checks_every_marker(tmp_path: Path) -> None:
    path = tmp_path / "results.md"
    text = results.skeleton().replace("<!-- END generated: figures -->", "")
    path.write_text(text, encoding="utf-8")
    with pytest.raises(results.MarkerError, match="END generated: figures -->"):
        results.read_document(path)


def test_a_missing_document_is_the_skeleton(tmp_path: Path) -> None:
    text = results.read_document(tmp_path / "absent.md")
    assert text == results.skeleton()
    assert text.startswith("# Results\n") and "benchmarks/results.py" in text.split("##")[0]
    results.check_markers(text)  # every block, once
    order = [text.index(f"<!-- BEGIN generated: {name} -->") for name in results.BLOCKS]
    assert order == sorted(order)
    placeholder = "_Commentary: to be written by the maintainers._"
    assert text.count(placeholder) == 2
    # after the suite (its details) and after the ablation, before the next block
    assert (text.index("<!-- END generated: suite-details -->") < text.index(placeholder)
            < text.index("<!-- BEGIN generated: ablation -->"))
    assert (text.index("<!-- END generated: ablation -->") < text.rindex(placeholder)
            < text.index("<!-- BEGIN generated: figures -->"))


# --------------------------------------------------------------------------- formatting


@pytest.mark.parametrize("names, expected", [
    (["tip", "slide", "slide", "slide", "push"], "tip, slide x3, push"),
    (["slide", "slide", "tip", "slide"], "slide x2, tip, slide"),
    (["air-move"], "air-move"),
    ([], "-"),
])
def test_compress_sequence(names: list[str], expected: str) -> None:
    assert results.compress_sequence(names) == expected


def test_shorten_and_cells() -> None:
    long = "timeout: " + "x" * 300
    short = results.shorten(long)
    assert len(short) == results.REASON_CELL_CHARS and short.endswith("…") and short.startswith("timeout: x")
    assert results.md_cell("a | b\nc") == "a \\| b c"


def _bench_row(scenario: str, status: str, reason: str = "", **counts: float | int) -> "BenchRow":
    from ldhp_tamp.bench import BenchRow, BenchStatus

    return BenchRow(scenario, f"scenarios/{scenario}.toml", "pyperplan", 0, 100, 4, BenchStatus(status), reason,
                    12.5, **counts)  # type: ignore[arg-type]


def test_suite_table_shortens_reasons_and_details_keep_them_whole(tmp_path: Path) -> None:
    long = "no contact-state path | after 3 iterations: " + "the bottom tier failed on pose path; " * 10
    doc = tmp_path / "results.md"
    entries = [
        results.SuiteEntry("ok", _bench_row("ok", "solved", steps=3, time_total_s=1.234), tmp_path / "results"
                           / "plans" / "ok-plan.json", ("tip", "tip", "push"), True),
        results.SuiteEntry("bad", _bench_row("bad", "failed", long, steps=0), None, (), None),
        results.SuiteEntry("odd", _bench_row("odd", "solved", steps=1), None, ("tip",), False,
                           ("rule 7 (support), step 0: unsupported",)),
    ]
    table = results.format_suite(entries, doc, "STAMP").splitlines()
    ok = next(line for line in table if line.startswith("| [ok](results/plans/ok-plan.json) | solved | yes |"))
    assert "| tip x2, push | 3 |" in ok and "| 1.23 |" in ok
    bad = next(line for line in table if line.startswith("| bad | failed | - | - | - | 0 |"))
    cell = bad.rsplit(" | ", 1)[1].rstrip(" |")
    assert cell.endswith("…") and cell.startswith("no contact-state path \\| after")
    assert results.REASON_CELL_CHARS - 5 < len(cell.replace("\\|", "|")) <= results.REASON_CELL_CHARS
    assert table[2].startswith("3 scenario(s): 2 solved (1 validated again, 0 executing in the physics simulation), "
                               "1 failed.")
    details = results.format_suite_details(entries, "STAMP")
    assert f"- `bad` (**failed**, 12.5 s wall): {' '.join(long.split())}" in details
    assert "- `odd` (**solved, not validated**, 12.5 s wall): the plan does not validate: rule 7" in details
    assert "`ok`" not in details


def test_doctests_of_the_script() -> None:
    failed, tried = doctest.testmod(results)
    assert tried > 0 and failed == 0


# --------------------------------------------------------------------------- the paper's Table III


def test_paper_table_is_the_papers() -> None:
    t = results.PAPER_TABLE3
    removed = [r for r in t if r != BASELINE]
    assert sorted(r for r in removed if t[r][0]) == ["slide"]
    assert sorted(r for r in removed if t[r][1]) == ["close", "slide", "tip"]
    from ldhp_tamp import symbolic
    from ldhp_tamp.resources import domains_dir

    assert set(removed) == set(symbolic.load_domain(domains_dir() / "ldhp.pddl").info.names())


def _cell(removed: str, scenario: str, feasible: bool, status: str = "", reason: str = "",
          primitives: tuple[str, ...] = ()) -> AblationCell:
    status = status or ("solved" if feasible else "failed")
    return AblationCell(removed, scenario, f"{scenario}.toml", feasible, status, reason, 0.1, primitives)


def _table() -> AblationTable:
    s1, s2 = "task1-zero-mobility-lift", "task2-slot-insertion"
    rows = (
        AblationRow(BASELINE, None, (_cell(BASELINE, s1, True, primitives=("tip", "slide", "slide")),
                                     _cell(BASELINE, s2, True))),
        AblationRow("tip", Family.MOVE_OBJECT, (_cell("tip", s1, True, primitives=("push",)),  # paper: N
                                                _cell("tip", s2, True))),
        AblationRow("push", Family.MOVE_OBJECT, (_cell("push", s1, False, "timeout", "timeout: 5 s ran out"),
                                                 _cell("push", s2, False))),
        AblationRow("close", Family.ADJUST_GRASP, (_cell("close", s1, False),
                                                   _cell("close", s2, False))),  # paper: Y
        AblationRow("lift", Family.MOVE_OBJECT, (_cell("lift", s1, False), _cell("lift", s2, True))),  # not in paper
    )
    return AblationTable("domains/ldhp.pddl", (s1, s2), rows)


def test_compare_with_the_paper_finds_the_disagreements() -> None:
    rows = results.compare_with_paper(_table())
    by = {r.removed: r for r in rows}
    assert [c.disagrees for c in by["tip"].cells] == [True, False]
    assert [c.disagrees for c in by["close"].cells] == [False, True]
    assert [c.disagrees for c in by[BASELINE].cells] == [False, False]
    assert [c.disagrees for c in by["push"].cells] == [False, False]
    assert [c.paper for c in by["lift"].cells] == [None, None]  # ours only: nothing to compare
    assert not any(c.disagrees for c in by["lift"].cells)
    # the paper's primitives our table lacks come last, without our value
    missing = [r.removed for r in rows if r.family == "not in our domain"]
    assert set(missing) == set(results.PAPER_TABLE3) - {BASELINE, "tip", "push", "close"}
    assert all(c.ours is None and not c.disagrees for r in rows if r.removed in missing for c in r.cells)


def test_format_ablation_marks_each_disagreement() -> None:
    table = _table()
    text = results.format_ablation(results.compare_with_paper(table), table.scenarios, "STAMP")
    lines = text.splitlines()
    assert lines[0] == "STAMP"
    assert "| none (baseline) | - | Y | Y | Y | Y |" in lines
    assert "| tip | move-object | **Y** ≠ | N | Y | Y |" in lines
    assert "| push | move-object | N (timeout) | N | N | N |" in lines
    assert "| close | adjust-grasp | N | N | **N** ≠ | Y |" in lines
    assert "| lift | move-object | N | - | Y | - |" in lines
    assert "| flip | not in our domain | - | N | - | N |" in lines
    assert sum(line.count("≠") for line in lines if line.startswith("| ")) == 2
    assert "6 of 8 cells agree with the paper: differ without tip (task 1), without close (task 2)." in lines
    assert "- without push, task 1: timeout: timeout: 5 s ran out" in lines
    assert "- baseline, task 1: tip, slide x2" in lines and "- without tip, task 1: push" in lines


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("argv, named", [
    (["--only", "no_such_scenario"], "no_such_scenario"),
    (["--only", "example_pick,nope"], "nope"),
    (["--timeout", "0"], "--timeout"),
    (["--timeout", "-5"], "--timeout"),
    (["--jobs", "0"], "--jobs"),
    (["--jobs", "two"], "--jobs"),
])
def test_bad_input_exits_2_with_one_line(argv: list[str], named: str, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "results.md"
    try:
        code = results.main([*argv, "--skip-ablation", "--skip-figures", "--out", str(out)])
    except SystemExit as exc:  # argparse's exit
        code = exc.code
    assert code == 2
    stdout, stderr = capsys.readouterr()
    assert stdout == "" and named in stderr and "Traceback" not in stderr
    assert len(stderr.strip().splitlines()) == 1
    assert not out.exists() and not (tmp_path / "results").exists()  # nothing ran, nothing written


def test_a_missing_marker_exits_2_before_anything_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "results.md"
    text = results.skeleton().replace("<!-- BEGIN generated: suite-details -->\n", "")
    out.write_text(text, encoding="utf-8")
    code = results.main(["--only", "example_pick", "--skip-ablation", "--skip-figures", "--out", str(out)])
    assert code == 2
    stderr = capsys.readouterr().err
    assert "<!-- BEGIN generated: suite-details -->" in stderr and "is missing" in stderr
    assert out.read_text(encoding="utf-8") == text
    assert not (tmp_path / "results").exists()


# --------------------------------------------------------------------------- end to end


@pytest.fixture(scope="module")
def pick_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str, str, int]:
    """One run on the pick example into a document that has hand-written text and an old
    ablation block: (document, its text before, after, exit status)."""
    out = tmp_path_factory.mktemp("results") / "results.md"
    before = results.replace_blocks(results.skeleton(), {"ablation": "OLD ABLATION, KEPT"}).replace(
        "_Commentary: to be written by the maintainers._", "Hand-written: *why* task 2 differs.  \t", 1)
    out.write_text(before, encoding="utf-8")
    code = results.main(["--only", "example_pick", "--skip-ablation", "--skip-figures", "--out", str(out),
                         "--timeout", "60"])
    return out, before, out.read_text(encoding="utf-8"), code


def test_end_to_end_on_the_pick_example(pick_run: tuple[Path, str, str, int],
                                        capsys: pytest.CaptureFixture[str]) -> None:
    out, before, after, code = pick_run
    assert code == 0
    plan_file = out.parent / "results" / "plans" / "example_pick-plan.json"
    plan = read_plan(plan_file)
    assert plan.status is PlanStatus.SOLVED and plan.scenario == "example-pick"
    start, end = results.find_block(after, "suite")
    suite = after[start:end]
    row = next(line for line in suite.splitlines() if line.startswith("| [example_pick]"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[:5] == ["[example_pick](results/plans/example_pick-plan.json)", "solved", "yes", "yes",
                         "approach-contact, air-move"]
    assert int(cells[5]) == len(plan.steps) and int(cells[6]) == len(plan.waypoints)
    assert int(cells[12]) == plan.stats.feasibility_checks > 0
    assert float(cells[16]) == pytest.approx(plan.stats.time_s["total"], abs=0.006)
    assert cells[17] == ""  # no reason
    assert "1 scenario(s): 1 solved (1 validated again, 1 executing in the physics simulation)" in suite
    assert "| [task2_slot_insertion]" not in suite  # --only limits what is written
    start, end = results.find_block(after, "suite-details")
    assert "Every scenario was solved, its plan validated and executed in the physics simulation." in after[start:end]
    start, end = results.find_block(after, "context")
    context = after[start:end]
    assert "--only example_pick --skip-ablation --skip-figures" in context and "Timeout: 60 s" in context
    assert "jobs: 1" in context and "Commit: `" in context and "kept from an earlier run: ablation, figures" in context
    # skipped blocks and everything outside the blocks are as they were
    for name in ("ablation", "figures"):
        s0, e0 = results.find_block(before, name)
        s1, e1 = results.find_block(after, name)
        assert after[s1:e1] == before[s0:e0]
    assert "OLD ABLATION, KEPT" in after
    assert after.index("Hand-written: *why* task 2 differs.  \t") > 0
    assert _outside(after) == _outside(before)


def _outside(text: str) -> list[str]:
    """The text outside every generated block (markers included), in order."""
    parts, pos = [], 0
    for start, end in sorted(results.find_block(text, name) for name in results.BLOCKS):
        parts.append(text[pos:start])
        pos = end
    return [*parts, text[pos:]]


def test_figures_keep_only_the_pngs_and_lower_the_dpi(pick_run: tuple[Path, str, str, int], tmp_path: Path,
                                                      caplog: pytest.LogCaptureFixture) -> None:
    out = pick_run[0]
    plan_file = out.parent / "results" / "plans" / "example_pick-plan.json"
    scenario = REPO / "scenarios" / "example_pick.toml"
    figures = results.render_pngs(plan_file, scenario, tmp_path / "fig", dpis=(50,))
    assert figures.dpi == 50 and sorted(p.name for p in (tmp_path / "fig").iterdir()) == sorted(results.FIGURE_PNGS)
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in figures.files)
    caplog.set_level(logging.WARNING, logger="results")
    small = results.render_pngs(plan_file, scenario, tmp_path / "small", dpis=(40, 20), limit=1)
    assert small.dpi == 20 and any("even at 20 dpi" in r.getMessage() for r in caplog.records)
    text = results.format_figures([figures], {"task2_slot_insertion": "the run is timeout"}, out, "STAMP")
    for name in results.FIGURE_PNGS:  # linked relative to the document's folder
        link = Path(os.path.relpath(tmp_path / "fig" / name, out.parent)).as_posix()
        assert f"![fig: {Path(name).stem.replace('_', ' ')}]({link})" in text
    assert ".gif" not in text and ".svg)" not in text
    assert "### `task2_slot_insertion`\n\nNo figures: the run is timeout." in text
