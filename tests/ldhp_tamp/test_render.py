"""``ldhp-tamp render`` and :mod:`ldhp_tamp.render`: the figures of a plan.

Renders the spec's example plan (through the CLI), a plan the planner makes for
``scenarios/example_pick.toml`` and a failed plan, with small figures (few frames, low
resolution) to stay fast; checks the files are what they claim (PNG, SVG, GIF with
frames), what the figures are built from (panels, frames, the graph's path), the exit
codes, and that bad input or a failure writes nothing.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from PIL import Image

from ldhp_tamp import render
from ldhp_tamp.cli import EXIT_BAD_INPUT, EXIT_OK, main
from ldhp_tamp.errors import PlanFormatError, ScenarioError
from ldhp_tamp.plan import Plan, PlanStatus, read_plan
from ldhp_tamp.render import (FIGURE_FILES, PathEdge, RenderError, RenderOptions, contact_graph_data,
                              frame_indices, render_files, render_plan, snapshots)
from ldhp_tamp.scenario import Scenario, load_scenario

REPO = Path(__file__).resolve().parents[2]
SPEC = REPO / "tests" / "data" / "spec"
SPEC_PLAN, SPEC_SCENARIO = SPEC / "pick-plan.json", SPEC / "pick.toml"
PICK = REPO / "scenarios" / "example_pick.toml"
TASK1 = REPO / "scenarios" / "task1_zero_mobility_lift.toml"
SMALL = RenderOptions(max_frames=6, dpi=40, gif_width=200)
SMALL_ARGS = ["--max-frames", "6", "--dpi", "40"]
NAMES = sorted(n for files in FIGURE_FILES.values() for n in files)


def _check_files(out: Path, max_frames: int, min_frames: int = 2) -> None:
    """Every figure file is there and is what its suffix says; nothing else is."""
    assert sorted(p.name for p in out.iterdir()) == NAMES  # no temporary file left over
    for name in NAMES:
        path = out / name
        if name.endswith(".svg"):
            root = ET.parse(path).getroot()
            assert root.tag == "{http://www.w3.org/2000/svg}svg"
            assert len(list(root.iter())) > 50  # drawn, not an empty page
            continue
        with Image.open(path) as im:
            assert im.format == ("PNG" if name.endswith(".png") else "GIF")
            assert im.width > 40 and im.height > 40
            if im.format == "GIF":
                assert min_frames <= im.n_frames <= max_frames
                assert im.info.get("loop") == 0
            im.verify()


# --------------------------------------------------------------------------------------
# The spec's example plan, through the CLI
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def spec_figures(tmp_path_factory: pytest.TempPathFactory) -> tuple[int, Path]:
    out = tmp_path_factory.mktemp("spec") / "figures"
    code = main(["render", str(SPEC_PLAN), "--scenario", str(SPEC_SCENARIO), "--out", str(out), *SMALL_ARGS])
    return code, out


def test_cli_renders_the_spec_example(spec_figures: tuple[int, Path]) -> None:
    code, out = spec_figures
    assert code == EXIT_OK
    _check_files(out, max_frames=6)


def test_spec_example_panels() -> None:
    plan, scenario = read_plan(SPEC_PLAN), load_scenario(SPEC_SCENARIO, check_planner=False)
    panels = snapshots(plan, scenario)
    assert [p.title for p in panels] == ["step 0 · approach-contact", "step 1 · close", "step 2 · air-move", "end"]
    assert [p.steps for p in panels] == [(0,), (1,), (2,), ()]
    # each panel starts at its step's first waypoint; the last one is the final waypoint
    firsts = [0, 31, 36]
    assert [p.index for p in panels] == [*firsts, 56]
    assert "at the goal" in panels[-1].subtitle


def test_spec_example_graph_places_foreign_state_names_by_geometry() -> None:
    """The spec's plan calls the table top e1; the scenario's own numbering makes it e3."""
    plan, scenario = read_plan(SPEC_PLAN), load_scenario(SPEC_SCENARIO, check_planner=False)
    graph = contact_graph_data(plan, scenario)
    assert graph.path == (PathEdge(2, "air-move", "l1-e3", "free"),)
    assert graph.start == "l1-e3" and graph.goal == "free"
    assert {"l1-e3", "free"} <= set(graph.states) and graph.extra == ()
    assert any("l1-e1 → l1-e3" in note for note in graph.notes)


def test_default_out_dir_is_next_to_the_plan() -> None:
    assert render.default_out_dir("/some/where/plan.json") == Path("/some/where/plan-figures")


# --------------------------------------------------------------------------------------
# A plan made by the planner
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def pick() -> tuple[Plan, Scenario]:
    from ldhp_tamp.tamp import solve

    scenario = load_scenario(PICK)
    result = solve(scenario)
    assert result.solved, result.reason
    return result.plan, scenario


@pytest.fixture(scope="module")
def pick_figures(pick: tuple[Plan, Scenario], tmp_path_factory: pytest.TempPathFactory) -> render.RenderedFigures:
    plan, scenario = pick
    return render_plan(plan, scenario, tmp_path_factory.mktemp("pick") / "out", SMALL)


def test_renders_a_solved_plan(pick: tuple[Plan, Scenario], pick_figures: render.RenderedFigures) -> None:
    plan, scenario = pick
    out = pick_figures.out_dir
    _check_files(out, max_frames=6)
    assert set(pick_figures.paths) == {out / n for n in NAMES}
    assert pick_figures.frames == 6 and not pick_figures.task_only
    assert pick_figures.panels == len(plan.steps) + 1
    graph = contact_graph_data(plan, scenario)
    moves = [(i, s) for i, s in enumerate(plan.steps) if s.family.value == "move-object"]
    assert [(e.step, e.primitive, e.source, e.target) for e in graph.path] == \
        [(i, s.primitive, *s.contact_state) for i, s in moves]
    assert all(n in graph.states for e in graph.path for n in (e.source, e.target))
    assert graph.notes == ()


def test_rendering_again_replaces_the_files(pick: tuple[Plan, Scenario], pick_figures: render.RenderedFigures,
                                            tmp_path: Path) -> None:
    plan, scenario = pick
    out = tmp_path / "out"
    shutil.copytree(pick_figures.out_dir, out)
    (out / "snapshots.png").write_bytes(b"stale")
    render_plan(plan, scenario, out, dataclasses.replace(SMALL, graph=False))
    _check_files(out, max_frames=6)


# --------------------------------------------------------------------------------------
# A failed plan: the task is drawn
# --------------------------------------------------------------------------------------


def _failed(plan: Plan) -> Plan:
    return dataclasses.replace(plan, status=PlanStatus.FAILED, steps=(), reason="symbolic tier: no plan")


def test_renders_a_failed_plan_as_the_task(pick: tuple[Plan, Scenario], tmp_path: Path) -> None:
    plan, scenario = pick
    failed = _failed(plan)
    panels = snapshots(failed, scenario)
    assert len(panels) == 1 and panels[0].title == "no plan (failed)"
    graph = contact_graph_data(failed, scenario, build=False)
    assert graph.path == () and graph.states == ()
    figures = render_plan(failed, scenario, tmp_path / "out", dataclasses.replace(SMALL, graph=False))
    assert figures.task_only and figures.frames == 1 and figures.panels == 1
    _check_files(tmp_path / "out", max_frames=1, min_frames=1)


# --------------------------------------------------------------------------------------
# Frames
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("steps, budget", [
    ([0] * 3 + [1] * 200 + [2] * 2 + [3] * 40, 150),
    ([0] * 3 + [1] * 200 + [2] * 2 + [3] * 40, 10),
    ([0] * 400, 150),
    (list(range(300)), 150),  # a step per waypoint: too many steps to keep them all
    ([0, 0, 1], 150),
])
def test_frame_indices(steps: list[int], budget: int) -> None:
    idx = frame_indices(steps, budget)
    n = len(steps)
    assert idx == sorted(set(idx)) and idx[0] == 0 and idx[-1] == n - 1
    assert len(idx) == min(n, budget)
    firsts = [i for i in range(n) if i == 0 or steps[i] != steps[i - 1]]
    if len(firsts) + 1 <= budget // 2:
        assert set(firsts) <= set(idx)


def test_render_options_refuse_nonsense() -> None:
    with pytest.raises(ValueError):
        RenderOptions(max_frames=1)
    with pytest.raises(ValueError):
        RenderOptions(columns=0)


# --------------------------------------------------------------------------------------
# Bad input: exit 2, a message naming the file, nothing written
# --------------------------------------------------------------------------------------


def _refused(args: list[str], named: str, capsys: pytest.CaptureFixture[str]) -> str:
    assert main(["render", *args, *SMALL_ARGS]) == EXIT_BAD_INPUT
    out, err = capsys.readouterr()
    assert out == "" and "Traceback" not in err
    assert err.startswith("error: ") and named in err, err
    return err


def test_cli_refuses_a_missing_plan(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nope.json"
    _refused([str(missing), "--scenario", str(SPEC_SCENARIO)], "nope.json", capsys)
    assert list(tmp_path.iterdir()) == []


def test_cli_refuses_a_missing_scenario(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _refused([str(SPEC_PLAN), "--scenario", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "f")],
             "nope.toml", capsys)
    assert list(tmp_path.iterdir()) == []


def test_cli_refuses_a_malformed_plan(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.json"
    data = json.loads(SPEC_PLAN.read_text())
    del data["steps"][0]["waypoints"][0]["gripper"]
    bad.write_text(json.dumps(data))
    err = _refused([str(bad), "--scenario", str(SPEC_SCENARIO)], "bad.json", capsys)
    assert "steps[0].waypoints[0]" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json"]


def test_cli_refuses_a_plan_for_another_scenario(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = _refused([str(SPEC_PLAN), "--scenario", str(TASK1), "--out", str(tmp_path / "f")], "pick-plan.json",
                   capsys)
    assert "task1_zero_mobility_lift.toml" in err and "example-pick" in err
    assert list(tmp_path.iterdir()) == []


def test_cli_refuses_an_out_that_is_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "figures"
    out.write_text("not a folder")
    _refused([str(SPEC_PLAN), "--scenario", str(SPEC_SCENARIO), "--out", str(out)], "figures", capsys)
    assert out.read_text() == "not a folder" and list(tmp_path.iterdir()) == [out]


def test_cli_refuses_nonsense_options(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["render", str(SPEC_PLAN), "--scenario", str(SPEC_SCENARIO), "--max-frames", "1"]) == EXIT_BAD_INPUT
    assert "max_frames" in capsys.readouterr().err


def test_library_errors_are_input_errors(tmp_path: Path) -> None:
    with pytest.raises(PlanFormatError, match="nope.json"):
        render_files(tmp_path / "nope.json", SPEC_SCENARIO, tmp_path / "f")
    with pytest.raises(ScenarioError, match="nope.toml"):
        render_files(SPEC_PLAN, tmp_path / "nope.toml", tmp_path / "f")
    with pytest.raises(RenderError, match="example-pick"):
        render_files(SPEC_PLAN, TASK1, tmp_path / "f")
    assert list(tmp_path.iterdir()) == []


def test_a_figure_path_that_is_a_folder_is_refused_before_drawing(pick: tuple[Plan, Scenario],
                                                                   tmp_path: Path) -> None:
    plan, scenario = pick
    (tmp_path / "contact_graph.svg").mkdir()
    with pytest.raises(RenderError, match="contact_graph.svg"):
        render_plan(plan, scenario, tmp_path, SMALL)
    assert [p.name for p in tmp_path.iterdir()] == ["contact_graph.svg"]


def test_a_drawing_error_writes_nothing(pick: tuple[Plan, Scenario], tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    def boom(*args: object, **kwargs: object) -> object:
        raise RuntimeError("drawing failed")

    monkeypatch.setattr(render, "_draw_contact_graph", boom)  # the last figure drawn
    plan, scenario = pick
    with pytest.raises(RuntimeError, match="drawing failed"):
        render_plan(_failed(plan), scenario, tmp_path / "out", dataclasses.replace(SMALL, graph=False))
    assert list(tmp_path.iterdir()) == []


def test_a_write_error_replaces_nothing_and_leaves_no_temporary_file(
        pick: tuple[Plan, Scenario], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    plan, scenario = pick
    failed = _failed(plan)
    out = tmp_path / "out"
    out.mkdir()
    (out / "snapshots.png").write_bytes(b"old")
    calls: list[Path] = []

    def replace(src: str, dst: str) -> None:
        calls.append(Path(dst))
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("ldhp_tamp.files.os.replace", replace)
    with pytest.raises(RenderError, match="No space left on device"):
        render_plan(failed, scenario, out, dataclasses.replace(SMALL, graph=False))
    assert len(calls) == 1  # the first move failed: no other was tried
    assert [p.name for p in out.iterdir()] == ["snapshots.png"]
    assert (out / "snapshots.png").read_bytes() == b"old"
