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


def test_every_wilson_interval_lies_in_the_unit_interval_and_holds_its_share() -> None:
    """n = 1 … 2,000 and every count k: 0 ≤ low ≤ k/n ≤ high ≤ 1, low = 0 at k = 0, high = 1 at n.

    The formula alone gave 2.8e-17 for 0/3 and 1.0000000000000002 for 16/16
    (issue 37: a negative error bar in ``cwrend compare``'s figure).
    """
    n = np.repeat(np.arange(1, 2001), np.arange(2, 2002))
    k = np.concatenate([np.arange(m + 1) for m in range(1, 2001)])
    low, high = statistics.wilson_cis(k, n)
    share = k / n
    assert np.all((low >= 0) & (low <= share) & (share <= high) & (high <= 1))
    assert np.all(low[k == 0] == 0.0)
    assert np.all(high[k == n] == 1.0)
    for m in (3, 6, 16, 2000):  # the scalar form is the same interval
        assert statistics.wilson_ci(0, m)[0] == 0.0
        assert statistics.wilson_ci(m, m)[1] == 1.0


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


def test_paired_compares_each_cone_program_architecture_with_its_shooting_one() -> None:
    """Issue 16, item 5: ``mtf_adaptive_socp`` vs ``mtf_adaptive`` on the same seeds."""
    runs = _runs().replace({"arch": {"plain_adaptive": "mtf_adaptive_socp"}})
    out = statistics.paired(runs)
    row = out[(out["statistic"] == "frac_less") & (out["arch"] == "mtf_adaptive_socp")]
    assert row["other"].item() == "mtf_adaptive"
    assert row["value"].item() == pytest.approx(0.5)  # seeds 2 and 3 of 0–3 (2.5 m < 3, 4 m)
    assert row["n"].item() == 4


# ---------------------------------------------------------------------------
# The batched statistics (issue 17) give the numbers of the per-group loop
# ---------------------------------------------------------------------------


def _scipy_interval(x: np.ndarray, fn: object, rng: np.random.Generator) -> tuple[float, float]:
    """One ``scipy.stats.bootstrap`` call as statistics.bootstrap_ci made it before issue 17."""
    from scipy import stats

    x = np.asarray(x, dtype=float)
    if x.size < 2:
        return float("nan"), float("nan")
    if np.ptp(x) == 0.0:
        value = float(fn(x))  # type: ignore[operator]
        return value, value
    res = stats.bootstrap(
        (x,), fn, n_resamples=statistics.N_RESAMPLES, confidence_level=statistics.CONFIDENCE,
        method="percentile", vectorized=True, rng=rng,
    )  # fmt: skip
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def test_batched_bootstrap_is_scipy_bootstrap_called_in_order_bit_for_bit() -> None:
    """Samples of mixed sizes (runs of equal size drawn in one call), constant and short ones."""
    gen = np.random.default_rng(3)
    sizes = [5, 5, 5, 1, 40, 40, 3, 3, 0, 2, 40, 5]
    samples = [gen.lognormal(size=n) for n in sizes]
    samples[6] = np.full(3, 0.25)  # constant: no draw
    fns = [statistics.STATISTICS[k] for k in ("mean", "median", "p95")] * 4
    got = statistics.bootstrap_cis(samples, fns, np.random.default_rng(11))
    rng = np.random.default_rng(11)
    want = np.array([_scipy_interval(x, f, rng) for x, f in zip(samples, fns, strict=True)])
    np.testing.assert_array_equal(got, want)


def _old_describe(runs: pd.DataFrame, by: list[str], seed: int) -> pd.DataFrame:
    """The per-group loop of statistics.describe before issue 17 (the oracle)."""
    ok = runs[runs["status"] == "ok"]
    rng = np.random.default_rng(seed)
    rows = []
    for keys, group in ok.groupby(by, sort=True, observed=True):
        ident = dict(zip(by, keys, strict=True))
        n = len(group)
        for metric in statistics.METRICS:
            x = group[metric].to_numpy(dtype=float)
            for name, fn in statistics.STATISTICS.items():
                lo, hi = _scipy_interval(x, fn, rng)
                rows.append({**ident, "kind": "marginal", "metric": metric, "statistic": name,
                             "value": float(fn(x)), "ci_low": lo, "ci_high": hi,
                             "n": n})  # fmt: skip
        for metric, name, fn in statistics.SOLVE_STATISTICS:
            x = group[metric].to_numpy(dtype=float)
            rows.append({**ident, "kind": "marginal", "metric": metric, "statistic": name,
                         "value": float(fn(x)), "ci_low": np.nan, "ci_high": np.nan,
                         "n": n})  # fmt: skip
    return pd.DataFrame(rows)


