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

import logging
import math
from typing import TYPE_CHECKING, Any, Iterator, Sequence

import numpy as np

from geometry.contacts import contact_points, contact_state, principal_contacts
from geometry.collision import gripper_env_overlap
from geometry.grasps import held_at_each, motion_conditioned
from geometry.features import FREE, Contact, ContactKind, ContactState
from geometry.kinematics import Motion, MotionKind, Sweep, SweepEnd, SweepPiece, kept_contact_holds, rotate_about, sweep, sweep_many, translate, two_contact
from geometry.poses import Pose, wrap_angle
from geometry.tolerances import CONTACT_TOL
from geometry.world import PolylineGripper, TwoPointGripper, World
from ldhp_tamp import budget
from ldhp_tamp.parallel import fork_map, two_halves
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
#: Sweeps walked side by side (:func:`geometry.kinematics.sweep_many`) when finding the
#: admissible transitions, about: the batches that the cores claim one at a time
#: (:func:`ldhp_tamp.parallel.fork_map`). Without a fork, all the sweeps are one batch.
TRANSITION_BATCH = 32
#: Fewest sweeps (of all the sweep-based primitives together) worth a forked process. A
#: forked child costs about 0.1 s of CPU time here (its copies of the pages the parent's
#: objects share) and 5-10 ms of the parent's; task 2 has 484 sweeps (its primitives
#: 88-240 each, 0.16-0.4 s in one process), task 1 50 (0.02-0.04 s a primitive). The
#: batches are claimed as the processes get free, so a child that waits for a core on a
#: loaded machine leaves them to the parent (an earlier static split made the parent
#: wait for it: task 2's sweeps took 1.4-2.0 s forked at load 3 on 2 cores, 0.7-1.1 s in
#: one process).
TRANSITION_FORK_MIN = 64

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


def _transit(sw: Sweep, nodes: frozenset[ContactState]) -> tuple[ContactState, ContactState, float] | None:
    """Where ``sw`` leaves a state of the graph for a degenerate one the graph leaves out
    (an object vertex on a convex environment vertex, see
    :func:`ldhp_tamp.contact_graph.proper_states`) and loses a kept contact there:
    ``(a, x, s)``, the state left, the degenerate state and a parameter inside it. A
    ladder slide over the slot's lip ends so (the top corner reaches the lip and the face
    that slid on it runs out); the motion goes on under another law (the corner down the
    wall), which :meth:`_Swept.transitions` and the streams follow."""
    pieces = sw.pieces
    for k in range(1, len(pieces)):
        if pieces[k].state in nodes:
            continue
        if k == len(pieces) - 1 and sw.end is SweepEnd.CONTACT_LOST and pieces[k - 1].state in nodes:
            return pieces[k - 1].state, pieces[k].state, 0.5 * (pieces[k].s0 + pieces[k].s1)
        return None
    return None


def _joint(motion: Motion, onward: Motion, lo: float, hi: float, guess: float) -> float:
    """The parameter of ``motion`` in [lo, hi] (widened by the interval's length each
    way) where its pose also satisfies ``onward``'s two contact lines, when ``onward`` is
    a two-contact motion (any other motion starts exactly where it is put): ``guess``
    otherwise, or when no such parameter is found."""
    if onward.kind is not MotionKind.TWO_CONTACT:
        return guess
    from scipy.optimize import minimize_scalar  # only the transits through an instant need it

    def gap(s: float) -> float:
        p = motion.poses([s])[0]
        q = onward.positions_at([p[2]])[0]
        d = float(np.hypot(p[0] - q[0], p[1] - q[1]))
        return d if math.isfinite(d) else 1e9

    width = max(hi - lo, 1e-9)
    res = minimize_scalar(gap, bounds=(max(lo - width, 0.0), hi + width), method="bounded",
                          options={"xatol": 1e-12})
    return float(res.x) if res.success and gap(float(res.x)) < min(gap(guess), 1e-6) else guess


def _from_instant(world: World, sw: Sweep, x: ContactState) -> Sweep:
    """``sw``, started in the degenerate state ``x``, with the brief states (pieces shorter
    than MARGIN_MM of vertex motion) it passes right after ``x`` counted as ``x``: at a
    vertex on a lip corner both faces at that vertex touch the wall within tolerance for
    a moment, which is one event, not a state to stop in."""
    pieces = list(sw.pieces)
    if not pieces or pieces[0].state != x:
        return sw
    speed = max(sw.motion.vertex_speed(world), 1e-9)
    while len(pieces) > 2 and (pieces[1].s1 - pieces[1].s0) * speed < MARGIN_MM:
        pieces[:2] = [SweepPiece(x, pieces[0].s0, pieces[1].s1)]
    return Sweep(sw.motion, tuple(pieces), sw.end)


def _onward(world: World, sw: Sweep, x: ContactState, nodes: frozenset[ContactState]) -> ContactState | None:
    """The graph state a sweep started in the degenerate state ``x`` enters first."""
    pieces = _from_instant(world, sw, x).pieces
    if len(pieces) < 2 or pieces[0].state != x or pieces[1].state not in nodes:
        return None
    return pieces[1].state


