"""Figures of a plan (``ldhp-tamp render``), drawn from a plan file and its scenario alone.

Three figures, in the style of the paper's Figs. 6 and 7 (see ``docs/figures.md``):

- **snapshots** (PNG and SVG): one panel per step (consecutive steps of the same
  AdjustGrasp primitive share one), showing the scene at the step's first waypoint (the
  environment, the object, the fingers at the waypoint's gripper pose and width, the
  finger contacts and the object-environment contacts), the path of the gripper during the
  step and where the object and the fingers end it; a last panel shows the final
  waypoint. Every panel has the same view, zoomed on what the plan moves.
- **animation** (GIF): the whole plan, subsampled to at most
  :attr:`RenderOptions.max_frames` frames (every step's first waypoint is kept when the
  budget allows).
- **contact-state graph** (PNG and SVG): the scenario's contact states (the top tier's
  nodes) and admissible MoveObject transitions, coloured by primitive, laid out in columns
  by the number of transitions from the start state; the plan's MoveObject steps are drawn
  thick and numbered by step.

A plan without steps (a failed solve) is drawn as the task: the object at the start, the
goal outline, and the reason in the title; the animation is that one frame, the graph has
no highlighted path. The same five files are written either way, so a figures folder
never mixes a new plan with an old one's animation.

Everything is drawn in memory first; then every file is written to a temporary file
(:func:`ldhp_tamp.files.atomic_output`) and only then are they all moved into place: bad
input, a drawing error or a failed write leaves the output folder as it was. matplotlib
is used without pyplot (no global state, no display); Pillow assembles the GIF.

Step numbers are 0-based, as in the plan file's ``steps[i]`` and ``ldhp-tamp validate``.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import os
import textwrap
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

import networkx as nx
import numpy as np
from matplotlib import rc_context
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, FancyArrowPatch, Patch
from matplotlib.patches import Polygon as PolygonPatch
from matplotlib.path import Path as MplPath
from PIL import Image

from geometry import collision
from geometry.contacts import contact_points
from geometry.errors import GeometryError
from geometry.features import ContactState
from geometry.grasps import GraspOptions, enumerate_grasps
from geometry.poses import FloatArray, Pose, transform_points
from geometry.tolerances import VALIDATE_TOL, VALIDATE_TOL_DEG
from geometry.world import World
from ldhp_tamp.errors import InputError
from ldhp_tamp.files import atomic_output
from ldhp_tamp.plan import Family, Plan, PlanStatus, read_plan
from ldhp_tamp.scenario import Scenario, load_scenario

__all__ = [
    "FIGURE_FILES",
    "GraphData",
    "PRIMITIVE_COLOURS",
    "PathEdge",
    "RenderError",
    "RenderOptions",
    "RenderedFigures",
    "Snapshot",
    "check_match",
    "contact_graph_data",
    "default_out_dir",
    "frame_indices",
    "primitive_colour",
    "render_files",
    "render_plan",
    "snapshots",
]

log = logging.getLogger(__name__)

#: The files :func:`render_plan` writes into the output folder, by figure.
FIGURE_FILES: dict[str, tuple[str, ...]] = {
    "snapshots": ("snapshots.png", "snapshots.svg"),
    "animation": ("animation.gif",),
    "contact_graph": ("contact_graph.png", "contact_graph.svg"),
}

#: Colours of the MoveObject primitives: the paper's (Fig. 7a: tip green, push orange,
#: biplanar-slide blue) and air-move purple; other MoveObject actions a domain adds take
#: :data:`_EXTRA_COLOURS` in name order; AdjustGrasp primitives are grey.
PRIMITIVE_COLOURS: dict[str, str] = {
    "tip": "#2ca02c", "push": "#ff7f0e", "biplanar-slide": "#1f77b4", "air-move": "#9467bd"}
_EXTRA_COLOURS = ("#d62728", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")
_ADJUST_COLOUR = "#4d4d4d"

# Scene colours.
_SOLID_FACE, _SOLID_EDGE = "#d4d4d4", "#6e6e6e"
_OBJECT_FACE, _OBJECT_EDGE = "#9ecae1", "#08519c"
_GOAL_EDGE = "#1b7837"
_FINGER_FACE, _FINGER_EDGE = "#3b3b3b", "#000000"
_GHOST_EDGE = "#5a5a5a"
_PATH_NODE, _START_COLOUR, _GOAL_COLOUR = "#fff3b0", "#1a9850", "#d73027"

# Graph layout: column spacing (few columns, many columns), row spacing, rows of room
# below a state for its first loop.
_GRAPH_DX, _GRAPH_DX_WIDE, _GRAPH_DY, _LOOP_ROWS = 2.3, 1.9, 0.62, 1.0
_PATH_COLOUR = "#c51b7d"
_FINGER_CONTACT = "#e41a1c"
_ENV_CONTACT = "#ffd92f"


class RenderError(InputError):
    """A plan and a scenario that cannot be drawn together (made for different
    scenarios), or an output folder that cannot be written. The message names the file."""


@dataclass(frozen=True)
class RenderOptions:
    """How the figures are drawn.

    Attributes
    ----------
    max_frames : int
        Most frames of the animation (at least 2).
    frame_ms : int
        Duration of one animation frame (ms).
    hold_ms : int
        Duration of the animation's first and last frames (ms).
    gif_width : int
        Width of the animation in pixels.
    dpi : int
        Resolution of the PNG figures.
    columns : int
        Most snapshot panels per row.
    graph : bool
        Build the scenario's contact-state graph (loads the domain and enumerates the
        contact states, about as long as a solve's setup); ``False`` draws only the
        plan's path.
    """

    max_frames: int = 150
    frame_ms: int = 80
    hold_ms: int = 1200
    gif_width: int = 640
    dpi: int = 150
    columns: int = 5
    graph: bool = True

    def __post_init__(self) -> None:
        if self.max_frames < 2:
            raise ValueError(f"max_frames must be at least 2, got {self.max_frames}")
        if self.columns < 1 or self.dpi < 10 or self.gif_width < 64 or self.frame_ms < 10 or self.hold_ms < 10:
            raise ValueError("columns >= 1, dpi >= 10, gif_width >= 64, frame_ms and hold_ms >= 10 ms")


@dataclass(frozen=True)
class RenderedFigures:
    """The files written, by figure (see :data:`FIGURE_FILES`); ``task_only`` when the
    plan has no waypoint and the figures show the task (start, goal) instead."""

    out_dir: Path
    snapshots: tuple[Path, ...]
    animation: Path
    contact_graph: tuple[Path, ...]
    frames: int
    panels: int
    task_only: bool = False

    @property
    def paths(self) -> tuple[Path, ...]:
        return (*self.snapshots, self.animation, *self.contact_graph)


# --------------------------------------------------------------------------------------
# Reading and checking
# --------------------------------------------------------------------------------------


def default_out_dir(plan_path: str | os.PathLike[str]) -> Path:
    """``<plan stem>-figures`` next to the plan file."""
    p = Path(plan_path)
    return p.with_name(f"{p.stem}-figures")


def check_match(plan: Plan, scenario: Scenario, plan_source: str = "<plan>") -> list[str]:
    """Refuse a plan made for another scenario; return warnings for lesser differences.

    Raises
    ------
    RenderError
        The plan names another scenario than the scenario file's ``name``.

    Returns
    -------
    list of str
        Warnings: the scenario file's bytes differ from those the plan was made for
        (``scenario_sha256``); the figures are drawn against the given file anyway.
    """
    where = str(scenario.path) if scenario.path is not None else scenario.name
    if plan.scenario != scenario.name:
        raise RenderError(f"{plan_source}: the plan is for scenario {plan.scenario!r}, but {where} "
                          f"is scenario {scenario.name!r}")
    if plan.scenario_sha256 != scenario.sha256:
        return [f"{plan_source} was made for another version of {where} (scenario_sha256 differs): "
                f"drawing against {where} anyway"]
    return []


def render_files(plan_path: str | os.PathLike[str], scenario_path: str | os.PathLike[str],
                 out_dir: str | os.PathLike[str] | None = None,
                 options: RenderOptions = RenderOptions()) -> RenderedFigures:
    """Read a plan and its scenario and draw the figures into ``out_dir`` (default
    :func:`default_out_dir`).

    Raises
    ------
    InputError
        Unreadable or malformed plan or scenario (:class:`~ldhp_tamp.errors.PlanFormatError`,
        :class:`~ldhp_tamp.errors.ScenarioError`), a plan for another scenario or an
        unwritable output folder (:class:`RenderError`). Nothing is written then.
    """
    plan = read_plan(plan_path)
    scenario = load_scenario(scenario_path, check_planner=False)
    for w in check_match(plan, scenario, str(plan_path)):
        log.warning("%s", w)
    out = Path(out_dir) if out_dir is not None else default_out_dir(plan_path)
    return render_plan(plan, scenario, out, options)


# --------------------------------------------------------------------------------------
# The plan as arrays
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Track:
    """The waypoints to draw, in order, as arrays (mm, radians), with the geometry that
    does not depend on the figure: world object vertices and finger shapes."""

    obj: FloatArray  # (W, 3)
    grip: FloatArray  # (W, 3)
    width: FloatArray  # (W,)
    contacts: FloatArray  # (W, 2, 2), NaN where a finger declares no contact
    step: np.ndarray  # (W,) step index, -1 for the task scene of a plan without steps
    object_vertices: FloatArray  # (W, N, 2)
    fingers: collision.FingerShapes  # at every waypoint
    has_gripper: np.ndarray  # (W,) bool: False for the task scene of an unheld start

    def __len__(self) -> int:
        return int(self.obj.shape[0])

    @classmethod
    def of(cls, plan: Plan, scenario: Scenario) -> "_Track":
        world = scenario.world
        rows = [(i, w) for i, s in enumerate(plan.steps) for w in s.waypoints]
        if rows:
            obj = np.array([w.object.as_array() for _, w in rows])
            grip = np.array([w.gripper.as_array() for _, w in rows])
            width = np.array([w.width for _, w in rows])
            contacts = np.array([[c if c is not None else (np.nan, np.nan) for c in w.finger_contacts]
                                 for _, w in rows], dtype=float).reshape(len(rows), 2, 2)
            step = np.array([i for i, _ in rows], dtype=np.int64)
            has_gripper = np.ones(len(rows), dtype=bool)
        else:  # the task: the start pose, held as the scenario says (or not held)
            g = scenario.start_grasp
            obj = scenario.start.as_array()[None]
            grip = (g.pose.as_array() if g else np.zeros(3))[None]
            width = np.array([g.width if g else world.gripper.width_range[0]])
            contacts = np.full((1, 2, 2), np.nan)
            step = np.array([-1], dtype=np.int64)
            has_gripper = np.array([g is not None])
        return cls(obj, grip, width, contacts, step,
                   transform_points(obj, world.object.polygon.vertices),
                   collision.finger_shapes(world.gripper, grip, width), has_gripper)

    def finger_outlines(self, i: int) -> list[FloatArray]:
        """Polyline model: finger 1, finger 2 (and the palm) world vertices at waypoint ``i``."""
        f = self.fingers
        if f.polygons is None:
            return []
        out = [f.polygons[i, 0], f.polygons[i, 1]]
        if f.palm is not None:
            out.append(f.palm[i])
        return out

    def gripper_points(self) -> FloatArray:
        """Every point of every drawn finger (and palm) over the track, (K, 2)."""
        f, keep = self.fingers, self.has_gripper
        if not keep.any():
            return np.zeros((0, 2))
        if f.centres is not None:
            assert f.radius is not None
            c = f.centres[keep].reshape(-1, 2)
            r = float(f.radius)
            return np.concatenate([c - r, c + r])
        assert f.polygons is not None
        pts = [f.polygons[keep].reshape(-1, 2)]
        if f.palm is not None:
            pts.append(f.palm[keep].reshape(-1, 2))
        return np.concatenate(pts)


def _dedupe(track: _Track) -> list[int]:
    """Waypoint indices without the repeated joins (a step's first waypoint equals the
    previous step's last one): the sequence the animation plays."""
    keep = [0] if len(track) else []
    for i in range(1, len(track)):
        same = (np.allclose(track.obj[i], track.obj[i - 1]) and np.allclose(track.grip[i], track.grip[i - 1])
                and track.width[i] == track.width[i - 1]
                and np.array_equal(np.isnan(track.contacts[i]), np.isnan(track.contacts[i - 1])))
        if not same:
            keep.append(i)
    return keep


def frame_indices(step_of: Sequence[int], max_frames: int) -> list[int]:
    """Which of the waypoints ``0..len(step_of)-1`` become animation frames: the first
    and the last, each step's first waypoint while they fit in half the budget, and the
    rest of the ``max_frames`` evenly spaced among the others.

    Examples
    --------
    >>> frame_indices([0, 0, 0, 1, 1, 1, 1, 1, 1, 1], 4)
    [0, 3, 7, 9]
    >>> frame_indices([0, 0, 0, 1, 1, 1, 1, 1, 1, 1], 6)
    [0, 2, 3, 5, 7, 9]
    >>> frame_indices([0, 1, 2], 150)
    [0, 1, 2]
    """
    n = len(step_of)
    if n <= max_frames:
        return list(range(n))
    firsts = [i for i in range(n) if i == 0 or step_of[i] != step_of[i - 1]]
    must = set(firsts) | {n - 1} if len(firsts) + 1 <= max_frames // 2 else {0, n - 1}
    rest = np.array([i for i in range(n) if i not in must])
    budget = max_frames - len(must)
    pick = rest[((np.arange(budget) + 0.5) * rest.size / budget).astype(int)]  # centred, distinct
    return sorted(must | {int(i) for i in pick})


# --------------------------------------------------------------------------------------
# Snapshots
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Snapshot:
    """One panel: the scene at waypoint ``index`` (global, over all steps), with the
    motion of waypoints ``index..last`` traced. ``steps`` are the step indices it covers
    (empty for the final panel and for the task scene of a plan without steps)."""

    index: int
    last: int
    steps: tuple[int, ...]
    title: str
    subtitle: str
    colour: str


def primitive_colour(primitive: str, family: Family, move_primitives: Iterable[str] = ()) -> str:
    """The colour of a primitive in every figure (see :data:`PRIMITIVE_COLOURS`)."""
    if primitive in PRIMITIVE_COLOURS:
        return PRIMITIVE_COLOURS[primitive]
    if family is not Family.MOVE_OBJECT:
        return _ADJUST_COLOUR
    others = sorted(set(move_primitives) - set(PRIMITIVE_COLOURS) | {primitive})
    return _EXTRA_COLOURS[others.index(primitive) % len(_EXTRA_COLOURS)]


def _move_primitives(plan: Plan, graph: "GraphData | None" = None) -> set[str]:
    names = {s.primitive for s in plan.steps if s.family is Family.MOVE_OBJECT}
    if graph is not None:
        names |= set(graph.transitions)
    return names


def snapshots(plan: Plan, scenario: Scenario) -> tuple[Snapshot, ...]:
    """The panels of the snapshot figure: the first waypoint of each step (a run of
    consecutive steps of one AdjustGrasp primitive is one panel), then the final waypoint
    (saying whether the object is at the scenario's goal, within the validator's 1 mm and
    1 degree). Steps without waypoints are skipped. A plan without waypoints has one
    panel, the task."""
    moves = _move_primitives(plan)
    out: list[Snapshot] = []
    start = 0
    runs: list[tuple[int, int, int]] = []  # (first step, last step, first global waypoint)
    for i, s in enumerate(plan.steps):
        n = len(s.waypoints)
        if n:
            prev = runs[-1] if runs else None
            if (prev is not None and s.family is Family.ADJUST_GRASP and prev[1] == i - 1
                    and plan.steps[prev[0]].primitive == s.primitive):
                runs[-1] = (prev[0], i, prev[2])
            else:
                runs.append((i, i, start))
        start += n
    total = start
    if total == 0:
        what = "failed" if plan.status is PlanStatus.FAILED else "empty"
        return (Snapshot(0, 0, (), f"no plan ({what})", "start pose, goal outline", _ADJUST_COLOUR),)
    ends = [sum(len(s.waypoints) for s in plan.steps[: b + 1]) - 1 for _, b, _ in runs]
    for (a, b, first), last in zip(runs, ends):
        step = plan.steps[a]
        colour = primitive_colour(step.primitive, step.family, moves)
        if a == b:
            title = f"step {a} · {step.primitive}"
        else:
            title = f"steps {a}–{b} · {step.primitive} ×{b - a + 1}"
        cs_from, cs_to = step.contact_state[0], plan.steps[b].contact_state[1]
        state = cs_from if cs_from == cs_to else f"{cs_from} → {cs_to}"
        out.append(Snapshot(first, last, tuple(range(a, b + 1)), title, f"{step.family.value} · {state}", colour))
    final = plan.steps[runs[-1][1]]
    last = final.waypoints[-1].object
    goal = scenario.goal
    off = math.hypot(last.x - goal.x, last.y - goal.y)
    turn = abs(math.degrees(math.remainder(last.theta - goal.theta, 2 * math.pi)))
    where = "at the goal" if off <= VALIDATE_TOL and turn <= VALIDATE_TOL_DEG else \
        f"{off:.0f} mm, {turn:.0f}° from the goal"
    out.append(Snapshot(total - 1, total - 1, (), "end", f"{where} · state {final.contact_state[1]}",
                        _ADJUST_COLOUR))
    return tuple(out)


def _view(track: _Track, scenario: Scenario, aspect_range: tuple[float, float] = (0.55, 1.4)
          ) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax): what the plan moves, the start and goal poses, with a
    margin; widened so that height/width stays within ``aspect_range``."""
    poly = scenario.world.object.polygon.vertices
    pts = [track.object_vertices.reshape(-1, 2), track.gripper_points(),
           transform_points(np.stack([scenario.start.as_array(), scenario.goal.as_array()]), poly).reshape(-1, 2)]
    allp = np.concatenate(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    size = float(max(hi[0] - lo[0], hi[1] - lo[1], 1.0))
    pad = max(0.08 * size, 12.0) if len(track) > 1 else max(0.3 * size, 30.0)  # the task alone: more context
    lo, hi = lo - pad, hi + pad
    w, h = hi - lo
    lo_a, hi_a = aspect_range
    if h / w < lo_a:
        grow = (lo_a * w - h) / 2
        lo[1], hi[1] = lo[1] - grow, hi[1] + grow
    elif h / w > hi_a:
        grow = (h / hi_a - w) / 2
        lo[0], hi[0] = lo[0] - grow, hi[0] + grow
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


class _Scene:
    """The artists of one scene on one Axes; :meth:`show` moves them to a waypoint."""

    def __init__(self, ax: Axes, scenario: Scenario, track: _Track, view: tuple[float, float, float, float],
                 scale: float):
        self.ax, self.world, self.track, self.scale = ax, scenario.world, track, scale
        self._env_cache: dict[int, FloatArray] = {}
        xmin, xmax, ymin, ymax = view
        ax.set_xlim(xmin, xmax)
        ax.set_ylim(ymin, ymax)
        ax.set_aspect("equal", adjustable="box")
        ax.tick_params(labelsize=6 * scale, length=2)
        ax.set_facecolor("white")
        for solid in self.world.environment.solids:
            ax.add_patch(PolygonPatch(solid.polygon.vertices, closed=True, facecolor=_SOLID_FACE,
                                      edgecolor=_SOLID_EDGE, linewidth=0.8 * scale, zorder=1))
        goal = self.world.object_vertices(scenario.goal)
        ax.add_patch(PolygonPatch(goal, closed=True, fill=False, edgecolor=_GOAL_EDGE, linestyle=(0, (4, 2)),
                                  linewidth=1.0 * scale, zorder=2))
        self.object = ax.add_patch(PolygonPatch(track.object_vertices[0], closed=True, facecolor=_OBJECT_FACE,
                                                edgecolor=_OBJECT_EDGE, linewidth=1.0 * scale, zorder=4))
        fs = track.fingers
        self.finger_patches: list[Any] = []
        if fs.centres is not None:
            for k in range(2):
                self.finger_patches.append(ax.add_patch(Circle(tuple(fs.centres[0, k]), float(fs.radius or 0.0),
                                                               facecolor=_FINGER_FACE, edgecolor=_FINGER_EDGE,
                                                               linewidth=0.6 * scale, zorder=6)))
        else:
            for outline in track.finger_outlines(0):
                self.finger_patches.append(ax.add_patch(PolygonPatch(outline, closed=True, facecolor=_FINGER_FACE,
                                                                     edgecolor=_FINGER_EDGE, linewidth=0.6 * scale,
                                                                     zorder=6)))
        ms = 4.8 * scale
        (self.env_contacts,) = ax.plot([], [], linestyle="none", marker="D", markersize=ms * 0.8,
                                       markerfacecolor=_ENV_CONTACT, markeredgecolor="black",
                                       markeredgewidth=0.6 * scale, zorder=8)
        (self.finger_contacts,) = ax.plot([], [], linestyle="none", marker="o", markersize=ms,
                                          markerfacecolor=_FINGER_CONTACT, markeredgecolor="white",
                                          markeredgewidth=0.8 * scale, zorder=9)

    def env_contact_points(self, i: int) -> FloatArray:
        if i not in self._env_cache:
            try:
                pts = contact_points(self.world, Pose.from_array(self.track.obj[i]), VALIDATE_TOL).points
            except GeometryError as exc:  # a pose the contact analysis cannot name
                log.debug("waypoint %d: no environment contacts drawn: %s", i, exc)
                pts = np.zeros((0, 2))
            self._env_cache[i] = pts
        return self._env_cache[i]

    def show(self, i: int) -> None:
        t = self.track
        self.object.set_xy(t.object_vertices[i])
        visible = bool(t.has_gripper[i])
        fs = t.fingers
        if fs.centres is not None:
            for k, patch in enumerate(self.finger_patches):
                patch.set_center(tuple(fs.centres[i, k]))
        else:
            for patch, outline in zip(self.finger_patches, t.finger_outlines(i)):
                patch.set_xy(outline)
        for patch in self.finger_patches:
            patch.set_visible(visible)
        fc = t.contacts[i][~np.isnan(t.contacts[i, :, 0])]
        self.finger_contacts.set_data(fc[:, 0], fc[:, 1])
        ec = self.env_contact_points(i)
        self.env_contacts.set_data(ec[:, 0], ec[:, 1])

    def trace(self, first: int, last: int) -> None:
        """Draw the motion of waypoints ``first..last``: the gripper's path (its frame's
        origin) with an arrow, and, when the object moves, its outline at ``last``."""
        t, ax, s = self.track, self.ax, self.scale
        if last <= first:
            return
        if t.has_gripper[first:last + 1].all():
            path = t.grip[first:last + 1, :2]
            if np.linalg.norm(path[-1] - path[0]) > 1.0 or np.ptp(path, axis=0).max() > 1.0:
                ax.plot(path[:, 0], path[:, 1], color=_PATH_COLOUR, linewidth=1.0 * s, linestyle=(0, (1.5, 1.5)),
                        zorder=7, solid_capstyle="round")
                ax.add_patch(FancyArrowPatch(tuple(path[-2]), tuple(path[-1]), arrowstyle="-|>",
                                             mutation_scale=9 * s, color=_PATH_COLOUR, linewidth=0, zorder=7,
                                             shrinkA=0, shrinkB=0))
        moved = np.linalg.norm(t.object_vertices[last] - t.object_vertices[first], axis=1).max()
        if moved > VALIDATE_TOL:
            ax.add_patch(PolygonPatch(t.object_vertices[last], closed=True, fill=False, edgecolor=_OBJECT_EDGE,
                                      linestyle=(0, (2, 1.5)), linewidth=0.9 * s, zorder=3, alpha=0.9))
        if not (t.has_gripper[first] and t.has_gripper[last]):
            return
        fs = t.fingers
        ghost = dict(fill=False, edgecolor=_GHOST_EDGE, linewidth=0.7 * s, linestyle=(0, (2, 1.5)), zorder=3)
        if fs.centres is not None:
            if np.linalg.norm(fs.centres[last] - fs.centres[first], axis=1).max() > VALIDATE_TOL:
                for k in range(2):
                    ax.add_patch(Circle(tuple(fs.centres[last, k]), float(fs.radius or 0.0), **ghost))
        elif np.linalg.norm(fs.polygons[last] - fs.polygons[first], axis=-1).max() > VALIDATE_TOL:
            for outline in t.finger_outlines(last):
                ax.add_patch(PolygonPatch(outline, closed=True, **ghost))

    def label_features(self, i: int) -> None:
        """Name the object's vertices (at waypoint ``i``) and the environment edges in
        view, as the contact-state names use them (``v1``, ``e3``)."""
        ax, s = self.ax, self.scale
        xmin, xmax = ax.get_xlim()
        ymin, ymax = ax.get_ylim()
        span = max(xmax - xmin, ymax - ymin)
        verts = self.track.object_vertices[i]
        centre = verts.mean(axis=0)
        for k, v in enumerate(verts):
            d = v - centre
            d = d / (np.linalg.norm(d) or 1.0)
            p = v + d * 0.035 * span
            if not (xmin < p[0] < xmax and ymin < p[1] < ymax):
                continue
            ax.text(p[0], p[1], f"v{k + 1}", fontsize=6.5 * s, color=_OBJECT_EDGE, ha="center", va="center",
                    zorder=10)
        env = self.world.environment
        for j, (a, b) in enumerate(env.edges):
            seg = _clip_segment(a, b, (xmin, xmax, ymin, ymax))
            if seg is None or np.linalg.norm(seg[1] - seg[0]) < 0.06 * span:
                continue
            mid = (seg[0] + seg[1]) / 2 - env.normals[j] * 0.03 * span
            if not (xmin + 0.02 * span < mid[0] < xmax - 0.02 * span and ymin < mid[1] < ymax):
                continue
            ax.text(mid[0], mid[1], f"e{j + 1}", fontsize=6.5 * s, color="#333333", ha="center", va="center",
                    zorder=10)


def _clip_segment(a: FloatArray, b: FloatArray, box: tuple[float, float, float, float]
                  ) -> tuple[FloatArray, FloatArray] | None:
    """The part of segment ab inside the box (Liang-Barsky), or ``None``."""
    xmin, xmax, ymin, ymax = box
    d = b - a
    t0, t1 = 0.0, 1.0
    for p, q in ((-d[0], a[0] - xmin), (d[0], xmax - a[0]), (-d[1], a[1] - ymin), (d[1], ymax - a[1])):
        if p == 0:
            if q < 0:
                return None
            continue
        r = q / p
        if p < 0:
            t0 = max(t0, r)
        else:
            t1 = min(t1, r)
    if t0 > t1:
        return None
    return a + t0 * d, a + t1 * d


def _legend_handles(with_trace: bool) -> list[Any]:
    h: list[Any] = [
        Patch(facecolor=_OBJECT_FACE, edgecolor=_OBJECT_EDGE, label="object"),
        Patch(facecolor=_FINGER_FACE, edgecolor=_FINGER_EDGE, label="fingers"),
        Patch(facecolor=_SOLID_FACE, edgecolor=_SOLID_EDGE, label="environment"),
        Line2D([], [], color=_GOAL_EDGE, linestyle=(0, (4, 2)), label="goal pose"),
        Line2D([], [], linestyle="none", marker="o", markerfacecolor=_FINGER_CONTACT, markeredgecolor="white",
               markersize=6, label="finger contact"),
        Line2D([], [], linestyle="none", marker="D", markerfacecolor=_ENV_CONTACT, markeredgecolor="black",
               markersize=5, label="object–environment contact"),
    ]
    if with_trace:
        h += [Line2D([], [], color=_PATH_COLOUR, linestyle=(0, (1.5, 1.5)), label="gripper path in the step"),
              Line2D([], [], color=_OBJECT_EDGE, linestyle=(0, (2, 1.5)), label="object at the step's end"),
              Line2D([], [], color=_GHOST_EDGE, linestyle=(0, (2, 1.5)), label="fingers at the step's end")]
    return h


def _title(plan: Plan, scenario: Scenario) -> str:
    if plan.steps and any(s.waypoints for s in plan.steps):
        moves = sum(1 for s in plan.steps if s.family is Family.MOVE_OBJECT)
        return (f"{scenario.name}: {plan.status.value} plan, {len(plan.steps)} steps "
                f"({moves} move the object), {sum(len(s.waypoints) for s in plan.steps)} waypoints")
    reason = plan.reason or ("the plan has no step" if plan.status is PlanStatus.SOLVED else "no reason given")
    return f"{scenario.name}: no plan ({plan.status.value}) — " + reason


def _wrap(text: str, width: int) -> str:
    return "\n".join(textwrap.wrap(text, width)) or text


def _draw_snapshots(plan: Plan, scenario: Scenario, track: _Track, view: tuple[float, float, float, float],
                   panels: Sequence[Snapshot], options: RenderOptions) -> Figure:
    """The snapshot figure (one panel per :class:`Snapshot`, in rows of ``options.columns``)."""
    cols = min(options.columns, len(panels))
    rows = math.ceil(len(panels) / cols)
    xmin, xmax, ymin, ymax = view
    panel_w = 3.0 if cols > 1 else 4.5
    panel_h = panel_w * (ymax - ymin) / (xmax - xmin)
    fig = Figure(figsize=(panel_w * cols + 0.5, rows * (panel_h + 0.62) + 1.3), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False, sharex=True, sharey=True)
    for k, snap in enumerate(panels):
        ax = axes[k // cols][k % cols]
        scene = _Scene(ax, scenario, track, view, 1.0)
        scene.show(snap.index)
        scene.trace(snap.index, snap.last)
        if k == 0:
            scene.label_features(snap.index)
        ax.set_title(f"{snap.title}\n", fontsize=9, color=snap.colour, fontweight="bold", loc="center", pad=2)
        ax.text(0.5, 1.0, snap.subtitle, transform=ax.transAxes, fontsize=7, color="#333333", ha="center",
                va="bottom")
        if k // cols == rows - 1 or k + cols >= len(panels):
            ax.set_xlabel("x (mm)", fontsize=7)
        if k % cols == 0:
            ax.set_ylabel("y (mm)", fontsize=7)
    for k in range(len(panels), rows * cols):
        axes[k // cols][k % cols].set_visible(False)
    fig.suptitle(_wrap(_title(plan, scenario), 30 * max(cols, 3)), fontsize=10)
    fig.legend(handles=_legend_handles(len(panels) > 1), loc="outside lower center", ncol=4, fontsize=7,
               frameon=False)
    return fig


# --------------------------------------------------------------------------------------
# Animation
# --------------------------------------------------------------------------------------


def _frame_caption(plan: Plan, track: _Track, i: int, order: int, count: int) -> str:
    s = int(track.step[i])
    if s < 0:
        return "no plan: the start pose (the goal outline dashed)"
    step = plan.steps[s]
    a, b = step.contact_state
    state = a if a == b else f"{a} → {b}"
    return f"step {s}/{len(plan.steps) - 1}: {step.primitive} ({step.family.value}), {state}   [{order + 1}/{count}]"


def _draw_animation(plan: Plan, scenario: Scenario, track: _Track, view: tuple[float, float, float, float],
                   options: RenderOptions) -> tuple[bytes, int]:
    """The GIF's bytes and frame count."""
    order = _dedupe(track)
    frames = [order[j] for j in frame_indices([int(track.step[i]) for i in order], options.max_frames)]
    xmin, xmax, ymin, ymax = view
    w_in = 6.4
    dpi = options.gif_width / w_in
    h_in = w_in * (ymax - ymin) / (xmax - xmin) + 0.9
    fig = Figure(figsize=(w_in, h_in), dpi=dpi, layout="constrained")
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    scene = _Scene(ax, scenario, track, view, 1.1)
    moves = _move_primitives(plan)
    fig.suptitle(_wrap(_title(plan, scenario), 95), fontsize=8)
    caption = ax.set_title(_frame_caption(plan, track, frames[-1], len(frames) - 1, len(frames)), fontsize=8.5)
    ax.tick_params(labelsize=6.5)
    ax.set_xlabel("x (mm)", fontsize=7)
    ax.set_ylabel("y (mm)", fontsize=7)
    # Blitting: draw the static scene once, then only the moving artists on a copy of it.
    moving = [scene.object, *scene.finger_patches, scene.env_contacts, scene.finger_contacts, caption]
    for a in moving:
        a.set_animated(True)
    canvas.draw()
    fig.set_layout_engine("none")  # the layout is fixed from here: the frames must not jitter
    background = canvas.copy_from_bbox(fig.bbox)
    images: list[Image.Image] = []
    for n, i in enumerate(frames):
        canvas.restore_region(background)
        scene.show(i)
        s = int(track.step[i])
        caption.set_text(_frame_caption(plan, track, i, n, len(frames)))
        caption.set_color(primitive_colour(plan.steps[s].primitive, plan.steps[s].family, moves) if s >= 0
                          else _ADJUST_COLOUR)
        for a in moving:
            if a.get_visible():
                fig.draw_artist(a)
        rgb = np.asarray(canvas.buffer_rgba())[..., :3].copy()
        images.append(Image.fromarray(rgb).quantize(colors=128, method=Image.Quantize.FASTOCTREE,
                                                    dither=Image.Dither.NONE))
    durations = [options.frame_ms] * len(images)
    durations[0] = options.hold_ms
    durations[-1] = options.hold_ms
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=durations, loop=0,
                   disposal=1)
    return buf.getvalue(), len(images)


