"""The AdjustGrasp primitives (paper, Table II): grasp changes at a fixed object pose.

Six primitives, each bound on :data:`~ldhp_tamp.primitives.registry.REGISTRY` under its
PDDL action name with :attr:`Family.ADJUST_GRASP`:

- ``approach-contact`` {0,0} -> g: from the layer's *home* pose (free space above the
  object) to above g's retreat pose, down to it, straight along the gripper's -y axis onto
  g at a wider approach width, then closed onto g.
- ``open`` g -> {0,0}: the reverse of ``approach-contact``.
- ``close``: one finger touching -> both; the touching finger stays put, the other closes
  (not for a fixed-width gripper).
- ``pivot``: turn the gripper about a touching finger (a circle about its centre, a pad
  about its contact point) to another grasp that keeps that contact; or roll a round
  finger along the edge it touches (the contact moves by radius x turn).
- ``slide``: translate the gripper along the object edge a finger touches, to another
  grasp on the same edge (same orientation and width).
- ``flip``: open, turn the gripper by 180 degrees in the plane about the gripper-frame
  point (0, y_m) so that the fingers swap onto the same contacts (``GraspSet.flipped``),
  close.

Every edge is a :class:`GripperMotion`: a few *legs*, each a screw motion of the gripper
in the object frame (rotation about a point, translation, width change), with the role of
each finger over the leg (:class:`FingerRole`: free, fixed on its contact, sliding along
an edge). One function samples any motion (:func:`sample_motion`: at most
``options.step`` of finger-centre/finger-vertex motion and of width change between
samples), one checks it (:func:`check_motion`), one turns it into plan waypoints
(:func:`motion_waypoints`): the waypoints are the checked samples. The checks, at every
sample: the fingers and palm overlap neither the environment nor the object (plan rule 3
at ``PENETRATION_TOL``); a free finger does not touch the object (except at the edge's
ends, which follow the grasps); and the object stays still under quasi-static support
(:func:`geometry.mechanics.feasible_batch`): the environment contacts at T (all
STICKING), the fixed fingers (STICKING) and the sliding fingers (SLIDING, friction
dragging the object along the slide); with no finger on it the object must rest on the
environment alone.

A primitive offers ``propose`` (every candidate edge among a set of grasps, vectorised,
with its exact cost and no check), ``check`` (a batch of candidates), ``intra_edges``
(both: the registry protocol), ``waypoints`` and ``parameters`` (of one edge).

Edge costs (paper, "Two-Tier Planning"): ``c = lambda1 * travel + lambda2 * switches``,
travel the mean path length (mm) of the two fingers, switches 1 per primitive instance.
The design, the definitions and measured sizes are in ``docs/design/grasp_graph.md``.
"""

from __future__ import annotations

import enum
import logging
import math
from collections import Counter
from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar, Iterator, Mapping, Protocol, Sequence, runtime_checkable

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from geometry import collision, mechanics
from geometry.contacts import contact_points, rests_alone
from geometry.grasps import NO_CONTACT, FingerPart, GraspSet, class_representatives, row_groups
from geometry.poses import BoolArray, IntArray, Pose, compose_batch, wrap_angle
from geometry.shapes import FloatArray, segment_distances
from geometry.tolerances import CONTACT_TOL, EPS, PENETRATION_TOL, WAYPOINT_STEP
from geometry.world import PolylineGripper, TwoPointGripper, World
from ldhp_tamp.errors import InputError
from ldhp_tamp.kernels import SEARCH, by_source
from ldhp_tamp.primitives.registry import REGISTRY, Family

if TYPE_CHECKING:  # pragma: no cover
    from ldhp_tamp.plan import Waypoint

__all__ = [
    "PRIMITIVES",
    "AdjustContext",
    "AdjustGraspOptions",
    "ApproachContact",
    "CheckFailure",
    "CheckResult",
    "Close",
    "FingerRole",
    "Flip",
    "GripperMotion",
    "IntraEdges",
    "LayerData",
    "LazyAdjustGrasp",
    "MotionSamples",
    "Open",
    "Pivot",
    "Slide",
    "check_motion",
    "motion_waypoints",
    "sample_motion",
]

log = logging.getLogger(__name__)


#: The six AdjustGrasp action names of the paper, in Table II order.
PRIMITIVES: tuple[str, ...] = ("open", "close", "pivot", "slide", "flip", "approach-contact")

#: Rotations smaller than this (radians) are no rotation.
_ANGLE_EPS = 1e-9


# --------------------------------------------------------------------------------------
# Options, enums, values
# --------------------------------------------------------------------------------------


class FingerRole(enum.IntEnum):
    """What a finger does over one leg of a gripper motion."""

    FREE = 0  #: off the object at the leg's interior samples (checked)
    FIXED = 1  #: keeps its contact point on the object: STICKING (a pivot, a kept finger)
    SLIDING = 2  #: its contact slides along an object edge with the gripper: SLIDING


class CheckFailure(enum.IntEnum):
    """Why an edge failed: the first check that failed, in the order they run."""

    NONE = 0  #: feasible
    ENVIRONMENT = 1  #: a finger or the palm overlaps the environment
    UNSUPPORTED = 2  #: no quasi-static equilibrium keeps the object still at some sample
    TOUCHING = 3  #: a free finger touches the object between the edge's ends
    OBJECT = 4  #: a finger or the palm overlaps the object


@dataclass(frozen=True)
class AdjustGraspOptions:
    """Settings of the AdjustGrasp primitives and of their edge costs.

    Attributes
    ----------
    lambda1 : float
        Cost per mm of finger travel (paper's lambda_1).
    lambda2 : float
        Cost per primitive switch (paper's lambda_2); every edge is one switch.
    step : float
        Largest finger-centre / finger-vertex motion and width change (mm) between
        consecutive samples (= waypoints).
    tol : float
        Overlap tolerance (mm) of the fingers and palm against environment and object.
    contact_tol : float
        A free finger closer than this (mm) to the object touches it.
    approach_clearance : float
        ``approach-contact`` / ``open``: the fingers travel at the approach width
        ``min(w + 2 * approach_clearance, w_max)`` (w for a fixed-width gripper).
    retreat_margin : float
        Retreat distance beyond the object along the gripper's +y axis (mm).
    home_margin : float
        Height of the home pose above the object, environment and the gripper's reach (mm).
    match_tol : float
        Grid (mm, and unit vectors) on which grasps are matched as sharing a contact,
        an anchor or an orientation.
    slide_max_travel : float
        Longest ``slide`` proposed (mm); a longer one is a chain of slides. Bounds the
        candidate edges (a slide group of n grasps along an edge has up to n^2 pairs).
    """

    lambda1: float = 0.01
    lambda2: float = 1.0
    step: float = WAYPOINT_STEP
    tol: float = PENETRATION_TOL
    contact_tol: float = CONTACT_TOL
    approach_clearance: float = 10.0
    retreat_margin: float = 10.0
    home_margin: float = 20.0
    match_tol: float = 1e-4
    slide_max_travel: float = 60.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"adjust-grasp options: {f.name} must be a finite number >= 0, got {v!r}")
        if self.step <= 0 or self.match_tol <= 0 or self.slide_max_travel <= 0:
            raise InputError("adjust-grasp options: step, match_tol and slide_max_travel must be > 0")


@dataclass(frozen=True, eq=False)
class LayerData:
    """What the primitives need about one object pose T (cached per pose).

    Attributes
    ----------
    pose : ndarray, shape (3,)
        T (x, y, theta), radians.
    env_points, env_normals : ndarray, shape (C, 2)
        Object-environment contacts at T (world; normals into the object).
    env_mu : ndarray, shape (C,)
    rests_alone : bool
        The environment contacts alone (STICKING) hold the object: a precondition of
        every edge with a sample where no finger touches.
    home : ndarray, shape (3,)
        World gripper pose from which ``approach-contact`` starts and where ``open``
        ends: above the object (fingers down), clear of it and of the environment below.
    home_width : float
        Gripper width at the home pose (the range's maximum).
    """

    pose: FloatArray
    env_points: FloatArray
    env_normals: FloatArray
    env_mu: FloatArray
    rests_alone: bool
    home: FloatArray
    home_width: float


@dataclass(frozen=True, eq=False)
class GripperMotion:
    """The gripper motions of E edges, each ``L`` legs long (struct of arrays).

    Leg ``l`` of edge ``e`` moves the gripper (object frame) by the screw

        o(s) = c + R(s a)(o_0 - c) + s d,   phi(s) = phi_0 + s a,   w(s) = w_0 + s dw,

    ``s`` in [0, 1]; a leg with ``a = 0``, ``d = 0`` and ``dw = 0`` is inactive. A finger
    that is FIXED touches ``contact`` (object frame), a SLIDING one ``contact + s d``;
    ``turn_normal`` marks normals that turn with the leg (a pad pivoting on a vertex).
    The first sample of an edge declares the contacts of grasp ``src``, the last those
    of ``dst``.

    Attributes
    ----------
    src, dst : ndarray of int, shape (E,)
    start : ndarray, shape (E, L, 3)
        ``(o_0, phi_0)`` of each leg.
    width, dwidth : ndarray, shape (E, L)
    centre : ndarray, shape (E, L, 2)
    angle : ndarray, shape (E, L)
    shift : ndarray, shape (E, L, 2)
    role : ndarray of int8, shape (E, L, 2)
        :class:`FingerRole` of finger 1 and finger 2.
    contact, normal : ndarray, shape (E, L, 2, 2)
        Contact point and normal (into the object) of FIXED / SLIDING fingers, at s = 0.
    mu : ndarray, shape (E, L, 2)
    turn_normal : ndarray of bool, shape (E, L, 2)
    """

    src: IntArray
    dst: IntArray
    start: FloatArray
    width: FloatArray
    dwidth: FloatArray
    centre: FloatArray
    angle: FloatArray
    shift: FloatArray
    role: NDArray[np.int8]
    contact: FloatArray
    normal: FloatArray
    mu: FloatArray
    turn_normal: BoolArray

    @property
    def n_edges(self) -> int:
        return int(self.src.shape[0])

    @property
    def n_legs(self) -> int:
        return int(self.start.shape[1])

    @cached_property
    def active(self) -> BoolArray:
        """(E, L) legs that move the gripper or change its width."""
        return ((np.abs(self.angle) > _ANGLE_EPS) | (np.hypot(self.shift[..., 0], self.shift[..., 1]) > EPS)
                | (np.abs(self.dwidth) > EPS))

    def take(self, idx: ArrayLike) -> "GripperMotion":
        i = np.asarray(idx, dtype=np.int64)
        return GripperMotion(*(getattr(self, f.name)[i] for f in fields(self)))

    @staticmethod
    def concat(parts: Sequence["GripperMotion"]) -> "GripperMotion":
        """Edges of several motions with the same number of legs, in order."""
        return GripperMotion(*(np.concatenate([getattr(p, f.name) for p in parts], axis=0)
                               for f in fields(GripperMotion)))

    def travel(self, context: "AdjustContext") -> FloatArray:
        """(E,) mean path length (mm) of the two fingers' anchors (exact for pure
        translations and rotations; an upper bound for legs that do both)."""
        o0 = self.start[..., :2]
        phi = self.start[..., 2]
        ex = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
        out = np.zeros(self.n_edges)
        for k, sign in ((0, -1.0), (1, 1.0)):
            anchor = o0 + (sign * 0.5 * self.width)[..., None] * ex
            r = np.linalg.norm(anchor - self.centre, axis=-1)
            lin = self.shift + (sign * 0.5 * self.dwidth)[..., None] * ex
            length = np.abs(self.angle) * r + np.linalg.norm(lin, axis=-1)
            out += 0.5 * np.where(self.active, length, 0.0).sum(axis=1)
        return out


