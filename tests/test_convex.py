"""The smoothed minimum-fuel cone program against the shooting solver (issue 16).

Cross-checks of :mod:`cwrend_cli.physics.guidance.convex`: the control law of
Eq. (10) is the pointwise minimiser of the smoothed Hamiltonian, the cone
program's plan converges to the shooting solution as the grid is refined, its
1 s plan reaches x_f in an independently integrated CW truth, the closed loop
runs through the CLI, and the shooting chain's ``socp_plan`` step.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.config import ALL_ARCHITECTURES, ARCHITECTURES, parse_archs
from cwrend_cli.errors import ConfigError
from cwrend_cli.physics import guidance
from cwrend_cli.physics.dynamics import costate_stm, cw_system, stm
from cwrend_cli.physics.guidance import convex, feasibility
from cwrend_cli.physics.params import Guidance, Scenario

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
SC = Scenario()
N_RAD_S = SC.mean_motion_rad_s
U_MAX = SC.u_max_km_s2
X0 = np.asarray(SC.x0, dtype=float)
runner = CliRunner()


# --- the derivation: Eq. (10) minimises (1 − ε)‖u‖ + (ε/u_max)‖u‖² + λ_vᵀu ----------


@pytest.mark.parametrize("eps", [1.0, 0.3, 0.05, 1e-3])
def test_control_law_is_the_pointwise_minimiser(eps: float) -> None:
    rng = np.random.default_rng(16)
    for _ in range(200):
        lam_v = rng.normal(size=3) * rng.uniform(0.2, 1.5)
        p = float(np.linalg.norm(lam_v))

        def cost(a: float, p: float = p) -> float:  # along −λ_v/‖λ_v‖, the minimising direction
            return (1.0 - eps) * a + (eps / U_MAX) * a * a - p * a

        # the cost is convex in a: ternary search on [0, u_max] to machine precision
        lo, hi = 0.0, U_MAX
        for _ in range(200):
            m1, m2 = lo + (hi - lo) / 3, hi - (hi - lo) / 3
            lo, hi = (lo, m2) if cost(m1) <= cost(m2) else (m1, hi)
        a_star = 0.5 * (lo + hi)
        u = guidance.control(lam_v, eps, U_MAX)
        # magnitude: near its minimum the cost changes by (ε/u_max)δa², below its rounding
        # (~1e-16 u_max) for δa < 1e-8 u_max/√ε: the search is that exact; Eq. (10) exactly
        assert np.linalg.norm(u) == pytest.approx(a_star, abs=1e-7 * U_MAX / np.sqrt(eps))
        if a_star > 1e-6 * U_MAX:
            np.testing.assert_allclose(u / np.linalg.norm(u), -lam_v / p, atol=1e-12)
        # and no other direction of the same magnitude does better (the λ_vᵀu term)
        other = rng.normal(size=3)
        other *= np.linalg.norm(u) / np.linalg.norm(other)
        assert lam_v @ u <= lam_v @ other + 1e-15


# --- convergence to the shooting solution as the grid is refined ------------------


def _shooting(eps: float) -> tuple[guidance.ShootingProblem, np.ndarray]:
    problem = guidance.ShootingProblem(X0, SC.horizon_s, eps, N_RAD_S, U_MAX)
    result = guidance.solve(problem, guidance.energy_optimal_costate(problem))
    assert result.status is guidance.SolveStatus.CONVERGED
    return problem, result.costate


def _shooting_fuel(problem: guidance.ShootingProblem, costate: np.ndarray, h: float) -> float:
    """∫‖u‖dt of the costate plan, trapezoid on an ``h`` grid (‖u‖ is Lipschitz for ε > 0)."""
    t = np.linspace(0.0, problem.horizon_s, round(problem.horizon_s / h) + 1)
    mags = np.array(
        [np.linalg.norm(guidance.control((costate_stm(N_RAD_S, s) @ costate)[3:], problem.eps,
                                         U_MAX)) for s in t]
    )  # fmt: skip
    return float(np.sum(0.5 * (mags[1:] + mags[:-1])) * h)


def _bang_bang_fuel(problem: guidance.ShootingProblem, costate: np.ndarray) -> float:
    """u_max × total burn time between the exact switching times (ε = 0)."""
    edges = np.concatenate(([0.0], guidance.switching_times(problem, costate), [problem.horizon_s]))
    burn = 0.0
    for a, b in itertools.pairwise(edges):
        mid = costate_stm(N_RAD_S, 0.5 * (a + b)) @ costate
        if np.linalg.norm(mid[3:]) > 1.0:
            burn += b - a
    return U_MAX * burn


def _plan(eps: float, dt: float) -> tuple[feasibility.GridProblem, guidance.SolveResult]:
    g = feasibility.grid_problem(N_RAD_S, X0, np.zeros(6), SC.horizon_s, dt, U_MAX)
    result = convex.solve(g, eps, N_RAD_S)
    assert result.status is guidance.SolveStatus.CONVERGED
    assert result.controls is not None
    return g, result


def _grid_state(g: feasibility.GridProblem, controls: np.ndarray, steps: int) -> np.ndarray:
    """State after ``steps`` held controls from x0 (exact ZOH dynamics)."""
    # blocks[-steps + j] = Φ^{steps−1−j} Γ, independent of the horizon the grid was built for
    reached = np.einsum("jab,jb->a", g.blocks[g.blocks.shape[0] - steps :], controls[:steps])
    return stm(N_RAD_S, steps * g.dt_s) @ X0 + reached


@pytest.mark.parametrize("eps", [1.0, 0.3, 0.05])
def test_cone_program_converges_to_shooting(eps: float) -> None:
    """Fuel, costate and the state at T/2 converge to the shooting solution like Δt².

    Errors against the shooting solution (fuel and costate relative, state at
    T/2 absolute) on Δt = 1, 0.5, 0.2, 0.1 s, observed: ε = 1: costate
    1.5e-6, 3.7e-7, 5.8e-8, 1.5e-8 (order 2.0); ε = 0.3: 1.6e-6 … 4.0e-8 at
    0.2 s; ε = 0.05: 1.4e-6 … 1.0e-7 at 0.2 s (order 1.6, the throttle ramp
    is only 0.05 wide); below 0.2 s the smoothed cases reach the floor of the
    shooting reference itself (~1e-8 relative: its quadrature and Newton
    tolerances). Required: order ≥ 1.5 from 1 s to 0.2 s for the costate and the
    state at T/2 (error ratio ≥ 5^1.5 ≈ 11.2), and at 0.1 s fuel < 5e-8 and
    costate < 1e-7 relative, state at T/2 < 1e-6 km and 3e-9 km/s (observed at
    most 2.1e-8, 5.2e-8, 3.5e-7 km, 1.6e-9 km/s). Both plans reach x_f: the
    cone program's to 1e-11 (6-norm of km and km/s, not in the paper; observed ≤ 2.5e-12).
    """
    problem, costate = _shooting(eps)
    fuel_ref = _shooting_fuel(problem, costate, 0.005)
    half = guidance.ShootingProblem(X0, SC.horizon_s / 2, eps, N_RAD_S, U_MAX)
    x_half = guidance.terminal_state(half, costate, nodes=24)
    errs = {}
    for dt in (1.0, 0.2, 0.1):
        g, plan = _plan(eps, dt)
        assert plan.controls is not None
        fuel = float(np.sum(np.linalg.norm(plan.controls, axis=1)) * dt)
        xh = _grid_state(g, plan.controls, round(SC.horizon_s / 2 / dt))
        errs[dt] = np.array(
            [
                abs(fuel - fuel_ref) / fuel_ref,
                np.linalg.norm(plan.costate - costate) / np.linalg.norm(costate),
                np.linalg.norm(xh[:3] - x_half[:3]),
                np.linalg.norm(xh[3:] - x_half[3:]),
            ]
        )
        assert plan.residual_km < 1e-11
    rates = errs[1.0] / errs[0.2]
    assert np.all(rates[1:] >= 5**1.5), rates
    fine = errs[0.1]
    assert fine[0] < 5e-8 and fine[1] < 1e-7, fine
    assert fine[2] < 1e-6 and fine[3] < 3e-9, fine


def test_bang_bang_fuel_matches_shooting_to_grid_accuracy() -> None:
    """At ε = 0 the cone program's fuel equals the shooting fuel to O(Δt²).

    Relative excess below 3e-6 on the 1 s grid and 5e-8 on 0.1 s (observed
    2.0e-6 and 3.3e-8: switching times fall inside steps); the
    regularisation's bound ρ = 1e-6 on the fuel it gives up is within both.
    """
    problem, costate = _shooting(0.0)
    fuel_ref = _bang_bang_fuel(problem, costate)
    for dt, tol in ((1.0, 3e-6), (0.1, 5e-8)):
        _, plan = _plan(0.0, dt)
        assert plan.controls is not None
        fuel = float(np.sum(np.linalg.norm(plan.controls, axis=1)) * dt)
        assert fuel == pytest.approx(fuel_ref, rel=tol)
        assert fuel >= fuel_ref * (1 - 1e-9)  # the grid cannot beat the continuous optimum


def test_regularised_plan_is_unique_and_costs_at_most_rho() -> None:
    """ε = 0: the plan is reproducible and its fuel within ρ (relative) of ρ = 0's."""
    g = feasibility.grid_problem(N_RAD_S, X0, np.zeros(6), SC.horizon_s, 1.0, U_MAX)
    a = convex.solve(g, 0.0, N_RAD_S)
    b = convex.solve(g, 0.0, N_RAD_S)
    exact = convex.solve(g, 0.0, N_RAD_S, regularisation=0.0)
    assert a.controls is not None and b.controls is not None and exact.controls is not None
    np.testing.assert_array_equal(a.controls, b.controls)
    fuel = np.linalg.norm(a.controls, axis=1).sum()
    fuel0 = np.linalg.norm(exact.controls, axis=1).sum()
    # ρ bound plus the solver's relative gap tolerance (1e-10)
    assert fuel <= fuel0 * (1 + convex.REGULARISATION + 1e-9)


