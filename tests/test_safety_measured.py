"""Safety measured on the true trajectory (issue 32 item 3): per run and per step.

The trajectories here are built in the test with known answers (straight lines at
constant velocity, whose cubic Hermite arcs are exact), and the expected values
are computed from the definitions written out in the test: the sphere's distance
‖r‖ − R, the angle to the axis by arccos. A run is measured only when its config
has constraints: without them no column changes (tests/test_same_numbers.py
compares the paper campaigns' columns to its fixture's too).
"""

from __future__ import annotations

import dataclasses
import glob
import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.output.tables import unit_of
from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.guidance import constrained
from cwrend_cli.physics.params import Constraints, Corridor, KeepOut

R = 0.2  # km
SPHERE = cg.geometry(Constraints(keep_out=KeepOut((R, R, R))))
runner = CliRunner()


def _line(start: np.ndarray, velocity: np.ndarray, n_steps: int, dt: float) -> np.ndarray:
    """States of uniform straight motion at t_k = k dt (N+1, 6)."""
    t = np.arange(n_steps + 1)[:, None] * dt
    return np.hstack([start + t * velocity, np.broadcast_to(velocity, (n_steps + 1, 3))])


def test_a_straight_pass_through_the_centre_is_measured() -> None:
    v = np.array([0.0, 0.0, -0.01])  # 10 m/s along -z
    x = _line(np.array([0.0, 0.0, 1.0]), v, 200, 1.0)  # through the origin at t = 100 s
    sf = cg.measure_safety(x, 1.0, SPHERE)
    assert sf.violated
    assert sf.min_distance_km == pytest.approx(-R, abs=1e-12)
    # inside for |1 - 0.01 t| < 0.2: t in (80, 120), 40 s, sampled every 0.05 s
    assert sf.unsafe_time_s == pytest.approx(40.0, abs=0.05 + 1e-9)
    assert sf.approach_speed_km_s == pytest.approx(0.01)
    assert math.isnan(sf.corridor_violation_deg) and math.isnan(sf.approach_angle_deg)
    expected_nodes = np.linalg.norm(x[:, :3], axis=1) - R
    np.testing.assert_allclose(sf.step_distance_km, expected_nodes, atol=1e-12)


def test_an_entry_between_two_nodes_is_caught() -> None:
    """Nodes 1 s apart on either side of a 0.2 km sphere at 0.5 km/s: no node is inside."""
    v = np.array([0.0, 0.0, -0.5])
    x = _line(np.array([0.0, 0.15, 1.25]), v, 5, 1.0)  # z = 1.25, 0.75, 0.25, -0.25, ...
    nodes = np.linalg.norm(x[:, :3], axis=1) - R
    assert np.all(nodes > 0)
    sf = cg.measure_safety(x, 1.0, SPHERE)
    # closest approach: the line at y = 0.15 passes 0.15 km from the centre
    assert sf.min_distance_km == pytest.approx(0.15 - R, abs=1e-12)
    assert sf.violated
    assert np.all(sf.step_distance_km > 0)


def test_a_path_that_stays_away_is_safe() -> None:
    x = _line(np.array([0.5, 0.0, 1.0]), np.array([0.0, 0.0, -0.01]), 200, 1.0)
    sf = cg.measure_safety(x, 1.0, SPHERE)
    assert not sf.violated
    assert sf.unsafe_time_s == 0.0
    assert sf.min_distance_km == pytest.approx(0.5 - R, abs=1e-12)


def test_the_hermite_arcs_reproduce_a_cubic() -> None:
    coef = np.array([[0.1, -0.2, 0.3], [0.01, 0.02, -0.03], [1e-3, 2e-3, 0], [1e-4, 0, -1e-4]])
    t = np.arange(11.0)
    r = sum(c * t[:, None] ** i for i, c in enumerate(coef))
    v = sum(i * c * t[:, None] ** (i - 1) for i, c in enumerate(coef) if i)
    arcs = cg.hermite_arcs(np.hstack([r, v]), 1.0, 4)
    tau = t[:-1, None] + np.linspace(0, 1, 5)[None, :]
    exact = sum(c * tau[..., None] ** i for i, c in enumerate(coef))
    np.testing.assert_allclose(arcs, exact, atol=1e-13)


