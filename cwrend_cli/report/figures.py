"""The report's figures: pure functions of :class:`~cwrend_cli.report.load.ReportData`.

Every figure function draws on matplotlib's object API (no pyplot state) and
returns a finished :class:`~matplotlib.figure.Figure`; nothing here writes a
file. Draw (and save) inside ``matplotlib.rc_context(STYLE)`` at ``DPI`` for
the report's look.

:data:`FIGURES` is the one registry of the report's figures: file name,
caption, drawing function and when each applies, in report order. It drives
both the drawing and the figure list of ``report.md``:

* per noise realisation (the first seed, or ``seed=``; in a sweep the
  reported grid point): ``fig1_trajectories.png`` (3D and x–z views, open and
  closed loop), ``fig2_control.png`` (‖u‖ and cumulative Δv),
  ``fig3_eps_score.png``, ``fig4_nis_mtf.png``, ``fig5_errors.png``
  (degradation windows shaded in 2–5), ``fig6_dv_vs_miss.png`` (every run of
  the reported point);
* with more than one seed per architecture: ``miss_distribution.png``,
  ``dv_distribution.png``, ``paired_miss.png`` (MTF vs plain, seed by seed);
* per swept parameter with more than one value: ``sweep_<key>.png`` (not for
  a sampled design, whose hundreds of points would not read; with path
  constraints a third panel, the distance to the unsafe set);
* for a ``sobol`` design: ``sensitivity.png`` (first-order and total Sobol
  indices per architecture and metric, with their 95 % intervals);
* when the steps hold it: ``nees.png`` (filter consistency, every seed of
  the reported point);
* when the configuration has path constraints (issue 32, ``[constraints]``):
  ``safety_trajectories.png`` (the reported seed's paths near the target in
  the x–y, x–z and y–z planes with the keep-out zone and the corridor, unsafe
  nodes marked) and ``safety_distance.png`` (the signed distance to the unsafe
  set against time, degradation windows shaded); for a tumbling target
  (issue 34) also ``safety_body_frame.png`` (the same paths in the target's
  body frame, where the zone and the corridor stand still).

Every figure names the simulated world it shows (:attr:`ReportData.world`:
the truth model, and actuator errors and sensor faults when configured) in
its title and caption (issue 15, item 6): the guidance and the filter always
assume CW, the truth need not. In a sweep that is the reported point's world
(its swept values set), and the figures of every point name each point's
world (:attr:`ReportData.worlds`; issue 37).

Units: km, s, km/s, km/s² (as in the Parquet files); ‖u‖ is drawn in m/s².
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, cast

import numpy as np
import pandas as pd
from matplotlib import patheffects
from matplotlib.axes import Axes
from matplotlib.collections import Collection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Ellipse, Patch, Polygon
from matplotlib.ticker import FuncFormatter, MaxNLocator, NullFormatter
from matplotlib.typing import RcKeyType
from scipy.spatial import ConvexHull

from cwrend_cli.config import ARCHITECTURES
from cwrend_cli.output.layout import PARAM_PREFIX
from cwrend_cli.output.recording import (
    CORRIDOR_COLOUR,
    DEGRADATION_COLOUR,
    REFERENCE_COLOURS,
    UNSAFE_COLOUR,
    arch_colour,
    inflation_ratio_names,
    port_path,
)
from cwrend_cli.physics.constraints import (
    Geometry,
    ellipsoids,
    rotate_to_body,
    rotation_matrices,
)
from cwrend_cli.physics.metrics import NEES_DOF, NIS_DOF, chi2_band, cumulative_delta_v
from cwrend_cli.physics.params import Window
from cwrend_cli.report.consistency import step_ensembles
from cwrend_cli.report.labels import (
    M_PER_KM,
    category_text,
    difference_text,
    format_value,
    param_label,
    param_setting,
    param_symbol,
    swept_values,
)
from cwrend_cli.report.load import ReportData, arch_label, param_value, param_values

#: Resolution of the saved PNG files [dots per inch].
DPI = 120
#: matplotlib settings the figures are drawn and saved with.
STYLE: dict[RcKeyType, Any] = {
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
_MISS_FLOOR_M = 1e-6  # misses below this are drawn at this value on log axes
_WINDOW_ALPHAS = (0.18, 0.32, 0.25, 0.4)  # shading of successive degradation windows


# ---------------------------------------------------------------------------
# Figure helpers
# ---------------------------------------------------------------------------


def _tidy_log_axes(fig: Figure) -> None:
    """Readable log axes: minor labels at 2 and 5 over 1–2.5 decades, none beyond.

    Axes within :data:`_PLAIN_LOG_RANGE` (misses in m, NIS) read plain numbers
    (``0.1``, ``1``, ``20``); wider ones keep powers of ten.
    """
    for ax in fig.axes:
        for axis, scale, lim in (
            (ax.xaxis, ax.get_xscale(), ax.get_xlim()),
            (ax.yaxis, ax.get_yscale(), ax.get_ylim()),
        ):
            lo, hi = sorted(lim)
            if scale != "log" or lo <= 0:
                continue
            decades = np.log10(hi / lo)
            plain = lo >= _PLAIN_LOG_RANGE[0] and hi <= _PLAIN_LOG_RANGE[1]
            if plain:  # 0.1, 1, 10, 20, 50 rather than 10⁻¹, 10¹, 2×10¹
                axis.set_major_formatter(FuncFormatter(_plain_log_label))
            if decades > 2.5:
                axis.set_minor_formatter(NullFormatter())
            elif decades > 1.0:  # otherwise a single labelled tick may be all there is
                label = _plain_minor_log_label if plain else _minor_log_label
                axis.set_minor_formatter(FuncFormatter(label))


#: Log axes whose limits lie within this range are labelled with plain numbers.
_PLAIN_LOG_RANGE = (1e-3, 1e5)


def _minor_log_label(value: float, _pos: int | None) -> str:
    """``2×10⁻³`` and ``5×10⁻³`` styled like the major labels; other minor ticks unlabelled."""
    exponent = int(np.floor(np.log10(value)))
    mantissa = round(value / 10.0**exponent)
    return rf"${mantissa}\times10^{{{exponent}}}$" if mantissa in (2, 5) else ""


def _plain_log_label(value: float, _pos: int | None) -> str:
    """A major log tick as a plain number (``0.01``, ``1``, ``100``)."""
    return format(float(value), ".6g") if value > 0 else ""


def _plain_minor_log_label(value: float, _pos: int | None) -> str:
    """The minor log ticks at 2 and 5 as plain numbers (``20``, ``0.5``); others unlabelled."""
    if value <= 0:
        return ""
    exponent = int(np.floor(np.log10(value)))
    mantissa = round(value / 10.0**exponent)
    return format(mantissa * 10.0**exponent, ".6g") if mantissa in (2, 5) else ""


def _finished(fig: Figure) -> Figure:
    """The figure with its final touches (log-axis labels set from the final limits)."""
    _tidy_log_axes(fig)
    return fig


def _figure(width: float, height: float) -> Figure:
    return Figure(figsize=(width, height), layout="constrained")


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
        return arch_label(slugs[0])
    known = [ARCHITECTURES[s] for s in slugs if s in ARCHITECTURES]
    if len(known) == len(slugs):
        if len({a.mtf for a in known}) == 1:
            kf = "MTF KF" if known[0].mtf else "plain KF"
            return f"{kf}, fixed and adaptive ε (identical)"
        if len({a.adaptive for a in known}) == 1:
            return f"plain and MTF KF, {'adaptive' if known[0].adaptive else 'fixed'} ε (identical)"
    return " = ".join(arch_label(s) for s in slugs)


def _shade(ax: Axes, windows: Sequence[Window]) -> None:
    for i, w in enumerate(windows):
        ax.axvspan(w.start_s, w.end_s, color=DEGRADATION_COLOUR, alpha=_WINDOW_ALPHAS[i % 4], lw=0)


def _window_handles(windows: Sequence[Window]) -> list[Patch]:
    return [
        Patch(
            color=DEGRADATION_COLOUR,
            alpha=_WINDOW_ALPHAS[i % 4],
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


def _refs(data: ReportData) -> Iterator[tuple[str, pd.DataFrame]]:
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


def _cumulative_dv(g: pd.DataFrame) -> np.ndarray:
    """Cumulative Δv [km/s] of a steps or reference table (trapezoid of ``u_norm_km_s2``)."""
    return cumulative_delta_v(g["t_s"].to_numpy(), g["u_norm_km_s2"].to_numpy())


def _title(data: ReportData) -> str:
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
    return [Line2D([], [], **_arch_style(a, archs), label=arch_label(a)) for a in archs]


def _group_handles(groups: Sequence[tuple[list[str], pd.DataFrame]], archs: Sequence[str],
                   **style: Any) -> list[Line2D]:  # fmt: skip
    return [
        Line2D([], [], color=_group_colour(m, archs), lw=2, label=_group_label(m), **style)
        for m, _ in groups
    ]


def _arch_handles_plain(archs: Sequence[str]) -> list[Line2D]:
    """Colour-only handles (the line style carries another meaning)."""
    return [
        Line2D([], [], color=arch_colour(a, archs.index(a)), lw=2.5, label=arch_label(a))
        for a in archs
    ]


#: Line width of the open-loop references in Fig. 1 (drawn over the closed-loop runs).
REF_LW_FIG1 = 2.6
#: A white outline under the references of Fig. 1: the dotted fuel-optimal one stays legible
#: on the fixed-ε runs it lies on.
_REF_HALO = [patheffects.Stroke(linewidth=REF_LW_FIG1 + 2.4, foreground="white"),
             patheffects.Normal()]  # fmt: skip


def _ref_handles(data: ReportData, **style: Any) -> list[Line2D]:
    return [Line2D([], [], **{**_ref_style(name), **style}) for name, _ in _refs(data)]


# ---------------------------------------------------------------------------
# Per-seed figures (paper Figs 1–6)
# ---------------------------------------------------------------------------


def fig_trajectories(data: ReportData) -> Figure:
    """Fig. 1: 3D and x–z views of the true trajectories, open and closed loop."""
    fig = _figure(13.5, 6.4)
    ax3: Any = fig.add_subplot(1, 2, 1, projection="3d")  # an Axes3D (mpl_toolkits is untyped)
    # mplot3d orders artists by their depth unless told otherwise, which puts the fuel-optimal
    # reference under the fixed-ε runs whatever its zorder: draw in zorder instead
    ax3.computed_zorder = False
    ax2 = fig.add_subplot(1, 2, 2)
    for a, g in _by_arch(data.steps, data.archs):
        st = _arch_style(a, data.archs)
        ax3.plot(g["x_km"], g["y_km"], g["z_km"], **st)
        ax2.plot(g["x_km"], g["z_km"], **st)
    # the references last and thicker: the fuel-optimal one lies under the fixed-ε runs
    for name, g in _refs(data):
        st = {**_ref_style(name), "lw": REF_LW_FIG1, "zorder": 4, "path_effects": _REF_HALO}
        ax3.plot(g["x_km"], g["y_km"], g["z_km"], **st)
        ax2.plot(g["x_km"], g["z_km"], **st)
    first = data.steps.sort_values("t_s").iloc[0] if not data.steps.empty else None
    start = (first["x_km"], first["y_km"], first["z_km"]) if first is not None else None
    target_style: dict[str, Any] = {"marker": "*", "s": 180, "color": "black", "zorder": 5}
    start_style: dict[str, Any] = {"marker": "o", "s": 50, "facecolor": "white",
                                   "edgecolor": "black", "zorder": 5}  # fmt: skip
    ax3.scatter(0.0, 0.0, 0.0, **target_style)
    if start is not None:
        ax3.scatter(*start, **start_style)
    ax2.scatter(0.0, 0.0, **target_style)
    if start is not None:
        ax2.scatter(start[0], start[2], **start_style)
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
    refs = _ref_handles(data, lw=REF_LW_FIG1)
    _legend_below(fig, _arch_handles(data.archs) + refs + markers, ncol=4)
    fig.suptitle(f"Fig. 1 · Trajectories, open and closed loop ({_title(data)})")
    return _finished(fig)


def fig_control(data: ReportData) -> Figure:
    """Fig. 2: thrust magnitude history and cumulative Δv."""
    archs = [a for a, _ in _by_arch(data.steps, data.archs)]
    n = len(archs)
    fig = _figure(13, 3.0 + 1.45 * n)
    grid = fig.add_gridspec(n, 2, width_ratios=[1.5, 1])
    ax_dv = fig.add_subplot(grid[:, 1])
    u_max = data.u_max_km_s2
    share: Axes | None = None
    for i, (a, g) in enumerate(_by_arch(data.steps, data.archs)):
        ax = fig.add_subplot(grid[i, 0], sharex=share, sharey=share)
        share = share or ax
        c = arch_colour(a, data.archs.index(a))
        for name, r in _refs(data):
            if name == "fuel":
                ax.plot(r["t_s"], 1e3 * r["u_norm_km_s2"], **{**_ref_style(name), "lw": 1.2})
        ax.plot(g["t_s"], 1e3 * g["u_norm_km_s2"], color=c, lw=1.3, drawstyle="steps-post")
        _shade(ax, data.windows)
        ax.set_title(arch_label(a), fontsize=10.5, loc="left", pad=3)
        ax.set_ylabel("‖u‖ [m/s²]")
        if u_max is not None:
            ax.set_ylim(-0.05 * 1e3 * u_max, 1.12 * 1e3 * u_max)
        if i < n - 1:
            ax.tick_params(labelbottom=False)
        else:
            ax.set_xlabel("time [s]")
        ax_dv.plot(g["t_s"], _cumulative_dv(g), **_arch_style(a, data.archs))
    for name, r in _refs(data):
        ax_dv.plot(r["t_s"], _cumulative_dv(r), **_ref_style(name))
    _shade(ax_dv, data.windows)
    ax_dv.set_xlabel("time [s]")
    ax_dv.set_ylabel(f"cumulative Δv [km/s] ({DV_TRAPEZOID})")
    ax_dv.set_title("cumulative Δv")
    handles = _arch_handles(archs) + _ref_handles(data) + _window_handles(data.windows)
    _legend_below(fig, handles, ncol=4)
    fig.suptitle(f"Fig. 2 · Thrust magnitude and cumulative Δv ({_title(data)})")
    return _finished(fig)


def fig_eps_score(data: ReportData) -> Figure:
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
    return _finished(fig)


def fig_nis_mtf(data: ReportData) -> Figure:
    """Fig. 4: NIS and the inflation ratio ρ, degradation windows shaded; close-up of the
    windows (ρ named for the estimators plotted: :func:`inflation_ratio_names`).

    The dotted line is the NIS offset ``m`` of the score (not drawn without a
    stored configuration).
    """
    fig = _figure(14, 7.8)
    axes = fig.subplots(2, 2, width_ratios=[1.6, 1])
    m = data.nis_offset
    lo = min((w.start_s for w in data.windows), default=None)
    hi = max((w.end_s for w in data.windows), default=None)
    nis_groups = _groups(data.steps, data.archs, ["nis"])
    mtf_groups = [
        (members, g)
        for members, g in _groups(data.steps, data.archs, ["mtf_ratio"])
        if g["mtf_ratio"].fillna(0.0).abs().max() > 0
    ]
    ratio, definition = inflation_ratio_names([a for members, _ in mtf_groups for a in members])
    for col in range(2):
        ax_n, ax_r = axes[0, col], axes[1, col]
        for members, g in nis_groups:
            ax_n.plot(g["t_s"], g["nis"], color=_group_colour(members, data.archs), lw=1.0)
        for members, g in mtf_groups:
            ax_r.plot(g["t_s"], g["mtf_ratio"], color=_group_colour(members, data.archs), lw=1.0)
        if m is not None:
            ax_n.axhline(m, color="black", lw=1.0, ls=":")
        for ax in (ax_n, ax_r):
            _shade(ax, data.windows)
        ax_n.set_yscale("log")
        ax_r.set_yscale("symlog", linthresh=1.0)
        ax_r.set_ylim(bottom=0.0)
        ax_n.set_ylabel("NIS [-]")
        ax_r.set_ylabel(f"{ratio} ρ [-]")
        ax_r.set_xlabel("time [s]")
        if col == 1 and lo is not None and hi is not None:
            span = hi - lo
            for ax in (ax_n, ax_r):
                ax.set_xlim(lo - 0.3 * span, hi + 0.3 * span)
            ax_n.set_title("close-up: degradation and recovery")
            ax_r.set_title("close-up: degradation and recovery")
        elif col == 0:
            ax_n.set_title("normalised innovation squared (dotted: offset m)")
            ax_r.set_title(f"{ratio} {definition}, linear below 1, log above")
    handles: list[Any] = _group_handles(nis_groups, data.archs)
    if m is not None:
        handles.append(
            Line2D([], [], color="black", ls=":", label=f"m = {m:g} (NIS offset of the score)")
        )
    _legend_below(fig, handles + _window_handles(data.windows), ncol=3)
    fig.suptitle(f"Fig. 4 · Scheduler inputs: NIS and {ratio} ({_title(data)})")
    return _finished(fig)


def fig_errors(data: ReportData) -> Figure:
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
    axes[0, 0].set_ylabel("‖r‖ [km]")
    axes[1, 0].set_ylabel("‖r̂ − r‖ [km]")
    axes[1, 0].legend(handles=_group_handles(est_groups, data.archs), loc="lower right",
                      framealpha=0.9)  # fmt: skip
    for ax in axes[1, :]:
        ax.set_xlabel("time [s]")
    handles = _arch_handles(data.archs) + _ref_handles(data) + _window_handles(data.windows)
    _legend_below(fig, handles, ncol=4)
    fig.suptitle(f"Fig. 5 · Position and estimation errors ({_title(data)})")
    return _finished(fig)


#: Which Δv the report's figures plot: the paper's (``delta_v_km_s``), as its Figs 2 and 6 do.
#: The applied impulse Σ‖u_k‖Δt of a run (``delta_v_applied_km_s``) is ‖u₀‖Δt/2 more, at
#: most u_max Δt / 2 (0.4 m/s on the paper scenario, 0.3 % of its Δv): the same picture
#: shifted by less than a marker; the applied Δv and its penalty are in the report's tables.
DV_TRAPEZOID = "trapezoid of ‖u‖, the paper's"
#: The caption's sentence on it (figures that plot Δv).
DV_CAPTION = (
    "Δv: the paper's trapezoid of ‖u‖ over the time steps (delta_v_km_s), not the applied "
    "impulse Σ‖u_k‖Δt (delta_v_applied_km_s, half the first step's impulse more; in the tables)."
)


def _exact_fuel_optimum(data: ReportData) -> float | None:
    """The exact continuous fuel optimum [km/s] (u_max times its burn time), from stored
    values: the fuel reference's ``delta_v_applied_km_s`` (a run directory), else what
    every ok run's applied Δv and penalty give, Δv_applied / (1 + penalty / 100), when they
    agree to 1e-9 (a campaign of one scenario); ``None`` for results written before them."""
    ref = data.ref_summary
    if "delta_v_applied_km_s" in ref.columns:
        row = ref.loc[ref["arch"] == "open_loop_fuel", "delta_v_applied_km_s"]
        if not row.empty and np.isfinite(float(row.iloc[0])):
            return float(row.iloc[0])
    runs = data.ok_runs()
    if runs.empty or not {"delta_v_applied_km_s", "fuel_penalty_applied_pct"} <= set(runs):
        return None
    dv = runs["delta_v_applied_km_s"].to_numpy(dtype=float)
    optimum = dv / (1.0 + runs["fuel_penalty_applied_pct"].to_numpy(dtype=float) / 100.0)
    optimum = optimum[np.isfinite(optimum)]
    if optimum.size == 0 or np.ptp(optimum) > 1e-9 * np.max(np.abs(optimum)):
        return None
    return float(np.median(optimum))


def fig_dv_vs_miss(data: ReportData) -> Figure:
    """Fig. 6: Δv against terminal miss, every run (log miss), references as vertical lines.

    Δv is the paper's trapezoid (:data:`DV_TRAPEZOID`); the fuel-optimal line also
    gives the exact continuous optimum, which a run left of the line does not beat.
    """
    fig = _figure(13, 6.8)
    ax = fig.subplots()
    runs = data.ok_runs()
    multi = runs.groupby("arch")["seed"].nunique().max() > 1 if not runs.empty else False
    for a in data.archs:
        g = runs[runs["arch"] == a]
        if g.empty:
            continue
        c = arch_colour(a, data.archs.index(a))
        miss = np.maximum(g["miss_km"].to_numpy(dtype=float) * M_PER_KM, _MISS_FLOOR_M)
        ax.scatter(g["delta_v_km_s"], miss, color=c, s=26 if multi else 90,
                   alpha=0.7 if multi else 0.95, edgecolor="black", lw=0.3 if multi else 1.0,
                   label=arch_label(a), zorder=4, gid=f"runs:{a}")  # fmt: skip
        if multi:  # hollow: a tight cluster (MTF-fixed) stays visible inside its median
            ax.scatter(g["delta_v_km_s"].median(), np.median(miss), s=190, marker="D",
                       facecolor="none", edgecolor=c, lw=2.2, zorder=5,
                       gid=f"median:{a}")  # fmt: skip
    exact = _exact_fuel_optimum(data)
    for _, row in data.ref_summary.iterrows():
        name = str(row["arch"]).removeprefix("open_loop_")
        st = _ref_style(name)
        beside = f" (trapezoid; exact {exact:.4g})" if name == "fuel" and exact else ""
        ax.axvline(float(row["delta_v_km_s"]), color=st["color"], ls=st["ls"], lw=1.6,
                   label=f"{st['label']} Δv = {row['delta_v_km_s']:.4g} km/s{beside}")  # fmt: skip
    ax.set_yscale("log")
    ax.margins(x=0.04, y=0.08)  # no run on the frame (margins of the log axis in decades)
    ax.set_xlabel(f"Δv [km/s] ({DV_TRAPEZOID})")
    ax.set_ylabel("terminal miss ‖r(T)‖ [m]")
    what = f"{len(runs)} runs; hollow diamonds: per-architecture median" if multi else _title(data)
    ax.set_title(f"Fig. 6 · Fuel against accuracy ({what})")
    handles = [
        Line2D([], [], marker="o", ls="", ms=9, color=arch_colour(a, data.archs.index(a)),
               mec="black", label=arch_label(a))
        for a in data.archs
        if (runs["arch"] == a).any()
    ] + [h for h in ax.get_legend_handles_labels()[0] if isinstance(h, Line2D)]  # fmt: skip
    if multi:
        handles.append(Line2D([], [], marker="D", ls="", ms=10, mfc="none", mec="black",
                              mew=2.0, label="median of the seeds"))  # fmt: skip
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    return _finished(fig)


#: Two-sided probability of the χ² band drawn in the NEES figure.
NEES_BAND_PROBABILITY = 0.95
#: Dimension of the state: NEES of a consistent filter is χ² with this many degrees of freedom.
STATE_DIM = NEES_DOF
#: ``gid`` of the χ² band's patch in the NEES figure.
NEES_BAND_GID = "nees_chi2_band"
#: Quantiles of the band over seeds in the NEES figure.
_NEES_SEED_BAND = (0.1, 0.9)


def nees_chi2_band(probability: float = NEES_BAND_PROBABILITY) -> tuple[float, float]:
    """The two-sided ``probability`` interval of χ²₆, where one run's NEES lies if consistent.

    (Bar-Shalom, Li & Kirubarajan 2001, §5.4.2): [1.24, 14.45] at 95 %.
    """
    low, high = chi2_band(1, STATE_DIM, probability)
    return float(low), float(high)


def _nees_lines(nees: pd.DataFrame, archs: Sequence[str]) -> pd.DataFrame:
    """Median and seed band of the NEES per architecture and time (arch, t_s, med, lo, hi)."""
    lo_q, hi_q = _NEES_SEED_BAND
    grouped = nees.groupby(["arch", "t_s"], observed=True)["nees"]
    out = pd.DataFrame(
        {"med": grouped.median(), "lo": grouped.quantile(lo_q), "hi": grouped.quantile(hi_q)}
    ).reset_index()
    return out[out["arch"].isin(archs)]


def fig_nees(data: ReportData) -> Figure:
    """Filter consistency: NEES against time per architecture, median and band over seeds.

    NEES = (x̂ − x)ᵀ P⁻¹ (x̂ − x) of every step (row 0 excluded when zero: no
    initial error); a consistent filter has NEES ~ χ²₆ (mean 6), the grey
    band is χ²₆'s 95 % interval of a single run. Architectures whose median
    curves coincide (same estimator, control-independent errors) are drawn
    once. Log y. Raises ``ValueError`` without stored NEES (see :data:`FIGURES`).
    """
    if data.nees is None or data.nees.empty:
        raise ValueError("no NEES stored")
    lines = _nees_lines(data.nees, data.archs)
    n_seeds = int(data.nees["seed"].nunique())
    fig = _figure(13, 6.4)
    ax = fig.subplots()
    low, high = nees_chi2_band()
    ax.axhspan(low, high, color="0.5", alpha=0.18, lw=0, gid=NEES_BAND_GID)
    ax.axhline(STATE_DIM, color="black", lw=1.0, ls=":")
    groups = _groups(lines, data.archs, ["med"])
    for members, g in groups:
        g = g[g["med"] > 0]
        c = _group_colour(members, data.archs)
        ax.plot(g["t_s"], g["med"], color=c, lw=1.5)
        if n_seeds > 1:
            ax.fill_between(g["t_s"], g["lo"].clip(lower=1e-12), g["hi"], color=c, alpha=0.15,
                            lw=0)  # fmt: skip
    _shade(ax, data.windows)
    ax.set_yscale("log")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("NEES [-]")
    what = (
        f"median over {n_seeds} seeds, band {100 * _NEES_SEED_BAND[0]:g}–"
        f"{100 * _NEES_SEED_BAND[1]:g} % of the seeds"
        if n_seeds > 1
        else f"noise seed {data.nees['seed'].iloc[0]}"
    )
    ax.set_title(f"normalised estimation error squared ({what})")
    handles: list[Any] = _group_handles(groups, data.archs)
    handles += [
        Patch(color="0.5", alpha=0.18, label=f"χ²₆ 95 % interval [{low:.2f}, {high:.2f}]"),
        Line2D([], [], color="black", ls=":", label="E[NEES] = 6 (consistent filter)"),
    ]
    _legend_below(fig, handles + _window_handles(data.windows), ncol=3)
    fig.suptitle("Filter consistency: NEES against time")
    return _finished(fig)


def _has_nees(data: ReportData) -> bool:
    return data.nees is not None and not data.nees.empty


#: ``gid`` of the χ² band's patch in each panel of the consistency figure (NEES, NIS).
ENSEMBLE_BAND_GID = "ensemble_chi2_band"
_ENSEMBLE_LABELS = {"nees": ("NEES", NEES_DOF), "nis": ("NIS", NIS_DOF)}


def fig_consistency(data: ReportData) -> Figure:
    """Filter consistency over the seeds: the ensemble mean NEES and NIS against their χ² bands.

    At each step the mean over the N seeds whose steps are stored (the NIS: over
    those with a measurement) per architecture; shaded, the 95 % band of a
    consistent filter's mean, χ²(N n)/N with n = 6 (NEES) or the sensor's m (NIS: 3, or 2
    for angles)
    (Bar-Shalom et al. 2001, §5.4.2; :mod:`~cwrend_cli.report.consistency`),
    the widest over the architectures where their seed counts differ. Row 0
    left out; architectures with identical curves drawn once; log y.
    Raises ``ValueError`` without stored NEES (see :data:`FIGURES`).
    """
    if data.nees is None or data.nees.empty:
        raise ValueError("no NEES stored")
    ensembles = step_ensembles(data.nees, data.nis_dof)
    n_seeds = int(data.nees["seed"].nunique())
    fig = _figure(13, 4.2 + 3.4 * len(ensembles))
    axes = np.atleast_1d(fig.subplots(len(ensembles), 1, sharex=True, squeeze=False)[:, 0])
    handles: list[Any] = []
    for ax, (column, ensemble) in zip(axes, ensembles.items(), strict=True):
        name, dof = _ENSEMBLE_LABELS[column]
        dof = data.nis_dof if column == "nis" else dof  # the sensor's m (issue 35)
        band = ensemble.groupby("t_s")[["band_low", "band_high"]].agg(
            {"band_low": "min", "band_high": "max"}
        )
        ax.fill_between(band.index, band["band_low"], band["band_high"], color="0.5",
                        alpha=0.25, lw=0, gid=ENSEMBLE_BAND_GID)  # fmt: skip
        ax.axhline(dof, color="black", lw=1.0, ls=":")
        groups = _groups(ensemble, data.archs, ["mean"])
        for members, g in groups:
            g = g[g["mean"] > 0]
            ax.plot(g["t_s"], g["mean"], color=_group_colour(members, data.archs), lw=1.5)
        _shade(ax, data.windows)
        ax.set_yscale("log")
        ax.set_ylabel(f"mean {name} [-]")
        ax.set_title(f"ensemble mean {name} over the seeds (consistent: inside the band, mean "
                     f"{dof})")  # fmt: skip
        if column == "nees":
            handles = _group_handles(groups, data.archs)
    axes[-1].set_xlabel("time [s]")
    handles += [
        Patch(color="0.5", alpha=0.25, label="95 % χ² band of a consistent filter's mean"),
        Line2D([], [], color="black", ls=":", label=f"E[NEES] = 6, E[NIS] = {data.nis_dof}"),
    ]
    _legend_below(fig, handles + _window_handles(data.windows), ncol=3)
    fig.suptitle(f"Filter consistency over {n_seeds} seed(s): ensemble means against χ² bands")
    return _finished(fig)


# ---------------------------------------------------------------------------
# Path constraints (issue 32): the keep-out zone, the corridor, the distance to them
# ---------------------------------------------------------------------------

#: The three planes of the safety figure: (horizontal axis, vertical axis) of the frame.
_PLANES = ((0, 1), (0, 2), (1, 2))
_AXIS_NAMES = ("x (radial)", "y (along-track)", "z (cross-track)")
_POSITION_COLUMNS = ("x_km", "y_km", "z_km")
#: Half-width of the safety figure's views, in units of the constraints' size (the largest
#: semi-axis or port distance): the approach near the target, where the constraints act.
_SAFETY_VIEW = 3.0
#: Points of the corridor's base circle projected to draw the cone's outline.
_CONE_CIRCLE = 96


def _rgb(colour: tuple[int, int, int]) -> tuple[float, float, float]:
    return (colour[0] / 255.0, colour[1] / 255.0, colour[2] / 255.0)


def _constraint_size(geo: Geometry) -> float:
    """The constraints' size [km]: the largest semi-axis or the port's distance to the target."""
    sizes = [0.0]
    if geo.semi_axes_km is not None:
        sizes.append(float(np.max(geo.semi_axes_km)))
    if geo.port_km is not None:
        sizes.append(float(np.linalg.norm(geo.port_km)))
    return max(sizes) or 1.0


def _cone_outline(geo: Geometry, plane: tuple[int, int], half_km: float) -> np.ndarray | None:
    """Outline (k, 2) of the corridor cone within the view, seen in ``plane``.

    The cone is cut where its axis leaves the cube of half-width ``half_km``
    around the target (the views' extent; at least ``half_km`` from the apex
    if the apex lies outside it); its outline is the convex hull of the
    projections of the apex and of the circle of the cut (the projection of a
    truncated cone is the hull of its apex's and its base's projections).
    ``None`` without a corridor.
    """
    if geo.port_km is None or geo.axis is None or geo.half_angle_rad is None:
        return None
    axis = geo.axis
    with np.errstate(divide="ignore"):
        exits = (half_km - np.sign(axis) * geo.port_km) / np.abs(axis)
    length_km = float(np.min(exits))
    if not length_km > 0.0:
        length_km = half_km
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    phi = np.linspace(0.0, 2.0 * np.pi, _CONE_CIRCLE, endpoint=False)[:, None]
    radius = length_km * np.tan(geo.half_angle_rad)
    circle = geo.port_km + length_km * axis + radius * (np.cos(phi) * e1 + np.sin(phi) * e2)
    points = np.vstack([geo.port_km, circle])[:, list(plane)]
    hull = ConvexHull(points, qhull_options="QJ")  # joggled: a flat projection still has one
    return np.asarray(points[hull.vertices], dtype=float)


def _unsafe_steps(g: pd.DataFrame) -> pd.DataFrame:
    """The rows of one run's steps whose true position was inside the unsafe set (φ < 0)."""
    if "safety_distance_km" not in g.columns:
        return g.iloc[:0]
    return g[g["safety_distance_km"].to_numpy(dtype=float) < 0.0]


