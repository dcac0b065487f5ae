"""Fuzzing (hypothesis): the loader accepts exactly the valid scenarios; the planner never
crashes, never hangs past its budget (a solve that runs out of it fails with a reason
naming the stage), and every plan it reports solved validates.

Whether a solve finishes within its budget depends on the machine's load; no verdict here
does: a solved plan must validate, a failed one must say why, and only a hang (past
:data:`HANG_GUARD_S`) fails. How far past ``--timeout`` a solve returns is measured by
``benchmarks/startup.py``.

A bounded run is part of the normal test suite (profile ``quick``, ~20 s); a longer one::

    HYPOTHESIS_PROFILE=long .venv/bin/python -m pytest tests/fuzz
"""

from __future__ import annotations

import re
import time

from hypothesis import assume, given, note, settings

from fuzz_scenarios import LONG, PROFILE, Ambiguous, Drawn, scenarios, verdict
from ldhp_tamp.errors import ScenarioError
from ldhp_tamp.plan import plan_to_json, read_plan_string
from ldhp_tamp.scenario import load_scenario_string
from ldhp_tamp.tamp import SolveOptions, SolveStatus, solve
from ldhp_tamp.validate import validate_plan

#: The planner's budget per example.
TIMEOUT_S = 1.5
#: The only upper bound on a solve's wall time: a guard against a hang, not a speed test.
HANG_GUARD_S = 60.0
#: A timeout's reason: the budget and the stage it ran out in (then what had been tried).
TIMEOUT_REASON = re.compile(rf"timeout: the {TIMEOUT_S:g} s budget ran out in \S.*")


def _expected(d: Drawn) -> list[str]:
    try:
        return verdict(d)
    except Ambiguous:
        assume(False)
        raise


@settings(settings.get_profile(PROFILE), max_examples=2000 if LONG else 60)
@given(scenarios())
def test_the_loader_accepts_exactly_the_valid_scenarios(d: Drawn) -> None:
    text = d.toml()
    note(text)
    expected = _expected(d)
    note(f"oracle: {expected or 'valid'}")
    try:
        load_scenario_string(text, "fuzz.toml", check_planner=False)
    except ScenarioError as exc:
        message = str(exc)
        assert expected, f"a valid scenario was refused: {message}"
        assert message.startswith("fuzz.toml: ") and "\n" not in message
        return
    assert not expected, f"an invalid scenario was accepted ({', '.join(expected)})"


@settings(settings.get_profile(PROFILE), max_examples=200 if LONG else 8)
@given(scenarios(valid_only=True))
def test_the_planner_never_crashes_overruns_or_reports_an_invalid_plan(d: Drawn) -> None:
    text = d.toml()
    note(text)
    assume(not _expected(d))
    scenario = load_scenario_string(text, "fuzz.toml")
    t0 = time.perf_counter()
    result = solve(scenario, SolveOptions(timeout=TIMEOUT_S, max_top_iterations=3))
    elapsed = time.perf_counter() - t0
    note(f"{result.status.value} in {elapsed:.2f} s: {result.reason}")
    assert elapsed < HANG_GUARD_S
    if result.status is SolveStatus.SOLVED:
        written = read_plan_string(plan_to_json(result.plan), "fuzz-plan.json")  # as a file would hold it
        report = validate_plan(written, scenario)
        assert report.valid, [str(v) for v in report.violations[:5]]
    else:
        assert result.reason and result.plan.steps == ()
        if result.reason.startswith("timeout"):
            assert TIMEOUT_REASON.fullmatch(result.reason), result.reason
