"""Top tier Steps 1-3: contact poses, the contact-state graph, streams."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

import ldhp_tamp.primitives.move_object  # noqa: F401  (registers the MoveObject primitives)
from geometry.collision import object_env_overlap
from geometry.contacts import contact_state
from geometry.features import FREE, ContactState
from geometry.poses import Pose
from ldhp_tamp.contact_graph import admissible_transitions, build_context, contact_pose, relevant_states
from ldhp_tamp.path import check_joined
from ldhp_tamp.primitives import REGISTRY
from ldhp_tamp.primitives.registry import Transition
from ldhp_tamp.resources import scenarios_dir
from ldhp_tamp.scenario import load_scenario
from ldhp_tamp.streams import StreamStats, pose_paths
from ldhp_tamp.symbolic import ContactGraph, build_problem, load_domain, parse_domain, solve

S = ContactState.parse


@pytest.fixture(scope="module")
def domain():
    return load_domain("ldhp")


@pytest.fixture(scope="module")
def task1():
    sc = load_scenario(scenarios_dir() / "task1_zero_mobility_lift.toml")
    return sc, build_context(sc.world, sc.start, sc.goal)


@pytest.fixture(scope="module")
def task1_grasps():
    """Task 1's context with its grasp set, as the planner builds it: air-move lifts need a
    grasp that carries the object."""
    from dataclasses import replace

    from geometry.grasps import GraspOptions, enumerate_grasps

    sc = load_scenario(scenarios_dir() / "task1_zero_mobility_lift.toml")
    ctx = build_context(sc.world, sc.start, sc.goal)
    return sc, replace(ctx, grasps=enumerate_grasps(sc.world, GraspOptions(samples_per_edge=sc.settings.samples_per_edge)))


@pytest.fixture(scope="module")
def task2():
    sc = load_scenario(scenarios_dir() / "task2_slot_insertion.toml")
    return sc, build_context(sc.world, sc.start, sc.goal)


def test_task1_has_the_papers_eight_states(task1) -> None:
    _, ctx = task1
    names = sorted(s.name for s in ctx.states if not s.is_free)
    assert names == sorted([f"v{i}-e1" for i in range(1, 5)] + [f"l{i}-e1" for i in range(1, 5)])
    assert FREE in ctx.states  # the goal is in the air


def test_step1_contact_poses(task1, task2) -> None:
    _, ctx = task1
    assert not ctx.start_free and ctx.start_state == S("l1-e1")
    # the goal (tipped 60 degrees, 100 mm up) comes down onto its corner v2
    assert ctx.goal_free and ctx.goal_contact.state == S("v2-e1")
    assert ctx.goal_contact.travel == pytest.approx(100.0, abs=1e-3)
    assert ctx.goal_contact.direction == (0.0, -1.0)
    _, ctx2 = task2
    # held above the slot, the block comes down onto the slot floor on its 70 mm end
    assert ctx2.start_free and ctx2.start_contact.state == S("l1-e1")
    assert ctx2.start_contact.pose.y == pytest.approx(0.0, abs=1e-3)


def test_contact_pose_refuses_an_object_with_nothing_around(task1) -> None:
    sc, _ = task1
    with pytest.raises(ValueError, match="touches nothing"):
        contact_pose(sc.world, Pose(0.0, 2000.0, 0.0), reach=100.0)


def test_task1_transitions(task1, task1_grasps, domain) -> None:
    _, ctx = task1_grasps
    tr = admissible_transitions(ctx, domain.info, REGISTRY)
    assert (S("l1-e1"), S("v2-e1")) in tr["tip"]
    assert (S("v2-e1"), S("l2-e1")) in tr["tip"]
    # Lifted only where a grasp fits that carries the block turned to the goal's 60
    # degrees: on its corner v2 (the Step-1 state); not standing or lying on a side (no
    # grasp of this fixed-width gripper holds it there), nor tipped the other way (the
    # turn passes through standing or upside down). Without the grasp set, the states
    # that a translation straight up leaves are lifted whatever holds them.
    assert tr["air-move"] == frozenset({(S("v2-e1"), FREE)})
    _, bare = task1
    assert {(S("l1-e1"), FREE), (S("l2-e1"), FREE), (S("v2-e1"), FREE)} <= admissible_transitions(
        bare, domain.info, REGISTRY)["air-move"]
    assert tr["biplanar-slide"] == frozenset()  # one environment edge: nothing to slide between
    for pairs in tr.values():
        for a, b in pairs:
            assert a != b and a in ctx.state_set and b in ctx.state_set


@pytest.mark.parametrize("n_cores", [1, 2])
def test_transitions_beside_other_work_are_the_same(task1_grasps, domain, monkeypatch, tmp_path,
                                                     n_cores: int) -> None:
    """``meanwhile``: the transitions computed in a forked process (two cores) or after
    the other work (one core), the same pairs with the same memo (the air-move's
    carrying grasps) as when computed here."""
    from dataclasses import replace

    from ldhp_tamp import parallel

    _, base = task1_grasps
    here = replace(base, memo={})
    expected = admissible_transitions(here, domain.info, REGISTRY)
    monkeypatch.setattr(parallel, "cores", lambda: n_cores)
    where = tmp_path / "pid"
    real = REGISTRY.admissible_transitions

    def recorded(*args, **kwargs):
        where.write_text(str(os.getpid()))  # a file: the forked process's memory is its own
        return real(*args, **kwargs)

    monkeypatch.setattr(REGISTRY, "admissible_transitions", recorded)
    ctx = replace(base, memo={})
    order = []
    got = admissible_transitions(ctx, domain.info, REGISTRY,
                                 meanwhile=lambda: order.append(("meanwhile", os.getpid(), len(ctx.memo))))
    assert got == expected
    assert order == [("meanwhile", os.getpid(), 0)]  # here, before the transitions' memo came in
    assert (int(where.read_text()) != os.getpid()) == (n_cores > 1)  # forked on two cores only
    assert set(ctx.memo) == set(here.memo) and ctx.memo
    for key, value in here.memo.items():
        np.testing.assert_array_equal(np.asarray(ctx.memo[key], dtype=object), np.asarray(value, dtype=object))


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")
def test_transitions_in_the_solves_helper_are_the_same(task1_grasps, domain) -> None:
    """With the solve's helper (forked with the setup's context, domain and registry as
    the last item of its state), the same pairs and memo as computed here; the helper
    lives on for the bottom tier's work."""
    from dataclasses import replace

    from ldhp_tamp.parallel import Helper

    _, base = task1_grasps
    here = replace(base, memo={})
    expected = admissible_transitions(here, domain.info, REGISTRY)
    ctx = replace(base, memo={})
    helper = Helper((None, None, None, None, (ctx, domain.info, REGISTRY)))
    try:
        order = []
        got = admissible_transitions(ctx, domain.info, REGISTRY, meanwhile=lambda: order.append(len(ctx.memo)),
                                     helper=helper)
        assert got == expected and order == [0]
        assert set(ctx.memo) == set(here.memo) and ctx.memo
        assert helper.idle  # its answer taken: free for the next call
    finally:
        helper.close()


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")
def test_a_failure_beside_the_helpers_transitions_ends_the_helper(task1_grasps, domain) -> None:
    from dataclasses import replace

    from ldhp_tamp.parallel import Helper

    _, base = task1_grasps
    ctx = replace(base, memo={})
    helper = Helper((None, None, None, None, (ctx, domain.info, REGISTRY)))

    def fail() -> None:
        raise KeyError("meanwhile")

    with pytest.raises(KeyError, match="meanwhile"):
        admissible_transitions(ctx, domain.info, REGISTRY, meanwhile=fail, helper=helper)
    assert not helper.alive  # closed and reaped: its answer would have come first


