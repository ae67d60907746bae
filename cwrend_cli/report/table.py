"""``cwrend table``: cross-campaign tables of stored statistics, for a paper (md, LaTeX, CSV).

A table is read, never recomputed, from the statistics each campaign stored
(``ablation.parquet`` / ``sweep.parquet``: values with their 95 % intervals,
bootstrap or Wilson); counts, shares and worst cases of the runs are computed
from its ``runs.parquet`` (and ``solves/``), and ``--versus`` pairs the runs
of two campaigns (:func:`_across`). What a table shows is said by:

* **fields**, the dimensions of its rows (``--rows``) and columns
  (``--cols``): ``campaign`` (each results directory, named by its directory
  or a ``LABEL=DIR`` argument), ``arch``, ``other`` (the B of a paired
  comparison A − B), ``point`` (a grid point's id), ``metric`` (the values
  asked for, one column each by default) and any configuration key
  (``guidance.hold``, ``param.guidance.hold`` alike): its swept value where a
  campaign sweeps it, else the campaign's base value, so an ablation and a
  sweep line up on the same keys;
* **values** (``--metric``), each ``[STATISTIC.]METRIC[@A-B][:bare][:DIGITS]``
  (:func:`parse_value`): a statistic of the runs of an architecture
  (``mean.miss``, ``median.miss``, ``p95.miss``, ``mean.dv``, ``mean.fuel``
  with their bootstrap intervals, Δv the paper's 1 s trapezoid of ‖u‖ and the
  fuel penalty against the fuel optimum's trapezoid; ``mean.dv_applied``,
  ``mean.fuel_applied``: the applied impulse Σ‖u_k‖Δt and its penalty against
  the exact continuous fuel optimum, issue 33; ``solve_mean_ms``, ``solve_max_ms``,
  ``solve_success_pct`` without), a paired comparison (``frac_less.miss``
  with its Wilson interval, ``median_diff.miss``, ``mean_diff.dv``; ``@A-B``
  fixes the pair, else ``arch`` and ``other`` are fields), the runs counted
  (``n``: the ok runs; the seed pairs in a table of paired values only), or
  a value computed from the cell's ok runs: the share of re-solves certified
  infeasible or failed (``infeasible_pct``, ``failed_pct``), their number
  (``infeasible_solves``, ``failed_solves``), the worst run (``max.miss``),
  each with ``:with=STEP`` / ``:without=STEP`` for the runs whose re-solves
  used / never used a fallback step (``n:with=socp_plan`` counts them);
* **filters** (``--where [CAMPAIGN:]FIELD=V1,V2``): keep the entries whose
  field has one of the values, shown in that order (only those of one
  campaign when prefixed, and its runs before a pair across campaigns);
* **pairs across campaigns** (``--versus CAMPAIGN``): paired values with A
  from another campaign and B from CAMPAIGN, paired by seed on matching grid
  points, with the intervals of a pair within a campaign (field
  ``other_campaign``: B's campaign).

Each cell must be one stored value: two matching entries (two campaigns,
grid points or pairs in one cell) are refused naming a field that tells
them apart. Units and precision per quantity as in the report: misses in m
(2 decimals), Δv in km/s (4; differences 5), fuel penalty in % (2), shares
3 decimals. A bootstrap interval from fewer than 10 seeds is marked ``*``.

``mean.nees`` and ``mean.nis`` (issue 33) are the mean over the runs of each
run's mean NEES and nominal mean NIS; their interval is the χ² 95 % band a
consistent filter's mean lies in (the ``consistency`` rows), never marked.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from cwrend_cli.config import get_dotted
from cwrend_cli.config.messages import did_you_mean
from cwrend_cli.errors import ConfigError
from cwrend_cli.output.layout import (
    ABLATION_STATS,
    MANIFEST,
    PARAM_PREFIX,
    RUNS,
    SOLVES,
    SWEEP_STATS,
)
from cwrend_cli.output.manifest import REPAIR_HINT, read_manifest
from cwrend_cli.output.tables import FALLBACK_STEPS, METRIC_NAMES
from cwrend_cli.physics.params import ALL_ARCHITECTURES, arch_order
from cwrend_cli.report.labels import (
    M_PER_KM,
    MIN_BOOTSTRAP_N,
    format_value,
    markdown_table,
    number,
)

__all__ = [
    "FIELDS",
    "FORMATS",
    "Source",
    "Value",
    "build_table",
    "load_source",
    "parse_value",
    "render",
]

Format = Literal["md", "latex", "csv"]
FORMATS: tuple[Format, ...] = ("md", "latex", "csv")
#: Fields that are not configuration keys.
FIELDS = ("campaign", "arch", "other", "other_campaign", "point", "metric")
UNRELIABLE_NOTE = f"* fewer than {MIN_BOOTSTRAP_N} seeds: bootstrap interval unreliable"
_MISSING = "–"


@dataclass(frozen=True)
class _Quantity:
    """How a stored metric is shown: name, unit, factor to that unit, decimals."""

    name: str
    unit: str
    scale: float
    digits: int


#: The metrics of the statistics files, as shown (the report's units and precision).
QUANTITIES: Mapping[str, _Quantity] = {
    "miss_km": _Quantity("miss", "m", M_PER_KM, 2),
    "delta_v_km_s": _Quantity("Δv", "km/s", 1.0, 4),
    "fuel_penalty_pct": _Quantity("fuel penalty", "%", 1.0, 2),
    "delta_v_applied_km_s": _Quantity("applied Δv", "km/s", 1.0, 4),
    "fuel_penalty_applied_pct": _Quantity("applied fuel penalty", "%", 1.0, 2),
    "solve_mean_ms": _Quantity("re-solve time", "ms", 1.0, 2),
    "solve_max_ms": _Quantity("re-solve time", "ms", 1.0, 1),
    "solve_success_pct": _Quantity("re-solve success", "%", 1.0, 2),
    "n_infeasible": _Quantity("infeasible re-solves per run", "-", 1.0, 2),
    "mean_nees": _Quantity("of the runs' mean NEES", "-", 1.0, 2),
    "mean_nis_nominal": _Quantity("of the runs' nominal mean NIS", "-", 1.0, 2),
    # safety of the true trajectory (issues 32 and 34), as the runs' columns hold it
    "safety_violated": _Quantity("runs that entered the unsafe set", "%", 100.0, 1),
    "safety_min_distance_km": _Quantity("closest approach to the unsafe set", "m", M_PER_KM, 1),
    "safety_unsafe_time_s": _Quantity("time in the unsafe set", "s", 1.0, 2),
    "safety_dock_position_error_km": _Quantity("docking position error", "m", M_PER_KM, 2),
    "safety_dock_velocity_error_km_s": _Quantity("docking velocity error", "mm/s", 1e6, 1),
    "abort_unsafe": _Quantity("runs with an unsafe abort drift", "%", 100.0, 1),
    "abort_min_distance_km": _Quantity("closest abort drift to the keep-out", "m", M_PER_KM, 1),
    # of the re-solves (solves/)
    "scp_iterations": _Quantity("SCP iterations per re-solve", "-", 1.0, 2),
    "wall_time_ms": _Quantity("re-solve time", "ms", 1.0, 0),
}
#: The statistics of each stored metric (the first is the default).
MARGINAL: Mapping[str, tuple[str, ...]] = {
    "miss_km": ("mean", "median", "p95"),
    "delta_v_km_s": ("mean", "median", "p95"),
    "fuel_penalty_pct": ("mean", "median", "p95"),
    "delta_v_applied_km_s": ("mean", "median", "p95"),
    "fuel_penalty_applied_pct": ("mean", "median", "p95"),
    "solve_mean_ms": ("mean",),
    "solve_max_ms": ("max",),
    "solve_success_pct": ("mean",),
    "n_infeasible": ("mean",),
    "mean_nees": ("mean",),
    "mean_nis_nominal": ("mean",),
    "safety_violated": ("share",),
    "safety_min_distance_km": ("median", "p1"),
    "safety_unsafe_time_s": ("mean",),
    "abort_unsafe": ("share",),
    "abort_min_distance_km": ("median", "p1"),
}
#: Stored shares of runs (Wilson 95 %), asked for by name: name → flag column. Shown in %.
SHARES: Mapping[str, str] = {"violated_pct": "safety_violated", "abort_pct": "abort_unsafe"}
#: Filter consistency (issue 33): stored as ``consistency`` rows whose interval is the χ²
#: 95 % band of a consistent filter's mean over the runs, not a confidence interval.
CONSISTENCY = ("mean_nees", "mean_nis_nominal")
#: The paired statistics of each metric (the first is the default).
PAIRED: Mapping[str, tuple[str, ...]] = {
    "miss_km": ("median_diff", "frac_less"),
    "delta_v_km_s": ("mean_diff",),
    # pairs across campaigns only (--versus: campaign.compare.paired_across)
    "delta_v_applied_km_s": ("mean_diff",),
}
#: The Δv metrics: a paired difference of theirs is shown with 5 decimals [km/s].
_DV = ("delta_v_km_s", "delta_v_applied_km_s")
#: Values computed from ``runs.parquet`` over the cell's ok runs: name → (column,
#: statistic, header). ``share``: 100 × Σ(column) / Σ(n_solves) [%]; ``sum``: Σ(column).
RUN_VALUES: Mapping[str, tuple[str, Literal["share", "sum"], str]] = {
    "infeasible_pct": ("n_infeasible", "share", "re-solves infeasible [%]"),
    "failed_pct": ("n_failed", "share", "re-solves failed [%]"),
    "infeasible_solves": ("n_infeasible", "sum", "re-solves infeasible"),
    "failed_solves": ("n_failed", "sum", "re-solves failed"),
}
#: The order statistics over the cell's ok runs ``STATISTIC.METRIC`` gives (runs.parquet; NaN
#: cells skipped): metric → its statistics computed from the runs (none stored).
RUN_ORDER: Mapping[str, tuple[str, ...]] = {
    "miss_km": ("max",),
    "delta_v_km_s": ("max",),
    "fuel_penalty_pct": ("max",),
    "safety_min_distance_km": ("min",),  # the worst run: < 0 entered the unsafe set
    "safety_dock_position_error_km": ("median", "max"),
    "safety_dock_velocity_error_km_s": ("median", "max"),
}
#: Values over the re-solves (``solves/`` rows of kind ``resolve``) of the cell's ok runs:
#: name → (column, its statistics). ``p95``: numpy's linear percentile, as the statistics'.
SOLVE_VALUES: Mapping[str, tuple[str, tuple[str, ...]]] = {
    "scp_iterations": ("scp_iterations", ("mean", "max")),
    "resolve_ms": ("wall_time_ms", ("mean", "p95", "max")),
}
#: Shares of those re-solves [%] that needed a softening (column > 0): name → (column, header).
SOLVE_SHARES: Mapping[str, tuple[str, str]] = {
    "slack_pct": ("slack_km", "re-solves with a path slack [%]"),
    "abort_slack_pct": ("abort_slack_km", "re-solves with an abort slack [%]"),
}
_ORDER_FN: Mapping[str, Callable[[pd.Series], float]] = {
    "max": lambda x: float(x.max()),
    "min": lambda x: float(x.min()),
    "median": lambda x: float(x.median()),
    "mean": lambda x: float(x.mean()),
    "p95": lambda x: float(np.percentile(x, 95)) if len(x) else math.nan,
}
_VALUE_SYNTAX = re.compile(
    r"^(?:(?P<stat>[a-z_0-9]+)\.)?(?P<metric>[a-z_]+)(?:@(?P<a>[a-z_]+)-(?P<b>[a-z_]+))?"
    r"(?P<mods>(?::[a-z0-9_=]+)*)$"
)
_SYNTAX_HELP = (
    "[STATISTIC.]METRIC[@A-B][:bare][:DIGITS][:with=STEP|:without=STEP], e.g. mean.miss, "
    "p95.miss:bare, frac_less.miss@mtf_adaptive-plain_adaptive, mean_diff.dv, n, "
    "infeasible_pct, failed_solves, max.miss:with=socp_plan"
)
_SHORT_NAME = {column: name for name, column in METRIC_NAMES.items()}
#: The values computed from the runs and the re-solves, named from :data:`RUN_ORDER`,
#: :data:`RUN_VALUES`, :data:`SOLVE_VALUES` and :data:`SOLVE_SHARES` (one list, no copy).
_RUN_HELP = (
    ", ".join(
        ["n"]
        + [f"{'|'.join(stats)}.{_SHORT_NAME[column]}" for column, stats in RUN_ORDER.items()]
        + list(RUN_VALUES)
    )
    + " (computed from the runs); "
    + ", ".join(
        [f"{'|'.join(stats)}.{name}" for name, (_, stats) in SOLVE_VALUES.items()]
        + list(SOLVE_SHARES)
    )
    + " (from the re-solves)"
)


@dataclass(frozen=True)
class Value:
    """One value asked for by ``--metric`` (:func:`parse_value`)."""

    text: str  # as given
    #: stored (marginal, paired, count: n) or computed from the cell's runs (runs) or their
    #: re-solves (solves)
    kind: Literal["marginal", "paired", "count", "runs", "solves"]
    #: column of the statistics; of a runs value: n, a name of RUN_VALUES or of RUN_ORDER;
    #: of a solves value: a column of solves/
    metric: str
    #: of a runs value: count, share, sum or one of RUN_ORDER; of a solves value: share or
    #: one of SOLVE_VALUES
    statistic: str
    pair: tuple[str, str] | None = None
    interval: bool = True  # show the stored interval
    digits: int | None = None  # decimals (None: the quantity's)
    #: of a runs value: only the runs whose re-solves used (with) or never used (without)
    #: a fallback step (solves/ ``fallback_step``)
    subset: tuple[Literal["with", "without"], str] | None = None

    @property
    def header(self) -> str:
        """The column header: quantity, unit, and the interval's kind."""
        if self.kind == "count":
            return "n"
        if self.kind in ("runs", "solves"):
            return self._runs_header()
        q = QUANTITIES[self.metric]
        if self.statistic == "share":
            return f"{q.name} [{q.unit}]" + (" (95 % Wilson)" if self.interval else "")
        ci = " (95 % CI)" if self.interval else ""
        if self.metric in CONSISTENCY:
            ci = " (95 % χ² band)" if self.interval else ""
        if self.statistic == "frac_less":
            a, b = self.pair or ("A", "B")
            ci = " (95 % Wilson)" if self.interval else ""
            return f"P({a} misses less than {b}){ci}"
        if self.kind == "paired":
            what = self.statistic.removesuffix("_diff")
            return f"{what} {q.name} difference [{q.unit}]{ci}"
        return f"{self.statistic} {q.name} [{q.unit}]{ci}"

    def _runs_header(self) -> str:
        if self.kind == "solves" and self.statistic == "share":
            head = next(h for c, h in SOLVE_SHARES.values() if c == self.metric)
        elif self.statistic in _ORDER_FN:
            q = QUANTITIES[self.metric]
            head = f"{self.statistic} {q.name} [{q.unit}]"
        elif self.statistic == "count":
            head = "runs"
        else:
            head = RUN_VALUES[self.metric][2]
        if self.subset is None:
            return head
        which, step = self.subset
        using = f"runs using {step}" if which == "with" else f"runs not using {step}"
        return using if self.statistic == "count" else f"{head}, {using}"

    @property
    def integer(self) -> bool:
        """Whether the value counts (runs, seed pairs, re-solves)."""
        return self.kind == "count" or (self.kind == "runs" and self.statistic in ("count", "sum"))

    def decimals(self) -> int:
        if self.digits is not None:
            return self.digits
        if self.integer:
            return 0
        if self.kind == "solves" and self.statistic == "max" and self.metric == "scp_iterations":
            return 0  # a count
        if self.kind in ("runs", "solves") and self.statistic == "share":
            return 1 if self.kind == "solves" else 2
        if self.statistic == "frac_less":
            return 3
        if self.statistic == "mean_diff" and self.metric in _DV:
            return 5
        return QUANTITIES[self.metric].digits

    def scale(self) -> float:
        if self.kind in ("runs", "solves") and self.statistic in _ORDER_FN:
            return QUANTITIES[self.metric].scale
        if self.kind in ("count", "runs", "solves") or self.statistic == "frac_less":
            return 1.0
        return QUANTITIES[self.metric].scale


