"""Tests of geometry.mechanics: contact modes, feasibility (fast vs reference), grasp quality."""

from __future__ import annotations

import math

import cvxpy as cp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import geometry.mechanics as mech
from geometry.errors import GeometryError
from geometry.mechanics import (
    MARGIN_CAP,
    ContactMode,
    Contacts,
    FeasibilityStatus,
    ModeTolerances,
    classify_contacts,
    cone_contains,
    feasible_batch,
    feasible_reference,
    force_closure_batch,
    grasp_quality,
    pose_displacements,
    reaction_angle_batch,
    twist_displacements,
    wrench_generators,
)
from geometry.poses import Pose
from geometry.tolerances import FEASIBILITY_MARGIN

S, R, SL, SEP, PEN, ABS = (
    ContactMode.STICKING,
    ContactMode.ROLLING,
    ContactMode.SLIDING,
    ContactMode.SEPARATING,
    ContactMode.PENETRATING,
    ContactMode.ABSENT,
)
UP = (0.0, 1.0)


def block_on_table(com_x: float = 0.0, mu: float = 0.0, half: float = 20.0, height: float = 10.0) -> tuple[Contacts, np.ndarray, float]:
    """A block resting flat on a table: two contacts at the bottom corners (+-half, 0)."""
    c = Contacts.make([[-half, 0.0], [half, 0.0]], [UP, UP], mu, S)
    return c, np.array([com_x, height]), math.hypot(half, height)


def on_slope(beta: float, mu: float, mode: ContactMode, slide_sign: float = 0.0, finger: bool = False):
    """A 20 x 10 block on a slope rising at angle beta; optional frictionless finger.

    The finger pushes horizontally (+x) through the COM from the uphill-facing side.
    ``slide_sign`` = +1 slides uphill, -1 downhill.
    """
    u = np.array([math.cos(beta), math.sin(beta)])  # uphill
    n = np.array([-math.sin(beta), math.cos(beta)])  # out of the slope, into the block
    pts = [-10.0 * u, 10.0 * u]
    com = 5.0 * n
    normals = [n, n]
    modes = [mode, mode]
    mus = [mu, mu]
    slides = [slide_sign * u, slide_sign * u]
    if finger:
        pts.append(com - 8.0 * np.array([1.0, 0.0]))
        normals.append(np.array([1.0, 0.0]))
        modes.append(S)
        mus.append(0.0)
        slides.append(np.zeros(2))
    return Contacts.make(np.array(pts), np.array(normals), mus, modes, np.array(slides)), com, math.hypot(10.0, 5.0)


def fast1(c: Contacts, com, L, margin: float = FEASIBILITY_MARGIN) -> bool:
    return bool(feasible_batch(c, com, L, margin)[0])


# --------------------------------------------------------------------------------------
# Contact modes
# --------------------------------------------------------------------------------------


def test_modes_translation_lift_push_and_rest():
    n = [[0.0, 1.0], [0.0, 1.0]]
    cases = {
        (1.0, 0.0): SL,
        (0.0, 1.0): SEP,
        (0.0, -1.0): PEN,
        (0.0, 0.0): S,
    }
    for d, mode in cases.items():
        m = classify_contacts(n, [d, d], 0.0, 10.0)
        assert (m.codes == mode).all(), (d, m.codes)
    m = classify_contacts(n, [[-2.0, 0.0], [-2.0, 0.0]], 0.0, 10.0)
    assert np.allclose(m.slide_dirs, [[-1.0, 0.0], [-1.0, 0.0]])
    assert m.penetrating.tolist() == [False]


def test_modes_tipping_about_a_corner():
    # block corners on the table at x = 0 and x = 20; tip about (20, 0)
    pts = np.array([[0.0, 0.0], [20.0, 0.0]])
    n = np.array([UP, UP])
    pose0 = Pose(10.0, 5.0, 0.0)
    pivot = np.array([20.0, 0.0])
    for dth, far in ((-0.02, SEP), (0.02, PEN)):  # clockwise lifts the left corner
        # rotate about the pivot: new origin = pivot + R(dth)(o - pivot)
        c, s = math.cos(dth), math.sin(dth)
        o = pivot + np.array([[c, -s], [s, c]]) @ (pose0.position - pivot)
        d, rot = pose_displacements(pts, pose0, Pose(o[0], o[1], dth))
        m = classify_contacts(n, d, rot[:, None], 22.4)
        assert m.codes[0].tolist() == [far, R]
    # the same tip as a twist about the pivot
    v = twist_displacements(pts, [0.0, 0.0, -0.02], pivot)
    m = classify_contacts(n, v, -0.02, 22.4)
    assert m.codes[0].tolist() == [SEP, R]


def test_pose_and_twist_displacements_agree_for_small_steps():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-50, 50, (5, 2))
    tw = np.array([0.3, -0.2, 1e-4])
    ref = np.array([4.0, -7.0])
    v = twist_displacements(pts, tw, ref)
    # the pose change that moves `ref` by (vx, vy) and rotates by omega
    p0 = Pose(ref[0], ref[1], 0.0)
    d, rot = pose_displacements(pts, p0, Pose(ref[0] + tw[0], ref[1] + tw[1], tw[2]))
    assert np.allclose(d, v, atol=1e-6)
    assert rot[0] == pytest.approx(1e-4)


def test_modes_are_scale_aware_and_respect_padding():
    rng = np.random.default_rng(5)
    n = rng.normal(size=(50, 4, 2))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    d = rng.normal(size=(50, 4, 2)) * np.array([1.0, 1e-5])[rng.integers(0, 2, (50, 4))][..., None]
    rot = rng.normal(size=(50, 1)) * 1e-3
    a = classify_contacts(n, d, rot, 30.0)
    for k in (0.1, 1e3):  # above the 1e-6 mm absolute floor, only ratios matter
        b = classify_contacts(n, d * k, rot, 30.0 * k)
        assert (a.codes == b.codes).all()
    assert {S, SL, SEP, PEN} <= set(np.unique(a.codes).tolist())
    present = np.ones((50, 4), bool)
    present[:, 3] = False
    p = classify_contacts(n, d, rot, 30.0, present=present)
    assert (p.codes[:, 3] == ABS).all()
    # thresholds are relative to the step: 1e-5 mm of slip is sticking next to a 1 mm
    # motion, sliding next to a 1e-3 mm motion, and sliding under a tight tolerance
    n2 = [UP, UP]
    assert classify_contacts(n2, [[1.0, 0.0], [1e-5, 0.0]], 0.0, 30.0).codes.tolist() == [[SL, S]]
    assert classify_contacts(n2, [[1e-3, 0.0], [1e-5, 0.0]], 0.0, 30.0).codes.tolist() == [[SL, SL]]
    tight = ModeTolerances(relative=1e-9, absolute=1e-12)
    assert classify_contacts(n2, [[1.0, 0.0], [1e-5, 0.0]], 0.0, 30.0, tight).codes.tolist() == [[SL, SL]]
    # rotation counts in mm through L: 1e-4 rad * 30 mm = 3e-3 mm > 1e-3 * 1 mm -> rolling
    assert classify_contacts(n2, [[1.0, 0.0], [0.0, 0.0]], [[0.0, 1e-4]], 30.0).codes.tolist() == [[SL, R]]
    assert classify_contacts(n2, [[1.0, 0.0], [0.0, 0.0]], [[0.0, 1e-6]], 30.0).codes.tolist() == [[SL, S]]


