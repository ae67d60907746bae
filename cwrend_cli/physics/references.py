"""Open-loop energy- and fuel-optimal references (paper Sec. "Numerical Results and Discussion").

Energy-optimal: unbounded ``min ∫½‖u‖²`` solved in closed form. Fuel-optimal:
ε-continuation 1.0, 0.9, …, 0.0 of the shooting problem, each solve
warm-started from the previous one, the first from the energy costate.
Δv (:func:`~cwrend_cli.physics.metrics.delta_v`) is the trapezoid of ‖u‖ sampled
on the grid (the paper's convention); beside it, ``delta_v_continuous_km_s`` is
the continuous plan's ∫‖u‖dt: for the fuel-optimal plan exactly ``u_max``
times its burn time, the switching times refined to rounding
(:func:`~cwrend_cli.physics.guidance.fuel_optimum.exact_bang_bang`; issue 33,
item 3), for the energy-optimal one a Gauss–Legendre quadrature (12 nodes on
cells of at most 40 s: the integrand is analytic). The miss is that of the
continuous plan, ``‖r(T) − r_f‖``.
Units: km, s, km/s, km/s².
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from cwrend_cli.physics import guidance
from cwrend_cli.physics.dynamics import costate_stm, cw_system
from cwrend_cli.physics.errors import ScenarioError
from cwrend_cli.physics.guidance.fuel_optimum import BangBangPlan, ExactPlanError, exact_bang_bang
from cwrend_cli.physics.metrics import delta_v

#: ε sequence of the fuel-optimal continuation (the authors' code's; not in the paper).
FUEL_CONTINUATION = tuple(round(1.0 - 0.1 * i, 1) for i in range(11))


@dataclass(frozen=True)
class OpenLoopResult:
    """One open-loop reference sampled on the simulation grid."""

    name: str  # "energy" or "fuel"
    costate: np.ndarray  # λ(0)
    t_s: np.ndarray  # (N+1,)
    x: np.ndarray  # (N+1, 6) state of the continuous plan at the grid times
    u: np.ndarray  # (N+1, 3) control sampled at the grid times
    delta_v_km_s: float
    miss_km: float
    solves: tuple[guidance.SolveResult, ...] = ()
    #: ∫‖u‖dt of the continuous plan [km/s] (module docstring); NaN for the fuel plan if its
    #: switching times could not be refined (:class:`ExactPlanError`: never seen)
    delta_v_continuous_km_s: float = float("nan")
    exact: BangBangPlan | None = None  # the fuel plan refined to rounding (None: energy)


def energy_optimal(problem: guidance.ShootingProblem, t_s: np.ndarray) -> OpenLoopResult:
    """Energy-optimal reference: ``u = −Bᵀλ`` with ``λ(0)`` in closed form."""
    lam0 = guidance.energy_optimal_costate(problem)
    n = problem.mean_motion_rad_s
    a, b = cw_system(n)
    z = np.zeros((12, 12))
    z[:6, :6] = a
    z[:6, 6:] = -b @ b.T
    z[6:, 6:] = -a.T
    # The state–costate system is linear: propagate [x; λ] exactly between grid times.
    zt = np.empty((t_s.size, 12))
    zt[0] = np.concatenate([problem.x0, lam0])
    steps: dict[float, np.ndarray] = {}
    for i in range(1, t_s.size):
        h = float(t_s[i] - t_s[i - 1])
        if h not in steps:
            steps[h] = scipy.linalg.expm(z * h)
        zt[i] = steps[h] @ zt[i - 1]
    x = zt[:, :6]
    u = -zt[:, 9:12]  # u = −Bᵀλ = −λ_v
    miss = float(np.linalg.norm(x[-1, :3] - problem.xf[:3]))
    continuous = _energy_delta_v(problem.mean_motion_rad_s, lam0, float(problem.horizon_s))
    return OpenLoopResult(
        "energy", lam0, t_s, x, u, delta_v(t_s, u), miss, delta_v_continuous_km_s=continuous
    )


def _energy_delta_v(n: float, lam0: np.ndarray, horizon_s: float) -> float:
    """∫₀ᵀ ‖λ_v(t)‖ dt [km/s]: the Δv of the energy-optimal plan ``u = −λ_v`` (module docstring)."""
    nodes, weights = guidance.SolverSettings().quadrature()
    cells = guidance.n_cells(horizon_s)
    h = horizon_s / cells
    total = 0.0
    for cell in range(cells):
        mid = (cell + 0.5) * h
        for node, weight in zip(nodes, weights, strict=True):
            lam_v = (costate_stm(n, mid + 0.5 * h * node) @ lam0)[3:]
            total += 0.5 * h * weight * float(np.linalg.norm(lam_v))
    return total


def plan_samples(
    problem: guidance.ShootingProblem, lam0: np.ndarray, t_s: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """State and control of the plan ``λ(0) = lam0`` at the times ``t_s`` (from t = 0)."""
    n = problem.mean_motion_rad_s
    x = np.empty((t_s.size, 6))
    u = np.empty((t_s.size, 3))
    for i, t in enumerate(t_s):
        lam_t = costate_stm(n, t) @ lam0
        u[i] = guidance.control(lam_t[3:], problem.eps, problem.u_max_km_s2)
        if t == 0.0:
            x[i] = problem.x0
        else:
            sub = guidance.ShootingProblem(
                problem.x0, float(t), problem.eps, n, problem.u_max_km_s2, problem.xf
            )
            x[i] = guidance.terminal_state(sub, lam0)
    return x, u


def fuel_optimal(
    problem: guidance.ShootingProblem,
    t_s: np.ndarray,
    settings: guidance.SolverSettings | None = None,
) -> OpenLoopResult:
    """Fuel-optimal reference by ε-continuation ``FUEL_CONTINUATION`` from the energy costate.

    ``problem.eps`` is ignored; the result is the ε = 0 (bang-bang) plan.
    Raises :class:`ScenarioError` if a continuation step does not converge
    (for instance because no control within ``u_max`` reaches the target).
    """
    lam = guidance.energy_optimal_costate(problem)
    solves = []
    for eps in FUEL_CONTINUATION:
        step = guidance.ShootingProblem(
            problem.x0,
            problem.horizon_s,
            eps,
            problem.mean_motion_rad_s,
            problem.u_max_km_s2,
            problem.xf,
        )
        result = guidance.solve(step, lam, settings)
        if result.status is guidance.SolveStatus.INFEASIBLE:
            where = ", ".join(f"{v:g}" for v in problem.xf[:3])
            raise ScenarioError(
                "scenario infeasible: no control with |u| <= scenario.u_max_km_s2 = "
                f"{problem.u_max_km_s2:g} reaches scenario.xf (position [{where}] km; with a "
                "corridor, constraints.corridor.port_km at rest) from scenario.x0 within "
                f"scenario.horizon_s = {problem.horizon_s:g}; increase u_max_km_s2 or horizon_s, "
                "or check the positions (in km)"
            )
        if not result.converged:
            raise ScenarioError(
                f"open-loop fuel-optimal continuation did not converge at eps = {eps} "
                f"(residual {result.residual_km:.3g}); check scenario.x0, xf and horizon_s"
            )
        solves.append(result)
        lam = result.costate
    final = guidance.ShootingProblem(
        problem.x0,
        problem.horizon_s,
        0.0,
        problem.mean_motion_rad_s,
        problem.u_max_km_s2,
        problem.xf,
    )
    x, u = plan_samples(final, lam, t_s)
    miss = float(np.linalg.norm(x[-1, :3] - problem.xf[:3]))
    try:
        exact: BangBangPlan | None = exact_bang_bang(final, lam, settings)
    except ExactPlanError:
        exact = None
    return OpenLoopResult(
        "fuel", lam, t_s, x, u, delta_v(t_s, u), miss, tuple(solves),
        delta_v_continuous_km_s=float("nan") if exact is None else exact.delta_v_km_s,
        exact=exact,
    )  # fmt: skip
