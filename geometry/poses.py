"""Planar rigid transforms (SE(2)) as immutable values and batched numpy helpers.

A pose ``(x, y, theta)`` places a body frame at world point (x, y), rotated
counter-clockwise by ``theta`` (radians): ``p_world = R(theta) p_body + (x, y)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Array aliases used across the project.
FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def wrap_angle(theta: float | FloatArray) -> float | FloatArray:
    """Wrap an angle (or array of angles) to [-pi, pi)."""
    wrapped = (np.asarray(theta, dtype=float) + math.pi) % (2.0 * math.pi) - math.pi
    return float(wrapped) if wrapped.ndim == 0 else wrapped


def rotation(theta: float) -> FloatArray:
    """2x2 rotation matrix."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class Pose:
    """A planar pose: position in mm, orientation in radians."""

    x: float
    y: float
    theta: float

    @classmethod
    def from_degrees(cls, x: float, y: float, theta_deg: float) -> "Pose":
        return cls(float(x), float(y), math.radians(theta_deg))

    @classmethod
    def from_array(cls, a: ArrayLike) -> "Pose":
        x, y, t = np.asarray(a, dtype=float)
        return cls(float(x), float(y), float(t))

    def to_degrees(self) -> tuple[float, float, float]:
        return (self.x, self.y, math.degrees(self.theta))

    def as_array(self) -> FloatArray:
        return np.array([self.x, self.y, self.theta])

    @property
    def position(self) -> FloatArray:
        return np.array([self.x, self.y])

    def rotation(self) -> FloatArray:
        return rotation(self.theta)

    def apply(self, points: ArrayLike) -> FloatArray:
        """Body-frame points (..., 2) to world frame."""
        p = np.asarray(points, dtype=float)
        c, s = math.cos(self.theta), math.sin(self.theta)
        out = np.empty_like(p)
        out[..., 0] = c * p[..., 0] - s * p[..., 1] + self.x
        out[..., 1] = s * p[..., 0] + c * p[..., 1] + self.y
        return out

    def apply_vector(self, vectors: ArrayLike) -> FloatArray:
        """Rotate body-frame directions (..., 2) into the world frame."""
        v = np.asarray(vectors, dtype=float)
        c, s = math.cos(self.theta), math.sin(self.theta)
        out = np.empty_like(v)
        out[..., 0] = c * v[..., 0] - s * v[..., 1]
        out[..., 1] = s * v[..., 0] + c * v[..., 1]
        return out

    def compose(self, other: "Pose") -> "Pose":
        """``self * other``: ``other`` expressed in ``self``'s frame, returned in world."""
        x, y = self.apply(np.array([other.x, other.y]))
        return Pose(float(x), float(y), float(wrap_angle(self.theta + other.theta)))

    def inverse(self) -> "Pose":
        c, s = math.cos(self.theta), math.sin(self.theta)
        return Pose(-(c * self.x + s * self.y), -(-s * self.x + c * self.y), float(wrap_angle(-self.theta)))

    def distance(self, other: "Pose") -> tuple[float, float]:
        """(translation distance in mm, absolute wrapped angle difference in radians)."""
        return (
            math.hypot(self.x - other.x, self.y - other.y),
            abs(float(wrap_angle(self.theta - other.theta))),
        )


def transform_points(poses: ArrayLike, points: ArrayLike) -> FloatArray:
    """Batched body-to-world transform.

    ``poses`` is (B, 3) rows of (x, y, theta); ``points`` is (N, 2) or (B, N, 2).
    Returns (B, N, 2).
    """
    P = np.asarray(poses, dtype=float).reshape(-1, 3)
    pts = np.asarray(points, dtype=float)
    c = np.cos(P[:, 2])[:, None]
    s = np.sin(P[:, 2])[:, None]
    px = pts[..., 0]
    py = pts[..., 1]
    out = np.empty(np.broadcast_shapes((P.shape[0], 1), px.shape) + (2,))
    out[..., 0] = c * px - s * py + P[:, 0:1]
    out[..., 1] = s * px + c * py + P[:, 1:2]
    return out


def compose_batch(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Batched pose composition ``a * b`` for (B, 3) arrays (broadcasting)."""
    A = np.asarray(a, dtype=float)
    B = np.asarray(b, dtype=float)
    c, s = np.cos(A[..., 2]), np.sin(A[..., 2])
    x = c * B[..., 0] - s * B[..., 1] + A[..., 0]
    y = s * B[..., 0] + c * B[..., 1] + A[..., 1]
    t = wrap_angle(A[..., 2] + B[..., 2])
    return np.stack([x, y, t], axis=-1)
