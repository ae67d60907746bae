"""Compiled kernels of the shooting solver (private; see :mod:`cwrend_cli.physics.guidance`).

Units: km, s, km/s, km/s², rad/s. Arrays and floats only, no config objects.

The shooting problem (paper Sec. "Receding-Horizon Indirect Guidance"): find
``λ₀`` so that the state, driven by the control law of Eq. (10) with
``λ(τ) = e^{−Aᵀτ} λ₀``, reaches ``x_f`` at ``T``.
With ``W(τ) = Φ(−τ) B`` we have ``λ_v(τ) = W(τ)ᵀ λ₀`` and

    x(T) = Φ(T) [x₀ + ∫₀ᵀ W(τ) u(τ) dτ],

so the residual in the initial frame is ``G(λ₀) = ∫ W u dτ − d`` with
``d = Φ(−T) x_f − x₀``. ``G`` is the gradient of the concave function

    D(λ₀) = −λ₀ᵀ d − u_max ∫₀ᵀ Ψ_ε(‖W(τ)ᵀ λ₀‖) dτ,

where ``Ψ_ε' = φ_ε`` is the throttle of Eq. (10) (``Ψ_ε(p) = 0`` below
``1 − ε``, ``(p − 1 + ε)²/(4ε)`` on the ramp, ``p − 1`` above ``1 + ε``).
``D`` is the Lagrange dual of the (smoothed) minimum-fuel problem with the
sign convention ``ν = −λ₀``. Solving the shooting problem is therefore
maximising a concave function: a Newton/Levenberg–Marquardt ascent with a
line search on ``D`` itself is globally convergent, which is what makes the
ε = 0 re-solves reliable. The dual also certifies infeasibility: if some
``λ`` has ``−λᵀd − u_max ∫‖Wᵀλ‖ dτ > 0`` then ``D`` is unbounded along that
ray and, by weak duality, no control with ``‖u‖ ≤ u_max`` reaches ``x_f``.

Integrals are evaluated arc by arc between switching times (roots of
``‖λ_v‖² = (1 ± ε)²``) with Gauss–Legendre quadrature, which is spectrally
accurate because the integrand is analytic on each arc. At ε = 0 the Hessian
gains a jump term ``−u_max W q̂ q̂ᵀ Wᵀ / |ṗ|`` at each switching time.

Kernels hand other kernels flags and small integers as runtime values
(``bool(np.bool_(True))``, ``int(np.int64(1))``), never as literals: numba
compiles a callee once per literal value it is called with (a ``Literal[int](2)``
signature beside the ``int64`` one), which was about 10 % of a first compile
(issue 37 item 12). Same arithmetic, so the same numbers.

The design model (issue 33). ``n`` is CW's mean motion [rad/s] (paper Eqs.
4, 11), or an :class:`~cwrend_cli.physics.lti_kernels.LtiKernel` of another
time-invariant model as a plain tuple (Schweighart–Sedwick's J2 model,
``model.guidance = "ss"``; numba's ``isinstance`` takes no NamedTuple, and a
plain tuple crosses from Python faster, so the leaves name it again): then
``Φ``, ``W`` and the primer are that model's
(:mod:`cwrend_cli.physics.lti_kernels`) and everything above holds as
written, since it needs only ``Φ(T)Φ(−τ) = Φ(T − τ)``. Only the leaves
:func:`model_input_kernel`, :func:`model_primer`, :func:`model_stm` and
:func:`model_costate_stm` look at the type (``isinstance``, resolved when
numba compiles), so a float ``n`` compiles CW's closed forms exactly as
before, with the same signatures, and another model compiles its own
specialisation of the same kernels.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from cwrend_cli.physics import lti_kernels as lti
from cwrend_cli.physics.dynamics import costate_stm, one_minus_cos, stm, x_minus_sin
from cwrend_cli.physics.lti_kernels import KernelModel

#: ε below this is exactly bang-bang (paper Eq. 10 as ε → 0; the threshold is not in the paper).
EPS_BANG_BANG = 1e-12
#: Most switching times one evaluation can track.
MAX_BREAKS = 64
#: Floor on |dp/dt| at a switching time for the ε = 0 jump term [1/s].
MIN_SWITCH_RATE = 1e-10

STATUS_CONVERGED = 0
STATUS_INFEASIBLE = 1
STATUS_FAILED = 2


class NewtonSettings(NamedTuple):
    """Settings of :func:`newton_ascent`; the defaults are the values it was tuned with.

    Stopping: ``‖Δr(T)‖ ≤ tol_pos_km`` and ``‖Δv(T)‖ ≤ tol_vel_km_s``, or
    ``max_iter`` iterations. Each iteration tries up to ``max_damping_tries``
    Levenberg–Marquardt dampings ``μ`` (grown by ``damping_growth`` from
    ``damping_start_indefinite`` when the damped Hessian is not definite, from
    ``damping_start_search`` when the line search failed), each with up to
    ``max_halvings`` step halvings against the Armijo condition
    ``D(λ + αs) ≥ D(λ) + armijo·α·∇Dᵀs``. A full step that leaves ``D``
    unchanged to ``flat_rtol`` (relative) is accepted when it reduces the
    terminal residual. After a full step ``μ`` shrinks by ``damping_shrink``,
    to 0 below ``damping_off``; ``damping_floor`` keeps the metric term
    positive.

    ``max_halvings = 2`` (8 before issue 17): when a full step fails, two
    halvings and then a larger ``μ`` (a shorter, better-turned step) cost
    fewer dual evaluations than eight halvings along a poor direction. Over
    the ε = 0 warm re-solves of the fixed-ε paper closed loops (seeds 0–9,
    both estimators, hold sample) the mean evaluations per re-solve fell from
    74 to 38 (mean time 0.95 → 0.46 ms) with the same statuses; with hold
    mean, 0.81 → 0.38 ms and the same number of failed warm attempts.
    """

    tol_pos_km: float = 1e-9
    tol_vel_km_s: float = 1e-12
    max_iter: int = 50
    max_damping_tries: int = 40
    max_halvings: int = 2
    armijo: float = 1e-4
    flat_rtol: float = 1e-13
    damping_floor: float = 1e-13
    damping_growth: float = 10.0
    damping_start_indefinite: float = 1e-10
    damping_start_search: float = 1e-6
    damping_shrink: float = 0.1
    damping_off: float = 1e-12


#: Scratch rows shared by the kernels of one evaluation (see :func:`workspace`).
WS_LAM = 0  # λ(t) at the last time evaluated (read back after _speed_and_rate: λ_v in 3:6)
WS_LAM_T = 1  # λ at a quadrature node (step-mean control)
WS_SWITCHES = 2  # switching times of the current evaluation (MAX_BREAKS entries)
WS_PRIMER = 3  # λ_v(t) and its first three derivatives (:func:`_primer`, 12 entries)
WS_ROWS = 4

#: The scratch of one evaluation: a (WS_ROWS, MAX_BREAKS) array, one row per WS_* name.
#: One array rather than a NamedTuple of six: it is passed through the hot root-finding
#: calls, and a tuple of six arrays made the ε = 0 re-solves 20 % slower (measured).
Workspace = np.ndarray


@njit(cache=True)
def n_cells(horizon_s: float) -> int:
    """Coarse cells of the switching-time search over ``horizon_s``: ≤ 40 s each, at least 4."""
    return max(4, int(np.ceil(horizon_s / 40.0)))


@njit(cache=True)
def workspace() -> Workspace:
    """A fresh :data:`Workspace` (its rows are named by the ``WS_*`` constants)."""
    return np.empty((WS_ROWS, MAX_BREAKS))


@njit(cache=True)
def input_kernel(n: float, tau: float, w: np.ndarray) -> None:
    """Write ``W(τ) = Φ(−τ) B`` (6×3) into ``w``."""
    x = -n * tau
    c = np.cos(x)
    s = np.sin(x)
    omc = one_minus_cos(x)
    xms = x_minus_sin(x)
    t = -tau
    w[0, 0] = s / n
    w[0, 1] = 2.0 * omc / n
    w[0, 2] = 0.0
    w[1, 0] = -2.0 * omc / n
    w[1, 1] = t - 4.0 * xms / n
    w[1, 2] = 0.0
    w[2, 0] = 0.0
    w[2, 1] = 0.0
    w[2, 2] = s / n
    w[3, 0] = c
    w[3, 1] = 2.0 * s
    w[3, 2] = 0.0
    w[4, 0] = -2.0 * s
    w[4, 1] = 1.0 - 4.0 * omc
    w[4, 2] = 0.0
    w[5, 0] = 0.0
    w[5, 1] = 0.0
    w[5, 2] = c


@njit(cache=True)
def model_input_kernel(n: KernelModel, tau: float, w: np.ndarray) -> None:
    """:func:`input_kernel` of the design model ``n`` (module docstring): ``W(τ) = Φ(−τ) B``."""
    if isinstance(n, float):
        input_kernel(n, tau, w)
    else:
        lti.velocity_columns(lti.LtiKernel(*n), -tau, w)


@njit(cache=True)
def model_stm(n: KernelModel, t: float) -> np.ndarray:
    """``Φ(t)`` (6×6) of the design model ``n`` (module docstring)."""
    if isinstance(n, float):
        return stm(n, t)
    return lti.transition(lti.LtiKernel(*n), t)


@njit(cache=True)
def model_costate_stm(n: KernelModel, t: float) -> np.ndarray:
    """``e^{−Aᵀt} = Φ(−t)ᵀ`` (6×6) of the design model ``n`` (module docstring)."""
    if isinstance(n, float):
        return costate_stm(n, t)
    return lti.transition(lti.LtiKernel(*n), -t).T.copy()


@njit(cache=True)
def costate_at(n: KernelModel, tau: float, lam0: np.ndarray, out: np.ndarray) -> None:
    """Write ``λ(τ) = Φ(−τ)ᵀ λ₀`` into ``out`` (closed-form costate, from paper Eq. 7)."""
    p = model_stm(n, -tau)
    for j in range(6):
        acc = 0.0
        for i in range(6):
            acc += p[i, j] * lam0[i]
        out[j] = acc


@njit(cache=True)
def throttle(p: float, eps: float) -> float:
    """Throttle ``‖u‖/u_max`` of Eq. (10) as a function of ``p = ‖λ_v‖``."""
    s = 1.0 - p
    if eps < EPS_BANG_BANG:
        return 1.0 if s < 0.0 else 0.0
    if s > eps:
        return 0.0
    if s < -eps:
        return 1.0
    return (eps - s) / (2.0 * eps)


@njit(cache=True)
def control_from_costate(lam_v: np.ndarray, eps: float, u_max: float, out: np.ndarray) -> None:
    """Control of Eqs. (8)–(10): ``u = u_max φ_ε(‖λ_v‖) (−λ_v/‖λ_v‖)``."""
    p = np.sqrt(lam_v[0] ** 2 + lam_v[1] ** 2 + lam_v[2] ** 2)
    mag = u_max * throttle(p, eps)
    if p > 0.0 and mag > 0.0:
        for i in range(3):
            out[i] = -mag * lam_v[i] / p
    else:
        for i in range(3):
            out[i] = 0.0


@njit(cache=True)
def copy_into(src: np.ndarray, out: np.ndarray) -> None:
    """``out[:] = src`` for 1-D arrays of one length, element by element.

    An array-to-array slice assignment compiles numba's shape-mismatch error
    (string formatting) into the kernel and every kernel that calls it: a
    loop copies the same values without it (issue 37 item 12).
    """
    for i in range(out.shape[0]):
        out[i] = src[i]


@njit(cache=True)
def copy_matrix_into(src: np.ndarray, out: np.ndarray) -> None:
    """``out[:, :] = src`` for 2-D arrays of one shape, element by element (:func:`copy_into`)."""
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j] = src[i, j]


@njit(cache=True)
def sort_prefix(a: np.ndarray, count: int) -> None:
    """Sort ``a[:count]`` in place, ascending with NaN last: ``np.sort``'s order.

    Insertion sort: the prefixes sorted here hold a few dozen breakpoints, and
    ``np.sort`` (a quicksort, which also sorts runs this short by insertion)
    compiles about ten times more code. Equal values are equal bits (the
    breakpoints are times, never ``-0.0``), so the order is the same.
    """
    for i in range(1, count):
        v = a[i]
        j = i - 1
        while j >= 0 and (v < a[j] or (a[j] != a[j] and v == v)):
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = v


@njit(cache=True)
def _primer(n: float, lam0: np.ndarray, tau: float, order: int, q: np.ndarray) -> None:
    """``λ_v(τ) = W(τ)ᵀ λ₀`` and its first ``order`` time derivatives, in closed form.

    Row ``j`` of ``q`` (shape (4, 3)) receives the j-th derivative. With
    ``C = cos nτ`` and ``S = sin nτ`` each component is a combination of
    ``1, τ, C, S`` (the entries of :func:`input_kernel` transposed), so one
    sine and cosine give the primer and its derivatives, instead of a full
    state-transition matrix per time (``1 − C`` and ``3τ − 4S/n`` are formed
    without cancellation, as in :func:`input_kernel`).
    """
    c = np.cos(n * tau)
    s = np.sin(n * tau)
    omc = one_minus_cos(n * tau)
    l0, l1, l2, l3, l4, l5 = lam0[0], lam0[1], lam0[2], lam0[3], lam0[4], lam0[5]
    q[0, 0] = -s / n * l0 - 2.0 * omc / n * l1 + c * l3 + 2.0 * s * l4
    q[0, 1] = (
        2.0 * omc / n * l0
        + (4.0 * x_minus_sin(n * tau) / n - tau) * l1
        - 2.0 * s * l3
        + (1.0 - 4.0 * omc) * l4
    )
    q[0, 2] = -s / n * l2 + c * l5
    if order < 1:
        return
    q[1, 0] = -c * l0 - 2.0 * s * l1 - n * s * l3 + 2.0 * n * c * l4
    q[1, 1] = 2.0 * s * l0 + (4.0 * omc - 1.0) * l1 - 2.0 * n * c * l3 - 4.0 * n * s * l4
    q[1, 2] = -c * l2 - n * s * l5
    if order < 2:
        return
    n2 = n * n
    q[2, 0] = n * s * l0 - 2.0 * n * c * l1 - n2 * c * l3 - 2.0 * n2 * s * l4
    q[2, 1] = 2.0 * n * c * l0 + 4.0 * n * s * l1 + 2.0 * n2 * s * l3 - 4.0 * n2 * c * l4
    q[2, 2] = n * s * l2 - n2 * c * l5
    if order < 3:
        return
    n3 = n2 * n
    q[3, 0] = n2 * c * l0 + 2.0 * n2 * s * l1 + n3 * s * l3 - 2.0 * n3 * c * l4
    q[3, 1] = -2.0 * n2 * s * l0 + 4.0 * n2 * c * l1 + 2.0 * n3 * c * l3 + 4.0 * n3 * s * l4
    q[3, 2] = n2 * c * l2 + n3 * s * l5


@njit(cache=True)
def model_primer(
    n: KernelModel, lam0: np.ndarray, tau: float, order: int, q: np.ndarray, ws: Workspace
) -> None:
    """:func:`_primer` of the design model ``n`` (module docstring).

    Another model's primer (:func:`cwrend_cli.physics.lti_kernels.primer`) builds
    ``W(τ)`` in ``ws[WS_PRIMER, 12:30]``.
    """
    if isinstance(n, float):
        _primer(n, lam0, tau, order, q)
    else:
        lti.primer(lti.LtiKernel(*n), lam0, tau, order, q, ws[WS_PRIMER, 12:30].reshape((6, 3)))


@njit(cache=True)
def _speed_and_rate(
    n: KernelModel, t: float, lam0: np.ndarray, ws: Workspace
) -> tuple[float, float, float]:
    """``(‖λ_v(t)‖, λ_v·λ̇_v / ‖λ_v‖, ‖λ̇_v‖)``; ``ws[WS_LAM, 3:6]`` holds λ_v(t) afterwards.

    Where ``λ_v(t) = 0`` (a primer that passes through zero: a rest-to-rest transfer along
    one axis is antisymmetric about its midpoint) ``‖λ_v‖`` has a kink at its minimum
    and the middle value is 0: its one-sided slopes are ``∓‖λ̇_v‖``.
    """
    q = ws[WS_PRIMER, :12].reshape((4, 3))
    model_primer(n, lam0, t, int(np.int64(1)), q, ws)  # runtime ints (module docstring)
    lam = ws[WS_LAM]
    lam[3] = q[0, 0]
    lam[4] = q[0, 1]
    lam[5] = q[0, 2]
    p = np.sqrt(q[0, 0] ** 2 + q[0, 1] ** 2 + q[0, 2] ** 2)
    pdot = (q[0, 0] * q[1, 0] + q[0, 1] * q[1, 1] + q[0, 2] * q[1, 2]) / p if p > 0.0 else 0.0
    r = np.sqrt(q[1, 0] ** 2 + q[1, 1] ** 2 + q[1, 2] ** 2)
    return p, pdot, r


@njit(cache=True)
def _switch_derivs(
    n: KernelModel, lam0: np.ndarray, t: float, ws: Workspace
) -> tuple[float, float, float, float]:
    """``f = ‖λ_v(t)‖²`` and its first three time derivatives."""
    q = ws[WS_PRIMER, :12].reshape((4, 3))
    model_primer(n, lam0, t, int(np.int64(3)), q, ws)
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    f3 = 0.0
    for i in range(3):
        f0 += q[0, i] * q[0, i]
        f1 += 2.0 * q[0, i] * q[1, i]
        f2 += 2.0 * (q[1, i] * q[1, i] + q[0, i] * q[2, i])
        f3 += 2.0 * (3.0 * q[1, i] * q[2, i] + q[0, i] * q[3, i])
    return f0, f1, f2, f3


@njit(cache=True)
def _g(
    n: KernelModel, lam0: np.ndarray, t: float, order: int, level: float, ws: Workspace
) -> tuple[float, float]:
    """Value and derivative of ``f⁽ᵒʳᵈᵉʳ⁾(t) − level`` (level only for order 0)."""
    f0, f1, f2, f3 = _switch_derivs(n, lam0, t, ws)
    if order == 0:
        return f0 - level, f1
    if order == 1:
        return f1, f2
    return f2, f3


@njit(cache=True)
def _bracketed_root(
    n: KernelModel,
    lam0: np.ndarray,
    a: float,
    b: float,
    ga: float,
    gb: float,
    order: int,
    level: float,
    ws: Workspace,
) -> float:
    """Root of ``f⁽ᵒʳᵈᵉʳ⁾ − level`` in ``[a, b]`` with ``ga·gb ≤ 0``.

    Newton safeguarded by bisection.
    """
    if ga == 0.0:
        return a
    if gb == 0.0:
        return b
    tol = 1e-15 * max(1.0, abs(a), abs(b))
    x = a - ga * (b - a) / (gb - ga)
    if not (a < x < b):
        x = 0.5 * (a + b)
    prev_width = b - a
    for _ in range(100):
        gx, dx = _g(n, lam0, x, order, level, ws)
        if gx == 0.0:
            return x
        if (gx < 0.0) == (ga < 0.0):
            a = x
            ga = gx
        else:
            b = x
            gb = gx
        width = b - a
        if width <= tol:
            break
        xn = x - gx / dx if dx != 0.0 else 0.5 * (a + b)
        if not (a < xn < b) or width > 0.5 * prev_width:
            # Newton left the bracket or the bracket is not shrinking fast: bisect.
            xn = 0.5 * (a + b)
        if abs(xn - x) <= tol:
            return xn
        prev_width = width
        x = xn
    return 0.5 * (a + b)


@njit(cache=True)
def find_switches(
    n: KernelModel,
    lam0: np.ndarray,
    t0: float,
    t1: float,
    eps: float,
    n_cells: int,
    breaks: np.ndarray,
    minima: np.ndarray,
    ws: Workspace,
) -> tuple[int, int]:
    """Switching times in ``(t0, t1)``, sorted, written into ``breaks``.

    Returns ``(count, n_minima)``; the interior local minima of ``‖λ_v‖`` met
    on the way are written into ``minima`` (used to refine the quadrature).

    Switching times are the roots of ``f(t) = ‖λ_v(t)‖²`` at the levels
    ``(1 ± ε)²`` (just 1 at ε = 0). ``[t0, t1]`` is cut into ``n_cells`` cells;
    each cell is split at inflection points (roots of ``f''``) and then at
    extrema (roots of ``f'``), so that ``f`` is monotone on every piece and a
    touching pair of crossings cannot hide between two samples. Each crossing
    is then polished by safeguarded Newton.
    """
    if eps < EPS_BANG_BANG:
        n_levels = 1
        lv0 = 1.0
        lv1 = 1.0
    elif eps < 1.0:
        n_levels = 2
        lv0 = (1.0 - eps) ** 2
        lv1 = (1.0 + eps) ** 2
    else:
        n_levels = 1
        lv0 = (1.0 + eps) ** 2
        lv1 = lv0
    # the derivative orders of f solved for, as runtime ints (module docstring)
    crossing, extremum, inflection = int(np.int64(0)), int(np.int64(1)), int(np.int64(2))
    count = 0
    n_min = 0
    pieces = np.empty(4)
    is_min = np.zeros(4, dtype=np.bool_)
    h = (t1 - t0) / n_cells
    a = t0
    fa0, fa1, fa2, _ = _switch_derivs(n, lam0, a, ws)
    for cell in range(n_cells):
        b = t1 if cell == n_cells - 1 else t0 + (cell + 1) * h
        fb0, fb1, fb2, _ = _switch_derivs(n, lam0, b, ws)
        # Split points: an inflection (f'' = 0) where f' may change sign twice,
        # then the extrema (f' = 0) on each side of it.
        pieces[0] = a
        n_pieces = 1
        is_min[:] = False
        inflect = -1.0
        if (fa2 < 0.0) != (fb2 < 0.0):
            inflect = _bracketed_root(n, lam0, a, b, fa2, fb2, inflection, 0.0, ws)
        if inflect > a and inflect < b:
            _, fi1, _, _ = _switch_derivs(n, lam0, inflect, ws)
            if (fa1 < 0.0) != (fi1 < 0.0):
                pieces[n_pieces] = _bracketed_root(n, lam0, a, inflect, fa1, fi1, extremum, 0.0, ws)
                is_min[n_pieces] = fa1 < 0.0
                n_pieces += 1
            pieces[n_pieces] = inflect
            n_pieces += 1
            if (fi1 < 0.0) != (fb1 < 0.0):
                pieces[n_pieces] = _bracketed_root(n, lam0, inflect, b, fi1, fb1, extremum, 0.0, ws)
                is_min[n_pieces] = fi1 < 0.0
                n_pieces += 1
        elif (fa1 < 0.0) != (fb1 < 0.0):
            pieces[n_pieces] = _bracketed_root(n, lam0, a, b, fa1, fb1, extremum, 0.0, ws)
            is_min[n_pieces] = fa1 < 0.0
            n_pieces += 1
        for k in range(1, n_pieces):
            if is_min[k] and n_min < minima.shape[0]:
                minima[n_min] = pieces[k]
                n_min += 1
        # Monotone pieces: each level is crossed at most once on each.
        u = a
        fu0 = fa0
        for k in range(1, n_pieces + 1):
            if k < n_pieces:
                v = pieces[k]
                fv0, _, _, _ = _switch_derivs(n, lam0, v, ws)
            else:
                v = b
                fv0 = fb0
            if v > u:
                increasing = fv0 > fu0
                for j in range(n_levels):
                    # visit the lower level first when f increases
                    lv = lv0 if (j == 0) == increasing else lv1
                    ga = fu0 - lv
                    gb = fv0 - lv
                    if (ga < 0.0) != (gb < 0.0) and count < breaks.shape[0]:
                        breaks[count] = _bracketed_root(n, lam0, u, v, ga, gb, crossing, lv, ws)
                        count += 1
            u = v
            fu0 = fv0
        a = b
        fa0 = fb0
        fa1 = fb1
        fa2 = fb2
    return count, n_min


#: Ratio of successive breakpoints of the graded quadrature, ``t_m ± w·GRADING_RATIO^k``:
#: every arc then lies at least ~1.7 of its half-lengths from the singularities
#: at ``t_m ± i w``, so Gauss–Legendre converges like ρ^(−2N) with ρ ≥ 3.4
#: (12 nodes: relative error ≲ 2e-13).
GRADING_RATIO = 4.0
#: Most quadrature breakpoints of one evaluation (switches plus refinement).
MAX_QUAD_BREAKS = 4 * MAX_BREAKS


@njit(cache=True)
def quadrature_breaks(
    n: KernelModel,
    lam0: np.ndarray,
    t0: float,
    t1: float,
    eps: float,
    n_cells: int,
    switches: np.ndarray,
    breaks: np.ndarray,
    ws: Workspace,
) -> tuple[int, int]:
    """Switching times, and the breakpoints of the arc-by-arc quadrature.

    Returns ``(n_switches, n_breaks)``. The integrand of the control integral
    contains ``‖λ_v‖`` and ``λ_v/‖λ_v‖``, whose complex singularities (zeros of
    ``‖λ_v‖²``) lie near each minimum ``t_m`` of ``‖λ_v‖`` on the interval
    (interior, or at an end), at distance ``w = ‖λ_v‖/‖λ̇_v‖`` from the real
    axis. Gauss–Legendre on an arc is only as accurate as the arc is short
    compared with its distance to them, so the breakpoints are the switching
    times plus, for every minimum with ``w`` shorter than the interval,
    ``t_m`` and ``t_m ± w·GRADING_RATIOᵏ``: a long arc is kept only where the
    singularity is far (a shallow minimum gives a few arcs, a near-zero
    ``‖λ_v‖`` a geometric refinement down to ``w``).
    """
    minima = np.empty(MAX_BREAKS // 4 + 2)
    n_sw, n_min = find_switches(n, lam0, t0, t1, eps, n_cells, switches, minima, ws)
    for i in range(n_sw):
        breaks[i] = switches[i]
    nb = n_sw  # an int64, not Literal[int](0): sort_prefix is compiled once (module docstring)
    # the ends are minima of ‖λ_v‖ on the interval when it grows away from them
    _, f1, _, _ = _switch_derivs(n, lam0, t0, ws)
    if f1 > 0.0:
        minima[n_min] = t0
        n_min += 1
    _, f1, _, _ = _switch_derivs(n, lam0, t1, ws)
    if f1 < 0.0:
        minima[n_min] = t1
        n_min += 1
    span = t1 - t0
    for i in range(n_min):
        tm = minima[i]
        p, _, r = _speed_and_rate(n, tm, lam0, ws)
        if r <= 0.0 or p >= span * r:
            continue  # singularities farther than the interval is long: one arc is accurate
        w = max(p / r, 1e-9)
        if t0 < tm < t1 and nb < breaks.shape[0]:
            breaks[nb] = tm
            nb += 1
        d = w
        while d < span:
            for t in (tm - d, tm + d):
                if t0 < t < t1 and nb < breaks.shape[0]:
                    breaks[nb] = t
                    nb += 1
            d *= GRADING_RATIO
    sort_prefix(breaks, nb)
    return n_sw, nb


@njit(cache=True)
def arc_bounds(
    arc: int, n_breaks: int, breaks: np.ndarray, t0: float, t1: float
) -> tuple[float, float]:
    """``(a, b)`` of quadrature arc ``arc`` of ``[t0, t1]`` split at ``breaks[:n_breaks]``."""
    a = t0 if arc == 0 else breaks[arc - 1]
    b = t1 if arc == n_breaks else breaks[arc]
    return a, b


@njit(cache=True)
def _regime_terms(p: float, eps: float) -> tuple[float, float, float]:
    """``(φ, φ', Ψ)`` of the throttle at ``p`` (Eq. 10 and its integral)."""
    if eps < EPS_BANG_BANG:
        if p > 1.0:
            return 1.0, 0.0, p - 1.0
        return 0.0, 0.0, 0.0
    lo = 1.0 - eps
    hi = 1.0 + eps
    if p <= lo:
        return 0.0, 0.0, 0.0
    if p >= hi:
        return 1.0, 0.0, p - 1.0
    r = p - lo
    return r / (2.0 * eps), 1.0 / (2.0 * eps), r * r / (4.0 * eps)


@njit(cache=True)
def node_primer(lam0: np.ndarray, w: np.ndarray) -> tuple[float, float, float, float]:
    """``λ_v = W(τ)ᵀ λ₀`` (three components) and ``p = ‖λ_v‖`` from ``w = W(τ)``."""
    q0 = w[0, 0] * lam0[0] + w[1, 0] * lam0[1] + w[3, 0] * lam0[3] + w[4, 0] * lam0[4]
    q1 = w[0, 1] * lam0[0] + w[1, 1] * lam0[1] + w[3, 1] * lam0[3] + w[4, 1] * lam0[4]
    q2 = w[2, 2] * lam0[2] + w[5, 2] * lam0[5]
    return q0, q1, q2, np.sqrt(q0 * q0 + q1 * q1 + q2 * q2)


@njit(cache=True)
def add_control_node(
    w: np.ndarray,
    q0: float,
    q1: float,
    q2: float,
    p: float,
    wk: float,
    phi: float,
    dphi: float,
    u_max: float,
    want_hess: bool,
    grad: np.ndarray,
    hess: np.ndarray,
    wq: np.ndarray,
) -> None:
    """Add one quadrature node (weight ``wk``) of ``∫ W u dτ`` and of its ``λ₀``-derivative.

    ``u = −u_max φ q̂`` with throttle ``φ`` and its slope ``φ'`` at ``p``;
    the derivative ``∂u/∂λ₀ = −u_max [φ' q̂q̂ᵀ + (φ/p)(I − q̂q̂ᵀ)] Wᵀ`` goes
    into the upper triangle of ``hess``. Shared by the dual evaluation and
    the switching-time Newton (:mod:`._switching_kernels`).
    """
    qh0 = q0 / p
    qh1 = q1 / p
    qh2 = q2 / p
    c = -u_max * phi
    for i in range(6):
        wq[i] = w[i, 0] * qh0 + w[i, 1] * qh1 + w[i, 2] * qh2
        grad[i] += wk * c * wq[i]
    if want_hess:
        a_iso = -u_max * wk * phi / p
        a_rad = -u_max * wk * (dphi - phi / p)
        for i in range(6):
            for j in range(i, 6):
                ww = w[i, 0] * w[j, 0] + w[i, 1] * w[j, 1] + w[i, 2] * w[j, 2]
                val = a_iso * ww + a_rad * wq[i] * wq[j]
                hess[i, j] += val


@njit(cache=True)
def terminal_offset(n: KernelModel, x0: np.ndarray, xf: np.ndarray, horizon: float) -> np.ndarray:
    """``d = Φ(−T) x_f − x₀``: the target in the initial frame (module docstring)."""
    pf = model_stm(n, -horizon)
    d = np.empty(6)
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += pf[i, j] * xf[j]
        d[i] = acc - x0[i]
    return d


@njit(cache=True)
def dual_evaluate(
    n: KernelModel,
    lam0: np.ndarray,
    d: np.ndarray,
    horizon: float,
    eps: float,
    u_max: float,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    n_cells: int,
    want_hess: bool,
    grad: np.ndarray,
    hess: np.ndarray,
    ws: Workspace,
) -> tuple[float, float, int]:
    """Dual value ``D``, gradient ``G = ∫W u dτ − d`` and Hessian ``∂G/∂λ₀`` at ``λ₀``.

    Also returns the infeasibility certificate value
    ``c = −λ₀ᵀd − u_max ∫‖W(τ)ᵀλ₀‖ dτ`` (positive ⇒ no bounded control reaches
    ``x_f``) and the number of switching times found.
    """
    switches = ws[WS_SWITCHES]
    breaks = np.empty(MAX_QUAD_BREAKS)
    n_switches, n_breaks = quadrature_breaks(
        n, lam0, 0.0, horizon, eps, n_cells, switches, breaks, ws
    )
    w = np.empty((6, 3))
    wq = np.empty(6)
    for i in range(6):
        grad[i] = 0.0
        if want_hess:
            for j in range(6):
                hess[i, j] = 0.0
    int_psi = 0.0
    int_p = 0.0
    n_nodes = gl_x.shape[0]
    for arc in range(n_breaks + 1):
        a, b = arc_bounds(arc, n_breaks, breaks, 0.0, horizon)
        if b <= a:
            continue
        half = 0.5 * (b - a)
        mid = 0.5 * (a + b)
        for k in range(n_nodes):
            tau = mid + half * gl_x[k]
            wk = half * gl_w[k]
            model_input_kernel(n, tau, w)
            q0, q1, q2, p = node_primer(lam0, w)
            int_p += wk * p
            phi, dphi, psi = _regime_terms(p, eps)
            if phi == 0.0 and dphi == 0.0:
                continue
            int_psi += wk * psi
            add_control_node(w, q0, q1, q2, p, wk, phi, dphi, u_max, want_hess, grad, hess, wq)
    if want_hess and eps < EPS_BANG_BANG:
        # Jump terms at ε = 0: −u_max W q̂q̂ᵀWᵀ/|ṗ| at each switching time.
        lam = ws[WS_LAM]  # λ(t_s), written by _speed_and_rate below
        for s in range(n_switches):
            ts = switches[s]
            p, pdot, _ = _speed_and_rate(n, ts, lam0, ws)
            rate = max(abs(pdot), MIN_SWITCH_RATE)
            model_input_kernel(n, ts, w)
            for i in range(6):
                wq[i] = (w[i, 0] * lam[3] + w[i, 1] * lam[4] + w[i, 2] * lam[5]) / p
            for i in range(6):
                for j in range(i, 6):
                    hess[i, j] -= u_max * wq[i] * wq[j] / rate
    if want_hess:
        for i in range(6):
            for j in range(i):
                hess[i, j] = hess[j, i]
    lam_d = 0.0
    for i in range(6):
        lam_d += lam0[i] * d[i]
        grad[i] -= d[i]
    value = -lam_d - u_max * int_psi
    cert = -lam_d - u_max * int_p
    return value, cert, n_switches


@njit(cache=True)
def _cholesky_solve(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> bool:
    """Solve ``a x = b`` for symmetric positive definite 6×6 ``a``; False if not PD."""
    m = a.shape[0]
    ell = np.zeros((m, m))
    for j in range(m):
        s = a[j, j]
        for k in range(j):
            s -= ell[j, k] * ell[j, k]
        if not (s > 0.0) or not np.isfinite(s):
            return False
        ell[j, j] = np.sqrt(s)
        for i in range(j + 1, m):
            s = a[i, j]
            for k in range(j):
                s -= ell[i, k] * ell[j, k]
            ell[i, j] = s / ell[j, j]
    y = np.empty(m)
    for i in range(m):
        s = b[i]
        for k in range(i):
            s -= ell[i, k] * y[k]
        y[i] = s / ell[i, i]
    for i in range(m - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, m):
            s -= ell[k, i] * out[k]
        out[i] = s / ell[i, i]
    return True


@njit(cache=True)
def damped_direction(
    hess: np.ndarray,
    metric: np.ndarray,
    damping: float,
    grad: np.ndarray,
    mat: np.ndarray,
    step: np.ndarray,
) -> bool:
    """The Levenberg–Marquardt step: solve ``(−H + damping·diag(metric)) s = G`` into ``step``.

    False if the damped matrix is not positive definite (then damp more).
    Shared by every dual ascent (this module's and :mod:`._grid_kernels`).
    """
    for i in range(6):
        for j in range(6):
            mat[i, j] = -hess[i, j]
        mat[i, i] += damping * metric[i]
    return _cholesky_solve(mat, grad, step)


@njit(cache=True)
def step_accepted(
    value_t: float,
    value: float,
    alpha: float,
    slope: float,
    merit_t: float,
    merit: float,
    settings_t: tuple[Any, ...],
) -> bool:
    """Whether a dual ascent accepts the trial point (:class:`NewtonSettings`).

    Armijo on the dual, ``D(λ + αs) ≥ D(λ) + armijo·α·∇Dᵀs``; or, for a full
    step that leaves ``D`` flat to rounding (``flat_rtol``, near the
    optimum), a reduction of the terminal-miss merit ``merit_t < merit``.
    """
    settings = NewtonSettings(*settings_t)
    if value_t >= value + settings.armijo * alpha * slope:
        return True
    if alpha == 1.0 and value_t >= value - settings.flat_rtol * (abs(value) + 1e-300):
        return merit_t < merit
    return False


@njit(cache=True)
def terminal_residual(
    n: KernelModel, horizon: float, grad: np.ndarray, out: np.ndarray
) -> tuple[float, float]:
    """``x(T) − x_f = Φ(T) G``; returns (‖Δr‖ [km], ‖Δv‖ [km/s])."""
    p = model_stm(n, horizon)
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += p[i, j] * grad[j]
        out[i] = acc
    rp = np.sqrt(out[0] ** 2 + out[1] ** 2 + out[2] ** 2)
    rv = np.sqrt(out[3] ** 2 + out[4] ** 2 + out[5] ** 2)
    return rp, rv


@njit(cache=True)
def best_start(
    n: KernelModel,
    starts: np.ndarray,
    d: np.ndarray,
    horizon: float,
    eps: float,
    u_max: float,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    n_cells: int,
    want_hess: bool,
    grad: np.ndarray,
    hess: np.ndarray,
    ws: Workspace,
) -> tuple[int, float, float]:
    """The row of ``starts`` with the highest dual value (the first on ties).

    Returns ``(row, D, certificate value)``; ``grad`` (and ``hess`` if
    ``want_hess``) hold that row's evaluation. ``D`` is concave and maximised
    by the solution, so this is the better start by the ascent's own measure.
    """
    grad_t = np.empty(6)
    hess_t = np.empty((6, 6))
    value, cert, _ = dual_evaluate(
        n, starts[0], d, horizon, eps, u_max, gl_x, gl_w, n_cells, want_hess, grad, hess, ws
    )
    best = 0
    for r in range(1, starts.shape[0]):
        value_t, cert_t, _ = dual_evaluate(
            n, starts[r], d, horizon, eps, u_max, gl_x, gl_w, n_cells, want_hess, grad_t,
            hess_t, ws,
        )  # fmt: skip
        if value_t > value:
            best = r
            copy_into(grad_t, grad)
            if want_hess:
                for i in range(6):
                    copy_into(hess_t[i], hess[i])
            value = value_t
            cert = cert_t
    return best, value, cert


@njit(cache=True)
def newton_ascent(
    n: KernelModel,
    x0: np.ndarray,
    xf: np.ndarray,
    horizon: float,
    eps: float,
    u_max: float,
    starts: np.ndarray,
    gl_x: np.ndarray,
    gl_w: np.ndarray,
    n_cells: int,
    settings_t: tuple[Any, ...],
    lam_out: np.ndarray,
) -> tuple[int, int, float, float]:
    """Solve one shooting problem by damped Newton / Levenberg–Marquardt ascent on ``D``.

    ``starts`` (k×6) are warm starts: the ascent begins at the row with the
    highest dual value ``D`` (concave, maximised by the solution, so the
    better start by the ascent's own measure; the first row on ties), whose
    evaluation it reuses. Returns ``(status, iterations, ‖Δr(T)‖, ‖Δv(T)‖)``;
    the costate is written to ``lam_out``. Status: 0 converged, 1 infeasible (certificate
    found), 2 failed (iteration limit or stalled line search). ``settings_t``
    holds the fields of a :class:`NewtonSettings` as a plain tuple (numba
    resolves a NamedTuple argument several times slower; named again here).
    """
    settings = NewtonSettings(*settings_t)
    tol_pos = settings.tol_pos_km
    tol_vel = settings.tol_vel_km_s
    d = terminal_offset(n, x0, xf, horizon)
    ws = workspace()
    grad = np.empty(6)
    hess = np.empty((6, 6))
    grad_t = np.empty(6)
    hess_t = np.empty((6, 6))
    lam_t = np.empty(6)
    step = np.empty(6)
    res = np.empty(6)
    mat = np.empty((6, 6))
    # Levenberg–Marquardt metric: the Hessian scale u_max ∫ W Wᵀ dτ on the diagonal.
    metric = np.empty(6)
    for i in range(3):
        metric[i] = u_max * horizon**3 / 3.0
        metric[i + 3] = u_max * horizon
    with_hess = bool(np.bool_(True))  # a runtime flag (module docstring)
    best, value, cert = best_start(
        n, starts, d, horizon, eps, u_max, gl_x, gl_w, n_cells, with_hess, grad, hess, ws
    )
    lam = starts[best].copy()
    mu = 0.0
    rp, rv = terminal_residual(n, horizon, grad, res)
    for it in range(settings.max_iter + 1):
        if rp <= tol_pos and rv <= tol_vel:
            copy_into(lam, lam_out)
            return STATUS_CONVERGED, it, rp, rv
        if cert > 0.0:
            copy_into(lam, lam_out)
            return STATUS_INFEASIBLE, it, rp, rv
        if it == settings.max_iter:
            break
        merit = (rp / tol_pos) ** 2 + (rv / tol_vel) ** 2
        accepted = False
        for _attempt in range(settings.max_damping_tries):
            if not damped_direction(hess, metric, max(mu, settings.damping_floor), grad, mat, step):
                mu = max(settings.damping_growth * mu, settings.damping_start_indefinite)
                continue
            slope = 0.0
            for i in range(6):
                slope += grad[i] * step[i]
            alpha = 1.0
            for _ls in range(settings.max_halvings):
                for i in range(6):
                    lam_t[i] = lam[i] + alpha * step[i]
                value_t, cert_t, _ = dual_evaluate(
                    n,
                    lam_t,
                    d,
                    horizon,
                    eps,
                    u_max,
                    gl_x,
                    gl_w,
                    n_cells,
                    with_hess,
                    grad_t,
                    hess_t,
                    ws,
                )
                rp_t, rv_t = terminal_residual(n, horizon, grad_t, res)
                merit_t = (rp_t / tol_pos) ** 2 + (rv_t / tol_vel) ** 2
                accepted = step_accepted(value_t, value, alpha, slope, merit_t, merit, settings_t)
                if accepted:
                    break
                alpha *= 0.5
            if accepted:
                break
            mu = max(settings.damping_growth * mu, settings.damping_start_search)
        if not accepted:
            break
        for i in range(6):
            lam[i] = lam_t[i]
            grad[i] = grad_t[i]
            for j in range(6):
                hess[i, j] = hess_t[i, j]
        value = value_t
        cert = cert_t
        rp = rp_t
        rv = rv_t
        if alpha == 1.0:
            mu = mu * settings.damping_shrink if mu > settings.damping_off else 0.0
    copy_into(lam, lam_out)
    return STATUS_FAILED, it, rp, rv