def test_one_second_plan_reaches_xf_in_integrated_cw_truth() -> None:
    """The 1 s ZOH plan, integrated by DOP853 (not the STM), ends at x_f.

    Tolerance 1e-8 km / 1e-11 km/s: the integrator's rtol 1e-12 over 800
    steps on a 31 km state; the cone program itself closes to ~1e-13.
    """
    a, b = cw_system(N_RAD_S)
    for eps in (0.3, 0.0):
        _, plan = _plan(eps, 1.0)
        assert plan.controls is not None
        x = X0.copy()
        for u in plan.controls:
            sol = solve_ivp(lambda _t, s, u=u: a @ s + b @ u, (0.0, 1.0), x, method="DOP853",
                            rtol=1e-12, atol=1e-15)  # fmt: skip
            x = sol.y[:, -1]
        assert np.linalg.norm(x[:3]) < 1e-8
        assert np.linalg.norm(x[3:]) < 1e-11


@pytest.mark.parametrize("eps", [0.0, 0.3])
@pytest.mark.parametrize("horizon", [60.0, 400.0])
def test_infeasible_problem_is_certified(eps: float, horizon: float) -> None:
    """Too short a horizon for u_max: the cone program reports infeasible, no plan.

    400 s is infeasible by 2.2 % only (the grid's minimum peak thrust is
    1.022 u_max); ε = 0 is decided by Clarabel, ε = 0.3 by the dual ascent's
    certificate.
    """
    g = feasibility.grid_problem(N_RAD_S, X0, np.zeros(6), horizon, 1.0, U_MAX)
    assert feasibility.min_peak_thrust(g) > U_MAX
    result = convex.solve(g, eps, N_RAD_S)
    assert result.status is guidance.SolveStatus.INFEASIBLE
    assert result.controls is None


