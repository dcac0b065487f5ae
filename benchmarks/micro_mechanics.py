"""Micro-benchmark of the quasi-static feasibility checks (geometry.mechanics).

Measures checks per second (of the best call) of the fast batched path
(``feasible_batch``) for 2, 3, 4 and 6 contacts, all STICKING (two generators each: the worst case for a given contact count),
called on batches of 100,000 instances: with the compiled kernel (``geometry/_kernels.c``,
where it is built) and with numpy alone (the same rule), and of the reference path
(``feasible_reference``, cvxpy + Clarabel, one instance per call). Run::

    .venv/bin/python benchmarks/micro_mechanics.py [seconds]
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

import geometry.mechanics as mechanics
from geometry.mechanics import ContactMode, Contacts, feasible_batch, feasible_reference

BATCH = 100_000


def random_contacts(rng: np.random.Generator, batch: int, count: int) -> tuple[Contacts, np.ndarray, float]:
    """Contacts on a ring of radius 30..50 mm around the COM, normals roughly inward."""
    ang = rng.uniform(0.0, 2.0 * np.pi, (batch, count))
    rad = rng.uniform(30.0, 50.0, (batch, count))
    pts = np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=-1)
    phi = ang + np.pi + rng.uniform(-1.0, 1.0, (batch, count))
    nrm = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    mu = rng.uniform(0.02, 1.0, (batch, count))
    return Contacts.make(pts, nrm, mu, ContactMode.STICKING), np.zeros(2), 50.0


def _rate(fn, per_call: int, seconds: float) -> float:
    """Checks per second of the fastest call in ``seconds`` (the machine is shared: the
    best call is the one least disturbed by other processes)."""
    fn()  # warm up (caches, lazy imports, allocator)
    best = math.inf
    t_end = time.perf_counter() + seconds
    while True:
        t0 = time.perf_counter()
        fn()
        t1 = time.perf_counter()
        best = min(best, t1 - t0)
        if t1 >= t_end:
            return per_call / best


def run(seconds: float = 2.0) -> dict[str, float]:
    """Checks per second, keyed ``fast_C`` (C contacts; the compiled kernel where it is
    built), ``numpy_C`` (numpy alone) and ``reference_C``.

    ``seconds`` is split evenly between the measurements.
    """
    rng = np.random.default_rng(0)
    counts = (2, 3, 4, 6)
    share = seconds / (3 * len(counts))
    out: dict[str, float] = {}
    kernel = mechanics._kernels
    for c in counts:
        contacts, com, L = random_contacts(rng, BATCH, c)
        out[f"fast_{c}"] = _rate(lambda: feasible_batch(contacts, com, L), BATCH, share)
        try:
            mechanics._kernels = None
            out[f"numpy_{c}"] = _rate(lambda: feasible_batch(contacts, com, L), BATCH, share)
        finally:
            mechanics._kernels = kernel
        singles = [contacts.select(slice(i, i + 1)) for i in range(200)]
        it = iter(range(10**9))
        out[f"reference_{c}"] = _rate(lambda: feasible_reference(singles[next(it) % 200], com, L), 1, share)
        out[f"feasible_share_{c}"] = float(feasible_batch(contacts, com, L).mean())
    return out


def main(argv: list[str]) -> None:
    seconds = float(argv[1]) if len(argv) > 1 else 2.0
    r = run(seconds)
    built = "compiled kernel" if mechanics._kernels is not None else "numpy: kernel not built"
    print(f"fast path: {built}")
    print(f"{'contacts':>8} {'fast checks/s':>15} {'numpy checks/s':>15} {'reference checks/s':>19} {'feasible':>9}")
    for c in (2, 3, 4, 6):
        print(f"{c:>8} {r[f'fast_{c}']:>15,.0f} {r[f'numpy_{c}']:>15,.0f} {r[f'reference_{c}']:>19,.0f}"
              f" {r[f'feasible_share_{c}']:>9.2f}")


if __name__ == "__main__":
    main(sys.argv)
