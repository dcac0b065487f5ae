"""Primitive kinematics: the one-parameter pose families of the MoveObject primitives.

Each MoveObject primitive moves the object along a one-parameter family of poses
``T(s)``, ``s >= 0``, that keeps its defining contacts (paper, Table I):

- ``tip``: rotation about a fixed world pivot (an object vertex sticking on an
  environment edge, or a convex environment vertex sticking on an object edge);
  ``s`` is the rotation angle (radians) in the chosen sense.
  ``T(s) = Rot_P(sense * s) * T0``.
- ``push``: translation along an environment edge's tangent (the contact with that edge
  is kept); ``s`` is the travel in mm. ``T(s) = T0 + s d``.
- ``biplanar-slide``: the object keeps two point contacts on two environment features
  while it rotates (corner guidance); ``s`` is the orientation change (radians) in the
  chosen sense. For each orientation, every kept contact is one linear equation in the
  translation ``t`` (see :func:`contact_line`), solved as a 2x2 system.
- ``air-move`` chains :func:`translate` (free-space straight lines) and
  :func:`rotate_about` the object's centre of mass (turns in the air).

:func:`sweep` walks a motion with a small step, identifies the contact state at every
sample and cuts the walk into pieces of constant state, stopping where the object would
penetrate the environment or a kept contact would leave its finite feature. The piece
boundaries are refined by bisection so that a new contact is made exactly.
"""

from __future__ import annotations

import enum
import math
import weakref
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from geometry.features import Contact, ContactKind, ContactState
from geometry.poses import FloatArray, Pose, wrap_angle
from geometry.tolerances import CONTACT_TOL, EPS, SWEEP_TOL
from geometry.world import World



class MotionKind(enum.Enum):
    ROTATE = "rotate"  # tip: rotation about a fixed world point
    TRANSLATE = "translate"  # push and air-move: straight-line translation
    TWO_CONTACT = "two-contact"  # biplanar-slide: rotation keeping two contacts


