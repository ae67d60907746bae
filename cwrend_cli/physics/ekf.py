"""Extended Kalman filter on the truth's nonlinear relative dynamics (issue 33 item 1).

``model.filter = "ekf_two_body"`` or ``"ekf_j2"``: the filter's time update
propagates the estimate through the nonlinear equations of relative motion of
:mod:`cwrend_cli.physics.truth` (``two_body``: exact two-body relative motion
about a Keplerian chief in its rotating frame; ``j2``: both spacecraft under
two-body + J2) and the covariance with the Jacobian of that step (Jazwinski,
*Stochastic Processes and Filtering Theory*, 1970, §8.3; Bar-Shalom, Li &
Kirubarajan 2001, §10.3)::

    x̂⁻ = F(x̂⁺, u),   P⁻ = Φ P⁺ Φᵀ + Q,   Φ = ∂F/∂x (x̂⁺)

F is one step Δt of the truth's own integrator (the RK8 step of
:func:`cwrend_cli.physics.truth.rk8_step`, the same substeps) with the control
held, and Φ is the state transition of the variational equations
Φ̇ = A(t) Φ, Φ(t_k) = I, integrated alongside the state by the same Runge–Kutta
step (A analytic: :mod:`cwrend_cli.physics.variational`). An explicit
Runge–Kutta method applied to a system and its variational equations gives
exactly the derivative of its own step map (the stages of the variational
equations are the derivatives of the stages), so Φ is the Jacobian of the
computed F, up to rounding. The update is the linear one (position measured,
H = [I 0]) of :func:`cwrend_cli.physics.estimation.kf_update`, MTF included.

The chief. The filter knows the chief orbit as the ``ss`` and ``ya`` filters
do: from ``[truth]``'s chief elements (a from ``scenario.mean_motion_rad_s``,
e, f₀ and, for ``ekf_j2``, i, Ω, u), with no error of its own. Its chief is
propagated by the filter's own dynamics (``ekf_two_body``: the Keplerian
radius and radial rate [r, ṙ]; ``ekf_j2``: the inertial [r_c, v_c] under
two-body + J2) and tabulated once per scenario at every t_k
(:func:`chief_table`). The chief's equations do not depend on the relative
state, so with the matching truth the table is the truth's own chief, bit
for bit; under another truth (``ekf_two_body`` in the ``j2`` world) the
filter's chief is the Keplerian one, a model mismatch as the CW filter's.

Units: km, s, km/s, km/s².
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Literal, NamedTuple

import numpy as np
from numba import njit

from cwrend_cli.physics.estimation import _sandwich
from cwrend_cli.physics.params import FilterModelName, FloatArray, Scenario, Truth
from cwrend_cli.physics.truth import (
    VARIATIONAL_J2,
    VARIATIONAL_TWO_BODY,
    TruthModel,
    inertial_to_lvlh,
    initial_chief,
    lvlh_frame,
    lvlh_to_inertial,
    rk8_step,
    truth_model,
    truth_step,
)

#: The extended Kalman filters and the truth dynamics each predicts with.
EKF_DYNAMICS: dict[str, Literal["two_body", "j2"]] = {"ekf_two_body": "two_body", "ekf_j2": "j2"}


class EkfModel(NamedTuple):
    """What the extended Kalman filter's prediction holds constant over a run."""

    tm: TruthModel  # the filter's dynamics, kind truth.VARIATIONAL_TWO_BODY or VARIATIONAL_J2
    chief: np.ndarray  # (N+1, 6) the filter's chief at t_k (truth.initial_chief's layout)


def is_ekf(name: FilterModelName) -> bool:
    """Whether ``model.filter = name`` is an extended Kalman filter."""
    return name in EKF_DYNAMICS


def _filter_truth(name: FilterModelName, truth: Truth) -> Truth:
    """``[truth]``'s chief elements with the dynamics of the filter ``name``."""
    return dataclasses.replace(truth, model=EKF_DYNAMICS[name])


@functools.lru_cache(maxsize=16)
def chief_table(name: FilterModelName, scenario: Scenario, truth: Truth) -> FloatArray:
    """The filter's chief (N+1, 6) at t_k = k Δt, k = 0 … N (read-only; module docstring).

    Stepped by :func:`~cwrend_cli.physics.truth.truth_step` with the filter's
    dynamics and a zero relative state. Cached per scenario and truth.
    """
    filt = _filter_truth(name, truth)
    tm = truth_model(filt, scenario)
    chief = initial_chief(filt, scenario)
    table = np.empty((scenario.n_steps + 1, 6))
    table[0] = chief
    zero_x, zero_u = np.zeros(6), np.zeros(3)
    for k in range(scenario.n_steps):
        truth_step(tm, chief, zero_x, zero_u)
        table[k + 1] = chief
    table.flags.writeable = False
    return table


