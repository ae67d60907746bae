"""Driving a campaign: resume, fan-out, journal, references and statistics.

:func:`run_campaign` executes the runs of a :class:`~cwrend_cli.campaign.plan.CampaignPlan`
that a campaign directory does not hold yet: it checks the manifest, cleans
orphans of interrupted executions, submits tasks to an executor with a
bounded number in flight (:func:`~cwrend_cli.campaign.worker.execute_task`)
and journals each as it completes, then writes ``runs.parquet`` and the
manifest. It computes each grid point's open-loop references when the
point's first task is submitted (once per distinct scenario and solver),
hands them to the tasks and writes them once per scenario and solver to
``references/r<digest>.parquet``, each point's file named in
``references/index.jsonl``.
:func:`write_statistics` writes ``ablation.parquet`` / ``sweep.parquet``
from ``runs.parquet``. Progress is reported through the :class:`Progress`
protocol, run by run where the executor signals runs (the local pool and
in-process; a Dask cluster per task, see
:func:`~cwrend_cli.campaign.executors.run_signals`); the journal records a
task execution when it comes back, whole or, after Ctrl-C, with the runs it
finished (:func:`_keep_finished_runs`), and the progress ends on what the
journal holds (:class:`_SettledProgress`).
"""

from __future__ import annotations

import contextlib
import errno
import gc
import shutil
import time
from collections import deque
from collections.abc import Collection, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal, Protocol

import pandas as pd
import pyarrow as pa

from cwrend_cli.campaign import design, guards, statistics
from cwrend_cli.campaign.executors import (
    DASK_LOST_AFTER_S,
    ExecutorKind,
    ask_workers_to_stop,
    check_address,
    default_workers,
    executor_alive,
    executor_broken,
    executor_workers,
    helper_process,
    open_executor,
    run_signals,
)
from cwrend_cli.campaign.journal import (
    JournalOwner,
    JournalState,
    append_events,
    campaign_lock,
    check_confined,
    check_same_campaign,
    events_of,
    finish_manifest,
    load_journal,
    new_manifest,
    read_events,
    remove_orphan_files,
    versions_digest,
    wipe,
)
from cwrend_cli.campaign.plan import CampaignPlan, RunSpec, Task, assignment_text
from cwrend_cli.campaign.worker import (
    InputChangedError,
    ReferencesKey,
    TaskInterrupted,
    TaskOutcome,
    compile_ahead,
    compile_newton,
    compile_top,
    execute_task,
    references_id,
    references_key,
    seeds_to_record,
)
from cwrend_cli.errors import CwrendError, InfrastructureError, ScenarioError
from cwrend_cli.output.files import (
    check_campaign_dir,
    estimated_bytes,
    make_output_dir,
    write_json,
    write_parquet,
)
from cwrend_cli.output.layout import (
    ABLATION_STATS,
    DESIGN,
    EVENTS,
    MANIFEST,
    PARAM_PREFIX,
    POINTS,
    PROBLEM,
    REFERENCES_INDEX,
    RUNS,
    SENSITIVITY,
    SWEEP_STATS,
    recording_path,
    references_path,
)
from cwrend_cli.output.manifest import read_manifest, recorded_pairs
from cwrend_cli.output.tables import (
    param_columns,
    points_table,
    references_table,
    runs_table,
    statistics_table,
)
from cwrend_cli.physics import simulation
from cwrend_cli.physics.metrics import NIS_DOF
from cwrend_cli.physics.params import Sensor
from cwrend_cli.teardown import raise_stop, stop_asked

__all__ = [
    "CampaignStatistics",
    "CampaignSummary",
    "Progress",
    "check_references",
    "hold_campaign",
    "no_statistics",
    "run_campaign",
    "write_sensitivity",
    "write_statistics",
]


class Progress(Protocol):
    """What the driver reports while it works (the CLI draws it; tests may ignore it)."""

    def start(self, total: int, skipped: int) -> None:
        """``total`` runs to execute now; ``skipped`` already done."""

    def advance(self, ok: int, failed: int) -> None:
        """Runs just completed (usually one); negative for the runs of a task execution
        that did not come back, which were counted and will run again."""

    def close(self) -> None:
        """The campaign stopped."""


class _NoProgress:
    def start(self, total: int, skipped: int) -> None:
        pass

    def advance(self, ok: int, failed: int) -> None:
        pass

    def close(self) -> None:
        pass


class _SettledProgress:
    """A :class:`Progress` that ends on the runs the journal holds, whatever it was told.

    Per-run signals advance it as runs finish; a run whose execution is then
    lost or abandoned (Ctrl-C) is not kept, so at the end the driver settles
    the count on the journal's (:meth:`settle`): the bar never shows as done
    a run a resume would compute again.
    """

    def __init__(self, inner: Progress) -> None:
        self._inner = inner
        self._ok = 0
        self._failed = 0

    def start(self, total: int, skipped: int) -> None:
        self._inner.start(total, skipped)

    def advance(self, ok: int, failed: int) -> None:
        self._ok += ok
        self._failed += failed
        self._inner.advance(ok, failed)

    def settle(self, ok: int, failed: int) -> None:
        """This invocation's runs kept: ``ok`` and ``failed``."""
        if (ok, failed) != (self._ok, self._failed):
            self.advance(ok - self._ok, failed - self._failed)

    def close(self) -> None:
        self._inner.close()


@dataclass(frozen=True)
class CampaignSummary:
    """Outcome of one invocation of a campaign."""

    out_dir: Path
    executed: int  # runs computed and journaled by this invocation
    skipped: int  # runs the directory already held
    ok: int  # in the whole campaign directory
    failed: int  # in the whole campaign directory
    interrupted: bool
    planned: int = 0  # runs of the plan (this invocation's command)
    #: run records of the journal not reused, by reason: not provably this campaign's or
    #: these versions' (journal.JournalOwner); their runs are computed again
    set_aside: Mapping[str, int] = field(default_factory=dict)
    #: the pairs to compare: those asked for (``run_campaign``'s ``pairs``), then the pairs
    #: added by earlier commands that the manifest records (``--pair A:B``)
    pairs: tuple[tuple[str, str], ...] = statistics.DEFAULT_PAIRS


