"""A cone-program run that would plan into the keep-out zone is refused (daily use).

``cwrend run campaigns/paper.toml --set constraints.keep_out.semi_axes_km=[0.2,0.2,0.2]
-a mtf_adaptive_socp`` exited 0 and said "converged 78/78": with no corridor the
terminal state stays ``scenario.xf``, the target's centre, inside the zone, and every
plan was softened by the zone's full depth (slack 0.2 km, the true path 200 m deep).
Where a cone-program architecture plans with the constraints, such a ``scenario.xf`` is
refused, exit 2, naming it and the fixes; the shooting architectures and a measure-only
config (``constraints.enforce = false``) only measure the zone and may end there.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign.plan import check_terminal_state
from cwrend_cli.cli import app
from cwrend_cli.config import ALL_ARCHITECTURES
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.config.io import config_from_dict
from cwrend_cli.errors import ConfigError

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
ZONE = {"keep_out": {"semi_axes_km": [0.2, 0.2, 0.2]}}  # round the paper's xf, the origin
runner = CliRunner()


def _check(constraints: dict[str, Any], arch: str, **scenario: Any) -> None:
    cfg = config_from_dict({"constraints": constraints, "scenario": scenario})
    check_terminal_state(cfg, problem_of(cfg), [ALL_ARCHITECTURES[arch]])


def test_a_cone_program_planning_into_the_zone_exits_2_naming_xf(tmp_path: Path) -> None:
    args = ["run", str(PAPER), "-a", "mtf_adaptive_socp", "-o", str(tmp_path / "run"),
            "--set", "constraints.keep_out.semi_axes_km=[0.2, 0.2, 0.2]"]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "scenario.xf = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]: the terminal position" in result.output
    assert "constraints.keep_out.semi_axes_km" in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "run").exists()


def test_a_shooting_architecture_only_measures_the_zone_and_may_end_in_it() -> None:
    _check(ZONE, "mtf_adaptive")  # no error


def test_a_measure_only_config_may_end_in_the_zone() -> None:
    _check({**ZONE, "enforce": False}, "mtf_adaptive_socp")  # no error


def test_an_xf_outside_the_zone_is_planned() -> None:
    _check(ZONE, "mtf_adaptive_socp", xf=[0.0, 0.0, 0.3, 0.0, 0.0, 0.0])  # no error


def test_an_xf_inside_another_body_names_that_body() -> None:
    body = {"centre_km": [0.0, 0.0, 0.3], "semi_axes_km": [0.05, 0.05, 0.05]}
    bodies = {"keep_out": {"semi_axes_km": [0.1, 0.1, 0.1], "bodies": [body]}}
    with pytest.raises(ConfigError) as caught:
        _check(bodies, "mtf_fixed_socp", xf=[0.0, 0.0, 0.31, 0.0, 0.0, 0.0])
    assert "in the ellipsoid constraints.keep_out.bodies.0" in " ".join(caught.value.problems)