def test_finger_moving_with_object_sticks():
    d_obj = np.array([[3.0, 1.0]])
    d_finger = np.array([[3.0, 1.0]])
    m = classify_contacts([[1.0, 0.0]], d_obj - d_finger, 0.0, 10.0)
    assert m.codes.tolist() == [[S]]


# --------------------------------------------------------------------------------------
# Feasibility: physical cases, both paths
# --------------------------------------------------------------------------------------


def test_block_flat_on_frictionless_table():
    c, com, L = block_on_table(com_x=5.0, mu=0.0)
    assert fast1(c, com, L)
    ref = feasible_reference(c, com, L, weight=9.81)
    assert ref.status is FeasibilityStatus.FEASIBLE
    # normal forces (20 - 5)/40 and (20 + 5)/40 of the weight, each split over 2 generators
    assert ref.margin == pytest.approx(0.5 * 15.0 / 40.0, abs=1e-7)
    assert ref.forces is not None
    assert ref.forces.sum(axis=0) == pytest.approx([0.0, 9.81], abs=1e-6)
    assert fast1(c, com, L, margin=ref.margin - 1e-6)
    assert not fast1(c, com, L, margin=ref.margin + 1e-6)


@pytest.mark.parametrize("half", [20.0, 1.0, 0.05])
def test_thin_cones_on_narrow_supports_stay_feasible(half):
    """Feasibility may not dip between mu = 0 (a plane of wrenches) and a thin solid cone."""
    for mu in (0.0, 1e-9, 1e-8, 2e-8, 1e-7, 1e-5, 1e-2, 0.5):
        c, com, L = block_on_table(com_x=0.3 * half, mu=mu, half=half)
        assert fast1(c, com, 50.0), mu


@pytest.mark.parametrize("com_x", [25.0, -21.0, 20.0 + 1e-3])
def test_com_outside_support_is_infeasible(com_x):
    c, com, L = block_on_table(com_x=com_x, mu=0.8)
    assert not fast1(c, com, L)
    assert feasible_reference(c, com, L).status is FeasibilityStatus.INFEASIBLE


def test_block_on_a_vertex():
    one = Contacts.make([[0.0, 0.0]], [UP], 0.7, S)
    assert not fast1(one, [3.0, 10.0], 12.0)
    assert feasible_reference(one, [3.0, 10.0], 12.0).status is FeasibilityStatus.INFEASIBLE
    # COM exactly over the support of two coincident-normal contacts at the edge: a force
    # is needed exactly on the boundary -> infeasible (conservative)
    c, com, L = block_on_table(com_x=20.0, mu=0.5)
    assert not fast1(c, com, L)


@pytest.mark.parametrize("beta_deg", [10.0, 25.0, 40.0])
def test_slope_needs_sliding_when_steeper_than_friction(beta_deg):
    mu = 0.4  # atan(0.4) = 21.8 deg
    beta = math.radians(beta_deg)
    steep = math.tan(beta) > mu
    stick, com, L = on_slope(beta, mu, S)
    assert fast1(stick, com, L) is (not steep)
    # lowering the block down the slope, restrained by a frictionless horizontal finger:
    # possible only when gravity beats friction
    down, com, L = on_slope(beta, mu, SL, slide_sign=-1.0, finger=True)
    assert fast1(down, com, L) is steep
    assert feasible_reference(down, com, L).feasible is steep
    # pushing it up the slope with the finger is always possible
    up, com, L = on_slope(beta, mu, SL, slide_sign=+1.0, finger=True)
    assert fast1(up, com, L)


def test_slide_direction_is_classified_from_motion():
    beta = math.radians(35.0)
    c, com, L = on_slope(beta, 0.3, S)
    downhill = -3.0 * np.array([math.cos(beta), math.sin(beta)])
    m = classify_contacts(c.normals, np.broadcast_to(downhill, (1, 2, 2)), 0.0, L)
    assert (m.codes == SL).all()
    moving = Contacts.make(c.points, c.normals, c.mu, m.codes, m.slide_dirs)
    ref, _, _ = on_slope(beta, 0.3, SL, slide_sign=-1.0)
    g1, _ = wrench_generators(moving, com, L)
    g2, _ = wrench_generators(ref, com, L)
    assert np.allclose(g1, g2)


def test_penetrating_separating_and_absent():
    c, com, L = block_on_table(mu=0.5)
    assert not fast1(c.with_modes([S, PEN]), com, L)
    assert feasible_reference(c.with_modes([S, PEN]), com, L).solver_status.startswith("not solved")
    # a separating contact carries nothing: the other alone cannot hold the block
    assert not fast1(c.with_modes([S, SEP]), com, L)
    assert not fast1(c.with_modes([ABS, ABS]), com, L)
    # a third contact pushed into makes an otherwise resting block infeasible
    three = Contacts.make([[-20.0, 0.0], [20.0, 0.0], [0.0, 10.0]], [UP, UP, [0.0, -1.0]], 0.5, [S, S, S])
    assert fast1(three, com, L)
    assert not fast1(three.with_modes([S, S, PEN]), com, L)
    assert fast1(three.with_modes([S, S, SEP]), com, L)
    r = feasible_reference(c.with_modes([SEP, SEP]), com, L)
    assert r.status is FeasibilityStatus.INFEASIBLE and r.margin == -math.inf


