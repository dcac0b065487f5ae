"""The MoveObject primitives: ``tip``, ``push``, ``biplanar-slide``, ``air-move``.

Each implementation lists the motion families it can start at a pose (pivots and senses
for ``tip``, edge directions for ``push``, pairs of kept contacts and senses for
``biplanar-slide``; see :mod:`geometry.kinematics`). Two uses:

- ``transitions(ctx)``: sweep every family from a few witness poses of every contact
  state; every pair of consecutive states met is a kinematically admissible transition
  (a static fact ``(can-<action> from to)`` of the PDDL problem).
- ``sample(ctx, from_state, to_state, start_pose, rng, limit)``: the stream. Sweep every
  family from the actual pose T_k; where the sweep leaves ``from_state`` directly into
  ``to_state``, propose end parameters: the end of the sweep where a new contact is made,
  or, when ``to_state`` holds over an interval, a few values in it (its two ends less a
  margin, a value drawn in it, and the value closest to the goal), ranked by the distance
  of the resulting pose to the goal contact pose T'_g (paper: samples limited and ranked
  by a light heuristic), ties broken at random. Every draw comes from the solve's seed.
"""

from __future__ import annotations

import functools
import logging
import math
from typing import TYPE_CHECKING, Any, Iterator

import numpy as np

from geometry.contacts import contact_points, principal_contacts
from geometry.grasps import motion_conditioned, pose_conditioned
from geometry.features import FREE, Contact, ContactKind, ContactState
from geometry.kinematics import Motion, MotionKind, Sweep, SweepEnd, kept_contact_holds, rotate_about, sweep, translate, two_contact
from geometry.poses import Pose, wrap_angle
from geometry.tolerances import CONTACT_TOL
from geometry.world import PolylineGripper, TwoPointGripper, World
from ldhp_tamp import budget
from ldhp_tamp.parallel import fork_map, two_at_a_time
from ldhp_tamp.path import Segment
from ldhp_tamp.primitives.registry import REGISTRY, Family

if TYPE_CHECKING:  # pragma: no cover
    from ldhp_tamp.contact_graph import PlanningContext

log = logging.getLogger(__name__)

#: A state piece shorter than this (mm of vertex motion) is a single instant.
INSTANT_MM = 0.5
#: Margin (mm of vertex motion) kept from the ends of an interval state.
MARGIN_MM = 2.0
#: Sampling step (mm of vertex motion) of the sweeps that find admissible transitions:
#: coarser than a stream's, since only the order of the states met matters there.
TRANSITION_STEP_MM = 3.0

#: Largest orientation error (mm of vertex motion at the object's radius) an air-move
#: leaves at its end: the in-state alignment's tolerance, far below the plan spec's 1 mm.
AIR_MOVE_ANGLE_MM = 0.05

Family_ = tuple[Motion, float, dict[str, Any]]


def _point_name(world: World, pose: Pose, point: np.ndarray) -> str:
    """The feature name of a contact point: the object vertex or environment vertex it
    coincides with, else the world point itself."""
    verts = world.object_vertices(pose)
    d = np.linalg.norm(verts - point, axis=1)
    if d.min() < 1e-3:
        return world.object.vertex_names[int(d.argmin())]
    d = np.linalg.norm(world.environment.vertices - point, axis=1)
    if d.min() < 1e-3:
        return world.environment.vertex_names[int(d.argmin())]
    return f"({point[0]:.1f}, {point[1]:.1f})"


def _consecutive_pairs(sw: Sweep) -> set[tuple[ContactState, ContactState]]:
    st = sw.states
    return {(a, b) for a, b in zip(st, st[1:]) if a != b}


def _sense_name(sense: int) -> str:
    return "ccw" if sense > 0 else "cw"


