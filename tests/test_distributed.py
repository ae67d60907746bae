"""A real distributed run: a Dask scheduler and two workers on 127.0.0.1 (issues 20 and 21).

The tests start ``dask scheduler`` and ``dask worker`` processes, run
campaigns with ``--executor dask --address …`` and check the numbers against
``--workers 1``; then they kill a worker, and stop the scheduler, in the
middle of a campaign: the campaign completes (Dask reruns a dead worker's
tasks) or stops with exit code 3, and never records an infrastructure fault
as a run's result or duplicates a row.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pytest
from hooked_cwrend import HANG_S, HOOKED, wait_stopped
from typer.testing import CliRunner

from cwrend_cli.campaign import journal
from cwrend_cli.cli import app

pytestmark = pytest.mark.skipif(shutil.which("dask") is None, reason="needs Dask distributed")

ARCHS = "mtf_adaptive,plain_adaptive"
TIMING = ("duration_s", "solve_mean_ms", "solve_max_ms", "wall_time_ms", "error")


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _wait_for_port(port: int, timeout_s: float = HANG_S) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.1)
    raise TimeoutError(f"nothing listens on port {port}")


class Cluster:
    """A scheduler and worker processes (one thread each) on the loopback interface."""

    def __init__(self, tmp: Path, workers: int) -> None:
        self.port = _free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.log = tmp / "dask.log"
        log = self.log.open("w")
        env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
        self.scheduler = subprocess.Popen(
            ["dask", "scheduler", "--host", "127.0.0.1", "--port", str(self.port),
             "--no-dashboard"],
            stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True,
        )  # fmt: skip
        _wait_for_port(self.port)
        self.workers = [
            subprocess.Popen(
                [
                    "dask",
                    "worker",
                    self.address,
                    "--nthreads",
                    "1",
                    "--nworkers",
                    "1",
                    "--no-dashboard",
                    "--no-nanny",
                    "--local-directory",
                    str(tmp / f"w{i}"),
                ],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=env,
                start_new_session=True,
            )
            for i in range(workers)
        ]
        self._wait_for_workers(workers)

    def _wait_for_workers(self, n: int) -> None:
        from distributed import Client

        with Client(self.address, timeout="30s") as client:  # type: ignore[no-untyped-call]
            client.wait_for_workers(n, timeout=HANG_S)  # type: ignore[no-untyped-call]

    def alive(self) -> bool:
        return all(proc.poll() is None for proc in [*self.workers, self.scheduler])

    def stop(self) -> None:
        for proc in [*self.workers, self.scheduler]:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@pytest.fixture(scope="module")
def _clusters() -> Iterator[list[Cluster]]:
    """The clusters the module started; all stopped at its end."""
    started: list[Cluster] = []
    try:
        yield started
    finally:
        for c in started:
            c.stop()


@pytest.fixture
def cluster(_clusters: list[Cluster], tmp_path_factory: pytest.TempPathFactory) -> Cluster:
    """A scheduler and two workers, every process alive.

    Shared by the tests (the workers stay warm from one campaign to the next);
    after a test killed one of its processes, the next test gets a new cluster.
    """
    if not _clusters or not _clusters[-1].alive():
        if _clusters:
            _clusters[-1].stop()
        _clusters.append(Cluster(tmp_path_factory.mktemp("cluster"), workers=2))
    return _clusters[-1]


def _config(tmp_path: Path, name: str) -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(
        f'[output]\ndir = "{tmp_path / "results"}"\nname = "{name}"\nseeds_per_task = 1\n'
        "rrd_seeds = 0\n"
    )
    return path


def _cwrend(*args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cwrend_cli", *args], capture_output=True,
                          text=True, timeout=timeout)  # fmt: skip


def _runs(out: Path) -> pd.DataFrame:
    runs = pd.read_parquet(out / "runs.parquet")
    runs = runs.drop(columns=[c for c in TIMING if c in runs.columns])
    return runs.sort_values("run_key").reset_index(drop=True)


def _steps(out: Path) -> pd.DataFrame:
    steps = pd.read_parquet(out / "steps")
    steps["arch"] = steps["arch"].astype(str)
    return steps.sort_values(["run_key", "step"]).reset_index(drop=True)


def _events_done(out: Path) -> int:
    return sum(e["event"] == "task_done" for e in journal.read_events(out / "events.jsonl"))


def _cli(*args: str) -> None:
    """A cwrend command in-process (the local references: nothing distributed about them)."""
    result = CliRunner().invoke(app, list(args))
    assert result.exit_code == 0, result.output


@pytest.fixture(scope="module")
def local(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The 16-seed ablation of ARCHS on one local worker: the numbers every Dask campaign must give.

    Runs are keyed by point, architecture and seed: a campaign of the first n
    seeds holds exactly this one's runs of those seeds (see :func:`_first_seeds`).
    """
    tmp = tmp_path_factory.mktemp("local")
    _cli("ablate", str(_config(tmp, "local")), "--seeds", "16", "--arch", ARCHS, "--workers", "1",
         "-q")  # fmt: skip
    return tmp / "results" / "local"


