"""`cwrend report` of a constrained campaign (issue 32 item 4): the paths with the keep-out
zone and the corridor in three planes, the distance to the unsafe set over time and a
violations table from the stored statistics; a report without constraints has none of them."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import matplotlib.image
import numpy as np
import pandas as pd
import pytest
from matplotlib.patches import Ellipse, Polygon
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.report import load_results
from cwrend_cli.report.figures import (
    fig_safety_distance,
    fig_safety_trajectories,
    planned_figures,
)

CAMPAIGNS = Path(__file__).resolve().parents[1] / "campaigns"
SAFETY_FIGURES = ("safety_trajectories.png", "safety_distance.png")
SEMI_AXES_KM = 0.2  # campaigns/safe_approach.toml: a keep-out sphere of 200 m
PORT_KM = (0.0, 0.0, -0.25)

runner = CliRunner()


def _ablate(config: Path, out: Path, archs: str) -> Path:
    args = ["ablate", str(config), "--seeds", "2", "--arch", archs, "--workers", "1",
            "--no-rrd", "-q", "--set", f"output.dir={out}", "--name", "c"]  # fmt: skip
    result = runner.invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return out / "c"


def _reported(root: Path) -> Path:
    result = runner.invoke(app, ["report", str(root)], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return root / "report"


@pytest.fixture(scope="module")
def constrained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The safe approach, shooting (unconstrained: enters the keep-out zone) and cone program."""
    out = tmp_path_factory.mktemp("safe")
    return _ablate(CAMPAIGNS / "safe_approach.toml", out, "mtf_adaptive,mtf_adaptive_socp")


@pytest.fixture(scope="module")
def constrained_report(constrained: Path) -> Path:
    return _reported(constrained)


def test_a_constrained_report_holds_the_two_safety_figures(constrained_report: Path) -> None:
    md = (constrained_report / "report.md").read_text(encoding="utf-8")
    for name in SAFETY_FIGURES:
        image = matplotlib.image.imread(constrained_report / name)
        assert image.shape[0] > 400 and image.shape[1] > 400
        assert f"![{Path(name).stem}]({name})" in md
    html = (constrained_report / "report.html").read_text(encoding="utf-8")
    assert "safety_trajectories" in html and "safety_distance" in html
    # a fixed target: no body-frame view (issue 34), no docking-error columns
    assert not (constrained_report / "safety_body_frame.png").exists()
    assert "dock position error" not in md
    assert "Measured only" not in md  # the cone program was constrained (enforce = true)


def test_the_paths_are_drawn_with_the_keep_out_zone_and_corridor_in_three_planes(
    constrained: Path,
) -> None:
    data = load_results(constrained)
    fig = fig_safety_trajectories(data)
    axes = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in axes] == ["x–y plane", "x–z plane", "y–z plane"]
    for ax in axes:
        (ellipse,) = [p for p in ax.patches if isinstance(p, Ellipse)]
        assert ellipse.width == pytest.approx(2 * SEMI_AXES_KM)
        assert ellipse.height == pytest.approx(2 * SEMI_AXES_KM)
        (cone,) = [p for p in ax.patches if isinstance(p, Polygon)]
        assert cone.get_xy().size > 0
    x_z = axes[1]
    cone_xz = next(p for p in x_z.patches if isinstance(p, Polygon)).get_xy()
    # the cone's outline starts at the port (its apex) and opens away from the target (−z)
    assert np.min(np.linalg.norm(cone_xz - [PORT_KM[0], PORT_KM[2]], axis=1)) < 1e-6
    assert np.max(cone_xz[:, 1]) == pytest.approx(PORT_KM[2], abs=1e-6)
    # the shooting run enters the unsafe set and is marked; the constrained one is not
    gids = {str(c.get_gid()) for ax in axes for c in ax.collections}
    assert "unsafe:mtf_adaptive" in gids and "unsafe:mtf_adaptive_socp" not in gids
    steps = data.steps[data.steps["arch"] == "mtf_adaptive"]
    inside = int((steps["safety_distance_km"] < 0).sum())
    marks = next(c for c in x_z.collections if c.get_gid() == "unsafe:mtf_adaptive")
    assert np.asarray(marks.get_offsets()).shape[0] == inside > 0


def test_a_corridor_seen_along_its_axis_is_an_outline_not_a_waived_disc(
    constrained: Path,
) -> None:
    """The corridor along −z projects on the x–y plane to a disc round the port that, filled,
    read as a waiver of the whole zone under it: there it is an outline, named in the
    panel; in the planes that hold the axis it stays a filled cone."""
    axes = [ax for ax in fig_safety_trajectories(load_results(constrained)).axes if ax.get_title()]
    cones = [next(p for p in ax.patches if isinstance(p, Polygon)) for ax in axes]
    assert [c.get_gid() for c in cones] == ["corridor:along", None, None]
    assert [c.get_facecolor()[3] for c in cones] == [0.0, 0.15, 0.15]  # no fill, then 15 %
    assert any("seen along its axis" in t.get_text() for t in axes[0].texts)
    assert not any("seen along its axis" in t.get_text() for ax in axes[1:] for t in ax.texts)


