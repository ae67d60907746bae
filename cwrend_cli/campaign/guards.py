"""What makes a run a failed run although it did not raise: non-finite results and time limits.

A run *fails* when the simulation raises, returns non-finite numbers or
exceeds its time limit; such a run is a result (recorded ``failed`` with the
reason, rerun by ``--retry-failed``), unlike an infrastructure fault, which is
retried (:mod:`cwrend_cli.campaign.driver`, issue 21). Both checks run around
the pure simulation, in the worker, never inside it.
"""

from __future__ import annotations

import math
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

import numpy as np

from cwrend_cli.errors import CwrendError
from cwrend_cli.physics import metrics
from cwrend_cli.physics.simulation import RunResult

__all__ = [
    "NonFiniteRunError",
    "RunTimeoutError",
    "check_finite",
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


def run_timeout_s(configured: float | None, n_steps: int) -> float:
    """A run's wall-time limit [s]: ``output.run_timeout_s``, else 60 s + 0.5 s per step.

    The default is generous: a paper run (800 steps) takes 5–100 ms on 2 cores,
    about 1 s with every fallback of the shooting chain at every re-solve.
    """
    return configured if configured is not None else 60.0 + 0.5 * n_steps


@contextmanager
def time_limit(seconds: float | None) -> Iterator[None]:
    """Raise :class:`RunTimeoutError` in the ``with`` block after ``seconds`` of wall time.

    Uses ``SIGALRM`` (Unix), so it acts only in a process's main thread (the
    local pool's workers and ``--workers 1``); elsewhere (Dask worker threads)
    and for ``seconds = None`` the block runs unlimited. The compiled step
    loop returns to Python at every re-solve, where the alarm is delivered.
    """
    usable = (
        seconds is not None
        and hasattr(signal, "setitimer")
        and threading.current_thread() is threading.main_thread()
    )
    if not usable or seconds is None:
        yield
        return

    def expire(signum: int, frame: FrameType | None) -> None:
        raise RunTimeoutError(f"timed out: the run took longer than {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