class _Swept:
    """Shared machinery of the sweep-based MoveObject primitives."""

    name = ""

    def families(self, ctx: PlanningContext, pose: Pose) -> list[Family_]:  # pragma: no cover
        raise NotImplementedError

    def transitions(self, ctx: PlanningContext) -> set[tuple[ContactState, ContactState]]:
        # One sweep per (witness pose, motion family), independent of each other: on the
        # machine's cores (ldhp_tamp.parallel; the same pairs on any number of them).
        where = f"the setup ({self.name} transitions)"
        motions = []
        for state in ctx.states:
            budget.check(ctx.deadline, where)
            if not state.is_free:
                motions += [(motion, s_max) for pose in ctx.witness_poses(state)
                            for motion, s_max, _ in self.families(ctx, pose)]

        def pairs_from(job: tuple[Motion, float]) -> set[tuple[ContactState, ContactState]]:
            budget.check(ctx.deadline, where)
            sw = sweep(ctx.world, job[0], job[1], step_mm=TRANSITION_STEP_MM, refine_bits=10)
            return _consecutive_pairs(sw)

        pairs: set[tuple[ContactState, ContactState]] = set()
        for found in fork_map(pairs_from, motions):
            pairs |= found
        return pairs

    def sample(self, ctx: PlanningContext, from_state: ContactState, to_state: ContactState,
               start_pose: Pose, rng: np.random.Generator, limit: int) -> Iterator[Segment]:
        scored: list[tuple[float, float, Segment]] = []
        families = list(self.families(ctx, start_pose))
        sweeps = _stream_sweeps(ctx, [(motion, s_max) for motion, s_max, _ in families])
        for (motion, s_max, params), sw in zip(families, sweeps):
            for s_end in _end_values(ctx, sw, from_state, to_state, rng):
                seg = self._segment(ctx, motion, s_end, from_state, to_state, params)
                score = float(ctx.goal_distance(seg.poses[-1:])[0])
                scored.append((score, float(rng.random()), seg))  # ties broken at random
        scored.sort(key=lambda t: (t[0], t[1]))
        for _, _, seg in scored[:limit]:
            yield seg

    def _segment(self, ctx: PlanningContext, motion: Motion, s_end: float, from_state: ContactState,
                 to_state: ContactState, params: dict[str, Any]) -> Segment:
        p = dict(params)
        if motion.kind is MotionKind.TRANSLATE:
            p["travel"] = round(s_end, 6)
        else:
            p["angle"] = round(math.degrees(s_end), 6)
        return Segment(self.name, from_state, to_state, motion, 0.0, s_end, ctx.world, p)


def _stream_sweeps(ctx: PlanningContext, jobs: list[tuple[Motion, float]]) -> list[Sweep]:
    """The streams' sweep of each (motion, s_max): memoised for the solve (a pure
    function of them; the top-tier iterations share their first steps), two at a time
    when the context offers a live helper process (``ctx.helper``), one in it and one
    here."""
    out: list[Sweep | None] = [ctx.memo.get(("sweep", m, s)) for m, s in jobs]
    todo = [i for i, sw in enumerate(out) if sw is None]
    done = two_at_a_time(ctx.helper() if ctx.helper is not None else None, [jobs[i] for i in todo],
                         lambda job: sweep(ctx.world, *job), lambda job: (_helper_sweep, job))
    for i, sw in zip(todo, done):
        out[i] = ctx.memo[("sweep", *jobs[i])] = sw
    return out  # type: ignore[return-value]


def _helper_sweep(state: tuple[Any, ...], motion: Motion, s_max: float) -> Sweep:
    """A stream's sweep in the helper process, whose state starts with the world."""
    return sweep(state[0], motion, s_max)


#: Where the halfway values between the goal value and an end of the interval may lie,
#: as fractions of the way (drawn uniformly from the seed; 1/2 without a generator).
HALFWAY_RANGE = (0.25, 0.75)


