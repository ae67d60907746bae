"""The constrained cone program beside the unconstrained one (issue 32).

Every re-solve of the closed loops of seeds 0…S−1 of each ``*_socp``
architecture in campaigns/safe_approach.toml (a keep-out sphere of 200 m and
a corridor to a port on the far side from x0): wall time (mean, p95, max) and
SCP iterations (the convex programs a re-solve solved: median, mean, max).
Baseline: the same architecture, seeds and scenario with ``[constraints]``
removed and ``scenario.xf`` the port at rest (what the corridor makes it), so
that the two differ only by the path constraints. Targets (issue 32): a
constrained re-solve ≤ 3× the unconstrained one, median SCP iterations ≤ 3.

Turning constraints (issue 34): the same per ``*_socp`` architecture on
campaigns/tumbling_target.toml (a bus and two panels, a corridor, a tumble of
about 2 °/s) over seeds 0…T−1, T = ``tumbling_seeds`` (a tumbling run takes
about ten times a fixed one's re-solve time), beside its fixed-target twin
(``[target]`` removed: the same bodies and corridor standing still, the same
seeds), so that the two differ only by the tumble.

With ``--abort-safe-s T`` both of the tumbling pair fly abort-safe for T (issue 34
item 4: the turning drift rows beside the fixed composite's).

Run alone: ``python -m benchmarks.bench_constrained [--seeds S] [--tumbling-seeds T]
[--abort-safe-s T]``.
"""

from __future__ import annotations

import argparse
import functools
import tomllib
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from benchmarks.common import Row
from cwrend_cli import campaign
from cwrend_cli.config import ALL_ARCHITECTURES, ARCHITECTURES, CwrendConfig, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.config.io import load_config
from cwrend_cli.physics import simulation
from cwrend_cli.physics.guidance import constrained

SECTION = "constrained cone program"
CAMPAIGN = Path(__file__).resolve().parents[1] / "campaigns" / "safe_approach.toml"
TUMBLING = CAMPAIGN.with_name("tumbling_target.toml")
TUMBLING_SECTION = "turning constraints (tumbling target)"


def configs() -> tuple[CwrendConfig, CwrendConfig]:
    """(constrained, unconstrained twin) of campaigns/safe_approach.toml."""
    constrained = load_config(CAMPAIGN)
    data = tomllib.loads(CAMPAIGN.read_text(encoding="utf-8"))
    data.pop("constraints")
    data.setdefault("scenario", {})["xf"] = list(constrained.scenario.xf)
    return constrained, config_from_dict(data)


def tumbling_configs(abort_safe_s: float | None = None) -> tuple[CwrendConfig, CwrendConfig]:
    """(tumbling, fixed-target twin) of campaigns/tumbling_target.toml, both with
    ``constraints.abort_safe_s`` = ``abort_safe_s`` when given (issue 34 item 4)."""
    data = tomllib.loads(TUMBLING.read_text(encoding="utf-8"))
    if abort_safe_s is not None:
        data["constraints"]["abort_safe_s"] = abort_safe_s
    twin = {k: v for k, v in data.items() if k != "target"}
    return config_from_dict(data), config_from_dict(twin)


class Loops(NamedTuple):
    """The re-solves of a set of closed loops: wall times [ms], SCP iterations, solver
    iterations and programs left to Clarabel of each, the softened re-solves, and (programs
    left by the dual solver to Clarabel, programs) counted from every constrained plan."""

    times: np.ndarray
    scp: np.ndarray
    iterations: np.ndarray
    fallbacks: np.ndarray
    softened: int
    counts: tuple[int, int]


#: A *typical* constrained re-solve: one SCP program, answered by the dual solver in at most
#: this many iterations (docs/solvers.md, where the mean goes) [-]; the others are the tail.
TYPICAL_ITERATIONS = 30


def _loops(cfg: CwrendConfig, slug: str, seeds: int) -> Loops:
    """The :class:`Loops` of ``slug`` over seeds 0 … ``seeds`` − 1 (the loops call
    ``constrained.plan``, wrapped here to count every plan's ``fallbacks`` and
    ``scp_iterations``)."""
    problem = problem_of(cfg)
    refs = simulation.open_loop_references(problem)
    times: list[float] = []
    scp: list[int] = []
    iterations: list[int] = []
    fallbacks: list[int] = []
    softened = 0
    counts = [0, 0]
    plan = constrained.plan

    @functools.wraps(plan)
    def counted(*args: Any, **kwargs: Any) -> constrained.ConstrainedPlan:
        out = plan(*args, **kwargs)
        counts[0] += out.fallbacks
        counts[1] += out.scp_iterations
        return out

    constrained.plan = counted
    try:
        for seed in range(seeds):
            noise = campaign.standard_normal_for(cfg, seed)
            result = simulation.simulate(problem, ALL_ARCHITECTURES[slug], noise, refs, seed=seed)
            for s in result.resolves:
                times.append(s.wall_time_ms)
                scp.append(s.scp_iterations)
                iterations.append(s.iterations)
                fallbacks.append(s.fallback_programs)
                softened += s.slack_km > 0.0
    finally:
        constrained.plan = plan
    return Loops(
        np.array(times), np.array(scp), np.array(iterations), np.array(fallbacks), softened,
        (counts[0], counts[1]),
    )  # fmt: skip


