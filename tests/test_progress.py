"""Progress that tells the truth (issue 17, item 3): per-run advances, a steady ETA.

The driver reports every finished run (the local pool through a queue its
workers inherit, in-process at once; a Dask cluster per task), settles each
task execution when it comes back and takes back the runs of one that was
lost. The ETA (:func:`cwrend_cli.console.progress_pace`) is checked on
constructed timelines of 2-worker campaigns, whose runs cost several times
more on some seeds than on others, as the real ones do.
"""

from __future__ import annotations

import heapq
import random
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from cwrend_cli import campaign
from cwrend_cli.campaign import driver as driver_module
from cwrend_cli.campaign import executors
from cwrend_cli.config import config_from_dict
from cwrend_cli.console import Mark, progress_pace


def _plan(tmp_path: Path, seeds: int, per_task: int) -> campaign.CampaignPlan:
    cfg = config_from_dict({"output": {"dir": str(tmp_path), "rrd_seeds": 0, "steps_seeds": 0}})
    return campaign.plan(cfg, ["mtf_adaptive"], list(range(seeds)), seeds_per_task=per_task)


# --- the driver reports runs ------------------------------------------------------------


def test_a_task_of_4_seeds_in_process_advances_4_times_by_one_run(
    tmp_path: Path, recording_progress
) -> None:
    """Before issue 17 the progress saw one advance of 4 when the task came back."""
    plan = _plan(tmp_path, 4, 4)
    assert len(plan.tasks) == 1
    recorder = recording_progress()
    campaign.run_campaign(plan, tmp_path / "c", command="ablate", workers=1, progress=recorder)
    assert recorder.advances == [1, 1, 1, 1]


def test_pool_workers_signal_each_run(tmp_path: Path, recording_progress) -> None:
    """2 workers, 2 tasks of 4 runs: the bar moves run by run, and counts each run once.

    A task's last signals may still be in the queue when its result arrives;
    the driver then counts them with the result (so an advance of 2 can
    happen, rarely), and ignores them when they arrive.
    """
    plan = _plan(tmp_path, 8, 4)
    recorder = recording_progress()
    campaign.run_campaign(plan, tmp_path / "c", command="ablate", workers=2, progress=recorder)
    assert sum(recorder.advances) == recorder.total == 8
    assert len(recorder.advances) >= 6 and min(recorder.advances) >= 1


@contextmanager
def _thread_pool(*args: Any, **kwargs: Any) -> Iterator[tuple[ThreadPoolExecutor, int]]:
    """An executor the driver has no run signals for (as a Dask client)."""
    with ThreadPoolExecutor(1) as pool:
        yield pool, 1


def test_an_executor_without_signals_advances_per_task(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, recording_progress
) -> None:
    monkeypatch.setattr(driver_module, "open_executor", _thread_pool)
    plan = _plan(tmp_path, 4, 2)
    recorder = recording_progress()
    campaign.run_campaign(plan, tmp_path / "c", command="ablate", workers=2, progress=recorder)
    assert recorder.advances == [2, 2]


