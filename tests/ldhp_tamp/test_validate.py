"""The plan validator: rules 0-9 of ``ldhp-plan/1`` and ``ldhp-tamp validate``.

Test data: the spec's examples (``pick.toml``, a valid and an invalid plan) and
``tests/data/plans/*.json``, each the valid example edited to break exactly one rule (the
file's ``breaks_rule`` key says which; its ``description`` says how; an ``against`` key
names another scenario in that folder to check it against, e.g. one with ``max_force``).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from geometry.poses import Pose
from ldhp_tamp.cli import main
from ldhp_tamp.plan import Family, Plan, PlanStatus, Step, Waypoint, read_plan
from ldhp_tamp.scenario import Scenario, load_scenario, load_scenario_string
from ldhp_tamp.validate import RULES, ValidationReport, format_violation, validate_plan

#: The format's examples: copies of docs/formats/examples (test_spec_copies.py keeps them equal).
EXAMPLES = Path(__file__).resolve().parents[1] / "data" / "spec"
BROKEN = Path(__file__).resolve().parents[1] / "data" / "plans"
PICK_TOML = EXAMPLES / "pick.toml"
VALID = EXAMPLES / "pick-plan.json"
INVALID = EXAMPLES / "pick-plan-invalid.json"


@pytest.fixture(scope="module")
def pick() -> Scenario:
    return load_scenario(PICK_TOML, check_planner=False)


@pytest.fixture(scope="module")
def plan() -> Plan:
    return read_plan(VALID)


def variant(edit: Callable[[str], str]) -> Scenario:
    """pick.toml with its text edited (the sha256 changes with it)."""
    text = edit(PICK_TOML.read_text())
    return load_scenario_string(text, "pick-variant.toml", check_planner=False)


def edit_step(plan: Plan, index: int, waypoints) -> Plan:
    steps = list(plan.steps)
    steps[index] = replace(steps[index], waypoints=tuple(waypoints))
    return replace(plan, steps=tuple(steps))


def where(report: ValidationReport) -> list[tuple[int, int | None, int | None, int | None]]:
    return [(v.rule, v.step, v.waypoint, v.last_waypoint) for v in report.violations]


# --------------------------------------------------------------------------- the examples


def test_the_valid_example_is_valid(pick: Scenario, plan: Plan) -> None:
    report = validate_plan(plan, pick)
    assert report.valid and report.violations == () and report.warnings == ()
    assert (report.steps_checked, report.waypoints_checked) == (3, 57)
    assert report.contacts_checked == 2 * 22 and report.support_checks == 57


def test_a_plans_arrays_and_support_batches_are_made_once_and_read_only(pick: Scenario, plan: Plan) -> None:
    """The judge validates a plan and then checks its forward problem: both read the same
    arrays (read-only) and support batches, made once for that plan object; another plan
    object, even an equal one, gets its own; the batches are those made afresh."""
    from ldhp_tamp.validate import PlanArrays, _batches_of, _support_batches

    flat = PlanArrays.of(plan)
    assert PlanArrays.of(plan) is flat and not flat.obj.flags.writeable and not flat.step.flags.writeable
    other = replace(plan)
    assert PlanArrays.of(other) is not flat and np.array_equal(PlanArrays.of(other).grip, flat.grip)
    world = pick.world
    made = _support_batches(world, flat)
    assert _support_batches(world, flat) is made and len(made)
    fresh = list(_batches_of(world, flat))
    assert len(fresh) == len(made)
    for a, b in zip(made, fresh):
        assert np.array_equal(a.rows, b.rows) and np.array_equal(a.com, b.com)
        assert np.array_equal(a.full.points, b.full.points) and np.array_equal(a.moving.modes, b.moving.modes)
    assert validate_plan(plan, pick).valid  # the example stays valid read through the kept arrays


def test_the_invalid_example_breaks_exactly_rules_5_and_7(pick: Scenario) -> None:
    report = validate_plan(read_plan(INVALID), pick)
    assert not report.valid and report.rules_broken == {5, 7}
    # the lift (step 1): no finger at any waypoint; unsupported once off the table
    assert where(report) == [(5, 1, 0, 20), (7, 1, 1, 20)]
    assert report.warnings == ()


BROKEN_FILES = sorted(BROKEN.glob("*.json"))


def test_there_is_a_broken_plan_for_every_rule() -> None:
    rules = {json.loads(p.read_text())["breaks_rule"] for p in BROKEN_FILES}
    assert rules == set(range(10)) == set(RULES)


def against(path: Path, pick: Scenario) -> Scenario:
    """The scenario a broken plan is checked against: ``pick.toml`` unless it names another."""
    other = json.loads(path.read_text()).get("against")
    return pick if other is None else load_scenario(path.parent / other, check_planner=False)


@pytest.mark.parametrize("path", BROKEN_FILES, ids=[p.stem for p in BROKEN_FILES])
def test_each_broken_plan_breaks_exactly_its_rule(path: Path, pick: Scenario) -> None:
    rule = json.loads(path.read_text())["breaks_rule"]
    report = validate_plan(read_plan(path), against(path, pick))
    assert report.rules_broken == {rule}, [format_violation(v, read_plan(path)) for v in report.violations]
    assert report.warnings == ()


# --------------------------------------------------------------------------- rule 1


def test_a_failed_or_empty_plan_is_invalid(pick: Scenario, plan: Plan) -> None:
    failed = replace(plan, status=PlanStatus.FAILED, steps=(), reason="no grasp sequence")
    report = validate_plan(failed, pick)
    assert where(report) == [(1, None, None, None), (1, None, None, None)]
    assert "no grasp sequence" in report.violations[0].message + report.violations[1].message
    other = validate_plan(replace(plan, format="ldhp-plan/0"), pick)
    assert where(other) == [(1, None, None, None)]
    empty = Step("close", Family.ADJUST_GRASP, {}, ("l1-e1", "l1-e1"), ())
    hollow = replace(plan, steps=plan.steps[:1] + (empty,) + plan.steps[1:])  # the others still join
    assert where(validate_plan(hollow, pick)) == [(1, 1, None, None)]


def test_steps_must_join(pick: Scenario, plan: Plan) -> None:
    close = plan.steps[1].waypoints
    # the close ends at 101.5 mm; the lift starts at 100 mm: a 1.5 mm seam
    broken = edit_step(plan, 1, close[:4] + (replace(close[4], width=101.5),))
    report = validate_plan(broken, pick)
    assert where(report) == [(1, 2, 0, None)]
    assert "width 101.50 -> 100.00 mm" in report.violations[0].message


def test_the_start_grasp_is_checked(plan: Plan) -> None:
    held = variant(lambda t: t + "start_grasp = { gripper = [50, 150, 0], width = 120 }\n")
    assert validate_plan(plan, held).valid
    elsewhere = variant(lambda t: t + "start_grasp = { gripper = [50, 148, 0.5], width = 118.5 }\n")
    report = validate_plan(plan, elsewhere)
    assert where(report) == [(1, 0, 0, None), (1, 0, 0, None)]
    assert "start_grasp" in report.violations[0].message and "width" in report.violations[1].message


def test_goal_release_means_no_finger_near_the_object(plan: Plan) -> None:
    release = variant(lambda t: t.replace("goal = [0, 100, 0]", "goal = [0, 0, 0]\ngoal_release = true"))
    approach = replace(plan, steps=plan.steps[:1])  # fingers end 10 mm from the block
    assert validate_plan(approach, release).valid
    # close to 101 mm without declaring contacts: each pad 0.5 mm from the block
    last = approach.steps[0].waypoints[-1]
    close = Step("close", Family.ADJUST_GRASP, {}, ("l1-e1", "l1-e1"),
                 tuple(replace(last, width=w) for w in (120, 115, 110, 105, 101)))
    report = validate_plan(replace(plan, steps=(approach.steps[0], close)), release)
    assert where(report) == [(1, 1, 4, None), (1, 1, 4, None)]
    assert "finger 1 still touches" in report.violations[0].message
    # the valid plan ends holding the block: both fingers declare contacts
    lifted = variant(lambda t: t + "goal_release = true\n")
    assert validate_plan(plan, lifted).rules_broken == {1}


# --------------------------------------------------------------------------- rule 2


def test_width_changes_at_most_5_mm(pick: Scenario, plan: Plan) -> None:
    close = plan.steps[1].waypoints
    report = validate_plan(edit_step(plan, 1, [replace(close[0], width=w) for w in (120, 112, 106, 103)] + [close[4]]), pick)
    assert where(report) == [(2, 1, 1, 2)]
    assert "width changes 8.00 mm" in report.violations[0].message


def test_continuity_holds_across_steps(pick: Scenario, plan: Plan) -> None:
    # the approach stops 10 mm up; the close starts at 2 mm: an 8 mm jump over the seam
    report = validate_plan(edit_step(plan, 0, plan.steps[0].waypoints[:-2]), pick)
    assert report.rules_broken == {1, 2}
    assert (2, 1, 0, None) in where(report)


# --------------------------------------------------------------------------- rule 3


@pytest.mark.parametrize("tip, penetrates", [(-1.9, False), (-2.1, True)])
def test_penetration_tolerance_is_the_1_mm_erosion(pick: Scenario, plan: Plan, tip: float, penetrates: bool) -> None:
    # a 10 mm wide fingertip d mm deep: the overlap eroded by 1 mm is empty iff d <= 2
    last = plan.steps[0].waypoints[-1]
    down = replace(last, gripper=Pose(last.gripper.x, tip, 0.0))
    report = validate_plan(edit_step(plan, 0, plan.steps[0].waypoints + (down, last)), pick)
    assert report.rules_broken == ({3} if penetrates else set())


def test_the_palm_collides_with_the_object_but_not_with_the_fingers(plan: Plan) -> None:
    # this palm overlaps the fingers' upper 5 mm: one rigid hand, not a violation
    high = variant(lambda t: t.replace("opening = [0, 140]", "opening = [0, 140]\npalm = [[-90, 40], [90, 40], [90, 60], [-90, 60]]"))
    assert validate_plan(plan, high).valid
    low = variant(lambda t: t.replace("opening = [0, 140]", "opening = [0, 140]\npalm = [[-90, 30], [90, 30], [90, 50], [-90, 50]]"))
    report = validate_plan(plan, low)
    assert report.rules_broken == {3}
    assert {v.message for v in report.violations} == {"the palm penetrates the object"}


# --------------------------------------------------------------------------- rule 4


def _shift_finger1(plan: Plan, dx: float) -> Plan:
    def move(w: Waypoint) -> Waypoint:
        c1, c2 = w.finger_contacts
        return replace(w, finger_contacts=(None if c1 is None else (c1[0] + dx, c1[1]), c2))
    plan = edit_step(plan, 1, map(move, plan.steps[1].waypoints))
    return edit_step(plan, 2, map(move, plan.steps[2].waypoints))


@pytest.mark.parametrize("dx, valid", [(-0.9, True), (-1.2, False), (0.9, True)])
def test_declared_contacts_lie_within_1_mm_of_both_boundaries(pick: Scenario, plan: Plan, dx: float, valid: bool) -> None:
    report = validate_plan(_shift_finger1(plan, dx), pick)
    assert report.rules_broken == (set() if valid else {4})


# --------------------------------------------------------------------------- rule 5


def test_a_contact_cannot_come_and_go_within_a_move_object_step(pick: Scenario, plan: Plan) -> None:
    lift = list(plan.steps[2].waypoints)
    for j in range(5, 10):
        lift[j] = replace(lift[j], finger_contacts=(lift[j].finger_contacts[0], None))
    report = validate_plan(edit_step(plan, 2, lift), pick)
    assert (5, 2, 5, 9) in where(report)
    assert report.rules_broken == {5, 7}  # one horizontal finger cannot carry the block either


# --------------------------------------------------------------------------- rule 6


def test_the_object_may_not_turn_during_an_adjust_grasp_step(pick: Scenario, plan: Plan) -> None:
    # turn the block 1.1 degrees about (50, 0): the origin moves 0.96 mm, both bottom
    # corners stay within 1 mm of the table (still supported), the angle is off
    a = math.radians(1.1)
    turned = Pose(50 - 50 * math.cos(a), -50 * math.sin(a), a)
    close = list(plan.steps[1].waypoints)
    close[2] = replace(close[2], object=turned)
    report = validate_plan(edit_step(plan, 1, close), pick)
    assert where(report) == [(6, 1, 2, None)]
    assert "1.10 deg" in report.violations[0].message


# --------------------------------------------------------------------------- rule 7


@pytest.mark.parametrize("height, rules", [(0.9, set()), (1.1, {1, 7})])
def test_a_vertex_within_1_mm_of_an_edge_is_a_contact(plan: Plan, height: float, rules: set[int]) -> None:
    still = variant(lambda t: t.replace("goal = [0, 100, 0]", "goal = [0, 0, 0]"))
    approach = plan.steps[0]
    floating = replace(approach, waypoints=tuple(replace(w, object=Pose(0, height, 0)) for w in approach.waypoints))
    assert validate_plan(replace(plan, steps=(floating,)), still).rules_broken == rules


TWO_POINT = '''format = "ldhp-scenario/1"
name = "balance"
[object]
vertices = [[0, 0], [100, 0], [100, 40], [0, 40]]
[[environment.solids]]
name = "table"
vertices = [[-300, -50], [300, -50], [300, 0], [-300, 0]]
[gripper]
model = "two-point"
finger_radius = 5
spacing = [80, 80]
[friction]
environment = 0.3
gripper = 0.6
[task]
start = [0, 50, {angle}]
goal = [0, 50, {angle}]
start_grasp = "any"
'''


@pytest.mark.parametrize("tilt, valid", [(0.0, True), (25.0, True), (40.0, False)])
def test_at_an_object_vertex_the_finger_normal_counts(tilt: float, valid: bool) -> None:
    """The block balances on its corner v1 with its centre of mass straight above, held
    from below by a round finger (mu = 0.6: cone half-angle 31 degrees). The contact
    force must be vertical; it is in the cone of the finger's radial normal if the
    finger is at most 31 degrees off the vertical, whatever the corner's edges say."""
    angle = 90.0 - math.degrees(math.atan2(20.0, 50.0))  # centre of mass above v1
    scenario = load_scenario_string(TWO_POINT.format(angle=angle), "balance.toml", check_planner=False)
    corner = np.array([0.0, 50.0])
    t = math.radians(tilt)
    centre = corner - 5.0 * np.array([math.sin(t), math.cos(t)])
    gripper = Pose(centre[0] + 40.0, centre[1], 0.0)  # finger 1 at (-w/2, 0)
    w = Waypoint(Pose(0.0, 50.0, math.radians(angle)), gripper, 80.0, ((0.0, 50.0), None))
    step = Step("air-move", Family.MOVE_OBJECT, {}, ("free", "free"), (w, w))
    plan = Plan("ldhp-plan/1", "balance", scenario.sha256, PlanStatus.SOLVED, (step,), read_plan(VALID).stats)
    report = validate_plan(plan, scenario)
    assert report.rules_broken == (set() if valid else {7}), report.violations


