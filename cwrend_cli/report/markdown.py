"""The report's markdown: summary tables and the text of ``report.md``.

Tables (GitHub-flavoured markdown) of the reported noise seed, of every seed
of the reported grid point and of every grid point of a sweep; the figure list
comes from the registry (:data:`~cwrend_cli.report.figures.FIGURES`) with its
captions. One unit and precision per quantity, as on the console: Δv in km/s
(4 decimals), misses in m (2 decimals), fuel penalty in % (2 decimals); beside
the paper's Δv (the 1 s trapezoid of ‖u‖) and fuel penalty the applied Δv
Σ‖u_k‖Δt and its penalty against the exact continuous fuel optimum (issue 33;
for the open-loop references a ``cwrend run``'s ``summary.parquet`` holds them,
"–" for a campaign's, whose exact Δv the stored samples do not hold, and for
campaigns written before). Campaign tables carry the 95 %
intervals and paired comparisons that the campaign stored in
``ablation.parquet`` / ``sweep.parquet`` (never recomputed here); an interval
from fewer than :data:`MIN_BOOTSTRAP_N` seeds is marked with
:data:`UNRELIABLE_MARK`. The filter-consistency means of the runs
(``mean_nees``, 6 for a consistent filter; ``mean_nis_nominal``, 3) are
averaged over the seeds (no interval is stored for them). A sampled design
(``sweep --design``) gets the table of its Sobol indices
(``sensitivity.parquet``) instead of a row per design point. A campaign whose
configuration has path constraints (issue 32) gets a table of the safety of
its true trajectories (:func:`safety_table`), from the safety rows of its
statistics file.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from cwrend_cli.output.layout import PARAM_PREFIX
from cwrend_cli.output.tables import param_columns
from cwrend_cli.physics.metrics import NEES_DOF, NIS_DOF, mean_in_band
from cwrend_cli.report.consistency import judged, share_inside, step_ensembles
from cwrend_cli.report.figures import SENSITIVITY_METRICS, sensitivity_archs
from cwrend_cli.report.labels import (
    M_PER_KM,
    MIN_BOOTSTRAP_N,
    consistency_text,
    format_value,
    markdown_table,
    number,
    param_label,
)
from cwrend_cli.report.load import ReportData, arch_label, param_values, point_values

UNRELIABLE_MARK = "\\*"  # a literal * in markdown
UNRELIABLE_NOTE = (
    f"{UNRELIABLE_MARK} fewer than {MIN_BOOTSTRAP_N} seeds: bootstrap interval unreliable."
)
DV = ".4f"  # km/s
MISS = ".2f"  # m (after M_PER_KM)
FUEL = ".2f"  # %
SHARE = ".2f"  # a proportion
CONSISTENCY = ".2f"  # mean NEES / NIS (dimensionless)
INDEX = ".2f"  # a Sobol index
UNSAFE_TIME = ".1f"  # s


def _fmt(value: Any, spec: str = ".4g") -> str:
    if value is None:
        return "–"
    try:
        f = float(value)
    except (TypeError, ValueError):
        return str(value)
    if not np.isfinite(f):
        return "–"
    return number(f, spec)


def _finite(value: Any) -> bool:
    try:
        return bool(np.isfinite(float(value)))
    except (TypeError, ValueError):
        return False


def _unreliable(row: Any) -> bool:
    """A bootstrap interval from fewer than :data:`MIN_BOOTSTRAP_N` samples."""
    return _finite(row["ci_low"]) and int(row["n"]) < MIN_BOOTSTRAP_N


def _ci(row: Any, spec: str, scale: float = 1.0, *, bootstrap: bool = True) -> str:
    """``value [low, high]`` of a statistics row (value alone without an interval)."""
    if row is None:
        return "–"
    value = _fmt(float(row["value"]) * scale, spec)
    if not _finite(row["ci_low"]):
        return value
    lo, hi = float(row["ci_low"]) * scale, float(row["ci_high"]) * scale
    mark = UNRELIABLE_MARK if bootstrap and _unreliable(row) else ""
    return f"{value} [{number(lo, spec)}, {number(hi, spec)}]{mark}"


def _lookup(stats: pd.DataFrame) -> dict[tuple[str, str], Any]:
    return {(str(r["metric"]), str(r["statistic"])): r for _, r in stats.iterrows()}


def seed_table(data: ReportData) -> str:
    """Open-loop references and each architecture's run of the reported seed."""
    runs = data.ok_runs()
    runs = runs[runs["seed"] == data.seed]
    header = ["case", "Δv [km/s]", "miss [m]", "fuel penalty [%]", "applied Δv [km/s]",
              "applied fuel penalty [%]", "re-solves", "success [%]", "infeasible", "failed",
              "solve mean / max [ms]"]  # fmt: skip
    rows = []
    for _, r in data.ref_summary.iterrows():
        rows.append([f"open-loop {str(r['arch']).removeprefix('open_loop_')}",
                     _fmt(r["delta_v_km_s"], DV), _fmt(r["miss_km"] * M_PER_KM, MISS),
                     _fmt(r.get("fuel_penalty_pct"), FUEL),
                     _fmt(r.get("delta_v_applied_km_s"), DV),
                     _fmt(r.get("fuel_penalty_applied_pct"), FUEL), "", "", "", "",
                     ""])  # fmt: skip
    for a in data.archs:
        g = runs[runs["arch"] == a]
        if g.empty:
            continue
        r = g.iloc[0]
        rows.append([
            arch_label(a), _fmt(r["delta_v_km_s"], DV), _fmt(r["miss_km"] * M_PER_KM, MISS),
            _fmt(r.get("fuel_penalty_pct"), FUEL), _fmt(r.get("delta_v_applied_km_s"), DV),
            _fmt(r.get("fuel_penalty_applied_pct"), FUEL), _fmt(r.get("n_solves"), "g"),
            _fmt(r.get("solve_success_pct"), ".2f"), _fmt(r.get("n_infeasible"), "g"),
            _fmt(r.get("n_failed"), "g"),
            f"{_fmt(r.get('solve_mean_ms'), '.3g')} / {_fmt(r.get('solve_max_ms'), '.3g')}",
        ])  # fmt: skip
    return markdown_table(header, rows)


