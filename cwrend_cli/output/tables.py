"""Arrow schemas and table builders of everything cwrend writes (nothing here writes a file).

Tables carry their units in the column names (``t_s``, ``miss_km``,
``u_norm_km_s2``) and explicit Arrow schemas so that typed columns never
drift between files: the per-run ``steps``/``solves``/``summary`` tables and
the open-loop ``references`` of ``cwrend run``, their campaign variants (the
hive-partitioned ``steps/`` and ``solves/`` datasets) and ``runs.parquet``.
Files are written by :mod:`cwrend_cli.output.files`; the campaign directory
and its journal are :mod:`cwrend_cli.campaign.journal`.

Data conventions (issue 18, item 5): every Parquet file carries, in its Arrow
schema metadata, ``cwrend_version`` and ``config_hash``
(:func:`cwrend_cli.config.config_hash` of the resolved config; a campaign's
files carry its base config's hash, as ``manifest.json``), and every column
a field-level ``unit`` (``b"km"``, ``b"km/s"``, ``b"-"`` for dimensionless …)
and ``description`` (:func:`with_conventions`, checked by
:func:`check_conventions` before any file is written). Units come from one
table: :data:`COLUMNS` names every fixed column, with its unit derived from
the name's suffix where it has one (:data:`SUFFIX_UNITS`) and explicit
otherwise; swept and dispersed values (``param.<key>``, ``disp.<key>``) take
the unit of their configuration key (:func:`unit_of`).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import operator
from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

if TYPE_CHECKING:  # frames are only passed in: a campaign worker never loads pandas
    import pandas as pd

from cwrend_cli import __version__
from cwrend_cli.output.layout import PARAM_PREFIX, UNIT_PREFIX
from cwrend_cli.physics.metrics import reference_metrics, run_metrics
from cwrend_cli.physics.references import OpenLoopResult
from cwrend_cli.physics.simulation import References, RunResult

_AXES = ("x", "y", "z")
_VEL = ("vx", "vy", "vz")


def _metadata(extra: Mapping[str, Any]) -> dict[bytes, bytes]:
    units = "per column: field metadata 'unit' (km, s, km/s, km/s^2; - dimensionless)"
    meta = {"cwrend_version": __version__, "units": units, **extra}
    return {k.encode(): str(v).encode() for k, v in meta.items()}


# ---------------------------------------------------------------------------
# Units and descriptions of every column (issue 18, item 5)
# ---------------------------------------------------------------------------

#: Short names of the run metrics, as ``--metric`` takes them (``cwrend compare`` and
#: ``cwrend table``; one table for both), → their ``runs.parquet`` / statistics column:
#: the paper's trapezoid Δv and its fuel penalty (``dv``, ``fuel``), the applied impulse
#: and its penalty against the exact continuous fuel optimum (``dv_applied``,
#: ``fuel_applied``, issue 33 item 3), the filter-consistency means (``nees``, ``nis``:
#: ``cwrend table`` only, as a consistent filter's is a value, not "lower is better").
METRIC_NAMES: Mapping[str, str] = {
    "miss": "miss_km",
    "dv": "delta_v_km_s",
    "fuel": "fuel_penalty_pct",
    "dv_applied": "delta_v_applied_km_s",
    "fuel_applied": "fuel_penalty_applied_pct",
    "nees": "mean_nees",
    "nis": "mean_nis_nominal",
    # safety of the true trajectory (issue 32; tumbling target and abort safety, issue 34)
    "min_distance": "safety_min_distance_km",
    "unsafe_time": "safety_unsafe_time_s",
    "dock_position": "safety_dock_position_error_km",
    "dock_velocity": "safety_dock_velocity_error_km_s",
    "abort_distance": "abort_min_distance_km",
}


def metric_name(column: str) -> str:
    """The short name of a metric column (``delta_v_applied_km_s`` → ``dv_applied``), else it."""
    return next((k for k, v in METRIC_NAMES.items() if v == column), column)


#: Unit of a column (or configuration key) from its name's suffix, longest first.
SUFFIX_UNITS: tuple[tuple[str, str], ...] = (
    ("_km_s2", "km/s^2"),
    ("_km_s", "km/s"),
    ("_rad_s", "rad/s"),
    ("_deg_s", "deg/s"),
    ("_km2", "km^2"),
    ("_km", "km"),
    ("_deg", "deg"),
    ("_pct", "%"),
    ("_ms", "ms"),
    ("_s", "s"),
)
#: Unit of the long-format statistics' ``value``, ``ci_low`` and ``ci_high``: that of the
#: row's ``metric`` (read from its suffix, e.g. ``miss_km`` → km; none: dimensionless).
PER_METRIC = "unit of metric"


def suffix_unit(name: str) -> str | None:
    """The unit a name's suffix gives (``miss_km`` → ``km``), ``None`` without one."""
    for suffix, unit in SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    return None


#: The values of the solves' ``fallback_step``: the step of the shooting chain that ended a
#: re-solve (:mod:`cwrend_cli.physics.guidance.shooting`, in the chain's order), the plan of
#: last resort, or the cone-program method's own re-solve.
FALLBACK_STEPS = (
    "warm",
    "socp_plan",
    "continuation_warm",
    "continuation_energy",
    "socp_multiplier",
    "dual_bound",
    "socp",
)


def _col(description: str, unit: str | None = None) -> tuple[str, str]:
    return (unit if unit is not None else "", description)


