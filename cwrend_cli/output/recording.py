"""Rerun recordings of closed-loop runs (I/O at the edge, after the numerics).

:func:`record_case` writes one ``.rrd`` file that overlays the architectures
of one noise realisation and the open-loop references, on a ``sim_time``
timeline (a duration in seconds), with a default blueprint laid out like the
paper's Figures 1–2: the 3D trajectories on the left, the control magnitude,
cumulative Δv, ε and score in the middle, the errors, NIS and MTF ratio on
the right. Open it with ``rerun <file>.rrd``.

Entity paths (``<slug>`` is an architecture slug, e.g. ``mtf_adaptive``)::

    /arch/<slug>/trajectory/true       LineStrips3D (whole path, static)
                                       + Points3D (current position, over time)
    /arch/<slug>/trajectory/estimate   the same for the filter estimate
    /arch/<slug>/thrust                Arrows3D from the current position along u (scaled)
    /arch/<slug>/line_of_sight         Arrows3D from the true position along the measured
                                       line of sight (a nonlinear [sensor], issue 35)
    /arch/<slug>/{u_norm, dv_cum, eps, score, score_filtered, nis, mtf_ratio,
                  pos_err_km, est_err_km}   Scalars over sim_time
    /arch/<slug>/resolve_success       Scalars at the re-solve times (1 success, 0 not)
    /reference/{energy,fuel}/trajectory  LineStrips3D + Points3D of the open-loop plan
    /reference/{energy,fuel}/{u_norm, dv_cum, pos_err_km}
    /target                            Points3D at the origin (static)
    /target/body                       Transform3D: a tumbling target's attitude over time
                                       (body to relative frame; with target.attitude =
                                       "tumbling", issue 34)
    /target/body/axes                  Arrows3D: the body's x, y, z axes (red, green, blue)
    /degradation/<i>                   Scalars 0/1 (window i active) + TextLog at start/end
    /constraints/{keep_out, corridor}  Ellipsoids3D, LineStrips3D (with [constraints], static;
                                       a tumbling target's under /target/body, turning)
    /arch/<slug>/safety_distance_km    Scalars: φ to the unsafe set (with [constraints])
    /arch/<slug>/trajectory/unsafe     Points3D: the nodes inside the unsafe set (static)
    /about                             TextDocument: what is in the recording, arrow scale

Every time series is sent with one ``send_columns`` call (no per-step
logging); samples that are NaN (e.g. the NIS at t = 0, where there is no
measurement) are left out. Units: km, s, km/s, km/s².

``rerun`` is imported lazily (about 0.4 s), only when a recording is
written, so the campaign workers that record nothing never load it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict, Unpack

import numpy as np

from cwrend_cli.errors import CwrendError
from cwrend_cli.output.files import atomic_path
from cwrend_cli.physics import measurement_models as mm
from cwrend_cli.physics.constraints import ellipsoids
from cwrend_cli.physics.metrics import cumulative_delta_v
from cwrend_cli.physics.params import ALL_ARCHITECTURES, Window
from cwrend_cli.physics.sensors import in_window

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

    from cwrend_cli.physics.constraints import Geometry
    from cwrend_cli.physics.references import OpenLoopResult
    from cwrend_cli.physics.simulation import References, RunResult


class RecordingError(CwrendError):
    """A recording cannot be written (e.g. Rerun disabled by ``RERUN=off``)."""


#: Colour of each architecture (hex), shared by the recordings and the report figures:
#: every slug of ``ALL_ARCHITECTURES`` has its own. A cone-program architecture takes the
#: light shade of its shooting counterpart (matplotlib's tab20 pairs); the single-factor
#: baseline is pink and cyan, away from the references and the degradation windows.
ARCH_COLOURS: Mapping[str, str] = {
    "plain_fixed": "#d62728",  # red
    "mtf_fixed": "#ff7f0e",  # orange
    "plain_adaptive": "#1f77b4",  # blue
    "mtf_adaptive": "#2ca02c",  # green
    "plain_fixed_socp": "#ff9896",  # light red
    "mtf_fixed_socp": "#ffbb78",  # light orange
    "plain_adaptive_socp": "#aec7e8",  # light blue
    "mtf_adaptive_socp": "#98df8a",  # light green
    "stf_fixed": "#e377c2",  # pink
    "stf_adaptive": "#17becf",  # cyan
    "stf_fixed_socp": "#f7b6d2",  # light pink
    "stf_adaptive_socp": "#9edae5",  # light cyan
}
#: Colour of each open-loop reference (hex).
REFERENCE_COLOURS: Mapping[str, str] = {
    "energy": "#9467bd",  # purple
    "fuel": "#8c8c8c",  # grey
}
#: Colour of the degradation-window series and shading (hex).
DEGRADATION_COLOUR = "#bcbd22"
_FALLBACK = ("#8c564b", "#7f7f7f")
#: Names of the colours above, for the colour key of the about panel.
COLOUR_NAMES: Mapping[str, str] = {
    "#d62728": "red",
    "#ff7f0e": "orange",
    "#1f77b4": "blue",
    "#2ca02c": "green",
    "#ff9896": "light red",
    "#ffbb78": "light orange",
    "#aec7e8": "light blue",
    "#98df8a": "light green",
    "#f7b6d2": "light pink",
    "#9edae5": "light cyan",
    "#9467bd": "purple",
    "#8c8c8c": "grey",
    "#bcbd22": "olive",
    "#17becf": "cyan",
    "#e377c2": "pink",
    "#8c564b": "brown",
    "#7f7f7f": "dark grey",
}

TIMELINE = "sim_time"

#: Scalar series of each architecture: entity name -> (label, unit).
ARCH_SERIES: Mapping[str, tuple[str, str]] = {
    "u_norm": ("‖u‖", "km/s²"),
    "dv_cum": ("cumulative Δv", "km/s"),
    "eps": ("ε", "-"),
    "score": ("score s", "-"),
    "score_filtered": ("filtered score s̄", "-"),
    "nis": ("NIS", "-"),
    "mtf_ratio": ("inflation ratio ρ (MTF: paper Eq. 23)", "-"),
    "pos_err_km": ("position error ‖r‖", "km"),
    "est_err_km": ("estimation error ‖r̂ − r‖", "km"),
}
REFERENCE_SERIES = ("u_norm", "dv_cum", "pos_err_km")


def inflation_ratio_names(slugs: Sequence[str]) -> tuple[str, str]:
    """Name and definition of the inflation ratio ρ that the ``mtf_ratio`` column holds.

    For MTF it is the MTF ratio tr(S_MTF)/tr(S) (paper Eq. 23); for a single-factor
    (``stf``) run it is (λ − 1) tr(R)/tr(S), the same definition applied to the single
    factor (docs/method.md, "The single-factor baseline"); both when both are shown.
    """
    estimators = {ALL_ARCHITECTURES[s].estimator for s in slugs if s in ALL_ARCHITECTURES}
    if "stf" not in estimators:
        return "MTF ratio", "tr(S_MTF)/tr(S)"
    if "mtf" not in estimators:
        return "single-factor ratio", "(λ − 1) tr(R)/tr(S)"
    return "inflation ratio", "MTF tr(S_MTF)/tr(S), single factor (λ − 1) tr(R)/tr(S)"


def arch_colour(slug: str, index: int = 0) -> str:
    """Hex colour of architecture ``slug`` (a fallback cycle for unknown slugs)."""
    return ARCH_COLOURS.get(slug, _FALLBACK[index % len(_FALLBACK)])


def rgb(hex_colour: str) -> tuple[int, int, int]:
    """``"#rrggbb"`` as an (r, g, b) tuple of 0–255 integers."""
    h = hex_colour.lstrip("#")
    return int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16)


def window_activity(t_s: np.ndarray, window: Window) -> np.ndarray:
    """1.0 where the window is active (``start_s ≤ t ≤ end_s``), else 0.0."""
    return in_window(np.asarray(t_s, dtype=float), window).astype(float)


def window_label(i: int, window: Window) -> str:
    """Degradation window ``i`` for legends, e.g. ``window 1: R×300 + 17.5 m bias``."""
    return f"window {i}: {window.label}"


# ---------------------------------------------------------------------------
# Blueprint
# ---------------------------------------------------------------------------


def _series_view(rrb: Any, name: str, paths: Sequence[str]) -> Any:
    """A time-series view of the whole run, without a legend (colours: see the about panel).

    The visible time range runs from the start to the end of ``sim_time``
    (both boundaries infinite), so the view shows the whole history wherever
    the time cursor is, instead of Rerun's default window around the cursor.
    """
    return rrb.TimeSeriesView(
        name=name,
        origin="/",
        contents=list(paths),
        plot_legend=rrb.PlotLegend(visible=False),
        time_ranges=full_time_range(rrb),
        axis_x=rrb.TimeAxis(view_range=_whole_timeline()),
    )


def _whole_timeline() -> Any:
    """A time range from the start to the end of the timeline (both boundaries infinite)."""
    import rerun as rr

    return rr.TimeRange(start=rr.TimeRangeBoundary.infinite(), end=rr.TimeRangeBoundary.infinite())


def full_time_range(rrb: Any) -> Any:
    """The visible time range from the start to the end of the ``sim_time`` timeline."""
    return rrb.VisibleTimeRange(TIMELINE, range=_whole_timeline())


def scene_bounds(runs: Sequence[RunResult], refs: References) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) corner [km] of the box holding every trajectory and the target."""
    stacked = np.concatenate(
        [r.x_true[:, :3] for r in runs]
        + [r.x_hat[:, :3] for r in runs]
        + [refs.energy.x[:, :3], refs.fuel.x[:, :3], np.zeros((1, 3))]
    )
    stacked = stacked[np.isfinite(stacked).all(axis=1)]
    return stacked.min(axis=0), stacked.max(axis=0)


