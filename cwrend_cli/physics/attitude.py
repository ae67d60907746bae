"""The target's attitude (issue 34, item 1): a torque-free rigid body, pure functions.

**Frames.** The relative frame is the Hill (LVLH) frame of the CW model: x
radial, y along-track, z cross-track, along the orbit normal. It rotates at
the mean motion n about its own +z relative to inertial space (for the
circular chief the CW model describes). The inertial frame I used here is the
Hill frame **frozen at t = 0**: the two coincide at t = 0, and at time t the
Hill axes are the inertial ones turned by the angle nt about z.

**Quaternions** are scalar-first, ``q = (q0, q1, q2, q3) = (cos ½α, ê sin ½α)``,
Hamilton's product ``p ⊗ q = (p0 q0 − p·q, p0 q + q0 p + p × q)``, and a
quaternion of frame F "body to F" maps body coordinates to F coordinates,
``v_F = q ⊗ (0, v_B) ⊗ q*`` (Diebel, "Representing attitude: Euler angles, unit
quaternions, and rotation vectors", 2006, whose quaternions are scalar-first
too). ``q_ib`` is the attitude body→inertial, ``q_hb`` body→Hill:

    q_hb(t) = q_z(−nt) ⊗ q_ib(t),     q_z(θ) = (cos ½θ, 0, 0, sin ½θ).

**Body rates** ω are the body's angular velocity **relative to inertial
space**, in body axes: what Euler's equations govern and what a rate gyro on
the target would read. The body's rate relative to the Hill frame is
``ω − R_bh (0, 0, n)``: a target at rest in the Hill frame (the ``fixed``
target of ``[target]``, today's geometry) has ω = R_bh(0, 0, n), a spin at n
about the orbit normal; a target with ω = 0 is at rest in inertial space and
turns at −n about z as seen from the chaser's frame.

**Dynamics** (torque-free, principal axes; Euler's equations and the
quaternion kinematics, e.g. Schaub & Junkins, *Analytical Mechanics of Space
Systems*, 4th ed. 2018, ch. 3 (kinematics) and ch. 4 (Euler's equations))::

    I₁ ω̇₁ = (I₂ − I₃) ω₂ ω₃,  I₂ ω̇₂ = (I₃ − I₁) ω₃ ω₁,  I₃ ω̇₃ = (I₁ − I₂) ω₁ ω₂,
    q̇_ib = ½ q_ib ⊗ (0, ω).

Only the ratios of the principal moments I matter (scaling I scales both sides).
The kinetic energy ½ ωᵀ I ω, the body angular momentum's norm ‖I ω‖ and the
inertial angular momentum L = R_ib I ω are constant.

**Integration**: the 3-stage Gauss–Legendre collocation method (order 6;
Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed. 2006,
Sec. II.1.3; by their Theorem IV.2.1 it conserves every quadratic first
integral exactly, here the energy, ‖I ω‖ and ‖q‖, so the quaternion stays a
unit quaternion with no renormalisation). Fixed step: every output interval
is split into equal steps of at most :data:`MAX_ANGLE_PER_STEP_RAD` of
rotation, from the largest rate the body can reach, ``√(ωᵀIω / min I)`` (the
energy bounds it). The implicit stage equations are solved by
:data:`FIXED_POINT_ITERATIONS` fixed-point sweeps; each contracts by about
½ h‖ω‖ ≤ 0.01 (by the triangle inequality of the moments, no entry of the
Jacobian of Euler's equations exceeds a component of ω), so they converge to rounding. The
local error, about 5e-7 (h‖ω‖)⁷ (the method's error constant
(3!)⁴/(7·(6!)³)), is below 1e-18 rad a step: what is left is rounding.

**Precomputed** (:func:`target_attitude`): the motion is torque-free, so it
depends on nothing the chaser does (its plume and contact forces are not
modelled) and is the same for every architecture of a run. The issue has the
truth propagate it inside the step loop; computing it for the whole run
before the loop, at every step and at the :data:`SAFETY_SUBSTEPS` sub-samples
of each step that the safety measurement reads, gives the same numbers (the
same integration of the same equations, with nothing from the loop in it) at
no cost inside the loop.

Units: rad, rad/s, s; inertia as ratios [-].
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from cwrend_cli.physics.constraints import (  # rotation_matrices: re-exported here
    SAFETY_SUBSTEPS,
    BodyMotion,
    rate_bounds,
    rotation_matrices,
)
from cwrend_cli.physics.params import FloatArray, Target

__all__ = [
    "FIXED_POINT_ITERATIONS",
    "MAX_ANGLE_PER_STEP_RAD",
    "AttitudeModel",
    "TargetAttitude",
    "attitude_model",
    "body_motion",
    "euler_rates",
    "hill_from_inertial",
    "knowledge_error",
    "max_rate_rad_s",
    "predict",
    "propagate",
    "quat_multiply",
    "rotation_matrices",
    "target_attitude",
]

#: Largest rotation of one integration step [rad] (of the fastest rate the body can reach).
MAX_ANGLE_PER_STEP_RAD = 0.02
#: Fixed-point sweeps of the Gauss–Legendre stage equations per step [-].
FIXED_POINT_ITERATIONS = 10

# The 3-stage Gauss–Legendre Butcher tableau (Hairer, Lubich & Wanner 2006, Sec. II.1.3).
_R15 = math.sqrt(15.0)
_GL_A = np.array(
    [
        [5.0 / 36.0, 2.0 / 9.0 - _R15 / 15.0, 5.0 / 36.0 - _R15 / 30.0],
        [5.0 / 36.0 + _R15 / 24.0, 2.0 / 9.0, 5.0 / 36.0 - _R15 / 24.0],
        [5.0 / 36.0 + _R15 / 30.0, 2.0 / 9.0 + _R15 / 15.0, 5.0 / 36.0],
    ]
)
_GL_B = np.array([5.0 / 18.0, 4.0 / 9.0, 5.0 / 18.0])


class AttitudeModel(NamedTuple):
    """A torque-free target as the kernels take it (constant over a run)."""

    inertia: FloatArray  # (3,) principal moments of inertia (I₁, I₂, I₃), ratios [-]
    q0: FloatArray  # (4,) attitude body→Hill at t = 0 (= body→inertial), unit, scalar-first [-]
    w0_rad_s: FloatArray  # (3,) angular velocity relative to inertial space, body axes [rad/s]
    n_rad_s: float  # mean motion: the Hill frame's rate about its z [rad/s]
    gl_a: FloatArray  # (3, 3) Gauss–Legendre Runge–Kutta matrix [-]
    gl_b: FloatArray  # (3,) its weights [-]


class TargetAttitude(NamedTuple):
    """The target's attitude over a run, at ``substeps`` equal sub-samples of every step.

    Row ``substeps·k`` is grid time t_k; ``t_s`` (M,) with M = substeps·N + 1.
    """

    t_s: FloatArray  # (M,) times [s]
    q_hb: FloatArray  # (M, 4) attitude body→Hill, scalar-first [-]
    w_rad_s: FloatArray  # (M, 3) angular velocity relative to inertial space, body axes [rad/s]
    substeps: int  # sub-samples per loop step [-]

    def at_steps(self) -> tuple[FloatArray, FloatArray]:
        """``(q_hb, w_rad_s)`` at the grid times t_0 … t_N: (N+1, 4) and (N+1, 3)."""
        return self.q_hb[:: self.substeps], self.w_rad_s[:: self.substeps]


def attitude_model(target: Target, mean_motion_rad_s: float) -> AttitudeModel:
    """The :class:`AttitudeModel` of a ``tumbling`` ``[target]`` (quaternion normalised)."""
    q0 = np.asarray(target.initial_quaternion, dtype=np.float64)
    return AttitudeModel(
        inertia=np.asarray(target.inertia, dtype=np.float64),
        q0=q0 / np.linalg.norm(q0),
        w0_rad_s=np.radians(np.asarray(target.body_rates_deg_s, dtype=np.float64)),
        n_rad_s=float(mean_motion_rad_s),
        gl_a=_GL_A,
        gl_b=_GL_B,
    )


def max_rate_rad_s(model: AttitudeModel) -> float:
    """The largest ‖ω‖ the body can reach [rad/s]: √(ωᵀIω / min I) (energy conservation)."""
    w, inertia = model.w0_rad_s, model.inertia
    return math.sqrt(float(np.sum(inertia * w * w)) / float(np.min(inertia)))


def target_attitude(
    model: AttitudeModel, n_steps: int, dt_s: float, substeps: int = SAFETY_SUBSTEPS
) -> TargetAttitude:
    """The attitude at every step and every ``substeps``-th of a step of a run of ``n_steps``.

    Each sub-interval Δt/substeps is split into the fewest equal integration
    steps of at most :data:`MAX_ANGLE_PER_STEP_RAD` of rotation.
    """
    h_out = dt_s / substeps
    per = max(1, math.ceil(max_rate_rad_s(model) * h_out / MAX_ANGLE_PER_STEP_RAD))
    count = n_steps * substeps
    q_ib, w = propagate(model, h_out, per, count)
    t = np.arange(count + 1, dtype=np.float64) * h_out
    return TargetAttitude(t, hill_from_inertial(q_ib, t, model.n_rad_s), w, substeps)


def body_motion(model: AttitudeModel, q_hb: FloatArray, w_rad_s: FloatArray) -> BodyMotion:
    """The turn of the body frame relative to the Hill frame at the given samples (M rows).

    ``R`` body→Hill from ``q_hb``; the body's angular velocity relative to the
    Hill frame in Hill axes ``Ω = R ω − n ẑ`` (module docstring: ω is relative
    to inertial space, the Hill frame turns at n about its z); the bounds of ‖Ω‖
    and ‖Ω̇‖ from the largest rate the body reaches
    (:func:`~cwrend_cli.physics.constraints.rate_bounds`).
    """
    rot = rotation_matrices(q_hb)
    rate = np.einsum("mij,mj->mi", rot, w_rad_s)
    rate[:, 2] -= model.n_rad_s
    bound, bound_dot = rate_bounds(max_rate_rad_s(model), model.n_rad_s)
    return BodyMotion(rot, np.asarray(rate, dtype=np.float64), bound, bound_dot)


def knowledge_error(target: Target, draws: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The attitude-knowledge error (issue 34 item 3) from standard normals (..., 6).

    ``(δθ [rad], δω [rad/s])``, each (..., 3): a rotation vector in body axes with
    σ = ``knowledge_sigma_deg`` per axis and a body-rate error with σ =
    ``knowledge_sigma_deg_s`` per axis. The guidance believes the attitude
    ``q ⊗ q(δθ)`` and the rates ``ω + δω``. One row (6,) for a run's error
    (``knowledge_draw = "run"``), one row per step for ``"resolve"`` (the
    re-solve at step k takes row k).
    """
    d = np.asarray(draws, dtype=np.float64)
    return (
        math.radians(target.knowledge_sigma_deg) * d[..., :3],
        math.radians(target.knowledge_sigma_deg_s) * d[..., 3:6],
    )


