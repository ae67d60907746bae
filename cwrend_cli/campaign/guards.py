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
)


class NonFiniteRunError(CwrendError):
    """A run produced a non-finite state, estimate, control or metric."""


class RunTimeoutError(CwrendError):
    """A run exceeded its time limit (``output.run_timeout_s``)."""


def check_finite(result: RunResult) -> None:
    """Raise :class:`NonFiniteRunError` naming the first non-finite quantity of ``result``.

    Rows of measurement quantities (NIS, measurement, score) are NaN by
    design where there is no measurement and are not checked; the states,
    estimates, controls, covariance trace and the metrics must be finite.
    """
    for attr, label in _FINITE_ROWS:
        values = np.asarray(getattr(result, attr), dtype=float)
        if np.isfinite(values).all():  # the common case: one pass, no per-row arrays
            continue
        bad = ~np.isfinite(values.reshape(values.shape[0], -1)).all(axis=1)
        if bad.any():
            row = int(np.argmax(bad))
            raise NonFiniteRunError(
                f"non-finite {label} ({attr}) from t = {result.t_s[row]:g} s (step {row}, "
                f"{int(bad.sum())} of {bad.size} rows); check the covariances, errors and "
                "biases of the configuration"
            )
    for attr in ("miss_km", "delta_v_km_s"):
        if not math.isfinite(getattr(result, attr)):
            raise NonFiniteRunError(f"non-finite {attr}")


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
