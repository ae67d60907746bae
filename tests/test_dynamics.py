"""Clohessy–Wiltshire dynamics in closed form (paper Eqs. 3–4 and 11).

References: ``scipy.linalg.expm`` of the matrices of paper Eq. 4 (written out in
``conftest.spec_cw_matrices``, not taken from the package) and 80-digit
``decimal`` Taylor series for the cancellation-prone scalar functions.

Matrix comparisons are made in mean-motion units: with ``T = diag(1,1,1,n,n,n)``
the scaled matrices ``T⁻¹ Φ T`` (velocities in km per radian of orbit) are
dimensionless functions of ``τ = n t`` with O(1) entries, so a single relative
tolerance applies to every entry whatever its physical unit.
"""

from __future__ import annotations

import decimal

import numpy as np
import pytest
import scipy.linalg

from cwrend_cli.physics import dynamics

N = dynamics.MEAN_MOTION_PAPER_RAD_S  # n = 0.00104218449 rad/s: the authors' code's
EPS_MACH = np.finfo(float).eps
SCALE = np.diag([1.0, 1.0, 1.0, N, N, N])
SCALE_INV = np.diag([1.0, 1.0, 1.0, 1.0 / N, 1.0 / N, 1.0 / N])

#: Times [s]: tiny, one step, ten steps, the paper horizon, one orbit (2π/n ≈ 6029 s),
#: and negative times (backward propagation, used by the costate).
TIMES_S = (1e-6, 1.0, 10.0, 800.0, 6029.0, -1.0, -800.0)

#: Relative tolerance of closed form vs expm (relative to the largest scaled entry):
#: scaling-and-squaring Padé is backward stable to ~1e-15 ‖A t‖; ×100 margin.
REL_TOL_EXPM = 1e-13


def scaled(m: np.ndarray) -> np.ndarray:
    """``T⁻¹ M T``: a state-to-state matrix in mean-motion units (dimensionless)."""
    return SCALE_INV @ m @ SCALE


def assert_matrix_close(actual: np.ndarray, expected: np.ndarray, rel: float) -> None:
    """Max-entry error at most ``rel`` times the largest entry of ``expected`` (≥ 1)."""
    err = np.abs(actual - expected).max()
    bound = rel * max(1.0, np.abs(expected).max())
    assert err <= bound, f"max entry error {err:.3e} > {bound:.3e}"


# --- A and B (Eq. 4) ----------------------------------------------------------------


def test_cw_system_matches_spec_entries(cw_matrices) -> None:
    """Paper Eq. 4: 3n² at (4,1), 2n at (4,5), −2n at (5,4), −n² at (6,3) (1-based); B = [0; I]."""
    a, b = dynamics.cw_system(N)
    assert a[3, 0] == 3.0 * N * N
    assert a[3, 4] == 2.0 * N
    assert a[4, 3] == -2.0 * N
    assert a[5, 2] == -N * N
    np.testing.assert_array_equal(a[0:3, 3:6], np.eye(3))  # ṙ = v
    a_ref, b_ref = cw_matrices(N)
    np.testing.assert_array_equal(a, a_ref)  # every other entry is zero
    np.testing.assert_array_equal(b, b_ref)


def test_costate_derivative_is_minus_a_transpose(cw_matrices) -> None:
    """λ̇ = −Aᵀ λ (from the Hamiltonian, paper Eq. 7)."""
    a, _ = cw_matrices(N)
    lam = np.array([1e-4, -2e-3, 3e-4, 0.5, -0.7, 0.2])
    out = np.empty(6)
    dynamics.costate_derivative(N, lam, out)
    np.testing.assert_allclose(out, -a.T @ lam, rtol=1e-15, atol=1e-22)  # exact up to rounding


# --- Φ, Γ and the costate transition vs matrix exponentials ----------------------


def test_stm_at_zero_is_identity() -> None:
    """Φ(0) = e^{0} = I exactly."""
    np.testing.assert_array_equal(dynamics.stm(N, 0.0), np.eye(6))


@pytest.mark.parametrize("t", TIMES_S)
def test_stm_matches_expm(t: float, cw_matrices) -> None:
    """Paper Eq. 11: Φ(t) = e^{A t}, for positive and negative t."""
    a, _ = cw_matrices(N)
    assert_matrix_close(scaled(dynamics.stm(N, t)), scaled(scipy.linalg.expm(a * t)), REL_TOL_EXPM)


@pytest.mark.parametrize("t", TIMES_S)
def test_input_matrix_matches_augmented_expm(t: float, cw_matrices) -> None:
    """Paper Eq. 11: Γ(t) = ∫₀ᵗ e^{Aτ} B dτ = top-right block of exp([[A, B],[0, 0]] t)."""
    a, b = cw_matrices(N)
    aug = np.zeros((9, 9))
    aug[:6, :6] = a
    aug[:6, 6:] = b
    expected = scipy.linalg.expm(aug * t)[:6, 6:]
    # control in units of n² km/s² → Γ dimensionless
    assert_matrix_close(
        SCALE_INV @ dynamics.input_matrix(N, t) * N * N,
        SCALE_INV @ expected * N * N,
        REL_TOL_EXPM,
    )


