"""Disk-full trials (issue 36, item 1): campaigns on a small tmpfs stop, then resume identically.

Not collected by pytest (it mounts file systems and takes minutes): run it as
root on Linux, from the repository, with the virtualenv active::

    python tests/disk_full_trials.py [--attempts 20] [--seeds 50] [--workers 2]

Each attempt mounts a tmpfs of 3-12 MB (spread over the attempts), runs
``cwrend ablate campaigns/paper.toml --seeds N --arch all --workers W
--rrd-seeds 1 --set output.seeds_per_task=2`` into it and requires exit 3
within ``--limit-s`` (30 s): the disk fills while steps files, the journal and
recordings are written. The tmpfs is then grown (remount, 1 GB) and the same
command run again: it must exit 0 with ``runs.parquet`` and ``ablation.parquet``
equal (wall times aside) to those of one campaign computed with room from the
start, and every recording the campaign owes. A command still running at
the limit is killed (its process group) and counted as a hang. Prints one line
per attempt and a summary; exits 1 if any attempt failed.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / "campaigns" / "paper.toml"
#: Columns of runs.parquet that hold wall times (they differ between identical runs).
TIMING = ("duration_s", "solve_mean_ms", "solve_max_ms", "wall_time_ms", "error")
ROOMY = "1g"


@dataclass(frozen=True)
class Attempt:
    """One trial: the tmpfs size, the first command's exit code and time, the rerun's verdict."""

    size_mb: int
    code: int | None  # None: killed at the limit (a hang)
    seconds: float
    verdict: str  # "ok" or what differed


def _command(out_dir: Path, seeds: int, workers: int) -> list[str]:
    return [
        sys.executable, "-m", "cwrend_cli", "ablate", str(CONFIG), "--seeds", str(seeds),
        "--arch", "all", "--workers", str(workers), "--rrd-seeds", "1", "-q",
        "--set", "output.seeds_per_task=2", "--set", f"output.dir={str(out_dir)!r}",
        "--set", "output.name='trial'",
    ]  # fmt: skip


def _run(command: list[str], limit_s: float) -> tuple[int | None, float, str]:
    """Exit code (None when killed at ``limit_s``), seconds taken and stderr of ``command``."""
    started = time.monotonic()
    proc = subprocess.Popen(
        command, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        start_new_session=True, text=True,
    )  # fmt: skip
    try:
        _, err = proc.communicate(timeout=limit_s)
        return proc.returncode, time.monotonic() - started, err
    except subprocess.TimeoutExpired:  # where it hangs: cwrend dumps its stacks on SIGUSR1
        os.kill(proc.pid, signal.SIGUSR1)
        time.sleep(2.0)
        os.killpg(proc.pid, signal.SIGKILL)
        _, err = proc.communicate()
        return None, time.monotonic() - started, err


Tables = tuple[pd.DataFrame, pd.DataFrame, list[str]]


def _tables(campaign: Path) -> Tables:
    runs = pd.read_parquet(campaign / "runs.parquet")
    runs = runs.drop(columns=[c for c in TIMING if c in runs.columns])
    runs = runs.sort_values("run_key").reset_index(drop=True)
    stats = pd.read_parquet(campaign / "ablation.parquet")
    stats = stats[~stats["metric"].isin(TIMING)].reset_index(drop=True)  # wall times differ
    recordings = sorted(p.name for p in (campaign / "recordings").glob("*.rrd"))
    return runs, stats, recordings


def _compare(campaign: Path, reference: Tables) -> str:
    runs, stats, recordings = _tables(campaign)
    if recordings != reference[2]:
        return f"recordings {recordings} != {reference[2]}"
    for name, got, want in (("runs", runs, reference[0]), ("ablation", stats, reference[1])):
        try:
            pd.testing.assert_frame_equal(got, want, check_exact=True)
        except AssertionError as exc:
            return f"{name}.parquet differs: {str(exc).splitlines()[0]}"
    return "ok"


def _mount(path: Path, size: str, remount: bool = False) -> None:
    options = f"remount,size={size}" if remount else f"size={size}"
    subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], check=True)


def _attempt(mount: Path, size_mb: int, args: argparse.Namespace, reference: Tables) -> Attempt:
    _mount(mount, f"{size_mb}m")
    try:
        command = _command(mount, args.seeds, args.workers)
        code, seconds, err = _run(command, args.limit_s)
        if code != 3:
            return Attempt(size_mb, code, seconds, f"expected exit 3: {err.strip()[-3000:]}")
        _mount(mount, ROOMY, remount=True)
        again, _, err = _run(command, args.rerun_limit_s)
        if again != 0:
            return Attempt(size_mb, code, seconds, f"rerun exit {again}: {err.strip()[-300:]}")
        return Attempt(size_mb, code, seconds, _compare(mount / "trial", reference))
    finally:
        subprocess.run(["umount", str(mount)], check=False)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--attempts", type=int, default=20)
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--min-mb", type=int, default=3)
    parser.add_argument("--max-mb", type=int, default=12)
    parser.add_argument("--limit-s", type=float, default=30.0, help="the stop's time limit")
    parser.add_argument("--rerun-limit-s", type=float, default=600.0)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="cwrend-disk-full-"))
    mount = work / "mnt"
    mount.mkdir()
    try:
        code, seconds, err = _run(_command(work, args.seeds, args.workers), args.rerun_limit_s)
        if code != 0:
            print(f"reference campaign failed (exit {code}): {err}", file=sys.stderr)
            return 1
        print(f"reference campaign: {seconds:.1f} s")
        reference = _tables(work / "trial")
        span = max(args.attempts - 1, 1)
        attempts = []
        for i in range(args.attempts):
            size = round(args.min_mb + (args.max_mb - args.min_mb) * i / span)
            attempt = _attempt(mount, size, args, reference)
            attempts.append(attempt)
            shown = "killed (hang)" if attempt.code is None else f"exit {attempt.code}"
            print(f"{size:3d} MB: {shown} after {attempt.seconds:5.1f} s; rerun: {attempt.verdict}")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    good = [a for a in attempts if a.code == 3 and a.verdict == "ok" and a.seconds <= args.limit_s]
    slowest = max(a.seconds for a in attempts)
    print(f"{len(good)} of {len(attempts)} attempts exited 3 within {args.limit_s:g} s and "
          f"resumed identically (slowest stop {slowest:.1f} s)")  # fmt: skip
    return 0 if len(good) == len(attempts) else 1


if __name__ == "__main__":
    sys.exit(main())
