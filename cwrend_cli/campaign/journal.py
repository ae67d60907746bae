"""What a campaign directory holds, and its journal.

Layout of ``<output.dir>/<name>/``::

    manifest.json                   what ran: config, grid, seeds, archs, hashes, status
    events.jsonl                    the journal: one JSON event per line, appended per task
    runs.parquet                    one row per run (output.tables.runs_table), from the journal
    points.parquet                  one row per point of those runs: id, swept values
                                    (output.tables.points_table; joins steps/ on point)
    ablation.parquet | sweep.parquet  statistics (written by the driver)
    steps/arch=<slug>/*.parquet     per-step data of each task execution (hive-partitioned)
    solves/arch=<slug>/*.parquet    per-solve data, likewise
    recordings/<point>.s<seed>.rrd  Rerun recordings
    references/r<digest>.parquet    open-loop references, one file per distinct scenario
                                    and solver (output.tables.references_table)
    references/index.jsonl          which of them each grid point uses ({"point", "file"})
    design.parquet, problem.json    a sampled design's matrix and SALib problem
    sensitivity.parquet             a sampled design's sensitivity indices

The journal is the truth: a task execution counts once its ``task_done``
event (written in the same append as its run events) is in
``events.jsonl`` (appended once the files it names are on disk, which the
workers leave to it); data files of executions that never completed are
orphans, removed on resume. References are deterministic functions of their
grid point, rewritten whenever needed, so they are never orphans. Here: the
names, appending and reading events, the journal's state, orphan removal,
the manifest check and the manifest, and ``--force``'s wipe.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import shlex
import shutil
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from datetime import UTC, datetime
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from cwrend_cli import __version__
from cwrend_cli.campaign.plan import CampaignPlan
from cwrend_cli.campaign.worker import TaskOutcome
from cwrend_cli.errors import ConfigError
from cwrend_cli.output.files import open_confined_dir, refuse_links
from cwrend_cli.output.layout import (
    ABLATION_STATS,
    DESIGN,
    EVENTS,
    LOCK,
    MANIFEST,
    POINTS,
    PROBLEM,
    RECORDINGS,
    REFERENCES,
    RUNS,
    SENSITIVITY,
    SOLVES,
    STEPS,
    SWEEP_STATS,
)
from cwrend_cli.output.manifest import damaged, pair_texts, read_manifest, recorded_pairs

__all__ = [
    "DATASETS",
    "RUN_FIELDS",
    "STATS_FILES",
    "JournalOwner",
    "JournalState",
    "append_events",
    "campaign_lock",
    "check_confined",
    "check_same_campaign",
    "events_of",
    "finish_manifest",
    "iso",
    "iter_events",
    "load_journal",
    "new_manifest",
    "read_events",
    "remove_orphan_files",
    "versions_digest",
    "wipe",
]

#: Directories of per-task files (journaled, removed on --force, orphans cleaned on resume).
DATASETS = (STEPS, SOLVES, RECORDINGS)
#: The statistics files of ``cwrend ablate`` and ``cwrend sweep`` (a design's matrix too).
STATS_FILES = (ABLATION_STATS, SWEEP_STATS, SENSITIVITY, DESIGN, PROBLEM)


def iso(unix: float) -> str:
    """A UNIX time as an ISO 8601 UTC timestamp with milliseconds."""
    return datetime.fromtimestamp(unix, tz=UTC).isoformat(timespec="milliseconds")


# ---------------------------------------------------------------------------
# Events
# ---------------------------------------------------------------------------


def append_events(
    path: str | Path, events: Sequence[Mapping[str, Any]], *, root: Path | None = None
) -> None:
    """Append JSON lines in one write and fsync.

    A ``kill -9`` or a full disk can only tear the last line; the next append
    first ends such a torn line, so the tear stays one unparsable line that
    :func:`read_events` drops, never glued to the events that follow.

    The data files a ``task_done`` event names (relative to the journal's
    directory) are flushed to disk first: workers write them without waiting
    for the disk (issue 17), and a task counts once its event is in the
    journal, so the event must never be on disk before its files.

    Never through a link: the file itself (``O_NOFOLLOW``), and with ``root``
    every directory between ``root`` and the file too
    (:func:`~cwrend_cli.output.files.open_confined_dir`).
    """
    base = Path(path).parent
    _flush(base / f for e in events if e.get("event") == "task_done" for f in e.get("files", ()))
    text = "".join(json.dumps(e, sort_keys=True, default=_json_default) + "\n" for e in events)
    with open(_open_to_append(Path(path), root), "ab") as fh:
        if fh.tell() > 0 and os.pread(fh.fileno(), 1, fh.tell() - 1) != b"\n":
            text = "\n" + text
        fh.write(text.encode("utf-8"))
        fh.flush()
        os.fsync(fh.fileno())


def _open_to_append(path: Path, root: Path | None = None) -> int:
    """A descriptor appending to ``path``, never through a link planted after start-up (issue 36,
    item 6): a link is an :class:`OSError` ``ELOOP`` naming it."""
    flags = os.O_RDWR | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW
    directory = open_confined_dir(root, path.parent) if root is not None else None
    try:
        return os.open(path if directory is None else path.name, flags, 0o644, dir_fd=directory)
    except OSError as exc:
        if exc.errno != errno.ELOOP:
            raise
        raise OSError(
            errno.ELOOP,
            "a symbolic link, and cwrend never writes through links: remove it and run the "
            "command again",
            str(path),
        ) from None
    finally:
        if directory is not None:
            os.close(directory)


def _flush(paths: Iterable[Path]) -> None:
    """Wait until the contents of the files ``paths`` are on disk."""
    for path in paths:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def iter_events(path: str | Path, start: int = 0) -> Iterator[dict[str, Any]]:
    """The complete events of a journal, one at a time, read line by line.

    A torn or unparsable line is dropped (a torn last line included); a
    missing journal has no events. Only one line is held at a time, so
    reading costs memory for what the caller keeps, not for the file.
    ``start``: read from this byte on (the journal's size when an invocation
    began: what it appended).
    """
    path = Path(path)
    if not path.exists():
        return
    with open(path, "rb") as fh:
        fh.seek(start)
        for chunk in fh:  # split on b"\n"; the \r-separated pieces as bytes.splitlines does
            for line in chunk.splitlines():
                try:
                    event = json.loads(line)
                except ValueError:  # torn, not JSON, not UTF-8
                    continue
                if isinstance(event, dict):
                    yield event


def read_events(path: str | Path) -> list[dict[str, Any]]:
    """All complete events of a journal; a torn or unparsable line is dropped.

    Holds every event: for a large journal prefer :func:`iter_events`.
    """
    return list(iter_events(path))


def events_of(outcome: TaskOutcome, campaign: str, now: float) -> list[dict[str, Any]]:
    """The journal events of one task execution, ``task_done`` last (``now``: UNIX time)."""
    events: list[dict[str, Any]] = []
    for o in outcome.outcomes:
        s = o.spec
        common = {
            "run_key": s.run_key,
            "execution": outcome.execution,
            "campaign_hash": campaign,
            "cwrend_version": __version__,
            "versions": versions_digest(),
        }
        events.append({"event": "run_started", "time": iso(o.started_at), **common})
        events.append(
            {
                "event": "run_finished" if o.status == "ok" else "run_failed",
                "time": iso(o.started_at + o.duration_s),
                **common,
                "point": s.point,
                "arch": s.arch,
                "seed": s.seed,
                "params": dict(s.params),
                "dispersed": dict(s.dispersed),
                "status": o.status,
                "metrics": dict(o.metrics),
                "error": o.error,
                "duration_s": o.duration_s,
            }
        )
    events.extend(
        {"event": "recording_failed", "time": iso(now), "error": w} for w in outcome.warnings
    )
    events.append(
        {
            "event": "task_done",
            "time": iso(now),
            "execution": outcome.execution,
            "files": list(outcome.files),
            "files_s": outcome.files_s,
            "campaign_hash": campaign,
            "cwrend_version": __version__,
            "versions": versions_digest(),
        }
    )
    return events


@dataclass(frozen=True)
class JournalOwner:
    """Whose journal lines count (issue 36 item 4): each line names its campaign and versions.

    ``campaign_hash``: the campaign's; ``versions``: the :func:`versions_digest`
    a line must carry (``None``: any, ``--allow-version-change``); ``legacy``:
    lines written before lines carried their versions count when their cwrend
    version is this one's (the caller has checked the manifest's environment).
    """

    campaign_hash: str
    versions: str | None
    legacy: bool = False

    def reason_against(self, event: Mapping[str, Any]) -> str | None:
        """Why ``event`` is not this owner's (a few words), or ``None`` when it is."""
        campaign = event.get("campaign_hash")
        if campaign is None:
            return "no campaign hash"
        if campaign != self.campaign_hash:
            return "another campaign"
        if self.versions is None:
            return None
        versions = event.get("versions")
        if versions is None:
            legacy = self.legacy and event.get("cwrend_version") == __version__
            return None if legacy else "no versions"
        return None if versions == self.versions else "other versions"


