"""Process noise of the Kalman filter per step: fixed, from the actuator, or adaptive (issue 33).

``estimator.process_noise`` chooses the discrete process-noise covariance
``Q_k`` of the filter's time update (paper Eq. 12, ``P⁻ = Φ P⁺ Φᵀ + Q``):

* ``"fixed"``: ``Q_k = Q`` (``estimator.q_process``; the paper's Table 1).
  The compiled loop then never calls this module (:func:`process_noise_model`
  returns None), so its numbers and its compiled code are the paper's.
* ``"from_actuator"``: ``Q_k = Q + Γ_k Σ_e(k) Γ_kᵀ`` (:func:`step_q`), with
  ``Σ_e(k) = E[(u_a − u_k)(u_a − u_k)ᵀ]`` the second moment of the error of
  the applied control ``u_a`` (:func:`cwrend_cli.physics.actuator.actuate`,
  from the command of ``delay_steps`` earlier) about the command ``u_k`` the
  filter predicts with (:func:`actuator_error_moment`), and ``Γ_k`` the
  filter's design-model input matrix. The applied control is held over the
  step (zero-order hold), so the truth's one-step response to the error is
  exactly ``Γ (u_a − u_k)`` (``x_{k+1} = Φ x_k + Γ u_a``) and its second moment
  is ``Γ Σ_e Γᵀ``; it is not the integral of a continuous white noise
  (Van Loan 1978, "Computing integrals involving the matrix exponential"),
  because the error does not change within the step. The errors are drawn
  independently per step, so the one-step terms add as independent noise;
  a fixed bias or misalignment is not white, and enters through its mean
  square (docs/method.md, "Process noise").
* ``"adaptive"``: the Sage–Husa estimator of the process noise (Sage & Husa
  1969, "Adaptive filtering with unknown prior statistics", Proc. JACC,
  pp. 760–769) with a forgetting factor b (exponentially fading memory,
  about ``1/(1 − b)`` steps), restricted to noise that enters through the
  control channel, ``Q_k = Q + Γ_k Σ_a Γ_kᵀ`` (the form of
  ``"from_actuator"``). After each measurement update the per-step sample
  ``Q̃_k = Δx Δxᵀ + P⁺_k − Φ P⁺_{k−1} Φᵀ``, with ``Δx = x⁺ − x⁻ = K ν`` the
  correction of the innovation ν (the same sample as the covariance matching
  of Mohamed & Schwarz 1999, "Adaptive Kalman filtering for INS/GPS",
  J. Geodesy 73, 193–203; its expectation is Q at the filter's steady state,
  since ``P⁻ − P⁺ = K S Kᵀ`` and ``E[ν νᵀ] = S``), is mapped to the
  acceleration in excess of the floor Q by ``Γ⁺ = (ΓᵀΓ)⁻¹Γᵀ``:
  ``Σ̂_k = b Σ̂_{k−1} + (1 − b) Γ⁺ (Q̃_k − Q) Γ⁺ᵀ``, ``Σ̂_0 = 0``; the filter predicts
  with ``Q_k = Q + Γ_k Π(Σ̂_{k−1}) Γ_kᵀ``, ``Π`` clipping the eigenvalues to
  ``[0, u_max²]`` (:func:`psd_part`), so ``Q_k ⪰ Q`` (``estimator.q_process``,
  the floor), is symmetric positive definite, and asks for no acceleration
  noise beyond the thruster's authority.
  ``Φ P⁺_{k−1} Φᵀ = P⁻_k − Q_k``, so nothing beyond the step's own prior and
  posterior is kept. The restriction is needed: with position-only
  measurements the unrestricted 6×6 estimate is not identified by the
  innovations (on the CW filter with 1 m position noise and an isotropic
  1e-5 km/s² acceleration noise, after 40,000 steps the unrestricted estimate
  sat at about 1,300 times the true position block and 0.07 times the
  velocity block). It is the process-side counterpart of the
  measurement-side MTF (paper Eqs. 16–19), which still inflates R on top; a
  dropout step has no innovation and leaves ``Σ̂`` unchanged.

Units: km, s, km/s, km/s² (``Σ_e`` in km²/s⁴, ``Q`` in km², km²/s², km²/s).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from cwrend_cli.physics.actuator import ActuatorModel, misaligned
from cwrend_cli.physics.estimation import _sandwich
from cwrend_cli.physics.params import Estimator

#: ``ProcessNoiseModel.kind`` values.
FROM_ACTUATOR = 1
ADAPTIVE = 2
_KINDS = {"from_actuator": FROM_ACTUATOR, "adaptive": ADAPTIVE}


class ProcessNoiseModel(NamedTuple):
    """The process noise of a run as the compiled loop takes it (one per run)."""

    kind: int  # FROM_ACTUATOR or ADAPTIVE
    forgetting: float  # b of the Sage–Husa estimate, in (0, 1) [-]
    q_floor: np.ndarray  # (6, 6) estimator.q_process [km², km²/s²]
    sigma_hat: np.ndarray  # (3, 3) Sage–Husa estimate Σ̂_a (in place; adaptive) [km²/s⁴]
    sigma_max: float  # ceiling of Σ̂_a's eigenvalues: u_max² [km²/s⁴]


def varies(est: Estimator, ideal_actuator: bool) -> bool:
    """True when Q_k is not ``q_process`` at every step (the loop then compiles its own variant)."""
    return not (
        est.process_noise == "fixed" or (est.process_noise == "from_actuator" and ideal_actuator)
    )


def process_noise_model(
    est: Estimator, ideal_actuator: bool, u_max_km_s2: float
) -> ProcessNoiseModel | None:
    """The loop's process noise for ``est``; None when it is ``q_process`` at every step.

    None for ``"fixed"``, and for ``"from_actuator"`` with an ideal actuator
    (no error: ``Σ_e = 0``), so that those runs are the fixed runs bit for bit.
    """
    if not varies(est, ideal_actuator):
        return None
    q = est.q_matrix()
    return ProcessNoiseModel(
        kind=_KINDS[est.process_noise],
        forgetting=est.q_forgetting,
        q_floor=q,
        sigma_hat=np.zeros((3, 3)),
        sigma_max=u_max_km_s2 * u_max_km_s2,
    )


@njit(cache=True)
def rayleigh_mean_cos(sigma: float) -> float:
    """``E[cos θ]`` for θ Rayleigh-distributed with scale σ [rad] (the pointing tilt angle).

    ``E[cos θ] = Σ_n (−2σ²)ⁿ n!/(2n)! = ₁F₁(1; ½; −σ²/2)`` (the moments
    ``E[θ²ⁿ] = (2σ²)ⁿ n!``), summed after Kummer's transformation
    (Abramowitz & Stegun 1964, Eq. 13.1.27) as
    ``e^{−y} (1 − Σ_{n≥1} yⁿ / (n! (2n − 1)))``, ``y = σ²/2``: terms of one
    sign, no cancellation between them. Small σ: ``1 − σ² + σ⁴/3 − …``.
    """
    y = 0.5 * sigma * sigma
    term = 1.0  # yⁿ / n!
    total = 0.0
    n = 1
    while True:
        term *= y / n
        add = term / (2 * n - 1)
        total += add
        if add <= 1e-17 * total or n > 500:
            break
        n += 1
    return math.exp(-y) * (1.0 - total)


@njit(cache=True)
def _phi(z: float) -> float:
    """Standard normal density."""
    return math.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)


@njit(cache=True)
def _cdf(z: float) -> float:
    """Standard normal distribution function (through erfc: no cancellation in the lower tail)."""
    return 0.5 * math.erfc(-z / math.sqrt(2.0))


@njit(cache=True)
def factor_moments(scale: float, sigma: float, ceiling: float) -> tuple[float, float]:
    """``(E[f], E[f²])`` of the actuator's magnitude factor f of one command.

    ``f = min(max(scale + σ z, 0), ceiling)``, z ~ N(0, 1), with
    ``ceiling = u_cap/‖c‖`` (:func:`cwrend_cli.physics.actuator.actuate`): a
    normal censored at both ends, whose moments are the masses at the ends
    plus the truncated moments between them, ``∫ z φ = −φ`` and
    ``∫ z² φ = Φ − z φ`` (Johnson, Kotz & Balakrishnan 1994, *Continuous
    Univariate Distributions* vol. 1, §13.10). σ = 0: the deterministic
    factor ``actuate`` applies (exactly 1 when ``scale`` is 1).
    """
    if sigma == 0.0:
        f = scale
        if f != 1.0 and f > ceiling:
            f = ceiling
        f = max(f, 0.0)
        return f, f * f
    a = (0.0 - scale) / sigma
    b = (ceiling - scale) / sigma
    pa, pb = _cdf(a), _cdf(b)
    da, db = _phi(a), _phi(b)
    mid = pb - pa
    upper = _cdf(-b)  # P(f = ceiling) = 1 − Φ(b)
    m1 = ceiling * upper + scale * mid + sigma * (da - db)
    m2 = (
        ceiling * ceiling * upper
        + scale * scale * mid
        + 2.0 * scale * sigma * (da - db)
        + sigma * sigma * (mid + a * da - b * db)
    )
    return m1, m2


@njit(cache=True)
def applied_moments(act: ActuatorModel, command: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean (3,) and second moment (3, 3) of the applied control for ``command`` [km/s²].

    The applied control of :func:`~cwrend_cli.physics.actuator.actuate`:
    ``u_a = f · P R c`` with ``v = R c`` (norm ‖c‖, direction d), the tilt
    ``P`` a rotation by θ about a direction uniform in the plane ⟂ d (θ
    Rayleigh with σ_p: ``‖ω‖`` of two N(0, σ_p²) components), so that
    ``P v = cos θ v + sin θ ‖c‖ e`` with e a unit vector ⟂ d of uniform
    direction, independent of θ, and f independent of both:

    ``E[u_a] = E[f] E[cos θ] v``,
    ``E[u_a u_aᵀ] = E[f²] (E[cos² θ] v vᵀ + ½ E[sin² θ] (‖c‖² I − v vᵀ))``,

    with ``E[cos² θ] = (1 + E[cos 2θ])/2`` and 2θ Rayleigh with 2σ_p
    (:func:`rayleigh_mean_cos`). Small angles: ``½ E[sin² θ] ≈ σ_p²`` per
    transverse axis. Below the minimum thrust (or a zero command) nothing is
    applied: both moments are zero.
    """
    mean = np.zeros(3)
    second = np.zeros((3, 3))
    m = math.sqrt(command[0] ** 2 + command[1] ** 2 + command[2] ** 2)
    if m == 0.0 or m < act.u_min:
        return mean, second
    v = misaligned(act, command)
    c1, c2 = 1.0, 1.0
    if act.sigma_pointing > 0.0:
        c1 = rayleigh_mean_cos(act.sigma_pointing)
        c2 = 0.5 * (1.0 + rayleigh_mean_cos(2.0 * act.sigma_pointing))
    half_s2 = 0.5 * (1.0 - c2)
    f1, f2 = factor_moments(act.scale, act.sigma_magnitude, act.u_cap / m)
    for i in range(3):
        mean[i] = f1 * c1 * v[i]
        for j in range(3):
            across = m * m if i == j else 0.0
            second[i, j] = f2 * (c2 * v[i] * v[j] + half_s2 * (across - v[i] * v[j]))
    return mean, second