class _PointReferences:
    """The open-loop references of the grid points of one campaign invocation.

    Computed when a point's first task is submitted, once per distinct
    (scenario, solver) (:func:`~cwrend_cli.campaign.worker.references_key`),
    and written once per distinct (scenario, solver) to
    ``references/<references_id>.parquet``: a sweep of the schedule's
    hyperparameters writes one file, not one per point. Each point's file is
    named by a line of ``references/index.jsonl``, appended (and on disk)
    before any of the point's tasks is submitted, hence before any of its
    runs is journaled. A computation that fails is remembered as ``None``:
    the tasks then compute the references run by run, so each run fails with
    its own error, as it would have alone. ``known``: references computed
    already (:func:`check_references`), written when their point's first task is.
    """

    def __init__(
        self,
        out_dir: Path,
        campaign_hash: str,
        config_hash: str,
        run_timeout_s: float | None = None,
        known: Mapping[ReferencesKey, simulation.References | None] | None = None,
    ) -> None:
        self._out_dir = out_dir
        self._run_timeout_s = run_timeout_s  # the references get their runs' limit
        self._campaign_hash = campaign_hash
        self._config_hash = config_hash
        # those computed before the campaign wrote anything (check_references)
        self._by_key: dict[ReferencesKey, simulation.References | None] = dict(known or {})
        self._written: set[str] = set()  # reference files written by this invocation
        self._indexed = indexed_points(out_dir)  # named by the index already (a resume)

    def of(self, task: Task) -> simulation.References | None:
        """The references of ``task``'s point (``None`` if they cannot be computed)."""
        key = references_key(task.problem)
        if key not in self._by_key:
            try:
                self._by_key[key] = _references_within_limit(task, self._run_timeout_s)
            except Exception:  # the runs report it (a time limit too), one by one
                self._by_key[key] = None
        refs = self._by_key[key]
        if refs is not None and task.point not in self._indexed:
            name = references_id(key)
            rel = references_path(name)
            if rel not in self._written and not (self._out_dir / rel).exists():
                meta = {
                    "config_hash": self._config_hash,
                    "campaign_hash": self._campaign_hash,
                    "references": name,
                }
                table = references_table(refs, meta)
                write_parquet(table, self._out_dir / rel, root=self._out_dir)
            self._written.add(rel)
            index = self._out_dir / REFERENCES_INDEX
            append_events(index, [{"point": task.point, "file": rel}], root=self._out_dir)
            self._indexed.add(task.point)
        return refs


def _references_within_limit(task: Task, run_timeout_s: float | None) -> simulation.References:
    """The open-loop references of ``task``'s point, within the limit of a process's first
    run (:func:`~cwrend_cli.campaign.guards.run_timeout_s`): what a point's runs wait for."""
    limit = guards.run_timeout_s(run_timeout_s, task.problem, first=True)
    with guards.time_limit(limit):
        return simulation.open_loop_references(task.problem)


class _CheckedReferences:
    """The references of a plan's scenarios, computed before its campaign writes anything."""

    def __init__(self, run_timeout_s: float | None) -> None:
        self._run_timeout_s = run_timeout_s
        #: ``None``: failed otherwise (a time limit); the runs compute them, as before
        self.known: dict[ReferencesKey, simulation.References | None] = {}

    def of(self, task: Task) -> simulation.References | None:
        """The references of ``task``'s point; :class:`ScenarioError` naming the point if it
        has none (``None``: another failure, which its runs report one by one)."""
        key = references_key(task.problem)
        if key not in self.known:
            try:
                self.known[key] = _references_within_limit(task, self._run_timeout_s)
            except ScenarioError as exc:
                params = task.runs[0].params if task.runs else ()
                if not params:  # the base configuration: cwrend run's message
                    raise
                where = f"grid point {task.point} ({assignment_text(params)})"
                raise ScenarioError(f"{where}: {exc}") from None
            except Exception:  # a time limit: the runs report it, as before
                self.known[key] = None
        return self.known[key]


def indexed_points(out_dir: Path) -> set[str]:
    """The points whose references a campaign directory's ``references/index.jsonl`` names:
    an earlier invocation computed them (empty for a new directory)."""
    index = out_dir / REFERENCES_INDEX
    events = read_events(index) if index.exists() else ()
    return {str(e["point"]) for e in events if "point" in e}


def check_references(
    plan_: CampaignPlan, beside: bool = False, out_dir: Path | None = None
) -> Mapping[ReferencesKey, simulation.References | None]:
    """The open-loop references of every scenario of ``plan_``: the check of ``cwrend run``.

    Computed before the campaign writes anything, so that a scenario without them is
    refused as ``cwrend run`` refuses it: :class:`ScenarioError` (exit 2), e.g. a
    target no control within ``scenario.u_max_km_s2`` reaches within the horizon (a
    corridor port typed in metres), naming the grid point of a sweep. A failure of
    another kind (the run time limit) is left to the runs, which report it one by one
    (``None``: they compute the references themselves, as :class:`_PointReferences` has
    them do).
    Pass the result to :func:`run_campaign` (``references``): nothing is computed twice.

    ``beside``: a local campaign on a machine of several cores; on a first run (the
    references' kernels not cached) a helper process compiles the step loop meanwhile
    (:func:`_compile_first_run`).

    ``out_dir``: the campaign's directory, whose points with references already
    (:func:`indexed_points`: an earlier invocation computed them, so they were
    reachable) are not checked again: a rerun of a finished campaign computes none
    (``None``: every point, e.g. with ``--force``, which starts over).
    """
    try:
        indexed = set() if out_dir is None else indexed_points(out_dir)
    except OSError:  # a directory the campaign refuses next, naming it (a name too long)
        indexed = set()
    tasks = [task for task in plan_.tasks if task.point not in indexed]
    references = _CheckedReferences(plan_.run_timeout_s)
    if beside:
        _compile_first_run(None, tasks, references)
    for task in tasks:
        references.of(task)
    return MappingProxyType(references.known)


