"""ldhp_tamp.parallel: fork_map gives the serial results, raises the children's errors,
and leaves no process behind."""

from __future__ import annotations

import os
import time

import pytest

from ldhp_tamp import parallel
from ldhp_tamp.errors import TimeBudgetExceeded
from ldhp_tamp.parallel import fork_map
from processes import child_pids

needs_fork = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this platform")


def _children() -> set[int]:
    """PIDs of this process's children (zombies included), once the ones that answered as
    they ended are reaped (``parallel.reap``, which a solve calls at its end)."""
    parallel.reap()
    return child_pids()


@needs_fork
def test_a_child_that_answered_is_reaped_later_and_none_is_left_after_reap() -> None:
    """The parent takes a child's whole answer without waiting for its end (the end of a
    forked copy of a large process takes milliseconds): such a child is left to
    ``reap``, and after it none is left, zombie or not."""
    before = _children()
    ballast = bytearray(200 << 20)  # a larger process ends more slowly
    ballast[::4096] = b"x" * len(ballast[::4096])
    assert fork_map(lambda x: x + 1, list(range(40)), 2) == list(range(1, 41))
    assert parallel.Forked(lambda: 7).result() == 7
    assert _children() <= before and not parallel._UNREAPED
    del ballast


def _wait_for(marker, seconds: float = 60.0) -> None:
    """Until ``marker`` exists (the other process has claimed an item), at most ``seconds``."""
    t_end = time.monotonic() + seconds
    while not marker.exists():
        assert time.monotonic() < t_end, f"{marker.name}: the other process never claimed an item"
        time.sleep(0.001)


def _child_does(parent: int, marker, in_child, in_parent=lambda x: x):
    """A function for fork_map whose first call in the parent waits until a child has
    claimed an item (so that a child surely computes one): ``in_child(x)`` there,
    ``in_parent(x)`` here."""
    def fn(x):
        if os.getpid() == parent:
            _wait_for(marker)
            return in_parent(x)
        marker.touch()
        return in_child(x)
    return fn


def _both_compute(parent: int, where):
    """A function for fork_map (its value: the pid computing it) whose calls wait, in
    the parent until a child has called it, in a child until the parent has, so that
    both surely compute an item however busy the machine (each holds one claim while it
    waits, which leaves the others to the other)."""
    mine, theirs = where / "parent", where / "child"

    def fn(x):
        here = os.getpid() == parent
        (mine if here else theirs).touch()
        _wait_for(theirs if here else mine)
        return os.getpid()
    return fn


