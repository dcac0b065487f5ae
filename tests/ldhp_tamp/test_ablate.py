"""The ablation (``ldhp-tamp ablate``): the domain-copy writer, one end-to-end ablation of
the spec's pick example through the API and one through the command line, exit codes.

Which primitives the pick needs was found by running the full ablation (every action
removed in turn): its plan is approach-contact -> air-move, and removing either of the two
leaves no plan; removing any other action leaves the baseline plan intact.
"""

from __future__ import annotations

import csv
import io
import logging
from pathlib import Path

import pytest

from ldhp_tamp import resources, symbolic
from ldhp_tamp.ablate import (
    BASELINE,
    CSV_COLUMNS,
    AblationOptions,
    AblationTable,
    _Job,
    _solve_job,
    ablate,
    domain_without,
    format_csv,
    format_table,
    parse_sexprs,
    write_domain_without,
)
from ldhp_tamp.bench import solver_has_timeout
from ldhp_tamp.cli import EXIT_BAD_INPUT, EXIT_OK, main
from ldhp_tamp.errors import DomainError, InputError
from ldhp_tamp.primitives import REGISTRY, Family, check_against_domain

REPO = Path(__file__).resolve().parents[2]
DOMAINS = sorted(resources.domains_dir().glob("*.pddl"))
LDHP = resources.domains_dir() / "ldhp.pddl"
PICK = resources.scenarios_dir() / "example_pick.toml"


def _actions(path: Path) -> tuple[str, ...]:
    return symbolic.load_domain(path).info.names()


# --------------------------------------------------------------------------- the domain copies


@pytest.mark.parametrize("domain", DOMAINS, ids=lambda p: p.name)
def test_each_action_can_be_removed(domain: Path, tmp_path: Path) -> None:
    original = symbolic.load_domain(domain).info
    actions = original.names()
    assert actions
    for action in actions:
        out = tmp_path / action
        out.mkdir()
        copy = write_domain_without(domain, {action}, out)
        assert copy.parent == out and copy.name == f"{domain.stem}-without-{action}.pddl"
        loaded = symbolic.load_domain(copy)  # it parses and keeps the domain's conventions
        assert loaded.info.names() == tuple(a for a in actions if a != action)
        for name in loaded.info.names():  # each kept action is unchanged, family included
            assert loaded.info.action(name) == original.action(name)
        check_against_domain(loaded.info, REGISTRY)
        assert f"(:action {action}" not in copy.read_text()


def test_the_copy_keeps_everything_but_the_action() -> None:
    text = LDHP.read_text()
    original = parse_sexprs(text)[0]
    copy = parse_sexprs(domain_without(text, {"biplanar-slide"}))[0]
    dropped = [f for f in original if isinstance(f, list) and f[:2] == [":action", "biplanar-slide"]]
    assert len(dropped) == 1
    assert copy == [f for f in original if f is not dropped[0]]
    # the predicates are kept, (can-biplanar-slide ...) now unused included
    assert ["can-biplanar-slide", "?from", "?to", "-", "state"] in next(
        f for f in copy if isinstance(f, list) and f[0] == ":predicates")
    assert parse_sexprs(domain_without(text, ()))[0] == original  # the baseline only reprints


def test_baseline_copy(tmp_path: Path) -> None:
    copy = write_domain_without("ldhp", (), tmp_path)  # a domain by name, as in a scenario
    assert copy.name == "ldhp-baseline.pddl" and _actions(copy) == _actions(LDHP)


def test_several_actions_at_once_and_names_ignore_case() -> None:
    text = domain_without(LDHP.read_text(), {"TIP", "Open"})
    names = symbolic.parse_domain(text).info.names()
    assert "tip" not in names and "open" not in names and len(names) == len(_actions(LDHP)) - 2


def test_unknown_action_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"no action 'lift' to remove; the domain declares tip, push"):
        domain_without(LDHP.read_text(), {"lift"}, source=str(LDHP))
    with pytest.raises(InputError, match="no action 'lift'"):
        write_domain_without(LDHP, {"lift"}, tmp_path)
    assert not list(tmp_path.iterdir())


