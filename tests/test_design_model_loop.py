"""The design models in the closed loop (issue 33 item 1): the cone program and the filter.

The cone-program re-solve takes any model's Φ_k, Γ_k: its plan, flown through the
same model step by step (written here), reaches x_f. The filter predicts with its
model's Φ_k, Γ_k at each step (time-varying for 'ya'). The shooting re-solve supports
CW and 'ss' (tests/test_ss_shooting.py): 'ya' with a shooting architecture, and any
model but CW with the constrained cone program, are refused before anything runs
(exit 2, the field named).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign.worker import run_case
from cwrend_cli.cli import app
from cwrend_cli.config.io import config_from_dict
from cwrend_cli.physics import design_models as dm
from cwrend_cli.physics import simulation
from cwrend_cli.physics.dynamics import discretize
from cwrend_cli.physics.guidance import convex, feasibility
from cwrend_cli.physics.params import (
    ALL_ARCHITECTURES,
    DesignModel,
    DesignModelName,
    Problem,
    Scenario,
    Truth,
)

REPO = Path(__file__).resolve().parents[1]
SC = Scenario()
N = SC.mean_motion_rad_s
X0 = np.asarray(SC.x0, dtype=float)
XF = np.asarray(SC.xf, dtype=float)
J2_TRUTH = Truth(model="j2", inclination_deg=51.6)
ECCENTRIC = Truth(model="two_body", eccentricity=0.05, true_anomaly_deg=30.0)
runner = CliRunner()


def test_the_step_transcription_of_cw_is_cws_grid() -> None:
    """grid_problem_from_steps on CW's steps: the blocks and b of grid_problem (to 1e-12)."""
    phi, gam = discretize(N, SC.dt_s)
    steps = 300
    g = feasibility.grid_problem_from_steps(
        np.repeat(phi[None], steps, 0), np.repeat(gam[None], steps, 0), X0, XF, 1.0, 8e-4
    )
    ref = feasibility.grid_problem(N, X0, XF, steps * 1.0, 1.0, 8e-4)
    assert np.abs(g.blocks - ref.blocks).max() < 1e-12 * np.abs(ref.blocks).max()
    assert np.abs(g.rhs - ref.rhs).max() < 1e-12 * np.abs(ref.rhs).max()
    assert np.array_equal(g.row_scale, ref.row_scale)
    lam = np.array([1e-3, -2e-3, 5e-4, 0.3, -0.1, 0.2])
    z = feasibility.multiplier_from_costate(g, N, lam)
    assert np.allclose(feasibility.costate_from_multiplier(g, N, z), lam, rtol=1e-12, atol=0)


@pytest.mark.parametrize(("name", "tr"), [("ss", J2_TRUTH), ("ya", ECCENTRIC)])
def test_the_cone_programs_plan_reaches_xf_in_its_own_model(
    name: DesignModelName, tr: Truth
) -> None:
    """The plan of the last 700 steps, flown by x⁺ = Φ_k x + Γ_k u_k of the model, ends at x_f."""
    tables = dm.step_tables(name, SC, tr)
    k0 = SC.n_steps - 700
    g = feasibility.grid_problem_from_steps(
        tables.phi[k0:], tables.gam[k0:], X0, XF, SC.dt_s, SC.u_max_km_s2
    )
    result = convex.solve(g, 0.5, N)
    assert result.controls is not None
    x = X0.copy()
    for k in range(700):
        x = tables.phi[k0 + k] @ x + tables.gam[k0 + k] @ result.controls[k]
    assert np.linalg.norm(x[:3] - XF[:3]) < 1e-6  # km; CW's plan in this model misses by more
    cw = convex.solve(feasibility.grid_problem(N, X0, XF, 700.0, 1.0, SC.u_max_km_s2), 0.5, N)
    assert cw.controls is not None
    x = X0.copy()
    for k in range(700):
        x = tables.phi[k0 + k] @ x + tables.gam[k0 + k] @ cw.controls[k]
    assert np.linalg.norm(x[:3] - XF[:3]) > 1e-4


