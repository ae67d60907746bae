"""``cwrend report``: the paper's figures and summary tables for a results directory.

Reads either layout that cwrend writes and never recomputes physics:

* a ``cwrend run`` directory: ``summary.parquet``, ``steps.parquet``,
  ``solves.parquet``, ``references.parquet``, ``config.json``;
* a campaign directory: ``runs.parquet`` (one row per run: ``run_key``,
  ``arch``, ``seed``, ``status``, the summary metrics, swept values as
  ``param.<key>``), the hive dataset ``steps/arch=<slug>/…`` (steps columns
  plus ``run_key``), ``references.parquet`` (optional ``point`` column) and
  ``manifest.json`` (``config`` = the resolved base config).

Writes into ``RESULTS_DIR/report/`` (each file atomically), with matplotlib's
Agg canvas and no pyplot state:

* per noise realisation (the first seed, or ``seed=``; in a sweep the first
  grid point): ``fig1_trajectories.png`` (3D and x–z views, open and closed
  loop), ``fig2_control.png`` (‖u‖ and cumulative Δv), ``fig3_eps_score.png``,
  ``fig4_nis_mtf.png``, ``fig5_errors.png`` (degradation windows shaded in
  3–5), ``fig6_dv_vs_miss.png`` (every run of the directory);
* with more than one seed per architecture: ``miss_distribution.png``,
  ``dv_distribution.png``, ``paired_miss.png`` (MTF vs plain, seed by seed);
* per swept parameter with more than one value: ``sweep_<key>.png``;
* ``report.md``: the tables and links to the figures.

Units: km, s, km/s, km/s² (as in the Parquet files).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FuncFormatter, NullFormatter
from pydantic import ValidationError

from cwrend_cli.config import ARCHITECTURES, DegradationWindow
from cwrend_cli.errors import CwrendError
from cwrend_cli.output.recording import (
    DEGRADATION_COLOUR,
    REFERENCE_COLOURS,
    arch_colour,
)
from cwrend_cli.output.tables import PARAM_PREFIX, atomic_path, param_columns
from cwrend_cli.physics.references import cumulative_delta_v

REPORT_DIR = "report"
_DPI = 120
_RC = {
    "font.size": 11,
    "axes.titlesize": 12,
    "axes.labelsize": 11,
    "legend.fontsize": 10,
    "xtick.labelsize": 10,
    "ytick.labelsize": 10,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "lines.linewidth": 1.4,
}
_MISS_FLOOR_KM = 1e-9  # misses below this are drawn at this value on log axes


class ReportError(CwrendError):
    """The results directory cannot be reported on (missing, incomplete or unreadable)."""


@dataclass(frozen=True)
class ReportSummary:
    """What :func:`write_report` wrote."""

    results_dir: Path
    out_dir: Path
    layout: str  # "run" or "campaign"
    seed: int  # noise realisation of the per-seed figures
    point: str | None  # grid point of the per-seed figures (campaigns)
    files: tuple[Path, ...]  # figures and report.md, in the order written
    notes: tuple[str, ...] = ()


@dataclass
class _Data:
    """Everything the figures need, loaded from one results directory."""

    layout: str
    runs: pd.DataFrame  # one row per closed-loop run: arch, seed, status, metrics, param.*
    ref_summary: pd.DataFrame  # arch ("open_loop_<name>"), delta_v_km_s, miss_km
    steps: pd.DataFrame  # steps of the selected seed (and point), all architectures
    references: pd.DataFrame | None  # reference trajectories (reference, t_s, x_km, …)
    windows: list[DegradationWindow]
    config: Mapping[str, Any]
    config_hash: str
    seed: int
    point: str | None
    archs: list[str]  # in canonical order
    params: list[str] = field(default_factory=list)  # swept param columns with > 1 value
    notes: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------


def _read_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ReportError(f"{path}: unreadable ({exc})") from None


def _read_parquet(path: Path, **kwargs: Any) -> pd.DataFrame:
    try:
        return pd.read_parquet(path, **kwargs)
    except (OSError, ValueError) as exc:
        raise ReportError(f"{path}: unreadable Parquet ({exc})") from None


def _order_archs(names: Sequence[str]) -> list[str]:
    known = [a for a in ARCHITECTURES if a in set(names)]
    return known + sorted(set(names) - set(known))


def _arch_label(slug: str) -> str:
    arch = ARCHITECTURES.get(slug)
    return arch.label if arch is not None else slug


def _arch_style(slug: str, archs: Sequence[str]) -> dict[str, Any]:
    """Line style of an architecture: its colour; MTF-fixed dashed over a thicker plain-fixed.

    The two fixed-ε architectures fly almost the same path, so the first is
    drawn thick and the second dashed on top: both stay visible.
    """
    index = archs.index(slug) if slug in archs else 0
    style: dict[str, Any] = {"color": arch_colour(slug, index), "lw": 1.6, "ls": "-"}
    if slug == "plain_fixed":
        style["lw"] = 2.8
    elif slug == "mtf_fixed":
        style.update(ls=(0, (4, 2.5)), lw=1.6)
    return style


def _group_label(slugs: Sequence[str]) -> str:
    """Legend label of architectures whose series coincide."""
    if len(slugs) == 1:
        return _arch_label(slugs[0])
    known = [ARCHITECTURES[s] for s in slugs if s in ARCHITECTURES]
    if len(known) == len(slugs):
        if len({a.mtf for a in known}) == 1:
            kf = "MTF KF" if known[0].mtf else "plain KF"
            return f"{kf}, fixed and adaptive ε (identical)"
        if len({a.adaptive for a in known}) == 1:
            return f"plain and MTF KF, {'adaptive' if known[0].adaptive else 'fixed'} ε (identical)"
    return " = ".join(_arch_label(s) for s in slugs)


def _windows(config: Mapping[str, Any]) -> list[DegradationWindow]:
    """The degradation windows of a saved config (ones that no longer validate are skipped)."""
    raw = (config.get("degradation") or {}).get("windows") or []
    out = []
    for w in raw:
        try:
            out.append(DegradationWindow.model_validate(w))
        except ValidationError:
            continue
    return out


def _reference_summary(references: pd.DataFrame | None) -> pd.DataFrame:
    """Δv (trapezoid of ‖u‖) and final distance of each reference trajectory."""
    rows = []
    if references is not None:
        for name, g in references.groupby("reference", sort=False, observed=True):
            g = g.sort_values("t_s")
            last = g.iloc[-1]
            rows.append(
                {
                    "arch": f"open_loop_{name}",
                    "seed": -1,
                    "delta_v_km_s": float(cumulative_delta_v(g["t_s"], g["u_norm_km_s2"])[-1]),
                    "miss_km": float(np.linalg.norm([last["x_km"], last["y_km"], last["z_km"]])),
                }
            )
    out = pd.DataFrame(rows, columns=["arch", "seed", "delta_v_km_s", "miss_km"])
    fuel = out.loc[out["arch"] == "open_loop_fuel", "delta_v_km_s"]
    if not fuel.empty:
        out["fuel_penalty_pct"] = 100.0 * (out["delta_v_km_s"] / float(fuel.iloc[0]) - 1.0)
    return out


def _param_value(value: Any) -> Any:
    """A ``param.<key>`` cell as the value that was applied (JSON text for mixed kinds)."""
    if isinstance(value, str):
        try:
            return json.loads(value)
        except json.JSONDecodeError:
            return value
    if isinstance(value, np.generic):
        return value.item()
    return value


def _computed_references(
    config: Mapping[str, Any], runs: pd.DataFrame, notes: list[str]
) -> pd.DataFrame | None:
    """Open-loop references of the reported grid point, from the manifest's config.

    The campaign layout stores no reference trajectories; they are deterministic
    functions of the scenario and solver settings, so they are recomputed here
    (about 0.1–0.3 s) with the grid values of the point applied.
    """
    from cwrend_cli import campaign
    from cwrend_cli.config import config_from_dict
    from cwrend_cli.output import tables as storage
    from cwrend_cli.physics import simulation

    row = runs.iloc[0]
    assignment = tuple(
        (c.removeprefix(PARAM_PREFIX), _param_value(row[c]))
        for c in param_columns(runs.columns)
        if pd.notna(row[c])
    )
    try:
        cfg = config_from_dict(campaign.apply(config, assignment))
    except Exception:  # grid values that do not round-trip: fall back to the base config
        try:
            cfg = config_from_dict(config)
            notes.append("Open-loop references computed for the base config (not the point).")
        except Exception as exc:
            notes.append(f"Open-loop references not drawn (config unusable: {exc}).")
            return None
    try:
        refs = simulation.open_loop_references(cfg)
    except CwrendError as exc:
        notes.append(f"Open-loop references not drawn ({exc}).")
        return None
    return storage.references_table(refs).to_pandas()


def _same_value(a: Any, b: Any) -> bool:
    try:
        return bool(np.isclose(float(a), float(b), rtol=1e-12, atol=0.0))
    except (TypeError, ValueError):
        return str(a) == str(b)


def _reported_point(runs: pd.DataFrame, config: Mapping[str, Any]) -> str | None:
    """The grid point of the per-seed figures: the one at the base config's values, else the first.

    Points are tried in sorted order; only points with a successful run qualify.
    """
    from cwrend_cli.campaign import get_dotted

    ok = runs[runs["status"] == "ok"]
    if ok.empty:
        return None
    params = param_columns(runs.columns)
    points = sorted(ok["point"].astype(str).unique())
    for point in points:
        row = ok[ok["point"].astype(str) == point].iloc[0]
        try:
            base = [get_dotted(config, c.removeprefix(PARAM_PREFIX)) for c in params]
        except (KeyError, IndexError, TypeError, ValueError):
            break
        values = [_param_value(row[c]) for c in params]
        if all(_same_value(v, b) for v, b in zip(values, base, strict=True)):
            return point
    return points[0]


def _point_values(runs: pd.DataFrame) -> str:
    """``key=value, …`` of the swept parameters of one point's runs."""
    if runs.empty:
        return ""
    row = runs.iloc[0]
    cols = param_columns(runs.columns)
    return ", ".join(f"{c.removeprefix(PARAM_PREFIX)}={_param_value(row[c])}" for c in cols)


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