#: Attempts of one task on infrastructure faults before the campaign stops.
MAX_TASK_ATTEMPTS = 3
#: Pause before the executor is reopened after a fault [s]; doubled on each reopening.
RETRY_BACKOFF_S = 0.5
#: How often the driver checks that its executor is alive while nothing completes [s].
_POLL_S = 1.0
#: How often the driver delivers the per-run signals to the progress [s].
_SIGNAL_POLL_S = 0.1
#: How long Ctrl-C waits for the tasks in flight to return the runs they finished [s]
#: (a pool worker stops its task at the next return of a run to Python: milliseconds).
STOP_GRACE_S = 1.0


class _RunTally:
    """Runs signalled per task execution in flight, settled when the execution ends.

    Each signal advances the progress by one run at once. When the execution
    comes back, the difference between its outcomes and the runs signalled is
    advanced (all of them for an executor without signals; signals still in
    the queue then are ignored, the outcomes count). When it is lost, the runs
    it signalled are taken back: they will run again.
    """

    def __init__(self, progress: Progress) -> None:
        self._progress = progress
        self._open: dict[int, list[int]] = {}  # token → [ok, failed] signalled

    def open(self, token: int) -> None:
        """Execution ``token`` is about to be submitted."""
        self._open[token] = [0, 0]

    def heard(self, token: int, ok: bool) -> None:
        """A run of execution ``token`` finished (a :data:`~executors.RunListener`)."""
        counts = self._open.get(token)
        if counts is None:  # the execution was settled already
            return
        counts[0 if ok else 1] += 1
        self._progress.advance(int(ok), int(not ok))

    def completed(self, token: int, ok: int, failed: int) -> None:
        """Execution ``token`` came back with ``ok`` and ``failed`` runs."""
        heard_ok, heard_failed = self._open.pop(token, [0, 0])
        if (ok, failed) != (heard_ok, heard_failed):
            self._progress.advance(ok - heard_ok, failed - heard_failed)

    def lost(self, token: int) -> None:
        """Execution ``token`` did not come back."""
        heard_ok, heard_failed = self._open.pop(token, [0, 0])
        if heard_ok or heard_failed:
            self._progress.advance(-heard_ok, -heard_failed)


def _fault_text(exc: BaseException) -> str:
    """What an infrastructure fault was, in a few words (for the message and the manifest)."""
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return f"disk full ({exc})"
    if isinstance(exc, OSError):
        return f"cannot write results ({type(exc).__name__}: {exc})"
    return f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__


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
    allow_version_change: bool = False,
    progress: Progress | None = None,
    argv: Sequence[str] | None = None,
    hold: contextlib.ExitStack | None = None,
    repair_manifest: bool = False,
    pairs: Sequence[tuple[str, str]] = statistics.DEFAULT_PAIRS,
    references: Mapping[ReferencesKey, simulation.References | None] | None = None,
) -> CampaignSummary:
    """Execute the runs of ``plan_`` not yet in ``out_dir``; keep everything computed.

    Completed runs (same campaign hash) are skipped, failed ones too unless
    ``retry_failed``; a changed configuration is refused unless ``force``,
    which starts over; one computed with other versions of cwrend or the
    numerics is refused unless ``allow_version_change``. Each finished task
    appends its run events and a ``task_done`` record to ``events.jsonl`` in
    one write, so an interrupted campaign keeps every completed task (``kill
    -9``), or every finished run (Ctrl-C, SIGTERM, SIGHUP: a stopped task
    returns its finished runs), and leaves no partial data: files of
    unfinished executions are removed on resume. ``argv``: the command line,
    recorded in the manifest's session.

    The directory is locked (:func:`hold_campaign`) while this runs, or, with
    ``hold``, until the caller closes that stack: a command that writes the
    statistics and a report after the runs keeps them under the same lock.

    ``repair_manifest``: a damaged ``manifest.json`` is rebuilt from the
    journal (whose records must name this campaign) and this plan, instead of
    refused (:func:`~cwrend_cli.campaign.journal.check_same_campaign`).

    ``pairs``: the pairs the statistics compare (``statistics.campaign_pairs``);
    those beyond :data:`~cwrend_cli.campaign.statistics.DEFAULT_PAIRS` are recorded
    in the manifest, after those earlier commands added (``--force`` forgets them),
    and the summary's ``pairs`` holds them all: what every later rewrite of the
    statistics compares.

    ``references``: the open-loop references :func:`check_references` computed.
    """
    progress = progress or _NoProgress()
    try:
        with contextlib.ExitStack() as own:
            (hold or own).enter_context(
                hold_campaign(out_dir, address if executor_kind == "dask" else None)
            )
            return _run_locked(
                plan_, out_dir, progress, command, executor_kind, workers, address, force,
                retry_failed, allow_version_change, argv, repair_manifest, pairs, references,
            )  # fmt: skip
    except OSError as exc:  # outside the runs (the lock, the first manifest): nothing computed
        raise InfrastructureError(
            f"campaign stopped: {_fault_text(exc)}. Every run the journal holds is kept; fix "
            "the cause and run the same command to resume"
        ) from None


#: Campaign directories this process holds locked (:func:`hold_campaign`).
_HELD: set[Path] = set()


