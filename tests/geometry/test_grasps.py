"""Tests of geometry.grasps: enumeration, pose-conditioned and motion-conditioned sets."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from geometry import collision, contacts, mechanics
from geometry.errors import GeometryError
from geometry.grasps import (
    NO_CONTACT,
    FingerPart,
    GraspOptions,
    GraspSet,
    MotionCheckOptions,
    enumerate_grasps,
    held_at_each,
    motion_conditioned,
    pose_conditioned,
    within_force_limit,
)
from geometry import grasps as grasps_module
from geometry.poses import Pose
from geometry.shapes import make_polygon
from geometry.tolerances import CONTACT_TOL
from geometry.world import (
    Environment,
    Friction,
    PolylineGripper,
    Solid,
    TwoPointGripper,
    World,
    make_object,
)

TABLE = [[500, 0], [-500, 0], [-500, -100], [500, -100]]
BLOCK = [[0, 0], [70, 0], [70, 150], [0, 150]]  # 70 wide, 150 tall: l1 bottom, l2 right, l3 top, l4 left
PICK_BLOCK = [[0, 0], [100, 0], [100, 40], [0, 40]]
L_SHAPE = [[0, 0], [120, 0], [120, 40], [40, 40], [40, 100], [0, 100]]  # concave at (40, 40)
TRIANGLE = [[0, 0], [90, 10], [30, 70]]
FINGER = [[0, 0], [10, 0], [10, 40], [0, 40]]
PALM = [[-90, 40], [90, 40], [90, 60], [-90, 60]]
R = 5.0


def make_world(gripper, obj=BLOCK, solids=(TABLE,), mu_env: float = 0.3, mu_grip: float = 0.6) -> World:
    env = Environment(tuple(Solid(f"s{k}", make_polygon(v)) for k, v in enumerate(solids)))
    return World(make_object(obj), env, gripper, Friction(mu_env, mu_grip))


def zero_mobility() -> TwoPointGripper:
    return TwoPointGripper(R, (90.0, 90.0))


def polyline(palm: bool = True) -> PolylineGripper:
    return PolylineGripper(make_polygon(FINGER), (0.0, 140.0), make_polygon(PALM) if palm else None)


GRIPPERS = {
    "two-point-fixed": zero_mobility,
    "two-point-range": lambda: TwoPointGripper(R, (20.0, 140.0)),
    "polyline-palm": lambda: polyline(True),
    "polyline": lambda: polyline(False),
    "polyline-tapered": lambda: PolylineGripper(make_polygon([[0, 0], [5, 0], [12, 40], [0, 40]]), (0.0, 120.0)),
}
OBJECTS = {"block": BLOCK, "pick-block": PICK_BLOCK, "L": L_SHAPE, "triangle": TRIANGLE}


@lru_cache(maxsize=None)
def grasp_set(gripper: str, obj: str = "block", k: int = 20) -> tuple[World, GraspSet]:
    world = make_world(GRIPPERS[gripper](), OBJECTS[obj])
    return world, enumerate_grasps(world, GraspOptions(samples_per_edge=k))


def gripper_frame(gs: GraspSet, rows: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Object-frame points (B, 2, 2) of grasps ``rows`` in their gripper frames."""
    g = gs.gripper[rows]
    c, s = np.cos(g[:, 2])[:, None], np.sin(g[:, 2])[:, None]
    d = points - g[:, None, :2]
    return np.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], axis=-1)


def boundary_distance(world: World, points: np.ndarray) -> np.ndarray:
    ring = shapely.LinearRing(world.object.polygon.vertices)
    return shapely.distance(ring, shapely.points(points.reshape(-1, 2))).reshape(points.shape[:-1])


# --------------------------------------------------------------------------------------
# Enumeration: structure
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("gripper", sorted(GRIPPERS))
@pytest.mark.parametrize("obj", sorted(OBJECTS))
def test_set_structure(gripper: str, obj: str) -> None:
    world, gs = grasp_set(gripper, obj)
    n = len(gs)
    assert gs.gripper.shape == (n, 3) and gs.contact.shape == (n, 2, 2) and gs.flipped.shape == (n,)
    # Row 0 is the no-contact grasp.
    assert NO_CONTACT == 0 and gs.n_touching[0] == 0 and np.isnan(gs.gripper[0]).all() and gs.flipped[0] == -1
    rest = slice(1, None)
    assert (gs.n_touching[rest] >= 1).all()
    assert (gs.n_touching == 2).sum() > 0 and (gs.n_touching == 1).sum() > 0
    # Columns agree with each other.
    t = gs.touching
    assert np.array_equal(t, ~np.isnan(gs.contact[..., 0]))
    assert np.array_equal(t, gs.feature >= 0) and np.array_equal(t, ~np.isnan(gs.arclength))
    assert np.allclose(np.linalg.norm(gs.normal[t], axis=1), 1.0)
    assert (gs.feature < 2 * gs.n_object).all()
    lo, hi = world.gripper.width_range
    assert ((gs.width[rest] >= lo - 1e-9) & (gs.width[rest] <= hi + 1e-9)).all()
    assert ((gs.gripper[rest, 2] >= -math.pi) & (gs.gripper[rest, 2] < math.pi)).all()
    assert ((gs.arclength[t] >= 0) & (gs.arclength[t] < gs.perimeter + 1e-9)).all()
    # Arrays are read-only values.
    with pytest.raises(ValueError):
        gs.width[1] = 0.0
    # No two rows share pose, width and touching pattern.
    key = np.concatenate([np.round(gs.gripper[rest], 6), np.round(gs.width[rest, None], 6), gs.part[rest]], axis=1)
    assert np.unique(key, axis=0).shape[0] == n - 1


@pytest.mark.parametrize("gripper", sorted(GRIPPERS))
def test_enumeration_is_deterministic_and_grows_with_k(gripper: str) -> None:
    world, gs = grasp_set(gripper)
    again = enumerate_grasps(world, GraspOptions(samples_per_edge=20))
    for name in ("gripper", "width", "contact", "normal", "feature", "part", "arclength", "flipped"):
        assert np.array_equal(getattr(gs, name), getattr(again, name), equal_nan=True), name
    _, coarse = grasp_set(gripper, k=10)
    assert (coarse.n_touching == 2).sum() < (gs.n_touching == 2).sum()
    assert (coarse.n_touching == 1).sum() < (gs.n_touching == 1).sum()


@pytest.mark.parametrize("gripper", sorted(GRIPPERS))
@pytest.mark.parametrize("obj", sorted(OBJECTS))
def test_contacts_lie_on_the_boundary_and_match_their_feature(gripper: str, obj: str) -> None:
    world, gs = grasp_set(gripper, obj)
    t = gs.touching
    assert boundary_distance(world, gs.contact[t]).max() <= 1e-6
    poly = world.object.polygon
    n = gs.n_object
    feat = gs.feature[t]
    pts = gs.contact[t]
    is_v = feat >= n
    assert np.allclose(pts[is_v], poly.vertices[feat[is_v] - n])
    e = feat[~is_v]
    a, d = poly.vertices[e], poly.edge_directions[e]
    off = pts[~is_v] - a
    assert np.abs(off[:, 0] * d[:, 1] - off[:, 1] * d[:, 0]).max() <= 1e-6  # on the edge's line
    along = np.sum(off * d, axis=1)
    assert (along >= -1e-6).all() and (along <= poly.edge_lengths[e] + 1e-6).all()
    # The boundary coordinate locates the contact.
    cum = np.concatenate([[0.0], np.cumsum(poly.edge_lengths)[:-1]])
    assert np.allclose(gs.arclength[t][~is_v], cum[e] + along, atol=1e-6)
    # An edge contact pushes along the edge's inward normal; a vertex contact along a
    # direction inside the vertex's (inward) normal fan.
    assert np.allclose(gs.normal[t][~is_v], -poly.normals[e])
    v = feat[is_v] - n
    m = -gs.normal[t][is_v]
    n_in, n_out = poly.normals[(v - 1) % n], poly.normals[v]
    cross = lambda a, b: a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]  # noqa: E731
    assert (cross(n_in, m) >= -1e-9).all() and (cross(m, n_out) >= -1e-9).all()