#: The steps columns of a tumbling target's attitude (issue 34): the quaternion body →
#: relative frame at each step, scalar-first.
_ATTITUDE_COLUMNS = ("target_q0", "target_q1", "target_q2", "target_q3")
_BODY_AXIS_NAMES = ("x_b (body)", "y_b (body)", "z_b (body)")


def _rotations(g: pd.DataFrame) -> np.ndarray:
    """The rotations body → relative frame (M, 3, 3) at one run's steps (their attitude)."""
    return rotation_matrices(g[list(_ATTITUDE_COLUMNS)].to_numpy(dtype=float))


def body_frame_steps(g: pd.DataFrame) -> pd.DataFrame:
    """One run's steps with the true positions in the tumbling target's body frame (issue 34).

    ``x_km``, ``y_km``, ``z_km`` replaced by ``ρ_k = R(q_k)ᵀ r_k``, each step's
    position turned by the truth's attitude at that step (the stored
    ``target_q*`` columns); the other columns unchanged.
    """
    out = g.copy()
    r = g[list(_POSITION_COLUMNS)].to_numpy(dtype=float)
    out[list(_POSITION_COLUMNS)] = rotate_to_body(_rotations(g), r)
    return out


#: The body-frame view draws the path only within this many view half-widths of the target
#: [-]: farther out the body's turn sweeps the path's projection across the view between
#: two steps (its chords would cross the view as straight lines that were never flown).
_BODY_VIEW_CUT = 2.0


