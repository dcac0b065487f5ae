"""The plan validator: rules 0-9 of ``ldhp-plan/1`` (``docs/formats/plan.md``).

:func:`validate_plan` checks a :class:`~ldhp_tamp.plan.Plan` against a
:class:`~ldhp_tamp.scenario.Scenario` from the two values alone (no planner internals),
with the spec's tolerances (:data:`~geometry.tolerances.VALIDATE_TOL` for contact and
position, :data:`~geometry.tolerances.VALIDATE_TOL_DEG` for angles). The choices the spec
leaves open are listed in ``docs/design/validation.md``; in short:

0. **Known primitives**: each step's primitive is an action of the scenario's domain
   (matched case-insensitively, as PDDL names are) and its family is the action's
   (MoveObject iff an effect changes ``(at ?s)``), read by the light
   :mod:`ldhp_tamp.domain_info` (no unified-planning). An unknown domain file is bad
   input (:class:`~ldhp_tamp.errors.DomainError`), not a broken rule.
1. **Ends** also covers the file (``ldhp-plan/1``, status ``solved``, at least one step,
   no empty step) and the joins between steps. Under ``goal_release`` a finger *touches*
   the object if it declares a contact or lies within 1 mm of it.
2. **Continuity** is checked over the whole waypoint sequence, so across step joins too;
   every width lies in the gripper's ``spacing``/``opening`` range within 1 mm.
3. **No penetration** uses the overlap rule of :mod:`geometry.collision` per solid; a
   finger and the palm are one rigid hand and are not tested against each other.
4. **Real finger contacts**: distances to the object's boundary and the finger's boundary.
5. **Move-object**: per finger, declared at every waypoint of the step or at none; at least
   one finger declared (at every waypoint); each declared contact, in the object frame,
   within 1 mm of where it was at the step's first waypoint.
6. **Adjust-grasp**: the object pose within 1 mm and 1 degree of the step's first one.
7. **Support**: every contact within 1 mm (and every declared finger contact) with its
   full Coulomb cone, tested by :func:`geometry.mechanics.feasible_batch` at margin 0.
8. **Support with the motion's contact modes**: rule 7's contacts, each SLIDING (the
   one cone edge opposing the slip) when its two bodies' material points drift apart
   tangentially by more than :data:`SLIP_TOL` = 0.1 mm over the motion to the next
   waypoint (over the whole sequence, as rule 2), every other one STICKING.
9. **Finger force limit** (with the gripper's ``max_force``): rule 8's contacts (rule
   7's at the last waypoint) hold the weight ``mass x 9.81 N`` with every finger's total
   normal force at most ``max_force``, by the LP :func:`geometry.mechanics.bounded_support`.

Rules 7, 8 and 9 are nested (each checks a subset of the previous one's forces), so a
waypoint is reported under the first of them it breaks only.

A run of consecutive waypoints of one step that break the same check the same way is one
:class:`Violation` (``waypoint`` .. ``last_waypoint``, the message quoting the worst one),
so a systematic fault is one line, not a thousand. Indices are 0-based, as JSON paths.
A plan made for another scenario file (``scenario_sha256`` differs) gets a warning, not a
violation: the rules are about geometry, and the geometry is checked.

:func:`support_analysis` measures what rules 7-9 only decide: per waypoint the fraction of
the friction coefficients rule 8 needs and the finger forces that hold the object, and the
plan's support margin (``docs/design/validation.md``, "Support margin and finger forces").
"""

from __future__ import annotations

import logging
import math
import weakref
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np
import shapely

from geometry import collision, mechanics
from geometry.poses import BoolArray, IntArray, transform_points, wrap_angle
from geometry.shapes import FloatArray, segment_distances
from geometry.tolerances import MAX_WAYPOINT_STEP, VALIDATE_TOL, VALIDATE_TOL_DEG
from geometry.world import Environment, PolylineGripper, TwoPointGripper, World
from ldhp_tamp.domain_info import DomainActions, read_domain_actions
from ldhp_tamp.errors import DomainError
from ldhp_tamp.plan import PLAN_FORMAT, Family, Plan, PlanStatus
from ldhp_tamp.scenario import Scenario, find_domain

__all__ = ["RULES", "SLIP_TOL", "SUPPORT_ROUNDS", "PlanArrays", "PlanContacts", "SupportAnalysis", "ValidationReport",
           "Violation", "domain_actions", "finger_offsets", "format_violation", "plan_contacts", "present_groups", "press_table",
           "pressed_support", "rotate_vectors", "support_analysis", "support_analysis_of", "validate_plan"]

log = logging.getLogger(__name__)


#: Short names of the spec's rules, by number.
RULES: dict[int, str] = {
    0: "known primitives",
    1: "ends",
    2: "continuity and width",
    3: "no penetration",
    4: "real finger contacts",
    5: "move-object keeps the grasp",
    6: "adjust-grasp keeps the object still",
    7: "quasi-static support",
    8: "support with the motion's contact modes",
    9: "finger force limit",
}

#: Slack (mm, or radians) for numbers that went through a file rounded to 6 decimals
#: (positions move by up to ~1e-6 mm, vertices of a turned body a few times that): "at most
#: 5 mm" accepts 5.00001 mm. Far below every tolerance of the spec.
ROUNDING_SLACK = 1e-5

_TOL = VALIDATE_TOL + ROUNDING_SLACK
_TOL_RAD = math.radians(VALIDATE_TOL_DEG) + ROUNDING_SLACK
_STEP = MAX_WAYPOINT_STEP + ROUNDING_SLACK


@dataclass(frozen=True)
class Violation:
    """One broken rule.

    Attributes
    ----------
    rule : int
        The spec's rule number, 0..9.
    step : int or None
        0-based step index (``steps[i]`` in the file); ``None`` for the plan as a whole.
    waypoint : int or None
        0-based waypoint index within the step (the first of a run).
    message : str
        What is wrong, with the numbers.
    last_waypoint : int or None
        Last waypoint (inclusive) of a run of consecutive waypoints that break the rule
        the same way; ``None`` for a single waypoint.
    """

    rule: int
    step: int | None
    waypoint: int | None
    message: str
    last_waypoint: int | None = None

    def sort_key(self) -> tuple[int, int, int]:
        return (-1 if self.step is None else self.step, -1 if self.waypoint is None else self.waypoint, self.rule)


@dataclass(frozen=True)
class ValidationReport:
    """The verdict on a plan: valid iff no violation. Warnings do not count.

    The counts say what was checked: steps and waypoints, declared finger contacts
    (rule 4), quasi-static support tests (rule 7, with rule 8 at the waypoints where a
    contact slips) and the waypoints whose finger forces the LP bounded (rule 9).
    """

    valid: bool
    violations: tuple[Violation, ...]
    warnings: tuple[str, ...] = ()
    steps_checked: int = 0
    waypoints_checked: int = 0
    contacts_checked: int = 0
    support_checks: int = 0
    force_checks: int = 0

    def __post_init__(self) -> None:
        if self.valid != (not self.violations):
            raise ValueError("a report is valid exactly when it has no violation")

    @property
    def rules_broken(self) -> frozenset[int]:
        """The numbers of the rules with at least one violation."""
        return frozenset(v.rule for v in self.violations)


