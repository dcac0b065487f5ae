"""Plans (``ldhp-plan/1``, see ``docs/formats/plan.md``): the model, reading and writing.

The last stage of the pipeline: what the planner produces, what the validator checks and
what other tools read. Inside the package poses are :class:`~geometry.poses.Pose` values
(radians); the file holds degrees. Every number is written rounded to
:data:`DECIMALS` decimals, in a stable key order, one waypoint per line.

Reading is strict about what the spec requires (every key of a plan, a step and a
waypoint; numbers finite; poses ``[x, y, theta]``) and names the file and the JSON path of
the first problem (``plan.json: steps[2].waypoints[4].gripper: expected [x, y, theta]``).
The optional ``finger_forces`` of a waypoint is read (and checked) when present and
written when set. Keys the spec does not name are ignored, except in ``stats``, which
keeps them, and ``failure``, this planner's structured account of a failed solve
(:class:`Failure`), which is read (and checked) when present and written when set.
Writing is atomic: a temporary file in the target's folder, then :func:`os.replace`.
"""

from __future__ import annotations

import enum
import json
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, NoReturn

from geometry.poses import Pose
from ldhp_tamp.errors import PlanFormatError
from ldhp_tamp.files import write_text_atomic
from ldhp_tamp.primitives.registry import Family  # the one vocabulary of primitive families

__all__ = [
    "DECIMALS",
    "MAX_ATTEMPTS",
    "PLAN_FORMAT",
    "Failure",
    "FailureCause",
    "FailureTier",
    "Family",
    "Force",
    "Plan",
    "PlanStats",
    "PlanStatus",
    "Point",
    "PRESS_KEY",
    "Press",
    "press_problem",
    "Step",
    "TIME_KEYS",
    "Waypoint",
    "plan_to_json",
    "read_plan",
    "read_plan_string",
    "write_plan",
]

log = logging.getLogger(__name__)

#: The format tag of plan files.
PLAN_FORMAT = "ldhp-plan/1"

#: Decimals kept when writing numbers (mm and degrees): 1 nm, well below any tolerance.
DECIMALS = 6

#: The keys of ``stats.time_s`` the spec names, in file order.
TIME_KEYS: tuple[str, ...] = ("symbolic", "streams", "grasp_graph", "total")

_COUNTER_KEYS: tuple[str, ...] = (
    "contact_state_nodes", "grasp_graph_nodes", "grasp_graph_edges",
    "top_iterations", "refinements", "feasibility_checks",
)

#: A world point (mm).
Point = tuple[float, float]

#: A finger's force on the object (N): ``(normal, tangential)``, see :class:`Waypoint`.
Force = tuple[float, float]


class PlanStatus(str, enum.Enum):
    """Outcome of a solve: a failed solve is a plan with a status, not an exception."""

    SOLVED = "solved"
    FAILED = "failed"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class Waypoint:
    """One instant of a plan.

    Attributes
    ----------
    object : Pose
        Object pose (world, radians).
    gripper : Pose
        Gripper frame pose (world, radians), see docs/formats/scenario.md, "The gripper frame".
    width : float
        Spacing (two-point) or opening (polyline), mm.
    finger_contacts : tuple
        Per finger (finger 1, finger 2) the world point (mm) where it touches the
        object, or ``None``.
    finger_forces : tuple or None
        Optional: per finger the force (N) it applies to the object as
        ``(normal, tangential)``, the tangential component along the touched object
        edge's counter-clockwise direction, or ``None`` for a finger without contact;
        ``None`` altogether when the plan does not say (the spec's optional key).
    """

    object: Pose
    gripper: Pose
    width: float
    finger_contacts: tuple[Point | None, Point | None] = (None, None)
    finger_forces: tuple[Force | None, Force | None] | None = None

    def __post_init__(self) -> None:
        if len(self.finger_contacts) != 2:
            raise ValueError(f"finger_contacts needs two entries, got {len(self.finger_contacts)}")
        pts = tuple(None if p is None else (float(p[0]), float(p[1])) for p in self.finger_contacts)
        object.__setattr__(self, "finger_contacts", pts)
        object.__setattr__(self, "width", float(self.width))
        if self.finger_forces is not None:
            if len(self.finger_forces) != 2:
                raise ValueError(f"finger_forces needs two entries, got {len(self.finger_forces)}")
            if any(f is not None and len(f) != 2 for f in self.finger_forces):
                raise ValueError("finger_forces: each entry is (normal, tangential) or None")
            forces = tuple(None if f is None else (float(f[0]), float(f[1])) for f in self.finger_forces)
            object.__setattr__(self, "finger_forces", forces)


