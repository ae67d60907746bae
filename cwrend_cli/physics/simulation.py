"""Closed-loop receding-horizon simulation of one architecture.

Paper Eqs. 11–26 and Sec. "Receding-Horizon Indirect Guidance".

An architecture is estimator {plain, MTF, single-factor STF} × schedule
{fixed, adaptive}: the same loop with two switches. The loop runs compiled
(:mod:`cwrend_cli.physics._loop_kernels`): with the shooting method, its
re-solves too, each the warm attempt of
:func:`cwrend_cli.physics.guidance.solve_state`; only a re-solve whose warm
attempt does not succeed comes back here to end (the fallback chain,
minimum-miss controls; :func:`_shooting_resolves`). The cone-program method
re-solves here between compiled stretches of steps (:func:`_cone_resolves`).
Nothing here writes files: the result is a plain :class:`RunResult` that
:mod:`cwrend_cli.output.tables` and the recorders consume.

The true state obeys ``problem.truth`` (:mod:`cwrend_cli.physics.truth`:
CW, exact two-body or two-body + J2 relative motion); the filter and the
guidance use the design models of ``problem.model`` (CW by default;
:mod:`cwrend_cli.physics.design_models`), or for the filter an extended
Kalman filter on the nonlinear dynamics (:mod:`cwrend_cli.physics.ekf`).
The truth receives the control the actuator applies (``problem.actuator``,
:mod:`cwrend_cli.physics.actuator`: scale error, noise, misalignment, minimum
thrust, delay); the filter predicts with the commanded control, which it
knows, not the errors. The per-step
actuator noise enters as draws (:class:`~cwrend_cli.physics.actuator.ActuatorDraws`)
made by the caller, like the measurement noise, so nothing here is random.
So are the draws of the sensor faults of the degradation windows
(:class:`~cwrend_cli.physics.sensors.FaultDraws`: dropouts, outliers, a
drifting bias; :func:`cwrend_cli.physics.sensors.sensor_noise`). A dropout
step has no measurement: the filter predicts only, its NIS, MTF ratio, score
and measurement are NaN and the filtered score and ε are held
(:mod:`cwrend_cli.physics._loop_kernels`).

Re-solve timing (``guidance.resolve_timing``):

* ``"correct"`` (default): the re-solve of step k starts from the estimate at
  t_{k+1} with the remaining horizon ``T − t_{k+1}``, and the costate is used
  as solved for the control at t_{k+1}.
* ``"reference"``: the authors' implementation — same estimate, horizon
  ``T − t_k``, solved costate then propagated by one step (plans to arrive
  about one step late).

Units: km, s, km/s, km/s².
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import pickle
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from cwrend_cli.physics import _loop_kernels as sk
from cwrend_cli.physics import (
    abort_safety,
    actuator,
    attitude,
    design_models,
    ekf,
    guidance,
    measurement_models,
    process_noise,
    references,
    sensors,
    truth,
)
from cwrend_cli.physics import constraints as safety_geometry
from cwrend_cli.physics.dynamics import costate_stm, discretize
from cwrend_cli.physics.estimation import ESTIMATOR_KINDS
from cwrend_cli.physics.guidance import constrained, convex, feasibility
from cwrend_cli.physics.metrics import delta_v
from cwrend_cli.physics.params import (
    Architecture,
    Constraints,
    DesignModelName,
    FloatArray,
    Problem,
    Scenario,
    Schedule,
    Truth,
)


@dataclass(frozen=True)
class SolveRecord:
    """One re-solve of a closed-loop run (a row of ``solves.parquet``)."""

    kind: str  # "initial" (before the loop) or "resolve"
    step: int  # loop step k whose re-solve this is (−1 for the initial solve)
    t_s: float  # time of the estimate the solve starts from
    horizon_s: float
    eps: float
    status: str  # converged / infeasible / failed
    fallback_step: str
    iterations: int
    residual_km: float
    wall_time_ms: float
    success: bool  # converged and residual below solver.success_residual (not in the paper)
    scp_iterations: int = 0  # constrained cone program (issue 32): its convex programs
    slack_km: float = 0.0  # constrained cone program: the path softening it needed [km]
    abort_slack_km: float = 0.0  # … and the abort-safety softening (issue 34 item 4) [km]
    fallback_programs: int = 0  # constrained cone program: programs left to Clarabel


#: A constrained re-solve's figures for its :class:`SolveRecord`: SCP iterations, path
#: slack [km], abort slack [km] and the programs left to Clarabel.
ScpFigures = tuple[int, float, float, int]


@dataclass(frozen=True)
class RunResult:
    """Per-step histories of one closed-loop run; row k is time ``t_s[k]``.

    Row k holds the state at t_k, the control applied over ``[t_k, t_{k+1})``
    (``u``: what the actuator gave the truth; ``u_cmd``: what the guidance
    commanded and the filter used; equal for an ideal actuator; zero in the
    last row), and the quantities of the measurement taken at
    t_k (NaN in row 0, where there is none, and in the rows of a sensor dropout)
    including the ε that results.
    """

    arch: str
    seed: int
    t_s: np.ndarray
    x_true: np.ndarray
    x_hat: np.ndarray
    u: np.ndarray  # applied control (Δv is computed from it)
    y: np.ndarray
    nis: np.ndarray
    mtf_ratio: np.ndarray
    score: np.ndarray
    score_filtered: np.ndarray
    eps: np.ndarray
    trace_p: np.ndarray
    window: np.ndarray  # index of the degradation window that corrupted the measurement, −1 none
    solves: tuple[SolveRecord, ...]
    delta_v_km_s: float  # trapezoid of ‖u‖ (applied) over the grid (not in the paper)
    miss_km: float
    u_cmd: np.ndarray  # commanded control (the filter's input)
    nees: np.ndarray  # (x̂ − x)ᵀ P⁻¹ (x̂ − x): row 0 with P0, then posterior (prior on a dropout)
    dropout: np.ndarray  # bool: the row has no measurement (sensor dropout); False in row 0
    outlier: np.ndarray  # bool: the row's measurement noise was an outlier; False in row 0
    trace_q: np.ndarray  # tr Q_k of the filter's prediction into the row (issue 33); NaN in row 0
    #: safety of the true trajectory (issue 32), only when the problem has constraints
    safety: safety_geometry.Safety | None = None
    #: the tumbling target's attitude over the run (issue 34), only with target.attitude
    #: = "tumbling"; at every step and sub-step (:func:`_target_attitude`)
    target_attitude: attitude.TargetAttitude | None = None
    #: what ``y`` holds (issue 35): "position" [km]; "range_bearing" (range [km], azimuth,
    #: elevation [rad]); "angles" (azimuth, elevation [rad], NaN)
    sensor: str = "position"
    #: abort safety of the true trajectory (issue 34 item 4), only with
    #: constraints.abort_safe_s (:func:`_abort_safety`)
    abort: abort_safety.AbortSafety | None = None

    @property
    def resolves(self) -> tuple[SolveRecord, ...]:
        """The receding-horizon re-solves (without the initial solve)."""
        return tuple(s for s in self.solves if s.kind == "resolve")


@dataclass(frozen=True)
class ResolveInput:
    """What one shooting re-solve of a closed loop started from (for a re-solve observer)."""

    step: int  # loop step k whose re-solve this is
    problem: guidance.ShootingProblem  # from the estimate at its time, the remaining horizon, ε
    guess: FloatArray  # the warm start (the current plan's costate at the re-solve's time)
    alternatives: tuple[FloatArray, ...]  # at ε = 0: the plan before it, propagated (else ())


#: Called with each shooting re-solve's input, before the re-solve ends (instrumentation).
ResolveObserver = Callable[[ResolveInput], None]


@dataclass(frozen=True)
class References:
    """The open-loop references of a scenario."""

    energy: references.OpenLoopResult
    fuel: references.OpenLoopResult


def solver_settings(problem: Problem) -> guidance.SolverSettings:
    """The shooting solver's settings for a closed-loop problem."""
    s = problem.solver
    return guidance.SolverSettings(
        tol_pos_km=s.tol_pos_km,
        tol_vel_km_s=s.tol_vel_km_s,
        max_iter=s.max_iter,
        quadrature_nodes=s.quadrature_nodes,
        fallback=s.fallback,
        success_residual=s.success_residual,
        dt_grid_s=problem.scenario.dt_s,
        switching_max_iter=s.switching_newton_steps,
    )


