"""The single-factor baseline (issue 35, item 4): Hajiyev & Soken's scale factor, its architectures.

Hajiyev, C., Soken, H. E., "Robust adaptive Kalman filter for estimation of UAV
dynamics in the presence of sensor/actuator faults", Aerospace Science and
Technology 28 (2013) 376–383: when NIS > χ²_{1−α, m}, ``R_eff = λ R`` with
``λ = (νᵀν − tr(H P⁻ Hᵀ)) / tr(R)`` (floored at 1 by cwrend), else the plain update.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.stats import chi2
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.cli import app
from cwrend_cli.config import CwrendConfig, parse_archs
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import measurement_models as mm
from cwrend_cli.physics import sensors, simulation
from cwrend_cli.physics.estimation import (
    PLAIN,
    STF,
    STF_FALSE_ALARM,
    kf_update,
    stf_factor,
    stf_inflation,
    stf_threshold,
)
from cwrend_cli.physics.params import (
    ALL_ARCHITECTURES,
    ARCHITECTURES,
    SOCP_ARCHITECTURES,
    STF_ARCHITECTURES,
)

runner = CliRunner()
#: One ulp of a 31 km coordinate is 3.6e-15 km; (x + v) − x recovers v to ~1e-14 km.
TOL_NOISE_KM = 1e-13
#: A hand case: H P⁻ Hᵀ = R = I/2 (S = I), no cross-covariance; ν = (3, 0, 0) gives NIS = 9.
P_HAND = np.diag([0.5, 0.5, 0.5, 1.0, 1.0, 1.0])
R_HAND = 0.5 * np.eye(3)


@pytest.mark.parametrize("m", [2, 3])
def test_the_threshold_is_the_chi2_quantile(m: int) -> None:
    """The written-out χ²_{0.95, m} of the fault test, against scipy (to its rounding)."""
    assert stf_threshold(m) == pytest.approx(chi2.ppf(1.0 - STF_FALSE_ALARM, m), rel=1e-15)


def test_the_factor_is_the_hand_computation() -> None:
    """NIS = 9 > 7.81: λ = (9 − 1.5) / 1.5 = 5, R_eff = 2.5 I, ρ = (5 − 1)·1.5/3 = 2 (exact
    in binary), and the gain 0.5/(0.5 + 2.5) puts x⁺ at 3/6 = 0.5 (to the 1e-12
    regularisation of the gain, relative 1e-12)."""
    nu = np.array([3.0, 0.0, 0.0])
    r_eff, rho = stf_inflation(9.0, nu, 1.5, R_HAND)
    np.testing.assert_array_equal(r_eff, 2.5 * np.eye(3))
    assert rho == 2.0
    x_post, _, nis, rho_kf = kf_update(np.zeros(6), P_HAND, nu, R_HAND, STF)
    assert nis == pytest.approx(9.0, rel=1e-15)
    assert rho_kf == pytest.approx(2.0, rel=1e-15)
    np.testing.assert_allclose(x_post, [0.5, 0, 0, 0, 0, 0], rtol=1e-11, atol=0)


def test_below_the_threshold_the_factor_is_one() -> None:
    """ν = (2.7, 0, 0): NIS = 7.29 ≤ 7.81, no inflation, whatever νᵀν says."""
    assert stf_factor(7.29, stf_threshold(3), 7.29, 1.5, 1.5) == 1.0


def test_the_factor_is_never_below_one() -> None:
    """An anisotropic S: NIS = 9 above the threshold along the small axis, νᵀν ≪ tr(S)."""
    p = np.diag([0.5e-4, 0.5, 0.5, 1.0, 1.0, 1.0])
    r = np.diag([0.5e-4, 0.5, 0.5])
    nu = np.array([0.03, 0.0, 0.0])
    _, _, nis, rho = kf_update(np.zeros(6), p, nu, r, STF)
    assert nis > stf_threshold(3)
    assert (0.03**2 - 1.00005) / 1.00005 < 1.0  # the unfloored λ
    plain = kf_update(np.zeros(6), p, nu, r, PLAIN)
    np.testing.assert_array_equal(kf_update(np.zeros(6), p, nu, r, STF)[1], plain[1])
    assert rho == 0.0


@given(
    nis=st.floats(0.0, 1e6),
    nu_sq=st.floats(0.0, 1e3),
    hph=st.floats(1e-12, 1e3),
    r=st.floats(1e-12, 1e3),
)
def test_the_factor_is_at_least_one(nis: float, nu_sq: float, hph: float, r: float) -> None:
    assert stf_factor(nis, stf_threshold(3), nu_sq, hph, r) >= 1.0


def _case(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A predicted state 5 km out and a random positive-definite covariance."""
    gen = np.random.default_rng(seed)
    a = gen.normal(size=(6, 6)) * 1e-3
    return (
        np.array([3.0, -4.0, 1.0, 1e-3, 0.0, -2e-3]),
        a @ a.T + 1e-8 * np.eye(6),
        gen.normal(size=3),
    )