def _eye(rrb: Any, bounds: tuple[np.ndarray, np.ndarray]) -> Any:
    """An orbital eye framing the box ``bounds``.

    It looks at the box centre across its thinnest axis (tilted a little off
    it, so the view stays three-dimensional), with the longest axis up, from
    far enough that the longest side fits the view.
    """
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    centre = 0.5 * (lo + hi)
    size = np.maximum(hi - lo, 1e-9)
    order = np.argsort(size)  # thinnest, middle, longest
    direction = np.zeros(3)
    direction[order[0]] = 1.0
    direction[order[1]] = -0.35
    direction[order[2]] = 0.25
    direction /= np.linalg.norm(direction)
    up = np.zeros(3)
    up[order[2]] = 1.0
    distance = 1.1 * float(size[order[2]])
    return rrb.EyeControls3D(
        kind="Orbital",
        position=(centre + distance * direction).tolist(),
        look_target=centre.tolist(),
        eye_up=up.tolist(),
    )


def build_blueprint(
    slugs: Sequence[str],
    reference_names: Sequence[str],
    n_windows: int,
    *,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    safety: bool = False,
    tumbling: bool = False,
) -> rrb.Blueprint:
    """Default layout like the paper's Figures 1–2 (trajectories, control, ε/score, errors).

    Readable as opened at 1600×1000: the side panels collapsed, every
    time-series view showing the whole run with no legend (the about panel
    gives the colours once), and, given ``bounds`` (see :func:`scene_bounds`),
    the 3D view framed on the trajectories and the target. The time cursor
    starts at the end of the run, where the 3D view shows the final positions.
    """
    import rerun.blueprint as rrb

    def arch(name: str) -> list[str]:
        return [f"/arch/{s}/{name}" for s in slugs]

    def ref(name: str) -> list[str]:
        return [f"/reference/{r}/{name}" for r in reference_names]

    windows = [f"/degradation/{i}" for i in range(1, n_windows + 1)]
    spatial = rrb.Spatial3DView(
        name="trajectories (km, CW frame)",
        origin="/",
        contents=[
            *[f"/arch/{s}/trajectory/**" for s in slugs],
            *[f"/arch/{s}/thrust" for s in slugs],
            *[f"/reference/{r}/trajectory" for r in reference_names],
            "/target",
            *(["/target/body/**"] if tumbling else []),
            "/constraints/**",
        ],
        eye_controls=_eye(rrb, bounds) if bounds is not None else None,
    )
    about = about_share(len(slugs) + len(reference_names))
    left = rrb.Vertical(
        spatial,
        rrb.TextDocumentView(name="about: colours, arrows, results", origin="/about"),
        row_shares=[1.0 - about, about],  # the about text whole, every case (about_share)
    )
    middle = rrb.Vertical(
        _series_view(rrb, "thrust ‖u‖ [km/s²]", arch("u_norm") + ref("u_norm")),
        _series_view(rrb, "cumulative Δv [km/s]", arch("dv_cum") + ref("dv_cum")),
        _series_view(rrb, "homotopy ε [-], windows (1 = on)", arch("eps") + windows),
        _series_view(rrb, "score s [-]", arch("score") + arch("score_filtered")),
        _series_view(rrb, "re-solve success [1 = ok]", arch("resolve_success")),
    )
    right = rrb.Vertical(
        _series_view(rrb, "position error ‖r‖ [km]", arch("pos_err_km") + ref("pos_err_km")),
        _series_view(rrb, "estimation error [km]", arch("est_err_km")),
        _series_view(rrb, "NIS [-]", arch("nis")),
        _series_view(rrb, f"{inflation_ratio_names(slugs)[0]} ρ [-]", arch("mtf_ratio")),
        *(
            [_series_view(rrb, "distance to the unsafe set [km]", arch("safety_distance_km"))]
            if safety
            else []
        ),
    )
    return rrb.Blueprint(
        rrb.Horizontal(left, middle, right, column_shares=[2, 1, 1]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline=TIMELINE, play_state="following"),
        collapse_panels=False,
    )


