"""Geometry of the path constraints (issue 32, physics/constraints.py) against independent checks.

Every expected value here is computed in the test: distances by minimising over a
parametrised surface with scipy, membership from the definitions ((x/a)² + … < 1,
the angle to the axis), the zero-order-hold arcs by integrating the CW equations
written out below with scipy's solve_ivp. Nothing calls the module's geometry to
check the module's geometry.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import minimize

from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.params import Constraints, Corridor, KeepOut

AXES = np.array([0.1, 0.25, 0.15])  # km
RNG = np.random.default_rng(32)


def _surface(a: np.ndarray, angles: np.ndarray) -> np.ndarray:
    th, ph = angles
    out: np.ndarray = a * np.array(
        [math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)]
    )
    return out


def _brute_ellipsoid_distance(y: np.ndarray, a: np.ndarray) -> float:
    """Nearest surface point by a coarse grid of (θ, φ) then Nelder–Mead from the best few."""
    th, ph = np.meshgrid(np.linspace(0, math.pi, 61), np.linspace(0, 2 * math.pi, 121))
    pts = np.stack(
        [a[0] * np.sin(th) * np.cos(ph), a[1] * np.sin(th) * np.sin(ph), a[2] * np.cos(th)], -1
    ).reshape(-1, 3)
    d = np.linalg.norm(pts - y, axis=1)
    best = math.inf
    for i in np.argsort(d)[:4]:
        start = np.array([th.reshape(-1)[i], ph.reshape(-1)[i]])
        res = minimize(
            lambda x: float(np.linalg.norm(_surface(a, x) - y)),
            start,
            method="Nelder-Mead",
            options={"xatol": 1e-12, "fatol": 1e-15, "maxiter": 4000},
        )
        best = min(best, float(res.fun))
    return best


@pytest.mark.parametrize("axes", [AXES, np.array([0.2, 0.2, 0.2]), np.array([0.1, 0.1, 0.3])])
def test_the_ellipsoid_distance_is_the_nearest_surface_point(axes: np.ndarray) -> None:
    pts = RNG.uniform(-0.5, 0.5, (25, 3))
    pts[:5] *= 0.2  # inside
    pts[5:10, 0] = 0.0  # on a plane of the shortest axis (the degenerate case)
    pts[10:12, :2] = 0.0  # on an axis
    got = cg.ellipsoid_signed_distance(pts, axes)
    for y, d in zip(pts, got, strict=True):
        inside = float(np.sum((y / axes) ** 2)) < 1.0
        assert (d < 0) == inside
        assert abs(d) == pytest.approx(_brute_ellipsoid_distance(y, axes), abs=1e-9)


def test_the_ellipsoid_distance_of_a_sphere_is_radial() -> None:
    pts = RNG.normal(size=(100, 3)) * 0.3
    got = cg.ellipsoid_signed_distance(pts, np.array([0.2, 0.2, 0.2]))
    np.testing.assert_allclose(got, np.linalg.norm(pts, axis=1) - 0.2, atol=1e-13)


APEX = np.array([0.0, 0.25, 0.0])
AXIS = np.array([0.0, 1.0, 0.0])
THETA = math.radians(20.0)


def _brute_cone_distance(y: np.ndarray) -> float:
    e1, e2 = np.array([1.0, 0, 0]), np.array([0, 0, 1.0])

    def point(x: np.ndarray) -> np.ndarray:
        s, psi = abs(x[0]), x[1]
        lateral = math.cos(psi) * e1 + math.sin(psi) * e2
        out: np.ndarray = APEX + s * (math.cos(THETA) * AXIS + math.sin(THETA) * lateral)
        return out

    best = float(np.linalg.norm(y - APEX))
    for psi in np.linspace(0, 2 * math.pi, 12, endpoint=False):
        res = minimize(
            lambda x: float(np.linalg.norm(point(x) - y)),
            np.array([float(np.linalg.norm(y - APEX)), psi]),
            method="Nelder-Mead",
            options={"xatol": 1e-12, "fatol": 1e-15, "maxiter": 4000},
        )
        best = min(best, float(res.fun))
    return best


def test_the_cone_distance_is_the_nearest_surface_point() -> None:
    pts = APEX + RNG.uniform(-0.3, 0.3, (30, 3))
    got = cg.cone_signed_distance(pts, APEX, AXIS, THETA)
    for y, d in zip(pts, got, strict=True):
        w = y - APEX
        inside = float(w @ AXIS) >= math.cos(THETA) * float(np.linalg.norm(w))
        assert (d <= 0) == inside
        assert abs(d) == pytest.approx(_brute_cone_distance(y), abs=1e-8)


GEO = cg.geometry(
    Constraints(
        keep_out=KeepOut((0.1, 0.25, 0.15)),
        corridor=Corridor((0.0, 0.25, 0.0), (0.0, 3.0, 0.0), 20.0),
    )
)


def test_the_geometry_normalises_the_axis() -> None:
    assert GEO.axis is not None
    np.testing.assert_array_equal(GEO.axis, [0.0, 1.0, 0.0])


def _unsafe(y: np.ndarray) -> bool:
    w = y - APEX
    in_cone = float(w @ AXIS) >= math.cos(THETA) * float(np.linalg.norm(w))
    return float(np.sum((y / AXES) ** 2)) < 1.0 and not in_cone


def test_the_signed_distance_is_negative_exactly_on_the_unsafe_set() -> None:
    pts = RNG.uniform(-0.3, 0.3, (4000, 3))
    phi = cg.signed_distance(pts, GEO)
    unsafe = np.array([_unsafe(y) for y in pts])
    assert unsafe.any() and (~unsafe).any()
    np.testing.assert_array_equal(phi < 0, unsafe)


def test_the_signed_distance_never_overstates_safety() -> None:
    """A safe point with φ = d: every point within d of it is safe (φ is a lower bound)."""
    pts = RNG.uniform(-0.3, 0.3, (300, 3))
    for y, d in zip(pts, cg.signed_distance(pts, GEO), strict=True):
        if d <= 1e-6:
            continue
        dirs = RNG.normal(size=(200, 3))
        ball = y + 0.999 * d * dirs / np.linalg.norm(dirs, axis=1)[:, None]
        assert not any(_unsafe(p) for p in ball)


def test_without_a_keep_out_zone_nothing_is_unsafe() -> None:
    geo = cg.geometry(Constraints(corridor=Corridor((0, 0.25, 0), (0, 1, 0), 20.0)))
    assert np.all(np.isinf(cg.signed_distance(RNG.normal(size=(10, 3)), geo)))


def test_the_linearised_keep_out_lies_outside_the_zone_with_its_margin() -> None:
    for _ in range(50):
        r_bar = RNG.uniform(-0.4, 0.4, 3)
        margin = float(RNG.uniform(0, 0.02))
        hs = cg.linearise_keep_out(AXES, r_bar, margin)
        # points of the half-space, and every point within the margin of them, are outside
        cloud = RNG.uniform(-0.5, 0.5, (3000, 3))
        kept = cloud[cloud @ hs.normal >= hs.offset_km]
        dirs = RNG.normal(size=kept.shape)
        shifted = kept + 0.999 * margin * dirs / np.linalg.norm(dirs, axis=1)[:, None]
        assert np.all(np.sum((shifted / AXES) ** 2, axis=1) >= 1.0)


def test_the_linearisation_at_a_surface_point_is_its_tangent_plane() -> None:
    r_bar = AXES * np.array([0.6, 0.0, 0.8])  # on the surface
    hs = cg.linearise_keep_out(AXES, r_bar, 0.0)
    assert float(hs.normal @ r_bar) == pytest.approx(hs.offset_km, abs=1e-15)
    assert np.linalg.norm(hs.normal) == pytest.approx(1.0)


def test_the_corridor_cone_holds_exactly_the_points_within_its_angle() -> None:
    soc = cg.corridor_cone(GEO, 0.0)
    pts = APEX + RNG.uniform(-0.3, 0.3, (2000, 3))
    w = pts - APEX
    inside = w @ AXIS >= math.cos(THETA) * np.linalg.norm(w, axis=1)
    np.testing.assert_array_equal(soc.residual_km(pts) >= 0, inside)


def test_the_tightened_cone_keeps_a_ball_of_its_margin_inside() -> None:
    margin = 0.01
    soc = cg.corridor_cone(GEO, margin)
    pts = APEX + RNG.uniform(-0.1, 0.1, (3000, 3)) + np.outer(RNG.uniform(0, 0.3, 3000), AXIS)
    kept = pts[soc.residual_km(pts) >= 0]
    assert len(kept) > 500
    dirs = RNG.normal(size=kept.shape)
    ball = kept + 0.999 * margin * dirs / np.linalg.norm(dirs, axis=1)[:, None]
    w = ball - APEX
    assert np.all(w @ AXIS >= math.cos(THETA) * np.linalg.norm(w, axis=1))


def _cw_arc(n: float, x0: np.ndarray, u: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The ZOH arc of the CW equations (x radial, y along-track, z cross-track), densely."""

    def f(_t: float, s: np.ndarray) -> np.ndarray:
        x, _y, z, vx, vy, vz = s
        return np.array(
            [vx, vy, vz, 3 * n**2 * x + 2 * n * vy + u[0], -2 * n * vx + u[1], -(n**2) * z + u[2]]
        )

    tau = np.linspace(0.0, dt, 401)
    sol = solve_ivp(f, (0.0, dt), x0, t_eval=tau, rtol=1e-12, atol=1e-15)
    return tau, sol.y[:3].T


