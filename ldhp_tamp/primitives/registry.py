"""The binding between PDDL action names and their geometric implementations.

The PDDL domain (``domains/ldhp.pddl``) is the list of primitives; this module binds each
action name to the Python object that implements it, and checks the two against each other
before any search (:func:`check_against_domain`), the way PDDLStream binds stream names to
functions::

    from ldhp_tamp.primitives.registry import REGISTRY, Family

    @REGISTRY.register("tip", Family.MOVE_OBJECT)
    class Tip:
        def transitions(self, context): ...
        def sample(self, context, from_state, to_state, start_pose, rng, limit): ...

This module knows nothing of unified-planning: :mod:`ldhp_tamp.symbolic` reads a domain
and describes it with the plain values :class:`ActionInfo` and :class:`DomainInfo` defined
here; the registry only ever sees those.
"""

from __future__ import annotations

import enum
import inspect
import logging
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, runtime_checkable

from geometry.features import ContactState
from ldhp_tamp.errors import DomainError

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

    from geometry.poses import Pose

log = logging.getLogger(__name__)

T = TypeVar("T")

#: The static precondition that admits a MoveObject action ``<a>`` is named ``can-<a>``.
ADMISSIBILITY_PREFIX = "can-"


class Family(enum.Enum):
    """The two families of the paper's primitive library."""

    MOVE_OBJECT = "move-object"
    """Changes the object's contact state, keeping the grasp (top tier)."""
    ADJUST_GRASP = "adjust-grasp"
    """Changes the grasp at a fixed object pose (bottom tier's intra-pose edges)."""


def admissibility_predicate(action: str) -> str:
    """The name of the static predicate admitting a MoveObject action: ``can-<action>``.

    Examples
    --------
    >>> admissibility_predicate("biplanar-slide")
    'can-biplanar-slide'
    """
    return ADMISSIBILITY_PREFIX + action


@dataclass(frozen=True)
class Transition:
    """One move of a MoveObject primitive: ``action`` takes the object from one contact
    state to another. The currency between the tiers: the symbolic plan's steps
    (``GroundAction.transition``) and what the TAMP loop forbids after a failed
    refinement (``build_problem(..., forbidden=...)``)."""

    action: str
    from_state: ContactState
    to_state: ContactState

    def __str__(self) -> str:
        return f"{self.action} {self.from_state.pddl_name} {self.to_state.pddl_name}"

    @property
    def label(self) -> str:
        """``tip l1-e1->v2-e1``: how reasons and progress messages name it."""
        return f"{self.action} {self.from_state.name}->{self.to_state.name}"


@dataclass(frozen=True)
class Sequel:
    """A transition that could not be realised right after another one: ``then`` may not
    directly follow ``after`` (so ``after.to_state == then.from_state``).

    The TAMP loop's feedback when a step fails geometrically from the pose its
    predecessor left the object in: the pose inside a contact state depends on how the
    state was entered, so the failure condemns the pair, not ``then`` everywhere. The
    symbolic tier compiles it into the problem (``symbolic.build_problem``) by giving
    the middle state a copy that only ``after`` enters and that lacks ``then``.
    """

    after: Transition
    then: Transition

    def __post_init__(self) -> None:
        if self.after.to_state != self.then.from_state:
            raise ValueError(f"{self.then.label} cannot follow {self.after.label}")

    @property
    def label(self) -> str:
        return f"{self.then.label} after {self.after.label}"


# --------------------------------------------------------------------------- protocols


@runtime_checkable
class MoveObjectPrimitive(Protocol):
    """What a MoveObject implementation (``tip``, ``push``, ...) provides.

    ``context`` is whatever the TAMP loop passes (the scenario's world, caches, settings);
    it is opaque to the registry.
    """

    def transitions(self, context: Any) -> Iterable[tuple[ContactState, ContactState]]:
        """The kinematically admissible ``(from_state, to_state)`` pairs of this primitive.

        They become the static facts ``(can-<action> from to)`` of the symbolic problem.
        """
        ...

    def sample(
        self,
        context: Any,
        from_state: ContactState,
        to_state: ContactState,
        start_pose: "Pose",
        rng: "np.random.Generator",
        limit: int,
    ) -> Iterator[Any]:
        """Stream at most ``limit`` pose sub-paths realising ``from_state -> to_state``
        from ``start_pose`` (the TAMP loop's stream; its item type is defined there)."""
        ...


