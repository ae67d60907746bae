"""An unknown name is answered with the closest known one (issue 37 item 14).

One suggestion function (:func:`cwrend_cli.config.messages.did_you_mean`) serves every
"unknown …" error: configuration keys (in files and ``--set``), architectures
(``--arch``, ``--pair``) and the fields of ``cwrend table``. Every refusal still exits 2.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign.compare import parse_metrics
from cwrend_cli.cli import app
from cwrend_cli.config.messages import did_you_mean
from cwrend_cli.errors import ConfigError

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
runner = CliRunner()


def _refused(args: list[str]) -> str:
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    return result.output


def test_a_misspelt_config_key_is_answered_with_the_key_meant() -> None:
    out = _refused(["config", "validate", str(PAPER), "--set", "schedule.betta=0.5"])
    assert "schedule.betta: unknown key" in out
    assert "did you mean 'beta'?" in out


def test_a_misspelt_architecture_is_answered_with_the_one_meant(tmp_path: Path) -> None:
    out_dir = f"output.dir={json.dumps(str(tmp_path))}"
    out = _refused(["ablate", str(PAPER), "--arch", "mtf_adaptve", "--set", out_dir])
    assert "did you mean 'mtf_adaptive'?" in out
    assert not list(tmp_path.iterdir())  # nothing written


def test_a_misspelt_pair_is_answered_with_an_architecture_of_the_campaign(
    tmp_path: Path,
) -> None:
    out_dir = f"output.dir={json.dumps(str(tmp_path))}"
    args = ["ablate", str(PAPER), "--arch", "plain_adaptive,mtf_adaptive"]
    out = _refused([*args, "--pair", "mtf_adaptive:plain_adaptiv", "--set", out_dir])
    assert "did you mean 'plain_adaptive'?" in out


def test_an_unrelated_word_gets_no_suggestion() -> None:
    assert did_you_mean("zzz", ["beta", "kappa_mtf"]) == ""
    assert did_you_mean(3, ["beta"]) == ""  # a list index is not a name


def test_a_misspelt_compare_metric_is_answered_with_the_metric_meant() -> None:
    """``cwrend compare --metric mis`` (as ``cwrend table``'s fields already were)."""
    with pytest.raises(ConfigError, match="did you mean 'miss'"):
        parse_metrics("mis")


def test_a_misspelt_design_range_is_answered_with_the_key_meant(tmp_path: Path) -> None:
    """``--range schedule.betta=0.1:1`` / ``shedule.beta``: "not a configuration value" with
    no suggestion, where ``--set`` suggests one."""
    out_dir = f"output.dir={json.dumps(str(tmp_path))}"
    for typo in ("schedule.betta", "shedule.beta"):
        args = ["sweep", str(PAPER), "--design", "lhs", "--samples", "4", "--range",
                f"{typo}=0.1:1", "--set", out_dir]  # fmt: skip
        assert "did you mean 'schedule.beta'?" in _refused(args)
    assert not list(tmp_path.iterdir())  # nothing written


TUMBLING = PAPER.parent / "tumbling_target.toml"


def test_a_misspelt_key_of_a_keep_out_body_is_answered_with_the_key_meant() -> None:
    args = ["config", "validate", str(TUMBLING)]
    out = _refused([*args, "--set", "constraints.keep_out.bodies.0.center_km=[0, 0.16, 0]"])
    assert "constraints.keep_out.bodies.0.center_km: unknown key" in out
    assert "did you mean 'centre_km'?" in out


def test_a_misspelt_key_of_an_optional_section_is_answered_with_the_key_meant() -> None:
    args = ["config", "validate", str(PAPER)]
    out = _refused([*args, "--set", "constraints.keep_out.semi_axs_km=[0.2, 0.2, 0.2]"])
    assert "did you mean 'semi_axes_km'?" in out


def test_a_misspelt_dispersion_key_is_answered_with_the_keys_meant(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text('[dispersions]\n"scenario.xo.2" = { dist = "normal", std = 0.05 }\n')
    out = _refused(["config", "validate", str(cfg)])
    assert "did you mean 'scenario.x0.2' or 'scenario.xf.2'?" in out


def test_a_dispersion_index_out_of_range_names_the_entries(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text('[dispersions]\n"scenario.x0.9" = { dist = "normal", std = 0.05 }\n')
    assert "(scenario.x0 has 6 entries: 0 to 5)" in _refused(["config", "validate", str(cfg)])


def test_a_malformed_array_says_what_was_given_and_what_is_expected() -> None:
    out = _refused(["config", "validate", str(PAPER), "--set", "scenario.x0=[1, 2"])
    assert 'scenario.x0 = "[1, 2": must be an array (written [v1, v2, …]), got a string' in out
    assert "not a valid TOML array" in out


def test_a_number_for_an_array_says_a_number_was_given() -> None:
    out = _refused(["config", "validate", str(PAPER), "--set", "scenario.x0=5"])
    assert "scenario.x0 = 5: must be an array (written [v1, v2, …]), got a number" in out
