"""Sensor faults of the degradation windows and their random streams (issue 15, items 3 and 4).

References:

* The fault model and its conventions: :class:`cwrend_cli.physics.params.Window`
  and :func:`cwrend_cli.physics.sensors.sensor_noise` (dropout, outliers as a
  contaminated Gaussian, Huber 1964, "Robust estimation of a location
  parameter"; a bias random walk, Maybeck 1979, *Stochastic Models,
  Estimation and Control* vol. 1, §4.3). Row k + 1 (the measurement at
  t_{k+1}) carries the window active at t_k (the authors' code; docs/method.md).
* A dropout step has no measurement: the Kalman filter predicts only,
  x̂ = Φ x̂ + Γ u (paper Eq. 11); NIS, MTF ratio and score are NaN, s̄ and ε held
  (:mod:`cwrend_cli.physics._loop_kernels`).
* Statistical tests: the number of outliers among N steps with probability p
  is Binomial(N, p); Σ z² of M independent N(0, 1) is χ²(M) (Bar-Shalom, Li &
  Kirubarajan, *Estimation with Applications to Tracking and Navigation*,
  2001, §1.4.17). Each test accepts between the 0.5e-6 and 1 − 0.5e-6
  quantiles: a two-sided false-alarm rate of 1e-6, on the draws of a fixed
  stream (so the outcome is fixed too).
* Random streams: NumPy ``SeedSequence`` spawn keys, ``(seed, 0)`` the
  measurement noise, ``(seed, 1)`` the dispersions, ``(seed, 2)`` the
  actuator, ``(seed, 3)`` the sensor faults (children 0 dropout, 1 outlier,
  2 drift).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.stats import binom, chi2
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.campaign import worker
from cwrend_cli.cli import app
from cwrend_cli.config import CwrendConfig, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import sensors, simulation
from cwrend_cli.physics.dynamics import discretize
from cwrend_cli.physics.estimation import kf_predict
from cwrend_cli.physics.params import ARCHITECTURES, Actuator, Degradation, Problem, Window

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
#: Two-sided false-alarm rate of every statistical test here.
FALSE_ALARM = 1e-6
#: Steps of the statistical tests.
N_STAT = 200_000
R_NOM = np.diag([1e-6, 1e-6, 1e-6])
runner = CliRunner()


def _problem(*windows: Window) -> Problem:
    return dataclasses.replace(Problem(), degradation=Degradation(windows=windows))


def _run(
    problem: Problem, refs: simulation.References, slug: str = "mtf_adaptive", seed: int = 0
) -> simulation.RunResult:
    """One closed-loop run with the worker's noise and fault draws of ``seed`` (root seed 0)."""
    noise = campaign.standard_normal_for(CwrendConfig(), seed)
    faults = worker.fault_draws(problem, 0, seed)
    return simulation.simulate(problem, ARCHITECTURES[slug], noise, refs, seed, fault_draws=faults)


def _stat_noise(window: Window, seed: int = 11) -> sensors.SensorNoise:
    """``N_STAT`` steps inside ``window`` (Δt = 1 s), zero Gaussian noise unless outliers."""
    times = np.arange(N_STAT, dtype=float)
    windows = (dataclasses.replace(window, start_s=0.0, end_s=float(N_STAT)),)
    draws = sensors.draw_faults(worker.fault_seed_sequence(0, seed), N_STAT, windows)
    std = np.random.Generator(np.random.PCG64(99)).standard_normal((N_STAT, 3))
    return sensors.sensor_noise(std, times, R_NOM, windows, draws, 1.0)


# --- dropouts in the loop ---------------------------------------------------------


def test_a_dropout_step_has_no_update_and_no_nis(paper_refs: simulation.References) -> None:
    problem = _problem(Window(start_s=100.0, end_s=600.0, dropout_probability=0.3))
    run = _run(problem, paper_refs)
    dropped = np.isnan(run.y[1:, 0])
    assert 0 < dropped.sum() < dropped.size
    phi, gam = discretize(problem.scenario.mean_motion_rad_s, problem.scenario.dt_s)
    q = problem.estimator.q_matrix()
    for k in np.flatnonzero(dropped):
        row = k + 1
        assert np.isnan(run.nis[row]) and np.isnan(run.mtf_ratio[row])
        assert np.isnan(run.score[row])
        assert run.eps[row] == run.eps[k]  # ε held
        assert run.score_filtered[row] == run.score_filtered[k]  # s̄ held
        x_pred, _ = kf_predict(run.x_hat[k], np.eye(6), phi, gam, run.u_cmd[k], q)
        np.testing.assert_array_equal(run.x_hat[row], x_pred)  # prediction only
    assert np.all(np.isfinite(run.nis[1:][~dropped]))  # every other step is measured


