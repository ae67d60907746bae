"""The CLI says all it means (issue 18, item 4): help, quiet, subsets, intervals, config show."""

from __future__ import annotations

import io
import math
import tomllib
from pathlib import Path

import pandas as pd
import pytest
from click.testing import Result
from rich.console import Console
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.cli import app
from cwrend_cli.config import ARCHITECTURES, CwrendConfig, config_from_dict, config_hash
from cwrend_cli.console import (
    MIN_BOOTSTRAP_N,
    UNRELIABLE_NOTE,
    RichProgress,
    ablation_console_table,
    summary_console_table,
)

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
HELP_COMMANDS = (
    [],
    ["run"],
    ["ablate"],
    ["sweep"],
    ["report"],
    ["compare"],
    ["config"],
    ["config", "show"],
    ["config", "validate"],
)
ADAPTIVE = "mtf_adaptive,plain_adaptive"
runner = CliRunner()


def _help(command: list[str]) -> str:
    result = runner.invoke(app, [*command, "--help"], env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    return result.stdout


def _render(renderable: object, width: int = 80) -> str:
    buf = io.StringIO()
    Console(file=buf, width=width, highlight=False).print(renderable)
    return buf.getvalue()


def _config(tmp_path: Path, name: str = "c") -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(f'[output]\ndir = "{tmp_path / "results"}"\nname = "{name}"\n')
    return path


def _ablate(cfg: Path, *args: str) -> Result:
    base = ["ablate", str(cfg), "--arch", ADAPTIVE, "--workers", "1", "--no-rrd"]
    return runner.invoke(app, [*base, *args], env={"COLUMNS": "100"})


# --- help ---------------------------------------------------------------------


def test_help_keeps_bracketed_words_at_80_columns() -> None:
    text = " ".join(_help(["sweep"]).split())  # undo the wrapping
    assert "with [dispersions] per run" in text
    assert "the config's [sweep] table" in text


@pytest.mark.parametrize("command", HELP_COMMANDS, ids=lambda c: " ".join(c) or "cwrend")
def test_help_is_complete_at_80_columns(command: list[str]) -> None:
    text = _help(command)
    assert "…" not in text  # nothing cut by the formatter
    lines = text.splitlines()
    assert all(len(line) <= 80 for line in lines)
    # click cuts a command's one-line help with "..."; only the usage line may end so
    assert not [ln for ln in lines if ln.rstrip().endswith("...") and "Usage:" not in ln]


@pytest.mark.parametrize("command", HELP_COMMANDS, ids=lambda c: " ".join(c) or "cwrend")
def test_help_has_real_metavars(command: list[str]) -> None:
    text = _help(command)
    for placeholder in ("<bool>", "<str>", "<int range>", "<int>"):
        assert placeholder not in text, placeholder


def test_no_stray_rrd_steps_alias(tmp_path: Path) -> None:
    assert "--rrd-steps" not in _help(["ablate"])
    result = _ablate(_config(tmp_path), "--rrd-steps", "1")
    assert result.exit_code == 2
    assert "No such option" in result.output


# --- quiet ----------------------------------------------------------------------


def test_quiet_campaign_prints_nothing(tmp_path: Path) -> None:
    result = _ablate(_config(tmp_path), "--seeds", "2", "-q")
    assert result.exit_code == 0, result.output
    assert result.stdout == ""
    assert result.stderr == ""


def test_quiet_run_prints_nothing(tmp_path: Path) -> None:
    result = runner.invoke(app, ["run", str(PAPER), "--out", str(tmp_path / "r"), "--no-rrd", "-q"])
    assert result.exit_code == 0, result.output
    assert result.stdout == "" and result.stderr == ""
    assert (tmp_path / "r" / "summary.parquet").exists()


# --- a re-run naming a subset ---------------------------------------------------


def test_rerun_with_fewer_seeds_reports_exactly_those(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    assert _ablate(cfg, "--seeds", "3", "-q").exit_code == 0
    result = _ablate(cfg, "--seeds", "2")
    assert result.exit_code == 0, result.output
    assert "2 seed(s)" in result.stdout and "3 seed(s)" not in result.stdout
    assert "the tables cover the 4 run(s) this command names" in result.stderr
    assert "the directory holds 6" in result.stderr
    # the statistics file still covers the whole directory
    stats = pd.read_parquet(tmp_path / "results" / "c" / "ablation.parquet")
    assert set(stats.loc[stats["kind"] == "marginal", "n"]) == {3}


@pytest.mark.parametrize("quiet", [(), ("-q",)], ids=["plain", "quiet"])
def test_the_script_table_of_a_rerun_with_fewer_seeds_is_of_those_seeds(
    tmp_path: Path, quiet: tuple[str, ...]
) -> None:
    """As the console table: ``-q --format csv`` printed the statistics of every seed held."""
    cfg = _config(tmp_path)
    assert _ablate(cfg, "--seeds", "3", "-q").exit_code == 0
    result = _ablate(cfg, "--seeds", "2", "--format", "csv", *quiet)
    assert result.exit_code == 0, result.output
    table = pd.read_csv(io.StringIO(result.stdout))
    assert set(table.loc[table["kind"] == "marginal", "n"]) == {2}


def test_rerun_with_fewer_architectures_reports_exactly_those(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    assert _ablate(cfg, "--seeds", "2", "-q").exit_code == 0
    result = runner.invoke(
        app,
        ["ablate", str(cfg), "--arch", "mtf_adaptive", "--seeds", "2", "-w", "1", "--no-rrd"],
        env={"COLUMNS": "100"},
    )
    assert result.exit_code == 0, result.output
    assert "mtf_adaptive" in result.stdout and "plain_adaptive" not in result.stdout
    assert "the directory holds 4" in result.stderr


def test_full_rerun_has_no_subset_note(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    assert _ablate(cfg, "--seeds", "2", "-q").exit_code == 0
    result = _ablate(cfg, "--seeds", "2")
    assert result.exit_code == 0, result.output
    assert "this command names" not in result.stderr


# --- intervals from few seeds -----------------------------------------------------


def _marginal_stats(n: int) -> pd.DataFrame:
    rows = []
    for metric, statistic in [
        ("delta_v_km_s", "mean"),
        ("miss_km", "mean"),
        ("fuel_penalty_pct", "mean"),
        ("solve_success_pct", "mean"),
        ("solve_mean_ms", "mean"),
        ("solve_max_ms", "max"),
    ]:
        with_ci = statistic == "mean" and not metric.startswith("solve")
        rows.append(
            {"kind": "marginal", "arch": "mtf_adaptive", "metric": metric,
             "statistic": statistic, "value": 1.0, "n": n,
             "ci_low": 0.9 if with_ci else math.nan, "ci_high": 1.1 if with_ci else math.nan}
        )  # fmt: skip
    return pd.DataFrame(rows)


def test_bootstrap_intervals_flagged_below_the_stated_n() -> None:
    text = _render(ablation_console_table(_marginal_stats(MIN_BOOTSTRAP_N - 1), "t"))
    assert UNRELIABLE_NOTE in " ".join(text.split())
    assert "1.1000*" in text  # the interval itself is marked


def test_bootstrap_intervals_not_flagged_from_the_stated_n() -> None:
    text = _render(ablation_console_table(_marginal_stats(MIN_BOOTSTRAP_N), "t"))
    assert "unreliable" not in text and "*" not in text


def test_campaign_of_two_seeds_says_its_intervals_are_unreliable(tmp_path: Path) -> None:
    result = _ablate(_config(tmp_path), "--seeds", "2")
    assert result.exit_code == 0, result.output
    assert f"fewer than {MIN_BOOTSTRAP_N} seeds: bootstrap interval unreliable" in result.stdout


# --- config show -------------------------------------------------------------------


def test_config_show_lists_unset_optionals() -> None:
    result = runner.invoke(app, ["config", "show", str(PAPER)])
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    for table, key in (("schedule", "eps_saturation"), ("noise", "file")):
        at = lines.index(f"[{table}]")
        end = next((i for i in range(at + 1, len(lines)) if lines[i].startswith("[")), len(lines))
        assert f"# {key} = (unset)" in lines[at:end], (table, key)


def test_config_show_with_unset_comments_reads_back_unchanged() -> None:
    result = runner.invoke(app, ["config", "show", str(PAPER)])
    cfg = config_from_dict(tomllib.loads(result.stdout))
    assert f"# config_hash = {config_hash(cfg)}" in result.stdout


# --- cwrend run's table --------------------------------------------------------------


def test_run_table_fits_80_columns() -> None:
    case = campaign.run_case(CwrendConfig(), tuple(ARCHITECTURES.values()), 0)
    text = _render(summary_console_table(case, title="cwrend run · campaigns/paper.toml"))
    assert "…" not in text
    assert max(len(line.rstrip()) for line in text.splitlines()) <= 80
    assert "seed 0" in text.splitlines()[0]  # the seed is in the title


# --- progress (issue 17) ---------------------------------------------------------------


class _Clock:
    """A settable clock for :class:`RichProgress`."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _plain_progress(clock: _Clock) -> tuple[RichProgress, io.StringIO]:
    buf = io.StringIO()
    return RichProgress(Console(file=buf, width=200), "ablate x", clock=clock), buf


def test_progress_rate_and_eta_count_from_the_first_completed_task() -> None:
    """Start-up (workers, kernels, references) does not enter the rate: 10 s of it here."""
    clock = _Clock()
    progress, _ = _plain_progress(clock)
    progress.start(total=400, skipped=0)
    clock.now = 10.0  # start-up, then the first task of 40 runs
    progress.advance(40, 0)
    assert progress.rate() is None and progress.eta() is None  # one completion: no rate yet
    clock.now = 12.0
    progress.advance(40, 0)  # 40 runs in 2 s: 20 runs/s (from the start it would be 6.7)
    assert progress.rate() == pytest.approx(20.0)
    assert progress.eta() == pytest.approx(320 / 20.0)
    clock.now = 13.0  # the ETA counts down between completions
    assert progress.eta() == pytest.approx(320 / 20.0 - 1.0)


def test_progress_lines_show_rate_and_eta() -> None:
    clock = _Clock()
    progress, buf = _plain_progress(clock)
    progress.start(total=100, skipped=0)
    clock.now = 5.0
    progress.advance(10, 0)
    clock.now = 15.0
    progress.advance(20, 1)
    lines = buf.getvalue().splitlines()
    assert lines[0] == "ablate x: 10/100 runs, 0 failed, 5 s elapsed"  # no rate yet: none shown
    assert lines[1] == "ablate x: 31/100 runs, 1 failed, 15 s elapsed, 2.1 runs/s, ETA 33 s"


def test_campaign_says_it_computes_the_statistics(tmp_path: Path) -> None:
    result = _ablate(_config(tmp_path), "--seeds", "2")
    assert result.exit_code == 0, result.output
    assert "ablate c: computing statistics…" in result.stderr


def test_quiet_campaign_does_not_announce_the_statistics(tmp_path: Path) -> None:
    result = _ablate(_config(tmp_path), "--seeds", "2", "-q")
    assert result.exit_code == 0, result.output
    assert "computing statistics" not in result.output


def test_progress_of_a_100_seed_ablation_on_2_workers_moves_often(
    tmp_path: Path, recording_progress
) -> None:
    """Unset output.seeds_per_task: at least 4 tasks per worker, not 0 → 128 → 200."""
    cfg = config_from_dict({"output": {"dir": str(tmp_path), "rrd_seeds": 0, "steps_seeds": 0}})
    plan = campaign.plan(cfg, ADAPTIVE.split(","), list(range(100)), workers=2)
    assert len(plan.tasks) >= 8
    recorder = recording_progress()
    campaign.run_campaign(plan, tmp_path / "p", command="ablate", workers=2, progress=recorder)
    assert sum(recorder.advances) == recorder.total == 200
    assert len(recorder.advances) >= 8
    assert max(recorder.advances) <= 2 * 16
