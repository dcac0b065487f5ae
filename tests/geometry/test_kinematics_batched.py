"""The batched sweeps and grids (geometry.kinematics.sweep_many, _grid_poses,
_last_true_many) give exactly what the one-at-a-time code they replaced gave: that code
is kept here, as it was, as the reference."""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np
import pytest

from geometry import kinematics as K
from geometry.contacts import principal_contact_masks
from geometry.features import Contact, ContactKind
from geometry.kinematics import Motion, SweepEnd, SweepPiece, Sweep, rotate_about, sweep, sweep_many, translate, two_contact
from geometry.poses import Pose
from geometry.shapes import make_polygon
from geometry.tolerances import CONTACT_TOL, EPS
from geometry.world import Environment, Friction, Solid, TwoPointGripper, World, make_object

BLOCK = [[0, 0], [70, 0], [70, 150], [0, 150]]


@pytest.fixture(scope="module")
def slot() -> World:
    # U-shaped solid: slot floor y=0 for x in [0, 300], walls up to y=75.
    u = [[-200, 75], [-200, -50], [500, -50], [500, 75], [300, 75], [300, 0], [0, 0], [0, 75]]
    env = Environment((Solid("slot", make_polygon(u)),))
    return World(make_object(BLOCK), env, TwoPointGripper(5.0, (90.0, 90.0)), Friction(0.2, 0.2))


# ---------------------------------------------------------------- the reference (old) code


def _old_vertex_steps(world: World, poses: np.ndarray) -> np.ndarray:
    verts = world.object.polygon.vertices
    c, sn = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    wx = c[:, None] * verts[None, :, 0] - sn[:, None] * verts[None, :, 1] + poses[:, 0:1]
    wy = sn[:, None] * verts[None, :, 0] + c[:, None] * verts[None, :, 1] + poses[:, 1:2]
    return np.max(np.hypot(np.diff(wx, axis=0), np.diff(wy, axis=0)), axis=1)


def _old_grid(world: World, motion: Motion, s0: float, s1: float, step_mm: float) -> np.ndarray:
    speed = max(motion.vertex_speed(world), EPS)
    if motion.kind is K.MotionKind.TWO_CONTACT:
        speed = min(speed, K.TWO_CONTACT_SPEED_CAP * world.object.polygon.radius)
    n = max(1, int(math.ceil(abs(s1 - s0) * speed / step_mm)))
    s = np.linspace(s0, s1, n + 1)
    for _ in range(40):
        d = _old_vertex_steps(world, motion.poses(s))
        undefined = np.flatnonzero(~np.isfinite(d))
        stop = int(undefined[0]) if undefined.size else d.size
        too_far = np.zeros(d.size, dtype=bool)
        too_far[:stop] = d[:stop] > step_mm
        if not np.any(too_far) or s.size >= K.MAX_GRID_SAMPLES:
            return s
        mids = 0.5 * (s[:-1][too_far] + s[1:][too_far])
        s = np.sort(np.concatenate([s, mids]))
    return s


def _old_last_true(pred: Callable[[np.ndarray], np.ndarray], lo: float, hi: float, bits: int, width: int = 64) -> float:
    rounds = max(1, int(math.ceil(bits / math.log2(width + 1))))
    for _ in range(rounds):
        x = np.linspace(lo, hi, width + 2)[1:-1]
        ok = pred(x)
        bad = np.flatnonzero(~ok)
        if bad.size == 0:
            lo = float(x[-1])
        else:
            i = int(bad[0])
            hi = float(x[i])
            lo = float(x[i - 1]) if i > 0 else lo
    return lo


def _old_state_keys(world: World, poses: np.ndarray, tol: float):  # type: ignore[no-untyped-def]
    m = principal_contact_masks(world, poses, tol)
    flat = np.concatenate([m.vertex_edge.reshape(len(poses), -1), m.edge_vertex.reshape(len(poses), -1),
                           m.edge_edge.reshape(len(poses), -1)], axis=1)
    return [row.tobytes() for row in np.packbits(flat, axis=1)], m


