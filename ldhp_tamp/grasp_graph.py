"""Bottom tier: grasp-sequence planning on the layered grasp graph (paper, "Two-Tier
Planning", and Algorithm 1's inner loop).

Given an object-pose path T_0..T_n (MoveObject segments m_0..m_(n-1)), the graph has one
layer per pose: nodes (k, g) for g in G_(T_k) (row 0, the no-contact grasp {0, 0},
always included). Edges:

- *inter-pose* (k, g) -> (k + 1, g) for g in G_(m_k), cost S_g(m_k) (the grasp quality
  of :func:`geometry.grasps.motion_conditioned`);
- *intra-pose* (k, g_i) -> (k, g_j), one per AdjustGrasp primitive instance the domain
  declares (:mod:`ldhp_tamp.primitives.adjust_grasp`), cost
  ``lambda1 * travel + lambda2 * switches``, between grasps that hold the object still
  at T_k.

The start node is (0, g_start): the scenario's start grasp in the object frame (an extra
row of the grasp set when it is not in the set exactly), or {0, 0} when the object
starts free of the gripper; with ``start_grasp = "any"`` every grasp of G_(T_0) that holds
the object still at T_0 is a start node, and the search starts from the cheapest. A goal node is (n, {0, 0}) under ``goal_release``, any
(n, g) otherwise (the last segment's G_m already guarantees the grasp holds the object).

Search: the graph's edges and costs are known up front (a layer's candidate intra-pose
edges come from each primitive's vectorised ``propose``); only the feasibility of the
intra-pose edges (collision and quasi-static checks along the gripper motion) is costly.
So the shortest path is found the LazySP way: the cheapest path of the *optimistic*
graph (unchecked edges assumed feasible, edges found infeasible removed) is computed by
vectorised Bellman-Ford rounds per layer (at most ``max_intra_depth`` AdjustGrasp edges in
a row at one pose); its unchecked edges -- and every unchecked edge on an optimistic path
at most ``slack`` dearer -- are checked in one vectorised batch; this repeats until the
cheapest optimistic path is all feasible (it is then the cheapest feasible path) or there
is none. G_T and G_m are cached per pose / per segment (its dense poses), the candidate
edges and what was learnt of their feasibility per pose, so the dichotomy refinement of
the TAMP loop recomputes only what the split changes. ``docs/design/grasp_graph.md`` has
the details and measurements.
"""

from __future__ import annotations

import enum
import functools
import logging
import math
import time
from collections import Counter, OrderedDict, defaultdict
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np
import shapely
from numpy.typing import NDArray

from geometry.collision import finger_shapes
from geometry.grasps import (
    NO_CONTACT,
    FingerPart,
    GraspSet,
    MotionCheckOptions,
    MotionGrasps,
    motion_conditioned,
    rate_motion_grasps,
    PRESS_LADDER,
    pose_conditioned,
    press_forces,
    within_force_limit,
)
from geometry.poses import BoolArray, IntArray, Pose, compose_batch, transform_points, wrap_angle
from geometry.shapes import FloatArray, segment_distances
from geometry.tolerances import CONTACT_TOL, EPS
from geometry.world import GripperState, PolylineGripper, World
from ldhp_tamp import budget
from ldhp_tamp.kernels import SEARCH, by_source, csr
from ldhp_tamp.parallel import Helper, cores, two_at_a_time
from ldhp_tamp.path import Segment
from ldhp_tamp.plan import PRESS_KEY, Press, Step, Waypoint
from ldhp_tamp.primitives.adjust_grasp import (
    AdjustContext,
    AdjustGraspOptions,
    CheckFailure,
    CheckResult,
    IntraEdges,
    LayerData,
    LazyAdjustGrasp,
    motion_waypoints,
)
from ldhp_tamp.primitives.registry import REGISTRY, Binding, Family
from ldhp_tamp.streams import PosePath

__all__ = [
    "GraspGraphOptions",
    "GraspPlanResult",
    "GraspPlanStatus",
    "GraspPlanner",
    "object_frame_grasp",
]

log = logging.getLogger(__name__)

#: The compiled array passes of the search (``ldhp_tamp/_search.c``, interface
#: ``ldhp_tamp.kernels.SEARCH_API``), or ``None``: numpy computes the same arrays.
_search = SEARCH

#: mm: a pivot the judge refuses takes with it the pivots of the same finger, the same way
#: round, on a contact at most this far from its own (GraspPlanner.reject_adjust).
PIVOT_REFUSAL_RADIUS = 5.0



class GraspPlanStatus(enum.Enum):
    """Outcome of one bottom-tier solve."""

    SOLVED = "solved"
    NO_GRASP_FOR_SEGMENT = "no-grasp-for-segment"  #: some G_m is empty
    NO_PATH = "no-path"  #: every G_m is non-empty but no grasp sequence joins them


@dataclass(frozen=True)
class GraspGraphOptions:
    """Settings of the bottom tier.

    Attributes
    ----------
    adjust : AdjustGraspOptions
        The AdjustGrasp primitives' settings and the intra-pose cost weights.
    motion : MotionCheckOptions
        Settings of G_m (:func:`geometry.grasps.motion_conditioned`), with the inter-pose
        quality weights w1, w2.
    max_intra_depth : int
        Most AdjustGrasp edges in a row at one pose (between two MoveObject steps, or
        before the first / after the last): the Bellman-Ford rounds per layer.
    slack : float
        Each LazySP round checks, besides the cheapest optimistic path's unchecked edges,
        every unchecked edge on an optimistic path at most this much dearer.
    batch : int
        Most intra-pose edges checked per LazySP round (cheapest first).
    max_edge_checks : int
        Budget of intra-pose edges checked per :meth:`GraspPlanner.plan` call; when it
        runs out the search stops with NO_PATH and says so.
    start_touch_tol : float
        A finger of the scenario's start grasp within this distance (mm) of the object
        touches it.
    cache_poses : int
        Poses whose candidate intra-pose edges (and what was learnt of them) are kept
        between solves, least recently used dropped first (each costs ~1-30 MB).
    helper : bool
        On a machine with more than one core, share the work with a helper process forked
        with the grasp set (:class:`ldhp_tamp.parallel.Helper`): the next uncached G_T and
        G_m while this process computes the current one, half of a LazySP round's larger
        edge checks, and (through :meth:`GraspPlanner.live_helper`) the streams' sweeps
        and, when the solve forks it in its setup (:meth:`GraspPlanner.start_helper`),
        the admissible transitions; the same results either way.
        :meth:`GraspPlanner.close` ends it.
    """

    adjust: AdjustGraspOptions = AdjustGraspOptions()
    motion: MotionCheckOptions = MotionCheckOptions()
    max_intra_depth: int = 3
    slack: float = 1.0
    batch: int = 512
    max_edge_checks: int = 30_000
    start_touch_tol: float = CONTACT_TOL
    cache_poses: int = 16
    helper: bool = True


@dataclass(frozen=True, eq=False)
class GraspPlanResult:
    """What :meth:`GraspPlanner.plan` returns.

    Attributes
    ----------
    status : GraspPlanStatus
    steps : tuple of Step
        SOLVED: the plan's steps, AdjustGrasp steps (with their waypoints) interleaved
        with the MoveObject steps (one per segment); empty otherwise.
    grasps : tuple of int
        SOLVED: g_0..g_n, the grasp carried out of each layer (the final grasp for the
        last), indices into :attr:`GraspPlanner.grasps`.
    cost : float
        SOLVED: the path's cost, sum of S_g(m_k) and of the AdjustGrasp edge costs.
    failing_segment : int or None
        NO_GRASP_FOR_SEGMENT: the first segment whose G_m is empty; NO_PATH: the segment
        at which forward reachability from the start node dies (the last segment when
        the goal layer is reached but the goal condition cannot be met), decided: a path
        of checked, feasible edges arrives at its first pose and none arrives at its
        last (unless the check budget ran out: then counting unchecked AdjustGrasp
        edges as feasible).
    reason : str
        Human-readable: which segment, which primitives, how many grasps were tried and
        why they failed.
    nodes : int
        Nodes of the layered graph (sum of |G_T_k|, plus an extra start node).
    edges : int
        Inter-pose edges (sum of |G_m_k|) plus the intra-pose edges found feasible.
    feasibility_checks : int
        Quasi-static instances decided in this call (G_m and intra-pose edges).
    time_s : float
        Wall time of the call.
    node_path : tuple of (int, int)
        SOLVED: the (layer, grasp) nodes of the path.
    layer_sizes : tuple of int
        |G_T_k| per layer computed.
    motion_sizes : tuple of int
        |G_m_k| per segment computed.
    search_rounds : int
        LazySP rounds (optimistic shortest path, then one batch of checks).
    intra_proposed, intra_checked, intra_feasible : int
        Intra-pose candidate edges in the graph, checked in this call, found feasible in
        this call (edges checked by earlier calls are not checked again).
    by_primitive : Mapping[str, Mapping[str, int]]
        Per bound AdjustGrasp primitive: ``candidates``, ``checked``, ``feasible`` and
        the failures by :class:`~ldhp_tamp.primitives.adjust_grasp.CheckFailure` name.
    timings : Mapping[str, float]
        Seconds per stage: ``pose_sets``, ``motion_sets``, ``candidates``, ``search``,
        ``steps``.
    candidates : int or None
        NO_GRASP_FOR_SEGMENT: the grasps tried on the failing segment (collision-free at
        both its ends).
    at_goal : bool
        NO_PATH: the goal layer is reached but the goal condition (a release) cannot be
        met; otherwise forward reachability dies at ``failing_segment``.
    """

    status: GraspPlanStatus
    steps: tuple[Step, ...] = ()
    grasps: tuple[int, ...] = ()
    cost: float = math.inf
    failing_segment: int | None = None
    reason: str = ""
    nodes: int = 0
    edges: int = 0
    feasibility_checks: int = 0
    time_s: float = 0.0
    node_path: tuple[tuple[int, int], ...] = ()
    layer_sizes: tuple[int, ...] = ()
    motion_sizes: tuple[int, ...] = ()
    search_rounds: int = 0
    intra_proposed: int = 0
    intra_checked: int = 0
    intra_feasible: int = 0
    by_primitive: Mapping[str, Mapping[str, int]] = field(default_factory=dict)
    timings: Mapping[str, float] = field(default_factory=dict)
    candidates: int | None = None
    at_goal: bool = False
    adjust_edges: tuple[Any, ...] = field(default=(), repr=False, compare=False)
    """SOLVED: per step, the AdjustGrasp candidate edge it takes (what
    :meth:`GraspPlanner.reject_adjust` marks infeasible), ``None`` for a MoveObject step."""

    @property
    def solved(self) -> bool:
        return self.status is GraspPlanStatus.SOLVED