def _shooting(
    sc: Scenario,
    x0: FloatArray,
    horizon_s: float,
    eps: float,
    design: design_models.LinearTimeInvariant | None = None,
) -> guidance.ShootingProblem:
    """One re-solve of the scenario: reach ``sc.xf`` from ``x0`` in ``horizon_s`` at ``eps``.

    ``design``: the guidance's design model other than CW (:func:`_shooting_design`).
    """
    return guidance.ShootingProblem(
        np.asarray(x0, dtype=float),
        float(horizon_s),
        float(eps),
        sc.mean_motion_rad_s,
        sc.u_max_km_s2,
        np.asarray(sc.xf, dtype=float),
        design,
    )


def _shooting_design(problem: Problem, socp: bool) -> design_models.LinearTimeInvariant | None:
    """The time-invariant design model of the shooting re-solves; None for CW (issue 33).

    ``model.guidance = "ss"`` with the shooting method: Schweighart–Sedwick
    (:func:`~cwrend_cli.physics.design_models.ss_model`). The cone-program method
    plans with the per-step tables instead (:func:`_guidance_tables`), and its
    costate fallback stays CW's as before (``socp``: None).
    """
    if socp or problem.model.guidance != "ss":
        return None
    return design_models.ss_model(problem.truth, problem.scenario)


def open_loop_references(problem: Problem) -> References:
    """Energy- and fuel-optimal open-loop references of the scenario.

    The references of paper Sec. "Numerical Results and Discussion".
    """
    sc = problem.scenario
    t = sc.time_grid()
    first = _shooting(sc, np.asarray(sc.x0), sc.horizon_s, 0.0)
    return References(
        energy=references.energy_optimal(first, t),
        fuel=references.fuel_optimal(first, t, solver_settings(problem)),
    )


def resolve_steps(problem: Problem) -> list[int]:
    """Steps k at which a re-solve is due (t_resolve, t_min,rem of paper Table 1)."""
    sc, gd = problem.scenario, problem.guidance
    every = round(gd.t_resolve_s / sc.dt_s)
    out = []
    for k in range(0, sc.n_steps, every):
        t_from = (k + 1) * sc.dt_s if gd.resolve_timing == "correct" else k * sc.dt_s
        if sc.horizon_s - t_from > gd.t_min_rem_s:
            out.append(k)
    return out


def _record(
    kind: str,
    step: int,
    t_s: float,
    result: guidance.SolveResult,
    threshold: float,
    scp: ScpFigures | None = None,
) -> SolveRecord:
    scp_iterations, slack_km, abort_slack_km, fallback_programs = (
        (0, 0.0, 0.0, 0) if scp is None else scp
    )
    return SolveRecord(
        scp_iterations=scp_iterations,
        slack_km=slack_km,
        abort_slack_km=abort_slack_km,
        fallback_programs=fallback_programs,
        kind=kind,
        step=step,
        t_s=t_s,
        horizon_s=result.horizon_s,
        eps=result.eps,
        status=result.status.value,
        fallback_step=result.step,
        iterations=result.iterations,
        residual_km=result.residual_km,
        wall_time_ms=result.wall_time_s * 1e3,
        success=result.converged and result.residual_km < threshold,
    )


def schedule_params(sch: Schedule) -> sk.ScheduleParams:
    """The schedule as the compiled loop takes it (NaN: no ε saturation)."""
    return sk.ScheduleParams(
        nis_offset=sch.nis_offset,
        kappa_mtf=sch.kappa_mtf,
        score_max=sch.score_max,
        score_lowpass=sch.score_lowpass,
        eps_min=sch.eps_min,
        eps_max=sch.eps_max,
        beta=sch.beta,
        deadband=sch.deadband,
        eps_saturation=np.nan if sch.eps_saturation is None else sch.eps_saturation,
        alpha_eps=sch.alpha_eps,
    )


def _empty_log(rows: int) -> sk.StepLog:
    """Histories of ``rows`` grid times: NaN until written, zero control."""
    return sk.StepLog(
        x=np.full((rows, 6), np.nan),
        x_hat=np.full((rows, 6), np.nan),
        u=np.zeros((rows, 3)),
        u_cmd=np.zeros((rows, 3)),
        y=np.full((rows, 3), np.nan),
        nis=np.full(rows, np.nan),
        mtf_ratio=np.full(rows, np.nan),
        score=np.full(rows, np.nan),
        score_filtered=np.full(rows, np.nan),
        eps=np.full(rows, np.nan),
        trace_p=np.full(rows, np.nan),
        nees=np.full(rows, np.nan),
        trace_q=np.full(rows, np.nan),
    )


