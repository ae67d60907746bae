"""Run time per sensor model beside the position sensor (issue 35).

``python -m benchmarks.bench_sensors [--seeds N]``, or within ``python -m benchmarks``.

One closed loop of the paper scenario per seed and architecture, in this process
after a warm-up run of each (compilation excluded), for ``[sensor] model`` =
``position`` (the baseline), ``range_bearing`` and ``angles``: the extended
update's cost and that of the loop it steers (a different sensor gives
different re-solves, so the ratio is the whole run's, not the update's alone).
"""

from __future__ import annotations

import argparse
import time

from benchmarks.common import Row

MODELS = ("position", "range_bearing", "angles")
SLUGS = ("plain_adaptive", "mtf_adaptive", "stf_adaptive")


def time_per_run(model: str, seeds: int) -> float:
    """Mean in-process ``simulate`` time per run [s] of :data:`SLUGS` under ``model``."""
    from cwrend_cli import campaign
    from cwrend_cli.config import ALL_ARCHITECTURES, config_from_dict
    from cwrend_cli.config.adapt import problem_of
    from cwrend_cli.physics import simulation

    cfg = config_from_dict({"sensor": {"model": model}})
    problem = problem_of(cfg)
    refs = simulation.open_loop_references(problem)
    archs = [ALL_ARCHITECTURES[s] for s in SLUGS]
    for arch in archs:  # warm-up: compile (or load) the kernels of this sensor
        simulation.simulate(problem, arch, campaign.standard_normal_for(cfg, 0), refs, seed=0)
    total, n = 0.0, 0
    for seed in range(seeds):
        noise = campaign.standard_normal_for(cfg, seed)
        for arch in archs:
            start = time.perf_counter()
            simulation.simulate(problem, arch, noise, refs, seed=seed)
            total += time.perf_counter() - start
            n += 1
    return total / n


def run(seeds: int = 5) -> list[Row]:
    """One row per sensor model, the position sensor's time as the baseline."""
    times = {model: time_per_run(model, seeds) for model in MODELS}
    note = f"{', '.join(SLUGS)}; {seeds} seeds each, in-process, warm"
    return [
        Row(
            "sensors",
            f"run time, sensor {model}",
            1e3 * times[model],
            "ms",
            baseline=None if model == "position" else 1e3 * times["position"],
            note=note if model == "position" else "baseline: the position sensor",
        )
        for model in MODELS
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    from benchmarks.__main__ import print_rows

    print_rows(run(args.seeds))


if __name__ == "__main__":
    main()
