"""Typed report data, loaded from a results directory (never recomputing physics).

Reads either layout that cwrend writes:

* a ``cwrend run`` directory: ``summary.parquet``, ``steps.parquet``,
  ``solves.parquet``, ``references.parquet``, ``config.json``;
* a campaign directory: ``runs.parquet`` (one row per run: ``run_key``,
  ``point``, ``arch``, ``seed``, ``status``, the summary metrics, swept values
  as ``param.<key>``), the hive dataset ``steps/arch=<slug>/…`` (steps columns
  plus ``run_key`` and ``point``; the per-step NEES of every seed of the
  reported point is read too, when stored), the open-loop references of each
  grid point (with the schema of a run's ``references.parquet``: the file
  ``references/index.jsonl`` names for the point, shared by the points of one
  scenario and solver, or ``references/<point>.parquet`` as earlier versions
  wrote them; :func:`references_file`) and ``manifest.json`` (``config`` =
  the resolved base config).

A campaign of a sampled design (``cwrend sweep --design …``) is recognised
(:attr:`ReportData.design`) by its ``sensitivity.parquet`` (Sobol indices of a
``sobol`` design, read into :attr:`ReportData.sensitivity`), or by a manifest
whose ``grid`` is empty while the runs hold swept (``param.``) values over
more than one point: its hundreds of points get no per-point sweep tables or
figures.

The stored configuration is validated with the config model
(:func:`~cwrend_cli.config.config_from_dict`); the figures and tables read
typed values from it. A campaign written before campaigns stored their
references is reported without them, with a note. Steps written before the
degradation-window column was renamed (``window``, issue 18 item 5) are read
with the current name (:func:`~cwrend_cli.output.tables.normalize_steps`).

Units: km, s, km/s, km/s² (as in the Parquet files).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
import pyarrow.dataset as ds

from cwrend_cli.config import (
    ALL_ARCHITECTURES,
    CwrendConfig,
    config_from_dict,
    get_dotted,
    resolved_dict,
    set_dotted,
)
from cwrend_cli.config.adapt import constraints_of, problem_of, windows_of
from cwrend_cli.config.overrides import point_tree
from cwrend_cli.errors import ConfigError, CwrendError
from cwrend_cli.output.files import refuse_links
from cwrend_cli.output.layout import (
    ABLATION_STATS,
    DESIGN,
    EVENTS,
    MANIFEST,
    PARAM_PREFIX,
    REFERENCES,
    REFERENCES_INDEX,
    REPORT_DIR,
    RUN_CONFIG,
    RUN_REFERENCES,
    RUN_STEPS,
    RUN_SUMMARY,
    RUNS,
    SENSITIVITY,
    STEPS,
    SWEEP_STATS,
    references_path,
)
from cwrend_cli.output.manifest import REPAIR_HINT, nis_offset_given, read_manifest, xf_given
from cwrend_cli.output.tables import REFERENCE_SCHEMA, normalize_steps, param_columns
from cwrend_cli.physics.constraints import Geometry, geometry
from cwrend_cli.physics.metrics import cumulative_delta_v
from cwrend_cli.physics.params import Sensor, Window, arch_order
from cwrend_cli.report.labels import format_value

Layout = Literal["run", "campaign"]


#: What a report reads (or writes: ``report/``) in a results directory; none may be a link:
#: a report never reads another directory's results nor writes outside (issue 36, item 6).
REPORTED = (
    MANIFEST, RUNS, EVENTS, STEPS, REFERENCES, ABLATION_STATS, SWEEP_STATS, SENSITIVITY,
    DESIGN, RUN_CONFIG, RUN_SUMMARY, RUN_STEPS, RUN_REFERENCES, REPORT_DIR,
)  # fmt: skip


class ReportError(CwrendError):
    """The results directory cannot be reported on (missing, incomplete or unreadable)."""


@dataclass(frozen=True, eq=False)
class ReportData:
    """Everything the figures and tables need, loaded from one results directory.

    Tables keep the stored column names and units. ``config`` is the stored
    configuration validated by the config model, or ``None`` when the
    directory holds none that validates (then no degradation window, thrust
    limit or NIS offset is drawn, and ``notes`` says why).
    """

    layout: Layout
    runs: pd.DataFrame  # one row per closed-loop run: arch, seed, status, metrics, param.*
    ref_summary: pd.DataFrame  # arch ("open_loop_<name>"), seed, delta_v_km_s, miss_km, …
    steps: pd.DataFrame  # steps of the selected seed (and point), all architectures
    references: pd.DataFrame | None  # reference trajectories (reference, t_s, x_km, …)
    config: CwrendConfig | None
    config_hash: str
    seed: int  # noise realisation of the per-seed figures
    point: str | None  # grid point of the per-seed figures (campaigns with several points)
    archs: tuple[str, ...]  # in canonical order
    params: tuple[str, ...] = ()  # swept param columns with > 1 value
    notes: tuple[str, ...] = ()
    #: rows of ``ablation.parquet`` / ``sweep.parquet`` (long format: kind, arch, metric,
    #: statistic, value, ci_low, ci_high, n; ``point`` and ``param.*`` for a sweep), if stored
    stats: pd.DataFrame | None = None
    #: per-step NEES of the reported point, every seed whose steps are stored (arch, seed,
    #: t_s, nees; and nis, degradation_window when stored); ``None`` for results written
    #: before cwrend stored the NEES
    nees: pd.DataFrame | None = None
    #: a sampled design's points (``sweep --design``) rather than a grid: no per-point
    #: sweep tables and figures (hundreds of points); ``params`` still lists the swept keys
    design: bool = False
    #: rows of ``sensitivity.parquet`` (arch, metric, parameter, statistic S1/ST, value,
    #: ci_low, ci_high, n_seeds), a ``sobol`` design's indices, if stored
    sensitivity: pd.DataFrame | None = None
    #: the campaign's base config gave ``schedule.nis_offset`` (its manifest's
    #: ``nis_offset_given``; else a point that sets the sensor has its sensor's offset)
    nis_offset_given: bool = True
    #: the base config gave ``scenario.xf`` (its manifest's ``xf_given``; else a point
    #: that introduces a corridor ends at its port at rest)
    xf_given: bool = True

    @property
    def world(self) -> str:
        """The simulated world of the reported point: truth model, actuator errors, sensor faults.

        E.g. ``truth: cw (the design model)`` or ``truth: j2 · actuator errors
        on · sensor faults on`` (issue 15: the guidance and the filter always
        assume CW; this names what the truth was). In a sweep, the world of the
        point the per-seed figures show, with its swept values set
        (:attr:`point_config`; issue 37: a sweep over ``truth.model``).
        """
        return world_of(self.point_config)

    @cached_property
    def point_config(self) -> CwrendConfig | None:
        """The configuration of the reported point: :attr:`config` with its swept values set.

        What the per-seed figures were simulated with (:func:`with_swept_values`);
        :attr:`config` itself for a run or an ablation.
        """
        return with_swept_values(self.config, self.ok_runs(), self.nis_offset_given, self.xf_given)

    @property
    def worlds(self) -> str:
        """The simulated worlds of every point, for the figures that show them all.

        The world of each point (:attr:`world`); when they differ (a sweep over
        ``truth.model``, say), ``one per point:`` and each distinct world once,
        sorted, separated by ``;`` (:func:`worlds_of`).
        """
        return worlds_of(self.config, self.runs, self.nis_offset_given, self.xf_given)

    def point_stats(self) -> pd.DataFrame | None:
        """The stored statistics of the reported grid point (all of them for an ablation)."""
        if self.stats is None:
            return None
        stats = self.stats
        if self.point is not None and "point" in stats.columns:
            stats = stats[stats["point"].astype(str) == self.point]
        elif "point" in stats.columns and stats["point"].nunique() > 1:
            return None
        return stats

    @property
    def windows(self) -> tuple[Window, ...]:
        """The degradation windows of the reported point (none without a configuration)."""
        return windows_of(self.point_config) if self.point_config is not None else ()

    @property
    def constraints(self) -> Geometry | None:
        """The path constraints of the reported point as arrays (issue 32; ``None`` without).

        The keep-out ellipsoid and the corridor cone the safety columns were measured
        against (:func:`~cwrend_cli.physics.constraints.geometry`); ``None`` without a
        stored configuration or when it has neither a keep-out zone nor a corridor.
        """
        config = self.point_config
        found = constraints_of(config) if config is not None else None
        return geometry(found) if found is not None else None

    @property
    def u_max_km_s2(self) -> float | None:
        """Thrust limit of the reported point [km/s²] (``None`` without a configuration)."""
        config = self.point_config
        return config.scenario.u_max_km_s2 if config is not None else None

    @property
    def nis_dof(self) -> int:
        """The NIS's degrees of freedom at the reported point: its sensor's dimension m.

        3, or 2 for the angles sensor (issue 35); 3 without a configuration.
        """
        config = self.point_config
        model = config.sensor.model if config is not None else "position"
        return Sensor(model=model).dimension

    @property
    def nis_offset(self) -> float | None:
        """NIS offset ``m`` of the reported point's score (``None`` without a configuration)."""
        config = self.point_config
        return config.schedule.nis_offset if config is not None else None

    def ok_runs(self) -> pd.DataFrame:
        """The successful runs of the reported grid point (every run of a single point)."""
        runs = self.runs[self.runs["status"] == "ok"]
        if self.point is not None and "point" in runs.columns:
            runs = runs[runs["point"].astype(str) == self.point]
        return runs

    def multi_seed(self) -> bool:
        """More than one successful seed for some architecture (distributions apply)."""
        ok = self.ok_runs()
        return not ok.empty and int(ok.groupby("arch")["seed"].nunique().max()) > 1