def _end_values(ctx: PlanningContext, sw: Sweep, from_state: ContactState, to_state: ContactState,
                rng: np.random.Generator | None = None) -> list[float]:
    """End parameters where ``sw`` goes from ``from_state`` straight into ``to_state``.

    With ``rng``, the interior samples are drawn: the "middle" of an interval anywhere in
    it (less the margins), the values between the goal value and each end anywhere in
    :data:`HALFWAY_RANGE` of the way; the ends and the goal value stay fixed. Without it,
    the middle and the halfway points."""
    pieces = sw.pieces
    if not pieces or pieces[0].state != from_state:
        return []
    speed = max(sw.motion.vertex_speed(ctx.world), 1e-9)
    for k in range(1, len(pieces)):
        if pieces[k].state == from_state:
            continue
        if pieces[k].state != to_state:
            return []
        a, b = pieces[k].s0, pieces[k].s1
        last = k == len(pieces) - 1
        if (b - a) * speed < INSTANT_MM:
            return [b] if last and sw.end is SweepEnd.BLOCKED else [0.5 * (a + b)]
        m = min(MARGIN_MM / speed, (b - a) / 4.0)
        mid = 0.5 * (a + b) if rng is None else a + m + float(rng.random()) * (b - a - 2.0 * m)
        values = [b - m, mid, a + m]
        if last and sw.end is SweepEnd.BLOCKED:
            values.insert(0, b)
        g = _goal_value(ctx, sw.motion, a + m, b - m)
        values.append(g)
        # Past and short of the goal value: halfway from it to each end of the interval.
        # The in-state alignment then brings the object back to T'_g (the paper's "short
        # motion within that state to align with T'_g"); a regrasp may only be possible
        # beyond the goal (Task 1: the lifting pinch is entered by a pivot about a finger
        # that holds the tipped block alone only past ~69 degrees, the goal being 60).
        for end in (b - m, a + m):
            w = 0.5 if rng is None else float(rng.uniform(*HALFWAY_RANGE))
            v = g + w * (end - g)
            if abs(v - g) * speed >= INSTANT_MM and all(abs(v - u) * speed >= INSTANT_MM for u in values):
                values.append(v)
        return values
    return []


def _goal_value(ctx: PlanningContext, motion: Motion, lo: float, hi: float) -> float:
    """The parameter in [lo, hi] whose pose is closest to the goal contact pose T'_g:
    exact for a rotation (the goal's orientation) and a translation (the projection of
    the goal's position), a 64-point grid search for a two-contact motion."""
    g = ctx.goal_contact.pose
    if motion.kind is MotionKind.ROTATE:
        s = float(wrap_angle(motion.sense * (g.theta - motion.start.theta)) % (2 * math.pi))
    elif motion.kind is MotionKind.TRANSLATE:
        d = np.asarray(motion.direction)
        s = float(np.dot([g.x - motion.start.x, g.y - motion.start.y], d))
    else:
        grid = np.linspace(lo, hi, 64)
        return float(grid[int(np.argmin(ctx.goal_distance(motion.poses(grid))))])
    if lo <= s <= hi:
        return s
    grid = np.array([lo, hi])
    return float(grid[int(np.argmin(ctx.goal_distance(motion.poses(grid))))])


def _point_contacts(world: World, pose: Pose) -> list[Contact]:
    """The principal contacts at ``pose`` as point contacts a motion can keep: vertex-edge
    and edge-vertex as they are; an edge-edge contact as the vertex-edge contacts of the
    object vertices that lie on the environment edge and the edge-vertex contacts of the
    convex environment vertices that lie on the object edge."""
    env = world.environment
    n = world.object.n
    out: list[Contact] = []
    p = pose.as_array()[None]
    for c in principal_contacts(world, pose):
        if c.kind is not ContactKind.EDGE_EDGE:
            out.append(c)
            continue
        for i in (c.obj, (c.obj + 1) % n):
            cand = Contact(ContactKind.VERTEX_EDGE, i, c.env)
            if kept_contact_holds(world, cand, p)[0]:
                out.append(cand)
        solid_next = c.env + 1 if c.env + 1 < env.m and env.edge_solid[c.env + 1] == env.edge_solid[c.env] else None
        ends = [c.env] + ([solid_next] if solid_next is not None else [])
        for k in ends:
            if env.vertex_convex[k]:
                cand = Contact(ContactKind.EDGE_VERTEX, c.obj, k)
                if kept_contact_holds(world, cand, p)[0]:
                    out.append(cand)
    return list(dict.fromkeys(out))


def _line_direction(world: World, c: Contact, pose: Pose) -> np.ndarray:
    """Tangent of the line a kept point contact stays on, at ``pose``."""
    if c.kind is ContactKind.VERTEX_EDGE:
        return world.environment.edge_directions[c.env]
    return pose.apply_vector(world.object.polygon.edge_directions[c.obj])


@REGISTRY.register("tip", Family.MOVE_OBJECT)
class Tip(_Swept):
    """Rotate the object about a sticking contact point: an object vertex on an
    environment edge, or a convex environment vertex on an object edge."""

    name = "tip"

    def families(self, ctx: PlanningContext, pose: Pose) -> list[Family_]:
        cp = contact_points(ctx.world, pose)
        pts = np.unique(np.round(cp.points, 9), axis=0) if len(cp) else np.empty((0, 2))
        out: list[Family_] = []
        for pt in pts:
            name = _point_name(ctx.world, pose, pt)
            for sense in (-1, 1):
                out.append((rotate_about(pose, pt, sense), math.pi,
                            {"pivot": name, "sense": _sense_name(sense)}))
        return out