def test_contacts_validation():
    with pytest.raises(GeometryError):
        Contacts.make([[0.0, 0.0]], [[0.0, 2.0]], 0.5)
    with pytest.raises(GeometryError):
        Contacts.make([[0.0, 0.0]], [UP], -0.1)
    with pytest.raises(GeometryError):
        Contacts.make([[0.0, 0.0]], [UP], 0.1, 9)
    with pytest.raises(GeometryError):
        feasible_reference(Contacts.make(np.zeros((2, 1, 2)), [UP], 0.1), [0, 1], 1.0)
    # zero normals are fine on padding slots
    Contacts.make([[0.0, 0.0], [0.0, 0.0]], [UP, [0.0, 0.0]], 0.1, [S, ABS])


# --------------------------------------------------------------------------------------
# Fast vs reference on random realistic instances
# --------------------------------------------------------------------------------------

N_AGREE = 10_000
BAND = 1e-5


def random_instances(rng: np.random.Generator, n: int):
    """Padded (n, 4) contact arrays, com (n, 2), L: three families.

    A (60 %): 2-4 contacts on a ring around the COM (radius 0.3-1 L), normals within
    +-57 deg of inward, mixed modes. B (25 %): a block on a table (two contacts, sticking or
    sliding) with the COM within +-2 % of a support corner, plus an optional finger: near
    the feasibility boundary. C (15 %): family A with one contact made frictionless.
    """
    L = 50.0
    C = 4
    pts = np.zeros((n, C, 2))
    nrm = np.zeros((n, C, 2))
    nrm[..., 1] = 1.0
    mu = rng.uniform(0.02, 1.0, (n, C))
    modes = np.zeros((n, C), np.int8)
    slide = rng.normal(size=(n, C, 2))
    com = np.zeros((n, 2))
    fam = rng.choice(3, n, p=[0.6, 0.25, 0.15])
    for i in range(n):
        if fam[i] in (0, 2):
            k = rng.integers(2, 5)
            ang = rng.uniform(0, 2 * np.pi, k)
            rad = rng.uniform(0.3, 1.0, k) * L
            pts[i, :k] = np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1)
            phi = ang + np.pi + rng.uniform(-1.0, 1.0, k)
            nrm[i, :k] = np.stack([np.cos(phi), np.sin(phi)], 1)
            modes[i, :k] = rng.choice([S, R, SL, SEP], k, p=[0.45, 0.15, 0.3, 0.1])
            if fam[i] == 2:
                mu[i, rng.integers(0, k)] = 0.0
        else:
            a, h = rng.uniform(10, 30), rng.uniform(10, 30)
            side = rng.choice([-1.0, 1.0])
            com[i] = [side * a * (1 + rng.uniform(-0.02, 0.02)), h]
            pts[i, :2] = [[-a, 0.0], [a, 0.0]]
            nrm[i, :2] = UP
            modes[i, :2] = rng.choice([S, SL])
            slide[i, :2] = [rng.choice([-1.0, 1.0]), 0.0]
            if rng.random() < 0.5:
                ang = rng.uniform(0, 2 * np.pi)
                pts[i, 2] = com[i] + 0.9 * min(a, h) * np.array([np.cos(ang), np.sin(ang)])
                phi = ang + np.pi + rng.uniform(-0.5, 0.5)
                nrm[i, 2] = [np.cos(phi), np.sin(phi)]
                modes[i, 2] = rng.choice([S, SL, SEP])
    return Contacts.make(pts, nrm, mu, modes, slide), com, L


@pytest.fixture(scope="module")
def agreement():
    rng = np.random.default_rng(20240611)
    contacts, com, L = random_instances(rng, N_AGREE)
    refs = [feasible_reference(contacts.select([i]), com[i], L) for i in range(N_AGREE)]
    return contacts, com, L, refs


def test_fast_and_reference_agree(agreement):
    contacts, com, L, refs = agreement
    fast = feasible_batch(contacts, com, L)
    status = np.array([r.status.value for r in refs])
    margin = np.array([r.margin for r in refs])
    known = status != FeasibilityStatus.UNKNOWN.value
    assert (~known).mean() < 0.002
    in_band = np.abs(margin) < BAND
    assert in_band.mean() < 0.02
    checked = known & ~in_band
    ref_ok = status == FeasibilityStatus.FEASIBLE.value
    mismatch = np.flatnonzero(checked & (fast != ref_ok))
    assert mismatch.size == 0, [(i, margin[i], fast[i]) for i in mismatch[:10]]
    # both outcomes well represented, and many instances close to the boundary
    assert 0.2 < ref_ok[checked].mean() < 0.8
    assert (np.abs(margin) < 1e-2).sum() > 0.03 * N_AGREE


def test_fast_margin_equals_reference_margin(agreement):
    """Bracketing the reference margin with the fast path's margin threshold."""
    contacts, com, L, refs = agreement
    margin = np.array([r.margin for r in refs])
    sel = np.flatnonzero(np.isfinite(margin) & (np.abs(margin) < MARGIN_CAP - 1e-3))
    assert sel.size > 0.5 * len(refs)
    sub = contacts.select(sel)
    tol = 1e-6 * np.maximum(1.0, np.abs(margin[sel]))
    below = feasible_batch(sub, com[sel], L, margin[sel] - tol)
    above = feasible_batch(sub, com[sel], L, margin[sel] + tol)
    assert below.all(), sel[~below][:10]
    assert not above.any(), sel[above][:10]


def test_reference_forces_balance_the_weight(agreement):
    contacts, com, L, refs = agreement
    for i, r in enumerate(refs[:400]):
        if r.feasible:
            assert r.forces is not None and r.forces.shape == (4, 2)
            assert r.forces.sum(axis=0) == pytest.approx([0.0, 1.0], abs=1e-6)
            pts = contacts.points[i] - com[i]
            moment = float(np.sum(pts[:, 0] * r.forces[:, 1] - pts[:, 1] * r.forces[:, 0]))
            assert moment == pytest.approx(0.0, abs=1e-6 * L)


# --------------------------------------------------------------------------------------
# The fast path against its definition, triple by triple
# --------------------------------------------------------------------------------------


