"""Convex guidance: the smoothed minimum-fuel problem as a cone program (paper Eqs. 5–10; issue 16).

The smoothed control law of paper Eq. 10 (throttle 0 for ``S > ε``,
``(ε − S)/(2ε)`` for ``|S| ≤ ε``, 1 for ``S < −ε``, ``S = 1 − ‖λ_v‖``) is the
pointwise minimiser over ``‖u‖ ≤ u_max`` of the Hamiltonian

    ``ℓ_ε(u) + λ_vᵀu``,  ``ℓ_ε(u) = (1 − ε)‖u‖ + (ε/u_max)‖u‖²``:

along ``u = −a λ_v/‖λ_v‖`` its derivative in ``a`` is
``(1 − ε) + 2εa/u_max − ‖λ_v‖``, zero at ``a = u_max(ε − S)/(2ε)``, clipped to
``[0, u_max]`` (``tests/test_convex.py`` checks this against
:func:`~cwrend_cli.physics.guidance.shooting.control`). The shooting re-solve
therefore solves ``min ∫ ℓ_ε(u) dt`` subject to the CW dynamics, ``x(T) = x_f``
and ``‖u‖ ≤ u_max``. On the zero-order-hold grid the loop executes, with the
exact discrete dynamics (condensed: ``x_N = Φᴺ x̂ + Σ_j Φ^{N−1−j} Γ u_j``,
:func:`~cwrend_cli.physics.guidance.feasibility.grid_problem`), that is the
second-order-cone program

    ``min Σ_j Δt ℓ_ε(u_j)``  s.t.  ``Σ_j M_j u_j = x_f − Φᴺ x̂``,  ``‖u_j‖ ≤ u_max``,

solved here in the scaled controls ``ũ = u/u_max`` (below: by a dual ascent or
by Clarabel); for Clarabel, variables
``(ũ_0 … ũ_{N−1}, t̃_0 … t̃_{N−1})`` with ``‖ũ_j‖ ≤ t̃_j ≤ 1`` (one SOC(4) and one
nonnegative row per step), cost ``Σ (1 − ε) t̃_j + ε‖ũ_j‖²`` (the quadratic
part through Clarabel's ``P``), i.e. the objective above divided by
``Δt u_max``.

Uniqueness at ε → 0: the fuel-optimal set can be a face rather than a point
(a small correction can sit almost anywhere at the same cost), so the
quadratic weight is ``max(ε, ρ)`` with ``ρ = REGULARISATION = 1e-6``. The cost
is then strictly convex, the plan unique and continuous in the data, and it
tends to the minimum-energy element of the fuel-optimal set as ρ → 0. The
fuel it gives up is bounded: with ``‖ũ_j‖ ≤ 1``, ``‖ũ_j‖² ≤ ‖ũ_j‖``, so
``F(u_ρ) − F* ≤ ρ Σ‖ũ*_j‖² ≤ ρ F*`` — at most a relative 1e-6 of the optimal
fuel (far below the grid's own discretisation error). Chosen over a second
stage (minimise ``Σ‖ũ_j‖²`` with the fuel held within a tolerance) because it
costs one cone program, not two, with the same kind of tolerance.

Two solvers, one program. Its Lagrange dual is a concave function of the six
terminal multipliers ``ν`` whose inner minimisation is the smoothed law of
Eq. (10) step by step, in closed form (:mod:`._grid_kernels`): the discrete
twin of the shooting solver's dual. Where the quadratic weight is at least
:data:`DUAL_MIN_WEIGHT` = 1e-3 (every re-solve of the adaptive architectures,
ε ≥ 0.07 in the paper's scenario) a Newton ascent on that dual, started from
the previous plan's multiplier, solves the program in 2–12 iterations of
~0.03 ms (issue 16's ≤ 10 ms: 0.3 ms mean in the closed loops instead of
Clarabel's 10–14 ms); its answer is the program's unique minimiser by
construction (each step's control minimises the Lagrangian, terminal miss
≤ 1e-12 km), and it agrees with Clarabel's to Clarabel's tolerance
(``tests/test_convex.py``). Below that weight (ε = 0: the weight is ρ) the
dual is nearly piecewise linear and Newton stalls (over the fixed-ε closed
loops at ρ it failed on most re-solves), so Clarabel's interior point solves
it — but first only on the steps that can thrust: the ascent at weight
``DUAL_MIN_WEIGHT`` gives a multiplier, Clarabel solves the program over the
steps it puts within 3 % of the switching value (a bang-bang plan thrusts on
a fifth of the horizon: 171 of 800 steps from x0), and the answer is
accepted only if every left-out step passes the optimality test at its own
multiplier (:func:`_clarabel_plan`); else more steps join, or the whole
program is solved. Full-horizon ε = 0 programs: ~20 → ~9 ms; in the
fixed-ε closed loops 19 → 7 ms mean (degenerate re-solves, where the primer
stays near 1 over the whole horizon, keep every step). Clarabel also answers
whenever the ascent neither converges nor finds a certificate.

Infeasible re-solves (the final burn; not in the paper, docs/method.md) are recognised by a dual
certificate: some ``ν`` with ``νᵀb > Σ_j ‖A_jᵀν‖`` proves by weak duality
that no bounded controls reach ``x_f`` — found by the ascent, or given by
Clarabel as its primal infeasibility certificate. When Clarabel stops
without one (a problem within about 1e-4 of the thrust boundary ends in a
numerical error), the grid's minimum peak thrust
(:func:`~cwrend_cli.physics.guidance.feasibility.min_peak_thrust`) decides
feasibility of exactly this discrete problem.

Units: km, s, km/s, km/s².
"""

