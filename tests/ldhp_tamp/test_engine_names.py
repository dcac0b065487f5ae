"""The engine names and supported kinds known without importing unified-planning's engines agree
with what the engines say."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ldhp_tamp import engine_names, symbolic
from ldhp_tamp.engine_names import (
    ONESHOT_PLANNERS,
    SUPPORTED_KINDS,
    config_files,
    installed_planners,
    recorded_kind,
)
from ldhp_tamp.errors import InputError

DATA = Path(__file__).resolve().parents[2] / "tests" / "data"


def _skip_if_configured() -> None:
    """A unified-planning configuration file on this machine (up.ini, ~/.uprc) sends every
    engine question to unified-planning: the fast answers cannot be compared."""
    if any(Path(f).is_file() for f in config_files()):
        pytest.skip("a unified-planning configuration file exists on this machine")


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


# --------------------------------------------------------------------------- recorded supported kinds


def _engine_class(name: str):  # noqa: ANN202 - an Engine subclass
    import importlib

    from unified_planning.engines.factory import DEFAULT_ENGINES

    module, cls = DEFAULT_ENGINES[name]
    return getattr(importlib.import_module(module), cls)


def _kinds_to_compare():  # noqa: ANN202 - ProblemKinds
    """Every one-feature kind, and the kinds of the shipped and test domains."""
    from unified_planning.model import ProblemKind
    from unified_planning.model.problem_kind import all_features

    from ldhp_tamp.resources import domains_dir

    kinds = [ProblemKind({f}) for f in sorted(all_features)]
    for path in [*domains_dir().glob("*.pddl"), *(DATA / "domains").glob("*.pddl")]:
        try:
            kinds.append(symbolic.load_domain(path).kind)
        except InputError:  # the test domains that do not load
            pass
    return kinds


@pytest.mark.parametrize("engine", sorted(SUPPORTED_KINDS))
def test_a_recorded_kind_is_the_installed_engines_own(engine: str) -> None:
    if engine not in installed_planners():
        pytest.skip(f"{SUPPORTED_KINDS[engine].distribution} is not installed")
    _skip_if_configured()
    recorded = SUPPORTED_KINDS[engine]
    # re-record SUPPORTED_KINDS from the installed release when it changes, or check pays 0.8 s
    assert recorded_kind(engine) == recorded, f"installed {recorded.distribution} is not {recorded.release}"
    cls = _engine_class(engine)
    own = cls.supported_kind()
    assert (own.version, own.features) == (recorded.version, recorded.features)
    from unified_planning.model import ProblemKind

    as_recorded = ProblemKind(recorded.features, recorded.version)
    for kind in _kinds_to_compare():  # its supports() is the comparison with its supported kind
        assert cls.supports(kind) == (kind <= as_recorded), sorted(kind.features)


def test_no_recorded_kind_for_another_release_or_a_configuration_file(monkeypatch: pytest.MonkeyPatch,
                                                                      tmp_path: Path) -> None:
    _skip_if_configured()
    assert recorded_kind("pyperplan") is not None
    assert recorded_kind("no-such-engine") is None
    monkeypatch.setattr(engine_names, "_release", lambda distribution: "0.0.1")
    assert recorded_kind("pyperplan") is None
    monkeypatch.undo()
    config = tmp_path / ".uprc"
    config.write_text("[engine pyperplan]\nmodule_name: elsewhere\nclass_name: Other\n")
    monkeypatch.setattr(engine_names, "config_files", lambda: [str(tmp_path / "up.ini"), str(config)])
    assert recorded_kind("pyperplan") is None


def test_the_installed_releases_are_importlib_metadatas() -> None:
    """``installed_releases``: for each recorded engine's distribution, the installed
    release (``None`` where it is not installed), as ``recorded_kind`` compares them."""
    import importlib.metadata

    got = engine_names.installed_releases()
    assert set(got) == {kind.distribution for kind in engine_names.SUPPORTED_KINDS.values()}
    for name, release in got.items():
        try:
            want = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            want = None
        assert release == want
    assert got["up-pyperplan"] is not None  # the default engine is installed


def test_the_configuration_files_are_those_unified_planning_reads() -> None:
    from unified_planning.engines.factory import get_possible_config_locations

    assert config_files() == get_possible_config_locations()


def test_the_known_planners_are_unified_plannings_unless_a_configuration_file_exists(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    _skip_if_configured()
    assert engine_names.known_planners() == symbolic.available_engines()
    config = tmp_path / "up.ini"
    config.write_text("[engine warp-drive]\nmodule_name: warp\nclass_name: Drive\n")
    monkeypatch.setattr(engine_names, "config_files", lambda: [str(config)])
    assert engine_names.known_planners() is None


def test_an_unknown_engine_is_refused_without_importing_unified_planning() -> None:
    _skip_if_configured()
    bad = DATA / "scenarios" / "bad" / "unknown_engine.toml"
    code = ("import sys; from ldhp_tamp.errors import ScenarioError; from ldhp_tamp.scenario import load_scenario\n"
            f"try:\n    load_scenario({str(bad)!r})\nexcept ScenarioError as exc:\n    print(exc)\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('unified_planning', 'ConfigSpace', 'scipy')))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    message, imported = run.stdout.strip().splitlines()
    assert message == (f"{bad}: planner.engine: unknown engine 'warp-drive' "
                       f"(installed: {', '.join(symbolic.available_engines())})")
    assert imported == "[]"
