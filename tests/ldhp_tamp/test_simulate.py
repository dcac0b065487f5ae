"""The MuJoCo replay (``ldhp_tamp.simulate``, ``ldhp_tamp.sim_model``) and ``ldhp-tamp simulate``.

The physics probes check the model against statics and Coulomb's law (a block at rest on
a table, a block on a 20 degree slope just above and just below the friction angle); the
spec's example plans check the verdicts; the CLI tests check exit codes and files. Nothing
here depends on the machine's speed.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from geometry.poses import Pose  # noqa: E402
from geometry.shapes import make_polygon, signed_area  # noqa: E402
from geometry.world import (  # noqa: E402
    Environment, Friction, PolylineGripper, Solid, TwoPointGripper, World, make_object)
from ldhp_tamp.cli import EXIT_BAD_INPUT, EXIT_NO_PLAN, EXIT_OK, main  # noqa: E402
from ldhp_tamp.plan import read_plan, read_plan_string  # noqa: E402
from ldhp_tamp.scenario import load_scenario, load_scenario_string  # noqa: E402
from ldhp_tamp.sim_model import build_model, convex_pieces, planar_inertia  # noqa: E402
from ldhp_tamp.simulate import (  # noqa: E402
    REPORT_FORMAT, SimOptions, SimStatus, format_verdict, report_to_json, simulate_plan, simulate_push,
    simulate_rest, write_gif)

REPO = Path(__file__).resolve().parents[2]
SPEC = REPO / "tests" / "data" / "spec"
PICK = SPEC / "pick.toml"
PICK_PLAN = SPEC / "pick-plan.json"
PICK_INVALID = SPEC / "pick-plan-invalid.json"
CONCAVE11 = REPO / "scenarios" / "gen_lift_concave11.toml"
CONCAVE11_TIP = REPO / "tests" / "data" / "sim" / "concave11-tip-plan.json"
G = 9.81


def _world(solid: list[list[float]], mu: float, block=((0, 0), (60, 0), (60, 30), (0, 30))) -> World:
    return World(make_object([list(p) for p in block], mass=0.5),
                 Environment((Solid("ground", make_polygon(solid)),)),
                 TwoPointGripper(5.0, (80.0, 80.0)), Friction(mu, mu))


FAR = Pose.from_degrees(0.0, 600.0, 0.0)  # the gripper, far above and still


# -------------------------------------------------------------------------------- model


@pytest.mark.parametrize("module", ["simulate.py", "sim_model.py"])
def test_simulator_never_imports_the_planner(module: str) -> None:
    """Like the validator: geometry, scenario, plan, files, errors (and the model builder)
    only; mujoco and matplotlib inside functions, not at import time."""
    import ast

    tree = ast.parse((REPO / "ldhp_tamp" / module).read_text())
    allowed = {"ldhp_tamp.scenario", "ldhp_tamp.plan", "ldhp_tamp.files", "ldhp_tamp.errors",
               "ldhp_tamp.sim_model"}
    for node in ast.walk(tree):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                 else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
        for name in names:
            if name.startswith("ldhp_tamp"):
                assert name in allowed, f"{module} imports {name}"
    top = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
    for node in top:
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
        assert not any(n.split(".")[0] in {"mujoco", "matplotlib", "PIL"} for n in names), module



def test_convex_pieces_of_a_concave_polygon_cover_it() -> None:
    poly = np.array([[0, 0], [70, 0], [70, 50], [50, 65], [70, 80], [70, 150], [45, 150], [35, 130],
                     [25, 150], [0, 150], [-5, 75]], dtype=float)
    pieces = convex_pieces(poly)
    assert 1 < len(pieces) < len(poly) - 2
    assert sum(signed_area(p) for p in pieces) == pytest.approx(signed_area(poly))
    for p in pieces:
        n = len(p)
        for i in range(n):
            a, b, c = p[i - 1], p[i], p[(i + 1) % n]
            assert (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) >= -1e-9


def test_planar_inertia_of_a_rectangle() -> None:
    rect = np.array([[0, 0], [60, 0], [60, 30], [0, 30]], dtype=float)
    assert planar_inertia(rect, np.array([30.0, 15.0])) == pytest.approx(60 * 30 * (60**2 + 30**2) / 12)


def test_plan_angle_is_a_positive_hinge_angle() -> None:
    """A counter-clockwise plan angle theta maps the object's x axis to (cos, 0, sin) in
    MuJoCo's x-z plane: the hinge turns about -y."""
    import mujoco

    world = _world([[-300, -50], [300, -50], [300, 0], [-300, 0]], 0.5)
    sim = build_model(world)
    data = mujoco.MjData(sim.model)
    theta = math.radians(30.0)
    data.qpos[list(sim.object_qpos)] = [0.01, 0.2, theta]
    mujoco.mj_forward(sim.model, data)
    body = mujoco.mj_name2id(sim.model, mujoco.mjtObj.mjOBJ_BODY, "object")
    xmat = data.xmat[body].reshape(3, 3)
    assert xmat[:, 0] == pytest.approx([math.cos(theta), 0.0, math.sin(theta)], abs=1e-12)
    # the centre of mass lands where the plan's pose puts it
    com = Pose(10.0, 200.0, theta).apply(world.object.com)
    assert data.xipos[body][[0, 2]] * 1000 == pytest.approx(com, abs=1e-6)


