"""From the validated configuration to the physics core's typed parameters.

The one place where pydantic models become the frozen dataclasses of
:mod:`cwrend_cli.physics.params`. The two mirror each other field for field,
so this is a plain copy: no value is computed or changed here, and a dotted
key names the same value on both sides (which is how dispersions are applied
to typed parameters, :func:`with_values`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from typing import Any

from cwrend_cli.config.schema import CwrendConfig, DegradationWindow
from cwrend_cli.physics import params


def window_of(w: DegradationWindow) -> params.Window:
    """One degradation window as the physics core's :class:`~params.Window`."""
    return params.Window(start_s=w.start_s, end_s=w.end_s, r_scale=w.r_scale, bias_km=w.bias_km)


def windows_of(cfg: CwrendConfig) -> tuple[params.Window, ...]:
    """The configured degradation windows, in order (later ones win where they overlap)."""
    return tuple(window_of(w) for w in cfg.degradation.windows)


def problem_of(cfg: CwrendConfig) -> params.Problem:
    """The closed-loop problem described by ``cfg`` (every section but noise and output)."""
    sc, est, sch, gd, so = cfg.scenario, cfg.estimator, cfg.schedule, cfg.guidance, cfg.solver
    return params.Problem(
        scenario=params.Scenario(
            mean_motion_rad_s=sc.mean_motion_rad_s,
            horizon_s=sc.horizon_s,
            dt_s=sc.dt_s,
            x0=sc.x0,
            xf=sc.xf,
            u_max_km_s2=sc.u_max_km_s2,
        ),
        estimator=params.Estimator(
            r_nominal_km2=est.r_nominal_km2,
            q_process=est.q_process,
            p0=est.p0,
            initial_error=est.initial_error,
        ),
        schedule=params.Schedule(
            beta=sch.beta,
            nis_offset=sch.nis_offset,
            score_lowpass=sch.score_lowpass,
            kappa_mtf=sch.kappa_mtf,
            score_max=sch.score_max,
            eps_min=sch.eps_min,
            eps_max=sch.eps_max,
            alpha_eps=sch.alpha_eps,
            deadband=sch.deadband,
            eps_saturation=sch.eps_saturation,
            eps_fixed=sch.eps_fixed,
        ),
        guidance=params.Guidance(
            t_resolve_s=gd.t_resolve_s,
            t_min_rem_s=gd.t_min_rem_s,
            resolve_timing=gd.resolve_timing,
            hold=gd.hold,
        ),
        solver=params.Solver(
            fallback=so.fallback,
            on_infeasible=so.on_infeasible,
            success_residual=so.success_residual,
            tol_pos_km=so.tol_pos_km,
            tol_vel_km_s=so.tol_vel_km_s,
            max_iter=so.max_iter,
            quadrature_nodes=so.quadrature_nodes,
        ),
        degradation=params.Degradation(windows=windows_of(cfg)),
        truth=params.Truth(**cfg.truth.model_dump()),
        actuator=params.Actuator(**cfg.actuator.model_dump()),
    )


def _replaced(node: Any, parts: list[str], value: Any) -> Any:
    """``node`` (a frozen dataclass or tuple) with the value at ``parts`` replaced."""
    head, rest = parts[0], parts[1:]
    if isinstance(node, tuple):
        index = int(head)
        item = value if not rest else _replaced(node[index], rest, value)
        return (*node[:index], item, *node[index + 1 :])
    child = value if not rest else _replaced(getattr(node, head), rest, value)
    return dataclasses.replace(node, **{head: child})


def with_values(problem: params.Problem, assignment: Iterable[tuple[str, Any]]) -> params.Problem:
    """``problem`` with each ``(dotted.key, value)`` set, e.g. ``("scenario.x0.2", 31.2)``.

    The keys are configuration keys; the values must already have been
    validated against the configuration model (the campaign plan does that
    once per run), so nothing is checked here.
    """
    for key, value in assignment:
        problem = _replaced(problem, key.split("."), value)
    return problem