# ---------------------------------------------------------------------------
# Logging
# ---------------------------------------------------------------------------


def _send_scalars(
    rec: rr.RecordingStream,
    path: str,
    t_s: np.ndarray,
    values: np.ndarray,
    *,
    name: str,
    colour: str,
    points: bool = False,
    width: float = 1.5,
    step: bool = False,
) -> None:
    """One scalar series in one call; NaN samples are left out; style logged static."""
    import rerun as rr

    t = np.asarray(t_s, dtype=float)
    v = np.asarray(values, dtype=float)
    keep = np.isfinite(v)
    if points:
        style: Any = rr.SeriesPoints(
            colors=[rgb(colour)], names=[name], markers=["Circle"], marker_sizes=[3.0]
        )
    else:
        style = rr.SeriesLines(
            colors=[rgb(colour)],
            names=[name],
            widths=[width],
            interpolation_mode="StepAfter" if step else None,
        )
    rec.log(path, style, static=True)
    if keep.any():
        rec.send_columns(
            path,
            indexes=[rr.TimeColumn(TIMELINE, duration=t[keep])],
            columns=rr.Scalars.columns(scalars=v[keep]),
        )


def _send_path(
    rec: rr.RecordingStream,
    path: str,
    t_s: np.ndarray,
    positions: np.ndarray,
    *,
    colour: str,
    line_radius: float,
    point_radius: float,
) -> None:
    """The whole path as a static line strip and the current point over time.

    No text labels: at the start and at the target every path meets the
    others, and their labels piled up into an unreadable clump; the about
    panel names the colours instead.
    """
    import rerun as rr

    pos = np.asarray(positions, dtype=float)
    finite = np.isfinite(pos).all(axis=1)
    c = rgb(colour)
    rec.log(path, rr.LineStrips3D([pos[finite]], colors=[c], radii=[line_radius]), static=True)
    rec.log(path, rr.Points3D.from_fields(colors=[c], radii=[point_radius]), static=True)
    rec.send_columns(
        path,
        indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(t_s, dtype=float)[finite])],
        columns=rr.Points3D.columns(positions=pos[finite]),
    )