@pytest.mark.parametrize("t", TIMES_S)
def test_costate_stm_matches_expm(t: float, cw_matrices) -> None:
    """λ(t) = e^{−Aᵀ t} λ(0) (from paper Eq. 7)."""
    a, _ = cw_matrices(N)
    # costates scale inversely to states: T Ψ T⁻¹ is dimensionless
    assert_matrix_close(
        SCALE @ dynamics.costate_stm(N, t) @ SCALE_INV,
        SCALE @ scipy.linalg.expm(-a.T * t) @ SCALE_INV,
        REL_TOL_EXPM,
    )


@pytest.mark.parametrize("t", TIMES_S)
def test_stm_inverse_is_backward_stm(t: float) -> None:
    """Φ(t) Φ(−t) = I (group property of e^{At})."""
    product = scaled(dynamics.stm(N, t) @ dynamics.stm(N, -t))
    assert_matrix_close(product, np.eye(6), REL_TOL_EXPM)


def test_stm_semigroup() -> None:
    """Φ(t₁) Φ(t₂) = Φ(t₁ + t₂): the 1 s step composed 800 times is the 800 s map."""
    phi_step = dynamics.stm(N, 1.0)
    acc = np.eye(6)
    for _ in range(800):
        acc = phi_step @ acc
    # 800 products accumulate ~800 roundings of O(1) scaled entries
    assert_matrix_close(scaled(acc), scaled(dynamics.stm(N, 800.0)), 1e-12)


def test_discretize_is_stm_and_input_matrix() -> None:
    """Paper Eq. 11: the exact ZOH discretisation over Δt is (Φ(Δt), Γ(Δt))."""
    phi, gam = dynamics.discretize(N, 1.0)
    np.testing.assert_array_equal(phi, dynamics.stm(N, 1.0))
    np.testing.assert_array_equal(gam, dynamics.input_matrix(N, 1.0))


def test_zoh_step_is_phi_x_plus_gamma_u() -> None:
    """Eq. 11: ``x⁺ = Φx + Γu`` (written-out kernel vs numpy matmul; rounding only)."""
    phi, gam = dynamics.discretize(N, 1.0)
    rng = np.random.default_rng(3)
    x, u = rng.normal(size=6), 1e-4 * rng.normal(size=3)
    expected = phi @ x + gam @ u
    np.testing.assert_allclose(dynamics.zoh_step(phi, gam, x, u), expected, rtol=1e-14, atol=0)


# --- cancellation-free scalar functions -----------------------------------------

ARGS = (1e-12, 1e-8, 1e-6, N * 1.0, 0.05, 0.0999999, 0.1, 0.1000001, 0.3, 1.0, 3.0)


def _series_reference(x: float) -> tuple[float, float]:
    """``(x − sin x, 1 − cos x)`` of the exact binary value of x, by 80-digit Taylor series."""
    with decimal.localcontext() as ctx:
        ctx.prec = 80
        d = decimal.Decimal(x)
        tiny = decimal.Decimal(10) ** -100
        sin_sum, term, k = decimal.Decimal(0), d, 1
        while abs(term) > tiny:
            sin_sum += term
            term = -term * d * d / ((k + 1) * (k + 2))
            k += 2
        cos_sum, term, k = decimal.Decimal(0), decimal.Decimal(1), 0
        while abs(term) > tiny:
            cos_sum += term
            term = -term * d * d / ((k + 1) * (k + 2))
            k += 2
        return float(d - sin_sum), float(1 - cos_sum)


@pytest.mark.parametrize("x", ARGS + tuple(-v for v in ARGS))
def test_x_minus_sin_accuracy(x: float) -> None:
    """``x − sin x`` keeps full relative accuracy down to tiny arguments (n Δt ≈ 1e-3)."""
    expected, _ = _series_reference(x)
    got = dynamics.x_minus_sin(x)
    # series branch (|x| < 0.1): no cancellation, a few roundings; direct branch: the
    # subtraction amplifies sin's 1-ulp error by x/(x − sin x)
    series_tol = 4 * EPS_MACH
    direct_tol = 2 * EPS_MACH * abs(x) / abs(expected)
    tol = series_tol if abs(x) < 0.1 else direct_tol
    assert abs(got - expected) <= tol * abs(expected)


@pytest.mark.parametrize("x", ARGS + tuple(-v for v in ARGS))
def test_one_minus_cos_accuracy(x: float) -> None:
    """``1 − cos x = 2 sin²(x/2)`` is accurate to a few ulp at every argument."""
    _, expected = _series_reference(x)
    got = dynamics.one_minus_cos(x)
    assert abs(got - expected) <= 4 * EPS_MACH * abs(expected)  # sin (1 ulp) and 2 products


def test_stm_short_step_entries_keep_relative_accuracy() -> None:
    """Φ(1 s)[1,0] = −6(nΔt − sin nΔt) ≈ −n³Δt³ keeps its digits (no cancellation)."""
    x = N * 1.0
    expected, _ = _series_reference(x)
    phi = dynamics.stm(N, 1.0)
    # naive −6(x − sin x) would be wrong by ~1e-16·x/x³ ≈ 1e-10 relative
    assert abs(phi[1, 0] - (-6.0 * expected)) <= 8 * EPS_MACH * abs(6.0 * expected)
