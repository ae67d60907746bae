"""Filter consistency against χ² bands over the seeds (issue 33, item 4).

The ensemble test of Bar-Shalom, Li & Kirubarajan 2001, *Estimation with
Applications to Tracking and Navigation*, §5.4.2: at one step the NEES of N
independent runs of a consistent filter, averaged, times N is χ²(6 N) (the NIS:
χ²(3 N)). The synthetic filters here are drawn in the test: Gaussian errors
with the covariance the filter states (consistent), or with a multiple of it.
"""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pytest
from rich.console import Console
from scipy.stats import chi2

from cwrend_cli.campaign import statistics
from cwrend_cli.console import consistency_console_table
from cwrend_cli.physics import metrics
from cwrend_cli.report import consistency
from cwrend_cli.report.labels import consistency_text

RUNS = 20
STEPS = 2000


def _nees(rng: np.random.Generator, scale: float, runs: int = RUNS, steps: int = STEPS):
    """NEES of ``runs`` × ``steps`` synthetic estimates: errors ~ N(0, scale · P), P stated.

    Each step has its own stated covariance P (a random symmetric positive definite
    6 × 6); the filter is consistent for ``scale`` = 1, overconfident above, conservative
    below. Returns the long frame (arch, seed, t_s, nees).
    """
    a = rng.standard_normal((steps, 6, 6))
    p = a @ a.transpose(0, 2, 1) + 0.5 * np.eye(6)
    chol = np.linalg.cholesky(p)
    z = rng.standard_normal((runs, steps, 6))
    err = np.sqrt(scale) * np.einsum("kij,rkj->rki", chol, z)
    solved = np.linalg.solve(p[None], err[..., None])[..., 0]
    nees = np.einsum("rki,rki->rk", err, solved)
    seed, step = np.meshgrid(np.arange(runs), np.arange(steps), indexing="ij")
    return pd.DataFrame(
        {"arch": "a", "seed": seed.ravel(), "t_s": step.ravel() * 1.0, "nees": nees.ravel()}
    )


@pytest.mark.parametrize("dof", [metrics.NEES_DOF, metrics.NIS_DOF])
def test_the_band_is_the_chi2_quantiles_over_n(dof: int) -> None:
    """[χ²⁻¹(0.025; dof N) / N, χ²⁻¹(0.975; dof N) / N], scipy.stats.chi2 to 1e-12 relative
    (both are the same special function; the tolerance leaves room for its rounding)."""
    n = np.array([1, 2, 3, 20, 100, 1000])
    low, high = metrics.chi2_band(n, dof)
    assert low == pytest.approx(chi2.ppf(0.025, dof * n) / n, rel=1e-12)
    assert high == pytest.approx(chi2.ppf(0.975, dof * n) / n, rel=1e-12)


def test_the_band_of_no_run_is_nan() -> None:
    low, high = metrics.chi2_band(np.array([0, 1]), 6)
    assert np.isnan(low[0]) and np.isnan(high[0])
    assert (low[1], high[1]) == pytest.approx((1.2373442, 14.449375), rel=1e-7)  # χ²₆ table


def test_a_consistent_filter_is_inside_at_about_95_percent_of_the_steps() -> None:
    """Each step's ensemble mean is inside with probability 0.95 exactly; over 2,000
    independent steps the share is 0.95 ± 0.0049 (1 σ, binomial): the bounds 0.93–0.97
    are ±4.1 σ, a false alarm of about 4e-5 (the draw is seeded: the test is repeatable)."""
    ensemble = consistency.ensemble_consistency(
        _nees(np.random.default_rng(1), 1.0), ["arch"], "nees", metrics.NEES_DOF
    )
    assert len(ensemble) == STEPS and set(ensemble["n"]) == {RUNS}
    (row,) = consistency.share_inside(ensemble, ["arch"]).itertuples()
    assert row.steps == STEPS and row.runs == RUNS
    assert 0.93 <= row.inside <= 0.97


@pytest.mark.parametrize("scale", [2.0, 0.5])
def test_a_filter_whose_covariance_is_off_by_two_is_outside(scale: float) -> None:
    """Errors of twice (half) the stated covariance: the ensemble mean of 20 runs is about
    12 (3) against the band [4.58, 7.61]; inside at a step with probability below 1e-4."""
    ensemble = consistency.ensemble_consistency(
        _nees(np.random.default_rng(2), scale), ["arch"], "nees", metrics.NEES_DOF
    )
    (row,) = consistency.share_inside(ensemble, [])[["inside"]].itertuples()
    assert row.inside < 0.01


def test_a_step_counts_only_the_runs_with_a_value() -> None:
    """A NIS is NaN on a dropout: the step's mean and band are over the other runs."""
    frame = pd.DataFrame(
        {"arch": "a", "seed": [0, 1, 2, 0, 1, 2], "t_s": [1.0, 1.0, 1.0, 2.0, 2.0, 2.0],
         "nis": [1.0, np.nan, 5.0, np.nan, np.nan, np.nan]}
    )  # fmt: skip
    ensemble = consistency.ensemble_consistency(frame, ["arch"], "nis", metrics.NIS_DOF)
    (row,) = ensemble.itertuples()  # t = 2 s: no measurement, no step
    assert (row.t_s, row.n, row.mean) == (1.0, 2, 3.0)
    low, high = metrics.chi2_band(2, metrics.NIS_DOF)
    assert (row.band_low, row.band_high) == (low, high) and row.inside