def _send_line_of_sight(
    rec: rr.RecordingStream, path: str, run: RunResult, colour: str, radius: float
) -> None:
    """The measured line of sight over time: from the true position towards the target.

    Its length is the measured range (``range_bearing``) or the range the filter
    estimates, ‖x̂‖ (``angles``: no range measured). Rows without a measurement
    (t = 0, dropouts) are left out.
    """
    import rerun as rr

    kind = mm.KINDS[run.sensor]
    sight = mm.line_of_sight(kind, np.asarray(run.y, dtype=float))
    if kind == mm.ANGLES:
        sight = sight * np.linalg.norm(run.x_hat[:, :3], axis=1)[:, None]
    ok = np.isfinite(sight).all(axis=1)
    rec.log(path, rr.Arrows3D.from_fields(colors=[rgb(colour)], radii=[radius]), static=True)
    rec.send_columns(
        path,
        indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(run.t_s, dtype=float)[ok])],
        columns=rr.Arrows3D.columns(origins=run.x_true[ok, :3], vectors=sight[ok]),
    )


#: The about panel at the default 1600×1000 window (:func:`build_blueprint`): height of a
#: line of its markdown and of its title bar and margins [px], the height of the left
#: column it shares with the 3D view [px], and the characters a line holds at its width
#: (half the window, ~8 px a character).
ABOUT_LINE_PX = 24
ABOUT_CHROME_PX = 48
LEFT_COLUMN_PX = 940
ABOUT_LINE_CHARS = 96
#: Lines of the about text besides its table's rows (the key under it, two lines; the
#: arrows; the degradation windows; the gaps between paragraphs; :func:`_about`).
ABOUT_TEXT_LINES = 7