def test_vertex_on_convex_vertex_states_are_dropped(task2) -> None:
    sc, ctx = task2
    env = sc.world.environment
    convex = env.vertices[env.vertex_convex]
    for w in ctx.witnesses:
        for p in w.witnesses:
            v = sc.world.object_vertices(p)
            assert np.min(np.linalg.norm(v[:, None] - convex[None], axis=2)) > 0.1


def test_vertices_on_vertices_is_the_one_pose_test_at_each(task2) -> None:
    """contact_graph._vertices_on_vertices (all witnesses at once) against the one-pose
    _vertex_on_vertex, on task 2's enumerated witnesses and poses nudged from them."""
    from geometry.contacts import enumerate_contact_states
    from ldhp_tamp.contact_graph import _vertex_on_vertex, _vertices_on_vertices

    sc, ctx = task2
    poses = [p for w in enumerate_contact_states(sc.world, ctx.workspace, max_contacts=3) for p in w.witnesses]
    rng = np.random.default_rng(0)
    poses += [Pose(p.x + 0.05 * rng.normal(), p.y + 0.05 * rng.normal(), p.theta) for p in poses]
    got = _vertices_on_vertices(sc.world, poses)
    assert got.tolist() == [_vertex_on_vertex(sc.world, p) for p in poses]
    assert got.any() and not got.all()
    assert _vertices_on_vertices(sc.world, []).shape == (0,)


