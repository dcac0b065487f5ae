"""The TAMP loop and `ldhp-tamp solve`, end to end on small tasks."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from ldhp_tamp.cli import main
from ldhp_tamp.executability import forward_check
from ldhp_tamp.plan import FailureCause, FailureTier, PlanStatus, read_plan
from ldhp_tamp.resources import scenarios_dir
from ldhp_tamp.scenario import load_scenario, load_scenario_string
from ldhp_tamp.tamp import SolveOptions, SolveStatus, solve
from ldhp_tamp.validate import validate_plan

PICK = scenarios_dir() / "example_pick.toml"


@pytest.fixture(scope="module")
def pick_result():
    return solve(load_scenario(PICK))


def test_pick_example_is_solved_with_a_valid_plan(pick_result) -> None:
    assert pick_result.status is SolveStatus.SOLVED
    plan = pick_result.plan
    assert validate_plan(plan, load_scenario(PICK)).valid
    families = [s.family.value for s in plan.steps]
    assert families[0] == "adjust-grasp" and families[-1] == "move-object"
    assert plan.steps[-1].primitive == "air-move"
    assert plan.reason is None and plan.failure is None  # a solved plan has no failure
    stats = plan.stats
    assert stats.contact_state_nodes > 0 and stats.grasp_graph_nodes > 0 and stats.top_iterations == 1
    assert stats.time_s["total"] >= stats.time_s["grasp_graph"] > 0


def test_same_seed_same_plan(pick_result) -> None:
    again = solve(load_scenario(PICK))
    assert [s.primitive for s in again.plan.steps] == [s.primitive for s in pick_result.plan.steps]
    assert [w for s in again.plan.steps for w in s.waypoints] == \
        [w for s in pick_result.plan.steps for w in s.waypoints]


def test_task1_zero_mobility_lift_is_solved_with_pivots() -> None:
    # Task 1 of the paper held at 70 degrees: tip the block, pivot into the lever pinch,
    # tip on and lift (regression: the tip sampled only a few angles and no pose path was
    # refinable). The plan passes the judge: rules 0-9 and the forward problem.
    sc = load_scenario(scenarios_dir() / "task1_zero_mobility_lift_tilt70.toml")
    result = solve(sc)
    assert result.status is SolveStatus.SOLVED
    plan = result.plan
    assert validate_plan(plan, sc).valid
    assert forward_check(plan, sc).ok
    prims = [s.primitive for s in plan.steps]
    assert prims[-1] == "air-move" and "pivot" in prims and "tip" in prims
    assert all(s.primitive != "open" for s in plan.steps)


def test_task1_at_60_degrees_is_lifted_in_a_corner_and_side_hold() -> None:
    """Held tilted 60 degrees the block used to be lifted only in the wedge between its top
    corner and its long side, which needs mu 0.1946 of 0.2 (the forward problem and the
    simulation let it slip out). Rolling a finger along the side (a rolling pivot) reaches
    the hold of one finger on the bottom corner v1 and the other under the long side
    about 40 mm from v2, which lifts it with room to spare."""
    sc = load_scenario(scenarios_dir() / "task1_zero_mobility_lift.toml")
    result = solve(sc)
    assert result.status is SolveStatus.SOLVED
    plan = result.plan
    assert validate_plan(plan, sc).valid and forward_check(plan, sc).ok
    assert plan.steps[-1].primitive == "air-move"
    assert any(s.primitive == "pivot" and s.parameters.get("rolls") for s in plan.steps)
    last = plan.steps[-1].waypoints[-1]
    body = [last.object.inverse().apply(c) for c in last.finger_contacts if c is not None]
    assert len(body) == 2
    at_v1 = [p for p in body if np.hypot(*p) < 0.5]
    under_l2 = [p for p in body if abs(p[0] - 70.0) < 0.5]
    assert len(at_v1) == 1 and len(under_l2) == 1 and 25.0 < under_l2[0][1] < 55.0


def test_an_impossible_task_fails_with_a_reason_naming_the_tier() -> None:
    # the goal is in the air beyond the end of the table (which spans x in [-300, 300]):
    # no axis translation brings it into contact, so there is no goal contact pose
    text = PICK.read_text().replace("goal = [0, 100, 0]", "goal = [1000, 100, 0]")
    sc = load_scenario_string(text, "impossible", base_dir=PICK.parent)
    result = solve(sc, SolveOptions(max_top_iterations=2))
    assert result.status is SolveStatus.FAILED
    assert result.plan.status is PlanStatus.FAILED and result.plan.steps == ()
    assert result.reason.startswith("top tier, step 1") and "touches nothing" in result.reason
    failure = result.plan.failure
    assert failure is not None and (failure.tier, failure.cause) == (FailureTier.SETUP, FailureCause.NO_CONTACT_POSE)
    assert failure.attempts == (result.reason,)  # short enough to be its own headline


def test_cli_solve_writes_a_valid_plan_and_emits_pddl(tmp_path: Path, capsys) -> None:
    out = tmp_path / "plan.json"
    pddl = tmp_path / "pddl"
    code = main(["solve", str(PICK), "--out", str(out), "--emit-pddl", str(pddl), "-q"])
    assert code == 0
    text = capsys.readouterr().out
    assert text.startswith("solved:") and "primitives:" in text
    assert read_plan(out).status is PlanStatus.SOLVED
    assert (pddl / "domain.pddl").is_file() and (pddl / "problem-01.pddl").is_file()
    assert main(["validate", str(out), "--scenario", str(PICK)]) == 0
    assert not list(tmp_path.glob("*.tmp*"))


def test_cli_solve_failed_plan_exits_1(tmp_path: Path, capsys) -> None:
    scen = tmp_path / "impossible.toml"
    scen.write_text(PICK.read_text().replace("goal = [0, 100, 0]", "goal = [1000, 100, 0]")
                    + "\n[planner]\nmax_top_iterations = 1\n")
    out = tmp_path / "plan.json"
    assert main(["solve", str(scen), "--out", str(out), "-q"]) == 1
    data = json.loads(out.read_text())
    assert data["status"] == "failed" and data["steps"] == [] and data["reason"]
    assert "reason:" in capsys.readouterr().out


def test_cli_solve_bad_input_exits_2(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('format = "nope"\n')
    assert main(["solve", str(bad), "--out", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "Traceback" not in err
    assert not (tmp_path / "p.json").exists()
    assert main(["solve", str(PICK), "--engine", "no-such-engine", "--out", str(tmp_path / "q.json")]) == 2


# --------------------------------------------------------------------------- feedback policy


def test_a_failure_condemns_the_step_after_its_predecessor_and_escalates() -> None:
    from geometry.features import FREE, ContactState
    from ldhp_tamp.primitives import Sequel, Transition
    from ldhp_tamp.tamp import ESCALATE_AFTER, FORBID_AFTER, _culprits

    S = ContactState.parse
    a, b, c, d = S("l1-e1"), S("v1-e1"), S("l4-e1"), S("v4-e1")
    plan = [Transition("air-move", FREE, a), Transition("tip", a, b), Transition("tip", b, c)]
    # the first step starts from a fixed pose: the transition itself
    assert _culprits(plan, 0, set()) == [plan[0]]
    # a later step: only right after its predecessor
    assert _culprits(plan, 2, set()) == [Sequel(plan[1], plan[2])]
    # a second different step failing after the same predecessor condemns the predecessor
    # too, in its own context
    known: set = {Sequel(plan[1], Transition("push", b, d))}
    assert ESCALATE_AFTER == 2
    assert _culprits(plan, 2, known) == [Sequel(plan[1], plan[2]), Sequel(plan[0], plan[1])]
    # a step that has failed after three different predecessors is forbidden outright
    assert FORBID_AFTER == 3
    e = S("v2-e1")
    known = {Sequel(Transition("push", e, b), plan[2]), Sequel(Transition("tip", d, b), plan[2])}
    assert _culprits(plan, 2, known) == [Sequel(plan[1], plan[2]), plan[2]]


def test_a_peg_is_lifted_and_lowered_into_a_hole() -> None:
    sc = load_scenario(scenarios_dir() / "cmgmp_peg_in_hole.toml")
    result = solve(sc)
    assert result.status is SolveStatus.SOLVED, result.reason
    assert [s.primitive for s in result.plan.steps] == ["air-move"] * 3
    assert validate_plan(result.plan, sc).valid


def test_a_peg_is_lowered_into_a_hole_with_3_5_mm_of_clearance_and_let_go() -> None:
    sc = load_scenario(scenarios_dir() / "peg_in_hole_tight.toml")
    result = solve(sc)
    assert result.status is SolveStatus.SOLVED, result.reason
    assert [s.primitive for s in result.plan.steps] == ["air-move", "open"]
    assert validate_plan(result.plan, sc).valid


def test_verbose_shows_the_planners_progress_and_vv_the_engines_too(tmp_path: Path) -> None:
    import subprocess
    import sys

    def stderr(*flags: str) -> str:
        cmd = [sys.executable, "-m", "ldhp_tamp.cli", *flags, "solve", str(PICK), "--out", str(tmp_path / "p.json")]
        return subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=True).stderr

    v, vv = stderr("-v"), stderr("-vv")
    assert "INFO ldhp_tamp.grasp_graph:" in v and "root:" not in v  # pyperplan's progress is noise at -v
    assert "INFO root: Search start" in vv and "DEBUG ldhp_tamp" in vv


def test_a_failing_tip_is_bisected_whether_no_grasp_or_no_reachable_grasp_executes_it() -> None:
    """Algorithm 1: a failing tip / biplanar slide is bisected up to L_max times, both when
    no grasp can execute it (G_m empty, the paper's text) and when no grasp reachable at
    its start can (the book stand-up needs three such bisections); a failing segment of
    another primitive goes straight back to the top tier."""
    import math

    from geometry.contacts import contact_state
    from geometry.kinematics import rotate_about, translate
    from ldhp_tamp.grasp_graph import GraspPlanResult, GraspPlanStatus
    from ldhp_tamp.path import Segment
    from ldhp_tamp.streams import PosePath
    from ldhp_tamp.tamp import _bottom_tier, _Clock, _Counters

    sc = load_scenario(scenarios_dir() / "task1_zero_mobility_lift.toml")
    w = sc.world
    motion = rotate_about(sc.start, w.object_vertices(sc.start)[1], -1)
    end = motion.pose(math.radians(30.0))
    tip = Segment("tip", contact_state(w, sc.start), contact_state(w, end), motion, 0.0, math.radians(30.0), w,
                  {"angle": 30.0})
    push = Segment("push", contact_state(w, sc.start), contact_state(w, sc.start), translate(sc.start, (1.0, 0.0)),
                   0.0, 20.0, w, {"travel": 20.0})
    assert tip.refinable and not push.refinable

    class Stub:
        def __init__(self, status: GraspPlanStatus) -> None:
            self.status, self.calls = status, []

        def plan(self, path, *, deadline=None):
            self.calls.append(len(path.segments))
            return GraspPlanResult(self.status, failing_segment=0, reason="stub")

    for seg, status, calls in ((tip, GraspPlanStatus.NO_GRASP_FOR_SEGMENT, [1, 2, 3]),
                               (tip, GraspPlanStatus.NO_PATH, [1, 2, 3]),
                               (push, GraspPlanStatus.NO_GRASP_FOR_SEGMENT, [1])):
        stub, c = Stub(status), _Counters()
        out = _bottom_tier(stub, PosePath((seg,)), 2, c, _Clock(), None)
        assert out.steps is None and out.segment is not None and "stub" in out.reason
        assert stub.calls == calls and c.refinements == len(calls) - 1, (seg.primitive, status)


def test_solve_simulate_judges_the_plan_in_the_physics_simulation() -> None:
    result = solve(load_scenario(PICK), SolveOptions(simulate=True))
    assert result.status is SolveStatus.SOLVED
    assert result.plan.stats.time_s["simulation"] > 0  # the replay ran and executed
    assert result.plan.stats.extra["judge_rejections"] == 0


def test_a_plan_that_diverges_in_simulation_is_fed_back(monkeypatch: pytest.MonkeyPatch) -> None:
    """The first plan 'diverges' at its MoveObject step: the grasp carried there leaves the
    segment's G_m and the path is planned again, with another grasp."""
    from types import SimpleNamespace

    import ldhp_tamp.simulate as sim

    seen: list[tuple] = []

    def fake(plan, scenario, options=None):
        carried = next(s for s in plan.steps if s.family.value == "move-object")
        seen.append(carried.waypoints[0].finger_contacts)
        if len(seen) == 1:
            step = plan.steps.index(carried)
            return SimpleNamespace(executes=False, diverged_step=step, reason="a test's divergence")
        return SimpleNamespace(executes=True, diverged_step=None, reason="")

    monkeypatch.setattr(sim, "simulate_plan", fake)
    result = solve(load_scenario(PICK), SolveOptions(simulate=True))
    assert result.status is SolveStatus.SOLVED
    assert len(seen) == 2 and seen[0] != seen[1]  # another grasp carries the lift
    assert result.plan.stats.extra["judge_rejections"] == 1


# --------------------------------------------------------------------------- failures


def test_a_long_reason_is_cut_to_its_first_clause() -> None:
    from ldhp_tamp.tamp import _short

    assert _short("short enough (kept whole); yes") == "short enough (kept whole); yes"
    long = "no contact-state path (" + "x" * 300 + ") from a to b; and more " + "y" * 200
    assert _short(long) == "no contact-state path from a to b"
    assert _short("word " * 100, 50).endswith("...") and len(_short("word " * 100, 50)) <= 50


def test_giving_up_names_the_attempt_that_got_furthest() -> None:
    from ldhp_tamp.tamp import _Attempt, _Clock, _Counters, _give_up

    c = _Counters(top_iterations=3)
    c.attempts += [
        _Attempt("it 1", FailureTier.BOTTOM, FailureCause.EMPTY_MOTION_SET, "bottom tier, step 2, segment 4 (tip a -> b)",
                 "no grasp executes it (9 candidates)", 2, 4, "tip", 9),
        _Attempt("it 2", FailureTier.STREAMS, FailureCause.NO_STREAM_SAMPLE, "streams, step 5 (push b->c)",
                 "no object pose path gets through it", 5, None, "push"),
        _Attempt("it 3", FailureTier.JUDGE, FailureCause.AMBIGUOUS_MOTION, "judge, step 3, segment 6 (tip b -> c)",
                 "the motion of plan step 8 (slide) is ambiguous (forward problem)", 3, 6, "slide"),
        _Attempt("it 4", FailureTier.BOTTOM, FailureCause.UNREACHABLE, "bottom tier, step 1, segment 1 (push a -> a)",
                 "no grasp sequence from the start reaches a grasp that executes it", 1, 1, "push"),
    ]
    sc = load_scenario(PICK)
    result = _give_up(sc, "pyperplan", " after 3 top-tier iterations (H_max)", c, _Clock())
    assert result.reason == ("judge, step 3, segment 6 (tip b -> c): the motion of plan step 8 (slide) is "
                             "ambiguous (forward problem) after 3 top-tier iterations (H_max)")
    f = result.plan.failure
    assert f is not None and (f.tier, f.cause, f.step, f.segment, f.primitive) == \
        (FailureTier.JUDGE, FailureCause.AMBIGUOUS_MOTION, 3, 6, "slide")
    assert f.attempts == ("it 1", "it 2", "it 3", "it 4") and f.counts["top_iterations"] == 3
    assert "candidates" not in f.counts


def test_a_plan_the_simulation_always_refuses_fails_in_the_judge(monkeypatch: pytest.MonkeyPatch) -> None:
    from types import SimpleNamespace

    import ldhp_tamp.simulate as sim

    def fake(plan, scenario, options=None):
        step = next(i for i, s in enumerate(plan.steps) if s.family.value == "move-object")
        return SimpleNamespace(executes=False, diverged_step=step, reason="a test's divergence")

    monkeypatch.setattr(sim, "simulate_plan", fake)
    result = solve(load_scenario(PICK), SolveOptions(simulate=True, max_top_iterations=1, judge_retries=0,
                                                     pose_paths_per_plan=1))
    assert result.status is SolveStatus.FAILED
    assert result.reason.startswith("judge, step 0, segment 0 (air-move ") and len(result.reason) <= 200
    assert "diverges in the physics simulation" in result.reason
    f = result.plan.failure
    assert f is not None and (f.tier, f.cause) == (FailureTier.JUDGE, FailureCause.DIVERGES_IN_SIMULATION)
    assert f.primitive == "air-move" and f.counts["judge_rejections"] >= 1
    assert any("a test's divergence" in a for a in f.attempts)


def test_a_failing_segment_is_cut_where_the_object_rests_alone() -> None:
    """Dichotomy refinement cuts a tip in the middle of its range, but a segment along
    which the object rests on the environment alone is cut in the middle of that window,
    where the gripper can let go and regrasp."""
    import math

    from geometry.contacts import contact_state
    from geometry.kinematics import rotate_about, translate
    from ldhp_tamp.path import Segment
    from ldhp_tamp.tamp import _rest_cut

    sc = load_scenario(scenarios_dir() / "task1_zero_mobility_lift.toml")
    w = sc.world
    motion = rotate_about(sc.start, w.object_vertices(sc.start)[1], -1)
    end = motion.pose(math.radians(30.0))
    tip = Segment("tip", contact_state(w, sc.start), contact_state(w, end), motion, 0.0, math.radians(30.0), w)
    assert _rest_cut(tip) is None  # on its corner the block does not rest alone
    push = Segment("push", contact_state(w, sc.start), contact_state(w, sc.start), translate(sc.start, (1.0, 0.0)),
                   0.0, 40.0, w)
    n = push.poses.shape[0]
    at = _rest_cut(push)  # standing on the table it rests all along: the middle
    assert at is not None and abs(at - (n - 1) / 2) <= 1
    a, b = push.split(at)
    assert a.poses.shape[0] == at + 1 and np.allclose(a.poses[-1], b.poses[0])
    with pytest.raises(ValueError):
        push.split(0)


def test_a_rest_window_inside_an_earlier_segment_becomes_a_layer() -> None:
    """When the grasps that execute a segment cannot be reached, the bottom tier cuts
    the latest earlier sensitive segment at a rest window inside it (where the gripper
    can let go and regrasp): the ladder slide of task 2 from standing against the slot's
    wall to 40 degrees rests alone only between about 25 and 27 degrees. A window at a
    segment's end is a layer already and is not cut again."""
    import math

    from ldhp_tamp.contact_graph import build_context
    from ldhp_tamp.primitives.move_object import BiplanarSlide
    from ldhp_tamp.tamp import _window_before, _window_cut

    sc = load_scenario(scenarios_dir() / "task2_slot_insertion.toml")
    ctx = build_context(sc.world, sc.start, sc.goal, stream_samples=3)
    s = {st.name: st for st in ctx.states}
    seg = next(x for x in BiplanarSlide().sample(ctx, s["l1-e1+l4-e2"], s["v1-e1+l4-ve3"],
                                                 ctx.witness_poses(s["l1-e1+l4-e2"])[0], np.random.default_rng(0), 5)
               if math.degrees(x.end.theta) > 40.0)
    at = _window_cut(seg)
    assert at is not None and 24.0 < math.degrees(seg.poses[at][2]) < 28.0
    a, b = seg.split(at)
    assert _window_cut(a) is None and _window_cut(b) is None  # the window now ends both halves
    per_root: dict[int, int] = {}
    assert _window_before([seg, b], 1, per_root, 4) == 0
    assert _window_before([seg, b], 1, {id(seg): 4}, 4) is None  # its refinements are spent


def test_start_grasp_any_starts_from_a_grasp_that_holds_the_object() -> None:
    """``start_grasp = "any"``: the search starts from every grasp that holds the block
    at its start pose in the air and takes the cheapest; the plan's first waypoint shows
    it, and the plan is judged like any other."""
    sc = load_scenario(scenarios_dir() / "example_place_any.toml")
    assert sc.start_grasp is None and sc.start_grasp_any
    result = solve(sc)
    assert result.status is SolveStatus.SOLVED
    plan = result.plan
    assert validate_plan(plan, sc).valid and forward_check(plan, sc).ok
    first = plan.steps[0].waypoints[0]
    assert all(c is not None for c in first.finger_contacts)  # held by a pinch from the start
    assert plan.steps[0].primitive == "air-move"


def test_a_rest_window_narrower_than_the_samples_is_found_between_them() -> None:
    """Standing the 70 x 150 block up into the slot's corner (v1 on the floor, v2 on the
    wall, mu_e = 0.03), it rests alone only where its centre of mass is just over v1:
    between about 24.5 and 25.0 degrees at 0.8 of mu_e. The slide's samples are 0.69
    degrees apart and can step over that window (they do from 90 to 1 degree); the cut is found between them, a parameter
    value, and both halves start and end exactly there."""
    import math

    from geometry.contacts import contact_state, rests_alone
    from geometry.features import Contact, ContactKind
    from geometry.kinematics import two_contact
    from geometry.poses import Pose
    from ldhp_tamp.path import Segment
    from ldhp_tamp.tamp import REST_FRICTION, _rest_cut, _rest_runs, _window_cut

    sc = load_scenario(scenarios_dir() / "inv_slot_extract.toml")
    w = sc.world
    start = Pose(300.0, 0.0, math.radians(90.0))  # lying, its end face l1 flush on the right wall
    kept = (Contact(ContactKind.VERTEX_EDGE, 0, 0), Contact(ContactKind.VERTEX_EDGE, 1, 7))  # v1-e1, v2-e8
    motion = two_contact(w, start, kept, -1)
    seg = Segment("biplanar-slide", contact_state(w, start), contact_state(w, start), motion, 0.0,
                  math.radians(89.0), w)  # to 1 degree: samples at 25.15 and 24.46 degrees
    assert abs(math.degrees(seg.poses[-1][2]) - 1.0) < 1e-6
    assert not any(a > 0 and b < seg.poses.shape[0] for a, b in _rest_runs(seg))  # the samples miss it
    cut = _window_cut(seg)
    assert isinstance(cut, float) and _rest_cut(seg) == cut
    at = motion.poses([cut])
    assert 24.4 < math.degrees(at[0, 2]) < 25.0 and rests_alone(w, at, REST_FRICTION)[0]
    a, b = seg.split(value=cut)
    assert np.allclose(a.poses[-1], at[0]) and np.allclose(b.poses[0], at[0])
    assert a.parent is seg and b.parent is seg and a.depth == b.depth == 1
    assert a.to_state == b.from_state
    assert _window_cut(a) is None and _window_cut(b) is None  # the window now ends both halves
    with pytest.raises(ValueError):
        seg.split(value=seg.s1 + 0.1)


def test_the_judge_has_the_helper_compute_the_annotation(monkeypatch) -> None:
    """While the judge checks a plan, an idle helper process computes the support analysis
    that annotates it: the same as computed here; kept only for the steps accepted; a
    busy helper is left alone; an interrupted judge closes the helper."""
    from dataclasses import replace

    from ldhp_tamp import tamp
    from ldhp_tamp.parallel import Helper
    from ldhp_tamp.validate import support_analysis

    sc = load_scenario(scenarios_dir() / "example_pick.toml")
    res = solve(sc, SolveOptions(helpers=False))
    assert res.status is SolveStatus.SOLVED
    steps = tuple(res.plan.steps)
    here = support_analysis(res.plan, sc, worst_only=True)
    helper = Helper(None)
    try:
        judge = tamp._Judge(sc, "pyperplan", False, tamp._Counters(), tamp._Clock(), helper=lambda: helper)
        assert judge(steps).ok and helper.idle
        there = judge.support_of(steps)
        assert there is not None and judge.support_of(tuple(steps)) is there  # the same tuple: no copy
        assert judge.support_of(steps[:-1]) is None
        for name in ("friction_needed", "finger_forces", "max_finger_force", "step", "waypoint"):
            assert np.array_equal(getattr(there, name), getattr(here, name), equal_nan=True)
        assert (there.margin, there.worst_at) == (here.margin, here.worst_at)
        annotated = tamp._annotate(res.plan, sc, there)
        assert annotated == tamp._annotate(res.plan, sc)

        broken = steps[:1] + (replace(steps[1], waypoints=steps[1].waypoints[::-1]),) + steps[2:]
        assert not judge(broken).ok and judge.support_of(broken) is None and helper.idle

        helper.submit(tamp._helper_support, *([None] * 3))  # busy: a call of someone else's
        assert judge(steps).ok and judge.support_of(steps) is None
        with pytest.raises(Exception):
            helper.result()

        def interrupted(plan, steps):
            raise tamp.TimeBudgetExceeded("the judge")
        monkeypatch.setattr(judge, "_verdict", interrupted)
        with pytest.raises(tamp.TimeBudgetExceeded):
            judge(steps)
        assert not helper.alive
    finally:
        helper.close()


# --------------------------------------------------------------------------- the domain beside the transitions


def _load_order(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Record when the solve loads its domain (unified-planning's parse) and when it
    computes the admissible transitions."""
    from ldhp_tamp import tamp

    events: list[str] = []
    load, transitions = tamp.symbolic.load_checked_domain, tamp.admissible_transitions

    def loading(*args, **kwargs):
        events.append("domain")
        return load(*args, **kwargs)

    def computing(*args, **kwargs):
        events.append("transitions")
        out = transitions(*args, **kwargs)
        events.append("transitions done")
        return out

    monkeypatch.setattr(tamp.symbolic, "load_checked_domain", loading)
    monkeypatch.setattr(tamp, "admissible_transitions", computing)
    return events


def test_the_domain_is_loaded_while_the_transitions_are_computed(pick_result, monkeypatch) -> None:
    events = _load_order(monkeypatch)
    res = solve(load_scenario(PICK))
    assert events == ["transitions", "domain", "transitions done"]  # in the transitions' meanwhile
    assert [w for s in res.plan.steps for w in s.waypoints] == [w for s in pick_result.plan.steps for w in s.waypoints]
    events.clear()
    one = solve(load_scenario(PICK), SolveOptions(helpers=False))
    assert events == ["domain", "transitions", "transitions done"]  # without helpers: first, as it was
    assert [w for s in one.plan.steps for w in s.waypoints] == [w for s in pick_result.plan.steps for w in s.waypoints]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")
@pytest.mark.skipif(not hasattr(os, "fork") or not os.path.isdir("/proc"), reason="needs os.fork and /proc")
def test_a_solve_leaves_no_child_behind(monkeypatch) -> None:
    """The children a solve forks (the grasps' child, the helper, the helper's own) are
    all ended and reaped when it returns, zombies included: a child whose answer came
    before it ended is reaped at the solve's end (``parallel.reap``)."""
    from ldhp_tamp import grasp_graph, parallel

    monkeypatch.setattr(parallel, "cores", lambda: 2)
    monkeypatch.setattr(grasp_graph, "cores", lambda: 2)

    from processes import child_pids

    parallel.reap()
    before = child_pids()
    assert solve(load_scenario(PICK)).status is SolveStatus.SOLVED
    assert child_pids() <= before and not parallel._UNREAPED


def test_the_solve_forks_its_helper_once_in_the_setup(pick_result, monkeypatch) -> None:
    """The transitions are computed by the bottom tier's helper, forked in the setup: the
    solve forks no other long-lived process (a fork costs the solve a page fault for each
    page it writes afterwards), only, before the helper, a child that enumerates the
    grasps while the solve enumerates the contact states; and the plan is the same."""
    from ldhp_tamp import grasp_graph, parallel

    monkeypatch.setattr(parallel, "cores", lambda: 2)
    monkeypatch.setattr(grasp_graph, "cores", lambda: 2)
    made = []
    real = parallel.Helper.__init__
    real_forked = parallel.Forked.__init__

    def init(self, state):
        made.append(("helper", len(state)))
        real(self, state)

    def forked(self, fn, *args):
        made.append(("forked", fn.__name__))
        real_forked(self, fn, *args)

    monkeypatch.setattr(parallel.Helper, "__init__", init)
    monkeypatch.setattr(parallel.Forked, "__init__", forked)
    res = solve(load_scenario(PICK))
    # the helper's state: (world, grasps, motion options, context, the setup's (ctx, domain, registry))
    assert made == [("forked", "enumerate_grasps"), ("helper", 5)]
    assert [w for s in res.plan.steps for w in s.waypoints] == [w for s in pick_result.plan.steps for w in s.waypoints]


def test_a_bad_domain_is_reported_before_a_missing_contact_pose(tmp_path: Path) -> None:
    from ldhp_tamp.errors import DomainError
    from ldhp_tamp.tamp import _declared_actions

    bad = Path(__file__).resolve().parents[1] / "data" / "domains" / "no-hand-free.pddl"
    assert _declared_actions(bad) is not None  # the light reading accepts it: its load is deferred
    text = PICK.read_text().replace("goal = [0, 100, 0]", "goal = [1000, 100, 0]")  # no goal contact pose
    sc = load_scenario_string(text, "impossible", base_dir=PICK.parent)
    with pytest.raises(DomainError, match="hand-free"):
        solve(sc, SolveOptions(domain=bad, max_top_iterations=1))


def test_when_the_two_readings_of_the_domain_differ_the_setup_is_made_again(pick_result, monkeypatch,
                                                                            caplog) -> None:
    from ldhp_tamp import tamp
    from ldhp_tamp.domain_info import DomainActions

    right = tamp._declared_actions(load_scenario(PICK).settings.domain_path)
    assert right is not None and "flip" in right.names()
    wrong = DomainActions(right.name, right.source, tuple(a for a in right.actions if a[0] != "flip"))
    monkeypatch.setattr(tamp, "_declared_actions", lambda source: wrong)
    with caplog.at_level("WARNING", logger="ldhp_tamp.tamp"):
        res = solve(load_scenario(PICK))
    assert "the setup again with unified-planning's" in caplog.text
    assert res.plan.stats.grasp_graph_edges == pick_result.plan.stats.grasp_graph_edges  # flip's edges too
    assert [w for s in res.plan.steps for w in s.waypoints] == [w for s in pick_result.plan.steps for w in s.waypoints]
