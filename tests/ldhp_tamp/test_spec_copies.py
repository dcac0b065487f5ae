"""The spec examples under tests/data/spec are exact copies of ../shared/spec/examples."""

from __future__ import annotations

from pathlib import Path

import pytest

from ldhp_tamp import resources

COPIES = Path(__file__).resolve().parents[1] / "data" / "spec"
SHARED = Path(__file__).resolve().parents[3] / "shared" / "spec" / "examples"


@pytest.mark.parametrize("name", ["pick.toml", "pick-plan.json", "pick-plan-invalid.json"])
def test_copy_matches_the_shared_spec(name: str) -> None:
    if not SHARED.is_dir():
        pytest.skip("../shared is not beside this checkout")
    assert (COPIES / name).read_bytes() == (SHARED / name).read_bytes()


def test_shipped_example_scenario_is_the_spec_example() -> None:
    assert (resources.scenarios_dir() / "example_pick.toml").read_bytes() == (COPIES / "pick.toml").read_bytes()