@pytest.mark.parametrize("gripper", sorted(GRIPPERS))
@pytest.mark.parametrize("obj", sorted(OBJECTS))
def test_no_finger_overlaps_the_object(gripper: str, obj: str) -> None:
    world, gs = grasp_set(gripper, obj)
    rows = np.arange(1, len(gs))
    # Nothing overlaps the object, even at a tolerance 100x tighter than the planner's.
    assert not collision.gripper_object_overlap(world, np.zeros(3), gs.gripper[rows], gs.width[rows], 1e-3).any()
    # A free finger is clear of the object; a touching one is within 1e-6 of it.
    fs = collision.finger_shapes(world.gripper, gs.gripper[rows], gs.width[rows])
    target = world.object.polygon.shapely
    if fs.centres is not None:
        dist = shapely.distance(target, shapely.points(fs.centres.reshape(-1, 2))).reshape(-1, 2) - R
    else:
        b, _, v, _ = fs.polygons.shape
        dist = shapely.distance(target, shapely.polygons(fs.polygons.reshape(-1, v, 2))).reshape(-1, 2)
    touching = gs.touching[rows]
    assert (dist[~touching] > 0.1).all()
    assert np.abs(dist[touching]).max() <= 1e-6


# --------------------------------------------------------------------------------------
# Configuration I
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("gripper", ["two-point-fixed", "two-point-range"])
@pytest.mark.parametrize("obj", sorted(OBJECTS))
def test_two_point_fingers_sit_on_their_contacts(gripper: str, obj: str) -> None:
    world, gs = grasp_set(gripper, obj)
    rows = np.arange(1, len(gs))
    g = gs.gripper[rows]
    ex = np.stack([np.cos(g[:, 2]), np.sin(g[:, 2])], axis=1)
    centres = g[:, None, :2] + np.array([-0.5, 0.5])[None, :, None] * gs.width[rows, None, None] * ex[:, None, :]
    assert np.allclose(np.linalg.norm(centres[:, 1] - centres[:, 0], axis=1), gs.width[rows])
    t = gs.touching[rows]
    # Finger centre = contact - r * inward normal.
    assert np.abs(centres[t] - (gs.contact[rows][t] - R * gs.normal[rows][t])).max() <= 1e-6
    assert (gs.part[rows][t] == FingerPart.CIRCLE).all()


def test_zero_mobility_has_only_diagonal_pinches_across_the_block() -> None:
    """90 mm between centres, r = 5, a 70 x 150 block: a square-on pinch across the 70 mm
    width needs 80 mm, one between the 70 mm ends 160 mm; diagonal ones across the width
    exist at cos(a) = 80 / 90 to the sides' normal."""
    world, gs = grasp_set("two-point-fixed", k=100)
    two = np.flatnonzero(gs.n_touching == 2)
    f = gs.feature[two]
    ex = np.stack([np.cos(gs.gripper[two, 2]), np.sin(gs.gripper[two, 2])], axis=1)
    # Never both fingers on the 70 mm ends (l1, l3).
    assert not np.isin(f, [0, 2]).all(axis=1).any()
    # No pinch is square-on to the edges it touches.
    n_out = -gs.normal[two]
    assert (np.abs(np.sum(ex[:, None, :] * n_out, axis=2)) < 1 - 1e-3).all()
    # Across the width (l2 and l4): every such pinch is at cos = 80 / 90.
    across = np.sort(f, axis=1).tolist()
    sides = np.array([a == [1, 3] for a in across])
    assert sides.sum() > 0
    assert np.allclose(np.abs(ex[sides, 0]), 80.0 / 90.0)


def test_exact_fit_spacing_gives_square_on_pinches() -> None:
    """Spacing 80 = 70 + 2 r: each sample on a long side has the square-on partner
    (a tangent circle-line solution)."""
    world = make_world(TwoPointGripper(R, (80.0, 80.0)))
    gs = enumerate_grasps(world, GraspOptions(samples_per_edge=10, vertex_fan=0))
    two = np.flatnonzero((gs.n_touching == 2) & (gs.feature == 1).any(axis=1) & (gs.feature == 3).any(axis=1))
    square = two[np.abs(np.cos(gs.gripper[two, 2])) > 1 - 1e-9]
    # 10 samples on each side, each as finger 1, both finger orders: 20 distinct grasps.
    assert square.size == 20
    assert np.allclose(gs.contact[square, 0, 1], gs.contact[square, 1, 1])


def test_range_two_point_closes_square_on() -> None:
    world, gs = grasp_set("two-point-range", "pick-block")
    two = np.flatnonzero(gs.n_touching == 2)
    # Pinch of the 40 mm thickness from above/below: spacing 50, vertical finger line.
    vertical = two[np.abs(np.sin(gs.gripper[two, 2])) > 1 - 1e-9]
    assert vertical.size > 0 and np.allclose(gs.width[vertical], 50.0)
    # End to end: 100 + 2 r = 110 mm, within the 20..140 range.
    horizontal = two[np.abs(np.cos(gs.gripper[two, 2])) > 1 - 1e-9]
    assert horizontal.size > 0 and np.allclose(gs.width[horizontal], 110.0)


# --------------------------------------------------------------------------------------
# Configuration II
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("gripper", ["polyline-palm", "polyline", "polyline-tapered"])
@pytest.mark.parametrize("obj", sorted(OBJECTS))
def test_polyline_contacts_lie_on_the_pads(gripper: str, obj: str) -> None:
    world, gs = grasp_set(gripper, obj)
    rows = np.flatnonzero(gs.n_touching >= 1)
    local = gripper_frame(gs, rows, np.nan_to_num(gs.contact[rows]))
    t = gs.touching[rows]
    side = np.array([-0.5, 0.5])[None, :] * gs.width[rows, None]
    assert np.abs(local[..., 0] - side)[t].max() <= 1e-6
    y = local[..., 1][t]
    assert (y >= -1e-6).all() and (y <= 40 + 1e-6).all()
    part = gs.part[rows][t]
    assert np.isin(part, [FingerPart.PAD, FingerPart.TIP]).all()
    assert (np.abs(y[part == FingerPart.TIP]) <= 1e-6).all()


def test_polyline_pinch_of_the_pick_block() -> None:
    """The example plan's grasp: from above, pads on the 40 mm ends, opening 100."""
    world, gs = grasp_set("polyline", "pick-block")
    two = np.flatnonzero(gs.n_touching == 2)
    above = two[(np.abs(gs.gripper[two, 2]) < 1e-9) & np.isclose(gs.width[two], 100.0)]
    assert above.size > 0
    assert (gs.feature[above] == [3, 1]).all()  # finger 1 on l4 (x = 0), finger 2 on l2 (x = 100)
    assert np.allclose(gs.contact[above, 0, 1], gs.contact[above, 1, 1])  # level, antipodal
    assert np.allclose(gs.normal[above], [[1, 0], [-1, 0]])
    # The opening limit: the 150 mm block cannot be pinched end to end.
    world, gs = grasp_set("polyline", "block")
    two = np.flatnonzero(gs.n_touching == 2)
    assert (gs.width[two] <= 140.0 + 1e-9).all()
    assert not (np.isin(gs.feature[two], [0, 2]).all(axis=1) & (np.abs(np.sin(gs.gripper[two, 2])) > 0.999)).any()


def test_palm_removes_grasps() -> None:
    _, with_palm = grasp_set("polyline-palm")
    _, without = grasp_set("polyline")
    assert len(with_palm) < len(without)