def parse_value(text: str) -> Value:
    """One ``--metric`` entry; :class:`ConfigError` naming it and the syntax when wrong."""
    m = _VALUE_SYNTAX.match(text.strip())
    if m is None:
        raise ConfigError(f"--metric {text!r}: expected {_SYNTAX_HELP}")
    interval, digits = True, None
    subset: tuple[Literal["with", "without"], str] | None = None
    for mod in filter(None, m["mods"].split(":")):
        which, eq, step = mod.partition("=")
        if mod == "bare":
            interval = False
        elif mod.isdigit() and int(mod) <= 12:
            digits = int(mod)
        elif eq and which in ("with", "without") and re.fullmatch(r"[a-z_0-9]+", step):
            subset = ("with" if which == "with" else "without", step)
        else:
            raise ConfigError(
                f"--metric {text!r}: unknown modifier {mod!r} (':bare' drops the interval, "
                "':3' shows 3 decimals, ':with=socp_plan' / ':without=socp_plan' keep the runs "
                "whose re-solves used / never used that fallback step)"
            )
    stat, name = m["stat"], m["metric"]
    metric = METRIC_NAMES.get(name, name)
    pair = (m["a"], m["b"]) if m["a"] else None
    if pair is not None:
        for slug in pair:
            if slug not in ALL_ARCHITECTURES:
                raise ConfigError(
                    f"--metric {text!r}: unknown architecture {slug!r} "
                    f"(choices: {', '.join(ALL_ARCHITECTURES)})"
                )
    runs_value = (stat is None and name in ("n", *RUN_VALUES)) or (
        stat in RUN_ORDER.get(metric, ())
    )
    solves_value = (stat is None and name in SOLVE_SHARES) or (
        name in SOLVE_VALUES and stat in SOLVE_VALUES[name][1]
    )
    if (runs_value or solves_value or name in SHARES) and pair is not None:
        raise ConfigError(f"--metric {text!r}: {name} is per architecture, not per pair")
    if stat is None and name == "n" and subset is None:
        return Value(text, "count", name, name, None, False, digits)
    if runs_value:
        statistic = "count" if name == "n" else stat if stat is not None else RUN_VALUES[name][1]
        column = name if stat is None else metric
        return Value(text, "runs", column, statistic, None, False, digits, subset)
    if solves_value:
        if stat is None:
            return Value(
                text, "solves", SOLVE_SHARES[name][0], "share", None, False, digits, subset
            )
        return Value(text, "solves", SOLVE_VALUES[name][0], stat, None, False, digits, subset)
    if name in SOLVE_VALUES:
        raise ConfigError(
            f"--metric {text!r}: statistic {stat!r} of {name} is one of "
            f"{', '.join(SOLVE_VALUES[name][1])} (over the re-solves)"
        )
    if subset is not None:
        raise ConfigError(
            f"--metric {text!r}: ':{subset[0]}=' keeps runs of a value computed from the runs "
            f"({_RUN_HELP}), not of a stored statistic"
        )
    if stat is None and name in SHARES:
        return Value(text, "marginal", SHARES[name], "share", None, interval, digits)
    paired_stats = PAIRED.get(metric, ())
    if metric not in MARGINAL and metric not in RUN_ORDER:
        shown = [k for k, v in METRIC_NAMES.items() if v in MARGINAL or v in RUN_ORDER]
        names = [*shown, *(m for m in MARGINAL if m not in METRIC_NAMES.values())]
        names = [n for n in names if n not in SHARES.values()]
        known = ", ".join([*names, *SHARES, *SOLVE_VALUES])
        every = [*names, *SHARES, *SOLVE_VALUES, *SOLVE_SHARES, *RUN_VALUES, "n"]
        raise ConfigError(
            f"--metric {text!r}: unknown metric {name!r} (metrics: {known}; also {_RUN_HELP})"
            f"{did_you_mean(name, every)}"
        )
    if stat in paired_stats or (stat is None and pair is not None):
        if not paired_stats:
            raise ConfigError(f"--metric {text!r}: {metric} has no paired comparison")
        return Value(text, "paired", metric, stat or paired_stats[0], pair, interval, digits)
    if pair is not None:
        raise ConfigError(
            f"--metric {text!r}: the paired statistics of {metric} are "
            f"{', '.join(paired_stats) or 'none'}"
        )
    stored = MARGINAL.get(metric, ())
    stat = stat or (stored or RUN_ORDER[metric])[0]
    if stat in RUN_ORDER.get(metric, ()):  # the default statistic of a metric stored nowhere
        return Value(text, "runs", metric, stat, None, False, digits)
    if stat not in stored:
        allowed = ", ".join([*stored, *RUN_ORDER.get(metric, ()), *paired_stats])
        raise ConfigError(f"--metric {text!r}: statistic {stat!r} of {metric} is one of {allowed}")
    return Value(text, "marginal", metric, stat, None, interval, digits)