def about_share(n_cases: int) -> float:
    """The share of the left column the about panel needs to show ``n_cases`` table rows
    (runs and open-loop references) and its text without scrolling (issue 37 item 14)."""
    needed = ABOUT_CHROME_PX + ABOUT_LINE_PX * (1 + n_cases + ABOUT_TEXT_LINES)
    return min(needed / LEFT_COLUMN_PX, 0.6)


def _about(
    runs: Sequence[RunResult],
    refs: References,
    windows: Sequence[Window],
    arrow_scale_s2: float,
    u_max_km_s2: float,
) -> str:
    """The about panel: one table row per case with its colour, Δv [km/s] and miss [m]
    (the units of every cwrend table), then a short key; compact enough that
    :func:`about_share` of the window shows it whole."""

    def name(hex_colour: str) -> str:
        return COLOUR_NAMES.get(hex_colour, hex_colour)

    cases: list[tuple[str, str, RunResult | OpenLoopResult]] = [
        (name(REFERENCE_COLOURS.get(ref.name, _FALLBACK[-1])), f"open-loop {ref.name}", ref)
        for ref in (refs.energy, refs.fuel)
    ]
    cases += [(name(arch_colour(r.arch, i)), r.arch, r) for i, r in enumerate(runs)]
    seeds = ", ".join(sorted({str(r.seed) for r in runs})) or "-"
    lines = ["| colour | case | Δv [km/s] | miss [m] |", "|---|---|---|---|"]
    lines += [
        f"| {colour} | {label} | {c.delta_v_km_s:.5f} | {c.miss_km * 1e3:.3g} |"
        for colour, label, c in cases
    ]
    lines += [
        "",
        f"Seed {seeds}; `sim_time` in s; positions in km (CW frame, target at the origin). "
        "3D: thick line true path, thin line estimate, white dot target; "
        "score: thin line filtered s̄.",
        "",
        f"Thrust arrows: {arrow_scale_s2:.4g} s² × u "
        f"({arrow_scale_s2 * u_max_km_s2:.3g} km at u_max = {u_max_km_s2:g} km/s²).",
    ]
    if windows:
        lines.append("")
        lines.append(f"Degradation ({name(DEGRADATION_COLOUR)}): " + "; ".join(
            f"{window_label(i, w)} [{w.start_s:g}, {w.end_s:g}] s"
            for i, w in enumerate(windows, start=1)
        ))  # fmt: skip
    return "\n".join(lines) + "\n"


