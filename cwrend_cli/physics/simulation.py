"""Closed-loop receding-horizon simulation of one architecture (SPEC §3–5).

An architecture is estimator {plain, MTF} × schedule {fixed, adaptive}: the
same loop with two switches. The step loop runs compiled
(:mod:`cwrend_cli.physics._loop_kernels`) between re-solves; re-solves go through
:func:`cwrend_cli.guidance.solve`. Nothing here writes files: the result is a
plain :class:`RunResult` that :mod:`cwrend_cli.output.tables` and the recorders consume.

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

from dataclasses import dataclass

import numpy as np

from cwrend_cli.config import Architecture, CwrendConfig
from cwrend_cli.physics import _loop_kernels as sk
from cwrend_cli.physics import guidance, references, sensors
from cwrend_cli.physics.dynamics import costate_stm, discretize
from cwrend_cli.physics.guidance import feasibility


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
    success: bool  # converged and residual below solver.success_residual (SPEC §5)


@dataclass(frozen=True)
class RunResult:
    """Per-step histories of one closed-loop run; row k is time ``t_s[k]``.

    Row k holds the state at t_k, the control applied over ``[t_k, t_{k+1})``
    (zero in the last row), and the quantities of the measurement taken at
    t_k (NaN in row 0, where there is none) including the ε that results.
    """

    arch: str
    seed: int
    t_s: np.ndarray
    x_true: np.ndarray
    x_hat: np.ndarray
    u: np.ndarray
    y: np.ndarray
    nis: np.ndarray
    mtf_ratio: np.ndarray
    score: np.ndarray
    score_filtered: np.ndarray
    eps: np.ndarray
    trace_p: np.ndarray
    window: np.ndarray  # index of the degradation window that corrupted the measurement, −1 none
    solves: tuple[SolveRecord, ...]
    delta_v_km_s: float
    miss_km: float

    @property
    def resolves(self) -> tuple[SolveRecord, ...]:
        """The receding-horizon re-solves (without the initial solve)."""
        return tuple(s for s in self.solves if s.kind == "resolve")


@dataclass(frozen=True)
class References:
    """The open-loop references of a scenario."""

    energy: references.OpenLoopResult
    fuel: references.OpenLoopResult


def solver_settings(cfg: CwrendConfig) -> guidance.SolverSettings:
    """Solver settings from the validated config."""
    s = cfg.solver
    return guidance.SolverSettings(
        tol_pos_km=s.tol_pos_km,
        tol_vel_km_s=s.tol_vel_km_s,
        max_iter=s.max_iter,
        quadrature_nodes=s.quadrature_nodes,
        fallback=s.fallback,
        success_residual=s.success_residual,
        dt_grid_s=cfg.scenario.dt_s,
    )


def time_grid(cfg: CwrendConfig) -> np.ndarray:
    """Grid times t_k = k Δt, k = 0 … N [s]."""
    return np.arange(cfg.scenario.n_steps + 1) * cfg.scenario.dt_s


def _problem(cfg: CwrendConfig, x0: np.ndarray, horizon_s: float, eps: float):
    sc = cfg.scenario
    return guidance.ShootingProblem(
        np.asarray(x0, dtype=float),
        float(horizon_s),
        float(eps),
        sc.mean_motion_rad_s,
        sc.u_max_km_s2,
        np.asarray(sc.xf, dtype=float),
    )


def open_loop_references(cfg: CwrendConfig) -> References:
    """Energy- and fuel-optimal open-loop references of the scenario (SPEC §2)."""
    t = time_grid(cfg)
    problem = _problem(cfg, np.asarray(cfg.scenario.x0), cfg.scenario.horizon_s, 0.0)
    return References(
        energy=references.energy_optimal(problem, t),
        fuel=references.fuel_optimal(problem, t, solver_settings(cfg)),
    )


def resolve_steps(cfg: CwrendConfig) -> list[int]:
    """Steps k at which a re-solve is due (SPEC §5)."""
    sc, gd = cfg.scenario, cfg.guidance
    every = round(gd.t_resolve_s / sc.dt_s)
    out = []
    for k in range(0, sc.n_steps, every):
        t_from = (k + 1) * sc.dt_s if gd.resolve_timing == "correct" else k * sc.dt_s
        if sc.horizon_s - t_from > gd.t_min_rem_s:
            out.append(k)
    return out


def _record(kind: str, step: int, t_s: float, result: guidance.SolveResult, threshold: float):
    return SolveRecord(
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


def simulate(
    cfg: CwrendConfig,
    arch: Architecture,
    standard_normal: np.ndarray,
    refs: References,
    seed: int = 0,
) -> RunResult:
    """Run one closed-loop case of ``arch`` on the noise realisation ``standard_normal`` (N, 3)."""
    sc, est, sch, gd = cfg.scenario, cfg.estimator, cfg.schedule, cfg.guidance
    n, dt, n_steps = sc.mean_motion_rad_s, sc.dt_s, sc.n_steps
    settings = solver_settings(cfg)
    gl_x, gl_w = settings.quadrature()
    t = time_grid(cfg)
    phi, gam = discretize(n, dt)
    lam_step = costate_stm(n, dt)
    r_nominal = est.r_nominal_matrix()
    noise, active = sensors.measurement_noise(
        standard_normal, t[:-1], r_nominal, cfg.degradation.windows
    )

    x0 = np.asarray(sc.x0, dtype=float)
    # the filter starts at the true initial state (SPEC §3) unless an initial error is set
    x_hat0 = x0 + np.asarray(est.initial_error, dtype=float)
    solves: list[SolveRecord] = []
    if arch.adaptive:
        eps0 = sch.eps_max
        # initial solve at ε_max from the energy costate; on failure keep it (SPEC §4)
        first = _problem(cfg, x_hat0, sc.horizon_s, eps0)
        result = guidance.solve(first, refs.energy.costate, settings)
        solves.append(_record("initial", -1, 0.0, result, settings.success_residual))
        lam = result.costate.copy() if solves[-1].success else refs.energy.costate.copy()
    else:
        eps0 = sch.eps_fixed
        lam = refs.fuel.costate.copy()

    sched = np.empty(sk.N_SCHEDULE_PARAMS)
    sched[sk.P_NIS_OFFSET] = sch.nis_offset
    sched[sk.P_KAPPA] = sch.kappa_mtf
    sched[sk.P_SCORE_MAX] = sch.score_max
    sched[sk.P_RHO_S] = sch.score_lowpass
    sched[sk.P_EPS_MIN] = sch.eps_min
    sched[sk.P_EPS_MAX] = sch.eps_max
    sched[sk.P_BETA] = sch.beta
    sched[sk.P_DEADBAND] = sch.deadband
    sched[sk.P_EPS_SAT] = np.nan if sch.eps_saturation is None else sch.eps_saturation
    sched[sk.P_ALPHA] = sch.alpha_eps

    rows = n_steps + 1
    log_x = np.full((rows, 6), np.nan)
    log_xhat = np.full((rows, 6), np.nan)
    log_u = np.zeros((rows, 3))
    log_y = np.full((rows, 3), np.nan)
    log_nis = np.full(rows, np.nan)
    log_rho = np.full(rows, np.nan)
    log_score = np.full(rows, np.nan)
    log_sf = np.full(rows, np.nan)
    log_eps = np.full(rows, np.nan)
    log_trp = np.full(rows, np.nan)
    x_true = x0.copy()
    x_hat = x_hat0.copy()
    p = est.p0_matrix()
    q = est.q_matrix()
    log_x[0] = x_true
    log_xhat[0] = x_hat
    log_eps[0] = eps0
    log_trp[0] = np.trace(p)
    scal = np.array([eps0, 0.0, 1.0])
    u_override = np.zeros((n_steps, 3))
    override = np.zeros(n_steps, dtype=np.bool_)

    def run_until(k_start: int, k_stop: int) -> None:
        sk.advance(
            k_start, k_stop, n_steps, phi, gam, lam_step, q, r_nominal, noise,
            arch.mtf, arch.adaptive, gd.hold == "mean", sched, n, sc.u_max_km_s2, dt,
            gl_x, gl_w, u_override, override, x_true, x_hat, p, lam, scal,
            log_x, log_xhat, log_u, log_y, log_nis, log_rho, log_score, log_sf, log_eps, log_trp,
        )  # fmt: skip

    schedule = resolve_steps(cfg)
    correct = gd.resolve_timing == "correct"
    k_next = 0
    for i, k in enumerate(schedule):
        run_until(k_next, k)
        k_next = k + 1
        t_est = (k + 1) * dt
        horizon = sc.horizon_s - (t_est if correct else k * dt)
        eps = scal[sk.EPS]
        lam_next = lam_step @ lam
        problem = _problem(cfg, x_hat, horizon, eps)
        result = guidance.solve(problem, lam_next if correct else lam, settings)
        rec = _record("resolve", k, t_est, result, settings.success_residual)
        solves.append(rec)
        if rec.success:
            lam[:] = result.costate if correct else lam_step @ result.costate
        else:
            lam[:] = lam_next
        if (
            result.status is guidance.SolveStatus.INFEASIBLE
            and cfg.solver.on_infeasible == "min_miss"
        ):
            stop = schedule[i + 1] if i + 1 < len(schedule) else n_steps - 1
            _apply_min_miss(cfg, x_hat, t_est, k + 1, stop, u_override, override)
    run_until(k_next, n_steps)

    miss = float(np.linalg.norm(log_x[-1, :3] - np.asarray(sc.xf[:3])))
    window = np.full(rows, -1, dtype=np.int64)
    window[1:] = active
    return RunResult(
        arch=arch.slug,
        seed=seed,
        t_s=t,
        x_true=log_x,
        x_hat=log_xhat,
        u=log_u,
        y=log_y,
        nis=log_nis,
        mtf_ratio=log_rho,
        score=log_score,
        score_filtered=log_sf,
        eps=log_eps,
        trace_p=log_trp,
        window=window,
        solves=tuple(solves),
        delta_v_km_s=references.delta_v(t, log_u),
        miss_km=miss,
    )


def _apply_min_miss(
    cfg: CwrendConfig,
    x_hat: np.ndarray,
    t_est: float,
    k_first: int,
    k_last: int,
    u_override: np.ndarray,
    override: np.ndarray,
) -> None:
    """Hold the bounded controls minimising the terminal miss for steps ``k_first … k_last``."""
    sc = cfg.scenario
    g = feasibility.grid_problem(
        sc.mean_motion_rad_s, x_hat, np.asarray(sc.xf, dtype=float),
        sc.horizon_s - t_est, sc.dt_s, sc.u_max_km_s2,
    )  # fmt: skip
    controls = feasibility.min_miss_controls(g, velocity_weight_s=sc.dt_s)
    if controls is None:
        return
    count = min(k_last - k_first + 1, controls.shape[0], u_override.shape[0] - k_first)
    u_override[k_first : k_first + count] = controls[:count]
    override[k_first : k_first + count] = True