# ---------------------------------------------------------------------------
# Stored values
# ---------------------------------------------------------------------------


def world_of(config: CwrendConfig | None) -> str:
    """The simulated world of ``config`` (see :attr:`ReportData.world`)."""
    if config is None:
        return "truth model not stored"
    model = config.truth.model
    parts = [f"truth: {model}" + (" (the design model)" if model == "cw" else "")]
    if not problem_of(config).actuator.ideal:
        parts.append("actuator errors on")
    if any(_has_faults(w) for w in windows_of(config)):
        parts.append("sensor faults on")
    return " · ".join(parts)


def worlds_of(
    config: CwrendConfig | None,
    runs: pd.DataFrame,
    offset_given: bool = True,
    xf_given_: bool = True,
) -> str:
    """The simulated worlds of every point of ``runs`` (rows of ``runs.parquet``).

    The world of each point's successful runs, ``config`` with their swept values
    set (:func:`with_swept_values`); when they differ (a sweep over ``truth.model``,
    say), ``one per point:`` and each distinct world once, sorted, separated by
    ``;``. ``config``'s own world without runs (a single run's directory).
    """
    ok = runs[runs["status"] == "ok"] if "status" in runs.columns else runs
    if "point" not in ok.columns or ok["point"].nunique() <= 1:
        return world_of(with_swept_values(config, ok, offset_given, xf_given_))
    found = {
        world_of(with_swept_values(config, point, offset_given, xf_given_))
        for _, point in ok.groupby(ok["point"].astype(str), sort=False)
    }
    return found.pop() if len(found) == 1 else "one per point: " + "; ".join(sorted(found))