def test_comments_do_not_confuse_the_parser() -> None:
    text = """; (:action ghost) in a comment, with an unbalanced ( too
(define (domain d) ; (:action ghost2
  (:requirements :strips) (:types state)
  (:predicates (at ?s - state) (touching) (hand-free))
  (:action a :parameters () :precondition (touching) :effect (and (hand-free) (not (touching)))) ; ))
  (:action b :parameters () :precondition (hand-free) :effect (and (touching) (not (hand-free)))))
"""
    out = domain_without(text, {"a"})
    assert "ghost" not in out
    assert symbolic.parse_domain(out).info.names() == ("b",)


@pytest.mark.parametrize("text", ["(define (domain d) (:action a)", "(define (domain d)))",
                                  "(define (problem p))", "(define (domain d)) (define (domain e))"])
def test_malformed_domain_is_a_domain_error(text: str) -> None:
    with pytest.raises(DomainError, match="x.pddl"):
        domain_without(text, (), source="x.pddl")


# --------------------------------------------------------------------------- solving one cell


def test_a_crashing_solve_is_an_error_cell(tmp_path: Path) -> None:
    job = _Job("tip", "ghost", str(tmp_path / "missing.toml"), str(LDHP), _actions(LDHP), None)
    cell = _solve_job(job)
    assert not cell.feasible and cell.status == "error" and "missing.toml" in cell.reason


# --------------------------------------------------------------------------- end to end


@pytest.fixture(scope="module")
def pick_table() -> AblationTable:
    """The pick example without air-move and without slide, and the baseline."""
    return ablate([PICK], AblationOptions(remove=("slide", "air-move")))


def test_pick_ablation(pick_table: AblationTable) -> None:
    t = pick_table
    assert t.scenarios == ("example-pick",) and t.domain == str(LDHP)
    # rows: the baseline, then MoveObject before AdjustGrasp whatever the order asked
    assert [(r.removed, r.family) for r in t.rows] == [
        (BASELINE, None), ("air-move", Family.MOVE_OBJECT), ("slide", Family.ADJUST_GRASP)]
    base = t.cell(BASELINE, "example-pick")
    assert base.feasible and base.status == "solved" and base.reason == ""
    assert base.primitives == ("approach-contact", "air-move")
    no_air = t.cell("air-move", "example-pick")
    assert not no_air.feasible and no_air.status == "failed" and "air-move" not in no_air.primitives
    assert "no contact-state path" in no_air.reason  # the symbolic tier has nothing to move with
    assert t.feasible("slide", "example-pick")  # the pick never slides a finger


def test_table_and_csv(pick_table: AblationTable, tmp_path: Path) -> None:
    text = format_table(pick_table)
    lines = text.splitlines()
    assert "| primitive removed | example-pick |" in lines
    assert lines.index("| none (baseline) | Y |") < lines.index("| *MoveObject* | |") \
        < lines.index("| air-move | N |") < lines.index("| *AdjustGrasp* | |") < lines.index("| slide | Y |")
    rows = list(csv.reader(io.StringIO(format_csv(pick_table))))
    assert tuple(rows[0]) == CSV_COLUMNS == ("removed", "scenario", "feasible", "reason", "time_s", "status",
                                             "primitives")
    assert [r[:3] for r in rows[1:]] == [["none", "example-pick", "Y"], ["air-move", "example-pick", "N"],
                                         ["slide", "example-pick", "Y"]]
    # why a cell is not feasible, on one line (the solve's headline); empty when it is
    reasons = [r[3] for r in rows[1:]]
    assert reasons[0] == reasons[2] == "" and reasons[1].startswith("symbolic tier") and "\n" not in reasons[1]
    assert reasons[1] == " ".join(pick_table.rows[1].cells[0].reason.split())
    # the wall time of each solve, in seconds
    assert all(float(r[4]) > 0 and len(r[4].split(".")[1]) == 3 for r in rows[1:])
    # the status and the plan's primitives
    assert [r[5] for r in rows[1:]] == ["solved", "failed", "solved"]
    assert rows[1][6] == "approach-contact air-move" and rows[2][6] == ""


