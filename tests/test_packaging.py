"""pyproject.toml lists every package, so `pip install .` (not only -e) is complete."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_folder_is_listed() -> None:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts)
             for top in ("geometry", "ldhp_tamp") for p in (ROOT / top).rglob("__init__.py")}
    assert found <= listed, f"missing from pyproject.toml packages: {sorted(found - listed)}"


def test_shipped_data_is_mapped() -> None:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert config["package-dir"] == {"ldhp_tamp.domains": "domains", "ldhp_tamp.scenarios": "scenarios"}
    assert list((ROOT / "domains").glob("*.pddl")) and list((ROOT / "scenarios").glob("*.toml"))