# --------------------------------------------------------------------------------------
# The scenario's start grasp in the object frame
# --------------------------------------------------------------------------------------


def object_frame_grasp(world: World, gripper: Pose, width: float, tol: float = CONTACT_TOL) -> dict[str, Any]:
    """The columns of one grasp-set row for a gripper placed at ``gripper`` (object
    frame) with ``width``: which fingers touch (within ``tol``), where, with which
    normal, feature, finger part and boundary coordinate.

    Two-point: the contact is the boundary point nearest to the finger centre, normal
    from the centre towards it. Polyline: the contact region (object boundary within
    ``tol`` of the finger polygon) is represented by the midpoint of its longest piece,
    as :mod:`geometry.grasps` does for a pad flush on an edge; the normal is minus the
    object edge's outward normal, or at an object vertex the outward normal of the
    nearest finger edge.

    Returns
    -------
    dict
        ``gripper`` (3,), ``width``, ``contact`` (2, 2), ``normal`` (2, 2), ``feature``
        (2,), ``part`` (2,), ``arclength`` (2,) -- NaN / -1 / NONE where not touching.
    """
    poly = world.object.polygon
    n = len(poly)
    grip = world.gripper
    g = gripper.as_array()
    contact = np.full((2, 2), np.nan)
    normal = np.full((2, 2), np.nan)
    feature = np.full(2, -1, dtype=np.int64)
    part = np.zeros(2, dtype=np.int8)
    fs = finger_shapes(grip, g[None], float(width))
    vtol = 1e-6 * max(1.0, float(np.abs(poly.vertices).max()))
    for k in range(2):
        if fs.centres is not None:
            c = fs.centres[0, k]
            d, t = segment_distances(c[None], poly.edges)
            i = int(np.argmin(d[0]))
            if d[0, i] - float(fs.radius) > tol:
                continue
            p = poly.vertices[i] + t[0, i] * poly.edge_vectors[i]
            nv = (p - c) / max(float(np.linalg.norm(p - c)), EPS)
            part[k] = FingerPart.CIRCLE
        else:
            assert fs.polygons is not None
            fpoly = shapely.Polygon(fs.polygons[0, k])
            if shapely.distance(fpoly, poly.shapely) > tol:
                continue
            region = shapely.intersection(shapely.LinearRing(poly.vertices), shapely.buffer(fpoly, tol))
            pieces = [q for q in shapely.get_parts(region) if not q.is_empty]
            if not pieces:
                continue
            best = max(pieces, key=lambda q: q.length)
            pt = best.interpolate(0.5, normalized=True)
            p = np.array([pt.x, pt.y])
            fe = fs.polygons[0, k]
            fseg = np.stack([fe, np.roll(fe, -1, axis=0)], axis=1)
            fd, _ = segment_distances(p[None], fseg)
            j = int(np.argmin(fd[0]))
            dvec = fseg[j, 1] - fseg[j, 0]
            nv = np.array([dvec[1], -dvec[0]]) / max(float(np.linalg.norm(dvec)), EPS)  # outward (CCW)
            assert isinstance(grip, PolylineGripper)
            local_y = float(np.dot(p - g[:2], [-math.sin(g[2]), math.cos(g[2])]))
            pad_lo = float(grip.finger.vertices[:, 1].min())
            part[k] = FingerPart.TIP if abs(local_y - pad_lo) <= vtol else FingerPart.PAD
        dv = np.linalg.norm(poly.vertices - p, axis=1)
        if dv.min() <= vtol:
            j = int(np.argmin(dv))
            feature[k] = n + j
            p = poly.vertices[j].copy()
        else:
            d, _ = segment_distances(p[None], poly.edges)
            i = int(np.argmin(d[0]))
            feature[k] = i
            nv = -poly.normals[i]
        contact[k] = p
        normal[k] = nv
    cum = np.concatenate([[0.0], np.cumsum(poly.edge_lengths)[:-1]])
    arc = np.full(2, np.nan)
    for k in range(2):
        f = int(feature[k])
        if f >= n:
            arc[k] = cum[f - n]
        elif f >= 0:
            arc[k] = cum[f] + float(np.linalg.norm(contact[k] - poly.vertices[f]))
    return {"gripper": g, "width": float(width), "contact": contact, "normal": normal, "feature": feature,
            "part": part, "arclength": arc}


def _with_row(grasps: GraspSet, row: Mapping[str, Any]) -> GraspSet:
    """The grasp set with one more row (its ``flipped`` is -1)."""

    def cat(name: str, value: Any) -> np.ndarray:
        a = getattr(grasps, name)
        out = np.concatenate([a, np.asarray(value, dtype=a.dtype)[None]], axis=0)
        out.setflags(write=False)
        return out

    return GraspSet(cat("gripper", row["gripper"]), cat("width", row["width"]), cat("contact", row["contact"]),
                    cat("normal", row["normal"]), cat("feature", row["feature"]), cat("part", row["part"]),
                    cat("arclength", row["arclength"]), cat("flipped", -1), grasps.n_object, grasps.perimeter)


def _find_row(grasps: GraspSet, row: Mapping[str, Any], tol: float = 1e-6) -> int | None:
    g = row["gripper"]
    d = np.hypot(grasps.gripper[:, 0] - g[0], grasps.gripper[:, 1] - g[1])
    da = np.abs(wrap_angle(grasps.gripper[:, 2] - g[2]))
    ok = (d <= tol) & (da <= tol) & (np.abs(grasps.width - row["width"]) <= tol)
    ok &= np.all((grasps.part != 0) == (np.asarray(row["part"]) != 0)[None, :], axis=1)
    idx = np.flatnonzero(ok)
    return int(idx[0]) if idx.size else None


# --------------------------------------------------------------------------------------
# The planner
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Prim:
    """One bound AdjustGrasp primitive."""

    name: str
    impl: Any
    lazy: bool


@dataclass(frozen=True, eq=False)
class _Layer:
    """The static data of one layer of one solve."""

    index: int
    pose: FloatArray
    key: bytes
    members: BoolArray  # (G,) G_T (and the start node at layer 0)
    size: int
    state: str  # contact-state name at T_k
    holding: Callable[[], BoolArray] = field(repr=False)  # computes ``intra``

    @cached_property
    def intra(self) -> BoolArray:
        """(G,) members that hold the object still: the only intra-pose ends (decided
        when first asked: a layer the forward pass never reaches does not pay for it)."""
        return self.holding()


@dataclass(frozen=True, eq=False)
class _Cands:
    """The candidate intra-pose edges of one primitive at one layer, sorted by source
    (stably: the order the search breaks ties in), with their costs and what is known of
    their feasibility (0 unknown, 1 feasible, -1 not), kept across solves."""

    edges: IntraEdges
    cost: FloatArray
    valid: NDArray[np.int8]


@dataclass(eq=False)
class _Search:
    """Book-keeping of one A* run."""

    proposed: int = 0
    checked: int = 0
    feasible: int = 0
    checks: int = 0
    cost: float = math.inf
    rounds: int = 0
    stats: dict[tuple[int, str], Counter] = field(default_factory=lambda: defaultdict(Counter))


