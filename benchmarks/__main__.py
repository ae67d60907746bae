"""All benchmarks in one run: ``python -m benchmarks`` (by hand, never in CI).

Prints one table (figure, value, the baseline measured in the same run and
the ratio, the target and whether it holds) beside the paper's published
MATLAB figures, and writes ``benchmarks/results.json`` (machine, versions,
every figure) so successive runs can be compared. Takes a few minutes on
2 cores; ``--quick`` uses fewer seeds and runs.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path

from rich import box
from rich.console import Console
from rich.table import Table

from benchmarks import (
    bench_campaign,
    bench_constrained,
    bench_convex,
    bench_sensors,
    bench_solver,
    bench_startup,
)
from benchmarks.common import PUBLISHED, Row

RESULTS = Path(__file__).resolve().parent / "results.json"


def print_rows(rows: list[Row]) -> None:
    """The benchmark table on the console."""
    table = Table(box=box.SIMPLE_HEAD, header_style="bold cyan", show_lines=False)
    for col, justify in (
        ("section", "left"),
        ("figure", "left"),
        ("value", "right"),
        ("baseline", "right"),
        ("ratio", "right"),
        ("target", "right"),
        ("", "left"),
    ):
        table.add_column(col, justify=justify, overflow="fold")
    for r in rows:
        verdict = {True: "[green]met[/green]", False: "[red]missed[/red]", None: ""}[r.met]
        table.add_row(
            r.section,
            r.name + (f"\n[dim]{r.note}[/dim]" if r.note else ""),
            f"{r.value:.4g} {r.unit}",
            f"{r.baseline:.4g} {r.unit}" if r.baseline is not None else "",
            _ratio(r.ratio),
            f"{r.target} {r.unit}" if r.target else "",
            verdict,
        )
    console = Console(width=max(Console().width, 120))
    console.print(table)
    console.print(
        "[bold]Published MATLAB figures[/bold] (Candan & Servadio, AAS 26-893; not measured here):"
    )
    for name, text in PUBLISHED.items():
        console.print(f"  {name}: {text}")


def _ratio(ratio: float | None) -> str:
    if ratio is None:
        return ""
    return f"{ratio:,.0f}×" if ratio >= 10 else f"{ratio:.2f}×"


def machine() -> dict[str, object]:
    """What the figures were measured on."""
    versions = {}
    for pkg in ("cwrend", "numpy", "scipy", "numba", "pyarrow", "clarabel", "distributed"):
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            versions[pkg] = None
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "versions": versions,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description="cwrend benchmarks")
    parser.add_argument("--quick", action="store_true", help="fewer seeds and runs")
    parser.add_argument("--out", type=Path, default=RESULTS, help="results JSON file")
    args = parser.parse_args()
    seeds, runs, big = (5, 100, 400) if args.quick else (20, 200, 2000)
    start = time.perf_counter()
    rows = (
        bench_startup.run(reps=5)  # first: fresh processes, before the machine warms up
        + bench_solver.run(seeds=seeds, naive=3)
        + bench_convex.run(seeds=seeds)
        + bench_sensors.run(seeds=seeds)
        + bench_constrained.run(seeds=seeds)
        + bench_campaign.run(runs=runs, big=big)
    )
    elapsed = time.perf_counter() - start
    print_rows(rows)
    report = {
        "measured_at": datetime.now(tz=UTC).isoformat(timespec="seconds"),
        "elapsed_s": elapsed,
        "settings": {"seeds": seeds, "runs": runs, "big": big},
        "machine": machine(),
        "published_matlab": PUBLISHED,
        "rows": [r.as_dict() for r in rows],
    }
    args.out.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    print(f"\n{len(rows)} figures in {elapsed:.0f} s → {args.out}")


if __name__ == "__main__":
    main()
