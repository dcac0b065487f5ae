"""What a sweep's worker processes load once, before their first cell.

``ldhp-tamp bench`` and ``ldhp-tamp ablate`` run each cell in a process forked from a
forkserver that has imported the modules of their :class:`ldhp_tamp.sweep.CellTask`
``preload`` (:mod:`ldhp_tamp.sweep`). This module is one of them: importing it imports the
planner and makes the symbolic tier's engines ready (unified-planning's engine factory,
which imports every installed engine and with them ConfigSpace and scipy.stats: about
0.8 s, and 0.1 s to make the factory), as :func:`ldhp_tamp.symbolic.load_checked_domain`
would in each cell's solve, and builds unified-planning's PDDL grammar (0.02 s, as the
first parse would) and streamlines it with a parse of a small domain (pyparsing does that
in a process's first parse: 14 ms). It also reads the installed engines' releases
(``importlib.metadata``, which :func:`ldhp_tamp.engine_names.recorded_kind` compares with
the recorded ones: 3-6 ms with its import of the email parser) and imports
``multiprocessing.connection``, through whose pipes the solve talks to its helper process
(2 ms). A cell's ``time_s`` then counts the solve, not these imports, as it counts no
other import (``docs/benchmarks.md``, "The paper's tasks").

``ldhp-tamp solve`` does not import it: there the engines are made while the solve loads,
and ``time_s`` counts from the command's start anyway.
"""

from __future__ import annotations

import contextlib
import multiprocessing.connection  # noqa: F401  (the helper process's pipes)

import ldhp_tamp.tamp  # noqa: F401  (the planner)
from ldhp_tamp import engine_names, symbolic

with contextlib.suppress(Exception):  # an engine that fails to load fails the solve that uses it, with its message
    symbolic.available_engines()
symbolic.prepare_pddl_reader()  # unified-planning's PDDL grammar, built and streamlined once
engine_names.installed_releases()  # read once, before the cells (importlib.metadata)
