"""The immutable world of a planning problem: object, environment, gripper, friction.

These are the values of the paper's input tuple I = (O, E, G, T0, Tg, {mu}) less the task
poses (which the planner's scenario holds). Feature names follow the scenario spec:

- object vertices ``v1..vN`` and edges ``l1..lN`` (``l_i`` joins ``v_i`` to ``v_(i+1)``);
- environment edges ``e1..eM`` numbered across solids in file order, each solid walked
  counter-clockwise from its first vertex; environment vertices ``ve1..veM`` numbered the
  same way, so ``ve_j`` is the start vertex of ``e_j`` (the paper's v^E_j).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Mapping

import numpy as np
import shapely
from numpy.typing import NDArray

from geometry.errors import GeometryError
from geometry.poses import Pose
from geometry.shapes import FloatArray, Polygon, make_polygon
from geometry.tolerances import GRAVITY


def _ro(a) -> np.ndarray:
    arr = np.array(a, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class ObjectModel:
    """The manipulated rigid object O: polygon in its own frame, centre of mass, mass."""

    polygon: Polygon
    com: FloatArray
    mass: float = 1.0

    @property
    def n(self) -> int:
        return len(self.polygon)

    @cached_property
    def vertex_names(self) -> tuple[str, ...]:
        return tuple(f"v{i + 1}" for i in range(self.n))

    @cached_property
    def edge_names(self) -> tuple[str, ...]:
        return tuple(f"l{i + 1}" for i in range(self.n))

    @property
    def weight(self) -> float:
        """Weight in newtons (mass in kg times g)."""
        return self.mass * GRAVITY

    @property
    def length_scale(self) -> float:
        """Characteristic length (mm) used to normalise moments: circumradius about the COM."""
        return float(np.max(np.linalg.norm(self.polygon.vertices - self.com, axis=1)))


@dataclass(frozen=True, eq=False)
class Solid:
    """A rigid static solid of the environment (world frame, counter-clockwise)."""

    name: str
    polygon: Polygon


@dataclass(frozen=True, eq=False)
class Environment:
    """The static environment E: one or more solids, with its edges and vertices numbered."""

    solids: tuple[Solid, ...]

    @cached_property
    def edges(self) -> FloatArray:
        """(M, 2, 2) all solid edges as [start, end], numbered across solids."""
        return _ro(np.concatenate([s.polygon.edges for s in self.solids], axis=0))

    @cached_property
    def normals(self) -> FloatArray:
        """(M, 2) outward unit normals (pointing out of the solid, into free space)."""
        return _ro(np.concatenate([s.polygon.normals for s in self.solids], axis=0))

    @cached_property
    def edge_directions(self) -> FloatArray:
        return _ro(np.concatenate([s.polygon.edge_directions for s in self.solids], axis=0))

    @cached_property
    def edge_lengths(self) -> FloatArray:
        return _ro(np.concatenate([s.polygon.edge_lengths for s in self.solids], axis=0))

    @cached_property
    def edge_solid(self) -> NDArray[np.int64]:
        """(M,) index of the solid owning each edge (and each vertex)."""
        return _ro(np.concatenate([np.full(len(s.polygon), k) for k, s in enumerate(self.solids)]))

    @cached_property
    def vertices(self) -> FloatArray:
        """(M, 2) all solid vertices; vertex j is the start of edge j."""
        return _ro(np.concatenate([s.polygon.vertices for s in self.solids], axis=0))

    @cached_property
    def vertex_convex(self) -> NDArray[np.bool_]:
        """(M,) True for convex corners of a solid: the only vertices an object edge can touch."""
        return _ro(np.concatenate([s.polygon.convex_vertices for s in self.solids]))

    @cached_property
    def vertex_edges(self) -> NDArray[np.int64]:
        """(M, 2) for each vertex: (edge arriving at it, edge leaving it)."""
        out = []
        base = 0
        for s in self.solids:
            n = len(s.polygon)
            idx = np.arange(n)
            out.append(np.stack([base + (idx - 1) % n, base + idx], axis=1))
            base += n
        return _ro(np.concatenate(out, axis=0))

    @property
    def m(self) -> int:
        return int(self.edges.shape[0])

    @cached_property
    def edge_names(self) -> tuple[str, ...]:
        return tuple(f"e{j + 1}" for j in range(self.m))

    @cached_property
    def vertex_names(self) -> tuple[str, ...]:
        return tuple(f"ve{j + 1}" for j in range(self.m))

    @cached_property
    def shapely(self) -> shapely.MultiPolygon:
        """All solids as one prepared shapely geometry."""
        g = shapely.MultiPolygon([s.polygon.shapely for s in self.solids])
        shapely.prepare(g)
        return g


@dataclass(frozen=True)
class TwoPointGripper:
    """Configuration I: two cylindrical fingers seen as circles.

    Finger centres sit at (-w/2, 0) and (+w/2, 0) in the gripper frame, w the spacing
    between centres; ``spacing[0] == spacing[1]`` is the zero-mobility gripper.
    """

    finger_radius: float
    spacing: tuple[float, float]
    max_force: float | None = None
    """The largest normal force (N) one finger may apply; ``None``: unbounded."""

    @property
    def width_range(self) -> tuple[float, float]:
        return self.spacing

    @property
    def fixed_width(self) -> bool:
        return self.spacing[0] == self.spacing[1]


@dataclass(frozen=True, eq=False)
class PolylineGripper:
    """Configuration II: fingertips as polygons, plus an optional palm.

    ``finger`` is the right finger (finger 2) in its own frame: contact pad on x = 0, body
    at x >= 0, tip at y = 0, palm side towards +y. In the gripper frame finger 2 is
    ``finger`` shifted by (+w/2, 0) and finger 1 its mirror image shifted by (-w/2, 0),
    w the opening (gap between the pad faces).
    """

    finger: Polygon
    opening: tuple[float, float]
    palm: Polygon | None = None
    max_force: float | None = None
    """The largest normal force (N) one finger may apply; ``None``: unbounded."""

    @property
    def width_range(self) -> tuple[float, float]:
        return self.opening

    @property
    def fixed_width(self) -> bool:
        return self.opening[0] == self.opening[1]

    @cached_property
    def mirrored_finger(self) -> Polygon:
        """Finger 1's polygon in its own frame (mirror x -> -x, re-ordered CCW)."""
        v = self.finger.vertices * np.array([-1.0, 1.0])
        return make_polygon(v, what="mirrored finger")

    def finger_polygons(self, width: float) -> tuple[FloatArray, FloatArray]:
        """Finger 1 and finger 2 vertices (CCW) in the gripper frame at opening ``width``."""
        f1 = self.mirrored_finger.vertices + np.array([-width / 2.0, 0.0])
        f2 = self.finger.vertices + np.array([width / 2.0, 0.0])
        return f1, f2