# --------------------------------------------------------------------------------------
# Flip partners
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("gripper", sorted(GRIPPERS))
@pytest.mark.parametrize("obj", sorted(OBJECTS))
def test_flip_partners_swap_fingers_on_the_same_contacts(gripper: str, obj: str) -> None:
    world, gs = grasp_set(gripper, obj)
    g = np.flatnonzero(gs.flipped >= 0)
    f = gs.flipped[g]
    assert (f != g).all()
    if gripper != "polyline-palm":  # a 180 mm palm turned over lands on the object
        assert g.size > 0
    assert np.array_equal(gs.flipped[f], g)  # an involution
    assert np.allclose(gs.contact[f], gs.contact[g][:, ::-1], equal_nan=True, atol=1e-6)
    assert np.array_equal(gs.feature[f], gs.feature[g][:, ::-1])
    assert np.allclose(gs.width[f], gs.width[g])
    dphi = np.mod(gs.gripper[f, 2] - gs.gripper[g, 2], 2 * math.pi)
    assert np.allclose(dphi, math.pi)
    if gripper.startswith("two-point"):
        # The circles are point-symmetric: every grasp has its flip, about the same origin.
        assert g.size == len(gs) - 1
        assert np.allclose(gs.gripper[f, :2], gs.gripper[g, :2])


# --------------------------------------------------------------------------------------
# Pose-conditioned sets
# --------------------------------------------------------------------------------------


def world_fingers(world: World, gs: GraspSet, pose, rows) -> collision.FingerShapes:
    return collision.finger_shapes(world.gripper, gs.world_gripper(pose, rows), gs.width[rows])


def test_pose_conditioned_two_point_on_the_table() -> None:
    world, gs = grasp_set("two-point-fixed")
    kept = pose_conditioned(world, gs, [0.0, 0.0, 0.0])
    assert kept[0] == NO_CONTACT and np.all(np.diff(kept) > 0)
    removed = np.setdiff1d(np.arange(1, len(gs)), kept)
    tol = 0.1
    # Rule 3 against the half-plane y <= 0 (the table is far wider than the gripper):
    # a circle overlaps iff its centre is below r - 2 tol.
    low_kept = world_fingers(world, gs, [0, 0, 0], kept[1:]).centres[..., 1].min(axis=1)
    low_removed = world_fingers(world, gs, [0, 0, 0], removed).centres[..., 1].min(axis=1)
    assert (low_kept > R - 2 * tol - 1e-9).all()
    assert (low_removed <= R - 2 * tol + 1e-9).all()
    # Grasps touching the bottom edge have a finger under the table: all removed.
    bottom = np.flatnonzero((gs.feature == 0).any(axis=1))
    assert bottom.size > 0 and not np.isin(bottom, kept).any()
    # In the air nothing collides.
    assert len(pose_conditioned(world, gs, [0.0, 300.0, 0.3])) == len(gs)


def test_pose_conditioned_follows_the_object_pose() -> None:
    """Grasps on the top edge are kept on the table; turned upside down, they are not."""
    world, gs = grasp_set("two-point-fixed")
    top = np.flatnonzero((gs.feature == 2).any(axis=1) & (gs.n_touching == 1))
    upright = pose_conditioned(world, gs, [0.0, 0.0, 0.0])
    flipped = pose_conditioned(world, gs, [70.0, 150.0, math.pi])  # same footprint, upside down
    assert np.isin(top, upright).mean() > 0.5
    assert np.isin(top, flipped).mean() < np.isin(top, upright).mean()


@pytest.mark.parametrize("gripper", ["polyline-palm", "polyline"])
def test_pose_conditioned_polyline_on_the_table(gripper: str) -> None:
    world, gs = grasp_set(gripper)
    kept = pose_conditioned(world, gs, [0.0, 0.0, 0.0])
    removed = np.setdiff1d(np.arange(1, len(gs)), kept)
    assert removed.size > 0
    fs = world_fingers(world, gs, [0, 0, 0], kept[1:])
    assert fs.polygons[..., 1].min() >= -0.5  # nothing sinks into the table
    fr = world_fingers(world, gs, [0, 0, 0], removed)
    low = fr.polygons[..., 1].min(axis=(1, 2))
    if fr.palm is not None:
        low = np.minimum(low, fr.palm[..., 1].min(axis=1))
    assert (low < 0.0).all()


SLOT = [[300, 0], [0, 0], [0, 75], [-200, 75], [-200, -50], [500, -50], [500, 75], [300, 75]]


@pytest.mark.parametrize("gripper", sorted(GRIPPERS))
@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (80.0, 0.0, 1.2), (-60.0, 75.0, -0.4),
                                  (150.0, 40.0, math.pi / 2)])
def test_pose_conditioned_equals_the_plain_overlap_test(gripper: str, pose) -> None:
    """The bounding-disk pre-filter changes nothing (slot environment: the gripper origin
    can be inside a solid, near an edge, or far from all)."""
    world = make_world(GRIPPERS[gripper](), solids=(SLOT,))
    gs = enumerate_grasps(world, GraspOptions(samples_per_edge=10))
    kept = pose_conditioned(world, gs, pose)
    hit = collision.gripper_env_overlap(world, gs.world_gripper(pose)[1:], gs.width[1:])
    assert np.array_equal(kept, np.concatenate([[0], 1 + np.flatnonzero(~hit)]))
    assert 1 < len(kept) < len(gs)


# --------------------------------------------------------------------------------------
# Motion-conditioned sets
# --------------------------------------------------------------------------------------

TASK2_FINGER = [[0, 0], [12, 0], [12, 45], [0, 45]]


def straight(start, end, step: float = 4.0) -> np.ndarray:
    start, end = np.asarray(start, float), np.asarray(end, float)
    n = max(1, int(math.ceil(np.linalg.norm(end[:2] - start[:2]) / step)))
    return start + np.linspace(0.0, 1.0, n + 1)[:, None] * (end - start)


def tip_right(deg: float, step_deg: float = 0.5) -> np.ndarray:
    """The 70 x 150 block tipping clockwise about its bottom-right corner (70, 0)."""
    phi = np.radians(np.arange(0.0, deg + 1e-9, step_deg))
    return np.stack([70.0 - 70.0 * np.cos(phi), 70.0 * np.sin(phi), -phi], axis=1)


def candidates(world: World, gs: GraspSet, path: np.ndarray) -> np.ndarray:
    return np.intersect1d(pose_conditioned(world, gs, path[0]), pose_conditioned(world, gs, path[-1]))


