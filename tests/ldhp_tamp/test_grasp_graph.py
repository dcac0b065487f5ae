"""The bottom tier (``ldhp_tamp.grasp_graph``): the layered grasp graph on small pose paths.

The spec's pick example (a 100 x 40 block on a table, the polyline gripper) with pose
paths built by hand from :class:`ldhp_tamp.path.Segment` and
:func:`geometry.kinematics.translate` / ``rotate_about``; K = 10 samples per edge keeps
every solve well under a second. Solved plans are checked by the plan validator.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from geometry.contacts import contact_state
from geometry.grasps import GraspOptions, enumerate_grasps
from geometry.kinematics import rotate_about, translate
from geometry.poses import Pose
from geometry.world import World
from ldhp_tamp.grasp_graph import GraspGraphOptions, GraspPlanner, GraspPlanStatus, object_frame_grasp
from ldhp_tamp.path import Segment
from ldhp_tamp.plan import PLAN_FORMAT, Family, Plan, PlanStats, PlanStatus
from ldhp_tamp.primitives import REGISTRY, ActionInfo, Binding, DomainInfo
from ldhp_tamp.primitives.adjust_grasp import PRIMITIVES, ApproachContact, CheckFailure, CheckResult
from ldhp_tamp.scenario import Scenario, load_scenario, load_scenario_string
from ldhp_tamp.streams import PosePath
from ldhp_tamp.validate import validate_plan

#: A copy of docs/formats/examples/pick.toml (tests/ldhp_tamp/test_spec_copies.py).
PICK_TOML = Path(__file__).resolve().parents[1] / "data" / "spec" / "pick.toml"
K = 10

PICK_LIKE = """
format = "ldhp-scenario/1"
name = "{name}"
[object]
vertices = [[0, 0], [100, 0], [100, 40], [0, 40]]
[[environment.solids]]
name = "table"
vertices = [[-300, -50], [300, -50], [300, 0], [-300, 0]]
{extra}
[gripper]
model = "polyline"
finger = [[0, 0], [10, 0], [10, 45], [0, 45]]
opening = [0, 140]
[friction]
environment = 0.3
gripper = 0.6
[task]
start = [0, 0, 0]
goal = {goal}
{task}
"""


def bindings(without: tuple[str, ...] = ()):
    return [REGISTRY.binding(name) for name in PRIMITIVES if name not in without]


def scenario(name: str, goal: str, extra: str = "", task: str = "") -> Scenario:
    return load_scenario_string(PICK_LIKE.format(name=name, goal=goal, extra=extra, task=task), name)


def segment(world: World, name: str, motion, s1: float, **params) -> Segment:
    start = motion.pose(0.0)
    end = motion.pose(s1)
    return Segment(name, contact_state(world, start), contact_state(world, end), motion, 0.0, s1, world, params)


def lift(world: World, start: Pose, dy: float) -> Segment:
    return segment(world, "air-move", translate(start, (0.0, 1.0 if dy > 0 else -1.0)), abs(dy), lift=dy)


def validate(sc: Scenario, steps) -> None:
    plan = Plan(PLAN_FORMAT, sc.name, sc.sha256, PlanStatus.SOLVED, tuple(steps), PlanStats())
    report = validate_plan(plan, sc)
    assert report.valid, [str(v) for v in report.violations[:5]]


@pytest.fixture(scope="module")
def pick() -> Scenario:
    return load_scenario(PICK_TOML, check_planner=False)


@pytest.fixture(scope="module")
def pick_grasps(pick: Scenario):
    return enumerate_grasps(pick.world, GraspOptions(samples_per_edge=K))


def test_pick_example_approaches_closes_and_lifts_and_the_plan_validates(pick: Scenario, pick_grasps):
    world = pick.world
    path = PosePath((lift(world, pick.start, 100.0),))
    planner = GraspPlanner(world, pick_grasps, bindings(), pick.start_grasp, pick.goal_release)
    res = planner.plan(path)
    assert res.status is GraspPlanStatus.SOLVED and res.solved, res.reason
    names = [s.primitive for s in res.steps]
    assert names[0] == "approach-contact" and names[-1] == "air-move"
    assert set(names[1:-1]) <= {"close"}
    assert [s.family for s in res.steps] == [Family.ADJUST_GRASP] * (len(names) - 1) + [Family.MOVE_OBJECT]
    move = res.steps[-1]
    assert len(move.waypoints) == path.segments[0].poses.shape[0]
    assert move.contact_state == ("l1-e3", "free") and move.parameters["lift"] == 100.0
    held = planner.grasps
    g = res.grasps[0]
    assert held.n_touching[g] == 2 and res.grasps == (g, g)  # a pinch, carried up
    assert res.node_path[0] == (0, 0) and res.node_path[-1] == (1, g)
    assert all(c is not None for c in move.waypoints[0].finger_contacts)
    validate(pick, res.steps)
    # The graph: one layer per pose, nodes = |G_T| summed, edges = G_m + candidates.
    assert len(res.layer_sizes) == 2 and res.nodes == sum(res.layer_sizes)
    assert res.edges == res.motion_sizes[0] + res.intra_proposed
    assert 0 < res.intra_checked <= res.intra_proposed and res.feasibility_checks > 0
    assert set(res.by_primitive) == set(PRIMITIVES)


def test_a_second_solve_reuses_the_cached_sets_and_checks(pick: Scenario, pick_grasps):
    world = pick.world
    planner = GraspPlanner(world, pick_grasps, bindings(), None, False)
    path = PosePath((lift(world, pick.start, 100.0),))
    first = planner.plan(path)
    again = planner.plan(PosePath((lift(world, pick.start, 100.0),)))  # a new, equal segment
    assert first.solved and again.solved
    assert again.feasibility_checks == 0 and again.intra_checked == 0
    assert again.node_path == first.node_path


def test_the_tables_prepared_at_the_start_pose_serve_the_plans_from_there(pick: Scenario, pick_grasps):
    """``prepare`` at the path's start then ``prepare_tables``: the context the plan uses
    is that one, its tables built, and the plan is the one a planner without them makes."""
    world = pick.world
    path = PosePath((lift(world, pick.start, 100.0),))
    planner = GraspPlanner(world, pick_grasps, bindings(), pick.start_grasp, pick.goal_release)
    planner.prepare(pick.start.as_array())
    planner.prepare_tables()
    ctx = planner.context
    assert {("pivot-pairs", 0), "pivot-table", "slide-table"} <= set(ctx._cache)
    res = planner.plan(path)
    plain = GraspPlanner(world, pick_grasps, bindings(), pick.start_grasp, pick.goal_release).plan(path)
    assert planner.context is ctx and res.solved
    assert res.node_path == plain.node_path and res.cost == plain.cost


def test_without_approach_contact_a_task_starting_with_the_gripper_away_has_no_path(pick: Scenario, pick_grasps):
    world = pick.world
    path = PosePath((lift(world, pick.start, 100.0),))
    res = GraspPlanner(world, pick_grasps, bindings(without=("approach-contact",))).plan(path)
    assert res.status is GraspPlanStatus.NO_PATH and not res.steps
    assert res.failing_segment == 0
    assert "segment 0 (air-move l1-e3 -> free)" in res.reason
    assert "approach-contact" not in res.by_primitive


def test_only_the_actions_the_domain_declares_make_edges(pick: Scenario, pick_grasps):
    declared = tuple(name for name in PRIMITIVES if name != "slide")
    domain = DomainInfo("toy", "toy.pddl", tuple(ActionInfo(name, REGISTRY.family(name)) for name in declared))
    bound = REGISTRY.bound(domain, REGISTRY.family("slide"))
    assert [b.name for b in bound] == list(declared)
    world = pick.world
    res = GraspPlanner(world, pick_grasps, bound).plan(PosePath((lift(world, pick.start, 100.0),)))
    assert res.solved
    assert set(res.by_primitive) == set(declared)
    full = GraspPlanner(world, pick_grasps, bindings()).plan(PosePath((lift(world, pick.start, 100.0),)))
    assert full.intra_proposed - res.intra_proposed == full.by_primitive["slide"]["candidates"] > 0


def test_a_segment_no_grasp_can_hold_is_reported_with_its_index():
    # Lift the block, carry it over a pit exactly its size, lower it in: at the bottom
    # no finger fits beside or below it, so no grasp can execute the last segment.
    pit = """
