"""Convex checks on the zero-order-hold grid and ``solver.on_infeasible``.

Not in the paper: docs/solvers.md.
"""

from __future__ import annotations

import numpy as np
import pytest

from cwrend_cli import campaign
from cwrend_cli.config import ARCHITECTURES, CwrendConfig, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import guidance, simulation
from cwrend_cli.physics.dynamics import MEAN_MOTION_PAPER_RAD_S, discretize
from cwrend_cli.physics.guidance import feasibility

N = MEAN_MOTION_PAPER_RAD_S
U_MAX = 8e-4  # km/s², paper Table 1
# x0 of paper Sec. "Numerical Results and Discussion" [km, km/s]
X0 = np.array([0.03031809, 0.0, 31.16639, -0.02963377, 0.04570523, 0.0])


def _grid(x0: np.ndarray, horizon_s: float) -> feasibility.GridProblem:
    return feasibility.grid_problem(N, x0, np.zeros(6), horizon_s, 1.0, U_MAX)


def _propagate(x0: np.ndarray, u: np.ndarray) -> np.ndarray:
    phi, gam = discretize(N, 1.0)
    x = x0.copy()
    for uk in u:
        x = phi @ x + gam @ uk
    return x


def test_paper_scenario_needs_less_than_u_max() -> None:
    assert feasibility.min_peak_thrust(_grid(X0, 800.0)) < U_MAX