@contextlib.contextmanager
def hold_campaign(out_dir: Path, address: str | None = None) -> Iterator[None]:
    """Create, confine and lock a campaign directory for the ``with`` block (issue 36 item 2).

    Everything a command writes in the directory (runs, manifest, statistics,
    sensitivity, report) is written under one lock, so another process (even
    with ``--force``) never writes between them. Reentrant in a process: a
    campaign run inside a command's hold does not lock again. ``address``: a
    Dask scheduler checked before anything is written. A directory holding a
    ``cwrend run``'s output is refused before anything is written
    (:func:`~cwrend_cli.output.files.check_campaign_dir`).
    """
    key = out_dir.resolve()
    if key in _HELD:
        yield
        return
    if address:
        check_address(address)  # before anything is written
    check_campaign_dir(out_dir)  # never beside a cwrend run's files
    make_output_dir(out_dir, "choose another output.dir or output.name")
    check_confined(out_dir)
    with campaign_lock(out_dir):
        _HELD.add(key)
        try:
            yield
        finally:
            _HELD.discard(key)


def _run_locked(
    plan_: CampaignPlan,
    out_dir: Path,
    progress: Progress,
    command: str,
    executor_kind: ExecutorKind,
    workers: int | None,
    address: str | None,
    force: bool,
    retry_failed: bool,
    allow_version_change: bool,
    argv: Sequence[str] | None = None,
    repair_manifest: bool = False,
    pairs: Sequence[tuple[str, str]] = statistics.DEFAULT_PAIRS,
    references: Mapping[ReferencesKey, simulation.References | None] | None = None,
) -> CampaignSummary:
    """:func:`run_campaign` once the directory exists, is confined and locked."""
    progress = _SettledProgress(progress)
    if force:
        wipe(out_dir)
    previous = check_same_campaign(
        out_dir, plan_, allow_version_change=allow_version_change, repair_manifest=repair_manifest
    )
    # only the journal lines that prove this campaign and these versions count (legacy ones,
    # without versions, when the manifest proves them)
    digest = None if allow_version_change else versions_digest()
    owner = JournalOwner(plan_.campaign_hash, digest, legacy=bool(previous))
    journaled_to, done, owed, set_aside = _journal_before(out_dir, plan_, retry_failed, owner)
    tasks = [
        replace(t, runs=tuple(r for r in t.runs if r.run_key not in done)) for t in plan_.tasks
    ]
    tasks = [t for t in tasks if t.runs]
    total = sum(len(t.runs) for t in tasks)
    skipped = len(plan_.runs) - total
    tasks += owed  # recordings lost before: written again, counted in no run
    executor = {"kind": executor_kind, "workers": workers, "address": address}
    added = [p for p in pairs if p not in statistics.DEFAULT_PAIRS]
    manifest = new_manifest(
        plan_, command=command, executor=executor, started=time.time(), previous=previous,
        argv=argv, pairs=added,
    )  # fmt: skip
    compared = (*pairs, *(p for p in recorded_pairs(manifest) if p not in pairs))
    write_json(manifest, out_dir / MANIFEST)
    interrupted = False
    stopped: str | None = None
    progress.start(total, skipped)
    try:
        if tasks:
            _check_room(out_dir, plan_, tasks[0])
            beside = False  # one task in-process on a machine of several cores
            if executor_kind == "local":  # no pool larger than the work (one task: in-process)
                cores = workers or default_workers()
                workers = min(cores, len(tasks))
                beside = workers == 1 < cores
            _execute(
                tasks, plan_, out_dir, progress, executor_kind, workers, address, beside, owner,
                references,
            )  # fmt: skip
    except KeyboardInterrupt:
        interrupted = True
    except _StopError as stop:
        stopped = stop.cause
    except CwrendError as exc:  # e.g. the executor could not be opened: recorded, then raised
        stopped = str(exc)
        raise
    finally:
        if interrupted:  # the pool's queues, held by cycles through the interrupt's traceback,
            gc.collect()  # release their semaphores now (cwrend ends without a collection)
        # the bar stays (complete) while runs.parquet is written: about 1 s per 10,000 runs
        try:
            journal = load_journal(out_dir / EVENTS, owner=owner)
            records = list(journal.runs.values())
            # runs journaled by this invocation, from the journal itself (a Ctrl-C between a
            # journal write and the progress update must not make the count lie), also those
            # rerun under an execution name they had before (--retry-failed of a whole task)
            since = load_journal(out_dir / EVENTS, start=journaled_to, owner=owner).runs.values()
            new = [e["status"] == "ok" for e in since]
            computed = len(new)
            progress.settle(sum(new), computed - sum(new))  # the bar ends on what is kept
            ok = sum(r["status"] == "ok" for r in records)
            failed = len(records) - ok
            status = "interrupted" if interrupted else "complete"
            if stopped is not None:
                status = f"stopped: {stopped}"
            try:  # under a full disk these may fail too: the journal stays the record
                write_parquet(runs_table(records, _file_metadata(plan_)), out_dir / RUNS)
                write_parquet(points_table(_points_of(records), _file_metadata(plan_)),
                              out_dir / POINTS)  # fmt: skip
                finish_manifest(
                    manifest,
                    finished=time.time(),
                    status=status,
                    computed=computed,
                    skipped=skipped,
                    counts={"ok": ok, "failed": failed, "runs": len(records)},
                    archs=(str(r["arch"]) for r in records),
                    seeds=(int(r["seed"]) for r in records),
                )
                write_json(manifest, out_dir / MANIFEST)
            except OSError as exc:
                stopped = stopped or _fault_text(exc)
        finally:
            progress.close()
    if stopped is not None:
        raise InfrastructureError(
            f"campaign stopped: {stopped}. {len(records)} of {len(plan_.runs)} run(s) are done "
            f"and kept ({failed} failed), none was recorded for this fault; fix the cause and run "
            "the same command to compute exactly the missing runs"
        )
    return CampaignSummary(
        out_dir, computed, skipped, ok, failed, interrupted, len(plan_.runs), set_aside, compared
    )


def _points_of(records: Sequence[Mapping[str, Any]]) -> list[tuple[str, Mapping[str, Any]]]:
    """Each point of the runs ``records`` once, with its swept values, in first-seen order."""
    points: dict[str, Mapping[str, Any]] = {}
    for r in records:
        points.setdefault(str(r["point"]), r.get("params", {}))
    return list(points.items())


