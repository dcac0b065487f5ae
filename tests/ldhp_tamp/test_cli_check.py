"""``ldhp-tamp check``: refusals exit 2 with one line on stderr and no traceback.

Unlike ``test_scenario.py`` these run the real stack: the shipped ``domains/`` and the
engines ``ldhp_tamp.symbolic.available_engines()`` reports.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ldhp_tamp import resources
from ldhp_tamp.cli import COMMANDS, EXIT_BAD_INPUT, EXIT_OK, main

REPO = Path(__file__).resolve().parents[2]
BAD = sorted((REPO / "tests" / "data" / "scenarios" / "bad").glob("*.toml"))
GOOD = sorted((REPO / "tests" / "data" / "scenarios" / "good").glob("*.toml"))
SHIPPED = sorted(resources.scenarios_dir().glob("*.toml"))
EXECUTABLE = Path(sys.executable).parent / "ldhp-tamp"


def _one_line_error(stderr: str, path: Path) -> None:
    assert "Traceback" not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: ") and path.name in lines[0]


@pytest.mark.parametrize("path", BAD, ids=lambda p: p.name)
def test_check_refuses_bad_file(path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(path)]) == EXIT_BAD_INPUT
    out, err = capsys.readouterr()
    assert out == ""
    _one_line_error(err, path)


@pytest.mark.parametrize("path", [*SHIPPED, *GOOD], ids=lambda p: f"{p.parent.name}/{p.name}")
def test_check_accepts_good_file(path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(path)]) == EXIT_OK
    out, _ = capsys.readouterr()
    assert out.startswith("scenario ") and "object: " in out


def test_check_reports_every_file_and_fails_if_one_is_bad(capsys: pytest.CaptureFixture[str]) -> None:
    good = resources.scenarios_dir() / "task1_zero_mobility_lift.toml"
    bad = REPO / "tests" / "data" / "scenarios" / "bad" / "unknown_engine.toml"
    assert main(["check", str(bad), str(good)]) == EXIT_BAD_INPUT
    out, err = capsys.readouterr()
    assert "scenario task1-zero-mobility-lift" in out
    _one_line_error(err, bad)


def test_executable_refuses_bad_file() -> None:
    bad = REPO / "tests" / "data" / "scenarios" / "bad" / "self_intersecting_object.toml"
    run = subprocess.run([str(EXECUTABLE), "check", str(bad)], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == EXIT_BAD_INPUT
    assert run.stdout == ""
    _one_line_error(run.stderr, bad)
    assert "object.vertices: self-intersecting polygon" in run.stderr


def test_executable_checks_the_shipped_scenarios() -> None:
    run = subprocess.run([str(EXECUTABLE), "check", *map(str, SHIPPED)], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == EXIT_OK, run.stderr
    assert run.stderr == ""
    assert run.stdout.count("\nscenario ") + run.stdout.startswith("scenario ") == len(SHIPPED)


# --------------------------------------------------------------------------- what solve refuses before searching

DOMAINS = REPO / "tests" / "data" / "domains"
PICK = resources.scenarios_dir() / "example_pick.toml"
#: Domain files that load and pass the registry and engine checks.
USABLE_DOMAINS = {"no-air-move.pddl"}


def _pick_with_domain(folder: Path, domain: Path) -> Path:
    path = folder / f"pick-with-{domain.stem}.toml"
    path.write_text(PICK.read_text() + f"\n[planner]\ndomain = '{domain}'\n")
    return path


@pytest.mark.parametrize("domain", sorted(p for p in DOMAINS.glob("*.pddl") if p.name not in USABLE_DOMAINS),
                         ids=lambda p: p.name)
def test_check_refuses_what_solve_refuses_before_searching(domain: Path, tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    scenario = _pick_with_domain(tmp_path, domain)
    assert main(["check", str(scenario)]) == EXIT_BAD_INPUT
    check_out, check_err = capsys.readouterr()
    assert check_out == ""
    _one_line_error(check_err, scenario)
    assert str(domain) in check_err
    # solve refuses it with the same message (less the scenario's name), before any search
    assert main(["solve", str(scenario), "--out", str(tmp_path / "plan.json"), "-q"]) == EXIT_BAD_INPUT
    solve_err = capsys.readouterr().err
    assert check_err == solve_err.replace("error: ", f"error: {scenario}: ", 1)
    assert not (tmp_path / "plan.json").exists()


def test_check_names_the_action_without_implementation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    domain = DOMAINS / "no-implementation.pddl"
    scenario = _pick_with_domain(tmp_path, domain)
    assert main(["check", str(scenario), str(PICK)]) == EXIT_BAD_INPUT
    out, err = capsys.readouterr()
    assert out.startswith("scenario example-pick")  # the other file is still checked
    assert err.strip() == (f"error: {scenario}: {domain}: action 'juggle' has no registered implementation "
                           "(see docs/extending.md)")


@pytest.mark.parametrize("name", sorted(USABLE_DOMAINS))
def test_check_accepts_a_usable_domain(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(_pick_with_domain(tmp_path, DOMAINS / name))]) == EXIT_OK
    assert capsys.readouterr().out.startswith("scenario example-pick")


# --------------------------------------------------------------------------- --strict

TYPO = REPO / "tests" / "data" / "scenarios" / "good" / "extra_keys.toml"


def test_unknown_keys_are_warned_and_ignored_by_default(capsys: pytest.CaptureFixture[str],
                                                       caplog: pytest.LogCaptureFixture) -> None:
    assert main(["check", str(TYPO)]) == EXIT_OK
    assert "samples_per_edge 100" in capsys.readouterr().out
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert f"{TYPO}: planner.sample_per_edge: unknown key ignored; did you mean 'samples_per_edge'?" in warned


def test_check_strict_refuses_an_unknown_key(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "--strict", str(TYPO)]) == EXIT_BAD_INPUT
    out, err = capsys.readouterr()
    assert out == ""
    _one_line_error(err, TYPO)
    assert f"{TYPO}: author: unknown key" in err


def test_strict_scenario_options_of_solve_validate_simulate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    typo = tmp_path / "pick-typo.toml"
    typo.write_text(PICK.read_text().replace("[object]", "[object]\nmas = 5", 1))
    plan = REPO / "tests" / "data" / "spec" / "pick-plan.json"
    runs = [["solve", str(typo), "--out", str(tmp_path / "plan.json"), "-q"],
            ["validate", str(plan), "--scenario", str(typo)]]
    if "simulate" in COMMANDS:
        runs.append(["simulate", str(plan), "--scenario", str(typo)])
    for args in runs:
        assert main([args[0], "--strict", *args[1:]]) == EXIT_BAD_INPUT, args
        out, err = capsys.readouterr()
        assert out == "", args
        _one_line_error(err, typo)
        assert f"{typo}: object.mas: unknown key" in err and "did you mean 'mass'?" in err
    assert not (tmp_path / "plan.json").exists()


def test_validate_ignores_an_unknown_key_without_strict(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    extended = tmp_path / "pick-extended.toml"
    extended.write_text(PICK.read_text().replace("[object]", "[object]\ncolour = 'red'", 1))
    plan = REPO / "tests" / "data" / "spec" / "pick-plan.json"
    assert main(["validate", str(plan), "--scenario", str(extended)]) == EXIT_OK
    assert "\nvalid: " in capsys.readouterr().out  # after the warning that the sha256 differs


# --------------------------------------------------------------------------- the engines are not imported

#: ``close`` changes (at ?s) here, so the domain makes it a MoveObject action; its implementation
#: is registered as an AdjustGrasp one.
MISFILED_CLOSE = """(define (domain misfiled-close)
  (:requirements :strips :typing)
  (:types state)
  (:predicates (at ?s - state) (touching) (hand-free) (can-close ?from ?to - state))
  (:action close
    :parameters (?from ?to - state)
    :precondition (and (at ?from) (touching) (can-close ?from ?to))
    :effect (and (not (at ?from)) (at ?to))))
