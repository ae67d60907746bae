"""Tests of ``cwrend config validate|show`` and the CLI error handling."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cwrend_cli import __version__
from cwrend_cli.cli import app
from cwrend_cli.config import config_hash, load_config

REPO = Path(__file__).resolve().parents[1]
PAPER_TOML = REPO / "campaigns" / "paper.toml"
runner = CliRunner()


def test_validate_paper_toml_ok() -> None:
    result = runner.invoke(app, ["config", "validate", str(PAPER_TOML)])
    assert result.exit_code == 0, result.output
    assert result.stdout.strip() == f"OK {config_hash(load_config(PAPER_TOML))}"


def test_validate_bad_override_exits_2_naming_field() -> None:
    result = runner.invoke(
        app, ["config", "validate", str(PAPER_TOML), "--set", "schedule.alpha_eps=1.5"]
    )
    assert result.exit_code == 2
    assert "error:" in result.stderr
    assert "schedule.alpha_eps = 1.5: must be <= 1" in result.stderr
    assert "Traceback" not in result.output


def test_validate_unknown_override_key_exits_2() -> None:
    result = runner.invoke(app, ["config", "validate", str(PAPER_TOML), "-s", "scenario.foo=1"])
    assert result.exit_code == 2
    assert "scenario.foo: unknown key" in result.stderr


def test_validate_malformed_override_exits_2() -> None:
    result = runner.invoke(app, ["config", "validate", str(PAPER_TOML), "--set", "nokey"])
    assert result.exit_code == 2
    assert "malformed override" in result.stderr


def test_validate_missing_file_exits_2(tmp_path: Path) -> None:
    result = runner.invoke(app, ["config", "validate", str(tmp_path / "absent.toml")])
    assert result.exit_code == 2
    assert "config file not found" in result.stderr
    assert "Traceback" not in result.output


def test_show_toml_includes_hash_and_override() -> None:
    result = runner.invoke(app, ["config", "show", str(PAPER_TOML), "--set", "schedule.beta=0.5"])
    assert result.exit_code == 0, result.output
    cfg = load_config(PAPER_TOML, ["schedule.beta=0.5"])
    assert f"# config_hash = {config_hash(cfg)}" in result.stdout
    assert "beta = 0.5" in result.stdout


def test_show_json_is_the_resolved_config() -> None:
    result = runner.invoke(app, ["config", "show", str(PAPER_TOML), "--format", "json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["output"]["name"] == "paper"
    assert data["scenario"]["horizon_s"] == 800.0


def test_version() -> None:
    result = runner.invoke(app, ["--version"])
    assert result.exit_code == 0
    assert __version__ in result.stdout


def test_unknown_command_option_exits_2() -> None:
    result = runner.invoke(app, ["config", "validate", str(PAPER_TOML), "--nope"])
    assert result.exit_code == 2


def test_a_number_given_with_its_unit_is_told_to_drop_it() -> None:
    """``--set scenario.horizon_s=800s`` said only "must be a number"; the key's unit is fixed
    (its description's, the suffix of its name), so the fix is the number alone."""
    args = ["config", "validate", str(PAPER_TOML), "--set", "scenario.horizon_s=800s",
            "--set", 'scenario.u_max_km_s2="0.8 m/s^2"', "--set", "schedule.beta=abc"]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert 'scenario.horizon_s = "800s": must be a number; write the number alone, in s' in (
        result.stderr
    )
    assert "write the number alone, in km/s²" in result.stderr
    assert 'schedule.beta = "abc": must be a number\n' in result.stderr  # no number: no hint


def test_the_command_list_says_report_writes_report_html() -> None:
    """``cwrend --help`` listed report as "Figures (PNG) and report.md …", leaving out the
    self-contained report.html the tour and the guide open."""
    result = runner.invoke(app, ["--help"], env={"COLUMNS": "80"})
    line = next(x for x in result.stdout.splitlines() if x.strip().startswith("report"))
    assert "report.html" in line and len(line) <= 80


def _validate_and_sweep(tmp_path: Path, text: str) -> tuple[str, str]:
    """The errors of ``config validate`` and of ``sweep`` for one config (both exit 2)."""
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(text + f"\n[output]\ndir = {json.dumps(str(tmp_path / 'out'))}\n")
    checked = runner.invoke(app, ["config", "validate", str(cfg)])
    swept = runner.invoke(app, ["sweep", str(cfg), "-n", "1", "-a", "plain_adaptive", "-q"])
    assert swept.exit_code == 2, swept.output
    assert checked.exit_code == 2, checked.output
    assert "Traceback" not in checked.output
    assert not (tmp_path / "out").exists()
    return checked.stderr, swept.stderr


def test_validate_refuses_a_misspelt_dispersion_key_as_sweep_does(tmp_path: Path) -> None:
    checked, swept = _validate_and_sweep(
        tmp_path, '[dispersions]\n"scenario.xo.2" = { dist = "normal", std = 0.05 }\n'
    )
    assert "dispersions.scenario.xo.2: no such config value to disperse" in checked
    assert checked == swept


def test_validate_refuses_a_dispersion_index_out_of_range_as_sweep_does(tmp_path: Path) -> None:
    checked, swept = _validate_and_sweep(
        tmp_path, '[dispersions]\n"scenario.x0.9" = { dist = "normal", std = 0.05 }\n'
    )
    assert "dispersions.scenario.x0.9: no such config value to disperse" in checked
    assert checked == swept


def test_validate_refuses_a_noise_file_with_bad_columns_as_sweep_does(tmp_path: Path) -> None:
    (tmp_path / "n.csv").write_text("a,b\n1,2\n")
    checked, swept = _validate_and_sweep(tmp_path, '[noise]\nfile = "n.csv"\n')
    assert "missing column(s) n1, n2, n3" in checked
    assert checked == swept


def test_validate_refuses_a_noise_file_with_too_few_rows_as_sweep_does(tmp_path: Path) -> None:
    (tmp_path / "n.csv").write_text("n1,n2,n3\n" + "0,0,0\n" * 10)
    checked, swept = _validate_and_sweep(tmp_path, '[noise]\nfile = "n.csv"\n')
    assert "noise.file" in checked and "10" in checked
    assert checked == swept


def test_validate_accepts_the_shipped_dispersed_campaign() -> None:
    cfg = REPO / "campaigns" / "sweep_beta_dispersed.toml"
    result = runner.invoke(app, ["config", "validate", str(cfg)])
    assert result.exit_code == 0, result.output
    assert result.stdout.strip() == f"OK {config_hash(load_config(cfg))}"


def test_validate_help_says_what_it_checks_of_the_dispersions_and_what_not() -> None:
    """It draws the dispersions of seed 0 only: its help said "the checks every campaign
    makes before it runs", which a campaign of more seeds makes for every seed."""
    result = runner.invoke(app, ["config", "validate", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    text = " ".join(result.stdout.split())
    assert "their draws for seed 0 on the base configuration" in text
    assert "Not checked: the draws of other seeds" in text
    assert "ablate and sweep check every run's draws before anything runs" in text
    assert "[sweep] as sweep checks it: its keys, and every grid point" in text


def test_validate_draws_seed_0_and_a_campaign_every_seed_as_the_guide_says(
    tmp_path: Path,
) -> None:
    """The config guide's example: β = 0.25 + U(−0.5, 0.5) is valid for seed 0 (validate
    says OK), and ``ablate --seeds 4`` is refused at seed 3 before anything runs."""
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(
        '[dispersions]\n"schedule.beta" = { dist = "uniform", low = -0.5, high = 0.5 }\n'
        f"[output]\ndir = {json.dumps(str(tmp_path / 'out'))}\n"
    )
    checked = runner.invoke(app, ["config", "validate", str(cfg)])
    assert checked.exit_code == 0 and checked.stdout.startswith("OK "), checked.output
    ran = runner.invoke(app, ["ablate", str(cfg), "-n", "4", "-a", "mtf_adaptive", "-q"])
    assert ran.exit_code == 2, ran.output
    assert "error: dispersed run (seed 3) (schedule.beta = -0.13" in ran.stderr
    assert "must be > 0" in ran.stderr and not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "sweep",
    ['"schedule.betta" = [0.1]', '"schedule.beta" = [0.1, -0.1]', '"schedule.beta" = "0:1:3"'],
    ids=["unknown key", "value the key does not take", "range string reaching 0"],
)
def test_validate_refuses_the_sweep_that_sweep_refuses(tmp_path: Path, sweep: str) -> None:
    """``config validate`` runs the campaign's grid checks on ``[sweep]``: the message and
    exit code 2 of ``cwrend sweep``'s plan, before anything runs (it said OK)."""
    from cwrend_cli.campaign.plan import plan
    from cwrend_cli.errors import ConfigError

    cfg_file = tmp_path / "sweep.toml"
    cfg_file.write_text(PAPER_TOML.read_text() + f"\n[sweep]\n{sweep}\n")
    with pytest.raises(ConfigError) as refused:
        plan(load_config(cfg_file), ["mtf_adaptive"], [0])
    result = runner.invoke(app, ["config", "validate", str(cfg_file)])
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    assert str(refused.value).splitlines()[0] in result.output
    for problem in refused.value.problems:
        assert problem in result.output


def test_validate_accepts_a_valid_grid_and_a_design_s_ranges(tmp_path: Path) -> None:
    grid = tmp_path / "grid.toml"
    grid.write_text(
        PAPER_TOML.read_text()
        + '\n[sweep]\n"schedule.beta" = [0.1, 0.5]\n"schedule.kappa_mtf" = [6.0, 12.0]\n'
    )
    design = PAPER_TOML.with_name("sobol_schedule.toml")
    for path in (grid, design):
        result = runner.invoke(app, ["config", "validate", str(path)])
        assert result.exit_code == 0, result.output
        assert result.output.startswith("OK ")


def test_validate_refuses_a_design_range_its_key_does_not_take(tmp_path: Path) -> None:
    cfg_file = tmp_path / "design.toml"
    cfg_file.write_text(
        PAPER_TOML.read_text() + '\n[sweep]\n"schedule.beta" = { low = -0.5, high = 1.0 }\n'
    )
    result = runner.invoke(app, ["config", "validate", str(cfg_file)])
    assert result.exit_code == 2
    assert "[sweep] schedule.beta: low = -0.5 is not a value schedule.beta takes" in result.output