@dataclass(frozen=True)
class Motion:
    """A one-parameter family of object poses starting at ``start`` (``s = 0``).

    Build with :func:`rotate_about`, :func:`translate` or :func:`two_contact`.
    """

    kind: MotionKind
    start: Pose
    sense: int = 1
    pivot: tuple[float, float] | None = None  # ROTATE
    direction: tuple[float, float] | None = None  # TRANSLATE (unit)
    kept: tuple[Contact, ...] = ()  # contacts the motion keeps (TWO_CONTACT: exactly 2)
    lines: tuple[tuple[float, float, float, float, float, float], ...] = ()  # TWO_CONTACT

    def poses(self, s: Sequence[float] | FloatArray) -> FloatArray:
        """Poses (n, 3) at the parameter values ``s`` (NaN rows where undefined)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        x0, y0, t0 = self.start.x, self.start.y, self.start.theta
        out = np.empty((s.size, 3))
        if self.kind is MotionKind.TRANSLATE:
            dx, dy = self.direction  # type: ignore[misc]
            out[:, 0] = x0 + s * dx
            out[:, 1] = y0 + s * dy
            out[:, 2] = t0
        elif self.kind is MotionKind.ROTATE:
            px, py = self.pivot  # type: ignore[misc]
            a = self.sense * s
            c, sn = np.cos(a), np.sin(a)
            out[:, 0] = px + c * (x0 - px) - sn * (y0 - py)
            out[:, 1] = py + sn * (x0 - px) + c * (y0 - py)
            out[:, 2] = wrap_angle(t0 + a)
        else:
            theta = t0 + self.sense * s
            out[:, 2] = wrap_angle(theta)
            out[:, :2] = _solve_two_lines(self.lines, theta)
        return out

    def pose(self, s: float) -> Pose:
        return Pose.from_array(self.poses([s])[0])

    def positions_at(self, theta: Sequence[float] | FloatArray) -> FloatArray:
        """TWO_CONTACT: the translations (n, 2) that keep both contacts at orientations
        ``theta`` (NaN where the lines are parallel), whatever the start."""
        if self.kind is not MotionKind.TWO_CONTACT:
            raise ValueError("positions_at: only a two-contact motion is solved for its orientation")
        return _solve_two_lines(self.lines, np.atleast_1d(np.asarray(theta, dtype=float)))

    def vertex_speed(self, world: World) -> float:
        """Upper bound of how far (mm) any object vertex moves per unit of ``s``."""
        verts = world.object_vertices(self.start)
        if self.kind is MotionKind.TRANSLATE:
            return 1.0
        if self.kind is MotionKind.ROTATE:
            return float(np.max(np.linalg.norm(verts - np.asarray(self.pivot), axis=1)))
        # two-contact: finite-difference estimate, with margin
        h = 1e-4
        p = self.poses([0.0, h])
        if np.any(~np.isfinite(p)):
            return world.object.polygon.radius * 4.0
        v1 = world.object.polygon.transformed(*p[1])
        return 2.0 * float(np.max(np.linalg.norm(v1 - verts, axis=1))) / h + 1.0


def rotate_about(start: Pose, pivot: Sequence[float], sense: int) -> Motion:
    """Rotation about a world point; ``sense`` +1 counter-clockwise, -1 clockwise."""
    return Motion(MotionKind.ROTATE, start, int(np.sign(sense)), pivot=(float(pivot[0]), float(pivot[1])))


def translate(start: Pose, direction: Sequence[float], kept: Sequence[Contact] = ()) -> Motion:
    """Straight-line translation along a (normalised) direction, optionally keeping point
    contacts (a push keeps the vertices that slide on its edge)."""
    d = np.asarray(direction, dtype=float)
    n = float(np.linalg.norm(d))
    if n <= EPS:
        raise ValueError("translation direction must be non-zero")
    return Motion(MotionKind.TRANSLATE, start, 1, direction=(float(d[0] / n), float(d[1] / n)), kept=tuple(kept))


def contact_line(world: World, contact: Contact) -> tuple[float, float, float, float, float, float]:
    """The kept contact as a constraint linear in the translation, for any orientation.

    Returns ``(kind, a, b, c, d, e)`` with the meaning:

    - vertex-edge (object vertex ``p`` (object frame) on the line of environment edge
      with outward normal ``n`` through point ``q``): ``n . (R(theta) p + t) = n . q``;
      encoded as kind 0, ``(p_x, p_y, n_x, n_y, n . q)``.
    - edge-vertex (environment vertex ``q`` on the line of object edge with outward
      normal ``m`` (object frame) through object point ``a``):
      ``(R(theta) m) . (q - t) = m . a``; encoded as kind 1, ``(m_x, m_y, q_x, q_y, m . a)``.
    """
    obj = world.object.polygon
    env = world.environment
    if contact.kind is ContactKind.VERTEX_EDGE:
        p = obj.vertices[contact.obj]
        n = env.normals[contact.env]
        q = env.edges[contact.env][0]
        return (0.0, float(p[0]), float(p[1]), float(n[0]), float(n[1]), float(n @ q))
    if contact.kind is ContactKind.EDGE_VERTEX:
        m = obj.normals[contact.obj]
        a = obj.vertices[contact.obj]
        q = env.vertices[contact.env]
        return (1.0, float(m[0]), float(m[1]), float(q[0]), float(q[1]), float(m @ a))
    raise ValueError(f"an edge-edge contact fixes the orientation; keep one of its vertices instead: {contact.name}")


def _solve_two_lines(lines, theta: FloatArray) -> FloatArray:
    """Translations (n, 2) satisfying both contact lines at orientations ``theta``."""
    theta = np.asarray(theta, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    A = np.empty(theta.shape + (2, 2))
    b = np.empty(theta.shape + (2,))
    for row, (kind, u0, u1, w0, w1, k) in enumerate(lines):
        if kind == 0.0:
            # n . (R p + t) = k  ->  n . t = k - n . (R p)
            rpx = c * u0 - s * u1
            rpy = s * u0 + c * u1
            A[..., row, 0] = w0
            A[..., row, 1] = w1
            b[..., row] = k - (w0 * rpx + w1 * rpy)
        else:
            # (R m) . (q - t) = k  ->  (R m) . t = (R m) . q - k
            rmx = c * u0 - s * u1
            rmy = s * u0 + c * u1
            A[..., row, 0] = rmx
            A[..., row, 1] = rmy
            b[..., row] = rmx * w0 + rmy * w1 - k
    return _solve_2x2(A, b)


def two_contact(world: World, start: Pose, kept: tuple[Contact, Contact], sense: int) -> Motion:
    """Rotation by ``sense`` keeping two point contacts (vertex-edge or edge-vertex).

    The start pose must satisfy both contacts; the two constraint lines must not be
    parallel at the start orientation (otherwise the motion is not a slide on two
    features but a translation, see :func:`translate`).
    """
    lines = tuple(contact_line(world, c) for c in kept)
    m = Motion(MotionKind.TWO_CONTACT, start, int(np.sign(sense)), kept=tuple(kept), lines=lines)
    p0 = m.poses([0.0])[0]
    if not np.all(np.isfinite(p0)):
        raise ValueError("the two kept contacts are parallel: no biplanar motion")
    return m


def _poses_many(motions: Sequence[Motion], params: Sequence[Sequence[float] | FloatArray]) -> list[FloatArray]:
    """``[m.poses(s) for m, s in zip(motions, params)]``, each kind of motion in one
    vectorised computation: :meth:`Motion.poses`' formulas with each row's motion's
    numbers (elementwise, so the same numbers)."""
    s_each = [np.atleast_1d(np.asarray(x, dtype=float)).ravel() for x in params]
    sizes = [x.size for x in s_each]
    if not s_each:
        return []
    s = np.concatenate(s_each)
    out = np.empty((s.size, 3))
    owner = np.repeat(np.arange(len(motions)), sizes)
    code = {MotionKind.TRANSLATE: 0, MotionKind.ROTATE: 1, MotionKind.TWO_CONTACT: 2}
    kind = np.array([code[m.kind] for m in motions], dtype=np.int64)[owner]
    x0 = np.array([m.start.x for m in motions], dtype=float)
    y0 = np.array([m.start.y for m in motions], dtype=float)
    t0 = np.array([m.start.theta for m in motions], dtype=float)
    sense = np.array([m.sense for m in motions], dtype=float)
    rows = np.flatnonzero(kind == 0)
    if rows.size:
        o, sr = owner[rows], s[rows]
        d = np.array([m.direction if m.kind is MotionKind.TRANSLATE else (0.0, 0.0) for m in motions], dtype=float)
        out[rows, 0] = x0[o] + sr * d[o, 0]
        out[rows, 1] = y0[o] + sr * d[o, 1]
        out[rows, 2] = t0[o]
    rows = np.flatnonzero(kind == 1)
    if rows.size:
        o, sr = owner[rows], s[rows]
        pv = np.array([m.pivot if m.kind is MotionKind.ROTATE else (0.0, 0.0) for m in motions], dtype=float)
        px, py = pv[o, 0], pv[o, 1]
        a = sense[o] * sr
        c, sn = np.cos(a), np.sin(a)
        out[rows, 0] = px + c * (x0[o] - px) - sn * (y0[o] - py)
        out[rows, 1] = py + sn * (x0[o] - px) + c * (y0[o] - py)
        out[rows, 2] = wrap_angle(t0[o] + a)
    rows = np.flatnonzero(kind == 2)
    if rows.size:
        o, sr = owner[rows], s[rows]
        lines = np.array([m.lines if m.kind is MotionKind.TWO_CONTACT else ((0.0,) * 6,) * 2 for m in motions],
                         dtype=float)  # (motions, 2, 6)
        theta = t0[o] + sense[o] * sr
        out[rows, 2] = wrap_angle(theta)
        out[rows, :2] = _solve_line_rows(lines[o], theta)
    return np.split(out, np.cumsum(sizes)[:-1])


def _solve_2x2(A: FloatArray, b: FloatArray) -> FloatArray:
    """``t`` with ``A t = b`` for stacked 2 x 2 systems (..., 2, 2), by Cramer's rule;
    ``nan`` where ``|det A| <= 1e-9`` (parallel contact lines)."""
    det = A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
    ok = np.abs(det) > 1e-9
    safe = np.where(ok, det, 1.0)
    tx = (b[..., 0] * A[..., 1, 1] - b[..., 1] * A[..., 0, 1]) / safe
    ty = (A[..., 0, 0] * b[..., 1] - A[..., 1, 0] * b[..., 0]) / safe
    out = np.stack([tx, ty], axis=-1)
    out[~ok] = np.nan
    return out


def _solve_line_rows(lines: FloatArray, theta: FloatArray) -> FloatArray:
    """:func:`_solve_two_lines` with each row's own two lines, (n, 2, 6)."""
    c, s = np.cos(theta), np.sin(theta)
    A = np.empty(theta.shape + (2, 2))
    b = np.empty(theta.shape + (2,))
    for row in range(2):
        kind, u0, u1, w0, w1, k = lines[:, row].T
        edge = kind == 0.0
        rx = c * u0 - s * u1  # R p (vertex-edge) or R m (edge-vertex)
        ry = s * u0 + c * u1
        A[:, row, 0] = np.where(edge, w0, rx)
        A[:, row, 1] = np.where(edge, w1, ry)
        b[:, row] = np.where(edge, k - (w0 * rx + w1 * ry), rx * w0 + ry * w1 - k)
    return _solve_2x2(A, b)


