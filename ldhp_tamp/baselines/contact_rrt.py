"""``contact-rrt``: a baseline of another planner family, after CMGMP-2D.

Cheng, Huang, Hou, Mason, "Contact Mode Guided Sampling-Based Planning for Quasistatic
Dexterous Manipulation in 2D" (ICRA 2021): an RRT over object poses whose extensions
follow enumerated contact modes between the object and the environment, with the finger
contacts sampled and quasi-static checks deciding. It runs on the same geometric backend
and with the same checks as the LDHP planner (:mod:`ldhp_tamp.tamp`), but with no
primitive library driving the search and no symbolic tier: exactly what LDHP claims to
improve on. ``docs/design/contact_rrt.md`` explains the algorithm.

One extension, from the tree node nearest (``|dp| + r |dtheta|``) to a target pose
(the goal with probability ``goal_bias``, else uniform in the task's workspace box):

1. **Modes.** The object-environment point contacts at the node's pose
   (:func:`geometry.contacts.contact_points`) each take a mode: sticking, sliding either
   way, or separating. Each assignment constrains the object's twist (maintained
   contacts: no normal velocity; sticking: no tangential velocity; separating and sliding:
   the sign of the normal, tangential velocity); :func:`mode_twists` projects the twist
   toward the target onto each mode's null space and keeps the modes whose projection
   obeys their inequalities and is a motion the plan's vocabulary can carry out exactly:
   a rotation about a sticking point (``tip``), a translation keeping sliding contacts
   (``push``), a rotation keeping two sliding contacts on two non-parallel features
   (``biplanar-slide``), and with every contact separating the screw that lands on the
   target (``air-move``).
2. **Step.** The mode's one-parameter motion (:mod:`geometry.kinematics`) is walked
   toward the target at most ``step_mm`` of vertex motion (the parameter closest to the
   target) and swept against the environment (:func:`geometry.kinematics.sweep`): it stops
   where it would penetrate and where the contact state changes (a mode change).
3. **Fingers.** The grasp in hand is kept if it executes the step
   (:func:`geometry.grasps.motion_conditioned`: collision-free, quasi-statically feasible
   at every sample with the environment's modes from the motion, fingers sticking, the
   scenario's friction less ``friction_margin``); otherwise grasps are sampled among those
   the AdjustGrasp motions (pivot, slide, close, open to one finger, flip) reach from it at
   the node's pose with the object held, or, where the object rests alone, among those
   ``approach-contact`` reaches after an ``open`` release; the first sampled grasp that
   executes the step and whose change is feasible (the primitive's own check) is taken.

A node at the goal (within ``goal_tol_mm``; released there by ``open`` under
``goal_release``) ends the search: the path's plan is assembled with the bottom tier's
step builders (:meth:`ldhp_tamp.grasp_graph.GraspPlanner.move_step`, the AdjustGrasp
primitives' waypoints) and judged like LDHP's (plan rules 0-9 with the scenario's own
friction, the forward problem, the simulation with ``simulate``); a refused plan prunes
the subtree below the refused step's edge and the search goes on. Every random draw comes
from ``seed``; the search is bounded by ``max_extensions`` and ``max_nodes`` (work) and
the solve's ``timeout`` (wall time).
"""

from __future__ import annotations

import contextlib
import enum
import itertools
import logging
import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np

from geometry.contacts import ContactPoints, contact_points, contact_state, rests_alone, workspace_for_task
from geometry.features import Contact, ContactKind
from geometry.grasps import NO_CONTACT, GraspOptions, MotionCheckOptions, enumerate_grasps, motion_conditioned, pose_conditioned
from geometry.kinematics import Motion, MotionKind, rotate_about, sweep, translate, two_contact
from geometry.poses import FloatArray, IntArray, Pose, wrap_angle
from geometry.world import World
from ldhp_tamp import budget, parallel
from ldhp_tamp.budget import Budget
from ldhp_tamp.domain_info import DomainActions, read_domain_actions
from ldhp_tamp.errors import TimeBudgetExceeded
from ldhp_tamp.executability import forward_check
from ldhp_tamp.grasp_graph import GraspGraphOptions, GraspPlanner
from ldhp_tamp.path import Segment
from ldhp_tamp.plan import PLAN_FORMAT, Failure, FailureCause, FailureTier, Family, Plan, PlanStats, PlanStatus, Step
from ldhp_tamp.planners import register
from ldhp_tamp.primitives import REGISTRY
from ldhp_tamp.primitives.adjust_grasp import IntraEdges
from ldhp_tamp.scenario import Scenario
from ldhp_tamp.tamp import EDGE_OFFSET_RANGE, SolveOptions, SolveResult, SolveStatus
from ldhp_tamp.validate import domain_actions, validate_plan

__all__ = ["ENGINE", "Mode", "ModeTwist", "RRTOptions", "mode_twists", "solve", "solve_rrt"]

log = logging.getLogger(__name__)

#: The planner's name, written as the plan's ``stats.engine``.
ENGINE = "contact-rrt"


