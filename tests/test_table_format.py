"""Tables for scripts: ``--format md|csv|json`` (issue 37, item 11).

``run``, ``ablate``, ``sweep`` and ``compare`` print their table on stdout in
the format asked for, with every value as stored and nothing else there (no
console table, progress or colour).
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "campaigns" / "paper.toml"

runner = CliRunner()


def _ablate(out: Path, name: str, *args: str) -> str:
    where = f"output.dir={json.dumps(str(out))}"
    result = runner.invoke(
        app, ["ablate", str(PAPER), "--seeds", "2", "--arch", "mtf_adaptive,plain_adaptive",
              "-w", "1", "--no-rrd", "--name", name, "--set", where, *args],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    return result.stdout


def test_ablate_csv_is_the_statistics_file_unrounded(tmp_path: Path) -> None:
    printed = pd.read_csv(io.StringIO(_ablate(tmp_path, "a", "--format", "csv")))
    stored = pd.read_parquet(tmp_path / "a" / "ablation.parquet")
    assert list(printed.columns) == list(stored.columns) and len(printed) == len(stored)
    pd.testing.assert_series_equal(printed["value"], stored["value"], check_exact=True)


def test_ablate_json_is_records_and_nothing_else(tmp_path: Path) -> None:
    out = _ablate(tmp_path, "a", "--format", "json")
    records = json.loads(out)  # the whole of stdout: no table, no progress
    stored = pd.read_parquet(tmp_path / "a" / "ablation.parquet")
    assert len(records) == len(stored)
    assert {r["arch"] for r in records} == {"mtf_adaptive", "plain_adaptive"}


def test_run_md_is_the_run_table_as_markdown(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["run", str(PAPER), "--arch", "mtf_adaptive", "--no-rrd", "--out",
              str(tmp_path / "r"), "--format", "md"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("| ") and "| miss_km |" in lines[0] and lines[1].startswith("|---")
    assert len(lines) == 2 + 3  # the two open-loop references and the run
    stored = pd.read_parquet(tmp_path / "r" / "summary.parquet")
    miss = float(stored.query("arch == 'mtf_adaptive'")["miss_km"].iloc[0])
    assert any(f"| {miss!r} |" in line for line in lines)


@pytest.mark.parametrize("fmt", ["csv", "json"])
def test_compare_prints_the_paired_differences(tmp_path: Path, fmt: str) -> None:
    _ablate(tmp_path, "a", "-q")
    _ablate(tmp_path, "b", "-q", "--set", "schedule.beta=0.5")
    result = runner.invoke(
        app, ["compare", str(tmp_path / "a"), str(tmp_path / "b"), "--out",
              str(tmp_path / "c"), "--format", fmt],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    if fmt == "json":
        rows = pd.DataFrame(json.loads(result.stdout))
    else:
        rows = pd.read_csv(io.StringIO(result.stdout))
    assert {"arch", "metric", "statistic", "value"} <= set(rows.columns)
    assert "A − B" not in result.stdout  # no console table
