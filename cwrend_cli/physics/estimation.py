"""Linear Kalman filter with measurement-side MTF covariance inflation.

Paper Eqs. (11)–(23); the single-factor baseline of issue 35 (:func:`stf_inflation`,
Hajiyev & Soken 2013). Pure step functions on arrays (compiled with numba so the
closed loop can call them); history is kept by the caller. Units: km, km/s.
The measurement is the relative position, ``H = [I₃ 0]`` (Eq. 13), so every
product with ``H`` is a slice: ``H P Hᵀ = P[:3, :3]``, ``P Hᵀ = P[:, :3]``.
The 6×6 and 3×3 products are written out as loops: at this size that is
several times faster than calling BLAS/LAPACK, and it allocates only the
returned arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cwrend_cli.physics.dynamics import zoh_step

#: Regularisation added to the innovation covariance before inversion (none in paper
#: Eq. 19: the authors' code's, a convention of cwrend).
GAIN_REGULARISATION = 1e-12
#: Floor of tr(S) in the MTF ratio (none in paper Eq. 23: the authors' code's,
#: a convention of cwrend).
TRACE_FLOOR = 1e-12

#: Estimator kinds of :func:`kf_update` (and the extended update): no inflation,
#: the per-component MTF inflation (paper Eqs. 16–18), the single-factor one.
PLAIN = 0
MTF = 1
STF = 2
#: Kind of each ``Architecture.estimator`` name.
ESTIMATOR_KINDS = {"plain": PLAIN, "mtf": MTF, "stf": STF}
#: False-alarm probability α of the single-factor filter's fault test (Hajiyev &
#: Soken 2013 test NIS against the χ² quantile at a chosen α; 0.05: a convention of cwrend).
STF_FALSE_ALARM = 0.05


@njit(cache=True)
def mtf_inflation(nu: np.ndarray, s: np.ndarray, r_nominal: np.ndarray) -> tuple[np.ndarray, float]:
    """``(R_eff, ρ)`` of the MTF filter for an m-component innovation ``ν`` with nominal
    covariance ``S`` (paper Eqs. 16–18, 23).

    ``S_raw = ννᵀ − S`` (Eq. 16); only its positive diagonal excess is kept
    (``S_MTF``, Eq. 17) and added to R (``R_eff = R + S_MTF``, Eq. 18);
    ``ρ = tr(S_MTF)/tr(S)`` (Eq. 23), with a floor on tr(S). The linear update
    (:func:`kf_update`) and the extended one
    (:func:`cwrend_cli.physics.measurement_models.ekf_update`) both call it.
    """
    r_eff = r_nominal.copy()
    s_mtf_trace = 0.0
    s_trace = 0.0
    for i in range(nu.shape[0]):
        excess = nu[i] * nu[i] - s[i, i]
        s_trace += s[i, i]
        if excess > 0.0:
            r_eff[i, i] += excess
            s_mtf_trace += excess
    return r_eff, s_mtf_trace / max(s_trace, TRACE_FLOOR)


@njit(cache=True)
def stf_threshold(m: int) -> float:
    """χ²_{1−α, m}, the NIS above which the single-factor filter inflates R (α = 0.05) [-].

    ``scipy.stats.chi2.ppf(1 − STF_FALSE_ALARM, m)`` for m = 2, 3, written out so that
    the compiled update calls no scipy (a test checks them).
    """
    return 7.814727903251178 if m == 3 else 5.991464547107979


@njit(cache=True)
def stf_factor(
    nis: float, threshold: float, nu_sq: float, hph_trace: float, r_trace: float
) -> float:
    """The single measurement-noise scale factor λ ≥ 1 (Hajiyev & Soken 2013) [-].

    Hajiyev, C., Soken, H. E., "Robust adaptive Kalman filter for estimation of UAV
    dynamics in the presence of sensor/actuator faults", Aerospace Science and
    Technology 28 (2013) 376–383: when the fault statistic NIS = νᵀS⁻¹ν exceeds
    χ²_{1−α, m}, R is scaled by the one factor that matches the trace of the
    innovation covariance to the innovation's energy,
    ``tr(ννᵀ) − tr(H P⁻ Hᵀ) = λ tr(R)``, i.e.

        λ = (νᵀν − tr(H P⁻ Hᵀ)) / tr(R)   if NIS > χ²_{1−α, m},   else 1,

    with their averaging window of one step (the instantaneous innovation, as MTF's
    paper Eq. 16). λ is floored at 1 (a convention of cwrend: the filter never
    trusts a measurement more than its nominal R; a NIS above the threshold can
    come with νᵀν < tr(S) when S is anisotropic).
    """
    if not nis > threshold:
        return 1.0
    return max((nu_sq - hph_trace) / r_trace, 1.0)


@njit(cache=True)
def stf_inflation(
    nis: float, nu: np.ndarray, hph_trace: float, r_nominal: np.ndarray
) -> tuple[np.ndarray, float]:
    """``(R_eff, ρ)`` of the single-factor filter: ``R_eff = λ R`` (:func:`stf_factor`).

    ``ρ = (λ − 1) tr(R) / tr(S)`` is the MTF ratio's definition (paper Eq. 23:
    ``tr(S_eff − S)/tr(S)``, the relative growth of the innovation covariance's
    trace) applied to the single factor, so the composite score (paper Eq. 24)
    and the adaptive schedule read it as they read MTF's. λ = 1 returns a copy
    of ``R`` and ρ = 0: the update is then the plain filter's, bit for bit.
    """
    m = nu.shape[0]
    nu_sq = 0.0
    r_trace = 0.0
    for i in range(m):
        nu_sq += nu[i] * nu[i]
        r_trace += r_nominal[i, i]
    lam = stf_factor(nis, stf_threshold(m), nu_sq, hph_trace, r_trace)
    r_eff = r_nominal.copy()
    if lam == 1.0:
        return r_eff, 0.0
    for i in range(m):
        for j in range(m):
            r_eff[i, j] *= lam
    # ρ = tr(R_eff − R)/tr(S), with the floor of tr(S) of Eq. 23
    return r_eff, (lam - 1.0) * r_trace / max(hph_trace + r_trace, TRACE_FLOOR)


@njit(cache=True)
def _inverse_spd3(s: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive-definite 3×3 matrix (adjugate / determinant)."""
    a, b, c = s[0, 0], s[0, 1], s[0, 2]
    d, e = s[1, 1], s[1, 2]
    f = s[2, 2]
    inv = np.empty((3, 3))
    inv[0, 0] = d * f - e * e
    inv[0, 1] = c * e - b * f
    inv[0, 2] = b * e - c * d
    inv[1, 1] = a * f - c * c
    inv[1, 2] = b * c - a * e
    inv[2, 2] = a * d - b * b
    det = a * inv[0, 0] + b * inv[0, 1] + c * inv[0, 2]
    for i in range(3):
        for j in range(i, 3):
            inv[i, j] /= det
            inv[j, i] = inv[i, j]
    return inv


