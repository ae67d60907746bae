"""The applied Δv and the exact continuous fuel optimum (issue 33, item 3).

Beside the paper's Δv (the 1 s trapezoid of ‖u‖, ``delta_v_km_s``), the
applied impulse Σ‖u_k‖Δt of the zero-order-hold steps
(``delta_v_applied_km_s``) and its penalty against the exact continuous fuel
optimum (``fuel_penalty_applied_pct``). Reference values of the exact optimum:
"issue 33 measurement" (the issue's text: switches at 82.352 s and 741.025 s,
Δv = 0.1130615 km/s, 141.327 s of burn on the paper scenario).
"""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.physics import metrics, simulation

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
U_MAX = 8e-4  # km/s², paper Table 1
HORIZON = 800.0  # s, paper Table 1
#: issue 33 measurement, printed to 3 decimals [s] and 7 significant digits [km/s]: the
#: tolerances are half a unit in the last printed place.
SWITCHES_ISSUE_S = (82.352, 741.025)
DV_EXACT_ISSUE = 0.1130615
BURN_ISSUE_S = 141.327


# --- the applied impulse ---------------------------------------------------------------


def test_trapezoid_drops_half_the_first_and_last_held_impulse() -> None:
    """On a uniform grid, trapezoid − applied = (‖u_N‖ − ‖u₀‖) Δt / 2, exactly.

    Trapezoid: Δt (‖u₀‖/2 + ‖u₁‖ + … + ‖u_N−1‖ + ‖u_N‖/2); applied: Δt (‖u₀‖ + … +
    ‖u_N−1‖) (the last row starts no step). The norms (5, 13, 0, 3, 25) and Δt = 0.5
    are exact in binary, so every sum is exact and the identity holds with ``==``.
    With u_N = 0 (the closed loop computes no control at T) it is −‖u₀‖Δt/2: the
    0.4 m/s of a fixed-ε run (‖u₀‖ = 8e-4 km/s², Δt = 1 s; issue 33 measurement).
    """
    t = np.arange(5) * 0.5
    u = np.array([[3.0, 4.0, 0.0], [5.0, 0.0, 12.0], [0.0, 0.0, 0.0], [0.0, 3.0, 0.0],
                  [7.0, 0.0, 24.0]])  # fmt: skip
    assert metrics.applied_delta_v(t, u) == 0.5 * (5 + 13 + 0 + 3)
    assert metrics.delta_v(t, u) - metrics.applied_delta_v(t, u) == (25 - 5) * 0.5 / 2
    u[-1] = 0.0
    assert metrics.delta_v(t, u) - metrics.applied_delta_v(t, u) == -5 * 0.5 / 2


def test_applied_delta_v_weights_each_held_step_by_its_own_length() -> None:
    """On a non-uniform grid the applied impulse is Σ‖u_k‖(t_k+1 − t_k), not ‖u‖ × mean Δt."""
    t = np.array([0.0, 1.0, 1.25, 3.25])
    u = np.array([[0.0, 0.0, 2.0], [4.0, 0.0, 0.0], [0.0, 1.0, 0.0], [9.0, 9.0, 9.0]])
    assert metrics.applied_delta_v(t, u) == 2.0 * 1.0 + 4.0 * 0.25 + 1.0 * 2.0


# --- the exact continuous fuel optimum -------------------------------------------------


def test_exact_fuel_optimum_matches_the_issue_measurement(paper_refs) -> None:
    """Burns [0, 82.352 s] and [741.025 s, 800 s], Δv 0.1130615 km/s (issue 33 measurement).

    Tolerances: half a unit of the printed last place (5e-4 s, 5e-8 km/s). The
    fuel reference's continuous Δv is this plan's, u_max × burn time; its 1 s
    trapezoid is 141 u_max (test_references), 0.327 u_max s below it.
    """
    plan = paper_refs.fuel.exact
    assert plan is not None
    np.testing.assert_allclose(plan.switching_times_s, SWITCHES_ISSUE_S, rtol=0, atol=5e-4)
    np.testing.assert_allclose(plan.burns_s[:, [0]].ravel(), [0.0, SWITCHES_ISSUE_S[1]], atol=5e-4)
    assert plan.burns_s[0, 0] == 0.0 and plan.burns_s[-1, 1] == HORIZON
    assert plan.delta_v_km_s == pytest.approx(DV_EXACT_ISSUE, abs=5e-8)
    burn = float(np.sum(plan.burns_s[:, 1] - plan.burns_s[:, 0]))
    assert burn == pytest.approx(BURN_ISSUE_S, abs=5e-4)
    assert plan.delta_v_km_s == pytest.approx(U_MAX * burn, rel=1e-15)
    assert paper_refs.fuel.delta_v_continuous_km_s == plan.delta_v_km_s
    assert paper_refs.fuel.delta_v_km_s < plan.delta_v_km_s  # the trapezoid is below the optimum