def format_violation(v: Violation, plan: Plan) -> str:
    """One line: ``rule 5 (move-object keeps the grasp), step 2 (air-move), waypoints 3-20: ...``."""
    where = [f"rule {v.rule} ({RULES.get(v.rule, '?')})"]
    if v.step is not None:
        prim = plan.steps[v.step].primitive if 0 <= v.step < len(plan.steps) else "?"
        where.append(f"step {v.step} ({prim})")
    if v.waypoint is not None:
        where.append(f"waypoint {v.waypoint}" if v.last_waypoint is None
                     else f"waypoints {v.waypoint}-{v.last_waypoint}")
    return ", ".join(where) + ": " + v.message


# --------------------------------------------------------------------------------------
# The plan as arrays
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PlanArrays:
    """All waypoints of the non-empty steps, in order, as arrays (radians, mm)."""

    obj: FloatArray  # (W, 3)
    grip: FloatArray  # (W, 3)
    width: FloatArray  # (W,)
    contacts: FloatArray  # (W, 2, 2), NaN where not declared
    declared: BoolArray  # (W, 2)
    step: IntArray  # (W,) step index
    local: IntArray  # (W,) waypoint index within its step

    @classmethod
    def of(cls, plan: Plan) -> "PlanArrays":
        """The plan's waypoints as arrays (read-only). The last plan's are kept: a judge
        validates a plan and then checks its forward problem, each from its arrays."""
        global _LAST_ARRAYS
        last, flat = _LAST_ARRAYS
        if last is not None and last() is plan:
            return flat
        flat = cls._of(plan)
        for arr in (flat.obj, flat.grip, flat.width, flat.contacts, flat.declared, flat.step, flat.local):
            arr.setflags(write=False)
        _LAST_ARRAYS = (weakref.ref(plan), flat)
        return flat

    @classmethod
    def _of(cls, plan: Plan) -> "PlanArrays":
        rows = [(i, j, w) for i, s in enumerate(plan.steps) for j, w in enumerate(s.waypoints)]
        n = len(rows)
        obj = np.array([w.object.as_array() for _, _, w in rows], dtype=float).reshape(n, 3)
        grip = np.array([w.gripper.as_array() for _, _, w in rows], dtype=float).reshape(n, 3)
        contacts = np.array([[c if c is not None else (np.nan, np.nan) for c in w.finger_contacts]
                             for _, _, w in rows], dtype=float).reshape(n, 2, 2)
        return cls(
            obj=obj, grip=grip,
            width=np.array([w.width for _, _, w in rows], dtype=float),
            contacts=contacts,
            declared=~np.isnan(contacts[..., 0]),
            step=np.array([i for i, _, _ in rows], dtype=np.int64),
            local=np.array([j for _, j, _ in rows], dtype=np.int64),
        )

    def __len__(self) -> int:
        return int(self.step.shape[0])

    def take(self, rows: slice) -> "PlanArrays":
        """The waypoints ``rows`` as a smaller :class:`PlanArrays`."""
        return PlanArrays(self.obj[rows], self.grip[rows], self.width[rows], self.contacts[rows],
                     self.declared[rows], self.step[rows], self.local[rows])

    def step_slice(self, i: int) -> slice:
        idx = np.flatnonzero(self.step == i)
        return slice(int(idx[0]), int(idx[-1]) + 1) if idx.size else slice(0, 0)


#: The last plan :meth:`PlanArrays.of` was asked for (a weak reference) and its arrays.
_LAST_ARRAYS: "tuple[weakref.ref[Plan] | None, PlanArrays | None]" = (None, None)


def _runs(bad: BoolArray, step: IntArray) -> Iterator[tuple[int, int]]:
    """(first, last) global indices of maximal runs of ``bad`` within one step."""
    idx = np.flatnonzero(bad)
    if idx.size == 0:
        return
    breaks = np.flatnonzero((np.diff(idx) != 1) | (np.diff(step[idx]) != 0))
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [idx.size - 1]])
    for a, b in zip(starts, ends):
        yield int(idx[a]), int(idx[b])


class _Findings:
    """Collects violations; groups runs of bad waypoints into one violation each."""

    def __init__(self, flat: PlanArrays):
        self.flat = flat
        self.violations: list[Violation] = []

    def add(self, rule: int, step: int | None, waypoint: int | None, message: str) -> None:
        self.violations.append(Violation(rule, step, waypoint, message))

    def flag(self, rule: int, bad: BoolArray, describe: Callable[[int], str],
             severity: FloatArray | None = None) -> None:
        """One violation per run of ``bad`` waypoints; ``describe(i)`` words waypoint ``i``
        (the run's worst by ``severity``, else its first)."""
        f = self.flat
        for i0, i1 in _runs(bad, f.step):
            worst = i0 if severity is None else i0 + int(np.argmax(severity[i0:i1 + 1]))
            msg = describe(worst)
            if i1 > i0 and worst != i0:
                msg += f" (worst at waypoint {f.local[worst]})"
            self.violations.append(Violation(rule, int(f.step[i0]), int(f.local[i0]), msg,
                                             int(f.local[i1]) if i1 > i0 else None))


def _mm(x: float) -> str:
    return f"{x:.2f} mm"


def _pt(p: FloatArray) -> str:
    return f"({p[0]:.2f}, {p[1]:.2f})"