def top_and_left_fingers(world: World, gs: GraspSet, path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of the 70 x 150 block's candidate grasps along ``path``: the one-finger ones, those
    on its top face away from its corners, and those high on its left side."""
    cand = candidates(world, gs, path)
    one = cand[gs.n_touching[cand] == 1]
    f = np.where(gs.touching[one, 0], 0, 1)
    y = gs.contact[one, f, 1]
    x = gs.contact[one, f, 0]
    top = one[(np.abs(y - 150.0) < 1e-6) & (x > 5.0) & (x < 65.0)]
    left = one[(np.abs(x) < 1e-6) & (y > 100.0)]
    assert top.size and left.size
    return one, top, left


@lru_cache(maxsize=None)
def lift_world() -> tuple[World, GraspSet]:
    world = make_world(PolylineGripper(make_polygon(TASK2_FINGER), (0.0, 140.0)), mu_env=0.3, mu_grip=0.6)
    return world, enumerate_grasps(world, GraspOptions(samples_per_edge=20))


def test_lift_in_the_air_needs_a_pinch() -> None:
    world, gs = lift_world()
    path = straight([0, 100, 0], [0, 140, 0])
    cand = candidates(world, gs, path)
    res = motion_conditioned(world, gs, path, cand)
    assert len(res) > 0 and res.checks >= len(res) * len(path)
    assert (gs.n_touching[res.indices] == 2).all()
    # The pinches across the 70 mm width (pads on l2 and l4) are admissible.
    across = cand[(np.sort(gs.feature[cand], axis=1) == [1, 3]).all(axis=1)]
    assert across.size > 0 and np.isin(across, res.indices).all()
    # A single finger on top pushes down: never admissible, whatever the rest.
    on_top = cand[(gs.n_touching[cand] == 1) & (gs.feature[cand] == 2).any(axis=1)]
    assert on_top.size > 0
    assert motion_conditioned(world, gs, path, on_top).indices.size == 0
    # Without friction at the fingers the vertical pads cannot carry the weight.
    slippery = make_world(world.gripper, mu_env=0.3, mu_grip=0.0)
    assert motion_conditioned(slippery, gs, path, across).indices.size == 0


def test_quality_matches_the_mechanics_definition() -> None:
    world, gs = lift_world()
    path = straight([0, 0, 0], [0, 20, 0])  # lifting off the table: l1-e1 separates
    # alpha over every sample at full bisection precision: the mechanics' definition
    full = MotionCheckOptions(alpha_samples=len(path), angle_iterations=16)
    res = motion_conditioned(world, gs, path, candidates(world, gs, path), full)
    assert len(res) > 3
    assert np.allclose(res.quality, (~res.force_closure) + res.alpha)
    # the default averages fewer samples at a coarser precision: the same grasps, close values
    fast = motion_conditioned(world, gs, path, candidates(world, gs, path))
    assert np.array_equal(fast.indices, res.indices)
    assert np.array_equal(fast.force_closure, res.force_closure)
    assert np.allclose(fast.alpha, res.alpha, atol=0.05)
    for k in np.linspace(0, len(res) - 1, 4).astype(int):
        g = int(res.indices[k])
        fingers, motion, com = one_grasp_contacts(world, gs, g, path)
        q = mechanics.grasp_quality(fingers, motion, com, world.object.length_scale)
        assert q.admissible
        assert q.force_closure == res.force_closure[k]
        assert math.isclose(q.value, res.quality[k], rel_tol=1e-9, abs_tol=1e-12)
    # Weights.
    w = motion_conditioned(world, gs, path, res.indices, MotionCheckOptions(w1=10.0, w2=0.0, alpha_samples=len(path)))
    assert np.array_equal(w.indices, res.indices)
    assert np.allclose(w.quality, 10.0 * ~res.force_closure)


def one_grasp_contacts(world: World, gs: GraspSet, g: int, path: np.ndarray):
    """Independent construction of one grasp's contacts along a path, for grasp_quality."""
    env_pts, env_n, env_mu, env_modes, env_slide = [], [], [], [], []
    for j, pose in enumerate(path):
        cp = contacts.contact_points(world, Pose.from_array(pose))
        a, b = (j, j + 1) if j + 1 < len(path) else (j - 1, j)
        d, r = mechanics.pose_displacements(cp.points, path[a], path[b])
        m = mechanics.classify_contacts(cp.normals, d, r[:, None], world.object.length_scale)
        env_pts.append(cp.points), env_n.append(cp.normals), env_mu.append(cp.mu)
        env_modes.append(m.codes[0]), env_slide.append(m.slide_dirs[0])
    c = max(len(p) for p in env_pts)

    def pad(xs, tail):
        out = np.zeros((len(xs), c) + tail)
        for j, x in enumerate(xs):
            out[j, :len(x)] = x
        return out

    fp = np.stack([Pose.from_array(p).apply(np.nan_to_num(gs.contact[g])) for p in path])
    fn = np.stack([Pose.from_array(p).apply_vector(np.nan_to_num(gs.normal[g])) for p in path])
    mu = np.nan_to_num(gs.contact_mu(world)[g])
    fm = np.where(gs.touching[g], mechanics.ContactMode.STICKING, mechanics.ContactMode.ABSENT)
    fingers = mechanics.Contacts.make(fp, fn, mu, fm)
    motion = mechanics.Contacts.make(
        np.concatenate([pad(env_pts, (2,)), fp], axis=1), np.concatenate([pad(env_n, (2,)), fn], axis=1),
        np.concatenate([pad(env_mu, ()), np.broadcast_to(mu, (len(path), 2))], axis=1),
        np.concatenate([pad(env_modes, ()), np.broadcast_to(fm, (len(path), 2))], axis=1).astype(np.int8),
        np.concatenate([pad(env_slide, (2,)), np.zeros((len(path), 2, 2))], axis=1))
    com = np.stack([Pose.from_array(p).apply(world.object.com) for p in path])
    return fingers, motion, com


@pytest.mark.parametrize("mu_env", [0.2, 0.3])
def test_tip_by_one_finger_is_decided_by_the_mechanics(mu_env: float) -> None:
    """Tip the standing 70 x 150 block (COM (35, 75)) clockwise about its corner (70, 0),
    one finger pushing its left side (normal +x) at height h.

    At the start the pivot is the only support (the bottom separates). With finger force
    (f, k f), |k| <= mu_g, moments about the pivot give f (h + 70 k) = 35 m g and the pivot
    must not slip: f <= mu_e (m g - k f). Eliminating f: 35 <= mu_e (h + 35 k), easiest at
    k = mu_g. So h* = 35 / mu_e - 35 mu_g: 95.7 mm for mu_e = 0.3, mu_g = 0.6; for
    mu_e = 0.2, h* = 154 mm, above the block. A 2-degree tip only gets easier.
    """
    world = make_world(zero_mobility(), mu_env=mu_env, mu_grip=0.6)
    gs = enumerate_grasps(world, GraspOptions(samples_per_edge=20))
    path = tip_right(2.0)
    cand = candidates(world, gs, path)
    left = cand[(gs.n_touching[cand] == 1) & (gs.feature[cand] == 3).any(axis=1)]
    h = np.nanmax(gs.contact[left, :, 1], axis=1)
    h_star = 35.0 / mu_env - 35.0 * 0.6
    assert left.size > 0 and h.max() > 140.0
    res = motion_conditioned(world, gs, path, left)
    admitted = np.isin(left, res.indices)
    if mu_env == 0.2:
        assert not admitted.any()
    else:
        assert admitted.any()
        assert np.array_equal(admitted, h > h_star)
        assert (~admitted).any()


def test_collision_anywhere_along_the_path_excludes_a_grasp() -> None:
    """A beam above the middle of a carry: grasps free at both ends that sweep through it
    are not admissible; every admitted grasp is free at every sample."""
    beam = [[95, 260], [105, 260], [105, 400], [95, 400]]
    world = make_world(PolylineGripper(make_polygon(TASK2_FINGER), (0.0, 140.0)), solids=(TABLE, beam))
    gs = enumerate_grasps(world, GraspOptions(samples_per_edge=20))
    path = straight([0, 100, 0], [200, 100, 0])
    cand = candidates(world, gs, path)[1:]  # without the no-contact grasp
    res = motion_conditioned(world, gs, path, cand)
    hits = np.stack([collision.gripper_env_overlap(world, gs.world_gripper(p, cand), gs.width[cand]) for p in path])
    swept = cand[hits.any(axis=0)]
    assert swept.size > 0 and not np.isin(swept, res.indices).any()
    assert len(res) > 0
    assert np.array_equal(res.indices, motion_conditioned(world, gs, path, cand[~hits.any(axis=0)]).indices)


def test_max_checks_truncates_and_counts() -> None:
    world, gs = lift_world()
    path = straight([0, 100, 0], [0, 140, 0])
    cand = candidates(world, gs, path)
    full = motion_conditioned(world, gs, path, cand, MotionCheckOptions(chunk=4))
    assert not full.truncated and full.checks > 0
    part = motion_conditioned(world, gs, path, cand, MotionCheckOptions(chunk=4), max_checks=full.checks // 3)
    assert part.truncated and part.checks <= full.checks // 3
    assert np.isin(part.indices, full.indices).all() and len(part) < len(full)
    same = motion_conditioned(world, gs, path, cand, MotionCheckOptions(chunk=4), max_checks=full.checks)
    assert not same.truncated and np.array_equal(same.indices, full.indices)


def test_motion_conditioned_edge_cases() -> None:
    world, gs = lift_world()
    path = straight([0, 100, 0], [0, 140, 0])
    # Row 0 and an empty candidate list give an empty set without any check.
    for cand in ([], [NO_CONTACT]):
        res = motion_conditioned(world, gs, path, cand)
        assert len(res) == 0 and res.checks == 0 and not res.truncated
    with pytest.raises(GeometryError):
        motion_conditioned(world, gs, path, [-1])
    # A single pose is a motionless segment: a pinch in the air holds.
    one = motion_conditioned(world, gs, path[:1], np.arange(len(gs)))
    assert len(one) > 0 and one.checks > 0


@pytest.mark.parametrize("gripper", ["lift", "zero-mobility"])
def test_held_at_each_is_one_pose_at_a_time(gripper: str) -> None:
    """``held_at_each`` gives, pose by pose, what ``motion_conditioned`` of that pose alone
    gives: in the air (decided together: the same sets, to the grasp), resting on the table
    or standing on a corner (each pose its own call), inside the table (nothing holds it
    clear, but touching nothing: decided with the others), for all the grasps and for a
    subset, in the poses' order."""
    if gripper == "lift":
        world, gs = lift_world()
    else:
        world = make_world(zero_mobility())
        gs = enumerate_grasps(world, GraspOptions(samples_per_edge=12))
    rng = np.random.default_rng(7)
    air = np.column_stack([rng.uniform(-50, 50, 9), np.full(9, 900.0), rng.uniform(-np.pi, np.pi, 9)])
    rest = np.array([[0.0, 0.0, 0.0], [70.0, 0.0, math.pi / 2], tip_right(30.0)[-1]])
    sunk = np.array([[0.0, -40.0, 0.3]])
    poses = np.concatenate([air[:4], rest[:1], air[4:], rest[1:], sunk, air[:1]])
    every = np.arange(len(gs))
    some = np.flatnonzero(rng.random(len(gs)) < 0.4)
    for cand in (every, some, np.concatenate([some, [NO_CONTACT], some[:5]])):
        got = held_at_each(world, gs, poses, cand)
        want = [motion_conditioned(world, gs, poses[j:j + 1], cand, rate=False).indices for j in range(len(poses))]
        assert len(got) == len(want)
        for g, w in zip(got, want):
            assert g.dtype == np.int64 and np.array_equal(g, w) and not g.flags.writeable
    touching = contacts.contact_point_arrays(world, poses)[3].any(axis=1)
    assert touching[[4, 10, 11]].all() and not touching[[0, 1, 2, 3, 12]].any()  # both branches taken
    assert max(len(g) for g in held_at_each(world, gs, poses[:4], every)) > 0
    assert held_at_each(world, gs, poses[:0], every) == []
    assert all(len(g) == 0 for g in held_at_each(world, gs, poses, [NO_CONTACT]))
    with pytest.raises(GeometryError):
        held_at_each(world, gs, poses, [len(gs)])


# --------------------------------------------------------------------------------------
# Random objects
# --------------------------------------------------------------------------------------


@st.composite
def star_polygons(draw) -> list[list[float]]:
    """Simple (star-shaped, possibly concave) polygons of 3..7 vertices, 20..80 mm."""
    n = draw(st.integers(3, 7))
    gaps = draw(st.lists(st.floats(0.3, 1.0), min_size=n, max_size=n))
    radii = draw(st.lists(st.floats(20.0, 80.0), min_size=n, max_size=n))
    ang = np.cumsum(np.asarray(gaps) / np.sum(gaps) * 2 * math.pi)
    return [[float(r * math.cos(a)), float(r * math.sin(a))] for r, a in zip(radii, ang)]


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(obj=star_polygons(), gripper=st.sampled_from(["two-point-fixed", "two-point-range", "polyline-tapered"]))
def test_invariants_on_random_objects(obj: list[list[float]], gripper: str) -> None:
    world = make_world(GRIPPERS[gripper](), obj)
    gs = enumerate_grasps(world, GraspOptions(samples_per_edge=8))
    rows = np.arange(1, len(gs))
    t = gs.touching
    assert (gs.n_touching[rows] >= 1).all()
    assert boundary_distance(world, gs.contact[t]).max(initial=0.0) <= 1e-6
    assert not collision.gripper_object_overlap(world, np.zeros(3), gs.gripper[rows], gs.width[rows], 1e-3).any()
    f = gs.flipped
    ok = np.flatnonzero(f >= 0)
    assert np.array_equal(f[f[ok]], ok)
    assert np.allclose(gs.contact[f[ok]], gs.contact[ok][:, ::-1], equal_nan=True, atol=1e-6)


def test_bad_options_and_fingers_are_refused() -> None:
    for bad in ({"samples_per_edge": 0}, {"pad_heights": (1.5,)}, {"tip_angles_deg": (90.0,)}, {"orientations": -1}):
        with pytest.raises(GeometryError):
            GraspOptions(**bad)
    with pytest.raises(GeometryError):
        MotionCheckOptions(chunk=0)
    # A finger whose body is not at x >= 0 has no pad on x = 0.
    hook = PolylineGripper(make_polygon([[-2, 0], [10, 0], [10, 40], [0, 40]]), (0.0, 140.0))
    with pytest.raises(GeometryError, match="pad"):
        enumerate_grasps(make_world(hook), GraspOptions(samples_per_edge=4))


def test_a_segment_that_ends_by_making_contact_can_have_grasps() -> None:
    """Setting a pinched block down on the table: the contact made at the last sample is
    where the object stops, not a penetration (regression: G_m of placing was empty)."""
    from geometry.grasps import GraspOptions, enumerate_grasps, motion_conditioned, pose_conditioned
    from geometry.kinematics import translate
    from geometry.poses import Pose
    from geometry.shapes import make_polygon
    from geometry.world import Environment, Friction, PolylineGripper, Solid, World, make_object

    table = Solid("table", make_polygon([[300, 0], [-300, 0], [-300, -50], [300, -50]]))
    world = World(make_object([[0, 0], [100, 0], [100, 40], [0, 40]]), Environment((table,)),
                  PolylineGripper(make_polygon([[0, 0], [10, 0], [10, 45], [0, 45]]), (0.0, 140.0)),
                  Friction(0.3, 0.6))
    grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=10))
    down = translate(Pose(0.0, 20.0, 0.0), (0.0, -1.0)).poses(np.linspace(0.0, 20.0, 6))
    cand = np.intersect1d(pose_conditioned(world, grasps, down[0]), pose_conditioned(world, grasps, down[-1]))
    gm = motion_conditioned(world, grasps, down, cand)
    assert gm.indices.size > 0
    assert np.all(grasps.n_touching[gm.indices] == 2)  # only pinches carry it down


