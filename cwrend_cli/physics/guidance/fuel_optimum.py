"""The exact continuous minimum-fuel plan: its switching times to machine precision (issue 33).

Units: km, s, km/s, km/s², rad/s.

At ε = 0 the fuel-optimal control of paper Eqs. 8–10 is bang-bang: full
thrust ``u_max`` along ``−λ_v/‖λ_v‖`` where ``‖λ_v‖ > 1``, none elsewhere, so
its Δv is exactly ``u_max`` times the burn time, ``u_max Σ_i (b_i − a_i)``
over the burns ``[a_i, b_i]`` (Pontryagin's minimum principle; e.g. Bryson &
Ho 1975, *Applied Optimal Control*, §3.9, the bounded-thrust minimum-fuel
problem). The shooting solve that gives the fuel-optimal reference stops at
the terminal tolerances (1e-9 km, 1e-12 km/s), which leaves the switching
times uncertain by up to ~1e-6 s. Here they are made exact to rounding: the
classical switching-time shooting of
:mod:`~cwrend_cli.physics.guidance._switching_kernels` — unknowns ``λ₀`` and
the switching times ``t_k``, equations ``∫W u dτ = d`` (paper Eq. 10 at ε = 0,
the 6 terminal conditions) and ``‖λ_v(t_k)‖ = 1`` — is iterated by Newton from
the converged costate until its step stops shrinking, i.e. until rounding,
not the tolerance, limits it. Its Jacobian is analytic and its quadrature
spectrally accurate (Gauss–Legendre on arcs of at most 40 s, each burn an
analytic integrand), so the limit is a few ulps.

Measured on the paper scenario (issue 33): burns [0, 82.352 s] and
[741.025 s, 800 s], 141.327 s of burn, Δv = 0.1130615 km/s, where the
trapezoid of the plan sampled on the 1 s grid gives 141 u_max.
"""

from __future__ import annotations

from itertools import pairwise
from typing import NamedTuple

import numpy as np

from cwrend_cli.physics.guidance import _kernels as kern
from cwrend_cli.physics.guidance import _switching_kernels as switching
from cwrend_cli.physics.guidance.shooting import ShootingProblem, SolverSettings, switching_times

#: Most Newton steps of the refinement; from a costate converged to the solver's
#: tolerances it reaches the rounding floor in 2–3 (quadratic convergence).
MAX_STEPS = 12


class ExactPlanError(ArithmeticError):
    """The switching structure of the costate could not be refined (singular or changed)."""


class BangBangPlan(NamedTuple):
    """The exact minimum-fuel plan of one shooting problem at ε = 0."""

    costate: np.ndarray  # λ(0) solving the switching-time system to rounding
    burns_s: np.ndarray  # (m, 2): start and end of each full-thrust arc [s]
    switching_times_s: np.ndarray  # the burn ends that are switching times, increasing [s]
    delta_v_km_s: float  # u_max × total burn time
    miss_km: float  # ‖r(T) − r_f‖ of the switching-time system at the solution
    miss_km_s: float  # ‖v(T) − v_f‖ of it
    switch_residual: float  # max |‖λ_v(t_k)‖ − 1| over the switching times [-]
    newton_steps: int


