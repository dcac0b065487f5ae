"""The MuJoCo model of a scenario, for :mod:`ldhp_tamp.simulate` (``docs/design/simulation.md``).

The planar world (x right, y up, millimetres) becomes MuJoCo's x-z plane (metres, gravity
-z); MuJoCo's y axis is the out-of-plane depth. Every polygon is split into convex pieces
(:func:`convex_pieces`) and each piece is extruded into a slab, one mesh geom per piece
(MuJoCo collides the convex hull of a mesh).

Bodies and joints (every planar pose ``(x, y, theta)`` is three joints ``slide x``,
``slide z`` and ``hinge`` about MuJoCo's -y, whose positions are ``x/1000``, ``y/1000``
and ``theta`` in radians, so that a counter-clockwise plan angle is a positive joint angle):

- ``object``: the three joints, the scenario's mass, the centre of mass and the planar
  inertia of the polygon set explicitly;
- the solids: static geoms of the world body;
- ``hand``: the gripper frame on the three joints, gravity-compensated, each joint driven
  by a stiff position actuator (with damping) whose target the simulator moves along the
  plan: the hand is a dynamic body, so it carries its velocity into its contacts (a mocap
  body moved by setting its pose would not transmit friction);
- the fingers: with a variable width, ``finger1`` and ``finger2`` are bodies on a slide
  joint along the gripper's x axis (joint position = the finger frame's x, ``-w/2`` and
  ``+w/2`` in metres), each driven by a position actuator whose force is capped at the
  gripper's ``max_force`` (or :attr:`ModelOptions.default_max_force` when the scenario has
  none); with a fixed width they are geoms of the hand.

Contacts exist only between the pairs listed in ``<contact><pair>`` (every geom has
``contype = conaffinity = 0``): object-solid, object-finger, object-palm, finger-solid and
palm-solid, each with the scenario's coefficient (MuJoCo would otherwise combine two geoms'
coefficients by their maximum), ``condim = 3`` and an elliptic cone.

``mujoco`` is imported inside :func:`build_model` only (a heavy import).
"""

from __future__ import annotations

import logging
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from geometry.poses import Pose
from geometry.shapes import FloatArray, polar_moment, signed_area
from geometry.world import PolylineGripper, TwoPointGripper, World

__all__ = [
    "MM",
    "ModelOptions",
    "SimModel",
    "build_model",
    "build_xml",
    "convex_pieces",
    "planar_inertia",
]

log = logging.getLogger(__name__)

#: Metres per millimetre.
MM = 1e-3