def test_rating_a_motion_set_later_gives_the_same_quality() -> None:
    """motion_conditioned(rate=False) then rate_motion_grasps == motion_conditioned()."""
    from geometry.grasps import rate_motion_grasps

    world, gs = lift_world()
    path = straight([0, 0, 0], [0, 20, 0])  # lifting off the table
    cand = candidates(world, gs, path)
    full = motion_conditioned(world, gs, path, cand)
    bare = motion_conditioned(world, gs, path, cand, rate=False)
    assert len(full) and full.rated and not bare.rated
    assert np.array_equal(bare.indices, full.indices) and np.isnan(bare.quality).all()
    rated = rate_motion_grasps(world, gs, path, bare)
    assert rated.rated and np.array_equal(rated.indices, full.indices)
    np.testing.assert_array_equal(rated.quality, full.quality)
    np.testing.assert_array_equal(rated.force_closure, full.force_closure)
    assert rate_motion_grasps(world, gs, path, rated) is rated


def test_samples_known_collision_free_are_not_tested_again_and_change_nothing() -> None:
    world, gs = lift_world()
    path = straight([0, 0, 0], [0, 20, 0])
    cand = candidates(world, gs, path)  # G_T at both ends
    plain = motion_conditioned(world, gs, path, cand)
    ends = motion_conditioned(world, gs, path, cand, free_at=(0, len(path) - 1))
    assert len(plain) and np.array_equal(ends.indices, plain.indices)
    np.testing.assert_array_equal(ends.quality, plain.quality)
    # with every sample declared free, only the quasi-static test decides: a superset
    loose = motion_conditioned(world, gs, path, cand, free_at=np.arange(len(path)))
    assert set(plain.indices) <= set(loose.indices)