def _first_seeds(frame: pd.DataFrame, seeds: int) -> pd.DataFrame:
    return frame[frame["seed"] < seeds].reset_index(drop=True)


def test_a_dask_cluster_gives_the_numbers_of_one_worker(
    tmp_path: Path, cluster: Cluster, local: Path
) -> None:
    result = _cwrend("ablate", str(_config(tmp_path, "dask")), "--seeds", "6", "--arch", ARCHS,
                     "--executor", "dask", "--address", cluster.address, "-q")  # fmt: skip
    assert result.returncode == 0, result.stderr
    out = tmp_path / "results" / "dask"
    pd.testing.assert_frame_equal(_runs(out), _first_seeds(_runs(local), 6))
    pd.testing.assert_frame_equal(_steps(out), _first_seeds(_steps(local), 6), check_exact=True)


def test_a_sobol_design_on_dask_gives_the_numbers_of_one_worker_and_resumes(
    tmp_path: Path, cluster: Cluster
) -> None:
    """Issue 19: a design campaign end to end on the Dask executor, resumed, equal to local."""
    ranges = '[sweep]\n"schedule.beta" = { low = 0.05, high = 1.0 }\n'
    for name in ("dask_design", "local_design"):
        cfg = _config(tmp_path, name)
        cfg.write_text(cfg.read_text() + ranges)
    design = ["--design", "sobol", "--samples", "2", "--arch", "mtf_adaptive", "-q"]
    dask = ["--executor", "dask", "--address", cluster.address]
    first = _cwrend("sweep", str(tmp_path / "dask_design.toml"), "--seeds", "1", *design, *dask)
    assert first.returncode == 0, first.stderr
    resumed = _cwrend("sweep", str(tmp_path / "dask_design.toml"), "--seeds", "2", *design, *dask)
    assert resumed.returncode == 0, resumed.stderr
    _cli("sweep", str(tmp_path / "local_design.toml"), "--seeds", "2", *design, "--workers", "1")
    out, ref = tmp_path / "results" / "dask_design", tmp_path / "results" / "local_design"
    pd.testing.assert_frame_equal(_runs(out), _runs(ref))
    indices = pd.read_parquet(out / "sensitivity.parquet")
    pd.testing.assert_frame_equal(indices, pd.read_parquet(ref / "sensitivity.parquet"))


def _start_campaign(tmp_path: Path, cluster: Cluster, seeds: int) -> subprocess.Popen[str]:
    """The campaign, which stops itself (SIGSTOP) once its second task is journaled."""
    args = [sys.executable, str(HOOKED), "journal", "2", "SIGSTOP", "ablate",
            str(_config(tmp_path, "dask")), "--seeds", str(seeds), "--arch", ARCHS,
            "--executor", "dask", "--address", cluster.address, "-q"]  # fmt: skip
    return subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _kill_mid_campaign(
    tmp_path: Path, cluster: Cluster, seeds: int, victim: subprocess.Popen[bytes]
) -> tuple[int, str]:
    """Start a Dask campaign, kill ``victim`` once two tasks are done; its exit code and stderr."""
    proc = _start_campaign(tmp_path, cluster, seeds)
    wait_stopped(proc)  # frozen with two tasks journaled: the kill lands mid-campaign
    assert _events_done(tmp_path / "results" / "dask") == 2
    os.killpg(victim.pid, signal.SIGKILL)
    proc.send_signal(signal.SIGCONT)
    try:
        _, stderr = proc.communicate(timeout=HANG_S)
    except subprocess.TimeoutExpired:  # say where it hangs (faulthandler on SIGUSR1), then fail
        proc.send_signal(signal.SIGUSR1)
        time.sleep(2)
        proc.kill()
        _, stderr = proc.communicate()
        pytest.fail(f"the campaign did not end after the kill:\n{stderr[-6000:]}")
    return proc.returncode, stderr


