"""Outcome of one guidance re-solve, shooting or cone program.

A re-solve of paper Sec. "Receding-Horizon Indirect Guidance".
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np


class SolveStatus(StrEnum):
    """Outcome of one re-solve."""

    CONVERGED = "converged"
    INFEASIBLE = "infeasible"
    FAILED = "failed"


@dataclass(frozen=True)
class SolveResult:
    """Outcome of one re-solve; ``costate`` is ``λ(0)`` at the solve time.

    ``controls`` is set when the plan is a sequence of held controls on the
    zero-order-hold grid rather than a costate (the cone-program method and the
    shooting chain's ``socp_plan`` step): row j is the control [km/s²] held over
    ``[t_0 + jΔt, t_0 + (j+1)Δt)`` from the solve time ``t_0``.
    """

    costate: np.ndarray
    status: SolveStatus
    step: str  # fallback step that ended the solve: warm, continuation_warm, ...
    iterations: int
    residual_km: float  # ‖x(T) − x_f‖ (6-vector norm of km and km/s; not in the paper)
    wall_time_s: float
    eps: float
    horizon_s: float
    controls: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        """True when the solver converged (whatever the residual threshold)."""
        return self.status is SolveStatus.CONVERGED