# --- the dual ascent (issue 16's speed): same program, same answer ---------------


def _full_grid() -> feasibility.GridProblem:
    return feasibility.grid_problem(N_RAD_S, X0, np.zeros(6), SC.horizon_s, 1.0, U_MAX)


def _clarabel(g: feasibility.GridProblem, eps: float) -> tuple[np.ndarray, np.ndarray]:
    status, controls, costate, _ = convex._clarabel_plan(g, 1.0 - eps, eps, N_RAD_S)
    assert status is guidance.SolveStatus.CONVERGED
    return controls, costate


@pytest.mark.parametrize("eps", [1.0, 0.3, 0.05, 1e-3])
def test_dual_ascent_agrees_with_clarabel(eps: float) -> None:
    """Above DUAL_MIN_WEIGHT the ascent answers, and its plan is Clarabel's to Clarabel's accuracy.

    800 s from x0 on the 1 s grid. Tolerances: controls 5e-6 u_max, costate
    1e-6 relative (observed at most 1.1e-6 u_max and 1.5e-7, at ε = 1e-3,
    where the ramp is narrowest and Clarabel's interior point least exact);
    the ascent's cost is never above Clarabel's (it is the exact minimiser:
    observed lower by up to 9e-12 relative; allowed 1e-12 above, rounding).
    """
    g = _full_grid()
    status, controls, costate, iterations = convex.plan_controls(g, eps, N_RAD_S)
    assert status is guidance.SolveStatus.CONVERGED
    assert iterations <= 12
    ref_controls, ref_costate = _clarabel(g, eps)
    assert np.abs(controls - ref_controls).max() <= 5e-6 * U_MAX
    assert np.linalg.norm(costate - ref_costate) <= 1e-6 * np.linalg.norm(ref_costate)

    def cost(u: np.ndarray) -> float:
        norms = np.linalg.norm(u, axis=1) / U_MAX
        return float(np.sum((1.0 - eps) * norms + eps * norms**2))

    assert cost(controls) <= cost(ref_controls) * (1.0 + 1e-12)


