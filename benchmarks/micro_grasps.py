"""Speed of the grasp candidate sets: enumeration, G_T and G_m (``geometry/grasps.py``).

Worlds mirror the paper's tasks: the 70 x 150 mm block standing on a table, gripped by

- ``two-point``: Configuration I of task 1, finger radius 5 mm, spacing fixed at 90 mm;
- ``polyline``: Configuration II of task 2, 12 x 45 mm fingertips, opening 0..140 mm;
- ``polyline+palm``: the same with a 190 x 20 mm palm above the fingers.

Measured at K = 100 samples per edge (the paper's value): the enumeration, G_T at the
start pose (block on the table) and G_m for a 40 mm lift off the table in 4 mm steps
(11 samples, candidates = G_T at both ends), reported per sample. Times are the best of
``repeats`` runs.

Run::

    .venv/bin/python benchmarks/micro_grasps.py
    .venv/bin/python benchmarks/micro_grasps.py --k 50 --repeats 3
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from geometry.grasps import GraspOptions, enumerate_grasps, motion_conditioned, pose_conditioned
from geometry.shapes import make_polygon
from geometry.world import Environment, Friction, PolylineGripper, Solid, TwoPointGripper, World, make_object

BLOCK = [[0, 0], [70, 0], [70, 150], [0, 150]]
TABLE = [[500, 0], [-500, 0], [-500, -100], [500, -100]]
FINGER = [[0, 0], [12, 0], [12, 45], [0, 45]]
PALM = [[-95, 45], [95, 45], [95, 65], [-95, 65]]


def worlds() -> dict[str, World]:
    """The benchmark worlds by name."""
    env = Environment((Solid("table", make_polygon(TABLE)),))
    obj = make_object(BLOCK, mass=0.5)
    finger = make_polygon(FINGER)
    grippers = {
        "two-point": TwoPointGripper(5.0, (90.0, 90.0)),
        "polyline": PolylineGripper(finger, (0.0, 140.0)),
        "polyline+palm": PolylineGripper(finger, (0.0, 140.0), make_polygon(PALM)),
    }
    return {name: World(obj, env, g, Friction(0.3, 0.6)) for name, g in grippers.items()}


def _best(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    best, out = float("inf"), None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def run(k: int = 100, repeats: int = 5) -> dict[str, dict[str, float | int]]:
    """Measure every world; returns ``{world: {figure: value}}`` (times in ms)."""
    lift = np.stack([np.zeros(11), np.arange(11) * 4.0, np.zeros(11)], axis=1)
    out: dict[str, dict[str, float | int]] = {}
    for name, world in worlds().items():
        opts = GraspOptions(samples_per_edge=k)
        t_enum, gs = _best(lambda: enumerate_grasps(world, opts), repeats)
        t_gt, g_t = _best(lambda: pose_conditioned(world, gs, lift[0]), repeats)
        cand = np.intersect1d(g_t, pose_conditioned(world, gs, lift[-1]))
        t_gm, g_m = _best(lambda: motion_conditioned(world, gs, lift, cand), max(1, repeats // 2))
        out[name] = {
            "grasps": len(gs),
            "two_finger": int((gs.n_touching == 2).sum()),
            "one_finger": int((gs.n_touching == 1).sum()),
            "enumerate_ms": 1e3 * t_enum,
            "g_t_size": int(g_t.size),
            "g_t_ms": 1e3 * t_gt,
            "g_m_candidates": int(cand.size),
            "g_m_size": len(g_m),
            "g_m_checks": g_m.checks,
            "g_m_ms": 1e3 * t_gm,
            "g_m_ms_per_sample": 1e3 * t_gm / lift.shape[0],
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--k", type=int, default=100, help="samples per edge (default 100)")
    ap.add_argument("--repeats", type=int, default=5, help="best of this many runs (default 5)")
    ap.add_argument("--json", action="store_true", help="print the raw dict as JSON")
    args = ap.parse_args()
    res = run(args.k, args.repeats)
    if args.json:
        print(json.dumps(res, indent=1))
        return
    print(f"K = {args.k}; times in ms (best of {args.repeats})")
    head = f"{'world':<15}{'grasps':>8}{'2-finger':>10}{'1-finger':>10}{'enum':>8}{'|G_T|':>7}{'G_T':>7}" \
           f"{'cand':>7}{'|G_m|':>7}{'checks':>8}{'G_m':>8}{'/sample':>9}"
    print(head)
    for name, r in res.items():
        print(f"{name:<15}{r['grasps']:>8}{r['two_finger']:>10}{r['one_finger']:>10}{r['enumerate_ms']:>8.1f}"
              f"{r['g_t_size']:>7}{r['g_t_ms']:>7.1f}{r['g_m_candidates']:>7}{r['g_m_size']:>7}{r['g_m_checks']:>8}"
              f"{r['g_m_ms']:>8.1f}{r['g_m_ms_per_sample']:>9.2f}")


if __name__ == "__main__":
    main()