class GraspPlanner:
    """The bottom tier for one task: grasp sets, bound AdjustGrasp primitives, caches.

    Parameters
    ----------
    world : World
    grasps : GraspSet
        The enumerated grasp set (object frame).
    adjust : iterable of Binding
        The AdjustGrasp primitives the domain declares
        (``REGISTRY.bound(domain, Family.ADJUST_GRASP)``): only these make intra-pose
        edges. An implementation with ``propose`` / ``check`` / ``waypoints``
        (:class:`~ldhp_tamp.primitives.adjust_grasp.LazyAdjustGrasp`) is checked lazily;
        any other only through its ``intra_edges``, once per layer.
    start_grasp : GripperState or None
        The scenario's start grasp (world frame); ``None``: the object starts free of
        the gripper (start node {0, 0}), unless ``start_any``.
    start_any : bool
        ``start_grasp = "any"``: the start nodes are every grasp of G_T at the start pose
        that holds the object still there (``AdjustContext.holds``); the search starts
        from whichever gives the cheapest path.
    goal_release : bool
        The gripper must end out of contact (goal node {0, 0}).
    options : GraspGraphOptions, optional
    """

    def __init__(self, world: World, grasps: GraspSet, adjust: Iterable[Binding], start_grasp: GripperState | None = None,
                 goal_release: bool = False, options: GraspGraphOptions | None = None, *,
                 start_any: bool = False) -> None:
        self.world = world
        self.base = grasps
        self.start_grasp = start_grasp
        self.start_any = bool(start_any) and start_grasp is None
        self.goal_release = bool(goal_release)
        self.options = options or GraspGraphOptions()
        prims = []
        for b in adjust:
            if b.family is not Family.ADJUST_GRASP:
                raise ValueError(f"grasp graph: {b.name!r} is a {b.family.value} primitive, not adjust-grasp")
            prims.append(_Prim(b.name, b.implementation, isinstance(b.implementation, LazyAdjustGrasp)))
        self.primitives: tuple[_Prim, ...] = tuple(prims)
        self._start_key: bytes | None = None
        self._start_index: int | IntArray = NO_CONTACT  # the start nodes' grasps with start_any
        self._context: AdjustContext | None = None
        self._pose_sets: dict[bytes, IntArray] = {}
        self._motion_sets: dict[tuple[str, bytes], tuple[MotionGrasps, int]] = {}  # G_m, candidates
        self._cands: OrderedDict[tuple[bytes, str, bool], _Cands] = OrderedDict()
        # a layer's candidate edges, all primitives together (keyed by the _Cands objects)
        self._layer_graphs: OrderedDict[tuple[_Cands, ...], _LayerGraph] = OrderedDict()
        self._helper: Helper | None = None
        self._helper_grasps: GraspSet | None = None  # the grasp set in the helper's state
        self._helper_shared: object = None  # and its last item
        self._shared: object = None  # the last item of every helper forked from now (start_helper)
        self._force_bounded: set[tuple[str, bytes]] = set()  # segments whose G_m is force-bounded

    # ---- sets ------------------------------------------------------------------------

    @property
    def context(self) -> AdjustContext:
        """The primitives' context (its grasp set is :attr:`grasps`)."""
        if self._context is None:
            self._context = AdjustContext(self.world, self.base, self.options.adjust)
        return self._context

    @property
    def grasps(self) -> GraspSet:
        """The grasp set the results index: the enumerated set, plus the start grasp's
        row when it is not in it (fixed by the first :meth:`plan`)."""
        return self.context.grasps

    @property
    def start_index(self) -> int | IntArray:
        """The start node's grasp (0 when the object starts free of the gripper); with
        ``start_any``, the array of the start nodes' grasps."""
        return self._start_index

    def prepare(self, start_pose: Sequence[float] | FloatArray) -> None:
        """Fix the grasp set (:attr:`grasps`, :attr:`context`, :attr:`start_index`) for a
        path starting at ``start_pose``, as :meth:`plan` does (for other planners on the
        same grasp set, e.g. :mod:`ldhp_tamp.baselines.contact_rrt`)."""
        self._prepare(np.asarray(start_pose, dtype=float))

    def prepare_tables(self) -> None:
        """Have the AdjustGrasp primitives build what their proposals share at every
        pose of the grasp set (their optional ``prepare``: pivots', slides' and
        closings' tables of pairs), which their first proposals would build otherwise:
        the solve does it while its helper process computes the setup's transitions
        (the helper, forked before, needs none: it checks edges and computes grasp
        sets). Call :meth:`prepare` first (a change of
        grasp set makes a new context)."""
        for prim in self.primitives:
            build = getattr(prim.impl, "prepare", None)
            if build is not None:
                build(self.context)

    def move_step(self, segment: Segment, g: int, press: float | None = None) -> Step:
        """The MoveObject plan step of ``segment`` carrying grasp ``g`` (as in the plans
        :meth:`plan` makes); ``press`` (N), when given, is the press the step asks for
        (otherwise the one the segment's cached G_m holds for ``g``, if any)."""
        return self._move_step(self.context, segment, g, press)

    def _prepare(self, start_pose: FloatArray) -> None:
        """Fix the grasp set for a path starting at ``start_pose`` (the start grasp's
        row depends on it); the caches are reset when it changes."""
        key = start_pose.tobytes()
        if self._context is not None and self._start_key == key:
            return
        gs = self.base
        index = NO_CONTACT
        if self.start_grasp is not None:
            rel = Pose.from_array(start_pose).inverse().compose(self.start_grasp.pose)
            row = object_frame_grasp(self.world, rel, self.start_grasp.width, self.options.start_touch_tol)
            found = _find_row(gs, row)
            if found is None:
                gs = _with_row(gs, row)
                index = len(gs) - 1
                log.debug("start grasp added as grasp %d (%d finger(s) touching)", index, int((row["part"] != 0).sum()))
            else:
                index = found
        self._context = AdjustContext(self.world, gs, self.options.adjust)
        self._start_key = key
        self._start_index = index
        if self.start_any:  # every grasp that holds the object at the start pose
            held = np.zeros(len(gs), dtype=bool)
            held[pose_conditioned(self.world, gs, start_pose, self.options.adjust.tol)] = True
            held &= gs.n_touching >= 1
            starts = np.flatnonzero(self._context.holds(start_pose, held) & held)
            self._start_index = starts if starts.size else np.array([NO_CONTACT])
        self._pose_sets.clear()
        self._motion_sets.clear()
        self._force_bounded.clear()
        self._cands.clear()
        self._layer_graphs.clear()
        self.close()  # a helper holds the previous grasp set

    def pose_grasps(self, pose: FloatArray) -> IntArray:
        """G_T at an object pose (cached by the pose's bytes)."""
        key = np.asarray(pose, dtype=float).tobytes()
        hit = self._pose_sets.get(key)
        if hit is None:
            hit = pose_conditioned(self.world, self.grasps, pose, self.options.adjust.tol)
            self._pose_sets[key] = hit
        return hit

    def close(self) -> None:
        """End the helper process, if any (a later :meth:`plan` starts another)."""
        if self._helper is not None:
            self._helper.close()
            self._helper = None

    def live_helper(self, grasps: GraspSet | None = None) -> Helper | None:
        """The helper process if one is running (none is started here); its state is
        ``(world, grasps, motion options, AdjustGrasp context, shared)``
        (:meth:`start_helper`). With ``grasps``: only if that grasp set (this very object)
        is the one in its state and the solve gave it ``shared``."""
        h = self._helper
        if h is None or not h.alive:
            return None
        if grasps is not None and (self._helper_grasps is not grasps or self._helper_shared is None):
            return None
        return h

    def start_helper(self, shared: object = None) -> Helper | None:
        """Fork the helper process now (none if it is off or the machine has one core),
        with ``shared`` as the fifth item of its state, after ``(world, grasps, motion
        options, AdjustGrasp context)``, and of every helper forked after it (a change of
        grasp set ends a helper; the next use forks another): the solve forks it in its
        setup, while little is built yet, and has it compute the admissible transitions
        first (:func:`ldhp_tamp.contact_graph.admissible_transitions`). Call
        :meth:`prepare` first. A live helper is kept as it is."""
        self._shared = shared
        return self._helper_process()

    def _helper_process(self) -> Helper | None:
        if not self.options.helper or cores() < 2:
            return None
        if self._helper is None or not self._helper.alive:
            try:
                self._helper = Helper((self.world, self.grasps, self.options.motion, self.context, self._shared))
                self._helper_grasps, self._helper_shared = self.grasps, self._shared
            except (OSError, RuntimeError) as exc:  # no fork: one core it is
                log.debug("no helper process: %s", exc)
                self._helper = None
        return self._helper

    def _pose_sets_paired(self, poses: Sequence[FloatArray]) -> None:
        """G_T of the poses not cached yet, every second one in the helper process."""
        todo = list({p.tobytes(): p for p in poses if p.tobytes() not in self._pose_sets}.values())
        if len(todo) < 2:
            return
        tol = self.options.adjust.tol
        done = two_at_a_time(self._helper_process(), todo, lambda p: pose_conditioned(self.world, self.grasps, p, tol),
                             lambda p: (_helper_pose, (p, tol)))
        for p, hit in zip(todo, done):
            self._pose_sets[p.tobytes()] = hit

    def motion_grasps(self, segment: Segment, rate: bool = True) -> tuple[MotionGrasps, int, bool]:
        """G_m of a segment (cached by its primitive and dense poses): the value, the
        number of candidates (G_T at both ends) and whether it was computed now.
        ``rate=False``: the grasps' quality may be left out (``rated`` False); it is
        computed when a later call asks for it.

        A half of a bisected segment whose parent's G_m is known starts from it: its
        samples are the parent's (:meth:`Segment.split`), so a grasp admitted on the parent
        is admitted on the second half, and on the first half if it passes at the half's
        last sample (where the environment's contact modes now come from the incoming
        motion); a grasp the parent rejected at a sample of this half is rejected here
        too (except at that last sample). Only the rest is checked in full.
        """
        key = _motion_key(segment)
        hit = self._motion_sets.get(key)
        if hit is not None:
            if rate and not hit[0].rated:
                hit = self._motion_sets[key] = (rate_motion_grasps(self.world, self.grasps, segment.poses, hit[0],
                                                                   self.options.motion), hit[1])
            return hit[0], hit[1], False
        cand, n_cand, verified, recheck, ends = self._motion_inputs(segment)
        mg = motion_conditioned(self.world, self.grasps, segment.poses, cand, self.options.motion,
                                verified=verified, recheck=recheck, rate=rate, free_at=ends)
        self._motion_sets[key] = (mg, n_cand)
        return mg, n_cand, True

    def reject_carry(self, segment: Segment, grasp: int) -> bool:
        """Take ``grasp`` out of ``segment``'s cached G_m: a judge downstream of this tier
        (the plan's validation with the motion's contact modes and force limit, or the
        physics simulation) found that carrying it along the segment does not execute.
        Returns whether it was there (the next :meth:`plan` of the path avoids it)."""
        key = _motion_key(segment)
        hit = self._motion_sets.get(key)
        if hit is None:
            return False
        return self._drop(key, hit[0].indices == grasp) > 0

    def raise_press(self, segment: Segment, grasp: int) -> float | None:
        """Give ``grasp`` the next press of :data:`geometry.grasps.PRESS_LADDER` above the
        one it carries ``segment`` with in the cached G_m, when a judge downstream (the
        physics simulation: a press of 2 W against a stiff wall is a 0.2 mm guarded move,
        which the object's first lag undoes) refused the step: the higher press must pass
        every test of :func:`geometry.grasps.press_forces` along the segment, as the first
        did. Returns the new press (N), or ``None`` (no press, none higher that makes the
        motion: the caller rejects the grasp instead)."""
        key = _motion_key(segment)
        hit = self._motion_sets.get(key)
        if hit is None:
            return None
        mg, n_cand = hit
        now = mg.press_of(grasp)
        if now is None or mg.press is None:
            return None
        weight = self.world.object.weight
        higher = tuple(f for f in PRESS_LADDER if f * weight > now * (1.0 + 1e-9))
        if not higher:
            return None
        force = float(press_forces(self.world, self.grasps, segment.poses, np.array([grasp]), ladder=higher)[0])
        if not np.isfinite(force):
            return None
        press = np.array(mg.press, dtype=float)
        press[np.flatnonzero(mg.indices == grasp)[0]] = force
        press.setflags(write=False)
        self._motion_sets[key] = (replace(mg, press=press), n_cand)
        return force

    def reject_adjust(self, result: GraspPlanResult, step: int) -> bool:
        """Mark the AdjustGrasp edge that plan step ``step`` of ``result`` takes as
        infeasible: a judge downstream of this tier (the plan's validation, the forward
        problem, the physics simulation) found that its motion does not execute. Returns
        whether it was marked (False for a MoveObject step or an edge already known
        infeasible); the next :meth:`plan` of the path avoids it (the layer's candidate
        edges, with what is known of them, are cached per pose). A refused ``pivot``
        marks the pivots like it too: the same finger, the same way round, a contact
        within :data:`PIVOT_REFUSAL_RADIUS`."""
        taken = result.adjust_edges[step] if 0 <= step < len(result.adjust_edges) else None
        if taken is None:
            return False
        cands, i = taken
        if cands.valid[i] < 0:
            return False
        cands.valid[i] = -1
        e = cands.edges
        if e.primitive == "pivot":
            # The judge refuses a turn of the gripper about finger k when the object may
            # follow that finger instead of staying (its surface sticks) or move otherwise.
            # Turning the same way about the same finger on nearly the same contact pushes
            # the object alike: those go too (one refusal each would spend the judge's
            # retries on near-copies of this one).
            gs = self.grasps
            k = int(e.finger[i])
            here = gs.contact[e.src, k]
            off = np.nan_to_num(here - gs.contact[e.src[i], k], nan=np.inf)
            near = np.linalg.norm(off, axis=1) <= PIVOT_REFUSAL_RADIUS
            alike = (e.finger == k) & (np.sign(e.sense) == np.sign(e.sense[i])) & near
            log.debug("the judge's refusal of pivot %d -> %d takes %d like it", e.src[i], e.dst[i], int(alike.sum()))
            cands.valid[alike] = -1
        return True

    def _drop(self, key: tuple[str, bytes], out: BoolArray) -> int:
        """Move the grasps of the cached G_m under ``key`` marked in ``out`` (aligned with
        its indices) to its rejected ones (at sample 0); returns how many."""
        mg, n_cand = self._motion_sets[key]
        if not out.any():
            return 0
        keep = ~out
        rejected = np.concatenate([mg.rejected, mg.indices[out]])
        at = np.concatenate([mg.rejected_at, np.zeros(int(out.sum()), dtype=np.int64)])
        order = np.argsort(rejected, kind="stable")
        self._motion_sets[key] = (replace(mg.take(keep), rejected=rejected[order], rejected_at=at[order]), n_cand)
        return int(out.sum())

    def bound_forces(self, segment: Segment) -> int:
        """Take out of ``segment``'s cached G_m every grasp that cannot carry the object
        along it within the gripper's ``max_force`` (:func:`geometry.grasps.within_force_limit`):
        a plan carrying one of them broke the force limit (plan rule 9), and G_m bounds no
        force. Once per segment; returns how many grasps left (0 without a limit)."""
        max_force = getattr(self.world.gripper, "max_force", None)
        key = _motion_key(segment)
        hit = self._motion_sets.get(key)
        if max_force is None or hit is None or key in self._force_bounded:
            return 0
        self._force_bounded.add(key)
        mg = hit[0]
        ok = within_force_limit(self.world, self.grasps, segment.poses, mg.indices, max_force, self.options.motion)
        removed = self._drop(key, ~ok)
        if removed:
            log.info("force limit: %d of %d grasps of G_m need more than %g N along segment %s", removed,
                     mg.indices.size, max_force, _describe(segment))
        return removed

    def _motion_inputs(self, segment: Segment) -> tuple[IntArray, int, IntArray, IntArray, tuple[int, ...]]:
        """What :func:`motion_conditioned` is given for ``segment``: the candidates
        left to check, how many G_T gives, the grasps verified on the parent, the samples
        to check those at, the samples known collision-free."""
        # G_T arrays are sorted and unique (pose_conditioned), and so are G_m's lists
        cand = np.intersect1d(self.pose_grasps(segment.poses[0]), self.pose_grasps(segment.poses[-1]),
                              assume_unique=True)
        n_cand = cand.size
        verified, recheck = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        parent, span = segment.parent, segment.span
        parent_hit = None if parent is None else self._motion_sets.get(_motion_key(parent))
        known = None if parent_hit is None else parent_hit[0]
        if known is not None and parent is not None and span is not None:
            lo, hi = span
            last = parent.poses.shape[0] - 1
            verified = np.intersect1d(known.indices, cand, assume_unique=True)
            if hi < last:  # a first half: its last sample's modes differ from the parent's
                recheck = np.array([hi - lo])
            inside = (known.rejected_at >= lo) & (known.rejected_at <= hi) & ~((known.rejected_at == hi) & (hi < last))
            cand = np.setdiff1d(cand, known.rejected[inside], assume_unique=True)
        # The candidates are G_T at both ends: collision-free there if G_T's tolerance is
        # at most G_m's (a smaller tolerance is the stricter rule).
        ends = (0, segment.poses.shape[0] - 1) if self.options.adjust.tol <= self.options.motion.tol else ()
        return cand, n_cand, verified, recheck, ends

    def _motion_ahead(self, segments: Sequence[Segment], k: int) -> tuple[Segment, int] | None:
        """Send the G_m of the first segment after ``k`` that is not cached (and not a
        half of an uncached segment) to the helper; returns it with its candidate count."""
        helper = self._helper_process()
        if helper is None:
            return None
        for seg in segments[k + 1:]:
            if _motion_key(seg) in self._motion_sets:
                continue
            if seg.parent is not None and _motion_key(seg.parent) not in self._motion_sets:
                return None  # its inputs depend on a G_m not computed yet
            cand, n_cand, verified, recheck, ends = self._motion_inputs(seg)
            helper.submit(_helper_motion, np.asarray(seg.poses), cand, verified, recheck, ends)
            return seg, n_cand
        return None

    def _rate_meanwhile(self, segments: Sequence[Segment]) -> list[tuple[tuple[str, bytes], MotionGrasps]]:
        """Send the rating of the path's unrated G_m (:func:`rate_motion_grasps`) to an idle
        helper, which rates them while this process makes the candidate edges; returns
        what was sent (nothing without an idle helper or an unrated set): :meth:`_rated`
        takes the answer. A path that turns out to have no optimistic path does not need
        the quality, and the helper's time went in vain."""
        todo: dict[tuple[str, bytes], tuple[FloatArray, MotionGrasps]] = {}
        for seg in segments:
            key = _motion_key(seg)
            hit = self._motion_sets.get(key)
            if hit is not None and not hit[0].rated and len(hit[0]):
                todo[key] = (np.asarray(seg.poses), hit[0])
        helper = self._helper_process() if todo else None
        if helper is None or not helper.idle:
            return []
        helper.submit(_helper_rate, list(todo.values()))
        return [(key, mg) for key, (_, mg) in todo.items()]

    def _rated(self, sent: list[tuple[tuple[str, bytes], MotionGrasps]]) -> None:
        """Take the helper's ratings of :meth:`_rate_meanwhile` into the cache (where the
        set is still the one sent: the same values :func:`rate_motion_grasps` gives
        here)."""
        assert self._helper is not None
        for (key, mg), rated in zip(sent, self._helper.result()):
            hit = self._motion_sets.get(key)
            if hit is not None and hit[0] is mg:
                self._motion_sets[key] = (rated, hit[1])

    def _layers_meanwhile(self, ctx: AdjustContext, layers: Sequence[_Layer]) -> list[int]:
        """Send the layers after the first whose intra-pose ends (:attr:`_Layer.intra`, the
        :meth:`AdjustContext.holds` of G_T) are not decided yet and whose candidates are
        not cached to an idle helper, which decides them (with each pose's
        :class:`LayerData`) while this process makes layer 0's candidates; returns those
        layers' indices (none without an idle helper or such a layer): :meth:`_layers_taken`
        takes the answer."""
        todo = [k for k, layer in enumerate(layers) if k > 0
                and not all((layer.key, prim.name, False) in self._cands for prim in self.primitives)
                and not ctx.holds_known(layer.pose, layer.members)]
        helper = self._helper_process() if todo else None
        if helper is None or not helper.idle:
            return []
        helper.submit(_helper_layers, [(layers[k].pose, layers[k].members) for k in todo])
        return todo

    def _layers_taken(self, ctx: AdjustContext, layers: Sequence[_Layer], sent: list[int]) -> None:
        """Take the helper's answer to :meth:`_layers_meanwhile` (about ``layers[k]`` for
        each ``k`` of ``sent``) into the context's caches (the same values
        :meth:`AdjustContext.holds` and :meth:`AdjustContext.layer` give here: every
        instance is decided by the same operations)."""
        assert self._helper is not None
        for k, (data, held) in zip(sent, self._helper.result()):
            ctx.take_holds(data, layers[k].members, held)

    def _meanwhile(self, segments: Sequence[Segment], busy: Segment) -> int:
        """While the helper's G_m (of segment ``busy``) has not come back, the G_m of the
        next uncached segments after it (not halves of uncached segments), here, one at
        a time: main would otherwise wait. Returns the instances they decided. Work for a
        path that fails before them is spent in vain, as the helper's is; their G_m stay
        cached for the path's next plan."""
        helper = self._helper
        checks = 0
        after = False
        for seg in segments:
            if seg is busy:
                after = True
                continue
            if not after or _motion_key(seg) in self._motion_sets:
                continue
            if seg.parent is not None and _motion_key(seg.parent) not in self._motion_sets:
                break  # its inputs depend on a G_m not computed yet
            if helper is None or helper.answered():
                break
            mg, _, fresh = self.motion_grasps(seg, rate=False)
            checks += mg.checks if fresh else 0
        return checks

    # ---- the solve ---------------------------------------------------------------------

    def plan(self, path: PosePath, *, deadline: float | None = None) -> GraspPlanResult:
        """Find the cheapest grasp sequence along ``path`` (see the module docstring).

        Parameters
        ----------
        path : PosePath
        deadline : float or None
            A :func:`time.perf_counter` value; checked before each G_m and each search
            round. ``None``: no limit.

        Returns
        -------
        GraspPlanResult
            SOLVED with the plan's steps, or NO_GRASP_FOR_SEGMENT / NO_PATH with the
            failing segment and a reason. Never raises for an infeasible path.

        Raises
        ------
        TimeBudgetExceeded
            When ``deadline`` has passed.
        """
        t_start = time.perf_counter()
        timings: dict[str, float] = {}
        segments = path.segments
        if not segments:
            return GraspPlanResult(GraspPlanStatus.NO_PATH, reason="the pose path has no segment",
                                   time_s=time.perf_counter() - t_start)
        n = len(segments)
        self._prepare(np.asarray(segments[0].poses[0], dtype=float))
        gs = self.grasps
        ctx = self.context
        size = len(gs)

        # G_T per layer.
        t0 = time.perf_counter()
        poses = [np.asarray(s.poses[0], dtype=float) for s in segments] + [np.asarray(segments[-1].poses[-1], dtype=float)]
        states = [s.from_state.name for s in segments] + [segments[-1].to_state.name]
        self._pose_sets_paired(poses)
        layers = []
        for k, p in enumerate(poses):
            members = np.zeros(size, dtype=bool)
            members[self.pose_grasps(p)] = True
            if k == 0:
                members[self._start_index] = True
            layers.append(_Layer(k, p, p.tobytes(), members, int(members.sum()), states[k],
                                 functools.partial(ctx.holds, p, members)))
        timings["pose_sets"] = time.perf_counter() - t0

        # G_m per segment, in order; stop at the first empty one.
        t0 = time.perf_counter()
        inter: list[FloatArray] = []
        checks = 0
        motion_sizes = []
        for k, seg in enumerate(segments):
            budget.check(deadline, "the bottom tier, computing the grasp sets G_m")
            ahead = None if _motion_key(seg) in self._motion_sets else self._motion_ahead(segments, k)
            try:
                mg, n_cand, fresh = self.motion_grasps(seg, rate=False)
                if ahead is not None:  # while the helper's is not back, the ones after it here
                    checks += self._meanwhile(segments, ahead[0])
            finally:
                if ahead is not None:  # the helper's G_m, computed meanwhile
                    assert self._helper is not None
                    other = self._helper.result()
                    self._motion_sets[_motion_key(ahead[0])] = (other, ahead[1])
                    checks += other.checks
            if fresh:
                checks += mg.checks
            motion_sizes.append(len(mg))
            if not len(mg):
                timings["motion_sets"] = time.perf_counter() - t0
                reason = (f"no grasp can execute segment {k} ({_describe(seg)}): none of the {n_cand} grasps "
                          f"collision-free at both ends (of {layers[k].size} at T_{k}) is collision-free and "
                          f"quasi-statically feasible at all {seg.poses.shape[0]} samples and able to start the "
                          f"motion"
                          + (" (check budget ran out)" if mg.truncated else ""))
                return GraspPlanResult(GraspPlanStatus.NO_GRASP_FOR_SEGMENT, failing_segment=k, reason=reason,
                                       candidates=n_cand,
                                       nodes=sum(layer.size for layer in layers), edges=sum(motion_sizes),
                                       feasibility_checks=checks, time_s=time.perf_counter() - t_start,
                                       layer_sizes=tuple(layer.size for layer in layers),
                                       motion_sizes=tuple(motion_sizes), timings=timings)
            cost = np.full(size, np.inf)
            cost[mg.indices] = 0.0  # the quality S_g(m_k) once a path is known to exist
            inter.append(cost)
        timings["motion_sets"] = time.perf_counter() - t0

        # Whether any optimistic path reaches the goal at all (costs do not matter for
        # that), layer by layer with each layer's candidate intra-pose edges: an
        # infeasible path pays neither for the grasps' quality nor for the candidates of
        # the layers after the one where forward reachability dies.
        search = _Search()
        cands: list[list[_Cands]] = [[] for _ in layers]
        lg: list[_LayerGraph] = [_LayerGraph.of((), size) for _ in layers]
        opt = _Optimistic(layers, inter, lg, self._start_index, self.goal_release, self.options.max_intra_depth)
        reach = [np.full(size, np.inf) for _ in layers]
        t_cand = t_reach = 0.0
        # The helper decides the later layers' intra-pose ends while this process makes
        # layer 0's candidates, then rates the grasps' quality while it makes the rest.
        ahead = self._layers_meanwhile(ctx, layers)
        rating = [] if ahead else self._rate_meanwhile(segments)
        try:
            for k, layer in enumerate(layers):
                budget.check(deadline, "the bottom tier, making the candidate AdjustGrasp edges")
                if ahead and k == ahead[0]:
                    self._layers_taken(ctx, layers, ahead)
                    ahead = []
                    rating = self._rate_meanwhile(segments)
                t0 = time.perf_counter()
                cands[k] = [self._candidates(ctx, layer, prim, search) for prim in self.primitives]
                lg[k] = self._layer_graph(cands[k], size)
                t1 = time.perf_counter()
                opt.refresh([k])
                reach[k] = opt.forward(k, k)[k][-1]
                t_reach += time.perf_counter() - t1
                t_cand += t1 - t0
                if not np.isfinite(reach[k]).any():
                    break
        except BaseException:
            if rating or ahead:
                self.close()  # its answer is not wanted (the next use forks another helper)
            raise
        if ahead:  # the layers' forward reachability died before them: taken for the cache
            self._layers_taken(ctx, layers, ahead)
        if rating:
            self._rated(rating)
        timings["candidates"] = t_cand
        t0 = time.perf_counter() - t_reach
        last = reach[-1]
        if (last[NO_CONTACT] if self.goal_release else last[layers[-1].members].min(initial=np.inf)) < np.inf:
            t1 = time.perf_counter()
            for k, seg in enumerate(segments):
                budget.check(deadline, "the bottom tier, rating the grasp sets G_m")
                mg = self.motion_grasps(seg)[0]
                inter[k][mg.indices] = mg.quality  # opt sees it: the same arrays
            timings["motion_sets"] += time.perf_counter() - t1
            t0 += time.perf_counter() - t1
            node_path, edge_path, reach, exhausted = self._search(ctx, layers, inter, cands, search, deadline, opt)
        else:
            search.rounds += 1
            node_path, edge_path, exhausted = None, [], False
        if node_path is None and not exhausted:
            # The reachability above is optimistic: it may run on through unchecked edges
            # that fail once checked, and the segment it dies at is what the top tier
            # bisects or forbids. Decide the last layer a feasible path arrives at.
            reach, exhausted = self._decided_reach(ctx, layers, inter, cands, search, deadline, reach)
        timings["search"] = time.perf_counter() - t0
        checks += search.checks
        nodes = sum(layer.size for layer in layers)
        edges = int(sum(np.isfinite(c).sum() for c in inter)) + search.proposed
        per: dict[str, Counter] = {p.name: Counter() for p in self.primitives}
        for (_, name), st in search.stats.items():
            per[name].update({("candidates" if key == "proposed" else key): v for key, v in st.items()})
        common = dict(nodes=nodes, edges=edges, layer_sizes=tuple(layer.size for layer in layers),
                      motion_sizes=tuple(motion_sizes), search_rounds=search.rounds, intra_proposed=search.proposed,
                      intra_checked=search.checked, intra_feasible=search.feasible,
                      by_primitive={name: dict(c) for name, c in per.items()})
        if node_path is None:
            reached = [int(np.isfinite(r).sum()) for r in reach]
            k = max((i for i, c in enumerate(reached) if c), default=0)
            if exhausted:
                # Nothing is decided: optimistic reachability counts the unchecked edges as
                # feasible and may run on to the goal. The layer the search spent most of its
                # checks at is where its cheap paths kept failing: blame the segment after it.
                spent = _checks_by_layer(search)
                if spent:
                    k = max(spent, key=lambda j: (spent[j], j))
            failing = k if k < n else n - 1
            reason = self._failure_reason(segments, layers, inter, reached, k, search, exhausted)
            log.info("grasp graph: no path (%s)", reason)
            return GraspPlanResult(GraspPlanStatus.NO_PATH, failing_segment=failing, reason=reason,
                                   at_goal=k >= n, feasibility_checks=checks, time_s=time.perf_counter() - t_start,
                                   timings=timings, **common)

        # Steps.
        t0 = time.perf_counter()
        steps, carried, taken = self._steps(ctx, segments, layers, cands, node_path, edge_path)
        timings["steps"] = time.perf_counter() - t0
        log.info("grasp graph: %d nodes, %d edges, %d intra-pose edges checked (%d feasible), %d steps",
                 nodes, edges, search.checked, search.feasible, len(steps))
        return GraspPlanResult(GraspPlanStatus.SOLVED, steps=tuple(steps), grasps=tuple(carried), cost=search.cost,
                               feasibility_checks=checks, time_s=time.perf_counter() - t_start,
                               node_path=tuple(node_path), timings=timings, adjust_edges=tuple(taken), **common)

    # ---- candidate edges ---------------------------------------------------------------

    def _candidates(self, ctx: AdjustContext, layer: _Layer, prim: _Prim, search: _Search) -> _Cands:
        """The candidate edges of ``prim`` among the layer's intra-pose grasps (cached
        per pose, with what was learnt of their feasibility)."""
        key = (layer.key, prim.name, layer.index == 0)
        hit = self._cands.get(key)
        if hit is None:
            pose = Pose.from_array(layer.pose)
            rows = np.flatnonzero(layer.intra)
            if prim.lazy:
                edges = prim.impl.propose(ctx, pose, rows, layer.intra)
                valid = np.zeros(len(edges), dtype=np.int8)
            else:
                edges = prim.impl.intra_edges(ctx, pose, rows)
                search.checks += int(getattr(edges, "feasibility_checks", 0))
                valid = np.ones(len(edges), dtype=np.int8)
            src = np.asarray(edges.src)
            if (src[1:] < src[:-1]).any():  # (most proposals come sorted: then they are kept as they are)
                edges = edges.take(_csr(src, len(ctx.grasps))[0])
            hit = _Cands(edges, np.asarray(edges.cost(self.options.adjust), dtype=float), valid)
            self._cands[key] = hit
            while len(self._cands) > max(1, self.options.cache_poses) * max(1, len(self.primitives)):
                self._cands.popitem(last=False)
        else:
            self._cands.move_to_end(key)
        search.proposed += len(hit.edges)
        search.stats[(layer.index, prim.name)]["proposed"] += len(hit.edges)
        return hit

    # ---- the lazy shortest-path search -------------------------------------------------

    def _search(self, ctx: AdjustContext, layers: list[_Layer], inter: list[FloatArray], cands: list[list[_Cands]],
                search: _Search, deadline: float | None = None, opt: "_Optimistic | None" = None,
                release: bool | None = None
                ) -> tuple[list[tuple[int, int]] | None, list[Any], list[FloatArray], bool]:
        """LazySP over the layered graph (see :class:`_Optimistic`): returns (the node path
        or None, its edges, the optimistic cost-to-come per layer -- unchecked edges
        counted as feasible --, whether the check budget ran out). ``release``: the goal
        is {0, 0} at the last layer (default ``goal_release``), else any of its grasps."""
        opts = self.options
        release = self.goal_release if release is None else release
        lg = [self._layer_graph(c, len(ctx.grasps)) for c in cands]
        starts = np.atleast_1d(self._start_index)
        exhausted = False
        fresh = opt is None  # else: its edge validity is current, its costs are not
        if opt is None:
            opt = _Optimistic(layers, inter, lg, self._start_index, release, opts.max_intra_depth)
        dirty: set[int] = set(range(len(layers)))
        while True:
            search.rounds += 1
            budget.check(deadline, "the bottom tier's grasp-graph search")
            fwd, bwd = opt.update(dirty) if fresh else opt.recompute(0, len(layers) - 1)
            fresh = True
            # the cheapest start (one, unless start_grasp = "any")
            start = int(starts[np.argmin(bwd[0][-1][starts])])
            best = float(bwd[0][-1][start])
            if not math.isfinite(best):
                return None, [], [f[-1] for f in fwd], False
            nodes, edges = _extract(layers, inter, lg, bwd, start, release)
            unknown = [e for e in edges if e is not None and lg[e[0]].valid(e[1], e[2]) == 0]
            if not unknown:
                search.cost = best
                return nodes, edges, [f[-1] for f in fwd], False
            if search.checked >= opts.max_edge_checks:
                exhausted = True
                break
            # LazySP's "reverse" selector, by layer: the unchecked edges of the cheapest
            # path in its last layer that has any, with that layer's near-optimal ones.
            # Failures cluster where the path meets the goal side (the layer whose
            # grasps cannot carry on), so an infeasible path is refuted in few checks.
            top = max(e[0] for e in unknown)
            picks = _select(lg, fwd, bwd, best, opts.slack, opts.batch, [e for e in unknown if e[0] == top], layer=top)
            self._check(ctx, layers, cands, picks, search)
            dirty = {k for k, _ in picks}
        return None, [], [f[-1] for f in fwd], exhausted

    def _decided_reach(self, ctx: AdjustContext, layers: list[_Layer], inter: list[FloatArray],
                       cands: list[list[_Cands]], search: _Search, deadline: float | None,
                       reach: list[FloatArray]) -> tuple[list[FloatArray], bool]:
        """After a search that found no path: the optimistic cost-to-come per layer again,
        once the last layer that a path of *feasible* edges arrives at is decided.

        ``reach`` counts unchecked edges as feasible, so the layer where it dies may lie
        beyond every layer a feasible path gets to (the search refutes cheap paths where
        they meet the goal side, and stops when none is left, leaving the edges that
        carried them there unchecked). From the last layer ``reach`` gets to down to layer
        1, each is made the goal (any grasp arriving there) of a LazySP search on the
        path's first layers, until one is reached. The searches record what they check,
        so the recomputed cost-to-come arrives at that layer and, as the search of the
        layer after it ended without an optimistic path, at none after it. Returns it and
        whether the check budget ran out (then ``reach`` is returned as it was).
        """
        last = max((i for i, r in enumerate(reach) if np.isfinite(r).any()), default=0)
        for j in range(last, 0, -1):
            found, _, _, exhausted = self._search(ctx, layers[:j + 1], inter[:j], cands[:j + 1], search, deadline,
                                                  release=False)
            if exhausted:
                return reach, True
            if found is not None:
                break
        lg = [self._layer_graph(c, len(ctx.grasps)) for c in cands]
        opt = _Optimistic(layers, inter, lg, self._start_index, self.goal_release, self.options.max_intra_depth)
        opt.refresh(range(len(layers)))
        return [f[-1] for f in opt.forward(0)], False

    def _layer_graph(self, cands: Sequence[_Cands], size: int) -> _LayerGraph:
        """The :class:`_LayerGraph` of one layer's candidates (cached while they are:
        what is learnt of their feasibility lives in the candidates' ``valid``)."""
        key = tuple(cands)
        hit = self._layer_graphs.get(key)
        if hit is None:
            hit = self._layer_graphs[key] = _LayerGraph.of(key, size)
            while len(self._layer_graphs) > max(1, self.options.cache_poses):
                self._layer_graphs.popitem(last=False)
        else:
            self._layer_graphs.move_to_end(key)
        return hit

    def _check(self, ctx: AdjustContext, layers: list[_Layer], cands: list[list[_Cands]],
               picks: dict[tuple[int, int], IntArray], search: _Search) -> None:
        """Check the picked candidate edges, one vectorised call per layer and primitive,
        and record the outcome in the candidates' ``valid`` arrays."""
        helper = self.live_helper()
        for (k, pi), idx in picks.items():
            prim = self.primitives[pi]
            cd = cands[k][pi]
            pose = Pose.from_array(layers[k].pose)
            if helper is not None and idx.size >= 2 * _MIN_SHARED_CHECKS:
                # half of the edges checked in the helper process meanwhile, the same way
                half = idx.size // 2
                helper.submit(_helper_check, prim.name, layers[k].pose, cd.edges.take(idx[half:]))
                try:
                    mine = prim.impl.check(ctx, pose, cd.edges.take(idx[:half]))
                finally:
                    theirs = helper.result()
                res = CheckResult(np.concatenate([mine.ok, theirs.ok]), np.concatenate([mine.failure, theirs.failure]),
                                  mine.feasibility_checks + theirs.feasibility_checks, mine.samples + theirs.samples)
            else:
                res = prim.impl.check(ctx, pose, cd.edges.take(idx))
            cd.valid[idx] = np.where(res.ok, 1, -1)
            search.checked += idx.size
            search.checks += res.feasibility_checks
            n_ok = int(np.count_nonzero(res.ok))
            search.feasible += n_ok
            st = search.stats[(k, prim.name)]
            st["checked"] += idx.size
            st["feasible"] += n_ok
            for code, count in Counter(res.failure[~res.ok].tolist()).items():
                st[CheckFailure(code).name.lower()] += count

    # ---- results -----------------------------------------------------------------------

    def _steps(self, ctx: AdjustContext, segments: Sequence[Segment], layers: list[_Layer], cands: list[list[_Cands]],
               node_path: list[tuple[int, int]], edge_path: list[Any]
               ) -> tuple[list[Step], list[int], list[tuple[_Cands, int] | None]]:
        steps: list[Step] = []
        carried: list[int] = []
        taken: list[tuple[_Cands, int] | None] = []
        for (k0, g0), (k1, _), payload in zip(node_path, node_path[1:], edge_path):
            if payload is None:
                carried.append(g0)
                steps.append(self._move_step(ctx, segments[k0], g0))
                taken.append(None)
                continue
            k, pi, i = payload
            taken.append((cands[k][pi], int(i)))
            prim = self.primitives[pi]
            edges = cands[k][pi].edges.take([i])
            pose = Pose.from_array(layers[k].pose)
            if prim.lazy:
                wps = prim.impl.waypoints(ctx, pose, edges, 0)
            else:
                wps = motion_waypoints(ctx, pose, edges.motion, 0)
            params_of = getattr(prim.impl, "parameters", None)
            params = params_of(ctx, edges, 0) if params_of is not None else {
                "from_grasp": int(edges.src[0]), "to_grasp": int(edges.dst[0])}
            state = layers[k].state
            steps.append(Step(prim.name, Family.ADJUST_GRASP, params, (state, state), wps))
        carried.append(node_path[-1][1])
        return steps, carried, taken

    def _move_step(self, ctx: AdjustContext, seg: Segment, g: int, press: float | None = None) -> Step:
        """The MoveObject step of ``seg`` carrying grasp ``g``: the segment's dense poses
        (refined where a finger would move more than the waypoint step), gripper T * g,
        the grasp's contacts in the world."""
        gs = ctx.grasps
        poses = _dense_for_gripper(ctx, seg, g)
        grip = compose_batch(poses, gs.gripper[g][None])
        touch = gs.touching[g]
        contact = np.nan_to_num(gs.contact[g])
        wps = []
        for j in range(poses.shape[0]):
            obj = Pose(float(poses[j, 0]), float(poses[j, 1]), float(poses[j, 2]))
            pts = obj.apply(contact)
            fc = tuple((float(pts[m, 0]), float(pts[m, 1])) if touch[m] else None for m in range(2))
            wps.append(Waypoint(obj, Pose(float(grip[j, 0]), float(grip[j, 1]), float(grip[j, 2])),
                                float(gs.width[g]), fc))  # type: ignore[arg-type]
        params = dict(seg.parameters)
        hit = self._motion_sets.get(_motion_key(seg)) if press is None else None
        force = press if press is not None else (None if hit is None else hit[0].press_of(g))
        if force is not None:  # the executor presses the one finger first (G_m found it needs it)
            params[PRESS_KEY] = Press(int(np.argmax(touch)), force).as_dict()
        return Step(seg.primitive, Family.MOVE_OBJECT, params,
                    (seg.from_state.name, seg.to_state.name), tuple(wps))

    def _failure_reason(self, segments: Sequence[Segment], layers: list[_Layer], inter: list[FloatArray],
                        reached: list[int], k: int, search: _Search, exhausted: bool) -> str:
        n = len(segments)
        layer = layers[k]
        if exhausted:
            spent = _checks_by_layer(search)
            where = (f"undecided: the budget of {self.options.max_edge_checks} intra-pose edge checks ran out "
                     f"({search.checked} checked, {spent.get(k, 0)} of them at T_{k}) before a grasp sequence of "
                     f"checked edges got past T_{k}")
            if k < n:
                need = (f"the search was looking there for a way from the grasps that arrive to one of the "
                        f"{int(np.isfinite(inter[k]).sum())} grasps that execute segment {k} ({_describe(segments[k])}) "
                        f"within {self.options.max_intra_depth} AdjustGrasp edges")
            else:
                need = f"the search was looking there for a release within {self.options.max_intra_depth} AdjustGrasp edges"
        elif k < n:
            where = f"forward reachability dies at segment {k} ({_describe(segments[k])})"
            need = (f"none of them is, or reaches within {self.options.max_intra_depth} feasible AdjustGrasp edges, "
                    f"one of the {int(np.isfinite(inter[k]).sum())} grasps that can execute it")
        else:
            where = "the goal pose is reached but the gripper cannot release the object there"
            need = f"none of them reaches {{0, 0}} within {self.options.max_intra_depth} feasible AdjustGrasp edges"
        rests = self.context.layer(layer.pose).rests_alone
        parts = []
        for prim in self.primitives:
            st = search.stats.get((k, prim.name), Counter())
            fails = ", ".join(f"{v} {c}" for c, v in sorted(st.items()) if c not in ("proposed", "checked", "feasible"))
            parts.append(f"{prim.name} {st['feasible']} feasible of {st['checked']} checked "
                         f"({st['proposed']} candidates" + (f"; failed: {fails}" if fails else "") + ")")
        msg = (f"no grasp sequence: {where}; {reached[k]} of the {layer.size} grasps at T_{k} are reachable from "
               f"the start (unchecked AdjustGrasp edges counted as feasible), {need}; {int(layer.intra.sum())} grasps hold the object still at T_{k}; the object "
               f"{'rests' if rests else 'does not rest'} on the environment alone there; AdjustGrasp edges at "
               f"T_{k}: " + ("; ".join(parts) if parts else "none (the domain declares no AdjustGrasp primitive)"))
        return msg