#: The fields of an outcome event that :func:`load_journal` keeps: what ``runs.parquet``
#: (:func:`~cwrend_cli.output.tables.runs_table`) and the driver read.
RUN_FIELDS = (
    "run_key", "execution", "point", "arch", "seed", "status", "error", "duration_s",
    "metrics", "params", "dispersed",
)  # fmt: skip
#: Fields whose few distinct texts repeat from run to run (held once each).
_SHARED_FIELDS = frozenset({"execution", "point", "arch", "status"})


def _one(value: Any, shared: dict[str, str]) -> Any:
    """``value``, or the equal text already in ``shared`` (then held once)."""
    return shared.setdefault(value, value) if isinstance(value, str) else value


def _kept(event: Mapping[str, Any], shared: dict[str, str]) -> dict[str, Any]:
    """The :data:`RUN_FIELDS` of an outcome event, compact: the names and texts of its mappings
    (metrics, parameters, draws) and its repeated texts held once in ``shared``, not once per run.

    JSON parsing makes new strings for every line: shared, a run's outcome takes about 1.5 kB
    instead of 3.6 kB (issue 17); every value is equal to the event's.
    """
    record: dict[str, Any] = {}
    for name in RUN_FIELDS:
        if name not in event:
            continue
        value = event[name]
        if isinstance(value, dict):
            value = {shared.setdefault(k, k): _one(v, shared) for k, v in value.items()}
        elif name in _SHARED_FIELDS:
            value = _one(value, shared)
        record[name] = value
    return record