_A = {"x": "radial", "y": "along-track", "z": "cross-track"}
#: Every fixed column cwrend writes: ``name → (unit, description)``; an empty unit is
#: read from the name's suffix (:func:`unit_of`), the others are explicit.
COLUMNS: Mapping[str, tuple[str, str]] = {
    "arch": _col("architecture (estimator_schedule) or open_loop_<reference>", "-"),
    "seed": _col("seed index k of the noise stream (SeedSequence spawn key (k, …))", "-"),
    "step": _col("step index k; row k is time t_k", "-"),
    "t_s": _col("time t_k from the start"),
    **{f"{a}_km": _col(f"true relative position, {d} (CW frame)") for a, d in _A.items()},
    **{f"v{a}_km_s": _col(f"true relative velocity, {d}") for a, d in _A.items()},
    **{f"{a}_hat_km": _col(f"estimated position, {d} (filter posterior)") for a, d in _A.items()},
    **{f"v{a}_hat_km_s": _col(f"estimated velocity, {d}") for a, d in _A.items()},
    **{
        f"u{a}_km_s2": _col(f"control applied over [t_k, t_k+1) (after actuator errors), {d}")
        for a, d in _A.items()
    },
    "u_norm_km_s2": _col("norm of the applied control"),
    **{
        f"ucmd_{a}_km_s2": _col(f"control commanded at t_k (what the filter uses), {d}")
        for a, d in _A.items()
    },
    **{
        f"meas_{a}_km": _col(f"position measurement of row k (taken at t_k), {d}; NaN: none")
        for a, d in _A.items()
    },
    "meas_range_km": _col(
        "range of the target measured at t_k (sensor.model = 'range_bearing'); NaN: none"
    ),
    "meas_azimuth_deg": _col(
        "azimuth of the target measured at t_k, in (-180, 180] (sensor.model "
        "'range_bearing' or 'angles'); NaN: none"
    ),
    "meas_elevation_deg": _col(
        "elevation of the target measured at t_k, in [-90, 90] (sensor.model "
        "'range_bearing' or 'angles'); NaN: none"
    ),
    "nis": _col(
        "normalised innovation squared of the row's measurement (chi2_m, m = 3, or 2 for "
        "sensor.model = 'angles')",
        "-",
    ),
    "mtf_ratio": _col(
        "inflation ratio ρ: MTF tr(S_MTF)/tr(S), stf (λ − 1) tr(R)/tr(S); 0 for the plain KF", "-"
    ),
    "score": _col("composite innovation score s", "-"),
    "score_filtered": _col("low-pass filtered score s-bar", "-"),
    "eps": _col("homotopy parameter epsilon after the row's update", "-"),
    "pos_err_km": _col("distance to the target ||r||"),
    "est_err_km": _col("position estimation error ||r-hat - r||"),
    "est_vel_err_km_s": _col("velocity estimation error ||v-hat - v||"),
    "trace_p": _col("trace of the estimate covariance P (sums km^2 and km^2/s^2)", "mixed"),
    "trace_q": _col(
        "trace of the process noise Q_k of the prediction into the row (sums km^2 and "
        "km^2/s^2; estimator.process_noise); NaN in row 0",
        "mixed",
    ),
    "nees": _col(
        "normalised estimation error squared (x-hat - x)' P^-1 (x-hat - x) (chi2_6); "
        "row 0: initial error against P0; posterior, prior on a dropout row",
        "-",
    ),
    "degradation_window": _col(
        "index of the degradation window active at t_(k-1), whose noise the row's "
        "measurement carries; -1 none",
        "-",
    ),
    "dropout": _col("sensor dropout: the row has no measurement", "-"),
    "outlier": _col("the row's measurement noise is an outlier (scaled)", "-"),
    "run_key": _col("run identifier <point>.<arch>.s<seed>", "-"),
    "point": _col("grid point identifier", "-"),
    # solves
    "kind": _col("initial or resolve (solves); marginal or paired (statistics)", "-"),
    "horizon_s": _col("horizon of the solve"),
    "status": _col("solve outcome (solves) or run outcome ok/failed (runs)", "-"),
    "fallback_step": _col(
        "solver step that produced the result: warm (the warm Newton attempt), a step of the "
        "fallback chain, socp_plan (its cone-program plan of last resort), or socp (the "
        "cone-program method)",
        "-",
    ),
    "iterations": _col(
        "iterations of the solver that answered, summed over the steps of the fallback "
        "chain: Newton iterations of the shooting ascent; for a cone program, of its dual "
        "ascent where the quadratic weight max(eps, 1e-6) is at least 1e-3, else Clarabel's "
        "interior-point iterations; for a constrained cone program (scp_iterations > 0), "
        "the iterations of every convex program of the re-solve summed: the dual Newton "
        "method's, certified or not, and Clarabel's on the programs it was left "
        "(fallback_programs)",
        "-",
    ),
    "residual_km": _col("terminal residual norm of the solve"),
    "wall_time_ms": _col("wall time of the solve"),
    "success": _col("converged with residual below solver.success_residual", "-"),
    # summary / runs
    "delta_v_km_s": _col(
        "trapezoid of ||u|| (applied) over the grid, the paper's convention: it drops "
        "||u_0|| dt/2 of a closed-loop run"
    ),
    "delta_v_applied_km_s": _col(
        "applied impulse sum_k ||u_k|| dt over the zero-order-hold steps k = 0..N-1 (what the "
        "thruster did); open-loop references: integral of ||u|| dt of the continuous plan"
    ),
    "miss_km": _col("terminal miss ||r(T) - r_f||"),
    "fuel_penalty_pct": _col(
        "delta-v above the open-loop fuel optimum's, both trapezoids (the paper's; can be < 0)"
    ),
    "fuel_penalty_applied_pct": _col(
        "applied delta-v above the exact continuous fuel optimum (u_max x its burn time); "
        ">= 0 for a run that reaches the target"
    ),
    "n_solves": _col("receding-horizon re-solves", "-"),
    "n_converged": _col("re-solves that converged", "-"),
    "n_infeasible": _col("re-solves found infeasible", "-"),
    "n_failed": _col("re-solves that failed", "-"),
    "solve_success_pct": _col("share of successful re-solves"),
    "solve_mean_ms": _col("mean wall time per re-solve"),
    "solve_max_ms": _col("longest re-solve"),
    "mean_nis_nominal": _col(
        "mean NIS over rows with a measurement outside every degradation window "
        "(3 for a consistent filter)",
        "-",
    ),
    "mean_nees": _col("mean NEES over rows 1..N (6 for a consistent filter)", "-"),
    "error": _col("error text and traceback of a failed run", "-"),
    # safety of the true trajectory (issue 32; only with [constraints])
    "safety_min_distance_km": _col(
        "minimum signed distance of the true trajectory to the unsafe set (keep-out zone "
        "minus corridor), its arcs sampled every dt/20; < 0: it entered the set"
    ),
    "safety_unsafe_time_s": _col("time the true trajectory spent in the unsafe set, to dt/20"),
    "safety_corridor_violation_deg": _col(
        "largest angle beyond the corridor half-angle of the true positions inside the "
        "keep-out zone (0: never outside the corridor there; NaN: no zone or no corridor)"
    ),
    "safety_approach_speed_km_s": _col("speed of the true relative state at T ||v(T)||"),
    "safety_approach_angle_deg": _col(
        "angle between the true velocity at T and the inward corridor axis -a (0: straight "
        "down the corridor; NaN: no corridor or at rest; near rest the velocity is the "
        "estimation error's, not the path's direction)"
    ),
    "safety_violated": _col("the true trajectory entered the unsafe set (min distance < 0)", "-"),
    # a tumbling target (issue 34): the docking state error against the moving port
    "safety_dock_position_error_km": _col(
        "distance of the true position at T to the tumbling target's port ||r(T) - R(T) p|| "
        "(NaN without a corridor)"
    ),
    "safety_dock_velocity_error_km_s": _col(
        "difference of the true velocity at T and the tumbling target's port velocity "
        "||v(T) - Omega(T) x R(T) p|| (NaN without a corridor)"
    ),
    "scp_iterations": _col(
        "convex programs the constrained cone program solved (sequential convex "
        "programming); 0: not a constrained solve",
        "-",
    ),
    "fallback_programs": _col(
        "convex programs of the constrained cone program that the dual Newton method could "
        "not certify and Clarabel solved (0: every program solved by the dual method)",
        "-",
    ),
    "slack_km": _col(
        "path-constraint softening the constrained cone program needed (0: every keep-out "
        "and corridor row held)"
    ),
    # abort safety of the true trajectory (issue 34 item 4; only with constraints.abort_safe_s)
    "abort_min_distance_km": _col(
        "worst signed distance to the keep-out zone of the free drifts (CW, no thrust, over "
        "constraints.abort_safe_s) from the true state of every step before the final "
        "approach in the corridor, re-sampled every 0.1 s where near; < 0: a drift enters"
    ),
    "abort_unsafe_steps": _col(
        "steps (before the final approach) whose free drift enters the keep-out zone", "-"
    ),
    "abort_unsafe": _col("some step's free drift enters the keep-out zone", "-"),
    "abort_slack_km": _col(
        "abort-safety softening the constrained cone program needed (0: every node's free "
        "drift kept out of the keep-out zone)"
    ),
    "safety_distance_km": _col(
        "signed distance of the true position at t_k to the unsafe set (< 0: inside)"
    ),
    # the tumbling target's attitude (issue 34; only with target.attitude = "tumbling")
    **{
        f"target_q{i}": _col(
            f"component {i} of the target's attitude quaternion, body to relative frame, "
            "scalar-first (q0 the scalar part)",
            "-",
        )
        for i in range(4)
    },
    **{
        f"target_w{a}_deg_s": _col(
            f"target body rate about its {a} axis: angular velocity relative to inertial "
            "space, in body axes"
        )
        for a in ("x", "y", "z")
    },
    "duration_s": _col("wall time of the run"),
    # references
    "reference": _col("open-loop reference: energy or fuel", "-"),
    # statistics (ablation.parquet, sweep.parquet, compare.parquet)
    "metric": _col("runs.parquet column the statistic is of", "-"),
    "statistic": _col("mean, median, p95, frac_less, median_diff, mean_diff, …", "-"),
    "value": _col("the statistic's value", PER_METRIC),
    "ci_low": _col("lower end of its 95 % interval (bootstrap; Wilson for shares)", PER_METRIC),
    "ci_high": _col("upper end of its 95 % interval", PER_METRIC),
    "n": _col("number of runs or seed pairs", "-"),
    "other": _col("the architecture A is compared with (A - B)", "-"),
    "point_a": _col("grid point of campaign A", "-"),
    "point_b": _col("grid point of campaign B", "-"),
    # sensitivity.parquet (statistic: S1 first-order, ST total, S2 second-order Sobol index)
    "parameter": _col("the swept configuration key of a Sobol index", "-"),
    "parameter_2": _col("the other key of a second-order index (S2), else empty", "-"),
    "method": _col("estimator: sobol (Saltelli design) or rbd_fast (any design), by SALib", "-"),
    "n_seeds": _col("fewest ok seeds of a design point (the index is of the mean over seeds)", "-"),
    # design.parquet (a sampled design's rows in SALib's order)
    "row": _col("row of the design matrix, in SALib's sample order", "-"),
}
#: Configuration keys without a unit suffix whose value is dimensionless.
#: (Keys with a unit suffix, e.g. ``guidance.t_resolve_s``, take it first.) Choices given
#: as text (``truth.model``, ``guidance.method``, …) and counts are dimensionless too.
_DIMENSIONLESS_KEYS = (
    "schedule.",
    "truth.",
    "guidance.",
    "noise.seed",
    "actuator.magnitude_",
    "solver.fallback",
    "solver.on_infeasible",
    "solver.max_iter",
    "solver.quadrature_nodes",
    "constraints.sigma_margin",
    "constraints.enforce",
    "constraints.corridor.axis",
    "target.",
)
#: Configuration keys without a unit suffix that are not dimensionless.
_KEY_UNITS = {"actuator.delay_steps": "steps", "estimator.r_nominal_km2": "km^2"}
#: Prefixes of the ``runs.parquet`` columns of swept values and dispersion draws.
_VALUE_PREFIXES = ("param.", "disp.")