@pytest.mark.parametrize(("name", "tr"), [("ss", J2_TRUTH), ("ya", ECCENTRIC)])
def test_the_filter_predicts_with_its_model(name: DesignModelName, tr: Truth) -> None:
    """model.filter: the loop's Φ_k, Γ_k are the model's steps; 'cw': Eq. 11 at every step."""
    problem = Problem(truth=tr, model=DesignModel(filter=name))
    cw_phi, cw_gam = discretize(N, SC.dt_s)
    phi, gam = simulation._filter_tables(problem)
    tables = dm.step_tables(name, SC, tr)
    assert phi.shape == (SC.n_steps, 6, 6) and gam.shape == (SC.n_steps, 6, 3)
    assert np.array_equal(phi, tables.phi) and np.array_equal(gam, tables.gam)
    assert phi.flags.writeable and phi.flags.c_contiguous
    phi, gam = simulation._filter_tables(Problem(truth=tr))
    assert all(np.array_equal(p, cw_phi) for p in phi)
    assert all(np.array_equal(g, cw_gam) for g in gam)


def test_a_ya_filter_is_consistent_where_cw_is_not() -> None:
    """e = 0.05 two-body truth, 'ya' guidance, plain_fixed_socp, seed 0: mean NEES over t > 0.

    Measured: 61,424 with the CW filter (the eccentric chief's motion
    unmodelled), 2,021 with 'ya' (what is left: the truth's nonlinearity at
    31 km and the paper's small Q); miss 6.5 m and 1.3 m.
    """
    nees = {}
    for name in ("cw", "ya"):
        cfg = config_from_dict(
            {
                "truth": {"model": "two_body", "eccentricity": 0.05, "true_anomaly_deg": 30.0},
                "model": {"guidance": "ya", "filter": name},
            }
        )
        (run,) = run_case(cfg, [ALL_ARCHITECTURES["plain_fixed_socp"]], 0).runs
        nees[name] = float(np.nanmean(run.nees[1:]))
    assert nees["ya"] < nees["cw"] / 20, nees


def test_ya_tables_are_the_transition_of_each_step() -> None:
    tables = dm.step_tables("ya", SC, ECCENTRIC)
    chief = dm.ya_chief(ECCENTRIC, SC)
    assert chief.e == 0.05 and chief.f0 == pytest.approx(math.radians(30.0))
    assert not tables.time_invariant
    assert np.array_equal(tables.phi[417], dm.ya_stm(chief, 417.0, 418.0))
    assert np.array_equal(tables.gam[417], dm.ya_input_matrix(chief, 417.0, 418.0))