# --------------------------------------------------------------------------- sweeps


class SweepEnd(enum.Enum):
    """Why a sweep stopped."""

    BLOCKED = "blocked"  # the next step would penetrate the environment
    CONTACT_LOST = "contact-lost"  # a kept contact would leave its finite feature
    LIMIT = "limit"  # the parameter range was exhausted
    DEGENERATE = "degenerate"  # the motion is undefined further on (two-contact singularity)


@dataclass(frozen=True)
class SweepPiece:
    """A parameter interval ``[s0, s1]`` over which the contact state is constant."""

    state: ContactState
    s0: float
    s1: float


@dataclass(frozen=True)
class Sweep:
    """The contact states met along a motion, in order, and why the walk ended."""

    motion: Motion
    pieces: tuple[SweepPiece, ...]
    end: SweepEnd

    @property
    def states(self) -> tuple[ContactState, ...]:
        return tuple(p.state for p in self.pieces)

    @property
    def s_end(self) -> float:
        return self.pieces[-1].s1 if self.pieces else 0.0


OverlapFn = Callable[[World, FloatArray], NDArray[np.bool_]]


def _default_overlap(world: World, poses: FloatArray) -> NDArray[np.bool_]:
    from geometry.collision import object_env_overlap

    return object_env_overlap(world, poses, tol=SWEEP_TOL)


