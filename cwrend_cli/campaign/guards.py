"""What makes a run a failed run although it did not raise: non-finite results and time limits.

A run *fails* when the simulation raises, returns non-finite numbers or
exceeds its time limit; such a run is a result (recorded ``failed`` with the
reason, rerun by ``--retry-failed``), unlike an infrastructure fault, which is
retried (:mod:`cwrend_cli.campaign.driver`, issue 21). Both checks run around
the pure simulation, in the worker, never inside it.
"""

from __future__ import annotations

import ctypes
import math
import signal
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from types import FrameType
from typing import Protocol

import numpy as np
from numba.core import event as numba_event

from cwrend_cli.errors import CwrendError
from cwrend_cli.physics import metrics
from cwrend_cli.physics.params import Problem
from cwrend_cli.physics.simulation import RunResult

__all__ = [
    "NonFiniteRunError",
    "RunTimeoutError",
    "check_finite",
    "resolves",
    "run_cost_s",
    "run_timeout_s",
    "time_limit",
]

#: Quantities of a :class:`RunResult` that must be finite in every row, with their names.
_FINITE_ROWS = (
    ("x_true", "true state"),
    ("x_hat", "estimate"),
    ("u", "applied control"),
    ("u_cmd", "commanded control"),
    ("trace_p", "covariance trace"),
    ("nees", "NEES"),  # every row has an estimate and a covariance (NaN: P not definite)
    ("eps", "homotopy parameter"),
)
#: Quantities of the measurement of a row: NaN by design on a row without one (row 0,
#: a dropout; the filtered score before the first measurement), finite on every other.
_MEASURED_ROWS = (
    ("y", "measurement"),
    ("nis", "NIS"),
    ("mtf_ratio", "MTF ratio"),
    ("score", "score"),
    ("score_filtered", "filtered score"),
)


class NonFiniteRunError(CwrendError):
    """A run produced a non-finite state, estimate, control or metric."""


class RunTimeoutError(CwrendError):
    """A run exceeded its time limit (``output.run_timeout_s``)."""


def _first_bad_row(result: RunResult, attr: str, label: str, bad: np.ndarray) -> None:
    """Raise :class:`NonFiniteRunError` for the rows ``bad`` of ``attr``, if any."""
    if bad.any():
        row = int(np.argmax(bad))
        raise NonFiniteRunError(
            f"non-finite {label} ({attr}) from t = {result.t_s[row]:g} s (step {row}, "
            f"{int(bad.sum())} of {bad.size} rows); check the covariances, errors and "
            "biases of the configuration"
        )


def check_finite(result: RunResult) -> None:
    """Raise :class:`NonFiniteRunError` naming the first non-finite quantity of ``result``.

    The states, estimates, controls, covariance trace, NEES and ε must be
    finite in every row. The quantities of a row's measurement (measurement,
    NIS, MTF ratio, scores) are NaN by design on a row without one (row 0, a
    dropout) and must be finite on every row with one; none may be infinite.
    The logged metrics must be finite: Δv, miss, mean NEES, and the mean
    nominal NIS, which is NaN by design only when no row outside the
    degradation windows has a measurement (:func:`metrics.mean_nis_nominal`).
    """
    for attr, label in _FINITE_ROWS:
        values = np.asarray(getattr(result, attr), dtype=float)
        if np.isfinite(values).all():  # the common case: one pass, no per-row arrays
            continue
        _first_bad_row(
            result, attr, label, ~np.isfinite(values.reshape(values.shape[0], -1)).all(axis=1)
        )
    measured: np.ndarray | None = None
    for attr, label in _MEASURED_ROWS:
        values = np.asarray(getattr(result, attr), dtype=float)
        if attr == "y" and result.sensor == "angles":
            values = values[:, :2]  # two components (issue 35): the third is NaN by design
        if np.isfinite(values[1:]).all():  # the common case: only row 0 is NaN
            continue
        if measured is None:
            measured = ~np.asarray(result.dropout, dtype=bool)
            measured[0] = False
        rows = values.reshape(values.shape[0], -1)
        _first_bad_row(
            result,
            attr,
            label,
            np.isinf(rows).any(axis=1) | (measured & np.isnan(rows).any(axis=1)),
        )
    for attr in ("miss_km", "delta_v_km_s"):
        if not math.isfinite(getattr(result, attr)):
            raise NonFiniteRunError(f"non-finite {attr}")
    with np.errstate(over="ignore"):  # an overflowing mean is reported here, not warned
        mean_nees = metrics.mean_nees(result.nees)
        mean_nis = metrics.mean_nis_nominal(result.nis, result.window)
    if not math.isfinite(mean_nees):
        raise NonFiniteRunError("non-finite mean_nees (the NEES rows overflow their mean)")
    if math.isinf(mean_nis):
        raise NonFiniteRunError("non-finite mean_nis_nominal (the NIS rows overflow their mean)")