def _near(g: pd.DataFrame, radius_km: float) -> pd.DataFrame:
    """``g`` with the positions farther than ``radius_km`` from the target set to NaN (the
    line is broken there)."""
    r = g[list(_POSITION_COLUMNS)].to_numpy(dtype=float)
    out = g.copy()
    out.loc[np.linalg.norm(r, axis=1) > radius_km, list(_POSITION_COLUMNS)] = np.nan
    return out


def _tumbling(data: ReportData) -> bool:
    return set(_ATTITUDE_COLUMNS) <= set(data.steps.columns)


def _ellipse(centre: np.ndarray, axes: np.ndarray, turn: np.ndarray | None,
             plane: tuple[int, int], **style: Any) -> Ellipse:  # fmt: skip
    """The projection on ``plane`` of the ellipsoid of semi-axes ``axes`` along the frame's
    axes around ``centre``, turned by ``turn`` (3, 3) about the origin (``None``: not)."""
    i, j = plane
    if turn is None:
        return Ellipse((centre[i], centre[j]), 2 * axes[i], 2 * axes[j], **style)
    # {x: xᵀ M⁻¹ x ≤ 1}, M = R diag(a²) Rᵀ, projects on (i, j) to the ellipse of M's block
    shape = (turn * axes**2) @ turn.T
    values, vectors = np.linalg.eigh(shape[np.ix_(plane, plane)])
    c = turn @ centre
    angle = float(np.degrees(np.arctan2(vectors[1, 1], vectors[0, 1])))
    width, height = 2 * np.sqrt(np.maximum(values[::-1], 0.0))
    return Ellipse((c[i], c[j]), width, height, angle=angle, **style)