"""


def test_check_refuses_an_implementation_registered_in_another_family(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    domain = tmp_path / "misfiled-close.pddl"
    domain.write_text(MISFILED_CLOSE)
    scenario = _pick_with_domain(tmp_path, domain)
    assert main(["check", str(scenario)]) == EXIT_BAD_INPUT
    check_out, check_err = capsys.readouterr()
    assert check_out == ""
    _one_line_error(check_err, scenario)
    assert (f"{domain}: action 'close' is move-object in the domain (it changes (at ?s)) but its implementation "
            "is registered as adjust-grasp") in check_err
    assert main(["solve", str(scenario), "--out", str(tmp_path / "plan.json"), "-q"]) == EXIT_BAD_INPUT
    assert check_err == capsys.readouterr().err.replace("error: ", f"error: {scenario}: ", 1)


def test_check_imports_no_engine() -> None:
    """Every check is made without unified-planning's engines (ConfigSpace, scipy.stats: 0.8 s of
    imports): their supported kinds are recorded in ldhp_tamp.engine_names."""
    from ldhp_tamp.engine_names import config_files

    if any(Path(f).is_file() for f in config_files()):  # then unified-planning is asked
        pytest.skip("a unified-planning configuration file exists on this machine")
    scenario = resources.scenarios_dir() / "task1_zero_mobility_lift.toml"
    code = ("import sys; from ldhp_tamp.cli import main; status = main(['check', sys.argv[1]]); "
            "print(sorted({m.split('.')[0] for m in sys.modules if m.startswith(('unified_planning.engines', "
            "'ConfigSpace', 'scipy', 'up_pyperplan', 'up_fast_downward'))}), status)")
    run = subprocess.run([sys.executable, "-c", code, str(scenario)], capture_output=True, text=True, timeout=120,
                         check=True)
    assert run.stdout.splitlines()[0].startswith("scenario task1-zero-mobility-lift")
    assert run.stdout.splitlines()[-1] == "[] 0"
