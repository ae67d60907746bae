"""Convex checks on the zero-order-hold grid (SPEC §5) and ``solver.on_infeasible``."""

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
X0 = np.array([0.03031809, 0.0, 31.16639, -0.02963377, 0.04570523, 0.0])  # SPEC §6


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
    """The SOCP multiplier is close to the fuel-optimal costate (SPEC §5 fallback step 4)."""
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