def predict(
    model: AttitudeModel,
    q_hb: FloatArray,
    w_rad_s: FloatArray,
    t_s: float,
    n_steps: int,
    dt_s: float,
    error: tuple[FloatArray, FloatArray],
    substeps: int = SAFETY_SUBSTEPS,
) -> tuple[AttitudeModel, FloatArray, FloatArray]:
    """The attitude the guidance predicts at ``t_s + k·dt_s``, k = 0 … ``n_steps`` (issue 34).

    From the known attitude at ``t_s``: the truth's ``q_hb`` (body→Hill),
    ``w_rad_s`` turned by the knowledge ``error`` (δθ, δω of
    :func:`knowledge_error`): ``q ⊗ q(δθ)``, ``ω + δω``; propagated by the same
    torque-free model and integrator as the truth (:func:`target_attitude`, on
    the same sub-samples). Returns the believed body's model (its rates at
    ``t_s``, for the rate bounds), ``q_hb`` (n_steps+1, 4) and ``ω`` (n_steps+1, 3).
    """
    d_theta, d_w = error
    angle = float(np.linalg.norm(d_theta))
    turn = np.array([1.0, 0.0, 0.0, 0.0])
    if angle > 0.0:
        turn = np.r_[math.cos(0.5 * angle), math.sin(0.5 * angle) * d_theta / angle]
    to_inertial = np.array([math.cos(0.5 * model.n_rad_s * t_s), 0.0, 0.0,
                            math.sin(0.5 * model.n_rad_s * t_s)])  # fmt: skip
    q_ib = quat_multiply(quat_multiply(to_inertial, np.asarray(q_hb, dtype=np.float64)), turn)
    believed = model._replace(
        q0=q_ib / np.linalg.norm(q_ib), w0_rad_s=np.asarray(w_rad_s, dtype=np.float64) + d_w
    )
    h_out = dt_s / substeps
    per = max(1, math.ceil(max_rate_rad_s(believed) * h_out / MAX_ANGLE_PER_STEP_RAD))
    q, w = propagate(believed, h_out, per, n_steps * substeps)
    t = t_s + np.arange(n_steps * substeps + 1, dtype=np.float64) * h_out
    q_h = hill_from_inertial(q, t, model.n_rad_s)
    return believed, q_h[::substeps], w[::substeps]