@dataclass(frozen=True)
class JournalState:
    """What a campaign directory holds according to its journal."""

    runs: Mapping[str, Mapping[str, Any]]  # run_key -> its latest complete outcome (RUN_FIELDS)
    files: frozenset[str]  # data files written by completed task executions
    set_aside: Mapping[str, int] = field(default_factory=dict)  # why -> run records not owned


def load_journal(
    path: str | Path, start: int = 0, owner: JournalOwner | None = None
) -> JournalState:
    """Runs and files of every task execution that completed (its ``task_done`` was written).

    ``start``: only the events from this byte on (:func:`iter_events`), e.g.
    the runs an invocation journaled, however their executions are named.
    ``owner``: only the lines that prove they are its campaign's and versions'
    (:meth:`JournalOwner.reason_against`) count; the run records set aside are
    counted by reason in ``set_aside``, and the files of a ``task_done`` set
    aside are orphans (removed on resume, computed again).

    Streams the journal (:func:`iter_events`) and keeps what the state needs:
    per run key its latest outcome event (by position in the journal) that a
    ``task_done`` of its execution follows, and the files the ``task_done``
    events name. An execution's outcome events precede its ``task_done`` (one
    append), so they wait in a buffer per execution until it arrives;
    ``run_started`` and other events are dropped at once. Memory:
    the latest outcome per run plus the outcomes of executions not (yet)
    done, not the file; of each outcome only its :data:`RUN_FIELDS` are kept
    (:func:`_kept`).
    """
    # run_key -> [first position, latest position, latest event] of a done execution's outcomes
    runs: dict[str, list[Any]] = {}
    pending: dict[Any, list[tuple[int, dict[str, Any]]]] = {}  # not-done execution -> outcomes
    files: dict[Any, Sequence[str]] = {}  # done execution -> the files of its last task_done
    shared: dict[str, str] = {}

    def keep(position: int, event: dict[str, Any]) -> None:
        latest = runs.get(event["run_key"])
        if latest is None:
            runs[event["run_key"]] = [position, position, event]
        elif latest[1] < position:
            latest[1:] = [position, event]
        else:
            latest[0] = min(latest[0], position)

    set_aside: dict[str, int] = {}
    for position, event in enumerate(iter_events(path, start)):
        kind = event.get("event")
        if owner is not None and kind in ("run_finished", "run_failed", "task_done"):
            reason = owner.reason_against(event)
            if reason is not None:  # never reused: its runs are computed again
                if kind != "task_done":
                    set_aside[reason] = set_aside.get(reason, 0) + 1
                continue
        if kind in ("run_finished", "run_failed"):
            execution = event.get("execution")
            # counts once a task_done of its execution follows it: the name of an execution
            # repeats when a task is rerun, and a rerun torn before its task_done counts for
            # nothing (its files are orphans), even if an earlier run of the name completed
            pending.setdefault(execution, []).append((position, _kept(event, shared)))
        elif kind == "task_done":
            files[event["execution"]] = event.get("files", ())
            for buffered in pending.pop(event["execution"], ()):
                keep(*buffered)
    ordered = sorted(runs.items(), key=lambda item: int(item[1][0]))  # first seen, as before
    return JournalState(
        {key: entry[2] for key, entry in ordered},
        frozenset(f for named in files.values() for f in named),
        set_aside,
    )


