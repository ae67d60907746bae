"""CPU time a run of each cell of the safe-approach study (issue 32), and the study's cost.

The study (docs/guide/safe-approach.md, *The safe-approach study*): on
campaigns/safe_approach.toml, with the CW and the two-body truths, the four
cone-program architectures constrained with ``constraints.sigma_margin`` 0 and
3, the same unconstrained (``constraints.enforce = false``: measure only, the
guidance of the config without ``[constraints]``) and the four shooting
architectures in the constrained config (measured on the truth, not
constrained). Each cell's runs of seeds 0…S−1 are timed in process CPU time
(``time.process_time``): the closed loop, the safety measurement on the truth
and the run's summary row, after one unmeasured run of the cell (compiled
kernels loaded; the references and the initial constrained plan made once per
cell, as a campaign's worker makes them once per point:
``simulate(initial_plans=…)``). A campaign's own cost (its files, statistics, recordings) comes on
top: docs/performance.md, *The safe-approach study*.

Run alone: ``python -m benchmarks.bench_safe_study [--seeds S]``.
"""

from __future__ import annotations

import argparse
import time
import tomllib
from typing import Any

import numpy as np

from benchmarks.bench_constrained import CAMPAIGN
from benchmarks.common import Row
from cwrend_cli import campaign
from cwrend_cli.campaign.worker import summary_row
from cwrend_cli.config import ALL_ARCHITECTURES, ARCHITECTURES, CwrendConfig, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import simulation

SECTION = "safe-approach study (CPU s a run)"
TRUTHS = ("cw", "two_body")
#: ``sigma_margin`` of the constrained cells; None: the unconstrained twin (measure only).
MARGINS: tuple[float | None, ...] = (0.0, 3.0, None)
#: Seeds of the study the estimate is for [-].
STUDY_SEEDS = 1000


def config(margin: float | None, truth: str) -> CwrendConfig:
    """campaigns/safe_approach.toml with ``sigma_margin`` = ``margin`` (None:
    ``constraints.enforce = false``, measure only) and ``truth.model`` = ``truth``."""
    data: dict[str, Any] = tomllib.loads(CAMPAIGN.read_text(encoding="utf-8"))
    if margin is None:
        data["constraints"]["enforce"] = False
    else:
        data["constraints"]["sigma_margin"] = margin
    data.setdefault("truth", {})["model"] = truth
    return config_from_dict(data)


def cells() -> list[tuple[str, float | None, str]]:
    """(architecture slug, margin, truth) of every cell of the study."""
    out: list[tuple[str, float | None, str]] = []
    for truth in TRUTHS:
        for base in ARCHITECTURES:
            out.append((base, 0.0, truth))
            out += [(f"{base}_socp", margin, truth) for margin in MARGINS]
    return out


def cell_seconds(slug: str, margin: float | None, truth: str, seeds: int) -> np.ndarray:
    """CPU seconds of each run of seeds 0…seeds−1 of one cell (module docstring)."""
    cfg = config(margin, truth)
    problem = problem_of(cfg)
    refs = simulation.open_loop_references(problem)
    arch = ALL_ARCHITECTURES[slug]
    plans: simulation.InitialPlans = {}
    out = []
    for seed in range(-1, seeds):  # seed −1: the unmeasured run (seed 0's noise)
        noise = campaign.standard_normal_for(cfg, max(seed, 0))
        start = time.process_time()
        result = simulation.simulate(
            problem, arch, noise, refs, seed=max(seed, 0), initial_plans=plans
        )
        summary_row(result, refs.fuel)
        if seed >= 0:
            out.append(time.process_time() - start)
    return np.array(out)


def run(seeds: int = 5) -> list[Row]:
    """One row per cell (mean CPU s a run; note: max), then the study's total for
    :data:`STUDY_SEEDS` seeds."""
    rows = []
    total = 0.0
    for slug, margin, truth in cells():
        t = cell_seconds(slug, margin, truth, seeds)
        total += float(t.mean())
        what = "unconstrained" if margin is None else f"sigma_margin {margin:g}"
        if not slug.endswith("_socp"):
            what = "shooting (measured, not constrained)"
        rows.append(
            Row(
                SECTION,
                f"{slug}, {what}, {truth} truth",
                float(t.mean()),
                "s",
                note=f"seeds 0–{seeds - 1}, max {t.max():.3f} s",
            )
        )
    runs = len(cells()) * STUDY_SEEDS
    rows.append(
        Row(
            SECTION,
            f"the study: {runs:,} runs, CPU",
            total * STUDY_SEEDS / 3600.0,
            "h",
            note=f"{total * STUDY_SEEDS / 7200.0:.2f} h on 2 cores (the runs alone)",
        )
    )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    from benchmarks.__main__ import print_rows

    print_rows(run(args.seeds))


if __name__ == "__main__":
    main()
