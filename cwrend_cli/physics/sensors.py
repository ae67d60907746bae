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

from cwrend_cli.physics import measurement_models as mm
from cwrend_cli.physics.params import FloatArray, Sensor, Window


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
    #: (N, 3) U[0, 1): component i of step k is an outlier when below p_o,i (issue 35
    #: item 3: the windows whose outlier_probability is given per component)
    outlier_axes: FloatArray | None = None


class FaultKinds(NamedTuple):
    """Which sensor faults some window switches on (each needs its own draws)."""

    dropout: bool
    outlier: bool  # a window with one outlier probability for every component
    drift: bool
    outlier_axes: bool = False  # a window with an outlier probability per component

    @property
    def any(self) -> bool:
        """True when at least one fault is on."""
        return self.dropout or self.outlier or self.drift or self.outlier_axes


def fault_kinds(windows: Sequence[Window]) -> FaultKinds:
    """The fault kinds ``windows`` use (an outlier scale alone, at probability 0, is off)."""
    outliers = [w for w in windows if w.has_outliers]
    return FaultKinds(
        dropout=any(w.dropout_probability > 0.0 for w in windows),
        outlier=any(not isinstance(w.outlier_probability, tuple) for w in outliers),
        drift=any(w.bias_drift_km_per_sqrt_s > 0.0 for w in windows),
        outlier_axes=any(isinstance(w.outlier_probability, tuple) for w in outliers),
    )


def _child(seq: np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """Child ``index`` of ``seq``, built explicitly (``spawn`` would depend on call history)."""
    return np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, index))


def draw_faults(
    seq: np.random.SeedSequence, n_steps: int, windows: Sequence[Window]
) -> FaultDraws | None:
    """The fault draws of ``n_steps`` steps from ``seq``; ``None`` when every fault is off.

    One PCG64 stream per kind, from child 0 (dropout), 1 (outlier), 2
    (drift) or 3 (per-component outliers) of ``seq`` (NumPy ``SeedSequence``
    spawn keys), drawn only for the kinds ``windows`` use: switching one kind
    on changes no other draw.
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
        outlier_axes=gen(3).random((n_steps, 3)) if kinds.outlier_axes else None,
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


class NoiseParts(NamedTuple):
    """The parts of each step's measurement error, before a sensor model combines them."""

    gaussian_scale: FloatArray  # (N, 3) c_k √r_scale_i: factor on component i's Gaussian noise
    bias_km: FloatArray  # (N, 3) the window's bias_km
    drift: FloatArray  # (N, 3) random-walk part of the bias [km]
    active: np.ndarray  # (N,) index of the window whose faults apply, −1 none
    dropout: np.ndarray  # (N,) bool: no measurement on that step
    outlier: np.ndarray  # (N,) bool: some component's Gaussian noise scaled by outlier_scale


def per_component(value: float | tuple[float, ...]) -> FloatArray:
    """A window's scalar-or-per-component value as 3 entries (a scalar: every one; a
    2-component value, of the angles sensor, padded with 1)."""
    out = np.ones(3)
    if isinstance(value, tuple):
        out[: len(value)] = value
    else:
        out[:] = value
    return out