def with_swept_values(
    config: CwrendConfig | None,
    runs: pd.DataFrame,
    offset_given: bool = True,
    xf_given_: bool = True,
) -> CwrendConfig | None:
    """The configuration ``runs`` were simulated with: ``config`` with their swept values set.

    ``runs`` are one point's rows of ``runs.parquet``; every ``param.<key>``
    column with a single value over them is set at ``key``, as the campaign set
    it on the base configuration (:func:`~cwrend_cli.config.overrides.point_tree`,
    ``offset_given`` as the manifest records it: a point that sets the sensor has
    its sensor's NIS offset unless the base gave one; ``xf_given_`` likewise: a point
    that introduces a corridor ends at its port unless the base gave ``scenario.xf``).
    ``config`` itself when
    nothing was swept; ``None`` without a configuration or when the result does
    not validate.
    """
    if config is None:
        return None
    assignment = []
    for column in param_columns(runs.columns):
        values = runs[column].dropna().unique()
        if len(values) == 1:
            assignment.append((column.removeprefix(PARAM_PREFIX), param_value(values[0])))
    if not assignment:
        return config
    try:
        tree = point_tree(resolved_dict(config), assignment, offset_given, xf_given_)
        return config_from_dict(tree)
    except ConfigError:
        return None


def results_world(results_dir: Path) -> str:
    """The simulated worlds of a run or campaign directory (:func:`worlds_of`).

    For figures that are not part of a report (``cwrend compare``'s): the stored
    configuration of ``manifest.json`` (campaign) or ``config.json`` (run), with
    the swept values of each point of a campaign's ``runs.parquet`` set (a sweep
    over ``truth.model`` names each point's world, not the base's);
    ``truth model not stored`` when neither holds a configuration that validates.
    """
    root = Path(results_dir)
    for name in (MANIFEST, RUN_CONFIG):
        path = root / name
        if path.exists():
            try:
                stored = _read_json(path)
                runs = _world_columns(root / RUNS) if (root / RUNS).exists() else pd.DataFrame()
            except ReportError:
                break
            config = _stored_config(stored.get("config"), path, [])
            return worlds_of(config, runs, nis_offset_given(stored), xf_given(stored))
    return world_of(None)


