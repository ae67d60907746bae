"""``cwrend table``: the safety, docking and re-solve values (issues 32 and 34 studies).

A synthetic campaign of one architecture: six runs (five ok, one failed) with hand-set
safety columns, its statistics written by the campaign's own functions
(:func:`cwrend_cli.campaign.statistics.safety` and ``abort_safety``), and a solves/
table of hand-set re-solves. Each value is checked against the number computed here
by hand from those columns (CSV output: unrounded, in the header's unit).
"""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign.statistics import abort_safety, safety
from cwrend_cli.cli import app

runner = CliRunner()
ARCH = "mtf_fixed_socp"
# five ok runs and a failed one (its values must count nowhere)
MIN_DISTANCE_KM = [0.0190, -0.0040, 0.0205, 0.0030, -0.0012, -0.5]
DOCK_POSITION_KM = [0.0010, 0.0004, 0.0020, 0.0007, 0.0013, 9.0]
DOCK_VELOCITY_KM_S = [2e-6, 1e-5, 4e-6, 3e-6, 6e-6, 1.0]
ABORT_UNSAFE = [False, True, False, False, False, True]
ABORT_DISTANCE_KM = [0.0100, -0.0020, 0.0150, 0.0080, 0.0090, -1.0]
STATUS = ["ok"] * 5 + ["failed"]


def _runs(safety_columns: bool = True) -> pd.DataFrame:
    runs = pd.DataFrame(
        {
            "run_key": [f"r{i}" for i in range(6)],
            "point": "base",
            "arch": ARCH,
            "seed": range(6),
            "status": STATUS,
            "miss_km": 0.001,
            "delta_v_km_s": 0.11,
            "n_solves": 3,
            "n_infeasible": 0,
            "n_failed": 0,
        }
    )
    if safety_columns:
        runs["safety_min_distance_km"] = MIN_DISTANCE_KM
        runs["safety_violated"] = [d < 0 for d in MIN_DISTANCE_KM]
        runs["safety_unsafe_time_s"] = [0.0, 0.5, 0.0, 0.0, 0.25, 9.0]
        runs["safety_dock_position_error_km"] = DOCK_POSITION_KM
        runs["safety_dock_velocity_error_km_s"] = DOCK_VELOCITY_KM_S
        runs["abort_unsafe"] = ABORT_UNSAFE
        runs["abort_min_distance_km"] = ABORT_DISTANCE_KM
    return runs


# per ok run: an initial solve (never counted) and three re-solves
SCP = {"r0": [1, 2, 1], "r1": [3, 8, 1], "r2": [1, 1, 1], "r3": [2, 2, 4], "r4": [1, 5, 1]}
SLACK_KM = {"r0": [0, 0, 0], "r1": [0.01, 0.02, 0], "r2": [0, 0, 0], "r3": [0, 0, 0.003],
            "r4": [0, 0, 0]}  # fmt: skip
WALL_MS = {"r0": [10, 20, 30], "r1": [40, 50, 60], "r2": [70, 80, 90], "r3": [100, 110, 120],
           "r4": [130, 140, 1000]}  # fmt: skip


def _solves(safety_columns: bool = True) -> pd.DataFrame:
    rows = []
    for key in [*SCP, "r5"]:
        # the initial solve and the failed run r5: outliers that must not count
        rows.append({"run_key": key, "kind": "initial", "scp": 99, "slack": 9.0, "ms": 1e6})
        for k in range(3):
            failed = key == "r5"
            rows.append(
                {
                    "run_key": key,
                    "kind": "resolve",
                    "scp": 99 if failed else SCP[key][k],
                    "slack": 9.0 if failed else SLACK_KM[key][k],
                    "ms": 1e6 if failed else WALL_MS[key][k],
                }
            )
    frame = pd.DataFrame(rows)
    out = pd.DataFrame(
        {
            "run_key": frame["run_key"],
            "kind": frame["kind"],
            "fallback_step": "socp",
            "wall_time_ms": frame["ms"].astype(float),
        }
    )
    if safety_columns:
        out["scp_iterations"] = frame["scp"].astype("int64")
        out["slack_km"] = frame["slack"].astype(float)
    return out