def test_model_has_explicit_pairs_only() -> None:
    scenario = load_scenario(PICK, check_planner=False)
    sim = build_model(scenario.world)
    m = sim.model
    assert (m.geom_contype == 0).all() and (m.geom_conaffinity == 0).all()
    assert m.npair > 0
    assert sim.variable_width and len(sim.finger_actuators) == 2
    assert sim.max_force == 1000.0 and not sim.max_force_from_scenario


# -------------------------------------------------------------------------------- physics


def test_block_at_rest_on_a_table_stays_put() -> None:
    world = _world([[-300, -50], [300, -50], [300, 0], [-300, 0]], 0.3)
    track = simulate_rest(world, Pose(0.0, 0.0, 0.0), FAR, 80.0, 5.0)
    moved = np.hypot(track[:, 1] - track[0, 1], track[:, 2] - track[0, 2])
    assert track[-1, 0] == pytest.approx(5.0)
    assert moved.max() < 0.5
    assert np.abs(track[:, 3]).max() < 0.1


def _slope(mu: float) -> World:
    t = math.tan(math.radians(20.0))
    return _world([[-400, -400 * t - 50], [300, -400 * t - 50], [300, 300 * t], [-400, -400 * t]], mu)


def test_block_on_a_slope_sticks_above_the_friction_angle() -> None:
    mu = 1.02 * math.tan(math.radians(20.0))
    track = simulate_rest(_slope(mu), Pose.from_degrees(0.0, 0.0, 20.0), FAR, 80.0, 2.0)
    moved = math.hypot(track[-1, 1] - track[0, 1], track[-1, 2] - track[0, 2])
    assert moved < 1.0


def test_block_on_a_slope_slides_as_coulomb_predicts() -> None:
    mu = 0.98 * math.tan(math.radians(20.0))
    seconds = 2.0
    track = simulate_rest(_slope(mu), Pose.from_degrees(0.0, 0.0, 20.0), FAR, 80.0, seconds)
    moved = math.hypot(track[-1, 1] - track[0, 1], track[-1, 2] - track[0, 2])
    a = G * (math.sin(math.radians(20.0)) - mu * math.cos(math.radians(20.0)))  # m/s^2
    expected = 0.5 * a * seconds**2 * 1000.0  # mm
    assert moved == pytest.approx(expected, rel=0.25)
    assert track[-1, 1] < track[0, 1] and track[-1, 2] < track[0, 2]  # down the slope
    assert abs(track[-1, 3] - 20.0) < 1.0  # sliding, not tumbling