def campaign_table(data: ReportData) -> str:
    """Per architecture over the seeds of the reported point (failed runs counted).

    Means, medians and p95 with the 95 % intervals stored by the campaign;
    without stored statistics, the values alone.
    """
    all_runs = data.runs
    if data.point is not None and "point" in all_runs.columns:
        all_runs = all_runs[all_runs["point"].astype(str) == data.point]
    stats = data.point_stats()
    header = ["architecture", "runs ok / failed", "mean Δv [km/s]", "mean miss [m]",
              "median miss [m]", "p95 miss [m]", "max miss [m]", "mean fuel penalty [%]",
              "mean success [%]", "mean NEES [-] (6)", f"mean NIS [-] ({data.nis_dof})",
              "mean applied Δv [km/s]", "mean applied fuel penalty [%]"]  # fmt: skip
    rows = []
    for a in data.archs:
        g = all_runs[all_runs["arch"] == a]
        ok = g[g["status"] == "ok"]
        miss = ok["miss_km"].astype(float) * M_PER_KM
        ok_label = f"{len(ok)} / {len(g) - len(ok)}"
        success = _fmt(ok["solve_success_pct"].mean() if "solve_success_pct" in ok else None, ".2f")
        consistency = [_mean(ok, "mean_nees", CONSISTENCY), _mean(ok, "mean_nis_nominal",
                                                                 CONSISTENCY)]  # fmt: skip
        if stats is not None:
            get = _lookup(stats[(stats["kind"] == "marginal") & (stats["arch"] == a)])
            rows.append([
                arch_label(a), ok_label, _ci(get.get(("delta_v_km_s", "mean")), DV),
                _ci(get.get(("miss_km", "mean")), MISS, M_PER_KM),
                _ci(get.get(("miss_km", "median")), MISS, M_PER_KM),
                _ci(get.get(("miss_km", "p95")), MISS, M_PER_KM), _fmt(miss.max(), MISS),
                _ci(get.get(("fuel_penalty_pct", "mean")), FUEL), success, *consistency,
                _ci(get.get(("delta_v_applied_km_s", "mean")), DV),
                _ci(get.get(("fuel_penalty_applied_pct", "mean")), FUEL),
            ])  # fmt: skip
            continue
        fuel = ok["fuel_penalty_pct"].mean() if "fuel_penalty_pct" in ok else None
        rows.append([
            arch_label(a), ok_label, _fmt(ok["delta_v_km_s"].mean(), DV),
            _fmt(miss.mean(), MISS), _fmt(miss.median(), MISS),
            _fmt(miss.quantile(0.95) if len(miss) else None, MISS), _fmt(miss.max(), MISS),
            _fmt(fuel, FUEL), success, *consistency, _mean(ok, "delta_v_applied_km_s", DV),
            _mean(ok, "fuel_penalty_applied_pct", FUEL),
        ])  # fmt: skip
    return markdown_table(header, rows)


