"""Abort (passive) safety: the free drift from a node stays outside the keep-out zone.

Issue 34 item 4. If the thrusters stop at node k of a plan, the chaser drifts
freely from the node's state x_k: ``x(t) = Φ(t) x_k`` with Φ the design
model's state-transition matrix (CW today, paper Eq. 11, the transition the
constrained cone program uses; :func:`cwrend_cli.physics.dynamics.stm`). The
node is *abort-safe* for a time T when its drift stays outside the keep-out
ellipsoid E for t ∈ [0, T] (the zone, not the unsafe set: a drift is checked
against the whole zone, corridor or not).

**Samples and chords.** The drift is sampled every h = :data:`ABORT_SAMPLE_S`
(``t_j = j h``, j = 0 … M, M = ⌈T/h⌉, so t_M ≥ T); chord j joins samples j
and j + 1. Free drift is the zero-order-hold arc of paper Eq. 1 with u = 0, so
the bound of :func:`~cwrend_cli.physics.constraints.acceleration_bound` holds
over the chord from the state at its first sample (with u_max = 0):
``A_j = (3n²(‖r_j‖ + ‖v_j‖h) + 2n‖v_j‖) / (1 − 3n²h² − 2nh)``. A chord is
*covered* (its arc provably outside E) when either

* (a) its first sample is farther from E than the arc can travel in h:
  ``d_E(r_j) ≥ ‖v_j‖h + ½A_j h²`` (the arc stays in that ball; d_E from
  below by ``a_min(√g − 1)``, g the ellipsoid's level); or
* (b) both samples lie in a half-space that supports E tightened by δ ≥
  A_j h²/8 (the arc stays within A_j h²/8 of the chord, the chord in the
  half-space by convexity: the argument of
  :func:`~cwrend_cli.physics.constraints.chord_margin_km`).

On the paper's orbit (n = 1.04e-3 rad/s) with h = 10 s, a drift at 50 m/s a
kilometre from the target has A ≈ 1.1e-4 km/s², so δ ≈ 1.4 m; the margin is
what the sampling costs, and M = 540 samples cover T = 5,400 s.

**Inside the cone program** (Botelho 2019 style: linear constraints on the
node states) a chord j of node k gets the rows ``nᵀ C Φ(t_j) x_k ≥ o`` and
``nᵀ C Φ(t_j+1) x_k ≥ o`` (C picks the position) of one half-space (n, o)
tangent to E at a surface point from the previous iterate's drift
(:func:`tangent_points`), o raised by δ: (b) holds for every iterate whose
own A_j h²/8 ≤ δ, an inner approximation like the keep-out rows. Only the
chords that the previous iterate has near E get rows (:func:`chord_set`,
within the ball of (a) plus a buffer); the others are checked on the answer
(:func:`widened`) and any that is not covered by (a) or (b) gets its rows and
the subproblem is solved again, so every returned plan has every chord of
every constrained node covered by (a) or (b), not only those given rows.

**On the truth** (:func:`measure_abort`): the true state of every step,
drifted by CW's Φ (for a CW truth the truth's own free drift; for a nonlinear
truth CW's prediction of it from the true state) over T, chords found by the
bounds above, those that can come near E re-sampled every
h/:data:`MEASURE_SUBSAMPLES`; the sampled minimum of the signed distance is at
most ``‖v‖h/(2·MEASURE_SUBSAMPLES)`` above the continuous one.

**Exemption.** The nodes of the final approach cannot be abort-safe against a
zone that holds the port's neighbourhood (a drift from near the port, even at
rest, passes through it: the cross-track motion oscillates through 0), and
neither can the nodes that slide along the zone's surface to a port on it.
The rule (:func:`exempt`): exempt are the nodes inside the corridor at the end
(the last contiguous stretch inside the cone, up to the terminal node: the cone
program's corridor nodes, :func:`final_approach_start`) and every node within
:data:`EXEMPT_RADIUS_FACTOR` × the largest semi-axis of the plan's last node
(the port, or x_f without a corridor); every other node is constrained and
measured. Node 0 of a plan (the state it starts from) is given, not planned:
the cone program cannot constrain it, the truth's measure counts it.

**Several bodies, a turning target** (:class:`BodyDrift`). The zone is the
union of ellipsoids E_b (centre c_b, semi-axes a_b) given in the target's body
frame, which turns as ``r = R(t) ρ`` (for a fixed target R = I); the drift from
node k (time t_k) must stay outside every E_b at its attitude at t_k + s,
s ∈ [0, T]: ``R(t_k + s)ᵀ Φ(s) x_k ∉ E_b``. Two levels of chords:

* (s) **coarse chords** of h_c (:data:`ABORT_SAMPLE_S` fixed; for a turning
  target r Δt, the whole multiple of the plan step nearest it,
  :func:`turning_samples`, so that every sample falls on the grid of the
  predicted attitude): covered at any attitude when the arc stays outside the
  sphere of radius R_b (:func:`enclosing_radius_km`) that holds every body at
  any attitude, test (a) above in the Hill frame against that sphere (its
  distance ‖r‖ − R_b is exact); and
* **fine chords** of h_f = h_c / per (the planner: Δt for a turning target, h_c
  for a fixed one; the truth's measure: :data:`MEASURE_SUBSAMPLES` re-samples of
  each coarse chord) of the coarse chords that (s) does not clear, tested per
  body in the body frame at each sample's own time: (a) with the body-frame
  reach ``(‖v‖ + ‖Ω‖‖r‖) h_f + ½ B h_f²`` (the body-frame speed
  ‖Rᵀ(v − Ω × r)‖ ≤ ‖v‖ + ‖Ω‖‖r‖), or (b) both samples in a half-space
  tangent to E_b raised by δ ≥ B h_f²/8. B is the body-frame acceleration bound
  of :func:`~cwrend_cli.physics.constraints.body_acceleration_bound` (the
  between-node margin of a turning set, derived there: the fixed drift bound
  A_j plus the rotation's ``(‖Ω̇‖ + ‖Ω‖²) R + 2‖Ω‖V``), from the Hill state at
  the chord's first sample; for a fixed target ‖Ω‖ = 0 and B = A_j. The
  body-frame arc stays within B h_f²/8 of its body-frame chord, so (b) keeps it
  outside E_b (the argument of the node chords, in the body frame).

Why Δt for the planner's fine chords of a turning target: B grows with the
distance (the spin term) and with the drift's speed (2‖Ω‖V): near the
shipped target (0.3 km out at 40 m/s, 2.8 °/s reachable) B h²/8 is 96 m at
h = 10 s and 0.72 m at h = 1 s (B = 7.7e-3 and 5.8e-3 km/s²). The coarse
sphere test keeps the count down: a drift leaves the target's neighbourhood
fast, and only its chords within R_b plus their reach are sampled finely.

Rows of fine chord i of coarse chord j of node k and body b: ``(R_p n)ᵀ C
Φ(i h_f) Φ(j h_c) x_k ≥ o + nᵀc_b + δ`` at both its samples, p the sample's row
of the predicted turn (t_0 + p h_f; :func:`body_rows`); one row per body that
needs it. The coarse chords that (s) leaves short of the trust radius are
sampled finely, and a body's fine chords get rows when the previous iterate
leaves them less than :data:`BODY_BUFFER` × the trust radius of room; each
answer is checked and widened as above (:func:`body_widened`). The attitude
over the drifts is the guidance's own prediction (every Δt from the attitude
known at the re-solve, beyond the plan's horizon by :func:`turn_steps`); the
truth's measure uses the truth's (its torque-free motion propagated past the
run's end), re-sampled every
h_f = Δt/:func:`turn_stride` (0.1 s at Δt = 1 s), where the sampled minimum is
at most ``(‖v‖ + ‖Ω‖‖r‖) h_f/2`` above the continuous one.

**Exemption of a turning target.** The same rule, in the body frame: the final
approach is the last contiguous stretch of nodes inside the corridor turned to
each node's own time (``R_kᵀ r_k`` in the cone: the nodes the cone program holds
in the turning corridor), and the exempt neighbourhood is that of the plan's
last node in the body frame (``‖R_kᵀ r_k − R_Nᵀ r_N‖`` ≤ the zone's largest
semi-axis over its bodies): near the moving port, where it is at each node's
time. For a fixed target it is the rule above (R = I).

One ellipsoid standing still keeps the functions above (:func:`chord_set`,
:func:`widened`, :func:`rows_of`), whose plans are pinned bit for bit;
:func:`planner_drift`, :func:`chords_near`, :func:`widen`, :func:`rows_for`
choose.

Units: km, s, km/s.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.dynamics import stm
from cwrend_cli.physics.params import FloatArray

#: A boolean array (chords with rows, uncovered chords).
BoolArray = npt.NDArray[np.bool_]

__all__ = [
    "ABORT_SAMPLE_S",
    "MEASURE_SUBSAMPLES",
    "AbortRows",
    "AbortSafety",
    "ChordSet",
    "DriftTable",
    "chord_accelerations",
    "chord_set",
    "drift_table",
    "exempt",
    "final_approach_start",
    "half_space_rows",
    "measure_abort",
    "rows_of",
    "tangent_points",
    "widened",
]

#: Drift sample interval h [s] (module docstring: the margin it costs is A h²/8).
ABORT_SAMPLE_S = 10.0
#: Re-samples per chord of a true drift that may come near the zone [-] (h/100 = 0.1 s).
MEASURE_SUBSAMPLES = 100
#: Drift samples computed at once (a chunk of nodes × M + 1) [-]: bounds the memory.
_CHUNK = 1 << 18
#: Corridor membership tolerance of the final approach [km] (the SCP's, 1 mm).
_CORRIDOR_TOL_KM = 1e-6
#: Radius of the exempt neighbourhood of the end of a plan, a multiple of the keep-out
#: zone's largest semi-axis [-] (module docstring, Exemption).
EXEMPT_RADIUS_FACTOR = 1.0


class DriftTable(NamedTuple):
    """Φ(t_j) of the drift samples t_j = j h, j = 0 … M (module docstring)."""

    h_s: float  # sample interval h [s]
    time_s: float  # abort-safety time T [s]; t_M ≥ T
    phis: FloatArray  # (M + 1, 6, 6) [-, s, 1/s]


@functools.lru_cache(maxsize=8)
def _phis(n_rad_s: float, h_s: float, count: int) -> FloatArray:
    out = np.array([stm(n_rad_s, j * h_s) for j in range(count + 1)])
    out.flags.writeable = False
    return out


def drift_table(n_rad_s: float, time_s: float, h_s: float = ABORT_SAMPLE_S) -> DriftTable:
    """The CW drift samples covering [0, ``time_s``] every ``h_s`` (paper Eq. 11's Φ)."""
    count = max(1, math.ceil(time_s / h_s - 1e-9))
    return DriftTable(h_s, time_s, _phis(n_rad_s, h_s, count))


def _chunks(table: DriftTable, x: FloatArray) -> Iterator[tuple[slice, FloatArray]]:
    """(node slice, drift states (K, M + 1, 6)) of the nodes ``x`` (K, 6), a chunk at a time."""
    per = max(1, _CHUNK // table.phis.shape[0])
    for start in range(0, x.shape[0], per):
        part = slice(start, min(start + per, x.shape[0]))
        # x Φ(t_j)ᵀ for every j at once: one matrix product (K, 6) × (6, (M + 1) 6)
        stacked = table.phis.transpose(2, 0, 1).reshape(6, -1)
        yield part, (x[part] @ stacked).reshape(-1, table.phis.shape[0], 6)


def chord_accelerations(n_rad_s: float, h_s: float, d: FloatArray) -> FloatArray:
    """A_j of every chord (..., M) from the drift states ``d`` (..., M + 1, 6) [km/s²].

    :func:`~cwrend_cli.physics.constraints.acceleration_bound` with u_max = 0,
    which is linear in ‖r_j‖ and ‖v_j‖ (its coefficients are taken from it).
    """
    per_r = cg.acceleration_bound(1.0, 0.0, 0.0, n_rad_s, h_s)
    per_v = cg.acceleration_bound(0.0, 1.0, 0.0, n_rad_s, h_s)
    r = np.linalg.norm(d[..., :-1, :3], axis=-1)
    v = np.linalg.norm(d[..., :-1, 3:], axis=-1)
    return np.asarray(per_r * r + per_v * v, dtype=np.float64)


def _ball_test(
    semi_axes_km: FloatArray, n_rad_s: float, h_s: float, d: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(room, A): ``d_E`` from below minus the chord's reach ``‖v‖h + ½Ah²`` (≥ 0: covered
    by (a)), and A_j, of every chord (K, M) of the drift states ``d`` (K, M + 1, 6)."""
    accel = chord_accelerations(n_rad_s, h_s, d)
    # d_E ≥ a_min (√g − 1) outside E (constraints._ellipsoid_distance_bounds); inside it is
    # negative, so a chord that starts inside is never covered by (a), as it must not be
    q = np.sqrt(cg.ellipsoid_level(d[:, :-1, :3], semi_axes_km))
    low = float(np.min(semi_axes_km)) * (q - 1.0)
    # the reach of a step, constraints.step_excursion_km, elementwise
    reach = np.linalg.norm(d[:, :-1, 3:], axis=-1) * h_s + 0.5 * accel * h_s**2
    return low - reach, accel


def _scan(
    semi_axes_km: FloatArray, n_rad_s: float, table: DriftTable, x: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(room, A) of every chord (K, M) of the drifts from ``x`` (K, 6) (:func:`_ball_test`)."""
    room = np.empty((x.shape[0], table.phis.shape[0] - 1))
    accel = np.empty_like(room)
    for part, d in _chunks(table, x):
        room[part], accel[part] = _ball_test(semi_axes_km, n_rad_s, table.h_s, d)
    return room, accel


def tangent_points(
    semi_axes_km: FloatArray, table: DriftTable, x: FloatArray, chords: BoolArray
) -> FloatArray:
    """Surface points (K, M, 3) of E whose tangent planes bound the ``chords`` (K, M) of
    ``x``'s drifts (zero for the other chords).

    The first sample of a chord projected radially onto the surface (r/√g);
    inside E, moved first by the largest semi-axis towards a side of the
    drift (the component of its deepest sample across its velocity there, as
    the keep-out rows of :mod:`.guidance.constrained` do for a path), so that
    every sample of a drift that crosses E goes round it on one side.
    """
    a = np.asarray(semi_axes_km, dtype=np.float64)
    out = np.zeros((x.shape[0], table.phis.shape[0] - 1, 3))
    some = np.flatnonzero(np.any(chords, axis=1))
    for part, d in _chunks(table, x[some]):
        r = d[:, :-1, :3]
        level = cg.ellipsoid_level(r, a)
        deep = np.argmin(level, axis=1)
        at = d[np.arange(d.shape[0]), deep]
        side = _sides(at[:, :3], at[:, 3:], float(np.max(a)))
        out[some[part]] = _surface_points(r, level, a, side[:, None, :])
    return out


def _sides(at_km: FloatArray, direction: FloatArray, size_km: float) -> FloatArray:
    """Unit vectors (K, 3) across the ``direction``s (K, 3) towards the points ``at_km``
    (K, 3): the side on which a drift goes round a body (:func:`tangent_points`); a point on
    its direction's line (within 1e-9 ``size_km``) gets the axis least aligned with it."""
    vel = direction / np.maximum(np.linalg.norm(direction, axis=1), 1e-300)[:, None]
    side = at_km - np.sum(at_km * vel, axis=1)[:, None] * vel
    size = np.linalg.norm(side, axis=1)
    flat = size <= 1e-9 * size_km
    if np.any(flat):  # through the centre: the axis least aligned with the velocity
        axis = np.eye(3)[np.argmin(np.abs(vel[flat]), axis=1)]
        side[flat] = axis - np.sum(axis * vel[flat], axis=1)[:, None] * vel[flat]
        size[flat] = np.linalg.norm(side[flat], axis=1)
    side /= size[:, None]
    return np.asarray(side, dtype=np.float64)


def _surface_points(
    r_km: FloatArray, level: FloatArray, semi_axes_km: FloatArray, side: FloatArray
) -> FloatArray:
    """The points ``r_km`` (..., 3) of ``level`` (...) projected radially onto the ellipsoid's
    surface, those inside moved first by the largest semi-axis along ``side`` (broadcast)."""
    moved = np.where((level < 1.0)[..., None], r_km + float(np.max(semi_axes_km)) * side, r_km)
    return np.asarray(
        moved / np.sqrt(cg.ellipsoid_level(moved, semi_axes_km))[..., None], dtype=np.float64
    )


class AbortRows(NamedTuple):
    """Rows ``coeffs[i] · x_nodes[i] ≥ offsets_km[i]`` on node states (one per chord end)."""

    nodes: np.ndarray  # (R,) node indices of the plan [-]
    coeffs: FloatArray  # (R, 6) [-, s]
    offsets_km: FloatArray  # (R,) [km]


def half_space_rows(
    semi_axes_km: FloatArray,
    table: DriftTable,
    nodes: np.ndarray,
    chords: BoolArray,
    points: FloatArray,
    margin_km: float,
) -> AbortRows:
    """The rows of the ``chords`` (K, M) of ``nodes`` (K,): both ends of chord j of node k in
    the half-space tangent to E at ``points[k, j]`` raised by ``margin_km``
    (:func:`~cwrend_cli.physics.constraints.tangent_planes`, raised by the margin)."""
    k, j = np.nonzero(chords)
    normal, offset = cg.tangent_planes(semi_axes_km, points[k, j])
    offset = offset + margin_km
    # nᵀ C Φ(t) x_k for the chord's two samples t_j, t_j+1
    first = np.einsum("ra,rab->rb", normal, table.phis[j, :3, :])
    second = np.einsum("ra,rab->rb", normal, table.phis[j + 1, :3, :])
    return AbortRows(
        np.concatenate([nodes[k], nodes[k]]),
        np.concatenate([first, second]),
        np.concatenate([offset, offset]),
    )


class ChordSet(NamedTuple):
    """The chords of one SCP iteration that carry rows, and where they are linearised."""

    nodes: np.ndarray  # (K,) the constrained nodes of the plan [-]
    chords: BoolArray  # (K, M): the chord has rows
    points: FloatArray  # (K, M, 3) surface points of their half-spaces [km]
    margin_km: float  # δ, the half-spaces' tightening [km]


def chord_set(
    semi_axes_km: FloatArray,
    n_rad_s: float,
    table: DriftTable,
    x_bar: FloatArray,
    nodes: np.ndarray,
    buffer_km: float,
    accel_factor: float,
) -> ChordSet:
    """The chords of ``nodes`` that the previous iterate ``x_bar`` (N + 1, 6) has near E
    (the ball test (a) short of ``buffer_km``), linearised there, δ = ``accel_factor`` ×
    their largest A h²/8."""
    x = x_bar[nodes]
    room, accel = _scan(semi_axes_km, n_rad_s, table, x)
    chords = room < buffer_km
    points = tangent_points(semi_axes_km, table, x, chords)
    margin = cg.chord_margin_km(accel_factor * float(np.max(accel[chords], initial=0.0)), table.h_s)
    return ChordSet(nodes, chords, points, margin)


def widened(
    semi_axes_km: FloatArray,
    n_rad_s: float,
    table: DriftTable,
    cs: ChordSet,
    x_new: FloatArray,
    nodes: np.ndarray,
    accel_factor: float,
) -> ChordSet | None:
    """``cs`` with the chords that the answer ``x_new`` leaves uncovered (neither (a) nor,
    with rows, (b): module docstring) given rows linearised at ``x_new``'s drift, and δ
    raised to cover them; None when every chord is covered.

    ``nodes``: those the answer needs constrained (the rule applied to its own
    positions); any not in ``cs`` joins it, its chords checked like the others.
    """
    every = np.union1d(cs.nodes, nodes).astype(np.int64)
    at = np.searchsorted(every, cs.nodes)
    chords = np.zeros((every.size, cs.chords.shape[1]), dtype=bool)
    chords[at] = cs.chords
    points = np.zeros((every.size, *cs.points.shape[1:]))
    points[at] = cs.points
    x = x_new[every]
    room, accel = _scan(semi_axes_km, n_rad_s, table, x)
    by_rows = chords & (cg.chord_margin_km(1.0, table.h_s) * accel <= cs.margin_km)
    missing = (room < 0.0) & ~by_rows
    if not np.any(missing):
        return None
    points[missing] = tangent_points(semi_axes_km, table, x, missing)[missing]
    chords |= missing
    largest = accel_factor * float(np.max(accel[chords], initial=0.0))
    return ChordSet(
        every, chords, points, max(cs.margin_km, cg.chord_margin_km(largest, table.h_s))
    )


def rows_of(semi_axes_km: FloatArray, table: DriftTable, cs: ChordSet) -> AbortRows:
    """The rows of the chord set ``cs`` (:func:`half_space_rows`)."""
    return half_space_rows(semi_axes_km, table, cs.nodes, cs.chords, cs.points, cs.margin_km)


def exempt(geo: cg.Geometry, r_km: FloatArray, motion: cg.BodyMotion | None = None) -> BoolArray:
    """The exempt nodes (N + 1,) of positions ``r_km`` (N + 1, 3) (module docstring):
    the final approach in the corridor (:func:`final_approach_start`) and every node
    within :data:`EXEMPT_RADIUS_FACTOR` × the zone's largest semi-axis (over its bodies) of
    the last node. ``motion`` (a turning target, its turn at the N + 1 nodes): both in the
    body frame, each node at its own time."""
    rho = cg.to_body(motion, r_km)
    radius = EXEMPT_RADIUS_FACTOR * max(float(np.max(axes)) for _, axes in cg.ellipsoids(geo))
    out: BoolArray = np.linalg.norm(rho - rho[-1], axis=1) <= radius
    out[final_approach_start(geo, rho) :] = True
    return out


def final_approach_start(geo: cg.Geometry, r_km: FloatArray) -> int:
    """The first node of the exempt final approach of positions ``r_km`` (N + 1, 3) (in the
    body frame, each at its node's time, for a turning target).

    The terminal node and, with a corridor, the contiguous stretch of nodes
    before it inside the corridor cone (to 1 mm): module docstring. N without
    a corridor.
    """
    if geo.port_km is None:
        return int(r_km.shape[0]) - 1
    inside = cg.corridor_cone(geo, 0.0).residual_km(r_km) >= -_CORRIDOR_TOL_KM
    return cg.approach_start(inside, 0)


@dataclass(frozen=True)
class AbortSafety:
    """The abort safety of a flown trajectory (:func:`measure_abort`)."""

    time_s: float  # T, the drift time checked [s]
    min_distance_km: float  # min over checked steps and their drifts of d_E [km]; < 0: entered E
    unsafe_steps: int  # checked steps whose drift enters E within T [-]
    checked_steps: int  # steps before the exempt final approach [-]

    @property
    def unsafe(self) -> bool:
        """Some checked step's drift enters the keep-out zone within T."""
        return self.unsafe_steps > 0


def measure_abort(
    x: FloatArray,
    n_rad_s: float,
    geo: cg.Geometry,
    time_s: float,
    h_s: float = ABORT_SAMPLE_S,
    subsamples: int = MEASURE_SUBSAMPLES,
    turn: cg.BodyMotion | None = None,
    dt_s: float = 0.0,
) -> AbortSafety:
    """The :class:`AbortSafety` of the trajectory ``x`` (N + 1, 6) [km, km/s] (module docstring).

    Every step before the final approach (:func:`final_approach_start`) drifts
    freely by CW for ``time_s``; chords whose ball test (a) leaves room below
    0 (may enter E) or below the best upper bound of the distance (may hold the
    minimum) are re-sampled every h/``subsamples``, where the distance is
    computed (exactly where its bounds allow it to be the minimum).

    Several bodies or a turning target (``turn``: its attitude at t = p·Δt/stride,
    p = 0 … (N + :func:`turn_steps`)·stride, stride = :func:`turn_stride` of ``dt_s``, the
    grid step, and ``subsamples``): :func:`_measure_bodies` (module docstring).
    """
    assert geo.semi_axes_km is not None
    a = geo.semi_axes_km
    x = np.asarray(x, dtype=np.float64)
    if turn is not None and dt_s <= 0.0:
        raise ValueError("a turning target's abort measure needs the grid step dt_s > 0")
    if turn is not None or geo.bodies_centre_km is not None:
        drift = body_drift(n_rad_s, time_s, geo, dt_s, turn, subsamples)
        motion = None
        if turn is not None:  # the turn at the steps, for the exemption
            motion = turn._replace(rotation=turn.rotation[:: drift.stride][: x.shape[0]])
        steps = np.flatnonzero(~exempt(geo, x[:, :3], motion))
        if steps.size == 0:
            return AbortSafety(time_s, math.inf, 0, 0)
        return _measure_bodies(x, steps, geo, drift, time_s)
    steps = np.flatnonzero(~exempt(geo, x[:, :3]))
    if steps.size == 0:
        return AbortSafety(time_s, math.inf, 0, 0)
    table = drift_table(n_rad_s, time_s, h_s)
    rooms = np.empty((steps.size, table.phis.shape[0] - 1))
    best = math.inf  # the smallest upper bound of d_E over the samples
    for part, d in _chunks(table, x[steps]):
        rooms[part], _ = _ball_test(a, n_rad_s, h_s, d)
        best = min(best, float(np.min(cg._ellipsoid_distance_bounds(d[:, :-1, :3], a)[1])))
    k, j = np.nonzero((rooms < 0.0) | (rooms <= best))
    fine = np.array([stm(n_rad_s, i * h_s / subsamples) for i in range(subsamples + 1)])
    keep_out = cg.Geometry(a, None, None, None)
    unsafe = np.zeros(steps.size, dtype=bool)
    lowest = best
    per = max(1, _CHUNK // (subsamples + 1))
    for start in range(0, k.size, per):
        kk, jj = k[start : start + per], j[start : start + per]
        starts = np.einsum("rab,rb->ra", table.phis[jj], x[steps[kk]])
        points = np.einsum("iab,rb->ria", fine[:, :3, :], starts)
        inside = np.any(cg.ellipsoid_level(points, a) < 1.0, axis=1)
        unsafe[kk[inside]] = True
        lowest = min(lowest, cg._min_signed_distance(points.reshape(-1, 3), keep_out, None))
    return AbortSafety(time_s, lowest, int(np.count_nonzero(unsafe)), int(steps.size))


# ---------------------------------------------------------------------------
# Several bodies, a turning target (module docstring, *Several bodies, a turning target*)
# ---------------------------------------------------------------------------

#: The buffer of a body's fine chords, a fraction of the coarse chords' (the trust radius)
#: [-]: their rows are many (a chord a plan step), so only those the previous iterate has
#: within a fifth of it get rows at first, the widening adding any the answer needs. On
#: the first re-solve of campaigns/tumbling_target.toml, 2,893 chords instead of 40,026.
BODY_BUFFER = 0.2
#: An integer array (node indices, chord keys).
IntArray = npt.NDArray[np.int64]


class BodyDrift(NamedTuple):
    """The drift samples against a zone of several bodies, or a turning one: coarse chords
    of ``coarse.h_s`` for the enclosing-sphere test, each split into ``per`` fine chords of
    h_f = ``coarse.h_s / per`` for the body tests (module docstring)."""

    n_rad_s: float  # mean motion [rad/s]
    coarse: DriftTable  # Φ(j h_c), j = 0 … M
    fine: FloatArray  # (per + 1, 6, 6) Φ(i h_f), i = 0 … per [-, s, 1/s]
    per: int  # fine chords per coarse chord [-]
    #: (P, 3, 3) body→Hill at t_0 + p h_f, P > N·stride + M·per; None: fixed (Hill axes)
    rotation: FloatArray | None
    stride: int  # fine samples per plan step: node k's drift starts at row k·stride [-]
    rate_bound_rad_s: float  # ≥ ‖Ω‖ (0 fixed) [rad/s]
    rate_dot_bound_rad_s2: float  # ≥ ‖Ω̇‖ (0 fixed) [rad/s²]
    radius_km: float  # R_b: every body lies within it of the centre, at any attitude [km]

    @property
    def h_fine_s(self) -> float:
        """h_f, the fine chords' length [s]."""
        return self.coarse.h_s / self.per


def turning_samples(dt_s: float) -> int:
    """r: plan steps Δt per coarse chord of a turning target's drift, the whole multiple of
    Δt nearest :data:`ABORT_SAMPLE_S` (at least 1) [-]: every drift sample then falls on a
    time t_0 + p·Δt (p whole) of the predicted attitude."""
    return max(1, round(ABORT_SAMPLE_S / dt_s))


def turn_steps(time_s: float, dt_s: float) -> int:
    """The plan steps Δt after a node that its drift's last sample reaches: M·r (M the coarse
    chords covering ``time_s``, r = :func:`turning_samples`) [-]. The attitude must be
    known (predicted) that far beyond the plan's last node."""
    r = turning_samples(dt_s)
    return max(1, math.ceil(time_s / (r * dt_s) - 1e-9)) * r


def turn_stride(dt_s: float, resample: int) -> int:
    """Fine samples per plan step of a turning drift re-sampled ``resample`` times a coarse
    chord at least (1: the planner's rows, every Δt; :data:`MEASURE_SUBSAMPLES`: the
    truth's measure) [-]."""
    return max(1, math.ceil(resample / turning_samples(dt_s)))


def enclosing_radius_km(geo: cg.Geometry) -> float:
    """R_b [km]: the radius about the target's centre that holds every body of the zone at
    any attitude, max over the bodies of ‖c‖ + the largest semi-axis."""
    return max(
        (0.0 if c is None else float(np.linalg.norm(c))) + float(np.max(a))
        for c, a in cg.ellipsoids(geo)
    )


def body_drift(
    n_rad_s: float,
    time_s: float,
    geo: cg.Geometry,
    dt_s: float,
    turn: cg.BodyMotion | None = None,
    resample: int = 1,
) -> BodyDrift:
    """The :class:`BodyDrift` of ``geo`` over ``time_s`` (module docstring).

    Fixed (``turn`` None): coarse chords of :data:`ABORT_SAMPLE_S`, each re-sampled
    ``resample`` times. Turning: coarse chords of r Δt (:func:`turning_samples`), fine
    ones of Δt / :func:`turn_stride` (Δt for the planner's ``resample`` = 1), ``turn``'s
    rows the attitude at t_0 + p h_f (at least N·stride + :func:`turn_steps`·stride + 1)
    with its rate bounds.
    """
    if turn is None:
        coarse = drift_table(n_rad_s, time_s)
        per, stride, rotation, rates = resample, 1, None, (0.0, 0.0)
    else:
        r = turning_samples(dt_s)
        stride = turn_stride(dt_s, resample)
        coarse = drift_table(n_rad_s, time_s, r * dt_s)
        per, rotation = r * stride, turn.rotation
        rates = (turn.rate_bound_rad_s, turn.rate_dot_bound_rad_s2)
    fine = _phis(n_rad_s, coarse.h_s / per, per)
    return BodyDrift(n_rad_s, coarse, fine, per, rotation, stride, *rates, enclosing_radius_km(geo))


class _Fine(NamedTuple):
    """The fine samples of the coarse chords near the zone (:func:`_near`)."""

    node: IntArray  # (F,) the node of each coarse chord [-]
    chord: IntArray  # (F,) its coarse index j [-]
    states: FloatArray  # (F, per + 1, 6) Hill states of its fine samples [km, km/s]
    body: FloatArray  # (F, per + 1, 3) their body-frame positions [km]
    accel: FloatArray  # (F, per) body-frame acceleration bound B of each fine chord [km/s²]
    reach: FloatArray  # (F, per) how far a fine chord's body-frame arc gets [km]


def _rows(drift: BodyDrift, node: IntArray, chord: IntArray, fine: IntArray) -> IntArray:
    """Rows of ``drift.rotation`` of node k's fine sample i of coarse chord j."""
    return np.asarray(node * drift.stride + chord * drift.per + fine, dtype=np.int64)


def _near(drift: BodyDrift, x: FloatArray, nodes: IntArray, buffer_km: float) -> _Fine:
    """The fine samples of the coarse chords of ``nodes``' drifts (``x`` (N + 1, 6)) that the
    enclosing-sphere test leaves short of ``buffer_km`` (module docstring, test (s))."""
    sphere = np.full(3, drift.radius_km)
    room, _ = _scan(sphere, drift.n_rad_s, drift.coarse, x[nodes])
    k, j = np.nonzero(room < buffer_km)
    node = nodes[k].astype(np.int64)
    start = np.einsum("fab,fb->fa", drift.coarse.phis[j], x[node])
    states = np.einsum("iab,fb->fia", drift.fine, start)
    r = states[..., :3]
    body = r
    if drift.rotation is not None:  # ρ = Rᵀ r at each sample's own time
        rows = _rows(drift, node[:, None], j[:, None], np.arange(drift.per + 1)[None, :])
        body = np.einsum("fiba,fib->fia", drift.rotation[rows], r)
    h = drift.h_fine_s
    accel = chord_accelerations(drift.n_rad_s, h, states)
    r_norm = np.linalg.norm(r[:, :-1], axis=-1)
    v_norm = np.linalg.norm(states[:, :-1, 3:], axis=-1)
    rate = drift.rate_bound_rad_s
    big = cg.body_acceleration_bound(accel, r_norm, v_norm, rate, drift.rate_dot_bound_rad_s2, h)
    # the body-frame speed ‖Rᵀ(v − Ω × r)‖ ≤ ‖v‖ + ‖Ω‖‖r‖: constraints.step_excursion_km
    reach = cg.step_excursion_km(v_norm + rate * r_norm, big, h)
    return _Fine(node, j.astype(np.int64), states, body, big, reach)


def _candidates(
    geo: cg.Geometry, drift: BodyDrift, fine: _Fine, below_km: float
) -> tuple[IntArray, FloatArray, FloatArray, FloatArray]:
    """The fine chords of ``fine`` whose body test (a) of some body leaves less room than
    ``below_km``, one per (chord, body): (keys (E,) sorted, body-local first samples (E, 3),
    their chord directions (E, 3), B (E,)). A key is ((node·M + j)·per + i)·B_n + b."""
    bodies = cg.ellipsoids(geo)
    count = drift.coarse.phis.shape[0] - 1
    keys, local, direction, accel = [], [], [], []
    for b, (centre, axes) in enumerate(bodies):
        rho = fine.body if centre is None else fine.body - centre
        # d_Eb ≥ a_min (√g − 1): the ball test of the body, in the body frame
        low = float(np.min(axes)) * (np.sqrt(cg.ellipsoid_level(rho[:, :-1], axes)) - 1.0)
        f, i = np.nonzero(low - fine.reach < below_km)
        keys.append(((fine.node[f] * count + fine.chord[f]) * drift.per + i) * len(bodies) + b)
        local.append(rho[f, i])
        direction.append(rho[f, i + 1] - rho[f, i])
        accel.append(fine.accel[f, i])
    key = np.concatenate(keys).astype(np.int64)
    order = np.argsort(key, kind="stable")
    return (
        key[order],
        np.concatenate(local)[order],
        np.concatenate(direction)[order],
        np.concatenate(accel)[order],
    )


def _decode(geo: cg.Geometry, drift: BodyDrift, keys: IntArray) -> tuple[IntArray, ...]:
    """(node, coarse j, fine i, body b) of chord ``keys`` (:func:`_candidates`)."""
    bodies = len(cg.ellipsoids(geo))
    count = drift.coarse.phis.shape[0] - 1
    rest, b = np.divmod(keys, bodies)
    rest, i = np.divmod(rest, drift.per)
    node, j = np.divmod(rest, count)
    return node, j, i, b


def _body_points(
    geo: cg.Geometry, drift: BodyDrift, keys: IntArray, local: FloatArray, direction: FloatArray
) -> FloatArray:
    """Surface points (E, 3) of the chords ``keys``' bodies (body-local), the tangent planes'
    points: as :func:`tangent_points`, each node's drift going round each body on one side,
    that of its deepest fine sample with rows across the body-frame chord there."""
    node, _, _, b = _decode(geo, drift, keys)
    out = np.empty_like(local)
    for body, (_, axes) in enumerate(cg.ellipsoids(geo)):
        sel = np.flatnonzero(b == body)
        if sel.size == 0:
            continue
        level = cg.ellipsoid_level(local[sel], axes)
        order = np.lexsort((level, node[sel]))  # by node, deepest first
        first = np.r_[True, node[sel][order][1:] != node[sel][order][:-1]]
        deep = sel[order[first]]
        side = _sides(local[deep], direction[deep], float(np.max(axes)))
        group = np.searchsorted(node[deep], node[sel])
        out[sel] = _surface_points(local[sel], level, axes, side[group])
    return out


class BodyChords(NamedTuple):
    """The fine chords of one SCP iteration that carry rows (a zone of several bodies, or a
    turning one), one per (chord, body), and where they are linearised."""

    nodes: IntArray  # (K,) the constrained nodes of the plan [-]
    keys: IntArray  # (E,) sorted chord keys (:func:`_candidates`) [-]
    points: FloatArray  # (E, 3) body-local surface points of their half-spaces [km]
    margin_km: float  # δ, the half-spaces' tightening [km]


def body_chord_set(
    geo: cg.Geometry,
    drift: BodyDrift,
    x_bar: FloatArray,
    nodes: IntArray,
    buffer_km: float,
    accel_factor: float,
) -> BodyChords:
    """:func:`chord_set` of a zone of several bodies or a turning one: the fine chords of
    ``nodes`` that the previous iterate ``x_bar`` has near a body (its test (a) short of
    ``buffer_km``), linearised there, δ = ``accel_factor`` × their largest B h_f²/8."""
    fine = _near(drift, x_bar, nodes, buffer_km)
    keys, local, direction, accel = _candidates(geo, drift, fine, BODY_BUFFER * buffer_km)
    points = _body_points(geo, drift, keys, local, direction)
    margin = cg.chord_margin_km(accel_factor * float(np.max(accel, initial=0.0)), drift.h_fine_s)
    return BodyChords(nodes, keys, points, margin)


def body_widened(
    geo: cg.Geometry,
    drift: BodyDrift,
    cs: BodyChords,
    x_new: FloatArray,
    nodes: IntArray,
    accel_factor: float,
) -> BodyChords | None:
    """:func:`widened` of a zone of several bodies or a turning one: ``cs`` with the fine
    chords that the answer ``x_new`` leaves uncovered (neither (a) nor, with rows, (b)) given
    rows linearised at ``x_new``'s drift, δ raised to cover them; None when all are."""
    every = np.union1d(cs.nodes, nodes).astype(np.int64)
    fine = _near(drift, x_new, every, 0.0)
    keys, local, direction, accel = _candidates(geo, drift, fine, 0.0)
    by_rows = np.isin(keys, cs.keys) & (cg.chord_margin_km(1.0, drift.h_fine_s) * accel
                                        <= cs.margin_km)  # fmt: skip
    missing = ~by_rows
    if not np.any(missing):
        return None
    fresh = np.isin(keys, cs.keys, invert=True) & missing
    points = _body_points(geo, drift, keys[fresh], local[fresh], direction[fresh])
    all_keys = np.r_[cs.keys, keys[fresh]]
    order = np.argsort(all_keys, kind="stable")
    largest = accel_factor * float(np.max(accel, initial=0.0))
    return BodyChords(
        every,
        all_keys[order],
        np.vstack([cs.points, points])[order],
        max(cs.margin_km, cg.chord_margin_km(largest, drift.h_fine_s)),
    )


def body_rows(geo: cg.Geometry, drift: BodyDrift, cs: BodyChords) -> AbortRows:
    """The rows of ``cs``: both ends of fine chord i of coarse chord j of node k in body b's
    half-space tangent at its point raised by δ, in the body frame at each end's own time:
    ``(R_p n)ᵀ C Φ(i h_f) Φ(j h_c) x_k ≥ o + nᵀc_b + δ`` (p the end's row of the turn)."""
    node, j, i, b = _decode(geo, drift, cs.keys)
    normal = np.empty((cs.keys.size, 3))
    offset = np.empty(cs.keys.size)
    for body, (centre, axes) in enumerate(cg.ellipsoids(geo)):
        sel = b == body
        normal[sel], offset[sel] = cg.tangent_planes(axes, cs.points[sel])
        if centre is not None:  # nᵀ(ρ − c) ≥ o ⇔ nᵀρ ≥ o + nᵀc
            offset[sel] += normal[sel] @ centre
    offset += cs.margin_km
    ends = []
    for end in (i, i + 1):
        phi = np.einsum("eab,ebc->eac", drift.fine[end, :3, :], drift.coarse.phis[j])
        turned = normal
        if drift.rotation is not None:  # nᵀ ρ = (R n)ᵀ r
            turned = np.einsum("eab,eb->ea", drift.rotation[_rows(drift, node, j, end)], normal)
        ends.append(np.einsum("ea,eab->eb", turned, phi))
    return AbortRows(np.r_[node, node], np.vstack(ends), np.r_[offset, offset])


def _measure_bodies(
    x: FloatArray, steps: IntArray, geo: cg.Geometry, drift: BodyDrift, time_s: float
) -> AbortSafety:
    """:func:`measure_abort` of a zone of several bodies or a turning one (module docstring):
    the coarse chords that the enclosing-sphere test does not clear, or that may hold the
    minimum, re-sampled every h_f; there the exact distance to the union of bodies, in the
    body frame at each sample's own time."""
    count = drift.coarse.phis.shape[0] - 1
    sphere = np.full(3, drift.radius_km)
    rooms = np.empty((steps.size, count))
    best = math.inf  # the smallest upper bound of the distance over the coarse samples
    for part, d in _chunks(drift.coarse, x[steps]):
        rooms[part], _ = _ball_test(sphere, drift.n_rad_s, drift.coarse.h_s, d)
        rho = d[:, :-1, :3]
        if drift.rotation is not None:
            rows = _rows(drift, steps[part, None], np.arange(count)[None, :], np.zeros(1, int))
            rho = np.einsum("kjba,kjb->kja", drift.rotation[rows], rho)
        for centre, axes in cg.ellipsoids(geo):
            local = rho if centre is None else rho - centre
            best = min(best, float(np.min(cg._ellipsoid_distance_bounds(local, axes)[1])))
    near_k, near_j = np.nonzero((rooms < 0.0) | (rooms <= best))
    unsafe = np.zeros(steps.size, dtype=bool)
    lowest = best
    per = max(1, _CHUNK // (drift.per + 1))
    for start in range(0, near_k.size, per):
        kk, jj = near_k[start : start + per], near_j[start : start + per]
        node = steps[kk].astype(np.int64)
        first = np.einsum("fab,fb->fa", drift.coarse.phis[jj], x[node])
        points = np.einsum("iab,fb->fia", drift.fine[:, :3, :], first)
        if drift.rotation is not None:
            rows = _rows(drift, node[:, None], jj[:, None], np.arange(drift.per + 1)[None, :])
            points = np.einsum("fiba,fib->fia", drift.rotation[rows], points)
        unsafe[kk[np.any(cg._inside_keep_out(points, geo), axis=1)]] = True
        flat = points.reshape(-1, 3)
        low = np.full(flat.shape[0], np.inf)
        for centre, axes in cg.ellipsoids(geo):
            local = flat if centre is None else flat - centre
            low = np.minimum(low, cg._ellipsoid_distance_bounds(local, axes)[0])
        maybe = low <= lowest  # only where the bounds allow the minimum: exact there
        if np.any(maybe):
            lowest = min(lowest, float(np.min(cg.keep_out_distance(flat[maybe], geo))))
    return AbortSafety(time_s, lowest, int(np.count_nonzero(unsafe)), int(steps.size))


#: What the planner's drift is: one ellipsoid standing still (:class:`DriftTable`) or
#: several bodies or a turning zone (:class:`BodyDrift`).
Drift = DriftTable | BodyDrift
#: Its chord set.
Chords = ChordSet | BodyChords


def planner_drift(
    n_rad_s: float,
    time_s: float,
    geo: cg.Geometry,
    dt_s: float,
    turn: cg.BodyMotion | None = None,
) -> Drift:
    """The planner's drift samples over ``time_s``: :func:`drift_table` for one ellipsoid
    standing still, else :func:`body_drift` (``turn``: the predicted attitude at
    t_0 + p Δt, p = 0 … N + :func:`turn_steps`)."""
    if turn is None and geo.bodies_centre_km is None:
        return drift_table(n_rad_s, time_s)
    return body_drift(n_rad_s, time_s, geo, dt_s, turn)


def chords_near(
    geo: cg.Geometry,
    n_rad_s: float,
    drift: Drift,
    x_bar: FloatArray,
    nodes: IntArray,
    buffer_km: float,
    accel_factor: float,
) -> Chords:
    """:func:`chord_set` or :func:`body_chord_set`, as ``drift`` is."""
    if isinstance(drift, BodyDrift):
        return body_chord_set(geo, drift, x_bar, nodes, buffer_km, accel_factor)
    assert geo.semi_axes_km is not None
    return chord_set(geo.semi_axes_km, n_rad_s, drift, x_bar, nodes, buffer_km, accel_factor)


def widen(
    geo: cg.Geometry,
    n_rad_s: float,
    drift: Drift,
    cs: Chords,
    x_new: FloatArray,
    nodes: IntArray,
    accel_factor: float,
) -> Chords | None:
    """:func:`widened` or :func:`body_widened`, as ``drift`` is."""
    if isinstance(drift, BodyDrift):
        assert isinstance(cs, BodyChords)
        return body_widened(geo, drift, cs, x_new, nodes, accel_factor)
    assert geo.semi_axes_km is not None and isinstance(cs, ChordSet)
    return widened(geo.semi_axes_km, n_rad_s, drift, cs, x_new, nodes, accel_factor)


def rows_for(geo: cg.Geometry, drift: Drift, cs: Chords) -> AbortRows:
    """:func:`rows_of` or :func:`body_rows`, as ``drift`` is."""
    if isinstance(drift, BodyDrift):
        assert isinstance(cs, BodyChords)
        return body_rows(geo, drift, cs)
    assert geo.semi_axes_km is not None and isinstance(cs, ChordSet)
    return rows_of(geo.semi_axes_km, drift, cs)
