"""Compiled step loop of the closed loop (private; see :mod:`cwrend_cli.physics.simulation`).

One step k (the authors' code's order; not in the paper, see docs/method.md):
control from the current costate and ε → actuator (the applied control,
:mod:`cwrend_cli.physics.actuator`) → truth step → measurement (noise of the
window at t_k) → KF predict (with the commanded control) → innovation, NIS,
MTF → update → score → ε → [re-solve, done by the caller] → costate
propagated by Δt.

A dropout step (``LoopModel.dropout``, a sensor fault of the window at t_k,
:mod:`cwrend_cli.physics.sensors`) has no measurement: the filter predicts
only (x̂ = x⁻, P = P⁻), NIS, MTF ratio, score and measurement are logged as
NaN, the filtered score s̄ and ε are held (no score, so no update of Eqs.
24–26), and the re-solves go on from the predicted estimate.

Each row also logs the normalised estimation error squared (NEES,
Bar-Shalom, Li & Kirubarajan 2001, *Estimation with Applications to
Tracking and Navigation*, §5.4.2) ``(x̂ − x)ᵀ P⁻¹ (x̂ − x)`` of the estimate
and covariance the row holds (the posterior; the prior on a dropout row)
against the true state: χ² with 6 degrees of freedom, mean 6, for a
consistent filter. One 6×6 Cholesky solve per step (:func:`nees`).

With the shooting method the whole run is compiled (:func:`resolve_loop`,
issue 17): at each step with a re-solve due, right after its ε update, the
warm attempt of the re-solve runs here (the switching-time Newton and dual
ascent of :mod:`cwrend_cli.physics.guidance._switching_kernels`), and a
successful one sets the costate; the first that does not succeed returns
to the Python driver, which ends it (fallback chain) and calls again. The
cone-program method uses :func:`advance`, which stops right after the ε
update of a step that has a re-solve due; the Python driver re-solves and
sets the costate. The inputs are a few typed
tuples (numba compiles NamedTuples of floats and arrays): the constant
:class:`LoopModel`, :class:`~cwrend_cli.physics.truth.TruthModel`,
:class:`~cwrend_cli.physics.actuator.ActuatorModel` and
:class:`ScheduleParams`, the :class:`LoopState` arrays
it updates in place, the :class:`LoopScalars` it returns, and the
:class:`StepLog` it fills. Units: km, s, km/s, km/s².
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit, typeof, types
from numba._dispatcher import compute_fingerprint

from cwrend_cli.physics import _calls
from cwrend_cli.physics._clock import monotonic_s
from cwrend_cli.physics.actuator import ActuatorModel, actuate
from cwrend_cli.physics.dynamics import zoh_step
from cwrend_cli.physics.ekf import EkfModel, ekf_predict
from cwrend_cli.physics.estimation import kf_predict, kf_update
from cwrend_cli.physics.guidance._kernels import (
    EPS_BANG_BANG,
    MAX_QUAD_BREAKS,
    STATUS_CONVERGED,
    WS_LAM_T,
    WS_SWITCHES,
    Workspace,
    arc_bounds,
    control_from_costate,
    copy_into,
    copy_matrix_into,
    costate_at,
    model_costate_stm,
    n_cells,
    quadrature_breaks,
    workspace,
)
from cwrend_cli.physics.guidance._switching_kernels import bang_bang_ascent
from cwrend_cli.physics.lti_kernels import KernelModel
from cwrend_cli.physics.measurement_models import SensorModel, measure_truth, sensor_update
from cwrend_cli.physics.process_noise import ProcessNoiseModel, adapt, step_q
from cwrend_cli.physics.scheduling import composite_score, eps_blend, eps_target, lowpass_score
from cwrend_cli.physics.truth import TRUTH_CW, TruthModel, truth_step


class LoopModel(NamedTuple):
    """What the step loop holds constant over a run."""

    phi: np.ndarray  # (6, 6) Φ(Δt) = e^{AΔt} of CW (the CW truth's step)
    gam: np.ndarray  # (6, 3) Γ(Δt) = ∫₀^Δt e^{Aτ}B dτ of CW
    lam_step: np.ndarray  # (6, 6) costate propagation e^{−AᵀΔt}
    q: np.ndarray  # (6, 6) process-noise covariance Q
    r_nominal: np.ndarray  # (3, 3) nominal measurement covariance R [km²]
    noise: np.ndarray  # (N, 3) measurement noise of each step [km]
    n: KernelModel  # mean motion [rad/s] (CW), or the ss model's LtiKernel tuple (issue 33)
    u_max: float  # [km/s²]
    dt: float  # step Δt [s]
    gl_x: np.ndarray  # Gauss–Legendre nodes on [−1, 1] (step-mean control)
    gl_w: np.ndarray  # and weights
    estimator: int  # estimation.PLAIN, MTF (paper Eqs. 16–19) or STF (single factor)
    adaptive: bool  # ε from the innovation score (paper Eqs. 24–26), else held
    hold_mean: bool  # control averaged over the step, else sampled at its start
    u_override: np.ndarray  # (N, 3) controls held instead of the plan where ``override``
    override: np.ndarray  # (N,) bool
    dropout: np.ndarray  # (N,) bool: no measurement at t_{k+1} (predict only)
    filter_phi: np.ndarray  # (N, 6, 6) Φ_k of the filter's design model (issue 33)
    filter_gam: np.ndarray  # (N, 6, 3) Γ_k of the filter's design model


class ScheduleParams(NamedTuple):
    """The homotopy schedule of paper Eqs. 24–26."""

    nis_offset: float  # m
    kappa_mtf: float  # κ_MTF
    score_max: float
    score_lowpass: float  # ρ_s
    eps_min: float
    eps_max: float
    beta: float  # β
    deadband: float
    eps_saturation: float  # NaN: no saturation
    alpha_eps: float  # α_ε


class LoopState(NamedTuple):
    """The arrays the loop updates in place."""

    x_true: np.ndarray  # (6,) true state
    x_hat: np.ndarray  # (6,) estimate
    p: np.ndarray  # (6, 6) estimate covariance
    lam: np.ndarray  # (6,) costate of the current plan
    chief: np.ndarray  # (6,) the truth's chief state (truth.initial_chief; unused for CW)


class LoopScalars(NamedTuple):
    """The scalar loop state, returned by :func:`advance`."""

    eps: float  # ε applied from the next step on
    score_filtered: float  # s̄
    first: bool  # no measurement processed yet (the low-pass starts at s̄ = s)


class StepLog(NamedTuple):
    """Per-step histories; row k + 1 receives the results of step k."""

    x: np.ndarray  # (N+1, 6) true state
    x_hat: np.ndarray  # (N+1, 6)
    u: np.ndarray  # (N+1, 3) control applied (actuated) over [t_k, t_{k+1}) (row k)
    u_cmd: np.ndarray  # (N+1, 3) control commanded at t_k (row k): what the filter uses
    y: np.ndarray  # (N+1, 3) measurement (NaN on a dropout)
    nis: np.ndarray  # (N+1,) (NaN on a dropout)
    mtf_ratio: np.ndarray  # (N+1,) (NaN on a dropout)
    score: np.ndarray  # (N+1,) (NaN on a dropout)
    score_filtered: np.ndarray  # (N+1,) (held on a dropout; NaN before any measurement)
    eps: np.ndarray  # (N+1,)
    trace_p: np.ndarray  # (N+1,)
    nees: np.ndarray  # (N+1,) (x̂ − x)ᵀ P⁻¹ (x̂ − x) of the row's estimate and covariance
    trace_q: np.ndarray  # (N+1,) tr Q_k of the prediction into the row (NaN in row 0)


@njit(cache=True)
def nees(p: np.ndarray, x_hat: np.ndarray, x_true: np.ndarray, scratch: np.ndarray) -> float:
    """NEES ``(x̂ − x)ᵀ P⁻¹ (x̂ − x)`` of a 6-state estimate, by a Cholesky solve of ``P``.

    ``P = L Lᵀ`` and NEES = ‖z‖² with ``L z = x̂ − x``; ``L`` is built in
    ``scratch[:, :6]`` and ``z`` in ``scratch[:, 6]`` (``scratch`` (6, 7):
    nothing allocated). NaN when ``P`` is not positive definite.
    """
    for i in range(6):
        for j in range(i + 1):
            acc = p[i, j]
            for m in range(j):
                acc -= scratch[i, m] * scratch[j, m]
            if i == j:
                if not acc > 0.0:
                    return np.nan
                scratch[i, i] = np.sqrt(acc)
            else:
                scratch[i, j] = acc / scratch[j, j]
    total = 0.0
    for i in range(6):
        acc = x_hat[i] - x_true[i]
        for m in range(i):
            acc -= scratch[i, m] * scratch[m, 6]
        z = acc / scratch[i, i]
        scratch[i, 6] = z
        total += z * z
    return total


@njit(cache=True)
def mean_control(
    n: KernelModel,
    lam: np.ndarray,
    dt: float,
    eps: float,
    u_max: float,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    ws: Workspace,
    out: np.ndarray,
) -> None:
    """Plan's control averaged over ``[0, dt]`` from costate ``lam`` (``guidance.hold = "mean"``).

    Integrated exactly arc by arc between switching times, so its norm never
    exceeds ``u_max``.
    """
    breaks = np.empty(MAX_QUAD_BREAKS)
    one_cell = int(np.int64(1))  # a runtime int, not a literal (guidance._kernels' docstring)
    _, n_breaks = quadrature_breaks(n, lam, 0.0, dt, eps, one_cell, ws[WS_SWITCHES], breaks, ws)
    lam_t = ws[WS_LAM_T, :6]
    u = np.empty(3)
    acc0 = 0.0
    acc1 = 0.0
    acc2 = 0.0
    for arc in range(n_breaks + 1):
        a, b = arc_bounds(arc, n_breaks, breaks, 0.0, dt)
        if b <= a:
            continue
        half = 0.5 * (b - a)
        mid = 0.5 * (a + b)
        for k in range(gl_x.shape[0]):
            costate_at(n, mid + half * gl_x[k], lam, lam_t)
            control_from_costate(lam_t[3:6], eps, u_max, u)
            wk = half * gl_w[k]
            acc0 += wk * u[0]
            acc1 += wk * u[1]
            acc2 += wk * u[2]
    out[0] = acc0 / dt
    out[1] = acc1 / dt
    out[2] = acc2 / dt


def advance(
    k_start: int,
    k_stop: int,
    n_steps: int,
    model: LoopModel,
    truth: TruthModel,
    act: ActuatorModel,
    sched: ScheduleParams,
    state: LoopState,
    scalars: LoopScalars,
    log: StepLog,
    sensor: SensorModel | None = None,
    ekf: EkfModel | None = None,
    pn: ProcessNoiseModel | None = None,
) -> LoopScalars:
    """Run steps ``k_start … k_stop``; the last one stops before its costate propagation.

    When ``k_stop == n_steps`` every step up to the end runs in full. The
    arrays of ``state`` are updated in place and row ``k + 1`` of ``log``
    receives step k's results; the scalar state after the last step run is
    returned.

    The typed tuples cross into compiled code as plain tuples and are named
    again inside (:func:`_advance`): numba resolves a NamedTuple argument
    about seven times slower than a plain tuple (measured: 4.0 against 0.6 µs
    per call with two small tuples), and this is called once per re-solve.
    The CW truth and the ideal actuator cross as ``None`` (:func:`_optional`),
    and so does the position sensor (``sensor`` None: the paper's measurement,
    compiled without the extended update; a nonlinear sensor of issue 35 is a
    :class:`~cwrend_cli.physics.measurement_models.SensorModel`), and so do a
    linear filter (``ekf`` None: :func:`_optional_ekf`), the fixed process noise
    ``pn`` (``None``: ``model.q`` at every step; else
    :mod:`cwrend_cli.physics.process_noise`) and the sample hold
    (:func:`_optional_hold`).
    """
    out = _advance(
        *_advance_args(k_start, k_stop, n_steps, model, truth, act, sched, state, scalars, log,
                       sensor, ekf, pn)
    )  # fmt: skip
    return LoopScalars(*out)


def _advance_args(
    k_start: int,
    k_stop: int,
    n_steps: int,
    model: LoopModel,
    truth: TruthModel,
    act: ActuatorModel,
    sched: ScheduleParams,
    state: LoopState,
    scalars: LoopScalars,
    log: StepLog,
    sensor: SensorModel | None,
    ekf: EkfModel | None,
    pn: ProcessNoiseModel | None,
) -> tuple[Any, ...]:
    """The arguments :func:`advance` hands :func:`_advance` (plain tuples, optional parts)."""
    return (
        k_start, k_stop, n_steps, tuple(model), *_optional(truth, act), tuple(sched),
        tuple(state), tuple(scalars), tuple(log), _optional_hold(model),
        None if sensor is None else tuple(sensor), _optional_ekf(ekf), _optional_noise(pn),
    )  # fmt: skip


def loop_signature(
    socp: bool,
    n_steps: int,
    model: LoopModel,
    truth: TruthModel,
    act: ActuatorModel,
    sched: ScheduleParams,
    state: LoopState,
    scalars: LoopScalars,
    log: StepLog,
    sensor: SensorModel | None = None,
    ekf: EkfModel | None = None,
    pn: ProcessNoiseModel | None = None,
) -> tuple[Any, tuple[types.Type, ...]]:
    """The step loop's entry point for these parts and the argument types it compiles for.

    :func:`_advance` as :func:`advance` calls it (``socp``: the cone program's
    loop), else :func:`_steps` as :func:`compile_steps` compiles it. Each
    choice of truth, actuator, sensor, filter, process noise, hold and design
    model is its own specialisation, compiled on its first run: what the
    first-run notice asks numba's cache about
    (:func:`cwrend_cli.physics.compiled.loop_cached`).
    """
    if socp:
        args = _advance_args(0, -1, n_steps, model, truth, act, sched, state, scalars, log,
                             sensor, ekf, pn)  # fmt: skip
        return _advance, tuple(typeof(a) for a in args)  # type: ignore[no-untyped-call]
    return _steps, _steps_types(model, truth, act, sched, state, log, sensor, ekf, pn)


def _optional(
    truth: TruthModel, act: ActuatorModel
) -> tuple[tuple[Any, ...] | None, tuple[Any, ...] | None]:
    """The truth and actuator as the compiled loop takes them: ``None`` for the CW truth
    and for the ideal actuator, else their plain tuples.

    With a ``None`` argument numba prunes the branch that uses the model before
    typing it (``if truth is None`` in :func:`_steps`), so a run with the CW truth
    and the ideal actuator (the paper's) never compiles the nonlinear truth's
    RK8 step nor the actuator's errors (issue 37 item 12: the compiled loop's
    first compile took 13.6 CPU s with them, 8.7 s without). A run that uses
    them compiles its own specialisation of the loop, with the same arithmetic.
    """
    return (
        None if truth.kind == TRUTH_CW else tuple(truth),
        None if act.ideal else tuple(act),
    )


def _optional_ekf(ekf: EkfModel | None) -> tuple[tuple[Any, ...], np.ndarray] | None:
    """The extended Kalman filter as the compiled loop takes it: ``None`` for a linear
    filter (the branch is pruned, as :func:`_optional`'s: the default loop compiles as
    before), else its dynamics' plain tuple and its chief table."""
    return None if ekf is None else (tuple(ekf.tm), ekf.chief)


