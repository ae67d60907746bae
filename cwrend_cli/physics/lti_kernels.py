"""Compiled closed form of a time-invariant design model (issue 33): Φ(t), W(τ), the primer.

The model is :class:`cwrend_cli.physics.design_models.LinearTimeInvariant`,
``ẍ = α x + β ẏ + u_x``, ``ÿ = −β ẋ + u_y``, ``z̈ = −q² z + u_z``: CW with
α = 3n², β = 2n, q = n (paper Eq. 4), Schweighart & Sedwick (2002, J. Guid.
Control Dyn. 25(6), with their constant coefficients) with
α = (5c² − 2)n², β = 2nc, q = n√(3c² − 2). The compiled kernels take it as
an :class:`LtiKernel` (a NamedTuple of floats). CW's own closed forms
(:mod:`cwrend_cli.physics.dynamics`, paper Eq. 11) stay what the CW guidance
computes with; these serve the other time-invariant models.

With θ = ωt, ω = √(β² − α) (1 − cos θ and θ − sin θ without cancellation)::

    x = x₀ (1 + α/ω² (1 − cos θ)) + ẋ₀ sin θ/ω + ẏ₀ β/ω² (1 − cos θ)
    y = y₀ − x₀ βα/ω³ (θ − sin θ) − ẋ₀ β/ω² (1 − cos θ) + ẏ₀ (t − β²/ω³ (θ − sin θ))

their time derivatives, and z = z₀ cos qt + ż₀ sin(qt)/q.

The primer vector of the minimum-fuel problem (Lawden 1963; paper Eqs. 7–9)
of ``ẋ = A x + B u`` is ``λ_v(τ) = Bᵀ e^{−Aᵀτ} λ₀ = W(τ)ᵀ λ₀`` with
``W(τ) = Φ(−τ) B``, and its k-th derivative is ``W(τ)ᵀ (−Aᵀ)ᵏ λ₀``
(:func:`primer`).

Units: km, s, km/s, km/s², rad/s. State ``[x, y, z, ẋ, ẏ, ż]``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cwrend_cli.physics.dynamics import one_minus_cos, x_minus_sin

#: The design model as the guidance kernels take it (:mod:`cwrend_cli.physics.guidance._kernels`):
#: CW's mean motion [rad/s], or the plain tuple of an :class:`LtiKernel`.
KernelModel = float | tuple[float, ...]


class LtiKernel(NamedTuple):
    """The coefficients of a time-invariant model as the compiled kernels take them."""

    alpha: float  # radial stiffness α [1/s²]
    beta: float  # Coriolis coefficient β [rad/s]
    q: float  # cross-track frequency q [rad/s]
    omega: float  # in-plane frequency ω = √(β² − α) [rad/s]


@njit(cache=True)
def velocity_columns(m: LtiKernel, t: float, out: np.ndarray) -> None:
    """Write the velocity columns ``Φ(t)[:, 3:6] = e^{At} B`` (6×3) into ``out``.

    Valid for negative ``t``: ``velocity_columns(m, −τ, w)`` writes ``W(τ)``.
    """
    w, be = m.omega, m.beta
    th = w * t
    s, c = np.sin(th), np.cos(th)
    omc, xms = one_minus_cos(th), x_minus_sin(th)
    w2, w3 = w * w, w * w * w
    qt = m.q * t
    out[0, 0] = s / w
    out[0, 1] = be / w2 * omc
    out[0, 2] = 0.0
    out[1, 0] = -be / w2 * omc
    out[1, 1] = t - be * be / w3 * xms
    out[1, 2] = 0.0
    out[2, 0] = 0.0
    out[2, 1] = 0.0
    out[2, 2] = np.sin(qt) / m.q
    out[3, 0] = c
    out[3, 1] = be / w * s
    out[3, 2] = 0.0
    out[4, 0] = -be / w * s
    out[4, 1] = 1.0 - be * be / w2 * omc
    out[4, 2] = 0.0
    out[5, 0] = 0.0
    out[5, 1] = 0.0
    out[5, 2] = np.cos(qt)


@njit(cache=True)
def transition(m: LtiKernel, t: float) -> np.ndarray:
    """``Φ(t) = e^{At}`` (6×6) in closed form (module docstring); valid for negative ``t``."""
    w, al, be = m.omega, m.alpha, m.beta
    th = w * t
    s = np.sin(th)
    omc, xms = one_minus_cos(th), x_minus_sin(th)
    w2, w3 = w * w, w * w * w
    qt = m.q * t
    p = np.zeros((6, 6))
    p[0, 0] = 1.0 + al / w2 * omc
    p[1, 0] = -be * al / w3 * xms
    p[1, 1] = 1.0
    p[3, 0] = al / w * s
    p[4, 0] = -be * al / w2 * omc
    p[2, 2] = np.cos(qt)
    p[5, 2] = -m.q * np.sin(qt)
    velocity_columns(m, t, p[:, 3:6])
    return p


@njit(cache=True)
def primer(
    m: LtiKernel, lam0: np.ndarray, tau: float, order: int, q: np.ndarray, w: np.ndarray
) -> None:
    """``λ_v(τ) = W(τ)ᵀ λ₀`` and its first ``order`` time derivatives into rows of ``q`` (4×3).

    The k-th derivative is ``W(τ)ᵀ μ_k`` with ``μ_k = (−Aᵀ)ᵏ λ₀``, since
    ``d/dτ e^{−Aᵀτ} = e^{−Aᵀτ}(−Aᵀ)``; ``−Aᵀλ = (−αλ_ẋ, 0, q²λ_ż, −λ_x + βλ_ẏ,
    −λ_y − βλ_ẋ, −λ_z)``. ``w`` (6×3) is scratch (it receives ``W(τ)``).
    """
    velocity_columns(m, -tau, w)
    m0, m1, m2, m3, m4, m5 = lam0[0], lam0[1], lam0[2], lam0[3], lam0[4], lam0[5]
    al, be, q2 = m.alpha, m.beta, m.q * m.q
    for k in range(order + 1):
        for c in range(3):
            q[k, c] = (
                w[0, c] * m0 + w[1, c] * m1 + w[2, c] * m2
                + w[3, c] * m3 + w[4, c] * m4 + w[5, c] * m5
            )  # fmt: skip
        m0, m1, m2, m3, m4, m5 = -al * m3, 0.0, q2 * m5, -m0 + be * m4, -m1 - be * m3, -m2
