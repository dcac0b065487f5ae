"""Transition priors: which contact-state transitions the bottom tier tends to accept.

The paper's future work asks for "learned priors to accelerate search". A prior here is
a file of counts fitted from earlier solves: for every transition (``tip v1-e1->l4-e1``)
how often the bottom tier found grasps that execute it in a pose path (``accepted``: the
transitions of a solved path) and how often a pose path failed there (``refused``: the
planned step the bottom tier, or a judge, failed at). Every solve records its own counts
in its plan's ``stats`` (``transitions``); :func:`fit_prior` adds them up over plans, and
a solve given the prior (``SolveOptions.prior``, ``ldhp-tamp solve --prior``) *defers*
the transitions it rates below :attr:`TransitionPrior.defer_below`: the symbolic tier plans
without them first, and with them as soon as no plan is left without them. A prior changes
which route is tried first, never what is feasible: the same checks decide every route,
and a deferred transition is used when the task needs it.

State names come from a world's numbering (``v1`` is the object's first vertex, ``e1`` the
environment's first edge): a prior is about the worlds numbered like the ones it was
fitted on (the scenarios it names in ``fit_on``: task 2's slot and its variants of
another length, say); on a world numbered otherwise its labels mean other contacts.

The file (``ldhp-prior/1``, JSON)::

    {"format": "ldhp-prior/1", "fit_on": ["task2_slot_insertion"], "plans": 5,
     "defer_below": 0.25,
     "transitions": {"tip v1-e1->l4-e1": {"accepted": 0, "refused": 15}, ...}}

A transition's acceptance is the posterior mean under a uniform prior,
``(accepted + 1) / (accepted + refused + 2)`` (0.5 for one never seen).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Iterable, Mapping

from ldhp_tamp.errors import InputError
from ldhp_tamp.files import write_text_atomic

#: The format tag of a prior file.
PRIOR_FORMAT = "ldhp-prior/1"
#: The plan ``stats`` key under which a solve records its transitions' outcomes.
STATS_KEY = "transitions"
#: A transition whose acceptance is below this is deferred (default of a fitted prior):
#: refused three times and never accepted (0.2), not once (0.33).
DEFER_BELOW = 0.25


class PriorError(InputError):
    """A prior file that cannot be read, or plans a prior cannot be fitted from."""


@dataclass(frozen=True)
class Outcomes:
    """How often a transition was accepted and refused by the bottom tier."""

    accepted: int = 0
    refused: int = 0

    def __post_init__(self) -> None:
        for name in ("accepted", "refused"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"{name} must be a count (an integer >= 0), got {v!r}")

    @property
    def acceptance(self) -> float:
        """Posterior mean of the acceptance probability (uniform prior)."""
        return (self.accepted + 1) / (self.accepted + self.refused + 2)

    def to_json(self) -> dict[str, int]:
        return {"accepted": self.accepted, "refused": self.refused}

    def __add__(self, other: "Outcomes") -> "Outcomes":
        return Outcomes(self.accepted + other.accepted, self.refused + other.refused)


@dataclass(frozen=True)
class TransitionPrior:
    """Outcome counts per transition label (:attr:`Transition.label`)."""

    transitions: Mapping[str, Outcomes] = field(default_factory=dict)
    fit_on: tuple[str, ...] = ()
    plans: int = 0
    defer_below: float = DEFER_BELOW

    def __post_init__(self) -> None:
        if not (isinstance(self.defer_below, (int, float)) and math.isfinite(self.defer_below)
                and 0.0 <= self.defer_below <= 1.0):
            raise ValueError(f"defer_below must be a number in [0, 1], got {self.defer_below!r}")
        object.__setattr__(self, "transitions", MappingProxyType(dict(sorted(self.transitions.items()))))

    def acceptance(self, label: str) -> float:
        """The acceptance of the transition ``label`` (0.5 when the prior never saw it)."""
        seen = self.transitions.get(label)
        return 0.5 if seen is None else seen.acceptance

    def deferred(self, labels: Iterable[str]) -> frozenset[str]:
        """The labels of ``labels`` rated below :attr:`defer_below`."""
        return frozenset(x for x in labels if self.acceptance(x) < self.defer_below)

    def to_json(self) -> dict[str, Any]:
        return {"format": PRIOR_FORMAT, "fit_on": list(self.fit_on), "plans": self.plans,
                "defer_below": self.defer_below,
                "transitions": {k: v.to_json() for k, v in self.transitions.items()}}


def outcomes_from_stats(extra: Mapping[str, Any], source: str = "<stats>") -> dict[str, Outcomes]:
    """The transition outcomes a plan's ``stats`` record (``{}`` when it has none)."""
    raw = extra.get(STATS_KEY)
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        raise PriorError(f"{source}: stats.{STATS_KEY} must be an object of transition -> counts")
    return {str(k): _outcomes(v, f"{source}: stats.{STATS_KEY}[{k!r}]") for k, v in raw.items()}


