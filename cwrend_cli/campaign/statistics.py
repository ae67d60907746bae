"""Campaign statistics: per-architecture summaries and paired comparisons.

Confidence intervals are 95 % percentile bootstraps with a generator seeded
from the campaign's root seed, so the same campaign gives the same intervals;
proportions use the Wilson score interval. A statistic over fewer than two
runs has no interval (NaN).

The bootstrap is computed in batches (:func:`bootstrap_cis`) but gives, bit
for bit, the intervals of one ``scipy.stats.bootstrap(..., method="percentile",
vectorized=True)`` call per interval in the order of the rows: the same
resampling indices are drawn from the generator in the same order (one
``integers`` call for consecutive intervals of equal sample size draws the
same stream as one call each), each statistic is evaluated row by row along
the last axis as scipy does, and the interval is ``scipy.stats.quantile`` of
the bootstrap distribution, written out (:func:`percentile_interval`, so no
scipy is imported). What made the old per-group loop slow (issue 17:
about 3 s for 2,400 runs of a few grid points, 8–11 s for hundreds of
one-seed points) was scipy's per-call overhead and one pandas group, pivot and
row dict per group; here the groups are index segments of one sorted array
and the point values of equal-sized groups are computed in one call. The
resamples are drawn and evaluated in blocks of at most :data:`_CHUNK_VALUES`
values (a block may end inside an interval's draw), so the memory is bounded
by a constant whatever the number of runs (issue 17: 2,000 runs of two
architectures held about 130 MB at once before, 16 MB now). The draws stay
in one thread, in order; the resampling and the statistics of each drawn
block are evaluated in a thread per core meanwhile (at most 4), into their
own rows: the same numbers, 1.4–1.6× faster on 2 cores (``describe`` of
1,000 and 3,000 runs, measured 2026-12-02), in the single-threaded phase
after a campaign's runs.
"""

from __future__ import annotations

import zlib
from collections import deque
from collections.abc import Callable, Hashable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from itertools import pairwise
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from cwrend_cli.campaign.executors import default_workers
from cwrend_cli.config.messages import did_you_mean
from cwrend_cli.errors import ConfigError
from cwrend_cli.physics.metrics import NEES_DOF, NIS_DOF, mean_in_band
from cwrend_cli.physics.params import ALL_ARCHITECTURES, Architecture

METRICS = ("delta_v_km_s", "miss_km", "fuel_penalty_pct")
CONFIDENCE = 0.95
#: ``scipy.special.ndtri(0.5 + CONFIDENCE / 2)`` (a test checks it): the normal quantile of
#: the two-sided 95 % Wilson interval, written out so that statistics import no scipy.
Z_TWO_SIDED = 1.959963984540054
N_RESAMPLES = 2000
#: Most resampled values held at once by :func:`bootstrap_cis` (4 MB of indices, 4 MB of
#: values and the statistic's working copy): a bounded memory whatever the number of runs.
_CHUNK_VALUES = 1 << 19

FloatArray = npt.NDArray[np.float64]
#: A statistic reducing along ``axis`` (``np.mean``, ``np.median``, ...).
Statistic = Callable[..., Any]

#: Pairs compared seed by seed (first vs second), when both are in a campaign: the
#: estimators, the schedules, and each cone-program architecture against its
#: shooting counterpart (issue 16, item 5). Their rows are bootstrapped from one
#: stream in this order, as since issue 16: kept as they are so that the rows of
#: every campaign stay the same; any other pair is an *added* pair (see :func:`paired`).
PAIRS = (
    ("mtf_adaptive", "plain_adaptive"),
    ("mtf_adaptive", "mtf_fixed"),
    ("plain_adaptive", "plain_fixed"),
    ("mtf_fixed", "plain_fixed"),
    ("plain_fixed_socp", "plain_fixed"),
    ("mtf_fixed_socp", "mtf_fixed"),
    ("plain_adaptive_socp", "plain_adaptive"),
    ("mtf_adaptive_socp", "mtf_adaptive"),
)
#: Stream of an added pair's bootstrap: ``default_rng([seed, PAIR_STREAM, crc32("A:B")])``.
PAIR_STREAM = 2**32 - 2


#: Expected order of the estimators (a pair puts the better-expected first): the
#: single-factor baseline (issue 35) between the plain and the MTF filter.
_ESTIMATOR_RANK = {"plain": 0, "stf": 1, "mtf": 2}


def _pairs_by_rule(archs: Sequence[Architecture]) -> tuple[tuple[str, str], ...]:
    """Every pair of ``archs`` that differs in one design choice, better-expected first.

    Within each re-solve method: the better-expected estimator against the other
    at the same schedule (MTF vs single-factor vs plain), adaptive vs fixed at
    the same estimator; across methods: cone program vs shooting at the same
    estimator and schedule. Ordered as :data:`PAIRS` (``archs`` from the last:
    MTF adaptive first for the paper's eight).
    """
    out: list[tuple[str, str]] = []
    for a in archs[::-1]:
        for b in archs[::-1]:
            same_method = a.method == b.method
            better = _ESTIMATOR_RANK[a.estimator] > _ESTIMATOR_RANK[b.estimator]
            estimator = same_method and a.adaptive == b.adaptive and better
            schedule = same_method and a.estimator == b.estimator and a.adaptive and not b.adaptive
            twins = (a.estimator, a.adaptive) == (b.estimator, b.adaptive)
            method = twins and a.method == "socp" and b.method is None
            if estimator or schedule or method:
                out.append((a.slug, b.slug))
    return tuple(out)