def _load_run_dir(root: Path, seed: int | None) -> _Data:
    for name in ("summary.parquet", "steps.parquet", "config.json"):
        if not (root / name).exists():
            raise ReportError(f"{root}: not a complete cwrend results directory (no {name})")
    meta = _read_json(root / "config.json")
    summary = _read_parquet(root / "summary.parquet")
    is_ref = summary["arch"].astype(str).str.startswith("open_loop_")
    runs = summary[~is_ref].copy()
    runs["arch"] = runs["arch"].astype(str)
    runs["status"] = "ok"
    chosen = _pick_seed(runs, seed)
    steps = _read_parquet(root / "steps.parquet")
    steps = steps[steps["seed"] == chosen].copy()
    references = (
        _read_parquet(root / "references.parquet")
        if (root / "references.parquet").exists()
        else None
    )
    config = meta.get("config") or {}
    return _Data(
        layout="run",
        runs=runs,
        ref_summary=summary[is_ref].copy(),
        steps=steps,
        references=references,
        windows=_windows(config),
        config=config,
        config_hash=str(meta.get("config_hash", "")),
        seed=chosen,
        point=None,
        archs=_order_archs(runs["arch"].unique()),
    )


def _load_campaign_dir(root: Path, seed: int | None) -> _Data:
    runs = _read_parquet(root / "runs.parquet")
    missing = {"arch", "seed", "status", "delta_v_km_s", "miss_km"} - set(runs.columns)
    if missing:
        raise ReportError(f"{root / 'runs.parquet'}: missing columns {', '.join(sorted(missing))}")
    runs["arch"] = runs["arch"].astype(str)
    meta = _read_json(root / "manifest.json") if (root / "manifest.json").exists() else {}
    config = meta.get("config") or {}
    notes: list[str] = []
    params = [c for c in param_columns(runs.columns) if runs[c].dropna().astype(str).nunique() > 1]
    point = None
    if "point" in runs.columns and runs["point"].nunique() > 1:
        point = _reported_point(runs, config)
    selected = runs if point is None else runs[runs["point"].astype(str) == point]
    chosen = _pick_seed(selected, seed)
    if point is not None:
        notes.append(
            f"Per-seed figures, the seed table and the distributions use grid point `{point}` "
            f"({_point_values(selected)}); the sweep tables and figures use every point."
        )
    steps_dir = root / "steps"
    if not steps_dir.exists():
        raise ReportError(f"{root}: campaign without a steps/ dataset (was it run with steps off?)")
    filters: list[tuple[str, str, Any]] = [("seed", "==", chosen)]
    steps = _read_parquet(steps_dir, filters=filters)
    if point is not None and "point" in steps.columns:
        steps = steps[steps["point"].astype(str) == point]
    if steps.empty:
        raise ReportError(f"{steps_dir}: no steps for seed {chosen}")
    steps["arch"] = steps["arch"].astype(str)
    references = None
    if (root / "references.parquet").exists():
        references = _read_parquet(root / "references.parquet")
        if "point" in references.columns and references["point"].nunique() > 1:
            want = point if point is not None else references["point"].astype(str).iloc[0]
            references = references[references["point"].astype(str) == want]
    elif config:
        references = _computed_references(config, selected, notes)
    else:
        notes.append("No references.parquet and no config: open-loop references are not drawn.")
    return _Data(
        layout="campaign",
        runs=runs,
        ref_summary=_reference_summary(references),
        steps=steps,
        references=references,
        windows=_windows(config),
        config=config,
        config_hash=str(meta.get("config_hash", meta.get("campaign_hash", ""))),
        seed=chosen,
        point=point,
        archs=_order_archs(runs["arch"].unique()),
        params=params,
        notes=notes,
    )