@njit(cache=True)
def actuator_error_moment(act: ActuatorModel, k: int, commands: np.ndarray) -> np.ndarray:
    """``Σ_e = E[(u_a − u_k)(u_a − u_k)ᵀ]`` (3, 3) of step ``k`` [km²/s⁴].

    ``commands`` (N, 3): the commanded controls of the run so far (row k:
    ``u_k``, what the filter predicts with). The applied control of step k
    comes from the command of ``act.delay`` steps earlier (none before):
    ``Σ_e = E[u_a u_aᵀ] − μ u_kᵀ − u_k μᵀ + u_k u_kᵀ``, μ = E[u_a]
    (:func:`applied_moments`). Without bias, misalignment, delay or clipping,
    ``Σ_e ≈ ‖u‖² (σ_m² û ûᵀ + σ_p² (I − û ûᵀ))`` for small σ_p.
    """
    u = commands[k]
    if k >= act.delay:
        mean, second = applied_moments(act, commands[k - act.delay])
    else:
        mean, second = np.zeros(3), np.zeros((3, 3))
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = second[i, j] - mean[i] * u[j] - u[i] * mean[j] + u[i] * u[j]
    return out


@njit(cache=True)
def psd_part(a: np.ndarray, top: float) -> np.ndarray:
    """``Π(A)`` (3, 3): the symmetric part of ``A`` with its eigenvalues clipped to ``[0, top]``.

    Clipping at zero gives the nearest positive-semidefinite matrix in the
    Frobenius norm (Higham 1988, "Computing a nearest symmetric positive
    semidefinite matrix", Linear Algebra Appl. 103, Theorem 2.1); at ``top``,
    the nearest one whose eigenvalues do not exceed it.
    """
    w, vecs = np.linalg.eigh(0.5 * (a + a.T))
    out = np.zeros((3, 3))
    for m in range(3):
        lam = min(w[m], top)
        if lam > 0.0:
            for i in range(3):
                for j in range(3):
                    out[i, j] += vecs[i, m] * lam * vecs[j, m]
    return 0.5 * (out + out.T)


