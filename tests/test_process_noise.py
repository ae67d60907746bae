"""Process noise per step (issue 33 item 2): ``estimator.process_noise``.

``from_actuator``: ``Q_k = Q + Γ Σ_e Γᵀ`` with Σ_e the second moment of the
actuator's error about the command, checked against the sample moment of the
actuator model itself (:func:`cwrend_cli.physics.actuator.actuate`) over 10⁵
draws. ``adaptive``: the Sage–Husa estimate, never below ``q_process``,
symmetric positive definite, and converging to the true process noise of a
linear system that has one. The default (``"fixed"``) is left out of the
resolved tree and runs the compiled loop without the process-noise branch
(tests/test_same_numbers.py: bit for bit).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.config.io import config_from_dict, config_hash, resolved_dict
from cwrend_cli.config.schema import CwrendConfig
from cwrend_cli.physics import actuator, ekf, params, simulation
from cwrend_cli.physics import process_noise as pnm
from cwrend_cli.physics.dynamics import discretize
from cwrend_cli.physics.estimation import kf_predict, kf_update

REPO = Path(__file__).resolve().parents[1]
U_MAX = params.Scenario().u_max_km_s2
N_DRAWS = 100_000
#: Per-entry two-sided z threshold: P(|z| > 5) = 5.7e-7 for a correct formula; over the
#: 6 distinct entries × 3 cases below, a family-wise false-alarm rate below 1.1e-5.
Z_MAX = 5.0


def _model(act: params.Actuator, seed: int) -> actuator.ActuatorModel:
    draws = actuator.draw(np.random.SeedSequence(seed), N_DRAWS)
    return actuator.actuator_model(act, U_MAX, N_DRAWS, draws)


CASES = {
    # the mismatch study's errors (1 %, 1°, 1σ per step) at half thrust: no clipping
    "noise": (params.Actuator(magnitude_sigma=0.01, pointing_sigma_deg=1.0), 0.5, 0),
    # large errors, a bias, a misalignment, at full thrust: the ceiling clips half the draws
    "biased_clipped": (
        params.Actuator(
            magnitude_bias=0.02,
            magnitude_sigma=0.05,
            pointing_sigma_deg=10.0,
            misalignment_deg=(1.0, -2.0, 0.5),
        ),
        1.0,
        0,
    ),
    # a delay of 2 steps: the applied control answers the command of 2 steps before
    "delayed": (
        params.Actuator(magnitude_sigma=0.03, pointing_sigma_deg=3.0, delay_steps=2),
        0.8,
        2,
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_actuator_error_moment_is_the_actuator_models_sample_moment(case: str) -> None:
    """Σ_e (:func:`actuator_error_moment`) against the mean of e eᵀ over 10⁵ actuations.

    e = u_a − u_k with u_a = ``actuate`` of the (delayed) command. Each of the six
    distinct entries: |sample mean − Σ_e| below Z_MAX standard errors (the sample's
    own standard deviation of e_i e_j over √n).
    """
    act, fraction, delay = CASES[case]
    am = _model(act, seed=1234)
    direction = np.array([0.3, -0.8, 0.52]) / np.linalg.norm([0.3, -0.8, 0.52])
    commands = np.zeros((3, 3))
    commands[2] = fraction * U_MAX * direction  # u_k, what the filter predicts with
    commands[0] = U_MAX * np.array([0.6, 0.0, 0.8]) * 0.9  # the command of k − 2
    k = 2
    source = commands[k - delay]
    applied = np.empty((N_DRAWS, 3))
    out = np.empty(3)
    for i in range(N_DRAWS):
        actuator.actuate(am, i, source, out)
        applied[i] = out
    err = applied - commands[k]
    _assert_second_moment(err, pnm.actuator_error_moment(am, k, commands), case)


def _assert_second_moment(samples: np.ndarray, expected: np.ndarray, case: str) -> None:
    """Each distinct entry of the sample mean of s sᵀ (rows of ``samples``) against
    ``expected``: within Z_MAX standard errors (the sample's own standard deviation of
    s_i s_j over √n)."""
    n, d = samples.shape
    for i in range(d):
        for j in range(i, d):
            prod = samples[:, i] * samples[:, j]
            se = prod.std(ddof=1) / math.sqrt(n)
            z = (prod.mean() - expected[i, j]) / se
            assert abs(z) < Z_MAX, (case, i, j, prod.mean(), expected[i, j], z)


def test_the_small_angle_form_is_the_limit_of_the_exact_one() -> None:
    """1 %, 1° at ‖u‖: ‖u‖² (σ_m² ûûᵀ + σ_p² (I − ûûᵀ)) to O(σ_p²) relative (docs/method.md)."""
    act = params.Actuator(magnitude_sigma=0.01, pointing_sigma_deg=1.0)
    am = actuator.actuator_model(act, U_MAX, 1, actuator.zero_draws(1))
    u = 0.5 * U_MAX * np.array([0.0, 0.6, 0.8])
    got = pnm.actuator_error_moment(am, 0, u[None, :])
    uh = u / np.linalg.norm(u)
    sp = math.radians(1.0)
    small = np.dot(u, u) * (0.01**2 * np.outer(uh, uh) + sp**2 * (np.eye(3) - np.outer(uh, uh)))
    # the neglected terms are of relative order σ_p² = 3e-4 (of the largest entry)
    np.testing.assert_allclose(got, small, rtol=0, atol=3 * sp**2 * float(np.abs(small).max()))


@pytest.mark.parametrize("sigma", [1e-3, 0.0174533, 0.5, 2.0, 2 * math.pi])
def test_the_mean_cosine_of_the_pointing_tilt(sigma: float) -> None:
    """E[cos θ], θ Rayleigh(σ): the series against quadrature of the density (1e-13)."""

    def integrand(t: float) -> float:
        return math.cos(t) * t / sigma**2 * math.exp(-(t * t) / (2 * sigma**2))

    ref = integrate.quad(integrand, 0.0, 40.0 * sigma, limit=4000, epsabs=1e-15)[0]
    assert pnm.rayleigh_mean_cos(sigma) == pytest.approx(ref, abs=1e-13)


def test_from_actuator_q_is_the_floor_plus_gamma_sigma_gamma() -> None:
    """Q_k = q_process + Γ Σ_e Γᵀ for the filter's Γ (zero-order-hold error over the step)."""
    est = params.Estimator(process_noise="from_actuator")
    act = params.Actuator(magnitude_sigma=0.01, pointing_sigma_deg=1.0)
    pn = pnm.process_noise_model(est, act.ideal, U_MAX)
    assert pn is not None
    am = actuator.actuator_model(act, U_MAX, 1, actuator.zero_draws(1))
    _, gam = discretize(params.Scenario().mean_motion_rad_s, 1.0)
    u = np.array([[4e-4, -2e-4, 1e-4]])
    sig = pnm.actuator_error_moment(am, 0, u)
    np.testing.assert_allclose(
        pnm.step_q(pn, am, 0, u, gam), est.q_matrix() + gam @ sig @ gam.T, rtol=1e-14, atol=0
    )


