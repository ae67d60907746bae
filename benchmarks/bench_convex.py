"""The cone-program guidance method beside the shooting one (issue 16).

Sections, each figure with the shooting figure of the same run as baseline
(ratio = shooting / cone program, so below 1 means the cone program is slower):

1. one re-solve over the full 800 s horizon from x0 (N = 800 held controls),
   at ε = 0 (fixed architectures) and ε = 0.3, mean of repeated solves, target
   ≤ 10 ms; baseline: the shooting solve of the same problem warm-started from
   its own solution (a warm re-solve);
2. every re-solve of the closed loops of seeds 0…S−1 of each ``*_socp``
   architecture: mean, p95 and max wall time; baseline: the mean shooting
   re-solve of the same seeds' shooting architecture;
3. one closed-loop run per method (median of 5), shooting run as baseline.

Run alone: ``python -m benchmarks.bench_convex [--seeds S]``.
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.common import Row, seeds_main
from cwrend_cli import campaign
from cwrend_cli.config import ALL_ARCHITECTURES, ARCHITECTURES, CwrendConfig
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import guidance, simulation
from cwrend_cli.physics.guidance import convex, feasibility

SECTION = "cone program"


def _solver_of(eps: float) -> str:
    """Which solver answers a cone program at ``eps`` (convex module docstring)."""
    if max(eps, convex.REGULARISATION) >= convex.DUAL_MIN_WEIGHT:
        return "dual-ascent"
    return "screened interior-point"


def full_horizon(repeats: int = 20) -> list[Row]:
    """Section 1: the 800 s re-solve from x0, cone program vs warm shooting."""
    sc = problem_of(CwrendConfig()).scenario
    x0 = np.asarray(sc.x0, dtype=float)
    rows = []
    for eps in (0.0, 0.3):
        problem = guidance.ShootingProblem(x0, sc.horizon_s, eps, sc.mean_motion_rad_s,
                                           sc.u_max_km_s2)  # fmt: skip
        solved = guidance.solve(problem, guidance.energy_optimal_costate(problem))
        shoot, cone = [], []
        for _ in range(repeats):
            shoot.append(guidance.solve(problem, solved.costate).wall_time_s)
            start = time.perf_counter()
            g = feasibility.grid_problem(sc.mean_motion_rad_s, x0, np.zeros(6), sc.horizon_s,
                                         sc.dt_s, sc.u_max_km_s2)  # fmt: skip
            result = convex.solve(g, eps, sc.mean_motion_rad_s)
            cone.append(time.perf_counter() - start)
        rows.append(
            Row(
                SECTION,
                f"800 s re-solve from x0, ε = {eps:g} (N = 800, mean of {repeats})",
                float(np.mean(cone)) * 1e3,
                "ms",
                baseline=float(np.mean(shoot)) * 1e3,
                target="<= 10",
                note=f"{result.iterations} {_solver_of(eps)} iterations, residual "
                f"{result.residual_km:.1e} km; p95 {np.percentile(cone, 95) * 1e3:.1f} ms; "
                "baseline: warm shooting re-solve",
            )
        )
    return rows


def closed_loops(seeds: int) -> list[Row]:
    """Sections 2 and 3: re-solve times over seeds and one run per method."""
    cfg = CwrendConfig()
    problem = problem_of(cfg)
    refs = simulation.open_loop_references(problem)
    rows = []
    run_rows = []
    for slug in ARCHITECTURES:
        socp = ALL_ARCHITECTURES[f"{slug}_socp"]
        cone_ms: list[float] = []
        shoot_ms: list[float] = []
        statuses: dict[str, int] = {}
        for seed in range(seeds):
            noise = campaign.standard_normal_for(cfg, seed)
            for arch, sink in ((socp, cone_ms), (ARCHITECTURES[slug], shoot_ms)):
                result = simulation.simulate(problem, arch, noise, refs, seed=seed)
                for s in result.resolves:
                    sink.append(s.wall_time_ms)
                    if arch is socp:
                        statuses[s.status] = statuses.get(s.status, 0) + 1
        t = np.array(cone_ms)
        shoot_mean = float(np.mean(shoot_ms))
        label = f"{socp.slug}: re-solve, seeds 0–{seeds - 1}"
        note = f"statuses {statuses}; baseline: {slug} mean"
        rows.append(Row(SECTION, f"{label}: mean", float(t.mean()), "ms", shoot_mean, note=note))
        rows.append(Row(SECTION, f"{label}: p95", float(np.percentile(t, 95)), "ms"))
        shoot_max = float(np.max(shoot_ms))
        note = f"baseline: {slug} max"
        rows.append(Row(SECTION, f"{label}: max", float(t.max()), "ms", shoot_max, note=note))
        noise = campaign.standard_normal_for(cfg, 0)
        times = {}
        for arch in (socp, ARCHITECTURES[slug]):
            runs = []
            for _ in range(5):
                start = time.perf_counter()
                simulation.simulate(problem, arch, noise, refs)
                runs.append(time.perf_counter() - start)
            times[arch.slug] = float(np.median(runs)) * 1e3
        run_rows.append(
            Row(
                SECTION,
                f"{socp.slug}: one closed-loop run (median of 5)",
                times[socp.slug],
                "ms",
                baseline=times[slug],
                note=f"baseline: {slug}",
            )
        )
    return rows + run_rows


def run(seeds: int = 20) -> list[Row]:
    """All cone-program sections."""
    return [*full_horizon(), *closed_loops(seeds)]


def main() -> None:
    seeds_main(__doc__, run)


if __name__ == "__main__":
    main()