def simulate(
    problem: Problem,
    arch: Architecture,
    standard_normal: FloatArray,
    refs: References,
    seed: int = 0,
    actuator_draws: actuator.ActuatorDraws | None = None,
    fault_draws: sensors.FaultDraws | None = None,
    observe: ResolveObserver | None = None,
    attitude_draws: FloatArray | None = None,
    initial_plans: InitialPlans | None = None,
) -> RunResult:
    """Run one closed-loop case of ``arch`` on the noise realisation ``standard_normal`` (N, 3).

    ``actuator_draws``: the standard-normal draws of the per-step actuator
    errors (required when ``problem.actuator`` has per-step noise; ignored
    where its σ is zero). ``fault_draws``: the draws of the degradation
    windows' sensor faults (required for the kinds some window switches on,
    :func:`cwrend_cli.physics.sensors.draw_faults`). ``attitude_draws``: the
    standard normals of the guidance's attitude-knowledge error (a tumbling target
    with ``target.knowledge_sigma_*``; :func:`cwrend_cli.physics.attitude.knowledge_error`):
    6, or (N, 6) with ``target.knowledge_draw = "resolve"`` (row k at step k's re-solve).

    ``initial_plans`` (a campaign worker's): the initial constrained plans already
    made, by their inputs (:func:`_initial_constrained_plan`); the runs of one
    campaign point start from the same estimate, so each worker plans that start
    once (the same plan, bit for bit: it is a function of its inputs).

    ``observe`` (tests, benchmarks): called with the input of every shooting
    re-solve (:class:`ResolveInput`: the problem and the warm starts its warm
    attempt used). Watching changes no number: each re-solve then ends in
    Python instead of compiled code, with the same arithmetic.
    """
    sc, est, sch, gd = problem.scenario, problem.estimator, problem.schedule, problem.guidance
    n, n_steps = sc.mean_motion_rad_s, sc.n_steps
    settings = solver_settings(problem)
    t = sc.time_grid()
    sensor, noise, active, dropout_steps, outlier_steps = _measured(
        problem, standard_normal, fault_draws
    )

    # torque-free, so nothing the chaser does changes it: the whole run's, before the loop
    target_attitude = _target_attitude(problem)
    known = _Knowledge(target_attitude, _knowledge_error(problem, attitude_draws))
    x0 = np.asarray(sc.x0, dtype=float)
    # the filter starts at the true initial state (a convention of cwrend; not in the paper)
    # unless an initial error is set
    x_hat0 = x0 + np.asarray(est.initial_error, dtype=float)
    solves: list[SolveRecord] = []
    socp = arch.resolved_method(gd) == "socp"
    eps0 = sch.eps_max if arch.adaptive else sch.eps_fixed
    design = _shooting_design(problem, socp)
    if arch.adaptive and not socp:
        # initial solve at ε_max from the energy costate; on failure keep it (not in the paper)
        first = _shooting(sc, x_hat0, sc.horizon_s, eps0, design)
        result = guidance.solve(first, refs.energy.costate, settings)
        solves.append(_record("initial", -1, 0.0, result, settings.success_residual))
        lam = result.costate.copy() if solves[-1].success else refs.energy.costate.copy()
    elif design is not None:
        # the references are CW's: the first plan in the guidance's own model, at ε0 from the
        # fuel reference's costate; on failure keep that (issue 33)
        first = _shooting(sc, x_hat0, sc.horizon_s, eps0, design)
        result = guidance.solve(first, refs.fuel.costate, settings)
        solves.append(_record("initial", -1, 0.0, result, settings.success_residual))
        lam = result.costate.copy() if solves[-1].success else refs.fuel.costate.copy()
    else:
        lam = refs.fuel.costate.copy()

    loop = _loop_parts(
        problem, arch, noise, dropout_steps, sensor, x_hat0, lam, eps0, actuator_draws
    )
    model = loop.model
    # the last cone-program plan's costate and its step: the next one's warm start (issue 16)
    plan_costate: FloatArray | None = None
    duals: constrained.Duals | None = None  # the constrained plan's row multipliers
    if socp:  # the cone program's plan from x̂0 at ε0, held until the first re-solve (issue 16)
        scp = _initial_constrained_plan(
            problem, x_hat0, eps0, est.p0_matrix(), known, initial_plans
        )
        if scp is not None:  # a keep-out zone: the constrained cone program (issue 32)
            result, duals = scp[0], scp[2]
        else:
            result = convex.solve(
                _grid(sc, x_hat0, sc.horizon_s, _guidance_condensed(problem)), eps0, n
            )
        solves.append(
            _record("initial", -1, 0.0, result, settings.success_residual, scp and scp[1])
        )
        _hold_plan(result, 0, model)
        if solves[-1].success:
            plan_costate = result.costate
    scalars = sk.LoopScalars(eps=eps0, score_filtered=0.0, first=True)
    log = loop.log

    schedule = resolve_steps(problem)
    if socp:
        solves += _cone_resolves(problem, schedule, loop, scalars, plan_costate, known, duals)
    else:
        solves += _shooting_resolves(problem, settings, schedule, loop, scalars, observe)

    safety = _safety(problem, log.x, target_attitude)
    if safety is not None and safety.rotating and not math.isnan(safety.dock_position_error_km):
        miss = safety.dock_position_error_km  # a tumbling target: the moving port (issue 34)
    else:
        miss = float(np.linalg.norm(log.x[-1, :3] - np.asarray(sc.xf[:3])))
    window = np.full(n_steps + 1, -1, dtype=np.int64)
    window[1:] = active
    dropout = np.concatenate(([False], dropout_steps))
    outlier = np.concatenate(([False], outlier_steps))
    log.nees[0] = sk.nees(est.p0_matrix(), x_hat0, x0, np.empty((6, 7)))
    return RunResult(
        arch=arch.slug,
        seed=seed,
        t_s=t,
        x_true=log.x,
        x_hat=log.x_hat,
        u=log.u,
        y=log.y,
        nis=log.nis,
        mtf_ratio=log.mtf_ratio,
        score=log.score,
        score_filtered=log.score_filtered,
        eps=log.eps,
        trace_p=log.trace_p,
        window=window,
        solves=tuple(solves),
        delta_v_km_s=delta_v(t, log.u),
        miss_km=miss,
        u_cmd=log.u_cmd,
        nees=log.nees,
        dropout=dropout,
        outlier=outlier,
        safety=safety,
        trace_q=log.trace_q,
        target_attitude=target_attitude,
        sensor=problem.sensor.model,
        abort=_abort_safety(problem, log.x, target_attitude is not None),
    )


def _measured(
    problem: Problem, standard_normal: FloatArray, fault_draws: sensors.FaultDraws | None
) -> tuple[
    measurement_models.SensorModel | None,
    FloatArray,
    npt.NDArray[np.int64],
    npt.NDArray[np.bool_],
    npt.NDArray[np.bool_],
]:
    """``(sensor, noise, active, dropout, outlier)`` of each step of a run.

    The position sensor (``sensor`` None): its measurement noise
    (:func:`cwrend_cli.physics.sensors.sensor_noise`); a nonlinear sensor
    (issue 35): its model, measured and updated in the compiled loop, and no
    additive noise. ``active``: the degradation window of each step (−1 none).
    """
    sc = problem.scenario
    t = sc.time_grid()[:-1]
    windows = problem.degradation.windows
    r_nominal = problem.estimator.r_nominal_matrix()
    if problem.sensor.model == "position":
        meas = sensors.sensor_noise(standard_normal, t, r_nominal, windows, fault_draws, sc.dt_s)
        return None, meas.noise, meas.active, meas.dropout, meas.outlier
    sensor, parts = sensors.sensor_model(
        problem.sensor, standard_normal, t, windows, fault_draws, sc.dt_s
    )
    return sensor, np.zeros((sc.n_steps, 3)), parts.active, parts.dropout, parts.outlier


