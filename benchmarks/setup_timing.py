"""Time of a solve's setup: the contact states and the admissible transitions (issue 17).

For each scenario (default: task 2 and task 1 at 70 degrees), ``--repeat`` times in one
process: :func:`ldhp_tamp.contact_graph.build_context` (the workspace, the contact poses,
the contact-state enumeration) and :func:`~ldhp_tamp.contact_graph.admissible_transitions`
(the sweeps of every MoveObject action, on the machine's cores as the solve runs them),
with the grasp set enumerated once beforehand as the solve does (the air-move's lifts ask
it for carriers; its enumeration is not timed here). The first run of each is a warm-up
and not counted. Prints the median and the fastest run of each part (wall time), the CPU
time of both (this process and the forked children: steadier than the wall time on a
loaded machine), the machine's load before and after, and exits 0. Run::

    PYTHONPATH=. .venv/bin/python benchmarks/setup_timing.py [--repeat 7] [SCENARIO...]

``PYTHONPATH`` chooses the code measured (another checkout for a before/after comparison).
"""

from __future__ import annotations

import argparse
import logging
import os
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DEFAULT = ("scenarios/task2_slot_insertion.toml", "scenarios/task1_zero_mobility_lift_tilt70.toml")


def _cpu() -> float:
    """CPU time (s) of this process and its reaped children (the transitions' forks)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenarios", nargs="*", default=list(DEFAULT))
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    logging.disable(logging.WARNING)

    from geometry.grasps import GraspOptions, enumerate_grasps
    from ldhp_tamp.contact_graph import admissible_transitions, build_context
    from ldhp_tamp.primitives import REGISTRY
    from ldhp_tamp.scenario import load_scenario
    from ldhp_tamp.symbolic import load_checked_domain
    from ldhp_tamp.tamp import EDGE_OFFSET_RANGE
    import geometry

    print(f"code: {Path(geometry.__file__).resolve().parent.parent}; load {os.getloadavg()[0]:.2f}")
    for name in args.scenarios:
        path = Path(name) if Path(name).exists() else ROOT / name
        sc = load_scenario(path)
        st = sc.settings
        world = sc.world
        if st.friction_margin > 0:
            world = replace(world, friction=world.friction.scaled(1.0 - st.friction_margin))
        domain = load_checked_domain(st.domain_path or st.domain, st.engine, REGISTRY, load_engine=False)
        rng, _ = (np.random.default_rng(s) for s in np.random.SeedSequence(st.seed).spawn(2))
        offsets = tuple(float(u) for u in rng.uniform(*EDGE_OFFSET_RANGE, size=world.object.n))
        grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=st.samples_per_edge, edge_offsets=offsets))
        ctx_t: list[float] = []
        tr_t: list[float] = []
        cpu: list[float] = []
        for k in range(args.repeat + 1):
            c0 = _cpu()
            t0 = time.perf_counter()
            ctx = build_context(world, sc.start, sc.goal)
            t1 = time.perf_counter()
            transitions = admissible_transitions(replace(ctx, grasps=grasps), domain.info, REGISTRY)
            t2 = time.perf_counter()
            if k:
                ctx_t.append(t1 - t0)
                tr_t.append(t2 - t1)
                cpu.append(_cpu() - c0)
        total = [a + b for a, b in zip(ctx_t, tr_t)]
        n_tr = sum(len(v) for v in transitions.values())
        print(f"{path.name}: {len(ctx.states)} states, {n_tr} transitions; median (fastest) of {args.repeat}: "
              f"build_context {statistics.median(ctx_t):.3f} ({min(ctx_t):.3f}) s, "
              f"admissible_transitions {statistics.median(tr_t):.3f} ({min(tr_t):.3f}) s, "
              f"both {statistics.median(total):.3f} ({min(total):.3f}) s; CPU time (children included) "
              f"{statistics.median(cpu):.3f} ({min(cpu):.3f}) s", flush=True)
    print(f"load {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
