"""The top tier's symbolic stage: PDDL domain, contact-graph problems, engines, plans.

The only module of the project that imports :mod:`unified_planning`. Data flows through
plain functions over small values, as in pyperplan::

    domain = load_domain("ldhp")                        # parse the file once
    check_against_domain(domain.info, REGISTRY)         # before any search
    graph = ContactGraph(states, transitions, start, goal, start_touching, goal_release)
    problem = build_problem(domain, graph, forbidden)   # model API, ~2 ms
    result = solve(problem, engine="pyperplan")         # SymbolicResult with a status
    emit_pddl(out_dir, problem, iteration)              # --emit-pddl DIR

The domain file is parsed once into a *template* problem (its types, predicates and
actions); each problem is a clone of the template to which the contact states (objects),
the initial facts and the goal are added through unified-planning's model API, which is
two orders of magnitude faster than writing and re-parsing problem text.

Encoding (see ``domains/ldhp.pddl`` and ``docs/design/symbolic.md``): one object of type
``state`` per contact state (``s-l1-e1``); ``(at s)`` for the start; ``(touching)`` or
``(hand-free)``; one static fact ``(can-<a> from to)`` per admissible transition of each
MoveObject action ``<a>`` that the TAMP loop has not forbidden; the goal ``(at g)`` plus
``(hand-free)`` with ``goal_release``. A :class:`~ldhp_tamp.primitives.registry.Sequel`
(transition B may not directly follow transition A) adds a copy of the state between them,
``s-x--after-<A>``, which only A enters and which has every transition of ``s-x`` but B.
"""

from __future__ import annotations

import bisect
import contextlib
import copy
import enum
import logging
import os
import pickle
import re
import select
import signal
import tempfile
import threading
import time
import types
import warnings
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import unified_planning.environment as up_environment
import unified_planning.model as up_model
from unified_planning.environment import Environment, get_environment
from unified_planning.io import PDDLReader, PDDLWriter

if TYPE_CHECKING:  # unified_planning.engines imports every installed engine (ConfigSpace, scipy)
    from unified_planning.engines import Factory, PlanGenerationResult

from geometry.features import ContactState
from ldhp_tamp import budget, engine_names
from ldhp_tamp.errors import DomainError, EngineError, TimeBudgetExceeded
from ldhp_tamp.primitives.registry import (
    ActionInfo,
    DomainInfo,
    Family,
    PrimitiveRegistry,
    Sequel,
    Transition,
    admissibility_predicate,
    check_against_domain,
)
from ldhp_tamp.resources import domains_dir
from ldhp_tamp.scenario import find_domain

__all__ = [
    "ContactGraph",
    "GroundAction",
    "SymbolicDomain",
    "SymbolicProblem",
    "SymbolicResult",
    "SymbolicStatus",
    "Transition",
    "available_engines",
    "build_problem",
    "check_engine",
    "emit_pddl",
    "load_checked_domain",
    "load_domain",
    "parse_domain",
    "prepare_pddl_reader",
    "solve",
]

log = logging.getLogger(__name__)

DEFAULT_ENGINE = "pyperplan"

#: The problem vocabulary every domain must declare (see ``domains/ldhp.pddl``).
STATE_TYPE = "state"
AT = "at"
TOUCHING = "touching"
HAND_FREE = "hand-free"

_TOTAL_COST = "total-cost"

# Fast Downward's driver writes ``output.sas`` into the working directory, so every solve
# runs in a private temporary directory; the working directory belongs to the process,
# hence one solve at a time per process.
_SOLVE_LOCK = threading.Lock()


class _Environment(Environment):
    """unified-planning's :class:`Environment`, its engine factory made when first used.

    ``Environment.__init__`` makes the factory, which imports every installed engine and
    with them ConfigSpace and scipy.stats (0.8 s), though reading a domain and building
    problems never use it: ``ldhp-tamp check`` does not, and a solve makes it when it
    loads (:func:`load_checked_domain`). The attributes are those ``Environment.__init__``
    sets (unified-planning 1.3); ``tests/ldhp_tamp/test_symbolic.py`` checks that they agree.
    """

    def __init__(self) -> None:  # Environment.__init__, but the factory
        import unified_planning.model.walkers as walkers
        from unified_planning.model.type_manager import TypeManager

        self._type_manager = TypeManager()
        self._factory = None
        self._tc = walkers.TypeChecker(self)
        self._expression_manager = up_model.ExpressionManager(self)
        self._free_vars_oracle = up_model.FreeVarsOracle()
        self._simplifier = walkers.Simplifier(self)
        self._substituter = walkers.Substituter(self)
        self._free_vars_extractor = walkers.FreeVarsExtractor()
        self._names_extractor = walkers.NamesExtractor()
        self._credits_stream = None
        self._error_used_name = True

    @property
    def factory(self) -> Factory:
        if self._factory is None:
            from unified_planning.engines import Factory

            self._factory = Factory(self)
        return self._factory


def _environment() -> Environment:
    """unified-planning's global environment, credits banner off.

    The global one, not a private ``Environment()``: up-fast-downward builds expressions
    in the global environment, so ``fast-downward-opt`` fails on problems of any other.
    When none exists yet it is made here, as an :class:`_Environment`, whose engines are
    imported only when one is looked up.
    """
    if up_environment.GLOBAL_ENVIRONMENT is None:
        up_environment.GLOBAL_ENVIRONMENT = _Environment()
    env = get_environment()
    env.credits_stream = None
    return env


# --------------------------------------------------------------------------- engines


def available_engines() -> tuple[str, ...]:
    """Names of the installed one-shot planning engines, sorted. Prints nothing.

    Meta-engines (``replanner[...]``, ``oversubscription[...]``) are left out: they solve
    other kinds of problems than the contact-state tier's.

    Returns
    -------
    tuple of str
        e.g. ``("fast-downward", "fast-downward-opt", "pyperplan", "pyperplan-opt")``.
    """
    factory = _environment().factory
    return tuple(sorted(n for n in factory.engines
                        if "[" not in n and factory.engine(n).is_oneshot_planner()))