@dataclass(frozen=True)
class ModelOptions:
    """The physical and numerical settings of the model.

    Attributes
    ----------
    timestep_s : float
        Integration step (s).
    impratio : float
        MuJoCo's ratio of frictional to normal constraint impedance: with the default (1)
        a block pinched with friction to spare creeps about 0.1 mm/s; at 100 (with the
        default ``solref``/``solimp``) about 0.003 mm/s.
    object_depth_mm, solid_depth_mm, finger_depth_mm : float
        Out-of-plane thickness of the extruded slabs: the object's thinner than the
        solids' and fingers', so its faces never meet their edges.
    hand_mass_kg, finger_mass_kg : float
        Masses of the (gravity-compensated) hand and fingers.
    hand_kp : float
        Stiffness of the hand's translation drives (N/m); the rotation drive's is
        ``hand_kp * hand_lever_m**2`` (N m/rad), so a point ``hand_lever_m`` from the
        gripper origin sees the same stiffness.
    hand_lever_m : float
        Lever arm of the rotation drive and radius of gyration of the hand (m).
    finger_kp : float
        Stiffness of the finger drives (N/m): a finger pressed 2.5 mm short of its target
        pushes with 50 N at the default, at most the force cap.
    default_max_force : float
        Finger force cap (N) when the scenario's gripper has no ``max_force``.
    solref_timeconst_s : float
        Contact stiffness as MuJoCo's ``solref`` time constant (s); at least twice the step.
    solimp : tuple of float
        MuJoCo's ``solimp`` (dmin, dmax, width in m) of every contact pair: a harder
        impedance than the default (0.9, 0.95) halves the creep of a pinch.
    env_finger_mu : float or None
        Finger-solid and palm-solid coefficient; ``None``: the scenario's environment one.
    """

    timestep_s: float = 0.001
    impratio: float = 100.0
    object_depth_mm: float = 40.0
    solid_depth_mm: float = 80.0
    finger_depth_mm: float = 60.0
    hand_mass_kg: float = 1.0
    finger_mass_kg: float = 0.1
    hand_kp: float = 1.0e5
    hand_lever_m: float = 0.1
    finger_kp: float = 2.0e4
    default_max_force: float = 1000.0
    solref_timeconst_s: float = 0.002
    solimp: tuple[float, float, float] = (0.95, 0.99, 0.001)
    env_finger_mu: float | None = None

    def __post_init__(self) -> None:
        for name in ("timestep_s", "impratio", "object_depth_mm", "solid_depth_mm", "finger_depth_mm",
                     "hand_mass_kg", "finger_mass_kg", "hand_kp", "hand_lever_m", "finger_kp",
                     "default_max_force", "solref_timeconst_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        if self.solref_timeconst_s < 2 * self.timestep_s:
            raise ValueError("solref_timeconst_s must be at least twice timestep_s")


@dataclass(frozen=True, eq=False)
class SimModel:
    """A compiled model and where its parts live in MuJoCo's arrays.

    Attributes
    ----------
    model : mujoco.MjModel
    xml : str
        The MJCF it was compiled from.
    object_qpos : tuple of int
        ``qpos`` addresses of the object's x, z, angle joints.
    hand_qpos : tuple of int
        ``qpos`` addresses of the hand's joints.
    hand_actuators : tuple of int
        Actuator ids driving the hand's x, z, angle.
    finger_qpos, finger_actuators : tuple of int
        Finger 1 and finger 2 slide joints and drives; empty for a fixed width.
    variable_width : bool
    max_force : float
        The finger force cap used (N).
    max_force_from_scenario : bool
        False when the scenario gives none and the default is used.
    """

    model: Any
    xml: str
    object_qpos: tuple[int, int, int]
    hand_qpos: tuple[int, int, int]
    hand_actuators: tuple[int, int, int]
    finger_qpos: tuple[int, ...]
    finger_actuators: tuple[int, ...]
    variable_width: bool
    max_force: float
    max_force_from_scenario: bool


# --------------------------------------------------------------------------------------
# Polygons
# --------------------------------------------------------------------------------------


def _cross(o: FloatArray, a: FloatArray, b: FloatArray) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def _is_convex(pts: FloatArray, eps: float = 1e-9) -> bool:
    n = len(pts)
    return all(_cross(pts[i - 1], pts[i], pts[(i + 1) % n]) >= -eps for i in range(n))


def _ear_clip(pts: FloatArray) -> list[tuple[int, int, int]]:
    """Triangles (CCW index triples) of a simple CCW polygon by ear clipping."""
    idx = list(range(len(pts)))
    triangles: list[tuple[int, int, int]] = []
    guard = 0
    while len(idx) > 3 and guard < 10 * len(pts) ** 2:
        guard += 1
        n = len(idx)
        for k in range(n):
            a, b, c = idx[k - 1], idx[k], idx[(k + 1) % n]
            if _cross(pts[a], pts[b], pts[c]) <= 1e-12:
                continue  # reflex or flat corner
            tri = (pts[a], pts[b], pts[c])
            inside = False
            for j in idx:
                if j in (a, b, c):
                    continue
                p = pts[j]
                if (_cross(tri[0], tri[1], p) >= 0 and _cross(tri[1], tri[2], p) >= 0
                        and _cross(tri[2], tri[0], p) >= 0):
                    inside = True
                    break
            if not inside:
                triangles.append((a, b, c))
                del idx[k]
                break
        else:  # no ear: numerical trouble; drop the flattest corner
            k = min(range(n), key=lambda k: abs(_cross(pts[idx[k - 1]], pts[idx[k]], pts[idx[(k + 1) % n]])))
            del idx[k]
    if len(idx) == 3:
        triangles.append((idx[0], idx[1], idx[2]))
    return triangles


def convex_pieces(vertices: Sequence[Sequence[float]] | FloatArray) -> list[FloatArray]:
    """Split a simple polygon into convex pieces (CCW vertex arrays).

    A convex polygon is one piece. Otherwise ear clipping gives triangles, and
    Hertel-Mehlhorn merging removes every diagonal whose removal leaves both sides
    convex (at most four times the optimal number of pieces).

    Examples
    --------
    >>> len(convex_pieces([[0, 0], [2, 0], [2, 2], [0, 2]]))
    1
    >>> len(convex_pieces([[0, 0], [3, 0], [3, 1], [1, 1], [1, 3], [0, 3]]))
    2
    """
    pts = np.asarray(vertices, dtype=float)
    if signed_area(pts) < 0:
        pts = pts[::-1]
    if _is_convex(pts):
        return [pts.copy()]
    pieces: list[list[int]] = [list(t) for t in _ear_clip(pts)]
    merged = True
    while merged:
        merged = False
        for i in range(len(pieces)):
            for j in range(i + 1, len(pieces)):
                joined = _merge(pieces[i], pieces[j])
                if joined is not None and _is_convex(pts[joined]):
                    pieces[i] = joined
                    del pieces[j]
                    merged = True
                    break
            if merged:
                break
    return [pts[p] for p in pieces]


def _merge(a: list[int], b: list[int]) -> list[int] | None:
    """The union of two CCW index polygons that share an edge (u, v) in a, (v, u) in b."""
    na, nb = len(a), len(b)
    for i in range(na):
        u, v = a[i], a[(i + 1) % na]
        for j in range(nb):
            if b[j] == v and b[(j + 1) % nb] == u:
                # a from v round to u, then b from u (exclusive) round to v (exclusive)
                out = [a[(i + 1 + k) % na] for k in range(na)]  # starts at v, ends at u
                out += [b[(j + 2 + k) % nb] for k in range(nb - 2)]
                return out
    return None


def planar_inertia(vertices: FloatArray, about: FloatArray) -> float:
    """Polar second moment of area (mm^4) of a polygon about a point: ``Iyy = mass * J / A``.

    Examples
    --------
    >>> round(planar_inertia(np.array([[0., 0.], [2., 0.], [2., 2.], [0., 2.]]), np.array([1., 1.])), 6)
    2.666667
    """
    return polar_moment(vertices, about)


# --------------------------------------------------------------------------------------
# MJCF
# --------------------------------------------------------------------------------------


def _fmt(*xs: float) -> str:
    return " ".join(f"{x:.9g}" for x in xs)


def _slab(piece: FloatArray, depth_mm: float) -> str:
    """Mesh vertices (metres) of a planar piece extruded symmetrically along MuJoCo's y."""
    h = depth_mm / 2.0 * MM
    out: list[float] = []
    for x, y in piece:
        out += [x * MM, -h, y * MM, x * MM, h, y * MM]
    return _fmt(*out)


class _Builder:
    def __init__(self, opts: ModelOptions):
        self.opts = opts
        self.root = ET.Element("mujoco", model="ldhp-sim")
        self.asset = ET.SubElement(self.root, "asset")
        self.contact = ET.SubElement(self.root, "contact")
        self.n_mesh = 0

    def mesh_geoms(self, parent: ET.Element, name: str, polygon: FloatArray, depth_mm: float) -> list[str]:
        names = []
        for k, piece in enumerate(convex_pieces(polygon)):
            mesh = f"{name}_mesh{k}"
            ET.SubElement(self.asset, "mesh", name=mesh, vertex=_slab(piece, depth_mm))
            geom = f"{name}_{k}"
            ET.SubElement(parent, "geom", name=geom, type="mesh", mesh=mesh, contype="0", conaffinity="0",
                          group="1")
            names.append(geom)
        return names

    def pair(self, g1: str, g2: str, mu: float) -> None:
        ET.SubElement(self.contact, "pair", geom1=g1, geom2=g2, condim="3",
                      friction=_fmt(mu, mu, 0.0, 0.0, 0.0),
                      solref=_fmt(self.opts.solref_timeconst_s, 1.0), solimp=_fmt(*self.opts.solimp))


def _planar_joints(body: ET.Element, prefix: str, damping: float = 0.0) -> None:
    attrs = {"damping": _fmt(damping)} if damping else {}
    ET.SubElement(body, "joint", name=f"{prefix}_x", type="slide", axis="1 0 0", **attrs)
    ET.SubElement(body, "joint", name=f"{prefix}_z", type="slide", axis="0 0 1", **attrs)
    ET.SubElement(body, "joint", name=f"{prefix}_theta", type="hinge", axis="0 -1 0", **attrs)


def _piece_edges(polygon: FloatArray, piece: FloatArray) -> list[int]:
    """Indices of the polygon's edges that a piece's boundary runs along (its outer edges)."""
    out = []
    n = len(polygon)
    for i in range(n):
        a, b = polygon[i], polygon[(i + 1) % n]
        for k in range(len(piece)):
            p, q = piece[k], piece[(k + 1) % len(piece)]
            if np.allclose(p, a) and np.allclose(q, b):
                out.append(i)
                break
    return out


def build_xml(world: World, options: ModelOptions = ModelOptions()) -> tuple[str, float, bool]:
    """The MJCF text of a scenario's world (see the module docstring).

    Returns
    -------
    xml : str
    max_force : float
        The finger force cap (N) written into the finger drives.
    from_scenario : bool
        Whether ``max_force`` is the scenario's own.
    """
    o = options
    b = _Builder(o)
    root = b.root
    ET.SubElement(root, "compiler", angle="radian", inertiafromgeom="false")
    option = ET.SubElement(root, "option", timestep=_fmt(o.timestep_s), gravity="0 0 -9.81", cone="elliptic",
                           impratio=_fmt(o.impratio), integrator="implicitfast", solver="Newton",
                           iterations="100", tolerance="1e-10")
    # several contacts per convex pair (a face on a face touches at its corners): an enable
    # flag before MuJoCo 3.2, the default (and still accepted) since
    ET.SubElement(option, "flag", multiccd="enable")
    world_body = ET.SubElement(root, "worldbody")

    # -- solids (static)
    friction = world.friction
    env = world.environment
    solid_geoms: list[tuple[str, list[int]]] = []  # geom, the environment edges it carries
    base = 0
    for s, solid in enumerate(env.solids):
        poly = solid.polygon.vertices
        for k, piece in enumerate(convex_pieces(poly)):
            mesh = f"solid{s}_mesh{k}"
            ET.SubElement(b.asset, "mesh", name=mesh, vertex=_slab(piece, o.solid_depth_mm))
            geom = f"solid{s}_{k}"
            ET.SubElement(world_body, "geom", name=geom, type="mesh", mesh=mesh, contype="0", conaffinity="0")
            solid_geoms.append((geom, [base + e for e in _piece_edges(poly, piece)]))
        base += len(poly)

    # -- the object
    obj = world.object
    opoly = obj.polygon.vertices
    body = ET.SubElement(world_body, "body", name="object", pos="0 0 0")
    _planar_joints(body, "object")
    iyy = obj.mass * planar_inertia(opoly, obj.com) / abs(obj.polygon.area) * MM * MM
    ET.SubElement(body, "inertial", pos=_fmt(obj.com[0] * MM, 0.0, obj.com[1] * MM), mass=_fmt(obj.mass),
                  diaginertia=_fmt(iyy, iyy, iyy))
    object_geoms: list[tuple[str, list[int]]] = []
    n_obj = len(opoly)
    for k, piece in enumerate(convex_pieces(opoly)):
        mesh = f"object_mesh{k}"
        ET.SubElement(b.asset, "mesh", name=mesh, vertex=_slab(piece, o.object_depth_mm))
        geom = f"object_{k}"
        ET.SubElement(body, "geom", name=geom, type="mesh", mesh=mesh, contype="0", conaffinity="0",
                      rgba="0.2 0.4 0.8 1")
        object_geoms.append((geom, _piece_edges(opoly, piece) or list(range(n_obj))))

    # -- the hand and fingers
    g = world.gripper
    mf = getattr(g, "max_force", None)
    max_force = float(mf) if mf is not None else o.default_max_force
    hand = ET.SubElement(world_body, "body", name="hand", pos="0 0 0", gravcomp="1")
    _planar_joints(hand, "hand")
    lever = o.hand_lever_m
    ET.SubElement(hand, "inertial", pos="0 0 0", mass=_fmt(o.hand_mass_kg),
                  diaginertia=_fmt(*(3 * [o.hand_mass_kg * lever * lever])))
    lo, hi = g.width_range
    variable = hi > lo
    finger_geoms: list[str] = []
    palm_geoms: list[str] = []
    fingers: list[ET.Element] = []
    for f in (1, 2):
        if variable:
            fb = ET.SubElement(hand, "body", name=f"finger{f}", pos="0 0 0", gravcomp="1")
            ET.SubElement(fb, "joint", name=f"finger{f}", type="slide", axis="1 0 0")
            ET.SubElement(fb, "inertial", pos="0 0 0", mass=_fmt(o.finger_mass_kg),
                          diaginertia=_fmt(*(3 * [o.finger_mass_kg * 1e-4])))
            offset = 0.0  # the joint carries +-w/2
        else:
            fb = hand
            offset = (-1 if f == 1 else 1) * lo / 2.0
        fingers.append(fb)
        if isinstance(g, TwoPointGripper):
            h = o.finger_depth_mm / 2.0 * MM
            name = f"finger{f}_0"
            ET.SubElement(fb, "geom", name=name, type="cylinder", size=_fmt(g.finger_radius * MM),
                          fromto=_fmt(offset * MM, -h, 0.0, offset * MM, h, 0.0),
                          contype="0", conaffinity="0", rgba="0.3 0.3 0.3 1")
            finger_geoms.append(name)
        else:
            assert isinstance(g, PolylineGripper)
            poly = (g.mirrored_finger if f == 1 else g.finger).vertices + np.array([offset, 0.0])
            finger_geoms += b.mesh_geoms(fb, f"finger{f}", poly, o.finger_depth_mm)
    if isinstance(g, PolylineGripper) and g.palm is not None:
        palm_geoms = b.mesh_geoms(hand, "palm", g.palm.vertices, o.finger_depth_mm)

    # -- contact pairs
    env_edges = env.vertex_edges
    for og, oedges in object_geoms:
        for sg, sedges in solid_geoms:
            mus = [friction.environment_mu("l", i, "e", j, env_edges, n_obj) for i in oedges for j in sedges]
            if not mus:
                mus = [friction.environment_mu("l", i, "e", 0, env_edges, n_obj) for i in oedges]
            b.pair(og, sg, min(mus))
        mu_g = min(friction.gripper_mu("l", i, n_obj) for i in oedges)
        for fg in finger_geoms + palm_geoms:
            b.pair(og, fg, mu_g)
    mu_fs = friction.environment if o.env_finger_mu is None else o.env_finger_mu
    for fg in finger_geoms + palm_geoms:
        for sg, _ in solid_geoms:
            b.pair(fg, sg, mu_fs)

    # -- drives
    act = ET.SubElement(root, "actuator")
    kp = o.hand_kp
    kv = 2.0 * math.sqrt(kp * o.hand_mass_kg)
    kp_rot = kp * lever * lever
    kv_rot = 2.0 * math.sqrt(kp_rot * o.hand_mass_kg * lever * lever)
    ET.SubElement(act, "position", name="hand_x", joint="hand_x", kp=_fmt(kp), kv=_fmt(kv))
    ET.SubElement(act, "position", name="hand_z", joint="hand_z", kp=_fmt(kp), kv=_fmt(kv))
    ET.SubElement(act, "position", name="hand_theta", joint="hand_theta", kp=_fmt(kp_rot), kv=_fmt(kv_rot))
    if variable:
        kf = o.finger_kp
        kvf = 2.0 * math.sqrt(kf * o.finger_mass_kg)
        for f in (1, 2):
            ET.SubElement(act, "position", name=f"finger{f}", joint=f"finger{f}", kp=_fmt(kf), kv=_fmt(kvf),
                          forcelimited="true", forcerange=_fmt(-max_force, max_force))
    ET.indent(root)
    return ET.tostring(root, encoding="unicode"), max_force, mf is not None


def build_model(world: World, options: ModelOptions = ModelOptions()) -> SimModel:
    """Compile the world into a :class:`SimModel` (imports ``mujoco``)."""
    import mujoco

    xml, max_force, from_scenario = build_xml(world, options)
    model = mujoco.MjModel.from_xml_string(xml)

    def qadr(name: str) -> int:
        return int(model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)])

    def aid(name: str) -> int:
        return int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name))

    lo, hi = world.gripper.width_range
    variable = hi > lo
    return SimModel(
        model=model,
        xml=xml,
        object_qpos=(qadr("object_x"), qadr("object_z"), qadr("object_theta")),
        hand_qpos=(qadr("hand_x"), qadr("hand_z"), qadr("hand_theta")),
        hand_actuators=(aid("hand_x"), aid("hand_z"), aid("hand_theta")),
        finger_qpos=(qadr("finger1"), qadr("finger2")) if variable else (),
        finger_actuators=(aid("finger1"), aid("finger2")) if variable else (),
        variable_width=variable,
        max_force=max_force,
        max_force_from_scenario=from_scenario,
    )


def pose_to_qpos(pose: Pose) -> tuple[float, float, float]:
    """A planar pose (mm, radians) as the three joint positions (m, m, rad)."""
    return pose.x * MM, pose.y * MM, pose.theta
