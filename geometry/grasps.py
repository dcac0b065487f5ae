"""Candidate grasp sets (paper, "Candidate Grasp Sets"): enumeration, G_T and G_m.

A grasp ``g`` relates the gripper to the object. In the *object frame* it is the gripper
pose ``(x, y, phi)`` (see the scenario spec, "The gripper frame"), the width (spacing of
the two-point model, opening of the polyline model) and, per finger, the point of the
object's boundary it touches (or none). At object pose ``T`` the world gripper pose is
``T * g``. The discrete set is a struct of arrays, :class:`GraspSet`; its row 0 is the
no-contact grasp ``{0, 0}`` of the paper.

Three steps, one function each:

1. :func:`enumerate_grasps`: the discrete set in the object frame, ``K`` samples per
   object edge (Configuration I: exact circle/offset-curve solutions; Configuration II:
   parallel pads closed onto the object), one- and two-finger grasps, both finger orders.
2. :func:`pose_conditioned`: ``G_T``, the grasps whose gripper is free of the
   environment at object pose ``T`` (row 0 always kept).
3. :func:`motion_conditioned`: ``G_m``, the grasps that are collision-free and
   quasi-statically feasible at every sample of a MoveObject pose path, with their
   quality ``S(g, m)``.

Every sampling choice is listed in :class:`GraspOptions` and derived in
``docs/design/grasps.md``.
"""

from __future__ import annotations

import enum
import logging
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from typing import Any

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from geometry import collision, contacts, mechanics
from geometry.contacts import row_groups
from geometry.errors import GeometryError
from geometry.poses import BoolArray, IntArray, Pose, compose_batch, transform_points, wrap_angle
from geometry.shapes import FloatArray, Polygon
from geometry.tolerances import CONTACT_TOL, EPS, GRASP_OBJECT_TOL, PENETRATION_TOL, VALIDATE_TOL
from geometry.world import PolylineGripper, TwoPointGripper, World

__all__ = [
    "FingerPart",
    "GraspOptions",
    "GraspSet",
    "MotionCheckOptions",
    "MotionGrasps",
    "NO_CONTACT",
    "PRESS_LADDER",
    "enumerate_grasps",
    "class_representatives",
    "held_at_each",
    "pose_conditioned",
    "motion_conditioned",
    "press_forces",
    "rate_motion_grasps",
    "row_groups",
    "within_force_limit",
]

logger = logging.getLogger(__name__)


#: Row index of the no-contact grasp ``{0, 0}`` in every :class:`GraspSet`.
NO_CONTACT: int = 0


#: Relative tolerance (times the object's size) for geometric coincidences in the
#: enumeration: which closing events happen "at the same time", which edges lie flush.
_COINCIDENT: float = 1e-9


class FingerPart(enum.IntEnum):
    """Which part of a finger touches the object."""

    NONE = 0  #: the finger does not touch
    CIRCLE = 1  #: two-point model: the finger's circle
    PAD = 2  #: polyline model: the pad face (the finger polygon's x = 0 side)
    TIP = 3  #: polyline model: the fingertip corner (the pad's end at the tip, y = y_min)


@dataclass(frozen=True)
class GraspOptions:
    """Sampling choices of the enumeration (defaults as documented in ``grasps.md``).

    Attributes
    ----------
    samples_per_edge : int
        ``K``: contact samples per object edge, at ``t = (k + u) / K``, ``k < K``.
    edge_offsets : tuple of float, optional
        ``u`` per object edge, each in ``[0, 1)`` (a planner draws them from its seed);
        ``None``: ``u = 1/2`` on every edge.
    vertex_fan : int
        Normals sampled strictly inside the normal fan of each convex object vertex
        (evenly, excluding the two edge normals, which the edge samples cover).
    orientations : int
        One-finger grasps of the two-point model: directions from the touching finger to
        the free one, evenly spaced over the full circle starting at the outward normal.
    closing_angles_deg : tuple of float
        Two-point model with a spacing *range*: closing directions, the inward normal at
        finger 1's contact rotated by these angles (degrees). A pinch across two faces a
        span D apart is offset along them by D tan(angle), which must stay within the
        faces: across a 100 x 20 book's ends only angles below atan(20 / 110) = 10.3
        degrees give a pinch whose fingers are at different heights (the one that
        tips it), so small angles are sampled too (5 degrees apart up to 15).
    pad_heights : tuple of float
        Polyline model: where along the pad the sampled contact lies, as fractions of
        the pad length from the fingertip (0) to the pad's upper end (1).
    tip_angles_deg : tuple of float
        Polyline model, one-finger fingertip-corner grasps: angles (degrees, > 0) between
        the gripper's approach axis and the contacted edge's normal; the finger body is
        tilted away from the edge (sign chosen per finger).
    free_widths : tuple of float
        One-finger grasps: widths of the free finger as fractions of the width range
        (``w = w_min + f (w_max - w_min)``; duplicates merged).
    tol : float
        Overlap tolerance (mm) of the fingers and palm against the object (the rule of
        plan rule 3, much tighter than the planner's 0.1 mm: grasps touch exactly and
        nothing else sinks into the object).
    contact_tol : float
        A free finger must stay farther than this (mm) from the object.
    """

    samples_per_edge: int = 100
    edge_offsets: tuple[float, ...] | None = None
    vertex_fan: int = 3
    orientations: int = 8
    closing_angles_deg: tuple[float, ...] = (0.0, -15.0, 15.0, -30.0, 30.0, -5.0, 5.0, -10.0, 10.0)
    pad_heights: tuple[float, ...] = (0.1, 0.5)
    tip_angles_deg: tuple[float, ...] = (30.0, 60.0)
    free_widths: tuple[float, ...] = (1.0, 0.5)
    tol: float = GRASP_OBJECT_TOL
    contact_tol: float = CONTACT_TOL

    def __post_init__(self) -> None:
        if self.samples_per_edge < 1:
            raise GeometryError(f"grasp options: samples_per_edge must be >= 1, got {self.samples_per_edge}")
        if self.edge_offsets is not None:
            object.__setattr__(self, "edge_offsets", tuple(float(u) for u in self.edge_offsets))
            if any(not 0.0 <= u < 1.0 for u in self.edge_offsets):
                raise GeometryError("grasp options: edge_offsets are fractions in [0, 1)")
        if self.vertex_fan < 0 or self.orientations < 0:
            raise GeometryError("grasp options: vertex_fan and orientations must be >= 0")
        if any(not 0.0 <= f <= 1.0 for f in self.pad_heights + self.free_widths):
            raise GeometryError("grasp options: pad_heights and free_widths are fractions in [0, 1]")
        if any(not 0.0 < a < 90.0 for a in self.tip_angles_deg):
            raise GeometryError("grasp options: tip_angles_deg must lie in (0, 90)")