@njit(cache=True)
def _sandwich(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``A B Aᵀ + C`` for symmetric ``B`` (n×n) and ``C`` (m×m), ``A`` m×n; symmetric result."""
    m, n = a.shape
    ab = np.empty((m, n))
    for i in range(m):
        for j in range(n):
            acc = 0.0
            for k in range(n):
                acc += a[i, k] * b[k, j]
            ab[i, j] = acc
    out = np.empty((m, m))
    for i in range(m):
        for j in range(i, m):
            acc = c[i, j]
            for k in range(n):
                acc += ab[i, k] * a[j, k]
            out[i, j] = acc
            out[j, i] = acc
    return out


@njit(cache=True)
def kf_predict(
    x: np.ndarray, p: np.ndarray, phi: np.ndarray, gam: np.ndarray, u: np.ndarray, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Time update, Eqs. (11)–(12): ``x⁻ = Φx⁺ + Γu``, ``P⁻ = ΦP⁺Φᵀ + Q``."""
    return zoh_step(phi, gam, x, u), _sandwich(phi, p, q)


@njit(cache=True)
def kf_update(
    x_pred: np.ndarray, p_pred: np.ndarray, y: np.ndarray, r_nominal: np.ndarray, estimator: int
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Measurement update with optional MTF inflation, Eqs. (14)–(23).

    ``estimator``: :data:`PLAIN`, :data:`MTF` or :data:`STF` (the single-factor
    baseline, :func:`stf_inflation`). Returns ``(x⁺, P⁺, NIS, ρ)``; ``ρ = 0``
    for the plain filter.
    """
    # innovation ν = y − H x⁻ (Eq. 14) and nominal covariance S = H P⁻ Hᵀ + R (Eq. 15)
    nu = np.empty(3)
    s = np.empty((3, 3))
    for i in range(3):
        nu[i] = y[i] - x_pred[i]
        for j in range(3):
            s[i, j] = p_pred[i, j] + r_nominal[i, j]
    # NIS = νᵀ S⁻¹ ν (Eq. 22)
    s_inv = _inverse_spd3(s)
    nis = 0.0
    for i in range(3):
        for j in range(3):
            nis += nu[i] * s_inv[i, j] * nu[j]
    r_eff = r_nominal.copy()
    rho = 0.0
    if estimator == MTF:
        r_eff, rho = mtf_inflation(nu, s, r_nominal)
    elif estimator == STF:
        r_eff, rho = stf_inflation(nis, nu, p_pred[0, 0] + p_pred[1, 1] + p_pred[2, 2], r_nominal)
    # K = P⁻Hᵀ (H P⁻ Hᵀ + R_eff + δI)⁻¹ (Eq. 19)
    s_eff = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            s_eff[i, j] = p_pred[i, j] + r_eff[i, j]
        s_eff[i, i] += GAIN_REGULARISATION
    s_eff_inv = _inverse_spd3(s_eff)
    k = np.empty((6, 3))
    for i in range(6):
        for j in range(3):
            k[i, j] = (
                p_pred[i, 0] * s_eff_inv[0, j]
                + p_pred[i, 1] * s_eff_inv[1, j]
                + p_pred[i, 2] * s_eff_inv[2, j]
            )
    # x⁺ = x⁻ + K ν (Eq. 20)
    x_post = np.empty(6)
    for i in range(6):
        x_post[i] = x_pred[i] + k[i, 0] * nu[0] + k[i, 1] * nu[1] + k[i, 2] * nu[2]
    # Joseph form P⁺ = (I − KH) P⁻ (I − KH)ᵀ + K R_eff Kᵀ (Eq. 21): symmetric PSD by construction
    ikh = np.eye(6)
    for i in range(6):
        for j in range(3):
            ikh[i, j] -= k[i, j]
    p_post = _sandwich(ikh, p_pred, _sandwich(k, r_eff, np.zeros((6, 6))))
    return x_post, p_post, nis, rho
