"""Truth dynamics: the world the closed loop flies in, separate from the CW design model.

The guidance and the filter use the Clohessy–Wiltshire model (paper Eqs. 3–4) unless
``[model]`` gives them another (:mod:`cwrend_cli.physics.design_models`; the EKF filters
of :mod:`cwrend_cli.physics.ekf` predict with this module's own step);
``truth.model`` chooses what the true relative state obeys (issue 15, item 1):

* ``"cw"``: the same CW model, stepped exactly by ``x⁺ = Φx + Γu`` (Eq. 11);
  the step loop keeps its own code for it, bit for bit.
* ``"two_body"``: the exact nonlinear equations of relative motion of two
  point masses about a Keplerian chief, written in the chief's rotating
  local-vertical frame, for an eccentric chief with its own varying rate ḟ
  (Schaub & Junkins, *Analytical Mechanics of Space Systems*, 4th ed. 2018,
  ch. 14; Alfriend et al., *Spacecraft Formation Flying*, 2010, ch. 4)::

      ẍ − 2ḟẏ − f̈y − ḟ²x = −μ(r + x)/r_d³ + μ/r² + u_x
      ÿ + 2ḟẋ + f̈x − ḟ²y = −μ y/r_d³ + u_y
      z̈                   = −μ z/r_d³ + u_z

  with r_d = ‖(r + x, y, z)‖, the chief radius obeying r̈ = h²/r³ − μ/r²,
  ḟ = h/r² and f̈ = −2ṙḟ/r (h = chief angular momentum, constant).
* ``"j2"``: chief and deputy both under two-body gravity plus the J2 zonal
  term (Vallado, *Fundamentals of Astrodynamics and Applications*, 4th ed.
  2013, ch. 8), integrated in the Earth-centred inertial frame as the
  chief state and the inertial relative state (deputy − chief), never as two
  7,000 km vectors subtracted. The relative state and the control are
  expressed in the chief's actual local-vertical frame, whose angular
  velocity is ω = (r a_h/h) x̂ + (h/r²) ẑ (a_h: the chief's perturbing
  acceleration along ẑ; Schaub & Junkins 2018, ch. 14), so
  that ``ρ̇_LVLH = Rᵀ δv − ω × ρ``.

Axes (the paper's, as the CW model): x radial (outward, along the chief's
position), y along-track (completing the triad, in the direction of motion
for a circular chief), z cross-track (along the chief's orbital angular
momentum). State ``[x y z ẋ ẏ ż]`` in km and km/s, relative to the chief,
its rates taken in the rotating frame.

The control is a zero-order hold over each step, constant in the chief's
local-vertical frame. Each step is integrated by a fixed-step explicit
Runge–Kutta method of order 8: the 12-stage eighth-order solution of
DOP853 (Prince & Dormand, J. Comput. Appl. Math. 7, 1981; Hairer, Nørsett
& Wanner, *Solving Ordinary Differential Equations I*, 2nd ed. 1993), its
coefficients taken
from SciPy's implementation of DOP853 so that none is retyped here. Steps
longer than :data:`MAX_SUBSTEP_S` are split into equal substeps.

The two-body difference ``g(r_c + ρ) − g(r_c)``, g(r) = −μ r/‖r‖³, is
computed without cancellation through Battin's ``f(q) = (1 + q)^{3/2} − 1``
(Battin, *An Introduction to the Mathematics and Methods of Astrodynamics*,
rev. ed. 1999, Encke's method)::

    g(r_c + ρ) − g(r_c) = −μ/r_d³ (ρ − f(q) r_c),   q = (2 r_c·ρ + ρ·ρ)/r_c².

Units: km, s, km/s, km/s², rad.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit
from scipy.integrate._ivp import dop853_coefficients as _dop853

from cwrend_cli.physics.params import FloatArray, Scenario, Truth
from cwrend_cli.physics.variational import j2_relative_gradient, two_body_jacobian

# ---------------------------------------------------------------------------
# Constants: Earth Gravitational Model 2008 (Pavlis, Holmes, Kenyon & Factor,
# "The development and evaluation of the Earth Gravitational Model 2008
# (EGM2008)", J. Geophys. Res. 117, B04406, 2012), its own reference values:
# GM = 3.986004415e14 m³/s², a = 6378136.3 m, C̄20 = −4.84165143790815e-4
# (fully normalised), so J2 = −√5 C̄20.
# ---------------------------------------------------------------------------

#: Earth's gravitational parameter μ (EGM2008) [km³/s²].
MU_EARTH_KM3_S2 = 398600.4415
#: Earth's reference radius R_E (EGM2008) [km].
R_EARTH_KM = 6378.1363
#: Second zonal harmonic J2 = −√5 C̄20 (EGM2008) [-].
J2_EARTH = -math.sqrt(5.0) * -4.84165143790815e-4

#: Codes of ``truth.model`` as the compiled loop takes them.
TRUTH_CW = 0
TRUTH_TWO_BODY = 1
TRUTH_J2 = 2
KIND_CODES = {"cw": TRUTH_CW, "two_body": TRUTH_TWO_BODY, "j2": TRUTH_J2}
#: Codes of the same dynamics with their variational equations Φ̇ = AΦ integrated
#: alongside (the extended Kalman filter's prediction, :mod:`cwrend_cli.physics.ekf`):
#: the state is followed by Φ (6×6, row-major).
VARIATIONAL_TWO_BODY = 3
VARIATIONAL_J2 = 4

#: Longest integration substep [s]; a scenario step Δt is split into ceil(Δt / this).
MAX_SUBSTEP_S = 5.0

_STAGES = int(_dop853.N_STAGES)  # 12 stages of the 8th-order solution
_RK_A = np.ascontiguousarray(np.asarray(_dop853.A, dtype=np.float64)[:_STAGES, :_STAGES])
_RK_B = np.ascontiguousarray(np.asarray(_dop853.B, dtype=np.float64)[:_STAGES])


class TruthModel(NamedTuple):
    """The truth dynamics as the compiled step loop takes them (constant over a run).

    The chief's evolving state is not here: it lives in the loop state
    (``chief``, see :func:`initial_chief`).
    """

    kind: int  # TRUTH_CW, TRUTH_TWO_BODY or TRUTH_J2
    mu: float  # μ [km³/s²]
    r_e: float  # R_E [km]
    j2: float  # J2 [-]
    h: float  # chief specific angular momentum (two_body) [km²/s]
    dt: float  # loop step Δt [s]
    substeps: int  # integration substeps per loop step
    rk_a: np.ndarray  # (12, 12) Runge–Kutta matrix (DOP853, 8th-order solution)
    rk_b: np.ndarray  # (12,) weights


# ---------------------------------------------------------------------------
# Set-up (Python)
# ---------------------------------------------------------------------------


def semi_major_axis_km(mean_motion_rad_s: float, mu: float = MU_EARTH_KM3_S2) -> float:
    """Chief semi-major axis a = (μ/n²)^{1/3} from the CW mean motion n (Kepler's third law)."""
    return float((mu / (mean_motion_rad_s * mean_motion_rad_s)) ** (1.0 / 3.0))


def chief_elements(truth: Truth, scenario: Scenario) -> tuple[float, float, float]:
    """Semi-latus rectum p [km], angular momentum h [km²/s] and radius r(0) [km] of the chief."""
    a = semi_major_axis_km(scenario.mean_motion_rad_s)
    e = truth.eccentricity
    p = a * (1.0 - e * e)
    h = math.sqrt(MU_EARTH_KM3_S2 * p)
    r0 = p / (1.0 + e * math.cos(math.radians(truth.true_anomaly_deg)))
    return p, h, r0


def chief_inertial_state(truth: Truth, scenario: Scenario) -> FloatArray:
    """Chief position and velocity ``[r, v]`` (6,) in the inertial frame at t = 0.

    From the osculating elements a (from n), e, i, Ω, argument of latitude
    u = ω + f and true anomaly f (Vallado 2013, Algorithm 10, written with the
    unit vectors of the local-vertical frame): r = r x̂,
    v = ṙ x̂ + (h/r) ŷ with ṙ = (μ/h) e sin f.
    """
    _, h, r0 = chief_elements(truth, scenario)
    i = math.radians(truth.inclination_deg)
    raan = math.radians(truth.raan_deg)
    u = math.radians(truth.arg_latitude_deg)
    f = math.radians(truth.true_anomaly_deg)
    cu, su, ci, si, co, so = (
        math.cos(u), math.sin(u), math.cos(i), math.sin(i), math.cos(raan), math.sin(raan),
    )  # fmt: skip
    x_hat = np.array([co * cu - so * su * ci, so * cu + co * su * ci, su * si])
    z_hat = np.array([so * si, -co * si, ci])
    y_hat = np.cross(z_hat, x_hat)
    r_dot = MU_EARTH_KM3_S2 / h * truth.eccentricity * math.sin(f)
    out = np.empty(6)
    out[:3] = r0 * x_hat
    out[3:] = r_dot * x_hat + (h / r0) * y_hat
    return out


def initial_chief(truth: Truth, scenario: Scenario) -> FloatArray:
    """The chief's state at t = 0 as the loop carries it (6,).

    ``two_body``: ``[r, ṙ, 0, 0, 0, 0]`` (radius and radial rate);
    ``j2``: the inertial ``[r, v]``; ``cw``: zeros (unused).
    """
    out = np.zeros(6)
    if truth.model == "two_body":
        _, h, r0 = chief_elements(truth, scenario)
        out[0] = r0
        out[1] = (
            MU_EARTH_KM3_S2
            / h
            * truth.eccentricity
            * math.sin(math.radians(truth.true_anomaly_deg))
        )
    elif truth.model == "j2":
        out[:] = chief_inertial_state(truth, scenario)
    return out


def truth_model(truth: Truth, scenario: Scenario) -> TruthModel:
    """The :class:`TruthModel` of ``truth`` for the loop step ``scenario.dt_s``."""
    _, h, _ = chief_elements(truth, scenario)
    return TruthModel(
        kind=KIND_CODES[truth.model],
        mu=MU_EARTH_KM3_S2,
        r_e=R_EARTH_KM,
        j2=J2_EARTH if truth.model == "j2" else 0.0,
        h=h,
        dt=scenario.dt_s,
        substeps=max(1, math.ceil(scenario.dt_s / MAX_SUBSTEP_S - 1e-12)),
        rk_a=_RK_A,
        rk_b=_RK_B,
    )


# ---------------------------------------------------------------------------
# Compiled kernels
# ---------------------------------------------------------------------------


@njit(cache=True)
def battin_f(q: float) -> float:
    """``(1 + q)^{3/2} − 1`` without cancellation for small q (Battin 1999, Encke's method)."""
    s = math.sqrt(1.0 + q)
    return q * (3.0 + q * (3.0 + q)) / (1.0 + s * s * s)


@njit(cache=True)
def j2_accel(
    mu: float, r_e: float, j2: float, x: float, y: float, z: float
) -> tuple[float, float, float]:
    """J2 perturbing acceleration at the inertial position (x, y, z).

    ``a = −(3/2) J2 μ R_E²/r⁵ [x(1 − 5z²/r²), y(1 − 5z²/r²), z(3 − 5z²/r²)]``,
    the gradient of the J2 term of the zonal potential (Vallado 2013, ch. 8;
    Curtis, *Orbital Mechanics for Engineering Students*, ch. 10).
    """
    r2 = x * x + y * y + z * z
    c = -1.5 * j2 * mu * r_e * r_e / (r2 * r2 * math.sqrt(r2))
    z2 = 5.0 * z * z / r2
    return c * x * (1.0 - z2), c * y * (1.0 - z2), c * z * (3.0 - z2)


@njit(cache=True)
def _axes(chief: np.ndarray, rot: np.ndarray) -> tuple[float, float]:
    """Columns x̂ = r/r, ŷ = ẑ × x̂, ẑ = h/h of ``rot`` (3, 3); returns (r, h)."""
    r = chief[0:3]
    v = chief[3:6]
    hx = r[1] * v[2] - r[2] * v[1]
    hy = r[2] * v[0] - r[0] * v[2]
    hz = r[0] * v[1] - r[1] * v[0]
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    rn = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    for i in range(3):
        rot[i, 0] = r[i] / rn
    rot[0, 2] = hx / hn
    rot[1, 2] = hy / hn
    rot[2, 2] = hz / hn
    rot[0, 1] = rot[1, 2] * rot[2, 0] - rot[2, 2] * rot[1, 0]
    rot[1, 1] = rot[2, 2] * rot[0, 0] - rot[0, 2] * rot[2, 0]
    rot[2, 1] = rot[0, 2] * rot[1, 0] - rot[1, 2] * rot[0, 0]
    return rn, hn


@njit(cache=True)
def lvlh_frame(tm: TruthModel, chief: np.ndarray, rot: np.ndarray, omega: np.ndarray) -> None:
    """Chief local-vertical frame: ``rot`` (3, 3) columns x̂, ŷ, ẑ; ``omega`` its rate in it.

    x̂ = r/r, ẑ = h/h, ŷ = ẑ × x̂; ω = (r a_h/h, 0, h/r²) with a_h the chief's
    J2 acceleration along ẑ (Schaub & Junkins 2018, ch. 14).
    """
    rn, hn = _axes(chief, rot)
    ax, ay, az = j2_accel(tm.mu, tm.r_e, tm.j2, chief[0], chief[1], chief[2])
    a_h = ax * rot[0, 2] + ay * rot[1, 2] + az * rot[2, 2]
    omega[0] = rn * a_h / hn
    omega[1] = 0.0
    omega[2] = hn / (rn * rn)


@njit(cache=True)
def lvlh_to_inertial(tm: TruthModel, chief: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """Relative LVLH state ``x`` (6,) → inertial ``[δr, δv]``: δr = Rρ, δv = R(ρ̇ + ω×ρ)."""
    rot = np.empty((3, 3))
    w = np.empty(3)
    lvlh_frame(tm, chief, rot, w)
    vx = x[3] + w[1] * x[2] - w[2] * x[1]
    vy = x[4] + w[2] * x[0] - w[0] * x[2]
    vz = x[5] + w[0] * x[1] - w[1] * x[0]
    for i in range(3):
        out[i] = rot[i, 0] * x[0] + rot[i, 1] * x[1] + rot[i, 2] * x[2]
        out[3 + i] = rot[i, 0] * vx + rot[i, 1] * vy + rot[i, 2] * vz


@njit(cache=True)
def inertial_to_lvlh(tm: TruthModel, chief: np.ndarray, d: np.ndarray, out: np.ndarray) -> None:
    """Inertial relative state ``[δr, δv]`` → LVLH ``[ρ, ρ̇]``: ρ = Rᵀδr, ρ̇ = Rᵀδv − ω×ρ."""
    rot = np.empty((3, 3))
    w = np.empty(3)
    lvlh_frame(tm, chief, rot, w)
    for j in range(3):
        out[j] = rot[0, j] * d[0] + rot[1, j] * d[1] + rot[2, j] * d[2]
        out[3 + j] = rot[0, j] * d[3] + rot[1, j] * d[4] + rot[2, j] * d[5]
    out[3] -= w[1] * out[2] - w[2] * out[1]
    out[4] -= w[2] * out[0] - w[0] * out[2]
    out[5] -= w[0] * out[1] - w[1] * out[0]


@njit(cache=True)
def _rhs_two_body(tm: TruthModel, s: np.ndarray, u: np.ndarray, out: np.ndarray) -> None:
    """Derivative of ``[x y z ẋ ẏ ż r ṙ]``: relative motion in the chief's frame (module doc)."""
    x, y, z, vx, vy = s[0], s[1], s[2], s[3], s[4]
    r, r_dot = s[6], s[7]
    f_dot = tm.h / (r * r)
    f_ddot = -2.0 * r_dot * f_dot / r
    big_f = battin_f((2.0 * r * x + x * x + y * y + z * z) / (r * r))
    c = -tm.mu / (r * r * r * (1.0 + big_f))  # −μ/r_d³
    out[0] = vx
    out[1] = vy
    out[2] = s[5]
    out[3] = c * (x - big_f * r) + 2.0 * f_dot * vy + f_ddot * y + f_dot * f_dot * x + u[0]
    out[4] = c * y - 2.0 * f_dot * vx - f_ddot * x + f_dot * f_dot * y + u[1]
    out[5] = c * z + u[2]
    out[6] = r_dot
    out[7] = tm.h * tm.h / (r * r * r) - tm.mu / (r * r)


@njit(cache=True)
def _rhs_j2(tm: TruthModel, s: np.ndarray, u: np.ndarray, out: np.ndarray) -> None:
    """Derivative of ``[r_c v_c δr δv]`` (inertial) under two-body + J2, control in LVLH."""
    rx, ry, rz, vx, vy, vz = s[0], s[1], s[2], s[3], s[4], s[5]
    dx, dy, dz = s[6], s[7], s[8]
    rc2 = rx * rx + ry * ry + rz * rz
    rcn = math.sqrt(rc2)
    big_f = battin_f((2.0 * (rx * dx + ry * dy + rz * dz) + dx * dx + dy * dy + dz * dz) / rc2)
    c_chief = -tm.mu / (rc2 * rcn)
    c_dep = c_chief / (1.0 + big_f)  # −μ/r_d³
    jcx, jcy, jcz = j2_accel(tm.mu, tm.r_e, tm.j2, rx, ry, rz)
    jdx, jdy, jdz = j2_accel(tm.mu, tm.r_e, tm.j2, rx + dx, ry + dy, rz + dz)
    # chief local-vertical axes: x̂ = r/r, ẑ = h/h, ŷ = ẑ × x̂
    hx = ry * vz - rz * vy
    hy = rz * vx - rx * vz
    hz = rx * vy - ry * vx
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    ex, ey, ez = rx / rcn, ry / rcn, rz / rcn
    zx, zy, zz = hx / hn, hy / hn, hz / hn
    yx, yy, yz = zy * ez - zz * ey, zz * ex - zx * ez, zx * ey - zy * ex
    out[0] = vx
    out[1] = vy
    out[2] = vz
    out[3] = c_chief * rx + jcx
    out[4] = c_chief * ry + jcy
    out[5] = c_chief * rz + jcz
    out[6] = s[9]
    out[7] = s[10]
    out[8] = s[11]
    out[9] = c_dep * (dx - big_f * rx) + (jdx - jcx) + ex * u[0] + yx * u[1] + zx * u[2]
    out[10] = c_dep * (dy - big_f * ry) + (jdy - jcy) + ey * u[0] + yy * u[1] + zy * u[2]
    out[11] = c_dep * (dz - big_f * rz) + (jdz - jcz) + ez * u[0] + yz * u[1] + zz * u[2]


@njit(cache=True)
def _times_phi(a: np.ndarray, s: np.ndarray, at: int, out: np.ndarray) -> None:
    """``out[at:at+36]`` ← AΦ (row-major), ``Φ = s[at:at+36]``, A = [[0, I], [A_r, A_v]]."""
    for i in range(3):
        for j in range(6):
            out[at + 6 * i + j] = s[at + 6 * (3 + i) + j]
    for i in range(3, 6):
        for j in range(6):
            acc = 0.0
            for m in range(6):
                acc += a[i, m] * s[at + 6 * m + j]
            out[at + 6 * i + j] = acc


@njit(cache=True)
def _variational_two_body(tm: TruthModel, s: np.ndarray, out: np.ndarray) -> None:
    """Φ̇ = AΦ of ``[x y z ẋ ẏ ż r ṙ Φ]``, A of :func:`.variational.two_body_jacobian`."""
    a = np.empty((6, 6))
    two_body_jacobian(tm.mu, tm.h, s[0:6], s[6], s[7], a)
    _times_phi(a, s, 8, out)


@njit(cache=True)
def _variational_j2(tm: TruthModel, s: np.ndarray, out: np.ndarray) -> None:
    """Φ̇ = AΦ of ``[r_c v_c δr δv Φ]`` (inertial), A = [[0, I], [∂(δr̈)/∂δr, 0]]."""
    a = np.zeros((6, 6))
    j2_relative_gradient(tm.mu, tm.r_e, tm.j2, s[0:3], s[6:9], a[3:6, 0:3])
    _times_phi(a, s, 12, out)


@njit(cache=True)
def _rhs(tm: TruthModel, s: np.ndarray, u: np.ndarray, out: np.ndarray) -> None:
    if tm.kind == TRUTH_TWO_BODY:
        _rhs_two_body(tm, s, u, out)
    elif tm.kind == TRUTH_J2:
        _rhs_j2(tm, s, u, out)
    elif tm.kind == VARIATIONAL_TWO_BODY:
        _rhs_two_body(tm, s, u, out)
        _variational_two_body(tm, s, out)
    else:
        _rhs_j2(tm, s, u, out)
        _variational_j2(tm, s, out)


@njit(cache=True)
def rk8_step(
    tm: TruthModel, y: np.ndarray, u: np.ndarray, h: float, k: np.ndarray, ys: np.ndarray
) -> None:
    """One explicit Runge–Kutta step of order 8 of ``y`` in place (DOP853's 12 stages).

    Prince & Dormand (1981); Hairer, Nørsett & Wanner (1993). ``k`` (12, n)
    and ``ys`` (n,) are scratch arrays.
    """
    n = y.shape[0]
    stages = tm.rk_b.shape[0]
    for s in range(stages):
        # Σ_j a_sj k_j accumulated in ys in the order j = 0, 1, …, component by component
        # (the loop over the components innermost, so that it vectorises)
        ys[:] = 0.0
        for j in range(s):
            a_sj = tm.rk_a[s, j]
            for i in range(n):
                ys[i] += a_sj * k[j, i]
        for i in range(n):
            ys[i] = y[i] + h * ys[i]
        _rhs(tm, ys, u, k[s])
    for i in range(n):
        acc = 0.0
        for s in range(stages):
            acc += tm.rk_b[s] * k[s, i]
        y[i] += h * acc


@njit(cache=True)
def truth_step(tm: TruthModel, chief: np.ndarray, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Relative LVLH state after one step Δt under ``u`` held in LVLH, as a new 6-vector.

    ``chief`` (6,) is advanced in place (see :func:`initial_chief`). Only
    for ``two_body`` and ``j2``; the CW truth is stepped by ``zoh_step``.
    """
    h = tm.dt / tm.substeps
    out = np.empty(6)
    n = 8 if tm.kind == TRUTH_TWO_BODY else 12
    y = np.empty(n)
    k = np.empty((tm.rk_b.shape[0], n))
    ys = np.empty(n)
    if tm.kind == TRUTH_TWO_BODY:
        y[:6] = x
        y[6] = chief[0]
        y[7] = chief[1]
        for _ in range(tm.substeps):
            rk8_step(tm, y, u, h, k, ys)
        out[:] = y[:6]
        chief[0] = y[6]
        chief[1] = y[7]
    else:
        y[:6] = chief
        lvlh_to_inertial(tm, chief, x, y[6:12])
        for _ in range(tm.substeps):
            rk8_step(tm, y, u, h, k, ys)
        chief[:] = y[:6]
        inertial_to_lvlh(tm, chief, y[6:12], out)
    return out


def propagate(truth: Truth, scenario: Scenario, x0: FloatArray, controls: FloatArray) -> FloatArray:
    """Truth trajectory (K+1, 6) from ``x0`` under ``controls`` (K, 3), one held per step.

    A Python loop over :func:`truth_step` for tests and analysis (the closed
    loop calls the kernel from compiled code). ``truth.model`` must not be ``"cw"``.
    """
    if truth.model == "cw":
        raise ValueError("propagate() integrates the two_body and j2 truths only")
    tm = truth_model(truth, scenario)
    chief = initial_chief(truth, scenario)
    out = np.empty((controls.shape[0] + 1, 6))
    out[0] = x0
    for k in range(controls.shape[0]):
        out[k + 1] = truth_step(tm, chief, out[k], np.ascontiguousarray(controls[k], dtype=float))
    return out