def test_exact_fuel_optimum_is_solved_to_rounding(paper_refs, paper_cfg) -> None:
    """The switching-time system holds to rounding, not to the solver's tolerances.

    Its terminal miss is below 1e-12 km and 1e-15 km/s (1000× below the shooting
    tolerances 1e-9 km and 1e-12 km/s; measured 6e-15 km and 6e-18 km/s on a 31 km
    state), ‖λ_v(t_k)‖ = 1 to 1e-13, and more quadrature nodes (16, 24 instead of 12)
    move no switching time by more than 1e-10 s (measured: 4e-14 s).
    """
    from cwrend_cli.physics import guidance
    from cwrend_cli.physics.guidance.fuel_optimum import exact_bang_bang

    plan = paper_refs.fuel.exact
    assert plan.miss_km < 1e-12 and plan.miss_km_s < 1e-15
    assert plan.switch_residual < 1e-13
    n = paper_cfg.scenario.mean_motion_rad_s
    problem = guidance.ShootingProblem(
        np.array(paper_cfg.scenario.x0), HORIZON, 0.0, n, U_MAX, np.zeros(6)
    )
    for nodes in (16, 24):
        finer = exact_bang_bang(
            problem, paper_refs.fuel.costate, guidance.SolverSettings(quadrature_nodes=nodes)
        )
        np.testing.assert_allclose(finer.switching_times_s, plan.switching_times_s, atol=1e-10)


def test_exact_fuel_optimum_solves_its_own_boundary_conditions(
    paper_refs, paper_cfg, cw_matrices
) -> None:
    """Flying the plan's bang-bang control reaches x_f, and ‖λ_v‖ = 1 at its switches.

    Independent of the package's kernels: λ_v(t) from ``expm(−Aᵀt)`` of paper Eq. 4's
    A (written out in the test), u = −u_max λ_v/‖λ_v‖ on the burns and 0 between,
    integrated by DOP853 (rtol 3e-14) arc by arc between the switching times. That
    integration is accurate to ~1e-11 km on the 31 km state (test_references);
    1e-9 km and 1e-12 km/s (the shooting tolerances) leave ×100 margin. ‖λ_v(t_k)‖ = 1
    to 1e-12 (the expm's rounding over 800 s).
    """
    n = paper_cfg.scenario.mean_motion_rad_s
    a, b = cw_matrices(n)
    plan = paper_refs.fuel.exact
    lam0 = plan.costate

    def lam_v(t: float) -> np.ndarray:
        return (scipy.linalg.expm(-a.T * t) @ lam0)[3:]

    for t_k in plan.switching_times_s:
        assert np.linalg.norm(lam_v(t_k)) == pytest.approx(1.0, abs=1e-12)

    def rhs(t: float, x: np.ndarray, burning: bool) -> np.ndarray:
        lv = lam_v(t)
        u = -U_MAX * lv / np.linalg.norm(lv) if burning else np.zeros(3)
        return np.asarray(a @ x + b @ u)

    x = np.array(paper_cfg.scenario.x0, dtype=float)
    for lo, hi in pairwise([0.0, *plan.switching_times_s, HORIZON]):
        mid = (lo + hi) / 2
        inside = bool(np.any((plan.burns_s[:, 0] <= mid) & (mid <= plan.burns_s[:, 1])))
        assert inside == (np.linalg.norm(lam_v(mid)) > 1.0)  # burns where ‖λ_v‖ > 1 only
        sol = solve_ivp(rhs, (lo, hi), x, method="DOP853", rtol=3e-14, atol=1e-16, args=(inside,))
        x = sol.y[:, -1]
    assert np.linalg.norm(x[:3]) < 1e-9
    assert np.linalg.norm(x[3:]) < 1e-12


