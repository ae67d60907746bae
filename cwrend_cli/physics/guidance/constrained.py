"""The constrained cone program: keep-out zone and corridor by sequential convex programming.

Issue 32, item 2. The smoothed minimum-fuel program of :mod:`.convex` (same
cost, ``Σ (1 − ε)‖ũ_j‖ + max(ε, ρ)‖ũ_j‖²`` in the scaled controls ũ = u/u_max,
same ``‖ũ_j‖ ≤ 1``, same exact zero-order-hold CW dynamics, paper Eq. 11, and
terminal state x_f) with the path constraints of
:mod:`cwrend_cli.physics.constraints` at every node k = 1 … N−1 of the grid,
written in the states (variables x_1 … x_N, the dynamics as equality rows: a
sparse program, solved by Clarabel).

**Modes.** The safe set (outside the zone or inside the corridor) is not
convex; each node gets one of two convex subsets from the previous iterate
r̄: the *corridor* nodes are the last contiguous stretch of nodes that r̄ has
inside the corridor cone (the final approach; the terminal node, the port, is
its apex), the others are *keep-out* nodes. A keep-out node must lie in the
half-space tangent to the zone at r̄_k (r̄_k projected radially onto the
surface when inside: :func:`~cwrend_cli.physics.constraints.linearise_keep_out`);
a corridor node in the cone (a second-order cone, exact); the first corridor
node in both, so that the chord between any two consecutive nodes lies in one
convex safe set. The half-space is an inner approximation of the outside of
the zone (the level function is convex), so **every iterate is safe**, not
only the last: stopping early costs fuel, never safety.

**Margins.** Every constraint of nodes 1 … N−1 is tightened by the chord
margin AΔt²/8 (:func:`~cwrend_cli.physics.constraints.chord_margin_km`, A
from the previous iterate's largest ‖r‖, ‖v‖ plus the trust radius and a
factor :data:`ACCEL_FACTOR`; checked on the answer, which is refused as
unconverged if its own bound is larger), so the zero-order-hold arc between
two nodes satisfies the untightened constraint. The keep-out half-spaces are
further tightened by ``k √(nᵀ P_pos n)`` (``constraints.sigma_margin`` = k,
P_pos the filter's position covariance at the re-solve, **held** over the
horizon: the guidance plans with what the chaser knows now; propagating the
open-loop prediction would only grow it by Q, 1e-12 km² a step in the paper,
and the filter's updates shrink it). The corridor is not tightened by the
covariance: its apex is the port, where any margin would forbid docking. The
terminal node (the port, fixed by the terminal equality) carries no path
constraint; the last step's arc is within AΔt²/8 of its chord, which is inside
the cone.

**Iterations.** Trust region ``‖r_k − r̄_k‖_∞ ≤`` :data:`TRUST_RADIUS_FACTOR`
× the largest semi-axis; stop when no node moves by more than
:data:`SCP_TOL_KM` between iterates or the cost falls by less than
:data:`SCP_COST_RTOL` of itself, with no slack and the modes unchanged, at most
:data:`SCP_MAX_ITER` iterations; at the cap the last iterate is returned (safe,
see above) with its status converged if its terminal and path rows hold.

**Infeasibility.** The path rows carry one slack s ≥ 0 (every half-space and
cone row loosened by s) priced :data:`SLACK_PENALTY` per km in the scaled cost:
an exact (ℓ∞) penalty, so s = 0 whenever a safe plan exists and its multiplier
is below the price; s > 0 says by how much the plan had to enter the unsafe
set (returned as ``slack_km``).

**Several bodies, a tumbling target** (issue 34). Every ellipsoid of the zone
gets its own half-space at each keep-out node (one row each; the zone's outside
is their intersection, convex). For a tumbling target (``motion``: the body
frame's predicted turn R_k at every node) the geometry is given in the body
frame: each ellipsoid is linearised at the iterate's body-frame position
R_kᵀ r̄_k, and a body-frame row ``nᵀ ρ ≥ d`` binds node k as ``(R_k n)ᵀ r_k ≥ d``;
the corridor cone likewise. The chord argument above holds in the body frame
with the body-frame acceleration bound
(:func:`~cwrend_cli.physics.constraints.body_acceleration_bound`), which grows
with the distance from the target, so each step has its own margin and each
node takes the larger of its two steps'. The terminal state (the caller's
``xf``) is then the port's predicted position and velocity.

Units: km, s, km/s, km/s².
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import clarabel
import numpy as np
import scipy.sparse as sp

from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.dynamics import discretize
from cwrend_cli.physics.guidance import convex, feasibility
from cwrend_cli.physics.guidance.results import SolveStatus

__all__ = [
    "ACCEL_FACTOR",
    "SCP_COST_RTOL",
    "SCP_MAX_ITER",
    "SCP_TOL_KM",
    "SLACK_PENALTY",
    "SLACK_TOL_KM",
    "TRUST_RADIUS_FACTOR",
    "ConstrainedPlan",
    "node_positions",
    "plan",
]

#: Iteration cap of the sequential convex programming [-].
SCP_MAX_ITER = 8
#: Stop when no node position moves more than this between iterates [km] (1 mm) ...
SCP_TOL_KM = 1e-6
#: ... or when an iterate lowers the cost by less than this fraction of it [-] (0.01 %; a plan
#: that slides along the curved surface keeps moving by ~0.3 m an iteration while its
#: cost changes in the sixth digit; every iterate is safe, so stopping costs no safety).
SCP_COST_RTOL = 1e-4
#: Trust radius of the node positions, a multiple of the largest semi-axis [-].
TRUST_RADIUS_FACTOR = 1.0
#: Price of the path slack in the scaled cost [1/km]: the cost of a plan is of order the
#: fuel over Δt u_max (at most N), so 1e6 per km outweighs any fuel saving.
SLACK_PENALTY = 1e6
#: A slack below this is the interior point's tolerance, not a softening [km] (1 µm).
SLACK_TOL_KM = 1e-9
#: Safety factor on the acceleration bound of the chord margin [-].
ACCEL_FACTOR = 1.5

_CORRIDOR, _KEEP_OUT, _BOTH = 1, 2, 3


@dataclass(frozen=True)
class ConstrainedPlan:
    """The answer of :func:`plan`.

    ``controls`` (N, 3) [km/s²] and ``positions`` (N+1, 3) [km] of the nodes
    (row 0 the start) are zero/NaN unless converged; ``modes`` (N+1,) per node:
    0 none, 1 corridor, 2 keep-out, 3 both; ``slack_km`` the softening used
    (0: every path constraint held); ``scp_iterations`` the convex programs
    solved, ``solver_iterations`` Clarabel's iterations summed.
    """

    status: SolveStatus
    controls: np.ndarray
    positions: np.ndarray
    modes: np.ndarray
    slack_km: float
    scp_iterations: int
    solver_iterations: int
    wall_time_s: float


def node_positions(
    n: float, dt_s: float, x0: np.ndarray, controls: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """States (N+1, 6) of held ``controls`` from x0 under the exact ZOH dynamics (Eq. 11)."""
    phi, gam = discretize(n, dt_s)
    x = np.empty((controls.shape[0] + 1, 6))
    x[0] = x0
    for k, u in enumerate(controls):
        x[k + 1] = phi @ x[k] + gam @ u
    return x, x[:, :3]


def _modes(geo: cg.Geometry, r_bar: np.ndarray, motion: cg.BodyMotion | None) -> np.ndarray:
    """Each node's constraint set from the previous iterate (module docstring)."""
    steps = r_bar.shape[0] - 1
    modes = np.zeros(steps + 1, dtype=np.int8)
    if geo.semi_axes_km is None:
        return modes  # nothing is unsafe: no path constraint
    modes[1:steps] = _KEEP_OUT
    if geo.port_km is None:
        return modes
    inside = cg.corridor_cone(geo, 0.0).residual_km(cg.to_body(motion, r_bar)) >= -SCP_TOL_KM
    first = steps  # the terminal node is the apex
    while first - 1 >= 1 and inside[first - 1]:
        first -= 1
    modes[first:steps] = _CORRIDOR
    if first < steps:
        modes[first] = _BOTH
    return modes


