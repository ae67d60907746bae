"""The turning-constraint SCP's compiled kernels give the scalar functions' numbers bit for
bit (issue 34: the cost of a tumbling run).

Each test writes the formula the code had before — the scalar functions of
:mod:`cwrend_cli.physics.constraints` called step by step — and compares on random inputs
exactly (``np.array_equal``: no tolerance, bits are the claim; whole tumbling runs are
pinned by ``test_tumbling_guidance`` and ``test_abort_tumbling``).
"""

from __future__ import annotations

import numpy as np

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
