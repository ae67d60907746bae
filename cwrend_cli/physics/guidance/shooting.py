"""Indirect minimum-fuel guidance: control law and the shooting re-solve (paper Eqs. 8–10).

The typed API over the compiled kernels of :mod:`cwrend_cli.physics.guidance._kernels`.
One re-solve finds ``λ(0)`` so that the state reaches ``x_f`` at the remaining
horizon under the smoothed control of Eq. (10) with homotopy parameter ε.

The solver maximises the concave dual function whose gradient is the
shooting residual (see the kernel module), so a damped Newton ascent is
globally convergent for feasible problems, and a ray along which the dual
grows without bound is a certificate that no control with ``‖u‖ ≤ u_max``
reaches the target (status ``infeasible``).

Fallback chain (``fallback = "chain"``), each step only when the previous one
fails: warm Newton → ``socp_plan``, the plan of last resort: the smoothed
minimum-fuel cone program at the same ε on the 1 s zero-order-hold grid
(:mod:`~cwrend_cli.physics.guidance.convex`), whose held controls are the plan
until the next re-solve (status ``converged``, ``SolveResult.controls`` set,
the residual its plan's terminal miss, the costate its terminal multiplier's)
or whose certificate, confirmed by the continuous-time dual bound (below),
makes the re-solve ``infeasible`` → adaptive geometric ε-continuation from the
warm start → the same from the energy-optimal costate → a costate from the
multiplier of the discretised minimum-fuel SOCP, then Newton → the
continuous-time dual bound (:func:`classify_failure`, step ``dual_bound``)
decides between ``infeasible`` and ``failed``. With
``fallback = "none"`` only the warm attempt is made, as in the authors'
implementation.

Where ``socp_plan`` sits (issue 16, measured with ``guidance.hold = "mean"``,
plain and MTF fixed ε, seeds 0–39): right after the warm attempt, 140 plans,
no failed re-solve, total re-solve time 12.0 s and mean miss 1.080 m (max
2.80 m); after the two continuations, 73 plans, no failure, 32.4 s and
1.079 m (max 2.80 m). As good and 2.7× cheaper first, so it is first; the
cone program's costate then warm-starts the next re-solve, which mostly
converges again at once (seed 262: 5 plans instead of 24).

Design model (issue 33): CW (paper Eqs. 4, 11) unless the problem carries
another time-invariant model (``ShootingProblem.design``: Schweighart–Sedwick's
J2 model, ``model.guidance = "ss"``). Then the kernels, the energy-optimal
start, the cone program's grid and the dual bound all use that model; the
primer vector is ``λ_v(t) = Bᵀ Φ(T, t)ᵀ ν`` with ``Φ(T, t) = e^{A(T − t)}``
(Lawden's primer vector of a linear system), and the control law, the
shooting residual and the fallback chain are the same.

Units: km, s, km/s, km/s², rad/s.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import scipy.linalg

from cwrend_cli.physics.design_models import LinearTimeInvariant, lti_input_matrix, lti_stm
from cwrend_cli.physics.dynamics import cw_system, stm
from cwrend_cli.physics.guidance import _kernels as kern
from cwrend_cli.physics.guidance import _switching_kernels as switching
from cwrend_cli.physics.guidance import convex, feasibility
from cwrend_cli.physics.guidance.results import SolveResult, SolveStatus
from cwrend_cli.physics.lti_kernels import KernelModel

EPS_BANG_BANG = kern.EPS_BANG_BANG


#: The kernels' status codes (``_kernels.STATUS_*``) as statuses.
KERNEL_STATUS = {
    kern.STATUS_CONVERGED: SolveStatus.CONVERGED,
    kern.STATUS_INFEASIBLE: SolveStatus.INFEASIBLE,
    kern.STATUS_FAILED: SolveStatus.FAILED,
}


@dataclass(frozen=True)
class ShootingProblem:
    """One re-solve: reach ``xf`` from ``x0`` in ``horizon_s`` at homotopy parameter ``eps``."""

    x0: np.ndarray  # (6,) km, km/s
    horizon_s: float
    eps: float
    mean_motion_rad_s: float
    u_max_km_s2: float
    xf: np.ndarray = field(default_factory=lambda: np.zeros(6))
    #: the guidance's time-invariant design model other than CW (issue 33); None: CW of
    #: ``mean_motion_rad_s``
    design: LinearTimeInvariant | None = None

    def __post_init__(self) -> None:
        # Own read-only copies: callers often pass views of arrays they keep mutating.
        for name in ("x0", "xf"):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.shape != (6,):
                raise ValueError(f"{name} must have shape (6,), got {arr.shape}")
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    @property
    def kernel_model(self) -> KernelModel:
        """The design model as the compiled kernels take it (:mod:`._kernels`' docstring)."""
        return kernel_model(self.mean_motion_rad_s, self.design)

    def transition(self, t: float) -> np.ndarray:
        """``Φ(t)`` (6×6) of the design model."""
        return stm(self.mean_motion_rad_s, t) if self.design is None else lti_stm(self.design, t)

    def system(self) -> tuple[np.ndarray, np.ndarray]:
        """``A`` (6×6) and ``B`` (6×3) of the design model."""
        return cw_system(self.mean_motion_rad_s) if self.design is None else self.design.system()


def kernel_model(n: float, design: LinearTimeInvariant | None) -> KernelModel:
    """The model the kernels take: CW's mean motion ``n`` [rad/s], or ``design``'s coefficients.

    The coefficients as the plain tuple of an :class:`~cwrend_cli.physics.lti_kernels.LtiKernel`
    (:mod:`._kernels`' docstring).
    """
    return n if design is None else tuple(design.kernel())


@dataclass(frozen=True)
class SolverSettings:
    """Numerical settings of the shooting solver."""

    tol_pos_km: float = 1e-9
    tol_vel_km_s: float = 1e-12
    max_iter: int = 50
    quadrature_nodes: int = 12
    fallback: Literal["chain", "none"] = "chain"
    success_residual: float = (
        1e-4  # not in the paper: a solve succeeds if converged and ‖x(T)−x_f‖ below this
    )
    dt_grid_s: float = 1.0  # zero-order-hold grid of the convex checks
    #: Newton steps of the switching-time Newton tried first at ε = 0 (0: the dual ascent
    #: only, as before issue 17); see :mod:`._switching_kernels`. 20, not 12: 78 of the
    #: 3,120 warm re-solves of seeds 0–19 converge at 13–14 steps after a structure change
    #: (p99 re-solve time 0.90 → 0.47 ms); a failing attempt costs at most ~0.08 ms.
    switching_max_iter: int = 20

    def newton(self) -> kern.NewtonSettings:
        """Settings of the compiled Newton ascent (its other constants at their defaults)."""
        return kern.NewtonSettings(
            tol_pos_km=self.tol_pos_km, tol_vel_km_s=self.tol_vel_km_s, max_iter=self.max_iter
        )

    @functools.cached_property
    def newton_fields(self) -> tuple[Any, ...]:
        """:meth:`newton` as the plain tuple the kernel takes, built once per settings."""
        return tuple(self.newton())

    def quadrature(self) -> tuple[np.ndarray, np.ndarray]:
        """Gauss–Legendre nodes and weights on [−1, 1]."""
        return _gauss_legendre(self.quadrature_nodes)


_GL_CACHE: dict[int, tuple[np.ndarray, np.ndarray]] = {}


def _gauss_legendre(k: int) -> tuple[np.ndarray, np.ndarray]:
    if k not in _GL_CACHE:
        x, w = np.polynomial.legendre.leggauss(k)
        _GL_CACHE[k] = (np.ascontiguousarray(x), np.ascontiguousarray(w))
    return _GL_CACHE[k]


def n_cells(horizon_s: float) -> int:
    """Coarse cells of the switching-time search: at most 40 s each, at least 4."""
    return int(kern.n_cells(float(horizon_s)))


def control(costate_v: np.ndarray, eps: float, u_max_km_s2: float) -> np.ndarray:
    """Control acceleration of Eqs. (8)–(10) from the velocity costate ``λ_v`` [km/s²]."""
    out = np.empty(3)
    kern.control_from_costate(np.ascontiguousarray(costate_v, dtype=float), eps, u_max_km_s2, out)
    return out


def energy_optimal_costate(problem: ShootingProblem) -> np.ndarray:
    """``λ(0)`` of the unbounded energy-optimal problem, in closed form.

    The paper's open-loop energy reference (paper Sec. "Numerical Results and Discussion").

    With ``u = −Bᵀλ`` the state–costate system is linear,
    ``d/dt [x; λ] = [[A, −BBᵀ], [0, −Aᵀ]] [x; λ]``; its 12×12 matrix exponential
    over the horizon gives ``x(T) = E₁₁ x₀ + E₁₂ λ(0)``, solved for ``λ(0)``.
    """
    a, b = problem.system()
    z = np.zeros((12, 12))
    z[:6, :6] = a
    z[:6, 6:] = -b @ b.T
    z[6:, 6:] = -a.T
    e = scipy.linalg.expm(z * problem.horizon_s)
    return np.linalg.solve(e[:6, 6:], problem.xf - e[:6, :6] @ problem.x0)


def warm_attempt(
    n: KernelModel,
    u_max_km_s2: float,
    x0: np.ndarray,
    xf: np.ndarray,
    horizon_s: float,
    eps: float,
    starts: np.ndarray,
    settings: SolverSettings,
) -> tuple[SolveStatus, np.ndarray, int, float]:
    """One Newton ascent from the best of ``starts`` (k×6): ``(status, λ(0), iterations, res.)``.

    The compiled ascent on plain arrays, with no Python object built around
    it: the warm attempt of :func:`solve_state` and every Newton solve of the
    fallback chain. At ε = 0 the switching-time Newton runs first
    (``settings.switching_max_iter`` steps; its answer confirmed by the full
    dual evaluation, else the damped ascent goes on; the iterations are the
    sum of both). ``residual`` is ``hypot(‖Δr(T)‖, ‖Δv(T)‖)`` [km, km/s].
    ``n``: the design model as the kernels take it (:func:`kernel_model`).
    ``starts`` must be float64 and C-contiguous; ``x0`` and ``xf`` are made
    so, and writable: numba compiles a read-only array (a ShootingProblem's)
    as another type, so a read-only state here made the closed loop's first
    re-solve compile every kernel again inside its timed call (3 s cold).
    """
    x0 = np.require(x0, dtype=float, requirements=["C", "W"])
    xf = np.require(xf, dtype=float, requirements=["C", "W"])
    gl_x, gl_w = settings.quadrature()
    out = np.empty(6)
    status, iters, rp, rv = switching.bang_bang_ascent(
        n, x0, xf, horizon_s, eps, u_max_km_s2, starts, gl_x, gl_w, n_cells(horizon_s),
        settings.newton_fields, settings.switching_max_iter, out,
    )  # fmt: skip
    return KERNEL_STATUS[status], out, iters, float(np.hypot(rp, rv))


def warm_starts(guess: np.ndarray, alternatives: Sequence[np.ndarray], eps: float) -> np.ndarray:
    """The rows the warm attempt chooses from: ``guess`` and, at ε = 0, the ``alternatives``.

    Why the alternatives (issue 17): in the fixed-ε closed loops the
    bang-bang plan alternates between two costate families from one re-solve
    to the next (a short burn at the start of the plan, executed over a whole
    step by the sample hold, is over-corrected by the next re-solve), so the
    plan before the previous one is often the closer start: starting from the
    one with the higher dual value took the median warm re-solve of seeds 0–9
    from 15 to 10 Newton iterations. At ε > 0 the warm re-solve converges in
    2–3 iterations from ``guess``, and a choice would only cost evaluations.
    """
    guess = np.asarray(guess, dtype=float)
    if len(alternatives) == 0 or eps >= EPS_BANG_BANG:
        return np.ascontiguousarray(guess.reshape(1, 6))
    return np.ascontiguousarray(np.vstack([guess, *alternatives]), dtype=float)


def _newton(
    problem: ShootingProblem, eps: float, guess: np.ndarray, settings: SolverSettings
) -> tuple[SolveStatus, np.ndarray, int, float]:
    return warm_attempt(
        problem.kernel_model,
        problem.u_max_km_s2,
        problem.x0,
        problem.xf,
        float(problem.horizon_s),
        float(eps),
        warm_starts(guess, (), eps),
        settings,
    )


def _continuation(
    problem: ShootingProblem, guess: np.ndarray, settings: SolverSettings
) -> tuple[SolveStatus, np.ndarray, int, float]:
    """Adaptive geometric ε-continuation from ε = 1 down to ``problem.eps``.

    The ratio between successive ε starts at 0.1, is shrunk towards 1 after a
    failed step and relaxed after a success. Below 1e-4 the next step is the
    target itself (ε = 0 for bang-bang).
    """
    target = problem.eps
    lam = guess
    eps = max(1.0, target)
    status, lam_try, total, res = _newton(problem, eps, lam, settings)
    if status is not SolveStatus.CONVERGED:
        return status, lam_try, total, res
    lam = lam_try
    ratio = 0.1
    for _ in range(60):
        if eps <= target:
            return SolveStatus.CONVERGED, lam, total, res
        nxt = eps * ratio
        if nxt < max(target, 1e-4):
            nxt = target
        status, lam_try, iters, res_try = _newton(problem, nxt, lam, settings)
        total += iters
        if status is SolveStatus.INFEASIBLE:
            return status, lam_try, total, res_try
        if status is SolveStatus.CONVERGED:
            eps, lam, res = nxt, lam_try, res_try
            ratio = max(ratio * ratio, 0.01)
        else:
            ratio = np.sqrt(ratio)
            if ratio > 0.99:
                break
    return SolveStatus.FAILED, lam, total, res


def _grid(problem: ShootingProblem, settings: SolverSettings) -> feasibility.GridProblem:
    """The re-solve transcribed on the zero-order-hold grid of the convex checks.

    Another design model's grid is its steps' ``Φ(Δt)``, ``Γ(Δt)`` (issue 33).
    """
    if problem.design is not None:
        dt = settings.dt_grid_s
        steps = max(1, round(problem.horizon_s / dt))
        phi = np.broadcast_to(lti_stm(problem.design, dt), (steps, 6, 6))
        gam = np.broadcast_to(lti_input_matrix(problem.design, dt), (steps, 6, 3))
        return feasibility.grid_problem_from_steps(
            phi, gam, problem.x0, problem.xf, dt, problem.u_max_km_s2
        )
    return feasibility.grid_problem(
        problem.mean_motion_rad_s,
        problem.x0,
        problem.xf,
        problem.horizon_s,
        settings.dt_grid_s,
        problem.u_max_km_s2,
    )


def _multiplier_guess(problem: ShootingProblem, settings: SolverSettings) -> np.ndarray | None:
    return feasibility.min_fuel_costate(_grid(problem, settings), problem.mean_motion_rad_s)


def solve(
    problem: ShootingProblem,
    guess: np.ndarray,
    settings: SolverSettings | None = None,
    alternatives: Sequence[np.ndarray] = (),
) -> SolveResult:
    """Solve one shooting problem from the warm start ``guess``.

    One re-solve of paper Sec. "Receding-Horizon Indirect Guidance".

    Returns the costate with status ``converged``, ``infeasible`` (a
    certificate that no bounded control reaches ``x_f``) or ``failed``; on
    anything but ``converged`` the returned costate is the caller's guess.

    ``alternatives``: other warm starts (costates at the same time as
    ``guess``). At ε = 0 the warm attempt starts from whichever of ``guess``
    and these has the highest dual value (:func:`warm_starts`); the fallback
    chain still starts from ``guess``.
    """
    return solve_state(
        problem.mean_motion_rad_s,
        problem.u_max_km_s2,
        problem.x0,
        problem.xf,
        problem.horizon_s,
        problem.eps,
        guess,
        settings or SolverSettings(),
        alternatives,
        problem.design,
    )


def solve_state(
    n: float,
    u_max_km_s2: float,
    x0: np.ndarray,
    xf: np.ndarray,
    horizon_s: float,
    eps: float,
    guess: np.ndarray,
    settings: SolverSettings,
    alternatives: Sequence[np.ndarray] = (),
    design: LinearTimeInvariant | None = None,
) -> SolveResult:
    """:func:`solve` on plain values: the closed loop's re-solve (issue 17).

    ``design``: the design model other than CW (:attr:`ShootingProblem.design`).

    The warm attempt runs straight on the arrays given; the validated
    :class:`ShootingProblem` (copies) is built only when the fallback chain
    has to run, because the Python work around each re-solve was about a
    third of an adaptive closed-loop run.
    """
    start = time.perf_counter()
    guess = np.array(guess, dtype=float)
    warm = warm_attempt(
        kernel_model(n, design),
        u_max_km_s2,
        x0,
        xf,
        float(horizon_s),
        float(eps),
        warm_starts(guess, alternatives, eps),
        settings,
    )
    return after_warm(n, u_max_km_s2, x0, xf, horizon_s, eps, guess, settings, warm, start, design)


def after_warm(
    n: float,
    u_max_km_s2: float,
    x0: np.ndarray,
    xf: np.ndarray,
    horizon_s: float,
    eps: float,
    guess: np.ndarray,
    settings: SolverSettings,
    warm: tuple[SolveStatus, np.ndarray, int, float],
    start: float,
    design: LinearTimeInvariant | None = None,
) -> SolveResult:
    """How a re-solve ends once its warm attempt ``warm`` (:func:`warm_attempt`) is known.

    The fallback chain when it failed (and ``settings.fallback == "chain"``),
    else the warm attempt's result. ``start`` is the :func:`time.perf_counter`
    at which the re-solve began. Also the end of the re-solves whose warm
    attempt the compiled closed loop made (:mod:`cwrend_cli.physics._loop_kernels`).
    """
    status, lam, iters, res = warm
    if status is SolveStatus.FAILED and settings.fallback == "chain":
        problem = ShootingProblem(x0, float(horizon_s), float(eps), n, u_max_km_s2, xf, design)
        return _fallback_chain(problem, guess, settings, iters, res, start)
    return SolveResult(
        costate=lam if status is SolveStatus.CONVERGED else guess,
        status=status,
        step="warm",
        iterations=iters,
        residual_km=res,
        wall_time_s=time.perf_counter() - start,
        eps=float(eps),
        horizon_s=float(horizon_s),
    )


def _fallback_chain(
    problem: ShootingProblem,
    guess: np.ndarray,
    settings: SolverSettings,
    warm_iterations: int,
    warm_residual: float,
    start: float,
) -> SolveResult:
    """The fallback chain after a failed warm attempt (module docstring): how a re-solve ends.

    ``warm_iterations`` and ``warm_residual`` are the failed attempt's;
    ``start`` the :func:`time.perf_counter` at which the re-solve began (its
    wall time includes the warm attempt).
    """
    total = warm_iterations

    def done(
        status: SolveStatus,
        lam: np.ndarray,
        step: str,
        res: float,
        controls: np.ndarray | None = None,
    ) -> SolveResult:
        keep = lam if status is SolveStatus.CONVERGED else guess
        return SolveResult(
            costate=keep,
            status=status,
            step=step,
            iterations=total,
            residual_km=res,
            wall_time_s=time.perf_counter() - start,
            eps=problem.eps,
            horizon_s=problem.horizon_s,
            controls=controls,
        )

    first_res = warm_residual
    # The plan of last resort first (issue 16): held controls of the cone program at the
    # same ε; cheaper than the continuations and as good (measured, shooting.py docstring).
    plan = convex.solve(_grid(problem, settings), problem.eps, problem.mean_motion_rad_s)
    total += plan.iterations
    if plan.status is SolveStatus.CONVERGED:
        return done(plan.status, plan.costate, "socp_plan", plan.residual_km, plan.controls)
    if plan.status is SolveStatus.INFEASIBLE and classify_failure(problem) is plan.status:
        # the grid's certificate, confirmed for the continuous problem (issue 16, item 3)
        return done(plan.status, guess, "socp_plan", first_res)
    restarts: list[tuple[str, np.ndarray | None]] = [
        ("continuation_warm", guess),
        ("continuation_energy", None),
    ]
    for step, start_guess in restarts:
        if start_guess is None:
            start_guess = energy_optimal_costate(problem)
        status, lam, iters, res = _continuation(problem, start_guess, settings)
        total += iters
        if status is not SolveStatus.FAILED:
            return done(status, lam, step, res)
    mult = _multiplier_guess(problem, settings)
    if mult is not None:
        for sign in (1.0, -1.0):
            status, lam, iters, res = _newton(problem, problem.eps, sign * mult, settings)
            total += iters
            if status is not SolveStatus.FAILED:
                return done(status, lam, "socp_multiplier", res)
    # Every step failed without a certificate: the continuous-time dual bound decides.
    return done(classify_failure(problem), guess, "dual_bound", first_res)


def _evaluate(
    problem: ShootingProblem, costate: np.ndarray, nodes: int, want_hess: bool
) -> tuple[np.ndarray, np.ndarray]:
    """``Φ(T)·(x₀ + ∫W u dτ) = x(T)`` and ``Φ(T)·∂G/∂λ₀`` for a costate (any ``x_f``)."""
    gl_x, gl_w = _gauss_legendre(nodes)
    grad = np.empty(6)
    hess = np.empty((6, 6))
    ws = kern.workspace()
    kern.dual_evaluate(
        problem.kernel_model,
        np.ascontiguousarray(costate, dtype=float),
        -np.asarray(problem.x0, dtype=float),  # d = −x₀ makes G = x₀ + ∫ W u dτ
        float(problem.horizon_s),
        float(problem.eps),
        problem.u_max_km_s2,
        gl_x,
        gl_w,
        n_cells(problem.horizon_s),
        want_hess,
        grad,
        hess,
        ws,
    )
    phi = problem.transition(problem.horizon_s)
    return phi @ grad, phi @ hess


def terminal_state(problem: ShootingProblem, costate: np.ndarray, nodes: int = 12) -> np.ndarray:
    """``x(T)`` reached from ``x0`` under the control law with ``λ(0) = costate``."""
    return _evaluate(problem, costate, nodes, want_hess=False)[0]


def shooting_jacobian(problem: ShootingProblem, costate: np.ndarray, nodes: int = 12) -> np.ndarray:
    """Analytic ``∂x(T)/∂λ(0)`` (6×6), including the ε = 0 jump terms."""
    return _evaluate(problem, costate, nodes, want_hess=True)[1]


def switching_times(
    problem: ShootingProblem, costate: np.ndarray, t0: float = 0.0, t1: float | None = None
) -> np.ndarray:
    """Times in ``(t0, t1)`` where ``‖λ_v‖`` crosses ``1 ± ε`` (1 at ε = 0) [s]."""
    t1 = problem.horizon_s if t1 is None else t1
    breaks = np.empty(kern.MAX_BREAKS)
    minima = np.empty(kern.MAX_BREAKS)
    ws = kern.workspace()
    count, _ = kern.find_switches(
        problem.kernel_model,
        np.ascontiguousarray(costate, dtype=float),
        float(t0),
        float(t1),
        float(problem.eps),
        n_cells(t1 - t0),
        breaks,
        minima,
        ws,
    )
    return breaks[:count].copy()


def classify_failure(problem: ShootingProblem) -> SolveStatus:
    """``infeasible`` if the continuous-time dual bound certifies it, else ``failed``.

    Not in the paper (docs/solvers.md).

    :func:`~cwrend_cli.physics.guidance.feasibility.continuous_peak_thrust` is
    a certified lower bound of the least peak thrust reaching ``x_f``, so a
    feasible problem, however close to the boundary, is never labelled
    infeasible (the 1 s grid's minimum peak thrust, used before issue 16,
    overstates it by up to ~8e-4 relative).
    """
    peak = feasibility.continuous_peak_thrust(
        problem.mean_motion_rad_s, problem.x0, problem.xf, problem.horizon_s,
        design=problem.design,
    )  # fmt: skip
    return SolveStatus.INFEASIBLE if peak > problem.u_max_km_s2 else SolveStatus.FAILED
