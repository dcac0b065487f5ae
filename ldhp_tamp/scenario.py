"""Scenario loading (``ldhp-scenario/1``, see ``docs/formats/scenario.md``).

Stage 1 of the pipeline: a TOML file becomes an immutable :class:`Scenario` holding the
geometric :class:`~geometry.world.World` and the task. Every refusal of the spec raises
:class:`~ldhp_tamp.errors.ScenarioError` naming the file, the key and the problem.

Keys in messages are dotted TOML paths with 0-based array indices, as in
``environment.solids[1].vertices`` or ``friction.object_edges[0].edge``. Feature names
(``v1``, ``l1``, ``e1``, ``ve1``) stay 1-based, as in the paper.

>>> s = load_scenario_string('''
... format = "ldhp-scenario/1"
... name = "doc"
... [object]
... vertices = [[0, 0], [0, 40], [100, 40], [100, 0]]   # clockwise: re-ordered
... [[environment.solids]]
... vertices = [[-300, -50], [300, -50], [300, 0], [-300, 0]]
... [gripper]
... model = "two-point"
... finger_radius = 5
... spacing = [80, 120]
... [friction]
... environment = 0.3
... gripper = 0.6
... [task]
... start = [0, 0, 0]
... goal = [0, 100, 90]
... ''', check_planner=False)
>>> s.world.object.polygon.vertices.tolist()[:2]
[[0.0, 0.0], [100.0, 0.0]]
>>> round(s.goal.theta, 6), s.world.object.mass, s.world.environment.edge_names[0]
(1.570796, 1.0, 'e1')
"""

from __future__ import annotations

import difflib
import hashlib
import logging
import math
import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import shapely

from geometry.errors import GeometryError
from geometry.poses import Pose
from geometry.shapes import Polygon, make_polygon, signed_area
from geometry.tolerances import VALIDATE_TOL
from geometry.world import (
    Environment,
    Friction,
    Gripper,
    GripperState,
    ObjectModel,
    PolylineGripper,
    Solid,
    TwoPointGripper,
    World,
)
from ldhp_tamp import resources
from ldhp_tamp.errors import ScenarioError

log = logging.getLogger(__name__)

#: The one format this loader reads.
FORMAT = "ldhp-scenario/1"

#: Gripper models of the spec: two-point (Configuration I) and polyline (Configuration II).
GRIPPER_MODELS = ("two-point", "polyline")

#: Range of ``planner.samples_per_edge`` (K of the paper), inclusive.
SAMPLES_PER_EDGE_RANGE = (2, 10000)


@dataclass(frozen=True)
class PlannerSettings:
    """The ``[planner]`` table, every key with its spec default.

    ``domain`` is the value as written (a name in ``domains/`` or a path);
    ``domain_path`` is the resolved, existing ``.pddl`` file, set by the loader. A
    hand-built ``PlannerSettings()`` has ``domain_path=None``: resolve it with
    :func:`find_domain`.
    """

    domain: str = "ldhp"
    engine: str = "pyperplan"
    samples_per_edge: int = 100
    max_top_iterations: int = 10
    max_refinements: int = 4
    seed: int = 0
    domain_path: Path | None = None
    friction_margin: float = 0.0
    """The planner plans with every coefficient scaled by ``1 - friction_margin``; plans
    are judged (validated, simulated) with the scenario's own coefficients."""


@dataclass(frozen=True, eq=False)
class Scenario:
    """One planning problem: the paper's input tuple plus planner settings."""

    name: str
    description: str
    path: Path | None
    sha256: str
    world: World
    start: Pose
    goal: Pose
    start_grasp: GripperState | None
    goal_release: bool
    settings: PlannerSettings
    start_grasp_any: bool = False
    """``start_grasp = "any"``: the object starts held by a grasp the planner chooses
    (``start_grasp`` is then ``None``)."""

    @property
    def starts_held(self) -> bool:
        """The object starts in the gripper (a given ``start_grasp`` or ``"any"``)."""
        return self.start_grasp is not None or self.start_grasp_any


@dataclass(frozen=True)
class FeatureNames:
    """The 1-based feature names of a scenario, as the paper and the plans use them."""

    object_vertices: tuple[str, ...]
    object_edges: tuple[str, ...]
    environment_edges: tuple[str, ...]
    environment_vertices: tuple[str, ...]
    #: (solid name, its edge names) in file order.
    solid_edges: tuple[tuple[str, tuple[str, ...]], ...]