# --------------------------------------------------------------------------- per-edge offsets


def test_edge_offsets_move_the_edge_samples_and_default_to_the_middle():
    world = make_world(TwoPointGripper(R, (0.0, 140.0)))
    k = 4
    mid = enumerate_grasps(world, GraspOptions(samples_per_edge=k))
    same = enumerate_grasps(world, GraspOptions(samples_per_edge=k, edge_offsets=(0.5,) * 4))
    assert np.array_equal(mid.arclength, same.arclength, equal_nan=True)
    off = enumerate_grasps(world, GraspOptions(samples_per_edge=k, edge_offsets=(0.1, 0.5, 0.9, 0.25)))
    # contacts on edge l1 (from v1, length 70) at t = (i + 0.1) / 4 of it, none at the middles
    def at(gs: GraspSet, edge: int, s: float) -> bool:
        return bool(np.any(np.isclose(gs.arclength[gs.feature == edge], s, atol=1e-6)))

    for i in range(k):
        assert at(off, 0, 70.0 * (i + 0.1) / k) and not at(off, 0, 70.0 * (i + 0.5) / k)
        assert at(mid, 0, 70.0 * (i + 0.5) / k) and not at(mid, 0, 70.0 * (i + 0.1) / k)
        assert at(off, 1, 70.0 + 150.0 * (i + 0.5) / k)


@pytest.mark.parametrize("offsets", [(0.5, 0.5, 0.5), (0.5, 0.5, 1.0, 0.5), (-0.1, 0.5, 0.5, 0.5)])
def test_edge_offsets_are_checked(offsets):
    world = make_world(TwoPointGripper(R, (0.0, 140.0)))
    with pytest.raises(GeometryError, match="edge_offsets"):
        enumerate_grasps(world, GraspOptions(samples_per_edge=4, edge_offsets=offsets))


# -- environment contact modes along a path -------------------------------------------

SLOT = [[300, 0], [0, 0], [0, 75], [-200, 75], [-200, -50], [500, -50], [500, 75], [300, 75]]


def _ladder_over_the_lip(lean_deg: float, turn_deg: float, steps: int = 6) -> np.ndarray:
    """Poses of the 70 x 150 block leaning left in the 75 mm deep slot, its corner v1 on
    the floor and its left face l4 on the lip corner (0, 75), turning from ``lean_deg``
    by ``turn_deg``: v1 at x = 75 tan(phi), the pose's origin being v1."""
    phi = np.radians(np.linspace(lean_deg, lean_deg + turn_deg, steps))
    return np.stack([75.0 * np.tan(phi), np.zeros_like(phi), phi], axis=1)


def test_a_face_sliding_over_a_lip_corner_while_turning_slides() -> None:
    """The lip corner stays on the turning face l4 (kept by construction), so the
    contact slides at every sample: measured in the face's own frame its normal drift is
    zero. In the world frame the face turns under the corner, a drift of step x turn
    (0.03 mm on a 2 mm step turning a degree) that the scale-aware threshold would call
    separating, leaving a one-finger hold nothing to lean on."""
    world = make_world(polyline(palm=False), solids=(SLOT,), mu_env=0.03)
    path = _ladder_over_the_lip(40.0, 5.0)
    env = grasps_module._env_contacts(world, path, CONTACT_TOL)
    lip = np.linalg.norm(env.points - np.array([0.0, 75.0]), axis=2) < 1e-6
    assert lip.sum(axis=1).tolist() == [1] * len(path)
    assert (env.modes[lip] == mechanics.ContactMode.SLIDING).all()
    floor = np.abs(env.points[..., 1]) < 1e-6
    assert (env.modes[floor] == mechanics.ContactMode.SLIDING).all()  # v1 slides right, the last sample too


def test_a_corner_leaving_the_lip_for_the_wall_separates_there() -> None:
    """At the instant the block's top corner v4 sits on the lip corner, the contact
    reported there has one face's normal; the corner going down the wall moves into that
    normal's half-plane without overlapping anything, which is a separation, not a
    penetration (that would make the motion infeasible for every grasp)."""
    world = make_world(polyline(palm=False), solids=(SLOT,), mu_env=0.03)
    phi0 = math.acos(0.5)  # v4 = v1 + 150 (-sin, cos) on (0, 75)
    phi = phi0 + np.radians([0.0, 1.0, 2.0])
    path = np.stack([150.0 * np.sin(phi), np.zeros_like(phi), phi], axis=1)  # v1 on the floor, v4 down the wall
    assert not collision.object_env_overlap(world, path[1:]).any()
    env = grasps_module._env_contacts(world, path, CONTACT_TOL)
    assert not (env.modes[0] == mechanics.ContactMode.PENETRATING).any()
    corner = np.linalg.norm(env.points[0] - np.array([0.0, 75.0]), axis=1) < CONTACT_TOL
    assert corner.any() and (env.modes[0][corner] != mechanics.ContactMode.STICKING).all()


def test_a_finger_that_would_rise_off_a_resting_block_starts_its_tip_only_pressed() -> None:
    """The standing block rests on the table alone. Tipped clockwise about its
    bottom-right corner, a finger on its left side presses into it (the motion is forced),
    while a finger on its top face left of the corner rises with the planned motion and
    would leave the block where it is: such a grasp cannot start the tip by position
    control alone, however well forces balance along it. Pressed down first (the
    executor's guarded move), its friction drags the top: near the corner that tips the
    block (mu_e = 0.3: the drag needs (35 W + f (70 - x)) / 150 < mu_e (W + f)), far from
    it the block slides. G_m admits the first with their press and refuses the others (for
    the path as a whole: a part of it may admit them)."""
    world, gs = lift_world()
    path = tip_right(3.0)
    one, top, left = top_and_left_fingers(world, gs, path)
    idle = grasps_module._leaves_it_still(world, gs, path, np.concatenate([top, left]))
    assert idle[:top.size].mean() > 0.9  # (a free finger swinging into the block presses too)
    assert not idle[top.size:].any()
    res = motion_conditioned(world, gs, path, np.concatenate([top, left]), rate=False)
    still = top[idle[:top.size]]
    pressed = np.array([res.press_of(int(g)) is not None for g in still])
    admitted = np.isin(still, res.indices)
    assert (pressed == admitted).all()  # none of them without a press
    assert admitted.any() and not admitted.all()
    xs = gs.contact[still, np.where(gs.touching[still, 0], 0, 1), 0]
    assert xs[admitted].min() > xs[~admitted].min()  # the far ones slide instead
    assert np.isin(still[~admitted], res.rejected).all()
    assert (res.rejected_at[np.isin(res.rejected, still[~admitted])] == -1).any()  # no press serves the path
    assert np.isin(left, res.indices).any()
    assert all(res.press_of(int(g)) is None for g in left)
    lifted = straight([0, 10, 0], [0, 30, 0])  # in the air the test does not apply: nothing rests
    assert grasps_module._leaves_it_still(world, gs, lifted, one).sum() == 0


SQUARE = [[0, 0], [80, 0], [80, 80], [0, 80]]  # the quarter turn's 80 mm block: l1 bottom, l2 right, l3 top, l4 left


def _tip_about_v1(deg: float) -> np.ndarray:
    phi = np.radians(np.arange(0.0, deg + 1e-9, 0.5))
    return np.stack([np.zeros_like(phi), np.zeros_like(phi), phi], axis=1)  # the square about v1 = (0, 0)