def _sense_name(sense: int) -> str:
    return "ccw" if sense > 0 else "cw"


def swept_transitions(ctx: PlanningContext, prims: Sequence["_Swept"]
                      ) -> list[set[tuple[ContactState, ContactState]]]:
    """The admissible transitions of each sweep-based primitive of ``prims``: the pairs of
    consecutive states along one sweep per (non-free state, witness pose, motion family of
    the primitive), and on through a vertex-on-vertex instant under the primitive's
    motion from there.

    The sweeps are independent of each other: every primitive's go into one list, walked
    side by side in batches (:func:`geometry.kinematics.sweep_many`, the same sweeps
    whatever the batch), the batches claimed by the machine's cores from
    ``TRANSITION_FORK_MIN`` sweeps on (:func:`ldhp_tamp.parallel.fork_map`: one forked
    child for all the primitives), else one batch in this process.
    """
    where = f"the setup ({', '.join(p.name for p in prims)} transitions)"
    jobs: list[tuple[int, Motion, float]] = []  # (primitive, motion, s_max)
    for i, prim in enumerate(prims):
        for state in ctx.states:
            budget.check(ctx.deadline, where)
            if not state.is_free:
                jobs += [(i, motion, s_max) for pose in ctx.witness_poses(state)
                         for motion, s_max, _ in prim.families(ctx, pose)]
    nodes = ctx.state_set

    def pairs_from(batch: list[tuple[int, Motion, float]]) -> list[set[tuple[ContactState, ContactState]]]:
        budget.check(ctx.deadline, where)
        found: list[set[tuple[ContactState, ContactState]]] = [set() for _ in prims]
        onward: list[tuple[Motion, float]] = []
        onward_of: list[tuple[int, ContactState, ContactState]] = []  # (primitive, a, x) of each onward job
        sweeps = sweep_many(ctx.world, [(m, s_max) for _, m, s_max in batch], step_mm=TRANSITION_STEP_MM,
                            refine_bits=10)
        for (i, _, _), sw in zip(batch, sweeps):
            found[i] |= _consecutive_pairs(sw)
            transit = _transit(sw, nodes)
            if transit is not None:  # on through a vertex-on-vertex instant, under another motion law
                a, x, s_x = transit
                for motion, s_max, _ in prims[i].families(ctx, sw.motion.pose(s_x)):
                    onward.append((motion, s_max))
                    onward_of.append((i, a, x))
        budget.check(ctx.deadline, where)
        for (i, a, x), after in zip(onward_of, sweep_many(ctx.world, onward, step_mm=TRANSITION_STEP_MM,
                                                          refine_bits=10)):
            b = _onward(ctx.world, after, x, nodes)
            if b is not None and b != a:
                found[i].add((a, b))
        return found

    # Batches of about TRANSITION_BATCH sweeps (every n-th job in each: neighbours, of
    # one state and primitive, tend to cost alike), claimed by the cores when there are
    # enough; else one batch, in this process.
    fork = len(jobs) >= TRANSITION_FORK_MIN
    n = max(1, math.ceil(len(jobs) / TRANSITION_BATCH)) if fork else 1
    out: list[set[tuple[ContactState, ContactState]]] = [set() for _ in prims]
    for found in fork_map(pairs_from, [jobs[i::n] for i in range(n)], None if fork else 1, min_items_per_core=1):
        for pairs, more in zip(out, found):
            pairs |= more
    return out