[[environment.solids]]
name = "right"
vertices = [[250, -100], [300, -100], [300, 0], [250, 0]]
[[environment.solids]]
name = "floor"
vertices = [[150, -100], [250, -100], [250, -50], [150, -50]]"""
    text = PICK_LIKE.format(name="pit", goal="[150, -50, 0]", extra=pit, task="").replace(
        "[[-300, -50], [300, -50], [300, 0], [-300, 0]]", "[[-300, -100], [150, -100], [150, 0], [-300, 0]]")
    sc = load_scenario_string(text, "pit")
    world = sc.world
    grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=K))
    up = lift(world, sc.start, 100.0)
    over = segment(world, "air-move", translate(up.end, (1.0, 0.0)), 150.0)
    down = lift(world, over.end, -150.0)
    res = GraspPlanner(world, grasps, bindings()).plan(PosePath((up, over, down)))
    assert res.status is GraspPlanStatus.NO_GRASP_FOR_SEGMENT
    assert res.failing_segment == 2
    assert res.reason.startswith("no grasp can execute segment 2 (air-move free -> ")
    assert res.motion_sizes[0] > 0 and res.motion_sizes[1] > 0 and res.motion_sizes[2] == 0


def test_no_path_names_the_segment_where_reachability_dies():
    # Lift the block, then carry it under a ceiling 2 mm above its top: only pinches
    # whose fingers hang below the block pass under it, none of which can lift it from
    # the table, and nothing regrasps a block held in the air.
    ceiling = '[[environment.solids]]\nname = "ceiling"\nvertices = [[150, 142], [400, 142], [400, 200], [150, 200]]'
    sc = scenario("ceiling", "[200, 100, 0]", extra=ceiling)
    world = sc.world
    grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=K))
    up = lift(world, sc.start, 100.0)
    under = segment(world, "air-move", translate(up.end, (1.0, 0.0)), 200.0)
    planner = GraspPlanner(world, grasps, bindings())
    res = planner.plan(PosePath((up, under)))
    assert res.status is GraspPlanStatus.NO_PATH, res.reason
    assert res.motion_sizes[0] > 0 and res.motion_sizes[1] > 0
    assert np.intersect1d(planner.motion_grasps(up)[0].indices, planner.motion_grasps(under)[0].indices).size == 0
    assert res.failing_segment == 1
    assert "forward reachability dies at segment 1 (air-move free -> free)" in res.reason
    assert "does not rest" in res.reason


def test_no_path_names_the_segment_a_feasible_path_cannot_pass_not_where_optimism_stops():
    # The ceiling path again, with every approach refused when checked: no grasp gets
    # onto the block, so nothing lifts it (segment 0). Counting unchecked edges as
    # feasible, reachability runs on to T_1 and dies at segment 1, and no search is
    # needed to see that no path exists; the failing segment (which the top tier
    # bisects or forbids) must be the one where a path of feasible edges stops.
    ceiling = '[[environment.solids]]\nname = "ceiling"\nvertices = [[150, 142], [400, 142], [400, 200], [150, 200]]'
    sc = scenario("ceiling", "[200, 100, 0]", extra=ceiling)
    world = sc.world
    grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=K))
    up = lift(world, sc.start, 100.0)
    under = segment(world, "air-move", translate(up.end, (1.0, 0.0)), 200.0)
    veto = VetoApproach(set(range(len(grasps))))
    binds = [Binding(b.name, b.family, veto) if b.name == "approach-contact" else b for b in bindings()]
    res = GraspPlanner(world, grasps, binds).plan(PosePath((up, under)))
    assert res.status is GraspPlanStatus.NO_PATH, res.reason
    assert res.failing_segment == 0, res.reason
    assert veto.asked  # the approaches were checked (and refused)
    assert "forward reachability dies at segment 0 (air-move l1-e3 -> free)" in res.reason
    assert "approach-contact 0 feasible of" in res.reason
    # Without the veto the same path dies at segment 1, after grasps got onto the block.
    free = GraspPlanner(world, grasps, bindings()).plan(PosePath((up, under)))
    assert free.status is GraspPlanStatus.NO_PATH and free.failing_segment == 1


def test_a_start_grasp_off_the_grid_is_added_and_released_at_the_goal():
    # Held by its ends, pushed 30 mm along the table, released.
    sc = scenario("held", "[30, 0, 0]", task="start_grasp = { gripper = [50, 5, 0], width = 100 }\ngoal_release = true")
    world = sc.world
    grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=K))
    push = segment(world, "push", translate(sc.start, (1.0, 0.0)), 30.0, travel=30.0)
    planner = GraspPlanner(world, grasps, bindings(), sc.start_grasp, sc.goal_release)
    res = planner.plan(PosePath((push,)))
    assert res.solved, res.reason
    start = planner.start_index
    assert start == len(grasps) == len(planner.grasps) - 1  # an extra row
    assert planner.grasps.n_touching[start] == 2
    assert res.node_path == ((0, start), (1, start), (1, 0))
    assert [s.primitive for s in res.steps] == ["push", "open"]
    assert res.steps[0].waypoints[0].gripper.as_array() == pytest.approx([50.0, 5.0, 0.0])
    validate(sc, res.steps)


def test_release_in_the_air_is_refused_at_the_last_segment():
    sc = scenario("held-up", "[0, 60, 0]", task="start_grasp = { gripper = [50, 5, 0], width = 100 }\ngoal_release = true")
    world = sc.world
    grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=K))
    res = GraspPlanner(world, grasps, bindings(), sc.start_grasp, True).plan(PosePath((lift(world, sc.start, 60.0),)))
    assert res.status is GraspPlanStatus.NO_PATH and res.failing_segment == 0
    assert "cannot release the object" in res.reason and "does not rest" in res.reason


def test_a_turn_in_the_air_gets_waypoints_dense_enough_for_the_fingers():
    centre = (50.0, 80.0)
    angle = math.radians(30.0)
    start = Pose(0.0, 60.0, 0.0)
    end = rotate_about(start, centre, 1).pose(angle)
    sc = scenario("turn", "[{:.9f}, {:.9f}, {:.9f}]".format(end.x, end.y, math.degrees(end.theta)))
    world = sc.world
    grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=K))
    up = lift(world, sc.start, 60.0)
    turn = segment(world, "air-move", rotate_about(up.end, centre, 1), angle)
    res = GraspPlanner(world, grasps, bindings()).plan(PosePath((up, turn)))
    assert res.solved, res.reason
    move = res.steps[-1]
    assert len(move.waypoints) > turn.poses.shape[0]  # refined for the fingers
    validate(sc, res.steps)


def test_lazy_checking_finds_the_cheapest_path_that_checking_everything_finds(pick: Scenario, pick_grasps):
    world = pick.world
    path = PosePath((lift(world, pick.start, 100.0),))
    lazy = GraspPlanner(world, pick_grasps, bindings(), options=GraspGraphOptions(slack=0.0, batch=1))
    eager = GraspPlanner(world, pick_grasps, bindings(), options=GraspGraphOptions(slack=1e9, batch=10**9))
    a, b = lazy.plan(path), eager.plan(path)
    assert a.solved and b.solved
    assert a.cost == pytest.approx(b.cost) and math.isfinite(a.cost)
    assert a.intra_checked < b.intra_checked
    assert a.search_rounds >= b.search_rounds == 2  # check everything once, then confirm
    # The cost is the quality of the lift plus lambda1 * travel + lambda2 per AdjustGrasp edge.
    q = lazy.motion_grasps(path.segments[0])[0]
    s_lift = float(q.quality[np.searchsorted(q.indices, a.grasps[0])])
    adjust = [s for s in a.steps if s.family is Family.ADJUST_GRASP]
    assert a.cost == pytest.approx(s_lift + sum(0.01 * s.parameters["travel"] + 1.0 for s in adjust), abs=1e-3)


class VetoApproach(ApproachContact):
    """``approach-contact`` whose check refuses the ``veto`` cheapest edges it is asked
    about (a small fake: the search must route around infeasible cheap edges)."""

    def __init__(self, veto: set[int]) -> None:
        self.veto = veto
        self.asked: list[int] = []

    def check(self, context, pose, edges):
        res = super().check(context, pose, edges)
        self.asked += edges.dst.tolist()
        bad = np.isin(edges.dst, list(self.veto))
        failure = np.where(bad, CheckFailure.OBJECT, res.failure).astype(np.int8)
        return CheckResult(res.ok & ~bad, failure, res.feasibility_checks, res.samples)


def test_the_search_routes_around_edges_found_infeasible(pick: Scenario, pick_grasps):
    world = pick.world
    path = PosePath((lift(world, pick.start, 100.0),))
    free = GraspPlanner(world, pick_grasps, bindings()).plan(path)
    first = free.grasps[0]
    veto = VetoApproach({first})
    binds = [Binding(b.name, b.family, veto) if b.name == "approach-contact" else b for b in bindings()]
    res = GraspPlanner(world, pick_grasps, binds, options=GraspGraphOptions(slack=0.0, batch=1)).plan(path)
    assert res.solved and first in veto.asked
    assert res.node_path[1][1] != first and res.cost > free.cost
    validate(pick, res.steps)


def test_an_empty_path_and_object_frame_grasps(pick: Scenario, pick_grasps):
    res = GraspPlanner(pick.world, pick_grasps, bindings()).plan(PosePath(()))
    assert res.status is GraspPlanStatus.NO_PATH and "no segment" in res.reason
    row = object_frame_grasp(pick.world, Pose(50.0, 5.0, 0.0), 100.0)
    assert row["part"].tolist() == [2, 2] and row["feature"].tolist() == [3, 1]
    assert row["contact"][:, 0].tolist() == [0.0, 100.0] and np.allclose(row["contact"][:, 1], 22.5)
    assert row["normal"].tolist() == [[1.0, 0.0], [-1.0, 0.0]]
    free = object_frame_grasp(pick.world, Pose(50.0, 5.0, 0.0), 120.0)
    assert free["part"].tolist() == [0, 0] and np.isnan(free["contact"]).all()


def test_a_bisected_segments_halves_get_the_grasp_sets_checking_them_from_scratch_gives():
    """The halves of a split segment have their parent's samples; their G_m is derived
    from the parent's (only what the parent does not settle is checked) and must equal
    the G_m of the same poses and candidates computed from nothing."""
    from geometry.grasps import motion_conditioned

    sc = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "task1_zero_mobility_lift.toml")
    world = sc.world
    grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=30))
    pivot = world.object_vertices(sc.start)[1]  # v2, the corner the block tips onto
    tip = segment(world, "tip", rotate_about(sc.start, pivot, -1), math.radians(25.0))  # v1 goes up
    planner = GraspPlanner(world, grasps, bindings())
    planner._prepare(np.asarray(tip.poses[0]))
    parent, _, _ = planner.motion_grasps(tip)
    assert len(parent) and parent.rejected.size
    first, second = tip.split()
    assert np.array_equal(np.concatenate([first.poses, second.poses[1:]]), tip.poses)
    for half in (first, second, *first.split(), *second.split()):
        derived, n_cand, fresh = planner.motion_grasps(half)
        assert fresh
        cand = np.intersect1d(planner.pose_grasps(half.poses[0]), planner.pose_grasps(half.poses[-1]))
        scratch = motion_conditioned(world, planner.grasps, half.poses, cand, planner.options.motion)
        assert np.array_equal(derived.indices, scratch.indices)
        np.testing.assert_allclose(derived.quality, scratch.quality)
        assert derived.checks < scratch.checks  # what the parent settled was not checked again


def task1_tip(k: int):
    """Task 1's scenario, its grasp set at ``k`` samples an edge and the block tipped 40
    degrees about its bottom-right corner (a tip segment)."""
    sc = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "task1_zero_mobility_lift.toml")
    pivot = sc.world.object_vertices(sc.start)[1]
    tip = segment(sc.world, "tip", rotate_about(sc.start, pivot, -1), math.radians(40.0))
    return sc, enumerate_grasps(sc.world, GraspOptions(samples_per_edge=k)), tip


def test_the_helper_process_changes_no_grasp_plan_and_ends_with_close():
    """G_m of two segments at once (one in a helper process) gives what one process
    gives, on a path whose refinement halves depend on their parents' G_m."""
    import dataclasses
    import os

    sc, grasps, tip = task1_tip(20)
    world = sc.world
    a, b = tip.split()
    paths = [PosePath((tip, lift(world, tip.end, 50.0))), PosePath((*a.split(), *b.split(), lift(world, tip.end, 50.0)))]
    out = {}
    for on in (False, True):
        opts = dataclasses.replace(GraspGraphOptions(), helper=on)
        planner = GraspPlanner(world, grasps, bindings(), sc.start_grasp, sc.goal_release, opts)
        try:
            out[on] = [(r.status, r.failing_segment, r.cost, r.nodes, r.layer_sizes, r.motion_sizes)
                       for r in (planner.plan(p) for p in paths)]
            if on and hasattr(os, "fork") and os.cpu_count() and os.cpu_count() > 1:
                assert planner._helper is not None and planner._helper.alive
        finally:
            planner.close()
        assert planner._helper is None
    assert out[True] == out[False]