def _own_steps_grid(
    phi: np.ndarray, gam: np.ndarray, k0: int, x0: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A re-solve from step k0 condensed from its own steps alone (blocks, b, Φ(t_N, t_k0)).

    What every re-solve did before the condensation onto t_N was shared:
    ``M_j = Φ_{N−1} ⋯ Φ_{j+1} Γ_j``, the product grown on the right from t_N back to t_k0.
    """
    steps = phi.shape[0]
    blocks = np.empty((steps - k0, 6, 3))
    acc = np.eye(6)
    for j in range(steps - 1, k0 - 1, -1):
        blocks[j - k0] = acc @ gam[j]
        acc = acc @ phi[j]
    return blocks, XF - acc @ x0, acc


@pytest.mark.parametrize(("name", "tr"), [("ss", J2_TRUTH), ("ya", ECCENTRIC)])
def test_a_resolve_slices_the_shared_condensation_bit_for_bit(
    name: DesignModelName, tr: Truth
) -> None:
    """Each re-solve's grid (simulation._grid) equals its own steps' condensation exactly.

    Exact, not to a tolerance: the shared condensation forms the same products
    in the same order (from t_N backwards, growing on the right), so its row j
    and its Φ(t_N, t_k0) do not depend on where the grid starts. Horizons: the
    whole, a remainder that rounds to 537 steps, and the last step.
    """
    problem = Problem(truth=tr, model=DesignModel(guidance=name))
    condensed = simulation._guidance_condensed(problem)
    assert condensed is not None
    assert simulation._guidance_condensed(Problem(truth=tr)) is None  # CW: Eq. 11's powers
    tables = dm.step_tables(name, SC, tr)
    x_hat = X0 + np.array([1e-3, -2e-3, 5e-4, 1e-6, -2e-6, 3e-6])
    for horizon_s, steps in ((SC.horizon_s, SC.n_steps), (537.0000001, 537), (1.0, 1)):
        g = simulation._grid(SC, x_hat, horizon_s, condensed)
        blocks, rhs, transition = _own_steps_grid(tables.phi, tables.gam, SC.n_steps - steps, x_hat)
        assert g.blocks.shape == (steps, 6, 3)
        assert np.array_equal(g.blocks, blocks)
        assert np.array_equal(g.rhs, rhs)
        assert g.transition is not None and np.array_equal(g.transition, transition)
        ref = feasibility.grid_problem_from_steps(
            tables.phi[-steps:], tables.gam[-steps:], x_hat, XF, SC.dt_s, SC.u_max_km_s2
        )
        assert np.array_equal(g.row_scale, ref.row_scale)
        assert np.array_equal(g.blocks, ref.blocks) and np.array_equal(g.rhs, ref.rhs)


#: Combinations not flown yet: (campaign, architectures, --set, what the refusal says).
_REFUSED = {
    # the shooting kernels need the transition in closed form at any time: not 'ya' (issue 33)
    "shooting": (
        "paper_j2.toml",
        "mtf_adaptive_socp,plain_fixed",
        ["model.guidance='ya'"],
        "model.guidance = 'ya' with architecture plain_fixed",
    ),
    # the constrained cone program plans with CW: it must not silently fly 'ss' as CW
    "constrained cone program": (
        "safe_approach.toml",
        "mtf_adaptive_socp",
        ["truth.model='j2'", "model.guidance='ss'"],
        "model.guidance = 'ss' with [constraints] and architecture mtf_adaptive_socp",
    ),
}


@pytest.mark.parametrize("command", ["run", "ablate"])
@pytest.mark.parametrize("case", list(_REFUSED))
def test_a_guidance_that_plans_with_cw_refuses_another_guidance_model(
    case: str, command: str, tmp_path: Path
) -> None:
    config, archs, extra, message = _REFUSED[case]
    sets = [*extra, f"output.dir='{tmp_path}'"]
    args = [command, str(REPO / "campaigns" / config), "--arch", archs]
    result = runner.invoke(app, [*args, *(a for s in sets for a in ("--set", s))])
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert "Traceback" not in result.output
    assert not any(tmp_path.iterdir())


#: The end-to-end commands of issue 33's "Done when": (campaign, --arch, --set).
_END_TO_END = {
    "ss shooting": ("paper_j2.toml", "all", ["model.guidance='ss'", "model.filter='ss'"]),
    "ss cone program": ("paper_j2.toml", "all_socp", ["model.guidance='ss'", "model.filter='ss'"]),
    "ya cone program, eccentric chief": (
        "paper.toml",
        "all_socp",
        [
            "truth.model='two_body'",
            "truth.eccentricity=0.05",
            "model.guidance='ya'",
            "model.filter='ya'",
        ],
    ),
}


@pytest.mark.parametrize("case", list(_END_TO_END))
def test_the_design_model_ablations_run_end_to_end(case: str, tmp_path: Path) -> None:
    """`cwrend ablate` with each design model, one seed: exit 0, every run ok, on target.

    On target: the miss below 100 m (seed 0, measured: 5.0–30.1 m with ss shooting, the
    largest MTF-fixed's, whose fixed ε flies the paper's sample hold of campaigns/
    paper_j2.toml: 22.8 m on average with CW under J2, docs/results/mismatch.md; below
    20 m on the cone program), and the campaign's configuration holds the models it was
    asked for.
    """
    import json

    import pandas as pd

    config, archs, extra = _END_TO_END[case]
    sets = [*extra, f"output.dir='{tmp_path}'", "output.name='e2e'"]
    args = ["ablate", str(REPO / "campaigns" / config), "--arch", archs, "--seeds", "1"]
    args += ["--workers", "1", "--no-rrd", "-q"]
    result = runner.invoke(app, [*args, *(a for s in sets for a in ("--set", s))])
    assert result.exit_code == 0, result.output
    runs = pd.read_parquet(tmp_path / "e2e" / "runs.parquet")
    assert len(runs) == 4 and (runs["status"] == "ok").all(), runs[["arch", "status", "error"]]
    assert (runs["miss_km"] < 0.100).all(), runs[["arch", "miss_km"]]
    model = json.loads((tmp_path / "e2e" / "manifest.json").read_text())["config"]["model"]
    name = extra[-1].split("=")[1].strip("'")
    assert model == {"guidance": name, "filter": name}, model
