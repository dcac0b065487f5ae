"""The format examples the repository holds in three places agree byte for byte.

``docs/formats/examples/`` is the documented copy (docs/formats/plan.md and scenario.md
link to it), ``tests/data/spec/`` the copy the tests read, and
``scenarios/example_pick.toml`` the shipped scenario. Everything here reads the
repository only.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from ldhp_tamp import resources

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs" / "formats" / "examples"
TESTS = REPO / "tests" / "data" / "spec"
NAMES = ("pick.toml", "pick-plan.json", "pick-plan-invalid.json")


def test_the_two_folders_hold_the_same_files() -> None:
    assert sorted(p.name for p in DOCS.iterdir()) == sorted(p.name for p in TESTS.iterdir()) == sorted(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_the_documented_example_is_the_tested_one(name: str) -> None:
    assert (DOCS / name).read_bytes() == (TESTS / name).read_bytes()


def test_shipped_example_scenario_is_the_documented_example() -> None:
    assert (resources.scenarios_dir() / "example_pick.toml").read_bytes() == (DOCS / "pick.toml").read_bytes()
