"""Top tier, Steps 1-2: contact poses near the start and goal, and the contact-state graph.

Step 1 (paper): when the start (goal) pose touches nothing, the object is translated
along -y, -x, +x, +y until it touches the environment; the shortest such translation
gives the contact pose T'_0 (T'_g) and an ``air-move`` joins the two. Step 2: the nodes
of the graph are the contact states enumerated by :mod:`geometry.contacts` in the task's
workspace, plus the states of T'_0 and T'_g and ``free`` when an end is in the air; its
edges are the kinematically admissible transitions that every MoveObject implementation
of the domain reports (they become the ``can-<action>`` facts of the PDDL problem).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Callable

import numpy as np

from geometry.contacts import StateWitness, Workspace, contact_state, enumerate_contact_states, workspace_for_task
from geometry.features import FREE, ContactState
from geometry.grasps import GraspSet
from geometry.kinematics import SweepEnd, sweep, translate
from geometry.poses import Pose, transform_points
from geometry.tolerances import CONTACT_BACKOFF, CONTACT_TOL
from geometry.world import World
from ldhp_tamp.parallel import Forked, Helper
from ldhp_tamp.primitives.registry import DeclaresActions, PrimitiveRegistry

log = logging.getLogger(__name__)

#: Step 1 directions, in order of preference on equal travel: down first (gravity).
CONTACT_DIRECTIONS: tuple[tuple[float, float], ...] = ((0.0, -1.0), (-1.0, 0.0), (1.0, 0.0), (0.0, 1.0))


class ContactPoseError(ValueError):
    """No translation along the four directions brings the object into contact."""


@dataclass(frozen=True)
class ContactPose:
    """Step 1's answer for one end of the task."""

    pose: Pose  # T' (equal to the end pose when it already touches)
    state: ContactState
    travel: float  # mm from the end pose to T'
    direction: tuple[float, float] | None  # None when the end pose already touches


def contact_pose(world: World, pose: Pose, reach: float) -> ContactPose:
    """The nearest contact pose along the axis directions (paper, Step 1).

    Raises
    ------
    ContactPoseError
        When the object touches nothing within ``reach`` mm along any direction.
    """
    state = contact_state(world, pose)
    if not state.is_free:
        return ContactPose(pose, state, 0.0, None)
    best: ContactPose | None = None
    for d in CONTACT_DIRECTIONS:
        sw = sweep(world, translate(pose, d), reach)
        if sw.end is not SweepEnd.BLOCKED or sw.states[-1].is_free:
            continue
        if best is None or sw.s_end < best.travel - 1e-9:
            travel = max(0.0, sw.s_end - CONTACT_BACKOFF)
            pose_c = sw.motion.pose(travel)
            state_c = contact_state(world, pose_c)
            if state_c != sw.states[-1]:  # the back-off must not lose the contact made
                pose_c, state_c, travel = sw.motion.pose(sw.s_end), sw.states[-1], sw.s_end
            best = ContactPose(pose_c, state_c, travel, d)
    if best is None:
        raise ContactPoseError(
            f"the object at {pose.to_degrees()} touches nothing when moved up to {reach:.0f} mm "
            f"along -y, -x, +x or +y")
    return best


