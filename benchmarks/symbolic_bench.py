"""Speed of the symbolic tier: milliseconds per top-tier iteration (problem build + solve).

Synthetic contact graphs shaped like the paper's tasks: 8 states (task 1, lifting) and 40
states (task 2, slot insertion: "the contact-state search explores forty candidate
states"), each state with 3-6 random admissible out-transitions spread over tip, push and
biplanar-slide, air-moves between ``free`` and a few contact states. Each iteration builds
the problem (with the forbidden transitions of the previous iterations, as the TAMP loop
does) and solves it; the failed transition reported back is the plan's last move.

Also measured: building a problem through the model API against parsing the same problem
from PDDL text (what re-reading a problem file per iteration would cost).

Run::

    .venv/bin/python benchmarks/symbolic_bench.py                # 8 and 40 states
    .venv/bin/python benchmarks/symbolic_bench.py --states 100 --engines pyperplan
    .venv/bin/python benchmarks/symbolic_bench.py --scenario scenarios/task2_slot_insertion.toml

With ``--scenario`` the graph is the real one the TAMP loop gives the symbolic tier for
that scenario: the enumerated contact states, the admissible transitions from the
MoveObject sweeps, and only the states on some start-goal path.
"""

from __future__ import annotations

import argparse
import logging
import random
import statistics
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from geometry.features import FREE, Contact, ContactKind, ContactState
from ldhp_tamp.symbolic import (
    ContactGraph,
    SymbolicDomain,
    SymbolicStatus,
    Transition,
    available_engines,
    build_problem,
    load_domain,
    solve,
)

log = logging.getLogger("symbolic_bench")

CONTACT_MOVES = ("tip", "push", "biplanar-slide")


