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
        vel = at[:, 3:] / np.maximum(np.linalg.norm(at[:, 3:], axis=1), 1e-300)[:, None]
        side = at[:, :3] - np.sum(at[:, :3] * vel, axis=1)[:, None] * vel
        size = np.linalg.norm(side, axis=1)
        flat = size <= 1e-9 * float(np.max(a))
        if np.any(flat):  # through the centre: the axis least aligned with the velocity
            axis = np.eye(3)[np.argmin(np.abs(vel[flat]), axis=1)]
            side[flat] = axis - np.sum(axis * vel[flat], axis=1)[:, None] * vel[flat]
            size[flat] = np.linalg.norm(side[flat], axis=1)
        side /= size[:, None]
        moved = np.where((level < 1.0)[..., None], r + float(np.max(a)) * side[:, None, :], r)
        out[some[part]] = moved / np.sqrt(cg.ellipsoid_level(moved, a))[..., None]
    return out


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


def exempt(geo: cg.Geometry, r_km: FloatArray) -> BoolArray:
    """The exempt nodes (N + 1,) of positions ``r_km`` (N + 1, 3) (module docstring):
    the final approach in the corridor (:func:`final_approach_start`) and every node
    within :data:`EXEMPT_RADIUS_FACTOR` × the largest semi-axis of the last node."""
    assert geo.semi_axes_km is not None
    radius = EXEMPT_RADIUS_FACTOR * float(np.max(geo.semi_axes_km))
    out: BoolArray = np.linalg.norm(r_km - r_km[-1], axis=1) <= radius
    out[final_approach_start(geo, r_km) :] = True
    return out


def final_approach_start(geo: cg.Geometry, r_km: FloatArray) -> int:
    """The first node of the exempt final approach of positions ``r_km`` (N + 1, 3).

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
) -> AbortSafety:
    """The :class:`AbortSafety` of the trajectory ``x`` (N + 1, 6) [km, km/s] (module docstring).

    Every step before the final approach (:func:`final_approach_start`) drifts
    freely by CW for ``time_s``; chords whose ball test (a) leaves room below
    0 (may enter E) or below the best upper bound of the distance (may hold the
    minimum) are re-sampled every h/``subsamples``, where the distance is
    computed (exactly where its bounds allow it to be the minimum).
    """
    assert geo.semi_axes_km is not None
    a = geo.semi_axes_km
    x = np.asarray(x, dtype=np.float64)
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