def _world_columns(runs_path: Path) -> pd.DataFrame:
    """The columns of ``runs.parquet`` a world is told from (:func:`worlds_of`): ``status``,
    ``point`` and the swept values, not the whole file (a 5,000,000-run campaign's)."""
    try:
        names = ds.dataset(runs_path, format="parquet").schema.names
    except (OSError, ValueError) as exc:
        raise ReportError(f"{runs_path}: unreadable Parquet ({exc})") from None
    wanted = [c for c in names if c in ("status", "point")] + param_columns(names)
    return _read_parquet(runs_path, columns=wanted)


def arch_label(slug: str) -> str:
    """Display name of an architecture, the cone-program ones too (the slug itself if unknown)."""
    arch = ALL_ARCHITECTURES.get(slug)
    return arch.label if arch is not None else slug


def param_value(value: Any) -> Any:
    """A ``param.<key>`` cell as the value that was applied (JSON text for mixed kinds)."""
    if isinstance(value, str):
        try:
            return json.loads(value)
        except json.JSONDecodeError:
            return value
    if isinstance(value, np.generic):
        return value.item()
    return value


def param_values(series: pd.Series) -> tuple[np.ndarray, bool]:
    """A ``param.<key>`` column as floats if every value is numeric, else as strings."""
    numeric = pd.to_numeric(series, errors="coerce")
    if numeric.notna().all():
        return numeric.to_numpy(dtype=float), True
    return series.astype(str).to_numpy(), False


def point_values(runs: pd.DataFrame) -> str:
    """``key=value, …`` of the swept parameters of one point's runs."""
    if runs.empty:
        return ""
    row = runs.iloc[0]
    cols = param_columns(runs.columns)
    return ", ".join(
        f"{c.removeprefix(PARAM_PREFIX)}={format_value(param_value(row[c]))}" for c in cols
    )


# ---------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:  # ValueError: not UTF-8, not JSON
        raise ReportError(f"{path}: unreadable ({exc})") from None
    except RecursionError:
        raise ReportError(f"{path}: unreadable (nested too deep)") from None
    if not isinstance(data, dict):
        raise ReportError(f"{path}: unreadable (not a JSON object)")
    return data


def _has_faults(w: Window) -> bool:
    """True when degradation window ``w`` switches a sensor fault on (issue 15, item 3)."""
    return w.dropout_probability > 0.0 or w.has_outliers or w.bias_drift_km_per_sqrt_s > 0.0


def _read_parquet(path: Path, **kwargs: Any) -> pd.DataFrame:
    try:
        return pd.read_parquet(path, **kwargs)
    except (OSError, ValueError) as exc:
        raise ReportError(f"{path}: unreadable Parquet ({exc})") from None


def _read_steps(path: Path, **kwargs: Any) -> pd.DataFrame:
    """Steps (file or dataset) with the current column names, whatever cwrend wrote them."""
    return normalize_steps(_read_parquet(path, **kwargs))


#: The steps columns of filter consistency read for every seed, when stored (beside the NEES).
_CONSISTENCY_COLUMNS = ("nis", "degradation_window")


def _nees_of(steps: pd.DataFrame) -> pd.DataFrame | None:
    """The consistency columns of steps of every seed (``None`` when no NEES is stored).

    ``arch``, ``seed``, ``t_s``, ``nees``, and ``nis`` and ``degradation_window``
    where the steps hold them.
    """
    if "nees" not in steps.columns:
        return None
    extra = [c for c in _CONSISTENCY_COLUMNS if c in steps.columns]
    out = steps[["arch", "seed", "t_s", "nees", *extra]].copy()
    out["arch"] = out["arch"].astype(str)
    return out


