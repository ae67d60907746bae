"""Campaign statistics: bootstrap and Wilson intervals, summaries, paired comparisons (issue 9)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cwrend_cli.campaign import statistics


def test_wilson_interval_reference_values() -> None:
    """Wilson 95 % interval of 5/10 is [0.2366, 0.7634] and of 0/10 is [0, 0.2775].

    Reference: the Wilson (1927) score interval worked by hand with z = 1.96:
    5/10 → centre 0.5, half-width 1.96·√(0.025 + 0.009604)/1.38416 = 0.2634;
    0/10 → centre = half-width = 0.19208/1.38416 = 0.1388. Tolerance 1e-4:
    the 4-decimal rounding of these hand values.
    """
    assert statistics.wilson_ci(5, 10) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert statistics.wilson_ci(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)


def test_wilson_interval_of_nothing_is_nan() -> None:
    assert all(np.isnan(statistics.wilson_ci(0, 0)))


def test_bootstrap_interval_brackets_the_statistic_and_is_reproducible() -> None:
    x = np.random.default_rng(1).normal(10.0, 2.0, size=200)
    a = statistics.bootstrap_ci(x, np.mean, np.random.default_rng(7))
    b = statistics.bootstrap_ci(x, np.mean, np.random.default_rng(7))
    assert a == b
    assert a[0] < x.mean() < a[1]
    # percentile bootstrap of a mean ≈ mean ± 1.96 σ/√n; 20 % slack for resampling noise
    half = 1.96 * x.std(ddof=1) / np.sqrt(x.size)
    assert (a[1] - a[0]) / 2 == pytest.approx(half, rel=0.2)


def test_bootstrap_of_a_single_value_has_no_interval() -> None:
    assert all(np.isnan(statistics.bootstrap_ci(np.array([1.0]), np.mean, np.random.default_rng())))


def test_bootstrap_of_constant_values_is_that_value() -> None:
    assert statistics.bootstrap_ci(np.full(5, 3.0), np.mean, np.random.default_rng()) == (3.0, 3.0)


def _runs() -> pd.DataFrame:
    rows = []
    for seed in range(4):
        for arch, miss in (("mtf_adaptive", 0.001 * (seed + 1)), ("plain_adaptive", 0.0025)):
            rows.append(
                {"arch": arch, "seed": seed, "status": "ok", "miss_km": miss,
                 "delta_v_km_s": 0.14, "fuel_penalty_pct": 24.0, "solve_success_pct": 100.0,
                 "solve_mean_ms": 0.05, "solve_max_ms": 0.2, "n_infeasible": 0}
            )  # fmt: skip
    rows.append({**rows[0], "seed": 9, "status": "failed", "miss_km": np.nan})
    return pd.DataFrame(rows)


def test_describe_counts_only_ok_runs() -> None:
    out = statistics.describe(_runs(), ["arch"])
    mean_miss = out[(out["metric"] == "miss_km") & (out["statistic"] == "mean")].set_index("arch")
    assert mean_miss.loc["mtf_adaptive", "n"] == 4
    assert mean_miss.loc["mtf_adaptive", "value"] == pytest.approx(0.0025)


def test_paired_share_of_seeds_where_mtf_misses_less() -> None:
    out = statistics.paired(_runs())
    row = out[(out["statistic"] == "frac_less") & (out["arch"] == "mtf_adaptive")]
    assert row["other"].item() == "plain_adaptive"
    assert row["value"].item() == pytest.approx(0.5)  # seeds 0 and 1 of 0–3
    assert row["n"].item() == 4
