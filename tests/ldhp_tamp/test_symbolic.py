"""The symbolic tier: domains, problems from contact graphs, engines, feedback, --emit-pddl."""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from pathlib import Path

import pytest

from geometry.features import FREE, ContactState
from ldhp_tamp.errors import DomainError, EngineError, InputError
from ldhp_tamp.primitives import Family, PrimitiveRegistry, Sequel, check_against_domain
from ldhp_tamp.resources import domains_dir
from ldhp_tamp.symbolic import (
    ContactGraph,
    SymbolicResult,
    SymbolicStatus,
    Transition,
    available_engines,
    build_problem,
    emit_pddl,
    load_domain,
    parse_domain,
    solve,
)

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "domains"
SHIPPED = sorted(domains_dir().glob("*.pddl"))

MOVE_OBJECT = ("tip", "push", "biplanar-slide", "air-move")
ADJUST_GRASP = ("open", "close", "pivot", "slide", "flip", "approach-contact")

needs_fd = pytest.mark.skipif("fast-downward" not in available_engines(),
                              reason="up-fast-downward is not installed")

S = ContactState.parse
L = [S(f"l{i}-e1") for i in range(1, 5)]
V = [S(f"v{i}-e1") for i in range(1, 5)]


# --------------------------------------------------------------------------- helpers


class FakeMove:
    def transitions(self, context):
        return ()

    def sample(self, context, from_state, to_state, start_pose, rng, limit):
        return iter(())


class FakeGrasp:
    def intra_edges(self, context, pose, grasps):
        return ()


def fake_registry(extra: Iterable[str] = ()) -> PrimitiveRegistry:
    """The paper's ten primitives (plus ``extra`` MoveObject ones) with fake bodies."""
    reg = PrimitiveRegistry()
    for name in (*MOVE_OBJECT, *extra):
        reg.bind(name, Family.MOVE_OBJECT, FakeMove())
    for name in ADJUST_GRASP:
        reg.bind(name, Family.ADJUST_GRASP, FakeGrasp())
    return reg


def lifting_graph(start: ContactState = L[0], goal: ContactState = V[1], *,
                  start_touching: bool = False, goal_release: bool = False) -> ContactGraph:
    """Task 1's graph: a box on the ground edge e1. Sides l1..l4, corners v1..v4 (v_i
    starts side l_i, so l_i touches corners v_i and v_(i+1)).

    tip between a side and its two corners, push within a side (l_i -> l_i), air-move
    between every contact state and free.
    """
    tip = set()
    for i in range(4):
        for corner in (V[i], V[(i + 1) % 4]):
            tip |= {(L[i], corner), (corner, L[i])}
    contact = L + V
    return ContactGraph(
        states=(*contact, FREE),
        transitions={
            "tip": frozenset(tip),
            "push": frozenset((s, s) for s in L),
            "air-move": frozenset({(s, FREE) for s in contact} | {(FREE, s) for s in contact}),
        },
        start=start, goal=goal, start_touching=start_touching, goal_release=goal_release)


def assert_plan_is_valid(graph: ContactGraph, result: SymbolicResult) -> None:
    """Replay the plan on the graph: admissible moves, hand state respected, goal reached."""
    assert result.status is SymbolicStatus.SOLVED, result.reason
    state, touching = graph.start, graph.start_touching
    for step in result.actions:
        if step.family is Family.MOVE_OBJECT:
            assert touching, f"{step} without a finger on the object"
            assert step.from_state == state
            assert (step.from_state, step.to_state) in graph.transitions[step.name]
            state = step.to_state
        elif step.name == "approach-contact":
            assert not touching
            touching = True
        elif step.name == "open":
            assert touching
            touching = False
    assert state == graph.goal
    if graph.goal_release:
        assert not touching