@runtime_checkable
class AdjustGraspPrimitive(Protocol):
    """What an AdjustGrasp implementation (``open``, ``pivot``, ...) provides.

    One method, ``intra_edges(context, pose, candidates)``: the intra-pose edges the
    primitive realises at object pose ``pose`` (a :class:`~geometry.poses.Pose`) among
    the grasps ``candidates`` (indices into ``context.grasps``, normally G_T, with row 0
    the no-contact grasp {0, 0}), *feasibility checked*, as an
    :class:`~ldhp_tamp.primitives.adjust_grasp.IntraEdges` value: arrays ``src``,
    ``dst``, ``travel`` (mm) and ``switches``, and each edge's gripper motion, from which
    :func:`~ldhp_tamp.primitives.adjust_grasp.motion_waypoints` makes the plan waypoints.
    ``context`` is an :class:`~ldhp_tamp.primitives.adjust_grasp.AdjustContext` (world,
    grasp set, options, caches).

    The bottom tier (:mod:`ldhp_tamp.grasp_graph`) calls ``intra_edges`` once per layer.
    An implementation that also has the lazy interface
    (:class:`~ldhp_tamp.primitives.adjust_grasp.LazyAdjustGrasp`: ``propose`` the
    candidate edges with their costs, ``check`` a batch of them, ``waypoints`` of one) is
    used lazily instead: only the edges that can lie on a cheapest path are checked. The
    six primitives of :mod:`ldhp_tamp.primitives.adjust_grasp` have both.
    """

    def intra_edges(self, context: Any, pose: "Pose", candidates: "Sequence[int] | np.ndarray") -> Any:
        """The feasible intra-pose edges (an ``IntraEdges``) of this primitive at
        ``pose`` among ``candidates``; ``context`` is an ``AdjustContext``."""
        ...


_PROTOCOLS: dict[Family, type] = {
    Family.MOVE_OBJECT: MoveObjectPrimitive,
    Family.ADJUST_GRASP: AdjustGraspPrimitive,
}


def _required_methods(family: Family) -> tuple[str, ...]:
    """The public methods of the family's protocol, e.g. ``("sample", "transitions")``."""
    return tuple(sorted(name for name, value in vars(_PROTOCOLS[family]).items()
                        if callable(value) and not name.startswith("_")))


# --------------------------------------------------------------------------- domain facts


@dataclass(frozen=True)
class ActionInfo:
    """What the registry needs to know about one PDDL action.

    Attributes
    ----------
    name
        The action name, lower case as PDDL reads it (``"biplanar-slide"``).
    family
        Derived from the action itself: it changes ``(at ?s)`` -> MoveObject.
    parameters
        The parameter names, without ``?``.
    admissibility
        For a MoveObject action, the indices ``(i, j)`` of the parameters bound to
        ``?from`` and ``?to`` in its static precondition ``(can-<name> ?from ?to)``;
        ``None`` if the action has no such precondition (refused for MoveObject).
    """

    name: str
    family: Family
    parameters: tuple[str, ...] = ()
    admissibility: tuple[int, int] | None = None

    @property
    def static_predicate(self) -> str:
        """``can-<name>``."""
        return admissibility_predicate(self.name)


