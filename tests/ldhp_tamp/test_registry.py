"""The registry binding PDDL action names to implementations, tested without any PDDL:
domains are described by hand-made :class:`DomainInfo` values."""

from __future__ import annotations

import logging

import pytest

from geometry.features import FREE, ContactState
from ldhp_tamp.errors import DomainError, LdhpError
from ldhp_tamp.primitives import (
    REGISTRY,
    ActionInfo,
    DomainInfo,
    Family,
    PrimitiveRegistry,
    check_against_domain,
)

L1, V2 = ContactState.parse("l1-e1"), ContactState.parse("v2-e1")


class FakeMove:
    """A MoveObject implementation with fixed transitions."""

    def __init__(self, pairs: tuple[tuple[ContactState, ContactState], ...] = ()) -> None:
        self.pairs = pairs

    def transitions(self, context):
        return self.pairs

    def sample(self, context, from_state, to_state, start_pose, rng, limit):
        return iter(())


class FakeGrasp:
    def intra_edges(self, context, pose, grasps):
        return ()


def move(name: str) -> ActionInfo:
    return ActionInfo(name, Family.MOVE_OBJECT, ("from", "to"), (0, 1))


def grasp(name: str) -> ActionInfo:
    return ActionInfo(name, Family.ADJUST_GRASP)


DOMAIN = DomainInfo("toy", "toy.pddl", (move("tip"), move("air-move"), grasp("open")))


def full_registry() -> PrimitiveRegistry:
    reg = PrimitiveRegistry()
    reg.bind("tip", Family.MOVE_OBJECT, FakeMove(((L1, V2),)))
    reg.bind("air-move", Family.MOVE_OBJECT, FakeMove(((V2, FREE), (FREE, V2))))
    reg.bind("open", Family.ADJUST_GRASP, FakeGrasp())
    return reg


def test_decorator_binds_an_instance_and_returns_the_class():
    reg = PrimitiveRegistry()

    @reg.register("Tip", Family.MOVE_OBJECT)
    class Tip(FakeMove):
        pass

    assert isinstance(Tip, type)
    assert "tip" in reg and "TIP" in reg
    assert isinstance(reg.implementation("tip"), Tip)
    assert reg.family("tip") is Family.MOVE_OBJECT


def test_decorator_accepts_an_object():
    reg = PrimitiveRegistry()
    impl = FakeGrasp()
    assert reg.register("flip", Family.ADJUST_GRASP)(impl) is impl
    assert reg.implementation("flip") is impl


def test_registering_a_name_twice_is_an_error():
    reg = full_registry()
    with pytest.raises(DomainError, match="'tip' is registered twice"):
        reg.bind("tip", Family.MOVE_OBJECT, FakeMove())


def test_an_implementation_must_provide_its_family_methods():
    reg = PrimitiveRegistry()
    with pytest.raises(DomainError, match=r"lacks sample\(\), transitions\(\)"):
        reg.bind("tip", Family.MOVE_OBJECT, FakeGrasp())
    with pytest.raises(DomainError, match=r"lacks intra_edges\(\)"):
        reg.bind("open", Family.ADJUST_GRASP, FakeMove())


def test_complete_registry_passes_the_check():
    check_against_domain(DOMAIN, full_registry())


def test_action_without_implementation_is_named():
    reg = PrimitiveRegistry()
    reg.bind("tip", Family.MOVE_OBJECT, FakeMove())
    with pytest.raises(DomainError) as info:
        check_against_domain(DOMAIN, reg)
    message = str(info.value)
    assert "toy.pddl" in message
    assert "'air-move' has no registered implementation" in message
    assert "'open' has no registered implementation" in message
    assert "'tip'" not in message
    assert isinstance(info.value, LdhpError)


def test_family_disagreement_is_an_error():
    reg = PrimitiveRegistry()
    reg.bind("tip", Family.MOVE_OBJECT, FakeMove())
    reg.bind("air-move", Family.MOVE_OBJECT, FakeMove())
    reg.bind("open", Family.MOVE_OBJECT, FakeMove())
    with pytest.raises(DomainError, match="'open' is adjust-grasp in the domain .* registered as move-object"):
        check_against_domain(DOMAIN, reg)