def _seen_along_axis(geo: Geometry, plane: tuple[int, int]) -> bool:
    """Whether the corridor's axis leaves ``plane`` steeply enough that the cone's projection
    surrounds the port on every side: its in-plane part at most sin θ."""
    assert geo.axis is not None and geo.half_angle_rad is not None
    i, j = plane
    return bool(math.hypot(geo.axis[i], geo.axis[j]) <= math.sin(geo.half_angle_rad))


def _safety_planes(
    data: ReportData,
    paths: Sequence[tuple[str, pd.DataFrame]],
    turn: np.ndarray | None,
    names: Sequence[str],
    port_path: np.ndarray | None = None,
) -> tuple[Figure, list[Any]]:
    """The three planes of a safety figure and its legend handles.

    ``paths``: (architecture, steps) with the positions to draw in ``x_km`` …;
    the keep-out ellipsoids and the corridor as given in the configuration,
    turned by ``turn`` (``None``: as given); ``port_path`` (M, 3): the moving
    port's positions, drawn as a dotted line.
    """
    geo = data.constraints
    assert geo is not None
    half = _SAFETY_VIEW * _constraint_size(geo)
    unsafe, corridor = _rgb(UNSAFE_COLOUR), _rgb(CORRIDOR_COLOUR)
    shown = geo if turn is None or geo.port_km is None or geo.axis is None else replace(
        geo, port_km=turn @ geo.port_km, axis=turn @ geo.axis)  # fmt: skip
    fig = _figure(16, 6.6)
    axes = fig.subplots(1, 3)
    marked = False
    for ax, plane in zip(axes, _PLANES, strict=True):
        i, j = plane
        for centre, a in ellipsoids(geo):
            ax.add_patch(_ellipse(np.zeros(3) if centre is None else centre, a, turn, plane,
                                  facecolor=(*unsafe, 0.22), edgecolor=unsafe, lw=1.6,
                                  zorder=1))  # fmt: skip
        outline = _cone_outline(shown, plane, half)
        if outline is not None:
            # seen along its axis (out of the plane) the cone projects to a disc round the
            # port, which filled would read as a waiver of everything under it: an outline
            along = _seen_along_axis(shown, plane)
            fill = "none" if along else (*corridor, 0.15)
            ax.add_patch(Polygon(outline, closed=True, lw=1.6, ls="--", zorder=1,
                                 facecolor=fill, edgecolor=corridor,
                                 gid="corridor:along" if along else None))  # fmt: skip
            if along:
                ax.text(0.02, 0.02, "corridor seen along its axis\n(out of the plane)",
                        transform=ax.transAxes, fontsize=8, color=corridor,
                        va="bottom")  # fmt: skip
        if port_path is not None:
            ax.plot(port_path[:, i], port_path[:, j], color="black", lw=1.0, ls=":", zorder=2)
        for arch, g in paths:
            ax.plot(g[_POSITION_COLUMNS[i]], g[_POSITION_COLUMNS[j]],
                    **_arch_style(arch, data.archs), zorder=3)  # fmt: skip
            bad = _unsafe_steps(g)
            if not bad.empty:
                marked = True
                ax.scatter(bad[_POSITION_COLUMNS[i]], bad[_POSITION_COLUMNS[j]], s=16,
                           marker="x", color=unsafe, lw=1.0, zorder=4,
                           gid=f"unsafe:{arch}")  # fmt: skip
        if shown.port_km is not None:  # under the target, which it may hide in projection
            ax.scatter(shown.port_km[i], shown.port_km[j], marker="D", s=90, facecolor="white",
                       edgecolor="black", zorder=5)  # fmt: skip
        ax.scatter(0.0, 0.0, marker="*", s=150, color="black", zorder=6)
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
        ax.set_aspect("equal")
        ax.set_xlabel(f"{names[i]} [km]")
        ax.set_ylabel(f"{names[j]} [km]")
        ax.set_title(f"{names[i].split(' ')[0]}–{names[j].split(' ')[0]} plane")
    handles: list[Any] = _arch_handles(data.archs)
    if geo.semi_axes_km is not None:
        handles.append(Patch(facecolor=(*unsafe, 0.22), edgecolor=unsafe, label="keep-out zone"))
    if geo.port_km is not None:
        handles.append(Patch(facecolor=(*corridor, 0.15), edgecolor=corridor, ls="--",
                             label="approach corridor (keep-out waived)"))  # fmt: skip
    if marked:
        handles.append(Line2D([], [], marker="x", ls="", ms=7, color=unsafe,
                              label="node inside the unsafe set"))  # fmt: skip
    handles.append(Line2D([], [], marker="*", ls="", ms=12, color="black", label="target"))
    if geo.port_km is not None:
        handles.append(Line2D([], [], marker="D", ls="", ms=7, mfc="white", mec="black",
                              label="docking port" if port_path is None
                              else "docking port at t = 0"))  # fmt: skip
    if port_path is not None:
        handles.append(Line2D([], [], color="black", lw=1.0, ls=":", label="docking port's path"))
    return fig, handles


def fig_safety_trajectories(data: ReportData) -> Figure:
    """The reported seed's true paths near the target with the constraints, in three planes.

    x–y, x–z and y–z of the relative frame (km), each a projection: the
    keep-out ellipsoids' (their sections through their centres too, their axes
    being the frame's), the corridor cone's (apex at the port, cut beyond the
    view) and each architecture's path; its nodes inside the unsafe set
    (per-step ``safety_distance_km`` < 0) marked. The views span
    ±:data:`_SAFETY_VIEW` times the constraints' size around the target.
    For a tumbling target (issue 34) the zone and the corridor are drawn as
    they stood at t = 0 (turned by the first step's attitude) and the moving
    port's path is drawn; :func:`fig_safety_body_frame` shows them fixed.
    Raises ``ValueError`` without constraints (see :data:`FIGURES`).
    """
    geo = data.constraints
    if geo is None:
        raise ValueError("no path constraints configured")
    paths = list(_by_arch(data.steps, data.archs))
    turn = port = None
    if _tumbling(data) and paths:
        q_hb = paths[0][1][list(_ATTITUDE_COLUMNS)].to_numpy(dtype=float)
        turn = rotation_matrices(q_hb[:1])[0]
        if geo.port_km is not None:
            port = port_path(q_hb, geo.port_km)
    fig, handles = _safety_planes(data, paths, turn, _AXIS_NAMES, port)
    _legend_below(fig, handles, ncol=4)
    what = "keep-out zone and corridor" if turn is None else (
        "keep-out zone and corridor at t = 0 (they turn with the target)")  # fmt: skip
    fig.suptitle(f"Safe approach: true paths near the target, {what} ({_title(data)})")
    return _finished(fig)


