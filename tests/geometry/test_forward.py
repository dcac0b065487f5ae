"""The quasi-static forward problem (geometry.forward): is the planned object motion the
only one the commanded finger motion allows?"""

from __future__ import annotations

import numpy as np
import pytest

from geometry import mechanics
from geometry.errors import GeometryError
from geometry.forward import MAX_CONTACTS, alternative_motions

# A 10 x 20 block standing on the floor (corners (0, 0) and (10, 0)), a finger on its left
# side at height h pushing right (+x) and sticking to it.
COM = np.array([[5.0, 10.0]])


def _push(h: float, mu_floor: float, mu_finger: float = 1.0):
    pts = [[[0.0, 0.0], [10.0, 0.0], [0.0, h]]]
    nrm = [[[0.0, 1.0], [0.0, 1.0], [1.0, 0.0]]]
    w = [[[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]]]
    return pts, nrm, [[mu_floor, mu_floor, mu_finger]], [[True, True, True]], w


def _tip_twist(h: float) -> np.ndarray:
    """The twist (about the COM) of a tip about the corner (10, 0) that moves the finger
    point (0, h) by (1, ...): omega = -1 / h."""
    om = -1.0 / h
    c = COM[0] - np.array([10.0, 0.0])
    return np.array([[-om * c[1], om * c[0], om]])


@pytest.mark.parametrize("h, mu, ambiguous", [
    (20.0, 0.1, True),   # sliding needs 0.1 W, tipping 0.25 W: the block slides
    (20.0, 0.8, False),  # sliding needs 0.8 W: it tips as planned
    (5.0, 0.8, True),    # pushed low (tipping needs W): it slides
])
def test_a_pushed_block_tips_only_when_sliding_costs_more(h: float, mu: float, ambiguous: bool) -> None:
    chk = alternative_motions(*_push(h, mu), COM, 11.2, _tip_twist(h))
    assert bool(chk.ambiguous[0]) is ambiguous
    if ambiguous:  # the alternative found slides on the floor (flat, or on one corner)
        assert mechanics.ContactMode.SLIDING in chk.modes[0, :2].tolist()
        assert chk.modes[0, 2] == mechanics.ContactMode.STICKING


def test_a_planned_slide_is_not_its_own_alternative() -> None:
    # frictionless floor, pushed low: sliding is what is planned, tipping is impossible
    chk = alternative_motions(*_push(5.0, 0.0), COM, 11.2, [[1.0, 0.0, 0.0]])
    assert not chk.ambiguous[0]


def test_padding_slots_are_ignored_and_batches_are_independent() -> None:
    pts, nrm, mu, on, w = _push(20.0, 0.1)
    pad = lambda a, v: np.concatenate([np.asarray(a, float), np.full((1, 1) + np.shape(a)[2:], v)], axis=1)  # noqa: E731
    one = alternative_motions(pad(pts, 0.0), pad(nrm, 0.0), pad(mu, 0.0), pad(on, False), pad(w, 0.0), COM, 11.2,
                              _tip_twist(20.0))
    assert one.ambiguous.tolist() == [True]
    pts2, nrm2, mu2, on2, w2 = _push(20.0, 0.8)
    both = alternative_motions(np.concatenate([pts, pts2]), np.concatenate([nrm, nrm2]), np.concatenate([mu, mu2]),
                               np.concatenate([on, on2]), np.concatenate([w, w2]), np.concatenate([COM, COM]), 11.2,
                               np.concatenate([_tip_twist(20.0)] * 2))
    assert both.ambiguous.tolist() == [True, False]


def test_too_many_contacts_is_an_error() -> None:
    c = MAX_CONTACTS + 1
    with pytest.raises(GeometryError):
        alternative_motions(np.zeros((1, c, 2)), np.tile([0.0, 1.0], (1, c, 1)), np.zeros((1, c)), np.ones((1, c), bool),
                            np.zeros((1, c, 2)), COM, 1.0, np.zeros((1, 3)))