def _decide_one(g: np.ndarray, target: np.ndarray, eps: float) -> bool:
    """``target - eps * sum g in cone{g}`` by the fast path's rule, written out for one
    instance with Python floats (each operation rounded as numpy rounds it): the target
    mapped to a positive multiple of e_y, then every triple's certificate, then the one-
    and two-generator certificates of the instances with a near-zero cross."""
    s = [0.0, 0.0, 0.0]
    for row in g:
        for c in range(3):
            s[c] += float(row[c])
    t = [float(target[c]) - eps * s[c] for c in range(3)]
    ax, ay, az = (abs(x) for x in t)
    if max(ax, ay, az) == 0.0:
        return True
    rows = [tuple(float(x) for x in row) for row in g]
    if not (t[1] > 0 and ay >= ax and ay >= az):  # largest |component| to the middle, positive
        kx = ax >= ay and ax >= az
        kz = not kx and az > ay
        k = 0 if kx else 2 if kz else 1
        sgn = math.copysign(1.0, t[k]) if t[k] != 0 else 0.0

        def perm(x: float, y: float, z: float) -> tuple[float, float, float]:
            return (y if kx else x), (x if kx else z if kz else y) * sgn, (y if kz else z)

        rows = [perm(*r) for r in rows]
        t = list(perm(*t))
    u, v, w = t
    a, c = u / v, w / v
    P = [x - a * y for x, y, _ in rows]
    Q = [z - c * y for _, y, z in rows]
    A = [y for _, y, _ in rows]
    live = [k for k in range(len(rows)) if P[k] != 0.0 or Q[k] != 0.0 or A[k] != 0.0]
    P, Q, A = [P[k] for k in live], [Q[k] for k in live], [A[k] for k in live]
    n = len(live)
    cross = {(j, k): P[j] * Q[k] - Q[j] * P[k] for j in range(n) for k in range(j + 1, n)}
    tol, det = mech._CROSS_TOL, mech._DET_TOL
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                cjk, cik, cij = cross[j, k], cross[i, k], cross[i, j]
                d = A[i] * cjk - A[j] * cik + A[k] * cij
                if (cjk >= -tol and cik <= tol and cij >= -tol and d > det) or \
                        (cjk <= tol and cik >= -tol and cij <= tol and d < -det):
                    return True
    if n >= 3 and not any(abs(x) <= 3.0 * mech._DEGENERATE_TOL for x in cross.values()):
        return False
    tol2 = mech._DEGENERATE_TOL * mech._DEGENERATE_TOL
    norm2 = [p * p + q * q for p, q in zip(P, Q)]
    if any(a > 0 and n2 <= tol2 * a * a for n2, a in zip(norm2, A)):
        return True
    nrm = [math.sqrt(x) for x in norm2]
    for j in range(n):
        for k in range(j + 1, n):
            rx = nrm[k] * P[j] + nrm[j] * P[k]
            ry = nrm[k] * Q[j] + nrm[j] * Q[k]
            h = nrm[k] * A[j] + nrm[j] * A[k]
            if h > 0 and rx * rx + ry * ry <= tol2 * h * h:
                return True
    return False


def degenerate_instances(rng: np.random.Generator, n: int, count: int):
    """Instances rich in the fast path's special cases: normals and points snapped to a
    grid (parallel normals, contacts in line with the COM), frictionless and tiny
    coefficients, every mode, sliding with no tangential speed, per-instance COMs."""
    ang = rng.uniform(0, 2 * np.pi, (n, count))
    rad = rng.uniform(0.0, 50.0, (n, count))
    pts = np.stack([rad * np.cos(ang), rad * np.sin(ang)], -1)
    pts = np.where(rng.random((n, count, 1)) < 0.3, np.round(pts / 10.0) * 10.0, pts)
    phi = ang + np.pi + rng.uniform(-1.2, 1.2, (n, count))
    phi = np.where(rng.random((n, count)) < 0.4, np.round(phi / (np.pi / 2)) * (np.pi / 2), phi)
    nrm = np.stack([np.cos(phi), np.sin(phi)], -1)
    nrm = np.where(np.abs(nrm) < 1e-12, 0.0, nrm)
    nrm /= np.hypot(nrm[..., 0], nrm[..., 1])[..., None]
    mu = np.where(rng.random((n, count)) < 0.5, rng.choice([0.0, 1e-9, 0.2, 1.0], (n, count)),
                  rng.uniform(0.0, 1.0, (n, count)))
    modes = rng.choice([ABS, S, R, SL, SEP, PEN], (n, count), p=[0.1, 0.4, 0.15, 0.25, 0.08, 0.02])
    slide = rng.choice([-1.0, 0.0, 1.0], (n, count, 2))
    com = np.where(rng.random((n, 1)) < 0.5, 0.0, rng.uniform(-20.0, 20.0, (n, 2)))
    return Contacts.make(pts, nrm, mu, modes, slide), com, 50.0


def _assert_fast_decides_as_definition(rng: np.random.Generator, c: Contacts, com: np.ndarray,
                                       L: float) -> np.ndarray:
    """``feasible_batch`` at random margins (half the default) decides every instance as
    the certificate rule one instance at a time, with both outcomes present; returns the
    instances' generators."""
    n = c.batch
    margin = np.where(rng.random(n) < 0.5, FEASIBILITY_MARGIN, rng.uniform(-0.05, 0.2, n))
    fast = feasible_batch(c, com, L, margin)
    gens, pen = wrench_generators(c, com, L)
    slow = np.array([not pen[i] and _decide_one(gens[i], np.array([0.0, 1.0, 0.0]), float(margin[i]))
                     for i in range(n)])
    assert (fast == slow).all(), np.flatnonzero(fast != slow)[:10]
    assert fast.any() and not fast.all()  # both outcomes
    return gens


@pytest.mark.parametrize("count", [1, 2, 3, 4, 6])
def test_fast_path_decides_as_its_triple_by_triple_definition(count: int):
    """The vectorised kernel (blocks of triples, the instances accepted early left out of
    the later triples, the degenerate test on the few left) decides every instance as the
    certificate rule written out one instance and one triple at a time."""
    rng = np.random.default_rng(1000 + count)
    n = 1500 if count < 6 else 400
    c, com, L = degenerate_instances(rng, n, count)
    gens = _assert_fast_decides_as_definition(rng, c, com, L)
    t = rng.normal(size=(n, 3)) * (rng.random((n, 3)) < 0.7)
    g = np.where(rng.random(gens.shape[:2] + (1,)) < 0.2, 0.0, gens)
    fast = cone_contains(g, t, 1e-7)
    slow = np.array([_decide_one(g[i], t[i], 1e-7) for i in range(n)])
    assert (fast == slow).all(), np.flatnonzero(fast != slow)[:10]