def _log_case(
    rec: rr.RecordingStream,
    runs: Sequence[RunResult],
    refs: References,
    windows: Sequence[Window],
    u_max_km_s2: float,
) -> None:
    import rerun as rr

    all_pos = [r.x_true[:, :3] for r in runs] + [refs.energy.x[:, :3], refs.fuel.x[:, :3]]
    stacked = np.concatenate(all_pos)
    stacked = stacked[np.isfinite(stacked).all(axis=1)]
    extent = float(np.max(np.ptp(stacked, axis=0))) if stacked.size else 1.0
    extent = extent if extent > 0 else 1.0
    line_r = 0.002 * extent
    point_r = 0.008 * extent
    # an arrow at full thrust is 8 % of the scene
    arrow_scale = 0.08 * extent / u_max_km_s2 if u_max_km_s2 > 0 else 1.0

    rec.log(
        "/target",
        rr.Points3D(
            [[0.0, 0.0, 0.0]], colors=[(255, 255, 255)], radii=[point_r], labels=["target"]
        ),
        static=True,
    )
    geo = next((r.safety.geometry for r in runs if r.safety is not None), None)
    tumble = next((r for r in runs if r.target_attitude is not None), None)
    if geo is not None:  # issue 32: the keep-out zone and the corridor (34: in the body)
        _log_constraints(rec, geo, line_r, "/target/body" if tumble is not None else "")
    if tumble is not None:  # issue 34: the same for every architecture of the case
        _log_target_attitude(rec, tumble, TARGET_AXES_SHARE * extent, line_r)
    rec.log(
        "/about",
        rr.TextDocument(
            _about(runs, refs, windows, arrow_scale, u_max_km_s2), media_type="text/markdown"
        ),
        static=True,
    )

    for i, run in enumerate(runs):
        base = f"/arch/{run.arch}"
        colour = arch_colour(run.arch, i)
        t = run.t_s
        _send_path(
            rec, f"{base}/trajectory/true", t, run.x_true[:, :3],
            colour=colour, line_radius=line_r, point_radius=point_r,
        )  # fmt: skip
        _send_path(
            rec, f"{base}/trajectory/estimate", t, run.x_hat[:, :3],
            colour=colour, line_radius=0.5 * line_r, point_radius=0.6 * point_r,
        )  # fmt: skip
        rec.log(
            f"{base}/thrust",
            rr.Arrows3D.from_fields(colors=[rgb(colour)], radii=[0.5 * line_r]),
            static=True,
        )
        rec.send_columns(
            f"{base}/thrust",
            indexes=[rr.TimeColumn(TIMELINE, duration=t)],
            columns=rr.Arrows3D.columns(origins=run.x_true[:, :3], vectors=arrow_scale * run.u),
        )
        if run.sensor != "position":
            _send_line_of_sight(rec, f"{base}/line_of_sight", run, colour, 0.3 * line_r)
        u_norm = np.linalg.norm(run.u, axis=1)
        series = {
            "u_norm": u_norm,
            "dv_cum": cumulative_delta_v(t, u_norm),
            "eps": run.eps,
            "score": run.score,
            "score_filtered": run.score_filtered,
            "nis": run.nis,
            "mtf_ratio": run.mtf_ratio,
            "pos_err_km": np.linalg.norm(run.x_true[:, :3], axis=1),
            "est_err_km": np.linalg.norm(run.x_hat[:, :3] - run.x_true[:, :3], axis=1),
        }
        for name, values in series.items():
            label = run.arch if name != "score_filtered" else f"{run.arch} (filtered)"
            _send_scalars(
                rec, f"{base}/{name}", t, values, name=label, colour=colour,
                width=1.0 if name == "score_filtered" else 1.5,
            )  # fmt: skip
        if run.safety is not None:  # issue 32: the distance, and where the path was unsafe
            _send_scalars(
                rec, f"{base}/safety_distance_km", t, run.safety.step_distance_km,
                name=run.arch, colour=colour,
            )  # fmt: skip
            unsafe = run.x_true[run.safety.step_distance_km < 0.0, :3]
            rec.log(
                f"{base}/trajectory/unsafe",
                rr.Points3D(unsafe, colors=[UNSAFE_COLOUR], radii=[0.6 * point_r]),
                static=True,
            )
        resolves = run.resolves
        _send_scalars(
            rec,
            f"{base}/resolve_success",
            np.array([s.t_s for s in resolves], dtype=float),
            np.array([1.0 if s.success else 0.0 for s in resolves]),
            name=run.arch,
            colour=colour,
            points=True,
        )

    for ref in (refs.energy, refs.fuel):
        base = f"/reference/{ref.name}"
        colour = REFERENCE_COLOURS.get(ref.name, _FALLBACK[-1])
        label = f"open-loop {ref.name}"
        _send_path(
            rec, f"{base}/trajectory", ref.t_s, ref.x[:, :3],
            colour=colour, line_radius=line_r, point_radius=0.7 * point_r,
        )  # fmt: skip
        u_norm = np.linalg.norm(ref.u, axis=1)
        ref_series = {
            "u_norm": u_norm,
            "dv_cum": cumulative_delta_v(ref.t_s, u_norm),
            "pos_err_km": np.linalg.norm(ref.x[:, :3], axis=1),
        }
        for name, values in ref_series.items():
            _send_scalars(rec, f"{base}/{name}", ref.t_s, values, name=label, colour=colour)

    t_grid = runs[0].t_s if runs else refs.fuel.t_s
    for i, w in enumerate(windows, start=1):
        path = f"/degradation/{i}"
        _send_scalars(
            rec, path, t_grid, window_activity(t_grid, w),
            name=window_label(i, w), colour=DEGRADATION_COLOUR, width=2.0, step=True,
        )  # fmt: skip
        rec.send_columns(
            path,
            indexes=[rr.TimeColumn(TIMELINE, duration=[w.start_s, w.end_s])],
            columns=rr.TextLog.columns(
                text=[f"{window_label(i, w)}: start", f"{window_label(i, w)}: end"],
                level=["WARN", "INFO"],
            ),
        )


