"""The quasi-static forward problem: which object motion a commanded gripper motion makes.

A plan commands the gripper's motion (position control); the object's motion follows
from contact mechanics. :func:`geometry.mechanics.feasible_batch` answers "do balancing
forces exist for the *planned* contact modes?"; that is necessary, not enough: the same
finger motion may let the object take *another* motion (a block tipped by one finger on
a slippery floor slides instead: both motions balance, and the one with the sliding
floor contact is what happens). This module enumerates the object motions consistent
with the commanded finger motion and decides whether any other than the planned one is
quasi-statically consistent.

Model (planar, rigid, quasi-static, Coulomb)
---------------------------------------------
Per waypoint, the contacts present: a point ``p``, a unit normal ``n`` into the object, a
coefficient ``mu`` and the velocity ``w`` of the *other* body's material point at ``p``
(zero for the environment; the finger's for a finger contact, from the commanded
gripper motion). The object's unknown twist ``xi = (v, omega)`` (about the COM) gives the
object's material velocity ``u(p) = v + omega J (p - com)``, ``J`` the quarter turn, and
the relative velocity ``r = u - w``. Each contact takes one mode:

- STICKING: ``r = 0`` (two equations); force anywhere in the cone;
- SLIDING: ``r . n = 0`` and ``r . t != 0`` (one equation); force on the cone edge
  opposing ``r``;
- SEPARATING (free): ``r . n >= 0``; no force.

A mode assignment whose equations fix the twist (rank 3) is *consistent* when the twist
it gives respects every contact's mode (no penetration, sliding really slides, the
equations hold: an over-determined assignment may be inconsistent) and the weight is
balanced with the modes' force sets (:func:`geometry.mechanics.feasible_batch`, closed
cones: margin 0, the permissive reading, so that an alternative that is only just
possible counts). A waypoint is **ambiguous** when a consistent assignment gives a twist
other than the planned one. Assignments that leave the twist undetermined (rank < 3:
e.g. a pinch slipping as a whole) are not enumerated: for two fingers that squeeze the
object the grip force decides slip, which the force limit (plan rule 9) and the friction
margin govern.

Everything is vectorised over waypoints; assignments are enumerated (3^C for C contacts
present, at most :data:`MAX_CONTACTS`).
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from geometry import mechanics
from geometry.errors import GeometryError
from geometry.poses import BoolArray, FloatArray, IntArray, wrap_angle
from geometry.shapes import polar_moment, signed_area

__all__ = ["MAX_CONTACTS", "ForwardCheck", "alternative_motions", "falling_accelerations", "gyration_sq",
           "screw_velocity"]

#: Contacts per waypoint the enumeration takes (3^6 = 729 assignments).
MAX_CONTACTS = 6

_FREE, _STICK, _SLIDE = 0, 1, 2
_SPLUS, _SMINUS = 2, 3  # falling_accelerations: sliding either way

#: An assignment fixes the twist when its equations' smallest singular value is at least
#: this fraction of the largest (nearer singular: a mechanism, not enumerated).
_RANK_TOL = 1e-6


@dataclass(frozen=True, eq=False)
class ForwardCheck:
    """The forward problem's answer per waypoint.

    Attributes
    ----------
    ambiguous : ndarray of bool, shape (B,)
        Another object motion than the planned one is quasi-statically consistent.
    twist : ndarray, shape (B, 3)
        For an ambiguous waypoint, one such motion (object twist about the COM, per unit
        of the commanded motion: mm and rad); zeros elsewhere.
    modes : ndarray of int8, shape (B, C)
        Its contact modes (:class:`~geometry.mechanics.ContactMode` codes).
    """

    ambiguous: BoolArray
    twist: FloatArray
    modes: NDArray[np.int8]


def screw_velocity(pose0: FloatArray, pose1: FloatArray, points: FloatArray) -> FloatArray:
    """Velocities (B, P, 2) of material points at ``points`` (world, at ``pose0``) under
    the displacement ``pose0 -> pose1`` (B, 3) taken as the screw it is: a turn ``d``
    about its fixed point ``c`` gives ``d J (p - c)`` (a point on the turn's centre does
    not move, as a round finger's centre in a pivot), a pure translation its shift."""
    d = wrap_angle(pose1[:, 2] - pose0[:, 2])
    ca, sa = np.cos(d), np.sin(d)
    # p' = R(d) (p - o0) + o1: the fixed point solves (I - R) c = o1 - R o0
    ro0 = np.stack([ca * pose0[:, 0] - sa * pose0[:, 1], sa * pose0[:, 0] + ca * pose0[:, 1]], axis=-1)
    t = pose1[:, :2] - ro0
    det = (1.0 - ca) ** 2 + sa ** 2
    turning = np.abs(d) > 1e-12
    safe = np.where(turning, det, 1.0)
    cx = ((1.0 - ca) * t[:, 0] - sa * t[:, 1]) / safe
    cy = (sa * t[:, 0] + (1.0 - ca) * t[:, 1]) / safe
    rel = points - np.stack([cx, cy], axis=-1)[:, None, :]
    screw = d[:, None, None] * np.stack([-rel[..., 1], rel[..., 0]], axis=-1)
    shift = np.broadcast_to((pose1[:, :2] - pose0[:, :2])[:, None, :], screw.shape)
    return np.where(turning[:, None, None], screw, shift)


def _rows(points: FloatArray, normals: FloatArray, com: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The rows giving ``r . n`` and ``r . t`` as ``row . xi`` (B, C, 3) each (without
    the other body's velocity)."""
    d = points - com[:, None, :]
    jd = np.stack([-d[..., 1], d[..., 0]], axis=-1)  # J (p - com)
    n = normals
    t = np.stack([-n[..., 1], n[..., 0]], axis=-1)
    rn = np.concatenate([n, (jd * n).sum(-1, keepdims=True)], axis=-1)
    rt = np.concatenate([t, (jd * t).sum(-1, keepdims=True)], axis=-1)
    return rn, rt


def alternative_motions(points: ArrayLike, normals: ArrayLike, mu: ArrayLike, present: ArrayLike,
                        other_velocity: ArrayLike, com: ArrayLike, length_scale: float,
                        planned_twist: ArrayLike, *, relative_tol: float = 1e-3,
                        same_tol: float = 0.02, pressed: ArrayLike | None = None,
                        press_group: ArrayLike | None = None) -> ForwardCheck:
    """Whether the commanded motion admits another consistent object motion.

    Parameters
    ----------
    points, normals : array_like, shape (B, C, 2)
        World contact points and unit normals into the object.
    mu : array_like, shape (B, C)
    present : array_like of bool, shape (B, C)
        Padding slots are False.
    other_velocity : array_like, shape (B, C, 2)
        Velocity of the other body's material point at each contact (mm per unit of
        the commanded motion): zero for the environment.
    com : array_like, shape (B, 2)
        World centre of mass.
    length_scale : float
        The object's ``L`` (mm): rotations compare to translations as ``omega * L``.
    planned_twist : array_like, shape (B, 3)
        The planned object twist ``(v_x, v_y, omega)`` about the COM.
    relative_tol : float
        Velocities below ``relative_tol`` times the motion's scale are zero.
    same_tol : float
        A twist within ``same_tol`` times the motion's scale of the planned one (per
        component, rotations times ``length_scale``) is the planned motion.
    pressed : array_like, shape (B, C), optional
        Per contact, the normal force a press holds it at, in units of the object's
        weight; ``nan`` (the default for all) for a contact that is not pressed. A
        pressed finger follows the object along its normal (the executor pressed it to
        that force and its compliance keeps it there): its contact takes no normal
        equation and never separates; STICKING adds ``r . t = 0``, SLIDING nothing; its
        force is ``pressed`` along ``n`` plus friction within the mode's cone.
    press_group : array_like of int, shape (B, C), optional
        Which pressed contacts belong to one finger (the same id, ``0 .. G-1``): the
        press holds their normal forces' *sum* at the (common) ``pressed`` value. By
        default each pressed contact is a finger of its own.

    Returns
    -------
    ForwardCheck

    Examples
    --------
    A block on a frictionless floor pushed sideways at its top by a finger that sticks to
    it: the planned tip about the bottom-right corner competes with sliding.

    >>> pts = [[[0.0, 0.0], [10.0, 0.0], [0.0, 20.0]]]
    >>> nrm = [[[0.0, 1.0], [0.0, 1.0], [1.0, 0.0]]]
    >>> w = [[[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]]]
    >>> chk = alternative_motions(pts, nrm, [[0.0, 0.0, 1.0]], [[True] * 3], w, [[5.0, 10.0]], 22.0,
    ...                           [[1.0, 0.5, -0.1]])
    >>> bool(chk.ambiguous[0])
    True
    """
    p = np.asarray(points, dtype=float)
    n = np.asarray(normals, dtype=float)
    if p.ndim != 3 or p.shape != n.shape or p.shape[-1] != 2:
        raise GeometryError(f"forward: points and normals must have shape (B, C, 2), got {p.shape}, {n.shape}")
    b, c = p.shape[:2]
    m = np.broadcast_to(np.asarray(mu, dtype=float), (b, c))
    live = np.broadcast_to(np.asarray(present, dtype=bool), (b, c))
    w = np.broadcast_to(np.asarray(other_velocity, dtype=float), (b, c, 2))
    cm = np.broadcast_to(np.asarray(com, dtype=float).reshape(-1, 2), (b, 2))
    plan = np.broadcast_to(np.asarray(planned_twist, dtype=float).reshape(-1, 3), (b, 3))
    press = np.full((b, c), np.nan) if pressed is None else np.broadcast_to(np.asarray(pressed, dtype=float), (b, c))
    grp_id = (np.broadcast_to(np.arange(c), (b, c)) if press_group is None
              else np.broadcast_to(np.asarray(press_group, dtype=np.int64), (b, c)))
    count = live.sum(axis=1)
    if (count > MAX_CONTACTS).any():
        raise GeometryError(f"forward: at most {MAX_CONTACTS} contacts per waypoint, got {int(count.max())}")
    if c == 0:  # no contact: no equation fixes a twist
        return ForwardCheck(np.zeros(b, dtype=bool), np.zeros((b, 3)), np.zeros((b, 0), dtype=np.int8))
    # contacts present first, padding after
    order = np.argsort(~live, axis=1, kind="stable")[:, :MAX_CONTACTS]
    k = min(c, MAX_CONTACTS)
    take = lambda a: np.take_along_axis(a, order[..., None] if a.ndim == 3 else order, axis=1)  # noqa: E731
    p, n, m, live, w, press, grp_id = take(p), take(n), take(m), take(live), take(w), take(press), take(grp_id)
    is_pressed = np.isfinite(press) & live
    rn, rt = _rows(p, n, cm)
    wn = (w * n).sum(-1)
    tvec = np.stack([-n[..., 1], n[..., 0]], axis=-1)
    wt = (w * tvec).sum(-1)
    L = float(length_scale)
    scale = np.maximum(np.abs(plan[:, :2]).max(axis=1), np.abs(plan[:, 2]) * L)
    scale = np.maximum(scale, np.linalg.norm(w, axis=-1).max(axis=1, initial=0.0))
    tol = np.maximum(relative_tol * scale, 1e-12)
    weights = np.array([1.0, 1.0, L])  # compare twists with the rotation in mm

    ambiguous = np.zeros(b, dtype=bool)
    found_twist = np.zeros((b, 3))
    found_modes = np.zeros((b, c), dtype=np.int8)
    # instances grouped by which (ordered) slots are pressed: the equations differ
    patterns, group = np.unique(is_pressed, axis=0, return_inverse=True)
    group = np.asarray(group).reshape(-1)

    def _record(hit: IntArray, twist: FloatArray, modes: NDArray[np.int8]) -> None:
        ambiguous[hit] = True
        found_twist[hit] = twist
        back = np.zeros((hit.size, c), dtype=np.int8)
        np.put_along_axis(back, order[hit], modes, axis=1)  # back to the caller's columns
        found_modes[hit] = back

    # per contact (first index) and instance, the rows giving r . n and r . t as
    # row . xi, as components; their outer products and products with the other
    # body's velocity: an assignment's normal equations are sums of them
    rows_n = [np.ascontiguousarray(rn[..., e].T) for e in range(3)]
    rows_t = [np.ascontiguousarray(rt[..., e].T) for e in range(3)]
    wn_c, wt_c = np.ascontiguousarray(wn.T), np.ascontiguousarray(wt.T)
    gram_n = {(e, f): rows_n[e] * rows_n[f] for e, f in _SYM}
    gram_t = {(e, f): rows_t[e] * rows_t[f] for e, f in _SYM}
    rhs_n = [rows_n[e] * wn_c for e in range(3)]
    rhs_t = [rows_t[e] * wt_c for e in range(3)]
    table = _assignments(k)  # every mode assignment, in enumeration order
    stick_all, slide_all = table == _STICK, table == _SLIDE
    for gi, pr in enumerate(patterns):
        # the assignments this press pattern takes: a pressed finger keeps touching, and
        # the equations (normal rows, pressed ones left out, and tangent rows of the
        # sticking contacts) are at least 3
        normal_all = (stick_all | slide_all) & ~pr[None, :]
        usable = ~(pr[None, :] & (table == _FREE)).any(axis=1)
        usable &= normal_all.sum(axis=1) + stick_all.sum(axis=1) >= 3
        a_ids = np.flatnonzero(usable)
        if not a_ids.size:
            continue
        stick, slide, normal_eq = stick_all[a_ids], slide_all[a_ids], normal_all[a_ids]
        sel_n, sel_t = normal_eq.astype(float), stick.astype(float)
        nonfree = table[a_ids] != _FREE
        found: list[tuple[IntArray, IntArray, FloatArray, FloatArray]] = []  # (assignment, instance, xi, r_t)
        members = np.flatnonzero(group == gi)
        per_chunk = max(1, _PAIRS_PER_CHUNK // a_ids.size)
        for lo_i in range(0, members.size, per_chunk):
            r = members[lo_i:lo_i + per_chunk]
            # least squares per (assignment, instance): the normal equations
            # A^T A xi = A^T y, sums over the assignment's rows, solved in closed form;
            # A must have rank 3, its smallest singular value at least _RANK_TOL of its
            # largest (the square roots of A^T A's eigenvalues)
            gram = {ef: sel_n @ gram_n[ef][:, r] + sel_t @ gram_t[ef][:, r] for ef in _SYM}
            h = [sel_n @ rhs_n[e][:, r] + sel_t @ rhs_t[e][:, r] for e in range(3)]
            lo, hi = _sym3_extreme_eigenvalues(gram)
            # padding slots must be FREE; instances with fewer contacts take the prefix
            ok = ~(nonfree[:, None, :] & ~live[r][None, :, :]).any(axis=2)
            ok &= lo > _RANK_TOL ** 2 * np.maximum(hi, 1e-300)
            if not ok.any():
                continue
            xi = _sym3_solve(gram, h)  # 3 x (assignments, instances)
            r_n = sum(rows_n[e][:, None, r] * xi[e][None] for e in range(3)) - wn_c[:, None, r]
            r_t = sum(rows_t[e][:, None, r] * xi[e][None] for e in range(3)) - wt_c[:, None, r]
            t0 = tol[r][None, None, :]
            resid = np.maximum(np.where(normal_eq.T[..., None], np.abs(r_n), 0.0).max(axis=0),
                               np.where(stick.T[..., None], np.abs(r_t), 0.0).max(axis=0))
            cons = ok & (resid <= t0[0])
            cons &= ~((r_n < -t0) & (live[r].T & ~pr[:, None])[:, None, :]).any(axis=0)  # nothing penetrates
            cons &= ~(slide.T[..., None] & (np.abs(r_t) <= t0)).any(axis=0)  # sliding slides
            differs = np.zeros_like(cons)
            for e in range(3):
                differs |= np.abs((xi[e] - plan[r, e][None]) * weights[e]) > same_tol * scale[r][None]
            cons &= differs
            ai, ii = np.nonzero(cons)
            if ai.size:
                found.append((ai, r[ii], np.stack([x[ai, ii] for x in xi], axis=-1), r_t[:, ai, ii].T))
        if not found:
            continue
        ai = np.concatenate([q[0] for q in found])
        idx = np.concatenate([q[1] for q in found])
        xi = np.concatenate([q[2] for q in found])
        r_t = np.concatenate([q[3] for q in found])
        at = np.lexsort((idx, ai))  # enumeration order: by assignment, then instance
        ai, idx, xi, r_t = ai[at], idx[at], xi[at], r_t[at]
        st, sl = stick[ai], slide[ai]
        modes = np.where(live[idx], np.where(st, mechanics.ContactMode.STICKING,
                                             np.where(sl, mechanics.ContactMode.SLIDING,
                                                      mechanics.ContactMode.SEPARATING)),
                         mechanics.ContactMode.ABSENT).astype(np.int8)
        sdir = np.where((sl & live[idx])[..., None], np.sign(r_t)[..., None] * tvec[idx], 0.0)
        contacts = mechanics.Contacts.trusted(p[idx], np.where(live[idx][..., None], n[idx], 0.0),
                                              np.where(live[idx], m[idx], 0.0), modes, sdir)
        if not pr.any():  # the balance of the assignment's force sets: closed cones
            feas = mechanics.feasible_batch(contacts, cm[idx], L, margin=0.0)
        elif int(pr.sum()) == 1:  # one pressed contact: exact cone tests
            slot = int(np.flatnonzero(pr)[0])
            feas = mechanics.pressed_feasible(contacts, cm[idx], L, np.full(idx.size, slot), press[idx, slot])
        else:  # one "finger" per press group, its force the group's pressed value: the LP
            gid = grp_id[idx]
            ids = np.unique(gid[:, pr])
            finger_of = np.where(pr[None, :], np.searchsorted(ids, gid), -1)
            held = np.full((idx.size, ids.size), np.nan)
            for j, g in enumerate(ids):
                top = np.where(pr[None, :] & (gid == g), press[idx], -np.inf).max(axis=1)
                held[:, j] = np.where(np.isfinite(top), top, np.nan)
            feas = mechanics.bounded_support(contacts, cm[idx], L, 1.0, finger_of, None, margin=0.0,
                                             fingers=ids.size, pressed=held).feasible
        # the first consistent alternative of each instance, in enumeration order
        first = np.zeros(idx.size, dtype=bool)
        _, at = np.unique(np.where(feas, idx, -1), return_index=True)
        first[at] = True
        keep = feas & first
        _record(idx[keep], xi[keep], modes[keep])
    return ForwardCheck(ambiguous, found_twist, found_modes)


#: (assignment, instance) pairs :func:`alternative_motions` evaluates at once.
_PAIRS_PER_CHUNK = 1 << 16


@functools.lru_cache(maxsize=None)
def _assignments(k: int) -> NDArray[np.int8]:
    """Every assignment of FREE, STICK, SLIDE to ``k`` contacts, (3^k, k), in
    :func:`itertools.product` order."""
    return np.array(list(itertools.product((_FREE, _STICK, _SLIDE), repeat=k)), dtype=np.int8).reshape(-1, k)


#: The upper triangle of a symmetric 3 x 3 matrix, as (row, column) pairs.
_SYM = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def _sym3_extreme_eigenvalues(g: dict[tuple[int, int], FloatArray]) -> tuple[FloatArray, FloatArray]:
    """The smallest and largest eigenvalues of symmetric 3 x 3 matrices (upper triangle
    ``g``, arrays over instances), by the trigonometric solution of the characteristic
    cubic (absolute error a few ulps of the largest)."""
    a, b, c, d, e, f = (g[ef] for ef in _SYM)  # [[a b c] [b d e] [c e f]]
    q = (a + d + f) / 3.0
    p1 = b * b + c * c + e * e
    a0, d0, f0 = a - q, d - q, f - q
    p = np.sqrt((a0 * a0 + d0 * d0 + f0 * f0 + 2.0 * p1) / 6.0)
    safe = np.where(p > 0.0, p, 1.0)
    # det((G - q I) / p) / 2, clipped to [-1, 1]
    det = (a0 * (d0 * f0 - e * e) - b * (b * f0 - e * c) + c * (b * e - d0 * c)) / (2.0 * safe ** 3)
    phi = np.arccos(np.clip(det, -1.0, 1.0)) / 3.0
    hi = np.where(p > 0.0, q + 2.0 * p * np.cos(phi), q)
    lo = np.where(p > 0.0, q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0), q)
    return lo, hi


def _sym3_solve(g: dict[tuple[int, int], FloatArray], h: list[FloatArray]) -> list[FloatArray]:
    """``x`` with ``G x = h`` for symmetric 3 x 3 matrices ``G`` (upper triangle ``g``,
    arrays over instances), by the adjugate; ``nan`` where ``G`` is singular."""
    a, b, c, d, e, f = (g[ef] for ef in _SYM)
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    safe = np.where(det != 0.0, det, np.nan)
    return [(c00 * h[0] + c01 * h[1] + c02 * h[2]) / safe,
            (c01 * h[0] + c11 * h[1] + c12 * h[2]) / safe,
            (c02 * h[0] + c12 * h[1] + c22 * h[2]) / safe]


def gyration_sq(vertices: ArrayLike, com: ArrayLike) -> float:
    """A uniform polygon's radius of gyration squared about ``com`` (mm^2): the
    ``gyration_sq`` :func:`falling_accelerations` takes.

    >>> round(gyration_sq([[0, 0], [80, 0], [80, 40], [0, 40]], [40, 20]), 6) == round((80 ** 2 + 40 ** 2) / 12, 6)
    True
    """
    v = np.asarray(vertices, dtype=float)
    return polar_moment(v, com) / abs(signed_area(v))


def falling_accelerations(points: ArrayLike, normals: ArrayLike, mu: ArrayLike, present: ArrayLike,
                          com: ArrayLike, gyration_sq: float, probe_points: ArrayLike, probe_normals: ArrayLike,
                          *, tol: float = 1e-6) -> tuple[BoolArray, BoolArray]:
    """Which way the object starts to move from rest when nothing but the environment
    holds it, and whether that motion presses it onto a probe contact.

    The rigid-body contact problem at one instant, from rest (no velocities): the object's
    acceleration ``a = (a_x, a_y, alpha)`` (gravity 1, mass 1, ``gyration_sq`` its radius of
    gyration squared about the COM, mm^2) and the environment contacts' forces (weights)
    satisfy ``a_lin = (0, -1) + sum F``, ``k^2 alpha = sum (p - com) x F``; each contact is
    STICKING (its point does not accelerate, force in the cone), SLIDING either way (no
    normal acceleration, force on the cone edge opposing the tangential acceleration, which
    it has) or SEPARATING (no force, no acceleration into the solid). Every assignment gives
    a square linear system; a consistent solution is one whose signs hold.

    Solved by elimination: lengths in units of the radius of gyration make the dynamics
    ``a = g + W f`` (``g = (0, -1, 0)``, ``W``'s columns the force directions' wrenches
    ``(u, d x u)``), and the ``m`` kinematic rows ``K a = 0`` (``K``'s rows ``(e, d x e)``
    for the constrained directions ``e``) leave ``(K W) f = -K g``, an ``m x m`` system
    (``m`` = twice the sticking contacts plus the sliding ones), solved in closed form. Its
    determinant is the whole system's (``det [[I, -W], [K, 0]] = det(K W)``), tested
    against the largest entry of the whole system to the power of its size, ``3 + m``.
    ``K W`` has rank at most 3: assignments with ``m > 3`` are singular and skipped.

    Parameters
    ----------
    points, normals : array_like, shape (B, C, 2)
        Environment contacts: points and unit normals into the object.
    mu : array_like, shape (B, C)
    present : array_like of bool, shape (B, C)
    com : array_like, shape (B, 2)
    gyration_sq : float
    probe_points, probe_normals : array_like, shape (B, 2)
        A finger contact (its normal into the object) the answer is about.

    Returns
    -------
    falls : ndarray of bool, shape (B,)
        Some consistent solution accelerates the object (it does not rest alone).
    onto_probe : ndarray of bool, shape (B,)
        Some consistent nonzero solution moves the object's material point at the probe
        against the probe's normal (onto the finger): the object leans on it.

    Examples
    --------
    A block balanced on its bottom-left corner, tilted 10 degrees counter-clockwise,
    falls back clockwise: away from a finger on its top face, onto one on its right side.

    >>> import math
    >>> c, s = math.cos(math.radians(10)), math.sin(math.radians(10))
    >>> com = [[c * 40 - s * 20, s * 40 + c * 20]]
    >>> top = [[c * 40 - s * 40, s * 40 + c * 40]]
    >>> falls, onto = falling_accelerations([[[0.0, 0.0]]], [[[0.0, 1.0]]], [[0.5]], [[True]], com,
    ...                                     (80 ** 2 + 40 ** 2) / 12, top, [[s, -c]])
    >>> bool(falls[0]), bool(onto[0])
    (True, False)
    """
    p = np.asarray(points, dtype=float)
    n = np.asarray(normals, dtype=float)
    b, c = p.shape[:2]
    if not gyration_sq > 0.0:
        raise GeometryError(f"forward: gyration_sq must be positive, got {gyration_sq}")
    m = np.broadcast_to(np.asarray(mu, dtype=float), (b, c))
    live = np.broadcast_to(np.asarray(present, dtype=bool), (b, c))
    cm = np.broadcast_to(np.asarray(com, dtype=float).reshape(-1, 2), (b, 2))
    pp = np.broadcast_to(np.asarray(probe_points, dtype=float).reshape(-1, 2), (b, 2))
    pn = np.broadcast_to(np.asarray(probe_normals, dtype=float).reshape(-1, 2), (b, 2))
    if (live[:, :-1] < live[:, 1:]).any():  # the contacts present first
        order = np.argsort(~live, axis=1, kind="stable")
        tk = lambda a: np.take_along_axis(a, order[..., None] if a.ndim == 3 else order, axis=1)  # noqa: E731
        p, n, m, live = tk(p), tk(n), tk(m), tk(live)
    # lengths in units of the radius of gyration (alpha then in 1 / that unit): the
    # systems are dimensionless, so the determinant test below is scale-free (in mm, a
    # 70 x 150 block's k^2 = 2283 made a well-posed sticking pivot look singular)
    unit = math.sqrt(float(gyration_sq))
    d = (p - cm[:, None, :]) / unit
    dp = (pp - cm) / unit
    falls = np.zeros(b, dtype=bool)
    onto = np.zeros(b, dtype=bool)
    count = live.sum(axis=1)
    for kk in np.unique(count):
        rows = np.flatnonzero(count == kk)
        kk = int(kk)
        # per contact (first index) and instance, components as contiguous arrays
        dx, dy = (np.ascontiguousarray(d[rows, :kk, e].T) for e in (0, 1))
        nx, ny = (np.ascontiguousarray(n[rows, :kk, e].T) for e in (0, 1))
        mm = np.ascontiguousarray(m[rows, :kk].T)

        # the rows (e, d x e) of K, normal and tangent (a point's acceleration along e is
        # that row times a); the columns (u, d x u) of W: the normal and the tangent
        # (sticking), the cone edges n -/+ mu t (sliding +/-); t = (-n_y, n_x)
        def wrench(ux: FloatArray, uy: FloatArray) -> _Vec:
            return ux, uy, dx * uy - dy * ux

        k_n, k_t = wrench(nx, ny), wrench(-ny, nx)
        w_edge = {_SPLUS: wrench(nx + mm * ny, ny - mm * nx), _SMINUS: wrench(nx - mm * ny, ny + mm * nx)}

        def largest(v: _Vec) -> FloatArray:
            return np.maximum(np.maximum(np.abs(v[0]), np.abs(v[1])), np.abs(v[2]))

        big_kn = largest(k_n)  # (kk, r): the rows' and columns' largest entries
        big_k = np.maximum(big_kn, largest(k_t))
        big_w = {sense: largest(w) for sense, w in w_edge.items()}
        dpx, dpy, pnx, pny = dp[rows, 0], dp[rows, 1], pn[rows, 0], pn[rows, 1]
        for assign in itertools.product((_FREE, _STICK, _SPLUS, _SMINUS), repeat=kk):
            mcount = sum(2 if mode == _STICK else 1 for mode in assign if mode != _FREE)
            if mcount > 3:  # rank(K W) <= rank(K) <= 3: singular
                continue
            todo = ~onto[rows]  # an instance found leaning on its probe is decided
            if not todo.any():
                break
            K: list[_Vec] = []
            W: list[_Vec] = []
            big = np.ones(rows.size)  # the largest entry of the whole system
            for j, mode in enumerate(assign):
                if mode == _STICK:
                    K += [_at(k_n, j), _at(k_t, j)]
                    W += [_at(k_n, j), _at(k_t, j)]
                    big = np.maximum(big, big_k[j])
                elif mode != _FREE:
                    K.append(_at(k_n, j))
                    W.append(_at(w_edge[mode], j))
                    big = np.maximum(big, np.maximum(big_kn[j], big_w[mode][j]))
            f, det = _solve_small(K, W, rows.size)
            ok = todo & (np.abs(det) > 1e-12 * np.maximum(big ** (3 + mcount), 1e-300))
            ax, ay, al = np.zeros(rows.size), np.full(rows.size, -1.0), np.zeros(rows.size)
            for fc, w in zip(f, W):
                ax = ax + fc * w[0]
                ay = ay + fc * w[1]
                al = al + fc * w[2]
            acc = (ax, ay, al)
            col = 0
            for j, mode in enumerate(assign):
                if mode == _FREE:
                    ok &= _dot(acc, _at(k_n, j)) >= -tol
                elif mode == _STICK:
                    fn_, ft_ = f[col], f[col + 1]
                    ok &= (fn_ >= -tol) & (np.abs(ft_) <= mm[j] * fn_ + tol)
                    col += 2
                else:
                    sgn = 1.0 if mode == _SPLUS else -1.0
                    ok &= (f[col] >= -tol) & (sgn * _dot(acc, _at(k_t, j)) > tol)
                    col += 1
            good = ok & (np.maximum(np.maximum(np.abs(ax), np.abs(ay)), np.abs(al)) > tol)
            if not good.any():
                continue
            falls[rows[good]] = True
            # the probe's material point: a_lin + alpha J dp
            into = (ax - al * dpy) * pnx + (ay + al * dpx) * pny
            onto[rows[good & (into < -tol)]] = True
    return falls, onto


#: A 3-vector per instance, as its three components.
_Vec = tuple[FloatArray, FloatArray, FloatArray]


def _at(v: _Vec, j: int) -> _Vec:
    return v[0][j], v[1][j], v[2][j]


def _dot(u: _Vec, v: _Vec) -> FloatArray:
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


def _solve_small(K: list[_Vec], W: list[_Vec], r: int) -> tuple[list[FloatArray], FloatArray]:
    """Per instance (``r`` of them), ``f`` solving ``(K W) f = -K g`` (``g = (0, -1, 0)``)
    and ``det(K W)``, in closed form, for ``m = len(K) = len(W)`` of 0 to 3 (rows of K and
    columns of W as 3-vectors of (r,) arrays). ``f`` (``m`` arrays) is ``nan`` where the
    determinant is 0."""
    mcount = len(K)
    if mcount == 0:
        return [], np.ones(r)
    S = [[_dot(K[i], W[j]) for j in range(mcount)] for i in range(mcount)]
    rhs = [K[i][1] for i in range(mcount)]  # -K g
    if mcount == 1:
        det = S[0][0]
        inv = [[np.ones(r)]]
    elif mcount == 2:
        det = S[0][0] * S[1][1] - S[0][1] * S[1][0]
        inv = [[S[1][1], -S[0][1]], [-S[1][0], S[0][0]]]
    else:  # the adjugate: cofactors of the transposed matrix
        def cof(i: int, j: int) -> FloatArray:
            a, b = [x for x in range(3) if x != i], [y for y in range(3) if y != j]
            return (-1.0) ** (i + j) * (S[a[0]][b[0]] * S[a[1]][b[1]] - S[a[0]][b[1]] * S[a[1]][b[0]])

        inv = [[cof(j, i) for j in range(3)] for i in range(3)]
        det = S[0][0] * inv[0][0] + S[0][1] * inv[1][0] + S[0][2] * inv[2][0]
    safe = np.where(det != 0.0, det, np.nan)
    return [sum(inv[i][j] * rhs[j] for j in range(mcount)) / safe for i in range(mcount)], det
