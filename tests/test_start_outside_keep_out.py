"""A start inside the unsafe set at t = 0 is refused (daily use).

``cwrend config validate campaigns/safe_approach.toml --set scenario.x0=[0,0,0.1,0,0,0]``
passed and ``cwrend run`` exited 0. The unsafe set is the keep-out zone (every
ellipsoid, in the body frame of a tumbling target) minus the corridor
(docs/guide/safe-approach.md): a start there is refused, exit 2, naming
``scenario.x0``, the ellipsoid and the fix; a start in the corridor is safe.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign.plan import plan
from cwrend_cli.cli import app
from cwrend_cli.config.io import config_from_dict
from cwrend_cli.errors import ConfigError

SAFE_APPROACH = Path(__file__).resolve().parents[1] / "campaigns" / "safe_approach.toml"
runner = CliRunner()

#: A bus of 0.1 km and a panel straight out along the corridor (-z) from the port on the
#: bus's surface, so the corridor runs through the panel.
PANELLED: dict[str, Any] = {
    "constraints": {
        "keep_out": {
            "semi_axes_km": [0.1, 0.1, 0.1],
            "bodies": [
                {"centre_km": [0.0, 0.0, -0.3], "semi_axes_km": [0.05, 0.05, 0.05]},
                {"centre_km": [0.0, 0.3, 0.0], "semi_axes_km": [0.05, 0.05, 0.05]},
            ],
        },
        "corridor": {"port_km": [0.0, 0.0, -0.1], "axis": [0.0, 0.0, -1.0], "half_angle_deg": 10.0},
    }
}


def _at(cfg: dict[str, Any], x0: list[float]) -> dict[str, Any]:
    return {**cfg, "scenario": {"x0": [*x0, 0.0, 0.0, 0.0]}}


def test_a_start_inside_the_keep_out_zone_exits_2_naming_x0_and_the_zone() -> None:
    result = runner.invoke(
        app, ["config", "validate", str(SAFE_APPROACH), "--set", "scenario.x0=[0,0,0.1,0,0,0]"]
    )
    assert result.exit_code == 2, result.output
    assert "scenario.x0 = [0.0, 0.0, 0.1, 0.0, 0.0, 0.0]" in result.output
    assert "inside the keep-out zone" in result.output
    assert "change constraints.keep_out.semi_axes_km" in result.output
    assert "Traceback" not in result.output


def test_a_start_on_the_keep_out_surface_is_safe() -> None:
    """The zone is open ((x/a)² + … < 1): its surface is outside it."""
    config_from_dict(_at(PANELLED, [0.0, 0.1, 0.0]))


def test_a_start_inside_the_corridor_within_the_zone_is_safe() -> None:
    """Inside the panel on the corridor's axis: in the corridor, hence safe."""
    config_from_dict(_at(PANELLED, [0.0, 0.0, -0.3]))


def test_a_start_inside_another_body_names_that_body() -> None:
    with pytest.raises(ConfigError, match=r"constraints\.keep_out\.bodies\.1"):
        config_from_dict(_at(PANELLED, [0.0, 0.3, 0.0]))


TUMBLING: dict[str, Any] = {
    # a rod along the body's y axis, turned 90° about x at t = 0: y_body along +z
    "constraints": {"keep_out": {"semi_axes_km": [0.05, 0.5, 0.05]}},
    "target": {
        "attitude": "tumbling",
        "initial_quaternion": [2**-0.5, 2**-0.5, 0.0, 0.0],
        "body_rates_deg_s": [0.0, 0.0, 0.0],
    },
}


def test_a_tumbling_target_zone_is_taken_at_its_attitude_at_t0() -> None:
    with pytest.raises(ConfigError, match=r"scenario\.x0.*body frame at t = 0"):
        config_from_dict(_at(TUMBLING, [0.0, 0.0, 0.3]))
    config_from_dict(_at(TUMBLING, [0.0, 0.3, 0.0]))  # along y of the frame: outside the rod


def test_a_swept_start_inside_the_zone_is_refused_at_its_point() -> None:
    cfg = config_from_dict(
        {**PANELLED, "sweep": {"scenario.x0.1": [10.0, 0.3], "scenario.x0.2": [0.0]}}
    )
    with pytest.raises(ConfigError, match=r"scenario\.x0"):
        plan(cfg, ["mtf_adaptive_socp"], [0])


def test_a_dispersed_start_inside_the_zone_is_refused() -> None:
    disp = {"scenario.x0.2": {"dist": "uniform", "low": -31.0, "high": -30.9}}
    cfg = config_from_dict({**_at(PANELLED, [0.0, 0.0, 31.0]), "dispersions": disp})
    with pytest.raises(ConfigError, match=r"scenario\.x0"):
        plan(cfg, ["mtf_adaptive_socp"], [0])