def check_engine(domain: SymbolicDomain, engine: str) -> None:
    """Refuse an unknown engine, or one that does not support the domain's features.

    An engine whose supported kind is recorded (:func:`ldhp_tamp.engine_names.recorded_kind`)
    is accepted without importing the engines; any other, and every refusal, is decided
    by the engines themselves, so the messages name every installed engine.

    Raises
    ------
    EngineError
        Naming the installed engines, or those that support the domain.
    """
    recorded = engine_names.recorded_kind(engine)
    if recorded is not None and domain.kind <= up_model.ProblemKind(recorded.features, recorded.version):
        return
    _ask_engines(domain, engine)


def _ask_engines(domain: SymbolicDomain, engine: str) -> None:
    """:func:`check_engine` decided by the engines themselves (imports them all)."""
    installed = available_engines()
    if engine not in installed:
        raise EngineError(f"unknown planning engine {engine!r} for domain {domain.info.source}; "
                          f"installed: {', '.join(installed)}")
    factory = _environment().factory
    kind = domain.kind
    if factory.engine(engine).supports(kind):
        return
    able = [e for e in installed if factory.engine(e).supports(kind)]
    what = ("declares action costs, which it would ignore" if domain.uses_action_costs
            else f"uses features it does not support ({', '.join(sorted(kind.features))})")
    raise EngineError(f"engine {engine!r} cannot solve domain {domain.info.source}: the domain "
                      f"{what}; engines that can: {', '.join(able) or 'none installed'}")


# --------------------------------------------------------------------------- domain


@dataclass(frozen=True, eq=False)
class SymbolicDomain:
    """A parsed PDDL domain: the primitive library, ready to build problems from.

    Attributes
    ----------
    info
        The actions and their families, for the registry check.
    uses_action_costs
        The domain declares ``total-cost``; engines that ignore costs are refused.
    grasp_makers, releasers
        The actions that make ``(touching)``, resp. ``(hand-free)``, true; used to
        explain an unsolvable problem (e.g. no ``approach-contact`` in the domain).
    template, kind
        The unified-planning problem every problem is cloned from, and its problem
        kind (what an engine must support). Only this module touches them.
    """

    info: DomainInfo
    uses_action_costs: bool
    grasp_makers: tuple[str, ...]
    releasers: tuple[str, ...]
    template: up_model.Problem = field(repr=False)
    kind: up_model.ProblemKind = field(repr=False)


def load_domain(domain: str | Path, base: Path | None = None) -> SymbolicDomain:
    """Read and check a domain: a shipped domain's name (``"ldhp"``) or a ``.pddl`` path.

    Names and relative paths are resolved by :func:`ldhp_tamp.scenario.find_domain`
    (relative to ``base``, default the working directory), as for a scenario's
    ``planner.domain``; a loaded scenario's ``settings.domain_path`` is already resolved.

    Raises
    ------
    DomainError
        Unknown domain, unreadable file, PDDL syntax error (with the line when
        unified-planning gives it), or a broken convention (see :func:`parse_domain`).
    """
    path = find_domain(str(domain), base)
    if path is None:
        raise DomainError(f"domain not found: {domain} (neither a shipped domain in "
                          f"{domains_dir()} nor an existing .pddl file)")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DomainError(f"{path}: cannot read domain: {exc}") from exc
    return parse_domain(text, source=str(path))


def load_checked_domain(domain: str | Path, engine: str, registry: PrimitiveRegistry,
                        base: Path | None = None, *, load_engine: bool = True) -> SymbolicDomain:
    """Load a domain and run every check a solve makes before searching.

    The one place those checks are made, so that ``ldhp-tamp check`` refuses exactly what
    ``ldhp-tamp solve`` would refuse before any search:

    1. the domain loads (:func:`load_domain`: found, readable, PDDL that parses, the
       conventions of ``domains/ldhp.pddl``);
    2. every action has an implementation of the same family in ``registry``
       (:func:`~ldhp_tamp.primitives.registry.check_against_domain`);
    3. ``engine`` is installed and supports the domain's features (:func:`check_engine`).

    Parameters
    ----------
    domain
        A shipped domain's name or a ``.pddl`` path (a loaded scenario's
        ``settings.domain_path``), resolved as by :func:`load_domain` against ``base``.
    engine
        The unified-planning engine the solve will use.
    registry
        The primitive registry, normally :data:`ldhp_tamp.primitives.REGISTRY`.
    load_engine
        Import the engines now (unified-planning's engine factory, 0.8 s) and let them
        decide, so that a solve pays for them while loading rather than in its first
        engine call. ``ldhp-tamp check`` passes ``False``: the checks themselves need no
        engine whose supported kind is recorded (:func:`check_engine`).

    Raises
    ------
    DomainError
        The domain does not load, or an action has no (or a mismatched) implementation;
        the message names the domain file.
    EngineError
        Unknown engine, or one that cannot solve the domain; the message names both.
    """
    loaded = load_domain(domain, base)
    check_against_domain(loaded.info, registry)
    if load_engine:  # the engines are imported now, so they decide (one that fails to import is unknown)
        _ask_engines(loaded, engine)
    else:
        check_engine(loaded, engine)
    return loaded


def parse_domain(text: str, source: str = "<string>") -> SymbolicDomain:
    """Parse PDDL domain text; the string twin of :func:`load_domain`.

    Checks the conventions of ``domains/ldhp.pddl``: a type ``state``; predicates
    ``(at ?s - state)``, ``(touching)``, ``(hand-free)``; only instantaneous actions;
    every MoveObject action ``<a>`` (one whose effects change ``at``) requires
    ``(can-<a> ?from ?to)`` on two ``state`` parameters; no action changes a ``can-*``
    predicate.

    Raises
    ------
    DomainError
        Naming ``source``, and the line and column of a syntax error when known.
    """
    _check_requirements(text, source)
    env = _environment()
    template = _parse(env, text, None, source)
    if template.has_fluent(_TOTAL_COST):
        # Parse again with a problem asking to minimise total-cost, so that
        # unified-planning turns the increase effects into action costs (its problem
        # kind then shows ACTION_COSTS and engines that ignore them can be refused).
        name = template.name
        stub = (f"(define (problem {name}) (:domain {name})\n"
                f" (:init (= ({_TOTAL_COST}) 0)) (:goal (and))\n"
                f" (:metric minimize ({_TOTAL_COST})))")
        template = _parse(env, text, stub, source)
        template.name = name
    info = _describe(template, source)
    return SymbolicDomain(
        info=info,
        uses_action_costs=bool(template.quality_metrics),
        grasp_makers=_adders(template, TOUCHING),
        releasers=_adders(template, HAND_FREE),
        template=template,
        kind=template.kind,
    )


