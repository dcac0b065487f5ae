"""Which planning engines are installed, answered without importing unified-planning.

unified-planning finds its engines by importing every package its factory knows
(``unified_planning.engines.factory.DEFAULT_ENGINES``), and its ``Environment`` does that
on creation: over a second of imports (ConfigSpace, scipy.stats), more than the rest of a
scenario's loading. The scenario loader only asks whether the engine a scenario names is
installed, and most scenarios name ``pyperplan``: this module answers from unified-planning's
own table of one-shot planners and the package providing each, found with
:func:`importlib.util.find_spec` (which locates a package without importing it).

A name it does not know is not refused here: the loader then asks unified-planning itself
(:func:`ldhp_tamp.symbolic.available_engines`), which also knows engines configured in a
``.uprc`` file. ``tests/ldhp_tamp/test_engine_names.py`` checks that the table agrees with
unified-planning's on the installed engines and on the package of every entry.

>>> "pyperplan" in installed_planners()
True
"""

from __future__ import annotations

import importlib.util

__all__ = ["ONESHOT_PLANNERS", "installed_planners"]

#: unified-planning's one-shot planning engines (the planners of its factory's
#: ``DEFAULT_ENGINES``; not its anytime planners, validators or compilers) and the
#: top-level package each is imported from.
ONESHOT_PLANNERS: dict[str, str] = {
    "aries": "up_aries",
    "enhsp": "up_enhsp",
    "enhsp-opt": "up_enhsp",
    "fast-downward": "up_fast_downward",
    "fast-downward-opt": "up_fast_downward",
    "fmap": "up_fmap",
    "lpg": "up_lpg",
    "pyperplan": "up_pyperplan",
    "pyperplan-opt": "up_pyperplan",
    "symk": "up_symk",
    "symk-opt": "up_symk",
    "tamer": "up_tamer",
}


def installed_planners() -> tuple[str, ...]:
    """The names of :data:`ONESHOT_PLANNERS` whose package is installed, sorted."""
    found: dict[str, bool] = {}
    for package in ONESHOT_PLANNERS.values():
        if package not in found:
            try:
                found[package] = importlib.util.find_spec(package) is not None
            except (ImportError, ValueError):
                found[package] = False
    return tuple(sorted(name for name, package in ONESHOT_PLANNERS.items() if found[package]))
