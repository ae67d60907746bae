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
the cone. **A corridor clear of the zone is not tightened** (a fixed target): when
the cone keeps farther from every keep-out ellipsoid than the largest chord margin
(:func:`~cwrend_cli.physics.constraints.corridor_clearance_km`, a lower bound), a
point of an arc lies within that margin of its chord, the chord in the cone, so the
point is outside the zone: safe whether in the corridor or not (the unsafe set is the
zone less the corridor). Its nodes are still held in the cone. Tightened, the cone's
apex would move back from the port by the margin over sin θ (0.3 m in
campaigns/safe_approach.toml) while the node before the port lies within ½u_maxΔt²
(0.4 m) of it: a sliver that the last step reaches only at full thrust, where the dual
solver stalls (docs/solvers.md, *where the mean goes*). A corridor that may enter the
zone (a port on its surface, the circumscribed spheres of a long ellipsoid) keeps the
margin, and so does a turning body's.

**Iterations.** Trust region ``‖r_k − r̄_k‖_∞ ≤ T_k``: T = :data:`TRUST_RADIUS_FACTOR`
× the largest semi-axis near the zone; at a node far from it (a fixed target, abort
safety off) the larger of T and :data:`TRUST_FAR_FRACTION` of the largest box about r̄_k
that the node's half-spaces hold (:func:`trust_radii`). The box is there to keep an iterate where
the zone was linearised; such a node's box meets its half-spaces nowhere (their rows are
left out, *Reductions* (i)), and one radius for all would only hold the far nodes back
from where a new estimate or a new ε takes the plan (trust rows binding at tens of nodes
4–26 km from the zone, docs/solvers.md). Stop when no node moves by more than
:data:`SCP_TOL_KM` between iterates or the cost falls by less than
:data:`SCP_COST_RTOL` of itself, with no slack and the modes unchanged, at most
:data:`SCP_MAX_ITER` iterations; at the cap the last iterate is returned (safe,
see above) with its status converged if its terminal and path rows hold. The
cost before the first iterate counts as infinite, so its fall is infinite too
and meets the test: **the first program is the last** whenever it needs no
slack, leaves every node's mode as it found it and its own chord bound holds
(a warm re-solve, from the previous plan shifted to the current step, nearly
always: one iteration in 776 of the 780 re-solves of seeds 0–4 of
campaigns/safe_approach.toml, MTF architectures). A turning body's SCP
(``motion``, issue 34) also stops with a slack, once the slack is settled (within
:data:`SCP_TOL_KM` of the previous iterate's): next to a moving port the
tightened corridor rows of the last nodes cannot all hold, the slack is the same
at every iterate, and more iterations only repeat the program
(docs/guide/tumbling-target.md, *The cost of a turning set*). A fixed target keeps
the rule above (its plans are pinned bit for bit).

**A moved target.** The first program is linearised at the warm start (the plan the
re-solve replaces, from the new estimate) and keeps every node within the trust box of
it. Its only rows without a slack are the dynamics, ``‖ũ_j‖ ≤ 1``, the terminal
equality and the trust box (the path rows share the slack s below, the abort rows have
their own), so it has an answer exactly when some bounded control reaches x_f with every
node within the box. When x_f moved (a tumbling port predicted afresh, issue 34) the last
nodes cannot follow and the program is infeasible though the problem is not (the
*artificial infeasibility* of successive convexification, which Mao, Szmuk & Açıkmeşe
2016, arXiv:1608.05133, meet with virtual controls). The SCP then restarts from the
unconstrained plan (:func:`.convex.plan_controls`, the cold start's first iterate), which
meets those rows by construction (bounded controls that reach x_f, at the centre of its
own box), so its first program has an answer and every later one too (each is linearised
at the previous answer). The restart is taken a priori
when the warm plan's end is farther than one trust radius from x_f in some axis
(:func:`out_of_reach`), and a posteriori when the first program has no answer while the
unconstrained program has a plan (the box blocked it). The blocked program counts in
``scp_iterations`` but not against :data:`SCP_MAX_ITER`; ``ConstrainedPlan.restarted``
says so. Where the warm start reaches x_f within its box (a fixed target, a port that
moved less) nothing changes.

**Reductions.** Each iteration's program is solved smaller, with the same
answer (to Clarabel's tolerance): (i) a half-space row whose node's trust box
cannot reach its plane is left out (:func:`_pairs`: implied by the trust rows,
exactly); (ii) the states before the first node that carries a path row are
substituted by the dynamics, their trust rows left out (:func:`_first_node`);
(iii) the steps that the previous iterate leaves coasting (but for their
neighbours) are held at zero (:func:`_thrust_guess`). (ii) and (iii) relax the
program, so the answer is checked: every left-out trust row within
:data:`SLACK_TOL_KM` and every left-out half-space row held exactly
(:func:`_broken_rows`), every held step passing the screen of the unconstrained
program, ``‖A_jᵀ z‖ ≤ 1 − ε`` (:func:`_coasting_broken`: its KKT conditions with
the step free); whatever fails is put back and the program solved again, the
whole program after :data:`REDUCED_ROUNDS` reduced ones (seed 0 of
campaigns/safe_approach.toml: a second program in 3 of 78 warm re-solves at
ε = 0, in 15 of 78 adaptive ones, whose far nodes move by up to 10 trust radii
from the shifted plan: there the trust rows are active). A relaxation's answer
that is feasible for the whole program is its answer (the relaxation's cost is
no higher, and the whole program's optimum is unique in the controls, which
fix the states), so every iterate keeps the safety argued above. In
campaigns/safe_approach.toml a re-solve's program has path rows on about the
last 60 nodes of up to 800, and at ε = 0 about 65 steps that thrust.

**Solvers.** Each SCP program is first given to the projected dual Newton
solver of :mod:`.path_dual` (numba) — below the quadratic weight
:data:`.convex.DUAL_MIN_WEIGHT` (the fixed-ε re-solves, weight ρ) by its homotopy
in the weight, over the steps the iterate thrusts on (:func:`_thrust_guess`; the
held steps are certified by their Lagrangian, :func:`.path_dual.solve`) —
whole: the terminal rows, every kept half-space row, the trust rows of every
constrained node and the abort rows; a corridor cone the answer breaks adds its
supporting plane at that point (a cut the cone implies) and the program is
solved again (:data:`CONE_ROUNDS`). Its answer is the Lagrangian's minimiser,
accepted only when it is certified optimal for the whole program
(:func:`_dual_solve`): every row within :data:`DUAL_TOL_KM`
(:data:`DUAL_TOL_KM_S` on the terminal velocity), every row with a positive
multiplier within it of equality, every corridor cone held, and the path and
abort multipliers summing below their slack's price (so the exact penalty keeps
its slack at 0). Otherwise Clarabel solves the program as below (counted in
``ConstrainedPlan.fallbacks``); ``plan(solver="clarabel")`` uses Clarabel only.
The two agree to the solvers' tolerances (``tests/test_path_dual.py``). The
dual solver starts from the row multipliers of the previous SCP iteration, or
of the plan the re-solve replaces (``warm_duals``, :func:`shift_duals`), else
from the half-space rows the previous iterate touches (:func:`_guess_active`); when
these fail on a program with cuts of the corridor cone (at adaptive ε), from the
multipliers of the program at ε = 1 (:func:`.path_dual.solve_from_smooth`).

**Abort safety** (``constraints.abort_safe_s`` = T, issue 34 item 4): the
free drift from every keep-out node (the corridor nodes of the final approach,
node 0 and the terminal node exempt) stays outside the keep-out zone for T,
by linear rows on the node states (:mod:`cwrend_cli.physics.abort_safety`,
which says how many drift samples and why they suffice) with their own slack
priced :data:`ABORT_SLACK_PENALTY` per km; the chords the rows left out are
checked on each answer and the subproblem solved again with their rows (at
most :data:`ABORT_ROUNDS` solves an iteration; an answer still uncovered is
not converged). Several bodies, or a tumbling target (``abort_turn``: the
predicted turn over the drifts): one row per body and fine chord, in the body
frame at each drift sample's own time (:mod:`cwrend_cli.physics.abort_safety`,
*Several bodies, a turning target*).

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
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import clarabel
import numpy as np
import scipy.sparse as sp
from numba import njit

from cwrend_cli.physics import abort_safety as ab
from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.dynamics import discretize, stm, zoh_rollout
from cwrend_cli.physics.guidance import convex, feasibility, path_dual
from cwrend_cli.physics.guidance.results import SolveStatus

__all__ = [
    "ABORT_ROUNDS",
    "ABORT_SLACK_PENALTY",
    "ACCEL_FACTOR",
    "COAST_TOL",
    "REDUCED_ROUNDS",
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
#: A node far from its keep-out half-spaces gets a larger trust radius: this fraction of
#: the largest box about it that they hold (:func:`trust_radii`) [-].
TRUST_FAR_FRACTION = 0.5
#: Price of the path slack in the scaled cost [1/km]: the cost of a plan is of order the
#: fuel over Δt u_max (at most N), so 1e6 per km outweighs any fuel saving.
SLACK_PENALTY = 1e6
#: A slack below this is the interior point's tolerance, not a softening [km] (1 µm).
SLACK_TOL_KM = 1e-9
#: Safety factor on the acceleration bound of the chord margin [-].
ACCEL_FACTOR = 1.5
#: A step of the previous iterate with ‖u‖ ≤ this × u_max is guessed coasting [-].
COAST_TOL = 1e-6
#: Reduced programs of one SCP iteration before the whole program is solved [-].
REDUCED_ROUNDS = 4
#: Price of the abort-safety slack in the scaled cost [1/km]: a tenth of the path's, so a
#: plan gives up abort safety before it enters the unsafe set, and 1 m of it outweighs 100
#: steps at full thrust.
ABORT_SLACK_PENALTY = 1e5
#: Solves of one SCP iteration at most: the first, then one for each widening of the
#: abort rows to chords the answer left uncovered [-].
ABORT_ROUNDS = 4

_CORRIDOR, _KEEP_OUT, _BOTH = 1, 2, 3


class Duals(NamedTuple):
    """The row multipliers of a plan's last program when the dual solver answered it:
    ``codes`` (M,) int64 (node, kind and key of each row, :func:`_dual_rows`) and their
    ``values`` (M,) [scaled cost per scaled row]; the next re-solve's warm start
    (:func:`shift_duals`)."""

    codes: np.ndarray
    values: np.ndarray


@dataclass(frozen=True)
class ConstrainedPlan:
    """The answer of :func:`plan`.

    ``controls`` (N, 3) [km/s²] and ``positions`` (N+1, 3) [km] of the nodes
    (row 0 the start) are zero/NaN unless converged; ``modes`` (N+1,) per node:
    0 none, 1 corridor, 2 keep-out, 3 both; ``slack_km`` the softening used
    (0: every path constraint held); ``scp_iterations`` the convex programs
    solved, ``solver_iterations`` the iterations of all of them summed (the dual Newton
    method's, certified or not, and Clarabel's on the ``fallbacks``).
    """

    status: SolveStatus
    controls: np.ndarray
    positions: np.ndarray
    modes: np.ndarray
    slack_km: float
    scp_iterations: int
    solver_iterations: int
    wall_time_s: float
    abort_slack_km: float = 0.0  # the abort rows' softening (0: every drift covered) [km]
    fallbacks: int = 0  # programs the dual solver left to Clarabel (module docstring) [-]
    duals: Duals | None = None  # the last program's row multipliers (dual solver only)
    restarted: bool = False  # a warm start out of reach, replaced by the unconstrained plan


def node_positions(
    n: float, dt_s: float, x0: np.ndarray, controls: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """States (N+1, 6) of held ``controls`` from x0 under the exact ZOH dynamics (Eq. 11)."""
    phi, gam = path_dual.transitions(n, dt_s)
    x = zoh_rollout(
        phi,
        gam,
        np.ascontiguousarray(x0, dtype=np.float64),
        np.ascontiguousarray(controls, dtype=np.float64),
    )
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
    a, b, c, d = _untightened_corridor(geo)[1]
    _approach_modes(cg.to_body(motion, r_bar), a, b, c, d, modes)
    return modes


@njit(cache=True)
def _approach_modes(
    r: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: float, modes: np.ndarray
) -> None:
    """Writes the final approach into ``modes`` (N + 1,) (:func:`_modes`): the nodes inside the
    untightened corridor cone (its residual ≥ −:data:`SCP_TOL_KM` at the iterate's positions
    ``r`` (N + 1, 3), the cone's rows a, b, c, d: :meth:`.constraints.SecondOrderCone.residual_km`'s
    kernel, from the products ``cᵀr`` and ``A r`` summed in order here, where numpy's matmul
    may round the last bit otherwise: a node's mode could differ only at a residual of −1 mm
    to that bit) from :func:`.constraints.approach_start` (not below node 1: node 0 is x0;
    the terminal node is the apex) to N − 1 are corridor nodes, the first of them both."""
    steps = modes.size - 1
    along = np.empty(steps + 1)
    across = np.empty((steps + 1, 3))
    for k in range(steps + 1):
        r0, r1, r2 = r[k, 0], r[k, 1], r[k, 2]
        along[k] = r0 * c[0] + r1 * c[1] + r2 * c[2]
        for i in range(3):
            across[k, i] = r0 * a[i, 0] + r1 * a[i, 1] + r2 * a[i, 2]
    inside = cg._cone_residuals(along, across, b, d) >= -SCP_TOL_KM
    first = cg.approach_start(inside, 1)
    for k in range(first, steps):
        modes[k] = _CORRIDOR
    if first < steps:
        modes[first] = _BOTH


@njit(cache=True)
def _same_modes(first: np.ndarray, second: np.ndarray) -> bool:
    """``np.array_equal`` of two nodes' modes: the same length and every node's mode."""
    if first.size != second.size:
        return False
    for k in range(first.size):  # noqa: SIM110 (a loop: numba compiles no generator)
        if first[k] != second[k]:
            return False
    return True


@njit(cache=True)
def _corridor_nodes(modes: np.ndarray) -> np.ndarray:
    """The nodes in the corridor cone (modes corridor and both), in order."""
    return np.flatnonzero((modes == _CORRIDOR) | (modes == _BOTH))


@njit(cache=True)
def _half_space_nodes(modes: np.ndarray) -> np.ndarray:
    """The nodes with keep-out half-spaces, in order: node 0 (the start, never a keep-out
    node: :func:`_modes`) and the keep-out nodes (modes keep-out and both)."""
    keep_out = modes >= _KEEP_OUT
    keep_out[0] = True
    return np.flatnonzero(keep_out)


#: The last corridor's untightened cone, its rows and its clearance of the zone
#: (:func:`_untightened_corridor`), with the geometry last asked and its key (the
#: corridor's port, axis and half-angle and the zone's ellipsoids).
_CORRIDOR_KEPT: list[
    tuple[cg.Geometry, tuple[Any, ...], cg.SecondOrderCone, tuple[Any, ...], float]
] = []


def _array_key(array: np.ndarray | None) -> tuple[str, tuple[int, ...], bytes] | None:
    """What an array is, bit for bit, as a dictionary key: dtype, shape and bytes."""
    if array is None:
        return None
    return array.dtype.str, array.shape, array.tobytes()


def _untightened_corridor(
    geo: cg.Geometry,
) -> tuple[cg.SecondOrderCone, tuple[np.ndarray, np.ndarray, np.ndarray, float], float]:
    """``corridor_cone(geo, 0)``, its rows and :func:`.constraints.corridor_clearance_km`,
    kept for the corridor last asked (a closed loop's re-solves share one, each with its
    own :class:`.constraints.Geometry`, and :func:`_modes` reads it twice a re-solve): the
    same values as made afresh (the key is every bit they are made of: the port's and the
    axis' arrays, the half-angle and the zone's semi-axes and centres)."""
    kept = _CORRIDOR_KEPT[0] if _CORRIDOR_KEPT else None
    if kept is None or kept[0] is not geo:  # the geometry last asked: no key to compare
        key = (
            _array_key(geo.port_km), _array_key(geo.axis), geo.half_angle_rad,
            _array_key(geo.semi_axes_km), _array_key(geo.bodies_centre_km),
            _array_key(geo.bodies_semi_axes_km),
        )  # fmt: skip
        if kept is None or kept[1] != key:
            cone = cg.corridor_cone(geo, 0.0)
            rows = cone.rows()
            for array in rows[:3]:
                array.flags.writeable = False
            kept = (geo, key, cone, rows, cg.corridor_clearance_km(geo))
        else:  # the same corridor: kept for this geometry from now on
            kept = (geo, *kept[1:])
        _CORRIDOR_KEPT[:] = [kept]
    _, _, cone, rows, clearance_km = kept
    return cone, (rows[0], rows[1], rows[2], rows[3]), clearance_km


def _cone_margins(
    geo: cg.Geometry, margins_km: np.ndarray, motion: cg.BodyMotion | None
) -> np.ndarray:
    """The corridor cone's tightening at each node (N+1,) [km] (module docstring,
    *Margins*): the nodes' chord margins ``margins_km``, or none at all when the corridor
    clears the keep-out zone by more than the largest of them (a fixed target only)."""
    clear = (
        motion is None
        and geo.port_km is not None
        and geo.semi_axes_km is not None
        and _untightened_corridor(geo)[2] > _largest(margins_km)
    )
    return np.zeros(margins_km.shape) if clear else margins_km


@njit(cache=True)
def _largest(values: np.ndarray) -> float:
    """``np.max`` of a nonempty 1-D array: its largest value, NaN if one is."""
    out = values[0]
    for v in values:
        if v != v:
            return math.nan
        out = max(out, v)
    return float(out)


class HalfSpaces(Mapping[int, cg.HalfSpace]):
    """The half-spaces H_j of the nodes j that have one: node j → :class:`.HalfSpace`, kept
    as arrays (``normals`` (K, 3), ``offsets`` (K,) [km] of ``nodes`` (K,); ``index``
    (N + 1,): a node's row, −1 for none) so that the program reads them at once."""

    def __init__(
        self,
        nodes: np.ndarray,
        normals: np.ndarray,
        offsets: np.ndarray,
        size: int,
        index: np.ndarray | None = None,
    ):
        self.nodes, self.normals, self.offsets = nodes, normals, offsets
        self.index = _node_index(nodes, size) if index is None else index

    def __getitem__(self, j: int) -> cg.HalfSpace:
        i = int(self.index[j]) if 0 <= j < self.index.size else -1
        if i < 0:
            raise KeyError(j)
        return cg.HalfSpace(self.normals[i], float(self.offsets[i]))

    def __iter__(self) -> Iterator[int]:
        return iter(self.nodes.tolist())

    def __len__(self) -> int:
        return int(self.nodes.size)


@njit(cache=True)
def _node_index(nodes: np.ndarray, size: int) -> np.ndarray:
    """Each node's position in ``nodes`` (sorted, distinct), −1 for a node not in it (size,)."""
    index = np.full(size, -1, dtype=np.int64)
    for i in range(nodes.size):
        index[nodes[i]] = i
    return index


def _detour_side(
    semi_axes: np.ndarray, r_bar: np.ndarray, level: np.ndarray | None = None
) -> np.ndarray:
    """The side (a unit vector) on which an iterate that crosses the zone goes round it.

    At the deepest node k* the component of r̄_k* across the path's direction
    there (r̄_k*+1 − r̄_k*−1); a path straight through the centre has none, and
    gets the coordinate axis least aligned with its direction, made
    perpendicular to it (a deterministic choice; the other side costs the same
    by symmetry). ``level``: :func:`.constraints.ellipsoid_level` of ``r_bar`` when the
    caller has it.
    """
    if level is None:
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


@njit(cache=True)
def _node_planes(
    a: np.ndarray,
    r: np.ndarray,
    level: np.ndarray,
    nodes: np.ndarray,
    shift: np.ndarray,
    margins_km: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The tangent planes of :func:`_half_spaces` at ``nodes``, tightened by their margins:
    (unit normals (K, 3), offsets (K,) [km]) of ellipsoid ``a`` (3,) at the points whose
    planes bound the nodes' positions ``r[nodes]``: the position itself outside the zone
    (``level`` ≥ 1, :func:`.constraints.ellipsoid_level` of ``r``); inside, the radial
    projection onto the surface of the position moved by ``shift`` (the largest semi-axis
    towards the detour side, :func:`_detour_side`, so that the nodes of a crossing iterate
    all go round on one side): s = r + shift, s / √(level of s). The planes by
    :func:`.constraints.tangent_planes`' kernel, then + ``margins_km[nodes]`` (numpy's
    arithmetic in its order: the same bits)."""
    points = np.empty((nodes.size, 3))
    for i in range(nodes.size):
        k = nodes[i]
        if level[k] < 1.0:
            s0, s1, s2 = r[k, 0] + shift[0], r[k, 1] + shift[1], r[k, 2] + shift[2]
            x, y, z = s0 / a[0], s1 / a[1], s2 / a[2]
            root = math.sqrt(x * x + y * y + z * z)
            points[i, 0], points[i, 1], points[i, 2] = s0 / root, s1 / root, s2 / root
        else:
            points[i, 0], points[i, 1], points[i, 2] = r[k, 0], r[k, 1], r[k, 2]
    normals, offsets = cg._tangent_planes(a, points)
    for i in range(nodes.size):
        offsets[i] = offsets[i] + margins_km[nodes[i]]
    return normals, offsets


#: :func:`_node_planes`' shift when no node is inside the zone (it reads none then).
_NO_SHIFT = np.zeros(3)


@njit(cache=True)
def _any_inside(level: np.ndarray, nodes: np.ndarray) -> bool:
    """Whether one of ``nodes`` has its ``level`` below 1 (inside the ellipsoid)."""
    for k in nodes:  # noqa: SIM110 (a loop: numba compiles no generator for any())
        if level[k] < 1.0:
            return True
    return False


def _half_spaces(
    geo: cg.Geometry,
    modes: np.ndarray,
    r_bar: np.ndarray,
    margins_km: np.ndarray,
    p_pos_km2: np.ndarray | None,
    sigma_margin: float,
    motion: cg.BodyMotion | None = None,
) -> list[HalfSpaces]:
    """The tightened keep-out half-spaces H_k,b of every keep-out node k (and of node 0), one
    :class:`HalfSpaces` per ellipsoid b of the zone, in the body frame (the relative frame
    without ``motion``).

    Each ellipsoid is linearised at the iterate's body-frame position at the node's time
    (issue 34). ``margins_km`` (N+1,): each node's between-node margin. With ``motion``
    the covariance margin is taken along the half-space's normal in the relative frame at
    the two nodes it binds (k and k+1), the larger.
    """
    rho_bar = cg.to_body(motion, r_bar)
    margins_km = np.asarray(margins_km, dtype=np.float64)
    out = []
    for centre, axes in cg.ellipsoids(geo):
        local = np.ascontiguousarray(rho_bar if centre is None else rho_bar - centre)
        a = np.asarray(axes, dtype=np.float64)
        nodes, index, level, normals, offsets = _outside_planes(a, local, modes, margins_km)
        if normals is None or offsets is None:  # a node inside (not in most re-solves): the
            # detour side, which moves only the nodes inside
            shift = float(np.max(axes)) * _detour_side(axes, local, level)
            normals, offsets = _node_planes(a, local, level, nodes, shift, margins_km)
        if sigma_margin > 0.0 and p_pos_km2 is not None:
            if motion is None:
                offsets = offsets + cg.covariance_margins_km(normals, p_pos_km2, sigma_margin)
            else:
                after = np.minimum(nodes + 1, modes.size - 1)
                turned = [
                    np.einsum("kij,kj->ki", motion.rotation[at], normals) for at in (nodes, after)
                ]
                offsets = offsets + np.maximum(
                    cg.covariance_margins_km(turned[0], p_pos_km2, sigma_margin),
                    cg.covariance_margins_km(turned[1], p_pos_km2, sigma_margin),
                )
        if centre is not None:  # nᵀ(ρ − c) ≥ offset ⇔ nᵀρ ≥ offset + nᵀc
            offsets = offsets + normals @ centre
        out.append(HalfSpaces(nodes, normals, offsets, modes.size, index))
    return out


@njit(cache=True)
def _outside_planes(
    a: np.ndarray, r: np.ndarray, modes: np.ndarray, margins_km: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """:func:`_half_spaces`' arrays of ellipsoid ``a`` (3,) at the positions ``r`` (N + 1, 3)
    (its frame, contiguous): the nodes with a half-space (:func:`_half_space_nodes`), their
    index (:func:`_node_index`), the positions' :func:`.constraints.ellipsoid_level` (its
    kernel) and, when no node is inside the zone, their :func:`_node_planes` (normals,
    offsets: no detour side to shift by); (None, None) when one is (the caller shifts)."""
    nodes = _half_space_nodes(modes)
    level = cg._levels(r, a)
    if _any_inside(level, nodes):
        return nodes, _node_index(nodes, modes.size), level, None, None
    normals, offsets = _node_planes(a, r, level, nodes, _NO_SHIFT, margins_km)
    return nodes, _node_index(nodes, modes.size), level, normals, offsets


def trust_radii(
    modes: np.ndarray, r_bar: np.ndarray, half_spaces: list[HalfSpaces], trust_km: float
) -> np.ndarray:
    """Each node's trust radius (N + 1,) [km] of a fixed target (module docstring,
    *Iterations*): the larger of ``trust_km`` and :data:`TRUST_FAR_FRACTION` of the largest
    ∞-norm box about r̄_k that every half-space binding node k holds (the rows of
    :func:`_pairs`; a node with none keeps ``trust_km``).

    The trust box keeps an iterate where the keep-out zone was linearised. A node whose
    half-spaces hold a box twice its own meets them nowhere in its box: its rows are left
    out (:func:`_pairs`), it is safe anywhere in the box, and a smaller box would only hold
    the plan back from where a new estimate takes it (the nodes far from the zone, which
    moved by more than ``trust_km`` between re-solves and made the trust rows bind at tens
    of nodes: docs/solvers.md). The nodes near the zone keep ``trust_km``. A turning body
    keeps one radius (:func:`plan`)."""
    normals, offsets = _stacked_planes(half_spaces)
    return _fixed_radii(
        half_spaces[0].index, normals, offsets, modes, r_bar, trust_km, TRUST_FAR_FRACTION
    )


@njit(cache=True)
def _fixed_radii(
    index: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    modes: np.ndarray,
    r_bar: np.ndarray,
    trust_km: float,
    fraction: float,
) -> np.ndarray:
    """:func:`trust_radii`'s kernel: over the rows of :func:`_pair_rows`, each row's plane
    read as :func:`_fixed_pairs` reads it (``index`` (N + 1,) a node's plane, −1 for none;
    ``normals`` (B, K, 3), ``offsets`` (B, K) of the B ellipsoids), node k's largest held
    box is the smallest over its rows of ``(nᵀ r̄_k − offset) / ‖n‖₁`` (where
    :func:`_box_low` reaches the plane; a zero normal holds any box), ∞ for a node without
    a row."""
    pairs = _pair_rows(index >= 0, modes, normals.shape[0])
    held = np.full(modes.size, np.inf)
    for p in range(pairs.shape[0]):
        k, row, b = pairs[p, 0], index[pairs[p, 1]], pairs[p, 2]
        n0, n1, n2 = normals[b, row, 0], normals[b, row, 1], normals[b, row, 2]
        size = abs(n0) + abs(n1) + abs(n2)
        if size > 0.0:
            dot = n0 * r_bar[k, 0] + n1 * r_bar[k, 1] + n2 * r_bar[k, 2]
            held[k] = min(held[k], (dot - offsets[b, row]) / size)
    radii = np.full(modes.size, trust_km)
    for k in range(modes.size):
        if held[k] < np.inf and fraction * held[k] > trust_km:
            radii[k] = fraction * held[k]
    return radii


def _pairs(
    modes: np.ndarray,
    r_bar: np.ndarray,
    half_spaces: list[HalfSpaces],
    trust_km: float | np.ndarray,
    motion: cg.BodyMotion | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The half-space rows (node k, half-space j, ellipsoid b) of the program, and those
    left out, each (P, 3).

    Node k lies in its own half-space and in its predecessor's: the chord
    k−1 → k then lies in H_k−1 (convex), the arc within the chord margin of it.
    A row is **left out** when the trust box of its node cannot reach the
    plane: ``nᵀ r̄_k − trust ‖n‖₁ ≥ offset + SCP_TOL_KM`` (the smallest nᵀr over
    the box ``‖r − r̄_k‖_∞ ≤ trust``, with a millimetre to spare over the
    solver's feasibility tolerance), so the trust rows imply it: the program,
    and its answer, are the same with and without it.
    """
    kept, left_out, _ = _pairs_planes(modes, r_bar, half_spaces, trust_km, motion)
    return kept, left_out


def _radii(trust_km: float | np.ndarray, nodes: int) -> np.ndarray:
    """Each of ``nodes`` nodes' trust radius (nodes,) [km]: ``trust_km`` itself when it
    gives one per node (:func:`trust_radii`), else one radius for all."""
    radii = np.asarray(trust_km, dtype=np.float64)
    if radii.shape == (nodes,) and radii.flags.c_contiguous:  # already one a node
        return radii
    return np.ascontiguousarray(np.broadcast_to(radii, (nodes,)))


def _stacked_planes(half_spaces: list[HalfSpaces]) -> tuple[np.ndarray, np.ndarray]:
    """The ellipsoids' planes as stacks, normals (B, K, 3) and offsets (B, K) [km] (every
    ellipsoid has the same nodes): one ellipsoid's arrays as a stack of one, no copy."""
    if len(half_spaces) == 1:
        return half_spaces[0].normals[None], half_spaces[0].offsets[None]
    return (
        np.stack([hs.normals for hs in half_spaces]),
        np.stack([hs.offsets for hs in half_spaces]),
    )


def _pairs_planes(
    modes: np.ndarray,
    r_bar: np.ndarray,
    half_spaces: list[HalfSpaces],
    trust_km: float | np.ndarray,
    motion: cg.BodyMotion | None = None,
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """:func:`_pairs` and the kept rows' planes (normals (P, 3), offsets (P,) [km]): those
    :func:`_planes` gives for them, taken from the trust test's (the same bits). ``trust_km``:
    one radius, or each node's (:func:`trust_radii`)."""
    trust_km = _radii(trust_km, modes.size)
    if motion is None:  # the three steps below in one pass (the same rows, the same bits)
        normals, offsets = _stacked_planes(half_spaces)
        kept, left_out, kept_normals, kept_offsets = _fixed_pairs(
            half_spaces[0].index, normals, offsets, modes, r_bar, trust_km
        )
        return kept, left_out, (kept_normals, kept_offsets)
    # every ellipsoid has the same nodes
    pairs = _pair_rows(half_spaces[0].index >= 0, modes, len(half_spaces))
    normals, offsets = _planes(half_spaces, pairs, motion)
    kept, left_out, left = _trust_split(pairs, normals, offsets, r_bar, trust_km)
    return kept, left_out, (normals[~left], offsets[~left])


@njit(cache=True)
def _fixed_pairs(
    index: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    modes: np.ndarray,
    r_bar: np.ndarray,
    trust_km: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_pairs_planes` of a fixed target in one pass: the rows of :func:`_pair_rows` in
    its order, each row's plane as :func:`_planes` reads it (``index`` (N + 1,) a node's
    plane, −1 for none; ``normals`` (B, K, 3), ``offsets`` (B, K) of the B ellipsoids) and
    :func:`_box_low`'s trust test: (kept, left out, kept normals, kept
    offsets)."""
    pairs = _pair_rows(index >= 0, modes, normals.shape[0])
    size = pairs.shape[0]
    kept = np.empty((size, 3), dtype=np.int64)
    out = np.empty((size, 3), dtype=np.int64)
    kept_normals = np.empty((size, 3))
    kept_offsets = np.empty(size)
    i = o = 0
    for p in range(size):
        k, row, b = pairs[p, 0], index[pairs[p, 1]], pairs[p, 2]
        n0, n1, n2 = normals[b, row, 0], normals[b, row, 1], normals[b, row, 2]
        offset = offsets[b, row]
        if _box_low(n0, n1, n2, r_bar, k, trust_km[k]) >= offset + SCP_TOL_KM:
            out[o, 0], out[o, 1], out[o, 2] = k, pairs[p, 1], b
            o += 1
        else:
            kept[i, 0], kept[i, 1], kept[i, 2] = k, pairs[p, 1], b
            kept_normals[i, 0], kept_normals[i, 1], kept_normals[i, 2] = n0, n1, n2
            kept_offsets[i] = offset
            i += 1
    return kept[:i], out[:o], kept_normals[:i], kept_offsets[:i]


@njit(cache=True)
def _pair_rows(has: np.ndarray, modes: np.ndarray, bodies: int) -> np.ndarray:
    """The rows (node k, half-space j, ellipsoid b) of :func:`_pairs` before the trust
    test: node by node, its own plane first (j = k, where node k has one: ``has``), then
    its predecessor's (j = k − 1, where node k − 1 has one and node k is constrained),
    ellipsoid by ellipsoid."""
    out = np.empty((2 * bodies * modes.size, 3), dtype=np.int64)
    count = 0
    for k in range(1, modes.size - 1):
        for j in (k, k - 1):
            if has[j] and (j == k or modes[k] != 0):
                for b in range(bodies):
                    out[count, 0], out[count, 1], out[count, 2] = k, j, b
                    count += 1
    return out[:count]


@njit(cache=True)
def _box_low(n0: float, n1: float, n2: float, r_bar: np.ndarray, k: int, trust_km: float) -> float:
    """``nᵀ r̄_k − trust ‖n‖₁``: the smallest nᵀr over node k's trust box [km] (numpy's sums
    in their order)."""
    dot = n0 * r_bar[k, 0] + n1 * r_bar[k, 1] + n2 * r_bar[k, 2]
    return float(dot - trust_km * (abs(n0) + abs(n1) + abs(n2)))


@njit(cache=True)
def _trust_split(
    pairs: np.ndarray,
    normals: np.ndarray,
    offsets: np.ndarray,
    r_bar: np.ndarray,
    trust_km: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(kept, left out, the left-out mask (P,)) of the rows ``pairs`` (P, 3) with planes
    (normals (P, 3), offsets (P,)): a row is left out when ``nᵀ r̄_k − trust ‖n‖₁``, the
    smallest nᵀr over its node's trust box [km], is at least its offset + :data:`SCP_TOL_KM`
    (:func:`_pairs`; numpy's sums in their order, the same bits)."""
    left = np.empty(pairs.shape[0], dtype=np.bool_)
    count = 0
    for p in range(pairs.shape[0]):
        n0, n1, n2 = normals[p, 0], normals[p, 1], normals[p, 2]
        k = pairs[p, 0]
        left[p] = _box_low(n0, n1, n2, r_bar, k, trust_km[k]) >= offsets[p] + SCP_TOL_KM
        count += left[p]
    kept = np.empty((pairs.shape[0] - count, 3), dtype=np.int64)
    out = np.empty((count, 3), dtype=np.int64)
    i = o = 0
    for p in range(pairs.shape[0]):
        if left[p]:
            out[o] = pairs[p]
            o += 1
        else:
            kept[i] = pairs[p]
            i += 1
    return kept, out, left


def _planes(
    half_spaces: list[HalfSpaces], rows: np.ndarray, motion: cg.BodyMotion | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(normals (P, 3), offsets (P,) [km]) of the rows (node k, half-space j, ellipsoid b):
    H_j,b, its normal turned to node k's time with ``motion`` (nᵀ ρ_k = (R_k n)ᵀ r_k)."""
    if len(half_spaces) == 1:  # one ellipsoid (issue 32's arithmetic)
        i = half_spaces[0].index[rows[:, 1]]
        normals = half_spaces[0].normals[i].reshape(-1, 3)
        offsets = half_spaces[0].offsets[i]
    else:
        normals = np.empty((rows.shape[0], 3))
        offsets = np.empty(rows.shape[0])
        for b, hs in enumerate(half_spaces):
            sel = rows[:, 2] == b
            i = hs.index[rows[sel, 1]]
            normals[sel] = hs.normals[i].reshape(-1, 3)
            offsets[sel] = hs.offsets[i]
    if motion is not None:
        normals = np.einsum("pij,pj->pi", motion.rotation[rows[:, 0]], normals)
    return normals, offsets


def _first_node(modes: np.ndarray, pairs: np.ndarray) -> int:
    """The first node that carries a half-space or a corridor row (N when none does)."""
    corridor = _corridor_nodes(modes)
    return int(np.min(np.r_[pairs[:, 0], corridor, modes.size - 1]))


def _broken_rows(
    x: np.ndarray,
    r_bar: np.ndarray,
    modes: np.ndarray,
    first: int,
    half_spaces: list[HalfSpaces],
    dropped: np.ndarray,
    trust_km: np.ndarray,
    slack_km: float,
    motion: cg.BodyMotion | None = None,
) -> np.ndarray:
    """The nodes whose left-out rows fail at the answer ``x`` (N + 1, 6) of :func:`_program`.

    The program left out the trust rows of the constrained nodes before
    ``first`` and the half-space rows ``dropped`` by :func:`_pairs` (their
    trust box implied them). The answer of the relaxed program is that of the
    whole one when it satisfies what was left out (the relaxation is convex
    and its cost strictly convex in the controls, which fix the states): every
    such node within its trust radius + ``SLACK_TOL_KM`` of r̄_k (the solver's tolerance),
    and, so that every iterate stays safe whatever that tolerance, every
    left-out half-space row held exactly (with the answer's slack, as written).
    """
    r = x[:, :3]
    normals, offsets = _planes(half_spaces, dropped, motion)
    residual = np.sum(normals * r[dropped[:, 0]], axis=1) - offsets + slack_km
    prefix = np.flatnonzero(modes[:first] > 0)
    moved = np.max(np.abs(r[prefix] - r_bar[prefix]), axis=1, initial=0.0)
    return np.union1d(dropped[residual < 0.0, 0], prefix[moved > trust_km[prefix] + SLACK_TOL_KM])


def _thrust_guess(u_bar: np.ndarray, u_max: float, eps: float) -> np.ndarray:
    """The steps whose control the next program leaves free: those of the iterate ``u_bar``
    (N, 3) [km/s²] above :data:`COAST_TOL` u_max, and their neighbours (a switch moves by
    a step between re-solves); every step when ε ≥ 1 (no step coasts: the cost is then
    quadratic) or when the iterate never thrusts."""
    steps = u_bar.shape[0]
    on = np.linalg.norm(u_bar, axis=1) > COAST_TOL * u_max
    if eps >= 1.0 or not np.any(on):
        return np.arange(steps)
    on[1:] |= on[:-1].copy()
    on[:-1] |= on[1:].copy()
    return np.flatnonzero(on)


@dataclass(frozen=True)
class _Subproblem:
    """What one SCP iteration's convex program is built from (module docstring).

    The problem (mean motion n [rad/s], step Δt [s], u_max [km/s²], x0, x_f, ε),
    the geometry, and the previous iterate's modes, positions r̄ (N+1, 3) [km] and
    controls ū (N, 3) [km/s²], the corridor cone's tightening at each node [km]
    (:func:`_cone_margins`), the nodes' linearised half-spaces, each node's trust radius [km],
    the turning body frame of a tumbling target (``None``: fixed) and the abort-safety
    rows (``None``: off).
    """

    n: float
    dt_s: float
    u_max: float
    x0: np.ndarray
    xf: np.ndarray
    eps: float
    geo: cg.Geometry
    modes: np.ndarray
    r_bar: np.ndarray
    u_bar: np.ndarray
    cone_margins_km: np.ndarray
    half_spaces: list[HalfSpaces]
    trust_km: np.ndarray  # (N + 1,) each node's trust radius (:func:`trust_radii`); a float: all
    motion: cg.BodyMotion | None = None
    abort_rows: ab.AbortRows | None = None
    first_order: bool = True  # try the dual solver (:func:`_dual_solve`) before Clarabel
    warm_duals: Duals | None = None  # its starting multipliers (:func:`_warm_multipliers`)

    def __post_init__(self) -> None:
        # one radius given: every node's (the rows read each node's radius)
        object.__setattr__(self, "trust_km", _radii(self.trust_km, self.modes.size))


@dataclass(frozen=True)
class _DualSolution:
    """What :func:`plan` reads of a program's solution when the dual solver answered:
    its scaled cost and (last entry of ``x``) the abort slack, zero."""

    obj_val: float
    x: np.ndarray
    duals: Duals
    status: Any = None


#: Tolerance of every row of the dual solver: the terminal state within 1e-12 km and
#: 1e-15 km/s (the unconstrained ascent's, :data:`.convex._NEWTON`), every path, trust and
#: abort row within 1e-12 km (a thousandth of Clarabel's feasibility, which reaches ~1e-9
#: km on these programs) [km, km/s].
DUAL_TOL_KM = 1e-9
DUAL_TOL_KM_S = 1e-12


#: A row's code for carrying its multiplier to the next program: node × _CODE_NODE +
#: kind × _CODE_KIND + key (terminal and trust rows: their component 0 … 5; half-space
#: rows: (node − the plane's node) + 2 × ellipsoid; abort rows: none, key 999).
_CODE_NODE, _CODE_KIND = 1 << 20, 1 << 16


def _dual_rows(
    sub: _Subproblem,
    pairs: np.ndarray,
    row_scale: np.ndarray,
    box: tuple[np.ndarray, np.ndarray],
    planes: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[path_dual.DualRows, np.ndarray, np.ndarray]:
    """The linear rows of the program of ``sub`` (module docstring; the corridor cones
    aside, and of the trust rows only those of ``box``: (nodes, components) of
    :func:`_trust_rows`) for :func:`.path_dual.solve`, sorted by node, each row's kind
    (0 terminal, 1 half-space, 2 trust, 3 abort) and code (:data:`_CODE_NODE`). Rows
    scaled as the terminal position rows (``row_scale``: :func:`.feasibility.grid_problem`).
    ``planes``: :func:`_planes` of ``pairs`` when the caller has them (:func:`_pairs_planes`).
    Written by :func:`_row_arrays`."""
    if planes is None:
        planes = _planes(sub.half_spaces, pairs, sub.motion)
    abort = sub.abort_rows if sub.abort_rows is not None else _NO_ABORT_ROWS
    node, coeffs, offsets, tol, kind, code, equality = _row_arrays(
        row_scale, sub.xf, _TERMINAL_TOL, pairs, planes[0], planes[1], box[0], box[1],
        sub.r_bar, sub.trust_km, abort.nodes, abort.coeffs, abort.offsets_km,
    )  # fmt: skip
    return path_dual.DualRows(node, coeffs, offsets, equality, tol), kind, code


#: The terminal rows' tolerances before scaling: position [km], velocity [km/s].
_TERMINAL_TOL = np.r_[np.full(3, DUAL_TOL_KM), np.full(3, DUAL_TOL_KM_S)]
#: No abort row (abort safety off), for :func:`_row_arrays`.
_NO_ABORT_ROWS = ab.AbortRows(np.zeros(0, np.int64), np.zeros((0, 6)), np.zeros(0))


@njit(cache=True)
def _row_arrays(
    row_scale: np.ndarray,
    xf: np.ndarray,
    terminal_tol: np.ndarray,
    pairs: np.ndarray,
    normals: np.ndarray,
    plane_offsets: np.ndarray,
    box_nodes: np.ndarray,
    box_comps: np.ndarray,
    r_bar: np.ndarray,
    trust_km: np.ndarray,
    abort_nodes: np.ndarray,
    abort_coeffs: np.ndarray,
    abort_offsets: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rows of :func:`_dual_rows`: (nodes, coeffs (M, 6), offsets, tolerances, kinds,
    codes, equality (the terminal rows, kind 0)), sorted stably by node. Written block by
    block — the terminal state ``x_N = x_f`` (the last node of ``r_bar``), the half-space
    rows ``nᵀ r_k ≥ offset`` of ``pairs`` with their planes (``normals``,
    ``plane_offsets`` [km]), the trust rows of ``box_nodes``, ``box_comps``
    (:func:`_trust_arrays`) and the abort rows ``cᵀ x_k ≥ o`` — each scaled by
    ``row_scale`` (:func:`.feasibility.grid_problem`; the path rows by its position
    entry), then sorted (numpy's stable sort's order)."""
    steps = r_bar.shape[0] - 1
    s_p = row_scale[0]
    n_hs, n_tr, n_ab = pairs.shape[0], box_nodes.size, abort_nodes.size
    total = 6 + n_hs + n_tr + n_ab
    node = np.empty(total, np.int64)
    coeffs = np.zeros((total, 6))
    offsets, tol = np.empty(total), np.empty(total)
    kinds, keys = np.empty(total, np.int64), np.empty(total, np.int64)
    for i in range(6):
        node[i], kinds[i], keys[i] = steps, 0, i
        coeffs[i, i] = row_scale[i]
        offsets[i] = row_scale[i] * xf[i]
        tol[i] = row_scale[i] * terminal_tol[i]
    row = 6
    for p in range(n_hs):
        node[row], kinds[row] = pairs[p, 0], 1
        for c in range(3):
            coeffs[row, c] = normals[p, c] * s_p
        offsets[row], tol[row] = plane_offsets[p] * s_p, DUAL_TOL_KM * s_p
        keys[row] = pairs[p, 0] - pairs[p, 1] + 2 * pairs[p, 2]
        row += 1
    t_coeffs, t_offsets = _trust_arrays(box_nodes, box_comps, r_bar, trust_km, s_p)
    for p in range(n_tr):
        node[row], kinds[row], keys[row] = box_nodes[p], 2, box_comps[p]
        coeffs[row] = t_coeffs[p]
        offsets[row], tol[row] = t_offsets[p], DUAL_TOL_KM * s_p
        row += 1
    for p in range(n_ab):
        node[row], kinds[row], keys[row] = abort_nodes[p], 3, 999
        for c in range(6):
            coeffs[row, c] = abort_coeffs[p, c] * s_p
        offsets[row], tol[row] = abort_offsets[p] * s_p, DUAL_TOL_KM * s_p
        row += 1
    order = _node_order(node)
    out_node, out_coeffs = np.empty(total, np.int64), np.empty((total, 6))
    out_offsets, out_tol = np.empty(total), np.empty(total)
    kind, code = np.empty(total, np.int64), np.empty(total, np.int64)
    for r in range(total):  # the rows in that order (copies, as numpy's indexing)
        i = order[r]
        out_node[r], out_offsets[r], out_tol[r], kind[r] = node[i], offsets[i], tol[i], kinds[i]
        for c in range(6):
            out_coeffs[r, c] = coeffs[i, c]
        code[r] = node[i] * _CODE_NODE + kinds[i] * _CODE_KIND + keys[i]
    return out_node, out_coeffs, out_offsets, out_tol, kind, code, kind == 0


@njit(cache=True)
def _node_order(nodes: np.ndarray) -> np.ndarray:
    """``np.argsort(nodes, kind="stable")`` of nodes ≥ 0 (a stable sort's order is the one
    order of the rows by node that keeps tied rows as they come), by counting: O(rows + N)."""
    size = 0
    for k in nodes:
        size = max(size, k + 1)
    start = np.zeros(size + 1, np.int64)
    for k in nodes:
        start[k + 1] += 1
    for k in range(size):
        start[k + 1] += start[k]
    order = np.empty(nodes.size, np.int64)
    for i in range(nodes.size):
        order[start[nodes[i]]] = i
        start[nodes[i]] += 1
    return order


@njit(cache=True)
def _sorted_order(values: np.ndarray) -> np.ndarray:
    """``np.argsort(values, kind="stable")``: the identity when ``values`` are already in
    order (a plan's row codes, nearly always), else numba's merge sort (stable)."""
    for i in range(1, values.size):
        if values[i] < values[i - 1]:
            return np.argsort(values, kind="mergesort")
    return np.arange(values.size)


def _trust_rows(
    sub: _Subproblem, nodes: np.ndarray, comps: np.ndarray, scale: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Trust rows of ``sub`` at ``nodes`` (M,), component ``comps`` (M,) 0 … 5: (nodes,
    coeffs (M, 6), offsets, codes) of rows ``gᵀx_k ≥ f`` scaled by ``scale``
    (:func:`_trust_arrays`)."""
    coeffs, offsets = _trust_arrays(nodes, comps, sub.r_bar, sub.trust_km, scale)
    return nodes, coeffs, offsets, nodes * _CODE_NODE + 2 * _CODE_KIND + comps


@njit(cache=True)
def _trust_arrays(
    nodes: np.ndarray, comps: np.ndarray, r_bar: np.ndarray, trust_km: np.ndarray, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """(coeffs (M, 6), offsets (M,)) of the trust rows at ``nodes``, component ``comps``,
    scaled by ``scale``: component i < 3 ``r_k,i ≥ r̄_k,i − T_k``, i ≥ 3 ``−r_k,i−3 ≥
    −r̄_k,i−3 − T_k`` (T_k = ``trust_km[k]``, node k's radius), i.e. sign s = ±1 on axis
    i mod 3, offset ``(s r̄_k,i mod 3 − T_k) × scale``."""
    coeffs = np.zeros((nodes.size, 6))
    offsets = np.empty(nodes.size)
    for p in range(nodes.size):
        sign = 1.0 if comps[p] < 3 else -1.0
        axis = comps[p] % 3
        coeffs[p, axis] = sign * scale
        offsets[p] = (sign * r_bar[nodes[p], axis] - trust_km[nodes[p]]) * scale
    return coeffs, offsets


def _broken_trust(sub: _Subproblem, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The trust rows that the positions ``r`` (N + 1, 3) break by more than
    :data:`DUAL_TOL_KM` (the dual solver's tolerance of every row): (nodes, components),
    the rows of :func:`_trust_rows`, over every constrained node (``modes > 0``)."""
    return _box_broken(sub.modes, r, sub.r_bar, sub.trust_km, DUAL_TOL_KM)


@njit(cache=True)
def _box_broken(
    modes: np.ndarray, r: np.ndarray, r_bar: np.ndarray, trust_km: np.ndarray, tol_km: float
) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, components) of :func:`_broken_trust`, node by node: component i < 3 where
    ``r_k,i − r̄_k,i < floor``, i ≥ 3 where ``−(r_k,i−3 − r̄_k,i−3) < floor``, node k's
    floor ``−(T_k + tol_km)`` (``trust_km`` (N + 1,) the radii T_k)."""
    nodes = np.empty(6 * modes.size, dtype=np.int64)
    comps = np.empty(6 * modes.size, dtype=np.int64)
    count = 0
    for k in range(modes.size):
        if modes[k] <= 0:
            continue
        floor_km = -(trust_km[k] + tol_km)
        for i in range(6):
            d = r[k, i % 3] - r_bar[k, i % 3]
            if (d if i < 3 else -d) < floor_km:
                nodes[count], comps[count] = k, i
                count += 1
    return nodes[:count], comps[:count]


def _warm_trust(sub: _Subproblem) -> tuple[np.ndarray, np.ndarray]:
    """The trust rows with a multiplier in the warm start ``sub.warm_duals`` (those the
    previous program held active), at constrained nodes: (nodes, components)."""
    warm = sub.warm_duals
    if warm is None or warm.codes.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return _trust_codes(warm.codes, sub.modes)


@njit(cache=True)
def _trust_codes(codes: np.ndarray, modes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, components) of :func:`_warm_trust`, code by code in their order: the trust rows
    (kind 2) of ``codes`` at a constrained node (``modes > 0``) with a component below 6."""
    nodes = np.empty(codes.size, dtype=np.int64)
    comps = np.empty(codes.size, dtype=np.int64)
    count = 0
    for code in codes:
        node, comp = code // _CODE_NODE, code % _CODE_KIND
        kind = (code % _CODE_NODE) // _CODE_KIND
        if kind == 2 and node < modes.size and comp < 6 and modes[node] > 0:
            nodes[count], comps[count] = node, comp
            count += 1
    return nodes[:count], comps[:count]


def shift_duals(duals: Duals | None, steps: int) -> Duals | None:
    """A plan's row multipliers (:attr:`ConstrainedPlan.duals`) for a program that starts
    ``steps`` nodes later (the next re-solve): each row's node moves back by ``steps``; rows
    that fall on or before the new start are dropped."""
    if duals is None:
        return None
    codes = duals.codes - steps * _CODE_NODE
    keep = codes >= _CODE_NODE
    return Duals(codes[keep], duals.values[keep])


def _warm_multipliers(warm: Duals | None, code: np.ndarray, guess: np.ndarray) -> np.ndarray:
    """Starting multipliers of the rows ``code``: those of ``warm`` where a row has the same
    code, else ``guess`` (:func:`_guess_active`)."""
    if warm is None or warm.codes.size == 0:
        return guess
    out = guess.copy()
    if _carry_unique(warm.codes, warm.values, code, out):
        return out
    # codes repeated (abort rows share one): numpy's sort decides which value is read
    order = np.argsort(warm.codes)
    sorted_codes = warm.codes[order]
    at = np.clip(np.searchsorted(sorted_codes, code), 0, sorted_codes.size - 1)
    hit = sorted_codes[at] == code
    out = guess.copy()
    out[hit] = warm.values[order][at[hit]]
    return out


@njit(cache=True)
def _carry_unique(codes: np.ndarray, values: np.ndarray, code: np.ndarray, out: np.ndarray) -> bool:
    """:func:`_warm_multipliers` when no code repeats in ``codes``: ``out[i]`` = the value of
    the row of ``codes`` equal to ``code[i]``, where there is one (a copy: no arithmetic).
    False (``out`` untouched) when a code repeats."""
    order = _sorted_order(codes)
    for p in range(1, order.size):
        if codes[order[p]] == codes[order[p - 1]]:
            return False
    for i in range(code.size):
        lo, hi = 0, order.size
        while lo < hi:  # the first sorted code ≥ code[i]
            mid = (lo + hi) // 2
            if codes[order[mid]] < code[i]:
                lo = mid + 1
            else:
                hi = mid
        if lo < order.size and codes[order[lo]] == code[i]:
            out[i] = values[order[lo]]
    return True


#: A half-space row whose plane passes within this of the previous iterate's node starts
#: in the dual solver's working set (a plan that touches the zone lies on its planes, and
#: the next linearisation's plane passes through it to second order) [km].
GUESS_KM = 1e-3


def _guess_active(rows: path_dual.DualRows, kind: np.ndarray, r_bar: np.ndarray) -> np.ndarray:
    """Starting multipliers of the dual solver: a positive speck (1e-300: it only marks the
    row as in the working set) on the half-space rows that the previous iterate ``r_bar``
    nearly touches (within :data:`GUESS_KM`), one per run of consecutive such nodes (the
    closest: a state constraint touched over a stretch is held by a few of its rows);
    zero elsewhere (:func:`_mark_touching`)."""
    y = np.zeros(rows.nodes.size)
    _mark_touching(kind, rows.coeffs, rows.offsets, rows.nodes, r_bar, y)
    return y


@njit(cache=True)
def _mark_touching(
    kind: np.ndarray,
    coeffs: np.ndarray,
    offsets: np.ndarray,
    nodes: np.ndarray,
    r_bar: np.ndarray,
    y: np.ndarray,
) -> None:
    """Writes the speck of :func:`_guess_active` into ``y`` at the half-space rows (kind 1)
    whose distance ``(nᵀ r̄ − offset)/‖n‖`` (n = ``coeffs[i, :3]``, in the rows' scale, r̄ =
    ``r_bar`` at the row's node) is within :data:`GUESS_KM`: numpy's arithmetic, with nᵀ r̄
    summed in order (where numpy's einsum may round the last bit otherwise: a row could
    differ only at a distance of 1 m to that bit) and :func:`.constraints.row_norms`' norm."""
    for i in range(kind.size):
        if kind[i] != 1:
            continue
        n0, n1, n2 = coeffs[i, 0], coeffs[i, 1], coeffs[i, 2]
        k = nodes[i]
        dot = n0 * r_bar[k, 0] + n1 * r_bar[k, 1] + n2 * r_bar[k, 2]
        size = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if (dot - offsets[i]) / size <= GUESS_KM:
            y[i] = 1e-300


#: Rounds of corridor-cone cuts of the dual solver before Clarabel takes the program [-].
CONE_ROUNDS = 6
#: Rounds of trust rows added lazily (those an answer breaks) before the dual solver writes
#: every trust row (:func:`_dual_solve`) [-].
TRUST_ROUNDS = 3


def _cone_cuts(
    sub: _Subproblem, r: np.ndarray, scale: float, key: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cuts of the corridor cones that ``r`` (N + 1, 3) breaks: (nodes, coeffs (M, 6),
    offsets, codes) of rows ``gᵀx_k ≥ f`` scaled by ``scale``, code key ``key``.

    At a corridor node whose position breaks its (tightened) cone ``‖Aρ + b‖ ≤ cᵀρ + d``
    by more than :data:`DUAL_TOL_KM`, with w = Aρ + b and ŵ = w/‖w‖: ``ŵᵀ(Aρ + b) ≤ cᵀρ
    + d``, i.e. ``(c − Aᵀŵ)ᵀρ ≥ ŵᵀb − d``. The cone implies it (‖w‖ ≥ ŵᵀw for any
    unit ŵ), so a program with cuts is a relaxation of the one with cones (Kelley's
    cutting planes); ρ = R_kᵀ r with ``motion``.
    """
    nodes = _corridor_nodes(sub.modes)
    if nodes.size == 0:  # no corridor node (most programs): no cut
        return nodes, np.zeros((0, 6)), np.zeros(0), nodes * _CODE_NODE
    rho = cg.to_body(None if sub.motion is None else _motion_at(sub.motion, nodes), r[nodes])
    out_nodes, coeffs, offsets = [], [], []
    for i, k in enumerate(nodes.tolist()):
        a, b, c, d = cg.corridor_cone(sub.geo, float(sub.cone_margins_km[k])).rows()
        w = a @ rho[i] + b
        size = float(np.linalg.norm(w))
        if float(c @ rho[i]) + d - size >= -DUAL_TOL_KM:
            continue
        w_hat = w / size if size > 0.0 else np.zeros(3)
        normal = c - a.T @ w_hat
        if sub.motion is not None:
            normal = sub.motion.rotation[k] @ normal
        out_nodes.append(k)
        coeffs.append(np.r_[normal, np.zeros(3)] * scale)
        offsets.append((float(w_hat @ b) - d) * scale)
    m = len(out_nodes)
    node = np.array(out_nodes, dtype=np.int64)
    code = node * _CODE_NODE + 4 * _CODE_KIND + key
    return node, np.array(coeffs).reshape(m, 6), np.array(offsets), code


def _motion_at(motion: cg.BodyMotion, nodes: np.ndarray) -> cg.BodyMotion:
    """``motion`` at ``nodes`` only (its rotations; what :func:`.constraints.to_body` reads)."""
    return motion._replace(rotation=motion.rotation[nodes])


def _with_rows(
    rows: path_dual.DualRows,
    kind: np.ndarray,
    code: np.ndarray,
    cuts: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    tol: float,
    cut_kind: int = 4,
) -> tuple[path_dual.DualRows, np.ndarray, np.ndarray]:
    """``rows`` with the inequality rows ``cuts`` (:func:`_cone_cuts` or
    :func:`_trust_rows`, kind ``cut_kind``, tolerance ``tol``), sorted by node again
    (:func:`_merged_rows`)."""
    node, coeffs, offsets, cut_code = cuts
    nodes, coeffs, offsets, equality, tols, kinds, codes = _merged_rows(
        rows.nodes, rows.coeffs, rows.offsets, rows.equality, rows.tol, kind, code,
        node, coeffs, offsets, cut_code, tol, cut_kind,
    )  # fmt: skip
    return path_dual.DualRows(nodes, coeffs, offsets, equality, tols), kinds, codes


@njit(cache=True)
def _merged_rows(
    nodes: np.ndarray,
    coeffs: np.ndarray,
    offsets: np.ndarray,
    equality: np.ndarray,
    tol: np.ndarray,
    kind: np.ndarray,
    code: np.ndarray,
    new_nodes: np.ndarray,
    new_coeffs: np.ndarray,
    new_offsets: np.ndarray,
    new_code: np.ndarray,
    new_tol: float,
    new_kind: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_with_rows`' arrays: the rows (``nodes`` … ``code``) followed by the new
    inequality rows (``new_nodes`` … ``new_code``, each of tolerance ``new_tol`` and kind
    ``new_kind``), sorted stably by node (numpy's stable sort's order; copies only)."""
    old, total = nodes.size, nodes.size + new_nodes.size
    every = np.empty(total, np.int64)
    every[:old] = nodes
    every[old:] = new_nodes
    order = _node_order(every)
    out_coeffs = np.empty((total, 6))
    out_offsets, out_tol = np.empty(total), np.empty(total)
    out_equality = np.empty(total, np.bool_)
    out_kind, out_code = np.empty(total, np.int64), np.empty(total, np.int64)
    for r in range(total):
        i = order[r]
        if i < old:
            out_coeffs[r] = coeffs[i]
            out_offsets[r], out_tol[r], out_equality[r] = offsets[i], tol[i], equality[i]
            out_kind[r], out_code[r] = kind[i], code[i]
        else:
            j = i - old
            out_coeffs[r] = new_coeffs[j]
            out_offsets[r], out_tol[r], out_equality[r] = new_offsets[j], new_tol, False
            out_kind[r], out_code[r] = new_kind, new_code[j]
    return every[order], out_coeffs, out_offsets, out_equality, out_tol, out_kind, out_code


@njit(cache=True)
def _absent(values: np.ndarray, pool: np.ndarray) -> np.ndarray:
    """``~np.isin(values, pool)`` of integer arrays: where a value is not in ``pool``."""
    ordered = np.sort(pool)
    at = np.searchsorted(ordered, values)
    out = np.empty(values.size, np.bool_)
    for i in range(values.size):
        out[i] = at[i] >= ordered.size or ordered[at[i]] != values[i]
    return out


def _dual_solve(
    sub: _Subproblem, pairs: np.ndarray, planes: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[_DualSolution, int, tuple[np.ndarray, np.ndarray, float]] | tuple[None, int, None]:
    """The whole program of ``sub`` by the projected dual Newton method of
    :mod:`.path_dual` (module docstring, *Solvers*): (solution, iterations, (controls, states,
    slack 0)), or (None, iterations, None) when its answer is not certified optimal for the
    whole program (not converged, a corridor cone still broken after :data:`CONE_ROUNDS`
    rounds of cuts (:func:`_cone_cuts`), or a path or abort multiplier sum above its
    slack's price: then the program needs its slack) — Clarabel then solves it.

    The trust box enters lazily: the program starts with the trust rows the warm start
    holds active (:func:`_warm_trust`); the rows an answer breaks (:func:`_broken_trust`)
    are added and the program solved again, warm, and after :data:`TRUST_ROUNDS` such
    rounds every trust row is written. An answer that holds every trust row it left out
    (with multiplier 0) meets the whole program's KKT conditions: the same answer."""
    steps = sub.modes.size - 1
    # the grid's blocks and row scale: those of feasibility.grid_problem, without its rhs
    blocks = feasibility.grid_blocks(sub.n, sub.dt_s, steps)
    row_scale = feasibility.row_scale(steps * sub.dt_s, sub.u_max)
    rows, kind, code = _dual_rows(sub, pairs, row_scale, _warm_trust(sub), planes)
    weight = max(float(sub.eps), convex.REGULARISATION)
    warm = _warm_multipliers(sub.warm_duals, code, _guess_active(rows, kind, sub.r_bar))
    s_p = float(row_scale[0])
    used = 0
    cone_rounds = trust_rounds = 0
    retried = sub.warm_duals is None
    # below DUAL_MIN_WEIGHT (fixed ε): the steps the iterate thrusts on first, the others
    # held at zero until their Lagrangian says otherwise (path_dual.solve's ``keep``)
    keep = None
    if weight < convex.DUAL_MIN_WEIGHT:
        keep = _thrust_guess(sub.u_bar, sub.u_max, sub.eps)
    scaled, products = path_dual.grid_arrays(sub.n, sub.dt_s, sub.u_max, steps)
    while True:
        ans = path_dual.solve(
            sub.n, sub.dt_s, sub.u_max, sub.x0, blocks, sub.eps, weight, rows, warm,
            keep=keep, products=products, scaled=scaled,
        )  # fmt: skip
        used += ans.iterations
        if not ans.converged and not retried:  # the warm start failed: once from the guess
            retried = True
            ans = path_dual.solve(
                sub.n, sub.dt_s, sub.u_max, sub.x0, blocks, sub.eps, weight, rows,
                _guess_active(rows, kind, sub.r_bar), keep=keep, products=products,
                scaled=scaled,
            )  # fmt: skip
            used += ans.iterations
        if not ans.converged and keep is None and cone_rounds:  # with cuts: the smooth start
            ans = path_dual.solve_from_smooth(
                sub.n, sub.dt_s, sub.u_max, sub.x0, blocks, sub.eps, weight, rows, warm,
                products=products, scaled=scaled,
            )  # fmt: skip
            used += ans.iterations
        if not ans.converged:
            return None, used, None
        # numpy's (pairwise) sums of the multipliers in the rows' order
        if _sum_of_kinds(ans.multipliers, kind, 1, 4) * s_p > SLACK_PENALTY:
            return None, used, None
        abort = sub.abort_rows is not None and sub.abort_rows.nodes.size > 0
        if abort and _sum_of_kinds(ans.multipliers, kind, 3, 3) * s_p > ABORT_SLACK_PENALTY:
            return None, used, None
        cuts = _cone_cuts(sub, ans.states[:, :3], s_p, 100 + cone_rounds)
        box = _broken_trust(sub, ans.states[:, :3])
        # the next program's warm start: at a small weight the homotopy's first level's
        # multipliers (path_dual.DualAnswer.start: where the next one starts)
        carried = ans.multipliers if ans.start is None else ans.start
        if cuts[0].size == 0 and box[0].size == 0:
            duals = Duals(*_nonzero_rows(code, carried))
            return (
                _DualSolution(ans.cost, np.zeros(1), duals),
                used,
                (ans.controls, ans.states, 0.0),
            )
        known = Duals(code, carried)
        if cuts[0].size:
            if cone_rounds == CONE_ROUNDS:
                return None, used, None
            cone_rounds += 1
            rows, kind, code = _with_rows(rows, kind, code, cuts, DUAL_TOL_KM * s_p)
        if box[0].size:
            trust_rounds += 1
            if trust_rounds > TRUST_ROUNDS:  # every trust row not yet written
                boxed = np.flatnonzero(sub.modes > 0)
                box = (np.repeat(boxed, 6), np.tile(np.arange(6), boxed.size))
            trust = _trust_rows(sub, box[0], box[1], s_p)
            new = _absent(trust[3], code)
            if not np.any(new) and cuts[0].size == 0:  # broken though written: not certified
                return None, used, None
            trust = (trust[0][new], trust[1][new], trust[2][new], trust[3][new])
            rows, kind, code = _with_rows(rows, kind, code, trust, DUAL_TOL_KM * s_p, 2)
        warm = _warm_multipliers(known, code, np.zeros(code.size))


@njit(cache=True)
def _sum_of_kinds(values: np.ndarray, kind: np.ndarray, first: int, second: int) -> float:
    """``np.sum(values[(kind == first) | (kind == second)])``: the values of the rows of
    either kind, in their order, summed as numpy sums them (:func:`.path_dual.numpy_sum`;
    the same bits)."""
    out = np.empty(values.size)
    count = 0
    for i in range(values.size):
        if kind[i] == first or kind[i] == second:
            out[count] = values[i]
            count += 1
    return path_dual.numpy_sum(out[:count])


@njit(cache=True)
def _nonzero_rows(code: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(code[values != 0], values[values != 0])``: the rows with a multiplier, in their
    order (copies: numpy's boolean indexing's arrays)."""
    codes, kept = np.empty(values.size, np.int64), np.empty(values.size)
    count = 0
    for i in range(values.size):
        if values[i] != 0.0:
            codes[count], kept[count] = code[i], values[i]
            count += 1
    return codes[:count], kept[:count]


def _reduced_solve(
    sub: _Subproblem, reduce: bool = True
) -> tuple[Any, int, tuple[np.ndarray, np.ndarray, float] | None, int]:
    """One SCP iteration's program, solved reduced (module docstring, *Reductions*):
    (Clarabel's last solution, its iterations summed, (controls [km/s²], states,
    slack [km]) or None when unsolved).

    Starts without the left-out rows of :func:`_pairs`, without the states before
    :func:`_first_node` and with the controls of :func:`_thrust_guess` only; puts back
    whatever the answer breaks (:func:`_broken_rows`, :func:`_coasting_broken`) and
    solves again, at most :data:`REDUCED_ROUNDS` times, then the whole program.
    Unsolved with every row that could make it infeasible: so is the whole program.
    ``reduce=False``: the whole program at once, every row written (the reference).
    """
    n, dt_s, u_max, x0, xf, eps = sub.n, sub.dt_s, sub.u_max, sub.x0, sub.xf, sub.eps
    modes, r_bar, u_bar, half_spaces = sub.modes, sub.r_bar, sub.u_bar, sub.half_spaces
    trust_km, motion, abort_rows = sub.trust_km, sub.motion, sub.abort_rows
    steps = modes.size - 1
    pairs, dropped, planes = _pairs_planes(modes, r_bar, half_spaces, trust_km, motion)
    if not reduce:
        pairs, dropped = np.concatenate([pairs, dropped]), dropped[:0]
    used, fallback = 0, 0
    if reduce and sub.first_order:
        dual, used, dual_answer = _dual_solve(sub, pairs, planes)
        if dual is not None:
            return dual, used, dual_answer, 0
        fallback = 1
    # Clarabel's reductions (ii) and (iii), made only when it solves the program
    first = _first_node(modes, pairs)
    if abort_rows is not None and abort_rows.nodes.size:  # their nodes' states are variables
        first = min(first, int(np.min(abort_rows.nodes)))
    thrust = _thrust_guess(u_bar, u_max, eps)
    for attempt in range(0 if reduce else REDUCED_ROUNDS, REDUCED_ROUNDS + 1):
        if attempt == REDUCED_ROUNDS:  # the whole program (rows implied by trust aside)
            first, thrust = 1, np.arange(steps)
        sol, iterations = _program(sub, pairs, first, thrust)
        used += iterations
        if not feasibility.solved(sol):
            if thrust.size == steps:
                return sol, used, None, fallback
            thrust = np.arange(steps)  # the held steps may be why: free them
            continue
        u, x, slack = _answer(n, dt_s, u_max, x0, sol, steps, first, thrust)
        broken = _broken_rows(x, r_bar, modes, first, half_spaces, dropped, trust_km, slack, motion)
        wake = _coasting_broken(n, dt_s, u_max, x0, xf, eps, sol, steps, first, thrust)
        if attempt == REDUCED_ROUNDS or (broken.size == 0 and wake.size == 0):
            return sol, used, (u, x, slack), fallback
        if broken.size:
            first = min(first, int(broken[0]))
            back = (dropped[:, 0] >= first) | np.isin(dropped[:, 0], broken)
            pairs, dropped = np.concatenate([pairs, dropped[back]]), dropped[~back]
        thrust = np.union1d(thrust, wake)
    raise AssertionError("unreachable")  # the last attempt returns


def _program(
    sub: _Subproblem, pairs: np.ndarray, first: int, thrust: np.ndarray
) -> tuple[Any, int]:
    """One convex subproblem (module docstring) solved by Clarabel; (solution, steps).

    ``pairs``: the half-space rows (node k, half-space j) to write
    (:func:`_pairs`); ``first``: the first node whose state is a variable
    (:func:`_first_node`): the nodes before it carry no row, so their states
    are substituted (x_first = Φ^first x0 + Σ_j<first Φ^(first−1−j) Γ u_j, one
    block of 6 rows) and the trust region of constrained nodes before it is
    left to :func:`_broken_rows`, checked on the answer; ``thrust``: the steps
    whose control is a variable (sorted), the others held at zero
    (:func:`_coasting_broken` checks that on the answer). Variables: ũ_j and
    t̃_j of the ``thrust`` steps, x_first … x_N, s. With ``motion`` (a tumbling
    target) every body-frame half-space and the corridor cone bind node k through
    its body-frame position R_kᵀ r_k (issue 34).
    """
    n, dt_s, u_max, x0, xf, eps = sub.n, sub.dt_s, sub.u_max, sub.x0, sub.xf, sub.eps
    geo, modes, r_bar, margins_km = sub.geo, sub.modes, sub.r_bar, sub.cone_margins_km
    half_spaces, trust_km, motion, abort_rows = (
        sub.half_spaces, sub.trust_km, sub.motion, sub.abort_rows,
    )  # fmt: skip
    steps = modes.size - 1
    phi, gam = discretize(n, dt_s)
    gam_u = gam * u_max
    powers = _powers(n, dt_s, x0, xf, u_max, first)
    n_x = steps - first + 1  # states x_first … x_N
    n_u = thrust.size
    iu, it, ix, i_s = 0, 3 * n_u, 4 * n_u, 4 * n_u + 6 * n_x
    n_vars = i_s + 1 + (abort_rows is not None)  # … and the abort slack
    ucol = np.full(steps, -1, dtype=np.int64)
    ucol[thrust] = iu + 3 * np.arange(n_u)

    def xcol(k: int) -> int:  # first column of x_k, k = first … N
        return ix + 6 * (k - first)

    def xcols(nodes: np.ndarray) -> np.ndarray:
        """First columns of the states of ``nodes``: a path row on a node before ``first``
        (not a variable) is a bug: every row block names its nodes in :func:`_first_node`."""
        if np.any(nodes < first):
            raise ValueError(f"a path row on node {int(np.min(nodes))} < first = {first}")
        return np.asarray(ix + 6 * (nodes - first), dtype=np.int64)

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

    # dynamics: x_first − Σ_j<first Φ^(first−1−j) Γ̃ ũ_j = Φ^first x0 (x_1 − Γ̃ ũ_0 = Φ x0 when
    # first = 1), x_{k+1} − Φ x_k − Γ̃ ũ_k = 0 for k ≥ first, and x_N = x_f
    k_dyn = np.arange(first, steps)
    rows_dyn = 6 * (k_dyn - first + 1)
    pre, dyn_u = thrust[thrust < first], k_dyn[ucol[k_dyn] >= 0]
    parts = [
        dense_block(np.zeros(pre.size, np.int64), ucol[pre], -powers[pre]),
        dense_block(np.zeros(1, np.int64), np.array([xcol(first)]), np.eye(6)),
        dense_block(rows_dyn, ix + 6 * (k_dyn + 1 - first), np.eye(6)),
        dense_block(6 * (dyn_u - first + 1), ucol[dyn_u], -gam_u),
        dense_block(rows_dyn, ix + 6 * (k_dyn - first), -phi),
        dense_block(np.array([6 * n_x]), np.array([xcol(steps)]), np.eye(6)),
    ]
    b_eq = np.zeros(6 * n_x + 6)
    b_eq[0:6] = stm(n, first * dt_s) @ x0
    b_eq[6 * n_x :] = xf
    blocks.append((*_cat(parts), 6 * n_x + 6))
    rhs = [b_eq]
    cones.append(clarabel.ZeroConeT(6 * n_x + 6))
    # ‖ũ_j‖ ≤ t̃_j ≤ 1
    soc_u = feasibility.cone_rows(n_u, n_vars, it + np.arange(n_u)).tocoo()
    blocks.append((soc_u.row, soc_u.col, soc_u.data, 4 * n_u))
    rhs.append(np.zeros(4 * n_u))
    cones += [clarabel.SecondOrderConeT(4)] * n_u
    # nonnegative rows: t̃ ≤ 1, s ≥ 0, half-spaces, trust region
    j_u = np.arange(n_u)
    parts = [(j_u, it + j_u, np.ones(n_u)), (np.array([n_u]), np.array([i_s]), -np.ones(1))]
    b_nonneg = [np.ones(n_u), np.zeros(1)]
    # nᵀ r_k + s ≥ offset ⇔ −nᵀ r_k − s ≤ −offset
    row0 = n_u + 1
    if pairs.size:
        node = pairs[:, 0]
        normals, offsets = _planes(half_spaces, pairs, motion)
        rows_hs = row0 + np.arange(node.size)
        parts.append(dense_block(rows_hs, xcols(node), -normals[:, None, :]))
        parts.append((rows_hs, np.full(node.size, i_s), -np.ones(node.size)))
        b_nonneg.append(-offsets)
        row0 += node.size
    if abort_rows is not None:
        row0 = _abort_block(abort_rows, xcols(abort_rows.nodes), i_s + 1, row0, parts, b_nonneg)
    constrained = np.flatnonzero(modes > 0)
    constrained = constrained[constrained >= first]
    if constrained.size:  # ±(r_k − r̄_k) ≤ trust
        rows_tr = row0 + 6 * np.arange(constrained.size)
        cols_tr = xcols(constrained)
        parts.append(dense_block(rows_tr, cols_tr, np.eye(3)))
        parts.append(dense_block(rows_tr + 3, cols_tr, -np.eye(3)))
        b_nonneg.append(
            np.column_stack(
                [
                    trust_km[constrained, None] + r_bar[constrained],
                    trust_km[constrained, None] - r_bar[constrained],
                ]
            ).ravel()
        )
        row0 += 6 * constrained.size
    blocks.append((*_cat(parts), row0))
    rhs.append(np.concatenate(b_nonneg))
    cones.append(clarabel.NonnegativeConeT(row0))
    # corridor: ‖P(r_k − p)‖ ≤ tan θ âᵀ(r_k − p) − m + s, as (head, body) = b − A x ∈ SOC(4)
    corridor_nodes = _corridor_nodes(modes)
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
            dense_block(rows_c, xcols(corridor_nodes), head),
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
    q[it : it + n_u] = 1.0 - min(float(eps), 1.0)
    q[i_s] = SLACK_PENALTY
    if abort_rows is not None:
        q[i_s + 1] = ABORT_SLACK_PENALTY
    diag = np.zeros(n_vars)
    diag[: 3 * n_u] = 2.0 * weight
    p = sp.diags(diag, format="csc")
    sol = feasibility.solve_cone(p, q, a, b, cones)
    return sol, int(sol.iterations)


def _abort_block(
    rows: ab.AbortRows,
    cols: np.ndarray,
    i_slack: int,
    row0: int,
    parts: list[tuple[np.ndarray, ...]],
    b_nonneg: list[np.ndarray],
) -> int:
    """Append the abort rows ``cᵀ x_k + s_a ≥ o`` and ``s_a ≥ 0`` (as ``−cᵀ x_k − s_a ≤ −o``,
    ``−s_a ≤ 0``) at row ``row0`` of the nonnegative block; the next free row."""
    count = rows.nodes.size
    at = row0 + np.arange(count)
    parts.append(
        (
            np.repeat(at, 6),
            (cols[:, None] + np.arange(6)[None, :]).ravel(),
            -rows.coeffs.ravel(),
        )
    )
    parts.append((np.r_[at, row0 + count], np.full(count + 1, i_slack), -np.ones(count + 1)))
    b_nonneg += [-rows.offsets_km, np.zeros(1)]
    return row0 + count + 1


def _cat(parts: list[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenated (rows, columns, values) of triplet parts."""
    return (
        np.concatenate([p[0] for p in parts]).astype(np.int64),
        np.concatenate([p[1] for p in parts]).astype(np.int64),
        np.concatenate([p[2] for p in parts]).astype(np.float64),
    )


def _powers(
    n: float, dt_s: float, x0: np.ndarray, xf: np.ndarray, u_max: float, first: int
) -> np.ndarray:
    """``Φ^(first−1−j) Γ u_max`` (first, 6, 3): how ũ_j moves x_first (Eq. 11)."""
    return feasibility.grid_problem(n, x0, xf, first * dt_s, dt_s, u_max).blocks * u_max


def _coasting_broken(
    n: float,
    dt_s: float,
    u_max: float,
    x0: np.ndarray,
    xf: np.ndarray,
    eps: float,
    sol: Any,
    steps: int,
    first: int,
    thrust: np.ndarray,
) -> np.ndarray:
    """The steps held at zero by :func:`_program` for which zero is not optimal.

    With the multipliers z of the dynamics rows at the answer, ũ_j = 0 (and
    t̃_j = 0) is optimal in the program with ũ_j free iff ``‖A_jᵀ z‖ ≤ 1 − ε``
    (A_j the rows' columns of ũ_j: minimising ``(1 − ε)‖ũ‖ + w‖ũ‖² + (A_jᵀz)ᵀũ``
    over the ball, zero wins iff the linear term cannot beat the norm); the
    same screen as the unconstrained program's (:func:`.convex.plan_controls`).
    When every held step passes, the answer satisfies the optimality
    conditions of the program with every step free, to Clarabel's tolerance.
    """
    linear = 1.0 - min(float(eps), 1.0)
    coast = np.setdiff1d(np.arange(steps), thrust)
    z = np.asarray(sol.z)
    z_first = z[0:6]
    pre, late = coast[coast < first], coast[coast >= first]
    _, gam = discretize(n, dt_s)
    rows = 6 * (late - first + 1)
    z_late = z[rows[:, None] + np.arange(6)]
    norms = np.r_[
        np.linalg.norm(
            np.einsum("kij,i->kj", _powers(n, dt_s, x0, xf, u_max, first)[pre], z_first), axis=1
        ),
        np.linalg.norm(z_late @ (gam * u_max), axis=1),
    ]
    return np.asarray(np.r_[pre, late][norms > linear], dtype=np.int64)


def _answer(
    n: float,
    dt_s: float,
    u_max: float,
    x0: np.ndarray,
    sol: Any,
    steps: int,
    first: int,
    thrust: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, float]:
    """(controls (N, 3) [km/s²], states (N + 1, 6), slack [km]) of a solved :func:`_program`.

    Interior-point controls may exceed u_max by the solver tolerance: they are
    projected onto the ball. The states before ``first`` (not variables of the
    program) follow from the controls by the dynamics (Eq. 11).
    """
    x_sol = np.asarray(sol.x)
    u = np.zeros((steps, 3))
    u[thrust] = x_sol[: 3 * thrust.size].reshape(-1, 3)
    norms = np.linalg.norm(u, axis=1)
    u = np.where(norms[:, None] > 1.0, u / np.maximum(norms, 1.0)[:, None], u) * u_max
    head, _ = node_positions(n, dt_s, x0, u[: first - 1])
    i_x, n_x = 4 * thrust.size, steps - first + 1  # the path slack follows the states
    x = np.vstack([head, x_sol[i_x : i_x + 6 * n_x].reshape(n_x, 6)])
    return u, x, float(x_sol[i_x + 6 * n_x])


@njit(cache=True)
def _largest_norms(x: np.ndarray) -> tuple[float, float]:
    """(max ‖r_k‖ [km], max ‖v_k‖ [km/s]) over states (N + 1, 6): ``np.linalg.norm``'s sum
    of squares in its order, so the same bits; NaN if a state is NaN."""
    r2, v2, nan = 0.0, 0.0, False
    for k in range(x.shape[0]):
        a = x[k, 0] * x[k, 0] + x[k, 1] * x[k, 1] + x[k, 2] * x[k, 2]
        b = x[k, 3] * x[k, 3] + x[k, 4] * x[k, 4] + x[k, 5] * x[k, 5]
        nan = nan or a != a or b != b
        r2, v2 = max(r2, a), max(v2, b)
    if nan:
        return math.nan, math.nan
    return math.sqrt(r2), math.sqrt(v2)


def _accel(n: float, dt_s: float, u_max: float, x: np.ndarray, extra_km: float) -> float:
    """The acceleration bound of the chord margin over a plan's states (module docstring)."""
    r, v = _largest_norms(np.ascontiguousarray(x, dtype=np.float64))
    return cg.acceleration_bound(r + extra_km, v, u_max, n, dt_s)


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
    cg.acceleration_bound(0.0, 0.0, u_max, n, dt_s)  # its ValueError when nΔt is too large
    rate, rate_dot = motion.rate_bound_rad_s, motion.rate_dot_bound_rad_s2
    # the powers of the scalars as the scalar functions take them (Python's), then per step
    # only + − × ÷ in their order: the same bits as the scalar functions step by step
    return _turning_margins(
        np.ascontiguousarray(x, dtype=np.float64), extra_km, factor, u_max,
        1.0 - 3.0 * (n * dt_s) ** 2 - 2.0 * n * dt_s, 3.0 * n**2, 2.0 * n, dt_s, dt_s**2,
        rate_dot + rate**2, 2.0 * rate,
    )  # fmt: skip


@njit(cache=True)
def _larger(a: float, b: float) -> float:
    """``np.maximum`` of two floats: NaN when either is NaN."""
    return math.nan if a != a or b != b else (a if a >= b else b)


@njit(cache=True)
def _turning_margins(
    x: np.ndarray,
    extra_km: float,
    factor: float,
    u_max: float,
    denominator: float,
    gravity_r: float,
    gravity_v: float,
    dt_s: float,
    dt2_s2: float,
    spin: float,
    coriolis: float,
) -> np.ndarray:
    """:func:`_step_margins` of a turning body (N,) [km]: each step's
    :func:`~cwrend_cli.physics.constraints.chord_margin_km` of ``factor`` ×
    :func:`~cwrend_cli.physics.constraints.body_acceleration_bound` of
    :func:`~cwrend_cli.physics.constraints.acceleration_bound` from the larger of its two
    nodes' ‖r‖ (+ ``extra_km``) and ‖v‖ — their arithmetic in their order, with their
    scalar powers given (``denominator`` 1 − 3(nΔt)² − 2nΔt, ``gravity_r`` 3n²,
    ``gravity_v`` 2n, ``dt2_s2`` Δt², ``spin`` ‖Ω̇‖ + ‖Ω‖², ``coriolis`` 2‖Ω‖); the norms
    ``np.linalg.norm``'s sums of squares in its order; NaN where a state is NaN
    (``np.maximum``'s)."""
    steps = x.shape[0] - 1
    out = np.empty(steps)
    r0 = math.sqrt(x[0, 0] * x[0, 0] + x[0, 1] * x[0, 1] + x[0, 2] * x[0, 2])
    v0 = math.sqrt(x[0, 3] * x[0, 3] + x[0, 4] * x[0, 4] + x[0, 5] * x[0, 5])
    for k in range(steps):
        s = x[k + 1]
        r1 = math.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
        v1 = math.sqrt(s[3] * s[3] + s[4] * s[4] + s[5] * s[5])
        r = _larger(r0, r1) + extra_km
        v = _larger(v0, v1)
        accel = (u_max + (gravity_r * (r + v * dt_s) + gravity_v * v)) / denominator
        r_step = r + v * dt_s + accel * dt2_s2
        v_step = v + accel * dt_s
        body = accel + spin * r_step + coriolis * v_step
        out[k] = factor * body * dt2_s2 / 8.0
        r0, v0 = r1, v1
    return out


@njit(cache=True)
def _node_margins(step_margins: np.ndarray) -> np.ndarray:
    """Each node's margin (N+1,) [km]: the larger of its two steps' (a node's constraints
    bind the chords on both sides of it; the end nodes have one step); NaN where either
    is (``np.maximum``'s)."""
    size = step_margins.size
    out = np.empty(size + 1)
    out[0], out[size] = step_margins[0], step_margins[size - 1]
    for k in range(1, size):
        out[k] = _larger(step_margins[k - 1], step_margins[k])
    return out


@njit(cache=True)
def _largest_move(x: np.ndarray, r_bar: np.ndarray) -> float:
    """``max |r_k,i − r̄_k,i|`` [km] of the positions of states ``x`` (N + 1, 6 or 3) from
    ``r_bar`` (N + 1, 3): how far an iterate moved (or a warm plan's end is from the target,
    :func:`out_of_reach`); NaN if a difference is (``np.max``'s)."""
    out = -math.inf
    for k in range(r_bar.shape[0]):
        for i in range(3):
            d = abs(x[k, i] - r_bar[k, i])
            if d != d:
                return math.nan
            out = max(out, d)
    return out


@njit(cache=True)
def _within_margins(step_margins: np.ndarray, node_margins: np.ndarray) -> bool:
    """Whether every step's margin (N,) is at most both its nodes' (N + 1,) [km]: ``all(s_k ≤
    min(m_k, m_k+1))``, false where one is NaN (``np.minimum``'s)."""
    for k in range(step_margins.size):
        s = step_margins[k]
        if not (s <= node_margins[k] and s <= node_margins[k + 1]):
            return False
    return True


def _unconstrained_plan(
    n: float,
    dt_s: float,
    u_max_km_s2: float,
    x0: np.ndarray,
    xf: np.ndarray,
    horizon_s: float,
    eps: float,
) -> tuple[bool, np.ndarray, int]:
    """The first iterate of a cold plan: whether the unconstrained cone program
    (:func:`.convex.plan_controls`) from ``x0`` to ``xf`` has a plan, its controls (N, 3)
    [km/s²] (zeros when it has none) and its solver iterations [-]."""
    g = feasibility.grid_problem(n, x0, xf, horizon_s, dt_s, u_max_km_s2)
    status, controls, _, iterations = convex.plan_controls(g, eps, n)
    converged = status is SolveStatus.CONVERGED
    if not converged:
        controls = np.zeros((max(1, round(horizon_s / dt_s)), 3))
    return converged, controls, iterations


def out_of_reach(end_state: np.ndarray, xf: np.ndarray, trust_km: float) -> bool:
    """True when a warm plan ending at ``end_state`` (its terminal node, 6 or 3 components
    [km, km/s]) cannot be moved onto the terminal target ``xf`` within the trust box of the
    first SCP program: its end position is farther than ``trust_km`` from the target's in
    some axis (module docstring, *A moved target*)."""
    end = np.asarray(end_state, dtype=np.float64)[None]
    return bool(_largest_move(end, np.asarray(xf, dtype=np.float64)[None, :3]) > trust_km)


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
    reduce: bool = True,
    motion: cg.BodyMotion | None = None,
    abort_safe_s: float | None = None,
    solver: str = "auto",
    warm_duals: Duals | None = None,
    abort_turn: cg.BodyMotion | None = None,
) -> ConstrainedPlan:
    """The constrained cone program from ``x0`` to ``xf`` over ``horizon_s`` (module docstring).

    The first iterate is ``warm_controls`` (an earlier plan's remaining controls,
    N × 3) or the unconstrained plan of :func:`.convex.plan_controls`.
    ``p_pos_km2``: the filter's position covariance (3 × 3), for
    ``sigma_margin``. ``abort_safe_s``: the drift time T of abort safety (None:
    off; it needs a keep-out zone). ``reduce=False`` solves every SCP iteration's whole
    program, every row written (the reference the reductions are tested
    against; module docstring, *Reductions*). ``motion`` (a tumbling target,
    issue 34): the predicted turn of the body frame at the N + 1 nodes, in which
    ``geo`` is given; ``xf`` is then the port's predicted state at the horizon's end.
    ``solver``: ``"auto"`` tries the dual solver of :mod:`.path_dual` on every program
    (below :data:`.convex.DUAL_MIN_WEIGHT` by its homotopy in the weight), Clarabel
    whenever the dual answer is not certified; ``"clarabel"`` Clarabel always
    (module docstring, *Solvers*). ``warm_duals``: the dual solver's starting multipliers,
    an earlier plan's :attr:`ConstrainedPlan.duals` moved to this grid by
    :func:`shift_duals`. ``abort_turn`` (abort safety of a turning target): the predicted
    turn of the body frame at t_0 + pΔt, p = 0 … N + :func:`.abort_safety.turn_steps`, over
    the drifts (:mod:`cwrend_cli.physics.abort_safety`).
    """
    if solver not in ("auto", "clarabel"):
        raise ValueError(f"solver must be 'auto' or 'clarabel', not {solver!r}")
    start = time.perf_counter()
    steps = max(1, round(horizon_s / dt_s))
    x0 = np.asarray(x0, dtype=np.float64)
    xf = np.asarray(xf, dtype=np.float64)
    used = 0
    sizes = [float(axes.max()) for _, axes in cg.ellipsoids(geo)]
    trust = TRUST_RADIUS_FACTOR * (max(sizes) if sizes else 1.0)
    warm = warm_controls is not None and warm_controls.shape == (steps, 3)
    exists = True  # whether the first iterate, when unconstrained, has a plan
    if not warm:
        exists, warm_controls, used = _unconstrained_plan(
            n, dt_s, u_max_km_s2, x0, xf, horizon_s, eps
        )
    assert warm_controls is not None
    x_bar, r_bar = node_positions(n, dt_s, x0, warm_controls)
    restarted = warm and out_of_reach(r_bar[-1], xf, trust)
    if restarted:
        # the warm plan ends beyond the trust box's reach of the terminal target: restart from
        # the unconstrained plan, which reaches it (module docstring, *A moved target*)
        exists, warm_controls, used = _unconstrained_plan(
            n, dt_s, u_max_km_s2, x0, xf, horizon_s, eps
        )
        x_bar, r_bar = node_positions(n, dt_s, x0, warm_controls)
        warm_duals = None
    u_bar = warm_controls
    modes = _modes(geo, r_bar, motion)
    if not modes.any():  # nothing is unsafe: the unconstrained plan
        if warm and not restarted:  # a one-step horizon: no node to constrain, still re-plan
            exists, warm_controls, used = _unconstrained_plan(
                n, dt_s, u_max_km_s2, x0, xf, horizon_s, eps
            )
            r_bar = node_positions(n, dt_s, x0, warm_controls)[1]
        return ConstrainedPlan(
            SolveStatus.CONVERGED if exists else SolveStatus.FAILED,
            warm_controls,
            r_bar,
            modes,
            0.0,
            0,
            used,
            time.perf_counter() - start,
            restarted=restarted,
        )
    result: ConstrainedPlan | None = None
    cost, last_slack = math.inf, math.inf
    fallbacks = 0
    drift = None
    if abort_safe_s is not None:
        if motion is not None and abort_turn is None:
            raise ValueError("abort safety of a turning target needs abort_turn")
        drift = ab.planner_drift(n, abort_safe_s, geo, dt_s, abort_turn)
    scp, cap = 0, SCP_MAX_ITER
    while scp < cap:
        scp += 1
        margins = _node_margins(
            _step_margins(n, dt_s, u_max_km_s2, x_bar, trust, ACCEL_FACTOR, motion)
        )
        half_spaces = _half_spaces(geo, modes, r_bar, margins, p_pos_km2, sigma_margin, motion)
        cone_margins = _cone_margins(geo, margins, motion)
        chords, axes = None, geo.semi_axes_km
        if drift is not None and axes is not None:
            nodes = np.flatnonzero((modes == _KEEP_OUT) & ~ab.exempt(geo, r_bar, motion))
            chords = ab.chords_near(geo, n, drift, x_bar, nodes, trust, ACCEL_FACTOR)
        # one radius with abort safety (its drift chords are sized by it) and for a turning
        # body (not yet measured with far radii: docs/solvers.md)
        if drift is None and motion is None:
            radii = trust_radii(modes, r_bar, half_spaces, trust)
        else:
            radii = np.full(steps + 1, trust)
        for _ in range(ABORT_ROUNDS):
            rows = None
            if chords is not None and drift is not None and axes is not None:
                rows = ab.rows_for(geo, drift, chords)
            sub = _Subproblem(
                n, dt_s, u_max_km_s2, x0, xf, eps, geo, modes, r_bar, u_bar, cone_margins,
                half_spaces, radii, motion, rows, solver == "auto", warm_duals,
            )  # fmt: skip
            sol, iterations, answer, fell_back = _reduced_solve(sub, reduce)
            used += iterations
            fallbacks += fell_back
            warm_duals = sol.duals if isinstance(sol, _DualSolution) else None
            if rows is None or answer is None:
                break
            assert chords is not None and drift is not None and axes is not None
            x_sol = answer[1]
            needed = np.flatnonzero((modes == _KEEP_OUT) & ~ab.exempt(geo, x_sol[:, :3], motion))
            chords = ab.widen(geo, n, drift, chords, x_sol, needed, ACCEL_FACTOR)
            if chords is None:
                break
        if answer is None and scp == 1 and warm and not restarted:
            # the warm start's trust box blocked the first program (its only rows without a
            # slack are the dynamics, thrust, terminal and trust rows): restart from the
            # unconstrained plan when there is one (module docstring, *A moved target*)
            exists, controls, iterations = _unconstrained_plan(
                n, dt_s, u_max_km_s2, x0, xf, horizon_s, eps
            )
            used += iterations
            if exists:
                x_bar, r_bar = node_positions(n, dt_s, x0, controls)
                u_bar, modes, warm_duals = controls, _modes(geo, r_bar, motion), None
                restarted, cap = True, cap + 1  # the blocked program is not an SCP iterate
                continue
        if answer is None:
            status = (
                SolveStatus.INFEASIBLE if sol.status in convex._INFEASIBLE else SolveStatus.FAILED
            )
            return ConstrainedPlan(
                status,
                np.zeros((steps, 3)),
                np.full((steps + 1, 3), np.nan),
                modes,
                math.nan,
                scp,
                used,
                time.perf_counter() - start,
                fallbacks=fallbacks,
                restarted=restarted,
            )
        u, x_new, slack = answer
        slack = slack if slack > SLACK_TOL_KM else 0.0  # below: the solver's own tolerance
        moved = _largest_move(x_new, r_bar)
        new_modes = _modes(geo, x_new[:, :3], motion)
        # each step's own bound within what both its nodes' constraints were tightened by
        bound_ok = _within_margins(
            _step_margins(n, dt_s, u_max_km_s2, x_new, 0.0, 1.0, motion), margins
        )
        bound_ok = bound_ok and chords is None  # every abort chord covered (or abort off)
        abort_slack = float(sol.x[-1]) if drift is not None else 0.0
        result = ConstrainedPlan(
            SolveStatus.CONVERGED if bound_ok else SolveStatus.FAILED,
            u,
            x_new[:, :3],
            modes,
            slack,
            scp,
            used,
            time.perf_counter() - start,
            abort_slack if abort_slack > SLACK_TOL_KM else 0.0,
            fallbacks,
            warm_duals,
            restarted,
        )
        x_bar, r_bar, u_bar = x_new, x_new[:, :3], u
        settled = moved <= SCP_TOL_KM or cost - float(sol.obj_val) <= SCP_COST_RTOL * abs(cost)
        cost = float(sol.obj_val)
        settled = settled and result.abort_slack_km == 0.0
        # a turning body's slack that the iterates no longer change is the linearised set's
        # own: more iterations would not remove it (module docstring, Iterations)
        slack_settled = slack == 0.0 or (
            motion is not None and abs(slack - last_slack) <= SCP_TOL_KM
        )
        last_slack = slack
        if settled and slack_settled and _same_modes(new_modes, modes) and bound_ok:
            break
        modes = new_modes
    assert result is not None  # every SCP iteration sets it, returns or restarts
    return result
