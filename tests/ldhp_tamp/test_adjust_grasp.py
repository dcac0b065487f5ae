"""The AdjustGrasp primitives (``ldhp_tamp.primitives.adjust_grasp``) on hand-made cases.

A 100 x 40 block lies flat on a table (the spec's pick example, goal = start so that a
plan of AdjustGrasp steps alone has the right ends), grasped by the polyline gripper of
the example, or by a zero-mobility two-point gripper (40 mm spacing). Every edge used
here is turned into plan steps (an ``approach-contact`` first, so that the steps join)
and checked by the plan validator (rules 1-7 of ``ldhp-plan/1``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from geometry import mechanics
from geometry.grasps import GraspOptions, enumerate_grasps, pose_conditioned
from geometry.poses import Pose, wrap_angle
from ldhp_tamp.errors import InputError
from ldhp_tamp.plan import PLAN_FORMAT, Family, Plan, PlanStats, PlanStatus, Step
from ldhp_tamp.primitives import REGISTRY, AdjustGraspPrimitive
from ldhp_tamp.primitives import adjust_grasp as ag
from ldhp_tamp.scenario import Scenario, load_scenario_string
from ldhp_tamp.validate import validate_plan

BLOCK = """
format = "ldhp-scenario/1"
name = "{name}"
[object]
vertices = [[0, 0], [100, 0], [100, 40], [0, 40]]
[[environment.solids]]
name = "table"
vertices = [[-300, -50], [300, -50], [300, 0], [-300, 0]]
{extra}
[gripper]
{gripper}
[friction]
environment = 0.3
gripper = 0.6
[task]
start = [0, 0, 0]
goal = [0, 0, 0]
"""
POLYLINE = 'model = "polyline"\nfinger = [[0, 0], [10, 0], [10, 45], [0, 45]]\nopening = [0, 140]'
TWO_POINT = 'model = "two-point"\nfinger_radius = 5\nspacing = [40, 40]'
#: A two-point gripper that opens and closes: its pinches have the widths and closing
#: angles at which the second finger meets the object.
RANGED = 'model = "two-point"\nfinger_radius = 5\nspacing = [10, 150]'
#: A wall beside the middle of the block's top, clear of it: the half turn of a flip there hits it.
WALL = '[[environment.solids]]\nname = "wall"\nvertices = [[62, 48], [90, 48], [90, 200], [62, 200]]'
T0 = Pose(0.0, 0.0, 0.0)
STATE = ("l1-e3", "l1-e3")


class Case:
    """A scenario, its grasps (K = 10), the context and the approachable grasps at T0."""

    def __init__(self, gripper: str, extra: str = "") -> None:
        self.scenario: Scenario = load_scenario_string(BLOCK.format(name="block", extra=extra, gripper=gripper), "block")
        self.world = self.scenario.world
        self.grasps = enumerate_grasps(self.world, GraspOptions(samples_per_edge=10))
        self.ctx = ag.AdjustContext(self.world, self.grasps)
        self.gt = pose_conditioned(self.world, self.grasps, T0.as_array())
        self.approach = ag.ApproachContact().intra_edges(self.ctx, T0, self.gt)

    def step(self, prim: ag._AdjustGrasp, edges: ag.IntraEdges, i: int) -> Step:
        return Step(prim.name, Family.ADJUST_GRASP, prim.parameters(self.ctx, edges, i), STATE,
                    prim.waypoints(self.ctx, T0, edges, i))

    def approach_to(self, g: int) -> Step:
        i = int(np.flatnonzero(self.approach.dst == g)[0])
        return self.step(ag.ApproachContact(), self.approach, i)

    def approachable(self, rows: np.ndarray) -> np.ndarray:
        return np.isin(rows, self.approach.dst)

    def validate(self, steps: list[Step]) -> None:
        plan = Plan(PLAN_FORMAT, self.scenario.name, self.scenario.sha256, PlanStatus.SOLVED, tuple(steps), PlanStats())
        report = validate_plan(plan, self.scenario)
        assert report.valid, [str(v) for v in report.violations[:5]]
        assert report.steps_checked == len(steps)


@pytest.fixture(scope="module")
def poly() -> Case:
    return Case(POLYLINE)


@pytest.fixture(scope="module")
def two_point() -> Case:
    return Case(TWO_POINT)


@pytest.fixture(scope="module")
def ranged() -> Case:
    return Case(RANGED)


def finger_moves(case: Case, step: Step) -> tuple[float, float]:
    """Largest finger-centre / finger-vertex motion and width change between waypoints."""
    from geometry.poses import transform_points

    grip = np.array([w.gripper.as_array() for w in step.waypoints])
    width = np.array([w.width for w in step.waypoints])
    pts = np.stack([transform_points(grip[i:i + 1], case.ctx.finger_points(width[i])[0])[0] for i in range(len(width))])
    move = np.linalg.norm(np.diff(pts, axis=0), axis=-1).max() if len(width) > 1 else 0.0
    return float(move), float(np.abs(np.diff(width)).max() if len(width) > 1 else 0.0)


def test_the_six_primitives_are_registered_as_adjust_grasp_with_both_interfaces():
    for name in ag.PRIMITIVES:
        binding = REGISTRY.binding(name)
        assert binding.family is Family.ADJUST_GRASP
        assert isinstance(binding.implementation, AdjustGraspPrimitive)
        assert isinstance(binding.implementation, ag.LazyAdjustGrasp)
        assert binding.implementation.name == name


def test_approach_from_above_then_close_validates(poly: Case):
    gs = poly.grasps
    close = ag.Close().intra_edges(poly.ctx, T0, poly.gt)
    assert len(close) and close.checked
    i = int(np.flatnonzero(poly.approachable(close.src))[0])
    src, dst = int(close.src[i]), int(close.dst[i])
    assert gs.n_touching[src] == 1 and gs.n_touching[dst] == 2 and gs.width[dst] < gs.width[src]
    approach, closing = poly.approach_to(src), poly.step(ag.Close(), close, i)
    poly.validate([approach, closing])
    # The approach starts in free space above the block, touching nothing, and ends on g.
    first = approach.waypoints[0]
    assert first.finger_contacts == (None, None) and first.gripper.y > 40 + 45
    assert sum(c is not None for c in approach.waypoints[-1].finger_contacts) == 1
    # Closing keeps the touching finger's contact and ends with both fingers on the block.
    k = int(close.finger[i])
    kept = {w.finger_contacts[k] for w in closing.waypoints}
    assert len(kept) == 1 and None not in kept
    assert all(c is not None for c in closing.waypoints[-1].finger_contacts)
    for step in (approach, closing):
        move, dw = finger_moves(poly, step)
        assert move <= ag.AdjustGraspOptions().step + 1e-9 and dw <= ag.AdjustGraspOptions().step + 1e-9


def test_open_releases_the_pinch_and_ends_where_approach_starts(poly: Case):
    close = ag.Close().intra_edges(poly.ctx, T0, poly.gt)
    i = int(np.flatnonzero(poly.approachable(close.src))[0])
    opening = ag.Open().intra_edges(poly.ctx, T0, poly.gt)
    j = int(np.flatnonzero(opening.src == close.dst[i])[0])
    approach = poly.approach_to(int(close.src[i]))
    release = poly.step(ag.Open(), opening, j)
    poly.validate([approach, poly.step(ag.Close(), close, i), release])
    assert release.waypoints[-1].finger_contacts == (None, None)
    assert release.waypoints[-1].gripper == approach.waypoints[0].gripper  # the home pose
    assert opening.dst[j] == ag.NO_CONTACT


def test_pivot_turns_about_the_touching_finger(poly: Case):
    gs = poly.grasps
    pivot = ag.Pivot().intra_edges(poly.ctx, T0, poly.gt)
    i = int(np.flatnonzero(poly.approachable(pivot.src))[0])
    turn = poly.step(ag.Pivot(), pivot, i)
    poly.validate([poly.approach_to(int(pivot.src[i])), turn])
    k = int(pivot.finger[i])
    kept = {w.finger_contacts[k] for w in turn.waypoints}
    assert len(kept) == 1 and None not in kept  # the pivot finger never lets go
    dphi = math.remainder(gs.gripper[pivot.dst[i], 2] - gs.gripper[pivot.src[i], 2], 2 * math.pi)
    assert math.remainder(math.radians(turn.parameters["angle"]) - dphi, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    assert len(turn.waypoints) >= 2


def test_slide_moves_a_finger_along_the_top_edge(poly: Case):
    gs = poly.grasps
    slide = ag.Slide().intra_edges(poly.ctx, T0, poly.gt)
    top = 2  # l3, the top edge of the block
    on_top = (gs.feature[slide.src, slide.finger] == top) & poly.approachable(slide.src)
    i = int(np.flatnonzero(on_top)[0])
    step = poly.step(ag.Slide(), slide, i)
    poly.validate([poly.approach_to(int(slide.src[i])), step])
    k = int(slide.finger[i])
    pts = np.array([w.finger_contacts[k] for w in step.waypoints])
    assert np.allclose(pts[:, 1], 40.0)  # on the top edge all along
    assert abs(pts[-1, 0] - pts[0, 0]) == pytest.approx(slide.travel[i])
    assert gs.gripper[slide.src[i], 2] == gs.gripper[slide.dst[i], 2]


def test_flip_where_clearance_allows(two_point: Case):
    gs = two_point.grasps
    # Finger 1 on the middle of the top, finger 2 straight above it.
    g = int(np.flatnonzero((gs.n_touching == 1) & gs.touching[:, 0] & np.isclose(gs.contact[:, 0, 0], 45)
                           & np.isclose(gs.contact[:, 0, 1], 40) & np.isclose(gs.gripper[:, 2], math.pi / 2))[0])
    flip = ag.Flip().propose(two_point.ctx, T0, [g], np.isin(np.arange(len(gs)), two_point.gt))
    assert len(flip) == 2 and set(flip.sense.tolist()) == {1, -1}
    res = ag.Flip().check(two_point.ctx, T0, flip)
    assert res.ok.all()
    step = two_point.step(ag.Flip(), flip, 0)
    two_point.validate([two_point.approach_to(g), step])
    # The fingers have swapped onto the same contact.
    assert step.waypoints[0].finger_contacts[0] == pytest.approx(step.waypoints[-1].finger_contacts[1])
    assert step.waypoints[-1].finger_contacts[0] is None


def test_flip_refused_where_the_half_turn_hits_a_wall():
    case = Case(TWO_POINT, WALL)
    gs = case.grasps
    g = int(np.flatnonzero((gs.n_touching == 1) & gs.touching[:, 0] & np.isclose(gs.contact[:, 0, 0], 45)
                           & np.isclose(gs.contact[:, 0, 1], 40) & np.isclose(gs.gripper[:, 2], math.pi / 2))[0])
    assert g in case.gt and gs.flipped[g] in case.gt  # both ends are clear of the wall
    flip = ag.Flip().propose(case.ctx, T0, [g], np.isin(np.arange(len(gs)), case.gt))
    res = ag.Flip().check(case.ctx, T0, flip)
    assert not res.ok.any()
    assert set(res.failure.tolist()) == {ag.CheckFailure.ENVIRONMENT}


def test_close_is_refused_for_a_zero_mobility_gripper(two_point: Case, poly: Case):
    everything = np.ones(len(two_point.grasps), dtype=bool)
    assert len(ag.Close().propose(two_point.ctx, T0, two_point.gt, everything)) == 0
    assert len(ag.Close().intra_edges(two_point.ctx, T0, two_point.gt)) == 0
    assert len(ag.Close().propose(poly.ctx, T0, poly.gt, np.ones(len(poly.grasps), bool))) > 0


def test_approach_and_open_need_the_object_to_rest_without_the_gripper(poly: Case):
    in_air = Pose(0.0, 100.0, 0.0)
    assert not poly.ctx.layer(in_air).rests_alone and poly.ctx.layer(T0).rests_alone
    gt = pose_conditioned(poly.world, poly.grasps, in_air.as_array())
    approach = ag.ApproachContact()
    props = approach.propose(poly.ctx, in_air, [0], np.isin(np.arange(len(poly.grasps)), gt))
    res = approach.check(poly.ctx, in_air, props)
    assert len(props) and not res.ok.any()
    assert set(res.failure.tolist()) <= {ag.CheckFailure.UNSUPPORTED, ag.CheckFailure.ENVIRONMENT}
    assert (res.failure == ag.CheckFailure.UNSUPPORTED).any()
    assert len(ag.Open().intra_edges(poly.ctx, in_air, gt)) == 0


@pytest.mark.parametrize("name", ["approach-contact", "open", "close", "pivot", "slide", "flip"])
def test_waypoints_keep_the_step_and_the_grasps_at_the_ends(poly: Case, two_point: Case, name: str):
    case = two_point if name == "flip" else poly
    prim = REGISTRY.implementation(name)
    edges = prim.intra_edges(case.ctx, T0, case.gt)
    assert len(edges), name
    gs = case.grasps
    for i in np.linspace(0, len(edges) - 1, 4).astype(int):
        wps = prim.waypoints(case.ctx, T0, edges, int(i))
        step = Step(name, Family.ADJUST_GRASP, {}, STATE, wps)
        move, dw = finger_moves(case, step)
        assert move <= 4.0 + 1e-9 and dw <= 4.0 + 1e-9
        assert all(w.object == T0 for w in wps)
        for w, g in ((wps[0], int(edges.src[i])), (wps[-1], int(edges.dst[i]))):
            declared = [c is not None for c in w.finger_contacts]
            assert declared == gs.touching[g].tolist()
            if g != ag.NO_CONTACT:
                assert w.gripper.as_array() == pytest.approx(gs.gripper[g])
                assert w.width == pytest.approx(gs.width[g])


@pytest.mark.parametrize("name", ["close", "pivot", "slide", "flip", "approach-contact"])
def test_the_proposed_travel_is_the_motion_travel_and_sets_the_cost(poly: Case, two_point: Case, name: str):
    case = two_point if name == "flip" else poly
    prim = REGISTRY.implementation(name)
    props = prim.propose(case.ctx, T0, case.gt, np.isin(np.arange(len(case.grasps)), case.gt))
    sub = props.take(np.arange(min(len(props), 50)))
    motion = prim.motion(case.ctx, T0, sub)
    assert sub.travel == pytest.approx(motion.travel(case.ctx), rel=1e-9, abs=1e-9)
    opts = ag.AdjustGraspOptions(lambda1=0.5, lambda2=3.0)
    assert sub.cost(opts) == pytest.approx(0.5 * sub.travel + 3.0)
    assert (sub.switches == 1).all()


def test_intra_edges_are_the_proposals_that_pass_the_check(poly: Case):
    prim = ag.Pivot()
    members = np.isin(np.arange(len(poly.grasps)), poly.gt)
    props = prim.propose(poly.ctx, T0, poly.gt, members)
    res = prim.check(poly.ctx, T0, props)
    edges = prim.intra_edges(poly.ctx, T0, poly.gt)
    assert len(edges) == int(res.ok.sum()) < len(props)
    assert (edges.src == props.src[res.ok]).all() and (edges.dst == props.dst[res.ok]).all()
    assert edges.failures == res.failure_counts()


def test_check_motion_rejects_a_fixed_finger_pushed_into_the_object(two_point: Case):
    gs = two_point.grasps
    g = int(np.flatnonzero((gs.n_touching == 1) & gs.touching[:, 0] & np.isclose(gs.contact[:, 0, 0], 45)
                           & np.isclose(gs.contact[:, 0, 1], 40) & np.isclose(gs.gripper[:, 2], math.pi / 2))[0])

    def press(depth: float) -> ag.GripperMotion:
        """One leg moving the gripper down by ``depth`` with finger 1 FIXED on its contact."""
        one = lambda a: np.asarray(a, dtype=float)[None, None]  # noqa: E731
        return ag.GripperMotion(
            src=np.array([g]), dst=np.array([g]), start=one(gs.gripper[g]), width=one(gs.width[g]), dwidth=one(0.0),
            centre=one(gs.gripper[g, :2]), angle=one(0.0), shift=one([0.0, -depth]),
            role=np.array([[[ag.FingerRole.FIXED, ag.FingerRole.FREE]]], dtype=np.int8),
            contact=one(np.nan_to_num(gs.contact[g])), normal=one(np.nan_to_num(gs.normal[g])),
            mu=one(two_point.ctx.mu[g]), turn_normal=np.zeros((1, 1, 2), bool))

    layer = two_point.ctx.layer(T0)
    assert ag.check_motion(two_point.ctx, layer, press(0.0)).ok.all()
    res = ag.check_motion(two_point.ctx, layer, press(10.0))
    assert not res.ok[0] and res.failure[0] == ag.CheckFailure.OBJECT
    assert res.samples == 4  # ceil(10 / 4) steps


def test_options_are_checked():
    with pytest.raises(InputError, match="lambda1"):
        ag.AdjustGraspOptions(lambda1=-1.0)
    with pytest.raises(InputError, match="step"):
        ag.AdjustGraspOptions(step=0.0)


def test_holds_among_some_grasps_decides_them_as_for_all() -> None:
    from pathlib import Path

    from ldhp_tamp.primitives.adjust_grasp import AdjustContext
    from ldhp_tamp.scenario import load_scenario

    sc = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "task1_zero_mobility_lift.toml")
    gs = enumerate_grasps(sc.world, GraspOptions(samples_per_edge=20))
    pose = sc.start.as_array()
    everything = AdjustContext(sc.world, gs).holds(pose)
    ctx = AdjustContext(sc.world, gs)
    rng = np.random.default_rng(2)
    some = rng.random(len(gs)) < 0.3
    part = ctx.holds(pose, some)
    assert np.array_equal(part, everything & some) and everything[some].any()
    more = some | (rng.random(len(gs)) < 0.3)  # partly cached now
    assert np.array_equal(ctx.holds(pose, more), everything & more)
    assert np.array_equal(ctx.holds(pose), everything)
    # one test per class of grasps with the same finger contacts: what every grasp's own
    # instance answers (the environment's contacts and its fingers', all sticking), at the
    # start (standing: every grasp) and on its corner v2 tipped 70 degrees (some grasps)
    rows = np.flatnonzero(gs.n_touching >= 1)
    assert np.unique(gs.contact_classes(sc.world)[rows]).size < rows.size / 2
    for at in (pose, np.array([182.2030387935566, 65.77848345501359, -1.2217304763960293])):
        layer, p = ctx.layer(at), Pose.from_array(at)
        b, ce, touch = rows.size, layer.env_points.shape[0], gs.touching[rows]
        own = mechanics.Contacts.make(
            np.concatenate([np.broadcast_to(layer.env_points, (b, ce, 2)), p.apply(np.nan_to_num(gs.contact[rows]))], 1),
            np.concatenate([np.broadcast_to(layer.env_normals, (b, ce, 2)),
                            np.where(touch[..., None], p.apply_vector(np.nan_to_num(gs.normal[rows])), 0.0)], 1),
            np.concatenate([np.broadcast_to(layer.env_mu, (b, ce)), ctx.mu[rows]], 1),
            np.concatenate([np.full((b, ce), mechanics.ContactMode.STICKING, np.int8),
                            np.where(touch, mechanics.ContactMode.STICKING, mechanics.ContactMode.ABSENT)
                            .astype(np.int8)], 1))
        want = mechanics.feasible_batch(own, p.apply(sc.world.object.com), sc.world.object.length_scale)
        assert np.array_equal(ctx.holds(at)[rows], want) and want.any()
    assert not want.all()


@pytest.mark.parametrize("scenario", ["task2_slot_insertion", "task1_zero_mobility_lift"])
def test_slide_candidates_from_the_precomputed_pairs_are_the_per_layer_ones(scenario: str,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Slide's pairs are computed once per grasp set; a layer's candidates must be what
    pairing its own sources within their slide groups gives, by source (stably: a
    source's slides of finger 0 first, each finger's in group order), whether the
    compiled pass or numpy selects them."""
    from pathlib import Path

    from ldhp_tamp.primitives.adjust_grasp import AdjustContext, Slide, _group_pairs
    from ldhp_tamp.scenario import load_scenario

    sc = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / f"{scenario}.toml")
    gs = enumerate_grasps(sc.world, GraspOptions(samples_per_edge=20))
    ctx = AdjustContext(sc.world, gs)
    rng = np.random.default_rng(4)
    for trial in range(4):
        members = rng.random(len(gs)) < 0.6
        src = np.flatnonzero(members & (rng.random(len(gs)) < 0.8))
        got = Slide()._candidates(ctx, sc.start, src, members)
        if trial % 2:  # numpy's selection, the same arrays
            monkeypatch.setattr(ag, "_search", None)
            alone = AdjustContext(sc.world, gs)
            for x, y in zip(got, Slide()._candidates(alone, sc.start, src, members)):
                np.testing.assert_array_equal(x, y)
                assert x.dtype == y.dtype
            monkeypatch.undo()
        want = []
        for k in range(2):  # the per-layer computation
            s = src[gs.touching[src, k]]
            if k == 1:
                s = s[~gs.touching[s, 0]]
            a, b = _group_pairs(ctx.slide_groups[k], s)
            travel = np.linalg.norm(gs.gripper[b, :2] - gs.gripper[a, :2], axis=1)
            keep = members[b] & (a != b) & (travel <= ctx.options.slide_max_travel)
            want.append((a[keep], b[keep], np.full(int(keep.sum()), k), travel[keep]))
        a, b, f, travel = (np.concatenate(x) for x in zip(*want))
        by_source = np.argsort(a, kind="stable")
        a, b, f, travel = a[by_source], b[by_source], f[by_source], travel[by_source]
        assert a.size > 100
        for x, y in zip(got, (a, b, np.zeros(a.size, np.int64), f, travel)):
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("scenario", ["task1_zero_mobility_lift", "task2_slot_insertion", "cmgmp_book_stand_up"])
def test_pivot_candidates_from_the_precomputed_pairs_are_the_per_layer_ones(scenario: str) -> None:
    """The candidates of a layer are the pairs of its sources and members among the grasps
    sharing the pivot point: at one width, or a pinch and a one-finger grasp on the kept
    finger at a larger width (both turn widths for those); both senses each; by source,
    each source's in that order (finger 0's first)."""
    from pathlib import Path

    from geometry.poses import wrap_angle
    from ldhp_tamp.primitives.adjust_grasp import AdjustContext, Pivot, _group_pairs, _pivot_centre
    from ldhp_tamp.scenario import load_scenario

    sc = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / f"{scenario}.toml")
    gs = enumerate_grasps(sc.world, GraspOptions(samples_per_edge=20))
    ctx = AdjustContext(sc.world, gs)
    rng = np.random.default_rng(5)
    members = rng.random(len(gs)) < 0.6
    src = np.flatnonzero(members & (rng.random(len(gs)) < 0.8))
    got = Pivot()._candidates(ctx, sc.start, src, members)
    spins = np.abs(got[2]) != ag.ROLL_SENSE  # the rolls: test_a_round_finger_rolls_along_the_edge_it_touches
    got = tuple(x[spins] for x in got)
    want = []  # the per-layer computation
    for k in range(2):
        a, b = _group_pairs(ctx.pivot_groups[k], src[gs.touching[src, k]])
        delta = wrap_angle(gs.gripper[b, 2] - gs.gripper[a, 2]) if a.size else np.zeros(0)
        wa, wb, na, nb = gs.width[a], gs.width[b], gs.n_touching[a], gs.n_touching[b]
        same = np.rint(wa / 1e-4) == np.rint(wb / 1e-4)
        change = ((na == 2) & (nb == 1) & (wb > wa)) | ((na == 1) & (nb == 2) & (wb < wa))
        keep = members[b] & (a != b) & (np.abs(delta) > 1e-6) & (same | change)
        centre = np.nan_to_num(_pivot_centre(ctx, a, np.full(a.size, k)))
        if ctx.is_polyline and a.size:
            c, s = np.cos(delta), np.sin(delta)
            r = ctx.anchors[a, k] - centre
            moved = centre + np.stack([c * r[:, 0] - s * r[:, 1], s * r[:, 0] + c * r[:, 1]], axis=1)
            keep &= np.linalg.norm(np.nan_to_num(moved - ctx.anchors[b, k], nan=np.inf), axis=1) <= 5.0 * ctx.options.match_tol
        a, b, delta, centre, change = a[keep], b[keep], delta[keep], centre[keep], change[keep] & ~same[keep]
        wa, wb = gs.width[a], np.where(change, gs.width[b], gs.width[a])
        phi = gs.gripper[a, 2]
        ex = np.stack([np.cos(phi), np.sin(phi)], axis=1)
        for sense in (1, -1, 2, -2):
            i = np.arange(a.size) if abs(sense) == 1 else np.flatnonzero(change)
            wt = (np.maximum if abs(sense) == 1 else np.minimum)(wa, wb)[i]
            other = ctx.anchors[a[i], k] + ((1.0 if k == 0 else -1.0) * wt)[:, None] * ex[i]
            rad = 0.5 * (np.linalg.norm(ctx.anchors[a[i], k] - centre[i], axis=1) + np.linalg.norm(other - centre[i], axis=1))
            d = delta[i]
            ang = np.where(d * np.sign(sense) > 0, d, d + np.sign(sense) * 2.0 * np.pi)
            want.append((a[i], b[i], np.full(i.size, sense), np.full(i.size, k), np.abs(ang) * rad + 0.5 * np.abs(wb - wa)[i]))
    want = [np.concatenate(x) for x in zip(*want)]
    want = [x[np.argsort(want[0], kind="stable")] for x in want]  # by source, each source's as above
    assert want[0].size > 20
    for x, y in zip(got[:4], want[:4]):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_allclose(got[4], want[4], rtol=1e-12, atol=1e-9)
    if not sc.world.gripper.fixed_width:
        assert (np.abs(want[2]) == 2).any()  # a gripper that opens lets go of a finger turning