#: PDDL requirements a domain may declare: classical planning, STRIPS to ADL, with action
#: costs. Whether the chosen engine supports what the domain uses is checked when it is
#: chosen (:func:`check_engine`).
SUPPORTED_REQUIREMENTS = frozenset({
    ":strips", ":typing", ":negative-preconditions", ":disjunctive-preconditions", ":equality",
    ":existential-preconditions", ":universal-preconditions", ":quantified-preconditions",
    ":conditional-effects", ":adl", ":action-costs"})
#: Requirements of PDDL 2.1 to 3.1 (and PPDDL, HDDL) outside that fragment, and why.
_UNSUPPORTED_REQUIREMENTS = {
    ":durative-actions": "temporal planning", ":duration-inequalities": "temporal planning",
    ":continuous-effects": "temporal planning", ":timed-initial-literals": "temporal planning",
    ":time": "temporal planning", ":numeric-fluents": "numeric planning", ":fluents": "numeric planning",
    ":object-fluents": "object fluents", ":derived-predicates": "derived predicates",
    ":preferences": "preferences", ":constraints": "trajectory constraints",
    ":probabilistic-effects": "probabilistic planning", ":non-deterministic": "non-deterministic planning",
    ":hierarchy": "hierarchical planning", ":method-preconditions": "hierarchical planning"}
_REQUIREMENTS = re.compile(r"\(\s*:requirements\b([^()]*)\)", re.IGNORECASE)


def _check_requirements(text: str, source: str) -> None:
    """Refuse a requirement outside :data:`SUPPORTED_REQUIREMENTS`, naming its line.

    unified-planning's reader ignores most requirements (and answers an unknown one
    with a misleading "Expected ')'"), so they are read here first.
    """
    code = re.sub(r";[^\n]*", lambda m: " " * len(m.group()), text)  # comments out, offsets kept
    for block in _REQUIREMENTS.finditer(code):
        for word in re.finditer(r"\S+", block.group(1)):
            req = word.group().lower()
            if req in SUPPORTED_REQUIREMENTS:
                continue
            line = code.count("\n", 0, block.start(1) + word.start()) + 1
            what = (f"unsupported PDDL requirement {req} ({_UNSUPPORTED_REQUIREMENTS[req]})"
                    if req in _UNSUPPORTED_REQUIREMENTS else f"unknown PDDL requirement {word.group()}")
            raise DomainError(f"{source}:{line}: {what}; the contact-state tier is classical "
                              f"planning (supported: {' '.join(sorted(SUPPORTED_REQUIREMENTS))})")


@contextlib.contextmanager
def _no_packrat() -> Iterator[None]:
    """pyparsing without packrat memoization for the duration.

    unified-planning's ANML grammar turns packrat on for the whole process when
    ``unified_planning.io`` is imported, with pyparsing's FIFO cache of 128 entries,
    whose eviction (``next(iter(dict))`` after thousands of pops) costs more than the
    backtracking it saves on PDDL: a domain parses in about half the time without it
    (0.03 s instead of 0.06 s for ``domains/ldhp.pddl``), to the same problem. The
    previous state is put back, so that an ANML reader elsewhere keeps its memo.
    """
    from pyparsing import ParserElement

    saved = {name: ParserElement.__dict__[name] for name in ("_parse", "_packratEnabled", "_left_recursion_enabled", "packrat_cache")
             if name in ParserElement.__dict__}
    ParserElement.disable_memoization()
    try:
        yield
    finally:
        for name, value in saved.items():
            setattr(ParserElement, name, value)


#: unified-planning's PDDL reader of each environment, whose grammar (pyparsing elements,
#: 0.02 s to build) is made once per process: a parse reads with a copy of it.
_READERS: dict[int, tuple[Environment, PDDLReader]] = {}


def prepare_pddl_reader() -> None:
    """Build unified-planning's PDDL grammar for the global environment now, not in the
    first parse: what a sweep's worker processes do once, with their imports
    (:mod:`ldhp_tamp.solver_preload`). A parse of a small domain and problem then
    streamlines its elements (pyparsing does that in an element's first parse, once per
    process: 222 elements, 14 ms of a cell's first domain parse otherwise)."""
    env = _environment()
    _reader(env)
    _parse(env, _WARM_DOMAIN, _WARM_PROBLEM, "<the PDDL reader's warm-up>")


#: A domain and problem for :func:`prepare_pddl_reader` (an action with parameters: the
#: reader parses those with a grammar of their own).
_WARM_DOMAIN = """(define (domain warm-up) (:requirements :strips :typing) (:types thing)
  (:predicates (p ?x - thing))
  (:action a :parameters (?x - thing) :precondition (p ?x) :effect (not (p ?x))))"""
_WARM_PROBLEM = """(define (problem warm-up) (:domain warm-up) (:objects o - thing) (:init (p o))
  (:goal (and (p o))))"""


def _reader(env: Environment) -> PDDLReader:
    """A PDDL reader of ``env`` for one parse: a copy of the environment's first one.

    The grammar's elements keep nothing of a parse (packrat memoization is off while
    parsing, :func:`_no_packrat`); the reader's one attribute a parse sets, the
    ``total-cost`` fluent it found, starts unset in each copy. Should a version of
    unified-planning not have that attribute, every parse gets a new reader."""
    hit = _READERS.get(id(env))
    if hit is None or hit[0] is not env:
        hit = _READERS[id(env)] = (env, PDDLReader(env))
    template = hit[1]
    if not hasattr(template, "_totalcost"):
        return PDDLReader(env)
    reader = copy.copy(template)
    reader._totalcost = None
    return reader