@needs_fork
@pytest.mark.parametrize("jobs", [1, 2, 3, 5])
def test_results_are_the_serial_ones_in_order(jobs: int, tmp_path) -> None:
    before = _children()
    items = list(range(101))
    assert fork_map(lambda x: (x, x * x, {x % 7}), items, jobs) == [(x, x * x, {x % 7}) for x in items]
    # each item computed by exactly one process, whoever claims it
    log = tmp_path / "log"
    def fn(x):
        fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
        try:
            os.write(fd, f"{x} {os.getpid()}\n".encode())
        finally:
            os.close(fd)
        return x
    assert fork_map(fn, items, jobs) == items
    lines = [line.split() for line in log.read_text().splitlines()]
    assert sorted(int(x) for x, _ in lines) == items
    assert len({pid for _, pid in lines}) <= min(jobs, len(items) // parallel.MIN_ITEMS_PER_CORE, 5)
    assert _children() <= before


@needs_fork
def test_the_children_share_the_work(tmp_path) -> None:
    me = os.getpid()
    pids = fork_map(_both_compute(me, tmp_path), range(64), 2)
    assert me in pids and len(set(pids)) == 2


@needs_fork
def test_few_items_stay_in_the_parent() -> None:
    assert set(fork_map(lambda x: os.getpid(), range(5), 2)) == {os.getpid()}
    assert fork_map(lambda x: x, [], 2) == []


@needs_fork
def test_fewer_items_per_core_may_be_asked_for(tmp_path) -> None:
    """A few large items (the setup's batches of sweeps) are shared out too."""
    me = os.getpid()
    items = list(range(6))
    assert len(set(fork_map(_both_compute(me, tmp_path), items, 2, min_items_per_core=3))) == 2
    assert fork_map(lambda x: x * x, items, 2, min_items_per_core=3) == [x * x for x in items]
    assert set(fork_map(lambda x: os.getpid(), items, 2, min_items_per_core=4)) == {os.getpid()}


@needs_fork
def test_a_childs_exception_is_raised_in_the_parent(tmp_path) -> None:
    before = _children()
    def fail_on(bad: int):
        def fn(x: int) -> int:
            if x == bad:
                raise ValueError(f"item {x}")
            return x
        return fn

    with pytest.raises(ValueError, match="item 33"):  # whoever claims it
        fork_map(fail_on(33), range(64), 2)
    def in_child(x: int) -> int:
        raise ValueError(f"item {x}, in a child")

    with pytest.raises(ValueError, match="in a child"):  # after the parent's share
        fork_map(_child_does(os.getpid(), tmp_path / "claimed", in_child), range(64), 2)
    assert _children() <= before


@needs_fork
def test_an_exception_in_the_parent_kills_the_children(tmp_path) -> None:
    before = _children()
    finished = tmp_path / "finished"

    def hang(x):
        time.sleep(60.0)
        finished.touch()  # only if it was left to finish
        return x

    def boom(x):
        raise ValueError("the parent's item")

    with pytest.raises(ValueError, match="the parent's item"):
        fork_map(_child_does(os.getpid(), tmp_path / "claimed", hang, boom), range(64), 2)
    assert not finished.exists()  # the hanging child was killed, not waited for (no clock read)
    assert _children() <= before


@needs_fork
def test_a_timeout_in_a_child_keeps_its_stage(tmp_path) -> None:
    before = _children()
    def late(x: int) -> int:
        raise TimeBudgetExceeded("the setup (tip transitions)")

    with pytest.raises(TimeBudgetExceeded) as info:
        fork_map(_child_does(os.getpid(), tmp_path / "claimed", late), range(64), 2)
    assert info.value.where == "the setup (tip transitions)"
    assert _children() <= before


@needs_fork
def test_unpicklable_errors_and_results_are_reported(tmp_path) -> None:
    before = _children()
    class Local(Exception):  # a local class: not picklable
        pass

    def boom(x: int) -> int:
        raise Local("boom")

    with pytest.raises(RuntimeError, match="Local: boom"):
        fork_map(_child_does(os.getpid(), tmp_path / "a", boom), range(64), 2)
    with pytest.raises(RuntimeError, match="cannot be pickled"):
        fork_map(_child_does(os.getpid(), tmp_path / "b", lambda x: (lambda: x)), range(64), 2)  # a child's lambdas
    assert _children() <= before


def test_more_items_than_tokens_are_claimed_in_runs(monkeypatch, tmp_path) -> None:
    """A pipe holds MAX_TOKENS tokens: a longer list is claimed in runs of items, each
    item still computed once, by one process."""
    monkeypatch.setattr(parallel, "MAX_TOKENS", 4)
    items = list(range(101))
    me = os.getpid()
    pids = fork_map(_both_compute(me, tmp_path), items, 2)
    assert len(pids) == 101 and len(set(pids)) == 2
    # runs of 26 consecutive items (ceil(101 / 4)), each run in one process
    assert all(len(set(pids[k:k + 26])) == 1 for k in range(0, 101, 26))
    assert fork_map(lambda x: x * x, items, 2) == [x * x for x in items]
    with pytest.raises(ValueError, match="at most 4 tokens"):
        parallel._tokens(5)
    read_end = parallel._tokens(4)
    try:
        assert os.read(read_end, 8) == (0).to_bytes(4, "little") + (1).to_bytes(4, "little")
    finally:
        os.close(read_end)


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


def _after_a_byte(state, fd):
    return os.read(fd, 1)


@needs_fork
def test_a_helper_says_whether_its_answer_has_come() -> None:
    """``answered``: False with no call pending and while the call runs (here it waits for
    a byte this process has not written), True once the answer is there to read."""
    import time

    from ldhp_tamp.parallel import Helper

    read_end, write_end = os.pipe()
    h = Helper({"base": 40})
    try:
        assert not h.answered()
        h.submit(_after_a_byte, read_end)
        assert not h.answered() and not h.idle
        os.write(write_end, b"x")
        while not h.answered():
            time.sleep(0.001)
        assert h.result() == b"x" and not h.answered() and h.idle
    finally:
        h.close()
        os.close(read_end)
        os.close(write_end)
    assert not h.answered()


def _add_where(state, x):
    return state["base"] + x, os.getpid()


@needs_fork
def test_two_at_a_time_gives_every_second_item_to_the_helper_in_order() -> None:
    from ldhp_tamp.parallel import Helper, two_at_a_time

    here = lambda x: (40 + x, os.getpid())  # noqa: E731
    there = lambda x: (_add_where, (x,))  # noqa: E731
    assert two_at_a_time(None, [1, 2, 3], here, there) == [(41, os.getpid()), (42, os.getpid()), (43, os.getpid())]
    h = Helper({"base": 40})
    try:
        got = two_at_a_time(h, list(range(7)), here, there)
        assert [v for v, _ in got] == [40 + x for x in range(7)]
        assert all((pid == os.getpid()) == (i % 2 == 0) for i, (_, pid) in enumerate(got))
        assert h.idle
        assert two_at_a_time(h, [5], here, there) == [(45, os.getpid())]  # one item: here
        _a_failure_here_closes(h, lambda fail: two_at_a_time(h, [1, 2], fail, there))
    finally:
        h.close()


def _a_failure_here_closes(h, call) -> None:
    """``call(fail)`` raises ``fail``'s error, and ``h`` is closed: its answer is not
    wanted, and it is not waited for."""
    def fail(x):
        raise KeyError(x)
    with pytest.raises(KeyError):
        call(fail)
    assert not h.alive


def _add_all_where(state, xs):
    return [(state["base"] + x, os.getpid(), len(xs)) for x in xs]


@needs_fork
def test_two_halves_gives_every_second_item_to_the_helper_in_one_call() -> None:
    from ldhp_tamp.parallel import Helper, two_halves

    here = lambda xs: [(40 + x, os.getpid(), len(xs)) for x in xs]  # noqa: E731
    there = lambda xs: (_add_all_where, (list(xs),))  # noqa: E731
    assert two_halves(None, [1, 2, 3], here, there) == [(41, os.getpid(), 3), (42, os.getpid(), 3),
                                                         (43, os.getpid(), 3)]
    h = Helper({"base": 40})
    try:
        got = two_halves(h, list(range(7)), here, there)
        assert [v for v, _, _ in got] == [40 + x for x in range(7)]
        assert all((pid == os.getpid()) == (i % 2 == 0) for i, (_, pid, _) in enumerate(got))
        assert [n for _, _, n in got] == [4, 3, 4, 3, 4, 3, 4]  # one batch each
        assert h.idle
        assert two_halves(h, [5], here, there) == [(45, os.getpid(), 1)]  # one item: here
        _a_failure_here_closes(h, lambda fail: two_halves(h, [1, 2], fail, there))
    finally:
        h.close()


# ---- Forked ---------------------------------------------------------------------------


@needs_fork
def test_forked_computes_in_a_child_what_the_parent_takes_later(monkeypatch) -> None:
    from ldhp_tamp.parallel import Forked

    monkeypatch.setattr(parallel, "cores", lambda: 2)
    before = _children()
    state = {"base": 40}
    job = Forked(lambda x: (state["base"] + x, os.getpid()), 2)  # a closure: inherited, not pickled
    assert job.forked
    state["base"] = 0  # the child has its own copy, as it was at the fork
    value, pid = job.result()
    assert value == 42 and pid != os.getpid()
    with pytest.raises(RuntimeError, match="taken already"):
        job.result()
    job.close()  # idempotent, nothing left
    assert _children() <= before


@needs_fork
def test_forked_raises_the_childs_errors_and_timeouts(monkeypatch) -> None:
    from ldhp_tamp.parallel import Forked

    monkeypatch.setattr(parallel, "cores", lambda: 2)
    before = _children()

    def boom() -> None:
        raise ValueError("in the child")

    with pytest.raises(ValueError, match="in the child"):
        Forked(boom).result()
    with pytest.raises(TimeBudgetExceeded) as info:
        Forked(_late, None, "the setup (transitions)").result()
    assert info.value.where == "the setup (transitions)"
    with pytest.raises(RuntimeError, match="cannot be pickled"):
        Forked(lambda: (lambda: 1)).result()
    assert _children() <= before


@needs_fork
def test_a_closed_forked_child_is_killed_not_waited_for(monkeypatch, tmp_path) -> None:
    from ldhp_tamp.parallel import Forked

    monkeypatch.setattr(parallel, "cores", lambda: 2)
    before = _children()
    started, finished = tmp_path / "started", tmp_path / "finished"

    def hang() -> int:
        started.touch()
        time.sleep(60.0)
        finished.touch()  # only if it was left to finish
        return 1

    job = Forked(hang)
    _wait_for(started)
    job.close()
    assert not finished.exists() and _children() <= before
    with pytest.raises(RuntimeError, match="taken already"):
        job.result()


def test_forked_on_one_core_computes_when_asked(monkeypatch) -> None:
    from ldhp_tamp.parallel import Forked

    monkeypatch.setattr(parallel, "cores", lambda: 1)
    calls = []
    job = Forked(lambda x: calls.append(x) or os.getpid(), 7)
    assert not job.forked and calls == []  # nothing yet: the parent's other work comes first
    assert job.result() == os.getpid() and calls == [7]
