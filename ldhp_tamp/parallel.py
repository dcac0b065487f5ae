"""Independent work of one solve on the machine's cores, in forked children.

Three tools. :func:`fork_map` applies a function to a list of items: the parent process
and a forked child per other core claim the items one at a time as each gets free; a
child inherits everything the parent has built (the world, the contact states, the
grasp set) for free and sends only its results back through a pipe, pickled. It serves
the setup's transition sweeps, hundreds of small independent computations of a few
milliseconds each, in batches; a pool of workers would have to be sent the world first
and would cost more than it saves. :class:`Helper` is
one long-lived child for work that comes one piece at a time (the bottom tier's G_m and
G_T, the streams' sweeps): the solve hands it the next piece and computes the current
one itself. :class:`Forked` is one child for one call whose small result the parent
takes later, doing other work meanwhile (the setup's transitions, while the parent
builds the grasp graph's tables).

The results are those of ``[fn(x) for x in items]``, in that order, whatever the number
of cores: each item is computed by exactly one process, by the same code. An exception
in a child is raised again in the parent (a :class:`~ldhp_tamp.errors.TimeBudgetExceeded`
with its stage); when the parent is interrupted (its own exception, the budget's alarm),
the children are killed and reaped before the exception goes on.

Without ``os.fork`` (not POSIX), with one core, or with few items, it runs in the parent.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import os
import pickle
import signal
import threading
from typing import Callable, Generic, Iterator, Sequence, TypeVar

from ldhp_tamp.errors import TimeBudgetExceeded

__all__ = ["Forked", "Helper", "cores", "fork_map", "reap", "two_at_a_time"]

log = logging.getLogger(__name__)

T = TypeVar("T")
R = TypeVar("R")

#: Fewer items than this per core are not worth a fork (about 10-20 ms each).
MIN_ITEMS_PER_CORE = 16


def cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def fork_map(fn: Callable[[T], R], items: Sequence[T], jobs: int | None = None, *,
             min_items_per_core: int = MIN_ITEMS_PER_CORE) -> list[R]:
    """``[fn(x) for x in items]``, spread over ``jobs`` processes (default: the cores),
    no more processes than there are ``min_items_per_core`` items for each.

    The processes claim the items one at a time, in order, as each becomes free (from a
    pipe of tokens they share): a child that waits for a core on a busy machine leaves
    its items to the parent, which only ever waits for the items a child has started.
    """
    items = list(items)
    reap(block=False)  # the children of earlier calls that have ended since
    jobs = cores() if jobs is None else max(1, int(jobs))
    jobs = min(jobs, len(items) // max(1, int(min_items_per_core)))
    if jobs <= 1 or not hasattr(os, "fork"):
        return [fn(x) for x in items]
    per = -(-len(items) // MAX_TOKENS)  # items a token claims: one, unless there are very many
    tokens = _tokens(-(-len(items) // per))
    children: list[tuple[int, int]] = []  # (pid, read end)
    try:
        for _ in range(1, jobs):
            read_end, write_end = os.pipe()
            pid = os.fork()
            if pid == 0:  # the child: never returns
                try:
                    os.close(read_end)
                    _child(write_end, lambda: _claimed(fn, items, tokens, per))
                finally:
                    os._exit(0)
            os.close(write_end)
            children.append((pid, read_end))
        done = dict(_claimed(fn, items, tokens, per))
        for j, (pid, read_end) in enumerate(children):
            children[j] = (pid, -1)  # _collect closes, reaps (and kills if need be)
            done.update(_collect(pid, read_end))
    finally:
        os.close(tokens)
        for pid, read_end in children:  # what is left: interrupted
            if read_end >= 0:
                _end(pid, functools.partial(os.close, read_end))
    if len(done) != len(items):
        raise RuntimeError(f"the worker processes of the solve returned {len(done)} results, not {len(items)}")
    return [done[i] for i in range(len(items))]


#: Bytes of one token of :func:`_tokens` (an index, little-endian).
_TOKEN = 4
#: Most tokens in one pipe, written before anyone reads: a pipe holds one page at least
#: (4 KiB; 64 KiB by default on Linux, one page when the user's pipes are many). A list
#: of more items is claimed in runs.
MAX_TOKENS = 4096 // _TOKEN


def _tokens(n: int) -> int:
    """The read end of a pipe holding the tokens 0, 1, ..., n - 1 and closed for writing:
    reading one claims it (reads of a pipe are whole, under its lock), an empty read
    means none is left. ``n`` is at most :data:`MAX_TOKENS`."""
    if not 0 <= n <= MAX_TOKENS:
        raise ValueError(f"fork_map: at most {MAX_TOKENS} tokens, not {n}")
    read_end, write_end = os.pipe()
    try:
        os.write(write_end, b"".join(i.to_bytes(_TOKEN, "little") for i in range(n)))
    finally:
        os.close(write_end)
    return read_end


def _claimed(fn: Callable[[T], R], items: Sequence[T], tokens: int, per: int = 1) -> list[tuple[int, R]]:
    """``(i, fn(items[i]))`` for each item this process claims (token k: the items
    ``k * per`` to ``(k + 1) * per - 1``), until none is left."""
    out = []
    while token := os.read(tokens, _TOKEN):
        k = int.from_bytes(token, "little")
        for i in range(k * per, min((k + 1) * per, len(items))):
            out.append((i, fn(items[i])))
    return out


def _child(write_end: int, call: Callable[[], object]) -> None:
    """A forked child's work: ``call()``'s value (for a :func:`fork_map` child, the items
    it claims with their results), or what went wrong, pickled to the pipe."""
    signal.signal(signal.SIGALRM, signal.SIG_DFL)  # the parent's alarm is the parent's
    with os.fdopen(write_end, "wb") as pipe:
        pipe.write(_pickled(_outcome(call)))


def _outcome(call: Callable[[], object]) -> tuple[str, object]:
    """A child's answer for ``call()``: ("ok", value), ("timeout", stage), ("error",
    exception) or, for an exception that cannot be pickled, ("failed", its text)."""
    try:
        return "ok", call()
    except TimeBudgetExceeded as exc:
        return "timeout", exc.where
    except BaseException as exc:  # raised again in the parent
        try:
            pickle.dumps(exc)
            return "error", exc
        except Exception:
            return "failed", f"{type(exc).__name__}: {exc}"


def _pickled(message: tuple[str, object]) -> bytes:
    try:
        return pickle.dumps(message)
    except Exception as exc:
        return pickle.dumps(("failed", f"its results cannot be pickled: {type(exc).__name__}: {exc}"))


def _answer(message: tuple[str, object], who: str) -> object:
    """The value of an :func:`_outcome` message, or its error raised here."""
    kind, payload = message
    if kind == "timeout":
        raise TimeBudgetExceeded(payload)  # type: ignore[arg-type]
    if kind == "error":
        raise payload  # type: ignore[misc]
    if kind == "failed":
        raise RuntimeError(f"{who} failed: {payload}")
    return payload


def _collect(pid: int, read_end: int) -> list[tuple[int, R]]:
    """Read a :func:`fork_map` child's pickled answer to the end, reap it (or leave it
    to :func:`reap` while it ends), return its results or raise."""
    payload = _answer_of(pid, read_end, "a worker process of the solve")
    assert isinstance(payload, list)
    return payload


def _answer_of(pid: int, read_end: int, who: str) -> object:
    """Read a child's pickled :func:`_outcome` to the end, reap the child (killed first
    if the read was interrupted), return its value or raise its error.

    A child that sent its whole answer is reaped later (:func:`reap`) if it has not
    exited yet: the end of a forked copy of a large process (its pages unmapped) takes
    15-20 ms here, which the caller need not wait for."""
    chunks = []
    done = False
    try:
        while chunk := os.read(read_end, 1 << 16):
            chunks.append(chunk)
        done = True
    finally:
        os.close(read_end)
        if not done:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        if done and chunks:
            _reap_later(pid)
        else:
            _, status = os.waitpid(pid, 0)
    if not chunks:
        raise RuntimeError(f"{who} died (wait status {status})")
    return _answer(pickle.loads(b"".join(chunks)), who)


#: Children that sent their whole answer and had not exited when it was read: reaped by
#: :func:`reap` (the solve at its end, the helper while it waits for a call).
_UNREAPED: list[int] = []


def _reap_later(pid: int) -> None:
    """Reap ``pid`` if it has exited, else leave it to :func:`reap`."""
    with contextlib.suppress(ChildProcessError):
        if os.waitpid(pid, os.WNOHANG)[0] == 0:
            _UNREAPED.append(pid)


def reap(block: bool = True) -> None:
    """Reap the children whose answers came before they exited (waiting for them with
    ``block``; they are ending: their answer is sent, their pipe closed)."""
    for pid in list(_UNREAPED):
        try:
            finished = os.waitpid(pid, 0 if block else os.WNOHANG)[0] != 0
        except ChildProcessError:  # reaped already
            finished = True
        if finished:
            _UNREAPED.remove(pid)


class Forked(Generic[R]):
    """``fn(*args)`` computed in a child forked now, while this process does something
    else; :meth:`result` waits for its value (its exception raised again here).

    The child inherits everything the parent has built and sends back only the pickled
    value. For work whose result is small and whose inputs are large, beside work of
    this process whose result is large (the setup's transitions beside the grasp
    graph's tables). Without ``os.fork``, or on one core, ``fn`` runs in :meth:`result`.
    :meth:`close` kills and reaps a child whose value is not wanted (after an exception
    in the parent); :meth:`result` closes it too when interrupted.
    """

    def __init__(self, fn: Callable[..., R], *args: object) -> None:
        self._call: tuple[Callable[..., R], tuple[object, ...]] | None = None
        self._pid, self._read_end = -1, -1
        reap(block=False)  # the children of earlier calls that have ended since
        if cores() < 2 or not hasattr(os, "fork"):
            self._call = (fn, args)
            return
        read_end, write_end = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: never returns
            try:
                os.close(read_end)
                _child(write_end, lambda: fn(*args))
            finally:
                os._exit(0)
        os.close(write_end)
        self._pid, self._read_end = pid, read_end

    @property
    def forked(self) -> bool:
        """Whether a child computes the value (else :meth:`result` will)."""
        return self._pid > 0

    def result(self) -> R:
        """The value of ``fn(*args)``: the child's (waited for), or computed now."""
        if self._call is not None:
            fn, args = self._call
            self._call = None
            return fn(*args)
        if self._pid <= 0:
            raise RuntimeError("Forked: the value was taken already, or the child closed")
        pid, read_end = self._pid, self._read_end
        self._pid, self._read_end = -1, -1
        return _answer_of(pid, read_end, "the solve's forked process")  # type: ignore[return-value]

    def close(self) -> None:
        """Kill and reap the child, if any (idempotent); its value is dropped."""
        self._call = None
        if self._pid <= 0:
            return
        pid, read_end = self._pid, self._read_end
        self._pid, self._read_end = -1, -1
        _end(pid, functools.partial(os.close, read_end))

    def __del__(self) -> None:  # a child nobody waited for is still reaped
        with contextlib.suppress(Exception):
            self.close()


class Helper:
    """One forked child that runs calls for its parent, one at a time, on the other core.

    The child is forked when the helper is made and inherits ``state`` (for the bottom
    tier: the world and the grasp set), which is never pickled: a call sends only its
    function (a module-level one, pickled by name) and its small arguments, and the
    child runs ``fn(state, *args)``. :meth:`submit` sends a call and returns at once;
    :meth:`result` waits for its answer (its exception raised again here). After a
    result interrupted by an exception (the budget's alarm), the helper is closed: its
    pipe may still hold the answer. :meth:`close` ends the child (it also ends when the
    parent's end of the pipe closes, the parent exiting included).
    """

    def __init__(self, state: object) -> None:
        from multiprocessing.connection import Pipe

        if not hasattr(os, "fork"):
            raise RuntimeError("no os.fork on this platform")
        mine, theirs = Pipe(duplex=True)
        pid = os.fork()
        if pid == 0:  # the child: never returns
            try:
                mine.close()
                _serve(theirs, state)
            finally:
                os._exit(0)
        theirs.close()
        self._conn = mine
        self._pid = pid
        self._pending = False

    @property
    def alive(self) -> bool:
        return self._pid > 0

    @property
    def idle(self) -> bool:
        """Alive, and no call pending: :meth:`submit` may be called."""
        return self.alive and not self._pending

    def submit(self, fn: Callable[..., R], *args: object) -> None:
        """Send ``fn(state, *args)`` to the child (one call at a time)."""
        if not self.alive or self._pending:
            raise RuntimeError("helper: closed, or a call is still pending")
        self._conn.send((fn, args))
        self._pending = True

    def answered(self) -> bool:
        """A call is pending and its answer has come (:meth:`result` will not wait)."""
        return self._pending and self.alive and self._conn.poll()

    def result(self) -> R:  # type: ignore[type-var]
        """The pending call's value (its exception raised again here)."""
        if not self._pending:
            raise RuntimeError("helper: no call pending")
        try:
            message = pickle.loads(self._conn.recv_bytes())
        except BaseException:
            self.close()  # interrupted (or the child died): its answer may still come
            raise
        self._pending = False
        return _answer(message, "the solve's helper process")  # type: ignore[return-value]

    def close(self) -> None:
        """End the child and reap it (idempotent). The budget's alarm is held off until
        it is done, so that a close in a ``finally`` always reaps the child."""
        if not self.alive:
            return
        pid, self._pid = self._pid, -1
        _end(pid, self._conn.close)

    def __del__(self) -> None:  # a helper nobody closed still ends its child
        with contextlib.suppress(Exception):
            self.close()


def _end(pid: int, close: Callable[[], None]) -> None:
    """Close this process's end of a child's pipe (``close``), kill the child and reap
    it, the budget's alarm held off meanwhile (so that an end in a ``finally`` always
    reaps the child)."""
    with _alarm_held():
        with contextlib.suppress(OSError):
            close()
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(pid, 0)


@contextlib.contextmanager
def _alarm_held() -> Iterator[None]:
    """SIGALRM blocked in the body (where the platform and thread allow it); one that
    came meanwhile is delivered when it ends."""
    can = hasattr(signal, "pthread_sigmask") and threading.current_thread() is threading.main_thread()
    if can:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGALRM})
    try:
        yield
    finally:
        if can:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGALRM})


