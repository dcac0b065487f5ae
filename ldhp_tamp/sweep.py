"""Sweeps: many independent cells, each in a process of its own under a hard time limit,
on this machine or on a Dask cluster.

:func:`run_cells` is the executor that ``ldhp-tamp bench`` (:func:`ldhp_tamp.bench.run_all`)
and ``ldhp-tamp ablate`` share. A *cell* is any picklable value (a bench run, an ablation
cell); a :class:`CellTask` says how to run one, in the cell's own process, and how to
describe one that gave no result::

    task = CellTask(run=solve_run, failed=failed_row, preload=("ldhp_tamp.tamp",))
    rows = run_cells(specs, task, SweepOptions(executor="dask", jobs=2, hard_limit_s=70))

``task.run`` and ``task.failed`` must be module-level functions (they are pickled).
``task.failed(cell, failure, reason, wall_s)`` makes the result of a cell that raised, or
whose process died (:attr:`CellFailure.ERROR`), or that passed the hard limit
(:attr:`CellFailure.TIMEOUT`). The results come back in the order of the cells.

Executors (:data:`EXECUTORS`):

``local``
    At most ``jobs`` cells at once, each a fresh process forked from a forkserver that has
    imported ``task.preload`` once (a cell then pays no import time), in a process group
    of its own. :class:`concurrent.futures.ProcessPoolExecutor` is not used because it
    cannot stop one task: killing a pool worker breaks the pool and fails every pending
    task, and a task that hangs holds its worker forever.
``dask``
    One Dask task per cell (the ``distributed`` package, ``pip install 'ldhp-tamp[dask]'``)
    on a ``LocalCluster`` of ``jobs`` single-threaded worker processes made for the sweep
    and closed after it, or on the cluster of ``scheduler`` (``tcp://HOST:PORT``), whose
    workers decide how many cells run at once. The task, on its worker, runs the cell in a
    child process (``python -c`` importing this module; it pays the planner's import,
    about 0.6 s) in a session of its own, which it kills at the hard limit: a hung solve
    never holds a worker. The child kills itself when its worker dies (its stdin, a pipe
    from the worker, reaches end of file). A worker that dies while running a cell (Dask
    retries the task on another worker up to ``distributed.scheduler.allowed-failures``
    times) fails that cell only, as ``error`` with Dask's reason.

Isolation is the same in both: a cell's crash (``os._exit``, a signal, an exception) is
that cell's ``error``; a cell past ``hard_limit_s`` has its whole process group (an
engine's planner process included) terminated, SIGTERM then SIGKILL, and is a
``timeout``; the other cells go on.

Resuming is the callers' (they know their files): they pass only the cells still to run.
"""

from __future__ import annotations

import contextlib
import enum
import logging
import math
import multiprocessing
import multiprocessing.connection
import os
import pickle
import selectors
import signal
import subprocess
import sys
import threading
import time
import traceback
import uuid
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, TypeVar

from ldhp_tamp.errors import ExecutorError, InputError

__all__ = [
    "EXECUTORS",
    "CellFailure",
    "CellTask",
    "SweepOptions",
    "check_executor",
    "run_cells",
    "run_isolated",
]

log = logging.getLogger(__name__)

C = TypeVar("C")
R = TypeVar("R")

#: The executors :func:`run_cells` knows, by name (the CLI's ``--executor`` choices).
EXECUTORS: tuple[str, ...] = ("local", "dask")

#: Seconds a terminated cell process gets to clean up (SIGTERM) before it is killed (SIGKILL).
_TERM_WAIT_S = 2.0
#: Seconds to wait for a cell process to exit after it has sent its result.
_EXIT_WAIT_S = 10.0


class CellFailure(enum.Enum):
    """Why a cell has no result of its own."""

    ERROR = "error"
    """It raised, or its process (or the Dask worker running it) died."""
    TIMEOUT = "timeout"
    """It passed the hard limit; its process group was terminated."""