def _parse(env: Environment, domain_text: str, problem_text: str | None,
           source: str) -> up_model.Problem:
    try:
        with warnings.catch_warnings(), _no_packrat():
            warnings.simplefilter("ignore")
            return _reader(env).parse_problem_string(domain_text, problem_text)
    except TimeBudgetExceeded:  # the solve's alarm interrupted the parse: not the domain's fault
        raise
    except Exception as exc:  # the reader raises pyparsing, SyntaxError, UP and others
        line, col = getattr(exc, "lineno", None), getattr(exc, "col", None)
        where = f"{source}:{line}:{col}" if line is not None else source
        message = getattr(exc, "msg", None) if line is not None else None
        raise DomainError(f"{where}: PDDL error: {message or exc}") from exc


def _conjuncts(node: up_model.FNode) -> Iterator[up_model.FNode]:
    if node.is_and():
        for arg in node.args:
            yield from _conjuncts(arg)
    else:
        yield node


def _precondition_atoms(action: up_model.InstantaneousAction) -> Iterator[up_model.FNode]:
    """The conjuncts of an action's precondition, ``and`` flattened."""
    for pre in action.preconditions:
        yield from _conjuncts(pre)


def _describe(template: up_model.Problem, source: str) -> DomainInfo:
    """Read the actions, derive their families and check the conventions."""
    where = f"{source}: "
    if not template.has_type(STATE_TYPE):
        raise DomainError(where + f"the domain declares no type {STATE_TYPE!r} "
                          "(one object per contact state)")
    state = template.user_type(STATE_TYPE)
    for name, arity in ((AT, 1), (TOUCHING, 0), (HAND_FREE, 0)):
        fluent = template.fluent(name) if template.has_fluent(name) else None
        if (fluent is None or fluent.arity != arity or not fluent.type.is_bool_type()
                or any(p.type != state for p in fluent.signature)):
            shape = "(at ?s - state)" if arity else f"({name})"
            raise DomainError(where + f"the domain must declare the predicate {shape}: "
                              "the problem builder writes the start and goal with it")
    static = {admissibility_predicate(a.name) for a in template.actions}
    actions: list[ActionInfo] = []
    for action in template.actions:
        if not isinstance(action, up_model.InstantaneousAction):
            raise DomainError(where + f"action {action.name!r} is not instantaneous")
        changed = {e.fluent.fluent().name for e in action.effects}
        touched_static = sorted(changed & static)
        if touched_static:
            raise DomainError(where + f"action {action.name!r} changes {touched_static[0]}, "
                              "but can-* predicates are static: the planner writes them")
        family = Family.MOVE_OBJECT if AT in changed else Family.ADJUST_GRASP
        params = tuple(p.name for p in action.parameters)
        actions.append(ActionInfo(action.name, family, params,
                                  _admissibility(template, action, state)))
    return DomainInfo(name=template.name, source=source, actions=tuple(actions))


def _admissibility(template: up_model.Problem, action: up_model.InstantaneousAction,
                   state: up_model.Type) -> tuple[int, int] | None:
    """Parameter indices of ``(can-<action> ?from ?to)`` in the precondition, if any."""
    predicate = admissibility_predicate(action.name)
    if not template.has_fluent(predicate):
        return None
    fluent = template.fluent(predicate)
    if fluent.arity != 2 or any(p.type != state for p in fluent.signature):
        return None
    names = [p.name for p in action.parameters]
    for atom in _precondition_atoms(action):
        if (atom.is_fluent_exp() and atom.fluent() == fluent
                and all(a.is_parameter_exp() for a in atom.args)):
            i, j = (names.index(a.parameter().name) for a in atom.args)
            if i != j:
                return (i, j)
    return None


def _adders(template: up_model.Problem, name: str) -> tuple[str, ...]:
    """Actions that can make the 0-ary predicate ``name`` true while it is false: an
    effect sets it and no precondition requires it already."""
    fluent = template.fluent(name)
    return tuple(
        a.name for a in template.actions
        if any(e.fluent.fluent() == fluent and e.value.is_true() for e in a.effects)
        and not any(atom.is_fluent_exp() and atom.fluent() == fluent
                    for atom in _precondition_atoms(a)))


# --------------------------------------------------------------------------- problems


@dataclass(frozen=True)
class ContactGraph:
    """The contact-state graph of one task: the input of the symbolic tier.

    Attributes
    ----------
    states
        Every contact state the graph knows, ``FREE`` included if air-moves are used.
    transitions
        MoveObject action name -> its admissible ``(from_state, to_state)`` pairs
        (:meth:`PrimitiveRegistry.admissible_transitions` computes it). An action of
        the domain missing here has no admissible transition; an entry for an action
        the domain does not declare is ignored (the primitive was removed).
    start, goal
        The contact states of the start and goal contact poses T'0 and T'g.
    start_touching
        The object starts held (a ``start_grasp``); otherwise the hand starts free.
    goal_release
        The gripper must end out of contact with the object.

    Raises
    ------
    ValueError
        Duplicate states, or a start, goal or transition endpoint not in ``states``
        (a bug of the code that built the graph, not a user error).
    """

    states: tuple[ContactState, ...]
    transitions: Mapping[str, frozenset[tuple[ContactState, ContactState]]]
    start: ContactState
    goal: ContactState
    start_touching: bool = False
    goal_release: bool = False

    def __post_init__(self) -> None:
        known = set(self.states)
        if len(known) != len(self.states):
            raise ValueError("ContactGraph.states has duplicates")
        for what, s in (("start", self.start), ("goal", self.goal)):
            if s not in known:
                raise ValueError(f"ContactGraph.{what} {s} is not among the states")
        frozen = {name.lower(): frozenset(pairs) for name, pairs in self.transitions.items()}
        for name, pairs in frozen.items():
            for a, b in pairs:
                if a not in known or b not in known:
                    raise ValueError(f"transition {name} {a} -> {b}: state not in the graph")
        object.__setattr__(self, "transitions", types.MappingProxyType(frozen))

    def all_transitions(self) -> frozenset[Transition]:
        """Every admissible transition as a :class:`Transition`."""
        return frozenset(Transition(name, a, b)
                         for name, pairs in self.transitions.items() for a, b in pairs)


