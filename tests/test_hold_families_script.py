"""``benchmarks/hold_families.py``: the least friction of a two-finger hold, and the
families at a pose (the statics behind task 1's 60 degree analysis in docs/design.md).
The script is not a module of the package: it is imported by path."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "benchmarks" / "hold_families.py"


@pytest.fixture(scope="module")
def script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("ldhp_hold_families_script", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_a_level_pinch_needs_the_weight_over_twice_the_force_limit(script: ModuleType) -> None:
    """Two fingers squeezing a block's sides level with its centre of mass: friction
    carries the weight, W/2 per finger, so the least mu is W / (2 f_max) at the force
    limit."""
    q = np.array([[-20.0, 0.0], [20.0, 0.0]])
    n = np.array([[1.0, 0.0], [-1.0, 0.0]])
    mu, f1, f2 = script.least_mu(q, n, np.zeros(2), weight=5.0, max_force=50.0)
    assert mu == pytest.approx(5.0 / 100.0, rel=1e-3)
    assert f1 == pytest.approx(50.0, rel=1e-3) and f2 == pytest.approx(50.0, rel=1e-3)


def test_a_cradle_of_two_inclined_normals_needs_no_friction(script: ModuleType) -> None:
    """A V cradle under the centre of mass (normals 45 degrees either side of up)
    balances the weight with normal forces alone; the same fingers pressing down from
    above hold only with friction beyond 1 (the tangential force must exceed the
    normal one)."""
    s = np.sqrt(0.5)
    q = np.array([[-10.0, -10.0], [10.0, -10.0]])
    mu, _, _ = script.least_mu(q, np.array([[s, s], [-s, s]]), np.zeros(2), weight=5.0, max_force=125.0)
    assert mu < 1e-3
    mu, _, _ = script.least_mu(-q, np.array([[s, -s], [-s, -s]]), np.zeros(2), weight=5.0, max_force=125.0)
    assert mu == pytest.approx(1.0 + 5.0 / (2.0 * s * 125.0), rel=1e-3)


def test_task1_at_60_degrees_has_its_tipping_pinch_at_the_edge_of_friction(script: ModuleType) -> None:
    lines = script.families(REPO / "scenarios" / "task1_zero_mobility_lift.toml", None, 300)
    rows = {line.split("|")[1].strip(): float(line.split("|")[3]) for line in lines[3:]}
    assert rows["l1, l2"] < 0.02  # the cradle
    wedge = min(v for k, v in rows.items() if set(k.split(", ")) in ({"l2", "l4"}, {"l2", "v4"}))
    assert 0.18 < wedge <= 0.2