def _optional_hold(model: LoopModel) -> bool | None:
    """The step-mean control as the compiled loop takes it: ``None`` for the sample hold.

    As :func:`_optional`: with ``None`` numba prunes the step-mean branch of
    :func:`_steps`, so a loop that samples the control (``guidance.hold =
    "sample"``, the paper's) never compiles :func:`mean_control` and the
    switching-time search below it (issue 37 item 12); ``True`` for the mean hold.
    """
    return True if model.hold_mean else None


def _optional_noise(pn: ProcessNoiseModel | None) -> tuple[Any, ...] | None:
    """The process noise as the compiled loop takes it: ``None`` when fixed (``model.q``).

    As :func:`_optional`: with ``None`` numba prunes the process-noise branches of
    :func:`_steps`, so the fixed runs compile and compute what they always did.
    """
    return None if pn is None else tuple(pn)


def compile_steps(
    model: LoopModel,
    truth: TruthModel,
    act: ActuatorModel,
    sched: ScheduleParams,
    state: LoopState,
    log: StepLog,
    sensor: SensorModel | None = None,
    ekf: EkfModel | None = None,
    pn: ProcessNoiseModel | None = None,
) -> None:
    """Compile (or load) :func:`_steps` for these parts as :func:`resolve_loop` calls it.

    Runs no step: the argument types :func:`_resolve_loop` hands it
    (:func:`_steps_types`). A campaign's first run compiles this in a pool
    worker while the campaign process compiles the re-solves (issue 37 item
    12); the runs then load it from numba's cache instead of compiling it again.
    """
    _steps.compile(_steps_types(model, truth, act, sched, state, log, sensor, ekf, pn))