def _parse_press(raw: Any) -> Press:
    return Press(int(raw["finger"]), float(raw["force_n"]))


def press_problem(step: "Step") -> str | None:
    """Why ``step.parameters.press`` is not a press of this planner's convention, or
    ``None`` (also when the step has no such key)."""
    raw = step.parameters.get(PRESS_KEY)
    if raw is None:
        return None
    if step.family is not Family.MOVE_OBJECT:
        return "only a move-object step may ask for a press"
    if not isinstance(raw, Mapping) or set(raw) != {"finger", "force_n"}:
        return 'expected {"finger": 0 or 1, "force_n": newtons}'
    finger, force = raw["finger"], raw["force_n"]
    if isinstance(finger, bool) or not isinstance(finger, int) or isinstance(force, bool) \
            or not isinstance(force, (int, float)):
        return 'expected {"finger": 0 or 1, "force_n": newtons}'
    try:
        Press(finger, float(force))
    except ValueError as exc:  # the value checks are the Press's own
        return str(exc).removeprefix("press: ")
    return None


#: The step parameter that asks the executor for a press (:class:`Press`).
PRESS_KEY = "press"


@dataclass(frozen=True)
class Press:
    """An executor's press before a move-object step (``parameters.press`` of the step:
    ``{"finger": 0 or 1, "force_n": f}``): the executor moves the hand along that finger's
    contact normal, into the object, until the finger's normal force reaches ``force_n``
    newtons (a force-triggered guarded move, "press down"), replays the step's motion
    with that offset, and takes the offset back at the step's end. The step's motion is
    planned with that finger's normal force held at ``force_n`` (its compliance keeps it
    there while the object follows the plan). The parameter is this planner's, within
    the spec's free-form ``parameters``: an executor that does not know it replays the
    step without the press, and a key of that name that does not follow the convention
    is read as no press (with a warning), never refused."""

    finger: int
    force_n: float

    def __post_init__(self) -> None:
        if self.finger not in (0, 1):
            raise ValueError(f"press: finger must be 0 or 1, got {self.finger!r}")
        if not (math.isfinite(self.force_n) and self.force_n > 0):
            raise ValueError(f"press: force_n must be a positive number of newtons, got {self.force_n!r}")

    def as_dict(self) -> dict[str, Any]:
        return {"finger": self.finger, "force_n": round(float(self.force_n), DECIMALS)}


@dataclass(frozen=True)
class Step:
    """One primitive instance: its name in the PDDL domain, family and waypoints.

    ``parameters`` is free-form JSON (kept read-only); ``contact_state`` is the pair
    ``(from, to)`` of contact-state names. A move-object step's ``parameters.press``
    (:data:`PRESS_KEY`) is read as a :class:`Press` (:attr:`press`).
    """

    primitive: str
    family: Family
    parameters: Mapping[str, Any]
    contact_state: tuple[str, str]
    waypoints: tuple[Waypoint, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "family", Family(self.family))
        object.__setattr__(self, "parameters", MappingProxyType(dict(self.parameters)))
        object.__setattr__(self, "contact_state", tuple(self.contact_state))
        object.__setattr__(self, "waypoints", tuple(self.waypoints))
        if len(self.contact_state) != 2:
            raise ValueError("contact_state is a (from, to) pair")

    @property
    def press(self) -> Press | None:
        """The press this move-object step asks for (``parameters.press``), or ``None``.

        ``parameters`` is free-form in the spec, so another tool's key of that name that
        does not follow this planner's convention (a move-object step,
        ``{"finger": 0 or 1, "force_n": positive newtons}``) is no press: ``None``, with
        :func:`press_problem` saying why."""
        if self.parameters.get(PRESS_KEY) is None or press_problem(self):
            return None
        return _parse_press(self.parameters[PRESS_KEY])


