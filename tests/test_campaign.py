"""Campaigns: the planner, dispersions, fan-out, resume and failure isolation (issue 9)."""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import errno
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pool_tasks
import pyarrow.parquet as pq
import pytest
from hooked_cwrend import HANG_S, HOOKED, wait_stopped
from pydantic import BaseModel
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.campaign import driver as driver_module
from cwrend_cli.campaign import journal
from cwrend_cli.campaign import worker as worker_module
from cwrend_cli.campaign.executors import open_executor
from cwrend_cli.cli import app
from cwrend_cli.config import CwrendConfig, config_from_dict, expand_grid, load_config, parse_param
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.errors import ConfigError
from cwrend_cli.output.tables import references_table
from cwrend_cli.physics import simulation

runner = CliRunner()
# Wall-time columns differ between otherwise identical runs.
TIMING = ("duration_s", "solve_mean_ms", "solve_max_ms", "wall_time_ms", "error")
ADAPTIVE = "mtf_adaptive,plain_adaptive"  # the fast architectures (a few ms per run)


def _write_config(path: Path, name: str, extra: str = "") -> Path:
    path.write_text(f'[output]\ndir = "{path.parent / "results"}"\nname = "{name}"\n{extra}')
    return path


def _cli(*args: str):
    return runner.invoke(app, list(args))


def _runs(out: Path) -> pd.DataFrame:
    runs = pd.read_parquet(out / "runs.parquet")
    return runs.drop(columns=[c for c in TIMING if c in runs.columns])


def _steps(out: Path) -> pd.DataFrame:
    steps = pd.read_parquet(out / "steps")
    steps["arch"] = steps["arch"].astype(str)
    return steps.sort_values(["run_key", "step"]).reset_index(drop=True)


# --- planner (pure) ---------------------------------------------------------


def test_param_list_values_are_read_as_toml() -> None:
    assert parse_param("schedule.beta=0.1,0.5") == ("schedule.beta", (0.1, 0.5))
    assert parse_param("guidance.hold=sample,mean") == (
        "guidance.hold",
        ("sample", "mean"),
    )


def test_param_toml_array_lists_the_values_as_a_sweep_table_does() -> None:
    assert parse_param("schedule.beta=[0.1, 0.5]") == ("schedule.beta", (0.1, 0.5))
    rates = "target.body_rates_deg_s=[[0.0, 0.0, 0.0], [0.291, 0.3881, 1.9403]]"
    assert parse_param(rates) == (
        "target.body_rates_deg_s",
        ([0.0, 0.0, 0.0], [0.291, 0.3881, 1.9403]),
    )


def test_a_quoted_key_is_refused_naming_the_unquoted_form() -> None:
    with pytest.raises(ConfigError, match="quoted key components"):
        parse_param('sweep."target.body_rates_deg_s"=[[0, 0, 0]]')


def test_param_range_is_start_stop_num() -> None:
    key, values = parse_param("schedule.beta=0.1:0.5:5")
    assert key == "schedule.beta"
    assert values == pytest.approx((0.1, 0.2, 0.3, 0.4, 0.5))


@pytest.mark.parametrize(
    "text", ["schedule.beta", "schedule.beta=0.1,,0.2", "x=1:2:zero", "schedule.beta=[]"]
)
def test_malformed_param_is_refused(text: str) -> None:
    with pytest.raises(ConfigError):
        parse_param(text)


def test_grid_is_the_cartesian_product_and_cli_wins() -> None:
    grid = expand_grid(
        {"schedule.beta": (0.1, 0.2), "guidance.hold": ("sample",)},
        ["guidance.hold=sample,mean", "schedule.kappa_mtf=6,12,24"],
    )
    assert dict(grid)["guidance.hold"] == ("sample", "mean")
    assert len(campaign.grid_points(grid)) == 2 * 2 * 3


def test_point_id_does_not_depend_on_key_order() -> None:
    a = campaign.point_id((("schedule.beta", 0.1), ("guidance.hold", "mean")))
    b = campaign.point_id((("guidance.hold", "mean"), ("schedule.beta", 0.1)))
    assert a == b != campaign.BASE_POINT


def test_plan_has_every_arch_for_every_seed() -> None:
    plan = campaign.plan(CwrendConfig(), ["mtf_adaptive", "plain_fixed"], [0, 1, 2])
    keys = {(r.arch, r.seed) for r in plan.runs}
    assert keys == {(a, s) for a in ("mtf_adaptive", "plain_fixed") for s in (0, 1, 2)}
    assert len({r.run_key for r in plan.runs}) == 6


def test_bad_grid_value_fails_before_anything_runs() -> None:
    with pytest.raises(ConfigError, match=r"schedule\.alpha_eps"):
        campaign.plan(CwrendConfig(), ["mtf_adaptive"], [0], ["schedule.alpha_eps=0.1,1.5"])


def test_unknown_grid_key_is_refused() -> None:
    with pytest.raises(ConfigError, match="nonsense"):
        campaign.plan(CwrendConfig(), ["mtf_adaptive"], [0], ["schedule.nonsense=1,2"])


def _dispersed_config() -> CwrendConfig:
    return config_from_dict(
        {
            "dispersions": {
                "scenario.x0.0": {"dist": "normal", "std": 1e-3},
                "scenario.u_max_km_s2": {
                    "dist": "uniform",
                    "low": 7e-4,
                    "high": 9e-4,
                    "mode": "set",
                },
            }
        }
    )


def test_dispersions_are_shared_by_the_architectures_of_a_seed() -> None:
    plan = campaign.plan(_dispersed_config(), ["mtf_adaptive", "plain_fixed"], [0, 1])
    by_seed: dict[int, set] = {}
    for r in plan.runs:
        by_seed.setdefault(r.seed, set()).add(r.dispersed)
    assert all(len(v) == 1 for v in by_seed.values())
    assert by_seed[0] != by_seed[1]


def test_dispersion_draws_follow_their_distribution_and_mode() -> None:
    plan = campaign.plan(_dispersed_config(), ["mtf_adaptive"], list(range(200)))
    draws = pd.DataFrame([dict(r.dispersed) for r in plan.runs])
    x0 = CwrendConfig().scenario.x0[0]
    # mode "add": base + N(0, 1e-3); 200 draws: the mean is within 4 σ/√200 ≈ 2.8e-4
    assert abs(draws["scenario.x0.0"].mean() - x0) < 2.8e-4
    assert draws["scenario.u_max_km_s2"].between(7e-4, 9e-4).all()  # mode "set"


def test_dispersing_a_non_number_is_refused() -> None:
    cfg = config_from_dict({"dispersions": {"scenario.x0": {"dist": "normal", "std": 1.0}}})
    with pytest.raises(ConfigError, match=r"scenario\.x0"):
        campaign.plan(cfg, ["mtf_adaptive"], [0])


def test_noise_of_a_seed_does_not_depend_on_anything_else() -> None:
    cfg = CwrendConfig()
    a = campaign.standard_normal_for(cfg, 3)
    b = campaign.standard_normal_for(cfg, 3)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, campaign.standard_normal_for(cfg, 4))


