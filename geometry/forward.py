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

    for gi, pr in enumerate(patterns):
        in_group = group == gi
        pending: list[tuple[IntArray, FloatArray, NDArray[np.int8], FloatArray]] = []
        for assign in itertools.product((_FREE, _STICK, _SLIDE), repeat=k):
            a = np.asarray(assign, dtype=np.int8)
            if (pr & (a == _FREE)).any():  # a pressed finger keeps touching
                continue
            # padding slots must be FREE; instances with fewer contacts take the prefix
            valid = in_group & ~((a[None, :] != _FREE) & ~live).any(axis=1) & ~ambiguous
            stick, slide = a == _STICK, a == _SLIDE
            normal_eq = (stick | slide) & ~pr
            n_eq = int(normal_eq.sum()) + int(stick.sum())
            if n_eq < 3 or not valid.any():
                continue
            idx = np.flatnonzero(valid)
            A = np.concatenate([rn[idx][:, normal_eq], rt[idx][:, stick]], axis=1)  # (b', n_eq, 3)
            y = np.concatenate([wn[idx][:, normal_eq], wt[idx][:, stick]], axis=1)
            # least squares per instance; rank must be 3
            sv = np.linalg.svd(A, compute_uv=False)
            ok = sv[:, 2] > _RANK_TOL * np.maximum(sv[:, 0], 1e-300)
            if not ok.any():
                continue
            idx, A, y = idx[ok], A[ok], y[ok]
            xi = np.linalg.solve(np.einsum("bki,bkj->bij", A, A), np.einsum("bki,bk->bi", A, y)[..., None])[..., 0]
            resid = np.abs(np.einsum("bki,bi->bk", A, xi) - y).max(axis=1)
            t0 = tol[idx]
            r_n = np.einsum("bci,bi->bc", rn[idx], xi) - wn[idx]
            r_t = np.einsum("bci,bi->bc", rt[idx], xi) - wt[idx]
            lv = live[idx]
            cons = resid <= t0
            cons &= ~((r_n < -t0[:, None]) & lv & ~pr[None, :]).any(axis=1)  # nothing penetrates
            cons &= ~(slide[None, :] & (np.abs(r_t) <= t0[:, None])).any(axis=1)  # sliding slides
            differs = (np.abs((xi - plan[idx]) * weights) > same_tol * scale[idx, None]).any(axis=1)
            cons &= differs
            if not cons.any():
                continue
            idx, xi, r_t = idx[cons], xi[cons], r_t[cons]
            modes = np.where(live[idx], np.where(stick, mechanics.ContactMode.STICKING,
                                                 np.where(slide, mechanics.ContactMode.SLIDING,
                                                          mechanics.ContactMode.SEPARATING)),
                             mechanics.ContactMode.ABSENT).astype(np.int8)
            sdir = np.where((slide[None, :] & live[idx])[..., None], np.sign(r_t)[..., None] * tvec[idx], 0.0)
            if pr.any():  # the force LPs of all the group's assignments in one call, after the loop
                pending.append((idx, xi, modes, sdir))
                continue
            contacts = mechanics.Contacts.trusted(p[idx], np.where(live[idx][..., None], n[idx], 0.0),
                                                  np.where(live[idx], m[idx], 0.0), modes, sdir)
            feas = mechanics.feasible_batch(contacts, cm[idx], L, margin=0.0)
            _record(idx[feas], xi[feas], modes[feas])
        if pending:
            idx = np.concatenate([q[0] for q in pending])
            xi = np.concatenate([q[1] for q in pending])
            modes = np.concatenate([q[2] for q in pending])
            sdir = np.concatenate([q[3] for q in pending])
            contacts = mechanics.Contacts.trusted(p[idx], np.where(live[idx][..., None], n[idx], 0.0),
                                                  np.where(live[idx], m[idx], 0.0), modes, sdir)
            if int(pr.sum()) == 1:  # one pressed contact: exact cone tests
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
