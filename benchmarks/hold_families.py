"""Every hold of a two-point gripper on the object at one pose in the air, by family.

The statics behind ``docs/design.md`` ("Results on the paper's tasks", task 1 at 60
degrees): with the gripper's two round fingers at a fixed spacing ``s`` (centre to
centre; the range's maximum for a gripper that opens), finger 1's centre walks the
object's offset curve (distance ``r``, the finger radius: every placement that touches,
the corners included), finger 2's centre is every point of that curve at distance ``s``.
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

import numpy as np
import shapely

from geometry.world import TwoPointGripper
from ldhp_tamp.errors import LdhpError
from ldhp_tamp.scenario import feature_names, load_scenario

def _feature(poly: np.ndarray, point: np.ndarray, tol: float = 1e-6) -> tuple[str, int]:
    """('v', j) if ``point`` is vertex j, else ('l', i) for the nearest edge i."""
    d_v = np.linalg.norm(poly - point, axis=1)
    if d_v.min() <= tol:
        return "v", int(np.argmin(d_v))
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.clip(np.sum((point - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0.0, 1.0)
    return "l", int(np.argmin(np.linalg.norm(a + t[:, None] * ab - point, axis=1)))


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


def families(path: Path, theta_deg: float | None, samples: int) -> list[str]:
    scenario = load_scenario(path)
    world = scenario.world
    grip = world.gripper
    if not isinstance(grip, TwoPointGripper):
        raise LdhpError(f"{path}: the hold families are for the two-point gripper model")
    pose = scenario.goal.as_array().copy()
    if theta_deg is not None:
        pose[2] = np.radians(theta_deg)
    c, s_ = np.cos(pose[2]), np.sin(pose[2])
    rot = np.array([[c, -s_], [s_, c]])
    obj = world.object.polygon.vertices
    poly = obj @ rot.T  # world frame, about the object's origin (a translation changes nothing)
    com = world.object.com @ rot.T
    weight = world.object.weight
    mu_g = float(world.friction.gripper)
    max_force = float(grip.max_force) if grip.max_force is not None else 1e6
    radius, spacing = float(grip.finger_radius), float(max(grip.spacing))
    shape = shapely.Polygon(poly)
    curve = shape.buffer(radius, quad_segs=256).exterior
    pts = np.array(shapely.get_coordinates(shapely.line_interpolate_point(
        curve, np.linspace(0.0, 1.0, samples, endpoint=False), normalized=True)))
    boundary = shape.exterior
    names = feature_names(scenario)

    def contact(centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = np.array(shapely.get_coordinates(boundary.interpolate(boundary.project(shapely.Point(centre))))[0])
        return q, (q - centre) / np.linalg.norm(q - centre)

    fams: dict[tuple[str, str], list[tuple[float, np.ndarray, np.ndarray, float, float]]] = defaultdict(list)
    for i in range(samples):
        d = np.linalg.norm(pts - pts[i], axis=1) - spacing
        for j in np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0):
            w = d[j] / (d[j] - d[j + 1])
            centres = np.stack([pts[i], pts[j] + w * (pts[j + 1] - pts[j])])
            qn = [contact(cc) for cc in centres]
            q, n = np.stack([x[0] for x in qn]), np.stack([x[1] for x in qn])
            mu, f1, f2 = least_mu(q, n, com, weight, max_force)
            if mu > mu_g:
                continue
            feats = [_feature(poly, qq) for qq in q]
            key = tuple((names.object_vertices[k] if kind == "v" else names.object_edges[k]) for kind, k in feats)
            fams[key].append((mu, q[0] @ rot, q[1] @ rot, f1, f2))  # contacts back in the object frame
    out = [f"{scenario.name}: object at theta = {np.degrees(pose[2]):.1f} degrees in the air; fingers r = {radius:g} mm, "
           f"{spacing:g} mm apart; weight {weight:.3f} N; mu_g = {mu_g:g}; at most {max_force:g} N per finger; "
           f"{samples} placements of finger 1",
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
    ap.add_argument("--samples", type=int, default=8000, help="placements of finger 1 on the offset curve")
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