class _Swept:
    """Shared machinery of the sweep-based MoveObject primitives."""

    name = ""

    def families(self, ctx: PlanningContext, pose: Pose) -> list[Family_]:  # pragma: no cover
        raise NotImplementedError

    def transitions(self, ctx: PlanningContext) -> set[tuple[ContactState, ContactState]]:
        return swept_transitions(ctx, [self])[0]

    @staticmethod
    def transitions_together(ctx: PlanningContext, prims: Sequence["_Swept"]
                             ) -> list[set[tuple[ContactState, ContactState]]]:
        """The transitions of several sweep-based primitives at once (the registry asks
        the implementations sharing this function together): :func:`swept_transitions`."""
        return swept_transitions(ctx, prims)

    def sample(self, ctx: PlanningContext, from_state: ContactState, to_state: ContactState,
               start_pose: Pose, rng: np.random.Generator, limit: int) -> Iterator[Segment | tuple[Segment, ...]]:
        scored: list[tuple[float, float, Segment | tuple[Segment, ...]]] = []
        far: list[tuple[float, float, Segment | tuple[Segment, ...]]] = []  # the intervals' far ends
        families = list(self.families(ctx, start_pose))
        sweeps = _stream_sweeps(ctx, [(motion, s_max) for motion, s_max, _ in families])
        nodes = ctx.state_set
        for (motion, s_max, params), sw in zip(families, sweeps):
            ends = _end_values(ctx, sw, from_state, to_state, rng)
            for i, s_end in enumerate(ends):
                seg = self._segment(ctx, motion, s_end, from_state, to_state, params)
                score = float(ctx.goal_distance(seg.poses[-1:])[0])
                scored.append((score, float(rng.random()), seg))  # ties broken at random
                if i == 0 and len(ends) > 1:  # _end_values lists the far end first
                    far.append(scored[-1])
            transit = _transit(sw, nodes)
            if transit is None or transit[0] != from_state:
                continue
            # Through a vertex-on-vertex instant x (a state the graph leaves out): this
            # motion up to it, then another family of the primitive from there into to_state.
            _, x, s_x = transit
            piece = sw.pieces[-1]
            onward = list(self.families(ctx, motion.pose(s_x)))
            for (motion2, _, params2), sw2 in zip(onward, _stream_sweeps(ctx, [(m, s) for m, s, _ in onward])):
                ends = _end_values(ctx, _from_instant(ctx.world, sw2, x), x, to_state, rng)
                if not ends:
                    continue
                # Join the two motions where both hold exactly (a two-contact motion
                # re-solves its start onto its own contact lines).
                s_j = _joint(motion, motion2, piece.s0, piece.s1, s_x)
                first = self._segment(ctx, motion, s_j, from_state, x, params)
                if motion2.kind is MotionKind.TWO_CONTACT:
                    motion2 = two_contact(ctx.world, first.end, motion2.kept, motion2.sense)  # type: ignore[arg-type]
                for s_end in ends:
                    second = self._segment(ctx, motion2, s_end, x, to_state, params2)
                    score = float(ctx.goal_distance(second.poses[-1:])[0])
                    scored.append((score, float(rng.random()), (first, second)))
        scored.sort(key=lambda t: (t[0], t[1]))
        chosen = scored[:limit]
        if self.keep_far_end and limit >= 2 and far and not any(c in far for c in chosen):
            # The goal-ranked samples may all stop short of where the motion completes:
            # standing a lying block up into a corner (gen_slot_corner_start) ends
            # upside down, the farthest of the interval from the goal's orientation, and
            # only from there can it be lifted and turned in the air. The best-ranked far
            # end takes the last place.
            chosen = chosen[:-1] + [min(far, key=lambda t: (t[0], t[1]))]
        for _, _, seg in chosen:
            yield seg

    #: Whether the stream keeps the best-ranked far end of an interval among its samples
    #: (:meth:`sample`).
    keep_far_end = False

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
    function of them; the top-tier iterations share their first steps), walked side by
    side (:func:`geometry.kinematics.sweep_many`: the same sweeps, a batch's calls
    shared), every second one in the live helper process the context offers
    (``ctx.helper``), meanwhile (:func:`ldhp_tamp.parallel.two_halves`)."""
    out: list[Sweep | None] = [ctx.memo.get(("sweep", m, s)) for m, s in jobs]
    todo = [i for i, sw in enumerate(out) if sw is None]
    done = two_halves(ctx.helper() if ctx.helper is not None else None, [jobs[i] for i in todo],
                      lambda part: sweep_many(ctx.world, part), lambda part: (_helper_sweeps, (list(part),)))
    for i, sw in zip(todo, done):
        out[i] = ctx.memo[("sweep", *jobs[i])] = sw
    return out  # type: ignore[return-value]


def _helper_sweeps(state: tuple[Any, ...], jobs: list[tuple[Motion, float]]) -> list[Sweep]:
    """A stream's sweeps in the helper process, whose state starts with the world."""
    return sweep_many(state[0], jobs)


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
            # An instant: its end where the sweep stops there, else its middle; but the
            # refinement places a short piece's boundaries only to within the contact
            # tolerance (a ladder slide meets the wall with its top face 0.03 degrees
            # before it lies flat): the first of these where to_state does hold.
            tries = [b, 0.5 * (a + b)] if last else [0.5 * (a + b), b]
            for v in tries:
                if contact_state(ctx.world, sw.motion.pose(v)) == to_state:
                    return [v]
            return [tries[0]] if last and sw.end is SweepEnd.BLOCKED else [0.5 * (a + b)]
        m = min(MARGIN_MM / speed, (b - a) / 4.0)
        mid = 0.5 * (a + b) if rng is None else a + m + float(rng.random()) * (b - a - 2.0 * m)
        values = [b - m, mid, a + m]
        if last and sw.end is SweepEnd.BLOCKED and contact_state(ctx.world, sw.motion.pose(b)) == to_state:
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


def _point_contacts_at(ctx: PlanningContext, pose: Pose) -> list[Contact]:
    """:func:`_point_contacts` at ``pose``, memoised in ``ctx.memo`` (the push and the
    biplanar-slide families ask for the same witness poses)."""
    key = ("point-contacts", pose)
    if key not in ctx.memo:
        ctx.memo[key] = tuple(_point_contacts(ctx.world, pose))
    return list(ctx.memo[key])


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
        for c in _point_contacts_at(ctx, pose):
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
    keep_far_end = True  # a slide on two features completes where it lands (a block stood up into a corner)

    def families(self, ctx: PlanningContext, pose: Pose) -> list[Family_]:
        world = ctx.world
        pcs = _point_contacts_at(ctx, pose)
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
#: Largest turn (degrees) between the samples of an air-move's rotation, on top of the
#: 4 mm vertex step: the carried grasp is checked at every sample, and whether it holds
#: depends on the orientation (a small object's vertices move little per degree).
AIR_TURN_STEP_DEG = 2.0
#: Step 1 after a turn in the air (:meth:`AirMove._turned_downs`): the turns tried are
#: multiples of this (degrees), up to a quarter turn either way.
STEP1_TURN_DEG = 5.0


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