def load_results(results_dir: Path, seed: int | None = None) -> _Data:
    """Load a run or campaign directory (raises :class:`ReportError` if it is neither)."""
    root = Path(results_dir)
    if not root.exists():
        raise ReportError(f"{root}: no such directory")
    if not root.is_dir():
        raise ReportError(f"{root}: not a directory")
    if (root / "runs.parquet").exists():
        return _load_campaign_dir(root, seed)
    if (root / "summary.parquet").exists():
        return _load_run_dir(root, seed)
    raise ReportError(
        f"{root}: no cwrend results here (expected summary.parquet from `cwrend run` "
        "or runs.parquet from a campaign)"
    )


# ---------------------------------------------------------------------------
# Figure helpers
# ---------------------------------------------------------------------------


def _tidy_log_axes(fig: Figure) -> None:
    """Readable log axes: minor labels at 2 and 5 over 1–2.5 decades, none beyond."""
    for ax in fig.axes:
        for axis, scale, lim in (
            (ax.xaxis, ax.get_xscale(), ax.get_xlim()),
            (ax.yaxis, ax.get_yscale(), ax.get_ylim()),
        ):
            lo, hi = sorted(lim)
            if scale != "log" or lo <= 0:
                continue
            decades = np.log10(hi / lo)
            if decades > 2.5:
                axis.set_minor_formatter(NullFormatter())
            elif decades > 1.0:  # otherwise a single labelled tick may be all there is
                axis.set_minor_formatter(FuncFormatter(_minor_log_label))


def _minor_log_label(value: float, _pos: int) -> str:
    """``2×10⁻³`` and ``5×10⁻³`` styled like the major labels; other minor ticks unlabelled."""
    exponent = int(np.floor(np.log10(value)))
    mantissa = round(value / 10.0**exponent)
    return rf"${mantissa}\times10^{{{exponent}}}$" if mantissa in (2, 5) else ""


def _save(fig: Figure, path: Path) -> Path:
    _tidy_log_axes(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=_DPI, format="png")
    return path


def _figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    return fig


def _shade(ax: Axes, windows: Sequence[DegradationWindow]) -> None:
    alphas = (0.18, 0.32, 0.25, 0.4)
    for i, w in enumerate(windows):
        ax.axvspan(w.start_s, w.end_s, color=DEGRADATION_COLOUR, alpha=alphas[i % 4], lw=0)


def _window_handles(windows: Sequence[DegradationWindow]) -> list[Patch]:
    alphas = (0.18, 0.32, 0.25, 0.4)
    return [
        Patch(
            color=DEGRADATION_COLOUR,
            alpha=alphas[i % 4],
            label=f"degradation {i + 1}: {w.label}",
        )
        for i, w in enumerate(windows)
    ]


def _by_arch(steps: pd.DataFrame, archs: Sequence[str]) -> Iterator[tuple[str, pd.DataFrame]]:
    for a in archs:
        g = steps[steps["arch"] == a]
        if not g.empty:
            yield a, g.sort_values("t_s")


def _groups(
    steps: pd.DataFrame, archs: Sequence[str], columns: Sequence[str]
) -> list[tuple[list[str], pd.DataFrame]]:
    """Architectures grouped by identical ``columns`` (e.g. the NIS of one estimator).

    The innovation of a linear KF does not depend on the control, so the NIS,
    MTF ratio, score and estimation error of the fixed and the adaptive
    architecture with the same estimator coincide; they are drawn once.
    """
    out: list[tuple[list[str], pd.DataFrame]] = []
    for a, g in _by_arch(steps, archs):
        values = g[list(columns)].to_numpy(dtype=float)
        for members, first in out:
            ref = first[list(columns)].to_numpy(dtype=float)
            if ref.shape != values.shape:
                continue
            finite = np.abs(ref[np.isfinite(ref)])
            atol = 1e-9 * (finite.max() if finite.size else 0.0)
            if np.allclose(ref, values, rtol=1e-9, atol=atol, equal_nan=True):
                members.append(a)
                break
        else:
            out.append(([a], g))
    return out


def _group_colour(members: Sequence[str], archs: Sequence[str]) -> str:
    last = members[-1]
    return arch_colour(last, archs.index(last) if last in archs else 0)


def _refs(data: _Data) -> Iterator[tuple[str, pd.DataFrame]]:
    if data.references is None:
        return
    for name in ("energy", "fuel"):
        g = data.references[data.references["reference"].astype(str) == name]
        if not g.empty:
            yield name, g.sort_values("t_s")


def _ref_style(name: str) -> dict[str, Any]:
    return {
        "color": REFERENCE_COLOURS.get(name, "#7f7f7f"),
        "ls": "--" if name == "energy" else ":",
        "lw": 1.6,
        "label": f"open-loop {name}-optimal",
    }


def _title(data: _Data) -> str:
    where = f", point {data.point}" if data.point else ""
    return f"noise seed {data.seed}{where}"


def _legend_below(fig: Figure, handles: Sequence[Any], ncol: int = 4) -> None:
    fig.legend(
        handles=list(handles),
        loc="outside lower center",
        ncol=min(ncol, max(1, len(handles))),
        frameon=False,
    )


def _arch_handles(archs: Sequence[str]) -> list[Line2D]:
    return [Line2D([], [], **_arch_style(a, archs), label=_arch_label(a)) for a in archs]


def _group_handles(groups: Sequence[tuple[list[str], pd.DataFrame]], archs: Sequence[str],
                   **style: Any) -> list[Line2D]:  # fmt: skip
    return [
        Line2D([], [], color=_group_colour(m, archs), lw=2, label=_group_label(m), **style)
        for m, _ in groups
    ]


def _arch_handles_plain(archs: Sequence[str]) -> list[Line2D]:
    """Colour-only handles (the line style carries another meaning)."""
    return [
        Line2D([], [], color=arch_colour(a, archs.index(a)), lw=2.5, label=_arch_label(a))
        for a in archs
    ]