# A rigid finger (fixed width: geoms of the hand) driven into a concave object's edges
# pushes it: the concave 11-gon of gen_lift_concave11 (notches v3-v4-v5 on the right,
# v7-v8-v9 on top), 5 mm fingers 90 mm apart, mu 0.2. The expected travel is the hand's
# travel after the finger reaches the face (circle-line geometry below).
@pytest.mark.parametrize("start, end, pushed", [
    # finger 2 (x = 62) into the right notch's corner v4 = (50, 65): both faces at x = 58.33
    ((17.0, 65.0, 0.0), (-3.0, 65.0, 0.0), -(58.0 + 1.0 / 3.0 - 42.0)),
    # the same with the gripper turned 180 degrees: finger 1 does it
    ((17.0, 65.0, 180.0), (-3.0, 65.0, 180.0), -(58.0 + 1.0 / 3.0 - 42.0)),
    # finger 1 (35, 150) into the top notch's face v8-v7, reached at x = 35 + 4.41
    ((80.0, 150.0, 0.0), (100.0, 150.0, 0.0), 55.0 - 35.0 - (20.0 * 0.4472136 - 5.0) / 0.8944272),
    # gen_lift_concave11's tip pose (gripper at -79.45 degrees, finger 2 on the face v4-v5),
    # moved 15 mm left: into that face from the start
    ((51.870245, 110.569904, -79.453406), (36.870245, 110.569904, -79.453406), -15.0),
])
def test_rigid_finger_pushes_a_concave_object(start, end, pushed) -> None:
    world = load_scenario(CONCAVE11, check_planner=False).world
    a, b = Pose.from_degrees(*start), Pose.from_degrees(*end)
    track = simulate_push(world, Pose(0.0, 0.0, 0.0), a, b, 90.0, 3.0)
    assert track[-1, 1] == pytest.approx(pushed, abs=0.5)
    assert abs(track[-1, 2]) < 0.1 and abs(track[-1, 3]) < 0.5  # slid along the table, not tipped
    assert track[-1, 4:6] == pytest.approx([b.x, b.y], abs=0.2)  # the hand followed its command
    assert track[-1, 6] == pytest.approx(end[2], abs=0.05)


def _gap_to(polygon: np.ndarray, point: np.ndarray, radius: float) -> float:
    """Signed clearance (mm) between a circle and a polygon (negative: overlap)."""
    import shapely

    poly, p = shapely.Polygon(polygon), shapely.Point(point)
    d = poly.exterior.distance(p)
    return (-d if poly.contains(p) else d) - radius


def test_a_tip_the_finger_motion_does_not_force_is_not_executed() -> None:
    """gen_lift_concave11's tip (step 1) moves the zero-mobility gripper with the object,
    finger 1 on the convex corner v7 = (45, 150) of the top notch: its motion is 7 degrees
    from that corner's tangent, so against the object at rest the round finger rolls over
    the corner (at most 0.034 mm of interference) and then clears the top edge, while
    finger 2 leaves the right notch's face. Nothing forces the tip (a zero-mobility gripper
    cannot squeeze): the object stays, and the replay diverges there."""
    plan = read_plan(CONCAVE11_TIP)
    scenario = load_scenario(CONCAVE11, check_planner=False)
    world = scenario.world
    rest = world.object_vertices(Pose(0.0, 0.0, 0.0))
    wps = plan.steps[1].waypoints
    assert plan.steps[1].primitive == "tip"
    gaps: dict[int, list[float]] = {1: [], 2: []}
    for u, v in zip(wps[:-1], wps[1:]):
        for s in np.linspace(0.0, 1.0, 41)[:-1]:
            pose = Pose(*(u.gripper.as_array() + s * (v.gripper.as_array() - u.gripper.as_array())))
            for f, x in ((1, -45.0), (2, 45.0)):
                gaps[f].append(_gap_to(rest, pose.apply(np.array([[x, 0.0]]))[0], 5.0))
    g1, g2 = np.array(gaps[1]), np.array(gaps[2])
    assert -0.05 < g1.min() < 0.0  # grazes v7
    assert g1[40] > 0.3 and g1[7 * 40] > 1.9  # waypoints 1 and 7: above the top edge
    assert g2[0] == pytest.approx(0.0, abs=1e-3) and np.all(np.diff(g2) > 0)  # leaves at once
    r = simulate_plan(plan, scenario)
    assert r.status is SimStatus.DIVERGES and (r.diverged_step, r.diverged_primitive) == (1, "tip")
    during = [x for x in r.records if x.step == 1]
    assert len(during) > 5
    for x in during:
        assert math.hypot(x.simulated[0], x.simulated[1]) < 0.01 and abs(x.simulated[2]) < 0.01


# -------------------------------------------------------------------------------- plans


@pytest.fixture(scope="module")
def pick_report():
    return simulate_plan(read_plan(PICK_PLAN), load_scenario(PICK, check_planner=False))