@dataclass(frozen=True, eq=False)
class IntraEdges:
    """Intra-pose edges of one primitive at one object pose (struct of arrays).

    A primitive's ``propose`` returns candidates (``checked`` False) with their exact
    costs and no motion (it is built when needed, :meth:`_AdjustGrasp.motion`);
    ``intra_edges`` returns the feasible ones (``checked`` True) with their motions.

    Attributes
    ----------
    primitive : str
        The PDDL action name.
    src, dst : ndarray of int, shape (E,)
        Grasp indices (0 is {0, 0}).
    sense : ndarray of int, shape (E,)
        Rotation sense (+1 counter-clockwise, -1 clockwise) of ``pivot`` / ``flip``; 0
        (int8 in proposals).
    finger : ndarray of int, shape (E,)
        The finger (0 or 1) a ``pivot`` turns about, a ``slide`` slides, a ``close``
        keeps; -1 otherwise (int8 in proposals).
    travel : ndarray, shape (E,)
        Mean path length of the two fingers (mm), :meth:`GripperMotion.travel`.
    switches : ndarray of int, shape (E,)
        Primitive switches (1 per edge; in proposals a read-only broadcast of 1).
    motion : GripperMotion or None
        The edges' gripper motions, when built.
    checked : bool
    feasibility_checks : int
        Quasi-static feasibility instances decided while checking.
    failures : Mapping[str, int]
        Checked edges that failed, by :class:`CheckFailure` name.
    """

    primitive: str
    src: IntArray
    dst: IntArray
    sense: IntArray
    finger: IntArray
    travel: FloatArray
    switches: IntArray
    motion: GripperMotion | None = None
    checked: bool = False
    feasibility_checks: int = 0
    failures: Mapping[str, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.src.shape[0])

    def cost(self, options: AdjustGraspOptions) -> FloatArray:
        """``lambda1 * travel + lambda2 * switches`` per edge (into one new array: a layer
        costs hundreds of thousands of edges; the same sums)."""
        out = np.multiply(self.travel, options.lambda1, dtype=float)
        sw = np.asarray(self.switches)
        if sw.ndim == 1 and sw.size and sw.strides == (0,):  # one switch count for all (a proposal's)
            out += options.lambda2 * float(sw[0])
        else:
            out += options.lambda2 * sw
        return out

    def take(self, idx: ArrayLike) -> "IntraEdges":
        """Edges ``idx`` (the same flags and counts)."""
        i = np.asarray(idx, dtype=np.int64)
        return IntraEdges(self.primitive, self.src[i], self.dst[i], self.sense[i], self.finger[i], self.travel[i],
                          self.switches[i], None if self.motion is None else self.motion.take(i), self.checked,
                          self.feasibility_checks, dict(self.failures))

    def with_motion(self, motion: GripperMotion | None, *, checked: bool | None = None, feasibility_checks: int = 0,
                    failures: Mapping[str, int] | None = None) -> "IntraEdges":
        return IntraEdges(self.primitive, self.src, self.dst, self.sense, self.finger, self.travel, self.switches,
                          motion, self.checked if checked is None else checked, feasibility_checks,
                          dict(failures or {}))

    @staticmethod
    def concat(parts: Sequence["IntraEdges"]) -> "IntraEdges":
        """Edges of one primitive from several proposals, in order."""
        p0 = parts[0]
        cat = lambda name: np.concatenate([getattr(p, name) for p in parts])  # noqa: E731
        motions = [p.motion for p in parts]
        motion = GripperMotion.concat(motions) if all(m is not None for m in motions) else None  # type: ignore[arg-type]
        return IntraEdges(p0.primitive, cat("src"), cat("dst"), cat("sense"), cat("finger"), cat("travel"),
                          cat("switches"), motion, all(p.checked for p in parts))


@dataclass(frozen=True, eq=False)
class CheckResult:
    """Outcome of :func:`check_motion` for E edges.

    Attributes
    ----------
    ok : ndarray of bool, shape (E,)
    failure : ndarray of int8, shape (E,)
        :class:`CheckFailure` codes.
    feasibility_checks : int
        Quasi-static instances decided.
    samples : int
        Samples checked.
    """

    ok: BoolArray
    failure: NDArray[np.int8]
    feasibility_checks: int
    samples: int

    def failure_counts(self) -> dict[str, int]:
        c = Counter(int(f) for f in self.failure if f != CheckFailure.NONE)
        return {CheckFailure(k).name.lower(): v for k, v in sorted(c.items())}


# --------------------------------------------------------------------------------------
# The context: world, grasps, options, and what is derived from them
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Groups:
    """Grasps sharing a key, in CSR form: ``members[start[i]:start[i+1]]`` is group i."""

    of: IntArray  # (G,) group of each grasp, -1 if not eligible
    start: IntArray  # (n + 1,)
    members: IntArray  # (M,)


def _groups(keys: IntArray, rows: IntArray, size: int) -> _Groups:
    of = np.full(size, -1, dtype=np.int64)
    if rows.size == 0:
        return _Groups(of, np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64))
    inv, _ = row_groups(np.asarray(keys, dtype=np.int64))
    order = np.argsort(inv, kind="stable")
    counts = np.bincount(inv)
    of[rows] = inv
    return _Groups(of, np.concatenate([[0], np.cumsum(counts)]).astype(np.int64), rows[order].astype(np.int64))


def _group_pairs(groups: _Groups, sources: IntArray) -> tuple[IntArray, IntArray]:
    """All (source, member) pairs of each source's group (the source itself included)."""
    src = sources[groups.of[sources] >= 0]
    gid = groups.of[src]
    lo = groups.start[gid]
    cnt = groups.start[gid + 1] - lo
    rep = np.repeat(src, cnt)
    offs = np.repeat(lo - np.concatenate([[0], np.cumsum(cnt)[:-1]]), cnt) + np.arange(int(cnt.sum()))
    return rep, groups.members[offs]


#: The compiled selection of a layer's edges from a table of pairs (``ldhp_tamp/_search.c``),
#: or ``None``: numpy masks the table (:meth:`_PairTable.select`).
_search = SEARCH


@dataclass(frozen=True, eq=False)
class _PairTable:
    """Every candidate edge of a primitive in a grasp set, whatever the pose, by source.

    A primitive whose candidates do not depend on the object pose (``pivot``, ``slide``)
    builds it once per grasp set from its tables of pairs; a layer's candidates are then
    the rows of its sources whose destination it allows (:meth:`select`), already in the
    order the grasp graph reads (by source, stably: a source's edges in the order the
    parts were given). Source g's rows are ``starts[g]`` .. ``starts[g + 1] - 1``; 14
    bytes a row (the sources are the starts')."""

    dst: NDArray[np.int32]
    sense: NDArray[np.int8]
    finger: NDArray[np.int8]
    travel: FloatArray
    starts: IntArray  # (G + 1,) int64

    @staticmethod
    def of(parts: Sequence[tuple[IntArray, IntArray, ArrayLike, ArrayLike, FloatArray]], size: int) -> "_PairTable":
        """The table of ``parts`` ``(src, dst, sense, finger, travel)`` (a scalar sense or
        finger stands for every pair of its part) over ``size`` grasps."""
        def column(i: int) -> NDArray[np.int8]:
            return np.concatenate([np.broadcast_to(np.asarray(p[i], dtype=np.int8), np.shape(p[0])) for p in parts]
                                  + [np.zeros(0, np.int8)])

        # the grasp graph's order of a layer's edges (ldhp_tamp.kernels.by_source)
        order, starts, dst, travel = by_source([p[0] for p in parts], [p[1] for p in parts], [p[4] for p in parts],
                                               size, _search)
        return _PairTable(dst, column(2)[order], column(3)[order], travel, starts.astype(np.int64))

    def select(self, rows: IntArray, members: BoolArray
               ) -> tuple[IntArray, IntArray, NDArray[np.int8], NDArray[np.int8], FloatArray]:
        """(src, dst, sense, finger, travel) of the pairs from ``rows`` (ascending, no
        repeats) to a grasp of ``members``, in the table's order (the compiled pass walks
        the rows' runs; numpy masks the whole table, to the same arrays)."""
        rows = np.ascontiguousarray(rows, dtype=np.int64)
        allowed = np.ascontiguousarray(members, dtype=bool)
        if _search is not None:
            view = allowed.view(np.uint8)
            n = _search.select_pairs(self.starts, self.dst, rows, view)
            out = (np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int8), np.empty(n, np.int8),
                   np.empty(n))
            _search.select_pairs(self.starts, self.dst, rows, view, self.sense, self.finger, self.travel, *out)
            return out
        size = self.starts.size - 1
        src = np.repeat(np.arange(size, dtype=np.int64), np.diff(self.starts))
        is_src = np.zeros(size, dtype=bool)
        is_src[rows] = True
        keep = is_src[src] & allowed[self.dst]
        return src[keep], self.dst[keep].astype(np.int64), self.sense[keep], self.finger[keep], self.travel[keep]