def test_while_the_helpers_g_m_is_out_the_planner_decides_the_segments_after_it() -> None:
    """``_meanwhile``: until the helper's answer has come (a stand-in that has it at its
    second look), the segments after the helper's are decided here, in order: the cached
    ones and those before the helper's skipped, a half whose parent is not decided yet
    stopping it. Each is what it would be decided as later (the cache), and the instances
    counted are theirs."""
    from geometry.grasps import motion_conditioned

    sc, grasps, tip = task1_tip(12)
    world = sc.world
    a, b = tip.split()
    up = lift(world, tip.end, 50.0)
    planner = GraspPlanner(world, grasps, bindings(), sc.start_grasp, sc.goal_release, GraspGraphOptions(helper=False))
    planner._prepare(np.asarray(tip.poses[0], dtype=float))

    class Slow:
        def __init__(self, looks: int) -> None:
            self.looks = looks

        def answered(self) -> bool:
            self.looks -= 1
            return self.looks < 0

    from ldhp_tamp.grasp_graph import _motion_key

    planner._helper = Slow(1)
    first = lift(world, sc.start, 10.0)
    checks = planner._meanwhile([first, tip, up, lift(world, up.end, 20.0)], busy=tip)
    assert _motion_key(first) not in planner._motion_sets  # before the helper's: not here
    assert _motion_key(tip) not in planner._motion_sets  # the helper's own
    assert _motion_key(up) in planner._motion_sets and checks > 0
    done, n_cand = planner._motion_sets[_motion_key(up)]
    cand, _, _, _, ends = planner._motion_inputs(up)
    alone = motion_conditioned(world, planner.grasps, up.poses, cand, planner.options.motion, rate=False, free_at=ends)
    assert np.array_equal(done.indices, alone.indices) and checks == alone.checks
    # the second look found the answer: the last segment is left to the loop
    assert len(planner._motion_sets) == 1
    planner._helper = Slow(5)
    assert planner._meanwhile([tip, *b.split(), up], busy=tip) == 0  # halves of an undecided parent: none
    planner._helper = None


