"""Scenario loading (``ldhp-scenario/1``, see ``shared/spec/scenario.md``).

Stage 1 of the pipeline: a TOML file becomes an immutable :class:`Scenario` holding the
geometric :class:`~geometry.world.World` and the task. Every refusal of the spec raises
:class:`~ldhp_tamp.errors.ScenarioError` naming the file, the key and the problem.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from geometry.poses import Pose
from geometry.world import GripperState, World


@dataclass(frozen=True)
class PlannerSettings:
    """The ``[planner]`` table, every key with its spec default."""

    domain: str = "ldhp"
    engine: str = "pyperplan"
    samples_per_edge: int = 100
    max_top_iterations: int = 10
    max_refinements: int = 4
    seed: int = 0


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
