"""A projected dual Newton solver for the smoothed minimum-fuel program with linear path rows.

Issue 32: the constrained cone program's SCP subproblem, at adaptive ε (quadratic
weight ``c₂ = max(ε, ρ) ≥ 1e-3``) and, by a homotopy in the weight, at fixed ε
(``c₂ = ρ``; *Small weights* below). The program, in the scaled controls
``ũ_j = u_j/u_max`` (N × 3) on the zero-order-hold grid (exact CW dynamics,
paper Eq. 11: ``x_k = Φᵏ x₀ + Σ_{j<k} Φ^{k−1−j} Γ u_max ũ_j``):

    ``min Σ_j c₁‖ũ_j‖ + c₂‖ũ_j‖²``  s.t. ``‖ũ_j‖ ≤ 1``,
    ``g_iᵀ x_{k_i} = f_i`` (equality rows: the terminal state),
    ``g_iᵀ x_{k_i} ≥ f_i`` (inequality rows: keep-out half-spaces, trust box, abort rows),

``c₁ = 1 − ε``. It is the program of :mod:`.convex` (whose dual ascent,
:mod:`._grid_kernels`, is this solver's special case with the six terminal rows
only) with any number of rows, each a linear function of one node's state.

**Dual.** With ``L = Σ f(ũ_j) − Σ_i y_i (g_iᵀ x_{k_i} − f_i)`` (``y_i ≥ 0`` on
inequality rows) and ``A_j = Φ^{N−1−j} Γ u_max`` (the terminal blocks), a row
at node k acts on ũ_j (j < k) through ``g_iᵀ Φ^{k−1−j} Γ u_max = h_iᵀ A_j`` with
``h_i = (Φ^{k−N})ᵀ g_i``. So each step minimises ``f(ũ) − (A_jᵀ λ_j)ᵀ ũ`` with
the piecewise-constant ``λ_j = Σ_{i: k_i > j} y_i h_i`` — in closed form, the
smoothed law of paper Eq. 10 on the grid (:mod:`._grid_kernels`): ``ũ_j = a_j ŷ_j``,
``a_j = clip((‖y_j‖ − c₁)/(2c₂), 0, 1)``, ``y_j = A_jᵀ λ_j``. The dual function
``D(y) = yᵀ f' − Σ_j f*(y_j)`` (``f'_i = f_i − g_iᵀ Φ^{k_i} x₀``) is concave with
gradient ``f'_i − h_iᵀ Σ_{j<k_i} A_j ũ_j`` (the row's residual, negated) and
Hessian ``−h_aᵀ Q_{min(k_a,k_b)} h_b``, ``Q_k = Σ_{j<k} A_j J_j A_jᵀ``,
``J_j = ∂ũ_j/∂y_j`` (prefix sums: one pass over the steps whatever the rows).

**Method.** ``max D`` over ``y`` with ``y_i ≥ 0`` on inequality rows by the
projected Newton method of Bertsekas (1982, "Projected Newton methods for
optimization problems with simple constraints", SIAM J. Control Optim. 20(2)):
the inequality rows near their bound whose gradient points outward take a
scaled-gradient step, the others a Levenberg–Marquardt Newton step; a row the
Newton step would take below 0 is set to 0 and the step solved again for the
others (a primal–dual active-set step, :func:`_blocking_step`); violated rows
join the free set, :data:`ENTER` at a time and the most violated first, once the
free rows are within :data:`SETTLED_DIRECT` tolerances (:data:`SETTLED` in the
homotopy below); a step whose line search fails is tried again with more
Levenberg–Marquardt damping; an Armijo search along the
projection arc (backtracking by quadratic interpolation, :func:`_shrink`), or a
full step that leaves ``D`` flat to rounding and reduces the free rows' residuals
(two nearly parallel rows of neighbouring nodes make ``D`` almost flat along
their difference). **Certificate:** it stops only when
``ũ(y)`` — the Lagrangian's minimiser, so stationary by construction — meets
every equality row within its tolerance, every inequality row within its
tolerance, and every row with ``y_i > 0`` within its tolerance of equality
(complementarity); with ``c₂ > 0`` these KKT conditions make ``ũ(y)`` the
program's unique minimiser (to the tolerances). Otherwise the status is
failed and the caller solves the program with Clarabel (its reference).

**Small weights** (the fixed-ε architectures: ε = 0, ``c₂ = ρ = 1e-6``). There
a step's throttle ramps from 0 to 1 over ``‖y_j‖ ∈ [c₁, c₁ + 2c₂]``: the dual is
nearly piecewise linear and Newton from a distant start stalls. Below
:data:`HOMOTOPY_FROM` the weight is therefore followed down, ``1e-3, 1e-4, 1e-5,
ρ`` (:data:`HOMOTOPY_FACTOR`), each level's Newton started from the last one's
multipliers (a path-following in the smoothing, as the shooting method's fallback
chain continues in ε; here in the quadratic weight alone) and solved to
:data:`SETTLED` × the tolerances but the last, whose answer alone is certified as
above. And most steps coast: with ``keep`` the steps outside it (all but those
the previous plan thrusts on) are held at zero, which makes each Newton iteration
a pass over about a hundred steps instead of the whole horizon. A row at node k
acts on the kept steps before k, so the rows keep their vectors ``h`` and only
their nodes are renumbered. Zero minimises a held step's Lagrangian iff
``‖A_jᵀλ_j‖ ≤ c₁`` (:func:`held_norms`, for any ``c₂``), so the answer is the
whole program's exactly when every held step passes that test; the steps that
fail wake (with those within :data:`WAKE_MARGIN` of it) and the program is solved
again, the same screen as :mod:`.convex`'s at ε = 0 with Clarabel.

**A kinked last step** (:func:`solve_from_smooth`). A step whose ``‖y_j‖ < c₁`` coasts
and adds no curvature: a row whose effect differs from a combination of later rows only
through such steps leaves ``D`` linear along that difference, and Newton has no model
there (the cut of the corridor cone at the node before the port, with the terminal state
fixed: it binds the last control alone). Where the optimum asks that step for a sliver of
thrust (the port's drift over one step, a few 1e-4 u_max) the iterate crawls along the
dead zone with damped steps and fails (docs/solvers.md, *The last cut*). At ε = 1
(``c₁ = 0``, the quadratic cost alone) no step has a dead zone and the same rows'
program is solved in a few iterations; its multipliers are another start for the
program at ε, whose answer is certified as above (Newton only starts elsewhere: a
start changes no certificate). :mod:`.constrained` tries it on a program with cuts of the
corridor cone when its other starts (the warm one, the guess) have failed.

Units: km, s, km/s, km/s²; rows scaled by the caller (``h``, ``f`` and the
tolerances in the same scaled units).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from cwrend_cli.physics.dynamics import discretize, stm, zoh_rollout
from cwrend_cli.physics.guidance import feasibility
from cwrend_cli.physics.guidance._grid_kernels import step_law_by_products
from cwrend_cli.physics.guidance._kernels import STATUS_CONVERGED, STATUS_FAILED, _cholesky_solve

__all__ = [
    "ENTER",
    "HOMOTOPY_FACTOR",
    "HOMOTOPY_FROM",
    "MAX_ITER",
    "SMOOTH_EPS",
    "WAKE_MARGIN",
    "WAKE_ROUNDS",
    "DualAnswer",
    "DualRows",
    "held_norms",
    "numpy_sum",
    "solve",
    "solve_from_smooth",
    "transitions",
]

#: Newton iterations at most [-] (median 39 over the re-solves of seeds 0–1 of
#: campaigns/safe_approach.toml, MTF adaptive: 60 left 32 of 79 programs to Clarabel, 150
#: left 22; docs/solvers.md).
MAX_ITER = 150
#: Violated inequality rows that may join the free set in one iteration, the most violated
#: first [-] (a cold plan that crosses the zone violates the rows of tens of nodes, nearly
#: dependent on one another; a handful at a time keeps the Newton system small and well
#: posed).
ENTER = 4
#: Violated rows join once every free row is within this multiple of its tolerance [-]
#: (the working set need not be solved to the last digit before it grows); also the
#: tolerance of the homotopy's levels before the last (*Small weights*).
SETTLED = 1e3
#: :data:`SETTLED` of a program solved at its own weight (no homotopy: adaptive ε) [-]:
#: its violated rows join once the free rows are within this multiple, so that a row
#: found violated near the end is not entered after the working set has converged
#: (which restarts Newton for 2–3 iterations). Replayed on 400 re-solves of seeds 0–19
#: (docs/solvers.md): 1e3 → 1e7 saved 11 % of the Newton iterations (plain filter; 15 %
#: MTF), none failed; in the homotopy it made levels fail (6 → 51), so it stays 1e3 there.
SETTLED_DIRECT = 1e7
#: The smallest quadratic weight solved directly [-]; below it (ε = 0: ρ = 1e-6, the fixed-ε
#: architectures) :func:`solve` follows the weight down from here (module docstring,
#: *Small weights*).
HOMOTOPY_FROM = 1e-3
#: Factor between two weights of that homotopy [-] (1e-3, 1e-4, 1e-5, 1e-6 at ε = 0).
HOMOTOPY_FACTOR = 0.1
#: Held steps whose ``‖A_jᵀλ_j‖`` comes within this fraction of the switching value
#: ``1 − ε`` wake with those above it (:func:`solve`'s ``keep``) [-] (the screen of
#: :mod:`.convex`, its SCREEN_MARGIN).
WAKE_MARGIN = 0.03
#: Rounds of woken steps before every step is a variable [-].
WAKE_ROUNDS = 3
#: The cost weight ε of :func:`solve_from_smooth`'s first program [-]: 1, the quadratic
#: cost alone (``c₁ = 1 − ε = 0``), whose dual is smooth (module docstring, *A kinked last
#: step*).
SMOOTH_EPS = 1.0
_ARMIJO = 1e-4
#: Trials of the line search along one step [-].
_TRIALS = 4
#: Safeguards of the line search's next trial [-]: after a trial that lowered ``D`` the
#: next step is the maximiser of the quadratic through ``D``, its slope and the trial, kept
#: within these fractions of the trial's (Dennis & Schnabel 1983, "Numerical Methods for
#: Unconstrained Optimization and Nonlinear Equations", §6.3.2: [0.1, 0.5]); else half.
#: A warm re-solve's first Newton step overshoots ``D``'s maximum 20–40-fold; the halving
#: alone left 40 % of the plain filter's value passes in such iterations (docs/solvers.md).
_SHRINK_MIN = 0.1
_SHRINK_MAX = 0.5
#: Dampings tried in one iteration, ×10 each from 1e-4 (after the undamped step) [-]. The
#: plain projected Newton step (rows clipped at 0 instead of solved again), tried before
#: at each damping after the blocking step had failed, is not: its clipped rows break its
#: model, its line search fell to 1e-3 of its step, and the next damping's blocking step
#: did better. Replayed on 400 programs each: 18 % fewer value passes (plain filter),
#: 11 % (MTF), 12 % (fixed ε), no more failures (docs/solvers.md).
_DAMPING_TRIES = 20


class DualRows(NamedTuple):
    """Rows ``g_iᵀ x_{k_i} (= or ≥) f_i`` of the program, sorted by node.

    ``nodes`` (R,) int64 in 1 … N; ``coeffs`` (R, 6) g_i; ``offsets`` (R,) f_i;
    ``equality`` (R,) bool; ``tol`` (R,) each row's tolerance; all in the
    caller's scaled units (a row and its tolerance multiplied by one factor).
    """

    nodes: np.ndarray
    coeffs: np.ndarray
    offsets: np.ndarray
    equality: np.ndarray
    tol: np.ndarray


class DualAnswer(NamedTuple):
    """``converged``; ``controls`` (N, 3) [km/s²]; ``states`` (N + 1, 6); ``multipliers``
    (R,) of the rows (≥ 0 on inequality rows; in the rows' scaled units); ``cost`` the
    scaled cost ``Σ c₁‖ũ‖ + c₂‖ũ‖²``; ``iterations`` the Newton iterations; ``start``
    (below :data:`HOMOTOPY_FROM` only, else None): the multipliers at the homotopy's
    first weight, the warm start of a later homotopy on these rows (a re-solve's next
    one starts at that weight, where they are closer than ``multipliers``)."""

    converged: bool
    controls: np.ndarray
    states: np.ndarray
    multipliers: np.ndarray
    cost: float
    iterations: int
    start: np.ndarray | None = None


@njit(cache=True)
def _evaluate(
    a: np.ndarray,
    aat: np.ndarray,
    h: np.ndarray,
    f: np.ndarray,
    nodes: np.ndarray,
    y: np.ndarray,
    c1: float,
    c2: float,
    u: np.ndarray,
    curv: np.ndarray,
    grad: np.ndarray,
    q_rows: np.ndarray,
) -> float:
    """``D(y)``; writes ``ũ(y)`` (N, 3), the per-step curvature (N, 9), the gradient (R,)
    and each row's curvature prefix (R, 21): :func:`_value` then :func:`_forward`."""
    value = _value(a, h, f, nodes, y, c1, c2, u, curv)
    _forward(aat, h, f, nodes, curv, grad, q_rows)
    return value


@njit(cache=True)
def _value(
    a: np.ndarray,
    h: np.ndarray,
    f: np.ndarray,
    nodes: np.ndarray,
    y: np.ndarray,
    c1: float,
    c2: float,
    u: np.ndarray,
    curv: np.ndarray,
) -> float:
    """``D(y)``; writes ``ũ(y)`` and per step the curvature ``(iso, rad, A_j ŷ_j, a_j)``
    (N, 9) of ``J_j = iso I + rad ŷŷᵀ`` (module docstring; ``a_j`` the throttle, ``iso`` 0
    on a coasting step, whose other entries are then not written): the backward pass over
    the steps (the forward one, :func:`_forward`, sums what the gradient and the Hessian
    need)."""
    steps = a.shape[0]
    count = nodes.size
    lam = np.zeros(6)
    p = count - 1
    conj = 0.0
    slope = 1.0 / (2.0 * c2)
    for j in range(steps - 1, -1, -1):
        while p >= 0 and nodes[p] > j:
            if y[p] != 0.0:
                for i in range(6):
                    lam[i] += y[p] * h[p, i]
            p -= 1
        ny, level, ramp, h0, h1, h2, inv = step_law_by_products(a, j, lam, c1, slope, u)
        if level <= 0.0:
            curv[j, 0] = 0.0
            curv[j, 1] = 0.0
            continue
        conj += ny * level - c1 * level - c2 * level * level
        iso = level * inv
        curv[j, 0] = iso
        curv[j, 1] = (slope if ramp else 0.0) - iso
        for i in range(6):
            curv[j, 2 + i] = a[j, i, 0] * h0 + a[j, i, 1] * h1 + a[j, i, 2] * h2
        curv[j, 8] = level
    value = 0.0
    for p in range(count):  # Σ y_i f_i in the rows' order (sorted by node)
        value += y[p] * f[p]
    return value - conj


@njit(cache=True)
def _forward(
    aat: np.ndarray,
    h: np.ndarray,
    f: np.ndarray,
    nodes: np.ndarray,
    curv: np.ndarray,
    grad: np.ndarray,
    q_rows: np.ndarray,
) -> None:
    """From :func:`_value`'s curvature, one forward pass over the steps: writes the gradient
    (R,) of ``D``, each row's residual ``f_i − h_iᵀ Σ_{j<k_i} A_j ũ_j`` (``A_j ũ_j = a_j
    A_j ŷ_j``), and each row's curvature prefix ``Q_{k_i} = Σ_{j<k_i} A_j J_j A_jᵀ``
    (R, 21: the upper triangle, row by row), from which :func:`_hessian` writes the
    Hessian of any set of rows. The six running sums of ``A_j ũ_j`` are scalars the
    compiler keeps in registers (an array it would store at every step)."""
    steps = curv.shape[0]
    count = nodes.size
    s0 = s1 = s2 = s3 = s4 = s5 = 0.0
    q = np.zeros(21)
    p = 0
    for j in range(steps):
        iso = curv[j, 0]
        if iso != 0.0:  # a thrusting step (a coasting one adds nothing)
            rad = curv[j, 1]
            lv = curv[j, 8]
            s0 += lv * curv[j, 2]
            s1 += lv * curv[j, 3]
            s2 += lv * curv[j, 4]
            s3 += lv * curv[j, 5]
            s4 += lv * curv[j, 6]
            s5 += lv * curv[j, 7]
            k = 0
            for r in range(6):
                ar = rad * curv[j, 2 + r]
                for c in range(r, 6):
                    q[k] += iso * aat[j, r, c] + ar * curv[j, 2 + c]
                    k += 1
        while p < count and nodes[p] == j + 1:
            acc = h[p, 0] * s0 + h[p, 1] * s1 + h[p, 2] * s2
            acc = acc + h[p, 3] * s3 + h[p, 4] * s4 + h[p, 5] * s5
            grad[p] = f[p] - acc
            for k in range(21):
                q_rows[p, k] = q[k]
            p += 1


@njit(cache=True)
def _hessian(
    q_rows: np.ndarray, h: np.ndarray, free: np.ndarray, n_free: int, out: np.ndarray
) -> None:
    """``−H`` on the rows ``free[:n_free]`` (sorted by node): ``h_aᵀ Q_{min(k_a,k_b)} h_b``
    from the rows' curvature prefixes (:func:`_forward`)."""
    qh = np.empty((n_free, 6))  # Q_{k_a} h_a
    for p in range(n_free):
        row = free[p]
        for r in range(6):
            acc = 0.0
            for c in range(6):
                lo, hi = (r, c) if r <= c else (c, r)
                acc += q_rows[row, lo * 6 - lo * (lo - 1) // 2 + hi - lo] * h[row, c]
            qh[p, r] = acc
    for a_ in range(n_free):
        for b_ in range(a_, n_free):  # k_a ≤ k_b: Q_{min} = Q_{k_a}
            acc = 0.0
            for c in range(6):
                acc += qh[a_, c] * h[free[b_], c]
            out[a_, b_] = acc
            out[b_, a_] = acc


@njit(cache=True)
def _fill_metric(
    gram: np.ndarray, h: np.ndarray, nodes: np.ndarray, i: int, metric: np.ndarray
) -> float:
    """Row i's Levenberg–Marquardt metric ``h_iᵀ G_{k_i} h_i`` (``gram``: the prefix sums
    ``G_k = Σ_{j<k} A_j A_jᵀ``), computed the first time a row needs it (floored)."""
    if metric[i] < 0.0:
        k = nodes[i]
        acc = 0.0
        for r in range(6):
            for c in range(6):
                acc += h[i, r] * gram[k, r, c] * h[i, c]
        metric[i] = max(acc, 1e-300)
    return float(metric[i])


@njit(cache=True)
def _merit(grad: np.ndarray, free: np.ndarray, n_free: int, tol: np.ndarray) -> float:
    """``Σ (g_i/tol_i)²`` over the free rows: what a Newton step on them reduces."""
    total = 0.0
    for p in range(n_free):
        total += (grad[free[p]] / tol[free[p]]) ** 2
    return total


@njit(cache=True)
def _kkt_error(
    y: np.ndarray, grad: np.ndarray, equality: np.ndarray, tol: np.ndarray
) -> tuple[bool, int]:
    """(every row within its tolerance, the most violated inequality row at 0 or −1)."""
    ok = True
    worst = -1
    worst_v = 0.0
    for i in range(y.size):
        g = grad[i]
        if equality[i] or y[i] > 0.0:
            if abs(g) > tol[i]:
                ok = False
        elif g > tol[i]:
            ok = False
            if g / tol[i] > worst_v:
                worst_v = g / tol[i]
                worst = i
    return ok, worst


@njit(cache=True)
def _shrink(gain: float, change: float) -> float:
    """The factor of the line search's next step after a trial that failed [-]:
    ``gain`` the trial's first-order increase of ``D`` (its slope along the trial, times
    the trial), ``change`` its actual one. When ``D`` fell (``change < 0 < gain``) the
    maximiser ``gain / (2 (gain − change))`` of the quadratic ``q(t) = gain·t − (gain −
    change)·t²`` (``q(0) = 0``, ``q'(0) = gain``, ``q(1) = change``), within
    [:data:`_SHRINK_MIN`, :data:`_SHRINK_MAX`]; else :data:`_SHRINK_MAX` (halving)."""
    if gain > 0.0 and change < 0.0:
        return min(_SHRINK_MAX, max(_SHRINK_MIN, gain / (2.0 * (gain - change))))
    return _SHRINK_MAX


@njit(cache=True)
def _blocking_step(
    hess: np.ndarray,
    mat: np.ndarray,
    g_f: np.ndarray,
    y: np.ndarray,
    free: np.ndarray,
    n_free: int,
    equality: np.ndarray,
    step: np.ndarray,
) -> bool:
    """The Newton step on the free rows (``mat``: ``−H`` damped), with every inequality row
    whose multiplier the step would take below 0 sent to 0 and the step solved again for
    the others given that move (a primal–dual active-set step: a row that leaves does so
    in one iteration). False if a system is not positive definite."""
    kept = np.ones(n_free, dtype=np.bool_)
    for _round in range(n_free):
        idx = np.flatnonzero(kept)
        m = idx.size
        sub = np.empty((m, m))
        rhs = np.empty(m)
        for r in range(m):
            acc = g_f[idx[r]]
            for q in range(n_free):
                if not kept[q]:  # d_q = −y_q moves the model's gradient by M_rq y_q
                    acc += hess[idx[r], q] * y[free[q]]
            rhs[r] = acc
            for c in range(m):
                sub[r, c] = mat[idx[r], idx[c]]
        out = np.empty(m)
        if not _cholesky_solve(sub, rhs, out):
            return False
        for q in range(n_free):
            if not kept[q]:
                step[q] = -y[free[q]]
        for r in range(m):
            step[idx[r]] = out[r]
        blocked = False
        for r in range(m):
            q = idx[r]
            if not equality[free[q]] and y[free[q]] + out[r] < 0.0:
                kept[q] = False
                blocked = True
        if not blocked:
            return True
    return True


@njit(cache=True)
def projected_newton(
    a: np.ndarray,
    aat: np.ndarray,
    h: np.ndarray,
    f: np.ndarray,
    nodes: np.ndarray,
    equality: np.ndarray,
    tol: np.ndarray,
    metric: np.ndarray,
    c1: float,
    c2: float,
    y: np.ndarray,
    u: np.ndarray,
    max_iter: int,
    enter: int,
    enter_at: float,
) -> tuple[int, int]:
    """Maximise ``D`` over ``y`` (inequality entries ≥ 0) from ``y`` in place; writes ``ũ``.
    ``enter`` violated rows at most join the free set in one iteration, once the free
    rows are within ``enter_at`` × their tolerances (:data:`SETTLED`, :data:`SETTLED_DIRECT`).

    Returns ``(status, iterations)``: ``STATUS_CONVERGED`` when the KKT
    conditions hold to ``tol`` (module docstring), else ``STATUS_FAILED``.
    ``aat`` (N, 6, 6): the products ``A_j A_jᵀ`` of ``a`` (:func:`block_products`).
    ``metric`` (R,): the Levenberg–Marquardt metric ``h_iᵀ (Σ_{j<k_i} A_j A_jᵀ) h_i`` of
    each row, negative where not yet computed (filled as rows need it).
    """
    steps = a.shape[0]
    count = nodes.size
    gram = np.zeros((steps + 1, 6, 6))
    for j in range(steps):
        for r in range(6):
            for c in range(6):
                gram[j + 1, r, c] = gram[j, r, c] + aat[j, r, c]
    for i in range(count):
        if not equality[i] and y[i] < 0.0:
            y[i] = 0.0
    curv = np.empty((steps, 9))
    grad = np.empty(count)
    q_rows = np.empty((count, 21))
    u_t = np.empty((steps, 3))
    curv_t = np.empty((steps, 9))
    grad_t = np.empty(count)
    q_rows_t = np.empty((count, 21))
    y_t = np.empty(count)
    free = np.empty(count, dtype=np.int64)
    bound = np.empty(count, dtype=np.int64)
    in_free = np.zeros(count, dtype=np.bool_)
    value = _evaluate(a, aat, h, f, nodes, y, c1, c2, u, curv, grad, q_rows)
    # an accepted trial's arrays become the iterate's by swapping (no copy); the caller's
    # ``y`` and ``u`` receive the last iterate on return when it is held in the others
    y_out, u_out = y, u
    swapped = False
    damping = 0.0
    for it in range(max_iter + 1):
        ok, _ = _kkt_error(y, grad, equality, tol)
        if ok:
            if swapped:
                y_out[:] = y
                u_out[:, :] = u
            return STATUS_CONVERGED, it
        if it == max_iter:
            break
        # free set: equality rows, inequality rows away from their bound or violated
        # (at most ``enter`` of the violated rows at 0 join, the most violated first)
        n_free = 0
        n_bound = 0
        settled = True  # the rows already free hold: only then may violated rows join
        # Bertsekas's binding set: positive multipliers within δ (the projected scaled
        # gradient's size) of 0 whose gradient pushes them there take a scaled-gradient
        # step instead of a Newton step
        delta = 0.0
        for i in range(count):
            if not equality[i] and y[i] > 0.0:
                m_i = _fill_metric(gram, h, nodes, i, metric)
                delta = max(delta, y[i] - max(0.0, y[i] + grad[i] / m_i))
        for i in range(count):
            in_free[i] = equality[i] or y[i] > 0.0
            if in_free[i] and abs(grad[i]) > enter_at * tol[i]:
                settled = False
            if not equality[i] and 0.0 < y[i] <= delta and grad[i] < 0.0:
                in_free[i] = False
                bound[n_bound] = i
                n_bound += 1
        for _e in range(enter if settled else 0):
            best = -1
            best_v = 0.0
            for i in range(count):
                if not in_free[i] and grad[i] > tol[i] and grad[i] / tol[i] > best_v:
                    best_v = grad[i] / tol[i]
                    best = i
            if best < 0:
                break
            in_free[best] = True
        for i in range(count):
            if in_free[i]:
                free[n_free] = i
                n_free += 1
                _fill_metric(gram, h, nodes, i, metric)
        if n_free == 0 and n_bound == 0:
            break
        hess = np.empty((n_free, n_free))
        _hessian(q_rows, h, free, n_free, hess)
        g_f = np.empty(n_free)
        for p in range(n_free):
            g_f[p] = grad[free[p]]
        step = np.empty(n_free)
        mat = np.empty((n_free, n_free))
        accepted = False
        for _try in range(_DAMPING_TRIES):
            # the blocking step; when its line search fails, again with more damping
            for r in range(n_free):
                for c in range(n_free):
                    mat[r, c] = hess[r, c]
                mat[r, r] += max(damping, 1e-12) * metric[free[r]]
            if not _blocking_step(hess, mat, g_f, y, free, n_free, equality, step):
                damping = max(10.0 * damping, 1e-4)
                continue
            alpha = 1.0
            for _ls in range(_TRIALS):
                y_t[:] = y
                gain = 0.0
                for p in range(n_free):
                    i = free[p]
                    y_t[i] = y[i] + alpha * step[p]
                    if not equality[i] and y_t[i] < 0.0:
                        y_t[i] = 0.0
                    gain += grad[i] * (y_t[i] - y[i])
                for p in range(n_bound):
                    i = bound[p]
                    y_t[i] = max(0.0, y[i] + alpha * grad[i] / metric[i])
                    gain += grad[i] * (y_t[i] - y[i])
                if not gain > 0.0 and alpha != 1.0:  # neither test below can pass: skip D
                    alpha *= _SHRINK_MAX
                    continue
                # the trial's gradient only where it is read (an accepted or a flat step)
                value_t = _value(a, h, f, nodes, y_t, c1, c2, u_t, curv_t)
                if gain > 0.0 and value_t >= value + _ARMIJO * gain:
                    _forward(aat, h, f, nodes, curv_t, grad_t, q_rows_t)
                    accepted = True
                    break
                # a full step that leaves D flat to rounding (near the optimum, along a
                # nearly dependent pair of rows) is taken when it reduces the KKT errors
                flat = alpha == 1.0 and value_t >= value - 1e-13 * (abs(value) + 1e-300)
                if flat:
                    _forward(aat, h, f, nodes, curv_t, grad_t, q_rows_t)
                if flat and _merit(grad_t, free, n_free, tol) < _merit(grad, free, n_free, tol):
                    accepted = True
                    break
                alpha *= _shrink(gain, value_t - value)
            if accepted:
                if alpha == 1.0:
                    damping = 0.0 if damping < 1e-6 else damping * 0.01
                break
            damping = max(10.0 * damping, 1e-4)
        if not accepted:
            break
        y, y_t = y_t, y
        u, u_t = u_t, u
        curv, curv_t = curv_t, curv
        q_rows, q_rows_t = q_rows_t, q_rows
        grad, grad_t = grad_t, grad
        value = value_t
        swapped = not swapped
    if swapped:
        y_out[:] = y
        u_out[:, :] = u
    return STATUS_FAILED, it


@njit(cache=True)
def block_products(a: np.ndarray) -> np.ndarray:
    """``A_j A_jᵀ`` (N, 6, 6) of the blocks ``a`` (N, 6, 3): what :func:`projected_newton`'s
    Hessian adds up step by step."""
    aat = np.empty((a.shape[0], 6, 6))
    for j in range(a.shape[0]):
        for r in range(6):
            for c in range(6):
                aat[j, r, c] = (
                    a[j, r, 0] * a[j, c, 0] + a[j, r, 1] * a[j, c, 1] + a[j, r, 2] * a[j, c, 2]
                )
    return aat


#: :func:`grid_arrays` kept, by (n, Δt, u_max): the longest stacks made so far.
_PRODUCTS: dict[tuple[float, float, float], tuple[np.ndarray, np.ndarray]] = {}
#: Stacks kept in :data:`_PRODUCTS` at most (the oldest dropped) [-].
PRODUCTS_KEPT = 8


def grid_arrays(n: float, dt_s: float, u_max: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The scaled terminal blocks ``A_j = Φ^{N−1−j} Γ u_max`` (N, 6, 3) of a ``steps``-step
    grid (:func:`~.feasibility.grid_blocks` times u_max) and their
    :func:`block_products` (N, 6, 6), read-only.

    Each step's block and product are its own, and the last ``steps`` blocks of a longer
    grid are this grid's (:func:`~.feasibility.grid_blocks` slices one stack), so the
    longest stacks made for ``(n, Δt, u_max)`` are kept and sliced: the same bits as made
    afresh, once per closed loop instead of once per program (a re-solve's horizon only
    shrinks)."""
    key = (float(n), float(dt_s), float(u_max))
    cached = _PRODUCTS.get(key)
    if cached is None or cached[0].shape[0] < steps:
        scaled = np.ascontiguousarray(feasibility.grid_blocks(n, dt_s, steps) * u_max)
        cached = (scaled, block_products(scaled))
        _keep(_PRODUCTS, key, cached)
    size = cached[0].shape[0]
    return cached[0][size - steps :], cached[1][size - steps :]


#: :func:`backward_transitions` kept, by (n, Δt): the longest table made so far.
_BACKWARD: dict[tuple[float, float], np.ndarray] = {}


def backward_transitions(n: float, dt_s: float, steps: int) -> np.ndarray:
    """``Φ(−mΔt)`` (steps + 1, 6, 6) for m = 0 … ``steps``, each the closed-form
    :func:`~cwrend_cli.physics.dynamics.stm` of its own time (not a product), read-only:
    what :func:`_row_vectors` carries a row at node k back by (m = N − k).

    A longer table's first entries are this one's, so the longest table made for
    ``(n, Δt)`` is kept and sliced: the same bits as made afresh, once per closed loop
    instead of once a distinct row node per program."""
    key = (float(n), float(dt_s))
    cached = _BACKWARD.get(key)
    if cached is None or cached.shape[0] <= steps:
        cached = _transitions_back(n, dt_s, steps + 1)
        cached.flags.writeable = False
        _keep(_BACKWARD, key, cached)
    return cached[: steps + 1]


#: :func:`transitions` kept, by (n, Δt).
_TRANSITIONS: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}


def transitions(n: float, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~cwrend_cli.physics.dynamics.discretize`'s ``(Φ, Γ)`` of one step, kept by
    ``(n, Δt)`` (the same bits as made afresh; a closed loop's re-solves share one step),
    shared: read them, never write them."""
    key = (float(n), float(dt_s))
    cached = _TRANSITIONS.get(key)
    if cached is None:
        cached = discretize(n, dt_s)
        _keep(_TRANSITIONS, key, cached)
    return cached


def _keep(cache: dict[Any, Any], key: Any, value: Any) -> None:
    """Keep ``value`` as ``cache[key]``, the newest entry, the oldest dropped beyond
    :data:`PRODUCTS_KEPT` entries."""
    cache.pop(key, None)
    while len(cache) >= PRODUCTS_KEPT:
        cache.pop(next(iter(cache)))
    cache[key] = value


@njit(cache=True)
def _step_costs(u: np.ndarray, c1: float, c2: float) -> np.ndarray:
    """Each step's scaled cost ``c₁‖ũ_j‖ + c₂‖ũ_j‖²`` (N,) of the scaled controls ``u``
    (N, 3): numpy's elementwise arithmetic in its order (``norms**2`` is ``norms *
    norms``), :func:`~cwrend_cli.physics.constraints.row_norms`' norms: the same bits."""
    out = np.empty(u.shape[0])
    for j in range(u.shape[0]):
        size = math.sqrt(u[j, 0] * u[j, 0] + u[j, 1] * u[j, 1] + u[j, 2] * u[j, 2])
        out[j] = c1 * size + c2 * (size * size)
    return out


@njit(cache=True)
def _transitions_back(n: float, dt_s: float, count: int) -> np.ndarray:
    """:func:`backward_transitions`' table of ``count`` entries: ``stm(n, (−m) Δt)``."""
    out = np.empty((count, 6, 6))
    for m in range(count):
        out[m] = stm(n, (-m) * dt_s)
    return out


@njit(cache=True)
def _row_vectors(
    back: np.ndarray, steps: int, nodes: np.ndarray, coeffs: np.ndarray, out: np.ndarray
) -> None:
    """``h_i = (Φ^{k_i−N})ᵀ g_i`` (module docstring), ``Φ^{k−N}`` = ``back[N − k]``
    (:func:`backward_transitions`)."""
    for i in range(nodes.size):
        m = steps - nodes[i]
        for c in range(6):
            acc = 0.0
            for r in range(6):
                acc += back[m, r, c] * coeffs[i, r]
            out[i, c] = acc


@njit(cache=True)
def _row_inputs(
    phi: np.ndarray,
    gam: np.ndarray,
    x0: np.ndarray,
    back: np.ndarray,
    nodes: np.ndarray,
    coeffs: np.ndarray,
    offsets: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """What :func:`solve` reads of the rows ``g_iᵀ x_{k_i} (≥ or =) f_i`` (``coeffs`` (R, 6),
    ``offsets`` (R,)) at ``nodes`` (R,): their vectors ``h_i`` (:func:`_row_vectors`,
    ``back`` from :func:`backward_transitions`) and ``f'_i = f_i − g_iᵀ Φ^{k_i} x₀`` (module
    docstring), the free drift's states ``Φ^{k_i} x₀`` by ``zoh_rollout`` of zero controls
    and ``g_iᵀ Φ^{k_i} x₀`` by :func:`_einsum_row_dot` (numpy's einsum, the same bits)."""
    steps = back.shape[0] - 1
    free = zoh_rollout(phi, gam, x0, np.zeros((steps, 3)))
    h = np.empty_like(coeffs)
    _row_vectors(back, steps, nodes, coeffs, h)
    f = np.empty(nodes.size)
    for i in range(nodes.size):
        f[i] = offsets[i] - _einsum_row_dot(coeffs[i], free[nodes[i]])
    return h, f


@njit(cache=True)
def _einsum_row_dot(g: np.ndarray, x: np.ndarray) -> float:
    """``gᵀx`` of two 6-vectors as ``np.einsum("ij,ij->i", …)`` sums a row: two lanes (its
    128-bit SIMD loop, numpy's x86-64 baseline: einsum is not dispatched to wider
    registers), each from 0.0, of the products 0, 2, 4 and 1, 3, 5 in order, then added."""
    even = ((0.0 + g[0] * x[0]) + g[2] * x[2]) + g[4] * x[4]
    odd = ((0.0 + g[1] * x[1]) + g[3] * x[3]) + g[5] * x[5]
    return float(even + odd)


#: numpy's block of its pairwise sum: a block of at most this many values is summed by eight
#: accumulators (:func:`_pairwise_block`) [-].
_PAIRWISE_BLOCK = 128


@njit(cache=True)
def _pairwise_block(values: np.ndarray, start: int, count: int) -> float:
    """numpy's pairwise sum of ``values[start : start + count]``, ``count`` ≤
    :data:`_PAIRWISE_BLOCK` (its ``pairwise_sum`` of a contiguous float64 array): fewer than 8
    values in order from 0.0; else eight running sums of every eighth value, added in pairs,
    then the rest in order."""
    if count < 8:
        out = 0.0
        for i in range(start, start + count):
            out += values[i]
        return out
    v = values
    r0, r1, r2, r3 = v[start], v[start + 1], v[start + 2], v[start + 3]
    r4, r5, r6, r7 = v[start + 4], v[start + 5], v[start + 6], v[start + 7]
    i = start + 8
    end = start + count - count % 8
    while i < end:
        r0, r1, r2, r3 = r0 + v[i], r1 + v[i + 1], r2 + v[i + 2], r3 + v[i + 3]
        r4, r5, r6, r7 = r4 + v[i + 4], r5 + v[i + 5], r6 + v[i + 6], r7 + v[i + 7]
        i += 8
    out = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for k in range(i, start + count):
        out += v[k]
    return float(out)


@njit(cache=True)
def numpy_sum(values: np.ndarray) -> float:
    """``np.sum`` of a 1-D float64 array, bit for bit (numpy's pairwise sum of a contiguous
    array; 0.0 when empty): for a sum inside a kernel, whose value then needs no array
    handed back to numpy. A stretch of more than :data:`_PAIRWISE_BLOCK` values sums as its
    two halves' sums added (the first half a multiple of 8 long), down to blocks
    (:func:`_pairwise_block`); the halves are walked with a stack, not by recursion (numba's
    cache does not load a recursive kernel safely)."""
    if values.size <= _PAIRWISE_BLOCK:
        return _pairwise_block(values, 0, values.size)
    # each stretch on the stack: its start and length, and whether its second half is being
    # summed (its first half's sum then in ``left``)
    start = np.empty(64, np.int64)
    count = np.empty(64, np.int64)
    second = np.zeros(64, np.bool_)
    left = np.empty(64)
    top = 0
    start[0], count[0] = 0, values.size
    while True:
        size = count[top]
        if size > _PAIRWISE_BLOCK:  # split: its first half next
            half = size // 2
            half -= half % 8
            top += 1
            start[top], count[top], second[top] = start[top - 1], half, False
            continue
        total = _pairwise_block(values, start[top], size)
        top -= 1
        while top >= 0 and second[top]:  # a second half done: its stretch's sum
            total = left[top] + total
            top -= 1
        if top < 0:
            return total
        left[top], second[top] = total, True  # a first half done: the second half next
        half = count[top] // 2
        half -= half % 8
        top += 1
        start[top], count[top] = start[top - 1] + half, count[top - 1] - half
        second[top] = False


@njit(cache=True)
def _answer_arrays(
    phi: np.ndarray,
    gam: np.ndarray,
    x0: np.ndarray,
    u: np.ndarray,
    u_max: float,
    c1: float,
    c2: float,
) -> tuple[float, np.ndarray, np.ndarray]:
    """:func:`solve`'s answer from the scaled controls ``u`` (N, 3): its cost (numpy's sum,
    :func:`numpy_sum`, of each step's :func:`_step_costs`), the controls ``u × u_max`` (N, 3)
    [km/s²] and their states from ``x0`` (``zoh_rollout``, N + 1, 6): numpy's elementwise
    product, the same bits."""
    controls = np.empty_like(u)
    for j in range(u.shape[0]):
        for c in range(3):
            controls[j, c] = u[j, c] * u_max
    cost = numpy_sum(_step_costs(u, c1, c2))
    return cost, controls, zoh_rollout(phi, gam, x0, controls)


def held_norms(a: np.ndarray, h: np.ndarray, nodes: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``‖A_jᵀ λ_j‖`` (N,) of every step at the multipliers ``y`` (R,) of rows at ``nodes``
    (sorted, original grid), ``λ_j = Σ_{i: k_i > j} y_i h_i`` (module docstring); ``a``
    (N, 6, 3) the scaled blocks ``A_j``. Step j thrusts in the Lagrangian's minimiser iff
    it exceeds ``c₁`` (whatever ``c₂``)."""
    suffix = np.zeros((nodes.size + 1, 6))
    suffix[:-1] = np.cumsum((y[:, None] * h)[::-1], axis=0)[::-1]
    lam = suffix[np.searchsorted(nodes, np.arange(a.shape[0]), side="right")]
    norms: np.ndarray = np.linalg.norm(np.einsum("jab,ja->jb", a, lam), axis=1)
    return norms


def _homotopy(
    a: np.ndarray,
    aat: np.ndarray,
    h: np.ndarray,
    f: np.ndarray,
    nodes: np.ndarray,
    rows: DualRows,
    c1: float,
    weight: float,
    y: np.ndarray,
    u: np.ndarray,
    max_iter: int,
    first: np.ndarray | None = None,
) -> tuple[int, int]:
    """:func:`projected_newton` at ``weight``; below :data:`HOMOTOPY_FROM`, along the
    weights ``HOMOTOPY_FROM``, × :data:`HOMOTOPY_FACTOR` …, ``weight``, each level started
    from the last one's multipliers, the levels before the last to :data:`SETTLED` ×
    the rows' tolerances (only the last one's answer is certified); at or above it,
    directly, violated rows joining from :data:`SETTLED_DIRECT`. (status, iterations
    summed); ``first`` receives the multipliers of the level ``HOMOTOPY_FROM`` (the next
    homotopy's start: :attr:`DualAnswer.start`)."""
    metric = np.full(nodes.size, -1.0)
    level = max(float(weight), HOMOTOPY_FROM)
    enter_at = SETTLED_DIRECT if weight >= HOMOTOPY_FROM else SETTLED
    total = 0
    while True:
        last = level == weight
        tol = rows.tol if last else rows.tol * SETTLED
        status, iterations = projected_newton(
            a, aat, h, f, nodes, rows.equality, tol, metric, c1, level, y, u, max_iter, ENTER,
            enter_at,
        )  # fmt: skip
        total += iterations
        if first is not None and level == HOMOTOPY_FROM:
            first[:] = y
        # a level before the last that stalls early hands its multipliers on (only the
        # last is certified); one that reached the cap, or the first, ends the homotopy
        stalled = status != STATUS_CONVERGED
        if last or (stalled and (level == HOMOTOPY_FROM or iterations >= max_iter)):
            return status, total
        level *= HOMOTOPY_FACTOR
        if level <= weight * (1.0 + 1e-9):  # the last level is the weight itself
            level = float(weight)


def solve(
    n: float,
    dt_s: float,
    u_max: float,
    x0: np.ndarray,
    blocks: np.ndarray,
    eps: float,
    weight: float,
    rows: DualRows,
    warm: np.ndarray | None = None,
    max_iter: int = MAX_ITER,
    keep: np.ndarray | None = None,
    products: np.ndarray | None = None,
    scaled: np.ndarray | None = None,
) -> DualAnswer:
    """The program (module docstring) from ``x0`` over the grid of ``blocks`` (N, 6, 3), the
    terminal blocks Φ^{N−1−j}Γ of :func:`~.feasibility.grid_problem` [s, s²], with
    linear cost weight ``1 − ε`` and quadratic ``weight``; ``warm``: starting multipliers
    (R,) of ``rows`` (zero when None).

    Below :data:`HOMOTOPY_FROM` the weight is followed down to ``weight``
    (:func:`_homotopy`; module docstring, *Small weights*). ``keep`` (sorted step
    indices, e.g. the steps the previous plan thrusts on): the other steps are first
    held at zero, as are those the warm multipliers screen (:data:`WAKE_MARGIN`);
    the answer is accepted only when every held step's zero minimises its Lagrangian
    (``‖A_jᵀλ_j‖ ≤ 1 − ε``, :func:`held_norms`), else the steps that fail wake and
    the program is solved again, warm (:data:`WAKE_ROUNDS`, then every step).
    ``scaled``, ``products``: ``blocks × u_max`` and its :func:`block_products` when the
    caller has them (:func:`grid_arrays`), else made here."""
    steps = blocks.shape[0]
    phi, gam = transitions(n, dt_s)
    x0 = np.ascontiguousarray(x0, dtype=np.float64)
    a_all = np.ascontiguousarray(blocks * u_max) if scaled is None else scaled
    aat_all = block_products(a_all) if products is None else products
    if aat_all.shape != (steps, 6, 6) or a_all.shape != (steps, 6, 3):
        raise ValueError(
            f"scaled and products must be ({steps}, 6, 3) and ({steps}, 6, 6), "
            f"not {a_all.shape} and {aat_all.shape}"
        )
    h, f = _row_inputs(
        phi, gam, x0, backward_transitions(n, dt_s, steps), rows.nodes, rows.coeffs, rows.offsets
    )
    y = np.zeros(rows.nodes.size) if warm is None else np.array(warm, dtype=np.float64)
    c1 = 1.0 - min(float(eps), 1.0)
    if keep is not None:  # step 0 precedes every row: each row acts on a kept step
        keep = np.union1d(keep, 0)
        held = np.setdiff1d(np.arange(steps), keep)
        norms = held_norms(a_all, h, rows.nodes, y)
        keep = np.union1d(keep, held[norms[held] > c1 * (1.0 - WAKE_MARGIN)])
    u = np.zeros((steps, 3))
    start = np.zeros(rows.nodes.size) if weight < HOMOTOPY_FROM else None
    total = 0
    converged = False
    for round_ in range(WAKE_ROUNDS + 1):
        if keep is not None and (keep.size == steps or round_ == WAKE_ROUNDS):
            keep = None
        if keep is None:
            status, iterations = _homotopy(
                a_all, aat_all, h, f, rows.nodes, rows, c1, weight, y, u, max_iter, start
            )
        else:  # the rows at node k act on the kept steps before k: renumber the nodes
            u_kept = np.zeros((keep.size, 3))
            status, iterations = _homotopy(
                np.ascontiguousarray(a_all[keep]), np.ascontiguousarray(aat_all[keep]), h, f,
                np.searchsorted(keep, rows.nodes).astype(np.int64), rows, c1, weight, y,
                u_kept, max_iter, start,
            )  # fmt: skip
            u[:] = 0.0
            u[keep] = u_kept
        total += iterations
        if status != STATUS_CONVERGED:
            break
        if keep is None:
            converged = True
            break
        held = np.setdiff1d(np.arange(steps), keep)
        norms = held_norms(a_all, h, rows.nodes, y)
        if not np.any(norms[held] > c1):
            converged = True
            break
        keep = np.union1d(keep, held[norms[held] > c1 * (1.0 - WAKE_MARGIN)])
        if start is not None:  # the next round's homotopy starts where this one's did
            y[:] = start
    cost, controls, states = _answer_arrays(phi, gam, x0, u, u_max, c1, weight)
    return DualAnswer(converged, controls, states, y, cost, int(total), start)


def solve_from_smooth(
    n: float,
    dt_s: float,
    u_max: float,
    x0: np.ndarray,
    blocks: np.ndarray,
    eps: float,
    weight: float,
    rows: DualRows,
    warm: np.ndarray | None = None,
    max_iter: int = MAX_ITER,
    products: np.ndarray | None = None,
    scaled: np.ndarray | None = None,
) -> DualAnswer:
    """:func:`solve` started from the multipliers of the same rows' smooth program (module
    docstring, *A kinked last step*): first the program at ε = :data:`SMOOTH_EPS` (the
    quadratic cost ``‖ũ_j‖²`` alone, ``c₁ = 0``: no step has a dead zone) from ``warm``,
    then the program at ``eps`` and ``weight`` from its multipliers, whose answer alone is
    certified (its ``converged``). Weights of at least :data:`HOMOTOPY_FROM` only (every
    step a variable). ``iterations`` counts both solves'."""
    if weight < HOMOTOPY_FROM:
        raise ValueError(f"a weight of at least {HOMOTOPY_FROM}, not {weight}")
    grid = (n, dt_s, u_max, x0, blocks)
    smooth = solve(
        *grid, SMOOTH_EPS, max(SMOOTH_EPS, weight), rows, warm, max_iter,
        products=products, scaled=scaled,
    )  # fmt: skip
    ans = solve(
        *grid, eps, weight, rows, smooth.multipliers, max_iter, products=products, scaled=scaled
    )
    return ans._replace(iterations=smooth.iterations + ans.iterations)
