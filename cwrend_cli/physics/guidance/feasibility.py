"""Convex checks on the zero-order-hold grid, solved with Clarabel (not in the paper).

See docs/solvers.md.

Three second-order-cone problems over ``N = t_rem/Δt`` held controls ``u_j``
with the exact discrete dynamics ``x_N = Φᴺ x̂ + Σ_j Φ^{N−1−j} Γ u_j``:

* :func:`min_peak_thrust` — the smallest ``max_j ‖u_j‖`` that reaches ``x_f``.
  Above ``u_max`` the re-solve has no solution on the grid (docs/method.md).
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

from cwrend_cli.physics.design_models import LinearTimeInvariant, lti_stm
from cwrend_cli.physics.dynamics import cw_system, input_matrix, stm


@dataclass(frozen=True)
class GridProblem:
    """The ZOH-grid transcription of one re-solve: ``Σ_j M_j u_j = b``."""

    blocks: np.ndarray  # (N, 6, 3): M_j = Φ^{N−1−j} Γ
    rhs: np.ndarray  # (6,): b = x_f − Φᴺ x̂
    row_scale: np.ndarray  # (6,): multiplies the terminal rows
    dt_s: float
    u_max_km_s2: float
    #: Φ(t_N, t_0) of a design model other than CW (issue 33); None: CW's Φ(N Δt)
    transition: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class CondensedSteps:
    """The steps of a linear design model condensed onto their common end t_K (issue 33).

    Every re-solve's grid ends at the loop's final time t_K and starts at some
    step k0, so its blocks are the last ``K − k0`` rows of ``blocks`` and its
    transition is ``to_end[k0]``: condensed once per design model and
    scenario, sliced per re-solve (as :func:`_power_blocks` does for CW).
    """

    blocks: np.ndarray  # (K, 6, 3): M_j = Φ_{K−1} ⋯ Φ_{j+1} Γ_j [s, s²]
    to_end: np.ndarray  # (K + 1, 6, 6): Φ(t_K, t_j) = Φ_{K−1} ⋯ Φ_j; to_end[K] = I


def condense(phi: np.ndarray, gam: np.ndarray) -> CondensedSteps:
    """Condense the steps ``phi`` (K, 6, 6), ``gam`` (K, 6, 3) onto t_K (read-only arrays).

    Any linear design model (time-varying too): step j maps
    ``x_{j+1} = Φ_j x_j + Γ_j u_j``, so ``x_K = Φ(t_K, t_{k0}) x_{k0} + Σ_{j ≥ k0} M_j u_j``
    with ``M_j = Φ_{K−1} ⋯ Φ_{j+1} Γ_j``. One backward pass from t_K (the
    product grows on the right), so that row j does not depend on where a
    grid starts.
    """
    steps = phi.shape[0]
    blocks = np.empty((steps, 6, 3))
    to_end = np.empty((steps + 1, 6, 6))
    acc = np.eye(6)
    to_end[steps] = acc
    for j in range(steps - 1, -1, -1):
        blocks[j] = acc @ gam[j]
        acc = acc @ phi[j]
        to_end[j] = acc
    blocks.flags.writeable = False
    to_end.flags.writeable = False
    return CondensedSteps(blocks, to_end)


def grid_problem_from_condensed(
    c: CondensedSteps,
    steps: int,
    x0: np.ndarray,
    xf: np.ndarray,
    dt_s: float,
    u_max_km_s2: float,
) -> GridProblem:
    """Transcribe a re-solve over the last ``steps`` steps of ``c``: from x̂ = ``x0`` to t_K.

    ``b = x_f − Φ(t_K, t_{k0}) x̂``, ``k0 = K − steps``; the transition is kept for
    the costate (:func:`costate_from_multiplier`). Row scaling as :func:`grid_problem`.
    """
    k0 = c.blocks.shape[0] - steps
    transition = c.to_end[k0]
    scale = row_scale(steps * dt_s, u_max_km_s2)
    return GridProblem(
        c.blocks[k0:], xf - transition @ x0, scale, dt_s, u_max_km_s2, transition=transition
    )


def grid_problem_from_steps(
    phi: np.ndarray,
    gam: np.ndarray,
    x0: np.ndarray,
    xf: np.ndarray,
    dt_s: float,
    u_max_km_s2: float,
) -> GridProblem:
    """Transcribe a re-solve over all the steps of ``phi`` (K, 6, 6) and ``gam`` (K, 6, 3).

    :func:`condense` then :func:`grid_problem_from_condensed`; a loop that
    re-solves many times condenses once and slices instead.
    """
    return grid_problem_from_condensed(condense(phi, gam), phi.shape[0], x0, xf, dt_s, u_max_km_s2)


def row_scale(t: float, u_max_km_s2: float) -> np.ndarray:
    """The terminal rows' scale of a grid of length ``t`` [s]: position 1/(u_max t²), velocity
    1/(u_max t)."""
    return np.array([1.0, 1.0, 1.0, t, t, t]) / (u_max_km_s2 * t * t)


def _transition(g: GridProblem, n: float) -> np.ndarray:
    """Φ(t_N, t_0) of the grid's design model (CW's closed form unless it carries one)."""
    if g.transition is not None:
        return g.transition
    return stm(n, g.blocks.shape[0] * g.dt_s)


def grid_problem(
    n: float, x0: np.ndarray, xf: np.ndarray, horizon_s: float, dt_s: float, u_max_km_s2: float
) -> GridProblem:
    """Transcribe a re-solve on the ``dt_s`` zero-order-hold grid."""
    steps = max(1, round(horizon_s / dt_s))
    rhs = xf - stm(n, steps * dt_s) @ x0
    return GridProblem(
        grid_blocks(n, dt_s, steps), rhs, row_scale(steps * dt_s, u_max_km_s2), dt_s, u_max_km_s2
    )


def grid_blocks(n: float, dt_s: float, steps: int) -> np.ndarray:
    """The terminal blocks ``Φ^{N−1−j} Γ`` (N, 6, 3) [s, s²] of a ``steps``-step grid
    (:func:`grid_problem`'s, read-only), without the rest of its problem."""
    return _power_blocks(n, dt_s, steps)[-steps:]


_BLOCKS: dict[tuple[float, float], np.ndarray] = {}


def _power_blocks(n: float, dt_s: float, steps: int) -> np.ndarray:
    """Read-only ``(K, 6, 3)`` stack with row ``K−1−i = Φ^i Γ``, ``K ≥ steps``.

    Each power is the previous one times Φ, so the last ``steps`` rows do not
    depend on ``K``: the longest stack built so far for ``(n, Δt)`` is kept and
    sliced (a pure memo; a re-solve's horizon only shrinks).
    """
    cached = _BLOCKS.get((n, dt_s))
    if cached is not None and cached.shape[0] >= steps:
        return cached
    phi = stm(n, dt_s)
    blocks = np.empty((steps, 6, 3))
    acc = input_matrix(n, dt_s)
    for j in range(steps - 1, -1, -1):
        blocks[j] = acc
        acc = phi @ acc
    blocks.flags.writeable = False
    _BLOCKS[(n, dt_s)] = blocks
    return blocks


def solve_cone(
    p: sp.csc_matrix, q: np.ndarray, a: sp.csc_matrix, b: np.ndarray, cones: list[Any]
) -> Any:
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = 1e-10
    settings.tol_gap_rel = 1e-10
    settings.tol_feas = 1e-10
    # Measured on the 1,264 cone programs of the four socp architectures' closed loops
    # (seeds 0–3, issue 16/17): without iterative refinement and presolve (our problems
    # have no redundant rows) 17.4 → 12.4 ms CPU per solve, the same statuses, the plans'
    # terminal miss ≤ 2.8e-8 km (was ≤ 2.0e-9 km), controls within 1.7e-6 km/s².
    settings.iterative_refinement_enable = False
    settings.presolve_enable = False
    solver = clarabel.DefaultSolver(p, q, a, b, cones, settings)
    return solver.solve()


def held_controls(g: GridProblem, sol: Any) -> np.ndarray:
    """The controls (N, 3) [km/s²] of a solved program whose first 3N variables are ``ũ``.

    Interior-point solutions may exceed the bound by the solver tolerance:
    they are projected onto ``‖u‖ ≤ u_max``.
    """
    steps = g.blocks.shape[0]
    u = np.asarray(sol.x[: 3 * steps]).reshape(steps, 3) * g.u_max_km_s2
    norms = np.linalg.norm(u, axis=1)
    over = norms > g.u_max_km_s2
    u[over] *= (g.u_max_km_s2 / norms[over])[:, None]
    return u


def solved(sol: Any) -> bool:
    return bool(sol.status in (clarabel.SolverStatus.Solved, clarabel.SolverStatus.AlmostSolved))


def terminal_rows(g: GridProblem, n_vars: int) -> tuple[sp.csc_matrix, np.ndarray]:
    """Equality rows ``S M ũ = S b`` with ``u = u_max ũ`` (controls are the first 3N vars)."""
    steps = g.blocks.shape[0]
    m = np.transpose(g.blocks, (1, 0, 2)).reshape(6, 3 * steps) * g.u_max_km_s2
    m = m * g.row_scale[:, None]
    a = sp.hstack([sp.csc_matrix(m), sp.csc_matrix((6, n_vars - 3 * steps))]).tocsc()
    return a, g.rhs * g.row_scale


def cone_rows(steps: int, n_vars: int, head_cols: np.ndarray | None) -> sp.csc_matrix:
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
    a_eq, b_eq = terminal_rows(g, n_vars)
    cones = cone_rows(steps, n_vars, np.full(steps, 3 * steps))  # (s̃, ũ_j) ∈ SOC
    a = sp.vstack([a_eq, cones]).tocsc()
    b = np.concatenate([b_eq, np.zeros(4 * steps)])
    q = np.zeros(n_vars)
    q[-1] = 1.0
    sol = solve_cone(
        sp.csc_matrix((n_vars, n_vars)),
        q,
        a,
        b,
        [clarabel.ZeroConeT(6)] + [clarabel.SecondOrderConeT(4)] * steps,
    )
    if not solved(sol):
        return float("inf")
    return float(sol.x[-1]) * g.u_max_km_s2


def _affine_norm_integral(a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    """``∫_{−r}^{r} ‖a_i + s b_i‖ ds`` for each row i, in closed form."""
    alpha = np.einsum("ij,ij->i", b, b)
    beta = np.einsum("ij,ij->i", a, b)
    gamma = np.einsum("ij,ij->i", a, a)
    out = 2.0 * r * np.sqrt(gamma)
    k = alpha > 0.0
    al, be, ga = alpha[k], beta[k], gamma[k]
    c = np.maximum(ga - be * be / al, 0.0) / al  # ‖a + sb‖² = α((s + β/α)² + c)
    sc = np.sqrt(c)

    def prim(u: np.ndarray) -> np.ndarray:  # ∫ √(u² + c) du
        root = np.sqrt(u * u + c)
        safe = np.where(sc > 0.0, sc, 1.0)
        value: np.ndarray = 0.5 * (u * root + np.where(sc > 0.0, c * np.arcsinh(u / safe), 0.0))
        return value

    shift = be / al
    out[k] = np.sqrt(al) * (prim(r + shift) - prim(-r + shift))
    result: np.ndarray = out
    return result


def _system(n: float, design: LinearTimeInvariant | None) -> tuple[np.ndarray, np.ndarray]:
    """``A``, ``B`` of CW (mean motion ``n``) or of ``design`` (issue 33)."""
    return cw_system(n) if design is None else design.system()


def _stm(n: float, design: LinearTimeInvariant | None, t: float) -> np.ndarray:
    """``Φ(t)`` of CW (mean motion ``n``) or of ``design`` (issue 33)."""
    return stm(n, t) if design is None else lti_stm(design, t)


def _support_upper_bound(
    n: float,
    lam: np.ndarray,
    horizon_s: float,
    half_s: float,
    design: LinearTimeInvariant | None = None,
) -> float:
    """A rigorous upper bound of ``∫₀^T ‖W(τ)ᵀλ‖ dτ`` (up to rounding).

    ``f(τ) = W(τ)ᵀλ = Bᵀμ(τ)`` with ``μ(τ) = e^{−Aᵀτ}λ``, so ``f^{(k)} = Bᵀ(−Aᵀ)^k μ``.
    On a cell ``c ± r``: ``‖f(c+s)‖ ≤ ‖f(c) + s f′(c)‖ + s²/2 · M₂`` with
    ``M₂ = ‖f″(c)‖ + r‖Bᵀ(Aᵀ)³‖ e^{‖A‖r} ‖μ(c)‖ ≥ sup ‖f″‖``; the affine part
    is integrated exactly (:func:`_affine_norm_integral`), the rest gives
    ``M₂ r³/3``.
    """
    a_mat, b_mat = _system(n, design)
    at = -a_mat.T
    cells = max(1, int(np.ceil(horizon_s / (2.0 * half_s))))
    r = 0.5 * horizon_s / cells
    centres = (np.arange(cells) + 0.5) * 2.0 * r
    mu = np.stack([_stm(n, design, -c).T @ lam for c in centres])  # μ(c) = e^{−Aᵀc} λ
    bt = b_mat.T
    f0 = mu @ bt.T
    f1 = mu @ (bt @ at).T
    f2 = mu @ (bt @ at @ at).T
    k3 = np.linalg.norm(bt @ at @ at @ at, 2) * np.exp(np.linalg.norm(a_mat, 2) * r)
    m2 = np.linalg.norm(f2, axis=1) + r * k3 * np.linalg.norm(mu, axis=1)
    return float(np.sum(_affine_norm_integral(f0, f1, r) + m2 * r**3 / 3.0))


def continuous_peak_thrust(
    n: float,
    x0: np.ndarray,
    xf: np.ndarray,
    horizon_s: float,
    cells: int = 0,
    nodes: int = 8,
    design: LinearTimeInvariant | None = None,
) -> float:
    """Certified lower bound of the smallest ``max_t ‖u(t)‖`` reaching ``x_f`` [km/s²].

    Of the bound of paper Eq. 6.

    Continuous-time dual bound (issue 16, item 3). With ``W(τ) = e^{−Aτ}B``
    the target is reached iff ``∫₀^T W u dτ = d``, ``d = Φ(T)⁻¹x_f − x₀``. The
    set ``{∫W u dτ : ‖u‖ ≤ 1}`` has support function ``λ ↦ ∫‖Wᵀλ‖dτ``, so by
    duality the least bound on ‖u‖ reaching ``d`` is

        ``max_λ λᵀd / ∫₀^T ‖W(τ)ᵀλ‖ dτ``,

    and every λ gives a lower bound. λ is found by a cone program in its 6
    components (normalised by the quadrature of the integral ≤ 1, composite
    Gauss–Legendre, ``nodes`` on each of ``cells`` cells (default: 10 s cells,
    at least 64: ‖Wᵀλ‖ has a kink wherever Wᵀλ vanishes, e.g. the out-of-plane
    component of a short final burn), one epigraph variable and
    one SOC(4) per node); the bound returned is then ``λᵀd / Ī(λ)`` with a
    rigorous upper bound ``Ī`` of the integral (:func:`_support_upper_bound`,
    cells of 0.5 s; it exceeds the integral by ~1e-9 relative), not the
    quadrature. So a value above ``u_max`` certifies that no control reaches
    ``x_f``, and a feasible problem, however close to the boundary, is never
    labelled infeasible. Unlike :func:`min_peak_thrust` it does not depend on
    a control grid (whose held controls overstate the bound). Returns 0 when
    the cone program fails (no certificate). ``design``: a time-invariant design
    model other than CW (issue 33; None: CW of mean motion ``n``).
    """
    cells = cells or max(64, int(np.ceil(horizon_s / 10.0)))
    gx, gw = np.polynomial.legendre.leggauss(nodes)
    edges = np.linspace(0.0, horizon_s, cells + 1)
    half = 0.5 * np.diff(edges)
    tau = ((edges[:-1] + half)[:, None] + half[:, None] * gx[None, :]).ravel()
    w = (half[:, None] * gw[None, :]).ravel() / horizon_s  # weights of the mean over [0, T]
    m = tau.size
    # λ = diag(1/T, 1/T, 1/T, 1, 1, 1) λ̃: both halves of Wᵀλ are then O(1)
    scale = np.array([1.0 / horizon_s] * 3 + [1.0] * 3)
    wt = np.stack([_stm(n, design, -t)[:, 3:].T * scale[None, :] for t in tau])  # (m, 3, 6)
    d = np.linalg.solve(_stm(n, design, horizon_s), xf) - x0
    n_vars = 6 + m  # λ̃, then t_i ≥ ‖W_iᵀλ̃‖
    mean_row = sp.csc_matrix((w, (np.zeros(m, dtype=int), 6 + np.arange(m))), shape=(1, n_vars))
    body_rows = (4 * np.arange(m)[:, None, None] + 1 + np.arange(3)[None, :, None]).repeat(6, 2)
    rows = np.concatenate([4 * np.arange(m), body_rows.ravel()])
    cols = np.concatenate([6 + np.arange(m), np.tile(np.arange(6), 3 * m)])
    vals = np.concatenate([-np.ones(m), -wt.ravel()])
    cones_a = sp.csc_matrix((vals, (rows, cols)), shape=(4 * m, n_vars))  # (t_i, W_iᵀλ̃) ∈ SOC
    sol = solve_cone(
        sp.csc_matrix((n_vars, n_vars)),
        np.concatenate([-d * scale, np.zeros(m)]),  # maximise λ̃ᵀ(scale·d)
        sp.vstack([mean_row, cones_a]).tocsc(),
        np.concatenate([[1.0], np.zeros(4 * m)]),
        [clarabel.NonnegativeConeT(1)] + [clarabel.SecondOrderConeT(4)] * m,
    )
    if not solved(sol):
        return 0.0
    lam = np.asarray(sol.x[:6]) * scale
    gain = float(lam @ d)
    if gain <= 0.0:
        return 0.0
    return gain / _support_upper_bound(n, lam, horizon_s, 0.25, design)


def min_fuel_costate(g: GridProblem, n: float) -> np.ndarray | None:
    """Costate guess ``λ(0) = Φ(t_rem)ᵀ ν`` from the discretised minimum-fuel SOCP.

    ``ν`` is the multiplier of the terminal constraint in the convention
    ``L = Σ Δt‖u_j‖ − νᵀ(Σ M_j u_j − b)``, under which held thrust points along
    ``M_jᵀ ν`` and switches where ``‖M_jᵀ ν‖ = Δt``; the shooting costate is
    ``λ(0) = −Φ(t_rem)ᵀ ν``. Returns None when the SOCP is infeasible.
    """
    steps = g.blocks.shape[0]
    n_vars = 4 * steps  # ũ (3N), t̃ (N)
    a_eq, b_eq = terminal_rows(g, n_vars)
    epigraph = cone_rows(steps, n_vars, 3 * steps + np.arange(steps))  # (t̃_j, ũ_j) ∈ SOC
    bound = cone_rows(steps, n_vars, None)  # (1, ũ_j) ∈ SOC: ‖u_j‖ ≤ u_max
    a = sp.vstack([a_eq, epigraph, bound]).tocsc()
    b_bound = np.zeros(4 * steps)
    b_bound[0::4] = 1.0
    b = np.concatenate([b_eq, np.zeros(4 * steps), b_bound])
    q = np.zeros(n_vars)
    q[3 * steps :] = 1.0
    sol = solve_cone(
        sp.csc_matrix((n_vars, n_vars)),
        q,
        a,
        b,
        [clarabel.ZeroConeT(6)] + [clarabel.SecondOrderConeT(4)] * (2 * steps),
    )
    if not solved(sol):
        return None
    return costate_from_multiplier(g, n, np.asarray(sol.z[:6]))


def costate_from_multiplier(g: GridProblem, n: float, z_terminal: np.ndarray) -> np.ndarray:
    """``λ(0)`` from Clarabel's multiplier of the scaled terminal rows.

    Valid for a cost written as ``Σ Δt ℓ(u_j) / (Δt u_max)`` in the scaled
    controls (the convention of every program here): Clarabel's
    ``q + Aᵀz = 0`` then gives ``z`` in units where undoing the row scaling,
    ``Δt`` and ``u_max`` yields ``ν``, and ``λ(0) = Φ(t_rem)ᵀ ν``.
    """
    z_eq = z_terminal * g.row_scale * g.dt_s * g.u_max_km_s2
    costate: np.ndarray = _transition(g, n).T @ z_eq
    return costate


def multiplier_from_costate(g: GridProblem, n: float, costate: np.ndarray) -> np.ndarray:
    """The inverse of :func:`costate_from_multiplier`: Clarabel's scaled terminal multiplier.

    ``costate`` is ``λ`` at the grid's start. The terminal multiplier is the
    same object for every re-solve with the same final time, so an earlier
    plan's costate propagated to this grid's start gives this program's
    multiplier of that plan.
    """
    z_eq = np.linalg.solve(_transition(g, n).T, costate)
    z: np.ndarray = z_eq / (g.row_scale * g.dt_s * g.u_max_km_s2)
    return z


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
    bound = cone_rows(steps, n_vars, None)  # (1, ũ_j) ∈ SOC
    a = sp.vstack([top, body, bound]).tocsc()
    b_bound = np.zeros(4 * steps)
    b_bound[0::4] = 1.0
    b = np.concatenate([np.zeros(1), -wb, b_bound])
    q = np.zeros(n_vars)
    q[-1] = 1.0
    sol = solve_cone(
        sp.csc_matrix((n_vars, n_vars)),
        q,
        a,
        b,
        [clarabel.SecondOrderConeT(7)] + [clarabel.SecondOrderConeT(4)] * steps,
    )
    if not solved(sol):
        return None
    return held_controls(g, sol)