class FailureTier(str, enum.Enum):
    """Where a failed solve failed (``failure.tier`` of a plan file)."""

    SETUP = "setup"  #: before any search: the contact states, the goal's contact pose, the input
    SYMBOLIC = "symbolic"  #: the contact-state (PDDL) tier found no plan
    STREAMS = "streams"  #: no object-pose path for the contact-state plan
    BOTTOM = "bottom"  #: the grasp graph found no grasp sequence
    JUDGE = "judge"  #: a grasp sequence was found and refused (plan rules, forward problem, simulation)
    TIMEOUT = "timeout"  #: the ``--timeout`` budget ran out

    def __str__(self) -> str:
        return self.value


class FailureCause(str, enum.Enum):
    """Why a failed solve failed (``failure.cause``): a closed list, documented in
    docs/formats/plan.md, "failure"."""

    NO_CONTACT_POSE = "no-contact-pose"  #: Step 1: the start or goal pose touches nothing
    NO_SYMBOLIC_PLAN = "no-symbolic-plan"  #: no contact-state path (left) from start to goal
    NO_STREAM_SAMPLE = "no-stream-sample"  #: the streams found no pose path for a planned step
    EMPTY_MOTION_SET = "empty-motion-set"  #: no grasp executes a segment (its G_m is empty)
    UNREACHABLE = "unreachable"  #: forward reachability through the grasp graph dies at a segment
    NO_GRASP_PATH = "no-grasp-path"  #: every G_m is non-empty, but no grasp sequence reaches the goal
    PLAN_INVALID = "plan-invalid"  #: the judge: the plan breaks a rule of ldhp-plan/1
    AMBIGUOUS_MOTION = "ambiguous-motion"  #: the judge: the commanded motion has another outcome
    DIVERGES_IN_SIMULATION = "diverges-in-simulation"  #: the judge: the physics replay diverges
    TIMEOUT = "timeout"  #: the time budget ran out
    UNSUPPORTED_INPUT = "unsupported-input"  #: a scenario feature this planner does not handle

    def __str__(self) -> str:
        return self.value


#: At most this many attempts are kept in :attr:`Failure.attempts` (the last ones).
MAX_ATTEMPTS = 20


@dataclass(frozen=True)
class Failure:
    """This planner's structured account of a failed solve (``failure`` of a plan file).

    The plan's ``reason`` is a one-line headline; the detail is here.

    Attributes
    ----------
    tier : FailureTier
        Where the solve failed.
    cause : FailureCause
        Why, from a closed list.
    step : int or None
        The planned contact-state step (0-based index of the symbolic plan's transitions)
        at which it failed, when there is one.
    segment : int or None
        The pose-path segment (after the bisections) at which it failed, when there is one.
    primitive : str or None
        The primitive of that step or segment (for the judge: of the plan step it refused).
    counts : Mapping[str, int]
        The numbers of the search (``top_iterations``, ``pose_paths``, ``forbidden``,
        ``refinements``, ``candidates``, ...).
    attempts : tuple of str
        What failed, in full, in order: every pose path's failure, the streams' dead ends,
        the symbolic tier's last word; the last :data:`MAX_ATTEMPTS` of them.
    """

    tier: FailureTier
    cause: FailureCause
    step: int | None = None
    segment: int | None = None
    primitive: str | None = None
    counts: Mapping[str, int] = field(default_factory=dict)
    attempts: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "tier", FailureTier(self.tier))
        object.__setattr__(self, "cause", FailureCause(self.cause))
        object.__setattr__(self, "counts", MappingProxyType({str(k): int(v) for k, v in self.counts.items()}))
        object.__setattr__(self, "attempts", tuple(str(a) for a in self.attempts)[-MAX_ATTEMPTS:])


def _default_times() -> Mapping[str, float]:
    return MappingProxyType({k: 0.0 for k in TIME_KEYS})