# --------------------------------------------------------------------------------------
# Options
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RRTOptions:
    """The baseline's parameters (``docs/design/contact_rrt.md``).

    Attributes
    ----------
    max_extensions : int
        Extension attempts (one target each); the work budget that makes a run
        reproducible regardless of the machine's speed.
    max_nodes : int
        Tree nodes at most (the root included).
    goal_bias : float
        Probability that a target is the goal pose.
    step_mm : float
        Most object-vertex motion (mm) of one extension.
    grasp_samples : int
        Finger-contact sets (grasps) sampled per extension when the grasp in hand cannot
        be kept.
    goal_tol_mm : float
        A node is at the goal when ``|dp| + r |dtheta|`` is at most this (mm; r the
        object's radius).
    max_points : int
        Object-environment point contacts whose modes are enumerated (4^n assignments);
        a pose with more is extended by the modes of its first ``max_points`` only.
    judge_retries : int
        Plans refused by the judge before the search gives up.
    max_failures : int
        A node from which this many extensions have found nothing is extended toward the
        goal no more (random targets still reach it): a node stuck against an obstacle,
        nearest to the goal, would otherwise take every goal-biased extension.
    forward_checks : int
        Grasps per finger choice checked by the forward problem (the first ones, in the
        sampled order, that execute the step).
    """

    max_extensions: int = 20_000
    max_nodes: int = 5_000
    goal_bias: float = 0.3
    step_mm: float = 30.0
    grasp_samples: int = 32
    goal_tol_mm: float = 0.05
    max_points: int = 4
    judge_retries: int = 20
    max_failures: int = 8
    forward_checks: int = 4

    def __post_init__(self) -> None:
        if self.max_extensions < 1 or self.max_nodes < 2 or not 0.0 <= self.goal_bias <= 1.0:
            raise ValueError(f"contact-rrt options: max_extensions >= 1, max_nodes >= 2, 0 <= goal_bias <= 1: {self}")
        if self.step_mm <= 0 or self.grasp_samples < 1 or self.goal_tol_mm <= 0 or self.max_points < 1:
            raise ValueError(f"contact-rrt options: step_mm, goal_tol_mm > 0, grasp_samples, max_points >= 1: {self}")


#: A state piece of a sweep shorter than this (mm of vertex motion) is an instant: the
#: contacts that separate at the start of a step make one.
INSTANT_MM = 0.5
#: An extension that moves the object less than this (mm of vertex motion) is no progress,
#: unless it ends at its target (the last fraction of a millimetre to the goal).
MIN_PROGRESS_MM = 0.5
#: Relative tolerance of the mode inequalities and of "no rotation".
_TWIST_TOL = 1e-6


# --------------------------------------------------------------------------------------
# Contact modes
# --------------------------------------------------------------------------------------


class Mode(enum.Enum):
    """An object-environment contact's mode over an extension."""

    STICKING = "sticking"
    SLIDING_POS = "sliding+"  #: the object's point slides along +t, t = (-n_y, n_x)
    SLIDING_NEG = "sliding-"
    SEPARATING = "separating"


STICKING, SLIDING_POS, SLIDING_NEG, SEPARATING = Mode.STICKING, Mode.SLIDING_POS, Mode.SLIDING_NEG, Mode.SEPARATING
#: The enumeration order of each contact's modes.
MODES: tuple[Mode, ...] = tuple(Mode)


@dataclass(frozen=True)
class ModeTwist:
    """One kinematically feasible contact mode and the object twist it allows toward the
    target: ``twist`` = (vx, vy, omega) of the pose's origin, ``kind`` the motion family
    that realises it exactly (``rotate``: about ``pivot``, the sticking point, or with
    ``pivot`` None and every contact separating about the twist's instantaneous centre;
    ``translate``; ``two-contact``: keeping the points ``kept``)."""

    modes: tuple[Mode, ...]
    twist: FloatArray
    kind: MotionKind
    pivot: int | None = None
    kept: tuple[int, ...] = ()