from __future__ import annotations

import time
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp

from cwrend_cli.physics.guidance import _grid_kernels as grid_kernels
from cwrend_cli.physics.guidance import feasibility
from cwrend_cli.physics.guidance._kernels import (
    STATUS_CONVERGED,
    STATUS_FAILED,
    STATUS_INFEASIBLE,
    NewtonSettings,
)
from cwrend_cli.physics.guidance.results import SolveResult, SolveStatus

#: Quadratic weight used below ε = ρ so that the ε → 0 plan is unique (module docstring).
REGULARISATION = 1e-6

#: Smallest quadratic weight solved by the dual ascent (module docstring); below it, Clarabel.
DUAL_MIN_WEIGHT = 1e-3

#: Margin of the screen below DUAL_MIN_WEIGHT: Clarabel first sees the steps whose
#: ``‖A_jᵀν‖`` at weight DUAL_MIN_WEIGHT is within this fraction of the switching value.
SCREEN_MARGIN = 0.03

#: Reduced programs tried before Clarabel solves the whole one (:func:`_clarabel_plan`).
SCREEN_ROUNDS = 3

#: The dual ascent's damping and limits are the shooting solver's; it stops at a terminal
#: miss of 1e-12 km and 1e-15 km/s (the shooting tolerances / 1000: its quadratic
#: convergence makes the last digits cost no extra iteration over the in-loop problems of
#: seeds 0–2, and the plan then reaches x_f far closer than Clarabel's, ≤ 2.8e-8 km).
_NEWTON = tuple(NewtonSettings(tol_pos_km=1e-12, tol_vel_km_s=1e-15))

_ASCENT_STATUS = {
    STATUS_CONVERGED: SolveStatus.CONVERGED,
    STATUS_INFEASIBLE: SolveStatus.INFEASIBLE,
    STATUS_FAILED: SolveStatus.FAILED,
}

_INFEASIBLE = (clarabel.SolverStatus.PrimalInfeasible, clarabel.SolverStatus.AlmostPrimalInfeasible)