# ---------------------------------------------------------------------------
# Campaigns
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Source:
    """A campaign directory as a table reads it."""

    label: str
    path: Path
    manifest: Mapping[str, Any]
    stats: pd.DataFrame  # its ablation.parquet or sweep.parquet
    runs: pd.DataFrame | None = field(default=None, compare=False)  # read when a value needs it
    #: the distinct (run_key, fallback_step) of its solves/, read for ``:with=`` / ``:without=``
    steps: pd.DataFrame | None = field(default=None, compare=False)
    #: its solves/ re-solves (kind ``resolve``): run_key and the columns of the solves values
    solves: pd.DataFrame | None = field(default=None, compare=False)
    #: of the pairs across two campaigns (``--versus``): B's campaign (``stats``: the pairs)
    versus: Source | None = field(default=None, compare=False)

    @property
    def swept(self) -> tuple[str, ...]:
        """The configuration keys the campaign sweeps, in its grid's order."""
        grid = self.manifest.get("grid")
        keys = list(grid) if isinstance(grid, dict) else []
        cols = [
            c.removeprefix(PARAM_PREFIX) for c in self.stats.columns if c.startswith(PARAM_PREFIX)
        ]
        return tuple(dict.fromkeys([*keys, *cols]))

    def base_value(self, key: str) -> tuple[bool, Any]:
        """(found, value) of ``key`` in the campaign's base configuration.

        Of the pairs across two campaigns: the value both have, else ``"a vs b"``.
        """
        if self.versus is not None:
            (found_a, a), (found_b, b) = self._base(key), self.versus.base_value(key)
            if found_a and found_b and a != b:
                return True, f"{format_value(a)} vs {format_value(b)}"
            return (found_a, a) if found_a else (found_b, b)
        return self._base(key)

    def _base(self, key: str) -> tuple[bool, Any]:
        config = self.manifest.get("config")
        if not isinstance(config, Mapping):
            return False, None
        try:
            return True, get_dotted(config, key)
        except (KeyError, IndexError, TypeError, ValueError, ConfigError):
            return False, None


