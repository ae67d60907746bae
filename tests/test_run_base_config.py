"""``cwrend run`` flies the base configuration and says so when the config holds more.

A user inspecting "seed 0 of my campaign" with ``cwrend run`` got the base case
without a word: ``[sweep]`` and ``[dispersions]`` are a campaign's (``cwrend sweep``
applies them). The run warns on stderr, with ``-q`` too, and runs the base case.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app

runner = CliRunner()
DISPERSED = '[dispersions]\n"scenario.x0.2" = { dist = "normal", std = 1e-3 }\n'
SWEPT = '[sweep]\n"schedule.beta" = [0.25, 0.5]\n'


@pytest.mark.parametrize(
    ("table", "named"),
    [(DISPERSED, "its [dispersions] is not applied"), (SWEPT, "its [sweep] is not applied")],
)
def test_a_run_of_a_campaign_config_warns_that_it_flies_the_base_case(
    table: str, named: str, tmp_path: Path
) -> None:
    config = tmp_path / "c.toml"
    config.write_text(table, encoding="utf-8")
    args = ["run", str(config), "-a", "mtf_adaptive", "--no-rrd", "-q", "-o", str(tmp_path / "r")]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert f"warning: cwrend run flies the base configuration; {named}" in result.stderr


def test_a_run_of_a_plain_config_says_nothing(tmp_path: Path) -> None:
    config = tmp_path / "c.toml"
    config.write_text("", encoding="utf-8")
    args = ["run", str(config), "-a", "mtf_adaptive", "--no-rrd", "-q", "-o", str(tmp_path / "r")]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert result.stderr == ""


def test_a_first_run_says_it_compiles_when_stderr_is_not_a_terminal(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The compile notice lived only in the spinner, which a log file or a pipe never
    shows: a first run into ``2>err`` left nothing but "results written to …"."""
    from cwrend_cli.physics import compiled

    notice = "compiling kernels (first run only, about 15 s)…"
    monkeypatch.setattr(compiled, "compiling_notice", lambda methods, *_, **__: notice)
    config = tmp_path / "c.toml"
    config.write_text("", encoding="utf-8")
    args = ["run", str(config), "-a", "mtf_adaptive", "--no-rrd", "-o", str(tmp_path / "r")]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert result.stderr.startswith(notice)