def _rows(points: FloatArray, normals: FloatArray, origin: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(C, 3) normal and tangential velocity rows: a contact point's velocity component
    is row . (vx, vy, omega); tangent t = (-n_y, n_x)."""
    r = points - origin[None, :]
    t = np.stack([-normals[:, 1], normals[:, 0]], axis=1)
    jn = np.column_stack([normals, normals[:, 1] * r[:, 0] - normals[:, 0] * r[:, 1]])
    jt = np.column_stack([t, t[:, 1] * r[:, 0] - t[:, 0] * r[:, 1]])
    return jn, jt


def _project(rows: list[FloatArray], target: FloatArray, weight: FloatArray) -> FloatArray | None:
    """The twist nearest ``target`` (in the ``weight`` metric) on which every row is 0;
    ``None`` when only the zero twist is."""
    if rows:
        a = np.asarray(rows)
        _, s, vt = np.linalg.svd(a)
        rank = int((s > 1e-9 * max(1.0, s[0])).sum())
        basis = vt[rank:].T  # (3, k)
    else:
        basis = np.eye(3)
    if basis.shape[1] == 0:
        return None
    w = np.diag(weight)
    m = basis.T @ w @ basis
    return basis @ np.linalg.solve(m, basis.T @ w @ target)


def mode_twists(points: FloatArray, normals: FloatArray, origin: FloatArray, target: FloatArray,
                radius: float, free: FloatArray | None = None) -> list[ModeTwist]:
    """Enumerate the contact modes of the point contacts ``points`` (inward ``normals``)
    and, for each, the twist toward ``target`` it allows (CMGMP's mode-guided velocity).

    A mode assignment's maintained contacts (sticking or sliding) make equality rows
    (normal velocity 0, and tangential 0 for sticking); the target twist is projected onto
    their null space in the metric ``diag(1, 1, radius^2)``; the projection must separate
    the separating contacts and slide the sliding ones in their sense. A twist the plan's
    vocabulary cannot carry out exactly (a rotating slide on one contact) is projected
    again with no rotation. Equal twists of different assignments are kept
    once (the first, in :data:`MODES` order).

    Parameters
    ----------
    points, normals : (C, 2)
    origin : (2,)
        The object pose's position: the twist's reference point.
    target : (3,)
        Desired (dx, dy, dtheta).
    radius : float
        Object radius (mm): weighs rotation against translation.
    free : (3,), optional
        The twist of the mode where every contact separates (default ``target``): the
        screw that lands on the target pose exactly (:func:`_screw_twist`).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    normals = np.asarray(normals, dtype=float).reshape(-1, 2)
    c = points.shape[0]
    jn, jt = _rows(points, normals, np.asarray(origin, dtype=float))
    weight = np.array([1.0, 1.0, radius * radius])
    target = np.asarray(target, dtype=float)
    scale = float(np.sqrt(target @ (weight * target)))
    if scale <= 0.0:
        return []
    out: list[ModeTwist] = []
    seen: set[tuple[Any, ...]] = set()
    for modes in itertools.product(MODES, repeat=c):
        rows: list[FloatArray] = []
        for i, m in enumerate(modes):
            if m != SEPARATING:
                rows.append(jn[i])
            if m == STICKING:
                rows.append(jt[i])
        xi = _project(rows, target, weight) if rows or free is None else np.asarray(free, dtype=float)
        if xi is None:
            continue
        sticking = [i for i, m in enumerate(modes) if m == STICKING]
        sliding = [i for i, m in enumerate(modes) if m in (SLIDING_POS, SLIDING_NEG)]
        rotating = abs(xi[2]) * radius > _TWIST_TOL * scale
        kind, pivot, kept = MotionKind.TRANSLATE, None, tuple(sliding)
        if rotating and sticking:
            kind, pivot, kept = MotionKind.ROTATE, sticking[0], ()
        elif rotating and not sticking and len(sliding) == 2:
            kind, kept = MotionKind.TWO_CONTACT, tuple(sliding)
        elif rotating and not sliding:  # free: a rotation about the twist's instantaneous centre
            kind = MotionKind.ROTATE
        elif rotating:  # a slide that turns on one contact, not in the vocabulary: its translation part
            xi = _project(rows + [np.array([0.0, 0.0, 1.0])], target, weight)
            if xi is None:
                continue
        if sticking and kind is not MotionKind.ROTATE:
            continue  # a sticking contact that does not turn: the object stands still
        norm = float(np.sqrt(xi @ (weight * xi)))
        if norm <= _TWIST_TOL * scale:
            continue
        eps = _TWIST_TOL * norm
        vn, vt = jn @ xi, jt @ xi
        ok = True
        for i, m in enumerate(modes):
            if m == SEPARATING:
                ok = vn[i] > eps
            elif m == SLIDING_POS:
                ok = vt[i] > eps
            elif m == SLIDING_NEG:
                ok = vt[i] < -eps
            if not ok:
                break
        if not ok:
            continue
        key = (kind, pivot, kept, tuple(np.round(xi / norm, 6)))
        if key in seen:
            continue
        seen.add(key)
        out.append(ModeTwist(tuple(modes), xi, kind, pivot, kept))
    return out


# --------------------------------------------------------------------------------------
# Motions
# --------------------------------------------------------------------------------------


def _point_contact(world: World, pose: Pose, cp: ContactPoints, i: int) -> Contact | None:
    """The point contact (vertex-edge or edge-vertex) that point ``i`` of ``cp`` is: an
    edge-edge contact's point is its object vertex on the environment edge or the
    environment vertex on the object edge."""
    c = cp.contacts[int(cp.contact_index[i])]
    if c.kind is not ContactKind.EDGE_EDGE:
        return c
    p = cp.points[i]
    verts = world.object_vertices(pose)
    n = world.object.n
    for j in (c.obj, (c.obj + 1) % n):
        if np.linalg.norm(verts[j] - p) < 1e-6:
            return Contact(ContactKind.VERTEX_EDGE, j, c.env)
    ev = world.environment.vertices
    d = np.linalg.norm(ev - p, axis=1)
    if d.size and d.min() < 1e-6:
        return Contact(ContactKind.EDGE_VERTEX, c.obj, int(d.argmin()))
    return None


@dataclass(frozen=True)
class _Candidate:
    """A motion an extension may take: its primitive, the motion and the plan step's
    parameters."""

    primitive: str
    motion: Motion
    params: dict[str, Any]


def _candidates(world: World, pose: Pose, target: FloatArray, radius: float, max_points: int,
                declared: frozenset[str]) -> list[_Candidate]:
    """Every mode's motion toward ``target`` from ``pose`` (:func:`mode_twists`),
    as the primitives the domain declares."""
    cp = contact_points(world, pose)
    n = min(len(cp), max_points)
    pts, nrm = cp.points[:n], cp.normals[:n]
    p0 = pose.as_array()
    goal = np.array([target[0] - p0[0], target[1] - p0[1], float(wrap_angle(target[2] - p0[2]))])
    out: list[_Candidate] = []
    for mt in mode_twists(pts, nrm, p0[:2], goal, radius, free=_screw_twist(p0, np.asarray(target, dtype=float))):
        modes = [f"{cp.contacts[int(cp.contact_index[i])].name}:{m.value}" for i, m in enumerate(mt.modes)]
        sense = 1 if mt.twist[2] > 0 else -1
        try:
            if mt.kind is MotionKind.TRANSLATE:
                kept = [_point_contact(world, pose, cp, i) for i in mt.kept]
                name = "push" if mt.kept else "air-move"
                motion = translate(pose, mt.twist[:2], [k for k in kept if k is not None])
                params: dict[str, Any] = {"direction": [round(float(v), 6) for v in motion.direction or ()]}
            elif mt.kind is MotionKind.ROTATE and mt.pivot is None:  # free: about the instantaneous centre
                name = "air-move"
                v, w = mt.twist[:2], mt.twist[2]
                pt = p0[:2] + np.array([-v[1], v[0]]) / w
                motion = rotate_about(pose, pt, sense)
                params = {"centre": [round(float(pt[0]), 6), round(float(pt[1]), 6)],
                          "sense": "ccw" if sense > 0 else "cw"}
            elif mt.kind is MotionKind.ROTATE:
                assert mt.pivot is not None
                name = "tip"
                pt = pts[mt.pivot]
                motion = rotate_about(pose, pt, sense)
                params = {"pivot": [round(float(pt[0]), 6), round(float(pt[1]), 6)],
                          "sense": "ccw" if sense > 0 else "cw"}
            else:
                a, b = (_point_contact(world, pose, cp, i) for i in mt.kept)
                if a is None or b is None or a == b:
                    continue
                name = "biplanar-slide"
                motion = two_contact(world, pose, (a, b), sense)
                params = {"contacts": [a.name, b.name], "sense": "ccw" if sense > 0 else "cw"}
        except ValueError:  # parallel lines, a degenerate direction
            continue
        if name not in declared:
            continue
        params["modes"] = modes
        out.append(_Candidate(name, motion, params))
    return out


def _screw_twist(p0: FloatArray, p1: FloatArray) -> FloatArray:
    """The twist (vx, vy, omega) of the pose origin that carries pose ``p0`` onto ``p1``
    in unit time by one rotation (about the displacement's fixed point) or, without a
    turn, one translation: integrated, it lands on the target exactly."""
    dth = float(wrap_angle(p1[2] - p0[2]))
    if abs(dth) < 1e-9:
        return np.array([p1[0] - p0[0], p1[1] - p0[1], 0.0])
    c, s = math.cos(dth), math.sin(dth)
    rot = np.array([[c, -s], [s, c]])
    centre = np.linalg.solve(np.eye(2) - rot, p1[:2] - rot @ p0[:2])
    r = p0[:2] - centre
    return np.array([-dth * r[1], dth * r[0], dth])


def _distance(poses: FloatArray, target: FloatArray, radius: float) -> FloatArray:
    """``|dp| + r |dtheta|`` of each pose (n, 3) to ``target``; inf where undefined."""
    d = np.hypot(poses[:, 0] - target[0], poses[:, 1] - target[1]) + radius * np.abs(
        wrap_angle(poses[:, 2] - target[2]))
    return np.where(np.isfinite(d), d, np.inf)


def _toward(world: World, motion: Motion, target: FloatArray, radius: float, step_mm: float) -> float:
    """The parameter in [0, step] (``step_mm`` of vertex motion) whose pose is nearest
    ``target``: exact for a translation (the projection) and a rotation (the target's
    orientation), else the best of a 65-point grid."""
    speed = max(motion.vertex_speed(world), 1e-9)
    s_cap = step_mm / speed
    values = list(np.linspace(0.0, s_cap, 65))
    if motion.kind is MotionKind.TRANSLATE:
        d = np.asarray(motion.direction)
        values.append(float(np.dot(target[:2] - motion.start.as_array()[:2], d)))
    elif motion.kind is MotionKind.ROTATE:
        values.append(float(wrap_angle(motion.sense * (target[2] - motion.start.theta)) % (2 * math.pi)))
    s = np.array([v for v in values if 0.0 <= v <= s_cap])
    dist = _distance(motion.poses(s), target, radius)
    best = int(np.argmin(dist))
    if motion.kind is not MotionKind.TWO_CONTACT:
        return float(s[best])
    # a two-contact motion: the grid's best, refined between its neighbours (golden section)
    grid = s[:65]
    j = int(np.argmin(dist[:65]))
    lo, hi = float(grid[max(j - 1, 0)]), float(grid[min(j + 1, 64)])
    phi = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(60):
        a, b = hi - phi * (hi - lo), lo + phi * (hi - lo)
        da, db = _distance(motion.poses([a, b]), target, radius)
        if da <= db:
            hi = b
        else:
            lo = a
    mid = 0.5 * (lo + hi)
    return mid if _distance(motion.poses([mid]), target, radius)[0] < dist[best] else float(s[best])


def _step(world: World, cand: _Candidate, target: FloatArray, radius: float, step_mm: float,
          target_tol: float = 0.0) -> Segment | None:
    """The extension along ``cand`` toward ``target``: at most ``step_mm`` of vertex
    motion, stopped where it would penetrate and where the contact state changes after
    the start (a new mode); ``None`` when it makes no progress."""
    motion = cand.motion
    s_want = _toward(world, motion, target, radius, step_mm)
    speed = max(motion.vertex_speed(world), 1e-9)
    if s_want * speed <= 1e-9:
        return None
    sw = sweep(world, motion, s_want)
    pieces = sw.pieces
    k = 1 if len(pieces) > 1 and (pieces[0].s1 - pieces[0].s0) * speed < INSTANT_MM else 0
    s_end = pieces[k].s1
    if k + 2 == len(pieces) and (pieces[-1].s1 - pieces[-1].s0) * speed < INSTANT_MM:
        s_end = pieces[-1].s1  # a new contact is made: the step ends where it is made, not on its way in
    p_end = motion.poses([s_end])[0]
    moved = float(np.max(np.linalg.norm(world.object_vertices(Pose.from_array(p_end))
                                        - world.object_vertices(motion.start), axis=1)))
    if not np.all(np.isfinite(p_end)) or moved <= 1e-9:
        return None
    if moved < MIN_PROGRESS_MM and _distance(p_end[None], target, radius)[0] > target_tol:
        return None
    params = dict(cand.params)
    if motion.kind is MotionKind.TRANSLATE:
        params["travel"] = round(s_end, 6)
    else:
        params["angle"] = round(math.degrees(s_end), 6)
    return Segment(cand.primitive, contact_state(world, motion.start), contact_state(world, Pose.from_array(p_end)),
                   motion, 0.0, s_end, world, params)


# --------------------------------------------------------------------------------------
# The tree
# --------------------------------------------------------------------------------------


#: Grasps a change may go to, found per extension before the changes are checked.
CHANGE_TARGETS = 4

#: The root's grasp under ``start_grasp = "any"``: any grasp that holds the object there.
ANY_GRASP = -1


@dataclass(frozen=True)
class _Change:
    """A grasp change at a fixed object pose: one AdjustGrasp edge."""

    primitive: str
    edges: IntraEdges  # exactly one edge
    pose: Pose
    state: str


@dataclass
class _Node:
    pose: FloatArray
    grasp: int
    parent: int
    segment: Segment | None = None
    changes: tuple[_Change, ...] = ()  # at the parent's pose, before the segment
    gt: np.ndarray | None = field(default=None, repr=False)  # packed G_T mask (uint8), computed when needed


@dataclass
class _Stats:
    extensions: int = 0
    feasibility_checks: int = 0
    judge_rejections: int = 0
    motion_time: float = 0.0
    grasp_time: float = 0.0
    no_motion: int = 0
    no_grasp: int = 0
    ambiguous: int = 0  # grasps the forward problem refused on a step
    judge_time: float = 0.0
    states: set[str] = field(default_factory=set)
    best: float = math.inf  # the nearest any node came to the goal


class _Search:
    """One run of the RRT: the grasp machinery, the tree, the extension."""

    def __init__(self, scenario: Scenario, world: World, options: SolveOptions, rrt: RRTOptions,
                 domain: DomainActions, deadline: float | None, stats: _Stats):
        settings = scenario.settings
        self.scenario, self.world, self.rrt, self.deadline, self.stats = scenario, world, rrt, deadline, stats
        seed = settings.seed if options.seed is None else options.seed
        # the seed split as LDHP's solve splits it: the same seed, the same grasp set
        grasp_rng, self.rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
        self.radius = float(world.object.polygon.radius)
        self.declared = frozenset(domain.names(Family.MOVE_OBJECT))
        self._press: dict[tuple[int, int], float] = {}  # (id of a segment, grasp) -> the press G_m found
        k = options.samples_per_edge or settings.samples_per_edge
        offsets = tuple(float(u) for u in grasp_rng.uniform(*EDGE_OFFSET_RANGE, size=world.object.n))
        grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=k, edge_offsets=offsets))
        budget.check(deadline, "contact-rrt's setup (grasp enumeration)")
        adjust = [REGISTRY.binding(n) for n in domain.names(Family.ADJUST_GRASP) if n in REGISTRY]
        self.planner = GraspPlanner(world, grasps, adjust, scenario.start_grasp, scenario.goal_release,
                                    GraspGraphOptions(helper=False), start_any=scenario.start_grasp_any)
        self.planner.prepare(scenario.start.as_array())
        self.ctx = self.planner.context
        self.grasps = self.planner.grasps
        self.adjust = {b.name: b.implementation for b in adjust}
        self.motion_opts = MotionCheckOptions()
        start = self.planner.start_index
        root_grasp = ANY_GRASP if np.ndim(start) else int(start)
        self.goal = scenario.goal.as_array()
        self._goal_gt: np.ndarray | None = None
        ws = workspace_for_task(world, scenario.start, scenario.goal)
        self.box = (ws.xmin, ws.ymin, ws.xmax, ws.ymax)
        self.nodes: list[_Node] = []
        self.poses = np.zeros((rrt.max_nodes, 3))
        self.alive = np.zeros(rrt.max_nodes, dtype=bool)
        self.failures = np.zeros(rrt.max_nodes, dtype=np.int64)
        self._add(_Node(scenario.start.as_array().copy(), root_grasp, -1))

    # ---- tree ----------------------------------------------------------------------------

    def _add(self, node: _Node) -> int:
        i = len(self.nodes)
        self.nodes.append(node)
        self.poses[i] = node.pose
        self.alive[i] = True
        self.stats.states.add(contact_state(self.world, Pose.from_array(node.pose)).name)
        self.stats.best = min(self.stats.best, float(_distance(node.pose[None], self.goal, self.radius)[0]))
        return i

    def _gt_mask(self, pose: FloatArray) -> np.ndarray:
        mask = np.zeros(len(self.grasps), dtype=bool)
        mask[pose_conditioned(self.world, self.grasps, pose, self.planner.options.adjust.tol)] = True
        return mask

    def _gt(self, i: int) -> np.ndarray:
        """G_T at node ``i``'s pose as a mask (computed once, kept packed)."""
        node = self.nodes[i]
        if node.gt is None:
            node.gt = np.packbits(self._gt_mask(node.pose))
        return np.unpackbits(node.gt, count=len(self.grasps)).astype(bool)

    def prune(self, i: int) -> None:
        """Take node ``i`` and its subtree out of the search (a judge refused its edge)."""
        dead = {i}
        for j in range(i + 1, len(self.nodes)):
            if self.nodes[j].parent in dead:
                dead.add(j)
        self.alive[list(dead)] = False

    def target(self) -> FloatArray:
        if self.rng.random() < self.rrt.goal_bias:
            return self.goal.copy()
        x0, y0, x1, y1 = self.box
        u = self.rng.random(3)
        return np.array([x0 + u[0] * (x1 - x0), y0 + u[1] * (y1 - y0), -math.pi + 2 * math.pi * u[2]])

    def nearest(self, q: FloatArray) -> int | None:
        """The live node nearest ``q``, toward the goal one that is not exhausted
        (``None``: there is none)."""
        n = len(self.nodes)
        d = _distance(self.poses[:n], q, self.radius)
        d[~self.alive[:n]] = np.inf
        if np.array_equal(q, self.goal):
            d[self.failures[:n] >= self.rrt.max_failures] = np.inf
        i = int(np.argmin(d))
        return i if np.isfinite(d[i]) else None

    # ---- one extension -------------------------------------------------------------------

    def extend(self, q: FloatArray) -> int | None:
        """Extend the tree from the node nearest ``q`` toward it; the new node or None."""
        i = self.nearest(q)
        if i is None:
            return None
        new = self._extend_from(i, q)
        if new is None:
            self.failures[i] += 1
        return new

    def _extend_from(self, i: int, q: FloatArray) -> int | None:
        node = self.nodes[i]
        pose = Pose.from_array(node.pose)
        t0 = budget.clock()
        cands = _candidates(self.world, pose, q, self.radius, self.rrt.max_points, self.declared)
        order = self.rng.permutation(len(cands))
        self.stats.motion_time += budget.clock() - t0
        for c in order:
            budget.check(self.deadline, f"contact-rrt, extension {self.stats.extensions}")
            t0 = budget.clock()
            seg = _step(self.world, cands[int(c)], q, self.radius, self.rrt.step_mm, self.rrt.goal_tol_mm)
            self.stats.motion_time += budget.clock() - t0
            if seg is None:
                continue
            t0 = budget.clock()
            end = np.asarray(seg.poses[-1], dtype=float)
            fingers = self.fingers(i, seg)
            self.stats.grasp_time += budget.clock() - t0
            if fingers is None:
                self.stats.no_grasp += 1
                continue
            g, changes = fingers
            return self._add(_Node(end.copy(), g, i, seg, changes))
        self.stats.no_motion += not cands
        return None

    def _unambiguous(self, seg: Segment, g: int) -> bool:
        """The forward problem of the judge (:func:`ldhp_tamp.executability.forward_check`)
        on the edge's MoveObject step alone: carrying ``g`` along ``seg`` makes the planned
        motion and no other (a fingertip that could let go while the object stays put
        does not push it). Checked at once so that no subtree grows on a step the judge
        would refuse."""
        t0 = budget.clock()
        plan = Plan(PLAN_FORMAT, self.scenario.name, self.scenario.sha256, PlanStatus.SOLVED,
                    (self.planner.move_step(seg, g, self._press.get((id(seg), g))),), PlanStats(engine=ENGINE))
        ok = forward_check(plan, self.scenario).ok
        self.stats.judge_time += budget.clock() - t0
        self.stats.ambiguous += not ok
        return ok

    def _carries(self, seg: Segment, cand: IntArray, want: int) -> IntArray:
        """The first ``want`` grasps of ``cand`` (in its order) that execute ``seg``
        (:meth:`_executes`) unambiguously (:meth:`_unambiguous`, tried on at most
        ``forward_checks`` of them)."""
        ordered = cand[np.isin(cand, self._executes(seg, cand))]
        out: list[int] = []
        for g in ordered[: self.rrt.forward_checks]:
            if self._unambiguous(seg, int(g)):
                out.append(int(g))
                if len(out) >= want:
                    break
        return np.array(out, dtype=np.int64)

    def _executes(self, seg: Segment, cand: IntArray) -> IntArray:
        """The grasps of ``cand`` that execute ``seg`` (G_m restricted to them)."""
        if cand.size == 0:
            return cand
        mg = motion_conditioned(self.world, self.grasps, seg.poses, cand, self.motion_opts, rate=False)
        self.stats.feasibility_checks += mg.checks
        for g in mg.indices:  # the presses G_m found (a one-finger drag): the step asks for them
            force = mg.press_of(int(g))
            if force is not None:
                self._press[(id(seg), int(g))] = force
        return mg.indices

    def _sample(self, rows: IntArray) -> IntArray:
        """At most ``grasp_samples`` of ``rows`` (given in a random order), those
        collision-free at the goal pose first (a grasp that cannot be at the goal cannot
        finish the task without another change)."""
        if self._goal_gt is None:
            self._goal_gt = self._gt_mask(self.goal)
        at_goal = self._goal_gt[rows]
        rows = np.concatenate([rows[at_goal], rows[~at_goal]])
        return rows[: self.rrt.grasp_samples]

    def fingers(self, i: int, seg: Segment) -> tuple[int, tuple[_Change, ...]] | None:
        """A finger contact set that executes ``seg`` from node ``i``: the grasp in hand,
        or one reached by a grasp change at the node's pose; ``None`` if none is found."""
        node = self.nodes[i]
        g = node.grasp
        pose = Pose.from_array(node.pose)
        state = seg.from_state.name
        if g > NO_CONTACT and self._carries(seg, np.array([g]), 1).size:
            return g, ()
        ok = self._gt(i) & (self.grasps.n_touching >= 1)
        if g == ANY_GRASP:  # the held start: any grasp that holds the object there
            held = np.flatnonzero(self.ctx.holds(node.pose, ok) & ok)
            chosen = self._carries(seg, self._sample(self.rng.permutation(held)), 1)
            return (int(chosen[0]), ()) if chosen.size else None
        # an AdjustGrasp change with the object held (pivot, slide, close, open to one finger, flip)
        if g > NO_CONTACT:
            found = self._change(pose, state, seg, g, ok, [n for n in self.adjust if n != "approach-contact"])
            if found is not None:
                return found
        # let go where the object rests alone, and approach another grasp
        if "approach-contact" not in self.adjust:
            return None
        pre: tuple[_Change, ...] = ()
        if g > NO_CONTACT:
            if "open" not in self.adjust or not rests_alone(self.world, node.pose[None])[0]:
                return None
            release = self._release(pose, state, g)
            if release is None:
                return None
            pre = (release,)
        found = self._change(pose, state, seg, NO_CONTACT, ok, ["approach-contact"])
        return None if found is None else (found[0], pre + found[1])

    def _change(self, pose: Pose, state: str, seg: Segment, g: int, ok: np.ndarray,
                names: Sequence[str]) -> tuple[int, tuple[_Change, ...]] | None:
        """One AdjustGrasp edge of ``names`` from ``g`` to a sampled grasp of ``ok`` that
        executes ``seg`` and passes the primitive's check."""
        if g == NO_CONTACT:  # approach-contact reaches every grasp: sample first, then propose
            members = np.zeros_like(ok)
            members[self._carries(seg, self._sample(self.rng.permutation(np.flatnonzero(ok))), CHANGE_TARGETS)] = True
            ok = members
            if not ok.any():
                return None
        proposals: list[tuple[str, IntraEdges]] = []
        for name in names:
            impl = self.adjust[name]
            e = impl.propose(self.ctx, pose, np.array([g]), ok)
            keep = (e.dst != NO_CONTACT) & (e.dst != g)
            if keep.any():
                proposals.append((name, e.take(np.flatnonzero(keep))))
        if not proposals:
            return None
        dst = np.unique(np.concatenate([e.dst for _, e in proposals]))
        good = dst if g == NO_CONTACT else self._carries(seg, self._sample(self.rng.permutation(dst)), CHANGE_TARGETS)
        if not good.size:
            return None
        # every proposed edge into a good grasp, in a random order, checked one primitive at a time
        pending = [(name, e.take(np.flatnonzero(np.isin(e.dst, good)))) for name, e in proposals]
        pending = [(name, e) for name, e in pending if len(e)]
        for k in self.rng.permutation(len(pending)):
            name, e = pending[int(k)]
            e = e.take(self.rng.permutation(len(e)))
            assert self._goal_gt is not None
            e = e.take(np.argsort(~self._goal_gt[e.dst], kind="stable")[: self.rrt.grasp_samples])
            res = self.adjust[name].check(self.ctx, pose, e)
            self.stats.feasibility_checks += res.feasibility_checks
            hit = np.flatnonzero(res.ok)
            if hit.size:
                one = e.take(hit[:1])
                return int(one.dst[0]), (_Change(name, one, pose, state),)
        return None

    def _release(self, pose: Pose, state: str, g: int) -> _Change | None:
        """``open`` from ``g`` to no contact at ``pose``, if its check passes."""
        impl = self.adjust.get("open")
        if impl is None:
            return None
        members = np.zeros(len(self.grasps), dtype=bool)
        members[NO_CONTACT] = True
        e = impl.propose(self.ctx, pose, np.array([g]), members)
        e = e.take(np.flatnonzero(e.dst == NO_CONTACT))
        if not len(e):
            return None
        res = impl.check(self.ctx, pose, e.take([0]))
        self.stats.feasibility_checks += res.feasibility_checks
        return _Change("open", e.take([0]), pose, state) if res.ok[0] else None

    # ---- goal and plan -------------------------------------------------------------------

    def at_goal(self, i: int) -> bool:
        return float(_distance(self.nodes[i].pose[None], self.goal, self.radius)[0]) <= self.rrt.goal_tol_mm

    def finish(self, i: int) -> tuple[_Change, ...] | None:
        """What ends a plan at goal node ``i``: nothing, or a release under
        ``goal_release``; ``None`` when the gripper cannot let go there."""
        node = self.nodes[i]
        if not self.scenario.goal_release or node.grasp == NO_CONTACT:
            return ()
        pose = Pose.from_array(node.pose)
        release = self._release(pose, contact_state(self.world, pose).name, node.grasp)
        return None if release is None else (release,)

    def steps(self, i: int, end: tuple[_Change, ...]) -> tuple[list[Step], list[int]]:
        """The plan of the tree path to node ``i`` (then ``end``): its steps and, per
        step, the node whose edge made it."""
        chain = []
        while i > 0:
            chain.append(i)
            i = self.nodes[i].parent
        chain.reverse()
        steps: list[Step] = []
        owner: list[int] = []
        for j in chain:
            node = self.nodes[j]
            for ch in node.changes:
                steps.append(self._change_step(ch))
                owner.append(j)
            assert node.segment is not None
            steps.append(self.planner.move_step(node.segment, node.grasp,
                                                self._press.get((id(node.segment), node.grasp))))
            owner.append(j)
        for ch in end:
            steps.append(self._change_step(ch))
            owner.append(chain[-1] if chain else 0)
        return steps, owner

    def _change_step(self, ch: _Change) -> Step:
        impl = self.adjust[ch.primitive]
        return Step(ch.primitive, Family.ADJUST_GRASP, impl.parameters(self.ctx, ch.edges, 0), (ch.state, ch.state),
                    impl.waypoints(self.ctx, ch.pose, ch.edges, 0))