def fig_safety_body_frame(data: ReportData) -> Figure:
    """A tumbling target's approach in its body frame (issue 34), in three planes.

    Each step's true position turned into the target's body frame at that
    step's attitude (:func:`body_frame_steps`), with the keep-out ellipsoids,
    the corridor and the port fixed there as configured: a good approach ends
    down the corridor into the port. The path is drawn within :data:`_BODY_VIEW_CUT`
    view half-widths of the target only. Otherwise as :func:`fig_safety_trajectories`.
    Raises ``ValueError`` without constraints or a stored attitude (see :data:`FIGURES`).
    """
    if data.constraints is None or not _tumbling(data):
        raise ValueError("no tumbling target with path constraints")
    far = _BODY_VIEW_CUT * _SAFETY_VIEW * _constraint_size(data.constraints)
    paths = [
        (arch, _near(body_frame_steps(g), far)) for arch, g in _by_arch(data.steps, data.archs)
    ]
    fig, handles = _safety_planes(data, paths, None, _BODY_AXIS_NAMES)
    _legend_below(fig, handles, ncol=4)
    fig.suptitle(f"Safe approach in the tumbling target's body frame: true paths turned with "
                 f"the target, keep-out zone and corridor fixed ({_title(data)})")  # fmt: skip
    return _finished(fig)


def fig_safety_distance(data: ReportData) -> Figure:
    """Signed distance of the reported seed's true paths to the unsafe set against time.

    Per-step ``safety_distance_km`` (φ of :mod:`cwrend_cli.physics.constraints`:
    negative inside the unsafe set) per architecture; the zero line and the
    region below it (unsafe) marked; degradation windows shaded. Left: the
    whole run, symmetric-log axis (linear within a tenth of the smallest
    semi-axis); right: a close-up, linear, from when the first path comes
    within :data:`_SAFETY_VIEW` constraint sizes of the unsafe set. Raises
    ``ValueError`` without a keep-out zone or stored distances (see :data:`FIGURES`).
    """
    geo = data.constraints
    if geo is None or geo.semi_axes_km is None or "safety_distance_km" not in data.steps:
        raise ValueError("no distance to an unsafe set stored")
    near = _SAFETY_VIEW * _constraint_size(geo)
    unsafe = _rgb(UNSAFE_COLOUR)
    fig = _figure(14, 6.4)
    ax_all, ax_near = fig.subplots(1, 2, width_ratios=[1.4, 1])
    close: list[pd.DataFrame] = []
    for arch, g in _by_arch(data.steps, data.archs):
        style = _arch_style(arch, data.archs)
        for ax in (ax_all, ax_near):
            ax.plot(g["t_s"], g["safety_distance_km"], **style)
        within = g[g["safety_distance_km"].to_numpy(dtype=float) < near]
        close.append(within)
    horizon = float(data.steps["t_s"].max()) if not data.steps.empty else 1.0
    start = min((float(c["t_s"].min()) for c in close if not c.empty), default=0.9 * horizon)
    start = min(start, 0.9 * horizon)
    for ax in (ax_all, ax_near):
        _shade(ax, data.windows)
        _mark_unsafe_side(ax)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("distance to the unsafe set φ [km]")
    ax_all.set_yscale("symlog", linthresh=0.1 * float(np.min(geo.semi_axes_km)))
    ax_near.set_xlim(start, horizon)
    approach = data.steps[data.steps["t_s"] >= start]
    tail = approach["safety_distance_km"].to_numpy(dtype=float)
    tail = tail[np.isfinite(tail)]
    lo = min(float(tail.min()) if tail.size else 0.0, 0.0)
    hi = max(float(tail.max()) if tail.size else near, 0.0)
    pad = 0.06 * (hi - lo or 1.0)
    ax_near.set_ylim(lo - pad, hi + pad)
    _mark_deepest(ax_near, approach)
    values = data.steps["safety_distance_km"].to_numpy(dtype=float)
    values = values[np.isfinite(values)]
    if values.size:
        ax_all.set_ylim(min(values.min(), 0.0) * 1.5 - 0.01 * near, values.max() * 1.5)
    ax_all.set_title("whole run (symmetric log: linear near zero)")
    ax_near.set_title("close-up: the approach, linear")
    handles: list[Any] = _arch_handles(data.archs)
    handles.append(Patch(color=unsafe, alpha=0.2, label="φ < 0: inside the unsafe set"))
    _legend_below(fig, handles + _window_handles(data.windows), ncol=4)
    fig.suptitle(f"Distance to the unsafe set, the keep-out zone outside the corridor "
                 f"({_title(data)})")  # fmt: skip
    return _finished(fig)


def _mark_unsafe_side(ax: Axes) -> None:
    """The zero line of a distance to the unsafe set, and the unsafe side below it shaded.

    The shading reaches far below: the caller sets the axis's y limits afterwards.
    """
    ax.axhline(0.0, color="black", lw=1.1)
    ax.axhspan(-1e9, 0.0, color=_rgb(UNSAFE_COLOUR), alpha=0.08, lw=0)


def _mark_deepest(ax: Axes, steps: pd.DataFrame) -> None:
    """Mark and label the deepest point inside the unsafe set (the least φ < 0) of
    ``steps``: a violation of centimetres to metres is a sliver on a close-up whose
    scale is the approach's kilometre, and the label gives its depth and time."""
    phi = steps["safety_distance_km"].to_numpy(dtype=float)
    if not np.any(phi < 0.0):
        return
    k = int(np.nanargmin(phi))
    t, depth = float(steps["t_s"].iloc[k]), float(phi[k])
    ax.plot([t], [depth], marker="x", color="black", ms=9, mew=2, ls="none", gid="deepest")
    ax.annotate(
        f"deepest: {-depth * 1e3:.3g} m inside\nat t = {t:g} s ({steps['arch'].iloc[k]})",
        xy=(t, depth), xytext=(0.45, 0.3), textcoords="axes fraction", fontsize=9,
        arrowprops={"arrowstyle": "->", "color": "black", "lw": 0.8},
    )  # fmt: skip


def _has_constraints(data: ReportData) -> bool:
    return data.constraints is not None


def _has_body_frame(data: ReportData) -> bool:
    return data.constraints is not None and _tumbling(data)


def _has_safety_distance(data: ReportData) -> bool:
    geo = data.constraints
    return geo is not None and geo.semi_axes_km is not None and "safety_distance_km" in data.steps


# ---------------------------------------------------------------------------
# Campaign figures
# ---------------------------------------------------------------------------


def _distribution(
    data: ReportData, column: str, ylabel: str, log: bool, title: str, scale: float = 1.0
) -> Figure:
    """``column`` × ``scale`` per architecture over the seeds: violin (10+ runs), box, runs."""
    runs = data.ok_runs()
    archs = [a for a in data.archs if (runs["arch"] == a).any()]
    fig = _figure(max(8.0, 2.3 * len(archs) + 3), 6.2)
    ax = fig.subplots()
    values = []
    for a in archs:
        v = runs.loc[runs["arch"] == a, column].to_numpy(dtype=float) * scale
        v = v[np.isfinite(v)]
        values.append(np.maximum(v, _MISS_FLOOR_M) if log else v)
    positions = np.arange(1, len(archs) + 1)
    violin = all(v.size >= 10 for v in values)  # a violin of a handful of runs misleads
    if violin:
        parts = ax.violinplot(values, positions, widths=0.8, showextrema=False)
        bodies = cast("Sequence[Collection]", parts["bodies"])
        for body, a in zip(bodies, archs, strict=True):
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
    ax.set_xticks(positions, [arch_label(a) for a in archs])
    ax.set_ylabel(ylabel)
    n_seeds = runs["seed"].nunique()
    shape = "violin, " if violin else ""
    ax.set_title(f"{title} over {n_seeds} noise seeds ({shape}box = quartiles, dots = runs)")
    return _finished(fig)


def fig_miss_distribution(data: ReportData) -> Figure:
    """Terminal miss per architecture over the seeds (log scale)."""
    label = "terminal miss ‖r(T)‖ [m]"
    return _distribution(data, "miss_km", label, True, "Terminal miss", M_PER_KM)


def fig_dv_distribution(data: ReportData) -> Figure:
    """Δv per architecture over the seeds, open-loop Δv as horizontal lines."""
    return _distribution(data, "delta_v_km_s", "Δv [km/s]", False, "Δv")


#: The pairs of the paired-miss figure (x-axis, y-axis): the paper's three, then the same
#: three of the cone-program architectures, then single factor vs MTF (issue 35); at most
#: :data:`_MAX_PAIR_PANELS` are drawn, the first present, so a cone-program campaign gets
#: its own panels, and one of the single factor against MTF too.
_PAIRS = (
    ("plain_adaptive", "mtf_adaptive"),
    ("plain_fixed", "mtf_fixed"),
    ("mtf_fixed", "mtf_adaptive"),
    ("plain_adaptive_socp", "mtf_adaptive_socp"),
    ("plain_fixed_socp", "mtf_fixed_socp"),
    ("mtf_fixed_socp", "mtf_adaptive_socp"),
    ("stf_adaptive", "mtf_adaptive"),
    ("stf_fixed", "mtf_fixed"),
    ("stf_adaptive_socp", "mtf_adaptive_socp"),
    ("stf_fixed_socp", "mtf_fixed_socp"),
)
_MAX_PAIR_PANELS = 3


def _miss_by_seed(data: ReportData) -> pd.DataFrame:
    """Terminal miss [m] of the reported point's runs, one row per seed, one column per arch."""
    pivot = data.ok_runs().pivot_table(
        index="seed", columns="arch", values="miss_km", aggfunc="first"
    )
    return pivot * M_PER_KM


def _pairs(pivot: pd.DataFrame) -> list[tuple[str, str]]:
    present = [p for p in _PAIRS if p[0] in pivot.columns and p[1] in pivot.columns]
    return present[:_MAX_PAIR_PANELS]


def fig_paired_miss(data: ReportData) -> Figure:
    """Seed-by-seed miss of paired architectures (MTF vs plain; adaptive vs fixed).

    Raises ``ValueError`` when no pair of architectures ran (see :data:`FIGURES`).
    """
    pivot = _miss_by_seed(data)
    pairs = _pairs(pivot)
    if not pairs:
        raise ValueError("no paired architectures to compare")
    fig = _figure(5.4 * len(pairs) + 0.8, 6.4)
    axes = np.atleast_1d(fig.subplots(1, len(pairs)))
    for ax, (xa, ya) in zip(axes, pairs, strict=True):
        both = pivot[[xa, ya]].dropna()
        x = np.maximum(both[xa].to_numpy(dtype=float), _MISS_FLOOR_M)
        y = np.maximum(both[ya].to_numpy(dtype=float), _MISS_FLOOR_M)
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
        ax.set_xlabel(f"miss, {arch_label(xa)} [m]")
        ax.set_ylabel(f"miss, {arch_label(ya)} [m]")
        better = int((y < x).sum())
        ax.set_title(f"{arch_label(ya)} smaller\nin {better} of {x.size} seeds", fontsize=11)
        ax.legend(loc="upper left")
    title = "Paired miss per noise seed (below the diagonal: y-axis architecture is better)"
    fig.suptitle(title if len(pairs) > 1 else title.replace(" (", "\n("))
    return _finished(fig)