def load_source(text: str) -> Source:
    """``DIR`` or ``LABEL=DIR``: a campaign's manifest and statistics; exit 2 if it has none."""
    label, path = None, Path(text)
    if "=" in text and not path.exists():
        label, _, rest = text.partition("=")
        path = Path(rest)
    manifest_path = path / MANIFEST
    stats_path = next(
        (path / n for n in (SWEEP_STATS, ABLATION_STATS) if (path / n).is_file()), None
    )
    if not manifest_path.is_file() or stats_path is None:
        raise ConfigError(
            f"{path}: not a campaign directory with statistics (no {MANIFEST} and "
            f"{ABLATION_STATS} or {SWEEP_STATS}); give the directory of a cwrend ablate or "
            "cwrend sweep that ran to its end"
        )
    manifest = read_manifest(manifest_path, REPAIR_HINT)  # a damaged one: exit 2, its fix
    try:
        stats = pd.read_parquet(stats_path)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: unreadable campaign ({exc})") from None
    for name in ("arch", "other", "point", "kind", "metric", "statistic"):
        if name in stats.columns:
            stats[name] = stats[name].astype(object).where(stats[name].notna(), None)
    return Source(label or path.resolve().name, path, manifest, stats)


def _loaded(source: Source, runs: bool, steps: bool, resolves: bool = False) -> Source:
    """``source`` with its ``runs.parquet`` (``runs``), its solves' steps (``steps``) and
    its re-solves (``resolves``: run_key and the columns of the solves values it holds)."""
    if runs and source.runs is None:
        try:
            source = replace(source, runs=pd.read_parquet(source.path / RUNS))
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{source.path}: cannot read {RUNS} ({exc})") from None
    if steps and source.steps is None:
        try:
            solves = pd.read_parquet(source.path / SOLVES, columns=["run_key", "fallback_step"])
        except (OSError, ValueError) as exc:
            raise ConfigError(
                f"{source.path}: cannot read the per-solve data {SOLVES}/ ({exc}), which "
                "':with=' / ':without=' need"
            ) from None
        source = replace(source, steps=solves.drop_duplicates(ignore_index=True))
    if resolves and source.solves is None:
        source = replace(source, solves=_resolves(source.path))
    return source


def _resolves(path: Path) -> pd.DataFrame:
    """The re-solves of ``path/solves/``: run_key and each column of the solves values held."""
    import pyarrow.dataset as pads

    wanted = {c for c, _ in SOLVE_VALUES.values()} | {c for c, _ in SOLVE_SHARES.values()}
    try:
        held = set(pads.dataset(path / SOLVES, format="parquet", partitioning="hive").schema.names)
        columns = ["run_key", "kind", *sorted(wanted & held)]
        frame = pd.read_parquet(path / SOLVES, columns=columns)
    except (OSError, ValueError) as exc:
        raise ConfigError(
            f"{path}: cannot read the per-solve data {SOLVES}/ ({exc}), which the values of "
            "the re-solves need"
        ) from None
    return frame[frame["kind"] == "resolve"].drop(columns="kind").reset_index(drop=True)


# ---------------------------------------------------------------------------
# Fields
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class _Field:
    name: str  # campaign, arch, other, point, metric, or a configuration key
    header: str

    @property
    def is_key(self) -> bool:
        return self.name not in FIELDS


_HEADERS = {"campaign": "campaign", "arch": "architecture", "other": "vs",
            "other_campaign": "vs campaign", "point": "point", "metric": "value"}  # fmt: skip


def _field(text: str, sources: Sequence[Source], option: str) -> _Field:
    """``FIELD`` or ``FIELD=HEADER`` of ``--rows`` / ``--cols`` / ``--where``."""
    name, _, header = text.partition("=")
    name = name.strip().removeprefix(PARAM_PREFIX)
    if name in FIELDS:
        return _Field(name, header or _HEADERS[name])
    if any(name in s.swept or s.base_value(name)[0] for s in sources):
        return _Field(name, header or name.rsplit(".", 1)[-1])
    swept = sorted({k for s in sources for k in s.swept})
    last = name.rsplit(".", 1)[-1]
    keys = [*swept, *_config_keys(sources)]
    near = [k for k in keys if k.rsplit(".", 1)[-1] == last]
    hint = f"; did you mean {near[0]!r}?" if near else did_you_mean(name, [*FIELDS, *keys])
    raise ConfigError(
        f"{option} {name!r}: unknown field (fields: {', '.join(FIELDS)}, or a configuration "
        f"key{': swept here ' + ', '.join(swept) if swept else ''}){hint}"
    )


def _config_keys(sources: Sequence[Source]) -> list[str]:
    """The dotted keys of the campaigns' base configurations (for a did-you-mean)."""
    keys: list[str] = []

    def walk(tree: Mapping[str, Any], prefix: str) -> None:
        for k, v in tree.items():
            if isinstance(v, Mapping):
                walk(v, f"{prefix}{k}.")
            else:
                keys.append(f"{prefix}{k}")

    for s in sources:
        config = s.manifest.get("config")
        if isinstance(config, Mapping):
            walk(config, "")
    return list(dict.fromkeys(keys))


def _fields(text: str | None, sources: Sequence[Source], option: str) -> list[_Field]:
    fields = [_field(t, sources, option) for t in (text or "").split(",") if t.strip()]
    names = [f.name for f in fields]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise ConfigError(f"{option}: field {dup!r} named twice")
    return fields


@dataclass(frozen=True)
class _Filter:
    campaign: str | None
    field: _Field
    values: tuple[str, ...]


def _filter(text: str, sources: Sequence[Source]) -> _Filter:
    """``--where [CAMPAIGN:]FIELD=V1,V2``."""
    lhs, eq, rhs = text.partition("=")
    campaign, colon, key = lhs.rpartition(":")
    if not eq or not key.strip() or not rhs.strip():
        raise ConfigError(f"--where {text!r}: expected [CAMPAIGN:]FIELD=VALUE[,VALUE…]")
    if colon and campaign not in {s.label for s in sources}:
        labels = ", ".join(s.label for s in sources)
        raise ConfigError(f"--where {text!r}: no campaign {campaign!r} (campaigns: {labels})")
    f = _field(key, sources, "--where")
    values = tuple(v.strip() for v in rhs.split(",") if v.strip())
    return _Filter(campaign if colon else None, f, values)