def _checks_by_layer(search: _Search) -> Counter:
    """How many intra-pose edges the search checked at each layer."""
    spent: Counter = Counter()
    for (layer, _), st in search.stats.items():
        if st.get("checked"):
            spent[layer] += st["checked"]
    return spent


_csr = csr  # the stable order of keys and their runs' starts (:func:`ldhp_tamp.kernels.csr`)


@dataclass(frozen=True, eq=False)
class _LayerGraph:
    """The candidate intra-pose edges of one layer, all primitives', in one order: by
    source (stable, so a source's edges keep the candidates' order), the form the
    Bellman-Ford rounds and the path extraction read. An edge's *index* is its place in
    the primitives' candidates concatenated (``offsets`` says where each primitive's
    begin); its *position* is its place in the source order."""

    cands: tuple[_Cands, ...]
    size: int
    offsets: IntArray  # (P + 1,) where each primitive's candidates begin among the indices
    order: IntArray  # (E,) int32: the index of the edge at each position
    starts: IntArray  # (size + 1,) int32: where each grasp's edges (as source) begin
    dst: IntArray  # (E,) int32, by position
    cost: FloatArray  # (E,), by position
    keys: IntArray  # int32: the sources that have edges
    heads: IntArray  # int32: where their edges begin

    @staticmethod
    def of(cands: Sequence[_Cands], size: int) -> "_LayerGraph":
        counts = [len(c.edges) for c in cands]
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        if not sum(counts):
            none = np.zeros(0, dtype=np.int32)
            return _LayerGraph(tuple(cands), size, offsets, none, np.zeros(size + 1, dtype=np.int32), none,
                               np.zeros(0), none, none)
        order, starts, dst, cost = by_source([c.edges.src for c in cands], [c.edges.dst for c in cands],
                                             [c.cost for c in cands], size, _search)
        keys = np.flatnonzero(np.diff(starts)).astype(np.int32)
        return _LayerGraph(tuple(cands), size, offsets, order, starts, dst, cost, keys, starts[keys])

    def valid_all(self) -> NDArray[np.int8]:
        """(E,) by index: 0 unknown, 1 feasible, -1 infeasible (current knowledge)."""
        if not self.cands:
            return np.zeros(0, dtype=np.int8)
        return np.concatenate([c.valid for c in self.cands])

    def valid(self, prim: int, index: int) -> int:
        return int(self.cands[prim].valid[index])

    def edges(self, index: IntArray) -> tuple[IntArray, IntArray]:
        """(primitive, candidate) of each edge of the indices ``index``."""
        index = np.asarray(index, dtype=np.int64)
        prim = np.searchsorted(self.offsets, index, side="right") - 1
        return prim, index - self.offsets[prim]

    @functools.cached_property
    def src(self) -> IntArray:
        """(E,) int32, by position: each edge's source."""
        return np.repeat(np.arange(self.size, dtype=np.int32), np.diff(self.starts))

    @functools.cached_property
    def by_dst(self) -> tuple[IntArray, IntArray, FloatArray, IntArray, IntArray]:
        """numpy's forward rounds (without the compiled module) group the edges by
        destination: (the positions in that order, their sources, their costs, the
        destinations that have edges, where they begin)."""
        order, starts = _csr(self.dst, self.size)
        keys = np.flatnonzero(np.diff(starts))
        return order, self.src[order], self.cost[order], keys, starts[keys]