def _others_label(runs: pd.DataFrame, others: Sequence[str]) -> pd.Series:
    if not others:
        return pd.Series("", index=runs.index)
    return runs[list(others)].apply(
        lambda r: ", ".join(param_setting(str(k), param_value(v)) for k, v in r.items()),
        axis=1,
    )


_COMBO_STYLES = (("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"))


def _sweep_line(
    g: pd.DataFrame, stats: pd.DataFrame | None, metric: str, statistic: str, scale: float
) -> pd.DataFrame:
    """``x``, ``value``, ``low``, ``high`` per grid point of ``g`` (one arch and combination).

    From the stored statistics (rows of ``sweep.parquet`` of ``g``'s points)
    when there are any, else computed from the runs with no interval (NaN).
    """
    xs = g.groupby("point", observed=True)["_x"].first() if "point" in g.columns else None
    if stats is not None and xs is not None:
        sel = stats[(stats["metric"] == metric) & (stats["statistic"] == statistic)]
        sel = sel[sel["point"].astype(str).isin({str(p) for p in xs.index})]
        if len(sel) == len(xs):
            x = sel["point"].astype(str).map({str(k): v for k, v in xs.items()})
            return pd.DataFrame({"x": x.to_numpy(), "value": sel["value"].to_numpy() * scale,
                                 "low": sel["ci_low"].to_numpy() * scale,
                                 "high": sel["ci_high"].to_numpy() * scale})  # fmt: skip
    agg = g.groupby("_x")[metric].agg(statistic) * scale
    nan = np.full(len(agg), np.nan)
    return pd.DataFrame({"x": agg.index.to_numpy(), "value": agg.to_numpy(), "low": nan,
                         "high": nan})  # fmt: skip


def fig_sweep(data: ReportData, param: str) -> Figure:
    """Median miss and mean Δv against one swept parameter, per architecture.

    ``param`` is the ``param.<key>`` column. The bands are the 95 % intervals
    of ``sweep.parquet`` (none without it, or when the runs are pooled). With
    other swept parameters, each of their combinations (up to four) gets its
    own line style; with more, the runs are pooled over them (stated in the
    title). Axes are labelled with the parameter's symbol and unit, values as
    given. The miss axis is logarithmic only when the drawn misses span more
    than a decade (:func:`spans_decades`), else linear: misses within
    millimetres of each other would read as one unlabelled log tick. With path
    constraints (a third panel) the median over the seeds of each run's
    minimum signed distance to the unsafe set (the safety rows of the
    statistics file, as the report's safety table; negative: inside), linear,
    the unsafe side of zero shaded.
    """
    runs = data.runs[data.runs["status"] == "ok"].copy()
    key = param.removeprefix(PARAM_PREFIX)
    x_all, numeric = param_values(runs[param])
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
    stats = data.stats
    if pooled or stats is None or "point" not in stats.columns:
        stats = None
    else:
        stats = stats[stats["kind"] == "marginal"]
    safety = _has_constraints(data) and SAFETY_METRIC in runs.columns
    fig = _figure(19 if safety else 13, 6.6)
    axes = fig.subplots(1, 3 if safety else 2)
    ax_m, ax_v = axes[0], axes[1]
    panels = [(ax_m, "miss_km", "median", M_PER_KM), (ax_v, "delta_v_km_s", "mean", 1.0)]
    if safety:
        panels.append((axes[2], SAFETY_METRIC, "median", M_PER_KM))
    drawn: list[tuple[Axes, str, str, str, np.ndarray, pd.DataFrame]] = []
    for a in data.archs:
        c = arch_colour(a, data.archs.index(a))
        arch_stats = stats[stats["arch"] == a] if stats is not None else None
        for (ls, marker), combo in zip(_COMBO_STYLES, combos, strict=False):
            g = runs[(runs["arch"] == a) & (runs["_other"] == combo)]
            if g.empty:
                continue
            for ax, metric, statistic, scale in panels:
                line = _sweep_line(g, arch_stats, metric, statistic, scale)
                if not numeric:
                    line["x"] = [pos[v] for v in line["x"]]
                line = line.sort_values("x")
                drawn.append((ax, c, ls, marker, line["x"].to_numpy(dtype=float), line))
    misses = [line[["value", "low", "high"]].to_numpy() for ax, *_, line in drawn if ax is ax_m]
    log_miss = spans_decades(np.concatenate([m.ravel() for m in misses]) if misses else [])
    banded = False
    for ax, c, ls, marker, xs, line in drawn:
        low = _MISS_FLOOR_M if ax is ax_m and log_miss else -np.inf
        ax.plot(xs, np.maximum(line["value"], low), ls=ls, marker=marker, color=c)
        if line["low"].notna().all():
            banded = True
            ax.fill_between(xs, np.maximum(line["low"], low), np.maximum(line["high"], low),
                            color=c, alpha=0.12, lw=0)  # fmt: skip
    for _, row in data.ref_summary.iterrows():
        name = str(row["arch"]).removeprefix("open_loop_")
        st_ = _ref_style(name)
        ax_v.axhline(float(row["delta_v_km_s"]), color=st_["color"], ls=st_["ls"], lw=1.4)
    _miss_scale(ax_m, log_miss)
    symbol = param_label(key)
    for ax in axes:
        ax.set_xlabel(symbol)
        if numeric:
            ax.set_xticks(levels, [format_value(v) for v in levels])
        else:
            ax.set_xticks(range(len(levels)), [category_text(str(v)) for v in levels])
    band = " (band: 95 % interval)" if banded else ""
    ax_m.set_ylabel("median terminal miss [m]")
    ax_m.set_title(f"median miss over seeds{band}")
    ax_v.set_ylabel("mean Δv [km/s]")
    ax_v.set_title(f"mean Δv over seeds{band}")
    handles: list[Any] = _arch_handles_plain([a for a in data.archs if (runs["arch"] == a).any()])
    if safety:
        ax_s = axes[2]
        _mark_unsafe_side(ax_s)
        values = np.concatenate(
            [line[["value", "low", "high"]].to_numpy().ravel() for ax, *_, line in drawn
             if ax is ax_s] + [np.zeros(1)]
        )  # fmt: skip
        values = values[np.isfinite(values)]
        lo, hi = float(values.min()), float(values.max())
        pad = 0.08 * (hi - lo or 1.0)
        ax_s.set_ylim(lo - pad, hi + pad)
        ax_s.set_ylabel("median min distance to the unsafe set [m]")
        ax_s.set_title(f"closest approach to the unsafe set{band}")
        handles.append(Patch(color=_rgb(UNSAFE_COLOUR), alpha=0.2,
                             label="< 0: inside the unsafe set"))  # fmt: skip
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
    what = f" (pooled over {', '.join(param_symbol(o)[0] for o in others)})" if pooled else ""
    fig.suptitle(f"Sweep of {param_symbol(key)[0]} ({key}){what}")
    return _finished(fig)


#: A log axis is drawn only for values spanning more than this ratio (a decade):
#: within one, a log axis shows at most one labelled tick.
LOG_AXIS_MIN_RATIO = 10.0
#: The per-run safety column the sweep figure draws (the minimum signed distance [km]).
SAFETY_METRIC = "safety_min_distance_km"


def spans_decades(values: Any, floor: float = _MISS_FLOOR_M) -> bool:
    """Whether ``values`` (misses by default, each raised to ``floor``) span more than a decade.

    The rule of the sweep figure's miss axis: logarithmic when its largest
    drawn value exceeds :data:`LOG_AXIS_MIN_RATIO` times its smallest, linear
    otherwise. NaN (no interval) is ignored; nothing to draw is linear.
    """
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        return False
    v = np.maximum(v, floor)
    return bool(v.max() > LOG_AXIS_MIN_RATIO * v.min())


def _miss_scale(ax: Axes, log: bool) -> None:
    """The miss axis ``ax`` logarithmic (``log``: :func:`spans_decades`), else linear with
    plain labels: misses close together read as themselves (0.14402), not as an offset
    (1e-5+1.44e-1)."""
    if log:
        ax.set_yscale("log")
    else:
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)


#: Bins of a design figure's trend (equal counts of design points).
_DESIGN_BINS = 8


def fig_design(data: ReportData, param: str) -> Figure:
    """Mean miss and mean Δv of every design point against one sampled parameter.

    A sampled design (``sweep --design``) has hundreds of points, each at its
    own value of every parameter, so there is no line per value as in
    :func:`fig_sweep`: each point is a dot (its mean over the seeds), and a
    trend per architecture is drawn through :data:`_DESIGN_BINS` bins of equal
    point counts, the mean of the bin's points with its 95 % interval (normal
    approximation; for the miss on a log axis, the geometric mean and the
    interval of the log) as a band. The miss axis follows the sweep figure's
    rule (:func:`spans_decades`: logarithmic only when the drawn misses span
    more than a decade, else linear with plain labels), as does the parameter's
    axis; a categorical parameter is placed at its categories.
    """
    runs = data.runs[data.runs["status"] == "ok"]
    key = param.removeprefix(PARAM_PREFIX)
    per_point = runs.groupby(["arch", "point"], observed=True).agg(
        x=(param, "first"), miss=("miss_km", "mean"), dv=("delta_v_km_s", "mean")
    )
    per_point = per_point.reset_index()
    x_all, numeric = param_values(per_point["x"])
    levels = sorted(set(x_all)) if not numeric else []
    xs = np.asarray([levels.index(v) for v in x_all], dtype=float) if not numeric else x_all
    per_point["_x"] = xs
    log_miss = spans_decades(per_point["miss"].to_numpy(dtype=float) * M_PER_KM)
    fig = _figure(13, 6.6)
    ax_m, ax_v = fig.subplots(1, 2)
    for a in data.archs:
        g = per_point[per_point["arch"] == a].sort_values("_x")
        if g.empty:
            continue
        c = arch_colour(a, data.archs.index(a))
        for ax, column, scale, log in (
            (ax_m, "miss", M_PER_KM, log_miss),
            (ax_v, "dv", 1.0, False),
        ):
            y = g[column].to_numpy(dtype=float) * scale
            if log:
                y = np.maximum(y, _MISS_FLOOR_M)
            x = g["_x"].to_numpy(dtype=float)
            ax.scatter(x, y, s=9, color=c, alpha=0.35, lw=0)
            # the trend of a log axis is a geometric mean (its band stays positive)
            t = np.log10(y) if log else y
            bins = np.array_split(np.arange(len(x)), min(_DESIGN_BINS, len(x)))
            centre = np.array([x[b].mean() for b in bins])
            mean = np.array([t[b].mean() for b in bins])
            half = np.array([
                1.96 * t[b].std(ddof=1) / np.sqrt(len(b)) if len(b) > 1 else np.nan
                for b in bins
            ])  # fmt: skip
            lo, mid, hi = mean - half, mean, mean + half
            if log:
                lo, mid, hi = 10.0**lo, 10.0**mid, 10.0**hi
            ax.plot(centre, mid, color=c, lw=2.0)
            ax.fill_between(centre, lo, hi, color=c, alpha=0.15, lw=0)
    positive = numeric and np.nanmin(xs) > 0
    for ax in (ax_m, ax_v):
        ax.set_xlabel(param_label(key))
        if positive and spans_decades(xs, floor=0.0):
            ax.set_xscale("log")
        if not numeric:
            ax.set_xticks(range(len(levels)), [str(v) for v in levels])
    _miss_scale(ax_m, log_miss)
    ax_m.set_ylabel("mean terminal miss over seeds [m]")
    trend = "binned geometric mean" if log_miss else "binned mean"
    ax_m.set_title(f"miss per design point (dots); {trend}, 95 % band")
    ax_v.set_ylabel("mean Δv over seeds [km/s]")
    ax_v.set_title("Δv per design point (dots); binned mean, 95 % band")
    _legend_below(fig, _arch_handles_plain([a for a in data.archs if (runs["arch"] == a).any()]),
                  ncol=4)  # fmt: skip
    fig.suptitle(f"Sampled design: {param_symbol(key)[0]} ({key})")
    return _finished(fig)


