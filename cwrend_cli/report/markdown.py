"""The report's markdown: summary tables and the text of ``report.md``.

Tables (GitHub-flavoured markdown) of the reported noise seed, of every seed
of the reported grid point and of every grid point of a sweep; the figure
list comes from the registry (:data:`~cwrend_cli.report.figures.FIGURES`)
with its captions. Units: km, s, km/s (as in the Parquet files).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cwrend_cli.output.tables import PARAM_PREFIX
from cwrend_cli.report.load import ReportData, arch_label, param_values


def _fmt(value: Any, spec: str = ".4g") -> str:
    if value is None:
        return "–"
    try:
        f = float(value)
    except (TypeError, ValueError):
        return str(value)
    if not np.isfinite(f):
        return "–"
    return format(f, spec)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured markdown table."""
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)


def seed_table(data: ReportData) -> str:
    """Open-loop references and each architecture's run of the reported seed."""
    runs = data.ok_runs()
    runs = runs[runs["seed"] == data.seed]
    header = ["case", "Δv [km/s]", "miss [km]", "fuel penalty [%]", "re-solves",
              "success [%]", "infeasible", "failed", "solve mean / max [ms]"]  # fmt: skip
    rows = []
    for _, r in data.ref_summary.iterrows():
        rows.append([f"open-loop {str(r['arch']).removeprefix('open_loop_')}",
                     _fmt(r["delta_v_km_s"], ".7g"), _fmt(r["miss_km"], ".3g"),
                     _fmt(r.get("fuel_penalty_pct"), ".3f"), "", "", "", "", ""])  # fmt: skip
    for a in data.archs:
        g = runs[runs["arch"] == a]
        if g.empty:
            continue
        r = g.iloc[0]
        rows.append([
            arch_label(a), _fmt(r["delta_v_km_s"], ".7g"), _fmt(r["miss_km"], ".4g"),
            _fmt(r.get("fuel_penalty_pct"), ".3f"), _fmt(r.get("n_solves"), "g"),
            _fmt(r.get("solve_success_pct"), ".2f"), _fmt(r.get("n_infeasible"), "g"),
            _fmt(r.get("n_failed"), "g"),
            f"{_fmt(r.get('solve_mean_ms'), '.3g')} / {_fmt(r.get('solve_max_ms'), '.3g')}",
        ])  # fmt: skip
    return markdown_table(header, rows)


def campaign_table(data: ReportData) -> str:
    """Per architecture over the seeds of the reported point (failed runs counted)."""
    all_runs = data.runs
    if data.point is not None and "point" in all_runs.columns:
        all_runs = all_runs[all_runs["point"].astype(str) == data.point]
    header = ["architecture", "runs ok / failed", "mean Δv [km/s]", "mean miss [km]",
              "median miss [km]", "p95 miss [km]", "max miss [km]", "mean success [%]"]  # fmt: skip
    rows = []
    for a in data.archs:
        g = all_runs[all_runs["arch"] == a]
        ok = g[g["status"] == "ok"]
        miss = ok["miss_km"].astype(float)
        rows.append([
            arch_label(a), f"{len(ok)} / {len(g) - len(ok)}",
            _fmt(ok["delta_v_km_s"].mean()), _fmt(miss.mean()), _fmt(miss.median()),
            _fmt(miss.quantile(0.95) if len(miss) else None), _fmt(miss.max()),
            _fmt(ok["solve_success_pct"].mean() if "solve_success_pct" in ok else None, ".2f"),
        ])  # fmt: skip
    return markdown_table(header, rows)


def sweep_table(data: ReportData) -> str:
    """One row per grid point (all swept values) and architecture."""
    runs = data.runs[data.runs["status"] == "ok"].copy()
    keys: list[str] = []
    for param in data.params:
        runs[f"_{param}"] = param_values(runs[param])[0]
        keys.append(f"_{param}")
    header = [p.removeprefix(PARAM_PREFIX) for p in data.params] + [
        "architecture", "runs", "mean Δv [km/s]", "median miss [km]", "max miss [km]",
    ]  # fmt: skip
    rows = []
    order = {a: i for i, a in enumerate(data.archs)}
    for values, g in runs.groupby(keys, sort=True):
        values = values if isinstance(values, tuple) else (values,)
        for a, ga in sorted(g.groupby("arch"), key=lambda item: order.get(str(item[0]), 99)):
            rows.append([*(_fmt(v, "g") for v in values), arch_label(str(a)), str(len(ga)),
                         _fmt(ga["delta_v_km_s"].mean()), _fmt(ga["miss_km"].median()),
                         _fmt(ga["miss_km"].max())])  # fmt: skip
    return markdown_table(header, rows)


def report_md(data: ReportData, results_dir: Path, figures: Sequence[tuple[str, str]]) -> str:
    """The text of ``report.md``: provenance, notes, tables, then ``figures`` (file, caption)."""
    n_seeds = int(data.ok_runs()["seed"].nunique())
    lines = [
        "# cwrend report",
        "",
        f"Results: `{results_dir}` ({'`cwrend run` output' if data.layout == 'run' else 'campaign'}"
        + (f", config hash `{data.config_hash[:12]}`" if data.config_hash else "")
        + ").",
        f"Per-seed figures (1–5) show noise seed **{data.seed}**"
        + (f" at grid point `{data.point}`" if data.point else "")
        + (" (the first seed; choose another with `--seed N`)." if n_seeds > 1 else "."),
    ]
    if data.windows:
        wins = "; ".join(
            f"{i}: [{w.start_s:g}, {w.end_s:g}] s, {w.label}"
            for i, w in enumerate(data.windows, start=1)
        )
        lines.append(f"Degradation windows (shaded in the figures): {wins}.")
    lines += [f"{note}" for note in data.notes]
    lines += ["", f"## Noise seed {data.seed}", "", seed_table(data), ""]
    if n_seeds > 1:
        lines += [f"## Over {n_seeds} noise seeds", "", campaign_table(data), ""]
    if data.params:
        names = ", ".join(f"`{p.removeprefix(PARAM_PREFIX)}`" for p in data.params)
        lines += [f"## Sweep of {names} (every grid point)", "", sweep_table(data), ""]
    lines += ["## Figures", ""]
    for file, caption in figures:
        stem = Path(file).stem
        lines += [f"### {stem}", "", caption, "", f"![{stem}]({file})", ""]
    return "\n".join(lines)