def _edges_one_by_one(c: Contacts, com: np.ndarray, L: float) -> np.ndarray:
    """The generators edge by edge: ``(n + m t) * (1 / sqrt(1 + m^2))`` with ``m = mu``
    (or, sliding, ``-sign(s.t) mu``) for slot 2i and ``m = -mu`` for slot 2i+1, zero
    where the mode gives no such edge, and ``Z = r x (X, Y)`` with ``r = (p - com) / L``."""
    B, C = c.modes.shape
    out = np.zeros((B, 2 * C, 3))
    for i in range(C):
        n, p, md = c.normals[:, i], c.points[:, i], c.modes[:, i]
        mu = np.where(c.mu[:, i] < mech.MU_ZERO, 0.0, c.mu[:, i])
        full, sliding = (md == S) | (md == R), md == SL
        st = -c.slide_dirs[:, i, 0] * n[:, 1] + c.slide_dirs[:, i, 1] * n[:, 0]
        rx, ry = (p[:, 0] - com[0]) * (1.0 / L), (p[:, 1] - com[1]) * (1.0 / L)
        for e, m, on in ((0, np.where(sliding, -np.sign(st) * mu, mu), full | sliding), (1, -mu, full)):
            inv = on / np.sqrt(1.0 + m * m)
            x = (n[:, 0] - m * n[:, 1]) * inv
            y = (n[:, 1] + m * n[:, 0]) * inv
            out[:, 2 * i + e] = np.stack([x, y, rx * y - ry * x], -1)
    return out


@pytest.mark.parametrize("full", [False, True])
def test_generators_are_the_edges_bit_for_bit(full: bool):
    """Both generator builds (a chunk whose contacts are all STICKING or ROLLING skips the
    mode masks) give the edge-by-edge values exactly."""
    rng = np.random.default_rng(7)
    c, com, L = degenerate_instances(rng, 3000, 4)
    if full:
        c = c.with_modes(rng.choice([S, R], c.modes.shape))
    com = np.array([3.0, -2.0])
    g, _ = wrench_generators(c, com, L)
    assert np.array_equal(g, _edges_one_by_one(c, com, L))


@pytest.mark.parametrize("count", [3, 4, 5, 8])
@pytest.mark.parametrize("compact", [0.0, 1.0])
@pytest.mark.parametrize("full", [False, True])
def test_fast_path_stages_decide_as_their_definition(count: int, compact: float, full: bool, monkeypatch):
    """Both ways the kernel takes the triples left after the first generator's (on the
    whole chunk, or gathered into the grid of the open instances: ``_COMPACT`` forces
    each) and both generator builds (every contact STICKING or ROLLING, or any modes)
    decide every instance as the certificate rule written out one instance at a time."""
    monkeypatch.setattr(mech, "_COMPACT", compact)
    rng = np.random.default_rng(2000 + count)
    n = 500 if count < 8 else 200
    c, com, L = degenerate_instances(rng, n, count)
    if full:
        c = c.with_modes(rng.choice([S, R], c.modes.shape))
    _assert_fast_decides_as_definition(rng, c, com, L)


# --------------------------------------------------------------------------------------
# Properties
# --------------------------------------------------------------------------------------


@st.composite
def instances(draw, modes=(S, R, SL, SEP), min_size=2, max_size=4):
    k = draw(st.integers(min_size, max_size))
    f = st.floats(0.0, 1.0, allow_nan=False)
    ang = np.array([draw(f) for _ in range(k)]) * 2 * np.pi
    rad = 0.3 + 0.7 * np.array([draw(f) for _ in range(k)])
    dev = (np.array([draw(f) for _ in range(k)]) - 0.5) * 2.0
    mu = np.array([draw(st.one_of(st.just(0.0), st.floats(0.02, 1.2))) for _ in range(k)])
    md = [draw(st.sampled_from(modes)) for _ in range(k)]
    sd = [draw(st.sampled_from([-1.0, 1.0])) for _ in range(k)]
    pts = np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1) * 40.0
    phi = ang + np.pi + dev
    nrm = np.stack([np.cos(phi), np.sin(phi)], 1)
    slide = np.stack([-nrm[:, 1], nrm[:, 0]], 1) * np.array(sd)[:, None]
    com = np.array([draw(st.floats(-8.0, 8.0)), draw(st.floats(-8.0, 8.0))])
    return Contacts.make(pts, nrm, mu, md, slide), com, 40.0


@settings(max_examples=150, deadline=None)
@given(instances(), st.randoms(use_true_random=False))
def test_reordering_contacts_and_generators_changes_nothing(inst, rnd):
    c, com, L = inst
    perm = list(range(c.count))
    rnd.shuffle(perm)
    d = Contacts.make(c.points[:, perm], c.normals[:, perm], c.mu[:, perm], c.modes[:, perm], c.slide_dirs[:, perm])
    assert fast1(c, com, L) == fast1(d, com, L)
    g, _ = wrench_generators(c, com, L)
    gp = list(range(g.shape[1]))
    rnd.shuffle(gp)
    for m in (0.0, FEASIBILITY_MARGIN, 0.05):
        assert cone_contains(g, [0, 1, 0], m)[0] == cone_contains(g[:, gp], [0, 1, 0], m)[0]
    assert cone_contains(g, [0, 1, 0], FEASIBILITY_MARGIN)[0] == fast1(c, com, L)


@settings(max_examples=150, deadline=None)
@given(instances(), st.floats(1e-3, 1e3), st.floats(-500.0, 500.0), st.floats(-500.0, 500.0))
def test_rescaling_and_moving_the_object_changes_nothing(inst, k, dx, dy):
    c, com, L = inst
    shift = np.array([dx, dy])
    d = Contacts.make(c.points * k + shift, c.normals, c.mu, c.modes, c.slide_dirs)
    assert fast1(c, com, L) == fast1(d, com * k + shift, L * k)
    assert bool(force_closure_batch(c, com, L)[0]) == bool(force_closure_batch(d, com * k + shift, L * k)[0])


@settings(max_examples=25, deadline=None)
@given(instances(modes=(S, R, SL)), st.floats(0.1, 10.0), st.floats(0.01, 100.0))
def test_rescaling_in_the_reference(inst, k, weight):
    c, com, L = inst
    d = Contacts.make(c.points * k, c.normals, c.mu, c.modes, c.slide_dirs)
    a = feasible_reference(c, com, L, weight=1.0)
    b = feasible_reference(d, com * k, L * k, weight=weight)
    assert a.status == b.status
    if np.isfinite(a.margin):
        assert b.margin == pytest.approx(a.margin, abs=1e-6)
    if a.feasible:
        assert b.forces == pytest.approx(weight * a.forces, abs=1e-5 * weight)


@settings(max_examples=200, deadline=None)
@given(instances(modes=(S, R, SEP, SL)), st.lists(st.floats(0.0, 2.0), min_size=4, max_size=4))
def test_more_friction_never_loses_feasibility(inst, extra):
    """Raising mu on sticking/rolling contacts only widens cones (sliding edges would turn)."""
    c, com, L = inst
    grow = np.isin(c.modes, [S, R]) * np.array(extra[: c.count])
    more = c.with_mu(c.mu + grow)
    if fast1(c, com, L):
        assert fast1(more, com, L)
    if force_closure_batch(c, com, L)[0]:
        assert force_closure_batch(more, com, L)[0]