@dataclass(frozen=True, eq=False)
class AdjustContext:
    """Everything the AdjustGrasp primitives need for one task, plus their caches.

    Build one per task (world and grasp set); the values derived from the grasp set
    (anchors, groups of grasps that share a contact) are computed once, the per-pose
    values (:class:`LayerData`) once per pose. The caches are the only mutable state.

    Attributes
    ----------
    world : World
    grasps : GraspSet
    options : AdjustGraspOptions
    """

    world: World
    grasps: GraspSet
    options: AdjustGraspOptions = field(default_factory=AdjustGraspOptions)
    _cache: dict[Any, Any] = field(default_factory=dict, repr=False)

    # ---- gripper geometry --------------------------------------------------------------

    @property
    def is_polyline(self) -> bool:
        return isinstance(self.world.gripper, PolylineGripper)

    @cached_property
    def pad(self) -> tuple[float, float]:
        """Polyline: the pad's (tip end, upper end) heights; two-point: (0, 0)."""
        grip = self.world.gripper
        if not isinstance(grip, PolylineGripper):
            return (0.0, 0.0)
        e = grip.finger.edges
        on = (np.abs(e[:, 0, 0]) <= EPS) & (np.abs(e[:, 1, 0]) <= EPS)
        ys = e[on][:, :, 1] if on.any() else np.zeros((1, 2))
        return (float(ys.min()), float(ys.max()))

    @property
    def flip_height(self) -> float:
        """y_m of the ``flip`` rotation centre (0, y_m) in the gripper frame."""
        return 0.5 * (self.pad[0] + self.pad[1])

    def finger_points(self, widths: ArrayLike) -> FloatArray:
        """(B, P, 2) gripper-frame points plan rule 2 tracks: the finger centres
        (two-point) or every vertex of both finger polygons (polyline)."""
        w = np.atleast_1d(np.asarray(widths, dtype=float))
        grip = self.world.gripper
        if isinstance(grip, TwoPointGripper):
            z = np.zeros_like(w)
            return np.stack([np.stack([-w / 2, z], -1), np.stack([w / 2, z], -1)], axis=1)
        f1 = grip.mirrored_finger.vertices[None] + np.stack([-w / 2, np.zeros_like(w)], -1)[:, None]
        f2 = grip.finger.vertices[None] + np.stack([w / 2, np.zeros_like(w)], -1)[:, None]
        return np.concatenate([f1, f2], axis=1)

    def reach(self, widths: ArrayLike) -> FloatArray:
        """Largest distance (mm) of the rule-2 points from the gripper origin."""
        return np.linalg.norm(self.finger_points(widths), axis=-1).max(axis=-1)

    def body_reach(self, widths: ArrayLike) -> FloatArray:
        """Radius about the gripper origin of a disk holding fingers and palm."""
        w = np.atleast_1d(np.asarray(widths, dtype=float))
        grip = self.world.gripper
        if isinstance(grip, TwoPointGripper):
            return 0.5 * w + float(grip.finger_radius)
        out = self.reach(w)
        if grip.palm is not None:
            out = np.maximum(out, float(np.linalg.norm(grip.palm.vertices, axis=1).max()))
        return out

    @cached_property
    def finger_reach(self) -> float:
        """Radius about a finger's anchor of a disk holding that finger."""
        grip = self.world.gripper
        if isinstance(grip, TwoPointGripper):
            return float(grip.finger_radius)
        return float(np.linalg.norm(grip.finger.vertices, axis=1).max())

    @cached_property
    def finger_low(self) -> float:
        """Lowest gripper-frame y of the fingers (the fingertips)."""
        grip = self.world.gripper
        if isinstance(grip, TwoPointGripper):
            return -float(grip.finger_radius)
        return float(grip.finger.vertices[:, 1].min())

    # ---- grasp-set derived arrays ------------------------------------------------------

    @cached_property
    def anchors(self) -> FloatArray:
        """(G, 2, 2) object-frame anchor of each finger: ``o -+ (w / 2) e_x``, the finger
        centre (two-point) or the pad's tip end (polyline); NaN for row 0."""
        g = self.grasps.gripper
        ex = np.stack([np.cos(g[:, 2]), np.sin(g[:, 2])], axis=1)
        half = 0.5 * self.grasps.width[:, None]
        return np.stack([g[:, :2] - half * ex, g[:, :2] + half * ex], axis=1)

    @cached_property
    def mu(self) -> FloatArray:
        """(G, 2) finger-object friction of each contact (0 where none)."""
        return np.nan_to_num(self.grasps.contact_mu(self.world))

    @cached_property
    def edge_mu(self) -> FloatArray:
        """(N + N,) finger-object friction of each object edge ``l_(i+1)``, then of each
        vertex ``v_(j+1)`` (indexed by :attr:`GraspSet.feature`)."""
        n = self.grasps.n_object
        fr = self.world.friction
        return np.array([fr.gripper_mu("l", i, n) for i in range(n)] + [fr.gripper_mu("v", j, n) for j in range(n)])

    def _q(self, x: ArrayLike) -> IntArray:
        return np.rint(np.asarray(x, dtype=float) / self.options.match_tol).astype(np.int64)

    def _phi_key(self, rows: IntArray) -> IntArray:
        phi = self.grasps.gripper[rows, 2]
        return self._q(np.stack([np.cos(phi), np.sin(phi)], axis=1))

    @cached_property
    def pivot_groups(self) -> tuple[_Groups, _Groups]:
        """Per finger k: grasps where finger k touches, keyed by the pivot point (the
        finger's centre for a circle, its contact point for a pad). Which pairs of a
        group are pivots (the same width, or a pinch and a one-finger grasp) is
        :meth:`Pivot._pairs`' business."""
        gs = self.grasps
        out = []
        for k in range(2):
            rows = np.flatnonzero(gs.touching[:, k])
            rows = rows[rows != NO_CONTACT]
            point = self.anchors[rows, k] if not self.is_polyline else gs.contact[rows, k]
            out.append(_groups(self._q(point), rows, len(gs)))
        return out[0], out[1]

    @cached_property
    def close_groups(self) -> tuple[_Groups, _Groups]:
        """Per finger k: one-finger grasps on finger k and two-finger grasps, keyed by
        finger k's anchor, contact point and the gripper orientation."""
        gs = self.grasps
        out = []
        for k in range(2):
            one = gs.touching[:, k] & (gs.n_touching == 1)
            rows = np.flatnonzero(one | (gs.n_touching == 2))
            rows = rows[rows != NO_CONTACT]
            keys = np.concatenate([self._q(self.anchors[rows, k]), self._q(gs.contact[rows, k]),
                                   self._phi_key(rows)], axis=1)
            out.append(_groups(keys, rows, len(gs)))
        return out[0], out[1]

    @cached_property
    def slide_groups(self) -> tuple[_Groups, _Groups]:
        """Per finger k: grasps where finger k touches an object *edge*, keyed by that
        edge, the finger parts, the orientation, the width and where each contact sits
        in the gripper frame; members differ by a translation along the edge."""
        gs = self.grasps
        n = gs.n_object
        out = []
        for k in range(2):
            j = 1 - k
            rows = np.flatnonzero(gs.touching[:, k] & (gs.feature[:, k] >= 0) & (gs.feature[:, k] < n))
            rows = rows[rows != NO_CONTACT]
            g = gs.gripper[rows]
            c, s = np.cos(g[:, 2]), np.sin(g[:, 2])

            def local(p: FloatArray) -> FloatArray:
                d = p - g[:, :2]
                return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)

            other = gs.touching[rows, j]
            lj = np.where(other[:, None], local(np.nan_to_num(gs.contact[rows, j])), 0.0)
            keys = np.concatenate([
                gs.feature[rows, k][:, None], gs.part[rows].astype(np.int64), self._phi_key(rows),
                self._q(gs.width[rows])[:, None], self._q(local(gs.contact[rows, k])),
                gs.feature[rows, j][:, None], self._q(lj)], axis=1)
            out.append(_groups(keys, rows, len(gs)))
        return out[0], out[1]

    # ---- per-pose data -----------------------------------------------------------------

    def layer(self, pose: Pose | ArrayLike) -> LayerData:
        """The :class:`LayerData` of an object pose (cached by the pose's bytes)."""
        p = pose.as_array() if isinstance(pose, Pose) else np.asarray(pose, dtype=float).reshape(3)
        key = ("layer", p.tobytes())
        hit = self._cache.get(key)
        if hit is None:
            hit = self._make_layer(p)
            self._cache[key] = hit
        return hit

    def _make_layer(self, p: FloatArray) -> LayerData:
        world = self.world
        cp = contact_points(world, Pose.from_array(p), self.options.contact_tol)
        rests = bool(rests_alone(world, p[None], tol=self.options.contact_tol)[0])
        verts = world.object_vertices(Pose.from_array(p))
        w_home = float(world.gripper.width_range[1])
        reach = float(self.body_reach(w_home)[0])
        lo, hi = verts[:, 0].min(), verts[:, 0].max()
        top = verts[:, 1].max()
        ev = world.environment.vertices
        near = (ev[:, 0] >= lo - 2 * reach) & (ev[:, 0] <= hi + 2 * reach) if ev.size else np.zeros(0, bool)
        if near.any():
            top = max(top, float(ev[near, 1].max()))
        home = np.array([0.5 * (lo + hi), top + reach + self.options.home_margin, 0.0])
        return LayerData(p.copy(), cp.points, cp.normals, cp.mu, rests, home, w_home)

    def holds(self, pose: Pose | ArrayLike, among: BoolArray | None = None) -> BoolArray:
        """(G,) whether each grasp, standing still at object pose ``pose``, keeps the
        object still: the environment contacts and the grasp's finger contacts (all
        STICKING) balance the weight (row 0 and grasps touching nothing: the object
        rests on the environment alone). Every intra-pose edge starts and ends with this
        test, so a grasp failing it has no intra-pose edge at that pose.

        ``among``: a (G,) mask; only those grasps are decided (the others read False), so
        that a layer pays only for its G_T. Decisions are cached per pose."""
        layer = self.layer(pose)
        gs = self.grasps
        known, value = self._holds_entry(layer.pose)
        want = np.ones(len(gs), dtype=bool) if among is None else np.asarray(among, dtype=bool)
        todo = want & ~known
        if todo.any():
            value[todo & (gs.n_touching == 0)] = layer.rests_alone
            rows = np.flatnonzero(todo & (gs.n_touching >= 1))
            if rows.size:
                # grasps with the same finger contacts (bit for bit: points, normals,
                # friction, which touch) make the same instance: one test per class
                every, (rows, of) = rows, class_representatives(self.world, gs, rows)
                b = rows.size
                ce = layer.env_points.shape[0]
                t = layer.pose
                pose_t = Pose.from_array(t)
                fp = pose_t.apply(np.nan_to_num(gs.contact[rows]))
                fn = pose_t.apply_vector(np.nan_to_num(gs.normal[rows]))
                touch = gs.touching[rows]
                contacts = mechanics.Contacts.make(
                    np.concatenate([np.broadcast_to(layer.env_points, (b, ce, 2)), fp], axis=1),
                    np.concatenate([np.broadcast_to(layer.env_normals, (b, ce, 2)), np.where(touch[..., None], fn, 0.0)],
                                   axis=1),
                    np.concatenate([np.broadcast_to(layer.env_mu, (b, ce)), self.mu[rows]], axis=1),
                    np.concatenate([np.full((b, ce), mechanics.ContactMode.STICKING, np.int8),
                                    np.where(touch, mechanics.ContactMode.STICKING, mechanics.ContactMode.ABSENT)
                                    .astype(np.int8)], axis=1))
                value[every] = mechanics.feasible_batch(contacts, pose_t.apply(self.world.object.com),
                                                        self.world.object.length_scale)[of]
            known |= todo
        out = value & want
        out.setflags(write=False)
        return out

    def _holds_entry(self, pose: FloatArray) -> tuple[BoolArray, BoolArray]:
        """The (G,) masks :meth:`holds` keeps at ``pose`` (its (3,) array): the grasps
        decided and their answers."""
        key = ("holds", pose.tobytes())
        hit = self._cache.get(key)
        if hit is None:
            hit = self._cache[key] = (np.zeros(len(self.grasps), dtype=bool), np.zeros(len(self.grasps), dtype=bool))
        return hit

    def holds_known(self, pose: Pose | ArrayLike, among: BoolArray) -> bool:
        """Whether :meth:`holds` has decided every grasp of ``among`` at ``pose`` (it
        would compute nothing)."""
        p = pose.as_array() if isinstance(pose, Pose) else np.asarray(pose, dtype=float).reshape(3)
        hit = self._cache.get(("holds", p.tobytes()))
        return hit is not None and not (np.asarray(among, dtype=bool) & ~hit[0]).any()

    def take_holds(self, layer: LayerData, decided: BoolArray, held: BoolArray) -> None:
        """Take what another process's copy of this context found at ``layer.pose``: its
        :class:`LayerData`, and :meth:`holds` of the grasps ``decided`` (``held``), for
        the grasps not decided here yet (both decide an instance by the same operations,
        so the values agree)."""
        self._cache.setdefault(("layer", layer.pose.tobytes()), layer)
        known, value = self._holds_entry(layer.pose)
        new = np.asarray(decided, dtype=bool) & ~known
        value[new] = np.asarray(held, dtype=bool)[new]
        known |= new

    def cache(self, name: str, pose: FloatArray) -> dict[Any, Any]:
        """A per-pose memo shared by primitives (e.g. approach/open route validity)."""
        return self._cache.setdefault((name, np.asarray(pose, dtype=float).tobytes()), {})


# --------------------------------------------------------------------------------------
# Building motions
# --------------------------------------------------------------------------------------


@dataclass
class _Leg:
    """One leg for E edges (a builder; assembled into a :class:`GripperMotion`)."""

    start: FloatArray
    width: FloatArray
    dwidth: FloatArray
    centre: FloatArray
    angle: FloatArray
    shift: FloatArray
    role: NDArray[np.int8] | None = None
    contact: FloatArray | None = None
    normal: FloatArray | None = None
    mu: FloatArray | None = None
    turn_normal: BoolArray | None = None


def _linear(p0: FloatArray, p1: FloatArray, w0: FloatArray, w1: FloatArray) -> _Leg:
    """Straight interpolation of origin, orientation (the short way) and width."""
    e = p0.shape[0]
    return _Leg(p0.copy(), np.broadcast_to(w0, (e,)).astype(float), np.broadcast_to(w1 - w0, (e,)).astype(float),
                p0[:, :2].copy(), wrap_angle(p1[:, 2] - p0[:, 2]).reshape(e), p1[:, :2] - p0[:, :2])


def _rotation(p0: FloatArray, centre: FloatArray, angle: FloatArray, w: FloatArray) -> _Leg:
    e = p0.shape[0]
    return _Leg(p0.copy(), np.broadcast_to(w, (e,)).astype(float), np.zeros(e), centre.copy(),
                np.asarray(angle, dtype=float).reshape(e), np.zeros((e, 2)))


def _assemble(src: IntArray, dst: IntArray, legs: list[_Leg]) -> GripperMotion:
    e = src.shape[0]
    for leg in legs:
        leg.role = np.zeros((e, 2), np.int8) if leg.role is None else leg.role
        leg.contact = np.zeros((e, 2, 2)) if leg.contact is None else np.nan_to_num(leg.contact)
        leg.normal = np.zeros((e, 2, 2)) if leg.normal is None else np.nan_to_num(leg.normal)
        leg.mu = np.zeros((e, 2)) if leg.mu is None else np.nan_to_num(leg.mu)
        leg.turn_normal = np.zeros((e, 2), bool) if leg.turn_normal is None else leg.turn_normal
    st = lambda name: np.stack([getattr(leg, name) for leg in legs], axis=1)  # noqa: E731
    return GripperMotion(src.astype(np.int64), dst.astype(np.int64), st("start"), st("width"), st("dwidth"),
                         st("centre"), st("angle"), st("shift"), st("role"), st("contact"), st("normal"), st("mu"),
                         st("turn_normal"))


def _keep_finger(ctx: AdjustContext, leg: _Leg, rows: IntArray, finger: IntArray, role: FingerRole,
                 turn: BoolArray | None = None, where: BoolArray | None = None) -> _Leg:
    """Give finger ``finger[i]`` of edge i (where ``where[i]``) the role ``role`` with
    grasp ``rows[i]``'s contact, normal and friction."""
    e = rows.shape[0]
    leg.role = np.zeros((e, 2), np.int8) if leg.role is None else leg.role
    leg.contact = np.zeros((e, 2, 2)) if leg.contact is None else leg.contact
    leg.normal = np.zeros((e, 2, 2)) if leg.normal is None else leg.normal
    leg.mu = np.zeros((e, 2)) if leg.mu is None else leg.mu
    leg.turn_normal = np.zeros((e, 2), bool) if leg.turn_normal is None else leg.turn_normal
    idx = np.arange(e) if where is None else np.flatnonzero(where)
    f, r = finger[idx], rows[idx]
    leg.role[idx, f] = role
    leg.contact[idx, f] = ctx.grasps.contact[r, f]
    leg.normal[idx, f] = ctx.grasps.normal[r, f]
    leg.mu[idx, f] = ctx.mu[r, f]
    if turn is not None:
        leg.turn_normal[idx, f] = turn[idx]
    return leg


def _relative(frame: FloatArray, poses: FloatArray) -> FloatArray:
    """``frame^-1 * poses`` for a single frame (3,) and poses (B, 3)."""
    c, s = math.cos(frame[2]), math.sin(frame[2])
    dx, dy = poses[:, 0] - frame[0], poses[:, 1] - frame[1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(poses[:, 2] - frame[2])], axis=1)


