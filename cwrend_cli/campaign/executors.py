"""Where campaign tasks run: one interface, a ``concurrent.futures.Executor``.

* ``local`` (default): a process pool over the machine's cores (spawn start
  method; Ctrl-C makes a worker stop its task and return the runs it
  finished, the parent stops the campaign);
  ``workers = 1`` runs in-process.
* ``dask``: a Dask distributed cluster through ``Client.get_executor()``; a
  ``LocalCluster`` when no address is given. Dask workers must see the
  campaign's output directory (a shared filesystem), since each task writes
  its own Parquet files.

No scheduling logic lives here: the campaign driver submits tasks and
collects them as they complete, whatever executor it was given.

**Per-run signals** (issue 17: a progress bar that advances per run, not per
task of up to 16 seeds). :func:`run_signals` gives the driver a
:class:`RunSignals` for its executor: ``signal(token)`` is what the driver
hands a task (:func:`~cwrend_cli.campaign.worker.execute_task` calls it with
``True``/``False`` after each run), ``poll()`` delivers the signals that
arrived to the driver's listener. The local pool carries them on one
``multiprocessing`` queue that each worker inherits at start (a pipe write
of a few bytes per run, about 10 µs, beside runs of 5–90 ms); in-process
(``--workers 1``) the listener is called at once. A **Dask** cluster keeps
per-task granularity: its workers may be on other machines, which a local
queue does not reach, and a Dask queue or pub/sub would cost a scheduler
round trip per run; the driver then counts a task's runs when it completes.
Signals are only progress: the journal records a task when it comes back
(after Ctrl-C with the runs it finished, :func:`ask_workers_to_stop`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing.context import BaseContext, SpawnContext, SpawnProcess
from multiprocessing.queues import Queue
from types import FrameType
from typing import Literal, ParamSpec, Protocol, TypeVar
from urllib.parse import urlsplit

from cwrend_cli.campaign.worker import stop_task
from cwrend_cli.errors import ConfigError
from cwrend_cli.physics.compiled import tune_for_compiling
from cwrend_cli.teardown import STOP_SIGNALS, end_without_teardown, unraisable_stop

ExecutorKind = Literal["local", "dask"]

#: How long reaching a Dask scheduler may take before the campaign is refused [s].
DASK_CONNECT_TIMEOUT_S = 5.0
#: Address schemes of a Dask scheduler reached over TCP.
_TCP_SCHEMES = ("tcp", "tls")

_T = TypeVar("_T")
_P = ParamSpec("_P")


class InlineExecutor(Executor):
    """Runs each submitted call at once in this process (``--workers 1``)."""

    def submit(self, fn: Callable[_P, _T], /, *args: _P.args, **kwargs: _P.kwargs) -> Future[_T]:
        future: Future[_T] = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as exc:
            if isinstance(exc, KeyboardInterrupt):
                raise
            future.set_exception(exc)
        return future


#: This pool worker's end of the per-run signal queue (set by :func:`_worker_init`).
_RUN_QUEUE: Queue[tuple[int, bool]] | None = None


#: Signals a pool worker turns into a stop of its task (:func:`worker.stop_task`), not its end:
#: the terminal sends Ctrl-C (and a hang-up) to the whole process group, a batch scheduler
#: its time limit's SIGTERM to every process of the job (Slurm), and the driver forwards a
#: stop to its workers (:func:`ask_workers_to_stop`); the parent decides the rest. Each
#: worker returns the runs it finished; the driver ends workers with SIGKILL
#: (:func:`_terminate_workers`), the pool its idle ones with its sentinel.
WORKER_STOP_SIGNALS = STOP_SIGNALS


def _stop_task(signum: int, frame: FrameType | None) -> None:
    stop_task(signum)


@contextmanager
def _stop_signals_blocked() -> Iterator[None]:
    """Block :data:`WORKER_STOP_SIGNALS` in this thread while it starts worker processes.

    A process inherits the blocked mask, so a Ctrl-C while a worker is still
    importing (before its initializer installs :func:`_stop_task`) stays
    pending in the worker instead of raising ``KeyboardInterrupt`` there and
    printing its traceback (issue 36 item 12); the initializer unblocks it.
    Here, a Ctrl-C that arrived meanwhile is delivered on leaving the block.
    (Python's own resource tracker starts the same way.)
    """
    signal.pthread_sigmask(signal.SIG_BLOCK, WORKER_STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, WORKER_STOP_SIGNALS)


def _worker_init(runs: Queue[tuple[int, bool]] | None = None) -> None:
    """Pool workers stop their task on Ctrl-C or SIGTERM (the parent stops the campaign),
    exit if the parent dies.

    Ctrl-C, SIGTERM and SIGHUP (:data:`WORKER_STOP_SIGNALS`, blocked from the
    worker's start by :func:`_stop_signals_blocked`) stop the task running,
    which returns its finished runs (:func:`worker.stop_task`); they never
    print a traceback, and a stop swallowed by compiled code is raised again
    (:func:`cwrend_cli.teardown.unraisable_stop`).

    They end without the interpreter's teardown (:mod:`cwrend_cli.teardown`:
    0.5–0.6 s of every campaign's end, which waits for its workers to exit).

    ``runs`` is the pool's per-run signal queue; a worker never waits on it
    at exit (``cancel_join_thread``), so a sibling killed while writing to it
    cannot hold up the others.
    """
    global _RUN_QUEUE
    tune_for_compiling()  # a worker's first task may compile the kernels
    for signum in WORKER_STOP_SIGNALS:
        signal.signal(signum, _stop_task)
    sys.unraisablehook = unraisable_stop
    signal.pthread_sigmask(signal.SIG_UNBLOCK, WORKER_STOP_SIGNALS)
    if runs is not None:
        runs.cancel_join_thread()
        _RUN_QUEUE = runs
    parent = os.getppid()

    def watch() -> None:
        while True:
            time.sleep(1.0)
            if os.getppid() != parent:  # orphaned: the campaign was killed
                os._exit(1)

    threading.Thread(target=watch, name="cwrend-parent-watch", daemon=True).start()
    end_without_teardown(lambda: 0)


class _PoolWorkerProcess(SpawnProcess):
    """A pool worker that its pool's ``terminate()`` ends for sure (SIGKILL).

    A ``ProcessPoolExecutor`` one of whose workers dies fails every future
    it holds, then ends the other workers with ``terminate()`` (SIGTERM) and
    waits for them and for its call queue's feeder thread. A cwrend worker
    turns SIGTERM into a stop of its task (:func:`_worker_init`: a batch
    scheduler's time limit keeps the finished runs), so a survivor went on
    waiting for work, on the call queue's read lock its dead sibling held,
    while the feeder waited for room in the pipe only the survivor could
    read: the pool's shutdown, and the campaign, waited for ever (CI, a
    worker killed with ``kill -9`` while it waited for work). Ending the
    survivors loses nothing: their futures have already failed, and the
    driver submits those tasks again to a fresh pool and removes what the
    survivors wrote (:func:`cwrend_cli.campaign.journal.remove_orphan_files`).
    Only the pool calls ``terminate()``; a stop of the campaign sends the
    workers signals of its own (:func:`ask_workers_to_stop`, :func:`_terminate_workers`).
    """

    def terminate(self) -> None:
        self.kill()


class _PoolContext(SpawnContext):
    """The spawn start method, with workers a broken pool ends (:class:`_PoolWorkerProcess`)."""

    Process = _PoolWorkerProcess


def _quiet_dask_logs() -> None:
    """Silence Dask's loggers below CRITICAL in this process.

    cwrend reports a lost scheduler or worker itself (exit 3, the manifest):
    Dask's own log lines with tracebacks would only bury that message.
    Importing distributed applies its logging configuration, which sets some
    child loggers explicitly (``tornado.application`` at ERROR, so the
    ``tornado`` level alone does not reach it: a lost-scheduler test once
    printed a tornado traceback); so every existing ``distributed.*`` /
    ``tornado.*`` logger is set, and ``asyncio``, whose "exception was never
    retrieved" reports of the abandoned connections carry tracebacks too.
    """
    names = [
        name
        for name in logging.root.manager.loggerDict
        if name.split(".")[0] in ("distributed", "tornado")
    ]
    for name in ("distributed", "tornado", "asyncio", *names):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def _terminate_workers(pool: ProcessPoolExecutor) -> None:
    """End a pool's worker processes now (SIGKILL: the stop signals only stop their task).

    What their running tasks wrote is unjournaled and removed on resume
    (:func:`cwrend_cli.campaign.journal.remove_orphan_files`).
    """
    for process in list((pool._processes or {}).values()):
        process.kill()


def ask_workers_to_stop(executor: Executor) -> None:
    """Ask the workers of a local pool to stop their tasks, keeping their finished runs.

    Each gets SIGINT (:func:`worker.stop_task`): its task returns at once
    (:class:`~cwrend_cli.campaign.worker.TaskInterrupted`) with the runs it
    finished. In-process and on Dask nothing is sent: an in-process task has
    the Ctrl-C already, a Dask task runs to its end or is lost.
    """
    if not isinstance(executor, ProcessPoolExecutor):
        return
    for process in list((executor._processes or {}).values()):
        with contextlib.suppress(OSError):  # it has just exited
            if process.pid is not None:
                os.kill(process.pid, signal.SIGINT)


def _started() -> None:
    """Nothing: submitting it makes the pool start a worker process."""


def default_workers() -> int:
    """All cores available to this process."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


#: How long a Dask client may be without its scheduler before its tasks count as lost [s].
DASK_LOST_AFTER_S = 20.0


def executor_alive(executor: Executor) -> bool:
    """Whether ``executor`` can still deliver results (a Dask client still has its scheduler).

    A local pool reports its breakage through its futures; a Dask client
    that lost its scheduler may instead keep reconnecting while its futures
    wait forever, so the driver asks this when nothing completes.
    """
    client = getattr(executor, "_client", None)  # distributed.cfexecutor.ClientExecutor
    return client is None or getattr(client, "status", "running") == "running"


def executor_broken(executor: Executor) -> bool:
    """Whether ``executor`` is a local pool that broke and has ended: it delivers nothing more.

    A pool one of whose workers died fails the futures it holds and ends its
    management thread. Python's pool marks itself broken without the lock
    its ``submit`` holds, so a task submitted in that instant gets a future
    nothing will ever complete (seen: a campaign waiting for ever after a
    worker was killed, the driver submitting as the pool broke). The driver
    asks this when nothing completes and counts such futures lost.
    """
    if not getattr(executor, "_broken", False):
        return False
    manager = getattr(executor, "_executor_manager_thread", None)
    return manager is None or not manager.is_alive()


def executor_workers(executor: Executor) -> int | None:
    """Workers a Dask executor's cluster has; ``None`` for other executors or when unknown.

    What the client last heard from its scheduler (``n_workers``, refreshed by
    the client every 2 s: no round trip, so a lost scheduler cannot block
    here). A cluster whose workers all died keeps its tasks waiting for ever:
    the driver stops after ``output.dask_no_worker_timeout_s`` at 0 (issue 36).
    """
    client = getattr(executor, "_client", None)  # distributed.cfexecutor.ClientExecutor
    identity = getattr(client, "_scheduler_identity", None)
    count = identity.get("n_workers") if isinstance(identity, dict) else None
    return count if isinstance(count, int) else None


def check_address(address: str, timeout_s: float = DASK_CONNECT_TIMEOUT_S) -> None:
    """Refuse a malformed or unreachable Dask scheduler address (:class:`ConfigError`, exit 2).

    ``tcp://host:port``, ``tls://host:port`` or ``host:port``; the scheduler
    must accept a TCP connection within ``timeout_s``. Called before a
    campaign writes anything, so a wrong address leaves no directory behind.
    """
    text = address if "://" in address else f"tcp://{address}"
    fix = "give the scheduler as tcp://host:port (e.g. tcp://127.0.0.1:8786)"
    try:
        parts = urlsplit(text)
        host, port = parts.hostname, parts.port
    except ValueError:
        host = port = None
        parts = None
    if parts is None or parts.scheme not in _TCP_SCHEMES or not host or port is None:
        raise ConfigError(f"--address {address!r}: not a Dask scheduler address; {fix}")
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as exc:
        reason = "timed out" if isinstance(exc, TimeoutError) else str(exc)
        raise ConfigError(
            f"--address {address}: cannot reach the Dask scheduler within {timeout_s:g} s "
            f"({reason}); is it running?"
        ) from None


class _SignallingPool(ProcessPoolExecutor):
    """A process pool of ``workers`` spawned workers that signal each finished run on ``runs``."""

    def __init__(self, runs: Queue[tuple[int, bool]], workers: int, context: BaseContext) -> None:
        super().__init__(
            max_workers=workers, mp_context=context, initializer=_worker_init, initargs=(runs,)
        )
        self.runs = runs


#: Called by the driver for each finished run: (token of the task execution, run ok).
RunListener = Callable[[int, bool], None]
#: Called by a task after each run: whether it was ok.
RunSignal = Callable[[bool], None]


class RunSignals(Protocol):
    """Per-run signals from the tasks of one executor to the driver (see the module)."""

    def signal(self, token: int) -> RunSignal | None:
        """What to hand the task execution ``token`` (``None``: it reports per task)."""

    def poll(self) -> None:
        """Deliver the signals that arrived to the listener (never blocks)."""


@dataclass(frozen=True)
class _QueuedSignal:
    """A task's signal in a pool worker: the token and the worker's queue (picklable)."""

    token: int

    def __call__(self, ok: bool) -> None:
        if _RUN_QUEUE is not None:  # else not in a pool worker: the task reports when it ends
            _RUN_QUEUE.put_nowait((self.token, ok))


class _QueueSignals:
    """The local pool's signals: put by the workers, delivered by :meth:`poll`."""

    def __init__(self, runs: Queue[tuple[int, bool]], listener: RunListener) -> None:
        self._runs = runs
        self._listener = listener

    def signal(self, token: int) -> RunSignal | None:
        return _QueuedSignal(token)

    def poll(self) -> None:
        while True:
            try:
                token, ok = self._runs.get_nowait()
            except (queue.Empty, OSError, ValueError, EOFError):  # empty, or closed
                return
            self._listener(token, ok)


class _DirectSignals:
    """In-process tasks (``--workers 1``): the listener hears each run at once."""

    def __init__(self, listener: RunListener) -> None:
        self._listener = listener

    def signal(self, token: int) -> RunSignal | None:
        return lambda ok: self._listener(token, ok)

    def poll(self) -> None:
        pass


class _NoSignals:
    """An executor whose tasks report per task (Dask, see the module)."""

    def signal(self, token: int) -> RunSignal | None:
        return None

    def poll(self) -> None:
        pass


def run_signals(executor: Executor, listener: RunListener) -> RunSignals:
    """The per-run signals of ``executor`` (opened by :func:`open_executor`) for ``listener``."""
    if isinstance(executor, InlineExecutor):
        return _DirectSignals(listener)
    if isinstance(executor, _SignallingPool):
        return _QueueSignals(executor.runs, listener)
    return _NoSignals()


@contextmanager
def helper_process() -> Iterator[ProcessPoolExecutor]:
    """One spawned process that works beside an in-process campaign, shut down on leaving.

    For a first run's compile when the campaign has one task (it runs
    in-process, ``--workers`` not 1: issue 37 item 12,
    :func:`cwrend_cli.campaign.driver._compile_first_run`). Started as a pool's
    workers are (:func:`_stop_signals_blocked`, :func:`_worker_init`: a Ctrl-C
    prints no traceback there) and terminated when the campaign stops.
    """
    context = _PoolContext()
    with _stop_signals_blocked():
        pool = ProcessPoolExecutor(max_workers=1, mp_context=context, initializer=_worker_init)
        pool.submit(_started)  # start it now, while the campaign process prepares
    try:
        yield pool
    except BaseException:
        _terminate_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


@contextmanager
def open_executor(
    kind: ExecutorKind = "local", workers: int | None = None, address: str | None = None
) -> Iterator[tuple[Executor, int]]:
    """Yield ``(executor, parallelism)`` and shut it down afterwards."""
    n = workers or default_workers()
    if kind == "local":
        if n == 1:
            yield InlineExecutor(), 1
            return
        context = _PoolContext()
        # the workers and multiprocessing's resource tracker start with the stop signals
        # blocked: the tracker, started by the queue's first semaphore, ignores SIGINT and
        # SIGTERM itself, not SIGHUP; starting, it unblocks SIGINT and SIGTERM here, hence
        # two blocks
        with _stop_signals_blocked():
            runs: Queue[tuple[int, bool]] = context.Queue()
        with _stop_signals_blocked():
            pool = _SignallingPool(runs, n, context)
            for _ in range(n):  # start the workers now, while the driver prepares the first tasks
                pool.submit(_started)
        try:
            yield pool, n
        except BaseException:  # Ctrl-C or a stop: the running tasks are abandoned, not awaited
            _terminate_workers(pool)
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
            runs.close()
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise ConfigError(
            "--executor dask needs Dask distributed: pip install 'cwrend[dask]'"
        ) from None
    _quiet_dask_logs()
    cluster = None
    if address:
        try:
            client = Client(address, timeout=f"{DASK_CONNECT_TIMEOUT_S:g}s")  # type: ignore[no-untyped-call]
        except Exception as exc:  # refused, timed out, or not a Dask scheduler at all
            raise ConfigError(
                f"--address {address}: cannot open a Dask client to the scheduler "
                f"({type(exc).__name__}: {exc})"
            ) from None
    else:
        cluster = LocalCluster(  # type: ignore[no-untyped-call]
            n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)  # type: ignore[no-untyped-call]
    try:
        parallelism = sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values())
        yield client.get_executor(pure=False), max(parallelism, 1)  # type: ignore[no-untyped-call]
    finally:
        client.close(timeout=DASK_CONNECT_TIMEOUT_S)  # type: ignore[no-untyped-call]
        if cluster is not None:
            cluster.close()