@REGISTRY.register("push", Family.MOVE_OBJECT)
class Push(_Swept):
    """Translate the object along an environment edge it rests on, keeping that contact."""

    name = "push"

    def families(self, ctx: PlanningContext, pose: Pose) -> list[Family_]:
        world = ctx.world
        kept_by_edge: dict[int, list[Contact]] = {}
        for c in _point_contacts(world, pose):
            if c.kind is ContactKind.VERTEX_EDGE:
                kept_by_edge.setdefault(c.env, []).append(c)
        out: list[Family_] = []
        for j, kept in sorted(kept_by_edge.items()):
            d = world.environment.edge_directions[j]
            for sign in (1.0, -1.0):
                m = translate(pose, sign * d, kept)
                out.append((m, ctx.reach, {"edge": world.environment.edge_names[j],
                                           "direction": [round(float(sign * d[0]), 6), round(float(sign * d[1]), 6)]}))
        return out


@REGISTRY.register("biplanar-slide", Family.MOVE_OBJECT)
class BiplanarSlide(_Swept):
    """Rotate the object while it slides on two environment features at once."""

    name = "biplanar-slide"

    def families(self, ctx: PlanningContext, pose: Pose) -> list[Family_]:
        world = ctx.world
        pcs = _point_contacts(world, pose)
        out: list[Family_] = []
        for a in range(len(pcs)):
            for b in range(a + 1, len(pcs)):
                c1, c2 = pcs[a], pcs[b]
                if c1.kind == c2.kind and c1.env == c2.env:
                    continue  # same environment feature: a push or a tip, not two planes
                t1, t2 = _line_direction(world, c1, pose), _line_direction(world, c2, pose)
                if abs(t1[0] * t2[1] - t1[1] * t2[0]) < 1e-6:
                    continue  # parallel lines: no rotation keeps both
                for sense in (-1, 1):
                    try:
                        m = two_contact(world, pose, (c1, c2), sense)
                    except ValueError:
                        continue
                    out.append((m, math.pi, {"contacts": [c1.name, c2.name], "sense": _sense_name(sense)}))
        return out


#: Clearance (mm) kept above the environment by an air-move that carries the object over
#: it, besides the gripper's own reach below the object (its fingers may hang lower).
AIR_CLEARANCE_MM = 10.0
#: How far (mm) the admissibility sweeps of lifts and placements go: enough to leave a
#: resting contact (CONTACT_TOL) several times over.
AIR_PROBE_MM = 5.0


def _env_top(world: World, x0: float, x1: float) -> float:
    """Highest environment point (mm) over the vertical strip x0 <= x <= x1 (-inf if none)."""
    top = -math.inf
    for (ax, ay), (bx, by) in world.environment.edges:
        lo, hi = (ax, bx) if ax <= bx else (bx, ax)
        if hi < x0 or lo > x1:
            continue
        if abs(bx - ax) < 1e-12:
            top = max(top, ay, by)
            continue
        for x in (max(lo, x0), min(hi, x1)):
            top = max(top, ay + (by - ay) * (x - ax) / (bx - ax))
    return top


def _gripper_drop(world: World) -> float:
    """How far (mm) the gripper may reach below the object it holds: a finger's extent."""
    grip = world.gripper
    if isinstance(grip, PolylineGripper):
        v = grip.finger.vertices
        return float(np.max(np.linalg.norm(v[:, None, :] - v[None, :, :], axis=2)))
    assert isinstance(grip, TwoPointGripper)
    return 2.0 * float(grip.finger_radius)


def _same_orientation(ctx: PlanningContext, a: Pose, b: Pose) -> bool:
    """Whether ``a`` and ``b`` differ by a translation (to AIR_MOVE_ANGLE_MM of vertex motion)."""
    return abs(float(wrap_angle(a.theta - b.theta))) * ctx.world.object.polygon.radius <= AIR_MOVE_ANGLE_MM


