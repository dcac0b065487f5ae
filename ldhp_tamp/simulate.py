"""Physics replay of a plan in MuJoCo: does the plan execute? (``docs/design/simulation.md``).

The validator checks a plan against quasi-static rules; :func:`simulate_plan` replays it
open-loop on a rigid-body simulation of the scenario (:mod:`ldhp_tamp.sim_model`): the
object is free in the plane, the hand follows the plan's gripper poses and widths slowly
(the fastest point of the hand at :attr:`SimOptions.speed_mm_s`), and nothing else holds
the object. The plan **executes** when the simulated object stays within
:attr:`SimOptions.position_tol_mm` and :attr:`SimOptions.angle_tol_deg` of the planned pose
at every waypoint (measured when the commanded motion reaches it) and, after
:attr:`SimOptions.settle_s` at the end, lies within the goal tolerances of the scenario's
goal; otherwise it **diverges** at the step of the first waypoint beyond the tolerances.

Like the validator, this module never imports the planner: only :mod:`geometry`,
:mod:`ldhp_tamp.scenario`, :mod:`ldhp_tamp.plan`, :mod:`ldhp_tamp.files`,
:mod:`ldhp_tamp.errors` and :mod:`ldhp_tamp.sim_model`. ``mujoco`` and ``matplotlib`` are
imported inside the functions that need them.
"""

from __future__ import annotations

import enum
import io
import json
import logging
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from geometry.poses import FloatArray, Pose, rotation, wrap_angle
from geometry.shapes import segment_distances
from geometry.world import PolylineGripper, TwoPointGripper, World
from ldhp_tamp.errors import InputError
from ldhp_tamp.files import write_bytes_atomic, write_text_atomic
from ldhp_tamp.plan import Plan, PlanStatus
from ldhp_tamp.scenario import Scenario
from ldhp_tamp.sim_model import MM, ModelOptions, SimModel, build_model

__all__ = [
    "REPORT_FORMAT",
    "SimOptions",
    "SimStatus",
    "SimulationReport",
    "WaypointRecord",
    "format_verdict",
    "report_to_json",
    "simulate_plan",
    "simulate_push",
    "simulate_rest",
    "write_gif",
    "write_report",
]

log = logging.getLogger(__name__)

#: The format tag of simulation report files.
REPORT_FORMAT = "ldhp-sim-report/1"