def _journal_before(
    out_dir: Path, plan_: CampaignPlan, retry_failed: bool, owner: JournalOwner
) -> tuple[int, set[str], list[Task], Mapping[str, int]]:
    """Clean the orphans of a campaign directory; its journal's size [bytes], its done runs,
    the tasks that write again the recordings it owes (:func:`_owed_recordings`) and the
    run records set aside as not ``owner``'s (by reason).

    Done: ok runs, failed ones too unless ``retry_failed``. The journal's
    state is released on return, so the campaign never holds it while it
    runs, nor beside the state read again at its end.
    """
    journal = load_journal(out_dir / EVENTS, owner=owner)
    remove_orphan_files(out_dir, journal.files)
    size = (out_dir / EVENTS).stat().st_size if (out_dir / EVENTS).exists() else 0
    done = {k for k, e in journal.runs.items() if e["status"] == "ok" or not retry_failed}
    return size, done, _owed_recordings(out_dir, plan_, journal, done), journal.set_aside


def _owed_recordings(
    out_dir: Path, plan_: CampaignPlan, journal: JournalState, done: Collection[str]
) -> list[Task]:
    """``record_only`` tasks for the recordings the campaign owes and does not hold.

    A recording is owed for every seed a task records (:func:`seeds_to_record`)
    that has an ok run; it is held when a completed execution names it and
    its file is there. One whose seed's runs all run again now is written by
    their task; for the others (lost to a full disk by an earlier version,
    deleted, failed to encode) a task recomputes the seed's ok runs, without
    journaling them again, and writes the recording (issue 36, item 1).
    """
    owed: list[Task] = []
    if plan_.rrd_seeds == 0:
        return owed
    for task in plan_.tasks:
        runs: list[RunSpec] = []
        for seed in seeds_to_record(task, plan_.archs, plan_.rrd_seeds_of(task.point)):
            rel = recording_path(task.point, seed)
            if rel in journal.files and (out_dir / rel).is_file():
                continue
            of_seed = [r for r in task.runs if r.seed == seed]
            if all(r.run_key not in done for r in of_seed):
                continue  # its task computes them all again now, and records the seed
            runs += [r for r in of_seed if journal.runs.get(r.run_key, {}).get("status") == "ok"]
        if runs:
            owed.append(replace(task, runs=tuple(runs), record_only=True))
    return owed


def _check_room(out_dir: Path, plan_: CampaignPlan, first: Task) -> None:
    """Stop before computing when the disk cannot hold even the first task's files (exit 3)."""
    below = plan_.steps_seeds_of(first.point)
    steps = [r for r in first.runs if below is None or r.seed < below]
    recorded = seeds_to_record(first, plan_.archs, plan_.rrd_seeds_of(first.point))
    need = estimated_bytes(len(first.runs), len(steps), len(recorded))
    free = shutil.disk_usage(out_dir).free
    if free < need:
        raise _StopError(
            f"disk full: {free / 1e6:.1f} MB free in {out_dir}, the first task needs about "
            f"{need / 1e6:.1f} MB"
        )


class _StopError(Exception):
    """Internal: the campaign stops on an infrastructure fault (``cause`` in a few words)."""

    def __init__(self, cause: str) -> None:
        super().__init__(cause)
        self.cause = cause


def _execute(
    tasks: Sequence[Task],
    plan_: CampaignPlan,
    out_dir: Path,
    progress: Progress,
    kind: ExecutorKind,
    workers: int | None,
    address: str | None,
    beside: bool = False,
    owner: JournalOwner | None = None,
    known: Mapping[ReferencesKey, simulation.References | None] | None = None,
) -> None:
    """Run ``tasks`` on an executor, reopening it after an infrastructure fault.

    ``beside``: the tasks run in-process although more cores are free (one
    task); a first run then compiles in a helper process too
    (:func:`_compile_first_run`).

    A task whose execution did not come back (its worker died, the pool
    broke, the scheduler was lost, the task was cancelled) is submitted again
    to a fresh executor, up to :data:`MAX_TASK_ATTEMPTS` times, with a
    backoff of :data:`RETRY_BACKOFF_S` doubling per reopening; nothing of it is
    journaled as a result, and the files it wrote are removed before (a
    broken pool ends its surviving workers with SIGKILL, which may leave
    files of their runs, whole or half-written: :class:`~cwrend_cli.campaign.
    executors._PoolWorkerProcess`; ``owner``: the journal's, see
    :func:`~cwrend_cli.campaign.journal.load_journal`). A pool that broke as
    a task was submitted never completes that task's future: the driver
    counts it lost when the pool has ended (:func:`executor_broken`). An I/O error writing
    results stops at once (a full disk does not heal by retrying). Raises
    :class:`_StopError` when the campaign cannot go on.
    """
    attempts: dict[str, int] = {}
    references = _PointReferences(
        out_dir, plan_.campaign_hash, plan_.config_hash, plan_.run_timeout_s, known
    )
    pending = list(tasks)
    reopened = 0
    while pending:
        if reopened:
            time.sleep(RETRY_BACKOFF_S * 2 ** min(reopened - 1, 4))
            remove_orphan_files(out_dir, load_journal(out_dir / EVENTS, owner=owner).files)
        try:
            with open_executor(kind, workers, address) as (pool, parallel):
                if kind == "local" and (parallel > 1 or beside) and not reopened:
                    _compile_first_run(pool if parallel > 1 else None, pending, references)
                pending = _drive(
                    pool, parallel, pending, plan_, out_dir, progress, references, attempts
                )
        except InputChangedError:
            raise
        except (CwrendError, OSError) as exc:  # only opening or closing the executor raises these
            if not reopened:
                raise
            raise _StopError(f"the executor could not be reopened after a fault ({exc})") from None
        reopened += 1