def _key_unit(key: str) -> str:
    """Unit of a configuration key's value (``scenario.x0.2`` → km, ``schedule.beta`` → -)."""
    parts = key.split(".")
    index = int(parts[-1]) if parts[-1].isdigit() else None
    names = [p for p in parts if not p.isdigit()]
    field = ".".join(names)
    if names[-1] in ("x0", "xf", "initial_error") and index is not None:
        return "km" if index < 3 else "km/s"  # the state (x, y, z, vx, vy, vz)
    unit = suffix_unit(names[-1]) or _KEY_UNITS.get(field)
    if unit is not None:
        return unit
    if field.startswith(_DIMENSIONLESS_KEYS) or names[-1].endswith(("_probability", "_scale")):
        return "-"
    return f"as configuration key {field}"


def unit_of(name: str) -> str:
    """The unit of column ``name``; ``KeyError`` for a column the table does not know."""
    for prefix in _VALUE_PREFIXES:
        if name.startswith(prefix):
            return _key_unit(name.removeprefix(prefix))
    if name.startswith(UNIT_PREFIX):
        return "-"
    unit, _ = COLUMNS[name]
    if unit:
        return unit
    derived = suffix_unit(name)
    if derived is None:
        raise KeyError(f"column {name!r}: no unit (add it to output.tables.COLUMNS)")
    return derived