def _mean(runs: pd.DataFrame, column: str, spec: str) -> str:
    """Mean of a runs column over the runs (``–`` when not stored, e.g. older campaigns)."""
    if column not in runs.columns:
        return "–"
    values = pd.to_numeric(runs[column], errors="coerce")
    return _fmt(values.mean() if values.notna().any() else None, spec)


def paired_table(data: ReportData) -> str | None:
    """Seed-by-seed comparisons stored by the campaign (``None`` when there are none)."""
    stats = data.point_stats()
    if stats is None or "other" not in stats.columns:
        return None
    pairs = stats[stats["kind"] == "paired"]
    if pairs.empty:
        return None
    header = ["A vs B", "seeds", "P(miss A < B)", "median Δmiss [m]", "mean ΔΔv [km/s]"]
    rows = []
    for (a, b), g in pairs.groupby(["arch", "other"], sort=False):
        get = {str(r["statistic"]): r for _, r in g.iterrows()}
        less = get.get("frac_less")
        rows.append([
            f"{arch_label(str(a))} vs {arch_label(str(b))}",
            str(int(less["n"])) if less is not None else "–",
            _ci(less, SHARE, bootstrap=False),
            _ci(get.get("median_diff"), MISS, M_PER_KM), _ci(get.get("mean_diff"), DV),
        ])  # fmt: skip
    return markdown_table(header, rows)


def safety_table(data: ReportData) -> str | None:
    """The safety of the true trajectories per architecture (issue 32), as stored.

    From the safety rows of ``ablation.parquet`` / ``sweep.parquet`` of the
    reported point (``campaign.statistics.safety``, never recomputed): the share
    of runs that entered the unsafe set with its 95 % Wilson interval, the
    median and 1st percentile of the minimum signed distance (m; negative:
    inside) and the mean time inside (s) with their bootstrap intervals. With
    abort safety (issue 34 item 4, ``campaign.statistics.abort_safety``), three
    more columns: the share of runs with a step whose free drift enters the
    keep-out zone and the median and 1st percentile of the worst drift distance.
    ``None`` without path constraints in the configuration or without stored
    safety rows.
    """
    stats = data.point_stats()
    if data.constraints is None or stats is None:
        return None
    rows_of = stats[(stats["kind"] == "marginal") & stats["metric"].astype(str).str.match(
        "safety_|abort_")]  # fmt: skip
    if rows_of.empty:
        return None
    abort = bool(rows_of["metric"].astype(str).str.startswith("abort_").any())
    header = ["architecture", "runs", "violated (share) [95 % Wilson]",
              "median min distance [m]", "p1 min distance [m]",
              "mean unsafe time [s]"]  # fmt: skip
    runs = data.ok_runs()
    docking = [c for c in DOCKING_COLUMNS if c in runs.columns]
    header += [DOCKING_COLUMNS[c][0] for c in docking]
    if abort:
        header += ["abort-unsafe (share) [95 % Wilson]", "median worst drift distance [m]",
                   "p1 worst drift distance [m]"]  # fmt: skip
    rows = []
    for a in data.archs:
        get = _lookup(rows_of[rows_of["arch"] == a])
        cells = _violation_cells(get)
        if cells is None:
            continue
        n, violation = cells
        rows.append([
            arch_label(a), str(n), *violation,
            _ci(get.get(("safety_unsafe_time_s", "mean")), UNSAFE_TIME),
            *[_median_max(runs[runs["arch"] == a], c) for c in docking],
        ])  # fmt: skip
        if abort:
            rows[-1] += _abort_cells(get)
    return markdown_table(header, rows) if rows else None


#: Most grid points whose safety :func:`safety_points_table` lists (a sampled design of
#: hundreds is left to sweep.parquet) [-].
SAFETY_POINTS_MAX = 24