def test_implementation_without_action_is_unused_not_an_error(caplog):
    reg = full_registry()
    reg.bind("pivot", Family.ADJUST_GRASP, FakeGrasp())
    with caplog.at_level(logging.DEBUG, logger="ldhp_tamp.primitives.registry"):
        check_against_domain(DOMAIN, reg)
    assert any("'pivot'" in r.getMessage() and "unused" in r.getMessage() for r in caplog.records)


def test_move_object_action_needs_its_admissibility_predicate():
    with pytest.raises(DomainError, match=r"'push'.*\(can-push \?from \?to\)"):
        DomainInfo("bad", "bad.pddl", (ActionInfo("push", Family.MOVE_OBJECT, ("a", "b")),))


def test_duplicate_action_in_a_domain_is_an_error():
    with pytest.raises(DomainError, match="declared twice"):
        DomainInfo("bad", "bad.pddl", (grasp("open"), grasp("open")))


def test_bound_follows_the_domain_not_the_registry():
    reg = full_registry()
    reg.bind("pivot", Family.ADJUST_GRASP, FakeGrasp())  # not in DOMAIN: not bound
    assert [b.name for b in reg.bound(DOMAIN, Family.ADJUST_GRASP)] == ["open"]
    assert [b.name for b in reg.bound(DOMAIN, Family.MOVE_OBJECT)] == ["tip", "air-move"]


def test_admissible_transitions_asks_every_move_object_implementation():
    transitions = full_registry().admissible_transitions(DOMAIN, context=None)
    assert transitions == {"tip": frozenset({(L1, V2)}),
                           "air-move": frozenset({(V2, FREE), (FREE, V2)})}


class FakeSwept(FakeMove):
    """MoveObject implementations whose transitions are found together, in one call."""

    calls: list[tuple[object, tuple[str, ...]]] = []

    def __init__(self, name: str, pairs: tuple[tuple[ContactState, ContactState], ...]) -> None:
        super().__init__(pairs)
        self.name = name

    def transitions(self, context):  # pragma: no cover - the registry asks them together
        raise AssertionError("asked alone")

    @staticmethod
    def transitions_together(context, impls):
        FakeSwept.calls.append((context, tuple(i.name for i in impls)))
        return [set(i.pairs) for i in impls]


def test_implementations_sharing_transitions_together_are_asked_in_one_call():
    FakeSwept.calls = []
    domain = DomainInfo("toy", "toy.pddl", (move("tip"), move("air-move"), move("push"), grasp("open")))
    reg = PrimitiveRegistry()
    reg.bind("tip", Family.MOVE_OBJECT, FakeSwept("tip", ((L1, V2),)))
    reg.bind("air-move", Family.MOVE_OBJECT, FakeMove(((V2, FREE), (FREE, V2))))
    reg.bind("push", Family.MOVE_OBJECT, FakeSwept("push", ((V2, L1),)))
    transitions = reg.admissible_transitions(domain, context="ctx")
    assert FakeSwept.calls == [("ctx", ("tip", "push"))]  # one call, in the domain's order
    assert list(transitions) == ["tip", "air-move", "push"]
    assert transitions == {"tip": frozenset({(L1, V2)}), "air-move": frozenset({(V2, FREE), (FREE, V2)}),
                           "push": frozenset({(V2, L1)})}


def test_domain_info_lookups():
    assert DOMAIN.names(Family.MOVE_OBJECT) == ("tip", "air-move")
    assert DOMAIN.names() == ("tip", "air-move", "open")
    assert "open" in DOMAIN and "close" not in DOMAIN
    assert DOMAIN.action("tip").static_predicate == "can-tip"
    with pytest.raises(KeyError):
        DOMAIN.action("close")


def test_shared_registry_exists():
    assert isinstance(REGISTRY, PrimitiveRegistry)