@pytest.mark.parametrize(
    ("mode", "act"),
    [("fixed", params.Actuator(magnitude_sigma=0.01)), ("from_actuator", params.Actuator())],
)
def test_q_process_at_every_step_runs_the_fixed_loop(mode: str, act: params.Actuator) -> None:
    """Fixed, and from_actuator with an ideal actuator, hand the loop no process-noise model."""
    est = params.Estimator(process_noise=mode)  # type: ignore[arg-type]
    assert pnm.process_noise_model(est, act.ideal, U_MAX) is None


def test_adaptive_q_is_floored_and_positive_definite() -> None:
    """Q_k − q_process is PSD and Q_k symmetric PD, whatever the estimate Σ̂ (indefinite here),
    and Σ̂'s eigenvalues above u_max² are clipped there."""
    rng = np.random.default_rng(7)
    est = params.Estimator(process_noise="adaptive")
    _, gam = discretize(params.Scenario().mean_motion_rad_s, 1.0)
    for _ in range(200):
        pn = pnm.process_noise_model(est, True, U_MAX)
        assert pn is not None
        a = rng.standard_normal((3, 3)) * U_MAX**2 * rng.choice([1e-6, 1.0, 10.0])
        pn.sigma_hat[:, :] = a + a.T  # symmetric, indefinite
        q = pnm.step_q(pn, None, 0, np.zeros((1, 3)), gam)
        assert np.array_equal(q, q.T)
        excess = np.linalg.eigvalsh(q - est.q_matrix())
        assert excess.min() >= -1e-14 * np.abs(q).max()  # ⪰ the floor, to rounding
        assert np.linalg.eigvalsh(q).min() > 0.0
        sig = pnm.psd_part(pn.sigma_hat, pn.sigma_max)
        assert np.linalg.eigvalsh(sig).max() <= U_MAX**2 * (1 + 1e-12)