@njit(cache=True)
def step_q(
    pn: ProcessNoiseModel,
    act: ActuatorModel | None,
    k: int,
    commands: np.ndarray,
    gam: np.ndarray,
) -> np.ndarray:
    """The process noise ``Q_k = Q + Γ_k Σ Γ_kᵀ`` (6, 6) of step ``k``'s time update.

    ``gam``: the filter's Γ_k. ``Σ``: ``from_actuator``, the actuator error's
    second moment (:func:`actuator_error_moment`; ``act`` None, an ideal
    actuator: ``Q``); ``adaptive``, ``Σ̂_a`` with its eigenvalues clipped to
    ``[0, u_max²]`` (:func:`psd_part`), so that ``Q ⪯ Q_k ⪯ Q + u_max² Γ Γᵀ``
    and is symmetric positive definite.
    """
    if pn.kind == ADAPTIVE:
        return _sandwich(gam, psd_part(pn.sigma_hat, pn.sigma_max), pn.q_floor)
    if act is None:
        return pn.q_floor.copy()
    return _sandwich(gam, actuator_error_moment(act, k, commands), pn.q_floor)


@njit(cache=True)
def adapt(
    pn: ProcessNoiseModel,
    gam: np.ndarray,
    x_pred: np.ndarray,
    x_post: np.ndarray,
    p_pred: np.ndarray,
    p_post: np.ndarray,
    q_k: np.ndarray,
) -> None:
    """One Sage–Husa update of ``pn.sigma_hat`` after a measurement update (adaptive only).

    The sample ``Q̃ = Δx Δxᵀ + P⁺_k − Φ P⁺_{k−1} Φᵀ = Δx Δxᵀ + P⁺ − P⁻ + Q_k``
    (Δx = x⁺ − x⁻; ``Φ P⁺_{k−1} Φᵀ = P⁻ − Q_k``), less the floor Q, mapped to
    the acceleration by the pseudo-inverse ``Γ⁺ = (ΓᵀΓ)⁻¹Γᵀ`` of the step's Γ:
    ``Σ̂_a ← b Σ̂_a + (1 − b) Γ⁺ (Q̃ − Q) Γ⁺ᵀ`` (exact for a sample of the form
    ``Q + Γ Σ Γᵀ``): Σ̂_a estimates the noise in excess of the floor.
    """
    if pn.kind != ADAPTIVE:
        return
    q_tilde = np.empty((6, 6))
    for i in range(6):
        di = x_post[i] - x_pred[i]
        for j in range(6):
            excess = q_k[i, j] - pn.q_floor[i, j]
            q_tilde[i, j] = di * (x_post[j] - x_pred[j]) + p_post[i, j] - p_pred[i, j] + excess
    gtg = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            for m in range(6):
                gtg[i, j] += gam[m, i] * gam[m, j]
    pinv = np.linalg.solve(gtg, np.ascontiguousarray(gam.T))  # Γ⁺ (3, 6)
    sample = _sandwich(pinv, q_tilde, np.zeros((3, 3)))
    b = pn.forgetting
    for i in range(3):
        for j in range(3):
            pn.sigma_hat[i, j] = b * pn.sigma_hat[i, j] + (1.0 - b) * sample[i, j]
