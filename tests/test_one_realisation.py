"""The first table and an unmet --until (issue 37, item 13).

A quantity with one realisation has no interval, and its table says so
instead of a bootstrap caption; ``--until`` that reaches ``--max-seeds``
says which interval is too wide and about how many seeds it would need, and
``--strict`` makes that exit 1.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pytest
from rich.console import Console
from typer.testing import CliRunner

from cwrend_cli import cli
from cwrend_cli.campaign import sequential, statistics
from cwrend_cli.cli import app
from cwrend_cli.console import (
    ONE_REALISATION,
    ablation_console_table,
    paired_console_table,
    sweep_console_table,
)

runner = CliRunner()


def _stats(runs: pd.DataFrame, by: list[str]) -> pd.DataFrame:
    groups = [c for c in by if c != "arch"]
    return pd.concat([statistics.describe(runs, by), statistics.paired(runs, groups)])


def _caption(table: object) -> str:
    buf = io.StringIO()
    Console(file=buf, width=200, highlight=False).print(table)
    return " ".join(buf.getvalue().split())


def test_one_seed_ablation_says_one_realisation_not_bootstrap(
    synthetic_runs: Callable[..., pd.DataFrame],
) -> None:
    stats = _stats(synthetic_runs(1), ["arch"])
    text = _caption(ablation_console_table(stats, "t"))
    assert f"means; {ONE_REALISATION}" in text and "bootstrap" not in text
    paired = _caption(paired_console_table(stats))
    assert ONE_REALISATION in paired and "bootstrap" not in paired
    assert "Wilson interval below P" in paired  # P(A < B) has an interval even from one seed


def test_one_seed_per_point_sweep_says_one_realisation(
    synthetic_runs: Callable[..., pd.DataFrame],
) -> None:
    stats = _stats(synthetic_runs(1, points=2), ["point", "param.schedule.beta", "arch"])
    text = _caption(sweep_console_table(stats, ["point", "param.schedule.beta"], "t"))
    assert ONE_REALISATION in text and "bootstrap" not in text


def test_a_table_with_one_realisation_in_some_rows_says_so_for_them(
    synthetic_runs: Callable[..., pd.DataFrame],
) -> None:
    runs = synthetic_runs(12)
    runs = runs[(runs["arch"] == "mtf_adaptive") | (runs["seed"] == 0)]  # plain: one seed
    text = _caption(ablation_console_table(_stats(runs, ["arch"]), "t"))
    assert "means, 95 % bootstrap interval below" in text
    assert f"a value alone: {ONE_REALISATION}" in text


def test_the_seeds_needed_scale_as_the_inverse_square_of_the_half_width() -> None:
    a = sequential.Achieved("mtf_adaptive", 1e-3, half_width=4e-4, limit=2e-4, n=20)
    assert a.seeds_needed == 80  # half-width × 1/2 needs 4× the seeds
    assert sequential.Achieved("x", 1.0, 1e-4, 2e-4, 20).seeds_needed == 20  # met already
    assert sequential.Achieved("x", math.nan, math.nan, math.nan, 0).seeds_needed is None
    text = sequential.unmet_message([a], max_seeds=20)
    assert "--until not met: --max-seeds 20 reached" in text
    assert "half-width 0.0004 > 0.0002" in text and "about 80 seeds" in text


def _until(tmp_path: Path, *extra: str) -> object:
    """An --until campaign that stops at --max-seeds 20 with its target not met (checked:
    widths are checked from 20 seeds; before, it is "not checked", never "not met")."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path}"\n')
    args = ["ablate", str(cfg), "--name", "u", "--arch", "mtf_adaptive", "-w", "1", "--no-rrd",
            "--until", "miss_km:1e-9", "--batch", "10", "--max-seeds", "20", *extra]  # fmt: skip
    return runner.invoke(app, args, env={"COLUMNS": "200"})