class SimStatus(str, enum.Enum):
    """Outcome of a replay."""

    EXECUTES = "executes"
    DIVERGES = "diverges"
    #: The plan has no step to replay (a failed solve).
    NOT_SIMULATED = "not-simulated"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class SimOptions:
    """How a plan is replayed and judged.

    Attributes
    ----------
    speed_mm_s : float
        Speed of the fastest point of the hand and fingers (mm/s) between waypoints; a
        rotation counts through the lever arm of the farthest finger or palm point.
    ramp_s : float
        Each step starts from rest and ends at rest: the speed ramps up and down
        linearly over this long (s).
    min_segment_s : float
        Least time spent between two waypoints (s), also when the hand does not move.
    start_hold_s : float
        Before the motion the object is held still at the start pose this long while the
        fingers take their commanded width (and squeeze, for a held start); with rigid
        fingers (a fixed width) it is free meanwhile, settling into its contacts.
    settle_s : float
        After the last waypoint the commands stay put this long before the goal check.
    preload_mm : float
        A finger that declares a contact is commanded this far inside the object (along
        the gripper's x axis), so a pinch squeezes; its force is capped by ``max_force``.
    press_speed_mm_s, press_limit_mm, press_settle_s : float
        A step's press (``parameters.press``, :class:`ldhp_tamp.plan.Press`): before the
        step's motion the hand moves along the pressed finger's contact normal (fixed in
        the gripper frame) at ``press_speed_mm_s`` until that finger's normal force on the
        object reaches the press's force, or ``press_limit_mm`` of travel (then the step
        goes on with what it has: the replay judges), and holds ``press_settle_s``; the
        step is replayed with that offset, which is taken back at the same speed after
        the step's last waypoint. A guarded move, as the paper's executor's "press down";
        the force is not controlled during the motion.
    position_tol_mm, angle_tol_deg : float
        Largest error of the object pose at a waypoint.
    goal_position_tol_mm, goal_angle_tol_deg : float
        Largest error to the scenario's goal after the settle.
    stop_after_s : float
        Simulated seconds run past the first divergence before stopping.
    model : ModelOptions
        Physical and numerical settings of the MuJoCo model (timestep, impratio,
        stiffness, force cap default).
    """

    speed_mm_s: float = 5.0
    ramp_s: float = 0.2
    min_segment_s: float = 0.02
    start_hold_s: float = 0.3
    settle_s: float = 1.0
    preload_mm: float = 2.5
    preload_single_contacts: bool = False
    press_speed_mm_s: float = 2.0
    press_limit_mm: float = 10.0
    press_settle_s: float = 0.1
    position_tol_mm: float = 15.0
    angle_tol_deg: float = 15.0
    goal_position_tol_mm: float = 10.0
    goal_angle_tol_deg: float = 10.0
    stop_after_s: float = 1.0
    model: ModelOptions = field(default_factory=ModelOptions)

    def __post_init__(self) -> None:
        for name in ("speed_mm_s", "ramp_s", "min_segment_s", "position_tol_mm", "angle_tol_deg",
                     "goal_position_tol_mm", "goal_angle_tol_deg"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        for name in ("press_speed_mm_s", "press_limit_mm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        for name in ("start_hold_s", "settle_s", "preload_mm", "stop_after_s", "press_settle_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a non-negative number, got {value!r}")


@dataclass(frozen=True)
class WaypointRecord:
    """The simulated state when the commanded motion reaches one waypoint.

    Poses are ``(x, y, theta)`` in mm and degrees; ``fingers`` are the finger frames'
    x along the gripper's x axis (mm; ``-w/2``, ``+w/2`` when they follow the command).
    """

    step: int
    waypoint: int
    time_s: float
    planned: tuple[float, float, float]
    simulated: tuple[float, float, float]
    position_error_mm: float
    angle_error_deg: float
    gripper: tuple[float, float, float]
    fingers: tuple[float, float]


@dataclass(frozen=True)
class SimulationReport:
    """The verdict of a replay and what it rests on.

    Attributes
    ----------
    status : SimStatus
    executes : bool
    diverged_step, diverged_waypoint : int or None
        0-based step (and waypoint within it) of the first waypoint beyond the
        tolerances; when every waypoint is within them but the settled end is not at the
        goal, the last step and waypoint.
    diverged_primitive : str or None
    reason : str
        One line: why it diverges, or what it achieved.
    records : tuple of WaypointRecord
        One per waypoint reached (the simulation stops ``stop_after_s`` past a divergence).
    final_pose : tuple or None
        Object pose after the settle (mm, degrees); ``None`` when stopped early.
    final_position_error_mm, final_angle_error_deg : float or None
        Distance of ``final_pose`` to the scenario's goal.
    simulated_s, wall_s : float
        Simulated time (the start hold and settle included) and wall-clock time.
    max_force_n : float or None
        The finger drives' force cap; ``None`` for a fixed width (rigid fingers, no cap);
        ``max_force_default`` when it is not the scenario's.
    presses : tuple
        One ``(step, asked N, reached N, offset mm)`` per press made (a step's
        ``parameters.press``).
    """

    status: SimStatus
    executes: bool
    diverged_step: int | None
    diverged_waypoint: int | None
    diverged_primitive: str | None
    reason: str
    records: tuple[WaypointRecord, ...]
    final_pose: tuple[float, float, float] | None
    final_position_error_mm: float | None
    final_angle_error_deg: float | None
    simulated_s: float
    wall_s: float
    max_force_n: float | None = None
    max_force_default: bool = False
    presses: tuple[tuple[int, float, float, float], ...] = ()

    @property
    def max_position_error_mm(self) -> float:
        return max((r.position_error_mm for r in self.records), default=0.0)

    @property
    def max_angle_error_deg(self) -> float:
        return max((r.angle_error_deg for r in self.records), default=0.0)


# --------------------------------------------------------------------------------------
# The commanded motion
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Commands:
    """The plan as joint targets, one row per waypoint (all steps, joins repeated)."""

    step: np.ndarray  # (W,) step index
    index: np.ndarray  # (W,) waypoint index within its step
    hand: FloatArray  # (W, 3) m, m, rad (unwrapped)
    fingers: FloatArray  # (W, 2) finger joint targets (m), preload included
    cost: FloatArray  # (W,) within-step cumulative travel of the fastest point (mm), 0 at a step's start


def _hand_points(gripper: Any, width: float) -> FloatArray:
    """Points of the fingers (and palm) in the gripper frame, whose motion sets the pace."""
    if isinstance(gripper, TwoPointGripper):
        r = gripper.finger_radius
        ring = np.array([[r, 0.0], [-r, 0.0], [0.0, r], [0.0, -r], [0.0, 0.0]])
        return np.concatenate([ring + [-width / 2.0, 0.0], ring + [width / 2.0, 0.0]])
    assert isinstance(gripper, PolylineGripper)
    f1, f2 = gripper.finger_polygons(width)
    parts = [f1, f2] + ([gripper.palm.vertices] if gripper.palm is not None else [])
    return np.concatenate(parts)


def _commands(plan: Plan, world: World, options: SimOptions) -> _Commands:
    steps, index, grip, width, declared, cost = [], [], [], [], [], []
    for s, step in enumerate(plan.steps):
        prev: FloatArray | None = None
        c = 0.0
        for k, w in enumerate(step.waypoints):
            pts = w.gripper.apply(_hand_points(world.gripper, w.width))
            if prev is not None:
                d = float(np.max(np.linalg.norm(pts - prev, axis=1)))
                c += max(d, options.speed_mm_s * options.min_segment_s)
            prev = pts
            steps.append(s)
            index.append(k)
            grip.append(w.gripper.as_array())
            width.append(w.width)
            declared.append([p is not None for p in w.finger_contacts])
            cost.append(c)
    g = np.array(grip, dtype=float).reshape(-1, 3)
    g[:, 2] = np.unwrap(g[:, 2])
    hand = np.column_stack([g[:, 0] * MM, g[:, 1] * MM, g[:, 2]])
    wd = np.array(width, dtype=float)
    dec = np.array(declared, dtype=bool).reshape(-1, 2)
    if options.preload_single_contacts:
        pre = dec * options.preload_mm
    else:  # a pinch only: both fingers declared
        pre = (dec & dec.all(axis=1, keepdims=True)) * options.preload_mm
    fingers = np.column_stack([(-wd / 2.0 + pre[:, 0]) * MM, (wd / 2.0 - pre[:, 1]) * MM])
    return _Commands(np.array(steps, dtype=int), np.array(index, dtype=int), hand, fingers,
                     np.array(cost, dtype=float))


def _profile(total: float, v: float, ramp: float) -> tuple[float, Any]:
    """A rest-to-rest motion over ``total`` (mm) at peak speed ``v`` (mm/s), speed ramping
    linearly over ``ramp`` s: its duration and the travel as a function of time."""
    if total <= 0.0:
        return 0.0, lambda t: np.zeros_like(t)
    a = v / ramp
    if total >= v * ramp:  # trapezoid
        duration = total / v + ramp

        def travel(t: FloatArray) -> FloatArray:
            t = np.clip(t, 0.0, duration)
            up = 0.5 * a * np.minimum(t, ramp) ** 2
            mid = v * np.clip(t - ramp, 0.0, duration - 2 * ramp)
            td = np.clip(t - (duration - ramp), 0.0, ramp)
            down = v * td - 0.5 * a * td ** 2
            return up + mid + down
    else:  # triangle
        half = math.sqrt(total / a)
        duration = 2 * half

        def travel(t: FloatArray) -> FloatArray:
            t = np.clip(t, 0.0, duration)
            up = 0.5 * a * np.minimum(t, half) ** 2
            td = np.clip(t - half, 0.0, half)
            down = a * half * td - 0.5 * a * td ** 2
            return up + down
    return duration, travel


# --------------------------------------------------------------------------------------
# Replay
# --------------------------------------------------------------------------------------


class _Runner:
    def __init__(self, sim: SimModel, world: World, options: SimOptions):
        import mujoco

        self.mj = mujoco
        self.sim, self.world, self.options = sim, world, options
        self.model = sim.model
        self.data = mujoco.MjData(sim.model)
        self.oq = list(sim.object_qpos)
        self.hq = list(sim.hand_qpos)
        self.fq = list(sim.finger_qpos)
        self.ha = list(sim.hand_actuators)
        self.fa = list(sim.finger_actuators)
        self.dt = float(sim.model.opt.timestep)
        lo, _hi = world.gripper.width_range
        self.fixed_fingers = (-lo / 2.0, lo / 2.0)
        names = [mujoco.mj_id2name(sim.model, mujoco.mjtObj.mjOBJ_GEOM, i) or "" for i in range(sim.model.ngeom)]
        self.object_geoms = frozenset(i for i, nm in enumerate(names) if nm.startswith("object_"))
        self.finger_geoms = tuple(frozenset(i for i, nm in enumerate(names) if nm.startswith(f"finger{f}_"))
                                  for f in (1, 2))
        self._wrench = np.zeros(6)

    def finger_force(self, finger: int) -> float:
        """The normal force (N) finger ``finger`` (0 or 1, the plan's) exerts on the object."""
        d, m = self.data, self.model
        mine, obj = self.finger_geoms[finger], self.object_geoms
        total = 0.0
        for i in range(d.ncon):
            con = d.contact[i]
            g1, g2 = int(con.geom1), int(con.geom2)
            if (g1 in mine and g2 in obj) or (g2 in mine and g1 in obj):
                self.mj.mj_contactForce(m, d, i, self._wrench)
                total += abs(float(self._wrench[0]))
        return total

    def press(self, hand: FloatArray, fingers: FloatArray, direction: FloatArray, finger: int, force: float
              ) -> tuple[float, float]:
        """The guarded move of a press: the hand target moves from ``hand`` along
        ``direction`` (unit, gripper frame) until ``finger``'s normal force reaches
        ``force``; returns the offset (mm) and the force reached (N)."""
        o = self.options
        step_mm = o.press_speed_mm_s * self.dt
        world_dir = rotation(float(hand[2])) @ direction
        delta = 0.0
        reached = self.finger_force(finger)
        while reached < force and delta < o.press_limit_mm:
            delta += step_mm
            target = np.array(hand, dtype=float)
            target[:2] += world_dir * delta * MM
            self.command(target, fingers)
            self.mj.mj_step(self.model, self.data)
            reached = self.finger_force(finger)
        self.hold(o.press_settle_s)
        return delta, self.finger_force(finger)

    def place(self, obj: Pose, hand: Sequence[float], fingers: Sequence[float] | None) -> None:
        d = self.data
        d.qpos[self.oq] = [obj.x * MM, obj.y * MM, obj.theta]
        d.qpos[self.hq] = hand
        d.ctrl[self.ha] = hand
        if self.fq and fingers is not None:
            d.qpos[self.fq] = fingers
            d.ctrl[self.fa] = fingers
        d.qvel[:] = 0.0
        self.mj.mj_forward(self.model, d)

    def command(self, hand: Sequence[float], fingers: Sequence[float]) -> None:
        self.data.ctrl[self.ha] = hand
        if self.fa:
            self.data.ctrl[self.fa] = fingers

    def hold_object(self, seconds: float) -> None:
        """Step with the object pinned (kinematically) where it is."""
        d = self.data
        q = d.qpos[self.oq].copy()
        for _ in range(int(round(seconds / self.dt))):
            self.mj.mj_step(self.model, d)
            d.qpos[self.oq] = q
            d.qvel[self.oq] = 0.0
        self.mj.mj_forward(self.model, d)

    def run(self, hand: FloatArray, fingers: FloatArray) -> None:
        """Step once per row of targets."""
        d, m, step = self.data, self.model, self.mj.mj_step
        ctrl, ha, fa = d.ctrl, self.ha, self.fa
        if fa:
            for h, f in zip(hand, fingers):
                ctrl[ha] = h
                ctrl[fa] = f
                step(m, d)
        else:
            for h in hand:
                ctrl[ha] = h
                step(m, d)

    def hold(self, seconds: float) -> None:
        for _ in range(int(round(seconds / self.dt))):
            self.mj.mj_step(self.model, self.data)

    @property
    def time(self) -> float:
        return float(self.data.time)

    def object_pose(self) -> tuple[float, float, float]:
        x, z, th = self.data.qpos[self.oq]
        return float(x / MM), float(z / MM), float(math.degrees(th))

    def gripper_pose(self) -> tuple[float, float, float]:
        x, z, th = self.data.qpos[self.hq]
        return float(x / MM), float(z / MM), float(math.degrees(th))

    def finger_offsets(self) -> tuple[float, float]:
        if self.fq:
            a, b = self.data.qpos[self.fq]
            return float(a / MM), float(b / MM)
        return self.fixed_fingers

    def finite(self) -> bool:
        return bool(np.all(np.isfinite(self.data.qpos)))


def _press_direction(world: World, step: Any, finger: int) -> FloatArray | None:
    """The pressed finger's contact normal into the object at the step's first waypoint,
    in the gripper frame: the inward normal of the object edge nearest the declared
    contact point; ``None`` when that finger declares no contact there."""
    w = step.waypoints[0]
    point = w.finger_contacts[finger]
    if point is None:
        return None
    poly = world.object.polygon
    edges = np.stack([poly.vertices, np.roll(poly.vertices, -1, axis=0)], axis=1)
    dist, _ = segment_distances(w.object.inverse().apply(np.asarray(point, dtype=float)[None])[0], edges)
    inward = -poly.normals[int(np.argmin(dist))]  # object frame
    return rotation(w.object.theta - w.gripper.theta) @ inward


def _errors(planned: Pose, simulated: tuple[float, float, float]) -> tuple[float, float]:
    pos = math.hypot(simulated[0] - planned.x, simulated[1] - planned.y)
    ang = abs(math.degrees(float(wrap_angle(math.radians(simulated[2]) - planned.theta))))
    return pos, ang


def _not_simulated(plan: Plan, reason: str) -> SimulationReport:
    return SimulationReport(SimStatus.NOT_SIMULATED, False, None, None, None, reason, (), None, None, None,
                            0.0, 0.0)


def simulate_plan(plan: Plan, scenario: Scenario, options: SimOptions = SimOptions()) -> SimulationReport:
    """Replay a plan open-loop in MuJoCo and judge whether it executes.

    Parameters
    ----------
    plan : Plan
        An ``ldhp-plan/1`` plan (:func:`ldhp_tamp.plan.read_plan`).
    scenario : Scenario
        Its scenario: the world simulated, the start pose the object is placed at and
        the goal it must end at.
    options : SimOptions

    Returns
    -------
    SimulationReport
        ``status`` :attr:`SimStatus.NOT_SIMULATED` for a plan without steps (a failed
        solve), else the verdict with one record per waypoint reached.
    """
    wall0 = time.perf_counter()
    if plan.status is not PlanStatus.SOLVED or not plan.waypoints:
        why = plan.reason or "no waypoint"
        return _not_simulated(plan, f"the plan is a {plan.status.value} plan with no motion to replay: {why}")
    if plan.scenario != scenario.name:
        log.warning("the plan was made for scenario %r, simulating it in %r", plan.scenario, scenario.name)
    world = scenario.world
    sim = build_model(world, options.model)
    cmd = _commands(plan, world, options)
    run = _Runner(sim, world, options)
    dt = run.dt

    # Start: the object at the scenario's start, the hand at the first waypoint.
    run.place(scenario.start, cmd.hand[0], [f for f in (-plan.waypoints[0].width / 2.0 * MM,
                                                         plan.waypoints[0].width / 2.0 * MM)])
    run.command(cmd.hand[0], cmd.fingers[0])
    if run.fa:  # finger drives close to their commanded width and preload first
        run.hold_object(options.start_hold_s)
    else:
        # Rigid fingers (a fixed width) have nothing to wait for: the object settles into
        # its contacts with the hand. Pinned, its contacts would carry nothing at the
        # release, and it would drop into them: task 1's inverse starts wedged at 97 % of
        # the friction cone, and that drop alone made it slide out.
        run.hold(options.start_hold_s)

    records: list[WaypointRecord] = []
    presses: list[tuple[int, float, float, float]] = []  # step, asked (N), reached (N), offset (mm)
    diverged: WaypointRecord | None = None
    why = ""
    stop_at = math.inf

    def record(i: int) -> WaypointRecord:
        s, k = int(cmd.step[i]), int(cmd.index[i])
        planned = plan.steps[s].waypoints[k].object
        simulated = run.object_pose()
        pos, ang = _errors(planned, simulated)
        r = WaypointRecord(s, k, run.time, planned.to_degrees(), simulated, pos, ang, run.gripper_pose(),
                           run.finger_offsets())
        records.append(r)
        return r

    def check(r: WaypointRecord) -> None:
        nonlocal diverged, why, stop_at
        if diverged is not None:
            return
        bad = []
        if not run.finite():
            bad.append("the simulation went unstable")
        if r.position_error_mm > options.position_tol_mm:
            bad.append(f"the object is {r.position_error_mm:.1f} mm from its planned position "
                       f"(tolerance {options.position_tol_mm:g} mm)")
        if r.angle_error_deg > options.angle_tol_deg:
            bad.append(f"{r.angle_error_deg:.1f} deg from its planned angle (tolerance {options.angle_tol_deg:g} deg)")
        if bad:
            diverged = r
            why = f"at waypoint {r.waypoint} " + ", ".join(bad)
            stop_at = run.time + options.stop_after_s

    # Walk the steps; each is a rest-to-rest motion over its waypoints.
    first = 0
    n = len(cmd.step)
    while first < n and run.time <= stop_at:
        last = first
        while last + 1 < n and cmd.step[last + 1] == cmd.step[first]:
            last += 1
        costs = cmd.cost[first:last + 1]
        duration, travel = _profile(float(costs[-1]), options.speed_mm_s, options.ramp_s)
        check(record(first))
        step = plan.steps[int(cmd.step[first])]
        pr = step.press if last > first else None
        press_dir = None if pr is None else _press_direction(world, step, pr.finger)
        offset = 0.0
        if pr is not None and press_dir is not None and diverged is None:
            offset, reached = run.press(cmd.hand[first], cmd.fingers[first], press_dir, pr.finger, pr.force_n)
            presses.append((int(cmd.step[first]), pr.force_n, reached, offset))
            log.debug("step %d: pressed finger %d to %.3g N (asked %.3g N) over %.3f mm", int(cmd.step[first]),
                      pr.finger, reached, pr.force_n, offset)
        if duration > 0.0 and last > first:
            # the time at which each waypoint of the step is reached
            tt = np.arange(1, int(math.ceil(duration / dt)) + 1) * dt
            c = travel(tt)
            u = np.interp(c, costs, np.arange(len(costs), dtype=float))
            rows = np.arange(first, last + 1)
            hand = np.column_stack([np.interp(u, np.arange(len(rows)), cmd.hand[rows, j]) for j in range(3)])
            fingers = np.column_stack([np.interp(u, np.arange(len(rows)), cmd.fingers[rows, j]) for j in range(2)])
            if offset > 0.0:
                assert press_dir is not None
                ca, sa = np.cos(hand[:, 2]), np.sin(hand[:, 2])
                hand[:, 0] += (ca * press_dir[0] - sa * press_dir[1]) * offset * MM
                hand[:, 1] += (sa * press_dir[0] + ca * press_dir[1]) * offset * MM
            reach = np.searchsorted(c, costs[1:] - 1e-9)  # first sample at which waypoint k is reached
            reach = np.minimum(reach, len(tt) - 1)
            start = 0
            for k, stop in enumerate(reach, start=1):
                run.run(hand[start:stop + 1], fingers[start:stop + 1])
                start = stop + 1
                check(record(first + k))
                if run.time > stop_at or not run.finite():
                    break
            if start < len(tt) and run.time <= stop_at and run.finite():
                run.run(hand[start:], fingers[start:])
        elif last > first:
            for k in range(first + 1, last + 1):
                check(record(k))
        if offset > 0.0 and run.finite():  # the press taken back, at the press's speed
            assert press_dir is not None
            back = np.linspace(offset, 0.0, max(2, int(math.ceil(offset / (options.press_speed_mm_s * dt)))))
            wd = rotation(float(cmd.hand[last, 2])) @ press_dir
            hand = np.repeat(cmd.hand[last][None, :], back.size, axis=0)
            hand[:, 0] += wd[0] * back * MM
            hand[:, 1] += wd[1] * back * MM
            run.run(hand, np.repeat(cmd.fingers[last][None, :], back.size, axis=0))
        run.command(cmd.hand[last], cmd.fingers[last])
        if not run.finite():
            break
        first = last + 1
    if diverged is not None and run.time < stop_at and run.finite():
        run.hold(min(options.stop_after_s, stop_at - run.time))

    final_pose: tuple[float, float, float] | None = None
    fpos = fang = None
    if diverged is None:
        run.hold(options.settle_s)
        if run.finite():
            final_pose = run.object_pose()
            fpos, fang = _errors(scenario.goal, final_pose)
            if fpos > options.goal_position_tol_mm or fang > options.goal_angle_tol_deg:
                diverged = records[-1]
                why = (f"after the final settle the object is {fpos:.1f} mm and {fang:.1f} deg from the goal "
                       f"(tolerances {options.goal_position_tol_mm:g} mm, {options.goal_angle_tol_deg:g} deg)")
        else:
            diverged = records[-1]
            why = "the simulation went unstable in the final settle"
    wall = time.perf_counter() - wall0
    common = dict(records=tuple(records), final_pose=final_pose, final_position_error_mm=fpos,
                  final_angle_error_deg=fang, simulated_s=run.time, wall_s=wall,
                  max_force_n=sim.max_force if sim.variable_width else None,
                  max_force_default=sim.variable_width and not sim.max_force_from_scenario,
                  presses=tuple(presses))
    if diverged is None:
        assert fpos is not None and fang is not None
        reason = (f"every waypoint within {options.position_tol_mm:g} mm / {options.angle_tol_deg:g} deg "
                  f"of the plan; ends {fpos:.1f} mm and {fang:.1f} deg from the goal")
        return SimulationReport(SimStatus.EXECUTES, True, None, None, None, reason, **common)  # type: ignore[arg-type]
    prim = plan.steps[diverged.step].primitive
    return SimulationReport(SimStatus.DIVERGES, False, diverged.step, diverged.waypoint, prim, why,
                            **common)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------


def format_verdict(report: SimulationReport) -> str:
    """One line: ``executes`` or ``diverges at step k (primitive): ...``."""
    if report.status is SimStatus.EXECUTES:
        return f"executes: {report.reason}"
    if report.status is SimStatus.NOT_SIMULATED:
        return f"not simulated: {report.reason}"
    return f"diverges at step {report.diverged_step} ({report.diverged_primitive}): {report.reason}"


def _r(x: float | None, nd: int = 4) -> float | None:
    return None if x is None else round(float(x), nd)


def report_to_json(report: SimulationReport, plan: str = "", scenario: str = "",
                   options: SimOptions | None = None) -> str:
    """The report as ``ldhp-sim-report/1`` JSON text (one waypoint per line)."""
    head: dict[str, Any] = {
        "format": REPORT_FORMAT,
        "plan": str(plan),
        "scenario": str(scenario),
        "status": report.status.value,
        "executes": report.executes,
        "diverged_step": report.diverged_step,
        "diverged_waypoint": report.diverged_waypoint,
        "diverged_primitive": report.diverged_primitive,
        "reason": report.reason,
        "final_pose": None if report.final_pose is None else [_r(v) for v in report.final_pose],
        "final_position_error_mm": _r(report.final_position_error_mm),
        "final_angle_error_deg": _r(report.final_angle_error_deg),
        "max_position_error_mm": _r(report.max_position_error_mm),
        "max_angle_error_deg": _r(report.max_angle_error_deg),
        "simulated_s": _r(report.simulated_s),
        "wall_s": _r(report.wall_s, 3),
        "max_force_n": report.max_force_n,
        "max_force_default": report.max_force_default,
        "presses": [{"step": st, "force_n": _r(asked), "reached_n": _r(got), "offset_mm": _r(off)}
                    for st, asked, got, off in report.presses],
    }
    if options is not None:
        head["options"] = asdict(options)
    lines = []
    for r in report.records:
        lines.append(json.dumps({
            "step": r.step, "waypoint": r.waypoint, "time_s": _r(r.time_s),
            "planned": [_r(v) for v in r.planned], "simulated": [_r(v) for v in r.simulated],
            "position_error_mm": _r(r.position_error_mm), "angle_error_deg": _r(r.angle_error_deg),
            "gripper": [_r(v) for v in r.gripper], "fingers": [_r(v) for v in r.fingers]}))
    text = json.dumps(head, indent=1)
    body = ",\n  ".join(lines)
    return text[:-2] + ',\n "waypoints": [\n  ' + body + "\n ]\n}\n" if lines else \
        text[:-2] + ',\n "waypoints": []\n}\n'


def write_report(report: SimulationReport, path: str | Path, plan: str = "", scenario: str = "",
                 options: SimOptions | None = None) -> Path:
    """Write :func:`report_to_json` atomically.

    Raises
    ------
    InputError
        The file cannot be written (names it).
    """
    try:
        return write_text_atomic(path, report_to_json(report, plan, scenario, options))
    except OSError as exc:
        raise InputError(f"{path}: cannot write the report: {exc.strerror or exc}") from None


def write_gif(report: SimulationReport, plan: Plan, scenario: Scenario, path: str | Path,
              max_frames: int = 60, frame_ms: int = 100, width_px: int = 640) -> int:
    """Draw the simulated run (object, fingers at their simulated poses; the planned object
    as a dashed outline; the goal in green) as an animated GIF, one frame per recorded
    waypoint, at most ``max_frames``. Returns the number of frames.

    Raises
    ------
    InputError
        The file cannot be written (names it).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle
    from matplotlib.patches import Polygon as PolygonPatch
    from PIL import Image

    world = scenario.world
    recs = list(report.records)
    if not recs:
        raise InputError(f"{path}: --gif: nothing was simulated, no animation to draw")
    idx = np.unique(np.linspace(0, len(recs) - 1, min(max_frames, len(recs))).round().astype(int))
    frames = [recs[i] for i in idx]
    g = world.gripper

    def fingers_world(r: WaypointRecord) -> list[tuple[str, FloatArray]]:
        pose = Pose.from_degrees(*r.gripper)
        if isinstance(g, TwoPointGripper):
            return [("c", pose.apply(np.array([[r.fingers[0], 0.0]]))[0]),
                    ("c", pose.apply(np.array([[r.fingers[1], 0.0]]))[0])]
        assert isinstance(g, PolylineGripper)
        out = [("p", pose.apply(g.mirrored_finger.vertices + [r.fingers[0], 0.0])),
               ("p", pose.apply(g.finger.vertices + [r.fingers[1], 0.0]))]
        if g.palm is not None:
            out.append(("p", pose.apply(g.palm.vertices)))
        return out

    # the view: everything that moves, plus a margin, clipped to the solids' extent
    pts = [world.object_vertices(Pose.from_degrees(*r.simulated)) for r in frames]
    pts += [world.object_vertices(Pose.from_degrees(*r.planned)) for r in frames]
    pts.append(world.object_vertices(scenario.goal))
    for r in frames:
        for kind, p in fingers_world(r):
            pts.append(np.atleast_2d(p))
    allp = np.concatenate(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    pad = 0.15 * float(max(hi - lo)) + 20.0
    lo, hi = lo - pad, hi + pad
    aspect = (hi[1] - lo[1]) / (hi[0] - lo[0])
    fig = Figure(figsize=(6.4, max(2.5, min(8.0, 6.4 * aspect + 0.6))), dpi=width_px / 6.4, layout="tight")
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    images: list[Any] = []
    for n, r in enumerate(frames):
        ax.clear()
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal", adjustable="box")
        ax.tick_params(labelsize=6.5)
        for solid in world.environment.solids:
            ax.add_patch(PolygonPatch(solid.polygon.vertices, closed=True, facecolor="#d4d4d4",
                                      edgecolor="#6e6e6e", linewidth=0.8))
        ax.add_patch(PolygonPatch(world.object_vertices(scenario.goal), closed=True, fill=False,
                                  edgecolor="#1b7837", linestyle=(0, (4, 2)), linewidth=1.0))
        bad = r.position_error_mm > 0 and (report.diverged_step is not None and
                                           (r.step, r.waypoint) >= (report.diverged_step, report.diverged_waypoint or 0))
        ax.add_patch(PolygonPatch(world.object_vertices(Pose.from_degrees(*r.planned)), closed=True, fill=False,
                                  edgecolor="#5a5a5a", linestyle=(0, (2, 2)), linewidth=0.9, zorder=5))
        ax.add_patch(PolygonPatch(world.object_vertices(Pose.from_degrees(*r.simulated)), closed=True,
                                  facecolor="#fcae91" if bad else "#9ecae1",
                                  edgecolor="#a50f15" if bad else "#08519c", linewidth=1.0))
        for kind, p in fingers_world(r):
            if kind == "c":
                assert isinstance(g, TwoPointGripper)
                ax.add_patch(Circle(tuple(p), g.finger_radius, facecolor="#3b3b3b", edgecolor="black", linewidth=0.6))
            else:
                ax.add_patch(PolygonPatch(p, closed=True, facecolor="#3b3b3b", edgecolor="black", linewidth=0.6))
        prim = plan.steps[r.step].primitive
        ax.set_title(f"{scenario.name}: step {r.step} ({prim}), waypoint {r.waypoint}, t = {r.time_s:.1f} s\n"
                     f"error {r.position_error_mm:.1f} mm, {r.angle_error_deg:.1f} deg", fontsize=8)
        canvas.draw()
        rgb = np.asarray(canvas.buffer_rgba())[..., :3].copy()
        images.append(Image.fromarray(rgb).quantize(colors=128, method=Image.Quantize.FASTOCTREE,
                                                    dither=Image.Dither.NONE))
    durations = [frame_ms] * len(images)
    durations[-1] = 1500
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=durations, loop=0)
    try:
        write_bytes_atomic(path, buf.getvalue())
    except OSError as exc:
        raise InputError(f"{path}: --gif: cannot write the animation: {exc.strerror or exc}") from None
    return len(images)


def simulate_rest(world: World, object_pose: Pose, gripper_pose: Pose, width: float, seconds: float,
                  options: SimOptions = SimOptions(), sample_s: float = 0.1) -> FloatArray:
    """Release the object at ``object_pose`` with the hand held still at ``gripper_pose``
    and ``width`` (no preload), and simulate ``seconds``: a probe of the model's statics
    and friction (a block at rest on a table, on a slope).

    Returns
    -------
    numpy.ndarray
        ``(T, 4)``: time (s), object x, y (mm), theta (degrees), every ``sample_s`` from 0.
    """
    sim = build_model(world, options.model)
    run = _Runner(sim, world, options)
    hand = [gripper_pose.x * MM, gripper_pose.y * MM, gripper_pose.theta]
    fingers = [-width / 2.0 * MM, width / 2.0 * MM]
    run.place(object_pose, hand, fingers)
    run.command(hand, fingers)
    out = [(0.0, *run.object_pose())]
    every = max(1, int(round(sample_s / run.dt)))
    steps = int(round(seconds / run.dt))
    for i in range(1, steps + 1):
        run.mj.mj_step(run.model, run.data)
        if i % every == 0 or i == steps:
            out.append((run.time, *run.object_pose()))
    return np.array(out)


def simulate_push(world: World, object_pose: Pose, gripper_from: Pose, gripper_to: Pose, width: float,
                  seconds: float, settle_s: float = 0.5, options: SimOptions = SimOptions(),
                  sample_s: float = 0.1) -> FloatArray:
    """Release the object at ``object_pose`` and drive the hand (fixed ``width``, no
    preload) in a straight line from ``gripper_from`` to ``gripper_to`` (x, y and angle
    interpolated linearly, the angle taking the short way) over ``seconds``, then hold it
    ``settle_s``: a probe of the finger-object contacts (a rigid finger driven into the
    object must push it).

    Returns
    -------
    numpy.ndarray
        ``(T, 7)``: time (s), object x, y (mm), theta (degrees), then the simulated hand's
        x, y (mm), theta (degrees), every ``sample_s`` from 0.
    """
    sim = build_model(world, options.model)
    run = _Runner(sim, world, options)
    a = np.array([gripper_from.x * MM, gripper_from.y * MM, gripper_from.theta])
    b = np.array([gripper_to.x * MM, gripper_to.y * MM, gripper_from.theta
                  + float(wrap_angle(gripper_to.theta - gripper_from.theta))])
    fingers = [-width / 2.0 * MM, width / 2.0 * MM]
    run.place(object_pose, a, fingers)
    run.command(a, fingers)
    out = [(0.0, *run.object_pose(), *run.gripper_pose())]
    every = max(1, int(round(sample_s / run.dt)))
    moving = max(1, int(round(seconds / run.dt)))
    steps = moving + int(round(settle_s / run.dt))
    for i in range(1, steps + 1):
        run.command(a + min(i / moving, 1.0) * (b - a), fingers)
        run.mj.mj_step(run.model, run.data)
        if i % every == 0 or i == steps:
            out.append((run.time, *run.object_pose(), *run.gripper_pose()))
    return np.array(out)
