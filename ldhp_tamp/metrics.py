"""Measures of a plan, for comparing planners (:mod:`ldhp_tamp.bench`).

Plain functions of a :class:`~ldhp_tamp.plan.Plan` (any planner's, read from its file):

- ``regrasps``: the AdjustGrasp steps that change the grasp while the object is held, i.e.
  after the first MoveObject step and before the last one. A step changes the grasp when,
  between its first and its last waypoint, the set of fingers touching the object changes
  or a finger that touches at both ends touches another point of the object (more than
  :data:`REGRASP_MM` apart in the object's frame: a slide, a flip, a re-placed finger).
  Taking the object at the start and letting go at the end are not regrasps; a step that
  only moves the gripper in free space (``approach``) is none either.
- ``finger_travel_mm``: the length of the gripper frame's path (its origin, mm), summed
  over consecutive waypoints of every step.
- ``object_path_mm`` and ``object_rotation_rad``: the length of the object frame's path
  (its origin, mm) and the total angle it turns (radians, the sum of the absolute turns).
  :func:`object_path_equivalent_mm` combines them as mm + rad x the object's radius.
- ``support_margin``: the plan's smallest support margin (``stats.support_margin``, as
  :func:`ldhp_tamp.tamp.solve` writes it; :func:`ldhp_tamp.validate.support_analysis`
  when the plan does not carry it and a scenario is given).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ldhp_tamp.plan import Plan, Step, Waypoint
from ldhp_tamp.primitives.registry import Family

__all__ = ["PlanMetrics", "REGRASP_MM", "changes_grasp", "object_path_equivalent_mm", "plan_metrics"]

#: A finger's contact point that moves farther than this (mm, in the object's frame)
#: during an AdjustGrasp step makes the step a regrasp.
REGRASP_MM = 1.0


@dataclass(frozen=True)
class PlanMetrics:
    """What :func:`plan_metrics` measures (see the module's docstring)."""

    steps: int
    regrasps: int
    finger_travel_mm: float
    object_path_mm: float
    object_rotation_rad: float
    support_margin: float | None


def _object_frame(w: Waypoint, point: tuple[float, float]) -> np.ndarray:
    """``point`` (world, mm) in the frame of the object at ``w``."""
    c, s = math.cos(w.object.theta), math.sin(w.object.theta)
    dx, dy = point[0] - w.object.x, point[1] - w.object.y
    return np.array([c * dx + s * dy, -s * dx + c * dy])


def changes_grasp(step: Step) -> bool:
    """Whether ``step`` ends with another grasp than it starts with: the touching fingers
    differ, or a finger touching at both ends touches elsewhere (> :data:`REGRASP_MM`)."""
    if not step.waypoints:
        return False
    a, b = step.waypoints[0], step.waypoints[-1]
    for pa, pb in zip(a.finger_contacts, b.finger_contacts):
        if (pa is None) != (pb is None):
            return True
        if pa is not None and pb is not None and \
                float(np.linalg.norm(_object_frame(a, pa) - _object_frame(b, pb))) > REGRASP_MM:
            return True
    return False


def _path_length(xy: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()) if len(xy) > 1 else 0.0


def plan_metrics(plan: Plan, scenario: object | None = None) -> PlanMetrics:
    """The measures of ``plan`` (a solved one; a failed plan has no steps: zeros).

    ``scenario`` (a :class:`~ldhp_tamp.scenario.Scenario`): computes the support margin
    when the plan's statistics do not carry it."""
    steps = plan.steps
    moves = [i for i, s in enumerate(steps) if s.family is Family.MOVE_OBJECT]
    held = range(moves[0] + 1, moves[-1]) if moves else range(0)
    regrasps = sum(1 for i in held if steps[i].family is Family.ADJUST_GRASP and changes_grasp(steps[i]))
    travel = obj_mm = obj_rad = 0.0
    for s in steps:
        if not s.waypoints:
            continue
        grip = np.array([(w.gripper.x, w.gripper.y) for w in s.waypoints])
        obj = np.array([(w.object.x, w.object.y, w.object.theta) for w in s.waypoints])
        travel += _path_length(grip)
        obj_mm += _path_length(obj[:, :2])
        dth = np.diff(obj[:, 2])
        obj_rad += float(np.abs((dth + math.pi) % (2 * math.pi) - math.pi).sum())
    margin = plan.stats.extra.get("support_margin")
    if margin is None and scenario is not None and steps:
        from ldhp_tamp.validate import support_analysis

        m = support_analysis(plan, scenario).margin  # type: ignore[arg-type]
        margin = float(m) if np.isfinite(m) else None
    return PlanMetrics(steps=len(steps), regrasps=regrasps, finger_travel_mm=round(travel, 3),
                       object_path_mm=round(obj_mm, 3), object_rotation_rad=round(obj_rad, 6),
                       support_margin=None if margin is None else float(margin))


def object_path_equivalent_mm(metrics: PlanMetrics, radius: float) -> float:
    """The object's path as one length: mm travelled + radians turned x ``radius`` (mm)."""
    return metrics.object_path_mm + metrics.object_rotation_rad * radius