@contextlib.contextmanager
def _with_helper(k: int = 12) -> Iterator[tuple[Any, GraspPlanner, Any, Any]]:
    """Task 1's tip (K = ``k``) and a lift after it, with a planner whose helper process
    is running (the test is skipped on one core); the helper is closed after."""
    sc, grasps, tip = task1_tip(k)
    up = lift(sc.world, tip.end, 50.0)
    opts = dataclasses.replace(GraspGraphOptions(), helper=True)
    planner = GraspPlanner(sc.world, grasps, bindings(), sc.start_grasp, sc.goal_release, opts)
    try:
        planner._prepare(np.asarray(tip.poses[0], dtype=float))
        if planner._helper_process() is None:
            pytest.skip("no second core")
        yield sc, planner, tip, up
    finally:
        planner.close()


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="no os.fork on this platform")
def test_the_helper_rates_a_paths_grasp_sets_as_this_process_would() -> None:
    """``_rate_meanwhile`` sends a path's unrated G_m to the helper (each once), and
    ``_rated`` caches what it sends back: the quality, closure and reaction angles that
    ``rate_motion_grasps`` gives here, bit for bit; rated or empty sets are not sent."""
    from geometry.grasps import rate_motion_grasps
    from ldhp_tamp.grasp_graph import _motion_key

    with _with_helper() as (sc, planner, tip, up):
        world = sc.world
        sets = {seg: planner.motion_grasps(seg, rate=False)[0] for seg in (tip, up)}
        assert all(len(m) and not m.rated for m in sets.values())
        sent = planner._rate_meanwhile([tip, up, tip])
        assert [key for key, _ in sent] == [_motion_key(tip), _motion_key(up)]
        planner._rated(sent)
        assert planner._helper.idle
        for seg, mg in sets.items():
            got = planner._motion_sets[_motion_key(seg)][0]
            want = rate_motion_grasps(world, planner.grasps, seg.poses, mg, planner.options.motion)
            assert got.rated and got is not mg
            for field in ("indices", "quality", "force_closure", "alpha"):
                assert np.array_equal(getattr(got, field), getattr(want, field))
        assert planner._rate_meanwhile([tip, up]) == []  # rated now: nothing to send


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="no os.fork on this platform")
def test_the_helper_decides_later_layers_intra_pose_ends_as_this_process_would() -> None:
    """``_layers_meanwhile`` sends the layers after the first whose ``holds`` of G_T is
    not decided yet to the helper; ``_layers_taken`` puts its answer into the context's
    caches: the LayerData and ``holds`` that this process computes, bit for bit, and
    nothing is sent again once they are known."""
    from ldhp_tamp.grasp_graph import _Layer
    from ldhp_tamp.primitives.adjust_grasp import AdjustContext

    with _with_helper() as (sc, planner, tip, up):
        world = sc.world
        ctx = planner.context
        poses = [np.asarray(tip.poses[0], dtype=float), np.asarray(tip.end.as_array(), dtype=float),
                 np.asarray(up.end.as_array(), dtype=float)]
        layers = []
        for k, p in enumerate(poses):
            members = np.zeros(len(planner.grasps), dtype=bool)
            members[planner.pose_grasps(p)] = True
            layers.append(_Layer(k, p, p.tobytes(), members, int(members.sum()), "s",
                                 lambda p=p, m=members: ctx.holds(p, m)))
        sent = planner._layers_meanwhile(ctx, layers)
        assert sent == [1, 2]  # not the first: this process makes its candidates meanwhile
        planner._layers_taken(ctx, layers, sent)
        assert planner._helper.idle
        fresh = AdjustContext(world, planner.grasps, planner.options.adjust)
        for layer in layers[1:]:
            assert ctx.holds_known(layer.pose, layer.members)
            assert np.array_equal(ctx.holds(layer.pose, layer.members), fresh.holds(layer.pose, layer.members))
            got, want = ctx.layer(layer.pose), fresh.layer(layer.pose)
            for field in dataclasses.fields(want):
                assert np.array_equal(getattr(got, field.name), getattr(want, field.name))
        assert not ctx.holds_known(layers[0].pose, layers[0].members)
        assert planner._layers_meanwhile(ctx, layers) == []  # known now: nothing to send


