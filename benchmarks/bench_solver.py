"""Shooting-solver and closed-loop benchmark (run by hand, never in CI).

    python benchmarks/bench_solver.py [--seeds 20] [--naive 4]

Measures, in one run on this machine:

1. warm re-solves taken from closed loops of the paper scenario, at fixed
   ε ∈ {1, 0.3, 0.05, 0} (the fixed architecture with ``schedule.eps_fixed``),
   for cwrend's solver and for a naive SciPy baseline (solve_ivp of state +
   costate and ``least_squares`` with a finite-difference Jacobian, the way a
   straightforward port of the authors' fsolve + ode45 code works) on a
   handful of the same problems; prints medians and the ratio;
2. ε = 0 reliability: every re-solve of the four architectures over seeds
   0 … S−1 with the default fallback chain and with ``fallback = "none"``:
   share converged among the feasible ones, share flagged infeasible and
   where, mean and max time, which fallback step succeeded;
3. one 800-step closed-loop run per architecture after compilation (median);
4. the fixed-ε miss for both ``resolve_timing`` and both ``hold`` settings.

The published MATLAB figures (Candan & Servadio, AAS 26-893) are printed
beside ours for orientation; they were not measured here.
"""

from __future__ import annotations

import argparse
import platform
import time
from collections import Counter
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

from cwrend_cli import campaign, guidance, simulation
from cwrend_cli.config import ARCHITECTURES, CwrendConfig, config_from_dict, set_dotted
from cwrend_cli.dynamics import cw_system

PUBLISHED = {
    "mtf_adaptive": "54.89 ms mean / 163.61 ms max, 100 % success",
    "plain_adaptive": "324.18 ms mean / 2210.89 ms max, 67.95 % success",
}


@dataclass(frozen=True)
class Captured:
    problem: guidance.ShootingProblem
    guess: np.ndarray


def config_with(**dotted: object) -> CwrendConfig:
    data: dict = {}
    for key, value in dotted.items():
        data = set_dotted(data, key.replace("__", "."), value)
    return config_from_dict(data)


def capture_resolves(cfg: CwrendConfig, slug: str, seed: int) -> list[Captured]:
    """Re-solve problems (with their warm starts) met by one closed loop."""
    captured: list[Captured] = []
    original = guidance.solve

    def spy(problem, guess, settings=None):
        captured.append(Captured(problem, np.array(guess, dtype=float)))
        return original(problem, guess, settings)

    refs = simulation.open_loop_references(cfg)
    noise = campaign.standard_normal_for(cfg, seed)
    guidance.solve = spy
    try:
        simulation.simulate(cfg, ARCHITECTURES[slug], noise, refs, seed=seed)
    finally:
        guidance.solve = original
    return captured


def naive_solve(problem: guidance.ShootingProblem, guess: np.ndarray) -> tuple[float, bool]:
    """solve_ivp (state + costate) inside scipy least_squares with FD Jacobian."""
    a, b = cw_system(problem.mean_motion_rad_s)

    def rhs(_t, z):
        x, lam = z[:6], z[6:]
        u = guidance.control(lam[3:], problem.eps, problem.u_max_km_s2)
        return np.concatenate([a @ x + b @ u, -a.T @ lam])

    def residual(lam0):
        sol = solve_ivp(
            rhs, (0.0, problem.horizon_s), np.concatenate([problem.x0, lam0]),
            rtol=1e-10, atol=1e-13,
        )  # fmt: skip
        return sol.y[:6, -1] - problem.xf

    start = time.perf_counter()
    res = least_squares(residual, guess, method="lm", xtol=1e-14, ftol=1e-14, max_nfev=400)
    wall = time.perf_counter() - start
    ok = bool(np.linalg.norm(res.fun) < 1e-4)
    return wall, ok