@dataclass(frozen=True)
class DomainInfo:
    """The primitive library as a domain declares it: its actions, in file order.

    The constructor checks the conventions every consumer relies on, so a value of this
    type is always usable: unique action names, and every MoveObject action admitted by
    its ``can-<action>`` static precondition.

    Raises
    ------
    DomainError
        On a duplicate action or a MoveObject action without its ``can-<action>``
        precondition; the message names the action and the convention.
    """

    name: str
    source: str
    actions: tuple[ActionInfo, ...]

    def __post_init__(self) -> None:
        seen: set[str] = set()
        for action in self.actions:
            if action.name in seen:
                raise DomainError(f"{self.source}: action {action.name!r} is declared twice")
            seen.add(action.name)
            if action.family is Family.MOVE_OBJECT and action.admissibility is None:
                raise DomainError(
                    f"{self.source}: MoveObject action {action.name!r} (it changes (at ?s)) "
                    f"has no static precondition ({action.static_predicate} ?from ?to): "
                    f"every MoveObject action <a> must require (can-<a> ?from ?to) over two "
                    f"'state' parameters, declared in :predicates and never changed by an "
                    f"action; the planner writes the admissible transitions as those facts "
                    f"(see docs/extending.md)")

    def action(self, name: str) -> ActionInfo:
        """The action called ``name``; :class:`KeyError` if the domain has none."""
        for action in self.actions:
            if action.name == name:
                return action
        raise KeyError(name)

    def names(self, family: Family | None = None) -> tuple[str, ...]:
        """Action names in file order, optionally of one family only."""
        return tuple(a.name for a in self.actions if family is None or a.family is family)

    def __contains__(self, name: object) -> bool:
        return any(a.name == name for a in self.actions)


class DeclaresActions(Protocol):
    """What binding a domain's actions to implementations needs of the domain: their
    names by family, in the domain's order. A :class:`DomainInfo` (unified-planning's
    reading) has them, and so has the lighter reading of the domain file that the
    validator uses (:class:`ldhp_tamp.domain_info.DomainActions`), with which the setup's
    geometry starts while unified-planning parses the domain (``tamp``)."""

    def names(self, family: Family | None = None) -> tuple[str, ...]: ...


# --------------------------------------------------------------------------- registry


@dataclass(frozen=True)
class Binding:
    """One action name bound to its implementation."""

    name: str
    family: Family
    implementation: Any


