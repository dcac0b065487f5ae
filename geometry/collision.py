"""Overlap tests between the object, the gripper and the environment, batched over poses.

One overlap rule everywhere, the plan spec's rule 3 ("no penetration") at tolerance ``t``:

    bodies A and B overlap at ``t``  iff  (A ∩ B) eroded by t is non-empty
                                     iff  A ∩ B contains a closed disk of radius t
                                     iff  (A ⊖ t) ∩ (B ⊖ t) ≠ ∅,

because erosion distributes over intersection: ``(A ∩ B) ⊖ t = (A ⊖ t) ∩ (B ⊖ t)``.
Touching bodies never overlap for ``t > 0``; a strip-shaped intersection overlaps only
when it is at least ``2 t`` deep; a body thinner than ``2 t`` erodes to nothing and cannot
overlap anything. ``t = 0`` is the closed rule (touching counts).

How the rule is evaluated quickly:

- Polygons (the object, polyline fingers, the palm, the solids) are eroded once per
  tolerance in their own frame (``shapely.buffer(-t)``; an erosion may split into several
  parts or vanish; it never has holes) and cached. The static solids are eroded as their
  union. A moving polygon's eroded parts are transformed per pose in one numpy call, turned
  into a batch of shapely polygons (``shapely.polygons`` over a ``(B, V, 2)`` array) and
  tested with the vectorised, *prepared* ``shapely.intersects``.
- A circular finger (centre ``c``, radius ``r``) against a polygon ``P``: the disk eroded by
  ``t`` is the disk of radius ``r - t``, so they overlap iff ``r >= t`` and
  ``dist(c, P ⊖ t) <= r - t`` (vectorised, prepared ``shapely.dwithin``).
- Two circles: iff ``|c1 - c2| <= (r1 - t) + (r2 - t)`` with ``r1, r2 >= t``.
- Exact pre-filters spare most poses the GEOS geometry: a point predicate
  (``shapely.intersects_xy``) against the target grown by a distance ``d`` as two polygons,
  one inside the true offset region and one outside it, decides "within ``d``" for
  points not between them; a part whose bounding-disk centre is farther than its radius
  misses, a part with a vertex inside the target hits. A strictly convex part is then
  decided by exact orientation signs (Shewchuk's floating-point filter) of its edges
  against the target's boundary edges near it: a certain crossing or a target vertex
  certainly inside it hits, all certainly apart misses. Only the rest (near-degenerate
  signs, concave parts) are tested as above.

Rounded corners of an erosion (at concave corners of a polygon) are approximated by
shapely with 8 segments per quarter circle; the error is below ``0.005 t``.

Poses are ``(B, 3)`` arrays of ``(x, y, theta)`` (radians); a single ``(3,)`` pose is a
batch of one. Widths are scalars or ``(B,)`` arrays.
"""

from __future__ import annotations

import logging
import weakref
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from shapely.geometry.polygon import orient

from geometry.compiled import KERNELS
from geometry.poses import BoolArray, transform_points
from geometry.shapes import FloatArray, Polygon
from geometry.tolerances import PENETRATION_TOL
from geometry.world import Environment, Gripper, PolylineGripper, TwoPointGripper, World

__all__ = [
    "ErodedShape",
    "FingerShapes",
    "eroded_polygon",
    "eroded_environment",
    "finger_shapes",
    "polygon_env_overlap",
    "object_env_overlap",
    "finger_env_overlap",
    "palm_env_overlap",
    "gripper_env_overlap",
    "finger_object_overlap",
    "palm_object_overlap",
    "gripper_object_overlap",
    "fingers_overlap",
    "overlaps",
    "circle_overlaps",
    "finger_env_clearance",
]

logger = logging.getLogger(__name__)



# --------------------------------------------------------------------------------------
# Eroded shapes, cached per (body, tolerance)
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ErodedShape:
    """A polygon eroded by a tolerance, in the frame of the polygon it came from.

    Attributes
    ----------
    parts : tuple of ndarray
        Counter-clockwise exterior vertices ``(V_k, 2)`` (not closed) of each connected
        part of the erosion; empty when the body is thinner than ``2 t``.
    geometry : shapely.Geometry
        The erosion as one prepared shapely geometry (possibly empty).
    tol : float
        The erosion distance ``t`` (mm).
    convex : tuple of bool
        Whether each part is strictly convex (:func:`_strictly_convex`: its overlaps are
        decided by exact orientation signs first).
    """

    parts: tuple[FloatArray, ...]
    geometry: shapely.Geometry
    tol: float
    convex: tuple[bool, ...] = ()

    @property
    def is_empty(self) -> bool:
        return not self.parts