def test_adaptive_q_converges_to_the_true_process_noise() -> None:
    """Sage–Husa on a linear system with known process noise: the CW filter model (Δt = 1 s),
    x_{k+1} = Φ x_k + Γ a_k with a_k ~ N(0, Σ), Σ = σ² diag(1, 2, 0.5), σ = 1e-3 km/s², and
    position measurements with R = 1e-6 km² (tracking index σΔt²/√R = 1). From Σ̂ = 0
    (Q = q_process) with b = 0.995, the used Σ averaged over steps 5,000–10,000 matches Σ:
    each diagonal entry within 25 %, each off-diagonal within 0.2 σ². Measured over seeds
    0–9: the relative errors of the diagonal had a standard deviation of 5.7 % about a
    mean of 0.3 % (worst 16 %), so 25 % is 4.4 of them, a false-alarm rate of about 3e-5
    for the three entries (normal approximation); the off-diagonals reached 0.084 σ²."""
    n = params.Scenario().mean_motion_rad_s
    phi, gam = discretize(n, 1.0)
    sigma_a = 1e-3
    true = sigma_a**2 * np.diag([1.0, 2.0, 0.5])
    chol = np.linalg.cholesky(true)
    r = 1e-6 * np.eye(3)
    est = params.Estimator(process_noise="adaptive", q_forgetting=0.995)
    pn = pnm.process_noise_model(est, True, math.inf)
    assert pn is not None
    rng = np.random.default_rng(2026)
    x, x_hat = np.zeros(6), np.zeros(6)
    p = est.p0_matrix()
    u, commands = np.zeros(3), np.zeros((1, 3))
    used = np.zeros((3, 3))
    steps = 10_000
    for k in range(steps):
        x = phi @ x + gam @ (chol @ rng.standard_normal(3))
        y = x[:3] + 1e-3 * rng.standard_normal(3)
        q_k = pnm.step_q(pn, None, 0, commands, gam)
        x_pred, p_pred = kf_predict(x_hat, p, phi, gam, u, q_k)
        x_hat, p, _, _ = kf_update(x_pred, p_pred, y, r, False)
        pnm.adapt(pn, gam, x_pred, x_hat, p_pred, p, q_k)
        if k >= steps // 2:
            used += pnm.psd_part(pn.sigma_hat, pn.sigma_max)
    used /= steps - steps // 2
    np.testing.assert_allclose(np.diag(used), np.diag(true), rtol=0.25)
    off = used - np.diag(np.diag(used))
    assert np.abs(off).max() < 0.2 * sigma_a**2


def test_the_loop_logs_trace_q() -> None:
    """trace_q: tr q_process at every step when fixed; tr(Q + Γ Σ_e Γᵀ) with from_actuator."""
    sc = params.Scenario()
    act = params.Actuator(magnitude_sigma=0.01, pointing_sigma_deg=1.0)
    base = params.Problem(scenario=sc, actuator=act, degradation=params.Degradation(windows=()))
    refs = simulation.open_loop_references(base)
    draws = actuator.draw(np.random.SeedSequence(5), sc.n_steps)
    noise = np.random.default_rng(5).standard_normal((sc.n_steps, 3))
    arch = params.ARCHITECTURES["plain_fixed"]
    fixed = simulation.simulate(base, arch, noise, refs, 0, draws)
    assert np.isnan(fixed.trace_q[0])
    np.testing.assert_array_equal(fixed.trace_q[1:], np.trace(base.estimator.q_matrix()))
    prob = dataclasses.replace(base, estimator=params.Estimator(process_noise="from_actuator"))
    run = simulation.simulate(prob, arch, noise, refs, 0, draws)
    am = actuator.actuator_model(act, sc.u_max_km_s2, sc.n_steps, draws)
    _, gam = discretize(sc.mean_motion_rad_s, sc.dt_s)
    k = 10
    sig = pnm.actuator_error_moment(am, k, run.u_cmd)
    q_k = prob.estimator.q_matrix() + gam @ sig @ gam.T
    assert run.trace_q[k + 1] == pytest.approx(np.trace(q_k), rel=1e-12)
    assert np.all(run.trace_q[1:] >= np.trace(prob.estimator.q_matrix()))


