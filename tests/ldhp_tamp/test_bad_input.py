"""Bad input through the command line: every refusal is one line on stderr naming the file,
exit status 2, no traceback unless ``--debug``, and nothing written; an unexpected
exception is a bug and never passes for an outcome (exit 70, with its traceback).

Scenario refusals in detail are in ``test_scenario.py`` and ``test_cli_check.py``; the
domain files are under ``tests/data/domains/``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ldhp_tamp import tamp
from ldhp_tamp.cli import COMMANDS, EXIT_BAD_INPUT, EXIT_BUG, EXIT_NO_PLAN, EXIT_OK, main
from ldhp_tamp.errors import DomainError
from ldhp_tamp.resources import scenarios_dir

REPO = Path(__file__).resolve().parents[2]
DOMAINS = REPO / "tests" / "data" / "domains"
BAD_SCENARIOS = sorted((REPO / "tests" / "data" / "scenarios" / "bad").glob("*.toml"))
PICK = scenarios_dir() / "example_pick.toml"
EXECUTABLE = Path(sys.executable).parent / "ldhp-tamp"

#: Every domain file in tests/data/domains that ``solve`` must refuse (with the scenario's
#: engine, pyperplan): a fragment of the message.
REFUSED_DOMAINS: dict[str, str] = {
    "syntax-error.pddl": ":42:3: PDDL error: Expected ')'",  # tip's unclosed precondition
    "unsupported-requirement.pddl": ":5: unsupported PDDL requirement :durative-actions",
    "no-implementation.pddl": "action 'juggle' has no registered implementation",
    "no-admissibility.pddl": "MoveObject action 'push' (it changes (at ?s)) has no static precondition",
    "no-hand-free.pddl": "the domain must declare the predicate (hand-free)",
    "costs.pddl": "engine 'pyperplan' cannot solve domain",  # it would ignore the action costs
}
#: Domain files that load (used by other tests).
USABLE_DOMAINS = {"no-air-move.pddl"}

#: The refusals the format requires (docs/formats/scenario.md, "What the loader refuses"), each with
#: the files of tests/data/scenarios/bad/ that exercise it.
SPEC_REFUSALS: dict[str, tuple[str, ...]] = {
    "unknown format": ("unknown_format.toml",),
    "missing required key": ("missing_format.toml", "missing_name.toml", "missing_object_vertices.toml",
                             "missing_solid_vertices.toml", "missing_gripper_model.toml", "missing_spacing.toml",
                             "missing_friction_gripper.toml", "missing_task_goal.toml", "missing_task_table.toml",
                             "start_grasp_missing_width.toml"),
    "wrong type": ("wrong_type_name.toml", "wrong_type_object.toml", "wrong_type_vertices.toml",
                   "wrong_type_vertex_coordinate.toml", "wrong_type_mass.toml", "wrong_type_com.toml",
                   "wrong_type_engine.toml", "wrong_type_goal_release.toml", "bool_as_number.toml",
                   "bool_as_coordinate.toml", "samples_per_edge_float.toml", "float_seed.toml"),
    "non-finite number": ("nonfinite_coordinate.toml", "nan_pose.toml", "nonfinite_friction.toml",
                          "nonfinite_mass.toml"),
    "self-intersecting polygon": ("self_intersecting_object.toml", "bad_solid_polygon.toml", "bad_palm_polygon.toml"),
    "degenerate polygon": ("zero_area_object.toml", "repeated_vertex.toml", "two_vertices.toml",
                           "bad_finger_polygon.toml"),
    "negative friction": ("negative_friction.toml", "negative_override_mu.toml", "negative_object_edge_mu.toml"),
    "negative mass": ("negative_mass.toml",),
    "spacing/opening min > max": ("spacing_min_gt_max.toml", "opening_min_gt_max.toml"),
    "spacing/opening negative": ("negative_spacing.toml", "negative_opening.toml"),
    "start or goal overlaps a solid": ("start_overlaps_solid.toml", "goal_overlaps_solid.toml"),
    "unknown edge in an override": ("unknown_edge_override.toml", "edge_zero_override.toml",
                                    "unknown_object_edge_override.toml"),
    "samples_per_edge outside 2..10000": ("samples_per_edge_too_small.toml", "samples_per_edge_too_large.toml"),
    "unknown domain": ("unknown_domain.toml", "missing_domain_file.toml"),
    "unknown engine": ("unknown_engine.toml",),
}


def _one_line_error(stderr: str, *fragments: str) -> str:
    assert "Traceback" not in stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: ")
    for fragment in fragments:
        assert fragment in lines[0]
    return lines[0]


def _scenario_with_domain(folder: Path, domain: Path) -> Path:
    """example_pick with ``planner.domain`` set to ``domain``, written into ``folder``."""
    folder.mkdir(exist_ok=True)
    path = folder / f"pick-with-{domain.stem}.toml"
    path.write_text(PICK.read_text() + f"\n[planner]\ndomain = '{domain}'\n")
    return path


# --------------------------------------------------------------------------- coverage


def test_every_domain_file_has_an_expectation() -> None:
    assert {p.name for p in DOMAINS.glob("*.pddl")} == set(REFUSED_DOMAINS) | USABLE_DOMAINS


def test_every_refusal_of_the_scenario_spec_has_bad_files() -> None:
    on_disk = {p.name for p in BAD_SCENARIOS}
    for refusal, files in SPEC_REFUSALS.items():
        assert files and set(files) <= on_disk, refusal


# --------------------------------------------------------------------------- domains


@pytest.mark.parametrize("name", sorted(REFUSED_DOMAINS))
def test_solve_refuses_a_bad_domain_in_one_line_and_writes_nothing(name: str, tmp_path: Path, capsys) -> None:
    domain = DOMAINS / name
    scenario = _scenario_with_domain(tmp_path / "in", domain)
    out = tmp_path / "out"
    out.mkdir()
    code = main(["solve", str(scenario), "--out", str(out / "plan.json"), "--emit-pddl", str(out / "pddl"), "-q"])
    assert code == EXIT_BAD_INPUT
    captured = capsys.readouterr()
    assert captured.out == ""
    _one_line_error(captured.err, str(domain), REFUSED_DOMAINS[name])
    assert list(out.iterdir()) == []


def test_debug_shows_the_traceback_and_still_exits_2(tmp_path: Path, capsys) -> None:
    scenario = _scenario_with_domain(tmp_path, DOMAINS / "no-implementation.pddl")
    code = main(["--debug", "solve", str(scenario), "--out", str(tmp_path / "plan.json"), "-q"])
    assert code == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "ldhp_tamp.errors.DomainError" in err
    assert err.strip().splitlines()[-1].startswith("error: ") and "'juggle'" in err
    assert not (tmp_path / "plan.json").exists()


def test_the_executable_with_debug_prints_the_traceback_of_a_syntax_error(tmp_path: Path) -> None:
    domain = DOMAINS / "syntax-error.pddl"
    scenario = _scenario_with_domain(tmp_path, domain)
    args = [str(EXECUTABLE), "--debug", "solve", str(scenario), "--out", str(tmp_path / "plan.json"), "-q"]
    run = subprocess.run(args, capture_output=True, text=True, timeout=120)
    assert run.returncode == EXIT_BAD_INPUT and run.stdout == ""
    assert "Traceback (most recent call last)" in run.stderr
    assert run.stderr.strip().splitlines()[-1].startswith(f"error: {domain}:42:3: PDDL error")
    assert not (tmp_path / "plan.json").exists()


def test_an_unknown_engine_on_the_command_line_names_it_and_the_domain(tmp_path: Path, capsys) -> None:
    code = main(["solve", str(PICK), "--engine", "warp-drive", "--out", str(tmp_path / "p.json"), "-q"])
    assert code == EXIT_BAD_INPUT
    _one_line_error(capsys.readouterr().err, "unknown planning engine 'warp-drive' for domain",
                    "ldhp.pddl", "installed: ", "pyperplan")
    assert list(tmp_path.iterdir()) == []


def test_requirements_are_read_with_their_line() -> None:
    from ldhp_tamp.symbolic import parse_domain

    text = (REPO / "domains" / "ldhp.pddl").read_text()
    line = text[:text.index("(:requirements")].count("\n") + 1
    for requirement, problem in ((":derived-predicates", "unsupported PDDL requirement :derived-predicates"),
                                 (":warp-drive", "unknown PDDL requirement :warp-drive")):
        edited = text.replace("(:requirements :strips :typing)", f"(:requirements :strips :typing\n {requirement})")
        with pytest.raises(DomainError, match=f"^edited.pddl:{line + 1}: {problem}"):
            parse_domain(edited, "edited.pddl")
    # a requirement in a comment is no requirement; those of the fragment are accepted
    parse_domain(text.replace("(:requirements :strips :typing)",
                              "(:requirements :strips :typing :ADL :action-costs) ; (:requirements :time)"))


# --------------------------------------------------------------------------- scenarios


@pytest.mark.parametrize("path", BAD_SCENARIOS, ids=lambda p: p.name)
def test_solve_refuses_a_bad_scenario_and_writes_nothing(path: Path, tmp_path: Path, capsys) -> None:
    code = main(["solve", str(path), "--out", str(tmp_path / "plan.json"), "--emit-pddl", str(tmp_path / "pddl"),
                 "-q"])
    assert code == EXIT_BAD_INPUT
    _one_line_error(capsys.readouterr().err, path.name)
    assert list(tmp_path.iterdir()) == []


def test_an_output_folder_that_does_not_exist_is_refused_before_solving(tmp_path: Path, capsys,
                                                                       monkeypatch) -> None:
    monkeypatch.setattr(tamp, "solve", lambda *a, **k: pytest.fail("solved before checking --out"))
    out = tmp_path / "no" / "such" / "plan.json"
    assert main(["solve", str(PICK), "--out", str(out), "-q"]) == EXIT_BAD_INPUT
    _one_line_error(capsys.readouterr().err, str(out), "--out: no such directory")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- bugs


def test_an_unexpected_exception_is_a_bug_not_an_outcome(tmp_path: Path, capsys, monkeypatch) -> None:
    def broken(*args, **kwargs):
        raise ZeroDivisionError("a bug in the planner")

    monkeypatch.setattr(tamp, "solve", broken)
    code = main(["solve", str(PICK), "--out", str(tmp_path / "plan.json"), "-q"])
    assert code == EXIT_BUG and code not in (EXIT_OK, EXIT_NO_PLAN, EXIT_BAD_INPUT)
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "ZeroDivisionError: a bug in the planner" in err
    assert "internal error (a bug)" in err.strip().splitlines()[-1]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["check", "validate", "solve"])
def test_every_command_maps_an_unexpected_exception_to_70(command: str, monkeypatch, capsys) -> None:
    def broken(args):
        raise KeyError("oops")

    monkeypatch.setitem(COMMANDS, command, broken)
    argv = {"validate": ["validate", "p.json", "--scenario", "s.toml"]}.get(command, [command, "s.toml"])
    assert main(argv) == EXIT_BUG
    assert "KeyError: 'oops'" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["solve", "validate", "check"])
def test_the_exit_codes_are_documented(command: str, capsys) -> None:
    with pytest.raises(SystemExit) as info:
        main([command, "--help"])
    assert info.value.code == EXIT_OK
    help_text = capsys.readouterr().out
    readme = (REPO / "README.md").read_text()
    section = readme[readme.index("Exit status, for every command"):]
    section = section[:section.index("\n\n")]
    for code, words in ((0, "solved"), (1, "no plan found"), (2, "bad input or usage"), (70, "a bug")):
        assert f"\n  {code} " in help_text and words in help_text
        assert f"{code} {words}" in section
