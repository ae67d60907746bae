"""`cwrend report` of a tumbling target (issue 34 item 5): the approach in the target's body
frame beside the relative frame, and the docking errors in the safety table; a fixed
target's report has no body-frame figure."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import matplotlib.image
import numpy as np
import pandas as pd
import pytest
from matplotlib.patches import Ellipse
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.report import load_results
from cwrend_cli.report.figures import (
    body_frame_steps,
    fig_safety_body_frame,
    fig_safety_trajectories,
    planned_figures,
)

CAMPAIGNS = Path(__file__).resolve().parents[1] / "campaigns"
BODY_FIGURE = "safety_body_frame.png"
PORT_KM = (-0.1, 0.0, 0.0)  # campaigns/tumbling_target.toml, body frame

runner = CliRunner()


def test_a_point_fixed_in_the_body_frame_stays_at_one_place_in_the_body_view() -> None:
    """Positions r_k = R_k ρ of a body-fixed ρ, turned by attitudes R_k written here with
    scipy's ``Rotation`` (scalar-last), come back as ρ at every step."""
    rotations = Rotation.random(50, random_state=7)
    rho = np.array([0.03, -0.12, 0.07])
    xyzw = rotations.as_quat()
    steps = pd.DataFrame(rotations.apply(rho), columns=["x_km", "y_km", "z_km"])
    for i, col in enumerate((3, 0, 1, 2)):  # the steps' quaternion is scalar-first
        steps[f"target_q{i}"] = xyzw[:, col]
    steps["t_s"] = np.arange(50.0)
    body = body_frame_steps(steps)
    # rotations of a 0.15 km vector in float64: 1e-15 km is a few units of rounding
    assert np.allclose(body[["x_km", "y_km", "z_km"]], rho, rtol=0.0, atol=1e-15)
    assert np.array_equal(body["t_s"], steps["t_s"])
    assert not np.allclose(steps[["x_km", "y_km", "z_km"]], rho)  # the test has teeth