def test_rigid_fingers_must_push_into_a_resting_block_to_tip_it_a_closing_gripper_squeezes() -> None:
    """The square block rests on the table alone; tipped counter-clockwise about its
    bottom-left corner. Two fingers of a fixed-width gripper hugging its top-left corner
    (one on its left side, one on its top) move with the planned motion away from the
    side and along the top: rigid, they squeeze nothing, the object may as well stay (the
    judge's forward problem finds that motion), so G_m refuses them as it refuses a lone
    finger that rises off. The same two fingers of a gripper that closes under force grip
    the corner (the executor closes until its force setting): they squeeze, the test does
    not apply, and G_m keeps those that balance the motion."""
    fixed = make_world(TwoPointGripper(R, (90.0, 90.0)), SQUARE, mu_grip=0.8)
    closing = make_world(TwoPointGripper(R, (10.0, 150.0)), SQUARE, mu_grip=0.8)
    path = _tip_about_v1(5.0)
    for world, squeezes in ((fixed, False), (closing, True)):
        gs = enumerate_grasps(world, GraspOptions(samples_per_edge=20))
        cand = candidates(world, gs, path)
        two = cand[gs.n_touching[cand] == 2]
        hugs = two[(np.sort(gs.feature[two], axis=1) == [2, 3]).all(axis=1)]  # l3 (top) and l4 (left)
        assert hugs.size
        assert (grasps_module.squeezing(world, gs, hugs) == squeezes).all()
        idle = grasps_module._leaves_it_still(world, gs, path, hugs)
        assert idle.all() != squeezes and idle.any() != squeezes
        res = motion_conditioned(world, gs, path, hugs, rate=False)
        if squeezes:
            assert np.isin(hugs, res.indices).any()
        else:
            assert not np.isin(hugs, res.indices).any() and np.isin(hugs, res.rejected).all()
        assert not grasps_module.squeezing(world, gs, cand[gs.n_touching[cand] == 1]).any()


def test_a_pinch_closes_onto_contact_samples_so_either_finger_can_stay() -> None:
    """With a spacing range finger 2 closes along the closing angles and lands where the
    ray meets the object; its contact is moved to the nearest sample of that edge (the
    closing direction turning by under half a sample spacing over the span), so both
    contacts of a pinch are anchors of the one-finger grasps enumerated there: the gripper
    can keep finger 2 and let finger 1 go (a handover; off the grid no other grasp shares
    finger 2's contact). Offsets drawn per edge, as a solve draws them: the two sides'
    samples are not mirror images."""
    world = make_world(TwoPointGripper(R, (10.0, 150.0)), SQUARE, mu_grip=0.8)
    k, offsets = 20, (0.3, 0.55, 0.8, 0.15)
    gs = enumerate_grasps(world, GraspOptions(samples_per_edge=k, edge_offsets=offsets))
    poly = world.object.polygon
    two = np.flatnonzero((gs.n_touching == 2) & (gs.feature < len(poly)).all(axis=1))
    assert two.size > 100
    for f in (0, 1):
        edge = gs.feature[two, f]
        d = poly.edge_vectors[edge]
        t = np.sum((gs.contact[two, f] - poly.vertices[edge]) * d, axis=1) / np.sum(d * d, axis=1)
        cell = t * k - np.asarray(offsets)[edge]
        assert np.allclose(cell, np.round(cell), atol=1e-6)  # both contacts on the sample grid
    one = np.flatnonzero(gs.n_touching == 1)
    anchors = {tuple(np.round(gs.contact[g, 0 if gs.touching[g, 0] else 1], 6)) for g in one}
    assert all(tuple(np.round(gs.contact[g, 1], 6)) in anchors for g in two)
    # the fingers sit on their contacts: each centre the finger radius from it, along the gripper's axis
    axis = np.stack([np.cos(gs.gripper[two, 2]), np.sin(gs.gripper[two, 2])], axis=1)
    for f, sign in ((0, -1.0), (1, 1.0)):
        centre = gs.gripper[two, :2] + sign * axis * gs.width[two, None] / 2
        assert np.allclose(np.linalg.norm(gs.contact[two, f] - centre, axis=1), R, atol=1e-6)


def test_a_finger_dragging_the_top_of_a_tilted_block_continues_its_tip_only_pressed() -> None:
    """The same tip continued from 10 degrees: the block no longer rests on the table
    alone (it would fall back on its bottom), so the start-at-rest test does not apply.
    Left to gravity it falls back counter-clockwise about its corner, away from a finger on
    its top face and onto one on its left side. A finger on the top moved by position
    control carries no force there (the judge's "lone finger the object falls away from",
    ``ldhp_tamp.executability``): G_m admits such a grasp only with a press; the left-side
    fingers, which the block leans on, need none."""
    world, gs = lift_world()
    phi = np.radians(np.arange(10.0, 13.0 + 1e-9, 0.5))
    path = np.stack([70.0 - 70.0 * np.cos(phi), 70.0 * np.sin(phi), -phi], axis=1)
    one, top, left = top_and_left_fingers(world, gs, path)
    rows = np.concatenate([top, left])
    assert not grasps_module._leaves_it_still(world, gs, path, rows).any()
    env = grasps_module._env_contacts(world, path, CONTACT_TOL)
    away = grasps_module._falls_away(world, gs, path, rows, env)
    assert away[:top.size].all()
    assert not away[top.size:].any()
    res = motion_conditioned(world, gs, path, rows, rate=False)
    admitted = np.isin(top, res.indices)
    assert admitted.any()
    assert all(res.press_of(int(g)) is not None for g in top[admitted])  # none of them without a press
    assert np.isin(left, res.indices).any()
    assert all(res.press_of(int(g)) is None for g in left if g in res.indices)
    lifted = straight([0, 10, 0], [0, 30, 0])  # in the air nothing holds it but the finger: no test
    env = grasps_module._env_contacts(world, lifted, CONTACT_TOL)
    assert not grasps_module._falls_away(world, gs, lifted, one, env).any()


def test_a_pinch_lift_within_the_force_limit_needs_weight_over_two_mu() -> None:
    """A lift by a pinch of the 70 mm sides (mu_g = 0.6): friction carries the weight W, so
    each finger presses with W / (2 mu_g) at least. Under that limit no grasp is within it;
    at twice that the square-on pinches are."""
    world, gs = lift_world()
    path = straight([0, 100, 0], [0, 140, 0])
    cand = candidates(world, gs, path)
    across = cand[(np.sort(gs.feature[cand], axis=1) == [1, 3]).all(axis=1) & (np.abs(gs.gripper[cand, 2]) < 1e-9)]
    assert across.size
    need = world.object.weight / (2 * 0.6)
    assert not within_force_limit(world, gs, path, across, 0.9 * need).any()
    assert within_force_limit(world, gs, path, across, 2.0 * need).all()


def test_a_contact_the_validator_counts_at_a_vertex_has_the_vertexs_friction() -> None:
    """Plan rule 7 takes a finger contact within its contact tolerance of an object vertex
    as a contact at the vertex, with the vertex's coefficient (the smaller override of its
    two edges). A grasp sampled there has the same, not its edge's: a pinch 0.7 mm from
    a frictionless end face cannot lean on the cover's friction."""
    from geometry.tolerances import VALIDATE_TOL

    world = make_world(TwoPointGripper(R, (10.0, 150.0)), obj=PICK_BLOCK)
    world = World(world.object, world.environment, world.gripper,
                  Friction(0.3, 0.6, object_edges_gripper={1: 0.0}))  # l2, the right end, frictionless
    gs = enumerate_grasps(world, GraspOptions(samples_per_edge=100))
    mu = gs.contact_mu(world)
    verts = world.object.polygon.vertices
    on_cover = gs.touching & np.isin(gs.feature, [0, 2])  # l1 bottom, l3 top
    d = np.stack([np.linalg.norm(np.nan_to_num(gs.contact - v, nan=np.inf), axis=-1) for v in verts[[1, 2]]]).min(axis=0)
    near = on_cover & (d <= VALIDATE_TOL)
    assert near.any() and (mu[near] == 0.0).all()  # v2, v3: next to the frictionless l2
    assert (mu[on_cover & (d > VALIDATE_TOL + CONTACT_TOL)] == 0.6).all()
    far = on_cover & (np.stack([np.linalg.norm(np.nan_to_num(gs.contact - v, nan=np.inf), axis=-1)
                                for v in verts[[0, 3]]]).min(axis=0) <= VALIDATE_TOL)
    assert far.any() and (mu[far] == 0.6).all()  # v1, v4: both edges 0.6
    assert (mu[gs.touching & (gs.feature == 1)] == 0.0).all() and np.isnan(mu[~gs.touching]).all()