def test_plan_validates_each_point_and_each_dispersed_run_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    cfg = _dispersed_config()
    validated = []
    validate = CwrendConfig.model_validate

    def counting(*args: Any, **kwargs: Any) -> CwrendConfig:
        validated.append(args[0])
        return validate(*args, **kwargs)

    monkeypatch.setattr(CwrendConfig, "model_validate", counting)
    plan = campaign.plan(cfg, ["mtf_adaptive", "plain_fixed"], [0, 1, 2], ["schedule.beta=0.2,0.4"])
    assert len(plan.runs) == 2 * 2 * 3
    assert len(validated) == 2 + 2 * 3  # the grid points, then each point's dispersed seeds


def test_the_worker_builds_no_pydantic_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Tasks carry typed parameters; a run's dispersion is applied without validation."""
    task = campaign.plan(_dispersed_config(), ["mtf_adaptive"], [0, 1]).tasks[0]
    refs = simulation.open_loop_references(task.problem)

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the worker built a pydantic model")

    for name in (
        "model_validate",
        "model_validate_json",
        "model_validate_strings",
        "model_construct",
    ):
        monkeypatch.setattr(BaseModel, name, classmethod(refuse))
    monkeypatch.setattr(BaseModel, "__init__", refuse)
    monkeypatch.setattr(BaseModel, "model_copy", refuse)
    with pytest.raises(AssertionError, match="pydantic model"):
        CwrendConfig()  # the trap is set
    outcome = campaign.execute_task(task, refs, str(tmp_path))
    assert [o.status for o in outcome.outcomes] == ["ok", "ok"], [o.error for o in outcome.outcomes]
    # scenario.x0 is dispersed: each run computed its own references, in the worker
    assert all(o.spec.dispersed for o in outcome.outcomes)


# --- end to end -------------------------------------------------------------