def _detour_side(semi_axes: np.ndarray, r_bar: np.ndarray) -> np.ndarray:
    """The side (a unit vector) on which an iterate that crosses the zone goes round it.

    At the deepest node k* the component of r̄_k* across the path's direction
    there (r̄_k*+1 − r̄_k*−1); a path straight through the centre has none, and
    gets the coordinate axis least aligned with its direction, made
    perpendicular to it (a deterministic choice; the other side costs the same
    by symmetry).
    """
    level = cg.ellipsoid_level(r_bar, semi_axes)
    k = int(np.argmin(level))
    ahead, behind = r_bar[min(k + 1, len(r_bar) - 1)], r_bar[max(k - 1, 0)]
    direction = ahead - behind
    size = float(np.linalg.norm(direction))
    d = direction / size if size > 0.0 else np.array([0.0, 0.0, 1.0])
    side = r_bar[k] - float(r_bar[k] @ d) * d
    if float(np.linalg.norm(side)) <= 1e-9 * float(np.max(semi_axes)):
        axis = np.eye(3)[int(np.argmin(np.abs(d)))]
        side = axis - float(axis @ d) * d
    return np.asarray(side / np.linalg.norm(side), dtype=np.float64)


def _tangent_point(semi_axes: np.ndarray, r: np.ndarray, side: np.ndarray) -> np.ndarray:
    """The point whose tangent plane bounds node r: r itself outside the zone; inside, the
    radial projection onto the surface of r moved by the largest semi-axis towards ``side``
    (so the nodes of a crossing iterate all go round on one side)."""
    level = float(cg.ellipsoid_level(r, semi_axes))
    if level >= 1.0:
        return r
    shifted = r + float(np.max(semi_axes)) * side
    return shifted / math.sqrt(float(cg.ellipsoid_level(shifted, semi_axes)))


