"""Random scenarios for the fuzz tests: TOML text plus an independent verdict.

A :class:`Drawn` scenario is built from random simple polygons (convex and concave, 3 to
12 vertices, either orientation), sometimes corrupted (vertices swapped, repeated,
collinear, too few, non-finite), a table and 0 to 2 obstacles, a gripper of either model
with random (sometimes inverted or negative) ranges, friction, mass and poses resting on
the table, in the air or sunk into it. :func:`verdict` decides, without the loader, whether
``ldhp-scenario/1`` allows it, using shapely's validity and areas.

Profiles: ``HYPOTHESIS_PROFILE=quick`` (default, part of the normal test run) or ``long``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np
import shapely
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

settings.register_profile("quick", deadline=None, derandomize=True, database=None,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
settings.register_profile("long", deadline=None, max_examples=2000,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "quick")
LONG = PROFILE == "long"

#: Coordinates are rounded to this (mm), so that degenerate cases (repeated vertices,
#: collinear points) occur by chance too.
GRID = 0.1
TABLE = [[-400.0, -50.0], [400.0, -50.0], [400.0, 0.0], [-400.0, 0.0]]


@dataclass
class Drawn:
    """One random scenario: its parts (for the oracle) and its TOML text."""

    obj: list[list[float]]
    solids: list[tuple[str, list[list[float]]]]
    gripper: dict
    friction: tuple[float, float]
    mass: float | None
    start: tuple[float, float, float]
    goal: tuple[float, float, float]
    samples_per_edge: int | None = None
    notes: list[str] = field(default_factory=list)

    def toml(self) -> str:
        lines = ['format = "ldhp-scenario/1"', 'name = "fuzz"', "", "[object]", f"vertices = {_pts(self.obj)}"]
        if self.mass is not None:
            lines.append(f"mass = {_num(self.mass)}")
        for name, poly in self.solids:
            lines += ["", "[[environment.solids]]", f'name = "{name}"', f"vertices = {_pts(poly)}"]
        g = self.gripper
        lines += ["", "[gripper]", f'model = "{g["model"]}"']
        if g["model"] == "two-point":
            lines += [f"finger_radius = {_num(g['finger_radius'])}", f"spacing = {_pts([g['range']])[1:-1]}"]
        else:
            lines += [f"finger = {_pts(g['finger'])}", f"opening = {_pts([g['range']])[1:-1]}"]
        lines += ["", "[friction]", f"environment = {_num(self.friction[0])}", f"gripper = {_num(self.friction[1])}",
                  "", "[task]", f"start = [{', '.join(map(_num, self.start))}]",
                  f"goal = [{', '.join(map(_num, self.goal))}]"]
        if self.samples_per_edge is not None:
            lines += ["", "[planner]", f"samples_per_edge = {self.samples_per_edge}"]
        return "\n".join(lines) + "\n"


def _num(x: float) -> str:
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return repr(float(x))


def _pts(points: list[list[float]]) -> str:
    return "[" + ", ".join(f"[{', '.join(map(_num, p))}]" for p in points) + "]"


def _round(points: np.ndarray) -> list[list[float]]:
    return [[round(float(c) / GRID) * GRID if math.isfinite(c) else float(c) for c in p] for p in points]


# --------------------------------------------------------------------------- polygons


@st.composite
def simple_polygons(draw, r_min: float = 15.0, r_max: float = 60.0, n_max: int = 12) -> list[list[float]]:
    """A simple polygon of 3..n_max vertices: on a circle (convex) or at random radii
    around the origin (star-shaped, usually concave); counter-clockwise or clockwise. Every
    angular gap is below 180 degrees, so the polygon is simple before rounding."""
    n = draw(st.integers(3, n_max))
    gaps = np.asarray(draw(st.lists(st.floats(0.5, 1.0), min_size=n, max_size=n)))
    angles = np.cumsum(gaps / gaps.sum() * 2 * math.pi) + draw(st.floats(0.0, 2 * math.pi))
    if draw(st.booleans()):
        radii = np.full(n, draw(st.floats(r_min, r_max)))
    else:
        radii = np.asarray(draw(st.lists(st.floats(r_min, r_max), min_size=n, max_size=n)))
    pts = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
    if draw(st.booleans()):
        pts = pts[::-1]
    return _round(pts)


@st.composite
def polygons(draw, valid_only: bool = False, **kw) -> list[list[float]]:
    """A simple polygon, or (unless ``valid_only``) one corrupted in a random way."""
    poly = draw(simple_polygons(**kw))
    how = "none" if valid_only else draw(st.sampled_from(
        ["none", "none", "none", "swap", "repeat", "collinear", "few", "nonfinite"]))
    if how == "swap" and len(poly) >= 4:
        i = draw(st.integers(0, len(poly) - 1))
        j = (i + draw(st.integers(2, len(poly) - 2))) % len(poly)
        poly[i], poly[j] = poly[j], poly[i]
    elif how == "repeat":
        k = draw(st.integers(0, len(poly) - 1))
        poly.insert(draw(st.integers(0, len(poly))), list(poly[k]))
    elif how == "collinear":
        t = draw(st.lists(st.floats(-50, 50), min_size=3, max_size=6, unique=True))
        poly = _round(np.column_stack([np.asarray(t), 0.5 * np.asarray(t) + 3.0]))
    elif how == "few":
        poly = poly[:draw(st.integers(1, 2))]
    elif how == "nonfinite":
        poly[draw(st.integers(0, len(poly) - 1))][draw(st.integers(0, 1))] = draw(
            st.sampled_from([math.inf, -math.inf, math.nan]))
    return poly


def _resting_y(obj: list[list[float]], theta_deg: float) -> float | None:
    """The y that puts the object's lowest point at the table top (y = 0)."""
    v = np.asarray(obj, dtype=float)
    if not np.isfinite(v).all():
        return None
    t = math.radians(theta_deg)
    return float(-(np.sin(t) * v[:, 0] + np.cos(t) * v[:, 1]).min())