def _loop_parts(
    problem: Problem,
    arch: Architecture,
    noise: FloatArray,
    dropout: npt.NDArray[np.bool_],
    sensor: measurement_models.SensorModel | None,
    x_hat0: FloatArray,
    lam: FloatArray,
    eps0: float,
    actuator_draws: actuator.ActuatorDraws | None,
) -> _Loop:
    """The compiled loop's parts of a run of ``arch`` before its first step.

    ``noise``, ``dropout`` and ``sensor``: the measurement noise, the sensor
    dropouts of each step and the sensor (:func:`_measured`); ``x_hat0``: the
    filter's initial estimate; ``lam``: the first plan's costate; ``eps0``:
    the first ε. Row 0 of the log holds the initial state, estimate and ε.
    """
    sc, est, gd = problem.scenario, problem.estimator, problem.guidance
    n, dt, n_steps = sc.mean_motion_rad_s, sc.dt_s, sc.n_steps
    gl_x, gl_w = solver_settings(problem).quadrature()
    phi, gam = discretize(n, dt)
    filter_phi, filter_gam = _filter_tables(problem)
    # the shooting guidance's design model (issue 33): its own costate step and kernels
    design = _shooting_design(problem, arch.resolved_method(gd) == "socp")
    lam_step = (
        costate_stm(n, dt)
        if design is None
        else np.ascontiguousarray(design_models.lti_stm(design, -dt).T)
    )
    model = sk.LoopModel(
        phi=phi,
        gam=gam,
        lam_step=lam_step,
        q=est.q_matrix(),
        r_nominal=est.r_nominal_matrix(),
        noise=noise,
        n=guidance.kernel_model(n, design),
        u_max=sc.u_max_km_s2,
        dt=dt,
        gl_x=gl_x,
        gl_w=gl_w,
        estimator=ESTIMATOR_KINDS[arch.estimator],
        adaptive=arch.adaptive,
        hold_mean=gd.hold == "mean",
        u_override=np.zeros((n_steps, 3)),
        override=np.zeros(n_steps, dtype=np.bool_),
        dropout=dropout,
        filter_phi=filter_phi,
        filter_gam=filter_gam,
    )
    sched = schedule_params(problem.schedule)
    # the true relative state obeys problem.truth; guidance and filter their [model] (issue 33)
    truth_model = truth.truth_model(problem.truth, sc)
    act = actuator.actuator_model(problem.actuator, sc.u_max_km_s2, n_steps, actuator_draws)
    state = sk.LoopState(
        x_true=np.asarray(sc.x0, dtype=float).copy(),
        x_hat=x_hat0.copy(),
        p=est.p0_matrix(),
        lam=lam,
        chief=truth.initial_chief(problem.truth, sc),
    )
    log = _empty_log(n_steps + 1)
    log.x[0] = state.x_true
    log.x_hat[0] = state.x_hat
    log.eps[0] = eps0
    log.trace_p[0] = np.trace(state.p)
    filter_ekf = ekf.ekf_model(problem.model.filter, sc, problem.truth)
    # Q_k of each step: None for estimator.process_noise = "fixed" (issue 33)
    pn = process_noise.process_noise_model(est, problem.actuator.ideal, sc.u_max_km_s2)
    return _Loop(model, truth_model, act, sched, state, log, sensor, filter_ekf, pn)


def compile_loop(
    problem: Problem,
    arch: Architecture,
    standard_normal: FloatArray,
    actuator_draws: actuator.ActuatorDraws | None = None,
    fault_draws: sensors.FaultDraws | None = None,
    top: bool = False,
) -> None:
    """Compile (or load) the kernels below the re-solves of ``arch``'s closed loop; run nothing.

    The step loop of a run of ``arch`` on ``problem`` with these draws (the
    arguments of :func:`simulate`), for the same argument types as
    :func:`simulate` gives it: the shooting method's
    :func:`~cwrend_cli.physics._loop_kernels.compile_steps`, the cone program's
    :func:`~cwrend_cli.physics._loop_kernels.advance` of no step. Not the
    re-solves: a campaign compiles those of the references meanwhile
    (issue 37 item 12, :func:`cwrend_cli.physics.compiled.compile_ahead`).
    ``top``: instead, the top of the shooting method's loop, with its re-solves
    (:func:`~cwrend_cli.physics._loop_kernels.compile_resolve_loop`), which
    needs neither the step loop nor the solver compiled; nothing for the cone
    program, whose loop has no top of its own.
    """
    socp = arch.resolved_method(problem.guidance) == "socp"
    if top and socp:
        return
    sc = problem.scenario
    loop = _first_loop(problem, arch, standard_normal, actuator_draws, fault_draws)
    scalars = sk.LoopScalars(eps=0.0, score_filtered=0.0, first=True)
    if top:
        schedule = resolve_steps(problem)
        resolve, carry, rows = _resolve_parts(problem, solver_settings(problem), schedule, False)
        sk.compile_resolve_loop(sc.n_steps, loop.parts(resolve, scalars, carry, rows))
    elif socp:
        loop.advance(0, -1, sc.n_steps, scalars)  # k_stop < k_start: no step runs
    else:
        sk.compile_steps(
            loop.model, loop.truth, loop.act, loop.sched, loop.state, loop.log, loop.sensor,
            loop.ekf, loop.pn,
        )  # fmt: skip


def loop_signature(
    problem: Problem,
    arch: Architecture,
    standard_normal: FloatArray,
    actuator_draws: actuator.ActuatorDraws | None = None,
    fault_draws: sensors.FaultDraws | None = None,
) -> tuple[Any, tuple[Any, ...]]:
    """The step loop's entry point of a run of ``arch`` on ``problem`` and its argument types.

    The arguments as for :func:`compile_loop`; nothing compiled or run
    (:func:`~cwrend_cli.physics._loop_kernels.loop_signature`).
    """
    loop = _first_loop(problem, arch, standard_normal, actuator_draws, fault_draws)
    scalars = sk.LoopScalars(eps=0.0, score_filtered=0.0, first=True)
    return sk.loop_signature(
        arch.resolved_method(problem.guidance) == "socp", problem.scenario.n_steps, loop.model,
        loop.truth, loop.act, loop.sched, loop.state, scalars, loop.log, loop.sensor, loop.ekf,
        loop.pn,
    )  # fmt: skip


def _first_loop(
    problem: Problem,
    arch: Architecture,
    standard_normal: FloatArray,
    actuator_draws: actuator.ActuatorDraws | None,
    fault_draws: sensors.FaultDraws | None,
) -> _Loop:
    """The loop parts of a run's first step (the types every step has)."""
    sensor, noise, _, dropout, _ = _measured(problem, standard_normal, fault_draws)
    x0 = np.asarray(problem.scenario.x0, dtype=float)
    return _loop_parts(problem, arch, noise, dropout, sensor, x0, np.zeros(6), 0.0, actuator_draws)