def safety_points_table(data: ReportData) -> str | None:
    """The safety of every grid point of a sweep, per architecture (issue 32), as stored:
    the swept values, the share of runs that entered the unsafe set [95 % Wilson] and the
    median and 1st percentile of the minimum distance (m). ``None`` for one point, without
    path constraints or safety rows, or for more than :data:`SAFETY_POINTS_MAX` points."""
    stats = data.stats
    if data.constraints is None or stats is None or "point" not in stats.columns:
        return None
    if not 1 < stats["point"].nunique() <= SAFETY_POINTS_MAX:
        return None
    rows_of = stats[(stats["kind"] == "marginal") & stats["metric"].astype(str).str.startswith(
        "safety_")]  # fmt: skip
    params = param_columns(stats.columns)
    header = [param_label(c.removeprefix(PARAM_PREFIX)) for c in params]
    header += ["architecture", "violated (share) [95 % Wilson]", "median min distance [m]",
               "p1 min distance [m]"]  # fmt: skip
    rows = []
    for keys, g in rows_of.groupby([*params, "arch"], sort=True, observed=True):
        cells = _violation_cells(_lookup(g))
        if cells is not None:
            rows.append([*(format_value(k) for k in keys[:-1]), arch_label(str(keys[-1])),
                         *cells[1]])  # fmt: skip
    return markdown_table(header, rows) if rows else None


def _violation_cells(get: dict[tuple[str, str], Any]) -> tuple[int, list[str]] | None:
    """(runs, [violated: count of runs and share with its Wilson interval, median and 1st
    percentile of the minimum distance, m]) of an architecture's safety rows (``None``
    without them)."""
    share = get.get(("safety_violated", "share"))
    if share is None:
        return None
    n = int(share["n"])
    count = round(float(share["value"]) * n)
    return n, [
        f"{count} of {n}: {_ci(share, SHARE, bootstrap=False)}",
        _ci(get.get(("safety_min_distance_km", "median")), MISS, M_PER_KM),
        _ci(get.get(("safety_min_distance_km", "p1")), MISS, M_PER_KM),
    ]


def _abort_cells(get: dict[tuple[str, str], Any]) -> list[str]:
    """The abort-safety cells of an architecture's safety row (issue 34 item 4)."""
    share = get.get(("abort_unsafe", "share"))
    if share is None:
        return ["–"] * 3
    n = int(share["n"])
    return [
        f"{round(float(share['value']) * n)} of {n}: {_ci(share, SHARE, bootstrap=False)}",
        _ci(get.get(("abort_min_distance_km", "median")), MISS, M_PER_KM),
        _ci(get.get(("abort_min_distance_km", "p1")), MISS, M_PER_KM),
    ]


#: A tumbling target's docking errors (issue 34; runs.parquet, with a corridor): column →
#: (table header, scale to the header's unit, format).
DOCKING_COLUMNS: dict[str, tuple[str, float, str]] = {
    "safety_dock_position_error_km": ("dock position error [m], median (max)", M_PER_KM, ".2f"),
    "safety_dock_velocity_error_km_s": ("dock velocity error [mm/s], median (max)", 1e6, ".2f"),
}


def _median_max(runs: pd.DataFrame, column: str) -> str:
    """``median (max)`` of a docking-error column over the runs, scaled (``–``: none stored)."""
    _, scale, spec = DOCKING_COLUMNS[column]
    values = pd.to_numeric(runs[column], errors="coerce").dropna() * scale
    if values.empty:
        return "–"
    return f"{_fmt(values.median(), spec)} ({_fmt(values.max(), spec)})"


def _abort_text(data: ReportData) -> str:
    """What the abort-safety columns measure, with the zone turning for a tumbling target."""
    tumbling = data.point_config is not None and data.point_config.target.attitude == "tumbling"
    zone = (
        "the keep-out zones, turning with the target's attitude,"
        if tumbling
        else "the keep-out zone"
    )
    return (
        " Abort-unsafe (constraints.abort_safe_s): a step before the final approach whose "
        f"free drift (CW, no thrust) enters {zone} within that time; worst drift "
        "distance: the run's smallest signed distance of those drifts to the zone."
    )