def remove_orphan_files(root: str | Path, keep: frozenset[str]) -> list[str]:
    """Delete data files (and temp files) not written by a completed task execution.

    The references are not journaled and stay, except for the temporary file
    of an interrupted write.
    """
    root = Path(root)
    removed = []
    for dataset in DATASETS:
        base = root / dataset
        if not base.exists():
            continue
        for path in sorted(base.rglob("*")):
            if path.is_file():
                rel = path.relative_to(root).as_posix()
                if rel not in keep:
                    path.unlink()
                    removed.append(rel)
    if (root / REFERENCES).is_dir():
        for path in sorted((root / REFERENCES).glob(".*.tmp")):
            path.unlink()
            removed.append(path.relative_to(root).as_posix())
    return removed


# ---------------------------------------------------------------------------
# The manifest and --force
# ---------------------------------------------------------------------------


def check_confined(out_dir: Path) -> None:
    """Refuse a campaign directory holding symbolic links where cwrend reads or writes.

    cwrend never reads or writes through a link: a linked ``steps/`` (or
    journal, manifest, …) would send results, or ``--force``'s removal,
    outside the campaign directory (issue 20). Links planted later are
    refused by each write (:func:`~cwrend_cli.output.files.atomic_path`'s
    ``root``, :func:`append_events`; issue 36).
    """
    names = (MANIFEST, RUNS, POINTS, EVENTS, LOCK, *STATS_FILES, *DATASETS, REFERENCES)
    refuse_links(
        out_dir, names, "the campaign directory", ", or choose another output.dir / output.name"
    )


@contextmanager
def campaign_lock(out_dir: Path) -> Iterator[None]:
    """Hold an exclusive lock on a campaign directory for the ``with`` block.

    A second process on the same directory is refused (naming the holder)
    instead of writing duplicate rows beside the first. The lock is an
    ``flock`` on :data:`~cwrend_cli.output.layout.LOCK`, which names its
    holder: the kernel releases it when its holder exits however it exits,
    so a lock is never stale (a file left by a killed holder is taken over).

    The holder removes the file on release, still holding the lock, then
    closes it. Another process may have opened the file just before the
    removal and take the lock on the removed file once it is closed: a lock
    nobody else can see. So a lock counts only when the file locked is still
    the one at the path (same device and inode); otherwise it is dropped and
    the path opened again (:func:`_locked_fd`). Removing the file only while
    holding its lock keeps that check sound: a file at the path whose lock
    is held is never removed by anyone else.
    """
    path = out_dir / LOCK
    fd = _locked_fd(path, out_dir)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()}, since {iso(time.time())}\n".encode(), 0)
        yield
    finally:
        # while the lock is held (see above); an unwritable directory keeps it, still harmless
        with suppress(OSError):
            path.unlink(missing_ok=True)
        os.close(fd)  # releases the lock


