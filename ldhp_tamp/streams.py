"""Top tier, Step 3: from a contact-state plan to object-pose paths.

For each planned MoveObject transition s_k -> s_(k+1), the action's registered
implementation streams a few parameter samples from the current pose T_k, ranked by a
light heuristic (Sub-step 1); a depth-first search over those samples yields complete
pose paths T_0..T_n, one after the other. Before an ``air-move`` into free space, and
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
from typing import Iterator, Sequence

import numpy as np

from geometry.features import ContactState
from geometry.kinematics import Motion, MotionKind, SweepEnd, sweep
from geometry.poses import Pose, wrap_angle
from ldhp_tamp import budget
from ldhp_tamp.contact_graph import PlanningContext
from ldhp_tamp.path import Segment
from ldhp_tamp.primitives.registry import DomainInfo, Family, PrimitiveRegistry, Transition

log = logging.getLogger(__name__)

#: Poses closer than this (mm, and mm at the object's radius for the angle) coincide.
ALIGN_TOL_MM = 0.05
#: Where along an in-state stretch a repositioning motion may end (fractions of it).
REPOSITION_FRACTIONS = (0.25, 0.5, 0.75, 1.0)
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
    """What the streams tried: expansions, and transitions that had no sample."""

    expansions: int = 0
    dead_ends: Counter = field(default_factory=Counter)  # Transition -> count
    alignment_failures: Counter = field(default_factory=Counter)  # state -> count
    repositions: int = 0  # in-state repositioning motions tried


def _close(a: Pose, b: Pose, radius: float) -> bool:
    d, th = a.distance(b)
    return d <= ALIGN_TOL_MM and th * radius <= ALIGN_TOL_MM


def _stays(ctx: PlanningContext, motion: Motion, s_end: float, state: ContactState) -> bool:
    """Whether ``motion`` can run to ``s_end`` without leaving ``state``."""
    if s_end <= 0.0:
        return True
    sw = sweep(ctx.world, motion, s_end)
    return sw.end is SweepEnd.LIMIT and all(p.state == state for p in sw.pieces)


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
        dist = float(np.linalg.norm(d))
        for motion, _, params in registry.implementation("push").families(ctx, p):
            if np.dot(motion.direction, d) >= dist - 1e-6 and _stays(ctx, motion, dist, state):
                return [_seg("push", state, motion, dist, ctx, params, travel=dist)]
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


def reposition(ctx: PlanningContext, domain: DomainInfo, registry: PrimitiveRegistry, state: ContactState,
               pose: Pose, fractions: Sequence[float] = REPOSITION_FRACTIONS) -> list[Segment]:
    """In-state motions from ``pose``: for every motion family of every MoveObject
    primitive the domain declares, the stretch over which the object stays in ``state``,
    sampled at ``fractions`` of its length (shorter than ``REPOSITION_MIN_MM`` of vertex
    motion is skipped). These are the "short motions within a state" of the paper's
    Sub-step 2, used here before a transition as well as at the ends: a transition that
    is admissible from one pose of a state may be blocked from another (a block standing
    20 mm from a wall cannot tip towards it, but can once pushed along the floor)."""
    out: list[Segment] = []
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
            if len(pieces) > 1 or sw.end is SweepEnd.BLOCKED:
                # keep clear of the state's boundary
                stay -= min(REPOSITION_MARGIN_MM / max(motion.vertex_speed(ctx.world), 1e-9), 0.25 * stay)
            speed = motion.vertex_speed(ctx.world)
            for f in fractions:
                s_end = f * stay
                if s_end * speed < REPOSITION_MIN_MM:
                    continue
                key = "angle" if motion.kind is not MotionKind.TRANSLATE else "travel"
                val = math.degrees(s_end) if key == "angle" else s_end
                out.append(_seg(name, state, motion, s_end, ctx, params, **{key: val}))
    return out


def _candidates(ctx: PlanningContext, domain: DomainInfo, registry: PrimitiveRegistry, impl: object,
                t: Transition, pose: Pose, rng: np.random.Generator, limit: int,
                stats: StreamStats) -> Iterator[tuple[Segment, ...]]:
    """A transition's stream: the primitive's own samples from ``pose``; when it has none,
    samples from poses reached by an in-state motion (:func:`reposition`), ranked by the
    distance of their end pose to T'_g."""
    n = 0
    for seg in impl.sample(ctx, t.from_state, t.to_state, pose, rng, limit):  # type: ignore[attr-defined]
        n += 1
        yield (seg,)
    if n or t.from_state.is_free:
        return
    scored: list[tuple[float, int, tuple[Segment, ...]]] = []
    for pre in reposition(ctx, domain, registry, t.from_state, pose):
        stats.repositions += 1
        for seg in impl.sample(ctx, t.from_state, t.to_state, pre.end, rng, limit):  # type: ignore[attr-defined]
            score = float(ctx.goal_distance(seg.poses[-1:])[0])
            scored.append((score, len(scored), (pre, seg)))
    scored.sort(key=lambda x: (x[0], x[1]))
    for _, _, moves in scored[:limit]:
        yield moves


def pose_paths(ctx: PlanningContext, transitions: Sequence[Transition], domain: DomainInfo,
               registry: PrimitiveRegistry, rng: np.random.Generator, stats: StreamStats, *,
               limit: int | None = None, max_expansions: int = 200,
               deadline: float | None = None) -> Iterator[PosePath]:
    """Yield complete pose paths for a contact-state plan, best-ranked samples first.

    Depth-first over the stream samples of each transition (at most ``limit`` per
    transition, default ``ctx.stream_samples``), stopping after ``max_expansions``
    sampled segments in all. Dead ends are counted in ``stats``. Past ``deadline`` (a
    :func:`time.perf_counter` value) the next expansion raises
    :class:`~ldhp_tamp.errors.TimeBudgetExceeded`.
    """
    limit = ctx.stream_samples if limit is None else limit
    n = len(transitions)

    def rec(k: int, pose: Pose, segments: tuple[Segment, ...]) -> Iterator[PosePath]:
        if stats.expansions >= max_expansions:
            return
        budget.check(deadline, "the top tier's streams (object-pose paths)")
        if k == n:
            if not ctx.goal_free:
                last_state = transitions[-1].to_state if n else ctx.start_state
                tail = align(ctx, domain, registry, last_state, pose, ctx.goal)
                if tail is None:
                    stats.alignment_failures[last_state] += 1
                    if n:
                        stats.dead_ends[transitions[-1]] += 1
                    return
                segments = segments + tuple(replace(a, step=n - 1) for a in tail)
            yield PosePath(segments)
            return
        t = transitions[k]
        pre: list[Segment] = []
        if t.action == "air-move" and t.to_state.is_free:
            tail = align(ctx, domain, registry, t.from_state, pose, ctx.goal_contact.pose)
            if tail is None:
                stats.alignment_failures[t.from_state] += 1
                stats.dead_ends[t] += 1
                return
            pre = [replace(a, step=k) for a in tail]
            if pre:
                pose = pre[-1].end
        impl = registry.implementation(t.action)
        found = False
        for moves in _candidates(ctx, domain, registry, impl, t, pose, rng, limit, stats):
            moves = tuple(replace(m, step=k) for m in moves)
            stats.expansions += 1
            found = True
            yield from rec(k + 1, moves[-1].end, segments + tuple(pre) + moves)
            if stats.expansions >= max_expansions:
                return
        if not found:
            stats.dead_ends[t] += 1

    start = ctx.start if ctx.start_free else ctx.start_contact.pose
    yield from rec(0, start, ())