# --------------------------------------------------------------------------------------
# Contact-state graph
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PathEdge:
    """A MoveObject step of the plan as an edge of the contact-state graph."""

    step: int
    primitive: str
    source: str
    target: str


@dataclass(frozen=True)
class GraphData:
    """What the graph figure draws, by state name.

    ``states`` are the scenario's contact states (the top tier's nodes), ``transitions``
    the admissible MoveObject transitions per action, ``start``/``goal`` the symbolic
    start and goal states (``None`` when the graph could not be built), ``path`` the
    plan's MoveObject steps, ``extra`` states the path uses that are not nodes of the
    graph, ``notes`` what the figure should say about how it was made.
    """

    states: tuple[str, ...]
    transitions: dict[str, frozenset[tuple[str, str]]]
    start: str | None
    goal: str | None
    path: tuple[PathEdge, ...]
    extra: tuple[str, ...] = ()
    notes: tuple[str, ...] = field(default_factory=tuple)


def _state_name(name: str) -> str | None:
    """The canonical name of a contact-state name (sorted contacts), or ``None``."""
    try:
        return ContactState.parse(name).name
    except (ValueError, KeyError, IndexError, GeometryError):
        return None


def _geometric_state(world: World, pose: FloatArray) -> str:
    try:
        return contact_points(world, Pose.from_array(pose), VALIDATE_TOL).state.name
    except GeometryError:
        return "?"