#: Colour of the keep-out zone, the corridor and the unsafe nodes of a path (issue 32).
UNSAFE_COLOUR = (230, 60, 60)
CORRIDOR_COLOUR = (90, 200, 120)
#: Generator lines drawn of the corridor cone [-].
_CONE_LINES = 12


def _log_constraints(
    rec: rr.RecordingStream, geo: Geometry, line_radius: float, root: str = ""
) -> None:
    """The keep-out ellipsoids (``<root>/constraints/keep_out``) and the corridor cone
    (``<root>/constraints/corridor``: generator lines and two rings, out to twice the
    largest semi-axis or port distance), static; a tumbling target's under
    ``/target/body`` (issue 34), so that they turn with it."""
    import rerun as rr

    if geo.semi_axes_km is not None:
        parts = [(np.zeros(3) if c is None else c, a) for c, a in ellipsoids(geo)]
        rec.log(
            f"{root}/constraints/keep_out",
            rr.Ellipsoids3D(
                half_sizes=[a for _, a in parts],
                centers=[c for c, _ in parts],
                colors=[UNSAFE_COLOUR],
            ),
            static=True,
        )
    if geo.port_km is None or geo.axis is None or geo.half_angle_rad is None:
        return
    size = max(
        float(np.max(geo.semi_axes_km)) if geo.semi_axes_km is not None else 0.0,
        float(np.linalg.norm(geo.port_km)),
    )
    length = 2.0 * size if size > 0 else 1.0
    helper = np.eye(3)[int(np.argmin(np.abs(geo.axis)))]
    e1 = np.cross(geo.axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(geo.axis, e1)
    psi = np.linspace(0.0, 2.0 * np.pi, 4 * _CONE_LINES + 1)
    c, s = np.cos(geo.half_angle_rad), np.sin(geo.half_angle_rad)
    rim = geo.axis[None, :] * c + s * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2)
    strips = [np.stack([geo.port_km, geo.port_km + length * d]) for d in rim[::4][:-1]]
    strips += [geo.port_km + f * length * rim for f in (0.5, 1.0)]
    rec.log(
        f"{root}/constraints/corridor",
        rr.LineStrips3D(strips, colors=[CORRIDOR_COLOUR], radii=[0.5 * line_radius]),
        static=True,
    )


#: Length of the drawn body axes of a tumbling target, a share of the scene's extent [-].
TARGET_AXES_SHARE = 0.05
#: Colours of the body's x, y and z axes (RGB).
BODY_AXIS_COLOURS = ((214, 39, 40), (44, 160, 44), (31, 119, 180))


def _log_target_attitude(
    rec: rr.RecordingStream, run: RunResult, length_km: float, line_radius: float
) -> None:
    """A tumbling target's attitude (issue 34): ``/target/body`` turns over time (its
    body-to-relative-frame quaternion at every step, as a Transform3D) and carries the
    body's axes (``/target/body/axes``, static in the body frame). Anything logged
    under ``/target/body`` turns with the body."""
    import rerun as rr

    assert run.target_attitude is not None
    q_hb, _ = run.target_attitude.at_steps()
    xyzw = np.ascontiguousarray(q_hb[:, [1, 2, 3, 0]])  # Rerun's quaternions are scalar-last
    rec.send_columns(
        "/target/body",
        indexes=[rr.TimeColumn(TIMELINE, duration=np.asarray(run.t_s, dtype=float))],
        columns=rr.Transform3D.columns(quaternion=xyzw),
    )
    rec.log(
        "/target/body/axes",
        rr.Arrows3D(
            origins=np.zeros((3, 3)),
            vectors=length_km * np.eye(3),
            colors=list(BODY_AXIS_COLOURS),
            radii=[line_radius],
            labels=["x_b", "y_b", "z_b"],
        ),
        static=True,
    )


#: Values of the ``RERUN`` environment variable that turn Rerun's logging off, in any case
#: and unstripped ("SDK logging controls" of Rerun's documentation; checked against
#: ``rr.is_enabled`` by a test). Rerun reads it for every new recording stream.
RERUN_OFF = frozenset({"0", "off", "false"})
_DISABLED = "Rerun logging is disabled by the RERUN environment variable; unset it or pass --no-rrd"


