"""The journal is read line by line and keeps what its callers need (issue 17).

:func:`journal.load_journal` streams ``events.jsonl``: per run key the
latest outcome event of an execution whose ``task_done`` was written, and
the files of the executions done; nothing else is held. Each test checks one
behaviour against the journal's contract (and :func:`_reference`, the
whole-file reading it replaced, which must agree).
"""

from __future__ import annotations

import json
import tracemalloc
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from cwrend_cli.campaign import journal


def _outcome(run_key: str, execution: str, status: str = "ok", **extra: Any) -> dict[str, Any]:
    return {
        "event": "run_finished" if status == "ok" else "run_failed",
        "run_key": run_key,
        "execution": execution,
        "status": status,
        "point": "base",
        "arch": "a",
        "seed": 0,
        "metrics": {"miss_km": 0.1},
        "params": {},
        "dispersed": {},
        "error": "" if status == "ok" else "boom",
        **extra,
    }


def _kept(event: Mapping[str, Any]) -> dict[str, Any]:
    return {k: event[k] for k in journal.RUN_FIELDS if k in event}


def _started(run_key: str, execution: str) -> dict[str, Any]:
    return {"event": "run_started", "run_key": run_key, "execution": execution}


def _done(execution: str, *files: str) -> dict[str, Any]:
    return {"event": "task_done", "execution": execution, "files": list(files)}


def _write(path: Path, events: Sequence[Mapping[str, Any]]) -> Path:
    path.write_text("".join(json.dumps(e, sort_keys=True) + "\n" for e in events))
    return path


def _reference(path: Path) -> journal.JournalState:
    """The state as the journal was read before it streamed (the whole file at once; of each
    outcome event the fields kept)."""
    events = journal.read_events(path)
    done_tasks = {e["execution"]: e for e in events if e.get("event") == "task_done"}
    runs: dict[str, Mapping[str, Any]] = {}
    for e in events:
        if e.get("event") in ("run_finished", "run_failed") and e.get("execution") in done_tasks:
            runs[e["run_key"]] = {k: e[k] for k in journal.RUN_FIELDS if k in e}
    files = frozenset(f for e in done_tasks.values() for f in e.get("files", ()))
    return journal.JournalState(runs, files)


def _state(path: Path) -> journal.JournalState:
    state = journal.load_journal(path)
    reference = _reference(path)
    assert list(state.runs.items()) == list(reference.runs.items())  # same order too
    assert state.files == reference.files
    return state


def test_runs_of_an_execution_count_once_its_task_done_follows(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "events.jsonl",
        [_started("k1", "x"), _outcome("k1", "x"), _started("k2", "x"), _outcome("k2", "x"),
         _done("x", "solves/a/x.parquet")],
    )  # fmt: skip
    state = _state(path)
    assert list(state.runs) == ["k1", "k2"]
    assert state.files == {"solves/a/x.parquet"}


def test_an_execution_without_task_done_counts_for_nothing(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "events.jsonl",
        [_outcome("k1", "x"), _done("x", "f/x"), _outcome("k2", "y"), _outcome("k1", "y")],
    )
    state = _state(path)
    assert dict(state.runs) == {"k1": _kept(_outcome("k1", "x"))}
    assert state.files == {"f/x"}


def test_interleaved_executions_keep_the_latest_outcome_by_position(tmp_path: Path) -> None:
    # y's outcome of k is later in the journal than x's, though x's task_done comes last
    path = _write(
        tmp_path / "events.jsonl",
        [_outcome("k", "x", duration_s=1.0), _outcome("k", "y", duration_s=2.0), _done("y"),
         _done("x")],
    )  # fmt: skip
    assert _state(path).runs["k"]["execution"] == "y"


def test_a_failed_then_retried_task_keeps_the_retry(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "events.jsonl",
        [_outcome("k1", "x", "failed"), _outcome("k2", "x"), _done("x"),
         _outcome("k1", "x2"), _done("x2", "f/x2")],
    )  # fmt: skip
    state = _state(path)
    assert {k: e["status"] for k, e in state.runs.items()} == {"k1": "ok", "k2": "ok"}
    assert state.runs["k1"]["execution"] == "x2"


def test_a_torn_execution_rerun_under_the_same_name_counts_its_complete_run(
    tmp_path: Path,
) -> None:
    # an execution is named by its task and runs: rerun after a tear, it has the same name
    path = _write(
        tmp_path / "events.jsonl",
        [_outcome("k", "x", duration_s=1.0), _outcome("k", "x", duration_s=2.0), _done("x")],
    )
    assert _state(path).runs["k"]["duration_s"] == 2.0


