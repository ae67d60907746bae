"""The extended Kalman filter on the truth's nonlinear dynamics (issue 33 item 1).

References:

* The Jacobians (:mod:`cwrend_cli.physics.variational`): the gravity-gradient
  tensor μ/r⁵ (3 r rᵀ − r² I) (Montenbruck & Gill, *Satellite Orbits*, 2000,
  Eq. 7.56), the J2 partials (ibid. §7.2.1) and the rotating-frame terms of
  the relative motion (Schaub & Junkins 2018, ch. 14), each checked here
  against central differences of the truth's own right-hand side.
* The EKF time update x⁻ = F(x⁺), P⁻ = Φ P Φᵀ + Q, Φ = ∂F/∂x (Jazwinski 1970,
  §8.3; Bar-Shalom, Li & Kirubarajan 2001, §10.3): F is the truth's own step,
  so the predicted mean equals the truth's propagation exactly, and Φ is
  checked against central differences of F.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign import run_case
from cwrend_cli.cli import app
from cwrend_cli.config import config_from_dict
from cwrend_cli.physics import _loop_kernels, ekf, simulation, truth, variational
from cwrend_cli.physics.params import (
    ALL_ARCHITECTURES,
    Degradation,
    DesignModel,
    Estimator,
    FilterModelName,
    Problem,
    Scenario,
    Truth,
)

REPO = Path(__file__).resolve().parents[1]
SC = Scenario()
X0 = np.asarray(SC.x0, dtype=float)
MU, RE, J2 = truth.MU_EARTH_KM3_S2, truth.R_EARTH_KM, truth.J2_EARTH
#: An eccentric chief (varying ḟ, f̈) for the two-body filter; an inclined one for J2.
ECCENTRIC = Truth(model="two_body", eccentricity=0.1, true_anomaly_deg=40.0)
INCLINED = Truth(
    model="j2", eccentricity=0.01, true_anomaly_deg=30.0, inclination_deg=51.6, raan_deg=30.0,
    arg_latitude_deg=40.0,
)  # fmt: skip
CASES: list[tuple[FilterModelName, Truth]] = [("ekf_two_body", ECCENTRIC), ("ekf_j2", INCLINED)]
#: Relative states that exercise every term [km, km/s]: the paper's x0 and an out-of-plane one.
STATES = [X0, np.array([-12.0, 25.0, 8.0, 2e-3, -1e-2, 4e-3])]
runner = CliRunner()


def _central(f: object, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Central differences (f(x + h e_j) − f(x − h e_j)) / 2h, column j, for a callable f."""
    assert callable(f)
    cols = []
    for j, h in enumerate(steps):
        e = np.zeros_like(x)
        e[j] = h
        cols.append((f(x + e) - f(x - e)) / (2.0 * h))
    return np.stack(cols, axis=1)


def _relative_error(a: np.ndarray, ref: np.ndarray) -> float:
    return float(np.abs(a - ref).max() / np.abs(ref).max())


# --- the analytic Jacobians against central differences (1e-7 relative) ----------
#
# Position steps of 1e-3 km: the truncation error of a central difference is
# (h/r)² ≈ 2e-14 relative at r ≈ 7,000 km, the rounding error ε|f|/h ≈ 1e-12
# relative; the right-hand side is linear in the velocity. Measured: ≤ 1e-11 (the J2
# gradient alone 7.7e-10: the rounding of the differences of an acceleration 1e-3 of
# gravity's).


@pytest.mark.parametrize("x", STATES)
def test_the_two_body_jacobian_is_the_derivative_of_the_truths_equations(x: np.ndarray) -> None:
    tm = truth.truth_model(ECCENTRIC, SC)
    chief = truth.initial_chief(ECCENTRIC, SC)  # r, ṙ ≠ 0 at f = 40°

    def rhs(xx: np.ndarray) -> np.ndarray:
        out = np.empty(8)
        truth._rhs_two_body(tm, np.concatenate((xx, chief[:2])), np.zeros(3), out)
        return out[:6]

    a = np.empty((6, 6))
    variational.two_body_jacobian(MU, tm.h, x, chief[0], chief[1], a)
    fd = _central(rhs, x, np.array([1e-3] * 3 + [1e-6] * 3))
    assert _relative_error(a, fd) < 1e-7


