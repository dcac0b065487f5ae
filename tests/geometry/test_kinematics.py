"""Primitive kinematics: motion families keep their contacts; sweeps cut by state."""

from __future__ import annotations

import math

import numpy as np
import pytest

from geometry.collision import object_env_overlap
from geometry.contacts import contact_state
from geometry.features import Contact, ContactKind, ContactState
from geometry.kinematics import (
    MotionKind,
    SweepEnd,
    kept_contact_holds,
    rotate_about,
    sweep,
    translate,
    two_contact,
)
from geometry.poses import Pose
from geometry.tolerances import CONTACT_TOL
from geometry.shapes import make_polygon
from geometry.world import Environment, Friction, Solid, TwoPointGripper, World, make_object

BLOCK = [[0, 0], [70, 0], [70, 150], [0, 150]]


def _world(solids) -> World:
    env = Environment(tuple(Solid(n, make_polygon(v)) for n, v in solids))
    return World(make_object(BLOCK), env, TwoPointGripper(5.0, (90.0, 90.0)), Friction(0.2, 0.2))


@pytest.fixture()
def table() -> World:
    return _world([("table", [[500, 0], [-500, 0], [-500, -100], [500, -100]])])


@pytest.fixture()
def slot() -> World:
    # U-shaped solid: slot floor y=0 for x in [0, 300], walls up to y=75.
    u = [[-200, 75], [-200, -50], [500, -50], [500, 75], [300, 75], [300, 0], [0, 0], [0, 75]]
    return _world([("slot", u)])


def test_rotation_family_keeps_pivot(table: World) -> None:
    m = rotate_about(Pose(0, 0, 0), (70.0, 0.0), -1)
    poses = m.poses(np.linspace(0, math.pi / 2, 7))
    v2 = np.array([table.object.polygon.transformed(*p)[1] for p in poses])
    assert np.allclose(v2, [70.0, 0.0])
    assert math.isclose(poses[-1, 2], -math.pi / 2)


def test_tip_sweep_upright_block_lands_on_its_side(table: World) -> None:
    m = rotate_about(Pose(0, 0, 0), (70.0, 0.0), -1)
    sw = sweep(table, m, math.pi)
    names = [s.name for s in sw.states]
    assert names == ["l1-e1", "v2-e1", "l2-e1"]
    assert sw.end is SweepEnd.BLOCKED
    # exact to the sweep tolerance: the far end of the block (150 mm) lands within 1 um
    assert 150.0 * abs(sw.s_end - math.pi / 2) < 1e-3
    # the v2-e1 piece spans the interval between the two flat states, each flat state
    # lasting until the far end of its edge lifts by the contact tolerance
    piece = sw.pieces[1]
    assert piece.s0 == pytest.approx(CONTACT_TOL / 70.0, rel=1e-2)
    assert piece.s1 == pytest.approx(math.pi / 2 - CONTACT_TOL / 150.0, rel=1e-2)


def test_tip_in_the_wrong_sense_cannot_start(table: World) -> None:
    # rotating counter-clockwise about the bottom-right corner drives v1 into the table
    m = rotate_about(Pose(0, 0, 0), (70.0, 0.0), +1)
    sw = sweep(table, m, math.pi)
    assert sw.end is SweepEnd.BLOCKED
    assert 70.0 * sw.s_end < 1e-3  # blocked at once: v1 moves by less than 1 um


def test_push_to_the_wall_makes_a_new_contact(slot: World) -> None:
    m = translate(Pose(100, 0, 0), (-1.0, 0.0))
    sw = sweep(slot, m, 500.0)
    assert sw.states[0].name == "l1-e6"
    assert sw.end is SweepEnd.BLOCKED
    assert sw.s_end == pytest.approx(100.0, abs=1e-3)
    last = sw.states[-1]
    assert len(last) == 2 and ContactState.parse("l1-e6") != last


def test_push_off_the_end_of_an_edge_loses_contact(table: World) -> None:
    v1e1 = Contact(ContactKind.VERTEX_EDGE, 0, 0)
    m = translate(Pose(0, 0, 0), (1.0, 0.0), (v1e1,))
    sw = sweep(table, m, 1000.0)
    assert sw.end is SweepEnd.CONTACT_LOST
    assert sw.s_end == pytest.approx(500.0, abs=0.2)