def _departure_costs(layers: list[_Layer], inter: list[FloatArray], release: bool, k: int,
                     next_cost: FloatArray | None) -> FloatArray:
    """Cost of leaving layer k from each grasp: S_k(g) + cost-to-go at k + 1, or 0 at the
    goal nodes of the last layer."""
    n = len(inter)
    if k == n:
        out = np.full(layers[k].members.shape[0], np.inf)
        if release:
            out[NO_CONTACT] = 0.0
        else:
            out[layers[k].members] = 0.0
        return out
    assert next_cost is not None
    return np.where(layers[k].members, inter[k] + next_cost, np.inf)


class _Optimistic:
    """Optimistic cost-to-come and cost-to-go over the layered candidate graph: every
    intra-pose candidate edge not known to be infeasible counts, with its exact cost.

    Within layer k, at most ``rounds`` AdjustGrasp edges in a row (Bellman-Ford rounds,
    each a vectorised min-reduction over the layer's edges). ``bwd[k][r][g]``: the
    cheapest cost from (k, g) to a goal node with at most r AdjustGrasp edges before
    leaving layer k; ``fwd[k][r][g]``: the cheapest cost from the start to (k, g) with
    at most r AdjustGrasp edges since arriving at layer k. The cost of the cheapest path
    is ``bwd[0][rounds][start]``; it is a lower bound of every feasible path's cost, and
    equals it when the path's edges turn out feasible (LazySP).

    :meth:`update` recomputes after edges of some layers were checked: ``bwd`` of the
    layers after the last of them and ``fwd`` of the layers before the first are kept.
    """

    def __init__(self, layers: list[_Layer], inter: list[FloatArray], lg: list[_LayerGraph], start: int,
                 release: bool, rounds: int) -> None:
        self.layers, self.inter, self.lg = layers, inter, lg
        self.release, self.rounds = release, rounds
        n = len(inter)
        self.size = layers[0].members.shape[0]
        self.start = start
        self.valid: list[NDArray[np.int8] | None] = [None] * (n + 1)  # each layer's edges' validity, as read
        self.by_src: list[FloatArray | None] = [None] * (n + 1)  # numpy's edge costs, inf when infeasible
        self.by_dst: list[FloatArray | None] = [None] * (n + 1)
        self.fwd: list[list[FloatArray]] = [[] for _ in range(n + 1)]
        self.bwd: list[list[FloatArray]] = [[] for _ in range(n + 1)]

    def update(self, dirty: set[int]) -> tuple[list[list[FloatArray]], list[list[FloatArray]]]:
        """(fwd, bwd) now; ``dirty``: the layers whose edges' validity changed (all of
        them the first time)."""
        self.refresh(dirty)
        if not dirty:
            return self.fwd, self.bwd
        return self.recompute(min(dirty), max(dirty))

    def refresh(self, dirty: Iterable[int]) -> None:
        """Re-read which edges of layers ``dirty`` are known infeasible."""
        for k in dirty:
            g = self.lg[k]
            self.valid[k] = g.valid_all()
            if _search is None:  # the compiled rounds read ``valid`` edge by edge
                ok = self.valid[k][g.order] >= 0
                self.by_src[k] = np.where(ok, g.cost, np.inf)
                self.by_dst[k] = np.where(ok[g.by_dst[0]], g.by_dst[2], np.inf)

    def _rounds(self, k: int, h0: FloatArray, backward: bool) -> list[FloatArray]:
        """``h0`` and the ``rounds`` Bellman-Ford rounds after it over layer k's edges
        not known infeasible: backward (``backward``: a node's cost-to-go through its
        cheapest edge) or forward (cost-to-come); each round's array is the element-wise
        minimum of the previous one and the round's relaxation. Compiled, both walk the
        edges by source (the forward rounds lower each edge's destination); numpy groups
        them by the end it reduces at."""
        g = self.lg[k]
        if _search is not None:
            out = np.empty((self.rounds, self.size))
            (_search.relax if backward else _search.spread)(g.cost, g.dst, self.valid[k], g.order, g.keys, g.heads,
                                                             h0, out)
            return [h0, *out]
        if backward:
            cost, other, keys, heads = self.by_src[k], g.dst, g.keys, g.heads
        else:
            _, other, _, keys, heads = g.by_dst
            cost = self.by_dst[k]
        h = [h0]
        for _ in range(self.rounds):
            best = np.full(self.size, np.inf)
            if keys.size:
                best[keys] = np.minimum.reduceat(cost + h[-1][other], heads)
            h.append(np.minimum(h[-1], best))
        return h

    def recompute(self, lo: int, hi: int) -> tuple[list[list[FloatArray]], list[list[FloatArray]]]:
        """Recompute ``bwd`` of layers 0..hi and ``fwd`` of layers lo..n."""
        layers, inter = self.layers, self.inter
        n = len(inter)
        bwd = self.bwd
        for k in range(hi, -1, -1):
            bwd[k] = self._rounds(k, _departure_costs(layers, inter, self.release, k, bwd[k + 1][-1] if k < n
                                                      else None), backward=True)
        return self.forward(lo), bwd

    def forward(self, lo: int, hi: int | None = None) -> list[list[FloatArray]]:
        """Recompute ``fwd`` of layers ``lo``..``hi`` (default n; what :meth:`refresh` read
        of them must be current, ``fwd`` of layer ``lo - 1`` too)."""
        layers, inter, size = self.layers, self.inter, self.size
        n = len(inter)
        fwd = self.fwd
        if lo == 0:
            arrive = np.full(size, np.inf)
            arrive[self.start] = 0.0
        else:
            arrive = np.where(layers[lo].members, fwd[lo - 1][-1] + inter[lo - 1], np.inf)
        for k in range(lo, n + 1 if hi is None else hi + 1):
            f = fwd[k] = self._rounds(k, arrive, backward=False)
            if k < n:
                arrive = np.where(layers[k + 1].members, f[-1] + inter[k], np.inf)
        return fwd


