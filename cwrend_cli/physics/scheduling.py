"""Innovation-adaptive homotopy schedule (paper Eqs. 24–26).

Pure scalar functions, compiled so that the closed loop can call them.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def composite_score(
    nis: float, mtf_ratio: float, nis_offset: float, kappa_mtf: float, score_max: float
) -> float:
    """``s = min(max(NIS − m, 0) + κ_MTF ρ, score_max)`` (paper Eq. 24; cap: Table 1)."""
    return min(max(nis - nis_offset, 0.0) + kappa_mtf * mtf_ratio, score_max)


@njit(cache=True)
def lowpass_score(previous: float, score: float, rho_s: float, first: bool) -> float:
    """``s̄_k = ρ_s s̄_{k−1} + (1 − ρ_s) s_k`` (Eq. 25); the first step sets ``s̄ = s``."""
    if first:
        return score
    return rho_s * previous + (1.0 - rho_s) * score


@njit(cache=True)
def eps_target(
    score_filtered: float,
    eps_min: float,
    eps_max: float,
    beta: float,
    deadband: float,
    eps_saturation: float,
) -> float:
    """``ε* = ε_min + (ε_max − ε_min)(1 − e^{−β s̄})`` (Eq. 26).

    Options the paper allows (off at their defaults): a ``deadband`` on the
    filtered score (``s̄ ≤ deadband`` maps to ε_min, above it the excess is
    used) and a ``eps_saturation`` upper clip of ε* (NaN disables it).
    """
    s = score_filtered - deadband
    if s < 0.0:
        s = 0.0
    target = eps_min + (eps_max - eps_min) * (1.0 - np.exp(-beta * s))
    if not np.isnan(eps_saturation) and target > eps_saturation:
        target = eps_saturation
    return float(target)


@njit(cache=True)
def eps_blend(eps_previous: float, eps_star: float, alpha_eps: float) -> float:
    """Applied homotopy parameter ``ε_k = (1 − α_ε) ε_{k−1} + α_ε ε*`` (α_ε: paper Table 1)."""
    return (1.0 - alpha_eps) * eps_previous + alpha_eps * eps_star
