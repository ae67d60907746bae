"""Markdown tables of the README's two 1,000-seed studies (issues 15 and 16), from campaign results.

    python -m benchmarks.study_tables mismatch IDEAL ACTUATOR OUTLIERS
    python -m benchmarks.study_tables methods ABLATION [--mean-hold SWEEP]
    python -m benchmarks.study_tables fallbacks SWEEP

``mismatch``: three ``cwrend sweep campaigns/mismatch*.toml`` directories
(truth model × hold; ideal sensors and actuator, with actuator errors, with
outliers): per hold, the mean miss with its 95 % bootstrap interval for each
truth model × architecture × variant, then the paired share of seeds where
MTF-adaptive misses less than plain-adaptive (Wilson interval), all read
from each campaign's ``sweep.parquet``.

``methods``: a ``cwrend ablate --arch everything`` directory (shooting and
cone-program architectures on the same seeds, hold sample): per
architecture the miss, Δv, fuel penalty, re-solve time and statuses, then
each cone-program architecture against its shooting counterpart on the same
seeds (:func:`cwrend_cli.campaign.statistics.paired`). With ``--mean-hold``
(the README's ``paper-1000`` sweep) the shooting architectures with
``hold = "mean"``, correct timing and the fallback chain are added and
paired with the cone-program ones too (same seeds, hence the same noise).

``fallbacks``: any campaign directory (its ``solves/`` dataset): per grid
point and architecture, the re-solves that ended ``failed``, the runs whose
chain used the cone program's plan of last resort (``socp_plan``), and the
worst miss of those runs against the worst miss of the runs that never
needed it (issue 16's criterion: the plan of last resort must not make a
run an outlier).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.sweep_table import ARCH_ORDER, _ci
from cwrend_cli.campaign import statistics

VARIANTS = (
    "ideal sensors & actuator",
    "+ actuator errors 1 %, 1° (1σ, per step)",
    "+ 5 % outliers ×20 (nominal periods)",
)
TRUTHS = ("cw", "two_body", "j2")
SOCP_PAIRS = tuple((f"{a}_socp", a) for a in ARCH_ORDER)
MEAN_HOLD = "{}, hold mean"


def _stat(stats: pd.DataFrame, metric: str, statistic: str, scale: float, spec: str) -> str:
    row = stats[(stats["metric"] == metric) & (stats["statistic"] == statistic)]
    if row.empty:
        return "–"
    r = row.iloc[0]
    return _ci(r["value"], r["ci_low"], r["ci_high"], scale, spec)


def _point(sweep: pd.DataFrame, hold: str, truth: str, arch: str, kind: str) -> pd.DataFrame:
    """The statistics rows of one grid point (hold, truth model) and architecture."""
    return sweep[
        (sweep["param.guidance.hold"] == hold)
        & (sweep["param.truth.model"] == truth)
        & (sweep["arch"] == arch)
        & (sweep["kind"] == kind)
    ]


def mismatch(dirs: list[Path]) -> str:
    """The mismatch tables: hold × truth × architecture rows, one column per variant."""
    sweeps = [pd.read_parquet(d / "sweep.parquet") for d in dirs]
    lines: list[str] = []
    for hold in ("mean", "sample"):
        lines += [
            f'Mean miss [m] (95 % CI), `hold = "{hold}"`:',
            "",
            "| truth | architecture | " + " | ".join(VARIANTS) + " |",
            "|---|---|" + "---|" * len(VARIANTS),
        ]
        for truth in TRUTHS:
            for arch in ARCH_ORDER:
                cells = [
                    _stat(_point(s, hold, truth, arch, "marginal"), "miss_km", "mean", 1e3, ".2f")
                    for s in sweeps
                ]
                lines.append(f"| {truth} | {arch} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += [
        "P(MTF-adaptive misses less than plain-adaptive) on the same seeds (95 % Wilson):",
        "",
        "| hold | truth | " + " | ".join(VARIANTS) + " |",
        "|---|---|" + "---|" * len(VARIANTS),
    ]
    for hold in ("mean", "sample"):
        for truth in TRUTHS:
            cells = []
            for s in sweeps:
                g = _point(s, hold, truth, "mtf_adaptive", "paired")
                g = g[g["other"] == "plain_adaptive"]
                cells.append(_stat(g, "miss_km", "frac_less", 1.0, ".2f"))
            lines.append(f"| {hold} | {truth} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _mean_hold_runs(sweep: Path) -> pd.DataFrame:
    """The shooting runs of the ``paper-1000`` sweep with hold mean, correct timing, chain."""
    runs = pd.read_parquet(sweep / "runs.parquet")
    keep = (
        (runs["param.guidance.hold"] == "mean")
        & (runs["param.guidance.resolve_timing"] == "correct")
        & (runs["param.solver.fallback"] == "chain")
    )
    out = runs[keep].copy()
    out["arch"] = out["arch"].map(MEAN_HOLD.format)
    return out


def methods(ablation: Path, mean_hold: Path | None) -> str:
    """The shooting vs cone-program tables of an ``--arch everything`` ablation."""
    runs = pd.read_parquet(ablation / "runs.parquet")
    order = [*ARCH_ORDER, *(f"{a}_socp" for a in ARCH_ORDER)]
    pairs: list[tuple[str, str]] = list(SOCP_PAIRS)
    if mean_hold is not None:
        extra = _mean_hold_runs(mean_hold)
        seeds = set(runs["seed"])
        extra = extra[extra["seed"].isin(seeds)]
        runs = pd.concat([runs, extra[runs.columns.intersection(extra.columns)]])
        order += [MEAN_HOLD.format(a) for a in ARCH_ORDER]
        pairs += [(f"{a}_socp", MEAN_HOLD.format(a)) for a in ARCH_ORDER]
    stats = statistics.describe(runs, ["arch"])
    ok = runs[runs["status"] == "ok"]
    lines = [
        "| architecture | n | mean miss [m] (95 % CI) | median miss [m] (95 % CI) | p95 miss [m] "
        "| mean Δv [km/s] (95 % CI) | fuel penalty [%] | re-solve mean / max [ms] "
        "| infeasible | failed |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for arch in order:
        g = stats[(stats["arch"] == arch) & (stats["kind"] == "marginal")]
        r = ok[ok["arch"] == arch]
        if g.empty or r.empty:
            continue
        p95 = g[(g["metric"] == "miss_km") & (g["statistic"] == "p95")]["value"].iloc[0] * 1e3
        n_solves = r["n_solves"].sum()
        lines.append(
            f"| {arch} | {len(r)} | {_stat(g, 'miss_km', 'mean', 1e3, '.2f')} | "
            f"{_stat(g, 'miss_km', 'median', 1e3, '.2f')} | {p95:.2f} | "
            f"{_stat(g, 'delta_v_km_s', 'mean', 1.0, '.4f')} | "
            f"{r['fuel_penalty_pct'].mean():.1f} | "
            f"{r['solve_mean_ms'].mean():.2f} / {r['solve_max_ms'].max():.1f} | "
            f"{100 * r['n_infeasible'].sum() / n_solves:.2f} % | "
            f"{100 * r['n_failed'].sum() / n_solves:.2f} % |"
        )
    paired = statistics.paired(runs, pairs=pairs)
    lines += [
        "",
        "| cone program | vs shooting | n | P(cone program misses less) (95 % Wilson) "
        "| median miss difference [m] (95 % CI) | mean Δv difference [km/s] (95 % CI) |",
        "|---|---|---|---|---|---|",
    ]
    for a, b in pairs:
        g = paired[(paired["arch"] == a) & (paired["other"] == b)]
        if g.empty:
            continue
        lines.append(
            f"| {a} | {b} | {int(g['n'].iloc[0])} | "
            f"{_stat(g, 'miss_km', 'frac_less', 1.0, '.3f')} | "
            f"{_stat(g, 'miss_km', 'median_diff', 1e3, '.2f')} | "
            f"{_stat(g, 'delta_v_km_s', 'mean_diff', 1.0, '.5f')} |"
        )
    return "\n".join(lines)


def fallbacks(campaign: Path) -> str:
    """Failed re-solves and runs rescued by ``socp_plan``, per grid point and architecture."""
    runs = pd.read_parquet(campaign / "runs.parquet")
    solves = pd.read_parquet(campaign / "solves", columns=["run_key", "status", "fallback_step"])
    rescued = set(solves.loc[solves["fallback_step"] == "socp_plan", "run_key"])
    failed = solves[solves["status"] == "failed"].groupby("run_key").size()
    params = [c for c in runs.columns if c.startswith("param.")]
    names = [c.removeprefix("param.").split(".")[-1] for c in params]
    runs = runs[runs["status"] == "ok"].assign(
        rescued=lambda r: r["run_key"].isin(rescued),
        n_failed_solves=lambda r: r["run_key"].map(failed).fillna(0).astype(int),
    )
    lead = "".join(f"| {n} " for n in names)
    lines = [
        lead + "| architecture | runs | failed re-solves | runs using "
        "socp_plan | worst miss, those runs [m] | worst miss, the others [m] |",
        "|" + "---|" * (len(names) + 6),
    ]
    for keys, group in runs.groupby([*params, "arch"], sort=True, observed=True):
        keys = keys if isinstance(keys, tuple) else (keys,)
        used = group[group["rescued"]]
        others = group[~group["rescued"]]
        worst_used = f"{1e3 * used['miss_km'].max():.2f}" if len(used) else "–"
        worst_others = f"{1e3 * others['miss_km'].max():.2f}" if len(others) else "–"
        lines.append(
            "".join(f"| {k} " for k in keys) + f"| {len(group)} | "
            f"{int(group['n_failed_solves'].sum())} | {len(used)} | {worst_used} | {worst_others} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="study", required=True)
    mm = sub.add_parser("mismatch", help="issue 15: truth models, actuator errors, outliers")
    mm.add_argument("dirs", type=Path, nargs=3, metavar="DIR")
    me = sub.add_parser("methods", help="issue 16: shooting vs cone-program guidance")
    me.add_argument("ablation", type=Path)
    me.add_argument("--mean-hold", type=Path, default=None)
    fb = sub.add_parser("fallbacks", help="issue 16: failed re-solves and socp_plan rescues")
    fb.add_argument("campaign", type=Path)
    args = parser.parse_args()
    np.seterr(all="ignore")
    if args.study == "mismatch":
        print(mismatch(args.dirs))
    elif args.study == "methods":
        print(methods(args.ablation, args.mean_hold))
    else:
        print(fallbacks(args.campaign))


if __name__ == "__main__":
    main()