# --- the runs -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ablation(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small paper ablation: 2 seeds, the 8 architectures (the cone-program ones end
    closest to the fuel optimum)."""
    root = tmp_path_factory.mktemp("applied")
    out_dir = f"output.dir={json.dumps(str(root))}"
    result = CliRunner().invoke(
        app,
        ["ablate", str(PAPER), "--seeds", "2", "--arch", "everything", "--workers", "1",
         "--no-rrd", "-q", "--set", out_dir],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    return root / "paper"


def test_applied_delta_v_is_the_sum_of_the_held_steps_of_the_steps_file(ablation: Path) -> None:
    """``delta_v_applied_km_s`` = Σ_k<N ‖u_k‖(t_k+1 − t_k) of the run's ``steps/`` rows.

    The steps' ``u*_km_s2`` are the applied (actuated) control held over [t_k, t_k+1).
    Tolerance 1e-12 relative: the same floats summed in another order (800 terms,
    rounding ≤ 800 ε ≈ 2e-13).
    """
    runs = pd.read_parquet(ablation / "runs.parquet").set_index("run_key")
    steps = pd.read_parquet(ablation / "steps")
    assert len(runs) == 16
    for key, g in steps.groupby("run_key", observed=True):
        g = g.sort_values("step")
        u = g[["ux_km_s2", "uy_km_s2", "uz_km_s2"]].to_numpy()
        dt = np.diff(g["t_s"].to_numpy())
        expected = float(np.sum(np.linalg.norm(u[:-1], axis=1) * dt))
        assert runs.loc[key, "delta_v_applied_km_s"] == pytest.approx(expected, rel=1e-12)
        # and the paper's trapezoid is below it by ‖u₀‖Δt/2 exactly (u_N = 0)
        assert np.linalg.norm(u[-1]) == 0.0
        assert runs.loc[key, "delta_v_km_s"] - expected == pytest.approx(
            -np.linalg.norm(u[0]) * dt[0] / 2, abs=1e-15
        )


def test_applied_fuel_penalty_is_not_negative_in_a_small_paper_ablation(
    ablation: Path, paper_refs, paper_cfg, cw_matrices
) -> None:
    """Every run's applied penalty is ≥ 0 up to what its terminal error allows.

    Weak duality (the bound the solver's dual is built on, _kernels' docstring): for
    any control with ‖u‖ ≤ u_max driving CW from x₀ to x_T, and the optimal costate
    λ₀* of the target x_f, ∫‖u‖dt ≥ Δv* − λ₀*ᵀ Φ(−T)(x_T − x_f), with equality for the
    optimum (pointwise: ‖u‖ ≥ −λ_vᵀu − u_max(‖λ_v‖ − 1)₊). A closed-loop run holds
    each u_k over its step, so ∫‖u‖dt is its applied Δv; the truth is CW (paper
    scenario). Runs end 0.2–40 m from the target, so the bound allows a penalty
    slightly below 0 in principle; tolerance 1e-9 relative besides (rounding, and the
    cone program's plans meeting ‖u‖ ≤ u_max to its solver's tolerance). Measured:
    every run's penalty is also plainly ≥ 0 (lowest +0.009 %, mtf_fixed_socp).
    """
    runs = pd.read_parquet(ablation / "runs.parquet").set_index("run_key")
    steps = pd.read_parquet(ablation / "steps")
    exact = paper_refs.fuel.exact
    a, _ = cw_matrices(paper_cfg.scenario.mean_motion_rad_s)
    phi_back = scipy.linalg.expm(a * -HORIZON)
    for key, g in steps.groupby("run_key", observed=True):
        last = g.sort_values("step").iloc[-1]
        x_t = last[["x_km", "y_km", "z_km", "vx_km_s", "vy_km_s", "vz_km_s"]].to_numpy(float)
        bound = exact.delta_v_km_s - float(exact.costate @ phi_back @ x_t)  # x_f = 0
        applied = runs.loc[key, "delta_v_applied_km_s"]
        assert runs.loc[key, "status"] == "ok"
        assert applied >= bound * (1 - 1e-9), key
        assert runs.loc[key, "fuel_penalty_applied_pct"] >= 0.0, key
        assert runs.loc[key, "fuel_penalty_applied_pct"] == pytest.approx(
            100.0 * (applied / exact.delta_v_km_s - 1.0), rel=1e-12
        )


def test_the_references_applied_rows(paper_refs: simulation.References) -> None:
    """The fuel reference's applied penalty is 0; the energy plan's ∫‖u‖dt is its trapezoid's
    limit (the 1 s trapezoid of a smooth ‖u‖ is O(Δt²) off: within 1e-6 relative)."""
    fuel = metrics.reference_metrics(paper_refs.fuel, paper_refs.fuel)
    assert fuel.fuel_penalty_applied_pct == 0.0
    energy = metrics.reference_metrics(paper_refs.energy, paper_refs.fuel)
    assert energy.delta_v_applied_km_s == pytest.approx(paper_refs.energy.delta_v_km_s, rel=1e-6)
    assert energy.fuel_penalty_applied_pct > 0.0


def test_applied_statistics_have_their_own_stream_and_change_no_paper_row() -> None:
    """``statistics.applied`` adds mean/median/p95 rows of the two applied metrics; the
    rows of ``describe`` (the paper's metrics) are the same with or without them."""
    from cwrend_cli.campaign import statistics

    rng = np.random.default_rng(7)
    runs = pd.DataFrame(
        {"arch": ["a", "b"] * 6, "seed": np.repeat(np.arange(6), 2), "status": "ok",
         "delta_v_km_s": 0.14 + 1e-3 * rng.standard_normal(12),
         "miss_km": 1e-3 * rng.random(12), "fuel_penalty_pct": rng.standard_normal(12),
         "solve_success_pct": 100.0, "solve_mean_ms": 1.0, "solve_max_ms": 2.0,
         "n_infeasible": 0}
    )  # fmt: skip
    before = statistics.describe(runs, ["arch"], seed=3)
    assert statistics.applied(runs, ["arch"], seed=3).empty  # a campaign written before
    runs["delta_v_applied_km_s"] = runs["delta_v_km_s"] + 4e-4
    runs["fuel_penalty_applied_pct"] = runs["fuel_penalty_pct"] + 0.1
    pd.testing.assert_frame_equal(statistics.describe(runs, ["arch"], seed=3), before)
    rows = statistics.applied(runs, ["arch"], seed=3)
    assert set(rows["metric"]) == set(statistics.APPLIED_METRICS)
    mean = rows.query("arch == 'a' and metric == 'delta_v_applied_km_s' and statistic == 'mean'")
    expected = runs.loc[runs["arch"] == "a", "delta_v_applied_km_s"].mean()
    assert mean["value"].iloc[0] == pytest.approx(expected, rel=1e-15)
    assert mean["ci_low"].iloc[0] <= expected <= mean["ci_high"].iloc[0]


def test_a_costate_that_is_no_plan_is_refused(paper_cfg) -> None:
    """λ₀ = 0 has no burn: the switching-time system is singular, ExactPlanError (the fuel
    reference then has a NaN continuous Δv instead of a wrong one)."""
    from cwrend_cli.physics import guidance
    from cwrend_cli.physics.guidance.fuel_optimum import ExactPlanError, exact_bang_bang

    sc = paper_cfg.scenario
    problem = guidance.ShootingProblem(
        np.array(sc.x0), HORIZON, 0.0, sc.mean_motion_rad_s, U_MAX, np.zeros(6)
    )
    with pytest.raises(ExactPlanError):
        exact_bang_bang(problem, np.zeros(6))


# --- which Δv the report's figures plot --------------------------------------------------

#: The report's figures that plot a Δv (paper Figs 2 and 6, the distribution, sweep, design
#: and sensitivity figures): each plots the paper's trapezoid, and says so in its caption.
DV_FIGURES = (
    "fig2_control.png",
    "fig6_dv_vs_miss.png",
    "dv_distribution.png",
    "sweep_{key}.png",
    "design_{key}.png",
    "sensitivity.png",
)


def test_every_figure_that_plots_delta_v_says_which_in_its_caption() -> None:
    from cwrend_cli.report.figures import FIGURES

    captions = {entry.file: entry.caption for entry in FIGURES}
    for file in DV_FIGURES:
        assert "trapezoid" in captions[file], file


def test_fig6_names_the_trapezoid_and_gives_the_exact_fuel_optimum_beside_it(
    ablation: Path,
) -> None:
    """The x axis is the paper's trapezoid; the fuel-optimal line's legend also gives the
    exact continuous optimum (``delta_v_applied_km_s`` of the reference, 0.1130615 km/s)."""
    from cwrend_cli.report import figures
    from cwrend_cli.report.load import load_results

    data = load_results(ablation)
    ax = figures.fig_dv_vs_miss(data).axes[0]
    assert "trapezoid" in ax.get_xlabel()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    fuel = [t for t in labels if "fuel" in t.lower()]
    assert len(fuel) == 1 and "exact 0.1131" in fuel[0] and "0.1128" in fuel[0], labels


def test_fig2_names_the_trapezoid_on_its_cumulative_axis(ablation: Path) -> None:
    from cwrend_cli.report import figures
    from cwrend_cli.report.load import load_results

    fig = figures.fig_control(load_results(ablation))
    assert any("trapezoid" in ax.get_ylabel() for ax in fig.axes)
