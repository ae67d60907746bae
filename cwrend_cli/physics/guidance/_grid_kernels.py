"""Compiled dual ascent for the cone program on the zero-order-hold grid (private; issue 16).

Units as in :mod:`cwrend_cli.physics.guidance.convex`, whose scaled program
this solves: controls ``ũ_j = u_j/u_max`` (N × 3), terminal rows
``Σ_j A_j ũ_j = b`` with ``A_j = S M_j u_max`` and ``b = S(x_f − Φᴺx̂)``
(``S`` = ``row_scale``), cost ``Σ_j f(ũ_j)`` with
``f(ũ) = c₁‖ũ‖ + c₂‖ũ‖²`` (``c₁ = 1 − ε``, ``c₂ = max(ε, ρ)``) and
``‖ũ_j‖ ≤ 1``.

Lagrange duality with ``L = Σ f(ũ_j) − νᵀ(Σ A_j ũ_j − b)``: for fixed ``ν``
each step minimises ``f(ũ) − y_jᵀũ`` with ``y_j = A_jᵀν`` on its own, in
closed form (the smoothed law of Eq. 10 on the grid):

    ``ũ_j = a_j ŷ_j``,  ``a_j = clip((‖y_j‖ − c₁)/(2c₂), 0, 1)``.

The dual function ``D(ν) = νᵀb − Σ_j f*(y_j)`` is concave with gradient
``b − Σ A_j ũ_j(ν)`` (the negated, scaled terminal residual) and, where no
step sits exactly on a kink, Hessian ``−Σ A_j (∂ũ_j/∂y_j) A_jᵀ`` with

    ``∂ũ/∂y = (a/‖y‖)(I − ŷŷᵀ) + φ′ ŷŷᵀ``,  ``φ′ = 1/(2c₂)`` on the ramp, 0 off it.

Because ``c₂ > 0`` the primal cost is strictly convex: a ``ν`` whose gradient
vanishes gives the program's unique minimiser, and ``ũ(ν)`` is then optimal
by construction (stationary, feasible, ``‖ũ_j‖ ≤ 1`` exactly) — the ascent
needs no certificate beyond its terminal residual. It is the discrete twin of
the shooting solver's ascent (:func:`cwrend_cli.physics.guidance._kernels.newton_ascent`,
same Levenberg–Marquardt steps, Armijo search and settings) and converges in
2–10 iterations for ``c₂ ≥ 1e-3``; near ``c₂ = ρ`` the dual is almost
piecewise linear and Newton is the wrong tool (the caller uses Clarabel).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from cwrend_cli.physics.guidance._kernels import (
    STATUS_CONVERGED,
    STATUS_FAILED,
    STATUS_INFEASIBLE,
    NewtonSettings,
    _cholesky_solve,
    damped_direction,
    step_accepted,
)

#: Relative margin on ``Σ‖A_jᵀν‖`` before a positive certificate counts: far above the
#: rounding of an 800-term sum of O(1) norms (~1e-14 relative).
CERTIFICATE_MARGIN = 1e-12


@njit(cache=True, inline="always")
def _slope(a: np.ndarray, s: int, vec: np.ndarray) -> tuple[float, float, float]:
    """``y_s = A_sᵀ vec`` (3,), summed over the six rows in order."""
    y0 = 0.0
    y1 = 0.0
    y2 = 0.0
    for i in range(6):
        y0 += a[s, i, 0] * vec[i]
        y1 += a[s, i, 1] * vec[i]
        y2 += a[s, i, 2] * vec[i]
    return y0, y1, y2


@njit(cache=True)
def step_law(
    a: np.ndarray, s: int, vec: np.ndarray, c1: float, c2: float, u: np.ndarray
) -> tuple[float, float, bool, float, float, float]:
    """Step ``s``'s minimiser of ``f(ũ) − y_sᵀũ``, ``y_s = A_sᵀ vec`` (the smoothed law of
    paper Eq. 10 on the grid, module docstring): writes ``ũ_s`` into ``u[s]``; returns
    ``(‖y_s‖, a_s, on the ramp, ŷ_s)``, ``a_s = 0`` (and ŷ_s zero) on a coasting step."""
    y0, y1, y2 = _slope(a, s, vec)
    ny = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    level = (ny - c1) / (2.0 * c2)
    if level <= 0.0:
        u[s, 0] = 0.0
        u[s, 1] = 0.0
        u[s, 2] = 0.0
        return ny, 0.0, False, 0.0, 0.0, 0.0
    ramp = level < 1.0
    if not ramp:
        level = 1.0
    h0 = y0 / ny
    h1 = y1 / ny
    h2 = y2 / ny
    u[s, 0] = level * h0
    u[s, 1] = level * h1
    u[s, 2] = level * h2
    return ny, level, ramp, h0, h1, h2


@njit(cache=True, inline="always")
def step_law_by_products(
    a: np.ndarray, s: int, vec: np.ndarray, c1: float, ramp_slope: float, u: np.ndarray
) -> tuple[float, float, bool, float, float, float, float]:
    """:func:`step_law` with products for its divisions (``ramp_slope = 1/(2c₂)``, and
    ``1/‖y_s‖`` once): a third faster, rounded differently in the last bit. Returns
    :func:`step_law`'s tuple and ``1/‖y_s‖`` (0 on a coasting step). :mod:`.path_dual`'s
    passes use it; this module's ascent keeps :func:`step_law`, whose unconstrained plans
    are pinned bit for bit (``tests/test_same_numbers.py``)."""
    y0, y1, y2 = _slope(a, s, vec)
    ny = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    level = (ny - c1) * ramp_slope
    if level <= 0.0:
        u[s, 0] = 0.0
        u[s, 1] = 0.0
        u[s, 2] = 0.0
        return ny, 0.0, False, 0.0, 0.0, 0.0, 0.0
    ramp = level < 1.0
    if not ramp:
        level = 1.0
    inv = 1.0 / ny
    h0 = y0 * inv
    h1 = y1 * inv
    h2 = y2 * inv
    u[s, 0] = level * h0
    u[s, 1] = level * h1
    u[s, 2] = level * h2
    return ny, level, ramp, h0, h1, h2, inv


@njit(cache=True)
def grid_dual(
    a: np.ndarray,
    b: np.ndarray,
    nu: np.ndarray,
    c1: float,
    c2: float,
    grad: np.ndarray,
    hess: np.ndarray,
    u: np.ndarray,
) -> tuple[float, float]:
    """``(D(ν), c(ν))``; writes the gradient, Hessian and minimising controls ``ũ(ν)`` (N × 3).

    ``c(ν) = νᵀb − (1 + m) Σ_j ‖A_jᵀν‖`` is the infeasibility certificate:
    by weak duality no controls with ``‖ũ_j‖ ≤ 1`` reach ``b`` if it is
    positive (``m`` = :data:`CERTIFICATE_MARGIN` covers the rounding of the sum).
    """
    steps = a.shape[0]
    for i in range(6):
        grad[i] = b[i]
        for j in range(6):
            hess[i, j] = 0.0
    conj = 0.0
    norm_sum = 0.0
    ay = np.empty(6)
    for s in range(steps):
        ny, level, ramp, h0, h1, h2 = step_law(a, s, nu, c1, c2, u)
        norm_sum += ny
        if level <= 0.0:
            continue
        conj += ny * level - c1 * level - c2 * level * level  # f*(y) = yᵀũ − f(ũ)
        iso = level / ny
        rad = (1.0 / (2.0 * c2) if ramp else 0.0) - iso
        for i in range(6):
            ay[i] = a[s, i, 0] * h0 + a[s, i, 1] * h1 + a[s, i, 2] * h2
            grad[i] -= level * ay[i]
        for i in range(6):
            for j in range(i, 6):
                aa = a[s, i, 0] * a[s, j, 0] + a[s, i, 1] * a[s, j, 1] + a[s, i, 2] * a[s, j, 2]
                hess[i, j] -= iso * aa + rad * ay[i] * ay[j]
    for i in range(6):
        for j in range(i):
            hess[i, j] = hess[j, i]
    gain = 0.0
    for i in range(6):
        gain += nu[i] * b[i]
    return gain - conj, gain - norm_sum * (1.0 + CERTIFICATE_MARGIN)


@njit(cache=True)
def _gram(a: np.ndarray, out: np.ndarray) -> None:
    """``Σ_j A_j A_jᵀ``: the Hessian's scale on a full burn (the cold start solves with it)."""
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for s in range(a.shape[0]):
                acc += a[s, i, 0] * a[s, j, 0] + a[s, i, 1] * a[s, j, 1] + a[s, i, 2] * a[s, j, 2]
            out[i, j] = acc