@dataclass(frozen=True, eq=False)
class PlanningContext:
    """Everything the MoveObject implementations and streams need about one task.

    ``transition_witnesses`` caps how many witness poses per state are swept to find the
    admissible transitions; ``stream_samples`` is the number of parameter samples a stream
    yields per transition (paper: limited and ranked by a light heuristic). ``deadline``
    (a :func:`time.perf_counter` value, or ``None``) is the solve's time budget, which the
    loops over states check (:func:`ldhp_tamp.budget.check`).
    """

    world: World
    start: Pose
    goal: Pose
    start_contact: ContactPose
    goal_contact: ContactPose
    witnesses: tuple[StateWitness, ...]
    workspace: Workspace
    transition_witnesses: int = 1
    stream_samples: int = 3
    deadline: float | None = None
    grasps: GraspSet | None = None
    """The enumerated grasp set, for admissibility that needs some grasp to exist (an
    air-move lift or placement needs a grasp that carries the object); ``None``: such
    transitions are admitted without that test."""
    start_grasp: int | None = None
    """The row of :attr:`grasps` the object starts held in (``None``: it starts free of
    the gripper): the Step-1 air-move may turn the object in the air first, to where that
    hold is firmer."""
    memo: dict[Any, Any] = field(default_factory=dict, repr=False)
    """Results the streams may compute again for the same input within one solve (a
    stream's sweeps: the top-tier iterations share their first steps), keyed by it."""
    helper: Any = field(default=None, repr=False)
    """``None``, or the bottom tier's
    :meth:`~ldhp_tamp.grasp_graph.GraspPlanner.live_helper`: a function returning its
    live :class:`ldhp_tamp.parallel.Helper` (or ``None``), whose state starts with the
    world: every second stream sweep runs there."""

    @property
    def start_free(self) -> bool:
        return self.start_contact.direction is not None

    @property
    def goal_free(self) -> bool:
        return self.goal_contact.direction is not None

    @property
    def start_state(self) -> ContactState:
        """The symbolic start: ``free`` when T_0 touches nothing, else the state of T_0."""
        return FREE if self.start_free else self.start_contact.state

    @property
    def goal_state(self) -> ContactState:
        return FREE if self.goal_free else self.goal_contact.state

    @cached_property
    def reach(self) -> float:
        """Longest straight motion worth sweeping (mm): the workspace diagonal."""
        w = self.workspace
        return float(math.hypot(w.xmax - w.xmin, w.ymax - w.ymin))

    @cached_property
    def states(self) -> tuple[ContactState, ...]:
        """The graph's nodes, sorted by name."""
        s = {w.state for w in self.witnesses}
        s |= {self.start_contact.state, self.goal_contact.state, FREE}  # air-moves reach free
        return tuple(sorted(s, key=lambda x: x.name))

    @cached_property
    def state_set(self) -> frozenset[ContactState]:
        return frozenset(self.states)

    def witness_poses(self, state: ContactState) -> tuple[Pose, ...]:
        """Witness poses of ``state`` (the Step-1 contact poses count as witnesses)."""
        return self._witness_poses.get(state, ())

    @cached_property
    def _witness_poses(self) -> dict[ContactState, tuple[Pose, ...]]:
        """:meth:`witness_poses` of every state that has one: the start's contact pose,
        the goal's, then the witnesses' (``transition_witnesses`` of each), in that order.
        (One pass: the setup and the streams ask for every state's, and comparing two
        states compares their contacts.)"""
        out: dict[ContactState, list[Pose]] = {}
        for c in (self.start_contact, self.goal_contact):
            out.setdefault(c.state, []).append(c.pose)
        for w in self.witnesses:
            out.setdefault(w.state, []).extend(w.witnesses[: self.transition_witnesses])
        return {s: tuple(p) for s, p in out.items()}

    def goal_distance(self, poses: np.ndarray) -> np.ndarray:
        """Heuristic distance (mm) of poses (n, 3) to the goal contact pose T'_g:
        translation plus the object's radius times the wrapped angle difference."""
        g = self.goal_contact.pose
        p = np.atleast_2d(poses)
        dth = np.abs((p[:, 2] - g.theta + math.pi) % (2 * math.pi) - math.pi)
        return np.hypot(p[:, 0] - g.x, p[:, 1] - g.y) + self.world.object.polygon.radius * dth


def _vertex_on_vertex(world: World, pose: Pose, tol: float = CONTACT_TOL) -> bool:
    """Whether an object vertex sits on a convex environment vertex at ``pose``."""
    env = world.environment
    v = world.object_vertices(pose)
    d = np.linalg.norm(v[:, None, :] - env.vertices[None, env.vertex_convex, :], axis=2)
    return bool(np.any(d <= tol))


def _vertices_on_vertices(world: World, poses: list[Pose], tol: float = CONTACT_TOL) -> np.ndarray:
    """:func:`_vertex_on_vertex` at each of the poses, (n,) bool, in one computation."""
    env = world.environment
    if not poses:
        return np.zeros(0, dtype=bool)
    v = transform_points(np.array([p.as_array() for p in poses]), world.object.polygon.vertices)  # (n, N, 2)
    d = np.linalg.norm(v[:, :, None, :] - env.vertices[None, None, env.vertex_convex, :], axis=3)
    return np.any(d <= tol, axis=(1, 2))


def proper_states(world: World, witnesses: tuple[StateWitness, ...]) -> tuple[StateWitness, ...]:
    """Drop the states every witness of which rests an object vertex exactly on a convex
    environment vertex (e.g. a corner balanced on the slot's lip corner): a measure-zero
    configuration that no quasi-static primitive holds or passes through robustly. An
    object vertex in a concave corner (the slot's floor meeting its wall) is kept: that
    is where a biplanar slide along the floor and the wall starts or ends, and the corner
    holds it robustly. The witnesses that do so are dropped from the states kept, too."""
    poses = [p for w in witnesses for p in w.witnesses]
    on_vertex = iter(_vertices_on_vertices(world, poses).tolist())
    out = []
    for w in witnesses:
        keep = tuple(p for p in w.witnesses if not next(on_vertex))
        if keep:
            out.append(StateWitness(w.state, keep))
    return tuple(out)