def _outcomes(value: Any, where: str) -> Outcomes:
    if not isinstance(value, Mapping) or set(value) - {"accepted", "refused"}:
        raise PriorError(f"{where}: expected {{\"accepted\": N, \"refused\": M}}, got {value!r}")
    try:
        return Outcomes(value.get("accepted", 0), value.get("refused", 0))
    except ValueError as exc:
        raise PriorError(f"{where}: {exc}") from None


def fit_prior(plan_files: Iterable[str | Path], defer_below: float = DEFER_BELOW) -> TransitionPrior:
    """Add up the transition outcomes of the plans in ``plan_files`` (``ldhp-plan/1``
    files written by this planner: solved or failed, each records its own).

    Raises
    ------
    PriorError
        A file that is not a plan (the message names it), or no file at all.
    """
    from ldhp_tamp.plan import read_plan

    files = [Path(f) for f in plan_files]
    if not files:
        raise PriorError("no plan file to fit a prior from")
    total: dict[str, Outcomes] = {}
    names: dict[str, None] = {}
    for f in files:
        plan = read_plan(f)  # PlanFormatError (an InputError) names the file
        names[plan.scenario] = None
        for label, seen in outcomes_from_stats(plan.stats.extra, str(f)).items():
            total[label] = total.get(label, Outcomes()) + seen
    try:
        return TransitionPrior(total, tuple(names), len(files), defer_below)
    except ValueError as exc:
        raise PriorError(str(exc)) from None


def plan_files(paths: Iterable[str | Path]) -> list[Path]:
    """The plan files named by ``paths``: a file as it is, a directory's ``*-plan.json``
    files (recursively, sorted)."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out.extend(sorted(p.rglob("*-plan.json")))
        elif p.is_file():
            out.append(p)
        else:
            raise PriorError(f"{p}: no such file or directory")
    return out


def write_prior(prior: TransitionPrior, path: str | Path) -> Path:
    """Write ``prior`` to ``path`` (atomically)."""
    return write_text_atomic(path, json.dumps(prior.to_json(), indent=2) + "\n")


def read_prior(path: str | Path) -> TransitionPrior:
    """Read an ``ldhp-prior/1`` file.

    Raises
    ------
    PriorError
        The file is missing, not JSON or not a prior (the message names it and the problem).
    """
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise PriorError(f"{p}: cannot read the prior: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PriorError(f"{p}: not a JSON file: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != PRIOR_FORMAT:
        found = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise PriorError(f"{p}: not a prior file: expected \"format\": \"{PRIOR_FORMAT}\", got {found!r}")
    unknown = set(data) - {"format", "fit_on", "plans", "defer_below", "transitions"}
    if unknown:
        raise PriorError(f"{p}: unknown key(s) {', '.join(sorted(unknown))}")
    raw = data.get("transitions", {})
    if not isinstance(raw, dict):
        raise PriorError(f"{p}: \"transitions\" must be an object of transition -> counts")
    fit_on = data.get("fit_on", [])
    if not isinstance(fit_on, list) or not all(isinstance(x, str) for x in fit_on):
        raise PriorError(f"{p}: \"fit_on\" must be a list of scenario names")
    plans = data.get("plans", 0)
    if isinstance(plans, bool) or not isinstance(plans, int) or plans < 0:
        raise PriorError(f"{p}: \"plans\" must be a count, got {plans!r}")
    defer = data.get("defer_below", DEFER_BELOW)
    if isinstance(defer, bool):
        raise PriorError(f"{p}: \"defer_below\" must be a number in [0, 1], got {defer!r}")
    counts = {str(k): _outcomes(v, f"{p}: transitions[{k!r}]") for k, v in raw.items()}
    try:
        return TransitionPrior(counts, tuple(fit_on), plans, defer)
    except ValueError as exc:
        raise PriorError(f"{p}: {exc}") from None
