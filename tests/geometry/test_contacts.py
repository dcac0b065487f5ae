"""Tests of geometry.contacts: identification, contact points, state enumeration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from geometry.collision import object_env_overlap
from geometry.contacts import (
    Workspace,
    contact_points,
    contact_point_arrays,
    contact_state,
    enumerate_contact_states,
    principal_contact_masks,
    principal_contacts,
    relevant_features,
    workspace_for_task,
)
from geometry.features import FREE, ContactKind, ContactState
from geometry.poses import Pose
from geometry.shapes import make_polygon
from geometry.world import Environment, Friction, Solid, TwoPointGripper, World, make_object

BLOCK = [[0, 0], [70, 0], [70, 150], [0, 150]]
TABLE = [[500, 0], [-500, 0], [-500, -100], [500, -100]]  # e1 is the top face
# One U-shaped solid, counter-clockwise from its top-left corner:
# e1 outer left, e2 bottom, e3 outer right, e4 right top (y = 75, x in [300, 500]),
# e5 right inner wall (x = 300), e6 slot floor (y = 0), e7 left inner wall (x = 0),
# e8 left top (y = 75, x in [-200, 0]); ve5 = (300, 75) and ve8 = (0, 75) are the convex
# lips, ve6 = (300, 0) and ve7 = (0, 0) the concave slot corners.
SLOT = [[-200, 75], [-200, -50], [500, -50], [500, 75], [300, 75], [300, 0], [0, 0], [0, 75]]

TASK1 = (Pose(0.0, 0.0, 0.0), Pose(0.0, 300.0, 0.0))
TASK2 = (Pose(115.0, 150.0, 0.0), Pose(225.0, 0.0, math.pi / 2))
EDGE_KINDS = frozenset({ContactKind.VERTEX_EDGE, ContactKind.EDGE_EDGE})


def make_world(*solids, obj=BLOCK, friction: Friction | None = None) -> World:
    env = Environment(tuple(Solid(f"s{k}", make_polygon(v)) for k, v in enumerate(solids)))
    return World(make_object(obj), env, TwoPointGripper(5.0, (80.0, 80.0)), friction or Friction(0.2, 0.2))


def test_contact_point_arrays_match_one_pose_at_a_time() -> None:
    w = make_world(SLOT)
    rng = np.random.default_rng(3)
    # resting and wedged poses (one, two and edge-edge contacts) and random ones
    poses = [Pose(0.0, 0.0, 0.0), Pose(225.0, 0.0, math.pi / 2), Pose(80.0, 0.0, 0.2), Pose(115.0, 150.0, 0.0),
             Pose(0.0, 0.0, math.pi / 2 + 0.0), Pose(230.0, 0.0, 0.0), Pose(300.0, 0.0, math.pi / 2)]
    poses += [Pose(float(x), float(y), float(t)) for x, y, t in
              zip(rng.uniform(-10, 300, 40), rng.uniform(-1, 80, 40), rng.uniform(-3, 3, 40))]
    pts, nrm, mu, live = contact_point_arrays(w, np.array([p.as_array() for p in poses]))
    assert pts.shape[0] == len(poses) and live.any()
    for b, p in enumerate(poses):
        want = contact_points(w, p)
        k = len(want)
        assert live[b].sum() == k and live[b, :k].all()
        np.testing.assert_array_equal(pts[b, :k], want.points)
        np.testing.assert_array_equal(nrm[b, :k], want.normals)
        np.testing.assert_array_equal(mu[b, :k], want.mu)
    assert max(len(contact_points(w, p)) for p in poses) >= 2


def names(world: World, pose: Pose) -> list[str]:
    return [c.name for c in principal_contacts(world, pose)]


# --------------------------------------------------------------------------------------
# Identification at hand-made poses
# --------------------------------------------------------------------------------------


def test_block_flat_on_table_is_edge_edge() -> None:
    w = make_world(TABLE)
    assert names(w, Pose(0.0, 0.0, 0.0)) == ["l1-e1"]
    assert contact_state(w, Pose(0.0, 0.0, 0.0)) == ContactState.parse("l1-e1")
    # Lying on its long side l2 (rotated -90 deg about the origin, lifted by 70).
    assert names(w, Pose(0.0, 70.0, -math.pi / 2)) == ["l2-e1"]
    # Lifted by more than the tolerance: free. Within it: still in contact.
    assert contact_state(w, Pose(0.0, 0.2, 0.0)) == FREE
    assert names(w, Pose(0.0, 0.05, 0.0)) == ["l1-e1"]


def test_tilted_block_rests_on_a_corner() -> None:
    w = make_world(TABLE)
    th = -0.3  # clockwise: v2 goes down
    assert names(w, Pose(0.0, 70.0 * math.sin(-th), th)) == ["v2-e1"]
    assert names(w, Pose(0.0, 0.0, 0.3)) == ["v1-e1"]
    # A tilt whose far end lifts by 0.15 mm > tol is no longer flush: a vertex contact.
    th = math.asin(0.15 / 70.0)
    assert names(w, Pose(0.0, 0.0, th)) == ["v1-e1"]
    th = math.asin(0.05 / 70.0)
    assert names(w, Pose(0.0, 0.0, th)) == ["l1-e1"]


def test_block_wedged_against_the_slot_wall_has_two_contacts() -> None:
    w = make_world(SLOT)
    th = 0.3  # counter-clockwise: v1 lowest, v2 rightmost
    pose = Pose(300.0 - 70.0 * math.cos(th), 0.0, th)
    assert contact_state(w, pose).name == "v2-e5+v1-e6"
    assert not object_env_overlap(w, pose.as_array())[0]


def test_object_vertex_in_a_concave_corner_touches_both_edges() -> None:
    w = make_world(SLOT, obj=[[0, 0], [60, 20], [20, 60]])  # a thin triangle, corner at v1
    pose = Pose(0.0, 0.0, 0.0)  # v1 in the concave corner ve7 = (0, 0)
    assert names(w, pose) == ["v1-e6", "v1-e7"]


def test_block_resting_on_the_slot_lip_is_edge_vertex() -> None:
    w = make_world(SLOT)
    th, s = -0.2, 30.0  # l1 passes through the lip ve8 = (0, 75) at 30 mm from v1
    pose = Pose(-s * math.cos(th), 75.0 - s * math.sin(th), th)
    assert names(w, pose) == ["l1-ve8"]
    cp = contact_points(w, pose)
    assert np.allclose(cp.points, [[0.0, 75.0]])
    # The reaction pushes into the object: minus l1's outward normal, (sin th, -cos th).
    assert np.allclose(cp.normals, [[-math.sin(th), math.cos(th)]])


def test_concave_environment_vertex_is_never_an_edge_vertex_contact() -> None:
    w = make_world(SLOT)
    concave = np.flatnonzero(~w.environment.vertex_convex)
    assert set(concave.tolist()) == {5, 6}  # ve6, ve7
    # Block flat in the left corner: l1 on the floor, l4 on the wall, edges through ve7.
    assert contact_state(w, Pose(0.0, 0.0, 0.0)).name == "l1-e6+l4-e7"
    # Edges of a rotated block through the concave corners (penetrating or not): the
    # edge-vertex mask is always False there.
    rng = np.random.default_rng(0)
    th = rng.uniform(-math.pi, math.pi, 500)
    corner = w.environment.vertices[rng.choice(concave, 500)]
    s = rng.uniform(0, 70, 500)
    poses = np.column_stack([corner[:, 0] - s * np.cos(th), corner[:, 1] - s * np.sin(th), th])
    m = principal_contact_masks(w, poses)
    assert not m.edge_vertex[:, :, concave].any()
    assert m.edge_vertex.shape == (500, 4, 8)


def test_vertex_touching_a_convex_vertex_reports_the_valid_sides() -> None:
    w = make_world(SLOT)
    # v1 on the lip ve5 = (300, 75), block above the right top, tilted up by 0.01 rad:
    # v1's cone is above e4 (v1-e4) and the lip's cone is outside l1 (l1-ve5).
    pose = Pose(300.0, 75.0, 0.01)
    assert contact_state(w, pose).name == "v1-e4+l1-ve5"
    # v1 on the lip, block hanging into the slot (cone left of the wall line): v1 is on
    # the free side of the wall e5, and the lip is outside l4 but not outside l1.
    pose = Pose(300.0, 75.0, math.pi / 2 + 0.3)
    assert not object_env_overlap(w, pose.as_array())[0]
    assert contact_state(w, pose).name == "v1-e5+l4-ve5"


def test_contact_state_is_invariant_under_a_rigid_motion_of_everything() -> None:
    rng = np.random.default_rng(1)
    w = make_world(SLOT)
    base = [Pose(0.0, 0.0, 0.0), Pose(300.0 - 70.0 * math.cos(0.3), 0.0, 0.3), Pose(300.0, 75.0, 0.01)]
    for _ in range(5):
        mx, my, mt = rng.uniform(-500, 500), rng.uniform(-500, 500), rng.uniform(-math.pi, math.pi)
        motion = Pose(mx, my, mt)
        moved = make_world(np.asarray(motion.apply(np.asarray(SLOT, dtype=float))))
        for p in base:
            assert contact_state(moved, motion.compose(p)) == contact_state(w, p)


# --------------------------------------------------------------------------------------
# Contact points
# --------------------------------------------------------------------------------------


def test_edge_edge_contributes_the_overlap_ends() -> None:
    w = make_world(TABLE, friction=Friction(0.2, 0.6, environment_edges={0: 0.5}))
    cp = contact_points(w, Pose(10.0, 0.0, 0.0))
    assert [c.name for c in cp.contacts] == ["l1-e1"]
    assert sorted(cp.points[:, 0].tolist()) == [10.0, 80.0]
    assert np.allclose(cp.normals, [[0.0, 1.0], [0.0, 1.0]])
    assert cp.mu.tolist() == [0.5, 0.5] and cp.contact_index.tolist() == [0, 0]
    # Hanging 40 mm over the table's end (x = 500): the overlap is [470, 500] only.
    cp = contact_points(w, Pose(470.0, 0.0, 0.0))
    assert [c.name for c in cp.contacts] == ["l1-e1"]  # the table corner ve1 is subsumed
    assert sorted(cp.points[:, 0].tolist()) == pytest.approx([470.0, 500.0])


def test_vertex_edge_point_and_two_contact_rows() -> None:
    w = make_world(SLOT)
    th = 0.3
    pose = Pose(300.0 - 70.0 * math.cos(th), 0.0, th)
    cp = contact_points(w, pose)
    assert cp.state.name == "v2-e5+v1-e6" and len(cp) == 2
    v = w.object_vertices(pose)
    assert np.allclose(cp.points, [v[1], v[0]])
    assert np.allclose(cp.normals, [[-1.0, 0.0], [0.0, 1.0]])  # wall pushes left, floor up
    assert cp.contact_index.tolist() == [0, 1]
    assert contact_points(w, Pose(100.0, 100.0, 0.0)).points.shape == (0, 2)


# --------------------------------------------------------------------------------------
# Workspace and enumeration
# --------------------------------------------------------------------------------------


def test_workspace_excludes_the_table_underside() -> None:
    w = make_world(TABLE)
    ws = workspace_for_task(w, *TASK1)
    assert ws.ymin < -100.0  # the box does reach below the table ...
    rel = relevant_features(w, ws)
    assert rel.edges == (0,) and rel.vertices == ()  # ... but e3 (underside) is cut off
    # Without seeds, every free part counts: the underside e3 comes back.
    unseeded = Workspace(ws.xmin, ws.ymin, ws.xmax, ws.ymax)
    assert relevant_features(w, unseeded).edges == (0, 2)


def test_task1_has_the_papers_eight_states() -> None:
    w = make_world(TABLE)
    states = enumerate_contact_states(w, workspace_for_task(w, *TASK1))
    assert [s.name for s in states] == ["l1-e1", "l2-e1", "l3-e1", "l4-e1", "v1-e1", "v2-e1", "v3-e1", "v4-e1"]


def test_task2_counts() -> None:
    w = make_world(SLOT)
    ws = workspace_for_task(w, *TASK2)
    assert relevant_features(w, ws).edges == (3, 4, 5, 6, 7)
    assert relevant_features(w, ws).vertices == (4, 7)
    states = enumerate_contact_states(w, ws)
    by_size = {1: 0, 2: 0}
    for s in states:
        by_size[len(s.state)] += 1
    assert by_size == {1: 48, 2: 36}
    names_ = {s.name for s in states}
    # Corners flush, wedged against a wall, leaning on a lip, corner on the lip.
    assert {"l1-e6+l4-e7", "v2-e5+v1-e6", "l2-ve5+v2-e6", "v1-e6+l4-ve8", "v1-e4+l1-ve5"} <= names_
    assert not any("ve6" in n or "ve7" in n for n in names_)  # concave corners
    paper = enumerate_contact_states(w, ws, max_contacts=1, kinds=EDGE_KINDS)
    assert len(paper) == 40


@pytest.mark.parametrize("task", ["task1", "task2"])
def test_witnesses_are_valid_diverse_and_deterministic(task: str) -> None:
    w = make_world(TABLE) if task == "task1" else make_world(SLOT)
    ws = workspace_for_task(w, *(TASK1 if task == "task1" else TASK2))
    first = enumerate_contact_states(w, ws)
    again = enumerate_contact_states(w, ws)
    assert first == again
    assert [s.name for s in first] == sorted(s.name for s in first)
    for sw in first:
        assert 1 <= len(sw.witnesses) <= 8
        poses = np.array([p.as_array() for p in sw.witnesses])
        assert not object_env_overlap(w, poses).any(), sw.name
        assert len({tuple(np.round(p, 6)) for p in poses}) == len(poses), sw.name
        for p in sw.witnesses:
            assert contact_state(w, p) == sw.state, (sw.name, p)
    singles = [sw for sw in first if len(sw.state) == 1 and sw.state.contacts[0].kind is ContactKind.VERTEX_EDGE]
    assert all(len(sw.witnesses) == 8 for sw in singles)


def test_tiny_workspace_far_from_everything_has_no_states() -> None:
    w = make_world(TABLE)
    assert enumerate_contact_states(w, Workspace(0.0, 200.0, 10.0, 210.0)) == ()


def test_an_edge_on_the_solid_side_is_not_a_contact() -> None:
    w = make_world(TABLE)
    # Block sunk into the table with its top edge l3 on the table's top line: the edges do
    # not face each other, and v3/v4 have the object on the solid side.
    assert contact_state(w, Pose(0.0, -150.0, 0.0)) == FREE


def test_enumeration_finds_flush_states_of_a_tilted_table() -> None:
    # The table rotated by 17.3 degrees: edge-edge states need the exact antiparallel
    # orientations, which a 1-degree grid does not contain.
    motion = Pose(0.0, 0.0, math.radians(17.3))
    w = make_world(np.asarray(motion.apply(np.asarray(TABLE, dtype=float))))
    start, goal = motion.compose(TASK1[0]), motion.compose(TASK1[1])
    states = enumerate_contact_states(w, workspace_for_task(w, start, goal))
    assert [s.name for s in states] == ["l1-e1", "l2-e1", "l3-e1", "l4-e1", "v1-e1", "v2-e1", "v3-e1", "v4-e1"]


@pytest.mark.parametrize("tol", [0.1, 1e-4, 2.0])
def test_sparse_masks_equal_the_dense_frame(tol: float) -> None:
    """principal_contact_masks tests only the (pose, edge) pairs the object's bounding disk
    comes near (contacts._masks): the same masks as the dense frame, at contact poses (one,
    two, edge-edge, on the lips), near them and anywhere, with a concave object too."""
    from geometry.contacts import _frame, _masks

    rng = np.random.default_rng(5)
    notched = [[0, 0], [70, 0], [70, 150], [35, 150], [35, 100], [0, 100]]
    for obj in (BLOCK, notched):
        w = make_world(SLOT, [[520, -50], [620, -50], [620, 40], [520, 40]], obj=obj)  # two solids
        ws = workspace_for_task(w, *TASK2)
        sure = np.array([p.as_array() for sw in enumerate_contact_states(w, ws, max_contacts=3)
                         for p in sw.witnesses])
        poses = np.concatenate([
            sure, sure + rng.normal(0.0, 0.05, sure.shape) * [1.0, 1.0, 1e-3],
            np.column_stack([rng.uniform(ws.xmin, ws.xmax, 500), rng.uniform(ws.ymin, ws.ymax, 500),
                             rng.uniform(-4.0, 4.0, 500)]),
            [[np.nan, 0.0, 0.0]]])
        dense, sparse = _frame(w, poses, tol).masks, _masks(w, poses, tol)
        assert dense.counts.sum() > len(sure) // 2
        for kind in ("vertex_edge", "edge_vertex", "edge_edge"):
            np.testing.assert_array_equal(getattr(sparse, kind), getattr(dense, kind))


def test_byte_rows_group_as_numpys_unique_rows() -> None:
    """The contact-state enumeration groups its packed masks by ``row_groups`` of their
    bytes read as big-endian words: ``np.unique(axis=0)``'s groups, numbered alike (bytes
    of every value, row widths that are no multiple of 8)."""
    from geometry.contacts import _byte_words, row_groups

    rng = np.random.default_rng(5)
    for width in (1, 7, 8, 12, 17):
        rows = rng.choice(np.array([0, 1, 127, 128, 255], dtype=np.uint8), (3000, width))
        keys, first, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
        inv, firsts = row_groups(_byte_words(rows))
        assert np.array_equal(inv, inverse.ravel()) and np.array_equal(firsts, first)
        assert firsts.size == keys.shape[0]