def test_spec_example_plan_executes(pick_report) -> None:
    r = pick_report
    assert r.status is SimStatus.EXECUTES and r.executes
    assert r.diverged_step is None and r.diverged_primitive is None
    assert len(r.records) == len(read_plan(PICK_PLAN).waypoints)
    assert r.max_position_error_mm < 2.0 and r.max_angle_error_deg < 1.0
    assert r.final_position_error_mm is not None and r.final_position_error_mm < 2.0
    last = r.records[-1]
    assert last.planned == pytest.approx((0.0, 100.0, 0.0))
    assert last.simulated[1] == pytest.approx(100.0, abs=2.0)
    assert format_verdict(r).startswith("executes")


def test_spec_invalid_plan_diverges() -> None:
    r = simulate_plan(read_plan(PICK_INVALID), load_scenario(PICK, check_planner=False))
    assert r.status is SimStatus.DIVERGES and not r.executes
    assert r.diverged_step == 1 and r.diverged_primitive == "air-move"
    assert format_verdict(r).startswith("diverges at step 1 (air-move): ")
    bad = [x for x in r.records if x.position_error_mm > 15.0]
    assert bad and (bad[0].step, bad[0].waypoint) == (r.diverged_step, r.diverged_waypoint)
    # stopped early: about a second past the divergence, not the whole lift
    assert len(r.records) < len(read_plan(PICK_INVALID).waypoints)


def _pick_with_max_force(force: float) -> str:
    return PICK.read_text().replace('opening = [0, 140]', f'opening = [0, 140]\nmax_force = {force}')


@pytest.mark.parametrize("force, executes", [(8.0, False), (12.0, True)])
def test_finger_force_cap_decides_the_pinch(force: float, executes: bool) -> None:
    """A 1 kg block pinched with mu = 0.6 needs 8.2 N per finger."""
    scenario = load_scenario_string(_pick_with_max_force(force), "pick-capped.toml", check_planner=False)
    r = simulate_plan(read_plan(PICK_PLAN), scenario)
    assert r.executes is executes
    assert r.max_force_n == force and not r.max_force_default
    if not executes:
        assert r.diverged_primitive == "air-move"


def test_failed_plan_is_not_simulated() -> None:
    plan = read_plan_string(json.dumps({
        "format": "ldhp-plan/1", "scenario": "example-pick", "scenario_sha256": "", "status": "failed",
        "reason": "no plan", "steps": [], "stats": {}}))
    r = simulate_plan(plan, load_scenario(PICK, check_planner=False))
    assert r.status is SimStatus.NOT_SIMULATED and not r.executes and not r.records
    assert "no plan" in r.reason


def test_options_are_checked() -> None:
    with pytest.raises(ValueError):
        SimOptions(speed_mm_s=0.0)
    with pytest.raises(ValueError):
        SimOptions(position_tol_mm=-1.0)


def test_report_json_round_trip(pick_report) -> None:
    data = json.loads(report_to_json(pick_report, "p.json", "s.toml", SimOptions()))
    assert data["format"] == REPORT_FORMAT and data["status"] == "executes" and data["executes"] is True
    assert len(data["waypoints"]) == len(pick_report.records)
    w = data["waypoints"][0]
    assert set(w) >= {"step", "waypoint", "planned", "simulated", "position_error_mm", "angle_error_deg"}
    assert data["options"]["speed_mm_s"] == 5.0


def test_gif(pick_report, tmp_path: Path) -> None:
    from PIL import Image

    out = tmp_path / "run.gif"
    frames = write_gif(pick_report, read_plan(PICK_PLAN), load_scenario(PICK, check_planner=False), out,
                       max_frames=4)
    assert frames == 4
    with Image.open(out) as im:
        assert im.n_frames == 4


def test_polyline_fixed_width_and_palm_build() -> None:
    """A fixed-width polyline gripper with a palm: rigid fingers on the hand, no finger drive."""
    world = World(make_object([[0, 0], [40, 0], [40, 40], [0, 40]]),
                  Environment((Solid("t", make_polygon([[-200, -20], [200, -20], [200, 0], [-200, 0]])),)),
                  PolylineGripper(make_polygon([[0, 0], [10, 0], [10, 45], [0, 45]]), (50.0, 50.0),
                                  make_polygon([[-40, 45], [40, 45], [40, 60], [-40, 60]])),
                  Friction(0.3, 0.5))
    sim = build_model(world)
    assert not sim.variable_width and sim.finger_actuators == ()
    names = {sim.model.geom(i).name for i in range(sim.model.ngeom)}
    assert {"finger1_0", "finger2_0", "palm_0"} <= names