def _locked_fd(path: Path, out_dir: Path) -> int:
    """An open descriptor of ``path`` holding its ``flock``, the file still being at ``path``.

    Refuses (:class:`ConfigError`) when another process holds the lock.
    """
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            raise ConfigError(
                f"{path}: cannot open the campaign lock ({exc.strerror}); cwrend writes into "
                f"{out_dir} (a campaign's runs and statistics, a report's report/): make it "
                "writable, or copy the directory to a writable place and run the command on the "
                "copy"
            ) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 256, 0).decode("utf-8", "replace").strip() or "unknown"
            os.close(fd)
            raise ConfigError(
                f"{out_dir} is in use by another cwrend process ({holder}); wait for it to "
                "finish or stop it, then run the command again"
            ) from None
        except BaseException:
            os.close(fd)
            raise
        held = os.fstat(fd)
        try:
            now = os.stat(path, follow_symlinks=False)
        except FileNotFoundError:  # removed by its holder on release, after our open
            now = None
        if now is not None and (now.st_dev, now.st_ino) == (held.st_dev, held.st_ino):
            return fd
        os.close(fd)  # a lock on a file no longer at the path excludes nobody: again


def wipe(out_dir: Path) -> None:
    """Remove what a campaign writes (``--force``), nothing else."""
    for name in (MANIFEST, RUNS, POINTS, EVENTS, *STATS_FILES):
        (out_dir / name).unlink(missing_ok=True)
    for dataset in (*DATASETS, REFERENCES):
        if (out_dir / dataset).exists():
            shutil.rmtree(out_dir / dataset)


#: Distributions whose version can change a campaign's numbers (cwrend's own, and the numerics).
NUMERICS_DISTRIBUTIONS = ("numpy", "scipy", "numba", "clarabel")


def environment() -> dict[str, str]:
    """The versions a campaign's numbers depend on: cwrend and :data:`NUMERICS_DISTRIBUTIONS`."""
    versions = {"cwrend": __version__}
    for name in NUMERICS_DISTRIBUTIONS:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "absent"
    return versions