def _state_rows(world: World, poses: FloatArray, tol: float) -> tuple[NDArray[np.uint8], object]:
    """The packed principal-contact masks of each pose, (n, bytes), and the masks: equal
    rows, equal states."""
    from geometry.contacts import principal_contact_masks

    m = principal_contact_masks(world, poses, tol)
    flat = np.concatenate(
        [m.vertex_edge.reshape(len(poses), -1), m.edge_vertex.reshape(len(poses), -1),
         m.edge_edge.reshape(len(poses), -1)], axis=1)
    return np.packbits(flat, axis=1), m


def kept_contact_holds(world: World, contact: Contact, poses: FloatArray, tol: float = CONTACT_TOL) -> NDArray[np.bool_]:
    """Whether a kept point contact is still on its *finite* features at each pose.

    For a vertex-edge contact the object vertex must project inside the environment edge;
    for an edge-vertex contact the environment vertex must project inside the object edge.
    (The motion keeps the contact on the feature's line by construction.)
    """
    P = np.asarray(poses, dtype=float).reshape(-1, 3)
    obj = world.object.polygon
    env = world.environment
    c, s = np.cos(P[:, 2]), np.sin(P[:, 2])
    if contact.kind is ContactKind.VERTEX_EDGE:
        v = obj.vertices[contact.obj]
        wx = c * v[0] - s * v[1] + P[:, 0]
        wy = s * v[0] + c * v[1] + P[:, 1]
        a, b = env.edges[contact.env]
        d = b - a
        L = float(np.hypot(*d))
        u = ((wx - a[0]) * d[0] + (wy - a[1]) * d[1]) / L
        return (u >= -tol) & (u <= L + tol)
    if contact.kind is ContactKind.EDGE_VERTEX:
        q = env.vertices[contact.env]
        a, b = obj.edges[contact.obj]
        # environment vertex in the object frame
        dx, dy = q[0] - P[:, 0], q[1] - P[:, 1]
        qx = c * dx + s * dy
        qy = -s * dx + c * dy
        d = b - a
        L = float(np.hypot(*d))
        u = ((qx - a[0]) * d[0] + (qy - a[1]) * d[1]) / L
        return (u >= -tol) & (u <= L + tol)
    raise ValueError("edge-edge contacts are kept through one of their vertex contacts")


def _kept_params(world: World, contact: Contact) -> tuple[float, ...]:
    """The numbers :func:`kept_contact_holds` tests a contact by: ``(kind, point x, y,
    edge start x, y, edge vector x, y, edge length)``, kind 0 for vertex-edge (object
    vertex, environment edge), 1 for edge-vertex (environment vertex, object edge)."""
    if contact.kind is ContactKind.VERTEX_EDGE:
        p = world.object.polygon.vertices[contact.obj]
        a, b = world.environment.edges[contact.env]
        kind = 0.0
    elif contact.kind is ContactKind.EDGE_VERTEX:
        p = world.environment.vertices[contact.env]
        a, b = world.object.polygon.edges[contact.obj]
        kind = 1.0
    else:
        raise ValueError("edge-edge contacts are kept through one of their vertex contacts")
    d = b - a
    return (kind, float(p[0]), float(p[1]), float(a[0]), float(a[1]), float(d[0]), float(d[1]), float(np.hypot(*d)))


def _kept_hold_rows(world: World, kept: Sequence[Sequence[Contact]], sizes: Sequence[int], poses: FloatArray,
                    tol: float = CONTACT_TOL) -> NDArray[np.bool_]:
    """:func:`kept_contact_holds` of several motions' contacts in one computation: the
    poses are ``sizes[i]`` consecutive rows per motion ``i``, whose contacts are
    ``kept[i]``; a row is True when all its motion's contacts hold (the same numbers as
    one call per contact)."""
    P = np.asarray(poses, dtype=float).reshape(-1, 3)
    out = np.ones(P.shape[0], dtype=bool)
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    for q in range(max((len(k) for k in kept), default=0)):
        sel = [i for i, k in enumerate(kept) if len(k) > q and sizes[i]]
        if not sel:
            continue
        rows = np.concatenate([np.arange(starts[i], starts[i + 1]) for i in sel])
        par = np.repeat(np.array([_kept_params(world, kept[i][q]) for i in sel]), [sizes[i] for i in sel], axis=0)
        Q = P[rows]
        c, s = np.cos(Q[:, 2]), np.sin(Q[:, 2])
        kind, p0, p1, a0, a1, d0, d1, L = par.T
        ve = kind == 0.0
        u = np.empty(rows.size)
        # vertex-edge: the object vertex, placed, projected on the environment edge
        wx = c[ve] * p0[ve] - s[ve] * p1[ve] + Q[ve, 0]
        wy = s[ve] * p0[ve] + c[ve] * p1[ve] + Q[ve, 1]
        u[ve] = ((wx - a0[ve]) * d0[ve] + (wy - a1[ve]) * d1[ve]) / L[ve]
        # edge-vertex: the environment vertex, in the object frame, projected on the object edge
        ev = ~ve
        dx, dy = p0[ev] - Q[ev, 0], p1[ev] - Q[ev, 1]
        qx = c[ev] * dx + s[ev] * dy
        qy = -s[ev] * dx + c[ev] * dy
        u[ev] = ((qx - a0[ev]) * d0[ev] + (qy - a1[ev]) * d1[ev]) / L[ev]
        out[rows] &= (u >= -tol) & (u <= L + tol)
    return out


