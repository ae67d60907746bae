"""Innovation-adaptive homotopy schedule (paper Eqs. 24–26).

Score ``s = min(max(NIS − m, 0) + κ ρ, score_max)``; low-pass
``s̄_k = ρ_s s̄_{k−1} + (1 − ρ_s) s_k`` (first step ``s̄ = s``); target
``ε* = ε_min + (ε_max − ε_min)(1 − e^{−β s̄})`` with optional deadband and
saturation; applied ``ε_k = (1 − α) ε_{k−1} + α ε*``. Paper values (Table 1):
m = 3, κ = 12, score_max = 50, ρ_s = 0.85, β = 0.25, ε ∈ [0, 1], α = 0.1.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cwrend_cli.physics.scheduling import composite_score, eps_blend, eps_target, lowpass_score

M, KAPPA, SCORE_MAX = 3.0, 12.0, 50.0
RHO_S, BETA, ALPHA = 0.85, 0.25, 0.10
NO_SAT = math.nan  # saturation disabled
REL = 1e-15  # a few roundings of O(1) arithmetic


# --- composite score (Eq. 24 with the cap) -------------------------------------


def test_score_nis_below_offset_counts_only_mtf() -> None:
    """NIS ≤ m contributes nothing: s = κ ρ."""
    assert composite_score(2.0, 0.0, M, KAPPA, SCORE_MAX) == 0.0
    assert composite_score(2.0, 0.25, M, KAPPA, SCORE_MAX) == pytest.approx(3.0, rel=REL)


def test_score_adds_nis_excess_and_weighted_mtf_ratio() -> None:
    """s = (NIS − m) + κ ρ = (10 − 3) + 12·0.5 = 13."""
    assert composite_score(10.0, 0.5, M, KAPPA, SCORE_MAX) == pytest.approx(13.0, rel=REL)


def test_score_is_capped_at_score_max() -> None:
    """The instantaneous score of paper Eq. 24 is capped at score_max = 50 (paper Table 1)."""
    assert composite_score(1e6, 0.0, M, KAPPA, SCORE_MAX) == SCORE_MAX
    assert composite_score(40.0, 2.0, M, KAPPA, SCORE_MAX) == SCORE_MAX  # 37 + 24 > 50


@settings(max_examples=200, deadline=None)
@given(nis=st.floats(0.0, 1e8), rho=st.floats(0.0, 1e3))
def test_score_within_zero_and_cap(nis: float, rho: float) -> None:
    """0 ≤ s ≤ score_max, and s equals the uncapped formula whenever that is below the cap."""
    s = composite_score(nis, rho, M, KAPPA, SCORE_MAX)
    raw = max(nis - M, 0.0) + KAPPA * rho
    assert 0.0 <= s <= SCORE_MAX
    assert s == min(raw, SCORE_MAX)


# --- low-pass (Eq. 25) ------------------------------------------------------------


def test_lowpass_first_step_sets_score() -> None:
    """The first step sets s̄ = s (the previous value is ignored).

    The start of paper Eq. 25 is the authors' code's, not in the paper (docs/method.md).
    """
    assert lowpass_score(123.0, 7.0, RHO_S, True) == 7.0


def test_lowpass_recursion() -> None:
    """s̄ = 0.85·10 + 0.15·30 = 13."""
    assert lowpass_score(10.0, 30.0, RHO_S, False) == pytest.approx(13.0, rel=REL)


def test_lowpass_step_response() -> None:
    """A unit step after s̄ = 0 gives s̄_k = 1 − ρ_s^k (first-order filter)."""
    sbar = lowpass_score(0.0, 0.0, RHO_S, True)
    for k in range(1, 40):
        sbar = lowpass_score(sbar, 1.0, RHO_S, False)
        assert sbar == pytest.approx(1.0 - RHO_S**k, rel=1e-13)  # k roundings


# --- ε map (Eq. 26), deadband and saturation -------------------------------------------


def test_eps_map_endpoints() -> None:
    """s̄ = 0 → ε_min exactly; s̄ → ∞ → ε_max."""
    assert eps_target(0.0, 0.0, 1.0, BETA, 0.0, NO_SAT) == 0.0
    assert eps_target(0.0, 0.2, 0.9, BETA, 0.0, NO_SAT) == 0.2
    assert eps_target(1e4, 0.0, 1.0, BETA, 0.0, NO_SAT) == 1.0
    assert eps_target(1e4, 0.2, 0.9, BETA, 0.0, NO_SAT) == pytest.approx(0.9, rel=REL)


def test_eps_map_interior_value() -> None:
    """β s̄ = 1: ε* = ε_min + (ε_max − ε_min)(1 − e^{−1}) = 0.632120558828558 (paper β, ε range)."""
    assert eps_target(4.0, 0.0, 1.0, BETA, 0.0, NO_SAT) == pytest.approx(
        1.0 - math.exp(-1.0), rel=REL
    )


@settings(max_examples=100, deadline=None)
@given(s1=st.floats(0.0, 1e3), s2=st.floats(0.0, 1e3))
def test_eps_map_monotone_within_range(s1: float, s2: float) -> None:
    """ε* is nondecreasing in s̄ and stays within [ε_min, ε_max]."""
    lo, hi = sorted((s1, s2))
    e_lo = eps_target(lo, 0.1, 0.8, BETA, 0.0, NO_SAT)
    e_hi = eps_target(hi, 0.1, 0.8, BETA, 0.0, NO_SAT)
    assert 0.1 <= e_lo <= e_hi <= 0.8 + 1e-16


def test_eps_map_deadband() -> None:
    """Deadband d: s̄ ≤ d maps to ε_min; above, the excess s̄ − d drives the map."""
    assert eps_target(1.5, 0.0, 1.0, BETA, 2.0, NO_SAT) == 0.0
    assert eps_target(2.0, 0.0, 1.0, BETA, 2.0, NO_SAT) == 0.0
    assert eps_target(6.0, 0.0, 1.0, BETA, 2.0, NO_SAT) == pytest.approx(
        1.0 - math.exp(-BETA * 4.0), rel=REL
    )


def test_eps_map_saturation() -> None:
    """Saturation clips ε* from above; NaN disables it."""
    assert eps_target(100.0, 0.0, 1.0, BETA, 0.0, 0.4) == 0.4
    assert eps_target(1.0, 0.0, 1.0, BETA, 0.0, 0.4) == pytest.approx(
        1.0 - math.exp(-BETA), rel=REL
    )  # below the clip: unchanged
    assert eps_target(100.0, 0.0, 1.0, BETA, 0.0, NO_SAT) > 0.99


# --- blend -------------------------------------------------------------------


def test_eps_blend() -> None:
    """ε_k = (1 − α) ε_{k−1} + α ε* = 0.9·1 + 0.1·0.5 = 0.95."""
    assert eps_blend(1.0, 0.5, ALPHA) == pytest.approx(0.95, rel=REL)


def test_eps_blend_decays_geometrically_to_target() -> None:
    """From ε_max = 1 with target 0 the applied ε is 0.9^k (α_ε = 0.1: paper Table 1).

    The adaptive start at ε_max is the authors' code's, not in the paper (docs/method.md).
    """
    eps = 1.0
    for k in range(1, 60):
        eps = eps_blend(eps, 0.0, ALPHA)
        assert eps == pytest.approx(0.9**k, rel=1e-13)