@pytest.fixture(scope="module")
def small_ablation(tmp_path_factory: pytest.TempPathFactory) -> Path:
    cfg = _write_config(tmp_path_factory.mktemp("abl") / "c.toml", "small")
    result = _cli(
        "ablate", str(cfg), "--seeds", "3", "--arch", ADAPTIVE, "--workers", "1", "-q",
        "--rrd-seeds", "2",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    return cfg.parent / "results" / "small"


def test_ablation_writes_the_campaign_layout(small_ablation: Path) -> None:
    names = {p.name for p in small_ablation.iterdir()}
    assert {"manifest.json", "runs.parquet", "events.jsonl", "steps", "solves"} <= names
    assert "ablation.parquet" in names


def test_each_task_journals_its_workers_time_writing_its_files(small_ablation: Path) -> None:
    """``task_done`` carries ``files_s``: the worker's time writing the task's steps/solves
    files and recordings (what the benchmark's utilization counts as part of the job),
    positive for a task that wrote files and never more than the campaign's running
    phase (first run started to last task journaled)."""
    from datetime import datetime

    events = [json.loads(line) for line in (small_ablation / "events.jsonl").open()]
    done = [e for e in events if e["event"] == "task_done"]
    assert done and all(e["files"] and e["files_s"] > 0.0 for e in done)

    def at(e: dict[str, object]) -> float:
        return datetime.fromisoformat(str(e["time"])).timestamp()

    started = min(at(e) for e in events if e["event"] == "run_started")
    assert sum(e["files_s"] for e in done) <= max(at(e) for e in done) - started


def test_ablation_records_the_first_seeds_with_every_arch(small_ablation: Path) -> None:
    from rerun.chunk import RrdReader

    files = sorted(p.name for p in (small_ablation / "recordings").iterdir())
    assert files == ["base.s000000.rrd", "base.s000001.rrd"]  # --rrd-seeds 2 of 3 seeds
    paths = {c.entity_path for c in RrdReader(small_ablation / "recordings" / files[0]).stream()}
    for arch in ADAPTIVE.split(","):
        assert f"/arch/{arch}/trajectory/true" in paths
    assert "/reference/fuel/trajectory" in paths


def test_only_seeds_with_every_arch_in_the_task_are_recorded() -> None:
    cfg = CwrendConfig()
    archs = ("mtf_adaptive", "plain_adaptive")
    task = campaign.plan(cfg, archs, [0, 1, 2]).tasks[0]
    assert campaign.seeds_to_record(task, archs, None) == (0, 1, 2)
    assert campaign.seeds_to_record(task, archs, 2) == (0, 1)
    retry = dataclasses.replace(task, runs=tuple(r for r in task.runs if r.run_key[-1] != "0"
                                                 or r.arch == "mtf_adaptive"))  # fmt: skip
    assert campaign.seeds_to_record(retry, archs, None) == (1, 2)  # seed 0 only partly rerun


def test_runs_table_has_one_row_per_run(small_ablation: Path) -> None:
    runs = pd.read_parquet(small_ablation / "runs.parquet")
    assert len(runs) == 6 and (runs["status"] == "ok").all()
    assert runs["miss_km"].dtype == np.float64


def test_steps_dataset_reads_as_one_typed_table(small_ablation: Path) -> None:
    steps = pd.read_parquet(small_ablation / "steps")
    assert len(steps) == 6 * 801
    assert set(steps["arch"].astype(str)) == {"mtf_adaptive", "plain_adaptive"}
    assert steps["t_s"].dtype == np.float64 and steps["degradation_window"].dtype == np.int64
    assert steps.groupby("run_key").size().eq(801).all()


def test_ablation_statistics_have_intervals(small_ablation: Path) -> None:
    stats = pd.read_parquet(small_ablation / "ablation.parquet")
    mean_miss = stats.query("kind == 'marginal' and metric == 'miss_km' and statistic == 'mean'")
    assert len(mean_miss) == 2
    assert (mean_miss["ci_low"] <= mean_miss["value"]).all()
    assert (mean_miss["value"] <= mean_miss["ci_high"]).all()
    paired = stats.query("kind == 'paired' and statistic == 'frac_less'")
    assert set(zip(paired["arch"], paired["other"], strict=True)) == {
        ("mtf_adaptive", "plain_adaptive")
    }


def test_manifest_records_provenance(small_ablation: Path) -> None:
    manifest = json.loads((small_ablation / "manifest.json").read_text())
    assert manifest["seeds"] == [0, 1, 2]
    assert manifest["counts"] == {"ok": 6, "failed": 0, "runs": 6}
    assert manifest["status"] == "complete"
    assert len(manifest["campaign_hash"]) == 64


def test_rerun_skips_completed_runs(small_ablation: Path) -> None:
    before = (small_ablation / "events.jsonl").read_text()
    cfg = small_ablation.parent.parent / "c.toml"
    result = _cli(
        "ablate", str(cfg), "--seeds", "3", "--arch", ADAPTIVE, "--workers", "1", "-q",
        "--rrd-seeds", "2",  # the same command: a larger --rrd-seeds would record seed 2 now
    )  # fmt: skip
    assert result.exit_code == 0
    assert (small_ablation / "events.jsonl").read_text() == before  # nothing recomputed


def test_extending_seeds_equals_a_fresh_larger_campaign(
    tmp_path: Path, small_ablation: Path
) -> None:
    cfg = small_ablation.parent.parent / "c.toml"
    ext = _cli("ablate", str(cfg), "--seeds", "4", "--arch", ADAPTIVE, "--name", "ext", "-q",
               "--workers", "1")  # fmt: skip
    assert ext.exit_code == 0
    fresh_cfg = _write_config(tmp_path / "f.toml", "fresh")
    fresh = _cli(
        "ablate", str(fresh_cfg), "--seeds", "4", "--arch", ADAPTIVE, "--workers", "1", "-q"
    )
    assert fresh.exit_code == 0
    pd.testing.assert_frame_equal(
        _runs(small_ablation.parent / "ext"), _runs(tmp_path / "results" / "fresh")
    )


def test_changed_config_is_refused_unless_forced(small_ablation: Path) -> None:
    cfg = small_ablation.parent.parent / "c.toml"
    args = ["ablate", str(cfg), "--seeds", "3", "--arch", ADAPTIVE, "--workers", "1", "-q",
            "--set", "schedule.beta=0.3"]  # fmt: skip
    refused = _cli(*args)
    assert refused.exit_code == 2
    assert "--force" in refused.output


def test_campaign_writes_the_references_of_each_scenario_once(tmp_path: Path) -> None:
    """references/<id>.parquet per distinct scenario and solver, named for each point by
    references/index.jsonl (read back by report.load.references_file); kept on resume."""
    from cwrend_cli.report.load import references_file

    cfg_file = _write_config(tmp_path / "c.toml", "refs")
    args = ["sweep", str(cfg_file), "--param", "scenario.u_max_km_s2=8e-4,9e-4", "--param",
            "schedule.beta=0.25,0.5", "--arch", "mtf_adaptive", "--seeds", "1", "--workers", "1",
            "--no-rrd", "-q"]  # fmt: skip
    assert _cli(*args).exit_code == 0
    out = tmp_path / "results" / "refs"
    names = set()
    for u_max in (8e-4, 9e-4):
        problem = problem_of(load_config(cfg_file, [f"scenario.u_max_km_s2={u_max}"]))
        expected = references_table(simulation.open_loop_references(problem))
        files = {
            references_file(out, campaign.point_id((("scenario.u_max_km_s2", u_max),
                                                    ("schedule.beta", beta))))
            for beta in (0.25, 0.5)
        }  # fmt: skip
        (rel,) = files  # β does not change the references: both points name one file
        stored = pq.read_table(out / rel)
        assert stored.schema == expected.schema
        assert stored.equals(expected)
        names.add(Path(rel).name)
    assert len(names) == 2
    assert _cli(*args).exit_code == 0  # a resume with nothing to do keeps them
    assert {p.name for p in (out / "references").iterdir()} == names | {"index.jsonl"}
    assert len((out / "references" / "index.jsonl").read_text().splitlines()) == 4
    journal.wipe(out)  # what --force removes
    assert not (out / "references").exists()


def test_path_traversal_name_is_refused(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path / "c.toml", "ok")
    result = _cli("ablate", str(cfg), "--name", "../escape", "-q")
    assert result.exit_code == 2
    assert "output.name" in result.output
    assert not (tmp_path / "escape").exists()


# --- determinism across executors ---------------------------------------------


@pytest.mark.parametrize(("executor", "workers"), [("local", "2"), ("dask", "2")])
def test_numbers_do_not_depend_on_workers_or_executor(
    executor: str, workers: str, tmp_path: Path, small_ablation: Path
) -> None:
    # one seed per task: three tasks, so the two workers really share the work
    cfg = _write_config(tmp_path / "c.toml", "par", "seeds_per_task = 1\n")
    result = _cli("ablate", str(cfg), "--seeds", "3", "--arch", ADAPTIVE, "-q",
                  "--workers", workers, "--executor", executor)  # fmt: skip
    assert result.exit_code == 0, result.output
    out = tmp_path / "results" / "par"
    assert _events_done(out / "events.jsonl") == 3
    pd.testing.assert_frame_equal(_runs(out), _runs(small_ablation))
    a, b = _steps(out), _steps(small_ablation)
    pd.testing.assert_frame_equal(a, b, check_exact=True)


# --- failures and interruption ---------------------------------------------------


def test_failing_runs_are_isolated_and_retried(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The runs of u_max = 7e-4 km/s² fail (made to, in the simulation): the others go on.

    (An unreachable target, which made them fail before, is refused before the campaign
    starts: test_an_unreachable_port_is_refused_before_anything_is_written.)
    """
    from cwrend_cli.physics import simulation

    simulate = simulation.simulate

    def failing(problem: Any, *args: Any, **kwargs: Any) -> Any:
        if problem.scenario.u_max_km_s2 == 7e-4:
            raise RuntimeError("a run made to fail")
        return simulate(problem, *args, **kwargs)

    monkeypatch.setattr(simulation, "simulate", failing)  # --workers 1: in this process
    cfg = _write_config(tmp_path / "c.toml", "fail")
    args = ["sweep", str(cfg), "--param", "scenario.u_max_km_s2=8e-4,7e-4", "--arch",
            "mtf_adaptive", "--seeds", "2", "--workers", "1", "-q"]  # fmt: skip
    first = _cli(*args)
    assert first.exit_code == 1  # some runs failed
    out = tmp_path / "results" / "fail"
    runs = pd.read_parquet(out / "runs.parquet")
    failed = runs[runs["status"] == "failed"]
    assert len(failed) == 2 and (runs["status"] == "ok").sum() == 2
    assert failed["error"].str.contains("a run made to fail").all()
    assert (failed["param.scenario.u_max_km_s2"] == 7e-4).all()
    retry = _cli(*args, "--retry-failed")
    assert retry.exit_code == 1
    events = journal.read_events(out / "events.jsonl")
    finished = [e for e in events if e["event"] == "run_finished"]
    failed_events = [e for e in events if e["event"] == "run_failed"]
    assert len(finished) == 2  # the good runs were not recomputed
    assert len(failed_events) == 4  # the failed ones ran twice


def _events_done(path: Path) -> int:
    if not path.exists():
        return 0
    return sum(e["event"] == "task_done" for e in journal.read_events(path))


def _hooked(when: str, n: int, sig: str, *args: str, **popen: Any) -> subprocess.Popen[str]:
    """``cwrend *args`` sending ``sig`` at its ``n``-th state ``when`` ("journal" or "run")."""
    command = [sys.executable, str(HOOKED), when, str(n), sig, *args]
    return subprocess.Popen(command, text=True, **popen)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The interrupted campaigns below, computed in one go: a 40-seed ablation of ADAPTIVE.

    Runs are keyed by point, architecture and seed, not by task, worker or
    session (``test_resume_with_another_chunking_computes_only_the_missing_runs``,
    ``test_numbers_do_not_depend_on_workers_or_executor``): a campaign of the
    first ``n`` seeds holds exactly this campaign's runs of those seeds. So one
    in-process, one-worker campaign is the reference of every kill and Ctrl-C
    test (it was a subprocess campaign per test, with their chunking and workers).
    """
    cfg = _write_config(tmp_path_factory.mktemp("uninterrupted") / "w.toml", "whole")
    result = _cli("ablate", str(cfg), "--seeds", "40", "--arch", ADAPTIVE, "--workers", "1", "-q",
                  "--no-rrd")  # fmt: skip
    assert result.exit_code == 0, result.output
    return cfg.parent / "results" / "whole"


def _assert_same_as_uninterrupted(out: Path, whole: Path, seeds: int) -> None:
    """``out`` holds exactly the runs and steps of seeds ``0 … seeds - 1`` of ``whole``."""
    runs, expected = _runs(out), _runs(whole)
    pd.testing.assert_frame_equal(runs, expected[expected["seed"] < seeds].reset_index(drop=True))
    steps, expected_steps = _steps(out), _steps(whole)
    assert len(steps) == seeds * 2 * 801  # nothing duplicated, nothing left by lost executions
    expected_steps = expected_steps[expected_steps["seed"] < seeds].reset_index(drop=True)
    pd.testing.assert_frame_equal(steps, expected_steps, check_exact=True)


def test_killed_campaign_resumes_to_the_same_tables(tmp_path: Path, uninterrupted: Path) -> None:
    """SIGKILL mid-campaign, then resume: same tables as an uninterrupted run, no duplicates."""
    cfg = _write_config(tmp_path / "c.toml", "killed", "seeds_per_task = 4\n")
    out = tmp_path / "results" / "killed"
    args = ["ablate", str(cfg), "--seeds", "24", "--arch", ADAPTIVE, "--workers", "1", "-q"]
    # kill -9 right after the second of 6 tasks is journaled, however fast the machine is
    proc = _hooked("journal", 2, "SIGKILL", *args, stdout=subprocess.DEVNULL)
    assert proc.wait(timeout=HANG_S) == -signal.SIGKILL
    assert _events_done(out / "events.jsonl") == 2
    resumed = _cli(*args)  # the same command, in-process
    assert resumed.exit_code == 0, resumed.output
    _assert_same_as_uninterrupted(out, uninterrupted, seeds=24)


def _children(pid: int) -> list[int]:
    kids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                kids.append(int(entry.name))
    return kids


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_workers_exit_when_the_campaign_is_killed(tmp_path: Path) -> None:
    """No leaked processes: pool workers notice a killed parent and exit (NOTES item 7)."""
    cfg = _write_config(tmp_path / "c.toml", "orphans")
    args = ["ablate", str(cfg), "--seeds", "400", "--arch", ADAPTIVE, "--workers", "2", "-q"]
    proc = _hooked("journal", 1, "SIGSTOP", *args, stdout=subprocess.DEVNULL)
    wait_stopped(proc)  # frozen after its first task: its pool is running
    workers = [
        p for p in _children(proc.pid) if "spawn_main" in Path(f"/proc/{p}/cmdline").read_text()
    ]
    assert workers, "the pool should have started worker processes"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    hang = time.monotonic() + HANG_S  # they look for their parent once a second
    while any(Path(f"/proc/{p}").exists() for p in workers) and time.monotonic() < hang:
        time.sleep(0.1)
    alive = [p for p in workers if Path(f"/proc/{p}").exists()]
    for p in alive:
        os.kill(p, signal.SIGKILL)
    assert not alive, f"worker processes {alive} outlived the killed campaign"


def test_steps_seeds_limits_the_per_step_data(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path / "c.toml", "lean", "steps_seeds = 1\n")
    result = _cli("ablate", str(cfg), "--seeds", "2", "--arch", "mtf_adaptive", "-q", "--no-rrd",
                  "--workers", "1")  # fmt: skip
    assert result.exit_code == 0, result.output
    out = tmp_path / "results" / "lean"
    assert not (out / "recordings").exists()
    assert set(pd.read_parquet(out / "steps")["seed"]) == {0}
    assert set(pd.read_parquet(out / "solves")["seed"]) == {0, 1}
    assert len(pd.read_parquet(out / "runs.parquet")) == 2


def test_rrd_seeds_without_recordings_is_refused(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path / "c.toml", "contradiction")
    result = _cli("ablate", str(cfg), "--no-rrd", "--rrd-seeds", "2", "-q")
    assert result.exit_code == 2
    assert "--rrd-seeds" in result.output
    assert not (tmp_path / "results").exists()


def test_manifest_keeps_every_session(tmp_path: Path) -> None:
    """A resume adds a session; the first start time and the first session stay (issue 18)."""
    cfg = _write_config(tmp_path / "c.toml", "sessions")
    args = ("ablate", str(cfg), "--arch", ADAPTIVE, "--workers", "1", "-q", "--no-rrd")
    assert _cli(*args, "--seeds", "1").exit_code == 0
    first = json.loads((tmp_path / "results" / "sessions" / "manifest.json").read_text())
    assert _cli(*args, "--seeds", "2").exit_code == 0
    assert _cli(*args, "--seeds", "2").exit_code == 0  # nothing left to compute
    manifest = json.loads((tmp_path / "results" / "sessions" / "manifest.json").read_text())
    sessions = manifest["sessions"]
    assert [s["runs_computed"] for s in sessions] == [2, 2, 0]
    assert [s["runs_skipped"] for s in sessions] == [0, 2, 4]
    assert all(s["status"] == "complete" and s["finished_at"] for s in sessions)
    assert sessions[0] == first["sessions"][0]
    assert manifest["started_at"] == first["started_at"] == sessions[0]["started_at"]
    assert manifest["counts"] == {"ok": 4, "failed": 0, "runs": 4}


# --- infrastructure faults (issue 21): retried or stopped, never recorded as results ---


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_a_killed_worker_is_replaced_and_its_task_rerun(
    tmp_path: Path, uninterrupted: Path
) -> None:
    """kill -9 of one pool worker: every run ends ok, identical to an uninterrupted campaign."""
    cfg = _write_config(tmp_path / "c.toml", "workerkill", "seeds_per_task = 2\n")
    out = tmp_path / "results" / "workerkill"
    args = ["ablate", str(cfg), "--seeds", "24", "--arch", ADAPTIVE, "--workers", "2", "-q"]
    proc = _hooked("journal", 1, "SIGSTOP", *args, stdout=subprocess.DEVNULL,
                   stderr=subprocess.PIPE)  # fmt: skip
    wait_stopped(proc)  # frozen after the first of 12 tasks: the kill lands mid-campaign
    workers = [
        p for p in _children(proc.pid) if "spawn_main" in Path(f"/proc/{p}/cmdline").read_text()
    ]
    assert workers and _events_done(out / "events.jsonl") == 1
    os.kill(workers[0], signal.SIGKILL)
    proc.send_signal(signal.SIGCONT)
    _, stderr = proc.communicate(timeout=HANG_S)
    assert proc.returncode == 0, stderr
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 48 and (runs["status"] == "ok").all()  # nothing recorded as failed
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "complete"
    _assert_same_as_uninterrupted(out, uninterrupted, seeds=24)


def _process_ended(pid: int) -> bool:
    """Whether ``pid`` has exited (gone, or a zombie its parent has not reaped yet)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return True
    return fields[0] == "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_a_broken_pool_ends_its_surviving_workers(tmp_path: Path) -> None:
    """A worker dies: the pool ends the others, even one that a SIGTERM only asks to stop.

    cwrend's workers turn SIGTERM into a stop of their task, so the pool's
    ``terminate()`` left a survivor waiting for work on a lock its dead
    sibling held, and the pool's shutdown waited for it for ever (a CI run
    of the test above hung for 600 s; reproduced 2 in 6 by killing a worker
    0-0.3 s after the first task). Here the survivor is busy and ignores
    SIGTERM outright: without a SIGKILL it never ends.
    """
    marker = tmp_path / "holder.pid"
    with open_executor("local", 2) as (pool, _):
        held = pool.submit(pool_tasks.hold, str(marker))
        hang = time.monotonic() + HANG_S
        while not marker.exists() or not marker.read_text():  # a state: the task is running
            assert time.monotonic() < hang, "the held task never started"
            time.sleep(0.01)
        holder = int(marker.read_text())
        others = [p.pid for p in pool._processes.values() if p.pid not in (holder, None)]
        os.kill(others[0], signal.SIGKILL)
        with pytest.raises(BrokenProcessPool):
            held.result(timeout=HANG_S)
        while not _process_ended(holder):
            if time.monotonic() > hang:
                os.kill(holder, signal.SIGKILL)  # let the pool shut down, then fail
                pytest.fail("the pool left its surviving worker running: its shutdown would hang")
            time.sleep(0.01)


def test_a_full_disk_stops_the_campaign_with_exit_3_and_records_no_result(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """ENOSPC while a worker writes its files (simulated in the writer): stop, keep, resume."""
    cfg = _write_config(tmp_path / "c.toml", "full", "seeds_per_task = 1\n")
    out = tmp_path / "results" / "full"
    real_write = worker_module.write_parquet
    calls = {"n": 0}

    def filling_disk(table: Any, path: Path, **options: Any) -> None:
        calls["n"] += 1
        if calls["n"] > 6:  # the first three tasks' steps and solves fit; then the disk is full
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real_write(table, path, **options)

    monkeypatch.setattr(worker_module, "write_parquet", filling_disk)
    args = ["ablate", str(cfg), "--seeds", "6", "--arch", "mtf_adaptive", "--workers", "1", "-q"]
    result = _cli(*args)
    assert result.exit_code == 3, result.output
    assert "campaign stopped: disk full" in result.stderr and "Traceback" not in result.output
    assert "3 of 6 run(s) are done" in result.stderr, result.stderr
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"].startswith("stopped: disk full")
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 3 and (runs["status"] == "ok").all()  # nothing recorded for the fault
    monkeypatch.setattr(worker_module, "write_parquet", real_write)  # space freed
    resumed = _cli(*args)
    assert resumed.exit_code == 0, resumed.output
    assert json.loads((out / "manifest.json").read_text())["status"] == "complete"
    whole = _cli("ablate", str(_write_config(tmp_path / "w.toml", "whole")), *args[2:])
    assert whole.exit_code == 0, whole.output
    pd.testing.assert_frame_equal(_runs(out), _runs(tmp_path / "results" / "whole"))
    pd.testing.assert_frame_equal(
        _steps(out), _steps(tmp_path / "results" / "whole"), check_exact=True
    )


def test_a_lost_task_is_retried_then_the_campaign_stops_with_exit_3(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A task that never comes back (not an I/O error) is retried, then the campaign stops."""
    cfg = _write_config(tmp_path / "c.toml", "lost")
    monkeypatch.setattr(driver_module, "RETRY_BACKOFF_S", 0.0)
    attempts = {"n": 0}

    def lost(*args: Any, **kwargs: Any) -> Any:
        attempts["n"] += 1
        raise RuntimeError("worker lost")

    monkeypatch.setattr(driver_module, "execute_task", lost)
    result = _cli("ablate", str(cfg), "--seeds", "1", "--arch", "mtf_adaptive", "--workers", "1")
    assert result.exit_code == 3, result.output
    assert attempts["n"] == driver_module.MAX_TASK_ATTEMPTS
    assert "was lost 3 times, last: RuntimeError: worker lost" in result.stderr
    runs = pd.read_parquet(tmp_path / "results" / "lost" / "runs.parquet")
    assert runs.empty  # no run recorded as failed for a fault of the machine


def test_an_append_after_a_torn_journal_line_keeps_its_events(tmp_path: Path) -> None:
    path = tmp_path / "events.jsonl"
    journal.append_events(path, [{"event": "a"}])
    with open(path, "a", encoding="utf-8") as fh:
        fh.write('{"event": "tor')  # a kill -9 or a full disk mid-write
    journal.append_events(path, [{"event": "b"}, {"event": "c"}])
    assert [e["event"] for e in journal.read_events(path)] == ["a", "b", "c"]


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("foo://bar", "not a Dask scheduler address; give the scheduler as tcp://host:port"),
        ("nohost", "not a Dask scheduler address"),
        ("tcp://127.0.0.1:{port}", "cannot reach the Dask scheduler within 5 s"),
    ],
)
def test_a_bad_dask_address_exits_2_before_anything_is_written(
    tmp_path: Path, address: str, message: str
) -> None:
    cfg = _write_config(tmp_path / "c.toml", "dask")
    address = address.format(port=_free_port())
    result = _cli("ablate", str(cfg), "--executor", "dask", "--address", address, "-n", "1")
    assert result.exit_code == 2, result.output
    assert message in result.stderr and "Traceback" not in result.output
    assert not (tmp_path / "results").exists()