#: What a re-solve costs at most per step of the horizon it solves over [s]. Measured on a
#: 2-core AMD EPYC (2026-12-02): fixed-ε shooting at T = 8,000 s (its fallback chain to
#: Clarabel at most re-solves) 197-300 s for 800 re-solves over 4,000 steps on average,
#: 62-94 µs; cone programs (socp) at 800 / 3,200 steps 29 / 41 µs; adaptive shooting
#: 0.2-2 µs.
RESOLVE_STEP_COST_S = 100e-6
#: The same for a constrained re-solve (``[constraints]``: sequential convex programming,
#: a sparse Clarabel program per iteration) [s]. Measured on a 2-core Intel Xeon
#: (Sapphire Rapids, 2026-12-02): campaigns/safe_approach.toml's mtf_adaptive_socp run,
#: 79 re-solves in 17-18 s, 213 ms mean (670 ms max) over 400 steps on average: 0.53 ms a
#: step; twice that, so the limit stays a few times the cost on a machine twice as slow.
#: Kept after the program's matrix was assembled at once (5× faster re-solves): on the
#: 2-core AMD EPYC loaded about 4× by other processes, 296-331 ms mean over the loops of
#: seeds 0-19 (benchmarks/bench_constrained.py), 0.74-0.83 ms a step, so a lower value
#: would leave a loaded machine's runs less than twice their cost.
CONSTRAINED_RESOLVE_STEP_COST_S = 1e-3
#: The same with abort safety (``constraints.abort_safe_s``: drift rows, answers checked
#: chord by chord, programs solved again) [s]. Measured on the 2-core AMD EPYC shared with
#: six other agents (2026-12-02), campaigns/safe_approach.toml with abort_safe_s = 5,400:
#: mtf_fixed_socp 2.2 s mean a re-solve, mtf_adaptive_socp 0.94 s, over 400 steps on
#: average: 5.5 and 2.4 ms a step; a plain_fixed_socp run under a heavier load took more
#: than 700 s (over 22 ms a step), so the limit is set for that: 20 ms, three times over.
ABORT_RESOLVE_STEP_COST_S = 2e-2
#: A run's default limit is this multiple of its cost (:func:`run_cost_s`) ...
COST_MULTIPLE = 3.0
#: ... plus this [s] (a worker's pauses: the machine's other processes, the file writes).
RUN_BASE_S = 10.0
#: Added to the default limit of a process's first run of an architecture [s]: loading
#: its numba kernels, or compiling them on a fresh install (30-40 s on 2 cores), is not
#: the run's cost.
FIRST_RUN_ALLOWANCE_S = 120.0


def resolves(problem: Problem) -> int:
    """Re-solves of a run of ``problem``: every ``t_resolve_s`` until ``t_min_rem_s`` is left."""
    span = problem.scenario.horizon_s - problem.guidance.t_min_rem_s
    return max(math.ceil(span / problem.guidance.t_resolve_s), 0) + 1


def run_cost_s(n_steps: int, n_resolves: int, per_step_s: float = RESOLVE_STEP_COST_S) -> float:
    """What a run should cost at most [s]: each of its ``n_resolves`` re-solves over the
    remaining horizon (half of the ``n_steps`` on average) at ``per_step_s`` a step
    (:data:`RESOLVE_STEP_COST_S`, or :data:`CONSTRAINED_RESOLVE_STEP_COST_S` with
    ``[constraints]``, :data:`ABORT_RESOLVE_STEP_COST_S` with abort safety)."""
    return per_step_s * n_steps * n_resolves / 2