def without_action(text: str, name: str) -> str:
    """The domain text with the ``(:action name ...)`` block cut out (balanced parens)."""
    start = re.search(rf"\(:action\s+{re.escape(name)}\s", text).start()
    depth = 0
    for end in range(start, len(text)):
        depth += {"(": 1, ")": -1}.get(text[end], 0)
        if depth == 0:
            return text[:start] + text[end + 1:]
    raise AssertionError("unbalanced domain")


@pytest.fixture(scope="module")
def ldhp():
    return load_domain("ldhp")


# --------------------------------------------------------------------------- domains


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_every_shipped_domain_parses_and_passes_the_registry_check(path):
    domain = load_domain(path)
    check_against_domain(domain.info, fake_registry())


def test_the_shipped_domain_is_the_papers_library(ldhp):
    assert set(ldhp.info.names()) == {*MOVE_OBJECT, *ADJUST_GRASP}
    assert not ldhp.uses_action_costs


def test_families_are_derived_from_the_domain(ldhp):
    assert set(ldhp.info.names(Family.MOVE_OBJECT)) == set(MOVE_OBJECT)
    assert set(ldhp.info.names(Family.ADJUST_GRASP)) == set(ADJUST_GRASP)
    for name in MOVE_OBJECT:
        assert ldhp.info.action(name).admissibility == (0, 1)
    assert ldhp.grasp_makers == ("approach-contact",)
    assert ldhp.releasers == ("open",)


def test_a_domain_is_found_by_name_or_path():
    assert load_domain("ldhp").info.source == str((domains_dir() / "ldhp.pddl").resolve())
    assert load_domain("costs.pddl", base=DATA).info.name == "ldhp-costs"
    with pytest.raises(DomainError, match="domain not found: nope"):
        load_domain("nope")
    with pytest.raises(DomainError, match="domain not found"):
        load_domain(DATA / "missing.pddl")


def test_syntax_error_names_the_file_and_line():
    with pytest.raises(DomainError, match=r"syntax-error\.pddl:\d+:\d+: PDDL error") as info:
        load_domain(DATA / "syntax-error.pddl")
    assert isinstance(info.value, InputError)  # the CLI exits with status 2


def test_move_object_action_without_admissibility_is_refused():
    with pytest.raises(DomainError, match=r"'push'.*\(can-push \?from \?to\)"):
        load_domain(DATA / "no-admissibility.pddl")


def test_the_problem_vocabulary_is_required():
    with pytest.raises(DomainError, match=r"\(hand-free\)"):
        load_domain(DATA / "no-hand-free.pddl")