def test_states_in_a_concave_corner_are_kept(task2, domain) -> None:
    """The block lying in the slot's corner (l4 on the floor, l3 flush with the left
    wall, v4 in the corner) ends the paper's biplanar slide along floor and wall."""
    _, ctx = task2
    corner = S("l4-e1+l3-e2")
    assert corner in ctx.state_set
    tr = admissible_transitions(ctx, domain.info, REGISTRY)
    assert (S("v1-e1+v4-e2"), corner) in tr["biplanar-slide"]


def test_relevant_states_prune_only_states_off_every_path(task2, domain) -> None:
    _, ctx = task2
    tr = admissible_transitions(ctx, domain.info, REGISTRY)
    keep = relevant_states(ctx, tr)
    assert ctx.start_state in keep and ctx.goal_state in keep
    assert len(keep) < len(ctx.states)
    full = ContactGraph(ctx.states, tr, ctx.start_state, ctx.goal_state, True, True)
    pruned = ContactGraph(tuple(s for s in ctx.states if s in keep),
                          {a: frozenset(p for p in v if p[0] in keep and p[1] in keep) for a, v in tr.items()},
                          ctx.start_state, ctx.goal_state, True, True)
    a = solve(build_problem(domain, full), "pyperplan")
    b = solve(build_problem(domain, pruned), "pyperplan")
    assert a.solved and b.solved and len(a.actions) == len(b.actions)


def test_task1_streams_give_a_joined_path_to_the_goal(task1, domain) -> None:
    sc, ctx = task1
    plan = [Transition("tip", S("l1-e1"), S("v2-e1")), Transition("air-move", S("v2-e1"), FREE)]
    stats = StreamStats()
    paths = list(pose_paths(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), stats))
    assert paths
    best = paths[0]
    # ranked by the heuristic: the first path tips exactly to the goal's orientation
    assert best.primitives == ("tip", "air-move")
    assert best.segments[0].parameters["pivot"] == "v2"
    assert best.segments[0].parameters["angle"] == pytest.approx(60.0, abs=1e-6)
    for path in paths:
        check_joined(path.segments)
        assert np.allclose(path.segments[0].poses[0], [0.0, 0.0, 0.0])
        end = path.segments[-1].end
        assert end.distance(sc.goal)[0] < 1e-6 and end.distance(sc.goal)[1] < 1e-9
        for seg in path.segments:
            assert not object_env_overlap(sc.world, seg.poses).any()
            verts = np.array([sc.world.object.polygon.transformed(*p) for p in seg.poses])
            assert np.max(np.linalg.norm(np.diff(verts, axis=0), axis=2)) <= 4.0 + 1e-9
            assert seg.step in (0, 1)


