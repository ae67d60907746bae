"""Driving a campaign: resume, fan-out, journal, references and statistics.

:func:`run_campaign` executes the runs of a :class:`~cwrend_cli.campaign.plan.CampaignPlan`
that a campaign directory does not hold yet: it checks the manifest, cleans
orphans of interrupted executions, submits tasks to an executor with a
bounded number in flight (:func:`~cwrend_cli.campaign.worker.execute_task`)
and journals each as it completes, then writes ``runs.parquet`` and the
manifest. It computes each grid point's open-loop references when the
point's first task is submitted (once per distinct scenario and solver),
hands them to the tasks and writes them to ``references/<point>.parquet``.
:func:`write_statistics` writes ``ablation.parquet`` / ``sweep.parquet``
from ``runs.parquet``. Progress is reported through the :class:`Progress`
protocol.
"""

from __future__ import annotations

import time
from collections.abc import Collection, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal, Protocol

import pandas as pd
import pyarrow as pa

from cwrend_cli.campaign import statistics
from cwrend_cli.campaign.executors import ExecutorKind, default_workers, open_executor
from cwrend_cli.campaign.journal import (
    append_events,
    check_same_campaign,
    events_of,
    finish_manifest,
    load_journal,
    new_manifest,
    remove_orphan_files,
    wipe,
)
from cwrend_cli.campaign.plan import CampaignPlan, Task
from cwrend_cli.campaign.worker import (
    ReferencesKey,
    RunOutcome,
    TaskOutcome,
    execute_task,
    references_key,
    seeds_to_record,
)
from cwrend_cli.output.files import write_json, write_parquet
from cwrend_cli.output.layout import (
    ABLATION_STATS,
    EVENTS,
    MANIFEST,
    RUNS,
    SWEEP_STATS,
    references_path,
)
from cwrend_cli.output.tables import param_columns, references_table, runs_table
from cwrend_cli.physics import simulation

__all__ = [
    "CampaignStatistics",
    "CampaignSummary",
    "Progress",
    "run_campaign",
    "write_statistics",
]


class Progress(Protocol):
    """What the driver reports while it works (the CLI draws it; tests may ignore it)."""

    def start(self, total: int, skipped: int) -> None:
        """``total`` runs to execute now; ``skipped`` already done."""

    def advance(self, ok: int, failed: int) -> None:
        """Runs just completed."""

    def close(self) -> None:
        """The campaign stopped."""


class _NoProgress:
    def start(self, total: int, skipped: int) -> None:
        pass

    def advance(self, ok: int, failed: int) -> None:
        pass

    def close(self) -> None:
        pass


class _Counting:
    """A :class:`Progress` that also counts the runs journaled by this invocation."""

    def __init__(self, inner: Progress) -> None:
        self.inner = inner
        self.journaled = 0

    def start(self, total: int, skipped: int) -> None:
        self.inner.start(total, skipped)

    def advance(self, ok: int, failed: int) -> None:
        self.journaled += ok + failed
        self.inner.advance(ok, failed)

    def close(self) -> None:
        self.inner.close()


@dataclass(frozen=True)
class CampaignSummary:
    """Outcome of one invocation of a campaign."""

    out_dir: Path
    executed: int
    skipped: int
    ok: int  # in the whole campaign directory
    failed: int  # in the whole campaign directory
    interrupted: bool


class _PointReferences:
    """The open-loop references of the grid points of one campaign invocation.

    Computed when a point's first task is submitted, once per distinct
    (scenario, solver), and written to ``references/<point>.parquet``. A
    computation that fails is remembered as ``None``: the tasks then compute
    the references run by run, so each run fails with its own error, as it
    would have alone.
    """

    def __init__(self, out_dir: Path, campaign_hash: str) -> None:
        self._out_dir = out_dir
        self._campaign_hash = campaign_hash
        self._by_key: dict[ReferencesKey, simulation.References | None] = {}
        self._written: set[str] = set()

    def of(self, task: Task) -> simulation.References | None:
        """The references of ``task``'s point (``None`` if they cannot be computed)."""
        key = references_key(task.problem)
        if key not in self._by_key:
            try:
                self._by_key[key] = simulation.open_loop_references(task.problem)
            except Exception:  # the runs report it, one by one
                self._by_key[key] = None
        refs = self._by_key[key]
        if refs is not None and task.point not in self._written:
            meta = {"campaign_hash": self._campaign_hash, "point": task.point}
            write_parquet(references_table(refs, meta), self._out_dir / references_path(task.point))
            self._written.add(task.point)
        return refs