# --------------------------------------------------------------------------------------
# The solve
# --------------------------------------------------------------------------------------


def _judge(plan: Plan, scenario: Scenario, simulate: bool) -> tuple[int | None, str]:
    """LDHP's judge (:class:`ldhp_tamp.tamp._Judge`'s checks): the first plan step that
    does not execute and why, or ``(None, "")``."""
    report = validate_plan(plan, scenario)
    if not report.valid:
        first = min((v for v in report.violations if v.step is not None), key=lambda v: v.step or 0,
                    default=report.violations[0])
        return first.step or 0, f"breaks rule {first.rule}: {first.message}"
    forward = forward_check(plan, scenario)
    if not forward.ok:
        return forward.step or 0, f"is ambiguous at {forward.reason}"
    if simulate:
        from ldhp_tamp.simulate import simulate_plan  # MuJoCo loads only when asked for

        sim = simulate_plan(plan, scenario)
        if not sim.executes:
            return (sim.diverged_step if sim.diverged_step is not None else len(plan.steps) - 1,
                    f"diverges in the physics simulation: {sim.reason}")
    return None, ""


def _plan_stats(search: _Search | None, stats: _Stats, start: float) -> PlanStats:
    nodes = 0 if search is None else len(search.nodes)
    return PlanStats(engine=ENGINE, contact_state_nodes=len(stats.states), grasp_graph_nodes=nodes,
                     grasp_graph_edges=max(nodes - 1, 0), top_iterations=stats.extensions, refinements=0,
                     feasibility_checks=stats.feasibility_checks,
                     time_s={"symbolic": 0.0, "streams": round(stats.motion_time, 4),
                             "grasp_graph": round(stats.grasp_time, 4), "forward": round(stats.judge_time, 4),
                             "total": round(budget.clock() - start, 4)},
                     extra={"planner": ENGINE, "tree_nodes": nodes, "extensions": stats.extensions,
                            "judge_rejections": stats.judge_rejections, "ambiguous_steps": stats.ambiguous,
                            "closest_to_goal_mm": None if not math.isfinite(stats.best) else round(stats.best, 4)})