def _ro(a: ArrayLike, dtype: type | None = None) -> np.ndarray:
    arr = np.array(a, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class GraspSet:
    """A discrete grasp set in the object frame, as a struct of arrays (G rows).

    Row :data:`NO_CONTACT` (0) is the no-contact grasp ``{0, 0}``: NaN pose and width,
    no finger touching. Build with :func:`enumerate_grasps`.

    Attributes
    ----------
    gripper : ndarray, shape (G, 3)
        Gripper pose ``(x, y, phi)`` in the object frame (mm, radians, phi in [-pi, pi)).
    width : ndarray, shape (G,)
        Spacing (two-point) or opening (polyline), mm.
    contact : ndarray, shape (G, 2, 2)
        Finger 1 / finger 2 contact point in the object frame; NaN if not touching.
    normal : ndarray, shape (G, 2, 2)
        Unit contact normal pointing *into the object* (the direction of the finger's
        normal force on it); NaN if not touching.
    feature : ndarray of int, shape (G, 2)
        Object feature touched: ``i`` in ``[0, N)`` is edge ``l_(i+1)``, ``N + j`` is
        vertex ``v_(j+1)``, ``-1`` is none (``N`` = :attr:`n_object`).
    part : ndarray of int8, shape (G, 2)
        :class:`FingerPart` of each finger that touches (``NONE`` if it does not).
    arclength : ndarray, shape (G, 2)
        Boundary coordinate of each contact: length (mm) along the counter-clockwise
        boundary from ``v1``, in ``[0, perimeter)``; NaN if not touching. The ``slide``
        primitive's travel is a difference of these.
    flipped : ndarray of int, shape (G,)
        Index of the grasp obtained by the ``flip`` primitive (fingers swapped onto the
        same contacts, gripper turned by 180 degrees), or ``-1`` if that grasp is not in
        the set (it would overlap the object) or for row 0.
    n_object : int
        Vertex count of the object (decodes :attr:`feature`).
    perimeter : float
        Object perimeter (mm), the period of :attr:`arclength`.
    """

    gripper: FloatArray
    width: FloatArray
    contact: FloatArray
    normal: FloatArray
    feature: IntArray
    part: NDArray[np.int8]
    arclength: FloatArray
    flipped: IntArray
    n_object: int
    perimeter: float

    def __len__(self) -> int:
        return int(self.width.shape[0])

    @cached_property
    def touching(self) -> BoolArray:
        """(G, 2) whether finger 1 / finger 2 touches the object."""
        return _ro(self.part != FingerPart.NONE)

    @cached_property
    def n_touching(self) -> IntArray:
        """(G,) number of fingers touching (0, 1 or 2)."""
        return _ro(self.touching.sum(axis=1).astype(np.int64))

    @cached_property
    def vertex_contact(self) -> BoolArray:
        """(G, 2) whether the finger touches an object *vertex* (feature >= N)."""
        return _ro(self.feature >= self.n_object)

    def world_gripper(self, pose: ArrayLike, indices: ArrayLike | None = None) -> FloatArray:
        """World gripper poses (B, 3) of the grasps ``indices`` (all rows if None) at
        object pose ``pose = (x, y, theta)``."""
        g = self.gripper if indices is None else self.gripper[np.asarray(indices)]
        return compose_batch(np.asarray(pose, dtype=float)[None, :], g)

    def world_contacts(self, pose: ArrayLike, indices: ArrayLike | None = None) -> FloatArray:
        """World contact points (B, 2, 2) of the grasps ``indices`` at object pose ``pose``
        (NaN where a finger does not touch)."""
        c = self.contact if indices is None else self.contact[np.asarray(indices)]
        return Pose.from_array(pose).apply(c)

    @cached_property
    def _world_memo(self) -> dict[str, Any]:
        # what depends on the world, for the last world asked (a solve asks with one
        # world, thousands of times: each a pass over every grasp)
        return {"world": None}

    def _per_world(self, world: World, key: str, compute: Callable[[], np.ndarray]) -> np.ndarray:
        """``compute()`` (made read-only) for ``world``, memoised until another world is asked."""
        memo = self._world_memo
        if memo["world"] is not world:
            memo.clear()
            memo["world"] = world
        if key not in memo:
            out = compute()
            out.setflags(write=False)
            memo[key] = out
        return memo[key]

    def contact_mu(self, world: World) -> FloatArray:
        """(G, 2) finger-object friction coefficient of each contact (NaN if none).

        Resolved by :meth:`~geometry.world.Friction.gripper_mu` for the edge or vertex
        touched (a vertex takes the smaller override of its two edges, if any). A
        contact on an edge within the plan validator's contact tolerance
        (:data:`~geometry.tolerances.VALIDATE_TOL`, plus :data:`CONTACT_TOL` of margin)
        of one of its end vertices takes that vertex's: the validator counts it as a
        contact at the vertex (plan rule 7), and a plan must not lean on friction that
        its judge does not grant (a cover 0.7 mm from a frictionless end face).
        """
        return self._per_world(world, "contact_mu", lambda: self._contact_mu(world))

    @cached_property
    def _finger_rows(self) -> tuple[FloatArray, FloatArray, NDArray[np.int8]]:
        """(G, 2, 2) contacts and (G, 2, 2) normals with NaN as 0, and (G, 2) the finger
        contacts' modes (STICKING where touching, else ABSENT): the per-grasp part of every
        (grasp, sample) instance of :func:`motion_conditioned`, computed once per set."""
        modes = np.where(self.touching, mechanics.ContactMode.STICKING, mechanics.ContactMode.ABSENT).astype(np.int8)
        return _ro(np.nan_to_num(self.contact)), _ro(np.nan_to_num(self.normal)), _ro(modes)

    def _finger_mu(self, world: World) -> FloatArray:
        """(G, 2) :meth:`contact_mu` with NaN (no contact) as 0."""
        return self._per_world(world, "finger_mu", lambda: np.nan_to_num(self.contact_mu(world)))

    def contact_classes(self, world: World) -> IntArray:
        """(G,) ids of the grasps whose finger contacts are the same bit for bit (points and
        normals in the object frame, friction in ``world``, which fingers touch): their
        (grasp, sample) instances of :func:`motion_conditioned` are the same arrays, so the
        quasi-static tests are decided once per class (many grasps share their contacts and
        differ only by the gripper's pose or opening)."""
        def classes() -> IntArray:
            q, n, modes = self._finger_rows
            g = len(self)
            keys = np.concatenate([q.reshape(g, -1).view(np.int64), n.reshape(g, -1).view(np.int64),
                                   self._finger_mu(world).view(np.int64), modes.astype(np.int64)], axis=1)
            return row_groups(keys)[0]

        return self._per_world(world, "contact_classes", classes)

    def _contact_mu(self, world: World) -> FloatArray:
        n = self.n_object
        fr = world.friction
        table = np.array([fr.gripper_mu("l", i, n) for i in range(n)]
                         + [fr.gripper_mu("v", j, n) for j in range(n)] + [np.nan])
        feature = np.where(self.feature < 0, 2 * n, self.feature)
        on_edge = (self.feature >= 0) & (self.feature < n)
        if on_edge.any():
            verts = world.object.polygon.vertices
            near = VALIDATE_TOL + CONTACT_TOL
            for end in (0, 1):  # the edge's start vertex, then its end vertex
                j = (np.where(on_edge, self.feature, 0) + end) % n
                close = on_edge & (np.linalg.norm(np.nan_to_num(self.contact, nan=np.inf) - verts[j], axis=-1) <= near)
                feature = np.where(close & (table[n + j] < table[feature]), n + j, feature)
        return table[feature]


# --------------------------------------------------------------------------------------
# Candidate rows (mutable scratch arrays, assembled into a GraspSet at the end)
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Rows:
    """Candidate grasps under construction (same columns as :class:`GraspSet`)."""

    gripper: FloatArray  # (R, 3)
    width: FloatArray  # (R,)
    contact: FloatArray  # (R, 2, 2)
    normal: FloatArray  # (R, 2, 2)
    feature: IntArray  # (R, 2)
    part: NDArray[np.int8]  # (R, 2)

    def __len__(self) -> int:
        return int(self.width.shape[0])

    def take(self, idx: ArrayLike) -> "_Rows":
        i = np.asarray(idx)
        return _Rows(*(getattr(self, f.name)[i] for f in fields(self)))

    @staticmethod
    def empty() -> "_Rows":
        return _Rows(np.empty((0, 3)), np.empty(0), np.empty((0, 2, 2)), np.empty((0, 2, 2)),
                     np.empty((0, 2), dtype=np.int64), np.empty((0, 2), dtype=np.int8))

    @staticmethod
    def concat(parts: list["_Rows"]) -> "_Rows":
        parts = [p for p in parts if len(p)] or [_Rows.empty()]
        return _Rows(*(np.concatenate([getattr(p, f.name) for p in parts], axis=0) for f in fields(_Rows)))


def _one_finger_rows(gripper: FloatArray, width: FloatArray, finger: IntArray, point: FloatArray,
                     normal: FloatArray, feature: IntArray, part: int | IntArray) -> _Rows:
    """Rows where finger ``finger`` (0 or 1) touches ``point``; the other one is free."""
    r = gripper.shape[0]
    contact = np.full((r, 2, 2), np.nan)
    nrm = np.full((r, 2, 2), np.nan)
    feat = np.full((r, 2), -1, dtype=np.int64)
    prt = np.zeros((r, 2), dtype=np.int8)
    rows = np.arange(r)
    contact[rows, finger] = point
    nrm[rows, finger] = normal
    feat[rows, finger] = feature
    prt[rows, finger] = part
    return _Rows(gripper, width, contact, nrm, feat, prt)


def _frame(origin: FloatArray, ex: FloatArray) -> FloatArray:
    """Gripper poses (R, 3) from origins (R, 2) and unit x axes (R, 2)."""
    return np.concatenate([origin, wrap_angle(np.arctan2(ex[:, 1], ex[:, 0]))[:, None]], axis=1)


def _perp(v: FloatArray) -> FloatArray:
    """Rotate vectors (..., 2) by +90 degrees."""
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _rot(v: FloatArray, ang: FloatArray) -> FloatArray:
    c, s = np.cos(ang), np.sin(ang)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


# --------------------------------------------------------------------------------------
# Boundary samples
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Samples:
    """Contact samples on the object boundary: point, outward normal, feature code."""

    point: FloatArray  # (S, 2)
    normal: FloatArray  # (S, 2) outward unit normal (a fan normal at a vertex)
    feature: IntArray  # (S,) edge i or N + vertex j


def _boundary_samples(poly: Polygon, k: int, n_fan: int, offsets: tuple[float, ...] | None = None) -> _Samples:
    """``k`` samples per edge at ``t = (i + u) / k`` (``u`` the edge's offset, 1/2 by
    default) plus ``n_fan`` fan normals per convex vertex (strictly between its two edge
    normals)."""
    n = len(poly)
    if offsets is not None and len(offsets) != n:
        raise GeometryError(f"grasp options: {len(offsets)} edge_offsets for an object of {n} edges")
    u = np.full(n, 0.5) if offsets is None else np.asarray(offsets, dtype=float)
    t = (np.arange(k)[None, :] + u[:, None]) / k  # (n, k)
    pts = poly.vertices[:, None, :] + t[:, :, None] * poly.edge_vectors[:, None, :]
    nrm = np.broadcast_to(poly.normals[:, None, :], (n, k, 2))
    feat = np.broadcast_to(np.arange(n)[:, None], (n, k))
    points, normals, features = [pts.reshape(-1, 2)], [nrm.reshape(-1, 2)], [feat.reshape(-1)]
    conv = np.flatnonzero(poly.convex_vertices)
    if n_fan > 0 and conv.size:
        n_in = poly.normals[(conv - 1) % n]  # normal of the edge arriving at the vertex
        a0 = np.arctan2(n_in[:, 1], n_in[:, 0])
        turn = _fan_turn(poly)[conv]  # (0, pi): the exterior angle
        frac = np.arange(1, n_fan + 1) / (n_fan + 1)
        ang = a0[:, None] + turn[:, None] * frac[None, :]
        points.append(np.repeat(poly.vertices[conv], n_fan, axis=0))
        normals.append(np.stack([np.cos(ang), np.sin(ang)], axis=-1).reshape(-1, 2))
        features.append(np.repeat(n + conv, n_fan))
    return _Samples(np.concatenate(points), np.concatenate(normals), np.concatenate(features).astype(np.int64))


def _fan_turn(poly: Polygon) -> FloatArray:
    """(N,) signed turn (radians) from the arriving edge's normal to the leaving edge's
    normal at each vertex: in (0, pi) at convex vertices."""
    n_in = np.roll(poly.normals, 1, axis=0)
    n_out = poly.normals
    return np.arctan2(_cross(n_in, n_out), np.sum(n_in * n_out, axis=1))


def _in_fan(poly: Polygon, vertex: IntArray, m: FloatArray) -> BoolArray:
    """Whether directions ``m`` (..., 2) lie strictly inside the normal fan of the convex
    vertex ``vertex`` (...,) (endpoints excluded: the edges' offsets cover them)."""
    n = len(poly)
    n_in = poly.normals[(vertex - 1) % n]
    n_out = poly.normals[vertex]
    eps = 1e-12
    return (_cross(n_in, m) > eps) & (_cross(m, n_out) > eps) & poly.convex_vertices[vertex]


# --------------------------------------------------------------------------------------
# Configuration I: two-point gripper
# --------------------------------------------------------------------------------------


def _offset_hits_circle(poly: Polygon, r: float, centres: FloatArray, s: float
                        ) -> tuple[FloatArray, FloatArray, FloatArray, IntArray, BoolArray]:
    """Points at distance ``s`` from each centre on the offset curve (distance ``r``).

    Returns, for each centre (C,) and each of the ``2 N`` segment roots and ``2 N`` vertex
    arc roots (H = 4 N): finger-2 centre (C, H, 2), contact point (C, H, 2), outward
    normal (C, H, 2), feature (C, H) and validity (C, H).
    """
    n = len(poly)
    a = poly.vertices + r * poly.normals  # offset segment starts (N, 2)
    d = poly.edge_vectors
    w0 = a[None] - centres[:, None]  # (C, N, 2)
    qa = np.sum(d * d, axis=1)[None]
    qb = 2.0 * np.sum(d[None] * w0, axis=2)
    qc = np.sum(w0 * w0, axis=2) - s * s
    disc = qb * qb - 4.0 * qa * qc
    # A tangent circle (the spacing fits the object exactly) may round to disc < 0.
    tangent = disc >= -_COINCIDENT * (qb * qb + np.abs(4.0 * qa * qc))
    sq = np.sqrt(np.maximum(disc, 0.0))
    ts = np.stack([(-qb - sq) / (2 * qa), (-qb + sq) / (2 * qa)], axis=2)  # (C, N, 2)
    ok_s = tangent[..., None] & (ts >= 0.0) & (ts <= 1.0)
    seg_c2 = a[None, :, None] + ts[..., None] * d[None, :, None]
    seg_q = poly.vertices[None, :, None] + ts[..., None] * d[None, :, None]
    seg_n = np.broadcast_to(poly.normals[None, :, None], seg_c2.shape)
    seg_f = np.broadcast_to(np.arange(n)[None, :, None], ts.shape)

    v = poly.vertices
    e = v[None] - centres[:, None]  # (C, N, 2) from finger 1 to the vertex
    dist = np.linalg.norm(e, axis=2)
    safe = np.where(dist > EPS, dist, 1.0)
    along = (s * s - r * r + dist * dist) / (2.0 * safe)
    h2 = s * s - along * along
    ok_v = (dist > EPS) & (h2 >= -_COINCIDENT * s * s)
    h = np.sqrt(np.maximum(h2, 0.0))
    eu = e / safe[..., None]
    base = centres[:, None] + along[..., None] * eu
    arc_c2 = np.stack([base - h[..., None] * _perp(eu), base + h[..., None] * _perp(eu)], axis=2)  # (C, N, 2, 2)
    m = (arc_c2 - v[None, :, None]) / r
    vert = np.broadcast_to(np.arange(n)[None, :, None], ok_v.shape + (2,))
    ok_a = ok_v[..., None] & _in_fan(poly, vert, m)
    arc_q = np.broadcast_to(v[None, :, None], arc_c2.shape)
    arc_f = n + vert

    cs = centres.shape[0]
    cat = lambda x, y, tail: np.concatenate([x.reshape((cs, -1) + tail), y.reshape((cs, -1) + tail)], axis=1)  # noqa: E731
    return (cat(seg_c2, arc_c2, (2,)), cat(seg_q, arc_q, (2,)), cat(seg_n, m, (2,)),
            cat(seg_f, arc_f, ()), cat(ok_s, ok_a, ()))


def _offset_hits_ray(poly: Polygon, r: float, origins: FloatArray, dirs: FloatArray
                     ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, IntArray, BoolArray]:
    """Crossings of rays ``origins + lam dirs`` (lam > 0) with the offset curve.

    Returns lam (C, H), finger-2 centre (C, H, 2), contact (C, H, 2), outward normal
    (C, H, 2), feature (C, H) and validity (C, H), H = N segments + 2 N arc roots.
    """
    n = len(poly)
    a = poly.vertices + r * poly.normals
    d = poly.edge_vectors
    w = a[None] - origins[:, None]  # (C, N, 2)
    u = dirs[:, None]
    den = _cross(u, d[None])
    safe = np.where(np.abs(den) > EPS, den, 1.0)
    lam_s = _cross(w, d[None]) / safe
    t = _cross(w, u) / safe
    ok_s = (np.abs(den) > EPS) & (t >= 0.0) & (t <= 1.0) & (lam_s > EPS)
    seg_c2 = a[None] + t[..., None] * d[None]
    seg_q = poly.vertices[None] + t[..., None] * d[None]
    seg_n = np.broadcast_to(poly.normals[None], seg_c2.shape)
    seg_f = np.broadcast_to(np.arange(n)[None], t.shape)

    v = poly.vertices
    oc = origins[:, None] - v[None]  # (C, N, 2)
    b = np.sum(u * oc, axis=2)
    c = np.sum(oc * oc, axis=2) - r * r
    disc = b * b - c
    sq = np.sqrt(np.maximum(disc, 0.0))
    lam_a = np.stack([-b - sq, -b + sq], axis=2)  # (C, N, 2)
    arc_c2 = origins[:, None, None] + lam_a[..., None] * dirs[:, None, None]
    m = (arc_c2 - v[None, :, None]) / r
    vert = np.broadcast_to(np.arange(n)[None, :, None], lam_a.shape)
    ok_a = (disc[..., None] >= 0.0) & (lam_a > EPS) & _in_fan(poly, vert, m)
    arc_q = np.broadcast_to(v[None, :, None], arc_c2.shape)

    cs = origins.shape[0]
    cat = lambda x, y, tail: np.concatenate([x.reshape((cs, -1) + tail), y.reshape((cs, -1) + tail)], axis=1)  # noqa: E731
    return (cat(lam_s, lam_a, ()), cat(seg_c2, arc_c2, (2,)), cat(seg_q, arc_q, (2,)),
            cat(seg_n, m, (2,)), cat(seg_f, n + vert, ()), cat(ok_s, ok_a, ()))


def _two_point_pairs(world: World, grip: TwoPointGripper, smp: _Samples, opts: GraspOptions) -> _Rows:
    """Two-finger grasps of the two-point model, finger 1 on each sample.

    Fixed spacing ``s``: finger 2's centre is any point of the offset curve at distance
    ``s`` from finger 1's centre (exact segment and arc roots). Spacing range: close
    finger 2 along directions ``u`` (the inward normal turned by the closing angles);
    it stops at the last crossing of the ray with the offset curve, kept if within range.
    """
    poly = world.object.polygon
    r = float(grip.finger_radius)
    smin, smax = (float(v) for v in grip.spacing)
    c1 = smp.point + r * smp.normal
    if grip.fixed_width:
        c2, q2, n2, f2, ok = _offset_hits_circle(poly, r, c1, smax)
        ci, hi = np.nonzero(ok)
        c1r, p1, n1, f1 = c1[ci], smp.point[ci], smp.normal[ci], smp.feature[ci]
        c2, q2, n2, f2 = c2[ci, hi], q2[ci, hi], n2[ci, hi], f2[ci, hi]
        width = np.full(ci.shape[0], smax)
    else:
        ang = np.radians(np.asarray(opts.closing_angles_deg, dtype=float))
        na = ang.size
        rep = np.repeat(np.arange(c1.shape[0]), na)
        dirs = _rot(-smp.normal[rep], np.tile(ang, c1.shape[0]))
        lam, c2, q2, n2, f2, ok = _offset_hits_ray(poly, r, c1[rep], dirs)
        lam = np.where(ok, lam, -np.inf)
        best = np.argmax(lam, axis=1)
        rows = np.arange(rep.size)
        lam_b = lam[rows, best]
        keep = np.isfinite(lam_b) & (lam_b >= smin - 1e-9) & (lam_b <= smax + 1e-9)
        ci = rep[keep]
        hb = best[keep]
        kr = rows[keep]
        c1r, p1, n1, f1 = c1[ci], smp.point[ci], smp.normal[ci], smp.feature[ci]
        c2, q2, n2, f2 = c2[kr, hb], q2[kr, hb], n2[kr, hb], f2[kr, hb]
        c2, q2 = _snap_to_samples(poly, r, c1r, c2, q2, f2, opts, smin, smax)
        width = np.linalg.norm(c2 - c1r, axis=1)
    ex = (c2 - c1r) / np.where(width > EPS, width, 1.0)[:, None]
    gpose = _frame(0.5 * (c1r + c2), ex)
    contact = np.stack([p1, q2], axis=1)
    normal = -np.stack([n1, n2], axis=1)
    feature = np.stack([f1, f2], axis=1).astype(np.int64)
    part = np.full(feature.shape, FingerPart.CIRCLE, dtype=np.int8)
    return _Rows(gpose, width, contact, normal, feature, part)


def _snap_to_samples(poly: Polygon, r: float, c1: FloatArray, c2: FloatArray, q2: FloatArray, f2: IntArray,
                     opts: GraspOptions, smin: float, smax: float) -> tuple[FloatArray, FloatArray]:
    """The closing finger's contact moved to the nearest contact sample of the edge it
    lands on, when the gripper closed along the new axis lands there too (its last
    crossing with the offset curve) within the spacing range; otherwise where it landed.

    A pinch then touches two samples, each the anchor of the one-finger grasps and
    pinches enumerated from it, so the gripper can hand the object over from one finger
    to the other (keep finger 2, let finger 1 go and close it elsewhere). Landed off the
    grid, finger 2's contact is shared with no other grasp and no AdjustGrasp edge keeps
    it. The closing direction turns by at most atan(spacing / 2 / span) (0.3 degrees for
    the 80 mm block at K = 100)."""
    on_edge = np.flatnonzero(f2 < len(poly))
    if not on_edge.size:
        return c2, q2
    i = f2[on_edge]
    a, d = poly.vertices[i], poly.edge_vectors[i]
    k = opts.samples_per_edge
    u = np.full(len(poly), 0.5) if opts.edge_offsets is None else np.asarray(opts.edge_offsets, dtype=float)
    t = np.sum((q2[on_edge] - a) * d, axis=1) / np.sum(d * d, axis=1)
    ts = (np.clip(np.round(t * k - u[i]), 0, k - 1) + u[i]) / k
    qs = a + ts[:, None] * d
    cs = qs + r * poly.normals[i]
    w = np.linalg.norm(cs - c1[on_edge], axis=1)
    dirs = (cs - c1[on_edge]) / np.where(w > EPS, w, 1.0)[:, None]
    lam, *_, ok = _offset_hits_ray(poly, r, c1[on_edge], dirs)
    last = np.where(ok, lam, -np.inf).max(axis=1)
    good = (np.abs(last - w) <= 1e-6 * np.maximum(1.0, w)) & (w >= smin - 1e-9) & (w <= smax + 1e-9)
    c2, q2 = c2.copy(), q2.copy()
    c2[on_edge[good]] = cs[good]
    q2[on_edge[good]] = qs[good]
    return c2, q2


def _free_widths(lo: float, hi: float, fractions: tuple[float, ...]) -> FloatArray:
    w = lo + np.asarray(fractions, dtype=float) * (hi - lo)
    return np.unique(w)[::-1].copy()


def _two_point_single(world: World, grip: TwoPointGripper, smp: _Samples, opts: GraspOptions) -> _Rows:
    """One-finger grasps of the two-point model: finger 1 on each sample, finger 2 at
    ``orientations`` directions and each free width, kept if it stays off the object."""
    r = float(grip.finger_radius)
    k = opts.orientations
    if k == 0:
        return _Rows.empty()
    widths = _free_widths(*grip.spacing, opts.free_widths)
    c1 = smp.point + r * smp.normal
    s, nw = c1.shape[0], widths.size
    ang = 2.0 * np.pi * np.arange(k) / k
    si = np.repeat(np.arange(s), k * nw)
    ai = np.tile(np.repeat(np.arange(k), nw), s)
    wv = np.tile(widths, s * k)
    u = _rot(smp.normal[si], ang[ai])
    c2 = c1[si] + wv[:, None] * u
    clear = shapely.distance(world.object.polygon.shapely, shapely.points(c2)) - r
    keep = clear > opts.contact_tol
    si, u, wv, c2 = si[keep], u[keep], wv[keep], c2[keep]
    gpose = _frame(c1[si] + 0.5 * wv[:, None] * u, u)
    return _one_finger_rows(gpose, wv, np.zeros(si.size, dtype=np.int64), smp.point[si], -smp.normal[si],
                            smp.feature[si], FingerPart.CIRCLE)


# --------------------------------------------------------------------------------------
# Configuration II: polyline gripper
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Pad:
    """The pad of a polyline finger in the finger's own frame (finger 2: body x >= 0)."""

    y0: float  # tip end
    y1: float  # upper end

    @staticmethod
    def of(finger: Polygon) -> "_Pad":
        e = finger.edges
        on = (np.abs(e[:, 0, 0]) <= EPS) & (np.abs(e[:, 1, 0]) <= EPS)
        if not on.any() or np.min(finger.vertices[:, 0]) < -EPS:
            raise GeometryError("polyline finger: needs its contact pad on x = 0 and its body at x >= 0")
        ys = e[on][:, :, 1]
        return _Pad(float(ys.min()), float(ys.max()))

    @property
    def mid(self) -> float:
        """The pad's middle height: the centre of the ``flip`` rotation."""
        return 0.5 * (self.y0 + self.y1)

    def height(self, fraction: FloatArray) -> FloatArray:
        return self.y0 + fraction * (self.y1 - self.y0)

    def part(self, y: FloatArray, eps: float) -> NDArray[np.int8]:
        """:class:`FingerPart` of pad contacts at heights ``y``: the tip corner or the pad."""
        return np.where(np.abs(y - self.y0) <= eps, FingerPart.TIP, FingerPart.PAD).astype(np.int8)


def _close_finger(obj: FloatArray, finger: FloatArray, pad: _Pad, scale: float
                  ) -> tuple[FloatArray, IntArray, FloatArray, NDArray[np.int8], BoolArray]:
    """Close a finger (body at x <= 0, pad on x = 0) along +X onto the object.

    ``obj`` (R, N, 2) is the object's boundary in the closing frame (X the closing
    direction, Y the gripper's y axis), ``finger`` (F, 2) the finger polygon with its pad
    on X = 0.

    The finger placed with its pad at ``X = s`` first touches the object at the smallest
    ``s`` at which a finger edge meets an object vertex or a finger vertex meets an object
    edge (a translation's first contact is always one of these). Every event at that
    ``s`` is a contact; the grasp is valid only if all lie on the pad (or its ends). The
    contact reported is the candidate nearest to the pad's middle height: a flush object
    edge stands for the midpoint of its overlap with the pad, other events for their
    point. The rule depends on the gripper pose only, and is symmetric under ``flip``.

    Returns pad position s (R,), feature code (R,) (edge i, or N + j for an object
    vertex), the edge parameter t of the contact on edge ``feature`` (R,) (0 for a
    vertex), :class:`FingerPart` (R,) and validity (R,).
    """
    r, n, _ = obj.shape
    ox, oy = obj[..., 0], obj[..., 1]
    ox1, oy1 = np.roll(ox, -1, axis=1), np.roll(oy, -1, axis=1)
    fx, fy = finger[:, 0], finger[:, 1]
    fx1, fy1 = np.roll(fx, -1), np.roll(fy, -1)
    eps = _COINCIDENT * scale
    mid = pad.mid

    # (a) object vertex j meets finger edge k: s = X_j - x_k(Y_j).
    dy_f = fy1 - fy
    okf = np.abs(dy_f) > eps
    tf = (oy[..., None] - fy) / np.where(okf, dy_f, 1.0)  # (R, N, F)
    in_f = okf & (tf >= -eps) & (tf <= 1.0 + eps)
    xk = fx + np.clip(tf, 0.0, 1.0) * (fx1 - fx)
    s_a = np.where(in_f, ox[..., None] - xk, np.inf)
    # (b) finger vertex k meets object edge i: s = x_i(y_k) - x_k.
    dy_o = oy1 - oy  # (R, N)
    oko = np.abs(dy_o) > eps
    to = (fy[None, None, :] - oy[..., None]) / np.where(oko, dy_o, 1.0)[..., None]  # (R, N, F)
    in_o = oko[..., None] & (to >= -eps) & (to <= 1.0 + eps)
    to = np.clip(to, 0.0, 1.0)
    xi = ox[..., None] + to * (ox1 - ox)[..., None]
    s_b = np.where(in_o, xi - fx, np.inf)

    s = np.minimum(s_a.min(axis=(1, 2)), s_b.min(axis=(1, 2)))
    valid = np.isfinite(s)
    s_safe = np.where(valid, s, 0.0)
    at_a = s_a <= s_safe[:, None, None] + eps
    at_b = s_b <= s_safe[:, None, None] + eps
    # On the pad: an (a) event whose hit point has x = 0 within the pad's height; a (b)
    # event from a finger vertex on the pad.
    pad_a = (np.abs(xk) <= eps) & (oy[..., None] >= pad.y0 - eps) & (oy[..., None] <= pad.y1 + eps)
    pad_v = (np.abs(fx) <= eps) & (fy >= pad.y0 - eps) & (fy <= pad.y1 + eps)
    valid &= ~(at_a & ~pad_a).any(axis=(1, 2)) & ~(at_b & ~pad_v[None, None, :]).any(axis=(1, 2))

    # Candidates: flush edges (overlap midpoint), (b) events (edge points), (a) events
    # (object vertices on the pad).
    flush = oko & (np.abs(ox - s_safe[:, None]) <= eps) & (np.abs(ox1 - s_safe[:, None]) <= eps)
    lo = np.maximum(np.minimum(oy, oy1), pad.y0)
    hi = np.minimum(np.maximum(oy, oy1), pad.y1)
    flush &= hi > lo + eps
    y_fl = 0.5 * (lo + hi)
    t_fl = (y_fl - oy) / np.where(oko, dy_o, 1.0)
    # A flush edge stands for its whole overlap: the events at its ends and on it are
    # subsumed (as an edge-edge principal contact subsumes its vertex contacts).
    flush_v = flush | np.roll(flush, 1, axis=1)  # vertex i ends edges i and i-1
    at_start = to <= eps
    at_end = to >= 1.0 - eps
    sub_b = flush[..., None] | (at_start & flush_v[..., None]) | (at_end & np.roll(flush_v, -1, axis=1)[..., None])
    at_b_pad = at_b & pad_v[None, None, :] & ~sub_b
    at_a_pad = (at_a & pad_a).any(axis=2) & ~flush_v
    cost = np.concatenate([
        np.where(flush, np.abs(y_fl - mid), np.inf),
        np.where(at_b_pad, np.abs(fy - mid), np.inf).reshape(r, -1),
        np.where(at_a_pad, np.abs(oy - mid), np.inf),
    ], axis=1)  # (R, N + N F + N)
    best = np.argmin(cost, axis=1)
    rows = np.arange(r)
    valid &= np.isfinite(cost[rows, best])

    nf = finger.shape[0]
    kind = np.where(best < n, 0, np.where(best < n + n * nf, 1, 2))
    idx_fl = np.clip(best, 0, n - 1)
    idx_b = np.clip(best - n, 0, n * nf - 1)
    idx_a = np.clip(best - n - n * nf, 0, n - 1)
    edge_b, fing_b = idx_b // nf, idx_b % nf
    y = np.select([kind == 0, kind == 1], [y_fl[rows, idx_fl], fy[fing_b]], oy[rows, idx_a])
    feature = np.select([kind == 0, kind == 1], [idx_fl, edge_b], n + idx_a).astype(np.int64)
    t = np.select([kind == 0, kind == 1], [t_fl[rows, idx_fl], to[rows, edge_b, fing_b]], 0.0)
    return s, feature, t, pad.part(y, eps), valid


def _polyline_pairs(world: World, grip: PolylineGripper, pad: _Pad, smp: _Samples, opts: GraspOptions) -> _Rows:
    """Two-finger grasps of the polyline model: both pads closed onto the object.

    A closing is fixed by the gripper's x axis ``e_x`` and the band offset ``y0`` (the
    origin's coordinate along ``e_y``). Axes: ``e_x = n_i`` (finger 2 flush on edge i) and
    ``e_x = -n_i`` (finger 1 flush), and the fan normals of convex vertices with both
    signs. Band offsets: each sample point ``p`` of that edge (vertex) at each pad height
    ``a``: ``y0 = p . e_y - a``. Each finger then closes along e_x onto the object.
    """
    poly = world.object.polygon
    heights = pad.height(np.asarray(opts.pad_heights, dtype=float))
    nh = heights.size
    # Rows: sample x sign (finger 2 on the sample: e_x = n; finger 1: e_x = -n) x height.
    sign = np.array([1.0, -1.0])
    si = np.repeat(np.arange(smp.point.shape[0]), 2 * nh)
    sg = np.tile(np.repeat(sign, nh), smp.point.shape[0])
    a = np.tile(heights, 2 * smp.point.shape[0])
    ex = sg[:, None] * smp.normal[si]
    ey = _perp(ex)
    y0 = np.sum(smp.point[si] * ey, axis=1) - a

    v = poly.vertices
    scale = max(1.0, float(np.max(np.abs(v))))
    X = v[None, :, :] @ ex[:, :, None]  # (R, N, 1)
    Y = v[None, :, :] @ ey[:, :, None]
    Xo, Yo = X[..., 0], Y[..., 0] - y0[:, None]
    f1 = grip.mirrored_finger.vertices  # body x <= 0, pad on x = 0
    # Finger 1 closes along +X; finger 2 along -X, i.e. +X in the mirrored frame (X -> -X)
    # where its shape is finger 1's. Closing ignores the vertex order, so feature codes
    # and edge parameters carry over unchanged.
    s1, fe1, t1, p1, ok1 = _close_finger(np.stack([Xo, Yo], axis=-1), f1, pad, scale)
    s2m, fe2, t2, p2, ok2 = _close_finger(np.stack([-Xo, Yo], axis=-1), f1, pad, scale)
    s2 = -s2m
    width = s2 - s1
    wmin, wmax = (float(w) for w in grip.opening)
    ok = ok1 & ok2 & (width >= wmin - 1e-9) & (width <= wmax + 1e-9)
    origin = 0.5 * (s1 + s2)[:, None] * ex + y0[:, None] * ey
    gpose = _frame(origin, ex)
    q1, nn1 = _feature_point(poly, fe1, t1, ex)
    q2, nn2 = _feature_point(poly, fe2, t2, -ex)
    rows = _Rows(gpose, width, np.stack([q1, q2], axis=1), np.stack([nn1, nn2], axis=1),
                 np.stack([fe1, fe2], axis=1), np.stack([p1, p2], axis=1))
    return rows.take(np.flatnonzero(ok))


def _feature_point(poly: Polygon, feature: IntArray, t: FloatArray, pad_normal: FloatArray
                   ) -> tuple[FloatArray, FloatArray]:
    """Contact point and inward normal of a pad contact: a point of edge ``feature`` at
    parameter ``t`` (normal: minus the edge's outward normal) or vertex ``feature - N``
    (normal: the pad's, ``pad_normal`` (R, 2), pointing into the object)."""
    n = len(poly)
    is_v = feature >= n
    e = np.where(is_v, 0, feature)
    vtx = np.where(is_v, feature - n, 0)
    pe = poly.vertices[e] + t[:, None] * poly.edge_vectors[e]
    point = np.where(is_v[:, None], poly.vertices[vtx], pe)
    normal = np.where(is_v[:, None], pad_normal, -poly.normals[e])
    return point, normal


def _polyline_single(world: World, grip: PolylineGripper, pad: _Pad, smp: _Samples, opts: GraspOptions) -> _Rows:
    """One-finger grasps of the polyline model, for each finger k in {1, 2}:

    - pad flush on each edge sample (``e_x = -+n``), the sample at each pad height; the
      contact reported is the midpoint of the pad's overlap with the edge (as in
      :func:`_close_finger`, so that it depends on the gripper pose only);
    - pad on each convex vertex along each fan normal, the vertex at each pad height;
    - fingertip corner on each edge sample, the approach axis turned from the edge's
      normal by each tip angle, the finger body tilted away from the edge;

    each at every free width, kept if the free finger stays off the object.
    """
    poly = world.object.polygon
    n = len(poly)
    widths = _free_widths(*grip.opening, opts.free_widths)
    heights = pad.height(np.asarray(opts.pad_heights, dtype=float))
    s = smp.point.shape[0]
    edge_rows = np.flatnonzero(smp.feature < n)

    # Pad contacts: (sample, finger, height); finger 2 has e_x = n, finger 1 e_x = -n.
    nh = heights.size
    si = np.repeat(np.arange(s), 2 * nh)
    fk = np.tile(np.repeat([0, 1], nh), s)
    a = np.tile(heights, 2 * s)
    sign = np.where(fk == 1, 1.0, -1.0)  # the pad of finger k lies at x = sign w / 2
    ex = sign[:, None] * smp.normal[si]
    # Fingertip corners: (edge sample, finger, angle); e_y = R(+-beta) n.
    ang = np.radians(np.asarray(opts.tip_angles_deg, dtype=float))
    na = ang.size
    sj = np.repeat(edge_rows, 2 * na)
    fj = np.tile(np.repeat([0, 1], na), edge_rows.size)
    sign_j = np.where(fj == 1, 1.0, -1.0)
    ex_t = -_perp(_rot(smp.normal[sj], np.tile(ang, 2 * edge_rows.size) * sign_j))
    si = np.concatenate([si, sj])
    fk = np.concatenate([fk, fj])
    a = np.concatenate([a, np.full(sj.size, pad.y0)])
    ex = np.concatenate([ex, ex_t])
    sign = np.concatenate([sign, sign_j])
    ey = _perp(ex)
    is_pad = np.arange(si.size) < si.size - sj.size
    feat = smp.feature[si]
    is_v = feat >= n

    # Contact point, normal (into the object) and finger part.
    point = smp.point[si].copy()
    e = np.where(is_v, 0, feat)
    flush = is_pad & ~is_v
    # Gripper-frame heights of the edge's ends: (v - p) . e_y + a.
    ya = np.sum((poly.vertices[e] - point) * ey, axis=1) + a
    yb = np.sum((poly.vertices[(e + 1) % n] - point) * ey, axis=1) + a
    lo = np.maximum(np.minimum(ya, yb), pad.y0)
    hi = np.minimum(np.maximum(ya, yb), pad.y1)
    t = (0.5 * (lo + hi) - ya) / np.where(np.abs(yb - ya) > EPS, yb - ya, 1.0)
    point[flush] = (poly.vertices[e] + t[:, None] * poly.edge_vectors[e])[flush]
    normal = np.where(is_v[:, None], -sign[:, None] * ex, -poly.normals[e])
    height = np.where(flush, 0.5 * (lo + hi), a)
    part = pad.part(height, _COINCIDENT * max(1.0, float(np.max(np.abs(poly.vertices)))))

    nw = widths.size
    rep = np.repeat(np.arange(si.size), nw)
    wv = np.tile(widths, si.size)
    origin = smp.point[si[rep]] - (sign[rep] * 0.5 * wv)[:, None] * ex[rep] - a[rep][:, None] * ey[rep]
    gpose = _frame(origin, ex[rep])
    rows = _one_finger_rows(gpose, wv, fk[rep], point[rep], normal[rep], feat[rep], part[rep])
    # The free finger must stay off the object.
    fs = collision.finger_shapes(grip, gpose, wv)
    assert fs.polygons is not None
    free_poly = fs.polygons[np.arange(rep.size), 1 - fk[rep]]
    clear = shapely.distance(world.object.polygon.shapely, shapely.polygons(free_poly))
    return rows.take(np.flatnonzero(clear > opts.contact_tol))


# --------------------------------------------------------------------------------------
# Assembly: object overlap, flips, de-duplication
# --------------------------------------------------------------------------------------


def _flip(rows: _Rows, pad: _Pad | None, eps: float) -> _Rows:
    """The ``flip`` of each row: the gripper turned by pi in the plane about the
    gripper-frame point ``(0, y_m)``, so that the fingers swap places onto the same
    contacts. Two-point: ``y_m = 0`` (the circles are point-symmetric). Polyline:
    ``y_m`` the pad's middle height, which maps each pad segment onto the other's (a
    contact at pad height ``a`` moves to height ``2 y_m - a``; the finger parts are
    re-labelled by height). The flip of a flip is the identity."""
    g = rows.gripper
    new = g.copy()
    new[:, 2] = wrap_angle(g[:, 2] + np.pi)
    part = rows.part[:, ::-1].copy()
    contact = rows.contact[:, ::-1].copy()
    if pad is not None:
        ey = np.stack([-np.sin(g[:, 2]), np.cos(g[:, 2])], axis=1)
        new[:, :2] = g[:, :2] + 2.0 * pad.mid * ey
        h = 2.0 * pad.mid - np.sum((contact - g[:, None, :2]) * ey[:, None, :], axis=2)
        part = np.where(part == FingerPart.NONE, part, pad.part(h, eps)).astype(np.int8)
    return _Rows(new, rows.width.copy(), contact, rows.normal[:, ::-1].copy(), rows.feature[:, ::-1].copy(), part)


def _keys(rows: _Rows) -> IntArray:
    """Integer keys identifying a grasp: pose and width on a 1e-5 grid, touching parts."""
    q = 1e-5
    g = rows.gripper
    cols = [g[:, 0] / q, g[:, 1] / q, np.cos(g[:, 2]) / q, np.sin(g[:, 2]) / q, rows.width / q]
    k = np.rint(np.stack(cols, axis=1)).astype(np.int64)
    return np.concatenate([k, rows.part.astype(np.int64)], axis=1)


def _object_free(world: World, rows: _Rows, tol: float) -> _Rows:
    if not len(rows):
        return rows
    hit = collision.gripper_object_overlap(world, np.zeros(3), rows.gripper, rows.width, tol)
    return rows.take(np.flatnonzero(~hit))


def _arclength(poly: Polygon, feature: IntArray, contact: FloatArray) -> FloatArray:
    n = len(poly)
    cum = np.concatenate([[0.0], np.cumsum(poly.edge_lengths)[:-1]])
    none = feature < 0
    is_v = feature >= n
    e = np.where(none | is_v, 0, feature)
    along = np.linalg.norm(contact - poly.vertices[e], axis=-1)
    out = np.where(is_v, cum[np.where(is_v, feature - n, 0)], cum[e] + along)
    return np.where(none, np.nan, out)


def enumerate_grasps(world: World, options: GraspOptions | None = None) -> GraspSet:
    """Enumerate the discrete grasp set of the world's gripper on its object.

    Parameters
    ----------
    world : World
        Object, gripper (two-point or polyline) and friction; the environment is unused.
    options : GraspOptions, optional
        Sampling choices (``samples_per_edge`` is the scenario's ``K``).

    Returns
    -------
    GraspSet
        Row 0 the no-contact grasp, then the two-finger grasps, then the one-finger
        grasps, each block followed by its flips; no two rows share pose, width and
        touching parts. Deterministic.

    Examples
    --------
    >>> from geometry.world import (Environment, Friction, TwoPointGripper, World,
    ...                             make_object)
    >>> w = World(make_object([[0, 0], [70, 0], [70, 150], [0, 150]]), Environment(()),
    ...           TwoPointGripper(5.0, (90.0, 90.0)), Friction(0.2, 0.6))
    >>> gs = enumerate_grasps(w, GraspOptions(samples_per_edge=10))
    >>> int(gs.n_touching[0]), bool((gs.n_touching == 2).any())
    (0, True)
    """
    opts = options or GraspOptions()
    grip = world.gripper
    poly = world.object.polygon
    smp = _boundary_samples(poly, opts.samples_per_edge, opts.vertex_fan, opts.edge_offsets)
    pad: _Pad | None = None
    if isinstance(grip, TwoPointGripper):
        pairs = _two_point_pairs(world, grip, smp, opts)
        single = _two_point_single(world, grip, smp, opts)
    else:
        pad = _Pad.of(grip.finger)
        pairs = _polyline_pairs(world, grip, pad, smp, opts)
        single = _polyline_single(world, grip, pad, smp, opts)
    eps = _COINCIDENT * max(1.0, float(np.max(np.abs(poly.vertices))))
    blocks = []
    for rows in (pairs, single):
        rows = _object_free(world, rows, opts.tol)
        flips = _object_free(world, _flip(rows, pad, eps), opts.tol)
        blocks += [rows, flips]
    allrows = _Rows.concat(blocks)
    keys = _keys(allrows)
    first = np.sort(row_groups(keys)[1])
    allrows, keys = allrows.take(first), keys[first]

    # flipped[g]: the row whose key equals the key of flip(g).
    fkeys = _keys(_flip(allrows, pad, eps))
    inv, _ = row_groups(np.concatenate([keys, fkeys]))
    g = len(allrows)
    row_of = np.full(int(inv.max(initial=-1)) + 1, -1, dtype=np.int64)
    row_of[inv[:g]] = np.arange(g)
    flipped = row_of[inv[g:]]

    none = _Rows(np.full((1, 3), np.nan), np.full(1, np.nan), np.full((1, 2, 2), np.nan),
                 np.full((1, 2, 2), np.nan), np.full((1, 2), -1, dtype=np.int64), np.zeros((1, 2), dtype=np.int8))
    out = _Rows.concat([none, allrows])
    flipped = np.concatenate([[-1], np.where(flipped >= 0, flipped + 1, -1)])
    gs = GraspSet(
        gripper=_ro(out.gripper, float), width=_ro(out.width, float), contact=_ro(out.contact, float),
        normal=_ro(out.normal, float), feature=_ro(out.feature, np.int64), part=_ro(out.part, np.int8),
        arclength=_ro(_arclength(poly, out.feature, out.contact), float), flipped=_ro(flipped, np.int64),
        n_object=len(poly), perimeter=float(poly.edge_lengths.sum()),
    )
    logger.debug("enumerated %d grasps (%d two-finger, %d one-finger) for %s",
                 len(gs), int((gs.n_touching == 2).sum()), int((gs.n_touching == 1).sum()), type(grip).__name__)
    return gs


# --------------------------------------------------------------------------------------
# Gripper against the environment
# --------------------------------------------------------------------------------------


def _env_overlap(world: World, poses: FloatArray, width: FloatArray, tol: float) -> BoolArray:
    """:func:`collision.gripper_env_overlap` (whose own pre-filters, per finger and palm,
    decide most grippers far from or deep in the solids with point predicates)."""
    if world.environment.m == 0 or poses.shape[0] == 0:
        return np.zeros(poses.shape[0], dtype=bool)
    return collision.gripper_env_overlap(world, poses, width, tol)


# --------------------------------------------------------------------------------------
# Pose-conditioned sets G_T
# --------------------------------------------------------------------------------------


def pose_conditioned(world: World, grasps: GraspSet, pose: ArrayLike, tol: float = PENETRATION_TOL) -> IntArray:
    """``G_T``: the grasps whose gripper is free of the environment at object pose ``T``.

    The world gripper of grasp ``g`` is ``T * g`` at width ``g.width``; it is kept unless
    a finger or the palm overlaps the environment (plan rule 3 at ``tol``,
    :func:`geometry.collision.gripper_env_overlap`). Widths are within limits and the
    fingers free of the object by construction of the set. Row 0 (no contact) is always
    kept.

    Parameters
    ----------
    world : World
    grasps : GraspSet
    pose : array_like
        Object pose ``(x, y, theta)``, radians.
    tol : float
        Overlap tolerance (mm).

    Returns
    -------
    ndarray of int
        Sorted indices into ``grasps``, starting with 0.
    """
    poses = grasps.world_gripper(pose)[1:]
    hit = _env_overlap(world, poses, grasps.width[1:], tol)
    return np.concatenate([[NO_CONTACT], 1 + np.flatnonzero(~hit)]).astype(np.int64)


# --------------------------------------------------------------------------------------
# Motion-conditioned sets G_m
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MotionCheckOptions:
    """Settings of :func:`motion_conditioned`.

    Attributes
    ----------
    tol : float
        Overlap tolerance (mm) of the gripper against the environment.
    contact_tol : float
        Object-environment contact tolerance (mm) of :func:`geometry.contacts.contact_points`.
    w1, w2 : float
        Weights of the quality ``S = w1 s + w2 alpha`` (alpha in radians).
    angle_iterations : int
        Bisection steps of the reaction angle (:func:`geometry.mechanics.reaction_angle_batch`).
    chunk : int
        Samples in the first batched check; grasps failing a chunk skip the later ones.
    chunk_growth : int
        Each chunk is this many times the previous one: most failing grasps fail in the
        first chunks, and the survivors are then checked in few large calls (the cost of
        a call is mostly fixed).
    alpha_samples : int
        Samples (spread coarse to fine over the segment, ends first) over which the
        reaction angle alpha is averaged: it ranks feasible grasps, it decides nothing.
    """

    tol: float = PENETRATION_TOL
    contact_tol: float = CONTACT_TOL
    w1: float = 1.0
    w2: float = 1.0
    angle_iterations: int = 8
    chunk: int = 2
    chunk_growth: int = 4
    alpha_samples: int = 4

    def __post_init__(self) -> None:
        if self.chunk < 1 or self.chunk_growth < 1 or self.angle_iterations < 0 or self.tol < 0 or self.contact_tol < 0:
            raise GeometryError(f"motion check options: chunk >= 1, angle_iterations, tol, contact_tol >= 0: {self}")


@dataclass(frozen=True, eq=False)
class MotionGrasps:
    """``G_m`` for one MoveObject segment.

    Attributes
    ----------
    indices : ndarray of int, shape (A,)
        Admissible grasps (sorted indices into the :class:`GraspSet`).
    quality : ndarray, shape (A,)
        ``S(g, m) = w1 s + w2 alpha`` per admissible grasp (lower is better).
    force_closure : ndarray of bool, shape (A,)
        The finger contacts alone are force closure (``s = 0``).
    alpha : ndarray, shape (A,)
        Mean reaction angle (radians) over the samples.
    checks : int
        Quasi-static feasibility instances (grasp x sample) decided for admissibility.
    truncated : bool
        ``max_checks`` ran out: some candidates were left undecided (and not admitted).
    rejected : ndarray of int, shape (R,)
        Candidates found inadmissible (sorted; candidates left undecided by ``max_checks``
        are in neither list).
    rejected_at : ndarray of int, shape (R,)
        For each of them, a sample (index into ``path``) at which it collides or has no
        equilibrium: the parts of the path it was not checked on may still admit it;
        ``-1`` for a one-finger grasp that needs a press no force of the ladder serves
        over the whole path (:func:`press_forces`): a part of the path may still admit it.
    rated : bool
        ``quality``, ``force_closure`` and ``alpha`` are computed (otherwise NaN / False
        placeholders: :func:`rate_motion_grasps` fills them).
    press : ndarray, shape (A,), or None
        Per admissible grasp, the normal force (N) an executor's press must hold its one
        finger at for the motion to happen (:func:`press_forces`), ``nan`` for a grasp
        that needs none; ``None``: no grasp needs one.
    """

    indices: IntArray
    quality: FloatArray
    force_closure: BoolArray
    alpha: FloatArray
    checks: int
    truncated: bool
    rejected: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    rejected_at: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    rated: bool = True
    press: FloatArray | None = None

    def __len__(self) -> int:
        return int(self.indices.shape[0])

    def press_of(self, grasp: int) -> float | None:
        """The press (N) grasp ``grasp`` executes the segment with, or ``None``."""
        if self.press is None:
            return None
        at = np.flatnonzero(self.indices == grasp)
        if not at.size or not np.isfinite(self.press[at[0]]):
            return None
        return float(self.press[at[0]])

    def take(self, keep: BoolArray) -> "MotionGrasps":
        """The same G_m with only the grasps marked in ``keep`` (aligned with ``indices``)."""
        return replace(self, indices=_ro(self.indices[keep], np.int64), quality=_ro(self.quality[keep], float),
                       force_closure=_ro(self.force_closure[keep], bool), alpha=_ro(self.alpha[keep], float),
                       press=None if self.press is None else _ro(self.press[keep], float))


@dataclass(frozen=True, eq=False)
class _EnvContacts:
    """Object-environment contacts along a path, padded to ``C`` per sample."""

    points: FloatArray  # (S, C, 2) world
    normals: FloatArray  # (S, C, 2) into the object
    mu: FloatArray  # (S, C)
    modes: NDArray[np.int8]  # (S, C)
    slide_dirs: FloatArray  # (S, C, 2)


def _env_contacts(world: World, path: FloatArray, contact_tol: float) -> _EnvContacts:
    """Environment contacts at every sample with their modes from the object's motion:
    sample j moves along T_j -> T_(j+1), the last sample along T_(J-1) -> T_J.

    At the last sample a contact that the incoming motion drives into the environment is
    the contact the segment ends by making (a block landing flat, pushed against a
    wall): the object stops there, so that contact is STICKING, not penetrating.
    """
    s = path.shape[0]
    pts, nrm, mu, live = contacts.contact_point_arrays(world, path, contact_tol)
    # Sample j's own contact points move along T_j -> T_(j+1); the last sample's are
    # where they are at T_J, so its step is T_J -> T_(J-1) reversed (the material
    # points at the last contacts, not the ones there a step before).
    here = np.arange(s)
    there = np.where(here < s - 1, here + 1, max(s - 2, 0))
    sign = np.where(here < s - 1, 1.0, -1.0)
    verts = transform_points(path, world.object.polygon.vertices)  # (S, n, 2)
    disp, rot = mechanics.pose_displacements(pts, path[here], path[there])
    disp = _edge_vertex_displacements(world, path, verts, pts, disp, here, there, contact_tol) * sign[:, None, None]
    rot = rot * sign
    modes = mechanics.classify_contacts(nrm, disp, rot[:, None], world.object.length_scale, present=live)
    codes = np.array(modes.codes, dtype=np.int8, copy=True)
    if s > 1:
        made = codes[-1] == mechanics.ContactMode.PENETRATING
        codes[-1, made] = mechanics.ContactMode.STICKING
        _corner_separations(world, path, verts, pts, codes, there, contact_tol)
    return _EnvContacts(pts, nrm, mu, codes, np.asarray(modes.slide_dirs))


def _edge_vertex_displacements(world: World, path: FloatArray, verts: FloatArray, pts: FloatArray, disp: FloatArray,
                               here: IntArray, there: IntArray, contact_tol: float) -> FloatArray:
    """``disp`` with the displacements at environment-vertex-on-object-edge contacts
    measured in the object edge's own frame. There the normal is the object edge's and
    turns with the object: the world displacement of the object's material point at the
    vertex has a normal part of order step x rotation (0.03 mm on a ladder slide's 2 mm
    step turning 1 degree) even while the edge keeps sliding over the vertex, which the
    scale-aware threshold would call separating. The environment vertex's motion in the
    object frame, reversed and turned into the world at the step's start, has no normal
    part while the contact is kept, and its tangential part is the slip along the edge."""
    env_v = world.environment.vertices[world.environment.vertex_convex]
    if not env_v.size:
        return disp
    at_env = np.linalg.norm(pts[:, :, None, :] - env_v[None, None, :, :], axis=3).min(axis=2) <= contact_tol
    at_obj = np.linalg.norm(pts[:, :, None, :] - verts[:, None, :, :], axis=3).min(axis=2) <= contact_tol
    ev = at_env & ~at_obj
    if not ev.any():
        return disp
    j, k = np.nonzero(ev)
    a, b = path[here[j]], path[there[j]]
    p = pts[j, k]

    def to_object(pose: FloatArray, q: FloatArray) -> FloatArray:
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        dx, dy = q[:, 0] - pose[:, 0], q[:, 1] - pose[:, 1]
        return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)

    dq = to_object(b, p) - to_object(a, p)  # the vertex's motion over the object edge
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    out = np.array(disp, dtype=float, copy=True)
    out[j, k] = -np.stack([c * dq[:, 0] - s * dq[:, 1], s * dq[:, 0] + c * dq[:, 1]], axis=1)
    return out