@pytest.mark.parametrize("x", STATES)
def test_the_j2_relative_gradient_is_the_derivative_of_the_truths_equations(
    x: np.ndarray,
) -> None:
    tm = truth.truth_model(INCLINED, SC)
    chief = truth.initial_chief(INCLINED, SC)
    dr = x[:3]

    def accel(d: np.ndarray) -> np.ndarray:
        s = np.concatenate((chief, d, np.zeros(3)))
        out = np.empty(12)
        truth._rhs_j2(tm, s, np.zeros(3), out)
        return out[9:12]

    g = np.empty((3, 3))
    variational.j2_relative_gradient(MU, RE, J2, chief, dr, g)
    assert _relative_error(g, _central(accel, dr, np.full(3, 1e-3))) < 1e-7


def test_the_j2_gradient_alone_is_the_derivative_of_the_j2_acceleration() -> None:
    """Alone: in the sum above J2 is 1e-3 of the gradient, where an error could hide."""
    r = truth.chief_inertial_state(INCLINED, SC)[:3] + np.array([3.0, -20.0, 11.0])
    g = np.empty((3, 3))
    variational.j2_gradient(MU, RE, J2, r[0], r[1], r[2], g)
    fd = _central(lambda p: np.array(truth.j2_accel(MU, RE, J2, *p)), r, np.full(3, 1e-3))
    assert _relative_error(g, fd) < 1e-7
    # the gradient of a potential is symmetric; outside the masses it is trace-free (Laplace)
    assert np.abs(g - g.T).max() < 1e-14 * np.abs(g).max()
    assert abs(np.trace(g)) < 1e-14 * np.abs(g).max()


# --- the prediction ---------------------------------------------------------------


@pytest.mark.parametrize(("name", "tr"), CASES)
def test_the_predicted_mean_is_the_truths_own_propagation(name: FilterModelName, tr: Truth) -> None:
    """No control, no noise: 800 predictions equal truth.propagate bit for bit (same RK8)."""
    model = ekf.ekf_model(name, SC, tr)
    assert model is not None
    expected = truth.propagate(tr, SC, X0, np.zeros((SC.n_steps, 3)))
    x, phi, u = X0.copy(), np.empty((6, 6)), np.zeros(3)
    for k in range(SC.n_steps):
        x = ekf.ekf_step(model.tm, model.chief[k], x, u, phi)
        assert np.array_equal(x, expected[k + 1]), k


@pytest.mark.parametrize("dt", [1.0, 12.0])
@pytest.mark.parametrize(("name", "tr"), CASES)
def test_the_covariance_propagates_with_the_linearised_step(
    name: FilterModelName, tr: Truth, dt: float
) -> None:
    """P⁻ of ekf_predict against Φ P Φᵀ + Q with Φ the central differences of the step F.

    Steps 1e-2 km and 1e-4 km/s: truncation ≈ (h/r)² ≈ 2e-12, rounding
    ε|x|/h ≈ 6e-11 in Φ; tolerance 1e-9 relative (measured ≤ 4.1e-11). Δt = 12 s:
    three RK8 substeps of 4 s each. A control held over the step.
    """
    sc = Scenario(dt_s=dt)
    model = ekf.ekf_model(name, sc, tr)
    assert model is not None
    k = 37
    u = np.array([1e-4, -2e-4, 1.5e-4])
    x = np.array([-12.0, 25.0, 8.0, 2e-3, -1e-2, 4e-3])
    p = Estimator().p0_matrix() + 1e-6 * np.ones((6, 6))
    q = Estimator().q_matrix()

    def step(xx: np.ndarray) -> np.ndarray:
        return ekf.ekf_step(model.tm, model.chief[k], xx, u, np.empty((6, 6)))

    phi_fd = _central(step, x, np.array([1e-2] * 3 + [1e-4] * 3))
    phi = np.empty((6, 6))
    step_x = ekf.ekf_step(model.tm, model.chief[k], x, u, phi)
    assert _relative_error(phi, phi_fd) < 1e-9
    ekf_model = ekf.EkfModel(model.tm, model.chief)
    x_pred, p_pred = ekf.ekf_predict(ekf_model, k, x, p, u, q)
    assert np.array_equal(x_pred, step_x)
    assert _relative_error(p_pred, phi_fd @ p @ phi_fd.T + q) < 1e-9