def run_timeout_s(configured: float | None, problem: Problem, *, first: bool = False) -> float:
    """A run's wall-time limit [s]: ``output.run_timeout_s``, else a small multiple of its cost.

    Default: :data:`RUN_BASE_S` + :data:`COST_MULTIPLE` × :func:`run_cost_s`, and
    :data:`FIRST_RUN_ALLOWANCE_S` more for the ``first`` run of an architecture in
    a process. The paper's run (800 steps, 79 re-solves): 19.5 s (129.5 s the first),
    where it takes 5-100 ms and about 1 s with a cone program at every re-solve; with
    ``[constraints]`` (campaigns/safe_approach.toml, 17-18 s a cone-program run) 104.8 s; a
    20,000-step run (1,999 re-solves): 6,007 s (10,060 s before). The open-loop references of a grid
    point get the limit of its runs (issue 36, item 13).
    """
    if configured is not None:
        return configured
    per_step = (
        RESOLVE_STEP_COST_S if problem.constraints is None else CONSTRAINED_RESOLVE_STEP_COST_S
    )
    if problem.constraints is not None and problem.constraints.abort_safe_s is not None:
        per_step = ABORT_RESOLVE_STEP_COST_S
    cost = run_cost_s(problem.scenario.n_steps, resolves(problem), per_step)
    return RUN_BASE_S + COST_MULTIPLE * cost + (FIRST_RUN_ALLOWANCE_S if first else 0.0)


@contextmanager
def time_limit(seconds: float | None) -> Iterator[None]:
    """Raise :class:`RunTimeoutError` in the ``with`` block after ``seconds`` of wall time.

    In a process's main thread (the local pool's workers, ``--workers 1``) with
    ``SIGALRM`` (Unix); in any other thread (a Dask worker runs its tasks in
    threads, where no signal arrives) a timer thread raises it in the block's
    thread (:class:`_ThreadAlarm`). Either way it is raised where the block
    runs Python code: the compiled step loop returns to Python at every
    re-solve. ``seconds = None``: the block runs unlimited.

    Time numba spends loading or compiling a kernel inside the block does not
    count: the clock stops while numba holds its compiler lock, which it takes
    to load a kernel from its cache as well as to compile one
    (:class:`_CompilePause`). A kernel first met in the middle of a campaign (a
    fallback of the re-solve chain, a variant of the loop) costs 10-15 CPU s on
    a fresh install, loading the references' kernels from the cache about 1.5 s;
    the run's own cost is what its limit is for (a run of a sweep timed out that
    way on a loaded machine).

    The timeout is never raised where Python would swallow it (llvmlite's ctypes
    callbacks, a ``__del__``: "Exception ignored", a traceback on stderr and the
    run going on unlimited): there it waits for the block to leave such code
    (:func:`_swallowing`), so even a limit of a millisecond gives a clean
    "timed out".
    """
    if seconds is None:
        yield
        return
    message = f"timed out: the run took longer than {seconds:g} s"
    if (
        not hasattr(signal, "setitimer")
        or threading.current_thread() is not threading.main_thread()
    ):
        alarm = _ThreadAlarm(seconds)
        try:
            with _paused_by_numba(_CompilePause(alarm)):
                yield
        except _ExpiredError:
            raise RunTimeoutError(message) from None
        finally:
            alarm.stop()
        return

    pause = _CompilePause(_SignalAlarm())

    def expire(signum: int, frame: FrameType | None) -> None:
        if pause.depth > 0 or _swallowing(frame):  # not now: again once out of there
            signal.setitimer(signal.ITIMER_REAL, _RETRY_S)
            return
        raise RunTimeoutError(message)

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        with _paused_by_numba(pause):
            yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


#: numba's events during which the clock of :func:`time_limit` stops: its compiler lock
#: (held to load a kernel from the cache, to compile one, and waited for while another
#: thread does) and its compiles.
_NUMBA_PAUSE_EVENTS = ("numba:compiler_lock", "numba:compile")
#: How soon a timeout that could not be raised where the block was is tried again [s].
_RETRY_S = 1e-3
#: Where an exception raised is swallowed: the ctypes callbacks of llvmlite (numba's
#: code generator) call Python from C and print, not raise, what escapes them.
_SWALLOWING_PACKAGE = "llvmlite"


@contextmanager
def _paused_by_numba(pause: _CompilePause) -> Iterator[None]:
    """``pause`` listens to numba's :data:`_NUMBA_PAUSE_EVENTS` in the ``with`` block."""
    with ExitStack() as stack:
        for kind in _NUMBA_PAUSE_EVENTS:
            stack.enter_context(numba_event.install_listener(kind, pause))
        yield


def _swallowing(frame: FrameType | None) -> bool:
    """Whether an exception raised in ``frame`` would be swallowed on its way out.

    Python prints ("Exception ignored ...") rather than raises what escapes a
    ``__del__`` or a callback called from C through ctypes (llvmlite's, while
    numba loads or finalises a kernel), and the code around goes on as if
    nothing happened.
    """
    while frame is not None:
        code = frame.f_code
        if code.co_name == "__del__" or _SWALLOWING_PACKAGE in Path(code.co_filename).parts:
            return True
        frame = frame.f_back
    return False