@dataclass(frozen=True)
class PlanStats:
    """Search statistics. ``time_s`` holds at least :data:`TIME_KEYS`; keys of a file's
    ``stats`` the spec does not name are kept in ``extra`` (and written back)."""

    engine: str = ""
    contact_state_nodes: int = 0
    grasp_graph_nodes: int = 0
    grasp_graph_edges: int = 0
    top_iterations: int = 0
    refinements: int = 0
    feasibility_checks: int = 0
    time_s: Mapping[str, float] = field(default_factory=_default_times)
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        times = {k: 0.0 for k in TIME_KEYS}
        times.update({k: float(v) for k, v in self.time_s.items()})
        object.__setattr__(self, "time_s", MappingProxyType(times))
        object.__setattr__(self, "extra", MappingProxyType(dict(self.extra)))


@dataclass(frozen=True)
class Plan:
    """A plan file's content. ``reason`` says why a failed solve failed (one line);
    ``failure``, when set, says it in detail (this planner's extension, optional)."""

    format: str
    scenario: str
    scenario_sha256: str
    status: PlanStatus
    steps: tuple[Step, ...]
    stats: PlanStats
    reason: str | None = None
    failure: Failure | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", PlanStatus(self.status))
        object.__setattr__(self, "steps", tuple(self.steps))

    @property
    def waypoints(self) -> tuple[Waypoint, ...]:
        """All waypoints in order (the joins between steps appear twice)."""
        return tuple(w for s in self.steps for w in s.waypoints)


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------