def _runs(nees: np.ndarray, nis: np.ndarray) -> pd.DataFrame:
    return pd.DataFrame(
        {"arch": "a", "seed": np.arange(len(nees)), "status": "ok", "mean_nees": nees,
         "mean_nis_nominal": nis}
    )  # fmt: skip


def test_the_campaign_rows_are_the_mean_of_the_runs_and_its_band() -> None:
    runs = _runs(np.array([5.0, 7.0, 6.0, np.nan]), np.array([3.0, 2.0, 4.0, 3.0]))
    runs.loc[len(runs)] = {"arch": "a", "seed": 9, "status": "failed", "mean_nees": 1e9,
                           "mean_nis_nominal": 1e9}  # fmt: skip
    rows = statistics.consistency(runs, ["arch"]).set_index("metric")
    assert set(rows["kind"]) == {"consistency"} and set(rows["statistic"]) == {"mean"}
    nees, nis = rows.loc["mean_nees"], rows.loc["mean_nis_nominal"]
    assert (nees["value"], nees["n"], nis["value"], nis["n"]) == (6.0, 3, 3.0, 4)
    assert (nees["ci_low"], nees["ci_high"]) == tuple(x[()] for x in metrics.chi2_band(3, 6))
    assert (nis["ci_low"], nis["ci_high"]) == tuple(x[()] for x in metrics.chi2_band(4, 3))


def test_no_campaign_rows_without_the_columns() -> None:
    runs = _runs(np.ones(3), np.ones(3)).drop(columns="mean_nees")
    assert statistics.consistency(runs, ["arch"]).empty


def test_the_campaign_band_holds_the_mean_of_time_averages_at_95_percent_or_more() -> None:
    """The band of N runs for the mean of each run's time-averaged NEES: exact when a run's
    errors do not change over time (its average is one χ²₆ value), conservative when they
    do (independent steps). 4,000 synthetic campaigns of 20 runs: coverage 0.95 ± 0.0034
    (1 σ) in the first case, bounds ±4.4 σ (false alarm about 1e-5); above 0.99 in the
    second (its exact coverage is 1 − 2e-15 at 50 steps per run)."""
    rng = np.random.default_rng(3)
    low, high = metrics.chi2_band(RUNS, metrics.NEES_DOF)
    constant = rng.chisquare(6, (4000, RUNS)).mean(axis=1)
    covered = np.mean((constant >= low) & (constant <= high))
    assert 0.935 <= covered <= 0.965
    independent = rng.chisquare(6, (4000, RUNS, 50)).mean(axis=2).mean(axis=1)
    assert np.mean((independent >= low) & (independent <= high)) > 0.99


# --- the console table (80 columns, tests/test_console_80.py's rule) -------------------


SLUGS = ["plain_adaptive_socp", "mtf_adaptive_socp", "plain_fixed_socp", "mtf_fixed_socp"]


def test_the_console_table_shows_the_means_bands_and_verdicts_at_80_columns() -> None:
    rng = np.random.default_rng(4)
    frames = []
    for point in range(3):
        for k, arch in enumerate(SLUGS):
            runs = _runs(rng.chisquare(6, 12) * 10.0**k, rng.chisquare(3, 12))
            runs["arch"], runs["point"] = arch, f"p{point}"
            runs["param.schedule.beta"] = 0.125 * (point + 1)
            frames.append(runs)
    by = ["point", "param.schedule.beta", "arch"]
    stats = statistics.consistency(pd.concat(frames, ignore_index=True), by)
    table = consistency_console_table(stats, ["point", "param.schedule.beta"], "consistency")
    assert table is not None
    buf = io.StringIO()
    Console(file=buf, width=80, highlight=False, color_system=None).print(table)
    text = buf.getvalue()
    assert max(len(line) for line in text.splitlines()) <= 80 and "…" not in text
    cells = set(text.split())
    assert {"0.125", "0.25", "0.375", *SLUGS, "yes", "no"} <= cells
    low, high = metrics.chi2_band(12, 6)
    assert f"{low[()]:.2f}–{high[()]:.2f}" in cells
    for row in stats.itertuples():
        assert consistency_text(row.value) in cells


def test_a_mean_is_printed_with_2_decimals_below_1000_else_3_digits() -> None:
    assert [consistency_text(v) for v in (3.0, 5.344426, 999.994, 2065.087, 1.2e6)] == [
        "3.00", "5.34", "999.99", "2.07e+03", "1.2e+06"
    ]  # fmt: skip


def test_no_console_table_without_consistency_rows() -> None:
    assert consistency_console_table(pd.DataFrame({"kind": ["marginal"]}), [], "x") is None


# --- cwrend table (mean.nees, mean.nis) ---------------------------------------------------


