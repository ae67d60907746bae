"""Markdown tables of a multi-seed sweep, as in the README's 1,000-seed section.

    python -m benchmarks.sweep_table results/paper-1000

Reads the campaign's ``sweep.parquet`` (statistics with 95 % bootstrap /
Wilson intervals, written by ``cwrend sweep``) and ``runs.parquet`` (for the
share of re-solves certified infeasible) and prints two tables: per grid
point and architecture the miss and Δv, and per grid point the paired
MTF-adaptive vs plain-adaptive comparison.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from cwrend_cli.output.tables import PARAM_PREFIX, param_columns

ARCH_ORDER = ("plain_fixed", "mtf_fixed", "plain_adaptive", "mtf_adaptive")


def _ci(value: float, lo: float, hi: float, scale: float, spec: str) -> str:
    return f"{value * scale:{spec}} [{lo * scale:{spec}}, {hi * scale:{spec}}]"


def tables(campaign: Path) -> str:
    """The two markdown tables of ``campaign`` (a ``cwrend sweep`` directory)."""
    stats = pd.read_parquet(campaign / "sweep.parquet")
    runs = pd.read_parquet(campaign / "runs.parquet")
    params = param_columns(stats.columns)
    names = [p.removeprefix(PARAM_PREFIX).split(".")[-1] for p in params]
    ok = runs[runs["status"] == "ok"]
    infeasible = ok.groupby([*params, "arch"], observed=True).apply(
        lambda g: g["n_infeasible"].sum() / g["n_solves"].sum(), include_groups=False
    )
    failed = ok.groupby([*params, "arch"], observed=True).apply(
        lambda g: g["n_failed"].sum() / g["n_solves"].sum(), include_groups=False
    )
    marg = stats[stats["kind"] == "marginal"]
    lines = [
        "| " + " | ".join(names) + " | architecture | n | mean miss [m] (95 % CI) | "
        "median miss [m] (95 % CI) | p95 miss [m] | mean Δv [km/s] (95 % CI) | "
        "re-solves infeasible | failed |",
        "|" + "---|" * (len(names) + 8),
    ]
    for keys, group in marg.groupby(params, sort=True, observed=True):
        keys = keys if isinstance(keys, tuple) else (keys,)
        for arch in ARCH_ORDER:
            g = group[group["arch"] == arch].set_index(["metric", "statistic"])
            if g.empty:
                continue

            def cell(metric: str, stat: str, scale: float, spec: str, g=g) -> str:
                r = g.loc[(metric, stat)]
                return _ci(r["value"], r["ci_low"], r["ci_high"], scale, spec)

            p95 = g.loc[("miss_km", "p95")]["value"] * 1e3
            lines.append(
                "| " + " | ".join(str(k) for k in keys) + f" | {arch} | "
                f"{int(g.loc[('miss_km', 'mean')]['n'])} | "
                f"{cell('miss_km', 'mean', 1e3, '.2f')} | "
                f"{cell('miss_km', 'median', 1e3, '.2f')} | {p95:.2f} | "
                f"{cell('delta_v_km_s', 'mean', 1.0, '.4f')} | "
                f"{100 * infeasible[(*keys, arch)]:.2f} % | {100 * failed[(*keys, arch)]:.2f} % |"
            )
    paired = stats[
        (stats["kind"] == "paired")
        & (stats["arch"] == "mtf_adaptive")
        & (stats["other"] == "plain_adaptive")
    ]
    lines += [
        "",
        "| " + " | ".join(names) + " | P(MTF-adaptive misses less than plain-adaptive) "
        "(95 % Wilson) | median miss difference [m] (95 % CI) |",
        "|" + "---|" * (len(names) + 2),
    ]
    for keys, group in paired.groupby(params, sort=True, observed=True):
        keys = keys if isinstance(keys, tuple) else (keys,)
        g = group.set_index("statistic")
        frac = g.loc["frac_less"]
        diff = g.loc["median_diff"]
        lines.append(
            "| " + " | ".join(str(k) for k in keys) + " | "
            f"{_ci(frac['value'], frac['ci_low'], frac['ci_high'], 1.0, '.3f')} | "
            f"{_ci(diff['value'], diff['ci_low'], diff['ci_high'], 1e3, '.2f')} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("campaign", type=Path, help="a cwrend sweep results directory")
    print(tables(parser.parse_args().campaign))


if __name__ == "__main__":
    main()