def _steps_types(
    model: LoopModel,
    truth: TruthModel,
    act: ActuatorModel,
    sched: ScheduleParams,
    state: LoopState,
    log: StepLog,
    sensor: SensorModel | None,
    ekf: EkfModel | None,
    pn: ProcessNoiseModel | None,
) -> tuple[types.Type, ...]:
    """The numba types of :func:`_steps`' arguments as :func:`_resolve_loop` calls it.

    The typed tuples as :func:`_resolve_loop` names them again; the CW truth,
    the ideal actuator, the sample hold, the position sensor, a linear filter
    and a fixed process noise as ``None`` (:func:`_optional`,
    :func:`_optional_hold`, :func:`_optional_ekf`, :func:`_optional_noise`).
    """
    truth_t, act_t = _optional(truth, act)
    models = (None if truth_t is None else truth, None if act_t is None else act)
    # ``None if t is None else Model(*t)`` types as an optional Model when ``t`` is a tuple
    chosen = tuple(
        types.none if m is None else types.Optional(typeof(m))  # type: ignore[no-untyped-call]
        for m in (*models, sensor, ekf, pn)
    )
    plain = tuple(typeof(a) for a in (0, 0, 0, model, sched, state, 0.0, 0.0, True, log))  # type: ignore[no-untyped-call]
    hold = types.none if _optional_hold(model) is None else types.boolean
    return (*plain[:4], *chosen[:2], *plain[4:], hold, *chosen[2:])