def _old_paired(runs: pd.DataFrame, by: list[str], seed: int) -> pd.DataFrame:
    """The per-group loop of statistics.paired before issue 17 (the oracle)."""
    ok = runs[runs["status"] == "ok"]
    rng = np.random.default_rng(seed + 1)
    rows = []
    groups = ok.groupby(by, sort=True, observed=True) if by else [((), ok)]
    for keys, group in groups:
        ident = dict(zip(by, keys, strict=True))
        wide = group.pivot_table(index="seed", columns="arch", values=["miss_km", "delta_v_km_s"])
        for a, b in statistics.PAIRS:
            if ("miss_km", a) not in wide.columns or ("miss_km", b) not in wide.columns:
                continue
            cols = [("miss_km", a), ("miss_km", b), ("delta_v_km_s", a), ("delta_v_km_s", b)]
            both = wide[cols].dropna()
            n = len(both)
            if n == 0:
                continue
            less = int((both[("miss_km", a)] < both[("miss_km", b)]).sum())
            lo, hi = statistics.wilson_ci(less, n)
            base = {**ident, "kind": "paired", "arch": a, "other": b, "n": n}
            rows.append({**base, "metric": "miss_km", "statistic": "frac_less",
                         "value": less / n, "ci_low": lo, "ci_high": hi})  # fmt: skip
            for metric, name, fn in (("miss_km", "median_diff", np.median),
                                     ("delta_v_km_s", "mean_diff", np.mean)):  # fmt: skip
                diff = (both[(metric, a)] - both[(metric, b)]).to_numpy()
                lo, hi = _scipy_interval(diff, fn, rng)
                rows.append({**base, "metric": metric, "statistic": name,
                             "value": float(fn(diff)), "ci_low": lo, "ci_high": hi})  # fmt: skip
    return pd.DataFrame(rows)


def _sweep_runs() -> pd.DataFrame:
    """Three grid points × 4 architectures: 12, 1 and 3 seeds, failures, a constant metric."""
    gen = np.random.default_rng(5)
    archs = ("mtf_adaptive", "mtf_fixed", "plain_adaptive", "plain_fixed")
    rows = []
    for point, beta, seeds in (("p0", 0.25, 12), ("p1", 0.5, 1), ("p2", 0.75, 3)):
        for seed in range(seeds):
            for arch in archs:
                rows.append(
                    {"point": point, "param.schedule.beta": beta, "arch": arch, "seed": seed,
                     "status": "failed" if (seed, arch) == (2, "mtf_fixed") else "ok",
                     "miss_km": gen.lognormal(-6), "delta_v_km_s": gen.normal(0.14, 0.002),
                     "fuel_penalty_pct": 24.0 if point == "p2" else gen.normal(25, 1),
                     "solve_success_pct": 100.0, "solve_mean_ms": gen.uniform(0.1, 3),
                     "solve_max_ms": gen.uniform(3, 90), "n_infeasible": int(seed % 2)}
                )  # fmt: skip
    return pd.DataFrame(rows)


@pytest.mark.parametrize("by", [["arch"], ["point", "param.schedule.beta", "arch"]])
def test_describe_gives_the_numbers_of_the_per_group_loop(by: list[str]) -> None:
    runs = _sweep_runs()
    pd.testing.assert_frame_equal(
        statistics.describe(runs, by, seed=4), _old_describe(runs, by, 4), check_exact=True
    )


@pytest.mark.parametrize("by", [[], ["point", "param.schedule.beta"]])
def test_paired_gives_the_numbers_of_the_per_group_loop(by: list[str]) -> None:
    runs = _sweep_runs()
    pd.testing.assert_frame_equal(
        statistics.paired(runs, by, seed=4), _old_paired(runs, by, 4), check_exact=True
    )


def test_no_ok_run_gives_no_rows() -> None:
    runs = _runs().assign(status="failed")
    assert statistics.describe(runs, ["arch"]).empty
    assert statistics.paired(runs).empty


def test_percentile_interval_is_scipy_quantile_bit_for_bit() -> None:
    """Scales from 1e-8 to 1e2, rounded values (ties), a row with NaN, one row."""
    from scipy import stats

    gen = np.random.default_rng(2)
    alpha = np.asarray((1 - statistics.CONFIDENCE) / 2)
    p = np.stack((alpha, 1 - alpha), axis=-1)
    for k, scale in ((7, 1e-8), (1, 1.0), (30, 1e2)):
        theta = gen.normal(size=(k, statistics.N_RESAMPLES)) * scale
        for rows in (theta, np.round(theta, 1)):
            np.testing.assert_array_equal(
                statistics.percentile_interval(rows), stats.quantile(rows, p, axis=-1)
            )
    with_nan = gen.normal(size=(3, statistics.N_RESAMPLES))
    with_nan[1, 5] = np.nan
    np.testing.assert_array_equal(
        statistics.percentile_interval(with_nan), stats.quantile(with_nan, p, axis=-1)
    )


def test_the_wilson_z_is_the_normal_quantile() -> None:
    from scipy.special import ndtri

    assert ndtri(0.5 + statistics.CONFIDENCE / 2) == statistics.Z_TWO_SIDED