def test_a_pressed_finger_drags_a_lying_block_above_the_friction_ratio() -> None:
    """A block lying on a floor (mu_e 0.03), a finger on its top moving right (mu_g 0.6).
    Moved by position alone the finger may slide over it and leave it; pressed with a
    normal force f (weights), the block cannot stay once mu_g f > mu_e (1 + f), f > 0.0526,
    and the drag is the only motion; below that ratio the block staying balances too."""
    pts = [[[0.0, 0.0], [100.0, 0.0], [50.0, 20.0]]]
    nrm = [[[0.0, 1.0], [0.0, 1.0], [0.0, -1.0]]]
    mu = [[0.03, 0.03, 0.6]]
    w = [[[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]]]
    args = (pts, nrm, mu, [[True] * 3], w, [[50.0, 10.0]], 50.0, [[1.0, 0.0, 0.0]])
    assert alternative_motions(*args).ambiguous[0]
    threshold = 0.03 / (0.6 - 0.03)
    assert alternative_motions(*args, pressed=[[np.nan, np.nan, 0.9 * threshold]]).ambiguous[0]
    assert not alternative_motions(*args, pressed=[[np.nan, np.nan, 1.1 * threshold]]).ambiguous[0]
    assert not alternative_motions(*args, pressed=[[np.nan, np.nan, 2.0]]).ambiguous[0]


def test_a_block_on_its_corner_falls_back_away_from_its_top_and_onto_its_far_side() -> None:
    """An 100 x 70 block tilted 10 degrees counter-clockwise on its bottom-left corner
    (mu 0.5) falls back clockwise: its top face and left side move away from a finger
    there, its right side onto one (the block leans on a finger only there). Resting flat
    it does not fall at all."""
    from geometry.forward import falling_accelerations

    th = np.radians(10.0)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    com = R @ [50.0, 35.0]
    k2 = (100.0 ** 2 + 70.0 ** 2) / 12.0
    probes = {"top": ([50.0, 70.0], [0.0, -1.0]), "left": ([0.0, 35.0], [1.0, 0.0]),
              "right": ([100.0, 35.0], [-1.0, 0.0])}
    onto = {}
    for name, (p, n) in probes.items():
        falls, on = falling_accelerations([[[0.0, 0.0]]], [[[0.0, 1.0]]], [[0.5]], [[True]], [com], k2,
                                          [R @ p], [R @ n])
        assert falls[0]
        onto[name] = bool(on[0])
    assert onto == {"top": False, "left": False, "right": True}
    flat_falls, _ = falling_accelerations([[[0.0, 0.0], [100.0, 0.0]]], [[[0.0, 1.0], [0.0, 1.0]]], [[0.5, 0.5]],
                                          [[True, True]], [[50.0, 35.0]], k2, [[50.0, 70.0]], [[0.0, -1.0]])
    assert not flat_falls[0]


@pytest.mark.parametrize("scale", [0.1, 1.0, 10.0])
def test_a_tall_block_falling_back_about_a_sticking_corner_is_found_at_every_scale(scale: float) -> None:
    """The 70 x 150 block tilted 10 degrees clockwise on its bottom-right corner (mu 0.5)
    falls back with the corner sticking (it needs 0.32 of friction there). In mm its
    k^2 = 2283, and the determinant of that assignment's system, tested against the
    largest entry to the fifth power, looked singular: the fall went unseen, and a finger
    on the top was never found to be one the block falls away from. The answer cannot
    depend on the unit of length."""
    from geometry.forward import falling_accelerations, gyration_sq

    th = np.radians(-10.0)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    block = np.array([[0.0, 0.0], [70.0, 0.0], [70.0, 150.0], [0.0, 150.0]]) - [70.0, 0.0]
    com = R @ [-35.0, 75.0] * scale
    k2 = gyration_sq(block * scale, [-35.0 * scale, 75.0 * scale])
    assert k2 == pytest.approx((70.0 ** 2 + 150.0 ** 2) / 12.0 * scale ** 2)
    probes = {"top": ([-20.0, 150.0], [0.0, -1.0]), "left": ([-70.0, 20.0], [1.0, 0.0])}
    onto = {}
    for name, (p, n) in probes.items():
        falls, on = falling_accelerations([[[0.0, 0.0]]], [[[0.0, 1.0]]], [[0.5]], [[True]], [com], k2,
                                          [R @ p * scale], [R @ n])
        assert falls[0]
        onto[name] = bool(on[0])
    assert onto == {"top": False, "left": True}