def description_of(name: str) -> str:
    """What column ``name`` holds (swept and dispersed values: their key)."""
    if name.startswith(PARAM_PREFIX):
        return f"swept value of {name.removeprefix(PARAM_PREFIX)}"
    if name.startswith("disp."):
        return f"dispersed value of {name.removeprefix('disp.')} applied to the run"
    if name.startswith(UNIT_PREFIX):
        return f"unit-cube coordinate of {name.removeprefix(UNIT_PREFIX)} (SALib's sample)"
    return COLUMNS[name][1]


def with_conventions(table: pa.Table, metadata: Mapping[str, Any]) -> pa.Table:
    """``table`` with every column's ``unit`` and ``description`` and the file metadata.

    ``metadata`` must hold ``config_hash``; ``cwrend_version`` is added. Raises
    ``KeyError`` for a column without a unit. The columns are not touched
    (no copy, no cast): only the schema changes, and the annotated schema of
    a (schema, metadata) pair is built once per process (:func:`_annotated`;
    a campaign worker writes two tables a task with the same one).
    """
    if "config_hash" not in metadata:
        raise KeyError("Parquet metadata needs the config_hash")
    plain = table.schema.remove_metadata()  # what the cache tells apart: names and types
    existing = tuple(sorted((table.schema.metadata or {}).items()))
    extra = tuple(sorted((str(k), str(v)) for k, v in metadata.items()))
    return pa.Table.from_arrays(table.columns, schema=_annotated(plain, existing, extra))


@functools.lru_cache(maxsize=64)
def _annotated(
    schema: pa.Schema,
    existing: tuple[tuple[bytes, bytes], ...],
    metadata: tuple[tuple[str, str], ...],
) -> pa.Schema:
    """``schema`` with each field's unit and description, its ``existing`` and the ``metadata``.

    Keyed on the schema without metadata (a ``pa.Schema`` compares equal
    whatever its metadata) and the two metadata as tuples.
    """
    fields = [
        f.with_metadata(
            {b"unit": unit_of(f.name).encode(), b"description": description_of(f.name).encode()}
        )
        for f in schema
    ]
    file_metadata = dict(existing)
    file_metadata.update(_metadata(dict(metadata)))
    return pa.schema(fields, metadata=file_metadata)


def check_conventions(table: pa.Table) -> None:
    """Raise ``ValueError`` unless ``table`` carries the conventions of :func:`with_conventions`."""
    meta = table.schema.metadata or {}
    missing = [k for k in (b"cwrend_version", b"config_hash") if k not in meta]
    no_unit = [f.name for f in table.schema if b"unit" not in (f.metadata or {})]
    if missing or no_unit:
        raise ValueError(
            f"Parquet table without the data conventions: metadata {missing} missing, "
            f"columns without a unit {no_unit} (use output.tables.with_conventions)"
        )


