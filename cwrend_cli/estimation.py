"""Linear Kalman filter with measurement-side MTF covariance inflation (SPEC §3).

Paper Eqs. (11)–(23). Pure step functions on arrays (compiled with numba so the
closed loop can call them); history is kept by the caller. Units: km, km/s.
The measurement is the relative position, ``H = [I₃ 0]`` (Eq. 13).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Regularisation added to the innovation covariance before inversion (SPEC §3).
GAIN_REGULARISATION = 1e-12
#: Floor of tr(S) in the MTF ratio (SPEC §3).
TRACE_FLOOR = 1e-12


@njit(cache=True)
def kf_predict(
    x: np.ndarray, p: np.ndarray, phi: np.ndarray, gam: np.ndarray, u: np.ndarray, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Time update, Eqs. (11)–(12): ``x⁻ = Φx⁺ + Γu``, ``P⁻ = ΦP⁺Φᵀ + Q``."""
    x_pred = phi @ x + gam @ u
    p_pred = phi @ p @ phi.T + q
    return x_pred, p_pred


@njit(cache=True)
def kf_update(
    x_pred: np.ndarray, p_pred: np.ndarray, y: np.ndarray, r_nominal: np.ndarray, use_mtf: bool
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Measurement update with optional MTF inflation, Eqs. (14)–(23).

    Returns ``(x⁺, P⁺, NIS, ρ_MTF)``; ``ρ_MTF = 0`` when MTF is off.
    """
    # innovation ν = y − H x⁻ (Eq. 14) and nominal covariance S = H P⁻ Hᵀ + R (Eq. 15)
    nu = y - x_pred[:3]
    s = p_pred[:3, :3] + r_nominal
    # NIS = νᵀ S⁻¹ ν (Eq. 22)
    nis = nu @ np.linalg.solve(s, nu)
    r_eff = r_nominal.copy()
    rho = 0.0
    if use_mtf:
        # S_raw = ννᵀ − S (Eq. 16); keep positive diagonal excess only (Eq. 17)
        s_mtf_trace = 0.0
        for i in range(3):
            excess = nu[i] * nu[i] - s[i, i]
            if excess > 0.0:
                r_eff[i, i] += excess  # R_eff = R + S_MTF (Eq. 18)
                s_mtf_trace += excess
        # ρ = tr(S_MTF)/tr(S) (Eq. 23), with a floor on tr(S)
        rho = s_mtf_trace / max(np.trace(s), TRACE_FLOOR)
    # K = P⁻Hᵀ (H P⁻ Hᵀ + R_eff + δI)⁻¹ (Eq. 19)
    s_eff = p_pred[:3, :3] + r_eff + GAIN_REGULARISATION * np.eye(3)
    k = np.linalg.solve(s_eff, p_pred[:3, :].copy()).T
    # x⁺ = x⁻ + K ν (Eq. 20)
    x_post = x_pred + k @ nu
    # Joseph form P⁺ = (I − KH) P⁻ (I − KH)ᵀ + K R_eff Kᵀ (Eq. 21): stays symmetric PSD
    ikh = np.eye(6)
    ikh[:, :3] -= k
    p_post = ikh @ p_pred @ ikh.T + k @ r_eff @ k.T
    p_post = 0.5 * (p_post + p_post.T)
    return x_post, p_post, nis, rho
