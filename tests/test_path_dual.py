"""The dual solver of the constrained program at adaptive ε (issue 32; guidance/path_dual.py).

Clarabel is the reference: the dual solver's plans are compared with
``constrained.plan(solver="clarabel")`` on random constrained problems, and its
row algebra (rows at any node through ``h = (Φ^{k−N})ᵀ g``) with the
unconstrained dual ascent of ``convex`` when the rows are the terminal state's only.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_constrained_guidance import (
    DT,
    N_MOTION,
    SAFE_APPROACH,
    U_MAX,
    _far_problem,
    _geometry,
    _unsafe,
)

from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.guidance import constrained as cp
from cwrend_cli.physics.guidance import convex, feasibility, path_dual
from cwrend_cli.physics.guidance.results import SolveStatus


def _cost(controls: np.ndarray, eps: float) -> float:
    """The scaled cost ``Σ (1 − ε)‖ũ‖ + max(ε, ρ)‖ũ‖²`` of a plan (convex module docstring)."""
    norms = np.linalg.norm(controls / U_MAX, axis=1)
    weight = max(eps, convex.REGULARISATION)
    return float(np.sum((1.0 - min(eps, 1.0)) * norms + weight * norms**2))


@pytest.mark.parametrize("eps", [0.3, 0.9])
def test_terminal_rows_alone_give_the_unconstrained_dual_ascents_plan(eps: float) -> None:
    """With the six terminal rows only, the program is convex.plan_controls's: the same
    controls to 1e-9 u_max (both stop at a terminal miss of ≤ 1e-12 km; measured ≤ 1e-15)."""
    rng = np.random.default_rng(3290)
    x0 = np.r_[rng.normal(size=3) * 2.0, rng.normal(size=3) * 1e-3]
    xf = np.zeros(6)
    g = feasibility.grid_problem(N_MOTION, x0, xf, 300.0, DT, U_MAX)
    status, reference, _, _ = convex.plan_controls(g, eps, N_MOTION)
    assert status is SolveStatus.CONVERGED
    scale = g.row_scale
    rows = path_dual.DualRows(
        np.full(6, 300, dtype=np.int64),
        np.diag(scale),
        scale * xf,
        np.ones(6, dtype=bool),
        scale * np.r_[np.full(3, 1e-12), np.full(3, 1e-15)],
    )
    ans = path_dual.solve(N_MOTION, DT, U_MAX, x0, g.blocks, eps, eps, rows)
    assert ans.converged
    np.testing.assert_allclose(ans.controls, reference, rtol=0, atol=1e-9 * U_MAX)
    np.testing.assert_allclose(ans.states[-1], xf, rtol=0, atol=1e-12)


def test_dual_plans_match_clarabels_on_random_adaptive_problems() -> None:
    """On 8 random problems whose straight path crosses the zone (ε from 0.2 to 1, cold):
    the default solver's plan has the cost of Clarabel's within 1e-6 relative (both stop
    at ~1e-9 km of feasibility; measured ≤ 4.1e-11, controls within 4.9e-7 u_max,
    positions within 8.5e-8 km), every node outside the zone (the planes are inner
    approximations) and the terminal state within 1e-9 km. The dual solver answers most
    of these cold programs (measured: 6 of 8; the others fall back to Clarabel and are
    counted in ``fallbacks``)."""
    rng = np.random.default_rng(3291)
    programs, fallbacks = 0, 0
    for _ in range(8):
        x0, xf, geo = _far_problem(rng)
        eps = float(rng.uniform(0.2, 1.0))
        ref = cp.plan(N_MOTION, DT, U_MAX, x0, xf, 300.0, eps, geo, solver="clarabel")
        res = cp.plan(N_MOTION, DT, U_MAX, x0, xf, 300.0, eps, geo)
        assert ref.status is SolveStatus.CONVERGED and res.status is SolveStatus.CONVERGED
        assert ref.fallbacks == 0
        programs += res.scp_iterations
        fallbacks += res.fallbacks
        assert abs(_cost(res.controls, eps) - _cost(ref.controls, eps)) <= 1e-6 * _cost(
            ref.controls, eps
        )
        assert geo.semi_axes_km is not None
        level = np.sum((res.positions[1:-1] / geo.semi_axes_km) ** 2, axis=1)
        assert np.all(level >= 1.0)
        states, _ = cp.node_positions(N_MOTION, DT, x0, res.controls)
        assert np.max(np.abs(states[-1] - xf)) <= 1e-9
    assert fallbacks <= programs // 2


def test_an_unknown_solver_is_refused() -> None:
    x0, xf, geo = _far_problem(np.random.default_rng(3292))
    with pytest.raises(ValueError, match="solver"):
        cp.plan(N_MOTION, DT, U_MAX, x0, xf, 300.0, 0.5, geo, solver="pipg")


def test_shifted_duals_move_back_by_the_steps_flown_and_drop_the_past() -> None:
    """A row's code carries its node: after 10 steps a row at node 15 is at node 5, one at
    node 10 falls on the new start (node 0) and is dropped."""
    node = cp._CODE_NODE
    duals = cp.Duals(np.array([15 * node + 3, 10 * node + 1, 300 * node]), np.ones(3))
    shifted = cp.shift_duals(duals, 10)
    assert shifted is not None
    np.testing.assert_array_equal(shifted.codes, [5 * node + 3, 290 * node])
    assert cp.shift_duals(None, 10) is None


def test_a_warm_start_from_the_last_plans_duals_gives_the_same_plan() -> None:
    """A re-solve 10 steps on, started from the first plan's row multipliers moved by 10
    steps, gives the cold re-solve's plan (controls within 1e-6 u_max: both certified to
    1e-9 km; measured 1.4e-9) in fewer dual iterations (measured 9 against 20)."""
    rng = np.random.default_rng(3293)
    x0, xf, geo = _far_problem(rng)
    first = cp.plan(N_MOTION, DT, U_MAX, x0, xf, 300.0, 0.9, geo)
    assert first.duals is not None
    x1 = cp.node_positions(N_MOTION, DT, x0, first.controls[:10])[0][-1]
    warm_u = first.controls[10:]
    cold = cp.plan(N_MOTION, DT, U_MAX, x1, xf, 290.0, 0.9, geo, warm_controls=warm_u)
    warm = cp.plan(
        N_MOTION, DT, U_MAX, x1, xf, 290.0, 0.9, geo, warm_controls=warm_u,
        warm_duals=cp.shift_duals(first.duals, 10),
    )  # fmt: skip
    assert cold.fallbacks == 0 and warm.fallbacks == 0
    np.testing.assert_allclose(warm.controls, cold.controls, rtol=0, atol=1e-6 * U_MAX)
    assert warm.solver_iterations < cold.solver_iterations


def _every_trust_row(sub: cp._Subproblem) -> tuple[np.ndarray, np.ndarray]:
    """Every trust row of ``sub`` (six a constrained node): the program written whole."""
    boxed = np.flatnonzero(sub.modes > 0)
    return np.repeat(boxed, 6), np.tile(np.arange(6), boxed.size)


def test_lazy_trust_rows_give_the_plan_of_every_trust_row_written(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The dual solver writes only the trust rows an answer breaks (or the warm start holds
    active) and certifies the rest; on 4 random cold problems (ε 0.2–1, a trust radius of
    50 m so that the box binds: 8 SCP iterations each) the plan equals the one with every
    trust row written from the start: same status, SCP iterations and programs left to
    Clarabel (1–2 of 8, both ways), controls within 1e-6 u_max (both certified to 1e-9 km;
    measured 4.6e-14)."""
    monkeypatch.setattr(cp, "TRUST_RADIUS_FACTOR", 0.25)  # a box that binds
    rng = np.random.default_rng(3294)
    problems = []
    for _ in range(4):
        x0, xf, geo = _far_problem(rng)
        problems.append((x0, xf, geo, float(rng.uniform(0.2, 1.0))))
    lazy = [cp.plan(N_MOTION, DT, U_MAX, x0, xf, 300.0, e, geo) for x0, xf, geo, e in problems]
    monkeypatch.setattr(cp, "_warm_trust", _every_trust_row)
    whole = [cp.plan(N_MOTION, DT, U_MAX, x0, xf, 300.0, e, geo) for x0, xf, geo, e in problems]
    for a, b in zip(lazy, whole, strict=True):
        assert a.status is SolveStatus.CONVERGED and b.status is SolveStatus.CONVERGED
        assert a.scp_iterations == b.scp_iterations
        assert a.fallbacks == b.fallbacks
        np.testing.assert_allclose(a.controls, b.controls, rtol=0, atol=1e-6 * U_MAX)