def _serve(conn: object, state: object) -> None:
    """The helper child's loop: run each call received, send back its value or error.
    The children a call forked that were still ending when it took their answers are
    reaped while no call waits (:func:`reap`, looking every 2 ms): a call is never kept
    waiting for their end."""
    signal.signal(signal.SIGALRM, signal.SIG_DFL)
    while True:
        try:
            while _UNREAPED and not conn.poll(0.002):  # type: ignore[attr-defined]
                reap(block=False)
            fn, args = conn.recv()  # type: ignore[attr-defined]
        except (EOFError, OSError):
            return
        conn.send_bytes(_pickled(_outcome(lambda: fn(state, *args))))  # type: ignore[attr-defined]


def two_at_a_time(helper: Helper | None, items: Sequence[T], here: Callable[[T], R],
                  there: Callable[[T], tuple[Callable[..., R], tuple[object, ...]]]) -> list[R]:
    """``[here(x) for x in items]``, every second item computed by ``helper`` meanwhile
    (``there(x)`` is its call: a module-level function of the helper's state and its
    arguments), all of them in one call (:func:`two_halves` of the items one by one); all
    here without a helper. One round trip, and the two halves' times even out over the
    items (in pairs, each pair waits for its slower half). When ``here`` raises, the
    helper is closed rather than waited for (its answer is not wanted)."""
    return two_halves(helper, items, lambda part: [here(x) for x in part],
                      lambda part: (_each, ([there(x) for x in part],)))


def two_halves(helper: Helper | None, items: Sequence[T], here: Callable[[Sequence[T]], list[R]],
               there: Callable[[Sequence[T]], tuple[Callable[..., list[R]], tuple[object, ...]]]) -> list[R]:
    """``here(items)`` (a list, one value per item), the helper computing every second
    item meanwhile, all of them in one call (``there(items[1::2])``: a module-level
    function of the helper's state and its arguments, returning a list); all here without
    a helper. :func:`two_at_a_time` for work whose batch costs less than its items one
    by one (sweeps walked side by side). When ``here`` raises, the helper is closed rather
    than waited for."""
    if helper is None or len(items) < 2:
        return here(items)
    fn, args = there(items[1::2])
    helper.submit(fn, *args)
    try:
        mine = here(items[0::2])
    except BaseException:
        helper.close()
        raise
    theirs: list[R] = helper.result()
    out: list[R] = [None] * len(items)  # type: ignore[list-item]
    out[0::2], out[1::2] = mine, theirs
    return out


def _each(state: object, calls: list[tuple[Callable[..., R], tuple[object, ...]]]) -> list[R]:
    """The helper's half of :func:`two_at_a_time`: each call, in order."""
    return [fn(state, *args) for fn, args in calls]