def _same_pose(a: Pose, b: Pose) -> bool:
    return bool(np.allclose(a.as_array(), b.as_array(), atol=1e-9))


def _same_orientation(ctx: PlanningContext, a: Pose, b: Pose) -> bool:
    """Whether ``a`` and ``b`` differ by a translation (to AIR_MOVE_ANGLE_MM of vertex motion)."""
    return abs(float(wrap_angle(a.theta - b.theta))) * ctx.world.object.polygon.radius <= AIR_MOVE_ANGLE_MM


def _centre(world: World, pose: Pose) -> np.ndarray:
    """The object's centre of mass in the world at ``pose``: what an air-move turns about."""
    return pose.apply(world.object.com[None])[0]


def _clear_height(ctx: PlanningContext, pose: Pose, target: Pose) -> float:
    """How far (mm) to raise the object from ``pose`` so that it, and the gripper below
    it, clear the environment by AIR_CLEARANCE_MM between here and ``target``: the object
    as it is when the orientations agree, else the disc it sweeps turning about its centre
    of mass, grown by the gripper's reach (the gripper turns with it)."""
    world = ctx.world
    drop = _gripper_drop(world)
    if _same_orientation(ctx, pose, target):
        here, there = world.object_vertices(pose), world.object_vertices(target)
        x0 = float(min(here[:, 0].min(), there[:, 0].min()))
        x1 = float(max(here[:, 0].max(), there[:, 0].max()))
        return _env_top(world, x0, x1) + AIR_CLEARANCE_MM + drop - float(here[:, 1].min())
    r = world.object.length_scale + drop
    c, t = _centre(world, pose), _centre(world, target)
    top = _env_top(world, float(min(c[0], t[0]) - r), float(max(c[0], t[0]) + r))
    return top + AIR_CLEARANCE_MM + r - float(c[1])


def _waypoints(a: Pose, b: Pose) -> list[list[float]]:
    return [list(a.to_degrees()), list(b.to_degrees())]