def _failed_outcome(task: Task, exc: BaseException) -> TaskOutcome:
    """Every run of a task that did not come back (its worker died or it could not start)."""
    text = f"{type(exc).__name__}: {exc}"
    now = time.time()
    return TaskOutcome(
        f"{task.task_key}-lost",
        tuple(RunOutcome(r, "failed", {}, text, now, 0.0) for r in task.runs),
        (),
    )


def run_campaign(
    plan_: CampaignPlan,
    out_dir: Path,
    *,
    command: str,
    executor_kind: ExecutorKind = "local",
    workers: int | None = None,
    address: str | None = None,
    force: bool = False,
    retry_failed: bool = False,
    progress: Progress | None = None,
) -> CampaignSummary:
    """Execute the runs of ``plan_`` not yet in ``out_dir``; keep everything computed.

    Completed runs (same campaign hash) are skipped, failed ones too unless
    ``retry_failed``; a changed configuration is refused unless ``force``,
    which starts over. Each finished task appends its run events and a
    ``task_done`` record to ``events.jsonl`` in one write, so an interrupted
    campaign (Ctrl-C or ``kill -9``) keeps every completed task and leaves no
    partial data: files of unfinished executions are removed on resume.
    """
    progress = _Counting(progress or _NoProgress())
    out_dir.mkdir(parents=True, exist_ok=True)
    if force:
        wipe(out_dir)
    previous = check_same_campaign(out_dir, plan_)
    journal = load_journal(out_dir / EVENTS)
    remove_orphan_files(out_dir, journal.files)
    done = {k for k, e in journal.runs.items() if e["status"] == "ok" or not retry_failed}
    tasks = [
        replace(t, runs=tuple(r for r in t.runs if r.run_key not in done)) for t in plan_.tasks
    ]
    tasks = [t for t in tasks if t.runs]
    total = sum(len(t.runs) for t in tasks)
    skipped = len(plan_.runs) - total
    executor = {"kind": executor_kind, "workers": workers, "address": address}
    manifest = new_manifest(
        plan_, command=command, executor=executor, started=time.time(), previous=previous
    )
    write_json(manifest, out_dir / MANIFEST)
    interrupted = False
    progress.start(total, skipped)
    try:
        if tasks:
            if executor_kind == "local":  # no pool larger than the work (one task: in-process)
                workers = min(workers or default_workers(), len(tasks))
            with open_executor(executor_kind, workers, address) as (pool, parallel):
                _drive(pool, parallel, tasks, plan_, out_dir, progress)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        progress.close()
        journal = load_journal(out_dir / EVENTS)
        records = list(journal.runs.values())
        ok = sum(r["status"] == "ok" for r in records)
        failed = len(records) - ok
        write_parquet(runs_table(records, {"campaign_hash": plan_.campaign_hash}), out_dir / RUNS)
        finish_manifest(
            manifest,
            finished=time.time(),
            status="interrupted" if interrupted else "complete",
            computed=progress.journaled,
            skipped=skipped,
            counts={"ok": ok, "failed": failed, "runs": len(records)},
        )
        write_json(manifest, out_dir / MANIFEST)
    return CampaignSummary(out_dir, total, skipped, ok, failed, interrupted)