def _matches(value: Any, wanted: str) -> bool:
    """A field's value against a ``--where`` value as written (numbers to a relative 1e-9)."""
    if value is None:
        return wanted in ("none", "None", _MISSING)
    if isinstance(value, bool | np.bool_):
        return wanted.lower() == str(bool(value)).lower()
    if isinstance(value, int | float | np.integer | np.floating):
        try:
            return math.isclose(float(value), float(wanted), rel_tol=1e-9, abs_tol=0.0)
        except ValueError:
            return False
    return format_value(value) == wanted or json.dumps(value) == wanted


# ---------------------------------------------------------------------------
# Entries: one stored value each, with every field's value
# ---------------------------------------------------------------------------


def _cell_value(value: Any) -> Any:
    """A ``param.<key>`` cell as its value (JSON text for mixed kinds; NaN: none)."""
    if isinstance(value, float) and math.isnan(value):
        return None
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, str):
        try:
            parsed = json.loads(value)
        except ValueError:
            return value
        return parsed if isinstance(parsed, list | dict) else value
    return value


def _entries(
    source: Source, value: Value, index: int, keys: Sequence[str], pairs: Value | None = None
) -> pd.DataFrame:
    """The stored values of ``value`` in ``source``: value, ci_low, ci_high, n, the fields.

    ``pairs``: the paired value whose seed pairs ``n`` counts (a table of paired values
    only), else ``n`` counts the ok runs.
    """
    stats = source.stats
    if value.kind == "count" and pairs is not None:
        sel = _entries(source, pairs, index, keys)
        sel["value"] = sel["n"]
        sel["ci_low"] = sel["ci_high"] = math.nan
        return sel
    if value.kind in ("marginal", "count"):
        metric, statistic = (
            ("miss_km", "mean") if value.kind == "count" else (value.metric, value.statistic)
        )
        stored = "consistency" if metric in CONSISTENCY else "marginal"
        sel = stats[
            (stats["kind"] == stored)
            & (stats["metric"] == metric)
            & (stats["statistic"] == statistic)
        ].copy()
        if value.kind == "count":
            sel["value"] = sel["n"].astype(float)
            sel["ci_low"] = sel["ci_high"] = math.nan
        sel["other"] = None
    elif value.kind == "paired":
        sel = stats[
            (stats["kind"] == "paired")
            & (stats["metric"] == value.metric)
            & (stats["statistic"] == value.statistic)
        ].copy()
        if value.pair is not None:
            sel = sel[(sel["arch"] == value.pair[0]) & (sel["other"] == value.pair[1])]
    else:
        sel = _from_runs(source, value)
    if "point" not in sel.columns:
        sel["point"] = "base"
    versus = source.versus.label if source.versus is not None else source.label
    out = pd.DataFrame(
        {
            "value": sel["value"].astype(float).to_numpy(),
            "ci_low": sel["ci_low"].astype(float).to_numpy() if value.interval else math.nan,
            "ci_high": sel["ci_high"].astype(float).to_numpy() if value.interval else math.nan,
            "n": sel["n"].astype(float).to_numpy(),
            "campaign": source.label,
            "arch": sel["arch"].to_numpy(),
            "other": sel["other"].to_numpy() if "other" in sel.columns else None,
            "other_campaign": versus if value.kind == "paired" else None,
            "point": sel["point"].astype(str).to_numpy(),
            "metric": index,
        }
    )
    for key in keys:
        column = PARAM_PREFIX + key
        if column in sel.columns:
            out[key] = [_cell_value(v) for v in sel[column]]
        else:
            found, base = source.base_value(key)
            out[key] = [base if found else None] * len(out)
    return out


def _from_runs(source: Source, value: Value) -> pd.DataFrame:
    """A value computed from ``runs.parquet`` (or its re-solves) per grid point and architecture.

    Over the cell's ok runs (with ``value.subset``: those whose re-solves used, or
    never used, the fallback step): their number (``count``), Σ(column) (``sum``),
    100 × Σ(column) / Σ(n_solves) (``share``) or an order statistic of the metric
    (:data:`RUN_ORDER`; NaN cells skipped, none when no run is kept). A value of the
    re-solves (``kind`` solves): a statistic of :data:`SOLVE_VALUES` of the column over
    every re-solve of the kept runs, or the share [%] of them with the column > 0
    (:data:`SOLVE_SHARES`). ``n``: the runs kept.
    """
    runs = source.runs
    assert runs is not None
    column = (
        RUN_VALUES[value.metric][0]
        if value.kind == "runs" and value.statistic in ("share", "sum")
        else value.metric
    )
    params = [c for c in runs.columns if c.startswith(PARAM_PREFIX)]
    frame = source.solves if value.kind == "solves" else runs
    if value.statistic != "count" and (frame is None or column not in frame.columns):
        # a campaign without the column (another one holds it: _check_held): no value, –
        return pd.DataFrame(columns=["point", "arch", "value", "ci_low", "ci_high", "n", *params])
    ok = runs[runs["status"] == "ok"]
    kept = pd.Series(True, index=ok.index)
    if value.subset is not None:
        which, step = value.subset
        assert source.steps is not None
        steps = source.steps
        using = ok["run_key"].isin(set(steps.loc[steps["fallback_step"] == step, "run_key"]))
        kept = using if which == "with" else ~using
    resolves = source.solves if value.kind == "solves" else None
    rows = []
    for (point, arch), g in ok.groupby(["point", "arch"], sort=False, observed=True):
        sub = g[kept[g.index]]
        if resolves is not None:
            mine = resolves["run_key"].isin(set(sub["run_key"]))
            x = resolves.loc[mine, column].to_numpy(dtype=float)
            if value.statistic == "share":
                number = 100.0 * float(np.mean(x > 0.0)) if len(x) else math.nan
            else:
                number = _ORDER_FN[value.statistic](pd.Series(x)) if len(x) else math.nan
        elif value.statistic == "count":
            number = float(len(sub))
        elif value.statistic == "sum":
            number = float(sub[column].sum())
        elif value.statistic == "share":
            solves = float(sub["n_solves"].sum())
            number = 100.0 * float(sub[column].sum()) / solves if solves else math.nan
        else:
            number = _ORDER_FN[value.statistic](sub[column].astype(float)) if len(sub) else math.nan
        first = g.iloc[0]
        rows.append({"point": str(point), "arch": str(arch), "value": number,
                     "ci_low": math.nan, "ci_high": math.nan, "n": float(len(sub)),
                     **{p: first[p] for p in params}})  # fmt: skip
    return pd.DataFrame(rows, columns=["point", "arch", "value", "ci_low", "ci_high", "n", *params])


def _needs(value: Value) -> tuple[str, str] | None:
    """(where, column) a value reads that not every campaign writes: a stored statistic's
    metric (``stats``), a column of ``runs.parquet`` (``runs``) or of solves/ (``solves``)."""
    if value.kind == "marginal":
        return "stats", value.metric
    if value.kind == "solves":
        return "solves", value.metric
    if value.kind != "runs" or value.statistic == "count":
        return None
    if value.statistic in ("share", "sum"):
        return "runs", RUN_VALUES[value.metric][0]
    return "runs", value.metric


