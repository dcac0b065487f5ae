"""The geometric backend's compiled kernels (``geometry/_kernels.c``), where they are built.

numpy decides every check of the backend; a few checks whose numpy form is bound by
memory traffic also have a compiled twin in the C extension ``geometry._kernels`` that
makes the same floating-point operations in the same order, and so the same decisions
(``docs/design/mechanics.md``, "The compiled kernel"):

- the cone test and the fused feasibility test (:mod:`geometry.mechanics`);
- the exact-sign overlap of strictly convex parts with a target (:mod:`geometry.collision`);
- the principal-contact tests of the object's features against the environment's
  (:mod:`geometry.contacts`).

:data:`KERNELS` is the extension module, or ``None``: where pip found no C compiler
(the installation goes on without it), where ``LDHP_TAMP_PURE_NUMPY`` is set to anything
but ``0`` (to compare the two), or where the built extension is of another interface
version than :data:`API` (an editable installation not rebuilt after a pull: a warning
says so). The callers fall back to numpy whenever it is ``None``.
"""

from __future__ import annotations

import importlib
import logging
import os
from types import ModuleType

logger = logging.getLogger(__name__)

#: The interface version of ``geometry/_kernels.c`` that this package calls (its ``API``).
API: int = 4

#: Set to anything but ``0`` to leave the compiled kernels out.
PURE_NUMPY_ENV: str = "LDHP_TAMP_PURE_NUMPY"


def load() -> ModuleType | None:
    """The extension module, or ``None`` where it is not to be used (module docstring)."""
    return load_extension("geometry._kernels", API)


def load_extension(name: str, api: int) -> ModuleType | None:
    """The compiled extension module ``name`` (a dotted name) of interface version ``api``,
    or ``None``: where it was not built, where ``LDHP_TAMP_PURE_NUMPY`` is set to anything
    but ``0``, or where the built module is of another version (a warning says so). The
    planner's own compiled passes (``ldhp_tamp._search``) are loaded by this rule too."""
    if os.environ.get(PURE_NUMPY_ENV, "") not in ("", "0"):
        return None
    try:
        module = importlib.import_module(name)
    except ImportError:  # an installation without a C compiler: numpy computes alone
        return None
    if getattr(module, "API", None) != api:
        logger.warning("%s is out of date (interface %s, this code needs %s); numpy computes until it is "
                       "rebuilt (pip install -e .)", getattr(module, "__file__", name),
                       getattr(module, "API", None), api)
        return None
    return module


KERNELS: ModuleType | None = load()