def test_a_contact_that_carries_no_force_does_not_spoil_support(plan: Plan) -> None:
    """Closed cones: on a frictionless table the block also touches a wall on its left,
    which can only push right; the equilibrium needs the wall's force to be zero. The
    weight is balanced (an interior-margin test would say no)."""
    walled = variant(lambda t: t.replace("environment = 0.3", "environment = 0.0").replace(
        "[gripper]", '[[environment.solids]]\nname = "wall"\nvertices = [[-20, 0], [0, 0], [0, 60], [-20, 60]]\n\n[gripper]'
    ).replace("goal = [0, 100, 0]", "goal = [0, 0, 0]"))
    hover = replace(plan.steps[0], waypoints=plan.steps[0].waypoints[:1])  # the gripper 150 mm up
    assert validate_plan(replace(plan, steps=(hover,)), walled).valid


def test_rule_7_agrees_with_the_reference_linear_program(pick: Scenario) -> None:
    """The validator's contacts and verdicts at waypoints of the valid, invalid and
    one-finger plans, against geometry.mechanics.feasible_reference (cvxpy) at margin 0."""
    from geometry import mechanics
    from ldhp_tamp.validate import plan_contacts, PlanArrays, _support

    for path in (VALID, INVALID, BROKEN / "rule7-unsupported.json", BROKEN / "rule5-sliding-contact.json"):
        flat = PlanArrays.of(read_plan(path))
        verdicts = _support(pick.world, flat).rule7
        for i in range(0, len(flat), 7):
            c = plan_contacts(pick.world, flat.take(slice(i, i + 1)))
            on = c.on[0]
            if not on.any():
                assert not verdicts[i]
                continue
            contacts = mechanics.Contacts.make(c.points[0][on], c.normals[0][on], c.mu[0][on])
            com = Pose.from_array(flat.obj[i]).apply(pick.world.object.com)
            ref = mechanics.feasible_reference(contacts, com, pick.world.object.length_scale, margin=0.0)
            assert ref.feasible == verdicts[i], (path.name, i)