def _conventional(table: pa.Table, metadata: Mapping[str, Any] | None) -> pa.Table:
    """``table`` with the conventions when ``metadata`` names the config hash, else the units."""
    meta = dict(metadata or {})
    if "config_hash" in meta:
        return with_conventions(table, meta)
    return table.replace_schema_metadata(_metadata(meta))


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
        *[(f"ucmd_{a}_km_s2", pa.float64()) for a in _AXES],
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
        ("trace_q", pa.float64()),
        ("nees", pa.float64()),
        ("degradation_window", pa.int64()),
        ("dropout", pa.bool_()),
        ("outlier", pa.bool_()),
    ]
)


def _stacked(results: Sequence[RunResult], attr: str) -> np.ndarray:
    """Per-step ``attr`` (one value a row) of ``results``, one run's rows after another's."""
    if len(results) == 1:
        return np.asarray(getattr(results[0], attr))
    return np.concatenate([getattr(r, attr) for r in results])


def _components(results: Sequence[RunResult], attr: str) -> np.ndarray:
    """Per-step vectors ``attr`` (N × k a run) of ``results`` as k contiguous rows (k × ΣN).

    One copy, in the layout Arrow takes without copying a column again.
    """
    parts = [getattr(r, attr).T for r in results]
    rows = np.empty((parts[0].shape[0], sum(p.shape[1] for p in parts)), dtype=parts[0].dtype)
    return np.concatenate(parts, axis=1, out=rows)