def _compile_first_run(
    executor: Executor | None,
    tasks: Sequence[Task],
    references: _PointReferences | _CheckedReferences,
) -> None:
    """On a first run, compile in two processes at once before the first task (issue 37 item 12).

    Only when the references' kernels are not in numba's cache (a first run
    after an install or upgrade; :mod:`cwrend_cli.physics.compiled`). This
    process compiles the shooting solver's dual ascent, the longest chain of
    the compile, while a pool worker compiles what does not depend on it,
    the closed loop's step kernels, then the solver's switching-time Newton,
    then the compiled loop's top, which calls the step loop and the solver
    by their addresses and so needs neither
    (:func:`~cwrend_cli.campaign.worker.compile_ahead`,
    :func:`~cwrend_cli.campaign.worker.compile_newton`,
    :func:`~cwrend_cli.campaign.worker.compile_top`); this process waits for
    the Newton before it computes the first point's references, and the
    first task waits for the step kernels and the loop's top, so that
    whichever process needs them loads them rather than compiling them a
    second time. ``executor``
    ``None``: the tasks run in-process (one task, the paper ablation's), and
    a helper process does the worker's part
    (:func:`~cwrend_cli.campaign.executors.helper_process`).
    """
    from cwrend_cli.physics import compiled

    if not tasks or not compiled.references_cold():
        return
    if executor is None:
        with helper_process() as helper:
            _compile_beside(helper, tasks[0], references)
    else:
        _compile_beside(executor, tasks[0], references)


def _compile_beside(
    executor: Executor, task: Task, references: _PointReferences | _CheckedReferences
) -> None:
    """The solver's ascent and the references here while ``executor`` compiles the rest."""
    from cwrend_cli.physics import compiled

    loop = executor.submit(compile_ahead, task)
    newton = executor.submit(compile_newton)
    top = executor.submit(compile_top, task)  # the loop's top: needs neither of the above
    compiled.compile_ascent(task.problem)
    _wait_for(newton)  # the solver's other half: loaded below, not compiled a second time
    with contextlib.suppress(OSError):  # the first task's own call reports it
        references.of(task)
    _wait_for(loop)
    _wait_for(top)


def _wait_for(future: Future[None]) -> None:
    """Wait until ``future`` is done (a state, not a time: short polls stay interruptible)."""
    while not future.done():
        if stop_asked():  # a stop the references' code turned into an error of theirs
            raise_stop()
        wait([future], timeout=_POLL_S)


def _drive(
    executor: Executor,
    parallel: int,
    tasks: Sequence[Task],
    plan_: CampaignPlan,
    out_dir: Path,
    progress: Progress,
    references: _PointReferences,
    attempts: dict[str, int],
) -> list[Task]:
    """Submit tasks with a bounded number in flight; journal each as it completes.

    Returns the tasks still to run when an execution did not come back (the
    lost ones and those not yet submitted; the executor is then suspect and
    gets nothing new), else an empty list. When the campaign cannot go on (a
    task exhausted its attempts, results cannot be written) nothing new is
    submitted, the executions in flight are awaited and journaled, and then
    :class:`_StopError` is raised.
    """
    queue = deque(tasks)
    in_flight: dict[Future[TaskOutcome], tuple[int, Task]] = {}
    lost: list[Task] = []
    fatal: str | None = None
    changed: InputChangedError | None = None  # the campaign's input changed: exit 2
    limit = 2 * parallel
    submitted = 0
    dead_s = 0.0  # how long the executor has been unable to deliver results
    idle_s = 0.0  # how long the executor has had no worker at all (a Dask cluster)
    checked = time.monotonic()  # when the executor was last asked whether it is alive
    events_path = out_dir / EVENTS
    tally = _RunTally(progress)
    signals = run_signals(executor, tally.heard)
    try:
        while True:
            if stop_asked():  # a stop a library turned into an error (the references')
                raise_stop()
            while fatal is None and not lost and len(in_flight) < limit and queue:
                task = queue.popleft()
                record = seeds_to_record(task, plan_.archs, plan_.rrd_seeds_of(task.point))
                try:
                    refs = references.of(task)
                except OSError as exc:  # writing the point's references failed
                    fatal = _fault_text(exc)
                    break
                tally.open(submitted)
                try:
                    future = executor.submit(
                        execute_task,
                        task,
                        refs,
                        str(out_dir),
                        record,
                        plan_.steps_seeds_of(task.point),
                        _file_metadata(plan_),
                        plan_.run_timeout_s,
                        signals.signal(submitted),
                    )
                except RuntimeError as exc:  # a broken pool refuses new work
                    tally.lost(submitted)
                    fatal = _count_attempt(task, exc, attempts)
                    lost.append(task)
                    break
                in_flight[future] = (submitted, task)
                submitted += 1
            if not in_flight:
                break
            timeout = min(_SIGNAL_POLL_S, _POLL_S)
            finished, _ = wait(in_flight, timeout=timeout, return_when=FIRST_COMPLETED)
            signals.poll()
            now = time.monotonic()
            if not finished:
                if now - checked >= _POLL_S:
                    dead_s = 0.0 if executor_alive(executor) else dead_s + (now - checked)
                    idle_s = idle_s + (now - checked) if executor_workers(executor) == 0 else 0.0
                    checked = now
                _check_workers(idle_s, plan_.no_worker_timeout_s)
                broken = executor_broken(executor)
                if broken or dead_s >= DASK_LOST_AFTER_S:  # its futures would wait forever
                    cause = "the pool broke" if broken else "the executor lost its scheduler"
                    for token, task in in_flight.values():
                        tally.lost(token)
                        fault = RuntimeError(cause)
                        fatal = fatal or _count_attempt(task, fault, attempts)
                        lost.append(task)
                    in_flight.clear()
                continue
            dead_s = 0.0
            checked = now
            for future in sorted(finished, key=lambda f: in_flight[f][0]):  # submission order
                token, task = in_flight.pop(future)
                try:
                    outcome = future.result()
                except InputChangedError as exc:  # no new task; those in flight are kept
                    tally.lost(token)
                    changed, fatal = exc, fatal or str(exc)
                    continue
                except Exception as exc:  # the execution did not come back: not a result
                    tally.lost(token)
                    fatal = fatal or _count_attempt(task, exc, attempts)
                    lost.append(task)
                    continue
                try:
                    append_events(events_path, events_of(outcome, plan_.campaign_hash, time.time()))
                except OSError as exc:  # the journal itself cannot be written: stop now
                    raise _StopError(_fault_text(exc)) from None
                n_ok = sum(o.status == "ok" for o in outcome.outcomes)
                tally.completed(token, n_ok, len(outcome.outcomes) - n_ok)
    except KeyboardInterrupt as stop:  # Ctrl-C (or SIGTERM/SIGHUP): keep every finished run
        _keep_finished_runs(stop, executor, in_flight, events_path, plan_.campaign_hash)
        raise
    except BaseException:
        for future in in_flight:
            future.cancel()
        raise
    if changed is not None:
        raise changed
    if fatal is not None:
        raise _StopError(fatal)
    return [*lost, *queue] if lost else []