def plan_controls(
    g: feasibility.GridProblem,
    eps: float,
    n: float,
    regularisation: float = REGULARISATION,
    warm: np.ndarray | None = None,
) -> tuple[SolveStatus, np.ndarray, np.ndarray, int]:
    """Solve the smoothed minimum-fuel cone program on the grid of ``g``.

    Returns ``(status, controls (N, 3) [km/s²], λ(0), iterations)``; on
    anything but ``converged`` the controls are zero and ``λ(0)`` NaN.
    ``λ(0)`` is the costate the terminal multiplier implies
    (:func:`~cwrend_cli.physics.guidance.feasibility.costate_from_multiplier`).

    Two solvers, one program (module docstring): the dual ascent when the
    quadratic weight is at least :data:`DUAL_MIN_WEIGHT`, started from
    ``warm`` (a costate at the grid's start from an earlier plan) or cold;
    below that weight Clarabel, on the steps that the ascent at
    ``DUAL_MIN_WEIGHT`` screens (:func:`_clarabel_plan`); Clarabel on every
    step whenever the ascent neither converges nor certifies infeasibility.
    ``iterations`` counts the iterations of the solver that answered.
    """
    weight = max(float(eps), regularisation)
    linear = 1.0 - min(float(eps), 1.0)
    a, b = _scaled_rows(g)
    nu0 = np.empty(6)
    if warm is not None and np.all(np.isfinite(warm)):
        nu0[:] = -feasibility.multiplier_from_costate(g, n, warm)
    elif not grid_kernels.cold_start(a, b, linear, max(weight, DUAL_MIN_WEIGHT), nu0):
        return _clarabel_plan(g, linear, weight, n)
    # Above DUAL_MIN_WEIGHT the ascent solves the program; below, it solves it at that
    # weight to tell Clarabel which steps can thrust (module docstring).
    status, nu, u, iterations = _ascent(
        a, b, g.row_scale, linear, max(weight, DUAL_MIN_WEIGHT), nu0
    )
    if status is SolveStatus.INFEASIBLE:  # the certificate holds whatever the cost
        return status, np.zeros_like(u), np.full(6, np.nan), iterations
    if status is not SolveStatus.CONVERGED:
        return _clarabel_plan(g, linear, weight, n)
    if weight >= DUAL_MIN_WEIGHT:
        # Clarabel's terminal multiplier is z = −ν (its KKT reads ∇f + Aᵀz = 0)
        return status, u * g.u_max_km_s2, feasibility.costate_from_multiplier(g, n, -nu), iterations
    return _clarabel_plan(g, linear, weight, n, keep=_screen(_step_norms(a, nu), linear))


def _scaled_rows(g: feasibility.GridProblem) -> tuple[np.ndarray, np.ndarray]:
    """``(A_j, b)`` of the scaled program: ``A_j = S M_j u_max`` (N × 6 × 3), ``b = S rhs``."""
    a = g.blocks * (g.u_max_km_s2 * g.row_scale)[None, :, None]
    return np.ascontiguousarray(a), g.rhs * g.row_scale


def _ascent(
    a: np.ndarray,
    b: np.ndarray,
    row_scale: np.ndarray,
    linear: float,
    weight: float,
    nu0: np.ndarray,
) -> tuple[SolveStatus, np.ndarray, np.ndarray, int]:
    """The dual ascent (:mod:`._grid_kernels`): ``(status, ν, ũ (N × 3), iterations)``."""
    nu = np.empty(6)
    u = np.empty((a.shape[0], 3))
    status, iterations, _, _ = grid_kernels.grid_dual_ascent(
        a, b, row_scale, linear, weight, nu0, _NEWTON, nu, u
    )
    return _ASCENT_STATUS[status], nu, u, int(iterations)