@REGISTRY.register("air-move", Family.MOVE_OBJECT)
class AirMove:
    """Free-space motion between contact and non-contact (paper, Table I: params are
    waypoints in T, object poses; the object touches nothing in between and the gripper
    moves rigidly with it, the grasp fixed). A move is a chain of legs, each a translation
    or a turn about the object's centre of mass, every one swept against the environment;
    the bottom tier checks the carried grasp at every sample (collision-free, equilibrium
    of gravity and the finger contacts at each orientation).

    - Step 1 and Sub-step 3: from a start pose in the air down to its contact pose T'_0,
      and from the goal contact pose T'_g up to a goal pose in the air (one straight
      translation each, collision-free by construction of the contact poses).
    - Lifts (``s -> free``) from every state with a witness pose that a translation
      straight up takes into free space and that a grasp holding the object in the air at
      that orientation fits (:func:`_carriable`), at whatever orientation. With the goal
      in the air the lift carries the object to it: straight up to a clearance height,
      a turn about the centre of mass to the goal's orientation, a straight translation
      to the goal. With the goal in contact, the lift ends at the clearance height.
    - Placements (``free -> goal state``), when the goal is a contact pose a translation
      straight up from which goes into free space: from the pose in the air, a turn to the
      goal's orientation (raised first if it would not clear), over to above the goal,
      then straight down onto it.
    """

    name = "air-move"

    def transitions(self, ctx: PlanningContext) -> set[tuple[ContactState, ContactState]]:
        pairs: set[tuple[ContactState, ContactState]] = set()
        if ctx.start_free:
            pairs.add((FREE, ctx.start_contact.state))
        if ctx.goal_free:
            pairs.add((ctx.goal_contact.state, FREE))
        up = (0.0, 1.0)
        if not ctx.goal_free and _leaves_to_free(ctx, ctx.goal, ctx.goal_contact.state, up) \
                and _carriable(ctx, ctx.goal):
            pairs.add((FREE, ctx.goal_contact.state))  # placed from above
        if not ctx.goal_free and (FREE, ctx.goal_contact.state) not in pairs:
            return pairs  # free space leads nowhere nearer the goal: no lift is worth admitting
        where = "the setup (air-move transitions)"
        budget.check(ctx.deadline, where)
        lifts = [(state, _lift_witnesses(ctx, state)) for state in ctx.states
                 if not state.is_free and (state, FREE) not in pairs]
        ups = _leave_to_free(ctx, [(w, state) for state, ws in lifts for w in ws], up)
        if ctx.grasps is not None:  # the holds at the orientations the lifts may be tried at, found together
            _air_holders_of_goal_each(ctx, [w.theta for w, ok in zip((w for _, ws in lifts for w in ws), ups)
                                            if ok and not _same_orientation(ctx, w, ctx.goal)])
        leaves = iter(ups)
        for state, witnesses in lifts:
            budget.check(ctx.deadline, where)
            up_ok = [next(leaves) for _ in witnesses]  # the probes, swept side by side beforehand
            if any(ok and _carriable(ctx, w) for ok, w in zip(up_ok, witnesses)):
                pairs.add((state, FREE))  # lifted straight up
        return pairs

    def sample(self, ctx: PlanningContext, from_state: ContactState, to_state: ContactState,
               start_pose: Pose, rng: np.random.Generator, limit: int) -> Iterator[Segment | tuple[Segment, ...]]:
        if from_state.is_free and ctx.start_free and to_state == ctx.start_contact.state:
            seg = self._straight(ctx, from_state, to_state, start_pose, ctx.start_contact.pose)
            if seg is not None:
                yield seg
            if _same_pose(start_pose, ctx.start):
                yield from self._turned_downs(ctx, to_state, start_pose, limit)
        if to_state.is_free and ctx.goal_free:
            seg = self._straight(ctx, from_state, to_state, start_pose, ctx.goal)
            if seg is not None:
                yield seg
            elif not from_state.is_free and _carriable(ctx, start_pose):
                legs = self._carry(ctx, from_state, start_pose, ctx.goal)
                if legs is not None:
                    yield legs
            return
        if ctx.goal_free:
            return
        if from_state.is_free and to_state == ctx.goal_contact.state:
            legs = self._place(ctx, to_state, start_pose)
            if legs is not None:
                yield legs
        elif to_state.is_free and not from_state.is_free and _carriable(ctx, start_pose):
            seg = self._up(ctx, from_state, start_pose, _clear_height(ctx, start_pose, ctx.goal))
            if seg is not None:
                yield seg

    def _straight(self, ctx: PlanningContext, from_state: ContactState, to_state: ContactState,
                  start_pose: Pose, target: Pose) -> Segment | None:
        """The Step-1 translation to ``target`` (at the same orientation)."""
        d = np.array([target.x - start_pose.x, target.y - start_pose.y])
        dist = float(np.linalg.norm(d))
        # An in-state alignment reaches T'_g's orientation to within AIR_MOVE_ANGLE_MM of
        # vertex motion, not exactly: a translation then ends that close to the goal.
        if not _same_orientation(ctx, start_pose, target) or dist < 1e-9:
            return None
        return Segment(self.name, from_state, to_state, translate(start_pose, d), 0.0, dist, ctx.world,
                       {"waypoints": _waypoints(start_pose, target), "travel": round(dist, 6)})

    def _turned_downs(self, ctx: PlanningContext, to_state: ContactState, start_pose: Pose,
                      limit: int) -> list[tuple[Segment, ...]]:
        """Step 1 after a turn in the air, for an object held at the start: a turn about
        its centre of mass by a multiple of ``STEP1_TURN_DEG`` (either way, up to a
        quarter turn), then straight down until it touches, in ``to_state``. Only turns
        through which the start grasp holds the object (every ``AIR_TURN_STEP_DEG``,
        finger contacts sticking) and after which it clears the environment where the
        object lands; the ``limit`` where that hold is firmest first (least reaction
        angle: the least fraction of the friction it needs). A start hold at the edge of
        its friction cone may not last the way down (task 1's inverse: wedged at 97 % of
        the cone at -60 degrees, at 48 % at -75). None into a state with a face on a face
        (it fixes the orientation); computed once per solve (``ctx.memo``)."""
        g = ctx.start_grasp
        if ctx.grasps is None or g is None or any(c.kind is ContactKind.EDGE_EDGE for c in to_state.contacts):
            return []  # (a face on a face fixes the orientation: no turn lands there)
        key = ("turned-downs", to_state, start_pose.as_array().tobytes(), limit)
        if key not in ctx.memo:
            ctx.memo[key] = self._turned_downs_of(ctx, to_state, start_pose, limit, g)
        return ctx.memo[key]

    def _turned_downs_of(self, ctx: PlanningContext, to_state: ContactState, start_pose: Pose, limit: int,
                         g: int) -> list[tuple[Segment, ...]]:
        from ldhp_tamp.contact_graph import ContactPoseError, contact_pose  # (it imports the registry)

        assert ctx.grasps is not None
        rows = np.array([g])
        scored: list[tuple[float, float, tuple[Segment, ...]]] = []
        for k in range(1, int(round(90.0 / STEP1_TURN_DEG)) + 1):
            for sense in (-1, 1):
                d = sense * math.radians(k * STEP1_TURN_DEG)
                theta = start_pose.theta + d
                if not motion_conditioned(ctx.world, ctx.grasps, _turn_path(ctx, start_pose.theta, theta, False),
                                          rows, rate=False).indices.size:
                    continue
                turn = self._turn(ctx, start_pose, theta)
                if turn is None or abs(float(wrap_angle(turn.s1 * turn.motion.sense - d))) > 1e-9:
                    continue  # blocked the short way
                try:  # Step 1 from the turned pose: the shortest axis translation into contact
                    landing_pose = contact_pose(ctx.world, turn.end, ctx.reach)
                except ContactPoseError:
                    continue
                if landing_pose.state != to_state or landing_pose.direction is None:
                    continue
                end = landing_pose.pose
                grip = ctx.grasps.world_gripper(end.as_array(), rows)
                if gripper_env_overlap(ctx.world, grip, ctx.grasps.width[rows]).any():
                    continue
                high = _turn_path(ctx, theta, theta, False)[:1]
                alpha = float(motion_conditioned(ctx.world, ctx.grasps, high, rows).alpha[0])
                landing = Segment(self.name, FREE, to_state, translate(turn.end, landing_pose.direction), 0.0,
                                  landing_pose.travel, ctx.world,
                                  {"waypoints": _waypoints(turn.end, end), "travel": round(landing_pose.travel, 6)})
                scored.append((alpha, abs(d), (turn, landing)))
        scored.sort(key=lambda x: (x[0], x[1]))
        return [legs for _, _, legs in scored[:limit]]

    def _up(self, ctx: PlanningContext, from_state: ContactState, start_pose: Pose, height: float) -> Segment | None:
        """Straight up by ``height`` (at least AIR_PROBE_MM) out of ``from_state`` into
        free space (``from_state`` free: staying in it)."""
        h = max(height, AIR_PROBE_MM)
        m = translate(start_pose, (0.0, 1.0))
        sw = sweep(ctx.world, m, h)
        if sw.end is not SweepEnd.LIMIT or sw.states[-1] != FREE or any(
                st not in (from_state, FREE) for st in sw.states):
            return None
        return Segment(self.name, from_state, FREE, m, 0.0, h, ctx.world,
                       {"waypoints": _waypoints(start_pose, m.pose(h)), "travel": round(h, 6), "lift": True})

    def _turn(self, ctx: PlanningContext, start_pose: Pose, theta: float) -> Segment | None:
        """In free space, a turn about the object's centre of mass to orientation
        ``theta``: the shorter way if it touches nothing, else the longer way."""
        d = float(wrap_angle(theta - start_pose.theta))
        centre = _centre(ctx.world, start_pose)
        for sense, angle in ((1 if d >= 0 else -1, abs(d)), (-1 if d >= 0 else 1, 2.0 * math.pi - abs(d))):
            m = rotate_about(start_pose, centre, sense)
            sw = sweep(ctx.world, m, angle)
            if sw.end is SweepEnd.LIMIT and all(st.is_free for st in sw.states):
                end = m.pose(angle)
                return Segment(self.name, FREE, FREE, m, 0.0, angle, ctx.world,
                               {"waypoints": _waypoints(start_pose, end), "angle": round(math.degrees(angle), 6),
                                "sense": _sense_name(sense),
                                "centre": [round(float(centre[0]), 6), round(float(centre[1]), 6)]},
                               turn_step=math.radians(AIR_TURN_STEP_DEG))
        return None

    def _over(self, ctx: PlanningContext, start_pose: Pose, target: Pose) -> Segment | None:
        """In free space, a straight translation to ``target``'s position."""
        d = np.array([target.x - start_pose.x, target.y - start_pose.y])
        dist = float(np.linalg.norm(d))
        m = translate(start_pose, d)
        sw = sweep(ctx.world, m, dist)
        if sw.end is not SweepEnd.LIMIT or any(not st.is_free for st in sw.states):
            return None
        end = Pose(target.x, target.y, start_pose.theta)
        return Segment(self.name, FREE, FREE, m, 0.0, dist, ctx.world,
                       {"waypoints": _waypoints(start_pose, end), "travel": round(dist, 6)})

    def _carry(self, ctx: PlanningContext, from_state: ContactState, start_pose: Pose,
               target: Pose) -> tuple[Segment, ...] | None:
        """Lift off and carry to ``target`` in the air: straight up to the clearance
        height, a turn to ``target``'s orientation, a straight translation to it."""
        up = self._up(ctx, from_state, start_pose, _clear_height(ctx, start_pose, target))
        if up is None:
            return None
        legs = [up]
        if not _same_orientation(ctx, up.end, target):
            turn = self._turn(ctx, up.end, target.theta)
            if turn is None:
                return None
            legs.append(turn)
        here = legs[-1].end
        if math.hypot(target.x - here.x, target.y - here.y) > 1e-9:
            over = self._over(ctx, here, target)
            if over is None:
                return None
            legs.append(over)
        return tuple(legs)

    def _place(self, ctx: PlanningContext, to_state: ContactState, start_pose: Pose) -> tuple[Segment, ...] | None:
        """From the air onto the goal: a turn to its orientation (raised first to the
        clearance height if below it), over to above the goal, then straight down."""
        goal = ctx.goal
        legs: list[Segment] = []
        here = start_pose
        if not _same_orientation(ctx, here, goal):
            rise = _clear_height(ctx, here, goal)
            if rise > CONTACT_TOL:
                up = self._up(ctx, FREE, here, rise)
                if up is None:
                    return None
                legs.append(up)
                here = up.end
            turn = self._turn(ctx, here, goal.theta)
            if turn is None:
                return None
            legs.append(turn)
            here = turn.end
        if here.y <= goal.y:
            return None
        above = Pose(goal.x, here.y, here.theta)
        if abs(goal.x - here.x) > 1e-9:
            over = self._over(ctx, here, above)
            if over is None:
                return None
            legs.append(over)
        drop = above.y - goal.y
        down = translate(above, (0.0, -1.0))
        sw = sweep(ctx.world, down, drop + AIR_PROBE_MM)
        if sw.end is not SweepEnd.BLOCKED or sw.states[-1] != to_state or abs(sw.s_end - drop) > CONTACT_TOL \
                or any(not st.is_free for st in sw.states[:-1]):
            return None
        end = down.pose(sw.s_end)
        legs.append(Segment(self.name, FREE, to_state, down, 0.0, sw.s_end, ctx.world,
                            {"waypoints": _waypoints(above, end), "travel": round(sw.s_end, 6), "place": True}))
        return tuple(legs)