def test_the_filters_chief_is_the_truths() -> None:
    """The chief table of the matching truth is the truth's chief at every t_k, bit for bit."""
    chief = truth.initial_chief(ECCENTRIC, SC)
    tm = truth.truth_model(ECCENTRIC, SC)
    table = ekf.chief_table("ekf_two_body", SC, ECCENTRIC)
    x = X0.copy()
    for k in range(SC.n_steps):
        assert np.array_equal(table[k], chief)
        x = truth.truth_step(tm, chief, x, np.array([1e-4, 0.0, -1e-4]))
    assert np.array_equal(table[-1], chief)


# --- in the closed loop -------------------------------------------------------------


def _estimation_error_m(problem: Problem, slug: str) -> float:
    """Largest ‖x̂ − x‖ (position) over a run with zero measurement noise [m]."""
    arch = ALL_ARCHITECTURES[slug]
    refs = simulation.open_loop_references(problem)
    run = simulation.simulate(problem, arch, np.zeros((SC.n_steps, 3)), refs)
    return float(np.linalg.norm(run.x_hat[:, :3] - run.x_true[:, :3], axis=1).max() * 1e3)


@pytest.mark.parametrize("slug", ["plain_fixed", "plain_fixed_socp"])
def test_the_ekf_tracks_the_two_body_truth_where_the_cw_filter_drifts(slug: str) -> None:
    """Two-body truth (the paper's circular chief), zero measurement noise and no
    degradation windows (their bias), each loop (shooting: resolve_loop; cone program:
    advance).

    The EKF's prediction is the truth's step and each innovation is zero, so its
    estimate is the truth exactly (tolerance 1e-9 m, measured 0). The CW filter's
    prediction misses the nonlinearity each step: measured largest position error
    1.134 m (plain_fixed) and 1.135 m (plain_fixed_socp).
    """
    errors = {
        name: _estimation_error_m(
            Problem(
                truth=Truth(model="two_body"),
                model=DesignModel(filter=name),
                degradation=Degradation(windows=()),
            ),
            slug,
        )
        for name in ("cw", "ekf_two_body")
    }
    assert errors["ekf_two_body"] < 1e-9, errors
    assert errors["cw"] > 0.5, errors


def test_the_default_filter_takes_no_ekf() -> None:
    assert ekf.ekf_model("cw", SC, Truth()) is None
    assert ekf.ekf_model("ya", SC, ECCENTRIC) is None
    assert set(ekf.EKF_DYNAMICS) == {"ekf_two_body", "ekf_j2"}


@pytest.mark.parametrize("name", ["ekf_two_body", "ekf_j2"])
def test_an_ekf_under_the_cw_truth_exits_2_naming_the_field(name: str, tmp_path: Path) -> None:
    """The EKF's chief comes from [truth]; the CW truth flies none (as 'ss', 'ya')."""
    args = ["ablate", str(REPO / "campaigns" / "paper.toml"), "--seeds", "1"]
    sets = [f"model.filter='{name}'", f"output.dir='{tmp_path}'"]
    result = runner.invoke(app, [*args, *(a for s in sets for a in ("--set", s))])
    assert result.exit_code == 2, result.output
    assert "model.filter" in result.output and "truth.model = 'two_body' or 'j2'" in result.output
    assert "Traceback" not in result.output
    assert not any(tmp_path.iterdir())


def test_the_paper_loop_passes_no_ekf_to_compile() -> None:
    """The default filter crosses as None (pruned): the paper's loop compiles no EKF code."""
    archs = (ALL_ARCHITECTURES["plain_adaptive"], ALL_ARCHITECTURES["plain_fixed_socp"])
    run_case(config_from_dict({}), archs, 0)
    for kernel in (_loop_kernels._resolve_loop, _loop_kernels._advance):
        assert "none" in [str(sig[-1]) for sig in kernel.signatures]