_POLYGON_CACHE: "weakref.WeakKeyDictionary[Polygon, dict[float, ErodedShape]]" = weakref.WeakKeyDictionary()
_ENV_CACHE: "weakref.WeakKeyDictionary[Environment, dict[float, ErodedShape]]" = weakref.WeakKeyDictionary()


def _check_tol(tol: float) -> float:
    t = float(tol)
    if not (np.isfinite(t) and t >= 0.0):
        raise ValueError(f"tolerance must be a finite number >= 0, got {tol!r}")
    return t


def _erode(geom: shapely.Geometry, tol: float) -> ErodedShape:
    g = geom if tol == 0.0 else shapely.buffer(geom, -tol)
    parts: list[FloatArray] = []
    if not g.is_empty:
        for p in shapely.get_parts(g):
            if p.is_empty or p.area <= 0.0:
                continue
            p = orient(p, 1.0)
            coords = np.asarray(p.exterior.coords, dtype=float)[:-1]
            coords.setflags(write=False)
            parts.append(coords)
    out = shapely.MultiPolygon([shapely.Polygon(c) for c in parts]) if parts else shapely.Polygon()
    shapely.prepare(out)
    return ErodedShape(tuple(parts), out, tol, tuple(_strictly_convex(c) for c in parts))


def eroded_polygon(polygon: Polygon, tol: float) -> ErodedShape:
    """``polygon`` eroded by ``tol`` in its own frame (cached per polygon and tolerance).

    Parameters
    ----------
    polygon : Polygon
        Any body polygon (object, finger, palm) in its own frame.
    tol : float
        Erosion distance (mm), ``>= 0``.

    Returns
    -------
    ErodedShape

    Examples
    --------
    >>> from geometry.shapes import make_polygon
    >>> e = eroded_polygon(make_polygon([[0, 0], [10, 0], [10, 4], [0, 4]]), 1.0)
    >>> sorted(map(tuple, e.parts[0].tolist()))
    [(1.0, 1.0), (1.0, 3.0), (9.0, 1.0), (9.0, 3.0)]
    >>> eroded_polygon(make_polygon([[0, 0], [10, 0], [10, 1.5], [0, 1.5]]), 1.0).is_empty
    True
    """
    t = _check_tol(tol)
    per = _POLYGON_CACHE.setdefault(polygon, {})
    if t not in per:
        per[t] = _erode(shapely.Polygon(polygon.vertices), t)
    return per[t]


def eroded_environment(env: Environment, tol: float) -> ErodedShape:
    """The union of the solids eroded by ``tol`` (cached per environment and tolerance).

    The union is eroded (not each solid), so solids that abut act as one body: a body
    pressed across the seam of two solids overlaps "the environment" even if it overlaps
    neither solid alone by ``2 t``. This is stricter than a per-solid reading of plan rule
    3 only in that corner case, and never more lenient.
    """
    t = _check_tol(tol)
    per = _ENV_CACHE.setdefault(env, {})
    if t not in per:
        union = shapely.union_all([shapely.Polygon(s.polygon.vertices) for s in env.solids])
        per[t] = _erode(union, t)
    return per[t]


# --------------------------------------------------------------------------------------
# Batched inputs
# --------------------------------------------------------------------------------------


def _poses(poses: ArrayLike) -> FloatArray:
    p = np.asarray(poses, dtype=float)
    if p.ndim == 1:
        p = p.reshape(1, 3)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"poses must be (B, 3) or (3,), got shape {p.shape}")
    return p


def _widths(widths: ArrayLike, b: int) -> FloatArray:
    w = np.asarray(widths, dtype=float)
    return np.broadcast_to(w, (b,)) if w.ndim == 0 else w.reshape(b)


def _relative(frame_poses: FloatArray, poses: FloatArray) -> FloatArray:
    """``frame^-1 * pose`` for (B, 3) batches: ``poses`` expressed in ``frame_poses``."""
    c, s = np.cos(frame_poses[:, 2]), np.sin(frame_poses[:, 2])
    dx = poses[:, 0] - frame_poses[:, 0]
    dy = poses[:, 1] - frame_poses[:, 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, poses[:, 2] - frame_poses[:, 2]], axis=1)


