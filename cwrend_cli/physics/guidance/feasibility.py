"""Convex checks on the zero-order-hold grid, solved with Clarabel (SPEC §5).

Three second-order-cone problems over ``N = t_rem/Δt`` held controls ``u_j``
with the exact discrete dynamics ``x_N = Φᴺ x̂ + Σ_j Φ^{N−1−j} Γ u_j``:

* :func:`min_peak_thrust` — the smallest ``max_j ‖u_j‖`` that reaches ``x_f``.
  Above ``u_max`` the re-solve has no solution on the grid (SPEC §5).
* :func:`min_fuel_costate` — the discretised minimum-fuel problem; the
  multiplier ``ν`` of its terminal constraint gives a costate guess
  ``λ(0) = Φ(t_rem)ᵀ ν`` for the shooting solver's last fallback step.
* :func:`min_miss_controls` — bounded controls that minimise the terminal
  position miss, used by ``solver.on_infeasible = "min_miss"``.

Units: km, s, km/s, km/s². Decision variables are scaled by ``u_max`` and the
terminal rows by the horizon so that the conic solver sees O(1) numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp

from cwrend_cli.physics.dynamics import input_matrix, stm


@dataclass(frozen=True)
class GridProblem:
    """The ZOH-grid transcription of one re-solve: ``Σ_j M_j u_j = b``."""

    blocks: np.ndarray  # (N, 6, 3): M_j = Φ^{N−1−j} Γ
    rhs: np.ndarray  # (6,): b = x_f − Φᴺ x̂
    row_scale: np.ndarray  # (6,): multiplies the terminal rows
    dt_s: float
    u_max_km_s2: float


def grid_problem(
    n: float, x0: np.ndarray, xf: np.ndarray, horizon_s: float, dt_s: float, u_max_km_s2: float
) -> GridProblem:
    """Transcribe a re-solve on the ``dt_s`` zero-order-hold grid."""
    steps = max(1, round(horizon_s / dt_s))
    phi = stm(n, dt_s)
    gam = input_matrix(n, dt_s)
    blocks = np.empty((steps, 6, 3))
    acc = gam.copy()
    for j in range(steps - 1, -1, -1):
        blocks[j] = acc
        acc = phi @ acc
    rhs = xf - stm(n, steps * dt_s) @ x0
    t = steps * dt_s
    row_scale = np.array([1.0, 1.0, 1.0, t, t, t]) / (u_max_km_s2 * t * t)
    return GridProblem(blocks, rhs, row_scale, dt_s, u_max_km_s2)


def _solve(
    p: sp.csc_matrix, q: np.ndarray, a: sp.csc_matrix, b: np.ndarray, cones: list[Any]
) -> Any:
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = 1e-10
    settings.tol_gap_rel = 1e-10
    settings.tol_feas = 1e-10
    solver = clarabel.DefaultSolver(p, q, a, b, cones, settings)
    return solver.solve()


def _solved(sol: Any) -> bool:
    return bool(sol.status in (clarabel.SolverStatus.Solved, clarabel.SolverStatus.AlmostSolved))


def _terminal_rows(g: GridProblem, n_vars: int) -> tuple[sp.csc_matrix, np.ndarray]:
    """Equality rows ``S M ũ = S b`` with ``u = u_max ũ`` (controls are the first 3N vars)."""
    steps = g.blocks.shape[0]
    m = np.transpose(g.blocks, (1, 0, 2)).reshape(6, 3 * steps) * g.u_max_km_s2
    m = m * g.row_scale[:, None]
    a = sp.hstack([sp.csc_matrix(m), sp.csc_matrix((6, n_vars - 3 * steps))]).tocsc()
    return a, g.rhs * g.row_scale


def _cone_rows(steps: int, n_vars: int, head_cols: np.ndarray | None) -> sp.csc_matrix:
    """Rows of N second-order cones ``(head_j, ũ_j) ∈ SOC(4)`` as ``s = b − A x``.

    Cone j has rows 4j … 4j+3: the head is ``x[head_cols[j]]`` (or the constant
    in ``b`` when ``head_cols`` is None) and the body is ``ũ_j``.
    """
    j = np.arange(steps)
    body_rows = (4 * j[:, None] + 1 + np.arange(3)).ravel()
    body_cols = (3 * j[:, None] + np.arange(3)).ravel()
    rows = [body_rows]
    cols = [body_cols]
    if head_cols is not None:
        rows.append(4 * j)
        cols.append(head_cols)
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    return sp.csc_matrix((-np.ones(r.size), (r, c)), shape=(4 * steps, n_vars))


def min_peak_thrust(g: GridProblem) -> float:
    """Minimum over grid controls of ``max_j ‖u_j‖`` reaching ``x_f`` [km/s²]; inf if unsolved."""
    steps = g.blocks.shape[0]
    n_vars = 3 * steps + 1  # ũ_0 … ũ_{N−1}, s̃
    a_eq, b_eq = _terminal_rows(g, n_vars)
    cones = _cone_rows(steps, n_vars, np.full(steps, 3 * steps))  # (s̃, ũ_j) ∈ SOC
    a = sp.vstack([a_eq, cones]).tocsc()
    b = np.concatenate([b_eq, np.zeros(4 * steps)])
    q = np.zeros(n_vars)
    q[-1] = 1.0
    sol = _solve(
        sp.csc_matrix((n_vars, n_vars)),
        q,
        a,
        b,
        [clarabel.ZeroConeT(6)] + [clarabel.SecondOrderConeT(4)] * steps,
    )
    if not _solved(sol):
        return float("inf")
    return float(sol.x[-1]) * g.u_max_km_s2


def min_fuel_costate(g: GridProblem, n: float) -> np.ndarray | None:
    """Costate guess ``λ(0) = Φ(t_rem)ᵀ ν`` from the discretised minimum-fuel SOCP.

    ``ν`` is the multiplier of the terminal constraint in the convention
    ``L = Σ Δt‖u_j‖ − νᵀ(Σ M_j u_j − b)``, under which held thrust points along
    ``M_jᵀ ν`` and switches where ``‖M_jᵀ ν‖ = Δt``; the shooting costate is
    ``λ(0) = −Φ(t_rem)ᵀ ν``. Returns None when the SOCP is infeasible.
    """
    steps = g.blocks.shape[0]
    n_vars = 4 * steps  # ũ (3N), t̃ (N)
    a_eq, b_eq = _terminal_rows(g, n_vars)
    epigraph = _cone_rows(steps, n_vars, 3 * steps + np.arange(steps))  # (t̃_j, ũ_j) ∈ SOC
    bound = _cone_rows(steps, n_vars, None)  # (1, ũ_j) ∈ SOC: ‖u_j‖ ≤ u_max
    a = sp.vstack([a_eq, epigraph, bound]).tocsc()
    b_bound = np.zeros(4 * steps)
    b_bound[0::4] = 1.0
    b = np.concatenate([b_eq, np.zeros(4 * steps), b_bound])
    q = np.zeros(n_vars)
    q[3 * steps :] = 1.0
    sol = _solve(
        sp.csc_matrix((n_vars, n_vars)),
        q,
        a,
        b,
        [clarabel.ZeroConeT(6)] + [clarabel.SecondOrderConeT(4)] * (2 * steps),
    )
    if not _solved(sol):
        return None
    # Clarabel: q + Aᵀz = 0 with objective Σ t̃ = Σ Δt‖u‖/(Δt u_max); undo both scalings.
    z_eq = np.asarray(sol.z[:6]) * g.row_scale * g.dt_s * g.u_max_km_s2
    horizon = steps * g.dt_s
    costate: np.ndarray = stm(n, horizon).T @ z_eq
    return costate


def min_miss_controls(g: GridProblem, velocity_weight_s: float) -> np.ndarray | None:
    """Bounded grid controls (N, 3) minimising ``‖Δr(T)‖² + (w‖Δv(T)‖)²`` (SOC epigraph).

    ``velocity_weight_s`` converts the terminal velocity error into a
    position-like error [s]. Returns None if the SOCP fails.
    """
    steps = g.blocks.shape[0]
    n_vars = 3 * steps + 1  # ũ, e (epigraph of the weighted miss)
    m = np.transpose(g.blocks, (1, 0, 2)).reshape(6, 3 * steps) * g.u_max_km_s2
    weights = np.array([1.0, 1.0, 1.0, velocity_weight_s, velocity_weight_s, velocity_weight_s])
    scale = 1.0 / (g.u_max_km_s2 * max(steps * g.dt_s, 1.0) ** 2)
    wm = m * (weights * scale)[:, None]
    wb = g.rhs * weights * scale
    # (e, W(M ũ − b)) ∈ SOC(7):  s = b_c − A x  with  A = [[−1, 0], [−W M, 0]], b_c = [0, −W b]
    top = sp.csc_matrix(([-1.0], ([0], [3 * steps])), shape=(1, n_vars))
    body = sp.hstack([sp.csc_matrix(-wm), sp.csc_matrix((6, 1))])
    bound = _cone_rows(steps, n_vars, None)  # (1, ũ_j) ∈ SOC
    a = sp.vstack([top, body, bound]).tocsc()
    b_bound = np.zeros(4 * steps)
    b_bound[0::4] = 1.0
    b = np.concatenate([np.zeros(1), -wb, b_bound])
    q = np.zeros(n_vars)
    q[-1] = 1.0
    sol = _solve(
        sp.csc_matrix((n_vars, n_vars)),
        q,
        a,
        b,
        [clarabel.SecondOrderConeT(7)] + [clarabel.SecondOrderConeT(4)] * steps,
    )
    if not _solved(sol):
        return None
    u = np.asarray(sol.x[: 3 * steps]).reshape(steps, 3) * g.u_max_km_s2
    # Interior-point solutions may exceed the bound by the solver tolerance: project.
    norms = np.linalg.norm(u, axis=1)
    over = norms > g.u_max_km_s2
    u[over] *= (g.u_max_km_s2 / norms[over])[:, None]
    return u