def timed_solves(problems: list[Captured], settings: guidance.SolverSettings):
    times, statuses, steps, infeasible_t = [], [], [], []
    for c in problems:
        r = guidance.solve(c.problem, c.guess, settings)
        times.append(r.wall_time_s * 1e3)
        statuses.append(r.status.value)
        steps.append(r.step)
        if r.status is guidance.SolveStatus.INFEASIBLE:
            infeasible_t.append(800.0 - c.problem.horizon_s)
    return np.array(times), statuses, steps, infeasible_t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=20, help="seeds for the ε = 0 study")
    parser.add_argument("--naive", type=int, default=4, help="naive baseline solves per ε")
    args = parser.parse_args()
    print(
        f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}"
    )

    base = CwrendConfig()
    # warm compile
    campaign.run_case(base, tuple(ARCHITECTURES.values()), 0)
    settings = simulation.solver_settings(base)

    print("\n1. warm re-solves at fixed ε (fixed architecture, seed 0, paper scenario)")
    print(f"{'eps':>6} {'n':>4} {'median ms':>10} {'p95 ms':>8} {'max ms':>8} {'conv %':>7}"
          f" {'naive median ms':>16} {'naive ok':>9} {'speed-up':>9}")  # fmt: skip
    for eps in (1.0, 0.3, 0.05, 0.0):
        cfg = config_with(schedule__eps_fixed=eps)
        probs = [c for c in capture_resolves(cfg, "mtf_fixed", 0)]
        times, statuses, _, _ = timed_solves(probs, settings)
        conv = 100.0 * statuses.count("converged") / len(statuses)
        picks = probs[1 : 1 + args.naive]
        naive = [naive_solve(c.problem, c.guess) for c in picks]
        naive_med = float(np.median([t for t, _ in naive])) * 1e3
        n_ok = sum(ok for _, ok in naive)
        print(
            f"{eps:>6} {len(times):>4} {np.median(times):>10.3f} {np.percentile(times, 95):>8.3f}"
            f" {times.max():>8.3f} {conv:>7.1f} {naive_med:>16.1f} {n_ok:>5}/{len(naive):<3}"
            f" {naive_med / np.median(times):>8.0f}x"
        )

    print(f"\n2. every re-solve of each architecture, seeds 0..{args.seeds - 1}")
    problems = {
        slug: [p for seed in range(args.seeds) for p in capture_resolves(base, slug, seed)]
        for slug in ARCHITECTURES
    }
    for slug, fallback in [(s, f) for s in ARCHITECTURES for f in ("chain", "none")]:
        s = guidance.SolverSettings(**{**settings.__dict__, "fallback": fallback})
        all_t, all_status, all_steps, inf_t = timed_solves(problems[slug], s)
        counts = Counter(all_status)
        feasible = len(all_status) - counts["infeasible"]
        print(
            f"  {slug:<15} fallback={fallback:<5} solves {len(all_status)}:"
            f" converged {counts['converged']}"
            f" ({100 * counts['converged'] / feasible:.2f} % of feasible), infeasible"
            f" {counts['infeasible']} ({100 * counts['infeasible'] / len(all_status):.1f} %,"
            f" t in [{min(inf_t, default=np.nan):.0f}, {max(inf_t, default=np.nan):.0f}] s),"
            f" failed {counts['failed']}; mean {np.mean(all_t):.2f} ms, max {np.max(all_t):.2f} ms"
        )
        print(f"      step that ended each solve: {dict(Counter(all_steps))}")

    print("\n3. one closed-loop run (800 steps, after compilation), seed 0")
    refs = simulation.open_loop_references(base)
    noise = campaign.standard_normal_for(base, 0)
    for slug, arch in ARCHITECTURES.items():
        times = []
        for _ in range(7):
            start = time.perf_counter()
            simulation.simulate(base, arch, noise, refs)
            times.append(time.perf_counter() - start)
        published = PUBLISHED.get(slug, "")
        note = f"(published MATLAB re-solves: {published})" if published else ""
        print(f"  {slug:<15} median {1e3 * np.median(times):7.1f} ms   {note}")

    print(f"\n4. fixed-ε (ε = 0) miss and Δv over seeds 0..{args.seeds - 1} (mean, max)")
    for timing in ("correct", "reference"):
        for hold in ("sample", "mean"):
            cfg = config_with(guidance__resolve_timing=timing, guidance__hold=hold)
            refs = simulation.open_loop_references(cfg)
            miss, dv = [], []
            for seed in range(args.seeds):
                case = campaign.run_case(
                    cfg, (ARCHITECTURES["plain_fixed"], ARCHITECTURES["mtf_fixed"]), seed, refs
                )
                miss += [r.miss_km for r in case.runs]
                dv += [r.delta_v_km_s for r in case.runs]
            print(
                f"  timing={timing:<9} hold={hold:<6} miss mean {1e3 * np.mean(miss):7.1f} m,"
                f" max {1e3 * np.max(miss):7.1f} m; Δv mean {np.mean(dv):.4f} km/s"
                "   (paper: ≈160 m, Δv slightly < 0.1128)"
            )


if __name__ == "__main__":
    main()
