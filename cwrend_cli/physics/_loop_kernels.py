"""Compiled step loop of the closed loop (private; see :mod:`cwrend_cli.physics.simulation`).

One step k (SPEC §5, authors' order): control from the current costate and ε
→ truth step → measurement (noise of the window at t_k) → KF predict →
innovation, NIS, MTF → update → score → ε → [re-solve, done by the caller]
→ costate propagated by Δt.

The loop runs in compiled code between re-solves; :func:`advance` stops right
after the ε update of a step that has a re-solve due, and the Python driver
performs the re-solve and sets the costate. Units: km, s, km/s, km/s².
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cwrend_cli.physics.dynamics import zoh_step
from cwrend_cli.physics.estimation import kf_predict, kf_update
from cwrend_cli.physics.guidance._kernels import (
    MAX_BREAKS,
    MAX_QUAD_BREAKS,
    arc_bounds,
    control_from_costate,
    costate_at,
    quadrature_breaks,
)
from cwrend_cli.physics.scheduling import composite_score, eps_blend, eps_target, lowpass_score

# Indices into the scalar state vector.
EPS = 0
SCORE_FILTERED = 1
FIRST = 2

# Indices into the schedule parameter vector.
P_NIS_OFFSET = 0
P_KAPPA = 1
P_SCORE_MAX = 2
P_RHO_S = 3
P_EPS_MIN = 4
P_EPS_MAX = 5
P_BETA = 6
P_DEADBAND = 7
P_EPS_SAT = 8
P_ALPHA = 9
N_SCHEDULE_PARAMS = 10


@njit(cache=True)
def mean_control(
    n: float,
    lam: np.ndarray,
    dt: float,
    eps: float,
    u_max: float,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    work: np.ndarray,
    out: np.ndarray,
) -> None:
    """Plan's control averaged over ``[0, dt]`` from costate ``lam`` (``guidance.hold = "mean"``).

    Integrated exactly arc by arc between switching times, so its norm never
    exceeds ``u_max``.
    """
    switches = work[8, :MAX_BREAKS]
    breaks = np.empty(MAX_QUAD_BREAKS)
    _, n_breaks = quadrature_breaks(n, lam, 0.0, dt, eps, 1, switches, breaks, work)
    lam_t = work[7, :6]
    u = np.empty(3)
    acc0 = 0.0
    acc1 = 0.0
    acc2 = 0.0
    for arc in range(n_breaks + 1):
        a, b = arc_bounds(arc, n_breaks, breaks, 0.0, dt)
        if b <= a:
            continue
        half = 0.5 * (b - a)
        mid = 0.5 * (a + b)
        for k in range(gl_x.shape[0]):
            costate_at(n, mid + half * gl_x[k], lam, lam_t)
            control_from_costate(lam_t[3:6], eps, u_max, u)
            wk = half * gl_w[k]
            acc0 += wk * u[0]
            acc1 += wk * u[1]
            acc2 += wk * u[2]
    out[0] = acc0 / dt
    out[1] = acc1 / dt
    out[2] = acc2 / dt


@njit(cache=True)
def advance(
    k_start: int,
    k_stop: int,
    n_steps: int,
    phi: np.ndarray,
    gam: np.ndarray,
    lam_step: np.ndarray,
    q: np.ndarray,
    r_nominal: np.ndarray,
    noise: np.ndarray,
    use_mtf: bool,
    adaptive: bool,
    hold_mean: bool,
    sched: np.ndarray,
    n: float,
    u_max: float,
    dt: float,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    u_override: np.ndarray,
    override: np.ndarray,
    x_true: np.ndarray,
    x_hat: np.ndarray,
    p: np.ndarray,
    lam: np.ndarray,
    scal: np.ndarray,
    log_x: np.ndarray,
    log_xhat: np.ndarray,
    log_u: np.ndarray,
    log_y: np.ndarray,
    log_nis: np.ndarray,
    log_rho: np.ndarray,
    log_score: np.ndarray,
    log_score_f: np.ndarray,
    log_eps: np.ndarray,
    log_trp: np.ndarray,
) -> None:
    """Run steps ``k_start … k_stop``; the last one stops before its costate propagation.

    When ``k_stop == n_steps`` every step up to the end runs in full. State
    arrays (``x_true``, ``x_hat``, ``p``, ``lam``, ``scal``) are updated in
    place; row ``k + 1`` of the logs receives the step's results.
    """
    work = np.empty((9, MAX_BREAKS))
    u = np.empty(3)
    lam_next = np.empty(6)
    for k in range(k_start, min(k_stop + 1, n_steps)):
        eps = scal[EPS]
        # control from the current costate and ε (Eqs. 8–10), held over the step
        if override[k]:
            u[:] = u_override[k]
        elif hold_mean:
            mean_control(n, lam, dt, eps, u_max, gl_x, gl_w, work, u)
        else:
            control_from_costate(lam[3:6], eps, u_max, u)
        log_u[k] = u
        # truth step with zero-order hold: x_{k+1} = Φ x_k + Γ u_k (exact)
        x_next = zoh_step(phi, gam, x_true, u)
        x_true[:] = x_next
        # measurement of the new position with the noise of the window at t_k
        y = x_next[:3] + noise[k]
        # Kalman filter predict and update (Eqs. 11–23)
        x_pred, p_pred = kf_predict(x_hat, p, phi, gam, u, q)
        x_post, p_post, nis, rho = kf_update(x_pred, p_pred, y, r_nominal, use_mtf)
        x_hat[:] = x_post
        p[:, :] = p_post
        # score and homotopy parameter (Eqs. 24–26)
        score = composite_score(nis, rho, sched[P_NIS_OFFSET], sched[P_KAPPA], sched[P_SCORE_MAX])
        sbar = lowpass_score(scal[SCORE_FILTERED], score, sched[P_RHO_S], scal[FIRST] > 0.5)
        scal[SCORE_FILTERED] = sbar
        scal[FIRST] = 0.0
        if adaptive:
            target = eps_target(
                sbar,
                sched[P_EPS_MIN],
                sched[P_EPS_MAX],
                sched[P_BETA],
                sched[P_DEADBAND],
                sched[P_EPS_SAT],
            )
            scal[EPS] = eps_blend(eps, target, sched[P_ALPHA])
        row = k + 1
        log_x[row] = x_next
        log_xhat[row] = x_post
        log_y[row] = y
        log_nis[row] = nis
        log_rho[row] = rho
        log_score[row] = score
        log_score_f[row] = sbar
        log_eps[row] = scal[EPS]
        log_trp[row] = (
            p_post[0, 0] + p_post[1, 1] + p_post[2, 2] + p_post[3, 3] + p_post[4, 4] + p_post[5, 5]
        )
        if k == k_stop:
            return  # the caller re-solves and sets the costate
        # costate propagated exactly by one step: λ ← e^{−AᵀΔt} λ
        for i in range(6):
            acc = 0.0
            for j in range(6):
                acc += lam_step[i, j] * lam[j]
            lam_next[i] = acc
        lam[:] = lam_next
