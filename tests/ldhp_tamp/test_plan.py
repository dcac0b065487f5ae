"""Plans (``ldhp-plan/1``): the model, reading, writing (atomic), round trips."""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import replace
from pathlib import Path

import pytest

from geometry.poses import Pose
from ldhp_tamp.errors import InputError, PlanFormatError
from ldhp_tamp.plan import (
    MAX_ATTEMPTS,
    PLAN_FORMAT,
    Failure,
    FailureCause,
    FailureTier,
    Family,
    Plan,
    PlanStats,
    PlanStatus,
    Step,
    Waypoint,
    plan_to_json,
    read_plan,
    read_plan_string,
    write_plan,
)

#: The format's examples: copies of docs/formats/examples (test_spec_copies.py keeps them equal).
EXAMPLES = Path(__file__).resolve().parents[1] / "data" / "spec"
VALID = EXAMPLES / "pick-plan.json"


@pytest.fixture(scope="module")
def example() -> Plan:
    return read_plan(VALID)


def _odd_plan() -> Plan:
    """A plan with awkward values: angles with many decimals, negative zero, nested
    parameters, stats with extra keys."""
    w0 = Waypoint(Pose.from_degrees(1.25, -0.0, 33.3333333), Pose.from_degrees(10, 20.5, -179.999),
                  80.1234567, ((40.0, 70.0), None))
    w1 = Waypoint(Pose.from_degrees(2.0, 0.0, 34.0), Pose.from_degrees(11, 20.5, -178.0), 80.0,
                  (None, (1e-7, -3.5)))
    step = Step("tip", Family.MOVE_OBJECT, {"pivot": "v2", "angle": 20.0, "nested": {"a": [1, 2.5]}},
                ("l1-e1", "v2-e1"), (w0, w1))
    stats = PlanStats("pyperplan", 8, 1810, 3, 1, 0, 42,
                      {"symbolic": 0.1, "streams": 1.5, "grasp_graph": 2.25, "total": 4.0, "refine": 0.5},
                      {"seed": 7, "note": "extra keys survive"})
    return Plan(PLAN_FORMAT, "odd", "ab" * 32, PlanStatus.SOLVED, (step,), stats)


# --------------------------------------------------------------------------- reading


def test_reads_the_spec_example(example: Plan) -> None:
    assert example.format == PLAN_FORMAT and example.status is PlanStatus.SOLVED
    assert [s.primitive for s in example.steps] == ["approach-contact", "close", "air-move"]
    assert [s.family for s in example.steps] == [Family.ADJUST_GRASP, Family.ADJUST_GRASP, Family.MOVE_OBJECT]
    assert [len(s.waypoints) for s in example.steps] == [31, 5, 21]
    assert example.steps[2].contact_state == ("l1-e1", "free")
    last = example.steps[-1].waypoints[-1]
    assert last.object == Pose(0.0, 100.0, 0.0)
    assert last.finger_contacts == ((0.0, 120.0), (100.0, 120.0))
    assert example.steps[0].waypoints[0].finger_contacts == (None, None)
    assert example.stats.engine == "hand-written example"
    assert len(example.waypoints) == 57


def test_angles_are_degrees_in_the_file_radians_inside() -> None:
    text = plan_to_json(_odd_plan()).replace('"object": [2, 0, 34]', '"object": [2, 0, 90]')
    plan = read_plan_string(text)
    assert plan.steps[0].waypoints[1].object.theta == pytest.approx(math.pi / 2)


def _mutate(example_text: str, edit) -> str:
    data = json.loads(example_text)
    edit(data)
    return json.dumps(data)