def test_the_corridor_measures_angle_and_approach() -> None:
    geo = cg.geometry(
        Constraints(keep_out=KeepOut((R, R, R)), corridor=Corridor((0, 0, 0.25), (0, 0, 1), 30.0))
    )
    # straight down the axis to the port, then stopping there: inside the cone all the way
    down = _line(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -0.0075]), 100, 1.0)
    sf = cg.measure_safety(down, 1.0, geo)
    assert not sf.violated and sf.corridor_violation_deg == 0.0
    assert sf.approach_angle_deg == pytest.approx(0.0, abs=1e-6)
    # across the zone below the port, along -x: the angles inside are those of the nodes'
    side = _line(np.array([0.35, 0.0, 0.1]), np.array([-0.007, 0.0, 0.0]), 100, 1.0)
    sf = cg.measure_safety(side, 1.0, geo)
    w = side[:, :3] - np.array([0.0, 0.0, 0.25])
    inside = np.linalg.norm(side[:, :3], axis=1) < R
    angles = np.degrees(np.arccos(w[inside, 2] / np.linalg.norm(w[inside], axis=1)))
    assert sf.violated
    assert float(angles.max()) - 30.0 <= sf.corridor_violation_deg <= 180.0 - 30.0
    assert sf.approach_angle_deg == pytest.approx(90.0, abs=1e-9)


CONSTRAINED = [
    "--set",
    "constraints.keep_out.semi_axes_km=[0.2, 0.2, 0.2]",
    "--set",
    "constraints.corridor.port_km=[0, 0, -0.25]",
    "--set",
    "constraints.corridor.axis=[0, 0, -1]",
    "--set",
    "constraints.corridor.half_angle_deg=30",
]
RUN_COLUMNS = {
    "safety_min_distance_km",
    "safety_unsafe_time_s",
    "safety_corridor_violation_deg",
    "safety_approach_speed_km_s",
    "safety_approach_angle_deg",
    "safety_violated",
}
STEP_COLUMNS = {"safety_distance_km"}


def _ablate(tmp_path: Path, *extra: str) -> Path:
    config = tmp_path / "c.toml"
    config.write_text(f'[output]\ndir = "{tmp_path / "out"}"\n', encoding="utf-8")
    args = ["ablate", str(config), "--seeds", "1", "--arch", "mtf_fixed", "--workers", "1"]
    result = runner.invoke(app, [*args, "-q", *extra])
    assert result.exit_code == 0, result.output
    return Path(glob.glob(str(tmp_path / "out" / "*"))[0])


def test_a_constrained_campaign_writes_the_safety_of_its_runs(tmp_path: Path) -> None:
    campaign = _ablate(tmp_path, *CONSTRAINED)
    runs = pq.read_table(campaign / "runs.parquet")
    assert set(runs.column_names) >= RUN_COLUMNS
    row = runs.to_pylist()[0]
    # the unconstrained plan from 31 km along z crosses the sphere to reach the far port
    assert row["safety_violated"] is True and row["safety_min_distance_km"] < 0
    for name in RUN_COLUMNS:
        field = runs.schema.field(name)
        assert field.metadata[b"unit"].decode() == unit_of(name)
        assert field.metadata[b"description"]
    steps = ds.dataset(campaign / "steps", partitioning="hive").to_table()
    assert set(steps.column_names) >= STEP_COLUMNS
    # the nodes are among the sub-samples: the run's minimum is at most theirs
    assert row["safety_min_distance_km"] <= float(np.min(steps["safety_distance_km"]))


def test_an_unconstrained_campaign_has_no_safety_columns(tmp_path: Path) -> None:
    campaign = _ablate(tmp_path)
    runs = pq.read_table(campaign / "runs.parquet")
    steps = ds.dataset(campaign / "steps", partitioning="hive").to_table()
    assert not RUN_COLUMNS & set(runs.column_names)
    assert not STEP_COLUMNS & set(steps.column_names)
    assert not [c for c in runs.column_names + steps.column_names if c.startswith("safety")]


def test_the_screened_minimum_is_the_minimum_over_every_sub_sample() -> None:
    """Exact φ is computed only where its bounds allow the minimum: the same minimum."""
    geo = cg.geometry(
        Constraints(
            keep_out=KeepOut((0.2, 0.35, 0.15)), corridor=Corridor((0, 0, -0.25), (0, 0, -1), 30.0)
        )
    )
    rng = np.random.default_rng(3)
    for _ in range(20):
        x = np.cumsum(rng.normal(size=(101, 6)) * 0.02, axis=0)
        arcs = cg.hermite_arcs(x, 1.0, cg.SAFETY_SUBSTEPS)
        every = cg.signed_distance(arcs.reshape(-1, 3), geo)
        assert cg.measure_safety(x, 1.0, geo).min_distance_km == float(every.min())


