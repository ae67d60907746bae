"""Linear Kalman filter with measurement-side MTF inflation (paper Eqs. 11–23).

The reference below is a plain-numpy transcription of paper Eqs. 14–23 with explicit
``H = [I 0]`` and explicit inverses, so it shares no code path with the
compiled filter (which uses slices and ``solve``).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cwrend_cli.physics.dynamics import MEAN_MOTION_PAPER_RAD_S, discretize
from cwrend_cli.physics.estimation import MTF, PLAIN, kf_predict, kf_update

H = np.hstack([np.eye(3), np.zeros((3, 3))])  # Eq. (13)
R_NOM = np.diag([1e-6, 1e-6, 1e-6])  # km², paper Table 1 (1 m σ)
Q = np.diag([1e-12] * 3 + [1e-14] * 3)  # paper Table 1
P0 = np.diag([1e-6] * 3 + [1e-10] * 3)  # paper Table 1
# x0 of paper Sec. "Numerical Results and Discussion" [km, km/s]
X0 = np.array([0.03031809, 0.0, 31.16639, -0.02963377, 0.04570523, 0.0])

#: State agreement [km, km/s]: rounding of a 31 km state is ~4e-15 km; 1e-13 km = 0.1 nm.
TOL_X = 1e-13
#: Covariance agreement, relative to the largest entry of P (1e-6 km²): the update
#: subtracts nearly equal O(P) terms, so ~1e-16·cond(S) ≈ 1e-14 is rounding; ×100 margin.
REL_TOL_P = 1e-12


def reference_update(
    x_pred: np.ndarray, p_pred: np.ndarray, y: np.ndarray, r_nom: np.ndarray, use_mtf: bool
) -> tuple[np.ndarray, np.ndarray, float, float, np.ndarray]:
    """Paper Eqs. 14–23, verbatim. Returns (x⁺, P⁺, NIS, ρ, R_eff).

    The 1e-12 regularisation of the gain and floor of tr(S) are the authors' code's, not in
    the paper (docs/method.md).
    """
    nu = y - H @ x_pred  # Eq. (14)
    s = H @ p_pred @ H.T + r_nom  # Eq. (15)
    nis = float(nu @ np.linalg.inv(s) @ nu)  # Eq. (22)
    s_raw = np.outer(nu, nu) - s  # Eq. (16)
    s_mtf = np.diag(np.maximum(np.diag(s_raw), 0.0))  # Eq. (17)
    r_eff = r_nom + s_mtf if use_mtf else r_nom  # Eq. (18)
    k = p_pred @ H.T @ np.linalg.inv(H @ p_pred @ H.T + r_eff + 1e-12 * np.eye(3))  # Eq. (19)
    x_post = x_pred + k @ nu  # Eq. (20)
    ikh = np.eye(6) - k @ H
    p_post = ikh @ p_pred @ ikh.T + k @ r_eff @ k.T  # Eq. (21), Joseph form
    rho = float(np.trace(s_mtf) / max(np.trace(s), 1e-12)) if use_mtf else 0.0  # Eq. (23)
    return x_post, p_post, nis, rho, r_eff


def assert_cov_close(actual: np.ndarray, expected: np.ndarray) -> None:
    err = np.abs(actual - expected).max()
    assert err <= REL_TOL_P * np.abs(expected).max(), f"covariance error {err:.3e}"


@pytest.fixture(scope="module")
def predicted() -> tuple[np.ndarray, np.ndarray]:
    """A realistic prior: P0 and x0 of the paper propagated 10 steps with the KF predict."""
    phi, gam = discretize(MEAN_MOTION_PAPER_RAD_S, 1.0)
    x, p = X0.copy(), P0.copy()
    u = np.array([1e-4, -2e-4, 8e-4])
    for _ in range(10):
        x, p = phi @ x + gam @ u, phi @ p @ phi.T + Q
    return x, p


# --- predict (Eqs. 11–12) ------------------------------------------------------


def test_kf_predict_matches_eqs_11_12() -> None:
    """x⁻ = Φx⁺ + Γu, P⁻ = ΦP⁺Φᵀ + Q with the exact 1 s discretisation."""
    phi, gam = discretize(MEAN_MOTION_PAPER_RAD_S, 1.0)
    u = np.array([3e-4, -8e-4, 1e-5])
    x_pred, p_pred = kf_predict(X0, P0, phi, gam, u, Q)
    np.testing.assert_allclose(x_pred, phi @ X0 + gam @ u, rtol=0, atol=TOL_X)
    assert_cov_close(p_pred, phi @ P0 @ phi.T + Q)


# --- update (Eqs. 14–22), with and without MTF -------------------------------------


@pytest.mark.parametrize("use_mtf", [False, True])
@pytest.mark.parametrize(
    "noise_km",
    [
        np.array([4e-4, -1.1e-3, 7e-4]),  # nominal: ~1 m innovation
        np.array([0.03, -0.02, 0.035]),  # degraded window: 17 m σ plus [10, −8, 12] m bias
    ],
    ids=["nominal", "degraded"],
)
def test_kf_update_matches_spec_reference(predicted, noise_km: np.ndarray, use_mtf: bool) -> None:
    """x⁺, P⁺, NIS and ρ_MTF of paper Eqs. 14–23 (plain-numpy reference)."""
    x_pred, p_pred = predicted
    truth = x_pred + np.array([2e-4, -1e-4, 3e-4, 1e-6, 0.0, -2e-6])
    y = truth[:3] + noise_km
    x_post, p_post, nis, rho = kf_update(x_pred, p_pred, y, R_NOM, MTF if use_mtf else PLAIN)
    x_ref, p_ref, nis_ref, rho_ref, _ = reference_update(x_pred, p_pred, y, R_NOM, use_mtf)
    np.testing.assert_allclose(x_post, x_ref, rtol=0, atol=TOL_X)
    assert_cov_close(p_post, p_ref)
    assert nis == pytest.approx(nis_ref, rel=1e-12)  # 3×3 solve vs inverse: rounding only
    assert rho == pytest.approx(rho_ref, rel=1e-12, abs=0.0)


def test_nis_value_for_a_known_innovation() -> None:
    """Eq. (22): with P⁻ = 0 the NIS is νᵀR⁻¹ν; ν = [1, 2, 2] m, R = (1 m)² I ⇒ NIS = 9."""
    x_pred = np.zeros(6)
    p_pred = np.zeros((6, 6))
    y = np.array([1e-3, 2e-3, 2e-3])
    _, _, nis, _ = kf_update(x_pred, p_pred, y, R_NOM, PLAIN)
    assert nis == pytest.approx(9.0, rel=1e-14)


def test_mtf_ratio_is_zero_when_mtf_off(predicted) -> None:
    """ρ = 0 without MTF, even for a huge innovation (docs/method.md; the paper does not say)."""
    x_pred, p_pred = predicted
    y = x_pred[:3] + np.array([1.0, -1.0, 1.0])  # 1 km innovation
    _, _, nis, rho = kf_update(x_pred, p_pred, y, R_NOM, PLAIN)
    assert nis > 1e5
    assert rho == 0.0


def test_mtf_keeps_only_positive_diagonal_excess() -> None:
    """Eq. (17): S_MTF = diag(max(diag(ννᵀ − S), 0)): off-diagonals and deficits dropped.

    Innovation ν = [10, 0, 0.1] m with S = diag(2, 3, 4) m²: only axis 1 has an excess
    (100 − 2 m²); axis 2 and 3 are below S; ν₁ν₃ = 1 m² off-diagonal is not used.
    """
    p_pred = np.zeros((6, 6))
    p_pred[:3, :3] = np.diag([1e-6, 2e-6, 3e-6])
    p_pred[3:, 3:] = np.diag([1e-10] * 3)
    p_pred[0, 3] = p_pred[3, 0] = 2e-9  # velocity correlated with x
    x_pred = np.zeros(6)
    nu = np.array([1e-2, 0.0, 1e-4])
    x_post, p_post, _, rho = kf_update(x_pred, p_pred, nu, R_NOM, MTF)

    s_trace = 2e-6 + 3e-6 + 4e-6
    assert rho == pytest.approx((1e-4 - 2e-6) / s_trace, rel=1e-13)  # Eq. (23)

    # R_eff = R + diag(ν₁² − S₁₁, 0, 0), Eq. (18)
    r_eff = R_NOM + np.diag([1e-4 - 2e-6, 0.0, 0.0])
    k = p_pred @ H.T @ np.linalg.inv(p_pred[:3, :3] + r_eff + 1e-12 * np.eye(3))
    np.testing.assert_allclose(x_post, k @ nu, rtol=0, atol=TOL_X)
    ikh = np.eye(6) - k @ H
    assert_cov_close(p_post, ikh @ p_pred @ ikh.T + k @ r_eff @ k.T)

    # Sensitivity check: keeping the full positive part of S_raw (off-diagonal ν₁ν₃ and
    # all) would move the estimate by far more than the tolerance.
    s_raw = np.outer(nu, nu) - (p_pred[:3, :3] + R_NOM)
    r_wrong = R_NOM + np.maximum(s_raw, 0.0)
    k_wrong = p_pred @ H.T @ np.linalg.inv(p_pred[:3, :3] + r_wrong + 1e-12 * np.eye(3))
    assert np.abs(k_wrong @ nu - x_post).max() > 1e3 * TOL_X


def test_mtf_inflation_reduces_the_correction(predicted) -> None:
    """An outlier moves the MTF estimate less than the plain-KF estimate (R_eff ⪰ R)."""
    x_pred, p_pred = predicted
    y = x_pred[:3] + np.array([0.05, -0.04, 0.06])  # ~50 m outlier
    x_plain, *_ = kf_update(x_pred, p_pred, y, R_NOM, PLAIN)
    x_mtf, *_ = kf_update(x_pred, p_pred, y, R_NOM, MTF)
    assert np.linalg.norm(x_mtf[:3] - x_pred[:3]) < 0.1 * np.linalg.norm(x_plain[:3] - x_pred[:3])


# --- Joseph form (Eq. 21): symmetric positive semi-definite ------------------------

scales = st.floats(1e-12, 1e-4)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    pos_var=scales,
    vel_ratio=st.floats(1e-8, 1e-2),
    r_var=st.floats(1e-8, 1e-2),
    innovation_sigmas=st.floats(0.0, 1e3),
    use_mtf=st.booleans(),
)
def test_joseph_covariance_symmetric_psd(
    seed: int,
    pos_var: float,
    vel_ratio: float,
    r_var: float,
    innovation_sigmas: float,
    use_mtf: bool,
) -> None:
    """P⁺ of Eq. (21) is exactly symmetric and PSD, and its trace does not exceed tr P⁻.

    PSD to rounding: min eigenvalue ≥ −1e-13·‖P⁻‖ (eigvalsh error ~1e-16·‖P‖ per term).
    """
    rng = np.random.default_rng(seed)
    d = np.sqrt(np.array([pos_var] * 3 + [pos_var * vel_ratio] * 3))
    g = rng.standard_normal((6, 6))
    corr = g @ g.T + 0.1 * np.eye(6)  # SPD, arbitrary correlations
    p_pred = d[:, None] * corr * d[None, :] / np.trace(corr) * 6
    r_nom = np.diag(r_var * (0.5 + rng.random(3)))
    x_pred = rng.standard_normal(6)
    s = p_pred[:3, :3] + r_nom
    nu = innovation_sigmas * np.linalg.cholesky(s) @ rng.standard_normal(3)
    _, p_post, nis, rho = kf_update(
        x_pred, p_pred, x_pred[:3] + nu, r_nom, MTF if use_mtf else PLAIN
    )
    np.testing.assert_array_equal(p_post, p_post.T)
    norm = np.abs(np.linalg.eigvalsh(p_pred)).max()
    assert np.linalg.eigvalsh(p_post).min() >= -1e-13 * norm
    assert np.trace(p_post) <= np.trace(p_pred) * (1 + 1e-12)
    assert nis >= 0.0
    assert rho >= 0.0
