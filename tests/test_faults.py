"""Faults a campaign must survive without hanging, losing or writing outside (issue 36).

A full disk while a recording is written (item 1), links planted after
start-up (item 6), a noise file changed during a campaign (item 5), a Dask
cluster without workers (item 3) and computations without a bound (item 13).
"""

from __future__ import annotations

import errno
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.campaign import driver as driver_module
from cwrend_cli.campaign import journal
from cwrend_cli.campaign import worker as worker_module
from cwrend_cli.cli import app
from cwrend_cli.config import ARCHITECTURES, CwrendConfig, config_from_dict
from cwrend_cli.errors import InfrastructureError
from cwrend_cli.output import recording

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]
ADAPTIVE = "mtf_adaptive,plain_adaptive"  # the fast architectures (a few ms per run)
TIMING = ("duration_s", "solve_mean_ms", "solve_max_ms", "wall_time_ms", "error")


def _write_config(path: Path, name: str, extra: str = "") -> Path:
    path.write_text(f'[output]\ndir = "{path.parent / "results"}"\nname = "{name}"\n{extra}')
    return path


def _cli(*args: str) -> Any:
    return runner.invoke(app, list(args))


def _runs(out: Path) -> pd.DataFrame:
    runs = pd.read_parquet(out / "runs.parquet")
    return runs.drop(columns=[c for c in TIMING if c in runs.columns])


def _no_space(*args: Any, **kwargs: Any) -> Any:
    raise OSError(errno.ENOSPC, "No space left on device")


# --- item 1: a full disk while recording ------------------------------------


@pytest.fixture(scope="module")
def case() -> campaign.CaseResult:
    return campaign.run_case(CwrendConfig(), tuple(ARCHITECTURES.values())[2:], 0)


def test_a_recording_never_waits_on_a_rerun_file_sink(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, case: campaign.CaseResult
) -> None:
    """A Rerun file sink that died on a full disk blocks the next recording for ever."""
    import rerun as rr

    def blocking_sink(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("a Rerun file sink may block without bound on a full disk")

    for name in ("save", "flush", "disconnect"):
        monkeypatch.setattr(rr.RecordingStream, name, blocking_sink)
    path = recording.record_case(tmp_path / "r.rrd", case.runs, case.references, ())
    from rerun.chunk import RrdReader

    assert len(RrdReader(path).recordings()) == 1 and len(RrdReader(path).blueprints()) == 1


def test_a_full_disk_while_recording_is_an_oserror_and_leaves_no_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, case: campaign.CaseResult
) -> None:
    monkeypatch.setattr(Path, "write_bytes", _no_space)
    with pytest.raises(OSError) as raised:
        recording.record_case(tmp_path / "r.rrd", case.runs, case.references, ())
    assert raised.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []  # neither the file nor a temporary one


