"""Control law of paper Eqs. 8–10: direction, switching function, smoothed throttle.

``S = 1 − ‖λ_v‖``; ``u = 0`` if ``S > ε``; ``u_max (ε − S)/(2ε) α`` if ``−ε ≤ S ≤ ε``;
``u_max α`` if ``S < −ε``; ``α = −λ_v/‖λ_v‖``; ε below 1e-12 is exactly bang-bang.
The test inputs below are chosen so that ``1 − p`` and the ramp are exact in binary.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cwrend_cli.physics import guidance
from cwrend_cli.physics.guidance._kernels import throttle

U_MAX = 8e-4  # km/s², paper Table 1
EPS_MACH = np.finfo(float).eps
#: ‖u‖ may exceed u_max only by the rounding of the normalisation λ_v/‖λ_v‖ (a few ulp).
REL_TOL_NORM = 4 * EPS_MACH


# --- the three regimes (Eq. 10) --------------------------------------------------


@pytest.mark.parametrize(
    ("p", "expected"),
    [
        (0.0, 0.0),  # S = 1 > ε: coast
        (0.25, 0.0),  # S = 0.75 > ε: coast
        (0.5, 0.0),  # S = ε: ramp start, (ε − S)/(2ε) = 0
        (0.75, 0.25),  # S = 0.25: ramp
        (1.0, 0.5),  # S = 0: middle of the ramp
        (1.25, 0.75),  # S = −0.25: ramp
        (1.5, 1.0),  # S = −ε: ramp end, full thrust
        (2.0, 1.0),  # S < −ε: full thrust
        (100.0, 1.0),
    ],
)
def test_throttle_regimes_eps_half(p: float, expected: float) -> None:
    """Eq. (10) at ε = 0.5: coast, linear ramp (ε − S)/(2ε), full thrust (exact values)."""
    assert throttle(p, 0.5) == expected


@pytest.mark.parametrize(("p", "expected"), [(0.5, 0.0), (0.999, 0.0), (1.001, 1.0), (3.0, 1.0)])
def test_throttle_bang_bang_at_eps_zero(p: float, expected: float) -> None:
    """ε = 0: thrust u_max when S < 0 (‖λ_v‖ > 1), coast when S > 0."""
    assert throttle(p, 0.0) == expected


def test_eps_below_threshold_is_bang_bang() -> None:
    """ε below 1e-12 is treated as exactly 0, not as a (very steep) ramp.

    Paper Eq. 10 as ε → 0; the threshold is a convention of cwrend, not in the paper
    (docs/method.md).

    At ε = 1e-13 and S = ∓2e-14 the ramp would give 0.4 / 0.6; bang-bang gives 0 / 1.
    """
    eps = 1e-13
    assert throttle(1.0 + 2e-14, eps) == 1.0
    assert throttle(1.0 - 2e-14, eps) == 0.0
    assert throttle(1.0 + 2e-14, 0.0) == 1.0
    assert throttle(1.0 - 2e-14, 0.0) == 0.0


def test_eps_at_threshold_uses_the_ramp() -> None:
    """ε = 1e-12 is not below the threshold: S = −5e-13 is on the ramp, (ε − S)/(2ε) = 0.75.

    Tolerance 2e-4: 1 − p is only known to the spacing of doubles near 1 (2.2e-16),
    i.e. 1.1e-4 of 2ε.
    """
    assert throttle(1.0 + 5e-13, 1e-12) == pytest.approx(0.75, abs=2e-4)


@pytest.mark.parametrize("eps", [1.0, 0.3, 0.05, 1e-6])
def test_throttle_continuous_at_ramp_ends(eps: float) -> None:
    """Continuity at S = ±ε: approaching 1 ∓ ε from either side gives the same throttle.

    Steps δ = 1e-9 ε change the ramp value by δ/(2ε) = 5e-10; the arguments 1 ∓ ε ± δ
    are themselves rounded to the spacing of doubles near 1 (≤ 4 ulp(1) in all).
    """
    delta = 1e-9 * eps
    tol = (delta + 4 * EPS_MACH) / (2 * eps) + 1e-15
    for edge, value in ((1.0 - eps, 0.0), (1.0 + eps, 1.0)):
        assert abs(throttle(edge - delta, eps) - value) <= tol
        assert abs(throttle(edge + delta, eps) - value) <= tol


@settings(max_examples=200, deadline=None)
@given(
    p1=st.floats(0.0, 3.0),
    p2=st.floats(0.0, 3.0),
    eps=st.floats(1e-6, 2.0),
)
def test_throttle_is_monotone_and_lipschitz(p1: float, p2: float, eps: float) -> None:
    """Eq. (10) as a function of p = ‖λ_v‖ is nondecreasing, in [0, 1], Lipschitz 1/(2ε).

    Lipschitz continuity includes continuity at S = ±ε. Slack: S = 1 − p is rounded
    to ulp(1) = 2.2e-16, amplified by 1/(2ε), plus 1e-15 for rounding of (ε − S)/(2ε).
    """
    lo, hi = sorted((p1, p2))
    t_lo, t_hi = throttle(lo, eps), throttle(hi, eps)
    assert 0.0 <= t_lo <= t_hi <= 1.0
    assert t_hi - t_lo <= (hi - lo + 2 * EPS_MACH) / (2 * eps) + 1e-15


# --- direction (Eq. 8) and the vector control -------------------------------------


@pytest.mark.parametrize("eps", [0.0, 0.05, 0.3, 1.0])
def test_control_direction_is_minus_lambda_v(eps: float) -> None:
    """Eq. (8): u points along α = −λ_v/‖λ_v‖ with magnitude u_max·throttle (Eq. 10)."""
    lam_v = np.array([3.0, -4.0, 12.0]) / 10.0  # ‖λ_v‖ = 1.3
    u = guidance.control(lam_v, eps, U_MAX)
    mag = U_MAX * throttle(1.3, eps)
    assert mag > 0.0  # S = −0.3 ≤ ε: some thrust at each ε tested
    np.testing.assert_allclose(u, -mag * lam_v / 1.3, rtol=4 * EPS_MACH, atol=0.0)


def test_control_is_zero_when_coasting() -> None:
    """S > ε: u = 0 exactly (also for λ_v = 0, where the direction is undefined)."""
    np.testing.assert_array_equal(guidance.control(np.array([0.3, 0.0, 0.0]), 0.5, U_MAX), 0.0)
    np.testing.assert_array_equal(guidance.control(np.zeros(3), 0.0, U_MAX), 0.0)
    np.testing.assert_array_equal(guidance.control(np.zeros(3), 0.3, U_MAX), 0.0)


def test_control_matches_eq10_magnitudes() -> None:
    """‖u‖ over the three regimes at ε = 0.5 along a fixed direction (exact ramp values)."""
    direction = np.array([0.0, 0.6, -0.8])  # unit vector
    for p, frac in ((0.25, 0.0), (0.75, 0.25), (1.0, 0.5), (1.25, 0.75), (2.0, 1.0)):
        u = guidance.control(p * direction, 0.5, U_MAX)
        assert np.linalg.norm(u) == pytest.approx(frac * U_MAX, rel=REL_TOL_NORM, abs=0.0)


finite = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False)


@settings(max_examples=300, deadline=None)
@given(
    lam_v=st.tuples(finite, finite, finite),
    eps=st.one_of(st.just(0.0), st.floats(0.0, 2.0)),
    u_max=st.floats(1e-6, 1e-2),
)
def test_control_norm_never_exceeds_u_max(lam_v, eps: float, u_max: float) -> None:
    """‖u‖ ≤ u_max for every costate and ε ≥ 0 (Eq. 10, control bound of Eq. 6)."""
    u = guidance.control(np.array(lam_v), eps, u_max)
    assert np.all(np.isfinite(u))
    assert np.linalg.norm(u) <= u_max * (1.0 + REL_TOL_NORM)