# --------------------------------------------------------------------------- public API


def load_scenario(path: str | os.PathLike[str], *, check_planner: bool = True,
                  strict: bool = False) -> Scenario:
    """Load and validate a scenario file.

    Relative domain paths resolve against the file's folder. With ``check_planner=False``
    the domain and engine are not looked up (``settings.domain_path`` stays ``None``);
    the geometric checks all run. A key the format does not define is logged and ignored
    (the format allows extensions); with ``strict=True`` it is refused
    (:class:`~ldhp_tamp.errors.ScenarioError` naming it), which catches a misspelt
    optional key (``mas = 5``) that would otherwise leave its default in force.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise ScenarioError(p, None, f"cannot read the file: {exc.strerror or exc}") from None
    return _load_bytes(data, label=str(p), path=p, base_dir=p.resolve().parent,
                       check_planner=check_planner, strict=strict)


def load_scenario_string(text: str, name: str = "<string>", *,
                         base_dir: str | os.PathLike[str] | None = None,
                         check_planner: bool = True, strict: bool = False) -> Scenario:
    """Load a scenario from TOML text; ``name`` labels the error messages.

    Relative domain paths resolve against ``base_dir`` (default: the current directory).
    The sha256 is that of the UTF-8 encoded text. ``check_planner`` and ``strict`` as for
    :func:`load_scenario`.
    """
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    return _load_bytes(text.encode("utf-8"), label=name, path=None, base_dir=base,
                       check_planner=check_planner, strict=strict)


def find_domain(domain: str, relative_to: str | os.PathLike[str] | None = None) -> Path | None:
    """Resolve a ``planner.domain`` value to an existing file, or ``None``.

    A bare name (no ``/`` or ``\\``, no ``.pddl`` suffix) is ``<name>.pddl`` in
    :func:`ldhp_tamp.resources.domains_dir`; anything else is a path, relative paths
    resolving against ``relative_to`` (default: the current directory).
    """
    if _is_domain_name(domain):
        try:
            candidate = resources.domains_dir() / f"{domain}.pddl"
        except FileNotFoundError:
            return None
    else:
        candidate = Path(domain).expanduser()
        if not candidate.is_absolute():
            candidate = Path(relative_to if relative_to is not None else Path.cwd()) / candidate
    return candidate.resolve() if candidate.is_file() else None


def feature_names(scenario: Scenario) -> FeatureNames:
    """The object and environment feature names of ``scenario``."""
    env = scenario.world.environment
    solids: list[tuple[str, tuple[str, ...]]] = []
    base = 0
    for solid in env.solids:
        n = len(solid.polygon)
        solids.append((solid.name, env.edge_names[base:base + n]))
        base += n
    obj = scenario.world.object
    return FeatureNames(obj.vertex_names, obj.edge_names, env.edge_names, env.vertex_names,
                        tuple(solids))


def summarize(scenario: Scenario, contact_states: int | None = None) -> str:
    """A short multi-line, human-readable summary (what ``ldhp-tamp check`` prints)."""
    w = scenario.world
    names = feature_names(scenario)
    obj = w.object
    lines = [f"scenario {scenario.name}"
             + (f" ({scenario.path})" if scenario.path is not None else "")
             + f" sha256 {scenario.sha256[:12]}"]
    if scenario.description:
        lines.append("  " + " ".join(scenario.description.split()))
    lines.append(
        f"  object: {obj.n} vertices {_span(names.object_vertices)}, edges "
        f"{_span(names.object_edges)}; mass {_num(obj.mass)} kg; "
        f"com {_point(obj.com)} mm; area {_num(obj.polygon.area, 1)} mm^2"
    )
    solids = ", ".join(f"{n} {_span(e)}" for n, e in names.solid_edges)
    count = len(w.environment.solids)
    lines.append(f"  environment: {count} solid{'s' if count > 1 else ''}: {solids}; "
                 f"vertices {_span(names.environment_vertices)}")
    lines.append(f"  gripper: {_describe_gripper(w.gripper)}")
    lines.append(f"  friction: {_describe_friction(w.friction)}")
    lines.append(f"  start: {_pose(scenario.start)}   goal: {_pose(scenario.goal)}")
    if scenario.start_grasp is not None:
        g = scenario.start_grasp
        lines.append(f"  start grasp: gripper {_pose(g.pose)}, width {_num(g.width)} mm")
    elif scenario.start_grasp_any:
        lines.append("  start grasp: any (the planner chooses one that holds the object)")
    lines.append(f"  goal release: {'yes' if scenario.goal_release else 'no'}")
    s = scenario.settings
    domain = s.domain if s.domain_path is None else f"{s.domain} ({s.domain_path})"
    lines.append(
        f"  planner: domain {domain}, engine {s.engine}, samples_per_edge {s.samples_per_edge}, "
        f"max_top_iterations {s.max_top_iterations}, max_refinements {s.max_refinements}, "
        f"seed {s.seed}, friction_margin {_num(s.friction_margin)}"
    )
    if contact_states is not None:
        lines.append(f"  contact states: {contact_states}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- loading


_MISSING: Any = object()


@dataclass(frozen=True)
class _Reader:
    """Typed access to the parsed TOML, raising ScenarioError with dotted keys.

    ``strict``: refuse keys the format does not define instead of logging them.
    """

    label: str
    strict: bool = False

    def fail(self, key: str | None, problem: str) -> ScenarioError:
        return ScenarioError(self.label, key, " ".join(problem.split("\n")))

    def get(self, table: Mapping[str, Any], prefix: str, name: str, default: Any = _MISSING) -> Any:
        if name in table:
            return table[name]
        if default is _MISSING:
            raise self.fail(_join(prefix, name), "missing required key")
        return default

    def table(self, value: Any, key: str) -> Mapping[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(key, f"expected a table, got {_type_name(value)}")
        return value

    def array(self, value: Any, key: str) -> list[Any]:
        if not isinstance(value, list):
            raise self.fail(key, f"expected an array, got {_type_name(value)}")
        return value

    def string(self, value: Any, key: str) -> str:
        if not isinstance(value, str):
            raise self.fail(key, f"expected a string, got {_type_name(value)}")
        return value

    def boolean(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.fail(key, f"expected true or false, got {_type_name(value)}")
        return value

    def number(self, value: Any, key: str) -> float:
        # bool is a subclass of int in Python: refuse it explicitly.
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(key, f"expected a number, got {_type_name(value)}")
        x = float(value)
        if not math.isfinite(x):
            raise self.fail(key, f"expected a finite number, got {value}")
        return x

    def integer(self, value: Any, key: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, f"expected an integer, got {_type_name(value)}")
        return value

    def numbers(self, value: Any, key: str, length: int, what: str) -> tuple[float, ...]:
        arr = self.array(value, key)
        if len(arr) != length:
            raise self.fail(key, f"expected {what} ({length} numbers), got {len(arr)} element(s)")
        return tuple(self.number(v, f"{key}[{i}]") for i, v in enumerate(arr))

    def points(self, value: Any, key: str) -> list[tuple[float, ...]]:
        arr = self.array(value, key)
        return [self.numbers(v, f"{key}[{i}]", 2, "an [x, y] point") for i, v in enumerate(arr)]

    def polygon(self, value: Any, key: str, what: str | None = None) -> Polygon:
        pts = self.points(value, key)
        try:
            poly = make_polygon(pts, what=key)
        except GeometryError as exc:
            msg = str(exc)
            msg = msg[len(key) + 2:] if msg.startswith(key + ": ") else msg
            raise self.fail(key, (f"{what}: " if what else "") + msg) from None
        if signed_area(np.asarray(pts, dtype=float)) < 0:
            log.info("%s: %s: vertices are clockwise; re-ordered counter-clockwise keeping the "
                     "first vertex first (feature names follow the new order)", self.label, key)
        return poly

    def pose(self, value: Any, key: str) -> Pose:
        x, y, t = self.numbers(value, key, 3, "a pose [x, y, angle in degrees]")
        return Pose.from_degrees(x, y, t)

    def interval(self, value: Any, key: str) -> tuple[float, float]:
        lo, hi = self.numbers(value, key, 2, "a range [min, max]")
        if lo < 0 or hi < 0:
            raise self.fail(key, f"negative value in [{_num(lo)}, {_num(hi)}]")
        if lo > hi:
            raise self.fail(key, f"min {_num(lo)} is greater than max {_num(hi)}")
        return lo, hi

    def unknown_keys(self, table: Mapping[str, Any], prefix: str, known: Sequence[str],
                     note: str = "") -> None:
        """Log keys the format does not define: the format allows extensions, so by
        default they are ignored. In strict mode the first one is refused.

        A key that looks like a misspelling of an absent known key is logged as a warning
        (in strict mode, named in the refusal).
        """
        absent = [k for k in known if k not in table]
        for key in table:
            if key in known:
                continue
            close = difflib.get_close_matches(key, absent, n=1, cutoff=0.75)
            if self.strict:
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise self.fail(_join(prefix, key), f"unknown key{note} (strict mode refuses keys "
                                                    f"{FORMAT} does not define){hint}")
            if close:
                log.warning("%s: %s: unknown key ignored; did you mean %r?",
                            self.label, _join(prefix, key), close[0])
            else:
                log.info("%s: %s: unknown key ignored%s", self.label, _join(prefix, key), note)


def _load_bytes(data: bytes, *, label: str, path: Path | None, base_dir: Path,
                check_planner: bool, strict: bool = False) -> Scenario:
    r = _Reader(label, strict)
    sha = hashlib.sha256(data).hexdigest()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise r.fail(None, f"not UTF-8 text (line {line})") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise r.fail(None, f"not valid TOML: {exc}") from None

    fmt = r.string(r.get(doc, "", "format"), "format")
    if fmt != FORMAT:
        raise r.fail("format", f"unknown format {fmt!r} (expected {FORMAT!r})")
    r.unknown_keys(doc, "", ("format", "name", "description", "object", "environment",
                             "gripper", "friction", "task", "planner"))
    name = r.string(r.get(doc, "", "name"), "name")
    if not name.strip() or any(c in name for c in "/\\\0"):
        raise r.fail("name", f"{name!r} is not a usable id (empty, or contains a path separator)")
    description = r.string(r.get(doc, "", "description", ""), "description")

    obj = _read_object(r, r.table(r.get(doc, "", "object"), "object"))
    env = _read_environment(r, r.table(r.get(doc, "", "environment"), "environment"))
    gripper = _read_gripper(r, r.table(r.get(doc, "", "gripper"), "gripper"))
    friction = _read_friction(r, r.table(r.get(doc, "", "friction"), "friction"), obj, env)
    world = World(obj, env, gripper, friction)
    start, goal, start_grasp, goal_release, start_any = _read_task(
        r, r.table(r.get(doc, "", "task"), "task"), world)
    settings = _read_planner(r, r.table(r.get(doc, "", "planner", {}), "planner"), base_dir,
                             check_planner)
    scenario = Scenario(name=name, description=description, path=path, sha256=sha, world=world,
                        start=start, goal=goal, start_grasp=start_grasp,
                        goal_release=goal_release, settings=settings, start_grasp_any=start_any)
    log.debug("%s: loaded scenario %r", label, name)
    return scenario


def _read_object(r: _Reader, t: Mapping[str, Any]) -> ObjectModel:
    r.unknown_keys(t, "object", ("vertices", "com", "mass"))
    poly = r.polygon(r.get(t, "object", "vertices"), "object.vertices")
    com_raw = r.get(t, "object", "com", None)
    com = poly.centroid if com_raw is None else np.array(
        r.numbers(com_raw, "object.com", 2, "an [x, y] point"))
    mass = r.number(r.get(t, "object", "mass", 1.0), "object.mass")
    if mass < 0:
        raise r.fail("object.mass", f"negative mass {_num(mass)} kg")
    if mass == 0:
        raise r.fail("object.mass", "zero mass: the quasi-static checks balance the object's "
                                    "weight, so the mass must be positive (omit it for 1 kg)")
    if com_raw is not None and not shapely.convex_hull(poly.shapely).covers(shapely.Point(com)):
        log.warning("%s: object.com %s lies outside the object's convex hull", r.label,
                    _point(com))
    com_ro = np.array(com, dtype=float)
    com_ro.setflags(write=False)
    return ObjectModel(poly, com_ro, mass)


def _read_environment(r: _Reader, t: Mapping[str, Any]) -> Environment:
    r.unknown_keys(t, "environment", ("solids",))
    raw = r.array(r.get(t, "environment", "solids"), "environment.solids")
    if not raw:
        raise r.fail("environment.solids", "needs at least one solid")
    solids: list[Solid] = []
    for k, item in enumerate(raw):
        key = f"environment.solids[{k}]"
        st = r.table(item, key)
        r.unknown_keys(st, key, ("name", "vertices"))
        name = r.string(r.get(st, key, "name", f"solid{k + 1}"), f"{key}.name")
        poly = r.polygon(r.get(st, key, "vertices"), f"{key}.vertices", what=f"solid {name!r}")
        solids.append(Solid(name, poly))
    for i in range(len(solids)):
        for j in range(i + 1, len(solids)):
            if _overlaps(solids[i].polygon.shapely, solids[j].polygon.shapely):
                log.warning("%s: environment solids %r and %r overlap; their inner edges will "
                            "still count as contact edges", r.label, solids[i].name,
                            solids[j].name)
    return Environment(tuple(solids))


def _read_gripper(r: _Reader, t: Mapping[str, Any]) -> Gripper:
    model = r.string(r.get(t, "gripper", "model"), "gripper.model")
    if model == "two-point":
        r.unknown_keys(t, "gripper", ("model", "finger_radius", "spacing", "max_force"),
                       note=" (not used by the two-point model)")
        radius = r.number(r.get(t, "gripper", "finger_radius"), "gripper.finger_radius")
        if radius <= 0:
            raise r.fail("gripper.finger_radius", f"must be positive, got {_num(radius)}")
        spacing = r.interval(r.get(t, "gripper", "spacing"), "gripper.spacing")
        if spacing[0] < 2 * radius:
            log.warning("%s: gripper.spacing: minimum %s mm is below two finger radii (%s mm): "
                        "the fingers would overlap", r.label, _num(spacing[0]), _num(2 * radius))
        return TwoPointGripper(radius, spacing, _max_force(r, t))
    if model == "polyline":
        r.unknown_keys(t, "gripper", ("model", "finger", "opening", "palm", "max_force"),
                       note=" (not used by the polyline model)")
        finger = r.polygon(r.get(t, "gripper", "finger"), "gripper.finger")
        lo = finger.vertices.min(axis=0)
        if abs(lo[0]) > VALIDATE_TOL or abs(lo[1]) > VALIDATE_TOL:
            log.warning("%s: gripper.finger: expected the pad on x = 0 and the tip on y = 0 "
                        "(lowest x, y are %s)", r.label, _point(lo))
        opening = r.interval(r.get(t, "gripper", "opening"), "gripper.opening")
        palm_raw = r.get(t, "gripper", "palm", None)
        palm = None if palm_raw is None else r.polygon(palm_raw, "gripper.palm")
        return PolylineGripper(finger, opening, palm, _max_force(r, t))
    raise r.fail("gripper.model", f"unknown gripper model {model!r} "
                                  f"(expected one of {', '.join(map(repr, GRIPPER_MODELS))})")


def _max_force(r: _Reader, t: Mapping[str, Any]) -> float | None:
    """``gripper.max_force``: the largest normal force (N) of one finger; absent = unbounded."""
    raw = r.get(t, "gripper", "max_force", None)
    if raw is None:
        return None
    value = r.number(raw, "gripper.max_force")
    if value <= 0:
        raise r.fail("gripper.max_force", f"must be positive (newtons), got {_num(value)}")
    return value


_EDGE_NAME = {"e": re.compile(r"^e(\d+)$"), "l": re.compile(r"^l(\d+)$")}


def _edge_index(r: _Reader, value: Any, key: str, prefix: str, count: int, seen: dict[int, str]) -> int:
    name = r.string(value, key).strip().lower()
    what = "an environment edge" if prefix == "e" else "an object edge"
    m = _EDGE_NAME[prefix].match(name)
    if not m:
        raise r.fail(key, f"{value!r} is not {what} name (expected {prefix}1..{prefix}{count})")
    index = int(m.group(1)) - 1
    if not 0 <= index < count:
        raise r.fail(key, f"unknown edge {value!r}: there are {count} edges, "
                          f"{prefix}1..{prefix}{count}")
    if index in seen:
        raise r.fail(key, f"{prefix}{index + 1} is already overridden at {seen[index]}")
    seen[index] = key
    return index


def _coefficient(r: _Reader, value: Any, key: str) -> float:
    mu = r.number(value, key)
    if mu < 0:
        raise r.fail(key, f"negative friction coefficient {_num(mu)}")
    return mu


def _read_friction(r: _Reader, t: Mapping[str, Any], obj: ObjectModel, env: Environment) -> Friction:
    r.unknown_keys(t, "friction", ("environment", "gripper", "environment_edges", "object_edges"))
    mu_env = _coefficient(r, r.get(t, "friction", "environment"), "friction.environment")
    mu_grip = _coefficient(r, r.get(t, "friction", "gripper"), "friction.gripper")

    env_edges: dict[int, float] = {}
    seen: dict[int, str] = {}
    raw = r.array(r.get(t, "friction", "environment_edges", []), "friction.environment_edges")
    for k, item in enumerate(raw):
        key = f"friction.environment_edges[{k}]"
        it = r.table(item, key)
        r.unknown_keys(it, key, ("edge", "mu"))
        j = _edge_index(r, r.get(it, key, "edge"), f"{key}.edge", "e", env.m, seen)
        env_edges[j] = _coefficient(r, r.get(it, key, "mu"), f"{key}.mu")

    obj_env: dict[int, float] = {}
    obj_grip: dict[int, float] = {}
    seen = {}
    raw = r.array(r.get(t, "friction", "object_edges", []), "friction.object_edges")
    for k, item in enumerate(raw):
        key = f"friction.object_edges[{k}]"
        it = r.table(item, key)
        r.unknown_keys(it, key, ("edge", "environment", "gripper"))
        i = _edge_index(r, r.get(it, key, "edge"), f"{key}.edge", "l", obj.n, seen)
        if "environment" not in it and "gripper" not in it:
            raise r.fail(key, "an object-edge override needs environment or gripper (or both)")
        if "environment" in it:
            obj_env[i] = _coefficient(r, it["environment"], f"{key}.environment")
        if "gripper" in it:
            obj_grip[i] = _coefficient(r, it["gripper"], f"{key}.gripper")
    return Friction(mu_env, mu_grip, env_edges, obj_env, obj_grip)


def _read_task(r: _Reader, t: Mapping[str, Any], world: World
               ) -> tuple[Pose, Pose, GripperState | None, bool, bool]:
    r.unknown_keys(t, "task", ("start", "goal", "start_grasp", "goal_release"))
    start = r.pose(r.get(t, "task", "start"), "task.start")
    goal = r.pose(r.get(t, "task", "goal"), "task.goal")
    for key, pose in (("task.start", start), ("task.goal", goal)):
        obj = shapely.Polygon(world.object_vertices(pose))
        for solid in world.environment.solids:
            if _overlaps(obj, solid.polygon.shapely):
                inter = shapely.intersection(obj, solid.polygon.shapely)
                raise r.fail(key, f"the object at {_pose(pose)} overlaps solid {solid.name!r} "
                                  f"({_num(inter.area, 1)} mm^2 in common; touching is fine, "
                                  f"overlap deeper than {_num(VALIDATE_TOL)} mm is not)")

    grasp: GripperState | None = None
    raw = r.get(t, "task", "start_grasp", None)
    start_any = False
    if isinstance(raw, str):
        if raw != "any":
            raise r.fail("task.start_grasp", f"unknown value {raw!r}: a table "
                                             "{ gripper = [x, y, phi], width = w } or the string \"any\"")
        start_any = True
    elif raw is not None:
        key = "task.start_grasp"
        g = r.table(raw, key)
        r.unknown_keys(g, key, ("gripper", "width"))
        pose = r.pose(r.get(g, key, "gripper"), f"{key}.gripper")
        width = r.number(r.get(g, key, "width"), f"{key}.width")
        lo, hi = world.gripper.width_range
        if not lo <= width <= hi:
            raise r.fail(f"{key}.width", f"width {_num(width)} mm is outside the gripper's range "
                                         f"[{_num(lo)}, {_num(hi)}]")
        grasp = GripperState(pose, width)
        _check_grasp_clear(r, world, start, grasp)
    if raw is None:
        _check_start_supported(r, world, start)
    goal_release = r.boolean(r.get(t, "task", "goal_release", False), "task.goal_release")
    return start, goal, grasp, goal_release, start_any


def _check_start_supported(r: _Reader, world: World, start: Pose) -> None:
    """An object that starts free of the gripper must touch a solid (within 1 mm)."""
    obj = shapely.Polygon(world.object_vertices(start))
    gap = min(float(shapely.distance(obj, s.polygon.shapely)) for s in world.environment.solids)
    if gap > VALIDATE_TOL:
        raise r.fail("task.start", f"the object at {_pose(start)} touches nothing (the nearest solid is "
                                   f"{_num(gap, 1)} mm away) and would fall: give a task.start_grasp "
                                   "(or start_grasp = \"any\" to let the planner choose one)")


def _check_grasp_clear(r: _Reader, world: World, start: Pose, grasp: GripperState) -> None:
    """Plan rule 3 at the first waypoint: no finger (or palm) overlaps the object or a solid."""
    bodies: list[tuple[str, shapely.Geometry]] = []
    g = world.gripper
    pose, w = grasp.pose, grasp.width
    if isinstance(g, TwoPointGripper):
        for k, cx in ((1, -w / 2.0), (2, w / 2.0)):
            centre = pose.apply(np.array([cx, 0.0]))
            bodies.append((f"finger {k}", shapely.Point(centre).buffer(g.finger_radius, 32)))
    else:
        for k, verts in enumerate(g.finger_polygons(w), start=1):
            bodies.append((f"finger {k}", shapely.Polygon(pose.apply(verts))))
        if g.palm is not None:
            bodies.append(("the palm", shapely.Polygon(pose.apply(g.palm.vertices))))
    others = [("the object at the start pose", shapely.Polygon(world.object_vertices(start)))]
    others += [(f"solid {s.name!r}", s.polygon.shapely) for s in world.environment.solids]
    for body_name, body in bodies:
        for other_name, other in others:
            if _overlaps(body, other):
                raise r.fail("task.start_grasp", f"{body_name} overlaps {other_name} "
                                                 f"(overlap deeper than {_num(VALIDATE_TOL)} mm)")


def _read_planner(r: _Reader, t: Mapping[str, Any], base_dir: Path, check: bool) -> PlannerSettings:
    d = PlannerSettings()
    r.unknown_keys(t, "planner", ("domain", "engine", "samples_per_edge", "max_top_iterations",
                                  "max_refinements", "seed", "friction_margin"))
    domain = r.string(r.get(t, "planner", "domain", d.domain), "planner.domain")
    engine = r.string(r.get(t, "planner", "engine", d.engine), "planner.engine")
    k = r.integer(r.get(t, "planner", "samples_per_edge", d.samples_per_edge),
                  "planner.samples_per_edge")
    lo, hi = SAMPLES_PER_EDGE_RANGE
    if not lo <= k <= hi:
        raise r.fail("planner.samples_per_edge", f"{k} is outside {lo}..{hi}")
    counts: dict[str, int] = {}
    for name in ("max_top_iterations", "max_refinements"):
        v = r.integer(r.get(t, "planner", name, getattr(d, name)), f"planner.{name}")
        if v < 1:
            raise r.fail(f"planner.{name}", f"must be a positive integer, got {v}")
        counts[name] = v
    seed = r.integer(r.get(t, "planner", "seed", d.seed), "planner.seed")
    if seed < 0:
        raise r.fail("planner.seed", f"must be a non-negative integer, got {seed}")

    margin = r.number(r.get(t, "planner", "friction_margin", d.friction_margin), "planner.friction_margin")
    if not 0.0 <= margin < 1.0:
        raise r.fail("planner.friction_margin", f"must lie in [0, 1), got {_num(margin)}")

    domain_path: Path | None = None
    if check:
        domain_path = find_domain(domain, base_dir)
        if domain_path is None:
            raise r.fail("planner.domain", _unknown_domain(domain, base_dir))
        # The engines are known without importing unified-planning (over a second) unless a
        # configuration file may add some: then ldhp_tamp.symbolic, which imports it, asks.
        from ldhp_tamp.engine_names import installed_planners, known_planners

        if engine not in installed_planners():
            engines = known_planners()
            if engines is None:
                from ldhp_tamp.symbolic import available_engines

                engines = tuple(available_engines())
            if engine not in engines:
                raise r.fail("planner.engine", f"unknown engine {engine!r} "
                                               f"(installed: {', '.join(engines) or 'none'})")
    return PlannerSettings(domain=domain, engine=engine, samples_per_edge=k,
                           max_top_iterations=counts["max_top_iterations"],
                           max_refinements=counts["max_refinements"], seed=seed,
                           domain_path=domain_path, friction_margin=margin)


def _unknown_domain(domain: str, base_dir: Path) -> str:
    try:
        shipped = sorted(p.stem for p in resources.domains_dir().glob("*.pddl"))
    except FileNotFoundError:
        shipped = []
    names = ", ".join(shipped) or "none"
    if _is_domain_name(domain):
        return f"unknown domain {domain!r} (shipped domains: {names})"
    target = Path(domain).expanduser()
    target = target if target.is_absolute() else base_dir / target
    return (f"domain file {domain!r} not found (looked for {target}); a shipped domain is "
            f"named without .pddl: {names}")


# --------------------------------------------------------------------------- helpers


def _is_domain_name(domain: str) -> bool:
    """A shipped domain's name: no path separator, no ``.pddl`` suffix (as in
    :func:`ldhp_tamp.symbolic.domain_path`)."""
    return bool(domain) and not any(c in domain for c in "/\\") and not domain.endswith(".pddl")


def _overlaps(a: shapely.Geometry, b: shapely.Geometry) -> bool:
    """The plan spec's rule 3: the intersection, eroded by VALIDATE_TOL, is non-empty."""
    if not shapely.intersects(a, b):
        return False
    inter = shapely.intersection(a, b)
    return not shapely.is_empty(shapely.buffer(inter, -VALIDATE_TOL))


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, (int, float)):
        return f"a number ({value})"
    if isinstance(value, str):
        return f"a string ({value!r})"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