def _default_pairs() -> tuple[tuple[str, str], ...]:
    """:data:`PAIRS`, the other pairs of the paper's eight, then those of the single factor.

    The single-factor pairs (issue 35) come last, MTF against the single factor
    first (P(MTF beats STF)), so that every pair of the paper's eight keeps its place.
    """
    paper = [a for a in ALL_ARCHITECTURES.values() if a.estimator != "stf"]
    out = list(PAIRS) + [p for p in _pairs_by_rule(paper) if p not in PAIRS]
    stf = [p for p in _pairs_by_rule(list(ALL_ARCHITECTURES.values())) if p not in out]
    stf.sort(key=lambda p: ALL_ARCHITECTURES[p[0]].estimator != "mtf")  # stable
    return (*out, *stf)


#: The pairs every campaign compares when both architectures are in it: :data:`PAIRS`
#: (its rows as they always were), then the other pairs of :func:`_pairs_by_rule` (the
#: estimators and schedules of the cone-program architectures, issue 37; then the
#: single-factor baseline's, issue 35: MTF vs STF, STF vs plain, adaptive vs fixed and
#: cone program vs shooting of the STF), added pairs.
DEFAULT_PAIRS = _default_pairs()


def campaign_pairs(asked: Sequence[str], archs: Sequence[str]) -> tuple[tuple[str, str], ...]:
    """The pairs a campaign of ``archs`` compares: :data:`DEFAULT_PAIRS`, then ``--pair A:B``.

    Each of ``asked`` names two different architectures of the campaign;
    :class:`ConfigError` naming ``--pair`` and the campaign's architectures
    otherwise. A pair already compared by default is not repeated.
    """
    choices = ", ".join(archs)
    out = list(DEFAULT_PAIRS)
    for text in asked:
        parts = [p.strip() for p in text.split(":")]
        if len(parts) != 2 or not all(parts):
            raise ConfigError(
                f"--pair {text!r}: expected A:B, two architectures of the campaign ({choices})"
            )
        a, b = parts
        for slug in (a, b):
            if slug not in archs:
                known = "not in this campaign" if slug in ALL_ARCHITECTURES else "unknown"
                raise ConfigError(
                    f"--pair {text!r}: architecture {slug!r} is {known} (choices: {choices})"
                    f"{did_you_mean(slug, list(archs))}"
                )
        if a == b:
            raise ConfigError(f"--pair {text!r}: name two different architectures ({choices})")
        if (a, b) not in out:
            out.append((a, b))
    return tuple(out)


def _p95(x: np.ndarray, axis: int = -1) -> np.ndarray:
    p95: np.ndarray = np.percentile(x, 95, axis=axis)
    return p95


STATISTICS: dict[str, Callable[..., np.ndarray]] = {
    "mean": np.mean,
    "median": np.median,
    "p95": _p95,
}
#: Solve statistics: rows without an interval (metric, statistic name, statistic).
SOLVE_STATISTICS: tuple[tuple[str, str, Statistic], ...] = (
    ("solve_success_pct", "mean", np.mean),
    ("solve_mean_ms", "mean", np.mean),
    ("solve_max_ms", "max", np.max),
    ("n_infeasible", "mean", np.mean),
)


