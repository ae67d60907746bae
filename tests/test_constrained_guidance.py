"""The constrained cone program (issue 32 item 2, physics/guidance/constrained.py).

The checks are written here, not taken from the tool: the arcs between nodes are
propagated densely with the matrix exponential of the CW system written out below
(zero-order hold: the control enters as a constant input), membership of the
unsafe set from its definition ((x/a)² + … < 1 and the angle to the corridor axis).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.guidance import constrained as cp
from cwrend_cli.physics.guidance.results import SolveStatus
from cwrend_cli.physics.params import Constraints, Corridor, KeepOut

N_MOTION = 0.00104218449  # rad/s, the paper's
U_MAX = 8e-4  # km/s²
DT = 1.0


def _zoh(n: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Φ(h), Γ(h) of ẋ = A x + B u with u held: expm of [[A, B], [0, 0]] h."""
    a = np.zeros((9, 9))
    a[0:3, 3:6] = np.eye(3)
    a[3, 0], a[3, 4] = 3 * n**2, 2 * n
    a[4, 3] = -2 * n
    a[5, 2] = -(n**2)
    a[3:6, 6:9] = np.eye(3)
    e = expm(a * h)
    return e[:6, :6], e[:6, 6:]


def _dense(x0: np.ndarray, controls: np.ndarray, per_step: int = 40) -> np.ndarray:
    """Positions every DT/per_step along the held-control arcs."""
    phi, gam = _zoh(N_MOTION, DT / per_step)
    x, out = x0.copy(), [x0[:3].copy()]
    for u in controls:
        for _ in range(per_step):
            x = phi @ x + gam @ u
            out.append(x[:3].copy())
    return np.array(out)


def _unsafe(
    points: np.ndarray, axes: np.ndarray, port: np.ndarray, axis: np.ndarray, deg: float
) -> np.ndarray:
    inside = np.sum((points / axes) ** 2, axis=1) < 1.0
    w = points - port
    in_cone = w @ axis >= math.cos(math.radians(deg)) * np.linalg.norm(w, axis=1)
    unsafe: np.ndarray = inside & ~in_cone
    return unsafe


def _geometry(axes: np.ndarray, port: np.ndarray, axis: np.ndarray, deg: float) -> cg.Geometry:
    return cg.geometry(
        Constraints(keep_out=KeepOut(tuple(axes)), corridor=Corridor(tuple(port), tuple(axis), deg))
    )


def test_a_crossing_path_goes_round_the_zone_to_the_port() -> None:
    axes, port, axis = np.array([0.2, 0.2, 0.2]), np.array([0, 0, -0.25]), np.array([0, 0, -1.0])
    x0 = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])  # straight through the centre unconstrained
    res = cp.plan(
        N_MOTION, DT, U_MAX, x0, np.r_[port, 0, 0, 0], 200.0, 1.0, _geometry(axes, port, axis, 30.0)
    )
    assert res.status is SolveStatus.CONVERGED and res.slack_km == 0.0
    dense = _dense(x0, res.controls)
    assert not _unsafe(dense, axes, port, axis, 30.0).any()
    np.testing.assert_allclose(dense[-1], port, atol=1e-9)
    assert res.scp_iterations <= cp.SCP_MAX_ITER


def test_the_corridor_holds_at_every_corridor_node() -> None:
    axes = np.array([0.15, 0.25, 0.15])
    port, axis, deg = np.array([0.0, -0.25, 0.0]), np.array([0.0, -1.0, 0.0]), 20.0
    x0 = np.array([0.05, -1.2, 0.0, 0.0, 0.0, 0.0])  # in the corridor, far out
    res = cp.plan(
        N_MOTION, DT, U_MAX, x0, np.r_[port, 0, 0, 0], 120.0, 0.5, _geometry(axes, port, axis, deg)
    )
    assert res.status is SolveStatus.CONVERGED
    nodes = np.flatnonzero(np.isin(res.modes, (1, 3)))
    assert nodes.size > 10
    w = res.positions[nodes] - port
    excess = np.linalg.norm(w - np.outer(w @ axis, axis), axis=1) - math.tan(math.radians(deg)) * (
        w @ axis
    )
    assert np.all(excess <= 1e-7)  # Clarabel's tolerance, in km


def test_random_constrained_plans_never_enter_the_unsafe_set_between_nodes() -> None:
    """An independent dense check of planned ZOH arcs on random problems (40 sub-samples
    a step); 40 here (the suite stays fast), 1,000 run once when this was written."""
    rng = np.random.default_rng(32)
    checked = 0
    for _ in range(40):
        axes = rng.uniform(0.1, 0.3, 3)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        surface = axis / math.sqrt(float(np.sum((axis / axes) ** 2)))
        port = surface * rng.uniform(1.0, 1.2)
        deg = float(rng.uniform(10, 45))
        start = rng.normal(size=3)
        x0 = np.r_[0.8 * start / np.linalg.norm(start), rng.normal(size=3) * 1e-4]
        res = cp.plan(
            N_MOTION,
            DT,
            U_MAX,
            x0,
            np.r_[port, 0, 0, 0],
            100.0,
            float(rng.choice([0.0, 0.5, 1.0])),
            _geometry(axes, port, axis, deg),
        )
        if res.status is not SolveStatus.CONVERGED or res.slack_km > 0.0:
            continue  # softened: no safe plan was claimed
        dense = _dense(x0, res.controls)
        assert not _unsafe(dense, axes, port, axis, deg).any()
        checked += 1
    assert checked >= 30


def test_a_vanishing_covariance_margin_gives_the_unmargined_plan() -> None:
    axes, port, axis = np.array([0.2, 0.2, 0.2]), np.array([0, 0, -0.25]), np.array([0, 0, -1.0])
    geo = _geometry(axes, port, axis, 30.0)
    x0 = np.array([0.1, 0.0, 1.0, 0.0, 0.0, 0.0])
    xf = np.r_[port, 0, 0, 0]
    bare = cp.plan(N_MOTION, DT, U_MAX, x0, xf, 150.0, 1.0, geo)
    tiny = cp.plan(N_MOTION, DT, U_MAX, x0, xf, 150.0, 1.0, geo, np.eye(3) * 1e-30, 3.0)
    np.testing.assert_allclose(tiny.controls, bare.controls, atol=1e-12)
    # a 10 m σ at k = 3 keeps the nodes 30 m further out than the unmargined plan
    wide = cp.plan(N_MOTION, DT, U_MAX, x0, xf, 150.0, 1.0, geo, np.eye(3) * 1e-4, 3.0)
    assert wide.status is SolveStatus.CONVERGED
    keep_out = wide.modes == 2
    level = np.sqrt(np.sum((wide.positions[keep_out] / axes) ** 2, axis=1))
    assert np.min(np.linalg.norm(wide.positions[keep_out], axis=1) - 0.2) >= 0.03 - 1e-7
    assert np.all(level > 1.0)


def test_without_a_keep_out_zone_the_plan_is_the_unconstrained_one() -> None:
    geo = cg.geometry(Constraints(corridor=Corridor((0, 0, -0.25), (0, 0, -1), 30.0)))
    x0 = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    res = cp.plan(N_MOTION, DT, U_MAX, x0, np.array([0, 0, -0.25, 0, 0, 0]), 100.0, 1.0, geo)
    assert res.scp_iterations == 0 and not res.modes.any()
    assert res.status is SolveStatus.CONVERGED