@njit(cache=True)
def _miss(grad: np.ndarray, row_scale: np.ndarray) -> tuple[float, float]:
    """``(‖Δr‖, ‖Δv‖)`` of the terminal state [km, km/s] from the scaled gradient."""
    rp = 0.0
    rv = 0.0
    for i in range(3):
        rp += (grad[i] / row_scale[i]) ** 2
        rv += (grad[i + 3] / row_scale[i + 3]) ** 2
    return np.sqrt(rp), np.sqrt(rv)


@njit(cache=True)
def cold_start(a: np.ndarray, b: np.ndarray, c1: float, c2: float, out: np.ndarray) -> bool:
    """A first ``ν`` with no plan to start from: the minimum-energy direction ``G⁻¹b``.

    Scaled so that the busiest step sits at half throttle (``‖y_j‖ = c₁ + c₂``),
    where the Hessian already sees every step that thrusts. False if ``b = 0``.
    """
    gram = np.empty((6, 6))
    _gram(a, gram)
    direction = np.empty(6)
    if not _cholesky_solve(gram, b, direction):
        return False
    peak = 0.0
    for s in range(a.shape[0]):
        y = 0.0
        for k in range(3):
            acc = 0.0
            for i in range(6):
                acc += a[s, i, k] * direction[i]
            y += acc * acc
        peak = max(peak, np.sqrt(y))
    if not peak > 0.0:
        return False
    for i in range(6):
        out[i] = direction[i] * (c1 + c2) / peak
    return True