@pytest.mark.parametrize(("n", "dt"), [(0.00104218449, 1.0), (0.01, 10.0)])
def test_the_arc_of_a_step_stays_within_the_stated_margins(n: float, dt: float) -> None:
    u_max = 8e-4
    worst_chord, worst_start = 0.0, 0.0
    for _ in range(200):
        x0 = np.concatenate([RNG.uniform(-2, 2, 3), RNG.uniform(-0.05, 0.05, 3)])
        u = RNG.normal(size=3)
        u *= u_max * RNG.uniform(0, 1) / np.linalg.norm(u)
        tau, arc = _cw_arc(n, x0, u, dt)
        accel = cg.acceleration_bound(
            float(np.linalg.norm(x0[:3])), float(np.linalg.norm(x0[3:])), u_max, n, dt
        )
        chord = arc[0] + (tau / dt)[:, None] * (arc[-1] - arc[0])
        off_chord = float(np.max(np.linalg.norm(arc - chord, axis=1)))
        off_start = float(np.max(np.linalg.norm(arc - arc[0], axis=1)))
        assert off_chord <= cg.chord_margin_km(accel, dt)
        assert off_start <= cg.step_excursion_km(float(np.linalg.norm(x0[3:])), accel, dt)
        worst_chord = max(worst_chord, off_chord / cg.chord_margin_km(accel, dt))
        worst_start = max(worst_start, off_start)
    assert worst_chord > 0.1  # the bound is not vacuous: arcs come within 10x of it