def _failed(scenario: Scenario, search: _Search | None, stats: _Stats, start: float, reason: str,
            tier: FailureTier, cause: FailureCause, attempts: Sequence[str] = ()) -> SolveResult:
    log.info("failed: %s", reason)
    counts = {"extensions": stats.extensions, "tree_nodes": 0 if search is None else len(search.nodes),
              "judge_rejections": stats.judge_rejections}
    failure = Failure(tier, cause, counts=counts, attempts=tuple(attempts) or (reason,))
    plan = Plan(PLAN_FORMAT, scenario.name, scenario.sha256, PlanStatus.FAILED, (), _plan_stats(search, stats, start),
                reason, failure)
    return SolveResult(SolveStatus.FAILED, plan, reason)


def solve_rrt(scenario: Scenario, options: SolveOptions = SolveOptions(), rrt: RRTOptions = RRTOptions()
              ) -> SolveResult:
    """Plan for ``scenario`` with the contact-mode RRT (see the module docstring).

    Honours ``options.seed`` (else the scenario's), ``options.timeout`` (a failure whose
    reason starts ``timeout``), ``options.started``, ``options.samples_per_edge``,
    ``options.domain`` and ``options.simulate`` (the judge also replays the plan).

    Raises
    ------
    InputError
        An unusable domain (before any search).
    """
    start = budget.clock() if options.started is None else options.started
    deadline = Budget(options.timeout, start).deadline
    stats = _Stats()
    search: _Search | None = None
    domain = read_domain_actions(options.domain) if options.domain is not None else domain_actions(scenario)
    try:
        with budget.alarm(deadline):
            budget.check(deadline, "loading (the scenario and the planner, before the solve)")
            world = scenario.world
            if scenario.settings.friction_margin > 0:  # plan with less friction, as LDHP does
                world = replace(world, friction=world.friction.scaled(1.0 - scenario.settings.friction_margin))
            search = _Search(scenario, world, options, rrt, domain, deadline, stats)
            try:
                return _run(search, scenario, options, stats, start)
            finally:  # the forked children whose answers came as they ended (parallel.reap)
                with contextlib.suppress(TimeBudgetExceeded):
                    parallel.reap()
    except TimeBudgetExceeded as exc:
        nodes = 0 if search is None else len(search.nodes)
        reason = (f"timeout: the {options.timeout:g} s budget ran out in {exc.where} "
                  f"({stats.extensions} extensions, {nodes} tree nodes)")
        return _failed(scenario, search, stats, start, reason, FailureTier.TIMEOUT, FailureCause.TIMEOUT)


