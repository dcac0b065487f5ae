"""Which planning engines are installed, answered without importing unified-planning.

unified-planning finds its engines by importing every package its factory knows
(``unified_planning.engines.factory.DEFAULT_ENGINES``), and its ``Environment`` does that
on creation: over a second of imports (ConfigSpace, scipy.stats), more than the rest of a
scenario's loading. The scenario loader only asks whether the engine a scenario names is
installed, and most scenarios name ``pyperplan``: this module answers from unified-planning's
own table of one-shot planners and the package providing each, found with
:func:`importlib.util.find_spec` (which locates a package without importing it).

A name it does not know is refused without unified-planning too when no unified-planning
configuration file exists (:func:`known_planners`); where one does, the loader asks
unified-planning itself (:func:`ldhp_tamp.symbolic.available_engines`), which also knows
engines configured in it. ``tests/ldhp_tamp/test_engine_names.py`` checks that the table
agrees with unified-planning's on the installed engines and on the package of every entry.

:func:`recorded_kind` answers the other question asked before a search, whether the engine
supports the domain's problem kind, from :data:`SUPPORTED_KINDS`: each engine's
``supported_kind()`` as recorded from one release of its package. It is used only while
the installed release is that one and no unified-planning configuration file
(:func:`config_files`) may redefine the engine; otherwise :mod:`ldhp_tamp.symbolic` asks
the engine. ``ldhp-tamp check`` thereby makes every check of a solve without importing the
engines (0.8 s: ``unified_planning.engines`` imports ConfigSpace, hence scipy.stats).

>>> "pyperplan" in installed_planners()
True
"""

from __future__ import annotations

import functools
import importlib.metadata
import importlib.util
import os
import sys
from dataclasses import dataclass
from pathlib import PurePath

__all__ = ["ONESHOT_PLANNERS", "SUPPORTED_KINDS", "RecordedKind", "config_files", "installed_planners",
           "installed_releases", "known_planners", "recorded_kind"]

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


def known_planners() -> tuple[str, ...] | None:
    """The one-shot planners unified-planning's engine factory has, or ``None`` when only
    unified-planning can tell: a configuration file (:func:`config_files`) may add or
    redefine engines. Otherwise the factory has the planners of its table whose package
    imports, i.e. :func:`installed_planners` (a package that is found but fails to import
    is the one difference)."""
    if any(os.path.isfile(f) for f in config_files()):
        return None
    return installed_planners()


@dataclass(frozen=True)
class RecordedKind:
    """An engine's ``supported_kind()``, as one release of its package declares it.

    Attributes
    ----------
    distribution, release
        The package (as pip names it) and the release it was recorded from.
    version, features
        The ``ProblemKind``'s version and features: the engine supports a problem kind
        ``k`` when ``k <= ProblemKind(features, version)`` (its ``supports``).
    """

    distribution: str
    release: str
    version: int
    features: frozenset[str]


_PYPERPLAN = frozenset({"ACTION_BASED", "FLAT_TYPING", "HIERARCHICAL_TYPING", "PLAN_LENGTH"})
_FAST_DOWNWARD_OPT = frozenset({
    "ACTION_BASED", "FLAT_TYPING", "HIERARCHICAL_TYPING", "NEGATIVE_CONDITIONS", "DISJUNCTIVE_CONDITIONS",
    "EXISTENTIAL_CONDITIONS", "UNIVERSAL_CONDITIONS", "EQUALITIES", "ACTIONS_COST", "PLAN_LENGTH",
    "STATIC_FLUENTS_IN_ACTIONS_COST", "INT_NUMBERS_IN_ACTIONS_COST"})
_FAST_DOWNWARD = _FAST_DOWNWARD_OPT | {
    "CONDITIONAL_EFFECTS", "STATIC_FLUENTS_IN_BOOLEAN_ASSIGNMENTS", "FLUENTS_IN_BOOLEAN_ASSIGNMENTS",
    "FORALL_EFFECTS"}

#: The supported problem kinds of the planners this project uses, recorded from
#: up-pyperplan 1.1.0 and up-fast-downward 1.0.0 (``tests/ldhp_tamp/test_engine_names.py``
#: compares them with the installed engines' own). Another release is asked directly.
SUPPORTED_KINDS: dict[str, RecordedKind] = {
    "pyperplan": RecordedKind("up-pyperplan", "1.1.0", 2, _PYPERPLAN),
    "pyperplan-opt": RecordedKind("up-pyperplan", "1.1.0", 2, _PYPERPLAN),
    "fast-downward": RecordedKind("up-fast-downward", "1.0.0", 2, _FAST_DOWNWARD),
    "fast-downward-opt": RecordedKind("up-fast-downward", "1.0.0", 2, _FAST_DOWNWARD_OPT),
}


def recorded_kind(engine: str) -> RecordedKind | None:
    """The recorded supported kind of ``engine``, or ``None`` when it must be asked.

    ``None`` when the engine is not in :data:`SUPPORTED_KINDS`, its package is not
    installed or is another release than the recorded one, or a unified-planning
    configuration file exists (it may redefine the engine; :func:`known_planners`).
    """
    kind = SUPPORTED_KINDS.get(engine)
    if kind is None or engine not in (known_planners() or ()) or _release(kind.distribution) != kind.release:
        return None
    return kind


def installed_releases() -> dict[str, str | None]:
    """The installed release of each recorded engine's distribution (``None``: not
    installed), read once a process (:mod:`ldhp_tamp.solver_preload` reads them before a
    sweep's cells solve)."""
    return {kind.distribution: _release(kind.distribution) for kind in SUPPORTED_KINDS.values()}


@functools.cache  # the release whose code this process imports, if it imports it at all
def _release(distribution: str) -> str | None:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


def config_files() -> list[str]:
    """The files unified-planning's engine factory reads its configuration from.

    ``up.ini`` and ``.up.ini`` in every folder above the program's outermost frame's file
    (the script that was run), then ``~/up.ini``, ``~/.up.ini`` and ``~/.uprc``: the
    list of ``unified_planning.engines.factory.get_possible_config_locations``, which
    cannot be imported without the engines.
    """
    frame = sys._getframe()
    while frame.f_back is not None:
        frame = frame.f_back
    files = []
    for folder in PurePath(os.path.abspath(frame.f_code.co_filename)).parents:
        files += [os.path.join(folder, "up.ini"), os.path.join(folder, ".up.ini")]
    home = os.path.expanduser("~")
    return files + [os.path.join(home, name) for name in ("up.ini", ".up.ini", ".uprc")]