class _ExpiredError(RunTimeoutError):
    """What :class:`_ThreadAlarm` raises in the block's thread (a class without arguments:
    :func:`time_limit` raises the :class:`RunTimeoutError` with its limit instead)."""

    def __init__(self) -> None:
        super().__init__("timed out: the run took longer than its limit")


class _SignalAlarm:
    """The ``ITIMER_REAL`` clock of :func:`time_limit` in a main thread: stopped, then set
    again with the time it had left."""

    def __init__(self) -> None:
        self.left_s = 0.0

    def pause(self) -> None:
        self.left_s = signal.setitimer(signal.ITIMER_REAL, 0.0)[0]

    def resume(self) -> None:
        if self.left_s > 0.0:
            signal.setitimer(signal.ITIMER_REAL, self.left_s)


class _ThreadAlarm:
    """The clock of :func:`time_limit` outside a main thread: a :class:`threading.Timer`
    that raises :class:`_ExpiredError` in the thread that made it, once, while the block runs.

    ``PyThreadState_SetAsyncExc`` (the C API's asynchronous exception) raises it at the
    next Python instruction that thread runs, unless the thread is where it would be
    swallowed (:func:`_swallowing`): then the timer tries again shortly. :meth:`stop`
    withdraws one set but not yet raised, so nothing is raised after the block. A lock
    orders the timer's firing with :meth:`pause`, :meth:`resume` and :meth:`stop`.
    """

    def __init__(self, seconds: float) -> None:
        self._thread = threading.get_ident()
        self._lock = threading.Lock()
        self._left_s = seconds
        self._timer: threading.Timer | None = None
        self._started = 0.0
        self._live = True  # the block runs
        self._fired = False
        self._start()

    def _start(self) -> None:
        self._started = time.monotonic()
        self._timer = threading.Timer(max(self._left_s, 0.0), self._fire, (self._started,))
        self._timer.daemon = True
        self._timer.start()

    def _fire(self, started: float) -> None:
        with self._lock:
            if (
                self._live
                and not self._fired
                and self._timer is not None
                and started == self._started
            ):
                if _swallowing(sys._current_frames().get(self._thread)):
                    self._left_s = _RETRY_S  # not there: again once out of it
                    self._start()
                    return
                self._fired = True
                _set_async_exc(self._thread, _ExpiredError)

    def pause(self) -> None:
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
                self._left_s -= time.monotonic() - self._started

    def resume(self) -> None:
        with self._lock:
            if self._live and not self._fired and self._timer is None:
                self._start()

    def stop(self) -> None:
        with self._lock:
            self._live = False
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            if self._fired:  # raised already, or withdrawn now
                _set_async_exc(self._thread, None)


def _set_async_exc(thread: int, exc: type[BaseException] | None) -> None:
    """Raise ``exc`` in the thread ``thread`` (an ident) at its next Python instruction;
    ``None`` withdraws one set but not yet raised."""
    target = ctypes.py_object(exc) if exc is not None else None
    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(thread), target)


class _Alarm(Protocol):
    def pause(self) -> None: ...

    def resume(self) -> None: ...


class _CompilePause(numba_event.Listener):
    """Stops the clock of :func:`time_limit` while numba loads or compiles a kernel.

    numba announces each acquisition of its compiler lock (to load a kernel from its
    cache, to compile one) as a ``numba:compiler_lock`` event, each compile as a
    ``numba:compile`` event, nested for the kernels a kernel calls; the clock is
    stopped at the outermost start and set again, with the time it had left,
    at the outermost end.

    The listener is process-wide (numba's events are): on a Dask worker running
    tasks in threads, one thread's compile stops every thread's clock. Kept so on
    purpose, as it only lengthens a limit: numba compiles under a process-wide
    lock (``numba.core.compiler_lock``) that another thread meeting any kernel
    waits for, and the compile holds the GIL; a per-thread pause would count
    the GIL's share of that wait against the waiting run
    (docs/guide/integrity.md, "Time limits").
    """

    def __init__(self, alarm: _Alarm) -> None:
        self.depth = 0
        self.alarm = alarm

    def on_start(self, event: numba_event.Event) -> None:
        if self.depth == 0:
            self.alarm.pause()
        self.depth += 1

    def on_end(self, event: numba_event.Event) -> None:
        self.depth -= 1
        if self.depth == 0:
            self.alarm.resume()