@dataclass(frozen=True)
class SweepOptions:
    """How to run the cells.

    Attributes
    ----------
    executor
        ``local`` or ``dask`` (:data:`EXECUTORS`).
    jobs
        Cells at once: local processes, or the workers of the ``LocalCluster``; ignored
        with ``scheduler`` (the cluster's workers decide).
    scheduler
        ``dask`` only: the address of a running Dask scheduler, ``tcp://HOST:PORT``;
        ``None`` makes a ``LocalCluster`` on this machine.
    hard_limit_s
        Seconds a cell may take, process start-up included; ``None``: no limit.

    Raises
    ------
    InputError
        On a value out of range (the message names the option).
    """

    executor: str = "local"
    jobs: int = 1
    scheduler: str | None = None
    hard_limit_s: float | None = None

    def __post_init__(self) -> None:
        check_executor(self.executor, self.scheduler)
        if self.jobs < 1:
            raise InputError(f"--jobs: need at least 1 worker, got {self.jobs}")
        if self.hard_limit_s is not None and not (math.isfinite(self.hard_limit_s) and self.hard_limit_s > 0):
            raise InputError(f"hard limit: must be a positive number of seconds, got {self.hard_limit_s}")


def check_executor(executor: str, scheduler: str | None) -> None:
    """Check ``--executor`` and ``--scheduler`` together.

    Raises
    ------
    InputError
        An unknown executor, a scheduler without ``--executor dask``, or a scheduler
        address without a protocol and a port (``tcp://HOST:PORT``).
    """
    if executor not in EXECUTORS:
        raise InputError(f"--executor: unknown executor {executor!r}; choose one of {', '.join(EXECUTORS)}")
    if scheduler is None:
        return
    if executor != "dask":
        raise InputError("--scheduler: a scheduler address needs --executor dask")
    proto, sep, rest = scheduler.partition("://")
    host, colon, port = rest.rpartition(":")
    if not (sep and proto and host and colon and port.isdigit()):
        raise InputError(f"--scheduler: expected an address like tcp://HOST:PORT, got {scheduler!r}")


@dataclass(frozen=True)
class CellTask(Generic[C, R]):
    """What to do with a cell. Every callable is a module-level function (pickled).

    Attributes
    ----------
    run
        ``run(cell) -> result``, in the cell's process. An exception is the cell's
        ``error`` (through ``failed``).
    failed
        ``failed(cell, failure, reason, wall_s) -> result``: the result of a cell that gave
        none of its own.
    with_wall
        ``with_wall(result, wall_s) -> result``, or ``None``: the result with the wall time
        the executor measured for the cell (process start-up included).
    preload
        Modules the local executor's forkserver imports once, before the first cell.
    name
        A label for process names and Dask task keys.
    """

    run: Callable[[C], R]
    failed: Callable[[C, CellFailure, str, float], R]
    with_wall: Callable[[R, float], R] | None = None
    preload: tuple[str, ...] = ()
    name: str = "cell"


# --------------------------------------------------------------------------- in the cell's process


def _run_cell(task: CellTask[C, R], cell: C) -> R:
    """Run one cell; an exception is its ``error`` result, naming where it was raised."""
    start = time.perf_counter()
    try:
        return task.run(cell)
    except Exception as exc:  # any failure of one cell is its result, not the sweep's end
        last = traceback.extract_tb(exc.__traceback__)[-1:]
        where = f" (at {Path(last[0].filename).name}:{last[0].lineno})" if last else ""
        return task.failed(cell, CellFailure.ERROR, f"{type(exc).__name__}: {exc}{where}",
                           time.perf_counter() - start)


def _on_sigterm(signum: int, _frame: Any) -> None:
    raise SystemExit(128 + signum)  # unwinds: temporary directories are removed


def _child(task: CellTask[C, R], cell: C, conn: multiprocessing.connection.Connection) -> None:
    """Body of a local cell process: one cell, one result sent back through ``conn``."""
    os.setpgid(0, 0)  # a process group of its own: the parent stops the engine's children too
    signal.signal(signal.SIGTERM, _on_sigterm)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    conn.send(_run_cell(task, cell))
    conn.close()