@njit(cache=True)
def _advance(
    k_start: int,
    k_stop: int,
    n_steps: int,
    model_t: tuple[Any, ...],
    truth_t: tuple[Any, ...] | None,
    act_t: tuple[Any, ...] | None,
    sched_t: tuple[Any, ...],
    state_t: tuple[Any, ...],
    scalars_t: tuple[Any, ...],
    log_t: tuple[Any, ...],
    mean_hold: bool | None,
    sensor_t: tuple[Any, ...] | None,
    ekf_t: tuple[tuple[Any, ...], np.ndarray] | None,
    pn_t: tuple[Any, ...] | None,
) -> tuple[float, float, bool]:
    """:func:`advance` on the plain tuples of its typed arguments."""
    scalars = LoopScalars(*scalars_t)
    truth = None if truth_t is None else TruthModel(*truth_t)
    act = None if act_t is None else ActuatorModel(*act_t)
    sensor = None if sensor_t is None else SensorModel(*sensor_t)
    ekf = None if ekf_t is None else EkfModel(TruthModel(*ekf_t[0]), ekf_t[1])
    pn = None if pn_t is None else ProcessNoiseModel(*pn_t)
    return _steps(
        k_start, k_stop, n_steps, LoopModel(*model_t), truth, act, ScheduleParams(*sched_t),
        LoopState(*state_t), scalars.eps, scalars.score_filtered, scalars.first, StepLog(*log_t),
        mean_hold, sensor, ekf, pn,
    )  # fmt: skip