def test_biplanar_slide_lays_a_leaning_block_down(slot: World) -> None:
    # Block in the slot's left corner, tilted clockwise by 20 degrees: v1 (bottom-left)
    # on the left wall, v2 (bottom-right) on the floor.
    th = math.radians(-20.0)
    c, s = math.cos(th), math.sin(th)
    v1 = np.array([0.0, 0.0]); v2 = np.array([70.0, 0.0])
    r = lambda p: np.array([c * p[0] - s * p[1], s * p[0] + c * p[1]])
    # choose t so that rotated v1 has x = 0 and rotated v2 has y = 0
    t = np.array([-r(v1)[0], -r(v2)[1]])
    start = Pose(float(t[0]), float(t[1]), th)
    st = contact_state(slot, start)
    assert {c.name for c in st.contacts} == {"v1-e7", "v2-e6"}
    kept = (Contact(ContactKind.VERTEX_EDGE, 0, 6), Contact(ContactKind.VERTEX_EDGE, 1, 5))
    m = two_contact(slot, start, kept, -1)
    assert m.kind is MotionKind.TWO_CONTACT
    poses = m.poses(np.linspace(0, 0.5, 11))
    assert np.all(kept_contact_holds(slot, kept[0], poses)) and np.all(kept_contact_holds(slot, kept[1], poses))
    sw = sweep(slot, m, math.pi)
    # turning clockwise, v1 climbs the wall while v2 slides towards it, until the long
    # edge l2 lies flat on the floor against the wall
    assert 150.0 * abs(sw.s_end - math.radians(70.0)) < 1e-3
    assert "l2-e6" in sw.states[-1].name


def test_parallel_contacts_have_no_biplanar_motion(table: World) -> None:
    kept = (Contact(ContactKind.VERTEX_EDGE, 0, 0), Contact(ContactKind.VERTEX_EDGE, 1, 0))
    with pytest.raises(ValueError):
        two_contact(table, Pose(0, 0, 0), kept, 1)


def test_a_two_contact_speed_bound_from_a_near_singular_start_does_not_blow_up_the_grid(slot: World) -> None:
    """A two-contact motion's speed bound is a finite difference at its start; near a
    singular start it is millions of mm per radian (seen in the slot: 4.7 million sweep
    samples, 17 s a sweep). The grid starts from a capped speed and is subdivided where
    vertices move too far: same sweep, bounded work."""
    import dataclasses

    from geometry.kinematics import MAX_GRID_SAMPLES, Motion, dense_parameters

    th = math.radians(-20.0)
    c, s = math.cos(th), math.sin(th)
    start = Pose(-(c * 0.0 - s * 0.0), -(s * 70.0), th)
    kept = (Contact(ContactKind.VERTEX_EDGE, 0, 6), Contact(ContactKind.VERTEX_EDGE, 1, 5))
    honest = two_contact(slot, start, kept, -1)

    class Alarmist(Motion):  # the same motion, with the bound of a near-singular start
        def vertex_speed(self, world: World) -> float:
            return 1.5e6

    scared = Alarmist(**{f.name: getattr(honest, f.name) for f in dataclasses.fields(Motion)})
    a, b = sweep(slot, honest, math.pi), sweep(slot, scared, math.pi)
    assert a.end == b.end and a.states == b.states and abs(a.s_end - b.s_end) < 1e-6
    grid = dense_parameters(slot, scared, 0.0, 1.0, 1.0)
    assert grid.size < MAX_GRID_SAMPLES
    verts = slot.object.polygon
    moved = [np.max(np.linalg.norm(verts.transformed(*q) - verts.transformed(*p), axis=1))
             for p, q in zip(scared.poses(grid[:-1]), scared.poses(grid[1:]))]
    assert max(moved) <= 1.0 + 1e-9


def test_kept_contacts_of_several_motions_hold_as_one_at_a_time(slot: World) -> None:
    """kinematics._kept_hold_rows (the sweeps' batched test): row for row the conjunction
    of kept_contact_holds of each row's contacts, for vertex-edge and edge-vertex
    contacts, motions keeping none, one or two, empty blocks, inside and outside the
    features."""
    from geometry.kinematics import _kept_hold_rows

    rng = np.random.default_rng(2)
    ve = [Contact(ContactKind.VERTEX_EDGE, i, j) for i in range(4) for j in range(slot.environment.m)]
    ev = [Contact(ContactKind.EDGE_VERTEX, i, k) for i in range(4) for k in range(slot.environment.m)]
    kept = [(), (ve[3],), (ev[5],), (ve[6], ev[9]), (ev[1], ve[12]), (ve[20],), (ev[30], ev[2])]
    sizes = [5, 40, 0, 30, 25, 1, 33]
    poses = np.column_stack([rng.uniform(-100, 400, sum(sizes)), rng.uniform(-60, 200, sum(sizes)),
                             rng.uniform(-4, 4, sum(sizes))])
    got = _kept_hold_rows(slot, kept, sizes, poses)
    want, at = [], 0
    for contacts, n in zip(kept, sizes):
        ok = np.ones(n, dtype=bool)
        for c in contacts:
            ok &= kept_contact_holds(slot, c, poses[at:at + n])
        want.append(ok)
        at += n
    want = np.concatenate(want)
    assert 0 < want.sum() < want.size
    np.testing.assert_array_equal(got, want)
    with pytest.raises(ValueError):
        _kept_hold_rows(slot, [(Contact(ContactKind.EDGE_EDGE, 0, 0),)], [1], poses[:1])
