"""The ``[constraints]`` section (issue 32, item 1): off by default, validated, settable.

Off, the section leaves no trace: the resolved tree, the config hash and the typed
problem are those of a config without it (so every campaign hash and number of
today's configs is unchanged). On, every field is checked at validation (exit 2
naming the field), ``scenario.xf`` defaults to the corridor's port at rest and an
``xf`` that contradicts it is refused, and the values are shown, ``--set``,
swept and dispersed like any other.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign.plan import plan
from cwrend_cli.cli import app
from cwrend_cli.config.adapt import problem_of, with_values
from cwrend_cli.config.io import config_from_dict, config_hash, resolved_dict
from cwrend_cli.config.schema import ConstraintsConfig, CwrendConfig
from cwrend_cli.physics import params

runner = CliRunner()

KEEP_OUT = {"semi_axes_km": [0.1, 0.2, 0.1]}
CORRIDOR = {"port_km": [0.0, 0.2, 0.0], "axis": [0.0, 2.0, 0.0], "half_angle_deg": 20.0}
ON: dict[str, Any] = {"constraints": {"keep_out": KEEP_OUT, "corridor": CORRIDOR}}


def test_a_config_without_constraints_keeps_its_hash_and_tree() -> None:
    """An empty [constraints] table (the default) hashes and resolves as no table at all."""
    written = config_from_dict({"constraints": {}})
    default = CwrendConfig()
    assert "constraints" not in resolved_dict(written)
    assert config_hash(written) == config_hash(default)
    assert config_hash(CwrendConfig(constraints=ConstraintsConfig())) == config_hash(default)
    assert problem_of(written).constraints is None
    assert problem_of(written) == params.Problem()


def test_a_corridor_sets_the_terminal_state_to_the_port_at_rest() -> None:
    cfg = config_from_dict(ON)
    assert cfg.scenario.xf == (0.0, 0.2, 0.0, 0.0, 0.0, 0.0)
    # the resolved tree (the campaign's base) validates back to the same config
    assert config_from_dict(resolved_dict(cfg)) == cfg


def test_an_xf_equal_to_the_port_at_rest_is_accepted() -> None:
    cfg = config_from_dict({**ON, "scenario": {"xf": [0, 0.2, 0, 0, 0, 0]}})
    assert cfg.scenario.xf == (0.0, 0.2, 0.0, 0.0, 0.0, 0.0)


def test_the_typed_problem_carries_the_constraints_as_given() -> None:
    c = problem_of(config_from_dict({"constraints": {**ON["constraints"], "sigma_margin": 3}}))
    assert c.constraints == params.Constraints(
        keep_out=params.KeepOut((0.1, 0.2, 0.1)),
        corridor=params.Corridor((0.0, 0.2, 0.0), (0.0, 2.0, 0.0), 20.0),
        sigma_margin=3.0,
    )


REFUSED = {
    "a port inside the keep-out zone": (
        ["constraints.corridor.port_km=[0, 0.1, 0]"],
        "constraints.corridor.port_km = [0.0, 0.1, 0.0]: must lie on or outside the keep-out",
    ),
    "a half-angle of 0": (["constraints.corridor.half_angle_deg=0"], "half_angle_deg = 0"),
    "a half-angle of 90": (["constraints.corridor.half_angle_deg=90"], "half_angle_deg = 90"),
    "a negative half-angle": (["constraints.corridor.half_angle_deg=-5"], "half_angle_deg = -5"),
    "a zero semi-axis": (
        ["constraints.keep_out.semi_axes_km=[0.1, 0, 0.1]"],
        "constraints.keep_out.semi_axes_km.1 = 0",
    ),
    "a negative semi-axis": (
        ["constraints.keep_out.semi_axes_km=[-0.1, 0.2, 0.1]"],
        "constraints.keep_out.semi_axes_km.0 = -0.1",
    ),
    "two semi-axes": (["constraints.keep_out.semi_axes_km=[0.1, 0.2]"], "semi_axes_km"),
    "a zero axis": (
        ["constraints.corridor.axis=[0, 0, 0]"],
        "constraints.corridor.axis = [0, 0, 0]: must be a non-zero vector",
    ),
    "an xf away from the port": (
        ["scenario.xf=[0, 0, 0, 0, 0, 0]"],
        "scenario.xf = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]: with a corridor the terminal state is "
        "the port at rest",
    ),
    "an xf moving at the port": (["scenario.xf=[0, 0.2, 0, 0, -1e-4, 0]"], "scenario.xf"),
    "a negative sigma margin": (["constraints.sigma_margin=-1"], "constraints.sigma_margin"),
    "an unknown key": (["constraints.keep_out.radius_km=0.1"], "constraints.keep_out.radius_km"),
}


def _write(tmp_path: Path) -> Path:
    path = tmp_path / "c.toml"
    path.write_text(
        "[constraints.keep_out]\nsemi_axes_km = [0.1, 0.2, 0.1]\n"
        "[constraints.corridor]\nport_km = [0.0, 0.2, 0.0]\naxis = [0.0, 1.0, 0.0]\n"
        "half_angle_deg = 20.0\n",
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_bad_constraint_exits_2_naming_the_field(case: str, tmp_path: Path) -> None:
    sets, message = REFUSED[case]
    args = ["config", "validate", str(_write(tmp_path))]
    result = runner.invoke(app, args + [a for s in sets for a in ("--set", s)])
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert "Traceback" not in result.output


def test_config_show_prints_the_constraints(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["config", "show", str(_write(tmp_path)), "--set", "constraints.sigma_margin=3"]
    )
    assert result.exit_code == 0, result.output
    assert "[constraints.keep_out]" in result.output
    assert "[constraints.corridor]" in result.output
    assert "sigma_margin = 3.0" in result.output
    assert "half_angle_deg = 20.0" in result.output


def test_set_creates_the_section_in_an_empty_config(tmp_path: Path) -> None:
    empty = tmp_path / "empty.toml"
    empty.write_text("", encoding="utf-8")
    sets = [
        "constraints.keep_out.semi_axes_km=[0.1, 0.2, 0.1]",
        "constraints.corridor.port_km=[0, 0.2, 0]",
        "constraints.corridor.axis=[0, 1, 0]",
        "constraints.corridor.half_angle_deg=15",
    ]
    result = runner.invoke(
        app, ["config", "show", str(empty), *[a for s in sets for a in ("--set", s)]]
    )
    assert result.exit_code == 0, result.output
    assert "half_angle_deg = 15.0" in result.output


def test_sigma_margin_is_swept_like_any_value() -> None:
    cfg = config_from_dict({**ON, "sweep": {"constraints.sigma_margin": [0.0, 3.0]}})
    campaign = plan(cfg, ["mtf_adaptive_socp"], [0])
    margins = sorted(
        t.problem.constraints.sigma_margin for t in campaign.tasks if t.problem.constraints
    )
    assert margins == [0.0, 3.0]


def test_the_corridor_half_angle_is_dispersed_like_any_value() -> None:
    disp = {"constraints.corridor.half_angle_deg": {"dist": "uniform", "low": -5.0, "high": 5.0}}
    cfg = config_from_dict({**ON, "dispersions": disp})
    campaign = plan(cfg, ["mtf_adaptive_socp"], [0, 1, 2])
    angles = []
    for task in campaign.tasks:
        for run in task.runs:
            problem = with_values(task.problem, run.dispersed)
            assert problem.constraints is not None and problem.constraints.corridor is not None
            angles.append(problem.constraints.corridor.half_angle_deg)
    assert len(set(angles)) == 3
    assert all(15.0 <= a <= 25.0 for a in angles)


@pytest.mark.parametrize(
    ("column", "unit"),
    [
        ("param.constraints.sigma_margin", "-"),
        ("param.constraints.corridor.axis.1", "-"),
        ("disp.constraints.corridor.half_angle_deg", "deg"),
        ("param.constraints.keep_out.semi_axes_km.0", "km"),
        ("param.constraints.corridor.port_km.2", "km"),
    ],
)
def test_swept_and_dispersed_constraint_values_have_units(column: str, unit: str) -> None:
    from cwrend_cli.output.tables import unit_of

    assert unit_of(column) == unit
