"""Start-up of the ``cwrend`` command, by hand (issue 17: a CLI that answers at once).

    python -m benchmarks.bench_startup [--before TREE] [--reps 10]

Also part of ``python -m benchmarks`` (:func:`run`: median of 5, as rows).

Wall time (median of ``--reps`` fresh processes, interleaved) of ``cwrend --help``,
``cwrend ablate --help``, ``cwrend config validate campaigns/paper.toml`` and
``cwrend config show …``, each beside the baseline measured in the same run:
``python -c "import numba, pandas, scipy"`` (what every command paid before
the imports were made lazy) and, with ``--before``, the same commands run from
another source tree (e.g. ``git worktree add /tmp/before <rev>``). Prints
absolute figures and the ratios; targets from issue 17: ``--help`` ≤ 0.3 s and ≤ 20 % of
the heavy imports, ``config validate`` ≤ 0.6 s on a 2-core machine (its ≤ 20 % was
dropped by the team's decision on issue 17: no command validating with pydantic under
Typer reaches it). Beside them, the floor of ``config validate`` (:data:`FLOOR`: the
interpreter, Typer and the pydantic it coerces arguments with), which no command
validating with pydantic under this Typer can go below.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from benchmarks.common import Row

HERE = Path(__file__).resolve().parents[1]
PAPER = HERE / "campaigns" / "paper.toml"

#: (label, arguments of ``python -m cwrend_cli``, issue 17's target in seconds or None)
COMMANDS: tuple[tuple[str, tuple[str, ...], float | None], ...] = (
    ("cwrend --help", ("--help",), 0.3),
    ("cwrend ablate --help", ("ablate", "--help"), 0.3),
    ("cwrend config validate paper.toml", ("config", "validate", str(PAPER)), 0.6),
    ("cwrend config show paper.toml", ("config", "show", str(PAPER)), 0.6),
)
HEAVY = ("python -c 'import numba, pandas, scipy'", ("-c", "import numba, pandas, scipy"))
#: What ``config validate`` cannot avoid: the interpreter, Typer and the pydantic it
#: coerces every argument with (``typer._adapters``: a TypeAdapter per argument, whose
#: first build looks up pydantic's plugins, importing ``importlib.metadata``); what a
#: command costs beyond this is cwrend's own (its modules, the config models, the work).
FLOOR = (
    "python -c 'import typer._adapters; TypeAdapter(str)'",
    ("-c", "import typer, typer._adapters; from pydantic import TypeAdapter; TypeAdapter(str)"),
)


def wall_time(argv: list[str], tree: Path | None) -> float:
    """Seconds of one fresh ``python`` process (``PYTHONPATH`` = ``tree`` when given)."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = str(tree)
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, *argv], env=env, check=True, cwd=tree or HERE,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    return time.perf_counter() - start


def measure(reps: int, before: Path | None) -> dict[tuple[str, str], float]:
    """Median wall time of every command per tree, and of the heavy imports (interleaved)."""
    trees: dict[str, Path | None] = {"after": HERE}
    if before is not None:
        trees["before"] = before
    cases: list[tuple[tuple[str, str], list[str], Path | None]] = [
        ((HEAVY[0], ""), list(HEAVY[1]), None),
        ((FLOOR[0], ""), list(FLOOR[1]), None),
    ]
    for label, args, _ in COMMANDS:
        for name, tree in trees.items():
            cases.append(((label, name), ["-m", "cwrend_cli", *args], tree))
    for _, argv, tree in cases:  # warm the file cache (and numba's, for the old tree)
        wall_time(argv, tree)
    times: dict[tuple[str, str], list[float]] = {key: [] for key, _, _ in cases}
    for rep in range(reps):
        for key, argv, tree in cases if rep % 2 == 0 else cases[::-1]:
            times[key].append(wall_time(argv, tree))
    return {key: statistics.median(t) for key, t in times.items()}


def run(reps: int = 5) -> list[Row]:
    """The rows of ``python -m benchmarks``: each command beside the heavy imports, same run.

    Median of ``reps`` fresh processes per command; the ratio column is the
    heavy imports' time over the command's (issue 17: ≥ 5×, i.e. the command
    takes ≤ 20 % of them, for ``--help``; ``config`` has its ≤ 0.6 s alone).
    """
    from benchmarks.common import Row  # numpy and the campaign: not for the standalone script

    medians = measure(reps, None)
    heavy = medians[HEAVY[0], ""]
    floor = medians[FLOOR[0], ""]
    rows = [
        Row("start-up", HEAVY[0], heavy, "s", note="what every command paid before issue 17"),
        Row(
            "start-up",
            FLOOR[0],
            floor,
            "s",
            baseline=heavy,
            note=f"{floor / heavy:.0%} of the heavy imports: the floor of 'config validate'",
        ),
    ]
    for label, _, target in COMMANDS:
        now = medians[label, "after"]
        rows.append(
            Row(
                "start-up",
                label,
                now,
                "s",
                baseline=heavy,
                target=f"<= {target}" if target is not None else "",
                note=f"{now / heavy:.0%} of the heavy imports"
                + (" (≤ 20 %)" if "help" in label else "")
                + f"; median of {reps}",
            )
        )
    return rows


def main() -> None:
    """Measure and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", type=Path, help="source tree of the baseline (optional)")
    parser.add_argument("--reps", type=int, default=10, help="processes per command (median)")
    args = parser.parse_args()
    before = args.before.resolve() if args.before else None
    medians = measure(args.reps, before)
    heavy = medians[HEAVY[0], ""]
    print(f"median of {args.reps} fresh processes, {os.cpu_count()} cpus, seconds")
    print(f"  {HEAVY[0]:42s} {heavy:6.3f}")
    floor = medians[FLOOR[0], ""]
    print(f"  {FLOOR[0]:42s} {floor:6.3f}  {floor / heavy:6.0%}  (floor of config validate)")
    head = f"  {'command':42s} {'now':>6s}  {'/heavy':>6s}  target"
    print(head + (f"  {'before':>6s}  {'now/before':>10s}" if before else ""))
    for label, _, target in COMMANDS:
        now = medians[label, "after"]
        line = f"  {label:42s} {now:6.3f}  {now / heavy:6.0%}  ≤ {target:.1f} s"
        line += " met" if target is not None and now <= target else " missed"
        if before is not None:
            old = medians[label, "before"]
            line += f"  {old:6.3f}  {now / old:10.2f}"
        print(line)


if __name__ == "__main__":
    main()