def ekf_model(name: FilterModelName, scenario: Scenario, truth: Truth) -> EkfModel | None:
    """The :class:`EkfModel` of ``model.filter = name``; None for a linear filter."""
    if not is_ekf(name):
        return None
    tm = truth_model(_filter_truth(name, truth), scenario)
    kind = VARIATIONAL_TWO_BODY if EKF_DYNAMICS[name] == "two_body" else VARIATIONAL_J2
    # a writable copy: the compiled loop takes the arrays it always did
    return EkfModel(tm=tm._replace(kind=kind), chief=np.array(chief_table(name, scenario, truth)))


@njit(cache=True)
def _frame_map(tm: TruthModel, chief: np.ndarray, to_inertial: bool, out: np.ndarray) -> None:
    """``out`` (6, 6) ← the matrix of :func:`~cwrend_cli.physics.truth.lvlh_to_inertial`
    (``to_inertial``) or of :func:`~cwrend_cli.physics.truth.inertial_to_lvlh` at ``chief``.

    With R the frame's axes and Ω = [ω×] its rate: L = [[R, 0], [RΩ, R]] (δr = Rρ,
    δv = R(ρ̇ + ω×ρ)), inverse L⁻¹ = [[Rᵀ, 0], [−ΩRᵀ, Rᵀ]].
    """
    rot = np.empty((3, 3))
    w = np.empty(3)
    lvlh_frame(tm, chief, rot, w)
    cross = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    out[:, :] = 0.0
    for i in range(3):
        for j in range(3):
            r_ij = rot[i, j] if to_inertial else rot[j, i]
            out[i, j] = r_ij
            out[3 + i, 3 + j] = r_ij
            acc = 0.0
            for m in range(3):
                acc += rot[i, m] * cross[m, j] if to_inertial else -cross[i, m] * rot[j, m]
            out[3 + i, j] = acc


@njit(cache=True)
def ekf_step(
    tm: TruthModel, chief: np.ndarray, x: np.ndarray, u: np.ndarray, phi: np.ndarray
) -> np.ndarray:
    """F(x, u): the relative state one step Δt later, as a new 6-vector; Φ = ∂F/∂x into ``phi``.

    ``tm``: kind ``VARIATIONAL_TWO_BODY`` or ``VARIATIONAL_J2``; ``chief`` (6,)
    the filter's chief at the step's start (not modified); ``u`` (3,) held in
    the chief's frame. The state part is :func:`~cwrend_cli.physics.truth.truth_step`'s
    arithmetic. ``j2``: the variational equations are integrated for the
    inertial relative state, started at L₀ = ∂δ/∂x (the map
    :func:`~cwrend_cli.physics.truth.lvlh_to_inertial`, linear in x) and
    mapped back with L₁ = ∂x/∂δ at the step's end, so Φ = L₁ Φ_inertial L₀.
    """
    h = tm.dt / tm.substeps
    two_body = tm.kind == VARIATIONAL_TWO_BODY
    at = 8 if two_body else 12
    n = at + 36
    y = np.zeros(n)
    k = np.empty((tm.rk_b.shape[0], n))
    ys = np.empty(n)
    out = np.empty(6)
    if two_body:
        y[:6] = x
        y[6] = chief[0]
        y[7] = chief[1]
        for i in range(6):
            y[at + 7 * i] = 1.0
        for _ in range(tm.substeps):
            rk8_step(tm, y, u, h, k, ys)
        out[:] = y[:6]
        for i in range(6):
            for j in range(6):
                phi[i, j] = y[at + 6 * i + j]
        return out
    lmap = np.empty((6, 6))
    _frame_map(tm, chief, True, lmap)
    y[:6] = chief
    lvlh_to_inertial(tm, chief, x, y[6:12])
    for i in range(6):
        for j in range(6):
            y[at + 6 * i + j] = lmap[i, j]
    for _ in range(tm.substeps):
        rk8_step(tm, y, u, h, k, ys)
    chief_end = y[:6].copy()
    inertial_to_lvlh(tm, chief_end, y[6:12], out)
    _frame_map(tm, chief_end, False, lmap)
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for m in range(6):
                acc += lmap[i, m] * y[at + 6 * m + j]
            phi[i, j] = acc
    return out


@njit(cache=True)
def ekf_predict(
    ekf: EkfModel, k: int, x: np.ndarray, p: np.ndarray, u: np.ndarray, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Time update of step k: ``x⁻ = F(x⁺, u)``, ``P⁻ = Φ P⁺ Φᵀ + Q`` (module docstring)."""
    phi = np.empty((6, 6))
    x_pred = ekf_step(ekf.tm, ekf.chief[k], x, u, phi)
    return x_pred, _sandwich(phi, p, q)