def _num(x: float, digits: int = 3) -> str:
    s = f"{x:.{digits}f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _point(p: Sequence[float] | np.ndarray) -> str:
    return f"({_num(float(p[0]))}, {_num(float(p[1]))})"


def _pose(p: Pose) -> str:
    x, y, t = p.to_degrees()
    return f"[{_num(x)}, {_num(y)}, {_num(t)} deg]"


def _span(names: Sequence[str]) -> str:
    return names[0] if len(names) == 1 else f"{names[0]}..{names[-1]}"


def _describe_gripper(g: Gripper) -> str:
    def rng(lo: float, hi: float) -> str:
        return f"{_num(lo)} mm (fixed)" if lo == hi else f"{_num(lo)}..{_num(hi)} mm"

    force = "unbounded" if g.max_force is None else f"at most {_num(g.max_force)} N"
    if isinstance(g, TwoPointGripper):
        return (f"two-point, finger radius {_num(g.finger_radius)} mm, spacing between centres "
                f"{rng(*g.spacing)}, finger force {force}")
    lo, hi = g.finger.vertices.min(axis=0), g.finger.vertices.max(axis=0)
    palm = "none" if g.palm is None else f"{len(g.palm)}-gon"
    return (f"polyline, finger {len(g.finger)}-gon {_num(hi[0] - lo[0])} x {_num(hi[1] - lo[1])} "
            f"mm, opening {rng(*g.opening)}, palm {palm}, finger force {force}")


def _describe_friction(f: Friction) -> str:
    parts = [f"environment {_num(f.environment)}, gripper {_num(f.gripper)}"]
    overrides = [f"e{j + 1} {_num(mu)}" for j, mu in sorted(f.environment_edges.items())]
    for i in sorted(set(f.object_edges_environment) | set(f.object_edges_gripper)):
        sides = []
        if i in f.object_edges_environment:
            sides.append(f"environment {_num(f.object_edges_environment[i])}")
        if i in f.object_edges_gripper:
            sides.append(f"gripper {_num(f.object_edges_gripper[i])}")
        overrides.append(f"l{i + 1} {' '.join(sides)}")
    if overrides:
        parts.append("overrides: " + "; ".join(overrides))
    return "; ".join(parts)
