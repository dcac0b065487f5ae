"""Fixtures shared by the tests of several ``ldhp_tamp`` modules."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest


@pytest.fixture(scope="session")
def wedged_inverse() -> SimpleNamespace:
    """Task 1's inverse (``inv_place_release``) with its block set on its corner v2 at
    -75 degrees, still wedged by the start grasp: the scenario, the AdjustGrasp context,
    the start grasp's row, the pose, and the feasible pivots there among G_T and the
    start grasp (the rolling-pivot tests of the primitive and of the judge)."""
    from geometry.grasps import GraspOptions, enumerate_grasps
    from geometry.poses import Pose
    from ldhp_tamp.grasp_graph import GraspGraphOptions, GraspPlanner
    from ldhp_tamp.primitives import REGISTRY
    from ldhp_tamp.primitives import adjust_grasp as ag
    from ldhp_tamp.resources import scenarios_dir
    from ldhp_tamp.scenario import load_scenario

    sc = load_scenario(scenarios_dir() / "inv_place_release.toml")
    gs = enumerate_grasps(sc.world, GraspOptions(samples_per_edge=100))
    planner = GraspPlanner(sc.world, gs, [REGISTRY.binding("pivot")], sc.start_grasp, True,
                           GraspGraphOptions(helper=False))
    planner.prepare(sc.start.as_array())
    ctx, start = planner.context, int(planner.start_index)
    th = math.radians(-75.0)
    pose = Pose(70.0 - 70.0 * math.cos(th), -70.0 * math.sin(th), th)  # on its corner v2 = (70, 0)
    pivots = ag.Pivot().intra_edges(ctx, pose, np.union1d(planner.pose_grasps(pose.as_array()), [start]))
    return SimpleNamespace(scenario=sc, context=ctx, start=start, pose=pose, pivots=pivots)
