"""Markdown tables of a multi-seed sweep, as in the docs' 1,000-seed section.

    python -m benchmarks.sweep_table results/paper-1000

Kept for the commands in the docs; the tables are built by ``cwrend table``
(:mod:`cwrend_cli.report.table`, the one place that builds them), and these are
the two commands it runs (``<keys>``: the swept keys of the campaign)::

    cwrend table DIR --rows <keys>,arch \\
      --metric n,mean.miss,median.miss,p95.miss:bare,mean.dv,infeasible_pct,failed_pct
    cwrend table DIR --rows <keys> --metric frac_less.miss@mtf_adaptive-plain_adaptive,\\
    median_diff.miss@mtf_adaptive-plain_adaptive
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cwrend_cli.report import table

ARCH_ORDER = ("plain_fixed", "mtf_fixed", "plain_adaptive", "mtf_adaptive")
#: Per grid point and architecture: the runs, the miss and Δv with their intervals, the
#: shares of re-solves certified infeasible and failed.
PER_ARCH = "n,mean.miss,median.miss,p95.miss:bare,mean.dv,infeasible_pct,failed_pct"
#: Per grid point: MTF-adaptive against plain-adaptive on the same seeds.
PAIR = "@mtf_adaptive-plain_adaptive"
PAIRED = f"frac_less.miss{PAIR},median_diff.miss{PAIR}"


def tables(campaign: Path) -> str:
    """The two markdown tables of ``campaign`` (a ``cwrend sweep`` directory)."""
    source = table.load_source(str(campaign))
    keys = ",".join(source.swept)
    values = [table.parse_value(v) for v in PER_ARCH.split(",")]
    first = table.build_table([source], values, rows=f"{keys},arch")
    pairs = [table.parse_value(v) for v in PAIRED.split(",")]
    second = table.build_table([source], pairs, rows=keys)
    return table.render(first, "md") + "\n\n" + table.render(second, "md")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("campaign", type=Path, help="a cwrend sweep results directory")
    print(tables(parser.parse_args().campaign))


if __name__ == "__main__":
    main()