# -------------------------------------------------------------------------------- CLI


def test_cli_executes_and_writes_the_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report.json"
    assert main(["simulate", str(PICK_PLAN), "--scenario", str(PICK), "--out", str(out)]) == EXIT_OK
    stdout = capsys.readouterr().out
    assert stdout.splitlines()[0].startswith("executes")
    assert "max error to the plan" in stdout and "simulated" in stdout
    data = json.loads(out.read_text())
    assert data["executes"] is True and data["waypoints"]


def test_cli_diverges(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", str(PICK_INVALID), "--scenario", str(PICK), "--speed", "10"]) == EXIT_NO_PLAN
    assert capsys.readouterr().out.startswith("diverges at step 1 (air-move)")


def test_cli_failed_plan_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    failed = tmp_path / "failed.json"
    failed.write_text(json.dumps({"format": "ldhp-plan/1", "scenario": "example-pick", "scenario_sha256": "",
                                  "status": "failed", "reason": "no plan", "steps": [], "stats": {}}))
    assert main(["simulate", str(failed), "--scenario", str(PICK)]) == EXIT_NO_PLAN
    assert "not simulated" in capsys.readouterr().out


@pytest.mark.parametrize("case", ["missing-plan", "malformed-plan", "missing-scenario", "out-dir", "speed"])
def test_cli_bad_input_exits_2(case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plan, scenario, extra = str(PICK_PLAN), str(PICK), []
    named = None
    if case == "missing-plan":
        plan = named = str(tmp_path / "nothere.json")
    elif case == "malformed-plan":
        bad = tmp_path / "broken.json"
        bad.write_text("{\"format\": ")
        plan = named = str(bad)
    elif case == "missing-scenario":
        scenario = named = str(tmp_path / "nothere.toml")
    elif case == "out-dir":
        named = str(tmp_path / "no" / "such" / "r.json")
        extra = ["--out", named]
    else:
        extra = ["--speed", "-3"]
    if case == "speed":
        with pytest.raises(SystemExit) as exc:
            main(["simulate", plan, "--scenario", scenario, *extra])
        assert exc.value.code == EXIT_BAD_INPUT
        return
    assert main(["simulate", plan, "--scenario", scenario, *extra]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.startswith("error: ") and Path(named).name in err


def test_a_rigid_wedge_hold_at_the_edge_of_its_cone_is_not_dropped_at_the_start() -> None:
    """Task 1's inverse starts wedged between rigid fingers at 97 % of the friction cone
    (the hold needs mu 0.1946 of 0.2). The replay starts with the object free, settling
    into its contacts with the hand: pinned first (as for finger drives that close), its
    contacts carried nothing when let go, it dropped into them and slid out at once. Here
    the hand turns it 3 degrees about its centre of mass to a firmer hold (0.18)."""
    from ldhp_tamp.plan import PLAN_FORMAT, Family, Plan, PlanStats, PlanStatus, Step, Waypoint

    sc = load_scenario(REPO / "scenarios" / "inv_place_release.toml")
    rel = sc.start.inverse().compose(sc.start_grasp.pose)
    com = sc.start.apply(sc.world.object.com)
    wps = []
    for k in range(4):
        d = -math.radians(1.0) * k
        c, s = math.cos(d), math.sin(d)
        dx, dy = sc.start.x - com[0], sc.start.y - com[1]
        obj = Pose(float(com[0] + c * dx - s * dy), float(com[1] + s * dx + c * dy), sc.start.theta + d)
        grip = obj.compose(rel)
        pts = [obj.apply((0.0, 149.981056)), obj.apply((70.0, 108.75))]  # finger 1 on l4 at v4, finger 2 under l2
        wps.append(Waypoint(obj, grip, 90.0, tuple((float(p[0]), float(p[1])) for p in pts)))
    plan = Plan(PLAN_FORMAT, sc.name, sc.sha256, PlanStatus.SOLVED,
                (Step("air-move", Family.MOVE_OBJECT, {}, ("free", "free"), tuple(wps)),), PlanStats())
    report = simulate_plan(plan, sc)
    assert len(report.records) == 4
    assert max(r.position_error_mm for r in report.records) < 1.0