def test_the_acceleration_bound_refuses_a_step_too_long_for_it() -> None:
    with pytest.raises(ValueError, match="n dt"):
        cg.acceleration_bound(1.0, 0.0, 8e-4, 0.01, 40.0)


def test_the_covariance_margin_is_k_sigma_along_the_normal() -> None:
    normal = np.array([0.0, 0.6, 0.8])
    p = np.diag([1e-6, 4e-6, 9e-6])
    expected = 3 * math.sqrt(0.36 * 4e-6 + 0.64 * 9e-6)
    assert cg.covariance_margin_km(normal, p, 3.0) == pytest.approx(expected, rel=1e-14)
    assert cg.covariance_margin_km(normal, np.zeros((3, 3)), 3.0) == 0.0


def _corridor_geometry(
    port: np.ndarray, axis: np.ndarray, deg: float, axes: np.ndarray = AXES
) -> cg.Geometry:
    return cg.geometry(
        Constraints(keep_out=KeepOut(tuple(axes)), corridor=Corridor(tuple(port), tuple(axis), deg))
    )


def test_a_corridor_opening_away_from_a_sphere_clears_it_by_the_ports_height() -> None:
    """campaigns/safe_approach.toml: a 200 m sphere, the port 250 m out along −z, the axis
    −z: every point of the cone is at least 250 m from the centre (its apex the nearest),
    so 50 m from the sphere, whatever the half-angle below 90°."""
    for deg in (10.0, 30.0, 80.0):
        geo = _corridor_geometry(
            np.array([0.0, 0.0, -0.25]), np.array([0.0, 0.0, -1.0]), deg, np.full(3, 0.2)
        )
        assert cg.corridor_clearance_km(geo) == pytest.approx(0.05, abs=1e-15)


