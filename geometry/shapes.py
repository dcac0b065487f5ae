"""Simple polygons as immutable values, with the derived arrays the hot paths need.

Vertices are stored counter-clockwise as a read-only (N, 2) float array. Edge ``i`` joins
vertex ``i`` to vertex ``(i + 1) % N``; its outward normal points to the right of the
edge direction (CCW polygon). Feature names are 1-based (``v1``, ``l1``) and live in
:mod:`geometry.world`; here indices are 0-based.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from geometry.errors import GeometryError
from geometry.tolerances import EPS
from geometry.poses import FloatArray



def signed_area(vertices: FloatArray) -> float:
    """Shoelace signed area: positive for counter-clockwise vertex order."""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _readonly(a: ArrayLike) -> FloatArray:
    arr = np.array(a, dtype=float, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Polygon:
    """A simple polygon, counter-clockwise. Build with :func:`make_polygon`."""

    vertices: FloatArray

    def __len__(self) -> int:
        return int(self.vertices.shape[0])

    @cached_property
    def edges(self) -> FloatArray:
        """(N, 2, 2): edge i as [start, end]."""
        return _readonly(np.stack([self.vertices, np.roll(self.vertices, -1, axis=0)], axis=1))

    @cached_property
    def edge_vectors(self) -> FloatArray:
        return _readonly(np.roll(self.vertices, -1, axis=0) - self.vertices)

    @cached_property
    def edge_lengths(self) -> FloatArray:
        return _readonly(np.linalg.norm(self.edge_vectors, axis=1))

    @cached_property
    def edge_directions(self) -> FloatArray:
        """(N, 2) unit tangents of the edges."""
        return _readonly(self.edge_vectors / self.edge_lengths[:, None])

    @cached_property
    def normals(self) -> FloatArray:
        """(N, 2) outward unit normals of the edges (right of the direction, CCW)."""
        d = self.edge_directions
        return _readonly(np.stack([d[:, 1], -d[:, 0]], axis=1))

    @cached_property
    def area(self) -> float:
        return signed_area(self.vertices)

    @cached_property
    def centroid(self) -> FloatArray:
        """Area centroid."""
        v = self.vertices
        w = np.roll(v, -1, axis=0)
        cross = v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]
        a = cross.sum() / 2.0
        cx = ((v[:, 0] + w[:, 0]) * cross).sum() / (6.0 * a)
        cy = ((v[:, 1] + w[:, 1]) * cross).sum() / (6.0 * a)
        return _readonly([cx, cy])

    @cached_property
    def convex_vertices(self) -> NDArray[np.bool_]:
        """(N,) True where the interior angle is below 180 degrees (a convex corner)."""
        d_in = np.roll(self.edge_directions, 1, axis=0)  # edge arriving at vertex i
        d_out = self.edge_directions  # edge leaving vertex i
        cross = d_in[:, 0] * d_out[:, 1] - d_in[:, 1] * d_out[:, 0]
        out = cross > EPS
        out.setflags(write=False)
        return out

    @cached_property
    def is_convex(self) -> bool:
        return bool(np.all(self.convex_vertices))

    @cached_property
    def radius(self) -> float:
        """Largest distance from the centroid to a vertex (the characteristic length)."""
        return float(np.max(np.linalg.norm(self.vertices - self.centroid, axis=1)))

    @cached_property
    def shapely(self) -> shapely.Polygon:
        """The polygon as a prepared shapely geometry."""
        g = shapely.Polygon(self.vertices)
        shapely.prepare(g)
        return g

    def transformed(self, x: float, y: float, theta: float) -> FloatArray:
        """World vertices (N, 2) at pose (x, y, theta) (radians)."""
        c, s = np.cos(theta), np.sin(theta)
        v = self.vertices
        return np.stack([c * v[:, 0] - s * v[:, 1] + x, s * v[:, 0] + c * v[:, 1] + y], axis=1)


def polar_moment(vertices: ArrayLike, about: ArrayLike) -> float:
    """Polar second moment of area (mm^4) of a simple polygon about a point.

    >>> round(polar_moment([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]], [1.0, 1.0]), 6)
    2.666667
    """
    v = np.asarray(vertices, dtype=float) - np.asarray(about, dtype=float)
    w = np.roll(v, -1, axis=0)
    cross = v[:, 0] * w[:, 1] - w[:, 0] * v[:, 1]
    return float(abs(np.sum(cross * (v[:, 0] ** 2 + v[:, 0] * w[:, 0] + w[:, 0] ** 2
                                     + v[:, 1] ** 2 + v[:, 1] * w[:, 1] + w[:, 1] ** 2)) / 12.0))


def segment_distances(points: ArrayLike, segments: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Distances from points (..., 2) to closed segments (S, 2, 2), and where they fall.

    Returns ``(distance, t)``, both (..., S): ``t`` in [0, 1] is the parameter of the
    closest point ``a + t (b - a)`` on each segment ``[a, b]``.

    >>> d, t = segment_distances([[1.0, 2.0]], [[[0.0, 0.0], [2.0, 0.0]]])
    >>> d.tolist(), t.tolist()
    ([[2.0]], [[0.5]])
    """
    p = np.asarray(points, dtype=float)
    seg = np.asarray(segments, dtype=float)
    a = seg[:, 0]
    d = seg[:, 1] - a
    rel = p[..., None, :] - a  # (..., S, 2)
    t = np.clip(np.einsum("...sk,sk->...s", rel, d) / np.maximum(np.einsum("sk,sk->s", d, d), EPS), 0.0, 1.0)
    return np.linalg.norm(rel - t[..., None] * d, axis=-1), t


