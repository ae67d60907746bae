"""Measurement noise: degradation windows and standard-normal streams (v_k of paper Eq. 13).

No file I/O here: an external realisation is read by :mod:`cwrend_cli.config.io`.

The truth is measured as ``y = H x + chol(R_true) n + b`` where ``n`` is one
standard-normal 3-vector per step, shared by every architecture of a seed
(fair comparison; a convention of cwrend, not in the paper), and
``R_true = r_scale · R_nominal`` and the bias ``b`` come from the degradation
window active at the step's start time.

Sensor faults (issue 15, item 3; :class:`~cwrend_cli.physics.params.Window`)
compose with these: a dropout removes the step's measurement (the filter
predicts only), an outlier multiplies the Gaussian part ``chol(R_true) n``
by the window's ``outlier_scale`` (a contaminated Gaussian, Huber 1964,
"Robust estimation of a location parameter", Ann. Math. Statist. 35), and a
drifting bias adds a random walk ``d`` to ``b`` (a Wiener process sampled at
the steps, Maybeck 1979, *Stochastic Models, Estimation and Control* vol. 1,
§4.3). Their random draws (:class:`FaultDraws`) are made by the caller, one
stream per fault kind, only for the kinds some window switches on; with
every fault off the noise is computed exactly as before they existed.
Units: km, km², s.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from cwrend_cli.physics.params import FloatArray, Window


def in_window(times_s: np.ndarray, window: Window) -> np.ndarray:
    """True where ``window`` is active: ``start_s ≤ t ≤ end_s`` (both ends included)."""
    return (times_s >= window.start_s) & (times_s <= window.end_s)


def active_windows(times_s: np.ndarray, windows: Sequence[Window]) -> np.ndarray:
    """Index of the window active at each time (−1 for none).

    A window is active on ``start_s ≤ t ≤ end_s``; where windows overlap the
    later one in the list applies (so the paper's ``[250, 325)`` then
    ``[325, 400]`` is written as two windows sharing t = 325).
    """
    idx = np.full(times_s.shape, -1, dtype=np.int64)
    for i, w in enumerate(windows):
        idx[in_window(times_s, w)] = i
    return idx


class FaultDraws(NamedTuple):
    """The random draws of a run's sensor faults; ``None`` for a kind no window uses."""

    dropout: FloatArray | None  # (N,) U[0, 1): step k drops out when below p_d
    outlier: FloatArray | None  # (N,) U[0, 1): step k is an outlier when below p_o
    drift: FloatArray | None  # (N, 3) N(0, 1): the bias random walk's increments


class FaultKinds(NamedTuple):
    """Which sensor faults some window switches on (each needs its own draws)."""

    dropout: bool
    outlier: bool
    drift: bool

    @property
    def any(self) -> bool:
        """True when at least one fault is on."""
        return self.dropout or self.outlier or self.drift


def fault_kinds(windows: Sequence[Window]) -> FaultKinds:
    """The fault kinds ``windows`` use (an outlier scale alone, at probability 0, is off)."""
    return FaultKinds(
        dropout=any(w.dropout_probability > 0.0 for w in windows),
        outlier=any(w.outlier_probability > 0.0 and w.outlier_scale != 1.0 for w in windows),
        drift=any(w.bias_drift_km_per_sqrt_s > 0.0 for w in windows),
    )


def _child(seq: np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """Child ``index`` of ``seq``, built explicitly (``spawn`` would depend on call history)."""
    return np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, index))


def draw_faults(
    seq: np.random.SeedSequence, n_steps: int, windows: Sequence[Window]
) -> FaultDraws | None:
    """The fault draws of ``n_steps`` steps from ``seq``; ``None`` when every fault is off.

    One PCG64 stream per kind, from child 0 (dropout), 1 (outlier) or 2
    (drift) of ``seq`` (NumPy ``SeedSequence`` spawn keys), drawn only for
    the kinds ``windows`` use: switching one kind on changes no other draw.
    """
    kinds = fault_kinds(windows)
    if not kinds.any:
        return None

    def gen(index: int) -> np.random.Generator:
        return np.random.Generator(np.random.PCG64(_child(seq, index)))

    return FaultDraws(
        dropout=gen(0).random(n_steps) if kinds.dropout else None,
        outlier=gen(1).random(n_steps) if kinds.outlier else None,
        drift=gen(2).standard_normal((n_steps, 3)) if kinds.drift else None,
    )