def test_contact_mu_is_kept_for_the_world_asked_and_redone_for_another() -> None:
    """A solve asks ``contact_mu`` with one world thousands of times: the table is kept
    (the same read-only array), and a world with other coefficients gets its own."""
    world = make_world(TwoPointGripper(R, (10.0, 150.0)), obj=PICK_BLOCK)
    gs = enumerate_grasps(world, GraspOptions(samples_per_edge=10))
    first = gs.contact_mu(world)
    assert gs.contact_mu(world) is first and not first.flags.writeable
    other = World(world.object, world.environment, world.gripper, Friction(0.3, 0.2))
    mu = gs.contact_mu(other)
    assert np.allclose(mu[gs.touching], 0.2) and np.isnan(mu[~gs.touching]).all()
    assert np.array_equal(gs.contact_mu(world), first, equal_nan=True)


def testrow_groups_are_numpys_unique_rows() -> None:
    """``row_groups`` groups equal rows as ``np.unique(axis=0)`` does: the same first
    rows and the same ids."""
    from geometry.grasps import row_groups

    rng = np.random.default_rng(3)
    keys = rng.integers(-2, 3, (2000, 4)).astype(np.int64)
    inv, first = row_groups(keys)
    _, ref_first, ref_inv = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    assert first.tolist() == ref_first.tolist()
    assert inv.tolist() == np.asarray(ref_inv).reshape(-1).tolist()
    assert (keys[first[inv]] == keys).all()
    empty_inv, empty_first = row_groups(np.zeros((0, 3), dtype=np.int64))
    assert empty_inv.size == 0 and empty_first.size == 0


def _instances_reference(world: World, grasps: GraspSet, rows, path, env, samples):
    """The (grasp, sample) instances as ``_instances`` built them before it wrote into
    one buffer per field (stacked, broadcast and concatenated copies)."""
    a, k = rows.size, samples.size
    p = path[samples]
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])

    def place(q):
        x = c[None, :, None] * q[:, None, :, 0] - s[None, :, None] * q[:, None, :, 1] + p[None, :, None, 0]
        y = s[None, :, None] * q[:, None, :, 0] + c[None, :, None] * q[:, None, :, 1] + p[None, :, None, 1]
        return np.stack([x, y], axis=-1)

    touch = grasps.touching[rows]
    fp = place(np.nan_to_num(grasps.contact[rows]))
    fn = place(np.nan_to_num(grasps.normal[rows])) - p[None, :, None, :2]
    fmu = np.broadcast_to(np.nan_to_num(grasps.contact_mu(world)[rows])[:, None, :], (a, k, 2))
    fmode = np.broadcast_to(np.where(touch, mechanics.ContactMode.STICKING, mechanics.ContactMode.ABSENT)
                            .astype(np.int8)[:, None, :], (a, k, 2))
    b = a * k
    fingers = (fp.reshape(b, 2, 2), fn.reshape(b, 2, 2), fmu.reshape(b, 2), fmode.reshape(b, 2))

    def env_rep(x):
        return np.broadcast_to(x[samples][None], (a,) + x[samples].shape).reshape((b,) + x.shape[1:])

    allc = (np.concatenate([env_rep(env.points), fingers[0]], axis=1),
            np.concatenate([env_rep(env.normals), fingers[1]], axis=1),
            np.concatenate([env_rep(env.mu), fingers[2]], axis=1),
            np.concatenate([env_rep(env.modes), fingers[3]], axis=1),
            np.concatenate([env_rep(env.slide_dirs), np.zeros((b, 2, 2))], axis=1))
    com = np.broadcast_to(place(world.object.com[None, None, :])[0, :, 0][None], (a, k, 2)).reshape(b, 2)
    return fingers, allc, com


def _same_bits(x: np.ndarray, y: np.ndarray) -> bool:
    return x.dtype == y.dtype and x.shape == y.shape and x.flags.c_contiguous and x.tobytes() == y.tobytes()


@pytest.mark.parametrize("gripper", ["two-point-range", "polyline-palm"])
def test_instances_are_bit_for_bit_the_stacked_ones(gripper: str) -> None:
    """``_instances`` writes each field into one buffer: the same bits, dtypes, shapes and
    (C-contiguous) layouts as the stacked and concatenated arrays it built before, for
    rows that touch with one finger or two and samples in any order."""
    world, gs = grasp_set(gripper)
    path = tip_right(20.0, 1.0)
    env = grasps_module._env_contacts(world, path, CONTACT_TOL)
    rng = np.random.default_rng(5)
    rows = np.sort(rng.choice(np.arange(1, len(gs)), 40, replace=False))
    assert (gs.n_touching[rows] == 1).any() and (gs.n_touching[rows] == 2).any()
    for samples in (np.array([0]), np.array([0, path.shape[0] - 1]), rng.permutation(path.shape[0])[:7]):
        fingers, allc, com = grasps_module._instances(world, gs, rows, path, env, samples, with_fingers=True)
        ref_f, ref_a, ref_com = _instances_reference(world, gs, rows, path, env, samples)
        got_a = (allc.points, allc.normals, allc.mu, allc.modes, allc.slide_dirs)
        assert all(_same_bits(x, y) for x, y in zip(got_a, ref_a))
        assert all(_same_bits(x, y) for x, y in zip((fingers.points, fingers.normals, fingers.mu, fingers.modes), ref_f))
        assert _same_bits(com, ref_com)
        none, _, _ = grasps_module._instances(world, gs, rows, path, env, samples)
        assert none is None


def test_finger_rows_and_mu_are_kept_per_set_and_world() -> None:
    """The per-grasp parts of the instances are computed once: NaN as 0, read-only, and
    the friction table redone for another world."""
    world = make_world(TwoPointGripper(R, (10.0, 150.0)), obj=PICK_BLOCK)
    gs = enumerate_grasps(world, GraspOptions(samples_per_edge=10))
    q, n, modes = gs._finger_rows
    assert gs._finger_rows[0] is q and not q.flags.writeable
    assert np.array_equal(q, np.nan_to_num(gs.contact)) and np.array_equal(n, np.nan_to_num(gs.normal))
    assert np.array_equal(modes == mechanics.ContactMode.STICKING, gs.touching)
    mu = gs._finger_mu(world)
    assert gs._finger_mu(world) is mu and np.array_equal(mu, np.nan_to_num(gs.contact_mu(world)))
    other = World(world.object, world.environment, world.gripper, Friction(0.3, 0.2))
    assert np.allclose(gs._finger_mu(other)[gs.touching], 0.2)


def test_contact_classes_group_grasps_with_the_same_instances() -> None:
    """Grasps of one class have the same finger contacts bit for bit (so the same
    (grasp, sample) instances); the representatives are each class's first row."""
    world, gs = grasp_set("polyline-palm")
    ids = gs.contact_classes(world)
    assert gs.contact_classes(world) is ids and ids.shape == (len(gs),)
    q, n, modes = gs._finger_rows
    mu = gs._finger_mu(world)
    assert np.unique(ids).size < len(gs)  # openings share contacts
    for cls in np.unique(ids)[:50]:
        rows = np.flatnonzero(ids == cls)
        for x in (q, n, mu, modes):
            assert all(x[r].tobytes() == x[rows[0]].tobytes() for r in rows)
    rng = np.random.default_rng(2)
    rows = rng.choice(np.arange(1, len(gs)), 300, replace=False)
    rep, of = grasps_module.class_representatives(world, gs, rows)
    assert np.array_equal(ids[rep[of]], ids[rows]) and np.unique(ids[rep]).size == rep.size
    first = {}
    for r in rows:
        first.setdefault(ids[r], r)
    assert sorted(first.values()) == sorted(rep.tolist())