def test_a_helper_asked_for_by_grasp_set_holds_that_set_and_the_shared_state(monkeypatch) -> None:
    """``live_helper(grasps)``: the helper only if its state holds that very grasp set
    and the solve's shared state (``start_helper``), which every helper forked later
    holds too (a change of grasp set ends a helper; the next use forks another)."""
    import dataclasses
    import os

    from ldhp_tamp import grasp_graph

    if not hasattr(os, "fork"):
        pytest.skip("no os.fork on this platform")
    monkeypatch.setattr(grasp_graph, "cores", lambda: 2)
    sc = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "inv_place_release.toml")
    assert sc.start_grasp is not None  # the start grasp's row depends on the start pose
    opts = dataclasses.replace(GraspGraphOptions(), helper=True)
    planner = GraspPlanner(sc.world, enumerate_grasps(sc.world, GraspOptions(samples_per_edge=10)), bindings(),
                           sc.start_grasp, sc.goal_release, opts)
    try:
        start = sc.start.as_array()
        planner.prepare(start)
        grasps = planner.grasps
        assert planner._helper_process() is not None  # forked without shared state
        assert planner.live_helper() is not None and planner.live_helper(grasps) is None
        planner.close()
        shared = ("setup context", "domain", "registry")
        helper = planner.start_helper(shared)
        assert helper is not None and planner.live_helper(grasps) is helper
        assert planner.live_helper(dataclasses.replace(grasps)) is None  # an equal set, not this one
        moved = start + np.array([5.0, 0.0, 0.0])
        planner.prepare(moved)  # the start grasp's row moves with the start pose: another grasp set
        assert planner.grasps is not grasps and planner.live_helper() is None
        again = planner._helper_process()
        assert again is not None and again is not helper
        assert planner.live_helper(planner.grasps) is again and planner.live_helper(grasps) is None
    finally:
        planner.close()