@REGISTRY.register("air-move", Family.MOVE_OBJECT)
class AirMove:
    """Free-space motion between contact and non-contact (paper, Table I: params are
    waypoints; the object touches nothing in between). Translations only: the model has
    no rotation in the air.

    - Step 1 and Sub-step 3: from a start pose in the air down to its contact pose T'_0,
      and from the goal contact pose T'_g up to a goal pose in the air (one straight
      translation each, collision-free by construction of the contact poses).
    - Lift and place, when the goal is a contact pose: out of a contact state straight up
      (``s -> free``), and from the air onto the goal (``free -> goal state``): over to
      above the goal at the height reached, then straight down onto it. A lift is only
      useful at the goal's orientation (the placement cannot rotate), so it is admitted
      from the states with a witness at that orientation.
    """

    name = "air-move"

    def transitions(self, ctx: PlanningContext) -> set[tuple[ContactState, ContactState]]:
        pairs: set[tuple[ContactState, ContactState]] = set()
        if ctx.start_free:
            pairs.add((FREE, ctx.start_contact.state))
        if ctx.goal_free:
            pairs.add((ctx.goal_contact.state, FREE))
            return pairs
        up = (0.0, 1.0)
        holders = functools.cache(lambda: _air_holders(ctx, ctx.goal.theta))  # only if a pose needs it
        if _leaves_to_free(ctx, ctx.goal, ctx.goal_contact.state, up) and _carriable(ctx, ctx.goal, holders()):
            pairs.add((FREE, ctx.goal_contact.state))  # placed from above
        for state in ctx.states:
            if state.is_free:
                continue
            budget.check(ctx.deadline, "the setup (air-move transitions)")
            if any(_same_orientation(ctx, w, ctx.goal) and _leaves_to_free(ctx, w, state, up)
                   and _carriable(ctx, w, holders()) for w in ctx.witness_poses(state)):
                pairs.add((state, FREE))  # lifted straight up
        return pairs

    def sample(self, ctx: PlanningContext, from_state: ContactState, to_state: ContactState,
               start_pose: Pose, rng: np.random.Generator, limit: int) -> Iterator[Segment | tuple[Segment, ...]]:
        if from_state.is_free and ctx.start_free and to_state == ctx.start_contact.state:
            seg = self._straight(ctx, from_state, to_state, start_pose, ctx.start_contact.pose)
            if seg is not None:
                yield seg
        if to_state.is_free and ctx.goal_free:
            seg = self._straight(ctx, from_state, to_state, start_pose, ctx.goal)
            if seg is not None:
                yield seg
        if ctx.goal_free:
            return
        if from_state.is_free and to_state == ctx.goal_contact.state:
            legs = self._place(ctx, to_state, start_pose)
            if legs is not None:
                yield legs
        elif to_state.is_free and not from_state.is_free:
            seg = self._lift(ctx, from_state, start_pose)
            if seg is not None:
                yield seg

    def _straight(self, ctx: PlanningContext, from_state: ContactState, to_state: ContactState,
                  start_pose: Pose, target: Pose) -> Segment | None:
        """The Step-1 translation to ``target``."""
        d = np.array([target.x - start_pose.x, target.y - start_pose.y])
        dist = float(np.linalg.norm(d))
        # An in-state alignment reaches T'_g's orientation to within AIR_MOVE_ANGLE_MM of
        # vertex motion, not exactly: a translation then ends that close to the goal.
        if not _same_orientation(ctx, start_pose, target) or dist < 1e-9:
            if dist >= 1e-9:
                log.debug("air-move needs a rotation of %.4f degrees; only translations are modelled",
                          math.degrees(abs(float(wrap_angle(target.theta - start_pose.theta)))))
            return None
        return Segment(self.name, from_state, to_state, translate(start_pose, d), 0.0, dist, ctx.world,
                       {"waypoints": [list(start_pose.to_degrees()), list(target.to_degrees())],
                        "travel": round(dist, 6)})

    def _lift(self, ctx: PlanningContext, from_state: ContactState, start_pose: Pose) -> Segment | None:
        """Straight up until the object, and the gripper below it, clear the environment
        between here and the goal."""
        if not _same_orientation(ctx, start_pose, ctx.goal):
            return None
        here, there = ctx.world.object_vertices(start_pose), ctx.world.object_vertices(ctx.goal)
        x0 = float(min(here[:, 0].min(), there[:, 0].min()))
        x1 = float(max(here[:, 0].max(), there[:, 0].max()))
        clear = _env_top(ctx.world, x0, x1) + AIR_CLEARANCE_MM + _gripper_drop(ctx.world)
        h = max(clear - float(here[:, 1].min()), AIR_PROBE_MM)
        m = translate(start_pose, (0.0, 1.0))
        sw = sweep(ctx.world, m, h)
        if sw.end is not SweepEnd.LIMIT or sw.states[-1] != FREE or any(
                st not in (from_state, FREE) for st in sw.states):
            return None
        end = m.pose(h)
        return Segment(self.name, from_state, FREE, m, 0.0, h, ctx.world,
                       {"waypoints": [list(start_pose.to_degrees()), list(end.to_degrees())],
                        "travel": round(h, 6), "lift": True})

    def _place(self, ctx: PlanningContext, to_state: ContactState, start_pose: Pose) -> tuple[Segment, ...] | None:
        """Over to above the goal at this height, then straight down onto it."""
        goal = ctx.goal
        if not _same_orientation(ctx, start_pose, goal) or start_pose.y <= goal.y:
            return None
        legs: list[Segment] = []
        dx = goal.x - start_pose.x
        above = Pose(goal.x, start_pose.y, start_pose.theta)
        if abs(dx) > 1e-9:
            over = translate(start_pose, (math.copysign(1.0, dx), 0.0))
            sw = sweep(ctx.world, over, abs(dx))
            if sw.end is not SweepEnd.LIMIT or any(not st.is_free for st in sw.states):
                return None
            legs.append(Segment(self.name, FREE, FREE, over, 0.0, abs(dx), ctx.world,
                                {"waypoints": [list(start_pose.to_degrees()), list(above.to_degrees())],
                                 "travel": round(abs(dx), 6)}))
        drop = above.y - goal.y
        down = translate(above, (0.0, -1.0))
        sw = sweep(ctx.world, down, drop + AIR_PROBE_MM)
        if sw.end is not SweepEnd.BLOCKED or sw.states[-1] != to_state or abs(sw.s_end - drop) > CONTACT_TOL \
                or any(not st.is_free for st in sw.states[:-1]):
            return None
        end = down.pose(sw.s_end)
        legs.append(Segment(self.name, FREE, to_state, down, 0.0, sw.s_end, ctx.world,
                            {"waypoints": [list(above.to_degrees()), list(end.to_degrees())],
                             "travel": round(sw.s_end, 6), "place": True}))
        return tuple(legs)