def _corner_separations(world: World, path: FloatArray, verts: FloatArray, pts: FloatArray,
                        codes: NDArray[np.int8], nxt: IntArray, contact_tol: float) -> None:
    """In place: a contact at an object vertex sitting on an environment vertex has no
    single normal (the one reported is one edge's), so "penetrating" along it says
    nothing; whether the motion pushes into the environment there is the polygons'
    question. Where the object at the next sample overlaps nothing (a ladder slide's
    top corner leaving the slot's lip for the wall below it), such a contact separates."""
    pen = codes[:-1] == mechanics.ContactMode.PENETRATING
    if not pen.any():
        return
    j, k = np.nonzero(pen)
    at_obj = np.linalg.norm(verts[j] - pts[j, k][:, None, :], axis=2).min(axis=1) <= contact_tol
    env_v = world.environment.vertices
    at_env = np.linalg.norm(env_v[None, :, :] - pts[j, k][:, None, :], axis=2).min(axis=1) <= contact_tol
    corner = at_obj & at_env
    if not corner.any():
        return
    j, k = j[corner], k[corner]
    free = ~collision.object_env_overlap(world, path[nxt[j]])
    codes[j[free], k[free]] = mechanics.ContactMode.SEPARATING


def _instances(world: World, grasps: GraspSet, rows: IntArray, path: FloatArray, env: _EnvContacts,
               samples: IntArray, *, with_fingers: bool = False
               ) -> tuple[mechanics.Contacts | None, mechanics.Contacts, FloatArray]:
    """Contacts of every (grasp, sample) pair, grasp-major: all contacts (B, C + 2), the
    environment's then the two fingers', the world COM (B, 2) and, if ``with_fingers``,
    the finger contacts alone (B, 2; else None). Finger contacts move with the object, so
    they are STICKING; a finger that does not touch is ABSENT.

    Each field is one buffer: every grasp's block is a copy of one (K, C + 2) template of
    the samples' environment contacts, and the finger slots are computed sample-major, on
    long contiguous runs of grasps, by the same floating-point operations in the same order
    as ``c qx - s qy + x`` (a normal: that, less ``x``), then copied into place."""
    a, k = rows.size, samples.size
    b = a * k
    p = path[samples]
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    ce = env.points.shape[1]
    n_all = ce + 2
    q0, n0, modes0 = grasps._finger_rows
    mu0 = grasps._finger_mu(world)

    def filled(field: np.ndarray, dtype: type = float) -> np.ndarray:  # (A, K, C + 2, ...) from the template
        tmpl = np.zeros((k, n_all) + field.shape[2:], dtype=dtype)
        tmpl[:, :ce] = field[samples]
        out = np.empty((a,) + tmpl.shape, dtype=dtype)
        out[...] = tmpl
        return out

    points, normals, slide = filled(env.points), filled(env.normals), filled(env.slide_dirs)
    mu, modes = filled(env.mu), filled(env.modes, np.int8)
    mu[:, :, ce:] = mu0[rows][:, None, :]
    modes[:, :, ce:] = modes0[rows][:, None, :]
    ck, sk = c[:, None, None], s[:, None, None]  # (K, 1, 1) against (1, A, 2) contiguous grasps
    px, py = p[:, 0, None, None], p[:, 1, None, None]
    for q, out, normal in ((q0[rows], points, False), (n0[rows], normals, True)):
        qx, qy = np.ascontiguousarray(q[:, :, 0])[None], np.ascontiguousarray(q[:, :, 1])[None]
        for ax, (first, second, sub, shift) in enumerate(((ck, sk, True, px), (sk, ck, False, py))):
            t1 = first * qx  # (K, A, 2)
            t2 = second * qy
            if sub:  # x = c qx - s qy + px
                np.subtract(t1, t2, out=t1)
            else:  # y = s qx + c qy + py
                np.add(t1, t2, out=t1)
            np.add(t1, shift, out=t1)
            if normal:
                np.subtract(t1, shift, out=t1)
            out[:, :, ce:, ax] = t1.transpose(1, 0, 2)
    points, normals = points.reshape(b, n_all, 2), normals.reshape(b, n_all, 2)
    mu, modes, slide = mu.reshape(b, n_all), modes.reshape(b, n_all), slide.reshape(b, n_all, 2)
    allc = mechanics.Contacts.trusted(points, normals, mu, modes, slide)
    fingers = None
    if with_fingers:
        fingers = mechanics.Contacts.trusted(np.ascontiguousarray(points[:, ce:]), np.ascontiguousarray(normals[:, ce:]),
                                             np.ascontiguousarray(mu[:, ce:]), np.ascontiguousarray(modes[:, ce:]))
    com0 = world.object.com
    cx = c * com0[0] - s * com0[1] + p[:, 0]
    cy = s * com0[0] + c * com0[1] + p[:, 1]
    com = np.empty((a, k, 2))
    com[:, :, 0] = cx
    com[:, :, 1] = cy
    return fingers, allc, com.reshape(b, 2)


