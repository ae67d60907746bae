"""Shared pieces of the benchmarks: result rows, problem capture, the naive baseline."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

from cwrend_cli import campaign
from cwrend_cli.config import ARCHITECTURES, CwrendConfig, config_from_dict, set_dotted
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import guidance, simulation
from cwrend_cli.physics.dynamics import cw_system

#: Published MATLAB figures (Candan & Servadio, AAS 26-893), not measured here.
PUBLISHED = {
    "mtf_adaptive re-solve": "54.89 ms mean / 163.61 ms max, 100 % success",
    "plain_adaptive re-solve": "324.18 ms mean / 2210.89 ms max, 67.95 % success",
}


@dataclass
class Row:
    """One measured figure, with its baseline and target when it has them."""

    section: str
    name: str
    value: float
    unit: str
    baseline: float | None = None  # measured in the same run (e.g. the naive port)
    target: str = ""  # e.g. "<= 0.1"
    note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def ratio(self) -> float | None:
        """baseline / value (a speed-up when both are times)."""
        if self.baseline is None or self.value == 0:
            return None
        return self.baseline / self.value

    @property
    def met(self) -> bool | None:
        """Whether the target holds (None when there is none)."""
        if not self.target:
            return None
        op, bound = self.target.split()
        return self.value <= float(bound) if op == "<=" else self.value >= float(bound)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form, with the derived ratio and verdict."""
        return {**asdict(self), "ratio": self.ratio, "met": self.met}


def seeds_main(doc: str | None, run: Callable[[int], list[Row]]) -> None:
    """A benchmark module run alone: ``--seeds S`` (default 20), its rows printed."""
    parser = argparse.ArgumentParser(description=(doc or "").split("\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args()
    from benchmarks.__main__ import print_rows

    print_rows(run(args.seeds))


def interleaved(
    measure: Mapping[str, Callable[[range], float]], seeds: int, rounds: int
) -> dict[str, float]:
    """Mean of each ``measure[key](seeds share)`` over ``rounds`` rounds of the seeds 0…S−1.

    The seeds are split into ``rounds`` equal shares; each round times every
    variant on its share in turn (A B A B …), so a loaded machine's drift falls
    on every variant alike. Returns {key: mean over the rounds}.
    """
    per_round = max(seeds // rounds, 1)
    means = dict.fromkeys(measure, 0.0)
    for r in range(rounds):
        share = range(r * per_round, (r + 1) * per_round)
        for key, fn in measure.items():
            means[key] += fn(share) / rounds
    return means


#: A re-solve met in a closed loop, with its warm start (and the loop's second one).
Captured = simulation.ResolveInput


def config_with(**dotted: object) -> CwrendConfig:
    """The paper config with ``a__b=value`` overrides (dotted keys)."""
    data: dict = {}
    for key, value in dotted.items():
        data = set_dotted(data, key.replace("__", "."), value)
    return config_from_dict(data)


def capture_resolves(cfg: CwrendConfig, slug: str, seed: int) -> list[Captured]:
    """Re-solve problems (with the loop's warm starts) met by one closed loop."""
    captured: list[Captured] = []
    refs = simulation.open_loop_references(problem_of(cfg))
    noise = campaign.standard_normal_for(cfg, seed)
    simulation.simulate(
        problem_of(cfg), ARCHITECTURES[slug], noise, refs, seed=seed, observe=captured.append
    )
    return captured


def naive_solve(problem: guidance.ShootingProblem, guess: np.ndarray) -> tuple[float, bool]:
    """A straightforward SciPy port: solve_ivp of state + costate in least_squares (FD Jacobian).

    Returns (wall time [s], success with ‖x(T) − x_f‖ < 1e-4 as the re-solves count success).
    """
    a, b = cw_system(problem.mean_motion_rad_s)

    def rhs(_t, z):
        lam = z[6:]
        u = guidance.control(lam[3:], problem.eps, problem.u_max_km_s2)
        return np.concatenate([a @ z[:6] + b @ u, -a.T @ lam])

    def residual(lam0):
        z0 = np.concatenate([problem.x0, lam0])
        sol = solve_ivp(rhs, (0.0, problem.horizon_s), z0, rtol=1e-10, atol=1e-13)
        return sol.y[:6, -1] - problem.xf

    start = time.perf_counter()
    res = least_squares(residual, guess, method="lm", xtol=1e-14, ftol=1e-14, max_nfev=400)
    return time.perf_counter() - start, bool(np.linalg.norm(res.fun) < 1e-4)