MALFORMED = [
    ("not json", lambda d: None, "{not json", "not valid JSON"),
    ("top-level list", None, "[]", "expected an object, got a list"),
    ("missing format", lambda d: d.pop("format"), None, "missing key 'format'"),
    ("other format", lambda d: d.update(format="ldhp-plan/2"), None, "format: unknown format 'ldhp-plan/2'"),
    ("missing steps", lambda d: d.pop("steps"), None, "missing key 'steps'"),
    ("missing stats", lambda d: d.pop("stats"), None, "missing key 'stats'"),
    ("bad status", lambda d: d.update(status="ok"), None, "status: expected 'solved' or 'failed'"),
    ("bad gripper", lambda d: d["steps"][2]["waypoints"][4].update(gripper=[1, 2]), None,
     "steps[2].waypoints[4].gripper: expected [x, y, theta]"),
    ("string in pose", lambda d: d["steps"][0]["waypoints"][0].update(object=[0, "0", 0]), None,
     "steps[0].waypoints[0].object: expected [x, y, theta]"),
    ("missing width", lambda d: d["steps"][1]["waypoints"][2].pop("width"), None,
     "steps[1].waypoints[2]: missing key 'width'"),
    ("boolean width", lambda d: d["steps"][1]["waypoints"][2].update(width=True), None,
     "steps[1].waypoints[2].width: expected a number, got a boolean"),
    ("one finger", lambda d: d["steps"][2]["waypoints"][0].update(finger_contacts=[[0, 20]]), None,
     "steps[2].waypoints[0].finger_contacts: expected [finger 1, finger 2]"),
    ("bad contact", lambda d: d["steps"][2]["waypoints"][0].update(finger_contacts=[[0, 20, 3], None]), None,
     "steps[2].waypoints[0].finger_contacts[0]: expected [x, y] or null"),
    ("bad family", lambda d: d["steps"][0].update(family="move"), None,
     "steps[0].family: expected 'move-object' or 'adjust-grasp'"),
    ("missing parameters", lambda d: d["steps"][0].pop("parameters"), None, "steps[0]: missing key 'parameters'"),
    ("contact_state without to", lambda d: d["steps"][1]["contact_state"].pop("to"), None,
     "steps[1].contact_state: missing key 'to'"),
    ("waypoints not a list", lambda d: d["steps"][1].update(waypoints={}), None,
     "steps[1].waypoints: expected a list, got an object"),
    ("negative counter", lambda d: d["stats"].update(refinements=-1), None, "stats.refinements: expected a non-negative"),
    ("forces not a pair", lambda d: d["steps"][2]["waypoints"][3].update(finger_forces=[[1, 2]]), None,
     "steps[2].waypoints[3].finger_forces: expected [finger 1, finger 2], each [normal, tangential] or null"),
    ("forces null", lambda d: d["steps"][2]["waypoints"][3].update(finger_forces=None), None,
     "steps[2].waypoints[3].finger_forces: expected [finger 1, finger 2]"),
    ("force of three numbers", lambda d: d["steps"][2]["waypoints"][3].update(finger_forces=[[1, 2, 3], None]),
     None, "steps[2].waypoints[3].finger_forces[0]: expected [normal, tangential] or null"),
    ("force with a string", lambda d: d["steps"][2]["waypoints"][3].update(finger_forces=[None, [1, "2"]]),
     None, "steps[2].waypoints[3].finger_forces[1]: expected [normal, tangential] or null"),
    ("force with a boolean", lambda d: d["steps"][2]["waypoints"][3].update(finger_forces=[[True, 0], None]),
     None, "steps[2].waypoints[3].finger_forces[0]: expected [normal, tangential] or null"),
]