def synthetic_graph(n_states: int, seed: int = 0) -> ContactGraph:
    """A connected random contact graph of ``n_states`` states (``free`` included).

    Contact states are single vertex-edge / edge-edge contacts and, for biplanar-slide,
    pairs of them on two environment edges, named as the geometry names them.
    """
    rng = random.Random(seed)
    singles = [ContactState.of([Contact(kind, o, e)])
               for e in range(4) for o in range(8)
               for kind in (ContactKind.VERTEX_EDGE, ContactKind.EDGE_EDGE)]
    pairs = [ContactState.of([a.contacts[0], b.contacts[0]])
             for a in singles for b in singles if a.contacts[0].env < b.contacts[0].env]
    rng.shuffle(singles)
    rng.shuffle(pairs)
    n_contact = n_states - 1
    contact = (singles[: (n_contact + 1) // 2] + pairs[: n_contact // 2])[:n_contact]
    transitions: dict[str, set[tuple[ContactState, ContactState]]] = {
        name: set() for name in (*CONTACT_MOVES, "air-move")}
    for i, s in enumerate(contact):  # a chain keeps the graph connected
        if i + 1 < len(contact):
            transitions[rng.choice(CONTACT_MOVES)].add((s, contact[i + 1]))
        for _ in range(rng.randint(2, 5)):
            t = rng.choice(contact)
            if t != s:
                transitions[rng.choice(CONTACT_MOVES)].add((s, t))
    for s in rng.sample(contact[:-1], min(3, n_contact - 1)):  # more ways into the goal
        transitions[rng.choice(CONTACT_MOVES)].add((s, contact[-1]))
    for s in rng.sample(contact, max(1, n_contact // 8)):
        transitions["air-move"] |= {(s, FREE), (FREE, s)}
    return ContactGraph(
        states=(*contact, FREE),
        transitions={k: frozenset(v) for k, v in transitions.items()},
        start=contact[0], goal=contact[-1], start_touching=False, goal_release=True)


@dataclass(frozen=True)
class Timing:
    engine: str
    n_states: int
    n_transitions: int
    build_ms: float
    iteration_ms: list[float]
    plan_length: int
    final: SymbolicStatus


def _ms(f: Callable[[], object]) -> tuple[float, object]:
    start = time.perf_counter()
    value = f()
    return (time.perf_counter() - start) * 1e3, value


def run_engine(domain: SymbolicDomain, graph: ContactGraph, engine: str,
               iterations: int) -> Timing:
    """``iterations`` top-tier iterations with feedback; the first one is a warm-up."""
    solve(build_problem(domain, graph), engine)  # warm-up: imports, caches
    forbidden: set[Transition] = set()
    times: list[float] = []
    builds: list[float] = []
    length, status = 0, SymbolicStatus.SOLVED
    for _ in range(iterations):
        start = time.perf_counter()
        build_ms, problem = _ms(lambda: build_problem(domain, graph, forbidden))
        result = solve(problem, engine)
        times.append((time.perf_counter() - start) * 1e3)
        builds.append(build_ms)
        status = result.status
        if not result.solved or not result.transitions():
            break
        length = max(length, len(result.actions))
        forbidden.add(result.transitions()[-1])
    return Timing(engine, len(graph.states), len(graph.all_transitions()),
                  statistics.median(builds), times, length, status)


def build_vs_parse(domain: SymbolicDomain, graph: ContactGraph, repeats: int) -> tuple[float, float]:
    """Median ms to build a problem via the model API, and to parse its PDDL text."""
    from unified_planning.io import PDDLReader, PDDLWriter  # benchmark only

    problem = build_problem(domain, graph)
    writer = PDDLWriter(problem.up_problem)
    domain_text, problem_text = writer.get_domain(), writer.get_problem()
    build = [_ms(lambda: build_problem(domain, graph))[0] for _ in range(repeats)]
    parse = [_ms(lambda: PDDLReader().parse_problem_string(domain_text, problem_text))[0]
             for _ in range(max(1, repeats // 5))]
    return statistics.median(build), statistics.median(parse)


def scenario_graph(path: str) -> ContactGraph:
    """The contact graph the TAMP loop builds for a scenario (first iteration)."""
    from ldhp_tamp.contact_graph import admissible_transitions, build_context, relevant_states
    from ldhp_tamp.primitives import REGISTRY
    from ldhp_tamp.scenario import load_scenario

    sc = load_scenario(path)
    ctx = build_context(sc.world, sc.start, sc.goal)
    tr = admissible_transitions(ctx, load_domain("ldhp").info, REGISTRY)
    keep = relevant_states(ctx, tr)
    return ContactGraph(tuple(s for s in ctx.states if s in keep),
                        {a: frozenset(p for p in v if p[0] in keep and p[1] in keep) for a, v in tr.items()},
                        ctx.start_state, ctx.goal_state, sc.start_grasp is not None, sc.goal_release)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, nargs="+", default=[8, 40])
    parser.add_argument("--engines", nargs="+", default=None,
                        help="default: pyperplan and fast-downward if installed")
    parser.add_argument("--iterations", type=int, default=10, help="top-tier iterations per run")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scenario", nargs="+", default=[], metavar="FILE",
                        help="benchmark the real contact graphs of these scenarios instead")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    installed = available_engines()
    engines = args.engines or [e for e in ("pyperplan", "fast-downward") if e in installed]
    domain = load_domain("ldhp")
    out = sys.stdout
    out.write(f"{'states':>6} {'trans':>5} {'engine':<18} {'build ms':>8} {'median ms/iter':>14} "
              f"{'max ms':>7} {'iters':>5} {'plan len':>8} final\n")
    graphs = ([(f, scenario_graph(f)) for f in args.scenario] if args.scenario
              else [(str(n), synthetic_graph(n, args.seed)) for n in args.states])
    for name, graph in graphs:
        if args.scenario:
            out.write(f"{name}:\n")
        for engine in engines:
            t = run_engine(domain, graph, engine, args.iterations)
            out.write(f"{t.n_states:>6} {t.n_transitions:>5} {t.engine:<18} {t.build_ms:>8.1f} "
                      f"{statistics.median(t.iteration_ms):>14.1f} {max(t.iteration_ms):>7.1f} "
                      f"{len(t.iteration_ms):>5} {t.plan_length:>8} {t.final.value}\n")
    for name, graph in graphs:
        build, parse = build_vs_parse(domain, graph, 25)
        out.write(f"{name} ({len(graph.states)} states): model-API build {build:.1f} ms vs parsing "
                  f"the problem text {parse:.1f} ms\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
