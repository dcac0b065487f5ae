"""Where the shipped data lives: ``domains/`` and ``scenarios/``.

In a source checkout (and an editable install) they are top-level folders beside the
``ldhp_tamp`` package; ``pip install .`` copies them into the package as
``ldhp_tamp/domains`` and ``ldhp_tamp/scenarios`` (see ``pyproject.toml``).
"""

from __future__ import annotations

from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def data_dir(name: str) -> Path:
    """The folder holding the shipped ``domains`` or ``scenarios``."""
    for candidate in (_PACKAGE / name, _PACKAGE.parent / name):
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(f"shipped data folder {name!r} not found next to {_PACKAGE}")


def domains_dir() -> Path:
    return data_dir("domains")


def scenarios_dir() -> Path:
    return data_dir("scenarios")