def test_lift_off_candidates_are_one_pose_at_a_time(task1_grasps, domain) -> None:
    """The lift-off poses' carrier candidates, their holds found together and their
    overlaps tested in one batch (``carrier_candidates_each``), are what each pose alone
    gives: the grasps that hold the block in the air at the goal's orientation and at the
    pose's (``motion_conditioned`` of one pose far above the table) and are clear of the
    table at the pose. The same values, poses and grasps, in the same order."""
    from dataclasses import replace

    from geometry.collision import gripper_env_overlap
    from geometry.grasps import motion_conditioned
    from ldhp_tamp import streams
    from ldhp_tamp.primitives import move_object

    _, base = task1_grasps
    plan = [Transition("tip", S("l1-e1"), S("v2-e1")), Transition("air-move", S("v2-e1"), FREE)]
    path = next(iter(pose_paths(replace(base, memo={}), plan, domain.info, REGISTRY, np.random.default_rng(0),
                                StreamStats())))
    tip = path.segments[0]
    assert tip.primitive == "tip" and tip.to_state == S("v2-e1")
    ctx = replace(base, memo={})
    found = streams._lift_off_candidates(ctx, tip, S("v2-e1"))
    assert len(found) >= 3
    gs, world = base.grasps, base.world

    def high(theta: float) -> np.ndarray:
        w = base.workspace
        return np.array([[0.5 * (w.xmin + w.xmax), w.ymax + 10.0 * base.reach, theta]])

    goal = motion_conditioned(world, gs, high(base.goal.theta), np.arange(len(gs)), rate=False).indices
    for value, pose, held in found:
        assert np.array_equal(pose, tip.motion.poses([value])[0])
        both = motion_conditioned(world, gs, high(pose[2]), goal, rate=False).indices
        clear = both[~gripper_env_overlap(world, gs.world_gripper(pose, both), gs.width[both])]
        assert held.size and np.array_equal(held, clear)
    # one pose at a time through the memo, and again from it: the same sets
    poses = [Pose.from_array(p) for _, p, _ in found] + [base.goal]
    each = move_object.carrier_candidates_each(replace(base, memo={}), poses)
    alone = [move_object.carrier_candidates(replace(base, memo={}), p) for p in poses]
    again = move_object.carrier_candidates_each(ctx, poses)
    assert all(np.array_equal(a, b) and np.array_equal(a, c) for a, b, c in zip(each, alone, again))
    assert move_object.carrier_candidates_each(replace(base, grasps=None), poses) is None


def test_task1_tip_stream_offers_an_overshoot_aligned_back(task1, domain) -> None:
    """Among the first three tip samples is one past the goal's 60 degrees (halfway from
    the goal value to the end of the v2-e1 interval, ~74.6 degrees), aligned back by an
    in-state tip. Task 1 needs it: the lifting lever pinch (l2 at ~108 mm, l4 at ~150 mm)
    holds the block against the table only up to ~46 degrees and alone only from ~59.9,
    and its l2 finger holds the block alone (so that a pivot can re-enter the pinch) only
    past ~69 degrees."""
    sc, ctx = task1
    plan = [Transition("tip", S("l1-e1"), S("v2-e1")), Transition("air-move", S("v2-e1"), FREE)]
    paths = list(pose_paths(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), StreamStats(), limit=3))
    angles = [p.segments[0].parameters["angle"] for p in paths]
    assert angles[0] == pytest.approx(60.0, abs=1e-6)
    over = [p for p in paths if 69.0 < p.segments[0].parameters["angle"] < 85.0]
    assert over
    path = over[0]
    assert path.primitives == ("tip", "tip", "air-move")
    back = path.segments[1]
    assert back.parameters["in_state"] and back.parameters["pivot"] == "v2"
    assert back.parameters["angle"] == pytest.approx(path.segments[0].parameters["angle"] - 60.0, abs=1e-6)
    check_joined(path.segments)


def test_stream_repositions_within_a_state(task2, domain) -> None:
    """20 mm from the left wall the block cannot tip left onto its side; the stream
    pushes it along the floor first (an in-state motion) and tips it from there."""
    _, ctx = task2
    plan = [Transition("air-move", FREE, S("l1-e1")), Transition("tip", S("l1-e1"), S("v1-e1")),
            Transition("tip", S("v1-e1"), S("l4-e1"))]
    stats = StreamStats()
    paths = list(pose_paths(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), stats))
    assert paths and stats.repositions > 0
    for path in paths:
        check_joined(path.segments)
        last_tip = [s for s in path.segments if s.primitive == "tip" and s.to_state == S("l4-e1")][0]
        k = path.segments.index(last_tip)
        before = path.segments[k - 1]
        assert before.parameters["in_state"] and before.from_state == before.to_state == S("v1-e1")
        # the pivot v1 is at least the block's diagonal from the left wall
        assert last_tip.motion.pose(0.0).x >= 160.0


