"""The shooting re-solve with the Schweighart–Sedwick design model (issue 33 item 1).

For the linear model ``ẋ = A x + B u`` the primer vector is ``λ_v(t) = Bᵀ Φ(T, t)ᵀ ν``
(Lawden 1963), with ``Φ = e^{A(T − t)}`` for the time-invariant ``ss`` model; the
smoothed minimum-fuel control law (paper Eq. 10) and the shooting residual are CW's.
Checked here against what is written in the test: the adjoint ``λ̇ = −Aᵀλ`` and the
state equations integrated by DOP853, CW at J2 = 0, and the cone program of the same
model (the other method solving the same problem). Paper scenario (Table 1), chief at
i = 51.6° (campaigns/paper_j2.toml).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from cwrend_cli.physics import design_models as dm
from cwrend_cli.physics import guidance, simulation
from cwrend_cli.physics.dynamics import costate_stm
from cwrend_cli.physics.guidance import _kernels as kern
from cwrend_cli.physics.guidance import convex, feasibility
from cwrend_cli.physics.params import (
    ALL_ARCHITECTURES,
    Architecture,
    DesignModel,
    Guidance,
    Problem,
    Scenario,
    Truth,
)
from cwrend_cli.physics.truth import J2_EARTH, R_EARTH_KM, semi_major_axis_km

SC = Scenario()
N = SC.mean_motion_rad_s
X0 = np.asarray(SC.x0, dtype=float)
XF = np.asarray(SC.xf, dtype=float)
J2_TRUTH = Truth(model="j2", inclination_deg=51.6)
SS = dm.ss_model(J2_TRUTH, SC)


def _ss_system() -> tuple[np.ndarray, np.ndarray]:
    """A and B of Schweighart & Sedwick (2002), written here from their s and c.

    s = 3 J2 R_E²/(8 r²) (1 + 3 cos 2i), c = √(1 + s); ẍ = 2nc ẏ + (5c² − 2)n² x,
    ÿ = −2nc ẋ, z̈ = −(3c² − 2)n² z (the linear equations with constant coefficients).
    """
    r = semi_major_axis_km(N)
    s = 3.0 * J2_EARTH * R_EARTH_KM**2 / (8.0 * r * r) * (1.0 + 3.0 * math.cos(math.radians(103.2)))
    c2 = 1.0 + s
    a = np.zeros((6, 6))
    a[0:3, 3:6] = np.eye(3)
    a[3, 0] = (5.0 * c2 - 2.0) * N * N
    a[3, 4] = 2.0 * N * math.sqrt(c2)
    a[4, 3] = -2.0 * N * math.sqrt(c2)
    a[5, 2] = -(3.0 * c2 - 2.0) * N * N
    b = np.zeros((6, 3))
    b[3:6] = np.eye(3)
    return a, b


def _problem(eps: float, design: dm.LinearTimeInvariant | None = SS) -> guidance.ShootingProblem:
    return guidance.ShootingProblem(X0, SC.horizon_s, eps, N, SC.u_max_km_s2, XF, design)


def _solved(eps: float, design: dm.LinearTimeInvariant | None = SS) -> np.ndarray:
    problem = _problem(eps, design)
    result = guidance.solve(problem, guidance.energy_optimal_costate(problem))
    assert result.status is guidance.SolveStatus.CONVERGED
    return result.costate


def test_the_ss_costate_is_the_integrated_adjoint() -> None:
    """λ(τ) = Φ(−τ)ᵀλ₀ and the primer's derivatives Bᵀ(−Aᵀ)ᵏλ(τ), k ≤ 3, against DOP853.

    The adjoint λ̇ = −Aᵀλ of the A written in the test, integrated at rtol 1e-13 over
    the 800 s horizon; agreement to 1e-10 of ‖λ₀‖ (the integration's accuracy).
    """
    a, _ = _ss_system()
    lam0 = np.array([-5.6e-5, 1.5e-3, 2.2e-3, -0.56, 0.82, 0.63])
    times = np.linspace(0.0, SC.horizon_s, 17)
    sol = solve_ivp(
        lambda _t, lam: -a.T @ lam, (0.0, SC.horizon_s), lam0, method="DOP853",
        t_eval=times, rtol=1e-13, atol=1e-16,
    )  # fmt: skip
    model = guidance.kernel_model(N, SS)
    ws = kern.workspace()
    q = np.empty((4, 3))
    out = np.empty(6)
    scale = np.linalg.norm(lam0)
    for t, lam in zip(times, sol.y.T, strict=True):
        kern.costate_at(model, t, lam0, out)
        assert np.abs(out - lam).max() < 1e-10 * scale
        kern.model_primer(model, lam0, t, 3, q, ws)
        mu = lam.copy()
        for k in range(4):
            assert np.abs(q[k] - mu[3:]).max() < 1e-10 * scale * N**k
            mu = -a.T @ mu


def test_ss_shooting_reaches_the_terminal_state() -> None:
    """The ε = 0 plan, flown by DOP853 through the A written in the test, reaches x_f.

    Integrated between the switching times at rtol 1e-12 (the control is
    discontinuous there): the miss is within the solver's tolerances
    (1e-9 km, 1e-12 km/s); measured 2.8e-12 km and 3.6e-14 km/s.
    """
    a, b = _ss_system()
    lam0 = _solved(0.0)
    problem = _problem(0.0)
    edges = [0.0, *guidance.switching_times(problem, lam0), SC.horizon_s]
    assert len(edges) == 4  # burn, coast, burn: the paper's fuel-optimal structure

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        lam = solve_costate(t)
        return np.asarray(a @ x + b @ guidance.control(lam[3:], 0.0, SC.u_max_km_s2))

    def solve_costate(t: float) -> np.ndarray:
        out = np.empty(6)
        kern.costate_at(guidance.kernel_model(N, SS), t, lam0, out)
        return out

    x = X0.copy()
    for t0, t1 in itertools.pairwise(edges):
        x = solve_ivp(rhs, (t0, t1), x, method="DOP853", rtol=1e-12, atol=1e-15).y[:, -1]
    assert np.linalg.norm(x[:3] - XF[:3]) < 1e-9
    assert np.linalg.norm(x[3:] - XF[3:]) < 1e-12


@pytest.mark.parametrize("eps", [0.5, 0.05, 0.0])
def test_ss_at_j2_zero_is_cw(eps: float) -> None:
    """At J2 = 0 the ss model is CW (c = 1): the same costate to 1e-12 relative.

    Only rounding differs (the general closed form against CW's, e.g. β²/ω³ against
    4/n); measured ≤ 2e-15.
    """
    flat = dm.schweighart_sedwick(N, semi_major_axis_km(N), 51.6, 0.0, R_EARTH_KM).lti()
    lam_ss = _solved(eps, flat)
    lam_cw = _solved(eps, None)
    assert np.abs(lam_ss - lam_cw).max() < 1e-12 * np.abs(lam_cw).max()


def test_ss_shooting_costs_what_the_ss_cone_program_costs() -> None:
    """Both methods solve the ss minimum-fuel problem: the same Δv within 1e-5 relative.

    Shooting: the continuous optimum, u_max × the burn time between its switching
    times. Cone program: Σ‖u_k‖Δt of its held controls on the 1 s grid of the ss steps
    (:func:`cwrend_cli.physics.design_models.step_tables`), a restriction of the same
    problem, so never cheaper; it is dearer by the held steps at the switches and its
    regularisation (ρ = 1e-6, convex.py): measured 2.0e-6 relative, as CW's 2.2e-6.
    """
    problem = _problem(0.0)
    lam0 = _solved(0.0)
    t1, t2 = guidance.switching_times(problem, lam0)
    dv_shooting = SC.u_max_km_s2 * (t1 + SC.horizon_s - t2)
    tables = dm.step_tables("ss", SC, J2_TRUTH)
    grid = feasibility.grid_problem_from_steps(
        tables.phi, tables.gam, X0, XF, SC.dt_s, SC.u_max_km_s2
    )
    plan = convex.solve(grid, 0.0, N)
    assert plan.controls is not None
    dv_socp = float(np.linalg.norm(plan.controls, axis=1).sum()) * SC.dt_s
    assert 0.0 <= dv_socp - dv_shooting < 1e-5 * dv_shooting


def test_validation_accepts_ss_with_shooting_and_refuses_ya() -> None:
    """'ss' flies with the shooting architectures; 'ya' is refused with the reason."""
    arch = Architecture("mtf_adaptive", "mtf", adaptive=True)
    assert dm.unsupported(DesignModel(guidance="ss"), arch, Guidance()) is None
    assert dm.unsupported(DesignModel(guidance="ss"), arch, Guidance(), constrained=True) is None
    reason = dm.unsupported(DesignModel(guidance="ya"), arch, Guidance())
    assert reason is not None
    assert "model.guidance = 'ya'" in reason and "time-varying" in reason


@pytest.mark.parametrize("slug", ["mtf_fixed", "mtf_adaptive_socp"])
def test_the_shooting_loop_plans_with_ss_and_the_cone_programs_loop_as_before(slug: str) -> None:
    """With model.guidance = 'ss' the shooting loop's kernels and costate step are ss's.

    Its costate step is e^{−AᵀΔt} of the A written in the test (to 1e-13, the closed
    form against scipy's expm); the cone program's loop keeps CW's (its plan is the
    held controls of the ss tables; the costate law is only its fallback, as before).
    """
    problem = Problem(truth=J2_TRUTH, model=DesignModel(guidance="ss"))
    arch = ALL_ARCHITECTURES[slug]
    loop = simulation._loop_parts(
        problem, arch, np.zeros((SC.n_steps, 3)), np.zeros(SC.n_steps, dtype=np.bool_), None,
        X0, np.zeros(6), 0.0, None,
    )  # fmt: skip
    if slug == "mtf_fixed":
        a, _ = _ss_system()
        assert loop.model.n == tuple(SS.kernel())
        assert np.abs(loop.model.lam_step - expm(-a.T * SC.dt_s)).max() < 1e-13
    else:
        assert loop.model.n == N
        assert np.array_equal(loop.model.lam_step, costate_stm(N, SC.dt_s))