def test_a_force_limit_the_judge_met_leaves_a_segments_set_at_once(pick: Scenario, pick_grasps) -> None:
    """G_m bounds no force; after a plan broke the gripper's force limit along a segment,
    ``bound_forces`` takes out of that segment's G_m every grasp that needs more (a pinch
    lifting the block needs W / (2 mu_g) per finger), once; without a limit it does
    nothing."""
    import dataclasses

    need = pick.world.object.weight / (2 * pick.world.friction.gripper)
    for limit, left in ((0.5 * need, 0), (None, None)):
        world = dataclasses.replace(pick.world, gripper=dataclasses.replace(pick.world.gripper, max_force=limit))
        seg = lift(world, pick.start, 100.0)
        planner = GraspPlanner(world, pick_grasps, bindings(), pick.start_grasp, pick.goal_release)
        planner.prepare(seg.poses[0])
        before = len(planner.motion_grasps(seg)[0])
        assert before > 0
        removed = planner.bound_forces(seg)
        after = len(planner.motion_grasps(seg)[0])
        if limit is None:
            assert removed == 0 and after == before
        else:
            assert removed == before and after == left
            assert planner.bound_forces(seg) == 0  # once
            assert planner.plan(PosePath((seg,))).status is GraspPlanStatus.NO_GRASP_FOR_SEGMENT