@pytest.mark.parametrize("name, edit, text, fragment", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_plans_are_refused_with_file_and_json_path(name, edit, text, fragment) -> None:
    source = text if text is not None else _mutate(VALID.read_text(), edit)
    with pytest.raises(PlanFormatError) as err:
        read_plan_string(source, "broken.json")
    assert str(err.value).startswith("broken.json: ")
    assert fragment in str(err.value)
    assert isinstance(err.value, InputError)  # the CLI answers with exit status 2


@pytest.mark.parametrize("text, fragment", [
    ('{"format": NaN}', "NaN is not a JSON number"),
    ('{"format": "a", "format": "b"}', "duplicate key 'format'"),
])
def test_json_that_python_would_accept_is_still_refused(text: str, fragment: str) -> None:
    with pytest.raises(PlanFormatError, match=fragment):
        read_plan_string(text)


def test_finger_forces_are_optional_and_read_when_present() -> None:
    data = json.loads(VALID.read_text())
    data["steps"][2]["waypoints"][3]["finger_forces"] = [[8.175, -4.905], None]
    data["steps"][2]["waypoints"][4]["finger_forces"] = [None, None]
    plan = read_plan_string(json.dumps(data))
    wps = plan.steps[2].waypoints
    assert wps[3].finger_forces == ((8.175, -4.905), None)
    assert wps[4].finger_forces == (None, None)
    assert wps[2].finger_forces is None  # absent
    assert read_plan(VALID).steps[2].waypoints[3].finger_forces is None


def test_non_finite_forces_are_refused() -> None:
    data = json.loads(VALID.read_text())
    data["steps"][2]["waypoints"][3]["finger_forces"] = [["HUGE", 0], None]
    text = json.dumps(data).replace('"HUGE"', "1e999")
    with pytest.raises(PlanFormatError, match="p.json: not valid JSON: number 1e999 is out of range"):
        read_plan_string(text, "p.json")
    with pytest.raises(PlanFormatError, match="NaN is not a JSON number"):
        read_plan_string(json.dumps(data).replace('"HUGE"', "NaN"), "p.json")
    # Parsed JSON from elsewhere (json.loads accepts NaN): the reader checks finiteness itself.
    from ldhp_tamp.plan import _Reader
    wp = dict(data["steps"][2]["waypoints"][3], finger_forces=[[math.inf, 0], None])
    with pytest.raises(PlanFormatError, match=r"p.json: w.finger_forces\[0\]: expected \[normal, tangential\] "
                                              r"or null of finite numbers"):
        _Reader("p.json").waypoint(wp, "w")


# --------------------------------------------------------------------------- writing


def test_round_trip_of_the_example(example: Plan, tmp_path: Path) -> None:
    path = write_plan(example, tmp_path / "plan.json")
    assert read_plan(path) == example
    assert plan_to_json(read_plan(path)) == path.read_text()


def test_round_trip_of_awkward_values(tmp_path: Path) -> None:
    plan = _odd_plan()
    text = plan_to_json(plan)
    back = read_plan_string(text)
    assert plan_to_json(back) == text  # a fixed point after one write
    w0 = back.steps[0].waypoints[0]
    assert math.degrees(w0.object.theta) == pytest.approx(33.333333, abs=1e-9)  # 6 decimals
    assert w0.width == 80.123457
    assert back.steps[0].parameters == {"pivot": "v2", "angle": 20, "nested": {"a": [1, 2.5]}}
    assert back.stats.time_s["refine"] == 0.5 and back.stats.extra["seed"] == 7
    write_plan(back, tmp_path / "p.json")
    assert read_plan(tmp_path / "p.json") == back


def _with_forces(plan: Plan) -> Plan:
    """``plan`` with finger forces on every waypoint of its last step (an awkward mix)."""
    last = plan.steps[-1]
    forces = [((9.81, -4.905), (9.81, 4.905)), ((1 / 3, -0.0), None), (None, (2.0000004, 1e-7)), (None, None)]
    wps = tuple(replace(w, finger_forces=forces[j % len(forces)]) for j, w in enumerate(last.waypoints))
    return replace(plan, steps=plan.steps[:-1] + (replace(last, waypoints=wps),))


def test_round_trip_of_finger_forces(example: Plan, tmp_path: Path) -> None:
    plan = _with_forces(example)
    text = plan_to_json(plan)
    back = read_plan_string(text)
    assert plan_to_json(back) == text  # a fixed point
    wps = back.steps[-1].waypoints
    assert wps[0].finger_forces == ((9.81, -4.905), (9.81, 4.905))
    assert wps[1].finger_forces == ((0.333333, 0.0), None)  # rounded like every number, no -0
    assert wps[2].finger_forces == (None, (2.0, 0.0))
    assert wps[3].finger_forces == (None, None)
    assert back.steps[0].waypoints[0].finger_forces is None
    exact = _with_forces(example)
    exact = replace(exact, steps=exact.steps[:-1] + (replace(exact.steps[-1], waypoints=tuple(
        replace(w, finger_forces=((9.81, -4.905), None)) for w in exact.steps[-1].waypoints)),))
    assert read_plan(write_plan(exact, tmp_path / "p.json")) == exact
    assert read_plan(write_plan(example, tmp_path / "q.json")).steps[-1].waypoints[0].finger_forces is None


def test_finger_forces_keep_one_line_per_waypoint(example: Plan) -> None:
    text = plan_to_json(_with_forces(example))
    assert ('{"object": [0, 0, 0], "gripper": [50, 2, 0], "width": 100, "finger_contacts": [[0, 20], [100, 20]], '
            '"finger_forces": [[9.81, -4.905], [9.81, 4.905]]}') in text
    assert '"finger_forces": [null, null]}' in text
    assert text.count("finger_forces") == len(example.steps[-1].waypoints)
    assert len(text.splitlines()) == len(plan_to_json(example).splitlines())
    data = json.loads(text)
    assert list(data["steps"][2]["waypoints"][0]) == ["object", "gripper", "width", "finger_contacts", "finger_forces"]
    assert "finger_forces" not in data["steps"][0]["waypoints"][0]


def test_file_layout_is_stable_and_readable(example: Plan) -> None:
    text = plan_to_json(example)
    data = json.loads(text)
    assert list(data) == ["format", "scenario", "scenario_sha256", "status", "steps", "stats"]
    assert list(data["steps"][0]) == ["primitive", "family", "parameters", "contact_state", "waypoints"]
    assert list(data["steps"][0]["waypoints"][0]) == ["object", "gripper", "width", "finger_contacts"]
    assert list(data["stats"]["time_s"]) == ["symbolic", "streams", "grasp_graph", "total"]
    # one waypoint per line
    assert '{"object": [0, 100, 0], "gripper": [50, 102, 0], "width": 100, "finger_contacts": [[0, 120], [100, 120]]}' in text
    assert "-0" not in plan_to_json(_odd_plan()).replace("-0.", "")  # no negative zero


def test_write_replaces_atomically_and_leaves_no_temp_file(example: Plan, tmp_path: Path) -> None:
    target = tmp_path / "plan.json"
    target.write_text("old content")
    os.chmod(target, 0o640)
    write_plan(example, target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plan.json"]
    assert read_plan(target) == example
    assert target.stat().st_mode & 0o777 == 0o640  # the file keeps its permissions


def test_an_interrupted_write_leaves_the_old_file(example: Plan, tmp_path: Path, monkeypatch) -> None:
    target = tmp_path / "plan.json"
    target.write_text("old content")

    def crash(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(KeyboardInterrupt):
        write_plan(example, target)
    assert target.read_text() == "old content"
    assert [p.name for p in tmp_path.iterdir()] == ["plan.json"]


def test_a_value_that_cannot_be_written_touches_nothing(example: Plan, tmp_path: Path) -> None:
    target = tmp_path / "plan.json"
    target.write_text("old content")
    w = example.steps[0].waypoints[0]
    bad = replace(example, steps=(replace(example.steps[0], waypoints=(replace(w, width=math.nan),)),))
    with pytest.raises(ValueError, match="non-finite"):
        write_plan(bad, target)
    assert target.read_text() == "old content"
    assert [p.name for p in tmp_path.iterdir()] == ["plan.json"]


def test_model_coerces_and_checks() -> None:
    step = Step("close", "adjust-grasp", {}, ["a", "b"], [])
    assert step.family is Family.ADJUST_GRASP and step.contact_state == ("a", "b") and step.waypoints == ()
    with pytest.raises(ValueError):
        Step("x", "slide", {}, ("a", "b"), ())
    with pytest.raises(ValueError):
        Waypoint(Pose(0, 0, 0), Pose(0, 0, 0), 1.0, (None,))
    w = Waypoint(Pose(0, 0, 0), Pose(0, 0, 0), 1.0, ((0, 0), None), [[1, 2], None])
    assert w.finger_forces == ((1.0, 2.0), None) and isinstance(w.finger_forces[0][0], float)
    assert Waypoint(Pose(0, 0, 0), Pose(0, 0, 0), 1.0).finger_forces is None
    with pytest.raises(ValueError):
        Waypoint(Pose(0, 0, 0), Pose(0, 0, 0), 1.0, (None, None), ((1.0, 2.0),))
    with pytest.raises(ValueError):
        Waypoint(Pose(0, 0, 0), Pose(0, 0, 0), 1.0, (None, None), ((1.0, 2.0, 3.0), None))
    with pytest.raises(TypeError):
        step.parameters["k"] = 1  # read-only


# --------------------------------------------------------------------------- failure


def _failed_plan(**failure: object) -> Plan:
    detail = Failure(**{"tier": FailureTier.BOTTOM, "cause": FailureCause.EMPTY_MOTION_SET, "step": 3,
                        "segment": 5, "primitive": "biplanar-slide",
                        "counts": {"top_iterations": 10, "pose_paths": 25, "candidates": 1039},
                        "attempts": ("iteration 1, pose path 1: bottom tier: no grasp can execute segment 5 "
                                     '(a "quoted" name; ünïcode)', "iteration 2: no stream sample for tip l1-e1->v2-e1"),
                        **failure})  # type: ignore[arg-type]
    return Plan(PLAN_FORMAT, "failed", "ab" * 32, PlanStatus.FAILED, (), PlanStats("pyperplan"),
                "bottom tier, step 3, segment 5 (biplanar-slide a -> b): no grasp executes it", detail)


def test_the_failure_of_a_failed_plan_round_trips(tmp_path: Path) -> None:
    plan = _failed_plan()
    back = read_plan(write_plan(plan, tmp_path / "failed.json"))
    assert back == plan and back.failure is not None
    assert back.failure.cause is FailureCause.EMPTY_MOTION_SET and back.failure.tier is FailureTier.BOTTOM
    assert back.failure.counts == {"top_iterations": 10, "pose_paths": 25, "candidates": 1039}
    assert back.failure.attempts == plan.failure.attempts  # type: ignore[union-attr]
    data = json.loads((tmp_path / "failed.json").read_text())
    assert list(data)[-1] == "failure" and data["failure"]["cause"] == "empty-motion-set"
    assert data["failure"]["step"] == 3 and data["failure"]["primitive"] == "biplanar-slide"
    # nulls where there is no step, segment or primitive
    bare = _failed_plan(tier="setup", cause="no-contact-pose", step=None, segment=None, primitive=None,
                        counts={}, attempts=())
    text = plan_to_json(bare)
    assert json.loads(text)["failure"] == {"tier": "setup", "cause": "no-contact-pose", "step": None,
                                           "segment": None, "primitive": None, "counts": {}, "attempts": []}
    assert read_plan_string(text) == bare


def test_the_failure_keeps_one_attempt_per_line_and_the_last_ones() -> None:
    plan = _failed_plan(attempts=tuple(f"attempt {i}" for i in range(MAX_ATTEMPTS + 5)))
    assert plan.failure is not None and plan.failure.attempts[0] == "attempt 5"
    assert len(plan.failure.attempts) == MAX_ATTEMPTS
    lines = plan_to_json(plan).splitlines()
    assert '      "attempt 5",' in lines and '      "attempt 24"' in lines


def test_plans_without_a_failure_still_read(example: Plan) -> None:
    # the spec's examples, a solved plan, older failed plans: no failure key
    assert example.failure is None and '"failure"' not in plan_to_json(example)
    old = json.dumps({"format": PLAN_FORMAT, "scenario": "s", "scenario_sha256": "x", "status": "failed",
                      "reason": "no feasible plan after 10 top-tier iterations (H_max): ...", "steps": [],
                      "stats": {}})
    plan = read_plan_string(old)
    assert plan.status is PlanStatus.FAILED and plan.failure is None and plan.reason.startswith("no feasible")
    assert read_plan_string(old.replace('"stats": {}', '"stats": {}, "failure": null')).failure is None


@pytest.mark.parametrize("edit, fragment", [
    (lambda f: f.update(cause="gremlins"), "failure.cause: expected one of no-contact-pose, "),
    (lambda f: f.update(tier="middle"), "failure.tier: expected one of setup, symbolic,"),
    (lambda f: f.pop("cause"), "failure: missing key 'cause'"),
    (lambda f: f.update(step=-1), "failure.step: expected a non-negative integer"),
    (lambda f: f.update(primitive=3), "failure.primitive: expected a string"),
    (lambda f: f.update(counts={"top_iterations": 1.5}), "failure.counts.top_iterations: expected a non-negative"),
    (lambda f: f.update(attempts="one"), "failure.attempts: expected a list"),
    (lambda f: f.update(attempts=["a", 2]), "failure.attempts[1]: expected a string"),
])
def test_a_malformed_failure_is_refused(edit, fragment: str) -> None:
    data = json.loads(plan_to_json(_failed_plan()))
    edit(data["failure"])
    with pytest.raises(PlanFormatError, match=re.escape(fragment)):
        read_plan_string(json.dumps(data), "failed.json")


def test_the_cause_list_is_closed_and_documented() -> None:
    doc = (Path(__file__).resolve().parents[2] / "docs" / "formats" / "plan.md").read_text()
    for cause in FailureCause:
        assert f"`{cause.value}`" in doc, cause
    for tier in FailureTier:
        assert f"`{tier.value}`" in doc, tier
