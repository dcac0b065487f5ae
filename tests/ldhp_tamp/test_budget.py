"""Time budgets (``--timeout``): the deadline reaches every stage, the engine call is
killed at it, and a timeout is a failed result whose reason starts with ``timeout``.

No verdict here depends on how busy the machine is. Where a budget must run out at a
given point of a solve, the test replaces the budget's clock (``budget.clock``) with a
:class:`FakeClock` that stands still and moves only when the test moves it (e.g. on
entering the grasp enumeration), so the budget runs out there whatever the machine's
speed; a fake clock also keeps the real-time alarm off. Where real time is the point (the
alarm, the kill of an engine), a test asserts what happens, never how soon: waits have
:data:`HANG_GUARD_S` as their only upper bound. How long things take is measured by
``benchmarks/startup.py``.

The symbolic engine runs in a forked child when a deadline is set; a stub engine
(``symbolic._run_engine`` patched before the fork, so the child runs the stub) stands in
for one that never returns: it blocks until the test tells it to go on, which the test
does only at its end.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import time
from pathlib import Path

import pytest

from geometry.contacts import contact_state
from geometry.features import FREE, ContactState
from geometry.grasps import GraspOptions, enumerate_grasps
from geometry.kinematics import translate
from ldhp_tamp import budget, symbolic, tamp
from ldhp_tamp.budget import Budget, alarm, alarm_armed, check, expired, remaining
from ldhp_tamp.cli import EXIT_BAD_INPUT, EXIT_NO_PLAN, main
from ldhp_tamp.contact_graph import build_context
from ldhp_tamp.errors import TimeBudgetExceeded
from ldhp_tamp.grasp_graph import GraspPlanner
from ldhp_tamp.path import Segment
from ldhp_tamp.plan import PlanStatus, read_plan
from ldhp_tamp.primitives import REGISTRY, Family
from ldhp_tamp.resources import scenarios_dir
from ldhp_tamp.scenario import load_scenario
from ldhp_tamp.streams import PosePath, StreamStats, pose_paths
from ldhp_tamp.tamp import SolveOptions, SolveStatus, solve

PICK = scenarios_dir() / "example_pick.toml"
TASK1 = scenarios_dir() / "task1_zero_mobility_lift_tilt70.toml"  # solved (the 60 degree hold is not robust)
UNSOLVABLE = Path(__file__).resolve().parents[1] / "data" / "scenarios" / "unsolvable"
#: The only upper bound on a real-time wait: a guard against a hang, not a speed test.
HANG_GUARD_S = 60.0


L1, V2 = ContactState.parse("l1-e1"), ContactState.parse("v2-e1")


def lifting_graph() -> symbolic.ContactGraph:
    """Grasp, tip l1 -> v2, lift: approach-contact, tip, air-move."""
    return symbolic.ContactGraph(
        (L1, V2, FREE), {"tip": frozenset({(L1, V2), (V2, L1)}), "air-move": frozenset({(V2, FREE)})},
        L1, FREE)


class FakeClock:
    """A clock for :data:`ldhp_tamp.budget.clock` that stands still until the test moves it
    (:meth:`advance`), or lets it run with real time from some point on
    (:meth:`follow_real_time`). A forked child gets a copy of it as it is at the fork."""

    def __init__(self, now: float = 1000.0) -> None:
        self.now = now
        self._since: float | None = None

    def __call__(self) -> float:
        return self.now if self._since is None else self.now + (time.perf_counter() - self._since)

    def advance(self, seconds: float) -> None:
        self.now += seconds

    def follow_real_time(self) -> None:
        self.now, self._since = self(), time.perf_counter()


@pytest.fixture
def fake_clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    clock = FakeClock()
    monkeypatch.setattr(budget, "clock", clock)
    return clock


def advance_on_entry(monkeypatch: pytest.MonkeyPatch, owner: object, name: str, clock: FakeClock,
                     seconds: float, call: int = 1) -> None:
    """Move ``clock`` on by ``seconds`` when ``owner.name`` is entered for the ``call``-th time."""
    original = getattr(owner, name)
    calls = [0]

    def entered(*args: object, **kwargs: object) -> object:
        calls[0] += 1
        if calls[0] == call:
            clock.advance(seconds)
        return original(*args, **kwargs)

    monkeypatch.setattr(owner, name, entered)


@pytest.fixture(scope="module")
def ldhp():
    return symbolic.load_domain("ldhp")


@pytest.fixture
def blocked_engine(monkeypatch: pytest.MonkeyPatch):
    """An engine call that blocks until the test tells it to go on (the child inherits the
    patch and the pipe through fork); told only at the end of the test, or after
    :data:`HANG_GUARD_S`. A killed engine never goes on; one that does fails the test."""
    read_end, write_end = os.pipe()

    def block(problem, engine, timeout_s):
        select.select([read_end], [], [], HANG_GUARD_S)
        raise AssertionError("the engine was told to go on: it was not stopped at the deadline")

    monkeypatch.setattr(symbolic, "_run_engine", block)
    yield
    os.write(write_end, b"go")
    os.close(write_end)
    os.close(read_end)


def _dead(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    try:  # killed but not reaped yet (its parent is gone; init reaps it)
        return Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"
    except OSError:
        return True


# --------------------------------------------------------------------------- the value


def test_budget_deadline_remaining_and_check(fake_clock: FakeClock) -> None:
    unlimited = Budget.of(None)
    assert unlimited.deadline is None and unlimited.remaining() is None and not unlimited.expired()
    unlimited.check("anywhere")
    b = Budget.of(10.0)
    assert b.start == 1000.0 and b.deadline == 1010.0
    assert b.remaining() == 10.0 and not b.expired()
    fake_clock.advance(4.0)
    assert b.remaining() == 6.0 and not b.expired()
    b.check("the streams")
    fake_clock.advance(6.0)
    assert b.remaining() == 0.0 and b.expired()
    past = fake_clock() - 1.0
    assert expired(past) and remaining(past) == 0.0 and not expired(None)
    with pytest.raises(TimeBudgetExceeded, match="time budget exceeded in the streams") as info:
        check(past, "the streams")
    assert info.value.where == "the streams"
    with pytest.raises(ValueError, match="non-negative"):
        Budget(-1.0)


def test_the_budget_reads_the_real_clock_by_default() -> None:
    assert budget.clock is time.perf_counter
    b = Budget.of(3600.0)
    assert b.start <= time.perf_counter() and not b.expired()


# --------------------------------------------------------------------------- the engine call


def test_a_timed_engine_call_gives_the_same_plan_as_an_untimed_one(ldhp) -> None:
    graph = lifting_graph()
    problem = symbolic.build_problem(ldhp, graph)
    untimed = symbolic.solve(problem)
    timed = symbolic.solve(problem, timeout_s=HANG_GUARD_S)
    assert [a.name for a in timed.actions] == ["approach-contact", "tip", "air-move"]
    assert timed.actions == untimed.actions and timed.reason == untimed.reason


def test_a_timed_engine_call_reports_unsolvable_like_an_untimed_one(ldhp) -> None:
    graph = symbolic.ContactGraph((L1, V2), {"tip": frozenset({(V2, L1)})}, L1, V2, start_touching=True)
    result = symbolic.solve(symbolic.build_problem(ldhp, graph), timeout_s=HANG_GUARD_S)
    assert result.status is symbolic.SymbolicStatus.UNSOLVABLE
    assert "no contact-state path from s-l1-e1 to s-v2-e1" in result.reason


def test_an_engine_that_never_returns_is_killed_at_the_deadline(ldhp, blocked_engine) -> None:
    problem = symbolic.build_problem(ldhp, lifting_graph())
    t0 = time.perf_counter()
    result = symbolic.solve(problem, timeout_s=0.3)
    elapsed = time.perf_counter() - t0
    assert result.status is symbolic.SymbolicStatus.TIMEOUT and result.actions == ()
    assert "pyperplan hit the time limit of 0.3 s" in result.reason
    assert 0.3 <= elapsed < HANG_GUARD_S  # not before the deadline; not never


def test_the_engine_is_killed_when_the_budgets_clock_says_so(ldhp, blocked_engine, monkeypatch) -> None:
    # the wait reads budget.clock: a fake clock that jumps past the deadline ends it
    calls = [0]

    def clock() -> float:
        calls[0] += 1
        return 0.0 if calls[0] < 4 else 1e9

    monkeypatch.setattr(budget, "clock", clock)
    result = symbolic.solve(symbolic.build_problem(ldhp, lifting_graph()), timeout_s=0.05)
    assert result.status is symbolic.SymbolicStatus.TIMEOUT and calls[0] >= 4


def test_the_kill_reaches_the_engines_own_subprocesses(ldhp, monkeypatch, tmp_path) -> None:
    # Fast Downward runs as a subprocess of the engine call: it must die with it. The
    # budget's clock runs out once the engine has started its subprocess, not before.
    pid_file = tmp_path / "grandchild.pid"

    def spawn_and_hang(problem, engine, timeout_s):
        sleeper = subprocess.Popen(["sleep", "600"])
        pid_file.write_text(str(sleeper.pid))
        time.sleep(600)

    t0 = time.perf_counter()
    monkeypatch.setattr(symbolic, "_run_engine", spawn_and_hang)
    monkeypatch.setattr(budget, "clock", lambda: 1e9 if pid_file.exists() or time.perf_counter() - t0 > HANG_GUARD_S
                        else 0.0)
    result = symbolic.solve(symbolic.build_problem(ldhp, lifting_graph()), timeout_s=0.05)
    assert result.status is symbolic.SymbolicStatus.TIMEOUT
    pid = int(pid_file.read_text())
    stop = time.perf_counter() + HANG_GUARD_S
    while not _dead(pid) and time.perf_counter() < stop:
        time.sleep(0.05)
    assert _dead(pid)


def test_an_engine_that_raises_in_the_child_is_an_error_result(ldhp, monkeypatch) -> None:
    def broken(problem, engine, timeout_s):
        raise ValueError("the engine is broken")

    monkeypatch.setattr(symbolic, "_run_engine", broken)
    result = symbolic.solve(symbolic.build_problem(ldhp, lifting_graph()), timeout_s=HANG_GUARD_S)
    assert result.status is symbolic.SymbolicStatus.ERROR
    assert "ValueError: the engine is broken" in result.reason


def test_an_engine_process_that_dies_is_an_error_result(ldhp, monkeypatch) -> None:
    monkeypatch.setattr(symbolic, "_run_engine", lambda problem, engine, timeout_s: os._exit(3))
    result = symbolic.solve(symbolic.build_problem(ldhp, lifting_graph()), timeout_s=HANG_GUARD_S)
    assert result.status is symbolic.SymbolicStatus.ERROR
    assert "died (exit status 3)" in result.reason


def test_a_timed_engine_call_runs_in_a_forked_child(ldhp, monkeypatch) -> None:
    # A fork, not a fresh interpreter (which would cost ~1.5 s of imports per call): the
    # child runs this process's patched function. The fork's cost is measured by
    # benchmarks/startup.py (~25 ms per call on the development machine).
    here = os.getpid()

    def where(problem, engine, timeout_s):
        raise ValueError(f"ran in process {os.getpid()}, forked from {os.getppid()}")

    monkeypatch.setattr(symbolic, "_run_engine", where)
    result = symbolic.solve(symbolic.build_problem(ldhp, lifting_graph()), timeout_s=HANG_GUARD_S)
    assert f"forked from {here}" in result.reason and f"ran in process {here}," not in result.reason
    untimed = symbolic.solve(symbolic.build_problem(ldhp, lifting_graph()))
    assert f"ran in process {here}," in untimed.reason


def test_the_alarm_interrupts_code_without_deadline_checks() -> None:
    from geometry import shapes

    t0 = time.perf_counter()

    def busy() -> None:  # stands for a vectorised stage with no check() calls
        while time.perf_counter() - t0 < HANG_GUARD_S:
            shapes.segment_distances([[0.0, 0.0]], [[[1.0, 0.0], [2.0, 0.0]]])

    with pytest.raises(TimeBudgetExceeded) as info:
        with alarm(t0 + 0.2, grace=0.05):
            assert alarm_armed()
            busy()
    assert 0.2 <= time.perf_counter() - t0 < HANG_GUARD_S  # not before the deadline; not never
    assert "geometry.shapes.segment_distances" in info.value.where or "the solve" in info.value.where
    # nothing left behind: the previous handler, no timer
    assert signal.getsignal(signal.SIGALRM) is signal.SIG_DFL
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    assert not alarm_armed()


def test_an_alarm_a_library_turned_into_its_own_error_is_still_the_timeout() -> None:
    """numpy's ``norm`` reads ``axis`` under ``except Exception`` and raises a TypeError
    from whatever it caught: an alarm landing there leaves as that TypeError, with the
    timeout as its cause; the alarm raises the timeout again. Other errors go through."""
    late = TimeBudgetExceeded("geometry.shapes.segment_distances (interrupted)")

    def converted() -> None:
        try:
            raise late
        except Exception as exc:
            raise TypeError("'axis' must be None, an integer or a tuple of integers") from exc

    with pytest.raises(TimeBudgetExceeded) as info:
        with alarm(budget.clock() + 3600.0):  # armed, and never firing here
            assert alarm_armed()
            converted()
    assert info.value is late and isinstance(info.value.__cause__, TypeError)
    with pytest.raises(ValueError, match="its own"):
        with alarm(budget.clock() + 3600.0):
            raise ValueError("its own")
    assert not alarm_armed() and signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_the_alarm_interrupts_an_engine_running_in_this_process(ldhp, blocked_engine) -> None:
    problem = symbolic.build_problem(ldhp, lifting_graph())
    with pytest.raises(TimeBudgetExceeded):
        with alarm(budget.clock() + 0.1, grace=0.05):
            symbolic.solve(problem)  # no timeout: in this process, blocked until the alarm


def test_an_alarm_during_the_domain_parse_is_a_timeout_not_a_domain_error(monkeypatch) -> None:
    # the parse (unified-planning's reader, no checks of its own) is interrupted by the
    # alarm when the budget is shorter than the setup: the solve must see the timeout
    class Interrupted:
        def __init__(self, env) -> None:  # noqa: ANN001 - unified-planning's Environment
            pass

        def parse_problem_string(self, domain_text, problem_text):
            raise TimeBudgetExceeded("ldhp_tamp.symbolic._parse (interrupted: it has no deadline checks of its own)")

    monkeypatch.setattr(symbolic, "_reader", Interrupted)  # each parse's reader
    with pytest.raises(TimeBudgetExceeded, match="symbolic._parse"):
        symbolic.load_domain("ldhp")


def test_the_alarm_stays_off_without_a_deadline_or_when_sigalrm_is_taken() -> None:
    with alarm(None):
        assert signal.getsignal(signal.SIGALRM) is signal.SIG_DFL and not alarm_armed()
    def mine(signum, frame) -> None:  # noqa: ANN001 - someone else's handler
        pass
    previous = signal.signal(signal.SIGALRM, mine)
    try:
        with alarm(time.perf_counter() + 0.01, grace=0.0):
            assert not alarm_armed()
            time.sleep(0.05)  # not interrupted: the handler is not ours to replace
        assert signal.getsignal(signal.SIGALRM) is mine
    finally:
        signal.signal(signal.SIGALRM, previous)


def test_the_alarm_stays_off_on_a_fake_clock(fake_clock: FakeClock) -> None:
    # a real-time timer cannot follow a test's clock: the cooperative checks do the work
    with alarm(fake_clock() - 1.0, grace=0.0):
        assert signal.getsignal(signal.SIGALRM) is signal.SIG_DFL and not alarm_armed()
        assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


# --------------------------------------------------------------------------- the stages


def test_the_streams_stop_at_the_deadline(fake_clock: FakeClock) -> None:
    sc = load_scenario(PICK)
    ctx = build_context(sc.world, sc.start, sc.goal)
    domain = symbolic.load_domain("ldhp").info
    paths = pose_paths(ctx, [], domain, REGISTRY, None, StreamStats(), deadline=fake_clock() - 1)
    with pytest.raises(TimeBudgetExceeded, match="streams"):
        next(paths)


def test_the_grasp_graph_stops_at_the_deadline(fake_clock: FakeClock) -> None:
    sc = load_scenario(PICK)
    grasps = enumerate_grasps(sc.world, GraspOptions(samples_per_edge=10))
    planner = GraspPlanner(sc.world, grasps, REGISTRY.bound(symbolic.load_domain("ldhp").info, Family.ADJUST_GRASP))
    up = translate(sc.start, (0.0, 1.0))
    seg = Segment("air-move", contact_state(sc.world, sc.start), FREE, up, 0.0, 100.0, sc.world, {"lift": 100.0})
    path = PosePath((seg,))
    with pytest.raises(TimeBudgetExceeded, match="bottom tier"):
        planner.plan(path, deadline=fake_clock() - 1)
    assert planner.plan(path, deadline=fake_clock() + 1).solved  # the clock stands still


# --------------------------------------------------------------------------- whole solves


def _assert_timed_out(result, timeout: float) -> None:
    assert result.status is SolveStatus.FAILED and result.plan.status is PlanStatus.FAILED
    assert result.reason.startswith(f"timeout: the {timeout:g} s budget ran out in ")
    assert result.plan.reason == result.reason and result.plan.steps == ()
    assert result.plan.stats.time_s["total"] >= timeout


@pytest.mark.parametrize("helpers", [False, True])
def test_a_budget_shorter_than_the_setup_fails_in_it(fake_clock: FakeClock, monkeypatch, helpers: bool) -> None:
    # the budget runs out while the grasps are enumerated: the check after them says so.
    # With helpers a forked child enumerates them (its clock moves on in the child): the
    # clock moves on here as the solve waits for the child's grasp set.
    from ldhp_tamp import parallel

    if helpers:
        advance_on_entry(monkeypatch, parallel.Forked, "result", fake_clock, 1e-3)
    else:
        advance_on_entry(monkeypatch, tamp, "enumerate_grasps", fake_clock, 1e-3)
    result = solve(load_scenario(PICK), SolveOptions(timeout=1e-3, helpers=helpers))
    _assert_timed_out(result, 1e-3)
    assert result.reason.startswith("timeout: the 0.001 s budget ran out in the setup (grasp enumeration)")
    assert result.plan.stats.contact_state_nodes > 0  # what was gathered so far
    assert result.plan.stats.top_iterations == 0


def test_the_admissible_transitions_stop_at_the_deadline(fake_clock: FakeClock, monkeypatch) -> None:
    # 78 contact states: the budget runs out as their transitions are swept, and the
    # sweeps' own checks (in forked children too) stop them. The clock moves on as the
    # setup forks the helper that sweeps them (a forked child has the clock as it was).
    from ldhp_tamp.grasp_graph import GraspPlanner

    sc = load_scenario(UNSOLVABLE / "goal_in_closed_box.toml")
    advance_on_entry(monkeypatch, GraspPlanner, "start_helper", fake_clock, 0.8)
    result = solve(sc, SolveOptions(timeout=0.8))
    _assert_timed_out(result, 0.8)
    assert result.plan.stats.top_iterations == 0
    assert "ran out in the setup (" in result.reason
    assert "(contact-state graph, admissible transitions)" not in result.reason  # not the check after them
    assert result.plan.stats.time_s["setup"] >= 0.8


def test_a_hanging_engine_is_a_timeout_of_the_symbolic_tier(fake_clock: FakeClock, blocked_engine,
                                                             monkeypatch) -> None:
    # the setup takes no time on the fake clock, which runs in real time from the engine
    # call on: the engine (in a child: no alarm on a fake clock) gets the whole budget
    real_solve = symbolic.solve

    def solve_on_the_clock(*args, **kwargs):
        fake_clock.follow_real_time()
        return real_solve(*args, **kwargs)

    monkeypatch.setattr(symbolic, "solve", solve_on_the_clock)
    t0 = time.perf_counter()
    result = solve(load_scenario(PICK), SolveOptions(timeout=1.0))
    assert time.perf_counter() - t0 < HANG_GUARD_S
    _assert_timed_out(result, 1.0)
    assert "ran out in the symbolic tier, iteration 1 (pyperplan hit the time limit of 1 s" in result.reason
    assert result.plan.stats.top_iterations == 1 and result.plan.stats.time_s["symbolic"] >= 1.0


def test_a_budget_that_runs_out_in_a_grasp_plan_is_a_timeout_of_the_bottom_tier(fake_clock: FakeClock,
                                                                                 monkeypatch) -> None:
    # task 1's first pose path has no grasp sequence (the first grasp plan proves it);
    # the budget runs out as the second grasp plan starts
    advance_on_entry(monkeypatch, GraspPlanner, "plan", fake_clock, 100.0, call=2)
    result = solve(load_scenario(TASK1), SolveOptions(timeout=100.0))
    _assert_timed_out(result, 100.0)
    assert "ran out in the bottom tier" in result.reason
    stats = result.plan.stats
    assert stats.top_iterations >= 1 and stats.feasibility_checks > 0 and stats.time_s["grasp_graph"] >= 100.0


def test_a_generous_budget_changes_nothing() -> None:
    sc = load_scenario(PICK)
    free, timed = solve(sc), solve(sc, SolveOptions(timeout=3600.0))
    assert timed.solved and timed.plan.steps == free.plan.steps


def test_cli_timeout_writes_a_failed_plan_and_exits_1(fake_clock: FakeClock, monkeypatch, tmp_path: Path,
                                                      capsys) -> None:
    advance_on_entry(monkeypatch, tamp, "admissible_transitions", fake_clock, 0.5)
    out = tmp_path / "plan.json"
    assert main(["solve", str(TASK1), "--out", str(out), "--timeout", "0.5", "-q"]) == EXIT_NO_PLAN
    data = json.loads(out.read_text())
    assert data["status"] == "failed" and data["steps"] == [] and data["reason"].startswith("timeout")
    assert data["stats"]["time_s"]["total"] >= 0.5 and data["stats"]["contact_state_nodes"] > 0
    assert read_plan(out).status is PlanStatus.FAILED
    assert "reason: timeout" in capsys.readouterr().out


def test_cli_timeout_counts_from_the_start_of_the_command(fake_clock: FakeClock, monkeypatch,
                                                          tmp_path: Path) -> None:
    # loading the scenario takes the whole budget (and counts in the plan's time): the
    # solve fails at once
    from ldhp_tamp import scenario

    advance_on_entry(monkeypatch, scenario, "load_scenario", fake_clock, 2.0)
    out = tmp_path / "plan.json"
    assert main(["solve", str(PICK), "--out", str(out), "--timeout", "1", "-q"]) == EXIT_NO_PLAN
    data = json.loads(out.read_text())
    assert data["reason"].startswith("timeout: the 1 s budget ran out in loading (the scenario and the planner")
    assert data["stats"]["time_s"]["total"] == 2.0 and data["stats"]["top_iterations"] == 0


@pytest.mark.parametrize("value", ["0", "-1", "abc", "nan", "inf"])
def test_cli_refuses_a_timeout_that_is_not_a_positive_number(value: str, tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as info:
        main(["solve", str(PICK), "--out", str(tmp_path / "p.json"), "--timeout", value])
    assert info.value.code == EXIT_BAD_INPUT
    assert "--timeout" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_under_the_armed_alarm_pyperplan_runs_in_this_process(monkeypatch: pytest.MonkeyPatch) -> None:
    """A pure-Python engine needs no child process when the budget's alarm can interrupt
    it (a fork per iteration saved); the plan is the one the child would have found."""
    reference = solve(load_scenario(PICK))  # no budget: in this process anyway

    def no_child(problem, engine, timeout_s):
        raise AssertionError("the engine ran in a child process")

    monkeypatch.setattr(symbolic, "_run_engine_in_child", no_child)
    result = solve(load_scenario(PICK), SolveOptions(timeout=3600.0))
    assert result.solved
    assert [s.primitive for s in result.plan.steps] == [s.primitive for s in reference.plan.steps]
