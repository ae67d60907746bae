"""Writing files: every file cwrend writes goes through :func:`atomic_path`.

A file is written to a temporary name in its directory, flushed to disk and
moved into place with :func:`os.replace`, so a reader (a report, a resumed
campaign) or a ``kill -9`` never sees a half-written file (a campaign
worker's steps/solves files are flushed by the journal instead, before it
records their task: :func:`atomic_path`'s ``durable``). Here too: the
Parquet and JSON writers built on it, and :func:`write_run`, the directory of
``cwrend run``. The Arrow schemas of the tables live in
:mod:`cwrend_cli.output.tables`.
"""

from __future__ import annotations

import errno
import json
import os
import secrets
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from cwrend_cli import __version__
from cwrend_cli.errors import ConfigError
from cwrend_cli.output.layout import (
    EVENTS,
    MANIFEST,
    POINTS,
    RUN_CONFIG,
    RUN_FILES,
    RUN_REFERENCES,
    RUN_SOLVES,
    RUN_STEPS,
    RUN_SUMMARY,
    RUNS,
)
from cwrend_cli.output.tables import (
    reference_row,
    references_table,
    solves_table,
    steps_table,
    summary_row,
    summary_table,
)
from cwrend_cli.physics.simulation import References, RunResult

__all__ = [
    "atomic_path",
    "open_confined_dir",
    "refuse_links",
    "write_json",
    "write_parquet",
    "write_run",
]