@dataclass(frozen=True, eq=False)
class SymbolicProblem:
    """One top-tier problem: a contact graph, minus what the TAMP loop forbade, as PDDL.

    Attributes
    ----------
    domain, graph
        What it was built from.
    forbidden
        The forbidden transitions that the graph did admit (their facts are omitted),
        including those of sequels that could not be compiled (see :func:`build_problem`).
    sequels
        The sequels compiled as state copies.
    admitted
        Number of ``can-*`` facts written.
    up_problem
        The unified-planning problem. Only this module touches it.
    states_by_name
        PDDL object name -> contact state (a state's copies map to the state itself).
    """

    domain: SymbolicDomain
    graph: ContactGraph
    forbidden: frozenset[Transition]
    admitted: int
    up_problem: up_model.Problem = field(repr=False)
    states_by_name: Mapping[str, ContactState] = field(repr=False)
    sequels: frozenset[Sequel] = frozenset()


class _ClosedWorldProblem(up_model.Problem):
    """A problem of this module: STRIPS, every predicate false unless set, only true
    facts set. Its initial state is therefore its explicit facts, which is what
    :attr:`initial_values` returns here: unified-planning's own property builds an
    expression for every ground fluent (quadratic in the number of states, ~1 s per
    problem with 80 states), and the engines we hand problems to (up-pyperplan, the PDDL
    writer used for Fast Downward) keep only the true ones anyway."""

    @property
    def initial_values(self) -> dict[up_model.FNode, up_model.FNode]:
        return dict(self.explicit_initial_values)


def _copy_name(state: ContactState, after: Transition) -> str:
    """The PDDL object of ``state`` entered by ``after``: ``s-v1-e1--after-tip-s-l1-e1``."""
    return f"{state.pddl_name}--after-{after.action}-{after.from_state.pddl_name}"


def build_problem(domain: SymbolicDomain, graph: ContactGraph,
                  forbidden: Collection[Transition | Sequel] = frozenset()) -> SymbolicProblem:
    """Build the PDDL problem of ``graph`` through the model API, without ``forbidden``.

    Only true facts are written (the admissible transitions), so the problem grows with
    the number of transitions, not with the square of the number of states.

    Parameters
    ----------
    domain
        From :func:`load_domain`, parsed once per run.
    graph
        States, admissible transitions, start, goal and the hand at both ends.
    forbidden
        What the TAMP loop found unrealisable. A :class:`Transition` loses its ``can-*``
        fact, so no engine can use it again. A :class:`Sequel` (``then`` may not directly
        follow ``after``) is compiled into the problem, so that it too works with every
        engine and the domain stays as written: the state s between them gets a copy,
        an object of its own that ``after`` leads to instead of s and that has every
        transition out of s except ``then``. A sequel through the goal state cannot be
        compiled (the goal names one object) and forbids ``then`` outright.
    """
    env = _environment()
    em = env.expression_manager
    problem = domain.template.clone()
    problem.__class__ = _ClosedWorldProblem  # same layout, closed-world initial_values
    problem.name = domain.info.name
    state_type = problem.user_type(STATE_TYPE)

    banned = {t for t in forbidden if isinstance(t, Transition)}
    sequels: set[Sequel] = set()
    for q in forbidden:
        if isinstance(q, Sequel):
            if q.then.from_state == graph.goal:
                banned.add(q.then)
            else:
                sequels.add(q)
    # The copies: state -> the transitions entering it that lead to a copy, and what
    # each copy lacks.
    lacks: dict[Transition, set[Transition]] = {}
    for q in sequels:
        lacks.setdefault(q.after, set()).add(q.then)
    copies: dict[ContactState, list[Transition]] = {}
    for after in sorted(lacks, key=str):
        copies.setdefault(after.to_state, []).append(after)

    objects = {s: up_model.Object(s.pddl_name, state_type, env) for s in graph.states}
    copy_objects = {after: up_model.Object(_copy_name(after.to_state, after), state_type, env)
                    for entries in copies.values() for after in entries
                    if after.to_state in objects}
    problem.add_objects(objects.values())
    problem.add_objects(copy_objects.values())
    at = problem.fluent(AT)
    problem.set_initial_value(em.FluentExp(at, [objects[graph.start]]), True)
    problem.set_initial_value(
        em.FluentExp(problem.fluent(TOUCHING if graph.start_touching else HAND_FREE)), True)

    used: set[Transition] = set()
    admitted = 0
    declared = domain.info.names(Family.MOVE_OBJECT)
    for name in sorted(set(graph.transitions) - set(declared)):
        log.debug("transitions of %r ignored: the domain has no such MoveObject action", name)
    for name in declared:
        predicate = problem.fluent(admissibility_predicate(name))
        pairs = sorted(graph.transitions.get(name, ()),
                       key=lambda p: (p[0].pddl_name, p[1].pddl_name))
        for a, b in pairs:
            t = Transition(name, a, b)
            if t in banned:
                used.add(t)
                continue
            target = copy_objects.get(t, objects[b])
            sources = [objects[a]] + [copy_objects[after] for after in copies.get(a, ())
                                      if after in copy_objects and t not in lacks[after]]
            for source in sources:
                problem.set_initial_value(em.FluentExp(predicate, [source, target]), True)
                admitted += 1

    problem.add_goal(em.FluentExp(at, [objects[graph.goal]]))
    if graph.goal_release:
        problem.add_goal(em.FluentExp(problem.fluent(HAND_FREE)))
    for t in sorted(banned - used, key=str):
        log.debug("forbidden transition %s is not in the graph", t)
    by_name = {s.pddl_name: s for s in graph.states}
    by_name.update({o.name: after.to_state for after, o in copy_objects.items()})
    return SymbolicProblem(
        domain=domain, graph=graph, forbidden=frozenset(used), admitted=admitted,
        up_problem=problem, states_by_name=types.MappingProxyType(by_name),
        sequels=frozenset(q for q in sequels if q.after in copy_objects),
    )


# --------------------------------------------------------------------------- results


class SymbolicStatus(enum.Enum):
    """How a top-tier solve ended. Every engine status maps to one of these."""

    SOLVED = "solved"
    UNSOLVABLE = "unsolvable"
    """Proven: no contact-state plan exists with the declared primitives."""
    NOT_FOUND = "not-found"
    """An incomplete engine found no plan; one may still exist."""
    TIMEOUT = "timeout"
    MEMOUT = "memout"
    ERROR = "error"
    """The engine failed, or reported the problem unsupported."""