def _high(ctx: PlanningContext, thetas: Sequence[float] | np.ndarray) -> np.ndarray:
    """Object poses (n, 3) far above the environment, where nothing else touches, at the
    orientations ``thetas``."""
    w = ctx.workspace
    out = np.empty((len(thetas), 3))
    out[:, 0] = 0.5 * (w.xmin + w.xmax)
    out[:, 1] = w.ymax + 10.0 * ctx.reach
    out[:, 2] = thetas
    return out


def _air_holders(ctx: PlanningContext, theta: float) -> np.ndarray:
    """The grasps that hold the object in the air at orientation ``theta``: the gripper
    and gravity only, the finger contacts sticking (:func:`geometry.grasps.motion_conditioned`
    at a pose far above the environment, where nothing else touches). Equilibrium depends
    on the orientation alone, so this is computed once per orientation in a solve
    (``ctx.memo``)."""
    assert ctx.grasps is not None
    key = ("air-holders", round(float(wrap_angle(theta)), 9))
    if key not in ctx.memo:
        ctx.memo[key] = motion_conditioned(ctx.world, ctx.grasps, _high(ctx, [theta]), np.arange(len(ctx.grasps)),
                                           rate=False).indices
    return ctx.memo[key]


def _air_holders_of_goal_each(ctx: PlanningContext, thetas: Sequence[float]) -> list[np.ndarray]:
    """For each orientation of ``thetas``, ``_air_holders(ctx, theta)`` among
    ``_air_holders(ctx, ctx.goal.theta)``: the grasps that hold the object in the air at
    both orientations. Each grasp is decided on its own, so only the goal's holders (a few
    hundred of thousands of grasps) are tested at ``theta``; the orientations not memoised
    yet (``ctx.memo``, once per orientation in a solve) in one
    :func:`geometry.grasps.held_at_each` call (the same sets as one call each, a fraction
    of the time: a call's fixed cost is most of one orientation's), each memoised at the
    first of ``thetas`` with its key."""
    assert ctx.grasps is not None
    keys = [("air-holders-of-goal", round(float(wrap_angle(theta)), 9)) for theta in thetas]
    todo: dict[tuple[str, float], float] = {}
    for key, theta in zip(keys, thetas):
        if key in ctx.memo or key in todo:
            continue
        full = ctx.memo.get(("air-holders", key[1]))
        if full is not None:
            ctx.memo[key] = np.intersect1d(full, _air_holders(ctx, ctx.goal.theta))
        else:
            todo[key] = theta
    if todo:
        goal = _air_holders(ctx, ctx.goal.theta)
        for key, held in zip(todo, held_at_each(ctx.world, ctx.grasps, _high(ctx, list(todo.values())), goal)):
            ctx.memo[key] = held
    return [ctx.memo[key] for key in keys]


