"""Jacobians of the nonlinear relative dynamics of the truth (for the extended Kalman filter).

The variational equations Φ̇ = A(t) Φ of the truth's equations of motion
(:mod:`cwrend_cli.physics.truth`) need A = ∂f/∂x, the Jacobian of the
relative dynamics with respect to the relative state. Written analytically
here; ``tests/test_ekf.py`` checks each against central differences of the
truth's own right-hand side. Units: km, s, km/s, km/s²; 1/s² for a gradient.

* Point-mass gravity g(r) = −μ r/‖r‖³ has the gradient (the gravity-gradient
  tensor; Battin 1999, §9.7; Montenbruck & Gill, *Satellite Orbits*, 2000,
  Eq. 7.56)::

      ∂g/∂r = μ/‖r‖⁵ (3 r rᵀ − ‖r‖² I)

* The J2 acceleration a = k [x_i/r⁵ − 5 x_i z²/r⁷ + 2 δ_i3 z/r⁵],
  k = −(3/2) J2 μ R_E² (Vallado 2013, ch. 8; the truth's ``j2_accel``), has
  the symmetric gradient (differentiated term by term; Montenbruck & Gill
  2000, §7.2.1 give the same partials)::

      ∂a_i/∂x_j = k/r⁵ [δ_ij (1 − 5z²/r² + 2δ_i3) − 5 x_i x_j/r² (1 − 7z²/r²)
                         − 10 z (x_i δ_j3 + δ_i3 x_j)/r²]

* The ``two_body`` truth's relative motion in the chief's rotating frame
  (Schaub & Junkins 2018, ch. 14; the truth's module docstring) has, with
  R = (r + x, y, z) the deputy's position from Earth's centre in that frame,
  the Jacobian A = [[0, I], [A_r, A_v]]::

      A_r = ∂g/∂r (R) + [[ḟ², f̈, 0], [−f̈, ḟ², 0], [0, 0, 0]]
      A_v = [[0, 2ḟ, 0], [−2ḟ, 0, 0], [0, 0, 0]]

  (the chief's μ/r² term does not depend on the relative state).
* The ``j2`` truth's inertial relative motion δr̈ = g(r_c + δr) − g(r_c) +
  a_J2(r_c + δr) − a_J2(r_c) + R u has A = [[0, I], [∂g/∂r + ∂a_J2/∂r, 0]]
  at the deputy's position r_c + δr (the control, held in the chief's frame,
  does not depend on the relative state).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def gravity_gradient(mu: float, x: float, y: float, z: float, out: np.ndarray) -> None:
    """``out`` (3, 3) ← ∂g/∂r = μ/r⁵ (3 r rᵀ − r² I) of point-mass gravity at (x, y, z) [1/s²]."""
    r2 = x * x + y * y + z * z
    c = mu / (r2 * r2 * math.sqrt(r2))
    p = (x, y, z)
    for i in range(3):
        for j in range(3):
            out[i, j] = c * 3.0 * p[i] * p[j]
        out[i, i] -= c * r2


@njit(cache=True)
def j2_gradient(
    mu: float, r_e: float, j2: float, x: float, y: float, z: float, out: np.ndarray
) -> None:
    """``out`` (3, 3) ← ∂a_J2/∂r at the inertial position (x, y, z) [1/s²] (module docstring)."""
    out[:, :] = 0.0
    _add_j2_gradient(mu, r_e, j2, x, y, z, out)


@njit(cache=True)
def _add_j2_gradient(
    mu: float, r_e: float, j2: float, x: float, y: float, z: float, out: np.ndarray
) -> None:
    """``out`` (3, 3) += ∂a_J2/∂r at (x, y, z) (module docstring)."""
    r2 = x * x + y * y + z * z
    c = -1.5 * j2 * mu * r_e * r_e / (r2 * r2 * math.sqrt(r2))  # k/r⁵
    inv_r2 = 1.0 / r2
    zz = z * z * inv_r2
    diag = 1.0 - 5.0 * zz
    outer = -5.0 * inv_r2 * (1.0 - 7.0 * zz)
    z10 = 10.0 * z * inv_r2
    p = (x, y, z)
    for i in range(3):
        for j in range(3):
            v = outer * p[i] * p[j]
            if j == 2:
                v -= z10 * p[i]
            if i == 2:
                v -= z10 * p[j]
            if i == j:
                v += diag + (2.0 if i == 2 else 0.0)
            out[i, j] += c * v


@njit(cache=True)
def two_body_jacobian(
    mu: float, h: float, x: np.ndarray, r: float, r_dot: float, out: np.ndarray
) -> None:
    """``out`` (6, 6) ← A = ∂f/∂x of the ``two_body`` truth's relative motion (module docstring).

    ``x`` (6,) relative state in the chief's frame [km, km/s]; ``r`` [km] and
    ``r_dot`` [km/s] the chief's radius and radial rate; ``h`` its angular
    momentum [km²/s] (ḟ = h/r², f̈ = −2ṙḟ/r).
    """
    f_dot = h / (r * r)
    f_ddot = -2.0 * r_dot * f_dot / r
    out[:, :] = 0.0
    for i in range(3):
        out[i, 3 + i] = 1.0
    gravity_gradient(mu, r + x[0], x[1], x[2], out[3:6, 0:3])
    out[3, 0] += f_dot * f_dot
    out[3, 1] += f_ddot
    out[4, 0] -= f_ddot
    out[4, 1] += f_dot * f_dot
    out[3, 4] = 2.0 * f_dot
    out[4, 3] = -2.0 * f_dot


@njit(cache=True)
def j2_relative_gradient(
    mu: float, r_e: float, j2: float, chief: np.ndarray, dr: np.ndarray, out: np.ndarray
) -> None:
    """``out`` (3, 3) ← ∂(δr̈)/∂δr of the ``j2`` truth: ∂g/∂r + ∂a_J2/∂r at r_c + δr [1/s²]."""
    x, y, z = chief[0] + dr[0], chief[1] + dr[1], chief[2] + dr[2]
    gravity_gradient(mu, x, y, z, out)
    _add_j2_gradient(mu, r_e, j2, x, y, z, out)