def _route_legs(ctx: AdjustContext, layer: LayerData, rows: IntArray) -> tuple[list[_Leg], FloatArray, FloatArray]:
    """The ``approach-contact`` legs onto grasps ``rows`` (object frame), with the
    approach widths and retreat distances.

    home H -> V = (R_x, H_y, R_phi) above the retreat pose (move and turn at the safe
    height) -> R (vertical) -> P (along -e_y of g) -> g. The pre-contact pose P keeps the
    fingers ``approach_clearance`` off the object: a two-finger grasp is approached at
    the approach width ``min(w + 2 c, w_max)`` and closed at the end (straight at ``w``
    for a fixed-width gripper); a one-finger grasp is approached at ``w``, backed off by
    ``c`` against its contact normal, and pressed on along the normal at the end.
    R = P + D e_y, D the object's extent along e_y beyond P's fingertips plus
    ``retreat_margin``.
    """
    gs, opts = ctx.grasps, ctx.options
    grip = ctx.world.gripper
    c = opts.approach_clearance
    g = gs.gripper[rows]
    w = gs.width[rows]
    touch = gs.touching[rows]
    one = touch.sum(axis=1) == 1
    if grip.fixed_width:
        wa = w.copy()
    else:
        wa = np.where(one, w, np.maximum(np.minimum(w + 2.0 * c, float(grip.width_range[1])), w))
    k = np.argmax(touch, axis=1)
    normal = np.nan_to_num(gs.normal[rows, k])
    pre = g.copy()
    pre[:, :2] -= np.where(one[:, None], c * normal, 0.0)
    ey = np.stack([-np.sin(g[:, 2]), np.cos(g[:, 2])], axis=1)
    verts = ctx.world.object.polygon.vertices
    extent = ((verts[None, :, :] - pre[:, None, :2]) * ey[:, None, :]).sum(-1).max(axis=1)
    d = np.maximum(extent - ctx.finger_low + opts.retreat_margin, opts.retreat_margin)
    retreat = np.concatenate([pre[:, :2] + d[:, None] * ey, g[:, 2:3]], axis=1)
    rw = compose_batch(layer.pose[None], retreat)
    vw = np.stack([rw[:, 0], np.full(rows.size, layer.home[1]), rw[:, 2]], axis=1)
    home = _relative(layer.pose, np.broadcast_to(layer.home, (rows.size, 3)))
    above = _relative(layer.pose, vw)
    legs = [_linear(home, above, np.full(rows.size, layer.home_width), wa), _linear(above, retreat, wa, wa),
            _linear(retreat, pre, wa, wa), _linear(pre, g, wa, w)]
    return legs, wa, d


def _reverse(legs: list[_Leg]) -> list[_Leg]:
    """The reverse of a chain of linear legs (all FREE)."""
    out = []
    for leg in reversed(legs):
        p0 = leg.start
        p1 = np.concatenate([p0[:, :2] + leg.shift, wrap_angle(p0[:, 2] + leg.angle)[:, None]], axis=1)
        out.append(_linear(p1, p0, leg.width + leg.dwidth, leg.width))
    return out


# --------------------------------------------------------------------------------------
# Sampling and checking a motion
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class MotionSamples:
    """The samples (= waypoints) of the edges of a :class:`GripperMotion`, edge-major.

    Attributes
    ----------
    edge : ndarray of int, shape (S,)
        Edge of each sample.
    pose : ndarray, shape (S, 3)
        Gripper pose in the object frame.
    width : ndarray, shape (S,)
    first, last : ndarray of bool, shape (S,)
        The edge's first / last sample.
    declared : ndarray of bool, shape (S, 2)
        Finger k touches the object at this sample.
    point, normal : ndarray, shape (S, 2, 2)
        Object-frame contact point and normal (into the object) where declared.
    mu : ndarray, shape (S, 2)
    mode : ndarray of int8, shape (S, 2)
        :class:`~geometry.mechanics.ContactMode` of declared finger contacts.
    slide : ndarray, shape (S, 2, 2)
        Object-frame direction of the object's motion relative to a SLIDING finger.
    free : ndarray of bool, shape (S, 2)
        A FREE finger at an interior sample: it must stay off the object.
    """

    edge: IntArray
    pose: FloatArray
    width: FloatArray
    first: BoolArray
    last: BoolArray
    declared: BoolArray
    point: FloatArray
    normal: FloatArray
    mu: FloatArray
    mode: NDArray[np.int8]
    slide: FloatArray
    free: BoolArray

    def __len__(self) -> int:
        return int(self.edge.shape[0])


def sample_motion(context: AdjustContext, motion: GripperMotion) -> MotionSamples:
    """Sample every edge of ``motion`` so that no rule-2 point of the gripper moves more
    than ``options.step`` and the width changes by at most ``options.step`` between
    consecutive samples.

    A leg with rotation ``a`` about ``c``, shift ``d`` and width change ``dw`` moves a
    rule-2 point by at most ``|a| (|o_0 - c| + reach) + |d| + |dw| / 2`` (reach: the
    points' largest distance from the origin at the leg's larger width); it gets
    ``ceil(max(that, |dw|) / step)`` equal steps of ``s``. The first and last sample of
    an edge are exactly the poses of grasps ``src`` and ``dst`` (when not {0, 0}) and
    declare their contacts.
    """
    ctx = context
    gs = ctx.grasps
    m = motion
    e_n, l_n = m.n_edges, m.n_legs
    if e_n == 0:
        z, zb = np.zeros(0, np.int64), np.zeros(0, bool)
        return MotionSamples(z, np.zeros((0, 3)), np.zeros(0), zb, zb, np.zeros((0, 2), bool), np.zeros((0, 2, 2)),
                             np.zeros((0, 2, 2)), np.zeros((0, 2)), np.zeros((0, 2), np.int8), np.zeros((0, 2, 2)),
                             np.zeros((0, 2), bool))
    act = m.active.copy()
    none = ~act.any(axis=1)
    act[none, 0] = True  # an edge that does not move: one sample
    o0 = m.start[..., :2]
    wmax = np.maximum(m.width, m.width + m.dwidth)
    rho = np.linalg.norm(o0 - m.centre, axis=-1) + ctx.reach(wmax.reshape(-1)).reshape(e_n, l_n)
    bound = np.abs(m.angle) * rho + np.linalg.norm(m.shift, axis=-1) + 0.5 * np.abs(m.dwidth)
    need = np.maximum(bound, np.abs(m.dwidth))
    n = np.where(act, np.maximum(1, np.ceil(need / ctx.options.step - 1e-9)), 0).astype(np.int64)
    n[none, 0] = 0
    first_leg = np.argmax(act, axis=1)
    last_leg = l_n - 1 - np.argmax(act[:, ::-1], axis=1)
    inc0 = (np.arange(l_n)[None, :] == first_leg[:, None])
    cnt = (n + inc0).reshape(-1)
    total = int(cnt.sum())
    flat = np.repeat(np.arange(e_n * l_n), cnt)
    e_idx, l_idx = flat // l_n, flat % l_n
    offs = np.repeat(np.concatenate([[0], np.cumsum(cnt)[:-1]]), cnt)
    j = np.arange(total) - offs + np.where(inc0.reshape(-1)[flat], 0, 1)
    nn = n[e_idx, l_idx]
    s = np.where(nn > 0, j / np.maximum(nn, 1), 0.0)

    a = m.angle[e_idx, l_idx] * s
    ca, sa = np.cos(a), np.sin(a)
    c = m.centre[e_idx, l_idx]
    r = o0[e_idx, l_idx] - c
    sh = m.shift[e_idx, l_idx]
    pose = np.empty((total, 3))
    pose[:, 0] = c[:, 0] + ca * r[:, 0] - sa * r[:, 1] + s * sh[:, 0]
    pose[:, 1] = c[:, 1] + sa * r[:, 0] + ca * r[:, 1] + s * sh[:, 1]
    pose[:, 2] = wrap_angle(m.start[e_idx, l_idx, 2] + a)
    width = m.width[e_idx, l_idx] + s * m.dwidth[e_idx, l_idx]
    first = inc0[e_idx, l_idx] & (j == 0)
    last = (l_idx == last_leg[e_idx]) & (j == nn)

    # Roles at interior samples.
    role = m.role[e_idx, l_idx]  # (S, 2)
    declared = role != FingerRole.FREE
    point = m.contact[e_idx, l_idx] + np.where((role == FingerRole.SLIDING)[..., None], (s[:, None, None] * sh[:, None, :]), 0.0)
    normal = m.normal[e_idx, l_idx].copy()
    turn = m.turn_normal[e_idx, l_idx]
    if turn.any():
        rx = ca[:, None] * normal[..., 0] - sa[:, None] * normal[..., 1]
        ry = sa[:, None] * normal[..., 0] + ca[:, None] * normal[..., 1]
        normal = np.where(turn[..., None], np.stack([rx, ry], -1), normal)
    mu = m.mu[e_idx, l_idx].copy()
    # A SLIDING finger's material point at its contact p moves (per unit of the leg's
    # parameter) by v = shift + angle * J (p - centre - s * shift), J the quarter turn:
    # the object slides relative to the finger along -v (a slide: -shift; a round
    # finger turning about its centre: -angle * J * radius * n, its surface slipping).
    rel = point - (c + s[:, None] * sh)[:, None, :]
    ang = m.angle[e_idx, l_idx][:, None]
    v = sh[:, None, :] + ang[..., None] * np.stack([-rel[..., 1], rel[..., 0]], axis=-1)
    vn = np.linalg.norm(v, axis=-1)
    sliding = (role == FingerRole.SLIDING) & (vn > EPS)
    mode = np.where(sliding, mechanics.ContactMode.SLIDING, mechanics.ContactMode.STICKING)
    slide = np.where(sliding[..., None], -v / np.maximum(vn, EPS)[..., None], 0.0)

    # The ends follow the grasps.
    for mask, rows in ((first, m.src[e_idx]), (last, m.dst[e_idx])):
        idx = np.flatnonzero(mask)
        g = rows[idx]
        real = g != NO_CONTACT
        ri, rg = idx[real], g[real]
        pose[ri] = gs.gripper[rg]
        width[ri] = gs.width[rg]
        declared[idx] = gs.touching[g]
        point[idx] = np.nan_to_num(gs.contact[g])
        normal[idx] = np.nan_to_num(gs.normal[g])
        mu[idx] = ctx.mu[g]
        # An edge's ends are checked with the contact modes of its motion too (plan rule
        # 8): a finger that slides over the edge slides at its first and last sample, so
        # a slide of any length has sliding samples (between them, support holds too: a
        # single contact moving along a straight edge with a fixed force direction keeps
        # the feasible set connected, see docs/design/grasp_graph.md).
        keep = sliding[idx] & gs.touching[g]
        mode[idx] = np.where(keep, mechanics.ContactMode.SLIDING, mechanics.ContactMode.STICKING)
        slide[idx] = np.where(keep[..., None], slide[idx], 0.0)
    free = (role == FingerRole.FREE) & ~(first | last)[:, None]
    point = np.where(declared[..., None], point, 0.0)
    normal = np.where(declared[..., None], normal, 0.0)
    mode = np.where(declared, mode, mechanics.ContactMode.ABSENT).astype(np.int8)
    return MotionSamples(e_idx.astype(np.int64), pose, width, first, last, declared, point, normal,
                         np.where(declared, mu, 0.0), mode, slide, free)


def _env_overlap(ctx: AdjustContext, poses: FloatArray, widths: FloatArray) -> BoolArray:
    """Gripper-environment overlap, skipping poses whose bounding disk is clear."""
    env = ctx.world.environment
    hit = np.zeros(poses.shape[0], dtype=bool)
    if env.m == 0 or poses.shape[0] == 0:
        return hit
    dist = segment_distances(poses[:, :2], env.edges)[0].min(axis=1)
    inside = shapely.contains_xy(env.shapely, poses[:, 0], poses[:, 1])
    maybe = np.flatnonzero(inside | (dist <= ctx.body_reach(widths) + ctx.options.tol))
    if maybe.size:
        hit[maybe] = collision.gripper_env_overlap(ctx.world, poses[maybe], widths[maybe], ctx.options.tol)
    return hit


def _object_overlap(ctx: AdjustContext, poses: FloatArray, widths: FloatArray) -> BoolArray:
    """Gripper-object overlap (object frame), skipping poses whose bounding disk is clear."""
    poly = ctx.world.object.polygon
    hit = np.zeros(poses.shape[0], dtype=bool)
    if poses.shape[0] == 0:
        return hit
    dist = segment_distances(poses[:, :2], poly.edges)[0].min(axis=1)
    inside = shapely.contains_xy(poly.shapely, poses[:, 0], poses[:, 1])
    maybe = np.flatnonzero(inside | (dist <= ctx.body_reach(widths) + ctx.options.tol))
    if maybe.size:
        hit[maybe] = collision.gripper_object_overlap(ctx.world, np.zeros(3), poses[maybe], widths[maybe],
                                                      ctx.options.tol)
    return hit


def _free_touching(ctx: AdjustContext, poses: FloatArray, widths: FloatArray, finger: IntArray) -> BoolArray:
    """Whether finger ``finger[i]`` (object frame pose, width) is within ``contact_tol``
    of the object (or in it)."""
    poly = ctx.world.object.polygon
    b = poses.shape[0]
    out = np.zeros(b, dtype=bool)
    if b == 0:
        return out
    sign = np.where(finger == 0, -1.0, 1.0)
    ex = np.stack([np.cos(poses[:, 2]), np.sin(poses[:, 2])], axis=1)
    anchor = poses[:, :2] + (sign * 0.5 * widths)[:, None] * ex
    dist = segment_distances(anchor, poly.edges)[0].min(axis=1)
    inside = shapely.contains_xy(poly.shapely, anchor[:, 0], anchor[:, 1])
    tol = ctx.options.contact_tol
    grip = ctx.world.gripper
    if isinstance(grip, TwoPointGripper):
        return inside | (dist - float(grip.finger_radius) <= tol)
    maybe = np.flatnonzero(inside | (dist <= ctx.finger_reach + tol))
    if maybe.size:
        fs = collision.finger_shapes(grip, poses[maybe], widths[maybe])
        assert fs.polygons is not None
        polys = fs.polygons[np.arange(maybe.size), finger[maybe]]
        out[maybe] = shapely.distance(poly.shapely, shapely.polygons(polys)) <= tol
    return out


