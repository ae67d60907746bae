"""Measurement models of the chaser's sensor and their extended Kalman update (issue 35).

Three models of what the chaser measures (``[sensor] model``), each a pure
function ``h`` of the relative position ``r = x[:3]`` (the chaser relative to
the target, frame x radial, y along-track, z cross-track) with its analytic
Jacobian ``∂h/∂r`` (the velocity columns of ``H = ∂h/∂x`` are zero):

* ``position`` (:data:`POSITION`, m = 3): ``h(x) = r`` [km], ``H = [I₃ 0]``
  (paper Eq. 13, the paper's sensor).
* ``range_bearing`` (:data:`RANGE_BEARING`, m = 3): range ρ [km], azimuth α
  and elevation δ [rad] of the target seen from the chaser, i.e. of the
  line of sight ``d = −r``::

      ρ = ‖d‖ ≥ 0,   α = atan2(d_z, d_y) ∈ (−π, π],   δ = atan2(d_x, √(d_y² + d_z²)) ∈ [−π/2, π/2]

  the chaser's local-horizontal angles: α in the local horizontal plane
  (y–z, perpendicular to the radial x) from +y (along-track) towards +z
  (cross-track), δ above that plane towards +x (radial, up). Their pole is
  the radial axis (the target straight above or below the chaser), away
  from the paper's approach (from 31 km cross-track: α ≈ −90°, δ ≈ 0°).
  α is undefined on the radial axis (d_y = d_z = 0) and every angle at
  ρ = 0; the denominators there are floored at :data:`RANGE_FLOOR_KM`.
* ``angles`` (:data:`ANGLES`, m = 2): (α, δ) only (a camera).

The measurement noise is diagonal in the measurement space:
``σ_ρ = sigma_range_km + range_fraction · ρ`` [km] (a constant plus a
fraction of the range) and ``σ_α = σ_δ = sigma_angle_rad`` [rad].

The update (:func:`ekf_update`) is the extended Kalman filter's (Gelb 1974,
*Applied Optimal Estimation*, Table 6.1-1): paper Eqs. 14–23 with ``H`` the
Jacobian at the prediction and the innovation ``ν = y − h(x⁻)``, its angle
components wrapped to (−π, π] (:func:`wrap_angle`). MTF is applied in the
measurement space exactly as paper Eqs. 16–18 define it: the positive
diagonal excess of ``ννᵀ`` over ``S`` is added to ``R`` component by
component, and ``ρ_MTF = tr(S_MTF)/tr(S)`` (Eq. 23; for ``range_bearing`` the
trace sums km² and rad², as the paper's formula does for any measurement).
Units: km, km/s, rad.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cwrend_cli.physics.estimation import (
    GAIN_REGULARISATION,
    MTF,
    STF,
    _inverse_spd3,
    _sandwich,
    mtf_inflation,
    stf_inflation,
)

#: Model codes (``SensorModel.kind``).
POSITION = 0
RANGE_BEARING = 1
ANGLES = 2
#: Code of each ``[sensor] model`` name.
KINDS = {"position": POSITION, "range_bearing": RANGE_BEARING, "angles": ANGLES}
#: Floor of the range and of its projection on the x–y plane in the angles'
#: denominators [km] (1 nm: a convention of cwrend, far below any sensor's resolution).
RANGE_FLOOR_KM = 1e-12


class SensorModel(NamedTuple):
    """A nonlinear sensor as the compiled loop takes it (one row per step k).

    The measurement of step k is ``y = h(r + offset_km[k]) + σ(ρ) ∘ unit_noise[k]
    + bias[k]`` (:func:`measure_truth`), ``ρ = ‖r + offset_km[k]‖``.
    """

    kind: int  # RANGE_BEARING or ANGLES
    sigma_range_km: float  # constant part of σ_ρ [km]
    range_fraction: float  # σ_ρ grows by this fraction of the range [-]
    sigma_angle_rad: float  # σ of each angle [rad]
    unit_noise: np.ndarray  # (N, 3) the step's noise in units of σ (√r_scale and outliers in)
    offset_km: np.ndarray  # (N, 3) position offset the sensor sees (bias_km + its drift) [km]
    bias: np.ndarray  # (N, 3) bias in the measurement's units [km, rad] (unused entries 0)


@njit(cache=True)
def dimension(kind: int) -> int:
    """Measurement dimension m of a model (3, or 2 for angles)."""
    return 2 if kind == ANGLES else 3


@njit(cache=True)
def wrap_angle(a: float) -> float:
    """``a`` wrapped to (−π, π] [rad]: the short way round."""
    return float(a - 2.0 * np.pi * np.ceil((a - np.pi) / (2.0 * np.pi)))


@njit(cache=True)
def measure(kind: int, r: np.ndarray) -> np.ndarray:
    """``h(x)`` of model ``kind`` at the relative position ``r`` (3,) [km]: (m,) [km, rad]."""
    if kind == POSITION:
        return r[:3].copy()
    up, along, cross = -r[0], -r[1], -r[2]  # the line of sight d = −r
    az = np.arctan2(cross, along)
    el = np.arctan2(up, np.sqrt(along * along + cross * cross))
    if kind == ANGLES:
        out = np.empty(2)
        out[0] = az
        out[1] = el
        return out
    out = np.empty(3)
    out[0] = np.sqrt(up * up + along * along + cross * cross)
    out[1] = az
    out[2] = el
    return out


@njit(cache=True)
def jacobian(kind: int, r: np.ndarray) -> np.ndarray:
    """``∂h/∂r`` (m, 3) of model ``kind`` at ``r`` [km]; ``∂h/∂v`` is zero.

    With ``h² = r_y² + r_z²`` (the horizontal part) and ``ρ² = h² + r_x²``:
    ``∂ρ/∂r = r/ρ``, ``∂α/∂r = (0, −r_z, r_y)/h²``,
    ``∂δ/∂r = (−h², r_x r_y, r_x r_z)/(ρ² h)``.
    """
    if kind == POSITION:
        return np.eye(3)
    rx, ry, rz = r[0], r[1], r[2]
    h2 = max(ry * ry + rz * rz, RANGE_FLOOR_KM * RANGE_FLOOR_KM)
    hor = np.sqrt(h2)
    rho2 = h2 + rx * rx
    m = dimension(kind)
    out = np.zeros((m, 3))
    a = m - 2  # row of the azimuth
    if kind == RANGE_BEARING:
        rho = np.sqrt(rho2)
        out[0, 0] = rx / rho
        out[0, 1] = ry / rho
        out[0, 2] = rz / rho
    out[a, 1] = -rz / h2
    out[a, 2] = ry / h2
    out[a + 1, 0] = -hor / rho2
    out[a + 1, 1] = rx * ry / (rho2 * hor)
    out[a + 1, 2] = rx * rz / (rho2 * hor)
    return out


def line_of_sight(kind: int, y: np.ndarray) -> np.ndarray:
    """The line of sight of measurements ``y`` (n, ≥ m) of a nonlinear sensor: (n, 3).

    ``ρ (sin δ, cos δ cos α, cos δ sin α)`` (the inverse of :func:`measure`:
    ``d = −r``) with the measured range for ``RANGE_BEARING`` and a unit
    vector for ``ANGLES`` (no range measured). NaN rows stay NaN. Plain
    numpy, for drawing.
    """
    a = 1 if kind == RANGE_BEARING else 0
    az, el = y[:, a], y[:, a + 1]
    unit = np.stack([np.sin(el), np.cos(el) * np.cos(az), np.cos(el) * np.sin(az)], axis=1)
    return unit * y[:, :1] if kind == RANGE_BEARING else unit


@njit(cache=True)
def is_angle(kind: int, i: int) -> bool:
    """True when component ``i`` of model ``kind`` is an angle (wrapped residual)."""
    return kind == ANGLES or (kind == RANGE_BEARING and i > 0)


@njit(cache=True)
def sigmas(
    kind: int, rho_km: float, sigma_range_km: float, fraction: float, sigma_angle_rad: float
) -> np.ndarray:
    """The σ of each component (m,) at range ``rho_km``: ``(σ_ρ, σ_a, σ_a)`` or ``(σ_a, σ_a)``."""
    m = dimension(kind)
    out = np.full(m, sigma_angle_rad)
    if kind == RANGE_BEARING:
        out[0] = sigma_range_km + fraction * rho_km
    return out


@njit(cache=True)
def measure_truth(sensor: SensorModel, k: int, x: np.ndarray) -> np.ndarray:
    """The measurement of step k of the true state ``x``: (3,), NaN past the dimension m.

    ``y = h(r') + σ(‖r'‖) ∘ unit_noise[k] + bias[k]`` with ``r' = x[:3] + offset_km[k]``;
    the azimuth is reported in (−π, π].
    """
    r = x[:3] + sensor.offset_km[k]
    h = measure(sensor.kind, r)
    rho = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    sig = sigmas(sensor.kind, rho, sensor.sigma_range_km, sensor.range_fraction,
                 sensor.sigma_angle_rad)  # fmt: skip
    y = np.full(3, np.nan)
    for i in range(h.shape[0]):
        y[i] = h[i] + sig[i] * sensor.unit_noise[k, i] + sensor.bias[k, i]
    a = dimension(sensor.kind) - 2  # the azimuth
    y[a] = wrap_angle(y[a])
    return y


@njit(cache=True)
def _inverse_spd(s: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive-definite 2×2 or 3×3 matrix."""
    if s.shape[0] == 3:
        return _inverse_spd3(s)
    det = s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]
    inv = np.empty((2, 2))
    inv[0, 0] = s[1, 1] / det
    inv[1, 1] = s[0, 0] / det
    inv[0, 1] = -s[0, 1] / det
    inv[1, 0] = inv[0, 1]
    return inv