def _ref_handles(data: _Data) -> list[Line2D]:
    return [Line2D([], [], **_ref_style(name)) for name, _ in _refs(data)]


# ---------------------------------------------------------------------------
# Per-seed figures (paper Figs 1–6)
# ---------------------------------------------------------------------------


def fig_trajectories(data: _Data, path: Path) -> Path:
    """Fig. 1: 3D and x–z views of the true trajectories, open and closed loop."""
    fig = _figure(13.5, 6.4)
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    for name, g in _refs(data):
        st = _ref_style(name)
        ax3.plot(g["x_km"], g["y_km"], g["z_km"], **st)
        ax2.plot(g["x_km"], g["z_km"], **st)
    for a, g in _by_arch(data.steps, data.archs):
        st = _arch_style(a, data.archs)
        ax3.plot(g["x_km"], g["y_km"], g["z_km"], **st)
        ax2.plot(g["x_km"], g["z_km"], **st)
    first = data.steps.sort_values("t_s").iloc[0] if not data.steps.empty else None
    for ax_ in (ax3, ax2):
        pts = (0.0, 0.0, 0.0) if ax_ is ax3 else (0.0, 0.0)
        ax_.scatter(*pts, marker="*", s=180, color="black", zorder=5)
        if first is not None:
            start = (first["x_km"], first["y_km"], first["z_km"])
            ax_.scatter(*(start if ax_ is ax3 else (start[0], start[2])), marker="o", s=50,
                        facecolor="white", edgecolor="black", zorder=5)  # fmt: skip
    ax3.set_xlabel("x (radial) [km]", labelpad=8)
    ax3.set_ylabel("y (along-track) [km]", labelpad=8)
    ax3.set_zlabel("z (cross-track) [km]", labelpad=8)
    ax3.set_title("3D relative trajectories (CW frame)")
    ax3.view_init(elev=22, azim=-58)
    ax2.set_xlabel("x (radial) [km]")
    ax2.set_ylabel("z (cross-track) [km]")
    ax2.set_title("x–z view")
    markers = [
        Line2D([], [], marker="*", ls="", ms=12, color="black", label="target (origin)"),
        Line2D([], [], marker="o", ls="", ms=7, mfc="white", mec="black", label="start x₀"),
    ]
    _legend_below(fig, _arch_handles(data.archs) + _ref_handles(data) + markers, ncol=4)
    fig.suptitle(f"Fig. 1 · Trajectories, open and closed loop ({_title(data)})")
    return _save(fig, path)


def fig_control(data: _Data, path: Path) -> Path:
    """Fig. 2: thrust magnitude history and cumulative Δv."""
    archs = [a for a, _ in _by_arch(data.steps, data.archs)]
    n = len(archs)
    fig = _figure(13, 3.0 + 1.45 * n)
    grid = fig.add_gridspec(n, 2, width_ratios=[1.5, 1])
    ax_dv = fig.add_subplot(grid[:, 1])
    u_max = float((data.config.get("scenario") or {}).get("u_max_km_s2", np.nan))
    share = None
    for i, (a, g) in enumerate(_by_arch(data.steps, data.archs)):
        ax = fig.add_subplot(grid[i, 0], sharex=share, sharey=share)
        share = share or ax
        c = arch_colour(a, data.archs.index(a))
        for name, r in _refs(data):
            if name == "fuel":
                ax.plot(r["t_s"], 1e3 * r["u_norm_km_s2"], **{**_ref_style(name), "lw": 1.2})
        ax.plot(g["t_s"], 1e3 * g["u_norm_km_s2"], color=c, lw=1.3, drawstyle="steps-post")
        _shade(ax, data.windows)
        ax.set_title(_arch_label(a), fontsize=10.5, loc="left", pad=3)
        ax.set_ylabel("‖u‖ [m/s²]")
        if np.isfinite(u_max):
            ax.set_ylim(-0.05 * 1e3 * u_max, 1.12 * 1e3 * u_max)
        if i < n - 1:
            ax.tick_params(labelbottom=False)
        else:
            ax.set_xlabel("time [s]")
        ax_dv.plot(
            g["t_s"], cumulative_delta_v(g["t_s"], g["u_norm_km_s2"]), **_arch_style(a, data.archs)
        )
    for name, r in _refs(data):
        ax_dv.plot(r["t_s"], cumulative_delta_v(r["t_s"], r["u_norm_km_s2"]), **_ref_style(name))
    _shade(ax_dv, data.windows)
    ax_dv.set_xlabel("time [s]")
    ax_dv.set_ylabel("cumulative Δv [km/s]")
    ax_dv.set_title("cumulative Δv")
    handles = _arch_handles(archs) + _ref_handles(data) + _window_handles(data.windows)
    _legend_below(fig, handles, ncol=4)
    fig.suptitle(f"Fig. 2 · Thrust magnitude and cumulative Δv ({_title(data)})")
    return _save(fig, path)


def fig_eps_score(data: _Data, path: Path) -> Path:
    """Fig. 3: homotopy parameter ε and composite score (instantaneous and filtered)."""
    fig = _figure(15, 7.8)
    ax_e, ax_s = fig.subplots(2, 1, sharex=True)
    eps_groups = _groups(data.steps, data.archs, ["eps"])
    for members, g in eps_groups:
        ax_e.plot(g["t_s"], g["eps"], color=_group_colour(members, data.archs), lw=1.8)
    score_groups = _groups(data.steps, data.archs, ["score", "score_filtered"])
    for members, g in score_groups:
        c = _group_colour(members, data.archs)
        ax_s.plot(g["t_s"], g["score"], color=c, lw=0.7, alpha=0.4)
        ax_s.plot(g["t_s"], g["score_filtered"], color=c, lw=1.8)
    for ax in (ax_e, ax_s):
        _shade(ax, data.windows)
    ax_e.set_ylabel("ε [-]")
    ax_e.set_ylim(-0.05, 1.08)
    ax_e.set_title("homotopy parameter ε (0 = bang-bang, 1 = smooth)")
    ax_e.legend(handles=_group_handles(eps_groups, data.archs), loc="center left",
                bbox_to_anchor=(1.01, 0.5), frameon=False)  # fmt: skip
    ax_s.set_ylabel("score [-]")
    ax_s.set_xlabel("time [s]")
    ax_s.set_title("composite innovation score: instantaneous s (thin) and filtered s̄ (thick)")
    ax_s.legend(handles=_group_handles(score_groups, data.archs), loc="center left",
                bbox_to_anchor=(1.01, 0.5), frameon=False)  # fmt: skip
    _legend_below(fig, _window_handles(data.windows), ncol=2)
    fig.suptitle(f"Fig. 3 · Adaptation: ε and score ({_title(data)})")
    return _save(fig, path)