def test_a_campaign_computed_by_another_version_is_refused(tmp_path: Path) -> None:
    """Issue 21 item 4: resuming mixes numbers of two installations only when asked."""
    cfg = _write_config(tmp_path / "c.toml", "versions")
    out = tmp_path / "results" / "versions"
    args = ["ablate", str(cfg), "--seeds", "1", "--arch", "mtf_adaptive", "--workers", "1", "-q"]
    assert _cli(*args).exit_code == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["environment"] == journal.environment()
    events = journal.read_events(out / "events.jsonl")
    assert {e["cwrend_version"] for e in events} == {manifest["cwrend_version"]}
    manifest["environment"]["numpy"] = "1.0.0"
    (out / "manifest.json").write_text(json.dumps(manifest))
    refused = _cli(*args[:3], "2", *args[4:])
    assert refused.exit_code == 2
    assert "other versions (numpy 1.0.0 → " in refused.stderr
    assert "--allow-version-change" in refused.stderr
    assert len(pd.read_parquet(out / "runs.parquet")) == 1  # nothing was computed
    plan_ = campaign.plan(load_config(cfg), ["mtf_adaptive"], [0, 1])
    summary = campaign.run_campaign(plan_, out, command="ablate", workers=1,
                                    allow_version_change=True)  # fmt: skip
    assert summary.executed == 1 and summary.ok == 2