def test_the_pddl_readers_warm_up_streamlines_its_grammars_and_changes_no_parse():
    """prepare_pddl_reader (a sweep worker's preload) parses a small domain and problem,
    so that pyparsing streamlines the grammars then and not in a cell's first parse (in
    a fresh interpreter: this one's have parsed already); the project's domain reads the
    same after it."""
    import subprocess
    import sys

    code = ("from ldhp_tamp import symbolic as s; r = s._reader(s._environment()); "
            "g = (r._pp_domain, r._pp_problem, r._pp_parameters); print([e.streamlined for e in g]); "
            "s.prepare_pddl_reader(); print([e.streamlined for e in g])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split("\n")[:2] == ["[False, False, False]", "[True, True, True]"]
    text = (domains_dir() / "ldhp.pddl").read_text()
    before = parse_domain(text, "ldhp.pddl").info
    from ldhp_tamp import symbolic

    symbolic.prepare_pddl_reader()
    assert parse_domain(text, "ldhp.pddl").info == before


def test_an_action_changing_a_static_predicate_is_refused():
    text = (domains_dir() / "ldhp.pddl").read_text()
    text = text.replace("(and (touching) (not (hand-free)))",
                        "(and (touching) (not (hand-free)) (not (can-tip ?a ?b)))")
    text = text.replace("(:action approach-contact\n    :parameters ()",
                        "(:action approach-contact\n    :parameters (?a ?b - state)")
    with pytest.raises(DomainError, match="'approach-contact' changes can-tip"):
        parse_domain(text, "edited.pddl")


def test_action_without_implementation_is_an_error_naming_it(ldhp):
    registry = fake_registry()
    incomplete = PrimitiveRegistry()
    for binding in registry:
        if binding.name != "flip":
            incomplete.bind(binding.name, binding.family, binding.implementation)
    with pytest.raises(DomainError, match="'flip' has no registered implementation"):
        check_against_domain(ldhp.info, incomplete)


# --------------------------------------------------------------------------- problems and plans


def test_lifting_graph_yields_a_valid_plan(ldhp):
    graph = lifting_graph()
    result = solve(build_problem(ldhp, graph))
    assert_plan_is_valid(graph, result)
    assert result.actions[0].name == "approach-contact"
    assert result.engine == "pyperplan" and result.time_s > 0


def test_plan_steps_carry_contact_states(ldhp):
    graph = ContactGraph((L[0], V[1]), {"tip": frozenset({(L[0], V[1])})}, L[0], V[1],
                         start_touching=True)
    result = solve(build_problem(ldhp, graph))
    (step,) = result.actions
    assert (step.name, step.args) == ("tip", ("s-l1-e1", "s-v2-e1"))
    assert step.transition == Transition("tip", L[0], V[1])
    assert result.transitions() == (Transition("tip", L[0], V[1]),)


def test_goal_release_ends_with_the_hand_free(ldhp):
    graph = lifting_graph(start_touching=True, goal_release=True)
    result = solve(build_problem(ldhp, graph))
    assert_plan_is_valid(graph, result)
    assert result.actions[-1].name == "open"


def test_start_equal_to_goal_is_an_empty_plan(ldhp):
    graph = lifting_graph(start=V[1], goal=V[1])
    result = solve(build_problem(ldhp, graph))
    assert result.status is SymbolicStatus.SOLVED and result.actions == ()


def test_unsolvable_is_a_status_with_a_reason(ldhp):
    graph = ContactGraph((L[0], V[1], FREE), {"tip": frozenset({(V[1], L[0])})}, L[0], V[1],
                         start_touching=True)
    result = solve(build_problem(ldhp, graph))
    assert result.status is SymbolicStatus.UNSOLVABLE
    assert result.actions == ()
    assert "no contact-state path from s-l1-e1 to s-v2-e1" in result.reason


def test_transitions_of_undeclared_actions_are_ignored(ldhp):
    graph = ContactGraph((L[0], V[1]), {"roll": frozenset({(L[0], V[1])})}, L[0], V[1],
                         start_touching=True)
    problem = build_problem(ldhp, graph)
    assert problem.admitted == 0
    assert solve(problem).status is SymbolicStatus.UNSOLVABLE


def test_contact_graph_checks_its_states():
    with pytest.raises(ValueError, match="goal"):
        ContactGraph((L[0],), {}, L[0], V[1])
    with pytest.raises(ValueError, match="not in the graph"):
        ContactGraph((L[0], V[1]), {"tip": frozenset({(L[0], V[2])})}, L[0], V[1])


@pytest.mark.parametrize("removed", [*MOVE_OBJECT, *ADJUST_GRASP])
def test_removing_an_action_removes_it_from_every_plan(tmp_path, removed):
    text = without_action((domains_dir() / "ldhp.pddl").read_text(), removed)
    copy = tmp_path / "ablated.pddl"
    copy.write_text(text)
    domain = load_domain(copy)
    assert removed not in domain.info
    check_against_domain(domain.info, fake_registry())  # an unused implementation is fine
    for graph in (lifting_graph(goal_release=True), lifting_graph(L[0], L[1])):
        result = solve(build_problem(domain, graph))
        if result.status is SymbolicStatus.SOLVED:
            assert removed not in {a.name for a in result.actions}
            assert_plan_is_valid(graph, result)
        else:
            assert result.status is SymbolicStatus.UNSOLVABLE, result.reason
    # the ablations of the paper's reasoning: no way to grasp, no way to release
    if removed == "approach-contact":
        assert "no action makes (touching) true" in result.reason
    if removed == "open":
        result = solve(build_problem(domain, lifting_graph(goal_release=True)))
        assert result.status is SymbolicStatus.UNSOLVABLE
        assert "no action makes (hand-free) true" in result.reason


# --------------------------------------------------------------------------- feedback


def test_forbidden_transitions_are_left_out(ldhp):
    graph = lifting_graph(start_touching=True)
    first = solve(build_problem(ldhp, graph))
    failed = first.transitions()[0]
    problem = build_problem(ldhp, graph, forbidden={failed})
    assert problem.forbidden == {failed}
    assert problem.admitted == len(graph.all_transitions()) - 1
    second = solve(problem)
    assert_plan_is_valid(graph, second)
    assert failed not in second.transitions()


def test_feedback_loop_terminates_in_unsolvable(ldhp):
    graph = lifting_graph(start_touching=True)
    forbidden: set[Transition] = set()
    bound = len(graph.all_transitions()) + 1
    for _ in range(bound):
        result = solve(build_problem(ldhp, graph, forbidden))
        if result.status is not SymbolicStatus.SOLVED:
            break
        assert_plan_is_valid(graph, result)
        assert not forbidden & set(result.transitions())
        forbidden.add(result.transitions()[-1])  # the TAMP loop reports one failed step
    else:
        pytest.fail("the feedback loop did not terminate")
    assert result.status is SymbolicStatus.UNSOLVABLE
    assert f"{len(forbidden)} forbidden" in result.reason


def _line_graph() -> ContactGraph:
    """a -> b -> d, a -> c -> b: the state b entered two ways, and b -> d the only way out."""
    a, b, c, d = (S(f"l{i}-e1") for i in range(1, 5))
    return ContactGraph(states=(a, b, c, d),
                        transitions={"tip": frozenset({(a, b), (b, d), (a, c)}), "push": frozenset({(c, b)})},
                        start=a, goal=d, start_touching=True)


def test_a_sequel_forbids_a_step_only_right_after_its_predecessor(ldhp):
    graph = _line_graph()
    a, b, c, d = graph.states
    direct = solve(build_problem(ldhp, graph))
    assert [t.label for t in direct.transitions()] == ["tip l1-e1->l2-e1", "tip l2-e1->l4-e1"]
    after_tip = Sequel(Transition("tip", a, b), Transition("tip", b, d))
    problem = build_problem(ldhp, graph, {after_tip})
    assert problem.sequels == {after_tip} and not problem.forbidden
    detour = solve(problem)
    # b is now entered the other way; the plan maps the copy back to b itself
    assert [t.label for t in detour.transitions()] == ["tip l1-e1->l3-e1", "push l3-e1->l2-e1", "tip l2-e1->l4-e1"]
    assert "sequel" not in detour.reason and all(t.to_state in graph.states for t in detour.transitions())
    # forbidding the detour's last step after the push too leaves no plan
    after_push = Sequel(Transition("push", c, b), Transition("tip", b, d))
    none = solve(build_problem(ldhp, graph, {after_tip, after_push}))
    assert none.status is SymbolicStatus.UNSOLVABLE and "2 forbidden after another" in none.reason


def test_a_sequel_through_the_goal_state_forbids_its_step_outright(ldhp):
    graph = _line_graph()
    a, b, c, d = graph.states
    graph = ContactGraph(graph.states, graph.transitions, start=a, goal=b, start_touching=True)
    q = Sequel(Transition("tip", a, b), Transition("tip", b, d))
    problem = build_problem(ldhp, graph, {q})
    assert problem.forbidden == {q.then} and not problem.sequels


def test_a_sequel_needs_joined_transitions():
    a, b, c, d = _line_graph().states
    with pytest.raises(ValueError, match="cannot follow"):
        Sequel(Transition("tip", a, b), Transition("push", c, b))


# --------------------------------------------------------------------------- --emit-pddl


def test_emitted_pddl_reparses_and_shows_the_constraints(ldhp, tmp_path):
    from unified_planning.io import PDDLReader  # the test is an outside witness

    graph = lifting_graph(goal_release=True)
    failed = Transition("tip", L[0], V[1])
    emit_pddl(tmp_path, build_problem(ldhp, graph), 1)
    second = emit_pddl(tmp_path, build_problem(ldhp, graph, {failed}), 2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["domain.pddl", "problem-01.pddl",
                                                         "problem-02.pddl"]
    into_v1 = Transition("tip", L[0], V[0])
    third = emit_pddl(tmp_path, build_problem(ldhp, graph, {Sequel(into_v1, Transition("tip", V[0], L[3]))}), 3)
    assert ";   forbidden: (tip s-v1-e1 s-l4-e1) after (tip s-l1-e1 s-v1-e1)" in third.read_text()
    assert "(can-tip s-l1-e1 s-v1-e1--after-tip-s-l1-e1)" in third.read_text()
    PDDLReader().parse_problem(str(tmp_path / "domain.pddl"), str(third))
    third.unlink()
    text = second.read_text()
    assert "; top-tier iteration 2" in text
    assert ";   forbidden: (tip s-l1-e1 s-v2-e1)" in text
    assert "(can-tip s-l1-e1 s-v2-e1)" not in text
    assert "(can-tip s-l1-e1 s-v1-e1)" in text and "s-free" in text
    for name in ("problem-01.pddl", "problem-02.pddl"):
        parsed = PDDLReader().parse_problem(str(tmp_path / "domain.pddl"), str(tmp_path / name))
        assert {o.name for o in parsed.all_objects} == {s.pddl_name for s in graph.states}
    assert "(:action biplanar-slide" in (tmp_path / "domain.pddl").read_text()


# --------------------------------------------------------------------------- engines


def test_available_engines_is_quiet_and_has_pyperplan(capsys):
    engines = available_engines()
    assert "pyperplan" in engines and engines == tuple(sorted(engines))
    assert not any("[" in e for e in engines)
    assert capsys.readouterr() == ("", "")


def test_unknown_engine_lists_the_installed_ones(ldhp):
    problem = build_problem(ldhp, lifting_graph())
    with pytest.raises(EngineError, match="unknown planning engine 'nope' for domain .*ldhp.pddl; installed: .*pyperplan"):
        solve(problem, engine="nope")


def test_engine_ignoring_costs_is_refused_for_a_cost_domain():
    domain = load_domain(DATA / "costs.pddl")
    assert domain.uses_action_costs
    problem = build_problem(domain, lifting_graph())
    with pytest.raises(EngineError, match="'pyperplan'.*action costs"):
        solve(problem, engine="pyperplan")


def test_a_parse_keeps_nothing_of_the_one_before(monkeypatch):
    """Each parse reads with a copy of one reader per environment (the grammar is built
    once): a cost domain, then one without costs, then the cost domain again read as by
    fresh readers."""
    from unified_planning.io import PDDLReader

    from ldhp_tamp import symbolic

    costs, plain = (DATA / "costs.pddl").read_text(), (domains_dir() / "ldhp.pddl").read_text()
    shared = [parse_domain(t) for t in (costs, plain, costs)]
    assert [d.uses_action_costs for d in shared] == [True, False, True]
    env = symbolic._environment()
    assert symbolic._READERS[id(env)][0] is env
    template = symbolic._READERS[id(env)][1]
    assert template._totalcost is None  # the copies took the parses' state, not it
    made = []
    monkeypatch.setattr(symbolic, "_READERS", {})
    monkeypatch.setattr(symbolic, "_reader", lambda e: made.append(1) or PDDLReader(e))
    fresh = [parse_domain(t) for t in (costs, plain, costs)]
    assert len(made) == 5  # a cost domain is read twice (parse_domain)
    for a, b in zip(shared, fresh):
        assert (a.template, a.kind, a.info, a.uses_action_costs) == (b.template, b.kind, b.info, b.uses_action_costs)


@needs_fd
def test_fast_downward_honours_costs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    domain = load_domain(DATA / "costs.pddl")  # push 1, tip 3: the cheap plan pushes
    graph = ContactGraph((L[0], V[1], L[1], FREE),
                         {"tip": frozenset({(L[0], V[1]), (V[1], L[1])}),
                          "push": frozenset({(L[0], FREE), (FREE, L[1])})},
                         L[0], L[1], start_touching=True)
    result = solve(build_problem(domain, graph), engine="fast-downward-opt")
    assert [a.name for a in result.actions] == ["push", "push"]
    assert os.getcwd() == str(tmp_path)
    assert list(tmp_path.iterdir()) == []


@needs_fd
def test_fast_downward_runs_in_a_private_directory_under_the_lock(ldhp, tmp_path, monkeypatch):
    import subprocess

    from ldhp_tamp import symbolic

    seen: list[tuple[str, bool]] = []
    popen = subprocess.Popen

    def spy(*args, **kwargs):
        seen.append((os.getcwd(), symbolic._SOLVE_LOCK.locked()))
        return popen(*args, **kwargs)

    monkeypatch.setattr(subprocess, "Popen", spy)
    monkeypatch.chdir(tmp_path)
    graph = lifting_graph(goal_release=True)
    assert_plan_is_valid(graph, solve(build_problem(ldhp, graph), engine="fast-downward"))
    assert seen, "fast-downward did not start a process"
    for cwd, locked in seen:
        assert locked
        assert cwd != str(tmp_path) and not os.path.exists(cwd)  # private, then removed
    assert os.getcwd() == str(tmp_path)
    assert not (tmp_path / "output.sas").exists()


# --------------------------------------------------------------------------- extending


def _pddl_blocks(markdown: str) -> list[str]:
    return re.findall(r"```pddl\n(.*?)```", markdown, flags=re.S)


def test_adding_a_primitive_as_docs_extending_says(tmp_path):
    """Follow docs/extending.md literally: its PDDL snippets go into a copy of the domain."""
    predicate, action = _pddl_blocks((ROOT / "docs" / "extending.md").read_text())[:2]
    text = (domains_dir() / "ldhp.pddl").read_text()
    text = text.replace("  (:predicates\n", "  (:predicates\n" + predicate, 1)
    text = text[:text.rstrip().rindex(")")] + action + ")\n"
    copy = tmp_path / "with-roll.pddl"
    copy.write_text(text)

    domain = load_domain(copy)
    assert domain.info.action("roll").family is Family.MOVE_OBJECT
    with pytest.raises(DomainError, match="'roll' has no registered implementation"):
        check_against_domain(domain.info, fake_registry())
    registry = fake_registry(extra=("roll",))
    check_against_domain(domain.info, registry)

    graph = ContactGraph((L[0], L[1], FREE), {"roll": frozenset({(L[0], L[1])})}, L[0], L[1])
    result = solve(build_problem(domain, graph))
    assert [a.name for a in result.actions] == ["approach-contact", "roll"]
    assert result.actions[1].transition == Transition("roll", L[0], L[1])


# --------------------------------------------------------------------------- pyperplan's grounding


def _pyperplan_find_pred_in_init():
    """pyperplan's own grounding._find_pred_in_init (replaced when pyperplan first runs)."""
    import pyperplan.grounding as grounding

    from ldhp_tamp import symbolic

    symbolic._patch_pyperplan()
    assert grounding._find_pred_in_init is symbolic._find_pred_in_init
    return symbolic._REPLACED["_find_pred_in_init"]


def test_the_indexed_static_filter_answers_as_pyperplans_regex_one():
    """ldhp_tamp.symbolic replaces pyperplan's grounding._find_pred_in_init (a regex per
    call, a prefix match) by an index; the answers must be the same, quirks included."""
    import random

    from ldhp_tamp import symbolic

    original = _pyperplan_find_pred_in_init()
    rng = random.Random(5)
    names = ["s-l1-e1", "s-l1-e1_v2-e8", "s-l1-e11", "s-v1", "s-v1-e1", "a", "ab", "b-c", "s-x--after-tip-s-y"]
    preds = ["can-tip", "can-push", "at", "can-tip-x", "touching"]
    for trial in range(30):
        init = frozenset(
            f"({rng.choice(preds)}" + "".join(" " + rng.choice(names) for _ in range(rng.randint(0, 3))) + ")"
            for _ in range(rng.randint(0, 25)))
        for pred in preds:
            for param in names + ["s-l1", "s", "zz"]:
                for pos in range(3):
                    want = original(pred, param, pos, init)
                    assert symbolic._find_pred_in_init(pred, param, pos, init) == want, (trial, pred, param, pos)


def test_grounding_with_the_indexed_filter_makes_the_same_operators(ldhp):
    import pyperplan.grounding as grounding
    from up_pyperplan.engine import EngineImpl

    from ldhp_tamp import symbolic

    original = _pyperplan_find_pred_in_init()
    for graph in (lifting_graph(), _line_graph()):
        problem = build_problem(ldhp, graph).up_problem
        tasks = {}
        for name, fn in (("regex", original), ("indexed", symbolic._find_pred_in_init)):
            saved = grounding._find_pred_in_init
            grounding._find_pred_in_init = fn
            try:
                eng = EngineImpl()
                eng.pyp_types = {}
                task = grounding.ground(eng._convert_problem(eng._convert_domain(problem), problem))
            finally:
                grounding._find_pred_in_init = saved
            tasks[name] = sorted((op.name, sorted(op.preconditions), sorted(op.add_effects), sorted(op.del_effects))
                                 for op in task.operators)
        assert tasks["regex"] == tasks["indexed"] and len(tasks["regex"]) > 5


# --------------------------------------------------------------------------- load-time checks


def test_load_checked_domain_makes_every_check_solve_makes_before_searching() -> None:
    from ldhp_tamp.primitives import REGISTRY
    from ldhp_tamp.symbolic import load_checked_domain

    assert load_checked_domain("ldhp", "pyperplan", REGISTRY).info.name == "ldhp"
    with pytest.raises(DomainError, match="syntax-error.pddl:42:3: PDDL error"):
        load_checked_domain(DATA / "syntax-error.pddl", "pyperplan", REGISTRY)
    with pytest.raises(DomainError, match="action 'juggle' has no registered implementation"):
        load_checked_domain(DATA / "no-implementation.pddl", "pyperplan", REGISTRY)
    with pytest.raises(DomainError, match="action 'tip' has no registered implementation"):
        load_checked_domain("ldhp", "pyperplan", PrimitiveRegistry())
    with pytest.raises(EngineError, match="engine 'pyperplan' cannot solve domain"):
        load_checked_domain(DATA / "costs.pddl", "pyperplan", REGISTRY)
    with pytest.raises(EngineError, match="unknown planning engine 'no-such-engine'"):
        load_checked_domain("ldhp", "no-such-engine", REGISTRY)


# --------------------------------------------------------------------------- engines imported only when used


def test_the_lazy_environment_has_what_unified_plannings_has() -> None:
    from unified_planning.environment import Environment

    from ldhp_tamp.symbolic import _Environment

    theirs, ours = Environment(), _Environment()
    assert ours._factory is None
    assert ours.factory is ours.factory  # made once, on first use
    assert {k: type(v) for k, v in vars(ours).items() if k != "_credits_stream"} == \
           {k: type(v) for k, v in vars(theirs).items() if k != "_credits_stream"}
    assert ours.credits_stream is None


@pytest.mark.parametrize("engine", ["pyperplan", "pyperplan-opt", "fast-downward", "fast-downward-opt"])
def test_check_engine_decides_as_the_engines_do(engine: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The recorded supported kinds accept exactly what the engines accept."""
    from ldhp_tamp import engine_names
    from ldhp_tamp.symbolic import check_engine

    if engine not in available_engines():
        pytest.skip(f"{engine} is not installed")
    domains = [load_domain(p) for p in [*SHIPPED, DATA / "costs.pddl", DATA / "no-air-move.pddl"]]

    def verdicts() -> list[str]:
        out = []
        for domain in domains:
            try:
                check_engine(domain, engine)
                out.append("accepted")
            except EngineError as exc:
                out.append(str(exc))
        return out

    recorded = verdicts()
    monkeypatch.setattr(engine_names, "recorded_kind", lambda name: None)  # ask the engines
    assert recorded == verdicts()
    assert "accepted" in recorded


_IMPORTS = ("import sys; from ldhp_tamp.primitives import REGISTRY; from ldhp_tamp.symbolic import load_checked_domain; "
            "load_checked_domain('ldhp', 'pyperplan', REGISTRY, load_engine={}); "
            "print(sorted({{m.split('.')[0] for m in sys.modules if m.startswith(('unified_planning.engines', "
            "'ConfigSpace', 'scipy', 'up_pyperplan'))}}))")


def test_the_checks_before_a_search_import_no_engine_and_a_solve_imports_them_while_loading() -> None:
    import subprocess
    import sys
    from ldhp_tamp.engine_names import config_files

    if any(Path(f).is_file() for f in config_files()):  # then unified-planning is asked
        pytest.skip("a unified-planning configuration file exists on this machine")

    def imported(load_engine: bool) -> str:
        run = subprocess.run([sys.executable, "-c", _IMPORTS.format(load_engine)], capture_output=True, text=True,
                             timeout=120, check=True, cwd=ROOT)
        return run.stdout.strip()

    assert imported(False) == "[]"
    assert imported(True) == "['ConfigSpace', 'scipy', 'unified_planning', 'up_pyperplan']"


def test_a_solve_asks_the_engines_themselves_while_loading(monkeypatch: pytest.MonkeyPatch) -> None:
    """An engine the factory does not have (its package fails to import) is unknown to a solve;
    check, which does not import the engines, finds its package and its recorded kind."""
    from ldhp_tamp import symbolic
    from ldhp_tamp.primitives import REGISTRY

    monkeypatch.setattr(symbolic, "available_engines", lambda: ("fast-downward",))
    with pytest.raises(EngineError, match="unknown planning engine 'pyperplan' .*; installed: fast-downward$"):
        symbolic.load_checked_domain("ldhp", "pyperplan", REGISTRY)
    assert symbolic.load_checked_domain("ldhp", "pyperplan", REGISTRY, load_engine=False).info.name == "ldhp"


def test_a_domain_parses_without_packrat_and_puts_pyparsing_back() -> None:
    """The reader runs with pyparsing's memoization off (it is slower on PDDL) and the
    process-wide state is restored afterwards, packrat on or off as it was."""
    from pyparsing import ParserElement

    from ldhp_tamp import symbolic

    seen = []
    before = (ParserElement._parse, ParserElement._packratEnabled)
    with symbolic._no_packrat():
        seen.append(ParserElement._packratEnabled)
    assert seen == [False] and (ParserElement._parse, ParserElement._packratEnabled) == before
    ParserElement.enable_packrat()
    try:
        symbolic.load_domain("ldhp")
        assert ParserElement._packratEnabled and ParserElement._parse == ParserElement._parseCache
    finally:
        ParserElement._parse, ParserElement._packratEnabled = before