def noise_parts(
    times_s: np.ndarray,
    windows: Sequence[Window],
    faults: FaultDraws | None = None,
    dt_s: float = 1.0,
) -> NoiseParts:
    """The window of each step, its covariance scale, bias, dropouts, outliers and drift.

    Row k uses the window at ``times_s[k]`` (the step's start, as in the
    authors' code; docs/method.md). Component i of step k's Gaussian noise is
    multiplied by ``c_k,i √r_scale_i`` with ``c_k,i = outlier_scale_i`` on an
    outlier and 1 otherwise. With one ``outlier_probability`` every component
    is an outlier together (``faults.outlier[k] < outlier_probability``);
    given per component, each is one on its own draw
    (``faults.outlier_axes[k, i] < outlier_probability_i``, issue 35 item 3).
    The bias random walk ``d`` is zero on the window's first active step,
    then ``d_{k+1} = d_k + q √Δt w_k`` over its active steps (``w`` from
    ``faults.drift``; held across steps where a later window overrides it,
    gone outside it). Step k drops out when ``faults.dropout[k] <
    dropout_probability`` (always for a probability of 1).
    ``faults`` may be ``None`` only when no window has a fault on.
    """
    active = active_windows(times_s, windows)
    n = times_s.shape[0]
    scale = np.ones((n, 3))
    bias = np.zeros((n, 3))
    kinds = fault_kinds(windows)
    draws = faults if faults is not None else FaultDraws(None, None, None)
    dropout = np.zeros(n, dtype=np.bool_)
    outlier = np.zeros(n, dtype=np.bool_)
    factor = np.ones((n, 3))
    drift = np.zeros((n, 3))
    for i, w in enumerate(windows):
        mask = active == i
        scale[mask] = per_component(w.r_scale)
        bias[mask] = np.asarray(w.bias_km, dtype=float)
        if kinds.dropout and w.dropout_probability > 0.0:
            dropout[mask] = _draws_of("dropout", draws.dropout)[mask] < w.dropout_probability
        if w.has_outliers:
            c = per_component(w.outlier_scale)
            if isinstance(w.outlier_probability, tuple):
                u = _draws_of("outlier_axes", draws.outlier_axes)
                hits = mask[:, None] & (u < per_component(w.outlier_probability)) & (c != 1.0)
            else:
                hit = mask & (_draws_of("outlier", draws.outlier) < w.outlier_probability)
                hits = hit[:, None] & (c != 1.0)
            outlier |= hits.any(axis=1)
            factor[hits] = np.broadcast_to(c, (n, 3))[hits]
        if kinds.drift and w.bias_drift_km_per_sqrt_s > 0.0:
            rows = np.flatnonzero(mask)
            if rows.size:
                step = w.bias_drift_km_per_sqrt_s * np.sqrt(dt_s)
                w_k = _draws_of("drift", draws.drift)[rows[1:]]
                walk = np.zeros((rows.size, 3))
                walk[1:] = np.cumsum(step * w_k, axis=0)
                drift[rows] = walk
    # chol(c R) = √c chol(R), and chol(D R D) = D chol(R) for a diagonal D = diag(√r_scale_i)
    outliers = kinds.outlier or kinds.outlier_axes
    gaussian_scale = np.sqrt(scale) * factor if outliers else np.sqrt(scale)
    return NoiseParts(gaussian_scale, bias, drift, active, dropout, outlier)


def sensor_noise(
    standard_normal: np.ndarray,
    times_s: np.ndarray,
    r_nominal: np.ndarray,
    windows: Sequence[Window],
    faults: FaultDraws | None = None,
    dt_s: float = 1.0,
) -> SensorNoise:
    """Noise, dropouts and outliers of the position sensor under ``windows`` and their faults.

    ``v_k = c_k D_k chol(R_nominal) n_k + bias + d_k`` with ``D_k = diag(√r_scale_i)``
    (``chol(r_scale R_nominal)`` for a scalar ``r_scale``) and the rest as
    :func:`noise_parts` describes.
    """
    parts = noise_parts(times_s, windows, faults, dt_s)
    chol_nominal = np.linalg.cholesky(r_nominal)
    noise = parts.gaussian_scale * (standard_normal @ chol_nominal.T) + parts.bias_km
    if fault_kinds(windows).drift:
        noise = noise + parts.drift
    return SensorNoise(noise, parts.active, parts.dropout, parts.outlier, parts.drift)


def sensor_model(
    sensor: Sensor,
    standard_normal: np.ndarray,
    times_s: np.ndarray,
    windows: Sequence[Window],
    faults: FaultDraws | None = None,
    dt_s: float = 1.0,
) -> tuple[mm.SensorModel, NoiseParts]:
    """The nonlinear sensor of a run (``range_bearing``, ``angles``) and its noise parts.

    Each existing window field maps into the measurement space: ``r_scale``
    (each component's) scales that component's variance; an outlier
    multiplies the step's Gaussian noise (every component) by
    ``outlier_scale``; ``bias_km`` and its drift offset the position the
    sensor sees (``y = h(r + b + d) + …``: the sensor ranges and points at a
    spot displaced by ``b + d`` from the target); ``bias_range_km`` and
    ``bias_angles_deg`` are biases in the measurement's own units; a dropout
    removes the whole measurement. Component i of the Gaussian noise is
    ``gaussian_scale[k, i] n[k, i]`` in units of its σ
    (:func:`cwrend_cli.physics.measurement_models.sigmas`, which the compiled
    loop evaluates at the true range).
    """
    parts = noise_parts(times_s, windows, faults, dt_s)
    kind = mm.KINDS[sensor.model]
    active = parts.active
    bias = np.zeros((times_s.shape[0], 3))
    for i, w in enumerate(windows):
        angles = np.deg2rad(np.asarray(w.bias_angles_deg, dtype=float))
        bias[active == i] = (
            (w.bias_range_km, *angles) if kind == mm.RANGE_BEARING else (*angles, 0.0)
        )
    model = mm.SensorModel(
        kind=kind,
        sigma_range_km=sensor.sigma_range_km,
        range_fraction=sensor.sigma_range_fraction,
        sigma_angle_rad=float(np.deg2rad(sensor.sigma_angle_deg)),
        unit_noise=parts.gaussian_scale * standard_normal,
        offset_km=parts.bias_km + parts.drift,
        bias=bias,
    )
    return model, parts


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
