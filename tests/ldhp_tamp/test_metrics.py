"""Plan measures (:mod:`ldhp_tamp.metrics`): regrasps as defined, path lengths, the
support margin."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from geometry.poses import Pose
from ldhp_tamp.metrics import changes_grasp, object_path_equivalent_mm, plan_metrics
from ldhp_tamp.plan import Plan, PlanStats, PlanStatus, Step, Waypoint, read_plan
from ldhp_tamp.primitives import Family

STORED = Path(__file__).resolve().parents[1] / "data" / "planners" / "example_pick-plan.json"


def _w(obj=(0.0, 0.0, 0.0), grip=(0.0, 50.0, 0.0), contacts=(None, None)) -> Waypoint:
    return Waypoint(Pose(*obj), Pose(*grip), 90.0, contacts)


def _step(name: str, family: Family, *waypoints: Waypoint) -> Step:
    return Step(name, family, {}, ("a", "a"), waypoints)


A, B = (-45.0, 50.0), (45.0, 50.0)
PINCH = (A, B)


def test_regrasps_count_grasp_changes_while_held_only() -> None:
    steps = (
        _step("approach-contact", Family.ADJUST_GRASP, _w(), _w(contacts=PINCH)),  # taking it: not a regrasp
        _step("tip", Family.MOVE_OBJECT, _w(contacts=PINCH), _w(obj=(10.0, 0.0, 0.0), grip=(10.0, 50.0, 0.0),
                                                                contacts=((-35.0, 50.0), (55.0, 50.0)))),
        # a slide of finger 1 by 5 mm along the object: a regrasp
        _step("slide", Family.ADJUST_GRASP, _w(obj=(10.0, 0.0, 0.0), contacts=((-35.0, 50.0), (55.0, 50.0))),
              _w(obj=(10.0, 0.0, 0.0), contacts=((-35.0, 55.0), (55.0, 50.0)))),
        # finger 2 lets go: a regrasp
        _step("open", Family.ADJUST_GRASP, _w(obj=(10.0, 0.0, 0.0), contacts=((-35.0, 55.0), (55.0, 50.0))),
              _w(obj=(10.0, 0.0, 0.0), contacts=((-35.0, 55.0), None))),
        # the gripper moves, the contacts stay (0.5 mm): not a regrasp
        _step("pivot", Family.ADJUST_GRASP, _w(obj=(10.0, 0.0, 0.0), contacts=((-35.0, 55.0), None)),
              _w(obj=(10.0, 0.0, 0.0), grip=(20.0, 60.0, 0.3), contacts=((-35.0, 55.5), None))),
        _step("push", Family.MOVE_OBJECT, _w(obj=(10.0, 0.0, 0.0)), _w(obj=(10.0, 0.0, math.pi / 2))),
        _step("release", Family.ADJUST_GRASP, _w(contacts=PINCH), _w()),  # letting go: not a regrasp
    )
    plan = Plan("ldhp-plan/1", "s", "0" * 64, PlanStatus.SOLVED, steps, PlanStats(extra={"support_margin": 0.25}))
    m = plan_metrics(plan)
    assert m.regrasps == 2 and m.steps == 7
    assert [changes_grasp(s) for s in steps] == [True, False, True, True, False, False, True]
    assert m.object_path_mm == pytest.approx(10.0)  # within steps: the tip's 10 mm
    assert m.object_rotation_rad == pytest.approx(math.pi / 2)
    assert m.finger_travel_mm == pytest.approx(10.0 + math.hypot(20.0, 10.0), abs=1e-3)  # rounded to um
    assert m.support_margin == 0.25
    assert object_path_equivalent_mm(m, 10.0) == pytest.approx(10.0 + 5 * math.pi, abs=1e-3)


def test_the_contacts_are_compared_in_the_object_frame() -> None:
    # the object turns with the fingers on it: the contacts move in the world, not on the object
    turned = Pose(0.0, 0.0, math.pi / 2)
    a, b = turned.apply(A), turned.apply(B)
    step = _step("pivot", Family.ADJUST_GRASP, _w(contacts=PINCH),
                 _w(obj=(0.0, 0.0, math.pi / 2), contacts=((float(a[0]), float(a[1])), (float(b[0]), float(b[1])))))
    assert not changes_grasp(step)


def test_the_stored_pick_plan() -> None:
    m = plan_metrics(read_plan(STORED))
    assert m.regrasps == 0 and m.steps == 2
    assert m.object_path_mm == pytest.approx(100.0, abs=0.01) and m.object_rotation_rad == 0.0
    assert m.finger_travel_mm > m.object_path_mm  # the approach, then the lift
    assert m.support_margin == pytest.approx(1.0)
