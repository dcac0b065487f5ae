"""Every shipped scenario (``scenarios/*.toml``): it loads, follows the naming convention,
says what it is, and its contact-state graph builds; and the suite holds the paper's
generalization cases, both inverse tasks and the CMGMP-2D benchmark tasks, each as its
comments describe.

Unlike ``tests/ldhp_tamp/test_scenario.py`` these run the real stack (the shipped domain
and the installed engines), as ``ldhp-tamp check`` does.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from geometry.features import FREE
from ldhp_tamp import resources
from ldhp_tamp.contact_graph import build_context
from geometry.world import PolylineGripper, TwoPointGripper
from ldhp_tamp.scenario import Scenario, load_scenario

SHIPPED = sorted(resources.scenarios_dir().glob("*.toml"))

#: The suite of issue 5 (file stems), besides the paper's two tasks and the spec's example.
SUITE = {
    "gen_lift_concave11", "gen_slot_concave9", "gen_slot_length_260", "gen_slot_length_400",
    "gen_slot_corner_start", "inv_place_release", "inv_slot_extract",
    "cmgmp_block_quarter_turn", "cmgmp_book_stand_up", "cmgmp_cube_corner_pivot", "cmgmp_peg_in_hole",
}


def _load(stem: str) -> Scenario:
    return load_scenario(resources.scenarios_dir() / f"{stem}.toml")


def _same_object(a: Scenario, b: Scenario) -> bool:
    oa, ob = a.world.object, b.world.object
    return (np.array_equal(oa.polygon.vertices, ob.polygon.vertices) and np.array_equal(oa.com, ob.com)
            and oa.mass == ob.mass)


def _same_gripper(a: Scenario, b: Scenario) -> bool:
    ga, gb = a.world.gripper, b.world.gripper
    if isinstance(ga, PolylineGripper) and isinstance(gb, PolylineGripper):
        return (np.array_equal(ga.finger.vertices, gb.finger.vertices) and ga.opening == gb.opening
                and ga.palm is None and gb.palm is None)
    return ga == gb


def test_the_suite_is_shipped() -> None:
    assert {p.stem for p in SHIPPED} >= SUITE | {"task1_zero_mobility_lift", "task2_slot_insertion"}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_shipped_scenario(path: Path) -> None:
    s = load_scenario(path)
    # Naming convention: the name is the file stem with '-' for '_'.
    assert s.name == path.stem.replace("_", "-")
    assert s.description.strip(), "every shipped scenario says what it is"
    assert s.settings.domain_path is not None and s.settings.domain_path.name == "ldhp.pddl"
    ctx = build_context(s.world, s.start, s.goal)
    assert len(ctx.states) >= 2
    assert ctx.start_state in ctx.states and ctx.goal_state in ctx.states
    assert ctx.start_state != ctx.goal_state or s.start_grasp is not None or s.goal_release
    # Start and goal touch the environment without overlapping it (the loader refuses
    # overlap; a pose in the air has a contact pose below it, so FREE is then a state).
    for pose in (s.start, s.goal):
        obj = shapely.Polygon(s.world.object_vertices(pose))
        assert all(obj.intersection(solid.polygon.shapely).area < 1e-6 for solid in s.world.environment.solids)
    if ctx.start_free or ctx.goal_free:
        assert FREE in ctx.states


@pytest.mark.parametrize("path", [p for p in SHIPPED if p.stem != "example_pick"], ids=lambda p: p.name)
def test_shipped_scenario_file_opens_with_its_source(path: Path) -> None:
    # example_pick.toml is the spec's example, byte for byte (test_spec_copies.py).
    first = path.read_text(encoding="utf-8").splitlines()[0]
    assert first.startswith("# ") and len(first) > 20


# --------------------------------------------------------------------------- generalization


def _concave(s: Scenario) -> bool:
    poly = shapely.Polygon(s.world.object.polygon.vertices)
    return poly.convex_hull.area - poly.area > 1.0


@pytest.mark.parametrize(("stem", "task", "sides"), [("gen_lift_concave11", "task1_zero_mobility_lift", 11),
                                                     ("gen_slot_concave9", "task2_slot_insertion", 9)])
def test_concave_shapes_in_the_papers_tasks(stem: str, task: str, sides: int) -> None:
    s, t = _load(stem), _load(task)
    assert s.world.object.n == sides and _concave(s) and not _concave(t)
    # Only the object differs from the paper's task.
    np.testing.assert_array_equal(s.world.environment.vertices, t.world.environment.vertices)
    assert _same_gripper(s, t) and s.world.friction == t.world.friction and s.world.object.mass == t.world.object.mass
    assert (s.start, s.goal, s.start_grasp, s.goal_release) == (t.start, t.goal, t.start_grasp, t.goal_release)


@pytest.mark.parametrize("length", [260, 400])
def test_slot_of_another_length(length: int) -> None:
    s, t = _load(f"gen_slot_length_{length}"), _load("task2_slot_insertion")
    env = s.world.environment
    np.testing.assert_allclose(env.edges[0], [[length, 0], [0, 0]])  # e1: the slot floor
    np.testing.assert_allclose(env.edges[7], [[length, 75], [length, 0]])  # e8: right inner wall
    goal = s.world.object_vertices(s.goal)
    assert goal[:, 1].min() == pytest.approx(0) and 0 < goal[:, 0].min() and goal[:, 0].max() < length
    assert goal[:, 0].min() == pytest.approx(length - goal[:, 0].max())  # centred
    assert _same_object(s, t) and _same_gripper(s, t) and s.world.friction == t.world.friction
    assert (s.start, s.start_grasp, s.goal_release) == (t.start, t.start_grasp, t.goal_release)


def test_block_starting_in_the_slot_corner() -> None:
    s = _load("gen_slot_corner_start")
    start = s.world.object_vertices(s.start)
    # lying flat (150 mm along the floor) against the left wall: no finger fits on that side
    assert start[:, 0].min() == pytest.approx(0) and start[:, 1].min() == pytest.approx(0)
    assert np.ptp(start[:, 0]) == pytest.approx(150) and np.ptp(start[:, 1]) == pytest.approx(70)
    t = _load("task2_slot_insertion")
    assert _same_object(s, t) and _same_gripper(s, t) and s.world.friction == t.world.friction
    np.testing.assert_array_equal(s.world.environment.vertices, t.world.environment.vertices)
    assert s.start_grasp is None and not s.goal_release and s.goal == t.start


# --------------------------------------------------------------------------- inverse tasks


@pytest.mark.parametrize(("stem", "task"), [("inv_place_release", "task1_zero_mobility_lift"),
                                            ("inv_slot_extract", "task2_slot_insertion")])
def test_inverse_task_exchanges_start_and_goal(stem: str, task: str) -> None:
    s, t = _load(stem), _load(task)
    np.testing.assert_allclose(s.start.as_array(), t.goal.as_array(), atol=1e-9)
    np.testing.assert_allclose(s.goal.as_array(), t.start.as_array(), atol=1e-9)
    assert _same_object(s, t) and _same_gripper(s, t) and s.world.friction == t.world.friction
    np.testing.assert_array_equal(s.world.environment.vertices, t.world.environment.vertices)
    # The hand ends as it started in the forward task, and starts as it ended.
    assert (s.start_grasp is not None) == (not t.goal_release)
    assert s.goal_release == (t.start_grasp is None)


def test_inverse_place_starts_wedged_and_releases() -> None:
    s = _load("inv_place_release")
    assert s.start_grasp is not None and s.goal_release
    g = s.world.gripper
    assert isinstance(g, TwoPointGripper) and g.fixed_width and s.start_grasp.width == g.spacing[0]
    obj = shapely.Polygon(s.world.object_vertices(s.start))
    for cx in (-s.start_grasp.width / 2, s.start_grasp.width / 2):
        centre = s.start_grasp.pose.apply(np.array([cx, 0.0]))
        # each finger touches the block (its surface within 0.01 mm of the boundary)
        assert obj.exterior.distance(shapely.Point(centre)) == pytest.approx(g.finger_radius, abs=1e-2)


# --------------------------------------------------------------------------- CMGMP-2D


@pytest.mark.parametrize("stem", sorted(s for s in SUITE if s.startswith("cmgmp_")))
def test_cmgmp_tasks_use_the_benchmarks_friction_and_two_fingers(stem: str) -> None:
    s = _load(stem)
    assert "CMGMP" in s.description
    assert (s.world.friction.environment, s.world.friction.gripper) == (0.3, 0.8)
    g = s.world.gripper
    assert isinstance(g, TwoPointGripper) and g.finger_radius == 5 and g.spacing == (10, 150)


def test_cmgmp_quarter_turn() -> None:
    s = _load("cmgmp_block_quarter_turn")
    assert (s.start.x, s.start.y) == (s.goal.x, s.goal.y)
    assert math.degrees(s.goal.theta - s.start.theta) == pytest.approx(-90)


def test_cmgmp_book_ends_on_its_end() -> None:
    s = _load("cmgmp_book_stand_up")
    start, goal = s.world.object_vertices(s.start), s.world.object_vertices(s.goal)
    assert np.ptp(start[:, 1]) == pytest.approx(20) and np.ptp(goal[:, 1]) == pytest.approx(100)
    assert start[:, 1].min() == goal[:, 1].min() == pytest.approx(100)  # both on the table top


def test_cmgmp_cube_leans_in_the_corner() -> None:
    s = _load("cmgmp_cube_corner_pivot")
    goal = s.world.object_vertices(s.goal)
    assert goal[:, 0].min() == pytest.approx(0, abs=1e-9) and goal[:, 1].min() == pytest.approx(0, abs=1e-9)
    assert math.degrees(s.goal.theta) == pytest.approx(-45)


def test_cmgmp_peg_ends_in_the_hole() -> None:
    s = _load("cmgmp_peg_in_hole")
    goal = s.world.object_vertices(s.goal)
    assert goal[:, 1].min() == pytest.approx(-50) and -25 < goal[:, 0].min() < goal[:, 0].max() < 25
    assert s.start_grasp is not None and s.start_grasp.width == 55


# --------------------------------------------------------------------------- issue 14


def test_tight_peg_has_3_5_mm_of_clearance_and_ends_on_the_hole_floor() -> None:
    s = _load("peg_in_hole_tight")
    env = s.world.environment
    np.testing.assert_allclose(env.edges[0], [[35, -140], [-35, -140]])  # e1: the hole floor
    start, goal = s.world.object_vertices(s.start), s.world.object_vertices(s.goal)
    assert np.ptp(goal[:, 0]) == pytest.approx(63)  # a 70 mm hole: 3.5 mm on each side
    assert goal[:, 0].min() - (-35) == pytest.approx(3.5) and 35 - goal[:, 0].max() == pytest.approx(3.5)
    assert goal[:, 1].min() == pytest.approx(-140) and goal[:, 1].max() > 0  # its top stands out
    assert start[:, 1].min() > 0 and s.start_grasp is not None and s.goal_release
    # the gripper and the friction of task 2's second configuration, with its force limit
    t = _load("task2_slot_insertion")
    assert _same_gripper(s, t) and s.world.gripper.max_force == 125
    assert (s.world.friction.environment, s.world.friction.gripper) == (0.3, 0.6)


def _peg_held_off_the_floor(length: float, steepest: float, walls: tuple[str, ...]) -> bool:
    """Whether forces hold the tight peg (0.3 kg, 63 mm wide) still off the hole's floor:
    the walls (mu_e) at the corners in ``walls`` (``bl``: bottom left, ``tr``: top right,
    ...), and any number of fingers (mu_g, at most max_force each) anywhere on its top edge
    (pushing straight down) or on a top corner pushing towards the far wall with a contact
    normal at least ``steepest`` degrees below horizontal. A linear feasibility problem in
    the contact forces' friction-cone coefficients."""
    from scipy.optimize import linprog

    s = _load("peg_in_hole_tight")
    mu_e, mu_g, fmax = s.world.friction.environment, s.world.friction.gripper, s.world.gripper.max_force
    half, com = 31.5, np.array([0.0, length / 2])
    cols: list[tuple[float, float, float]] = []
    bounds: list[tuple[float, float | None]] = []

    def contact(point: tuple[float, float], normal: np.ndarray, mu: float, most: float | None) -> None:
        r = np.asarray(point) - com
        for side in (1.0, -1.0):
            f = normal + side * mu * np.array([-normal[1], normal[0]])
            cols.append((f[0], f[1], r[0] * f[1] - r[1] * f[0]))
            bounds.append((0.0, most))

    corners = {"bl": (-half, 0.0), "br": (half, 0.0), "tl": (-half, length), "tr": (half, length)}
    for name in walls:
        x, y = corners[name]
        contact((x, y), np.array([1.0 if x < 0 else -1.0, 0.0]), mu_e, None)
    for x in (-half, half):
        contact((x, length), np.array([0.0, -1.0]), mu_g, fmax)
        for beta in np.radians(np.linspace(steepest, 90.0, 10)):
            contact((x, length), np.array([np.cos(beta) * (1.0 if x < 0 else -1.0), -np.sin(beta)]), mu_g, fmax)
    weight = s.world.object.mass * 9.81
    res = linprog(np.zeros(len(cols)), A_eq=np.array(cols).T, b_eq=[0.0, weight, 0.0], bounds=bounds, method="highs")
    return res.status == 0


@pytest.mark.parametrize("length", [40.0, 130.0])
def test_a_tight_peg_off_the_floor_is_held_only_by_a_corner_pushed_nearly_flat(length: float) -> None:
    # What the scenario's comment says: with the peg flush against a wall, a finger must push
    # its top corner less than 46.6 degrees below horizontal; wedged across, 30.4 degrees; a
    # fingertip pushing straight down on its top holds it nowhere.
    flush, across = ("br", "tr"), ("bl", "tr")
    assert _peg_held_off_the_floor(length, 46.0, flush) and not _peg_held_off_the_floor(length, 47.0, flush)
    assert _peg_held_off_the_floor(length, 30.0, across) and not _peg_held_off_the_floor(length, 31.0, across)
    for walls in (flush, across, ("bl", "tl"), ("br", "tl")):
        assert not _peg_held_off_the_floor(length, 90.0, walls)