class _Reader:
    """Turns parsed JSON into a :class:`Plan`, naming the JSON path of any problem."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, where: str, problem: str) -> NoReturn:
        raise PlanFormatError(f"{self.source}: {where}: {problem}" if where else f"{self.source}: {problem}")

    def obj(self, value: Any, where: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            self.fail(where, f"expected an object, got {_kind(value)}")
        return value

    def key(self, d: dict[str, Any], key: str, where: str) -> Any:
        if key not in d:
            self.fail(where, f"missing key {key!r}")
        return d[key]

    def string(self, value: Any, where: str) -> str:
        if not isinstance(value, str):
            self.fail(where, f"expected a string, got {_kind(value)}")
        return value

    def number(self, value: Any, where: str) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(where, f"expected a number, got {_kind(value)}")
        x = float(value)
        if not math.isfinite(x):
            self.fail(where, "expected a finite number")
        return x

    def integer(self, value: Any, where: str) -> int:
        x = self.number(value, where)
        if not x.is_integer() or x < 0:
            self.fail(where, f"expected a non-negative integer, got {value!r}")
        return int(x)

    def numbers(self, value: Any, n: int, where: str, shape: str) -> list[float]:
        if (not isinstance(value, list) or len(value) != n
                or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value)):
            self.fail(where, f"expected {shape}")
        out = [float(v) for v in value]
        if not all(math.isfinite(v) for v in out):
            self.fail(where, f"expected {shape} of finite numbers")
        return out

    def pose(self, value: Any, where: str) -> Pose:
        x, y, theta = self.numbers(value, 3, where, "[x, y, theta]")
        return Pose.from_degrees(x, y, theta)

    def waypoint(self, value: Any, where: str) -> Waypoint:
        d = self.obj(value, where)
        contacts = self.key(d, "finger_contacts", where)
        cw = f"{where}.finger_contacts"
        if not isinstance(contacts, list) or len(contacts) != 2:
            self.fail(cw, "expected [finger 1, finger 2], each [x, y] or null")
        pts = tuple(None if c is None else tuple(self.numbers(c, 2, f"{cw}[{k}]", "[x, y] or null"))
                    for k, c in enumerate(contacts))
        forces = None
        if "finger_forces" in d:
            ff, fw = d["finger_forces"], f"{where}.finger_forces"
            if not isinstance(ff, list) or len(ff) != 2:
                self.fail(fw, "expected [finger 1, finger 2], each [normal, tangential] or null")
            forces = tuple(None if f is None else tuple(self.numbers(f, 2, f"{fw}[{k}]", "[normal, tangential] or null"))
                           for k, f in enumerate(ff))
        return Waypoint(
            object=self.pose(self.key(d, "object", where), f"{where}.object"),
            gripper=self.pose(self.key(d, "gripper", where), f"{where}.gripper"),
            width=self.number(self.key(d, "width", where), f"{where}.width"),
            finger_contacts=pts,  # type: ignore[arg-type]
            finger_forces=forces,  # type: ignore[arg-type]
        )

    def step(self, value: Any, where: str) -> Step:
        d = self.obj(value, where)
        primitive = self.string(self.key(d, "primitive", where), f"{where}.primitive")
        family = self.string(self.key(d, "family", where), f"{where}.family")
        if family not in {f.value for f in Family}:
            self.fail(f"{where}.family", f"expected 'move-object' or 'adjust-grasp', got {family!r}")
        parameters = self.obj(self.key(d, "parameters", where), f"{where}.parameters")
        cs = self.obj(self.key(d, "contact_state", where), f"{where}.contact_state")
        cs_from = self.string(self.key(cs, "from", f"{where}.contact_state"), f"{where}.contact_state.from")
        cs_to = self.string(self.key(cs, "to", f"{where}.contact_state"), f"{where}.contact_state.to")
        wps = self.key(d, "waypoints", where)
        if not isinstance(wps, list):
            self.fail(f"{where}.waypoints", f"expected a list, got {_kind(wps)}")
        step = Step(primitive, Family(family), parameters, (cs_from, cs_to),
                    tuple(self.waypoint(w, f"{where}.waypoints[{i}]") for i, w in enumerate(wps)))
        problem = press_problem(step)
        if problem:  # free-form in the spec: read, not refused; an executor replays no press
            log.warning("%s: %s.parameters.%s is not a press of this planner's convention (%s): no press",
                        self.source, where, PRESS_KEY, problem)
        return step

    def stats(self, value: Any) -> PlanStats:
        d = self.obj(value, "stats")
        kwargs: dict[str, Any] = {}
        if "engine" in d:
            kwargs["engine"] = self.string(d["engine"], "stats.engine")
        for k in _COUNTER_KEYS:
            if k in d:
                kwargs[k] = self.integer(d[k], f"stats.{k}")
        if "time_s" in d:
            t = self.obj(d["time_s"], "stats.time_s")
            kwargs["time_s"] = {k: self.number(v, f"stats.time_s.{k}") for k, v in t.items()}
        known = {"engine", "time_s", *_COUNTER_KEYS}
        kwargs["extra"] = {k: v for k, v in d.items() if k not in known}
        return PlanStats(**kwargs)

    def optional_integer(self, d: dict[str, Any], key: str, where: str) -> int | None:
        value = d.get(key)
        return None if value is None else self.integer(value, f"{where}.{key}")

    def failure(self, value: Any) -> Failure:
        d = self.obj(value, "failure")
        tier = self.string(self.key(d, "tier", "failure"), "failure.tier")
        if tier not in {t.value for t in FailureTier}:
            self.fail("failure.tier", f"expected one of {', '.join(t.value for t in FailureTier)}, got {tier!r}")
        cause = self.string(self.key(d, "cause", "failure"), "failure.cause")
        if cause not in {c.value for c in FailureCause}:
            self.fail("failure.cause", f"expected one of {', '.join(c.value for c in FailureCause)}, got {cause!r}")
        primitive = d.get("primitive")
        if primitive is not None:
            primitive = self.string(primitive, "failure.primitive")
        counts = self.obj(d.get("counts", {}), "failure.counts")
        attempts = d.get("attempts", [])
        if not isinstance(attempts, list):
            self.fail("failure.attempts", f"expected a list, got {_kind(attempts)}")
        return Failure(
            tier=FailureTier(tier), cause=FailureCause(cause),
            step=self.optional_integer(d, "step", "failure"),
            segment=self.optional_integer(d, "segment", "failure"),
            primitive=primitive,
            counts={k: self.integer(v, f"failure.counts.{k}") for k, v in counts.items()},
            attempts=tuple(self.string(a, f"failure.attempts[{i}]") for i, a in enumerate(attempts)),
        )

    def plan(self, value: Any) -> Plan:
        d = self.obj(value, "")
        fmt = self.string(self.key(d, "format", ""), "format")
        if fmt != PLAN_FORMAT:
            self.fail("format", f"unknown format {fmt!r} (expected {PLAN_FORMAT!r})")
        status = self.string(self.key(d, "status", ""), "status")
        if status not in {s.value for s in PlanStatus}:
            self.fail("status", f"expected 'solved' or 'failed', got {status!r}")
        reason = d.get("reason")
        if reason is not None:
            reason = self.string(reason, "reason")
        steps = self.key(d, "steps", "")
        if not isinstance(steps, list):
            self.fail("steps", f"expected a list, got {_kind(steps)}")
        failure = None if d.get("failure") is None else self.failure(d["failure"])
        ignored = sorted(set(d) - {"format", "scenario", "scenario_sha256", "status", "reason", "failure",
                                   "steps", "stats"})
        if ignored:
            log.debug("%s: ignoring unknown keys %s", self.source, ", ".join(ignored))
        return Plan(
            format=fmt,
            scenario=self.string(self.key(d, "scenario", ""), "scenario"),
            scenario_sha256=self.string(self.key(d, "scenario_sha256", ""), "scenario_sha256"),
            status=PlanStatus(status),
            steps=tuple(self.step(s, f"steps[{i}]") for i, s in enumerate(steps)),
            stats=self.stats(self.key(d, "stats", "")),
            reason=reason,
            failure=failure,
        )


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    return {bool: "a boolean", int: "a number", float: "a number", str: "a string",
            list: "a list", dict: "an object"}.get(type(value), type(value).__name__)


def _no_constants(name: str) -> NoReturn:
    raise ValueError(f"{name} is not a JSON number")


def _finite_float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise ValueError(f"number {text} is out of range")
    return x


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    d: dict[str, Any] = {}
    for k, v in pairs:
        if k in d:
            raise ValueError(f"duplicate key {k!r}")
        d[k] = v
    return d


def read_plan_string(text: str, source: str = "<string>") -> Plan:
    """Parse the text of an ``ldhp-plan/1`` file.

    Parameters
    ----------
    text : str
        JSON text.
    source : str
        Name used in error messages (the file name).

    Returns
    -------
    Plan

    Raises
    ------
    PlanFormatError
        Not JSON, or not ``ldhp-plan/1``; the message names ``source`` and the JSON path.

    Examples
    --------
    >>> read_plan_string('{"format": "ldhp-plan/2"}', "p.json")
    Traceback (most recent call last):
    ...
    ldhp_tamp.errors.PlanFormatError: p.json: format: unknown format 'ldhp-plan/2' (expected 'ldhp-plan/1')
    """
    try:
        data = json.loads(text, parse_constant=_no_constants, parse_float=_finite_float,
                          object_pairs_hook=_unique_keys)
    except json.JSONDecodeError as exc:
        raise PlanFormatError(f"{source}: not valid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None
    except (ValueError, RecursionError) as exc:
        raise PlanFormatError(f"{source}: not valid JSON: {exc}") from None
    return _Reader(source).plan(data)


def read_plan(path: str | Path) -> Plan:
    """Read an ``ldhp-plan/1`` file.

    Raises
    ------
    PlanFormatError
        The file cannot be read, is not UTF-8 JSON or is not ``ldhp-plan/1``; the message
        names the file and the JSON path of the problem.
    """
    try:
        text = Path(path).read_bytes().decode("utf-8")
    except OSError as exc:
        raise PlanFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise PlanFormatError(f"{path}: not UTF-8 text: {exc.reason} at byte {exc.start}") from None
    return read_plan_string(text, str(path))


# --------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------


def _num(x: float) -> int | float:
    """Round for the file: ``DECIMALS`` decimals, integral values as integers, no ``-0``."""
    if isinstance(x, bool):
        return x
    r = round(float(x), DECIMALS)
    if not math.isfinite(r):
        raise ValueError(f"cannot write a non-finite number ({x}) to a plan")
    if r.is_integer() and abs(r) < 2**53:
        return int(r)
    return r


def _json_value(value: Any) -> Any:
    """Free-form JSON with its numbers rounded as everywhere else."""
    if isinstance(value, Mapping):
        return {str(k): _json_value(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_value(v) for v in value]
    if isinstance(value, enum.Enum):
        return _json_value(value.value)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return _num(value)
    return value


def _dump(value: Any) -> str:
    return json.dumps(_json_value(value), ensure_ascii=False, allow_nan=False)


def _pose(p: Pose) -> list[int | float]:
    return [_num(v) for v in p.to_degrees()]


def _pair(p: tuple[float, float] | None) -> list[int | float] | None:
    return None if p is None else [_num(p[0]), _num(p[1])]


def _waypoint_json(w: Waypoint) -> str:
    d: dict[str, Any] = {"object": _pose(w.object), "gripper": _pose(w.gripper), "width": _num(w.width),
                         "finger_contacts": [_pair(c) for c in w.finger_contacts]}
    if w.finger_forces is not None:
        d["finger_forces"] = [_pair(f) for f in w.finger_forces]
    return json.dumps(d, allow_nan=False)


def _stats_json(s: PlanStats) -> dict[str, Any]:
    d: dict[str, Any] = {"engine": s.engine}
    d.update({k: getattr(s, k) for k in _COUNTER_KEYS})
    d["time_s"] = dict(s.time_s)
    d.update(s.extra)
    return d


def _failure_json(f: Failure) -> dict[str, Any]:
    return {"tier": f.tier.value, "cause": f.cause.value, "step": f.step, "segment": f.segment,
            "primitive": f.primitive, "counts": dict(f.counts), "attempts": list(f.attempts)}


def plan_to_json(plan: Plan) -> str:
    """The text of a plan file: spec key order, degrees, one waypoint per line.

    Numbers are rounded to :data:`DECIMALS` decimals (integral values written as
    integers); the text ends with a newline.

    Raises
    ------
    ValueError
        A number is not finite (NaN has no JSON spelling).
    """
    lines = ["{"]
    head = [("format", plan.format), ("scenario", plan.scenario),
            ("scenario_sha256", plan.scenario_sha256), ("status", plan.status.value)]
    if plan.reason is not None:
        head.append(("reason", plan.reason))
    lines += [f"  {_dump(k)}: {_dump(v)}," for k, v in head]
    if not plan.steps:
        lines.append('  "steps": [],')
    else:
        lines.append('  "steps": [')
        for i, step in enumerate(plan.steps):
            lines += [
                "    {",
                f'      "primitive": {_dump(step.primitive)},',
                f'      "family": {_dump(step.family.value)},',
                f'      "parameters": {_dump(step.parameters)},',
                f'      "contact_state": {_dump({"from": step.contact_state[0], "to": step.contact_state[1]})},',
            ]
            if step.waypoints:
                lines.append('      "waypoints": [')
                last = len(step.waypoints) - 1
                lines += [f"        {_waypoint_json(w)}{',' if j < last else ''}" for j, w in enumerate(step.waypoints)]
                lines.append("      ]")
            else:
                lines.append('      "waypoints": []')
            lines.append("    }" + ("," if i < len(plan.steps) - 1 else ""))
        lines.append("  ],")
    lines.append(f'  "stats": {_dump(_stats_json(plan.stats))}' + ("," if plan.failure is not None else ""))
    if plan.failure is not None:  # after the spec's keys; one attempt per line
        f = _failure_json(plan.failure)
        attempts = f.pop("attempts")
        lines.append('  "failure": {')
        lines += [f"    {_dump(k)}: {_dump(v)}," for k, v in f.items()]
        if attempts:
            lines.append('    "attempts": [')
            lines += [f"      {_dump(a)}{',' if j < len(attempts) - 1 else ''}" for j, a in enumerate(attempts)]
            lines.append("    ]")
        else:
            lines.append('    "attempts": []')
        lines.append("  }")
    lines.append("}")
    return "\n".join(lines) + "\n"


def write_plan(plan: Plan, path: str | Path) -> Path:
    """Write a plan file atomically.

    The text goes to a temporary file in the target's folder, is flushed to disk, then
    :func:`os.replace` puts it in place: an interrupted run leaves the old file or the
    new one, never part of one, and no temporary file.

    Parameters
    ----------
    plan : Plan
    path : str or Path
        Target file; its folder must exist.

    Returns
    -------
    Path
        The path written.
    """
    target = Path(path)
    text = plan_to_json(plan)  # before touching the disk: a bad value writes nothing
    write_text_atomic(target, text)
    log.info("wrote %s (%d steps, %d waypoints)", target, len(plan.steps), sum(len(s.waypoints) for s in plan.steps))
    return target