def class_representatives(world: World, grasps: GraspSet, rows: IntArray) -> tuple[IntArray, IntArray]:
    """``rows`` by their finger contacts (:meth:`GraspSet.contact_classes`): one
    representative row per class (its first in ``rows``) and, per row, the index of its
    class's representative. The instances of a class are the same arrays bit for bit, so
    a per-instance test of the representatives, indexed by the second, answers for all."""
    _, first, of = np.unique(grasps.contact_classes(world)[rows], return_index=True, return_inverse=True)
    return rows[first], of.reshape(-1)


def _spread_order(n: int) -> IntArray:
    """0..n-1 ordered coarse to fine: the two ends, the middle, the quarters, ... (each
    index once), so that the first chunks of a path's samples cover all of it."""
    if n <= 2:
        return np.arange(n, dtype=np.int64)
    out = [0, n - 1]
    seen = {0, n - 1}
    step = n - 1
    while step > 1:
        half = step / 2.0
        for k in np.arange(half, n - 1, step):
            i = int(round(k))
            if i not in seen:
                seen.add(i)
                out.append(i)
        step = half
    out.extend(i for i in range(n) if i not in seen)
    return np.asarray(out, dtype=np.int64)


def motion_conditioned(world: World, grasps: GraspSet, path: ArrayLike, candidates: ArrayLike,
                       options: MotionCheckOptions | None = None, *, max_checks: int | None = None,
                       verified: ArrayLike = (), recheck: ArrayLike = (), rate: bool = True,
                       free_at: ArrayLike = ()) -> MotionGrasps:
    """``G_m``: the grasps that can execute a MoveObject segment, with their quality.

    A candidate ``g`` (normally ``G_T`` at both ends) is admissible iff at least one
    finger touches and at every sample ``T_j`` of ``path``:

    (a) the world gripper ``T_j * g`` overlaps no solid (plan rule 3 at ``tol``);
    (b) the contact modes are identified: the object-environment contacts
        (:func:`geometry.contacts.contact_points` at ``T_j``) take their mode from the
        object's motion ``T_j -> T_(j+1)`` (the last sample from ``T_(J-1) -> T_J``)
        against the static environment; the finger contacts move with the object (the
        grasp is fixed in the object frame) and are STICKING;
    (c) forces inside the mode-dependent Coulomb cones of all these contacts balance
        the weight at the centre of mass (:func:`geometry.mechanics.feasible_batch`).

    The quality of an admissible grasp is ``S = w1 s + w2 alpha`` as in
    :func:`geometry.mechanics.grasp_quality`, batched over grasps: ``s = 0`` iff the
    finger contacts alone are force closure (invariant under the rigid motion, so tested
    once in the object frame), ``alpha`` the mean over ``alpha_samples`` samples spread over
    the segment (its ends first) of
    :func:`geometry.mechanics.reaction_angle_batch`.

    Parameters
    ----------
    world : World
    grasps : GraspSet
    path : array_like, shape (J + 1, 3)
        Object poses along the segment (radians), a few mm / degrees apart.
    candidates : array_like of int
        Grasp indices to test; row 0 and grasps without a finger contact are skipped.
    options : MotionCheckOptions, optional
    max_checks : int, optional
        Budget of feasibility instances; when it runs out the undecided candidates are
        not admitted and ``truncated`` is set.
    verified : array_like of int, optional
        Candidates already known to pass (a) and (c) at every sample of ``path`` except the
        ``recheck`` ones (a bisected segment's half, whose samples are its parent's): they
        are checked only there.
    recheck : array_like of int, optional
        Sample indices at which ``verified`` candidates are checked after all.
    rate : bool
        Compute the quality of the admissible grasps (most of the cost of an admissible
        set); ``False`` leaves it to :func:`rate_motion_grasps` (``rated`` is then False).
    free_at : array_like of int, optional
        Samples at which every candidate is known to be collision-free (the segment's
        ends when the candidates are G_T there at a tolerance at most ``tol``): (a) is not
        tested again there.

    Returns
    -------
    MotionGrasps
    """
    opts = options or MotionCheckOptions()
    p = np.asarray(path, dtype=float).reshape(-1, 3)
    if p.shape[0] == 0:
        raise GeometryError("motion_conditioned: the path needs at least one pose")
    cand = np.unique(np.asarray(candidates, dtype=np.int64).reshape(-1))
    if cand.size and (cand[0] < 0 or cand[-1] >= len(grasps)):
        raise GeometryError(f"motion_conditioned: candidate indices must lie in [0, {len(grasps)})")
    cand = cand[(cand != NO_CONTACT) & (grasps.n_touching[cand] >= 1)]
    n_s = p.shape[0]
    known = np.intersect1d(np.asarray(verified, dtype=np.int64).reshape(-1), cand)
    again = np.unique(np.asarray(recheck, dtype=np.int64).reshape(-1))
    if again.size and (again[0] < 0 or again[-1] >= n_s):
        raise GeometryError(f"motion_conditioned: recheck samples must lie in [0, {n_s})")
    cand = np.setdiff1d(cand, known)
    free = np.unique(np.asarray(free_at, dtype=np.int64).reshape(-1))

    # (a) collision-free and (b) + (c) feasible at every sample: chunk by chunk of samples
    # spread over the path (ends and middle first), pruning the candidates that fail
    # either test before the next chunk, so that most failures cost a few samples.
    env = _env_contacts(world, p, opts.contact_tol) if cand.size or known.size else None
    length = world.object.length_scale
    checks = 0
    truncated = False
    rejected: list[IntArray] = []
    rejected_at: list[IntArray] = []

    def check(alive: IntArray, samples: IntArray) -> IntArray:
        """The grasps of ``alive`` that pass at ``samples``; the others are recorded."""
        nonlocal checks
        if not alive.size or not samples.size:
            return alive
        # The quasi-static test first: it is ~10x cheaper per instance than the polyline
        # collision test and rejects most candidates.
        assert env is not None
        rep, of = class_representatives(world, grasps, alive)  # the same contacts, the same answer
        _, allc, com = _instances(world, grasps, rep, p, env, samples)
        ok = mechanics.feasible_batch(allc, com, length).reshape(rep.size, samples.size)[of]
        checks += int(ok.size)
        bad = ~ok.all(axis=1)
        rejected.append(alive[bad])
        rejected_at.append(samples[np.argmin(ok[bad], axis=1)])
        alive = alive[~bad]
        samples = samples[~np.isin(samples, free)]
        if not alive.size or not samples.size:
            return alive
        wp = compose_batch(p[samples][None, :, :], grasps.gripper[alive][:, None, :])
        hit = _env_overlap(world, wp.reshape(-1, 3), np.repeat(grasps.width[alive], samples.size),
                           opts.tol).reshape(alive.size, samples.size)
        bad = hit.any(axis=1)
        rejected.append(alive[bad])
        rejected_at.append(samples[np.argmax(hit[bad], axis=1)])
        return alive[~bad]

    alive = cand
    order = _spread_order(n_s)
    start, size = 0, opts.chunk
    while start < n_s:
        if not alive.size:
            break
        samples = order[start:start + size]
        start, size = start + size, size * opts.chunk_growth
        if max_checks is not None and checks + alive.size * samples.size > max_checks:
            keep = max(0, (max_checks - checks) // samples.size)
            truncated = True
            alive = alive[:keep]
            if not alive.size:
                break
        alive = check(alive, samples)
    alive = np.union1d(alive, check(known, again))
    # Grasps held by position control (one finger, or a fixed-width gripper's two) whose
    # fingers would leave the object resting where it is make the motion only under a
    # press (:func:`press_forces`, one-finger grasps); those no press of the ladder serves
    # are rejected (for the path as a whole).
    press = None
    idle = _leaves_it_still(world, grasps, p, alive)
    if env is not None:
        rep, of = class_representatives(world, grasps, alive)  # both answer per instance: per class
        idle |= _falls_away(world, grasps, p, rep, env)[of]
    if idle.any():
        assert env is not None
        rep, of = class_representatives(world, grasps, alive[idle])
        force = press_forces(world, grasps, p, rep, env)[of]
        served = np.isfinite(force)
        rejected.append(alive[idle][~served])
        rejected_at.append(np.full(int((~served).sum()), -1, dtype=np.int64))  # the path as a whole
        press = np.full(alive.size, np.nan)
        press[np.flatnonzero(idle)[served]] = force[served]
        keep = ~idle
        keep[np.flatnonzero(idle)[served]] = True
        alive, press = alive[keep], press[keep]
        if not np.isfinite(press).any():
            press = None

    if rate:
        closure, alpha, quality = _rating(world, grasps, p, alive, env, opts)
    else:
        closure, alpha, quality = np.zeros(alive.size, dtype=bool), np.full(alive.size, np.nan), np.full(alive.size, np.nan)
    logger.debug("G_m: %d of %d candidates admissible over %d samples (%d feasibility checks%s)",
                 alive.size, np.asarray(candidates).size, n_s, checks, ", truncated" if truncated else "")
    rej = np.concatenate(rejected) if rejected else np.zeros(0, dtype=np.int64)
    rat = np.concatenate(rejected_at) if rejected_at else np.zeros(0, dtype=np.int64)
    by = np.argsort(rej, kind="stable")
    return MotionGrasps(_ro(alive, np.int64), _ro(quality, float), _ro(closure, bool), _ro(alpha, float),
                        checks, truncated, _ro(rej[by], np.int64), _ro(rat[by], np.int64), rated=rate,
                        press=None if press is None else _ro(press, float))


def held_at_each(world: World, grasps: GraspSet, poses: ArrayLike, candidates: ArrayLike,
                 options: MotionCheckOptions | None = None) -> list[IntArray]:
    """``motion_conditioned(world, grasps, poses[j:j + 1], candidates, options,
    rate=False).indices`` for every pose ``j``, the poses that touch nothing decided
    together: the grasps of ``candidates`` that hold the object still at each pose, by
    the gripper and gravity alone where the object touches nothing (an air-move's holds,
    :mod:`ldhp_tamp.primitives.move_object`).

    A one-pose path has no motion: no press is asked for (:func:`_leaves_it_still` and
    :func:`_falls_away` need a moving sample), and a grasp passes iff at that pose its
    contacts balance the weight (the cone test, per instance) and the gripper overlaps no
    solid (per gripper pose). Both tests answer each (grasp, pose) pair on its own, by the
    same operations whatever else is in the batch; so the poses that touch nothing (no
    contact whose mode a path would set) are tested as one batch of pairs, and a pose that
    touches the environment is given its own call. One call instead of one per pose: the
    fixed cost of a call (the contacts at the path, the classes of finger contacts)
    dominates a single pose's.
    """
    opts = options or MotionCheckOptions()
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    cand = np.unique(np.asarray(candidates, dtype=np.int64).reshape(-1))
    if cand.size and (cand[0] < 0 or cand[-1] >= len(grasps)):
        raise GeometryError(f"held_at_each: candidate indices must lie in [0, {len(grasps)})")
    cand = cand[(cand != NO_CONTACT) & (grasps.n_touching[cand] >= 1)]
    out: list[IntArray] = [_ro(cand[:0], np.int64)] * p.shape[0]
    if not p.shape[0] or not cand.size:
        return out
    touching = contacts.contact_point_arrays(world, p, opts.contact_tol)[3].any(axis=1)
    for j in np.flatnonzero(touching):  # the modes of a one-pose path at its contacts: its own call
        out[j] = motion_conditioned(world, grasps, p[j:j + 1], cand, opts, rate=False).indices
    free = np.flatnonzero(~touching)
    if not free.size:
        return out
    q = p[free]
    env = _env_contacts(world, q, opts.contact_tol)  # no contact at any of them
    rep, of = class_representatives(world, grasps, cand)
    _, allc, com = _instances(world, grasps, rep, q, env, np.arange(free.size))
    ok = mechanics.feasible_batch(allc, com, world.object.length_scale).reshape(rep.size, free.size)[of]
    g, k = np.nonzero(ok)  # (grasp, pose) pairs that balance, grasp-major
    if g.size:
        wp = compose_batch(q[k], grasps.gripper[cand[g]])
        hit = _env_overlap(world, wp, grasps.width[cand[g]], opts.tol)
        ok[g[hit], k[hit]] = False
    for i, j in enumerate(free):
        out[j] = _ro(cand[ok[:, i]], np.int64)
    return out


def within_force_limit(world: World, grasps: GraspSet, path: ArrayLike, rows: ArrayLike, max_force: float,
                       options: MotionCheckOptions | None = None, max_samples: int = 32) -> BoolArray:
    """(len(rows),) whether each grasp of ``rows`` carries the object along ``path`` with
    every finger's normal force at most ``max_force`` (N) at every sample (up to
    ``max_samples`` of them spread over the path, its ends included): the contacts and
    modes of :func:`motion_conditioned`, one :func:`geometry.mechanics.bounded_support`
    LP per (grasp, sample), the plan rule 9 of a move-object step. ``G_m`` itself leaves
    the forces unbounded (the cone test is ~100x cheaper); a planner filters a segment's
    set with this when a plan carrying one of its grasps broke the limit."""
    opts = options or MotionCheckOptions()
    p = np.asarray(path, dtype=float).reshape(-1, 3)
    r = np.asarray(rows, dtype=np.int64).reshape(-1)
    ok = np.ones(r.size, dtype=bool)
    if not r.size or p.shape[0] == 0:
        return ok
    env = _env_contacts(world, p, opts.contact_tol)
    samples = np.unique(np.round(np.linspace(0, p.shape[0] - 1, min(p.shape[0], max_samples))).astype(np.int64))
    _, allc, com = _instances(world, grasps, r, p, env, samples)
    c = env.points.shape[1]
    finger_of = np.broadcast_to(np.concatenate([np.full(c, -1), [0, 1]]), (allc.batch, c + 2))
    res = mechanics.bounded_support(allc, com, world.object.length_scale, world.object.weight, finger_of,
                                    max_force, margin=0.0)
    return np.asarray(res.feasible, dtype=bool).reshape(r.size, samples.size).all(axis=1)


def squeezing(world: World, grasps: GraspSet, rows: ArrayLike) -> BoolArray:
    """(len(rows),) whether each grasp of ``rows`` is a pinch the gripper squeezes: both
    fingers touch and the width closes under force. The executor closes the gripper onto
    the object until its force setting (the simulation's preload), so both fingers stay on
    it whatever their normals: opposed, they hold it between them; on two faces of a
    corner, the grip drags them along the faces towards it. The force it takes is not the
    rigid model's to decide (``ldhp_tamp.executability`` leaves such waypoints to the
    physics replay). A fixed-width gripper's rigid fingers squeeze nothing; a single
    finger is held where position control puts it. Either carries force only where the
    motion pushes the object onto it."""
    r = np.asarray(rows, dtype=np.int64).reshape(-1)
    if world.gripper.fixed_width:
        return np.zeros(r.size, dtype=bool)
    return grasps.n_touching[r] == 2


#: How far (mm of gripper travel) a one-finger grasp must push into an object resting on
#: the environment alone at a segment's start for the motion to be forced, and the most
#: samples looked at (the judge's "the object may stay", ldhp_tamp.executability).
STAY_TRAVEL = 10.0
STAY_SAMPLES = 8


def _leaves_it_still(world: World, grasps: GraspSet, p: FloatArray, cand: IntArray) -> BoolArray:
    """(len(cand),) the grasps of ``cand`` held by position control (one finger, or the
    two rigid fingers of a fixed-width gripper, which do not squeeze: :func:`squeezing`)
    that cannot start the motion along ``p``: the
    object rests on the environment alone at ``p[0]`` (full cones), and over the next
    samples, up to :data:`STAY_TRAVEL` of gripper travel, no finger moving with the
    planned motion presses into the object left where it is (by more than
    ``PENETRATION_TOL``). Position control moves the fingers; the object may as well stay
    and the fingers leave it (a finger on a standing block's top face "tipping" it about
    a bottom corner rises off it; two rigid fingers hugging a block's top corner, one on
    its side and one on its top, "tip" it about the far bottom corner moving away from
    the side and along the top). Balancing forces along the path exist for such a grasp, so
    the per-sample test alone admits it; the forward problem (the judge's "the object may
    stay", which asks every grasp but a squeezing pinch) does not."""
    out = np.zeros(cand.size, dtype=bool)
    if p.shape[0] < 2 or not cand.size:
        return out
    one = np.flatnonzero(~squeezing(world, grasps, cand) & (grasps.n_touching[cand] >= 1))
    if not one.size or not contacts.rests_alone(world, p[:1])[0]:
        return out
    rows = cand[one]
    m = min(p.shape[0] - 1, STAY_SAMPLES)
    grip = compose_batch(p[:m + 1][None, :, :], grasps.gripper[rows][:, None, :])  # (A, m + 1, 3)
    travel = np.cumsum(np.linalg.norm(np.diff(grip[:, :, :2], axis=1), axis=2), axis=1)  # (A, m)
    pushed = np.zeros(rows.size, dtype=bool)
    for j in range(1, m + 1):
        live = ~pushed & (travel[:, j - 1] <= STAY_TRAVEL)
        if not live.any():
            break
        hit = collision.finger_object_overlap(world, p[0], grip[live, j], grasps.width[rows[live]], PENETRATION_TOL)
        pushed[np.flatnonzero(live)[np.asarray(hit).reshape(int(live.sum()), -1).any(axis=1)]] = True
    out[one[~pushed]] = True
    return out


def _falls_away(world: World, grasps: GraspSet, p: FloatArray, cand: IntArray, env: _EnvContacts) -> BoolArray:
    """(len(cand),) the one-finger grasps of ``cand`` that hold the object at some moving
    sample of ``p`` (every sample but the last) where it touches the environment but does
    not rest on it alone (full cones), and from which, left to gravity and the environment
    (:func:`geometry.forward.falling_accelerations`), it would move away from the finger
    and never onto it. A finger moved by position control and not pressed carries force
    only where the object leans on it, so such a grasp makes the motion only under a press
    (the judge's "a lone finger the object falls away from", ``ldhp_tamp.executability``):
    a tip continued from a tilted pose by a fingertip dragging the top, as much as one
    started from rest (:func:`_leaves_it_still`)."""
    from geometry.forward import falling_accelerations, gyration_sq

    out = np.zeros(cand.size, dtype=bool)
    if p.shape[0] < 2 or not cand.size:
        return out
    one = np.flatnonzero(grasps.n_touching[cand] == 1)
    if not one.size:
        return out
    c = env.points.shape[1]
    moving = np.arange(p.shape[0] - 1)
    touch = (env.modes[moving] != mechanics.ContactMode.ABSENT).any(axis=1)
    samples = moving[touch]
    if not samples.size:
        return out
    live = env.modes[samples] != mechanics.ContactMode.ABSENT
    com_s = transform_points(p[samples], world.object.com)[:, 0]
    rests = mechanics.feasible_batch(mechanics.Contacts.make(env.points[samples], np.where(live[..., None],
                                                                                           env.normals[samples], 0.0),
                                                             np.where(live, env.mu[samples], 0.0),
                                                             np.where(live, mechanics.ContactMode.STICKING,
                                                                      mechanics.ContactMode.ABSENT).astype(np.int8)),
                                     com_s, world.object.length_scale, margin=0.0)
    samples, live = samples[~rests], live[~rests]
    if not samples.size:
        return out
    rows = cand[one]
    _, allc, com = _instances(world, grasps, rows, p, env, samples)
    b = allc.points.shape[0]
    col = c + np.repeat(np.argmax(grasps.touching[rows], axis=1), samples.size)
    probe_p = allc.points[np.arange(b), col]
    probe_n = allc.normals[np.arange(b), col]
    present = np.tile(live, (rows.size, 1))
    falls, onto = falling_accelerations(np.nan_to_num(allc.points[:, :c]), np.nan_to_num(allc.normals[:, :c]),
                                        np.nan_to_num(allc.mu[:, :c]), present, com,
                                        gyration_sq(world.object.polygon.vertices, world.object.com),
                                        probe_p, probe_n)
    away = (falls & ~onto).reshape(rows.size, samples.size).any(axis=1)
    out[one[away]] = True
    return out


#: The normal forces a press is tried with, in multiples of the object's weight, least
#: first (capped by the gripper's ``max_force``). Not less than twice the weight: a
#: fingertip corner dragging a block at one weight creeps in the physics simulation
#: (task 2's last push: 16 mm behind after 75 mm at 1 W, 0.17 mm at 2 W; docs/design.md,
#: "Presses"), though Coulomb friction holds it there with a tenth of its cone.
PRESS_LADDER = (2.0, 4.0, 8.0)


def press_forces(world: World, grasps: GraspSet, path: ArrayLike, rows: ArrayLike,
                 env: _EnvContacts | None = None, ladder: tuple[float, ...] = PRESS_LADDER) -> FloatArray:
    """(len(rows),) the least normal force (N) of ``ladder`` (times the object's weight,
    at most the gripper's ``max_force``) with which a press of each one-finger grasp of
    ``rows`` makes the motion along ``path``; ``nan`` where none does.

    A press (the executor's guarded move, "press down": ``ldhp_tamp.plan.Press``) holds
    the finger's normal force at ``f`` through the step. With ``f`` it makes the motion
    when, tested cheapest first on the grasps still in question,

    (2) the object cannot stay where it is at the first sample: its environment contacts
        (full cones) do not balance the weight and the finger sliding over it, its force
        ``f`` along the normal and ``mu f`` along the finger's motion
        (:func:`geometry.mechanics.pressed_feasible`: one cone test, the force known);
    (3) the forward problem (:func:`geometry.forward.alternative_motions`, the finger
        pressed) has no other object motion at :data:`PRESS_FORWARD_SAMPLES` samples,
        the first among them;
    (1) at every sample the contacts and modes of :func:`motion_conditioned` (the finger
        sticking) balance the weight with the finger's normal force exactly ``f``
        (:func:`geometry.mechanics.pressed_feasible`, cone tests).

    The judge (``ldhp_tamp.executability``) solves the forward problem at every waypoint."""
    p = np.asarray(path, dtype=float).reshape(-1, 3)
    r = np.asarray(rows, dtype=np.int64).reshape(-1)
    out = np.full(r.size, np.nan)
    if not r.size or p.shape[0] < 2:
        return out
    weight = world.object.weight
    limit = getattr(world.gripper, "max_force", None)
    forces = [f * weight for f in ladder if limit is None or f * weight <= limit]
    if not forces:
        return out
    env = env if env is not None else _env_contacts(world, p, CONTACT_TOL)
    length = world.object.length_scale
    touch = grasps.touching[r]
    one = touch.sum(axis=1) == 1
    finger = np.argmax(touch, axis=1)
    c = env.points.shape[1]
    # (2) the object staying: the finger's velocity over the first motion, its slip against the object
    _, start, com0 = _instances(world, grasps, r, p, env, np.array([0]))
    a_ = np.arange(r.size)
    q = np.nan_to_num(grasps.contact[r, finger])  # the finger's contact, object frame (A, 2)
    moved = transform_points(p[1:2], q)[0] - start.points[a_, c + finger]  # (A, 2)
    nrm = start.normals[a_, c + finger]
    tang = np.stack([-nrm[:, 1], nrm[:, 0]], axis=-1)
    own = (moved * tang).sum(axis=-1)  # the finger's tangential motion
    todo = np.flatnonzero(one & (np.abs(own) > 1e-9))
    # staying, the environment keeps full cones and the finger slides over the object
    # (the object's slip against it opposes the finger's motion): its force is known
    modes = np.where(start.modes == mechanics.ContactMode.ABSENT, mechanics.ContactMode.ABSENT,
                     mechanics.ContactMode.STICKING).astype(np.int8)
    modes[a_, c + finger] = mechanics.ContactMode.SLIDING
    sdir = np.zeros(start.points.shape)
    sdir[a_, c + finger] = -np.sign(own)[:, None] * tang
    stay = mechanics.Contacts.trusted(start.points, start.normals, start.mu, modes, sdir)
    order = _spread_order(p.shape[0])
    for f in forces:
        if not todo.size:
            break
        stays = mechanics.pressed_feasible(stay.select(todo), com0[todo], length, c + finger[todo], f / weight)
        alive = todo[~stays]
        if alive.size:  # (3) no other motion under the press, where the motion starts
            alive = alive[~_press_alternatives(world, grasps, p, r[alive], finger[alive], env, f)]
        start_at, size = 0, 2
        while alive.size and start_at < order.size:  # (1) the planned motion balances with f
            samples = order[start_at:start_at + size]
            start_at, size = start_at + size, size * 4
            _, allc, com = _instances(world, grasps, r[alive], p, env, samples)
            ok = mechanics.pressed_feasible(allc, com, length, c + np.repeat(finger[alive], samples.size),
                                            f / weight).reshape(alive.size, samples.size)
            alive = alive[ok.all(axis=1)]
        out[alive] = f
        todo = np.setdiff1d(todo, alive)
    return out


#: Samples (the first, then spread over the path) at which :func:`press_forces` solves
#: the forward problem of a pressed grasp.
PRESS_FORWARD_SAMPLES = 2


def _press_alternatives(world: World, grasps: GraspSet, p: FloatArray, rows: IntArray, finger: IntArray,
                        env: _EnvContacts, force: float) -> BoolArray:
    """(len(rows),) whether the forward problem (:func:`geometry.forward.alternative_motions`)
    lets the object take another motion than the planned one under the press of
    ``force`` at some of :data:`PRESS_FORWARD_SAMPLES` samples (the first among them)."""
    from geometry.forward import MAX_CONTACTS, alternative_motions, screw_velocity

    moving = [j for j in _spread_order(p.shape[0] - 1) if j < p.shape[0] - 1]
    samples = np.array(sorted(set([0] + moving[:PRESS_FORWARD_SAMPLES - 1])), dtype=np.int64)
    a, k = rows.size, samples.size
    _, allc, com = _instances(world, grasps, rows, p, env, samples)
    c = env.points.shape[1]
    present = allc.modes != mechanics.ContactMode.ABSENT  # (a*k, C)
    p0 = np.repeat(p[samples][None], a, axis=0).reshape(-1, 3)
    p1 = np.repeat(p[samples + 1][None], a, axis=0).reshape(-1, 3)
    vel = np.zeros(allc.points.shape)
    vel[:, c:, :] = screw_velocity(p0, p1, allc.points[:, c:, :])  # the fingers move with the plan
    planned = np.column_stack([screw_velocity(p0, p1, com[:, None, :])[:, 0], wrap_angle(p1[:, 2] - p0[:, 2])])
    pressed = np.full(present.shape, np.nan)
    fk = np.repeat(finger, k)
    pressed[np.arange(a * k), c + fk] = force / world.object.weight
    bad = np.zeros(a * k, dtype=bool)
    count = present.sum(axis=1)
    ok = count <= MAX_CONTACTS  # more contacts: left to the judge (it logs them)
    for n_on in np.unique(count[ok]):
        sel = np.flatnonzero(ok & (count == n_on))
        order = np.argsort(~present[sel], axis=1, kind="stable")[:, :n_on]

        def take(x: np.ndarray, sel: IntArray = sel, order: IntArray = order) -> np.ndarray:
            return np.take_along_axis(x[sel], order[..., None] if x.ndim == 3 else order, axis=1)

        res = alternative_motions(take(allc.points), take(allc.normals), take(allc.mu), np.ones(order.shape, bool),
                                  take(vel), com[sel], world.object.length_scale, planned[sel],
                                  pressed=take(pressed))
        bad[sel] = res.ambiguous
    return bad.reshape(a, k).any(axis=1)


def _rating(world: World, grasps: GraspSet, p: FloatArray, alive: IntArray, env: _EnvContacts | None,
            opts: MotionCheckOptions) -> tuple[BoolArray, FloatArray, FloatArray]:
    """(force closure, alpha, quality S) of admissible grasps ``alive`` along poses ``p``."""
    if not alive.size:
        return np.zeros(0, dtype=bool), np.zeros(0), np.zeros(0)
    assert env is not None
    order = _spread_order(p.shape[0])
    at = np.sort(order[:max(1, opts.alpha_samples)])
    length = world.object.length_scale
    rep, of = class_representatives(world, grasps, alive)  # the same contacts, the same rating
    fingers, allc, com = _instances(world, grasps, rep, p, env, at, with_fingers=True)
    assert fingers is not None
    closure = mechanics.force_closure_batch(fingers.select(slice(None, None, at.size)), com[::at.size], length)[of]
    ang = mechanics.reaction_angle_batch(allc, com, length, iterations=opts.angle_iterations)
    ang = ang.reshape(rep.size, at.size)[of]
    fin = np.isfinite(ang)  # all of them: the samples passed the same feasibility test
    alpha = np.where(fin, ang, 0.0).sum(axis=1) / np.maximum(fin.sum(axis=1), 1)
    quality = opts.w1 * (~closure).astype(float) + opts.w2 * alpha
    return closure, alpha, quality


def rate_motion_grasps(world: World, grasps: GraspSet, path: ArrayLike, mg: MotionGrasps,
                       options: MotionCheckOptions | None = None) -> MotionGrasps:
    """``mg`` (from :func:`motion_conditioned` with ``rate=False`` on ``path``) with the
    quality of its grasps, exactly as ``rate=True`` would have computed it."""
    if mg.rated:
        return mg
    opts = options or MotionCheckOptions()
    p = np.asarray(path, dtype=float).reshape(-1, 3)
    env = _env_contacts(world, p, opts.contact_tol) if len(mg) else None
    closure, alpha, quality = _rating(world, grasps, p, np.asarray(mg.indices), env, opts)
    return replace(mg, quality=_ro(quality, float), force_closure=_ro(closure, bool), alpha=_ro(alpha, float),
                   rated=True)