#: unified-planning's ``PlanGenerationResultStatus``, by member name.
_STATUS = {
    "SOLVED_SATISFICING": SymbolicStatus.SOLVED,
    "SOLVED_OPTIMALLY": SymbolicStatus.SOLVED,
    "UNSOLVABLE_PROVEN": SymbolicStatus.UNSOLVABLE,
    "UNSOLVABLE_INCOMPLETELY": SymbolicStatus.NOT_FOUND,
    "TIMEOUT": SymbolicStatus.TIMEOUT,
    "MEMOUT": SymbolicStatus.MEMOUT,
    "INTERNAL_ERROR": SymbolicStatus.ERROR,
    "UNSUPPORTED_PROBLEM": SymbolicStatus.ERROR,
    "INTERMEDIATE": SymbolicStatus.ERROR,
}

# up-pyperplan 1.1 compares its search *function* with search names when no plan is
# found, so it always reports UNSOLVABLE_INCOMPLETELY; the searches these engines run
# (wastar for pyperplan, astar for pyperplan-opt) are exhaustive on a finite task, so
# their "no plan" is a proof.
_EXHAUSTIVE_ENGINES = frozenset({"pyperplan", "pyperplan-opt"})
#: Engines that run as Python code in this process (no subprocess of their own), so that
#: a signal can interrupt them: the TAMP loop runs them here when the budget's alarm is
#: armed, instead of in a child process (which costs a fork per call).
IN_PROCESS_ENGINES = frozenset({"pyperplan", "pyperplan-opt"})


@dataclass(frozen=True)
class GroundAction:
    """One step of a symbolic plan.

    Attributes
    ----------
    name
        The PDDL action (``"tip"``).
    family
        Its family in the domain.
    args
        The PDDL object names of its arguments.
    from_state, to_state
        For a MoveObject action, the contact states it connects; ``None`` otherwise.
    """

    name: str
    family: Family
    args: tuple[str, ...] = ()
    from_state: ContactState | None = None
    to_state: ContactState | None = None

    @property
    def transition(self) -> Transition | None:
        """The :class:`Transition` to forbid if this step cannot be realised."""
        if self.from_state is None or self.to_state is None:
            return None
        return Transition(self.name, self.from_state, self.to_state)

    def __str__(self) -> str:
        return f"({' '.join((self.name, *self.args))})"


@dataclass(frozen=True)
class SymbolicResult:
    """The outcome of one solve: a status, the plan (empty unless solved), a reason.

    Attributes
    ----------
    status
        See :class:`SymbolicStatus`.
    actions
        The plan, in order; MoveObject steps carry their contact states.
    reason
        One line for logs and the user: what was found, or why nothing was.
    time_s
        Wall time of the engine call (the problem build is not included).
    engine
        The engine's name.
    """

    status: SymbolicStatus
    actions: tuple[GroundAction, ...]
    reason: str
    time_s: float
    engine: str

    @property
    def solved(self) -> bool:
        return self.status is SymbolicStatus.SOLVED

    def transitions(self) -> tuple[Transition, ...]:
        """The MoveObject steps of the plan, as transitions."""
        return tuple(t for a in self.actions if (t := a.transition) is not None)


@contextlib.contextmanager
def _private_working_directory() -> Iterator[None]:
    """Run the body in a fresh temporary directory; restore the working directory."""
    with tempfile.TemporaryDirectory(prefix="ldhp-solve-") as tmp:
        previous = os.getcwd()
        os.chdir(tmp)
        try:
            yield
        finally:
            os.chdir(previous)


def solve(problem: SymbolicProblem, engine: str = DEFAULT_ENGINE,
          timeout_s: float | None = None) -> SymbolicResult:
    """Solve a problem with a unified-planning engine chosen by name.

    Every solve runs under a module-wide lock in a private temporary working directory
    (Fast Downward writes ``output.sas`` into the working directory), so solves never
    run in parallel within a process and never leave files behind.

    Parameters
    ----------
    problem
        From :func:`build_problem`.
    engine
        An entry of :func:`available_engines`: ``pyperplan`` (default),
        ``fast-downward``, their ``-opt`` variants, or any other installed engine.
    timeout_s
        Wall-time limit of the engine call. It is enforced here, for every engine
        (pyperplan ignores unified-planning's own timeout): the call runs in a forked
        child process, killed with its process group when the limit passes (about 25 ms
        of overhead per call; where there is no fork, the engine gets the limit as its own
        timeout). ``None`` (default): no limit, and the engine runs in this process.

    Returns
    -------
    SymbolicResult
        A failed solve is a status with a reason, not an exception; a killed engine is
        :attr:`SymbolicStatus.TIMEOUT`.

    Raises
    ------
    EngineError
        Unknown engine (the message lists the installed ones), or an engine that does
        not support the domain, e.g. one that would ignore its action costs.
    """
    check_engine(problem.domain, engine)
    start = time.perf_counter()
    try:
        with _SOLVE_LOCK, _private_working_directory():
            if timeout_s is None or not hasattr(os, "fork"):
                answer = _run_engine(problem, engine, timeout_s)
            else:
                answer = _run_engine_in_child(problem, engine, timeout_s)
    except TimeBudgetExceeded:  # the solve's budget interrupted the engine: not its failure
        raise
    except Exception as exc:  # any engine failure is a result, not a crash
        elapsed = time.perf_counter() - start
        log.warning("engine %s failed: %s", engine, exc)
        return SymbolicResult(SymbolicStatus.ERROR, (), f"engine {engine} failed: {exc}",
                              elapsed, engine)
    elapsed = time.perf_counter() - start
    for w in answer.warnings:
        log.info("engine %s: %s", engine, w)
    return _result(problem, answer, engine, elapsed, timeout_s)


@dataclass(frozen=True)
class _Answer:
    """What an engine call returns, reduced to picklable values (it may cross a process
    boundary): the status, the plan's ``(action, argument names)`` (``None`` without a
    plan), the engine's last log line and the warnings it raised."""

    status: str  # the name of unified-planning's PlanGenerationResultStatus
    actions: tuple[tuple[str, tuple[str, ...]], ...] | None
    last_log: str
    warnings: tuple[str, ...] = ()


