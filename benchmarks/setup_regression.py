"""The setup's results on every shipped scenario, recorded and compared (issue 17).

The setup of a solve (:func:`ldhp_tamp.contact_graph.build_context` and
:func:`~ldhp_tamp.contact_graph.admissible_transitions`, as :func:`ldhp_tamp.tamp.solve`
calls them) is made faster without changing what it computes. This script records, for
every ``scenarios/*.toml`` (or the files given), what the setup computes:

- the workspace, the contact poses T'_0 and T'_g (pose, state, travel);
- the enumerated contact states (:func:`geometry.contacts.enumerate_contact_states`, all
  their witness poses) and the states kept (:func:`~ldhp_tamp.contact_graph.proper_states`);
- the admissible transitions of every MoveObject action of the scenario's domain;
- every sweep the transitions make (``tip``, ``push``, ``biplanar-slide``: one per
  witness pose and motion family, at the transitions' step and precision) and the same
  motion swept as the streams sweep it (the defaults): its pieces (state, s0, s1), why it
  ended and its end pose.

``record FILE`` writes them as JSON (floats as Python writes them: exact); ``check FILE``
computes them again and compares: states, names and ends exactly, numbers to ``--atol``
(default 1e-9; exact equality is reported separately). Exit status 1 on any difference.
The reference of a change is recorded with the code before it, e.g. main's::

    mkdir /tmp/before && git archive main | tar -x -C /tmp/before
    PYTHONPATH=/tmp/before .venv/bin/python benchmarks/setup_regression.py record /tmp/setup_ref.json.gz
    PYTHONPATH=. .venv/bin/python benchmarks/setup_regression.py check /tmp/setup_ref.json.gz

The grasp set (which the air-move's lifts and placements ask for a carrier) is enumerated
at the scenario's seed and K, as the solve does.
"""

from __future__ import annotations

import argparse
import gzip
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _pose(p: Any) -> list[float]:
    return [float(p.x), float(p.y), float(p.theta)]


def _sweep_record(sw: Any) -> dict[str, Any]:
    return {"end": sw.end.value,
            "pieces": [[pc.state.name, float(pc.s0), float(pc.s1)] for pc in sw.pieces],
            "end_pose": [float(v) for v in sw.motion.poses([sw.s_end])[0]]}


def _motion_record(m: Any) -> dict[str, Any]:
    return {"kind": m.kind.value, "start": _pose(m.start), "sense": m.sense,
            "pivot": list(m.pivot) if m.pivot is not None else None,
            "direction": list(m.direction) if m.direction is not None else None,
            "kept": [c.name for c in m.kept]}


def setup_record(path: Path, sweeps: bool = True) -> dict[str, Any]:
    """What the setup computes for the scenario at ``path`` (see the module's text)."""
    from geometry.contacts import enumerate_contact_states
    from geometry.grasps import GraspOptions, enumerate_grasps
    from ldhp_tamp.contact_graph import admissible_transitions, build_context, proper_states
    from ldhp_tamp.primitives import REGISTRY
    from ldhp_tamp.primitives.move_object import TRANSITION_STEP_MM
    from ldhp_tamp.primitives.registry import Family
    from ldhp_tamp.scenario import load_scenario
    from ldhp_tamp.symbolic import load_checked_domain
    from ldhp_tamp.tamp import EDGE_OFFSET_RANGE
    from geometry.kinematics import sweep

    scenario = load_scenario(path)
    settings = scenario.settings
    world = scenario.world
    if settings.friction_margin > 0:
        world = replace(world, friction=world.friction.scaled(1.0 - settings.friction_margin))
    domain = load_checked_domain(settings.domain_path or settings.domain, settings.engine, REGISTRY,
                                 load_engine=False)
    ctx = build_context(world, scenario.start, scenario.goal)
    grasp_rng, _ = (np.random.default_rng(s) for s in np.random.SeedSequence(settings.seed).spawn(2))
    offsets = tuple(float(u) for u in grasp_rng.uniform(*EDGE_OFFSET_RANGE, size=world.object.n))
    grasps = enumerate_grasps(world, GraspOptions(samples_per_edge=settings.samples_per_edge, edge_offsets=offsets))
    ctx = replace(ctx, grasps=grasps)
    enumerated = enumerate_contact_states(world, ctx.workspace, max_contacts=3)
    kept = proper_states(world, enumerated)
    transitions = admissible_transitions(ctx, domain.info, REGISTRY)
    out: dict[str, Any] = {
        "workspace": [ctx.workspace.xmin, ctx.workspace.ymin, ctx.workspace.xmax, ctx.workspace.ymax,
                      [list(s) for s in ctx.workspace.seeds]],
        "contact_poses": [[_pose(c.pose), c.state.name, float(c.travel), list(c.direction) if c.direction else None]
                          for c in (ctx.start_contact, ctx.goal_contact)],
        "enumerated": [[w.state.name, [_pose(p) for p in w.witnesses]] for w in enumerated],
        "kept": [[w.state.name, [_pose(p) for p in w.witnesses]] for w in kept],
        "context_witnesses": [[w.state.name, [_pose(p) for p in w.witnesses]] for w in ctx.witnesses],
        "states": [s.name for s in ctx.states],
        "transitions": {name: sorted([a.name, b.name] for a, b in pairs) for name, pairs in sorted(transitions.items())},
        "sweeps": [],
    }
    if sweeps:
        for b in REGISTRY.bound(domain.info, Family.MOVE_OBJECT):
            impl = b.implementation
            if not hasattr(impl, "families"):
                continue
            for state in ctx.states:
                if state.is_free:
                    continue
                for pose in ctx.witness_poses(state):
                    for motion, s_max, params in impl.families(ctx, pose):
                        rec = {"action": b.name, "state": state.name, "motion": _motion_record(motion),
                               "s_max": float(s_max), "params": json.loads(json.dumps(params))}
                        rec["transition"] = _sweep_record(sweep(world, motion, s_max, step_mm=TRANSITION_STEP_MM,
                                                                refine_bits=10))
                        rec["stream"] = _sweep_record(sweep(world, motion, s_max))
                        out["sweeps"].append(rec)
    return out