def test_the_schedule_runs_on_top_of_the_adaptive_q() -> None:
    """MTF-adaptive with the adaptive Q under actuator errors: Q_k rises above the floor and
    never below it, and the score and ε schedule (Eqs. 24–26) still move ε on finite NIS."""
    act = params.Actuator(magnitude_sigma=0.01, pointing_sigma_deg=1.0)
    est = params.Estimator(process_noise="adaptive")
    prob = params.Problem(actuator=act, estimator=est)
    refs = simulation.open_loop_references(prob)
    n_steps = prob.scenario.n_steps
    draws = actuator.draw(np.random.SeedSequence(11), n_steps)
    noise = np.random.default_rng(11).standard_normal((n_steps, 3))
    run = simulation.simulate(prob, params.ARCHITECTURES["mtf_adaptive"], noise, refs, 0, draws)
    floor = np.trace(est.q_matrix())
    assert np.all(run.trace_q[1:] >= floor) and run.trace_q[1:].max() > 10 * floor
    assert np.all(np.isfinite(run.nis[1:])) and np.all(np.isfinite(run.score[1:]))
    assert np.ptp(run.eps) > 0.1


@pytest.mark.parametrize("table", [{}, {"process_noise": "fixed"}, {"q_forgetting": 0.99}])
def test_the_default_process_noise_keeps_the_hash_and_tree(table: dict[str, object]) -> None:
    cfg = config_from_dict({"estimator": table})
    assert "process_noise" not in resolved_dict(cfg)["estimator"]
    assert "q_forgetting" not in resolved_dict(cfg)["estimator"]
    assert config_hash(cfg) == config_hash(CwrendConfig())
    assert problem_of(cfg) == params.Problem()


def test_a_process_noise_setting_enters_the_tree_and_the_problem() -> None:
    cfg = config_from_dict({"estimator": {"process_noise": "adaptive", "q_forgetting": 0.95}})
    tree = resolved_dict(cfg)
    assert tree["estimator"]["process_noise"] == "adaptive"
    assert config_from_dict(tree) == cfg
    assert problem_of(cfg).estimator.q_forgetting == 0.95
    assert config_hash(cfg) != config_hash(CwrendConfig())


@pytest.mark.parametrize(
    ("setting", "field"),
    [
        ("estimator.process_noise='sage'", "estimator.process_noise"),
        ("estimator.q_forgetting=1.0", "estimator.q_forgetting"),
        ("estimator.q_forgetting=0.2", "estimator.q_forgetting"),
    ],
)
def test_a_bad_process_noise_setting_exits_2_naming_the_field(setting: str, field: str) -> None:
    result = CliRunner().invoke(
        app, ["config", "validate", str(REPO / "campaigns/paper.toml"), "--set", setting]
    )
    assert result.exit_code == 2, result.output
    assert field in result.output
    assert "Traceback" not in result.output


def test_a_process_noise_loop_gets_its_own_first_run_allowance() -> None:
    # from_actuator (with actuator errors) and adaptive compile their own loop: the first run
    # of each in a process is a first run (found when a sweep over the three modes timed out
    # compiling in its second mode); fixed and from_actuator without errors share the fixed one
    from cwrend_cli.campaign import worker

    noisy = {"actuator": {"magnitude_sigma": 0.01}}

    def variant(estimator: dict[str, object], act: dict[str, object]) -> tuple[object, ...]:
        cfg = config_from_dict({"estimator": estimator, "actuator": act})
        return worker.kernel_variant(problem_of(cfg), "mtf_adaptive")

    fixed = variant({}, noisy["actuator"])
    assert variant({"process_noise": "from_actuator"}, noisy["actuator"]) != fixed
    assert variant({"process_noise": "adaptive"}, {}) != variant({}, {})
    assert variant({"process_noise": "from_actuator"}, {}) == variant({}, {})


# --- with the extended Kalman filter (model.filter = "ekf_two_body" | "ekf_j2") ------
#
# The EKF predicts through its nonlinear step F (physics.ekf) and takes the process
# noise of the loop's step_q with the filter's input matrix of
# simulation._filter_tables (CW's Γ over the 1 s step: the EKF has no tables of its own).

#: The EKFs in their own worlds: an eccentric chief (ḟ ≠ n) and an inclined J2 one.
EKF_CASES: dict[str, tuple[params.FilterModelName, params.Truth]] = {
    "ekf_two_body": (
        "ekf_two_body",
        params.Truth(model="two_body", eccentricity=0.1, true_anomaly_deg=40.0),
    ),
    "ekf_j2": ("ekf_j2", params.Truth(model="j2", inclination_deg=51.6)),
}
STUDY_ACTUATOR = params.Actuator(magnitude_sigma=0.01, pointing_sigma_deg=1.0)


