"""Ctrl-C keeps every finished run, not only whole tasks (issue 37 item 2).

A task of many seeds stopped by Ctrl-C returns the runs it finished (their
files written, the run in progress dropped) and the driver journals them; the
progress bar and the summary end on what the journal holds, which is exactly
what a resume skips. Each interruption lands at a state of the campaign (a
run finished), never after a time.
"""

from __future__ import annotations

import ctypes
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from hooked_cwrend import HANG_S, HOOKED, wait_stopped
from typer.testing import CliRunner

from cwrend_cli import campaign, teardown
from cwrend_cli.cli import app
from cwrend_cli.config import load_config
from cwrend_cli.physics import simulation

runner = CliRunner()
ADAPTIVE = ["mtf_adaptive", "plain_adaptive"]  # the fast architectures


def _config(tmp_path: Path, name: str) -> Path:
    path = tmp_path / f"{name}.toml"
    results = tmp_path / "results"
    path.write_text(f'[output]\ndir = "{results}"\nname = "{name}"\nseeds_per_task = 8\n')
    return path


class _CtrlCAfter:
    """A progress that raises Ctrl-C when it hears the ``n``-th run finish (once)."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.advanced = 0

    def start(self, total: int, skipped: int) -> None:
        pass

    def advance(self, ok: int, failed: int) -> None:
        self.advanced += ok + failed
        if self.n and self.advanced >= self.n:
            self.n = 0
            raise KeyboardInterrupt

    def close(self) -> None:
        pass


def test_ctrl_c_in_a_task_keeps_the_runs_it_finished(tmp_path: Path) -> None:
    """In-process: one task of 16 runs, Ctrl-C after its third run: three runs are kept,
    the bar ends at three, and the resume computes the other 13 to the same numbers."""
    plan_ = campaign.plan(load_config(_config(tmp_path, "c")), ADAPTIVE, list(range(8)))
    assert len(plan_.tasks) == 1 and len(plan_.runs) == 16
    out = tmp_path / "results" / "c"
    progress = _CtrlCAfter(3)
    summary = campaign.run_campaign(plan_, out, command="ablate", workers=1, progress=progress)
    assert summary.interrupted
    assert summary.executed == 3 and progress.advanced == 3
    assert len(pd.read_parquet(out / "runs.parquet")) == 3
    resumed = campaign.run_campaign(plan_, out, command="ablate", workers=1)
    assert (resumed.skipped, resumed.executed) == (3, 13)
    whole = tmp_path / "results" / "whole"
    campaign.run_campaign(plan_, whole, command="ablate", workers=1)
    pd.testing.assert_frame_equal(_runs(out), _runs(whole))
    steps = pd.read_parquet(out / "steps").sort_values(["run_key", "step"], ignore_index=True)
    expected = pd.read_parquet(whole / "steps").sort_values(["run_key", "step"], ignore_index=True)
    pd.testing.assert_frame_equal(steps, expected, check_exact=True)  # no duplicate, no gap


def test_a_ctrl_c_a_library_turns_into_an_error_drops_the_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """In-process, Ctrl-C during the third run, which the code it lands in turns into an
    error: the run is dropped, never recorded failed, and the campaign stops with two runs."""
    real = simulation.simulate
    calls: list[int] = []

    def simulate(*args: Any, **kwargs: Any) -> Any:
        calls.append(1)
        if len(calls) == 3:
            try:
                signal.raise_signal(signal.SIGINT)  # Ctrl-C, handled before this returns
            except KeyboardInterrupt as exc:
                raise RuntimeError("a library's own error") from exc
        return real(*args, **kwargs)

    monkeypatch.setattr(simulation, "simulate", simulate)
    plan_ = campaign.plan(load_config(_config(tmp_path, "lib")), ADAPTIVE, list(range(8)))
    out = tmp_path / "results" / "lib"
    summary = campaign.run_campaign(plan_, out, command="ablate", workers=1)
    assert summary.interrupted
    assert (summary.executed, summary.failed) == (2, 0)
    assert set(pd.read_parquet(out / "runs.parquet")["status"]) == {"ok"}
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored


def test_a_stop_that_lands_in_a_compiled_callback_is_owed_not_printed(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """numba's compiler calls Python through ctypes, which can only print an exception: the
    stop's KeyboardInterrupt landing there prints nothing and is owed (raised again)."""

    def callback() -> None:
        raise KeyboardInterrupt

    owed: list[float] = []
    call = ctypes.CFUNCTYPE(None)(callback)
    monkeypatch.setattr(sys, "unraisablehook", teardown.unraisable_stop)
    monkeypatch.setattr(teardown, "redeliver", owed.append)  # not raised in pytest itself
    monkeypatch.setattr(teardown, "_RECEIVED", [signal.SIGINT])
    call()
    assert capsys.readouterr().err == "" and owed == [teardown.REDELIVER_S]
    teardown.clear_stop()  # not a stop's: printed as usual
    call()
    assert "KeyboardInterrupt" in capsys.readouterr().err and len(owed) == 1


