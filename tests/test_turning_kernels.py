"""The cheaper parts of a tumbling run give the numbers of before bit for bit (issue 34: the
cost of a tumbling run): the turning SCP's step margins in one compiled pass, the safety
measure of several bodies computing the exact distance only where it can be the minimum.

Each test writes the formula the code had before and compares on random inputs exactly
(``np.array_equal`` or ``==``: no tolerance, bits are the claim; whole tumbling runs are
pinned by ``test_tumbling_guidance`` and ``test_abort_tumbling``).
"""

from __future__ import annotations

import numpy as np
import pytest

from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.guidance import constrained as cp

N_MOTION = 0.00104218449  # rad/s, the paper's
U_MAX = 8e-4  # km/s²


def _margins_before(
    x: np.ndarray, extra_km: float, factor: float, rate: float, rate_dot: float, dt_s: float
) -> np.ndarray:
    """The turning body's step margins as ``_step_margins`` computed them before: numpy's
    norms and neighbour maxima, then the scalar bounds a step at a time."""
    r = np.linalg.norm(x[:, :3], axis=1)
    v = np.linalg.norm(x[:, 3:], axis=1)
    r_step = np.maximum(r[:-1], r[1:]) + extra_km
    v_step = np.maximum(v[:-1], v[1:])
    return np.array(
        [
            cg.chord_margin_km(
                factor
                * cg.body_acceleration_bound(
                    cg.acceleration_bound(ri, vi, U_MAX, N_MOTION, dt_s),
                    ri,
                    vi,
                    rate,
                    rate_dot,
                    dt_s,
                ),
                dt_s,
            )
            for ri, vi in zip(r_step.tolist(), v_step.tolist(), strict=True)
        ]
    )


def _motion(rate: float, rate_dot: float) -> cg.BodyMotion:
    """A body motion with these rate bounds (the margins read nothing else)."""
    return cg.BodyMotion(np.eye(3)[None], np.zeros((1, 3)), rate, rate_dot)


def test_turning_step_margins_are_the_scalar_bounds_bit_for_bit() -> None:
    rng = np.random.default_rng(34)
    for rows in range(2, 900, 11):
        # positions from metres to tens of km, speeds from mm/s to m/s
        x = np.hstack(
            [
                rng.normal(size=(rows, 3)) * 10.0 ** rng.uniform(-3, 1.5),
                rng.normal(size=(rows, 3)) * 10.0 ** rng.uniform(-6, -3),
            ]
        )
        dt_s = float(rng.choice([0.5, 1.0, 2.0, 10.0]))
        rate = float(rng.uniform(0.0, 0.2))  # up to ~11 deg/s
        rate_dot = float(rng.uniform(0.0, 0.05))
        extra, factor = float(rng.uniform(0.0, 0.5)), float(rng.choice([1.0, 1.5]))
        got = cp._step_margins(N_MOTION, dt_s, U_MAX, x, extra, factor, _motion(rate, rate_dot))
        assert np.array_equal(got, _margins_before(x, extra, factor, rate, rate_dot, dt_s))


def test_turning_step_margins_keep_nan_where_a_state_is_nan() -> None:
    rng = np.random.default_rng(35)
    x = rng.normal(size=(40, 6)) * 1e-2
    x[7, 1] = np.nan
    x[20, 4] = np.nan
    got = cp._step_margins(N_MOTION, 1.0, U_MAX, x, 0.1, 1.5, _motion(0.05, 0.01))
    want = _margins_before(x, 0.1, 1.5, 0.05, 0.01, 1.0)
    assert np.array_equal(np.isnan(got), np.isnan(want))
    assert np.array_equal(got[~np.isnan(got)], want[~np.isnan(want)])


def _bodies(rng: np.random.Generator, corridor: bool) -> cg.Geometry:
    """A bus and 1–3 panels of random sizes [km], a corridor off the bus's −x face or none."""
    count = int(rng.integers(1, 4))
    return cg.Geometry(
        rng.uniform(0.02, 0.1, 3),
        np.array([-0.1, 0.0, 0.0]) if corridor else None,
        np.array([-1.0, 0.0, 0.0]) if corridor else None,
        np.radians(30.0) if corridor else None,
        rng.normal(size=(count, 3)) * 0.15,
        rng.uniform(0.005, 0.1, (count, 3)),
    )


def _min_before(points: np.ndarray, geo: cg.Geometry) -> float:
    """min φ over ``points`` as :func:`cg._min_signed_distance` took it with several bodies
    before: d_E of every point."""
    d_e = cg.keep_out_distance(points, geo)
    if geo.port_km is None:
        return float(np.min(d_e))
    assert geo.axis is not None and geo.half_angle_rad is not None
    d_c = cg.cone_signed_distance(points, geo.port_km, geo.axis, geo.half_angle_rad)
    return float(np.min(np.maximum(d_e, -d_c)))


def test_the_smallest_distance_to_several_bodies_is_every_points_bit_for_bit(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Paths past, into and through random composite bodies (with and without a corridor):
    the same minimum as over every point, with the exact distance of a tenth of the points
    or fewer."""
    rng = np.random.default_rng(36)
    measured: list[int] = []
    exact = cg.ellipsoid_signed_distance

    def spy(r_km: np.ndarray, semi_axes_km: np.ndarray) -> np.ndarray:
        measured.append(int(np.asarray(r_km).reshape(-1, 3).shape[0]))
        return exact(r_km, semi_axes_km)

    total = 0
    for case in range(200):
        geo = _bodies(rng, corridor=case % 2 == 0)
        start, end = rng.normal(size=3) * 0.4, rng.normal(size=3) * 0.05
        t = np.linspace(0.0, 1.0, 2001)[:, None]
        wiggle = 0.02 * np.sin(40.0 * t) * rng.normal(size=3)
        points = start + t * (end - start) + wiggle
        want = _min_before(points, geo)
        d_c = None
        if geo.port_km is not None:
            assert geo.axis is not None and geo.half_angle_rad is not None
            d_c = cg.cone_signed_distance(points, geo.port_km, geo.axis, geo.half_angle_rad)
        monkeypatch.setattr(cg, "ellipsoid_signed_distance", spy)
        got = cg._min_signed_distance(points, geo, d_c)
        monkeypatch.setattr(cg, "ellipsoid_signed_distance", exact)
        assert got == want
        total += points.shape[0] * (1 + geo.bodies_centre_km.shape[0])  # type: ignore[union-attr]
    assert sum(measured) < total / 10  # 6 % of them on these paths