def _last_true(pred: Callable[[FloatArray], NDArray[np.bool_]], lo: float, hi: float, bits: int,
               width: int = 64) -> float:
    """Largest x in [lo, hi] with ``pred(x)`` true, for a predicate true at ``lo``, false
    at ``hi`` and monotone in between, to ``bits`` binary digits of ``hi - lo``.

    A batched multisection: each round evaluates ``width`` points at once (one vectorised
    call) and keeps the sub-interval where the predicate turns false.
    """
    return _last_true_many(lambda xs: [pred(xs[0])], [lo], [hi], bits, width)[0]


def _last_true_many(pred: Callable[[list[FloatArray]], list[NDArray[np.bool_]]], lo: Sequence[float],
                    hi: Sequence[float], bits: int, width: int = 64) -> list[float]:
    """:func:`_last_true` of several intervals at once: ``pred`` takes the points of
    every interval (a list of arrays) and answers for each, in one call per round."""
    lo, hi = [float(v) for v in lo], [float(v) for v in hi]
    rounds = max(1, int(math.ceil(bits / math.log2(width + 1))))
    for _ in range(rounds):
        if not lo:
            break
        xs = list(_linspaces(lo, hi, width + 2)[:, 1:-1])
        for k, (x, ok) in enumerate(zip(xs, pred(xs))):
            bad = np.flatnonzero(~ok)
            if bad.size == 0:
                lo[k] = float(x[-1])
            else:
                i = int(bad[0])
                hi[k] = float(x[i])
                lo[k] = float(x[i - 1]) if i > 0 else lo[k]
    return lo


def _linspaces(lo: Sequence[float], hi: Sequence[float], num: int) -> FloatArray:
    """``np.linspace(lo[k], hi[k], num)`` of each interval, as the rows of one array:
    numpy's arithmetic (``i * step + start``, the end set to ``stop``) on all rows at once;
    one interval at a time when some step is zero (numpy then computes differently)."""
    a, b = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    step = (b - a) / (num - 1) if num > 1 else np.zeros(a.size)
    if np.any(step == 0):
        return np.array([np.linspace(x, y, num) for x, y in zip(a, b)]).reshape(a.size, num)
    out = np.arange(0, num, dtype=float)[None, :] * step[:, None]
    out += a[:, None]
    out[:, -1] = b
    return out


def sweep(
    world: World,
    motion: Motion,
    s_max: float,
    overlap_fn: OverlapFn | None = None,
    *,
    step_mm: float = 1.0,
    refine_bits: int = 24,
    tol: float = CONTACT_TOL,
) -> Sweep:
    """Walk ``motion`` from ``s = 0`` to at most ``s_max`` and cut it by contact state.

    The walk samples ``s`` so that no object vertex moves more than ``step_mm`` between
    samples, stops before the first sample that overlaps the environment (``overlap_fn``,
    by default :func:`geometry.collision.object_env_overlap` at ``SWEEP_TOL``) or that
    loses a kept contact, and refines (to ``refine_bits`` binary digits of the step)
    between the last good and first bad sample so the walk ends exactly where the new
    contact is made. Every state change inside the walk is refined likewise (to half the
    digits), so piece boundaries are accurate. States are identified in batched calls.
    """
    return sweep_many(world, [(motion, s_max)], overlap_fn, step_mm=step_mm, refine_bits=refine_bits, tol=tol)[0]