def contact_graph_data(plan: Plan, scenario: Scenario, build: bool = True) -> GraphData:
    """The scenario's contact-state graph and the plan's path through it.

    The path is the plan's MoveObject steps, from each step's ``contact_state`` names.
    The spec lets a plan name states freely: a name that is not a node of the graph is
    replaced by the contact state the geometry shows at the step's first (or last)
    waypoint, within the validator's 1 mm; a state that is still not a node is added as
    an extra node. With ``build=False`` (or when the graph cannot be built) only the path
    is drawn.

    Raises
    ------
    InputError
        The scenario's domain cannot be loaded (:class:`~ldhp_tamp.errors.DomainError`).
    """
    from ldhp_tamp import symbolic
    from ldhp_tamp.contact_graph import ContactPoseError, admissible_transitions, build_context
    from ldhp_tamp.primitives import REGISTRY

    notes: list[str] = []
    states: tuple[str, ...] = ()
    transitions: dict[str, frozenset[tuple[str, str]]] = {}
    start = goal = None
    if not build:
        notes.append("the scenario's contact-state graph was not built: the plan's path only")
    else:
        settings = scenario.settings
        base = scenario.path.parent if scenario.path is not None else None
        domain = symbolic.load_domain(settings.domain_path or settings.domain, base)
        # the planner's graph: its air-move lifts and placements need a carrying grasp
        grasps = enumerate_grasps(scenario.world, GraspOptions(samples_per_edge=settings.samples_per_edge))
        try:
            ctx = build_context(scenario.world, scenario.start, scenario.goal, grasps=grasps)
        except ContactPoseError as exc:
            notes.append(f"no contact-state graph: {exc}")
        else:
            pairs = admissible_transitions(ctx, domain.info, REGISTRY)
            states = tuple(s.name for s in ctx.states)
            transitions = {a: frozenset((x.name, y.name) for x, y in p) for a, p in pairs.items()}
            start, goal = ctx.start_state.name, ctx.goal_state.name
    nodes = set(states)
    path: list[PathEdge] = []
    renamed: dict[str, str] = {}
    extra: list[str] = []
    for i, step in enumerate(plan.steps):
        if step.family is not Family.MOVE_OBJECT:
            continue
        ends = []
        for name, wp in zip(step.contact_state, (0, -1)):
            canon = _state_name(name)
            if canon is None or (nodes and canon not in nodes):
                if step.waypoints:
                    geo = _geometric_state(scenario.world, step.waypoints[wp].object.as_array())
                    renamed[name] = geo
                    canon = geo
                else:
                    canon = name
            if nodes and canon not in nodes and canon not in extra:
                extra.append(canon)
            elif not nodes and canon not in extra:
                extra.append(canon)
            ends.append(canon)
        path.append(PathEdge(i, step.primitive, ends[0], ends[1]))
    if renamed:
        notes.append("plan state names not in the scenario's graph, placed by the geometry: "
                     + ", ".join(f"{a} → {b}" for a, b in sorted(renamed.items())))
    if nodes and extra:
        notes.append("dashed: states the plan passes that the enumeration does not list: " + ", ".join(extra))
    if not path:
        notes.append("the plan moves the object with no MoveObject step" if plan.steps
                     else "no plan: no path to highlight")
    return GraphData(states, transitions, start, goal, tuple(path), tuple(extra), tuple(notes))