# --------------------------------------------------------------------------- warnings


def test_another_scenario_file_is_a_warning_not_a_violation(plan: Plan) -> None:
    commented = variant(lambda t: "# the same problem, another file\n" + t)
    report = validate_plan(plan, commented)
    assert report.valid
    assert len(report.warnings) == 1 and "sha256" in report.warnings[0]


@pytest.mark.parametrize("opening, runs", [("[0, 110]", [(2, 0, 0, 30), (2, 1, 0, 1)]),
                                            ("[0, 119]", []), ("[0, 118.9]", [(2, 0, 0, 30), (2, 1, 0, None)]),
                                            ("[101.5, 140]", [(2, 1, 4, None), (2, 2, 0, 20)])])
def test_every_width_lies_in_the_gripper_range_within_1_mm(plan: Plan, opening: str, runs: list) -> None:
    """Rule 2: widths 120 (approach), 120..100 (close), 100 (lift) against [min, max]."""
    narrow = variant(lambda t: t.replace("opening = [0, 140]", f"opening = {opening}"))
    report = validate_plan(plan, narrow)
    assert where(report) == runs
    assert all("outside the gripper's opening" in v.message for v in report.violations)


# --------------------------------------------------------------------------- speed


def test_a_long_plan_validates_quickly(pick: Scenario, plan: Plan) -> None:
    """2,000 waypoints turning the held block about its centre of mass, 0.1 degree each."""
    last = plan.steps[-1].waypoints[-1]
    com = np.array([50.0, 120.0])
    turn = []
    for k in range(2000):
        r = Pose(0.0, 0.0, math.radians(0.1 * k))

        def about(p: Pose) -> Pose:
            c = r.apply(p.position - com) + com
            return Pose(float(c[0]), float(c[1]), p.theta + r.theta)

        contacts = tuple(tuple(map(float, r.apply(np.array(c) - com) + com)) for c in last.finger_contacts)
        turn.append(Waypoint(about(last.object), about(last.gripper), last.width, contacts))
    long = replace(plan, steps=plan.steps + (Step("air-move", Family.MOVE_OBJECT, {}, ("free", "free"), tuple(turn)),))
    t0 = time.perf_counter()
    report = validate_plan(long, pick)
    elapsed = time.perf_counter() - t0
    assert report.waypoints_checked == 2057
    assert where(report) == [(1, 3, 1999, None)]  # it ends turned 199.9 degrees, not at the goal
    assert elapsed < 60.0  # a hang guard only: ~0.15 s here, but the verdict must not depend on the load