def make_polygon(vertices: ArrayLike, *, what: str = "polygon") -> Polygon:
    """Validate and normalise a vertex list into a counter-clockwise :class:`Polygon`.

    Refuses fewer than 3 vertices, non-finite coordinates, repeated vertices, zero area
    and self-intersection (raising :class:`GeometryError` with ``what`` in the message).
    A clockwise list is re-ordered counter-clockwise keeping its first vertex first:
    ``[p0, p1, ..., pn-1] -> [p0, pn-1, ..., p1]``.

    >>> make_polygon([[0, 0], [0, 1], [1, 0]]).vertices.tolist()
    [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
    """
    try:
        v = np.array(vertices, dtype=float)
    except (TypeError, ValueError) as exc:
        raise GeometryError(f"{what}: vertices must be a list of [x, y] numbers") from exc
    if v.ndim != 2 or v.shape[1] != 2:
        raise GeometryError(f"{what}: vertices must be a list of [x, y] pairs")
    if v.shape[0] < 3:
        raise GeometryError(f"{what}: needs at least 3 vertices, got {v.shape[0]}")
    if not np.all(np.isfinite(v)):
        raise GeometryError(f"{what}: coordinates must be finite numbers")
    n = v.shape[0]
    diff = np.linalg.norm(v[:, None, :] - v[None, :, :], axis=2)
    diff[np.arange(n), np.arange(n)] = np.inf
    if np.any(diff <= EPS):
        i, j = np.argwhere(diff <= EPS)[0]
        raise GeometryError(f"{what}: repeated vertex {v[i].tolist()} (vertices {i + 1} and {j + 1})")
    area = signed_area(v)
    scale = max(1.0, float(np.max(np.abs(v))))
    collinear = np.linalg.matrix_rank(v[1:] - v[0], tol=1e-9 * scale) < 2
    if collinear or abs(area) <= 1e-12 * scale * scale and shapely.LinearRing(v).is_simple:
        raise GeometryError(f"{what}: zero area (degenerate polygon)")
    # A spike (consecutive edges folding back) is non-simple for shapely too; a
    # collinear 'straight' vertex is legal and kept.
    if not shapely.LinearRing(v).is_simple:
        raise GeometryError(f"{what}: self-intersecting polygon")
    if area < 0:
        v = np.concatenate([v[:1], v[:0:-1]], axis=0)
    return Polygon(_readonly(v))