def _run(search: _Search, scenario: Scenario, options: SolveOptions, stats: _Stats, start: float) -> SolveResult:
    rrt = search.rrt
    refusals: list[str] = []
    while stats.extensions < rrt.max_extensions and len(search.nodes) < rrt.max_nodes:
        stats.extensions += 1
        budget.check(search.deadline, f"contact-rrt, extension {stats.extensions}")
        new = search.extend(search.target())
        if new is None and not search.alive.any():
            break  # every node is pruned
        if new is None or not search.at_goal(new):
            continue
        end = search.finish(new)
        if end is None:
            search.prune(new)
            refusals.append(f"node {new} reaches the goal but the gripper cannot release the object there")
            continue
        steps, owner = search.steps(new, end)
        plan = Plan(PLAN_FORMAT, scenario.name, scenario.sha256, PlanStatus.SOLVED, tuple(steps),
                    _plan_stats(search, stats, start))
        bad, why = _judge(plan, scenario, options.simulate)
        if bad is None:
            log.info("contact-rrt: solved after %d extensions, %d nodes", stats.extensions, len(search.nodes))
            return SolveResult(SolveStatus.SOLVED, replace(plan, stats=_plan_stats(search, stats, start)))
        stats.judge_rejections += 1
        text = f"the motion of plan step {bad} ({steps[bad].primitive}) {why}"
        refusals.append(text)
        log.info("contact-rrt: the judge refuses a plan: %s", text)
        search.prune(owner[bad])
        if stats.judge_rejections >= rrt.judge_retries:
            return _failed(scenario, search, stats, start,
                           f"judge: {stats.judge_rejections} plans refused, the last because {text}"[:300],
                           FailureTier.JUDGE, FailureCause.PLAN_INVALID, refusals)
    if stats.extensions >= rrt.max_extensions:
        within = f"within {rrt.max_extensions} extensions"
    elif len(search.nodes) >= rrt.max_nodes:
        within = f"within {rrt.max_nodes} tree nodes"
    else:
        within = f"after {stats.extensions} extensions: the judge refused every node's path"
    reason = (f"contact-rrt: no path to the goal {within} ({len(search.nodes)} nodes, "
              f"{len(stats.states)} contact states visited, nearest {stats.best:.1f} mm from the goal"
              + (f"; {stats.judge_rejections} plan(s) refused by the judge" if stats.judge_rejections else "") + ")")
    return _failed(scenario, search, stats, start, reason, FailureTier.STREAMS, FailureCause.NO_STREAM_SAMPLE,
                   refusals + [reason])


@register(ENGINE)
def solve(scenario: Scenario, options: SolveOptions) -> SolveResult:
    """The ``contact-rrt`` planner (:func:`solve_rrt` with the default :class:`RRTOptions`)."""
    return solve_rrt(scenario, options)
