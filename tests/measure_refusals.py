"""Time and memory of refusing every input of issue 36 items 7-11, each in its own process.

    python tests/measure_refusals.py            # the cases of test_refusals and test_manifest
    python tests/measure_refusals.py --large    # also the issue's full-size inputs

The tests check what each refusal says and that it writes nothing, never how
fast it is (no test depends on the machine's speed); this script measures
that. Each case runs ``python -m cwrend_cli …`` in a fresh empty directory
(its results root inside) and reports the exit code, the wall time, the CPU
time (user + sys) and the peak resident memory of the process
(``os.wait4``), against the issue's bound: exit 2 within 2 s, under 500 MB.
The large inputs: a sparse 3 GiB noise file, a Parquet noise file of 10**8
rows (1.2 MB), a ``[sweep]`` of 38,000 keys (0.98 MB) and 85,000 unknown keys.
On a loaded machine the wall time exceeds the CPU time; the CPU time is what
the refusal costs.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import test_manifest  # noqa: E402  (the cases are the tests')
import test_refusals  # noqa: E402

Setup = Callable[[Path], list[str]]
LIMIT_S, LIMIT_MB = 2.0, 500.0


def _large_cases() -> dict[str, Setup]:
    paper = str(test_refusals.PAPER)

    def sparse_3g(d: Path) -> list[str]:
        path = d / "n.csv"
        path.write_text("n1,n2,n3\n0,0,0\n")
        os.truncate(path, 3 << 30)
        return ["ablate", paper, "--set", f"noise.file={str(path)!r}"]

    def parquet_bomb(d: Path) -> list[str]:
        path = d / "n.parquet"
        zeros = pa.array(np.zeros(1_000_000))
        table = pa.table({"n1": zeros, "n2": zeros, "n3": zeros})
        with pq.ParquetWriter(path, table.schema) as writer:
            for _ in range(100):
                writer.write_table(table)
        return ["ablate", paper, "--set", f"noise.file={str(path)!r}"]

    def sweep_keys(d: Path) -> list[str]:
        keys = "".join(f'"schedule.k{i}" = [1.0]\n' for i in range(38_000))
        return ["sweep", test_refusals._write(d / "wide.toml", "[sweep]\n" + keys)]

    def unknown_keys(d: Path) -> list[str]:
        keys = "".join(f"a{i}=1\n" for i in range(85_000))
        return ["ablate", test_refusals._write(d / "unknown.toml", "[schedule]\n" + keys)]

    return {
        "a sparse 3 GiB noise file": sparse_3g,
        "a Parquet noise file of 10**8 rows": parquet_bomb,
        "a [sweep] of 38,000 keys": sweep_keys,
        "85,000 unknown keys": unknown_keys,
    }


def _manifest_cases(campaign: tuple[Path, Path]) -> dict[str, Setup]:
    cases: dict[str, Setup] = {}
    for name, (content, _) in test_manifest.DAMAGED.items():
        for command in ("report", "compare", "ablate"):

            def setup(d: Path, content: bytes = content, command: str = command) -> list[str]:
                cfg, out = test_manifest._damaged_copy(campaign, d, content)
                return {
                    "report": ["report", str(out)],
                    "compare": ["compare", str(out), str(out)],
                    "ablate": test_manifest._args(cfg),
                }[command]

            cases[f"manifest {name}: {command}"] = setup
    return cases


def _campaign(root: Path) -> tuple[Path, Path]:
    """A finished one-run campaign (as test_manifest's fixture makes it)."""
    cfg = root / "c.toml"
    cfg.write_text(f'[output]\ndir = "{root / "results"}"\nname = "c"\nrrd_seeds = 0\n')
    subprocess.run([sys.executable, "-m", "cwrend_cli", *test_manifest._args(cfg)], check=True)
    return cfg, root / "results" / "c"


def measure(setup: Setup) -> tuple[int, float, float, float]:
    """Exit code, wall time [s], CPU time [s] and peak RSS [MB] of one refusal."""
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        args = setup(d)
        if args[0] in ("ablate", "sweep"):
            args += ["--set", f"output.dir={str(d / 'results')!r}"]
        started = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "cwrend_cli", *args],
            cwd=d,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - started
        proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--large", action="store_true", help="also the full-size inputs")
    options = parser.parse_args()
    cases: dict[str, Setup] = {name: setup for name, (setup, _) in test_refusals.CASES.items()}
    with tempfile.TemporaryDirectory() as tmp:
        cases |= _manifest_cases(_campaign(Path(tmp)))
        if options.large:
            cases |= _large_cases()
        print(f"{'case':<48} {'exit':>4} {'wall s':>7} {'cpu s':>6} {'peak MB':>8}  bound")
        missed = 0
        for name, setup in cases.items():
            code, wall, cpu, peak = measure(setup)
            ok = code == 2 and cpu <= LIMIT_S and peak <= LIMIT_MB
            missed += not ok
            print(f"{name[:48]:<48} {code:>4} {wall:>7.2f} {cpu:>6.2f} {peak:>8.0f}  "
                  f"{'met' if ok else 'MISSED'}")  # fmt: skip
    print(
        f"{len(cases) - missed} of {len(cases)} within exit 2, {LIMIT_S:g} s CPU, {LIMIT_MB:g} MB"
    )
    sys.exit(1 if missed else 0)


if __name__ == "__main__":
    main()