@pytest.mark.parametrize("eps", [0.3, 1e-3])
def test_grid_dual_gradient_and_hessian_are_its_derivatives(eps: float) -> None:
    """``grid_dual``'s gradient and Hessian are the derivatives of its value (central differences).

    At a ν where steps coast, ramp and thrust fully (the cold start of the
    800 s problem, which puts the busiest step at half throttle, scaled by
    1.5; no step within 1e-4 of a kink, where the Hessian jumps), with
    relative steps h = 1e-6 of ‖ν‖:
    gradient and Hessian within 1e-8 relative to their norms (central
    differences err by O(h²) ~1e-12 plus rounding ~1e-16/1e-6 = 1e-10;
    observed ≤ 3e-10 and 6e-11). A ν exactly on a kink would not do: the
    difference quotient there averages the two one-sided Hessians.
    """
    from cwrend_cli.physics.guidance import _grid_kernels as gk

    g = _full_grid()
    a, b = convex._scaled_rows(g)
    c1, c2 = 1.0 - eps, eps
    nu = np.empty(6)
    assert gk.cold_start(a, b, c1, c2, nu)
    nu *= 1.5
    grad, hess, u = np.empty(6), np.empty((6, 6)), np.empty((a.shape[0], 3))
    gk.grid_dual(a, b, nu, c1, c2, grad, hess, u)
    levels = np.linalg.norm(u, axis=1)
    assert np.any(levels == 0.0) and np.any(levels == 1.0)
    assert np.any((levels > 0.0) & (levels < 1.0))
    raw = (np.linalg.norm(np.einsum("jab,a->jb", a, nu), axis=1) - c1) / (2 * c2)
    assert np.min(np.minimum(np.abs(raw), np.abs(raw - 1.0))) > 1e-4
    h = 1e-6 * np.linalg.norm(nu)
    fd_grad, fd_hess = np.empty(6), np.empty((6, 6))
    g_t, h_t, u_t = np.empty(6), np.empty((6, 6)), np.empty_like(u)
    for i in range(6):
        e = np.zeros(6)
        e[i] = h
        up, _ = gk.grid_dual(a, b, nu + e, c1, c2, g_t, h_t, u_t)
        grad_up = g_t.copy()
        down, _ = gk.grid_dual(a, b, nu - e, c1, c2, g_t, h_t, u_t)
        fd_grad[i] = (up - down) / (2 * h)
        fd_hess[:, i] = (grad_up - g_t) / (2 * h)
    assert np.linalg.norm(fd_grad - grad) <= 1e-8 * np.linalg.norm(grad)
    assert np.linalg.norm(fd_hess - hess) <= 1e-8 * np.linalg.norm(hess)