@njit(cache=True)
def ekf_update(
    kind: int,
    x_pred: np.ndarray,
    p_pred: np.ndarray,
    y: np.ndarray,
    r_nominal: np.ndarray,
    estimator: int,
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Extended Kalman measurement update with optional MTF inflation (paper Eqs. 14–23).

    ``y`` holds the m components of the measurement first; ``r_nominal`` is
    the (m, m) nominal covariance; ``estimator`` a kind of
    :func:`~cwrend_cli.physics.estimation.kf_update` (plain, MTF or the
    single-factor STF). Returns ``(x⁺, P⁺, NIS, ρ)``; NIS is χ² with m degrees
    of freedom for a consistent filter; ``ρ = 0`` for the plain filter. For
    ``POSITION`` this is :func:`~cwrend_cli.physics.estimation.kf_update` (to
    rounding).
    """
    m = dimension(kind)
    h = measure(kind, x_pred[:3])
    hr = jacobian(kind, x_pred[:3])  # H = [hr 0] (m, 6)
    # innovation ν = y − h(x⁻), angles the short way round (Eq. 14)
    nu = np.empty(m)
    for i in range(m):
        nu[i] = y[i] - h[i]
        if is_angle(kind, i):
            nu[i] = wrap_angle(nu[i])
    # P⁻Hᵀ (6, m) = P⁻[:, :3] hrᵀ
    pht = np.empty((6, m))
    for i in range(6):
        for j in range(m):
            pht[i, j] = p_pred[i, 0] * hr[j, 0] + p_pred[i, 1] * hr[j, 1] + p_pred[i, 2] * hr[j, 2]
    # S = H P⁻ Hᵀ + R (Eq. 15)
    hph = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            hph[i, j] = hr[i, 0] * pht[0, j] + hr[i, 1] * pht[1, j] + hr[i, 2] * pht[2, j]
    s = hph + r_nominal
    # NIS = νᵀ S⁻¹ ν (Eq. 22)
    s_inv = _inverse_spd(s)
    nis = 0.0
    for i in range(m):
        for j in range(m):
            nis += nu[i] * s_inv[i, j] * nu[j]
    r_eff = r_nominal.copy()
    rho = 0.0
    if estimator == MTF:
        r_eff, rho = mtf_inflation(nu, s, r_nominal)
    elif estimator == STF:
        hph_trace = 0.0
        for i in range(m):
            hph_trace += hph[i, i]
        r_eff, rho = stf_inflation(nis, nu, hph_trace, r_nominal)
    # K = P⁻Hᵀ (H P⁻ Hᵀ + R_eff + δI)⁻¹ (Eq. 19)
    s_eff = hph + r_eff
    for i in range(m):
        s_eff[i, i] += GAIN_REGULARISATION
    s_eff_inv = _inverse_spd(s_eff)
    k = np.zeros((6, m))
    for i in range(6):
        for j in range(m):
            for c in range(m):
                k[i, j] += pht[i, c] * s_eff_inv[c, j]
    # x⁺ = x⁻ + K ν (Eq. 20)
    x_post = x_pred.copy()
    for i in range(6):
        for j in range(m):
            x_post[i] += k[i, j] * nu[j]
    # Joseph form P⁺ = (I − KH) P⁻ (I − KH)ᵀ + K R_eff Kᵀ (Eq. 21): symmetric PSD by construction
    ikh = np.eye(6)
    for i in range(6):
        for j in range(3):
            for c in range(m):
                ikh[i, j] -= k[i, c] * hr[c, j]
    p_post = _sandwich(ikh, p_pred, _sandwich(k, r_eff, np.zeros((6, 6))))
    return x_post, p_post, nis, rho


@njit(cache=True)
def sensor_update(
    sensor: SensorModel, x_pred: np.ndarray, p_pred: np.ndarray, y: np.ndarray, estimator: int
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """:func:`ekf_update` of ``sensor`` with its nominal R at the predicted range ``‖x⁻[:3]‖``.

    ``R = diag(σ²)`` of :func:`sigmas` (the filter's σ_ρ uses the range it predicts).
    """
    rho = np.sqrt(x_pred[0] * x_pred[0] + x_pred[1] * x_pred[1] + x_pred[2] * x_pred[2])
    sig = sigmas(sensor.kind, rho, sensor.sigma_range_km, sensor.range_fraction,
                 sensor.sigma_angle_rad)  # fmt: skip
    r = np.diag(sig * sig)
    return ekf_update(sensor.kind, x_pred, p_pred, y, r, estimator)
