"""Honest failures: an unsolvable task ends with status ``failed``, exit status 1, a plan
file with no steps, the statistics, and a reason naming the tier and the cause.

One scenario per kind of impossibility in ``tests/data/scenarios/unsolvable/``, each a
variant of ``scenarios/example_pick.toml``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ldhp_tamp.cli import EXIT_NO_PLAN, main

UNSOLVABLE = Path(__file__).resolve().parents[1] / "data" / "scenarios" / "unsolvable"

#: Every file in tests/data/scenarios/unsolvable: fragments of the reason, the first one
#: its beginning (the tier).
EXPECTED: dict[str, tuple[str, ...]] = {
    # no translation along the axes brings the goal into contact: Step 1 fails
    "goal_out_of_reach.toml": ("top tier, step 1: no contact pose for the goal",
                               "touches nothing when moved up to"),
    # start and goal share a contact state, but the way between them is walled off
    "goal_in_closed_box.toml": ("top tier, step 3: the contact-state plan needs no change of contact state",
                                "no in-state motion", "without leaving l1-e3"),
    # no pinch: the only way up fails in the grasp graph, then nothing else is left
    "gripper_too_small.toml": ("bottom tier: no grasp can execute segment 0 (air-move l1-e3 -> free)",
                               "quasi-statically feasible", "after forbidding air-move l1-e3->free",
                               "the symbolic tier (pyperplan): no contact-state path from s-l1-e3 to s-free",
                               "no admissible and unforbidden transition of a declared MoveObject primitive "
                               "enters free"),
    # the domain without air-move: no primitive takes the object off the table
    "pick_without_air_move.toml": ("symbolic tier (pyperplan): no contact-state path from s-l1-e3 to s-free",
                                   "(MoveObject: tip, push, biplanar-slide;",
                                   "no admissible transition of a declared MoveObject primitive enters free"),
}


def test_every_unsolvable_file_has_an_expectation() -> None:
    assert {p.name for p in UNSOLVABLE.glob("*.toml")} == set(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_an_unsolvable_task_fails_honestly(name: str, tmp_path: Path, capsys) -> None:
    out = tmp_path / "plan.json"
    assert main(["solve", str(UNSOLVABLE / name), "--out", str(out), "-q"]) == EXIT_NO_PLAN
    plan = json.loads(out.read_text())
    assert plan["status"] == "failed" and plan["steps"] == []
    reason = plan["reason"]
    first, *rest = EXPECTED[name]
    assert reason.startswith(first), reason
    for fragment in rest:
        assert fragment in reason, reason
    assert set(plan["stats"]) >= {"engine", "contact_state_nodes", "top_iterations", "time_s"}
    printed = capsys.readouterr().out
    assert printed.startswith(f"failed: {plan['scenario']}") and f"reason: {reason}" in printed