def test_dual_plan_is_the_pointwise_minimiser_of_its_lagrangian() -> None:
    """KKT by construction: each control is the smoothed law of its step's ``y_j = A_jᵀν``.

    ``ν`` is recovered from the returned costate; the controls must equal
    ``u_max·clip((‖y‖ − 1 + ε)/(2ε), 0, 1)·ŷ`` to 1e-12 u_max (observed
    5e-16; the round trip through Φ(T)ᵀ, condition ~1e4, costs at most
    ~1e-12), stay within u_max exactly, and reach x_f to 1e-12 km (the
    ascent's tolerance; observed 5e-14).
    """
    eps = 0.3
    g = _full_grid()
    status, controls, costate, _ = convex.plan_controls(g, eps, N_RAD_S)
    assert status is guidance.SolveStatus.CONVERGED
    nu = -feasibility.multiplier_from_costate(g, N_RAD_S, costate)
    a, _ = convex._scaled_rows(g)
    y = np.einsum("jab,a->jb", a, nu)
    norms = np.linalg.norm(y, axis=1)
    level = np.clip((norms - 1.0 + eps) / (2.0 * eps), 0.0, 1.0)
    expected = U_MAX * level[:, None] * y / norms[:, None]
    assert np.abs(controls - expected).max() <= 1e-12 * U_MAX
    assert np.linalg.norm(controls, axis=1).max() <= U_MAX
    assert convex.terminal_miss(g, controls) <= 1e-12


def test_multiplier_and_costate_are_inverse() -> None:
    """``multiplier_from_costate`` undoes ``costate_from_multiplier`` (to 1e-12 relative)."""
    g = _full_grid()
    z = np.array([0.3, -1.2, 0.7, 2.0, -0.4, 1.1])
    back = feasibility.multiplier_from_costate(
        g, N_RAD_S, feasibility.costate_from_multiplier(g, N_RAD_S, z)
    )
    np.testing.assert_allclose(back, z, rtol=1e-12)


def test_warm_start_from_the_previous_plan_gives_the_same_plan_faster() -> None:
    """10 s later, from the previous plan's costate propagated: same plan, fewer iterations.

    The state 10 s on is the plan's own (held controls, exact dynamics), so
    the propagated plan is already optimal: the warm ascent needs ≤ 2
    iterations (observed 0) against the cold start's (observed 6), and both
    answers agree to 1e-9 u_max (observed 2e-15).
    """
    eps = 0.3
    g = _full_grid()
    _, controls, costate, _ = convex.plan_controls(g, eps, N_RAD_S)
    x10 = _grid_state(g, controls, 10)
    later = feasibility.grid_problem(N_RAD_S, x10, np.zeros(6), SC.horizon_s - 10.0, 1.0, U_MAX)
    warm = costate_stm(N_RAD_S, 10.0) @ costate
    w_status, w_controls, _, w_iters = convex.plan_controls(later, eps, N_RAD_S, warm=warm)
    c_status, c_controls, _, c_iters = convex.plan_controls(later, eps, N_RAD_S)
    assert w_status is c_status is guidance.SolveStatus.CONVERGED
    assert w_iters <= 2 < c_iters
    assert np.abs(w_controls - c_controls).max() <= 1e-9 * U_MAX