def _campaign(root: Path, safety_columns: bool = True) -> Path:
    path = root / ("safe" if safety_columns else "plain")
    (path / "solves").mkdir(parents=True)
    (path / "manifest.json").write_text(json.dumps({"command": "ablate", "archs": [ARCH]}))
    runs = _runs(safety_columns)
    runs.to_parquet(path / "runs.parquet")
    _solves(safety_columns).to_parquet(path / "solves" / "part-0.parquet")
    stats = [safety(runs, ["point", "arch"]), abort_safety(runs, ["point", "arch"])]
    held = [s for s in stats if not s.empty]
    frame = pd.concat(held, ignore_index=True) if held else pd.DataFrame()
    if frame.empty:  # a campaign without constraints: its other statistics only
        frame = pd.DataFrame(
            {
                "point": ["base"],
                "arch": [ARCH],
                "kind": ["marginal"],
                "metric": ["miss_km"],
                "statistic": ["mean"],
                "value": [0.001],
                "ci_low": [0.001],
                "ci_high": [0.001],
                "n": [5],
            }
        )
    frame.to_parquet(path / "ablation.parquet")
    return path


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _campaign(tmp_path_factory.mktemp("safety"))


def _csv(path: Path, metric: str) -> dict[str, float]:
    result = runner.invoke(app, ["table", str(path), "--metric", metric, "--format", "csv"])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(io.StringIO(result.stdout)))
    assert len(rows) == 1
    return {k: float(v) for k, v in rows[0].items() if k != "architecture"}