def run(
    seeds: int = 20,
    bases: tuple[str, ...] = tuple(ARCHITECTURES),
    tumbling_seeds: int | None = None,
    abort_safe_s: float | None = None,
) -> list[Row]:
    """Per ``*_socp`` architecture (of ``bases``, the shooting slugs): constrained re-solve
    time and SCP iterations, then the same on a tumbling target over ``tumbling_seeds``
    seeds (default ``seeds // 10``, at least 1); ``abort_safe_s``: the tumbling pair with
    abort safety for that long."""
    rows = _rows(SECTION, configs(), seeds, bases, "constrained", "unconstrained", 3.0)
    t_seeds = max(1, seeds // 10) if tumbling_seeds is None else tumbling_seeds
    what = "turning-constraint" + (
        "" if abort_safe_s is None else f", abort-safe {abort_safe_s:g} s"
    )
    return rows + _rows(TUMBLING_SECTION, tumbling_configs(abort_safe_s), t_seeds, bases, what,
                        "fixed-target constrained", None)  # fmt: skip


def _rows(
    section: str,
    pair: tuple[CwrendConfig, CwrendConfig],
    seeds: int,
    bases: tuple[str, ...],
    what: str,
    versus: str,
    factor: float | None,
) -> list[Row]:
    """Re-solve time (mean, p95, max; baseline: the same of ``pair[1]``) and SCP iterations
    of ``pair[0]``; a target of ``factor`` times the baseline's mean (None: no target).
    No seeds (``--tumbling-seeds 0``: the section left out): no rows."""
    if seeds < 1:
        return []
    measured, reference = pair
    rows = []
    for base in bases:
        slug = f"{base}_socp"
        loops = _loops(measured, slug, seeds)
        t, scp, softened = loops.times, loops.scp, loops.softened
        fallbacks, programs = loops.counts
        twin = _loops(reference, slug, seeds)
        t0, scp0 = twin.times, twin.scp
        label = f"{slug}: {what} re-solve, seeds 0–{seeds - 1}"
        for stat, value, ref in (
            ("mean", t.mean(), t0.mean()),
            ("p95", np.percentile(t, 95), np.percentile(t0, 95)),
            ("max", t.max(), t0.max()),
        ):
            target = f"<= {factor * ref:.3g}" if stat == "mean" and factor is not None else ""
            note = f"{t.size} re-solves; baseline: {versus} {stat}"
            rows.append(
                Row(
                    section,
                    f"{label}: {stat}",
                    float(value),
                    "ms",
                    baseline=float(ref),
                    target=target,
                    note=(f"{note}, target {factor:g}× it" if target else note)
                    if stat == "mean"
                    else "",
                )
            )
        if factor is not None:  # where the mean goes: the typical re-solve and the tail
            typical = (scp == 1) & (loops.fallbacks == 0) & (loops.iterations <= TYPICAL_ITERATIONS)
            left = loops.fallbacks > 0
            rows.append(
                Row(
                    section,
                    f"{label}: typical re-solve mean",
                    float(t[typical].mean()) if typical.any() else float("nan"),
                    "ms",
                    baseline=float(t0.mean()),
                    note=f"{int(typical.sum())} of {t.size} (one SCP program, none left to "
                    f"Clarabel, <= {TYPICAL_ITERATIONS} iterations); the others add "
                    f"{t[~typical].sum() / t.size:.3g} ms to the mean, those with a program "
                    f"left to Clarabel ({int(left.sum())}) {t[left].sum() / t.size:.3g} ms",
                )
            )
        # against the unconstrained loops (no SCP: 0 iterations) no baseline; against the
        # fixed target's constrained ones, theirs
        versus_scp = factor is None
        rows.append(
            Row(
                section,
                f"{slug}: SCP iterations a re-solve, seeds 0–{seeds - 1}: median",
                float(np.median(scp)),
                "",
                baseline=float(np.median(scp0)) if versus_scp else None,
                target="" if versus_scp else "<= 3",
                note=f"mean {scp.mean():.2f}"
                + (f" ({versus}: {scp0.mean():.2f})" if versus_scp else "")
                + f", max {scp.max()}, histogram {np.bincount(scp).tolist()}; "
                f"{softened} softened (slack > 0); {fallbacks} of {programs} programs "
                "left by the dual solver to Clarabel",
            )
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--tumbling-seeds", type=int, default=None)
    parser.add_argument("--arch", default=",".join(ARCHITECTURES), help="shooting slugs")
    parser.add_argument(
        "--abort-safe-s", type=float, default=None, help="tumbling pair with abort safety [s]"
    )
    args = parser.parse_args()
    from benchmarks.__main__ import print_rows

    print_rows(run(args.seeds, tuple(args.arch.split(",")), args.tumbling_seeds, args.abort_safe_s))


if __name__ == "__main__":
    main()