def _half_spaces(
    geo: cg.Geometry,
    modes: np.ndarray,
    r_bar: np.ndarray,
    margins_km: np.ndarray,
    p_pos_km2: np.ndarray | None,
    sigma_margin: float,
    motion: cg.BodyMotion | None,
) -> dict[tuple[int, int], cg.HalfSpace]:
    """The tightened keep-out half-space H_k,j of every keep-out node k (and of node 0) and
    ellipsoid j, in the body frame (the relative frame without ``motion``).

    Each ellipsoid is linearised at the iterate's body-frame position at the node's
    time (issue 34). ``margins_km`` (N+1,): each node's between-node margin. The
    covariance margin is taken along the half-space's normal in the relative frame at
    the two nodes it binds (k and k+1), the larger.
    """
    rho_bar = cg.to_body(motion, r_bar)
    keep_out = [0, *np.flatnonzero(modes >= _KEEP_OUT).tolist()]
    out: dict[tuple[int, int], cg.HalfSpace] = {}
    for j, (centre, axes) in enumerate(cg.ellipsoids(geo)):
        local = rho_bar if centre is None else rho_bar - centre
        side = _detour_side(axes, local)
        for k in keep_out:
            point = _tangent_point(axes, local[k], side)
            extra = float(margins_km[k])
            if sigma_margin > 0.0 and p_pos_km2 is not None:
                normal = cg.linearise_keep_out(axes, point, 0.0).normal
                if motion is not None:
                    at = motion.rotation[k : k + 2] @ normal
                    extra += max(cg.covariance_margin_km(m, p_pos_km2, sigma_margin) for m in at)
                else:
                    extra += cg.covariance_margin_km(normal, p_pos_km2, sigma_margin)
            hs = cg.linearise_keep_out(axes, point, extra)
            if centre is not None:  # nᵀ(ρ − c) ≥ offset ⇔ nᵀρ ≥ offset + nᵀc
                hs = cg.HalfSpace(hs.normal, hs.offset_km + float(hs.normal @ centre))
            out[int(k), j] = hs
    return out