def test_stream_dead_end_is_reported(task2, domain) -> None:
    _, ctx = task2
    # no rotation of the standing block reaches its top face directly
    plan = [Transition("air-move", FREE, S("l1-e1")), Transition("tip", S("l1-e1"), S("l3-e1"))]
    stats = StreamStats()
    assert list(pose_paths(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), stats)) == []
    assert stats.dead_ends[plan[1]] > 0


def test_a_domain_without_tip_has_no_tip_transitions(task1, domain) -> None:
    _, ctx = task1
    text = domain.info.source
    src = open(text).read() if not text.startswith("<") else text
    start = src.index("(:action tip")
    end = src.index("(:action", start + 5)
    reduced = parse_domain(src[:start] + src[end:], "no-tip")
    tr = admissible_transitions(ctx, reduced.info, REGISTRY)
    assert "tip" not in tr and "push" in tr


def test_task1_pddl_problem_has_the_eight_state_graph(task1_grasps, domain) -> None:
    sc, ctx = task1_grasps
    tr = admissible_transitions(ctx, domain.info, REGISTRY)
    keep = relevant_states(ctx, tr)
    graph = ContactGraph(tuple(s for s in ctx.states if s in keep),
                         {a: frozenset(p for p in v if p[0] in keep and p[1] in keep) for a, v in tr.items()},
                         ctx.start_state, ctx.goal_state, sc.start_grasp is not None, sc.goal_release)
    problem = build_problem(domain, graph)
    objects = sorted(o.name for o in problem.up_problem.all_objects)
    contact = [o for o in objects if o != "s-free"]
    # every one of the paper's 8 states is on a path from l1-e1 to the lift (tip onto a
    # corner, tip down onto the side, ... air-move from v2-e1), plus free
    assert len(contact) == 8 and "s-free" in objects
    result = solve(problem, "pyperplan")
    assert result.solved
    assert [str(a.transition) for a in result.actions if a.transition] == [
        "tip s-l1-e1 s-v2-e1", "air-move s-v2-e1 s-free"]


def _first_difference(a, b) -> int | None:
    """The first planned step at which two pose paths differ (None if they are equal)."""
    steps = sorted({s.step for s in a.segments} | {s.step for s in b.segments})
    for k in steps:
        sa = [s.poses for s in a.segments if s.step == k]
        sb = [s.poses for s in b.segments if s.step == k]
        if len(sa) != len(sb) or any(x.shape != y.shape or not np.allclose(x, y) for x, y in zip(sa, sb)):
            return k
    return None


def test_the_search_backjumps_to_the_failed_step(task2, domain) -> None:
    """After a failure at step j the next path differs at step j or before it, never only
    after it; without feedback the search is a plain depth-first one."""
    _, ctx = task2
    plan = [Transition("air-move", FREE, S("l1-e1")), Transition("tip", S("l1-e1"), S("v1-e1")),
            Transition("tip", S("v1-e1"), S("l4-e1"))]
    plain = pose_paths(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), StreamStats())
    first, second = plain.next(), plain.next()
    assert _first_difference(first, second) == 2  # the last step varies first
    search = pose_paths(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), StreamStats())
    previous = search.next()
    assert _first_difference(previous, first) is None
    for _ in range(3):
        path = search.next(failed_step=1)
        if path is None:
            break
        assert _first_difference(previous, path) <= 1
        check_joined(path.segments)
        previous = path


def test_the_search_stops_when_its_work_budget_is_spent(task2, domain) -> None:
    _, ctx = task2
    plan = [Transition("air-move", FREE, S("l1-e1")), Transition("tip", S("l1-e1"), S("v1-e1")),
            Transition("tip", S("v1-e1"), S("l4-e1"))]
    stats = StreamStats()
    # the second tip needs repositioning samples: far more than three sample calls
    assert list(pose_paths(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), stats,
                           max_sample_calls=3)) == []
    assert stats.budget_exhausted and stats.sample_calls == 3
    assert not stats.dead_ends  # running out of work is not evidence against a transition


def test_dead_ends_are_recorded_by_step(task2, domain) -> None:
    _, ctx = task2
    plan = [Transition("air-move", FREE, S("l1-e1")), Transition("tip", S("l1-e1"), S("l3-e1"))]
    stats = StreamStats()
    assert list(pose_paths(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), stats)) == []
    assert set(stats.dead_steps) == {1} and not stats.budget_exhausted