def fig_nis_mtf(data: _Data, path: Path) -> Path:
    """Fig. 4: NIS and MTF ratio, degradation windows shaded; close-up of the windows."""
    fig = _figure(14, 7.8)
    axes = fig.subplots(2, 2, width_ratios=[1.6, 1])
    m = float((data.config.get("schedule") or {}).get("nis_offset", 3.0))
    lo = min((w.start_s for w in data.windows), default=None)
    hi = max((w.end_s for w in data.windows), default=None)
    nis_groups = _groups(data.steps, data.archs, ["nis"])
    mtf_groups = [
        (members, g)
        for members, g in _groups(data.steps, data.archs, ["mtf_ratio"])
        if g["mtf_ratio"].fillna(0.0).abs().max() > 0
    ]
    for col in range(2):
        ax_n, ax_r = axes[0, col], axes[1, col]
        for members, g in nis_groups:
            ax_n.plot(g["t_s"], g["nis"], color=_group_colour(members, data.archs), lw=1.0)
        for members, g in mtf_groups:
            ax_r.plot(g["t_s"], g["mtf_ratio"], color=_group_colour(members, data.archs), lw=1.0)
        ax_n.axhline(m, color="black", lw=1.0, ls=":")
        for ax in (ax_n, ax_r):
            _shade(ax, data.windows)
        ax_n.set_yscale("log")
        ax_r.set_yscale("symlog", linthresh=1.0)
        ax_r.set_ylim(bottom=0.0)
        ax_n.set_ylabel("NIS [-]")
        ax_r.set_ylabel("MTF ratio ρ [-]")
        ax_r.set_xlabel("time [s]")
        if col == 1 and lo is not None and hi is not None:
            span = hi - lo
            for ax in (ax_n, ax_r):
                ax.set_xlim(lo - 0.3 * span, hi + 0.3 * span)
            ax_n.set_title("close-up: degradation and recovery")
            ax_r.set_title("close-up: degradation and recovery")
        elif col == 0:
            ax_n.set_title("normalised innovation squared (dotted: offset m)")
            ax_r.set_title("MTF ratio tr(S_MTF)/tr(S), linear below 1, log above")
    offset = Line2D([], [], color="black", ls=":", label=f"m = {m:g} (NIS offset of the score)")
    handles = [*_group_handles(nis_groups, data.archs), offset]
    _legend_below(fig, handles + _window_handles(data.windows), ncol=3)
    fig.suptitle(f"Fig. 4 · Scheduler inputs: NIS and MTF ratio ({_title(data)})")
    return _save(fig, path)


def fig_errors(data: _Data, path: Path) -> Path:
    """Fig. 5: position error to the target and estimation error (log y), terminal close-up."""
    fig = _figure(14, 8.2)
    axes = fig.subplots(2, 2, width_ratios=[1.6, 1])
    horizon = float(data.steps["t_s"].max()) if not data.steps.empty else 1.0
    zoom = max(0.0, horizon - 0.1 * horizon)
    for a, g in _by_arch(data.steps, data.archs):
        st = _arch_style(a, data.archs)
        for col in range(2):
            axes[0, col].plot(g["t_s"], g["pos_err_km"], **st)
    est_groups = _groups(data.steps, data.archs, ["est_err_km"])
    for members, g in est_groups:
        g = g[g["est_err_km"] > 0]
        for col in range(2):
            axes[1, col].plot(g["t_s"], g["est_err_km"], color=_group_colour(members, data.archs),
                              lw=1.1)  # fmt: skip
    for name, r in _refs(data):
        dist = np.linalg.norm(r[["x_km", "y_km", "z_km"]].to_numpy(), axis=1)
        for col in range(2):
            axes[0, col].plot(r["t_s"], dist, **_ref_style(name))
    for ax in axes.ravel():
        _shade(ax, data.windows)
        ax.set_yscale("log")
    closed = data.steps["pos_err_km"].to_numpy(dtype=float)
    closed = closed[closed > 0]
    if closed.size:  # the references end at ~1e-13 km: do not let them set the scale
        axes[0, 0].set_ylim(0.3 * closed.min(), 3.0 * closed.max())
    terminal = data.steps[data.steps["t_s"] >= zoom]
    for row, column in ((0, "pos_err_km"), (1, "est_err_km")):
        vals = terminal[column].to_numpy(dtype=float)
        vals = vals[vals > 0]
        if vals.size:
            axes[row, 1].set_ylim(0.5 * vals.min(), 2.0 * vals.max())
        axes[row, 1].set_xlim(zoom, horizon)
        axes[row, 1].set_title(f"close-up: last {horizon - zoom:g} s")
    axes[0, 0].set_title("position error to the target ‖r‖")
    axes[1, 0].set_title("estimation error ‖r̂ − r‖")
    axes[1, 0].legend(handles=_group_handles(est_groups, data.archs), loc="lower right",
                      framealpha=0.9)  # fmt: skip
    for ax in axes[:, 0]:
        ax.set_ylabel("[km]")
    for ax in axes[1, :]:
        ax.set_xlabel("time [s]")
    handles = _arch_handles(data.archs) + _ref_handles(data) + _window_handles(data.windows)
    _legend_below(fig, handles, ncol=4)
    fig.suptitle(f"Fig. 5 · Position and estimation errors ({_title(data)})")
    return _save(fig, path)


def _ok_runs(data: _Data) -> pd.DataFrame:
    runs = data.runs[data.runs["status"] == "ok"]
    if data.point is not None and "point" in runs.columns:
        runs = runs[runs["point"].astype(str) == data.point]
    return runs