def _require_enabled(rec: rr.RecordingStream) -> None:
    import rerun as rr

    if not rr.is_enabled(rec):
        # RERUN=off in the environment would silently write an empty file
        raise RecordingError(_DISABLED)


def check_enabled() -> None:
    """Raise :class:`RecordingError` now if recordings could not be written (``RERUN=off``).

    Reads the environment as Rerun does, without importing it (0.4–0.6 s): the
    campaign commands check before they compute, and their workers record.
    """
    if os.environ.get("RERUN", "").lower() in RERUN_OFF:
        raise RecordingError(_DISABLED)


class CaseOptions(TypedDict, total=False):
    """The keyword options of :func:`encode_case`, which :func:`record_case` passes on."""

    application_id: str
    recording_id: str | None
    recording_name: str | None
    u_max_km_s2: float


def record_case(
    path: Path,
    runs: Sequence[RunResult],
    refs: References,
    windows: Sequence[Window],
    *,
    root: Path | None = None,
    **options: Unpack[CaseOptions],
) -> Path:
    """Write one ``.rrd`` overlaying ``runs`` (one noise realisation) and the references.

    ``runs`` are the closed-loop results of one seed (any subset of the
    architectures), ``refs`` the open-loop references, ``windows`` the
    degradation windows of the config; ``options`` those of :func:`encode_case`
    (application id, recording id and name, ``u_max_km_s2``). ``root``: a
    directory the write must not leave
    (:func:`~cwrend_cli.output.files.atomic_path`). Returns ``path``.

    The recording is encoded in memory (:func:`encode_case`) and its bytes
    written by cwrend (:func:`~cwrend_cli.output.files.atomic_path`), never
    by a Rerun file sink: ``path`` is either absent or complete, and a full
    disk is an :class:`OSError` here instead of a sink that dies in the
    background and blocks the next recording for ever (issue 36, item 1).
    """
    data = encode_case(runs, refs, windows, **options)
    return write_recording(Path(path), data, root=root)


def write_recording(path: Path, data: bytes, *, root: Path | None = None) -> Path:
    """Write the encoded recording ``data`` to ``path`` atomically (an OSError if it cannot)."""
    with atomic_path(path, root=root) as tmp:
        tmp.write_bytes(data)
    return path


def encode_case(
    runs: Sequence[RunResult],
    refs: References,
    windows: Sequence[Window],
    *,
    application_id: str = "cwrend",
    recording_id: str | None = None,
    recording_name: str | None = None,
    u_max_km_s2: float = 8e-4,
) -> bytes:
    """The ``.rrd`` bytes of :func:`record_case`, encoded in memory (no file, no disk).

    ``recording_id`` defaults to a fresh UUID (never the process-wide default,
    which child processes inherit); files sharing a recording id merge in the
    viewer. ``u_max_km_s2`` [km/s²] only scales the thrust arrows.

    The default blueprint is sent as a file sink's ``default_blueprint`` is
    (the default, not made active); the bytes end with the footer a file
    sink writes on disconnect.
    """
    import rerun as rr

    rec = rr.RecordingStream(
        application_id,
        recording_id=recording_id or str(uuid.uuid4()),
        send_properties=True,
    )
    _require_enabled(rec)
    slugs = [r.arch for r in runs]
    blueprint = build_blueprint(
        slugs,
        ("energy", "fuel"),
        len(windows),
        bounds=scene_bounds(runs, refs),
        safety=any(r.safety is not None for r in runs),
        tumbling=any(r.target_attitude is not None for r in runs),
    )
    memory = rec.memory_recording()
    rec.send_blueprint(blueprint, make_active=False, make_default=True)
    seeds = sorted({r.seed for r in runs})
    default_name = f"cwrend seed {','.join(map(str, seeds))}" if seeds else "cwrend"
    rec.send_recording_name(recording_name or default_name)
    _log_case(rec, runs, refs, windows, u_max_km_s2)
    return memory.drain_as_bytes()


def open_in_viewer(path: Path) -> bool:
    """Start a Rerun viewer on ``path`` in the background; False if there is no viewer.

    Needs the ``rerun`` executable (installed with rerun-sdk) and a display;
    the viewer runs detached, so cwrend does not wait for it.
    """
    exe = shutil.which("rerun")
    if exe is None:
        return False
    headless_linux = sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    )
    if headless_linux:
        return False
    subprocess.Popen(
        [exe, str(path)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    return True
