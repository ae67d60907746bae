"""Abort (passive) safety (issue 34 item 4): physics/abort_safety.py and its rows in the
constrained cone program (physics/guidance/constrained.py).

The checks are written here, not taken from the tool: a free drift is propagated with
the matrix exponential of the CW system written out below (scipy's ``expm``, paper
Eq. 1 with u = 0), membership of the keep-out zone from its definition
((x/a)² + (y/b)² + (z/c)² < 1), the corridor nodes from the plan's own ``modes``.
"""

from __future__ import annotations

import glob
import math
from pathlib import Path

import numpy as np
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest
from scipy.linalg import expm
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.config.io import config_from_dict, config_hash, resolved_dict
from cwrend_cli.output.tables import unit_of
from cwrend_cli.physics import abort_safety as ab
from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.guidance import constrained as cp
from cwrend_cli.physics.guidance.results import SolveStatus
from cwrend_cli.physics.params import Constraints, Corridor, KeepOut

runner = CliRunner()

N_MOTION = 0.00104218449  # rad/s, the paper's
U_MAX = 8e-4  # km/s²
DT = 1.0
ABORT_S = 5400.0  # about 0.9 of the paper's orbit
#: Sample interval of the independent drift check [s]: a drift near the zone moves a few
#: m/s in these problems, so a crossing shorter than a few mm could fall between samples.
DENSE_S = 0.5


def _cw(n: float) -> np.ndarray:
    """The CW system matrix A of ẋ = A x (paper Eq. 1, no control)."""
    a = np.zeros((6, 6))
    a[0:3, 3:6] = np.eye(3)
    a[3, 0], a[3, 4] = 3 * n**2, 2 * n
    a[4, 3] = -2 * n
    a[5, 2] = -(n**2)
    return a


_PHI_DENSE = np.array(
    [expm(_cw(N_MOTION) * t)[:3] for t in np.arange(0.0, ABORT_S + DENSE_S, DENSE_S)]
)