def _layout(nodes: Sequence[str], edges: Iterable[tuple[str, str]], start: str | None,
            path_nodes: Sequence[str], loops: Counter[str]) -> dict[str, tuple[float, float]]:
    """Node positions: columns by the number of transitions from the start state (states
    it cannot reach in a last column; the plan's states pushed right so that the plan
    reads left to right); in each column the plan's states on the middle
    line (with room below for the loops of steps that stay in a state), the others above
    and below them, ordered by the mean height of their neighbours already placed."""
    g = nx.DiGraph()
    g.add_nodes_from(nodes)
    g.add_edges_from(edges)
    root = start if start in g else (path_nodes[0] if path_nodes else None)
    depth = nx.single_source_shortest_path_length(g, root) if root is not None else {}
    unreachable = max(depth.values(), default=-1) + 1
    column = {n: depth.get(n, unreachable) for n in nodes}
    seen: set[str] = set()
    for prev, n in zip(path_nodes, path_nodes[1:]):  # the plan reads left to right
        seen.add(prev)
        if n not in seen:
            column[n] = max(column[n], column[prev] + 1)
    on_path = {n: k for k, n in reversed(list(enumerate(path_nodes)))}
    pos: dict[str, tuple[float, float]] = {}
    dx = _GRAPH_DX if len(set(column.values())) <= 8 else _GRAPH_DX_WIDE

    def height(n: str) -> float:
        ys = [pos[m][1] for m in nx.all_neighbors(g, n) if m in pos]
        return float(np.mean(ys)) if ys else 0.0

    for c in sorted(set(column.values())):
        col = [n for n in nodes if column[n] == c]
        middle = sorted((n for n in col if n in on_path), key=on_path.__getitem__)
        rest = sorted((n for n in col if n not in on_path), key=lambda n: (-height(n), n))
        k = (len(rest) + 1) // 2 if middle else len(rest)
        # rows: the states above, the plan's (each followed by its loops' room), those below
        rows: list[tuple[str, float]] = [(n, 1.0) for n in rest[:k]]
        for n in middle:
            rows.append((n, 1.0 + _LOOP_ROWS * min(loops[n], 1) + 0.5 * max(loops[n] - 1, 0)))
        rows += [(n, 1.0) for n in rest[k:]]
        y, placed = 0.0, []
        for n, room in rows:
            placed.append((n, y))
            y -= room
        top = -placed[k][1] if middle else (len(placed) - 1) / 2
        for n, y in placed:
            pos[n] = (c * dx, (y + top) * _GRAPH_DY)
    return pos


