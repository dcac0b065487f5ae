"""The sweep-based MoveObject primitives (tip, push, biplanar-slide): transitions and
stream samples through events the contact-state graph leaves out."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from geometry.contacts import contact_state
from ldhp_tamp.contact_graph import build_context
from ldhp_tamp.primitives.move_object import BiplanarSlide, Push, Tip
from ldhp_tamp.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[3] / "scenarios"


@lru_cache(maxsize=1)
def _slot():
    sc = load_scenario(SCENARIOS / "task2_slot_insertion.toml")
    ctx = build_context(sc.world, sc.start, sc.goal, stream_samples=3)
    return ctx, {s.name: s for s in ctx.states}


def test_the_ladder_slide_goes_on_over_the_lip_corner_down_the_wall() -> None:
    """The block leaning on the slot's lip corner (v1 on the floor, l4 on the lip) slides
    until its top corner v4 reaches the lip: a vertex-on-vertex instant the graph leaves
    out, after which the corner goes down the wall. The transition across it is
    admissible, and the stream realises it as two joined motions meeting at that instant."""
    ctx, s = _slot()
    pairs = BiplanarSlide().transitions(ctx)
    lean, wall = s["v1-e1+l4-ve3"], s["v1-e1+v4-e2"]
    assert (lean, wall) in pairs and (wall, lean) in pairs
    start = ctx.witness_poses(lean)[0]
    samples = list(BiplanarSlide().sample(ctx, lean, wall, start, np.random.default_rng(0), 5))
    assert samples and all(isinstance(x, tuple) and len(x) == 2 for x in samples)
    for first, second in samples:
        assert first.from_state == lean and second.to_state == wall and first.to_state == second.from_state
        assert np.allclose(first.poses[-1], second.poses[0])
        v4 = ctx.world.object_vertices(first.end)[3]
        assert np.linalg.norm(v4 - [0.0, 75.0]) < 0.1  # the joint is the corner on the lip
        assert contact_state(ctx.world, second.end) == wall
        assert second.end.theta > first.end.theta  # on down the wall, not back


def test_a_ladder_slide_ends_lying_flat_where_the_state_holds() -> None:
    """The ladder down the wall ends where the block lies flat against it: the end pose
    is in the state the transition names (the sweep's refined end stops a hair short of
    flat, outside the contact tolerance), so a push can take it on from there."""
    ctx, s = _slot()
    wall, flat = s["v1-e1+v4-e2"], s["l4-e1+l3-e2"]
    start = ctx.witness_poses(wall)[0]
    segs = list(BiplanarSlide().sample(ctx, wall, flat, start, np.random.default_rng(0), 5))
    assert segs
    for seg in segs:
        assert contact_state(ctx.world, seg.end) == flat
        assert abs(seg.end.theta - math.pi / 2) < 1e-3
    pushes = list(Push().sample(ctx, flat, s["l4-e1"], segs[0].end, np.random.default_rng(0), 5))
    assert pushes


def test_a_stand_up_slide_is_streamed_to_where_it_completes() -> None:
    """The block lying against the slot's left wall stands up into the corner by a
    biplanar slide (v4 on the floor, v3 down the wall) that ends upside down, 180 degrees
    from the goal's orientation: ranked by the distance to T'_g its far end comes last,
    yet it is among the three samples tried (a biplanar slide keeps the best far end),
    next to the best-ranked ones."""
    sc = load_scenario(SCENARIOS / "gen_slot_corner_start.toml")
    ctx = build_context(sc.world, sc.start, sc.goal, stream_samples=3)
    s = {x.name: x for x in ctx.states}
    lying, standing = s["l4-e1+l3-e2"], s["v4-e1+v3-e2"]
    samples = list(BiplanarSlide().sample(ctx, lying, standing, sc.start, np.random.default_rng(0), 3))
    assert len(samples) == 3 and all(contact_state(ctx.world, x.end) == standing for x in samples)
    angles = sorted(math.degrees(x.end.theta) % 360.0 for x in samples)
    assert 179.0 < angles[-1] < 180.0  # stood up, 2 mm of vertex motion short of flat on its end
    assert angles[0] < 100.0  # the goal-ranked ones stay
    unranked = list(BiplanarSlide().sample(ctx, lying, standing, sc.start, np.random.default_rng(0), 30))
    assert len(unranked) > 3  # there are more, ranked before the far end


def test_the_primitives_found_together_are_each_ones_own(monkeypatch) -> None:
    """swept_transitions puts every primitive's sweeps in one list of batches (claimed by
    the cores from 64 sweeps on): each primitive gets the pairs it finds alone, forked or
    not, whatever the batch size."""
    from ldhp_tamp.primitives import move_object

    ctx, _ = _slot()
    prims = [Tip(), Push(), BiplanarSlide()]
    alone = [p.transitions(ctx) for p in prims]
    assert all(alone) and len({frozenset(a) for a in alone}) == 3
    assert move_object.swept_transitions(ctx, prims) == alone
    for batch, fork_min in ((7, 1), (1000, 10**9)):  # many forked batches; one batch in this process
        monkeypatch.setattr(move_object, "TRANSITION_BATCH", batch)
        monkeypatch.setattr(move_object, "TRANSITION_FORK_MIN", fork_min)
        assert move_object.swept_transitions(ctx, prims) == alone