def _program(
    n: float,
    dt_s: float,
    u_max: float,
    x0: np.ndarray,
    xf: np.ndarray,
    eps: float,
    geo: cg.Geometry,
    modes: np.ndarray,
    r_bar: np.ndarray,
    margins_km: np.ndarray,
    half_spaces: dict[tuple[int, int], cg.HalfSpace],
    trust_km: float,
    motion: cg.BodyMotion | None = None,
) -> tuple[Any, int]:
    """One convex subproblem (module docstring) solved by Clarabel; (solution, steps).

    With ``motion`` (a tumbling target) every body-frame half-space and the corridor
    cone bind node k through its body-frame position R_kᵀ r_k (issue 34).
    """
    steps = modes.size - 1
    phi, gam = discretize(n, dt_s)
    gam_u = gam * u_max
    iu, it, ix, i_s = 0, 3 * steps, 4 * steps, 10 * steps
    n_vars = 10 * steps + 1

    def xcol(k: int) -> int:  # first column of x_k, k = 1 … N
        return ix + 6 * (k - 1)

    # Every block as (row, column, value) triplets, rows counted from the block's first,
    # assembled at once (a sparse row at a time cost 5× the solve); explicit zeros are
    # dropped (eliminate_zeros below), as a row-by-row assembly drops them
    blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray, int]] = []
    cones: list[Any] = []

    def dense_block(r0: np.ndarray, c0: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, ...]:
        """Triplets of the dense (p, q) block ``m`` (or one per placement, (P, p, q)) placed
        at rows r0 + i, columns c0 + j."""
        p_, q_ = m.shape[-2:]
        r = (r0[:, None, None] + np.arange(p_)[None, :, None]) + np.zeros((1, 1, q_), np.int64)
        c = (c0[:, None, None] + np.arange(q_)[None, None, :]) + np.zeros((1, p_, 1), np.int64)
        v = np.broadcast_to(m, (r0.size, p_, q_))
        return r.ravel(), c.ravel(), v.ravel()

    # dynamics: x_{k+1} − Φ x_k − Γ̃ ũ_k = 0 (x_0 = x0 given), and x_N = x_f
    k_all = np.arange(steps)
    parts = [
        dense_block(6 * k_all, ix + 6 * k_all, np.eye(6)),
        dense_block(6 * k_all, iu + 3 * k_all, -gam_u),
        dense_block(6 * k_all[1:], ix + 6 * (k_all[1:] - 1), -phi),
        dense_block(np.array([6 * steps]), np.array([xcol(steps)]), np.eye(6)),
    ]
    b_eq = np.zeros(6 * steps + 6)
    b_eq[0:6] = phi @ x0
    b_eq[6 * steps :] = xf
    blocks.append((*_cat(parts), 6 * steps + 6))
    rhs = [b_eq]
    cones.append(clarabel.ZeroConeT(6 * steps + 6))
    # ‖ũ_j‖ ≤ t̃_j ≤ 1
    soc_u = feasibility.cone_rows(steps, n_vars, it + np.arange(steps)).tocoo()
    blocks.append((soc_u.row, soc_u.col, soc_u.data, 4 * steps))
    rhs.append(np.zeros(4 * steps))
    cones += [clarabel.SecondOrderConeT(4)] * steps
    # nonnegative rows: t̃ ≤ 1, s ≥ 0, half-spaces, trust region
    parts = [(k_all, it + k_all, np.ones(steps)), (np.array([steps]), np.array([i_s]), -np.ones(1))]
    b_nonneg = [np.ones(steps), np.zeros(1)]
    # node k in its own half-space and in its predecessor's: the chord k−1 → k then lies in
    # H_k−1 (convex), the arc within the chord margin of it; nᵀ r_k + s ≥ offset ⇔
    # −nᵀ r_k − s ≤ −offset
    # (one row per ellipsoid b of the zone)
    bodies = len(cg.ellipsoids(geo))
    pairs = [
        (k, (j, b))
        for k in range(1, steps)
        for j in (k, k - 1)
        if (j, 0) in half_spaces and not (j == k - 1 and modes[k] == 0)
        for b in range(bodies)
    ]
    row0 = steps + 1
    if pairs:
        node = np.array([k for k, _ in pairs])
        normals = np.array([half_spaces[key].normal for _, key in pairs], dtype=np.float64)
        if motion is not None:  # nᵀ ρ_k = (R_k n)ᵀ r_k
            normals = np.einsum("pij,pj->pi", motion.rotation[node], normals)
        rows_hs = row0 + np.arange(len(pairs))
        parts.append(dense_block(rows_hs, ix + 6 * (node - 1), -normals[:, None, :]))
        parts.append((rows_hs, np.full(len(pairs), i_s), -np.ones(len(pairs))))
        b_nonneg.append(-np.array([half_spaces[key].offset_km for _, key in pairs]))
        row0 += len(pairs)
    constrained = np.flatnonzero(modes > 0)
    if constrained.size:  # ±(r_k − r̄_k) ≤ trust
        rows_tr = row0 + 6 * np.arange(constrained.size)
        cols_tr = ix + 6 * (constrained - 1)
        parts.append(dense_block(rows_tr, cols_tr, np.eye(3)))
        parts.append(dense_block(rows_tr + 3, cols_tr, -np.eye(3)))
        b_nonneg.append(
            np.column_stack([trust_km + r_bar[constrained], trust_km - r_bar[constrained]]).ravel()
        )
        row0 += 6 * constrained.size
    blocks.append((*_cat(parts), row0))
    rhs.append(np.concatenate(b_nonneg))
    cones.append(clarabel.NonnegativeConeT(row0))
    # corridor: ‖P(r_k − p)‖ ≤ tan θ âᵀ(r_k − p) − m + s, as (head, body) = b − A x ∈ SOC(4)
    corridor_nodes = np.flatnonzero((modes == _CORRIDOR) | (modes == _BOTH))
    if corridor_nodes.size:
        rows_c = 4 * np.arange(corridor_nodes.size)
        if motion is None:  # one margin, one cone for every node
            soc = cg.corridor_cone(geo, float(margins_km[corridor_nodes[0]]))
            a_body, b_body, c_head, d_head = soc.rows()
            head = np.vstack([-c_head, -a_body])[None]
            cone_rhs = np.tile(np.r_[d_head, b_body], corridor_nodes.size)
        else:  # ‖P(R_kᵀ r − p)‖ ≤ (R_k c)ᵀ r + d_k: each node's turn and margin
            heads, cone_rhs_k = [], []
            for k in corridor_nodes:
                a_body, b_body, c_head, d_head = cg.corridor_cone(geo, margins_km[k]).rows()
                rot = motion.rotation[k]
                heads.append(np.vstack([-(rot @ c_head), -(a_body @ rot.T)]))
                cone_rhs_k.append(np.r_[d_head, b_body])
            head = np.array(heads)
            cone_rhs = np.concatenate(cone_rhs_k)
        parts = [
            dense_block(rows_c, ix + 6 * (corridor_nodes - 1), head),
            (rows_c, np.full(rows_c.size, i_s), -np.ones(rows_c.size)),
        ]
        blocks.append((*_cat(parts), 4 * corridor_nodes.size))
        rhs.append(cone_rhs)
        cones += [clarabel.SecondOrderConeT(4)] * corridor_nodes.size
    offset = 0
    r_all, c_all, v_all = [], [], []
    for r, c, v, height in blocks:
        r_all.append(r + offset)
        c_all.append(c)
        v_all.append(v)
        offset += height
    a = sp.csc_matrix(
        (np.concatenate(v_all), (np.concatenate(r_all), np.concatenate(c_all))),
        shape=(offset, n_vars),
    )
    a.eliminate_zeros()
    b = np.concatenate(rhs)
    weight = max(float(eps), convex.REGULARISATION)
    q = np.zeros(n_vars)
    q[it : it + steps] = 1.0 - min(float(eps), 1.0)
    q[i_s] = SLACK_PENALTY
    diag = np.zeros(n_vars)
    diag[: 3 * steps] = 2.0 * weight
    p = sp.diags(diag, format="csc")
    sol = feasibility.solve_cone(p, q, a, b, cones)
    return sol, int(sol.iterations)


