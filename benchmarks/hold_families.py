"""Every hold of a two-point gripper on the object at one pose in the air, by family.

The statics behind ``docs/design.md`` ("Results on the paper's tasks", task 1 at 60
degrees): with the gripper's two round fingers at a fixed spacing ``s`` (centre to
centre; the range's maximum for a gripper that opens), the placements are the pinches of
:func:`geometry.grasps.enumerate_grasps` (finger 1 on every contact sample, the corners'
normals included; finger 2 wherever a centre ``s`` away touches the object).
For each placement the two contact forces (normal + tangential, the normal along the
line from the finger's centre to its contact) and the weight at the centre of mass give
three equations in four unknowns; along the one free internal force the script finds
the least friction coefficient

    mu* = min over t of max(|f_t1| / f_n1, |f_t2| / f_n2),  0 < f_n1, f_n2 <= max_force,

at which the placement holds the object still. The placements with ``mu* <= mu`` (the
scenario's gripper coefficient) are grouped by the features touched (edges ``l``,
vertices ``v``, the scenario's names) and printed with the least ``mu*`` of the family
and the range of each contact along its edge, in the object frame::

    .venv/bin/python benchmarks/hold_families.py scenarios/task1_zero_mobility_lift.toml
    .venv/bin/python benchmarks/hold_families.py scenarios/task1_zero_mobility_lift.toml --theta -70

Pure statics of a rigid hold: whether a plan can reach a family is the planner's
business (and the design notes'). Exit status 0, or 2 on bad input.
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

from dataclasses import replace

import numpy as np

from geometry.grasps import GraspOptions, enumerate_grasps
from geometry.poses import Pose
from geometry.world import TwoPointGripper
from ldhp_tamp.errors import LdhpError
from ldhp_tamp.scenario import feature_names, load_scenario

def _interval(rows: list[tuple[float, float]]) -> tuple[float, float]:
    """The set of t with a + b t <= 0 for every (a, b), as (lo, hi) (empty if lo > hi)."""
    lo, hi = -np.inf, np.inf
    for a, b in rows:
        if abs(b) < 1e-15:
            if a > 1e-12:
                return np.inf, -np.inf
        elif b > 0:
            hi = min(hi, -a / b)
        else:
            lo = max(lo, -a / b)
    return lo, hi


def least_mu(q: np.ndarray, n: np.ndarray, com: np.ndarray, weight: float, max_force: float
             ) -> tuple[float, float, float]:
    """(mu*, f_n1, f_n2) of two contacts (points ``q``, unit normals ``n`` into the object)
    holding the weight at ``com`` (world frame, N and mm); ``inf`` if no internal force
    puts both normal forces in (0, max_force]. Exact up to the bisection's 1e-9: along
    the free internal force ``t`` every force is affine, so each bound is a half-line."""
    t = np.stack([-n[:, 1], n[:, 0]], axis=1)
    r = q - com

    def moment(p: np.ndarray, v: np.ndarray) -> float:
        return float(p[0] * v[1] - p[1] * v[0])

    a = np.array([[n[0, 0], t[0, 0], n[1, 0], t[1, 0]],
                  [n[0, 1], t[0, 1], n[1, 1], t[1, 1]],
                  [moment(r[0], n[0]), moment(r[0], t[0]), moment(r[1], n[1]), moment(r[1], t[1])]])
    rhs = np.array([0.0, weight, 0.0])
    x0 = np.linalg.lstsq(a, rhs, rcond=None)[0]
    if np.abs(a @ x0 - rhs).max() > 1e-6 * max(1.0, weight):
        return np.inf, np.nan, np.nan
    null = np.linalg.svd(a)[2][-1]
    eps = 1e-9 * max(1.0, weight)
    # normal forces in [eps, max_force]
    base = [(eps - x0[i], -null[i]) for i in (0, 2)] + [(x0[i] - max_force, null[i]) for i in (0, 2)]

    def feasible(mu: float) -> tuple[float, float]:
        rows = list(base)
        for fn, ft in ((0, 1), (2, 3)):  # |f_t| <= mu f_n, both signs
            for sign in (1.0, -1.0):
                rows.append((sign * x0[ft] - mu * x0[fn], sign * null[ft] - mu * null[fn]))
        return _interval(rows)

    lo_mu, hi_mu = 0.0, 1e3
    lo, hi = feasible(hi_mu)
    if lo > hi:
        return np.inf, np.nan, np.nan
    for _ in range(100):
        mid = 0.5 * (lo_mu + hi_mu)
        lo, hi = feasible(mid)
        if lo <= hi:
            hi_mu = mid
        else:
            lo_mu = mid
        if hi_mu - lo_mu < 1e-9:
            break
    lo, hi = feasible(hi_mu)
    x = x0 + 0.5 * (lo + hi) * null
    return hi_mu, float(x[0]), float(x[2])


def families(path: Path, theta_deg: float | None, samples: int, corner_normals: int = 60) -> list[str]:
    """The table's lines: the families of holds at the scenario's goal pose (or the goal
    turned to ``theta_deg``), over the pinches :func:`geometry.grasps.enumerate_grasps`
    gives at the gripper's widest spacing (``samples`` contact samples per edge,
    ``corner_normals`` per convex corner)."""
    scenario = load_scenario(path)
    world = scenario.world
    grip = world.gripper
    if not isinstance(grip, TwoPointGripper):
        raise LdhpError(f"{path}: the hold families are for the two-point gripper model")
    spacing = float(max(grip.spacing))
    rigid = replace(world, gripper=replace(grip, spacing=(spacing, spacing)))
    gs = enumerate_grasps(rigid, GraspOptions(samples_per_edge=samples, vertex_fan=corner_normals, orientations=0))
    pinches = np.flatnonzero(gs.n_touching == 2)
    theta = scenario.goal.theta if theta_deg is None else np.radians(theta_deg)
    turn = Pose(0.0, 0.0, float(theta))  # a translation changes nothing
    com = turn.apply(world.object.com)
    weight = world.object.weight
    mu_g = float(world.friction.gripper)
    max_force = float(grip.max_force) if grip.max_force is not None else 1e6
    names = feature_names(scenario)
    n = gs.n_object

    def name(f: int) -> str:
        return names.object_edges[f] if f < n else names.object_vertices[f - n]

    fams: dict[tuple[str, str], list[tuple[float, np.ndarray, np.ndarray]]] = defaultdict(list)
    for g in pinches:
        mu, _, _ = least_mu(turn.apply(gs.contact[g]), turn.apply_vector(gs.normal[g]), com, weight, max_force)
        if mu <= mu_g:
            fams[(name(gs.feature[g, 0]), name(gs.feature[g, 1]))].append((mu, gs.contact[g, 0], gs.contact[g, 1]))
    out = [f"{scenario.name}: object at theta = {np.degrees(theta):.1f} degrees in the air; fingers "
           f"r = {float(grip.finger_radius):g} mm, {spacing:g} mm apart; weight {weight:.3f} N; mu_g = {mu_g:g}; at most "
           f"{max_force:g} N per finger; {len(pinches)} placements ({samples} samples per edge, {corner_normals} per corner)",
           "| family (finger 1, finger 2) | placements | least mu | finger 1 contact (object frame) | finger 2 contact |",
           "| --- | ---: | ---: | --- | --- |"]
    for key in sorted(fams, key=lambda k: min(m[0] for m in fams[k])):
        rows = fams[key]
        c1, c2 = np.stack([r[1] for r in rows]), np.stack([r[2] for r in rows])
        span = lambda p: f"({p.min(0)[0]:.1f}, {p.min(0)[1]:.1f}) - ({p.max(0)[0]:.1f}, {p.max(0)[1]:.1f})"  # noqa: E731
        out.append(f"| {key[0]}, {key[1]} | {len(rows)} | {min(r[0] for r in rows):.4f} | {span(c1)} | {span(c2)} |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario", type=Path, help="scenario TOML (two-point gripper); the pose is its goal")
    ap.add_argument("--theta", type=float, default=None, help="the object's angle instead of the goal's (degrees)")
    ap.add_argument("--samples", type=int, default=1000, help="finger contact samples per object edge")
    args = ap.parse_args(argv)
    try:
        lines = families(args.scenario, args.theta, args.samples)
    except (LdhpError, OSError) as exc:
        print(f"hold_families: {exc}", file=sys.stderr)
        return 2
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