@lru_cache(maxsize=1)
def versions_digest() -> str:
    """A short digest of :func:`environment` that every journal line carries (16 hex digits).

    Proves which versions computed a line's runs in 26 bytes, where the
    versions themselves would take about 100 (the manifest lists them).
    """
    text = json.dumps(environment(), sort_keys=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def _changed_versions(previous: Mapping[str, Any]) -> list[str]:
    """``name a → b`` for each version that differs from the manifest's (old ones: cwrend only)."""
    recorded = previous.get("environment")
    if not isinstance(recorded, dict):
        recorded = {"cwrend": previous.get("cwrend_version")}
    now = environment()
    return [
        f"{name} {recorded[name]} → {now.get(name)}"
        for name in recorded
        if recorded[name] != now.get(name)
    ]


def check_same_campaign(
    out_dir: Path,
    plan_: CampaignPlan,
    *,
    allow_version_change: bool = False,
    repair_manifest: bool = False,
) -> dict[str, Any]:
    """Refuse a directory holding another campaign (other config or grid), unless empty.

    Also refuse to resume a campaign written by another cwrend version or
    with other versions of the numerics (:func:`environment`): its runs
    could differ from this installation's in the last bits, and a campaign
    must hold numbers from one computation (issue 21), unless
    ``allow_version_change``. Returns the directory's previous manifest
    (empty when there is none).

    A damaged manifest (:func:`~cwrend_cli.output.manifest.read_manifest`) is
    refused with its fix; with ``repair_manifest`` it is treated as lost: the
    journal's records must name this campaign, and the caller writes a new
    manifest over it (issue 36 item 10).
    """
    manifest = out_dir / MANIFEST
    if not manifest.exists() or (repair_manifest and damaged(manifest)):
        # each journal record names its campaign: a lost manifest cannot hide another one
        others = {
            str(e["campaign_hash"])
            for e in iter_events(out_dir / EVENTS)
            if "campaign_hash" in e and e["campaign_hash"] != plan_.campaign_hash
        }
        if others:
            lost = "a damaged" if manifest.exists() else "no"
            raise ConfigError(
                f"{out_dir} has {lost} manifest.json but its journal holds runs of another "
                f"campaign (hash {sorted(others)[0][:12]}… vs {plan_.campaign_hash[:12]}…); "
                "use --force to start over, or another output.name"
            )
        return {}
    previous = read_manifest(
        manifest,
        "run the same command with --repair-manifest to rebuild it from the journal (the runs "
        "it holds are kept), or with --force to start the campaign over",
    )
    if previous.get("campaign_hash") != plan_.campaign_hash:
        raise ConfigError(
            f"{out_dir} holds a campaign with a different configuration or grid "
            f"(hash {str(previous.get('campaign_hash'))[:12]}… vs {plan_.campaign_hash[:12]}…); "
            "use --force to start over, or another output.name"
        )
    changed = _changed_versions(previous)
    if changed and not allow_version_change:
        raise ConfigError(
            f"{out_dir} was computed with other versions ({', '.join(changed)}); its runs may "
            "differ from this installation's in the last bits. Resume anyway with "
            "--allow-version-change, or start over with --force"
        )
    return previous


def _earlier_sessions(previous: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The sessions a previous manifest records (one made up from a manifest without them)."""
    sessions = previous.get("sessions")
    if isinstance(sessions, list):
        return [dict(s) for s in sessions if isinstance(s, dict)]
    if "started_at" in previous:  # written before manifests kept their sessions
        keys = ("command", "cwrend_version", "started_at", "finished_at", "status")
        return [{k: previous.get(k) for k in keys}]
    return []


def _design_record(plan_: CampaignPlan) -> dict[str, Any] | None:
    """A sampled design as the manifest records it (None for a grid)."""
    if plan_.design is None:
        return None
    spec = plan_.design
    return {**spec.identity(), "samples": spec.samples, "second_order": spec.second_order}


def new_manifest(
    plan_: CampaignPlan,
    *,
    command: str,
    executor: Mapping[str, Any],
    started: float,
    previous: Mapping[str, Any] | None = None,
    argv: Sequence[str] | None = None,
    pairs: Sequence[tuple[str, str]] = (),
) -> dict[str, Any]:
    """The manifest of a campaign invocation that starts now (``status`` = running).

    ``sessions`` lists every invocation of the campaign (the ``previous``
    manifest's, then this one): command, its full command line (``argv``,
    quoted as a shell would, and the working directory it ran in), version,
    executor, config hash and ``[output]`` table, start, end, runs computed
    and skipped, how it ended. ``started_at`` is the first session's start,
    so resuming a campaign never hides when it began.

    ``config_hash`` is this session's; ``config_hashes`` every config hash the
    campaign's files were written under, in order of first use. A resume may
    change ``[output]`` (``--set output.steps_seeds=…``), which the config hash
    covers and the campaign hash does not: the files of earlier sessions keep
    their hash in their metadata, and each session's ``output`` gives back the
    whole config of that hash (the rest is the campaign's).

    ``pairs``: the pairs this invocation adds to the default comparisons
    (``--pair A:B``); ``pairs`` (as ``"A:B"``) records them after those the
    ``previous`` manifest recorded, so that a later command that rewrites the
    statistics compares them again (:func:`~cwrend_cli.output.manifest.recorded_pairs`).
    Absent when no command added a pair.

    ``archs``, ``seeds``: every architecture and seed the campaign's files hold,
    in order of first use (the ``previous`` manifest's, then this invocation's): a
    resume may add architectures or run fewer seeds (the campaign hash covers
    neither) and keeps the runs of the earlier ones; :func:`finish_manifest` adds
    those of the journal's runs (a manifest rebuilt by ``--repair-manifest`` has no
    ``previous``).

    ``nis_offset_given``: the base config's ``schedule.nis_offset`` was given by
    the user (:attr:`CampaignPlan.nis_offset_given`); ``config`` is a resolved
    tree, which has lost that, and a point that sets the sensor fills the offset
    in for its sensor only when it was not; likewise ``xf_given`` (a point that
    introduces a corridor ends at its port at rest when it is false). Outside
    ``config``: no hash changes.
    """
    sessions = _earlier_sessions(previous or {})
    earlier_hash = (previous or {}).get("config_hash")
    if sessions and isinstance(earlier_hash, str):  # the previous manifest's hash is its last's
        sessions[-1].setdefault("config_hash", earlier_hash)
    session: dict[str, Any] = {
        "command": command,
        "command_line": None if argv is None else shlex.join(argv),
        "cwd": None if argv is None else os.getcwd(),
        "cwrend_version": __version__,
        "environment": environment(),
        "executor": dict(executor),
        "config_hash": plan_.config_hash,
        "output": plan_.base.get("output"),
        "started_at": iso(started),
        "status": "running",
    }
    recorded = (previous or {}).get("config_hashes")
    hashes = [
        *(recorded if isinstance(recorded, list) else ()),
        *(s.get("config_hash") for s in sessions),
        plan_.config_hash,
    ]
    added = dict.fromkeys([*recorded_pairs(previous or {}), *pairs])
    return {
        **({"pairs": pair_texts(list(added))} if added else {}),
        "cwrend_version": __version__,
        "environment": environment(),
        "command": command,
        "campaign_hash": plan_.campaign_hash,
        "config": plan_.base,
        "config_hash": plan_.config_hash,
        "config_hashes": list(dict.fromkeys(h for h in hashes if isinstance(h, str))),
        "grid": {k: list(v) for k, v in plan_.grid},
        "design": _design_record(plan_),
        "seeds": _union((previous or {}).get("seeds"), plan_.seeds, int),
        "root_seed": plan_.root_seed,
        "archs": _union((previous or {}).get("archs"), plan_.archs, str),
        "nis_offset_given": plan_.nis_offset_given,
        "xf_given": plan_.xf_given,
        "executor": dict(executor),
        "started_at": sessions[0].get("started_at", iso(started)) if sessions else iso(started),
        "status": "running",
        "sessions": [*sessions, session],
    }


_Item = TypeVar("_Item", str, int)


def _union(earlier: object, later: Iterable[_Item], kind: type[_Item]) -> list[_Item]:
    """The ``kind`` items of the list ``earlier`` (anything else: none), then the new ones
    of ``later``, in order of first use."""
    kept: list[_Item] = []
    if isinstance(earlier, list):
        kept = [a for a in earlier if isinstance(a, kind) and not isinstance(a, bool)]
    kept.extend(later)
    return list(dict.fromkeys(kept))


def finish_manifest(
    manifest: dict[str, Any], *, finished: float, status: str, computed: int, skipped: int,
    counts: Mapping[str, int], archs: Iterable[str] = (), seeds: Iterable[int] = (),
) -> None:  # fmt: skip
    """Record the end of this invocation in ``manifest`` (its last session) and the counts.

    ``archs``, ``seeds``: the architectures and seeds of the runs the campaign's
    files now hold, added to the manifest's ``archs`` and ``seeds`` (:func:`new_manifest`).
    """
    manifest["archs"] = _union(manifest.get("archs"), archs, str)
    manifest["seeds"] = _union(manifest.get("seeds"), seeds, int)
    end = iso(finished)
    manifest["sessions"][-1].update(
        finished_at=end, status=status, runs_computed=computed, runs_skipped=skipped
    )
    manifest.update(finished_at=end, status=status, counts=dict(counts))
