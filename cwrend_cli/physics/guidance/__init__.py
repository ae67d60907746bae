"""Indirect minimum-fuel guidance: the shooting re-solve and its convex checks (SPEC §1, §5).

:mod:`~cwrend_cli.physics.guidance.shooting` is the typed API over the
compiled kernels of :mod:`~cwrend_cli.physics.guidance._kernels`;
:mod:`~cwrend_cli.physics.guidance.feasibility` holds the second-order-cone
programs on the zero-order-hold grid.
"""

from cwrend_cli.physics.guidance.shooting import (
    EPS_BANG_BANG,
    ShootingProblem,
    SolveResult,
    SolverSettings,
    SolveStatus,
    classify_failure,
    control,
    energy_optimal_costate,
    n_cells,
    shooting_jacobian,
    solve,
    switching_times,
    terminal_state,
)

__all__ = [
    "EPS_BANG_BANG",
    "ShootingProblem",
    "SolveResult",
    "SolveStatus",
    "SolverSettings",
    "classify_failure",
    "control",
    "energy_optimal_costate",
    "n_cells",
    "shooting_jacobian",
    "solve",
    "switching_times",
    "terminal_state",
]