def _target_attitude(problem: Problem) -> attitude.TargetAttitude | None:
    """The tumbling target's attitude at every step and safety sub-sample (issue 34 item 1).

    None for a fixed target (its axes are the relative frame's). Computed once
    before the loop: torque-free motion depends on nothing the chaser does, so
    these are the numbers a propagation inside the step loop would give
    (:mod:`cwrend_cli.physics.attitude`).
    """
    if not problem.target.tumbling:
        return None
    sc = problem.scenario
    model = attitude.attitude_model(problem.target, sc.mean_motion_rad_s)
    return attitude.target_attitude(model, sc.n_steps, sc.dt_s)


def _body_motion(
    problem: Problem, att: attitude.TargetAttitude, start: int, stop: int, stride: int
) -> safety_geometry.BodyMotion:
    """The tumbling target's turn at its samples ``start:stop:stride`` (issue 34)."""
    model = attitude.attitude_model(problem.target, problem.scenario.mean_motion_rad_s)
    rows = slice(start, stop, stride)
    return attitude.body_motion(model, att.q_hb[rows], att.w_rad_s[rows])


@dataclass(frozen=True)
class _Knowledge:
    """What the guidance knows of a tumbling target's attitude (issue 34): the truth's
    attitude (None for a fixed target) and the run's knowledge error (None: exact; each
    part (3,) for one error a run, (N, 3) for one a re-solve, row k at step k)."""

    truth: attitude.TargetAttitude | None
    error: tuple[FloatArray, FloatArray] | None


def _knowledge_error(
    problem: Problem, draws: FloatArray | None
) -> tuple[FloatArray, FloatArray] | None:
    """The run's attitude-knowledge error (δθ, δω), None when the guidance knows exactly."""
    if not problem.target.knowledge_error:
        return None
    per_step = (problem.scenario.n_steps, 6)
    expected = per_step if problem.target.knowledge_draw == "resolve" else (6,)
    if draws is None or np.shape(draws) != expected:
        raise ValueError(f"target.knowledge_sigma_*: the run needs its attitude draws {expected}")
    return attitude.knowledge_error(problem.target, draws)


def _predicted_motion(
    problem: Problem, known: _Knowledge, k_from: int, steps: int, substeps: int | None = None
) -> safety_geometry.BodyMotion:
    """The body's turn the guidance predicts at the nodes k_from … k_from + steps.

    ``substeps`` (abort safety's drifts, which reach beyond the run: issue 34 item 4):
    predicted with this many integration intervals a step, from the attitude known at
    ``k_from`` even when known exactly (:func:`cwrend_cli.physics.attitude.predict`)."""
    truth = known.truth
    assert truth is not None
    every = truth.substeps
    if known.error is None and substeps is None:  # exact: the truth's own at the nodes
        return _body_motion(problem, truth, k_from * every, (k_from + steps) * every + 1, every)
    sc = problem.scenario
    model = attitude.attitude_model(problem.target, sc.mean_motion_rad_s)
    i = k_from * every
    d_theta, d_w = known.error if known.error is not None else (np.zeros(3), np.zeros(3))
    if d_theta.ndim == 2:  # drawn at every re-solve: this one's (row k_from)
        d_theta, d_w = d_theta[k_from], d_w[k_from]
    believed, q_hb, w = attitude.predict(
        model, truth.q_hb[i], truth.w_rad_s[i], float(truth.t_s[i]), steps, sc.dt_s,
        (d_theta, d_w), every if substeps is None else substeps,
    )  # fmt: skip
    return attitude.body_motion(believed, q_hb, w)


def _safety(
    problem: Problem, x_true: FloatArray, att: attitude.TargetAttitude | None
) -> safety_geometry.Safety | None:
    """The safety of the true trajectory (issue 32 item 3); None without constraints.

    A tumbling target (``att``): against the set turning with the true attitude at
    every sub-sample (issue 34).
    """
    if problem.constraints is None:
        return None
    geo = safety_geometry.geometry(problem.constraints)
    motion = None
    if att is not None:
        motion = _body_motion(problem, att, 0, att.t_s.size, 1)
    return safety_geometry.measure_safety(
        x_true,
        problem.scenario.dt_s,
        geo,
        att.substeps if att else safety_geometry.SAFETY_SUBSTEPS,
        motion,
    )


def _abort_safety(
    problem: Problem, x_true: FloatArray, tumbling: bool = False
) -> abort_safety.AbortSafety | None:
    """The abort safety of the true trajectory (issue 34 item 4): every step's true state
    drifted freely by CW (:func:`~cwrend_cli.physics.abort_safety.measure_abort`); None
    without ``constraints.abort_safe_s``.

    A ``tumbling`` target: against the bodies at the truth's attitude at each drift
    sample's own time, the truth's torque-free motion propagated from t = 0 past the run's
    end by the drift time (:func:`cwrend_cli.physics.attitude.target_attitude`, the same
    integration of the same equations, sampled every Δt/stride)."""
    c = problem.constraints
    if c is None or c.abort_safe_s is None:
        return None
    sc = problem.scenario
    geo = safety_geometry.geometry(c)
    turn = None
    if tumbling:
        stride = abort_safety.turn_stride(sc.dt_s, abort_safety.MEASURE_SUBSAMPLES)
        model = attitude.attitude_model(problem.target, sc.mean_motion_rad_s)
        steps = sc.n_steps + abort_safety.turn_steps(c.abort_safe_s, sc.dt_s)
        long = attitude.target_attitude(model, steps, sc.dt_s, stride)
        turn = attitude.body_motion(model, long.q_hb, long.w_rad_s)
    return abort_safety.measure_abort(
        x_true, sc.mean_motion_rad_s, geo, c.abort_safe_s, turn=turn, dt_s=sc.dt_s
    )


@dataclass(frozen=True)
class _Loop:
    """The compiled loop's parts of one run (constant models, the state and log it updates)."""

    model: sk.LoopModel
    truth: truth.TruthModel
    act: actuator.ActuatorModel
    sched: sk.ScheduleParams
    state: sk.LoopState
    log: sk.StepLog
    sensor: measurement_models.SensorModel | None = None  # None: the position sensor
    ekf: ekf.EkfModel | None = None  # the extended Kalman filter's dynamics; None: linear
    pn: process_noise.ProcessNoiseModel | None = None  # None: estimator.q_process at every step

    def parts(
        self,
        resolve: sk.ResolveModel,
        scalars: sk.LoopScalars,
        carry: sk.ResolveCarry,
        solves: sk.SolveLog,
    ) -> sk.LoopParts:
        """:class:`~cwrend_cli.physics._loop_kernels.LoopParts` of these parts and re-solves."""
        return sk.LoopParts(
            self.model, self.truth, self.act, self.sched, resolve, self.state, scalars, carry,
            self.log, solves, self.sensor, self.ekf, self.pn,
        )  # fmt: skip

    def advance(
        self, k_start: int, k_stop: int, n_steps: int, scalars: sk.LoopScalars
    ) -> sk.LoopScalars:
        """:func:`~cwrend_cli.physics._loop_kernels.advance` of these parts."""
        return sk.advance(
            k_start, k_stop, n_steps, self.model, self.truth, self.act, self.sched, self.state,
            scalars, self.log, self.sensor, self.ekf, self.pn,
        )  # fmt: skip