# ---------------------------------------------------------------------------
# Sensitivity of a sampled design (``sweep --design sobol``)
# ---------------------------------------------------------------------------

#: Metrics of the sensitivity figure and table (``sensitivity.parquet``'s ``metric``), shown as.
SENSITIVITY_METRICS: tuple[tuple[str, str], ...] = (
    ("miss_km", "terminal miss"),
    ("delta_v_km_s", "Δv"),
)
#: The two Sobol indices: statistic, legend label, colour.
SOBOL_INDICES: tuple[tuple[str, str, str], ...] = (
    ("S1", "S1 (first-order)", "#4c72b0"),
    ("ST", "ST (total)", "#dd8452"),
)


def sensitivity_archs(data: ReportData) -> list[str]:
    """Architectures with stored Sobol indices, in canonical order."""
    table = data.sensitivity
    if table is None or table.empty:
        return []
    present = set(table["arch"])
    return [a for a in data.archs if a in present] + sorted(present - set(data.archs))


def fig_sensitivity(data: ReportData) -> Figure:
    """Sobol indices of a ``sobol`` design: one panel per architecture (row) and metric (column).

    Per parameter (labelled by symbol and unit) the first-order index S1 and
    the total index ST side by side as horizontal bars, their 95 % intervals
    (``ci_low``, ``ci_high`` of ``sensitivity.parquet``) as error bars. The
    indices are of the mean over the seeds of each design point. Raises
    ``ValueError`` without stored indices (see :data:`FIGURES`).
    """
    table = data.sensitivity
    archs = sensitivity_archs(data)
    if table is None or not archs:
        raise ValueError("no sensitivity indices stored")
    metrics = [(m, name) for m, name in SENSITIVITY_METRICS if (table["metric"] == m).any()]
    params = list(dict.fromkeys(table["parameter"]))
    # S1 and ST of a sobol design; S1 alone of RBD-FAST (lhs, random); S2 is in the tables
    indices = [t for t in SOBOL_INDICES if (table["statistic"] == t[0]).any()]
    height = 1.8 + len(archs) * (0.62 * len(params) + 1.3)
    fig = _figure(6.2 * len(metrics) + 2.2, height)
    axes = np.atleast_2d(fig.subplots(len(archs), len(metrics), sharey=True, squeeze=False))
    ys = np.arange(len(params), dtype=float)
    bar = 0.36
    for row, a in enumerate(archs):
        for col, (metric, name) in enumerate(metrics):
            ax = axes[row, col]
            sel = table[(table["arch"] == a) & (table["metric"] == metric)]
            for i, (stat, label, colour) in enumerate(indices):
                rows = sel[sel["statistic"] == stat].set_index("parameter").reindex(params)
                value = rows["value"].to_numpy(dtype=float)
                err = _error_bars(value, rows["ci_low"].to_numpy(dtype=float),
                                  rows["ci_high"].to_numpy(dtype=float))  # fmt: skip
                offset = (i - (len(indices) - 1) / 2) * bar
                ax.barh(ys + offset, np.nan_to_num(value), height=bar, color=colour,
                        xerr=err, capsize=3, label=label,
                        error_kw={"lw": 1.1, "ecolor": "black"})  # fmt: skip
            ax.axvline(0.0, color="black", lw=0.9)
            ax.axvline(1.0, color="black", lw=0.9, ls=":")  # an index lies in [0, 1]
            ax.set_yticks(ys, [param_label(p) for p in params])
            ax.set_ylim(len(params) - 0.5, -0.5)  # the first parameter on top
            n = int(sel["n_seeds"].min()) if "n_seeds" in sel and not sel.empty else None
            seeds = f", {n} seed{'s' if n != 1 else ''} per point" if n is not None else ""
            ax.set_title(f"{arch_label(a)} · {name}{seeds}", fontsize=10.5)
            if row == len(archs) - 1:
                ax.set_xlabel("Sobol index of the mean over seeds [-]")
    handles: list[Any] = [Patch(color=colour, label=label) for _, label, colour in indices]
    handles.append(Line2D([], [], color="black", marker="|", ms=10, ls="-", lw=1.1,
                          label="95 % interval"))  # fmt: skip
    _legend_below(fig, handles, ncol=3)
    fig.suptitle("Sensitivity indices of the sampled design")
    return _finished(fig)


def _has_sensitivity(data: ReportData) -> bool:
    return bool(sensitivity_archs(data))


# ---------------------------------------------------------------------------
# The registry of the report's figures
# ---------------------------------------------------------------------------


def _always(data: ReportData) -> bool:
    return True


def _has_pairs(data: ReportData) -> bool:
    return data.multi_seed() and bool(_pairs(_miss_by_seed(data)))


@dataclass(frozen=True)
class FigureEntry:
    """One figure of the report: PNG file, caption, drawing function, when it applies."""

    file: str
    caption: str
    draw: Callable[[ReportData], Figure]
    applies: Callable[[ReportData], bool] = _always
    #: shows every grid or design point (named by :attr:`ReportData.worlds`), not the reported one
    every_point: bool = False


@dataclass(frozen=True)
class SweepFigureEntry:
    """A figure drawn once per swept parameter with more than one value (grid sweeps only).

    ``{key}`` in ``file`` and ``caption`` stands for the swept key (made safe
    for a file name); ``draw`` takes the ``param.<key>`` column.
    """

    file: str
    caption: str
    draw: Callable[[ReportData, str], Figure]
    design: bool = False  # drawn for a sampled design's parameters instead of a grid's


#: The report's figures, in the order they are drawn and listed in report.md.
FIGURES: tuple[FigureEntry | SweepFigureEntry, ...] = (
    FigureEntry(
        "fig1_trajectories.png",
        "True relative trajectories, 3D and x–z (paper Fig. 1, top).",
        fig_trajectories,
    ),
    FigureEntry(
        "fig2_control.png",
        f"Thrust magnitude per architecture and cumulative Δv (paper Fig. 2, top). {DV_CAPTION}",
        fig_control,
    ),
    FigureEntry(
        "fig3_eps_score.png",
        "Homotopy parameter ε and the composite score (paper Fig. 2, bottom).",
        fig_eps_score,
    ),
    FigureEntry(
        "fig4_nis_mtf.png",
        "NIS and the inflation ratio ρ with the degradation windows shaded (paper Fig. 4): "
        "for MTF the MTF ratio tr(S_MTF)/tr(S) (paper Eq. 23), for the single-factor "
        "baseline (stf) (λ − 1) tr(R)/tr(S).",
        fig_nis_mtf,
    ),
    FigureEntry(
        "fig5_errors.png",
        "Position error to the target and estimation error, log scale, with "
        "terminal close-ups (paper Figs 1 bottom and 3).",
        fig_errors,
    ),
    FigureEntry(
        "fig6_dv_vs_miss.png",
        "Δv against terminal miss for every run; vertical lines: open-loop Δv (the fuel "
        "plan's trapezoid, with the exact continuous optimum beside it: a run left of the line "
        f"is the trapezoid's artefact, not a saving). {DV_CAPTION}",
        fig_dv_vs_miss,
    ),
    FigureEntry(
        "miss_distribution.png",
        "Terminal miss per architecture over the seeds (log scale).",
        fig_miss_distribution,
        ReportData.multi_seed,
    ),
    FigureEntry(
        "dv_distribution.png",
        f"Δv per architecture over the seeds. {DV_CAPTION}",
        fig_dv_distribution,
        ReportData.multi_seed,
    ),
    FigureEntry(
        "paired_miss.png",
        "Miss of paired architectures on the same noise, seed by seed.",
        fig_paired_miss,
        _has_pairs,
    ),
    SweepFigureEntry(
        "sweep_{key}.png",
        "Median miss and mean Δv against `{key}` (the miss on a log axis only when it spans "
        "more than a decade); with path constraints also the median minimum signed distance "
        f"to the unsafe set (negative: inside). {DV_CAPTION}",
        fig_sweep,
    ),
    SweepFigureEntry(
        "design_{key}.png",
        "Mean miss and mean Δv of every design point against `{key}` (dots), with a binned "
        "mean (geometric for the miss on a log axis, drawn only when the misses span more "
        f"than a decade) and its 95 % band per architecture. {DV_CAPTION}",
        fig_design,
        design=True,
    ),
    FigureEntry(
        "sensitivity.png",
        "Sensitivity of the sampled design: first-order (S1) and total (ST) Sobol indices of "
        "the mean miss and mean Δv over the seeds of each design point (S1 alone, by RBD-FAST, "
        "for an lhs or random design), per parameter and architecture; error bars: 95 % "
        f"intervals (sensitivity.parquet). {DV_CAPTION}",
        fig_sensitivity,
        _has_sensitivity,
        every_point=True,
    ),
    FigureEntry(
        "nees.png",
        "Filter consistency: NEES per architecture against time, median and band over the "
        "seeds, with the 95 % interval of χ²₆ (where one run's NEES lies if the filter is "
        "consistent; mean 6), log scale.",
        fig_nees,
        _has_nees,
    ),
    FigureEntry(
        "consistency.png",
        "Filter consistency over the seeds: the ensemble mean NEES and NIS per architecture at "
        "each step against the 95 % χ² band of a consistent filter's mean (shaded: χ²(N n)/N "
        "for N seeds, n = 6 and the sensor's m: 3, or 2 for angles; Bar-Shalom et al. 2001, "
        "§5.4.2), log scale.",
        fig_consistency,
        _has_nees,
    ),
    FigureEntry(
        "safety_trajectories.png",
        "Path constraints: the true paths of the reported seed near the target, projected on "
        "the x–y, x–z and y–z planes, with the keep-out zone (red) and the approach corridor "
        "(green, dashed; inside it the keep-out zone is waived); crosses: nodes inside the "
        "unsafe set.",
        fig_safety_trajectories,
        _has_constraints,
    ),
    FigureEntry(
        "safety_body_frame.png",
        "Tumbling target: the same true paths in the target's body frame, each step's position "
        "turned by the target's attitude at that step, with the keep-out zone, the corridor "
        "and the docking port fixed there (a good approach ends down the corridor); in the "
        "relative-frame figure above they are drawn as they stood at t = 0.",
        fig_safety_body_frame,
        _has_body_frame,
    ),
    FigureEntry(
        "safety_distance.png",
        "Signed distance of the reported seed's true paths to the unsafe set (negative: "
        "inside), the whole run and a close-up of the approach (its deepest point inside "
        "marked and labelled), degradation windows shaded.",
        fig_safety_distance,
        _has_safety_distance,
    ),
)


