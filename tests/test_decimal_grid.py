"""Grid ranges give the decimal values a person wrote (issue 37, item 3).

``start:stop:num`` (``--param`` and the ``[sweep]`` table) is computed in
decimal arithmetic from the numbers as typed and converted to a float once;
``numpy.linspace`` gave 0.0007999999999999999 for ``6e-4:1e-3:5``, which the
runs simulated and stored (``== 0.0008`` found no row).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign import design
from cwrend_cli.cli import app
from cwrend_cli.config.overrides import decimal_float, expand_grid, parse_param
from cwrend_cli.errors import ConfigError

U_MAX = [6e-4, 7e-4, 8e-4, 9e-4, 1e-3]


def test_a_param_range_gives_the_decimal_values_exactly() -> None:
    assert parse_param("scenario.u_max_km_s2=6e-4:1e-3:5") == ("scenario.u_max_km_s2", tuple(U_MAX))


def test_a_sweep_table_range_gives_the_decimal_values_exactly() -> None:
    grid = dict(expand_grid({"scenario.u_max_km_s2": "6e-4:1e-3:5", "schedule.beta": "0.1:0.5:5"}))
    assert grid["scenario.u_max_km_s2"] == tuple(U_MAX)
    assert grid["schedule.beta"] == (0.1, 0.2, 0.3, 0.4, 0.5)  # linspace: 0.30000000000000004


def test_a_range_keeps_its_ends_and_its_digits() -> None:
    """The ends as typed (more digits than a design rounds to are kept); one value is start."""
    assert parse_param("x=0.123456789012:1:3")[1] == (0.123456789012, 0.561728394506, 1.0)
    assert parse_param("x=2.5:7:1")[1] == (2.5,)
    assert parse_param("x=1:0:3")[1] == (1.0, 0.5, 0.0)
    assert parse_param("x=0:1:4")[1] == (0.0, 0.3333333333, 0.6666666667, 1.0)


@pytest.mark.parametrize("spec", ["inf:1:3", "0:nan:3", "1e999:1:3", "a:1:3", "0:1:x"])
def test_a_range_of_non_numbers_is_refused(spec: str) -> None:
    with pytest.raises(ConfigError, match="a range is 'start:stop:num'"):
        parse_param(f"schedule.beta={spec}")


def test_designs_and_ranges_round_with_one_function() -> None:
    assert design.SIGNIFICANT_DIGITS == 10
    r = design.ParameterRange("scenario.u_max_km_s2", "float", 6e-4, 1e-3)
    assert r.value(0.5) == decimal_float(6e-4 + 0.5 * 4e-4) == 8e-4


def test_the_runs_use_and_store_the_decimal_value(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path}"\n')
    args = ["sweep", str(cfg), "--name", "u", "--arch", "mtf_adaptive", "--seeds", "1", "-w",
            "1", "--no-rrd", "-q", "--param", "scenario.u_max_km_s2=6e-4:1e-3:5"]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    runs = pd.read_parquet(tmp_path / "u" / "runs.parquet")
    assert sorted(runs["param.scenario.u_max_km_s2"]) == U_MAX
    assert len(runs[runs["param.scenario.u_max_km_s2"] == 0.0008]) == 1


def test_a_param_without_values_names_the_option_and_its_forms() -> None:
    """``--param schedule.beta`` said "malformed override …: expected KEY=VALUE", the
    wording of ``--set``."""
    with pytest.raises(ConfigError, match=r"--param 'schedule.beta': expected KEY=VALUES"):
        parse_param("schedule.beta")


@pytest.mark.parametrize("spec", ["0.1:0.5", "0:1:5:2"])
def test_a_range_without_its_count_is_refused_as_a_range(spec: str) -> None:
    """``--param schedule.beta=0.1:0.5`` was taken for the string '0.1:0.5' and refused
    later as "grid point p… is invalid: must be a number"."""
    with pytest.raises(ConfigError, match=r"a range is start:stop:num, e\.g\. schedule.beta="):
        parse_param(f"schedule.beta={spec}")


def test_a_value_with_a_colon_that_is_not_a_range_stays_a_string() -> None:
    assert parse_param("output.name=run:a") == ("output.name", ("run:a",))
