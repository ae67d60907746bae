"""Clohessy–Wiltshire relative motion in closed form (paper Eqs. 3–4, 11).

Units throughout: km, s, km/s, km/s², rad/s. Frame: x radial, y along-track,
z cross-track; the state is ``[x, y, z, ẋ, ẏ, ż]``.

Everything here is a pure function. The ``@njit`` functions are used both from
Python and from the compiled guidance and simulation kernels, so they take and
return plain floats and arrays only.

Closed forms use ``1 − cos x = 2 sin²(x/2)`` and a series for ``x − sin x``
near zero so that short steps (n·Δt ≈ 1e-3) lose no digits to cancellation.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: Mean motion of the paper's scenario [rad/s] (the authors' code's; the paper gives no value).
MEAN_MOTION_PAPER_RAD_S = 0.00104218449


def cw_system(n: float) -> tuple[np.ndarray, np.ndarray]:
    """State and input matrices ``A`` (6×6) and ``B`` (6×3) of Eq. (4).

    Parameters
    ----------
    n : float
        Mean motion of the target's circular orbit [rad/s].
    """
    a = np.zeros((6, 6))
    a[0:3, 3:6] = np.eye(3)
    a[3, 0] = 3.0 * n * n
    a[3, 4] = 2.0 * n
    a[4, 3] = -2.0 * n
    a[5, 2] = -n * n
    b = np.zeros((6, 3))
    b[3:6, :] = np.eye(3)
    return a, b


@njit(cache=True)
def one_minus_cos(x: float) -> float:
    """``1 − cos x`` without cancellation for small ``x``."""
    h = np.sin(0.5 * x)
    return float(2.0 * h * h)


@njit(cache=True)
def x_minus_sin(x: float) -> float:
    """``x − sin x`` without cancellation for small ``x`` (Taylor series to x¹³)."""
    if abs(x) < 0.1:
        x2 = x * x
        # x³/3! − x⁵/5! + x⁷/7! − … ; truncation error < x¹⁵/15! ≈ 8e-28 at x = 0.1
        term = x * x2 / 6.0
        total = term
        k = 3
        for _ in range(5):
            term *= -x2 / ((k + 1) * (k + 2))
            total += term
            k += 2
        return total
    return float(x - np.sin(x))


@njit(cache=True)
def stm(n: float, t: float) -> np.ndarray:
    """State-transition matrix ``Φ(t) = e^{A t}`` in closed form (paper Eq. 11).

    Valid for negative ``t`` too (backward propagation).
    """
    x = n * t
    c = np.cos(x)
    s = np.sin(x)
    omc = one_minus_cos(x)
    xms = x_minus_sin(x)
    p = np.zeros((6, 6))
    p[0, 0] = 1.0 + 3.0 * omc
    p[0, 3] = s / n
    p[0, 4] = 2.0 * omc / n
    p[1, 0] = -6.0 * xms
    p[1, 1] = 1.0
    p[1, 3] = -2.0 * omc / n
    p[1, 4] = t - 4.0 * xms / n
    p[2, 2] = c
    p[2, 5] = s / n
    p[3, 0] = 3.0 * n * s
    p[3, 3] = c
    p[3, 4] = 2.0 * s
    p[4, 0] = -6.0 * n * omc
    p[4, 3] = -2.0 * s
    p[4, 4] = 1.0 - 4.0 * omc
    p[5, 2] = -n * s
    p[5, 5] = c
    return p


@njit(cache=True)
def input_matrix(n: float, t: float) -> np.ndarray:
    """Zero-order-hold input matrix ``Γ(t) = ∫₀ᵗ e^{Aτ} B dτ`` (6×3) in closed form (Eq. 11)."""
    x = n * t
    s = np.sin(x)
    omc = one_minus_cos(x)
    xms = x_minus_sin(x)
    n2 = n * n
    g = np.zeros((6, 3))
    # column of ẋ-impulse: ∫ Φ[:, 3]
    g[0, 0] = omc / n2
    g[1, 0] = -2.0 * xms / n2
    g[3, 0] = s / n
    g[4, 0] = -2.0 * omc / n
    # column of ẏ-impulse: ∫ Φ[:, 4]
    g[0, 1] = 2.0 * xms / n2
    g[1, 1] = 4.0 * omc / n2 - 1.5 * t * t
    g[3, 1] = 2.0 * omc / n
    g[4, 1] = t - 4.0 * xms / n
    # column of ż-impulse: ∫ Φ[:, 5]
    g[2, 2] = omc / n2
    g[5, 2] = s / n
    return g


@njit(cache=True)
def costate_stm(n: float, t: float) -> np.ndarray:
    """Costate transition ``e^{−Aᵀ t} = Φ(−t)ᵀ``, so ``λ(t) = e^{−Aᵀt} λ(0)`` (from paper Eq. 7)."""
    return stm(n, -t).T.copy()


@njit(cache=True)
def costate_derivative(n: float, lam: np.ndarray, out: np.ndarray) -> None:
    """Write ``λ̇ = −Aᵀ λ`` into ``out`` (both length 6)."""
    out[0] = -3.0 * n * n * lam[3]
    out[1] = 0.0
    out[2] = n * n * lam[5]
    out[3] = -lam[0] + 2.0 * n * lam[4]
    out[4] = -lam[1] - 2.0 * n * lam[3]
    out[5] = -lam[2]


def discretize(n: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation ``(Φ, Γ)`` over one step ``dt_s`` (Eq. 11)."""
    return stm(n, dt_s), input_matrix(n, dt_s)


@njit(cache=True)
def zoh_step(phi: np.ndarray, gam: np.ndarray, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """One exact zero-order-hold step ``x⁺ = Φx + Γu`` (Eq. 11), as a new 6-vector.

    Written out (no BLAS call): it runs twice per closed-loop step.
    """
    out = np.empty(6)
    for i in range(6):
        acc = gam[i, 0] * u[0] + gam[i, 1] * u[1] + gam[i, 2] * u[2]
        for j in range(6):
            acc += phi[i, j] * x[j]
        out[i] = acc
    return out


@njit(cache=True)
def zoh_rollout(phi: np.ndarray, gam: np.ndarray, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
    """States ``(N + 1, 6)`` of held controls ``u`` (N, 3) from ``x0``: :func:`zoh_step`'s
    arithmetic, in the same order (the same bits), written into the rows (no 6-vector made
    a step: a third of the time on an 800-step horizon)."""
    x = np.empty((u.shape[0] + 1, 6))
    x[0] = x0
    for k in range(u.shape[0]):
        for i in range(6):
            acc = gam[i, 0] * u[k, 0] + gam[i, 1] * u[k, 1] + gam[i, 2] * u[k, 2]
            for j in range(6):
                acc += phi[i, j] * x[k, j]
            x[k + 1, i] = acc
    return x
