"""Markdown tables of the tumbling-target study (docs/results/tumbling.md).

    python scripts/tumbling_study_table.py results/tumbling_study [--by arch|rate]

Reads a campaign of campaigns/tumbling_study.toml: ``runs.parquet`` (one row per
run, its safety columns and the swept ``param.*`` values; for a campaign not yet
finished, the journal's finished runs) and ``solves/`` (every re-solve). One row
per tumble rate ‖ω(0)‖ and truth model, and with ``--by arch`` per architecture too:

* violations: runs whose true trajectory entered the turning unsafe set
  (``safety_violated``), with the 95 % Wilson interval
  (:func:`cwrend_cli.campaign.statistics.wilson_ci`);
* min distance: the smallest signed distance of any run to the turning unsafe set
  (negative: inside);
* the docking position and velocity errors relative to the moving port at T,
  median (max);
* Δv (the paper's trapezoid), mean;
* the re-solves: wall time mean (p95), SCP iterations mean (max), and the share that
  needed a path slack (no plan met every tightened row), were certified infeasible or
  failed.
"""

from __future__ import annotations

import argparse
import json
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from cwrend_cli.campaign.statistics import wilson_ci

RATES = "param.target.body_rates_deg_s"
TRUTH = "param.truth.model"


def _rate(value: Any) -> float:
    """‖ω(0)‖ [deg/s] of a swept rate vector (1 decimal; JSON text in ``runs.parquet``)."""
    value = json.loads(value) if isinstance(value, str) else value
    return round(float(np.linalg.norm(np.asarray(value, dtype=float))), 1)


def _key(row: dict[str, Any], by_arch: bool) -> tuple[Any, ...]:
    base = (_rate(row[RATES]), row.get(TRUTH, "cw"))
    return (*base, row["arch"]) if by_arch else base


def _fmt(value: float, digits: int = 2) -> str:
    return "–" if math.isnan(value) else f"{value:.{digits}f}"


def _runs(campaign: Path) -> list[dict[str, Any]]:
    """The runs of ``runs.parquet``, or, for a campaign still running or interrupted, of the
    journal's ``run_finished`` records (their metrics and swept values)."""
    if (campaign / "runs.parquet").exists():
        return list(pq.read_table(campaign / "runs.parquet").to_pylist())
    out = []
    with (campaign / "events.jsonl").open(encoding="utf-8") as journal:
        for line in journal:
            event = json.loads(line)
            if event["event"] == "run_finished":
                params = {f"param.{k}": v for k, v in event["params"].items()}
                out.append({**event["metrics"], **params, "run_key": event["run_key"],
                            "status": event["status"]})  # fmt: skip
    return out


def table(campaign: Path, by_arch: bool) -> str:
    """The markdown table of one campaign (module docstring)."""
    runs = _runs(campaign)
    solves = ds.dataset(campaign / "solves", format="parquet", partitioning="hive").to_table()
    keys = {r["run_key"]: _key(r, by_arch) for r in runs}
    cells: dict[tuple[Any, ...], list[dict[str, Any]]] = defaultdict(list)
    for r in runs:
        cells[keys[r["run_key"]]].append(r)
    resolves: dict[tuple[Any, ...], list[dict[str, Any]]] = defaultdict(list)
    for s in solves.to_pylist():
        if s["kind"] == "resolve" and s["run_key"] in keys:
            resolves[keys[s["run_key"]]].append(s)
    head = ["rate [°/s]", "truth"] + (["architecture"] if by_arch else [])
    head += ["runs", "violations [Wilson 95 %]", "min distance [m]", "dock position error [m]",
             "dock velocity error [mm/s]", "Δv [m/s]", "re-solve [ms]", "SCP iterations",
             "slack / infeasible / failed [%]"]  # fmt: skip
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key in sorted(cells):
        rs = [r for r in cells[key] if r["status"] == "ok"]
        n = len(rs)
        bad = sum(bool(r["safety_violated"]) for r in rs)
        lo, hi = wilson_ci(bad, n)
        dp = np.array([r["safety_dock_position_error_km"] for r in rs]) * 1e3
        dv = np.array([r["safety_dock_velocity_error_km_s"] for r in rs]) * 1e6
        delta_v = np.mean([r["delta_v_km_s"] for r in rs]) * 1e3
        ss = resolves[key]
        ms = np.array([s["wall_time_ms"] for s in ss])
        scp = np.array([s["scp_iterations"] for s in ss])
        slack = 100 * np.mean([s["slack_km"] > 0.0 for s in ss])
        infeasible = 100 * np.mean([s["status"] == "infeasible" for s in ss])
        failed = 100 * np.mean([s["status"] == "failed" for s in ss])
        cols = [f"{key[0]:g}", str(key[1])] + ([str(key[2])] if by_arch else [])
        cols += [
            str(n),
            f"{bad}/{n} [{lo:.2f}, {hi:.2f}]",
            _fmt(1e3 * min(r["safety_min_distance_km"] for r in rs), 1),
            f"{_fmt(float(np.median(dp)))} ({_fmt(float(dp.max()))})",
            f"{_fmt(float(np.median(dv)), 1)} ({_fmt(float(dv.max()), 1)})",
            _fmt(float(delta_v), 1),
            f"{ms.mean():.0f} ({np.percentile(ms, 95):.0f})",
            f"{scp.mean():.2f} ({scp.max()})",
            f"{slack:.1f} / {infeasible:.1f} / {failed:.1f}",
        ]
        lines.append("| " + " | ".join(cols) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("campaign", type=Path)
    parser.add_argument("--by", choices=("rate", "arch"), default="rate")
    args = parser.parse_args()
    print(table(args.campaign, args.by == "arch"))


if __name__ == "__main__":
    main()
