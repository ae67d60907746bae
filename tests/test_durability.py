"""When a campaign's files reach the disk (issue 17: workers do not wait for it).

A worker writes its steps/solves files atomically but without waiting for
the disk; the journal flushes the files a ``task_done`` names before it
appends the event, so a task never counts on disk before its files do.
Every other file is flushed before it is moved into place.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from cwrend_cli import campaign
from cwrend_cli.campaign import journal
from cwrend_cli.config import CwrendConfig
from cwrend_cli.output import files
from cwrend_cli.physics import simulation


@pytest.fixture
def flushed(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The names of the files ``os.fsync`` is called on, in order."""
    names: list[str] = []
    real = os.fsync

    def recording(fd: int) -> None:
        names.append(Path(os.readlink(f"/proc/self/fd/{fd}")).name)
        real(fd)

    monkeypatch.setattr(os, "fsync", recording)
    return names


def test_a_file_is_on_disk_before_it_is_moved_into_place(
    tmp_path: Path, flushed: list[str]
) -> None:
    with files.atomic_path(tmp_path / "a.txt") as tmp:
        tmp.write_text("a")
    assert len(flushed) == 1 and flushed[0].startswith(".a.txt.")  # the temporary file
    assert (tmp_path / "a.txt").read_text() == "a"


def test_a_file_not_durable_is_moved_into_place_without_waiting(
    tmp_path: Path, flushed: list[str]
) -> None:
    with files.atomic_path(tmp_path / "a.txt", durable=False) as tmp:
        tmp.write_text("a")
    assert flushed == []
    assert (tmp_path / "a.txt").read_text() == "a"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]  # no temporary file left


def test_a_worker_writes_its_files_without_waiting_for_the_disk(
    tmp_path: Path, flushed: list[str]
) -> None:
    task = campaign.plan(CwrendConfig(), ["mtf_adaptive"], [0]).tasks[0]
    refs = simulation.open_loop_references(task.problem)
    outcome = campaign.execute_task(task, refs, str(tmp_path), metadata={"config_hash": "c"})
    assert sorted(f.split("/")[0] for f in outcome.files) == ["solves", "steps"]
    assert all((tmp_path / f).is_file() for f in outcome.files)
    assert flushed == []


def test_a_task_is_journaled_only_after_its_files_are_on_disk(
    tmp_path: Path, flushed: list[str]
) -> None:
    names = ["steps/arch=a/t-1.parquet", "solves/arch=a/t-1.parquet"]
    for name in names:
        (tmp_path / name).parent.mkdir(parents=True)
        (tmp_path / name).write_bytes(b"data")
    done = {"event": "task_done", "execution": "t-1", "files": names}
    journal.append_events(tmp_path / "events.jsonl", [{"event": "run_finished"}, done])
    assert flushed == ["t-1.parquet", "t-1.parquet", "events.jsonl"]
    assert journal.read_events(tmp_path / "events.jsonl")[-1] == done