def _old_sweep(world: World, motion: Motion, s_max: float, *, step_mm: float = 1.0, refine_bits: int = 24,
               tol: float = CONTACT_TOL) -> Sweep:
    overlap = K._default_overlap
    s = _old_grid(world, motion, 0.0, s_max, step_mm)

    def good_at(x: np.ndarray) -> np.ndarray:
        p = motion.poses(x)
        ok = np.all(np.isfinite(p), axis=1)
        safe = np.where(np.isfinite(p), p, 0.0)
        for c in motion.kept:
            ok &= K.kept_contact_holds(world, c, safe)
        idx = np.flatnonzero(ok)
        if idx.size:
            ok[idx] = ~overlap(world, p[idx])
        return ok

    first_bad = None
    i, size = 0, 64
    while i < s.size:
        j = min(s.size, i + size)
        ok = good_at(s[i:j])
        if not ok.all():
            first_bad = i + int(np.argmin(ok))
            break
        i, size = j, 2 * size
    if first_bad == 0:
        _, masks = _old_state_keys(world, motion.start.as_array()[None], tol)
        return Sweep(motion, (SweepPiece(masks.state(0), 0.0, 0.0),), SweepEnd.BLOCKED)
    if first_bad is None:
        end = SweepEnd.LIMIT
        poses = motion.poses(s)
    else:
        p_bad = motion.poses(s[first_bad:first_bad + 1])[0]
        if not np.all(np.isfinite(p_bad)):
            end = SweepEnd.DEGENERATE
        elif any(not K.kept_contact_holds(world, c, p_bad[None])[0] for c in motion.kept):
            end = SweepEnd.CONTACT_LOST
        else:
            end = SweepEnd.BLOCKED
        lo = _old_last_true(good_at, float(s[first_bad - 1]), float(s[first_bad]), refine_bits)
        s = np.concatenate([s[:first_bad], [lo]]) if lo > s[first_bad - 1] else s[:first_bad]
        poses = motion.poses(s)
    keys, masks = _old_state_keys(world, poses, tol)
    pieces = []
    start_i = 0
    s0 = 0.0
    for i in range(1, len(s) + 1):
        if i < len(s) and keys[i] == keys[start_i]:
            continue
        state = masks.state(start_i)
        if i == len(s):
            pieces.append(SweepPiece(state, s0, float(s[-1])))
            break
        key = keys[start_i]

        def same(x: np.ndarray, key: bytes = key) -> np.ndarray:
            return np.array([k == key for k in _old_state_keys(world, motion.poses(x), tol)[0]])

        boundary = _old_last_true(same, float(s[i - 1]), float(s[i]), refine_bits // 2)
        pieces.append(SweepPiece(state, s0, boundary))
        s0 = boundary
        start_i = i
    return Sweep(motion, tuple(pieces), end)


# ---------------------------------------------------------------- motions to compare on


def _leaning(world: World) -> Pose:
    """The block in the slot's left corner, tilted 20 degrees clockwise: v1 on the left
    wall, v2 on the floor."""
    th = math.radians(-20.0)
    return Pose(0.0, -(math.sin(th) * 70.0), th)


class _Alarmist(Motion):
    """A motion with the speed bound of a near-singular start (the grid is subdivided)."""

    def vertex_speed(self, world: World) -> float:
        return 1.5e6


def _motions(world: World) -> list[tuple[Motion, float]]:
    lean = _leaning(world)
    kept = (Contact(ContactKind.VERTEX_EDGE, 0, 6), Contact(ContactKind.VERTEX_EDGE, 1, 5))
    slide = two_contact(world, lean, kept, -1)
    scared = _Alarmist(**{f.name: getattr(slide, f.name) for f in dataclasses.fields(Motion)})
    standing = Pose(100.0, 0.0, 0.0)
    floor = [Contact(ContactKind.VERTEX_EDGE, 0, 5), Contact(ContactKind.VERTEX_EDGE, 1, 5)]
    return [
        (slide, math.pi), (two_contact(world, lean, kept, 1), math.pi), (scared, math.pi),
        (rotate_about(standing, (170.0, 0.0), -1), math.pi), (rotate_about(standing, (170.0, 0.0), 1), math.pi),
        (rotate_about(standing, (100.0, 0.0), 1), math.pi), (rotate_about(standing, (100.0, 0.0), -1), math.pi),
        (translate(standing, (1.0, 0.0), floor), 500.0), (translate(standing, (-1.0, 0.0), floor), 500.0),
        (translate(standing, (0.0, 1.0)), 40.0),  # leaves the floor: free at the end of the range
        (translate(Pose(100.0, 5.0, 0.3), (0.0, -1.0)), 30.0),
        (rotate_about(lean, (0.0, 0.0), -1), 0.01),  # a short range: a few samples
        (translate(Pose(100.0, -1.0, 0.0), (1.0, 0.0)), 50.0),  # in the floor from the start
    ]


@pytest.mark.parametrize("step_mm", [1.0, 3.0, 0.25])
def test_grid_poses_are_the_old_grid_and_its_poses(slot: World, step_mm: float) -> None:
    for motion, s_max in _motions(slot):
        s, p = K._grid_poses(slot, motion, 0.0, s_max, step_mm)
        old = _old_grid(slot, motion, 0.0, s_max, step_mm)
        assert s.shape == old.shape and np.array_equal(s, old)
        assert np.array_equal(p, motion.poses(s), equal_nan=True)
        assert np.array_equal(K._grid(slot, motion, 0.0, s_max, step_mm), old)


def _through_a_singularity(sense: int) -> Motion:
    """A two-contact motion whose contact lines turn parallel at +-90 degrees: the object
    vertex (0, 0) on the floor y = 0 and the environment vertex (300, 0) on the line of
    the object's edge x = 70 (normal (1, 0))."""
    lines = ((0.0, 0.0, 0.0, 0.0, 1.0, 0.0), (1.0, 1.0, 0.0, 300.0, 0.0, 70.0))
    return Motion(K.MotionKind.TWO_CONTACT, Pose(230.0, 0.0, 0.0), sense, lines=lines)


@pytest.mark.parametrize("sense", [-1, 1])
def test_a_grid_through_a_singularity_and_at_the_sample_cap(slot: World, sense: int) -> None:
    """Near the singularity the vertices move ever faster: the grid is refined up to the
    first undefined pose, or up to MAX_GRID_SAMPLES."""
    m = _through_a_singularity(sense)
    capped = undefined = False
    for step in (3.0, 1.0, 0.01):
        s, p = K._grid_poses(slot, m, 0.0, 2 * math.pi, step)
        old = _old_grid(slot, m, 0.0, 2 * math.pi, step)
        assert np.array_equal(s, old) and np.array_equal(p, m.poses(s), equal_nan=True)
        capped |= s.size >= K.MAX_GRID_SAMPLES
        undefined |= bool(np.isnan(p).any())
    assert capped and undefined


def test_last_true_many_is_last_true_per_interval() -> None:
    thresholds = [0.3, 0.71, 1.0 / 3.0, 0.999]
    preds = [lambda x, t=t: x <= t for t in thresholds]
    for bits in (5, 10, 24):
        got = K._last_true_many(lambda xs: [f(x) for f, x in zip(preds, xs)], [0.0] * 4, [1.0] * 4, bits)
        assert got == [_old_last_true(f, 0.0, 1.0, bits) for f in preds]
    assert K._last_true_many(lambda xs: [], [], [], 10) == []


@pytest.mark.parametrize("step_mm, refine_bits", [(1.0, 24), (3.0, 10)])
def test_sweep_many_is_the_old_sweep_of_each(slot: World, step_mm: float, refine_bits: int) -> None:
    jobs = _motions(slot) + [(_through_a_singularity(1), 2 * math.pi), (_through_a_singularity(-1), 2 * math.pi)]
    many = sweep_many(slot, jobs, step_mm=step_mm, refine_bits=refine_bits)
    assert len(many) == len(jobs)
    ends = set()
    for (motion, s_max), got in zip(jobs, many):
        want = _old_sweep(slot, motion, s_max, step_mm=step_mm, refine_bits=refine_bits)
        assert got.motion == motion and got.end is want.end and got.pieces == want.pieces
        one = sweep(slot, motion, s_max, step_mm=step_mm, refine_bits=refine_bits)
        assert one.end is want.end and one.pieces == want.pieces
        ends.add(got.end)
    # the cases the comparison covers: blocked at once and later, a kept contact lost, the limit
    assert {SweepEnd.BLOCKED, SweepEnd.CONTACT_LOST, SweepEnd.LIMIT} <= ends
    assert any(sw.end is SweepEnd.BLOCKED and sw.s_end == 0.0 for sw in many)
    assert any(len(sw.pieces) > 2 for sw in many)
    assert sweep_many(slot, []) == []



@pytest.mark.parametrize("step_mm", [3.0, 1.0, 0.01])
def test_a_grid_computed_in_part_starts_as_the_whole_grid(slot: World, step_mm: float) -> None:
    """_Grid.upto halves only the first intervals: what it knows is the start of the
    whole grid (up to a singularity and at the sample cap too), with the same poses."""
    motions = _motions(slot) + [(_through_a_singularity(1), 2 * math.pi), (_through_a_singularity(-1), 2 * math.pi)]
    parts = 0
    for motion, s_max in motions:
        whole = _old_grid(slot, motion, 0.0, s_max, step_mm)
        for count in (1, 64, 192, 448, 960):
            g = K._Grid(slot, motion, 0.0, s_max, step_mm)
            g.upto(count)
            assert g.s.size >= min(count, whole.size) and g.more(g.s.size) != g.complete
            assert np.array_equal(g.s, whole[:g.s.size])
            assert np.array_equal(g.p, motion.poses(g.s), equal_nan=True)
            parts += not g.complete
            s, p = g.whole()
            assert g.complete and np.array_equal(s, whole) and not g.more(s.size)
    assert parts  # some grids were known in part only


def test_poses_of_several_motions_are_each_motions_poses(slot: World) -> None:
    """kinematics._poses_many (the sweeps' refinements and grids place every motion of a
    batch at once): bit for bit Motion.poses of each, for every kind of motion, two-contact
    ones with both kinds of kept contact and through a singularity (NaN rows), empty and
    scalar parameters."""
    rng = np.random.default_rng(8)
    motions = [m for m, _ in _motions(slot)] + [_through_a_singularity(1), _through_a_singularity(-1)]
    motions += [_through_a_singularity(1)]  # vertex-edge and edge-vertex kept
    params = [rng.uniform(-0.5, 4.0, int(rng.integers(0, 40))) for _ in motions]
    params[3], params[-1] = np.zeros(0), 0.7
    params[-3] = np.append(np.linspace(1.4, 1.75, 30), math.pi / 2)  # the lines parallel at 90 degrees
    got = K._poses_many(motions, params)
    assert len(got) == len(motions)
    for m, x, p in zip(motions, params, got):
        np.testing.assert_array_equal(p, m.poses(x))
    assert any(np.isnan(p).any() for p in got)
    assert K._poses_many([], []) == []


def test_linspaces_are_numpy_linspace_of_each_interval() -> None:
    """kinematics._linspaces (the multisection's points of every interval at once): bit
    for bit np.linspace of each, zero-length and denormal intervals included."""
    rng = np.random.default_rng(9)
    lo = rng.uniform(-5, 5, 50) * 10.0 ** rng.integers(-8, 4, 50)
    hi = lo + rng.uniform(0, 3, 50) * 10.0 ** rng.integers(-12, 2, 50)
    for num in (66, 2, 7, 1):
        got = K._linspaces(lo, hi, num)
        assert np.array_equal(got, np.array([np.linspace(a, b, num) for a, b in zip(lo, hi)]))
    lo2, hi2 = np.array([0.0, 1.0, 5e-324]), np.array([1.0, 1.0, 1e-323])  # a zero and a denormal step
    assert np.array_equal(K._linspaces(lo2, hi2, 66), np.array([np.linspace(a, b, 66) for a, b in zip(lo2, hi2)]))
    assert K._linspaces([], [], 66).shape == (0, 66)