def _check_held(sources: Sequence[Source], values: Sequence[Value]) -> None:
    """Each value's metric or column is held by at least one campaign (a campaign without it
    shows –); else :class:`ConfigError` naming the value and what writes it."""
    for v in values:
        need = _needs(v)
        if need is None:
            continue
        where, column = need

        def held(s: Source, where: str = where, column: str = column) -> bool:
            if where == "stats":
                return bool((s.stats["metric"] == column).any())
            frame = s.runs if where == "runs" else s.solves
            return frame is not None and column in frame.columns

        if not any(held(s) for s in sources):
            names = ", ".join(s.label for s in sources)
            if column.startswith(("safety_", "abort_")) or column in ("scp_iterations", "slack_km"):
                why = (
                    "a campaign with [constraints] writes it (abort_*: with "
                    "constraints.abort_safe_s; dock_*: a tumbling target, "
                    'target.attitude = "tumbling", with a corridor)'
                )
            else:
                why = "written by a newer cwrend; re-run the campaign"
            file = {"stats": "statistics", "runs": RUNS, "solves": f"{SOLVES}/"}[where]
            raise ConfigError(
                f"--metric {v.text!r}: {names} hold(s) no {column} in its {file}: {why}"
            )


def _check_steps(sources: Sequence[Source], values: Sequence[Value]) -> None:
    """Each ``:with=`` / ``:without=`` step is a fallback step (else a typo): one of
    :data:`~cwrend_cli.output.tables.FALLBACK_STEPS` or that ended a re-solve here."""
    held = {str(x) for s in sources if s.steps is not None for x in s.steps["fallback_step"]}
    known = [*FALLBACK_STEPS, *sorted(held - set(FALLBACK_STEPS))]
    for v in values:
        if v.subset is not None and v.subset[1] not in known:
            raise ConfigError(
                f"--metric {v.text!r}: unknown fallback step {v.subset[1]!r} (steps: "
                f"{', '.join(known)}){did_you_mean(v.subset[1], known)}"
            )


# ---------------------------------------------------------------------------
# Pairs across campaigns (--versus)
# ---------------------------------------------------------------------------

#: The pairs of two campaigns' runs: ``(A, B, extra, keep)`` → for each pair (X of A, Y of
#: B) of the default ones (each architecture against itself and the pairs a campaign
#: compares) and ``extra`` that ``keep`` keeps, the rows of a paired comparison
#: (``kind`` … ``ci_high``, ``n``) with ``point_a``, ``point_b`` and ``param.<key>``:
#: :func:`cwrend_cli.campaign.compare.paired_across`, given by the CLI (the report reads
#: stored results and imports no campaign code).
PairAcross = Callable[
    [Source, Source, Sequence[tuple[str, str]], Callable[[tuple[str, str]], bool]],
    pd.DataFrame,
]


def _across(
    sources: Sequence[Source],
    versus: Sequence[str],
    values: Sequence[Value],
    filters: Sequence[_Filter],
    pair_across: PairAcross | None,
) -> list[Source]:
    """The pairs across campaigns, as campaigns: A from each campaign, B from each of
    ``versus``, one :class:`Source` per (A, B) holding their paired rows.

    Each side's runs are first kept by the ``--where CAMPAIGN:KEY=…`` filters of its
    campaign; the pairs by the ``--where arch=…`` and ``other=…`` filters. The two
    sides must hold the same seeds.
    """
    labels = [s.label for s in sources]
    out: list[Source] = []
    extra = [v.pair for v in values if v.pair is not None]
    keep = _pair_filter(filters)
    for name in dict.fromkeys(versus):
        if name not in labels:
            raise ConfigError(
                f"--versus {name!r}: no campaign {name!r} (campaigns: {', '.join(labels)}); "
                "name one by its label: its directory's name, or LABEL of a LABEL=DIR argument"
                f"{did_you_mean(name, labels)}"
            )
        if len(sources) < 2:
            raise ConfigError(
                f"--versus {name}: the pairs take A from another campaign: give its directory "
                f"too (cwrend table DIR_A DIR_B --versus {name})"
            )
        assert pair_across is not None, "build_table: --versus needs pair_across"
        b = _side(sources[labels.index(name)], filters)
        for a in sources:
            if a.label == name:
                continue
            a = _side(a, filters)
            _same_seeds(a, b)
            try:
                rows = pair_across(a, b, extra, keep)
            except ConfigError as exc:
                raise ConfigError(f"--versus {name}: {exc}") from None
            if not rows.empty:
                out.append(_crossed(a, b, rows))
    return out


def _side(source: Source, filters: Sequence[_Filter]) -> Source:
    """``source`` with the runs its ``--where CAMPAIGN:KEY=…`` filters keep."""
    runs = source.runs
    assert runs is not None
    for f in filters:
        if f.campaign != source.label or not f.field.is_key:
            continue
        column = PARAM_PREFIX + f.field.name
        if column in runs.columns:
            kept = runs[column].map(
                lambda v, f=f: any(_matches(_cell_value(v), w) for w in f.values)
            )
            runs = runs[kept.astype(bool)]
        else:
            found, base = source.base_value(f.field.name)
            if not (found and any(_matches(base, w) for w in f.values)):
                runs = runs.iloc[:0]
    return replace(source, runs=runs)


def _same_seeds(a: Source, b: Source) -> None:
    seeds_a, seeds_b = (_seed_set(s) for s in (a, b))
    if seeds_a and seeds_b and seeds_a != seeds_b:
        raise ConfigError(
            f"--versus {b.label}: {a.label} ran {_seeds(seeds_a)} and {b.label} "
            f"{_seeds(seeds_b)}; pairs across campaigns need the same seeds: run both with "
            "the same --seeds, or keep the same points with --where CAMPAIGN:KEY=…"
        )


def _seed_set(source: Source) -> set[int]:
    assert source.runs is not None
    return {int(x) for x in source.runs["seed"].unique()}


def _seeds(seeds: set[int]) -> str:
    low, high = min(seeds), max(seeds)
    span = f"{low}–{high}" if len(seeds) == high - low + 1 else f"from {low} to {high}"
    return f"{len(seeds)} seed(s) {span}"


def _pair_filter(filters: Sequence[_Filter]) -> Callable[[tuple[str, str]], bool]:
    """Whether ``--where arch=…`` and ``--where other=…`` keep a pair (X, Y)."""
    chosen = [(0 if f.field.name == "arch" else 1, f.values) for f in filters
              if f.campaign is None and f.field.name in ("arch", "other")]  # fmt: skip

    def keep(pair: tuple[str, str]) -> bool:
        return all(any(_matches(pair[i], w) for w in wanted) for i, wanted in chosen)

    return keep


def _crossed(a: Source, b: Source, rows: pd.DataFrame) -> Source:
    """The pairs of A's runs with B's as a campaign: A's, its point ``"<A's> vs <B's>"``."""
    stats = rows.copy()
    stats["point"] = [
        f"{x} vs {y}" for x, y in zip(stats["point_a"], stats["point_b"], strict=True)
    ]
    for name in ("arch", "other", "point", "kind", "metric", "statistic"):
        stats[name] = stats[name].astype(object)
    return Source(a.label, a.path, a.manifest, stats.drop(columns=["point_a", "point_b"]), versus=b)