def _wilson(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson (1927) score interval, written out here: (p + z²/2n ± z√(p(1−p)/n + z²/4n²))
    / (1 + z²/n); z the two-sided 95 % normal quantile."""
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def test_violated_pct_is_the_share_of_ok_runs_with_its_wilson_interval(campaign: Path) -> None:
    # ok runs r1 and r4 entered the set: 2 of 5 (the failed r5 does not count)
    row = _csv(campaign, "violated_pct")
    head = "runs that entered the unsafe set [%] (95 % Wilson)"
    lo, hi = _wilson(2, 5)
    assert row[head] == pytest.approx(40.0, rel=1e-12)
    assert row[f"{head} low"] == pytest.approx(100 * lo, rel=1e-12)
    assert row[f"{head} high"] == pytest.approx(100 * hi, rel=1e-12)


def test_min_distance_median_and_p1_are_stored_and_min_is_the_worst_run_in_m(
    campaign: Path,
) -> None:
    ok = sorted(MIN_DISTANCE_KM[:5])  # -4.0, -1.2, 3.0, 19.0, 20.5 m
    # numpy's linear percentile of 5 values: p1 at rank 0.04 between the two smallest
    p1 = ok[0] + 0.04 * (ok[1] - ok[0])
    row = _csv(campaign, "median.min_distance:bare,p1.min_distance:bare,min.min_distance")
    assert row["median closest approach to the unsafe set [m]"] == pytest.approx(3.0, rel=1e-12)
    assert row["p1 closest approach to the unsafe set [m]"] == pytest.approx(1e3 * p1, rel=1e-12)
    assert row["min closest approach to the unsafe set [m]"] == pytest.approx(-4.0, rel=1e-12)


def test_docking_errors_median_and_max_in_m_and_mm_s(campaign: Path) -> None:
    metric = "median.dock_position,max.dock_position,median.dock_velocity,max.dock_velocity"
    row = _csv(campaign, metric)
    assert row["median docking position error [m]"] == pytest.approx(1.0, rel=1e-12)
    assert row["max docking position error [m]"] == pytest.approx(2.0, rel=1e-12)
    assert row["median docking velocity error [mm/s]"] == pytest.approx(4.0, rel=1e-12)
    assert row["max docking velocity error [mm/s]"] == pytest.approx(10.0, rel=1e-12)


def test_scp_iterations_mean_and_max_over_the_resolves_of_ok_runs(campaign: Path) -> None:
    every = [x for xs in SCP.values() for x in xs]  # 15 re-solves, no initial solve
    row = _csv(campaign, "mean.scp_iterations,max.scp_iterations")
    assert row["mean SCP iterations per re-solve [-]"] == pytest.approx(sum(every) / 15, rel=1e-12)
    assert row["max SCP iterations per re-solve [-]"] == 8


def test_slack_pct_is_the_share_of_resolves_that_needed_a_path_slack(campaign: Path) -> None:
    # r1's first two and r3's last: 3 of 15 re-solves
    row = _csv(campaign, "slack_pct")
    assert row["re-solves with a path slack [%]"] == pytest.approx(20.0, rel=1e-12)


def test_resolve_ms_mean_and_p95_over_the_resolves(campaign: Path) -> None:
    every = sorted(x for xs in WALL_MS.values() for x in xs)
    # linear percentile of 15 values: rank 0.95 × 14 = 13.3, between the two largest
    p95 = every[13] + 0.3 * (every[14] - every[13])
    row = _csv(campaign, "mean.resolve_ms,p95.resolve_ms")
    assert row["mean re-solve time [ms]"] == pytest.approx(sum(every) / 15, rel=1e-12)
    assert row["p95 re-solve time [ms]"] == pytest.approx(p95, rel=1e-12)


def test_abort_pct_and_abort_distance(campaign: Path) -> None:
    row = _csv(campaign, "abort_pct,median.abort_distance:bare")
    head = "runs with an unsafe abort drift [%] (95 % Wilson)"
    lo, hi = _wilson(1, 5)
    assert row[head] == pytest.approx(20.0, rel=1e-12)
    assert (row[f"{head} low"], row[f"{head} high"]) == pytest.approx((100 * lo, 100 * hi))
    median = float(np.median(ABORT_DISTANCE_KM[:5])) * 1e3
    assert row["median closest abort drift to the keep-out [m]"] == pytest.approx(median)


def test_a_share_of_few_runs_is_not_marked_as_an_unreliable_bootstrap(campaign: Path) -> None:
    result = runner.invoke(app, ["table", str(campaign), "--metric", "violated_pct"])
    assert result.exit_code == 0, result.output
    assert "*" not in result.stdout


def test_an_unknown_metric_is_refused_with_a_did_you_mean(campaign: Path) -> None:
    result = runner.invoke(app, ["table", str(campaign), "--metric", "median.min_distanse"])
    assert result.exit_code == 2
    assert "unknown metric 'min_distanse'" in result.output
    assert "did you mean 'min_distance'" in result.output


@pytest.mark.parametrize("metric", ["violated_pct", "min.min_distance", "mean.scp_iterations"])
def test_a_campaign_without_safety_columns_is_refused_naming_the_metric(
    tmp_path: Path, metric: str
) -> None:
    plain = _campaign(tmp_path, safety_columns=False)
    result = runner.invoke(app, ["table", str(plain), "--metric", metric])
    assert result.exit_code == 2, result.output
    assert f"--metric {metric!r}" in result.output
    assert "[constraints]" in result.output
    assert "Traceback" not in result.output


def test_docking_values_of_a_fixed_target_are_refused_naming_the_tumbling_target(
    tmp_path: Path,
) -> None:
    """A fixed target with a corridor (campaigns/safe_approach.toml) writes the safety
    columns but no docking errors: only a tumbling target does, so the refusal says so
    rather than asking for the corridor the campaign already has."""
    path = _campaign(tmp_path)
    runs = pd.read_parquet(path / "runs.parquet")
    dock = ["safety_dock_position_error_km", "safety_dock_velocity_error_km_s"]
    runs.drop(columns=dock).to_parquet(path / "runs.parquet")
    result = runner.invoke(app, ["table", str(path), "--metric", "median.dock_position"])
    assert result.exit_code == 2, result.output
    assert "--metric 'median.dock_position'" in result.output
    assert 'target.attitude = "tumbling"' in " ".join(result.output.split())
    assert "Traceback" not in result.output