def test_the_files_of_an_execution_are_those_of_its_last_task_done(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "events.jsonl",
        [_outcome("k", "x"), _done("x", "f/1", "f/2"), _outcome("k", "x"), _done("x", "f/1")],
    )
    assert _state(path).files == {"f/1"}


def test_torn_and_unparsable_lines_are_dropped(tmp_path: Path) -> None:
    path = _write(tmp_path / "events.jsonl", [_outcome("k1", "x")])
    with open(path, "ab") as fh:
        fh.write(b'{"event": "run_finished", "run_key": "k2", "exec\n')  # torn, then ended
        fh.write(b"\xff\xfe not utf-8\n[1, 2]\n")  # not UTF-8; JSON but not an event
        fh.write((json.dumps(_done("x")) + "\n").encode())
    assert list(_state(path).runs) == ["k1"]


def test_a_torn_last_line_is_tolerated(tmp_path: Path) -> None:
    path = _write(tmp_path / "events.jsonl", [_outcome("k1", "x"), _done("x")])
    with open(path, "ab") as fh:
        fh.write(json.dumps(_outcome("k2", "y")).encode() + b"\n" + b'{"event": "task_do')
    state = _state(path)
    assert list(state.runs) == ["k1"]
    assert journal.read_events(path)[-1] == _outcome("k2", "y")


def test_of_an_outcome_the_state_keeps_what_runs_parquet_and_the_driver_read(
    tmp_path: Path,
) -> None:
    event = _outcome("k", "x", time="2026-12-01T00:00:00.000+00:00", campaign_hash="h" * 64,
                     cwrend_version="0.1.0", duration_s=0.5)  # fmt: skip
    path = _write(tmp_path / "events.jsonl", [event, _done("x")])
    kept = _state(path).runs["k"]
    assert set(kept) == set(journal.RUN_FIELDS)
    assert kept == {k: event[k] for k in journal.RUN_FIELDS}


def test_a_missing_journal_is_empty(tmp_path: Path) -> None:
    assert list(journal.iter_events(tmp_path / "events.jsonl")) == []
    state = journal.load_journal(tmp_path / "events.jsonl")
    assert (dict(state.runs), state.files) == ({}, frozenset())


def test_iter_events_reads_the_events_read_events_returns(tmp_path: Path) -> None:
    path = _write(tmp_path / "events.jsonl", [_started("k", "x"), _outcome("k", "x"), _done("x")])
    assert list(journal.iter_events(path)) == journal.read_events(path)
    assert len(journal.read_events(path)) == 3


def test_loading_a_journal_holds_the_runs_not_the_file(tmp_path: Path) -> None:
    # 2,000 runs in tasks of 16, each run with a large run_started event: the file is ~8 MB,
    # and what is held beyond the runs kept must stay small while it is read
    events: list[dict[str, Any]] = []
    for task in range(125):
        x = f"t{task}"
        for i in range(16):
            key = f"k{task * 16 + i:05d}"
            events += [{**_started(key, x), "padding": "p" * 4000}, _outcome(key, x)]
        events.append(_done(x, f"f/{x}"))
    path = _write(tmp_path / "events.jsonl", events)
    assert path.stat().st_size > 8_000_000
    tracemalloc.start()
    try:
        state = journal.load_journal(path)
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(state.runs) == 2000
    assert peak - kept < 1_000_000  # measured ~0.2 MB; reading the whole file: > 8 MB


def test_the_names_and_repeated_texts_of_the_runs_kept_are_held_once(tmp_path: Path) -> None:
    runs = [_outcome(k, "x", params={"estimator": "mtf"}) for k in ("k1", "k2")]
    path = _write(tmp_path / "events.jsonl", [*runs, _done("x")])
    one, two = _state(path).runs.values()
    ((name_one, _),), ((name_two, _),) = one["metrics"].items(), two["metrics"].items()
    assert name_one is name_two
    assert one["params"]["estimator"] is two["params"]["estimator"]
    assert one["execution"] is two["execution"] and one["point"] is two["point"]


def test_a_rerun_torn_before_its_task_done_counts_for_nothing(tmp_path: Path) -> None:
    """A task rerun under its earlier name (``--retry-failed`` of a task whose runs all
    failed) and killed before its ``task_done``: its runs keep their earlier outcome.

    Before, any outcome of an execution name that had completed once counted, so the torn
    rerun's runs counted as ok while its files, named by no ``task_done``, were removed as
    orphans on resume.
    """
    path = _write(
        tmp_path / "events.jsonl",
        [_outcome("k", "x", status="failed"), _done("x", "f/1"), _outcome("k", "x")],
    )
    state = journal.load_journal(path)
    assert state.runs["k"]["status"] == "failed"
    assert state.files == {"f/1"}
