"""Honest failures: an unsolvable task ends with status ``failed``, exit status 1, a plan
file with no steps, the statistics, a one-line reason naming the tier and the cause, and
the detail as the plan's ``failure`` (tier, cause, step, counts, every attempt in full).

One scenario per kind of impossibility in ``tests/data/scenarios/unsolvable/``, each a
variant of ``scenarios/example_pick.toml``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ldhp_tamp.cli import EXIT_NO_PLAN, main
from ldhp_tamp.plan import FailureCause, FailureTier, read_plan

UNSOLVABLE = Path(__file__).resolve().parents[1] / "data" / "scenarios" / "unsolvable"

#: Every file in tests/data/scenarios/unsolvable: the beginning of the reason (the tier),
#: then fragments of the reason or of the failure's attempts (the detail).
EXPECTED: dict[str, tuple[str, ...]] = {
    # no translation along the axes brings the goal into contact: Step 1 fails
    "goal_out_of_reach.toml": ("top tier, step 1: no contact pose for the goal",
                               "touches nothing when moved up to"),
    # start and goal share a contact state, but the way between them is walled off
    "goal_in_closed_box.toml": ("top tier, step 3: the contact-state plan needs no change of contact state",
                                "no in-state motion", "without leaving l1-e3"),
    # no pinch: the only way up fails in the grasp graph, then nothing else is left
    "gripper_too_small.toml": ("bottom tier, step 0, segment 0 (air-move l1-e3 -> free): no grasp executes it",
                               "no contact-state plan left after 2 top-tier iterations",
                               "bottom tier: no grasp can execute segment 0 (air-move l1-e3 -> free)",
                               "quasi-statically feasible", "after forbidding air-move l1-e3->free",
                               "the symbolic tier (pyperplan): no contact-state path from s-l1-e3 to s-free",
                               "no admissible and unforbidden transition of a declared MoveObject primitive "
                               "enters free"),
    # the domain without air-move: no primitive takes the object off the table
    "pick_without_air_move.toml": ("symbolic tier (pyperplan): no contact-state path from s-l1-e3 to s-free",
                                   "(MoveObject: tip, push, biplanar-slide;",
                                   "no admissible transition of a declared MoveObject primitive enters free"),
}


#: Every file in tests/data/scenarios/unsolvable: the failure's tier, cause, step, segment
#: and primitive.
FAILURE: dict[str, tuple[FailureTier, FailureCause, int | None, int | None, str | None]] = {
    "goal_out_of_reach.toml": (FailureTier.SETUP, FailureCause.NO_CONTACT_POSE, None, None, None),
    "goal_in_closed_box.toml": (FailureTier.STREAMS, FailureCause.NO_STREAM_SAMPLE, None, None, None),
    "gripper_too_small.toml": (FailureTier.BOTTOM, FailureCause.EMPTY_MOTION_SET, 0, 0, "air-move"),
    "pick_without_air_move.toml": (FailureTier.SYMBOLIC, FailureCause.NO_SYMBOLIC_PLAN, None, None, None),
}


def test_every_unsolvable_file_has_an_expectation() -> None:
    assert {p.name for p in UNSOLVABLE.glob("*.toml")} == set(EXPECTED) == set(FAILURE)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_an_unsolvable_task_fails_honestly(name: str, tmp_path: Path, capsys) -> None:
    out = tmp_path / "plan.json"
    assert main(["solve", str(UNSOLVABLE / name), "--out", str(out), "-q"]) == EXIT_NO_PLAN
    plan = json.loads(out.read_text())
    assert plan["status"] == "failed" and plan["steps"] == []
    reason = plan["reason"]
    # the reason is a headline: one line, short, the tier first
    assert len(reason) <= 200 and "\n" not in reason, reason
    first, *rest = EXPECTED[name]
    assert reason.startswith(first), reason
    # the detail is in the failure, every attempt in full
    detail = "\n".join([reason, *plan["failure"]["attempts"]])
    for fragment in rest:
        assert fragment in detail, detail
    assert set(plan["stats"]) >= {"engine", "contact_state_nodes", "top_iterations", "time_s"}
    failure = read_plan(out).failure  # read back through the reader
    assert failure is not None and failure.cause.value in {c.value for c in FailureCause}
    assert (failure.tier, failure.cause, failure.step, failure.segment, failure.primitive) == FAILURE[name]
    assert failure.attempts and failure.counts["top_iterations"] == plan["stats"]["top_iterations"]
    printed = capsys.readouterr().out
    assert printed.startswith(f"failed: {plan['scenario']}") and f"reason: {reason}" in printed
    assert "attempts" not in printed  # the whole failure only with -v


def test_verbose_solve_prints_the_whole_failure(tmp_path: Path, capsys) -> None:
    out = tmp_path / "plan.json"
    assert main(["solve", str(UNSOLVABLE / "gripper_too_small.toml"), "--out", str(out), "-q", "-v"]) == EXIT_NO_PLAN
    printed = capsys.readouterr().out
    attempts = json.loads(out.read_text())["failure"]["attempts"]
    assert len(attempts) == 2
    assert "  failure: tier bottom, cause empty-motion-set, step 0, segment 0, primitive air-move" in printed
    assert "  counts: top_iterations 2, pose_paths 1, forbidden 1" in printed
    for i, attempt in enumerate(attempts, start=1):
        assert f"    {i}. {attempt}\n" in printed
    # the global flag says the same
    assert main(["-v", "solve", str(UNSOLVABLE / "gripper_too_small.toml"), "--out", str(out), "-q"]) == EXIT_NO_PLAN
    assert f"    2. {attempts[1]}" in capsys.readouterr().out