def test_the_distance_figure_draws_the_stored_distances_and_the_zero_line(
    constrained: Path,
) -> None:
    data = load_results(constrained)
    fig = fig_safety_distance(data)
    ax = fig.axes[0]
    for arch in ("mtf_adaptive", "mtf_adaptive_socp"):
        stored = data.steps[data.steps["arch"] == arch].sort_values("t_s")
        drawn = [
            line for line in ax.get_lines()
            if np.array_equal(line.get_xdata(), stored["t_s"].to_numpy())
            and np.array_equal(line.get_ydata(), stored["safety_distance_km"].to_numpy())
        ]  # fmt: skip
        assert len(drawn) == 1, arch
    zero = [line for line in ax.get_lines() if np.array_equal(line.get_ydata(), [0.0, 0.0])]
    assert zero
    assert len(data.windows) == 2 and len(ax.patches) >= 2  # the degradation windows shaded


def test_the_close_up_marks_the_deepest_point_inside_with_its_depth(constrained: Path) -> None:
    """The shooting run goes through the zone: the close-up marks the least stored φ and
    labels its depth in metres and its time."""
    data = load_results(constrained)
    near = fig_safety_distance(data).axes[1]
    (mark,) = [line for line in near.get_lines() if line.get_gid() == "deepest"]
    deepest = data.steps.loc[data.steps["safety_distance_km"].idxmin()]
    assert mark.get_ydata()[0] == deepest["safety_distance_km"] < 0
    assert mark.get_xdata()[0] == deepest["t_s"]
    (label,) = near.texts
    assert f"{-deepest['safety_distance_km'] * 1e3:.3g} m inside" in label.get_text()
    assert f"t = {deepest['t_s']:g} s" in label.get_text()


def _row(md: str, label: str) -> list[str]:
    section = md.split("## Safety (path constraints)", 1)[1].split("\n## ", 1)[0]
    line = next(ln for ln in section.splitlines() if ln.startswith(f"| {label} |"))
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_the_violations_table_holds_the_stored_statistics(
    constrained: Path, constrained_report: Path
) -> None:
    md = (constrained_report / "report.md").read_text(encoding="utf-8")
    stats = pd.read_parquet(constrained / "ablation.parquet")

    def stored(arch: str, metric: str, statistic: str) -> pd.Series:
        sel = stats[(stats["arch"] == arch) & (stats["metric"] == metric)]
        return sel[sel["statistic"] == statistic].iloc[0]

    for arch, label, count in (
        ("mtf_adaptive", "MTF KF, adaptive ε", 2),
        ("mtf_adaptive_socp", "MTF KF, adaptive ε, SOCP", 0),
    ):
        row = _row(md, label)
        share = stored(arch, "safety_violated", "share")
        assert row[1] == "2"
        assert row[2] == (
            f"{count} of 2: {share['value']:.2f} [{share['ci_low']:.2f}, {share['ci_high']:.2f}]"
        )
        for cell, (metric, statistic, scale, spec) in zip(
            row[3:],
            (
                ("safety_min_distance_km", "median", 1e3, ".2f"),
                ("safety_min_distance_km", "p1", 1e3, ".2f"),
                ("safety_unsafe_time_s", "mean", 1.0, ".1f"),
            ),
            strict=True,
        ):
            s = stored(arch, metric, statistic)
            lo, hi = s["ci_low"] * scale, s["ci_high"] * scale
            assert cell == f"{s['value'] * scale:{spec}} [{lo:{spec}}, {hi:{spec}}]\\*"


def test_a_report_without_constraints_has_no_safety_figure_or_table(
    tmp_path: Path, constrained: Path
) -> None:
    root = _ablate(CAMPAIGNS / "paper.toml", tmp_path, "mtf_adaptive")
    names = {f.file for f in planned_figures(load_results(root))}
    assert not names & set(SAFETY_FIGURES)
    md = (_reported(root) / "report.md").read_text(encoding="utf-8")
    assert "Safety" not in md and "safety_" not in md
    assert not any((root / "report" / name).exists() for name in SAFETY_FIGURES)


def test_a_stored_config_without_constraints_draws_none_even_with_safety_columns(
    tmp_path: Path, constrained: Path
) -> None:
    """The figures and the table follow the configuration, not the columns."""
    root = tmp_path / "c"
    shutil.copytree(constrained, root)
    manifest = root / "manifest.json"
    meta = json.loads(manifest.read_text(encoding="utf-8"))
    meta["config"].pop("constraints", None)
    manifest.write_text(json.dumps(meta), encoding="utf-8")
    data = load_results(root)
    assert data.constraints is None
    assert not {f.file for f in planned_figures(data)} & set(SAFETY_FIGURES)


# --- issue 32's "done when", end to end: the commands as the issue names them ---------


