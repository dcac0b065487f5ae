"""The primitive library's Python side: implementations bound to PDDL action names.

The domain file (``domains/ldhp.pddl``) lists the primitives; :mod:`.registry` binds each
action name to its implementation and checks the two against each other before any search.
Implementations register themselves on the shared :data:`REGISTRY` when their module is
imported; the modules are imported explicitly below (no folder scanning), one line each,
as docs/extending.md describes.
"""

from ldhp_tamp.primitives.registry import (
    REGISTRY,
    ActionInfo,
    AdjustGraspPrimitive,
    Binding,
    DomainInfo,
    Family,
    MoveObjectPrimitive,
    PrimitiveRegistry,
    Sequel,
    Transition,
    admissibility_predicate,
    check_against_domain,
)

# Geometric implementations, imported explicitly so that they register on REGISTRY:
from ldhp_tamp.primitives import move_object  # noqa: E402,F401  tip, push, biplanar-slide, air-move
from ldhp_tamp.primitives import adjust_grasp  # noqa: E402,F401  open, close, pivot, slide, flip, approach-contact

__all__ = [
    "REGISTRY",
    "ActionInfo",
    "AdjustGraspPrimitive",
    "Binding",
    "DomainInfo",
    "Family",
    "MoveObjectPrimitive",
    "PrimitiveRegistry",
    "Sequel",
    "Transition",
    "admissibility_predicate",
    "check_against_domain",
]