def _extract(layers: list[_Layer], inter: list[FloatArray], lg: list[_LayerGraph], bwd: list[list[FloatArray]],
             start: int, release: bool) -> tuple[list[tuple[int, int]], list[Any]]:
    """The cheapest optimistic path from the start, following ``bwd``: its nodes and
    edges (None for an inter-pose edge, (layer, primitive, candidate) for an intra-pose
    one)."""
    n = len(inter)
    rounds = len(bwd[0]) - 1
    k, g, r = 0, start, rounds
    nodes = [(0, start)]
    edges: list[Any] = []
    while True:
        h = bwd[k]
        while r > 0 and h[r - 1][g] <= h[r][g] * (1 + 1e-12) + 1e-12:
            r -= 1
        if r == 0:
            if k == n:
                return nodes, edges
            k += 1
            r = rounds
            nodes.append((k, g))
            edges.append(None)
            continue
        lay = lg[k]
        lo, hi = int(lay.starts[g]), int(lay.starts[g + 1])
        ok = lay.valid_all()[lay.order[lo:hi]] >= 0
        vals = np.where(ok, lay.cost[lo:hi] + h[r - 1][lay.dst[lo:hi]], np.inf)
        at = lo + int(np.argmin(vals))
        g = int(lay.dst[at])
        r -= 1
        nodes.append((k, g))
        prim, cand = lay.edges(lay.order[at])
        edges.append((k, int(prim), int(cand)))