#: The worlds of the study's (e) (docs/results/mismatch.md): the paper's circular chief.
STUDY_CASES: dict[str, tuple[params.FilterModelName, params.Truth]] = {
    "ekf_two_body": ("ekf_two_body", params.Truth(model="two_body")),
    "ekf_j2": ("ekf_j2", params.Truth(model="j2", inclination_deg=51.6)),
}


def _ekf_problem(
    case: str,
    mode: str,
    windows: bool = True,
    cases: dict[str, tuple[params.FilterModelName, params.Truth]] = EKF_CASES,
) -> params.Problem:
    name, tr = cases[case]
    return params.Problem(
        truth=tr,
        model=params.DesignModel(filter=name),
        actuator=STUDY_ACTUATOR,
        estimator=params.Estimator(process_noise=mode),  # type: ignore[arg-type]
        degradation=params.Degradation() if windows else params.Degradation(windows=()),
    )


#: The step of the EKF tests below: step 37 from the paper's x0.
EKF_STEP = 37


def _ekf_step(case: str) -> tuple[params.Problem, Callable[[np.ndarray], np.ndarray]]:
    """The case's problem and u ↦ F(x0, u), its EKF's nonlinear step at EKF_STEP."""
    prob = _ekf_problem(case, "from_actuator")
    name, tr = EKF_CASES[case]
    model = ekf.ekf_model(name, prob.scenario, tr)
    assert model is not None
    x = np.asarray(prob.scenario.x0, dtype=float)
    scratch = np.empty((6, 6))

    def step(u: np.ndarray) -> np.ndarray:
        return ekf.ekf_step(model.tm, model.chief[EKF_STEP], x, u, scratch)

    return prob, step


@pytest.mark.parametrize("case", list(EKF_CASES))
def test_the_ekfs_actuator_q_is_its_steps_response_to_the_actuator_errors(case: str) -> None:
    """Q_k − q_process of an EKF against the sample second moment of F(x, u_a) − F(x, u_k).

    F: the EKF's own nonlinear step (:func:`cwrend_cli.physics.ekf.ekf_step`) from the
    paper's x0 at step 37, u_k at 0.8 u_max; u_a: :func:`actuator.actuate` of u_k, 10⁵
    draws of the study's errors (1 %, 1°). Each of the 21 distinct entries within Z_MAX
    standard errors: P(|z| > 5) = 5.7e-7 each, family-wise below 2.4e-5 over both cases.
    What the test can resolve: 5 standard errors are 1.6–1.8 % of each entry, and the CW Γ
    the Q is built with differs from ∂F/∂u by 1.8e-4 relative at most
    (test_the_ekfs_input_matrix_is_cws_to_the_frame_rates_change).
    """
    prob, step = _ekf_step(case)
    direction = np.array([0.3, -0.8, 0.52]) / np.linalg.norm([0.3, -0.8, 0.52])
    commands = (0.8 * U_MAX * direction)[None, :]
    am = _model(STUDY_ACTUATOR, seed=4321)
    nominal = step(commands[0])
    response = np.empty((N_DRAWS, 6))
    applied = np.empty(3)
    for i in range(N_DRAWS):
        actuator.actuate(am, i, commands[0], applied)
        response[i] = step(applied) - nominal
    pn = pnm.process_noise_model(prob.estimator, prob.actuator.ideal, U_MAX)
    assert pn is not None
    gam = simulation._filter_tables(prob)[1][EKF_STEP]
    expected = pnm.step_q(pn, am, 0, commands, gam) - prob.estimator.q_matrix()
    _assert_second_moment(response, expected, case)