def _air_holders(ctx: PlanningContext, theta: float) -> np.ndarray | None:
    """The grasps that hold the object in the air at orientation ``theta`` (the gripper
    and gravity only: :func:`geometry.grasps.motion_conditioned` over two poses far above
    the environment, where nothing else touches). Equilibrium depends on the orientation
    alone, so this is computed once. ``None`` without a grasp set in the context."""
    if ctx.grasps is None:
        return None
    w = ctx.workspace
    high = np.array([0.5 * (w.xmin + w.xmax), w.ymax + 10.0 * ctx.reach, theta])
    path = np.stack([high, high + [0.0, AIR_PROBE_MM, 0.0]])
    return motion_conditioned(ctx.world, ctx.grasps, path, np.arange(len(ctx.grasps))).indices


def _carriable(ctx: PlanningContext, pose: Pose, holders: np.ndarray | None) -> bool:
    """Whether one of ``holders`` (:func:`_air_holders`) fits at the contact pose ``pose``
    (the gripper clear of the environment, :func:`geometry.grasps.pose_conditioned`): the
    paper's air-move precondition, "a collision-free path exists with the same g", at the
    lift-off or touch-down pose. A block lying on the floor cannot be lifted by a pinch
    whose lower finger would be in the floor. Without a grasp set, every pose passes."""
    if holders is None or ctx.grasps is None:
        return True
    return bool(np.intersect1d(pose_conditioned(ctx.world, ctx.grasps, pose.as_array()), holders).size)


def _leaves_to_free(ctx: PlanningContext, pose: Pose, state: ContactState, direction: tuple[float, float]) -> bool:
    """Whether a translation from ``pose`` (in ``state``) goes straight into free space."""
    sw = sweep(ctx.world, translate(pose, direction), AIR_PROBE_MM, step_mm=1.0, refine_bits=10)
    return sw.end is SweepEnd.LIMIT and sw.states[0] == state and sw.states[-1] == FREE and len(sw.states) == 2