class PrimitiveRegistry:
    """Binds PDDL action names to implementations; the PDDLStream ``stream_map`` of LDHP.

    Names are stored lower case (PDDL is case-insensitive). Registration is explicit: the
    module that defines an implementation decorates it; nothing scans folders.

    Examples
    --------
    >>> reg = PrimitiveRegistry()
    >>> @reg.register("open", Family.ADJUST_GRASP)
    ... class Open:
    ...     def intra_edges(self, context, pose, grasps):
    ...         return ()
    >>> reg.family("open")
    <Family.ADJUST_GRASP: 'adjust-grasp'>
    """

    def __init__(self) -> None:
        self._bindings: dict[str, Binding] = {}

    def register(self, name: str, family: Family) -> Callable[[T], T]:
        """Decorator binding ``name`` to a class or an object.

        A decorated class is instantiated once, without arguments (implementations keep
        no per-task state; everything task-specific comes through ``context``). The
        decorated class or object is returned unchanged.

        Raises
        ------
        DomainError
            If ``name`` is already bound, or the implementation lacks a method its
            family's protocol requires.
        """

        def decorate(target: T) -> T:
            self.bind(name, family, target() if inspect.isclass(target) else target)
            return target

        return decorate

    def bind(self, name: str, family: Family, implementation: object) -> Binding:
        """Bind ``name`` to an implementation object (the non-decorator form)."""
        key = name.lower()
        if key in self._bindings:
            raise DomainError(
                f"primitive {key!r} is registered twice: "
                f"{self._bindings[key].implementation!r} and {implementation!r}")
        missing = [m for m in _required_methods(family)
                   if not callable(getattr(implementation, m, None))]
        if missing:
            raise DomainError(
                f"implementation of {family.value} primitive {key!r} lacks "
                f"{', '.join(m + '()' for m in missing)}: {implementation!r}")
        binding = Binding(key, family, implementation)
        self._bindings[key] = binding
        log.debug("bound %s primitive %r to %r", family.value, key, implementation)
        return binding

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name.lower() in self._bindings

    def __iter__(self) -> Iterator[Binding]:
        return iter(self._bindings.values())

    def __len__(self) -> int:
        return len(self._bindings)

    def binding(self, name: str) -> Binding:
        """The binding of ``name``; :class:`DomainError` if there is none."""
        try:
            return self._bindings[name.lower()]
        except KeyError:
            raise DomainError(
                f"no implementation registered for primitive {name!r} "
                f"(registered: {', '.join(sorted(self._bindings)) or 'none'})") from None

    def family(self, name: str) -> Family:
        return self.binding(name).family

    def implementation(self, name: str) -> Any:
        return self.binding(name).implementation

    def bound(self, domain: DeclaresActions, family: Family) -> tuple[Binding, ...]:
        """The bindings of the domain's actions of one family, in the domain's order.

        The bottom tier builds its grasp graph from ``bound(domain,
        Family.ADJUST_GRASP)``: exactly the AdjustGrasp actions the domain declares.
        Call :func:`check_against_domain` first.
        """
        return tuple(self.binding(name) for name in domain.names(family))

    def admissible_transitions(
        self, domain: DeclaresActions, context: Any,
    ) -> dict[str, frozenset[tuple[ContactState, ContactState]]]:
        """Ask every MoveObject implementation of the domain for its admissible transitions.

        Implementations with the same ``transitions_together`` attribute (a function of
        the context and a list of implementations that returns their transitions, in
        order) are asked in one call: the sweep-based primitives share one batch of
        sweeps on the machine's cores that way. The others are asked one by one
        (``transitions``).

        Returns
        -------
        dict
            Action name -> admissible ``(from_state, to_state)`` pairs: the
            ``transitions`` of a :class:`~ldhp_tamp.symbolic.ContactGraph`, in the
            domain's order of the actions.
        """
        bound = list(self.bound(domain, Family.MOVE_OBJECT))
        found: dict[str, frozenset[tuple[ContactState, ContactState]]] = {}
        together: dict[Callable[..., Any], list[Binding]] = {}
        for b in bound:
            fn = getattr(b.implementation, "transitions_together", None)
            if fn is None:
                found[b.name] = frozenset(b.implementation.transitions(context))
            else:
                together.setdefault(fn, []).append(b)
        for fn, group in together.items():
            pairs = fn(context, [b.implementation for b in group])
            if len(pairs) != len(group):
                raise RuntimeError(f"transitions_together returned {len(pairs)} sets for {len(group)} actions")
            found.update((b.name, frozenset(p)) for b, p in zip(group, pairs))
        return {b.name: found[b.name] for b in bound}


def check_against_domain(domain: DomainInfo, registry: PrimitiveRegistry) -> None:
    """Check, before any search, that every action of ``domain`` is implemented.

    - an action without implementation: :class:`DomainError` naming it (the CLI exits 2);
    - an implementation whose family disagrees with the domain's: :class:`DomainError`;
    - an implementation without action: unused (logged at DEBUG) -- that is how a
      primitive is removed, by deleting its action from the domain.

    The domain's own conventions (``can-<a>`` preconditions) were checked when the
    :class:`DomainInfo` was built.

    Raises
    ------
    DomainError
        Listing every offending action at once.
    """
    problems: list[str] = []
    for action in domain.actions:
        if action.name not in registry:
            problems.append(f"action {action.name!r} has no registered implementation")
            continue
        bound = registry.family(action.name)
        if bound is not action.family:
            problems.append(
                f"action {action.name!r} is {action.family.value} in the domain "
                f"({'it changes' if action.family is Family.MOVE_OBJECT else 'it does not change'}"
                f" (at ?s)) but its implementation is registered as {bound.value}")
    if problems:
        raise DomainError(f"{domain.source}: " + "; ".join(problems)
                          + " (see docs/extending.md)")
    for binding in registry:
        if binding.name not in domain:
            log.debug("primitive %r is registered but not in domain %s: unused",
                      binding.name, domain.source)


REGISTRY = PrimitiveRegistry()
"""The project's registry. Implementation modules register on it; the planner checks it
against the chosen domain with :func:`check_against_domain` before searching."""