def sweep_many(
    world: World,
    jobs: Sequence[tuple[Motion, float]],
    overlap_fn: OverlapFn | None = None,
    *,
    step_mm: float = 1.0,
    refine_bits: int = 24,
    tol: float = CONTACT_TOL,
) -> list[Sweep]:
    """:func:`sweep` of each ``(motion, s_max)``, the sweeps walked side by side.

    The same sweeps, computed by the same numbers: each stage (the walk's chunks, the
    refinement of the ends, the states, the refinement of the piece boundaries) runs
    over every sweep at once, in one overlap test and one contact identification per
    round instead of one per sweep (``overlap_fn`` must decide each pose on its own, as
    :func:`geometry.collision.object_env_overlap` does). The sweeps of a solve's setup
    are hundreds of small ones, whose cost is mostly the calls' own.
    """
    if not jobs:
        return []
    overlap = overlap_fn or _default_overlap
    motions = [m for m, _ in jobs]
    grids = _grids(world, [(m, 0.0, s_max) for m, s_max in jobs], step_mm)

    def good(which: Sequence[int], poses: Sequence[FloatArray]) -> list[NDArray[np.bool_]]:
        """Whether each pose of ``poses[i]`` (motion ``which[i]``) is finite, keeps the
        motion's contacts and does not overlap (one overlap call for all)."""
        if not poses:
            return []
        sizes = [p.shape[0] for p in poses]
        every = np.concatenate(poses)
        finite = np.isfinite(every)
        ok = np.all(finite, axis=1)
        ok &= _kept_hold_rows(world, [motions[k].kept for k in which], sizes, np.where(finite, every, 0.0))
        todo = np.flatnonzero(ok)
        if todo.size:
            ok[todo] = ~overlap(world, every[todo])
        return np.split(ok, np.cumsum(sizes)[:-1])

    # Walk in chunks that double, stopping at the first bad sample: most sweeps end (a
    # new contact, a kept contact lost) long before s_max, and a two-contact motion's
    # speed bound can make s_max thousands of samples.
    first_bad: list[int | None] = [None] * len(jobs)
    at = [0] * len(jobs)
    size = [64] * len(jobs)
    walking = list(range(len(jobs)))
    while walking:
        for k in walking:
            grids[k].upto(at[k] + size[k])
        ends = [min(grids[k].s.size, at[k] + size[k]) for k in walking]
        oks = good(walking, [grids[k].p[at[k]:j] for k, j in zip(walking, ends)])
        still = []
        for k, j, ok in zip(walking, ends, oks):
            if not ok.all():
                first_bad[k] = at[k] + int(np.argmin(ok))
                continue
            at[k], size[k] = j, 2 * size[k]
            if grids[k].more(at[k]):
                still.append(k)
        walking = still

    # Why each sweep ends, and where exactly (one multisection for all).
    end: list[SweepEnd] = [SweepEnd.LIMIT] * len(jobs)
    refine = [k for k in range(len(jobs)) if first_bad[k] is not None and first_bad[k] > 0]
    for k in range(len(jobs)):
        fb = first_bad[k]
        if fb is None:
            continue
        if fb == 0:
            end[k] = SweepEnd.BLOCKED
            continue
        p_bad = grids[k].p[fb]
        if not np.all(np.isfinite(p_bad)):
            end[k] = SweepEnd.DEGENERATE
        elif any(not kept_contact_holds(world, c, p_bad[None])[0] for c in motions[k].kept):
            end[k] = SweepEnd.CONTACT_LOST
        else:
            end[k] = SweepEnd.BLOCKED
    last = _last_true_many(
        lambda xs: good(refine, _poses_many([motions[k] for k in refine], xs)),
        [float(grids[k].s[first_bad[k] - 1]) for k in refine],  # type: ignore[operator]
        [float(grids[k].s[first_bad[k]]) for k in refine], refine_bits)  # type: ignore[index]
    last_of = dict(zip(refine, last))
    params: list[FloatArray] = []
    poses: list[FloatArray] = []
    for k in range(len(jobs)):
        fb = first_bad[k]
        s, p = grids[k].whole() if fb is None else (grids[k].s, grids[k].p)
        if fb == 0:  # blocked at once: the state of the start
            params.append(np.zeros(0))
            poses.append(motions[k].start.as_array()[None])
        elif fb is None:
            params.append(s)
            poses.append(p)
        else:
            lo = last_of[k]
            if lo > s[fb - 1]:
                params.append(np.concatenate([s[:fb], [lo]]))
                poses.append(np.concatenate([p[:fb], motions[k].poses([lo])]))
            else:
                params.append(s[:fb])
                poses.append(p[:fb])

    # The states along every sweep (one identification), and where they change.
    offsets = np.concatenate([[0], np.cumsum([p.shape[0] for p in poses])]).astype(np.int64)
    rows, masks = _state_rows(world, np.concatenate(poses), tol)
    changed = np.zeros(rows.shape[0], dtype=bool)  # row i differs from row i - 1 of its sweep
    changed[1:] = np.any(rows[1:] != rows[:-1], axis=1)
    changed[offsets[:-1]] = False
    states = _STATES.setdefault(world, {})  # a packed row names one state of the world

    def state(i: int) -> ContactState:
        key = rows[i].tobytes()
        if key not in states:
            states[key] = masks.state(i)  # type: ignore[attr-defined]
        return states[key]

    changes: list[tuple[int, int, int]] = []  # (sweep, first sample of the new state, first of the old)
    for k in range(len(jobs)):
        if first_bad[k] == 0:
            continue
        o = int(offsets[k])
        start_i = 0
        for i in (np.flatnonzero(changed[o:o + params[k].size])).tolist():
            changes.append((k, i, start_i))
            start_i = i

    def same(xs: list[FloatArray]) -> list[NDArray[np.bool_]]:
        placed = _poses_many([motions[k] for k, _, _ in changes], xs)
        got = _state_rows(world, np.concatenate(placed), tol)[0] if placed else rows[:0]
        out, at = [], 0
        for (k, _, start_i), p in zip(changes, placed):
            key = rows[int(offsets[k]) + start_i]
            out.append(np.all(got[at:at + p.shape[0]] == key, axis=1))
            at += p.shape[0]
        return out

    bounds = _last_true_many(same, [float(params[k][i - 1]) for k, i, _ in changes],
                             [float(params[k][i]) for k, i, _ in changes], refine_bits // 2)
    out: list[Sweep] = []
    c = 0
    for k in range(len(jobs)):
        o = int(offsets[k])
        if first_bad[k] == 0:
            out.append(Sweep(motions[k], (SweepPiece(state(o), 0.0, 0.0),), end[k]))
            continue
        pieces: list[SweepPiece] = []
        s0, start_i = 0.0, 0
        while c < len(changes) and changes[c][0] == k:
            _, i, _ = changes[c]
            pieces.append(SweepPiece(state(o + start_i), s0, bounds[c]))
            s0, start_i = bounds[c], i
            c += 1
        pieces.append(SweepPiece(state(o + start_i), s0, float(params[k][-1])))
        out.append(Sweep(motions[k], tuple(pieces), end[k]))
    return out


#: The contact state of each packed row of principal-contact masks met so far, per world
#: (:func:`_state_rows`: the row is the masks, so it names the state).
_STATES: "weakref.WeakKeyDictionary[World, dict[bytes, ContactState]]" = weakref.WeakKeyDictionary()

#: A two-contact motion's grid starts at most this fast (object radii of vertex motion
#: per radian) and is subdivided where it moves faster: its speed bound is a finite
#: difference at the start, which near a singular start is millions of mm per radian.
TWO_CONTACT_SPEED_CAP = 8.0
#: Most samples a grid is subdivided to.
MAX_GRID_SAMPLES = 20_000


def _placed_vertices(world: World, poses: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The object's vertices at each pose: world x and y, (n, N) each."""
    verts = world.object.polygon.vertices
    c, sn = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    wx = c[:, None] * verts[None, :, 0] - sn[:, None] * verts[None, :, 1] + poses[:, 0:1]
    wy = sn[:, None] * verts[None, :, 0] + c[:, None] * verts[None, :, 1] + poses[:, 1:2]
    return wx, wy


def _grid(world: World, motion: Motion, s0: float, s1: float, step_mm: float) -> FloatArray:
    """Parameter values from ``s0`` to ``s1`` (both included) such that no object vertex
    moves more than ``step_mm`` between consecutive values, up to the first undefined
    pose (a two-contact singularity) and up to ``MAX_GRID_SAMPLES``.

    A uniform grid sized by the motion's vertex speed (for a two-contact motion at most
    ``TWO_CONTACT_SPEED_CAP`` radii per radian), every interval that still moves a vertex
    too far halved, round after round.
    """
    return _grid_poses(world, motion, s0, s1, step_mm)[0]


def _grid_poses(world: World, motion: Motion, s0: float, s1: float, step_mm: float) -> tuple[FloatArray, FloatArray]:
    """:func:`_grid`'s parameter values and the motion's poses at them, (n,) and (n, 3)."""
    return _Grid(world, motion, s0, s1, step_mm).whole()


def _uniform_grids(world: World, jobs: Sequence[tuple[Motion, float, float]], step_mm: float
                   ) -> list[tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]]:
    """The uniform grid of each ``(motion, s0, s1)`` (sized by the motion's vertex speed,
    see :func:`_grid`): its values, poses, the object's placed vertices (x and y, (n+1, N)
    each) and the longest vertex step of each interval; the poses and vertices of all
    the grids in one computation (elementwise: the numbers of one grid at a time)."""
    values = []
    for motion, s0, s1 in jobs:
        speed = max(motion.vertex_speed(world), EPS)
        if motion.kind is MotionKind.TWO_CONTACT:
            speed = min(speed, TWO_CONTACT_SPEED_CAP * world.object.polygon.radius)
        n = max(1, int(math.ceil(abs(s1 - s0) * speed / step_mm)))  # uniform intervals
        values.append(np.linspace(s0, s1, n + 1))
    poses = _poses_many([m for m, _, _ in jobs], values)
    if not poses:
        return []
    wx, wy = _placed_vertices(world, np.concatenate(poses))
    step = np.max(np.hypot(np.diff(wx, axis=0), np.diff(wy, axis=0)), axis=1)  # consecutive samples
    out, at = [], 0
    for s, p in zip(values, poses):
        k = s.size
        out.append((s, p, wx[at:at + k], wy[at:at + k], step[at:at + k - 1]))
        at += k
    return out


def _grids(world: World, jobs: Sequence[tuple[Motion, float, float]], step_mm: float) -> list["_Grid"]:
    """A :class:`_Grid` of each ``(motion, s0, s1)``, their uniform grids computed together."""
    return [_Grid(world, m, s0, s1, step_mm, uniform)
            for (m, s0, s1), uniform in zip(jobs, _uniform_grids(world, jobs, step_mm))]


class _Grid:
    """:func:`_grid`'s values and poses, computed as far as a sweep walks them.

    The uniform grid is halved round after round: an interval that moves no vertex more
    than the step is never halved again, nor one with an undefined end, nor any interval
    after the first such (no refining past a singularity); the rounds stop when no
    interval is halved, after 40 rounds, or once the grid holds MAX_GRID_SAMPLES. Only
    the intervals still too long are halved, each new midpoint placed once, and every
    number is computed elementwise: the values and poses are those of halving the whole
    grid round after round.

    A sweep that stops after a few samples needs only the first ones, while a grid near
    a two-contact singularity holds thousands further on. :meth:`upto` halves only the
    first m intervals of the uniform grid, which is exact when the whole grid's rounds
    cannot have stopped earlier for its size: while the first part halves in round r,
    the rest holds at most its count times 2^r samples (each round adds at most one per
    interval), so below MAX_GRID_SAMPLES in all the whole grid is halved in that round
    too. When that bound does not hold, the whole grid is computed.
    """

    def __init__(self, world: World, motion: Motion, s0: float, s1: float, step_mm: float,
                 uniform: tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray] | None = None) -> None:
        """``uniform``: the uniform grid's values, poses, placed vertices (x and y) and
        the longest vertex step of each interval, as :func:`_grids` computes them for
        several grids at once (computed here when ``None``)."""
        self.world, self.motion, self.step = world, motion, step_mm
        if uniform is None:
            uniform = _uniform_grids(world, [(motion, s0, s1)], step_mm)[0]
        self.s0, self.p0, self.wx, self.wy, self.d0 = uniform
        self.n = self.s0.size - 1  # uniform intervals
        self.m = 0  # uniform intervals halved so far
        self.s, self.p = self.s0[:1], self.p0[:1]

    @property
    def complete(self) -> bool:
        return self.m == self.n

    def upto(self, count: int) -> None:
        """Make at least ``count`` values known (all of them when the grid has fewer)."""
        while not self.complete and self.s.size < count:
            m = max(count - 1, 2 * self.m, 1)
            got = self._halved(m) if m < self.n else None
            if got is None:
                m, got = self.n, self._halved(self.n)
            self.m, (self.s, self.p) = m, got  # type: ignore[misc]

    def more(self, at: int) -> bool:
        """Whether the grid holds a value at index ``at``, or may (not all computed)."""
        return not self.complete or at < self.s.size

    def whole(self) -> tuple[FloatArray, FloatArray]:
        """All the values and their poses."""
        if not self.complete:
            self.m, (self.s, self.p) = self.n, self._halved(self.n)  # type: ignore[misc]
        return self.s, self.p

    def _halved(self, m: int) -> tuple[FloatArray, FloatArray] | None:
        """The first ``m`` uniform intervals halved as in the whole grid, with their
        poses; ``None`` when that cannot be told without the rest."""
        outside = self.n - m  # samples after them
        s, p, wx, wy, d = self.s0[:m + 1], self.p0[:m + 1], self.wx[:m + 1], self.wy[:m + 1], self.d0[:m]
        k = np.flatnonzero(d > self.step)
        if not k.size:  # nothing to halve (the rounds below would stop at once)
            return s, p
        undefined = np.flatnonzero(~np.isfinite(d))
        first_undefined = float(s[undefined[0]]) if undefined.size else math.inf  # its start
        # the intervals still too long: their ends and the object's vertices there
        a, b = s[k], s[k + 1]
        ax, ay, bx, by = wx[k], wy[k], wx[k + 1], wy[k + 1]
        new_s: list[FloatArray] = [s]
        new_p: list[FloatArray] = [p]
        size = s.size
        for r in range(40):
            before = a < first_undefined
            if not np.any(before) or size >= MAX_GRID_SAMPLES:
                break
            if outside and size + outside * 2 ** r >= MAX_GRID_SAMPLES:
                return None  # the whole grid may have stopped growing by now
            if not before.all():
                a, b, ax, ay, bx, by = (v[before] for v in (a, b, ax, ay, bx, by))
            mids = 0.5 * (a + b)
            pm = self.motion.poses(mids)
            mx, my = _placed_vertices(self.world, pm)
            left = np.max(np.hypot(mx - ax, my - ay), axis=1)  # as consecutive samples
            right = np.max(np.hypot(bx - mx, by - my), axis=1)
            new_s.append(mids)
            new_p.append(pm)
            size += mids.size
            for starts, steps in ((a, left), (mids, right)):
                bad = ~np.isfinite(steps)
                if bad.any():
                    first_undefined = min(first_undefined, float(starts[bad].min()))
            lf, rf = left > self.step, right > self.step
            a, b = np.concatenate([a[lf], mids[rf]]), np.concatenate([mids[lf], b[rf]])
            ax, ay = np.concatenate([ax[lf], mx[rf]]), np.concatenate([ay[lf], my[rf]])
            bx, by = np.concatenate([mx[lf], bx[rf]]), np.concatenate([my[lf], by[rf]])
        if len(new_s) == 1:
            return s, p
        s, p = np.concatenate(new_s), np.concatenate(new_p)
        order = np.argsort(s, kind="stable")
        return s[order], p[order]


def dense_parameters(world: World, motion: Motion, s0: float, s1: float, step_mm: float) -> FloatArray:
    """Parameter values from ``s0`` to ``s1`` (both included) such that no object vertex
    moves more than ``step_mm`` between consecutive values (:func:`_grid`; a segment's
    motion is defined over its whole range)."""
    return _grid(world, motion, s0, s1, step_mm)