def test_an_unmet_until_says_so_and_estimates_the_seeds(tmp_path: Path) -> None:
    result = _until(tmp_path)
    assert result.exit_code == 0, result.output
    text = " ".join(result.stderr.split())
    assert "--until not met: --max-seeds 20 reached with 1 of 1 interval(s) too wide" in text
    assert "seeds would meet it (a half-width shrinks as 1/√seeds)" in text


def test_strict_makes_an_unmet_until_exit_1(tmp_path: Path) -> None:
    result = _until(tmp_path, "--strict", "-q")
    assert result.exit_code == 1, result.output
    assert "--until not met" in result.stderr  # said even when quiet: it is the error


def test_quiet_prints_a_not_checked_until_only_as_the_error_of_strict(tmp_path: Path) -> None:
    """``-q`` prints nothing but errors: with ``--strict`` a target not checked is the error
    of exit 1 and its verdict alone is printed; without ``--strict`` nothing is."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path}"\n')
    args = ["ablate", str(cfg), "--name", "u", "--arch", "mtf_adaptive", "-w", "1", "--no-rrd",
            "--until", "miss_km:1e-9", "--batch", "10", "--max-seeds", "10", "-q"]  # fmt: skip
    strict = runner.invoke(app, [*args, "--strict"], env={"COLUMNS": "200"})
    assert strict.exit_code == 1, strict.output
    assert strict.stdout == "" and strict.stderr.startswith("--until not checked: widths are")
    said = " ".join(strict.stderr.split())  # the verdict, nothing else (no table, progress)
    assert said.count("--until") == 1 and "computing" not in said and "ablate u" not in said
    quiet = runner.invoke(app, args, env={"COLUMNS": "200"})  # the same runs, resumed
    assert quiet.exit_code == 0, quiet.output
    assert quiet.stdout == "" and quiet.stderr == ""


@pytest.mark.parametrize("args", [["--seeds", "1"], []])
def test_strict_without_until_is_refused(tmp_path: Path, args: list[str]) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path}"\n')
    result = runner.invoke(app, ["ablate", str(cfg), "--strict", *args])
    assert result.exit_code == 2
    assert "--strict: applies to --until only" in result.stderr
    assert not (tmp_path / "campaign").exists()


def test_a_comparison_of_one_seed_says_one_realisation() -> None:
    from cwrend_cli.console import compare_console_tables

    rows = [
        {"kind": "paired", "arch": "mtf_adaptive", "metric": m, "statistic": s, "n": 1,
         "value": v, "ci_low": lo, "ci_high": hi}
        for m in ("miss_km", "delta_v_km_s")
        for s, v, lo, hi in (("mean_diff", -1e-3, math.nan, math.nan),
                             ("median_diff", -1e-3, math.nan, math.nan),
                             ("frac_better", 1.0, 0.21, 1.0),
                             ("frac_tied", 0.0, math.nan, math.nan))
    ]  # fmt: skip
    (table,) = compare_console_tables(pd.DataFrame(rows), [], "t")
    text = _caption(table)
    assert ONE_REALISATION in text and "bootstrap" not in text


def test_max_seeds_beyond_what_the_runs_a_seed_allow_is_refused_before_any_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Four architectures a seed: 1,250,001 seeds would be 5,000,004 runs, over the limit
    of 5,000,000. Refused (exit 2) before any run, naming --max-seeds and the most seeds
    allowed; before, the campaign ran until the batch that crossed the limit (a batch
    started here fails the test at once)."""

    def no_batch(*_args: object, **_kwargs: object) -> None:
        raise AssertionError("a batch ran before --max-seeds was checked")

    monkeypatch.setattr(cli, "_campaign_step", no_batch)
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path}"\n')
    args = ["ablate", str(cfg), "--name", "m", "--arch", "all", "-w", "1", "--no-rrd",
            "--until", "miss_km:1e-9", "--batch", "10", "--max-seeds", "1250001"]  # fmt: skip
    result = runner.invoke(app, args, env={"COLUMNS": "200"})
    assert result.exit_code == 2, result.output
    said = " ".join(result.stderr.split())
    assert "--max-seeds 1,250,001: at most 1,250,000 here (4 runs a seed" in said
    assert not (tmp_path / "m").exists()  # nothing written
