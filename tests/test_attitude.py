"""The torque-free target attitude (issue 34 item 1): cwrend_cli/physics/attitude.py.

Over the paper's horizon (800 s on its 1 s grid, sampled every Δt/20) an asymmetric
body tumbling at about 10 °/s (the fastest rate of the reference study, with energy
near the intermediate axis, so it nutates strongly):

* the kinetic energy and the inertial angular momentum are constant to 1e-12
  relative (the method conserves the quadratic invariants exactly, what is left is
  rounding over 16,000 steps);
* the attitude and the rates match an independent integration written here
  (quaternion + Euler's equations, scipy ``solve_ivp`` DOP853, rtol 1e-12) to
  1e-10 rad and 1e-10 rad/s (DOP853 at rtol 1e-12 is itself accurate to about
  1e-11 here);
* an axisymmetric body follows the closed-form precession (written here);
* the frames: a body spinning at n about the orbit normal stays at rest in the
  Hill frame, a body at rest in inertial space turns at −n about z in it.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from cwrend_cli.physics import attitude
from cwrend_cli.physics.params import Scenario, Target

N = Scenario().mean_motion_rad_s  # the paper's mean motion [rad/s]
HORIZON_S = Scenario().horizon_s  # 800 s
DT_S = Scenario().dt_s  # 1 s
STEPS = round(HORIZON_S / DT_S)

#: An asymmetric body near its intermediate axis, about 10 °/s.
TUMBLE = Target(
    attitude="tumbling",
    initial_quaternion=(0.9, 0.1, -0.3, 0.2),
    body_rates_deg_s=(1.0, 9.5, 2.0),
    inertia=(1.0, 1.7, 2.2),
)


def _run(target: Target) -> attitude.TargetAttitude:
    return attitude.target_attitude(attitude.attitude_model(target, N), STEPS, DT_S)


def _rotation(q_scalar_first: np.ndarray) -> Rotation:
    return Rotation.from_quat(q_scalar_first, scalar_first=True)


def _inertial(att: attitude.TargetAttitude) -> Rotation:
    """Body→inertial (the Hill frame at t = 0): the Hill frame is turned by nt about z."""
    return Rotation.from_rotvec(np.outer(att.t_s, [0.0, 0.0, N])) * _rotation(att.q_hb)


def test_kinetic_energy_is_conserved() -> None:
    att = _run(TUMBLE)
    inertia = np.asarray(TUMBLE.inertia)
    energy = 0.5 * np.sum(inertia * att.w_rad_s**2, axis=1)
    assert np.max(np.abs(energy / energy[0] - 1.0)) < 1e-12


def test_the_inertial_angular_momentum_is_conserved() -> None:
    att = _run(TUMBLE)
    momentum = _inertial(att).apply(np.asarray(TUMBLE.inertia) * att.w_rad_s)
    drift = np.linalg.norm(momentum - momentum[0], axis=1) / np.linalg.norm(momentum[0])
    assert np.max(drift) < 1e-12


def test_the_tumble_nutates() -> None:
    """Not a steady spin: the body rates swing (so the tests above test something)."""
    w = _run(TUMBLE).w_rad_s
    assert np.ptp(w[:, 0]) > 0.5 * np.max(np.abs(w[:, 0]))


def _independent(target: Target, t_eval: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body→inertial quaternions (scalar-first) and ω by DOP853, written independently."""
    i1, i2, i3 = target.inertia

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        q, (p, r, s) = y[:4], y[4:]
        omega = 0.5 * np.array(
            [[0, -p, -r, -s], [p, 0, s, -r], [r, -s, 0, p], [s, r, -p, 0]]
        )  # q̇ = ½ Ω(ω) q, the matrix form of ½ q ⊗ (0, ω)
        return np.concatenate(
            [omega @ q, [(i2 - i3) * r * s / i1, (i3 - i1) * s * p / i2, (i1 - i2) * p * r / i3]]
        )

    q0 = np.asarray(target.initial_quaternion) / np.linalg.norm(target.initial_quaternion)
    y0 = np.concatenate([q0, np.radians(target.body_rates_deg_s)])
    sol = solve_ivp(
        rhs, (0.0, t_eval[-1]), y0, method="DOP853", t_eval=t_eval, rtol=1e-12, atol=1e-14
    )
    assert sol.success
    return sol.y[:4].T, sol.y[4:].T


def test_it_matches_an_independent_integration() -> None:
    att = _run(TUMBLE)
    steps = slice(None, None, att.substeps)
    q_ref, w_ref = _independent(TUMBLE, att.t_s[steps])
    # the reference's attitude in the Hill frame, turned back by nt about z
    hill_ref = Rotation.from_rotvec(np.outer(att.t_s[steps], [0.0, 0.0, -N])) * _rotation(q_ref)
    angle = (hill_ref.inv() * _rotation(att.q_hb[steps])).magnitude()
    assert np.max(angle) < 1e-10
    assert np.max(np.abs(att.w_rad_s[steps] - w_ref)) < 1e-10