# --- confinement and exclusive use (issue 20, items 3 and 5) -----------------


@pytest.mark.parametrize("force", [False, True])
def test_a_symlinked_dataset_is_refused_and_never_written_through(
    tmp_path: Path, force: bool
) -> None:
    cfg = _write_config(tmp_path / "c.toml", "linked")
    out = tmp_path / "results" / "linked"
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "precious.txt").write_text("not cwrend's")
    out.mkdir(parents=True)
    (out / "steps").symlink_to(elsewhere, target_is_directory=True)
    args = ["ablate", str(cfg), "-n", "1", "--arch", "mtf_adaptive", "--workers", "1"]
    result = _cli(*args, *(["--force"] if force else []))
    assert result.exit_code == 2, result.output
    assert "a symbolic link inside the campaign directory" in result.stderr
    assert "Traceback" not in result.output
    assert [p.name for p in elsewhere.iterdir()] == ["precious.txt"]  # nothing written or removed
    assert (out / "steps").is_symlink() and not (out / "runs.parquet").exists()


def test_an_output_dir_that_is_a_file_exits_2_naming_it(tmp_path: Path) -> None:
    (tmp_path / "afile").write_text("")
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path / "afile"}"\nname = "x"\n')
    result = _cli("ablate", str(cfg), "-n", "1", "--arch", "mtf_adaptive", "--workers", "1")
    assert result.exit_code == 2, result.output
    assert f"'{tmp_path / 'afile' / 'x'}': cannot write results there" in result.stderr