def test_clarabel_answers_when_the_ascent_does_not_converge(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An ascent allowed no iteration fails; the plan is then exactly Clarabel's."""
    monkeypatch.setattr(convex, "_NEWTON", tuple(convex.NewtonSettings(max_iter=0)))
    g = _full_grid()
    status, controls, _, _ = convex.plan_controls(g, 0.3, N_RAD_S)
    assert status is guidance.SolveStatus.CONVERGED
    np.testing.assert_array_equal(controls, _clarabel(g, 0.3)[0])


def _fuel(u: np.ndarray) -> float:
    return float(np.linalg.norm(u, axis=1).sum())


def _counting_programs(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Record the number of steps of every program Clarabel is given."""
    sizes: list[int] = []
    program = convex._clarabel_program

    def spy(g: feasibility.GridProblem, linear: float, weight: float) -> tuple[object, int]:
        sizes.append(g.blocks.shape[0])
        return program(g, linear, weight)

    monkeypatch.setattr(convex, "_clarabel_program", spy)
    return sizes


def test_small_weight_plan_is_the_whole_programs_optimum(monkeypatch: pytest.MonkeyPatch) -> None:
    """ε = 0 (weight ρ): Clarabel on the screened steps gives the whole program's plan.

    800 s from x0: the screen keeps the 171 steps of the two burns of 800.
    Against Clarabel on all 800 steps: controls within 1e-5 u_max and fuel
    within 1e-9 relative (observed 1.0e-6 and 1.3e-11 — the spread two
    Clarabel settings show on this program, whose throttle moves by
    δ/(2ρ) for a multiplier error δ); every left-out step holds zero and
    passes the optimality test ``‖A_jᵀν‖ ≤ 1`` at the plan's own multiplier
    (observed ≤ 0.968).
    """
    sizes = _counting_programs(monkeypatch)
    g = _full_grid()
    status, controls, costate, _ = convex.plan_controls(g, 0.0, N_RAD_S)
    assert status is guidance.SolveStatus.CONVERGED
    assert sizes == [171]
    _, whole, _, _ = convex._clarabel_plan(g, 1.0, convex.REGULARISATION, N_RAD_S)
    assert np.abs(controls - whole).max() <= 1e-5 * U_MAX
    assert _fuel(controls) == pytest.approx(_fuel(whole), rel=1e-9)
    left_out = np.linalg.norm(controls, axis=1) == 0.0
    assert left_out.sum() == 800 - 171
    nu = -feasibility.multiplier_from_costate(g, N_RAD_S, costate)
    assert convex._step_norms(convex._scaled_rows(g)[0], nu)[left_out].max() <= 1.0


def test_screen_missing_a_thrusting_step_is_corrected(monkeypatch: pytest.MonkeyPatch) -> None:
    """A screen without the first steps of the first burn: the test finds them, a second program.

    Steps 0–4 thrust in the optimum (the first burn is steps 0–96); left out,
    the reduced optimum burns later at more fuel and its multiplier fails
    the test on them, so they join (295 → 300 steps). The final plan is the
    whole program's: controls within 1e-5 u_max, fuel within 1e-9 (observed
    3.4e-6 and 5e-11).
    """
    sizes = _counting_programs(monkeypatch)
    g = _full_grid()
    keep = np.concatenate([np.arange(5, 150), np.arange(650, 800)])
    status, controls, _, _ = convex._clarabel_plan(g, 1.0, convex.REGULARISATION, N_RAD_S, keep)
    assert status is guidance.SolveStatus.CONVERGED
    assert sizes == [295, 300]
    _, whole, _, _ = convex._clarabel_plan(g, 1.0, convex.REGULARISATION, N_RAD_S)
    assert np.abs(controls - whole).max() <= 1e-5 * U_MAX
    assert _fuel(controls) == pytest.approx(_fuel(whole), rel=1e-9)


def test_screen_too_small_to_reach_xf_falls_back_to_the_whole_program(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The first 400 steps cannot reach x_f (Clarabel: infeasible): all 800 are solved."""
    sizes = _counting_programs(monkeypatch)
    g = _full_grid()
    status, controls, _, _ = convex._clarabel_plan(
        g, 1.0, convex.REGULARISATION, N_RAD_S, np.arange(400)
    )
    assert status is guidance.SolveStatus.CONVERGED
    assert sizes == [400, 800]
    np.testing.assert_array_equal(
        controls, convex._clarabel_plan(g, 1.0, convex.REGULARISATION, N_RAD_S)[1]
    )


# --- architectures, configuration, CLI -------------------------------------------


def test_socp_slugs_and_groups() -> None:
    assert set(ARCHITECTURES) == {"plain_fixed", "mtf_fixed", "plain_adaptive", "mtf_adaptive"}
    paper = [a for a in ALL_ARCHITECTURES.values() if a.estimator != "stf"]  # issue 35's apart
    socp = [a for a in paper if a.method == "socp"]
    assert [a.slug for a in socp] == [f"{s}_socp" for s in ARCHITECTURES]
    assert parse_archs("all") == tuple(ARCHITECTURES.values())
    assert parse_archs("all_socp") == tuple(socp)
    assert len(parse_archs("everything")) == 8
    assert parse_archs("plain_fixed, mtf_adaptive_socp")[1].method == "socp"
    g = Guidance()
    assert ARCHITECTURES["mtf_fixed"].resolved_method(g) == "shooting"
    assert ARCHITECTURES["mtf_fixed"].resolved_method(Guidance(method="socp")) == "socp"
    assert ALL_ARCHITECTURES["mtf_fixed_socp"].resolved_method(g) == "socp"
    with pytest.raises(ConfigError, match=r"allowed: .*mtf_adaptive_socp"):
        parse_archs("mtf_socp")


def test_bad_method_exits_2_naming_the_field() -> None:
    result = runner.invoke(app, ["config", "validate", str(PAPER), "--set", "guidance.method=cvx"])
    assert result.exit_code == 2
    assert "guidance.method" in result.output


def test_method_in_config_show() -> None:
    result = runner.invoke(app, ["config", "show", str(PAPER)])
    assert result.exit_code == 0
    assert 'method = "shooting"' in result.output


def test_socp_closed_loop_through_the_cli(tmp_path: Path) -> None:
    out = tmp_path / "run"
    result = runner.invoke(
        app, ["run", str(PAPER), "--arch", "mtf_adaptive_socp", "--out", str(out), "-q"]
    )
    assert result.exit_code == 0, result.output
    summary = pd.read_parquet(out / "summary.parquet")
    solves = pd.read_parquet(out / "solves.parquet")
    run = summary[summary["arch"] == "mtf_adaptive_socp"]
    assert len(run) == 1
    mine = solves[solves["arch"] == "mtf_adaptive_socp"]
    assert set(mine["fallback_step"]) == {"socp"}
    assert (mine["kind"] == "initial").sum() == 1
    ok = mine[mine["status"] == "converged"]
    assert len(ok) >= 0.9 * len(mine)
    assert (ok["residual_km"] < 1e-8).all()
    assert (mine["wall_time_ms"] > 0).all()


def test_chain_plan_of_last_resort_on_seed_262(tmp_path: Path) -> None:
    """plain_fixed seed 262 (22 failed re-solves and 52 m before issue 16): no failure, < 10 m."""
    out = tmp_path / "run"
    result = runner.invoke(
        app, ["run", str(PAPER), "--arch", "plain_fixed", "--seed", "262", "--out", str(out), "-q"]
    )
    assert result.exit_code == 0, result.output
    solves = pd.read_parquet(out / "solves.parquet")
    summary = pd.read_parquet(out / "summary.parquet")
    assert (solves["status"] != "failed").all()
    plans = solves[solves["fallback_step"] == "socp_plan"]
    assert len(plans) >= 1
    assert (plans["status"] == "converged").all() and plans["success"].all()
    # the residual of the step used (the plan's), not the failed warm attempt's
    assert (plans["residual_km"] < 1e-8).all()
    miss_km = float(summary.loc[summary["arch"] == "plain_fixed", "miss_km"].iloc[0])
    assert miss_km < 0.010


def test_degenerate_problem_gets_a_plan() -> None:
    """A degenerate ε = 0 re-solve (‖λ_v‖ ≈ 1 over the whole horizon) yields a valid plan.

    The state, horizon and warm start are those of the first failed re-solve of
    ``plain_fixed --seed 262`` before issue 16 (t = 511 s; captured from the
    loop): the warm Newton ascent fails on it; the chain's ``socp_plan`` step
    returns held controls that reach x_f, and the optimal costate (the cone
    program's terminal multiplier) has ‖λ_v‖ within 1e-5 of 1 over all 289 s
    (observed 0.999994–1.000004): the fuel-optimal set is a face, not a point.
    """
    x0 = np.array(
        [
            0.004412438163979933,
            0.857705772007222,
            12.032330172517076,
            0.0008786391298324018,
            -0.0033571507573003675,
            -0.04574663867586507,
        ]
    )
    guess = np.array(
        [
            0.00010143349996422298,
            0.001519424856174881,
            0.008091334896182344,
            -0.052551172146071565,
            0.2976916331501046,
            0.8704139891154757,
        ]
    )
    problem = guidance.ShootingProblem(x0, 289.0, 0.0, N_RAD_S, U_MAX)
    warm = guidance.solve(problem, guess, guidance.SolverSettings(fallback="none"))
    assert warm.status is guidance.SolveStatus.FAILED
    result = guidance.solve(problem, guess)
    assert result.status is guidance.SolveStatus.CONVERGED
    assert result.step == "socp_plan"
    assert result.controls is not None and result.controls.shape == (289, 3)
    assert np.linalg.norm(result.controls, axis=1).max() <= U_MAX
    g = feasibility.grid_problem(N_RAD_S, x0, np.zeros(6), 289.0, 1.0, U_MAX)
    assert convex.terminal_miss(g, result.controls) == pytest.approx(result.residual_km)
    assert result.residual_km < 1e-11
    t = np.linspace(0.0, 289.0, 579)
    speed = [np.linalg.norm((costate_stm(N_RAD_S, s) @ result.costate)[3:]) for s in t]
    assert np.max(np.abs(np.array(speed) - 1.0)) < 1e-5
