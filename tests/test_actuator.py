"""Actuator errors and their random streams (issue 15, items 2 and 4).

References:

* The model and its conventions: :class:`cwrend_cli.physics.params.Actuator`
  (scale error, per-step magnitude noise, misalignment R = R_z(γ) R_y(β) R_x(α)
  as in Diebel 2006, "Representing attitude", per-step pointing noise ⟂ to
  the thrust, minimum thrust, delay, clipping at u_max (1 + bias)).
* Statistical tests: if z_1 … z_N are independent N(0, 1), Σ z_k² ~ χ²(N)
  (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking
  and Navigation*, 2001, §1.4.17); a pointing error with two independent
  N(0, σ²) tilt components has θ²/σ² ~ χ²(2). Each test accepts the sum
  between the χ² quantiles 0.5e-6 and 1 − 0.5e-6: a false-alarm rate of 1e-6
  (two-sided), with the draws of a fixed stream (so the outcome is fixed too).
* The filter predicts with the commanded control (issue 15: it does not know
  the actuator errors): paper Eq. 11, x⁻ = Φ x⁺ + Γ u.
* Random streams: NumPy ``SeedSequence`` spawn keys, ``(seed, 0)`` the
  measurement noise, ``(seed, 1)`` the dispersions, ``(seed, 2)`` the
  actuator (children 0: magnitude, 1: pointing).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.campaign import worker
from cwrend_cli.cli import app
from cwrend_cli.config import CwrendConfig, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import actuator, simulation
from cwrend_cli.physics.dynamics import discretize
from cwrend_cli.physics.estimation import PLAIN, kf_predict, kf_update
from cwrend_cli.physics.metrics import delta_v
from cwrend_cli.physics.params import ARCHITECTURES, Actuator, Problem

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
U_MAX = Problem().scenario.u_max_km_s2
#: Two-sided false-alarm rate of every statistical test here.
FALSE_ALARM = 1e-6
#: Steps of the statistical tests (calls of the compiled actuator).
N_STAT = 20_000
runner = CliRunner()


def _model(act: Actuator, n: int, seed: int = 7) -> actuator.ActuatorModel:
    """The loop's actuator with the worker's draws of realisation ``seed`` (root seed 0)."""
    draws = actuator.draw(worker.actuator_seed_sequence(0, seed), n)
    return actuator.actuator_model(act, U_MAX, n, draws)


def _applied(am: actuator.ActuatorModel, commands: np.ndarray) -> np.ndarray:
    """The applied control of each step k for ``commands[k]`` (no delay here)."""
    out = np.empty_like(commands)
    for k in range(commands.shape[0]):
        actuator.actuate(am, k, commands[k], out[k])
    return out


def _chi2_bounds(dof: int) -> tuple[float, float]:
    return float(chi2.ppf(FALSE_ALARM / 2, dof)), float(chi2.ppf(1 - FALSE_ALARM / 2, dof))


def _rz(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _run(
    act: Actuator,
    refs: simulation.References,
    slug: str = "mtf_adaptive",
    seed: int = 0,
    draws: actuator.ActuatorDraws | None = None,
) -> simulation.RunResult:
    """One closed-loop run of the paper scenario with actuator ``act`` (worker's draws)."""
    problem = dataclasses.replace(Problem(), actuator=act)
    noise = campaign.standard_normal_for(CwrendConfig(), seed)
    if draws is None:
        draws = worker.actuator_draws(problem, 0, seed)
    return simulation.simulate(problem, ARCHITECTURES[slug], noise, refs, seed, draws)


# --- the actuator model -----------------------------------------------------------


def test_magnitude_noise_matches_its_sigma() -> None:
    sigma, bias = 0.01, 0.02
    am = _model(Actuator(magnitude_bias=bias, magnitude_sigma=sigma), N_STAT)
    command = np.tile([0.5 * U_MAX, 0.0, 0.0], (N_STAT, 1))  # far from the clip
    ratio = np.linalg.norm(_applied(am, command), axis=1) / (0.5 * U_MAX)
    z = (ratio - (1.0 + bias)) / sigma
    low, high = _chi2_bounds(N_STAT)
    assert low < float(np.sum(z**2)) < high


def test_pointing_noise_matches_its_sigma() -> None:
    sigma_deg = 1.0
    am = _model(Actuator(pointing_sigma_deg=sigma_deg), N_STAT)
    direction = np.array([0.3, -0.5, 0.8]) / math.sqrt(0.98)
    command = np.tile(0.7 * U_MAX * direction, (N_STAT, 1))
    applied = _applied(am, command)
    # the pointing error only turns the thrust: its magnitude is the command's
    np.testing.assert_allclose(np.linalg.norm(applied, axis=1), 0.7 * U_MAX, rtol=1e-14)
    cos = np.clip(applied @ direction / (0.7 * U_MAX), -1.0, 1.0)
    theta = np.arctan2(np.linalg.norm(np.cross(applied, direction), axis=1), cos * 0.7 * U_MAX)
    low, high = _chi2_bounds(2 * N_STAT)
    assert low < float(np.sum((theta / math.radians(sigma_deg)) ** 2)) < high


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_misalignment_rotates_the_thrust_by_the_configured_angle(axis: int) -> None:
    angles = [0.0, 0.0, 0.0]
    angles[axis] = 3.0
    am = _model(Actuator(misalignment_deg=(angles[0], angles[1], angles[2])), 1)
    command = np.zeros(3)
    command[(axis + 1) % 3] = 0.4 * U_MAX  # perpendicular to the rotation axis
    out = np.empty(3)
    actuator.actuate(am, 0, command, out)
    angle = math.degrees(math.acos(out @ command / (0.4 * U_MAX) ** 2))
    assert angle == pytest.approx(3.0, abs=1e-9)
    # right-handed: the axis, the command and the applied thrust
    assert np.cross(command, out)[axis] > 0


def test_misalignment_sequence_is_z_y_x() -> None:
    a, b, g = 2.0, -3.0, 5.0
    ca, sa = math.cos(math.radians(a)), math.sin(math.radians(a))
    cb, sb = math.cos(math.radians(b)), math.sin(math.radians(b))
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    np.testing.assert_allclose(
        actuator.misalignment_matrix((a, b, g)), _rz(g) @ ry @ rx, rtol=0, atol=1e-15
    )


def test_minimum_thrust_zeroes_small_commands() -> None:
    am = _model(Actuator(min_thrust_km_s2=1e-4), 1)
    out = np.empty(3)
    actuator.actuate(am, 0, np.array([0.0, 0.99e-4, 0.0]), out)
    assert np.array_equal(out, np.zeros(3))
    big = np.array([0.0, 1.01e-4, 0.0])
    actuator.actuate(am, 0, big, out)
    np.testing.assert_allclose(out, big, rtol=1e-15)


@pytest.mark.parametrize("bias", [0.05, -0.05])
def test_applied_magnitude_never_exceeds_u_max_times_one_plus_bias(bias: float) -> None:
    am = _model(Actuator(magnitude_bias=bias, magnitude_sigma=0.5), 2_000)
    command = np.tile([0.0, 0.0, U_MAX], (2_000, 1))  # full-thrust commands
    norms = np.linalg.norm(_applied(am, command), axis=1)
    cap = U_MAX * (1.0 + bias)
    assert norms.max() <= cap * (1 + 1e-15)
    assert np.isclose(norms, cap, rtol=1e-15).sum() > 500  # the clip is reached (z > 0)
    assert norms.min() >= 0.0


def test_noise_without_draws_is_refused() -> None:
    with pytest.raises(ValueError, match="no actuator draws"):
        actuator.actuator_model(Actuator(magnitude_sigma=0.01), U_MAX, 10, None)


# --- the closed loop ----------------------------------------------------------------


def test_delay_shifts_the_applied_control_by_exactly_k_steps(
    paper_refs: simulation.References,
) -> None:
    run = _run(Actuator(delay_steps=3), refs=paper_refs)
    assert np.array_equal(run.u[:3], np.zeros((3, 3)))
    assert np.array_equal(run.u[3:-1], run.u_cmd[:-4])


def test_misalignment_in_the_loop_applies_r_to_every_command(
    paper_refs: simulation.References,
) -> None:
    run = _run(Actuator(misalignment_deg=(0.0, 0.0, 2.0)), refs=paper_refs)
    np.testing.assert_allclose(run.u, run.u_cmd @ _rz(2.0).T, rtol=0, atol=1e-18)
    assert not np.array_equal(run.u, run.u_cmd)


def test_minimum_thrust_in_the_loop(paper_refs: simulation.References) -> None:
    u_min = 2e-4
    run = _run(Actuator(min_thrust_km_s2=u_min), refs=paper_refs)
    small = np.linalg.norm(run.u_cmd, axis=1) < u_min
    assert small[:-1].any() and (~small).any()  # the adaptive run has both
    assert np.array_equal(run.u[small], np.zeros((small.sum(), 3)))
    assert np.array_equal(run.u[~small], run.u_cmd[~small])


def test_applied_thrust_in_the_loop_stays_below_the_cap(
    paper_refs: simulation.References,
) -> None:
    act = Actuator(magnitude_bias=0.02, magnitude_sigma=0.05, pointing_sigma_deg=1.0)
    run = _run(act, refs=paper_refs, slug="mtf_fixed")  # bang-bang: full-thrust commands
    norms = np.linalg.norm(run.u, axis=1)
    assert norms.max() <= U_MAX * 1.02 * (1 + 1e-15)
    assert np.isclose(norms, U_MAX * 1.02, rtol=1e-15).any()  # full-thrust steps clipped
    assert np.isfinite(run.x_true).all() and np.isfinite(run.x_hat).all()


def test_the_filter_predicts_with_the_commanded_control(
    paper_refs: simulation.References,
) -> None:
    run = _run(Actuator(magnitude_bias=0.05), slug="plain_adaptive", refs=paper_refs)
    problem = Problem()
    phi, gam = discretize(problem.scenario.mean_motion_rad_s, problem.scenario.dt_s)
    est = problem.estimator

    def replay(controls: np.ndarray) -> np.ndarray:
        x, p = run.x_hat[0].copy(), est.p0_matrix()
        out = [x]
        for k in range(run.t_s.size - 1):
            x_pred, p_pred = kf_predict(x, p, phi, gam, controls[k], est.q_matrix())
            x, p, _, _ = kf_update(x_pred, p_pred, run.y[k + 1], est.r_nominal_matrix(), PLAIN)
            out.append(x)
        return np.array(out)

    np.testing.assert_allclose(replay(run.u_cmd), run.x_hat, rtol=0, atol=1e-12)
    assert np.abs(replay(run.u) - run.x_hat).max() > 1e-6  # not with the applied control


def test_delta_v_is_that_of_the_applied_control(paper_refs: simulation.References) -> None:
    run = _run(Actuator(magnitude_bias=-0.1), refs=paper_refs)
    assert run.delta_v_km_s == delta_v(run.t_s, run.u)
    assert run.delta_v_km_s < delta_v(run.t_s, run.u_cmd)


def test_an_ideal_actuator_applies_the_command_bit_for_bit(
    paper_refs: simulation.References,
) -> None:
    base = _run(Actuator(), refs=paper_refs)
    draws = actuator.draw(worker.actuator_seed_sequence(0, 0), Problem().scenario.n_steps)
    with_draws = _run(Actuator(), refs=paper_refs, draws=draws)  # draws unused when ideal
    assert np.array_equal(base.u, base.u_cmd)
    assert np.array_equal(base.x_true, with_draws.x_true)
    assert np.array_equal(base.x_hat, with_draws.x_hat)


# --- random streams --------------------------------------------------------------


def test_actuator_noise_leaves_the_measurement_noise_alone(
    paper_refs: simulation.References,
) -> None:
    cfg = CwrendConfig()
    noisy = config_from_dict({"actuator": {"magnitude_sigma": 0.01, "pointing_sigma_deg": 1.0}})
    assert np.array_equal(
        campaign.standard_normal_for(cfg, 5), campaign.standard_normal_for(noisy, 5)
    )
    arch = (ARCHITECTURES["mtf_adaptive"],)
    plain = campaign.run_case(cfg, arch, 5, refs=paper_refs).runs[0]
    acted = campaign.run_case(noisy, arch, 5, refs=paper_refs).runs[0]
    assert not np.array_equal(plain.x_true, acted.x_true)
    # y − H x is the measurement noise of each step: the same in both runs
    np.testing.assert_allclose(
        plain.y[1:] - plain.x_true[1:, :3], acted.y[1:] - acted.x_true[1:, :3], rtol=0, atol=1e-13
    )


def test_pointing_noise_leaves_the_magnitude_draws_alone() -> None:
    mag = dataclasses.replace(Problem(), actuator=Actuator(magnitude_sigma=0.01))
    both = dataclasses.replace(
        Problem(), actuator=Actuator(magnitude_sigma=0.01, pointing_sigma_deg=1.0)
    )
    a, b = worker.actuator_draws(mag, 0, 4), worker.actuator_draws(both, 0, 4)
    assert a is not None and b is not None
    assert np.array_equal(a.magnitude, b.magnitude)
    assert worker.actuator_draws(Problem(), 0, 4) is None  # an ideal actuator draws nothing


def test_actuator_noise_leaves_the_dispersions_alone() -> None:
    disp = {"scenario.x0.0": {"dist": "normal", "std": 1e-3}}
    cfgs = [
        config_from_dict({"dispersions": disp}),
        config_from_dict({"dispersions": disp, "actuator": {"magnitude_sigma": 0.01}}),
    ]
    plans = [campaign.plan(c, ["mtf_adaptive"], [0, 1, 2]) for c in cfgs]
    assert [r.dispersed for r in plans[0].runs] == [r.dispersed for r in plans[1].runs]


# --- configuration, --set, campaigns ----------------------------------------------


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("actuator.magnitude_sigma=-0.01", "actuator.magnitude_sigma = -0.01: must be >= 0"),
        ("actuator.pointing_sigma_deg=-1.0", "actuator.pointing_sigma_deg = -1: must be >= 0"),
        ("actuator.magnitude_bias=-1.0", "actuator.magnitude_bias = -1: must be > -1"),
        ("actuator.misalignment_deg=[0,0,200]", "actuator.misalignment_deg.2 = 200"),
        ("actuator.misalignment_deg=[0,0]", "actuator.misalignment_deg"),
        ("actuator.min_thrust_km_s2=-1e-5", "actuator.min_thrust_km_s2 = -1e-05: must be >= 0"),
        ("actuator.min_thrust_km_s2=1e-3", "actuator.min_thrust_km_s2 = 0.001: must be <="),
        ("actuator.delay_steps=-1", "actuator.delay_steps = -1: must be >= 0"),
        ("actuator.delay_steps=1.5", "actuator.delay_steps"),
        ("actuator.delay_steps=800", "actuator.delay_steps = 800: must be <"),
        ("actuator.wobble=1.0", "actuator.wobble: unknown key"),
    ],
)
def test_bad_actuator_values_exit_2_naming_the_field(
    override: str, message: str, refused_override: Callable[[str], str]
) -> None:
    assert message in refused_override(override)