def _structure(problem: ShootingProblem, costate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The burns of ``costate`` as rows ``(start, end)`` and their kinds (fixed or switch)."""
    lam = np.ascontiguousarray(costate, dtype=float)
    crossings = switching_times(problem, lam)
    lam_v0 = np.empty(6)
    kern.costate_at(problem.mean_motion_rad_s, 0.0, lam, lam_v0)
    thrusting = bool(np.linalg.norm(lam_v0[3:]) > 1.0)
    times = np.zeros((switching.MAX_BURNS, 2))
    kinds = np.zeros((switching.MAX_BURNS, 2), dtype=np.int64)
    edges = [(0.0, switching.END_FIXED)]
    edges += [(float(t), switching.END_SWITCH) for t in crossings]
    edges += [(float(problem.horizon_s), switching.END_FIXED)]
    nb = 0
    for (a, ka), (b, kb) in pairwise(edges):
        if thrusting:
            if nb >= switching.MAX_BURNS:
                raise ExactPlanError(f"more than {switching.MAX_BURNS} burns")
            times[nb] = (a, b)
            kinds[nb] = (ka, kb)
            nb += 1
        thrusting = not thrusting
    return times[: max(nb, 0)].copy(), kinds[:nb].copy()


def exact_bang_bang(
    problem: ShootingProblem, costate: np.ndarray, settings: SolverSettings | None = None
) -> BangBangPlan:
    """The ε = 0 plan of ``costate`` (a converged fuel-optimal solve), refined to rounding.

    The burn structure is that of ``costate`` (its switching times found
    afresh over the horizon); Newton on the switching-time system (module
    docstring) runs until its scaled step (``δλ₀`` relative to ``‖λ₀‖``, the
    times' relative to ``T``) no longer shrinks. Raises :class:`ExactPlanError`
    when the system is singular, the step does not shrink below 1e-6 (the
    costate was not a converged plan) or the refined structure is not
    consistent (a switching time leaving [0, T], a burn of no length).
    """
    settings = settings or SolverSettings()
    n = problem.mean_motion_rad_s
    horizon = float(problem.horizon_s)
    u_max = problem.u_max_km_s2
    gl_x, gl_w = settings.quadrature()
    burns, kinds = _structure(problem, costate)
    nb = burns.shape[0]
    times = np.zeros((switching.MAX_BURNS, 2))
    kind_rows = np.zeros((switching.MAX_BURNS, 2), dtype=np.int64)
    times[:nb], kind_rows[:nb] = burns, kinds
    x0 = np.require(problem.x0, dtype=float, requirements=["C", "W"])
    xf = np.require(problem.xf, dtype=float, requirements=["C", "W"])
    d = kern.terminal_offset(n, x0, xf, horizon)
    size = 6 + 2 * switching.MAX_BURNS
    f = np.empty(size)
    jac = np.empty((size, size))
    step = np.empty(size)
    lam = np.array(costate, dtype=float)
    switches = kind_rows[:nb] == switching.END_SWITCH
    last = np.inf
    steps = 0
    for _ in range(MAX_STEPS):
        m = switching.joint_system(n, lam, d, u_max, gl_x, gl_w, nb, times, kind_rows, f, jac)
        rhs = -f[:m]
        if not switching.solve_dense(jac, rhs, m, step):
            raise ExactPlanError("the switching-time system is singular")
        size_step = max(
            float(np.linalg.norm(step[:6]) / np.linalg.norm(lam)),
            float(np.max(np.abs(step[6:m]), initial=0.0)) / horizon,
        )
        if size_step >= last:
            break  # rounding, not the model, limits the step: done
        lam += step[:6]
        times[:nb][switches] += step[6:m]
        last = size_step
        steps += 1
    if last > 1e-6:
        raise ExactPlanError(f"the Newton step stayed at {last:.3g} (not a converged costate)")
    _, changed = switching.update_structure(n, lam, horizon, nb, times.copy(), kind_rows.copy())
    if changed:
        raise ExactPlanError("the refined burns are not consistent (a switch left [0, T])")
    m = switching.joint_system(n, lam, d, u_max, gl_x, gl_w, nb, times, kind_rows, f, jac)
    res = np.empty(6)
    rp, rv = kern.terminal_residual(n, horizon, f[:6], res)
    plan = times[:nb].copy()
    return BangBangPlan(
        costate=lam,
        burns_s=plan,
        switching_times_s=np.sort(plan[switches]),
        delta_v_km_s=float(u_max * np.sum(plan[:, 1] - plan[:, 0])),
        miss_km=float(rp),
        miss_km_s=float(rv),
        switch_residual=float(np.max(np.abs(f[6:m]), initial=0.0)),
        newton_steps=steps,
    )