def test_an_adjust_grasp_edge_a_judge_refused_is_left_out_of_the_next_plan(pick: Scenario, pick_grasps):
    """A judge downstream (validation, the forward problem, the simulation) that refuses
    a plan at an AdjustGrasp step has that edge marked infeasible: the same path planned
    again takes another way; a MoveObject step or an edge already refused is not marked."""
    world = pick.world
    path = PosePath((lift(world, pick.start, 100.0),))
    planner = GraspPlanner(world, pick_grasps, bindings())
    first = planner.plan(path)
    assert first.solved and len(first.adjust_edges) == len(first.steps)
    adjust = [i for i, s in enumerate(first.steps) if s.family is Family.ADJUST_GRASP]
    move = [i for i, s in enumerate(first.steps) if s.family is Family.MOVE_OBJECT]
    assert adjust and move and all(first.adjust_edges[i] is None for i in move)
    assert not planner.reject_adjust(first, move[0])
    i = adjust[0]
    assert planner.reject_adjust(first, i) and not planner.reject_adjust(first, i)
    again = planner.plan(PosePath((lift(world, pick.start, 100.0),)))
    assert again.solved and again.cost >= first.cost
    taken = {(id(c), j) for c, j in (e for e in again.adjust_edges if e is not None)}
    cands, j = first.adjust_edges[i]
    assert (id(cands), j) not in taken and cands.valid[j] == -1
    validate(pick, again.steps)