def _campaign_nees(steps_dir: Path, point: str | None) -> pd.DataFrame | None:
    """NEES (and NIS) of every seed of the reported point from steps/ (``None``: not stored)."""
    names = set(ds.dataset(steps_dir, format="parquet", partitioning="hive").schema.names)
    if "nees" not in names:
        return None
    wanted = ["arch", "seed", "t_s", "nees", "point", *_CONSISTENCY_COLUMNS, "window"]
    frame = _read_steps(steps_dir, columns=[c for c in wanted if c in names])
    if point is not None and "point" in frame.columns:
        frame = frame[frame["point"].astype(str) == point]
    return _nees_of(frame)


def _read_references(path: Path) -> pd.DataFrame:
    """Reference trajectories (schema of :func:`~cwrend_cli.output.tables.references_table`)."""
    references = _read_parquet(path)
    missing = set(REFERENCE_SCHEMA.names) - set(references.columns)
    if missing:
        raise ReportError(f"{path}: missing columns {', '.join(sorted(missing))}")
    return references


def _stored_config(raw: Any, source: Path, notes: list[str]) -> CwrendConfig | None:
    """The configuration stored with the results, validated by the config model.

    A ``noise.file`` that is no longer where it was does not stop the report
    (which never reads the noise realisation): the config is then validated
    without it. ``None``, with a note, when no configuration is stored or it
    does not validate with this version of cwrend.
    """
    unused = "degradation windows, thrust limit and NIS offset are not drawn"
    if not isinstance(raw, Mapping) or not raw:
        notes.append(f"`{source.name}` holds no configuration: {unused}.")
        return None
    try:
        return config_from_dict(raw, source=source.name)
    except ConfigError as exc:
        error = exc
    if isinstance(raw.get("noise"), Mapping) and raw["noise"].get("file") is not None:
        try:
            return config_from_dict(set_dotted(raw, "noise.file", None), source=source.name)
        except ConfigError:
            pass
    problems = "; ".join(error.problems) or str(error)
    notes.append(f"The configuration in `{source.name}` does not validate ({problems}): {unused}.")
    return None


def _reference_summary(
    references: pd.DataFrame | None, config: CwrendConfig | None
) -> pd.DataFrame:
    """Δv (trapezoid of ‖u‖) and miss of each reference trajectory: its final distance to
    the terminal position ``scenario.xf`` of ``config`` (the port with a corridor; the
    target, the origin, without a configuration)."""
    target = np.zeros(3) if config is None else np.asarray(config.scenario.xf[:3], dtype=float)
    rows = []
    if references is not None:
        for name, g in references.groupby("reference", sort=False, observed=True):
            g = g.sort_values("t_s")
            last = g.iloc[-1]
            dv = cumulative_delta_v(g["t_s"].to_numpy(), g["u_norm_km_s2"].to_numpy())[-1]
            rows.append(
                {
                    "arch": f"open_loop_{name}",
                    "seed": -1,
                    "delta_v_km_s": float(dv),
                    "miss_km": float(
                        np.linalg.norm(
                            np.array([last["x_km"], last["y_km"], last["z_km"]], float) - target
                        )
                    ),
                }
            )
    out = pd.DataFrame(rows, columns=["arch", "seed", "delta_v_km_s", "miss_km"])
    fuel = out.loc[out["arch"] == "open_loop_fuel", "delta_v_km_s"]
    if not fuel.empty:
        out["fuel_penalty_pct"] = 100.0 * (out["delta_v_km_s"] / float(fuel.iloc[0]) - 1.0)
    return out


def _same_value(a: Any, b: Any) -> bool:
    try:
        return bool(np.isclose(float(a), float(b), rtol=1e-12, atol=0.0))
    except (TypeError, ValueError):
        return str(a) == str(b)


def _reported_point(runs: pd.DataFrame, config: CwrendConfig | None) -> str | None:
    """The grid point of the per-seed figures: the one at the base config's values, else the first.

    Points are tried in sorted order; only points with a successful run qualify.
    """
    ok = runs[runs["status"] == "ok"]
    if ok.empty:
        return None
    params = param_columns(runs.columns)
    points: list[str] = sorted(ok["point"].astype(str).unique())
    tree = resolved_dict(config) if config is not None else {}
    for point in points:
        row = ok[ok["point"].astype(str) == point].iloc[0]
        try:
            base = [get_dotted(tree, c.removeprefix(PARAM_PREFIX)) for c in params]
        except (KeyError, IndexError, TypeError, ValueError):
            break
        values = [param_value(row[c]) for c in params]
        if all(_same_value(v, b) for v, b in zip(values, base, strict=True)):
            return point
    return points[0]


