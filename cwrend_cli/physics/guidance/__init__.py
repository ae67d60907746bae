"""Indirect minimum-fuel guidance: the shooting re-solve and its convex checks (paper Eqs. 5–10).

:mod:`~cwrend_cli.physics.guidance.shooting` is the typed API over the
compiled kernels of :mod:`~cwrend_cli.physics.guidance._kernels`;
:mod:`~cwrend_cli.physics.guidance.feasibility` holds the second-order-cone
checks on the zero-order-hold grid and
:mod:`~cwrend_cli.physics.guidance.convex` the smoothed minimum-fuel cone
program (the ``socp`` method and the shooting chain's plan of last resort);
:mod:`~cwrend_cli.physics.guidance.results` the outcome both return.
"""

from cwrend_cli.physics.guidance.results import SolveResult, SolveStatus
from cwrend_cli.physics.guidance.shooting import (
    EPS_BANG_BANG,
    KERNEL_STATUS,
    ShootingProblem,
    SolverSettings,
    after_warm,
    classify_failure,
    control,
    energy_optimal_costate,
    kernel_model,
    n_cells,
    shooting_jacobian,
    solve,
    solve_state,
    switching_times,
    terminal_state,
    warm_attempt,
)

__all__ = [
    "EPS_BANG_BANG",
    "KERNEL_STATUS",
    "ShootingProblem",
    "SolveResult",
    "SolveStatus",
    "SolverSettings",
    "after_warm",
    "classify_failure",
    "control",
    "energy_optimal_costate",
    "kernel_model",
    "n_cells",
    "shooting_jacobian",
    "solve",
    "solve_state",
    "switching_times",
    "terminal_state",
    "warm_attempt",
]