def bootstrap_cis(
    samples: Sequence[FloatArray], statistics: Sequence[Statistic], rng: np.random.Generator
) -> FloatArray:
    """95 % percentile-bootstrap intervals ``(k, 2)`` of ``statistics[j](samples[j])``.

    Row ``j`` is NaN for fewer than 2 values and ``(s, s)`` with ``s`` the
    statistic for constant values (nothing drawn); otherwise exactly what
    ``scipy.stats.bootstrap`` with :data:`N_RESAMPLES` resamples gives when
    called once per sample, in order, with ``rng`` (see the module docstring).
    ``statistics`` must reduce along ``axis=-1`` of any array.
    """
    out = np.full((len(samples), 2), np.nan)
    spread = _point_values(samples, np.ptp)  # NaN values: not constant, resampled as scipy does
    drawn: list[int] = []  # the samples that are resampled, in order
    for j, (x, fn) in enumerate(zip(samples, statistics, strict=True)):
        if x.size < 2:
            continue
        if spread[j] == 0.0:
            out[j] = float(fn(x))
            continue
        drawn.append(j)
    if not drawn:
        return out
    most = max(1, _CHUNK_VALUES // N_RESAMPLES)  # intervals whose statistics are held at once
    start = 0
    while start < len(drawn):  # consecutive samples of equal size: one stream of draws
        n = samples[drawn[start]].size
        stop = start + 1
        while stop < len(drawn) and stop - start < most and samples[drawn[stop]].size == n:
            stop += 1
        chunk = drawn[start:stop]
        theta = _resampled_statistics(
            [samples[j] for j in chunk], [statistics[j] for j in chunk], rng
        )
        out[chunk] = percentile_interval(theta)
        start = stop
    return out


def _resampled_statistics(
    run: Sequence[FloatArray], statistics: Sequence[Statistic], rng: np.random.Generator
) -> FloatArray:
    """The bootstrap statistics ``(len(run), N_RESAMPLES)`` of samples of equal size ``n``.

    Drawn in order, as :func:`bootstrap_cis` describes. scipy's
    draw for one interval is ``rng.integers(0, n, (N_RESAMPLES, n))``, int64;
    the draws of consecutive intervals, concatenated, are one stream of rows of
    ``n`` indices, drawn here in blocks (at least one row): consecutive
    ``integers`` calls draw the same stream as one call, and each statistic
    reduces row by row, so the block size changes no number and bounds the
    memory whatever the run count.

    The draws stay in this thread, in order; the resampling and the
    statistics of a drawn block (:func:`_evaluate`, medians and percentiles
    most of the work) run in :func:`_evaluation_threads` threads meanwhile
    (numpy releases the GIL in them), each block into its own rows of the
    result, so the thread count changes no number either. At most that many
    blocks are evaluated while the next is drawn, each of ``_CHUNK_VALUES /
    threads`` values: the memory stays within a few ``_CHUNK_VALUES`` blocks.
    """
    n = run[0].size
    rows = len(run) * N_RESAMPLES
    theta = np.empty(rows)  # row-major (sample, resample)
    threads = _evaluation_threads()
    block = max(1, _CHUNK_VALUES // (n * threads))
    stacked = np.concatenate(run)
    blocks = range(0, rows, block)

    def drawn(first: int) -> npt.NDArray[np.int64]:  # the next block's draws, in order
        return rng.integers(0, n, (min(first + block, rows) - first, n), dtype=np.int64)

    if threads == 1 or len(blocks) == 1:
        for first in blocks:
            _evaluate(theta, stacked, drawn(first), first, statistics)
        return theta.reshape(len(run), N_RESAMPLES)
    with ThreadPoolExecutor(threads, thread_name_prefix="cwrend-bootstrap") as pool:
        evaluating: deque[Future[None]] = deque()
        for first in blocks:
            evaluating.append(
                pool.submit(_evaluate, theta, stacked, drawn(first), first, statistics)
            )
            while len(evaluating) >= threads:  # bounded memory: wait for the oldest block
                evaluating.popleft().result()
        for pending in evaluating:
            pending.result()
    return theta.reshape(len(run), N_RESAMPLES)


def _evaluation_threads() -> int:
    """Threads evaluating bootstrap statistics: the cores available, at most 4."""
    return max(1, min(4, default_workers()))


def _evaluate(
    theta: FloatArray,
    stacked: FloatArray,
    index: npt.NDArray[np.int64],
    first: int,
    statistics: Sequence[Statistic],
) -> None:
    """The statistics of resamples ``first`` … ``first + len(index) − 1`` into ``theta``.

    ``index`` holds each resample's ``n`` draws, indices into its own sample
    of the ``stacked`` ones; it is consumed (offset in place into them).
    """
    n = index.shape[1]
    last = first + len(index)
    owner = np.arange(first, last) // N_RESAMPLES  # the sample of each row, in ``run``
    index += (owner * n)[:, None]  # into the stacked samples
    resampled = stacked[index]
    del index
    # the rows of one sample are consecutive: split the block where its sample changes
    edges = [first, *range((first // N_RESAMPLES + 1) * N_RESAMPLES, last, N_RESAMPLES), last]
    fns = [statistics[a // N_RESAMPLES] for a in edges[:-1]]
    for fn in {id(f): f for f in fns}.values():
        spans = [(a, b) for (a, b), f in zip(pairwise(edges), fns, strict=True) if f is fn]
        if len(spans) == len(fns):  # the whole block: a view
            theta[first:last] = fn(resampled, axis=-1)
            continue
        chosen = np.concatenate([np.arange(a, b) for a, b in spans])
        theta[chosen] = fn(resampled[chosen - first], axis=-1)


def percentile_interval(theta: FloatArray) -> FloatArray:
    """The 95 % percentile interval ``(k, 2)`` of each row of bootstrap statistics ``theta``.

    ``scipy.stats.quantile(theta, [α, 1 − α], axis=-1)`` (its default
    ``linear`` method, Hyndman & Fan type 7) with α = (1 − 0.95)/2, computed
    the way scipy computes it, bit for bit (a test compares them): on the
    sorted row ``y`` of ``n`` values, ``j + g = p n + 1 − p`` and the value
    ``(1 − g) y[j−1] + g y[j]``. Written out so that a campaign's statistics
    do not import ``scipy.stats`` (0.5–1 s). A row holding NaN gives NaN.
    """
    alpha = (1 - CONFIDENCE) / 2
    p = np.array([alpha, 1 - alpha])
    n = theta.shape[-1]
    y = np.sort(theta, axis=-1)
    jg = p * n + (1 - p)
    upper = jg // 1
    g = jg % 1
    g = np.where(upper - 1 < 0, 0.0, g)
    lower = np.clip(upper - 1, 0.0, n - 1).astype(np.int64)
    upper = np.clip(upper, 0.0, n - 1).astype(np.int64)
    interval: FloatArray = (1 - g) * y[..., lower] + g * y[..., upper]
    interval[np.isnan(theta).any(axis=-1)] = np.nan
    return interval


def bootstrap_ci(
    x: np.ndarray, statistic: Callable[..., np.ndarray], rng: np.random.Generator
) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of ``statistic(x)``; NaN for fewer than 2 values."""
    lo, hi = bootstrap_cis([np.asarray(x, dtype=float)], [statistic], rng)[0]
    return float(lo), float(hi)


def wilson_ci(successes: int, n: int) -> tuple[float, float]:
    """Wilson score interval of a proportion (95 %); NaN for ``n = 0``. See :func:`wilson_cis`."""
    lo, hi = wilson_cis(np.asarray(successes), np.asarray(n))
    return float(lo), float(hi)


def wilson_cis(successes: npt.ArrayLike, n: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Wilson (1927) score intervals (95 %) of proportions ``successes / n``, element-wise.

    ``centre ± half`` with ``centre = (p + z²/2n) / (1 + z²/n)`` and
    ``half = z √(p(1−p)/n + z²/4n²) / (1 + z²/n)``. Exact in theory, the
    formula rounds: at ``p = 0`` its lower end came out 2.8e-17 for some
    ``n`` and at ``p = 1`` its upper end 1.0000000000000002, so an error bar
    ``p − low`` went negative. Every interval here lies in [0, 1] and holds
    its estimate: it is clipped to [0, p] below and [p, 1] above, so the lower
    end is exactly 0 at no success and the upper exactly 1 when all succeed.
    NaN where ``n = 0``.
    """
    k = np.asarray(successes, dtype=float)
    size = np.asarray(n, dtype=float)
    z = Z_TWO_SIDED
    with np.errstate(divide="ignore", invalid="ignore"):
        p = k / size
        denom = 1 + z * z / size
        centre = (p + z * z / (2 * size)) / denom
        half = z * np.sqrt(p * (1 - p) / size + z * z / (4 * size * size)) / denom
    lo = np.minimum(np.maximum(centre - half, 0.0), p)
    hi = np.maximum(np.minimum(centre + half, 1.0), p)
    return lo, hi


def _point_values(samples: Sequence[FloatArray], statistic: Statistic) -> FloatArray:
    """``statistic`` of each sample; samples of equal size in one call along ``axis=-1``."""
    out = np.empty(len(samples))
    by_size: dict[int, list[int]] = {}
    for j, x in enumerate(samples):
        by_size.setdefault(x.size, []).append(j)
    for size, indices in by_size.items():
        if size == 0:  # a statistic of nothing: NaN (never asked for by a campaign)
            out[indices] = np.nan
            continue
        out[indices] = statistic(np.stack([samples[j] for j in indices]), axis=-1)
    return out


def _segments(
    frame: pd.DataFrame, by: Sequence[str]
) -> tuple[list[tuple[Hashable, ...]], npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """The groups of ``frame.groupby(by, sort=True, observed=True)``, as index segments.

    Returns the group keys (tuples, in group order), the row positions sorted
    by group (stable: rows keep their order within a group) and the start of
    each group's segment in them, with the end as last element.
    """
    grouped = frame.groupby(list(by), sort=True, observed=True)
    codes = grouped.ngroup().to_numpy(dtype=float)  # NaN: a key with NaN, dropped
    kept = np.flatnonzero(~np.isnan(codes))
    order = kept[np.argsort(codes[kept], kind="stable")]
    counts = np.bincount(codes[order].astype(np.intp))
    bounds = np.concatenate(([0], np.cumsum(counts))).astype(np.intp)
    index = grouped.size().index
    keys = [k if isinstance(k, tuple) else (k,) for k in index]
    return keys, order, bounds


def _frame(
    by: Sequence[str], keys: Sequence[tuple[Hashable, ...]], per_group: int, columns: dict[str, Any]
) -> pd.DataFrame:
    """Long-format rows: ``per_group`` rows per group key, then ``columns`` (one value a row)."""
    cols: dict[str, Any] = {
        name: [k[i] for k in keys for _ in range(per_group)] for i, name in enumerate(by)
    }
    return pd.DataFrame({**cols, **columns})


def _marginal_frame(
    by: Sequence[str],
    keys: Sequence[tuple[Hashable, ...]],
    sizes: np.ndarray,
    labels: Sequence[tuple[str, str]],
    value: FloatArray,
    low: FloatArray,
    high: FloatArray,
    kind: str = "marginal",
) -> pd.DataFrame:
    """Marginal rows: per group key, one row per ``(metric, statistic)`` of ``labels``.

    ``value``, ``low`` and ``high`` are (groups × labels); ``sizes`` the ok runs per group
    (column ``n``), or per group and label (groups × labels). ``kind``: the rows' kind.
    """
    per_group = len(labels)
    n = sizes.astype(np.int64)
    return _frame(
        by,
        keys,
        per_group,
        {
            "kind": kind,
            "metric": [m for _ in keys for m, _ in labels],
            "statistic": [s for _ in keys for _, s in labels],
            "value": value.ravel(),
            "ci_low": low.ravel(),
            "ci_high": high.ravel(),
            "n": n.ravel() if n.ndim == 2 else np.repeat(n, per_group),
        },
    )


def describe(runs: pd.DataFrame, by: Sequence[str], seed: int = 0) -> pd.DataFrame:
    """Per group: mean/median/p95 of Δv, miss and fuel penalty with bootstrap CIs.

    Only runs with status ``ok`` count; ``n`` is their number. Solve statistics
    (success %, mean and max time) are added as rows without intervals. Rows
    per group: each metric of :data:`METRICS` with each statistic of
    :data:`STATISTICS`, then :data:`SOLVE_STATISTICS`; groups sorted by ``by``.
    """
    ok = runs[runs["status"] == "ok"]
    keys, order, bounds = _segments(ok, by)
    if not keys:
        return pd.DataFrame([])
    sizes = np.diff(bounds)
    spans = list(pairwise(bounds))
    n_stat = len(METRICS) * len(STATISTICS)
    value = np.empty((len(keys), n_stat + len(SOLVE_STATISTICS)))
    low = np.full_like(value, np.nan)
    high = np.full_like(value, np.nan)
    value[:, :n_stat], low[:, :n_stat], high[:, :n_stat] = _bootstrapped(
        ok, order, spans, METRICS, np.random.default_rng(seed)
    )
    for k, (metric, _, fn) in enumerate(SOLVE_STATISTICS):
        x = ok[metric].to_numpy(dtype=float)[order]
        value[:, n_stat + k] = _point_values([x[a:b] for a, b in spans], fn)
    labels = [(m, s) for m in METRICS for s in STATISTICS] + [
        (m, s) for m, s, _ in SOLVE_STATISTICS
    ]
    return _marginal_frame(by, keys, sizes, labels, value, low, high)


def _bootstrapped(
    ok: pd.DataFrame,
    order: npt.NDArray[np.intp],
    spans: Sequence[tuple[int, int]],
    metrics: Sequence[str],
    rng: np.random.Generator,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each :data:`STATISTICS` of each of ``metrics`` per group, with bootstrap intervals.

    Returns value, low and high, (groups × metrics·statistics); the draws are
    made from ``rng`` in row order (group, metric, statistic).
    """
    samples: list[FloatArray] = []
    fns: list[Statistic] = []
    per_metric = {m: ok[m].to_numpy(dtype=float)[order] for m in metrics}
    for a, b in spans:
        for metric in metrics:
            x = per_metric[metric][a:b]
            samples += [x] * len(STATISTICS)
            fns += STATISTICS.values()
    ci = bootstrap_cis(samples, fns, rng)
    n_stat = len(metrics) * len(STATISTICS)
    value = np.empty((len(spans), n_stat))
    for k, fn in enumerate(fns[:n_stat]):
        value[:, k] = _point_values(samples[k::n_stat], fn)
    return value, ci[:, 0].reshape(len(spans), n_stat), ci[:, 1].reshape(len(spans), n_stat)


def _ok_groups(
    runs: pd.DataFrame, by: Sequence[str], columns: Sequence[str]
) -> (
    tuple[pd.DataFrame, list[tuple[Hashable, ...]], npt.NDArray[np.intp], npt.NDArray[np.intp]]
    | None
):
    """The ok runs and their groups (:func:`_segments`); None without ``columns`` or groups."""
    if any(c not in runs.columns for c in columns):
        return None
    ok = runs[runs["status"] == "ok"]
    keys, order, bounds = _segments(ok, by)
    return (ok, keys, order, bounds) if keys else None


#: The applied Δv and its fuel penalty against the exact continuous fuel optimum (issue 33,
#: item 3), beside the paper's :data:`METRICS`.
APPLIED_METRICS = ("delta_v_applied_km_s", "fuel_penalty_applied_pct")
#: Stream of their bootstrap: ``default_rng([seed, APPLIED_STREAM])``, their own, so that
#: they change no row of :func:`describe` (as :data:`SAFETY_STREAM`).
APPLIED_STREAM = 2**32 - 4


def applied(runs: pd.DataFrame, by: Sequence[str], seed: int = 0) -> pd.DataFrame:
    """Per group: mean/median/p95 of :data:`APPLIED_METRICS` with bootstrap CIs.

    Rows as those of :func:`describe` for its metrics (ok runs only), drawn
    from a stream of their own (:data:`APPLIED_STREAM`). Empty when the runs
    have no such columns (a campaign written before issue 33).
    """
    groups = _ok_groups(runs, by, APPLIED_METRICS)
    if groups is None:
        return pd.DataFrame([])
    ok, keys, order, bounds = groups
    spans = list(pairwise(bounds))
    rng = np.random.default_rng([seed, APPLIED_STREAM])
    value, low, high = _bootstrapped(ok, order, spans, APPLIED_METRICS, rng)
    labels = [(m, s) for m in APPLIED_METRICS for s in STATISTICS]
    return _marginal_frame(by, keys, np.diff(bounds), labels, value, low, high)


#: Stream of the safety rows' bootstrap: ``default_rng([seed, SAFETY_STREAM])``, its own, so
#: that they change no other row (issue 32).
SAFETY_STREAM = 2**32 - 3


def _p1(x: np.ndarray, axis: int = -1) -> np.ndarray:
    p1: np.ndarray = np.percentile(x, 1, axis=axis)
    return p1


#: Safety rows (issue 32): (metric, statistic name, statistic) with bootstrap intervals.
SAFETY_STATISTICS: tuple[tuple[str, str, Statistic], ...] = (
    ("safety_min_distance_km", "median", np.median),
    ("safety_min_distance_km", "p1", _p1),
    ("safety_unsafe_time_s", "mean", np.mean),
)


def safety(runs: pd.DataFrame, by: Sequence[str], seed: int = 0) -> pd.DataFrame:
    """Per group, the safety of the true trajectories of a constrained campaign (issue 32).

    ``safety_violated`` / ``share``: the share of ok runs that entered the unsafe
    set, with its Wilson interval; the median and 1st percentile of
    ``safety_min_distance_km`` and the mean of ``safety_unsafe_time_s`` with
    bootstrap intervals from a stream of their own (:data:`SAFETY_STREAM`).
    Empty when the runs have no safety columns (a campaign without constraints).
    """
    return _flag_and_statistics(
        runs, by, "safety_violated", SAFETY_STATISTICS, np.random.default_rng([seed, SAFETY_STREAM])
    )


#: Abort-safety rows (issue 34 item 4): (metric, statistic name, statistic) with bootstrap
#: intervals, beside the share of runs with ``abort_unsafe``.
ABORT_STATISTICS: tuple[tuple[str, str, Statistic], ...] = (
    ("abort_min_distance_km", "median", np.median),
    ("abort_min_distance_km", "p1", _p1),
)
#: Stream of their bootstrap: ``default_rng([seed, ABORT_STREAM])``, their own, so that they
#: change no other row (as :data:`SAFETY_STREAM`).
ABORT_STREAM = 2**32 - 5


def abort_safety(runs: pd.DataFrame, by: Sequence[str], seed: int = 0) -> pd.DataFrame:
    """Per group, the abort safety of the true trajectories (issue 34 item 4).

    ``abort_unsafe`` / ``share``: the share of ok runs with a step whose free
    drift enters the keep-out zone (Wilson interval); the median and 1st
    percentile of ``abort_min_distance_km`` (bootstrap, :data:`ABORT_STREAM`).
    Empty without the abort columns (no ``constraints.abort_safe_s``).
    """
    return _flag_and_statistics(
        runs, by, "abort_unsafe", ABORT_STATISTICS, np.random.default_rng([seed, ABORT_STREAM])
    )


def _flag_and_statistics(
    runs: pd.DataFrame,
    by: Sequence[str],
    flag: str,
    statistics: tuple[tuple[str, str, Statistic], ...],
    rng: np.random.Generator,
) -> pd.DataFrame:
    """Per group: the share of ok runs with ``flag`` (Wilson) and ``statistics`` (bootstrap
    from ``rng``); empty when the runs have no ``flag`` column."""
    groups = _ok_groups(runs, by, (flag,))
    if groups is None:
        return pd.DataFrame([])
    ok, keys, order, bounds = groups
    spans = list(pairwise(bounds))
    sizes = np.diff(bounds)
    violated = ok[flag].to_numpy(dtype=float)[order]
    counts = np.array([np.sum(violated[a:b]) for a, b in spans])
    share_lo, share_hi = wilson_cis(counts, sizes)
    samples: list[FloatArray] = []
    fns: list[Statistic] = []
    per_metric = {m: ok[m].to_numpy(dtype=float)[order] for m, _, _ in statistics}
    for a, b in spans:
        for metric, _, fn in statistics:
            samples.append(per_metric[metric][a:b])
            fns.append(fn)
    ci = bootstrap_cis(samples, fns, rng)
    per_group = 1 + len(statistics)
    value = np.empty((len(keys), per_group))
    low = np.empty_like(value)
    high = np.empty_like(value)
    value[:, 0], low[:, 0], high[:, 0] = counts / sizes, share_lo, share_hi
    for k, (_, _, fn) in enumerate(statistics):
        value[:, 1 + k] = _point_values(samples[k :: len(statistics)], fn)
    low[:, 1:] = ci[:, 0].reshape(len(keys), len(statistics))
    high[:, 1:] = ci[:, 1].reshape(len(keys), len(statistics))
    labels = [(flag, "share")] + [(m, n) for m, n, _ in statistics]
    return _marginal_frame(by, keys, sizes, labels, value, low, high)


def paired(
    runs: pd.DataFrame,
    by: Sequence[str] = (),
    seed: int = 0,
    pairs: Sequence[tuple[str, str]] = DEFAULT_PAIRS,
) -> pd.DataFrame:
    """Seed-by-seed comparisons of architecture pairs (on the same noise).

    For each pair (A, B) in ``pairs`` present in the campaign: the share of
    seeds where A misses less than B (Wilson CI), the median of
    ``miss_A − miss_B`` and the mean of ``Δv_A − Δv_B`` (bootstrap CIs), over
    the seeds of the group where both ran ok. Rows per group and pair:
    ``frac_less``, ``median_diff``, ``mean_diff``.

    The pairs of :data:`PAIRS` come first (groups sorted by ``by``, then the
    pairs in the order given), bootstrapped from one stream seeded
    ``seed + 1`` as they always were; then each *added* pair (any other, e.g.
    ``--pair``), its groups in order, from a stream of its own keyed by its
    names (:data:`PAIR_STREAM`), so that a pair's rows are the same whatever
    other pairs are asked for and adding one changes no row of another.
    """
    ok = runs[runs["status"] == "ok"]
    if ok.empty:
        return pd.DataFrame([])
    wide = _wide(ok, by)
    keys, bounds = _groups(wide.index, by)
    columns: set[Any] = set(wide.columns)
    present = [
        (a, b)
        for a, b in dict.fromkeys(pairs)
        if ("miss_km", a) in columns and ("miss_km", b) in columns
    ]
    blocks = {p: _block(wide, wide, p) for p in present}
    shared = [p for p in present if p in PAIRS]
    streams = [(shared, np.random.default_rng(seed + 1))] if shared else []
    streams += [([p], _pair_generator(seed, p)) for p in present if p not in PAIRS]
    frames = [_paired_rows(blocks, keys, bounds, chosen, by, rng) for chosen, rng in streams]
    frames = [f for f in frames if not f.empty]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame([])


def paired_across(
    a: pd.DataFrame,
    b: pd.DataFrame,
    pairs: Sequence[tuple[str, str]],
    by: Sequence[str] = (),
    seed: int = 0,
) -> pd.DataFrame:
    """:func:`paired` across two campaigns on the same noise: A of each pair from the runs
    ``a``, B from the runs ``b``, seed by seed within each group of ``by`` (columns of both).

    The rows of :func:`paired` (``frac_less`` with its Wilson interval, ``median_diff``
    and ``mean_diff`` with bootstrap intervals), each pair drawn, its groups in order,
    from the stream of an *added* pair (:func:`_pair_generator`, keyed by its names):
    the rows :func:`paired` gives that pair added to one campaign that holds both
    runs. A pair may name one architecture twice (the same architecture in the two
    campaigns).
    """
    ok_a, ok_b = (r[r["status"] == "ok"] for r in (a, b))
    if ok_a.empty or ok_b.empty:
        return pd.DataFrame([])
    wide_a, wide_b = _wide(ok_a, by), _wide(ok_b, by)
    index = wide_a.index.union(wide_b.index)  # sorted: a group is a run of equal keys
    wide_a, wide_b = wide_a.reindex(index), wide_b.reindex(index)
    keys, bounds = _groups(index, by)
    present = [
        (x, y)
        for x, y in dict.fromkeys(pairs)
        if ("miss_km", x) in wide_a.columns and ("miss_km", y) in wide_b.columns
    ]
    blocks = {p: _block(wide_a, wide_b, p) for p in present}
    frames = [
        _paired_rows(blocks, keys, bounds, [p], by, _pair_generator(seed, p)) for p in present
    ]
    if APPLIED in ok_a.columns and APPLIED in ok_b.columns:
        frames += [_applied_across(ok_a, ok_b, index, keys, bounds, present, by, seed)]
    frames = [f for f in frames if not f.empty]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame([])


#: The applied Δv (issue 33, item 3) that :func:`paired_across` compares too, when both
#: campaigns hold it.
APPLIED = APPLIED_METRICS[0]


def _applied_across(
    ok_a: pd.DataFrame,
    ok_b: pd.DataFrame,
    index: pd.Index,
    keys: Sequence[tuple[Hashable, ...]],
    bounds: npt.NDArray[np.intp],
    pairs: Sequence[tuple[str, str]],
    by: Sequence[str],
    seed: int,
) -> pd.DataFrame:
    """``mean_diff`` rows of the applied Δv of each pair (A − B per seed, bootstrap CI) over
    the seeds where both have one, per group; from a stream of their own
    (``default_rng([seed, APPLIED_STREAM, crc32("A:B")])``), so that they change no row of
    the paper's metrics."""
    wide_a, wide_b = (
        ok.pivot_table(index=[*by, "seed"], columns="arch", values=APPLIED).reindex(index)
        for ok in (ok_a, ok_b)
    )
    idents: list[tuple[Hashable, ...]] = []
    head: list[tuple[str, str, int]] = []
    samples: list[FloatArray] = []
    cis: list[FloatArray] = []
    for x, y in pairs:  # each pair its stream, its groups in order (as an added pair's)
        if x not in wide_a.columns or y not in wide_b.columns:
            continue
        diff = wide_a[x].to_numpy(dtype=float) - wide_b[y].to_numpy(dtype=float)
        mine: list[FloatArray] = []
        for key, (lo, hi) in zip(keys, pairwise(bounds), strict=True):
            d = diff[lo:hi][~np.isnan(diff[lo:hi])]
            if len(d):
                idents.append(key)
                head.append((x, y, len(d)))
                mine.append(d)
        if mine:
            rng = np.random.default_rng([seed, APPLIED_STREAM, zlib.crc32(f"{x}:{y}".encode())])
            cis.append(bootstrap_cis(mine, [np.mean] * len(mine), rng))
            samples += mine
    if not head:
        return pd.DataFrame([])
    ci = np.vstack(cis)
    return _frame(
        by,
        idents,
        1,
        {
            "kind": "paired",
            "arch": [x for x, _, _ in head],
            "other": [y for _, y, _ in head],
            "n": [n for _, _, n in head],
            "metric": APPLIED,
            "statistic": "mean_diff",
            "value": _point_values(samples, np.mean),
            "ci_low": ci[:, 0],
            "ci_high": ci[:, 1],
        },
    )


def _wide(ok: pd.DataFrame, by: Sequence[str]) -> pd.DataFrame:
    """One table (group, seed) × (metric, arch) of the ok runs, sorted by group and seed."""
    return ok.pivot_table(index=[*by, "seed"], columns="arch", values=["miss_km", "delta_v_km_s"])


def _groups(
    index: pd.Index, by: Sequence[str]
) -> tuple[list[tuple[Hashable, ...]], npt.NDArray[np.intp]]:
    """The group keys of a sorted (group, seed) index and each group's first row (then the end)."""
    if not by:
        return [()], np.array([0, len(index)])
    per_row = list(zip(*(index.get_level_values(c) for c in by), strict=True))
    starts = [i for i, k in enumerate(per_row) if i == 0 or k != per_row[i - 1]]
    return [per_row[i] for i in starts], np.array([*starts, len(per_row)])


def _block(wide_a: pd.DataFrame, wide_b: pd.DataFrame, pair: tuple[str, str]) -> FloatArray:
    """Miss of A, miss of B, Δv of A, Δv of B per row (NaN where one did not run ok)."""
    a, b = pair
    columns = [
        wide_a[("miss_km", a)],
        wide_b[("miss_km", b)],
        wide_a[("delta_v_km_s", a)],
        wide_b[("delta_v_km_s", b)],
    ]
    return np.column_stack([c.to_numpy(dtype=float) for c in columns])


def _pair_generator(seed: int, pair: tuple[str, str]) -> np.random.Generator:
    """The bootstrap stream of an added pair: the seed, :data:`PAIR_STREAM` and its names."""
    return np.random.default_rng([seed, PAIR_STREAM, zlib.crc32(f"{pair[0]}:{pair[1]}".encode())])


def _paired_rows(
    blocks: Mapping[tuple[str, str], FloatArray],
    keys: Sequence[tuple[Hashable, ...]],
    bounds: npt.NDArray[np.intp],
    pairs: Sequence[tuple[str, str]],
    by: Sequence[str],
    rng: np.random.Generator,
) -> pd.DataFrame:
    """The rows of :func:`paired` for ``pairs`` (each group, then each pair), drawn from ``rng``.

    ``blocks``: per pair, the rows of :func:`_block` (groups delimited by ``bounds``).
    """
    idents: list[tuple[Hashable, ...]] = []
    head: list[tuple[str, str, int]] = []  # (arch, other, n) per group and pair
    less_rows: list[tuple[float, float, float]] = []
    samples: list[FloatArray] = []
    fns: list[Statistic] = []
    for key, (a_row, b_row) in zip(keys, pairwise(bounds), strict=True):
        for a, b in pairs:
            block = blocks[a, b][a_row:b_row]
            both = block[~np.isnan(block).any(axis=1)]
            n = len(both)
            if n == 0:
                continue
            less = int((both[:, 0] < both[:, 1]).sum())
            lo, hi = wilson_ci(less, n)
            idents.append(key)
            head.append((a, b, n))
            less_rows.append((less / n, lo, hi))
            samples += [both[:, 0] - both[:, 1], both[:, 2] - both[:, 3]]
            fns += [np.median, np.mean]
    if not head:
        return pd.DataFrame([])
    ci = bootstrap_cis(samples, fns, rng).reshape(len(head), 2, 2)
    value = np.column_stack(
        [
            [v for v, _, _ in less_rows],
            _point_values(samples[0::2], np.median),
            _point_values(samples[1::2], np.mean),
        ]
    )
    low = np.column_stack([[lo for _, lo, _ in less_rows], ci[:, :, 0]])
    high = np.column_stack([[hi for _, _, hi in less_rows], ci[:, :, 1]])
    return _frame(
        by,
        idents,
        3,
        {
            "kind": "paired",
            "arch": [a for a, _, _ in head for _ in range(3)],
            "other": [b for _, b, _ in head for _ in range(3)],
            "n": [n for _, _, n in head for _ in range(3)],
            "metric": ["miss_km", "miss_km", "delta_v_km_s"] * len(head),
            "statistic": ["frac_less", "median_diff", "mean_diff"] * len(head),
            "value": value.ravel(),
            "ci_low": low.ravel(),
            "ci_high": high.ravel(),
        },
    )


# ---------------------------------------------------------------------------
# Filter consistency against χ² bands (issue 33, item 4)
# ---------------------------------------------------------------------------

#: The runs columns of filter consistency (:mod:`cwrend_cli.physics.metrics`) and their
#: degrees of freedom: each run's time-averaged NEES (rows 1 … N) and NIS (nominal rows).
CONSISTENCY_METRICS: tuple[tuple[str, int], ...] = (
    ("mean_nees", NEES_DOF),
    ("mean_nis_nominal", NIS_DOF),
)


def consistency(
    runs: pd.DataFrame, by: Sequence[str], nis_dof: npt.ArrayLike = NIS_DOF
) -> pd.DataFrame:
    """Per group: the campaign mean of each run's time-averaged NEES and NIS, and its band.

    Rows ``kind = "consistency"`` for each metric of :data:`CONSISTENCY_METRICS`
    (statistic ``mean``): ``value`` the mean over the ok runs with a finite
    value, ``n`` their number, and ``ci_low`` / ``ci_high`` the χ² 95 % band
    for ``n`` runs (:func:`~cwrend_cli.physics.metrics.mean_in_band`), where the
    mean lies for a consistent filter (a band of the hypothesis, not an
    interval of the estimate).

    The band treats each run's time average as one χ² value: the steps of a
    run are correlated (the NEES strongly), and an average of correlated χ²_n
    values has the mean n and at most the variance 2n of one, so the sum over
    the runs has the mean of χ²(N n) and at most its variance: the band is
    conservative (exact when a run's errors do not change over time). Empty
    without the columns (runs written before cwrend stored them).

    ``nis_dof``: the NIS's degrees of freedom, the measurement dimension m of
    each run's sensor (3, or 2 for angles; one value for all, or one per row
    of ``runs``, constant within a group of ``by``).
    """
    if not all(m in runs.columns for m, _ in CONSISTENCY_METRICS):
        return pd.DataFrame([])
    is_ok = (runs["status"] == "ok").to_numpy()
    ok = runs[is_ok]
    m = np.broadcast_to(np.asarray(nis_dof, dtype=int), (len(runs),))[is_ok]
    keys, order, bounds = _segments(ok, by)
    if not keys:
        return pd.DataFrame([])
    rows = np.array(
        [
            [
                mean_in_band(
                    ok[metric].to_numpy(dtype=float)[order][a:b],
                    int(m[order][a]) if metric == "mean_nis_nominal" else dof,
                )
                for metric, dof in CONSISTENCY_METRICS
            ]
            for a, b in pairwise(bounds)
        ]
    )  # (group, metric, [mean, low, high, n])
    labels = [(metric, "mean") for metric, _ in CONSISTENCY_METRICS]
    value, low, high, n = (rows[..., k] for k in range(4))
    return _marginal_frame(by, keys, n, labels, value, low, high, kind="consistency")