def _arc_midpoint(a: tuple[float, float], b: tuple[float, float], rad: float) -> tuple[float, float]:
    """The midpoint of matplotlib's ``arc3,rad=rad`` curve from a to b (equal aspect)."""
    (x1, y1), (x2, y2) = a, b
    dx, dy = x2 - x1, y2 - y1
    return ((x1 + x2) / 2 + rad * dy / 2, (y1 + y2) / 2 - rad * dx / 2)


def _loop(x: float, y: float, box: float, k: int) -> tuple[MplPath, tuple[float, float]]:
    """The ``k``-th loop below a node at (x, y) whose box reaches ``box`` below it (a
    plan step that stays in the state), and where its label goes."""
    depth, half = 0.5 + 0.32 * k, 0.34 + 0.16 * k
    p0, p3 = (x - 0.18, y - box), (x + 0.18, y - box)
    verts = [p0, (x - half, y - depth), (x + half, y - depth), p3]
    path = MplPath(verts, [MplPath.MOVETO, MplPath.CURVE4, MplPath.CURVE4, MplPath.CURVE4])
    return path, (x, y - box * 0.25 - 0.75 * depth)


def _draw_contact_graph(graph: GraphData, plan: Plan, scenario: Scenario) -> Figure:
    """The contact-state graph figure (see the module docstring)."""
    moves = _move_primitives(plan, graph)
    nodes = list(graph.states) + [n for n in graph.extra if n not in graph.states]
    path_nodes: list[str] = []
    for e in graph.path:
        for n in (e.source, e.target):
            if not path_nodes or path_nodes[-1] != n:
                path_nodes.append(n)
    loops: Counter[str] = Counter(e.source for e in graph.path if e.source == e.target)
    all_edges = [(a, b) for pairs in graph.transitions.values() for a, b in pairs]
    pos = _layout(nodes, all_edges + [(e.source, e.target) for e in graph.path], graph.start, path_nodes, loops)
    relevant = _relevant(nodes, all_edges, graph.start, graph.goal)
    on_path = set(path_nodes)

    # legend and title first: the figure's size depends on them
    shown = {a for a, p in graph.transitions.items() if p} | {e.primitive for e in graph.path}
    handles: list[Any] = [Line2D([], [], color=primitive_colour(a, Family.MOVE_OBJECT, moves), lw=2, label=a)
                          for a in sorted(shown)]
    if graph.path:
        handles.append(Line2D([], [], color="black", lw=2.6, label="plan step (number: step index)"))
        handles.append(Patch(facecolor=_PATH_NODE, edgecolor="black", label="state on the plan"))
    if graph.start is not None:
        handles += [Patch(facecolor="white", edgecolor=_START_COLOUR, linewidth=2, label="start state"),
                    Patch(facecolor="white", edgecolor=_GOAL_COLOUR, linewidth=2, label="goal state")]
    if len(relevant) < len(nodes):
        handles.append(Patch(facecolor="white", edgecolor="#c8c8c8", label="state on no start→goal path"))
    n_tr = sum(len(p) for p in graph.transitions.values())
    steps = f"the plan: {len(graph.path)} MoveObject step{'s' if len(graph.path) != 1 else ''}"
    head = (f"{scenario.name}: contact-state graph, {len(graph.states)} states, {n_tr} admissible MoveObject "
            f"transitions; {steps}" if graph.states else f"{scenario.name}: {steps}")

    xs = [p[0] for p in pos.values()] or [0.0]
    ys = [p[1] for p in pos.values()] or [0.0]
    deepest = min((_loop(*pos[n], 0.14, loops[n] - 1)[1][1] for n in loops), default=math.inf)  # lowest label
    xlim = [min(xs) - 1.0, max(xs) + 1.0]
    ylim = [min(min(ys) - 0.35, deepest - 0.3), max(ys) + 0.55]
    inch = 0.75  # inches per layout unit
    min_w = 8.0
    if (xlim[1] - xlim[0]) * inch < min_w:
        grow = (min_w / inch - (xlim[1] - xlim[0])) / 2
        xlim = [xlim[0] - grow, xlim[1] + grow]
    fig_w = (xlim[1] - xlim[0]) * inch
    title = "\n".join(_wrap(t, int(fig_w * 15)) for t in [head, *graph.notes])
    ncol = max(2, min(len(handles), int(fig_w // 2.0)))
    legend_h = 0.22 * math.ceil(len(handles) / ncol) + 0.15
    title_h = 0.2 * (title.count("\n") + 1) + 0.2
    fig = Figure(figsize=(fig_w + 0.2, (ylim[1] - ylim[0]) * inch + legend_h + title_h), layout="constrained")
    ax = fig.add_subplot()
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_axis_off()

    boxes: dict[str, Any] = {}
    for n in nodes:
        x, y = pos[n]
        style: dict[str, Any] = dict(boxstyle="round,pad=0.3", linewidth=0.8, facecolor="white", edgecolor="#808080")
        colour = "#222222"
        if n in on_path:
            style.update(facecolor=_PATH_NODE, edgecolor="black", linewidth=1.3)
        elif n not in relevant:
            colour = "#9a9a9a"
            style.update(edgecolor="#c8c8c8")
        if n in graph.extra and graph.states:
            style.update(linestyle=(0, (3, 2)))
        if n == graph.start:
            style.update(edgecolor=_START_COLOUR, linewidth=2.2)
        elif n == graph.goal:
            style.update(edgecolor=_GOAL_COLOUR, linewidth=2.2)
        boxes[n] = ax.text(x, y, n, ha="center", va="center", fontsize=7.5, color=colour, bbox=style, zorder=5,
                           fontweight="bold" if n in on_path else "normal")
        tags = [(t, c) for t, s, c in (("start", graph.start, _START_COLOUR), ("goal", graph.goal, _GOAL_COLOUR))
                if s == n]
        for k, (t, c) in enumerate(tags):
            ax.text(x, y + 0.24 + 0.2 * k, t, ha="center", va="bottom", fontsize=7, zorder=6, color=c,
                    fontweight="bold")

    fig.legend(handles=handles, loc="outside lower center", ncol=ncol, fontsize=7, frameon=False)
    fig.suptitle(title, fontsize=9)
    half = _box_sizes(fig, ax, boxes)  # the layout is fixed from here

    # parallel edges (several actions on one ordered pair) curve apart
    slot: dict[tuple[str, str, str], float] = {}
    per_pair: Counter[tuple[str, str]] = Counter()
    keys = [(a, x, y) for a in sorted(graph.transitions) for x, y in sorted(graph.transitions[a])]
    keys += [(e.primitive, e.source, e.target) for e in graph.path if e.source != e.target]
    for key in keys:
        if key not in slot:
            slot[key] = 0.12 + 0.14 * per_pair[key[1:]]
            per_pair[key[1:]] += 1

    def arrow(a: str, b: str, rad: float, colour: str, lw: float, alpha: float, z: int) -> None:
        path = _edge_path(np.array(pos[a]), half[a], np.array(pos[b]), half[b], rad)
        ax.add_patch(FancyArrowPatch(path=path, arrowstyle="-|>", mutation_scale=7 + 3 * lw, color=colour, lw=lw,
                                     alpha=alpha, zorder=z, shrinkA=0, shrinkB=0))

    faint = 0.35 if n_tr > 60 else 0.6
    for action in sorted(graph.transitions):
        for a, b in sorted(graph.transitions[action]):
            arrow(a, b, slot[(action, a, b)], primitive_colour(action, Family.MOVE_OBJECT, moves), 0.7, faint, 2)
    drawn: Counter[str] = Counter()
    for e in graph.path:
        colour = primitive_colour(e.primitive, Family.MOVE_OBJECT, moves)
        if e.source == e.target:
            x, y = pos[e.source]
            path, (lx, ly) = _loop(x, y, half[e.source][1], drawn[e.source])
            drawn[e.source] += 1
            ax.add_patch(FancyArrowPatch(path=path, arrowstyle="-|>", mutation_scale=12, color=colour, lw=2.4,
                                         zorder=4))
        else:
            rad = slot[(e.primitive, e.source, e.target)]
            arrow(e.source, e.target, rad, colour, 2.6, 1.0, 4)
            lx, ly = _arc_midpoint(pos[e.source], pos[e.target], rad)
        ax.text(lx, ly, str(e.step), ha="center", va="center", fontsize=7, fontweight="bold", color="white",
                zorder=7, bbox=dict(boxstyle="circle,pad=0.18", facecolor=colour, edgecolor="white", linewidth=0.8))
    return fig


def _box_sizes(fig: Figure, ax: Axes, boxes: dict[str, Any]) -> dict[str, FloatArray]:
    """Half width and half height, in data units, of each node's box. Draws the figure
    once to lay it out, then fixes the layout so that the sizes stay true."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    fig.set_layout_engine("none")
    to_data = ax.transData.inverted()
    out = {}
    for n, text in boxes.items():
        bb = text.get_bbox_patch().get_window_extent()
        (x0, y0), (x1, y1) = to_data.transform([[bb.x0, bb.y0], [bb.x1, bb.y1]])
        out[n] = np.array([abs(x1 - x0) / 2, abs(y1 - y0) / 2])
    return out


def _edge_path(a: FloatArray, ha: FloatArray, b: FloatArray, hb: FloatArray, rad: float,
               gap: float = 0.03) -> MplPath:
    """matplotlib's ``arc3,rad=rad`` curve from box a to box b (centres, half sizes),
    cut where it leaves a and enters b (plus ``gap``): a quadratic Bezier in data units."""
    d = b - a
    c = (a + b) / 2 + rad * np.array([d[1], -d[0]])
    t = np.linspace(0.0, 1.0, 401)[:, None]
    pts = (1 - t) ** 2 * a + 2 * (1 - t) * t * c + t ** 2 * b
    out_a = np.any(np.abs(pts - a) > ha + gap, axis=1)
    out_b = np.any(np.abs(pts - b) > hb + gap, axis=1)
    inside = np.flatnonzero(out_a & out_b)
    t0, t1 = (float(t[inside[0], 0]), float(t[inside[-1], 0])) if inside.size else (0.0, 1.0)

    def blossom(u: float, v: float) -> FloatArray:
        return (1 - u) * (1 - v) * a + ((1 - u) * v + u * (1 - v)) * c + u * v * b

    verts = [blossom(t0, t0), blossom(t0, t1), blossom(t1, t1)]
    return MplPath(verts, [MplPath.MOVETO, MplPath.CURVE3, MplPath.CURVE3])


def _relevant(nodes: Sequence[str], edges: Sequence[tuple[str, str]], start: str | None, goal: str | None
              ) -> set[str]:
    """States on some start→goal path (all states when start or goal is unknown)."""
    if start is None or goal is None:
        return set(nodes)
    g = nx.DiGraph()
    g.add_nodes_from(nodes)
    g.add_edges_from(edges)
    if start not in g or goal not in g:
        return set(nodes)
    return (nx.descendants(g, start) | {start}) & (nx.ancestors(g, goal) | {goal}) | {start, goal}


# --------------------------------------------------------------------------------------
# Entry point
# --------------------------------------------------------------------------------------


def _figure_bytes(fig: Figure, fmt: str, dpi: int) -> bytes:
    """The figure as ``fmt`` bytes, margins cropped, no date or software stamp."""
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi, facecolor="white", bbox_inches="tight", pad_inches=0.1,
                metadata={"Date": None} if fmt == "svg" else {"Software": None})
    return buf.getvalue()


def _write_all(out: Path, data: dict[str, bytes]) -> None:
    """Write every file to a temporary file first, then move them all into place: a
    failure while writing (a full disk) replaces nothing and leaves no temporary file, nor
    the folder when this call created it."""
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        with contextlib.ExitStack() as stack:
            for name, blob in data.items():
                f, _tmp = stack.enter_context(atomic_output(out / name, binary=True))
                f.write(blob)
    except OSError as exc:
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()  # only if empty
        raise RenderError(f"{out}: cannot write the figures: {exc.strerror or exc}") from None


def render_plan(plan: Plan, scenario: Scenario, out_dir: str | os.PathLike[str],
                options: RenderOptions = RenderOptions()) -> RenderedFigures:
    """Draw the plan's figures and write them into ``out_dir`` (created if needed), as
    the files of :data:`FIGURE_FILES`.

    Everything is drawn before anything is written, and every file is written to a
    temporary file before any is moved into place: on an error the folder is as it was.

    Raises
    ------
    RenderError
        ``out_dir`` is not a folder, or a figure's path in it is a folder, or the files
        cannot be written.
    InputError
        The scenario's domain cannot be loaded (only with ``options.graph``).
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise RenderError(f"{out}: --out: not a folder")
    names = [n for files in FIGURE_FILES.values() for n in files]
    for name in names:
        if (out / name).is_dir():
            raise RenderError(f"{out / name}: is a folder, cannot write the figure there")
    track = _Track.of(plan, scenario)
    view = _view(track, scenario)
    panels = snapshots(plan, scenario)
    graph = contact_graph_data(plan, scenario, build=options.graph)
    data: dict[str, bytes] = {}
    with rc_context({"svg.hashsalt": "ldhp-render", "font.size": 8}):
        fig = _draw_snapshots(plan, scenario, track, view, panels, options)
        data["snapshots.png"] = _figure_bytes(fig, "png", options.dpi)
        data["snapshots.svg"] = _figure_bytes(fig, "svg", options.dpi)
        data["animation.gif"], frames = _draw_animation(plan, scenario, track, view, options)
        fig = _draw_contact_graph(graph, plan, scenario)
        data["contact_graph.png"] = _figure_bytes(fig, "png", options.dpi)
        data["contact_graph.svg"] = _figure_bytes(fig, "svg", options.dpi)
    assert sorted(data) == sorted(names)
    _write_all(out, data)
    log.info("wrote %d files into %s (%d panels, %d frames)", len(data), out, len(panels), frames)
    return RenderedFigures(
        out_dir=out,
        snapshots=tuple(out / n for n in FIGURE_FILES["snapshots"]),
        animation=out / FIGURE_FILES["animation"][0],
        contact_graph=tuple(out / n for n in FIGURE_FILES["contact_graph"]),
        frames=frames,
        panels=len(panels),
        task_only=int(track.step[0]) < 0,
    )