def _runs(out: Path) -> pd.DataFrame:
    """``runs.parquet`` without its wall-time columns (they differ between equal runs)."""
    runs = pd.read_parquet(out / "runs.parquet")
    timing = ("duration_s", "solve_mean_ms", "solve_max_ms", "wall_time_ms")
    return runs.drop(columns=[c for c in timing if c in runs.columns])


def _sigint_default() -> None:
    """In the child: SIGINT at its default, as in a terminal (see test_campaign)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _hooked(when: str, n: int, sig: str, *args: str) -> subprocess.CompletedProcess[str]:
    """``cwrend *args`` sending ``sig`` at its ``n``-th state ``when``, run to its end."""
    return subprocess.run(
        [sys.executable, str(HOOKED), when, str(n), sig, *args],
        capture_output=True, text=True, timeout=HANG_S, start_new_session=True,
        preexec_fn=_sigint_default,
    )  # fmt: skip


def test_ctrl_c_to_a_pool_keeps_the_finished_runs_the_summary_counts(tmp_path: Path) -> None:
    """Two workers, two tasks of 16 runs; Ctrl-C to the process group when the first run
    finishes: the summary's done count is > 0 and is exactly what the resume skips."""
    cfg = _config(tmp_path, "pool")
    args = ["ablate", str(cfg), "--seeds", "16", "--arch", ",".join(ADAPTIVE), "--no-rrd"]
    proc = _hooked("run", 1, "SIGINT", *args, "--workers", "2")
    assert proc.returncode == 130, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    found = re.search(r"interrupted: (\d+) of 32 runs done \((\d+) computed now\)", proc.stderr)
    assert found, proc.stderr
    done = int(found[1])
    assert done > 0 and int(found[2]) == done
    # out at once: the statistics are written when the campaign completes
    assert "run the same command to resume (and to write the statistics)" in proc.stderr
    assert not (tmp_path / "results" / "pool" / "ablation.parquet").exists()
    resumed = runner.invoke(app, [*args, "--workers", "1"])
    assert resumed.exit_code == 0, resumed.output
    assert f"{32 - done} run(s) computed, {done} already done" in resumed.stderr


def test_a_stopped_pool_leaves_no_file_of_a_run_it_did_not_keep(tmp_path: Path) -> None:
    """The files a stopped execution wrote name only the runs it journaled."""
    cfg = _config(tmp_path, "files")
    args = ["ablate", str(cfg), "--seeds", "16", "--arch", ",".join(ADAPTIVE), "--no-rrd", "-q"]
    proc = _hooked("run", 3, "SIGINT", *args, "--workers", "2")
    assert proc.returncode == 130, proc.stderr
    out = tmp_path / "results" / "files"
    kept = set(pd.read_parquet(out / "runs.parquet")["run_key"])
    assert kept
    assert set(pd.read_parquet(out / "solves")["run_key"]) == kept
    steps = pd.read_parquet(out / "steps")
    assert set(steps["run_key"]) == kept and len(steps) == len(kept) * 801
    assert os.listdir(out / "steps")  # the data were written, not only journaled


# --- signals (issue 36 item 12) ------------------------------------------------


def _workers(pid: int) -> list[int]:
    """The pool workers (spawned children) of process ``pid``."""
    kids = []
    for entry in Path("/proc").iterdir():
        try:
            if not entry.name.isdigit() or "spawn_main" not in (entry / "cmdline").read_text():
                continue
            if int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                kids.append(int(entry.name))
        except OSError:  # gone meanwhile
            continue
    return kids