def _drive(
    executor: Executor,
    parallel: int,
    tasks: Sequence[Task],
    plan_: CampaignPlan,
    out_dir: Path,
    progress: Progress,
) -> None:
    """Submit tasks with a bounded number in flight; journal each as it completes."""
    queue = iter(tasks)
    in_flight: dict[Future[TaskOutcome], Task] = {}
    limit = 2 * parallel
    events_path = out_dir / EVENTS
    references = _PointReferences(out_dir, plan_.campaign_hash)
    try:
        while True:
            while len(in_flight) < limit:
                task = next(queue, None)
                if task is None:
                    break
                record = seeds_to_record(task, plan_.archs, plan_.rrd_seeds)
                future = executor.submit(
                    execute_task,
                    task,
                    references.of(task),
                    str(out_dir),
                    record,
                    plan_.steps_seeds,
                )
                in_flight[future] = task
            if not in_flight:
                return
            finished, _ = wait(in_flight, return_when=FIRST_COMPLETED)
            for future in finished:
                task = in_flight.pop(future)
                try:
                    outcome = future.result()
                except Exception as exc:  # the worker itself died or the task failed to run
                    outcome = _failed_outcome(task, exc)
                append_events(events_path, events_of(outcome, plan_.campaign_hash, time.time()))
                n_ok = sum(o.status == "ok" for o in outcome.outcomes)
                progress.advance(n_ok, len(outcome.outcomes) - n_ok)
    except KeyboardInterrupt:
        for future in in_flight:
            future.cancel()
        raise


# ---------------------------------------------------------------------------
# Statistics files
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class CampaignStatistics:
    """The statistics of a campaign and how they are grouped."""

    frame: pd.DataFrame  # statistics.describe rows, then statistics.paired rows
    groups: tuple[str, ...]  # columns of a comparison group: () for an ablation
    path: Path | None  # the file written (None when there was nothing to write)


def _statistics(
    runs: pd.DataFrame, command: Literal["ablate", "sweep"], root_seed: int
) -> tuple[pd.DataFrame, tuple[str, ...]]:
    groups = () if command == "ablate" else ("point", *param_columns(runs.columns))
    by = [*groups, "arch"]
    frame = pd.concat(
        [
            statistics.describe(runs, by, seed=root_seed),
            statistics.paired(runs, list(groups), seed=root_seed),
        ],
        ignore_index=True,
    )
    return frame, groups


def write_statistics(
    out_dir: Path, command: Literal["ablate", "sweep"], root_seed: int
) -> CampaignStatistics:
    """Compute the statistics of ``runs.parquet`` and write them beside it.

    ``ablate``: per architecture, into ``ablation.parquet``; ``sweep``: per
    grid point (with its swept values) and architecture, into
    ``sweep.parquet``. Each with its paired comparisons; the bootstrap is
    seeded from ``root_seed``. Nothing is written when there are no
    statistics. The file always covers every run the directory holds.
    """
    runs = pd.read_parquet(out_dir / RUNS)
    frame, groups = _statistics(runs, command, root_seed)
    if frame.empty:
        return CampaignStatistics(frame, groups, None)
    path = out_dir / (ABLATION_STATS if command == "ablate" else SWEEP_STATS)
    write_parquet(pa.Table.from_pandas(frame, preserve_index=False), path)
    return CampaignStatistics(frame, groups, path)


def held_run_keys(out_dir: Path) -> set[str]:
    """Keys of the runs (any status) that ``runs.parquet`` of a campaign directory holds."""
    return {str(k) for k in pd.read_parquet(out_dir / RUNS, columns=["run_key"])["run_key"]}


def subset_statistics(
    out_dir: Path,
    command: Literal["ablate", "sweep"],
    root_seed: int,
    run_keys: Collection[str],
) -> CampaignStatistics:
    """The statistics of the runs ``run_keys`` of the directory only; nothing is written.

    What a re-run naming fewer seeds, architectures or grid points reports;
    computed as for the whole directory (same groups, bootstrap seeded from
    ``root_seed``).
    """
    runs = pd.read_parquet(out_dir / RUNS)
    frame, groups = _statistics(runs[runs["run_key"].isin(set(run_keys))], command, root_seed)
    return CampaignStatistics(frame, groups, None)