def _falling_by_dense_solves(p, n, mu, live, com, k2, pp, pn, tol=1e-6):
    """The contact problem from rest of :func:`falling_accelerations`, each instance and
    mode assignment solved as the full square system (dynamics and kinematic rows) with
    numpy's LU solver: the reference its closed-form elimination is pinned to."""
    import itertools

    unit = np.sqrt(k2)
    falls = np.zeros(len(p), dtype=bool)
    onto = np.zeros(len(p), dtype=bool)
    for b in range(len(p)):
        idx = np.flatnonzero(live[b])
        d = (p[b, idx] - com[b]) / unit
        nn, mm = n[b, idx], mu[b, idx]
        tt = np.stack([-nn[:, 1], nn[:, 0]], axis=-1)
        for assign in itertools.product(range(4), repeat=idx.size):  # free, stick, slide +, slide -
            forces = [(j, u) for j, a in enumerate(assign) if a
                      for u in ([nn[j], tt[j]] if a == 1 else [nn[j] - (1.0 if a == 2 else -1.0) * mm[j] * tt[j]])]
            kin = [(j, e) for j, a in enumerate(assign) if a for e in ([nn[j], tt[j]] if a == 1 else [nn[j]])]
            size = 3 + len(forces)
            M = np.zeros((size, size))
            M[:3, :3] = np.eye(3)
            for c, (j, u) in enumerate(forces):
                M[:3, 3 + c] = -np.array([u[0], u[1], d[j, 0] * u[1] - d[j, 1] * u[0]])
            for r, (j, e) in enumerate(kin):
                M[3 + r, :3] = [e[0], e[1], d[j, 0] * e[1] - d[j, 1] * e[0]]
            if abs(np.linalg.det(M)) <= 1e-12 * np.abs(M).max() ** size:
                continue
            rhs = np.zeros(size)
            rhs[1] = -1.0
            x = np.linalg.solve(M, rhs)
            acc, f = x[:3], x[3:]

            def along(e, q):
                return (acc[0] - acc[2] * q[1]) * e[0] + (acc[1] + acc[2] * q[0]) * e[1]

            ok, c = True, 0
            for j, a in enumerate(assign):
                if a == 0:
                    ok &= along(nn[j], d[j]) >= -tol
                elif a == 1:
                    ok &= f[c] >= -tol and abs(f[c + 1]) <= mm[j] * f[c] + tol
                    c += 2
                else:
                    ok &= f[c] >= -tol and (1.0 if a == 2 else -1.0) * along(tt[j], d[j]) > tol
                    c += 1
            if ok and np.abs(acc).max() > tol:
                falls[b] = True
                onto[b] |= along(pn[b], (pp[b] - com[b]) / unit) < -tol
    return falls, onto