def _keep_finished_runs(
    stop: KeyboardInterrupt,
    executor: Executor,
    in_flight: Collection[Future[TaskOutcome]],
    events_path: Path,
    campaign: str,
) -> None:
    """On Ctrl-C, journal the runs the executions in flight finished (issue 37 item 2).

    An in-process task raised the Ctrl-C itself, with its finished runs
    (:class:`TaskInterrupted`). The pool's workers are told to stop
    (:func:`ask_workers_to_stop`) and come back at once with theirs; those
    not back within :data:`STOP_GRACE_S` (a run in a long solver call) are
    abandoned, their runs computed again on resume. Nothing else is waited
    for: a second Ctrl-C abandons them all at once.
    """
    if isinstance(stop, TaskInterrupted):
        _journal_kept(stop.outcome, events_path, campaign)
    ask_workers_to_stop(executor)
    back, _ = wait(in_flight, timeout=STOP_GRACE_S) if in_flight else (set(), set())
    for future in in_flight:
        if future not in back:
            future.cancel()
            continue
        try:
            outcome = future.result()
        except TaskInterrupted as interrupted:
            outcome = interrupted.outcome
        except Exception:  # lost: nothing to keep
            continue
        _journal_kept(outcome, events_path, campaign)


def _journal_kept(outcome: TaskOutcome, events_path: Path, campaign: str) -> None:
    """Journal the runs of an execution that stopped; a journal that cannot be written keeps
    nothing more (the count of what is done comes from the journal)."""
    if outcome.outcomes:
        with contextlib.suppress(OSError):
            append_events(events_path, events_of(outcome, campaign, time.time()))


def _check_workers(idle_s: float, limit_s: float | None) -> None:
    """Stop (:class:`_StopError`) an executor without workers for ``limit_s`` [s] or more.

    Its tasks would wait for ever (a Dask scheduler alive, every worker
    gone); nothing of them is journaled, the same command resumes.
    """
    if limit_s is not None and idle_s >= limit_s:
        raise _StopError(
            f"the Dask cluster has had no worker for {idle_s:.0f} s "
            f"(output.dask_no_worker_timeout_s = {limit_s:g}); start workers"
        )


def _count_attempt(task: Task, exc: BaseException, attempts: dict[str, int]) -> str | None:
    """Count a lost execution of ``task``; the cause if the campaign cannot go on, else None."""
    if isinstance(exc, OSError):  # writing results failed (disk full, permission, read-only)
        return _fault_text(exc)
    attempts[task.task_key] = attempts.get(task.task_key, 0) + 1
    if attempts[task.task_key] >= MAX_TASK_ATTEMPTS:
        return f"task {task.task_key} was lost {MAX_TASK_ATTEMPTS} times, last: {_fault_text(exc)}"
    return None


# ---------------------------------------------------------------------------
# Statistics files
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class CampaignStatistics:
    """The statistics of a campaign and how they are grouped."""

    frame: pd.DataFrame  # statistics.describe, paired, safety (if any) and applied rows
    groups: tuple[str, ...]  # columns of a comparison group: () for an ablation
    path: Path | None  # the file written (None when there was nothing to write)


def no_statistics(command: Literal["ablate", "sweep"]) -> CampaignStatistics:
    """No statistics, none written (an interrupted campaign's: written when it completes)."""
    groups: tuple[str, ...] = () if command == "ablate" else ("point",)
    return CampaignStatistics(pd.DataFrame(), groups, None)


def _nis_dofs(runs: pd.DataFrame, out_dir: Path) -> list[int]:
    """Each run's NIS degrees of freedom: its sensor's measurement dimension m (issue 35).

    The swept ``sensor.model`` of the run's point, else the base config's (the
    manifest's; ``position`` when it has no [sensor]).
    """
    manifest = out_dir / MANIFEST
    base = read_manifest(manifest, "run the same command again") if manifest.exists() else {}
    sensor = base.get("config", {}).get("sensor", {})
    column = f"{PARAM_PREFIX}sensor.model"
    base_model = sensor.get("model", "position")
    models = runs[column] if column in runs.columns else [base_model] * len(runs)
    return [Sensor(model=str(m)).dimension for m in models]  # type: ignore[arg-type]