def test_a_corridor_holding_the_zones_centre_has_no_clearance() -> None:
    """A wide cone opening towards a small sphere 200 m away holds its centre, however deep
    the centre lies in the cone (here 246 m from its surface, deeper than the radius)."""
    for deg, radius in ((30.0, 0.2), (80.0, 0.05)):
        geo = _corridor_geometry(
            np.array([0.0, 0.0, -0.25]), np.array([0.0, 0.0, 1.0]), deg, np.full(3, radius)
        )
        assert cg.corridor_clearance_km(geo) <= 0.0


def test_the_corridor_clearance_never_exceeds_the_distance_to_the_zone() -> None:
    """A lower bound, checked by brute force written here on 200 random corridors (a port up
    to 100 m outside a sphere of 50–300 m, any axis, half-angle 5–80°): each cone sampled
    on 61 lengths to 1 km × 90 generator lines, each point's distance to the sphere
    ``‖p‖ − R`` exactly; the sampled minimum can only exceed the cone's, so a clearance above
    it would be an overstatement. Where the apex is the nearest point the bound is exact."""
    turn = np.linspace(0.0, 2 * math.pi, 90, endpoint=False)
    lengths = np.r_[0.0, np.geomspace(1e-4, 1.0, 60)]
    positive = exact = 0
    for _ in range(200):
        radius = float(RNG.uniform(0.05, 0.3))
        direction = RNG.normal(size=3)
        direction /= np.linalg.norm(direction)
        port = direction * (radius + RNG.uniform(0.0, 0.1))
        axis = direction + RNG.normal(size=3) * RNG.uniform(0.0, 1.5)
        axis /= np.linalg.norm(axis)
        deg = float(RNG.uniform(5.0, 80.0))
        geo = _corridor_geometry(port, axis, deg, np.full(3, radius))
        clearance = cg.corridor_clearance_km(geo)
        helper = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
        helper /= np.linalg.norm(helper)
        other = np.cross(axis, helper)
        tan = math.tan(math.radians(deg))
        lines = axis + tan * (np.outer(np.cos(turn), helper) + np.outer(np.sin(turn), other))
        lines /= np.linalg.norm(lines, axis=1)[:, None]
        points = port + np.einsum("l,gi->lgi", lengths, lines).reshape(-1, 3)
        sampled = float(np.min(np.linalg.norm(points, axis=1))) - radius
        assert clearance <= sampled + 1e-12
        positive += clearance > 0.0
        # the apex nearest: −port (the centre seen from the port) at least 90° + θ off the axis
        if float(-port @ axis) <= -math.sin(math.radians(deg)) * float(np.linalg.norm(port)):
            exact += 1
            assert clearance == pytest.approx(float(np.linalg.norm(port)) - radius, abs=1e-15)
    assert positive > 30 and exact > 10


def test_an_ellipsoid_is_cleared_by_its_circumscribed_sphere() -> None:
    """An ellipsoid counts as its circumscribed sphere: the clearance of AXES's zone is that
    of a sphere of its largest semi-axis."""
    port, axis = np.array([0.0, 0.0, -0.3]), np.array([0.0, 0.0, -1.0])
    clearance = cg.corridor_clearance_km(_corridor_geometry(port, axis, 30.0))
    assert clearance == pytest.approx(0.3 - float(np.max(AXES)), abs=1e-15)