def fig_dv_vs_miss(data: _Data, path: Path) -> Path:
    """Fig. 6: Δv against terminal miss, every run (log miss), references as vertical lines."""
    fig = _figure(13, 6.8)
    ax = fig.subplots()
    runs = _ok_runs(data)
    multi = runs.groupby("arch")["seed"].nunique().max() > 1 if not runs.empty else False
    for a in data.archs:
        g = runs[runs["arch"] == a]
        if g.empty:
            continue
        c = arch_colour(a, data.archs.index(a))
        miss = np.maximum(g["miss_km"].to_numpy(dtype=float), _MISS_FLOOR_KM)
        ax.scatter(g["delta_v_km_s"], miss, color=c, s=22 if multi else 90,
                   alpha=0.45 if multi else 0.95, edgecolor="none" if multi else "black",
                   label=_arch_label(a))  # fmt: skip
        if multi:
            ax.scatter(g["delta_v_km_s"].median(), np.median(miss), color=c, s=160, marker="D",
                       edgecolor="black", zorder=5)  # fmt: skip
    for _, row in data.ref_summary.iterrows():
        name = str(row["arch"]).removeprefix("open_loop_")
        st = _ref_style(name)
        ax.axvline(float(row["delta_v_km_s"]), color=st["color"], ls=st["ls"], lw=1.6,
                   label=f"{st['label']} Δv = {row['delta_v_km_s']:.4g} km/s")  # fmt: skip
    ax.set_yscale("log")
    ax.set_xlabel("Δv [km/s]")
    ax.set_ylabel("terminal miss ‖r(T)‖ [km]")
    what = f"{len(runs)} runs; diamonds: per-architecture median" if multi else f"{_title(data)}"
    ax.set_title(f"Fig. 6 · Fuel against accuracy ({what})")
    handles = [
        Line2D([], [], marker="o", ls="", ms=9, color=arch_colour(a, data.archs.index(a)),
               mec="black", label=_arch_label(a))
        for a in data.archs
        if (runs["arch"] == a).any()
    ] + [h for h in ax.get_legend_handles_labels()[0] if isinstance(h, Line2D)]  # fmt: skip
    if multi:
        handles.append(Line2D([], [], marker="D", ls="", ms=9, color="white", mec="black",
                              label="median of the seeds"))  # fmt: skip
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    return _save(fig, path)


# ---------------------------------------------------------------------------
# Campaign figures
# ---------------------------------------------------------------------------


def _distribution(data: _Data, path: Path, column: str, ylabel: str, log: bool, title: str):
    runs = _ok_runs(data)
    archs = [a for a in data.archs if (runs["arch"] == a).any()]
    fig = _figure(max(8.0, 2.3 * len(archs) + 3), 6.2)
    ax = fig.subplots()
    values = []
    for a in archs:
        v = runs.loc[runs["arch"] == a, column].to_numpy(dtype=float)
        v = v[np.isfinite(v)]
        values.append(np.maximum(v, _MISS_FLOOR_KM) if log else v)
    positions = np.arange(1, len(archs) + 1)
    violin = all(v.size >= 10 for v in values)  # a violin of a handful of runs misleads
    if violin:
        parts = ax.violinplot(values, positions, widths=0.8, showextrema=False)
        for body, a in zip(parts["bodies"], archs, strict=True):
            body.set_facecolor(arch_colour(a, data.archs.index(a)))
            body.set_alpha(0.25)
    ax.boxplot(values, positions=positions, widths=0.25, showfliers=False,
               medianprops={"color": "black", "lw": 2})  # fmt: skip
    rng = np.random.default_rng(0)
    for pos, a, v in zip(positions, archs, values, strict=True):
        jitter = rng.uniform(-0.12, 0.12, v.size)
        ax.scatter(pos + jitter, v, s=12, color=arch_colour(a, data.archs.index(a)), alpha=0.7,
                   edgecolor="none", zorder=3)  # fmt: skip
    if column == "delta_v_km_s":
        for _, row in data.ref_summary.iterrows():
            name = str(row["arch"]).removeprefix("open_loop_")
            st = _ref_style(name)
            ax.axhline(float(row["delta_v_km_s"]), color=st["color"], ls=st["ls"], lw=1.6,
                       label=f"{st['label']} ({row['delta_v_km_s']:.4g} km/s)")  # fmt: skip
        if len(data.ref_summary):
            ax.legend(loc="best")
    if log:
        ax.set_yscale("log")
    ax.set_xticks(positions, [_arch_label(a) for a in archs])
    ax.set_ylabel(ylabel)
    n_seeds = runs["seed"].nunique()
    shape = "violin, " if violin else ""
    ax.set_title(f"{title} over {n_seeds} noise seeds ({shape}box = quartiles, dots = runs)")
    return _save(fig, path)


_PAIRS = (
    ("plain_adaptive", "mtf_adaptive"),
    ("plain_fixed", "mtf_fixed"),
    ("mtf_fixed", "mtf_adaptive"),
)


def fig_paired_miss(data: _Data, path: Path) -> Path | None:
    """Seed-by-seed miss of paired architectures (MTF vs plain; adaptive vs fixed)."""
    runs = _ok_runs(data)
    pivot = runs.pivot_table(index="seed", columns="arch", values="miss_km", aggfunc="first")
    pairs = [p for p in _PAIRS if p[0] in pivot.columns and p[1] in pivot.columns]
    if not pairs:
        return None
    fig = _figure(5.4 * len(pairs) + 0.8, 6.4)
    axes = np.atleast_1d(fig.subplots(1, len(pairs)))
    for ax, (xa, ya) in zip(axes, pairs, strict=True):
        both = pivot[[xa, ya]].dropna()
        x = np.maximum(both[xa].to_numpy(dtype=float), _MISS_FLOOR_KM)
        y = np.maximum(both[ya].to_numpy(dtype=float), _MISS_FLOOR_KM)
        ax.scatter(x, y, s=30, color=arch_colour(ya, data.archs.index(ya)), edgecolor="black",
                   lw=0.4, alpha=0.85)  # fmt: skip
        if x.size:
            lo = min(x.min(), y.min()) / 1.5
            hi = max(x.max(), y.max()) * 1.5
            ax.plot([lo, hi], [lo, hi], color="black", lw=1, ls="--", label="y = x")
            ax.set_xlim(lo, hi)
            ax.set_ylim(lo, hi)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_box_aspect(1)
        ax.set_xlabel(f"miss, {_arch_label(xa)} [km]")
        ax.set_ylabel(f"miss, {_arch_label(ya)} [km]")
        better = int((y < x).sum())
        ax.set_title(f"{_arch_label(ya)} smaller\nin {better} of {x.size} seeds", fontsize=11)
        ax.legend(loc="upper left")
    title = "Paired miss per noise seed (below the diagonal: y-axis architecture is better)"
    fig.suptitle(title if len(pairs) > 1 else title.replace(" (", "\n("))
    return _save(fig, path)


def _param_values(series: pd.Series) -> tuple[np.ndarray, bool]:
    numeric = pd.to_numeric(series, errors="coerce")
    if numeric.notna().all():
        return numeric.to_numpy(dtype=float), True
    return series.astype(str).to_numpy(), False


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "param"


def _others_label(runs: pd.DataFrame, others: Sequence[str]) -> pd.Series:
    if not others:
        return pd.Series("", index=runs.index)
    return runs[list(others)].apply(
        lambda r: ", ".join(f"{k.removeprefix('param.')}={_param_value(v)}" for k, v in r.items()),
        axis=1,
    )