def row_norm(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """‖(x, y, z)‖ element by element, bit for bit ``np.linalg.norm(v, axis=1)`` of v = [x y z].

    That norm sums the squares of a row left to right, ``(x² + y²) + z²``,
    which this writes out on contiguous columns (10× faster than the
    reduction over rows of three; tests/test_campaign_tables.py checks
    that both agree on every bit).
    """
    norm: np.ndarray = np.sqrt((x * x + y * y) + z * z)
    return norm


def _steps_columns(results: Sequence[RunResult]) -> dict[str, Any]:
    """The :data:`STEPS_SCHEMA` columns but ``arch`` of ``results``, one run after another.

    Built from each quantity's arrays stacked once (not a table per run):
    row for row the same values as each run's own.
    """
    lengths = [r.t_s.size for r in results]
    x_true = _components(results, "x_true")
    x_hat = _components(results, "x_hat")
    u = _components(results, "u")
    u_cmd = _components(results, "u_cmd")
    y = _components(results, "y")
    cols: dict[str, Any] = {
        "seed": np.repeat(np.array([r.seed for r in results], dtype=np.int64), lengths),
        "step": np.concatenate([np.arange(n, dtype=np.int64) for n in lengths]),
        "t_s": _stacked(results, "t_s"),
    }
    for i, a in enumerate(_AXES):
        cols[f"{a}_km"] = x_true[i]
    for i, a in enumerate(_VEL):
        cols[f"{a}_km_s"] = x_true[3 + i]
    for i, a in enumerate(_AXES):
        cols[f"{a}_hat_km"] = x_hat[i]
    for i, a in enumerate(_VEL):
        cols[f"{a}_hat_km_s"] = x_hat[3 + i]
    # the control the actuator applied (RunResult.u; the command is RunResult.u_cmd)
    for i, a in enumerate(_AXES):
        cols[f"u{a}_km_s2"] = u[i]
    cols["u_norm_km_s2"] = row_norm(*u)
    for i, a in enumerate(_AXES):
        cols[f"ucmd_{a}_km_s2"] = u_cmd[i]
    if _has_angles(results):
        # a nonlinear sensor (issue 35): its components in their own columns, the
        # position measurement NaN (none was taken)
        parts = [_sensor_components(r) for r in results]
        y = np.concatenate([p[0] for p in parts], axis=1)
        for name, values in zip(
            ("meas_range_km", "meas_azimuth_deg", "meas_elevation_deg"),
            np.concatenate([p[1] for p in parts], axis=1),
            strict=True,
        ):
            cols[name] = values
    for i, a in enumerate(_AXES):
        cols[f"meas_{a}_km"] = y[i]
    for name in ("nis", "mtf_ratio", "score", "score_filtered", "eps"):
        cols[name] = _stacked(results, name)
    cols["pos_err_km"] = row_norm(*x_true[:3])
    cols["est_err_km"] = row_norm(*(x_hat[:3] - x_true[:3]))
    cols["est_vel_err_km_s"] = row_norm(*(x_hat[3:] - x_true[3:]))
    cols["trace_p"] = _stacked(results, "trace_p")
    cols["trace_q"] = _stacked(results, "trace_q")
    cols["nees"] = _stacked(results, "nees")
    cols["degradation_window"] = _stacked(results, "window").astype(np.int64)
    cols["dropout"] = _stacked(results, "dropout").astype(np.bool_)
    cols["outlier"] = _stacked(results, "outlier").astype(np.bool_)
    if _has_safety(results):
        safety = [r.safety for r in results if r.safety is not None]
        cols["safety_distance_km"] = np.concatenate([sf.step_distance_km for sf in safety])
    if _has_attitude(results):
        steps = [r.target_attitude.at_steps() for r in results if r.target_attitude is not None]
        q = np.concatenate([q for q, _ in steps])
        w = np.degrees(np.concatenate([w for _, w in steps]))
        for i in range(4):
            cols[f"target_q{i}"] = q[:, i]
        for i, a in enumerate(_AXES):
            cols[f"target_w{a}_deg_s"] = w[:, i]
    return cols


def _has_attitude(results: Sequence[RunResult]) -> bool:
    """True when the runs carry a tumbling target's attitude (all or none of them)."""
    flags = {r.target_attitude is not None for r in results}
    if len(flags) > 1:
        raise ValueError("runs with a tumbling and a fixed target in one steps table")
    return flags == {True}


def _has_angles(results: Sequence[RunResult]) -> bool:
    """True when a run measures range and angles or angles (issue 35): their columns are written."""
    return any(r.sensor != "position" for r in results)


def _sensor_components(result: RunResult) -> tuple[np.ndarray, np.ndarray]:
    """(position measurement (3, N) [km], (range [km], azimuth, elevation [deg]) (3, N)) of a run.

    Whichever the run's sensor did not measure is NaN.
    """
    y = np.asarray(result.y).T
    nan = np.full_like(y, np.nan)
    if result.sensor == "position":
        return y, nan
    if result.sensor == "range_bearing":
        return nan, np.vstack([y[:1], np.rad2deg(y[1:])])
    return nan, np.vstack([nan[:1], np.rad2deg(y[:2])])


#: The steps' columns of a nonlinear sensor (issue 35), only when a run has one.
SENSOR_STEP_FIELDS = [
    pa.field("meas_range_km", pa.float64()),
    pa.field("meas_azimuth_deg", pa.float64()),
    pa.field("meas_elevation_deg", pa.float64()),
]


def _has_safety(results: Sequence[RunResult]) -> bool:
    """True when the runs carry safety measurements (all or none of them: one problem)."""
    flags = {r.safety is not None for r in results}
    if len(flags) > 1:
        raise ValueError("runs with and without constraints in one steps table")
    return flags == {True}


def steps_table(result: RunResult, metadata: Mapping[str, Any] | None = None) -> pa.Table:
    """One row per grid time of a closed-loop run (row semantics: :class:`RunResult`)."""
    cols = {"arch": [result.arch] * result.t_s.size, **_steps_columns([result])}
    schema = _with_fields(STEPS_SCHEMA, SAFETY_STEP_FIELDS, result.safety is not None)
    schema = _with_fields(schema, SENSOR_STEP_FIELDS, _has_angles([result]), "nis")
    schema = _with_fields(schema, ATTITUDE_STEP_FIELDS, result.target_attitude is not None)
    return _conventional(pa.table(cols, schema=schema), metadata)


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


#: The :data:`SOLVES_SCHEMA` columns read from each :class:`SolveRecord`, in order.
_SOLVE_FIELDS = tuple(f.name for f in SOLVES_SCHEMA if f.name not in ("arch", "seed"))
_solve_values = operator.attrgetter(*_SOLVE_FIELDS)


def _solves_columns(results: Sequence[RunResult]) -> dict[str, Any]:
    """The :data:`SOLVES_SCHEMA` columns but ``arch`` of ``results``, one run after another.

    With constraints, also :data:`SCP_SOLVE_FIELDS`.
    """
    counts = [len(r.solves) for r in results]
    rows = [_solve_values(s) for r in results for s in r.solves]
    values = zip(*rows, strict=True) if rows else [()] * len(_SOLVE_FIELDS)
    cols = {
        "seed": np.repeat(np.array([r.seed for r in results], dtype=np.int64), counts),
        **dict(zip(_SOLVE_FIELDS, values, strict=True)),
    }
    if _has_safety(results):
        cols["scp_iterations"] = [s.scp_iterations for r in results for s in r.solves]
        cols["slack_km"] = [s.slack_km for r in results for s in r.solves]
        cols["fallback_programs"] = [s.fallback_programs for r in results for s in r.solves]
    if _has_abort(results):
        cols["abort_slack_km"] = [s.abort_slack_km for r in results for s in r.solves]
    return cols


def _has_abort(results: Sequence[RunResult]) -> bool:
    """True when the runs carry abort-safety measurements (one problem: all or none)."""
    return any(r.abort is not None for r in results)


#: The solves' columns of the constrained cone program (issue 32), only with constraints.
SCP_SOLVE_FIELDS = [
    pa.field("scp_iterations", pa.int64()),
    pa.field("slack_km", pa.float64()),
    pa.field("fallback_programs", pa.int64()),
]
#: The solves' abort-safety column (issue 34 item 4), only with constraints.abort_safe_s.
ABORT_SOLVE_FIELDS = [pa.field("abort_slack_km", pa.float64())]


def solves_table(result: RunResult, metadata: Mapping[str, Any] | None = None) -> pa.Table:
    """One row per solve (the initial one of adaptive runs, then every re-solve)."""
    cols = {"arch": [result.arch] * len(result.solves), **_solves_columns([result])}
    schema = _with_fields(SOLVES_SCHEMA, SCP_SOLVE_FIELDS, result.safety is not None)
    schema = _with_fields(schema, ABORT_SOLVE_FIELDS, result.abort is not None)
    return _conventional(pa.table(cols, schema=schema), metadata)


SUMMARY_SCHEMA = pa.schema(
    [
        ("arch", pa.string()),
        ("seed", pa.int64()),
        ("delta_v_km_s", pa.float64()),
        ("delta_v_applied_km_s", pa.float64()),
        ("miss_km", pa.float64()),
        ("fuel_penalty_pct", pa.float64()),
        ("fuel_penalty_applied_pct", pa.float64()),
        ("n_solves", pa.int64()),
        ("n_converged", pa.int64()),
        ("n_infeasible", pa.int64()),
        ("n_failed", pa.int64()),
        ("solve_success_pct", pa.float64()),
        ("solve_mean_ms", pa.float64()),
        ("solve_max_ms", pa.float64()),
        ("mean_nis_nominal", pa.float64()),
        ("mean_nees", pa.float64()),
    ]
)


#: The runs' safety columns (issue 32), written only when the runs have constraints.
SAFETY_RUN_FIELDS = [
    pa.field("safety_min_distance_km", pa.float64()),
    pa.field("safety_unsafe_time_s", pa.float64()),
    pa.field("safety_corridor_violation_deg", pa.float64()),
    pa.field("safety_approach_speed_km_s", pa.float64()),
    pa.field("safety_approach_angle_deg", pa.float64()),
    pa.field("safety_violated", pa.bool_()),
]
#: The runs' abort-safety columns (issue 34 item 4), written only with abort_safe_s.
ABORT_RUN_FIELDS = [
    pa.field("abort_min_distance_km", pa.float64()),
    pa.field("abort_unsafe_steps", pa.int64()),
    pa.field("abort_unsafe", pa.bool_()),
]
#: The runs' docking-state columns (issue 34), written after :data:`SAFETY_RUN_FIELDS` only
#: for a tumbling target (its measures are against the turning set).
DOCK_RUN_FIELDS = [
    pa.field("safety_dock_position_error_km", pa.float64()),
    pa.field("safety_dock_velocity_error_km_s", pa.float64()),
]
#: The steps' safety columns (issue 32), written only when the runs have constraints.
SAFETY_STEP_FIELDS = [
    pa.field("safety_distance_km", pa.float64()),
]
#: The steps' target-attitude columns (issue 34), written only for a tumbling target.
ATTITUDE_STEP_FIELDS = [
    *[pa.field(f"target_q{i}", pa.float64()) for i in range(4)],
    *[pa.field(f"target_w{a}_deg_s", pa.float64()) for a in _AXES],
]


def summary_row(result: RunResult, fuel: OpenLoopResult) -> dict[str, Any]:
    """A ``summary.parquet`` / ``runs.parquet`` row of one run.

    Among its metrics those of paper Sec. "Numerical Results and Discussion" (Δv, miss,
    fuel penalty, solve times and success).

    With constraints, the safety of the true trajectory too (:data:`SAFETY_RUN_FIELDS`;
    with abort safety, :data:`ABORT_RUN_FIELDS`).
    ``fuel`` is the scenario's open-loop fuel-optimal reference (the fuel penalties).
    """
    metrics = run_metrics(result, fuel)
    # its fields are numbers: no deep copy (dataclasses.asdict) needed
    fields = {f.name: getattr(metrics, f.name) for f in dataclasses.fields(metrics)}
    row = {"arch": result.arch, "seed": result.seed, **fields}
    if result.safety is not None:
        sf = result.safety
        row["safety_min_distance_km"] = sf.min_distance_km
        row["safety_unsafe_time_s"] = sf.unsafe_time_s
        row["safety_corridor_violation_deg"] = sf.corridor_violation_deg
        row["safety_approach_speed_km_s"] = sf.approach_speed_km_s
        row["safety_approach_angle_deg"] = sf.approach_angle_deg
        row["safety_violated"] = sf.violated
        if sf.rotating:
            row["safety_dock_position_error_km"] = sf.dock_position_error_km
            row["safety_dock_velocity_error_km_s"] = sf.dock_velocity_error_km_s
    if result.abort is not None:
        row["abort_min_distance_km"] = result.abort.min_distance_km
        row["abort_unsafe_steps"] = result.abort.unsafe_steps
        row["abort_unsafe"] = result.abort.unsafe
    return row


def _with_fields(
    schema: pa.Schema, fields: Sequence[pa.Field], present: bool, before: str | None = None
) -> pa.Schema:
    """``schema`` with the optional ``fields`` (before column ``before``, else last) if present."""
    if not present:
        return schema
    columns = list(schema)
    at = schema.names.index(before) if before is not None else len(columns)
    return pa.schema([*columns[:at], *fields, *columns[at:]])


def reference_row(ref: OpenLoopResult, fuel: OpenLoopResult) -> dict[str, Any]:
    """Summary row of an open-loop reference (``arch`` = ``open_loop_<name>``)."""
    metrics = reference_metrics(ref, fuel)
    return {"arch": f"open_loop_{ref.name}", "seed": -1, **dataclasses.asdict(metrics)}


def summary_table(
    rows: Sequence[Mapping[str, Any]], metadata: Mapping[str, Any] | None = None
) -> pa.Table:
    """Table of summary rows (see :func:`summary_row`)."""
    safety = any(SAFETY_RUN_FIELDS[0].name in r for r in rows)
    schema = _with_fields(SUMMARY_SCHEMA, SAFETY_RUN_FIELDS, safety)
    schema = _with_fields(schema, DOCK_RUN_FIELDS, any(DOCK_RUN_FIELDS[0].name in r for r in rows))
    abort = any(ABORT_RUN_FIELDS[0].name in r for r in rows)
    schema = _with_fields(schema, ABORT_RUN_FIELDS, abort)
    table = pa.Table.from_pylist([dict(r) for r in rows], schema=schema)
    return _conventional(table, metadata)


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
    return _conventional(pa.concat_tables(parts), metadata)


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


def _run_columns(
    extra: Mapping[str, Sequence[str]], rows_per_run: Sequence[int]
) -> dict[str, pa.Array]:
    """Each per-run value of ``extra`` repeated over its run's rows."""
    index = pa.array(np.repeat(np.arange(len(rows_per_run), dtype=np.int64), rows_per_run))
    return {name: pa.array(list(values), pa.string()).take(index) for name, values in extra.items()}


def campaign_steps_table(
    results: Sequence[RunResult],
    extra: Mapping[str, Sequence[str]],
    metadata: Mapping[str, Any] | None = None,
) -> pa.Table:
    """Steps of several runs for the hive-partitioned ``steps/`` dataset.

    ``arch`` is the partition key, not a column; ``extra`` holds a value per
    run (``run_key``, ``point``). One table built from the runs' stacked
    arrays: what a table per run concatenated held, with fewer allocations.
    """
    cols = _steps_columns(results)
    cols.update(_run_columns(extra, [r.t_s.size for r in results]))
    schema = _with_fields(
        CAMPAIGN_STEPS_SCHEMA, SAFETY_STEP_FIELDS, _has_safety(results), "run_key"
    )
    schema = _with_fields(schema, SENSOR_STEP_FIELDS, _has_angles(results), "nis")
    schema = _with_fields(schema, ATTITUDE_STEP_FIELDS, _has_attitude(results), "run_key")
    return _conventional(pa.table(cols, schema=schema), metadata)


def campaign_solves_table(
    results: Sequence[RunResult],
    extra: Mapping[str, Sequence[str]],
    metadata: Mapping[str, Any] | None = None,
) -> pa.Table:
    """Solves of several runs for the hive-partitioned ``solves/`` dataset (as the steps)."""
    cols = _solves_columns(results)
    cols.update(_run_columns(extra, [len(r.solves) for r in results]))
    safety = _has_safety(results)
    schema = _with_fields(CAMPAIGN_SOLVES_SCHEMA, SCP_SOLVE_FIELDS, safety, "run_key")
    schema = _with_fields(schema, ABORT_SOLVE_FIELDS, _has_abort(results), "run_key")
    return _conventional(pa.table(cols, schema=schema), metadata)


_RUN_METRICS = [f for f in SUMMARY_SCHEMA if f.name not in ("arch", "seed")]


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
    safety = any(SAFETY_RUN_FIELDS[0].name in r.get("metrics", {}) for r in records)
    dock = any(DOCK_RUN_FIELDS[0].name in r.get("metrics", {}) for r in records)
    abort = any(ABORT_RUN_FIELDS[0].name in r.get("metrics", {}) for r in records)
    optional = (SAFETY_RUN_FIELDS if safety else []) + (DOCK_RUN_FIELDS if dock else [])
    for f in _RUN_METRICS + optional + (ABORT_RUN_FIELDS if abort else []):
        cols[f.name] = [r.get("metrics", {}).get(f.name) for r in records]
        fields.append(f)
    for prefix, key in ((PARAM_PREFIX, "params"), ("disp.", "dispersed")):
        for name, arr in _keyed_columns(records, key, prefix):
            cols[name] = arr
            fields.append(pa.field(name, arr.type))
    return _conventional(pa.table(cols, schema=pa.schema(fields)), metadata)


def _keyed_columns(
    records: Sequence[Mapping[str, Any]], key: str, prefix: str
) -> list[tuple[str, pa.Array]]:
    """A column ``<prefix><config key>`` per key of the records' mappings ``record[key]``.

    Sorted by key; numbers as float64 (int64 when all are integers), other
    values of one type as that type, vectors (a swept ``body_rates_deg_s``) and
    mixed ones as JSON text, so that every cell is one hashable value that the
    report and ``cwrend table`` can group by; missing: null.
    """
    columns = []
    for name in sorted({k for r in records for k in r.get(key, {})}):
        values = [r.get(key, {}).get(name) for r in records]
        kinds = {type(v) for v in values if v is not None}
        if kinds <= {int, float} and not kinds <= {int}:
            arr = pa.array([None if v is None else float(v) for v in values], pa.float64())
        elif len(kinds) == 1 and not kinds & {list, tuple}:
            arr = pa.array(values)
        else:
            arr = pa.array([None if v is None else json.dumps(v) for v in values], pa.string())
        columns.append((prefix + name, arr))
    return columns


def points_table(
    points: Sequence[tuple[str, Mapping[str, Any]]], metadata: Mapping[str, Any]
) -> pa.Table:
    """``points.parquet``: one row per grid or design point, its id and its swept values.

    ``points``: ``(point id, {config key: value})`` in plan order. The columns
    are those of ``runs.parquet``: ``point`` and ``param.<key>`` (typed as
    there, with the key's unit), so the per-step and per-solve datasets,
    which name each row's point, join the swept values on ``point`` alone.
    """
    records = [{"params": dict(values)} for _, values in points]
    cols: dict[str, pa.Array] = {"point": pa.array([p for p, _ in points], pa.string())}
    cols.update(_keyed_columns(records, "params", PARAM_PREFIX))
    return _conventional(pa.table(cols), metadata)


def statistics_table(frame: pd.DataFrame, metadata: Mapping[str, Any]) -> pa.Table:
    """A long-format statistics table (``ablation.parquet``, ``sweep.parquet``) from pandas."""
    table = pa.Table.from_pandas(frame, preserve_index=False).replace_schema_metadata(None)
    return with_conventions(table, metadata)


def normalize_steps(frame: pd.DataFrame) -> pd.DataFrame:
    """Steps read back from any version: the old ``window`` column as ``degradation_window``.

    Campaigns written before issue 18 named the degradation-window column
    ``window`` (an SQL keyword). A dataset mixing both (a campaign resumed
    by a newer cwrend) has both; the new column is filled from the old.
    """
    if "window" not in frame.columns:
        return frame
    if "degradation_window" in frame.columns:
        frame["degradation_window"] = frame["degradation_window"].fillna(frame["window"])
        return frame.drop(columns="window")
    return frame.rename(columns={"window": "degradation_window"})