def _entities(rrd: Path) -> set[str]:
    from rerun.chunk import RrdReader

    return {chunk.entity_path for chunk in RrdReader(rrd).stream()}


def _safety_columns_of_every_ok_run(root: Path, archs: set[str]) -> pd.DataFrame:
    runs = pd.read_parquet(root / "runs.parquet")
    assert set(runs["arch"]) == archs and (runs["status"] == "ok").all(), runs[["arch", "status"]]
    assert runs[["safety_min_distance_km", "safety_violated"]].notna().all().all()
    return runs


@pytest.mark.slow
def test_the_safe_approach_ablation_of_every_cone_program_runs_end_to_end(
    tmp_path: Path,
) -> None:
    """``cwrend ablate campaigns/safe_approach.toml --arch all_socp`` (one seed): the
    Parquet with the safety columns, the recording with the keep-out zone and the
    corridor, the report with the safety figures."""
    args = ["ablate", str(CAMPAIGNS / "safe_approach.toml"), "--arch", "all_socp",
            "--seeds", "1", "--workers", "1", "-q", "--set", f"output.dir={tmp_path}",
            "--name", "c"]  # fmt: skip
    result = runner.invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    root = tmp_path / "c"
    socp = {"plain_fixed_socp", "mtf_fixed_socp", "plain_adaptive_socp", "mtf_adaptive_socp"}
    _safety_columns_of_every_ok_run(root, socp)
    (rrd,) = sorted((root / "recordings").glob("*.rrd"))
    assert {"/constraints/keep_out", "/constraints/corridor"} <= _entities(rrd)
    report = _reported(root)
    assert all((report / name).exists() for name in SAFETY_FIGURES)


@pytest.fixture(scope="module")
def dispersed_sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``cwrend sweep`` of campaigns/safe_approach.toml over ``constraints.sigma_margin``
    (0, 3) with the corridor's half-angle dispersed (±5° about 30°), two seeds."""
    tmp_path = tmp_path_factory.mktemp("sweep")
    config = tmp_path / "safe_dispersed.toml"
    config.write_text(
        (CAMPAIGNS / "safe_approach.toml").read_text(encoding="utf-8")
        + '\n[dispersions]\n"constraints.corridor.half_angle_deg" = '
        '{ dist = "uniform", low = -5.0, high = 5.0 }\n',
        encoding="utf-8",
    )
    args = ["sweep", str(config), "--param", "constraints.sigma_margin=0,3", "--arch",
            "mtf_adaptive_socp", "--seeds", "2", "--workers", "1", "-q", "--set",
            f"output.dir={tmp_path}", "--name", "s"]  # fmt: skip
    result = runner.invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return tmp_path / "s"


@pytest.mark.slow
def test_a_sweep_over_the_margin_with_a_dispersed_corridor_runs_end_to_end(
    dispersed_sweep: Path,
) -> None:
    """Each point's runs carry their margin, each run its own half-angle, the safety columns
    and statistics per point, the recording and the report."""
    root = dispersed_sweep
    runs = _safety_columns_of_every_ok_run(root, {"mtf_adaptive_socp"})
    assert sorted(runs["param.constraints.sigma_margin"]) == [0.0, 0.0, 3.0, 3.0]
    angles = runs["disp.constraints.corridor.half_angle_deg"]
    assert angles.between(25.0, 35.0).all() and angles.nunique() == 2  # per seed
    stats = pd.read_parquet(root / "sweep.parquet")
    violated = stats[(stats["metric"] == "safety_violated") & (stats["statistic"] == "share")]
    assert violated["point"].nunique() == 2
    assert list((root / "recordings").glob("*.rrd"))
    assert all((_reported(root) / name).exists() for name in SAFETY_FIGURES)


@pytest.mark.slow
def test_a_sweep_report_gives_the_safety_of_every_point(dispersed_sweep: Path) -> None:
    """The safety table is one point's, which the text names by its values; a second table
    lists every point's (the margin's effect is what such a sweep is for)."""
    md = (_reported(dispersed_sweep) / "report.md").read_text(encoding="utf-8")
    assert "(constraints.sigma_margin=0; `--point` chooses another)" in md
    every = md[md.index("### Every grid point") :].split("\n\n")[1]
    lines = every.splitlines()
    assert lines[0].startswith("| sigma_margin | architecture | violated (share)")
    assert [line.split(" | ")[0].strip("| ") for line in lines[2:]] == ["0", "3"]


def test_the_open_loop_misses_are_measured_from_the_port(constrained: Path) -> None:
    """The references end at the port, not at the target: their miss in the report is their
    distance to scenario.xf (the port at rest), about 0 m, not the port's 250 m from the
    target (the report measured it from the origin)."""
    data = load_results(constrained)
    misses = dict(zip(data.ref_summary["arch"], data.ref_summary["miss_km"], strict=True))
    assert set(misses) == {"open_loop_energy", "open_loop_fuel"}
    # the shooting solver's tolerance at the final state (1e-9 km), well below the 250 m
    assert all(m < 1e-8 for m in misses.values()), misses