class SensorNoise(NamedTuple):
    """What the measurements of a run receive, one row per step k (the measurement at t_{k+1})."""

    noise: FloatArray  # (N, 3) noise added to the true position [km]
    active: np.ndarray  # (N,) index of the window whose faults apply, −1 none
    dropout: np.ndarray  # (N,) bool: no measurement on that step
    outlier: np.ndarray  # (N,) bool: the step's Gaussian noise scaled by outlier_scale
    drift: FloatArray  # (N, 3) random-walk part of the bias [km]


def _draws_of(kind: str, values: FloatArray | None) -> FloatArray:
    if values is None:
        raise ValueError(f"a degradation window sets a {kind} fault but no {kind} draws were given")
    return values


def sensor_noise(
    standard_normal: np.ndarray,
    times_s: np.ndarray,
    r_nominal: np.ndarray,
    windows: Sequence[Window],
    faults: FaultDraws | None = None,
    dt_s: float = 1.0,
) -> SensorNoise:
    """Noise, dropouts and outliers of each step under ``windows`` and their faults.

    Row k uses the window at ``times_s[k]`` (the step's start, as in the
    authors' code; docs/method.md): ``v_k = c_k chol(r_scale R_nominal) n_k + bias + d_k``
    with ``c_k = outlier_scale`` on an outlier step (``faults.outlier[k] <
    outlier_probability``) and 1 otherwise, and ``d`` the window's bias
    random walk: zero on its first active step, then
    ``d_{k+1} = d_k + q √Δt w_k`` over its active steps (``w`` from
    ``faults.drift``; held across steps where a later window overrides it,
    gone outside it). Step k drops out when ``faults.dropout[k] <
    dropout_probability`` (always for a probability of 1).
    ``faults`` may be ``None`` only when no window has a fault on.
    """
    active = active_windows(times_s, windows)
    chol_nominal = np.linalg.cholesky(r_nominal)
    n = times_s.shape[0]
    scale = np.ones(times_s.shape)
    bias = np.zeros((n, 3))
    kinds = fault_kinds(windows)
    draws = faults if faults is not None else FaultDraws(None, None, None)
    dropout = np.zeros(n, dtype=np.bool_)
    outlier = np.zeros(n, dtype=np.bool_)
    factor = np.ones(n)
    drift = np.zeros((n, 3))
    for i, w in enumerate(windows):
        mask = active == i
        scale[mask] = w.r_scale
        bias[mask] = np.asarray(w.bias_km, dtype=float)
        if kinds.dropout and w.dropout_probability > 0.0:
            dropout[mask] = _draws_of("dropout", draws.dropout)[mask] < w.dropout_probability
        if kinds.outlier and w.outlier_probability > 0.0 and w.outlier_scale != 1.0:
            hit = mask & (_draws_of("outlier", draws.outlier) < w.outlier_probability)
            outlier[hit] = True
            factor[hit] = w.outlier_scale
        if kinds.drift and w.bias_drift_km_per_sqrt_s > 0.0:
            rows = np.flatnonzero(mask)
            if rows.size:
                step = w.bias_drift_km_per_sqrt_s * np.sqrt(dt_s)
                w_k = _draws_of("drift", draws.drift)[rows[1:]]
                walk = np.zeros((rows.size, 3))
                walk[1:] = np.cumsum(step * w_k, axis=0)
                drift[rows] = walk
    # chol(c R) = √c chol(R)
    gaussian_scale = np.sqrt(scale) if not kinds.outlier else np.sqrt(scale) * factor
    noise = gaussian_scale[:, None] * (standard_normal @ chol_nominal.T) + bias
    if kinds.drift:
        noise = noise + drift
    return SensorNoise(noise, active, dropout, outlier, drift)


def measurement_noise(
    standard_normal: np.ndarray,
    times_s: np.ndarray,
    r_nominal: np.ndarray,
    windows: Sequence[Window],
) -> tuple[np.ndarray, np.ndarray]:
    """Noise added to each measurement (N, 3) [km] and the active window index (N,).

    Row k uses the window at ``times_s[k]`` (the step's start, the authors' code):
    ``v_k = chol(r_scale R_nominal) n_k + bias`` (:func:`sensor_noise`
    without faults).
    """
    out = sensor_noise(standard_normal, times_s, r_nominal, windows)
    return out.noise, out.active


def standard_normal_stream(seed: np.random.SeedSequence | int, n_steps: int) -> np.ndarray:
    """One standard-normal realisation (n_steps, 3) from a ``SeedSequence``-keyed PCG64 stream."""
    seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    return np.random.Generator(np.random.PCG64(seq)).standard_normal((n_steps, 3))
