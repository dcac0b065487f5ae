"""Tests of geometry.collision: the fast paths agree with the literal rule 3.

The literal rule: bodies overlap at tolerance t iff ``intersection(A, B).buffer(-t)`` is
non-empty. The fast paths erode each body separately and use prepared predicates.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from geometry.collision import (
    circle_overlaps,
    eroded_environment,
    eroded_polygon,
    finger_env_clearance,
    finger_env_overlap,
    finger_object_overlap,
    finger_shapes,
    fingers_overlap,
    gripper_env_overlap,
    gripper_object_overlap,
    object_env_overlap,
    overlaps,
    polygon_env_overlap,
)
from geometry.poses import transform_points
from geometry.shapes import make_polygon
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
# One U-shaped solid: slot 300 wide, 75 deep, floor at y = 0, surroundings at y = 75.
SLOT = [[-200, 75], [0, 75], [0, 0], [300, 0], [300, 75], [500, 75], [500, -50], [-200, -50]]
BLOCK = [[0, 0], [70, 0], [70, 150], [0, 150]]
FINGER = [[0, 0], [10, 0], [10, 40], [0, 40]]
PALM = [[-90, 40], [90, 40], [90, 60], [-90, 60]]


def make_world(solids, obj=BLOCK, gripper=None) -> World:
    env = Environment(tuple(Solid(f"s{k}", make_polygon(v)) for k, v in enumerate(solids)))
    g = gripper if gripper is not None else TwoPointGripper(5.0, (80.0, 80.0))
    return World(make_object(obj), env, g, Friction(0.2, 0.2))


def polyline_gripper(palm: bool = True) -> PolylineGripper:
    return PolylineGripper(make_polygon(FINGER), (0.0, 140.0), make_polygon(PALM) if palm else None)


def literal(a: shapely.Geometry, b: shapely.Geometry, t: float) -> bool:
    """Rule 3 verbatim: the intersection eroded by t is non-empty."""
    return not shapely.intersection(a, b).buffer(-t).is_empty


def near_boundary(a: shapely.Geometry, b: shapely.Geometry, t: float, rel: float = 0.02) -> bool:
    """True when the literal answer flips within +-rel*t (or 0.002 mm): a tie to skip."""
    d = max(rel * t, 2e-3)
    return literal(a, b, max(t - d, 0.0)) != literal(a, b, t + d)


def random_polygon(rng: np.random.Generator, n: int, radius: float, concave: bool) -> np.ndarray:
    """A random simple polygon around the origin (its convex hull when not concave)."""
    while True:
        ang = np.sort(rng.uniform(0, 2 * math.pi, n))
        r = radius * (rng.uniform(0.35, 1.0, n) if concave else np.ones(n))
        pts = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
        if not concave:
            hull = shapely.MultiPoint(pts).convex_hull
            pts = np.asarray(hull.exterior.coords)[:-1]
        if len(pts) >= 3 and shapely.Polygon(pts).is_valid:
            return pts


def disk(c, r) -> shapely.Geometry:
    return shapely.Point(float(c[0]), float(c[1])).buffer(float(r), quad_segs=64)


# --------------------------------------------------------------------------------------
# Agreement with the literal rule on random instances
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("concave", [False, True])
@pytest.mark.parametrize("tol", [0.1, 1.0])
def test_object_env_agrees_with_literal_rule(concave: bool, tol: float) -> None:
    rng = np.random.default_rng(7 + int(concave) + int(10 * tol))
    checked = hits = 0
    for trial in range(12):
        obj = random_polygon(rng, 9, 20.0, concave)
        world = make_world([TABLE, SLOT], obj=obj)
        env = shapely.union_all([s.polygon.shapely for s in world.environment.solids])
        b = 60
        # Poses close to the table top / slot walls so that depths of order t are common.
        poses = np.column_stack([
            rng.choice([-300.0, 0.0, 300.0], b) + rng.uniform(-25, 25, b),
            rng.choice([0.0, 75.0], b) + rng.uniform(-22, 22, b),
            rng.uniform(-math.pi, math.pi, b),
        ])
        fast = object_env_overlap(world, poses, tol)
        world_v = transform_points(poses, world.object.polygon.vertices)
        for k in range(b):
            a = shapely.Polygon(world_v[k])
            if near_boundary(a, env, tol):
                continue
            checked += 1
            hits += bool(fast[k])
            assert fast[k] == literal(a, env, tol), (trial, k, poses[k].tolist())
    assert checked > 500 and 0.1 < hits / checked < 0.9


@pytest.mark.parametrize("tol", [0.1, 1.0])
def test_circle_finger_agrees_with_literal_rule(tol: float) -> None:
    rng = np.random.default_rng(11)
    checked = hits = 0
    for trial in range(10):
        poly = random_polygon(rng, 10, 30.0, concave=trial % 2 == 1)
        gp = shapely.Polygon(poly)
        r = float(rng.uniform(0.5, 8.0))
        world = make_world([poly], gripper=TwoPointGripper(r, (60.0, 60.0)))
        b = 80
        # Finger 1 is at (-30, 0) in the gripper frame: put it near the boundary.
        bpts = shapely.line_interpolate_point(gp.exterior, rng.uniform(0, 1, b), normalized=True)
        target = shapely.get_coordinates(bpts) + rng.normal(0, r, (b, 2))
        poses = np.column_stack([target[:, 0] + 30.0, target[:, 1], np.zeros(b)])
        fast = finger_env_overlap(world, poses, 60.0, tol)[:, 0]
        for k in range(b):
            d = disk(target[k], r)
            if near_boundary(d, gp, tol):
                continue
            checked += 1
            hits += bool(fast[k])
            assert fast[k] == literal(d, gp, tol), (trial, k)
            assert circle_overlaps(target[k], r, poly, tol) == fast[k]
    assert checked > 500 and 0.1 < hits / checked < 0.9


@pytest.mark.parametrize("tol", [0.1, 1.0])
def test_circle_circle_agrees_with_literal_rule(tol: float) -> None:
    for r in (0.05, 0.5, 5.0):
        g = TwoPointGripper(r, (0.0, 20.0))
        widths = np.linspace(0.0, 12.0, 241)
        fast = fingers_overlap(g, widths, tol)
        for w, f in zip(widths, fast):
            a, b = disk((-w / 2, 0), r), disk((w / 2, 0), r)
            if not near_boundary(a, b, tol):
                assert f == literal(a, b, tol), (r, w)
    # Exact threshold: |c1 - c2| <= 2 (r - t).
    g = TwoPointGripper(5.0, (0.0, 20.0))
    assert fingers_overlap(g, [9.8, 9.81], 0.1).tolist() == [True, False]


@pytest.mark.parametrize("tol", [0.1, 1.0])
def test_pairwise_overlaps_agrees_with_literal_rule(tol: float) -> None:
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(300):
        a = random_polygon(rng, 8, 10.0, concave=bool(rng.integers(2)))
        b = random_polygon(rng, 8, 10.0, concave=bool(rng.integers(2))) + rng.uniform(-18, 18, 2)
        ga, gb = shapely.Polygon(a), shapely.Polygon(b)
        if near_boundary(ga, gb, tol):
            continue
        checked += 1
        assert overlaps(a, b, tol) == literal(ga, gb, tol)
    assert checked > 250


# --------------------------------------------------------------------------------------
# Touching, depth thresholds, thin bodies
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("tol", [0.1, 1.0])
def test_touching_bodies_do_not_overlap(tol: float) -> None:
    world = make_world([TABLE, SLOT])
    # Block standing on the table, block lying on the slot floor against its wall.
    assert not object_env_overlap(world, [[-400, 0, 0], [0, 0, 0]], tol).any()
    assert not object_env_overlap(world, [[150, 0, math.pi / 2]], tol).any()  # lying on the floor, against the wall
    # Finger tangent to the table top; fingers tangent to each other.
    assert not gripper_env_overlap(world, [[-400, 5.0, 0.0]], 80.0, tol).any()
    assert not fingers_overlap(world.gripper, [10.0], tol).any()
    # At t = 0 the closed rule counts touching as overlap.
    assert object_env_overlap(world, [[-400, 0, 0]], 0.0).all()
    assert fingers_overlap(world.gripper, [10.0], 0.0).all()


def test_half_millimetre_overlap_depends_on_tolerance() -> None:
    world = make_world([TABLE])
    pose = [[0.0, -0.5, 0.0]]
    assert not object_env_overlap(world, pose, 1.0)[0]
    assert object_env_overlap(world, pose, 0.1)[0]
    assert not gripper_env_overlap(world, [[0.0, 4.5, 0.0]], 80.0, 1.0)[0]
    assert gripper_env_overlap(world, [[0.0, 4.5, 0.0]], 80.0, 0.1)[0]
    assert not overlaps(BLOCK, np.asarray(TABLE) + [0, 0.5], 1.0)
    assert overlaps(BLOCK, np.asarray(TABLE) + [0, 0.5], 0.1)


def test_thin_body_never_overlaps() -> None:
    thin = [[0, 0], [50, 0], [50, 1.5], [0, 1.5]]
    world = make_world([TABLE], obj=thin)
    assert eroded_polygon(world.object.polygon, 1.0).is_empty
    deep = [[0.0, -50.0, 0.0], [10.0, -20.0, 0.3]]
    assert not object_env_overlap(world, deep, 1.0).any()
    assert object_env_overlap(world, deep, 0.1).all()


def test_erosion_that_splits_keeps_every_part() -> None:
    # A dumbbell: two 20 x 20 lobes joined by a 1 mm neck; at t = 1 it splits in two.
    bell = [[0, 0], [20, 0], [20, 9.5], [40, 9.5], [40, 0], [60, 0], [60, 20], [40, 20],
            [40, 10.5], [20, 10.5], [20, 20], [0, 20]]
    world = make_world([TABLE], obj=bell)
    assert len(eroded_polygon(world.object.polygon, 1.0).parts) == 2
    # Tilted so that only one lobe dips about 3 mm into the table, then only the other.
    first = [[0.0, 50.0 * math.sin(0.1) - 3.0, -0.1]]
    second = [[0.0, -3.0, 0.1]]
    for pose in (first, second):
        assert object_env_overlap(world, pose, 1.0)[0]
        a = shapely.Polygon(transform_points(pose, world.object.polygon.vertices)[0])
        assert literal(a, world.environment.shapely, 1.0)


# --------------------------------------------------------------------------------------
# Batches equal single pairs; object-frame tests equal world-frame ones
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("model", ["two-point", "polyline"])
def test_gripper_batches_equal_single_pairs(model: str) -> None:
    gripper = TwoPointGripper(5.0, (20.0, 100.0)) if model == "two-point" else polyline_gripper()
    world = make_world([SLOT], gripper=gripper)
    rng = np.random.default_rng(5)
    b = 150
    gposes = np.column_stack([rng.uniform(-40, 340, b), rng.uniform(-10, 140, b), rng.uniform(-math.pi, math.pi, b)])
    oposes = np.column_stack([rng.uniform(0, 200, b), rng.uniform(0, 100, b), rng.uniform(-math.pi, math.pi, b)])
    widths = rng.uniform(20, 100, b)
    tol = 0.5
    env_batch = gripper_env_overlap(world, gposes, widths, tol)
    obj_batch = gripper_object_overlap(world, oposes, gposes, widths, tol)
    per_finger = finger_object_overlap(world, oposes, gposes, widths, tol)
    fs = finger_shapes(gripper, gposes, widths)
    env_geom = world.environment.shapely
    for k in range(b):
        assert gripper_env_overlap(world, gposes[k], widths[k], tol)[0] == env_batch[k]
        obj_world = transform_points(oposes[k], world.object.polygon.vertices)[0]
        if model == "two-point":
            bodies_env = [circle_overlaps(c, 5.0, env_geom, tol) for c in fs.centres[k]]
            bodies_obj = [circle_overlaps(c, 5.0, obj_world, tol) for c in fs.centres[k]]
        else:
            bodies = list(fs.polygons[k]) + [fs.palm[k]]
            bodies_env = [overlaps(p, env_geom, tol) for p in bodies]
            bodies_obj = [overlaps(p, obj_world, tol) for p in bodies]
        assert any(bodies_env) == env_batch[k], k
        assert any(bodies_obj) == obj_batch[k], k
        assert list(per_finger[k]) == bodies_obj[:2], k
    assert 0 < env_batch.sum() < b and 0 < obj_batch.sum() < b


def test_polyline_fingers_touch_at_zero_opening() -> None:
    g = polyline_gripper()
    assert not fingers_overlap(g, [0.0, 10.0], 0.1).any()
    assert fingers_overlap(g, [-0.3, -5.0], 0.1).all()
    assert not fingers_overlap(g, [-0.15], 0.1)[0]  # 0.15 mm deep strip < 2 t


def test_polyline_finger_shapes_follow_the_gripper_frame() -> None:
    g = polyline_gripper()
    fs = finger_shapes(g, [[100.0, 50.0, math.pi / 2]], 20.0)
    # Finger 2's pad-tip corner (0, 0) sits at (+w/2, 0) in the gripper frame.
    assert np.allclose(fs.polygons[0, 1, 0], [100.0, 60.0])
    assert fs.palm is not None and fs.palm.shape == (1, 4, 2)
    assert np.all(fs.polygons[0, 0, :, 1] <= 40.0 + 1e-9)  # finger 1 at x <= -w/2 -> y <= 40


def test_clearance_and_cache() -> None:
    world = make_world([TABLE])
    d = finger_env_clearance(world, [[0.0, 12.0, 0.0], [0.0, 3.0, 0.0]], 80.0)
    assert np.allclose(d, [[7.0, 7.0], [0.0, 0.0]])
    assert eroded_environment(world.environment, 0.1) is eroded_environment(world.environment, 0.1)
    assert polygon_env_overlap(world.environment, world.object.polygon, np.zeros((0, 3))).shape == (0,)
    with pytest.raises(ValueError):
        object_env_overlap(world, [[0, 0, 0]], -1.0)


# --------------------------------------------------------------------------------------
# The point-predicate pre-filters change no answer of the GEOS tests they stand before
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("tol", [0.0, 0.1, 1.0])
def test_circle_prefilter_matches_plain_dwithin(tol: float) -> None:
    from geometry.collision import _circles_vs_geometry

    target = eroded_environment(make_world([TABLE, SLOT]).environment, tol)
    rng = np.random.default_rng(11)
    r = 5.0
    lim = r - tol
    # Random centres, plus centres at distance lim (+- a hair) of a slot wall, floor,
    # rounded corner and lip, where the filters must hand over to GEOS.
    c = np.column_stack([rng.uniform(-250, 550, 4000), rng.uniform(-80, 120, 4000)])
    ref = shapely.dwithin(target.geometry, shapely.points(c), lim)
    assert (_circles_vs_geometry(c, r, target) == ref).all()
    base = np.array([[0.0 + tol, 40.0], [150.0, 0.0 + tol], [300.0 - tol, 40.0], [tol, tol], [0.0 - tol, 75.0 + tol]])
    way = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [math.sqrt(0.5), math.sqrt(0.5)], [-math.sqrt(0.5), math.sqrt(0.5)]])
    for eps in (-1e-9, 0.0, 1e-9, 1e-7, 1e-4):
        c = base + (lim + eps) * way
        ref = shapely.dwithin(target.geometry, shapely.points(c), lim)
        assert (_circles_vs_geometry(c, r, target) == ref).all(), eps


@pytest.mark.parametrize("tol", [0.0, 0.1])
def test_polygon_prefilter_matches_plain_intersects(tol: float) -> None:
    from geometry.collision import _parts_vs_geometry

    target = eroded_environment(make_world([TABLE, SLOT]).environment, tol)
    rng = np.random.default_rng(12)
    for parts in (eroded_polygon(make_polygon(FINGER), tol).parts, eroded_polygon(make_polygon(BLOCK), tol).parts):
        b = 3000
        poses = np.column_stack([rng.uniform(-250, 550, b), rng.uniform(-60, 140, b), rng.uniform(-math.pi, math.pi, b)])
        offsets = np.column_stack([rng.uniform(-70, 70, b), np.zeros(b)])
        ref = np.zeros(b, dtype=bool)
        for part in parts:
            ref |= shapely.intersects(target.geometry, shapely.polygons(transform_points(poses, part[None] + offsets[:, None])))
        got = _parts_vs_geometry(parts, poses, target, offsets)
        assert (got == ref).all()
        assert 0.05 < got.mean() < 0.95
    # A block standing exactly on the floor, and lifted by a hair.
    parts = eroded_polygon(make_polygon(BLOCK), tol).parts
    poses = np.array([[100.0, y, 0.0] for y in (-2 * tol, -tol, -1e-9, 0.0, 1e-9, tol)])
    ref = np.zeros(len(poses), dtype=bool)
    for part in parts:
        ref |= shapely.intersects(target.geometry, shapely.polygons(transform_points(poses, part[None])))
    assert (_parts_vs_geometry(parts, poses, target) == ref).all()


def test_orientation_signs_are_certain_or_zero() -> None:
    """collision._orient_sign: the exact sign of orient2d where the filter is sure (checked
    in rationals), 0 on the line and beside it within rounding."""
    from fractions import Fraction

    from geometry.collision import _orient_sign

    rng = np.random.default_rng(4)
    a, b = rng.uniform(-500, 500, (2, 400, 2))
    t = rng.uniform(-1, 2, 400)
    c = a + t[:, None] * (b - a)  # on the line, up to rounding
    c[:200] += rng.normal(0.0, 1e-12, (200, 2)) * 10.0 ** rng.integers(0, 13, (200, 1))
    got = _orient_sign(a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1])
    for i in range(400):
        fa, fb, fc = ([Fraction(float(v)) for v in p[i]] for p in (a, b, c))
        exact = (fa[0] - fc[0]) * (fb[1] - fc[1]) - (fa[1] - fc[1]) * (fb[0] - fc[0])
        assert got[i] == 0 or got[i] == (exact > 0) - (exact < 0)
    assert np.count_nonzero(got) > 50 and np.count_nonzero(got[200:] == 0) > 150
    assert _orient_sign(*map(np.array, (0.0, 0.0, 1.0, 0.0, 0.5, 0.0))) == 0


def test_convex_parts_are_decided_as_geos_decides() -> None:
    """collision._convex_vs_target, the exact-sign test of strictly convex parts: where it
    decides, it is shapely.intersects; it decides clear crossings, a target inside the part
    and clear misses, and leaves touching ones to GEOS."""
    from geometry.collision import _convex_vs_target, _strictly_convex

    target = eroded_environment(Environment((Solid("slot", make_polygon(
        [[300, 0], [0, 0], [0, 75], [-200, 75], [-200, -50], [500, -50], [500, 75], [300, 75]])),
        Solid("peg", make_polygon([[600, 100], [610, 100], [610, 110], [600, 110]])))), 1e-4)
    block = eroded_polygon(make_polygon([[0, 0], [70, 0], [70, 150], [0, 150]]), 1e-4)
    part = block.parts[0]
    assert _strictly_convex(part) and block.convex == (True,)
    assert eroded_polygon(make_polygon([[0, 0], [20, 0], [20, 20], [10, 20], [10, 10], [0, 10]]), 0.1).convex == (False,)
    assert not _strictly_convex(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 1.0]]))
    assert not _strictly_convex(np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.5], [2.0, 2.0], [0.0, 2.0]]))
    rng = np.random.default_rng(6)
    poses = np.column_stack([rng.uniform(-250, 650, 3000), rng.uniform(-100, 150, 3000), rng.uniform(-4, 4, 3000)])
    poses = np.concatenate([poses, [[0.0, 0.0, 0.0], [575.0, 50.0, 0.0]]])
    placed = transform_points(poses, np.broadcast_to(part, (poses.shape[0],) + part.shape))
    outside = ~shapely.intersects_xy(target.geometry, placed[..., 0].ravel(), placed[..., 1].ravel()
                                     ).reshape(placed.shape[:2]).any(axis=1)
    placed = placed[outside]
    hit, decided = _convex_vs_target(placed, target)
    want = shapely.intersects(target.geometry, shapely.polygons(placed))
    np.testing.assert_array_equal(hit[decided], want[decided])
    assert not np.any(hit & ~decided)
    assert decided.mean() > 0.99 and want[decided].sum() > 50 and (~want[decided]).sum() > 50
    # the pose resting in the slot's corner, 2e-4 mm clear, is decided a miss; the part
    # around the peg (a target part inside it) a hit
    assert list(zip(hit[-2:], decided[-2:])) == [(False, True), (True, True)]
    # a triangle touching a square's corner with an edge (exactly) is left to GEOS
    square = eroded_polygon(make_polygon([[0, 0], [1, 0], [1, 1], [0, 1]]), 0.0)
    hit, decided = _convex_vs_target(np.array([[[0.0, 2.0], [2.0, 0.0], [3.0, 3.0]]]), square)
    assert not decided[0] and not hit[0]