def test_the_dual_solver_writes_far_fewer_trust_rows_than_the_box_has(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """On a random cold problem whose trust box (50 m) binds, the programs given to the
    dual solver carry, summed over its solves, some trust rows but fewer than a tenth of
    those of the whole box (six a constrained node, summed over the SCP programs; measured:
    424 of 14,352 over 8 SCP programs)."""
    monkeypatch.setattr(cp, "TRUST_RADIUS_FACTOR", 0.25)
    x0, xf, geo = _far_problem(np.random.default_rng(3295))
    written, boxed = [0], [0]
    solve, rows_of = path_dual.solve, cp._dual_rows

    def counting_solve(*args: object, **kwargs: object) -> path_dual.DualAnswer:
        rows = args[7]
        assert isinstance(rows, path_dual.DualRows)
        coeffs = rows.coeffs[~rows.equality]
        # a trust row: one nonzero coefficient, on a position component
        written[0] += int(
            np.sum((np.count_nonzero(coeffs, axis=1) == 1) & (coeffs[:, 3:] == 0).all(1))
        )
        return solve(*args, **kwargs)  # type: ignore[arg-type]

    def counting_rows(sub: cp._Subproblem, *args: object) -> object:
        boxed[0] += 6 * int(np.count_nonzero(sub.modes > 0))
        return rows_of(sub, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(path_dual, "solve", counting_solve)
    monkeypatch.setattr(cp, "_dual_rows", counting_rows)
    res = cp.plan(N_MOTION, DT, U_MAX, x0, xf, 300.0, 0.5, geo)
    assert res.status is SolveStatus.CONVERGED
    assert written[0] > 0
    assert written[0] < boxed[0] // 10


def test_a_warm_start_that_fails_is_retried_from_the_guess() -> None:
    """A re-solve whose warm multipliers the Newton method cannot recover from within its
    iteration cap (the last plan's, shifted, times 1e12) is solved again from the guess of
    the rows the iterate touches, by the dual solver: no program left to Clarabel (before:
    one) and the cold re-solve's plan (controls within 1e-6 u_max; measured 0)."""
    x0, xf, geo = _far_problem(np.random.default_rng(3293))
    first = cp.plan(N_MOTION, DT, U_MAX, x0, xf, 300.0, 0.9, geo)
    shifted = cp.shift_duals(first.duals, 10)
    assert shifted is not None
    x1 = cp.node_positions(N_MOTION, DT, x0, first.controls[:10])[0][-1]
    warm_u = first.controls[10:]
    cold = cp.plan(N_MOTION, DT, U_MAX, x1, xf, 290.0, 0.9, geo, warm_controls=warm_u)
    bad = cp.plan(
        N_MOTION, DT, U_MAX, x1, xf, 290.0, 0.9, geo, warm_controls=warm_u,
        warm_duals=cp.Duals(shifted.codes, shifted.values * 1e12),
    )  # fmt: skip
    assert bad.status is SolveStatus.CONVERGED
    assert bad.fallbacks == 0
    np.testing.assert_allclose(bad.controls, cold.controls, rtol=0, atol=1e-6 * U_MAX)


def _terminal_rows(g: feasibility.GridProblem, xf: np.ndarray) -> path_dual.DualRows:
    """The six terminal rows of ``g`` at the constrained program's tolerances (1e-9 km,
    1e-12 km/s: ``constrained.DUAL_TOL_KM``, ``DUAL_TOL_KM_S``)."""
    scale = g.row_scale
    return path_dual.DualRows(
        np.full(6, g.blocks.shape[0], dtype=np.int64),
        np.diag(scale),
        scale * xf,
        np.ones(6, dtype=bool),
        scale * np.r_[np.full(3, cp.DUAL_TOL_KM), np.full(3, cp.DUAL_TOL_KM_S)],
    )


def test_the_weight_homotopy_solves_the_fixed_eps_program() -> None:
    """At ε = 0 (quadratic weight ρ = 1e-6) the dual is nearly piecewise linear: from a cold
    start Newton at ρ failed on 2 of these 4 random problems (150 iterations); followed down
    from 1e-3 it converges on all 4 (measured 36–87 iterations) to Clarabel's plan
    (convex.plan_controls: the screened program by Clarabel) within 1e-5 u_max (Clarabel's
    own spread at ρ, where a multiplier error δ moves a throttle by δ/(2ρ); measured
    4.4e-7) at a cost within 1e-9 relative (measured 5.4e-11, never above Clarabel's by
    more than 3e-12)."""
    rng = np.random.default_rng(3290)
    for _ in range(4):
        x0 = np.r_[rng.normal(size=3) * 2.0, rng.normal(size=3) * 1e-3]
        xf = np.zeros(6)
        g = feasibility.grid_problem(N_MOTION, x0, xf, 300.0, DT, U_MAX)
        status, reference, _, _ = convex.plan_controls(g, 0.0, N_MOTION)
        assert status is SolveStatus.CONVERGED
        ans = path_dual.solve(
            N_MOTION, DT, U_MAX, x0, g.blocks, 0.0, convex.REGULARISATION, _terminal_rows(g, xf)
        )
        assert ans.converged
        np.testing.assert_allclose(ans.controls, reference, rtol=0, atol=1e-5 * U_MAX)
        assert abs(_cost(ans.controls, 0.0) - _cost(reference, 0.0)) <= 1e-9 * _cost(reference, 0.0)
        np.testing.assert_allclose(ans.states[-1], xf, rtol=0, atol=1e-9)


def test_held_steps_that_should_thrust_wake_and_the_plan_is_the_whole_programs() -> None:
    """With ``keep`` (a third of the steps that thrust in the plan of every step left out,
    the rest held at zero) the held steps whose zero does not minimise their Lagrangian
    wake, and the plan is that of every step free: controls within 1e-9 u_max (both
    certified; measured 1.0e-10), some of the held steps thrusting."""
    rng = np.random.default_rng(3296)
    for eps in (0.5, 0.1):
        x0 = np.r_[rng.normal(size=3) * 2.0, rng.normal(size=3) * 1e-3]
        xf = np.zeros(6)
        g = feasibility.grid_problem(N_MOTION, x0, xf, 300.0, DT, U_MAX)
        rows = _terminal_rows(g, xf)
        whole = path_dual.solve(N_MOTION, DT, U_MAX, x0, g.blocks, eps, eps, rows)
        on = np.flatnonzero(np.linalg.norm(whole.controls, axis=1) > 0.0)
        held = on[on % 3 == 0]
        kept = path_dual.solve(
            N_MOTION, DT, U_MAX, x0, g.blocks, eps, eps, rows, keep=np.setdiff1d(on, held)
        )
        assert whole.converged and kept.converged
        np.testing.assert_allclose(kept.controls, whole.controls, rtol=0, atol=1e-9 * U_MAX)
        assert np.any(np.linalg.norm(kept.controls[held], axis=1) > 0.0)


def test_held_norms_are_the_steps_lagrangian_slopes() -> None:
    """``held_norms`` is ‖A_jᵀ λ_j‖ with λ_j = Σ over the rows after step j of y_i h_i,
    checked against the sum written out row by row (to 1e-12 relative)."""
    rng = np.random.default_rng(3297)
    steps, count = 30, 7
    a = rng.normal(size=(steps, 6, 3))
    h = rng.normal(size=(count, 6))
    nodes = np.sort(rng.integers(1, steps + 1, size=count))
    y = rng.normal(size=count)
    expected = np.empty(steps)
    for j in range(steps):
        lam = sum((y[i] * h[i] for i in range(count) if nodes[i] > j), np.zeros(6))
        expected[j] = np.linalg.norm(a[j].T @ lam)
    np.testing.assert_allclose(path_dual.held_norms(a, h, nodes, y), expected, rtol=1e-12)


def test_fixed_eps_dual_plans_match_clarabels_on_warm_re_solves() -> None:
    """At ε = 0 the default solver gives the plans of Clarabel alone: on 8 random problems
    (a plan by Clarabel, then the re-solve 10 steps on from its shifted controls, as in the
    closed loop) cost within 1e-8 relative, controls within 1e-2 u_max, positions within
    1e-5 km, the terminal state within 1e-9 km and every node outside the zone. Some
    re-solves are answered by the dual solver (measured 5 of 8; the others are left to
    Clarabel, counted in ``fallbacks``): before it, none at ε = 0.

    The tolerances are the certificate's. The dual answer meets the terminal rows to
    DUAL_TOL_KM and DUAL_TOL_KM_S (1e-9 km, 1e-12 km/s), and its cost may lie below the
    optimum by the rows' multipliers times those tolerances: about 1e-7 of 17.7 here
    (terminal velocity rows, 1e-12 km/s ≈ 1e-9 of a step's u_max·dt). At ρ = 1e-6 the
    program is nearly a linear one, flat along shifts of a thrust arc: a plan whose cost is
    Δ above the optimum may differ from it by up to √(Δ/ρ) in ‖ũ‖ (the ρ‖ũ‖² term is the
    only curvature), about 0.4 for Δ = 1e-8 relative. Measured: cost 6.5e-9, controls
    6.7e-3 u_max, positions 1.5e-6 km on the first problem and 4.5e-11, 1.3e-4 u_max,
    4.0e-7 km on the fourth, the two the dual solver certifies since its line search
    interpolates (path_dual._shrink; before, they went to Clarabel); on the other three
    at most 2.6e-11, 1.4e-5 u_max and 6.0e-8 km, as before (when the test held 1e-9,
    1e-4 u_max and 1e-6 km, tighter than the certificate)."""
    rng = np.random.default_rng(3295)
    answered = 0
    for _ in range(8):
        x0, xf, geo = _far_problem(rng)
        first = cp.plan(N_MOTION, DT, U_MAX, x0, xf, 300.0, 0.0, geo, solver="clarabel")
        x1 = cp.node_positions(N_MOTION, DT, x0, first.controls[:10])[0][-1]
        warm_u = first.controls[10:]
        ref = cp.plan(
            N_MOTION, DT, U_MAX, x1, xf, 290.0, 0.0, geo, warm_controls=warm_u, solver="clarabel"
        )
        res = cp.plan(N_MOTION, DT, U_MAX, x1, xf, 290.0, 0.0, geo, warm_controls=warm_u)
        assert ref.status is SolveStatus.CONVERGED and res.status is SolveStatus.CONVERGED
        answered += res.duals is not None
        assert abs(_cost(res.controls, 0.0) - _cost(ref.controls, 0.0)) <= 1e-8 * _cost(
            ref.controls, 0.0
        )
        np.testing.assert_allclose(res.controls, ref.controls, rtol=0, atol=1e-2 * U_MAX)
        np.testing.assert_allclose(res.positions, ref.positions, rtol=0, atol=1e-5)
        states, _ = cp.node_positions(N_MOTION, DT, x1, res.controls)
        assert np.max(np.abs(states[-1] - xf)) <= 1e-9
        assert geo.semi_axes_km is not None
        assert np.all(np.sum((res.positions[1:-1] / geo.semi_axes_km) ** 2, axis=1) >= 1.0)
    assert answered >= 1


def test_a_re_solve_docking_at_the_corridors_apex_is_certified_from_the_smooth_program() -> None:
    """A warm re-solve of campaigns/safe_approach.toml's geometry (the corridor clear of the
    zone, untightened) whose plan reaches the port from the side: its first answer breaks
    the cone at the node before the port, and the program with that node's cut has its
    optimum with that node at the cone's apex and the last thrust only the one that cancels
    the port's one-step drift (3.4e-4 u_max), in the kink of ‖u‖ (docs/solvers.md, *The
    last cut*). The dual solver failed on it from the warm start and from the guess (150
    iterations each), so the program went to Clarabel (``fallbacks`` 1); started from the
    multipliers of the smooth program (ε = 1) it is certified. The plan is Clarabel's:
    cost within 1e-8 relative (Clarabel stops at ~1e-9 km of feasibility; measured
    4.5e-11), controls within 1e-6 u_max (measured 6.9e-8), positions within 1e-7 km
    (measured 7.5e-9), the corridor node in the cone within DUAL_TOL_KM and no node in the
    unsafe set."""
    axes, port, axis, deg = SAFE_APPROACH
    geo = _geometry(axes, port, axis, deg)
    xf = np.r_[port, 0.0, 0.0, 0.0]
    x_prev = np.array([0.12281, 1.951579, 7.1627, 1.463e-3, -1.0139e-2, -5.9983e-2])
    first = cp.plan(N_MOTION, DT, U_MAX, x_prev, xf, 212.0, 0.539, geo)
    assert first.fallbacks == 0
    # ten steps flown, then the estimate's update (0.4 m, 8 mm/s)
    moved = np.array([5.3943e-5, -4.02475e-4, -5.4594e-5, -1.626e-6, 6e-9, -8.099e-6])
    x1 = cp.node_positions(N_MOTION, DT, x_prev, first.controls[:10])[0][-1] + moved
    warm_u = first.controls[10:]
    res = cp.plan(
        N_MOTION, DT, U_MAX, x1, xf, 202.0, 0.643, geo, warm_controls=warm_u,
        warm_duals=cp.shift_duals(first.duals, 10),
    )  # fmt: skip
    ref = cp.plan(
        N_MOTION, DT, U_MAX, x1, xf, 202.0, 0.643, geo, warm_controls=warm_u, solver="clarabel"
    )
    assert res.status is SolveStatus.CONVERGED and ref.status is SolveStatus.CONVERGED
    assert res.fallbacks == 0 and res.slack_km == 0.0
    assert np.linalg.norm(ref.controls[-1]) < 1e-3 * U_MAX  # the drift's thrust only
    cost, ref_cost = _cost(res.controls, 0.643), _cost(ref.controls, 0.643)
    assert abs(cost - ref_cost) <= 1e-8 * ref_cost
    np.testing.assert_allclose(res.controls, ref.controls, rtol=0, atol=1e-6 * U_MAX)
    np.testing.assert_allclose(res.positions, ref.positions, rtol=0, atol=1e-7)
    corridor = np.isin(res.modes, (1, 3))
    assert corridor[-2]  # the node before the port is a corridor node
    cone = cg.corridor_cone(geo, 0.0)
    assert np.min(cone.residual_km(res.positions[corridor])) >= -cp.DUAL_TOL_KM
    assert not _unsafe(res.positions, axes, port, axis, deg).any()


def test_the_smooth_start_gives_the_programs_answer_and_counts_both_solves() -> None:
    """``solve_from_smooth`` solves the same program as ``solve``, only from other
    multipliers: with the terminal rows alone (ε = 0.3) the same controls within 1e-9
    u_max (both certified to 1e-12 km), its iterations those of both solves; a weight
    below HOMOTOPY_FROM (the fixed-ε programs, solved by the homotopy) is refused."""
    rng = np.random.default_rng(3298)
    x0 = np.r_[rng.normal(size=3) * 2.0, rng.normal(size=3) * 1e-3]
    xf = np.zeros(6)
    g = feasibility.grid_problem(N_MOTION, x0, xf, 300.0, DT, U_MAX)
    rows = _terminal_rows(g, xf)
    direct = path_dual.solve(N_MOTION, DT, U_MAX, x0, g.blocks, 0.3, 0.3, rows)
    smooth = path_dual.solve(N_MOTION, DT, U_MAX, x0, g.blocks, 1.0, 1.0, rows)
    ans = path_dual.solve_from_smooth(N_MOTION, DT, U_MAX, x0, g.blocks, 0.3, 0.3, rows)
    assert direct.converged and smooth.converged and ans.converged
    np.testing.assert_allclose(ans.controls, direct.controls, rtol=0, atol=1e-9 * U_MAX)
    assert ans.iterations > smooth.iterations
    with pytest.raises(ValueError, match="weight"):
        path_dual.solve_from_smooth(N_MOTION, DT, U_MAX, x0, g.blocks, 0.0, 1e-6, rows)


def _random_dual(rng: np.random.Generator, steps: int = 60, rows: int = 9) -> tuple:
    """A random dual of the module docstring: blocks ``a`` (N, 6, 3), rows at sorted nodes
    with vectors ``h`` and offsets ``f``, multipliers ``y`` whose steps lie on the ramp or
    beyond it (``c₁ = 0.2``, ``c₂ = 0.3``)."""
    a = rng.normal(size=(steps, 6, 3))
    nodes = np.sort(rng.integers(1, steps + 1, rows)).astype(np.int64)
    nodes[-1] = steps
    h = rng.normal(size=(rows, 6))
    f = rng.normal(size=rows)
    y = 0.1 * rng.normal(size=rows)
    return a, path_dual.block_products(a), h, f, nodes, y, 0.2, 0.3


def _evaluated(inputs: tuple, y: np.ndarray) -> dict[str, np.ndarray]:
    """``path_dual._evaluate`` at ``y``: the controls, curvature, gradient and the rows'
    curvature prefixes it writes."""
    a, aat, h, f, nodes, _, c1, c2 = inputs
    steps, count = a.shape[0], nodes.size
    out = {"u": np.empty((steps, 3)), "curv": np.empty((steps, 9))}
    out |= {"grad": np.empty(count), "q_rows": np.empty((count, 21))}
    path_dual._evaluate(a, aat, h, f, nodes, y, c1, c2, *out.values())
    return out


def test_the_forward_pass_gives_each_rows_residual() -> None:
    """The gradient of D is each row's residual ``f_i − h_iᵀ Σ_{j<k_i} A_j ũ_j`` (module
    docstring), written here with numpy from the controls ``ũ`` of the same evaluation;
    to 1e-12 of the rows' scale (sums of 60 O(1) terms in another order)."""
    rng = np.random.default_rng(91)
    for _ in range(20):
        inputs = _random_dual(rng)
        a, _, h, f, nodes, y, _, _ = inputs
        got = _evaluated(inputs, y)
        moved = np.einsum("jab,jb->ja", a, got["u"])  # A_j ũ_j
        prefix = np.vstack([np.zeros(6), np.cumsum(moved, axis=0)])  # Σ_{j<k}
        want = f - np.einsum("ia,ia->i", h, prefix[nodes])
        np.testing.assert_allclose(got["grad"], want, rtol=0, atol=1e-12 * np.max(np.abs(want)))


def test_the_rows_hessian_is_the_gradients_derivative() -> None:
    """``_hessian`` from ``_forward``'s curvature prefixes is ``−∂²D/∂y²``: the central
    difference of the gradient (step 1e-6, on problems whose steps stay on or beyond the
    ramp within it), to 1e-5 relative (the difference's error: O(δ²) plus rounding
    1e-16/1e-6)."""
    rng = np.random.default_rng(92)
    checked = 0
    for _ in range(20):
        inputs = _random_dual(rng)
        a, _, h, _, nodes, y, c1, c2 = inputs
        steps, count = a.shape[0], nodes.size
        free = np.arange(count, dtype=np.int64)
        hess = np.empty((count, count))
        path_dual._hessian(_evaluated(inputs, y)["q_rows"], h, free, count, hess)
        delta = 1e-6
        numeric = np.empty((count, count))
        for i in range(count):
            e = np.zeros(count)
            e[i] = delta
            hi = _evaluated(inputs, y + e)["grad"]
            lo = _evaluated(inputs, y - e)["grad"]
            numeric[:, i] = -(hi - lo) / (2 * delta)
        # a step whose regime changes within ±δ has no derivative there: skip the problem
        norms = np.linalg.norm(np.einsum("jab,ja->jb", a, _lam(h, nodes, y, steps)), axis=1)
        ramp = (norms - c1) / (2 * c2)  # the throttle before it is clipped to [0, 1]
        if np.any(np.abs(ramp) < 1e-3) or np.any(np.abs(ramp - 1.0) < 1e-3):
            continue
        checked += 1
        np.testing.assert_allclose(hess, numeric, rtol=0, atol=1e-5 * np.max(np.abs(hess)))
    assert checked >= 10


def _lam(h: np.ndarray, nodes: np.ndarray, y: np.ndarray, steps: int) -> np.ndarray:
    """``λ_j = Σ_{i: k_i > j} y_i h_i`` (N, 6)."""
    return np.array([np.sum(y[nodes > j, None] * h[nodes > j], axis=0) for j in range(steps)])


def test_the_law_by_products_is_the_law_to_rounding() -> None:
    """``step_law_by_products`` (one division) gives ``step_law``'s controls and returns to a
    few ulps (4e-16 relative), coasting steps exactly."""
    from cwrend_cli.physics.guidance._grid_kernels import step_law, step_law_by_products

    rng = np.random.default_rng(93)
    a = rng.normal(size=(200, 6, 3))
    for s in range(200):
        vec = rng.normal(size=6) * rng.uniform(0.01, 1.0)
        c1, c2 = 0.5, 0.2
        u1, u2 = np.zeros((200, 3)), np.zeros((200, 3))
        one = step_law(a, s, vec, c1, c2, u1)
        two = step_law_by_products(a, s, vec, c1, 1.0 / (2.0 * c2), u2)
        assert one[2] == two[2]
        np.testing.assert_allclose(two[:2] + two[3:6], one[:2] + one[3:], rtol=4e-16, atol=0)
        np.testing.assert_allclose(u2[s], u1[s], rtol=4e-16, atol=0)
        if one[1] == 0.0:
            assert two[6] == 0.0 and np.all(u2[s] == 0.0)
        else:
            assert two[6] == pytest.approx(1.0 / one[0], rel=2e-16)


@pytest.mark.parametrize(
    ("gain", "change", "factor"),
    [
        (1.0, -1.0, 0.25),  # q(t) = t − 2t²: maximum at t = 1/4
        (1.0, -0.2, 0.5 / 1.2),  # at 0.4167, inside [0.1, 0.5]
        (1.0, 0.0, 0.5),  # D did not fall (a flat trial): halving
        (1.0, -100.0, 0.1),  # far overshoot: the maximiser 1/202, held at 0.1
        (-1.0, -2.0, 0.5),  # not an ascent direction: halving
    ],
)
def test_the_line_search_backtracks_to_the_quadratics_maximiser(
    gain: float, change: float, factor: float
) -> None:
    """``_shrink``: the maximiser ``gain / (2 (gain − change))`` of the quadratic through the
    trial's start (0), slope (``gain``) and value (``change``), kept in [0.1, 0.5] (Dennis &
    Schnabel 1983, §6.3.2); halving when D did not fall or the slope is not an ascent."""
    assert path_dual._shrink(gain, change) == pytest.approx(factor, rel=1e-15)
