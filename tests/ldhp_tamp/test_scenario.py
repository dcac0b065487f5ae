"""The scenario loader (``ldhp-scenario/1``): every refusal, every default, the shipped files.

The domain folder and the engine list are replaced by small fakes (``fake_planning``) so
these tests run without unified-planning and do not depend on which engines are installed;
``test_cli_check.py`` runs the real stack.
"""

from __future__ import annotations

import hashlib
import logging
import math
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geometry.world import PolylineGripper, TwoPointGripper
from ldhp_tamp import engine_names, resources
from ldhp_tamp.errors import InputError, ScenarioError
from ldhp_tamp.scenario import (
    PlannerSettings,
    feature_names,
    find_domain,
    load_scenario,
    load_scenario_string,
    summarize,
)

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data" / "scenarios"
#: The spec's own example; outside this workspace (a clean clone) only its copy is tested.
SPEC_EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "spec" / "pick.toml"

FAKE_ENGINES = ("fast-downward", "pyperplan")


@pytest.fixture(autouse=True)
def fake_planning(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A domains folder holding only ``ldhp.pddl`` and a symbolic module with two engines."""
    domains = tmp_path_factory.mktemp("domains")
    (domains / "ldhp.pddl").write_text("(define (domain ldhp))\n")
    monkeypatch.setattr(resources, "domains_dir", lambda: domains)
    fake = types.ModuleType("ldhp_tamp.symbolic")
    fake.available_engines = lambda: FAKE_ENGINES  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "ldhp_tamp.symbolic", fake)
    monkeypatch.setattr(engine_names, "installed_planners", lambda: ())  # always ask the fake
    monkeypatch.setattr(engine_names, "known_planners", lambda: None)
    return domains


# --------------------------------------------------------------------------- refusals

#: Every file in tests/data/scenarios/bad: (the dotted key named, a fragment of the problem).
BAD: dict[str, tuple[str | None, str]] = {
    "unknown_format.toml": ("format", "unknown format"),
    "missing_format.toml": ("format", "missing required key"),
    "missing_name.toml": ("name", "missing required key"),
    "empty_name.toml": ("name", "not a usable id"),
    "name_with_slash.toml": ("name", "not a usable id"),
    "wrong_type_name.toml": ("name", "expected a string"),
    "missing_object_vertices.toml": ("object.vertices", "missing required key"),
    "wrong_type_object.toml": ("object", "expected a table"),
    "wrong_type_vertices.toml": ("object.vertices", "expected an array"),
    "wrong_type_vertex_coordinate.toml": ("object.vertices[1][1]", "expected a number"),
    "vertex_with_three_numbers.toml": ("object.vertices[0]", "2 numbers"),
    "wrong_type_mass.toml": ("object.mass", "expected a number"),
    "wrong_type_com.toml": ("object.com", "2 numbers"),
    "bool_as_number.toml": ("friction.environment", "boolean"),
    "bool_as_coordinate.toml": ("task.start[1]", "boolean"),
    "nonfinite_coordinate.toml": ("object.vertices[1][0]", "finite"),
    "nan_pose.toml": ("task.goal[1]", "finite"),
    "nonfinite_friction.toml": ("friction.gripper", "finite"),
    "nonfinite_mass.toml": ("object.mass", "finite"),
    "pose_two_numbers.toml": ("task.start", "3 numbers"),
    "self_intersecting_object.toml": ("object.vertices", "self-intersecting"),
    "zero_area_object.toml": ("object.vertices", "zero area"),
    "repeated_vertex.toml": ("object.vertices", "repeated vertex"),
    "two_vertices.toml": ("object.vertices", "at least 3 vertices"),
    "no_solids.toml": ("environment.solids", "at least one solid"),
    "missing_solid_vertices.toml": ("environment.solids[0].vertices", "missing required key"),
    "bad_solid_polygon.toml": ("environment.solids[1].vertices", "self-intersecting"),
    "bad_finger_polygon.toml": ("gripper.finger", "zero area"),
    "bad_palm_polygon.toml": ("gripper.palm", "self-intersecting"),
    "missing_gripper_model.toml": ("gripper.model", "missing required key"),
    "unknown_gripper_model.toml": ("gripper.model", "unknown gripper model"),
    "missing_spacing.toml": ("gripper.spacing", "missing required key"),
    "zero_finger_radius.toml": ("gripper.finger_radius", "positive"),
    "negative_finger_radius.toml": ("gripper.finger_radius", "positive"),
    "spacing_min_gt_max.toml": ("gripper.spacing", "greater than max"),
    "negative_spacing.toml": ("gripper.spacing", "negative"),
    "spacing_one_number.toml": ("gripper.spacing", "[min, max]"),
    "negative_opening.toml": ("gripper.opening", "negative"),
    "opening_min_gt_max.toml": ("gripper.opening", "greater than max"),
    "missing_friction_gripper.toml": ("friction.gripper", "missing required key"),
    "negative_friction.toml": ("friction.environment", "negative friction"),
    "negative_override_mu.toml": ("friction.environment_edges[0].mu", "negative friction"),
    "negative_object_edge_mu.toml": ("friction.object_edges[0].gripper", "negative friction"),
    "negative_mass.toml": ("object.mass", "negative mass"),
    "zero_mass.toml": ("object.mass", "zero mass"),
    "unknown_edge_override.toml": ("friction.environment_edges[0].edge", "unknown edge 'e99'"),
    "edge_zero_override.toml": ("friction.environment_edges[0].edge", "unknown edge 'e0'"),
    "unknown_object_edge_override.toml": ("friction.object_edges[0].edge", "unknown edge 'l7'"),
    "malformed_edge_name.toml": ("friction.environment_edges[0].edge", "not an environment edge"),
    "malformed_object_edge_name.toml": ("friction.object_edges[0].edge", "not an object edge"),
    "duplicate_edge_override.toml": ("friction.environment_edges[1].edge", "already overridden"),
    "empty_object_edge_override.toml": ("friction.object_edges[0]", "needs environment or gripper"),
    "missing_task_goal.toml": ("task.goal", "missing required key"),
    "missing_task_table.toml": ("task", "missing required key"),
    "wrong_type_goal_release.toml": ("task.goal_release", "true or false"),
    "start_overlaps_solid.toml": ("task.start", "overlaps solid 'table'"),
    "goal_overlaps_solid.toml": ("task.goal", "overlaps solid 'table'"),
    "start_grasp_width_out_of_range.toml": ("task.start_grasp.width", "outside the gripper's range"),
    "start_grasp_missing_width.toml": ("task.start_grasp.width", "missing required key"),
    "start_grasp_finger_overlaps_object.toml": ("task.start_grasp", "overlaps the object"),
    "samples_per_edge_too_small.toml": ("planner.samples_per_edge", "outside 2..10000"),
    "samples_per_edge_too_large.toml": ("planner.samples_per_edge", "outside 2..10000"),
    "samples_per_edge_float.toml": ("planner.samples_per_edge", "expected an integer"),
    "zero_max_top_iterations.toml": ("planner.max_top_iterations", "positive integer"),
    "negative_max_refinements.toml": ("planner.max_refinements", "positive integer"),
    "float_seed.toml": ("planner.seed", "expected an integer"),
    "negative_seed.toml": ("planner.seed", "non-negative"),
    "unknown_domain.toml": ("planner.domain", "unknown domain 'no-such-domain'"),
    "missing_domain_file.toml": ("planner.domain", "not found"),
    "unknown_engine.toml": ("planner.engine", "unknown engine 'warp-drive'"),
    "wrong_type_engine.toml": ("planner.engine", "expected a string"),
    "not_toml.toml": (None, "line 4"),
    "not_utf8.toml": (None, "not UTF-8"),
    "zero_max_force.toml": ("gripper.max_force", "must be positive"),
    "string_max_force.toml": ("gripper.max_force", "expected a number"),
    "friction_margin_one.toml": ("planner.friction_margin", "[0, 1)"),
    "negative_friction_margin.toml": ("planner.friction_margin", "[0, 1)"),
    "start_grasp_unknown_string.toml": ("task.start_grasp", "'anything'"),
    "start_touches_nothing.toml": ("task.start", "touches nothing"),
}


def test_every_bad_file_has_an_expectation() -> None:
    on_disk = {p.name for p in (DATA / "bad").glob("*.toml")}
    assert on_disk == set(BAD)


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_file_is_refused_naming_file_key_and_problem(name: str) -> None:
    key, fragment = BAD[name]
    with pytest.raises(ScenarioError) as info:
        load_scenario(DATA / "bad" / name)
    err = info.value
    message = str(err)
    assert name in message
    assert err.key == key
    if key is not None:
        assert f": {key}: " in message
    assert fragment in message
    assert "\n" not in message
    assert isinstance(err, InputError)


@pytest.mark.parametrize("k, ok", [(1, False), (2, True), (10000, True), (10001, False)])
def test_samples_per_edge_bounds_are_inclusive(k: int, ok: bool) -> None:
    text = (DATA / "good" / "defaults.toml").read_text() + f"\n[planner]\nsamples_per_edge = {k}\n"
    if ok:
        assert load_scenario_string(text).settings.samples_per_edge == k
    else:
        with pytest.raises(ScenarioError, match="planner.samples_per_edge: .* outside 2..10000"):
            load_scenario_string(text)


def test_unreadable_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="missing.toml: cannot read"):
        load_scenario(tmp_path / "missing.toml")


def test_string_errors_use_the_given_name() -> None:
    with pytest.raises(ScenarioError, match=r"^inline: format: missing required key$"):
        load_scenario_string('name = "x"\n', name="inline")


def test_engine_list_comes_from_symbolic(monkeypatch: pytest.MonkeyPatch) -> None:
    """The default engine is checked too, against what ldhp_tamp.symbolic reports."""
    monkeypatch.setattr(sys.modules["ldhp_tamp.symbolic"], "available_engines", lambda: ("lama",))
    with pytest.raises(ScenarioError, match=r"planner.engine: unknown engine 'pyperplan' \(installed: lama\)"):
        load_scenario(DATA / "good" / "defaults.toml")


def test_check_planner_false_skips_domain_and_engine(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys.modules["ldhp_tamp.symbolic"], "available_engines", lambda: ())
    s = load_scenario(DATA / "bad" / "unknown_domain.toml", check_planner=False)
    assert s.settings.domain == "no-such-domain" and s.settings.domain_path is None


# --------------------------------------------------------------------------- good files

SHIPPED = sorted(resources.scenarios_dir().glob("*.toml"))
GOOD = [*SHIPPED, SPEC_EXAMPLE,
        *sorted((DATA / "good").glob("*.toml"))]


def test_the_paper_scenarios_are_shipped() -> None:
    assert {p.name for p in SHIPPED} >= {"task1_zero_mobility_lift.toml",
                                         "task2_slot_insertion.toml", "example_pick.toml"}


@pytest.mark.parametrize("path", GOOD, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_good_file_loads_and_summarises(path: Path) -> None:
    s = load_scenario(path)
    assert s.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    assert s.path == path
    assert s.settings.domain_path is not None and s.settings.domain_path.is_file()
    text = summarize(s)
    assert text.splitlines()[0].startswith(f"scenario {s.name}")
    assert "contact states" not in text


def test_defaults_are_applied(fake_planning: Path) -> None:
    s = load_scenario(DATA / "good" / "defaults.toml")
    obj = s.world.object
    np.testing.assert_allclose(obj.com, [50.0, 20.0])
    assert obj.mass == 1.0
    assert s.description == ""
    assert s.start_grasp is None and s.goal_release is False
    assert s.settings == PlannerSettings(domain_path=(fake_planning / "ldhp.pddl").resolve())
    assert s.world.environment.solids[0].name == "solid1"
    f = s.world.friction
    assert (f.environment, f.gripper) == (0.3, 0.6)
    assert not f.environment_edges and not f.object_edges_environment and not f.object_edges_gripper


def test_clockwise_polygons_are_normalised_keeping_the_first_vertex() -> None:
    s = load_scenario(DATA / "good" / "clockwise_polygons.toml")
    assert s.world.object.polygon.vertices.tolist() == [[0, 0], [100, 0], [100, 40], [0, 40]]
    table = s.world.environment.solids[0].polygon
    assert table.vertices.tolist() == [[-300, 0], [-300, -50], [300, -50], [300, 0]]
    # e4 is now the table top, walked right to left, its outward normal up.
    np.testing.assert_allclose(s.world.environment.edges[3], [[300, 0], [-300, 0]])
    np.testing.assert_allclose(s.world.environment.normals[3], [0, 1], atol=1e-12)


def test_collinear_vertex_is_kept() -> None:
    s = load_scenario(DATA / "good" / "collinear_vertex.toml")
    assert len(s.world.object.polygon) == 5
    assert s.world.object.edge_names == ("l1", "l2", "l3", "l4", "l5")


def test_integers_where_floats_are_expected() -> None:
    s = load_scenario(DATA / "good" / "integers_and_floats.toml")
    obj = s.world.object
    assert obj.mass == 2.0 and isinstance(obj.mass, float)
    assert isinstance(s.world.friction.environment, float) and s.world.friction.gripper == 0.0
    g = s.world.gripper
    assert isinstance(g, TwoPointGripper)
    assert g.finger_radius == 5.0 and g.spacing == (50.0, 120.5)
    assert all(isinstance(v, float) for v in (s.start.x, s.start.y, s.start.theta))
    assert s.goal.theta == pytest.approx(math.radians(270))  # as written, not wrapped
    assert s.description == "A multi-line description,\nkept as written."
    assert s.settings.samples_per_edge == 2 and s.settings.seed == 12345


def test_friction_overrides_resolve_to_zero_based_indices() -> None:
    s = load_scenario(DATA / "good" / "friction_overrides.toml")
    f = s.world.friction
    assert f.environment_edges == {2: 0.5, 7: 0.0}
    assert f.object_edges_environment == {1: 0.1, 0: 0.05}
    assert f.object_edges_gripper == {1: 0.8, 3: 1.0}
    # An environment-edge override wins over an object-edge one.
    assert f.environment_mu("l", 1, "e", 2) == 0.5
    assert f.environment_mu("l", 1, "e", 0) == 0.1
    assert f.environment_mu("l", 2, "e", 0) == 0.3
    assert f.gripper_mu("l", 3, 4) == 1.0
    assert s.world.environment.edge_names == tuple(f"e{j}" for j in range(1, 9))


def test_start_grasps_are_read() -> None:
    s = load_scenario(DATA / "good" / "polyline_palm_start_grasp.toml")
    assert isinstance(s.world.gripper, PolylineGripper) and s.world.gripper.palm is not None
    assert s.start_grasp is not None
    assert (s.start_grasp.pose.x, s.start_grasp.pose.y, s.start_grasp.pose.theta) == (50.0, 5.0, 0.0)
    assert s.start_grasp.width == 100.0 and s.goal_release is True
    s2 = load_scenario(DATA / "good" / "two_point_start_grasp.toml")
    assert s2.start_grasp is not None and s2.start_grasp.width == 110.0


def test_the_2026_12_keys_are_read() -> None:
    s = load_scenario(DATA / "good" / "new_keys.toml")
    assert s.world.gripper.max_force == 125.0
    assert s.settings.friction_margin == pytest.approx(0.1)
    assert s.start_grasp is None and s.start_grasp_any and s.starts_held
    d = load_scenario(DATA / "good" / "defaults.toml")
    assert d.world.gripper.max_force is None and d.settings.friction_margin == 0.0
    assert not d.start_grasp_any and not d.starts_held


def test_a_start_in_the_air_loads_with_a_start_grasp() -> None:
    text = (DATA / "bad" / "start_touches_nothing.toml").read_text()
    with pytest.raises(ScenarioError, match="start_grasp"):
        load_scenario_string(text, "air")
    held = text.replace("goal = [0, 100, 0]", 'goal = [0, 100, 0]\nstart_grasp = { gripper = [50, 70, -90], width = 60 }')
    assert load_scenario_string(held, "air").start_grasp is not None


def test_concave_object_with_explicit_com() -> None:
    s = load_scenario(DATA / "good" / "concave_object.toml")
    assert not s.world.object.polygon.is_convex
    np.testing.assert_allclose(s.world.object.com, [50, 55])
    assert s.world.object.mass == 0.3


def test_unknown_keys_are_logged_not_refused(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="ldhp_tamp.scenario"):
        s = load_scenario(DATA / "good" / "extra_keys.toml")
    assert s.settings.samples_per_edge == 100
    by_level = {(r.levelno, r.getMessage().split(": ")[1]) for r in caplog.records}
    assert (logging.INFO, "author") in by_level
    assert (logging.INFO, "object.colour") in by_level
    assert (logging.INFO, "render") in by_level
    assert (logging.WARNING, "planner.sample_per_edge") in by_level
    assert "did you mean 'samples_per_edge'" in caplog.text


def test_sha256_of_a_string_is_of_its_utf8_bytes() -> None:
    text = (DATA / "good" / "defaults.toml").read_text()
    s = load_scenario_string(text, name="defaults")
    assert s.sha256 == hashlib.sha256(text.encode()).hexdigest() == load_scenario(DATA / "good" / "defaults.toml").sha256
    assert s.path is None


# --------------------------------------------------------------------------- domains


def test_domain_paths_resolve_against_the_scenario_folder(tmp_path: Path) -> None:
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "custom.pddl").write_text("(define (domain custom))\n")
    text = (DATA / "good" / "defaults.toml").read_text() + '\n[planner]\ndomain = "mine/custom.pddl"\n'
    scenario_file = tmp_path / "s.toml"
    scenario_file.write_text(text)
    s = load_scenario(scenario_file)
    assert s.settings.domain == "mine/custom.pddl"
    assert s.settings.domain_path == (tmp_path / "mine" / "custom.pddl").resolve()
    # The string loader resolves against base_dir.
    assert load_scenario_string(text, base_dir=tmp_path).settings.domain_path == s.settings.domain_path
    with pytest.raises(ScenarioError, match="planner.domain: domain file 'mine/custom.pddl' not found"):
        load_scenario_string(text, base_dir=tmp_path / "mine")


def test_find_domain(fake_planning: Path, tmp_path: Path) -> None:
    assert find_domain("ldhp") == (fake_planning / "ldhp.pddl").resolve()
    assert find_domain("nope") is None
    assert find_domain("ldhp.pddl", tmp_path) is None  # a .pddl name is a path, not a name
    assert find_domain(str(fake_planning / "ldhp.pddl")) == (fake_planning / "ldhp.pddl").resolve()


# --------------------------------------------------------------------------- the paper's scenarios


def _shipped(name: str):
    return load_scenario(resources.scenarios_dir() / name)


def test_task1_zero_mobility_lift() -> None:
    s = _shipped("task1_zero_mobility_lift.toml")
    w = s.world
    np.testing.assert_allclose(w.environment.edges[0], [[500, 0], [-500, 0]])  # e1: table top
    np.testing.assert_allclose(w.environment.normals[0], [0, 1], atol=1e-12)
    g = w.gripper
    assert isinstance(g, TwoPointGripper)
    assert g.finger_radius == 5.0 and g.spacing == (90.0, 90.0) and g.fixed_width
    assert g.spacing[0] - 2 * g.finger_radius == 80.0  # 80 mm between finger surfaces
    f = w.friction
    assert f.environment == f.gripper == 0.2
    assert w.object.mass == 0.5
    np.testing.assert_allclose(w.object_vertices(s.start)[:2], [[0, 0], [70, 0]])  # l1 on e1
    goal = w.object_vertices(s.goal)
    assert math.degrees(s.goal.theta) == pytest.approx(-60)
    np.testing.assert_allclose(goal[1], [70, 100], atol=1e-6)  # v2 lifted 100 mm above its start
    assert goal[:, 1].min() == pytest.approx(100, abs=1e-6)
    assert s.start_grasp is None and not s.goal_release
    assert s.settings.samples_per_edge == 100


def test_task2_slot_insertion() -> None:
    s = _shipped("task2_slot_insertion.toml")
    w = s.world
    env = w.environment
    np.testing.assert_allclose(env.edges[0], [[300, 0], [0, 0]])  # e1: slot floor
    np.testing.assert_allclose(env.normals[0], [0, 1], atol=1e-12)
    np.testing.assert_allclose(env.edges[1], [[0, 0], [0, 75]])  # e2: left inner wall
    np.testing.assert_allclose(env.normals[1], [1, 0], atol=1e-12)
    np.testing.assert_allclose(env.edges[7], [[300, 75], [300, 0]])  # e8: right inner wall
    np.testing.assert_allclose(env.normals[7], [-1, 0], atol=1e-12)
    g = w.gripper
    assert isinstance(g, PolylineGripper) and g.opening == (0.0, 140.0) and g.palm is None
    assert (w.friction.environment, w.friction.gripper) == (0.03, 0.6)
    start = w.object_vertices(s.start)
    assert start[:, 0].min() >= 0 and start[:, 0].max() <= 300 and start[:, 1].min() >= 100
    # The start grasp pinches the long sides: the pads lie on the block's sides.
    assert s.start_grasp is not None and s.start_grasp.width == 70.0
    f1, f2 = (s.start_grasp.pose.apply(v) for v in g.finger_polygons(s.start_grasp.width))
    assert f1[:, 0].max() == pytest.approx(start[:, 0].min())
    assert f2[:, 0].min() == pytest.approx(start[:, 0].max())
    assert min(f1[:, 1].min(), f2[:, 1].min()) > 75  # fingertips above the wall tops
    goal = w.object_vertices(s.goal)
    assert goal[:, 1].min() == pytest.approx(0, abs=1e-9) and goal[:, 1].max() == pytest.approx(70)
    assert goal[:, 0].min() > 0 and goal[:, 0].max() < 300  # lying flat inside the slot
    assert s.goal_release and s.settings.samples_per_edge == 100


# --------------------------------------------------------------------------- summary


def test_summary_names_features_gripper_poses_and_contact_states() -> None:
    s = _shipped("task2_slot_insertion.toml")
    text = summarize(s, contact_states=17)
    for fragment in ("scenario task2-slot-insertion", "v1..v4", "l1..l4", "slot e1..e8",
                     "polyline", "opening 0..140 mm", "environment 0.03, gripper 0.6",
                     "[20, 100, 0 deg]", "[225, 0, 90 deg]", "width 70 mm", "goal release: yes",
                     "samples_per_edge 100", "contact states: 17"):
        assert fragment in text, fragment
    t1 = summarize(_shipped("task1_zero_mobility_lift.toml"))
    assert "two-point, finger radius 5 mm, spacing between centres 90 mm (fixed)" in t1
    assert "-60 deg]" in t1


def test_feature_names() -> None:
    names = feature_names(load_scenario(DATA / "good" / "friction_overrides.toml"))
    assert names.object_vertices == ("v1", "v2", "v3", "v4")
    assert names.object_edges == ("l1", "l2", "l3", "l4")
    assert names.environment_vertices[-1] == "ve8"
    assert names.solid_edges == (("table", ("e1", "e2", "e3", "e4")), ("wall", ("e5", "e6", "e7", "e8")))


# --------------------------------------------------------------------------- properties

_BLOCK = (DATA / "good" / "defaults.toml").read_text()


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-200, 200), y=st.floats(0, 500), theta=st.floats(-720, 720))
def test_poses_are_degrees_in_the_file_and_radians_in_memory(x: float, y: float, theta: float) -> None:
    text = _BLOCK.replace("goal = [0, 100, 0]", f"goal = [{x!r}, {y + 110!r}, {theta!r}]")
    s = load_scenario_string(text, check_planner=False)
    assert (s.goal.x, s.goal.y) == (x, y + 110)
    assert s.goal.theta == pytest.approx(math.radians(theta))


@settings(max_examples=40, deadline=None)
@given(depth=st.floats(0, 3))
def test_overlap_rule_is_the_eroded_intersection(depth: float) -> None:
    """Sinking the block into the table by up to 2 mm is a sliver; deeper is refused."""
    text = _BLOCK.replace("start = [0, 0, 0]", f"start = [0, {-depth!r}, 0]")
    if depth <= 1.9:
        load_scenario_string(text, check_planner=False)
    elif depth >= 2.1:
        with pytest.raises(ScenarioError, match="task.start: the object at .* overlaps solid"):
            load_scenario_string(text, check_planner=False)


# --------------------------------------------------------------------------- strict mode

_MASS_TYPO = _BLOCK.replace("[object]", "[object]\nmas = 5", 1)


def test_a_misspelt_key_is_ignored_by_default(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="ldhp_tamp.scenario"):
        s = load_scenario_string(_MASS_TYPO, "typo.toml", check_planner=False)
    assert s.world.object.mass == 1.0  # the default: the typo did not set it
    assert "object.mas: unknown key ignored; did you mean 'mass'?" in caplog.text


def test_strict_refuses_a_misspelt_key_naming_file_key_and_guess() -> None:
    with pytest.raises(ScenarioError) as info:
        load_scenario_string(_MASS_TYPO, "typo.toml", check_planner=False, strict=True)
    assert (info.value.path, info.value.key) == ("typo.toml", "object.mas")
    assert str(info.value).startswith("typo.toml: object.mas: unknown key")
    assert "did you mean 'mass'?" in str(info.value)


def _with(text: str, after: str | None, line: str) -> str:
    """``text`` with ``line`` inserted after the line ``after`` (at the top if ``None``)."""
    if after is None:
        return line + "\n" + text
    assert text.count(after + "\n") == 1, after
    return text.replace(after + "\n", f"{after}\n{line}\n")


@pytest.mark.parametrize(("after", "line", "key"), [
    (None, 'author = "a researcher"', "author"),
    ("[object]", 'colour = "red"', "object.colour"),
    ("[task]", "goal_relase = true", "task.goal_relase"),
    ("[friction]", "environment_edges = [{ edge = \"e1\", mu = 0.5, note = \"wet\" }]",
     "friction.environment_edges[0].note"),
    ("gripper = 0.6", "\n[planner]\nsample_per_edge = 50", "planner.sample_per_edge"),
    ("gripper = 0.6", "\n[render]\nscale = 2", "render"),
])
def test_strict_refuses_an_unknown_key_anywhere(after: str | None, line: str, key: str) -> None:
    text = _with(_BLOCK, after, line)
    load_scenario_string(text, "extra.toml", check_planner=False)  # the default: ignored
    with pytest.raises(ScenarioError) as info:
        load_scenario_string(text, "extra.toml", check_planner=False, strict=True)
    assert info.value.key == key and info.value.problem.startswith("unknown key")


def test_strict_refuses_a_key_of_the_other_gripper_model() -> None:
    text = _BLOCK.replace('model = "two-point"', 'model = "two-point"\nopening = [0, 100]', 1)
    assert 'opening = [0, 100]' in text
    load_scenario_string(text, check_planner=False)
    with pytest.raises(ScenarioError, match=r"gripper.opening: unknown key \(not used by the two-point model\)"):
        load_scenario_string(text, check_planner=False, strict=True)


@pytest.mark.parametrize("path", [*sorted(resources.scenarios_dir().glob("*.toml")),
                                  *sorted((DATA / "good").glob("*.toml"))],
                         ids=lambda p: f"{p.parent.name}/{p.name}")
def test_strict_accepts_every_file_that_uses_only_the_formats_keys(path: Path) -> None:
    if path.name == "extra_keys.toml":
        with pytest.raises(ScenarioError, match="unknown key"):
            load_scenario(path, strict=True)
    else:
        assert load_scenario(path, strict=True).name