SHORT = """
[scenario]
horizon_s = 200.0
x0 = [0.0, 0.02, 1.0, 0.0, 0.0, 0.0]
[degradation]
windows = []
[constraints.keep_out]
semi_axes_km = [0.2, 0.2, 0.2]
[constraints.corridor]
port_km = [0.0, 0.0, -0.25]
axis = [0.0, 0.0, -1.0]
half_angle_deg = 30.0
"""


def _run_short(tmp_path: Path, archs: str) -> Path:
    """``cwrend run`` of :data:`SHORT` with the architectures ``archs``: its output folder."""
    config = tmp_path / "short.toml"
    config.write_text(SHORT, encoding="utf-8")
    out = tmp_path / "run"
    args = ["run", str(config), "-a", archs, "--no-rrd", "-o", str(out)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    return out


def test_the_constrained_socp_flies_round_the_zone_and_shooting_does_not(tmp_path: Path) -> None:
    """1 km above a 200 m sphere, the port below it: the shooting plan goes through, the
    cone program's constrained re-solves keep the true path out (sigma_margin 0: its
    margin is the chord's; the true path is the estimate's, 1 m σ away)."""
    out = _run_short(tmp_path, "mtf_fixed,mtf_fixed_socp")
    rows = {r["arch"]: r for r in pq.read_table(out / "summary.parquet").to_pylist()}
    assert rows["mtf_fixed"]["safety_violated"] is True
    assert rows["mtf_fixed_socp"]["safety_violated"] is False
    assert rows["mtf_fixed_socp"]["miss_km"] < 1e-3
    solves = pq.read_table(out / "solves.parquet").to_pandas()
    socp = solves[solves["arch"] == "mtf_fixed_socp"]
    assert (socp["fallback_step"] == "socp_scp").all()
    assert (socp["scp_iterations"] >= 1).all() and (socp["slack_km"] == 0.0).all()
    assert (solves[solves["arch"] == "mtf_fixed"]["scp_iterations"] == 0).all()


def test_the_solves_count_the_programs_left_to_clarabel(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``fallback_programs`` is the re-solve's ``ConstrainedPlan.fallbacks`` (0 for a
    shooting re-solve): the plans are marked with 7 fallbacks here, and every constrained
    re-solve's row carries 7; its ``iterations`` sum every program's, so at least one a
    program."""
    real = constrained.plan

    def marked(*args: Any, **kwargs: Any) -> constrained.ConstrainedPlan:
        return dataclasses.replace(real(*args, **kwargs), fallbacks=7)

    monkeypatch.setattr(constrained, "plan", marked)
    out = _run_short(tmp_path, "mtf_fixed,mtf_adaptive_socp")
    solves = pq.read_table(out / "solves.parquet").to_pandas()
    socp = solves[solves["arch"] == "mtf_adaptive_socp"]
    assert len(socp) > 5 and (socp["fallback_programs"] == 7).all()
    assert (socp["iterations"] >= socp["scp_iterations"]).all()
    assert (solves[solves["arch"] == "mtf_fixed"]["fallback_programs"] == 0).all()


def test_a_constrained_campaign_states_its_violation_rate(tmp_path: Path) -> None:
    campaign = _ablate(tmp_path, *CONSTRAINED)
    stats = pq.read_table(campaign / "ablation.parquet").to_pandas()
    share = stats[(stats["metric"] == "safety_violated") & (stats["statistic"] == "share")]
    assert len(share) == 1
    row = share.iloc[0]
    # one run, through the zone: 1 of 1, Wilson's interval [0.2065, 1]
    assert row["value"] == 1.0 and row["n"] == 1
    assert row["ci_low"] == pytest.approx(0.2065, abs=1e-4) and row["ci_high"] == 1.0
    assert {"median", "p1"} <= set(stats[stats["metric"] == "safety_min_distance_km"]["statistic"])


def test_an_unconstrained_campaign_has_no_safety_statistics(tmp_path: Path) -> None:
    stats = pq.read_table(_ablate(tmp_path) / "ablation.parquet").to_pandas()
    assert not stats["metric"].str.startswith("safety").any()