def _patch_pyperplan() -> None:
    """Two fixes to pyperplan's grounding, installed once, before the first pyperplan call.

    - Plans independent of ``PYTHONHASHSEED``: pyperplan grounds each action's operators
      from a *set* of object names, so the order of ``task.operators`` -- hence of
      successors, of the search's tie-breaking, and of the plan among equally good ones --
      changes from one process to the next. The operators are sorted by name after
      grounding (``up_pyperplan.engine`` calls ``_ground`` by that name).
    - Speed: its static-precondition filter (``grounding._find_pred_in_init``) compiles a
      regular expression per (predicate, object, position) and matches it against every
      fact of the initial state: 4,000 compilations and a million matches per problem of
      task 2, 0.15 s of each solve. :func:`_find_pred_in_init` gives the same answers from
      an index of the initial state.
    """
    import pyperplan.grounding as grounding
    import up_pyperplan.engine as engine  # the engine is installed: the factory made it

    if not getattr(grounding._find_pred_in_init, "indexed", False):
        _REPLACED["_find_pred_in_init"] = grounding._find_pred_in_init  # kept for the tests
        grounding._find_pred_in_init = _find_pred_in_init
    ground = engine._ground
    if getattr(ground, "sorted_operators", False):
        return

    def sorted_ground(*args: object, **kwargs: object) -> object:
        task = ground(*args, **kwargs)
        task.operators.sort(key=lambda op: op.name)
        return task

    sorted_ground.sorted_operators = True  # type: ignore[attr-defined]
    engine._ground = sorted_ground


_REPLACED: dict[str, object] = {}  # pyperplan's functions that _patch_pyperplan replaced
_WORD = re.compile(r"[\w\d-]+")
_INIT_INDEX: list[object] = [None, None]  # (the initial state it indexes, the index)


def _init_index(init: Collection[str]) -> dict[tuple[str, int], list[str]]:
    """(predicate, position) -> the sorted argument tokens of the facts ``(pred a0 a1 ..)``
    at that position (the last keeps its ``)``), for the positions pyperplan's pattern
    can reach: every earlier argument a word (letters, digits, ``_`` and ``-``)."""
    if _INIT_INDEX[0] is init:
        return _INIT_INDEX[1]  # type: ignore[return-value]
    index: dict[tuple[str, int], list[str]] = {}
    for fact in init:
        if not fact.startswith("("):
            continue
        parts = fact[1:].split(" ")
        for pos, tok in enumerate(parts[1:]):
            if pos > 0 and not _WORD.fullmatch(parts[pos]):
                break
            index.setdefault((parts[0], pos), []).append(tok)
    for toks in index.values():
        toks.sort()
    _INIT_INDEX[0], _INIT_INDEX[1] = init, index
    return index


def _find_pred_in_init(pred_name: str, param: str, sig_pos: int, init: Collection[str]) -> bool:
    """pyperplan's ``grounding._find_pred_in_init`` (is there a fact ``(pred_name ...)``
    whose argument ``sig_pos`` starts with ``param``: its pattern is a prefix match) by a
    binary search in :func:`_init_index` instead of a regular expression per call. Facts
    are pyperplan's own strings, arguments separated by single spaces."""
    toks = _init_index(init).get((pred_name, sig_pos))
    if not toks:
        return False
    i = bisect.bisect_left(toks, param)
    return i < len(toks) and toks[i].startswith(param)


_find_pred_in_init.indexed = True  # type: ignore[attr-defined]


def _run_engine(problem: SymbolicProblem, engine: str, timeout_s: float | None) -> _Answer:
    """Call the engine in this process (the caller holds the lock and the directory)."""
    factory = _environment().factory
    if engine in _EXHAUSTIVE_ENGINES:  # the pyperplan engines
        _patch_pyperplan()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # The engine's class made directly, as ``factory.OneshotPlanner(name=engine)`` makes
        # it, without the factory's credits: those call ``inspect.stack()`` (reading the
        # source of every frame of the call: 12 ms in a bench cell) before finding that
        # the credits stream is off. check_engine has checked that it is a one-shot planner.
        if engine not in factory.engines:
            raise EngineError(f"the planning engine {engine!r} is not installed")
        with factory.engine(engine)() as planner:
            planner.skip_checks = True  # check_engine checked the domain's kind
            answer = planner.solve(problem.up_problem, timeout=timeout_s)
    actions = None if answer.plan is None else tuple(
        (ai.action.name, tuple(p.object().name for p in ai.actual_parameters))
        for ai in answer.plan.actions)
    return _Answer(answer.status.name, actions, _last_log(answer), tuple(str(w.message) for w in caught))


def _run_engine_in_child(problem: SymbolicProblem, engine: str, timeout_s: float) -> _Answer:
    """:func:`_run_engine` in a forked child that sends its :class:`_Answer` back through a
    pipe; killed, with the engine's own subprocesses (they share its process group), when
    ``timeout_s`` passes. A bare :func:`os.fork` rather than :mod:`multiprocessing`: the
    overhead per call is about 20 ms instead of 60 (measured by ``benchmarks/startup.py``)."""
    if timeout_s <= 0:
        return _Answer("TIMEOUT", None, "no time left")
    deadline = budget.clock() + timeout_s  # the solve's clock, which a test may replace
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns
        try:
            os.close(read_end)
            _engine_child(write_end, problem, engine, timeout_s)
        finally:
            os._exit(0)
    os.close(write_end)
    chunks: list[bytes] = []
    finished = False
    try:
        while (left := deadline - budget.clock()) > 0:
            ready, _, _ = select.select([read_end], [], [], left)
            if not ready:
                continue  # the deadline is the budget's clock's, read again
            chunk = os.read(read_end, 1 << 16)
            if not chunk:
                finished = True
                break
            chunks.append(chunk)
    finally:
        os.close(read_end)
        if not finished:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(pid, signal.SIGKILL)
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        _, wait_status = os.waitpid(pid, 0)
    if not finished:
        return _Answer("TIMEOUT", None, f"killed after {timeout_s:.3g} s")
    if not chunks:
        raise RuntimeError(f"the engine's process died ({_exit_description(wait_status)})")
    kind, payload = pickle.loads(b"".join(chunks))
    if kind == "error":
        raise RuntimeError(payload)
    return payload