def _safety_lines(data: ReportData) -> list[str]:
    """The safety section of a constrained campaign (none otherwise)."""
    table = safety_table(data)
    if table is None:
        return []
    lines = [
        "## Safety (path constraints)",
        "",
        "Measured on the true trajectories against the keep-out zone outside the corridor "
        "(the unsafe set), between steps too; from the campaign's statistics file. "
        "Violated: the run entered the unsafe set (95 % Wilson interval); min distance: the "
        "run's smallest signed distance to the unsafe set (negative: inside), over the seeds "
        "(95 % bootstrap interval)."
        + (_abort_text(data) if "abort-unsafe" in table else "")
        + (
            " Measured only (constraints.enforce = false): the cone-program guidance planned "
            "without the keep-out zone and the corridor, as without [constraints]."
            if data.point_config is not None and not data.point_config.constraints.enforce
            else ""
        )
        + (
            " Dock errors (a tumbling target): the distance to the moving port and the "
            "speed relative to it at the end, over the seeds (runs.parquet)."
            if any(c in data.ok_runs().columns for c in DOCKING_COLUMNS)
            else ""
        ),
        "",
        table,
        "",
    ]
    every = safety_points_table(data)
    if every is not None:  # a sweep: the table above is one point's
        lines[2] += (
            f" The table is grid point {data.point}'s ({point_values(data.ok_runs())}; "
            "`--point` chooses another); every point's below."
        )
        lines += ["### Every grid point", "", every, ""]
    stats = data.point_stats()
    once = int(data.ok_runs()["seed"].nunique()) > 1  # then the note closes the section above
    safety = (
        stats[stats["metric"].astype(str).str.startswith("safety_min")]
        if stats is not None
        else None
    )
    if not once and _flagged(safety):
        lines += [UNRELIABLE_NOTE, ""]
    return lines


def _flagged(stats: pd.DataFrame | None) -> bool:
    if stats is None or stats.empty:
        return False
    boot = stats[stats["statistic"] != "frac_less"]
    return bool(boot.apply(_unreliable, axis=1).any()) if not boot.empty else False


#: The runs columns of filter consistency, their steps column and degrees of freedom.
_CONSISTENCY = (("mean_nees", "nees", NEES_DOF), ("mean_nis_nominal", "nis", NIS_DOF))
BAND = ".2f"  # a χ² band's ends (dimensionless)


def _band_cell(row: Any) -> tuple[str, str]:
    """``mean [low, high]`` of a consistency row and whether the mean is in its band."""
    if row is None or not _finite(row["value"]):
        return "–", "–"
    value, low, high = float(row["value"]), float(row["ci_low"]), float(row["ci_high"])
    if not (_finite(low) and _finite(high)):
        return consistency_text(value), "–"
    text = f"{consistency_text(value)} [{low:{BAND}}, {high:{BAND}}]"
    return text, "yes" if low <= value <= high else "no"


def _stored_consistency(stats: pd.DataFrame, arch: Any) -> dict[str, Any]:
    """The consistency rows of ``arch`` in statistics ``stats``, by metric (empty: none)."""
    rows = stats[(stats["kind"] == "consistency") & (stats["arch"] == str(arch))]
    return {str(r["metric"]): r for _, r in rows.iterrows()}


def _consistency_rows(data: ReportData, arch: str) -> dict[str, Any]:
    """The stored consistency rows of ``arch`` at the reported point, else computed from the runs.

    From the statistics file (``campaign.statistics.consistency``); a run
    directory or an older campaign has none: the mean of the runs' columns
    and its band (:func:`~cwrend_cli.physics.metrics.mean_in_band`).
    """
    stats = data.point_stats()
    stored = _stored_consistency(stats, arch) if stats is not None else {}
    if stored:
        return stored
    runs = data.ok_runs()
    runs = runs[runs["arch"] == arch]
    out: dict[str, Any] = {}
    for metric, _, dof in _CONSISTENCY:
        dof = data.nis_dof if metric == "mean_nis_nominal" else dof  # the sensor's m
        if metric in runs.columns:
            value, low, high, n = mean_in_band(pd.to_numeric(runs[metric], errors="coerce"), dof)
            out[metric] = {"value": value, "ci_low": low, "ci_high": high, "n": n}
    return out