@pytest.mark.parametrize("scenario, samples", [("task2_slot_insertion", 20), ("gen_slot_concave9", 100),
                                               ("example_pick", 50)])
def test_polyline_pivot_pairs_found_in_bins_are_those_of_every_pair(scenario: str, samples: int,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """A polyline pivot's partner is its source turned about the pad's contact point: the
    pairs found by binning the grasps on where the anchor sits in the gripper frame
    (_turned_pairs) are the pivots found among every pair of a group, in the same order."""
    from pathlib import Path

    from ldhp_tamp.primitives.adjust_grasp import AdjustContext, Pivot
    from ldhp_tamp.scenario import load_scenario

    sc = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / f"{scenario}.toml")
    gs = enumerate_grasps(sc.world, GraspOptions(samples_per_edge=samples))
    # the anchors moved by up to 0.9 tol each way: partners on both sides of the tolerance
    tol = 5.0 * AdjustContext(sc.world, gs).options.match_tol
    shake = np.random.default_rng(3).uniform(-0.9 * tol, 0.9 * tol, (len(gs), 2, 2))
    found = {}
    for binned in (True, False):
        monkeypatch.setattr(ag, "TURNED_PAIRS_MIN", 0 if binned else 10 ** 18)
        ctx = AdjustContext(sc.world, gs)
        assert ctx.is_polyline
        ctx.__dict__["anchors"] = ctx.anchors + shake  # (a cached property)
        if binned:
            assert ag._turned_pairs(ctx, 0, np.flatnonzero(gs.touching[:, 0]), 5.0 * ctx.options.match_tol) is not None
        found[binned] = [Pivot._pairs(ctx, k) for k in range(2)]
    assert sum(p[0].size for p in found[True]) > 100
    for mine, every in zip(found[True], found[False]):
        for x, y in zip(mine, every):
            np.testing.assert_array_equal(x, y)