def test_a_second_process_on_the_same_campaign_is_refused(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path / "c.toml", "busy", "seeds_per_task = 1\n")
    args = ["ablate", str(cfg), "--seeds", "400", "--arch", ADAPTIVE, "--workers", "1", "-q"]
    first = _hooked("journal", 1, "SIGSTOP", *args, stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        wait_stopped(first)  # frozen mid-campaign, holding the lock
        second = _cli("ablate", str(cfg), "--seeds", "300", "--arch", ADAPTIVE, "-q")
        assert second.exit_code == 2, second.output
        assert f"is in use by another cwrend process (pid {first.pid}, since" in second.stderr
    finally:
        first.kill()
        first.wait()
    after = _cli("ablate", str(cfg), "--seeds", "2", "--arch", ADAPTIVE, "-q", "--workers", "1")
    assert after.exit_code == 0, after.output  # the kernel released the killed holder's lock


# --- Ctrl-C (issue 20, item 4) -------------------------------------------------


def _sigint_default() -> None:
    """In the child: SIGINT at its default, as in a terminal.

    A process started with SIGINT ignored (a shell's ``cmd &``) passes that on,
    and Python then installs no KeyboardInterrupt handler: Ctrl-C would do
    nothing and these tests would test the harness, not cwrend.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_stops_a_two_worker_campaign_quickly_and_it_resumes_identically(
    tmp_path: Path, uninterrupted: Path
) -> None:
    """SIGINT to the process group: exit 130 within seconds, true counts, identical resume."""
    cfg = _write_config(tmp_path / "c.toml", "ctrlc", "seeds_per_task = 2\n")
    out = tmp_path / "results" / "ctrlc"
    args = ["ablate", str(cfg), "--seeds", "40", "--arch", ADAPTIVE, "--workers", "2", "--no-rrd"]
    # Ctrl-C to the process group (as a terminal sends it) once 2 of 20 tasks are journaled
    proc = _hooked("journal", 2, "SIGINT", *args, stdout=subprocess.DEVNULL,
                   stderr=subprocess.PIPE, start_new_session=True,
                   preexec_fn=_sigint_default)  # fmt: skip
    _, stderr = proc.communicate(timeout=HANG_S)
    assert proc.returncode == 130, stderr
    held = len(pd.read_parquet(out / "runs.parquet"))
    assert 8 <= held < 80  # the two tasks journaled, and what the others finished
    assert f"interrupted: {held} of 80 runs done ({held} computed now), 0 failed" in stderr
    assert "run the same command to resume" in stderr and "Traceback" not in stderr
    assert json.loads((out / "manifest.json").read_text())["status"] == "interrupted"
    # what Ctrl-C left must resume to the same tables: the same command, in-process and on
    # one worker (a two-worker pool costs ~10 s of start-up; the numbers do not depend on it)
    resumed = _cli(*args[: args.index("--workers")], "--workers", "1", "--no-rrd")
    assert resumed.exit_code == 0, resumed.output
    _assert_same_as_uninterrupted(out, uninterrupted, seeds=40)


@pytest.mark.parametrize(("sig", "code"), [("SIGINT", 130), ("SIGTERM:self", 143)])
def test_a_stop_swallowed_by_a_compile_still_drops_the_run_and_resumes_identically(
    tmp_path: Path, uninterrupted: Path, sig: str, code: int
) -> None:
    """Ctrl-C to the process group, or ``kill <pid>``, landing where compiled code calls back
    into Python (numba's compiler, on a first run), where its exception cannot propagate: it
    is raised again, so the run compiling is dropped and none starts after it; the two tasks
    journaled before are kept, and the campaign resumes to the uninterrupted tables."""
    # no run time limit: it would end the "compile" as it ends a run (numba's own pauses it)
    cfg = _write_config(
        tmp_path / "c.toml", "compile", "seeds_per_task = 4\nrun_timeout_s = 86400\n"
    )
    out = tmp_path / "results" / "compile"
    args = ["ablate", str(cfg), "--seeds", "24", "--arch", ADAPTIVE, "--workers", "1", "-q",
            "--no-rrd"]  # fmt: skip
    # the first run of the third task of 6 (8 runs each) compiles, and the signal lands there
    proc = _hooked("compile", 17, sig, *args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                   start_new_session=True, preexec_fn=_sigint_default)  # fmt: skip
    _, stderr = proc.communicate(timeout=2 * HANG_S)
    assert proc.returncode == code, stderr
    assert "Traceback" not in stderr and "Exception ignored" not in stderr, stderr
    assert len(pd.read_parquet(out / "runs.parquet")) == 16  # no run finished after the signal
    resumed = _cli(*args)
    assert resumed.exit_code == 0, resumed.output
    _assert_same_as_uninterrupted(out, uninterrupted, seeds=24)


def test_sigterm_to_the_process_group_keeps_the_runs_the_workers_finished(
    tmp_path: Path, uninterrupted: Path
) -> None:
    """A batch scheduler's time limit (Slurm sends SIGTERM to every process of the job), once
    a run is heard: the workers stop their tasks and return the runs they finished instead
    of dying with them; exit 143, true counts, and the campaign resumes identically."""
    cfg = _write_config(tmp_path / "c.toml", "term", "seeds_per_task = 8\n")
    out = tmp_path / "results" / "term"
    args = ["ablate", str(cfg), "--seeds", "16", "--arch", ADAPTIVE, "--workers", "2", "--no-rrd"]
    proc = _hooked("run", 1, "SIGTERM", *args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                   start_new_session=True, preexec_fn=_sigint_default)  # fmt: skip
    _, stderr = proc.communicate(timeout=HANG_S)
    assert proc.returncode == 143, stderr
    held = len(pd.read_parquet(out / "runs.parquet"))
    assert held >= 1  # the run heard before the signal, at least: its task came back
    assert f"interrupted: {held} of 32 runs done ({held} computed now), 0 failed" in stderr
    assert "Traceback" not in stderr, stderr
    resumed = _cli(*args[: args.index("--workers")], "--workers", "1", "--no-rrd")
    assert resumed.exit_code == 0, resumed.output
    _assert_same_as_uninterrupted(out, uninterrupted, seeds=16)


def test_ctrl_c_during_start_up_exits_130_without_a_traceback(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path / "c.toml", "early")
    proc = subprocess.Popen(
        [sys.executable, "-m", "cwrend_cli", "ablate", str(cfg), "-n", "50", "--workers", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        preexec_fn=_sigint_default,
    )  # fmt: skip
    # Ctrl-C while the command imports its heavy libraries: once numpy's core is loaded (a
    # fixed 0.3 s could fall before the interpreter's own start-up was over on a loaded
    # machine, where a Ctrl-C is Python's fatal error, not cwrend's)
    _wait_until_loaded(proc.pid, "_multiarray_umath")
    os.killpg(proc.pid, signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr + stdout


def _wait_until_loaded(pid: int, library: str, timeout_s: float = HANG_S) -> None:
    """Wait until process ``pid`` has mapped a library named ``library`` (/proc; else 0.3 s)."""
    maps = Path(f"/proc/{pid}/maps")
    if not maps.exists():
        time.sleep(0.3)  # importing numba, scipy and pandas takes about a second
        return
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if library in maps.read_text():
            return
        time.sleep(0.002)
    raise AssertionError(f"process {pid} did not load {library} in {timeout_s} s")


def test_a_lost_manifest_does_not_let_another_config_reuse_the_runs(tmp_path: Path) -> None:
    """Issue 20 item 2: the journal's records name their campaign; a mismatch is refused."""
    cfg = _write_config(tmp_path / "c.toml", "nomanifest")
    out = tmp_path / "results" / "nomanifest"
    args = ["ablate", str(cfg), "-n", "1", "--arch", "mtf_adaptive", "--workers", "1", "-q"]
    assert _cli(*args).exit_code == 0
    (out / "manifest.json").unlink()
    changed = _cli(*args, "--set", "schedule.beta=0.5")
    assert changed.exit_code == 2, changed.output
    assert "has no manifest.json but its journal holds runs of another campaign" in changed.stderr
    same = _cli(*args)  # the same campaign may resume without its manifest
    assert same.exit_code == 0, same.output


@pytest.mark.parametrize("content", [b"[]", b"null", b"\xff\xfe\x00garbage"])
def test_a_corrupt_manifest_exits_2_with_the_fix(tmp_path: Path, content: bytes) -> None:
    cfg = _write_config(tmp_path / "c.toml", "corrupt")
    out = tmp_path / "results" / "corrupt"
    out.mkdir(parents=True)
    (out / "manifest.json").write_bytes(content)
    result = _cli("ablate", str(cfg), "-n", "1", "--arch", "mtf_adaptive", "--workers", "1")
    assert result.exit_code == 2, result.output
    assert "manifest.json: damaged manifest (" in result.stderr
    assert "with --repair-manifest to rebuild it from the journal" in result.stderr
    assert "Traceback" not in result.output


# --- runs that fail without raising (issue 21, items 1 and 3) ---------------------


def test_a_run_with_non_finite_estimates_is_recorded_failed_naming_the_quantity(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cfg = _write_config(tmp_path / "c.toml", "nonfinite")
    real = worker_module.simulation.simulate

    def overflowing(*args: Any, **kwargs: Any) -> simulation.RunResult:
        # no accepted configuration overflows any more (issue 36 item 7): the estimate of
        # a run is made to overflow at t = 326 s, as a 1e308 km bias used to
        run = real(*args, **kwargs)
        x_hat = run.x_hat.copy()
        x_hat[326:, 0] = np.inf
        return dataclasses.replace(run, x_hat=x_hat)

    monkeypatch.setattr(worker_module.simulation, "simulate", overflowing)
    result = _cli("ablate", str(cfg), "-n", "1", "--arch", "mtf_adaptive", "--workers", "1", "-q")
    assert result.exit_code == 1, result.output  # some runs failed
    runs = pd.read_parquet(tmp_path / "results" / "nonfinite" / "runs.parquet")
    assert len(runs) == 1 and (runs["status"] == "failed").all()
    assert runs["error"].str.contains(r"non-finite estimate \(x_hat\) from t = 326 s").all()


def test_a_run_past_its_time_limit_is_recorded_timed_out_and_the_campaign_goes_on(
    tmp_path: Path,
) -> None:
    cfg = _write_config(tmp_path / "c.toml", "slow", "seeds_per_task = 1\n")
    result = _cli("ablate", str(cfg), "-n", "3", "--arch", "mtf_adaptive", "--workers", "1",
                  "-q", "--set", "output.run_timeout_s=1e-6")  # fmt: skip
    assert result.exit_code == 1, result.output
    runs = pd.read_parquet(tmp_path / "results" / "slow" / "runs.parquet")
    assert len(runs) == 3 and (runs["status"] == "failed").all()  # every task ran
    assert runs["error"].str.contains("timed out: the run took longer than 1e-06 s").all()
    retried = _cli("ablate", str(cfg), "-n", "3", "--arch", "mtf_adaptive", "--workers", "1",
                   "-q", "--retry-failed")  # fmt: skip
    assert retried.exit_code == 0, retried.output  # the default limit lets them finish


def test_a_disk_without_room_for_the_first_task_stops_before_computing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 21 item 2: the room is checked before anything is computed (exit 3, nothing run)."""
    cfg = _write_config(tmp_path / "c.toml", "noroom")
    real = driver_module.shutil.disk_usage

    def almost_full(path: Any) -> Any:
        return real(path)._replace(free=100_000)  # 0.1 MB: less than one task's files

    monkeypatch.setattr(driver_module.shutil, "disk_usage", almost_full)
    result = _cli("ablate", str(cfg), "-n", "2", "--arch", "mtf_adaptive", "--workers", "1")
    assert result.exit_code == 3, result.output
    assert "campaign stopped: disk full: 0.1 MB free" in result.stderr
    out = tmp_path / "results" / "noroom"
    assert json.loads((out / "manifest.json").read_text())["status"].startswith("stopped: disk")
    assert pd.read_parquet(out / "runs.parquet").empty and not (out / "steps").exists()


# --- chunking (issue 17) --------------------------------------------------------------


def test_default_seeds_per_task_leaves_four_tasks_per_worker_up_to_16_seeds() -> None:
    from cwrend_cli.campaign.plan import default_seeds_per_task  # the package's `plan` is plan()

    assert default_seeds_per_task(100, 1, 2) == 12  # 9 tasks for 2 workers
    assert default_seeds_per_task(1000, 1, 2) == 16  # the cap
    assert default_seeds_per_task(5, 1, 8) == 1  # never fewer than one seed
    assert default_seeds_per_task(20, 10, 2) == 16  # grid points make tasks too
    assert default_seeds_per_task(100, 1, None) == 16  # unknown worker count


def test_unset_seeds_per_task_follows_the_workers_and_a_set_one_wins() -> None:
    cfg = CwrendConfig()
    assert cfg.output.seeds_per_task is None
    by_workers = campaign.plan(cfg, ["mtf_adaptive"], list(range(100)), workers=2)
    assert len(by_workers.tasks) == 9 and {len(t.runs) for t in by_workers.tasks} == {12, 4}
    set_cfg = config_from_dict({"output": {"seeds_per_task": 5}})
    assert len(campaign.plan(set_cfg, ["mtf_adaptive"], list(range(100)), workers=2).tasks) == 20
    # the chunking changes the tasks only: the same runs, keys and values
    default = campaign.plan(cfg, ["mtf_adaptive"], list(range(100)))
    assert by_workers.runs == default.runs and by_workers.campaign_hash == default.campaign_hash


def test_resume_with_another_chunking_computes_only_the_missing_runs(tmp_path: Path) -> None:
    """Runs are keyed by point, architecture and seed, not by task: any chunking resumes."""
    cfg = _write_config(tmp_path / "c.toml", "chunks")
    out = tmp_path / "results" / "chunks"
    base = ["ablate", str(cfg), "--arch", ADAPTIVE, "--workers", "1", "--no-rrd"]
    first = _cli(*base, "--seeds", "6", "--set", "output.seeds_per_task=4")
    assert first.exit_code == 0, first.output
    second = _cli(*base, "--seeds", "10", "--set", "output.seeds_per_task=3")
    assert second.exit_code == 0, second.output
    assert "12 run(s) already done, 8 to compute" in second.stderr
    assert "8 run(s) computed, 12 already done" in second.stderr
    whole_cfg = _write_config(tmp_path / "w.toml", "whole")
    whole = _cli("ablate", str(whole_cfg), "--arch", ADAPTIVE, "--workers", "1", "--no-rrd",
                 "--seeds", "10")  # fmt: skip
    assert whole.exit_code == 0, whole.output
    key = ["run_key"]
    pd.testing.assert_frame_equal(
        _runs(out).sort_values(key).reset_index(drop=True),
        _runs(tmp_path / "results" / "whole").sort_values(key).reset_index(drop=True),
    )
    steps = _steps(out)
    assert len(steps) == 20 * 801  # nothing computed twice
    pd.testing.assert_frame_equal(steps, _steps(tmp_path / "results" / "whole"), check_exact=True)


class _BrokenPool(concurrent.futures.Executor):
    """A local pool that broke as a task was submitted: its futures never complete.

    What Python's pool leaves when a worker dies as the driver submits (it
    marks itself broken without the lock ``submit`` holds): broken, its
    management thread ended, the new task's future pending for ever.
    """

    _broken = "A child process terminated abruptly, the process pool is not usable anymore"
    _executor_manager_thread = None

    def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> concurrent.futures.Future[Any]:
        return concurrent.futures.Future()


def test_a_task_a_broken_pool_never_completes_runs_again_on_a_fresh_pool(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, bounded_wait: Callable[..., Any]
) -> None:
    """The driver counts a broken pool's pending futures lost (a state, not a time) and reruns
    their tasks: the campaign completes instead of waiting for ever."""
    real_open = driver_module.open_executor
    openings: list[str] = []

    @contextlib.contextmanager
    def open_executor(kind: Any, workers: Any, address: Any) -> Iterator[tuple[Any, int]]:
        openings.append(kind)
        if len(openings) == 1:
            yield _BrokenPool(), 1
        else:
            with real_open(kind, 1, address) as opened:
                yield opened

    monkeypatch.setattr(driver_module, "open_executor", open_executor)
    monkeypatch.setattr(
        driver_module, "wait", bounded_wait(1_000, "the campaign waits for ever on a broken pool")
    )
    monkeypatch.setattr(driver_module, "_SIGNAL_POLL_S", 0.001)
    monkeypatch.setattr(driver_module, "RETRY_BACKOFF_S", 0.0)
    cfg = _write_config(tmp_path / "c.toml", "broken")
    result = _cli("ablate", str(cfg), "-n", "2", "--arch", "mtf_adaptive", "--workers", "1")
    assert result.exit_code == 0, result.output
    assert len(openings) == 2
    runs = pd.read_parquet(tmp_path / "results" / "broken" / "runs.parquet")
    assert len(runs) == 2 and (runs["status"] == "ok").all()


def test_an_executor_that_lost_its_scheduler_does_not_hang_the_campaign(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, stalled_executor: Callable[..., Any]
) -> None:
    """A Dask client may reconnect forever while its futures wait: the driver gives up (exit 3)."""

    class _LostClient:
        status = "connecting"  # what distributed.Client says while it looks for its scheduler

    monkeypatch.setattr(driver_module, "open_executor", stalled_executor(_LostClient()))
    monkeypatch.setattr(driver_module, "_POLL_S", 0.05)
    monkeypatch.setattr(driver_module, "DASK_LOST_AFTER_S", 0.2)
    monkeypatch.setattr(driver_module, "RETRY_BACKOFF_S", 0.0)
    cfg = _write_config(tmp_path / "c.toml", "stalled")
    result = _cli("ablate", str(cfg), "-n", "1", "--arch", "mtf_adaptive", "--workers", "1")
    assert result.exit_code == 3, result.output
    assert "was lost 3 times, last: RuntimeError: the executor lost its scheduler" in result.stderr


SAFE_APPROACH = Path(__file__).resolve().parents[1] / "campaigns" / "safe_approach.toml"
#: The safe approach's port typed in metres: out of reach of u_max within the horizon.
PORT_IN_METRES = "constraints.corridor.port_km=[0, 0, -250]"


def test_an_unreachable_port_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    out_dir = f"output.dir={json.dumps(str(tmp_path / 'results'))}"
    result = _cli("ablate", str(SAFE_APPROACH), "--arch", "plain_adaptive", "--seeds", "1",
                  "--workers", "1", "--set", PORT_IN_METRES, "--set", out_dir)  # fmt: skip
    assert result.exit_code == 2, result.output
    assert "error: scenario infeasible: no control with |u| <= scenario.u_max_km_s2" in (
        result.stderr
    )
    assert "Traceback" not in result.output
    assert not (tmp_path / "results").exists()


def test_a_sweep_with_an_unreachable_point_is_refused_naming_the_point(tmp_path: Path) -> None:
    out_dir = f"output.dir={json.dumps(str(tmp_path / 'results'))}"
    param = "constraints.corridor.port_km=[[0, 0, -0.25], [0, 0, -250]]"
    result = _cli("sweep", str(SAFE_APPROACH), "--param", param, "--arch", "plain_adaptive",
                  "--seeds", "1", "--workers", "1", "--set", out_dir)  # fmt: skip
    assert result.exit_code == 2, result.output
    assert "constraints.corridor.port_km = [0, 0, -250]): scenario infeasible" in result.stderr
    assert not (tmp_path / "results").exists()


@pytest.fixture
def computed_references(monkeypatch: pytest.MonkeyPatch) -> list[object]:
    """The scenarios whose open-loop references are computed in this process, in order."""
    computed: list[object] = []
    references = simulation.open_loop_references

    def counted(problem: Any) -> Any:
        computed.append(problem.scenario)
        return references(problem)

    monkeypatch.setattr(simulation, "open_loop_references", counted)
    return computed


def test_a_rerun_of_a_finished_campaign_computes_no_references(
    tmp_path: Path, computed_references: list[object]
) -> None:
    """The check before a campaign skips the points whose references the directory holds
    already: a rerun that computes nothing waits for no reference (one per distinct
    scenario: a design over scenario values has thousands)."""
    cfg = _write_config(tmp_path / "c.toml", "rerun")
    args = ["sweep", str(cfg), "--param", "scenario.u_max_km_s2=8e-4,1e-3", "--arch",
            "mtf_adaptive", "--seeds", "1", "--workers", "1", "-q", "--no-rrd"]  # fmt: skip
    assert _cli(*args).exit_code == 0
    assert len(computed_references) == 2  # two scenarios, each once
    result = _cli(*args)
    assert result.exit_code == 0, result.output
    assert len(computed_references) == 2  # none again
    assert _cli(*args, "--force").exit_code == 0
    assert len(computed_references) == 4  # --force starts over: both again


def test_the_references_checked_before_the_campaign_are_not_computed_again(
    tmp_path: Path, computed_references: list[object]
) -> None:
    cfg = _write_config(tmp_path / "c.toml", "once")
    result = _cli("sweep", str(cfg), "--param", "schedule.beta=0.25,0.5", "--arch",
                  "mtf_adaptive", "--seeds", "1", "--workers", "1", "-q", "--no-rrd")  # fmt: skip
    assert result.exit_code == 0, result.output
    assert len(computed_references) == 1  # one scenario (beta is no part of it), computed once
