"""The constrained cone program beside the unconstrained one (issue 32).

Every re-solve of the closed loops of seeds 0…S−1 of each ``*_socp``
architecture in campaigns/safe_approach.toml (a keep-out sphere of 200 m and
a corridor to a port on the far side from x0): wall time (mean, p95, max) and
SCP iterations (the convex programs a re-solve solved: median, mean, max).
Baseline: the same architecture, seeds and scenario with ``[constraints]``
removed and ``scenario.xf`` the port at rest (what the corridor makes it), so
that the two differ only by the path constraints. Targets (issue 32): a
constrained re-solve ≤ 3× the unconstrained one, median SCP iterations ≤ 3.

Run alone: ``python -m benchmarks.bench_constrained [--seeds S]``.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from benchmarks.common import Row, seeds_main
from cwrend_cli import campaign
from cwrend_cli.config import ALL_ARCHITECTURES, ARCHITECTURES, CwrendConfig, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.config.io import load_config
from cwrend_cli.physics import simulation

SECTION = "constrained cone program"
CAMPAIGN = Path(__file__).resolve().parents[1] / "campaigns" / "safe_approach.toml"


def configs() -> tuple[CwrendConfig, CwrendConfig]:
    """(constrained, unconstrained twin) of campaigns/safe_approach.toml."""
    constrained = load_config(CAMPAIGN)
    data = tomllib.loads(CAMPAIGN.read_text(encoding="utf-8"))
    data.pop("constraints")
    data.setdefault("scenario", {})["xf"] = list(constrained.scenario.xf)
    return constrained, config_from_dict(data)


def _loops(cfg: CwrendConfig, slug: str, seeds: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Re-solve wall times [ms], SCP iterations and softened re-solves over the seeds."""
    problem = problem_of(cfg)
    refs = simulation.open_loop_references(problem)
    times: list[float] = []
    scp: list[int] = []
    softened = 0
    for seed in range(seeds):
        noise = campaign.standard_normal_for(cfg, seed)
        result = simulation.simulate(problem, ALL_ARCHITECTURES[slug], noise, refs, seed=seed)
        for s in result.resolves:
            times.append(s.wall_time_ms)
            scp.append(s.scp_iterations)
            softened += s.slack_km > 0.0
    return np.array(times), np.array(scp), softened


def run(seeds: int = 20, bases: tuple[str, ...] = tuple(ARCHITECTURES)) -> list[Row]:
    """Per ``*_socp`` architecture (of ``bases``, the shooting slugs): constrained re-solve
    time and SCP iterations."""
    constrained, free = configs()
    rows = []
    for base in bases:
        slug = f"{base}_socp"
        t, scp, softened = _loops(constrained, slug, seeds)
        t0, _, _ = _loops(free, slug, seeds)
        label = f"{slug}: constrained re-solve, seeds 0–{seeds - 1}"
        for stat, value, ref in (
            ("mean", t.mean(), t0.mean()),
            ("p95", np.percentile(t, 95), np.percentile(t0, 95)),
            ("max", t.max(), t0.max()),
        ):
            rows.append(
                Row(
                    SECTION,
                    f"{label}: {stat}",
                    float(value),
                    "ms",
                    baseline=float(ref),
                    target=f"<= {3.0 * ref:.3g}" if stat == "mean" else "",
                    note=f"{t.size} re-solves; baseline: unconstrained {stat}, target 3× it"
                    if stat == "mean"
                    else "",
                )
            )
        rows.append(
            Row(
                SECTION,
                f"{slug}: SCP iterations a re-solve, seeds 0–{seeds - 1}: median",
                float(np.median(scp)),
                "",
                target="<= 3",
                note=f"mean {scp.mean():.2f}, max {scp.max()}, histogram "
                f"{np.bincount(scp).tolist()}; {softened} softened (slack > 0)",
            )
        )
    return rows


def main() -> None:
    seeds_main(__doc__, run)


if __name__ == "__main__":
    main()