# ---------------------------------------------------------------------------
# The table
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Table:
    """A built table: header cells, rows of display cells, and the numbers behind them."""

    row_headers: tuple[str, ...]
    columns: tuple[tuple[str, Value], ...]  # (header, the value shown)
    rows: tuple[tuple[tuple[str, ...], tuple[pd.Series | None, ...]], ...]
    title: str | None = None

    @property
    def flagged(self) -> bool:
        """Whether a shown bootstrap interval is from fewer than :data:`MIN_BOOTSTRAP_N` seeds."""
        return any(
            _unreliable(cell, value)
            for _, cells in self.rows
            for cell, (_, value) in zip(cells, self.columns, strict=True)
        )


def _unreliable(cell: pd.Series | None, value: Value) -> bool:
    if cell is None or value.statistic in ("frac_less", "share") or not value.interval:
        return False
    if value.metric in CONSISTENCY:  # a χ² band, not a bootstrap interval
        return False
    return math.isfinite(float(cell["ci_low"])) and float(cell["n"]) < MIN_BOOTSTRAP_N


def _order(
    field_: _Field,
    values: Iterable[Any],
    sources: Sequence[Source],
    filters: Sequence[_Filter],
    specs: Sequence[Value],
) -> list[Any]:
    """The distinct ``values`` of a field in display order.

    A ``--where`` list's order first (one naming no campaign); then campaigns
    as given, architectures in the one order of every table (:func:`arch_order`),
    values asked for as
    asked, a configuration key's values in the order of the first grid that
    sweeps it, the rest sorted.
    """
    present = list(dict.fromkeys(_hashable(v) for v in values))
    ranked: list[Any] = []
    for f in filters:
        if f.field.name == field_.name and f.campaign is None:
            ranked += [v for w in f.values for v in present if _matches(_unhash(v), w)]
    if field_.name in ("campaign", "other_campaign"):
        ranked += [s.label for s in sources]
    elif field_.name in ("arch", "other"):
        ranked += list(arch_order(present))
    elif field_.name == "metric":
        ranked += list(range(len(specs)))
    elif field_.is_key:
        for s in sources:
            grid = s.manifest.get("grid")
            if isinstance(grid, dict) and field_.name in grid:
                ranked += [_hashable(v) for v in grid[field_.name]]
    ranked = [r for r in dict.fromkeys(ranked) if r in present]
    rest = [v for v in present if v not in ranked]
    return ranked + sorted(rest, key=_sort_key)


def _hashable(value: Any) -> Any:
    return json.dumps(value) if isinstance(value, list | dict) else value


def _unhash(value: Any) -> Any:
    if isinstance(value, str) and value[:1] in "[{":
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value


def _sort_key(value: Any) -> tuple[int, Any]:
    if value is None:
        return (2, "")
    if isinstance(value, int | float) and not isinstance(value, bool):
        return (0, float(value))
    return (1, str(value))


def _shown(field_: _Field, value: Any, specs: Sequence[Value]) -> str:
    if field_.name == "metric":
        return specs[int(value)].header
    if value is None:
        return _MISSING
    return format_value(_unhash(value))


def build_table(
    sources: Sequence[Source],
    values: Sequence[Value],
    rows: str | None = None,
    cols: str | None = None,
    where: Sequence[str] = (),
    title: str | None = None,
    versus: Sequence[str] = (),
    pair_across: PairAcross | None = None,
) -> Table:
    """The table of ``values`` over ``sources`` with ``rows`` and ``cols`` (comma-separated
    fields, ``FIELD=HEADER`` to rename a header) after the ``where`` filters.

    ``versus``: labels of campaigns whose runs are B of pairs across campaigns, A
    from each other campaign (computed by ``pair_across``, see :func:`_across`).
    :class:`ConfigError` (exit 2) for an unknown field, a filter that keeps
    nothing, or two stored values in one cell.
    """
    if not values:
        raise ConfigError("--metric: name at least one value")
    row_fields = _fields(rows, sources, "--rows")
    col_fields = _fields(cols, sources, "--cols")
    filters = [_filter(w, sources) for w in where]
    shared = {f.name for f in row_fields} & {f.name for f in col_fields}
    if shared:
        raise ConfigError(f"--rows and --cols both name {sorted(shared)[0]!r}")
    if any(f.name == "metric" for f in row_fields):
        # each column is formatted as one value (its unit, digits, interval): values run
        # across the columns, never down the rows
        raise ConfigError(
            "--rows metric: the values are the table's columns; name 'metric' in --cols "
            "(with the other column fields, e.g. --cols metric,arch) or leave it out"
        )
    steps = any(v.subset is not None for v in values)
    solves = any(v.kind == "solves" for v in values)
    runs = steps or solves or bool(versus) or any(v.kind == "runs" for v in values)
    sources = [_loaded(s, runs, steps, solves) for s in sources]
    if steps:
        _check_steps(sources, values)
    _check_held(sources, values)
    crossed = _across(sources, versus, values, filters, pair_across)
    if not row_fields:
        row_fields = _default_rows(sources, values, col_fields, bool(crossed))
    if all(f.name != "metric" for f in (*row_fields, *col_fields)):
        col_fields.append(_Field("metric", "value"))
    keys = list(
        dict.fromkeys(
            [f.name for f in (*row_fields, *col_fields) if f.is_key]
            + [f.field.name for f in filters if f.field.is_key]
            + [k for s in sources for k in s.swept]
        )
    )
    # n counts the seed pairs in a table of paired values only, else the ok runs
    compared = [v for v in values if v.kind != "count"]
    pairs = compared[0] if compared and all(v.kind == "paired" for v in compared) else None
    entries = [_entries(s, v, i, keys, pairs) for s in sources for i, v in enumerate(values)]
    entries += [
        _entries(c, v, i, keys, pairs)
        for c in crossed
        for i, v in enumerate(values)
        if v.kind == "paired" or (v.kind == "count" and pairs is not None)
    ]
    frame = pd.concat(entries, ignore_index=True)
    if frame.empty:
        raise ConfigError(
            f"no stored value of --metric {','.join(v.text for v in values)} in "
            f"{', '.join(s.label for s in sources)}: check the architectures and pairs they hold"
        )
    # a pair across campaigns: its runs were filtered by CAMPAIGN:KEY before pairing
    across = frame["other_campaign"].notna() & (frame["other_campaign"] != frame["campaign"])
    for f in filters:
        keep = frame[f.field.name].map(lambda v, f=f: any(_matches(v, w) for w in f.values))
        if f.campaign is not None:
            keep |= frame["campaign"] != f.campaign
            if f.field.is_key:
                keep |= across
        if not keep.any():
            held = frame[f.field.name].map(lambda v: _MISSING if v is None else format_value(v))
            raise ConfigError(
                f"--where {f.field.name}={','.join(f.values)} keeps nothing: the entries have "
                f"{f.field.name} = {', '.join(dict.fromkeys(held))}"
            )
        held_before = set(frame["metric"])
        frame, across = frame[keep.astype(bool)], across[keep.astype(bool)]
        lost = sorted(held_before - set(frame["metric"]))
        if lost:  # its column would be left out without a word
            hint = (
                f"a value of one architecture's runs has no {f.field.name}: ask for it in a "
                "table of its own"
                if f.field.name in ("other", "other_campaign")
                else "drop the value or widen the filter"
            )
            raise ConfigError(
                f"--where {f.field.name}={','.join(f.values)} keeps no entry of --metric "
                f"{values[lost[0]].text!r}, so its column would be empty: {hint}"
            )
    names = [f.name for f in (*row_fields, *col_fields)]
    for name in names:
        # a list, not Series.map: pandas 3 infers a string dtype from mapped strings and
        # Nones and turns each None (no pair, no value) into NaN, printed as 'nan'
        frame[name] = pd.Series(
            [_hashable(v) for v in frame[name]], index=frame.index, dtype=object
        )
    _check_one_per_cell(frame, names, keys)
    row_keys = _keys(frame, row_fields, sources, filters, values)
    col_keys = _keys(frame, col_fields, sources, filters, values)
    # each cell's position in ``frame`` (one at most: _check_one_per_cell)
    cells = {tuple(k): i for i, k in enumerate(frame[names].itertuples(index=False, name=None))}
    columns = []
    for ck in col_keys:
        spec = values[int(ck[[f.name for f in col_fields].index("metric")])]
        others = [
            _shown(f, v, values) for f, v in zip(col_fields, ck, strict=True) if f.name != "metric"
        ]
        header = " · ".join([*others, *([spec.header] if len(values) > 1 or not others else [])])
        columns.append((header, spec))
    table_rows = []
    for rk in row_keys:
        row_cells: list[pd.Series | None] = []
        for ck in col_keys:
            hit = cells.get((*rk, *ck))
            row_cells.append(None if hit is None else frame.iloc[hit])
        if any(c is not None for c in row_cells):
            shown = tuple(_shown(f, v, values) for f, v in zip(row_fields, rk, strict=True))
            table_rows.append((shown, tuple(row_cells)))
    return Table(tuple(f.header for f in row_fields), tuple(columns), tuple(table_rows), title)