def _cat(parts: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenated (rows, columns, values) of triplet parts."""
    return (
        np.concatenate([p[0] for p in parts]).astype(np.int64),
        np.concatenate([p[1] for p in parts]).astype(np.int64),
        np.concatenate([p[2] for p in parts]).astype(np.float64),
    )


def _accel(n: float, dt_s: float, u_max: float, x: np.ndarray, extra_km: float) -> float:
    """The acceleration bound of the chord margin over a plan's states (module docstring)."""
    r = float(np.max(np.linalg.norm(x[:, :3], axis=1))) + extra_km
    v = float(np.max(np.linalg.norm(x[:, 3:], axis=1)))
    return cg.acceleration_bound(r, v, u_max, n, dt_s)


def _step_margins(
    n: float,
    dt_s: float,
    u_max: float,
    x: np.ndarray,
    extra_km: float,
    factor: float,
    motion: cg.BodyMotion | None,
) -> np.ndarray:
    """The chord margin of every step of a plan's states (N,) [km] (module docstring).

    Fixed target: one margin, from the plan's largest ‖r‖ (+ ``extra_km``) and ‖v‖.
    Turning body (issue 34): each step's own, from its two nodes' ‖r‖ (+ ``extra_km``)
    and ‖v‖ and the body-frame acceleration bound
    (:func:`~cwrend_cli.physics.constraints.body_acceleration_bound`), which grows with
    the distance from the target's centre. ``factor`` multiplies the acceleration.
    """
    steps = x.shape[0] - 1
    if motion is None:
        return np.full(
            steps, cg.chord_margin_km(factor * _accel(n, dt_s, u_max, x, extra_km), dt_s)
        )
    r = np.linalg.norm(x[:, :3], axis=1)
    v = np.linalg.norm(x[:, 3:], axis=1)
    r_step = np.maximum(r[:-1], r[1:]) + extra_km
    v_step = np.maximum(v[:-1], v[1:])
    rate, rate_dot = motion.rate_bound_rad_s, motion.rate_dot_bound_rad_s2
    return np.array(
        [
            cg.chord_margin_km(
                factor
                * cg.body_acceleration_bound(
                    cg.acceleration_bound(ri, vi, u_max, n, dt_s), ri, vi, rate, rate_dot, dt_s
                ),
                dt_s,
            )
            for ri, vi in zip(r_step.tolist(), v_step.tolist(), strict=True)
        ]
    )


def _node_margins(step_margins: np.ndarray) -> np.ndarray:
    """Each node's margin (N+1,) [km]: the larger of its two steps' (a node's constraints
    bind the chords on both sides of it; the end nodes have one step)."""
    out = np.empty(step_margins.size + 1)
    out[0], out[-1] = step_margins[0], step_margins[-1]
    out[1:-1] = np.maximum(step_margins[:-1], step_margins[1:])
    return out


def plan(
    n: float,
    dt_s: float,
    u_max_km_s2: float,
    x0: np.ndarray,
    xf: np.ndarray,
    horizon_s: float,
    eps: float,
    geo: cg.Geometry,
    p_pos_km2: np.ndarray | None = None,
    sigma_margin: float = 0.0,
    warm_controls: np.ndarray | None = None,
    motion: cg.BodyMotion | None = None,
) -> ConstrainedPlan:
    """The constrained cone program from ``x0`` to ``xf`` over ``horizon_s`` (module docstring).

    The first iterate is ``warm_controls`` (an earlier plan's remaining controls,
    N × 3) or the unconstrained plan of :func:`.convex.plan_controls`.
    ``p_pos_km2``: the filter's position covariance (3 × 3), for
    ``sigma_margin``. ``motion`` (a tumbling target, issue 34): the predicted turn
    of the body frame at the N + 1 nodes, in which ``geo`` is given; ``xf`` is then
    the port's predicted state at the horizon's end.
    """
    start = time.perf_counter()
    steps = max(1, round(horizon_s / dt_s))
    x0 = np.asarray(x0, dtype=np.float64)
    xf = np.asarray(xf, dtype=np.float64)
    used = 0
    if warm_controls is None or warm_controls.shape != (steps, 3):
        g = feasibility.grid_problem(n, x0, xf, horizon_s, dt_s, u_max_km_s2)
        status, warm_controls, _, iterations = convex.plan_controls(g, eps, n)
        used += iterations
        if status is not SolveStatus.CONVERGED:
            warm_controls = np.zeros((steps, 3))
    x_bar, r_bar = node_positions(n, dt_s, x0, warm_controls)
    sizes = [float(np.max(axes)) for _, axes in cg.ellipsoids(geo)]
    trust = TRUST_RADIUS_FACTOR * (max(sizes) if sizes else 1.0)
    modes = _modes(geo, r_bar, motion)
    failed = ConstrainedPlan(
        SolveStatus.FAILED,
        np.zeros((steps, 3)),
        np.full((steps + 1, 3), np.nan),
        modes,
        math.nan,
        0,
        used,
        0.0,
    )
    if not np.any(modes):  # nothing is unsafe: the unconstrained plan
        return ConstrainedPlan(
            SolveStatus.CONVERGED,
            warm_controls,
            r_bar,
            modes,
            0.0,
            0,
            used,
            time.perf_counter() - start,
        )
    result = failed
    cost = math.inf
    for scp in range(1, SCP_MAX_ITER + 1):
        margins = _node_margins(
            _step_margins(n, dt_s, u_max_km_s2, x_bar, trust, ACCEL_FACTOR, motion)
        )
        half_spaces = _half_spaces(geo, modes, r_bar, margins, p_pos_km2, sigma_margin, motion)
        sol, iterations = _program(
            n, dt_s, u_max_km_s2, x0, xf, eps, geo, modes, r_bar, margins, half_spaces, trust,
            motion,
        )  # fmt: skip
        used += iterations
        if not feasibility.solved(sol):
            status = (
                SolveStatus.INFEASIBLE if sol.status in convex._INFEASIBLE else SolveStatus.FAILED
            )
            return ConstrainedPlan(
                status,
                failed.controls,
                failed.positions,
                modes,
                math.nan,
                scp,
                used,
                time.perf_counter() - start,
            )
        u = np.asarray(sol.x[: 3 * steps]).reshape(steps, 3)
        norms = np.linalg.norm(u, axis=1)
        u = np.where(norms[:, None] > 1.0, u / np.maximum(norms, 1.0)[:, None], u) * u_max_km_s2
        x_new = np.vstack([x0, np.asarray(sol.x[4 * steps : 10 * steps]).reshape(steps, 6)])
        slack = float(sol.x[10 * steps])
        slack = slack if slack > SLACK_TOL_KM else 0.0  # below: the solver's own tolerance
        moved = float(np.max(np.abs(x_new[:, :3] - r_bar)))
        new_modes = _modes(geo, x_new[:, :3], motion)
        # each step's own bound within what both its nodes' constraints were tightened by
        bound_ok = bool(
            np.all(
                _step_margins(n, dt_s, u_max_km_s2, x_new, 0.0, 1.0, motion)
                <= np.minimum(margins[:-1], margins[1:])
            )
        )
        result = ConstrainedPlan(
            SolveStatus.CONVERGED if bound_ok else SolveStatus.FAILED,
            u,
            x_new[:, :3],
            modes,
            slack,
            scp,
            used,
            time.perf_counter() - start,
        )
        x_bar, r_bar = x_new, x_new[:, :3]
        settled = moved <= SCP_TOL_KM or cost - float(sol.obj_val) <= SCP_COST_RTOL * abs(cost)
        cost = float(sol.obj_val)
        if settled and slack == 0.0 and np.array_equal(new_modes, modes) and bound_ok:
            break
        modes = new_modes
    return result