def test_a_blackout_window_gives_the_pure_prediction(paper_refs: simulation.References) -> None:
    problem = _problem(Window(start_s=250.0, end_s=400.0, dropout_probability=1.0))
    run = _run(problem, paper_refs, slug="plain_adaptive")
    phi, gam = discretize(problem.scenario.mean_motion_rad_s, problem.scenario.dt_s)
    q = problem.estimator.q_matrix()
    # rows 251 … 401 carry the window active at t_k = 250 … 400 (the authors' convention)
    x, p = run.x_hat[250].copy(), np.zeros((6, 6))
    trace_start = run.trace_p[250]
    for k in range(250, 401):
        x, p = kf_predict(x, p, phi, gam, run.u_cmd[k], q)
        np.testing.assert_allclose(run.x_hat[k + 1], x, rtol=0, atol=1e-15)
    assert np.all(np.isnan(run.nis[251:402])) and np.isfinite(run.nis[250])
    assert np.isfinite(run.nis[402])
    assert np.all(run.eps[251:402] == run.eps[250])
    assert np.all(np.diff(run.trace_p[250:402]) > 0) and run.trace_p[401] > trace_start


# --- outliers and the drifting bias -------------------------------------------------


def test_outlier_frequency_matches_its_probability() -> None:
    p = 0.05
    out = _stat_noise(Window(0.0, 1.0, outlier_probability=p, outlier_scale=20.0))
    count = int(out.outlier.sum())
    low, high = binom.ppf(FALSE_ALARM / 2, N_STAT, p), binom.ppf(1 - FALSE_ALARM / 2, N_STAT, p)
    assert low <= count <= high, (count, low, high)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_a_per_axis_outlier_hits_only_its_component_at_its_rate(axis: int) -> None:
    # issue 35 item 3: an outlier probability given per component, 5 % on one axis, 0 on
    # the others (each component on its own draw, stream child 3)
    p = 0.05
    probability = tuple(p if i == axis else 0.0 for i in range(3))
    out = _stat_noise(Window(0.0, 1.0, outlier_probability=probability, outlier_scale=20.0))
    std = np.random.Generator(np.random.PCG64(99)).standard_normal((N_STAT, 3))
    ratio = out.noise / (std @ np.linalg.cholesky(R_NOM).T)
    others = [i for i in range(3) if i != axis]
    np.testing.assert_allclose(ratio[:, others], 1.0, rtol=1e-15)
    np.testing.assert_allclose(ratio[out.outlier, axis], 20.0, rtol=1e-15)
    np.testing.assert_allclose(ratio[~out.outlier, axis], 1.0, rtol=1e-15)
    count = int(out.outlier.sum())
    low, high = binom.ppf(FALSE_ALARM / 2, N_STAT, p), binom.ppf(1 - FALSE_ALARM / 2, N_STAT, p)
    assert low <= count <= high, (count, low, high)


def test_outlier_magnitudes_match_their_scale() -> None:
    c, r_scale = 20.0, 4.0
    out = _stat_noise(Window(0.0, 1.0, r_scale, outlier_probability=0.05, outlier_scale=c))
    std = np.random.Generator(np.random.PCG64(99)).standard_normal((N_STAT, 3))
    base = np.sqrt(r_scale) * 1e-3 * std  # chol(r_scale R_nominal) n
    np.testing.assert_allclose(out.noise[~out.outlier], base[~out.outlier], rtol=1e-15, atol=0)
    # on the outliers the noise is c · chol(R) n, so Σ (v / (c √r_scale σ))² ~ χ²(3 M)
    z = out.noise[out.outlier] / (c * np.sqrt(r_scale) * 1e-3)
    dof = z.size
    stat = float(np.sum(z**2))
    assert chi2.ppf(FALSE_ALARM / 2, dof) <= stat <= chi2.ppf(1 - FALSE_ALARM / 2, dof)