def test_the_runs_of_a_lost_execution_are_taken_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, recording_progress
) -> None:
    """Two runs signalled, then the execution is lost: −2, and the retried task's 4 runs."""
    monkeypatch.setattr(driver_module, "RETRY_BACKOFF_S", 0.0)
    real = driver_module.execute_task
    calls = {"n": 0}

    def lost_once(*args: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 1:
            on_run = args[-1]
            on_run(True)
            on_run(True)
            raise RuntimeError("worker lost")
        return real(*args)

    monkeypatch.setattr(driver_module, "execute_task", lost_once)
    plan = _plan(tmp_path, 4, 4)
    recorder = recording_progress()
    summary = campaign.run_campaign(
        plan, tmp_path / "c", command="ablate", workers=1, progress=recorder
    )
    assert recorder.advances == [1, 1, -2, 1, 1, 1, 1]
    assert summary.executed == summary.ok == 4


class _Listener:
    def __init__(self) -> None:
        self.advances: list[tuple[int, int]] = []

    def start(self, total: int, skipped: int) -> None:
        pass

    def advance(self, ok: int, failed: int) -> None:
        self.advances.append((ok, failed))

    def close(self) -> None:
        pass


def test_a_tally_settles_each_execution_once() -> None:
    """Signals advance at once; the result adds what was not heard; late signals are ignored."""
    progress = _Listener()
    tally = driver_module._RunTally(progress)
    tally.open(0)
    tally.heard(0, True)
    tally.heard(0, False)
    tally.completed(0, ok=2, failed=1)  # one ok run's signal still in the queue
    tally.heard(0, True)  # ... arrives now: already counted
    tally.open(1)
    tally.completed(1, ok=3, failed=0)  # no signals at all (a Dask task)
    assert progress.advances == [(1, 0), (0, 1), (1, 0), (3, 0)]


def test_signals_reach_the_listener_only_for_the_local_pool_and_in_process() -> None:
    heard: list[tuple[int, bool]] = []
    inline = executors.run_signals(executors.InlineExecutor(), lambda t, ok: heard.append((t, ok)))
    signal = inline.signal(7)
    assert signal is not None
    signal(False)
    assert heard == [(7, False)]
    with ThreadPoolExecutor(1) as other:
        assert executors.run_signals(other, lambda t, ok: None).signal(0) is None


# --- the ETA ----------------------------------------------------------------------------


def _timeline(
    seeds: int, per_task: int, seed: int, per_run: bool = True
) -> tuple[list[float], list[int]]:
    """Completions of a constructed 2-worker, 4-architecture campaign (clock [s], runs done).

    Workers start 5 s and 5.3 s in (start-up); a seed's runs cost a lognormal
    factor (σ = 0.6: some seeds several times dearer) times 12 ms (adaptive)
    or 70 ms (fixed ε), ±20 %; a task writes its files for 30 ms at the end.
    Tasks go to the first free worker. ``per_run=False``: one completion per
    task, as the progress saw it before issue 17.
    """
    rng = random.Random(seed)
    free = [(5.0, 0), (5.3, 1)]
    events: list[tuple[float, int]] = []
    for start in range(0, seeds, per_task):
        clock, worker = heapq.heappop(free)
        runs = []
        for _ in range(start, min(start + per_task, seeds)):
            hard = rng.lognormvariate(0.0, 0.6)
            for cost in (0.012, 0.07, 0.012, 0.07):
                clock += cost * hard * rng.uniform(0.8, 1.2)
                runs.append(clock)
        clock += 0.03
        runs[-1] = clock
        events += [(t, 1) for t in runs] if per_run else [(clock, len(runs))]
        heapq.heappush(free, (clock, worker))
    events.sort()
    times = [t for t, _ in events]
    done = [sum(n for _, n in events[: i + 1]) for i in range(len(events))]
    return times, done


def _eta_at(times: list[float], done: list[int], fraction: float) -> tuple[float | None, float]:
    """The ETA when ``fraction`` of the runs are done, and the true time left then."""
    total = done[-1]
    k = next(i for i, d in enumerate(done) if d >= fraction * total)
    first: Mark = (times[0], done[0])
    last: Mark = (times[k], done[k])
    _, eta = progress_pace(first, last, total, times[k])
    return eta, times[-1] - times[k]


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("fraction", [0.1, 0.25, 0.5, 0.75])
def test_eta_is_within_20_percent_after_10_percent_of_a_1000_seed_ablation(
    seed: int, fraction: float
) -> None:
    times, done = _timeline(1000, 16, seed)
    eta, left = _eta_at(times, done, fraction)
    assert eta is not None
    assert abs(eta - left) <= 0.2 * left


def test_a_per_task_progress_had_no_eta_at_10_percent_of_a_100_seed_ablation() -> None:
    """What issue 17 saw: 16-seed tasks, nothing to estimate from at 10 % (and then 0 → 128)."""
    times, done = _timeline(100, 16, 0, per_run=False)
    assert done[0] == 64
    eta, _ = _eta_at(times, done, 0.1)
    assert eta is None
    eta, _ = _eta_at(*_timeline(100, 16, 0), 0.1)
    assert eta is not None


def test_the_eta_counts_down_between_completions_and_ignores_start_up() -> None:
    """10 s of start-up before the first run do not enter the rate."""
    rate, eta = progress_pace((10.0, 1), (12.0, 41), 401, 12.0)
    assert rate == pytest.approx(20.0)
    assert eta == pytest.approx(360 / 20.0)
    assert progress_pace((10.0, 1), (12.0, 41), 401, 13.5)[1] == pytest.approx(360 / 20.0 - 1.5)
    assert progress_pace((10.0, 1), (10.0, 1), 401, 11.0) == (None, None)
    assert progress_pace(None, None, 401, 11.0) == (None, None)
