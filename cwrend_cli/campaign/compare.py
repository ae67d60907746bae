"""Paired comparison of two campaign directories on the runs they share (pure computation).

Two campaigns A and B (``cwrend ablate`` / ``cwrend sweep`` directories) are
compared run by run where they ran the same noise realisation:

* **Noise.** Seed k is the same realisation in both only when both draw it
  from the same root ``noise.seed`` (``root_seed`` in ``manifest.json``; it
  also keys the dispersion draws, actuator errors and sensor faults) and the same
  ``noise.file`` (same path, or files with identical bytes). A grid point
  that sweeps ``noise.seed`` / ``noise.file`` uses its swept value.
  :func:`compare` refuses two campaigns that share no noise.
* **Matching.** A run of A and a run of B match when they have the same
  architecture and seed and their grid points match. Grid points are
  matched by their **swept values**, never by their ids: on every key that
  both campaigns sweep the values must be equal (numbers to a relative
  1e-9, so ``6e-4:1e-3:3`` and ``0.0008`` meet); a key that only one
  campaign sweeps does not restrict the match (the other campaign ran its
  base value throughout) and becomes a grouping column of the result. Two
  ablations match base point to base point.
* **Statistics.** Per group (matched pair of points) and architecture, on
  the matched runs that succeeded in both: for each metric the per-seed
  difference d = A − B; ``mean_diff`` (the mean of d, which is the
  difference of the means) and ``median_diff`` (the median of d, the typical
  seed's change, not the difference of the medians) with 95 % percentile
  bootstrap intervals (:func:`~cwrend_cli.campaign.statistics.bootstrap_ci`,
  seeded from the shared root seed), ``frac_better`` (share of seeds with
  A < B: lower is better for every metric; ties count as not better) with
  its Wilson interval, and ``frac_tied`` (share with A = B exactly, no
  interval).

The rows have the long format of ``ablation.parquet`` (``kind`` = ``paired``,
``arch``, ``metric``, ``statistic``, ``value``, ``ci_low``, ``ci_high``,
``n``) plus ``point_a``, ``point_b`` and the swept values ``param.<key>``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa

from cwrend_cli.campaign import statistics
from cwrend_cli.campaign.statistics import (
    APPLIED_METRICS,
    DEFAULT_PAIRS,
    METRICS,
    bootstrap_ci,
    wilson_ci,
)
from cwrend_cli.config.io import file_digest
from cwrend_cli.config.messages import did_you_mean
from cwrend_cli.errors import ConfigError, InputDataError
from cwrend_cli.output.layout import MANIFEST, PARAM_PREFIX, RUNS
from cwrend_cli.output.manifest import REPAIR_HINT, read_manifest
from cwrend_cli.output.tables import METRIC_NAMES, metric_name, param_columns, statistics_table

__all__ = [
    "COMPARED",
    "DEFAULT_METRICS",
    "Campaign",
    "Comparison",
    "Difference",
    "Matched",
    "across_pairs",
    "compare",
    "compare_table",
    "config_diff",
    "load_campaign",
    "match_runs",
    "paired_across",
    "parse_metrics",
]

#: The ``runs.parquet`` columns ``--metric`` compares, by column name or by their short name
#: (:data:`~cwrend_cli.output.tables.METRIC_NAMES`): the paper's metrics, then the applied
#: Δv and its penalty against the exact fuel optimum (issue 33 item 3).
COMPARED = (*METRICS, *APPLIED_METRICS)
#: The short names of :data:`COMPARED` (``miss``, ``dv``, …).
_SHORT = tuple(k for k, v in METRIC_NAMES.items() if v in COMPARED)
DEFAULT_METRICS = ("miss_km", "delta_v_km_s")
#: Relative tolerance of equal swept numbers across campaigns.
_RTOL = 1e-9
_NOISE_KEYS = ("noise.seed", "noise.file")


def parse_metrics(text: str) -> tuple[str, ...]:
    """``miss,dv`` → ``("miss_km", "delta_v_km_s")``; unknown names raise :class:`ConfigError`.

    Each name is a short name of :data:`~cwrend_cli.output.tables.METRIC_NAMES` or a
    column of :data:`COMPARED`.
    """
    out: list[str] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        name = METRIC_NAMES.get(part, part)
        if name not in COMPARED:
            allowed = ", ".join([*_SHORT, *COMPARED])
            near = did_you_mean(part, [*_SHORT, *COMPARED])
            raise ConfigError(f"--metric {part!r}: unknown metric (allowed: {allowed}){near}")
        if name not in out:
            out.append(name)
    if not out:
        raise ConfigError(f"--metric {text!r}: name at least one of {', '.join(_SHORT)}")
    return tuple(out)


@dataclass(frozen=True)
class Campaign:
    """A campaign directory as compared: its manifest and ``runs.parquet``."""

    path: Path
    manifest: Mapping[str, Any]
    runs: pd.DataFrame

    @property
    def root_seed(self) -> int:
        """``noise.seed`` of the base config (keys every random stream of a seed)."""
        return int(self.manifest["root_seed"])

    @property
    def noise_file(self) -> str | None:
        """``noise.file`` of the base config (``None``: the seeded stream)."""
        noise = self.manifest.get("config", {}).get("noise", {})
        file = noise.get("file") if isinstance(noise, Mapping) else None
        return None if file is None else str(file)

    @property
    def swept(self) -> tuple[str, ...]:
        """The ``param.<key>`` columns of ``runs.parquet`` (keys swept by the grid)."""
        return tuple(param_columns(self.runs.columns))


def load_campaign(path: Path) -> Campaign:
    """Read a campaign directory; :class:`ConfigError` when it is not one."""
    manifest_path, runs_path = path / MANIFEST, path / RUNS
    if not manifest_path.is_file() or not runs_path.is_file():
        raise ConfigError(
            f"{path}: not a campaign directory (no {MANIFEST} and {RUNS}; "
            "compare the output of cwrend ablate or cwrend sweep)"
        )
    manifest = read_manifest(manifest_path, REPAIR_HINT)
    try:
        runs = pd.read_parquet(runs_path)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: unreadable campaign ({exc})") from None
    if "root_seed" not in manifest:
        raise ConfigError(f"{manifest_path}: no root_seed (not a cwrend campaign manifest)")
    runs["arch"] = runs["arch"].astype(str)
    runs["point"] = runs["point"].astype(str)
    return Campaign(path, manifest, runs)


# ---------------------------------------------------------------------------
# Noise and matching
# ---------------------------------------------------------------------------


def _file_digest(path: str) -> str | None:
    """SHA-256 of a file read in chunks (:func:`cwrend_cli.config.io.file_digest`), or None."""
    try:
        return file_digest(path)
    except InputDataError:
        return None


def _same_file(a: str | None, b: str | None) -> bool:
    """Whether two noise files hold the same bytes: sizes first, then (equal sizes) digests."""
    if a is None or b is None:
        return a is b
    if a == b:
        return True
    try:
        if Path(a).stat().st_size != Path(b).stat().st_size:
            return False
    except OSError:
        return False
    da = _file_digest(a)
    return da is not None and da == _file_digest(b)


def _noise_of(c: Campaign, row: Mapping[str, Any]) -> tuple[int, int, str | None]:
    """(root seed, measurement-noise seed, noise file) of a grid point of ``c``."""
    seed, file = c.root_seed, c.noise_file
    swept_seed, swept_file = (row.get(PARAM_PREFIX + k) for k in _NOISE_KEYS)
    if swept_seed is not None and not _missing(swept_seed):
        seed = int(swept_seed)
    if swept_file is not None and not _missing(swept_file):
        file = str(swept_file)
    return c.root_seed, seed, file


def _missing(value: Any) -> bool:
    return isinstance(value, float) and math.isnan(value)


def _describe_noise(noise: tuple[int, int, str | None]) -> str:
    root, seed, file = noise
    text = f"noise.seed = {seed}" if seed == root else f"noise.seed = {seed} (root {root})"
    return text + (f", noise.file = {file!r}" if file is not None else ", no noise.file")


def _same_noise(a: tuple[int, int, str | None], b: tuple[int, int, str | None]) -> bool:
    return a[0] == b[0] and a[1] == b[1] and _same_file(a[2], b[2])


def _equal(x: Any, y: Any) -> bool:
    numbers = (int, float, np.integer, np.floating)
    if isinstance(x, numbers) and isinstance(y, numbers) and not isinstance(x, bool):
        return bool(np.isclose(float(x), float(y), rtol=_RTOL, atol=0.0))
    return bool(x == y)


def _points(c: Campaign) -> list[dict[str, Any]]:
    cols = ["point", *c.swept]
    distinct = c.runs[cols].drop_duplicates("point")
    return [{str(k): v for k, v in r.items()} for r in distinct.to_dict(orient="records")]


@dataclass(frozen=True)
class Matched:
    """The matched runs of two campaigns and what was left out."""

    pairs: pd.DataFrame  # one row per matched run: point_a, point_b, params, arch, seed, metrics
    groups: tuple[str, ...]  # point_a, point_b and the swept keys (param.<key>) of A or B
    notes: tuple[str, ...]


def match_runs(a: Campaign, b: Campaign, metrics: Sequence[str] = METRICS) -> Matched:
    """The runs of A and B on the same noise, architecture, seed and swept values.

    Raises :class:`ConfigError` when the two campaigns share no noise or no run.
    Columns ``<metric>_a`` / ``<metric>_b`` and ``status_a`` / ``status_b``.
    """
    point_pairs, noise_mismatch = _matched_points(a, b)
    swept = _swept(a, b)
    keep = ["arch", "seed", "status", *metrics]
    frames = []
    for pa_, pb in point_pairs:
        ra = a.runs.loc[a.runs["point"] == pa_["point"], keep]
        rb = b.runs.loc[b.runs["point"] == pb["point"], keep]
        both = ra.merge(rb, on=["arch", "seed"], suffixes=("_a", "_b"))
        both.insert(0, "point_a", pa_["point"])
        both.insert(1, "point_b", pb["point"])
        for i, k in enumerate(swept):
            both.insert(2 + i, k, pa_[k] if k in pa_ else pb[k])
        frames.append(both)
    pairs = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    if pairs.empty:
        raise ConfigError(
            f"{a.path} and {b.path} share no run (same architecture, seed and swept "
            f"values): A has {_holds(a)}; B has {_holds(b)}"
        )
    notes = []
    if noise_mismatch:
        notes.append(f"{noise_mismatch} pair(s) of grid points on different noise left out")
    only = sorted(set(a.runs["arch"]) ^ set(b.runs["arch"]))
    if only:
        notes.append(f"architecture(s) in one campaign only, not compared: {', '.join(only)}")
    failed = int(((pairs["status_a"] != "ok") | (pairs["status_b"] != "ok")).sum())
    if failed:
        notes.append(f"{failed} shared run(s) failed in A or B and are left out")
    return Matched(pairs, ("point_a", "point_b", *swept), tuple(notes))


_Point = dict[str, Any]


def _matched_points(a: Campaign, b: Campaign) -> tuple[list[tuple[_Point, _Point]], int]:
    """The pairs of grid points of A and B that match (equal values of every key both
    sweep) on the same noise, in A's order then B's, and how many matched on other noise.

    Raises :class:`ConfigError` when points match but none on the same noise.
    """
    common = [k for k in a.swept if k in b.swept]
    point_pairs: list[tuple[_Point, _Point]] = []
    noise_mismatch: list[tuple[tuple[int, int, str | None], tuple[int, int, str | None]]] = []
    for pa_ in _points(a):
        for pb in _points(b):
            if not all(_equal(pa_[k], pb[k]) for k in common):
                continue
            na, nb = _noise_of(a, pa_), _noise_of(b, pb)
            if _same_noise(na, nb):
                point_pairs.append((pa_, pb))
            else:
                noise_mismatch.append((na, nb))
    if not point_pairs and noise_mismatch:
        na, nb = noise_mismatch[0]
        raise ConfigError(
            f"{a.path} and {b.path} do not share noise: A has {_describe_noise(na)}, "
            f"B has {_describe_noise(nb)}; a paired comparison needs the same noise "
            "realisations (the same noise.seed, root_seed in manifest.json, and noise file)"
        )
    return point_pairs, len(noise_mismatch)


def _swept(a: Campaign, b: Campaign) -> list[str]:
    """The ``param.<key>`` columns of A, then those only B sweeps."""
    return [*a.swept, *(k for k in b.swept if k not in a.swept)]


def _holds(c: Campaign) -> str:
    seeds = sorted(int(s) for s in c.runs["seed"].unique())
    span = f"{seeds[0]}–{seeds[-1]}" if seeds else "none"
    archs = ", ".join(sorted(c.runs["arch"].unique()))
    points = c.runs["point"].nunique()
    swept = ", ".join(k.removeprefix(PARAM_PREFIX) for k in c.swept) or "nothing swept"
    return f"{archs}; {len(seeds)} seed(s) {span}; {points} point(s) ({swept})"


# ---------------------------------------------------------------------------
# Statistics
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Comparison:
    """The paired differences A − B of two campaigns."""

    frame: pd.DataFrame  # the rows of compare.parquet
    groups: tuple[str, ...]  # point_a, point_b, param.<key>…
    metrics: tuple[str, ...]
    matched: int  # runs matched (any status)
    compared: int  # runs compared (ok in both)
    notes: tuple[str, ...]
    a: Campaign
    b: Campaign


def compare(a: Campaign, b: Campaign, metrics: Sequence[str] = DEFAULT_METRICS) -> Comparison:
    """Per group and architecture, the paired differences A − B of ``metrics``.

    Raises :class:`ConfigError` (exit 2) when the campaigns share no noise, no
    run, or no run that succeeded in both.
    """
    metrics = tuple(metrics)
    for c in (a, b):
        _check_metrics(c, metrics)
    matched = match_runs(a, b, metrics)
    pairs = matched.pairs
    ok = pairs[(pairs["status_a"] == "ok") & (pairs["status_b"] == "ok")]
    if ok.empty:
        raise ConfigError(
            f"{a.path} and {b.path} share {len(pairs)} run(s), none of which succeeded in both"
        )
    rng = np.random.default_rng(a.root_seed)
    rows: list[dict[str, Any]] = []
    by = [*matched.groups, "arch"]
    for keys, group in ok.groupby(by, sort=False, dropna=False):
        ident = dict(zip(by, keys, strict=True))
        group = group.sort_values("seed")
        n = len(group)
        for metric in metrics:
            d = (group[f"{metric}_a"] - group[f"{metric}_b"]).to_numpy(dtype=float)
            base = {**ident, "kind": "paired", "metric": metric, "n": n}
            for name, fn in (("mean_diff", np.mean), ("median_diff", np.median)):
                lo, hi = bootstrap_ci(d, fn, rng)
                rows.append(
                    {**base, "statistic": name, "value": float(fn(d)), "ci_low": lo, "ci_high": hi}
                )
            better = int((d < 0).sum())
            lo, hi = wilson_ci(better, n)
            rows.append(
                {**base, "statistic": "frac_better", "value": better / n, "ci_low": lo,
                 "ci_high": hi}
            )  # fmt: skip
            rows.append(
                {**base, "statistic": "frac_tied", "value": float((d == 0).sum()) / n,
                 "ci_low": math.nan, "ci_high": math.nan}
            )  # fmt: skip
    columns = ["kind", "arch", "metric", "statistic", "value", "ci_low", "ci_high", "n"]
    frame = pd.DataFrame(rows)[[*columns, *matched.groups]]
    return Comparison(
        frame=frame,
        groups=matched.groups,
        metrics=metrics,
        matched=len(pairs),
        compared=len(ok),
        notes=matched.notes,
        a=a,
        b=b,
    )


def _check_metrics(c: Campaign, metrics: Sequence[str]) -> None:
    """Refuse (:class:`ConfigError`, exit 2) a metric that ``runs.parquet`` of ``c`` lacks:
    a campaign written by a cwrend that did not compute it (the applied Δv before issue 33)."""
    missing = [m for m in metrics if m not in c.runs.columns]
    if not missing:
        return
    names = ", ".join(f"{metric_name(m)} ({m})" for m in missing)
    held = ", ".join(metric_name(m) for m in COMPARED if m in c.runs.columns)
    raise ConfigError(
        f"{c.path}: --metric {names}: runs.parquet has no such column (the campaign was "
        "written by a cwrend that did not compute it); re-run the campaign with this version "
        "(its command with --force, or with another --name) to compare it, or compare "
        f"{held or 'the metrics it holds'}"
    )


def across_pairs(
    archs_a: Sequence[str], archs_b: Sequence[str], extra: Sequence[tuple[str, str]] = ()
) -> tuple[tuple[str, str], ...]:
    """The pairs (X of A, Y of B) that :func:`paired_across` compares by default: each
    architecture against itself (as :func:`compare`), then the pairs a campaign compares
    (:data:`~cwrend_cli.campaign.statistics.DEFAULT_PAIRS`), then ``extra``; those whose
    X ran in A and Y in B."""
    same = [(x, x) for x in archs_a]
    candidates = dict.fromkeys([*same, *DEFAULT_PAIRS, *extra])
    return tuple((x, y) for x, y in candidates if x in archs_a and y in archs_b)


def paired_across(
    a: Campaign,
    b: Campaign,
    extra: Sequence[tuple[str, str]] = (),
    keep: Callable[[tuple[str, str]], bool] | None = None,
) -> pd.DataFrame:
    """Seed-by-seed comparisons of architecture X of campaign A with Y of campaign B.

    For each ``(X, Y)`` of :func:`across_pairs` (with ``extra``) that ``keep`` keeps, and
    each pair of
    matched grid points (as :func:`match_runs`: equal values of the keys both sweep,
    the same noise), the rows of
    :func:`~cwrend_cli.campaign.statistics.paired_across` (``frac_less``,
    ``median_diff``, ``mean_diff`` with their intervals, bootstrapped from the shared
    root seed), with ``point_a``, ``point_b`` and the swept values ``param.<key>``
    (of the campaign that sweeps the key). Raises :class:`ConfigError` when the
    campaigns share no noise.
    """
    archs_a = [str(x) for x in a.runs["arch"].unique()]
    archs_b = [str(y) for y in b.runs["arch"].unique()]
    chosen = [p for p in across_pairs(archs_a, archs_b, extra) if keep is None or keep(p)]
    point_pairs, _ = _matched_points(a, b)
    if not point_pairs or not chosen:
        return pd.DataFrame([])
    columns = ["arch", "seed", "status", "miss_km", "delta_v_km_s"]
    # the applied Δv where both campaigns hold it (written since issue 33, item 3)
    applied = statistics.APPLIED
    columns += [applied] if applied in a.runs.columns and applied in b.runs.columns else []
    sides: tuple[list[pd.DataFrame], list[pd.DataFrame]] = ([], [])
    for group, (pa_, pb) in enumerate(point_pairs):
        for side, c, point in ((0, a, pa_), (1, b, pb)):
            runs = c.runs.loc[c.runs["point"].astype(str) == str(point["point"]), columns]
            sides[side].append(runs.assign(arch=runs["arch"].astype(str), group=group))
    rows = statistics.paired_across(
        pd.concat(sides[0], ignore_index=True),
        pd.concat(sides[1], ignore_index=True),
        chosen,
        by=["group"],
        seed=a.root_seed,
    )
    if rows.empty:
        return rows
    groups = rows.pop("group").to_numpy()
    rows["point_a"] = [str(point_pairs[g][0]["point"]) for g in groups]
    rows["point_b"] = [str(point_pairs[g][1]["point"]) for g in groups]
    for k in _swept(a, b):
        rows[k] = [
            point_pairs[g][0][k] if k in point_pairs[g][0] else point_pairs[g][1][k] for g in groups
        ]
    return rows


def compare_table(comparison: Comparison) -> pa.Table:
    """``compare.parquet``: the rows, with both campaigns, the units and what differs
    between their configurations (``config_diff``, :func:`config_diff` as JSON) in the
    metadata."""
    a, b = comparison.a, comparison.b
    hash_a = str(a.manifest.get("config_hash", ""))
    hash_b = str(b.manifest.get("config_hash", ""))
    meta = {
        # one config hash when both campaigns share their base config, else both
        "config_hash": hash_a if hash_a == hash_b else f"A {hash_a}; B {hash_b}",
        "difference": "A - B per seed; frac_better: share of seeds with A < B",
        "units": "miss_km km, delta_v_km_s km/s, fuel_penalty_pct %, delta_v_applied_km_s "
        "km/s, fuel_penalty_applied_pct %",
        "a": str(a.path.resolve()),
        "b": str(b.path.resolve()),
        "campaign_hash_a": str(a.manifest.get("campaign_hash", "")),
        "campaign_hash_b": str(b.manifest.get("campaign_hash", "")),
        "config_hash_a": hash_a,
        "config_hash_b": hash_b,
        "root_seed": str(a.root_seed),
        # what differs between A and B: [{"key": dotted key, "a": A's value, "b": B's}, ...]
        "config_diff": json.dumps(
            [{"key": d.key, "a": d.a, "b": d.b} for d in config_diff(a, b)], ensure_ascii=False
        ),
    }
    return statistics_table(comparison.frame, meta)


# ---------------------------------------------------------------------------
# What differs between A and B
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Difference:
    """A configuration key whose value differs between A and B (``None``: absent there)."""

    key: str  # dotted: schedule.beta; a grid's values as sweep.<key>, a design's as design.<field>
    a: Any  # A's value as its manifest stores it (JSON: numbers, strings, lists)
    b: Any


def config_diff(a: Campaign, b: Campaign) -> tuple[Difference, ...]:
    """What differs between the configurations of A and B, key by key, in A's key order.

    Read from each manifest: the resolved base configuration without
    ``[output]`` (where results go and which seeds keep per-step data: not
    what the runs compute; the campaign hash leaves it out likewise), the
    grid's values of each swept key as ``sweep.<key>`` and a sampled design's
    fields as ``design.<field>``. Tables are walked to their leaves; an array
    is one value. Empty when the two configurations are the same.
    """
    left, right = _settings(a.manifest), _settings(b.manifest)
    keys = dict.fromkeys([*left, *right])
    return tuple(
        Difference(k, left.get(k), right.get(k)) for k in keys if left.get(k) != right.get(k)
    )


def _settings(manifest: Mapping[str, Any]) -> dict[str, Any]:
    """The dotted keys and values :func:`config_diff` compares, of one manifest."""
    config = manifest.get("config")
    # the base config's [sweep] is empty: the grid stands for it
    skip = ("output", "sweep")
    tree = {k: v for k, v in config.items() if k not in skip} if isinstance(config, dict) else {}
    grid = manifest.get("grid")
    if isinstance(grid, dict) and grid:
        tree["sweep"] = dict(grid)
    design = manifest.get("design")
    if isinstance(design, dict):
        tree["design"] = dict(design)
    leaves: dict[str, Any] = {}
    _leaves(tree, "", leaves)
    return leaves


def _leaves(tree: Mapping[str, Any], prefix: str, into: dict[str, Any]) -> None:
    for key, value in tree.items():
        # a grid's keys are dotted themselves (sweep.schedule.beta): kept whole, never split
        if isinstance(value, Mapping) and prefix != "sweep.":
            _leaves(value, f"{prefix}{key}.", into)  # an empty table has no leaf
        else:
            into[f"{prefix}{key}"] = value
