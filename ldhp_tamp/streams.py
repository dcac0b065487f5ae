"""Top tier, Step 3: from a contact-state plan to object-pose paths.

For each planned MoveObject transition s_k -> s_(k+1), the action's registered
implementation streams a few parameter samples from the current pose T_k, ranked by a
light heuristic (Sub-step 1); a depth-first search over those samples yields complete
pose paths T_0..T_n, one after the other, and after a failure of the bottom tier at step
j it backjumps to step j (:class:`PathSearch`). Before an ``air-move`` into free space, and
after the last transition when the goal is a contact pose, a short in-state motion
aligns the object with T'_g (Sub-step 2): a rotation about a kept contact point and a
translation along a kept edge, or a biplanar slide, whichever stays in the state and
ends at the target. Transitions for which no sample exists from any pose tried are
recorded, so the TAMP loop can turn them into constraints of the symbolic tier.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any, Iterator, Sequence

import numpy as np

from geometry.features import ContactState
from geometry.kinematics import Motion, MotionKind, SweepEnd, sweep
from geometry.poses import Pose, wrap_angle
from geometry.tolerances import CONTACT_TOL
from ldhp_tamp import budget
from ldhp_tamp.contact_graph import PlanningContext
from ldhp_tamp.path import Segment
from ldhp_tamp.primitives.move_object import MARGIN_MM, carrier_candidates_each, carriers_among
from ldhp_tamp.primitives.registry import DomainInfo, Family, PrimitiveRegistry, Transition

log = logging.getLogger(__name__)

#: Poses closer than this (mm, and mm at the object's radius for the angle) coincide.
ALIGN_TOL_MM = 0.05
#: Where along an in-state stretch a repositioning motion may end (fractions of it), in
#: the order they are tried.
REPOSITION_FRACTIONS = (0.5, 1.0, 0.25, 0.75)
#: Most repositioning poses tried for a transition with no sample from the actual pose.
MAX_REPOSITIONS = 12
#: The work budget of one contact-state plan's search: samples drawn, and calls of a
#: primitive's ``sample`` (a sweep per motion family, ~5-30 ms each on the paper's tasks).
MAX_EXPANSIONS = 200
MAX_SAMPLE_CALLS = 150
#: Repositioning motions shorter than this (mm of vertex motion) are not worth a step.
REPOSITION_MIN_MM = 5.0
#: Distance (mm of vertex motion) a repositioning motion keeps from the state's boundary.
REPOSITION_MARGIN_MM = 2.0


@dataclass(frozen=True, eq=False)
class PosePath:
    """An object-pose path: MoveObject segments whose ends join."""

    segments: tuple[Segment, ...]

    @property
    def layer_poses(self) -> tuple[Pose, ...]:
        """T_0..T_n: the start of the first segment and the end of every segment."""
        if not self.segments:
            return ()
        return (self.segments[0].start,) + tuple(s.end for s in self.segments)

    @property
    def primitives(self) -> tuple[str, ...]:
        return tuple(s.primitive for s in self.segments)


@dataclass
class StreamStats:
    """What the streams tried: samples drawn, work spent, and where they found none."""

    expansions: int = 0  # samples drawn (segments handed to the next level)
    sample_calls: int = 0  # calls of a primitive's sample(), the unit of the work budget
    dead_ends: Counter = field(default_factory=Counter)  # Transition -> count
    dead_steps: Counter = field(default_factory=Counter)  # planned step index -> count
    alignment_failures: Counter = field(default_factory=Counter)  # state -> count
    repositions: int = 0  # in-state repositioning motions tried
    budget_exhausted: bool = False  # the search stopped because max_sample_calls ran out
    deepest: int = -1  # the deepest planned step the search drew samples for


def _close(a: Pose, b: Pose, radius: float) -> bool:
    d, th = a.distance(b)
    return d <= ALIGN_TOL_MM and th * radius <= ALIGN_TOL_MM


#: A motion blocked this close (mm of vertex motion) to its end still reaches it: it ends
#: by making a contact (an alignment that settles a block flat on the floor).
SETTLE_MM = 1e-3


def _stays(ctx: PlanningContext, motion: Motion, s_end: float, state: ContactState) -> bool:
    """Whether ``motion`` can run to ``s_end`` without leaving ``state``.

    A motion blocked at its very end (within ``SETTLE_MM``) counts: contact states are
    identified within ``CONTACT_TOL``, so a block can be in the state "l1 on the floor"
    while 0.05 degrees off flat, and the rotation that aligns it ends exactly where it
    lands flat."""
    if s_end <= 0.0:
        return True
    sw = sweep(ctx.world, motion, s_end)
    if not all(p.state == state for p in sw.pieces):
        return False
    if sw.end is SweepEnd.LIMIT:
        return True
    return sw.end is SweepEnd.BLOCKED and (s_end - sw.s_end) * motion.vertex_speed(ctx.world) <= SETTLE_MM


def align(ctx: PlanningContext, domain: DomainInfo, registry: PrimitiveRegistry, state: ContactState,
          pose: Pose, target: Pose) -> list[Segment] | None:
    """In-state motions from ``pose`` to ``target`` (both in ``state``), or ``None``.

    Tries, with the MoveObject primitives the domain declares: a rotation about a contact
    point (``tip``) followed by a translation along a kept edge (``push``); a translation
    alone; a biplanar slide by the angle difference.
    """
    radius = ctx.world.object.polygon.radius
    if _close(pose, target, radius):
        return []
    declared = set(domain.names(Family.MOVE_OBJECT))
    dth = float(wrap_angle(target.theta - pose.theta))
    sense = 1 if dth >= 0 else -1

    def translate_to(p: Pose) -> list[Segment] | None:
        if _close(p, target, radius):
            return []
        if "push" not in declared or abs(wrap_angle(target.theta - p.theta)) * radius > ALIGN_TOL_MM:
            return None
        d = np.array([target.x - p.x, target.y - p.y])
        for motion, _, params in registry.implementation("push").families(ctx, p):
            # along the push line; what is left across it is a contact-tolerance offset
            # (a block resting 0.06 mm above the floor is on the floor)
            u = float(np.dot(motion.direction, d))
            if u > 0.0 and float(np.linalg.norm(d - u * np.asarray(motion.direction))) <= CONTACT_TOL \
                    and _stays(ctx, motion, u, state):
                return [_seg("push", state, motion, u, ctx, params, travel=u)]
        return None

    # a translation alone
    out = translate_to(pose)
    if out is not None:
        return out
    # a rotation about a contact point, then a translation
    if "tip" in declared:
        for motion, _, params in registry.implementation("tip").families(ctx, pose):
            if motion.sense != sense or not _stays(ctx, motion, abs(dth), state):
                continue
            rot = _seg("tip", state, motion, abs(dth), ctx, params, angle=math.degrees(abs(dth)))
            rest = translate_to(rot.end)
            if rest is not None:
                return [rot] + rest
    # a biplanar slide
    if "biplanar-slide" in declared:
        for motion, _, params in registry.implementation("biplanar-slide").families(ctx, pose):
            if motion.sense != sense or not _stays(ctx, motion, abs(dth), state):
                continue
            seg = _seg("biplanar-slide", state, motion, abs(dth), ctx, params, angle=math.degrees(abs(dth)))
            if _close(seg.end, target, radius):
                return [seg]
    return None


def _seg(name: str, state: ContactState, motion: Motion, s_end: float, ctx: PlanningContext,
         params: dict, **extra: float) -> Segment:
    p = dict(params)
    p.update({k: round(v, 6) for k, v in extra.items()})
    p["in_state"] = True
    return Segment(name, state, state, motion, 0.0, s_end, ctx.world, p)


#: How far (a fraction of the stretch, either way) a seeded repositioning fraction below 1
#: may be moved from its nominal value: a quarter-width bin around it.
REPOSITION_JITTER = 0.125


def reposition(ctx: PlanningContext, domain: DomainInfo, registry: PrimitiveRegistry, state: ContactState,
               pose: Pose, fractions: Sequence[float] = REPOSITION_FRACTIONS,
               rng: np.random.Generator | None = None) -> list[Segment]:
    """In-state motions from ``pose``: for every motion family of every MoveObject
    primitive the domain declares, the stretch over which the object stays in ``state``,
    sampled at ``fractions`` of its length (shorter than ``REPOSITION_MIN_MM`` of vertex
    motion is skipped). These are the "short motions within a state" of the paper's
    Sub-step 2, used here before a transition as well as at the ends: a transition that
    is admissible from one pose of a state may be blocked from another (a block standing
    20 mm from a wall cannot tip towards it, but can once pushed along the floor).

    With ``rng``, each fraction below 1 is drawn within ``REPOSITION_JITTER`` of its
    nominal value (one draw per fraction); the full stretch (1) stays."""
    stretches: list[tuple[str, Motion, float, float, dict]] = []
    for name in domain.names(Family.MOVE_OBJECT):
        impl = registry.implementation(name)
        families = getattr(impl, "families", None)
        if families is None:
            continue
        for motion, s_max, params in families(ctx, pose):
            sw = sweep(ctx.world, motion, s_max)
            pieces = sw.pieces
            if not pieces or pieces[0].state != state:
                continue
            stay = pieces[0].s1
            speed = motion.vertex_speed(ctx.world)
            if len(pieces) > 1 or sw.end is SweepEnd.BLOCKED:
                # keep clear of the state's boundary
                stay -= min(REPOSITION_MARGIN_MM / max(speed, 1e-9), 0.25 * stay)
            stretches.append((name, motion, stay, speed, params))
    if rng is not None:
        fractions = [f if f >= 1.0 else f + float(rng.uniform(-REPOSITION_JITTER, REPOSITION_JITTER))
                     for f in fractions]
    out: list[Segment] = []
    for f in fractions:  # every family at the first fraction, then at the next one, ...
        for name, motion, stay, speed, params in stretches:
            s_end = f * stay
            if s_end * speed < REPOSITION_MIN_MM:
                continue
            key = "angle" if motion.kind is not MotionKind.TRANSLATE else "travel"
            val = math.degrees(s_end) if key == "angle" else s_end
            out.append(_seg(name, state, motion, s_end, ctx, params, **{key: val}))
    return out


class PathSearch:
    """Object-pose paths for a contact-state plan, best-ranked samples first: a depth-first
    search over the stream samples of each transition that *backjumps*.

    Level k draws the samples of transition k from the pose T_k that level k - 1 left
    (at most ``limit`` per pose, ranked by the heuristic distance to T'_g; when there is
    none, samples from poses reached by an in-state motion, :func:`reposition`). Each
    complete path is returned by :meth:`next`; when the bottom tier then fails at planned
    step j, ``next(j)`` drops every deeper level and continues with the next sample of
    level j (then j - 1, ...): the steps after j cannot repair a failure at j, so a plain
    depth-first order, which varies the last step first, would return paths that fail the
    same way. Iterating the search is ``next()`` without feedback.

    The search is bounded by work, not time (so that a seed gives one result):
    ``max_sample_calls`` calls of a primitive's ``sample`` (a sweep per motion family;
    repositioning included) and ``max_expansions`` samples drawn. A level left without a
    single sample is a dead end, recorded in ``stats`` (by transition and by step), and
    so is an end pose that no in-state motion aligns with T'_g. Past ``deadline`` (a
    :func:`time.perf_counter` value) :class:`~ldhp_tamp.errors.TimeBudgetExceeded` is raised.
    """

    def __init__(self, ctx: PlanningContext, transitions: Sequence[Transition], domain: DomainInfo,
                 registry: PrimitiveRegistry, rng: np.random.Generator, stats: StreamStats, *,
                 limit: int | None = None, max_expansions: int = MAX_EXPANSIONS,
                 max_sample_calls: int = MAX_SAMPLE_CALLS, deadline: float | None = None) -> None:
        self.ctx = ctx
        self.transitions = tuple(transitions)
        self.domain = domain
        self.registry = registry
        self.rng = rng
        self.stats = stats
        self.limit = ctx.stream_samples if limit is None else limit
        self.max_expansions = max_expansions
        self.max_sample_calls = max_sample_calls
        self.deadline = deadline
        self._stack: list[_Level] = []
        self._started = False

    def __iter__(self) -> "PathSearch":
        return self

    def __next__(self) -> PosePath:
        path = self.next()
        if path is None:
            raise StopIteration
        return path

    def next(self, failed_step: int | None = None) -> PosePath | None:
        """The next complete pose path, or ``None`` when the search is exhausted.

        ``failed_step``: the planned step (``Segment.step``) at which the previous path
        failed; the next path differs from it at that step or an earlier one.
        """
        budget.check(self.deadline, "the top tier's streams (object-pose paths)")
        if not self._started:
            self._started = True
            start = self.ctx.start if self.ctx.start_free else self.ctx.start_contact.pose
            if not self.transitions:  # start and goal in one state: only the alignment
                return self._finish(start, ())
            self._stack.append(self._level(0, start, ()))
        elif failed_step is not None:
            del self._stack[max(int(failed_step), 0) + 1:]
        n = len(self.transitions)
        while self._stack:
            budget.check(self.deadline, "the top tier's streams (object-pose paths)")
            level = self._stack[-1]
            moves = next(level.candidates, None) if self.stats.expansions < self.max_expansions else None
            if moves is None:
                self._stack.pop()
                if not level.found and not self.stats.budget_exhausted and self.stats.expansions < self.max_expansions:
                    self._dead_end(level.k)
                continue
            key = b"".join(m.primitive.encode() + np.round(np.asarray(m.poses), 6).tobytes() for m in moves)
            if key in level.seen:  # two candidates with one motion (e.g. the goal value is an end)
                continue
            level.seen.add(key)
            self.stats.expansions += 1
            self.stats.deepest = max(self.stats.deepest, level.k)
            moves = tuple(replace(m, step=level.k) for m in moves)
            segments = level.prefix + level.pre + moves
            if level.k + 1 < n:
                level.found = True
                self._stack.append(self._level(level.k + 1, moves[-1].end, segments))
                continue
            path = self._finish(moves[-1].end, segments)
            if path is not None:
                level.found = True
                return path
        return None

    # ---- levels ------------------------------------------------------------------------

    def _level(self, k: int, pose: Pose, prefix: tuple[Segment, ...]) -> "_Level":
        t = self.transitions[k]
        pre: tuple[Segment, ...] = ()
        if t.action == "air-move" and t.to_state.is_free and self.ctx.goal_free \
                and t.from_state == self.ctx.goal_contact.state:
            # Sub-step 2 before Sub-step 3: align with T'_g within the state, then leave it.
            tail = align(self.ctx, self.domain, self.registry, t.from_state, pose, self.ctx.goal_contact.pose)
            if tail is None:
                self.stats.alignment_failures[t.from_state] += 1
                return _Level(k, prefix, (), iter(()))
            pre = tuple(replace(a, step=k) for a in tail)
            if pre:
                pose = pre[-1].end
        after = self.transitions[k + 1] if k + 1 < len(self.transitions) else None
        lift_next = after is not None and after.action == "air-move" and after.to_state.is_free \
            and after.from_state == t.to_state and not t.to_state.is_free
        return _Level(k, prefix, pre, self._candidates(t, pose, lift_next))

    def _finish(self, pose: Pose, segments: tuple[Segment, ...]) -> PosePath | None:
        """The complete path: ``segments`` and, when the goal is a contact pose, the
        in-state alignment from ``pose`` to it (Sub-step 2)."""
        n = len(self.transitions)
        if not self.ctx.goal_free:
            last_state = self.transitions[-1].to_state if n else self.ctx.start_state
            tail = align(self.ctx, self.domain, self.registry, last_state, pose, self.ctx.goal)
            if tail is None:
                self.stats.alignment_failures[last_state] += 1
                return None
            segments = segments + tuple(replace(a, step=max(n - 1, 0)) for a in tail)
        return PosePath(segments)

    def _dead_end(self, k: int) -> None:
        self.stats.dead_ends[self.transitions[k]] += 1
        self.stats.dead_steps[k] += 1

    def _charge(self, calls: int) -> bool:
        """Spend ``calls`` sample calls of the work budget; ``False`` (and the budget marked
        spent) when they do not fit."""
        if self.stats.sample_calls + calls > self.max_sample_calls:
            self.stats.budget_exhausted = True
            return False
        self.stats.sample_calls += calls
        return True

    def _sample(self, impl: object, t: Transition, pose: Pose) -> list[tuple[Segment, ...]] | None:
        """One stream call within the work budget (``None`` once it is spent). A sample is
        one segment, or several joined ones (an air-move over and down onto the goal)."""
        if not self._charge(1):
            return None
        return [s if isinstance(s, tuple) else (s,)
                for s in impl.sample(self.ctx, t.from_state, t.to_state, pose,  # type: ignore[attr-defined]
                                     self.rng, self.limit)]

    def _lift_offs(self, t: Transition, samples: list[tuple[Segment, ...]]) -> list[tuple[Segment, ...]]:
        """The samples of ``t`` with their last motion ended instead where the most grasps
        can lift the object off and carry it to the goal's orientation
        (:func:`ldhp_tamp.primitives.move_object.carriers`, the statics of the hold at every
        orientation of the turn), on a grid ``LIFT_OFF_STEP_MM`` of vertex motion apart
        over the stretch of that motion in ``t.to_state`` (less ``MARGIN_MM`` at its
        ends): the best ``limit`` of them, most carriers first, none without a carrier.
        The next step lifts the object off where this one leaves it, and the goal-ranked
        ends may all miss the window where a carrying grasp both fits beside the
        environment and can be reached (task 1 held flat in the air: the tip's ends at
        1.4, 45 and 88.6 degrees, the lever pinch that carries the block to flat from 66
        to 82 degrees only).

        The ranking is (carriers, most first; the end's distance to the goal; the order
        found). A pose's carriers are among its candidates (held at its orientation and
        clear of the environment, :func:`_lift_off_candidates`), which cost about half as
        much as the turn that decides them: the poses are taken by their candidates' count
        and the turn is made only while a pose can still rank among the best ``limit``
        (its count bounds its carriers'), so the same poses come first as with every
        pose's carriers counted."""
        ctx = self.ctx
        if ctx.grasps is None or self.limit < 1:
            return []
        entries: list[tuple[int, float, int, float, np.ndarray, np.ndarray, tuple[Any, ...], tuple[Segment, ...]]] = []
        done: set[tuple[object, float]] = set()
        for moves in samples:
            seg = moves[-1]
            if seg.to_state != t.to_state or (seg.motion, seg.s0) in done:
                continue
            done.add((seg.motion, seg.s0))
            key = ("lift-off-candidates", seg.motion, seg.s0, t.to_state)
            if key not in ctx.memo:
                ctx.memo[key] = _lift_off_candidates(ctx, seg, t.to_state)
            for value, pose, held in ctx.memo[key]:
                end = seg.motion.poses([value])
                entries.append((-held.size, float(ctx.goal_distance(end)[0]), len(entries), value, pose, held, key,
                                moves))
        entries.sort(key=lambda x: x[:3])
        best: list[tuple[int, float, int, float, tuple[Segment, ...]]] = []  # (-carriers, distance, order, ...)
        for bound, distance, order, value, pose, held, key, moves in entries:
            if len(best) >= self.limit and best[self.limit - 1][:3] < (bound, distance, order):
                break  # no pose left can rank among the best: its carriers are at most its candidates
            count_key = ("lift-off-carriers",) + key[1:] + (value,)
            if count_key not in ctx.memo:
                ctx.memo[count_key] = int(carriers_among(ctx, Pose.from_array(pose), held).size)
            if ctx.memo[count_key]:
                best.append((-ctx.memo[count_key], distance, order, value, moves))
                best.sort(key=lambda x: x[:3])
        out = []
        for _, _, _, value, moves in best[:self.limit]:
            seg = moves[-1]
            param = "travel" if seg.motion.kind is MotionKind.TRANSLATE else "angle"
            length = abs(value - seg.s0)
            params = dict(seg.parameters, **{param: round(length if param == "travel" else math.degrees(length), 6)})
            out.append(moves[:-1] + (replace(seg, s1=float(value), parameters=params),))
        return out

    def _candidates(self, t: Transition, pose: Pose, lift_next: bool = False) -> Iterator[tuple[Segment, ...]]:
        """A transition's stream: the primitive's own samples from ``pose``; when it has
        none, samples from poses reached by an in-state motion (:func:`reposition`, at
        most ``MAX_REPOSITIONS`` of them), ranked by the distance of their end pose to T'_g.
        Before a lift out of the state the transition enters (``lift_next``), its samples
        ended where the object is best lifted off come first (:meth:`_lift_offs`)."""
        impl = self.registry.implementation(t.action)
        own = self._sample(impl, t, pose)
        if own:
            if lift_next:
                yield from self._lift_offs(t, own)
            yield from own
        if own is None or own or t.from_state.is_free:
            return
        # repositioning sweeps every family of every primitive: a sample call's worth each
        if not self._charge(len(self.domain.names(Family.MOVE_OBJECT))):
            return
        scored: list[tuple[float, float, tuple[Segment, ...]]] = []
        for pre in reposition(self.ctx, self.domain, self.registry, t.from_state, pose,
                              rng=self.rng)[:MAX_REPOSITIONS]:
            self.stats.repositions += 1
            samples = self._sample(impl, t, pre.end)
            if samples is None:
                break
            for moves in samples:
                end = moves[-1].poses[-1:]
                scored.append((float(self.ctx.goal_distance(end)[0]), float(self.rng.random()), (pre,) + moves))
        scored.sort(key=lambda x: (x[0], x[1]))
        for _, _, moves in scored[:self.limit]:
            yield moves


#: Grid step (mm of vertex motion) of the lift-off poses looked at along a motion before a lift.
LIFT_OFF_STEP_MM = 10.0


def _lift_off_candidates(ctx: PlanningContext, seg: Segment, state: ContactState
                         ) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """``(parameter, pose, candidates)`` along ``seg``'s motion where it stays in ``state``, on
    the grid of :meth:`PathSearch._lift_offs`, for the values with a candidate: the grasps
    that hold the object in the air at the pose's orientation and the goal's and are clear
    of the environment there (:func:`ldhp_tamp.primitives.move_object.carrier_candidates`,
    a superset of the pose's carriers).

    The poses' holds are found together and their gripper overlaps in one batch
    (:func:`ldhp_tamp.primitives.move_object.carrier_candidates_each`): the same sets as
    one pose at a time, in a fraction of the time (one pose's call is mostly fixed cost),
    so they are not shared out to another process."""
    motion = seg.motion
    s_max = ctx.reach if motion.kind is MotionKind.TRANSLATE else math.pi
    sw = sweep(ctx.world, motion, s_max)
    piece = next((p for p in sw.pieces if p.state == state and p.s0 <= seg.s1 <= p.s1 + 1e-12), None)
    if piece is None:
        return []
    speed = max(motion.vertex_speed(ctx.world), 1e-9)
    a, b = piece.s0, piece.s1
    margin = min(MARGIN_MM / speed, (b - a) / 4.0)
    n = int(math.ceil((b - a - 2.0 * margin) * speed / LIFT_OFF_STEP_MM))
    if n < 1:
        return []
    values = np.linspace(a + margin, b - margin, n + 1)
    poses = list(motion.poses(values))
    found = carrier_candidates_each(ctx, [Pose.from_array(p) for p in poses]) or [np.zeros(0, np.int64)] * len(poses)
    return [(float(value), pose, held) for value, pose, held in zip(values, poses, found) if held.size]


@dataclass(eq=False)
class _Level:
    """One level of :class:`PathSearch`: transition ``k`` after ``prefix`` (and the
    in-state alignment ``pre`` before an air-move into free space)."""

    k: int
    prefix: tuple[Segment, ...]
    pre: tuple[Segment, ...]
    candidates: Iterator[tuple[Segment, ...]]
    found: bool = False
    seen: set[bytes] = field(default_factory=set)  # the motions drawn so far


#: The pose paths of a contact-state plan (the name the stream stage had before it
#: backjumped): iterate the search, or call its ``next(failed_step)`` after a failure.
pose_paths = PathSearch