def _supported(ctx: AdjustContext, layer: LayerData, smp: MotionSamples, idx: IntArray) -> tuple[BoolArray, int]:
    """Quasi-static support at samples ``idx``; returns (ok, instances decided)."""
    ok = np.zeros(idx.size, dtype=bool)
    dec = smp.declared[idx].any(axis=1)
    ok[~dec] = layer.rests_alone
    rows = idx[dec]
    if rows.size == 0:
        return ok, 0
    world = ctx.world
    t = layer.pose
    c, s = math.cos(t[2]), math.sin(t[2])

    def rot(v: FloatArray) -> FloatArray:
        return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)

    b = rows.size
    ce = layer.env_points.shape[0]
    pts = np.concatenate([np.broadcast_to(layer.env_points, (b, ce, 2)), rot(smp.point[rows]) + t[:2]], axis=1)
    nrm = np.concatenate([np.broadcast_to(layer.env_normals, (b, ce, 2)), rot(smp.normal[rows])], axis=1)
    mu = np.concatenate([np.broadcast_to(layer.env_mu, (b, ce)), smp.mu[rows]], axis=1)
    modes = np.concatenate([np.full((b, ce), mechanics.ContactMode.STICKING, np.int8), smp.mode[rows]], axis=1)
    slide = np.concatenate([np.zeros((b, ce, 2)), rot(smp.slide[rows])], axis=1)
    contacts = mechanics.Contacts.trusted(pts, nrm, mu, modes, slide)
    com = Pose.from_array(t).apply(world.object.com)
    ok[dec] = mechanics.feasible_batch(contacts, com, world.object.length_scale)
    return ok, b


def check_motion(context: AdjustContext, layer: LayerData, motion: GripperMotion) -> CheckResult:
    """Check the edges of ``motion`` at the object pose of ``layer``, at every sample.

    In order (an edge stops at its first failure, later checks skip it):
    ENVIRONMENT (fingers and palm against the solids, rule 3 at ``options.tol``),
    UNSUPPORTED (quasi-static support; see the module docstring), TOUCHING (a free
    finger within ``contact_tol`` of the object between the edge's ends), OBJECT
    (fingers and palm against the object).

    Returns
    -------
    CheckResult
    """
    ctx = context
    smp = sample_motion(ctx, motion)
    e_n = motion.n_edges
    failure = np.zeros(e_n, dtype=np.int8)
    alive = np.ones(e_n, dtype=bool)
    checks = 0

    def mark(sample_idx: IntArray, code: CheckFailure) -> None:
        bad = np.unique(smp.edge[sample_idx])
        bad = bad[alive[bad]]
        failure[bad] = code
        alive[bad] = False

    def live() -> IntArray:
        return np.flatnonzero(alive[smp.edge])

    idx = live()
    wp = compose_batch(layer.pose[None], smp.pose[idx])
    mark(idx[_env_overlap(ctx, wp, smp.width[idx])], CheckFailure.ENVIRONMENT)
    idx = live()
    ok, checks = _supported(ctx, layer, smp, idx)
    mark(idx[~ok], CheckFailure.UNSUPPORTED)
    idx = live()
    si, fk = np.nonzero(smp.free[idx])
    if si.size:
        rows = idx[si]
        mark(rows[_free_touching(ctx, smp.pose[rows], smp.width[rows], fk)], CheckFailure.TOUCHING)
    idx = live()
    mark(idx[_object_overlap(ctx, smp.pose[idx], smp.width[idx])], CheckFailure.OBJECT)
    return CheckResult(alive.copy(), failure, checks, len(smp))


def motion_waypoints(context: AdjustContext, pose: Pose | ArrayLike, motion: GripperMotion,
                     edge: int = 0) -> tuple["Waypoint", ...]:
    """The plan waypoints of edge ``edge`` of ``motion`` at object pose ``pose``: its
    samples (:func:`sample_motion`), in the world frame, with the finger contacts
    declared where the fingers touch."""
    from ldhp_tamp.plan import Waypoint  # here: ldhp_tamp.plan imports this package

    t = pose.as_array() if isinstance(pose, Pose) else np.asarray(pose, dtype=float).reshape(3)
    smp = sample_motion(context, motion.take([edge]))
    obj = Pose.from_array(t)
    grip = compose_batch(t[None], smp.pose)
    pts = obj.apply(smp.point)
    out = []
    for i in range(len(smp)):
        fc = tuple((float(pts[i, k, 0]), float(pts[i, k, 1])) if smp.declared[i, k] else None for k in range(2))
        out.append(Waypoint(obj, Pose(float(grip[i, 0]), float(grip[i, 1]), float(grip[i, 2])),
                            float(smp.width[i]), fc))  # type: ignore[arg-type]
    return tuple(out)


# --------------------------------------------------------------------------------------
# The primitives
# --------------------------------------------------------------------------------------