def _point_list(runs: pd.DataFrame) -> str:
    """``id (key=value, …)`` of every grid point with a successful run, for messages."""
    ok = runs[runs["status"] == "ok"]
    points = sorted(ok["point"].astype(str).unique()) if "point" in ok.columns else []
    return (
        "; ".join(f"{p} ({point_values(ok[ok['point'].astype(str) == p])})" for p in points)
        or "none"
    )


def _matches(row: pd.Series, params: list[str], wanted: str) -> bool:
    """Whether a point's swept values are ``wanted``: ``key=value, …`` or the values alone.

    Keys may be given in full (``schedule.beta``) or by their last segment
    (``beta``); with the values alone they are in the order of the columns.
    """
    parts = [p.strip() for p in wanted.split(",") if p.strip()]
    if not parts or len(parts) != len(params):
        return False
    given: dict[str, str] = {}
    for i, part in enumerate(parts):
        if "=" in part:
            key, value = (x.strip() for x in part.split("=", 1))
            full = [c for c in params if c.removeprefix(PARAM_PREFIX) == key
                    or c.removeprefix(PARAM_PREFIX).rsplit(".", 1)[-1] == key]  # fmt: skip
            if len(full) != 1:
                return False
            given[full[0]] = value
        else:
            given[params[i]] = part
    if set(given) != set(params):
        return False
    return all(_same_value(param_value(row[c]), _parsed(v)) for c, v in given.items())