@pytest.mark.parametrize("count", [0, 1, 2, 3])
def test_the_fall_from_rest_is_the_dense_solves_answer(count: int) -> None:
    """The closed-form elimination of :func:`falling_accelerations` decides as solving
    every assignment's full system does, on random contacts (some on a floor, some
    absent, frictionless ones among them) and random probes."""
    from geometry.forward import falling_accelerations

    rng = np.random.default_rng(count)
    b = 150
    pts = rng.normal(0.0, 40.0, (b, max(count, 1), 2))
    ang = rng.uniform(0.0, 2.0 * np.pi, pts.shape[:2])
    nrm = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    pts[: b // 3, :, 1] = 0.0
    nrm[: b // 3] = [0.0, 1.0]
    mu = rng.choice([0.0, 0.2, 0.6], pts.shape[:2])
    live = rng.random(pts.shape[:2]) < (0.8 if count else 0.0)
    com = rng.normal(0.0, 30.0, (b, 2))
    k2 = 1500.0
    pp = rng.normal(0.0, 40.0, (b, 2))
    pa = rng.uniform(0.0, 2.0 * np.pi, b)
    pn = np.stack([np.cos(pa), np.sin(pa)], axis=-1)
    falls, onto = falling_accelerations(pts, nrm, mu, live, com, k2, pp, pn)
    ref_falls, ref_onto = _falling_by_dense_solves(pts, nrm, mu, live, com, k2, pp, pn)
    assert falls.tolist() == ref_falls.tolist()
    assert onto.tolist() == ref_onto.tolist()
    assert falls.any() and 0 < onto.sum() < b  # not a trivial answer
    assert count < 2 or not falls.all()


def test_a_fall_needs_a_positive_gyration() -> None:
    from geometry.errors import GeometryError
    from geometry.forward import falling_accelerations

    with pytest.raises(GeometryError, match="gyration_sq"):
        falling_accelerations([[[0.0, 0.0]]], [[[0.0, 1.0]]], [[0.5]], [[True]], [[0.0, 10.0]], 0.0,
                              [[0.0, 20.0]], [[0.0, -1.0]])


def _alternatives_by_dense_least_squares(p, n, mu, live, w, com, L, plan, tol_rel=1e-3, same=0.02):
    """:func:`alternative_motions` (no presses) one instance and assignment at a time:
    the kinematic equations by numpy's SVD and least squares, the balance by
    :func:`geometry.mechanics.feasible_batch`: the reference its batched closed form is
    pinned to."""
    import itertools

    out = np.zeros(len(p), dtype=bool)
    for b in range(len(p)):
        idx = np.flatnonzero(live[b])
        d = p[b, idx] - com[b]
        nn = n[b, idx]
        tt = np.stack([-nn[:, 1], nn[:, 0]], axis=-1)
        rn = np.column_stack([nn, d[:, 0] * nn[:, 1] - d[:, 1] * nn[:, 0]])
        rt = np.column_stack([tt, d[:, 0] * tt[:, 1] - d[:, 1] * tt[:, 0]])
        wn, wt = (w[b, idx] * nn).sum(1), (w[b, idx] * tt).sum(1)
        scale = max(np.abs(plan[b, :2]).max(), abs(plan[b, 2]) * L, np.linalg.norm(w[b], axis=-1).max())
        tol = max(tol_rel * scale, 1e-12)
        for assign in itertools.product(range(3), repeat=idx.size):  # free, stick, slide
            a = np.array(assign)
            A = np.vstack([rn[a > 0], rt[a == 1]])
            y = np.concatenate([wn[a > 0], wt[a == 1]])
            if len(A) < 3:
                continue
            sv = np.linalg.svd(A, compute_uv=False)
            if not sv[2] > 1e-6 * sv[0]:
                continue
            xi = np.linalg.lstsq(A, y, rcond=None)[0]
            r_n, r_t = rn @ xi - wn, rt @ xi - wt
            if (np.abs(A @ xi - y).max() > tol or (r_n < -tol).any() or (np.abs(r_t[a == 2]) <= tol).any()
                    or not (np.abs((xi - plan[b]) * [1.0, 1.0, L]) > same * scale).any()):
                continue
            modes = np.choose(a, [mechanics.ContactMode.SEPARATING, mechanics.ContactMode.STICKING,
                                  mechanics.ContactMode.SLIDING]).astype(np.int8)
            sdir = np.where((a == 2)[:, None], np.sign(r_t)[:, None] * tt, 0.0)
            contacts = mechanics.Contacts.trusted(p[b, idx][None], nn[None], mu[b, idx][None], modes[None], sdir[None])
            if mechanics.feasible_batch(contacts, com[b][None], L, margin=0.0)[0]:
                out[b] = True
                break
    return out


@pytest.mark.parametrize("count", [3, 4])
def test_the_other_motions_are_the_dense_least_squares_answer(count: int) -> None:
    """The batched closed-form least squares of :func:`alternative_motions` finds another
    motion exactly where solving every instance's every assignment with numpy's SVD and
    least squares does: a block on a floor (some contacts absent) pushed by a finger."""
    rng = np.random.default_rng(10 + count)
    b = 120
    pts = np.zeros((b, count, 2))
    nrm = np.zeros((b, count, 2))
    pts[:, :2, 0] = [0.0, 10.0]
    nrm[:, :2] = [0.0, 1.0]  # the floor under both corners
    h = rng.uniform(2.0, 20.0, (b, count - 2))
    pts[:, 2:, 1] = h
    nrm[:, 2:, 0] = 1.0  # fingers on the left side
    pts[:, 2:, 0] = 0.0
    live = np.ones((b, count), dtype=bool)
    live[rng.random(b) < 0.3, 1] = False
    mu = rng.choice([0.0, 0.3, 1.0], (b, count))
    w = np.zeros((b, count, 2))
    w[:, 2:, 0] = 1.0
    w[:, 2:, 1] = rng.uniform(-0.3, 0.3, (b, count - 2))
    com = np.broadcast_to(COM, (b, 2)).copy()
    plan = np.array([_tip_twist(float(x))[0] for x in h[:, 0]])
    got = alternative_motions(pts, nrm, mu, live, w, com, 22.0, plan).ambiguous
    want = _alternatives_by_dense_least_squares(pts, nrm, mu, live, w, com, 22.0, plan)
    assert got.tolist() == want.tolist()
    assert 0 < got.sum() < b


@pytest.mark.parametrize("b", [0, 2])
def test_no_contact_allows_no_other_motion_and_no_waypoint_is_fine(b: int) -> None:
    """Empty inputs: no contact column (nothing fixes a twist) or no waypoint."""
    for c in (0, 3):
        chk = alternative_motions(np.zeros((b, c, 2)), np.tile([0.0, 1.0], (b, c, 1)), np.zeros((b, c)),
                                  np.ones((b, c), bool), np.zeros((b, c, 2)), np.zeros((b, 2)), 10.0, np.zeros((b, 3)))
        assert chk.ambiguous.shape == (b,) and not chk.ambiguous.any()
        assert chk.twist.shape == (b, 3) and chk.modes.shape == (b, c)
