"""Compiled Newton on the switching structure of a bang-bang plan (private; issue 17).

Units: km, s, km/s, km/s², rad/s. Arrays and floats only.

At ε = 0 the dual ascent of :mod:`._kernels` is slow in the coasting re-solves
of the closed loop: each of them needs a short burn at τ = 0 (0.3–0.6 s with
the paper's sample hold) that the warm start lacks, the burn's length is
``(‖λ_v(0)‖ − 1)/|ṗ(0)|`` with ``|ṗ(0)|`` down to 1e-5, and in half of them
the burn's direction is opposite to the warm start's primer (the sample hold
over-executes a sub-second burn, which the next re-solve takes back), so the
dual's quadratic model is poor all the way. The median warm re-solve took 10
damped iterations, the ε = 0.05 one 2–3; with this module first, 4 (3 with
the mean hold; 5 before the new burn started at :func:`predicted_length`),
most of them cheap (seeds 0–19, README "Performance").

This module solves the same optimality conditions with the switching times as
unknowns beside ``λ₀``, the classical switching-time shooting: with the burns
``[a_i, b_i]`` (an end either fixed at 0 or at the horizon ``T``, or a
switching time ``t_k``), the unknowns ``z = (λ₀, t_1 … t_m)`` solve

    F_G(z) = Σ_i ∫_{a_i}^{b_i} W(τ) (−u_max q̂(τ)) dτ − d = 0    (6 equations; paper Eq. 10, ε = 0)
    F_k(z) = ‖λ_v(t_k)‖ − 1 = 0                                  (one per switching time)

which is smooth in ``z`` for a fixed structure, even where a burn has zero or
negative length, so Newton converges quadratically where the structure is
right, with no ``1/|ṗ|`` blow-up (the reduced Hessian's jump term) near a
burn about to be born. The structure starts from the warm start's switching
times plus a burn at τ = 0 where ``‖λ_v‖`` falls there below 1, started at
the length that best cuts the miss with the rest held (at zero length its
direction has no lever) and given its length by Newton; when Newton has
converged, the single most violated boundary condition (a switching time
beyond 0 or ``T``, a fixed end where ``‖λ_v‖ < 1``, a burn of negative
length) changes the structure and Newton goes on: a small active-set method.

Nothing here decides that a re-solve converged. :func:`bang_bang_ascent`
accepts its answer only after the full evaluation of :mod:`._kernels`
(switching times found afresh over the whole horizon) has measured the
terminal miss within the tolerances, which makes ``λ₀`` the maximiser of the
concave dual, i.e. the minimum-fuel plan: a wrong structure can cost time,
never a wrong answer. Otherwise the damped dual ascent runs as before (from
the same starts, or beside them from a consistent but unconfirmed answer of
this method), and the iterations of both count.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, typeof, types

from cwrend_cli.physics.guidance import _kernels as kern
from cwrend_cli.physics.lti_kernels import KernelModel

#: An end of a burn fixed at 0 or at the horizon.
END_FIXED = 0
#: An end of a burn at a switching time (an unknown).
END_SWITCH = 1
#: Most burns the structure tracks.
MAX_BURNS = 16
#: Longest quadrature arc of a burn [s]: with ``‖λ̇_v‖ ≤ 1e-2/s`` on the paper's plans the
#: integrand's complex singularities lie ≥ 100 s off the axis, 5 half-arcs away.
MAX_ARC_S = 40.0
#: Most structure changes of one solve.
MAX_CHANGES = 4


@njit(cache=True)
def burn_integral(
    n: KernelModel,
    lam0: np.ndarray,
    a: float,
    b: float,
    u_max: float,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    grad: np.ndarray,
    hess: np.ndarray,
    w: np.ndarray,
    wq: np.ndarray,
) -> None:
    """Add ``∫_a^b W u dτ`` at full thrust and its ``λ₀``-derivative (upper triangle).

    ``b < a`` integrates backwards (a burn of negative length: the smooth
    extension of the structure). Gauss–Legendre on arcs of at most
    :data:`MAX_ARC_S`.
    """
    with_hess = bool(np.bool_(True))  # a runtime flag, not a literal (_kernels' docstring)
    span = b - a
    arcs = max(1, int(np.ceil(abs(span) / MAX_ARC_S)))
    h = span / arcs
    for arc in range(arcs):
        half = 0.5 * h
        mid = a + arc * h + half
        for k in range(gl_x.shape[0]):
            tau = mid + half * gl_x[k]
            kern.model_input_kernel(n, tau, w)
            q0, q1, q2, p = kern.node_primer(lam0, w)
            wk = half * gl_w[k]
            kern.add_control_node(w, q0, q1, q2, p, wk, 1.0, 0.0, u_max, with_hess, grad, hess, wq)


@njit(cache=True)
def initial_burns(
    n: KernelModel,
    lam0: np.ndarray,
    horizon: float,
    n_cells: int,
    times: np.ndarray,
    kinds: np.ndarray,
) -> int:
    """The burns of ``λ₀`` (rows of ``times``/``kinds``), plus one of zero length at τ = 0.

    The zero-length burn is added when ``‖λ_v‖ < 1`` and falling at τ = 0:
    the coast begins at the current time, where the closed loop's next
    correction goes (module docstring). Returns the number of burns.
    """
    ws = kern.workspace()
    switches = np.empty(kern.MAX_BREAKS)
    minima = np.empty(kern.MAX_BREAKS)
    count, _ = kern.find_switches(n, lam0, 0.0, horizon, 0.0, n_cells, switches, minima, ws)
    p0, pdot0, _ = kern._speed_and_rate(n, 0.0, lam0, ws)
    nb = 0
    thrusting = p0 > 1.0
    if not thrusting and pdot0 < 0.0:
        times[0, 0] = 0.0
        kinds[0, 0] = END_FIXED
        times[0, 1] = 0.0
        kinds[0, 1] = END_SWITCH
        nb = 1
    start = 0.0
    start_kind = END_FIXED
    for i in range(count):
        if nb >= MAX_BURNS:
            return -1
        if thrusting:
            times[nb, 0] = start
            kinds[nb, 0] = start_kind
            times[nb, 1] = switches[i]
            kinds[nb, 1] = END_SWITCH
            nb += 1
        else:
            start = switches[i]
            start_kind = END_SWITCH
        thrusting = not thrusting
    if thrusting:
        if nb >= MAX_BURNS:
            return -1
        times[nb, 0] = start
        kinds[nb, 0] = start_kind
        times[nb, 1] = horizon
        kinds[nb, 1] = END_FIXED
        nb += 1
    return nb


@njit(cache=True)
def joint_system(
    n: KernelModel,
    lam0: np.ndarray,
    d: np.ndarray,
    u_max: float,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    nb: int,
    times: np.ndarray,
    kinds: np.ndarray,
    f: np.ndarray,
    jac: np.ndarray,
) -> int:
    """Residual ``F = [F_G; F_k]`` and its Jacobian in ``z = (λ₀, t_k)``; returns ``6 + m``.

    ``∂F_G/∂λ₀`` is the integral part of the dual Hessian (no jump terms),
    ``∂F_G/∂t_k = ±W(t_k) u(t_k)`` (+ at a burn's end, − at its start),
    ``∂F_k/∂λ₀ = (W(t_k) q̂(t_k))ᵀ`` and ``∂F_k/∂t_k = ṗ(t_k)``.
    """
    ws = kern.workspace()
    w = np.empty((6, 3))
    wq = np.empty(6)
    hess = np.zeros((6, 6))
    m = 6
    for b in range(nb):
        for e in range(2):
            if kinds[b, e] == END_SWITCH:
                m += 1
    for i in range(m):
        f[i] = 0.0
        for j in range(m):
            jac[i, j] = 0.0
    for b in range(nb):
        burn_integral(n, lam0, times[b, 0], times[b, 1], u_max, gl_x, gl_w, f, hess, w, wq)
    for i in range(6):
        f[i] -= d[i]
        for j in range(6):
            jac[i, j] = hess[min(i, j), max(i, j)]
    k = 6
    lam = ws[kern.WS_LAM]
    for b in range(nb):
        for e in range(2):
            if kinds[b, e] != END_SWITCH:
                continue
            t = times[b, e]
            p, pdot, _ = kern._speed_and_rate(n, t, lam0, ws)
            kern.model_input_kernel(n, t, w)
            sign = 1.0 if e == 1 else -1.0
            for i in range(6):
                wqi = (w[i, 0] * lam[3] + w[i, 1] * lam[4] + w[i, 2] * lam[5]) / p
                jac[i, k] = -sign * u_max * wqi
                jac[k, i] = wqi
            jac[k, k] = pdot
            f[k] = p - 1.0
            k += 1
    return m


@njit(cache=True)
def solve_dense(a: np.ndarray, b: np.ndarray, m: int, out: np.ndarray) -> bool:
    """Solve the leading ``m×m`` system ``a x = b`` (partial pivoting); False if singular."""
    mat = a[:m, :m].copy()
    rhs = b[:m].copy()
    for c in range(m):
        piv = c
        best = abs(mat[c, c])
        for i in range(c + 1, m):
            if abs(mat[i, c]) > best:
                best = abs(mat[i, c])
                piv = i
        if not (best > 0.0) or not np.isfinite(best):
            return False
        if piv != c:
            for j in range(m):
                tmp = mat[c, j]
                mat[c, j] = mat[piv, j]
                mat[piv, j] = tmp
            tmp = rhs[c]
            rhs[c] = rhs[piv]
            rhs[piv] = tmp
        for i in range(c + 1, m):
            factor = mat[i, c] / mat[c, c]
            for j in range(c, m):
                mat[i, j] -= factor * mat[c, j]
            rhs[i] -= factor * rhs[c]
    for i in range(m - 1, -1, -1):
        s = rhs[i]
        for j in range(i + 1, m):
            s -= mat[i, j] * out[j]
        out[i] = s / mat[i, i]
    return True


@njit(cache=True)
def update_structure(
    n: KernelModel, lam0: np.ndarray, horizon: float, nb: int, times: np.ndarray, kinds: np.ndarray
) -> tuple[int, bool]:
    """At a solution of the joint system, change the most violated boundary condition.

    Violations, in ``‖λ_v‖`` units: a switching time beyond 0 or ``T`` (the
    burn then ends there, or vanishes if it lies wholly outside), a fixed end
    where ``‖λ_v‖ < 1`` (it becomes a switching time), and a burn of zero or
    negative length (it vanishes; counted as 1, so it goes first: the burn
    at τ = 0 that Newton gave a negative length is dropped, not turned
    into a burn starting later). Returns
    ``(burns, changed)``; unchanged means the structure is consistent.
    """
    ws = kern.workspace()
    p_start, _, _ = kern._speed_and_rate(n, 0.0, lam0, ws)
    p_end, _, _ = kern._speed_and_rate(n, horizon, lam0, ws)
    worst = 0.0
    worst_b = -1
    worst_e = -1
    for b in range(nb):
        vanished = times[b, 1] <= times[b, 0]
        for e in range(2):
            t = times[b, e]
            v = 0.0
            if vanished:
                v = 1.0
            elif kinds[b, e] == END_SWITCH and t < 0.0:
                v = abs(p_start - 1.0) + 1e-300
            elif kinds[b, e] == END_SWITCH and t > horizon:
                v = abs(p_end - 1.0) + 1e-300
            elif kinds[b, e] == END_FIXED and t == 0.0 and p_start < 1.0:
                v = 1.0 - p_start
            elif kinds[b, e] == END_FIXED and t == horizon and p_end < 1.0:
                v = 1.0 - p_end
            if v > worst:
                worst = v
                worst_b = b
                worst_e = e
    if worst_b < 0:
        return nb, False
    b = worst_b
    e = worst_e
    t = times[b, e]
    drop = False
    if times[b, 1] <= times[b, 0]:
        drop = True
    elif kinds[b, e] == END_SWITCH:
        bound = 0.0 if t < 0.0 else horizon
        drop = (e == 1 and t < 0.0) or (e == 0 and t > horizon) or times[b, 1 - e] == bound
        times[b, e] = bound
        kinds[b, e] = END_FIXED
    else:
        kinds[b, e] = END_SWITCH
    if drop:
        for j in range(b, nb - 1):
            for c in range(2):
                times[j, c] = times[j + 1, c]
                kinds[j, c] = kinds[j + 1, c]
        nb -= 1
    return nb, True


@njit(cache=True)
def predicted_length(
    n: KernelModel,
    lam0: np.ndarray,
    d: np.ndarray,
    horizon: float,
    u_max: float,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    nb: int,
    times: np.ndarray,
    kinds: np.ndarray,
    f: np.ndarray,
    jac: np.ndarray,
) -> float:
    """Length [s] of the new burn at τ = 0 (``times[0]``, of zero length) that best cuts the miss.

    With the rest of the plan held, a burn of length ``δ`` at τ = 0 moves the
    terminal condition by ``δ ∂F_G/∂t_1`` (its column of the joint Jacobian);
    the least-squares ``δ ≥ 0`` on ``F_G`` with the velocity rows in
    position units (× horizon) is where Newton starts. From zero length the
    burn has no direction lever (``∂F_G/∂λ₀`` of a burn scales with its
    length), so the first Newton step turned ``λ_v`` far to redirect the miss
    and came back over 3–5 steps; from here the median ε = 0 warm re-solve
    of seeds 0–19 takes 4 Newton steps instead of 5 (the 5–7-step group,
    1,216 of 3,120, to 4; the same 2,919 solved).
    """
    m = joint_system(n, lam0, d, u_max, gl_x, gl_w, nb, times, kinds, f, jac)
    num = 0.0
    den = 0.0
    for i in range(6):
        w = 1.0 if i < 3 else horizon
        num += (jac[i, 6] * w) * (f[i] * w)
        den += (jac[i, 6] * w) ** 2
    if m <= 6 or not den > 0.0:
        return 0.0
    return max(-num / den, 0.0)


@njit(cache=True)
def switching_newton(
    n: KernelModel,
    lam_start: np.ndarray,
    d: np.ndarray,
    horizon: float,
    u_max: float,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    n_cells: int,
    tol_pos: float,
    tol_vel: float,
    max_iter: int,
    lam_out: np.ndarray,
) -> tuple[bool, int]:
    """Newton on the joint system with the active-set updates (module docstring).

    Returns ``(solved, iterations)`` and writes the last ``λ₀`` into
    ``lam_out``. Solved: the joint system holds to the terminal tolerances
    (in the final frame) with what its switching-time errors can add, and
    the structure is consistent. Stops early when the miss grows a hundredfold (a wrong
    structure diverging), a switching time leaves ``[−T, 2T]`` or the system
    is singular.
    """
    times = np.empty((MAX_BURNS, 2))
    kinds = np.empty((MAX_BURNS, 2), dtype=np.int64)
    kern.copy_into(lam_start, lam_out)  # then the last iterate, written after each step
    nb = initial_burns(n, lam_start, horizon, n_cells, times, kinds)
    if nb < 0:
        return False, 0
    size = 6 + 2 * MAX_BURNS
    f = np.empty(size)
    jac = np.empty((size, size))
    step = np.empty(size)
    res = np.empty(6)
    lam = lam_start.copy()
    if nb > 0 and kinds[0, 0] == END_FIXED and kinds[0, 1] == END_SWITCH and times[0, 1] == 0.0:
        times[0, 1] = predicted_length(
            n, lam, d, horizon, u_max, gl_x, gl_w, nb, times, kinds, f, jac
        )
    first_miss = -1.0
    changes = 0
    it = 0
    while True:
        m = joint_system(n, lam, d, u_max, gl_x, gl_w, nb, times, kinds, f, jac)
        rp, rv = kern.terminal_residual(n, horizon, f[:6], res)
        if not (np.isfinite(rp) and np.isfinite(rv)):
            return False, it
        if first_miss < 0.0:
            first_miss = rp
        elif rp > 100.0 * first_miss + 1e-6:
            return False, it
        # Newton stops when the terminal miss of the joint system plus what its switching-time
        # errors ``δt_k = |‖λ_v(t_k)‖ − 1| / |ṗ(t_k)|`` can add (about ``u_max Σδt_k`` in
        # velocity, ``u_max T Σδt_k`` in position) is within the tolerances, so that the full
        # evaluation confirms it. A tolerance on ``‖λ_v‖ − 1`` alone (1e-13) left, where
        # ``|ṗ|`` is 1e-5/s, time errors of 1e-8 s and velocity misses of 2–6e-12 km/s that
        # the full evaluation rejected (78 of 3,120 re-solves, seeds 0–19); a tenth of the
        # tolerances for the times alone stalled at the rounding floor where ``|ṗ|`` ~ 1e-6/s.
        dt_sum = 0.0  # switching-time errors [s]
        for k in range(6, m):
            dt_sum += abs(f[k]) / max(abs(jac[k, k]), kern.MIN_SWITCH_RATE)
        drift = u_max * dt_sum  # what they can add to the terminal velocity [km/s]
        if rp + drift * horizon <= tol_pos and rv + drift <= tol_vel:
            nb, changed = update_structure(n, lam, horizon, nb, times, kinds)
            if not changed:
                return True, it
            changes += 1
            if changes > MAX_CHANGES or nb < 0:
                return False, it
            continue
        if it >= max_iter:
            return False, it
        for i in range(m):
            f[i] = -f[i]
        if not solve_dense(jac, f, m, step):
            return False, it
        for i in range(6):
            lam[i] += step[i]
        k = 6
        for b in range(nb):
            for e in range(2):
                if kinds[b, e] == END_SWITCH:
                    times[b, e] += step[k]
                    if not (-horizon <= times[b, e] <= 2.0 * horizon):
                        return False, it + 1
                    k += 1
        it += 1
        kern.copy_into(lam, lam_out)


def compile_switching_newton() -> None:
    """Compile (or load) :func:`switching_newton` for the argument types
    :func:`bang_bang_ascent` calls it with; runs nothing.

    A campaign's first run compiles it in a second process while the campaign
    process compiles the rest of the solver, which then loads it from numba's
    cache (issue 37 item 12, :func:`cwrend_cli.physics.compiled.compile_ahead`).
    """
    vec = types.float64[::1]
    f, i = types.float64, types.int64
    switching_newton.compile((f, vec, vec, f, f, vec, vec, i, f, f, i, vec))


def compile_predicted_length() -> None:
    """Compile (or load) :func:`predicted_length` for the argument types
    :func:`switching_newton` calls it with; runs nothing.

    A campaign's first run compiles it with the dual ascent
    (:func:`compile_newton_ascent`), before the second process compiling
    :func:`switching_newton` reaches it: the two processes then finish their
    halves of the solver about together (issue 37 item 12,
    :func:`cwrend_cli.physics.compiled.compile_ascent`).
    """
    vec, mat = types.float64[::1], types.float64[:, ::1]
    f, i = types.float64, types.int64
    kinds = types.int64[:, ::1]
    predicted_length.compile((f, vec, vec, f, f, vec, vec, i, mat, kinds, vec, mat))


def compile_newton_ascent(settings_t: tuple[Any, ...]) -> None:
    """Compile (or load) :func:`._kernels.newton_ascent` for the argument types
    :func:`bang_bang_ascent` calls it with, CW's mean motion as the model; runs nothing.

    ``settings_t``: the solver's :class:`._kernels.NewtonSettings` as the plain
    tuple :func:`bang_bang_ascent` takes (only its types matter). The dual
    ascent is the longest chain of the solver's compile (the ascent, its start
    selection, the dual evaluation, its breakpoints, the switching times): a
    campaign's first run compiles it first while a second process compiles
    :func:`switching_newton` (issue 37 item 12,
    :func:`cwrend_cli.physics.compiled.compile_ascent`).
    """
    vec, mat = types.float64[::1], types.float64[:, ::1]
    f, i = types.float64, types.int64
    settings = typeof(settings_t)  # type: ignore[no-untyped-call]
    sig = (f, vec, vec, f, f, f, mat, vec, vec, i, settings, vec)
    kern.newton_ascent.compile(sig)


@njit(cache=True)
def bang_bang_ascent(
    n: KernelModel,
    x0: np.ndarray,
    xf: np.ndarray,
    horizon: float,
    eps: float,
    u_max: float,
    starts: np.ndarray,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    n_cells: int,
    settings_t: tuple[Any, ...],
    max_iter_switching: int,
    lam_out: np.ndarray,
) -> tuple[int, int, float, float]:
    """:func:`._kernels.newton_ascent`, with :func:`switching_newton` first at ε = 0.

    Same arguments, returns and statuses as ``newton_ascent`` (plus
    ``max_iter_switching``, 0 to skip the switching Newton). At ε = 0 the
    start with the highest dual value (the one ``newton_ascent`` would take)
    is handed to :func:`switching_newton` unless it is already converged or
    certifies infeasibility; its answer is accepted only when the full dual
    evaluation confirms the terminal miss within the tolerances. Otherwise
    ``newton_ascent`` runs as it would alone (from the start it would choose
    among ``starts``, given alone so that the others are not evaluated a
    second time), or, when the
    switching Newton reached a consistent structure that the evaluation did
    not confirm, from that start and this near plan (the better by the dual
    value; the start on ties); the iterations reported are the sum of both.
    Measured (seeds 0–19, sample hold): offering a diverged iterate too made
    the slowest 45 re-solves' ascent 32 iterations instead of 18.
    """
    if eps >= kern.EPS_BANG_BANG or max_iter_switching <= 0:
        return kern.newton_ascent(
            n, x0, xf, horizon, eps, u_max, starts, gl_x, gl_w, n_cells, settings_t, lam_out
        )
    settings = kern.NewtonSettings(*settings_t)
    d = kern.terminal_offset(n, x0, xf, horizon)
    ws = kern.workspace()
    grad = np.empty(6)
    hess = np.empty((6, 6))
    res = np.empty(6)
    no_hess = bool(np.bool_(False))  # a runtime flag, not a literal (_kernels' docstring)
    best, _, best_cert = kern.best_start(
        n, starts, d, horizon, eps, u_max, gl_x, gl_w, n_cells, no_hess, grad, hess, ws
    )
    start = starts[best].copy()
    # the ascent below would choose this row again (same dual values): hand it only this one
    chosen = np.empty((1, 6))
    kern.copy_into(start, chosen[0])
    rp, rv = kern.terminal_residual(n, horizon, grad, res)
    if (rp <= settings.tol_pos_km and rv <= settings.tol_vel_km_s) or best_cert > 0.0:
        return kern.newton_ascent(
            n, x0, xf, horizon, eps, u_max, chosen, gl_x, gl_w, n_cells, settings_t, lam_out
        )
    lam = np.empty(6)
    solved, iters = switching_newton(
        n, start, d, horizon, u_max, gl_x, gl_w, n_cells,
        settings.tol_pos_km, settings.tol_vel_km_s, max_iter_switching, lam,
    )  # fmt: skip
    if solved:
        kern.dual_evaluate(
            n, lam, d, horizon, eps, u_max, gl_x, gl_w, n_cells, no_hess, grad, hess, ws
        )
        rp, rv = kern.terminal_residual(n, horizon, grad, res)
        if rp <= settings.tol_pos_km and rv <= settings.tol_vel_km_s:
            kern.copy_into(lam, lam_out)
            return kern.STATUS_CONVERGED, iters, rp, rv
        # a consistent structure not confirmed: a near plan, offered to the ascent beside the start
        pair = np.empty((2, 6))
        kern.copy_into(start, pair[0])
        kern.copy_into(lam, pair[1])
        status, more, rp, rv = kern.newton_ascent(
            n, x0, xf, horizon, eps, u_max, pair, gl_x, gl_w, n_cells, settings_t, lam_out
        )
        return status, iters + more, rp, rv
    # Newton diverged or stalled: its iterate says nothing; the ascent exactly as without it
    status, more, rp, rv = kern.newton_ascent(
        n, x0, xf, horizon, eps, u_max, chosen, gl_x, gl_w, n_cells, settings_t, lam_out
    )
    return status, iters + more, rp, rv