def _watch_parent() -> None:
    """In a Dask cell's process: wait for end of file on stdin (the worker holds the
    other end until the cell is over), then terminate this process group; the worker is
    gone and nobody would read the result. Reads the raw descriptor: a daemon thread
    must not hold the buffered reader's lock at the interpreter's shutdown."""
    with contextlib.suppress(OSError):
        while os.read(0, 1 << 12):
            pass
    with contextlib.suppress(OSError):
        os.killpg(0, signal.SIGTERM)
    time.sleep(_TERM_WAIT_S)
    with contextlib.suppress(OSError):
        os.killpg(0, signal.SIGKILL)


def _main() -> None:
    """Entry of a Dask cell's process (``python -c``): read the worker's ``sys.path``
    and then ``(task, cell)`` from stdin (pickled), run the cell, write the pickled
    result to the file descriptor given as the first argument."""
    fd = int(sys.argv[1])
    signal.signal(signal.SIGTERM, _on_sigterm)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stdin = sys.stdin.buffer
    path = pickle.load(stdin)
    sys.path[:] = [p for p in path if p not in sys.path] + sys.path  # the modules the worker sees
    task, cell = pickle.load(stdin)
    threading.Thread(target=_watch_parent, name="ldhp-sweep-watch", daemon=True).start()
    result = _run_cell(task, cell)
    with os.fdopen(fd, "wb") as out:
        pickle.dump(result, out, protocol=pickle.HIGHEST_PROTOCOL)


# --------------------------------------------------------------------------- local executor


@dataclass
class _Active:
    position: int
    cell: Any
    process: multiprocessing.process.BaseProcess
    conn: multiprocessing.connection.Connection
    start: float
    deadline: float | None