@pytest.mark.parametrize("kind", [mm.POSITION, mm.RANGE_BEARING, mm.ANGLES])
def test_below_the_threshold_stf_is_the_plain_filter(kind: int) -> None:
    """No innovation above χ²_{0.95, m}: every output of the STF update is the plain one's."""
    x, p, z = _case(1)
    m = mm.dimension(kind)
    r = np.diag([1e-6, 3e-6, 2e-6][3 - m :])
    hr = mm.jacobian(kind, x[:3])
    s = hr @ p[:3, :3] @ hr.T + r
    nu = 0.5 * np.linalg.cholesky(s) @ z[:m]  # NIS = ‖z/2‖² well below the threshold
    y = mm.measure(kind, x[:3]) + nu
    plain = mm.ekf_update(kind, x, p, y, r, PLAIN)
    assert plain[2] < stf_threshold(m)
    for got, want in zip(mm.ekf_update(kind, x, p, y, r, STF), plain, strict=True):
        np.testing.assert_array_equal(got, want)
    if kind == mm.POSITION:
        for got, want in zip(kf_update(x, p, y, r, STF), kf_update(x, p, y, r, PLAIN), strict=True):
            np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("kind", [mm.RANGE_BEARING, mm.ANGLES])
def test_above_the_threshold_the_extended_update_is_the_plain_one_with_lambda_r(kind: int) -> None:
    """An outlier (8σ along each component): STF is the plain update with R scaled by the
    λ computed here from ν, H P⁻ Hᵀ and R (relative 1e-12: a different order of sums)."""
    x, p, _ = _case(2)
    m = mm.dimension(kind)
    r = np.diag([1e-6, 3e-6, 2e-6][3 - m :])
    hr = mm.jacobian(kind, x[:3])
    hph = hr @ p[:3, :3] @ hr.T
    nu = 8.0 * np.sqrt(np.diag(hph + r))
    x_stf, p_stf, nis, rho = mm.ekf_update(kind, x, p, mm.measure(kind, x[:3]) + nu, r, STF)
    assert nis > stf_threshold(m)
    lam = (nu @ nu - np.trace(hph)) / np.trace(r)
    assert lam > 1.0
    x_ref, p_ref, _, _ = mm.ekf_update(kind, x, p, mm.measure(kind, x[:3]) + nu, lam * r, PLAIN)
    np.testing.assert_allclose(x_stf, x_ref, rtol=1e-12)
    np.testing.assert_allclose(p_stf, p_ref, rtol=1e-12, atol=1e-12 * np.abs(p_ref).max())
    assert rho == pytest.approx((lam - 1.0) * np.trace(r) / np.trace(hph + r), rel=1e-12)


# --- architectures -------------------------------------------------------------------


def test_the_paper_groups_leave_out_the_single_factor() -> None:
    assert {a.estimator for a in parse_archs("all")} == {"plain", "mtf"}
    assert parse_archs("everything") == (*ARCHITECTURES.values(), *SOCP_ARCHITECTURES.values())
    shooting = [a for a in STF_ARCHITECTURES.values() if a.method is None]
    assert parse_archs("with_stf") == (*ARCHITECTURES.values(), *shooting)
    assert parse_archs("everything_with_stf") == tuple(ALL_ARCHITECTURES.values())
    assert [a.slug for a in parse_archs("stf_adaptive_socp, mtf_adaptive")] == [
        "stf_adaptive_socp",
        "mtf_adaptive",
    ]


@pytest.mark.parametrize(
    ("name", "hint"), [("stf_adaptve", "stf_adaptive"), ("with_stff", "with_stf")]
)
def test_a_bad_architecture_exits_2_with_did_you_mean(tmp_path: Path, name: str, hint: str) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path / "results"}"\nname = "c"\n')
    result = runner.invoke(app, ["ablate", str(cfg), "--arch", name, "-w", "1", "--no-rrd"])
    assert result.exit_code == 2, result.output
    assert f"did you mean {hint!r}?" in result.stderr
    assert "Traceback" not in result.output
    assert not (tmp_path / "results").exists()


def test_the_single_factor_runs_on_the_noise_of_the_others(
    paper_cfg: CwrendConfig, paper_refs
) -> None:
    """Seed 0 of the paper scenario: y − H x_true is the seed's realisation for the STF runs
    (as for the paper's four), and the factor acts (ρ > 0 in the degradation windows)."""
    problem = problem_of(paper_cfg)
    z = campaign.standard_normal_for(paper_cfg, 0)
    expected, _ = sensors.measurement_noise(
        z, problem.scenario.time_grid()[:-1], problem.estimator.r_nominal_matrix(),
        problem.degradation.windows,
    )  # fmt: skip
    for slug in ("stf_fixed", "stf_adaptive"):
        run = simulation.simulate(problem, ALL_ARCHITECTURES[slug], z, paper_refs, 0)
        noise = run.y[1:] - run.x_true[1:, :3]
        np.testing.assert_allclose(noise, expected, rtol=0, atol=TOL_NOISE_KM, err_msg=slug)
        assert np.nanmax(run.mtf_ratio) > 0.0


def test_an_ablation_with_the_single_factor_runs_end_to_end(tmp_path: Path) -> None:
    """``--arch with_stf``: six architectures, every run ok, P(MTF beats STF) paired."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path / "results"}"\nname = "c"\n')
    result = runner.invoke(
        app, ["ablate", str(cfg), "--arch", "with_stf", "--seeds", "2", "-w", "1", "--no-rrd", "-q"]
    )
    assert result.exit_code == 0, result.output
    stats = pd.read_parquet(tmp_path / "results" / "c" / "ablation.parquet")
    marginal = stats[stats["kind"] == "marginal"]
    assert set(marginal["arch"]) == {*ARCHITECTURES, "stf_fixed", "stf_adaptive"}
    assert set(marginal["n"]) == {2}  # every run ok
    paired = stats[stats["kind"] == "paired"]
    pairs = list(dict.fromkeys(zip(paired["arch"], paired["other"], strict=True)))
    assert pairs[4:6] == [("mtf_adaptive", "stf_adaptive"), ("mtf_fixed", "stf_fixed")]
