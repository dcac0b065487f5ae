"""Transition priors (:mod:`ldhp_tamp.prior`): the file, the fit from plans, and what a
solve does with one (defers the transitions it rates low, lets them back in when no plan
is left without them)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from ldhp_tamp.cli import EXIT_BAD_INPUT, EXIT_OK, main
from ldhp_tamp.errors import InputError
from ldhp_tamp.plan import read_plan, write_plan
from ldhp_tamp.prior import (
    DEFER_BELOW,
    PRIOR_FORMAT,
    STATS_KEY,
    Outcomes,
    PriorError,
    TransitionPrior,
    fit_prior,
    outcomes_from_stats,
    plan_files,
    read_prior,
    write_prior,
)
from ldhp_tamp.resources import scenarios_dir
from ldhp_tamp.scenario import load_scenario
from ldhp_tamp.tamp import SolveOptions, solve

PICK = scenarios_dir() / "example_pick.toml"


def test_acceptance_is_the_posterior_mean_and_low_ones_are_deferred() -> None:
    assert Outcomes().acceptance == 0.5
    assert Outcomes(0, 3).acceptance == pytest.approx(0.2)
    assert Outcomes(1, 1).acceptance == 0.5
    assert Outcomes(3, 0).acceptance == pytest.approx(0.8)
    assert Outcomes(1, 2) + Outcomes(2, 5) == Outcomes(3, 7)
    prior = TransitionPrior({"tip a->b": Outcomes(0, 3), "tip b->c": Outcomes(0, 1), "push c->d": Outcomes(4, 9)})
    assert prior.acceptance("never seen") == 0.5
    # 0.2 < 0.25; 1/3 and 5/15 are not
    assert prior.deferred(["tip a->b", "tip b->c", "push c->d", "never seen"]) == {"tip a->b"}
    assert TransitionPrior(prior.transitions, defer_below=0.4).deferred(prior.transitions) == \
        {"tip a->b", "tip b->c", "push c->d"}
    assert TransitionPrior(prior.transitions, defer_below=0.0).deferred(prior.transitions) == frozenset()
    with pytest.raises(ValueError, match="count"):
        Outcomes(-1, 0)
    with pytest.raises(ValueError, match="defer_below"):
        TransitionPrior({}, defer_below=1.5)


def test_a_prior_file_round_trips(tmp_path: Path) -> None:
    prior = TransitionPrior({"tip v1-e1->l4-e1": Outcomes(0, 15), "push l1-e1->l1-e1+l2-e8": Outcomes(5, 0)},
                            ("task2-slot-insertion",), 5, 0.3)
    path = write_prior(prior, tmp_path / "prior.json")
    data = json.loads(path.read_text(encoding="utf-8"))
    assert data["format"] == PRIOR_FORMAT and data["transitions"]["tip v1-e1->l4-e1"] == {"accepted": 0, "refused": 15}
    assert read_prior(path) == prior


@pytest.mark.parametrize("text, problem", [
    (None, "cannot read"),
    ("{not json", "not a JSON file"),
    ('{"format": "ldhp-plan/1"}', "not a prior file"),
    ('[1, 2]', "not a prior file"),
    ('{"format": "ldhp-prior/1", "colour": 1}', "unknown key"),
    ('{"format": "ldhp-prior/1", "transitions": []}', "transitions"),
    ('{"format": "ldhp-prior/1", "transitions": {"a": {"accepted": -1}}}', "count"),
    ('{"format": "ldhp-prior/1", "transitions": {"a": {"acepted": 1}}}', "expected"),
    ('{"format": "ldhp-prior/1", "transitions": {"a": {"accepted": true}}}', "count"),
    ('{"format": "ldhp-prior/1", "defer_below": 2}', "defer_below"),
    ('{"format": "ldhp-prior/1", "defer_below": "low"}', "defer_below"),
    ('{"format": "ldhp-prior/1", "plans": -3}', "plans"),
    ('{"format": "ldhp-prior/1", "fit_on": "task"}', "fit_on"),
])
def test_a_bad_prior_file_is_refused_naming_it(tmp_path: Path, text: str | None, problem: str) -> None:
    path = tmp_path / "p.json"
    if text is not None:
        path.write_text(text, encoding="utf-8")
    with pytest.raises(PriorError, match=problem) as err:
        read_prior(path)
    assert str(path) in str(err.value) and isinstance(err.value, InputError)


@pytest.fixture(scope="module")
def pick_plan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    result = solve(load_scenario(PICK), SolveOptions(seed=0))
    assert result.solved
    return write_plan(result.plan, tmp_path_factory.mktemp("plans") / "pick-plan.json")


def test_a_solve_records_what_the_bottom_tier_accepted(pick_plan: Path) -> None:
    plan = read_plan(pick_plan)  # written and read back: the counts are part of the file
    seen = outcomes_from_stats(plan.stats.extra, str(pick_plan))
    assert seen == {"air-move l1-e3->free": Outcomes(1, 0)}  # the pick's one transition, accepted
    assert "prior_deferred" not in plan.stats.extra  # no prior given


def test_a_prior_is_fitted_by_adding_up_plans(pick_plan: Path, tmp_path: Path) -> None:
    other = json.loads(pick_plan.read_text(encoding="utf-8"))
    other["stats"][STATS_KEY] = {"air-move l1-e3->free": {"accepted": 2, "refused": 1},
                                 "tip l1-e3->v1-e3": {"accepted": 0, "refused": 4}}
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "other-plan.json").write_text(json.dumps(other), encoding="utf-8")
    (tmp_path / "runs.json").write_text("{}", encoding="utf-8")  # not a plan: not picked up in a folder
    files = plan_files([pick_plan, tmp_path])
    assert [f.name for f in files] == ["pick-plan.json", "other-plan.json"]
    prior = fit_prior(files)
    assert prior.transitions == {"air-move l1-e3->free": Outcomes(3, 1), "tip l1-e3->v1-e3": Outcomes(0, 4)}
    assert prior.plans == 2 and prior.fit_on == ("example-pick",) and prior.defer_below == DEFER_BELOW
    assert prior.deferred(prior.transitions) == {"tip l1-e3->v1-e3"}
    with pytest.raises(PriorError, match="no plan file"):
        fit_prior([])
    with pytest.raises(InputError, match="runs.json"):
        fit_prior([tmp_path / "runs.json"])  # named explicitly: it must be a plan
    with pytest.raises(PriorError, match="no such file"):
        plan_files([tmp_path / "missing"])


def test_deferred_transitions_are_let_back_in_when_no_plan_is_left_without_them() -> None:
    """A prior that defers every transition (each unseen one rates 0.5, below 1) leaves the
    symbolic tier no plan: they all come back, and the solve is the one without a prior."""
    scenario = load_scenario(PICK)
    plain = solve(scenario, SolveOptions(seed=0))
    result = solve(scenario, SolveOptions(seed=0, prior=TransitionPrior({}, defer_below=1.0)))
    assert result.solved
    extra = result.plan.stats.extra
    assert extra["prior_deferred"] > 0 and extra["prior_relaxed"] is True
    assert result.plan.steps == plain.plan.steps


def test_a_deferred_transition_is_planned_around_where_the_world_allows() -> None:
    """Deferring the pick's lift off the table (air-move l1-e3->free): the block is tipped
    onto a corner and lifted from there, a route the same checks accept."""
    scenario = load_scenario(PICK)
    result = solve(scenario, SolveOptions(seed=0, prior=TransitionPrior({"air-move l1-e3->free": Outcomes(0, 10)})))
    assert result.solved
    extra = result.plan.stats.extra
    assert extra["prior_deferred"] == 1 and extra["prior_relaxed"] is False
    assert "air-move l1-e3->free" not in extra[STATS_KEY] and "tip" in [s.primitive for s in result.plan.steps]


def test_a_prior_that_defers_nothing_leaves_the_solve_as_it_is() -> None:
    scenario = load_scenario(PICK)
    plain = solve(scenario, SolveOptions(seed=0))
    result = solve(scenario, SolveOptions(seed=0, prior=TransitionPrior({"air-move l1-e3->free": Outcomes(3, 0)})))
    assert result.solved and result.plan.steps == plain.plan.steps
    assert result.plan.stats.extra["prior_deferred"] == 0 and result.plan.stats.extra["prior_relaxed"] is False


def test_the_prior_command_fits_and_writes_a_prior(pick_plan: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "prior.json"
    assert main(["prior", str(pick_plan), "--out", str(out), "--defer-below", "0.1"]) == EXIT_OK
    assert "1 transition from 1 plan(s) of example-pick" in capsys.readouterr().out
    prior = read_prior(out)
    assert prior.defer_below == 0.1 and prior.transitions == {"air-move l1-e3->free": Outcomes(1, 0)}
    # and a solve takes it
    plan = tmp_path / "pick-plan.json"
    assert main(["solve", str(PICK), "--prior", str(out), "--out", str(plan), "-q"]) == EXIT_OK
    assert read_plan(plan).stats.extra["prior_deferred"] == 0


@pytest.mark.parametrize("argv, named", [
    (["prior", "missing-plan.json", "--out", "{tmp}/p.json"], "missing-plan.json"),
    (["prior", str(PICK), "--out", "{tmp}/p.json"], "example_pick.toml"),  # not a plan
    (["prior", "{plan}", "--out", "{tmp}/no/such/dir/p.json"], "--out"),
    (["prior", "{plan}", "--out", "{tmp}/p.json", "--defer-below", "2"], "--defer-below"),
    (["solve", str(PICK), "--prior", "{tmp}/missing.json", "--out", "{tmp}/x-plan.json"], "missing.json"),
])
def test_bad_prior_input_exits_2_and_writes_nothing(argv: list[str], named: str, pick_plan: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    args = [a.format(tmp=tmp_path, plan=pick_plan) for a in argv]
    assert _exit_status(args) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "Traceback" not in err and named in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing half-written


def _exit_status(argv: list[str]) -> int:
    """``main(argv)``'s status, or argparse's for a usage error (it exits)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