def test_unreachable_target_needs_more_than_u_max() -> None:
    """100 km away with 100 s: even full thrust moves only ½ u_max T² = 4 km."""
    far = np.array([100.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    assert feasibility.min_peak_thrust(_grid(far, 100.0)) > U_MAX


def test_min_peak_thrust_scales_with_distance() -> None:
    """The dynamics are linear, so the minimum peak thrust scales with the state."""
    x = np.array([1.0, 0.5, -0.3, 0.0, 0.0, 0.0])
    a = feasibility.min_peak_thrust(_grid(x, 120.0))
    b = feasibility.min_peak_thrust(_grid(2 * x, 120.0))
    assert b == pytest.approx(2 * a, rel=1e-6)  # interior-point tolerance 1e-10 relative


def test_multiplier_costate_seeds_a_converging_newton() -> None:
    """The SOCP multiplier is close to the fuel-optimal costate.

    The last step of the fallback chain (not in the paper: docs/solvers.md).
    """
    guess = feasibility.min_fuel_costate(_grid(X0, 800.0), N)
    assert guess is not None
    problem = guidance.ShootingProblem(X0, 800.0, 0.0, N, U_MAX)
    settings = guidance.SolverSettings(fallback="none")
    result = guidance.solve(problem, guess, settings)
    assert result.converged
    assert result.iterations <= 5


def test_min_miss_controls_are_bounded_and_reach_a_reachable_target() -> None:
    u = feasibility.min_miss_controls(_grid(X0, 800.0), velocity_weight_s=1.0)
    assert u is not None
    assert np.linalg.norm(u, axis=1).max() <= U_MAX * (1 + 1e-12)
    # SOCP tolerance 1e-10 on O(1) scaled rows: a metre-level miss would be a bug
    assert np.linalg.norm(_propagate(X0, u)[:3]) < 1e-3


def test_min_miss_controls_reduce_an_unreachable_miss() -> None:
    x = np.array([3.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # ½ u_max (60 s)² = 1.44 km < 3 km
    u = feasibility.min_miss_controls(_grid(x, 60.0), velocity_weight_s=1.0)
    assert u is not None
    drift = np.linalg.norm(_propagate(x, np.zeros_like(u))[:3])
    assert np.linalg.norm(_propagate(x, u)[:3]) < drift


def test_on_infeasible_min_miss_overrides_only_after_an_infeasible_resolve() -> None:
    base = CwrendConfig()
    alt = config_from_dict({"solver": {"on_infeasible": "min_miss"}})
    refs = simulation.open_loop_references(problem_of(base))
    noise = campaign.standard_normal_for(base, 0)
    arch = ARCHITECTURES["mtf_fixed"]
    keep = simulation.simulate(problem_of(base), arch, noise, refs)
    steer = simulation.simulate(problem_of(alt), arch, noise, refs)
    infeasible = [s for s in keep.resolves if s.status == "infeasible"]
    assert infeasible, "the paper scenario has infeasible final-burn re-solves at ε = 0"
    first = infeasible[0].step + 1
    assert np.array_equal(keep.u[:first], steer.u[:first])
    assert not np.array_equal(keep.u[first:], steer.u[first:])
    assert np.linalg.norm(steer.u, axis=1).max() <= U_MAX * (1 + 1e-12)


# --- the continuous-time dual bound (issue 16, item 3) -------------------------------

SHORT_S = 5.0  # a last-seconds horizon: there the 1 s grid overstates the bound by ~4 %


def _shooting_problem(x0: np.ndarray, horizon_s: float) -> guidance.ShootingProblem:
    return guidance.ShootingProblem(x0, horizon_s, 0.0, N, U_MAX)


def test_support_upper_bound_is_an_upper_bound_and_tight() -> None:
    """Ī(λ) ≥ ∫‖Wᵀλ‖dτ (a 0.01 s composite Gauss quadrature) and within 3e-5 relative.

    Tightness observed for random λ: 2e-6 (400 s), 1.1e-5 (5 s; the cells'
    second-derivative bound carries ‖μ‖ over all six components); at the
    maximising λ the bound is used with, ~1e-12 (against 0.25 s × 16-node
    quadrature). Slack only makes the test more cautious (an infeasible
    problem within it of the boundary would be called failed, not infeasible).
    """
    rng = np.random.default_rng(3)
    gx, gw = np.polynomial.legendre.leggauss(8)
    for horizon in (SHORT_S, 400.0):
        edges = np.linspace(0.0, horizon, round(horizon / 0.01) + 1)
        half = 0.5 * np.diff(edges)
        tau = ((edges[:-1] + half)[:, None] + half[:, None] * gx).ravel()
        w = (half[:, None] * gw).ravel()
        for _ in range(3):
            lam = rng.normal(size=6) * np.array([1 / horizon] * 3 + [1.0] * 3)
            f = np.array([np.linalg.norm(feasibility.stm(N, -t)[:, 3:].T @ lam) for t in tau])
            exact = float(w @ f)
            bound = feasibility._support_upper_bound(N, lam, horizon, 0.25)
            assert exact <= bound <= exact * (1 + 3e-5)


def test_continuous_bound_is_homogeneous_and_below_every_grid() -> None:
    """The least continuous peak thrust scales with the distance to cover, and any grid's
    held controls are continuous controls, so their minimum peak bounds it from above."""
    bound = feasibility.continuous_peak_thrust(N, X0, np.zeros(6), 120.0)
    twice = feasibility.continuous_peak_thrust(N, 2 * X0, np.zeros(6), 120.0)
    assert twice == pytest.approx(2 * bound, rel=1e-9)
    for dt in (1.0, 0.1):
        g = feasibility.grid_problem(N, X0, np.zeros(6), 120.0, dt, U_MAX)
        assert feasibility.min_peak_thrust(g) >= bound * (1 - 1e-9)


def test_infeasible_by_1e4_is_recognised() -> None:
    """Scaled 1e-4 beyond the boundary: the certified bound exceeds u_max."""
    scale = U_MAX / feasibility.continuous_peak_thrust(N, X0, np.zeros(6), SHORT_S)
    x0 = X0 * scale * (1 + 1e-4)
    assert feasibility.continuous_peak_thrust(N, x0, np.zeros(6), SHORT_S) > U_MAX
    problem = _shooting_problem(x0, SHORT_S)
    assert guidance.classify_failure(problem) is guidance.SolveStatus.INFEASIBLE


def test_feasible_within_1e4_of_the_boundary_is_not_labelled_infeasible() -> None:
    """Scaled 1e-4 inside the boundary: feasible (a 0.01 s grid plan proves it), not
    infeasible by the dual bound, though the 1 s grid's peak thrust says infeasible."""
    scale = U_MAX / feasibility.continuous_peak_thrust(N, X0, np.zeros(6), SHORT_S)
    x0 = X0 * scale * (1 - 1e-4)
    fine = feasibility.grid_problem(N, x0, np.zeros(6), SHORT_S, 0.01, U_MAX)
    assert feasibility.min_peak_thrust(fine) <= U_MAX  # a bounded control reaches x_f
    assert feasibility.continuous_peak_thrust(N, x0, np.zeros(6), SHORT_S) <= U_MAX
    problem = _shooting_problem(x0, SHORT_S)
    assert guidance.classify_failure(problem) is guidance.SolveStatus.FAILED
    # what the grid test of before issue 16 said (the 1 s grid overstates by ~4 % here)
    assert feasibility.min_peak_thrust(_grid(x0, SHORT_S)) > U_MAX
