"""Sequential Monte Carlo: seeds in batches until the 95 % intervals are narrow enough (issue 19).

``cwrend ablate … --until TARGET`` runs seeds ``0 … n−1`` for
``n = batch, 2·batch, …`` (each step an ordinary campaign that resumes the
previous one, so the result is the fixed campaign of the final seed count,
bit for bit) and stops when every targeted interval's half-width is at most
the target, or at ``--max-seeds``. This module is pure: it parses targets and
reads the campaign's own statistics frame (:mod:`cwrend_cli.campaign.statistics`),
so a target reported as met is met by the intervals the campaign reports.

Target syntax, ``[STATISTIC.]METRIC[@A-B]:HALF_WIDTH[%]``:

* ``miss_km:0.0005`` — the half-width of the 95 % interval of the mean miss
  is at most 0.5 m, for every architecture;
* ``miss:0.0005`` — the same: ``miss``, ``dv`` and ``fuel`` name the metrics as in
  ``cwrend compare`` and ``cwrend table``;
* ``median.miss_km:5%`` — of the median, relative: at most 5 % of |median|;
* ``miss_km@mtf_adaptive-plain_adaptive:0.0005`` — the paired difference of
  the two architectures on the same seeds (``median_diff`` for the miss,
  ``mean_diff`` for Δv, or ``frac_less.miss_km@A-B:0.05`` for the share of
  seeds where A misses less).

The stopping rule and coverage: a rule that stops when an interval is narrow
enough looks at the data several times, and stopping on a lucky, too-narrow
interval would lower coverage. cwrend limits this as the fixed-width
sequential procedures of Chow & Robbins (1965, *Ann. Math. Statist.* 36, 457)
do: widths are checked only at batch boundaries, never before
:data:`MIN_BATCHES` batches (at least ``MIN_BATCHES · batch`` seeds, and
:data:`MIN_SEEDS`), and the reported intervals are those of the final seed
count, recomputed on all its seeds. For such rules the coverage of the final
interval tends to the nominal 95 % as the target width shrinks; with wide
targets (few batches) it can fall a little short of it, so a target should
ask for several batches' worth of seeds.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import pandas as pd

from cwrend_cli.campaign.statistics import DEFAULT_PAIRS, METRICS, STATISTICS
from cwrend_cli.config.messages import did_you_mean
from cwrend_cli.errors import ConfigError
from cwrend_cli.limits import MAX_RUNS
from cwrend_cli.output.tables import METRIC_NAMES, suffix_unit

__all__ = [
    "MIN_BATCHES",
    "MIN_SEEDS",
    "Achieved",
    "Target",
    "achieved",
    "checked_from",
    "next_batch_message",
    "parse_until",
    "ready",
    "seed_counts",
    "unchecked_message",
    "unmet_message",
]

#: Widths are not checked before this many batches.
MIN_BATCHES = 2
#: Nor before this many seeds (a bootstrap interval of fewer is unreliable).
MIN_SEEDS = 20
#: The paired statistic of each metric (statistics.paired).
_PAIRED_STATISTIC = {"miss_km": "median_diff", "delta_v_km_s": "mean_diff"}
_SYNTAX = re.compile(
    r"^(?:(?P<stat>[a-z_0-9]+)\.)?(?P<metric>[a-z_0-9]+)"
    r"(?:@(?P<a>[a-z_0-9]+)-(?P<b>[a-z_0-9]+))?:(?P<width>[^%]+)(?P<pct>%)?$"
)


@dataclass(frozen=True)
class Target:
    """A requested half-width of a 95 % interval (absolute, in the metric's unit, or relative)."""

    metric: str
    statistic: str
    half_width: float
    relative: bool  # half_width is a fraction of |value|
    pair: tuple[str, str] | None = None  # a paired difference A − B, else every architecture

    @property
    def unit(self) -> str | None:
        """The unit of the targeted value and its half-width: the metric's (``miss_km`` → km),
        ``None`` for a share of seeds (``frac_less``)."""
        return None if self.statistic == "frac_less" else suffix_unit(self.metric)


def parse_until(
    text: str,
    pairs: Sequence[tuple[str, str]] = DEFAULT_PAIRS,
    archs: Sequence[str] | None = None,
    remembered: Sequence[tuple[str, str]] = (),
) -> Target:
    """Parse ``--until``; :class:`ConfigError` with the syntax on a bad target.

    A paired target names one of ``pairs`` whose architectures are all in
    ``archs`` (those the command runs; ``None``: any), the pairs the campaign
    compares; the refusal lists only those. ``remembered``: pairs earlier
    commands added (``--pair``, in the manifest), named with the architecture
    to add when the target is one of them that ``archs`` do not make.
    """
    syntax = (
        "[STATISTIC.]METRIC[@A-B]:HALF_WIDTH[%], e.g. miss_km:0.0005, median.miss_km:5% or "
        "miss_km@mtf_adaptive-plain_adaptive:0.0005"
    )
    m = _SYNTAX.match(text.strip())
    if m is None:
        raise ConfigError(f"--until {text!r}: expected {syntax}")
    metric = METRIC_NAMES.get(m["metric"], m["metric"])  # miss, dv, fuel as in compare, table
    try:
        width = float(m["width"])
    except ValueError:
        raise ConfigError(f"--until {text!r}: the half-width must be a number; {syntax}") from None
    relative = m["pct"] is not None
    if not math.isfinite(width) or width <= 0:
        raise ConfigError(f"--until {text!r}: the half-width must be positive")
    if m["a"] is None:
        if metric not in METRICS:
            short = [k for k, v in METRIC_NAMES.items() if v in METRICS]
            near = did_you_mean(m["metric"], [*short, *METRICS])
            raise ConfigError(
                f"--until {text!r}: metric must be one of {', '.join(short)} "
                f"({', '.join(METRICS)}){near}"
            )
        statistic = m["stat"] or "mean"
        if statistic not in STATISTICS:
            raise ConfigError(f"--until {text!r}: statistic must be one of {', '.join(STATISTICS)}")
        return Target(metric, statistic, width / 100 if relative else width, relative)
    pair = (m["a"], m["b"])
    compared = [p for p in pairs if archs is None or set(p) <= set(archs)]
    if pair not in compared:
        known = ", ".join(f"{a}-{b}" for a, b in compared) or "none (--pair A:B adds one)"
        why = ""
        if pair in remembered and archs is not None:
            missing = " and ".join(a for a in pair if a not in archs)
            why = (
                f"; {pair[0]}-{pair[1]} (added by an earlier --pair) is compared when both its "
                f"architectures run: add {missing} to --arch"
            )
        raise ConfigError(f"--until {text!r}: pairs compared are {known}{why}")
    if metric not in _PAIRED_STATISTIC:
        raise ConfigError(f"--until {text!r}: a paired target is on miss_km or delta_v_km_s")
    statistic = m["stat"] or _PAIRED_STATISTIC[metric]
    allowed = {_PAIRED_STATISTIC[metric], *(("frac_less",) if metric == "miss_km" else ())}
    if statistic not in allowed:
        raise ConfigError(
            f"--until {text!r}: the paired statistic of {metric} is {' or '.join(sorted(allowed))}"
        )
    return Target(metric, statistic, width / 100 if relative else width, relative, pair)


def seed_counts(batch: int, max_seeds: int) -> Iterator[int]:
    """Seed counts to try: ``batch, 2·batch, …`` up to ``max_seeds`` (always tried last)."""
    if batch < 1 or max_seeds < 1:
        raise ConfigError("--batch and --max-seeds must be at least 1")
    n = batch
    while n < max_seeds:
        yield n
        n += batch
    yield max_seeds


def checked_from(batch: int) -> int:
    """The seed count from which widths are checked: :data:`MIN_BATCHES` batches and at
    least :data:`MIN_SEEDS` seeds."""
    return max(MIN_BATCHES * batch, MIN_SEEDS)


def ready(n_seeds: int, batch: int) -> bool:
    """Whether widths may be checked at ``n_seeds`` (the minimum batches and seeds reached)."""
    return n_seeds >= checked_from(batch)


def seeds_limit(runs_per_seed: int = 1) -> int:
    """The most seeds a campaign of ``runs_per_seed`` runs a seed (points × architectures)
    accepts: :data:`~cwrend_cli.limits.MAX_RUNS` runs, the bound of ``--max-seeds`` too."""
    return MAX_RUNS // max(1, runs_per_seed)


def _beyond_limit(needed: int, limit: int, them: str = "it") -> str:
    """The advice when ``needed`` seeds exceed ``limit`` (:func:`seeds_limit`): none to raise
    --max-seeds to, but what else to change."""
    return (
        f"about {needed:,} seeds would meet {them} (a half-width shrinks as 1/√seeds), more "
        f"than the {limit:,} seeds a campaign can run here (at most {MAX_RUNS:,} runs: seeds "
        "× points × architectures): "
        "the target cannot be reached within that limit; widen the target or target "
        "another metric or statistic"
    )


def unchecked_message(
    n_seeds: int, batch: int, achieved: Sequence[Achieved] = (), limit: int = MAX_RUNS
) -> str:
    """What ``--until`` says when it stopped at ``n_seeds`` (``--max-seeds``) before widths are
    checked (:func:`ready`): whether the target was met is not known, and how to know.

    The only verdict then (never beside :func:`unmet_message`): intervals of ``achieved``
    wider than their target so far are named, with the seeds they would need. Seeds
    beyond ``limit`` (:func:`seeds_limit`) are never advised: a target that would need
    more is said to be out of reach.
    """
    first = checked_from(batch)
    text = (
        f"--until not checked: widths are checked from {first:,} seeds ({MIN_BATCHES} batches "
        f"of --batch {batch}, at least {MIN_SEEDS}) and --max-seeds stopped the campaign at "
        f"{n_seeds}"
    )
    unmet = [a for a in achieved if not a.met]
    needed = [a.seeds_needed for a in unmet if a.seeds_needed is not None]
    lower = math.ceil(MIN_SEEDS / MIN_BATCHES)
    if first > limit:  # only a smaller batch is checked within the limit
        fix = f"lower --batch to {lower} (the limit is {limit:,} seeds)"
    else:
        fix = f"raise --max-seeds to {max([first, *needed]):,}"
        if MIN_BATCHES * batch > MIN_SEEDS:
            fix += f" or lower --batch to {lower}"
    if unmet:
        text += (
            f"; so far {len(unmet)} of {len(achieved)} interval(s) are wider than the target "
            f"({_too_wide(unmet)})"
        )
        if needed and max(needed) > limit:
            return f"{text}: {_beyond_limit(max(needed), limit)}"
        if needed:
            shrinks = "(a half-width shrinks as 1/√seeds)"
            fix = f"about {max(needed):,} seeds would meet it {shrinks}: {fix}"
    return f"{text}: {fix}"


def next_batch_message(n_seeds: int, batch: int, achieved: Sequence[Achieved]) -> str:
    """What ``--until`` says before its next batch: the widest interval against its target,
    or, every one within its target before widths are checked, from when they are."""
    unmet = [a for a in achieved if not a.met]
    if not unmet:
        return (
            f"{n_seeds} seeds: within the target, but widths are checked from "
            f"{checked_from(batch):,} seeds ({MIN_BATCHES} batches, at least {MIN_SEEDS}); "
            "next batch"
        )
    without = [a for a in unmet if not math.isfinite(a.half_width)]
    if without:
        return f"{n_seeds} seeds: not yet ({without[0].label}: no interval yet); next batch"
    widest = max(unmet, key=lambda a: a.half_width / a.limit if a.limit else math.inf)
    return (
        f"{n_seeds} seeds: not yet ({widest.label}: half-width {widest.half_width:.3g} "
        f"> {widest.limit:.3g}); next batch"
    )


@dataclass(frozen=True)
class Achieved:
    """A targeted interval as the campaign reports it."""

    label: str  # the architecture, or "A − B"
    value: float
    half_width: float
    limit: float  # the target half-width in the metric's unit
    n: int

    @property
    def met(self) -> bool:
        """Half-width at most the limit (a NaN interval, from < 2 seeds, is not met)."""
        return self.half_width <= self.limit

    @property
    def seeds_needed(self) -> int | None:
        """The seeds that would meet the limit if the half-width shrinks as 1/√n, else None.

        ``⌈n (half-width / limit)²⌉`` (at least ``n``): an estimate from the
        interval at ``n`` seeds, as the half-width of a mean's interval scales
        with ``σ/√n``; ``None`` without an interval or a positive limit.
        """
        usable = math.isfinite(self.half_width) and math.isfinite(self.limit) and self.limit > 0
        if not usable or self.n < 1:
            return None
        return max(self.n, math.ceil(self.n * (self.half_width / self.limit) ** 2))


def unmet_message(achieved: Sequence[Achieved], max_seeds: int, limit: int = MAX_RUNS) -> str:
    """What ``--until`` says when ``--max-seeds`` was reached with a target not met.

    Each interval not met with its half-width and target, and the seeds the
    widest would need (:attr:`Achieved.seeds_needed`); more than ``limit``
    (:func:`seeds_limit`): that the target is out of reach, not to raise --max-seeds.
    """
    unmet = [a for a in achieved if not a.met]
    text = (
        f"--until not met: --max-seeds {max_seeds} reached with "
        f"{len(unmet)} of {len(achieved)} interval(s) too wide ({_too_wide(unmet)})"
    )
    needed = [a.seeds_needed for a in unmet if a.seeds_needed is not None]
    them = "it" if len(unmet) == 1 else "them"
    if needed and max(needed) > limit:
        text += f"; {_beyond_limit(max(needed), limit, them)}"
    elif needed:
        text += (
            f"; about {max(needed):,} seeds would meet {them} "
            "(a half-width shrinks as 1/√seeds): raise --max-seeds or widen the target"
        )
    return text


def _too_wide(unmet: Sequence[Achieved]) -> str:
    """The intervals of ``unmet`` against their targets: ``A: half-width 0.0012 > 0.001; …``."""
    return "; ".join(
        f"{a.label}: no interval" if a.seeds_needed is None
        else f"{a.label}: half-width {a.half_width:.3g} > {a.limit:.3g}"
        for a in unmet
    )  # fmt: skip


def achieved(stats: pd.DataFrame, target: Target, archs: Sequence[str]) -> list[Achieved]:
    """The targeted intervals of a statistics frame (``statistics.describe`` + ``paired`` rows).

    Per architecture of ``archs`` (marginal) or for the target's pair; an
    interval the frame lacks (an architecture with no ok run) is reported
    with a NaN half-width, never met.
    """
    if target.pair is None:
        rows = stats[(stats["kind"] == "marginal") & (stats["metric"] == target.metric)]
        rows = rows[rows["statistic"] == target.statistic]
        wanted = [(a, rows[rows["arch"] == a]) for a in archs]
    else:
        a, b = target.pair
        rows = stats[(stats["kind"] == "paired") & (stats["metric"] == target.metric)]
        rows = rows[(rows["statistic"] == target.statistic) & (rows["arch"] == a)]
        wanted = [(f"{a} − {b}", rows[rows["other"] == b])]
    out = []
    for label, row in wanted:
        if row.empty:
            out.append(Achieved(label, math.nan, math.nan, math.nan, 0))
            continue
        r = row.iloc[0]
        value = float(r["value"])
        half = (float(r["ci_high"]) - float(r["ci_low"])) / 2
        limit = target.half_width * abs(value) if target.relative else target.half_width
        out.append(Achieved(label, value, half, limit, int(r["n"])))
    return out