def _shooting_resolves(
    problem: Problem,
    settings: guidance.SolverSettings,
    schedule: list[int],
    loop: _Loop,
    scalars: sk.LoopScalars,
    observe: ResolveObserver | None,
) -> list[SolveRecord]:
    """Run the loop with its shooting re-solves; the re-solves' records.

    The common case runs compiled from start to end
    (:func:`~cwrend_cli.physics._loop_kernels.resolve_loop`: each re-solve's
    warm attempt, and the plan it makes when it succeeds). A re-solve whose
    warm attempt does not succeed returns here, where it ends as
    :func:`cwrend_cli.physics.guidance.solve_state` ends one
    (:func:`~cwrend_cli.physics.guidance.after_warm`: the fallback chain),
    then the plan, the minimum-miss controls of an infeasible one and its
    record, and the compiled loop goes on from the next re-solve. With an
    observer every re-solve ends here, after it has been shown the input.
    """
    model, state = loop.model, loop.state
    sc = problem.scenario
    n, dt, n_steps = sc.mean_motion_rad_s, sc.dt_s, sc.n_steps
    correct = problem.guidance.resolve_timing == "correct"
    xf = np.asarray(sc.xf, dtype=float)
    count = len(schedule)
    design = _shooting_design(problem, socp=False)
    resolve, carry, rows = _resolve_parts(problem, settings, schedule, observe is not None)
    ended: dict[int, SolveRecord] = {}  # the re-solves ended here (after the compiled warm attempt)
    lam = state.lam
    i, k_start = 0, 0
    while True:
        i, scalars = sk.resolve_loop(i, k_start, n_steps, loop.parts(resolve, scalars, carry, rows))
        if i == count:
            break
        k = schedule[i]
        horizon = float(rows.horizon_s[i])
        if observe is not None:
            starts = [carry.starts[r].copy() for r in range(int(carry.n_starts[0]))]
            shooting = guidance.ShootingProblem(
                state.x_hat, horizon, float(rows.eps[i]), n, sc.u_max_km_s2, xf, design
            )
            observe(ResolveInput(k, shooting, starts[0], tuple(starts[1:])))
        lam_next = model.lam_step @ lam
        guess = lam_next if correct else lam.copy()
        warm = (
            guidance.KERNEL_STATUS[int(rows.status[i])],
            carry.warm.copy(),
            int(rows.iterations[i]),
            float(rows.residual_km[i]),
        )
        began = time.perf_counter() - float(rows.wall_time_ms[i]) * 1e-3
        result = guidance.after_warm(
            n, sc.u_max_km_s2, state.x_hat, xf, horizon, scalars.eps, guess, settings, warm, began,
            design,
        )  # fmt: skip
        rec = ended[i] = _record("resolve", k, (k + 1) * dt, result, settings.success_residual)
        if rec.success:
            carry.older[:] = lam_next
            carry.k_older[0] = k + 1
            lam[:] = result.costate if correct else model.lam_step @ result.costate
            _hold_plan(result, k + 1, model)
        else:
            lam[:] = lam_next
        _min_miss_if_infeasible(problem, result, schedule, i, state.x_hat, model)
        i, k_start = i + 1, k + 1
    columns = zip(
        schedule, rows.t_s.tolist(), rows.horizon_s.tolist(), rows.eps.tolist(),
        rows.status.tolist(), rows.iterations.tolist(), rows.residual_km.tolist(),
        rows.wall_time_ms.tolist(), rows.success.tolist(), strict=True,
    )  # fmt: skip
    return [
        ended.get(j)
        or SolveRecord("resolve", k, t, h, e, _STATUS_NAMES[c], "warm", it, res, wall, ok)
        for j, (k, t, h, e, c, it, res, wall, ok) in enumerate(columns)
    ]


def _resolve_parts(
    problem: Problem, settings: guidance.SolverSettings, schedule: list[int], stop_every: bool
) -> tuple[sk.ResolveModel, sk.ResolveCarry, sk.SolveLog]:
    """What the compiled loop's re-solves of a run hold, hand on and log
    (:func:`_shooting_resolves`)."""
    sc = problem.scenario
    count = len(schedule)
    resolve = sk.ResolveModel(
        steps=np.asarray(schedule, dtype=np.int64),
        xf=np.asarray(sc.xf, dtype=float),
        horizon_s=sc.horizon_s,
        correct=problem.guidance.resolve_timing == "correct",
        success_residual=settings.success_residual,
        newton=settings.newton_fields,
        switching_max_iter=settings.switching_max_iter,
        stop_every=stop_every,
    )
    carry = sk.ResolveCarry(
        older=np.zeros(6),
        k_older=np.full(1, -1, dtype=np.int64),
        warm=np.zeros(6),
        starts=np.zeros((2, 6)),
        n_starts=np.zeros(1, dtype=np.int64),
    )
    rows = sk.SolveLog(
        t_s=np.empty(count),
        horizon_s=np.empty(count),
        eps=np.empty(count),
        status=np.empty(count, dtype=np.int64),
        iterations=np.empty(count, dtype=np.int64),
        residual_km=np.empty(count),
        wall_time_ms=np.empty(count),
        success=np.empty(count, dtype=np.bool_),
    )
    return resolve, carry, rows


#: Status names of the kernels' status codes (``SolveRecord.status``).
_STATUS_NAMES = {code: status.value for code, status in guidance.KERNEL_STATUS.items()}


def _cone_resolves(
    problem: Problem,
    schedule: list[int],
    loop: _Loop,
    scalars: sk.LoopScalars,
    plan_costate: FloatArray | None,
    known: _Knowledge | None = None,
    duals: constrained.Duals | None = None,
) -> list[SolveRecord]:
    """Run the loop with its cone-program re-solves (``guidance.method = "socp"``, issue 16).

    Driven from Python between compiled stretches of steps. Each re-solve
    starts from the last successful plan's costate propagated to its time
    (``plan_costate``: the initial plan's, or None); a successful one holds its
    controls; the costate is propagated either way. A constrained re-solve's dual
    solver starts from the last successful plan's row multipliers (``duals``: the
    initial plan's, or None), moved to its start (:func:`.constrained.shift_duals`).
    """
    model, state = loop.model, loop.state
    sc = problem.scenario
    n, dt, n_steps = sc.mean_motion_rad_s, sc.dt_s, sc.n_steps
    correct = problem.guidance.resolve_timing == "correct"
    threshold = problem.solver.success_residual
    tables = _guidance_tables(problem)
    condensed = _guidance_condensed(problem)
    lam = state.lam
    records: list[SolveRecord] = []
    k_next, k_plan, k_duals = 0, 0, 0
    for i, k in enumerate(schedule):
        scalars = loop.advance(k_next, k, n_steps, scalars)
        k_next = k + 1
        k_from = k + 1 if correct else k
        horizon = sc.horizon_s - k_from * dt
        lam_next = model.lam_step @ lam
        scp = _constrained_plan(
            problem, state.x_hat, horizon, scalars.eps, state.p, model, k_from, known,
            constrained.shift_duals(duals, k_from - k_duals),
        )  # fmt: skip
        if scp is not None:  # a keep-out zone: the constrained cone program (issue 32)
            result = scp[0]
        else:
            warm = _warm_costate(plan_costate, k_plan, k_from, n, dt, tables)
            grid = _grid(sc, state.x_hat, horizon, condensed)
            result = convex.solve(grid, scalars.eps, n, warm=warm)
        rec = _record("resolve", k, (k + 1) * dt, result, threshold, scp and scp[1])
        records.append(rec)
        if rec.success:
            plan_costate, k_plan = result.costate, k_from
            _hold_plan(result, k + 1, model)
            if scp is not None:
                duals, k_duals = scp[2], k_from
        lam[:] = lam_next
        _min_miss_if_infeasible(problem, result, schedule, i, state.x_hat, model)
    loop.advance(k_next, n_steps, n_steps, scalars)
    return records