def _select(lg: list[_LayerGraph], fwd: list[list[FloatArray]], bwd: list[list[FloatArray]], best: float,
            slack: float, batch: int, must: list[tuple[int, int, int]], layer: int | None = None
            ) -> dict[tuple[int, int], IntArray]:
    """The unchecked candidate edges to check next: ``must`` (unchecked edges of the
    current cheapest path), then every unchecked edge (of ``layer`` only, when given)
    whose cheapest optimistic path through it costs at most ``best + slack``, cheapest
    first, up to ``batch`` edges; grouped by (layer, primitive)."""
    picked: dict[tuple[int, int], set[int]] = defaultdict(set)
    for k, pi, i in must:
        picked[(k, pi)].add(i)
    count = len(must)
    rows = []
    for k, lay in enumerate(lg):
        if not lay.order.size or (layer is not None and k != layer):
            continue
        if _search is not None:  # one pass over the layer's edges
            sel, f_sel = np.empty(lay.order.size, np.int32), np.empty(lay.order.size)
            n = _search.near_best(lay.valid_all(), lay.order, lay.keys, lay.heads, lay.dst, lay.cost, fwd[k][-1],
                                  bwd[k][-1], best + slack, sel, f_sel)
            sel, f_sel = sel[:n], f_sel[:n]
        else:
            unk = lay.valid_all()[lay.order] == 0
            f = fwd[k][-1][lay.src] + lay.cost + bwd[k][-1][lay.dst]
            sel = np.flatnonzero(unk & (f <= best + slack))
            f_sel = f[sel]
        if sel.size:
            index = lay.order[sel]
            by_index = np.argsort(index)  # the candidates' order, in which ties are broken
            rows.append((f_sel[by_index], np.full(sel.size, k), *lay.edges(index[by_index])))
    if rows:
        f, ks, ps, ix = (np.concatenate(x) for x in zip(*rows))
        for j in np.argsort(f, kind="stable"):
            if count >= batch:
                break
            key = (int(ks[j]), int(ps[j]))
            if int(ix[j]) not in picked[key]:
                picked[key].add(int(ix[j]))
                count += 1
    return {key: np.array(sorted(v), dtype=np.int64) for key, v in picked.items() if v}


