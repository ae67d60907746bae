"""Arrow schemas and table builders of everything cwrend writes (nothing here writes a file).

Tables carry their units in the column names (``t_s``, ``miss_km``,
``u_norm_km_s2``) and explicit Arrow schemas so that typed columns never
drift between files: the per-run ``steps``/``solves``/``summary`` tables and
the open-loop ``references`` of ``cwrend run``, their campaign variants (the
hive-partitioned ``steps/`` and ``solves/`` datasets) and ``runs.parquet``.
Files are written by :mod:`cwrend_cli.output.files`; the campaign directory
and its journal are :mod:`cwrend_cli.campaign.journal`.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from cwrend_cli import __version__
from cwrend_cli.physics.metrics import reference_metrics, run_metrics
from cwrend_cli.physics.references import OpenLoopResult
from cwrend_cli.physics.simulation import References, RunResult

_AXES = ("x", "y", "z")
_VEL = ("vx", "vy", "vz")


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
        ("degradation_window", pa.int64()),
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
    # the control the actuator applied (RunResult.u; the command is RunResult.u_cmd)
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
    cols["degradation_window"] = result.window.astype(np.int64)
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


# ---------------------------------------------------------------------------
# Campaign datasets: steps/arch=<slug>/*.parquet, solves/arch=<slug>/*.parquet
# ---------------------------------------------------------------------------

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


def campaign_steps_table(
    results: Sequence[RunResult], extra: Mapping[str, Sequence[str]]
) -> pa.Table:
    """Steps of several runs for the hive-partitioned ``steps/`` dataset."""
    return _with_run_columns([steps_table(r) for r in results], extra, CAMPAIGN_STEPS_SCHEMA)


def campaign_solves_table(
    results: Sequence[RunResult], extra: Mapping[str, Sequence[str]]
) -> pa.Table:
    """Solves of several runs for the hive-partitioned ``solves/`` dataset."""
    return _with_run_columns([solves_table(r) for r in results], extra, CAMPAIGN_SOLVES_SCHEMA)


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