#: The initial constrained plans a campaign worker made, by the pickled inputs of
#: :func:`_initial_constrained_plan` (at most :data:`INITIAL_PLANS_KEPT`, the oldest dropped).
InitialPlans = dict[bytes, tuple[guidance.SolveResult, ScpFigures, "constrained.Duals | None"]]
#: Initial plans a worker keeps (:data:`InitialPlans`) [-].
INITIAL_PLANS_KEPT = 64


def _initial_constrained_plan(
    problem: Problem,
    x_hat: FloatArray,
    eps: float,
    p: FloatArray,
    known: _Knowledge | None,
    plans: InitialPlans | None,
) -> tuple[guidance.SolveResult, ScpFigures, constrained.Duals | None] | None:
    """:func:`_constrained_plan` from ``x_hat`` at step 0 over the whole horizon, cold.

    With ``plans`` (:func:`simulate`'s ``initial_plans``) a plan is made once for each
    set of inputs — the problem, the estimate, ε and the covariance, pickled — and a
    copy returned after that (its ``wall_time_s`` that of the look-up). A cold plan is
    a function of exactly these (no warm start, no random draw), so the copy is the plan
    bit for bit. A tumbling target known exactly too (issue 34): the attitude it predicts
    from is the truth's, a function of the problem (:func:`_target_attitude`). Not with an
    attitude-knowledge error (``known.error``: drawn per seed), planned every time."""
    horizon = problem.scenario.horizon_s
    key = None
    c = problem.constraints
    if c is None or not c.planned:  # no constrained plan (:func:`_constrained_plan`)
        return None
    if plans is not None and (known is None or known.truth is None or known.error is None):
        start = time.perf_counter()
        key = pickle.dumps((problem, x_hat, eps, p), protocol=pickle.HIGHEST_PROTOCOL)
        hit = plans.get(key)
        if hit is not None:
            result, scp, duals = copy.deepcopy(hit)
            return dataclasses.replace(result, wall_time_s=time.perf_counter() - start), scp, duals
    made = _constrained_plan(problem, x_hat, horizon, eps, p, None, 0, known)
    if key is not None and plans is not None and made is not None:
        while len(plans) >= INITIAL_PLANS_KEPT:
            plans.pop(next(iter(plans)))
        plans[key] = copy.deepcopy(made)
    return made


@functools.lru_cache(maxsize=16)
def _planning_geometry(c: Constraints) -> safety_geometry.Geometry:
    """:func:`~cwrend_cli.physics.constraints.geometry` of ``c``, one object for every
    re-solve of the same constraints (the planner keeps the corridor's rows for the geometry
    it last saw, by identity first: :func:`.constrained._untightened_corridor`); the
    planner only reads it."""
    return safety_geometry.geometry(c)


def _constrained_plan(
    problem: Problem,
    x_hat: FloatArray,
    horizon_s: float,
    eps: float,
    p: FloatArray,
    model: sk.LoopModel | None,
    k_from: int,
    known: _Knowledge | None = None,
    warm_duals: constrained.Duals | None = None,
) -> tuple[guidance.SolveResult, ScpFigures, constrained.Duals | None] | None:
    """A re-solve by the constrained cone program (issue 32), None without a keep-out zone
    or with ``constraints.enforce = false`` (measure only: the unconstrained program).

    From the estimate ``x_hat`` at step ``k_from`` over ``horizon_s``, with the
    filter's position covariance (``p[:3, :3]``, held over the horizon) for
    ``constraints.sigma_margin``; warm-started from the plan held from
    ``k_from`` on (``model``'s override), else from the unconstrained plan.
    Returns the result (its plan the held controls; no costate),
    (SCP iterations, path slack [km], abort slack [km]) and the plan's row multipliers
    (``warm_duals`` of the next re-solve, after :func:`.constrained.shift_duals`).

    A tumbling target (``known``, issue 34): the attitude predicted over the
    horizon from the one known at ``k_from`` turns the keep-out bodies and the
    corridor at every node, and with a corridor the terminal state is the port's
    predicted position and velocity at the horizon's end, ``(R p, Ω × R p)`` in
    the relative frame. Known exactly, the prediction is the truth's attitude
    (torque-free motion predicted by the same model is the truth's own); with a
    knowledge error, :func:`cwrend_cli.physics.attitude.predict` from the truth's
    attitude at ``k_from`` turned by it.
    """
    c = problem.constraints
    if c is None or not c.planned:
        return None
    sc = problem.scenario
    steps = max(1, round(horizon_s / sc.dt_s))
    warm = None
    held = model is not None and k_from + steps <= model.override.size
    if model is not None and held and bool(np.all(model.override[k_from : k_from + steps])):
        warm = model.u_override[k_from : k_from + steps].copy()
    xf = np.asarray(sc.xf, dtype=float)
    geo = _planning_geometry(c)
    motion = abort_turn = None
    if known is not None and known.truth is not None:
        motion = _predicted_motion(problem, known, k_from, steps)
        if c.abort_safe_s is not None:  # the drifts' attitude, predicted every Δt
            extra = abort_safety.turn_steps(c.abort_safe_s, sc.dt_s)
            abort_turn = _predicted_motion(problem, known, k_from, steps + extra, 1)
        if geo.port_km is not None:
            port = motion.rotation[-1] @ geo.port_km
            xf = np.concatenate([port, np.cross(motion.rate_rad_s[-1], port)])
    ans = constrained.plan(
        sc.mean_motion_rad_s,
        sc.dt_s,
        sc.u_max_km_s2,
        x_hat,
        xf,
        horizon_s,
        eps,
        geo,
        np.asarray(p)[:3, :3],
        c.sigma_margin,
        warm,
        motion=motion,
        abort_safe_s=c.abort_safe_s,
        warm_duals=warm_duals,
        abort_turn=abort_turn,
    )
    converged = ans.status is guidance.SolveStatus.CONVERGED
    miss = math.nan
    if converged:
        states, _ = constrained.node_positions(sc.mean_motion_rad_s, sc.dt_s, x_hat, ans.controls)
        miss = float(np.linalg.norm(states[-1] - xf))
    result = guidance.SolveResult(
        costate=np.full(6, np.nan),
        status=ans.status,
        step="socp_scp",
        iterations=ans.solver_iterations,
        residual_km=miss,
        wall_time_s=ans.wall_time_s,
        eps=float(eps),
        horizon_s=steps * sc.dt_s,
        controls=ans.controls if converged else None,
    )
    slack = 0.0 if math.isnan(ans.slack_km) else ans.slack_km
    return result, (ans.scp_iterations, slack, ans.abort_slack_km, ans.fallbacks), ans.duals