@st.composite
def poses(draw, obj: list[list[float]], valid_only: bool) -> tuple[float, float, float]:
    """A pose over the table: resting on it, in the air, or (unless ``valid_only``) sunk."""
    theta = float(draw(st.integers(-180, 180)))
    x = draw(st.floats(-150.0, 150.0))
    rest = _resting_y(obj, theta)
    base = 0.0 if rest is None else rest
    kinds = ["rest", "air"] if valid_only else ["rest", "air", "sunk"]
    kind = draw(st.sampled_from(kinds))
    gap = {"rest": 0.0, "air": draw(st.floats(2.0, 120.0)), "sunk": -draw(st.floats(3.0, 30.0))}[kind]
    return (x, base + gap, theta)


@st.composite
def scenarios(draw, valid_only: bool = False) -> Drawn:
    """A random scenario; with ``valid_only``, nothing is corrupted on purpose (obstacles
    may still overlap the object: filter with :func:`verdict`)."""
    bad = not valid_only
    obj = draw(polygons(valid_only=valid_only))
    solids = [("table", TABLE)]
    for k in range(draw(st.integers(0, 2))):
        poly = np.asarray(draw(polygons(valid_only=valid_only, r_min=10.0, r_max=40.0, n_max=8)), dtype=float)
        centre = (draw(st.floats(-300.0, 300.0)), draw(st.floats(0.0, 250.0)))
        solids.append((f"obstacle-{k + 1}", _round(poly + np.asarray(centre))))
    if draw(st.booleans()):
        radius = draw(st.floats(-2.0 if bad else 1.0, 10.0))
        lo = draw(st.floats(-10.0 if bad else 2 * radius + 1.0, 120.0))
        hi = draw(st.floats(-10.0 if bad else lo, 200.0))
        gripper = {"model": "two-point", "finger_radius": radius, "range": [round(lo, 1), round(hi, 1)]}
    else:
        lo = draw(st.floats(-10.0 if bad else 0.0, 60.0))
        hi = draw(st.floats(-10.0 if bad else lo, 200.0))
        w, h = draw(st.floats(4.0, 15.0)), draw(st.floats(20.0, 60.0))
        finger = [[0.0, 0.0], [round(w, 1), 0.0], [round(w, 1), round(h, 1)], [0.0, round(h, 1)]]
        gripper = {"model": "polyline", "finger": finger, "range": [round(lo, 1), round(hi, 1)]}
    friction = (draw(st.floats(-0.2 if bad else 0.0, 1.0)), draw(st.floats(-0.2 if bad else 0.05, 1.0)))
    mass = draw(st.one_of(st.none(), st.floats(-1.0 if bad else 0.1, 3.0)))
    start = draw(poses(obj, valid_only))
    if draw(st.booleans()):  # a lift: the goal is the start, raised
        goal = (start[0], start[1] + draw(st.floats(20.0, 150.0)), start[2])
    else:
        goal = draw(poses(obj, valid_only))
    samples = draw(st.one_of(st.none(), st.integers(0, 12000))) if bad else draw(st.integers(4, 24))
    return Drawn(obj, solids, gripper, friction, mass, start, goal, samples)