# Exact pre-filters with GEOS point predicates (no geometry built per pose): the target
# grown by ``d`` as a polygon inside the true offset region (its arcs are chords: a point
# in it is within ``d``) and one outside it (grown by ``d / cos(pi / 4 q)``, plus a hair:
# a point outside it is farther than ``d``). Only points in between are decided exactly.
_QUAD_SEGS = 8
_HAIR = 1e-6


def _grown(target: ErodedShape, d: float) -> tuple[shapely.Geometry, shapely.Geometry]:
    """(inner, outer) prepared approximations of ``target`` grown by ``d`` (cached)."""
    per = _GROWN_CACHE.setdefault(target, {})
    hit = per.get(d)
    if hit is None:
        inner = shapely.buffer(target.geometry, max(d - _HAIR, 0.0), quad_segs=_QUAD_SEGS) if d > _HAIR else \
            shapely.Polygon()
        outer = shapely.buffer(target.geometry, (d + _HAIR) / np.cos(np.pi / (4 * _QUAD_SEGS)) + _HAIR,
                               quad_segs=_QUAD_SEGS)
        shapely.prepare(inner)
        shapely.prepare(outer)
        hit = per[d] = (inner, outer)
    return hit


_GROWN_CACHE: "weakref.WeakKeyDictionary[ErodedShape, dict[float, tuple[shapely.Geometry, shapely.Geometry]]]" = \
    weakref.WeakKeyDictionary()


#: The compiled exact-sign overlap (:mod:`geometry.compiled`), or None: numpy decides alone.
_kernels = KERNELS

# Exact orientation signs without GEOS: Shewchuk's filter for orient2d (a sign is certain
# when the determinant exceeds 3.33e-16 times the sum of its two products' magnitudes;
# 1e-15 is taken), the rest left to GEOS, whose predicates are exact.
_ORIENT_ERR = 1e-15
_ORIENT_FLOOR = 1e-250  # below it, products may have lost digits to underflow


def _orient_sign(ax: FloatArray, ay: FloatArray, bx: FloatArray, by: FloatArray,
                 cx: FloatArray, cy: FloatArray) -> NDArray[np.int8]:
    """Sign of ``orient2d(a, b, c)`` (+1: c left of the line a -> b, -1: right) where
    the floating-point determinant certainly has the exact sign; 0 where it may not
    (c on or very near the line)."""
    left = (ax - cx) * (by - cy)
    right = (ay - cy) * (bx - cx)
    det = left - right
    bound = _ORIENT_ERR * (np.abs(left) + np.abs(right)) + _ORIENT_FLOOR
    return (det > bound).astype(np.int8) - (det < -bound).astype(np.int8)


