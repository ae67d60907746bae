"""Rich tables for the console (presentation only)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from rich.table import Table

from cwrend_cli.campaign import CaseResult
from cwrend_cli.storage import reference_row, summary_row


def _num(value: float, spec: str) -> str:
    return "–" if math.isnan(value) else f"{value:{spec}}"


def _solves(r: Mapping[str, Any]) -> str:
    if not r["n_solves"]:
        return "–"
    ok = r["n_converged"]
    text = f"{ok}/{r['n_solves']}"
    return text + (f" ({r['n_infeasible']} inf.)" if r["n_infeasible"] else "")


def summary_console_table(case: CaseResult, title: str = "") -> Table:
    """Compact table: one row per open-loop reference and closed-loop run."""
    fuel = case.references.fuel.delta_v_km_s
    rows = [reference_row(case.references.energy, fuel), reference_row(case.references.fuel, fuel)]
    rows += [summary_row(r, fuel) for r in case.runs]
    table = Table(title=title or None, title_style="bold", header_style="bold cyan")
    table.add_column("case", no_wrap=True, min_width=14)
    for name in ("seed", "Δv km/s", "miss km", "vs fuel", "converged", "solve ms"):
        table.add_column(name, justify="right", no_wrap=True)
    for r in rows:
        table.add_row(
            r["arch"].replace("open_loop_", "open-loop "),
            "–" if r["seed"] < 0 else str(r["seed"]),
            f"{r['delta_v_km_s']:.5f}",
            f"{r['miss_km']:.2e}",
            _num(r["fuel_penalty_pct"], "+.1f") + "%",
            _solves(r),
            f"{_num(r['solve_mean_ms'], '.2f')}/{_num(r['solve_max_ms'], '.1f')}",
        )
    table.caption = "solve ms: mean/max wall time per re-solve; inf.: certified infeasible"
    return table
