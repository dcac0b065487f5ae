"""The forward problem on plans (ldhp_tamp.executability): the commanded finger motion
must make the planned object motion and no other."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from geometry.poses import Pose
from ldhp_tamp.executability import forward_check
from ldhp_tamp.plan import PLAN_FORMAT, Family, Plan, PlanStats, PlanStatus, Step, Waypoint, read_plan
from ldhp_tamp.scenario import load_scenario, load_scenario_string

SPEC = Path(__file__).resolve().parents[1] / "data" / "spec"

BLOCK_ON_TABLE = """
format = "ldhp-scenario/1"
name = "{name}"
[object]
vertices = [[0, 0], [{w}, 0], [{w}, {h}], [0, {h}]]
[[environment.solids]]
name = "table"
vertices = [[-300, -50], [300, -50], [300, 0], [-300, 0]]
[gripper]
model = "two-point"
finger_radius = 5
spacing = [{lo}, {hi}]
[friction]
environment = {mu_env}
gripper = 0.8
[task]
start = [0, 0, 0]
goal = [0, 0, 0]
"""


def _tip_plan(height: float, turn_deg: float = 5.0, steps: int = 5) -> Plan:
    """One finger on the block's left face at ``height``, the block tipped clockwise about
    its bottom-right corner (40, 0) with the finger carried along (a MoveObject step)."""
    grip0 = Pose(-35.0, height, math.pi)  # finger 1 at (-5, height), finger 2 further left
    wps = []
    for k in range(steps + 1):
        a = -math.radians(turn_deg) * k / steps
        c, s = math.cos(a), math.sin(a)
        obj = Pose(40.0 - c * 40.0, -s * 40.0, a)  # the turn about (40, 0)
        contact = obj.apply((0.0, height))
        wps.append(Waypoint(obj, obj.compose(grip0), 60.0, ((float(contact[0]), float(contact[1])), None)))
    step = Step("tip", Family.MOVE_OBJECT, {}, ("l1-e1", "v2-e1"), tuple(wps))
    return Plan(PLAN_FORMAT, "tall-block", "0" * 64, PlanStatus.SOLVED, (step,), PlanStats())


@pytest.mark.parametrize("mu_env, height, ambiguous", [
    (0.9, 90.0, False),  # tipping needs 0.22 W of push, sliding 0.9 W: it tips as planned
    (0.1, 90.0, True),   # sliding needs 0.1 W: the block slides along the table instead
    (0.9, 15.0, False),  # held low, the finger rises along the arc and lifts the block's side by
                         # friction (0.43 W of push, floor friction within 0.9): it tips
])
def test_a_one_finger_tip_is_refused_when_the_block_would_slide(mu_env: float, height: float, ambiguous: bool) -> None:
    text = BLOCK_ON_TABLE.format(name="tall-block", w=40, h=100, lo=20, hi=140, mu_env=mu_env)
    scenario = load_scenario_string(text, "tall-block")
    report = forward_check(_tip_plan(height), scenario)
    assert report.checked > 0
    assert (not report.ok) is ambiguous
    if ambiguous:
        assert report.step == 0 and report.waypoint == 0 and "-e3 slides" in report.reason  # the table top is e3


def test_a_pinch_of_a_gripper_that_closes_is_left_to_the_grip_force() -> None:
    plan = read_plan(SPEC / "pick-plan.json")
    report = forward_check(plan, load_scenario(SPEC / "pick.toml"))
    assert report.ok


def test_a_tip_the_fingers_do_not_force_is_refused() -> None:
    """The concave 11-gon's tip of an earlier planner: finger 1 grazes a corner and rolls
    over it (0.03 mm of overlap at most), finger 2 leaves: the block may stay standing,
    which the physics simulation shows (tests/ldhp_tamp/test_simulate.py)."""
    repo = Path(__file__).resolve().parents[2]
    plan = read_plan(repo / "tests" / "data" / "sim" / "concave11-tip-plan.json")
    report = forward_check(plan, load_scenario(repo / "scenarios" / "gen_lift_concave11.toml"))
    assert not report.ok and report.step == 1 and plan.steps[1].primitive == "tip"
    assert "may stay where it is" in report.reason


def _square(lo: float, hi: float) -> str:
    """An 80 mm square block on the table (mu_e 0.3, mu_g 0.8), the spacing [lo, hi]."""
    return BLOCK_ON_TABLE.format(name="square-block", w=80, h=80, lo=lo, hi=hi, mu_env=0.3)


def _corner_tip_plan(turn_deg: float = 5.0, steps: int = 5) -> tuple[Plan, float]:
    """Two fingers on the square block's top-right corner, finger 1 on its right face at
    height 75 and finger 2 on its top at x = 60 (normals at right angles), the block
    tipped counter-clockwise about its bottom-left corner with the gripper carried along."""
    c1, c2 = (85.0, 75.0), (60.0, 85.0)
    w = math.hypot(c2[0] - c1[0], c2[1] - c1[1])
    grip0 = Pose((c1[0] + c2[0]) / 2, (c1[1] + c2[1]) / 2, math.atan2(c2[1] - c1[1], c2[0] - c1[0]))
    wps = []
    for k in range(steps + 1):
        obj = Pose(0.0, 0.0, math.radians(turn_deg) * k / steps)
        p1, p2 = obj.apply((80.0, 75.0)), obj.apply((60.0, 80.0))
        wps.append(Waypoint(obj, obj.compose(grip0), w, ((float(p1[0]), float(p1[1])), (float(p2[0]), float(p2[1])))))
    step = Step("tip", Family.MOVE_OBJECT, {}, ("l1-e1", "v1-e1"), tuple(wps))
    return Plan(PLAN_FORMAT, "square-block", "0" * 64, PlanStatus.SOLVED, (step,), PlanStats()), w


def test_two_fingers_on_a_corner_of_a_gripper_that_closes_are_left_to_the_grip_force() -> None:
    """The quarter turn's tip: a corner pinch (one finger on the side, one on the top) of
    a gripper that closes under force grips the corner; neither finger can let go, and the
    grip is the physics replay's to judge (which executes the quarter turn's plan). The
    same fingers rigid on a fixed-width gripper squeeze nothing: the top one may let go
    and the side one push the block along the table instead of tipping it (tipping about
    the far corner takes 0.53 W at height 75, sliding 0.3 W)."""
    plan, w = _corner_tip_plan()
    closing = load_scenario_string(_square(10, 150), "square-block")
    assert forward_check(plan, closing).ok
    rigid = load_scenario_string(_square(w, w), "square-block")
    report = forward_check(plan, rigid)
    assert not report.ok and report.step == 0 and report.waypoint == 0, report.reason


def test_a_finger_rolling_on_the_object_is_seen_rolling(wedged_inverse) -> None:
    """A rolling pivot (task 1's inverse, the block on its corner at 75 degrees, finger 2
    rolling along the long side under it while finger 1 lets go): the object stays still.
    Between two waypoints the gripper's screw turns about a point half a step ahead of the
    contact, so the displacement to the next waypoint alone has the finger's surface leave
    the object by radius x turn^2 / 2, and the block following it balances too; the motion
    from the previous waypoint to the next is centred on the contact."""
    from ldhp_tamp.primitives import adjust_grasp as ag

    sc, ctx, start, pose = wedged_inverse.scenario, wedged_inverse.context, wedged_inverse.start, wedged_inverse.pose
    edges = wedged_inverse.pivots
    rolls = np.flatnonzero((edges.src == start) & (np.abs(edges.sense) == ag.ROLL_SENSE))
    assert rolls.size
    i = int(rolls[0])
    step = Step("pivot", Family.ADJUST_GRASP, ag.Pivot().parameters(ctx, edges, i), ("v2-e1", "v2-e1"),
                ag.Pivot().waypoints(ctx, pose, edges, i))
    plan = Plan(PLAN_FORMAT, sc.name, sc.sha256, PlanStatus.SOLVED, (step,), PlanStats())
    report = forward_check(plan, sc)
    assert report.checked > 0 and report.ok, report.reason