def test_a_pinch_lets_go_of_a_finger_turning_about_the_other(ranged: Case):
    """A pinch's width and orientation come from where its second finger meets the
    object, a one-finger grasp's from a few fixed widths and orientations: most pinches
    share neither with any one-finger grasp, so ``open`` (same orientation) cannot let go
    of a finger, and a same-width ``pivot`` finds no partner. ``pivot`` between a pinch and
    a one-finger grasp on the kept finger does it (opening before or after the turn), and
    its reverse closes the finger onto the object; the plan validates, finger k never lets
    go, the other finger leaves the object at once."""
    gs = ranged.grasps
    members = np.isin(np.arange(len(gs)), ranged.gt)
    pinch = ranged.gt[gs.n_touching[ranged.gt] == 2]
    opened = ag.Open().propose(ranged.ctx, T0, pinch, members)
    stuck = np.setdiff1d(pinch, opened.src[opened.dst != ag.NO_CONTACT])
    assert stuck.size > pinch.size // 2  # most pinches: no open to one finger
    pivot = ag.Pivot().propose(ranged.ctx, T0, pinch, members)
    release = np.flatnonzero(gs.n_touching[pivot.dst] == 1)
    assert np.isin(stuck, pivot.src[release]).all()  # ... every one can let go by pivoting
    edges = pivot.take(release)
    assert set(np.unique(edges.sense).tolist()) == {-2, -1, 1, 2}
    k = edges.finger
    assert np.allclose(gs.contact[edges.src, k], gs.contact[edges.dst, k]) and (gs.width[edges.dst] > gs.width[edges.src]).all()
    # the closed-form travel is the motion's
    sub = edges.take(np.linspace(0, len(edges) - 1, 60).astype(int))
    assert sub.travel == pytest.approx(ag.Pivot().motion(ranged.ctx, T0, sub).travel(ranged.ctx), rel=1e-9, abs=1e-9)
    # the reverse of each is proposed: a one-finger grasp turns and closes onto the pinch
    back = ag.Pivot().propose(ranged.ctx, T0, np.unique(edges.dst), members)
    assert set(zip(edges.dst.tolist(), edges.src.tolist(), edges.sense.tolist())) <= set(
        zip(back.src.tolist(), back.dst.tolist(), (-back.sense).tolist()))
    res = ag.Pivot().check(ranged.ctx, T0, edges)
    ok = res.ok & ranged.approachable(edges.src)
    assert ok.any() and set(np.unique(edges.sense[res.ok]).tolist()) == {-2, -1, 1, 2}
    for i in np.flatnonzero(ok)[:: max(1, int(ok.sum()) // 3)]:
        step = ranged.step(ag.Pivot(), edges, int(i))
        ranged.validate([ranged.approach_to(int(edges.src[i])), step])
        f = int(edges.finger[i])
        assert len({w.finger_contacts[f] for w in step.waypoints}) == 1 and None not in {
            w.finger_contacts[f] for w in step.waypoints}
        assert step.waypoints[0].finger_contacts[1 - f] is not None
        assert all(w.finger_contacts[1 - f] is None for w in step.waypoints[1:])
        move, dw = finger_moves(ranged, step)
        assert move <= 4.0 + 1e-9 and dw <= 4.0 + 1e-9
        assert step.parameters["sense"] in (-1, 1) and step.parameters["turn_width"] in (
            pytest.approx(gs.width[edges.src[i]], abs=1e-3), pytest.approx(gs.width[edges.dst[i]], abs=1e-3))


def test_a_slide_meets_the_edges_friction_between_its_ends() -> None:
    """A grasp within the validator's contact tolerance of a vertex has the vertex's
    coefficient (here a frictionless end face's); a slide from it meets the edge's own
    coefficient once it is on the edge. Friction that opposes a slip is not always on
    the safe side, so a smaller coefficient is no conservative stand-in."""
    sc = load_scenario_string(BLOCK.format(name="block", extra="", gripper=RANGED).replace(
        'gripper = 0.6', 'gripper = 0.6\nobject_edges = [{ edge = "l2", gripper = 0.0 }]'), "block")
    gs = enumerate_grasps(sc.world, GraspOptions(samples_per_edge=100))
    ctx = ag.AdjustContext(sc.world, gs)
    top = (gs.feature == 2) & gs.touching  # on l3, the top, from (100, 40) to (0, 40)
    near = top & (np.linalg.norm(np.nan_to_num(gs.contact - [100.0, 40.0], nan=np.inf), axis=-1) <= 1.0)
    assert near.any() and (ctx.mu[near] == 0.0).all() and (ctx.mu[top & ~near] == 0.6).all()
    rows = np.flatnonzero(near.any(axis=1))
    gt = pose_conditioned(sc.world, gs, T0.as_array())
    members = np.isin(np.arange(len(gs)), gt)
    slide = ag.Slide().propose(ctx, T0, rows[np.isin(rows, gt)], members)
    slide = slide.take(np.flatnonzero(near[slide.src, slide.finger]))  # the sliding finger starts near v3
    assert len(slide)
    smp = ag.sample_motion(ctx, ag.Slide().motion(ctx, T0, slide.take(np.arange(min(len(slide), 30)))))
    inner = ~(smp.first | smp.last)
    k = slide.finger[smp.edge]
    assert inner.any() and (smp.mu[np.arange(len(smp)), k][inner] == 0.6).all()
    assert (smp.mu[np.arange(len(smp)), k][smp.first] == 0.0).all()


def test_every_sample_of_a_slide_is_checked_sliding_even_a_short_one(poly: Case):
    gs = poly.grasps
    slide = ag.Slide().propose(poly.ctx, T0, poly.gt, np.isin(np.arange(len(gs)), poly.gt))
    short = np.flatnonzero(slide.travel <= 4.0)
    assert short.size
    motion = ag.Slide().motion(poly.ctx, T0, slide.take(short[:20]))
    smp = ag.sample_motion(poly.ctx, motion)
    k = slide.finger[short[:20]][smp.edge]
    mode = smp.mode[np.arange(len(smp)), k]
    # the sliding finger slides at every sample, the edge's first and last included
    assert (mode == mechanics.ContactMode.SLIDING).all()
    assert smp.first.any() and smp.last.any()
    # the object slides relative to the finger against the finger's travel
    travel = gs.gripper[motion.dst, :2] - gs.gripper[motion.src, :2]
    slide_dir = smp.slide[np.arange(len(smp)), k]
    assert (np.einsum("ij,ij->i", slide_dir, travel[smp.edge]) < 0).all()


def test_a_round_finger_pivoting_about_its_centre_slips(two_point: Case):
    gs = two_point.grasps
    members = np.isin(np.arange(len(gs)), two_point.gt)
    pivot = ag.Pivot().propose(two_point.ctx, T0, two_point.gt, members)
    assert len(pivot)
    take = pivot.take(np.arange(min(20, len(pivot))))
    smp = ag.sample_motion(two_point.ctx, ag.Pivot().motion(two_point.ctx, T0, take))
    k = take.finger[smp.edge]
    mode = smp.mode[np.arange(len(smp)), k]
    assert (mode == mechanics.ContactMode.SLIDING).all()
    # the slip is tangential: perpendicular to the contact normal
    n = smp.normal[np.arange(len(smp)), k]
    s = smp.slide[np.arange(len(smp)), k]
    assert np.allclose(np.einsum("ij,ij->i", n, s), 0.0, atol=1e-9)


def test_a_pad_pivoting_about_its_contact_point_sticks(poly: Case):
    gs = poly.grasps
    pivot = ag.Pivot().propose(poly.ctx, T0, poly.gt, np.isin(np.arange(len(gs)), poly.gt))
    take = pivot.take(np.arange(min(20, len(pivot))))
    smp = ag.sample_motion(poly.ctx, ag.Pivot().motion(poly.ctx, T0, take))
    k = take.finger[smp.edge]
    assert (smp.mode[np.arange(len(smp)), k] == mechanics.ContactMode.STICKING).all()


def test_open_lets_go_of_one_finger_the_reverse_of_close(poly: Case):
    """``open`` from a pinch to finger k alone: finger k keeps its contact, the other
    opens; every such edge is the reverse of a ``close`` edge."""
    gs = poly.grasps
    close = ag.Close().intra_edges(poly.ctx, T0, poly.gt)
    members = np.isin(np.arange(len(gs)), poly.gt)
    two = np.unique(close.dst)
    opened = ag.Open().propose(poly.ctx, T0, two, members)
    one = opened.dst != 0
    assert one.any()
    pairs = set(zip(opened.src[one].tolist(), opened.dst[one].tolist()))
    assert {(int(b), int(a)) for a, b in zip(close.src, close.dst)} <= pairs
    feasible = ag.Open().intra_edges(poly.ctx, T0, np.union1d(two, opened.dst[one]))
    i = int(np.flatnonzero(feasible.dst != 0)[0])
    step = poly.step(ag.Open(), feasible, i)
    k = int(feasible.finger[i])
    kept = {w.finger_contacts[k] for w in step.waypoints}
    assert len(kept) == 1 and None not in kept  # finger k never lets go
    assert step.waypoints[-1].finger_contacts[1 - k] is None
    assert gs.width[feasible.dst[i]] > gs.width[feasible.src[i]]


def test_a_one_finger_grasp_changes_its_width_under_the_finger_that_holds(poly: Case):
    """``close`` narrows and ``open`` widens a one-finger grasp keeping finger k on its
    contact (the free finger moves, off the object): a pivot keeps the width, so this is
    how a fingertip on a corner gets from one tip angle and width to another. The two are
    each other's reverse; the free finger never touches, finger k never lets go."""
    gs = poly.grasps
    members = np.isin(np.arange(len(gs)), poly.gt)
    one = poly.gt[gs.n_touching[poly.gt] == 1]
    narrowed = ag.Close().propose(poly.ctx, T0, one, members)
    both_one = gs.n_touching[narrowed.dst] == 1
    assert both_one.any()
    a, b = narrowed.src[both_one], narrowed.dst[both_one]
    assert (gs.width[b] < gs.width[a]).all()
    k = narrowed.finger[both_one]
    assert np.allclose(gs.contact[a, k], gs.contact[b, k]) and (gs.touching[b, k]).all()
    widened = ag.Open().propose(poly.ctx, T0, np.unique(b), members)
    assert set(zip(b.tolist(), a.tolist())) <= set(zip(widened.src.tolist(), widened.dst.tolist()))
    feasible = ag.Close().intra_edges(poly.ctx, T0, np.union1d(a, b))
    sel = np.flatnonzero(gs.n_touching[feasible.dst] == 1)
    assert sel.size
    step = poly.step(ag.Close(), feasible, int(sel[0]))
    f = int(feasible.finger[sel[0]])
    assert len({w.finger_contacts[f] for w in step.waypoints}) == 1
    assert all(w.finger_contacts[1 - f] is None for w in step.waypoints)


def test_a_round_finger_rolls_along_the_edge_it_touches(two_point: Case):
    """Rolling pivots: the kept finger's contact moves along its edge by radius x turn
    (the target's, within ROLL_TOL: the rest is slid), the motion ends on the target, and
    the finger's contact slips only by that rest, along the edge."""
    ctx, gs = two_point.ctx, two_point.grasps
    r = float(two_point.world.gripper.finger_radius)
    found = 0
    for k in range(2):
        a, b, delta, rad, resid = ag.Pivot._rolls(ctx, k)
        found += a.size
        assert (gs.feature[a, k] == gs.feature[b, k]).all() and (gs.feature[a, k] < gs.n_object).all()
        np.testing.assert_allclose(gs.arclength[b, k] - gs.arclength[a, k] - r * delta, resid, atol=1e-9)
        assert (np.abs(resid) <= ag.ROLL_TOL).all() and (np.abs(delta) > 0).all()
        # the turn's radius is the source's own (about its kept anchor, at its width),
        # computed once per contact: what the travel takes, to the bit
        assert np.array_equal(rad, ag._turn_radius(ctx, a, k, ctx.anchors[a, k], gs.width[a]))
    assert found
    members = np.isin(np.arange(len(gs)), two_point.gt)
    props = ag.Pivot().propose(ctx, T0, two_point.gt, members)
    rolls = props.take(np.flatnonzero(np.abs(props.sense) == ag.ROLL_SENSE))
    assert len(rolls)
    smp = ag.sample_motion(ctx, ag.Pivot().motion(ctx, T0, rolls))
    ends = np.flatnonzero(smp.last)
    np.testing.assert_allclose(smp.pose[ends], gs.gripper[rolls.dst[smp.edge[ends]]], atol=1e-9)
    i = np.flatnonzero(~smp.first & ~smp.last)
    k = rolls.finger[smp.edge[i]]
    # the slip direction (object relative to the finger) is along the edge, against the rest slid
    turn = wrap_angle(gs.gripper[rolls.dst, 2] - gs.gripper[rolls.src, 2])
    resid = (gs.arclength[rolls.dst, rolls.finger] - gs.arclength[rolls.src, rolls.finger] - r * turn)[smp.edge[i]]
    mode = smp.mode[i, k]
    assert (mode[np.abs(resid) < 1e-9] == mechanics.ContactMode.STICKING).all()
    slipping = np.abs(resid) > 1e-6
    assert (mode[slipping] == mechanics.ContactMode.SLIDING).all()
    n = smp.normal[i, k][slipping]
    assert np.allclose(np.einsum("ij,ij->i", n, smp.slide[i, k][slipping]), 0.0, atol=1e-9)


def test_the_rolls_are_every_pair_that_rolls_found_by_brute_force(two_point: Case):
    """``Pivot._rolls`` looks for targets in three narrow windows (v = u - r theta);
    every pair of contacts on one edge at one width whose residual slide is within
    ROLL_TOL must be there, in (source, target) order: compared with all pairs."""
    ctx, gs = two_point.ctx, two_point.grasps
    r = float(two_point.world.gripper.finger_radius)
    for k in range(2):
        a, b, delta, _, resid = ag.Pivot._rolls(ctx, k)
        rows = np.flatnonzero(gs.touching[:, k] & (gs.feature[:, k] >= 0) & (gs.feature[:, k] < gs.n_object))
        i, j = (x.reshape(-1) for x in np.meshgrid(rows, rows, indexing="ij"))
        d = wrap_angle(gs.gripper[j, 2] - gs.gripper[i, 2])
        res = gs.arclength[j, k] - gs.arclength[i, k] - r * d
        same = (gs.feature[i, k] == gs.feature[j, k]) & (ctx._q(gs.width[i]) == ctx._q(gs.width[j]))
        ok = same & (i != j) & (np.abs(d) > ag.ROLL_MIN_TURN) & (np.abs(res) <= ag.ROLL_TOL)
        want = {(int(x), int(y)) for x, y in zip(i[ok], j[ok])}
        got = list(zip(a.tolist(), b.tolist()))
        assert len(got) == len(set(got)) and set(got) == want
        np.testing.assert_allclose(resid, gs.arclength[b, k] - gs.arclength[a, k] - r * delta, atol=1e-9)


def test_a_wedged_block_is_let_go_of_by_rolling_the_finger_under_it(wedged_inverse) -> None:
    """Task 1's inverse: the block on its corner v2, tilted 75 degrees, wedged between the
    zero-mobility gripper's fingers (finger 1 on the top corner, finger 2 under the long
    side). Finger 2 and the table hold it alone (mu >= 0.12 of 0.2), but turning the
    gripper about finger 2's centre makes its surface slip towards v2 and drag the block
    that way, which the table's friction does not hold; turning the other way rolls
    finger 1 into the corner. Rolling finger 2 along the side, it sticks: the rolls are
    the only pivots that hold the block still."""
    feasible, start = wedged_inverse.pivots, wedged_inverse.start
    from_start = feasible.take(np.flatnonzero(feasible.src == start))
    assert len(from_start) and (np.abs(from_start.sense) == ag.ROLL_SENSE).all()
    assert (from_start.finger == 1).all()


def test_hypot_is_numpys_norm_to_the_bit() -> None:
    """Slide travels and pivot turn radii take the root of the summed squares of the
    components: numpy's norm of the stacked pairs, bit for bit (np.hypot rounds otherwise)."""
    from ldhp_tamp.primitives.adjust_grasp import _hypot

    rng = np.random.default_rng(11)
    x = rng.standard_normal(100_000) * 10.0 ** rng.integers(-8, 9, 100_000)
    y = rng.standard_normal(100_000) * 10.0 ** rng.integers(-8, 9, 100_000)
    got = _hypot(x, y)
    assert got.tobytes() == np.linalg.norm(np.stack([x, y], axis=1), axis=1).tobytes()
    assert got.tobytes() == np.linalg.norm(np.stack([y, x], axis=1), axis=1).tobytes()


@pytest.mark.parametrize("case", ["poly", "ranged"])
def test_prepare_builds_ahead_the_tables_the_first_proposals_would(case: str, request) -> None:
    """``prepare`` builds the grasp-set tables (pivots' pairs and rolls, slides' pairs,
    the two primitives' tables of every edge, closings' groups) into the context's
    caches; proposals afterwards are those of a context that built them on the way."""
    c: Case = request.getfixturevalue(case)
    prims = [ag.ApproachContact(), ag.Open(), ag.Close(), ag.Pivot(), ag.Slide(), ag.Flip()]
    ready = ag.AdjustContext(c.world, c.grasps)
    for prim in prims:
        prim.prepare(ready)
    keys = {key for key in ready._cache if isinstance(key, tuple) and isinstance(key[0], str)}
    assert {("pivot-pairs", 0), ("pivot-pairs", 1), ("pivot-rolls", 0), ("pivot-rolls", 1)} <= keys
    # slides' pairs: the compiled module builds their table straight from the groups
    assert ag._search is not None or {("slide-pairs", 0), ("slide-pairs", 1)} <= keys
    assert {"pivot-table", "slide-table"} <= set(ready._cache)
    assert ("close_groups" in vars(ready)) == (not c.world.gripper.fixed_width)
    assert not any(key[0] in ("layer", "holds") for key in keys)  # nothing per pose
    fresh = ag.AdjustContext(c.world, c.grasps)
    members = np.zeros(len(c.grasps), dtype=bool)
    members[c.gt] = True
    src = np.flatnonzero(ready.holds(T0, members))
    for prim in prims:
        a, b = prim.propose(ready, T0, src, members), prim.propose(fresh, T0, src, members)
        for name in ("src", "dst", "sense", "finger", "travel", "switches"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_edge_costs_are_the_formula_to_the_bit() -> None:
    """``IntraEdges.cost`` is ``lambda1 * travel + lambda2 * switches`` (computed in place,
    with one switch count for a proposal's broadcast switches)."""
    rng = np.random.default_rng(12)
    n = 5000
    travel = rng.random(n) * 300.0
    for switches in (np.broadcast_to(np.int64(1), (n,)), rng.integers(0, 3, n)):
        edges = ag.IntraEdges("slide", np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int8),
                              np.zeros(n, np.int8), travel, switches)
        for options in (ag.AdjustGraspOptions(), ag.AdjustGraspOptions(lambda1=0.37, lambda2=3.3)):
            assert edges.cost(options).tobytes() == (options.lambda1 * travel + options.lambda2 * switches).tobytes()