def test_cwrend_table_gives_the_consistency_means_with_their_bands(tmp_path) -> None:
    """``mean.nees`` / ``mean.nis``: the stored consistency rows, the χ² band as the interval,
    never marked unreliable (5 runs: the bootstrap interval of the miss is)."""
    import json

    from typer.testing import CliRunner

    from cwrend_cli.cli import app

    rng = np.random.default_rng(5)
    runs = _runs(rng.chisquare(6, 5), rng.chisquare(3, 5))
    runs["miss_km"], runs["delta_v_km_s"], runs["fuel_penalty_pct"] = 1e-3, 0.14, 1.0
    for column in ("solve_success_pct", "solve_mean_ms", "solve_max_ms", "n_infeasible"):
        runs[column] = 1.0
    stats = pd.concat([statistics.describe(runs, ["arch"]), statistics.consistency(runs, ["arch"])])
    stats.to_parquet(tmp_path / "ablation.parquet")
    (tmp_path / "manifest.json").write_text(json.dumps({"config": {}}))
    result = CliRunner().invoke(
        app, ["table", str(tmp_path), "--metric", "mean.nees,mean.nis,mean.miss"]
    )
    assert result.exit_code == 0, result.output
    header, _, row = result.stdout.splitlines()[:3]
    assert header == (
        "| architecture | mean of the runs' mean NEES [-] (95 % χ² band) | mean of the runs' "
        "nominal mean NIS [-] (95 % χ² band) | mean miss [m] (95 % CI) |"
    )
    cells = [c.strip() for c in row.strip("|").split("|")]
    for cell, column, dof in ((cells[1], "mean_nees", 6), (cells[2], "mean_nis_nominal", 3)):
        low, high = chi2.ppf([0.025, 0.975], dof * 5) / 5
        assert cell == f"{runs[column].mean():.2f} [{low:.2f}, {high:.2f}]"
    assert cells[3].endswith("\\*")


def _stored_nis_band(tmp_path, runs: pd.DataFrame, config: dict, command: str) -> pd.DataFrame:
    """The NIS rows ``write_statistics`` stores for ``runs`` under a manifest of ``config``."""
    import json

    from cwrend_cli.campaign.driver import write_statistics

    runs["miss_km"], runs["delta_v_km_s"], runs["fuel_penalty_pct"] = 1e-3, 0.14, 1.0
    for column in ("solve_success_pct", "solve_mean_ms", "solve_max_ms", "n_infeasible"):
        runs[column] = 1.0
    runs["run_key"] = [f"k{i}" for i in range(len(runs))]
    runs.to_parquet(tmp_path / "runs.parquet")
    (tmp_path / "manifest.json").write_text(json.dumps({"config": config}))
    frame = write_statistics(tmp_path, command, 0, pairs=()).frame  # type: ignore[arg-type]
    return frame[frame["metric"] == "mean_nis_nominal"]


def test_an_angles_campaign_stores_the_nis_band_of_two_degrees_of_freedom(tmp_path) -> None:
    # angles-only (issue 35): m = 2, the band of χ²(2 n) / n (Bar-Shalom et al. 2001, §5.4.2)
    n = 1000
    runs = _runs(np.full(n, 6.0), np.full(n, 2.0))
    row = _stored_nis_band(tmp_path, runs, {"sensor": {"model": "angles"}}, "ablate").iloc[0]
    band = chi2.ppf([0.025, 0.975], 2 * n) / n
    np.testing.assert_allclose((row["ci_low"], row["ci_high"]), band, rtol=1e-12)  # rounding


def test_a_sweep_over_the_sensor_stores_each_points_nis_band(tmp_path) -> None:
    n = 10
    runs = pd.concat([_runs(np.full(n, 6.0), np.full(n, 3.0))] * 2, ignore_index=True)
    runs["point"] = ["p0"] * n + ["p1"] * n
    runs["param.sensor.model"] = ["position"] * n + ["angles"] * n
    rows = _stored_nis_band(tmp_path, runs, {}, "sweep").set_index("point")
    for point, m in (("p0", 3), ("p1", 2)):
        band = chi2.ppf([0.025, 0.975], m * n) / n
        stored = rows.loc[point, ["ci_low", "ci_high"]].to_numpy(float)
        np.testing.assert_allclose(stored, band, rtol=1e-12)  # the order of ppf's rounding


def test_the_step_ensembles_of_an_angles_sensor_use_its_two_degrees_of_freedom() -> None:
    from cwrend_cli.report.consistency import step_ensembles

    runs, steps = 4, 3
    steps_frame = pd.DataFrame(
        {"arch": "a", "seed": np.repeat(np.arange(runs), steps),
         "t_s": np.tile(np.arange(steps, dtype=float), runs), "nees": 6.0, "nis": 2.0}
    )  # fmt: skip
    nis = step_ensembles(steps_frame, nis_dof=2)["nis"]
    band = chi2.ppf([0.025, 0.975], 2 * runs) / runs
    np.testing.assert_allclose(nis[["band_low", "band_high"]].to_numpy(), [band] * 2, rtol=1e-12)