@settings(max_examples=100, deadline=None)
@given(instances(), st.lists(st.floats(-1.0, 1.0), min_size=9, max_size=9))
def test_cone_membership_is_linear_invariant(inst, m):
    """Membership of any target is unchanged by an invertible linear map of wrench space."""
    c, com, L = inst
    g, _ = wrench_generators(c, com, L)
    M = np.array(m).reshape(3, 3) + 2.0 * np.eye(3)
    if abs(np.linalg.det(M)) < 0.5:
        return
    for t in (np.eye(3)[0], -np.eye(3)[1], np.array([0.3, 1.0, -0.2]), np.eye(3)[2]):
        # M maps cone(G) onto cone(MG): with a margin on one side, the image is (closed)
        # in the other; comparing margin-to-closed keeps rounding at the boundary out
        if cone_contains(g, t, 1e-9)[0]:
            assert cone_contains(g @ M.T, M @ t)[0]
        if cone_contains(g @ M.T, M @ t, 1e-9)[0]:
            assert cone_contains(g, t)[0]


@settings(max_examples=200, deadline=None)
@given(instances(modes=(S, R, SL), max_size=5))
def test_force_closure_matches_convex_hull_definition(inst):
    """Force closure <=> the origin is strictly inside the convex hull of the generators."""
    spatial = pytest.importorskip("scipy.spatial")
    c, com, L = inst
    g, _ = wrench_generators(c, com, L)
    pts = g[0][np.abs(g[0]).sum(axis=1) > 0]
    if len(pts) < 4 or np.linalg.matrix_rank(pts[1:] - pts[0], tol=1e-9) < 3:
        # a flat hull has no interior: the origin cannot be strictly inside
        assert not force_closure_batch(c, com, L)[0]
        return
    hull = spatial.ConvexHull(pts)
    offsets = hull.equations[:, 3] / np.linalg.norm(hull.equations[:, :3], axis=1)
    if np.abs(offsets).min() < 1e-6:  # origin (nearly) on a facet: boundary case
        return
    assert bool(force_closure_batch(c, com, L)[0]) == bool((offsets < 0).all())


@settings(max_examples=150, deadline=None)
@given(instances(modes=(S, R)))
def test_force_closure_implies_feasible(inst):
    c, com, L = inst
    if force_closure_batch(c, com, L)[0]:
        assert fast1(c, com, L)


# --------------------------------------------------------------------------------------
# Force closure and grasp quality
# --------------------------------------------------------------------------------------


def test_force_closure_cases():
    # antipodal pinch of a 40 x 20 block, fingers at mid-height
    pinch = Contacts.make([[-20.0, 0.0], [20.0, 0.0]], [[1.0, 0.0], [-1.0, 0.0]], 0.5, S)
    assert force_closure_batch(pinch, [0.0, 0.0], 22.4).tolist() == [True]
    assert force_closure_batch(pinch.with_mu(0.0), [0.0, 0.0], 22.4).tolist() == [False]
    # contact line outside the cones: fingers offset vertically beyond atan(0.5)
    skew = Contacts.make([[-20.0, -10.0], [20.0, 10.0]], [[1.0, 0.0], [-1.0, 0.0]], 0.3, S)
    assert force_closure_batch(skew, [0.0, 0.0], 22.4).tolist() == [False]
    assert force_closure_batch(skew.with_mu(0.6), [0.0, 0.0], 22.4).tolist() == [True]
    # frictionless pinwheel on a square: four contacts are force closure, three are not
    p = [[-1.0, 0.5], [1.0, -0.5], [0.5, -1.0], [-0.5, 1.0]]
    n = [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]]
    wheel = Contacts.make(p, n, 0.0, S)
    assert force_closure_batch(wheel, [0.0, 0.0], 1.5).tolist() == [True]
    assert force_closure_batch(wheel.with_modes([S, S, S, ABS]), [0.0, 0.0], 1.5).tolist() == [False]
    assert force_closure_batch(wheel.with_modes([S, S, S, SL]), [0.0, 0.0], 1.5).tolist() == [True]
    assert force_closure_batch(wheel.with_modes([S, S, S, PEN]), [0.0, 0.0], 1.5).tolist() == [False]


def test_reaction_angle_on_a_slope_is_the_slope_angle():
    beta = math.radians(15.0)
    c, com, L = on_slope(beta, 0.6, S)
    alpha = reaction_angle_batch(c, com, L, iterations=20)
    assert alpha[0] == pytest.approx(beta, abs=2e-6)
    flat, fcom, fL = block_on_table(mu=0.6)
    assert reaction_angle_batch(flat, fcom, fL).tolist() == [0.0]
    steep, scom, sL = on_slope(math.radians(40.0), 0.6, S)
    assert np.isnan(reaction_angle_batch(steep, scom, sL)[0])
    # a batch gives the per-instance values
    pts = np.concatenate([c.points, flat.points])
    both = Contacts.make(pts, np.concatenate([c.normals, flat.normals]), 0.6, S)
    two = reaction_angle_batch(both, np.stack([com, fcom]), np.array([L, fL]), iterations=20)
    assert two[0] == pytest.approx(beta, abs=2e-6) and two[1] == 0.0


def test_grasp_quality_formula():
    beta = math.radians(15.0)
    c, com, L = on_slope(beta, 0.6, S, finger=True)
    J = 3
    motion = Contacts.make(np.repeat(c.points, J, 0), np.repeat(c.normals, J, 0), c.mu, c.modes)
    fingers = motion.select(slice(None))
    fingers = Contacts.make(fingers.points[:, 2:], fingers.normals[:, 2:], 0.0, S)
    coms = np.repeat(com[None], J, 0)
    q = grasp_quality(fingers, motion, coms, L, w1=2.0, w2=3.0)
    assert not q.force_closure and q.s == 1 and q.admissible
    # the frictionless finger can push the block uphill: less friction is needed than beta
    assert 0.0 <= q.alpha < beta
    assert q.value == pytest.approx(2.0 + 3.0 * q.alpha)
    pinch = Contacts.make(np.array([[[-20.0, 0.0], [20.0, 0.0]]] * J), [[1.0, 0.0], [-1.0, 0.0]], 0.5, S)
    qp = grasp_quality(pinch, pinch, np.zeros((J, 2)), 22.4)
    # squeezing makes any friction angle > 0 suffice: alpha is at the bisection floor
    assert qp.force_closure and qp.s == 0 and qp.alpha < 1e-4 and qp.value == pytest.approx(qp.alpha)