@pytest.fixture(scope="module")
def tumbling(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shipped tumbling campaign, one seed, one cone-program architecture."""
    out = tmp_path_factory.mktemp("tumbling")
    args = ["ablate", str(CAMPAIGNS / "tumbling_target.toml"), "--seeds", "1", "--arch",
            "mtf_fixed_socp", "--workers", "1", "--no-rrd", "-q", "--set",
            f"output.dir={out}", "--name", "c"]  # fmt: skip
    result = runner.invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    root = out / "c"
    result = runner.invoke(app, ["report", str(root)], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return root


def test_a_tumbling_report_holds_the_body_frame_figure(tumbling: Path) -> None:
    report = tumbling / "report"
    image = matplotlib.image.imread(report / BODY_FIGURE)
    assert image.shape[0] > 400 and image.shape[1] > 400
    md = (report / "report.md").read_text(encoding="utf-8")
    assert f"![safety_body_frame]({BODY_FIGURE})" in md


def test_the_body_frame_figure_draws_the_bodies_fixed_and_the_paths_turned(
    tumbling: Path,
) -> None:
    data = load_results(tumbling)
    fig = fig_safety_body_frame(data)
    axes = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in axes] == ["x_b–y_b plane", "x_b–z_b plane", "y_b–z_b plane"]
    assert "body frame" in fig.get_suptitle()
    x_y = axes[0]
    ellipses = [p for p in x_y.patches if isinstance(p, Ellipse)]
    # the bus and the two panels, as configured in body axes (x–y plane: semi-axes x, y)
    got = np.array(sorted((e.center[1], e.width, e.height) for e in ellipses))
    configured = [(-0.16, 0.02, 0.2), (0.0, 0.16, 0.12), (0.16, 0.02, 0.2)]
    assert np.allclose(got, configured, rtol=0.0, atol=1e-15)  # drawn as given: no arithmetic
    steps = data.steps[data.steps["arch"] == "mtf_fixed_socp"]
    body = body_frame_steps(steps)
    drawn = [ln for ln in x_y.get_lines() if len(ln.get_xdata()) == len(body)]
    assert len(drawn) == 1
    x_drawn = np.asarray(drawn[0].get_xdata(), dtype=float)
    shown = np.isfinite(x_drawn)  # the path near the target; far out the line is broken
    assert shown[-1] and not shown[0]
    assert np.array_equal(x_drawn[shown], body["x_km"].to_numpy()[shown])
    # the run ends at the port, which stands still in the body frame (1 m: the dock error)
    end = body[["x_km", "y_km", "z_km"]].to_numpy()[-1]
    assert np.linalg.norm(end - PORT_KM) < 1e-3


def test_the_relative_frame_figure_says_its_zone_is_at_t0_and_draws_the_port_path(
    tumbling: Path,
) -> None:
    data = load_results(tumbling)
    fig = fig_safety_trajectories(data)
    assert "at t = 0" in fig.get_suptitle()
    x_y = next(ax for ax in fig.axes if ax.get_title() == "x–y plane")
    dotted = [ln for ln in x_y.get_lines() if ln.get_linestyle() == ":"]
    assert len(dotted) == 1
    port = np.column_stack([dotted[0].get_xdata(), dotted[0].get_ydata()])
    assert np.ptp(port, axis=0).max() > 0.05  # the port turns with the target


def test_the_safety_table_holds_the_docking_errors(tumbling: Path) -> None:
    md = (tumbling / "report" / "report.md").read_text(encoding="utf-8")
    section = md.split("## Safety (path constraints)", 1)[1].split("\n## ", 1)[0]
    assert "dock position error [m], median (max)" in section
    assert "dock velocity error [mm/s], median (max)" in section
    runs = pd.read_parquet(tumbling / "runs.parquet")
    error_m = float(runs["safety_dock_position_error_km"].iloc[0]) * 1e3
    row = next(ln for ln in section.splitlines() if ln.startswith("| MTF KF, fixed ε, SOCP |"))
    assert f"{error_m:.2f} ({error_m:.2f})" in row


def test_a_fixed_target_report_has_no_body_frame_figure(tumbling: Path) -> None:
    """The figure follows the stored attitude columns: a fixed target stores none."""
    stored = load_results(tumbling)
    data = replace(stored, steps=stored.steps.drop(columns=[f"target_q{i}" for i in range(4)]))
    names = {f.file for f in planned_figures(data)}
    assert "safety_trajectories.png" in names and BODY_FIGURE not in names
    assert "at t = 0" not in fig_safety_trajectories(data).get_suptitle()


def test_a_sweep_over_the_body_rates_stores_each_vector_as_one_groupable_value() -> None:
    """A swept vector (``target.body_rates_deg_s``, campaigns/tumbling_study.toml) is a JSON
    text cell of ``runs.parquet``, so the report finds each point's value and sets it on the
    configuration (a list cell was unhashable: ``cwrend report`` of the sweep raised)."""
    from cwrend_cli.config.io import load_config
    from cwrend_cli.output.tables import runs_table
    from cwrend_cli.report.load import with_swept_values

    rates = ([0.0, 0.0, 0.0], [0.291, 0.3881, 1.9403])
    records = [
        {"run_key": f"p{i}.a.s{s}", "point": f"p{i}", "arch": "mtf_fixed_socp", "seed": s,
         "status": "ok", "params": {"target.body_rates_deg_s": rate}}
        for i, rate in enumerate(rates) for s in (0, 1)
    ]  # fmt: skip
    runs = runs_table(records, {}).to_pandas()
    assert runs["param.target.body_rates_deg_s"].tolist() == [
        "[0.0, 0.0, 0.0]", "[0.0, 0.0, 0.0]",
        "[0.291, 0.3881, 1.9403]", "[0.291, 0.3881, 1.9403]",
    ]  # fmt: skip
    config = load_config(CAMPAIGNS / "tumbling_target.toml")
    point = with_swept_values(config, runs[runs["point"] == "p1"])
    assert point is not None
    assert point.target.body_rates_deg_s == (0.291, 0.3881, 1.9403)


@pytest.mark.slow
def test_a_sweep_over_the_tumble_rate_runs_end_to_end(tmp_path: Path) -> None:
    """Issue 34's "done when": ``cwrend sweep`` of campaigns/tumbling_target.toml over the
    tumble rate (at rest in inertial space, and the shipped 2 °/s), one seed, with the
    recording and the report: each point's runs carry their rates and the safety and
    docking columns, the recording draws the turning body, the report its body frame."""
    from rerun.chunk import RrdReader

    config = tmp_path / "tumbling_sweep.toml"
    config.write_text(
        (CAMPAIGNS / "tumbling_target.toml").read_text(encoding="utf-8")
        + '\n[sweep]\n"target.body_rates_deg_s" = [[0.0, 0.0, 0.0], [0.3, 0.4, 2.0]]\n',
        encoding="utf-8",
    )
    args = ["sweep", str(config), "--arch", "mtf_adaptive_socp", "--seeds", "1", "--workers",
            "1", "-q", "--set", f"output.dir={tmp_path}", "--name", "s"]  # fmt: skip
    result = runner.invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    root = tmp_path / "s"
    runs = pd.read_parquet(root / "runs.parquet")
    assert (runs["status"] == "ok").all() and len(runs) == 2
    assert sorted(runs["param.target.body_rates_deg_s"]) == ["[0.0, 0.0, 0.0]", "[0.3, 0.4, 2.0]"]
    columns = ["safety_min_distance_km", "safety_dock_position_error_km"]
    assert runs[columns].notna().all().all()
    rrds = sorted((root / "recordings").glob("*.rrd"))
    assert rrds
    entities = {chunk.entity_path for chunk in RrdReader(rrds[0]).stream()}
    assert "/target/body/constraints/keep_out" in entities
    result = runner.invoke(app, ["report", str(root)], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    assert (root / "report" / BODY_FIGURE).exists()


def test_the_abort_text_says_the_zones_turn_with_a_tumbling_target() -> None:
    """The safety section's abort-safety sentence names the keep-out zones turning with the
    target's attitude for a tumbling target, and one fixed keep-out zone otherwise (only the
    reported point's configuration is read)."""
    from types import SimpleNamespace

    from cwrend_cli.config.io import load_config
    from cwrend_cli.report.markdown import _abort_text

    def text(campaign: str) -> str:
        return _abort_text(SimpleNamespace(point_config=load_config(CAMPAIGNS / campaign)))

    assert "turning with the target's attitude" in text("tumbling_target.toml")
    assert "turning" not in text("safe_approach.toml")
    assert "enters the keep-out zone within" in text("safe_approach.toml")
