r"""Markdown tables of the docs' two 1,000-seed studies (model mismatch; shooting vs cone program).

    python -m benchmarks.study_tables mismatch IDEAL ACTUATOR OUTLIERS
    python -m benchmarks.study_tables methods ABLATION [--mean-hold SWEEP]
    python -m benchmarks.study_tables fallbacks SWEEP

Kept for the commands in the docs. ``mismatch`` and ``methods`` are built by
``cwrend table`` (:mod:`cwrend_cli.report.table`, the one place that builds
these tables from the stored statistics) with the options below;
``fallbacks`` reads the per-solve data, which no statistics file holds.

``mismatch``: three ``cwrend sweep campaigns/mismatch*.toml`` directories
(truth model × hold; ideal sensors and actuator, with actuator errors, with
outliers): per hold, the mean miss with its 95 % bootstrap interval for each
truth model × architecture (rows) and variant (columns), then the paired
share of seeds where MTF-adaptive misses less than plain-adaptive (Wilson
interval)::

    cwrend table "ideal sensors & actuator=IDEAL" \
      "+ actuator errors 1 %, 1° (1σ, per step)=ACTUATOR" \
      "+ 5 % outliers ×20 (nominal periods)=OUTLIERS" --where guidance.hold=mean \
      --rows truth.model=truth,arch --cols campaign --metric mean.miss
    cwrend table … (the same three) --where guidance.hold=mean,sample \
      --rows guidance.hold,truth.model=truth --cols campaign \
      --metric frac_less.miss@mtf_adaptive-plain_adaptive:2

``methods``: a ``cwrend ablate --arch everything`` directory (shooting and
cone-program architectures on the same seeds, hold sample) and, with
``--mean-hold``, the ``paper-1000`` sweep, whose shooting runs with
``hold = "mean"``, correct timing and the fallback chain line up as rows of
their own::

    cwrend table ABLATION SWEEP --where SWEEP:guidance.hold=mean \
      --where SWEEP:guidance.resolve_timing=correct --where SWEEP:solver.fallback=chain \
      --rows guidance.hold=hold,arch --metric n,mean.miss,median.miss,p95.miss:bare,mean.dv,\
    mean.fuel:bare:1,solve_mean_ms:bare,solve_max_ms:bare,infeasible_pct,failed_pct
    cwrend table ABLATION --rows "arch=cone program,other=vs shooting" \
      --where arch=plain_fixed_socp,mtf_fixed_socp,plain_adaptive_socp,mtf_adaptive_socp \
      --where other=plain_fixed,mtf_fixed,plain_adaptive,mtf_adaptive \
      --metric frac_less.miss,median_diff.miss,mean_diff.dv

The cone program against the *mean-hold* shooting runs pairs runs of two
campaigns, which no statistics file holds: with ``--mean-hold`` they are
computed here (:func:`cwrend_cli.campaign.statistics.paired` on the runs of
both). A campaign that stores them is a sweep over the hold with every
architecture (``cwrend sweep campaigns/paper.toml --seeds 1000 --arch
everything --param guidance.hold=sample,mean --set
guidance.resolve_timing='"correct"'``; the cone program ignores the hold),
whose pairs ``cwrend table`` shows with ``--rows guidance.hold,arch,other``.

``fallbacks``: any campaign directory (its ``solves/`` dataset): per grid
point and architecture, the re-solves that ended ``failed``, the runs whose
chain used the cone program's plan of last resort (``socp_plan``), and the
worst miss of those runs against the worst miss of the runs that never
needed it (the plan of last resort must not make a run an outlier).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.sweep_table import ARCH_ORDER
from cwrend_cli.campaign import statistics
from cwrend_cli.report import table

VARIANTS = (
    "ideal sensors & actuator",
    "+ actuator errors 1 %, 1° (1σ, per step)",
    "+ 5 % outliers ×20 (nominal periods)",
)
SOCP = tuple(f"{a}_socp" for a in ARCH_ORDER)
SOCP_PAIRS = tuple(zip(SOCP, ARCH_ORDER, strict=True))
MEAN_HOLD = "{}, hold mean"
METHODS = (
    "n,mean.miss,median.miss,p95.miss:bare,mean.dv,mean.fuel:bare:1,solve_mean_ms:bare,"
    "solve_max_ms:bare,infeasible_pct,failed_pct"
)
PAIRED = "frac_less.miss,median_diff.miss,mean_diff.dv"


def _values(text: str) -> list[table.Value]:
    return [table.parse_value(v) for v in text.split(",")]


def mismatch(dirs: Sequence[Path]) -> str:
    """The mismatch tables: truth × architecture rows, one column per variant, per hold."""
    sources = [table.load_source(f"{v}={d}") for v, d in zip(VARIANTS, dirs, strict=True)]
    parts = []
    for hold in ("mean", "sample"):
        built = table.build_table(
            sources, _values("mean.miss"), rows="truth.model=truth,arch", cols="campaign",
            where=[f"guidance.hold={hold}"],
            title=f'Mean miss [m] (95 % CI), `hold = "{hold}"`:',
        )  # fmt: skip
        parts.append(table.render(built, "md"))
    built = table.build_table(
        sources, _values("frac_less.miss@mtf_adaptive-plain_adaptive:2"),
        rows="guidance.hold,truth.model=truth", cols="campaign",
        where=["guidance.hold=mean,sample"],
        title="P(MTF-adaptive misses less than plain-adaptive) on the same seeds (95 % Wilson):",
    )  # fmt: skip
    parts.append(table.render(built, "md"))
    return "\n\n".join(parts)


def methods(ablation: Path, mean_hold: Path | None) -> str:
    """The shooting vs cone-program tables of an ``--arch everything`` ablation."""
    sources = [table.load_source(str(ablation))]
    where = []
    if mean_hold is not None:
        sweep = table.load_source(str(mean_hold))
        sources.append(sweep)
        settings = (
            "guidance.hold=mean",
            "guidance.resolve_timing=correct",
            "solver.fallback=chain",
        )
        where = [f"{sweep.label}:{k}" for k in settings]
    marginal = table.build_table(
        sources, _values(METHODS), rows="guidance.hold=hold,arch", where=where
    )
    paired = table.build_table(
        sources[:1], _values(PAIRED), rows="arch=cone program,other=vs shooting",
        where=[f"arch={','.join(SOCP)}", f"other={','.join(ARCH_ORDER)}"],
    )  # fmt: skip
    parts = [table.render(marginal, "md"), table.render(paired, "md")]
    if mean_hold is not None:
        parts.append(_mean_hold_pairs(ablation, mean_hold))
    return "\n\n".join(parts)


def _mean_hold_pairs(ablation: Path, sweep: Path) -> str:
    """Each cone-program architecture against its mean-hold shooting twin: runs of two
    campaigns, so computed here (no statistics file holds them; see the module's doc)."""
    runs = pd.read_parquet(ablation / "runs.parquet")
    other = pd.read_parquet(sweep / "runs.parquet")
    keep = (
        (other["param.guidance.hold"] == "mean")
        & (other["param.guidance.resolve_timing"] == "correct")
        & (other["param.solver.fallback"] == "chain")
        & other["seed"].isin(set(runs["seed"]))
    )
    extra = other[keep].copy()
    extra["arch"] = extra["arch"].map(MEAN_HOLD.format)
    runs = pd.concat([runs, extra[runs.columns.intersection(extra.columns)]])
    pairs = [(a, MEAN_HOLD.format(b)) for a, b in SOCP_PAIRS]
    frame = statistics.paired(runs, pairs=pairs)
    lines = [
        "| cone program | vs shooting | n | P(cone program misses less) (95 % Wilson) "
        "| median miss difference [m] (95 % CI) | mean Δv difference [km/s] (95 % CI) |",
        "|---|---|---|---|---|---|",
    ]
    for a, b in pairs:
        g = frame[(frame["arch"] == a) & (frame["other"] == b)].set_index("statistic")
        if g.empty:
            continue
        cells = [
            _ci(g.loc["frac_less"], 1.0, ".3f"),
            _ci(g.loc["median_diff"], 1e3, ".2f"),
            _ci(g.loc["mean_diff"], 1.0, ".5f"),
        ]
        lines.append(f"| {a} | {b} | {int(g['n'].iloc[0])} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _ci(row: pd.Series, scale: float, spec: str) -> str:
    v, lo, hi = (float(row[c]) * scale for c in ("value", "ci_low", "ci_high"))
    return f"{v:{spec}} [{lo:{spec}}, {hi:{spec}}]"


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
