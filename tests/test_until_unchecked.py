"""``ablate --until`` that stops before widths are checked says so (daily use).

Widths are checked from 2 batches and 20 seeds (``sequential.checked_from``); with
``--max-seeds 4`` none was, yet the final table said "yes" under "met" and
``--strict`` exited 0. It now reads "not checked", says how to check, and
``--strict`` (exit 1 unless the target is known met) exits 1.
"""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from cwrend_cli.cli import app

#: A half-width of 1000 km: met by any interval, so only the check is missing.
WIDE = "miss_km:1000"


def _ablate(tmp_path: Path, *extra: str, target: str = WIDE) -> list[str]:
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path}"\nrrd_seeds = 0\n', encoding="utf-8")
    return ["ablate", str(cfg), "--arch", "mtf_adaptive", "--workers", "1", "--no-rrd",
            "--until", target, "--batch", "2", "--max-seeds", "4", *extra]  # fmt: skip


def _until_row(stdout: str) -> str:
    """The --until table's row (of its one architecture), printed last but its captions."""
    rows = [line for line in stdout.splitlines() if line.startswith(" mtf_adaptive")]
    return rows[-1].rstrip()


def test_until_stopped_before_widths_are_checked_does_not_say_met(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, _ablate(tmp_path))
    assert result.exit_code == 0, result.output
    row = _until_row(result.stdout)
    assert row.endswith("not checked"), result.stdout
    assert "--until not checked: widths are checked from 20 seeds" in result.stderr
    assert "raise --max-seeds to 20" in result.stderr


def test_until_strict_exits_1_when_widths_were_not_checked(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, _ablate(tmp_path, "--strict"))
    assert result.exit_code == 1, result.output


def test_until_stopped_before_widths_are_checked_says_not_checked_only(
    tmp_path: Path,
) -> None:
    """With intervals still too wide, it printed "--until not met" and "--until not
    checked" one after the other: whether the target is met is not known, so only the
    latter, naming the intervals too wide so far and the seeds they would need."""
    result = CliRunner().invoke(app, _ablate(tmp_path, target="miss_km:1e-7"))
    assert result.exit_code == 0, result.output
    said = " ".join(result.stderr.split())  # the console folds lines
    assert "not met" not in said
    assert "--until not checked: widths are checked from 20 seeds" in said
    assert "so far 1 of 1 interval(s) are wider than the target" in said
    assert _until_row(result.stdout).endswith("not checked"), result.stdout