class _Diff:
    """Differences between two records: structure and text exactly, numbers to ``atol``."""

    def __init__(self, atol: float) -> None:
        self.atol = atol
        self.max_num = 0.0  # the largest difference between two numbers
        self.inexact = 0  # numbers that differ at all
        self.problems: list[str] = []

    def compare(self, a: Any, b: Any, where: str) -> None:
        if isinstance(a, bool) or isinstance(b, bool) or a is None or b is None or isinstance(a, str):
            if a != b:
                self.problems.append(f"{where}: {a!r} != {b!r}")
        elif isinstance(a, (int, float)) and isinstance(b, (int, float)):
            if a == b or (math.isnan(a) and math.isnan(b)):
                return
            d = abs(a - b) if math.isfinite(a) and math.isfinite(b) else math.inf
            self.inexact += 1
            self.max_num = max(self.max_num, d)
            if not d <= self.atol:
                self.problems.append(f"{where}: {a!r} != {b!r}")
        elif isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                self.problems.append(f"{where}: {len(a)} items != {len(b)}")
                return
            for k, (x, y) in enumerate(zip(a, b)):
                self.compare(x, y, f"{where}[{k}]")
        elif isinstance(a, dict) and isinstance(b, dict):
            if set(a) != set(b):
                self.problems.append(f"{where}: keys {sorted(set(a) ^ set(b))} differ")
            for k in sorted(set(a) & set(b)):
                self.compare(a[k], b[k], f"{where}.{k}")
        else:
            self.problems.append(f"{where}: {type(a).__name__} != {type(b).__name__}")


def _open(path: Path, mode: str):  # type: ignore[no-untyped-def]
    return gzip.open(path, mode + "t") if path.suffix == ".gz" else open(path, mode)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("what", choices=("record", "check"))
    ap.add_argument("file", type=Path, help="the reference (.json or .json.gz)")
    ap.add_argument("scenarios", nargs="*", type=Path, help="default: scenarios/*.toml")
    ap.add_argument("--atol", type=float, default=1e-9)
    ap.add_argument("--no-sweeps", action="store_true", help="states and transitions only")
    args = ap.parse_args(argv)
    import logging
    logging.disable(logging.WARNING)
    paths = args.scenarios or sorted((ROOT / "scenarios").glob("*.toml"))
    if args.what == "record":
        data = {}
        for p in paths:
            t0 = time.perf_counter()
            data[p.name] = setup_record(p, not args.no_sweeps)
            print(f"{p.name}: {len(data[p.name]['states'])} states, "
                  f"{sum(len(v) for v in data[p.name]['transitions'].values())} transitions, "
                  f"{len(data[p.name]['sweeps'])} sweeps ({time.perf_counter() - t0:.1f} s)", flush=True)
        with _open(args.file, "w") as fh:
            json.dump(data, fh)
        return 0
    with _open(args.file, "r") as fh:
        ref = json.load(fh)
    failed = 0
    for p in paths:
        if p.name not in ref:
            print(f"{p.name}: not in the reference")
            failed += 1
            continue
        got = setup_record(p, not args.no_sweeps)
        want = ref[p.name]
        if args.no_sweeps:
            want = dict(want, sweeps=[])
        d = _Diff(args.atol)
        d.compare(want, got, p.name)
        status = "same" if not d.problems and not d.inexact else (
            f"same to {args.atol:g} ({d.inexact} numbers differ, at most {d.max_num:.3g})" if not d.problems
            else f"DIFFERENT ({len(d.problems)} differences)")
        print(f"{p.name}: {status}", flush=True)
        for line in d.problems[:10]:
            print("   ", line)
        failed += bool(d.problems)
    print(f"{len(paths) - failed} of {len(paths)} scenarios as recorded")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