def test_a_killed_dask_worker_loses_no_run_and_duplicates_none(
    tmp_path: Path, cluster: Cluster, local: Path
) -> None:
    out = tmp_path / "results" / "dask"
    returncode, stderr = _kill_mid_campaign(tmp_path, cluster, 16, cluster.workers[0])
    assert returncode == 0, stderr  # Dask reran the dead worker's tasks on the other
    runs = _runs(out)
    assert len(runs) == 32 and (runs["status"] == "ok").all()
    pd.testing.assert_frame_equal(runs, _runs(local))
    pd.testing.assert_frame_equal(_steps(out), _steps(local), check_exact=True)


def test_a_lost_scheduler_stops_the_campaign_and_records_no_result(
    tmp_path: Path, cluster: Cluster
) -> None:
    out = tmp_path / "results" / "dask"
    returncode, stderr = _kill_mid_campaign(tmp_path, cluster, 40, cluster.scheduler)
    assert returncode == 3, stderr
    assert "campaign stopped:" in stderr and "Traceback" not in stderr
    runs = pd.read_parquet(out / "runs.parquet")
    assert (runs["status"] == "ok").all()  # nothing recorded for the lost scheduler
    assert json.loads((out / "manifest.json").read_text())["status"].startswith("stopped:")


def test_a_cluster_whose_workers_all_died_stops_the_campaign_and_it_resumes(
    tmp_path: Path, cluster: Cluster, local: Path, _clusters: list[Cluster]
) -> None:
    """Scheduler alive, every worker killed: exit 3 after output.dask_no_worker_timeout_s
    (it waited for ever), nothing recorded for it; the same command resumes on new workers."""
    out = tmp_path / "results" / "dask"
    args = ["ablate", str(_config(tmp_path, "dask")), "--seeds", "16", "--arch", ARCHS,
            "--executor", "dask", "-q", "--set", "output.dask_no_worker_timeout_s=1"]  # fmt: skip
    proc = subprocess.Popen(
        [sys.executable, str(HOOKED), "journal", "2", "SIGSTOP", *args, "--address",
         cluster.address], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    wait_stopped(proc)  # two tasks journaled, the others in flight or queued
    for worker in cluster.workers:
        os.killpg(worker.pid, signal.SIGKILL)
        worker.wait()
    proc.send_signal(signal.SIGCONT)
    try:
        _, stderr = proc.communicate(timeout=HANG_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("the campaign waits for ever on a cluster without workers")
    assert proc.returncode == 3, stderr
    assert "the Dask cluster has had no worker for" in stderr and "Traceback" not in stderr
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) >= 4 and (runs["status"] == "ok").all()  # nothing recorded for it
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"].startswith("stopped: the Dask cluster has had no worker")
    (tmp_path / "fresh").mkdir()
    fresh = Cluster(tmp_path / "fresh", workers=2)
    _clusters.append(fresh)  # stopped with the module's others; later tests use it
    resumed = _cwrend(*args, "--address", fresh.address)
    assert resumed.returncode == 0, resumed.stderr
    pd.testing.assert_frame_equal(_runs(out), _runs(local))
    pd.testing.assert_frame_equal(_steps(out), _steps(local), check_exact=True)


def test_dask_log_lines_are_silenced_below_critical() -> None:
    """Every distributed/tornado logger, including those distributed's own logging
    configuration sets explicitly (``tornado.application`` at ERROR), stays quiet: a
    lost scheduler is reported by cwrend, not by a tornado traceback."""
    import logging

    import distributed  # noqa: F401  (applies Dask's logging configuration)

    from cwrend_cli.campaign import executors

    executors._quiet_dask_logs()
    names = [
        name
        for name in logging.root.manager.loggerDict
        if name.split(".")[0] in ("distributed", "tornado")
    ]
    assert "tornado.application" in names
    for name in [*names, "asyncio"]:
        assert logging.getLogger(name).getEffectiveLevel() == logging.CRITICAL, name