def test_a_full_disk_while_recording_stops_the_campaign_and_the_resume_records(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cfg = _write_config(tmp_path / "c.toml", "full", "seeds_per_task = 1\n")
    out = tmp_path / "results" / "full"
    args = ["ablate", str(cfg), "-n", "3", "--arch", ADAPTIVE, "--workers", "1", "-q",
            "--rrd-seeds", "3"]  # fmt: skip
    real = recording.record_case
    calls = {"n": 0}

    def filling(*args: Any, **kwargs: Any) -> Path:
        calls["n"] += 1
        if calls["n"] > 1:  # the first recording fits, then the disk is full
            _no_space()
        return real(*args, **kwargs)

    monkeypatch.setattr(recording, "record_case", filling)
    stopped = _cli(*args)
    assert stopped.exit_code == 3, stopped.output
    assert "campaign stopped: disk full" in stopped.stderr and "Traceback" not in stopped.output
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 2 and (runs["status"] == "ok").all()  # seed 1's task not journaled
    monkeypatch.setattr(recording, "record_case", real)
    resumed = _cli(*args)
    assert resumed.exit_code == 0, resumed.output
    assert sorted(p.name for p in (out / "recordings").iterdir()) == [
        f"base.s00000{s}.rrd" for s in range(3)
    ]


def test_a_resume_writes_again_every_recording_the_campaign_lost(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Recordings lost while their runs were journaled are recomputed, the runs not again."""
    cfg = _write_config(tmp_path / "c.toml", "lost", "seeds_per_task = 2\n")
    out = tmp_path / "results" / "lost"
    args = ["ablate", str(cfg), "-n", "3", "--arch", ADAPTIVE, "--workers", "1", "-q",
            "--rrd-seeds", "3"]  # fmt: skip

    def failing(*args: Any, **kwargs: Any) -> None:
        raise RuntimeError("encoder failed")

    monkeypatch.setattr(recording, "_log_case", failing)  # a warning: the runs stay
    assert _cli(*args).exit_code == 0
    assert not any(out.glob("recordings/*.rrd"))
    monkeypatch.undo()
    before = _runs(out)
    events = len(journal.read_events(out / "events.jsonl"))
    resumed = _cli(*args)
    assert resumed.exit_code == 0, resumed.output
    assert sorted(p.name for p in (out / "recordings").iterdir()) == [
        f"base.s00000{s}.rrd" for s in range(3)
    ]
    pd.testing.assert_frame_equal(_runs(out), before)
    added = journal.read_events(out / "events.jsonl")[events:]
    assert {e["event"] for e in added} == {"task_done"}  # no run journaled twice
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["sessions"][-1]["runs_computed"] == 0
    # a recording deleted by hand is owed too, and only it is written again
    (out / "recordings" / "base.s000001.rrd").unlink()
    assert _cli(*args).exit_code == 0
    assert (out / "recordings" / "base.s000001.rrd").is_file()


def test_a_full_disk_before_the_runs_is_exit_3_not_a_traceback(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A finished campaign rerun on a full disk: the manifest cannot be written."""
    cfg = _write_config(tmp_path / "c.toml", "done")
    args = ["ablate", str(cfg), "-n", "1", "--arch", "mtf_adaptive", "--workers", "1", "-q"]
    assert _cli(*args).exit_code == 0
    monkeypatch.setattr(driver_module, "write_json", _no_space)
    result = _cli(*args)
    assert result.exit_code == 3, result.output
    assert "campaign stopped: disk full" in result.stderr and "Traceback" not in result.output


def test_a_full_disk_writing_the_statistics_is_exit_3(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cfg = _write_config(tmp_path / "c.toml", "stats")
    args = ["ablate", str(cfg), "-n", "2", "--arch", "mtf_adaptive", "--workers", "1", "-q"]
    assert _cli(*args).exit_code == 0
    monkeypatch.setattr(driver_module, "write_parquet", _no_space)
    with pytest.raises(InfrastructureError, match=r"ablation\.parquet not written: disk full"):
        campaign.write_statistics(tmp_path / "results" / "stats", "ablate", 0)


# --- item 6: links planted after start-up --------------------------------------


def test_a_write_confined_to_a_directory_never_follows_a_link_below_it(tmp_path: Path) -> None:
    from cwrend_cli.output.files import atomic_path

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "out" / "steps").mkdir(parents=True)
    (tmp_path / "out" / "steps" / "arch=a").symlink_to(elsewhere, target_is_directory=True)
    with (
        pytest.raises(OSError, match="never writes through links") as raised,
        atomic_path(tmp_path / "out" / "steps" / "arch=a" / "t.parquet", root=tmp_path / "out"),
    ):
        pass
    assert raised.value.errno == errno.ELOOP
    assert list(elsewhere.iterdir()) == []


@pytest.mark.parametrize(
    "planted", ["steps/arch=mtf_adaptive", "recordings", "references", "events.jsonl"]
)
def test_a_link_planted_after_start_up_is_never_written_through(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, planted: str
) -> None:
    cfg = _write_config(tmp_path / "c.toml", "planted")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    real = journal.check_confined  # what the driver calls

    def then_plant(out_dir: Path) -> None:
        real(out_dir)  # the start-up check passes; the link comes after it
        link = out_dir / planted
        link.parent.mkdir(parents=True, exist_ok=True)
        target = elsewhere / link.name
        if planted.endswith(".jsonl"):
            target.write_text("")
        else:
            target.mkdir()
        link.symlink_to(target)

    monkeypatch.setattr(driver_module, "check_confined", then_plant)
    args = ["ablate", str(cfg), "-n", "2", "--arch", "mtf_adaptive", "--workers", "1", "-q"]
    result = _cli(*args, "--rrd-seeds", "1")
    assert result.exit_code == 3, result.output
    assert "never writes through links" in result.stderr and "Traceback" not in result.output
    assert [p for p in elsewhere.rglob("*") if p.is_file() and p.stat().st_size] == []
    monkeypatch.undo()
    again = _cli(*args)  # the link is still there: refused at start-up, exit 2
    assert again.exit_code == 2 and "a symbolic link inside the campaign directory" in again.stderr


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    cfg = _write_config(tmp_path_factory.mktemp("fin") / "c.toml", "fin")
    args = ["ablate", str(cfg), "-n", "2", "--arch", "mtf_adaptive", "--workers", "1", "-q"]
    assert _cli(*args).exit_code == 0
    return cfg.parent / "results" / "fin"


@pytest.mark.parametrize("linked", ["report", "steps", "manifest.json", "events.jsonl"])
def test_a_report_through_a_link_is_refused_with_exit_2(
    tmp_path: Path, finished: Path, linked: str
) -> None:
    import shutil

    results = tmp_path / "fin"
    shutil.copytree(finished, results)
    elsewhere = tmp_path / "elsewhere"
    if linked == "report":
        elsewhere.mkdir()
    else:
        (results / linked).rename(elsewhere)
    (results / linked).symlink_to(elsewhere)
    before = sorted(elsewhere.rglob("*")) if elsewhere.is_dir() else []
    result = _cli("report", str(results))
    assert result.exit_code == 2, result.output
    assert "a symbolic link inside the results directory" in result.stderr
    assert not (results / "report").is_dir() or (results / "report").is_symlink()
    assert (sorted(elsewhere.rglob("*")) if elsewhere.is_dir() else []) == before


# --- item 5: a noise file changed during a campaign ---------------------------


def _noise_file(path: Path, seed: int) -> Path:
    import numpy as np

    values = np.random.default_rng(seed).standard_normal((800, 3))
    pd.DataFrame(values, columns=["n1", "n2", "n3"]).to_csv(path, index=False)
    return path


def test_a_noise_file_changed_during_a_campaign_stops_it_as_a_changed_input(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    noise = _noise_file(tmp_path / "noise.csv", 1)
    original = noise.read_bytes()
    extra = f'seeds_per_task = 1\n[noise]\nfile = "{noise}"\n'
    cfg = _write_config(tmp_path / "c.toml", "noisy", extra)
    out = tmp_path / "results" / "noisy"
    real = worker_module.execute_task  # what the driver submits
    calls = {"n": 0}

    def then_change(*args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 2:  # after the first task: the file is edited under the campaign
            _noise_file(noise, 2)
        return real(*args, **kwargs)

    monkeypatch.setattr(driver_module, "execute_task", then_change)
    args = ["ablate", str(cfg), "-n", "3", "--arch", ADAPTIVE, "--workers", "1", "-q"]
    result = _cli(*args)
    assert result.exit_code == 2, result.output
    assert "changed since the campaign was planned" in result.stderr
    assert "Traceback" not in result.output
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 2 and (runs["status"] == "ok").all()  # nothing recorded as failed
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"].startswith("stopped: noise.file")
    monkeypatch.undo()
    noise.write_bytes(original)  # restored: the same command resumes
    assert _cli(*args).exit_code == 0
    whole = _cli("ablate", str(_write_config(tmp_path / "w.toml", "whole", extra)), *args[2:])
    assert whole.exit_code == 0
    pd.testing.assert_frame_equal(_runs(out), _runs(tmp_path / "results" / "whole"))


def test_retry_failed_counts_every_run_it_computed_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A task whose runs all failed reruns under its old execution name: still counted."""
    from cwrend_cli.physics import simulation

    simulate = simulation.simulate

    def failing(problem: Any, *args: Any, **kwargs: Any) -> Any:
        if problem.scenario.u_max_km_s2 == 7e-4:  # (an unreachable target is refused)
            raise RuntimeError("a run made to fail")
        return simulate(problem, *args, **kwargs)

    monkeypatch.setattr(simulation, "simulate", failing)  # --workers 1: in this process
    cfg = _write_config(tmp_path / "c.toml", "retry")
    args = ["sweep", str(cfg), "--param", "scenario.u_max_km_s2=8e-4,7e-4", "--arch",
            "mtf_adaptive", "--seeds", "2", "--workers", "1"]  # fmt: skip
    assert _cli(*args, "-q").exit_code == 1  # the u_max = 7e-4 point's 2 runs fail
    retry = _cli(*args, "--retry-failed")
    assert retry.exit_code == 1
    assert "2 run(s) computed, 2 already done" in retry.stderr
    manifest = json.loads((tmp_path / "results" / "retry" / "manifest.json").read_text())
    assert manifest["sessions"][-1]["runs_computed"] == 2


# --- item 3: a Dask cluster without workers -------------------------------------


def test_a_dask_cluster_without_workers_stops_the_campaign_with_exit_3(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    stalled_executor: Callable[..., Any],
    bounded_wait: Callable[..., Any],
) -> None:
    """Scheduler alive, no worker: the futures would wait for ever (real cluster:
    tests/test_distributed.py)."""

    class _WorkerlessClient:
        status = "running"  # the scheduler answers
        _scheduler_identity: ClassVar[dict[str, int]] = {"n_workers": 0}  # no worker

    guarded_wait = bounded_wait(100_000, "the campaign waits for ever on a cluster without workers")
    monkeypatch.setattr(driver_module, "open_executor", stalled_executor(_WorkerlessClient()))
    monkeypatch.setattr(driver_module, "wait", guarded_wait)
    monkeypatch.setattr(driver_module, "_POLL_S", 0.05)
    monkeypatch.setattr(driver_module, "_SIGNAL_POLL_S", 0.001)
    cfg = _write_config(tmp_path / "c.toml", "idle", "dask_no_worker_timeout_s = 0.2\n")
    result = _cli("ablate", str(cfg), "-n", "1", "--arch", "mtf_adaptive", "--workers", "1")
    assert result.exit_code == 3, result.output
    assert "the Dask cluster has had no worker for" in result.stderr
    assert "output.dask_no_worker_timeout_s = 0.2" in result.stderr
    manifest = json.loads((tmp_path / "results" / "idle" / "manifest.json").read_text())
    assert manifest["status"].startswith("stopped: the Dask cluster has had no worker")


# --- item 13: every computation a campaign starts has a bound ---------------------


def test_the_default_run_limit_is_a_small_multiple_of_what_the_run_costs() -> None:
    from cwrend_cli.campaign import guards
    from cwrend_cli.config.adapt import problem_of

    paper = problem_of(CwrendConfig())
    assert guards.resolves(paper) == 79  # every 10 s until 20 s are left, and at t = 0
    cost = guards.run_cost_s(800, 79)
    assert cost == pytest.approx(100e-6 * 800 * 79 / 2)
    assert guards.run_timeout_s(None, paper) == pytest.approx(10.0 + 3.0 * cost)  # 19.5 s
    first = guards.run_timeout_s(None, paper, first=True)
    assert first == pytest.approx(10.0 + 3.0 * cost + guards.FIRST_RUN_ALLOWANCE_S)
    assert guards.run_timeout_s(2.5, paper, first=True) == 2.5  # output.run_timeout_s wins


def test_a_constrained_run_gets_the_limit_of_its_costlier_re_solves() -> None:
    # a constrained cone-program run of campaigns/safe_approach.toml takes 17-18 s on a
    # 2-core machine: the paper run's 19.5 s limit would time it out on a slower one
    from cwrend_cli.campaign import guards
    from cwrend_cli.config import load_config
    from cwrend_cli.config.adapt import problem_of

    safe = problem_of(load_config(ROOT / "campaigns" / "safe_approach.toml", []))
    assert safe.constraints is not None and guards.resolves(safe) == 79
    cost = guards.run_cost_s(800, 79, guards.CONSTRAINED_RESOLVE_STEP_COST_S)
    assert guards.run_timeout_s(None, safe) == pytest.approx(10.0 + 3.0 * cost)  # 104.8 s
    long = problem_of(CwrendConfig.model_validate({"scenario": {"horizon_s": 20000.0}}))
    assert guards.run_timeout_s(None, long) < 10_060.0 * 0.6  # the old default: 60 s + 0.5 s/step


def test_references_past_the_run_limit_are_stopped_and_their_runs_reported_timed_out(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The open-loop references were computed in the campaign process with no bound."""
    import time

    from cwrend_cli.physics import simulation

    def slow_references(*args: Any, **kwargs: Any) -> Any:
        for _ in range(2000):  # a guard against a hang only: 20 s unbounded, then an error
            time.sleep(0.01)
        raise AssertionError("the references ran without a bound")

    monkeypatch.setattr(simulation, "open_loop_references", slow_references)
    cfg = _write_config(tmp_path / "c.toml", "refs", "run_timeout_s = 0.05\n")
    result = _cli("ablate", str(cfg), "-n", "2", "--arch", "mtf_adaptive", "--workers", "1", "-q")
    assert result.exit_code == 1, result.output  # the runs failed: a result, reported
    runs = pd.read_parquet(tmp_path / "results" / "refs" / "runs.parquet")
    assert len(runs) == 2
    assert runs["error"].str.contains("timed out: the run took longer than 0.05 s").all()


def test_a_processs_first_run_of_an_architecture_gets_the_allowance_for_its_kernels(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from cwrend_cli.campaign import guards

    firsts: list[bool] = []
    real = guards.run_timeout_s

    def recorded(configured: float | None, problem: Any, *, first: bool = False) -> float:
        firsts.append(first)
        return real(configured, problem, first=first)

    monkeypatch.setattr(guards, "run_timeout_s", recorded)
    monkeypatch.setattr(worker_module, "_VARIANTS_RUN", set())  # a fresh process
    task = campaign.plan(CwrendConfig(), ["mtf_adaptive", "plain_adaptive"], [0, 1]).tasks[0]
    worker_module.execute_task(task, None, str(tmp_path), metadata={"config_hash": "c"})
    assert firsts == [True, True, False, False]  # seed 0's two architectures, then seed 1's


def test_a_design_model_that_compiles_its_own_loop_is_its_own_variant() -> None:
    # the ss design model enters the step loop as a kernel tuple: its loop is typed (and
    # compiled) apart from CW's in the same world, so its first run in a process is a first
    # run; two configs whose loops have the same argument types share the variant
    from cwrend_cli.config.adapt import problem_of

    def variant(model: dict[str, str]) -> tuple[object, ...]:
        cfg = config_from_dict({"truth": {"model": "two_body"}, "model": model})
        return worker_module.kernel_variant(problem_of(cfg), "mtf_adaptive")

    assert variant({"guidance": "ss"}) != variant({})
    assert variant({"guidance": "ya"}) == variant({})  # the same loop: tables, not types


def test_each_compiled_variant_of_the_loop_gets_the_first_run_allowance() -> None:
    # a nonlinear truth or an actuator with errors compiles its own loop: its first run in a
    # process is a first run, even after runs of the same architecture in the CW world
    from cwrend_cli.config.adapt import problem_of

    paper = problem_of(CwrendConfig())
    j2 = problem_of(config_from_dict({"truth": {"model": "j2"}}))
    noisy = problem_of(config_from_dict({"actuator": {"magnitude_sigma": 0.01}}))
    variants = {worker_module.kernel_variant(p, "mtf_adaptive") for p in (paper, j2, noisy)}
    assert len(variants) == 3
    assert worker_module.kernel_variant(paper, "mtf_adaptive") != worker_module.kernel_variant(
        paper, "mtf_fixed"
    )
