"""Beyond the plan rules: does the commanded gripper motion make the planned object motion?

The rules of ``ldhp-plan/1`` (:mod:`ldhp_tamp.validate`) ask that balancing forces exist
at every waypoint, with the motion's contact modes. An executor that commands the
gripper's *positions* (the paper's: position control with force-triggered events) gets
whichever object motion the contact mechanics makes of that finger motion; when another
motion than the planned one is consistent too (a block tipped by one finger on a
slippery floor slides instead; a finger meant to tip an object leaves it where it is),
the plan is not executable as written. :func:`forward_check` solves that quasi-static
forward problem (:func:`geometry.forward.alternative_motions`) over the motion from each
waypoint to the next, with the contacts rule 7 finds there.

Two fingers of a gripper that closes under force squeeze the object between them: the
executor closes the gripper until its force setting (the simulation's preload), so neither
finger lets go, whatever their normals (opposed, they hold it between them; on two faces
of a corner the grip drags them towards it). They hold it as the grip force decides,
which the force limit (rule 9), the planner's friction margin and, with ``solve
--simulate``, the physics replay govern: waypoints with such a pinch are not enumerated
(the rigid model lets a finger leave the object, and would call every pinch ambiguous,
its squeeze being indeterminate). An earlier version counted only fingers whose normals
oppose within 60 degrees, and refused the quarter turn's corner pinch (one finger on the
block's top, one on its side) for a motion in which the top finger lets go, while the
simulation, squeezing it, executes the plan. A fixed-width gripper's rigid fingers
squeeze nothing: their waypoints are enumerated like any other.

This module reads a plan and a scenario only (like the validator, it never imports the
planner's search).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from geometry import collision, mechanics
from geometry.forward import MAX_CONTACTS, alternative_motions, falling_accelerations, gyration_sq, screw_velocity
# How far ahead (finger travel, mm; and waypoints) the fingers must push into an object
# that stays put for a planned object motion to be forced (:func:`_object_may_stay`):
# the bottom tier's G_m makes the same test at a segment's start, with the same bounds.
from geometry.grasps import STAY_SAMPLES as _STAY_AHEAD
from geometry.grasps import STAY_TRAVEL
from geometry.poses import BoolArray, IntArray, transform_points, wrap_angle
from geometry.shapes import FloatArray
from geometry.tolerances import PENETRATION_TOL
from ldhp_tamp.plan import Plan
from ldhp_tamp.scenario import Scenario
from geometry.world import World
from ldhp_tamp.validate import (ROUNDING_SLACK, PlanArrays, PlanContacts, PresentGroup, finger_offsets, plan_contacts,
                                present_groups, press_table, pressed_support, rotate_vectors)

__all__ = ["ForwardReport", "forward_check"]

log = logging.getLogger(__name__)

#: Motions smaller than this (mm, and radians times the length scale) are no motion: the
#: slack of numbers that went through a plan file rounded to 6 decimals (a finger that
#: stays put in the planner's arrays moves by a few 1e-6 mm once written and read back).
_STILL = ROUNDING_SLACK


@dataclass(frozen=True)
class ForwardReport:
    """Where the commanded motion admits another object motion than the planned one.

    ``ambiguous`` marks waypoints (over the whole plan, in order) at whose motion to the
    next waypoint it does; ``step`` and ``waypoint`` locate the first (0-based, as the
    validator's) or are ``None``; ``reason`` says which other motion.
    """

    ambiguous: BoolArray
    checked: int
    step: int | None = None
    waypoint: int | None = None
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.step is None


def _describe(labels: tuple[str, ...], modes: np.ndarray, twist: FloatArray) -> str:
    names = {mechanics.ContactMode.STICKING: "sticks", mechanics.ContactMode.SLIDING: "slides",
             mechanics.ContactMode.SEPARATING: "lets go"}
    what = sorted({f"{labels[j]} {names[int(m)]}" for j, m in enumerate(modes) if int(m) in names})
    turn = np.degrees(twist[2])
    return (f"the same finger motion also lets the object move by ({twist[0]:.2f}, {twist[1]:.2f}) mm and "
            f"{turn:.2f} deg ({', '.join(what) or 'every contact lets go'}), a motion that balances too")


def _object_may_stay(world: World, flat: PlanArrays, c: PlanContacts, com: FloatArray, held: BoolArray
                     ) -> BoolArray:
    """Waypoints i (before the last) of MoveObject motions at which the object may simply
    stay: it rests on the environment alone there (full cones, no finger), and over the
    next waypoints of the step, up to :data:`STAY_TRAVEL` of gripper travel, no finger
    penetrates the object held at pose i by more than ``PENETRATION_TOL`` (finite
    motions: a round finger that grazes a corner rolls over it, which the first-order
    enumeration does not see). Waypoints ``held`` are not asked: a squeezing pinch carries
    the object by its grip force, and a pressed finger's friction is the enumeration's to
    decide (the object staying while it slides is one of its assignments)."""
    n = len(flat)
    rows = np.arange(n - 1)
    moves = ((np.abs(flat.obj[rows + 1, :2] - flat.obj[rows, :2]).max(axis=1) > _STILL)
             | (np.abs(wrap_angle(flat.obj[rows + 1, 2] - flat.obj[rows, 2])) * world.object.length_scale > _STILL))
    moves &= flat.step[rows + 1] == flat.step[rows]
    out = np.zeros(n, dtype=bool)
    if not moves.any():
        return out
    env = c.on & (c.finger < 0)[None, :]
    cand = np.flatnonzero(moves & env.any(axis=1) & ~held[rows])
    if cand.size == 0:
        return out
    # rests alone at pose i: the environment contacts present, full cones
    rests = np.zeros(cand.size, dtype=bool)
    for grp in present_groups(env[cand]):
        def take(a: np.ndarray, grp: PresentGroup = grp) -> np.ndarray:
            return grp.take(a[cand])

        rests[grp.rows] = mechanics.feasible_batch(mechanics.Contacts.make(take(c.points), take(c.normals),
                                                                           take(c.mu)),
                                                   com[cand[grp.rows]], world.object.length_scale, margin=0.0)
    cand = cand[rests]
    if cand.size == 0:
        return out
    # the fingers at the next waypoints against the object held at pose i
    pushed = np.zeros(cand.size, dtype=bool)
    travel = np.zeros(cand.size)
    for j in range(1, _STAY_AHEAD + 1):
        k = cand + j
        live = (k < n) & ~pushed
        live[live] &= flat.step[k[live]] == flat.step[cand[live]]
        if not live.any():
            break
        kk = k[live]
        travel[live] += np.hypot(*(flat.grip[kk, :2] - flat.grip[kk - 1, :2]).T)
        live[live] &= travel[live] <= STAY_TRAVEL
        if not live.any():
            break
        kk = k[live]
        hit = collision.finger_object_overlap(world, flat.obj[cand[live]], flat.grip[kk], flat.width[kk],
                                              PENETRATION_TOL).any(axis=1)
        pushed[live] |= hit
    out[cand[~pushed]] = True
    return out


def _falls_off_the_finger(world: World, flat: PlanArrays, c: PlanContacts, com: FloatArray, rows: IntArray
                          ) -> BoolArray:
    """(len(rows),) of waypoints ``rows`` (one finger touching, no press), whether the
    object, which does not rest on the environment alone there, would start to move away
    from the finger if the finger gave no force (:func:`geometry.forward.falling_accelerations`):
    a finger moved by position control, not pressed, carries force only where the object
    leans on it (or where the finger pushes into it, which the finger's own motion does not
    say here: the motion is planned with the finger sticking)."""
    out = np.zeros(rows.size, dtype=bool)
    if not rows.size:
        return out
    env = c.on[rows] & (c.finger < 0)[None, :]
    fin = c.on[rows] & (c.finger >= 0)[None, :]
    # the finger's contact: its first candidate column (points coincide; normals may differ)
    fcol = np.argmax(fin, axis=1)
    probe_p = c.points[rows, fcol]
    probe_n = c.normals[rows, fcol]
    k2 = gyration_sq(world.object.polygon.vertices, world.object.com)
    cand = np.flatnonzero(env.any(axis=1))
    rest = np.zeros(rows.size, dtype=bool)
    for grp in present_groups(env[cand]):
        def take(a: np.ndarray, grp: PresentGroup = grp) -> np.ndarray:
            return grp.take(a[rows[cand]])

        sel = cand[grp.rows]
        rest[sel] = mechanics.feasible_batch(mechanics.Contacts.make(take(c.points), take(c.normals), take(c.mu)),
                                             com[rows[sel]], world.object.length_scale, margin=0.0)
        todo = ~rest[sel]
        if not todo.any():
            continue
        s2 = sel[todo]
        pts, nrm, mu = take(c.points)[todo], take(c.normals)[todo], take(c.mu)[todo]
        falls, onto = falling_accelerations(pts, nrm, mu, np.ones(pts.shape[:2], bool), com[rows[s2]], k2,
                                            probe_p[s2], probe_n[s2])
        out[s2] = falls & ~onto
    return out


def _same_leg(flat: PlanArrays, rows: IntArray) -> BoolArray:
    """(len(rows),) whether waypoints ``i - 1``, ``i``, ``i + 1`` are in one step and the
    displacements ``i - 1 -> i`` and ``i -> i + 1`` turn the gripper and the object by the
    same angles and change the width by the same amount (relative 1e-3): one leg, sampled
    evenly, where a central difference of the motion is its derivative at ``i``."""
    i = np.asarray(rows, dtype=np.int64)
    a, b = np.maximum(i - 1, 0), np.minimum(i + 1, len(flat) - 1)
    ok = (i > 0) & (flat.step[a] == flat.step[i]) & (flat.step[b] == flat.step[i])

    def alike(x: FloatArray, y: FloatArray) -> BoolArray:
        return np.abs(x - y) <= _LEG_REL * np.maximum(np.abs(x), np.abs(y)) + 1e-12

    for angles in (flat.grip[:, 2], flat.obj[:, 2]):
        ok &= alike(wrap_angle(angles[i] - angles[a]), wrap_angle(angles[b] - angles[i]))
    ok &= alike(flat.width[i] - flat.width[a], flat.width[b] - flat.width[i])
    return ok


#: Relative difference under which two displacements of a step count as one leg's.
_LEG_REL = 1e-3


def forward_check(plan: Plan, scenario: Scenario) -> ForwardReport:
    """The forward problem at every waypoint of ``plan`` but the last (see the module
    docstring). Waypoints with more than :data:`~geometry.forward.MAX_CONTACTS` contacts
    present are left unchecked (logged)."""
    world = scenario.world
    flat = PlanArrays.of(plan)
    n = len(flat)
    ambiguous = np.zeros(n, dtype=bool)
    if n < 2:
        return ForwardReport(ambiguous, 0)
    rows = np.arange(n - 1)
    nxt = rows + 1
    c = plan_contacts(world, flat.take(slice(0, n - 1)))
    # The commanded motion at waypoint i: the displacement to the next waypoint, or, where
    # the previous one is in the same step and the two displacements turn the gripper and
    # the object by the same angles and change the width alike (one leg of one motion),
    # the displacement from the previous to the next (a central difference, its scale
    # immaterial: the forward problem is homogeneous in the velocities). A finger that
    # rolls on the object turns about its contact point, which moves along the edge: the
    # forward displacement's screw turns about a point half a step ahead of the contact,
    # and the finger's surface there seems to leave the object by radius x turn^2 / 2;
    # the central one is centred on it. For a screw of constant twist (a tip, a push, a
    # spin about a finger) both are the same.
    prv = np.where((rows > 0) & _same_leg(flat, rows), rows - 1, rows)
    # planned twist: the COM's displacement and the turn; the other bodies' displacements
    com0 = transform_points(flat.obj[rows], world.object.com)[:, 0]
    turn = wrap_angle(flat.obj[nxt, 2] - flat.obj[prv, 2])
    planned = np.column_stack([screw_velocity(flat.obj[prv], flat.obj[nxt], com0[:, None, :])[:, 0], turn])
    finger = c.finger >= 0
    dg = screw_velocity(flat.grip[prv], flat.grip[nxt], c.points)  # (B, C, 2)
    shift = rotate_vectors(flat.grip[nxt], finger_offsets(flat.width[nxt] - flat.width[prv]))  # (B, 2, 2)
    other = np.where(finger[None, :, None], dg + shift[:, np.clip(c.finger, 0, 1), :], 0.0)
    L = world.object.length_scale
    finger_moves = np.where(c.on, np.linalg.norm(other, axis=-1), 0.0).max(axis=1, initial=0.0)
    moving = (np.abs(planned[:, :2]).max(axis=1) > _STILL) | (np.abs(turn) * L > _STILL) | (finger_moves > _STILL)
    # a pinch: both fingers on the object, the gripper closed on it under force (the
    # executor's squeeze, geometry.grasps.squeezing), whatever their normals
    f1 = c.on & (c.finger == 0)[None, :]
    f2 = c.on & (c.finger == 1)[None, :]
    squeeze = f1.any(axis=1) & f2.any(axis=1)
    if world.gripper.fixed_width:  # rigid fingers squeeze nothing: the motion decides alone
        squeeze[:] = False
    # a step's press holds its finger's normal force (the executor's guarded move):
    # the planned motion must balance with exactly that force, and the enumeration takes
    # the finger's force as given instead of its normal velocity
    press = press_table(plan)
    pressed_rows = np.isfinite(press[rows]).any(axis=1)
    if pressed_rows.any():
        balanced = pressed_support(world, flat, press)[rows]
        bad = pressed_rows & moving & ~balanced
        if bad.any():
            i = int(np.argmax(bad))
            f = press[i][np.isfinite(press[i])]
            return ForwardReport(bad, 0, int(flat.step[i]), int(flat.local[i]),
                                 f"waypoint {int(flat.local[i])}: with the step's press ({float(f[0]):.3g} N) "
                                 "the planned motion does not balance")
    col_press = np.where(finger[None, :] & c.on, press[rows][:, np.clip(c.finger, 0, 1)], np.nan) / world.object.weight
    count = c.on.sum(axis=1)
    todo = moving & ~squeeze & (count > 0)
    skipped = int((todo & (count > MAX_CONTACTS)).sum())
    if skipped:
        log.info("forward check: %d waypoint(s) with more than %d contacts left unchecked", skipped, MAX_CONTACTS)
    todo &= count <= MAX_CONTACTS
    first: tuple[int, str] | None = None
    checked = 0
    for grp in present_groups(c.on, todo):
        sel, cols, take = grp.rows, grp.cols, grp.take
        pr = take(col_press)
        res = alternative_motions(take(c.points), take(c.normals), take(c.mu), np.ones(cols.shape, bool),
                                  take(other), com0[sel], L, planned[sel],
                                  pressed=pr if np.isfinite(pr).any() else None, press_group=c.finger[cols])
        checked += sel.size
        ambiguous[sel] = res.ambiguous
        if res.ambiguous.any():
            j = int(np.argmax(res.ambiguous))
            i = int(sel[j])
            if first is None or i < first[0]:
                labels = tuple(c.labels[k] for k in cols[j])
                first = (i, _describe(labels, res.modes[j], res.twist[j]))
    stays = _object_may_stay(world, flat, c, com0, squeeze | pressed_rows)
    # one finger, not pressed, on an object the environment alone does not hold: it carries
    # force only where the object leans on it
    one_finger = (f1.any(axis=1) ^ f2.any(axis=1)) & moving & ~pressed_rows & (flat.step[nxt] == flat.step[rows])
    lone = rows[one_finger]
    off = _falls_off_the_finger(world, flat, c, com0, lone)
    for i in lone[off]:
        ambiguous[i] = True
        if first is None or i < first[0]:
            first = (int(i), "left to gravity the object falls away from the one finger that holds it: moved by "
                             "position control, not pressed, the finger carries no force there")
        break
    for i in np.flatnonzero(stays):
        ambiguous[i] = True
        if first is None or i < first[0]:
            first = (int(i), "the fingers' motion over the next waypoints does not push into the object, "
                             "which rests on the environment alone: it may stay where it is")
        break
    if first is None:
        return ForwardReport(ambiguous, checked)
    i, why = first
    return ForwardReport(ambiguous, checked, int(flat.step[i]), int(flat.local[i]),
                         f"waypoint {int(flat.local[i])}: {why}")