def _pose_gap(a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Position distance (mm) and absolute wrapped angle difference (rad) of pose rows."""
    a2, b2 = np.atleast_2d(a), np.atleast_2d(b)
    return (np.hypot(a2[:, 0] - b2[:, 0], a2[:, 1] - b2[:, 1]),
            np.abs(np.asarray(wrap_angle(a2[:, 2] - b2[:, 2]))))


def _pose_differs(a: FloatArray, b: FloatArray) -> str | None:
    """``None`` when the poses agree within the tolerances, else the gap in words."""
    d, t = (float(x[0]) for x in _pose_gap(a, b))
    if d <= _TOL and t <= _TOL_RAD:
        return None
    return f"{_mm(d)} and {math.degrees(t):.2f} deg apart"


def _fmt_pose(p: FloatArray) -> str:
    return f"[{p[0]:.2f}, {p[1]:.2f}, {math.degrees(p[2]):.2f}]"


# --------------------------------------------------------------------------------------
# Geometry helpers
# --------------------------------------------------------------------------------------


def _to_frame(poses: FloatArray, points: FloatArray) -> FloatArray:
    """World points (B, ..., 2) into the frames of poses (B, 3)."""
    shape = (-1,) + (1,) * (points.ndim - 2)
    c = np.cos(poses[:, 2]).reshape(shape)
    s = np.sin(poses[:, 2]).reshape(shape)
    dx = points[..., 0] - poses[:, 0].reshape(shape)
    dy = points[..., 1] - poses[:, 1].reshape(shape)
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)


def rotate_vectors(poses: FloatArray, vectors: FloatArray) -> FloatArray:
    """Body directions (..., 2) (broadcast against B) into the world, for poses (B, 3)."""
    v = np.asarray(vectors, dtype=float)
    shape = (-1,) + (1,) * (v.ndim - 2)
    c = np.cos(poses[:, 2]).reshape(shape)
    s = np.sin(poses[:, 2]).reshape(shape)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def finger_offsets(width: FloatArray) -> FloatArray:
    """(B, 2, 2): the shift of finger 1 and finger 2 in the gripper frame."""
    z = np.zeros_like(width)
    return np.stack([np.stack([-width / 2, z], -1), np.stack([width / 2, z], -1)], axis=1)


@dataclass(frozen=True, eq=False)
class _FingerBoundary:
    """Where a point is relative to each finger's boundary, batched over waypoints."""

    distance: FloatArray  # (B, 2) distance to finger k's boundary
    normals: FloatArray  # (B, 2, E, 2) outward boundary normals (world) near the point
    near: BoolArray  # (B, 2, E) which of those normals apply (within tolerance)


def _finger_boundary(world: World, grip: FloatArray, width: FloatArray, points: FloatArray) -> _FingerBoundary:
    """Distance from ``points`` (B, 2 fingers, 2) to each finger's boundary, and the
    finger's outward normals there (two-point: the radial direction; polyline: every
    finger edge within tolerance of the point)."""
    g = world.gripper
    off = finger_offsets(width)
    local = _to_frame(grip, points) - off  # in each finger's own frame (B, 2, 2)
    if isinstance(g, TwoPointGripper):
        rho = np.linalg.norm(local, axis=-1)
        radial = local / np.where(rho > 0, rho, 1.0)[..., None]
        return _FingerBoundary(np.abs(rho - g.finger_radius), rotate_vectors(grip, radial)[:, :, None, :],
                               (rho > 0)[..., None])
    assert isinstance(g, PolylineGripper)
    dist = np.empty(points.shape[:2])
    normals, near = [], []
    for k, poly in enumerate((g.mirrored_finger, g.finger)):
        d = segment_distances(local[:, k], poly.edges)[0]  # (B, E)
        dist[:, k] = d.min(axis=1)
        normals.append(rotate_vectors(grip, np.broadcast_to(poly.normals, (grip.shape[0],) + poly.normals.shape)))
        near.append(d <= _TOL)
    return _FingerBoundary(dist, np.stack(normals, axis=1), np.stack(near, axis=1))


def _solid_label(env: Environment, k: int) -> str:
    name = env.solids[k].name
    return f"solid {name!r}" if name else f"solid {k + 1}"


# --------------------------------------------------------------------------------------
# Rule 7: quasi-static support
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class PlanContacts:
    """The contacts present at each waypoint, as candidate normals (force directions on
    the object) at points, each with a friction coefficient; ``on`` marks those present."""

    points: FloatArray  # (B, C, 2)
    normals: FloatArray  # (B, C, 2) unit, pointing into the object
    mu: FloatArray  # (B, C)
    on: BoolArray  # (B, C)
    labels: tuple[str, ...]  # (C,) the contact each candidate belongs to
    finger: IntArray  # (C,) the finger (0, 1) of a finger candidate, -1 for the environment


def plan_contacts(world: World, flat: PlanArrays) -> PlanContacts:
    """Every contact of rule 7 at every waypoint, with its candidate normals.

    - object vertex ``v_i`` within tolerance of environment edge ``e_j``: at the vertex,
      normal ``e_j``'s outward normal;
    - environment vertex ``ve_j`` within tolerance of object edge ``l_i``: at the vertex,
      normal ``l_i``'s inward normal;
    - declared finger contact: near an object vertex (within tolerance), the finger's
      outward boundary normal there (two-point: radial; polyline: each finger edge within
      tolerance); otherwise the inward normal of each object edge within tolerance. A
      contact rule 4 rejects (no feature within tolerance) takes the nearest object edge's.
    """
    obj, env, fr = world.object, world.environment, world.friction
    poly = obj.polygon
    n, m, b = len(poly), env.m, len(flat)
    pts, nrm, mus, ons, labels, owner = [], [], [], [], [], []

    def add(p: FloatArray, nv: FloatArray, mu: FloatArray, on: BoolArray, names: list[str], finger: int = -1) -> None:
        c = on.shape[1]
        pts.append(np.broadcast_to(p, (b, c, 2)))
        nrm.append(np.broadcast_to(nv, (b, c, 2)))
        mus.append(np.broadcast_to(mu, (b, c)))
        ons.append(on)
        labels.extend(names)
        owner.extend([finger] * c)

    # Object vertices on environment edges.
    verts = transform_points(flat.obj, poly.vertices)  # (B, N, 2)
    d_ve = segment_distances(verts, env.edges)[0]  # (B, N, M)
    mu_ve = np.array([[fr.environment_mu("v", i, "e", j, n_object=n) for j in range(m)] for i in range(n)])
    add(np.repeat(verts, m, axis=1), np.tile(env.normals, (n, 1)), mu_ve.reshape(-1),
        (d_ve <= _TOL).reshape(b, n * m), [f"v{i + 1}-e{j + 1}" for i in range(n) for j in range(m)])

    # Environment vertices on object edges.
    ev_local = _to_frame(flat.obj, np.broadcast_to(env.vertices, (b, m, 2)))  # (B, M, 2)
    d_ev = segment_distances(ev_local, poly.edges)[0]  # (B, M, N)
    inward = rotate_vectors(flat.obj, np.broadcast_to(-poly.normals, (b, n, 2)))  # (B, N, 2)
    mu_ev = np.array([[fr.environment_mu("l", i, "ve", j, world_edges=env.vertex_edges, n_object=n)
                       for i in range(n)] for j in range(m)])
    add(np.repeat(env.vertices, n, axis=0), np.tile(inward, (1, m, 1)), mu_ev.reshape(-1),
        (d_ev <= _TOL).reshape(b, m * n), [f"l{i + 1}-ve{j + 1}" for j in range(m) for i in range(n)])

    # Declared finger contacts.
    if flat.declared.any():
        p = np.nan_to_num(flat.contacts)  # (B, 2, 2)
        q = _to_frame(flat.obj, p)  # object frame
        d_edge = segment_distances(q, poly.edges)[0]  # (B, 2, N)
        d_vert = np.linalg.norm(q[:, :, None, :] - poly.vertices, axis=-1)  # (B, 2, N)
        at_vertex = (d_vert <= _TOL).any(axis=-1)  # (B, 2)
        nearest_vertex = np.argmin(d_vert, axis=-1)
        fb = _finger_boundary(world, flat.grip, flat.width, p)
        mu_l = np.array([fr.gripper_mu("l", i, n) for i in range(n)])
        mu_v = np.array([fr.gripper_mu("v", i, n) for i in range(n)])
        nearest_edge = np.argmin(d_edge, axis=-1)
        for k in range(2):
            dec = flat.declared[:, k]
            on_edge = (d_edge[:, k] <= _TOL) & (dec & ~at_vertex[:, k])[:, None]  # (B, N)
            on_finger = fb.near[:, k] & (dec & at_vertex[:, k])[:, None]  # (B, E)
            fallback = dec & ~on_edge.any(axis=1) & ~on_finger.any(axis=1)
            on_edge |= fallback[:, None] & (np.arange(n) == nearest_edge[:, k][:, None])
            label = f"finger {k + 1}"
            add(p[:, k, None, :], inward, mu_l, on_edge, [label] * n, k)
            e = on_finger.shape[1]
            add(p[:, k, None, :], fb.normals[:, k], mu_v[nearest_vertex[:, k]][:, None] * np.ones(e),
                on_finger, [label] * e, k)

    return PlanContacts(np.concatenate(pts, 1), np.concatenate(nrm, 1), np.concatenate(mus, 1),
                     np.concatenate(ons, 1), tuple(labels), np.array(owner, dtype=np.int64))


@dataclass(frozen=True, eq=False)
class PresentGroup:
    """Waypoints with the same number ``k`` of contact candidates present: their indices
    ``rows`` and, per row, the ``k`` columns present, in order (``cols``, (r, k))."""

    rows: IntArray
    cols: IntArray

    def take(self, a: np.ndarray) -> np.ndarray:
        """The present columns of ``a`` (B, C) or (B, C, 2) at ``rows``: (r, k) or (r, k, 2)."""
        return np.take_along_axis(a[self.rows], self.cols[..., None] if a.ndim == 3 else self.cols, axis=1)


def present_groups(on: BoolArray, where: BoolArray | None = None) -> Iterator[PresentGroup]:
    """The rows of ``on`` (B, C) with something present (and ``where``, if given), grouped
    by how many columns are present: dense (r, k) batches for the cone tests and LPs."""
    count = on.sum(axis=1)
    keep = count > 0 if where is None else (count > 0) & where
    for kc in np.unique(count[keep]):
        rows = np.flatnonzero(keep & (count == kc))
        yield PresentGroup(rows, np.argsort(~on[rows], axis=1, kind="stable")[:, :kc])


#: Waypoints per block of rules 7-9 (bounds the memory for large environments).
_BLOCK = 1024

#: Rule 8: a contact whose two bodies' material points drift apart tangentially by more
#: than this (mm) over the motion to the next waypoint is sliding.
SLIP_TOL = 0.1


@dataclass(frozen=True, eq=False)
class _Motion:
    """The contact modes of the motion from each waypoint to the next (rule 8), per
    contact candidate of :class:`PlanContacts`."""

    sliding: BoolArray  # (B, C) present and drifting more than SLIP_TOL tangentially
    slide_dirs: FloatArray  # (B, C, 2) the object's tangential slip direction where sliding
    drift: FloatArray  # (B, C) tangential drift along t = (-n_y, n_x) (mm, object relative to the other body)


def _motion(world: World, flat: PlanArrays, rows: IntArray, c: PlanContacts) -> _Motion:
    """Rule 8's contact modes at waypoints ``rows`` (global indices) of the contacts
    ``c`` present there, for the motion to the next waypoint (none after the last).

    The object's material point at a contact point p is p carried by the object's rigid
    motion; a finger's is p carried by the gripper's rigid motion plus that finger's own
    shift by the width change (finger 1 by -dw/2, finger 2 by +dw/2 along the gripper's
    x axis); an environment solid's stays at p. The drift is the object's material point
    relative to the other body's, along the candidate's tangent.
    """
    nxt = np.minimum(rows + 1, len(flat) - 1)
    has_next = rows + 1 < len(flat)
    d = mechanics.pose_displacements(c.points, flat.obj[rows], flat.obj[nxt])[0]  # (B, C, 2)
    if (c.finger >= 0).any():
        dg = mechanics.pose_displacements(c.points, flat.grip[rows], flat.grip[nxt])[0]
        shift = rotate_vectors(flat.grip[nxt], finger_offsets(flat.width[nxt] - flat.width[rows]))  # (B, 2, 2)
        finger = c.finger >= 0
        d = d - np.where(finger[None, :, None], dg + shift[:, np.clip(c.finger, 0, 1), :], 0.0)
    t = np.stack([-c.normals[..., 1], c.normals[..., 0]], axis=-1)
    drift = (d * t).sum(axis=-1)
    modes = mechanics.classify_contacts(
        c.normals, drift[..., None] * t, 0.0, world.object.length_scale,
        mechanics.ModeTolerances(relative=0.0, absolute=SLIP_TOL + ROUNDING_SLACK),
        present=c.on & has_next[:, None])
    return _Motion(modes.codes == mechanics.ContactMode.SLIDING, np.asarray(modes.slide_dirs), drift)


@dataclass(frozen=True, eq=False)
class _SupportBatch:
    """Waypoints with the same number of contacts present, as dense batches: rule 7's
    contacts (all sticking) and rule 8's (the motion's contact modes)."""

    rows: IntArray  # (r,) global waypoint indices
    fingers: IntArray  # (r, k) the finger of each contact present, -1 for the environment
    full: mechanics.Contacts  # every contact with its whole cone
    moving: mechanics.Contacts  # the contacts that slip over the motion to the next waypoint SLIDING
    slips: BoolArray  # (r,) some contact slips
    com: FloatArray  # (r, 2) the world centre of mass


#: The support batches of each plan's arrays still in use (the judge's validation and its
#: forward problem's presses ask for the same ones).
_BATCHES: "weakref.WeakKeyDictionary[PlanArrays, tuple[World, list[_SupportBatch]]]" = weakref.WeakKeyDictionary()


def _support_batches(world: World, flat: PlanArrays) -> list[_SupportBatch]:
    """:func:`_batches_of`, kept while ``flat`` is in use (its consumers read them)."""
    hit = _BATCHES.get(flat)
    if hit is not None and hit[0] is world:
        return hit[1]
    out = list(_batches_of(world, flat))
    _BATCHES[flat] = (world, out)
    return out


def _batches_of(world: World, flat: PlanArrays) -> Iterator[_SupportBatch]:
    """Every waypoint with a contact present, block by block (``_BLOCK`` waypoints) and
    grouped by how many (:func:`present_groups`)."""
    n_wp = len(flat)
    com = transform_points(flat.obj, world.object.com)[:, 0] if n_wp else np.zeros((0, 2))
    for start in range(0, n_wp, _BLOCK):
        block = slice(start, min(start + _BLOCK, n_wp))
        c = plan_contacts(world, flat.take(block))
        mo = _motion(world, flat, np.arange(block.start, block.stop), c)
        for grp in present_groups(c.on):
            take = grp.take
            points, normals, mu, sliding = take(c.points), take(c.normals), take(c.mu), take(mo.sliding)
            modes = np.where(sliding, mechanics.ContactMode.SLIDING, mechanics.ContactMode.STICKING).astype(np.int8)
            yield _SupportBatch(start + grp.rows, c.finger[grp.cols], mechanics.Contacts.make(points, normals, mu),
                                mechanics.Contacts.make(points, normals, mu, modes, take(mo.slide_dirs)),
                                sliding.any(axis=1), com[block][grp.rows])


@dataclass(frozen=True, eq=False)
class _Support:
    """Rules 7-9 at every waypoint."""

    rule7: BoolArray  # (W,) full cones balance the weight
    rule8: BoolArray  # (W,) the motion's contact modes balance it (= rule7 where nothing slides)
    rule9: BoolArray  # (W,) ... with every finger's normal force within max_force (True without one)
    force: FloatArray  # (W,) least largest finger normal force (N) where the LP ran, else nan
    force_checks: int  # waypoints that needed the LP


def _support(world: World, flat: PlanArrays, max_force: float | None = None) -> _Support:
    """Rules 7, 8 and 9 at every waypoint.

    Rule 7: every contact candidate is a STICKING contact (full cone) of
    :func:`geometry.mechanics.feasible_batch` with margin 0: closed cone membership, so
    contacts that must carry no force do not spoil an equilibrium. Rule 8: the same with
    the contacts that slip over the motion to the next waypoint SLIDING (tested only
    where some contact slips and rule 7 holds). Rule 9 (with ``max_force``): the batched
    LP :func:`geometry.mechanics.bounded_support` with rule 8's modes, where rule 8 holds
    and a finger touches.
    """
    n_wp = len(flat)
    ok7 = np.zeros(n_wp, dtype=bool)
    ok8 = np.zeros(n_wp, dtype=bool)
    ok9 = np.ones(n_wp, dtype=bool)
    force = np.full(n_wp, np.nan)
    lps = 0
    scale = world.object.length_scale
    for b in _support_batches(world, flat):
        g = b.rows
        ok7[g] = mechanics.feasible_batch(b.full, b.com, scale, margin=0.0)
        ok8[g] = ok7[g]
        slips = ok7[g] & b.slips
        if slips.any():
            ok8[g[slips]] = mechanics.feasible_batch(b.moving.select(slips), b.com[slips], scale, margin=0.0)
        if max_force is None:
            continue
        need = ok8[g] & (b.fingers >= 0).any(axis=1)
        if need.any():
            r = mechanics.bounded_support(b.moving.select(need), b.com[need], scale, world.object.weight,
                                          b.fingers[need], max_force, margin=0.0)
            ok9[g[need]] = r.feasible
            force[g[need]] = r.max_finger_force
            lps += int(need.sum())
    return _Support(ok7, ok8, ok9, force, lps)


def press_table(plan: Plan) -> FloatArray:
    """(W, 2) per waypoint of :meth:`PlanArrays.of` and finger, the normal force (N) a
    step's press (:attr:`ldhp_tamp.plan.Step.press`) holds that finger at, ``nan``
    where the step asks for none. Presses are this planner's executor convention, not
    a rule of the spec: the validator's rules do not read them."""
    rows = []
    for step in plan.steps:
        row = [np.nan, np.nan]
        pr = step.press
        if pr is not None:
            row[pr.finger] = pr.force_n
        rows.extend([row] * len(step.waypoints))
    return np.array(rows, dtype=float).reshape(-1, 2)


def pressed_support(world: World, flat: PlanArrays, press: FloatArray) -> BoolArray:
    """(W,) whether, at each waypoint whose finger a press holds (``press``, from
    :func:`press_table`), rule 8's contacts and modes balance the weight with that
    finger's normal force exactly the press's (:func:`geometry.mechanics.bounded_support`
    with ``pressed``; the other finger's force bounded by ``max_force``); True at the
    other waypoints."""
    ok = np.ones(len(flat), dtype=bool)
    rows = np.isfinite(press).any(axis=1) & flat.declared.any(axis=1)
    if not rows.any():
        return ok
    max_force = getattr(world.gripper, "max_force", None)
    for b in _support_batches(world, flat):
        g = b.rows
        sel = rows[g]
        if not sel.any():
            continue
        r = mechanics.bounded_support(b.moving.select(sel), b.com[sel], world.object.length_scale,
                                      world.object.weight, b.fingers[sel], max_force, margin=0.0,
                                      pressed=press[g[sel]])
        ok[g[sel]] = r.feasible
    ok[np.isfinite(press).any(axis=1) & ~flat.declared.any(axis=1)] = False  # a press needs a contact
    return ok


#: Bisection rounds of :func:`support_analysis`: the friction fractions it reports are
#: the feasible ends of brackets of width 2**-24 (about 6e-8).
SUPPORT_ROUNDS = 24


@dataclass(frozen=True, eq=False)
class SupportAnalysis:
    """How much friction and squeeze a plan's quasi-static support needs, per waypoint.

    Waypoints are those of :meth:`PlanArrays.of` (the non-empty steps', joins twice), in
    order; ``step`` and ``waypoint`` give each one's indices in the file.

    Attributes
    ----------
    friction_needed : ndarray, shape (W,)
        The least fraction ``f`` of every friction coefficient (all contacts' ``mu``
        scaled by ``f`` together) with which rule 8 still holds at the waypoint (rule 7's
        full cones at the last): 0 where it holds frictionless, ``inf`` where it does not
        hold even at ``f = 1``, else the feasible end of a bisection bracket of width
        ``2**-rounds``. Finger forces are unbounded here (``max_force`` does not enter).
    finger_forces : ndarray, shape (W, 2, 2)
        Per finger ``[normal, tangential]`` (N) on the object in the plan spec's
        convention (tangential along the object edge's counter-clockwise direction): the
        force solution of :func:`geometry.mechanics.bounded_support` with rule 8's modes,
        the equilibrium whose largest finger normal force is least (a finger a step's
        press holds has that force: :func:`press_table`). ``nan`` for a finger
        without contact, and for both where no finger touches or no equilibrium exists.
    max_finger_force : ndarray, shape (W,)
        The largest finger normal force (N) of that equilibrium; ``nan`` where no LP ran
        (no finger touches) or it found no equilibrium.
    step, waypoint : ndarray of int, shape (W,)
        Each waypoint's step index and index within its step.
    """

    friction_needed: FloatArray
    finger_forces: FloatArray
    max_finger_force: FloatArray
    step: IntArray
    waypoint: IntArray

    @property
    def worst(self) -> int | None:
        """Index (into the arrays) of the waypoint needing the most friction, the first of
        equals; ``None`` for a plan without waypoints."""
        return int(np.argmax(self.friction_needed)) if self.friction_needed.size else None

    @property
    def margin(self) -> float:
        """``1 - max(friction_needed)``: the fraction of every friction coefficient the plan
        could lose and still balance the object at its worst waypoint (1 when no waypoint
        needs friction, ``-inf`` when some waypoint is not supported at all; ``nan``
        without waypoints)."""
        i = self.worst
        return math.nan if i is None else 1.0 - float(self.friction_needed[i])

    @property
    def worst_at(self) -> tuple[int, int] | None:
        """``(step, waypoint)`` of :attr:`worst`, as in the file."""
        i = self.worst
        return None if i is None else (int(self.step[i]), int(self.waypoint[i]))

    @property
    def largest_finger_force(self) -> float:
        """The largest finger normal force (N) over the plan's waypoints with an
        equilibrium; 0 when no finger ever touches."""
        f = self.max_finger_force[np.isfinite(self.max_finger_force)]
        return float(f.max()) if f.size else 0.0


def support_analysis(plan: Plan, scenario: Scenario, rounds: int = SUPPORT_ROUNDS, *,
                     worst_only: bool = False) -> SupportAnalysis:
    """The friction each waypoint needs and the finger forces that hold the object.

    Rule 8's contacts and modes (:func:`plan_contacts`, the motion to the next waypoint;
    rule 7's full cones at the last waypoint) at every waypoint. ``friction_needed`` is
    found by a bisection over all waypoints at once: each round one
    :func:`geometry.mechanics.feasible_batch` (margin 0, as rules 7-8) per number of
    contact candidates, with every ``mu`` scaled by the waypoint's midpoint. Feasibility
    is monotone in the scale for sticking contacts; a sliding contact's force turns with
    its ``mu``, and there the value is a scale at which rule 8 holds with a smaller one
    in the last bracket that does not. The forces are the LP
    :func:`geometry.mechanics.bounded_support` with the gripper's ``max_force`` (which
    does not change the solution: it minimises the largest finger normal force), on the
    waypoints where a finger touches and rule 8 holds.

    Parameters
    ----------
    plan : Plan
    scenario : Scenario
    rounds : int
        Bisection rounds (bracket width ``2**-rounds``).
    worst_only : bool
        Only :attr:`SupportAnalysis.margin`, ``worst`` and ``worst_at`` are wanted: a
        waypoint whose bracket lies wholly below another's leaves the bisection (it cannot
        be the worst), and its ``friction_needed`` is its bracket's upper end then, an
        upper bound below the worst's value. The worst waypoint and its value are the
        same as without.

    Returns
    -------
    SupportAnalysis

    Examples
    --------
    The spec's example lifts a 1 kg block pinched by its ends (gripper ``mu`` 0.6): in
    the air any friction holds it with enough squeeze, and the least squeeze is
    ``W / (2 mu)`` = 8.175 N per finger.

    >>> from pathlib import Path
    >>> from ldhp_tamp.plan import read_plan
    >>> from ldhp_tamp.scenario import load_scenario
    >>> spec = Path(__file__).resolve().parents[1] / "docs" / "formats" / "examples"  # in a checkout
    >>> a = support_analysis(read_plan(spec / "pick-plan.json"), load_scenario(spec / "pick.toml", check_planner=False))
    >>> round(a.margin, 4), a.worst_at, round(a.largest_finger_force, 3)
    (1.0, (2, 1), 8.175)
    """
    return support_analysis_of(PlanArrays.of(plan), press_table(plan), scenario.world, rounds,
                               worst_only=worst_only)


def support_analysis_of(flat: PlanArrays, press: FloatArray, world: World, rounds: int = SUPPORT_ROUNDS, *,
                        worst_only: bool = False) -> SupportAnalysis:
    """:func:`support_analysis` of a plan's waypoints (:meth:`PlanArrays.of`), presses
    (:func:`press_table`) and the scenario's world: plain arrays, which a helper process
    is sent (a plan's steps hold read-only mappings, which do not pickle)."""
    n_wp = len(flat)
    need = np.full(n_wp, np.inf)
    forces = np.full((n_wp, 2, 2), np.nan)
    largest = np.full(n_wp, np.nan)
    max_force = getattr(world.gripper, "max_force", None)
    scale = world.object.length_scale
    floor = [-math.inf]  # worst_only: a lower bound of the worst waypoint's value
    for b in _support_batches(world, flat):
        g = b.rows
        need[g] = _friction_needed(b.moving, b.com, scale, rounds, floor if worst_only else None)
        lp = np.isfinite(need[g]) & (b.fingers >= 0).any(axis=1)
        if lp.any():
            pr = press[g[lp]]
            r = mechanics.bounded_support(b.moving.select(lp), b.com[lp], scale, world.object.weight,
                                          b.fingers[lp], max_force, margin=0.0,
                                          pressed=pr if np.isfinite(pr).any() else None)
            forces[g[lp]] = r.finger_forces
            largest[g[lp]] = r.max_finger_force
    forces[~flat.declared] = np.nan  # a finger without contact has no force
    # No contact at all: the weight is not balanced (rule 7 fails), need stays inf.
    return SupportAnalysis(need, forces, largest, flat.step, flat.local)


def _friction_needed(contacts: mechanics.Contacts, com: FloatArray, scale: float, rounds: int,
                     floor: list[float] | None = None) -> FloatArray:
    """The least scale ``f`` in [0, 1] of every ``mu`` with which ``contacts`` balance the
    weight (closed cones), by vectorised bisection; ``inf`` where not even at 1.

    With ``floor`` (a one-item list: a lower bound of the largest value over every batch,
    raised here as brackets close), an instance whose bracket's upper end falls below it
    leaves the bisection with that upper end: only the largest value is exact."""
    out = np.full(contacts.batch, np.inf)
    ok = mechanics.feasible_batch(contacts, com, scale, margin=0.0)
    free = np.zeros(contacts.batch, dtype=bool)
    if ok.any():
        free[ok] = mechanics.feasible_batch(contacts.select(ok).with_mu(0.0), com[ok], scale, margin=0.0)
    out[free] = 0.0
    todo = np.flatnonzero(ok & ~free)
    if todo.size == 0:
        return out
    sub, com_s = contacts.select(todo), com[todo]
    lo, hi = np.zeros(todo.size), np.ones(todo.size)
    live = np.arange(todo.size)
    for _ in range(rounds):
        if floor is not None:  # brackets wholly below another's cannot hold the largest value
            floor[0] = max(floor[0], float(lo[live].max(initial=-math.inf)))
            live = live[hi[live] >= floor[0]]
            if not live.size:
                break
        mid = 0.5 * (lo[live] + hi[live])
        part = sub if live.size == todo.size else sub.select(live)
        f = mechanics.feasible_batch(part.with_mu(part.mu * mid[:, None]), com_s[live], scale, margin=0.0)
        hi[live] = np.where(f, mid, hi[live])
        lo[live] = np.where(f, lo[live], mid)
    out[todo] = hi
    return out


# --------------------------------------------------------------------------------------
# The rules
# --------------------------------------------------------------------------------------


def domain_actions(scenario: Scenario) -> DomainActions:
    """The actions and families of the domain ``scenario`` names (rule 0).

    ``settings.domain_path`` when the loader resolved it, else ``settings.domain``
    resolved by :func:`ldhp_tamp.scenario.find_domain` against the scenario file's folder.

    Raises
    ------
    DomainError
        The domain cannot be found or read (bad input, not a broken rule).
    """
    s = scenario.settings
    path = s.domain_path
    if path is None:
        path = find_domain(s.domain, scenario.path.parent if scenario.path is not None else None)
    if path is None:
        raise DomainError(f"{scenario.path or scenario.name}: planner.domain: unknown domain {s.domain!r}: "
                          "the plan's primitives cannot be checked (rule 0)")
    return read_domain_actions(path)


def _rule0(plan: Plan, domain: DomainActions, out: _Findings) -> None:
    where = f"domain {domain.name!r} ({domain.source})"
    for s, step in enumerate(plan.steps):
        family = domain.family(step.primitive)
        if family is None:
            out.add(0, s, None, f"primitive {step.primitive!r} is not an action of {where}; its actions: "
                    + ", ".join(domain.names()))
        elif family is not step.family:
            out.add(0, s, None, f"family is {step.family.value!r}, but {step.primitive!r} is "
                    f"{family.value} in {where}")


def _rule1(plan: Plan, scenario: Scenario, flat: PlanArrays, out: _Findings) -> None:
    first, last = 0, len(flat) - 1
    gap = _pose_differs(flat.obj[first], scenario.start.as_array())
    if gap:
        out.add(1, int(flat.step[first]), 0, f"first object pose {_fmt_pose(flat.obj[first])} is not the "
                f"scenario's start {_fmt_pose(scenario.start.as_array())} ({gap})")
    gap = _pose_differs(flat.obj[last], scenario.goal.as_array())
    if gap:
        out.add(1, int(flat.step[last]), int(flat.local[last]), f"last object pose {_fmt_pose(flat.obj[last])} "
                f"is not the scenario's goal {_fmt_pose(scenario.goal.as_array())} ({gap})")
    g = scenario.start_grasp
    if g is not None:
        gap = _pose_differs(flat.grip[first], g.pose.as_array())
        if gap:
            out.add(1, int(flat.step[first]), 0, f"first gripper pose {_fmt_pose(flat.grip[first])} is not the "
                    f"scenario's start_grasp {_fmt_pose(g.pose.as_array())} ({gap})")
        if abs(flat.width[first] - g.width) > _TOL:
            out.add(1, int(flat.step[first]), 0, f"first width {flat.width[first]:.2f} mm is not the "
                    f"start_grasp width {g.width:.2f} mm")
    if scenario.goal_release:
        for k in np.flatnonzero(_touching(scenario.world, flat, last)):
            out.add(1, int(flat.step[last]), int(flat.local[last]),
                    f"goal_release: finger {k + 1} still touches the object at the last waypoint")
    # Joins: a step's first waypoint equals the previous (non-empty) step's last one.
    starts = np.flatnonzero(np.diff(flat.step) != 0) + 1
    for i in starts:
        problems = []
        for what, a in (("object pose", flat.obj), ("gripper pose", flat.grip)):
            gap = _pose_differs(a[i], a[i - 1])
            if gap:
                problems.append(f"{what} {gap}")
        if abs(flat.width[i] - flat.width[i - 1]) > _TOL:
            problems.append(f"width {flat.width[i - 1]:.2f} -> {flat.width[i]:.2f} mm")
        for k in range(2):
            da, db = flat.declared[i - 1, k], flat.declared[i, k]
            if da != db:
                problems.append(f"finger {k + 1} contact {'declared' if db else 'not declared'} here, "
                                f"{'declared' if da else 'not declared'} there")
            elif da and np.linalg.norm(flat.contacts[i, k] - flat.contacts[i - 1, k]) > _TOL:
                problems.append(f"finger {k + 1} contact {_pt(flat.contacts[i - 1, k])} -> {_pt(flat.contacts[i, k])}")
        if problems:
            prev = int(flat.step[i - 1])
            out.add(1, int(flat.step[i]), 0, f"does not join step {prev}'s last waypoint: " + "; ".join(problems))


def _touching(world: World, flat: PlanArrays, i: int) -> BoolArray:
    """(2,) whether each finger touches the object at waypoint ``i``: a declared contact,
    or the finger within tolerance of the object."""
    obj = shapely.Polygon(transform_points(flat.obj[i:i + 1], world.object.polygon.vertices)[0])
    fs = collision.finger_shapes(world.gripper, flat.grip[i:i + 1], flat.width[i:i + 1])
    if fs.centres is not None:
        gaps = shapely.distance(shapely.points(fs.centres[0]), obj) - float(fs.radius)
    else:
        assert fs.polygons is not None
        gaps = shapely.distance(shapely.polygons(fs.polygons[0]), obj)
    return flat.declared[i] | (np.asarray(gaps) <= _TOL)


def _rule2(world: World, flat: PlanArrays, out: _Findings) -> None:
    def moves(points: FloatArray) -> FloatArray:
        d = np.zeros(points.shape[0])
        if points.shape[0] > 1:
            d[1:] = np.linalg.norm(np.diff(points, axis=0), axis=-1).reshape(points.shape[0] - 1, -1).max(axis=1)
        return d

    obj_move = moves(transform_points(flat.obj, world.object.polygon.vertices))
    fs = collision.finger_shapes(world.gripper, flat.grip, flat.width)
    finger_move = moves(fs.centres if fs.centres is not None else fs.polygons)
    width_move = np.concatenate([[0.0], np.abs(np.diff(flat.width))])
    what = "finger centre" if fs.centres is not None else "finger vertex"
    for name, d in (("object vertex", obj_move), (what, finger_move), ("width", width_move)):
        verb = "changes" if name == "width" else "moves"
        out.flag(2, d > _STEP, lambda i, d=d, name=name, verb=verb:
                 f"{name} {verb} {_mm(d[i])} since the previous waypoint (limit {_mm(MAX_WAYPOINT_STEP)})", d)
    lo, hi = world.gripper.width_range
    outside = np.maximum(lo - flat.width, flat.width - hi)
    word = "spacing" if isinstance(world.gripper, TwoPointGripper) else "opening"
    out.flag(2, outside > _TOL, lambda i: f"width {flat.width[i]:.2f} mm is outside the gripper's {word} "
             f"[{lo:g}, {hi:g}] mm (tolerance {_mm(VALIDATE_TOL)})", outside)


def _rule3(world: World, flat: PlanArrays, out: _Findings) -> None:
    tol = VALIDATE_TOL
    env = world.environment
    has_palm = isinstance(world.gripper, PolylineGripper) and world.gripper.palm is not None
    for k, solid in enumerate(env.solids):
        one = World(world.object, Environment((solid,)), world.gripper, world.friction)
        label = _solid_label(env, k)
        out.flag(3, collision.object_env_overlap(one, flat.obj, tol), lambda i, s=label: f"the object penetrates {s}")
        fingers = collision.finger_env_overlap(one, flat.grip, flat.width, tol)
        for f in range(2):
            out.flag(3, fingers[:, f], lambda i, s=label, f=f: f"finger {f + 1} penetrates {s}")
        if has_palm:
            out.flag(3, collision.palm_env_overlap(one, flat.grip, tol), lambda i, s=label: f"the palm penetrates {s}")
    fingers = collision.finger_object_overlap(world, flat.obj, flat.grip, flat.width, tol)
    for f in range(2):
        out.flag(3, fingers[:, f], lambda i, f=f: f"finger {f + 1} penetrates the object")
    if has_palm:
        out.flag(3, collision.palm_object_overlap(world, flat.obj, flat.grip, tol), lambda i: "the palm penetrates the object")
    out.flag(3, collision.fingers_overlap(world.gripper, flat.width, tol), lambda i: "the fingers penetrate each other")


def _rule4(world: World, flat: PlanArrays, out: _Findings) -> None:
    if not flat.declared.any():
        return
    p = np.nan_to_num(flat.contacts)
    d_obj = segment_distances(_to_frame(flat.obj, p), world.object.polygon.edges)[0].min(axis=-1)  # (B, 2)
    d_fin = _finger_boundary(world, flat.grip, flat.width, p).distance
    for k in range(2):
        worst = np.maximum(d_obj[:, k], d_fin[:, k])
        bad = flat.declared[:, k] & (worst > _TOL)
        out.flag(4, bad, lambda i, k=k: f"finger {k + 1} contact {_pt(flat.contacts[i, k])} is "
                 f"{_mm(d_obj[i, k])} from the object's boundary and {_mm(d_fin[i, k])} from the finger's "
                 f"(tolerance {_mm(VALIDATE_TOL)})", worst)


def _rule5(plan: Plan, flat: PlanArrays, out: _Findings) -> None:
    for s, step in enumerate(plan.steps):
        sl = flat.step_slice(s)
        if step.family is not Family.MOVE_OBJECT or sl.stop == sl.start:
            continue
        bad = np.zeros(len(flat), dtype=bool)
        dec = flat.declared[sl]
        bad[sl] = ~dec.any(axis=1)
        out.flag(5, bad, lambda i: "no finger touches the object (no declared finger contact)")
        q = _to_frame(flat.obj[sl], np.nan_to_num(flat.contacts[sl]))  # (n, 2, 2) object frame
        for k in range(2):
            bad[:] = False
            bad[sl] = dec[:, k] != dec[0, k]
            first = "declared" if dec[0, k] else "not declared"
            out.flag(5, bad, lambda i, k=k, first=first: f"finger {k + 1} contact is {first} at the step's first "
                     f"waypoint but {'not ' if first == 'declared' else ''}declared here")
            if not dec[:, k].any():
                continue
            ref = int(np.argmax(dec[:, k]))
            drift = np.zeros(len(flat))
            drift[sl] = np.where(dec[:, k], np.linalg.norm(q[:, k] - q[ref, k], axis=-1), 0.0)
            out.flag(5, drift > _TOL, lambda i, k=k, ref=ref: f"finger {k + 1} contact moves {_mm(drift[i])} in "
                     f"the object frame since waypoint {ref} (tolerance {_mm(VALIDATE_TOL)})", drift)


def _rule6(plan: Plan, flat: PlanArrays, out: _Findings) -> None:
    for s, step in enumerate(plan.steps):
        sl = flat.step_slice(s)
        if step.family is not Family.ADJUST_GRASP or sl.stop == sl.start:
            continue
        d, t = _pose_gap(flat.obj[sl], flat.obj[sl.start])
        bad = np.zeros(len(flat), dtype=bool)
        bad[sl] = (d > _TOL) | (t > _TOL_RAD)
        severity = np.zeros(len(flat))
        severity[sl] = np.maximum(d / VALIDATE_TOL, t / math.radians(VALIDATE_TOL_DEG))
        dd, tt = np.zeros(len(flat)), np.zeros(len(flat))
        dd[sl], tt[sl] = d, t
        out.flag(6, bad, lambda i: f"the object moves {_mm(dd[i])} and {math.degrees(tt[i]):.2f} deg since the "
                 f"step's first waypoint (tolerance {_mm(VALIDATE_TOL)}, {VALIDATE_TOL_DEG:g} deg)", severity)


def _present(c: PlanContacts) -> str:
    names = sorted({c.labels[j] for j in np.flatnonzero(c.on[0])}, key=lambda s: (s.startswith("finger"), s))
    return f"contacts present: {', '.join(names)}" if names else "the object touches nothing"


def _rules789(world: World, flat: PlanArrays, out: _Findings) -> _Support:
    """Rules 7-9. A waypoint that breaks rule 7 breaks rules 8 and 9 too (their cones are
    subsets), and one that breaks rule 8 breaks rule 9: each is reported under the first
    rule it breaks only."""
    max_force = getattr(world.gripper, "max_force", None)
    sup = _support(world, flat, max_force)

    def describe7(i: int) -> str:
        c = plan_contacts(world, flat.take(slice(i, i + 1)))
        return f"no contact forces in the friction cones balance the weight ({_present(c)})"

    def describe8(i: int) -> str:
        c = plan_contacts(world, flat.take(slice(i, i + 1)))
        mo = _motion(world, flat, np.array([i]), c)
        drift: dict[str, float] = {}
        for j in np.flatnonzero(mo.sliding[0]):
            drift[c.labels[j]] = max(drift.get(c.labels[j], 0.0), abs(float(mo.drift[0, j])))
        slips = ", ".join(f"{name} slips {_mm(d)}" for name, d in sorted(drift.items(), key=lambda kv: -kv[1]))
        return (f"over the motion to the next waypoint {slips} (more than {_mm(SLIP_TOL)}); with those "
                f"contacts sliding (force on the cone edge opposing the slip) no contact forces balance "
                f"the weight ({_present(c)})")

    def describe9(i: int) -> str:
        need = (f"needs a finger normal force of {sup.force[i]:.2f} N at least" if math.isfinite(sup.force[i])
                else "has no equilibrium the force LP could find")
        modes = "" if i == len(flat) - 1 else " with the motion's contact modes"
        return (f"holding the weight ({world.object.weight:.2f} N){modes} {need}, above the gripper's "
                f"max_force {max_force:g} N")

    out.flag(7, ~sup.rule7, describe7)
    out.flag(8, sup.rule7 & ~sup.rule8, describe8)
    out.flag(9, sup.rule7 & sup.rule8 & ~sup.rule9, describe9, np.nan_to_num(sup.force, nan=np.inf))
    return sup


# --------------------------------------------------------------------------------------
# Entry point
# --------------------------------------------------------------------------------------


def _warnings(plan: Plan, scenario: Scenario, flat: PlanArrays) -> list[str]:
    warn = []
    where = scenario.path if scenario.path is not None else scenario.name
    if plan.scenario_sha256 != scenario.sha256:
        warn.append(f"the plan was made for a scenario with sha256 {plan.scenario_sha256[:12]}..., "
                    f"not {where} (sha256 {scenario.sha256[:12]}...): checking against {where} anyway")
    if plan.scenario != scenario.name:
        warn.append(f"the plan names scenario {plan.scenario!r}, the scenario file is {scenario.name!r}")
    return warn


def validate_plan(plan: Plan, scenario: Scenario) -> ValidationReport:
    """Check a plan against its scenario: rules 0-9 of ``ldhp-plan/1``.

    Parameters
    ----------
    plan : Plan
    scenario : Scenario

    Returns
    -------
    ValidationReport
        ``valid`` iff no rule is broken; every violation found (all rules are checked,
        not only up to the first failure), sorted by step, waypoint and rule.

    Raises
    ------
    DomainError
        The scenario's domain cannot be found or read (rule 0 needs it).
    """
    world = scenario.world
    flat = PlanArrays.of(plan)
    out = _Findings(flat)
    if plan.format != PLAN_FORMAT:
        out.add(1, None, None, f"format is {plan.format!r}, not {PLAN_FORMAT!r}")
    if plan.status is not PlanStatus.SOLVED:
        out.add(1, None, None, f"status is {plan.status.value!r}" + (f": {plan.reason}" if plan.reason else ""))
    if not plan.steps:
        out.add(1, None, None, "the plan has no step")
    for s, step in enumerate(plan.steps):
        if not step.waypoints:
            out.add(1, s, None, "the step has no waypoint")
    warnings = _warnings(plan, scenario, flat) if len(flat) else []
    _rule0(plan, domain_actions(scenario), out)
    support_checks = force_checks = 0
    if len(flat):
        _rule1(plan, scenario, flat, out)
        _rule2(world, flat, out)
        _rule3(world, flat, out)
        _rule4(world, flat, out)
        _rule5(plan, flat, out)
        _rule6(plan, flat, out)
        force_checks = _rules789(world, flat, out).force_checks
        support_checks = len(flat)
    for w in warnings:
        log.info("warning: %s", w)
    violations = tuple(sorted(out.violations, key=Violation.sort_key))
    log.info("validated %d steps, %d waypoints: %d violations", len(plan.steps), len(flat), len(violations))
    return ValidationReport(
        valid=not violations,
        violations=violations,
        warnings=tuple(warnings),
        steps_checked=len(plan.steps),
        waypoints_checked=len(flat),
        contacts_checked=int(flat.declared.sum()),
        support_checks=support_checks,
        force_checks=force_checks,
    )
