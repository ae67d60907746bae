"""The ``[target]`` section (issue 34, item 1): off (fixed) by default, validated, settable.

Fixed, the section leaves no trace: the resolved tree, the config hash and the typed
problem are those of a config without it. Tumbling, every field is checked at
validation (exit 2 naming the field), is shown, ``--set``, swept and dispersed like
any other. With ``[constraints]`` it is accepted: they are given in the body frame
(``test_tumbling_config``).
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
from cwrend_cli.config.schema import CwrendConfig
from cwrend_cli.physics import params

runner = CliRunner()

TUMBLING: dict[str, Any] = {
    "target": {
        "attitude": "tumbling",
        "initial_quaternion": [1.0, 0.0, 0.0, 0.2],
        "body_rates_deg_s": [1.0, 5.0, 0.5],
        "inertia": [1.0, 2.0, 2.5],
    }
}


@pytest.mark.parametrize("written", [{}, {"target": {}}, {"target": {"attitude": "fixed"}}])
def test_a_fixed_target_keeps_the_hash_and_the_tree(written: dict[str, Any]) -> None:
    cfg = config_from_dict(written)
    assert "target" not in resolved_dict(cfg)
    assert config_hash(cfg) == config_hash(CwrendConfig())
    assert problem_of(cfg) == params.Problem()


def test_the_typed_problem_carries_the_target_as_given() -> None:
    cfg = config_from_dict(TUMBLING)
    assert problem_of(cfg).target == params.Target(
        attitude="tumbling",
        initial_quaternion=(1.0, 0.0, 0.0, 0.2),
        body_rates_deg_s=(1.0, 5.0, 0.5),
        inertia=(1.0, 2.0, 2.5),
    )
    assert config_from_dict(resolved_dict(cfg)) == cfg  # the resolved tree validates back


REFUSED = {
    "a zero quaternion": (
        "target.initial_quaternion=[0, 0, 0, 0]",
        "target.initial_quaternion = [0, 0, 0, 0]: must be a non-zero quaternion",
    ),
    "three quaternion entries": ("target.initial_quaternion=[1, 0, 0]", "must have 4 entries"),
    "a zero moment": ("target.inertia=[0, 1, 1]", "target.inertia.0 = 0: must be > 0"),
    "a negative moment": ("target.inertia=[1, -1, 1]", "target.inertia.1 = -1"),
    "moments no body has": (
        "target.inertia=[1, 1, 2.5]",
        "target.inertia = [1, 1, 2.5]: no rigid body has these moments: I3 = 2.5 exceeds the "
        "sum of the other two (2)",
    ),
    "a rate above the bound": (
        "target.body_rates_deg_s=[0, 61, 0]",
        "target.body_rates_deg_s.1 = 61: must be <= 60",
    ),
    "an unknown attitude": ("target.attitude='spinning'", "target.attitude"),
    "tumbling fields on a fixed target": (
        "target.attitude='fixed'",
        "target.initial_quaternion = [1.0, 0.0, 0.0, 0.2]: applies to a tumbling target only",
    ),
    "an unknown key": ("target.spin_deg_s=1", "target.spin_deg_s"),
}


def _write(tmp_path: Path) -> Path:
    path = tmp_path / "t.toml"
    path.write_text(
        '[target]\nattitude = "tumbling"\ninitial_quaternion = [1.0, 0.0, 0.0, 0.2]\n'
        "body_rates_deg_s = [1.0, 5.0, 0.5]\ninertia = [1.0, 2.0, 2.5]\n",
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_bad_target_exits_2_naming_the_field(case: str, tmp_path: Path) -> None:
    setting, message = REFUSED[case]
    result = runner.invoke(app, ["config", "validate", str(_write(tmp_path)), "--set", setting])
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert "Traceback" not in result.output


def test_a_run_of_a_refused_target_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "out"
    args = ["run", str(_write(tmp_path)), "-o", str(out), "--set", "target.inertia=[1, 1, 3]"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert not out.exists()


def test_config_show_prints_the_target(tmp_path: Path) -> None:
    result = runner.invoke(app, ["config", "show", str(_write(tmp_path)), "--format", "json"])
    assert result.exit_code == 0, result.output
    assert '"attitude": "tumbling"' in result.output
    assert '"body_rates_deg_s"' in result.output


def test_set_creates_the_section_in_an_empty_config(tmp_path: Path) -> None:
    empty = tmp_path / "empty.toml"
    empty.write_text("", encoding="utf-8")
    sets = ["target.attitude='tumbling'", "target.body_rates_deg_s=[0, 2, 0]"]
    result = runner.invoke(
        app, ["config", "show", str(empty), *[a for s in sets for a in ("--set", s)]]
    )
    assert result.exit_code == 0, result.output
    assert "[target]" in result.output
    assert 'attitude = "tumbling"' in result.output


def test_a_body_rate_is_swept_like_any_value() -> None:
    cfg = config_from_dict({**TUMBLING, "sweep": {"target.body_rates_deg_s.1": [0.0, 5.0, 10.0]}})
    campaign = plan(cfg, ["mtf_adaptive"], [0])
    rates = sorted(t.problem.target.body_rates_deg_s[1] for t in campaign.tasks)
    assert rates == [0.0, 5.0, 10.0]


def test_a_body_rate_is_dispersed_like_any_value() -> None:
    disp = {"target.body_rates_deg_s.0": {"dist": "uniform", "low": -2.0, "high": 2.0}}
    cfg = config_from_dict({**TUMBLING, "dispersions": disp})
    campaign = plan(cfg, ["mtf_adaptive"], [0, 1, 2])
    rates = [
        with_values(task.problem, run.dispersed).target.body_rates_deg_s[0]
        for task in campaign.tasks
        for run in task.runs
    ]
    assert len(set(rates)) == 3
    assert all(-1.0 <= r <= 3.0 for r in rates)


@pytest.mark.parametrize(
    ("column", "unit"),
    [
        ("param.target.body_rates_deg_s.1", "deg/s"),
        ("disp.target.initial_quaternion.0", "-"),
        ("param.target.inertia.2", "-"),
        ("param.target.attitude", "-"),
        ("target_q0", "-"),
        ("target_wz_deg_s", "deg/s"),
    ],
)
def test_target_values_and_columns_have_units(column: str, unit: str) -> None:
    from cwrend_cli.output.tables import unit_of

    assert unit_of(column) == unit