def _exit_description(wait_status: int) -> str:
    if os.WIFSIGNALED(wait_status):
        return f"killed by signal {os.WTERMSIG(wait_status)}"
    return f"exit status {os.waitstatus_to_exitcode(wait_status)}"


def _engine_child(write_end: int, problem: SymbolicProblem, engine: str, timeout_s: float) -> None:
    """The child's side of :func:`_run_engine_in_child`: one pickled answer on the pipe."""
    os.setpgrp()  # its own process group, so that a kill reaches the engine's subprocesses
    try:
        message: tuple[str, object] = ("ok", _run_engine(problem, engine, timeout_s))
    except BaseException as exc:  # reported to the parent, which returns an ERROR result
        message = ("error", f"{type(exc).__name__}: {exc}")
    with os.fdopen(write_end, "wb") as pipe:
        pipe.write(pickle.dumps(message))


def _result(problem: SymbolicProblem, answer: _Answer, engine: str,
            elapsed: float, timeout_s: float | None) -> SymbolicResult:
    status = _STATUS.get(answer.status, SymbolicStatus.ERROR)
    if status is SymbolicStatus.NOT_FOUND and engine in _EXHAUSTIVE_ENGINES:
        status = SymbolicStatus.UNSOLVABLE
    if status is SymbolicStatus.SOLVED and answer.actions is not None:
        actions = tuple(_ground(problem, name, args) for name, args in answer.actions)
        moves = " ".join(f"-{a.name}-> {a.to_state.pddl_name}" for a in actions
                         if a.to_state is not None)
        reason = (f"{engine}: {len(actions)} action(s) from "
                  f"{problem.graph.start.pddl_name} {moves}".rstrip())
        log.debug("%s", reason)
        return SymbolicResult(status, actions, reason, elapsed, engine)
    if status is SymbolicStatus.SOLVED:  # a "solution" without a plan: treat as an error
        status = SymbolicStatus.ERROR
    reason = {
        SymbolicStatus.UNSOLVABLE: _no_path(problem),
        SymbolicStatus.NOT_FOUND: f"{engine} found no plan (its search is incomplete): "
                                  + _no_path(problem),
        SymbolicStatus.TIMEOUT: f"{engine} hit the time limit of {timeout_s or 0:.3g} s after "
                                f"{elapsed:.3g} s",
        SymbolicStatus.MEMOUT: f"{engine} ran out of memory",
    }.get(status, f"{engine} reported {answer.status}: {answer.last_log}")
    log.info("%s", reason)
    return SymbolicResult(status, (), reason, elapsed, engine)


def _ground(problem: SymbolicProblem, name: str, args: tuple[str, ...]) -> GroundAction:
    info = problem.domain.info.action(name)
    if info.admissibility is None:
        return GroundAction(info.name, info.family, args)
    i, j = info.admissibility
    states = problem.states_by_name
    return GroundAction(info.name, info.family, args, states[args[i]], states[args[j]])


def _no_path(problem: SymbolicProblem) -> str:
    """Why no plan exists, in the words of the encoding."""
    graph, domain = problem.graph, problem.domain
    moves = ", ".join(domain.info.names(Family.MOVE_OBJECT)) or "none"
    text = (f"no contact-state path from {graph.start.pddl_name} to {graph.goal.pddl_name}"
            f"{' ending with the hand free' if graph.goal_release else ''}"
            f" with the declared primitives (MoveObject: {moves}; {problem.admitted} "
            f"admissible transition(s), {len(problem.forbidden)} forbidden"
            + (f", {len(problem.sequels)} forbidden after another" if problem.sequels else "") + ")")
    if not graph.start_touching and not domain.grasp_makers:
        text += f"; the hand starts free and no action makes ({TOUCHING}) true"
    if graph.goal_release and not domain.releasers:
        text += f"; the goal releases the object but no action makes ({HAND_FREE}) true"
    return text


def _last_log(answer: PlanGenerationResult) -> str:
    lines = [ln for m in answer.log_messages or () for ln in m.message.splitlines() if ln.strip()]
    return lines[-1] if lines else "no message"


# --------------------------------------------------------------------------- --emit-pddl


def emit_pddl(directory: str | Path, problem: SymbolicProblem, iteration: int) -> Path:
    """Write ``domain.pddl`` and ``problem-NN.pddl`` of one top-tier iteration.

    Both are written by unified-planning's PDDLWriter, so the problem refers to the
    domain by the writer's name (``ldhp-domain``) and any planner can re-read the pair.
    A comment header names the source domain, the iteration, and the transitions
    forbidden so far (their ``can-*`` facts are absent from ``:init``).

    Parameters
    ----------
    directory
        Created if missing.
    problem
        From :func:`build_problem`.
    iteration
        1-based top-tier iteration: ``problem-01.pddl``, ``problem-02.pddl``, ...

    Returns
    -------
    Path
        The problem file written.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    writer = PDDLWriter(problem.up_problem)
    source = problem.domain.info.source
    (out / "domain.pddl").write_text(
        f"; domain {problem.domain.info.name} from {source}, written by ldhp-tamp\n"
        + writer.get_domain(), encoding="utf-8")
    header = [f"; top-tier iteration {iteration} of domain {problem.domain.info.name}",
              f"; start {problem.graph.start.pddl_name}, goal {problem.graph.goal.pddl_name}",
              f"; {problem.admitted} admissible transition(s); "
              f"forbidden after failed refinements: {len(problem.forbidden)}"]
    header += [f";   forbidden: ({t})" for t in sorted(problem.forbidden, key=str)]
    if problem.sequels:
        header.append(f"; forbidden right after another transition: {len(problem.sequels)} (the state between "
                      "them has a copy 's-x--after-<action>-<from>' that only the first enters and that lacks "
                      "the second)")
        header += [f";   forbidden: ({q.then}) after ({q.after})" for q in sorted(problem.sequels, key=str)]
    path = out / f"problem-{iteration:02d}.pddl"
    path.write_text("\n".join(header) + "\n" + writer.get_problem(), encoding="utf-8")
    log.info("wrote %s", path)
    return path