Gripper = TwoPointGripper | PolylineGripper


@dataclass(frozen=True)
class GripperState:
    """Gripper pose (gripper frame in world, radians) and width (spacing or opening)."""

    pose: Pose
    width: float


@dataclass(frozen=True)
class Friction:
    """Coulomb coefficients with per-edge overrides (0-based edge indices).

    Resolution for an object-environment contact: an environment-edge override wins over
    an object-edge one, which wins over the default. A vertex has no coefficient of its
    own: it takes the smallest override among its two adjacent edges (if any), which is
    the conservative reading. Object-finger contacts use the object side only.
    """

    environment: float
    gripper: float
    environment_edges: Mapping[int, float] = field(default_factory=dict)
    object_edges_environment: Mapping[int, float] = field(default_factory=dict)
    object_edges_gripper: Mapping[int, float] = field(default_factory=dict)

    def _object_side(self, table: Mapping[int, float], kind: str, index: int, n: int) -> float | None:
        if kind == "l":
            return table.get(index)
        vals = [table[k] for k in ((index - 1) % n, index) if k in table]
        return min(vals) if vals else None

    def environment_mu(self, obj_kind: str, obj_index: int, env_kind: str, env_index: int,
                       world_edges: NDArray[np.int64] | None = None, n_object: int = 0) -> float:
        """Coefficient of the contact between an object feature and an environment feature.

        ``obj_kind`` is ``"v"`` or ``"l"``, ``env_kind`` ``"e"`` or ``"ve"``;
        ``world_edges`` is :attr:`Environment.vertex_edges` (needed for ``"ve"``) and
        ``n_object`` the object's vertex count (needed for ``"v"``).
        """
        if env_kind == "e":
            if env_index in self.environment_edges:
                return self.environment_edges[env_index]
        else:
            assert world_edges is not None
            vals = [self.environment_edges[k] for k in world_edges[env_index] if k in self.environment_edges]
            if vals:
                return min(vals)
        mu = self._object_side(self.object_edges_environment, obj_kind, obj_index, n_object)
        return self.environment if mu is None else mu

    def scaled(self, factor: float) -> "Friction":
        """Every coefficient (defaults and overrides) times ``factor`` (a planning margin:
        ``1 - friction_margin``)."""
        f = float(factor)
        return Friction(self.environment * f, self.gripper * f,
                        {k: v * f for k, v in self.environment_edges.items()},
                        {k: v * f for k, v in self.object_edges_environment.items()},
                        {k: v * f for k, v in self.object_edges_gripper.items()})

    def gripper_mu(self, obj_kind: str, obj_index: int, n_object: int) -> float:
        """Coefficient between a finger and an object feature (``"v"`` or ``"l"``)."""
        mu = self._object_side(self.object_edges_gripper, obj_kind, obj_index, n_object)
        return self.gripper if mu is None else mu


@dataclass(frozen=True, eq=False)
class World:
    """Everything physical about a problem: object, environment, gripper, friction."""

    object: ObjectModel
    environment: Environment
    gripper: Gripper
    friction: Friction

    def object_vertices(self, pose: Pose) -> FloatArray:
        """World vertices of the object at ``pose``."""
        return self.object.polygon.transformed(pose.x, pose.y, pose.theta)


def make_object(vertices, com=None, mass: float = 1.0) -> ObjectModel:
    """Build an :class:`ObjectModel`; ``com`` defaults to the area centroid."""
    poly = make_polygon(vertices, what="object")
    if not (math.isfinite(mass) and mass > 0):
        raise GeometryError(f"object: mass must be a positive number, got {mass}")
    c = poly.centroid if com is None else np.asarray(com, dtype=float)
    return ObjectModel(poly, _ro(c), float(mass))
