"""The ``[sensor]`` section (issue 35 item 1): what the chaser measures.

Default ``"position"``: without the section (or with it at its defaults) the
resolved tree, the config hash and the typed problem are today's, so every number
and hash is unchanged (tests/test_same_numbers.py checks the numbers). Fields that
make no sense with the chosen sensor are refused naming the field, exit 2.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.config.io import config_from_dict, config_hash, resolved_dict
from cwrend_cli.config.schema import CwrendConfig, SensorConfig
from cwrend_cli.output.tables import steps_table
from cwrend_cli.physics import params, sensors, simulation

runner = CliRunner()
REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("table", [{}, {"model": "position"}])
def test_a_config_without_a_sensor_keeps_its_hash_and_tree(table: dict[str, str]) -> None:
    written = config_from_dict({"sensor": table})
    default = CwrendConfig()
    assert "sensor" not in resolved_dict(written)
    assert config_hash(written) == config_hash(default)
    assert config_hash(CwrendConfig(sensor=SensorConfig())) == config_hash(default)
    assert problem_of(written) == params.Problem()


def test_the_typed_problem_carries_the_sensor() -> None:
    cfg = config_from_dict({"sensor": {"model": "range_bearing", "sigma_angle_deg": 0.1}})
    assert problem_of(cfg).sensor == params.Sensor(model="range_bearing", sigma_angle_deg=0.1)
    tree = resolved_dict(cfg)
    assert tree["sensor"]["model"] == "range_bearing"
    assert config_from_dict(tree) == cfg


@pytest.mark.parametrize(
    ("table", "offset"),
    [
        ({"sensor": {"model": "angles"}}, 2.0),  # m = 2 (paper Eq. 24)
        ({"sensor": {"model": "range_bearing"}}, 3.0),
        ({"sensor": {"model": "angles"}, "schedule": {"nis_offset": 3.0}}, 3.0),  # as given
    ],
)
def test_the_nis_offset_defaults_to_the_measurement_dimension(
    table: dict[str, dict[str, object]], offset: float
) -> None:
    assert config_from_dict(table).schedule.nis_offset == offset


@pytest.mark.parametrize(
    ("sets", "field", "words"),
    [
        (("sensor.sigma_angle_deg=0.1",), "sensor.sigma_angle_deg", "measures no angle"),
        (
            ("sensor.model='angles'", "sensor.sigma_range_km=0.01"),
            "sensor.sigma_range_km",
            "measures no range",
        ),
        (
            ("sensor.model='range_bearing'", "estimator.r_nominal_km2=[4e-6, 4e-6, 4e-6]"),
            "estimator.r_nominal_km2",
            "sensor.sigma_range_km",
        ),
        (
            ("sensor.model='angles'", "degradation.windows.0.r_scale=[1.0, 2.0, 3.0]"),
            "degradation.windows.0.r_scale",
            "one value or 2",
        ),
        (
            ("degradation.windows.0.outlier_probability=[0.05, 0.0]",),
            "degradation.windows.0.outlier_probability",
            "one value or 3",
        ),
        (
            ("sensor.model='angles'", "degradation.windows.1.bias_range_km=0.01"),
            "degradation.windows.1.bias_range_km",
            "measures no range",
        ),
        (
            ("degradation.windows.1.bias_angles_deg=[0.1, 0.0]",),
            "degradation.windows.1.bias_angles_deg",
            "measures no angle",
        ),
        (("sensor.model='lidar'",), "sensor.model", "'range_bearing'"),
    ],
)
def test_a_bad_sensor_config_exits_2_naming_the_field(
    refused_override: Callable[..., str], sets: tuple[str, ...], field: str, words: str
) -> None:
    err = refused_override(*sets)  # exit 2, no traceback
    assert field in err and words in err, err


@pytest.mark.parametrize("model", ["range_bearing", "angles"])
def test_the_paper_config_validates_with_each_nonlinear_sensor(model: str) -> None:
    # with a per-component r_scale of the sensor's dimension in the first window
    scale = "[300, 1]" if model == "angles" else "[1, 300, 300]"
    args = ["config", "validate", str(REPO / "campaigns/paper.toml"), "--set"]
    result = runner.invoke(
        app, [*args, f"sensor.model='{model}'", "--set", f"degradation.windows.0.r_scale={scale}"]
    )
    assert result.exit_code == 0 and result.output.startswith("OK "), result.output


def test_an_angles_run_logs_two_components_and_writes_them_in_degrees() -> None:
    # a short angles-only run (60 s, no windows): y holds (azimuth, elevation) [rad] and NaN,
    # the steps table the azimuth and elevation in degrees and no position measurement
    problem = params.Problem(
        scenario=params.Scenario(horizon_s=60.0, x0=(0.01, 0.0, 0.3, 0.0, 0.0, 0.0)),
        guidance=params.Guidance(t_min_rem_s=20.0),
        degradation=params.Degradation(windows=()),
        sensor=params.Sensor(model="angles"),
    )
    refs = simulation.open_loop_references(problem)
    z = sensors.standard_normal_stream(0, problem.scenario.n_steps)
    arch = params.Architecture("mtf_adaptive", "mtf", adaptive=True)
    result = simulation.simulate(problem, arch, z, refs)
    assert np.isfinite(result.y[1:, :2]).all() and np.isnan(result.y[:, 2]).all()
    assert np.isfinite(result.nis[1:]).all()
    table = steps_table(result).to_pandas()
    np.testing.assert_allclose(table["meas_azimuth_deg"][1:], np.rad2deg(result.y[1:, 0]))
    np.testing.assert_allclose(table["meas_elevation_deg"][1:], np.rad2deg(result.y[1:, 1]))
    assert table["meas_range_km"].isna().all() and table["meas_x_km"].isna().all()


def _offsets(table: dict, param: str = "sensor.model=position,angles") -> dict[str, float]:
    from cwrend_cli.campaign.plan import plan

    tasks = plan(config_from_dict(table), ["mtf_adaptive"], [0], [param]).tasks
    return {t.problem.sensor.model: t.problem.schedule.nis_offset for t in tasks}


@pytest.mark.parametrize("base", [{}, {"sensor": {"model": "angles"}}])
def test_a_sweep_over_the_sensor_gives_each_point_its_own_nis_offset(base: dict) -> None:
    # nis_offset not given: each point's m (paper Eq. 24), not the base's resolved value
    assert _offsets(base) == {"position": 3.0, "angles": 2.0}


@pytest.mark.parametrize("offset", [3.0, 2.5])
def test_a_given_nis_offset_is_kept_at_every_point_of_a_sensor_sweep(offset: float) -> None:
    assert _offsets({"schedule": {"nis_offset": offset}}) == {"position": offset, "angles": offset}


def test_a_swept_nis_offset_is_kept_with_the_sensor_swept_in_the_file() -> None:
    table = {"sweep": {"sensor.model": ["angles"]}}
    assert _offsets(table, "schedule.nis_offset=2.5") == {"angles": 2.5}


@pytest.mark.parametrize(
    ("table", "given"), [({}, False), ({"schedule": {"nis_offset": 3.0}}, True)]
)
def test_the_manifest_records_whether_the_nis_offset_was_given(table: dict, given: bool) -> None:
    """The manifest's ``config`` is resolved (its offset looks given): ``nis_offset_given``,
    outside it, lets a report fill in each point's offset as the campaign did."""
    from cwrend_cli.campaign.journal import new_manifest
    from cwrend_cli.campaign.plan import plan

    planned = plan(config_from_dict(table), ["mtf_adaptive"], [0], ["sensor.model=angles"])
    manifest = new_manifest(planned, command="sweep", executor={}, started=0.0)
    assert manifest["nis_offset_given"] is given