def _parsed(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _chosen_point(runs: pd.DataFrame, wanted: str) -> str:
    """The grid point named by ``--point`` (its id or its swept values)."""
    ok = runs[runs["status"] == "ok"]
    points: list[str] = sorted(ok["point"].astype(str).unique())
    if wanted in points:
        return wanted
    params = param_columns(runs.columns)
    found = [
        p for p in points if params and _matches(ok[ok["point"].astype(str) == p].iloc[0],
                                                  params, wanted)
    ]  # fmt: skip
    if len(found) == 1:
        return found[0]
    if not params:  # an ablation (or a run): one point, nothing swept
        raise ReportError(
            f"--point {wanted}: this campaign sweeps nothing (one point, {', '.join(points)}); "
            "--point picks a point of a sweep: drop it"
        )
    what = "matches several grid points" if found else "no such grid point"
    raise ReportError(f"--point {wanted}: {what} (points: {_point_list(runs)})")


def _pick_seed(runs: pd.DataFrame, seed: int | None) -> int:
    ok = runs[runs["status"] == "ok"]
    if ok.empty:
        raise ReportError("no successful run to report on (every run failed)")
    seeds = sorted(int(s) for s in ok["seed"].unique())
    if seed is None:
        return seeds[0]
    if seed not in seeds:
        shown = ", ".join(map(str, seeds[:10])) + (" …" if len(seeds) > 10 else "")
        raise ReportError(f"--seed {seed}: no successful run with that seed (available: {shown})")
    return seed


# ---------------------------------------------------------------------------
# The two layouts
# ---------------------------------------------------------------------------


def _load_run_dir(root: Path, seed: int | None, point: str | None = None) -> ReportData:
    if point is not None:
        raise ReportError(f"--point {point}: {root} is a `cwrend run` directory (one point)")
    for name in (RUN_SUMMARY, RUN_STEPS, RUN_CONFIG):
        if not (root / name).exists():
            raise ReportError(f"{root}: not a complete cwrend results directory (no {name})")
    meta = _read_json(root / RUN_CONFIG)
    notes: list[str] = []
    config = _stored_config(meta.get("config"), root / RUN_CONFIG, notes)
    summary = _read_parquet(root / RUN_SUMMARY)
    is_ref = summary["arch"].astype(str).str.startswith("open_loop_")
    runs = summary[~is_ref].copy()
    runs["arch"] = runs["arch"].astype(str)
    runs["status"] = "ok"
    chosen = _pick_seed(runs, seed)
    all_steps = _read_steps(root / RUN_STEPS)
    steps = all_steps[all_steps["seed"] == chosen].copy()
    references = (
        _read_references(root / RUN_REFERENCES) if (root / RUN_REFERENCES).exists() else None
    )
    return ReportData(
        layout="run",
        runs=runs,
        ref_summary=summary[is_ref].copy(),
        steps=steps,
        references=references,
        config=config,
        config_hash=str(meta.get("config_hash", "")),
        seed=chosen,
        point=None,
        archs=arch_order(runs["arch"].unique()),
        notes=tuple(notes),
        nees=_nees_of(all_steps),
    )


def references_file(root: Path, point: str) -> str:
    """The references file of grid point ``point`` of a campaign (relative to ``root``).

    The file ``references/index.jsonl`` names for the point (shared by the
    points of one scenario and solver), else ``references/<point>.parquet``
    (one file per point, as earlier versions of cwrend wrote them). A torn
    or unparsable line of the index is skipped, and so is a line naming a
    file outside ``references/``; the last line of a point wins.
    """
    index = root / REFERENCES_INDEX
    named = references_path(point)
    if index.is_file():
        for line in index.read_text(encoding="utf-8").splitlines():
            try:
                entry = json.loads(line)
            except ValueError:
                continue
            if isinstance(entry, dict) and entry.get("point") == point and "file" in entry:
                file = Path(str(entry["file"]))
                if file.parent == Path(REFERENCES) and file.suffix == ".parquet":  # nothing else
                    named = file.as_posix()
    return named


def _campaign_references(root: Path, point: str | None, notes: list[str]) -> pd.DataFrame | None:
    """The stored open-loop references of grid point ``point`` (absent: ``None`` and a note)."""
    rel = references_file(root, str(point))
    if point is not None and (root / rel).exists():
        return _read_references(root / rel)
    notes.append(
        f"Open-loop references are not drawn: this campaign does not store them (no `{rel}`; "
        "campaigns written by older versions of cwrend lack them). Rerun the campaign to "
        "store them."
    )
    return None


def _load_campaign_dir(root: Path, seed: int | None, wanted: str | None = None) -> ReportData:
    runs = _read_parquet(root / RUNS)
    missing = {"arch", "seed", "status", "delta_v_km_s", "miss_km"} - set(runs.columns)
    if missing:
        raise ReportError(f"{root / RUNS}: missing columns {', '.join(sorted(missing))}")
    runs["arch"] = runs["arch"].astype(str)
    manifest = root / MANIFEST
    meta = read_manifest(manifest, REPAIR_HINT) if manifest.exists() else {}
    notes: list[str] = []
    config = _stored_config(meta.get("config"), manifest, notes)
    params = [c for c in param_columns(runs.columns) if runs[c].dropna().astype(str).nunique() > 1]
    point = None
    if wanted is not None:
        if "point" not in runs.columns:
            raise ReportError(f"--point {wanted}: {root / RUNS} has no point column")
        point = _chosen_point(runs, wanted)
        if runs["point"].nunique() <= 1:
            point = None  # a single point: as without --point
    elif "point" in runs.columns and runs["point"].nunique() > 1:
        point = _first_design_point(root, runs) or _reported_point(runs, config)
    selected = runs if point is None else runs[runs["point"].astype(str) == point]
    chosen = _pick_seed(selected, seed)
    sensitivity = _campaign_sensitivity(root)
    design = sensitivity is not None or _design_manifest(meta, runs)
    if point is not None:
        rest = (
            "the sensitivity indices use every design point"
            if design
            else "the sweep tables and figures use every point"
        )
        notes.append(
            f"Per-seed figures, the seed table and the distributions use "
            f"{'design' if design else 'grid'} point `{point}` ({point_values(selected)}); {rest}."
        )
    steps_dir = root / STEPS
    if not steps_dir.exists():
        raise ReportError(f"{root}: campaign without a steps/ dataset (was it run with steps off?)")
    filters: list[tuple[str, str, Any]] = [("seed", "==", chosen)]
    steps = _read_steps(steps_dir, filters=filters)
    if point is not None and "point" in steps.columns:
        steps = steps[steps["point"].astype(str) == point]
    if steps.empty:
        hint = (
            " (a design writes per-step data of its first output.design_steps_points "
            "point(s) only, in design.parquet's order)"
            if (root / DESIGN).exists()
            else ""
        )
        raise ReportError(f"{steps_dir}: no steps for seed {chosen}" + hint)
    steps["arch"] = steps["arch"].astype(str)
    ref_point = point
    if ref_point is None and "point" in selected.columns and not selected.empty:
        ref_point = str(selected["point"].iloc[0])
    references = _campaign_references(root, ref_point, notes)
    data = ReportData(
        layout="campaign",
        runs=runs,
        ref_summary=_reference_summary(None, None),
        steps=steps,
        references=references,
        config=config,
        config_hash=str(meta.get("config_hash", meta.get("campaign_hash", ""))),
        seed=chosen,
        point=point,
        archs=arch_order(runs["arch"].unique()),
        params=tuple(params),
        notes=tuple(notes),
        stats=_campaign_stats(root),
        nees=_campaign_nees(steps_dir, point),
        design=design,
        sensitivity=sensitivity,
        nis_offset_given=nis_offset_given(meta),
        xf_given=xf_given(meta),
    )
    # the references' miss against the reported point's terminal position
    return replace(data, ref_summary=_reference_summary(references, data.point_config))


def _first_design_point(root: Path, runs: pd.DataFrame) -> str | None:
    """A design's first point in design order with an ok run (``design.parquet``), if any.

    The point whose per-step data a design writes first (``output.design_steps_points``).
    """
    path = root / DESIGN
    if not path.is_file():
        return None
    ok = set(runs.loc[runs["status"] == "ok", "point"].astype(str))
    for point in _read_parquet(path)["point"].astype(str):
        if point in ok:
            return str(point)
    return None


def _design_manifest(meta: Mapping[str, Any], runs: pd.DataFrame) -> bool:
    """A sampled design by its manifest: ``grid`` recorded empty, swept values over points.

    (The manifest records no design kind; a grid campaign records its grid.)
    A manifest without ``grid`` (hand-made or older campaigns) says nothing.
    """
    grid = meta.get("grid")
    if not isinstance(grid, Mapping) or grid or "point" not in runs.columns:
        return False
    return bool(param_columns(runs.columns)) and runs["point"].nunique() > 1


def _campaign_sensitivity(root: Path) -> pd.DataFrame | None:
    """``sensitivity.parquet`` of a ``sobol`` design campaign (``None`` if not stored)."""
    path = root / SENSITIVITY
    if not path.exists():
        return None
    table = _read_parquet(path)
    missing = {"arch", "metric", "parameter", "statistic", "value", "ci_low", "ci_high"}
    missing -= set(table.columns)
    if missing:
        raise ReportError(f"{path}: missing columns {', '.join(sorted(missing))}")
    for column in ("arch", "metric", "parameter", "statistic"):
        table[column] = table[column].astype(str)
    return table


def _campaign_stats(root: Path) -> pd.DataFrame | None:
    """``ablation.parquet`` or ``sweep.parquet`` of a campaign (``None`` if neither)."""
    for name in (SWEEP_STATS, ABLATION_STATS):
        if (root / name).exists():
            stats = _read_parquet(root / name)
            missing = {"kind", "arch", "metric", "statistic", "value", "ci_low", "ci_high", "n"}
            missing -= set(stats.columns)
            if missing:
                raise ReportError(f"{root / name}: missing columns {', '.join(sorted(missing))}")
            stats["arch"] = stats["arch"].astype(str)
            return stats
    return None


def load_results(
    results_dir: Path, seed: int | None = None, point: str | None = None
) -> ReportData:
    """Load a run or campaign directory (raises :class:`ReportError` if it is neither).

    ``seed`` selects the noise realisation of the per-seed data (default: the
    first seed with a successful run); ``point`` the grid point of a campaign,
    by its id or its swept values (``beta=0.5``, ``schedule.beta=0.5, …`` or
    the values alone, comma-separated; default: the point at the base
    config's values, else the first). An unknown point raises
    :class:`ReportError` listing the points.
    """
    root = Path(results_dir)
    if not root.exists():
        raise ReportError(f"{root}: no such directory")
    if not root.is_dir():
        raise ReportError(f"{root}: not a directory")
    refuse_links(root, REPORTED, "the results directory")
    if (root / RUNS).exists():
        return _load_campaign_dir(root, seed, point)
    if (root / RUN_SUMMARY).exists():
        return _load_run_dir(root, seed, point)
    raise ReportError(
        f"{root}: no cwrend results here (expected summary.parquet from `cwrend run` "
        "or runs.parquet from a campaign)"
    )