def _statistics(
    runs: pd.DataFrame,
    command: Literal["ablate", "sweep"],
    root_seed: int,
    pairs: Sequence[tuple[str, str]] = statistics.DEFAULT_PAIRS,
    nis_dof: Sequence[int] | int = NIS_DOF,
) -> tuple[pd.DataFrame, tuple[str, ...]]:
    groups = () if command == "ablate" else ("point", *param_columns(runs.columns))
    by = [*groups, "arch"]
    frames = [
        statistics.describe(runs, by, seed=root_seed),
        statistics.paired(runs, list(groups), seed=root_seed, pairs=pairs),
    ]
    safety = statistics.safety(runs, by, seed=root_seed)  # issue 32: constrained campaigns
    if not safety.empty:
        frames.append(safety)
    abort = statistics.abort_safety(runs, by, seed=root_seed)  # issue 34 item 4
    if not abort.empty:
        frames.append(abort)
    applied = statistics.applied(runs, by, seed=root_seed)  # issue 33: the applied Δv
    if not applied.empty:
        frames.append(applied)
    consistency = statistics.consistency(runs, by, nis_dof)  # issue 33: against the χ² bands
    if not consistency.empty:
        frames.append(consistency)
    frame = pd.concat(frames, ignore_index=True)
    return frame, groups


def _file_metadata(plan_: CampaignPlan) -> dict[str, str]:
    """Schema metadata of a campaign's Parquet files: its base config's and its own hash."""
    return {"config_hash": plan_.config_hash, "campaign_hash": plan_.campaign_hash}


def _stored_metadata(out_dir: Path) -> dict[str, str]:
    """The config and campaign hashes of a campaign directory (its manifest; empty if none)."""
    manifest = out_dir / MANIFEST
    stored = read_manifest(manifest, "run the same command again") if manifest.exists() else {}
    return {k: str(stored.get(k, "")) for k in ("config_hash", "campaign_hash")}


def write_statistics(
    out_dir: Path,
    command: Literal["ablate", "sweep"],
    root_seed: int,
    pairs: Sequence[tuple[str, str]] = statistics.DEFAULT_PAIRS,
) -> CampaignStatistics:
    """Compute the statistics of ``runs.parquet`` and write them beside it.

    ``ablate``: per architecture, into ``ablation.parquet``; ``sweep``: per
    grid point (with its swept values) and architecture, into
    ``sweep.parquet``. Each with its paired comparisons of ``pairs`` (those
    present; :func:`statistics.paired`); the bootstrap is seeded from
    ``root_seed``. Nothing is written when there are no statistics. The file
    always covers every run the directory holds.
    """
    runs = pd.read_parquet(out_dir / RUNS)
    frame, groups = _statistics(runs, command, root_seed, pairs, _nis_dofs(runs, out_dir))
    if frame.empty:
        return CampaignStatistics(frame, groups, None)
    path = out_dir / (ABLATION_STATS if command == "ablate" else SWEEP_STATS)
    _write_statistics_file(statistics_table(frame, _stored_metadata(out_dir)), path)
    return CampaignStatistics(frame, groups, path)


def _write_statistics_file(table: pa.Table, path: Path) -> None:
    """Write a statistics file; a full disk stops the command (exit 3), the runs stay."""
    try:
        write_parquet(table, path)
    except OSError as exc:
        raise InfrastructureError(
            f"{path.name} not written: {_fault_text(exc)}. Every run is kept; fix the cause "
            "and run the same command to write it"
        ) from None


def write_sensitivity(out_dir: Path, plan_: CampaignPlan) -> pd.DataFrame:
    """A design campaign's matrix and sensitivity indices (nothing for a grid).

    Writes ``design.parquet`` (:func:`~cwrend_cli.campaign.design.design_matrix`)
    and ``problem.json`` (:func:`~cwrend_cli.campaign.design.problem_document`)
    of the plan's design, then the indices computed from ``runs.parquet``
    (:func:`cwrend_cli.campaign.design.sensitivity`: Sobol for ``sobol``,
    RBD-FAST for ``lhs`` and ``random``) into ``sensitivity.parquet``;
    returns them (empty when the plan has no design, no point has ok runs
    of an architecture, or an RBD-FAST design has fewer than 9 rows).
    """
    spec = plan_.design
    if spec is None:
        return pd.DataFrame()
    unit = spec.unit(plan_.root_seed)
    meta = _stored_metadata(out_dir)
    matrix = design.design_matrix(spec.ranges, spec.rows, unit)
    write_parquet(statistics_table(matrix, meta), out_dir / DESIGN)
    problem = design.problem_document(
        spec.kind, spec.samples, spec.ranges, plan_.root_seed, len(spec.rows), spec.second_order
    )
    write_json(problem, out_dir / PROBLEM)
    runs = pd.read_parquet(out_dir / RUNS)
    runs = runs[runs["run_key"].isin({r.run_key for r in plan_.runs})]
    frame = design.sensitivity(
        runs, spec.rows, spec.ranges, plan_.root_seed, kind=spec.kind, unit=unit,
        second_order=spec.second_order,
    )  # fmt: skip
    if not frame.empty:
        table = statistics_table(frame, _stored_metadata(out_dir))
        _write_statistics_file(table, out_dir / SENSITIVITY)
    return frame


def held_run_keys(out_dir: Path) -> set[str]:
    """Keys of the runs (any status) that ``runs.parquet`` of a campaign directory holds."""
    return {str(k) for k in pd.read_parquet(out_dir / RUNS, columns=["run_key"])["run_key"]}


def subset_statistics(
    out_dir: Path,
    command: Literal["ablate", "sweep"],
    root_seed: int,
    run_keys: Collection[str],
    pairs: Sequence[tuple[str, str]] = statistics.DEFAULT_PAIRS,
) -> CampaignStatistics:
    """The statistics of the runs ``run_keys`` of the directory only; nothing is written.

    What a re-run naming fewer seeds, architectures or grid points reports;
    computed as for the whole directory (same groups and ``pairs``, bootstrap
    seeded from ``root_seed``).
    """
    runs = pd.read_parquet(out_dir / RUNS)
    subset = runs[runs["run_key"].isin(set(run_keys))]
    frame, groups = _statistics(subset, command, root_seed, pairs, _nis_dofs(subset, out_dir))
    return CampaignStatistics(frame, groups, None)
