"""The engine names known without importing unified-planning agree with unified-planning's."""

from __future__ import annotations

import subprocess
import sys

from ldhp_tamp import symbolic
from ldhp_tamp.engine_names import ONESHOT_PLANNERS, installed_planners


def test_the_installed_planners_are_unified_plannings_one_shot_engines() -> None:
    assert set(installed_planners()) == set(symbolic.available_engines())
    assert "pyperplan" in installed_planners()


def test_each_entry_is_imported_from_the_package_unified_planning_names() -> None:
    from unified_planning.engines.factory import DEFAULT_ENGINES

    for name, package in ONESHOT_PLANNERS.items():
        assert DEFAULT_ENGINES[name][0].split(".")[0] == package, name


def test_loading_a_scenario_does_not_import_unified_planning() -> None:
    code = ("import sys; from ldhp_tamp.resources import scenarios_dir; from ldhp_tamp.scenario import load_scenario; "
            "load_scenario(scenarios_dir() / 'example_pick.toml'); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('unified_planning', 'ConfigSpace', 'scipy', 'matplotlib', 'mujoco', 'cvxpy')))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert run.stdout.strip() == "[]"