_COMBO_STYLES = (("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"))


def fig_sweep(data: _Data, param: str, path: Path) -> Path:
    """Median miss (quartile band) and mean Δv against one swept parameter, per architecture.

    With other swept parameters, each of their combinations (up to four) gets
    its own line style; with more, the runs are pooled over them (stated in
    the title).
    """
    runs = data.runs[data.runs["status"] == "ok"].copy()
    key = param.removeprefix(PARAM_PREFIX)
    x_all, numeric = _param_values(runs[param])
    runs["_x"] = x_all
    levels = np.sort(np.unique(x_all)) if numeric else sorted(set(x_all))
    pos = {v: i for i, v in enumerate(levels)}
    others = [p for p in data.params if p != param]
    runs["_other"] = _others_label(runs, others)
    combos = sorted(runs["_other"].unique())
    pooled = len(combos) > len(_COMBO_STYLES)
    if pooled:
        runs["_other"] = ""
        combos = [""]
    fig = _figure(13, 6.6)
    ax_m, ax_v = fig.subplots(1, 2)
    floor = _MISS_FLOOR_KM
    for a in data.archs:
        c = arch_colour(a, data.archs.index(a))
        for (ls, marker), combo in zip(_COMBO_STYLES, combos, strict=False):
            g = runs[(runs["arch"] == a) & (runs["_other"] == combo)]
            if g.empty:
                continue
            stats = g.groupby("_x").agg(
                med=("miss_km", "median"),
                q1=("miss_km", lambda v: v.quantile(0.25)),
                q3=("miss_km", lambda v: v.quantile(0.75)),
                dv=("delta_v_km_s", "mean"),
            )
            xs = stats.index.to_numpy() if numeric else np.array([pos[v] for v in stats.index])
            order = np.argsort(xs)
            xs, st = xs[order], stats.iloc[order]
            ax_m.plot(xs, np.maximum(st["med"], floor), ls=ls, marker=marker, color=c)
            if len(combos) == 1:
                ax_m.fill_between(xs, np.maximum(st["q1"], floor), np.maximum(st["q3"], floor),
                                  color=c, alpha=0.12, lw=0)  # fmt: skip
            ax_v.plot(xs, st["dv"], ls=ls, marker=marker, color=c)
    for _, row in data.ref_summary.iterrows():
        name = str(row["arch"]).removeprefix("open_loop_")
        st_ = _ref_style(name)
        ax_v.axhline(float(row["delta_v_km_s"]), color=st_["color"], ls=st_["ls"], lw=1.4)
    ax_m.set_yscale("log")
    for ax in (ax_m, ax_v):
        ax.set_xlabel(key)
        if not numeric:
            ax.set_xticks(range(len(levels)), [str(v) for v in levels])
    ax_m.set_ylabel("terminal miss [km]")
    band = " (band: quartiles over seeds)" if len(combos) == 1 else ""
    ax_m.set_title(f"median miss{band}")
    ax_v.set_ylabel("mean Δv [km/s]")
    ax_v.set_title("mean Δv over seeds")
    handles: list[Any] = _arch_handles_plain([a for a in data.archs if (runs["arch"] == a).any()])
    if len(combos) > 1:
        handles += [
            Line2D([], [], color="black", ls=ls, marker=marker, label=combo)
            for (ls, marker), combo in zip(_COMBO_STYLES, combos, strict=False)
        ]
    handles += [
        Line2D([], [], **{**_ref_style(str(r).removeprefix("open_loop_")),
                          "label": _ref_style(str(r).removeprefix("open_loop_"))["label"]
                          + " (reported point)"})
        for r in data.ref_summary["arch"]
    ]  # fmt: skip
    _legend_below(fig, handles, ncol=3)
    what = f" (pooled over {', '.join(o.removeprefix('param.') for o in others)})" if pooled else ""
    fig.suptitle(f"Sweep of {key}{what}")
    return _save(fig, path)


# ---------------------------------------------------------------------------
# report.md
# ---------------------------------------------------------------------------