@pytest.mark.parametrize(
    ("case", "bound"),
    [("ekf_two_body", 2.5e-4), ("ekf_j2", 1e-6)],
)
def test_the_ekfs_input_matrix_is_cws_to_the_frame_rates_change(case: str, bound: float) -> None:
    """The Γ of an EKF's Q (CW's) against central differences of its step F in u.

    Over one step the control's response is kinematic, Δt²/2 and Δt, corrected by
    the frame's rotation at O(ω Δt) relative; CW's Γ rotates at n, the EKF's frame
    at ḟ. Eccentric chief (e = 0.1, f = 40° at t = 0): ḟ/n − 1 = 0.18 and
    (ḟ − n)Δt = 1.9e-4; measured 1.77e-4, bound 2.5e-4. Circular J2 chief: ω = n up
    to J2's 1e-3, measured 5.2e-8, bound 1e-6. Steps of 1e-6 km/s² in u (1 % of u):
    F is nearly affine in u (the control enters the equations linearly; the curvature
    comes only through the state's change, the gravity gradient acting over one step),
    so the central difference's truncation is far below the bounds, and its rounding
    too (ε |F| / (h Δt²/2) ≈ 1.4e-8 relative in the position rows, |F| ≈ 31 km: part of
    the J2 case's 5.2e-8).
    """
    prob, step = _ekf_step(case)
    u = np.array([1e-4, -2e-4, 1.5e-4])
    h = 1e-6
    cols = []
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        cols.append((step(u + e) - step(u - e)) / (2.0 * h))
    d_f_du = np.stack(cols, axis=1)
    gam = simulation._filter_tables(prob)[1][EKF_STEP]
    assert float(np.abs(gam - d_f_du).max() / np.abs(d_f_du).max()) < bound


def test_the_ekf_loop_predicts_with_the_actuators_q() -> None:
    """trace_q of an ekf_two_body run: tr(q_process + Γ Σ_e Γᵀ) at the commanded u_k."""
    prob = _ekf_problem("ekf_two_body", "from_actuator")
    sc = prob.scenario
    refs = simulation.open_loop_references(prob)
    draws = actuator.draw(np.random.SeedSequence(5), sc.n_steps)
    noise = np.random.default_rng(5).standard_normal((sc.n_steps, 3))
    run = simulation.simulate(prob, params.ARCHITECTURES["plain_fixed"], noise, refs, 0, draws)
    am = actuator.actuator_model(STUDY_ACTUATOR, sc.u_max_km_s2, sc.n_steps, draws)
    gam = simulation._filter_tables(prob)[1]
    for k in (10, 400):
        sig = pnm.actuator_error_moment(am, k, run.u_cmd)
        q_k = prob.estimator.q_matrix() + gam[k] @ sig @ gam[k].T
        assert run.trace_q[k + 1] == pytest.approx(np.trace(q_k), rel=1e-12)


#: Seeds and band of the EKF consistency test below.
CONSISTENCY_SEEDS = 20
NEES_BAND = (5.0, 7.5)


def _mean_nees(prob: params.Problem) -> float:
    """Mean over seeds 0–19 of each plain_fixed run's mean NEES (steps 1–800)."""
    sc = prob.scenario
    refs = simulation.open_loop_references(prob)
    arch = params.ARCHITECTURES["plain_fixed"]
    means = []
    for seed in range(CONSISTENCY_SEEDS):
        draws = actuator.draw(np.random.SeedSequence(seed), sc.n_steps)
        noise = np.random.default_rng(seed).standard_normal((sc.n_steps, 3))
        run = simulation.simulate(prob, arch, noise, refs, seed, draws)
        means.append(float(np.mean(run.nees[1:])))
    return float(np.mean(means))


@pytest.mark.parametrize("case", list(STUDY_CASES))
def test_the_ekf_with_the_actuators_q_is_consistent_under_actuator_errors(case: str) -> None:
    """Each EKF in its own world of the study (the paper's circular chief; J2 at
    i = 51.6°), the study's actuator errors (1 %, 1°), the paper's sensor
    without degradation windows (their R scaling is what the plain filter cannot follow):
    with ``from_actuator`` the mean NEES over 20 seeds lies in [5, 7.5] (6 if consistent);
    with the paper's fixed Q it is thousands.

    The band: the steps' NEES are correlated, so a run's mean NEES is not the mean of 800
    independent χ²(6); measured over seeds 0–99 (circular two-body chief and i = 51.6°
    J2 chief) the run means have a standard deviation of 0.75 about 6.18 and 6.34, so a
    20-seed mean has about 0.17, and the band's ends lie 6.8–7.1 of them from those
    means. Measured here: 6.28 (ekf_two_body) and 6.23 (ekf_j2); with the fixed Q 4,150
    and 4,305. (About the eccentric chief of EKF_CASES, e = 0.1, the run means are
    6.75 ± 0.68 over seeds 0–99: 12 % above 6, slightly overconfident.)
    """
    got = _mean_nees(_ekf_problem(case, "from_actuator", windows=False, cases=STUDY_CASES))
    assert NEES_BAND[0] < got < NEES_BAND[1], got
    fixed = _mean_nees(_ekf_problem(case, "fixed", windows=False, cases=STUDY_CASES))
    assert fixed > 100.0 * NEES_BAND[1], fixed