@njit(cache=True)
def _steps(
    k_start: int,
    k_stop: int,
    n_steps: int,
    model: LoopModel,
    truth: TruthModel | None,
    act: ActuatorModel | None,
    sched: ScheduleParams,
    state: LoopState,
    eps: float,
    sbar: float,
    first: bool,
    log: StepLog,
    mean_hold: bool | None,
    sensor: SensorModel | None,
    ekf: EkfModel | None,
    pn: ProcessNoiseModel | None,
) -> tuple[float, float, bool]:
    """The steps of :func:`advance` from the scalar state ``(ε, s̄, first)``; returns the new one.

    ``truth`` ``None``: the CW truth; ``act`` ``None``: the ideal actuator
    (:func:`_optional`); ``mean_hold`` ``None``: the control sampled at the
    step's start, else averaged over the step (:func:`_optional_hold`);
    ``sensor`` ``None``: the position sensor (paper
    Eq. 13), else a nonlinear sensor measured and updated by the extended
    filter (:mod:`cwrend_cli.physics.measurement_models`; ``log.y`` then holds
    its m components in its own units, NaN after them); ``ekf`` ``None``: the
    linear filter of ``m.filter_phi`` (:func:`_optional_ekf`); ``pn`` ``None``: the
    fixed process noise ``model.q`` (:func:`_optional_noise`). Arrays are
    copied element by element (:func:`~cwrend_cli.physics.guidance._kernels.copy_into`):
    a slice assignment would compile numba's shape-mismatch message into the loop.
    """
    m = model
    ws = workspace()
    u = np.empty(3)
    u_applied = np.empty(3)
    lam_next = np.empty(6)
    chol = np.empty((6, 7))  # nees() scratch
    x_true, x_hat, p, lam = state.x_true, state.x_hat, state.p, state.lam
    for k in range(k_start, min(k_stop + 1, n_steps)):
        eps_k = eps
        # control from the current costate and ε (Eqs. 8–10), held over the step
        if m.override[k]:
            copy_into(m.u_override[k], u)
        elif mean_hold is not None:
            mean_control(m.n, lam, m.dt, eps_k, m.u_max, m.gl_x, m.gl_w, ws, u)
        else:
            control_from_costate(lam[3:6], eps_k, m.u_max, u)
        copy_into(u, log.u_cmd[k])
        # the actuator: what the truth receives (the command delayed by act.delay steps,
        # then its errors); an ideal actuator applies the command itself
        if act is None:
            copy_into(u, u_applied)
        elif k >= act.delay:
            actuate(act, k, log.u_cmd[k - act.delay], u_applied)
        else:
            u_applied[:] = 0.0
        copy_into(u_applied, log.u[k])
        # truth step with zero-order hold: CW x_{k+1} = Φ x_k + Γ u_k (exact), or the
        # nonlinear truth integrated over the step (truth.py)
        if truth is None:
            x_next = zoh_step(m.phi, m.gam, x_true, u_applied)
        else:
            x_next = truth_step(truth, state.chief, x_true, u_applied)
        copy_into(x_next, x_true)
        # measurement of the new position with the noise of the window at t_k
        if sensor is None:  # noqa: SIM108 (an if statement: numba prunes the untaken branch)
            y = x_next[:3] + m.noise[k]
        else:
            y = measure_truth(sensor, k, x_next)
        # Kalman filter predict (with the commanded control: the filter does not
        # know the actuator errors) and update (Eqs. 11–23); or the extended Kalman
        # filter's predict through the nonlinear dynamics (physics.ekf); its process
        # noise: Q, or Q_k from the actuator or the adaptive estimate (issue 33)
        q_k = m.q if pn is None else step_q(pn, act, k, log.u_cmd, m.filter_gam[k])
        if ekf is None:
            x_pred, p_pred = kf_predict(x_hat, p, m.filter_phi[k], m.filter_gam[k], u, q_k)
        else:
            x_pred, p_pred = ekf_predict(ekf, k, x_hat, p, u, q_k)
        log.trace_q[k + 1] = (
            q_k[0, 0] + q_k[1, 1] + q_k[2, 2] + q_k[3, 3] + q_k[4, 4] + q_k[5, 5]
        )  # fmt: skip
        if m.dropout[k]:
            # no measurement: predict only; no NIS, MTF or score; s̄ and ε held
            copy_into(x_pred, x_hat)
            copy_matrix_into(p_pred, p)
            row = k + 1
            copy_into(x_next, log.x[row])
            copy_into(x_pred, log.x_hat[row])
            log.y[row] = np.nan
            log.nis[row] = np.nan
            log.mtf_ratio[row] = np.nan
            log.score[row] = np.nan
            log.score_filtered[row] = np.nan if first else sbar
            log.eps[row] = eps
            log.trace_p[row] = (
                p_pred[0, 0] + p_pred[1, 1] + p_pred[2, 2]
                + p_pred[3, 3] + p_pred[4, 4] + p_pred[5, 5]
            )  # fmt: skip
            log.nees[row] = nees(p_pred, x_pred, x_next, chol)
            if k == k_stop:
                break  # the caller re-solves and sets the costate
            _propagate_costate(m.lam_step, lam, lam_next)
            continue
        if sensor is None:
            x_post, p_post, nis, rho = kf_update(x_pred, p_pred, y, m.r_nominal, m.estimator)
        else:
            x_post, p_post, nis, rho = sensor_update(sensor, x_pred, p_pred, y, m.estimator)
        copy_into(x_post, x_hat)
        copy_matrix_into(p_post, p)
        if pn is not None:
            adapt(pn, m.filter_gam[k], x_pred, x_post, p_pred, p_post, q_k)
        # score and homotopy parameter (Eqs. 24–26)
        score = composite_score(nis, rho, sched.nis_offset, sched.kappa_mtf, sched.score_max)
        sbar = lowpass_score(sbar, score, sched.score_lowpass, first)
        first = False
        if m.adaptive:
            target = eps_target(
                sbar,
                sched.eps_min,
                sched.eps_max,
                sched.beta,
                sched.deadband,
                sched.eps_saturation,
            )
            eps = eps_blend(eps_k, target, sched.alpha_eps)
        row = k + 1
        copy_into(x_next, log.x[row])
        copy_into(x_post, log.x_hat[row])
        copy_into(y, log.y[row])
        log.nis[row] = nis
        log.mtf_ratio[row] = rho
        log.score[row] = score
        log.score_filtered[row] = sbar
        log.eps[row] = eps
        log.trace_p[row] = (
            p_post[0, 0] + p_post[1, 1] + p_post[2, 2] + p_post[3, 3] + p_post[4, 4] + p_post[5, 5]
        )
        log.nees[row] = nees(p_post, x_post, x_next, chol)
        if k == k_stop:
            break  # the caller re-solves and sets the costate
        _propagate_costate(m.lam_step, lam, lam_next)
    return eps, sbar, first


