"""Actuator errors between the commanded and the applied control (issue 15, item 2).

The model and its conventions are those of :class:`~cwrend_cli.physics.params.Actuator`:
a fixed magnitude scale error, a per-step magnitude noise, a fixed
misalignment (rotation R = R_z(γ) R_y(β) R_x(α), the z-y-x Euler sequence
of Diebel 2006, "Representing attitude: Euler angles, unit quaternions, and
rotation vectors", written here as active rotations of the thrust vector), a
per-step pointing noise (a rotation vector perpendicular to the thrust,
applied with Rodrigues' rotation formula, ibid.), a minimum
thrust and an actuation delay in whole steps; the applied magnitude is clipped
at ``u_max (1 + magnitude_bias)``.

Randomness stays out of the compiled loop: the per-step standard-normal draws
are made here, in Python, from a ``SeedSequence`` the caller chooses (the
campaign worker keys it by realisation, ``spawn_key=(seed, 2)``), and enter
the loop as arrays (:class:`ActuatorDraws`). The magnitude and the pointing
draws come from two children of that sequence (``spawn_key + (0,)`` and
``+ (1,)``), so switching one on never changes the draws of the other.
Units: km/s², rad inside the loop, degrees in the parameters.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from cwrend_cli.physics.params import Actuator, FloatArray


class ActuatorDraws(NamedTuple):
    """The standard-normal draws of the per-step actuator errors of one run."""

    magnitude: FloatArray  # (N,) z_k of the magnitude noise
    pointing: FloatArray  # (N, 3) w_k of the pointing noise (projected ⟂ to the thrust)


class ActuatorModel(NamedTuple):
    """The actuator as the compiled step loop takes it (constant over a run)."""

    ideal: bool  # every error off: applied = commanded, bit for bit
    scale: float  # 1 + magnitude_bias [-]
    sigma_magnitude: float  # σ_m [-]
    rotate: bool  # a misalignment is set (else R = I is skipped, not multiplied)
    rotation: np.ndarray  # (3, 3) misalignment R
    sigma_pointing: float  # σ_p [rad]
    u_min: float  # minimum thrust [km/s²]
    u_cap: float  # u_max (1 + magnitude_bias): the largest magnitude applied [km/s²]
    delay: int  # actuation delay d [steps]
    magnitude_noise: np.ndarray  # (N,) standard-normal z_k
    pointing_noise: np.ndarray  # (N, 3) standard-normal w_k


def _child(seq: np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """Child ``index`` of ``seq``, built explicitly (``spawn`` would depend on call history)."""
    return np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, index))


def draw(seq: np.random.SeedSequence, n_steps: int) -> ActuatorDraws:
    """The standard-normal draws of ``n_steps`` steps from ``seq`` (PCG64 streams).

    The magnitude draws come from child 0 of ``seq``, the pointing draws from
    child 1 (NumPy ``SeedSequence`` spawn keys), independently of each other.
    """
    mag = np.random.Generator(np.random.PCG64(_child(seq, 0))).standard_normal(n_steps)
    point = np.random.Generator(np.random.PCG64(_child(seq, 1))).standard_normal((n_steps, 3))
    return ActuatorDraws(magnitude=mag, pointing=point)


def zero_draws(n_steps: int) -> ActuatorDraws:
    """Draws of a run without per-step actuator noise (all zero)."""
    return ActuatorDraws(magnitude=np.zeros(n_steps), pointing=np.zeros((n_steps, 3)))


def misalignment_matrix(angles_deg: tuple[float, float, float]) -> FloatArray:
    """R = R_z(γ) R_y(β) R_x(α) for ``angles_deg = (α, β, γ)`` (active, right-handed)."""
    a, b, g = (math.radians(v) for v in angles_deg)
    rx = np.array(
        [[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)], [0.0, math.sin(a), math.cos(a)]]
    )
    ry = np.array(
        [[math.cos(b), 0.0, math.sin(b)], [0.0, 1.0, 0.0], [-math.sin(b), 0.0, math.cos(b)]]
    )
    rz = np.array(
        [[math.cos(g), -math.sin(g), 0.0], [math.sin(g), math.cos(g), 0.0], [0.0, 0.0, 1.0]]
    )
    return np.asarray(rz @ ry @ rx, dtype=np.float64)


def actuator_model(
    act: Actuator, u_max_km_s2: float, n_steps: int, draws: ActuatorDraws | None
) -> ActuatorModel:
    """The loop's actuator for ``act``; ``draws`` are required when ``act.noisy``.

    Raises ``ValueError`` when per-step noise is configured but no draws are
    given (the physics core never draws random numbers itself), or when the
    draws do not cover ``n_steps`` steps.
    """
    if draws is None:
        if act.noisy:
            raise ValueError("actuator noise is on but no actuator draws were given")
        draws = zero_draws(n_steps)
    if draws.magnitude.shape != (n_steps,) or draws.pointing.shape != (n_steps, 3):
        raise ValueError(f"actuator draws must cover {n_steps} steps")
    return ActuatorModel(
        ideal=act.ideal,
        scale=1.0 + act.magnitude_bias,
        sigma_magnitude=act.magnitude_sigma,
        rotate=any(angle != 0.0 for angle in act.misalignment_deg),
        rotation=misalignment_matrix(act.misalignment_deg),
        sigma_pointing=math.radians(act.pointing_sigma_deg),
        u_min=act.min_thrust_km_s2,
        u_cap=u_max_km_s2 * (1.0 + act.magnitude_bias),
        delay=act.delay_steps,
        magnitude_noise=np.ascontiguousarray(draws.magnitude, dtype=np.float64),
        pointing_noise=np.ascontiguousarray(draws.pointing, dtype=np.float64),
    )


@njit(cache=True)
def misaligned(am: ActuatorModel, command: np.ndarray) -> np.ndarray:
    """``R c``: the command rotated by the fixed misalignment (a copy of it without one)."""
    v = np.empty(3)
    for i in range(3):
        if am.rotate:
            v[i] = (
                am.rotation[i, 0] * command[0]
                + am.rotation[i, 1] * command[1]
                + am.rotation[i, 2] * command[2]
            )
        else:
            v[i] = command[i]
    return v


@njit(cache=True)
def actuate(am: ActuatorModel, k: int, command: np.ndarray, out: np.ndarray) -> None:
    """Applied control of step ``k`` from the (already delayed) ``command`` into ``out``.

    The rule of :class:`~cwrend_cli.physics.params.Actuator`: nothing below
    the minimum thrust; the command rotated by R, then tilted by the pointing
    vector ω ⟂ R c (Rodrigues' formula, so the tilt angle is exactly ‖ω‖ and
    the norm is kept); magnitude ``‖c‖ (scale + σ_m z_k)`` clipped to
    ``[0, u_cap]``. Written so that an error left at zero changes no bit
    (no rotation without a misalignment, and a factor of exactly 1 reproduces
    the command).
    """
    m = math.sqrt(command[0] ** 2 + command[1] ** 2 + command[2] ** 2)
    if m == 0.0 or m < am.u_min:
        out[:] = 0.0
        return
    v = misaligned(am, command)
    if am.sigma_pointing > 0.0:
        w = am.pointing_noise[k]
        wd = (w[0] * v[0] + w[1] * v[1] + w[2] * v[2]) / m  # w · d, d = R c / ‖c‖
        om = np.empty(3)
        for i in range(3):
            om[i] = am.sigma_pointing * (w[i] - wd * v[i] / m)
        theta = math.sqrt(om[0] ** 2 + om[1] ** 2 + om[2] ** 2)
        if theta > 0.0:
            c, s = math.cos(theta), math.sin(theta) / theta
            # ω ⟂ v: R(ω) v = cos θ v + sin θ (ω̂ × v)
            cx = om[1] * v[2] - om[2] * v[1]
            cy = om[2] * v[0] - om[0] * v[2]
            cz = om[0] * v[1] - om[1] * v[0]
            v[0], v[1], v[2] = c * v[0] + s * cx, c * v[1] + s * cy, c * v[2] + s * cz
    factor = am.scale + am.sigma_magnitude * am.magnitude_noise[k]
    # the magnitude errors never push the thrust above u_cap; a factor of exactly 1
    # (no magnitude error) passes the command through, which the guidance bounds by u_max
    if factor != 1.0 and m * factor > am.u_cap:
        factor = am.u_cap / m
    factor = max(factor, 0.0)
    for i in range(3):
        out[i] = factor * v[i]