def test_drift_increments_have_the_configured_variance_per_step() -> None:
    q = 2e-4  # km/√s
    bias = (0.01, -0.008, 0.012)
    out = _stat_noise(Window(0.0, 1.0, bias_km=bias, bias_drift_km_per_sqrt_s=q))
    assert np.array_equal(out.drift[0], np.zeros(3))  # the walk starts at zero …
    inc = np.diff(out.drift, axis=0) / (q * np.sqrt(1.0))  # … and adds N(0, q² Δt I) per step
    dof = inc.size
    stat = float(np.sum(inc**2))
    assert chi2.ppf(FALSE_ALARM / 2, dof) <= stat <= chi2.ppf(1 - FALSE_ALARM / 2, dof)


def test_drift_starts_with_the_window_and_does_not_persist() -> None:
    times = np.arange(100, dtype=float)
    windows = (Window(20.0, 59.0, bias_km=(0.01, 0.0, 0.0), bias_drift_km_per_sqrt_s=1e-3),)
    draws = sensors.draw_faults(worker.fault_seed_sequence(0, 1), 100, windows)
    out = sensors.sensor_noise(np.zeros((100, 3)), times, R_NOM, windows, draws, 1.0)
    assert np.all(out.noise[:20] == 0.0) and np.all(out.noise[60:] == 0.0)
    np.testing.assert_array_equal(out.noise[20], [0.01, 0.0, 0.0])  # bias_km exactly
    assert np.all(out.noise[21:60] != out.noise[20])


def test_faults_compose_with_r_scale_and_bias() -> None:
    w = Window(0.0, 1.0, 300.0, (0.01, -0.008, 0.012), outlier_probability=0.05, outlier_scale=3)
    out = _stat_noise(w)
    std = np.random.Generator(np.random.PCG64(99)).standard_normal((N_STAT, 3))
    factor = np.where(out.outlier, 3.0, 1.0)[:, None]
    expected = factor * np.sqrt(300.0) * 1e-3 * std + np.array(w.bias_km)
    np.testing.assert_allclose(out.noise, expected, rtol=1e-12, atol=1e-15)  # 1e-12 m


# --- random streams ----------------------------------------------------------------


def test_all_faults_off_give_the_same_numbers(paper_refs: simulation.References) -> None:
    plain = _run(Problem(), paper_refs)
    inert = tuple(
        dataclasses.replace(w, outlier_scale=50.0)  # a scale without a probability is off
        for w in Problem().degradation.windows
    )
    assert worker.fault_draws(_problem(*inert), 0, 0) is None
    again = _run(_problem(*inert), paper_refs)
    for name in ("x_true", "x_hat", "u", "y", "nis", "eps", "trace_p"):
        np.testing.assert_array_equal(getattr(plain, name), getattr(again, name))


def test_one_fault_leaves_the_other_draws_alone() -> None:
    w = Window(0.0, 800.0, outlier_probability=0.1, outlier_scale=5.0)
    one = worker.fault_draws(_problem(w), 0, 4)
    both = worker.fault_draws(
        _problem(dataclasses.replace(w, dropout_probability=0.2, bias_drift_km_per_sqrt_s=1e-4)),
        0,
        4,
    )
    assert one is not None and both is not None
    assert one.dropout is None and one.drift is None
    assert both.outlier is not None and one.outlier is not None
    assert np.array_equal(one.outlier, both.outlier)


def test_faults_leave_the_noise_and_actuator_streams_alone() -> None:
    faulty = config_from_dict(
        {"degradation": {"windows": [{"start_s": 0.0, "end_s": 800.0, "dropout_probability": 0.5}]}}
    )
    assert np.array_equal(
        campaign.standard_normal_for(CwrendConfig(), 3), campaign.standard_normal_for(faulty, 3)
    )
    act = Actuator(magnitude_sigma=0.01)
    a = worker.actuator_draws(dataclasses.replace(Problem(), actuator=act), 0, 3)
    b = worker.actuator_draws(dataclasses.replace(problem_of(faulty), actuator=act), 0, 3)
    assert a is not None and b is not None
    assert np.array_equal(a.magnitude, b.magnitude) and np.array_equal(a.pointing, b.pointing)