@njit(cache=True)
def _propagate_costate(lam_step: np.ndarray, lam: np.ndarray, scratch: np.ndarray) -> None:
    """The costate propagated exactly by one step, in place: λ ← e^{−AᵀΔt} λ."""
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += lam_step[i, j] * lam[j]
        scratch[i] = acc
    copy_into(scratch, lam)


# ---------------------------------------------------------------------------
# The shooting re-solves inside the compiled loop (issue 17)
# ---------------------------------------------------------------------------


class ResolveModel(NamedTuple):
    """What the compiled shooting re-solves of a run hold constant."""

    steps: np.ndarray  # (R,) int64: the steps k with a re-solve due (simulation.resolve_steps)
    xf: np.ndarray  # (6,) target state [km, km/s]
    horizon_s: float  # the scenario's horizon T [s]
    correct: bool  # guidance.resolve_timing = "correct" (else "reference")
    success_residual: float  # a re-solve succeeds below this terminal residual [km] (cwrend's)
    newton: tuple[Any, ...]  # the fields of the solver's NewtonSettings
    switching_max_iter: int  # steps of the switching-time Newton at ε = 0
    stop_every: bool  # return after every warm attempt (a re-solve observer is watching)


class ResolveCarry(NamedTuple):
    """What the re-solves hand on, updated in place."""

    older: np.ndarray  # (6,) the costate of the plan before the current one, at step k_older
    k_older: np.ndarray  # (1,) int64: its step; −1 while there is none
    warm: np.ndarray  # (6,) the costate of the last warm attempt (read after a stop)
    starts: np.ndarray  # (2, 6) the warm starts of the last warm attempt, rows 0 … n_starts − 1
    n_starts: np.ndarray  # (1,) int64


class SolveLog(NamedTuple):
    """One row per scheduled re-solve (row i: ``ResolveModel.steps[i]``)."""

    t_s: np.ndarray  # (R,) time of the estimate the re-solve starts from [s]
    horizon_s: np.ndarray  # (R,) remaining horizon [s]
    eps: np.ndarray  # (R,) ε of the re-solve
    status: np.ndarray  # (R,) int64: guidance._kernels.STATUS_* of the re-solve
    iterations: np.ndarray  # (R,) int64
    residual_km: np.ndarray  # (R,) hypot(‖Δr(T)‖, ‖Δv(T)‖)
    wall_time_ms: np.ndarray  # (R,)
    success: np.ndarray  # (R,) bool: converged and residual below success_residual


class LoopParts(NamedTuple):
    """What :func:`resolve_loop` runs: the loop's parts and its re-solves' (see :func:`advance`)."""

    model: LoopModel
    truth: TruthModel
    act: ActuatorModel
    sched: ScheduleParams
    resolve: ResolveModel
    state: LoopState
    scalars: LoopScalars
    carry: ResolveCarry
    log: StepLog
    solves: SolveLog
    sensor: SensorModel | None = None  # None: the position sensor
    ekf: EkfModel | None = None  # None: a linear filter
    pn: ProcessNoiseModel | None = None  # None: the fixed process noise


def resolve_loop(
    i_start: int, k_start: int, n_steps: int, parts: LoopParts
) -> tuple[int, LoopScalars]:
    """Run the loop from step ``k_start`` through the re-solves ``i_start, …`` of
    ``parts.resolve.steps``.

    Each re-solve is its warm attempt (:func:`~cwrend_cli.physics.guidance.
    _switching_kernels.bang_bang_ascent`, from the propagated costate and, at
    ε = 0, the plan before it, as :func:`cwrend_cli.physics.guidance.solve_state`
    starts it), timed (:mod:`cwrend_cli.physics._clock`) and written to row i
    of ``solves``. A successful one becomes the plan, as in the Python loop
    of :func:`cwrend_cli.physics.simulation.simulate`: its costate drives the
    control (held controls cleared), the propagated previous plan becomes
    ``carry.older``. The first re-solve that does not succeed stops the loop
    right after its warm attempt (its costate in ``carry.warm``, its row
    written, the costate not yet set; ``resolve.stop_every``: every re-solve
    stops so): the caller ends it (fallback chain, records) and calls again
    from ``i + 1``. Returns ``(i, scalars)``: the
    index of that re-solve, or ``len(resolve.steps)`` once every re-solve
    succeeded and every step up to the end has run.

    Same conventions as :func:`advance`: the typed tuples cross as plain
    tuples and are named again inside. The step loop and the solver cross as
    handles (:func:`compiled_loop`).
    """
    args = _plain_args(i_start, k_start, n_steps, parts)
    entry, steps, solve = compiled_loop(args, parts)
    i, eps, sbar, first = entry(steps, solve, *args)
    return i, LoopScalars(eps, sbar, first)


