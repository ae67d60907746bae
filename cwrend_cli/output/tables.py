"""Parquet and JSON output of runs (I/O at the edge; nothing here computes physics).

Tables carry their units in the column names (``t_s``, ``miss_km``,
``u_norm_km_s2``) and explicit Arrow schemas so that typed columns never
drift between files. Every file is written to a temporary name in the same
directory and moved into place with :func:`os.replace`, so a reader (or a
``kill -9``) never sees a half-written file.
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from cwrend_cli import __version__
from cwrend_cli.physics.metrics import reference_metrics, run_metrics
from cwrend_cli.physics.references import OpenLoopResult
from cwrend_cli.physics.simulation import References, RunResult

_AXES = ("x", "y", "z")
_VEL = ("vx", "vy", "vz")


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; move it onto ``path`` on success.

    The one way cwrend writes a file: readers (and a resumed campaign) see
    either nothing or the complete file, never a partial one.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp_path, 0o644)  # mkstemp creates 0600; results are ordinary files
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_parquet(table: pa.Table, path: str | Path) -> Path:
    """Write ``table`` to ``path`` atomically (temp file + rename)."""
    path = Path(path)
    # Dictionary encoding pays off for the repeated strings only; on float columns it
    # costs half the write time and makes the file larger.
    strings = [f.name for f in table.schema if pa.types.is_string(f.type)]
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd", use_dictionary=strings)
    return path


def write_json(data: Any, path: str | Path) -> Path:
    """Write ``data`` as indented JSON to ``path`` atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    return path


def _metadata(extra: Mapping[str, Any]) -> dict[bytes, bytes]:
    meta = {"cwrend_version": __version__, "units": "km, s, km/s, km/s^2", **extra}
    return {k.encode(): str(v).encode() for k, v in meta.items()}


STEPS_SCHEMA = pa.schema(
    [
        ("arch", pa.string()),
        ("seed", pa.int64()),
        ("step", pa.int64()),
        ("t_s", pa.float64()),
        *[(f"{a}_km", pa.float64()) for a in _AXES],
        *[(f"{a}_km_s", pa.float64()) for a in _VEL],
        *[(f"{a}_hat_km", pa.float64()) for a in _AXES],
        *[(f"{a}_hat_km_s", pa.float64()) for a in _VEL],
        *[(f"u{a}_km_s2", pa.float64()) for a in _AXES],
        ("u_norm_km_s2", pa.float64()),
        *[(f"meas_{a}_km", pa.float64()) for a in _AXES],
        ("nis", pa.float64()),
        ("mtf_ratio", pa.float64()),
        ("score", pa.float64()),
        ("score_filtered", pa.float64()),
        ("eps", pa.float64()),
        ("pos_err_km", pa.float64()),
        ("est_err_km", pa.float64()),
        ("est_vel_err_km_s", pa.float64()),
        ("trace_p", pa.float64()),
        ("window", pa.int64()),
    ]
)


def steps_table(result: RunResult, metadata: Mapping[str, Any] | None = None) -> pa.Table:
    """One row per grid time of a closed-loop run (row semantics: :class:`RunResult`)."""
    rows = result.t_s.size
    cols: dict[str, Any] = {
        "arch": [result.arch] * rows,
        "seed": np.full(rows, result.seed, dtype=np.int64),
        "step": np.arange(rows, dtype=np.int64),
        "t_s": result.t_s,
    }
    for i, a in enumerate(_AXES):
        cols[f"{a}_km"] = result.x_true[:, i]
    for i, a in enumerate(_VEL):
        cols[f"{a}_km_s"] = result.x_true[:, 3 + i]
    for i, a in enumerate(_AXES):
        cols[f"{a}_hat_km"] = result.x_hat[:, i]
    for i, a in enumerate(_VEL):
        cols[f"{a}_hat_km_s"] = result.x_hat[:, 3 + i]
    for i, a in enumerate(_AXES):
        cols[f"u{a}_km_s2"] = result.u[:, i]
    cols["u_norm_km_s2"] = np.linalg.norm(result.u, axis=1)
    for i, a in enumerate(_AXES):
        cols[f"meas_{a}_km"] = result.y[:, i]
    cols["nis"] = result.nis
    cols["mtf_ratio"] = result.mtf_ratio
    cols["score"] = result.score
    cols["score_filtered"] = result.score_filtered
    cols["eps"] = result.eps
    cols["pos_err_km"] = np.linalg.norm(result.x_true[:, :3], axis=1)
    cols["est_err_km"] = np.linalg.norm(result.x_hat[:, :3] - result.x_true[:, :3], axis=1)
    cols["est_vel_err_km_s"] = np.linalg.norm(result.x_hat[:, 3:] - result.x_true[:, 3:], axis=1)
    cols["trace_p"] = result.trace_p
    cols["window"] = result.window.astype(np.int64)
    schema = STEPS_SCHEMA.with_metadata(_metadata(metadata or {}))
    return pa.table(cols, schema=schema)