@dataclass(frozen=True)
class PlannedFigure:
    """A figure of one report: its PNG file name, its caption and how to draw it."""

    file: str
    caption: str
    draw: Callable[[], Figure]


def _file_key(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "param"


def _with_world(draw: Callable[[], Figure], world: str) -> Figure:
    """The figure of ``draw`` with the simulated world added to its title.

    Under the figure's title (a second line of its suptitle). A figure of one
    titled axes (fig. 6, the distributions) has that title made its suptitle
    first, so the world is under it there too, not above it.
    """
    fig = draw()
    title = fig.get_suptitle()
    titled = [ax for ax in fig.axes if ax.get_title()]
    if not title and len(titled) == 1:
        title = titled[0].get_title()
        titled[0].set_title("")
    fig.suptitle(f"{title}\n{world}" if title else world)
    return fig


def _captioned(caption: str, world: str) -> str:
    return f"{caption} Simulated world: {world}."


def planned_figures(data: ReportData) -> tuple[PlannedFigure, ...]:
    """The figures of :data:`FIGURES` that apply to ``data``, in report order.

    Each one's title and caption name the simulated world of the point it
    shows (:attr:`ReportData.world`), or of every point
    (:attr:`ReportData.worlds`) for the sweep, design and sensitivity figures.
    """
    out: list[PlannedFigure] = []
    world = data.world
    worlds = data.worlds if data.params else world
    for entry in FIGURES:
        if isinstance(entry, SweepFigureEntry):
            for param in data.params if entry.design == data.design else ():
                key = _file_key(param.removeprefix(PARAM_PREFIX))
                out.append(
                    PlannedFigure(
                        entry.file.format(key=key),
                        _captioned(entry.caption.format(key=key), worlds),
                        partial(_with_world, partial(entry.draw, data, param), worlds),
                    )
                )
        elif entry.applies(data):
            shown = worlds if entry.every_point else world
            out.append(
                PlannedFigure(
                    entry.file,
                    _captioned(entry.caption, shown),
                    partial(_with_world, partial(entry.draw, data), shown),
                )
            )
    return tuple(out)


# ---------------------------------------------------------------------------
# Two campaigns compared (``cwrend compare``; not part of a report)
# ---------------------------------------------------------------------------

#: Axis label and scale of each compared metric (misses in m).
_COMPARE_AXES: dict[str, tuple[str, float]] = {
    "miss_km": ("miss, A − B [m]", 1e3),
    "delta_v_km_s": ("Δv, A − B [km/s]", 1.0),
    "fuel_penalty_pct": ("fuel penalty, A − B [points of %]", 1.0),
    "delta_v_applied_km_s": ("applied Δv, A − B [km/s]", 1.0),
    "fuel_penalty_applied_pct": ("applied fuel penalty, A − B [points of %]", 1.0),
}
_SHARE_MARKERS = ("s", "^", "v", "<", ">")


def _error_bars(value: Any, low: Any, high: Any) -> np.ndarray:
    """Error bar lengths ``(2, k)`` below and above ``value`` of the interval ``[low, high]``.

    Never negative (matplotlib refuses them): an end that rounding put a hair
    past the estimate (or an interval that does not hold it) draws no bar on
    that side; a missing interval (NaN) draws none.
    """
    v = np.atleast_1d(np.asarray(value, dtype=float))
    lo = np.atleast_1d(np.asarray(low, dtype=float))
    hi = np.atleast_1d(np.asarray(high, dtype=float))
    bars: np.ndarray = np.clip(np.nan_to_num(np.vstack([v - lo, hi - v])), 0.0, None)
    return bars


def _compare_row_label(first: pd.Series, groups: Sequence[str]) -> str:
    label = arch_label(str(first["arch"]))
    return "\n".join([label, *swept_values(first, groups)])


def fig_compare(
    frame: pd.DataFrame,
    label_a: str,
    label_b: str,
    worlds: tuple[str, str] | None = None,
    differences: Sequence[tuple[str, Any, Any]] | None = None,
) -> Figure:
    """Paired differences A − B per architecture (and grid point) with 95 % intervals.

    ``frame`` holds the rows of ``compare.parquet``. One panel per metric: the
    mean (circle) and median (diamond) of the per-seed differences with their
    bootstrap intervals, zero marked; a last panel: the share of seeds where
    A is lower, with its Wilson interval, one half marked. ``worlds``: the
    simulated worlds of A and B (:func:`~cwrend_cli.report.load.results_world`),
    named under the title (once when they are the same). ``differences``: what
    differs between their configurations, ``(dotted key, A's value, B's value)``
    (``campaign.compare.config_diff``), the first :data:`_DIFFERENCES_SHOWN`
    named under the title and the count of the others.
    """
    groups = [c for c in frame.columns if c in ("point_a", "point_b") or c.startswith(PARAM_PREFIX)]
    metrics = [m for m in _COMPARE_AXES if m in set(frame["metric"])]
    keys = [*groups, "arch"]
    rows = list(frame.groupby(keys, sort=False, dropna=False)) if keys else []
    archs = list(dict.fromkeys(str(a) for a in frame["arch"]))
    fig = _figure(3.9 * (len(metrics) + 1) + 1.5, 2.2 + 0.8 * max(2, len(rows)))
    axes = np.atleast_1d(fig.subplots(1, len(metrics) + 1, sharey=True))
    ys = np.arange(len(rows))[::-1].astype(float)
    labels = []
    for y, (_, g) in zip(ys, rows, strict=True):
        first = g.iloc[0]
        labels.append(_compare_row_label(first, groups))
        colour = arch_colour(str(first["arch"]), archs.index(str(first["arch"])))
        for ax, metric in zip(axes, metrics, strict=False):
            scale = _COMPARE_AXES[metric][1]
            get = {r.statistic: r for _, r in g[g["metric"] == metric].iterrows()}
            for name, marker, dy in (("mean_diff", "o", 0.13), ("median_diff", "D", -0.13)):
                r = get[name]
                err = _error_bars(r["value"], r["ci_low"], r["ci_high"]) * scale
                ax.errorbar(r["value"] * scale, y + dy, xerr=err, fmt=marker,
                            color=colour, ms=6, capsize=3, lw=1.6)  # fmt: skip
        for i, metric in enumerate(metrics):
            r = g[(g["metric"] == metric) & (g["statistic"] == "frac_better")].iloc[0]
            err = _error_bars(r["value"], r["ci_low"], r["ci_high"])
            dy = 0.2 * (i - (len(metrics) - 1) / 2)
            axes[-1].errorbar(r["value"], y - dy, xerr=err, color=colour,
                              fmt=_SHARE_MARKERS[i], ms=6, capsize=3, lw=1.6)  # fmt: skip
    for ax, metric in zip(axes, metrics, strict=False):
        ax.axvline(0.0, color="black", lw=1)
        ax.set_xlabel(_COMPARE_AXES[metric][0])
        ax.xaxis.set_major_locator(MaxNLocator(nbins=4))  # long labels such as −0.0035
    axes[-1].axvline(0.5, color="black", lw=1, ls="--")
    axes[-1].set_xlim(-0.02, 1.02)
    axes[-1].set_xlabel("share of seeds where A is lower")
    axes[0].set_yticks(ys, labels)
    axes[0].set_ylim(-0.7, len(rows) - 0.3)
    n = int(frame["n"].max()) if not frame.empty else 0
    handles = [
        Line2D([], [], marker="o", ls="", color="black", label="mean of A − B (95 % bootstrap)"),
        Line2D([], [], marker="D", ls="", color="black", label="median of A − B (95 % bootstrap)"),
    ]
    for i, m in enumerate(metrics):
        what = _COMPARE_AXES[m][0].split(",")[0]
        handles.append(Line2D([], [], marker=_SHARE_MARKERS[i], ls="", color="black",
                              label=f"share A lower, {what} (95 % Wilson)"))  # fmt: skip
    _legend_below(fig, handles, ncol=2 if len(handles) == 4 else 3)
    title = f"Paired differences per noise seed, A = {label_a}, B = {label_b} (n ≤ {n})"
    if worlds is not None:
        world_a, world_b = worlds
        same = f"A and B: {world_a}" if world_a == world_b else f"A: {world_a}  |  B: {world_b}"
        title = f"{title}\n{same}"
    if differences is not None:
        title = f"{title}\n{_differences_line(differences)}"
    fig.suptitle(title)
    return _finished(fig)


#: Configuration differences named under the title of the comparison figure.
_DIFFERENCES_SHOWN = 3


def _differences_line(differences: Sequence[tuple[str, Any, Any]]) -> str:
    """``A and B differ in schedule.beta: A 0.25, B 0.5``: the first few, a line each, then
    a count of the others."""
    if not differences:
        return "A and B have the same configuration"
    lines = [difference_text(*d) for d in differences[:_DIFFERENCES_SHOWN]]
    more = len(differences) - _DIFFERENCES_SHOWN
    if more > 0:
        lines.append(f"and {more} more setting(s): config_diff in compare.parquet")
    return "A and B differ in " + "\n".join(lines)