def _lift_witnesses(ctx: PlanningContext, state: ContactState) -> list[Pose]:
    """The poses a lift out of ``state`` is looked for at: its witness poses for the
    transitions, then every other witness of its enumeration (a block on its corner has
    them at several tilts, and only some of them leave room for a carrying grasp)."""
    poses = list(ctx.witness_poses(state))
    for w in ctx.witnesses:
        if w.state == state:
            poses.extend(w.witnesses)
    unique: dict[bytes, Pose] = {}
    for p in poses:
        unique.setdefault(p.as_array().round(9).tobytes(), p)
    return list(unique.values())


def _turn_path(ctx: PlanningContext, theta0: float, theta1: float, longer: bool) -> np.ndarray:
    """Poses (n, 3) far above the environment at the orientations of a turn from
    ``theta0`` to ``theta1`` (the shorter way, or the longer), AIR_TURN_STEP_DEG apart."""
    d = float(wrap_angle(theta1 - theta0))
    if longer:
        d -= math.copysign(2.0 * math.pi, d) if d != 0.0 else 0.0
    n = max(1, int(math.ceil(abs(d) / math.radians(AIR_TURN_STEP_DEG))))
    return _high(ctx, theta0 + np.linspace(0.0, d, n + 1))


#: Candidates checked at a time along a turn when only whether one carries is asked.
CARRIER_BATCH = 64


