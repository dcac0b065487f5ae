"""ldhp_tamp.parallel: fork_map gives the serial results, raises the children's errors,
and leaves no process behind."""

from __future__ import annotations

import os

import pytest

from ldhp_tamp import parallel
from ldhp_tamp.errors import TimeBudgetExceeded
from ldhp_tamp.parallel import fork_map

needs_fork = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")


def _children() -> set[int]:
    """PIDs of this process's live children (Linux /proc); other tests may have left some
    (multiprocessing's resource tracker): compare with the set before."""
    me = os.getpid()
    out = set()
    for pid in os.listdir("/proc"):
        if pid.isdigit():
            try:
                with open(f"/proc/{pid}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == me:
                out.add(int(pid))
    return out


@needs_fork
@pytest.mark.parametrize("jobs", [1, 2, 3, 5])
def test_results_are_the_serial_ones_in_order(jobs: int) -> None:
    before = _children()
    items = list(range(101))
    pids = set(fork_map(lambda x: os.getpid(), items, jobs))
    assert fork_map(lambda x: (x, x * x, {x % 7}), items, jobs) == [(x, x * x, {x % 7}) for x in items]
    assert len(pids) == min(jobs, len(items) // parallel.MIN_ITEMS_PER_CORE)  # the work was shared
    assert _children() <= before


@needs_fork
def test_few_items_stay_in_the_parent() -> None:
    assert set(fork_map(lambda x: os.getpid(), range(5), 2)) == {os.getpid()}
    assert fork_map(lambda x: x, [], 2) == []


@needs_fork
def test_fewer_items_per_core_may_be_asked_for() -> None:
    """A few large items (the setup's batches of sweeps) are shared out too."""
    items = list(range(6))
    assert len(set(fork_map(lambda x: os.getpid(), items, 2, min_items_per_core=3))) == 2
    assert fork_map(lambda x: x * x, items, 2, min_items_per_core=3) == [x * x for x in items]
    assert set(fork_map(lambda x: os.getpid(), items, 2, min_items_per_core=4)) == {os.getpid()}


@needs_fork
def test_a_childs_exception_is_raised_in_the_parent() -> None:
    before = _children()
    def fail_on(bad: int):
        def fn(x: int) -> int:
            if x == bad:
                raise ValueError(f"item {x}")
            return x
        return fn

    with pytest.raises(ValueError, match="item 33"):  # 33 % 2 == 1: the child's share
        fork_map(fail_on(33), range(64), 2)
    with pytest.raises(ValueError, match="item 32"):  # the parent's share; the child is killed
        fork_map(fail_on(32), range(64), 2)
    assert _children() <= before


@needs_fork
def test_a_timeout_in_a_child_keeps_its_stage() -> None:
    before = _children()
    def fn(x: int) -> int:
        if x == 5:
            raise TimeBudgetExceeded("the setup (tip transitions)")
        return x

    with pytest.raises(TimeBudgetExceeded) as info:
        fork_map(fn, range(64), 2)
    assert info.value.where == "the setup (tip transitions)"
    assert _children() <= before


@needs_fork
def test_unpicklable_errors_and_results_are_reported() -> None:
    before = _children()
    class Local(Exception):  # a local class: not picklable
        pass

    def fn(x: int) -> int:
        if x == 3:
            raise Local("boom")
        return x

    with pytest.raises(RuntimeError, match="Local: boom"):
        fork_map(fn, range(64), 2)
    with pytest.raises(RuntimeError, match="cannot be pickled"):
        fork_map(lambda x: (lambda: x), range(64), 2)  # a child's lambdas
    assert _children() <= before


def _add(state, x):
    return state["base"] + x


def _boom(state, message):
    raise ValueError(message)


def _late(state, where):
    raise TimeBudgetExceeded(where)


def _pid(state):
    return os.getpid()


@needs_fork
def test_a_helper_runs_calls_with_the_state_it_was_forked_with() -> None:
    from ldhp_tamp.parallel import Helper

    before = _children()
    h = Helper({"base": 40})
    try:
        h.submit(_add, 2)
        assert h.result() == 42
        h.submit(_pid)
        assert h.result() != os.getpid()
        h.submit(_boom, "no")
        with pytest.raises(ValueError, match="no"):
            h.result()
        h.submit(_late, "the bottom tier")  # still usable after an error it reported
        with pytest.raises(TimeBudgetExceeded) as info:
            h.result()
        assert info.value.where == "the bottom tier"
        h.submit(_add, 0)
        with pytest.raises(RuntimeError):
            h.submit(_add, 1)  # one call at a time
        assert h.result() == 40
    finally:
        h.close()
    h.close()  # idempotent
    assert not h.alive and _children() <= before
    with pytest.raises(RuntimeError):
        h.submit(_add, 1)