def consistency_table(data: ReportData) -> tuple[str, int] | None:
    """Filter consistency per architecture against the χ² bands, and the seeds of the steps.

    Per architecture: the mean over the ok runs of each run's mean NEES and
    NIS with the 95 % band of a consistent filter's mean for that many runs
    and whether it is in it; the share of the steps whose ensemble mean over
    the seeds lies in that step's band (:mod:`~cwrend_cli.report.consistency`;
    the NIS over the steps outside the degradation windows). Returns the
    table and the number of seeds whose steps are stored; ``None`` when the
    runs hold no consistency column.
    """
    if not any(m in data.runs.columns for m, _, _ in _CONSISTENCY):
        return None
    steps = data.nees
    ensembles = step_ensembles(steps, data.nis_dof) if steps is not None and not steps.empty else {}
    shares: dict[str, dict[str, float]] = {}
    for column, ensemble in ensembles.items():
        frame = share_inside(judged(ensemble, column), ["arch"])
        names, values = frame["arch"].astype(str), frame["inside"].astype(float)
        shares[column] = dict(zip(names, values, strict=True))
    header = ["architecture", "runs", "mean NEES [95 % χ² band]", "in band",
              "steps in NEES band [%]", "mean NIS [95 % χ² band]", "in band",
              "steps in NIS band [%]"]  # fmt: skip
    rows = []
    for a in data.archs:
        stored = _consistency_rows(data, a)
        if not stored:
            continue
        cells: list[str] = []
        for metric, column, _ in _CONSISTENCY:
            cells += _band_cell(stored.get(metric))
            inside = shares.get(column, {}).get(a)
            cells.append(_fmt(100.0 * inside if inside is not None else None, ".1f"))
        first = stored.get("mean_nees", stored.get("mean_nis_nominal"))
        runs = str(int(first["n"])) if first is not None else "–"
        rows.append([arch_label(a), runs, *cells])
    if not rows:
        return None
    seeds = int(data.nees["seed"].nunique()) if ensembles and data.nees is not None else 0
    return markdown_table(header, rows), seeds


def _consistency_lines(data: ReportData) -> list[str]:
    """The filter-consistency section (none without consistency columns in the runs)."""
    found = consistency_table(data)
    if found is None:
        return []
    table, seeds = found
    n_runs = int(data.ok_runs()["seed"].nunique())
    about = (
        "Mean over the runs of each run's time-averaged NEES (6 for a consistent filter) and "
        f"NIS (outside the degradation windows; {data.nis_dof}, the sensor's dimension m), "
        "against the 95 % χ² band of a consistent "
        "filter's mean over that many runs (Bar-Shalom et al. 2001, §5.4.2; conservative for "
        "time averages). Steps in band: the share of the steps at which the mean over the "
        "seeds lies in that step's band (about 95 % for a consistent filter; the NIS over the "
        "steps outside the degradation windows); the figure `consistency.png` draws them."
    )
    if seeds == 0:
        where = "No per-step NEES is stored: no step shares."
    elif seeds < n_runs:
        where = (
            f"The step shares are over the {seeds} seed(s) whose steps are stored "
            f"(`output.steps_seeds`), the means over all {n_runs}."
        )
    else:
        where = f"The step shares are over the {seeds} seed(s)."
    return ["## Filter consistency", "", f"{about} {where}", "", table, ""]


def sweep_table(data: ReportData) -> str:
    """One row per grid point (all swept values) and architecture.

    Mean Δv and miss with the 95 % intervals of ``sweep.parquet`` when stored;
    then, where it stores them, the mean NEES and NIS of the runs with their
    χ² 95 % bands and whether each is in its band (issue 33).
    """
    runs = data.runs[data.runs["status"] == "ok"].copy()
    keys: list[str] = []
    for param in data.params:
        runs[f"_{param}"] = param_values(runs[param])[0]
        keys.append(f"_{param}")
    stats = data.stats if data.stats is not None and "point" in data.stats.columns else None
    header = [param_label(p) for p in data.params] + [
        "architecture", "runs", "mean Δv [km/s]", "mean miss [m]", "median miss [m]",
        "max miss [m]", "mean applied Δv [km/s]",
    ]  # fmt: skip
    consistent = stats is not None and bool((stats["kind"] == "consistency").any())
    if consistent:
        header += ["mean NEES [95 % χ² band]", "in band", "mean NIS [95 % χ² band]", "in band"]
    rows = []
    order = {a: i for i, a in enumerate(data.archs)}
    for values, g in runs.groupby(keys, sort=True):
        values = values if isinstance(values, tuple) else (values,)
        for a, ga in sorted(g.groupby("arch"), key=lambda item: order.get(str(item[0]), 99)):
            miss = ga["miss_km"].astype(float) * M_PER_KM
            cells = [_fmt(ga["delta_v_km_s"].mean(), DV), _fmt(miss.mean(), MISS),
                     _fmt(miss.median(), MISS)]  # fmt: skip
            applied = _mean(ga, "delta_v_applied_km_s", DV)
            if stats is not None:
                point_ids = {str(p) for p in ga["point"].unique()} if "point" in ga else set()
                sel = stats[(stats["kind"] == "marginal") & (stats["arch"] == str(a))]
                sel = sel[sel["point"].astype(str).isin(point_ids)]
                if not sel.empty:
                    get = _lookup(sel)
                    applied = _ci(get.get(("delta_v_applied_km_s", "mean")), DV)
                    cells = [_ci(get.get(("delta_v_km_s", "mean")), DV),
                             _ci(get.get(("miss_km", "mean")), MISS, M_PER_KM),
                             _ci(get.get(("miss_km", "median")), MISS, M_PER_KM)]  # fmt: skip
            row = [*(format_value(v) for v in values), arch_label(str(a)), str(len(ga)),
                   *cells, _fmt(miss.max(), MISS), applied]  # fmt: skip
            if stats is not None and consistent:
                points = {str(p) for p in ga["point"].unique()} if "point" in ga else set()
                stored = _stored_consistency(stats[stats["point"].astype(str).isin(points)], a)
                for metric, _, _ in _CONSISTENCY:
                    row += _band_cell(stored.get(metric))
            rows.append(row)
    return markdown_table(header, rows)


