"""What a run is judged by: Δv, miss, fuel penalty and its re-solve statistics.

The quantities paper Sec. "Numerical Results and Discussion" reports.

Δv is the trapezoid of ‖u‖ sampled on the grid t = 0 … T (the authors' code's
convention, kept as ``delta_v_km_s``; in closed loop no control is computed at
t = T, so that sample is 0); the miss is the distance ‖r(T) − r_f‖; the fuel
penalty is Δv relative to the open-loop fuel-optimal Δv, both trapezoids
(paper Table 2). Solve statistics are over the receding-horizon re-solves,
not the initial solve (a convention of cwrend; the paper does not say).

The applied Δv (issue 33, item 3) is what the thruster did: the control u_k
is held over [t_k, t_k+1) (zero-order hold), so the impulse is Σ_k ‖u_k‖ Δt_k
over the N steps. On a uniform grid the trapezoid is Δt (‖u₀‖/2 + ‖u₁‖ + … +
‖u_N−1‖ + ‖u_N‖/2), hence trapezoid − applied = (‖u_N‖ − ‖u₀‖) Δt / 2: the
trapezoid drops half of the first step's impulse (‖u₀‖ = u_max on a fixed-ε
run, 0.4 m/s with the paper's Δt = 1 s and u_max = 8e-4 km/s²). The applied
fuel penalty compares it with the exact continuous fuel optimum (u_max times
the bang-bang plan's burn time, its switching times solved to machine
precision: :func:`~cwrend_cli.physics.guidance.fuel_optimum.exact_bang_bang`),
so no run that reaches the target can have a negative one; the paper's
compares two trapezoids, and the fuel optimum's trapezoid (141 u_max on the
paper scenario, against an exact 141.327 s of burn) is below the optimum.

Filter consistency (issue 15, item 6), the chi-square tests of Bar-Shalom,
Li & Kirubarajan 2001, *Estimation with Applications to Tracking and
Navigation*, §5.4: the NIS ``νᵀ S⁻¹ ν`` of paper Eq. 22 (S with the nominal R) is
χ² with 3 degrees of freedom for a filter whose model matches the world, so
its mean is 3; the NEES ``(x̂ − x)ᵀ P⁻¹ (x̂ − x)`` against the simulated truth
is χ² with 6, mean 6. Means well below say the filter is conservative (its P
larger than its errors: e.g. a process noise Q where the truth has none),
above that it is overconfident (model mismatch, faults). The NIS mean is
taken over the nominal periods only (:func:`mean_nis_nominal`), because a
degradation window inflates it by design.
Units: km, s, km/s, km/s².
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from cwrend_cli.physics.params import FloatArray

if TYPE_CHECKING:  # types only: simulation and references import this module
    from cwrend_cli.physics.references import OpenLoopResult
    from cwrend_cli.physics.simulation import RunResult


def delta_v(t_s: FloatArray, u: FloatArray) -> float:
    """Δv [km/s]: trapezoid of ‖u‖ over the grid (a convention of cwrend; not in the paper)."""
    return float(np.trapezoid(np.linalg.norm(u, axis=1), t_s))


def applied_delta_v(t_s: FloatArray, u: FloatArray) -> float:
    """Applied Δv [km/s]: Σ_k ‖u_k‖ (t_k+1 − t_k), k = 0 … N−1, the zero-order-hold impulse.

    Row k of ``u`` is the control held over [t_k, t_k+1); the last row (t = T)
    starts no step and does not count (module docstring; issue 33, item 3).
    """
    norms = np.linalg.norm(np.asarray(u, dtype=float), axis=1)
    return float(np.dot(norms[:-1], np.diff(np.asarray(t_s, dtype=float))))


def cumulative_delta_v(t_s: FloatArray, u_norm: FloatArray) -> FloatArray:
    """Cumulative trapezoid of ‖u‖ over the grid [km/s]; its last value is :func:`delta_v`."""
    t = np.asarray(t_s, dtype=float)
    a = np.asarray(u_norm, dtype=float)
    out = np.zeros_like(a)
    if a.size > 1:
        out[1:] = np.cumsum(0.5 * (a[1:] + a[:-1]) * np.diff(t))
    return out


def fuel_penalty_pct(delta_v_km_s: float, fuel_delta_v_km_s: float) -> float:
    """Δv above the open-loop fuel optimum [%] (paper Table 2's "fuel penalty")."""
    return 100.0 * (delta_v_km_s / fuel_delta_v_km_s - 1.0)


def fuel_penalty_applied_pct(delta_v_applied_km_s: float, fuel: OpenLoopResult) -> float:
    """Applied Δv above the exact continuous fuel optimum [%] (issue 33, item 3).

    ``fuel.delta_v_continuous_km_s``: u_max times the fuel-optimal plan's burn
    time (module docstring). Not negative for a run that reaches the target:
    no bounded control does with less.
    """
    return fuel_penalty_pct(delta_v_applied_km_s, fuel.delta_v_continuous_km_s)


@dataclass(frozen=True)
class RunMetrics:
    """The figures of merit of one closed-loop run or open-loop reference."""

    delta_v_km_s: float  # trapezoid of ‖u‖ (the paper's convention)
    miss_km: float
    fuel_penalty_pct: float  # trapezoid against the fuel optimum's trapezoid (paper Table 2)
    n_solves: int
    n_converged: int
    n_infeasible: int
    n_failed: int
    solve_success_pct: float  # converged with ‖residual‖ below the threshold (not in the paper)
    solve_mean_ms: float  # wall time per solve
    solve_max_ms: float
    mean_nis_nominal: float  # mean NIS outside the degradation windows; 3 if consistent
    mean_nees: float  # mean NEES over rows 1 … N; 6 if consistent (NaN for references)
    delta_v_applied_km_s: float  # Σ‖u_k‖Δt_k (references: ∫‖u‖dt of the continuous plan)
    fuel_penalty_applied_pct: float  # applied Δv against the exact continuous fuel optimum


def mean_nis_nominal(nis: FloatArray, window: np.ndarray) -> float:
    """Mean NIS over the rows with a measurement outside every degradation window.

    ``window`` is the row's degradation-window index (−1 none,
    :attr:`~cwrend_cli.physics.simulation.RunResult.window`: the window whose
    noise the row's measurement carries). Rows without a measurement (row 0,
    dropouts) have NaN NIS and are skipped. E[NIS] = 3 (the measurement's
    dimension, χ²₃; paper Eq. 22, Bar-Shalom et al. 2001, §5.4.2) for a
    consistent filter. NaN when no such row exists.
    """
    values = np.asarray(nis, dtype=float)[np.asarray(window) < 0]
    values = values[~np.isnan(values)]
    return float(values.mean()) if values.size else float("nan")


def mean_nees(nees: FloatArray) -> float:
    """Mean NEES over rows 1 … N (row 0, the initial error against P0, left out).

    E[NEES] = 6 (the state's dimension, χ²₆; Bar-Shalom et al. 2001, §5.4.2)
    for a consistent filter; a NaN row (a covariance not positive definite)
    makes it NaN.
    """
    values = np.asarray(nees, dtype=float)[1:]
    return float(values.mean()) if values.size else float("nan")


#: Degrees of freedom of the NEES (the state's dimension) and of the NIS (the measurement's).
NEES_DOF = 6
NIS_DOF = 3
#: Two-sided probability of the χ² consistency bands.
BAND_PROBABILITY = 0.95


def chi2_band(
    n_runs: npt.ArrayLike, dof: int, probability: float = BAND_PROBABILITY
) -> tuple[FloatArray, FloatArray]:
    """The two-sided ``probability`` band of the mean of ``n_runs`` independent χ²_dof values.

    The ensemble test of Bar-Shalom, Li & Kirubarajan 2001, §5.4.2: for a
    consistent filter the NEES of each of N independent runs at one step is
    χ² with n = 6 degrees of freedom (the NIS with m = 3), so N times their
    average is χ²(N n), and the average lies in
    ``[χ²⁻¹(α/2; N n) / N, χ²⁻¹(1 − α/2; N n) / N]`` with probability
    1 − α = ``probability``. Element-wise over ``n_runs``; NaN where it is
    below 1. E.g. N = 1, n = 6: [1.24, 14.45]; N = 20: [4.58, 7.61] at 95 %.
    """
    from scipy.special import chdtri  # on first use (0.4 s): not for every import of metrics

    n = np.asarray(n_runs, dtype=float)
    tail = (1.0 - probability) / 2.0
    valid = n >= 1
    size = np.where(valid, n, 1.0)
    low: FloatArray = np.where(valid, chdtri(dof * size, 1.0 - tail) / size, np.nan)
    high: FloatArray = np.where(valid, chdtri(dof * size, tail) / size, np.nan)
    return low, high


def mean_in_band(values: npt.ArrayLike, dof: int) -> tuple[float, float, float, int]:
    """Mean of the finite ``values`` (one χ²_dof statistic per run), its band and their count.

    ``(mean, low, high, n)``: the band of :func:`chi2_band` for the ``n``
    runs with a finite value (a NaN mean NIS: no nominal measurement); NaN
    throughout for none.
    """
    x = np.asarray(values, dtype=float)
    finite = x[np.isfinite(x)]
    low, high = chi2_band(finite.size, dof)
    mean = float(finite.mean()) if finite.size else float("nan")
    return mean, float(low), float(high), int(finite.size)


def _times(times_ms: Sequence[float]) -> tuple[float, float]:
    """Mean and max of solve wall times [ms] (NaN when there is none)."""
    arr = np.array(times_ms) if times_ms else np.array([np.nan])
    return float(np.mean(arr)), float(np.max(arr))


def run_metrics(result: RunResult, fuel: OpenLoopResult) -> RunMetrics:
    """Metrics of a closed-loop run; solve statistics over its re-solves.

    ``fuel``: the scenario's open-loop fuel-optimal reference (both fuel penalties).
    """
    rs = result.resolves
    applied = applied_delta_v(result.t_s, result.u)
    mean_ms, max_ms = _times([s.wall_time_ms for s in rs])
    statuses = [s.status for s in rs]
    return RunMetrics(
        delta_v_km_s=result.delta_v_km_s,
        miss_km=result.miss_km,
        fuel_penalty_pct=fuel_penalty_pct(result.delta_v_km_s, fuel.delta_v_km_s),
        n_solves=len(rs),
        n_converged=statuses.count("converged"),
        n_infeasible=statuses.count("infeasible"),
        n_failed=statuses.count("failed"),
        solve_success_pct=100.0 * sum(s.success for s in rs) / len(rs) if rs else float("nan"),
        solve_mean_ms=mean_ms,
        solve_max_ms=max_ms,
        mean_nis_nominal=mean_nis_nominal(result.nis, result.window),
        mean_nees=mean_nees(result.nees),
        delta_v_applied_km_s=applied,
        fuel_penalty_applied_pct=fuel_penalty_applied_pct(applied, fuel),
    )


def reference_metrics(ref: OpenLoopResult, fuel: OpenLoopResult) -> RunMetrics:
    """Metrics of an open-loop reference; solve statistics over its continuation solves.

    Its applied Δv is the continuous plan's ∫‖u‖dt (no zero-order hold: what a
    thruster following the plan would do); the fuel reference's applied
    penalty is 0 by construction.
    """
    mean_ms, max_ms = _times([s.wall_time_s * 1e3 for s in ref.solves])
    return RunMetrics(
        delta_v_km_s=ref.delta_v_km_s,
        miss_km=ref.miss_km,
        fuel_penalty_pct=fuel_penalty_pct(ref.delta_v_km_s, fuel.delta_v_km_s),
        n_solves=len(ref.solves),
        n_converged=sum(s.converged for s in ref.solves),
        n_infeasible=0,
        n_failed=sum(not s.converged for s in ref.solves),
        solve_success_pct=100.0 if ref.solves else float("nan"),
        solve_mean_ms=mean_ms,
        solve_max_ms=max_ms,
        mean_nis_nominal=float("nan"),  # open loop: no filter
        mean_nees=float("nan"),
        delta_v_applied_km_s=ref.delta_v_continuous_km_s,
        fuel_penalty_applied_pct=fuel_penalty_applied_pct(ref.delta_v_continuous_km_s, fuel),
    )
