"""ldhp-tamp: library-driven hierarchical planning (LDHP) for non-prehensile manipulation.

Stages, in the order data flows (one module each): :mod:`~ldhp_tamp.scenario` (loading),
:mod:`~ldhp_tamp.symbolic` (PDDL problem and engines), :mod:`~ldhp_tamp.primitives`
(registry binding PDDL actions to geometric streams), the TAMP loop, and the plan writers
and validator. The geometry lives in the separate package :mod:`geometry`.
"""

__version__ = "0.1.0"
