"""Quasi-static planar mechanics: contact modes, Coulomb-cone feasibility, grasp quality.

Frame and units
---------------
The vertical plane: world x to the right, y up, gravity ``(0, -g)``. Lengths in mm,
angles in radians, forces in newtons. A *contact* is a point on the object with a unit
normal pointing INTO the object (the direction in which a pushing reaction acts on the
object) and a Coulomb coefficient ``mu``. The object's weight ``m g`` acts at its centre of
mass (a world point, ``com``).

Normalised wrench space
-----------------------
A force ``f`` applied at world point ``p`` has the normalised wrench

    w(f, p) = (f_x / (m g), f_y / (m g), ((p - com) x f) / (m g L))

with ``L`` the object's length scale (:attr:`geometry.world.ObjectModel.length_scale`, the
circumradius about the COM, so a contact on the object has ``|p - com| <= L``). The weight
is balanced by the contact forces iff their wrenches sum to the *target* ``e_y = (0, 1, 0)``.

Each contact contributes up to two *generators* (unit-force wrenches along the edges of its
mode-dependent friction cone): STICKING/ROLLING give both edges ``(n +- mu t)/sqrt(1+mu^2)``
(``t = (-n_y, n_x)``); SLIDING gives the single edge ``(n - mu s)/sqrt(1+mu^2)`` opposing the
sliding direction ``s``; SEPARATING and ABSENT give none (zero generators); PENETRATING makes
the whole instance infeasible.

The feasibility margin
----------------------
With generators ``g_k`` (zero vectors for unused slots) the margin is the value of the LP

    M = max s   subject to   sum_k lam_k g_k = e_y,   lam_k >= s   (all k),   s <= MARGIN_CAP,

i.e. the largest normalised force (in units of ``m g``) that *every* generator can be made
to carry in an equilibrium (``-inf`` when no equilibrium exists even with negative
coefficients). ``M > 0`` iff ``e_y`` lies in the relative interior of the cone, so a block
flat on a frictionless table is feasible while an equilibrium that needs a force exactly
on a cone edge is not. Substituting ``lam_k = s + nu_k`` gives the identity used by the fast
path:

    M >= eps   <=>   e_y - eps * gbar  in  cone{g_k},      gbar = sum_k g_k,

so the fast path decides ``M >= margin`` by one exact cone-membership test of a shifted
target, and the reference path (cvxpy + Clarabel) computes ``M`` itself: both paths work
with the same quantity. An instance is feasible iff ``M >= FEASIBILITY_MARGIN``.

See ``docs/design/mechanics.md`` for the derivations and the tolerances.
"""

from __future__ import annotations

import enum
import functools
import itertools
import logging
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from geometry.compiled import KERNELS
from geometry.errors import GeometryError
from geometry.poses import BoolArray, FloatArray, Pose
from geometry.tolerances import FEASIBILITY_MARGIN

logger = logging.getLogger(__name__)

#: The compiled cone test (:mod:`geometry.compiled`), or None: numpy decides alone.
_kernels = KERNELS

ModeArray = NDArray[np.int8]

#: Margins are reported saturated at this value (normalised force units). The LP margin is
#: +inf exactly when the generators positively span a subspace containing e_y (e.g. a
#: force-closure grasp); the cap keeps the reference LP bounded.
MARGIN_CAP: float = 1.0

#: Batch chunk of the fast path: the working set of one chunk stays in L2 cache.
_CHUNK: int = 8192

#: Two projected generators whose 2-D cross product is within this of zero count as
#: parallel (the projected generators have norm <= ~1.5, rounding error ~5e-16).
_CROSS_TOL: float = 1e-14

#: A generator triple is used as a certificate only if |det| exceeds this, well above the
#: determinant's rounding error (~6e-16 for generators of norm <= ~1.5), so its sign, and
#: with it the certificate, is exact; thin cones (mu ~ 1e-8) still have |det| above it.
_DET_TOL: float = 1e-12

#: Relative tolerance of the degenerate (pair / single generator) certificates: the found
#: cone element deviates from the target direction by at most this angle (radians).
_DEGENERATE_TOL: float = 1e-12

#: Friction coefficients below this are treated as exactly 0 (frictionless): a cone
#: thinner than this is numerically neither a plane nor a solid cone.
MU_ZERO: float = 1e-8

#: Reference path: a least-squares residual of ``G lam = e_y`` above this (normalised)
#: proves infeasibility without a solve (e_y outside the span of the generators).
_SPAN_TOL: float = 1e-9

#: Residual (normalised units) within which an inaccurate reference solution still counts
#: as an equilibrium when its forces are verified.
_VERIFY_TOL: float = FEASIBILITY_MARGIN


# --------------------------------------------------------------------------------------
# Modes, statuses and values
# --------------------------------------------------------------------------------------


class ContactMode(enum.IntEnum):
    """Mode of one contact during a motion step; the integer value is the batch code.

    ``ABSENT`` (0) pads batches with fewer contacts, so ``np.zeros`` is an empty batch.
    ``PENETRATING`` marks a motion that pushes into a contact: the instance is infeasible.
    """

    ABSENT = 0
    STICKING = 1
    ROLLING = 2
    SLIDING = 3
    SEPARATING = 4
    PENETRATING = 5


class FeasibilityStatus(enum.Enum):
    """Outcome of the reference feasibility check."""

    FEASIBLE = "feasible"
    INFEASIBLE = "infeasible"
    UNKNOWN = "unknown"


@dataclass(frozen=True)
class ModeTolerances:
    """Scale-aware thresholds of :func:`classify_contacts`.

    For a batch instance with largest contact displacement ``d_max`` (mm) and largest
    relative rotation ``r_max`` (rad) the threshold is
    ``tol = max(relative * max(d_max, r_max * L), absolute)`` (mm), applied to the normal
    and tangential displacement of every contact and to ``|rotation| * L``.

    Attributes
    ----------
    relative : float
        Fraction of the step's own size (dimensionless).
    absolute : float
        Floor in mm, used when the step does not move at all.
    """

    relative: float = 1e-3
    absolute: float = 1e-6

    def __post_init__(self) -> None:
        if not (self.relative >= 0 and self.absolute > 0):
            raise GeometryError(f"mode tolerances must be relative >= 0 and absolute > 0, got {self}")