def test_the_alignment_settles_a_block_that_is_in_contact_within_tolerance(task2, domain) -> None:
    """A block in state l1-e1 may be 0.05 degrees off flat and 0.06 mm above the floor
    (contacts are identified within CONTACT_TOL): the alignment to a flat target rotates
    it until it lands flat, then pushes it along the floor; what is left across the push
    is the contact-tolerance offset."""
    from ldhp_tamp.streams import align

    _, ctx = task2
    off = Pose(150.0, 0.06, -0.00086)  # v1 0.06 mm up, v2 on the floor
    assert contact_state(ctx.world, off) == S("l1-e1")
    target = Pose(20.0, 0.0008, 0.0)  # T'_g of task 2's start (1 um back-off)
    moves = align(ctx, domain.info, REGISTRY, S("l1-e1"), off, target)
    assert moves is not None and [m.primitive for m in moves] == ["tip", "push"]
    end = moves[-1].end
    assert abs(end.theta) < 1e-9 and abs(end.x - 20.0) < 1e-6 and abs(end.y - target.y) <= 0.1
    check_joined(tuple(moves))


def test_air_moves_lift_and_place_when_the_goal_is_a_contact_pose(domain) -> None:
    """With the goal in contact, air-move enters the goal's state from above and leaves
    every state with a witness that a translation straight up takes into free space, at
    any orientation (the carried object is turned to the goal's in the air)."""
    peg = load_scenario(scenarios_dir() / "cmgmp_peg_in_hole.toml")
    ctx = build_context(peg.world, peg.start, peg.goal)
    pairs = admissible_transitions(ctx, domain.info, REGISTRY)["air-move"]
    assert (FREE, ctx.goal_contact.state) in pairs  # lowered into the hole
    assert (ctx.start_contact.state, FREE) in pairs  # the standing peg is lifted
    lifted = {a for a, b in pairs if b == FREE}
    # some states are lifted from tilted only: no witness at the goal's orientation
    assert any(all(abs(w.theta - peg.goal.theta) > 1e-6 for w in ctx.witness_poses(state)) for state in lifted)


def test_a_placement_goes_over_then_straight_down(domain) -> None:
    peg = load_scenario(scenarios_dir() / "cmgmp_peg_in_hole.toml")
    ctx = build_context(peg.world, peg.start, peg.goal)
    plan = [Transition("air-move", ctx.start_state, FREE), Transition("air-move", FREE, ctx.goal_state)]
    path = next(pose_paths(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), StreamStats()))
    up, over, down = path.segments
    assert (up.motion.direction, over.motion.direction, down.motion.direction) == ((0.0, 1.0), (1.0, 0.0), (0.0, -1.0))
    assert up.to_state == over.from_state == over.to_state == down.from_state == FREE
    end = down.end
    assert abs(end.x - peg.goal.x) < 1e-9 and abs(end.y - peg.goal.y) < 0.1 and end.theta == peg.goal.theta
    check_joined(path.segments)
    for seg in path.segments:
        assert not object_env_overlap(peg.world, seg.poses).any()


def test_lifts_and_placements_need_a_grasp_that_carries_the_object(task2, domain) -> None:
    """Task 2's goal lies flat on the slot floor: a pinch that would carry it in the air
    has its lower finger in the floor there, so the goal is never placed from above, nor
    is the block lifted off the slot floor (without a grasp set, both are admitted). The
    block lying across a lip of the slot can be pinched from above and below, and lifted."""
    from geometry.grasps import GraspOptions, enumerate_grasps

    sc, ctx = task2
    grasps = enumerate_grasps(sc.world, GraspOptions(samples_per_edge=20))
    with_grasps = build_context(sc.world, sc.start, sc.goal, grasps=grasps)
    air = admissible_transitions(with_grasps, domain.info, REGISTRY)["air-move"]
    assert (FREE, with_grasps.start_contact.state) in air  # Step 1
    assert (FREE, with_grasps.goal_contact.state) not in air
    assert not any(a.contacts and all(c.env == 0 for c in a.contacts) for a, b in air if b == FREE)  # e1: the floor
    unfiltered = admissible_transitions(ctx, domain.info, REGISTRY)["air-move"]
    assert (FREE, ctx.goal_contact.state) in unfiltered and (ctx.goal_contact.state, FREE) in unfiltered