# --------------------------------------------------------------------------- the command line


def test_cli_valid_plan(capsys) -> None:
    assert main(["validate", str(VALID), "--scenario", str(PICK_TOML)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 1 and out[0].startswith("valid: ")


def test_cli_prints_each_violation_then_a_verdict(capsys) -> None:
    assert main(["validate", str(INVALID), "--scenario", str(PICK_TOML)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("rule 5 (move-object keeps the grasp), step 1 (air-move), waypoints 0-20: ")
    assert out[1].startswith("rule 7 (quasi-static support), step 1 (air-move), waypoints 1-20: ")
    assert out[2].startswith("invalid: ") and "2 violations of rules 5" in out[2]
    assert len(out) == 3


def test_cli_warns_about_another_scenario_file(tmp_path: Path, capsys) -> None:
    other = tmp_path / "pick.toml"
    other.write_text("# edited\n" + PICK_TOML.read_text())
    assert main(["validate", str(VALID), "--scenario", str(other)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("warning: ") and "sha256" in out[0] and out[1].startswith("valid: ")


@pytest.mark.parametrize("plan_text, scenario_text, fragment", [
    ("{", None, "not valid JSON"),
    ('{"format": "ldhp-plan/1"}', None, "missing key"),
    (None, "format = 'ldhp-scenario/1'\n", "scenario.toml"),
])
def test_cli_bad_input_exits_2_naming_the_file(tmp_path: Path, capsys, plan_text, scenario_text, fragment) -> None:
    plan_path, scenario_path = VALID, PICK_TOML
    if plan_text is not None:
        plan_path = tmp_path / "plan.json"
        plan_path.write_text(plan_text)
    if scenario_text is not None:
        scenario_path = tmp_path / "scenario.toml"
        scenario_path.write_text(scenario_text)
    assert main(["validate", str(plan_path), "--scenario", str(scenario_path)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith("error: ") and fragment in captured.err
    assert (str(plan_path) if plan_text is not None else str(scenario_path)) in captured.err
    assert "Traceback" not in captured.err


def test_cli_missing_files_exit_2(tmp_path: Path, capsys) -> None:
    assert main(["validate", str(tmp_path / "nope.json"), "--scenario", str(PICK_TOML)]) == 2
    assert "nope.json: cannot read" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["validate", str(VALID)])  # --scenario is required
    assert exc.value.code == 2


# --------------------------------------------------------------------------- rule 0


def test_primitives_match_the_domain_case_insensitively(pick: Scenario, plan: Plan) -> None:
    steps = list(plan.steps)
    steps[1] = replace(steps[1], primitive="Close")
    assert validate_plan(replace(plan, steps=tuple(steps)), pick).valid
    steps[1] = replace(steps[1], primitive="close", family=Family.MOVE_OBJECT)
    report = validate_plan(replace(plan, steps=tuple(steps)), pick)
    assert (0, 1, None, None) in where(report)
    assert "family is 'move-object', but 'close' is adjust-grasp in domain 'ldhp'" in report.violations[0].message


def test_rule_0_reads_the_domain_the_scenario_names(plan: Plan, tmp_path: Path) -> None:
    from ldhp_tamp.errors import DomainError

    no_air = Path(__file__).resolve().parents[1] / "data" / "domains" / "no-air-move.pddl"
    ablated = variant(lambda t: t + f"\n[planner]\ndomain = {json.dumps(str(no_air))}\n")
    report = validate_plan(plan, ablated)
    assert where(report) == [(0, 2, None, None)] and "'air-move' is not an action" in report.violations[0].message
    unknown = variant(lambda t: t + "\n[planner]\ndomain = \"no-such-domain\"\n")
    with pytest.raises(DomainError, match="no-such-domain"):
        validate_plan(plan, unknown)


# --------------------------------------------------------------------------- rule 8


def _balance(step_deg: float, steps: int = 3) -> tuple[Plan, Scenario]:
    """The block balanced on its corner v1 = (0, 50) above a round finger (radius 5,
    centre (0, 45)); the gripper pivots about that centre by ``step_deg`` per waypoint
    while the block stays: the finger's surface slips under the corner by 5 x turn."""
    angle = 90.0 - math.degrees(math.atan2(20.0, 50.0))
    scenario = load_scenario_string(TWO_POINT.format(angle=angle), "balance.toml", check_planner=False)
    centre = np.array([0.0, 45.0])
    obj = Pose(0.0, 50.0, math.radians(angle))
    wps = []
    for j in range(steps + 1):
        phi = math.radians(step_deg * j)
        origin = centre + 40.0 * np.array([math.cos(phi), math.sin(phi)])  # finger 1 at (-w/2, 0)
        wps.append(Waypoint(obj, Pose(float(origin[0]), float(origin[1]), phi), 80.0, ((0.0, 50.0), None)))
    step = Step("pivot", Family.ADJUST_GRASP, {}, ("free", "free"), tuple(wps))
    return Plan("ldhp-plan/1", "balance", scenario.sha256, PlanStatus.SOLVED, (step,), read_plan(VALID).stats), scenario


@pytest.mark.parametrize("step_deg, rules", [(1.0, set()), (2.0, {8}), (-2.0, {8})])
def test_a_round_finger_pivoting_about_its_centre_slips(step_deg: float, rules: set[int]) -> None:
    """5 mm x 1 deg = 0.087 mm per motion sticks; 5 mm x 2 deg = 0.175 mm slides, and a
    sliding contact's force is on a cone edge: it cannot hold the corner up vertically."""
    from ldhp_tamp.validate import plan_contacts, PlanArrays, _motion

    plan, scenario = _balance(step_deg)
    report = validate_plan(plan, scenario)
    assert report.rules_broken == rules, [format_violation(v, plan) for v in report.violations]
    if rules:
        assert where(report) == [(8, 0, 0, 2)]
        assert f"finger 1 slips {5 * math.radians(abs(step_deg)):.2f} mm" in report.violations[0].message
    flat = PlanArrays.of(plan)
    c = plan_contacts(scenario.world, flat)
    mo = _motion(scenario.world, flat, np.arange(len(flat)), c)
    j = int(np.flatnonzero((c.finger == 0) & c.on[0])[0])  # the radial normal at the corner
    # the finite turn: the chord 2 r sin(d/2), whose component along the tangent is r sin d
    assert np.abs(mo.drift[:3, j]) == pytest.approx([5 * math.sin(math.radians(abs(step_deg)))] * 3, rel=1e-9)
    assert not mo.sliding[3].any()  # nothing after the last waypoint


def _slide(plan: Plan, dy: float, n: int = 3) -> Plan:
    """The valid plan, then a slide: the gripper moves dy per waypoint along the held
    block's ends (n waypoints), the block stays in the air."""
    last = plan.steps[-1].waypoints[-1]
    wps = tuple(replace(last, gripper=Pose(last.gripper.x, last.gripper.y + dy * j, 0.0)) for j in range(n + 1))
    return replace(plan, steps=plan.steps + (Step("slide", Family.ADJUST_GRASP, {}, ("free", "free"), wps),))


@pytest.mark.parametrize("dy, rules", [(-1.0, {8}), (1.0, set()), (-0.09, set())])
def test_a_short_slide_is_checked_sliding(pick: Scenario, plan: Plan, dy: float, rules: set[int]) -> None:
    """Both pads slide 3 mm along the held block's ends over three waypoints. Sliding
    down, their friction pulls the block down: it falls (rule 8). Sliding up, kinetic
    friction mu N carries it exactly as sticking friction could (valid). Under 0.1 mm
    per motion the pads stick."""
    from ldhp_tamp.validate import plan_contacts, PlanArrays, _motion

    slid = _slide(plan, dy)
    report = validate_plan(slid, pick)
    assert report.rules_broken == rules
    if rules:
        assert where(report) == [(8, 3, 0, 2)]
        assert "finger 1 slips 1.00 mm, finger 2 slips 1.00 mm" in report.violations[0].message
    flat = PlanArrays.of(slid).take(slice(-4, None))
    full = PlanArrays.of(slid)
    c = plan_contacts(pick.world, flat)
    mo = _motion(pick.world, full, np.arange(len(full) - 4, len(full)), c)
    fingers = c.finger >= 0
    sliding = mo.sliding[:, fingers & c.on[0]]
    assert sliding[:3].all() == (abs(dy) > 0.1) and not sliding[3].any()
    if abs(dy) > 0.1:  # the object's velocity relative to the pads: opposite the gripper's
        dirs = mo.slide_dirs[:3][:, fingers & c.on[0]]
        assert dirs[..., 1] == pytest.approx(np.full(dirs.shape[:2], -math.copysign(1.0, dy)))


def test_a_width_change_moves_each_finger_by_half_of_it(pick: Scenario) -> None:
    """A fingertip resting on the block's top face while the gripper closes 1 mm per
    waypoint: finger 1 moves +0.5 mm along the face (slides), the block stays on the table."""
    from ldhp_tamp.validate import plan_contacts, PlanArrays, _motion

    wps = tuple(Waypoint(Pose(0.0, 0.0, 0.0), Pose(50.0, 40.0, 0.0), 60.0 - j, ((15.0 + 0.5 * j, 40.0), None))
                for j in range(4))
    plan = replace(read_plan(VALID), steps=(Step("close", Family.ADJUST_GRASP, {}, ("l1-e1", "l1-e1"), wps),))
    still = variant(lambda t: t.replace("goal = [0, 100, 0]", "goal = [0, 0, 0]"))
    assert validate_plan(plan, still).valid  # the table carries the block: the slip is harmless
    flat = PlanArrays.of(plan)
    c = plan_contacts(still.world, flat)
    mo = _motion(still.world, flat, np.arange(4), c)
    j = int(np.flatnonzero((c.finger == 0) & c.on[0])[0])
    # the top face's inward normal is (0, -1), t = (1, 0): the block moves -0.5 mm relative to finger 1
    assert mo.drift[:3, j] == pytest.approx([-0.5] * 3) and mo.sliding[:3, j].all()


# --------------------------------------------------------------------------- rule 9


@pytest.mark.parametrize("limit, valid", [(8.2, True), (8.15, False), (100.0, True)])
def test_the_finger_force_limit(plan: Plan, limit: float, valid: bool) -> None:
    """A 1 kg block pinched with mu = 0.6 needs 9.81 / 1.2 = 8.175 N per finger in the air."""
    bounded = variant(lambda t: t.replace("opening = [0, 140]", f"opening = [0, 140]\nmax_force = {limit}"))
    report = validate_plan(plan, bounded)
    assert report.valid == valid
    assert report.force_checks == 1 + 21  # the close's last waypoint and the lift
    if not valid:
        assert where(report) == [(9, 2, 1, 20)]
        assert "8.18 N at least" in report.violations[0].message


def test_heavier_objects_need_more_force(plan: Plan) -> None:
    light = variant(lambda t: t.replace("opening = [0, 140]", "opening = [0, 140]\nmax_force = 5")
                    .replace("[object]", "[object]\nmass = 0.5"))
    assert validate_plan(plan, light).valid  # 4.09 N per finger
    heavy = variant(lambda t: t.replace("opening = [0, 140]", "opening = [0, 140]\nmax_force = 5")
                    .replace("[object]", "[object]\nmass = 0.7"))
    assert validate_plan(plan, heavy).rules_broken == {9}  # 5.72 N


def test_cli_names_the_new_rules(capsys) -> None:
    path = BROKEN / "rule9-pinch-above-max-force.json"
    assert main(["validate", str(path), "--scenario", str(BROKEN / "pick-max-force-8.toml")]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("rule 9 (finger force limit), step 2 (air-move), waypoints 1-20: ")
    assert "violation of rules 9 (finger force limit)" in out[-1]


# --------------------------------------------------------------------------- support analysis


def _pinch_at(plan: Plan, low: float, high: float) -> Plan:
    """The valid plan with the lift's pinch skewed: finger 1 touches the block's left end
    ``low`` mm above its bottom, finger 2 the right end ``high`` mm above it."""
    lift = plan.steps[2]
    wps = tuple(replace(w, finger_contacts=((0.0, w.object.y + low), (100.0, w.object.y + high)))
                for w in lift.waypoints)
    return edit_step(plan, 2, wps)


def test_support_analysis_of_the_spec_example(pick: Scenario, plan: Plan) -> None:
    """By hand: on the table (no finger, or fingers that need not squeeze) the block
    holds frictionless (0). In the air two opposite fingers at one height hold W = 9.81 N
    with any friction given enough squeeze N (mu f >= W / (2 N)), so the least fraction
    is the bisection's floor, above 0; the least squeeze is N = W / (2 mu) = 8.175 N per
    finger, each carrying W / 2 = 4.905 N tangentially: upward, which is clockwise on
    the left end (-) and counter-clockwise on the right end (+)."""
    from ldhp_tamp.validate import SUPPORT_ROUNDS, support_analysis

    a = support_analysis(plan, pick)
    lifted = (a.step == 2) & (a.waypoint >= 1)
    assert a.friction_needed.shape == (57,) and a.finger_forces.shape == (57, 2, 2)
    assert (a.friction_needed[~lifted] == 0).all()
    assert (a.friction_needed[lifted] > 0).all() and (a.friction_needed[lifted] <= 2.0 ** -SUPPORT_ROUNDS).all()
    assert a.margin == pytest.approx(1.0, abs=1e-6) and a.margin < 1.0
    assert a.worst_at == (2, 1)
    assert a.largest_finger_force == pytest.approx(9.81 / 1.2, abs=1e-6)
    assert a.finger_forces[lifted] == pytest.approx(np.broadcast_to([[8.175, -4.905], [8.175, 4.905]], (20, 2, 2)),
                                                    abs=1e-6)
    assert a.max_finger_force[lifted] == pytest.approx(np.full(20, 8.175), abs=1e-6)
    untouched = ~pick_declared(plan)
    assert np.isnan(a.finger_forces[untouched]).all() and np.isnan(a.max_finger_force[untouched]).all()
    on_table = np.flatnonzero(pick_declared(plan) & ~lifted)  # the close's last waypoint, the lift's first
    assert on_table.tolist() == [35, 36]
    assert a.finger_forces[on_table] == pytest.approx(np.zeros((2, 2, 2)))  # the table carries the block


def pick_declared(plan: Plan) -> np.ndarray:
    """(W,) whether any finger declares a contact at each waypoint."""
    return np.array([any(c is not None for c in w.finger_contacts) for w in plan.waypoints])


def test_friction_needed_is_inf_where_the_plan_drops_the_block(pick: Scenario) -> None:
    from ldhp_tamp.validate import support_analysis

    a = support_analysis(read_plan(INVALID), pick)
    air = (a.step == 1) & (a.waypoint >= 1)
    assert np.isinf(a.friction_needed[air]).all() and (a.friction_needed[~air] == 0).all()
    assert a.margin == -math.inf and a.worst_at == (1, 1)
    assert np.isnan(a.finger_forces).all() and a.largest_finger_force == 0.0


def test_a_skewed_pinch_needs_a_fraction_of_its_friction(pick: Scenario, plan: Plan) -> None:
    """Fingers 30 mm apart in height on the ends of a 100 mm block: with squeeze N the
    moment balance gives T1 - T2 = 0.6 N and T1 + T2 = W, so T1 = W / 2 + 0.3 N <= mu f N
    for some N iff mu f > 0.3: f > 0.3 / 0.6 = 0.5. At the gripper's mu (0.6) the least
    squeeze is N = W / (2 (0.6 - 0.3)) = 16.35 N, finger 1 carrying the whole weight."""
    from ldhp_tamp.validate import support_analysis

    a = support_analysis(_pinch_at(plan, 5.0, 35.0), pick)
    lifted = (a.step == 2) & (a.waypoint >= 1)
    assert a.friction_needed[lifted] == pytest.approx(np.full(20, 0.5), abs=1e-6)
    assert (a.friction_needed[lifted] > 0.5).all()  # at exactly 0.5 the cones' edges are parallel: no balance
    assert a.margin == pytest.approx(0.5, abs=1e-6) and a.worst_at == (2, 1)
    assert a.finger_forces[lifted] == pytest.approx(np.broadcast_to([[16.35, -9.81], [16.35, 0.0]], (20, 2, 2)),
                                                    abs=1e-5)
    assert a.largest_finger_force == pytest.approx(16.35, abs=1e-5)
    too_skewed = support_analysis(_pinch_at(plan, 5.0, 35.0 + 35.0), pick)  # 70 mm: 0.7 > 0.6
    assert np.isinf(too_skewed.friction_needed[lifted]).all() and too_skewed.margin == -math.inf


def test_the_force_limit_changes_neither_friction_nor_forces(pick: Scenario, plan: Plan) -> None:
    """``max_force`` below what the pinch needs breaks rule 9, but the analysis reports the
    friction with unbounded squeeze and the least squeeze, as without the limit."""
    from ldhp_tamp.validate import support_analysis

    bounded = variant(lambda t: t.replace("opening = [0, 140]", "opening = [0, 140]\nmax_force = 5"))
    a, b = support_analysis(plan, pick), support_analysis(plan, bounded)
    assert np.array_equal(a.friction_needed, b.friction_needed)
    assert np.allclose(a.finger_forces, b.finger_forces, equal_nan=True, atol=1e-9)
    assert b.largest_finger_force == pytest.approx(8.175, abs=1e-6)


@pytest.mark.parametrize("dy, holds", [(1.0, True), (-1.0, False)])
def test_support_analysis_uses_the_motions_sliding_modes(pick: Scenario, plan: Plan, dy: float, holds: bool) -> None:
    """The pads slide 1 mm per waypoint along the held block's ends (rule 8 test above):
    sliding up, kinetic friction carries the block with any friction; sliding down it
    pulls the block down whatever the friction (inf). The last waypoint has full cones."""
    from ldhp_tamp.validate import support_analysis

    a = support_analysis(_slide(plan, dy), pick)
    sliding = a.friction_needed[-4:-1]
    assert (np.isfinite(sliding) & (sliding < 1e-6)).all() if holds else np.isinf(sliding).all()
    assert 0 < a.friction_needed[-1] < 1e-6
    assert a.worst_at == ((2, 1) if holds else (3, 0))


def test_support_analysis_is_fast(pick: Scenario, plan: Plan) -> None:
    """2,057 waypoints, 2,022 of them pinched (an LP each) and a bisection over all."""
    from ldhp_tamp.validate import support_analysis

    last = plan.steps[-1].waypoints[-1]
    up = tuple(replace(last, object=Pose(0.0, 100.0 + 0.001 * k, 0.0), gripper=Pose(50.0, 102.0 + 0.001 * k, 0.0),
                       finger_contacts=((0.0, 120.0 + 0.001 * k), (100.0, 120.0 + 0.001 * k))) for k in range(2000))
    long = replace(plan, steps=plan.steps + (Step("air-move", Family.MOVE_OBJECT, {}, ("free", "free"), up),))
    support_analysis(plan, pick)  # imports scipy
    t0 = time.perf_counter()
    a = support_analysis(long, pick)
    elapsed = time.perf_counter() - t0
    assert a.friction_needed.shape == (2057,) and np.isfinite(a.max_finger_force).sum() == 1 + 21 + 2000
    assert elapsed < 60.0  # a hang guard only: ~0.5 s here, but the verdict must not depend on the load


def test_the_planner_annotates_its_plans_with_the_analysis(pick: Scenario, plan: Plan, tmp_path: Path) -> None:
    """``tamp._annotate``, run on every solved plan: each waypoint gets its finger forces
    (``null`` for a finger without contact), the stats the margin, where it is least and
    the largest finger force; the plan still validates and survives the file."""
    from ldhp_tamp.plan import plan_to_json, read_plan_string, write_plan
    from ldhp_tamp.tamp import _annotate

    annotated = _annotate(plan, pick)
    wps = annotated.waypoints
    assert all(w.finger_forces is not None for w in wps)
    assert wps[0].finger_forces == (None, None)
    assert wps[35].finger_forces == ((0.0, 0.0), (0.0, 0.0))  # closed on the block, the table carries it
    assert np.array(wps[-1].finger_forces) == pytest.approx(np.array([[8.175, -4.905], [8.175, 4.905]]), abs=1e-6)
    extra = annotated.stats.extra
    assert extra["support_margin"] == 1.0 and extra["support_margin_at"] == {"step": 2, "waypoint": 1}
    assert extra["max_finger_force_n"] == pytest.approx(8.175)
    assert validate_plan(annotated, pick).valid
    path = write_plan(annotated, tmp_path / "annotated.json")
    data = json.loads(path.read_text())
    assert data["stats"]["support_margin_at"] == {"step": 2, "waypoint": 1}
    assert np.array(data["steps"][2]["waypoints"][-1]["finger_forces"]) == pytest.approx(
        np.array([[8.175, -4.905], [8.175, 4.905]]), abs=1e-5)
    back = read_plan(path)
    assert back.stats.extra["max_finger_force_n"] == pytest.approx(8.175, abs=1e-5)
    assert plan_to_json(read_plan_string(path.read_text())) == path.read_text()
    skewed = _annotate(_pinch_at(plan, 5.0, 35.0), pick)
    assert skewed.stats.extra["support_margin"] == 0.5
    assert skewed.stats.extra["max_finger_force_n"] == pytest.approx(16.35)


@pytest.mark.parametrize("path", BROKEN_FILES + [VALID, INVALID], ids=lambda p: p.name)
def test_friction_needed_is_inf_exactly_where_rules_7_or_8_fail(path: Path, pick: Scenario) -> None:
    """The analysis and the validator agree: ``inf`` where rule 7 or 8 fails, a fraction
    in [0, 1] elsewhere, and finger forces wherever a finger touches a balanced waypoint."""
    from ldhp_tamp.validate import PlanArrays, _support, support_analysis

    plan = read_plan(path)
    scenario = load_scenario(BROKEN / "pick-max-force-8.toml", check_planner=False) if "rule9" in path.name else pick
    flat = PlanArrays.of(plan)
    sup = _support(scenario.world, flat)
    a = support_analysis(plan, scenario)
    held = sup.rule7 & sup.rule8
    assert np.array_equal(np.isinf(a.friction_needed), ~held)
    assert ((a.friction_needed[held] >= 0) & (a.friction_needed[held] <= 1)).all()
    touched = held[:, None] & flat.declared
    assert np.isfinite(a.finger_forces[touched]).all() and np.isnan(a.finger_forces[~touched]).all()


@pytest.mark.parametrize("name", ["task1_zero_mobility_lift_tilt70", "gen_slot_corner_start", "cmgmp_book_stand_up"])
def test_the_worst_waypoint_alone_is_the_full_analysis_worst(name: str) -> None:
    """``worst_only`` (what a solve writes into its plan's stats) drops waypoints from the
    bisection once another's bracket lies above theirs: the margin, where it is least and
    the forces are the full analysis's, and every value it leaves inexact is below the
    worst's."""
    from ldhp_tamp.validate import support_analysis

    root = Path(__file__).resolve().parents[2]
    scenario = load_scenario(root / "scenarios" / f"{name}.toml")
    plan = read_plan(root / "docs" / "results" / "plans" / f"{name}-plan.json")
    full = support_analysis(plan, scenario)
    worst = support_analysis(plan, scenario, worst_only=True)
    assert worst.margin == full.margin and worst.worst_at == full.worst_at
    assert worst.finger_forces.tobytes() == full.finger_forces.tobytes()
    assert worst.largest_finger_force == full.largest_finger_force
    inexact = worst.friction_needed != full.friction_needed
    assert inexact.any()  # the pruning happened
    assert (worst.friction_needed[inexact] >= full.friction_needed[inexact]).all()
    assert (worst.friction_needed[inexact] < full.friction_needed.max()).all()