def _plain_args(i_start: int, k_start: int, n_steps: int, parts: LoopParts) -> tuple[Any, ...]:
    """:func:`_resolve_loop`'s arguments after its two functions (:func:`advance`'s conventions)."""
    p = parts
    return (
        i_start, k_start, n_steps, tuple(p.model), *_optional(p.truth, p.act), tuple(p.sched),
        tuple(p.resolve), tuple(p.state), tuple(p.scalars), tuple(p.carry), tuple(p.log),
        tuple(p.solves), _optional_hold(p.model), None if p.sensor is None else tuple(p.sensor),
        _optional_ekf(p.ekf), _optional_noise(p.pn),
    )  # fmt: skip


#: The numba types :func:`_steps` and the solver return, as :func:`_resolve_loop` calls them
#: (:mod:`cwrend_cli.physics._calls`): ``(ε, s̄, first)`` and ``(status, iterations, rp, rv)``.
STEPS_RETURN = types.Tuple((types.float64, types.float64, types.boolean))  # type: ignore[no-untyped-call]
SOLVER_RETURN = types.Tuple((types.int64, types.int64, types.float64, types.float64))  # type: ignore[no-untyped-call]

#: The compiled :func:`_resolve_loop` and its callees' handles of each argument fingerprint
#: (:func:`compiled_loop`).
_COMPILED_LOOPS: dict[bytes, tuple[Any, _calls.Handle, _calls.Handle]] = {}


def compiled_loop(
    args: tuple[Any, ...], parts: LoopParts
) -> tuple[Any, _calls.Handle, _calls.Handle]:
    """The compiled :func:`_resolve_loop` for ``args`` (:func:`_plain_args` of these parts),
    with the handles of the step loop and of the solver it takes first.

    Compiled (or loaded) on first use, with the step loop and the solver.
    The compiled loop calls them by their addresses
    (:mod:`cwrend_cli.physics._calls`), so that neither is compiled into it
    (issue 37 item 12: numba links a callee's whole call tree into its
    caller, where LLVM optimises and emits it once more; the loop's top
    carried the step loop and the solver, and compiled only after both).
    Returns ``(entry, steps, solve)``: call ``entry(steps, solve, *args)``.
    Looked up by the arguments' numba fingerprint (numba's own dispatch
    key, about a microsecond): their numba types, in Python, take
    milliseconds, and this is called once per re-solve that ends in Python.
    """
    try:
        key: bytes | None = compute_fingerprint(args)
    except Exception:  # a value numba does not fingerprint: typed below at every call
        key = None
    done = _COMPILED_LOOPS.get(key) if key is not None else None
    if done is not None:
        return done
    steps_t, solver_t = _callee_types(parts)
    entry = _compile_top(args, steps_t, solver_t)
    steps = _calls.handle(_steps, steps_t, STEPS_RETURN)
    solve = _calls.handle(bang_bang_ascent, solver_t, SOLVER_RETURN)
    if key is not None:
        _COMPILED_LOOPS[key] = (entry, steps, solve)
    return entry, steps, solve


def compile_resolve_loop(n_steps: int, parts: LoopParts) -> None:
    """Compile (or load) :func:`_resolve_loop` for these parts as :func:`resolve_loop` calls it.

    Runs nothing, and compiles neither the step loop nor the solver
    (:func:`compiled_loop`): a campaign's first run compiles it in a second
    process while the campaign process compiles the solver (issue 37 item 12).
    """
    _compile_top(_plain_args(0, 0, n_steps, parts), *_callee_types(parts))


def _compile_top(
    args: tuple[Any, ...], steps_t: tuple[types.Type, ...], solver_t: tuple[types.Type, ...]
) -> Any:
    """Compile (or load) :func:`_resolve_loop` for ``args`` and callees of these argument
    types; its entry point."""
    sig = (
        _calls.handle_type(steps_t, STEPS_RETURN),
        _calls.handle_type(solver_t, SOLVER_RETURN),
        *(typeof(a) for a in args),  # type: ignore[no-untyped-call]
    )
    return _resolve_loop.compile(sig)


def _callee_types(parts: LoopParts) -> tuple[tuple[types.Type, ...], tuple[types.Type, ...]]:
    """The numba types of the arguments of :func:`_steps` and of the solver as
    :func:`_resolve_loop` calls them."""
    p = parts
    steps_t = _steps_types(p.model, p.truth, p.act, p.sched, p.state, p.log, p.sensor, p.ekf, p.pn)
    return steps_t, _solver_types(p.model, p.resolve, p.state, p.carry)