@runtime_checkable
class LazyAdjustGrasp(Protocol):
    """The lazy interface the grasp graph prefers when an implementation has it:
    candidate edges with exact costs first (``propose``, vectorised over all sources),
    their feasibility later and in batches (``check``), the plan waypoints of one edge
    (``waypoints``)."""

    def propose(self, context: AdjustContext, pose: Pose, sources: ArrayLike, members: BoolArray) -> IntraEdges:
        ...

    def check(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> CheckResult:
        ...

    def waypoints(self, context: AdjustContext, pose: Pose, edges: IntraEdges, index: int = 0) -> tuple["Waypoint", ...]:
        ...


def _as_rows(x: ArrayLike) -> IntArray:
    """Sorted unique grasp indices (``np.unique``, skipped when they already are)."""
    a = np.asarray(x, dtype=np.int64).reshape(-1)
    if a.size < 2 or bool((a[1:] > a[:-1]).all()):
        return a
    return np.unique(a)


def _ints(x: ArrayLike) -> IntArray:
    return np.asarray(x, dtype=np.int64).reshape(-1)


def _small_ints(x: ArrayLike) -> NDArray[np.int8]:
    """A sense or a finger (|value| <= ROLL_SENSE) per edge, a byte each: a layer proposes
    hundreds of thousands of edges, and the memory they take is paid in page faults."""
    return np.asarray(x, dtype=np.int8).reshape(-1)


class _AdjustGrasp:
    """Shared machinery. A primitive defines ``_candidates`` (which edges, with their
    closed-form travel) and ``motion`` (their legs); the rest is common."""

    name: ClassVar[str] = ""

    def _candidates(self, ctx: AdjustContext, pose: Pose, src: IntArray, members: BoolArray
                    ) -> tuple[IntArray, IntArray, IntArray, IntArray, FloatArray]:
        """(src, dst, sense, finger, travel) of every candidate edge."""
        raise NotImplementedError

    def motion(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> GripperMotion:
        """The gripper motions of ``edges`` (object frame)."""
        raise NotImplementedError

    def prepare(self, context: AdjustContext) -> None:
        """Build ahead what this primitive's proposals share at every pose of a grasp
        set (its tables of pairs), which the first :meth:`propose` would otherwise
        build: the grasp graph has it done while another process computes the setup's
        transitions (:meth:`ldhp_tamp.grasp_graph.GraspPlanner.prepare_tables`).
        Optional for an implementation; this default builds nothing."""

    def propose(self, context: AdjustContext, pose: Pose, sources: ArrayLike, members: BoolArray) -> IntraEdges:
        """Every candidate edge from a grasp of ``sources`` to a grasp allowed by
        ``members`` (a (G,) mask, normally G_T), with its exact travel and switches; no
        check, no motion. Vectorised over all sources at once."""
        src, dst, sense, finger, travel = self._candidates(context, pose, _as_rows(sources),
                                                           np.asarray(members, dtype=bool))
        n = src.shape[0]
        return IntraEdges(self.name, _ints(src), _ints(dst), _small_ints(sense), _small_ints(finger),
                          np.asarray(travel, dtype=float).reshape(n),
                          np.broadcast_to(np.int64(1), (n,)))  # one switch each, read-only, no memory

    def check(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> CheckResult:
        """Check candidate edges at object pose ``pose`` (:func:`check_motion`)."""
        motion = edges.motion if edges.motion is not None else self.motion(context, pose, edges)
        return check_motion(context, context.layer(pose), motion)

    def intra_edges(self, context: AdjustContext, pose: Pose, candidates: ArrayLike) -> IntraEdges:
        """The feasible intra-pose edges of this primitive at ``pose`` among the grasps
        ``candidates`` (G_T, with 0 for {0, 0}), with their motions: every candidate
        edge proposed, all checked in one vectorised call."""
        rows = _as_rows(candidates)
        members = np.zeros(len(context.grasps), dtype=bool)
        members[rows] = True
        props = self.propose(context, pose, rows, members)
        if not len(props):
            return props.with_motion(self.motion(context, pose, props), checked=True)
        props = props.with_motion(self.motion(context, pose, props))
        res = self.check(context, pose, props)
        out = props.take(np.flatnonzero(res.ok))
        log.debug("%s at %s: %d of %d candidate edges feasible %s", self.name, pose, len(out), len(props),
                  res.failure_counts())
        return out.with_motion(out.motion, checked=True, feasibility_checks=res.feasibility_checks,
                               failures=res.failure_counts())

    def waypoints(self, context: AdjustContext, pose: Pose, edges: IntraEdges, index: int = 0) -> tuple["Waypoint", ...]:
        """Plan waypoints of edge ``index`` of ``edges``."""
        one = edges.take([int(index)])
        motion = one.motion if one.motion is not None else self.motion(context, pose, one)
        return motion_waypoints(context, pose, motion, 0)

    def edge(self, context: AdjustContext, pose: Pose, src: int, dst: int, sense: int = 0) -> IntraEdges:
        """The single candidate edge ``src -> dst`` (with ``sense`` if the primitive has
        one; 0 takes the first); raises :class:`InputError` if there is none."""
        members = np.zeros(len(context.grasps), dtype=bool)
        members[int(dst)] = True
        props = self.propose(context, pose, np.array([int(src)]), members)
        ok = np.flatnonzero((props.dst == dst) & ((props.sense == sense) | (sense == 0)))
        if not ok.size:
            raise InputError(f"{self.name}: no edge from grasp {src} to grasp {dst} (sense {sense})")
        return props.take(ok[:1])

    def parameters(self, context: AdjustContext, edges: IntraEdges, index: int = 0) -> dict[str, Any]:
        """Free-form plan parameters of one edge."""
        i = int(index)
        out: dict[str, Any] = {"from_grasp": int(edges.src[i]), "to_grasp": int(edges.dst[i]),
                               "travel": round(float(edges.travel[i]), 3)}
        if edges.finger[i] >= 0:
            out["finger"] = int(edges.finger[i]) + 1
        if edges.sense[i] != 0:
            out["sense"] = int(edges.sense[i])
        if edges.dst[i] != NO_CONTACT:
            out["width"] = round(float(context.grasps.width[edges.dst[i]]), 4)
        return out

    def __repr__(self) -> str:
        return f"<AdjustGrasp {self.name}>"


def _route_motion(ctx: AdjustContext, pose: Pose, rows: IntArray, reverse: bool) -> GripperMotion:
    legs, _, _ = _route_legs(ctx, ctx.layer(pose), rows)
    zero = np.zeros(rows.size, np.int64)
    if reverse:
        return _assemble(rows, zero, _reverse(legs))
    return _assemble(zero, rows, legs)


def _route_check(ctx: AdjustContext, pose: Pose, rows: IntArray) -> CheckResult:
    """Validity of the approach route of each grasp in ``rows`` (memoised per pose:
    ``approach-contact`` and ``open`` share it, their samples being the same)."""
    layer = ctx.layer(pose)
    memo = ctx.cache("route", layer.pose)
    todo = np.array([g for g in dict.fromkeys(rows.tolist()) if g not in memo], dtype=np.int64)
    checks, samples = 0, 0
    if todo.size:
        res = check_motion(ctx, layer, _route_motion(ctx, pose, todo, False))
        checks, samples = res.feasibility_checks, res.samples
        memo.update(zip(todo.tolist(), res.failure.tolist()))
    code = np.array([memo[g] for g in rows.tolist()], dtype=np.int8)
    return CheckResult(code == CheckFailure.NONE, code, checks, samples)


@REGISTRY.register("approach-contact", Family.ADJUST_GRASP)
class ApproachContact(_AdjustGrasp):
    """``approach-contact``: {0, 0} -> g, g with at least one finger touching.

    Motion (four legs, all fingers FREE until the last sample): from the layer's home
    pose H (above the object, fingers down, width at its maximum) move at the safe height
    to above g's retreat pose R while turning to g's orientation and setting the approach
    width; descend vertically to R; move straight along g's -y axis to the pre-contact
    pose P, ``approach_clearance`` off the object; make the contact. A two-finger grasp:
    P = g at ``w_a = min(w + 2 approach_clearance, w_max)``, then close to ``w`` (w_a = w
    for a fixed-width gripper); a one-finger grasp: P = g backed off against the contact
    normal, then pressed on along it. R is P moved along the gripper's +y axis (the palm
    side) until the fingertips clear the object by ``retreat_margin``.
    Preconditions (checked at every sample): the object rests on the environment alone,
    the gripper overlaps nothing, the fingers touch the object only at the end.
    """

    name = "approach-contact"

    def _candidates(self, ctx: AdjustContext, pose: Pose, src: IntArray, members: BoolArray
                    ) -> tuple[IntArray, IntArray, IntArray, IntArray, FloatArray]:
        dst = np.flatnonzero(members & (ctx.grasps.n_touching >= 1)) if NO_CONTACT in src else np.zeros(0, np.int64)
        dst = dst[dst != NO_CONTACT]
        z = np.zeros(dst.size, np.int64)
        travel = _route_motion(ctx, pose, dst, False).travel(ctx) if dst.size else np.zeros(0)
        return z, dst, z, z - 1, travel

    def motion(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> GripperMotion:
        return _route_motion(context, pose, edges.dst, False)

    def check(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> CheckResult:
        return _route_check(context, pose, edges.dst)


@REGISTRY.register("open", Family.ADJUST_GRASP)
class Open(_AdjustGrasp):
    """``open``: disengage contacts (paper, Table II: "change opening width to disengage").

    Two kinds of edge:

    - g -> {0, 0}, the reverse of ``approach-contact``: leave the contact (a two-finger
      grasp opens to the approach width, or moves straight up at a fixed width; a
      one-finger grasp backs off along its contact normal), retreat along the gripper's +y
      axis until clear of the object, rise to the safe height and move to the home pose.
      Same checks as ``approach-contact`` (the object must rest without the gripper); the
      two share one memo of route validity per pose.
    - both fingers touching -> finger k alone, the reverse of ``close``: finger k stays
      put (FIXED on its contact), the other opens to the destination's larger width, the
      gripper origin following at half the rate (the arm keeps finger k where it is). The
      object must stay still under finger k and the environment at every sample. Not for
      a fixed-width gripper. Likewise finger k alone -> finger k alone at a larger width
      (the free finger moves away; the reverse of ``close``'s narrowing).
    """

    name = "open"

    def prepare(self, context: AdjustContext) -> None:
        if not context.world.gripper.fixed_width:
            context.close_groups  # noqa: B018 (a cached property: built now)

    def _candidates(self, ctx: AdjustContext, pose: Pose, src: IntArray, members: BoolArray
                    ) -> tuple[IntArray, IntArray, IntArray, IntArray, FloatArray]:
        gs = ctx.grasps
        full = src[src != NO_CONTACT] if members[NO_CONTACT] else np.zeros(0, np.int64)
        z = np.zeros(full.size, np.int64)
        travel = _route_motion(ctx, pose, full, True).travel(ctx) if full.size else np.zeros(0)
        parts = [(full, z, z - 1, travel)]
        if not ctx.world.gripper.fixed_width:
            for k in range(2):
                # both touching, or finger k alone, -> finger k alone at a larger width
                from_k = src[(gs.n_touching[src] == 2) | ((gs.n_touching[src] == 1) & gs.touching[src, k])]
                pa, pb = _group_pairs(ctx.close_groups[k], from_k)
                keep = members[pb] & (gs.n_touching[pb] == 1) & gs.touching[pb, k] & (gs.width[pb] > gs.width[pa] + EPS)
                pa, pb = pa[keep], pb[keep]
                parts.append((pa, pb, np.full(pa.size, k, np.int64), 0.5 * (gs.width[pb] - gs.width[pa])))
        a, b, f, t = (np.concatenate(x) for x in zip(*parts))
        return a, b, np.zeros(a.size, np.int64), f, t

    def motion(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> GripperMotion:
        release = edges.dst == NO_CONTACT
        if release.all():
            return _route_motion(context, pose, edges.src, True)
        gs = context.grasps
        one = np.flatnonzero(~release)
        a, b = edges.src[one], edges.dst[one]
        leg = _linear(gs.gripper[a], gs.gripper[b], gs.width[a], gs.width[b])
        _keep_finger(context, leg, a, edges.finger[one], FingerRole.FIXED)
        if not release.any():
            return _assemble(a, b, [leg])
        full = np.flatnonzero(release)
        route = _route_motion(context, pose, edges.src[full], True)
        rest = [_linear(gs.gripper[b], gs.gripper[b], gs.width[b], gs.width[b]) for _ in range(route.n_legs - 1)]
        both = GripperMotion.concat([route, _assemble(a, b, [leg] + rest)])
        return both.take(np.argsort(np.concatenate([full, one]), kind="stable"))

    def check(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> CheckResult:
        release = edges.dst == NO_CONTACT
        if release.all():
            return _route_check(context, pose, edges.src)
        if not release.any():
            return super().check(context, pose, edges)
        full, one = np.flatnonzero(release), np.flatnonzero(~release)
        r1 = _route_check(context, pose, edges.src[full])
        r2 = super().check(context, pose, edges.take(one))
        ok = np.empty(len(edges), dtype=bool)
        failure = np.empty(len(edges), dtype=np.int8)
        ok[full], ok[one] = r1.ok, r2.ok
        failure[full], failure[one] = r1.failure, r2.failure
        return CheckResult(ok, failure, r1.feasibility_checks + r2.feasibility_checks, r1.samples + r2.samples)


@REGISTRY.register("close", Family.ADJUST_GRASP)
class Close(_AdjustGrasp):
    """``close``: one finger touching -> both touching, the touching finger fixed; or a
    one-finger grasp narrowed with the other finger still free (a width change under a
    finger that holds, to a grasp that another primitive needs: a pivot keeps the width).

    Finger k stays put (FIXED on its contact): the destination has the same anchor,
    contact and orientation for finger k (:attr:`AdjustContext.close_groups`) and a
    smaller width; the other finger closes from the source width to the destination
    width (FREE, off the object, until it touches at the end when it does), the gripper
    origin following at half the rate. Travel ``(w_s - w_d) / 2`` (the
    mean of the two fingers'). Impossible for a fixed-width (zero-mobility) gripper. The
    "none touching" case is the closing leg of ``approach-contact``.
    """

    name = "close"

    prepare = Open.prepare  # the same groups

    def _candidates(self, ctx: AdjustContext, pose: Pose, src: IntArray, members: BoolArray
                    ) -> tuple[IntArray, IntArray, IntArray, IntArray, FloatArray]:
        gs = ctx.grasps
        a = b = f = np.zeros(0, np.int64)
        if not ctx.world.gripper.fixed_width:
            parts = []
            for k in range(2):
                s = src[(gs.n_touching[src] == 1) & gs.touching[src, k]]
                pa, pb = _group_pairs(ctx.close_groups[k], s)
                # onto the object, or nearer it with the other finger still free
                keep = members[pb] & (gs.width[pb] < gs.width[pa] - EPS) & (
                    (gs.n_touching[pb] == 2) | ((gs.n_touching[pb] == 1) & gs.touching[pb, k]))
                parts.append((pa[keep], pb[keep], np.full(int(keep.sum()), k, dtype=np.int64)))
            a, b, f = (np.concatenate(x) for x in zip(*parts))
        return a, b, np.zeros(a.size, np.int64), f, 0.5 * (gs.width[a] - gs.width[b])

    def motion(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> GripperMotion:
        gs = context.grasps
        a, b = edges.src, edges.dst
        leg = _linear(gs.gripper[a], gs.gripper[b], gs.width[a], gs.width[b])
        _keep_finger(context, leg, a, edges.finger, FingerRole.FIXED)
        return _assemble(a, b, [leg])


#: Pairs of a pivot group from which :func:`_turned_pairs` bins them rather than forming
#: them all (below, binning costs more than it saves: task 2 has 18,000).
TURNED_PAIRS_MIN = 100_000


def _turned_pairs(ctx: AdjustContext, k: int, sources: IntArray, tol: float) -> tuple[IntArray, IntArray] | None:
    """The pairs of ``_group_pairs(ctx.pivot_groups[k], sources)`` (polyline) whose
    member may be the source turned about its pivot point, in the same (source, member)
    order: a superset of those :meth:`Pivot._pairs` keeps, found without forming the
    others (a 12-gon's pads on its vertices make groups of 400 grasps: 1.8 million pairs,
    of which 8,640 are pivots).

    The member b of a kept pair is the source a turned about a's pivot point c_a by their
    orientation difference, to ``tol``: |c_a + R(delta) (p_a - c_a) - p_b| <= tol for the
    finger's anchors p. With v = R(-phi) (p - c) in each grasp's own gripper frame (its own
    pivot point c), that distance is |v_a - v_b - R(-phi_b) (c_b - c_a)|, and the points
    of a group agree to ``match_tol`` in each coordinate: so a kept pair has |v_a - v_b|
    <= tol + sqrt(2) match_tol. The grasps are binned by group and v on a grid of that
    width and paired with the 3 x 3 cells around their own. ``None`` (all pairs are
    formed) where there are fewer than ``TURNED_PAIRS_MIN`` pairs, some point or anchor is
    not finite, or the bins do not fit one key."""
    groups = ctx.pivot_groups[k]
    gs = ctx.grasps
    rows = groups.members
    src = sources[groups.of[sources] >= 0]
    if int(np.diff(groups.start)[groups.of[src]].sum()) < TURNED_PAIRS_MIN:
        return None  # few pairs: forming them all is cheaper than binning
    d = ctx.anchors[rows, k] - gs.contact[rows, k]
    if not np.isfinite(d).all():
        return None
    phi = gs.gripper[rows, 2]
    c, s = np.cos(phi), np.sin(phi)
    radius = tol + math.sqrt(2.0) * ctx.options.match_tol + 1e-9  # (the last term: rounding, mm)
    own = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)  # v of each row
    cell = np.floor(own / radius).astype(np.int64)
    lo = cell.min(axis=0) - 1
    span = cell.max(axis=0) - lo + 2  # room for the neighbours' offsets
    n_groups = int(groups.start.size - 1)
    if float(n_groups) * float(span[0]) * float(span[1]) >= 2.0 ** 62:
        return None
    v = np.full((len(gs), 2), np.nan)
    v[rows] = own
    ix = cell - lo
    at = np.full((len(gs), 2), -1, dtype=np.int64)
    at[rows] = ix
    key_of = lambda g, x, y: (g * int(span[0]) + x) * int(span[1]) + y  # noqa: E731
    keys = key_of(groups.of[rows], ix[:, 0], ix[:, 1])
    order = np.argsort(keys, kind="stable")
    sorted_keys, targets = keys[order], rows[order]
    parts_a, parts_b = [], []
    g_src, x_src, y_src = groups.of[src], at[src, 0], at[src, 1]
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            want = key_of(g_src, x_src + dx, y_src + dy)
            first = np.searchsorted(sorted_keys, want, side="left")
            cnt = np.searchsorted(sorted_keys, want, side="right") - first
            pa = np.repeat(src, cnt)
            offs = np.repeat(first - np.concatenate([[0], np.cumsum(cnt)[:-1]]), cnt) + np.arange(int(cnt.sum()))
            pb = targets[offs]
            near = np.hypot(v[pa, 0] - v[pb, 0], v[pa, 1] - v[pb, 1]) <= radius
            parts_a.append(pa[near])
            parts_b.append(pb[near])
    a, b = np.concatenate(parts_a), np.concatenate(parts_b)
    by = np.argsort(a * len(gs) + b, kind="stable")
    return a[by], b[by]


def _pivot_centre(ctx: AdjustContext, rows: IntArray, finger: IntArray) -> FloatArray:
    """Pivot point: finger k's centre (two-point) or contact point (polyline)."""
    if ctx.is_polyline:
        return ctx.grasps.contact[rows, finger]
    return ctx.anchors[rows, finger]


@REGISTRY.register("pivot", Family.ADJUST_GRASP)
class Pivot(_AdjustGrasp):
    """``pivot``: turn the gripper about a touching finger k to another grasp keeping
    finger k's contact (e.g. until the other finger touches too); between a pinch and a
    one-finger grasp the other finger also opens or closes.

    The centre is finger k's centre (two-point: the circle turns in place) or its contact
    point (polyline: the pad or fingertip corner turns about it; a pad on an object
    vertex turns its normal with it). Source and destination share finger k's pivot
    point (:attr:`AdjustContext.pivot_groups`); a polyline destination must be the
    source turned about the point. They have the same width, or one is a pinch (both
    fingers touching) and the other a one-finger grasp on finger k at a larger width:
    the pinch lets go of its other finger (or the one-finger grasp closes it onto the
    object) while turning about finger k. That is what a gripper holding an object that
    does not rest alone can do to change its grasp, and the grasp set needs it: a pinch's
    width and orientation come from where its second finger meets the object, a
    one-finger grasp's from a few fixed widths and orientations, so the two never share
    both (only a pinch closed straight along the contact normal shares an orientation
    with a one-finger grasp, which ``open`` and ``close`` need).

    Motion, three legs with finger k on its contact throughout: the other finger's width
    goes from the source's to the *turn width*, the gripper turns about the centre, the
    width goes to the destination's. Both senses of the turn are proposed (the long way
    round may be the free one), and where the width changes, both turn widths: the wider
    (``sense`` +-1: open first, or close last) and the narrower (``sense`` +-2: turn
    first, then open; or close first, then turn onto the object) -- the other finger of
    a pinch leaves the object along the width or across it. Finger k is FIXED over the
    width legs (as in ``close``), FIXED over the turn for a pad and SLIDING for a round
    finger (turning about its centre, its surface slips over the contact); the other
    finger is FREE between the ends. Travel: ``|angle|`` times the mean distance of the
    fingers' anchors from the centre at the turn width, plus half the width change.

    A round finger may also *roll* (``sense`` +-``ROLL_SENSE``, :meth:`_rolls`,
    :func:`_roll_legs`): the gripper turns about the finger's centre while the centre
    moves along the edge by ``radius x turn``, so the contact moves along the edge and
    sticks, to a grasp at the same width with the finger on the same edge where the roll
    puts it (within ``ROLL_TOL``, the rest slipped). Turning in place, the finger's
    surface drags the object along the edge, which what else holds it may not resist:
    task 1's inverse holds its block wedged on its corner, and the finger under it can let
    the other go only by rolling (spinning, it drags the block towards the corner on the
    table, beyond the table's friction). Travel: ``|turn|`` times the mean anchor
    distance from the finger's centre, plus the slip.
    """

    name = "pivot"

    def prepare(self, context: AdjustContext) -> None:
        self._table(context)

    def _candidates(self, ctx: AdjustContext, pose: Pose, src: IntArray, members: BoolArray
                    ) -> tuple[IntArray, IntArray, IntArray, IntArray, FloatArray]:
        return self._table(ctx).select(src, members)

    def _table(self, ctx: AdjustContext) -> _PairTable:
        """Every pivot of the grasp set, by source; built once per grasp set. For finger
        0, then finger 1: each pair of :meth:`_pairs` turned counter-clockwise and
        clockwise at the wider width (senses 1, -1), the pairs that change the width
        turned either way at the narrower one too (2, -2), then the rolls
        (:meth:`_rolls`, ``ROLL_SENSE`` times the turn's sign). Travel: the turn (the
        chosen way round) times the mean anchor radius, plus half the width change, or
        for a roll the turn times the radius plus the slip."""
        hit = ctx._cache.get("pivot-table")
        if hit is not None:
            return hit
        parts = []
        for k in range(2):
            a, b, delta, wide, narrow, radial = self._pairs(ctx, k)
            both = np.flatnonzero(radial > 0.0)  # the width changes: both turn widths
            for sense in (1, -1, 2, -2):
                i = np.arange(a.size) if abs(sense) == 1 else both
                rad = (wide if abs(sense) == 1 else narrow)[i]
                ang = _turn(delta[i], np.sign(sense))
                parts.append((a[i], b[i], sense, k, np.abs(ang) * rad + radial[i]))
            a, b, delta, rad, resid = self._rolls(ctx, k)
            parts.append((a, b, ROLL_SENSE * np.sign(delta).astype(np.int64), k, np.abs(delta) * rad + np.abs(resid)))
        hit = ctx._cache["pivot-table"] = _PairTable.of(parts, len(ctx.grasps))
        return hit

    @staticmethod
    def _pairs(ctx: AdjustContext, k: int
               ) -> tuple[IntArray, IntArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Every pivot about finger k in the grasp set, whatever the pose: (source,
        target, turn angle, mean anchor radius at the wider and at the narrower width,
        half the width change) for sources touching with finger k and targets sharing its
        pivot point, at the same width or one a pinch and the other a one-finger grasp
        on finger k at a larger width (a polyline target must be the source turned about
        the point); sources ascending, targets in group order. Computed once per grasp
        set; a layer keeps the pairs of its sources and G_T."""
        key = ("pivot-pairs", k)
        hit = ctx._cache.get(key)
        if hit is None:
            gs = ctx.grasps
            tol = 5.0 * ctx.options.match_tol
            sources = np.flatnonzero(gs.touching[:, k])
            turned = _turned_pairs(ctx, k, sources, tol) if ctx.is_polyline else None
            a, b = turned if turned is not None else _group_pairs(ctx.pivot_groups[k], sources)
            delta = wrap_angle(gs.gripper[b, 2] - gs.gripper[a, 2]) if a.size else np.zeros(0)
            wa, wb = gs.width[a], gs.width[b]
            na, nb = gs.n_touching[a], gs.n_touching[b]
            same = ctx._q(wa) == ctx._q(wb)
            lets_go = (na == 2) & (nb == 1) & (wb > wa + EPS)  # a pinch opens its other finger
            closes = (na == 1) & (nb == 2) & (wb < wa - EPS)  # ... or closes it
            keep = (a != b) & (np.abs(delta) > 1e-6) & (same | lets_go | closes)
            centre = np.nan_to_num(_pivot_centre(ctx, a, np.full(a.size, k)))
            if ctx.is_polyline and a.size:
                c, s = np.cos(delta), np.sin(delta)
                r = ctx.anchors[a, k] - centre
                moved = centre + np.stack([c * r[:, 0] - s * r[:, 1], s * r[:, 0] + c * r[:, 1]], axis=1)
                keep &= np.linalg.norm(np.nan_to_num(moved - ctx.anchors[b, k], nan=np.inf), axis=1) <= tol
            a, b, delta, centre = a[keep], b[keep], delta[keep], centre[keep]
            wa = gs.width[a]
            wb = np.where(same[keep], wa, gs.width[b])  # a pivot at one width keeps the source's
            wide = _turn_radius(ctx, a, k, centre, np.maximum(wa, wb))
            narrow = wide.copy()  # at one width the same turn: computed where the width changes
            change = np.flatnonzero(wb != wa)
            narrow[change] = _turn_radius(ctx, a[change], k, centre[change], np.minimum(wa, wb)[change])
            hit = ctx._cache[key] = (a, b, delta, wide, narrow, 0.5 * np.abs(wb - wa))
        return hit

    def motion(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> GripperMotion:
        gs = context.grasps
        a, b, k = edges.src, edges.dst, edges.finger
        wa = gs.width[a]
        wb = np.where(context._q(gs.width[b]) == context._q(wa), wa, gs.width[b])  # one width: the source's
        wt = np.where(np.abs(edges.sense) == 1, np.maximum(wa, wb), np.minimum(wa, wb))
        ang = _turn(wrap_angle(gs.gripper[b, 2] - gs.gripper[a, 2]).reshape(-1), np.sign(edges.sense))
        g0 = _at_width(context, a, k, wt)  # source orientation, turn width
        g1 = _at_width(context, b, k, wt)  # destination orientation, turn width
        open_leg = _linear(gs.gripper[a], g0, wa, wt)
        _keep_finger(context, open_leg, a, k, FingerRole.FIXED)
        turn_leg = _rotation(g0, _pivot_centre(context, a, k), ang, wt)
        turn = context.is_polyline & (gs.feature[a, k] >= gs.n_object) & (gs.part[a, k] == FingerPart.PAD)
        # A pad or fingertip corner turns about its contact point: it sticks. A round
        # finger turns about its centre: its surface slips over the contact by radius x
        # turn, so the contact is SLIDING (sample_motion derives the direction).
        role = FingerRole.FIXED if context.is_polyline else FingerRole.SLIDING
        _keep_finger(context, turn_leg, a, k, role, np.asarray(turn, dtype=bool).reshape(-1))
        close_leg = _linear(g1, _at_width(context, b, k, wb), wt, wb)
        _keep_finger(context, close_leg, b, k, FingerRole.FIXED)
        legs = [open_leg, turn_leg, close_leg]
        rolls = np.flatnonzero(np.abs(edges.sense) == ROLL_SENSE)
        if rolls.size:
            _roll_legs(context, legs, rolls, a[rolls], b[rolls], k[rolls])
        return _assemble(a, b, legs)

    @staticmethod
    def _rolls(ctx: AdjustContext, k: int) -> tuple[IntArray, IntArray, FloatArray, FloatArray, FloatArray]:
        """Every rolling pivot about round finger k in the grasp set (none for pads):
        (source, target, turn, mean anchor radius about the finger's centre, the slide
        left after the roll). Source and target touch with finger k on the same object
        edge at the same width; turning the gripper by ``delta`` (the short way) while
        the finger rolls moves its contact along the edge by ``radius * delta``, and the
        target's contact lies within ``ROLL_TOL`` of there (the rest is slid). Computed
        once per grasp set."""
        key = ("pivot-rolls", k)
        hit = ctx._cache.get(key)
        if hit is not None:
            return hit
        gs = ctx.grasps
        z = np.zeros(0, np.int64)
        if ctx.is_polyline:
            hit = ctx._cache[key] = (z, z, np.zeros(0), np.zeros(0), np.zeros(0))
            return hit
        r = float(ctx.world.gripper.finger_radius)
        rows = np.flatnonzero(gs.touching[:, k] & (gs.feature[:, k] >= 0) & (gs.feature[:, k] < gs.n_object))
        rows = rows[rows != NO_CONTACT]
        # one group per edge and width, sorted by the contact's place along the edge
        u = gs.arclength[rows, k]
        order = np.lexsort((u, ctx._q(gs.width[rows]), gs.feature[rows, k]))
        rows, u = rows[order], u[order]
        group = np.concatenate([[0], np.cumsum((np.diff(gs.feature[rows, k]) != 0)
                                                | (np.diff(ctx._q(gs.width[rows])) != 0))]) if rows.size else z
        reach = r * np.pi + ROLL_TOL  # the farthest a turn of at most half a circle rolls
        key_u = group * (10.0 * (gs.perimeter + reach)) + u  # groups far apart on one line
        theta = gs.gripper[rows, 2]
        found = []
        for ia, ib in _roll_candidates(rows.size, group, u, wrap_angle(theta), r,
                                       10.0 * (gs.perimeter + 2.0 * reach + 2.0 * np.pi * r)):
            # the pairs within reach along the edge (all the rolls)
            near = (key_u[ib] >= key_u[ia] - reach) & (key_u[ib] <= key_u[ia] + reach)
            ia, ib = ia[near], ib[near]
            delta = wrap_angle(theta[ib] - theta[ia])
            resid = (u[ib] - u[ia]) - r * delta
            keep = (ia != ib) & (np.abs(delta) > ROLL_MIN_TURN) & (np.abs(resid) <= ROLL_TOL)
            found.append((ia[keep], ib[keep], delta[keep], resid[keep]))
        ia, ib, delta, resid = (np.concatenate(part) for part in zip(*found)) if found else (z, z, np.zeros(0),
                                                                                           np.zeros(0))
        # in (source, target) order, each pair once (the tests are the pair's alone, so
        # the few that pass are ordered, not the candidates)
        pick = _pair_order(ia, ib, rows.size)
        ia, ib, delta, resid = ia[pick], ib[pick], delta[pick], resid[pick]
        a, b = rows[ia], rows[ib]
        # the radius is the source's own (about its anchor, at its width): once per contact
        rad = _turn_radius(ctx, rows, k, ctx.anchors[rows, k], gs.width[rows])[ia] if a.size else np.zeros(0)
        hit = ctx._cache[key] = (a, b, delta, rad, resid)
        return hit

    def parameters(self, context: AdjustContext, edges: IntraEdges, index: int = 0) -> dict[str, Any]:
        out = super().parameters(context, edges, index)
        one = edges.take([index])
        m = self.motion(context, Pose(0.0, 0.0, 0.0), one)
        out["sense"] = int(np.sign(one.sense[0]))
        if abs(int(one.sense[0])) == ROLL_SENSE:
            out["rolls"] = True
            out["angle"] = round(math.degrees(float(m.angle[0, 0])), 4)
            out["turn_width"] = round(float(m.width[0, 0]), 4)
            return out
        out["angle"] = round(math.degrees(float(m.angle[0, 1])), 4)
        out["turn_width"] = round(float(m.width[0, 1]), 4)
        return out


def _roll_candidates(n: int, group: IntArray, u: FloatArray, theta: FloatArray, r: float, spread: float
                     ) -> Iterator[tuple[IntArray, IntArray]]:
    """Pairs (i, j) of ``n`` contacts that may be rolls, window by window, each window's
    by i ascending, possibly repeated across windows (:func:`_pair_order` orders the few
    that pass): a superset of the pairs in one group whose residual slide ``(u_j - u_i) - r
    wrap(theta_j - theta_i)`` is within ``ROLL_TOL``.

    With ``v = u - r theta`` (``theta`` in [-pi, pi)) that residual is ``v_j - v_i +
    2 pi r m`` for m in {-1, 0, 1}, so j lies in one of three windows of half-width
    ``ROLL_TOL`` (and a rounding margin) about ``v_i - 2 pi r m`` in the group's order by
    v: a few contacts each, where the window of the reach along the edge (``r pi +
    ROLL_TOL`` either way) holds dozens. ``spread`` keeps the groups apart on one line.
    """
    if n == 0:
        return
    v = u - r * theta
    order = np.lexsort((v, group))
    key = group[order] * spread + v[order]
    half = ROLL_TOL + 1e-6
    at = np.empty(n, np.int64)  # contact i's place in that order
    at[order] = np.arange(n)
    for m in (-1, 0, 1):
        centre = key[at] - 2.0 * np.pi * r * m
        lo = np.searchsorted(key, centre - half, side="left")
        hi = np.searchsorted(key, centre + half, side="right")
        cnt = hi - lo
        # i ascending (a window's pairs come grouped by i: cheap to sort, _pair_order)
        i = np.repeat(np.arange(n), cnt)
        j = np.repeat(lo - np.concatenate([[0], np.cumsum(cnt)[:-1]]), cnt) + np.arange(int(cnt.sum()))
        yield i, order[j]


def _pair_order(i: IntArray, j: IntArray, n: int) -> IntArray:
    """The positions of the pairs ``(i, j)`` (indices below ``n``) sorted by i then j,
    each pair's first only (the windows of :func:`_roll_candidates` meet when the radius
    is tiny)."""
    if i.size == 0:
        return np.zeros(0, np.int64)
    pos = np.argsort(i * n + j, kind="stable")
    pair = (i * n + j)[pos]
    return pos[np.concatenate([[True], pair[1:] != pair[:-1]])]


#: ``IntraEdges.sense`` of a rolling pivot (times the sign of its turn).
ROLL_SENSE = 3
#: The largest slide (mm) along the edge after a rolling pivot, onto the target's sample.
ROLL_TOL = 1.0
#: Turns smaller than this (radians) are slides, not pivots.
ROLL_MIN_TURN = 1e-6


def _roll_legs(ctx: AdjustContext, legs: list[_Leg], i: IntArray, a: IntArray, b: IntArray, k: IntArray) -> None:
    """Make edges ``i`` of the pivot's three legs a rolling pivot of grasp ``a`` onto
    ``b`` about round finger ``k``: the gripper turns by the orientation difference about
    the finger's centre while that centre moves along the edge from ``a``'s contact to
    ``b``'s, so the finger rolls on the object (its contact moves along the edge) and
    slips only by what the roll does not cover (at most ``ROLL_TOL``: the contact is
    SLIDING then, sticking for a pure roll, :func:`sample_motion` tells from the
    motion); the other two legs stand still at ``b``. The other finger is free."""
    gs = ctx.grasps
    ga, gb = gs.gripper[a], gs.gripper[b]
    delta = wrap_angle(gb[:, 2] - ga[:, 2]).reshape(-1)
    shift = gs.contact[b, k] - gs.contact[a, k]  # the centre moves as the contact does
    z = np.zeros(i.size)
    for n, leg in enumerate(legs):
        leg.start[i] = ga if n == 0 else gb
        leg.width[i], leg.dwidth[i] = gs.width[a], 0.0
        leg.centre[i] = ctx.anchors[a, k] if n == 0 else gb[:, :2]
        leg.angle[i] = delta if n == 0 else z
        leg.shift[i] = shift if n == 0 else 0.0
        assert leg.role is not None and leg.contact is not None and leg.normal is not None and leg.mu is not None
        leg.role[i] = FingerRole.FREE
        leg.contact[i], leg.normal[i], leg.mu[i] = 0.0, 0.0, 0.0
        if leg.turn_normal is not None:
            leg.turn_normal[i] = False
        leg.role[i, k] = FingerRole.SLIDING if n == 0 else FingerRole.FIXED
        leg.contact[i, k] = gs.contact[a, k] if n == 0 else gs.contact[b, k]
        leg.normal[i, k] = gs.normal[a, k]
        leg.mu[i, k] = ctx.mu[a, k]


def _turn(delta: FloatArray, sense: ArrayLike) -> FloatArray:
    """The turn by ``delta`` (wrapped) the ``sense`` way round (+1 counter-clockwise)."""
    sense = np.asarray(sense, dtype=float)
    return np.where(delta * sense > 0, delta, delta + sense * 2.0 * np.pi)


def _at_width(ctx: AdjustContext, rows: IntArray, finger: IntArray, width: FloatArray) -> FloatArray:
    """Object-frame gripper poses of grasps ``rows`` with the width changed to ``width``
    and finger ``finger``'s anchor kept where it is (the other finger moves)."""
    g = ctx.grasps.gripper[rows].copy()
    ex = np.stack([np.cos(g[:, 2]), np.sin(g[:, 2])], axis=1)
    sign = np.where(np.asarray(finger) == 0, -1.0, 1.0)  # finger 1 sits at o - (w / 2) e_x
    g[:, :2] = ctx.anchors[rows, finger] - (sign * 0.5 * width)[:, None] * ex
    return g


def _turn_radius(ctx: AdjustContext, rows: IntArray, finger: int, centre: FloatArray, width: FloatArray) -> FloatArray:
    """Mean distance from ``centre`` of the two fingers' anchors of grasps ``rows`` at
    ``width`` with finger ``finger``'s anchor kept (what :meth:`GripperMotion.travel`
    takes for the turn)."""
    phi = ctx.grasps.gripper[rows, 2]
    kept = ctx.anchors[rows, finger]
    kx, ky = kept[:, 0], kept[:, 1]
    cx, cy = centre[:, 0], centre[:, 1]
    w = (1.0 if finger == 0 else -1.0) * width
    ox, oy = kx + w * np.cos(phi), ky + w * np.sin(phi)
    return 0.5 * (_hypot(kx - cx, ky - cy) + _hypot(ox - cx, oy - cy))


def _hypot(x: FloatArray, y: FloatArray) -> FloatArray:
    """``np.linalg.norm(np.stack([x, y], axis=1), axis=1)`` without the stack, to the
    bit: numpy's norm adds the squares (two of them: one addition, in either order) and
    takes the root; ``np.hypot`` rounds otherwise."""
    return np.sqrt(x * x + y * y)


@REGISTRY.register("slide", Family.ADJUST_GRASP)
class Slide(_AdjustGrasp):
    """``slide``: translate the gripper along the object edge finger k touches, to
    another grasp on that edge with the same orientation, width and contact placement in
    the gripper frame (:attr:`AdjustContext.slide_groups`).

    Finger k is SLIDING (friction on the object along the slide); the other finger slides
    too if it touches (on a parallel edge, same group), else it is FREE. A two-finger
    slide is proposed once (as finger 1's). Travel: the translation's length, at most
    ``slide_max_travel``.
    """

    name = "slide"

    def prepare(self, context: AdjustContext) -> None:
        self._table(context)

    def _candidates(self, ctx: AdjustContext, pose: Pose, src: IntArray, members: BoolArray
                    ) -> tuple[IntArray, IntArray, IntArray, IntArray, FloatArray]:
        return self._table(ctx).select(src, members)

    def _table(self, ctx: AdjustContext) -> _PairTable:
        """Every slide of the grasp set (:meth:`_pairs` of finger 0, then finger 1; sense
        0), by source; built once per grasp set (by the compiled module from the slide
        groups, to the same table)."""
        hit = ctx._cache.get("slide-table")
        if hit is None:
            if _search is not None:  # straight from the groups, as _pairs pairs them (one pass to count, one to fill)
                gs = ctx.grasps
                size = len(gs)
                groups = [(np.ascontiguousarray(g.of, dtype=np.int64), np.ascontiguousarray(g.start, dtype=np.int64),
                           np.ascontiguousarray(g.members, dtype=np.int64)) for g in ctx.slide_groups]
                args = (np.ascontiguousarray(gs.touching, dtype=bool).view(np.uint8), *groups[0], *groups[1],
                        np.ascontiguousarray(gs.gripper[:, 0], dtype=float),
                        np.ascontiguousarray(gs.gripper[:, 1], dtype=float), float(ctx.options.slide_max_travel))
                starts = np.empty(size + 1, np.int64)
                n = _search.slide_table(*args, starts)
                dst, finger, travel = np.empty(n, np.int32), np.empty(n, np.int8), np.empty(n)
                _search.slide_table(*args, starts, dst, finger, travel)
                hit = _PairTable(dst, np.zeros(n, np.int8), finger, travel, starts)
            else:
                parts = [(a, b, 0, k, travel) for k in range(2) for a, b, travel in [self._pairs(ctx, k)]]
                hit = _PairTable.of(parts, len(ctx.grasps))
            ctx._cache["slide-table"] = hit
        return hit

    @staticmethod
    def _pairs(ctx: AdjustContext, k: int) -> tuple[IntArray, IntArray, FloatArray]:
        """Every slide of finger k in the grasp set, whatever the pose: (source, target,
        travel) for sources touching with finger k (and not finger 0 when k = 1, a
        two-finger slide being finger 0's), targets in the source's slide group, travel
        within ``slide_max_travel``; sources ascending, each source's targets in group
        order (what :func:`_group_pairs` gives for any sorted subset of the sources).
        Computed once per grasp set; a layer keeps the pairs of its sources and G_T."""
        key = ("slide-pairs", k)
        hit = ctx._cache.get(key)
        if hit is None:
            gs = ctx.grasps
            s = np.flatnonzero(gs.touching[:, k])
            if k == 1:
                s = s[~gs.touching[s, 0]]
            a, b = _group_pairs(ctx.slide_groups[k], s)
            x, y = gs.gripper[:, 0], gs.gripper[:, 1]
            travel = _hypot(x[b] - x[a], y[b] - y[a])
            keep = (a != b) & (travel <= ctx.options.slide_max_travel)
            hit = ctx._cache[key] = (a[keep], b[keep], travel[keep])
        return hit

    def motion(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> GripperMotion:
        gs = context.grasps
        a, b, k = edges.src, edges.dst, edges.finger
        leg = _linear(gs.gripper[a], gs.gripper[b], gs.width[a], gs.width[b])
        _keep_finger(context, leg, a, k, FingerRole.SLIDING)
        _keep_finger(context, leg, a, 1 - k, FingerRole.SLIDING, where=gs.touching[a, 1 - k])
        # Between the ends a sliding contact is on the edge, with the edge's coefficient
        # (a grasp near a vertex has the vertex's, ``GraspSet.contact_mu``; the ends keep
        # the grasps' own). Friction that opposes a slip does not only help: the
        # coefficient must be the one the finger meets, not a smaller one.
        assert leg.mu is not None and leg.role is not None
        leg.mu = np.where(leg.role == FingerRole.SLIDING, context.edge_mu[np.maximum(gs.feature[a], 0)], leg.mu)
        return _assemble(a, b, [leg])


@REGISTRY.register("flip", Family.ADJUST_GRASP)
class Flip(_AdjustGrasp):
    """``flip``: turn the gripper by pi in the plane about the gripper-frame point
    (0, y_m) -- y_m = 0 for circles, the pad's middle height for pads -- so that the
    fingers swap places onto the same contacts: g -> ``GraspSet.flipped[g]``.

    Three legs: open symmetrically to ``w_f = min(w + 2 approach_clearance, w_max)``
    (nothing for a fixed-width gripper), turn by +pi or -pi (both senses are proposed)
    about (0, y_m) -- a point the symmetric opening does not move --, close back to
    ``w``. Opening first keeps a pad from digging its far end into the surface it
    swings onto. Both fingers leave the object at once and are FREE until the last
    sample: the object must rest on the environment alone, and the fingers and palm
    must clear the object and the environment over the whole half turn. Travel
    ``(w_f - w) + pi sqrt((w_f / 2)^2 + y_m^2)``.
    """

    name = "flip"

    def _flip_width(self, ctx: AdjustContext, w: FloatArray) -> FloatArray:
        grip = ctx.world.gripper
        if grip.fixed_width:
            return w.copy()
        return np.maximum(np.minimum(w + 2.0 * ctx.options.approach_clearance, float(grip.width_range[1])), w)

    def _candidates(self, ctx: AdjustContext, pose: Pose, src: IntArray, members: BoolArray
                    ) -> tuple[IntArray, IntArray, IntArray, IntArray, FloatArray]:
        gs = ctx.grasps
        src = src[src != NO_CONTACT]
        dst = gs.flipped[src]
        keep = dst >= 0
        keep[keep] = members[dst[keep]]
        a, b = src[keep], dst[keep]
        w = gs.width[a]
        wf = self._flip_width(ctx, w)
        travel = (wf - w) + np.pi * np.hypot(0.5 * wf, ctx.flip_height)
        n = a.size
        return (np.concatenate([a, a]), np.concatenate([b, b]), np.concatenate([np.ones(n, np.int64), -np.ones(n, np.int64)]),
                np.full(2 * n, -1), np.concatenate([travel, travel]))

    def motion(self, context: AdjustContext, pose: Pose, edges: IntraEdges) -> GripperMotion:
        gs = context.grasps
        a, b = edges.src, edges.dst
        g = gs.gripper[a]
        w = gs.width[a]
        wf = self._flip_width(context, w)
        ey = np.stack([-np.sin(g[:, 2]), np.cos(g[:, 2])], axis=1)
        centre = g[:, :2] + context.flip_height * ey
        legs = [_linear(g, g, w, wf), _rotation(g, centre, edges.sense * np.pi, wf),
                _linear(gs.gripper[b], gs.gripper[b], wf, gs.width[b])]
        return _assemble(a, b, legs)