# ---------------------------------------------------------------------------
# Compiled kernels
# ---------------------------------------------------------------------------


@njit(cache=True)
def quat_multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton's product p ⊗ q of scalar-first quaternions (4,)."""
    out = np.empty(4)
    out[0] = p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3]
    out[1] = p[0] * q[1] + q[0] * p[1] + p[2] * q[3] - p[3] * q[2]
    out[2] = p[0] * q[2] + q[0] * p[2] + p[3] * q[1] - p[1] * q[3]
    out[3] = p[0] * q[3] + q[0] * p[3] + p[1] * q[2] - p[2] * q[1]
    return out


@njit(cache=True)
def euler_rates(inertia: np.ndarray, w: np.ndarray, out: np.ndarray) -> None:
    """ω̇ of Euler's torque-free equations in principal axes into ``out`` (3,) [rad/s²]."""
    out[0] = (inertia[1] - inertia[2]) * w[1] * w[2] / inertia[0]
    out[1] = (inertia[2] - inertia[0]) * w[2] * w[0] / inertia[1]
    out[2] = (inertia[0] - inertia[1]) * w[0] * w[1] / inertia[2]


@njit(cache=True)
def _rhs(inertia: np.ndarray, y: np.ndarray, out: np.ndarray) -> None:
    """Derivative of ``y = [q_ib (4), ω (3)]``: ½ q ⊗ (0, ω) and Euler's equations."""
    q0, q1, q2, q3 = y[0], y[1], y[2], y[3]
    wx, wy, wz = y[4], y[5], y[6]
    out[0] = 0.5 * (-q1 * wx - q2 * wy - q3 * wz)
    out[1] = 0.5 * (q0 * wx + q2 * wz - q3 * wy)
    out[2] = 0.5 * (q0 * wy + q3 * wx - q1 * wz)
    out[3] = 0.5 * (q0 * wz + q1 * wy - q2 * wx)
    euler_rates(inertia, y[4:7], out[4:7])