def _drift_levels(states: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(x/a)² + … of the free drifts from ``states`` (K, 6), every DENSE_S over ABORT_S."""
    r = np.einsum("tab,kb->kta", _PHI_DENSE, states)
    levels: np.ndarray = np.sum((r / axes) ** 2, axis=-1)
    return levels


def _states(x0: np.ndarray, controls: np.ndarray) -> np.ndarray:
    """Node states of held controls, Φ(Δt), Γ(Δt) from the augmented matrix exponential."""
    aug = np.zeros((9, 9))
    aug[:6, :6] = _cw(N_MOTION)
    aug[3:6, 6:9] = np.eye(3)
    e = expm(aug * DT)
    x = np.empty((controls.shape[0] + 1, 6))
    x[0] = x0
    for k, u in enumerate(controls):
        x[k + 1] = e[:6, :6] @ x[k] + e[:6, 6:] @ u
    return x


def _geometry(axes: np.ndarray, port: np.ndarray, axis: np.ndarray, deg: float) -> cg.Geometry:
    return cg.geometry(
        Constraints(keep_out=KeepOut(tuple(axes)), corridor=Corridor(tuple(port), tuple(axis), deg))
    )


def _constrained_nodes(
    modes: np.ndarray,
    r: np.ndarray,
    axes: np.ndarray,
    port: np.ndarray,
    axis: np.ndarray,
    deg: float,
) -> np.ndarray:
    """The rule: nodes 1 … N−1 outside the final approach in the corridor (the plan's
    corridor nodes, modes 1 and 3, and the last nodes of ``r`` inside the cone, to 1 mm) and
    farther than the largest semi-axis from the end (the port)."""
    far = np.linalg.norm(r - r[-1], axis=1) > np.max(axes)
    w = r - port
    inside = w @ axis >= math.cos(math.radians(deg)) * np.linalg.norm(w, axis=1) - 1e-6
    final = np.zeros(r.shape[0], dtype=bool)
    k = r.shape[0] - 1
    while k >= 0 and (inside[k] or k == r.shape[0] - 1):
        final[k] = True
        k -= 1
    nodes: np.ndarray = np.flatnonzero((modes == 2) & far & ~final)
    return nodes


SPHERE = np.array([0.2, 0.2, 0.2])
PORT, AXIS = np.array([0.0, 0.0, -0.25]), np.array([0.0, 0.0, -1.0])
#: At rest 1 km out along z: unconstrained, the plan round the sphere to the far port has a
#: node whose drift (the cross-track oscillation through 0) passes through the zone.
CROSSING_X0 = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


def test_a_plan_whose_drift_enters_the_zone_is_made_abort_safe() -> None:
    geo = _geometry(SPHERE, PORT, AXIS, 30.0)
    xf = np.r_[PORT, 0, 0, 0]
    plain = cp.plan(N_MOTION, DT, U_MAX, CROSSING_X0, xf, 200.0, 1.0, geo)
    safe = cp.plan(N_MOTION, DT, U_MAX, CROSSING_X0, xf, 200.0, 1.0, geo, abort_safe_s=ABORT_S)
    assert plain.status is SolveStatus.CONVERGED and safe.status is SolveStatus.CONVERGED
    x = _states(CROSSING_X0, plain.controls)
    nodes = _constrained_nodes(plain.modes, x[:, :3], SPHERE, PORT, AXIS, 30.0)
    entered = _drift_levels(x[nodes], SPHERE).min(axis=1) < 1.0
    assert entered.any()  # without abort safety some node's drift goes through the zone
    assert safe.slack_km == 0.0 and safe.abort_slack_km == 0.0
    x = _states(CROSSING_X0, safe.controls)
    nodes = _constrained_nodes(safe.modes, x[:, :3], SPHERE, PORT, AXIS, 30.0)
    assert _drift_levels(x[nodes], SPHERE).min() >= 1.0
    np.testing.assert_allclose(x[-1, :3], PORT, atol=1e-9)


@pytest.mark.slow
def test_random_abort_safe_plans_drift_clear_of_the_zone_from_every_node() -> None:
    """An independent dense check (every 0.5 s over 5,400 s from every constrained node) of
    30 random abort-safe plans: ellipsoids of 120–250 m semi-axes, a port on the surface
    along a random axis with a corridor of 20–40°, a start 0.6–1.2 km out in a random
    direction at up to 2 m/s, a 60–120 s horizon, ε ∈ {0, 0.5, 1}. A plan that is not
    converged or that softened a row (slack > 0) claims nothing and is not checked (4 of
    the first 12 here: 1 infeasible, 3 softened); at least 15 of the 30 must be checked."""
    rng = np.random.default_rng(34)
    checked = 0
    for _ in range(30):
        axes = rng.uniform(0.12, 0.25, 3)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        port = axis / math.sqrt(float(np.sum((axis / axes) ** 2)))  # on the surface
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        x0 = np.r_[rng.uniform(0.6, 1.2) * direction, rng.uniform(-2e-3, 2e-3, 3)]
        horizon = float(rng.integers(60, 121))
        deg = float(rng.uniform(20.0, 40.0))
        geo = _geometry(axes, port, axis, deg)
        res = cp.plan(
            N_MOTION, DT, U_MAX, x0, np.r_[port, 0, 0, 0], horizon,
            float(rng.choice([0.0, 0.5, 1.0])), geo, abort_safe_s=ABORT_S,
        )  # fmt: skip
        if res.status is not SolveStatus.CONVERGED or res.slack_km or res.abort_slack_km:
            continue
        x = _states(x0, res.controls)
        nodes = _constrained_nodes(res.modes, x[:, :3], axes, port, axis, deg)
        assert _drift_levels(x[nodes], axes).min(initial=np.inf) >= 1.0, (checked, nodes.size)
        checked += 1
    assert checked >= 15


def test_the_chord_acceleration_bounds_the_drift_everywhere() -> None:
    """A_j (abort_safety.chord_accelerations) ≥ ‖r̈‖ of the drift at every dense time of
    its chord, r̈ = A_rv-rows of the CW system (paper Eq. 1, u = 0)."""
    rng = np.random.default_rng(4)
    x = np.c_[rng.uniform(-2, 2, (20, 3)), rng.uniform(-0.05, 0.05, (20, 3))]
    table = ab.drift_table(N_MOTION, 600.0)
    d = np.einsum("jab,kb->kja", table.phis, x)
    bound = ab.chord_accelerations(N_MOTION, table.h_s, d)
    a_full = np.array([expm(_cw(N_MOTION) * t) for t in np.arange(0.0, 600.0 + 0.1, 0.1)])
    states = np.einsum("tab,kb->kta", a_full, x)
    accel = np.linalg.norm(np.einsum("ab,ktb->kta", _cw(N_MOTION)[3:], states), axis=-1)
    per_chord = accel[:, :-1].reshape(20, 60, 100).max(axis=2)
    assert np.all(per_chord <= bound * (1 + 1e-12))


#: The last node of a measured trajectory, and so exempt with its neighbourhood: far away.
FAR_END = np.array([0.0, 5.0, 0.0, 0.0, 0.0, 0.0])


def test_the_truth_measure_of_a_drift_through_the_centre() -> None:
    """At rest 1 km out along z the drift is z = cos(nt) (paper Eq. 11's Φ_zz), x = y = 0: it
    passes the centre of a 200 m sphere at t = π/(2n) ≈ 1,507 s, distance −0.2 km; the
    sampled minimum is within the drift's speed there (n · 1 km) times half a re-sample
    (0.05 s), 0.05 m."""
    x = np.array([CROSSING_X0, FAR_END])
    m = ab.measure_abort(x, N_MOTION, cg.Geometry(SPHERE, None, None, None), ABORT_S)
    assert m.checked_steps == 1 and m.unsafe_steps == 1 and m.unsafe
    assert m.min_distance_km == pytest.approx(-0.2, abs=N_MOTION * 0.05)


def test_the_truth_measure_of_a_stationary_point() -> None:
    """At rest on the along-track axis a chaser stays put (CW, paper Eq. 11): 800 m from the
    surface of a 200 m sphere for ever."""
    x = np.array([[0.0, 1.0, 0.0, 0, 0, 0]] * 2 + [FAR_END])
    m = ab.measure_abort(x, N_MOTION, cg.Geometry(SPHERE, None, None, None), ABORT_S)
    assert m.checked_steps == 2 and m.unsafe_steps == 0 and not m.unsafe
    assert m.min_distance_km == pytest.approx(0.8, abs=1e-12)


def test_the_final_approach_in_the_corridor_is_exempt() -> None:
    """The terminal node and the contiguous nodes inside the cone before it are exempt; a
    node inside the cone before a node outside it is not."""
    geo = _geometry(SPHERE, PORT, AXIS, 30.0)
    r = np.array([[0, 0, -0.4], [0.3, 0, -0.3], [0, 0, -0.5], [0, 0.01, -0.3], [0, 0, -0.25]])
    assert ab.final_approach_start(geo, r) == 2
    assert ab.final_approach_start(cg.Geometry(SPHERE, None, None, None), r) == 4
    # and within the largest semi-axis (0.2 km) of the last node
    np.testing.assert_array_equal(ab.exempt(geo, r), [True, False, True, True, True])


ABORT_SET = [
    arg
    for value in (
        "constraints.keep_out.semi_axes_km=[0.2, 0.2, 0.2]",
        "constraints.corridor.port_km=[0, 0, -0.25]",
        "constraints.corridor.axis=[0, 0, -1]",
        "constraints.corridor.half_angle_deg=30",
        "scenario.x0=[0.001, 0, 1.0, -0.001, 0.0015, 0]",
        "scenario.horizon_s=400",
        "guidance.t_resolve_s=100",
    )
    for arg in ("--set", value)
]
RUN_COLUMNS = {"abort_min_distance_km", "abort_unsafe_steps", "abort_unsafe"}


def test_an_abort_safe_campaign_writes_the_abort_safety_of_its_runs(tmp_path: Path) -> None:
    config = tmp_path / "c.toml"
    config.write_text(f'[output]\ndir = "{tmp_path / "out"}"\n', encoding="utf-8")
    args = ["ablate", str(config), "--seeds", "1", "--arch", "mtf_fixed_socp", "--workers", "1"]
    # no run time limit: the default is a multiple of the run's cost on a typical machine,
    # and a test waits for the run to end, whatever the machine's speed or load
    no_limit = ["--set", "output.run_timeout_s=86400"]
    result = runner.invoke(
        app, [*args, "-q", *ABORT_SET, *no_limit, "--set", f"constraints.abort_safe_s={ABORT_S}"]
    )
    assert result.exit_code == 0, result.output
    runs = pq.read_table(glob.glob(str(tmp_path / "out" / "*" / "runs.parquet"))[0])
    assert set(runs.column_names) >= RUN_COLUMNS
    for name in RUN_COLUMNS:
        field = runs.schema.field(name)
        assert field.metadata[b"unit"].decode() == unit_of(name)
        assert field.metadata[b"description"]
    row = runs.to_pylist()[0]
    steps = ds.dataset(glob.glob(str(tmp_path / "out" / "*" / "steps"))[0], partitioning="hive")
    x = steps.to_table(columns=["x_km", "y_km", "z_km", "vx_km_s", "vy_km_s", "vz_km_s"])
    geo = _geometry(SPHERE, PORT, AXIS, 30.0)
    m = ab.measure_abort(x.to_pandas().to_numpy(), N_MOTION, geo, ABORT_S)
    assert row["abort_min_distance_km"] == m.min_distance_km
    assert row["abort_unsafe_steps"] == m.unsafe_steps
    assert row["abort_unsafe"] is m.unsafe


def test_without_abort_safety_no_abort_column_and_the_same_hash() -> None:
    on = {"constraints": {"keep_out": {"semi_axes_km": [0.2, 0.2, 0.2]}}}
    cfg = config_from_dict(on)
    assert "abort_safe_s" not in resolved_dict(cfg)["constraints"]
    assert config_hash(cfg) == config_hash(config_from_dict(on))
    with_abort = config_from_dict({"constraints": {**on["constraints"], "abort_safe_s": 60.0}})
    assert config_hash(with_abort) != config_hash(cfg)
    assert resolved_dict(with_abort)["constraints"]["abort_safe_s"] == 60.0


@pytest.mark.parametrize(
    ("sets", "message"),
    [
        (["constraints.abort_safe_s=0"], "constraints.abort_safe_s = 0"),
        (["constraints.abort_safe_s=-5400"], "constraints.abort_safe_s = -5400"),
        (["constraints.abort_safe_s=1e6"], "constraints.abort_safe_s"),
        (["constraints.abort_safe_s='orbit'"], "constraints.abort_safe_s"),
        (
            ["constraints.abort_safe_s=5400", "constraints.sigma_margin=1"],
            "constraints.abort_safe_s = 5400: abort safety keeps the free drift out of the "
            "keep-out zone",
        ),
    ],
    ids=["zero", "negative", "above a day", "not a number", "no keep-out zone"],
)
def test_a_bad_abort_config_exits_2_naming_the_field(
    sets: list[str], message: str, tmp_path: Path
) -> None:
    config = tmp_path / "c.toml"
    config.write_text("", encoding="utf-8")
    args = ["config", "validate", str(config)]
    result = runner.invoke(app, args + [a for s in sets for a in ("--set", s)])
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert "Traceback" not in result.output