def test_config_show_lists_the_actuator_section() -> None:
    result = runner.invoke(
        app, ["config", "show", str(PAPER), "--set", "actuator.pointing_sigma_deg=1.0"]
    )
    assert result.exit_code == 0, result.output
    section = result.stdout.split("[actuator]")[1]
    assert "pointing_sigma_deg = 1.0" in section and "delay_steps = 0" in section


def test_run_with_actuator_errors_set_on_the_command_line(tmp_path: Path) -> None:
    out = tmp_path / "run"
    result = runner.invoke(
        app,
        ["run", str(PAPER), "-a", "mtf_adaptive", "--no-rrd", "-q", "--out", str(out),
         "--set", "actuator.magnitude_sigma=0.01", "--set", "actuator.delay_steps=1"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    steps = pd.read_parquet(out / "steps.parquet")
    assert np.array_equal(steps["ux_km_s2"].to_numpy()[:1], [0.0])  # delayed by one step
    assert '"magnitude_sigma": 0.01' in (out / "config.json").read_text()


def test_a_dispersed_misalignment_is_applied_per_run(
    tmp_path: Path, mtf_sweep: Callable[..., pd.DataFrame]
) -> None:
    body = '[dispersions]\n"actuator.misalignment_deg.2" = { dist = "normal", std = 1.0 }\n'
    runs = mtf_sweep(tmp_path, "disp", body)
    angles = runs["disp.actuator.misalignment_deg.2"].to_numpy()
    assert angles[0] != angles[1] and np.all(np.abs(angles) < 6.0)
    for seed, angle, miss in zip(runs["seed"], angles, runs["miss_km"], strict=True):
        cfg = config_from_dict({"actuator": {"misalignment_deg": [0.0, 0.0, float(angle)]}})
        alone = campaign.run_case(cfg, (ARCHITECTURES["mtf_adaptive"],), int(seed))
        assert alone.runs[0].miss_km == miss  # the same run as a single run of that angle


def test_problem_mirrors_the_actuator_section() -> None:
    cfg = config_from_dict(
        {
            "actuator": {
                "magnitude_bias": 0.01,
                "misalignment_deg": [1.0, 2.0, 3.0],
                "delay_steps": 2,
            }
        }
    )
    assert problem_of(cfg).actuator == Actuator(
        magnitude_bias=0.01, misalignment_deg=(1.0, 2.0, 3.0), delay_steps=2
    )
    assert problem_of(CwrendConfig()).actuator.ideal
