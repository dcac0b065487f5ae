"""The planner's compiled array passes (``ldhp_tamp/_search.c``), where they are built.

:data:`SEARCH` is the extension module ``ldhp_tamp._search`` of interface version
:data:`SEARCH_API`, or ``None`` (not built, ``LDHP_TAMP_PURE_NUMPY`` set, or built from
other sources: :func:`geometry.compiled.load_extension`); its callers compute the same
arrays with numpy then. The grasp graph's Bellman-Ford rounds and counting order
and the layer graphs' order and edge selection (:mod:`ldhp_tamp.grasp_graph`) and the
AdjustGrasp primitives' selection of a layer's
candidate edges from their tables of pairs (:mod:`ldhp_tamp.primitives.adjust_grasp`)
call it; each pass gives numpy's result bit for bit (``tests/ldhp_tamp/test_search_kernels.py``).
"""

from __future__ import annotations

import numpy as np

from types import ModuleType
from typing import Sequence

from numpy.typing import ArrayLike, NDArray

from geometry.compiled import load_extension
from geometry.poses import IntArray

#: The interface version of ``ldhp_tamp/_search.c`` this package calls (its ``API``).
SEARCH_API = 5
#: The module, or ``None``: numpy computes the same arrays.
SEARCH = load_extension("ldhp_tamp._search", SEARCH_API)


def csr(keys: IntArray, size: int) -> tuple[IntArray, IntArray]:
    """The stable order of ``keys`` (in [0, size)) and where each key's run starts in it
    (``size + 1`` offsets), both int32: one counting pass in the compiled module, else
    numpy's argsort as 16-bit keys when they fit, which it sorts by radix (10x faster on a
    layer's 300,000 slides), and a binary search."""
    k = np.ascontiguousarray(keys, dtype=np.int64)
    if k.size > np.iinfo(np.int32).max or size > np.iinfo(np.int32).max:
        raise ValueError(f"{k.size} edges among {size} grasps: the search indexes them with 32 bits")
    if SEARCH is not None:
        order, starts = np.empty(k.size, dtype=np.int32), np.empty(size + 1, dtype=np.int32)
        SEARCH.counting_order(k, order, starts)
        return order, starts
    order = np.argsort(k.astype(np.uint16) if size <= np.iinfo(np.uint16).max + 1 and k.size else k, kind="stable")
    return order.astype(np.int32), np.searchsorted(k[order], np.arange(size + 1)).astype(np.int32)


def by_source(srcs: Sequence[ArrayLike], dsts: Sequence[ArrayLike], values: Sequence[ArrayLike], size: int,
              module: ModuleType | None = SEARCH
              ) -> tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.int32], NDArray[np.float64]]:
    """Edges given in parts (each part's sources, destinations and a value per edge, the
    parts' edges numbered one after the other) in one order by source, stably: the index
    of the edge at each position, where each source's run starts (``size + 1``), and the
    destinations (int32) and values in that order. ``module``: the compiled module, whose
    ``layer_order`` makes them in one counting pass without concatenating the parts (the
    caller's, so that a test can leave it out); ``None``: numpy concatenates them and
    takes them in the order of :func:`csr`."""
    n = sum(int(np.shape(x)[0]) for x in srcs)
    if module is not None:
        order, starts, dst, out = (np.empty(n, np.int32), np.empty(size + 1, np.int32), np.empty(n, np.int32),
                                   np.empty(n))
        module.layer_order(tuple(np.ascontiguousarray(x, dtype=np.int64) for x in srcs),
                           tuple(np.ascontiguousarray(x, dtype=np.int64) for x in dsts),
                           tuple(np.ascontiguousarray(x, dtype=float) for x in values), order, starts, dst, out)
        return order, starts, dst, out

    def cat(parts: Sequence[ArrayLike], dtype: type) -> NDArray:
        return np.concatenate([np.asarray(x, dtype=dtype) for x in parts] + [np.zeros(0, dtype)])

    order, starts = csr(cat(srcs, np.int64), size)
    return order, starts, cat(dsts, np.int64)[order].astype(np.int32), cat(values, float)[order]