@contextmanager
def atomic_path(path: Path, *, durable: bool = True, root: Path | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; move it onto ``path`` on success.

    The one way cwrend writes a file: readers (and a resumed campaign) see
    either nothing or the complete file, never a partial one.

    ``durable``: the file is on disk before it is moved into place, so a
    crash of the machine leaves the old file or the complete new one.
    ``False`` leaves that wait to whoever records the file: a campaign
    worker's steps/solves files, which the journal flushes before it records
    their task (:func:`cwrend_cli.campaign.journal.append_events`), so the
    worker computes on instead of waiting for the disk.

    ``root``: a directory holding ``path`` that the write must not leave.
    Every directory between ``root`` and ``path`` is opened (or created)
    without following links, and the file is created, written and moved
    within the last one through its descriptor: a link planted there at any
    time, also after a campaign started, is refused with an :class:`OSError`
    (``ELOOP``) instead of written through (issue 36, item 6). Without
    ``root`` the directory of ``path`` is made as given (links followed).
    """
    path = Path(path)
    (path.parent if root is None else root).mkdir(parents=True, exist_ok=True)
    directory = open_confined_dir(root if root is not None else path.parent, path.parent)
    try:
        name = _create_temporary(directory, path.name)
        try:
            yield _through(directory, name, path.parent)
            if durable:
                fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW, dir_fd=directory)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
            os.chmod(name, 0o644, dir_fd=directory, follow_symlinks=False)
            os.replace(name, path.name, src_dir_fd=directory, dst_dir_fd=directory)
        finally:
            with suppress(FileNotFoundError):  # moved into place, or never written
                os.unlink(name, dir_fd=directory)
    finally:
        os.close(directory)


#: Where this process sees its open descriptors as paths (Linux); elsewhere names are used.
_FD_PATHS = Path("/proc/self/fd")


def _through(directory: int, name: str, parent: Path) -> Path:
    """A path to ``name`` in the open ``directory`` that no link planted later can redirect."""
    if _FD_PATHS.is_dir():
        return _FD_PATHS / str(directory) / name
    return parent / name


def _create_temporary(directory: int, name: str) -> str:
    """Create an empty file ``.<name>.<random>.tmp`` in the open ``directory``; its name."""
    for _ in range(100):
        temporary = f".{name}.{secrets.token_hex(4)}.tmp"
        try:
            fd = os.open(
                temporary,
                os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW,
                0o600,
                dir_fd=directory,
            )
        except FileExistsError:
            continue
        os.close(fd)
        return temporary
    raise FileExistsError(errno.EEXIST, "no free temporary name", name)


def open_confined_dir(root: Path, directory: Path) -> int:
    """A descriptor of ``directory``, reached from ``root`` without following any link.

    Each directory below ``root`` is created when missing and opened with
    ``O_NOFOLLOW``; a link (or a file) in the way raises :class:`OSError`
    ``ELOOP`` naming it. ``directory`` must be ``root`` or inside it. The
    caller closes the descriptor.
    """
    parts = Path(os.path.normpath(directory)).relative_to(os.path.normpath(root)).parts
    fd = os.open(root, os.O_RDONLY | os.O_DIRECTORY)
    try:
        for i, part in enumerate(parts):
            if part == "..":
                raise ValueError(f"{directory} is not inside {root}")
            with suppress(FileExistsError):
                os.mkdir(part, 0o777, dir_fd=fd)
            try:
                inner = os.open(part, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=fd)
            except OSError as exc:
                if exc.errno not in (errno.ENOTDIR, errno.ELOOP):
                    raise
                where = Path(root, *parts[: i + 1])
                raise OSError(
                    errno.ELOOP,
                    f"not a directory but a link or a file, and cwrend never writes through "
                    f"links nor outside {root}: remove it and run the command again",
                    str(where),
                ) from None
            os.close(fd)
            fd = inner
    except BaseException:
        os.close(fd)
        raise
    return fd


def refuse_links(root: Path, names: Iterable[str], what: str, fix: str = "") -> None:
    """Refuse (:class:`ConfigError`, exit 2) a link at ``root/<name>`` or inside such a directory.

    What cwrend reads or writes in a results directory is checked before a
    command reads or writes it (its writes are confined as well:
    :func:`atomic_path`'s ``root``). ``what`` names the directory for the
    message (``the campaign directory``), ``fix`` is appended to its advice.
    """
    for name in names:
        path = root / name
        if path.is_symlink():
            raise _linked(path, root, what, fix)
        for base, dirs, files in os.walk(path):  # follows no link; nothing for a file
            for entry in (*dirs, *files):
                if (Path(base) / entry).is_symlink():
                    raise _linked(Path(base) / entry, root, what, fix)


def _linked(path: Path, root: Path, what: str, fix: str) -> ConfigError:
    return ConfigError(
        f"{path}: a symbolic link inside {what}; cwrend reads and writes only inside {root} "
        f"and never follows links: remove the link{fix}"
    )


#: Approximate bytes a run adds to a campaign directory: its per-step data (when kept,
#: output.steps_seeds), and the rest (re-solves, journal, runs.parquet row).
STEPS_BYTES_PER_RUN = 200_000
OTHER_BYTES_PER_RUN = 6_000
#: Approximate bytes of one recording (a seed's architectures and references).
RECORDING_BYTES = 1_600_000


def estimated_bytes(runs: int, runs_with_steps: int, recordings: int) -> int:
    """Roughly what ``runs`` runs (``runs_with_steps`` with per-step data) and recordings take."""
    return (
        runs * OTHER_BYTES_PER_RUN
        + runs_with_steps * STEPS_BYTES_PER_RUN
        + recordings * RECORDING_BYTES
    )


def _cannot_write(path: Path, reason: str, setting: str) -> ConfigError:
    return ConfigError(f"{str(path)!r}: cannot write results there ({reason}); {setting}")


def check_output_dir(path: str | Path, setting: str) -> Path:
    """Refuse, without creating anything, a ``path`` that cannot become a results directory.

    For a command that computes before it writes (``cwrend run``): a file in
    the way, a parent that is a file or not writable, a name longer than the
    file system allows. ``setting`` names the option or key to change.
    """
    out = Path(path)
    if out.exists():
        if not out.is_dir():
            raise _cannot_write(out, "File exists", setting)
        return out
    existing = out.parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise _cannot_write(out, "Not a directory", setting)
    name_max = os.pathconf(existing, "PC_NAME_MAX") if hasattr(os, "pathconf") else 255
    if any(len(part.encode()) > name_max for part in out.parts):
        raise _cannot_write(out, "File name too long", setting)
    if not os.access(existing, os.W_OK | os.X_OK):
        read_only = hasattr(os, "statvfs") and os.statvfs(existing).f_flag & os.ST_RDONLY
        raise _cannot_write(out, "Read-only file system" if read_only else "Permission denied",
                            setting)  # fmt: skip
    return out


def _there(path: Path, *names: str) -> bool:
    """Whether one of ``names`` exists in ``path`` (False for a path that cannot be looked
    at, e.g. a name too long: what writes there says why)."""
    return any(os.path.lexists(path / name) for name in names)


def holds_campaign(path: Path) -> bool:
    """Whether ``path`` holds a campaign: its manifest, or its journal (a manifest lost)."""
    return _there(path, MANIFEST, EVENTS)


def holds_run(path: Path) -> bool:
    """Whether ``path`` holds a ``cwrend run``'s output (its config or summary), no campaign."""
    return _there(path, RUN_CONFIG, RUN_SUMMARY) and not holds_campaign(path)


def _campaign_above(path: Path) -> bool:
    """Whether ``path``, a directory above the one checked, holds a campaign.

    Its journal, or its manifest beside its runs or points: a ``manifest.json``
    alone (a web project's has that name too) does not make a parent a campaign.
    """
    return _there(path, EVENTS) or (_there(path, MANIFEST) and _there(path, RUNS, POINTS))


def _run_above(path: Path) -> bool:
    """Whether ``path``, a directory above the one checked, holds a ``cwrend run``'s output.

    Its summary beside its config or steps (the summary is written first): a
    ``config.json`` alone (a project's) does not make a parent a run's directory.
    """
    return (
        _there(path, RUN_SUMMARY)
        and _there(path, RUN_CONFIG, RUN_STEPS)
        and not _campaign_above(path)
    )


def _enclosing(path: Path, holds: Callable[[Path], bool]) -> Path | None:
    """The nearest directory strictly above ``path`` (links and ``..`` resolved) that ``holds``."""
    for parent in Path(path).resolve().parents:
        if holds(parent):
            return parent
    return None


def check_run_dir(path: Path, setting: str) -> None:
    """Refuse (:class:`ConfigError`, exit 2) a ``cwrend run`` directory in a campaign's tree.

    The directory itself or any directory above it holding a campaign: a
    run's files among a campaign's would be neither's. ``setting`` names the
    option or key to change.
    """
    campaign = path if holds_campaign(path) else _enclosing(path, _campaign_above)
    if campaign is not None:
        where = "" if campaign == path else f"{path} is inside {campaign}, which "
        raise ConfigError(
            f"{where or f'{path} '}holds a campaign ({MANIFEST} or {EVENTS}) and cwrend run "
            f"never writes into a campaign's directory or below it: {setting} outside it, "
            "or use the campaign's own commands (cwrend ablate / sweep with its config to add "
            "runs, cwrend report to report on it)"
        )


def check_campaign_dir(path: Path) -> None:
    """Refuse (:class:`ConfigError`, exit 2) a campaign directory among a run's or a campaign's.

    A directory that holds a ``cwrend run``'s output, or any directory inside
    one; or a directory inside another campaign's directory. A campaign's
    files beside a run's would be neither's, and ``--force`` removes only what
    a campaign writes, so it is refused with ``--force`` too.
    """
    fix = "choose another --name (output.name) or output.dir"
    if holds_run(path):
        raise ConfigError(
            f"{path} holds the output of cwrend run ({RUN_CONFIG} / {RUN_SUMMARY}, no "
            f"{MANIFEST}) and a campaign never writes beside a run's files (--force "
            f"included): {fix}, or move the run's files elsewhere (a new cwrend run into it "
            "replaces them)"
        )
    run = _enclosing(path, _run_above)
    if run is not None:
        raise ConfigError(
            f"{path} is inside {run}, which holds the output of cwrend run ({RUN_SUMMARY}), "
            f"and a campaign never writes inside a run's directory (--force included): {fix} "
            "outside it"
        )
    campaign = _enclosing(path, _campaign_above)
    if campaign is not None:
        raise ConfigError(
            f"{path} is inside {campaign}, which holds a campaign ({MANIFEST} / {EVENTS}), "
            f"and a campaign never writes inside another campaign's directory (--force "
            f"included): {fix} outside it"
        )


def remove_run(path: Path) -> None:
    """Remove the files of an earlier ``cwrend run`` in ``path`` (:data:`RUN_FILES`), if any.

    :data:`RUN_CONFIG` first: a directory left between the removal and the new
    run's writes holds no config, so it reads as incomplete rather than as a
    mix of two runs. Other files in ``path`` are not touched.
    """
    for name in RUN_FILES:
        (path / name).unlink(missing_ok=True)


def make_output_dir(path: str | Path, setting: str) -> Path:
    """Create the directory ``path`` (and parents) to write results into, or refuse clearly.

    Raises :class:`~cwrend_cli.errors.ConfigError` naming the path, the reason
    and ``setting`` (the option or config key to change) when it cannot be a
    directory: a file is in the way, a parent is a file, permission is
    denied, a name is too long.
    """
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _cannot_write(out, exc.strerror or str(exc), setting) from None
    return out


def write_parquet(
    table: pa.Table, path: str | Path, *, durable: bool = True, root: Path | None = None
) -> Path:
    """Write ``table`` to ``path`` atomically (temp file + rename; ``durable``, ``root``: see
    :func:`atomic_path`).

    Snappy-compressed, strings dictionary-encoded and floats byte-stream-split:
    what a worker spends most of its non-simulation time on is encoding and
    compressing per-step floats, which do not compress much. Splitting their
    bytes by significance lets Snappy find the repeats (the sign and
    exponent bytes): the steps file of a 16-seed task is about 9 % smaller
    than with Zstandard and its write 25–35 % cheaper (issue 17). Min/max
    statistics are written for the columns that are not floats (run keys,
    points, steps, statuses: what a reader filters row groups by) and not
    for the floats, where they took half of the write (0.73 → 0.37 ms per
    adaptive run's 801 steps, measured on a 16-seed task) for a pruning no
    reader of these one-row-group files gets. Encodings of the file only:
    the table read back is the one written (values, types, metadata).
    """
    path = Path(path)
    # Dictionary encoding pays off for the repeated strings only; on float columns it
    # costs half the write time and makes the file larger.
    strings = [f.name for f in table.schema if pa.types.is_string(f.type)]
    floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
    others = [f.name for f in table.schema if not pa.types.is_floating(f.type)]
    with atomic_path(path, durable=durable, root=root) as tmp:
        pq.write_table(
            table,
            tmp,
            compression="snappy",
            use_dictionary=strings,
            use_byte_stream_split=floats or False,
            write_statistics=others or False,
        )
    return path


def write_json(data: Any, path: str | Path, *, root: Path | None = None) -> Path:
    """Write ``data`` as indented JSON to ``path`` atomically (``root``: :func:`atomic_path`)."""
    path = Path(path)
    with atomic_path(path, root=root) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return path


def write_run(
    out_dir: str | Path,
    resolved_config: Mapping[str, Any],
    config_hash: str,
    results: Sequence[RunResult],
    refs: References,
) -> Path:
    """Write the files of ``cwrend run`` into ``out_dir``.

    ``config.json`` (resolved config and its hash), ``summary.parquet``,
    ``steps.parquet``, ``solves.parquet`` and ``references.parquet``. The
    config is written last, so its presence marks a complete output. The
    files of an earlier run in ``out_dir`` are removed first
    (:func:`remove_run`, its recording included): the directory never holds
    files of two runs.
    """
    out = Path(out_dir)
    remove_run(out)
    meta = {"config_hash": config_hash}
    rows = [reference_row(refs.energy, refs.fuel), reference_row(refs.fuel, refs.fuel)]
    rows += [summary_row(r, refs.fuel) for r in results]
    write_parquet(summary_table(rows, meta), out / RUN_SUMMARY)
    write_parquet(pa.concat_tables([steps_table(r, meta) for r in results]), out / RUN_STEPS)
    write_parquet(pa.concat_tables([solves_table(r, meta) for r in results]), out / RUN_SOLVES)
    write_parquet(references_table(refs, meta), out / RUN_REFERENCES)
    write_json(
        {"cwrend_version": __version__, "config_hash": config_hash, "config": resolved_config},
        out / RUN_CONFIG,
    )
    return out