SOLVES_SCHEMA = pa.schema(
    [
        ("arch", pa.string()),
        ("seed", pa.int64()),
        ("kind", pa.string()),
        ("step", pa.int64()),
        ("t_s", pa.float64()),
        ("horizon_s", pa.float64()),
        ("eps", pa.float64()),
        ("status", pa.string()),
        ("fallback_step", pa.string()),
        ("iterations", pa.int64()),
        ("residual_km", pa.float64()),
        ("wall_time_ms", pa.float64()),
        ("success", pa.bool_()),
    ]
)


def solves_table(result: RunResult, metadata: Mapping[str, Any] | None = None) -> pa.Table:
    """One row per solve (the initial one of adaptive runs, then every re-solve)."""
    recs = result.solves
    cols = {
        "arch": [result.arch] * len(recs),
        "seed": [result.seed] * len(recs),
        "kind": [s.kind for s in recs],
        "step": [s.step for s in recs],
        "t_s": [s.t_s for s in recs],
        "horizon_s": [s.horizon_s for s in recs],
        "eps": [s.eps for s in recs],
        "status": [s.status for s in recs],
        "fallback_step": [s.fallback_step for s in recs],
        "iterations": [s.iterations for s in recs],
        "residual_km": [s.residual_km for s in recs],
        "wall_time_ms": [s.wall_time_ms for s in recs],
        "success": [s.success for s in recs],
    }
    schema = SOLVES_SCHEMA.with_metadata(_metadata(metadata or {}))
    return pa.table(cols, schema=schema)


SUMMARY_SCHEMA = pa.schema(
    [
        ("arch", pa.string()),
        ("seed", pa.int64()),
        ("delta_v_km_s", pa.float64()),
        ("miss_km", pa.float64()),
        ("fuel_penalty_pct", pa.float64()),
        ("n_solves", pa.int64()),
        ("n_converged", pa.int64()),
        ("n_infeasible", pa.int64()),
        ("n_failed", pa.int64()),
        ("solve_success_pct", pa.float64()),
        ("solve_mean_ms", pa.float64()),
        ("solve_max_ms", pa.float64()),
    ]
)


def summary_row(result: RunResult, fuel_delta_v_km_s: float) -> dict[str, Any]:
    """A ``summary.parquet`` / ``runs.parquet`` row of one run (metrics: SPEC §7 convention)."""
    metrics = run_metrics(result, fuel_delta_v_km_s)
    return {"arch": result.arch, "seed": result.seed, **dataclasses.asdict(metrics)}


def reference_row(ref: OpenLoopResult, fuel_delta_v_km_s: float) -> dict[str, Any]:
    """Summary row of an open-loop reference (``arch`` = ``open_loop_<name>``)."""
    metrics = reference_metrics(ref, fuel_delta_v_km_s)
    return {"arch": f"open_loop_{ref.name}", "seed": -1, **dataclasses.asdict(metrics)}


def summary_table(
    rows: Sequence[Mapping[str, Any]], metadata: Mapping[str, Any] | None = None
) -> pa.Table:
    """Table of summary rows (see :func:`summary_row`)."""
    schema = SUMMARY_SCHEMA.with_metadata(_metadata(metadata or {}))
    return pa.Table.from_pylist([dict(r) for r in rows], schema=schema)