def _solver_types(
    model: LoopModel, resolve: ResolveModel, state: LoopState, carry: ResolveCarry
) -> tuple[types.Type, ...]:
    """The numba types of the solver's arguments as :func:`_resolve_loop` calls it."""
    f, i = types.float64, types.int64
    vec = (typeof(state.x_hat), typeof(resolve.xf))  # type: ignore[no-untyped-call]
    nodes = (typeof(model.gl_x), typeof(model.gl_w))  # type: ignore[no-untyped-call]
    settings = typeof(resolve.newton)  # type: ignore[no-untyped-call]
    n, warm = typeof(model.n), typeof(carry.warm)  # type: ignore[no-untyped-call]
    return (n, *vec, f, f, typeof(model.u_max), types.float64[:, ::1], *nodes, i, settings, i, warm)  # type: ignore[no-untyped-call]


@njit(cache=True)
def _resolve_loop(
    steps: Any,
    solve: Any,
    i_start: int,
    k_start: int,
    n_steps: int,
    model_t: tuple[Any, ...],
    truth_t: tuple[Any, ...] | None,
    act_t: tuple[Any, ...] | None,
    sched_t: tuple[Any, ...],
    resolve_t: tuple[Any, ...],
    state_t: tuple[Any, ...],
    scalars_t: tuple[Any, ...],
    carry_t: tuple[Any, ...],
    log_t: tuple[Any, ...],
    solves_t: tuple[Any, ...],
    mean_hold: bool | None,
    sensor_t: tuple[Any, ...] | None,
    ekf_t: tuple[tuple[Any, ...], np.ndarray] | None,
    pn_t: tuple[Any, ...] | None,
) -> tuple[int, float, float, bool]:
    """:func:`resolve_loop` on the plain tuples of its typed arguments; ``steps``:
    :func:`_steps`, ``solve``: the solver, as handles (:func:`compiled_loop`)."""
    m = LoopModel(*model_t)
    truth = None if truth_t is None else TruthModel(*truth_t)
    act = None if act_t is None else ActuatorModel(*act_t)
    sched = ScheduleParams(*sched_t)
    rs = ResolveModel(*resolve_t)
    state = LoopState(*state_t)
    scalars = LoopScalars(*scalars_t)
    carry = ResolveCarry(*carry_t)
    log = StepLog(*log_t)
    solves = SolveLog(*solves_t)
    sensor = None if sensor_t is None else SensorModel(*sensor_t)
    ekf = None if ekf_t is None else EkfModel(TruthModel(*ekf_t[0]), ekf_t[1])
    pn = None if pn_t is None else ProcessNoiseModel(*pn_t)
    eps, sbar, first = scalars.eps, scalars.score_filtered, scalars.first
    lam = state.lam
    k_next = k_start
    n_resolves = rs.steps.shape[0]
    for i in range(i_start, n_resolves):
        k = rs.steps[i]
        eps, sbar, first = _calls.call(  # type: ignore[call-arg]
            steps,
            (k_next, k, n_steps, m, truth, act, sched, state, eps, sbar, first, log,
             mean_hold, sensor, ekf, pn),
        )  # fmt: skip
        k_next = k + 1
        k_from = k + 1 if rs.correct else k
        horizon = rs.horizon_s - k_from * m.dt
        # the warm starts of shooting.warm_starts: np.dot, as numpy's @ in the Python loop
        lam_next = np.dot(m.lam_step, lam)
        with_older = eps < EPS_BANG_BANG and carry.k_older[0] >= 0
        starts = np.empty((2 if with_older else 1, 6))
        copy_into(lam_next if rs.correct else lam, starts[0])
        if with_older:
            back = model_costate_stm(m.n, (k_from - carry.k_older[0]) * m.dt)
            copy_into(np.dot(back, carry.older), starts[1])
        t0 = monotonic_s()
        status, iters, rp, rv = _calls.call(
            solve,
            (m.n, state.x_hat, rs.xf, horizon, eps, m.u_max, starts, m.gl_x, m.gl_w,
             n_cells(horizon), rs.newton, rs.switching_max_iter, carry.warm),
        )  # fmt: skip
        wall = monotonic_s() - t0
        residual = np.hypot(rp, rv)
        copy_matrix_into(starts, carry.starts[: starts.shape[0]])
        carry.n_starts[0] = starts.shape[0]
        ok = status == STATUS_CONVERGED and residual < rs.success_residual and not rs.stop_every
        solves.t_s[i] = (k + 1) * m.dt
        solves.horizon_s[i] = horizon
        solves.eps[i] = eps
        solves.status[i] = status
        solves.iterations[i] = iters
        solves.residual_km[i] = residual
        solves.wall_time_ms[i] = wall * 1e3
        solves.success[i] = ok
        if not ok:
            return i, eps, sbar, first  # the caller ends this re-solve
        copy_into(lam_next, carry.older)
        carry.k_older[0] = k + 1
        if rs.correct:
            copy_into(carry.warm, lam)
        else:
            copy_into(np.dot(m.lam_step, carry.warm), lam)
        m.override[k + 1 :] = False  # a costate plan: no held controls from here on
    eps, sbar, first = _calls.call(  # type: ignore[call-arg]
        steps,
        (k_next, n_steps, n_steps, m, truth, act, sched, state, eps, sbar, first, log,
         mean_hold, sensor, ekf, pn),
    )  # fmt: skip
    return n_resolves, eps, sbar, first