def _min_miss_if_infeasible(
    problem: Problem,
    result: guidance.SolveResult,
    schedule: list[int],
    i: int,
    x_hat: FloatArray,
    model: sk.LoopModel,
) -> None:
    """After an infeasible re-solve ``i`` with ``solver.on_infeasible = "min_miss"``: hold the
    minimum-miss controls until the next re-solve (cwrend's; docs/solvers.md)."""
    if not (
        result.status is guidance.SolveStatus.INFEASIBLE
        and problem.solver.on_infeasible == "min_miss"
    ):
        return
    sc = problem.scenario
    k = schedule[i]
    stop = schedule[i + 1] if i + 1 < len(schedule) else sc.n_steps - 1
    _apply_min_miss(
        sc,
        x_hat,
        (k + 1) * sc.dt_s,
        k + 1,
        stop,
        model.u_override,
        model.override,
        _guidance_condensed(problem),
    )


def _grid(
    sc: Scenario,
    x_hat: FloatArray,
    horizon_s: float,
    condensed: feasibility.CondensedSteps | None = None,
) -> feasibility.GridProblem:
    """One re-solve of the scenario on its zero-order-hold grid (the loop's Δt).

    ``condensed``: the guidance's design model other than CW (issue 33,
    :func:`_guidance_condensed`), whose last ``horizon_s/Δt`` steps are the
    grid's; None: CW (Eq. 11).
    """
    xf = np.asarray(sc.xf, dtype=float)
    if condensed is None:
        return feasibility.grid_problem(
            sc.mean_motion_rad_s, x_hat, xf, horizon_s, sc.dt_s, sc.u_max_km_s2
        )
    steps = max(1, round(horizon_s / sc.dt_s))
    return feasibility.grid_problem_from_condensed(
        condensed, steps, x_hat, xf, sc.dt_s, sc.u_max_km_s2
    )


def _guidance_tables(problem: Problem) -> design_models.StepTables | None:
    """The per-step Φ_k, Γ_k of the guidance's design model; None for CW (issue 33)."""
    name = problem.model.guidance
    if name == "cw":
        return None
    return design_models.step_tables(name, problem.scenario, problem.truth)


def _guidance_condensed(problem: Problem) -> feasibility.CondensedSteps | None:
    """The guidance's design model condensed onto the final time; None for CW (issue 33).

    Every re-solve's grid ends at t_N, so one condensation
    (:func:`feasibility.condense`) serves every re-solve of every run on
    this scenario and truth: each slices it (:func:`_grid`).
    """
    name = problem.model.guidance
    if name == "cw":
        return None
    return _condensed(name, problem.scenario, problem.truth)


@functools.lru_cache(maxsize=16)
def _condensed(
    name: DesignModelName, scenario: Scenario, truth: Truth
) -> feasibility.CondensedSteps:
    """:func:`feasibility.condense` of :func:`design_models.step_tables` (cached as they are)."""
    tables = design_models.step_tables(name, scenario, truth)
    return feasibility.condense(tables.phi, tables.gam)


def _filter_tables(problem: Problem) -> tuple[FloatArray, FloatArray]:
    """Φ_k (N, 6, 6) and Γ_k (N, 6, 3) the filter predicts with at each step (issue 33).

    The :func:`design_models.step_tables` of ``model.filter`` (CW: Eq. 11 at
    every step), as writable copies, so that the compiled loop sees the arrays
    it always did. An extended Kalman filter predicts through the nonlinear
    dynamics instead (:mod:`cwrend_cli.physics.ekf`); its tables are CW's, read only
    by ``estimator.process_noise`` (Q_k = q + Γ_k Σ Γ_kᵀ), where CW's Γ over a
    1 s step stands for the nonlinear step's ∂F/∂u (they differ at O(ωΔt)
    relative through the frame's rate ω ≠ n: measured 5.2e-8 on the J2 chief
    at i = 51.6°, 1.8e-4 on an eccentric one, e = 0.1 at f = 40°;
    tests/test_process_noise.py).
    """
    name = problem.model.filter
    tables = design_models.step_tables(
        name if name == "ss" or name == "ya" else "cw", problem.scenario, problem.truth
    )
    return np.array(tables.phi), np.array(tables.gam)


def _warm_costate(
    plan_costate: FloatArray | None,
    k_plan: int,
    k_from: int,
    n: float,
    dt: float,
    tables: design_models.StepTables | None,
) -> FloatArray | None:
    """The last plan's costate carried from step ``k_plan`` to ``k_from``: λ(t) = Φ(T, t)ᵀν.

    CW: ``e^{−Aᵀ(t_from − t_plan)}`` λ; another model: Φ(t_from, t_plan)⁻ᵀ λ with
    Φ(t_from, t_plan) the product of its steps (issue 33).
    """
    if plan_costate is None:
        return None
    if tables is None:
        out: FloatArray = costate_stm(n, (k_from - k_plan) * dt) @ plan_costate
        return out
    acc = np.eye(6)
    for k in range(k_plan, k_from):
        acc = tables.phi[k] @ acc
    return np.asarray(np.linalg.solve(acc.T, plan_costate))


def _hold_plan(result: guidance.SolveResult, k_first: int, model: sk.LoopModel) -> None:
    """Make a successful re-solve the plan from step ``k_first`` on.

    Held controls (cone program, shooting's ``socp_plan``) go into the override
    arrays up to the end; a costate plan clears them (the costate then drives
    the control, as without overrides).
    """
    if result.controls is None:
        model.override[k_first:] = False
        return
    count = min(result.controls.shape[0], model.u_override.shape[0] - k_first)
    model.u_override[k_first : k_first + count] = result.controls[:count]
    model.override[k_first : k_first + count] = True


def _apply_min_miss(
    sc: Scenario,
    x_hat: FloatArray,
    t_est: float,
    k_first: int,
    k_last: int,
    u_override: FloatArray,
    override: npt.NDArray[np.bool_],
    condensed: feasibility.CondensedSteps | None = None,
) -> None:
    """Hold the bounded controls minimising the terminal miss for steps ``k_first … k_last``."""
    g = _grid(sc, x_hat, sc.horizon_s - t_est, condensed)
    controls = feasibility.min_miss_controls(g, velocity_weight_s=sc.dt_s)
    if controls is None:
        return
    count = min(k_last - k_first + 1, controls.shape[0], u_override.shape[0] - k_first)
    u_override[k_first : k_first + count] = controls[:count]
    override[k_first : k_first + count] = True