def _context(preload: Sequence[str]) -> multiprocessing.context.BaseContext:
    """A forkserver that has imported ``preload`` (a fork then costs no import time);
    ``spawn`` where there is no forkserver. Never plain ``fork``: the parent may hold
    threads and locks."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["ldhp_tamp.sweep", *preload])
        return ctx
    return multiprocessing.get_context("spawn")


def _start(ctx: multiprocessing.context.BaseContext, task: CellTask[Any, Any], position: int, cell: Any,
           hard_limit_s: float | None) -> _Active:
    reader, writer = ctx.Pipe(duplex=False)
    process = ctx.Process(target=_child, args=(task, cell, writer), name=f"ldhp-{task.name}-{position}")
    process.start()  # the first start waits for the forkserver's imports: not the cell's time
    start = time.monotonic()
    writer.close()  # the child holds the only write end: end of file when it dies
    deadline = None if hard_limit_s is None else start + hard_limit_s
    return _Active(position, cell, process, reader, start, deadline)


def _kill_group(pid: int | None, wait: Callable[[float], bool]) -> None:
    """Terminate the process group led by ``pid``: SIGTERM, then SIGKILL; ``wait(s)``
    waits up to ``s`` seconds for the leader and says whether it has exited. The group
    is killed once more after the leader exits (an engine's planner process may
    outlive it)."""
    for sig, wait_s in ((signal.SIGTERM, _TERM_WAIT_S), (signal.SIGKILL, _EXIT_WAIT_S)):
        if pid is None:
            break
        try:
            os.killpg(pid, sig)
        except (ProcessLookupError, PermissionError):
            # the child has not made its group yet (or is gone): signal it alone
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, sig)
        if wait(wait_s):
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(pid, signal.SIGKILL)
            break


def _stop(active: _Active) -> None:
    proc = active.process

    def wait(s: float) -> bool:
        proc.join(s)
        return proc.exitcode is not None

    _kill_group(proc.pid, wait)
    active.conn.close()


def _died(code: int | None) -> str:
    how = f"killed by signal {-code}" if code is not None and code < 0 else f"exit status {code}"
    return f"the cell's process died without a result ({how})"


def _collect(task: CellTask[Any, R], active: _Active) -> R:
    """The result of a child whose pipe is readable: its own, or an error if it died."""
    wall = time.monotonic() - active.start
    try:
        result: Any = active.conn.recv()
        got = True
    except (EOFError, OSError):
        got = False
    active.process.join(_EXIT_WAIT_S)
    if active.process.exitcode is None:
        log.warning("cell %d: the process did not exit after its result; stopping it", active.position)
        _stop(active)
    active.conn.close()
    if not got:
        return task.failed(active.cell, CellFailure.ERROR, _died(active.process.exitcode), wall)
    return result if task.with_wall is None else task.with_wall(result, wall)


def _timeout_reason(hard_limit_s: float) -> str:
    return f"hard limit: no result after {hard_limit_s:g} s; the cell's process was terminated"


def _run_local(cells: Sequence[C], task: CellTask[C, R], options: SweepOptions,
               on_result: Callable[[int, R], None]) -> None:
    ctx = _context(task.preload)
    pending = deque(enumerate(cells))
    active: list[_Active] = []
    hard = options.hard_limit_s
    try:
        while pending or active:
            while pending and len(active) < options.jobs:
                position, cell = pending.popleft()
                active.append(_start(ctx, task, position, cell, hard))
            deadlines = [a.deadline for a in active if a.deadline is not None]
            wait_s = max(0.0, min(deadlines) - time.monotonic()) if deadlines else None
            ready = multiprocessing.connection.wait([a.conn for a in active], timeout=wait_s)
            now = time.monotonic()
            for a in list(active):
                if a.conn in ready:
                    result = _collect(task, a)
                elif a.deadline is not None and hard is not None and now >= a.deadline:
                    _stop(a)
                    result = task.failed(a.cell, CellFailure.TIMEOUT, _timeout_reason(hard), now - a.start)
                else:
                    continue
                active.remove(a)
                on_result(a.position, result)
    finally:
        for a in active:
            _stop(a)


# --------------------------------------------------------------------------- dask executor

_CHILD_CODE = "from ldhp_tamp.sweep import _main; _main()"


def run_isolated(task: CellTask[C, R], cell: C, hard_limit_s: float | None) -> R:
    """Run one cell in a child process of its own session and wait for its result, at
    most ``hard_limit_s`` seconds (then its process group is terminated: a ``timeout``).
    The body of a Dask task; it never raises for what the cell does."""
    read_fd, write_fd = os.pipe()
    start = time.monotonic()
    try:
        proc = subprocess.Popen([sys.executable, "-c", _CHILD_CODE, str(write_fd)], stdin=subprocess.PIPE,
                                pass_fds=(write_fd,), start_new_session=True)
    except BaseException:
        os.close(read_fd)
        raise
    finally:
        os.close(write_fd)  # the child holds the only write end: end of file when it dies
    assert proc.stdin is not None
    chunks: list[bytes] = []
    timed_out = False
    ended = False  # the child closed its end: it is exiting
    try:
        proc.stdin.write(pickle.dumps(list(sys.path)))
        proc.stdin.write(pickle.dumps((task, cell), protocol=pickle.HIGHEST_PROTOCOL))
        proc.stdin.flush()  # stdin stays open: its end of file tells the child we are gone
        deadline = None if hard_limit_s is None else start + hard_limit_s
        with selectors.DefaultSelector() as sel:
            sel.register(read_fd, selectors.EVENT_READ)
            while True:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    timed_out = True
                    break
                if not sel.select(left):
                    continue
                data = os.read(read_fd, 1 << 16)
                if not data:
                    ended = True
                    break
                chunks.append(data)
    except BrokenPipeError:  # the child died before reading its cell
        ended = True
    finally:
        wall = time.monotonic() - start

        def wait(s: float) -> bool:
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(s)
            return proc.returncode is not None

        if not ended or not wait(_EXIT_WAIT_S):  # the limit, or an exception here (Ctrl-C)
            _kill_group(proc.pid, wait)
        else:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)  # what the cell left running
        with contextlib.suppress(OSError):
            proc.stdin.close()
        os.close(read_fd)
    if timed_out:
        assert hard_limit_s is not None
        return task.failed(cell, CellFailure.TIMEOUT, _timeout_reason(hard_limit_s), wall)
    try:
        result: R = pickle.loads(b"".join(chunks))
    except Exception:  # nothing (the process died), or a result cut short
        return task.failed(cell, CellFailure.ERROR, _died(proc.returncode), wall)
    return result if task.with_wall is None else task.with_wall(result, wall)


def _import_distributed() -> Any:
    """The ``distributed`` package; :class:`ExecutorError` if it is not installed."""
    chosen = logging.getLogger("distributed").level  # the application's choice, if any
    try:
        import distributed
    except ImportError as exc:
        raise ExecutorError(f"--executor dask needs the 'distributed' package ({exc}); install it with "
                            f"pip install 'ldhp-tamp[dask]'") from None
    if chosen != logging.NOTSET:  # the first import sets the level from dask's configuration
        logging.getLogger("distributed").setLevel(chosen)
    return distributed


@contextlib.contextmanager
def _dask_client(options: SweepOptions) -> Any:
    """A client of ``options.scheduler``, or of a ``LocalCluster`` of ``options.jobs``
    single-threaded worker processes, closed (workers and all) on exit."""
    distributed = _import_distributed()
    import dask

    Client, LocalCluster = distributed.Client, distributed.LocalCluster
    if options.scheduler is not None:
        try:
            client = Client(options.scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise ExecutorError(f"--scheduler {options.scheduler}: cannot connect to the Dask scheduler: "
                                f"{exc}") from None
        with client:
            yield client
        return
    # One cell per worker at a time: no cell waits in a busy worker's queue, and a worker
    # that dies takes only its running cell with it.
    with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
        # The scheduler's HTTP server on a free port (no dashboard): sweeps side by side
        # never compete for port 8787.
        with LocalCluster(n_workers=options.jobs, threads_per_worker=1, processes=True,
                          scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"}) as cluster, \
                Client(cluster) as client:
            yield client


def _run_dask(cells: Sequence[C], task: CellTask[C, R], options: SweepOptions,
              on_result: Callable[[int, R], None]) -> None:
    with _dask_client(options) as client:
        from distributed import as_completed

        workers = len(client.scheduler_info().get("workers", {}))
        where = options.scheduler or "a LocalCluster on this machine"
        log.info("dask: %d cells on %s (%d workers)", len(cells), where, workers)
        if workers == 0:
            log.warning("dask: the scheduler %s has no worker yet; the cells wait for one", where)
        token = uuid.uuid4().hex[:8]
        submitted = time.monotonic()
        futures = {client.submit(run_isolated, task, cell, options.hard_limit_s, pure=False,
                                 key=f"ldhp-{task.name}-{position}-{token}"): position
                   for position, cell in enumerate(cells)}
        try:
            for future in as_completed(futures):
                position = futures.pop(future)  # released: a result is never computed twice
                try:
                    result = future.result()
                except Exception as exc:  # KilledWorker, a lost scheduler, a cancelled task
                    first = str(exc).split(". ")[0]
                    result = task.failed(cells[position], CellFailure.ERROR,
                                         f"the Dask worker running the cell failed: {type(exc).__name__}: {first}",
                                         time.monotonic() - submitted)
                del future
                on_result(position, result)
        finally:
            client.cancel(list(futures), force=True)


# --------------------------------------------------------------------------- entry


def run_cells(cells: Sequence[C], task: CellTask[C, R], options: SweepOptions,
              on_result: Callable[[int, R], None] | None = None) -> list[R]:
    """Run every cell with ``options.executor``, each in a process of its own under
    ``options.hard_limit_s``; the results in the order of ``cells``.

    ``on_result(position, result)`` is called as each cell ends (``position``: the cell's
    index in ``cells``). On an exception (Ctrl-C) the running cells are stopped (the
    ``LocalCluster``, if one was made, is closed) before it propagates.

    Raises
    ------
    ExecutorError
        ``dask`` without the ``distributed`` package, or a scheduler that cannot be
        reached; nothing has run.
    """
    results: dict[int, R] = {}

    def done(position: int, result: R) -> None:
        results[position] = result
        if on_result is not None:
            on_result(position, result)

    if cells:
        (_run_dask if options.executor == "dask" else _run_local)(cells, task, options, done)
    return [results[i] for i in range(len(cells))]