def carriers(ctx: PlanningContext, pose: Pose, *, first: bool = False) -> np.ndarray | None:
    """The grasps that can lift the object off at the contact pose ``pose`` and carry it
    to the goal's orientation: the gripper clear of the environment at ``pose`` (as in
    :func:`geometry.grasps.pose_conditioned`), and the object held in the air by the
    gripper and gravity alone (the finger contacts sticking) at every orientation of a
    turn from the pose's to the goal's, AIR_TURN_STEP_DEG apart, the shorter way (the
    longer when none holds the shorter). The paper's air-move precondition, "a
    collision-free path exists with the same g", at the lift-off or touch-down pose: a
    block lying on the floor cannot be lifted by a pinch whose lower finger would be in
    the floor, nor turned through an orientation no grasp of it holds. ``first``: only
    whether there is one (the first batch of CARRIER_BATCH candidates that has any).
    Without a grasp set in the context: ``None``. :func:`carrier_candidates`, then
    :func:`carriers_among` them."""
    held = carrier_candidates(ctx, pose)
    return None if held is None else carriers_among(ctx, pose, held, first=first)


def carrier_candidates(ctx: PlanningContext, pose: Pose) -> np.ndarray | None:
    """The grasps :func:`carriers` turns: those that hold the object in the air at the
    pose's orientation (and the goal's) and are clear of the environment at ``pose``, a
    superset of the carriers (the turn starts at the pose's orientation), computed
    without the turn; ``None`` without a grasp set in the context."""
    found = carrier_candidates_each(ctx, [pose])
    return None if found is None else found[0]


def carrier_candidates_each(ctx: PlanningContext, poses: Sequence[Pose]) -> list[np.ndarray] | None:
    """:func:`carrier_candidates` of each pose of ``poses``, the holds at their
    orientations found together (:func:`_air_holders_of_goal_each`) and the gripper's
    overlap with the environment tested in one batch of (pose, grasp) pairs: the same
    sets as one pose at a time; ``None`` without a grasp set in the context."""
    if ctx.grasps is None:
        return None
    same = [_same_orientation(ctx, pose, ctx.goal) for pose in poses]
    turned = iter(_air_holders_of_goal_each(ctx, [pose.theta for pose, s in zip(poses, same) if not s]))
    # held at both ends (at the goal's orientation, the goal's holders)
    held = [_air_holders(ctx, pose.theta) if s else next(turned) for pose, s in zip(poses, same)]
    sizes = [h.size for h in held]
    if not sum(sizes):
        return held
    grip = np.concatenate([ctx.grasps.world_gripper(pose.as_array(), h) for pose, h in zip(poses, held)])
    clear = ~gripper_env_overlap(ctx.world, grip, ctx.grasps.width[np.concatenate(held)])
    return [h[ok] for h, ok in zip(held, np.split(clear, np.cumsum(sizes)[:-1]))]


def carriers_among(ctx: PlanningContext, pose: Pose, held: np.ndarray, *, first: bool = False) -> np.ndarray:
    """:func:`carriers` at ``pose`` given its :func:`carrier_candidates` ``held``: those
    that hold the object at every orientation of the turn to the goal's."""
    assert ctx.grasps is not None
    if not held.size or _same_orientation(ctx, pose, ctx.goal):
        return held
    for longer in (False, True):
        path = _turn_path(ctx, pose.theta, ctx.goal.theta, longer)
        for batch in np.array_split(held, -(-held.size // CARRIER_BATCH)) if first else [held]:
            ok = motion_conditioned(ctx.world, ctx.grasps, path, batch, rate=False).indices
            if ok.size:
                return ok
    return held[:0]


def _carriable(ctx: PlanningContext, pose: Pose) -> bool:
    """Whether some grasp lifts the object off at ``pose`` and carries it to the goal's
    orientation (:func:`carriers`; without a grasp set in the context, every pose passes)."""
    found = carriers(ctx, pose, first=True)
    return found is None or bool(found.size)


def _leaves_to_free(ctx: PlanningContext, pose: Pose, state: ContactState, direction: tuple[float, float]) -> bool:
    """Whether a translation from ``pose`` (in ``state``) goes straight into free space."""
    return _leave_to_free(ctx, [(pose, state)], direction)[0]


def _leave_to_free(ctx: PlanningContext, starts: list[tuple[Pose, ContactState]],
                   direction: tuple[float, float]) -> list[bool]:
    """:func:`_leaves_to_free` of each (pose, state), the probes swept side by side."""
    sweeps = sweep_many(ctx.world, [(translate(pose, direction), AIR_PROBE_MM) for pose, _ in starts],
                        step_mm=1.0, refine_bits=10)
    return [sw.end is SweepEnd.LIMIT and sw.states[0] == state and sw.states[-1] == FREE and len(sw.states) == 2
            for (_, state), sw in zip(starts, sweeps)]