# --------------------------------------------------------------------------------------
# Reference solver outcomes
# --------------------------------------------------------------------------------------


@pytest.fixture
def held():
    c, com, L = block_on_table(com_x=3.0, mu=0.5)
    return c, com, L


def _patched(monkeypatch, status: str, corrupt: bool = False, raise_: Exception | None = None, drop_s: bool = False):
    real = mech._run_solver

    def fake(ref):
        if raise_ is not None:
            raise raise_
        real(ref)
        if corrupt:
            ref.lam.value = np.zeros(ref.lam.shape)
        if drop_s:
            ref.s.value = None
        return status

    monkeypatch.setattr(mech, "_run_solver", fake)


def test_reference_optimal(held):
    r = feasible_reference(*held)
    assert r.status is FeasibilityStatus.FEASIBLE and r.solver_status == cp.OPTIMAL and r.margin > 0.1


def test_reference_optimal_inaccurate_verified(monkeypatch, held):
    _patched(monkeypatch, cp.OPTIMAL_INACCURATE)
    r = feasible_reference(*held)
    assert r.status is FeasibilityStatus.FEASIBLE and r.solver_status == cp.OPTIMAL_INACCURATE
    assert r.forces is not None


def test_reference_optimal_inaccurate_unverified(monkeypatch, held):
    _patched(monkeypatch, cp.OPTIMAL_INACCURATE, corrupt=True)
    r = feasible_reference(*held)
    assert r.status is FeasibilityStatus.UNKNOWN and r.forces is None and math.isnan(r.margin)


def test_reference_optimal_without_values(monkeypatch, held):
    _patched(monkeypatch, cp.OPTIMAL, drop_s=True)
    assert feasible_reference(*held).status is FeasibilityStatus.UNKNOWN


def test_reference_optimal_but_below_margin(held):
    c, com, L = held
    r = feasible_reference(c, com, L, margin=0.49)
    assert r.status is FeasibilityStatus.INFEASIBLE and 0 < r.margin < 0.49 and r.forces is None


@pytest.mark.parametrize(
    "status, expected",
    [
        (cp.INFEASIBLE, FeasibilityStatus.INFEASIBLE),
        (cp.INFEASIBLE_INACCURATE, FeasibilityStatus.UNKNOWN),
        (cp.UNBOUNDED, FeasibilityStatus.UNKNOWN),
        (cp.UNBOUNDED_INACCURATE, FeasibilityStatus.UNKNOWN),
        (cp.USER_LIMIT, FeasibilityStatus.UNKNOWN),
        (cp.SOLVER_ERROR, FeasibilityStatus.UNKNOWN),
    ],
)
def test_reference_other_statuses(monkeypatch, held, status, expected):
    _patched(monkeypatch, status)
    r = feasible_reference(*held)
    assert r.status is expected and r.solver_status == status and r.forces is None


@pytest.mark.parametrize("exc", [cp.error.SolverError("clarabel gave up"), RuntimeError("boom")])
def test_reference_solver_exceptions_do_not_escape(monkeypatch, held, exc):
    _patched(monkeypatch, "", raise_=exc)
    r = feasible_reference(*held)
    assert r.status is FeasibilityStatus.UNKNOWN and str(exc) in r.solver_status


def test_reference_outside_span_needs_no_solve(monkeypatch):
    def boom(ref):
        raise AssertionError("the solver must not be called")

    monkeypatch.setattr(mech, "_run_solver", boom)
    one = Contacts.make([[0.0, 0.0]], [UP], 0.7, S)
    r = feasible_reference(one, [3.0, 10.0], 12.0)
    assert r.status is FeasibilityStatus.INFEASIBLE and "span" in r.solver_status


# --------------------------------------------------------------------------------------
# bounded_support: the finger force limit (plan rule 9) and the force solution
# --------------------------------------------------------------------------------------


def _pinch(mu: float, modes=(S, S), slide=((0.0, 0.0), (0.0, 0.0))) -> Contacts:
    """A block pinched at its ends (x = -30, +30) by two horizontal fingers."""
    return Contacts.make([[-30.0, 0.0], [30.0, 0.0]], [[1.0, 0.0], [-1.0, 0.0]], mu, list(modes), list(slide))


@pytest.mark.parametrize("mu, weight", [(0.5, 9.81), (0.2, 4.905), (1.0, 20.0)])
def test_bounded_support_pinch_needs_w_over_2_mu_per_finger(mu: float, weight: float):
    need = weight / (2 * mu)
    for limit, ok in ((need * 1.001, True), (need * 0.999, False), (None, True)):
        r = mech.bounded_support(_pinch(mu), [0.0, 0.0], 40.0, weight, [0, 1], limit)
        assert bool(r.feasible[0]) is ok and bool(r.equilibrium[0])
        assert r.max_finger_force[0] == pytest.approx(need, rel=1e-6)
        # each finger presses with W / (2 mu); friction carries half the weight each, on the cone edge
        assert r.forces[0, :, 0] == pytest.approx([need, need], rel=1e-6)
        assert r.finger_forces[0, :, 0] == pytest.approx([need, need], rel=1e-6)
        assert np.abs(r.forces[0, :, 1]) == pytest.approx([weight / 2, weight / 2], rel=1e-6)


def test_bounded_support_respects_the_sliding_modes():
    # finger 2 slips down relative to the object (the object moves up: friction pulls it down)
    down = _pinch(0.5, (S, SL), ((0, 0), (0.0, 1.0)))
    assert not mech.bounded_support(down, [0.0, 0.0], 40.0, 9.81, [0, 1]).feasible[0]
    # the object moves down relative to finger 2: kinetic friction mu N up; the moment
    # balance puts finger 1's friction on its cone edge too (closed cones: margin 0)
    up = _pinch(0.5, (S, SL), ((0, 0), (0.0, -1.0)))
    r = mech.bounded_support(up, [0.0, 0.0], 40.0, 9.81, [0, 1], margin=0.0)
    assert r.feasible[0] and r.max_finger_force[0] == pytest.approx(9.81, rel=1e-6)
    f2 = r.forces[0, 1]
    assert abs(f2[1]) == pytest.approx(0.5 * f2[0], rel=1e-6)  # on the cone edge