def test_a_notched_polygon_lying_in_the_corner_is_a_three_contact_state(domain) -> None:
    """The 9-gon of gen_slot_concave9 lying flat in the slot's right corner touches the wall
    with l1 and the floor with v1 and l7 (its notch between): a three-contact state, which
    the biplanar slide that lays it down ends in, and from which it is pushed to the goal."""
    sc = load_scenario(scenarios_dir() / "gen_slot_concave9.toml")
    ctx = build_context(sc.world, sc.start, sc.goal)
    corner = S("v1-e1+l7-e1+l1-e8")
    assert corner in ctx.state_set and len(corner.contacts) == 3
    tr = admissible_transitions(ctx, domain.info, REGISTRY)
    assert (S("v1-e1+v2-e8"), corner) in tr["biplanar-slide"]
    assert (corner, ctx.goal_state) in tr["push"]


def test_point_contacts_are_memoised_per_pose(task2) -> None:
    """move_object._point_contacts_at: _point_contacts at the pose, computed once per pose
    and context (the push and biplanar-slide families of a witness share it)."""
    from dataclasses import replace

    from ldhp_tamp.primitives import move_object as mo

    sc, ctx = task2
    ctx = replace(ctx, memo={})
    poses = [p for w in ctx.witnesses[:12] for p in w.witnesses[:2]]
    for p in poses:
        want = mo._point_contacts(sc.world, p)
        assert mo._point_contacts_at(ctx, p) == want and want
        ctx.memo[("point-contacts", p)] = ("sentinel",)
        assert mo._point_contacts_at(ctx, p) == ["sentinel"]  # the memo answers


@pytest.mark.parametrize("loose", [False, True])
@pytest.mark.parametrize("limit", [1, 3, 6, 100])
def test_lift_offs_rank_as_with_every_carrier_counted(task1_grasps, domain, limit, loose, monkeypatch) -> None:
    """The lift-off ends a stream tries first: the best ``limit`` by carriers (most
    first), then the end's distance to the goal, then the order found, as when every
    pose's carriers are counted; only the poses that can still rank are turned. Task 1's
    turns keep every candidate; ``loose``: a turn that keeps some of them only (from
    none to all, by the pose), so that the candidates' counts bound the carriers'
    loosely and the ranking must turn more poses to be sure."""
    from dataclasses import replace

    from ldhp_tamp import streams
    from ldhp_tamp.primitives.move_object import carriers

    _, base = task1_grasps
    t = Transition("tip", S("l1-e1"), S("v2-e1"))
    plan = [t, Transition("air-move", S("v2-e1"), FREE)]
    path = next(iter(pose_paths(replace(base, memo={}), plan, domain.info, REGISTRY, np.random.default_rng(0),
                                StreamStats())))
    tip = path.segments[0]
    ctx = replace(base, memo={})
    turned = []
    real = streams.carriers_among

    def turn(c, pose, held, **kw):
        if loose:
            return held[:int(round(abs(pose.theta) * 1000.0)) % (held.size + 1)]
        return real(c, pose, held, **kw)

    def counted(c, pose, held, **kw):
        turned.append(pose.theta)
        return turn(c, pose, held, **kw)

    monkeypatch.setattr(streams, "carriers_among", counted)
    search = streams.PathSearch(ctx, plan, domain.info, REGISTRY, np.random.default_rng(0), StreamStats(), limit=limit)
    got = [moves[-1].s1 for moves in search._lift_offs(t, [(tip,)])]
    # every pose's carriers counted, then ranked
    found = streams._lift_off_candidates(replace(base, memo={}), tip, S("v2-e1"))
    values = [v for v, _, _ in found]
    ranked = []
    for i, (v, pose, held) in enumerate(found):
        c = replace(base, memo={})
        n = int(turn(c, Pose.from_array(pose), held).size if loose else carriers(c, Pose.from_array(pose)).size)
        if n:
            ranked.append((-n, float(ctx.goal_distance(tip.motion.poses([v]))[0]), i, v))
    want = [v for *_, v in sorted(ranked)[:limit]]
    assert got == want and len(want) == min(limit, len(ranked)) >= 1
    assert len(turned) < len(values) or limit >= len(values)