@njit(cache=True)
def _gauss_step(
    model: AttitudeModel, y: np.ndarray, h: float, k: np.ndarray, kn: np.ndarray, ys: np.ndarray
) -> None:
    """One Gauss–Legendre step (3 stages, order 6) of ``y`` in place.

    ``k``, ``kn`` (3, 7) and ``ys`` (7,) are scratch arrays.
    """
    for s in range(3):
        _rhs(model.inertia, y, k[s])
    for _ in range(FIXED_POINT_ITERATIONS):
        for s in range(3):
            for i in range(7):
                ys[i] = y[i] + h * (
                    model.gl_a[s, 0] * k[0, i]
                    + model.gl_a[s, 1] * k[1, i]
                    + model.gl_a[s, 2] * k[2, i]
                )
            _rhs(model.inertia, ys, kn[s])
        k[:, :] = kn
    for i in range(7):
        y[i] += h * (model.gl_b[0] * k[0, i] + model.gl_b[1] * k[1, i] + model.gl_b[2] * k[2, i])


@njit(cache=True)
def propagate(
    model: AttitudeModel, h_out_s: float, per_sample: int, count: int
) -> tuple[np.ndarray, np.ndarray]:
    """``(q_ib, ω)`` at ``count`` + 1 times ``i·h_out_s``: (count+1, 4), (count+1, 3).

    ``per_sample`` equal Gauss–Legendre steps between two samples.
    """
    q = np.empty((count + 1, 4))
    w = np.empty((count + 1, 3))
    y = np.empty(7)
    y[:4] = model.q0
    y[4:] = model.w0_rad_s
    k = np.empty((3, 7))
    kn = np.empty((3, 7))
    ys = np.empty(7)
    h = h_out_s / per_sample
    q[0] = y[:4]
    w[0] = y[4:]
    for i in range(count):
        for _ in range(per_sample):
            _gauss_step(model, y, h, k, kn, ys)
        q[i + 1] = y[:4]
        w[i + 1] = y[4:]
    return q, w


@njit(cache=True)
def hill_from_inertial(q_ib: np.ndarray, t_s: np.ndarray, n_rad_s: float) -> np.ndarray:
    """``q_hb = q_z(−nt) ⊗ q_ib`` at each time (M, 4): the attitude in the turning Hill frame."""
    out = np.empty_like(q_ib)
    turn = np.zeros(4)
    for i in range(t_s.shape[0]):
        half = -0.5 * n_rad_s * t_s[i]
        turn[0] = math.cos(half)
        turn[3] = math.sin(half)
        out[i] = quat_multiply(turn, q_ib[i])
    return out