def test_a_fault_without_its_draws_is_refused(paper_refs: simulation.References) -> None:
    problem = _problem(Window(0.0, 800.0, dropout_probability=0.5))
    noise = campaign.standard_normal_for(CwrendConfig(), 0)
    with pytest.raises(ValueError, match="dropout"):
        simulation.simulate(problem, ARCHITECTURES["mtf_adaptive"], noise, paper_refs)


# --- configuration, --set, campaigns ----------------------------------------------


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ("degradation.windows.0.dropout_probability=1.5", "dropout_probability = 1.5: must be <="),
        (
            "degradation.windows.0.dropout_probability=-0.1",
            "dropout_probability = -0.1: must be >=",
        ),
        ("degradation.windows.1.outlier_probability=2.0", "outlier_probability = 2: must be <="),
        ("degradation.windows.0.outlier_scale=-1.0", "outlier_scale = -1: must be >= 0"),
        ("degradation.windows.1.bias_drift_km_per_sqrt_s=-1e-4", "bias_drift_km_per_sqrt_s"),
    ],
)
def test_bad_fault_values_exit_2_naming_the_field(
    override: str, message: str, refused_override: Callable[[str], str]
) -> None:
    stderr = refused_override(override)
    assert "degradation.windows." in stderr and message in stderr


def test_run_with_a_dropout_set_on_the_command_line(tmp_path: Path) -> None:
    out = tmp_path / "run"
    result = runner.invoke(
        app,
        ["run", str(PAPER), "-a", "mtf_adaptive", "--no-rrd", "-q", "--out", str(out),
         "--set", "degradation.windows.0.dropout_probability=1.0"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    steps = pd.read_parquet(out / "steps.parquet")
    nis = steps.set_index("t_s")["nis"]
    assert nis.loc[251.0:325.0].isna().all() and nis.loc[326.0:].notna().all()


def test_a_dispersed_fault_is_applied_per_run(
    tmp_path: Path, mtf_sweep: Callable[..., pd.DataFrame]
) -> None:
    key = "degradation.windows.1.outlier_probability"
    body = (
        "[[degradation.windows]]\nstart_s = 250.0\nend_s = 325.0\n"
        "r_scale = 300.0\n[[degradation.windows]]\nstart_s = 325.0\nend_s = 400.0\n"
        "r_scale = 300.0\nbias_km = [0.010, -0.008, 0.012]\noutlier_scale = 20.0\n"
        f'[dispersions]\n"{key}" = {{ dist = "uniform", low = 0.0, high = 0.5 }}\n'
    )
    runs = mtf_sweep(tmp_path, "disp", body)
    probs = runs[f"disp.{key}"].to_numpy()
    assert probs[0] != probs[1] and np.all((probs >= 0) & (probs <= 0.5))
    for seed, prob, miss in zip(runs["seed"], probs, runs["miss_km"], strict=True):
        windows = [w.model_dump() for w in CwrendConfig().degradation.windows]
        windows[1] |= {"outlier_scale": 20.0, "outlier_probability": float(prob)}
        cfg = config_from_dict({"degradation": {"windows": windows}})
        alone = campaign.run_case(cfg, (ARCHITECTURES["mtf_adaptive"],), int(seed))
        assert alone.runs[0].miss_km == miss  # the same run as a single run of that value


def test_problem_mirrors_the_fault_fields() -> None:
    cfg = config_from_dict(
        {
            "degradation": {
                "windows": [
                    {
                        "start_s": 10.0,
                        "end_s": 20.0,
                        "dropout_probability": 0.1,
                        "outlier_probability": 0.2,
                        "outlier_scale": 5.0,
                        "bias_drift_km_per_sqrt_s": 1e-4,
                    }
                ]
            }
        }
    )
    assert problem_of(cfg).degradation.windows == (
        Window(10.0, 20.0, 1.0, (0.0, 0.0, 0.0), 0.1, 0.2, 5.0, 1e-4),
    )