# --------------------------------------------------------------------------- the oracle


class Ambiguous(Exception):
    """An overlap too close to the 1 mm tolerance to call independently."""


def _polygon_ok(points: list[list[float]]) -> bool:
    v = np.asarray(points, dtype=float)
    if len(v) < 3 or not np.isfinite(v).all():
        return False
    if len({(x, y) for x, y in v.tolist()}) < len(v):
        return False
    poly = shapely.Polygon(v)
    return bool(poly.is_valid) and poly.area > 0


def _placed(obj: list[list[float]], pose: tuple[float, float, float]) -> shapely.Polygon:
    x, y, theta = pose
    t = math.radians(theta)
    v = np.asarray(obj, dtype=float)
    rot = np.column_stack([math.cos(t) * v[:, 0] - math.sin(t) * v[:, 1],
                           math.sin(t) * v[:, 0] + math.cos(t) * v[:, 1]])
    return shapely.Polygon(rot + np.asarray([x, y]))


def _overlaps(a: shapely.Polygon, b: shapely.Polygon) -> bool:
    """Whether ``a`` and ``b`` overlap by more than the spec's 1 mm: yes if the overlap
    holds a disc of radius 1.5 mm, no if it holds none of 0.5 mm; else :class:`Ambiguous`."""
    inter = shapely.intersection(a, b)
    if inter.area < 1e-6:
        return False
    if not shapely.buffer(inter, -1.5).is_empty:
        return True
    if shapely.buffer(inter, -0.5).is_empty:
        return False
    raise Ambiguous


def verdict(d: Drawn) -> list[str]:
    """The reasons ``ldhp-scenario/1`` refuses ``d`` (empty: it must load).

    Raises
    ------
    Ambiguous
        When an overlap is within tolerance of the limit.
    """
    why = []
    if not _polygon_ok(d.obj):
        why.append("object polygon")
    for name, poly in d.solids:
        if not _polygon_ok(poly):
            why.append(f"solid {name} polygon")
    g = d.gripper
    lo, hi = g["range"]
    if lo < 0 or hi < 0 or lo > hi:
        why.append("gripper range")
    if g["model"] == "two-point" and not g["finger_radius"] > 0:
        why.append("finger radius")
    if g["model"] == "polyline" and not _polygon_ok(g["finger"]):
        why.append("finger polygon")
    if min(d.friction) < 0:
        why.append("friction")
    if d.mass is not None and not d.mass > 0:
        why.append("mass")
    if d.samples_per_edge is not None and not 2 <= d.samples_per_edge <= 10000:
        why.append("samples_per_edge")
    if not why:  # the overlap rule needs valid polygons
        for end, pose in (("start", d.start), ("goal", d.goal)):
            placed = _placed(d.obj, pose)
            for name, poly in d.solids:
                if _overlaps(placed, shapely.Polygon(poly)):
                    why.append(f"{end} overlaps {name}")
        # no start_grasp is drawn: a start that touches no solid (within 1 mm) would fall
        gap = min(shapely.distance(_placed(d.obj, d.start), shapely.Polygon(poly)) for _, poly in d.solids)
        if abs(gap - 1.0) < 0.05:
            raise Ambiguous
        if gap > 1.0:
            why.append("start touches nothing")
    return why