@njit(cache=True)
def grid_dual_ascent(
    a: np.ndarray,
    b: np.ndarray,
    row_scale: np.ndarray,
    c1: float,
    c2: float,
    nu0: np.ndarray,
    settings_t: tuple[Any, ...],
    nu_out: np.ndarray,
    u_out: np.ndarray,
) -> tuple[int, int, float, float]:
    """Maximise ``D`` from ``nu0``; returns ``(status, iterations, ‖Δr‖, ‖Δv‖)``.

    Stops when the terminal miss of ``ũ(ν)`` is within the tolerances of
    ``settings_t`` (a :class:`NewtonSettings` as a tuple, whose damping,
    search and iteration limits it also uses). Status 0 converged
    (``nu_out``, ``u_out`` the solution), 1 infeasible (``nu_out`` a
    certificate, :func:`grid_dual`), 2 failed (iteration limit or stalled
    search; the caller then solves the program with Clarabel).
    """
    settings = NewtonSettings(*settings_t)
    metric = np.empty(6)  # the Levenberg–Marquardt metric: diag Σ A_j A_jᵀ
    for i in range(6):
        acc = 0.0
        for s in range(a.shape[0]):
            acc += a[s, i, 0] * a[s, i, 0] + a[s, i, 1] * a[s, i, 1] + a[s, i, 2] * a[s, i, 2]
        metric[i] = acc
    steps = a.shape[0]
    nu = nu0.copy()
    grad = np.empty(6)
    hess = np.empty((6, 6))
    grad_t = np.empty(6)
    hess_t = np.empty((6, 6))
    u_t = np.empty((steps, 3))
    nu_t = np.empty(6)
    step = np.empty(6)
    mat = np.empty((6, 6))
    value, cert = grid_dual(a, b, nu, c1, c2, grad, hess, u_out)
    rp, rv = _miss(grad, row_scale)
    mu = 0.0
    for it in range(settings.max_iter + 1):
        if rp <= settings.tol_pos_km and rv <= settings.tol_vel_km_s:
            nu_out[:] = nu
            return STATUS_CONVERGED, it, rp, rv
        if cert > 0.0:
            nu_out[:] = nu
            return STATUS_INFEASIBLE, it, rp, rv
        if it == settings.max_iter:
            break
        merit = (rp / settings.tol_pos_km) ** 2 + (rv / settings.tol_vel_km_s) ** 2
        accepted = False
        alpha = 1.0
        value_t = value
        cert_t = cert
        rp_t = rp
        rv_t = rv
        for _attempt in range(settings.max_damping_tries):
            if not damped_direction(hess, metric, max(mu, settings.damping_floor), grad, mat, step):
                mu = max(settings.damping_growth * mu, settings.damping_start_indefinite)
                continue
            slope = 0.0
            for i in range(6):
                slope += grad[i] * step[i]
            alpha = 1.0
            for _ls in range(settings.max_halvings):
                for i in range(6):
                    nu_t[i] = nu[i] + alpha * step[i]
                value_t, cert_t = grid_dual(a, b, nu_t, c1, c2, grad_t, hess_t, u_t)
                rp_t, rv_t = _miss(grad_t, row_scale)
                merit_t = (rp_t / settings.tol_pos_km) ** 2 + (rv_t / settings.tol_vel_km_s) ** 2
                accepted = step_accepted(value_t, value, alpha, slope, merit_t, merit, settings_t)
                if accepted:
                    break
                alpha *= 0.5
            if accepted:
                break
            mu = max(settings.damping_growth * mu, settings.damping_start_search)
        if not accepted:
            break
        nu[:] = nu_t
        grad[:] = grad_t
        hess[:, :] = hess_t
        u_out[:, :] = u_t
        value = value_t
        cert = cert_t
        rp = rp_t
        rv = rv_t
        if alpha == 1.0:
            mu = mu * settings.damping_shrink if mu > settings.damping_off else 0.0
    nu_out[:] = nu
    return STATUS_FAILED, it, rp, rv