def sensitivity_table(data: ReportData) -> str | None:
    """Sensitivity indices of a sampled design: a row per architecture and parameter.

    S1 and ST (a ``sobol`` design; S1 alone for RBD-FAST's indices of an
    ``lhs`` or ``random`` design) of the mean miss and of the mean Δv over the
    seeds of each design point, ``value [low, high]`` (95 %, as stored in
    ``sensitivity.parquet``). ``None`` without stored indices.
    """
    table = data.sensitivity
    archs = sensitivity_archs(data)
    if table is None or not archs:
        return None
    metrics = [(m, name) for m, name in SENSITIVITY_METRICS if (table["metric"] == m).any()]
    stats = [k for k in ("S1", "ST") if (table["statistic"] == k).any()]
    header = ["architecture", "parameter"] + [
        f"{stat} {name}" for _, name in metrics for stat in stats
    ]
    first = table[table["statistic"].isin(stats)]
    get = {
        (str(r["arch"]), str(r["metric"]), str(r["parameter"]), str(r["statistic"])): r
        for _, r in first.iterrows()
    }
    rows = []
    for a in archs:
        for param in dict.fromkeys(first.loc[first["arch"] == a, "parameter"]):
            cells = [
                _ci(get.get((a, m, param, stat)), INDEX, bootstrap=False)
                for m, _ in metrics
                for stat in stats
            ]
            rows.append([arch_label(a), param_label(param), *cells])
    return markdown_table(header, rows)


def second_order_table(data: ReportData) -> str | None:
    """Second-order Sobol indices (S2) of a ``sobol`` design, a row per pair of parameters.

    ``None`` unless ``sensitivity.parquet`` holds them (``--second-order``).
    """
    table = data.sensitivity
    archs = sensitivity_archs(data)
    if table is None or not archs or "parameter_2" not in table:
        return None
    pairs = table[table["statistic"] == "S2"]
    if pairs.empty:
        return None
    metrics = [(m, name) for m, name in SENSITIVITY_METRICS if (pairs["metric"] == m).any()]
    header = ["architecture", "parameters"] + [f"S2 {name}" for _, name in metrics]
    get = {
        (str(r["arch"]), str(r["metric"]), str(r["parameter"]), str(r["parameter_2"])): r
        for _, r in pairs.iterrows()
    }
    rows = []
    for a in archs:
        sel = pairs[pairs["arch"] == a]
        for p1, p2 in dict.fromkeys(zip(sel["parameter"], sel["parameter_2"], strict=True)):
            cells = [_ci(get.get((a, m, p1, p2)), INDEX, bootstrap=False) for m, _ in metrics]
            rows.append([arch_label(a), f"{param_label(p1)} × {param_label(p2)}", *cells])
    return markdown_table(header, rows)


