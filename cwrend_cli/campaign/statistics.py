"""Campaign statistics: per-architecture summaries and paired comparisons.

Confidence intervals are 95 % percentile bootstraps (``scipy.stats.bootstrap``)
with a generator seeded from the campaign's root seed, so the same campaign
gives the same intervals; proportions use the Wilson score interval. A
statistic over fewer than two runs has no interval (NaN).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import pandas as pd
from scipy.special import ndtri

METRICS = ("delta_v_km_s", "miss_km", "fuel_penalty_pct")
CONFIDENCE = 0.95
N_RESAMPLES = 2000

#: Pairs compared seed by seed (first vs second), when both are in a campaign.
PAIRS = (
    ("mtf_adaptive", "plain_adaptive"),
    ("mtf_adaptive", "mtf_fixed"),
    ("plain_adaptive", "plain_fixed"),
    ("mtf_fixed", "plain_fixed"),
)


def _p95(x: np.ndarray, axis: int = -1) -> np.ndarray:
    p95: np.ndarray = np.percentile(x, 95, axis=axis)
    return p95


STATISTICS: dict[str, Callable[..., np.ndarray]] = {
    "mean": np.mean,
    "median": np.median,
    "p95": _p95,
}


def bootstrap_ci(
    x: np.ndarray, statistic: Callable[..., np.ndarray], rng: np.random.Generator
) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of ``statistic(x)``; NaN for fewer than 2 values."""
    x = np.asarray(x, dtype=float)
    if x.size < 2:
        return float("nan"), float("nan")
    if np.ptp(x) == 0.0:
        value = float(statistic(x))
        return value, value
    from scipy import stats  # about 0.5 s to import; only campaigns with several seeds need it

    res = stats.bootstrap(
        (x,),
        statistic,
        n_resamples=N_RESAMPLES,
        confidence_level=CONFIDENCE,
        method="percentile",
        vectorized=True,
        rng=rng,
    )
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def wilson_ci(successes: int, n: int) -> tuple[float, float]:
    """Wilson score interval of a proportion (95 %)."""
    if n == 0:
        return float("nan"), float("nan")
    z = ndtri(0.5 + CONFIDENCE / 2)
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return float(centre - half), float(centre + half)


def describe(runs: pd.DataFrame, by: Sequence[str], seed: int = 0) -> pd.DataFrame:
    """Per group: mean/median/p95 of Δv, miss and fuel penalty with bootstrap CIs.

    Only runs with status ``ok`` count; ``n`` is their number. Solve statistics
    (success %, mean and max time) are added as rows without intervals.
    """
    ok = runs[runs["status"] == "ok"]
    rng = np.random.default_rng(seed)
    rows = []
    for keys, group in ok.groupby(list(by), sort=True, observed=True):
        keys = keys if isinstance(keys, tuple) else (keys,)
        ident = dict(zip(by, keys, strict=True))
        n = len(group)
        for metric in METRICS:
            x = group[metric].to_numpy(dtype=float)
            for name, fn in STATISTICS.items():
                lo, hi = bootstrap_ci(x, fn, rng)
                rows.append(
                    {**ident, "kind": "marginal", "metric": metric, "statistic": name,
                     "value": float(fn(x)), "ci_low": lo, "ci_high": hi, "n": n}
                )  # fmt: skip
        for metric, name, fn in (
            ("solve_success_pct", "mean", np.mean),
            ("solve_mean_ms", "mean", np.mean),
            ("solve_max_ms", "max", np.max),
            ("n_infeasible", "mean", np.mean),
        ):
            x = group[metric].to_numpy(dtype=float)
            rows.append(
                {**ident, "kind": "marginal", "metric": metric, "statistic": name,
                 "value": float(fn(x)), "ci_low": np.nan, "ci_high": np.nan, "n": n}
            )  # fmt: skip
    return pd.DataFrame(rows)


def paired(runs: pd.DataFrame, by: Sequence[str] = (), seed: int = 0) -> pd.DataFrame:
    """Seed-by-seed comparisons of architecture pairs (on the same noise).

    For each pair (A, B) in :data:`PAIRS` present in the campaign: the share of
    seeds where A misses less than B (Wilson CI), the median of
    ``miss_A − miss_B`` and the mean of ``Δv_A − Δv_B`` (bootstrap CIs).
    """
    ok = runs[runs["status"] == "ok"]
    rng = np.random.default_rng(seed + 1)
    rows = []
    groups = ok.groupby(list(by), sort=True, observed=True) if by else [((), ok)]
    for keys, group in groups:
        keys = keys if isinstance(keys, tuple) else (keys,)
        ident = dict(zip(by, keys, strict=True))
        wide = group.pivot_table(index="seed", columns="arch", values=["miss_km", "delta_v_km_s"])
        for a, b in PAIRS:
            if ("miss_km", a) not in wide.columns or ("miss_km", b) not in wide.columns:
                continue
            both = wide[[("miss_km", a), ("miss_km", b), ("delta_v_km_s", a), ("delta_v_km_s", b)]]
            both = both.dropna()
            n = len(both)
            if n == 0:
                continue
            less = int((both[("miss_km", a)] < both[("miss_km", b)]).sum())
            lo, hi = wilson_ci(less, n)
            base = {**ident, "kind": "paired", "arch": a, "other": b, "n": n}
            rows.append(
                {**base, "metric": "miss_km", "statistic": "frac_less",
                 "value": less / n, "ci_low": lo, "ci_high": hi}
            )  # fmt: skip
            for metric, name, fn in (
                ("miss_km", "median_diff", np.median),
                ("delta_v_km_s", "mean_diff", np.mean),
            ):
                diff = (both[(metric, a)] - both[(metric, b)]).to_numpy()
                lo, hi = bootstrap_ci(diff, fn, rng)
                rows.append(
                    {**base, "metric": metric, "statistic": name,
                     "value": float(fn(diff)), "ci_low": lo, "ci_high": hi}
                )  # fmt: skip
    return pd.DataFrame(rows)