def _step_norms(a: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """``‖A_jᵀν‖`` per step (``a``: :func:`_scaled_rows`): a step thrusts in the optimum iff
    it exceeds ``1 − ε``."""
    norms: np.ndarray = np.linalg.norm(np.einsum("jab,a->jb", a, nu), axis=1)
    return norms


def _screen(norms: np.ndarray, linear: float) -> np.ndarray:
    """Steps that may thrust by their :func:`_step_norms`: ``≥ (1 − ε)(1 − SCREEN_MARGIN)``."""
    return np.flatnonzero(norms >= linear * (1.0 - SCREEN_MARGIN))


def _clarabel_plan(
    g: feasibility.GridProblem,
    linear: float,
    weight: float,
    n: float,
    keep: np.ndarray | None = None,
) -> tuple[SolveStatus, np.ndarray, np.ndarray, int]:
    """The program by Clarabel's interior point, with its infeasibility certificate.

    With ``keep`` (step indices, e.g. :func:`_screen` of the multiplier at a
    nearby weight) Clarabel first sees only those steps, the others held at
    zero. Zero is optimal for a step iff ``‖A_jᵀν*‖ ≤ 1 − ε`` at the answer's
    own multiplier, so the answer is accepted only when every left-out step
    passes that test (it then satisfies the whole program's optimality
    conditions, to Clarabel's tolerance); otherwise the screen of the new
    multiplier joins and the reduced program is solved again (at most
    :data:`SCREEN_ROUNDS` programs), and any other outcome (an unsolved
    reduced program: too few steps to reach x_f) falls back to the whole
    program. ``iterations`` sums the interior-point iterations.
    """
    steps = g.blocks.shape[0]
    used = 0
    if keep is not None:
        a, _ = _scaled_rows(g)
        for _round in range(SCREEN_ROUNDS):
            if keep.size == 0 or keep.size == steps:
                break
            sub = feasibility.GridProblem(
                np.ascontiguousarray(g.blocks[keep]), g.rhs, g.row_scale, g.dt_s, g.u_max_km_s2
            )
            sol, iterations = _clarabel_program(sub, linear, weight)
            used += iterations
            if not feasibility.solved(sol):
                break
            z = np.asarray(sol.z[:6])  # −ν
            norms = _step_norms(a, -z)
            outside = np.ones(steps, dtype=bool)
            outside[keep] = False
            if not np.any(norms[outside] > linear):
                u = np.zeros((steps, 3))
                u[keep] = feasibility.held_controls(sub, sol)
                costate = feasibility.costate_from_multiplier(g, n, z)
                return SolveStatus.CONVERGED, u, costate, used
            keep = np.union1d(keep, _screen(norms, linear))
    sol, iterations = _clarabel_program(g, linear, weight)
    used += iterations
    if not feasibility.solved(sol):
        infeasible = sol.status in _INFEASIBLE
        if not infeasible:
            # No certificate (within ~1e-4 of the boundary the interior point stalls):
            # the grid's own test (feasibility.min_peak_thrust), on exactly this grid.
            infeasible = feasibility.min_peak_thrust(g) > g.u_max_km_s2
        status = SolveStatus.INFEASIBLE if infeasible else SolveStatus.FAILED
        return status, np.zeros((steps, 3)), np.full(6, np.nan), used
    costate = feasibility.costate_from_multiplier(g, n, np.asarray(sol.z[:6]))
    return SolveStatus.CONVERGED, feasibility.held_controls(g, sol), costate, used


def _clarabel_program(g: feasibility.GridProblem, linear: float, weight: float) -> tuple[Any, int]:
    """Clarabel's solution of the scaled program over the steps of ``g``, and its iterations."""
    steps = g.blocks.shape[0]
    n_vars = 4 * steps  # ũ (3N), t̃ (N)
    a_eq, b_eq = feasibility.terminal_rows(g, n_vars)
    epigraph = feasibility.cone_rows(steps, n_vars, 3 * steps + np.arange(steps))
    # t̃_j ≤ 1 as s = 1 − t̃_j ≥ 0
    cap = sp.csc_matrix(
        (np.ones(steps), (np.arange(steps), 3 * steps + np.arange(steps))), shape=(steps, n_vars)
    )
    a = sp.vstack([a_eq, epigraph, cap]).tocsc()
    b = np.concatenate([b_eq, np.zeros(4 * steps), np.ones(steps)])
    q = np.zeros(n_vars)
    q[3 * steps :] = linear
    diag = np.zeros(n_vars)
    diag[: 3 * steps] = 2.0 * weight  # Clarabel's cost is ½xᵀPx + qᵀx
    p = sp.diags(diag, format="csc")
    cones = [
        clarabel.ZeroConeT(6),
        *([clarabel.SecondOrderConeT(4)] * steps),
        clarabel.NonnegativeConeT(steps),
    ]
    sol = feasibility.solve_cone(p, q, a, b, cones)
    return sol, int(sol.iterations)


def terminal_miss(g: feasibility.GridProblem, controls: np.ndarray) -> float:
    """``‖x_N − x_f‖`` of held ``controls`` under the exact discrete dynamics (6-vector norm)."""
    reached = np.einsum("jab,jb->a", g.blocks, controls)
    return float(np.linalg.norm(reached - g.rhs))


def solve(
    g: feasibility.GridProblem,
    eps: float,
    n: float,
    step: str = "socp",
    regularisation: float = REGULARISATION,
    warm: np.ndarray | None = None,
) -> SolveResult:
    """One cone-program re-solve as a :class:`SolveResult` whose plan is ``controls``.

    ``step`` names the method in the solves table (``socp`` for the
    cone-program architectures, ``socp_plan`` in the shooting chain);
    ``warm`` is an earlier plan's costate propagated to the grid's start
    (:func:`plan_controls`).
    """
    start = time.perf_counter()
    status, controls, costate, iterations = plan_controls(g, eps, n, regularisation, warm)
    converged = status is SolveStatus.CONVERGED
    return SolveResult(
        costate=costate,
        status=status,
        step=step,
        iterations=iterations,
        residual_km=terminal_miss(g, controls) if converged else float("nan"),
        wall_time_s=time.perf_counter() - start,
        eps=float(eps),
        horizon_s=g.blocks.shape[0] * g.dt_s,
        controls=controls if converged else None,
    )