def build_context(world: World, start: Pose, goal: Pose, *, transition_witnesses: int = 1,
                  stream_samples: int = 3, deadline: float | None = None,
                  grasps: GraspSet | None = None) -> PlanningContext:
    """Steps 1-2 inputs: the workspace, contact poses T'_0 and T'_g, the enumerated states
    (up to three contacts at poses solved from one or two; without degenerate
    vertex-on-vertex states, see :func:`proper_states`).

    Raises
    ------
    ContactPoseError
        When an end pose in free space has no contact pose within reach.
    """
    workspace = workspace_for_task(world, start, goal)
    reach = float(math.hypot(workspace.xmax - workspace.xmin, workspace.ymax - workspace.ymin))
    found: dict[str, ContactPose] = {}
    for end, pose in (("start", start), ("goal", goal)):
        try:
            found[end] = contact_pose(world, pose, reach)
        except ContactPoseError as exc:
            raise ContactPoseError(f"no contact pose for the {end}: {exc}") from None
    start_c, goal_c = found["start"], found["goal"]
    enumerated = enumerate_contact_states(world, workspace, max_contacts=3)
    witnesses = proper_states(world, enumerated)
    log.info("contact states: %d enumerated, %d kept; T'_0 in %s, T'_g in %s", len(enumerated),
             len(witnesses), start_c.state.name, goal_c.state.name)
    return PlanningContext(world, start, goal, start_c, goal_c, witnesses, workspace,
                           transition_witnesses, stream_samples, deadline, grasps)


def admissible_transitions(ctx: PlanningContext, domain: DeclaresActions, registry: PrimitiveRegistry,
                           meanwhile: Callable[[], object] | None = None, helper: Helper | None = None,
                           ) -> dict[str, frozenset[tuple[ContactState, ContactState]]]:
    """The registry's transitions for the domain's MoveObject actions, restricted to the
    graph: pairs whose ends are not nodes (a sweep can leave the workspace) and self-loops
    are dropped.

    ``meanwhile``: other work of the solve, done in this process while another one
    computes the transitions: ``helper``, when given, whose state ends with
    ``(ctx, domain, registry)`` (the solve's helper, forked in the setup with them,
    :meth:`ldhp_tamp.grasp_graph.GraspPlanner.start_helper`), else a process forked now
    (:class:`ldhp_tamp.parallel.Forked`). That process sends the transitions back with
    what it added to ``ctx.memo`` (the air-move's carrying grasps), so that this process
    ends as if it had computed them itself. With one core, ``meanwhile`` runs first, then
    the transitions."""
    if meanwhile is None:
        found = registry.admissible_transitions(domain, ctx)
    else:
        if helper is not None:
            helper.submit(_helper_transitions)
            take, drop = helper.result, helper.close
        else:
            job = Forked(_transitions_and_memo, ctx, domain, registry)
            take, drop = job.result, job.close
        try:
            meanwhile()
        except BaseException:
            drop()  # the answer is not wanted (a helper's would come before its next one)
            raise
        found, memo = take()  # (interrupted, either ends its process)
        for key, value in memo.items():  # what another process memoised, as if memoised here
            ctx.memo.setdefault(key, value)
    nodes = ctx.state_set
    out = {name: frozenset((a, b) for a, b in pairs if a != b and a in nodes and b in nodes)
           for name, pairs in found.items()}
    for name, pairs in out.items():
        log.debug("%s: %d admissible transitions", name, len(pairs))
    return out


def _transitions_and_memo(ctx: PlanningContext, domain: DeclaresActions, registry: PrimitiveRegistry
                          ) -> tuple[dict[str, frozenset[tuple[ContactState, ContactState]]], dict[Any, Any]]:
    """The registry's transitions and the entries they added to ``ctx.memo``."""
    before = set(ctx.memo)
    found = registry.admissible_transitions(domain, ctx)
    return found, {key: value for key, value in ctx.memo.items() if key not in before}


def _helper_transitions(state: tuple[Any, ...]
                        ) -> tuple[dict[str, frozenset[tuple[ContactState, ContactState]]], dict[Any, Any]]:
    """:func:`_transitions_and_memo` in the solve's helper process, whose state ends with
    the setup's ``(ctx, domain, registry)``."""
    return _transitions_and_memo(*state[-1])


def relevant_states(ctx: PlanningContext, transitions: dict[str, frozenset[tuple[ContactState, ContactState]]]
                    ) -> frozenset[ContactState]:
    """States on some path from the symbolic start to the goal (reachable from the start
    and co-reachable to the goal through admissible transitions): no plan can use any
    other state, so the PDDL problem omits them (grounding grows with the square of the
    number of states)."""
    succ: dict[ContactState, set[ContactState]] = {}
    pred: dict[ContactState, set[ContactState]] = {}
    for pairs in transitions.values():
        for a, b in pairs:
            succ.setdefault(a, set()).add(b)
            pred.setdefault(b, set()).add(a)

    def closure(seed: ContactState, nxt: dict[ContactState, set[ContactState]]) -> set[ContactState]:
        seen, todo = {seed}, [seed]
        while todo:
            for t in nxt.get(todo.pop(), ()):
                if t not in seen:
                    seen.add(t)
                    todo.append(t)
        return seen

    return frozenset(closure(ctx.start_state, succ) & closure(ctx.goal_state, pred)) | {ctx.start_state, ctx.goal_state}