def test_a_refused_pivot_takes_the_pivots_like_it_along(pick: Scenario, pick_grasps):
    """The judge refusing a pivot (the object may follow the finger it turns about) marks
    infeasible every pivot about the same finger, turning the same way, on a contact within
    PIVOT_REFUSAL_RADIUS of its own; the other sense and farther contacts stay unknown."""
    from types import SimpleNamespace

    from ldhp_tamp.grasp_graph import PIVOT_REFUSAL_RADIUS, _Cands
    from ldhp_tamp.primitives.adjust_grasp import Pivot

    planner = GraspPlanner(pick.world, pick_grasps, bindings())
    every = np.ones(len(pick_grasps), dtype=bool)
    edges = Pivot().propose(planner.context, pick.start, np.arange(1, len(pick_grasps)), every)
    n = len(edges)
    cands = _Cands(edges, np.zeros(n), np.zeros(n, dtype=np.int8))
    i = 0
    k = int(edges.finger[i])
    assert planner.reject_adjust(SimpleNamespace(adjust_edges=[(cands, i)]), 0)
    dist = np.linalg.norm(np.nan_to_num(pick_grasps.contact[edges.src, k] - pick_grasps.contact[edges.src[i], k],
                                        nan=np.inf), axis=1)
    alike = (edges.finger == k) & (np.sign(edges.sense) == np.sign(edges.sense[i])) & (dist <= PIVOT_REFUSAL_RADIUS)
    assert alike.sum() > 1 and (cands.valid[alike] == -1).all()
    assert (~alike).any() and (cands.valid[~alike] == 0).all()


def test_a_search_out_of_edge_checks_says_so_and_blames_where_it_spent_them(pick: Scenario, pick_grasps):
    # The pick's lift with every approach refused when checked and a budget of a few edge
    # checks: the search spends them on approaches at T_0 and stops undecided. Counting the
    # unchecked approaches as feasible, reachability runs on to the goal (which asks for
    # no release), so the last layer it reaches says nothing; the failure is at T_0, the
    # segment after it is the one to blame, and the reason must not claim the goal is reached.
    world = pick.world
    path = PosePath((lift(world, pick.start, 100.0),))
    veto = VetoApproach(set(range(len(pick_grasps))))
    binds = [Binding(b.name, b.family, veto) if b.name == "approach-contact" else b for b in bindings()]
    res = GraspPlanner(world, pick_grasps, binds, options=GraspGraphOptions(max_edge_checks=3)).plan(path)
    assert res.status is GraspPlanStatus.NO_PATH, res.reason
    assert veto.asked
    assert res.failing_segment == 0 and not res.at_goal, res.reason
    assert res.reason.startswith("no grasp sequence: undecided: the budget of 3 intra-pose edge checks ran out ")
    assert f"{len(veto.asked)} of them at T_0" in res.reason
    assert "goal pose is reached" not in res.reason
    assert "approach-contact 0 feasible of" in res.reason