def _target_edges(target: ErodedShape) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The boundary edges of an eroded target (every part's exterior, closed): starts,
    ends, and the lower and upper corners of each edge's bounding box, (K, 2) each
    (cached)."""
    hit = _EDGES_CACHE.get(target)
    if hit is None:
        a = np.concatenate(target.parts) if target.parts else np.zeros((0, 2))
        b = np.concatenate([np.roll(p, -1, axis=0) for p in target.parts]) if target.parts else a
        hit = _EDGES_CACHE[target] = (a, b, np.minimum(a, b), np.maximum(a, b))
    return hit


_EDGES_CACHE: "weakref.WeakKeyDictionary[ErodedShape, tuple[FloatArray, FloatArray, FloatArray, FloatArray]]" = \
    weakref.WeakKeyDictionary()

#: A part is tested without GEOS when it turns left at every vertex by at least this
#: (cross product of the unit edge directions): strictly convex beyond any rounding.
_CONVEX_TURN = 1e-6


def _strictly_convex(part: FloatArray) -> bool:
    """Whether the counter-clockwise ``part`` is strictly convex (:data:`_CONVEX_TURN`)."""
    d = np.roll(part, -1, axis=0) - part
    length = np.hypot(d[:, 0], d[:, 1])
    if part.shape[0] < 3 or np.any(length <= 0.0):
        return False
    d = d / length[:, None]
    nxt = np.roll(d, -1, axis=0)
    return bool(np.all(d[:, 0] * nxt[:, 1] - d[:, 1] * nxt[:, 0] >= _CONVEX_TURN))


def _convex_vs_target(placed: FloatArray, target: ErodedShape) -> tuple[BoolArray, BoolArray]:
    """:func:`_convex_vs_target_numpy`'s ``(hit, decided)``, by the compiled kernel where
    it is built (:mod:`geometry.compiled`; the same signs, the same decisions)."""
    b, v = placed.shape[:2]
    if _kernels is None or not 1 <= v <= _kernels.MAX_POLYGON:
        return _convex_vs_target_numpy(placed, target)
    starts, ends, lo, hi = _target_edges(target)
    hit = np.empty(b, dtype=bool)
    decided = np.empty(b, dtype=bool)
    c = np.ascontiguousarray
    _kernels.convex_overlap(c(placed, dtype=float), v, c(starts, dtype=float), c(ends, dtype=float),
                            c(lo, dtype=float), c(hi, dtype=float), hit.view(np.uint8), decided.view(np.uint8),
                            _ORIENT_ERR, _ORIENT_FLOOR)
    return hit, decided


def _convex_vs_target_numpy(placed: FloatArray, target: ErodedShape) -> tuple[BoolArray, BoolArray]:
    """``shapely.intersects(target, polygon)`` for strictly convex polygons (B, V, 2)
    (counter-clockwise) none of whose vertices is in the target, where exact
    orientation signs decide it: ``(hit, decided)``, each (B,).

    With every vertex of the polygon outside the target, they intersect iff an edge of
    the polygon meets an edge of the target's boundary or a vertex of the target lies
    in the polygon; both are read from the signs of :func:`_orient_sign`, for the
    target edges whose bounding box meets the polygon's (the others can do neither). A
    polygon is decided when a certain crossing or a target vertex certainly inside is
    found (hit), or when every such edge is certainly apart and its start vertex
    certainly outside (miss); the rest (near-degenerate signs) are not decided.
    """
    b = placed.shape[0]
    starts, ends, lo, hi = _target_edges(target)
    plo, phi = placed.min(axis=1), placed.max(axis=1)
    r, k = np.nonzero((lo[None, :, 0] <= phi[:, None, 0]) & (hi[None, :, 0] >= plo[:, None, 0])
                      & (lo[None, :, 1] <= phi[:, None, 1]) & (hi[None, :, 1] >= plo[:, None, 1]))
    A = placed[r]  # (Q, V, 2): the polygon's edges A_i -> A_(i+1)
    Bn = np.roll(A, -1, axis=1)
    c, d = starts[k][:, None, :], ends[k][:, None, :]  # (Q, 1, 2): the target's edge c -> d
    o_c = _orient_sign(A[..., 0], A[..., 1], Bn[..., 0], Bn[..., 1], c[..., 0], c[..., 1])  # (Q, V)
    o_d = _orient_sign(A[..., 0], A[..., 1], Bn[..., 0], Bn[..., 1], d[..., 0], d[..., 1])
    o_a = _orient_sign(c[..., 0], c[..., 1], d[..., 0], d[..., 1], A[..., 0], A[..., 1])
    o_b = np.roll(o_a, -1, axis=1)  # the same determinant at A_(i+1)
    cd, ab = o_c * o_d, o_a * o_b  # > 0: both certain, same side; < 0: both certain, opposite
    pair_hit = np.any((cd < 0) & (ab < 0), axis=1) | np.all(o_c > 0, axis=1)
    pair_miss = np.all((cd > 0) | (ab > 0), axis=1) & np.any(o_c < 0, axis=1)
    hit = np.zeros(b, dtype=bool)
    hit[r[pair_hit]] = True
    unsure = np.zeros(b, dtype=bool)
    unsure[r[~pair_hit & ~pair_miss]] = True
    return hit, hit | ~unsure


def _parts_vs_geometry(parts: tuple[FloatArray, ...] | ErodedShape, poses: FloatArray,
                       target: ErodedShape, offsets: FloatArray | None = None) -> BoolArray:
    """Whether any eroded part, placed at each pose, intersects the eroded ``target``.

    ``parts``: the parts, or the eroded body (its parts, whose convexity it knows).
    ``offsets`` (B, 2) shifts the parts in their own frame before the pose (finger opening).

    Exact pre-filters decide most poses with point predicates: a part whose bounding
    disk's centre is outside the target grown by the disk's radius misses it, a part with
    a vertex inside the target hits it; a strictly convex part is then decided by exact
    orientation signs (:func:`_convex_vs_target`) where they are certain; only the rest
    are built as shapely polygons.
    """
    if isinstance(parts, ErodedShape):
        parts, convex = parts.parts, parts.convex
    else:
        convex = tuple(_strictly_convex(p) for p in parts)
    b = poses.shape[0]
    hit = np.zeros(b, dtype=bool)
    if b == 0 or not parts or target.is_empty:
        return hit
    for part, part_convex in zip(parts, convex):
        centre = 0.5 * (part.min(axis=0) + part.max(axis=0))
        radius = float(np.linalg.norm(part - centre, axis=1).max())
        local_c = np.broadcast_to(centre if offsets is None else centre + offsets, (b, 2))
        world_c = transform_points(poses, local_c[:, None, :])[:, 0, :]
        _, outer = _grown(target, radius)
        near = np.flatnonzero(~hit & shapely.intersects_xy(outer, world_c[:, 0], world_c[:, 1]))
        if not near.size:
            continue
        local = part[None, :, :] if offsets is None else part[None, :, :] + offsets[near][:, None, :]
        world = transform_points(poses[near], np.broadcast_to(local, (near.size,) + part.shape))
        flat = world.reshape(-1, 2)
        deep = shapely.intersects_xy(target.geometry, flat[:, 0], flat[:, 1]).reshape(near.size, -1).any(axis=1)
        hit[near[deep]] = True
        rest = np.flatnonzero(~deep)
        if rest.size and part_convex:
            got, decided = _convex_vs_target(world[rest], target)
            hit[near[rest[got]]] = True
            rest = rest[~decided]
        if rest.size:
            hit[near[rest]] = shapely.intersects(target.geometry, shapely.polygons(world[rest]))
    return hit


def _circles_vs_geometry(centres: FloatArray, radius: float, target: ErodedShape) -> BoolArray:
    """(...,) overlap of circles (centres (..., 2), one radius) with an eroded target:
    ``dist(c, target) <= radius - t``, decided by the grown-target pre-filters and, for
    the centres between them, prepared ``shapely.dwithin``."""
    shape = centres.shape[:-1]
    t = target.tol
    if radius < t or target.is_empty or centres.size == 0:
        return np.zeros(shape, dtype=bool)
    c = centres.reshape(-1, 2)
    lim = radius - t
    inner, outer = _grown(target, lim)
    out = shapely.intersects_xy(inner, c[:, 0], c[:, 1]) if not inner.is_empty else np.zeros(c.shape[0], dtype=bool)
    unsure = np.flatnonzero(~out & shapely.intersects_xy(outer, c[:, 0], c[:, 1]))
    if unsure.size:
        out[unsure] = shapely.dwithin(target.geometry, shapely.points(c[unsure]), lim)
    return out.reshape(shape)


# --------------------------------------------------------------------------------------
# Gripper bodies
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FingerShapes:
    """World geometry of a batch of gripper configurations.

    Attributes
    ----------
    centres : ndarray or None
        Two-point model: (B, 2, 2) finger centres (finger 1, finger 2). ``None`` otherwise.
    radius : float or None
        Two-point model: finger radius (mm).
    polygons : ndarray or None
        Polyline model: (B, 2, V, 2) world vertices (CCW) of finger 1 and finger 2.
    palm : ndarray or None
        Polyline model with a palm: (B, P, 2) world palm vertices (CCW).
    """

    centres: FloatArray | None = None
    radius: float | None = None
    polygons: FloatArray | None = None
    palm: FloatArray | None = None


def _finger_offsets(widths: FloatArray) -> tuple[FloatArray, FloatArray]:
    zeros = np.zeros_like(widths)
    return (np.stack([-widths / 2.0, zeros], axis=1), np.stack([widths / 2.0, zeros], axis=1))


def finger_shapes(gripper: Gripper, gripper_poses: ArrayLike, widths: ArrayLike) -> FingerShapes:
    """World geometry of the fingers (and palm) for a batch of gripper poses and widths.

    Parameters
    ----------
    gripper : TwoPointGripper or PolylineGripper
    gripper_poses : array_like
        (B, 3) gripper poses (x, y, phi), radians.
    widths : array_like
        Scalar or (B,) spacing (two-point) or opening (polyline), mm.

    Returns
    -------
    FingerShapes

    Examples
    --------
    >>> from geometry.world import TwoPointGripper
    >>> fs = finger_shapes(TwoPointGripper(5.0, (80.0, 80.0)), [[0.0, 100.0, 0.0]], 80.0)
    >>> fs.centres.tolist()
    [[[-40.0, 100.0], [40.0, 100.0]]]
    """
    poses = _poses(gripper_poses)
    w = _widths(widths, poses.shape[0])
    off1, off2 = _finger_offsets(w)
    if isinstance(gripper, TwoPointGripper):
        local = np.stack([off1, off2], axis=1)  # (B, 2, 2)
        return FingerShapes(centres=transform_points(poses, local), radius=float(gripper.finger_radius))
    f1 = gripper.mirrored_finger.vertices[None] + off1[:, None, :]
    f2 = gripper.finger.vertices[None] + off2[:, None, :]
    polys = np.stack([transform_points(poses, f1), transform_points(poses, f2)], axis=1)
    palm = None if gripper.palm is None else transform_points(poses, gripper.palm.vertices)
    return FingerShapes(polygons=polys, palm=palm)


def _fingers_vs(gripper: Gripper, poses: FloatArray, w: FloatArray, target: ErodedShape) -> BoolArray:
    """(B, 2) finger overlap with an eroded target, fingers placed by ``poses`` in its frame."""
    b = poses.shape[0]
    if isinstance(gripper, TwoPointGripper):
        off1, off2 = _finger_offsets(w)
        centres = transform_points(poses, np.stack([off1, off2], axis=1))
        return _circles_vs_geometry(centres, float(gripper.finger_radius), target)
    out = np.zeros((b, 2), dtype=bool)
    off1, off2 = _finger_offsets(w)
    t = target.tol
    out[:, 0] = _parts_vs_geometry(eroded_polygon(gripper.mirrored_finger, t), poses, target, off1)
    out[:, 1] = _parts_vs_geometry(eroded_polygon(gripper.finger, t), poses, target, off2)
    return out


def _palm_vs(gripper: Gripper, poses: FloatArray, target: ErodedShape) -> BoolArray:
    if not isinstance(gripper, PolylineGripper) or gripper.palm is None:
        return np.zeros(poses.shape[0], dtype=bool)
    return _parts_vs_geometry(eroded_polygon(gripper.palm, target.tol), poses, target)


# --------------------------------------------------------------------------------------
# Public overlap tests
# --------------------------------------------------------------------------------------


def polygon_env_overlap(env: Environment, polygon: Polygon, poses: ArrayLike,
                        tol: float = PENETRATION_TOL) -> BoolArray:
    """Whether a body polygon placed at each pose overlaps the environment.

    Parameters
    ----------
    env : Environment
    polygon : Polygon
        The moving body in its own frame.
    poses : array_like
        (B, 3) body poses (x, y, theta), radians.
    tol : float
        Overlap tolerance ``t`` (mm): overlap iff the intersection eroded by ``t`` is
        non-empty.

    Returns
    -------
    ndarray of bool, shape (B,)
    """
    t = _check_tol(tol)
    return _parts_vs_geometry(eroded_polygon(polygon, t), _poses(poses), eroded_environment(env, t))


def object_env_overlap(world: World, object_poses: ArrayLike, tol: float = PENETRATION_TOL) -> BoolArray:
    """Whether the object at each pose overlaps the environment (rule 3 at ``tol``).

    Examples
    --------
    >>> import numpy as np
    >>> from geometry.world import (Environment, Friction, Solid, TwoPointGripper, World,
    ...                             make_object)
    >>> from geometry.shapes import make_polygon
    >>> table = Solid("table", make_polygon([[500, 0], [-500, 0], [-500, -100], [500, -100]]))
    >>> w = World(make_object([[0, 0], [70, 0], [70, 150], [0, 150]]), Environment((table,)),
    ...           TwoPointGripper(5.0, (80.0, 80.0)), Friction(0.2, 0.2))
    >>> object_env_overlap(w, [[0, 0, 0], [0, -0.15, 0], [0, -0.25, 0]]).tolist()
    [False, False, True]
    """
    return polygon_env_overlap(world.environment, world.object.polygon, object_poses, tol)


def finger_env_overlap(world: World, gripper_poses: ArrayLike, widths: ArrayLike,
                       tol: float = PENETRATION_TOL) -> BoolArray:
    """(B, 2) whether finger 1 / finger 2 overlaps the environment."""
    t = _check_tol(tol)
    poses = _poses(gripper_poses)
    return _fingers_vs(world.gripper, poses, _widths(widths, poses.shape[0]), eroded_environment(world.environment, t))


def palm_env_overlap(world: World, gripper_poses: ArrayLike, tol: float = PENETRATION_TOL) -> BoolArray:
    """(B,) whether the palm overlaps the environment (always False without a palm)."""
    t = _check_tol(tol)
    return _palm_vs(world.gripper, _poses(gripper_poses), eroded_environment(world.environment, t))


def gripper_env_overlap(world: World, gripper_poses: ArrayLike, widths: ArrayLike,
                        tol: float = PENETRATION_TOL) -> BoolArray:
    """(B,) whether any finger or the palm overlaps the environment.

    Parameters
    ----------
    world : World
    gripper_poses : array_like
        (B, 3) gripper poses (x, y, phi), radians.
    widths : array_like
        Scalar or (B,) spacing / opening (mm).
    tol : float
        Overlap tolerance (mm).

    Examples
    --------
    >>> from geometry.world import (Environment, Friction, Solid, TwoPointGripper, World,
    ...                             make_object)
    >>> from geometry.shapes import make_polygon
    >>> table = Solid("table", make_polygon([[500, 0], [-500, 0], [-500, -100], [500, -100]]))
    >>> w = World(make_object([[0, 0], [70, 0], [70, 150], [0, 150]]), Environment((table,)),
    ...           TwoPointGripper(5.0, (80.0, 80.0)), Friction(0.2, 0.2))
    >>> gripper_env_overlap(w, [[35, 5, 0], [35, 4, 0]], 80.0).tolist()
    [False, True]
    """
    t = _check_tol(tol)
    poses = _poses(gripper_poses)
    target = eroded_environment(world.environment, t)
    hit = _fingers_vs(world.gripper, poses, _widths(widths, poses.shape[0]), target).any(axis=1)
    return hit | _palm_vs(world.gripper, poses, target)


def finger_object_overlap(world: World, object_poses: ArrayLike, gripper_poses: ArrayLike,
                          widths: ArrayLike, tol: float = PENETRATION_TOL) -> BoolArray:
    """(B, 2) whether finger 1 / finger 2 overlaps the object (poses paired row by row)."""
    t = _check_tol(tol)
    obj, grip = np.broadcast_arrays(_poses(object_poses), _poses(gripper_poses))
    rel = _relative(obj, grip)  # gripper in the object frame
    target = eroded_polygon(world.object.polygon, t)
    return _fingers_vs(world.gripper, rel, _widths(widths, rel.shape[0]), target)


def palm_object_overlap(world: World, object_poses: ArrayLike, gripper_poses: ArrayLike,
                        tol: float = PENETRATION_TOL) -> BoolArray:
    """(B,) whether the palm overlaps the object (always False without a palm)."""
    t = _check_tol(tol)
    obj, grip = np.broadcast_arrays(_poses(object_poses), _poses(gripper_poses))
    return _palm_vs(world.gripper, _relative(obj, grip), eroded_polygon(world.object.polygon, t))


def gripper_object_overlap(world: World, object_poses: ArrayLike, gripper_poses: ArrayLike,
                           widths: ArrayLike, tol: float = PENETRATION_TOL) -> BoolArray:
    """(B,) whether any finger or the palm overlaps the object.

    ``object_poses`` and ``gripper_poses`` are paired row by row (either may be a single
    pose, broadcast). The test runs in the object frame: the object's erosion is computed
    once, the fingers are moved by ``object^-1 * gripper``.
    """
    t = _check_tol(tol)
    obj, grip = np.broadcast_arrays(_poses(object_poses), _poses(gripper_poses))
    rel = _relative(obj, grip)
    target = eroded_polygon(world.object.polygon, t)
    hit = _fingers_vs(world.gripper, rel, _widths(widths, rel.shape[0]), target).any(axis=1)
    return hit | _palm_vs(world.gripper, rel, target)


def fingers_overlap(gripper: Gripper, widths: ArrayLike, tol: float = PENETRATION_TOL) -> BoolArray:
    """(B,) whether the two fingers overlap each other at each width.

    The fingers' relative placement depends on the width only. Two-point: overlap iff
    ``r >= t`` and ``w <= 2 (r - t)``. Polyline: the eroded fingers, shifted by ``-w/2`` and
    ``+w/2``, intersect (at opening 0 the pads touch along x = 0: no overlap for t > 0).
    The palm is part of the hand and is not tested against the fingers.
    """
    t = _check_tol(tol)
    w = np.atleast_1d(np.asarray(widths, dtype=float))
    if isinstance(gripper, TwoPointGripper):
        r = float(gripper.finger_radius)
        return (r >= t) & (np.abs(w) <= 2.0 * (r - t))
    off1, off2 = _finger_offsets(w)
    e2 = eroded_polygon(gripper.finger, t)
    e1 = eroded_polygon(gripper.mirrored_finger, t)
    # Finger 1 expressed in finger 2's frame: shifted by off1 - off2 = (-w, 0).
    ident = np.zeros((w.shape[0], 3))
    return _parts_vs_geometry(e1, ident, e2, off1 - off2)


def overlaps(a: ArrayLike | shapely.Geometry, b: ArrayLike | shapely.Geometry,
             tol: float = PENETRATION_TOL) -> bool:
    """Single-pair rule 3: whether ``(A ∩ B)`` eroded by ``tol`` is non-empty.

    Parameters
    ----------
    a, b : array_like (N, 2) of polygon vertices, or shapely geometries
        The two bodies, in the same frame.
    tol : float
        Tolerance ``t`` (mm).

    Examples
    --------
    >>> sq = [[0, 0], [10, 0], [10, 10], [0, 10]]
    >>> overlaps(sq, [[10, 0], [20, 0], [20, 10], [10, 10]], 0.1)   # touching
    False
    >>> overlaps(sq, [[9.5, 0], [20, 0], [20, 10], [9.5, 10]], 1.0)  # 0.5 mm deep
    False
    >>> overlaps(sq, [[9.5, 0], [20, 0], [20, 10], [9.5, 10]], 0.1)
    True
    """
    t = _check_tol(tol)
    ga = a if isinstance(a, shapely.Geometry) else shapely.Polygon(np.asarray(a, dtype=float))
    gb = b if isinstance(b, shapely.Geometry) else shapely.Polygon(np.asarray(b, dtype=float))
    if t == 0.0:
        return bool(shapely.intersects(ga, gb))
    return bool(shapely.intersects(shapely.buffer(ga, -t), shapely.buffer(gb, -t)))


def circle_overlaps(centre: ArrayLike, radius: float, b: ArrayLike | shapely.Geometry,
                    tol: float = PENETRATION_TOL) -> bool:
    """Single-pair rule 3 for a circle (finger) against a polygon: ``dist(c, B ⊖ t) <= r - t``.

    Examples
    --------
    >>> sq = [[0, 0], [10, 0], [10, 10], [0, 10]]
    >>> circle_overlaps([15, 5], 5.0, sq, 0.1), circle_overlaps([14.5, 5], 5.0, sq, 0.1)
    (False, True)
    """
    t = _check_tol(tol)
    r = float(radius)
    if r < t:
        return False
    gb = b if isinstance(b, shapely.Geometry) else shapely.Polygon(np.asarray(b, dtype=float))
    eb = gb if t == 0.0 else shapely.buffer(gb, -t)
    if eb.is_empty:
        return False
    c = np.asarray(centre, dtype=float)
    return bool(shapely.dwithin(eb, shapely.Point(c[0], c[1]), r - t))


def finger_env_clearance(world: World, gripper_poses: ArrayLike, widths: ArrayLike) -> FloatArray:
    """(B, 2) distance (mm) from each finger to the environment; 0 when they intersect.

    Two-point: ``max(dist(c, E) - r, 0)``. Polyline: the polygon-to-solids distance.
    """
    poses = _poses(gripper_poses)
    w = _widths(widths, poses.shape[0])
    env = eroded_environment(world.environment, 0.0).geometry
    fs = finger_shapes(world.gripper, poses, w)
    if fs.centres is not None:
        d = shapely.distance(shapely.points(fs.centres.reshape(-1, 2)), env).reshape(-1, 2)
        return np.maximum(d - float(fs.radius), 0.0)
    assert fs.polygons is not None
    b, _, v, _ = fs.polygons.shape
    return shapely.distance(shapely.polygons(fs.polygons.reshape(b * 2, v, 2)), env).reshape(b, 2)