def test_an_axisymmetric_body_precesses_in_closed_form() -> None:
    """Torque-free axisymmetric body (Schaub & Junkins, *Analytical Mechanics of Space
    Systems*, 4th ed. 2018, ch. 4, torque-free motion; Landau & Lifshitz, *Mechanics*,
    3rd ed. 1976, §33): with I₁ = I₂ = I_t, I₃ = I_a, the angular velocity is
    ω = (‖L‖/I_t) L̂ + λ ê₃, λ = (I_t − I_a) ω₃ / I_t: a precession at ‖L‖/I_t about the
    fixed inertial L and a spin λ about the body's symmetry axis, so
    R(t) = exp(t ‖L‖/I_t [L̂×]) R(0) exp(t λ [ê₃×]) and the transverse rate turns by −λt
    in the body: ω₁ + iω₂ = (ω₁ + iω₂)(0) e^{−iλt}."""
    target = Target(
        attitude="tumbling",
        initial_quaternion=(0.8, -0.2, 0.5, 0.1),
        body_rates_deg_s=(3.0, -4.0, 8.0),
        inertia=(1.5, 1.5, 1.0),
    )
    att = _run(target)
    t = att.t_s
    i_t, i_a = target.inertia[0], target.inertia[2]
    w0 = np.radians(target.body_rates_deg_s)
    r0 = _rotation(
        np.asarray(target.initial_quaternion) / np.linalg.norm(target.initial_quaternion)
    )
    momentum = r0.apply(np.asarray(target.inertia) * w0)  # inertial, constant
    rate_p = np.linalg.norm(momentum) / i_t
    lam = (i_t - i_a) * w0[2] / i_t
    precession = Rotation.from_rotvec(np.outer(rate_p * t, momentum / np.linalg.norm(momentum)))
    spin = Rotation.from_rotvec(np.outer(lam * t, [0.0, 0.0, 1.0]))
    expected = precession * r0 * spin
    assert np.max((expected.inv() * _inertial(att)).magnitude()) < 1e-10
    transverse = (w0[0] + 1j * w0[1]) * np.exp(-1j * lam * t)
    assert np.max(np.abs(att.w_rad_s[:, 0] - transverse.real)) < 1e-10
    assert np.max(np.abs(att.w_rad_s[:, 1] - transverse.imag)) < 1e-10
    assert np.max(np.abs(att.w_rad_s[:, 2] - w0[2])) < 1e-10


def test_a_spin_at_the_mean_motion_about_the_orbit_normal_is_at_rest_in_the_hill_frame() -> None:
    target = Target(attitude="tumbling", body_rates_deg_s=(0.0, 0.0, math.degrees(N)))
    q = _run(target).q_hb
    assert np.max(np.abs(q - [1.0, 0.0, 0.0, 0.0])) < 1e-12


def test_a_body_at_rest_in_inertial_space_turns_at_minus_n_in_the_hill_frame() -> None:
    att = _run(Target(attitude="tumbling"))
    half = -0.5 * N * att.t_s
    expected = np.stack([np.cos(half), 0 * half, 0 * half, np.sin(half)], axis=1)
    assert np.max(np.abs(att.q_hb - expected)) < 1e-12


def test_the_samples_are_every_step_and_every_safety_sub_step() -> None:
    att = _run(TUMBLE)
    assert att.substeps == 20
    assert att.t_s.shape == (20 * STEPS + 1,)
    q, w = att.at_steps()
    assert q.shape == (STEPS + 1, 4) and w.shape == (STEPS + 1, 3)
    np.testing.assert_array_equal(att.t_s[:: att.substeps], Scenario().time_grid())


def test_the_fastest_allowed_tumble_matches_too() -> None:
    """At 60 °/s about two axes (the bound of body_rates_deg_s) the step is split so that
    no integration step turns the body by more than 0.02 rad: 100 s still match."""
    target = Target(
        attitude="tumbling", body_rates_deg_s=(60.0, -60.0, 5.0), inertia=(1.0, 1.7, 2.2)
    )
    att = attitude.target_attitude(attitude.attitude_model(target, N), 100, DT_S)
    q_ref, w_ref = _independent(target, att.t_s)
    angle = (_rotation(q_ref).inv() * _inertial(att)).magnitude()
    assert np.max(angle) < 1e-10
    assert np.max(np.abs(att.w_rad_s - w_ref)) < 1e-10
