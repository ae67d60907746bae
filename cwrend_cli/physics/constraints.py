"""Geometry of the path constraints (issue 32): pure functions and small frozen types.

The constraints of :class:`cwrend_cli.physics.params.Constraints`, in the relative
frame of the target (x radial, y along-track, z cross-track; km, s):

* the **keep-out zone** E, the open ellipsoid ``(x/a)² + (y/b)² + (z/c)² < 1``;
* the **corridor** C, the closed cone with apex at the port p, unit axis â and
  half-angle θ: ``C = {r : â·(r − p) ≥ cos θ ‖r − p‖}``.

A position is safe when it is outside E or inside C; the **unsafe set** is
``U = E ∖ C``. Its signed distance (:func:`signed_distance`) is

    φ(r) = max(d_E(r), −d_C(r)),

with d_E the signed Euclidean distance to the ellipsoid's surface (positive
outside, :func:`ellipsoid_signed_distance`) and d_C that to the cone's surface
(positive outside the cone, :func:`cone_signed_distance`). φ ≤ 0 exactly on U's
closure; inside U, −φ is the exact distance to U's boundary (the distance to the
boundary of an intersection is the smaller of the distances to its parts'
boundaries); outside U, φ is a lower bound of the distance to U (the larger of
the distances to the two sets whose intersection U is), so it never overstates
safety. Without a corridor φ = d_E; without a keep-out zone U is empty and
φ = +∞. φ is 1-Lipschitz (a maximum of 1-Lipschitz functions): a point that
moves by at most δ changes φ by at most δ, which is what the between-node
margins below rest on.

**Between nodes.** A node plan holds the constraints at the grid times t_k; the
trajectory between two nodes is the zero-order-hold arc of the CW dynamics
(paper Eq. 1, constant control u over the step, ‖u‖ ≤ u_max). Its acceleration
is ``r̈ = (3n²x + 2nẏ, −2nẋ, −n²z) + u``, so ``‖r̈‖ ≤ u_max + 3n²‖r‖ + 2n‖v‖``.
Over a step of length Δt from (r_k, v_k), with A = sup ‖r̈‖ over the step,
``‖v‖ ≤ ‖v_k‖ + AΔt`` and ``‖r‖ ≤ ‖r_k‖ + ‖v_k‖Δt + AΔt²``, hence

    A ≤ (u_max + 3n²(‖r_k‖ + ‖v_k‖Δt) + 2n‖v_k‖) / (1 − 3n²Δt² − 2nΔt)

whenever the denominator is positive (nΔt < 0.39; the paper's is 1e-3):
:func:`acceleration_bound`. Two consequences:

* the arc stays within ``‖v_k‖Δt + ½AΔt²`` of r_k (:func:`step_excursion_km`),
  so φ along the arc is at least φ(r_k) minus that;
* the arc stays within ``AΔt²/8`` of the chord between its two nodes
  (:func:`chord_margin_km`: the interpolation error e(τ) = r(τ) − chord(τ)
  vanishes at both ends and ‖ë‖ = ‖r̈‖ ≤ A, so ‖e(τ)‖ ≤ A τ(Δt − τ)/2 ≤ AΔt²/8).
  A convex constraint (a half-space, the corridor cone) tightened by that margin
  at both nodes therefore holds at every point of the arc: the chord lies in the
  tightened set by convexity and the arc within the margin of the chord.

**Covariance margin.** :func:`covariance_margin_km` gives ``k √(nᵀ P_pos n)``:
k standard deviations of the position estimate along a constraint's unit
normal n (``constraints.sigma_margin`` = k).

**Several bodies** (issue 34 item 2). The keep-out zone may be a union of
axis-aligned ellipsoids E_j, centre c_j, semi-axes a_j (a bus and its panels):
E = ∪ E_j, d_E = min_j d_Ej (the distance to a union is the smallest of the
distances; inside, −min_j d_Ej is the depth in the deepest body, a lower bound
of the depth in the union), still 1-Lipschitz. The corridor waives every body.

**A tumbling target** (issue 34 items 1b and 3). The ellipsoids, the port and
the corridor axis are given in the target's body frame B, which turns relative
to the Hill frame H: ``r_H = R(t) ρ_B`` with R body→Hill, ``Ṙ = [Ω×] R``, Ω the
body's angular velocity relative to H in H axes (:class:`BodyMotion`). In B
the unsafe set is fixed, and the chaser's body-frame position ρ = Rᵀ r obeys
(differentiating ρ = Rᵀ r twice)

    ρ̈ = Rᵀ (r̈ − 2 Ω × ṙ − Ω̇ × r + Ω × (Ω × r)),

so ``‖ρ̈‖ ≤ A + (‖Ω̇‖ + ‖Ω‖²) R + 2‖Ω‖ V`` with A, R, V the bounds of ‖r̈‖,
‖r‖, ‖v‖ over the step (:func:`body_acceleration_bound`). Everything above
then holds in B with that bound in place of A: the body-frame arc stays within
``‖ρ̈‖Δt²/8`` of the body-frame chord, so a convex body-frame set (a half-space
of one ellipsoid, the corridor cone) tightened by it at both nodes holds along
the arc; a point's excursion within a step gains the rotation's share: a body
point at distance R from the centre moves by ‖Ω‖RΔt (the ω × r of the port),
and the bound above is the second-order form of the same fact. With
``Ω_H = R ω_B − n ẑ`` (ω_B the inertial body rates, n the Hill frame's rate),
``‖Ω‖ ≤ ω + n`` and ``Ω̇ = −n ẑ × R ω_B + R ω̇_B``, so ``‖Ω̇‖ ≤ nω + ‖ω̇_B‖ ≤
nω + ω²`` (Euler's torque-free equations with |I_j − I_k| ≤ I_i give
|ω̇_i| ≤ |ω_j ω_k|, whose norm is at most ω²/√3), ω the largest inertial rate
the body reaches (energy bound): :func:`rate_bounds`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, TypeVar

import numpy as np
import numpy.typing as npt
from numba import njit

from cwrend_cli.physics.params import Constraints, Corridor, FloatArray, KeepOut

__all__ = [
    "SAFETY_SUBSTEPS",
    "BodyMotion",
    "Geometry",
    "HalfSpace",
    "Safety",
    "SecondOrderCone",
    "acceleration_bound",
    "approach_start",
    "body_acceleration_bound",
    "chord_margin_km",
    "cone_products",
    "cone_signed_distance",
    "corridor_angle_deg",
    "corridor_clearance_km",
    "corridor_cone",
    "covariance_margin_km",
    "covariance_margins_km",
    "ellipsoid_level",
    "ellipsoid_signed_distance",
    "ellipsoids",
    "geometry",
    "hermite_arcs",
    "keep_out_distance",
    "linearise_keep_out",
    "measure_safety",
    "rate_bounds",
    "rotate_to_body",
    "rotation_matrices",
    "signed_distance",
    "step_excursion_km",
    "tangent_planes",
    "to_body",
]

#: A float or an array of them (the bounds below work elementwise).
Num = TypeVar("Num", float, FloatArray)

#: Bisection steps of the ellipsoid distance (geometric, on a range of at most 1e40):
#: each halves the logarithm of the bracket, 100 reach the float resolution.
_BISECTIONS = 100
#: Smallest relative size of the coordinate along the shortest semi-axis [-]: a point on
#: that axis's plane is moved this far off it (φ changes by at most as much, φ being
#: 1-Lipschitz), so the distance equation always has its root in the bracket.
_AXIS_NUDGE = 1e-12


@dataclass(frozen=True)
class Geometry:
    """The constraints as arrays, the corridor's axis normalised.

    ``semi_axes_km`` (3,) [km] or None; ``port_km`` (3,) [km], ``axis`` (3,) unit
    vector [-] and ``half_angle_rad`` [rad] of the corridor, or None.
    ``bodies_centre_km``, ``bodies_semi_axes_km`` (M, 3) [km]: the extra ellipsoids
    (issue 34), or None. For a tumbling target every vector is in body axes.
    """

    semi_axes_km: FloatArray | None
    port_km: FloatArray | None
    axis: FloatArray | None
    half_angle_rad: float | None
    bodies_centre_km: FloatArray | None = None
    bodies_semi_axes_km: FloatArray | None = None


def geometry(constraints: Constraints) -> Geometry:
    """The arrays of ``constraints`` (the axis normalised to unit length)."""
    ko: KeepOut | None = constraints.keep_out
    co: Corridor | None = constraints.corridor
    axes = None if ko is None else np.array(ko.semi_axes_km, dtype=np.float64)
    centres = sizes = None
    if ko is not None and ko.bodies:
        centres = np.array([b.centre_km for b in ko.bodies], dtype=np.float64)
        sizes = np.array([b.semi_axes_km for b in ko.bodies], dtype=np.float64)
    if co is None:
        return Geometry(axes, None, None, None, centres, sizes)
    axis = np.array(co.axis, dtype=np.float64)
    return Geometry(
        axes,
        np.array(co.port_km, dtype=np.float64),
        axis / np.linalg.norm(axis),
        math.radians(co.half_angle_deg),
        centres,
        sizes,
    )


def ellipsoids(geo: Geometry) -> list[tuple[FloatArray | None, FloatArray]]:
    """``(centre_km, semi_axes_km)`` of every keep-out ellipsoid, the centred one first (its
    centre None: the origin); empty without a keep-out zone."""
    if geo.semi_axes_km is None:
        return []
    out: list[tuple[FloatArray | None, FloatArray]] = [(None, geo.semi_axes_km)]
    if geo.bodies_centre_km is not None and geo.bodies_semi_axes_km is not None:
        out += list(zip(geo.bodies_centre_km, geo.bodies_semi_axes_km, strict=True))
    return out


def keep_out_distance(r_km: FloatArray, geo: Geometry) -> FloatArray:
    """d_E [km]: signed distance of positions (..., 3) to the keep-out zone, the smallest over
    its ellipsoids (module docstring); +∞ without a zone."""
    r = np.asarray(r_km, dtype=np.float64)
    d = np.full(r.shape[:-1], np.inf)
    for centre, axes in ellipsoids(geo):
        d = np.minimum(d, ellipsoid_signed_distance(r if centre is None else r - centre, axes))
    return d


def _inside_keep_out(r_km: FloatArray, geo: Geometry) -> npt.NDArray[np.bool_]:
    """True where positions (..., 3) lie inside some ellipsoid of the zone (level < 1)."""
    inside = np.zeros(np.asarray(r_km).shape[:-1], dtype=bool)
    for centre, axes in ellipsoids(geo):
        inside |= ellipsoid_level(r_km if centre is None else r_km - centre, axes) < 1.0
    return inside


class BodyMotion(NamedTuple):
    """How the target's body frame turns over a sequence of times (issue 34).

    ``rotation`` (M, 3, 3) body→Hill, ``rate_rad_s`` (M, 3) its angular velocity
    relative to the Hill frame in Hill axes (Ω of the module docstring), and
    bounds over every time: ``rate_bound_rad_s`` ≥ ‖Ω‖,
    ``rate_dot_bound_rad_s2`` ≥ ‖Ω̇‖ (:func:`rate_bounds`).
    """

    rotation: FloatArray
    rate_rad_s: FloatArray
    rate_bound_rad_s: float
    rate_dot_bound_rad_s2: float


def to_body(motion: BodyMotion | None, r_km: FloatArray) -> FloatArray:
    """Body-frame coordinates ``ρ_i = R_iᵀ r_i`` of Hill positions (M, 3); ``r`` without motion."""
    if motion is None:
        return r_km
    return rotate_to_body(motion.rotation, r_km)


def rotation_matrices(q: FloatArray) -> FloatArray:
    """The rotation matrices (M, 3, 3) of unit scalar-first quaternions (M, 4).

    ``R(q) v = q ⊗ (0, v) ⊗ q*`` (Diebel 2006: the rotation matrix of a unit
    quaternion, written for Hamilton's product).
    """
    q0, q1, q2, q3 = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    rows = [
        [1 - 2 * (q2 * q2 + q3 * q3), 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
        [2 * (q1 * q2 + q0 * q3), 1 - 2 * (q1 * q1 + q3 * q3), 2 * (q2 * q3 - q0 * q1)],
        [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), 1 - 2 * (q1 * q1 + q2 * q2)],
    ]
    return np.asarray(np.moveaxis(np.array(rows), (0, 1), (-2, -1)), dtype=np.float64)


def rotate_to_body(rotation: FloatArray, r_km: FloatArray) -> FloatArray:
    """``ρ_i = R_iᵀ r_i`` [km]: Hill positions (M, 3) in the body frame of the rotations
    body→Hill (M, 3, 3) at their times."""
    return np.asarray(np.einsum("mji,mj->mi", rotation, r_km), dtype=np.float64)


def rate_bounds(omega_max_rad_s: float, n_rad_s: float) -> tuple[float, float]:
    """``(ω + n, nω + ω²)``: bounds of ‖Ω‖ [rad/s] and ‖Ω̇‖ [rad/s²] from the largest inertial
    body rate ω and the mean motion n (module docstring)."""
    w = omega_max_rad_s
    return w + n_rad_s, n_rad_s * w + w * w


def body_acceleration_bound(
    accel_km_s2: Num,
    r_km: Num,
    v_km_s: Num,
    rate_rad_s: float,
    rate_dot_rad_s2: float,
    dt_s: float,
) -> Num:
    """A bound on ‖ρ̈‖, the body-frame acceleration, over a step [km/s²] (module docstring).

    ``A + (‖Ω̇‖ + ‖Ω‖²) R + 2‖Ω‖ V`` with A = ``accel_km_s2`` (a bound of ‖r̈‖ over
    the step, :func:`acceleration_bound` from ‖r_k‖ = ``r_km``, ‖v_k‖ =
    ``v_km_s``), ``R = ‖r_k‖ + ‖v_k‖Δt + AΔt²`` and ``V = ‖v_k‖ + AΔt``; elementwise
    on arrays (abort safety's drift chords).
    """
    r_step = r_km + v_km_s * dt_s + accel_km_s2 * dt_s**2
    v_step = v_km_s + accel_km_s2 * dt_s
    spin = rate_dot_rad_s2 + rate_rad_s**2
    return accel_km_s2 + spin * r_step + 2.0 * rate_rad_s * v_step


@njit(cache=True)
def _row_norms(w: FloatArray) -> FloatArray:
    """Euclidean norms of rows w (K, 3): ``np.linalg.norm``'s sum of squares in its order."""
    out = np.empty(w.shape[0])
    for k in range(w.shape[0]):
        out[k] = math.sqrt(w[k, 0] * w[k, 0] + w[k, 1] * w[k, 1] + w[k, 2] * w[k, 2])
    return out


def row_norms(w: FloatArray) -> FloatArray:
    """``np.linalg.norm(w, axis=-1)`` of vectors w (..., 3), the same bits, without numpy's
    slow reduction over a short last axis."""
    w = np.asarray(w, dtype=np.float64)
    return _row_norms(np.ascontiguousarray(w.reshape(-1, 3))).reshape(w.shape[:-1])


@njit(cache=True)
def _levels(r: FloatArray, a: FloatArray) -> FloatArray:
    """:func:`ellipsoid_level` of rows r (K, 3): numpy's arithmetic in its order."""
    out = np.empty(r.shape[0])
    for k in range(r.shape[0]):
        x, y, z = r[k, 0] / a[0], r[k, 1] / a[1], r[k, 2] / a[2]
        out[k] = x * x + y * y + z * z
    return out


def ellipsoid_level(r_km: FloatArray, semi_axes_km: FloatArray) -> FloatArray:
    """``(x/a)² + (y/b)² + (z/c)²`` of positions ``r_km`` (..., 3) [-]: < 1 inside."""
    r = np.asarray(r_km, dtype=np.float64)
    a = np.asarray(semi_axes_km, dtype=np.float64)
    if a.shape != (3,):  # axes per position: numpy's broadcasting
        return np.asarray(np.sum((r / a) ** 2, axis=-1), dtype=np.float64)
    return _levels(np.ascontiguousarray(r.reshape(-1, 3)), a).reshape(r.shape[:-1])


def ellipsoid_signed_distance(r_km: FloatArray, semi_axes_km: FloatArray) -> FloatArray:
    """Signed Euclidean distance of positions (..., 3) to the ellipsoid's surface [km].

    Positive outside, negative inside. The nearest surface point of y (by
    symmetry, |y|) is ``x_i = a_i² y_i / (t + a_i²)`` with t the root of
    ``Σ (a_i y_i / (t + a_i²))² = 1`` on t > −a_min² (the Lagrange condition of
    the nearest point; Eberly, "Distance from a point to an ellipse, an
    ellipsoid, or a hyperellipsoid", 2013). The left side decreases in t; the
    root is found by geometric bisection on s = t + a_min² ∈ (0, a_min² + a_max‖y‖]
    (:data:`_BISECTIONS` steps), with the coordinate along the shortest axis
    kept at least :data:`_AXIS_NUDGE`·a_min from 0 so that the root exists.
    """
    y = np.abs(np.asarray(r_km, dtype=np.float64))
    shape = y.shape[:-1]
    y = y.reshape(-1, 3).copy()
    a = np.asarray(semi_axes_km, dtype=np.float64)
    j = int(np.argmin(a))
    a_min = a[j]
    y[:, j] = np.maximum(y[:, j], _AXIS_NUDGE * a_min)
    shift = a**2 - a_min**2  # t + a_i² = s + shift_i
    norm = np.linalg.norm(y, axis=1)
    lo = np.full(len(y), 1e-30 * a_min**2)
    hi = a_min**2 + float(np.max(a)) * norm + a_min**2
    for _ in range(_BISECTIONS):
        mid = np.sqrt(lo * hi)
        f = np.sum((a * y / (mid[:, None] + shift)) ** 2, axis=1) - 1.0
        above = f > 0.0  # root beyond mid
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    s = np.sqrt(lo * hi)
    x = a**2 * y / (s[:, None] + shift)
    dist = np.linalg.norm(x - y, axis=1)
    inside = np.sum((np.abs(np.asarray(r_km).reshape(-1, 3)) / a) ** 2, axis=1) < 1.0
    return np.asarray(np.where(inside, -dist, dist).reshape(shape), dtype=np.float64)


def cone_signed_distance(
    r_km: FloatArray, apex_km: FloatArray, axis: FloatArray, half_angle_rad: float
) -> FloatArray:
    """Signed Euclidean distance of positions (..., 3) to the cone's surface [km].

    Positive outside the cone, negative inside. With w = r − p, h = â·w and
    ρ = ‖w − hâ‖, in the half-plane (h, ρ) the cone's boundary is the ray at
    angle θ from the axis: the nearest point is on that ray when
    ``h cos θ + ρ sin θ ≥ 0`` (distance ``|ρ cos θ − h sin θ|``), else the apex
    (distance ‖w‖, outside).
    """
    w = np.asarray(r_km, dtype=np.float64) - apex_km
    h = w @ axis
    rho = np.linalg.norm(w - h[..., None] * axis, axis=-1)
    c, s = math.cos(half_angle_rad), math.sin(half_angle_rad)
    across = rho * c - h * s  # > 0 outside
    along = h * c + rho * s
    return np.asarray(np.where(along >= 0.0, across, np.linalg.norm(w, axis=-1)), np.float64)


def corridor_angle_deg(r_km: FloatArray, apex_km: FloatArray, axis: FloatArray) -> FloatArray:
    """Angle between r − p and the corridor axis at the port [deg] (0 on the axis; NaN at p)."""
    w = np.asarray(r_km, dtype=np.float64) - apex_km
    norm = np.linalg.norm(w, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.clip((w @ axis) / norm, -1.0, 1.0)
    return np.asarray(np.degrees(np.arccos(cos)), dtype=np.float64)


def signed_distance(r_km: FloatArray, geo: Geometry) -> FloatArray:
    """φ(r) [km]: signed distance of positions (..., 3) to the unsafe set (module docstring).

    ``max(d_E, −d_C)``; d_E alone without a corridor; +∞ without a keep-out zone.
    """
    r = np.asarray(r_km, dtype=np.float64)
    if geo.semi_axes_km is None:
        return np.full(r.shape[:-1], np.inf)
    d_e = keep_out_distance(r, geo)
    if geo.port_km is None or geo.axis is None or geo.half_angle_rad is None:
        return d_e
    d_c = cone_signed_distance(r, geo.port_km, geo.axis, geo.half_angle_rad)
    return np.asarray(np.maximum(d_e, -d_c), dtype=np.float64)


@dataclass(frozen=True)
class HalfSpace:
    """The half-space ``normalᵀ r ≥ offset_km`` of positions; ``normal`` a unit vector [-]."""

    normal: FloatArray
    offset_km: float

    def residual_km(self, r_km: FloatArray) -> FloatArray:
        """``normalᵀ r − offset`` [km]: ≥ 0 inside; the distance to the plane."""
        return np.asarray(np.asarray(r_km) @ self.normal - self.offset_km, dtype=np.float64)


def linearise_keep_out(
    semi_axes_km: FloatArray, r_bar_km: FloatArray, margin_km: float
) -> HalfSpace:
    """The keep-out constraint linearised at r̄, tightened by ``margin_km`` [km] (for SCP).

    g(r) = Σ (r_i/a_i)² is convex, so its tangent plane at r̄ lies below it:
    ``g(r̄) + ∇g(r̄)ᵀ (r − r̄) ≥ 1`` implies g(r) ≥ 1 (outside the zone). With
    n = ∇g/‖∇g‖ that is ``nᵀ r ≥ nᵀ r̄ + (1 − g(r̄))/‖∇g(r̄)‖``; the offset is
    raised by ``margin_km``, so every point of the returned half-space has its
    ball of radius ``margin_km`` outside the zone (d_E ≥ margin). r̄ ≠ 0.
    """
    normals, offsets = tangent_planes(semi_axes_km, np.reshape(r_bar_km, (1, 3)))
    return HalfSpace(normals[0], float(offsets[0]) + margin_km)


def tangent_planes(semi_axes_km: FloatArray, r_bar_km: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`linearise_keep_out` at K points at once, untightened: (unit normals (K, 3),
    offsets (K,) [km]) of the half-spaces ``nᵀ r ≥ offset``; rows r̄ ≠ 0."""
    a = np.asarray(semi_axes_km, dtype=np.float64)
    r_bar = np.ascontiguousarray(r_bar_km, dtype=np.float64)
    return _tangent_planes(a, r_bar)


@njit(cache=True)
def _tangent_planes(a: FloatArray, r: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`tangent_planes`, row by row: ∇g = 2r/a², n = ∇g/‖∇g‖, offset
    ``nᵀr + (1 − g)/‖∇g‖`` (numpy's arithmetic in its order: the same bits)."""
    normals = np.empty((r.shape[0], 3))
    offsets = np.empty(r.shape[0])
    level = _levels(r, a)
    for k in range(r.shape[0]):
        g0 = 2.0 * r[k, 0] / (a[0] * a[0])
        g1 = 2.0 * r[k, 1] / (a[1] * a[1])
        g2 = 2.0 * r[k, 2] / (a[2] * a[2])
        size = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        n0, n1, n2 = g0 / size, g1 / size, g2 / size
        normals[k, 0], normals[k, 1], normals[k, 2] = n0, n1, n2
        offsets[k] = (n0 * r[k, 0] + n1 * r[k, 1] + n2 * r[k, 2]) + (1.0 - level[k]) / size
    return normals, offsets


@dataclass(frozen=True)
class SecondOrderCone:
    """The corridor as a second-order cone of positions: ``‖P (r − p)‖ ≤ tan θ âᵀ(r − p) − m``.

    P = I − ââᵀ projects across the axis; m = margin / cos θ [km], so that a
    position satisfying it has its ball of radius ``margin`` inside the cone
    (the distance of an inside point to the surface is ``h sin θ − ρ cos θ``).
    Written for a cone solver as ``‖A r + b‖ ≤ cᵀ r + d``: :meth:`rows`.
    """

    apex_km: FloatArray
    axis: FloatArray
    tan_half: float
    offset_km: float  # m = margin / cos θ [km]

    def rows(self) -> tuple[FloatArray, FloatArray, FloatArray, float]:
        """(A (3, 3), b (3,), c (3,), d) with ``‖A r + b‖ ≤ cᵀ r + d``."""
        proj = np.eye(3) - np.outer(self.axis, self.axis)
        c = self.tan_half * self.axis
        return proj, -proj @ self.apex_km, c, float(-c @ self.apex_km - self.offset_km)

    def residual_km(
        self,
        r_km: FloatArray,
        rows: tuple[FloatArray, FloatArray, FloatArray, float] | None = None,
    ) -> FloatArray:
        """``cᵀ r + d − ‖A r + b‖`` [km]: ≥ 0 inside the (tightened) cone; ``rows``: its
        :meth:`rows` when the caller keeps them."""
        a, b, c, d = self.rows() if rows is None else rows
        along, across = cone_products(r_km, (a, b, c, d))
        return _cone_residuals(along.reshape(-1), across.reshape(-1, 3), b, d).reshape(along.shape)


def cone_products(
    r_km: FloatArray, rows: tuple[FloatArray, FloatArray, FloatArray, float]
) -> tuple[FloatArray, FloatArray]:
    """``(r c, r Aᵀ)`` of positions ``r_km`` (..., 3) and a cone's :meth:`SecondOrderCone.rows`
    (numpy's matmuls): what :func:`_cone_residuals` reads."""
    a, _, c, _ = rows
    r = np.asarray(r_km, dtype=np.float64)
    return r @ c, r @ a.T


@njit(cache=True)
def _cone_residuals(along: FloatArray, across: FloatArray, b: FloatArray, d: float) -> FloatArray:
    """:meth:`SecondOrderCone.residual_km` of rows r given ``along`` = r c (K,) and ``across``
    = r Aᵀ (K, 3) (numpy's products): ``along + d − ‖across + b‖``, numpy's elementwise
    arithmetic in its order and :func:`row_norms`' norm (the same bits)."""
    out = np.empty(along.size)
    for k in range(along.size):
        w0, w1, w2 = across[k, 0] + b[0], across[k, 1] + b[1], across[k, 2] + b[2]
        out[k] = (along[k] + d) - math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    return out


def corridor_cone(geo: Geometry, margin_km: float) -> SecondOrderCone:
    """The corridor of ``geo`` as a second-order cone tightened by ``margin_km`` [km]."""
    if geo.port_km is None or geo.axis is None or geo.half_angle_rad is None:
        raise ValueError("no corridor")
    theta = geo.half_angle_rad
    return SecondOrderCone(geo.port_km, geo.axis, math.tan(theta), margin_km / math.cos(theta))


def corridor_clearance_km(geo: Geometry) -> float:
    """A lower bound [km] on the distance between the corridor cone and the keep-out zone
    (≤ 0: the corridor may enter the zone; +∞ without a zone).

    Each ellipsoid lies in its circumscribed sphere (centre c, radius its largest
    semi-axis), so the cone is at least ``dist(c, cone) − max semi-axis`` from it
    (the distance by :func:`cone_signed_distance`, taken as 0 for a centre inside the
    cone); the smallest over the zone's ellipsoids. A corridor
    that opens away from a zone it starts outside of (campaigns/safe_approach.toml: a port
    50 m outside a 200 m sphere, the axis along the outward radial) clears it everywhere."""
    if geo.port_km is None or geo.axis is None or geo.half_angle_rad is None:
        raise ValueError("no corridor")
    clearance = math.inf
    for centre, axes in ellipsoids(geo):
        c = np.zeros(3) if centre is None else centre
        outside = float(cone_signed_distance(c, geo.port_km, geo.axis, geo.half_angle_rad))
        clearance = min(clearance, max(outside, 0.0) - float(np.max(axes)))
    return clearance


@njit(cache=True)
def approach_start(inside: npt.NDArray[np.bool_], lowest: int) -> int:
    """The first node of the final approach: the last contiguous stretch of nodes before
    the terminal one (the port, the corridor's apex) that lie ``inside`` the corridor
    (N + 1,), not below node ``lowest``; the terminal node N when the one before it is
    outside. Shared by the SCP's modes and the abort-safety exemption."""
    first = int(inside.shape[0]) - 1
    while first - 1 >= lowest and inside[first - 1]:
        first -= 1
    return first


def acceleration_bound(
    r_km: float, v_km_s: float, u_max_km_s2: float, n_rad_s: float, dt_s: float
) -> float:
    """A bound on ‖r̈‖ over a ZOH step of length Δt from ‖r_k‖, ‖v_k‖ [km/s²].

    ``(u_max + 3n²(‖r_k‖ + ‖v_k‖Δt) + 2n‖v_k‖) / (1 − 3n²Δt² − 2nΔt)`` (module
    docstring; CW, paper Eq. 1); ValueError when nΔt is too large for it.
    """
    denominator = 1.0 - 3.0 * (n_rad_s * dt_s) ** 2 - 2.0 * n_rad_s * dt_s
    if denominator <= 0.0:
        raise ValueError(f"n dt = {n_rad_s * dt_s:g}: the bound needs 3(n dt)² + 2 n dt < 1")
    gravity = 3.0 * n_rad_s**2 * (r_km + v_km_s * dt_s) + 2.0 * n_rad_s * v_km_s
    return (u_max_km_s2 + gravity) / denominator


def step_excursion_km(v_km_s: Num, accel_km_s2: Num, dt_s: float) -> Num:
    """``‖v_k‖Δt + ½AΔt²`` [km]: how far the arc of a step gets from its first node
    (elementwise on arrays)."""
    return v_km_s * dt_s + 0.5 * accel_km_s2 * dt_s**2


def chord_margin_km(accel_km_s2: float, dt_s: float) -> float:
    """``AΔt²/8`` [km]: how far the arc of a step gets from the chord between its nodes."""
    return accel_km_s2 * dt_s**2 / 8.0


def covariance_margin_km(normal: FloatArray, p_pos_km2: FloatArray, k: float) -> float:
    """``k √(nᵀ P_pos n)`` [km]: k σ of the position estimate along the unit normal n."""
    return float(covariance_margins_km(np.reshape(normal, (1, 3)), p_pos_km2, k)[0])


def covariance_margins_km(normals: FloatArray, p_pos_km2: FloatArray, k: float) -> FloatArray:
    """:func:`covariance_margin_km` of K unit normals (K, 3) at once [km]."""
    n = np.asarray(normals, dtype=np.float64)
    quad = np.einsum("ki,ij,kj->k", n, np.asarray(p_pos_km2, dtype=np.float64), n)
    return np.asarray(k * np.sqrt(np.maximum(quad, 0.0)), dtype=np.float64)


# ---------------------------------------------------------------------------
# Safety of a flown trajectory (issue 32 item 3): measured on the truth
# ---------------------------------------------------------------------------

#: Sub-samples per step of the true arc [-]: φ is evaluated every Δt/20 (0.05 s on the
#: paper's 1 s grid).
SAFETY_SUBSTEPS = 20


def hermite_arcs(x: FloatArray, dt_s: float, substeps: int) -> FloatArray:
    """Positions of every step's arc at ``substeps`` + 1 equally spaced times [km].

    ``x`` (N+1, 6): the states at the nodes [km, km/s]. Each step's arc is the
    cubic Hermite interpolant of its two end states (positions and velocities):
    with s = τ/Δt, ``r = h00 r_k + h10 Δt v_k + h01 r_k+1 + h11 Δt v_k+1``. Its
    error is at most ``Δt⁴/384 · max‖r⁗‖`` within the step (the dynamics are smooth
    within a step, the control being held; on the paper's scenario
    ‖r⁗‖ ≲ n²u_max ≈ 1e-9 km/s⁴, so the error is below 1e-11 km at Δt = 1 s).
    Returns (N, substeps + 1, 3); sample 0 and sample ``substeps`` are the nodes.
    """
    s = np.linspace(0.0, 1.0, substeps + 1)[:, None]
    h00 = 2 * s**3 - 3 * s**2 + 1
    h10 = s**3 - 2 * s**2 + s
    h01 = -2 * s**3 + 3 * s**2
    h11 = s**3 - s**2
    r0, v0 = x[:-1, None, :3], x[:-1, None, 3:]
    r1, v1 = x[1:, None, :3], x[1:, None, 3:]
    arcs = h00 * r0 + h10 * dt_s * v0 + h01 * r1 + h11 * dt_s * v1
    arcs[:, 0] = x[:-1, :3]  # the nodes exactly
    arcs[:, -1] = x[1:, :3]
    return np.asarray(arcs, dtype=np.float64)


@dataclass(frozen=True)
class Safety:
    """How safe a flown trajectory was (module docstring; per run and per step).

    Over the arcs sub-sampled every Δt/``substeps`` (:func:`hermite_arcs`). The
    minimum of φ between two sub-samples is at most ``‖v‖ Δt/(2 substeps)``
    below the smaller of the two (φ is 1-Lipschitz), which bounds what the
    sampling can miss.
    """

    min_distance_km: float  # min φ over the run [km]; < 0: the path entered the unsafe set
    unsafe_time_s: float  # time with φ < 0, to Δt/substeps [s]
    corridor_violation_deg: float  # max (angle to the axis − θ)⁺ inside the keep-out zone [deg]
    approach_speed_km_s: float  # ‖v(T)‖ [km/s]
    approach_angle_deg: float  # angle between v(T) and −â (0: straight down the corridor) [deg]
    violated: bool  # min_distance_km < 0
    step_distance_km: FloatArray  # (N+1,) φ at the nodes t_k [km]
    geometry: Geometry  # what was measured against (drawn by the recordings)
    #: a tumbling target (issue 34): measured against the turning set, and the docking
    #: state error at T relative to the moving port (NaN without a corridor)
    rotating: bool = False
    dock_position_error_km: float = math.nan  # ‖r(T) − R(T) p‖ [km]
    dock_velocity_error_km_s: float = math.nan  # ‖v(T) − Ω(T) × R(T) p‖ [km/s]


def _ellipsoid_distance_bounds(
    r_km: FloatArray, semi_axes_km: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Lower and upper bounds of :func:`ellipsoid_signed_distance` of positions (M, 3) [km].

    With L the level and q = √L: √(level) is a norm whose gradient is at most
    1/a_min long, so ``|d_E| ≥ a_min |q − 1|``; the surface point on the ray
    from the centre, r/q, is at ``‖r‖ |1 − 1/q|``, so ``|d_E| ≤`` that.
    """
    q = np.sqrt(ellipsoid_level(r_km, semi_axes_km))
    norm = np.linalg.norm(r_km, axis=-1)
    a_min = float(np.min(semi_axes_km))
    with np.errstate(divide="ignore", invalid="ignore"):
        ray = np.where(q > 0.0, norm * np.abs(1.0 - 1.0 / q), a_min)
    near = a_min * np.abs(q - 1.0)
    outside = q >= 1.0
    return np.where(outside, near, -ray), np.where(outside, ray, -near)


#: Relative margin over the smallest upper bound within which a point is measured exactly
#: among several bodies (:func:`_min_signed_distance`) [-]: 1e-9 of the distance plus the
#: largest semi-axis, some 1e6 times the bisection's rounding and the axis nudge
#: (:data:`_AXIS_NUDGE`).
_PRUNE_MARGIN = 1e-9


def _min_signed_distance(points: FloatArray, geo: Geometry, d_c: FloatArray | None) -> float:
    """min φ over ``points`` (M, 3) [km], exact, computing d_E only where it can be the minimum.

    φ's bounds from :func:`_ellipsoid_distance_bounds` (d_C is exact and cheap):
    only the points whose lower bound is at most the smallest upper bound can
    hold the minimum. With several bodies (issue 34), d_E's bounds are the smallest of
    the bodies' bounds, and the points kept those within :data:`_PRUNE_MARGIN` of the
    smallest upper bound (far above the bisection's rounding and the axis nudge): d_E is
    computed point by point, so the minimum is the one over every point, to the bit.
    """
    assert geo.semi_axes_km is not None
    if geo.bodies_centre_km is not None:
        low = high = np.full(points.shape[0], np.inf)
        size = 0.0  # the largest semi-axis [km]
        for centre, axes in ellipsoids(geo):
            body = _ellipsoid_distance_bounds(points if centre is None else points - centre, axes)
            low, high = np.minimum(low, body[0]), np.minimum(high, body[1])
            size = max(size, float(np.max(axes)))
        if d_c is not None:
            low, high = np.maximum(low, -d_c), np.maximum(high, -d_c)
        best = int(np.argmin(high))
        keep = low <= high[best] + _PRUNE_MARGIN * (abs(high[best]) + size)
        keep[best] = True
        d_e = keep_out_distance(points[keep], geo)
        return float(np.min(d_e if d_c is None else np.maximum(d_e, -d_c[keep])))
    low, high = _ellipsoid_distance_bounds(points, geo.semi_axes_km)
    if d_c is not None:
        low, high = np.maximum(low, -d_c), np.maximum(high, -d_c)
    best = int(np.argmin(high))
    # a rounding margin: where the bounds meet (a sphere) they may cross by an ulp
    candidates = low <= high[best] + 1e-12 * (abs(high[best]) + float(np.max(geo.semi_axes_km)))
    candidates[best] = True
    exact = ellipsoid_signed_distance(points[candidates], geo.semi_axes_km)
    if d_c is not None:
        exact = np.maximum(exact, -d_c[candidates])
    return float(np.min(exact))


def measure_safety(
    x: FloatArray,
    dt_s: float,
    geo: Geometry,
    substeps: int = SAFETY_SUBSTEPS,
    motion: BodyMotion | None = None,
) -> Safety:
    """The :class:`Safety` of the trajectory ``x`` (N+1, 6) [km, km/s] on a grid of step Δt.

    The minimum distance is exact over the sub-samples (φ computed exactly
    where its bounds allow it to be the minimum); the unsafe time counts the
    sub-samples inside the keep-out zone and outside the corridor, from the
    definitions. The corridor-angle violation is taken over the sub-samples
    inside the keep-out zone (where the corridor is what makes a position safe):
    0 when the path never enters it; NaN without a corridor or without a
    keep-out zone. The approach angle is NaN without a corridor or at rest.

    ``motion`` (a tumbling target, issue 34): the body frame's turn at every
    sub-sample (N·substeps + 1 rows). Every sub-sample is then measured in the
    body frame at its own time, the approach speed and angle are those of the
    velocity relative to the body at T (ρ̇ = Rᵀ(v − Ω × r)), and the docking
    state error is taken against the moving port (R p, Ω × R p).
    """
    x = np.asarray(x, dtype=np.float64)
    arcs = hermite_arcs(x, dt_s, substeps)
    points = np.concatenate([arcs[:, :-1].reshape(-1, 3), x[-1:, :3]])  # every Δt/substeps
    v_end = x[-1, 3:]
    dock = (math.nan, math.nan)
    if motion is not None:
        points = to_body(motion, points)
        rot_end, rate_end = motion.rotation[-1], motion.rate_rad_s[-1]
        v_end = rot_end.T @ (v_end - np.cross(rate_end, x[-1, :3]))
        nodes = signed_distance(points[::substeps], geo)
        if geo.port_km is not None:
            port = rot_end @ geo.port_km
            dock = (
                float(np.linalg.norm(x[-1, :3] - port)),
                float(np.linalg.norm(x[-1, 3:] - np.cross(rate_end, port))),
            )
    else:
        nodes = signed_distance(x[:, :3], geo)
        if geo.port_km is not None:
            dock = (float(np.linalg.norm(x[-1, :3] - geo.port_km)), float(np.linalg.norm(v_end)))
    corridor = geo.port_km is not None and geo.axis is not None and geo.half_angle_rad is not None
    speed = float(np.linalg.norm(v_end))
    violation, angle = math.nan, math.nan
    if corridor and speed > 0.0:
        assert geo.axis is not None
        angle = math.degrees(math.acos(min(max(float(-v_end @ geo.axis) / speed, -1.0), 1.0)))
    if geo.semi_axes_km is None:  # nothing is unsafe
        min_distance, unsafe_time = math.inf, 0.0
    else:
        d_c = None
        if corridor:
            assert geo.port_km is not None and geo.axis is not None
            assert geo.half_angle_rad is not None
            d_c = cone_signed_distance(points, geo.port_km, geo.axis, geo.half_angle_rad)
        min_distance = _min_signed_distance(points, geo, d_c)
        inside = _inside_keep_out(points, geo)
        unsafe = inside if d_c is None else inside & (d_c > 0.0)
        unsafe_time = float(np.count_nonzero(unsafe)) * dt_s / substeps
        if corridor:
            assert geo.port_km is not None and geo.axis is not None
            assert geo.half_angle_rad is not None
            excess = corridor_angle_deg(points[inside], geo.port_km, geo.axis)
            excess = excess[np.isfinite(excess)] - math.degrees(geo.half_angle_rad)
            violation = float(max(excess.max(initial=0.0), 0.0))
    return Safety(
        min_distance_km=min_distance,
        unsafe_time_s=unsafe_time,
        corridor_violation_deg=violation,
        approach_speed_km_s=speed,
        approach_angle_deg=angle,
        violated=bool(min_distance < 0.0),
        step_distance_km=np.asarray(nodes, dtype=np.float64),
        geometry=geo,
        rotating=motion is not None,
        dock_position_error_km=dock[0],
        dock_velocity_error_km_s=dock[1],
    )