def test_bounded_support_agrees_with_the_cone_test_without_a_limit():
    """max_force = inf: the same verdict as feasible_batch at the same margin, and where
    feasible, forces that balance the weight (force and moment)."""
    rng = np.random.default_rng(7)
    contacts, com, L = random_instances(rng, 600)
    finger_of = np.where(np.arange(4) >= 2, np.arange(4) - 2, -1)  # contacts 2, 3 are fingers
    for margin in (0.0, FEASIBILITY_MARGIN):
        r = mech.bounded_support(contacts, com, L, 9.81, finger_of, math.inf, margin=margin)
        cone = feasible_batch(contacts, com, L, margin=margin)
        assert (r.feasible == cone).all() and (r.equilibrium == cone).all()
    ok = np.flatnonzero(r.feasible)
    assert 100 < ok.size < 550
    n = contacts.normals[ok]
    t = np.stack([-n[..., 1], n[..., 0]], -1)
    f = r.forces[ok, :, :1] * n + r.forces[ok, :, 1:] * t  # (k, C, 2) world forces
    assert f.sum(axis=1) == pytest.approx(np.tile([0.0, 9.81], (ok.size, 1)), abs=1e-5)
    arm = contacts.points[ok] - com[ok][:, None, :]
    moment = (arm[..., 0] * f[..., 1] - arm[..., 1] * f[..., 0]).sum(axis=1)
    assert moment == pytest.approx(np.zeros(ok.size), abs=1e-5 * L)
    largest = np.maximum(r.finger_forces[ok, 0, 0], r.finger_forces[ok, 1, 0])
    assert r.max_finger_force[ok] == pytest.approx(np.maximum(largest, 0.0), abs=1e-6)
    bad = np.flatnonzero(~r.feasible)
    assert np.isnan(r.forces[bad]).all() and np.isnan(r.max_finger_force[bad]).all()


def test_bounded_support_minimises_the_largest_finger_force():
    """On a table with a finger on each side the table carries the weight: no finger
    needs to push, whatever the limit."""
    c = Contacts.make([[-20.0, -10.0], [20.0, -10.0], [-20.0, 0.0], [20.0, 0.0]],
                      [UP, UP, [1.0, 0.0], [-1.0, 0.0]], 0.3)
    r = mech.bounded_support(c, [0.0, 0.0], 25.0, 9.81, [-1, -1, 0, 1], max_force=1e-3)
    assert r.feasible[0] and r.max_finger_force[0] == pytest.approx(0.0, abs=1e-6)


def test_bounded_support_input_checks():
    with pytest.raises(GeometryError):
        mech.bounded_support(_pinch(0.5), [0.0, 0.0], 40.0, 9.81, [0, 2])
    with pytest.raises(GeometryError):
        mech.bounded_support(_pinch(0.5), [0.0, 0.0], 40.0, -1.0, [0, 1])
    with pytest.raises(GeometryError):
        mech.bounded_support(_pinch(0.5), [0.0, 0.0], 40.0, 9.81, [0, 1], max_force=0.0)


def test_bounded_support_holds_a_pressed_finger_at_its_force() -> None:
    """A block on a floor (mu 0.03) dragged by a finger pressing on its top: with the
    press fixed at f the floor carries W + f and the finger's friction balances the floor's
    sliding friction 0.03 (W + f), within mu_g f only for f >= 0.03 W / 0.57."""
    from geometry.mechanics import ContactMode, bounded_support

    W = 4.905
    drag = Contacts.make([[0.0, 0.0], [100.0, 0.0], [50.0, 20.0]], [[0.0, 1.0], [0.0, 1.0], [0.0, -1.0]],
                         [0.03, 0.03, 0.6], [ContactMode.SLIDING, ContactMode.SLIDING, ContactMode.STICKING],
                         [[1.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    r = bounded_support(drag, [50.0, 10.0], 50.0, W, [-1, -1, 0], None, margin=0.0, pressed=[W, np.nan])
    assert r.feasible[0]
    assert r.finger_forces[0, 0, 0] == pytest.approx(W)
    assert r.finger_forces[0, 0, 1] == pytest.approx(-0.03 * 2 * W)
    low = 0.9 * 0.03 * W / 0.57
    assert not bounded_support(drag, [50.0, 10.0], 50.0, W, [-1, -1, 0], None, margin=0.0,
                               pressed=[low, np.nan]).feasible[0]
    # unpressed, the least finger force is the threshold itself
    free = bounded_support(drag, [50.0, 10.0], 50.0, W, [-1, -1, 0], None, margin=0.0)
    assert free.max_finger_force[0] == pytest.approx(0.03 * W / 0.57, rel=1e-6)


def test_pressed_feasible_decides_as_the_pressed_lp() -> None:
    """The cone-test decision of a pressed contact's support (two cone tests for a
    sticking contact, one for a sliding one) against the force LP with that contact's
    normal force fixed, on random instances."""
    from geometry.mechanics import ContactMode, bounded_support, pressed_feasible

    rng = np.random.default_rng(7)
    B, C = 400, 4
    ang = rng.uniform(0, 2 * np.pi, (B, C))
    normals = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    points = rng.uniform(-50, 50, (B, C, 2))
    mu = rng.choice([0.0, 0.1, 0.3, 0.8], (B, C))
    modes = rng.choice([ContactMode.STICKING, ContactMode.SLIDING, ContactMode.ABSENT], (B, C), p=[0.5, 0.3, 0.2])
    modes[:, 0] = rng.choice([ContactMode.STICKING, ContactMode.SLIDING], B)
    sdir = rng.normal(size=(B, C, 2))
    contacts = Contacts.make(points, np.where((modes == ContactMode.ABSENT)[..., None], 0.0, normals), mu,
                             modes, sdir)
    force = rng.choice([0.2, 1.0, 3.0], B)
    fast = pressed_feasible(contacts, [0.0, 0.0], 40.0, np.zeros(B, dtype=np.int64), force)
    finger_of = np.full(C, -1)
    finger_of[0] = 0
    lp = bounded_support(contacts, [0.0, 0.0], 40.0, 1.0, finger_of, None, margin=0.0, fingers=1,
                         pressed=force[:, None]).feasible
    assert fast.any() and (~fast).any()
    assert (fast == lp).all()


def test_an_empty_batch_has_no_generators() -> None:
    from geometry.mechanics import ContactMode, Contacts, wrench_generators

    c = Contacts.make(np.zeros((0, 2, 2)), np.zeros((0, 2, 2)), np.zeros((0, 2)), ContactMode.STICKING)
    for com in (np.zeros(2), np.zeros((0, 2))):
        gens, pen = wrench_generators(c, com, 10.0)
        assert gens.shape == (0, 4, 3) and pen.shape == (0,)