def _when_importing(pid: int) -> None:
    """Stop process ``pid`` as soon as it has loaded numpy (it is importing cwrend's modules)."""
    maps = Path(f"/proc/{pid}/maps")
    hang = time.monotonic() + HANG_S
    while "_multiarray_umath" not in maps.read_text():
        assert time.monotonic() < hang, f"worker {pid} never loaded numpy"
        time.sleep(0.001)
    os.kill(pid, signal.SIGSTOP)


def _wait_handled(pid: int, signum: int) -> None:
    """Wait until process ``pid`` has ended or handles ``signum`` and holds none pending."""
    bit = 1 << (signum - 1)
    hang = time.monotonic() + HANG_S
    while time.monotonic() < hang:
        try:
            fields = dict(
                line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines()
            )
        except OSError:  # reaped: it ended
            return
        if fields["State"].strip().startswith(("Z", "X")):
            return
        pending = int(fields["SigPnd"], 16) | int(fields["ShdPnd"], 16)
        if int(fields["SigCgt"], 16) & bit and not pending & bit:
            return
        time.sleep(0.005)
    raise AssertionError(f"process {pid} neither ended nor handled signal {signum}")


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs Linux /proc")
def test_ctrl_c_while_the_workers_import_prints_no_traceback(tmp_path: Path) -> None:
    """Ctrl-C to the process group while the pool's workers import their modules (each frozen
    there, then let go with the Ctrl-C pending): exit 130, no worker prints a traceback."""
    args = ["ablate", str(_config(tmp_path, "early")), "--seeds", "16", "--arch",
            ",".join(ADAPTIVE), "--no-rrd", "--workers", "2"]  # fmt: skip
    proc = subprocess.Popen(
        [sys.executable, str(HOOKED), "pool", "1", "SIGSTOP", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        preexec_fn=_sigint_default,
    )  # fmt: skip
    try:
        wait_stopped(proc, poll_s=0.001)  # at its state: the pool's two workers started
        hang = time.monotonic() + HANG_S
        while len(workers := _workers(proc.pid)) < 2:  # each runs Python once it is exec'd
            assert time.monotonic() < hang, "the pool's workers never ran"
            time.sleep(0.001)
        for pid in workers:
            _when_importing(pid)
        os.killpg(proc.pid, signal.SIGINT)  # pending in every process, all stopped
        for pid in workers:  # each handles it before the campaign goes on and stops them
            os.kill(pid, signal.SIGCONT)
            _wait_handled(pid, signal.SIGINT)
        os.kill(proc.pid, signal.SIGCONT)
        _, stderr = proc.communicate(timeout=HANG_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    assert "interrupted: 0 of 32 runs done" in stderr


@pytest.mark.parametrize(
    ("sig", "code"), [("SIGTERM:self", 143), ("SIGHUP", 129), ("SIGINT:self", 130)]
)
def test_sigterm_and_sighup_stop_a_campaign_as_ctrl_c_does(
    tmp_path: Path, sig: str, code: int
) -> None:
    """``kill <pid>`` (SIGTERM), a hang-up to the process group (SIGHUP) and ``kill -INT
    <pid>``: the summary, the manifest finished, no leaked semaphore, exit 128 + signal."""
    cfg = _config(tmp_path, "signal")
    args = ["ablate", str(cfg), "--seeds", "16", "--arch", ",".join(ADAPTIVE), "--no-rrd"]
    proc = _hooked("journal", 1, sig, *args, "--workers", "2")
    assert proc.returncode == code, proc.stderr
    found = re.search(r"interrupted: (\d+) of 32 runs done", proc.stderr)
    assert found and int(found[1]) >= 16, proc.stderr  # the task journaled, at least
    assert "Traceback" not in proc.stderr and "leaked" not in proc.stderr, proc.stderr
    out = tmp_path / "results" / "signal"
    assert json.loads((out / "manifest.json").read_text())["status"] == "interrupted"
    resumed = runner.invoke(app, [*args, "--workers", "1"])
    assert resumed.exit_code == 0, resumed.output
    assert f"{32 - int(found[1])} run(s) computed, {found[1]} already done" in resumed.stderr