def _fmt(value: Any, spec: str = ".4g") -> str:
    if value is None:
        return "–"
    try:
        f = float(value)
    except (TypeError, ValueError):
        return str(value)
    if not np.isfinite(f):
        return "–"
    return format(f, spec)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured markdown table."""
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)


def _seed_table(data: _Data) -> str:
    runs = _ok_runs(data)
    runs = runs[runs["seed"] == data.seed]
    header = ["case", "Δv [km/s]", "miss [km]", "fuel penalty [%]", "re-solves",
              "success [%]", "infeasible", "failed", "solve mean / max [ms]"]  # fmt: skip
    rows = []
    for _, r in data.ref_summary.iterrows():
        rows.append([f"open-loop {str(r['arch']).removeprefix('open_loop_')}",
                     _fmt(r["delta_v_km_s"], ".7g"), _fmt(r["miss_km"], ".3g"),
                     _fmt(r.get("fuel_penalty_pct"), ".3f"), "", "", "", "", ""])  # fmt: skip
    for a in data.archs:
        g = runs[runs["arch"] == a]
        if g.empty:
            continue
        r = g.iloc[0]
        rows.append([
            _arch_label(a), _fmt(r["delta_v_km_s"], ".7g"), _fmt(r["miss_km"], ".4g"),
            _fmt(r.get("fuel_penalty_pct"), ".3f"), _fmt(r.get("n_solves"), "g"),
            _fmt(r.get("solve_success_pct"), ".2f"), _fmt(r.get("n_infeasible"), "g"),
            _fmt(r.get("n_failed"), "g"),
            f"{_fmt(r.get('solve_mean_ms'), '.3g')} / {_fmt(r.get('solve_max_ms'), '.3g')}",
        ])  # fmt: skip
    return markdown_table(header, rows)


def _campaign_table(data: _Data) -> str:
    all_runs = data.runs
    if data.point is not None and "point" in all_runs.columns:
        all_runs = all_runs[all_runs["point"].astype(str) == data.point]
    header = ["architecture", "runs ok / failed", "mean Δv [km/s]", "mean miss [km]",
              "median miss [km]", "p95 miss [km]", "max miss [km]", "mean success [%]"]  # fmt: skip
    rows = []
    for a in data.archs:
        g = all_runs[all_runs["arch"] == a]
        ok = g[g["status"] == "ok"]
        miss = ok["miss_km"].astype(float)
        rows.append([
            _arch_label(a), f"{len(ok)} / {len(g) - len(ok)}",
            _fmt(ok["delta_v_km_s"].mean()), _fmt(miss.mean()), _fmt(miss.median()),
            _fmt(miss.quantile(0.95) if len(miss) else None), _fmt(miss.max()),
            _fmt(ok["solve_success_pct"].mean() if "solve_success_pct" in ok else None, ".2f"),
        ])  # fmt: skip
    return markdown_table(header, rows)


def _sweep_table(data: _Data) -> str:
    """One row per grid point (all swept values) and architecture."""
    runs = data.runs[data.runs["status"] == "ok"].copy()
    keys: list[Any] = []
    for param in data.params:
        runs[f"_{param}"] = _param_values(runs[param])[0]
        keys.append(f"_{param}")
    header = [p.removeprefix(PARAM_PREFIX) for p in data.params] + [
        "architecture", "runs", "mean Δv [km/s]", "median miss [km]", "max miss [km]",
    ]  # fmt: skip
    rows = []
    order = {a: i for i, a in enumerate(data.archs)}
    for values, g in runs.groupby(keys, sort=True):
        values = values if isinstance(values, tuple) else (values,)
        for a, ga in sorted(g.groupby("arch"), key=lambda item: order.get(item[0], 99)):
            rows.append([*(_fmt(v, "g") for v in values), _arch_label(a), str(len(ga)),
                         _fmt(ga["delta_v_km_s"].mean()), _fmt(ga["miss_km"].median()),
                         _fmt(ga["miss_km"].max())])  # fmt: skip
    return markdown_table(header, rows)


_CAPTIONS = {
    "fig1_trajectories": "True relative trajectories, 3D and x–z (paper Fig. 1, top).",
    "fig2_control": "Thrust magnitude per architecture and cumulative Δv (paper Fig. 2, top).",
    "fig3_eps_score": "Homotopy parameter ε and the composite score (paper Fig. 2, bottom).",
    "fig4_nis_mtf": "NIS and MTF ratio with the degradation windows shaded (paper Fig. 4).",
    "fig5_errors": "Position error to the target and estimation error, log scale, with "
    "terminal close-ups (paper Figs 1 bottom and 3).",
    "fig6_dv_vs_miss": "Δv against terminal miss for every run; vertical lines: open-loop Δv.",
    "miss_distribution": "Terminal miss per architecture over the seeds (log scale).",
    "dv_distribution": "Δv per architecture over the seeds.",
    "paired_miss": "Miss of paired architectures on the same noise, seed by seed.",
}


def _report_md(data: _Data, results_dir: Path, figures: Sequence[Path]) -> str:
    n_seeds = int(_ok_runs(data)["seed"].nunique())
    lines = [
        "# cwrend report",
        "",
        f"Results: `{results_dir}` ({'`cwrend run` output' if data.layout == 'run' else 'campaign'}"
        + (f", config hash `{data.config_hash[:12]}`" if data.config_hash else "")
        + ").",
        f"Per-seed figures (1–5) show noise seed **{data.seed}**"
        + (f" at grid point `{data.point}`" if data.point else "")
        + (" (the first seed; choose another with `--seed N`)." if n_seeds > 1 else "."),
    ]
    if data.windows:
        wins = "; ".join(
            f"{i}: [{w.start_s:g}, {w.end_s:g}] s, {w.label}"
            for i, w in enumerate(data.windows, start=1)
        )
        lines.append(f"Degradation windows (shaded in the figures): {wins}.")
    lines += [f"{note}" for note in data.notes]
    lines += ["", f"## Noise seed {data.seed}", "", _seed_table(data), ""]
    if n_seeds > 1:
        lines += [f"## Over {n_seeds} noise seeds", "", _campaign_table(data), ""]
    if data.params:
        names = ", ".join(f"`{p.removeprefix('param.')}`" for p in data.params)
        lines += [f"## Sweep of {names} (every grid point)", "", _sweep_table(data), ""]
    lines += ["## Figures", ""]
    for fig in figures:
        caption = _CAPTIONS.get(fig.stem) or (
            f"Median miss and mean Δv against `{fig.stem.removeprefix('sweep_')}`."
            if fig.stem.startswith("sweep_")
            else ""
        )
        lines += [f"### {fig.stem}", "", caption, "", f"![{fig.stem}]({fig.name})", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------
# Entry point
# ---------------------------------------------------------------------------


def write_report(results_dir: Path, seed: int | None = None) -> ReportSummary:
    """Write the figures and ``report.md`` of a run or campaign directory.

    ``seed`` selects the noise realisation of the per-seed figures (default:
    the first seed with a successful run). Raises :class:`ReportError` (a
    :class:`~cwrend_cli.errors.CwrendError`) for a missing or unreadable
    directory or an unknown seed.
    """
    import matplotlib as mpl

    results_dir = Path(results_dir)
    data = load_results(results_dir, seed)
    out = results_dir / REPORT_DIR
    out.mkdir(parents=True, exist_ok=True)
    figures: list[Path] = []
    with mpl.rc_context(_RC):
        figures.append(fig_trajectories(data, out / "fig1_trajectories.png"))
        figures.append(fig_control(data, out / "fig2_control.png"))
        figures.append(fig_eps_score(data, out / "fig3_eps_score.png"))
        figures.append(fig_nis_mtf(data, out / "fig4_nis_mtf.png"))
        figures.append(fig_errors(data, out / "fig5_errors.png"))
        figures.append(fig_dv_vs_miss(data, out / "fig6_dv_vs_miss.png"))
        ok = _ok_runs(data)
        if not ok.empty and ok.groupby("arch")["seed"].nunique().max() > 1:
            figures.append(
                _distribution(data, out / "miss_distribution.png", "miss_km",
                              "terminal miss ‖r(T)‖ [km]", True, "Terminal miss")
            )  # fmt: skip
            figures.append(
                _distribution(data, out / "dv_distribution.png", "delta_v_km_s",
                              "Δv [km/s]", False, "Δv")
            )  # fmt: skip
            paired = fig_paired_miss(data, out / "paired_miss.png")
            if paired is not None:
                figures.append(paired)
        for param in data.params:
            name = f"sweep_{_slug(param.removeprefix('param.'))}.png"
            figures.append(fig_sweep(data, param, out / name))
    md = out / "report.md"
    with atomic_path(md) as tmp:
        tmp.write_text(_report_md(data, results_dir, figures), encoding="utf-8")
    return ReportSummary(
        results_dir=results_dir,
        out_dir=out,
        layout=data.layout,
        seed=data.seed,
        point=data.point,
        files=(*figures, md),
        notes=tuple(data.notes),
    )


__all__ = ["ReportError", "ReportSummary", "load_results", "markdown_table", "write_report"]