def _frozen(a: ArrayLike, dtype: Any) -> np.ndarray:
    arr = np.array(a, dtype=dtype, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Contacts:
    """A batch of point contacts on the object, in one frame (normally the world).

    Build with :meth:`make`, which validates and broadcasts. Arrays are read-only copies.

    Attributes
    ----------
    points : ndarray, shape (B, C, 2)
        Contact points (mm).
    normals : ndarray, shape (B, C, 2)
        Unit normals pointing into the object (zero allowed only for ABSENT contacts).
    mu : ndarray, shape (B, C)
        Coulomb coefficients (>= 0).
    modes : ndarray of int8, shape (B, C)
        :class:`ContactMode` codes.
    slide_dirs : ndarray, shape (B, C, 2)
        For SLIDING contacts, the direction of the object's velocity at the contact
        relative to the other body (only the sign of its component along
        ``t = (-n_y, n_x)`` is used); ignored for other modes.
    """

    points: FloatArray
    normals: FloatArray
    mu: FloatArray
    modes: ModeArray
    slide_dirs: FloatArray

    @classmethod
    def make(
        cls,
        points: ArrayLike,
        normals: ArrayLike,
        mu: ArrayLike,
        modes: ArrayLike = ContactMode.STICKING,
        slide_dirs: ArrayLike | None = None,
    ) -> "Contacts":
        """Validate and broadcast contact arrays; ``(C, 2)`` points make a batch of one.

        Parameters
        ----------
        points, normals : array_like, shape (B, C, 2) or (C, 2)
        mu, modes : array_like, broadcastable to (B, C)
        slide_dirs : array_like, broadcastable to (B, C, 2), optional

        Examples
        --------
        >>> c = Contacts.make([[-1.0, -1.0], [1.0, -1.0]], [[0.0, 1.0], [0.0, 1.0]], 0.5)
        >>> c.batch, c.count
        (1, 2)
        """
        p = np.asarray(points, dtype=float)
        if p.ndim == 2:
            p = p[None]
        if p.ndim != 3 or p.shape[-1] != 2:
            raise GeometryError(f"contacts: points must have shape (B, C, 2), got {np.shape(points)}")
        shape2 = p.shape
        shape1 = p.shape[:2]
        try:
            n = np.broadcast_to(np.asarray(normals, dtype=float), shape2)
            m = np.broadcast_to(np.asarray(mu, dtype=float), shape1)
            md = np.broadcast_to(np.asarray(modes, dtype=np.int8), shape1)
            s = np.zeros(shape2) if slide_dirs is None else np.broadcast_to(np.asarray(slide_dirs, dtype=float), shape2)
        except ValueError as exc:
            raise GeometryError(f"contacts: arrays do not broadcast to {shape2}: {exc}") from exc
        if not (np.isfinite(p).all() and np.isfinite(n).all() and np.isfinite(s).all()):
            raise GeometryError("contacts: points, normals and slide directions must be finite")
        if not (np.isfinite(m).all() and (m >= 0).all()):
            raise GeometryError("contacts: friction coefficients must be finite and >= 0")
        if md.size and (md.min() < 0 or md.max() > max(ContactMode)):
            raise GeometryError("contacts: unknown contact-mode code")
        norm = np.hypot(n[..., 0], n[..., 1])
        bad = (np.abs(norm - 1.0) > 1e-6) & (md != ContactMode.ABSENT)
        if bad.any():
            raise GeometryError(f"contacts: {int(bad.sum())} present contact(s) have a non-unit normal")
        return cls(_frozen(p, float), _frozen(n, float), _frozen(m, float), _frozen(md, np.int8), _frozen(s, float))

    @classmethod
    def trusted(
        cls,
        points: FloatArray,
        normals: FloatArray,
        mu: FloatArray,
        modes: ModeArray,
        slide_dirs: FloatArray | None = None,
    ) -> "Contacts":
        """Wrap arrays already of shape (B, C, 2) / (B, C) and valid by construction (the
        batched checks' own instances, built from validated contacts and grasps), without
        :meth:`make`'s validation and copies. The caller must not modify them after."""
        s = np.zeros(points.shape) if slide_dirs is None else slide_dirs
        return cls(points, normals, mu, modes, s)

    @property
    def batch(self) -> int:
        """Number of instances B."""
        return int(self.points.shape[0])

    @property
    def count(self) -> int:
        """Contact slots per instance C."""
        return int(self.points.shape[1])

    def select(self, index: ArrayLike | slice) -> "Contacts":
        """Sub-batch ``index`` (an index array, a boolean mask or a slice)."""
        idx = index if isinstance(index, slice) else np.asarray(index)
        return Contacts(*(_frozen(a[idx], a.dtype) for a in (self.points, self.normals, self.mu, self.modes, self.slide_dirs)))

    def with_mu(self, mu: ArrayLike) -> "Contacts":
        """The same contacts with other friction coefficients (broadcast to (B, C))."""
        m = np.broadcast_to(np.asarray(mu, dtype=float), self.mu.shape)
        if not (np.isfinite(m).all() and (m >= 0).all()):
            raise GeometryError("contacts: friction coefficients must be finite and >= 0")
        return Contacts(self.points, self.normals, _frozen(m, float), self.modes, self.slide_dirs)

    def with_modes(self, modes: ArrayLike) -> "Contacts":
        """The same contacts with other modes (broadcast to (B, C))."""
        md = np.broadcast_to(np.asarray(modes, dtype=np.int8), self.modes.shape)
        return Contacts.make(self.points, self.normals, self.mu, md, self.slide_dirs)


@dataclass(frozen=True, eq=False)
class ContactModes:
    """Result of :func:`classify_contacts`.

    Attributes
    ----------
    codes : ndarray of int8, shape (B, C)
        :class:`ContactMode` codes.
    slide_dirs : ndarray, shape (B, C, 2)
        Unit tangent of the object's relative velocity at SLIDING contacts, zero elsewhere
        (the friction force on the object opposes it).
    normal : ndarray, shape (B, C)
        Normal relative displacement (mm, > 0 separates).
    tangential : ndarray, shape (B, C)
        Relative displacement along ``t = (-n_y, n_x)`` (mm).
    tolerance : ndarray, shape (B,)
        The per-instance threshold used (mm).
    """

    codes: ModeArray
    slide_dirs: FloatArray
    normal: FloatArray
    tangential: FloatArray
    tolerance: FloatArray

    @property
    def penetrating(self) -> BoolArray:
        """(B,) True where some contact is pushed into (the motion is infeasible)."""
        return (self.codes == ContactMode.PENETRATING).any(axis=1)


@dataclass(frozen=True, eq=False)
class ReferenceResult:
    """Outcome of :func:`feasible_reference` for one instance.

    Attributes
    ----------
    status : FeasibilityStatus
    margin : float
        The LP margin ``M`` (normalised, capped at :data:`MARGIN_CAP`); ``-inf`` when the
        LP is infeasible, ``nan`` when unknown.
    forces : ndarray, shape (C, 2), or None
        Contact forces on the object in newtons (world frame) when FEASIBLE.
    solver_status : str
        The raw cvxpy status string, or a note when the solver was not called or raised.
    """

    status: FeasibilityStatus
    margin: float
    forces: FloatArray | None
    solver_status: str

    @property
    def feasible(self) -> bool:
        return self.status is FeasibilityStatus.FEASIBLE


@dataclass(frozen=True)
class GraspQuality:
    """Grasp quality ``S = w1 * s + w2 * alpha`` of a grasp along one motion.

    Attributes
    ----------
    value : float
        ``S`` (lower is better); ``nan`` when ``alpha`` is undefined.
    force_closure : bool
        The finger contacts alone are force closure at every sample.
    s : int
        ``0`` if force closure, else ``1``.
    alpha : float
        Mean reaction angle (radians) over the samples with a sticking/rolling contact.
    admissible : bool
        Every sample of the motion is quasi-statically feasible.
    """

    value: float
    force_closure: bool
    s: int
    alpha: float
    admissible: bool


# --------------------------------------------------------------------------------------
# Motion -> contact modes
# --------------------------------------------------------------------------------------


def _as_poses(poses: Pose | ArrayLike) -> FloatArray:
    if isinstance(poses, Pose):
        return poses.as_array()[None]
    return np.asarray(poses, dtype=float).reshape(-1, 3)


def pose_displacements(points: ArrayLike, pose_from: Pose | ArrayLike, pose_to: Pose | ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Displacement of the object's material points when it moves between two poses.

    The object point at world ``p`` (at ``pose_from``) goes to
    ``R(theta1 - theta0) (p - o0) + o1``, ``o`` the pose positions.

    Parameters
    ----------
    points : array_like, shape (B, C, 2) or (C, 2)
        World contact points at ``pose_from``.
    pose_from, pose_to : Pose or array_like, shape (3,) or (B, 3)

    Returns
    -------
    displacements : ndarray, shape (B, C, 2)
        mm.
    rotations : ndarray, shape (B,)
        ``theta1 - theta0`` (rad, not wrapped: pass small steps).

    Examples
    --------
    >>> d, r = pose_displacements([[1.0, 0.0]], Pose(0, 0, 0), Pose(0, 0, math.pi / 2))
    >>> np.round(d, 12).tolist(), float(r[0]) == math.pi / 2
    ([[[-1.0, 1.0]]], True)
    """
    p = np.asarray(points, dtype=float)
    if p.ndim == 2:
        p = p[None]
    a, b = _as_poses(pose_from), _as_poses(pose_to)
    dth = b[:, 2] - a[:, 2]
    c, s = np.cos(dth)[:, None], np.sin(dth)[:, None]
    rx = p[..., 0] - a[:, 0:1]
    ry = p[..., 1] - a[:, 1:2]
    out = np.empty(np.broadcast_shapes(p.shape, (dth.shape[0], 1, 2)))
    out[..., 0] = c * rx - s * ry + b[:, 0:1] - p[..., 0]
    out[..., 1] = s * rx + c * ry + b[:, 1:2] - p[..., 1]
    return out, np.broadcast_to(dth, out.shape[:1]).copy()


def twist_displacements(points: ArrayLike, twist: ArrayLike, reference: ArrayLike) -> FloatArray:
    """Velocity of the object's points under a planar twist about a reference point.

    ``v(p) = (vx, vy) + omega * (-(p_y - r_y), p_x - r_x)``; multiply by a step to get
    a displacement.

    Parameters
    ----------
    points : array_like, shape (B, C, 2) or (C, 2)
    twist : array_like, shape (3,) or (B, 3)
        ``(vx, vy, omega)``: velocity of the reference point (mm per step) and rotation
        rate (rad per step).
    reference : array_like, shape (2,) or (B, 2)

    Returns
    -------
    ndarray, shape (B, C, 2)
    """
    p = np.asarray(points, dtype=float)
    if p.ndim == 2:
        p = p[None]
    tw = np.asarray(twist, dtype=float).reshape(-1, 3)
    ref = np.asarray(reference, dtype=float).reshape(-1, 2)
    w = tw[:, 2:3]
    out = np.empty(np.broadcast_shapes(p.shape, (tw.shape[0], 1, 2), (ref.shape[0], 1, 2)))
    out[..., 0] = tw[:, 0:1] - w * (p[..., 1] - ref[:, 1:2])
    out[..., 1] = tw[:, 1:2] + w * (p[..., 0] - ref[:, 0:1])
    return out


def classify_contacts(
    normals: ArrayLike,
    displacements: ArrayLike,
    rotations: ArrayLike,
    length_scale: float | ArrayLike,
    tolerances: ModeTolerances = ModeTolerances(),
    present: ArrayLike | None = None,
) -> ContactModes:
    """Classify each contact of a motion step.

    ``displacements`` are those of the object's material point at each contact relative
    to the other body (for an environment contact the object's own displacement; for a
    finger contact subtract the finger point's displacement), ``rotations`` the object's
    rotation relative to the other body. With ``tol`` from :class:`ModeTolerances`:

    - normal displacement ``d.n > tol`` -> SEPARATING; ``< -tol`` -> PENETRATING;
    - else tangential ``|d.t| <= tol`` -> STICKING if ``|rotation| * L <= tol`` else ROLLING;
    - else SLIDING with direction ``sign(d.t) t``.

    Parameters
    ----------
    normals : array_like, shape (B, C, 2) or (C, 2)
        Unit normals into the object.
    displacements : array_like, shape (B, C, 2) or (C, 2)
        Relative displacement per step (mm).
    rotations : array_like, broadcastable to (B, C)
        Relative rotation per step (rad); a (B,) array must be passed as (B, 1).
    length_scale : float or array_like, broadcastable to (B,)
        Object length scale ``L`` (mm), converts rotation to mm.
    tolerances : ModeTolerances
    present : array_like of bool, broadcastable to (B, C), optional
        False marks padding slots, classified ABSENT.

    Returns
    -------
    ContactModes

    Examples
    --------
    >>> m = classify_contacts([[0.0, 1.0]], [[1.0, 0.0]], 0.0, 10.0)
    >>> ContactMode(int(m.codes[0, 0])).name, m.slide_dirs[0, 0].tolist()
    ('SLIDING', [1.0, 0.0])
    """
    n = np.asarray(normals, dtype=float)
    d = np.asarray(displacements, dtype=float)
    if n.ndim == 2:
        n = n[None]
    if d.ndim == 2:
        d = d[None]
    n, d = np.broadcast_arrays(n, d)
    shape = n.shape[:2]
    rot = np.broadcast_to(np.asarray(rotations, dtype=float), shape)
    L = np.broadcast_to(np.asarray(length_scale, dtype=float).reshape(-1), (shape[0],))
    tx, ty = -n[..., 1], n[..., 0]
    vn = d[..., 0] * n[..., 0] + d[..., 1] * n[..., 1]
    vt = d[..., 0] * tx + d[..., 1] * ty
    rot_mm = np.abs(rot) * L[:, None]
    live = np.ones(shape, bool) if present is None else np.broadcast_to(np.asarray(present, bool), shape)
    dmag = np.where(live, np.hypot(d[..., 0], d[..., 1]), 0.0)
    scale = np.maximum(dmag.max(axis=1, initial=0.0), np.where(live, rot_mm, 0.0).max(axis=1, initial=0.0))
    tol = np.maximum(tolerances.relative * scale, tolerances.absolute)
    t2 = tol[:, None]
    codes = np.full(shape, ContactMode.STICKING, dtype=np.int8)
    codes[rot_mm > t2] = ContactMode.ROLLING
    sliding = np.abs(vt) > t2
    codes[sliding] = ContactMode.SLIDING
    codes[vn > t2] = ContactMode.SEPARATING
    codes[vn < -t2] = ContactMode.PENETRATING
    codes[~live] = ContactMode.ABSENT
    sl = codes == ContactMode.SLIDING
    sgn = np.where(sl, np.sign(vt), 0.0)
    slide = np.stack([sgn * tx, sgn * ty], axis=-1) + 0.0  # no negative zeros
    return ContactModes(_frozen(codes, np.int8), _frozen(slide, float), _frozen(vn, float), _frozen(vt, float), _frozen(tol, float))


# --------------------------------------------------------------------------------------
# Generators
# --------------------------------------------------------------------------------------


Rows = FloatArray  # (K, b): one row per generator slot
Gens = FloatArray  # (3, K, b): the rows X, Y, Z of the generators

# the mode codes as numpy scalars: comparing an int8 array with an IntEnum member costs
# 5 us more per call (the member goes through Python's int conversion)
_STICKING, _ROLLING, _SLIDING, _PENETRATING = (np.int8(m) for m in (ContactMode.STICKING, ContactMode.ROLLING,
                                                                   ContactMode.SLIDING, ContactMode.PENETRATING))


def _generators_chunk(
    contacts: Contacts, sl: slice, com: FloatArray, inv_L: FloatArray, mu_override: FloatArray | None = None
) -> tuple[Gens, BoolArray]:
    """Generators of a chunk: a (3, K, b) array ``G`` of rows ``X, Y, Z = G``, row
    k = 2i or 2i+1 for contact i; plus the chunk's penetrating flags (b,).

    All contacts at once, on (C, b) arrays: the two edges of a cone share their
    ``sqrt(1 + mu^2)``, its reciprocal and the products ``mu n`` (the edge ``n - mu t`` is
    ``n + (-mu) t``; negating ``mu`` changes no rounding), so the values are bit for bit
    those of the edge-by-edge formula ``(n + m t) / sqrt(1 + m^2)``.
    """
    # (C, b) blocks, instances contiguous: one transposing copy per input
    md = contacts.modes[sl]
    # every contact STICKING or ROLLING (codes 1 and 2; ABSENT = 0 wraps to 255): full
    # cones everywhere, no mode masks needed
    all_full = md.size > 0 and int((md.view(np.uint8) - np.uint8(1)).max()) <= 1
    pts = np.ascontiguousarray(contacts.points[sl].transpose(2, 1, 0))
    nx, ny = np.ascontiguousarray(contacts.normals[sl].transpose(2, 1, 0))
    mus = np.ascontiguousarray((contacts.mu[sl] if mu_override is None else mu_override).T)
    mu = np.where(mus < MU_ZERO, 0.0, mus)
    cx = com[sl, 0] if com.shape[0] > 1 else com[0, 0]
    cy = com[sl, 1] if com.shape[0] > 1 else com[0, 1]
    il = inv_L[sl] if inv_L.shape[0] > 1 else inv_L[0]
    rx = pts[0] - cx
    rx *= il
    ry = pts[1] - cy
    ry *= il
    C, b = mu.shape
    G = np.empty((3, C, 2, b))  # (x, y, z) x contact x edge x instance
    mny = mu * ny
    mnx = mu * nx
    root = mu * mu
    root += 1.0
    np.sqrt(root, out=root)
    X, Y, Z = G  # (C, 2, b) each: edge 0 and edge 1 of every contact
    # edge 1: n - mu t, i.e. m = -mu: (nx + mu ny, ny - mu nx) / sqrt(1 + mu^2)
    np.add(nx, mny, out=X[:, 1])
    np.subtract(ny, mnx, out=Y[:, 1])
    if all_full:
        pen = np.zeros(b, dtype=bool)
        inv = np.divide(1.0, root, out=root)  # = full / root with full all True
        # edge 0: n + mu t
        np.subtract(nx, mny, out=X[:, 0])
        np.add(ny, mnx, out=Y[:, 0])
        X *= inv[:, None]
        Y *= inv[:, None]
    else:
        modes = np.ascontiguousarray(md.T)
        pen = (modes == _PENETRATING).any(axis=0)
        full = modes == _STICKING
        full |= modes == _ROLLING
        sliding = modes == _SLIDING
        inv = np.divide(full, root)
        X[:, 1] *= inv
        Y[:, 1] *= inv
        # edge 0: n + mA t, mA = mu, or -sign(s.t) mu when sliding (the edge opposing sliding)
        X0, Y0 = X[:, 0], Y[:, 0]
        if sliding.any():
            sdx, sdy = np.ascontiguousarray(contacts.slide_dirs[sl].transpose(2, 1, 0))
            st = -sdx * ny + sdy * nx
            mA = np.where(sliding, -np.sign(st) * mu, mu)
            invA = (full | sliding) / np.sqrt(1.0 + mA * mA)
            np.subtract(nx, mA * ny, out=X0)
            X0 *= invA
            np.add(ny, mA * nx, out=Y0)
            Y0 *= invA
        else:
            np.subtract(nx, mny, out=X0)
            X0 *= inv
            np.add(ny, mnx, out=Y0)
            Y0 *= inv
    # Z = r x (X, Y) for both edges at once
    np.multiply(rx[:, None], Y, out=Z)
    tmp = np.multiply(ry[:, None], X)
    Z -= tmp
    return G.reshape(3, 2 * C, b), pen


def _com_and_scale(com: ArrayLike, length_scale: float | ArrayLike, batch: int) -> tuple[FloatArray, FloatArray]:
    c = np.asarray(com, dtype=float).reshape(-1, 2)
    L = np.asarray(length_scale, dtype=float).reshape(-1)
    if c.shape[0] not in (1, batch) or L.shape[0] not in (1, batch):
        raise GeometryError(f"com / length_scale must be per batch ({batch}) or single")
    if not (np.isfinite(c).all() and np.isfinite(L).all() and (L > 0).all()):
        raise GeometryError("com must be finite and length_scale positive")
    return c, 1.0 / L


def wrench_generators(contacts: Contacts, com: ArrayLike, length_scale: float | ArrayLike) -> tuple[FloatArray, BoolArray]:
    """Normalised wrench generators of the mode-dependent friction cones.

    Slot ``2i`` of contact ``i`` holds the edge ``(n + mu t)/sqrt(1+mu^2)`` (for a SLIDING
    contact the edge opposing sliding instead), slot ``2i+1`` the edge
    ``(n - mu t)/sqrt(1+mu^2)``; unused slots are zero. A generator with force direction
    ``d`` at point ``p`` is ``(d_x, d_y, ((p - com) x d) / L)``. Coefficients below
    :data:`MU_ZERO` count as 0.

    Parameters
    ----------
    contacts : Contacts
    com : array_like, shape (2,) or (B, 2)
        World centre of mass (mm).
    length_scale : float or array_like, shape (B,)
        ``L`` (mm).

    Returns
    -------
    generators : ndarray, shape (B, 2C, 3)
    penetrating : ndarray of bool, shape (B,)
    """
    c, il = _com_and_scale(com, length_scale, contacts.batch)
    if contacts.batch == 0:
        return np.zeros((0, 2 * contacts.count, 3)), np.zeros(0, dtype=bool)
    (X, Y, Z), pen = _generators_chunk(contacts, slice(None), c, il)
    K, B = len(X), contacts.batch
    out = np.zeros((B, K, 3))
    for k in range(K):
        out[:, k, 0], out[:, k, 1], out[:, k, 2] = X[k], Y[k], Z[k]
    return out, pen


# --------------------------------------------------------------------------------------
# Exact cone membership (the fast path)
# --------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _pair_offsets(k: int) -> tuple[int, ...]:
    """Row of pair (j, j+1) in the lexicographic list of the pairs (j, m), j < m < k: the
    pairs (j, j+1 .. k-1) are the rows ``off[j] .. off[j] + k-2-j``."""
    off, n = [], 0
    for j in range(k):
        off.append(n)
        n += k - 1 - j
    return tuple(off)


def _reduce_to_ey(X: Rows, Y: Rows, Z: Rows, t: FloatArray) -> tuple[Rows, Rows, Rows, BoolArray]:
    """Map each instance linearly so that its target ``t`` (3, b) becomes a positive
    multiple of e_y.

    Returns (K, b) arrays ``P, Q, A``: the generators' two components orthogonal (after
    the map) to the target and their component along it, and a (b,) mask of zero targets
    (which are trivially in the cone). Cone membership is invariant under invertible
    linear maps.
    """
    tx, ty, tz = t
    ax, az = np.abs(tx), np.abs(tz)
    if (ty > 0).all() and (ty >= ax).all() and (ty >= az).all():  # no target zero, none to permute
        zero = np.zeros(ty.shape, dtype=bool)
        u, v, w = tx, ty, tz
    else:  # permute coordinates so that the largest |component| sits in the middle slot
        ay = np.abs(ty)
        zero = np.maximum(np.maximum(ax, ay), az) == 0.0
        kx = (ax >= ay) & (ax >= az)
        kz = ~kx & (az > ay)
        sgn = np.where(kx, np.sign(tx), np.where(kz, np.sign(tz), np.sign(ty)))
        sgn[zero] = 1.0

        def perm(x: FloatArray, y: FloatArray, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
            return np.where(kx, y, x), np.where(kx, x, np.where(kz, z, y)) * sgn, np.where(kz, y, z)

        X, Y, Z = perm(X, Y, Z)
        u, v, w = perm(tx, ty, tz)
        v = np.where(zero, 1.0, v)
    # shear (x, y, z) -> (x - (u/v) y, y, z - (w/v) y): maps (u, v, w) to (0, v, 0), v > 0
    a, c = u / v, w / v
    P = a * Y
    np.subtract(X, P, out=P)
    Q = c * Y
    np.subtract(Z, Q, out=Q)
    return P, Q, Y, zero


def _contains_reduced(P: Rows, Q: Rows, A: Rows, b: int) -> BoolArray:
    """Is e_y in the cone of the generators ``(P_k, A_k, Q_k)``? Exact up to tolerances.

    e_y is in the cone iff some lam >= 0 has ``sum lam (P, Q) = 0`` and ``sum lam A > 0``.
    Carathéodory: a certificate uses at most three generators. For a triple (i, j, k) the
    2-D crosses ``c_jk = P_j Q_k - Q_j P_k`` give the unique zero combination
    ``lam = (c_jk, -c_ik, c_ij)``; the triple certifies iff lam has one sign and
    ``D = A_i c_jk - A_j c_ik + A_k c_ij`` (the 3x3 determinant) has the same sign.

    The crosses are one (pairs, b) array in lexicographic order (:func:`_triples`). The
    answer is the OR over the triples, so an instance accepted by a triple needs no other:
    after the triples of the first generator (most certificates among them), the
    instances still open are gathered and only they meet the other triples, which are all
    the triples of generators 1 .. n-1 (:func:`_triples_grid`, on their crosses gathered
    into the upper triangle of an (n-1, n-1, open) array). Every triple's determinant and
    sign tests are the same operations on the same values whichever way it is taken.
    """
    acc = np.zeros(b, dtype=bool)
    # the generator slots not zero in every instance (a first element decides most)
    live = [k for k in range(P.shape[0])
            if A[k, 0] != 0.0 or P[k, 0] != 0.0 or Q[k, 0] != 0.0 or A[k].any() or P[k].any() or Q[k].any()]
    n = len(live)
    if n < P.shape[0]:
        P, Q, A = P[live], Q[live], A[live]
    if n >= 3:
        off = _pair_offsets(n)
        C = np.empty((off[n - 1], b))
        T = np.empty((n - 1, b))
        for j in range(n - 1):
            m = n - 1 - j
            c = C[off[j]:off[j] + m]
            np.multiply(P[j], Q[j + 1:], out=c)
            np.multiply(Q[j], P[j + 1:], out=T[:m])
            c -= T[:m]
        GE = np.greater_equal(C, -_CROSS_TOL)
        LE = np.less_equal(C, _CROSS_TOL)
        _triples(A, C, GE, LE, n, 0, 1, acc)
        if n > 3:
            todo = np.flatnonzero(~acc)
            if todo.size > _COMPACT * b:  # too few accepted to pay for the gathers
                _triples(A, C, GE, LE, n, 1, n - 2, acc)
            elif todo.size:
                # the triples left are those of generators 1 .. n-1: the crosses of their
                # pairs gathered into the upper triangle of an (n-1, n-1, open) array (mode
                # "clip" skips take's buffered bounds check; the indices are valid), their
                # sign tests recomputed from them (cheaper than gathering them)
                m, nt = n - 1, todo.size
                Cg = np.empty((m, m, nt))
                GEg = np.empty((m, m, nt), dtype=bool)
                LEg = np.empty((m, m, nt), dtype=bool)
                for j in range(1, n - 1):
                    row = Cg[j - 1, j:]
                    np.take(C[off[j]:off[j] + n - 1 - j], todo, axis=1, out=row, mode="clip")
                    np.greater_equal(row, -_CROSS_TOL, out=GEg[j - 1, j:])
                    np.less_equal(row, _CROSS_TOL, out=LEg[j - 1, j:])
                sub = np.zeros(nt, dtype=bool)
                _triples_grid(np.take(A[1:], todo, axis=1, mode="clip"), Cg, GEg, LEg, sub)
                acc[todo] = sub
        # A one- or two-generator certificate needs a pair with |c_jk| <= |r| <= 3 tol
        # (|p| <= 1.5, |A| <= 1): only such instances go to the degenerate test.
        rest = np.flatnonzero(~acc)
        if rest.size > b // 2:
            np.abs(C, out=C)
            small = np.less_equal(C, 3.0 * _DEGENERATE_TOL, out=GE).any(axis=0)
            rest = np.flatnonzero(small & ~acc)
        elif rest.size:
            Cr = np.take(C, rest, axis=1, mode="clip")
            rest = rest[(np.abs(Cr, out=Cr) <= 3.0 * _DEGENERATE_TOL).any(axis=0)]
    else:
        rest = np.flatnonzero(~acc)
    if rest.size and n:
        acc[rest] = _contains_degenerate(P[:, rest], Q[:, rest], A[:, rest])
    return acc


#: Gather the instances still open after the first generator's triples only when at
#: most this fraction of the chunk is left (the gathers cost about as much as a sixth of
#: the remaining triples).
_COMPACT: float = 0.75


def _triples(A: Rows, C: Rows, GE: BoolArray, LE: BoolArray, n: int, first: int, stop: int, acc: BoolArray) -> None:
    """``acc |=`` the certificates of the triples (i, j, k), ``first <= i < stop``, of n
    generators. Pair (j, k) is row ``off[j] + k - j - 1`` of ``C`` (its crosses),
    ``GE`` (``c >= -tol``) and ``LE`` (``c <= tol``), ``off`` from :func:`_pair_offsets`.

    For a fixed (i, j) the triples (i, j, k > j) need the rows (j, k) and (i, k) as two
    contiguous blocks and the row (i, j): their determinants are three block operations
    with the same products and sums, in the same order, as triple by triple.
    """
    off = _pair_offsets(n)
    b = acc.shape[0]
    D = np.empty((n - 2, b))
    T = np.empty((n - 2, b))
    M1 = np.empty((n - 2, b), dtype=bool)
    M2 = np.empty((n - 2, b), dtype=bool)
    M3 = np.empty((n - 2, b), dtype=bool)
    hit = np.zeros((n - 2, b), dtype=bool)
    for i in range(first, stop):
        for j in range(i + 1, n - 1):
            m = n - 1 - j
            jk = slice(off[j], off[j] + m)  # (j, k) for k = j+1 .. n-1
            ik = slice(off[i] + j - i, off[i] + n - 1 - i)  # (i, k), same k
            ij = off[i] + j - i - 1  # (i, j)
            d, t = D[:m], T[:m]
            np.multiply(A[i], C[jk], out=d)
            np.multiply(A[j], C[ik], out=t)
            d -= t
            np.multiply(A[j + 1:], C[ij], out=t)
            d += t
            m1, m2, m3 = M1[:m], M2[:m], M3[:m]
            np.logical_and(GE[jk], LE[ik], out=m1)
            m1 &= GE[ij]
            m1 &= np.greater(d, _DET_TOL, out=m3)
            np.logical_and(LE[jk], GE[ik], out=m2)
            m2 &= LE[ij]
            m2 &= np.less(d, -_DET_TOL, out=m3)
            m1 |= m2
            hit[:m] |= m1
    acc |= hit.any(axis=0)


def _triples_grid(A: Rows, Cg: FloatArray, GEg: BoolArray, LEg: BoolArray, acc: BoolArray) -> None:
    """``acc |=`` the certificates of all the triples (i, j, k), i < j < k, of n generators
    whose crosses ``c_jk`` are the upper triangle of the (n, n, b) array ``Cg`` (its sign
    tests ``GEg``, ``LEg`` alike; the rest is never read).

    For a fixed middle j the triples (i, j, k), i < j < k, form an (i, k) grid: its crosses
    c_jk (a row block, broadcast over i), c_ik (one strided block) and c_ij (a column,
    broadcast over k) are views of ``Cg``, so the grid's determinants and sign tests are
    one set of array operations, with the same products and sums, in the same order, as
    triple by triple (:func:`_triples`): n - 2 sets instead of (n - 1)(n - 2)/2. On the
    few instances left after the first generator's triples, where a call's fixed cost
    weighs, this is about a quarter faster.
    """
    n, b = A.shape
    size = max([j * (n - 1 - j) for j in range(1, n - 1)], default=0) * b
    if size == 0:
        return
    D = np.empty(size)
    T = np.empty(size)
    M1 = np.empty(size, dtype=bool)
    M2 = np.empty(size, dtype=bool)
    M3 = np.empty(size, dtype=bool)
    hit = np.zeros(size, dtype=bool)
    for j in range(1, n - 1):
        m = n - 1 - j
        shape = (j, m, b)
        s = j * m * b
        d, t = D[:s].reshape(shape), T[:s].reshape(shape)
        m1, m2, m3 = M1[:s].reshape(shape), M2[:s].reshape(shape), M3[:s].reshape(shape)
        ks = slice(j + 1, n)
        np.multiply(A[:j, None], Cg[j, ks], out=d)  # A_i c_jk
        np.multiply(A[j], Cg[:j, ks], out=t)  # A_j c_ik
        d -= t
        np.multiply(A[ks], Cg[:j, j, None], out=t)  # A_k c_ij
        d += t
        np.logical_and(GEg[j, ks], LEg[:j, ks], out=m1)
        m1 &= GEg[:j, j, None]
        m1 &= np.greater(d, _DET_TOL, out=m3)
        np.logical_and(LEg[j, ks], GEg[:j, ks], out=m2)
        m2 &= LEg[:j, j, None]
        m2 &= np.less(d, -_DET_TOL, out=m3)
        m1 |= m2
        h = hit[:s].reshape(shape)
        h |= m1
    acc |= hit.reshape(-1, b).any(axis=0)


def _contains_degenerate(P: Rows, Q: Rows, A: Rows) -> BoolArray:
    """Certificates with one or two generators (needed when the cone is not full-dim).

    Single k: ``|p_k| <= tol * A_k``. Pair (j, k): the combination ``|p_k| g_j + |p_j| g_k``
    has planar part ``r`` and height ``h``; it certifies iff ``|r| <= tol * h``. Either way
    the cone holds a vector within angle ``tol`` of the target direction.
    """
    tol2 = _DEGENERATE_TOL * _DEGENERATE_TOL
    norm2 = [p * p + q * q for p, q in zip(P, Q)]
    acc = np.zeros(P[0].shape, dtype=bool)
    for n2, a in zip(norm2, A):
        acc |= (a > 0) & (n2 <= tol2 * a * a)
    nrm = [np.sqrt(n2) for n2 in norm2]
    for j, k in itertools.combinations(range(len(P)), 2):
        rx = nrm[k] * P[j] + nrm[j] * P[k]
        ry = nrm[k] * Q[j] + nrm[j] * Q[k]
        h = nrm[k] * A[j] + nrm[j] * A[k]
        acc |= (h > 0) & (rx * rx + ry * ry <= tol2 * h * h)
    return acc


def _contains_numpy(G: Gens, t: FloatArray) -> BoolArray:
    """The cone test's rule in numpy: is ``t[:, i]`` in the cone of the generators
    ``G[:, :, i]`` of a chunk (``G`` (3, K, b), ``t`` (3, b))?"""
    P, Q, A, zero = _reduce_to_ey(G[0], G[1], G[2], t)
    return _contains_reduced(P, Q, A, zero.shape[0]) | zero


def _contains_compiled(G: Gens, t: FloatArray) -> BoolArray:
    """:func:`_contains_numpy`'s rule in the compiled kernel (``geometry/_kernels.c``): the
    same operations on the same values, in blocks of instances that stop once each of
    their instances holds a certificate."""
    G = np.ascontiguousarray(G, dtype=float)
    out = np.empty(G.shape[2], dtype=bool)
    _kernels.contains(G[0], G[1], G[2], np.ascontiguousarray(t, dtype=float), out.view(np.uint8),
                      _CROSS_TOL, _DET_TOL, _DEGENERATE_TOL)
    return out


def _contains(G: Gens, t: FloatArray) -> BoolArray:
    """Cone membership of a chunk: the compiled kernel where it is built and the chunk
    has at most its number of generator slots, otherwise numpy (both decide alike)."""
    if _kernels is not None and G.shape[1] <= _kernels.MAX_SLOTS and G.shape[2]:
        return _contains_compiled(G, t)
    return _contains_numpy(G, t)


def _shifted_target(G: Gens, target: FloatArray, eps: FloatArray | float) -> FloatArray:
    """``target - eps * sum_k g_k`` as a (3, b) array; ``target`` is (3,) or (3, b). The
    sum runs over the generators in order, from zero."""
    s = np.zeros((3, G.shape[2]))
    for k in range(G.shape[1]):
        s += G[:, k]
    s *= eps
    return np.subtract(np.reshape(target, (3, -1)), s, out=s)


def cone_contains(generators: ArrayLike, target: ArrayLike, margin: float | ArrayLike = 0.0) -> BoolArray:
    """Exact test ``target - margin * sum_k g_k  in  cone{g_k}`` for a batch of cones.

    With ``margin = eps`` this decides ``M(target) >= eps`` for the LP margin
    ``M = max{s : sum lam_k g_k = target, lam_k >= s}``; ``margin = 0`` is plain
    (closed) cone membership.

    Parameters
    ----------
    generators : array_like, shape (B, K, 3)
        Zero rows are unused slots.
    target : array_like, shape (3,) or (B, 3)
    margin : float or array_like, shape (B,)

    Returns
    -------
    ndarray of bool, shape (B,)

    Examples
    --------
    >>> g = np.array([[[0.0, 1.0, -0.5], [0.0, 1.0, 0.5]]])
    >>> cone_contains(g, [0.0, 1.0, 0.0], 1e-7).tolist()
    [True]
    """
    g = np.asarray(generators, dtype=float)
    if g.ndim != 3 or g.shape[-1] != 3:
        raise GeometryError(f"generators must have shape (B, K, 3), got {g.shape}")
    B, K = g.shape[:2]
    tgt = np.broadcast_to(np.asarray(target, dtype=float).reshape(-1, 3), (B, 3))
    eps = np.broadcast_to(np.asarray(margin, dtype=float).reshape(-1), (B,))
    out = np.empty(B, dtype=bool)
    for s in range(0, B, _CHUNK):
        sl = slice(s, min(s + _CHUNK, B))
        b = sl.stop - sl.start
        G = np.ascontiguousarray(g[sl].transpose(2, 1, 0)) if K else np.zeros((3, 1, b))
        out[sl] = _contains(G, _shifted_target(G, tgt[sl].T, eps[sl]))
    return out


def _check_contacts_frame(contacts: Contacts, com: ArrayLike, length_scale: float | ArrayLike) -> tuple[FloatArray, FloatArray]:
    return _com_and_scale(com, length_scale, contacts.batch)


_EY = np.array([0.0, 1.0, 0.0])


_MODE_CODES = (int(ContactMode.STICKING), int(ContactMode.ROLLING), int(ContactMode.SLIDING),
               int(ContactMode.PENETRATING))


def _feasible_impl(
    contacts: Contacts, com: FloatArray, inv_L: FloatArray, margin: FloatArray, mu_override: FloatArray | None = None
) -> BoolArray:
    """Feasibility of every instance: the compiled kernel (generators, shifted target and
    cone test fused, ``geometry/_kernels.c``) where it is built and takes the contact count,
    otherwise :func:`_feasible_numpy` (both decide alike)."""
    B, C = contacts.batch, contacts.count
    if _kernels is not None and 0 < 2 * C <= _kernels.MAX_SLOTS:
        mu = contacts.mu if mu_override is None else np.asarray(mu_override, dtype=float)
        if mu.shape == (B, C):
            out = np.empty(B, dtype=bool)
            c = np.ascontiguousarray
            _kernels.feasible(c(contacts.points), c(contacts.normals), c(mu), c(contacts.modes),
                              c(contacts.slide_dirs), c(com, dtype=float), c(inv_L, dtype=float),
                              c(margin, dtype=float), out.view(np.uint8), _CHUNK, _MODE_CODES, MU_ZERO,
                              _CROSS_TOL, _DET_TOL, _DEGENERATE_TOL)
            return out
    return _feasible_numpy(contacts, com, inv_L, margin, mu_override)


def _feasible_numpy(
    contacts: Contacts, com: FloatArray, inv_L: FloatArray, margin: FloatArray, mu_override: FloatArray | None = None
) -> BoolArray:
    """The feasibility rule in numpy, chunk by chunk: the generators, the target e_y
    shifted by the margin, the cone test, and no PENETRATING contact."""
    B = contacts.batch
    out = np.empty(B, dtype=bool)
    if contacts.count == 0:
        out[:] = False
        return out
    for s in range(0, B, _CHUNK):
        sl = slice(s, min(s + _CHUNK, B))
        mu = None if mu_override is None else mu_override[sl]
        G, pen = _generators_chunk(contacts, sl, com, inv_L, mu)
        eps = margin[sl] if margin.shape[0] > 1 else margin[0]
        out[sl] = _contains(G, _shifted_target(G, _EY, eps)) & ~pen
    return out


def feasible_batch(
    contacts: Contacts, com: ArrayLike, length_scale: float | ArrayLike, margin: float | ArrayLike = FEASIBILITY_MARGIN
) -> BoolArray:
    """Fast batched quasi-static feasibility: is the weight balanced with margin?

    True iff no contact is PENETRATING and the LP margin ``M`` (module docstring) is at
    least ``margin``, decided exactly (up to floating-point conditioning) as
    ``e_y - margin * gbar in cone{g_k}``.

    Parameters
    ----------
    contacts : Contacts
        (B, C) contacts with their modes.
    com : array_like, shape (2,) or (B, 2)
        World centre of mass (mm).
    length_scale : float or array_like, shape (B,)
        ``L`` (mm), normally ``ObjectModel.length_scale``.
    margin : float or array_like, shape (B,)
        Normalised margin threshold; default :data:`FEASIBILITY_MARGIN`.

    Returns
    -------
    ndarray of bool, shape (B,)

    Examples
    --------
    >>> block = Contacts.make([[-1.0, -1.0], [1.0, -1.0]], [[0.0, 1.0], [0.0, 1.0]], 0.0)
    >>> feasible_batch(block, [0.0, 0.0], math.sqrt(2.0)).tolist()
    [True]
    """
    c, il = _check_contacts_frame(contacts, com, length_scale)
    eps = np.asarray(margin, dtype=float).reshape(-1)
    if eps.shape[0] not in (1, contacts.batch):
        raise GeometryError("margin must be a float or one value per instance")
    return _feasible_impl(contacts, c, il, eps)


def force_closure_batch(
    contacts: Contacts, com: ArrayLike, length_scale: float | ArrayLike, margin: float = FEASIBILITY_MARGIN
) -> BoolArray:
    """Force closure: the contacts' cones (as given by their modes) span all of R^3.

    True iff each of the six targets ``+-e_x, +-e_y, +-e_tau`` passes the fast test with
    ``margin`` (then the cone contains a neighbourhood of 0, i.e. it is R^3). PENETRATING
    contacts make it False. Gravity plays no part; ``com`` only fixes the moment reference
    (force closure does not depend on it).

    Returns
    -------
    ndarray of bool, shape (B,)
    """
    c, il = _check_contacts_frame(contacts, com, length_scale)
    B = contacts.batch
    out = np.zeros(B, dtype=bool)
    if contacts.count == 0:
        return out
    targets = np.concatenate([np.eye(3), -np.eye(3)])
    for s in range(0, B, _CHUNK):
        sl = slice(s, min(s + _CHUNK, B))
        G, pen = _generators_chunk(contacts, sl, c, il)
        ok = ~pen
        for e in targets:
            idx = np.flatnonzero(ok)
            if not idx.size:
                break
            Gi = np.take(G, idx, axis=2)
            ok[idx] = _contains(Gi, _shifted_target(Gi, e, margin))
        out[sl] = ok
    return out


# --------------------------------------------------------------------------------------
# Reference path (cvxpy + Clarabel)
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _ReferenceProblem:
    """A parametrised LP ``max s : G lam = e_y, lam >= s, s <= cap`` for k generators."""

    problem: Any
    G: Any
    lam: Any
    s: Any


@functools.lru_cache(maxsize=32)
def _reference_problem(k: int) -> _ReferenceProblem:
    import cvxpy as cp

    G = cp.Parameter((3, k))
    lam = cp.Variable(k)
    s = cp.Variable()
    prob = cp.Problem(cp.Maximize(s), [G @ lam == np.array([0.0, 1.0, 0.0]), lam >= s, s <= MARGIN_CAP])
    return _ReferenceProblem(prob, G, lam, s)


def _run_solver(ref: _ReferenceProblem) -> str:
    """Solve with Clarabel and return cvxpy's status string (a seam for tests)."""
    import cvxpy as cp

    with warnings.catch_warnings():  # "solution may be inaccurate": the status says it
        warnings.simplefilter("ignore", UserWarning)
        ref.problem.solve(solver=cp.CLARABEL)
    return str(ref.problem.status)


def feasible_reference(
    contacts: Contacts,
    com: ArrayLike,
    length_scale: float,
    weight: float = 1.0,
    margin: float = FEASIBILITY_MARGIN,
) -> ReferenceResult:
    """Reference feasibility of ONE instance: the margin LP solved by cvxpy with Clarabel.

    Status mapping (never raises for solver outcomes):

    - ``optimal``: margin ``M = s``; FEASIBLE iff ``M >= margin`` else INFEASIBLE;
    - ``optimal_inaccurate``: FEASIBLE only if the recovered coefficients verify the
      equilibrium (residual ``<= FEASIBILITY_MARGIN`` and least coefficient ``>= margin``),
      else UNKNOWN;
    - ``infeasible``: INFEASIBLE with ``M = -inf``;
    - ``infeasible_inaccurate``, ``unbounded``, ``unbounded_inaccurate``, any other status,
      and solver exceptions: UNKNOWN.

    Three outcomes need no solve and are INFEASIBLE with ``M = -inf``: a PENETRATING
    contact, no generator at all, and ``e_y`` outside the linear span of the generators
    (least-squares residual above 1e-9: the equality ``G lam = e_y`` has no solution; on
    such rank-deficient systems Clarabel tends to stall rather than certify).

    Parameters
    ----------
    contacts : Contacts
        A batch of exactly one instance.
    com : array_like, shape (2,)
    length_scale : float
    weight : float
        ``m g`` in newtons: only scales the returned forces.
    margin : float

    Returns
    -------
    ReferenceResult
    """
    import cvxpy as cp

    if contacts.batch != 1:
        raise GeometryError(f"feasible_reference takes one instance, got a batch of {contacts.batch}")
    gens, pen = wrench_generators(contacts, com, length_scale)
    C = contacts.count
    if pen[0]:
        return ReferenceResult(FeasibilityStatus.INFEASIBLE, -math.inf, None, "not solved: penetrating contact")
    g = gens[0]
    active = np.flatnonzero(np.abs(g).sum(axis=1) > 0)
    if active.size == 0:
        return ReferenceResult(FeasibilityStatus.INFEASIBLE, -math.inf, None, "not solved: no contact force available")
    Ga = g[active].T
    ey = np.array([0.0, 1.0, 0.0])
    lsq = np.linalg.lstsq(Ga, ey, rcond=None)[0]
    residual = float(np.linalg.norm(Ga @ lsq - ey))
    if residual > _SPAN_TOL:
        note = f"not solved: e_y outside the span of the generators (residual {residual:.3g})"
        return ReferenceResult(FeasibilityStatus.INFEASIBLE, -math.inf, None, note)
    ref = _reference_problem(int(active.size))
    ref.G.value = Ga
    try:
        status = _run_solver(ref)
    except cp.error.SolverError as exc:
        logger.debug("reference solve failed: %s", exc)
        return ReferenceResult(FeasibilityStatus.UNKNOWN, math.nan, None, f"solver error: {exc}")
    except Exception as exc:  # noqa: BLE001 - the contract is: no exception escapes a solve
        logger.warning("reference solve raised %s: %s", type(exc).__name__, exc)
        return ReferenceResult(FeasibilityStatus.UNKNOWN, math.nan, None, f"{type(exc).__name__}: {exc}")

    def forces(lam: FloatArray) -> FloatArray:
        f = np.zeros((2 * C, 2))
        f[active] = lam[:, None] * g[active, :2]
        return weight * f.reshape(C, 2, 2).sum(axis=1)

    lam = ref.lam.value
    if status == cp.OPTIMAL:
        if ref.s.value is None or lam is None:
            return ReferenceResult(FeasibilityStatus.UNKNOWN, math.nan, None, status)
        m = min(float(ref.s.value), MARGIN_CAP)
        if m >= margin:
            return ReferenceResult(FeasibilityStatus.FEASIBLE, m, forces(np.asarray(lam)), status)
        return ReferenceResult(FeasibilityStatus.INFEASIBLE, m, None, status)
    if status == cp.OPTIMAL_INACCURATE:
        if lam is not None and np.all(np.isfinite(lam)):
            lam = np.asarray(lam, dtype=float)
            residual = float(np.max(np.abs(Ga @ lam - ey)))
            m = min(float(lam.min()), MARGIN_CAP)
            if residual <= _VERIFY_TOL and m >= margin:
                return ReferenceResult(FeasibilityStatus.FEASIBLE, m, forces(lam), status)
            logger.debug("inaccurate reference solution not verified: residual %.3g, margin %.3g", residual, m)
        return ReferenceResult(FeasibilityStatus.UNKNOWN, math.nan, None, status)
    if status == cp.INFEASIBLE:
        return ReferenceResult(FeasibilityStatus.INFEASIBLE, -math.inf, None, status)
    logger.debug("reference solve ended with status %s", status)
    return ReferenceResult(FeasibilityStatus.UNKNOWN, math.nan, None, status)


# --------------------------------------------------------------------------------------
# Grasp quality
# --------------------------------------------------------------------------------------


def reaction_angle_batch(
    contacts: Contacts,
    com: ArrayLike,
    length_scale: float | ArrayLike,
    iterations: int = 16,
    margin: float = FEASIBILITY_MARGIN,
) -> FloatArray:
    """Smallest mean friction-usage angle that still admits equilibrium, per instance.

    With ``R`` the STICKING/ROLLING contacts of an instance, narrow each of their cones to
    half-angle ``rho * atan(mu_i)`` (i.e. ``mu_i -> tan(rho * atan(mu_i))``; SLIDING edges keep
    their ``mu``) and find the least ``rho in [0, 1]`` that stays feasible by bisection
    (feasibility is monotone in ``rho``). The result is

        alpha = rho_hi * mean_{i in R} atan(mu_i)

    with ``rho_hi`` the feasible end of the final bracket (width ``2**-iterations``).
    ``nan`` where the instance is infeasible at ``rho = 1``; ``0`` where feasible with
    ``R`` empty or at ``rho = 0``.

    Returns
    -------
    ndarray, shape (B,)
        Radians.
    """
    c, il = _check_contacts_frame(contacts, com, length_scale)
    eps = np.array([margin], dtype=float)
    modes = contacts.modes
    R = (modes == ContactMode.STICKING) | (modes == ContactMode.ROLLING)
    half = np.arctan(contacts.mu)
    nR = R.sum(axis=1)
    mean_half = np.where(nR > 0, np.where(R, half, 0.0).sum(axis=1) / np.maximum(nR, 1), 0.0)
    ok = _feasible_impl(contacts, c, il, eps)
    out = np.full(contacts.batch, np.nan)
    out[ok] = 0.0
    todo = np.flatnonzero(ok & (nR > 0))
    if todo.size == 0:
        return out
    sub = contacts.select(todo)
    cs = c if c.shape[0] == 1 else c[todo]
    ils = il if il.shape[0] == 1 else il[todo]
    Rs, hs = R[todo], half[todo]

    def feasible_at(rho: FloatArray) -> BoolArray:
        mu = np.where(Rs, np.tan(rho[:, None] * hs), sub.mu)
        return _feasible_impl(sub, cs, ils, eps, mu)

    lo = np.zeros(todo.size)
    hi = np.ones(todo.size)
    hi[feasible_at(lo)] = 0.0
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        f = feasible_at(mid)
        hi = np.where(f, mid, hi)
        lo = np.where(f, lo, mid)
    out[todo] = hi * mean_half[todo]
    return out


def grasp_quality(
    fingers: Contacts,
    motion: Contacts,
    com: ArrayLike,
    length_scale: float,
    w1: float = 1.0,
    w2: float = 1.0,
    iterations: int = 16,
) -> GraspQuality:
    """Grasp quality ``S(g, m) = w1 * s + w2 * alpha`` (paper, "Grasp quality").

    - ``s = 0`` if the finger contacts alone (full cones, i.e. taken as STICKING) are force
      closure at every sample (:func:`force_closure_batch`), else ``1``;
    - ``alpha`` = mean over the samples having a STICKING/ROLLING contact of
      :func:`reaction_angle_batch` (radians).

    Parameters
    ----------
    fingers : Contacts
        (J, F) finger contacts at each of the J samples (modes ignored except ABSENT).
    motion : Contacts
        (J, C) every contact (fingers and environment) at each sample, with its mode.
    com : array_like, shape (J, 2) or (2,)
        World COM at each sample.
    length_scale : float
    w1, w2 : float
        Weights; ``alpha`` enters in radians.
    iterations : int
        Bisection steps of :func:`reaction_angle_batch`.

    Returns
    -------
    GraspQuality
        ``admissible`` is False (and ``alpha``, ``value`` may be nan) when some sample is
        infeasible; those samples are left out of ``alpha``.
    """
    fm = np.where(fingers.modes == ContactMode.ABSENT, ContactMode.ABSENT, ContactMode.STICKING)
    closure = bool(force_closure_batch(fingers.with_modes(fm), com, length_scale).all())
    angles = reaction_angle_batch(motion, com, length_scale, iterations=iterations)
    admissible = bool(np.isfinite(angles).all())
    has_R = ((motion.modes == ContactMode.STICKING) | (motion.modes == ContactMode.ROLLING)).any(axis=1)
    use = has_R & np.isfinite(angles)
    if use.any():
        alpha = float(angles[use].mean())
    else:
        alpha = 0.0 if admissible else math.nan
    s = 0 if closure else 1
    return GraspQuality(w1 * s + w2 * alpha, closure, s, alpha, admissible)



# --------------------------------------------------------------------------------------
# Forces under a finger force limit (batched LP)
# --------------------------------------------------------------------------------------

#: Instances per block-diagonal LP of :func:`bounded_support`.
_LP_CHUNK: int = 256


@dataclass(frozen=True, eq=False)
class BoundedSupport:
    """Result of :func:`bounded_support`: equilibria under a finger force limit.

    Attributes
    ----------
    feasible : ndarray of bool, shape (B,)
        The cone test passes and some equilibrium has every finger's normal force at
        most ``max_force``.
    equilibrium : ndarray of bool, shape (B,)
        The LP found an equilibrium (force limit aside): the forces below are defined.
    forces : ndarray, shape (B, C, 2)
        Per contact, the force on the object as ``[normal, tangential]`` in newtons:
        along the contact's normal ``n`` (into the object) and along its tangent
        ``t = (-n_y, n_x)``; zero for absent contacts, ``nan`` where no equilibrium.
    finger_forces : ndarray, shape (B, F, 2)
        Per finger, the sum over its contacts of ``[normal, tangential]`` in the plan
        spec's convention (``finger_forces`` of ``ldhp-plan/1``): the normal component
        pushes into the object, the tangential one is along the object edge's
        counter-clockwise direction, i.e. along ``-t`` for an inward edge normal ``n``;
        zero for a finger without contact, ``nan`` where no equilibrium.
    max_finger_force : ndarray, shape (B,)
        The largest finger normal force (N) of that equilibrium, the least possible over
        all equilibria (the LP's objective); 0 without finger contact, ``nan`` where no
        equilibrium.
    """

    feasible: BoolArray
    equilibrium: BoolArray
    forces: FloatArray
    finger_forces: FloatArray
    max_finger_force: FloatArray


def _lp_block(G: FloatArray, A: FloatArray, ub: FloatArray, fixed: FloatArray | None = None) -> FloatArray | None:
    """Solve ``min sum_b t_b : G_b lam_b = e_y, A_b lam_b <= t_b, 0 <= lam_b <= ub_b``
    for a chunk at once (the instances decouple: one block-diagonal LP). ``G`` is
    (b, 3, K), ``A`` (b, F, K) and ``ub`` (b, K). ``fixed`` (b, F), where finite, adds
    the equality ``A_bf lam_b = fixed_bf`` (a pressed finger's normal force). Returns
    ``lam`` (b, K) or ``None`` when HiGHS does not report an optimum."""
    import scipy.sparse as sp
    from scipy.optimize import linprog

    b, _, K = G.shape
    F = A.shape[1]
    nv = K + 1
    base = (np.arange(b) * nv)[:, None, None]
    cols = base + np.arange(K)[None, None, :]
    eq_rows = (np.arange(b)[:, None, None] * 3 + np.arange(3)[None, :, None]).repeat(K, axis=2)
    eq = sp.coo_array((G.reshape(-1), (eq_rows.reshape(-1), np.broadcast_to(cols, G.shape).reshape(-1))),
                      shape=(3 * b, nv * b))
    b_eq = np.tile(_EY, b)
    if fixed is not None and np.isfinite(fixed).any():
        fb, ff = np.nonzero(np.isfinite(fixed))
        n_fix = fb.size
        vals = A[fb, ff, :]  # (n_fix, K)
        fix = sp.coo_array((vals.reshape(-1), (np.repeat(np.arange(n_fix), K), (fb[:, None] * nv + np.arange(K)[None, :])
                                                 .reshape(-1))), shape=(n_fix, nv * b))
        eq = sp.vstack([eq, fix])
        b_eq = np.concatenate([b_eq, fixed[fb, ff]])
    rows_ub = (np.arange(b)[:, None] * F + np.arange(F)[None, :])  # (b, F)
    ub_vals = np.concatenate([A, -np.ones((b, F, 1))], axis=2)  # (b, F, K+1)
    ub_cols = np.broadcast_to((np.arange(b) * nv)[:, None, None] + np.arange(nv)[None, None, :], ub_vals.shape)
    ub_rows = np.broadcast_to(rows_ub[..., None], ub_vals.shape)
    ineq = sp.coo_array((ub_vals.reshape(-1), (ub_rows.reshape(-1), ub_cols.reshape(-1))), shape=(F * b, nv * b))
    c = np.zeros((b, nv))
    c[:, K] = 1.0
    bounds = np.zeros((b, nv, 2))
    bounds[:, :K, 1] = ub
    bounds[:, K, 1] = np.inf
    res = linprog(c.reshape(-1), A_ub=ineq.tocsr() if F else None, b_ub=np.zeros(F * b) if F else None,
                  A_eq=eq.tocsr(), b_eq=b_eq, bounds=bounds.reshape(-1, 2), method="highs",
                  options={"primal_feasibility_tolerance": 0.1 * FEASIBILITY_MARGIN,
                           "dual_feasibility_tolerance": 0.1 * FEASIBILITY_MARGIN})
    if res.status != 0 or res.x is None:
        return None
    return np.asarray(res.x, dtype=float).reshape(b, nv)[:, :K]


def pressed_feasible(contacts: Contacts, com: ArrayLike, length_scale: float, column: ArrayLike,
                     force: ArrayLike) -> BoolArray:
    """(B,) quasi-static support with one contact's normal force fixed (a pressed finger),
    decided exactly by cone tests, without an LP.

    Contact ``column[b]`` of instance ``b`` has its normal force fixed at ``force[b]`` (in
    units of the weight); the other contacts keep their mode-dependent cones (closed:
    margin 0). A SLIDING pressed contact's force is then known, ``w``, and the test is
    ``e_y - w in cone{g}``. A STICKING one's is ``w(a) = (1 - a) w_- + a w_+``, ``a`` in
    [0, 1], between its two cone edges scaled to that normal force: with ``d = w_+ - w_-``
    the set of feasible ``a`` is an interval (the cone is convex), so it meets [0, 1]
    exactly when ``e_y - w_- in cone{g, d}`` (some feasible ``a >= 0``) and
    ``e_y - w_+ in cone{g, -d}`` (some feasible ``a <= 1``). The same decisions as
    :func:`bounded_support` with ``pressed`` (a test compares them).
    """
    c, il = _check_contacts_frame(contacts, com, length_scale)
    B, C = contacts.batch, contacts.count
    col = np.broadcast_to(np.asarray(column, dtype=np.int64), (B,))
    f = np.broadcast_to(np.asarray(force, dtype=float), (B,))
    gens, pen = wrench_generators(contacts, c, 1.0 / il)  # (B, 2C, 3), unit force directions
    rows = np.arange(B)
    mu = contacts.mu[rows, col]
    scale = (f * np.sqrt(1.0 + np.where(mu < MU_ZERO, 0.0, mu) ** 2))[:, None]
    w_plus = gens[rows, 2 * col] * scale
    w_minus = gens[rows, 2 * col + 1] * scale
    others = gens.copy()
    others[rows, 2 * col] = 0.0
    others[rows, 2 * col + 1] = 0.0
    sliding = contacts.modes[rows, col] == ContactMode.SLIDING
    out = np.zeros(B, dtype=bool)
    if sliding.any():
        sl = np.flatnonzero(sliding)
        out[sl] = cone_contains(others[sl], _EY[None, :] - w_plus[sl], 0.0)
    st = np.flatnonzero(~sliding)
    if st.size:
        d = (w_plus - w_minus)[st]
        a = cone_contains(np.concatenate([others[st], d[:, None, :]], axis=1), _EY[None, :] - w_minus[st], 0.0)
        b = np.zeros(st.size, dtype=bool)
        if a.any():
            sa = st[a]
            b[a] = cone_contains(np.concatenate([others[sa], -d[a][:, None, :]], axis=1),
                                 _EY[None, :] - w_plus[sa], 0.0)
        out[st] = a & b
    return out & ~pen


def _lp_phase1(G: FloatArray, A: FloatArray, ub: FloatArray, fixed: FloatArray | None = None) -> BoolArray | None:
    """(b,) which instances of a chunk of :func:`_lp_block` have a feasible point: one
    block-diagonal LP, always feasible, minimising per instance the slack its equalities
    need (``G lam + s+ - s- = e_y``, and the fixed rows); feasible where the slack is at
    most :data:`FEASIBILITY_MARGIN`. ``None`` when HiGHS does not report an optimum. It
    lets one infeasible instance leave its chunk instead of sending every instance of the
    chunk to an LP of its own."""
    import scipy.sparse as sp
    from scipy.optimize import linprog

    b, _, K = G.shape
    F = A.shape[1]
    fx = np.full((b, F), np.nan) if fixed is None else fixed
    R = 3 + F
    nv = K + 2 * R
    rows = np.arange(b)[:, None] * R  # first row of each instance
    # G rows, then one row per finger (zero where the finger is not fixed)
    M = np.concatenate([G, np.where(np.isfinite(fx)[..., None], A, 0.0)], axis=1)  # (b, R, K)
    rr = np.broadcast_to((rows + np.arange(R)[None, :])[..., None], M.shape)
    cc = np.broadcast_to((np.arange(b) * nv)[:, None, None] + np.arange(K)[None, None, :], M.shape)
    sr = np.broadcast_to(rows + np.arange(R)[None, :], (b, R))
    plus = (np.arange(b) * nv)[:, None] + K + np.arange(R)[None, :]
    minus = plus + R
    data = np.concatenate([M.reshape(-1), np.ones(b * R), -np.ones(b * R)])
    ri = np.concatenate([rr.reshape(-1), sr.reshape(-1), sr.reshape(-1)])
    ci = np.concatenate([cc.reshape(-1), plus.reshape(-1), minus.reshape(-1)])
    eq = sp.coo_array((data, (ri, ci)), shape=(R * b, nv * b)).tocsr()
    rhs = np.concatenate([np.broadcast_to(_EY, (b, 3)), np.nan_to_num(fx)], axis=1).reshape(-1)
    c = np.zeros((b, nv))
    c[:, K:] = 1.0
    bounds = np.zeros((b, nv, 2))
    bounds[:, :K, 1] = ub
    bounds[:, K:, 1] = np.inf
    res = linprog(c.reshape(-1), A_eq=eq, b_eq=rhs, bounds=bounds.reshape(-1, 2), method="highs")
    if res.status != 0 or res.x is None:
        return None
    slack = np.asarray(res.x, dtype=float).reshape(b, nv)[:, K:].sum(axis=1)
    return slack <= FEASIBILITY_MARGIN


def bounded_support(
    contacts: Contacts,
    com: ArrayLike,
    length_scale: float | ArrayLike,
    weight: float,
    finger_of: ArrayLike,
    max_force: float | None = None,
    margin: float = FEASIBILITY_MARGIN,
    fingers: int = 2,
    pressed: ArrayLike | None = None,
) -> BoundedSupport:
    """Quasi-static support with every finger's normal force bounded, and its forces.

    First the cone test (:func:`feasible_batch` with ``margin``): instances it refuses
    stay refused. On the others, one linear program per instance (solved a chunk at a
    time by HiGHS, ``scipy.optimize.linprog``, as one block-diagonal LP):

        min t   s.t.   sum_k lam_k g_k = e_y,   lam >= 0,
                       sum_{k of finger f} (d_k . n_k) lam_k <= t   (every finger f)

    over the mode-dependent generators ``g_k`` of :func:`wrench_generators` (two per
    STICKING/ROLLING contact, one per SLIDING one; ``d_k`` the generator's unit force,
    ``n_k`` its contact's normal), in normalised units (forces / ``weight``). ``t``
    is the least possible largest finger normal force; the instance is feasible iff
    ``t * weight <= max_force`` within :data:`FEASIBILITY_MARGIN` (normalised, like the
    equilibrium residual the LP solution is verified to). The LP's solution is also the
    force solution returned (a vertex: forces often lie on cone edges).

    A *pressed* finger (``pressed``, an executor's press to a set force) has its normal
    force fixed: ``sum_{k of finger f} (d_k . n_k) lam_k = pressed_f / weight``, its
    tangential force free within its mode's cone (both edges for a sticking contact, the
    one edge opposing the slip for a sliding one).

    Parameters
    ----------
    contacts : Contacts
        (B, C) contacts with their modes.
    com : array_like, shape (2,) or (B, 2)
    length_scale : float or array_like, shape (B,)
    weight : float
        ``m g`` (N).
    finger_of : array_like of int, broadcastable to (B, C)
        The finger (``0 .. fingers-1``) each contact belongs to, ``-1`` for an
        environment contact.
    max_force : float or None
        The limit (N) on each finger's total normal force; ``None`` or ``inf``: none
        (the forces are still computed).
    margin : float
        The cone test's margin (0 for closed cones, as the plan validator uses).
    fingers : int
        ``F``, the number of fingers in ``finger_forces``.
    pressed : array_like, shape (F,) or (B, F), optional
        Per finger, the normal force (N) a press holds it at, ``nan`` for a finger that
        is not pressed (its force is the LP's, bounded by ``max_force``).

    Returns
    -------
    BoundedSupport

    Examples
    --------
    A 1 kg block pinched at its ends by two fingers with mu = 0.5: each finger must
    press with at least W / (2 mu) = 9.81 N.

    >>> pinch = Contacts.make([[-1.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [-1.0, 0.0]], 0.5)
    >>> r = bounded_support(pinch, [0.0, 0.0], 1.0, weight=9.81, finger_of=[0, 1], max_force=10.0)
    >>> bool(r.feasible[0]), round(float(r.max_finger_force[0]), 6)
    (True, 9.81)
    >>> np.round(r.finger_forces[0], 6).tolist()   # [normal, tangential (counter-clockwise)] per finger
    [[9.81, -4.905], [9.81, 4.905]]
    >>> bool(bounded_support(pinch, [0.0, 0.0], 1.0, 9.81, [0, 1], max_force=9.0).feasible[0])
    False
    """
    c, il = _check_contacts_frame(contacts, com, length_scale)
    B, C = contacts.batch, contacts.count
    if not (math.isfinite(weight) and weight > 0):
        raise GeometryError(f"weight must be a positive number of newtons, got {weight}")
    limit = math.inf if max_force is None else float(max_force)
    if not limit > 0:
        raise GeometryError(f"max_force must be positive, got {max_force}")
    fo = np.broadcast_to(np.asarray(finger_of, dtype=np.int64), (B, C))
    if fo.size and (fo.min() < -1 or fo.max() >= fingers):
        raise GeometryError(f"finger_of must lie in -1 .. {fingers - 1}")
    fixed = None
    if pressed is not None:
        fixed = np.array(np.broadcast_to(np.asarray(pressed, dtype=float), (B, fingers))) / weight
        if (fixed[np.isfinite(fixed)] < 0).any():
            raise GeometryError("pressed forces must be non-negative")
        if not np.isfinite(fixed).any():
            fixed = None
    cone = _feasible_impl(contacts, c, il, np.array([margin], dtype=float)) if C else np.zeros(B, bool)
    lam = np.full((B, 2 * C), np.nan)
    todo = np.flatnonzero(cone)
    if todo.size:
        sub = contacts.select(todo)
        gens, _ = wrench_generators(sub, c if c.shape[0] == 1 else c[todo], 1.0 / (il if il.shape[0] == 1 else il[todo]))
        G = np.swapaxes(gens, 1, 2)  # (b, 3, K)
        n_k = np.repeat(sub.normals, 2, axis=1)  # (b, K, 2)
        a = gens[..., 0] * n_k[..., 0] + gens[..., 1] * n_k[..., 1]  # normal part of each unit generator
        owner = np.repeat(fo[todo], 2, axis=1)  # (b, K)
        A = np.where(owner[:, None, :] == np.arange(fingers)[None, :, None], a[:, None, :], 0.0)
        ub = np.where(np.abs(gens).sum(axis=2) > 0, np.inf, 0.0)
        for s in range(0, todo.size, _LP_CHUNK):
            sl = slice(s, min(s + _LP_CHUNK, todo.size))
            fx = None if fixed is None else fixed[todo[sl]]
            x = _lp_block(G[sl], A[sl], ub[sl], fx)
            if x is None:  # an infeasible (or troublesome) instance must not spoil the chunk
                x = np.full((sl.stop - sl.start, G.shape[2]), np.nan)
                can = _lp_phase1(G[sl], A[sl], ub[sl], fx)
                go = np.flatnonzero(can) if can is not None else np.arange(sl.stop - sl.start)
                sub = None if not go.size else _lp_block(G[sl][go], A[sl][go], ub[sl][go],
                                                           None if fx is None else fx[go])
                if sub is not None:
                    x[go] = sub
                elif go.size:
                    logger.debug("bounded_support: chunk LP not optimal, solving its %d instances one by one", go.size)
                    for j in go:
                        one = _lp_block(G[sl][j:j + 1], A[sl][j:j + 1], ub[sl][j:j + 1],
                                        None if fx is None else fx[j:j + 1])
                        if one is not None:
                            x[j] = one[0]
            x = np.maximum(x, 0.0)
            residual = np.abs(np.einsum("bik,bk->bi", G[sl], x) - _EY).max(axis=1)
            if fx is not None:
                held = np.einsum("bfk,bk->bf", A[sl], x)
                residual = np.maximum(residual, np.where(np.isfinite(fx), np.abs(held - fx), 0.0).max(axis=1))
            x[~(residual <= FEASIBILITY_MARGIN)] = np.nan
            lam[todo[sl]] = x
    equilibrium = np.isfinite(lam).all(axis=1) & cone
    gens_all, _ = wrench_generators(contacts, c, 1.0 / il) if C else (np.zeros((B, 0, 3)), None)
    f_world = weight * (np.nan_to_num(lam)[..., None] * gens_all[..., :2]).reshape(B, C, 2, 2).sum(axis=2)  # (B, C, 2)
    n, t = contacts.normals, np.stack([-contacts.normals[..., 1], contacts.normals[..., 0]], axis=-1)
    fn = (f_world * n).sum(axis=-1)
    ft = (f_world * t).sum(axis=-1)
    forces = np.stack([fn, ft], axis=-1)
    mine = fo[..., None] == np.arange(fingers)  # (B, C, F)
    finger_forces = np.stack([np.einsum("bc,bcf->bf", fn, mine), np.einsum("bc,bcf->bf", -ft, mine)], axis=-1)
    largest = finger_forces[..., 0].max(axis=1, initial=0.0)
    forces[~equilibrium] = np.nan
    finger_forces[~equilibrium] = np.nan
    largest[~equilibrium] = np.nan
    feasible = equilibrium & (largest <= limit + FEASIBILITY_MARGIN * weight)
    return BoundedSupport(_frozen(feasible, bool), _frozen(equilibrium, bool), _frozen(forces, float),
                          _frozen(finger_forces, float), _frozen(largest, float))

__all__: list[str] = [
    "MARGIN_CAP",
    "BoundedSupport",
    "MU_ZERO",
    "ContactMode",
    "ContactModes",
    "Contacts",
    "FeasibilityStatus",
    "GraspQuality",
    "ModeTolerances",
    "ReferenceResult",
    "bounded_support",
    "classify_contacts",
    "pressed_feasible",
    "cone_contains",
    "feasible_batch",
    "feasible_reference",
    "force_closure_batch",
    "grasp_quality",
    "pose_displacements",
    "reaction_angle_batch",
    "twist_displacements",
    "wrench_generators",
]