def test_plan_with_a_primitive_the_domain_lacks_is_refused() -> None:
    # A cell that claims the domain has only air-move: the baseline's plan, which also
    # approaches the block, must not count as feasible.
    job = _Job("approach-contact", "example-pick", str(PICK), str(LDHP), ("air-move",), None)
    cell = _solve_job(job)
    assert not cell.feasible and cell.status == "invalid" and "approach-contact" in cell.reason


def test_cli_ablate_in_worker_processes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "table3.csv"
    keep = tmp_path / "domains"
    code = main(["ablate", str(PICK), "--remove", "approach-contact", "--csv", str(out), "--jobs", "2",
                 "--keep-domains", str(keep)])
    stdout, stderr = capsys.readouterr()
    assert code == EXIT_OK
    assert "| none (baseline) | Y |" in stdout and "| approach-contact | N |" in stdout
    assert f"wrote {out}" in stdout
    assert "[2/2]" in stderr and "Traceback" not in stderr
    rows = list(csv.reader(io.StringIO(out.read_text())))
    assert rows[0] == ["removed", "scenario", "feasible", "reason", "time_s", "status", "primitives"]
    assert [r[:3] for r in rows[1:]] == [["none", "example-pick", "Y"], ["approach-contact", "example-pick", "N"]]
    assert rows[1][3] == "" and rows[2][3] and all(float(r[4]) > 0 for r in rows[1:])
    assert sorted(p.name for p in keep.iterdir()) == ["ldhp-baseline.pddl", "ldhp-without-approach-contact.pddl"]


@pytest.mark.parametrize("argv", [
    ["ablate", "no/such/scenario.toml"],
    ["ablate", str(PICK), "--remove", "lift"],
    ["ablate", str(PICK), "--domain", "no-such-domain"],
    ["ablate", str(PICK), "--jobs", "0"],
    ["ablate", str(PICK), "--timeout", "-1"],
    ["ablate", str(PICK), str(PICK)],  # two columns with the same name
    ["ablate", str(PICK), "--domain", str(REPO / "tests" / "data" / "domains" / "syntax-error.pddl")],
])
def test_cli_bad_input_exits_2(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == EXIT_BAD_INPUT
    stdout, stderr = capsys.readouterr()
    assert stdout == "" and stderr.startswith("error: ") and "Traceback" not in stderr


def test_bad_scenario_path_exits_2_before_any_solve(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ablate", str(PICK), "no/such/scenario.toml"]) == EXIT_BAD_INPUT
    _, stderr = capsys.readouterr()
    assert "no/such/scenario.toml" in stderr and "[1/" not in stderr


def test_timeout_without_planner_support_warns(caplog: pytest.LogCaptureFixture) -> None:
    # --remove of an unknown action fails after the timeout check and before any solve
    caplog.set_level(logging.WARNING, logger="ldhp_tamp.ablate")
    with pytest.raises(InputError):
        ablate([PICK], AblationOptions(timeout_s=5.0, remove=("lift",)))
    warned = any("--timeout is ignored" in r.getMessage() for r in caplog.records)
    assert warned == (not solver_has_timeout())


def test_a_solve_out_of_time_is_a_timeout_cell() -> None:
    table = ablate([PICK], AblationOptions(remove=("tip",), timeout_s=0.01))
    cells = [c for row in table.rows for c in row.cells]
    assert [(c.removed, c.feasible, c.status) for c in cells] == [(BASELINE, False, "timeout"),
                                                                  ("tip", False, "timeout")]
    text = format_table(table)
    assert "| none (baseline) | N |" in text and "- baseline, example-pick: timeout: " in text


def test_with_simulate_a_cell_is_solved_with_the_simulation_judge(monkeypatch: pytest.MonkeyPatch) -> None:
    """``simulate`` reaches the solve of every cell (``SolveOptions(simulate=True)``): a
    cell is then Y only for a plan the physics replay executes."""
    import ldhp_tamp.tamp as tamp

    seen: list[bool] = []
    real = tamp.solve

    def spy(scenario, options=tamp.SolveOptions(), progress=None):  # type: ignore[no-untyped-def]
        seen.append(options.simulate)
        return real(scenario, options, progress)

    monkeypatch.setattr(tamp, "solve", spy)
    table = ablate([PICK], AblationOptions(remove=("flip",), simulate=True))
    assert seen and all(seen)
    assert table.feasible("flip", table.scenarios[0])