def _helper_pose(state: tuple[Any, ...], pose: FloatArray, tol: float) -> IntArray:
    """A G_T computed in the helper process (see :meth:`GraspPlanner._pose_sets_paired`)."""
    world, grasps = state[0], state[1]
    return pose_conditioned(world, grasps, pose, tol)


#: Fewer intra-pose edges than twice this in one check are not shared with the helper.
_MIN_SHARED_CHECKS = 32


def _helper_check(state: tuple[Any, ...], name: str, pose: FloatArray, edges: IntraEdges) -> CheckResult:
    """AdjustGrasp edges checked in the helper process (see :meth:`GraspPlanner._check`),
    with its copy of the primitives' context."""
    return REGISTRY.binding(name).implementation.check(state[3], Pose.from_array(pose), edges)


def _helper_motion(state: tuple[Any, ...], poses: FloatArray, cand: IntArray,
                   verified: IntArray, recheck: IntArray, ends: tuple[int, ...]) -> MotionGrasps:
    """A G_m computed in the helper process (see :meth:`GraspPlanner._motion_ahead`)."""
    world, grasps, options = state[0], state[1], state[2]
    return motion_conditioned(world, grasps, poses, cand, options, verified=verified, recheck=recheck, rate=False,
                              free_at=ends)


def _helper_layers(state: tuple[Any, ...], layers: list[tuple[FloatArray, BoolArray]]
                   ) -> list[tuple[LayerData, BoolArray]]:
    """The helper's intra-pose ends of layers (see :meth:`GraspPlanner._layers_meanwhile`):
    each pose's :class:`LayerData` and which grasps of its G_T hold the object still,
    with its copy of the primitives' context."""
    ctx: AdjustContext = state[3]
    return [(ctx.layer(pose), ctx.holds(pose, members)) for pose, members in layers]


def _helper_rate(state: tuple[Any, ...], sets: list[tuple[FloatArray, MotionGrasps]]) -> list[MotionGrasps]:
    """The helper's ratings of G_m (see :meth:`GraspPlanner._rate_meanwhile`)."""
    world, grasps, options = state[0], state[1], state[2]
    return [rate_motion_grasps(world, grasps, poses, mg, options) for poses, mg in sets]


def _motion_key(seg: Segment) -> tuple[str, bytes]:
    """The cache key of a segment's G_m: its primitive and its dense poses."""
    return seg.primitive, np.asarray(seg.poses).tobytes()


def _describe(seg: Segment) -> str:
    return f"{seg.primitive} {seg.from_state.name} -> {seg.to_state.name}"


def _dense_for_gripper(ctx: AdjustContext, seg: Segment, g: int) -> FloatArray:
    """The segment's poses, with parameter steps subdivided where a finger centre or
    finger vertex of grasp ``g`` would move more than ``options.step``."""
    step = ctx.options.step
    gs = ctx.grasps
    pts = ctx.finger_points(gs.width[g])[0]  # (P, 2) gripper frame
    s = np.asarray(seg.parameter_values, dtype=float)
    poses = np.array(seg.poses, dtype=float)
    for _ in range(8):
        world = transform_points(compose_batch(poses, gs.gripper[g][None]), pts)  # (J+1, P, 2)
        d = np.linalg.norm(np.diff(world, axis=0), axis=-1).max(axis=1)
        m = np.ceil(d / step - 1e-9).astype(np.int64)
        if not (m > 1).any():
            return poses
        new_s = [s[:1]]
        for j in range(s.size - 1):
            new_s.append(np.linspace(s[j], s[j + 1], max(1, int(m[j])) + 1)[1:])
        s2 = np.concatenate(new_s)
        p2 = seg.motion.poses(s2)
        keep = np.isin(s2, s)
        orig = np.searchsorted(s, s2[keep])
        p2[keep] = poses[orig]
        s, poses = s2, p2
    return poses