REFERENCE_SCHEMA = pa.schema(
    [
        ("reference", pa.string()),
        ("t_s", pa.float64()),
        *[(f"{a}_km", pa.float64()) for a in _AXES],
        *[(f"{a}_km_s", pa.float64()) for a in _VEL],
        *[(f"u{a}_km_s2", pa.float64()) for a in _AXES],
        ("u_norm_km_s2", pa.float64()),
    ]
)


def references_table(refs: References, metadata: Mapping[str, Any] | None = None) -> pa.Table:
    """Open-loop reference trajectories sampled on the grid, one row per (reference, time)."""
    parts = []
    for ref in (refs.energy, refs.fuel):
        cols: dict[str, Any] = {"reference": [ref.name] * ref.t_s.size, "t_s": ref.t_s}
        for i, a in enumerate(_AXES):
            cols[f"{a}_km"] = ref.x[:, i]
        for i, a in enumerate(_VEL):
            cols[f"{a}_km_s"] = ref.x[:, 3 + i]
        for i, a in enumerate(_AXES):
            cols[f"u{a}_km_s2"] = ref.u[:, i]
        cols["u_norm_km_s2"] = np.linalg.norm(ref.u, axis=1)
        parts.append(pa.table(cols, schema=REFERENCE_SCHEMA))
    return pa.concat_tables(parts).replace_schema_metadata(_metadata(metadata or {}))


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
    config is written last, so its presence marks a complete output.
    """
    out = Path(out_dir)
    meta = {"config_hash": config_hash}
    fuel_dv = refs.fuel.delta_v_km_s
    rows = [reference_row(refs.energy, fuel_dv), reference_row(refs.fuel, fuel_dv)]
    rows += [summary_row(r, fuel_dv) for r in results]
    write_parquet(summary_table(rows, meta), out / "summary.parquet")
    write_parquet(pa.concat_tables([steps_table(r, meta) for r in results]), out / "steps.parquet")
    write_parquet(
        pa.concat_tables([solves_table(r, meta) for r in results]), out / "solves.parquet"
    )
    write_parquet(references_table(refs, meta), out / "references.parquet")
    write_json(
        {"cwrend_version": __version__, "config_hash": config_hash, "config": resolved_config},
        out / "config.json",
    )
    return out


# ---------------------------------------------------------------------------
# Campaign layout: results/<name>/{manifest.json, runs.parquet, events.jsonl,
# steps/arch=<slug>/*.parquet, solves/arch=<slug>/*.parquet}
# ---------------------------------------------------------------------------

MANIFEST = "manifest.json"
RUNS = "runs.parquet"
EVENTS = "events.jsonl"
RECORDINGS = "recordings"
#: Directories of per-task files (journaled, removed on --force, orphans cleaned on resume).
DATASETS = ("steps", "solves", RECORDINGS)

CAMPAIGN_STEPS_SCHEMA = pa.schema(
    [f for f in STEPS_SCHEMA if f.name != "arch"]
    + [pa.field("run_key", pa.string()), pa.field("point", pa.string())]
)
CAMPAIGN_SOLVES_SCHEMA = pa.schema(
    [f for f in SOLVES_SCHEMA if f.name != "arch"]
    + [pa.field("run_key", pa.string()), pa.field("point", pa.string())]
)


def _with_run_columns(
    tables: Sequence[pa.Table], extra: Mapping[str, Sequence[str]], schema: pa.Schema
) -> pa.Table:
    """Concatenate per-run tables, drop ``arch`` (a partition key), add per-run columns."""
    parts = []
    for i, table in enumerate(tables):
        table = table.drop_columns(["arch"]).replace_schema_metadata(None)
        for name, values in extra.items():
            table = table.append_column(name, pa.array([values[i]] * table.num_rows, pa.string()))
        parts.append(table.cast(schema))
    return pa.concat_tables(parts)


def campaign_steps_table(results: Sequence[RunResult], extra: Mapping[str, Sequence[str]]):
    """Steps of several runs for the hive-partitioned ``steps/`` dataset."""
    return _with_run_columns([steps_table(r) for r in results], extra, CAMPAIGN_STEPS_SCHEMA)


def campaign_solves_table(results: Sequence[RunResult], extra: Mapping[str, Sequence[str]]):
    """Solves of several runs for the hive-partitioned ``solves/`` dataset."""
    return _with_run_columns([solves_table(r) for r in results], extra, CAMPAIGN_SOLVES_SCHEMA)


def append_events(path: str | Path, events: Sequence[Mapping[str, Any]]) -> None:
    """Append JSON lines in one write and fsync (a ``kill -9`` can only tear the last line)."""
    text = "".join(json.dumps(e, sort_keys=True, default=_json_default) + "\n" for e in events)
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def read_events(path: str | Path) -> list[dict[str, Any]]:
    """All complete events of a journal; a torn (unparsable) line is dropped."""
    path = Path(path)
    if not path.exists():
        return []
    events = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            events.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return events


@dataclass(frozen=True)
class JournalState:
    """What a campaign directory holds according to its journal."""

    runs: Mapping[str, Mapping[str, Any]]  # run_key -> its latest complete outcome event
    files: frozenset[str]  # data files written by completed task executions


def load_journal(path: str | Path) -> JournalState:
    """Runs and files of every task execution that completed (its ``task_done`` was written)."""
    events = read_events(path)
    done_tasks = {e["execution"]: e for e in events if e.get("event") == "task_done"}
    runs: dict[str, Mapping[str, Any]] = {}
    for e in events:
        if e.get("event") in ("run_finished", "run_failed") and e.get("execution") in done_tasks:
            runs[e["run_key"]] = e
    files = frozenset(f for e in done_tasks.values() for f in e.get("files", ()))
    return JournalState(runs, files)


def remove_orphan_files(root: str | Path, keep: frozenset[str]) -> list[str]:
    """Delete data files (and temp files) not written by a completed task execution."""
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
    return removed


_RUN_METRICS = [f for f in SUMMARY_SCHEMA if f.name not in ("arch", "seed")]
#: Prefix of the ``runs.parquet`` columns holding a run's swept values.
PARAM_PREFIX = "param."


def param_columns(columns: Iterable[str]) -> list[str]:
    """The swept-value columns (``param.<key>``) among ``columns``, in order."""
    return [c for c in columns if c.startswith(PARAM_PREFIX)]


def runs_table(records: Sequence[Mapping[str, Any]], metadata: Mapping[str, Any]) -> pa.Table:
    """``runs.parquet``: one row per run, sorted by run key, with applied parameters.

    Swept values are columns ``param.<key>``, dispersion draws ``disp.<key>``.
    """
    records = sorted(records, key=lambda r: r["run_key"])
    cols: dict[str, list[Any]] = {
        "run_key": [r["run_key"] for r in records],
        "point": [r["point"] for r in records],
        "arch": [r["arch"] for r in records],
        "seed": [r["seed"] for r in records],
        "status": [r["status"] for r in records],
        "error": [r.get("error", "") for r in records],
        "duration_s": [r.get("duration_s", float("nan")) for r in records],
    }
    fields = [
        pa.field("run_key", pa.string()),
        pa.field("point", pa.string()),
        pa.field("arch", pa.string()),
        pa.field("seed", pa.int64()),
        pa.field("status", pa.string()),
        pa.field("error", pa.string()),
        pa.field("duration_s", pa.float64()),
    ]
    for f in _RUN_METRICS:
        cols[f.name] = [r.get("metrics", {}).get(f.name) for r in records]
        fields.append(f)
    for prefix, key in ((PARAM_PREFIX, "params"), ("disp.", "dispersed")):
        names = sorted({k for r in records for k in r.get(key, {})})
        for name in names:
            values = [r.get(key, {}).get(name) for r in records]
            kinds = {type(v) for v in values if v is not None}
            if kinds <= {int, float} and not kinds <= {int}:
                arr = pa.array([None if v is None else float(v) for v in values], pa.float64())
            elif len(kinds) == 1:
                arr = pa.array(values)
            else:
                arr = pa.array([None if v is None else json.dumps(v) for v in values], pa.string())
            cols[prefix + name] = arr
            fields.append(pa.field(prefix + name, arr.type))
    schema = pa.schema(fields).with_metadata(_metadata(metadata))
    return pa.table(cols, schema=schema)
