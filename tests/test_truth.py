"""Truth dynamics separate from the CW design model (issue 15, item 1).

References:

* Schaub & Junkins, *Analytical Mechanics of Space Systems*, 4th ed. 2018,
  ch. 14: the CW equations are the linearisation of the exact relative
  motion about a circular chief, so their error is second order in the
  separation, O(ρ²/a).
* Vallado, *Fundamentals of Astrodynamics and Applications*, 4th ed. 2013,
  ch. 8; Curtis, *Orbital Mechanics for Engineering Students*, ch. 10: the
  J2 potential Φ = −μ/r + μ J2 R²(3z²/r² − 1)/(2r³), under which the energy
  v²/2 + Φ and the polar angular momentum h_z are integrals of motion (and
  the whole h without J2).
* SciPy's DOP853 (Hairer, Nørsett & Wanner 1993) at rtol 1e-12: the
  independent reference trajectories, written here from the inertial
  equations of both spacecraft without any package code.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import solve_ivp
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.cli import app
from cwrend_cli.config import config_from_dict, overrides
from cwrend_cli.physics import truth
from cwrend_cli.physics.dynamics import stm
from cwrend_cli.physics.params import ARCHITECTURES, Scenario, Truth

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
SC = Scenario()
N = SC.mean_motion_rad_s
MU, RE, J2 = truth.MU_EARTH_KM3_S2, truth.R_EARTH_KM, truth.J2_EARTH
X0 = np.array(SC.x0)
#: An eccentric, inclined chief that exercises every term (varying ḟ, J2 out of plane).
ORBIT = {
    "eccentricity": 0.01,
    "true_anomaly_deg": 30.0,
    "inclination_deg": 51.6,
    "raan_deg": 30.0,
    "arg_latitude_deg": 40.0,
}
#: A constant control held in the chief's local-vertical frame [km/s²] (u_max = 8e-4).
U_CONST = np.array([1e-4, -2e-4, 1.5e-4])

runner = CliRunner()


# --- an independent reference: both spacecraft in the inertial frame ------------


def _gravity(r: np.ndarray, j2: float) -> np.ndarray:
    """−∇Φ of the J2 potential above, written out (Curtis ch. 10)."""
    x, y, z = r
    rn = np.linalg.norm(r)
    zr2 = (z / rn) ** 2
    k = 1.5 * j2 * MU * RE**2 / rn**5
    return -MU * r / rn**3 + k * np.array([x * (5 * zr2 - 1), y * (5 * zr2 - 1), z * (5 * zr2 - 3)])


def _frame(rc: np.ndarray, vc: np.ndarray, j2: float) -> tuple[np.ndarray, np.ndarray]:
    """Hill frame (columns radial, along-track, cross-track) and its rate in it.

    ω = (r a_h / h, 0, h / r²) with a_h the chief's perturbing acceleration
    along the angular momentum (Schaub & Junkins 2018, ch. 14).
    """
    h = np.cross(rc, vc)
    ex = rc / np.linalg.norm(rc)
    ez = h / np.linalg.norm(h)
    rot = np.column_stack([ex, np.cross(ez, ex), ez])
    a_pert = _gravity(rc, j2) + MU * rc / np.linalg.norm(rc) ** 3
    rn, hn = np.linalg.norm(rc), np.linalg.norm(h)
    return rot, np.array([rn * (a_pert @ ez) / hn, 0.0, hn / rn**2])


def _chief0(orbit: dict[str, float]) -> np.ndarray:
    """Chief r, v at t = 0 from a = (μ/n²)^{1/3} and the elements (perifocal rotation)."""
    a = (MU / N**2) ** (1 / 3)
    e = orbit["eccentricity"]
    f = np.radians(orbit["true_anomaly_deg"])
    i, raan = np.radians(orbit["inclination_deg"]), np.radians(orbit["raan_deg"])
    argp = np.radians(orbit["arg_latitude_deg"]) - f
    p = a * (1 - e * e)
    r_pf = p / (1 + e * np.cos(f)) * np.array([np.cos(f), np.sin(f), 0.0])
    v_pf = np.sqrt(MU / p) * np.array([-np.sin(f), e + np.cos(f), 0.0])

    def r3(t: float) -> np.ndarray:
        return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])

    def r1(t: float) -> np.ndarray:
        return np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])

    q = r3(raan) @ r1(i) @ r3(argp)
    return np.concatenate([q @ r_pf, q @ v_pf])


def reference(
    orbit: dict[str, float], j2: float, x0: np.ndarray, u: np.ndarray, times: np.ndarray
) -> np.ndarray:
    """Relative Hill state at ``times`` by solve_ivp (DOP853, rtol 1e-12), u fixed in Hill axes.

    Integrates the chief and the deputy-minus-chief inertial state (the
    deputy's acceleration minus the chief's, evaluated directly).
    """
    c0 = _chief0(orbit)
    rot, w = _frame(c0[:3], c0[3:], j2)
    d0 = np.concatenate([rot @ x0[:3], rot @ (x0[3:] + np.cross(w, x0[:3]))])

    def rhs(_t: float, s: np.ndarray) -> np.ndarray:
        rc, vc, dr, dv = s[:3], s[3:6], s[6:9], s[9:]
        rot_t, _ = _frame(rc, vc, j2)
        g_c = _gravity(rc, j2)
        return np.concatenate([vc, g_c, dv, _gravity(rc + dr, j2) - g_c + rot_t @ u])

    sol = solve_ivp(
        rhs, (0.0, times[-1]), np.concatenate([c0, d0]), method="DOP853",
        rtol=1e-12, atol=1e-13, t_eval=times,
    )  # fmt: skip
    assert sol.success
    out = []
    for s in sol.y.T:
        rot_t, w_t = _frame(s[:3], s[3:6], j2)
        rho = rot_t.T @ s[6:9]
        out.append(np.concatenate([rho, rot_t.T @ s[9:] - np.cross(w_t, rho)]))
    return np.array(out)


# --- tests -----------------------------------------------------------------------


def test_j2_constant_is_egm2008() -> None:
    # EGM2008: C̄20 = −4.84165143790815e-4 (fully normalised), J2 = −√5 C̄20
    assert abs(J2 / 1.0826261738522e-3 - 1.0) < 1e-12
    assert truth.semi_major_axis_km(N) == pytest.approx(7159.5, abs=0.1)  # issue 15


def test_initial_chief_matches_the_perifocal_construction() -> None:
    tr = Truth(model="j2", **ORBIT)
    np.testing.assert_allclose(truth.chief_inertial_state(tr, SC), _chief0(ORBIT), rtol=1e-13)


def test_two_body_agrees_with_cw_to_second_order() -> None:
    """Schaub & Junkins ch. 14: CW − exact = O(ρ²/a); 10× the separation, 100× the error."""
    errors = {}
    for rho in (0.01, 0.1):  # 10 m and 100 m
        x = X0 * rho / np.linalg.norm(X0[:3])
        exact = truth.propagate(Truth(model="two_body"), SC, x, np.zeros((800, 3)))
        cw = np.array([stm(N, float(k)) @ x for k in range(801)])
        errors[rho] = float(np.max(np.linalg.norm(exact[:, :3] - cw[:, :3], axis=1)))
        a = truth.semi_major_axis_km(N)
        assert errors[rho] < rho**2 / a  # measured 0.66 ρ²/a over 800 s
    assert errors[0.1] / errors[0.01] == pytest.approx(100.0, rel=1e-3)


@pytest.mark.parametrize("j2", [0.0, J2], ids=["two_body_inertial", "j2"])
def test_chief_energy_and_angular_momentum_are_conserved(j2: float) -> None:
    """Vallado ch. 8: energy and h_z (and h without J2) conserved to 1e-12 over the horizon."""
    tr = Truth(model="j2", **ORBIT)
    tm = truth.truth_model(tr, SC)._replace(j2=j2)
    chief = truth.initial_chief(tr, SC)

    def invariants(c: np.ndarray) -> tuple[float, np.ndarray]:
        r, v = c[:3], c[3:]
        rn = np.linalg.norm(r)
        phi = -MU / rn + MU * j2 * RE**2 * (3 * (r[2] / rn) ** 2 - 1) / (2 * rn**3)
        return 0.5 * v @ v + phi, np.cross(r, v)

    e0, h0 = invariants(chief)
    x = X0.copy()
    for _ in range(SC.n_steps):
        x = truth.truth_step(tm, chief, x, U_CONST)
    e1, h1 = invariants(chief)
    assert abs(e1 / e0 - 1) < 1e-12
    assert abs(h1[2] / h0[2] - 1) < 1e-12
    if j2 == 0.0:
        assert np.linalg.norm(h1 - h0) / np.linalg.norm(h0) < 1e-12


@pytest.mark.parametrize("model", ["two_body", "j2"])
@pytest.mark.parametrize("control", ["coast", "constant"])
def test_truth_matches_an_independent_dop853_integration(model: str, control: str) -> None:
    """800 s against solve_ivp (DOP853, rtol 1e-12): ≤ 1e-8 km, and ≤ 1e-10 km after one step."""
    u = U_CONST if control == "constant" else np.zeros(3)
    tr = Truth(model=model, **ORBIT)
    ours = truth.propagate(tr, SC, X0, np.tile(u, (800, 1)))
    times = np.arange(0.0, 801.0, 50.0)
    times[0] = 1.0  # the first 1 s step
    ref = reference(ORBIT, J2 if model == "j2" else 0.0, X0, u, times)
    pos_err = np.linalg.norm(ours[times.astype(int), :3] - ref[:, :3], axis=1)
    assert pos_err[0] <= 1e-10
    assert pos_err.max() <= 1e-8


def test_the_two_truths_differ_from_cw_and_from_each_other() -> None:
    x_cw = stm(N, 800.0) @ X0
    ends = {
        m: truth.propagate(Truth(model=m, **ORBIT), SC, X0, np.zeros((800, 3)))[-1]
        for m in ("two_body", "j2")
    }
    for m in ends:
        assert 1e-3 < np.linalg.norm(ends[m][:3] - x_cw[:3]) < 1.0  # metres to a kilometre
    assert np.linalg.norm(ends["j2"][:3] - ends["two_body"][:3]) > 1e-3


def test_cw_truth_is_refused_by_propagate() -> None:
    with pytest.raises(ValueError, match="two_body and j2"):
        truth.propagate(Truth(), SC, X0, np.zeros((1, 3)))


# --- the closed loop and the CLI --------------------------------------------------


def test_run_with_a_two_body_truth(tmp_path: Path) -> None:
    out = tmp_path / "run"
    result = runner.invoke(
        app,
        ["run", str(PAPER), "-a", "all", "--no-rrd", "-q", "--out", str(out),
         "--set", 'truth.model="two_body"'],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    summary = pd.read_parquet(out / "summary.parquet")
    assert len(summary) >= 4 and np.isfinite(summary["miss_km"]).all()
    config = (out / "config.json").read_text()
    assert '"two_body"' in config


def test_ablate_with_a_two_body_truth(tmp_path: Path) -> None:
    result = runner.invoke(
        app,
        ["ablate", str(PAPER), "--seeds", "2", "--workers", "1", "--no-rrd", "-q",
         "--set", f"output.dir={str(tmp_path)!r}", "--set", 'truth.model="two_body"'],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    runs = pd.read_parquet(tmp_path / "paper" / "runs.parquet")
    assert len(runs) == 8 and (runs["status"] == "ok").all()
    # a nonlinear truth under CW guidance: no run reaches the target exactly
    assert (runs["miss_km"] > 1e-5).all()


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("truth.eccentricity=1.0", "truth.eccentricity = 1: must be < 1"),
        ("truth.eccentricity=-0.1", "truth.eccentricity = -0.1: must be >= 0"),
        ("truth.inclination_deg=181.0", "truth.inclination_deg = 181: must be <= 180"),
        ('truth.model="j3"', "truth.model"),
        ("truth.wobble=1.0", "truth.wobble: unknown key"),
    ],
)
def test_bad_truth_values_exit_2_naming_the_field(
    override: str, message: str, refused_override: Callable[[str], str]
) -> None:
    assert message in refused_override(override)


def test_a_chief_below_the_surface_is_refused() -> None:
    result = runner.invoke(
        app,
        ["config", "validate", str(PAPER), "--set", 'truth.model="j2"',
         "--set", "truth.eccentricity=0.2"],
    )  # fmt: skip
    assert result.exit_code == 2
    assert "truth.eccentricity = 0.2: the chief's perigee radius" in result.stderr


def test_a_sweep_over_the_truth_model_and_a_fault_runs_each_point_as_configured(
    tmp_path: Path, mtf_sweep: Callable[..., pd.DataFrame]
) -> None:
    """Issue 15 item 5: the new fields sweep like any other; each point is its config."""
    body = (
        '[sweep]\n"truth.model" = ["cw", "j2"]\n'
        '"degradation.windows.1.dropout_probability" = [0.0, 0.5]\n'
    )
    runs = mtf_sweep(tmp_path, "mismatch", body, seeds=1)
    assert len(runs) == 4 and (runs["status"] == "ok").all()
    assert set(runs["param.truth.model"]) == {"cw", "j2"}
    for _, row in runs.iterrows():
        model = row["param.truth.model"]
        dropout = float(row["param.degradation.windows.1.dropout_probability"])
        tree = overrides.apply(
            {},
            [("truth.model", model), ("degradation.windows.1.dropout_probability", dropout)],
        )
        cfg = config_from_dict(tree, source="test")
        alone = campaign.run_case(cfg, (ARCHITECTURES["mtf_adaptive"],), int(row["seed"]))
        assert alone.runs[0].miss_km == row["miss_km"]  # bit for bit: the point is its config
    misses = runs.set_index(
        ["param.truth.model", "param.degradation.windows.1.dropout_probability"]
    )
    miss = misses["miss_km"]
    assert float(miss.loc[("cw", 0.0)]) != float(miss.loc[("j2", 0.0)])
    assert float(miss.loc[("cw", 0.0)]) != float(miss.loc[("cw", 0.5)])


@pytest.mark.parametrize(
    ("sweep", "message"),
    [
        (  # a two-body chief: the 'cw' truth refuses any eccentricity
            '"truth.eccentricity" = [0.1, 1.2]\n"truth.model" = ["two_body"]',
            "truth.eccentricity = 1.2: must be < 1",
        ),
        ('"truth.model" = ["cw", "kepler"]', "truth.model"),
    ],
)
def test_a_bad_swept_truth_value_exits_2_before_any_run(
    tmp_path: Path, sweep: str, message: str
) -> None:
    (tmp_path / "bad.toml").write_text(f"[sweep]\n{sweep}\n")
    result = runner.invoke(
        app,
        ["sweep", str(tmp_path / "bad.toml"), "--seeds", "1", "--no-rrd", "-q",
         "--set", f"output.dir={str(tmp_path)!r}"],
    )  # fmt: skip
    assert result.exit_code == 2
    assert message in result.stderr and "Traceback" not in result.output
    assert not (tmp_path / "bad").exists()  # refused before anything was written


def test_an_eccentricity_the_cw_truth_ignores_is_refused_naming_the_truth_model() -> None:
    result = runner.invoke(
        app, ["config", "validate", str(PAPER), "--set", "truth.eccentricity=0.05"]
    )
    assert result.exit_code == 2, result.output
    assert "truth.eccentricity = 0.05: the 'cw' truth (truth.model)" in result.stderr
    assert "'two_body' or 'j2'" in result.stderr
    assert "Traceback" not in result.output
