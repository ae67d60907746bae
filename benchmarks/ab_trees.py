"""Campaign wall times of two checkouts of cwrend, interleaved in one run (by hand).

    git worktree add /tmp/before <rev>
    python -m benchmarks.ab_trees /tmp/before . [--reps 3]

"Did this change slow anything down?" is hard to answer from two benchmark
runs made minutes apart on a noisy 2-core machine (run-to-run differences of
±30 % were seen here). This runs the same ``cwrend ablate`` commands from both
source trees alternately (A B, then B A, …), each in a fresh process with
``PYTHONPATH`` pointing at its tree (its workers inherit it), and prints the
best wall time of each and their ratio. Both trees must hold the ``cwrend_cli``
package and share this interpreter's dependencies; their numba caches are
warmed first.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: (label, seeds, architectures, workers): 200 and 1,000 adaptive runs, the four-architecture
#: ablation (200 and 1,000 runs: issue 17's "≥ 5× the runs/s" is the difference between
#: the two, once started), and the README's paper ablation (one seed: one task, in-process).
CASES: tuple[tuple[str, int, str, int], ...] = (
    ("adaptive, 200 runs, 2 workers", 100, "plain_adaptive,mtf_adaptive", 2),
    ("adaptive, 1000 runs, 2 workers", 500, "plain_adaptive,mtf_adaptive", 2),
    ("four architectures, 200 runs, 2 workers", 50, "all", 2),
    ("four architectures, 1000 runs, 2 workers", 250, "all", 2),
    ("paper ablation, 1 seed", 1, "all", 2),
)


def wall_time(tree: Path, out: Path, seeds: int, archs: str, workers: int) -> float:
    """Seconds of one ``cwrend ablate`` of the paper scenario run from ``tree``."""
    paper = tree / "campaigns" / "paper.toml"
    cmd = [
        sys.executable, "-m", "cwrend_cli", "ablate", str(paper), "--seeds", str(seeds),
        "--arch", archs, "--workers", str(workers), "--no-rrd", "-q", "--force",
        "--set", f'output.dir="{out}"', "--name", "ab",
    ]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    # cwd outside both trees: `python -m` puts the working directory first on sys.path
    # (and spawned workers inherit it), so run from a tree it would shadow PYTHONPATH
    subprocess.run(
        cmd, env=env, cwd=out, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    return time.perf_counter() - start


def main() -> None:
    """Run every case from both trees, alternating their order, and print the ratios."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("before", type=Path, help="source tree of the baseline")
    parser.add_argument("after", type=Path, help="source tree of the change")
    parser.add_argument("--reps", type=int, default=3, help="repetitions of each case per tree")
    args = parser.parse_args()
    trees = {"before": args.before.resolve(), "after": args.after.resolve()}
    tmp = Path(tempfile.mkdtemp(prefix="cwrend-ab-"))
    for name, tree in trees.items():  # warm the numba caches of both trees
        wall_time(tree, tmp / name, 2, "all", 1)
    times: dict[tuple[str, str], list[float]] = {}
    for rep in range(args.reps):
        order = list(trees.items()) if rep % 2 == 0 else list(trees.items())[::-1]
        for label, seeds, archs, workers in CASES:
            for name, tree in order:
                t = wall_time(tree, tmp / name, seeds, archs, workers)
                times.setdefault((label, name), []).append(t)
    print(f"before: {trees['before']}\nafter:  {trees['after']}\n(best of {args.reps}, seconds)")
    for label, *_ in CASES:
        b, a = min(times[label, "before"]), min(times[label, "after"])
        print(f"  {label:42s} {b:7.2f}  {a:7.2f}  after/before {a / b:5.2f}")
    print("throughput once started, runs/s: (1000 − 200) / Δ(best wall time)")
    for kind in ("adaptive", "four architectures"):
        rates = {
            name: 800.0 / (min(times[f"{kind}, 1000 runs, 2 workers", name])
                           - min(times[f"{kind}, 200 runs, 2 workers", name]))
            for name in trees
        }  # fmt: skip
        print(
            f"  {kind:42s} {rates['before']:7.1f}  {rates['after']:7.1f}"
            f"  after/before {rates['after'] / rates['before']:5.2f}"
        )


if __name__ == "__main__":
    main()
