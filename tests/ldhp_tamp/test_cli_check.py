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
from ldhp_tamp.cli import EXIT_BAD_INPUT, EXIT_OK, main

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