def _default_rows(
    sources: Sequence[Source], values: Sequence[Value], cols: Sequence[_Field], crossed: bool
) -> list[_Field]:
    """campaign (several), the swept keys, arch, other (for a paired value), and
    other_campaign (with pairs across campaigns)."""
    taken = {f.name for f in cols}
    names = ["campaign"] if len(sources) > 1 else []
    names += list(dict.fromkeys(k for s in sources for k in s.swept))
    names += ["arch"]
    if any(v.kind == "paired" and v.pair is None for v in values):
        names += ["other"]
    if crossed:
        names += ["other_campaign"]
    return [_field(n, sources, "--rows") for n in names if n not in taken]


def _keys(
    frame: pd.DataFrame,
    fields: Sequence[_Field],
    sources: Sequence[Source],
    filters: Sequence[_Filter],
    values: Sequence[Value],
) -> list[tuple[Any, ...]]:
    """The combinations of the fields' values present in ``frame``, in display order."""
    if not fields:
        return [()]
    names = [f.name for f in fields]
    present = set(frame[names].itertuples(index=False, name=None))
    orders = [_order(f, frame[f.name], sources, filters, values) for f in fields]
    rank = [{v: i for i, v in enumerate(o)} for o in orders]
    return sorted(present, key=lambda k: tuple(r[v] for r, v in zip(rank, k, strict=True)))


def _check_one_per_cell(frame: pd.DataFrame, names: Sequence[str], keys: Sequence[str]) -> None:
    dup = frame[frame.duplicated(names, keep=False)]
    if dup.empty:
        return
    first = next(iter(dup.groupby(list(names), sort=False, dropna=False)))[1]
    candidates = ["campaign", "other_campaign", *keys, "point", "arch", "other"]
    differs = next(
        (c for c in candidates if c not in names and first[c].map(_hashable).nunique() > 1),
        "point",
    )
    seen = ", ".join(dict.fromkeys(format_value(_unhash(v)) for v in first[differs]))
    raise ConfigError(
        f"a cell holds {len(first)} stored values that differ in {differs} ({seen}): add "
        f"{differs} to --rows or --cols, or keep one with --where {differs}=…"
    )


# ---------------------------------------------------------------------------
# Rendering
# ---------------------------------------------------------------------------


def _cell(cell: pd.Series | None, value: Value, mark: str) -> str:
    """``value [low, high]`` in the value's unit and precision (``–`` when not stored)."""
    if cell is None or not math.isfinite(float(cell["value"])):
        return _MISSING
    scale, spec = value.scale(), f".{value.decimals()}f"
    text = number(float(cell["value"]) * scale, spec)
    lo, hi = float(cell["ci_low"]), float(cell["ci_high"])
    if value.interval and math.isfinite(lo) and math.isfinite(hi):
        text += f" [{number(lo * scale, spec)}, {number(hi * scale, spec)}]"
        if _unreliable(cell, value):
            text += mark
    return text


def render(table: Table, fmt: Format) -> str:
    """The table as GitHub markdown, a LaTeX ``tabular`` (booktabs) or CSV."""
    if fmt == "csv":
        return _csv(table)
    mark = "\\*" if fmt == "md" else "$^{*}$"
    header = [*table.row_headers, *(h for h, _ in table.columns)]
    body = [
        [*keys, *(_cell(c, v, mark) for c, (_, v) in zip(cells, table.columns, strict=True))]
        for keys, cells in table.rows
    ]
    note = UNRELIABLE_NOTE if table.flagged else None
    if fmt == "md":
        lines = [f"{table.title}", ""] if table.title else []
        lines.append(markdown_table(header, body))
        if note:
            lines += ["", "\\" + note]
        return "\n".join(lines)
    return _latex(table, header, body, note)


#: Characters LaTeX reads as commands, and the Unicode of cwrend's labels, in LaTeX.
_LATEX = {
    "\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
    "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}",
    "Δ": r"$\Delta$", "ε": r"$\varepsilon$", "β": r"$\beta$", "σ": r"$\sigma$", "κ": r"$\kappa$",
    "ρ": r"$\rho$", "α": r"$\alpha$", "°": r"$^\circ$", "×": r"$\times$", "–": "--",
    "ω": r"$\omega$", "−": "$-$", "·": r"$\cdot$", "²": r"$^2$", "≤": r"$\le$", "≥": r"$\ge$",
}  # fmt: skip


def _tex(text: str) -> str:
    return "".join(_LATEX.get(ch, ch) for ch in text)


def _latex(table: Table, header: list[str], body: list[list[str]], note: str | None) -> str:
    align = "l" * len(table.row_headers) + "r" * len(table.columns)
    lines = [f"% {_tex(table.title)}"] if table.title else []
    lines += [
        f"\\begin{{tabular}}{{{align}}}",
        "\\toprule",
        " & ".join(_tex(h) for h in header) + " \\\\",
        "\\midrule",
    ]
    lines += [
        " & ".join(c if c.endswith("$^{*}$") else _tex(c) for c in row) + " \\\\" for row in body
    ]
    lines += ["\\bottomrule", "\\end{tabular}"]
    if note:
        lines.append(f"% {_tex(note)}")
    return "\n".join(lines)


def _csv(table: Table) -> str:
    """One column per row field; per value its number, and its interval's ends when it has one
    (in the value's unit, unrounded)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    header = list(table.row_headers)
    for h, v in table.columns:
        header += [h, f"{h} low", f"{h} high"] if v.interval and v.kind != "count" else [h]
    writer.writerow(header)
    for keys, cells in table.rows:
        row = list(keys)
        for cell, (_, v) in zip(cells, table.columns, strict=True):
            numbers = (
                ["value", "ci_low", "ci_high"] if v.interval and v.kind != "count" else ["value"]
            )
            for name in numbers:
                x = math.nan if cell is None else float(cell[name]) * v.scale()
                if not math.isfinite(x):
                    row.append("")
                else:
                    row.append(str(int(x)) if v.integer else repr(x))
        writer.writerow(row)
    return out.getvalue().rstrip("\n")