def _design_lines(data: ReportData) -> list[str]:
    """The section of a sampled design: its points, parameters and Sobol indices."""
    runs = data.runs[data.runs["status"] == "ok"]
    n_points = int(runs["point"].nunique()) if "point" in runs.columns else 0
    names = ", ".join(param_label(p) for p in data.params) or "–"
    lines = [
        "## Sampled design",
        "",
        f"{n_points} design points over {names}; no per-point table or figures (see "
        "`runs.parquet` and `sweep.parquet` for each point).",
        "",
    ]
    table = sensitivity_table(data)
    if table is None:
        return [
            *lines,
            "No sensitivity indices stored (an `lhs` or `random` design needs at least 9 "
            "design rows for RBD-FAST).",
            "",
        ]
    stored = data.sensitivity
    seeds: Any = stored["n_seeds"].min() if stored is not None and "n_seeds" in stored else None
    per_point = f"; at least {int(float(seeds))} seed(s) per point" if _finite(seeds) else ""
    rbd = stored is not None and "method" in stored and set(stored["method"]) == {"rbd_fast"}
    if rbd:
        about = (
            "First-order indices (S1) of the mean over the seeds of each design point, "
            "estimated from the design as it is by RBD-FAST (SALib; Plischke 2010, bias "
            "corrected as Tissot & Prieur 2012), 95 % bootstrap interval in brackets "
            f"(`sensitivity.parquet`{per_point}). S1 is the share of the variance explained "
            "by one parameter alone; 1 − ΣS1 is left to interactions (and noise)."
        )
    else:
        about = (
            "First-order (S1) and total (ST) Sobol indices of the mean over the seeds of each "
            f"design point, 95 % interval in brackets (`sensitivity.parquet`{per_point}). "
            "ST ≥ S1 up to sampling error; ST − S1 is the share through interactions."
        )
    lines += ["### Sensitivity indices", "", about, "", table, ""]
    pairs = second_order_table(data)
    if pairs is not None:
        lines += ["Second-order Sobol indices (S2: the share of a pair's interaction), "
                  "95 % interval in brackets:", "", pairs, ""]  # fmt: skip
    return lines


def report_md(data: ReportData, results_dir: Path, figures: Sequence[tuple[str, str]]) -> str:
    """The text of ``report.md``: provenance, notes, tables, then ``figures`` (file, caption).

    The tables: the statistics over the campaign's seeds (with the paired
    comparisons) before the rows of the one seed the per-seed figures show,
    then the sweep or design tables.
    """
    n_seeds = int(data.ok_runs()["seed"].nunique())
    lines = [
        "# cwrend report",
        "",
        f"Results: `{results_dir}` ({'`cwrend run` output' if data.layout == 'run' else 'campaign'}"
        + (f", config hash `{data.config_hash[:12]}`" if data.config_hash else "")
        + ").",
        f"Per-seed figures (1–5) show noise seed **{data.seed}**"
        + (f" at {'design' if data.design else 'grid'} point `{data.point}`" if data.point else "")
        + (" (the first seed; choose another with `--seed N`)." if n_seeds > 1 else "."),
    ]
    if data.windows:
        wins = "; ".join(
            f"{i}: [{w.start_s:g}, {w.end_s:g}] s, {w.label}"
            for i, w in enumerate(data.windows, start=1)
        )
        lines.append(f"Degradation windows (shaded in the figures): {wins}.")
    lines += [f"{note}" for note in data.notes]
    lines += [""]
    if n_seeds > 1:  # the campaign's statistics first, then one seed's rows (issue 37 item 14)
        stats = data.point_stats()
        about = (
            "Values [95 % bootstrap interval], from the campaign's statistics file."
            if stats is not None
            else "No statistics file (ablation.parquet / sweep.parquet): values without intervals."
        )
        lines += [f"## Over {n_seeds} noise seeds", "", about, "", campaign_table(data), ""]
        pairs = paired_table(data)
        if pairs is not None:
            lines += ["### Paired comparisons (same noise)", "",
                      "Δ = A − B per seed; 95 % interval in brackets (Wilson for P, "
                      "bootstrap otherwise).", "", pairs, ""]  # fmt: skip
        if _flagged(stats):
            lines += [UNRELIABLE_NOTE, ""]
    lines += _safety_lines(data)
    lines += _consistency_lines(data)
    lines += [f"## Noise seed {data.seed}", "", seed_table(data), ""]
    if data.design:
        lines += _design_lines(data)
    elif data.params:
        names = ", ".join(f"`{p.removeprefix(PARAM_PREFIX)}`" for p in data.params)
        lines += [f"## Sweep of {names} (every grid point)", "", sweep_table(data), ""]
        if _flagged(data.stats if data.stats is not None and "point" in data.stats else None):
            lines += [UNRELIABLE_NOTE, ""]
    lines += ["## Figures", ""]
    for file, caption in figures:
        stem = Path(file).stem
        lines += [f"### {stem}", "", caption, "", f"![{stem}]({file})", ""]
    return "\n".join(lines)
