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
    if os.environ.get(PURE_NUMPY_ENV, "") not in ("", "0"):
        return None
    try:
        from geometry import _kernels
    except ImportError:  # an installation without a C compiler: numpy decides alone
        return None
    if getattr(_kernels, "API", None) != API:
        logger.warning("%s is out of date (interface %s, this code needs %s); numpy decides until it is "
                       "rebuilt (pip install -e .)", getattr(_kernels, "__file__", "geometry._kernels"),
                       getattr(_kernels, "API", None), API)
        return None
    return _kernels


KERNELS: ModuleType | None = load()
