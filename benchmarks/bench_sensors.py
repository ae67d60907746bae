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
from collections.abc import Sequence

from benchmarks.bench_campaign import simulate_time_per_run
from benchmarks.common import Row

MODELS = ("position", "range_bearing", "angles")
SLUGS = ("plain_adaptive", "mtf_adaptive", "stf_adaptive")


#: Rounds the seeds are split into, the models interleaved in each (a loaded machine's
#: drift then falls on every model alike).
ROUNDS = 4


def time_per_run(model: str, seeds: Sequence[int]) -> float:
    """Mean in-process ``simulate`` time per run [s] of :data:`SLUGS` under ``model``."""
    from cwrend_cli.config import config_from_dict

    cfg = config_from_dict({"sensor": {"model": model}})
    return simulate_time_per_run(SLUGS, seeds, cfg)


def run(seeds: int = 20) -> list[Row]:
    """One row per sensor model, the position sensor's time as the baseline.

    The seeds in :data:`ROUNDS` rounds, each timing every model on its share of them.
    """
    per_round = max(seeds // ROUNDS, 1)
    times = dict.fromkeys(MODELS, 0.0)
    for r in range(ROUNDS):
        for model in MODELS:
            share = range(r * per_round, (r + 1) * per_round)
            times[model] += time_per_run(model, share) / ROUNDS
    note = f"{', '.join(SLUGS)}; {ROUNDS * per_round} seeds each, interleaved, in-process, warm"
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
    parser.add_argument("--seeds", type=int, default=20)
    args = parser.parse_args()
    from benchmarks.__main__ import print_rows

    print_rows(run(args.seeds))


if __name__ == "__main__":
    main()
