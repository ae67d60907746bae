"""The console at 80 columns (issue 37, items 11 and 14).

The campaign progress stays on one line at 80 columns whatever the
campaign's name, size and pace, and shows a rate and an ETA only once it
has one (two completions).
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from rich.console import Console
from typer.testing import CliRunner

from cwrend_cli.campaign import statistics
from cwrend_cli.cli import app
from cwrend_cli.console import (
    RichProgress,
    ablation_console_table,
    applied_console_table,
    paired_console_table,
    sweep_console_table,
)
from cwrend_cli.physics import metrics

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"


class _Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _bar_lines(progress: RichProgress) -> list[str]:
    """The progress bar as drawn now on an 80-column terminal."""
    bar = progress._bar
    assert bar is not None
    buf = io.StringIO()
    Console(file=buf, width=80, color_system=None).print(bar.make_tasks_table(bar.tasks))
    return buf.getvalue().splitlines()


def _terminal_progress(label: str, clock: _Clock) -> RichProgress:
    console = Console(file=io.StringIO(), width=80, force_terminal=True, color_system=None)
    return RichProgress(console, label, clock=clock)


def test_the_progress_bar_is_one_line_at_80_columns_at_its_widest() -> None:
    clock = _Clock()
    progress = _terminal_progress("sweep a-campaign-with-a-long-name", clock)
    progress.start(total=100_000, skipped=0)
    try:
        clock.now = 100.0
        progress.advance(10, 2)
        clock.now = 110.0
        progress.advance(12_330, 7)  # 1,234 runs/s
        lines = _bar_lines(progress)
        assert len(lines) == 1 and len(lines[0]) <= 80
        for part in ("12349/100000", "9 failed", "0:01:50", "1234 runs/s", "ETA 1 min 11 s"):
            assert part in lines[0]
    finally:
        progress.close()


def test_the_progress_shows_no_rate_before_it_has_one() -> None:
    clock = _Clock()
    progress = _terminal_progress("ablate paper", clock)
    progress.start(total=120, skipped=0)
    try:
        clock.now = 20.0  # compiling, the first task
        progress.advance(4, 0)
        (line,) = _bar_lines(progress)
        assert "runs/s" not in line and "ETA" not in line and "–" not in line
        assert "4/120" in line and "failed" not in line  # no failure: no failure count
        clock.now = 21.0
        progress.advance(4, 0)
        (line,) = _bar_lines(progress)
        assert "4 runs/s" in line and "ETA 28 s" in line
    finally:
        progress.close()


# --- the tables at 80 columns (item 11) ------------------------------------------------


def _render(table: object) -> str:
    buf = io.StringIO()
    Console(file=buf, width=80, highlight=False, color_system=None).print(table)
    text = buf.getvalue()
    assert max(len(line) for line in text.splitlines()) <= 80
    assert "…" not in text
    return text


def _cells(text: str) -> set[str]:
    """Every cell of a rendered table as a whole word (what a reader sees between spaces)."""
    return set(text.replace("│", " ").split())


def test_the_run_table_shows_every_case_and_number_whole_at_80_columns() -> None:
    from cwrend_cli import campaign
    from cwrend_cli.config import config_from_dict, parse_archs
    from cwrend_cli.console import summary_console_table

    case = campaign.run_case(config_from_dict({}), parse_archs("everything"), 0)
    cells = _cells(_render(summary_console_table(case, title="cwrend run · paper.toml")))
    for run in case.runs:
        assert run.arch in cells
        assert f"{run.delta_v_km_s:.5f}" in cells
        assert f"{run.miss_km * 1e3:.3g}" in cells  # the miss in m
        applied = metrics.applied_delta_v(run.t_s, run.u)  # its own table (issue 33)
        assert f"{applied:.5f}" in cells


def test_the_run_table_states_the_consistent_nis_of_its_sensor() -> None:
    """E[NIS] is the measurement's dimension m: 2 for the angles sensor, not always 3."""
    from cwrend_cli import campaign
    from cwrend_cli.config import config_from_dict, parse_archs
    from cwrend_cli.console import summary_console_table

    case = campaign.run_case(config_from_dict({}), parse_archs("mtf_adaptive"), 0)
    for dof in (3, 2):
        text = " ".join(_render(summary_console_table(case, "run", dof)).split())
        assert f"degradation windows ({dof} if consistent)" in text


def _stats(archs: list[str], points: int = 1) -> pd.DataFrame:
    rng = np.random.default_rng(3)
    rows = []
    for point in range(points):
        for seed in range(12):
            for k, arch in enumerate(archs):
                rows.append(
                    {"point": f"p{point}", "param.schedule.beta": 0.125 * (point + 1),
                     "seed": seed, "arch": arch, "status": "ok",
                     "miss_km": 10.0 ** (k - 4) * (1 + 0.3 * rng.standard_normal()),
                     "delta_v_km_s": 0.14 + 1e-3 * rng.standard_normal(),
                     "fuel_penalty_pct": 125.0 + rng.standard_normal(),
                     "delta_v_applied_km_s": 0.14 + 1e-3 * rng.standard_normal(),
                     "fuel_penalty_applied_pct": 125.0 + rng.standard_normal(),
                     "solve_success_pct": 99.5, "solve_mean_ms": 123.45,
                     "solve_max_ms": 9876.5, "n_infeasible": 0}
                )  # fmt: skip
    runs = pd.DataFrame(rows)
    by = ["point", "param.schedule.beta", "arch"] if points > 1 else ["arch"]
    groups = [c for c in by if c != "arch"]
    return pd.concat(
        [statistics.describe(runs, by), statistics.paired(runs, groups),
         statistics.applied(runs, by)]
    )  # fmt: skip


SLUGS = ["plain_adaptive_socp", "mtf_adaptive_socp", "plain_fixed_socp", "mtf_fixed_socp"]


def test_the_campaign_tables_show_every_name_and_number_whole_at_80_columns() -> None:
    """The ablation, its paired comparisons and a sweep (compare: test_compare)."""
    stats = _stats(SLUGS)
    text = _render(ablation_console_table(stats, "cwrend ablate · a-long-campaign-name"))
    cells = _cells(text)
    marginal = stats[stats["kind"] == "marginal"]
    for arch in SLUGS:
        assert arch in cells
        miss = marginal.query("arch == @arch and metric == 'miss_km' and statistic == 'mean'")
        (value,) = miss["value"]
        assert f"{value * 1e3:.2f}" in cells
    applied = _cells(_render(applied_console_table(stats)))
    for arch in SLUGS:
        assert arch in applied
        row = marginal.query(
            "arch == @arch and metric == 'fuel_penalty_applied_pct' and statistic == 'mean'"
        )
        assert f"{row['value'].iloc[0]:.2f}" in applied
    paired = _render(paired_console_table(stats))
    assert all(arch in _cells(paired) for arch in SLUGS)
    sweep = _stats(SLUGS, points=3)
    text = _render(sweep_console_table(sweep, ["point", "param.schedule.beta"], "sweep"))
    assert {"0.125", "0.25", "0.375", *SLUGS} <= _cells(text)
    text = _render(applied_console_table(sweep, ["point", "param.schedule.beta"]))
    assert {"0.125", "0.25", "0.375", *SLUGS} <= _cells(text)


def _at_80(renderable: object) -> str:
    buf = io.StringIO()
    Console(file=buf, width=80, color_system=None).print(renderable)
    return buf.getvalue()


def test_compare_of_two_equal_configurations_says_so_on_one_line() -> None:
    """``cwrend compare A A``: the empty table's caption folded into a 14-column stack and
    lost ``[output]`` (read as markup)."""
    from cwrend_cli.console import config_diff_console_table

    text = _at_80(config_diff_console_table([]))
    assert text == "A and B have the same configuration (no setting differs outside [output])\n"


def test_compare_shows_a_setting_whose_value_looks_like_markup() -> None:
    from cwrend_cli.console import config_diff_console_table

    text = _at_80(config_diff_console_table([("noise.file", "[bold]a.npz", "b.npz")]))
    assert '"[bold]a.npz"' in text or "[bold]a.npz" in text


def test_a_campaign_under_the_working_directory_is_named_as_the_tour_gives_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``cwrend ablate … --name tour`` ended "… → /home/me/cwrend/results/tour", past 80
    columns; under the working directory it is ``results/tour``."""
    monkeypatch.chdir(tmp_path)
    args = ["ablate", str(PAPER), "--seeds", "1", "--arch", "mtf_adaptive", "--workers", "1",
            "--no-rrd", "--name", "tour", "--set", 'output.dir="results"']  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    last = result.stderr.strip().splitlines()[-1]
    assert last == "1 run(s) computed, 0 already done; campaign holds 1 ok, 0 failed → results/tour"


def test_a_difference_that_rounds_to_zero_has_no_minus_sign() -> None:
    """An ``everything_with_stf`` ablation's paired table read "-0.0000–-0.0000*" for the
    Δv of mtf_fixed_socp vs stf_fixed_socp; the report's and ``cwrend table``'s likewise."""
    from cwrend_cli.console import _ci
    from cwrend_cli.report import markdown
    from cwrend_cli.report.table import _cell, parse_value

    row = pd.Series({"value": -2e-6, "ci_low": -4e-6, "ci_high": -1e-6, "n": 2})
    assert _ci(row, ".4f") == "0.0000\n[dim]0.0000–0.0000*[/dim]"
    assert markdown._ci(row, ".4f") == "0.0000 [0.0000, 0.0000]\\*"
    assert markdown._fmt(-0.004, "+.2f") == "+0.00"
    assert _cell(row, parse_value("mean_diff.dv"), "*") == "0.00000 [0.00000, 0.00000]*"
    assert _ci(pd.Series({"value": -0.25, "ci_low": -0.5, "ci_high": 0.1, "n": 20}), ".2f") == (
        "-0.25\n[dim]-0.50–0.10[/dim]"
    )


def test_the_no_sensitivity_note_breaks_between_phrases_at_80_columns(tmp_path: Path) -> None:
    """``sweep --design lhs --samples 4``: the note wrapped at 80 columns as "…; raise" /
    "--samples"; it is now two lines, each whole."""
    cfg = tmp_path / "lhs.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path}"\nrrd_seeds = 0\n'
                   '[sweep]\n"schedule.beta" = { low = 0.05, high = 1.0 }\n')  # fmt: skip
    args = ["sweep", str(cfg), "--design", "lhs", "--samples", "4", "--seeds", "1",
            "--arch", "mtf_adaptive", "--workers", "1", "--no-rrd"]  # fmt: skip
    result = CliRunner(env={"COLUMNS": "80"}).invoke(app, args)
    assert result.exit_code == 0, result.output
    lines = result.stderr.splitlines()
    at = lines.index("no sensitivity indices: RBD-FAST needs at least 9 design rows")
    assert lines[at + 1] == "(this design has 4): raise --samples to 9 or more"


def _columns_of(text: str, names: Sequence[str]) -> set[int]:
    """The column at which each of ``names`` starts on its row of a rendered table."""
    return {line.index(f" {n} ") + 1 for line in text.splitlines() for n in names
            if f" {n} " in line}  # fmt: skip


def test_the_sweep_table_left_aligns_the_architectures() -> None:
    """Names left-aligned as in the ablation tables (they were right-aligned here)."""
    text = _render(sweep_console_table(_stats(SLUGS, points=2), ["point", "param.schedule.beta"],
                                       "sweep"))  # fmt: skip
    assert len(_columns_of(text, SLUGS)) == 1


def test_the_consistency_table_left_aligns_the_architectures() -> None:
    from cwrend_cli.console import consistency_console_table

    rows = pd.DataFrame(
        [{"kind": "consistency", "arch": arch, "metric": metric, "statistic": "mean",
          "value": 6.0, "ci_low": 5.0, "ci_high": 7.0, "n": 12}
         for arch in SLUGS for metric in ("mean_nees", "mean_nis_nominal")]
    )  # fmt: skip
    table = consistency_console_table(rows, [], "filter consistency")
    assert table is not None
    assert len(_columns_of(_render(table), SLUGS)) == 1


def _row_archs(text: str, archs: list[str]) -> list[str]:
    """The architectures of ``archs`` in the order a rendered table lists them."""
    return [cell for line in text.splitlines() for cell in line.split() if cell in archs]


def test_the_ablation_console_lists_architectures_in_the_order_of_cwrend_table() -> None:
    """The console followed the statistics file (sorted by slug: mtf_… before plain_…), while
    ``cwrend table`` and the report list them in the package's order (plain before mtf)."""
    from cwrend_cli.physics.params import arch_order

    archs = ["mtf_adaptive", "plain_fixed", "plain_adaptive", "mtf_fixed"]
    stats = _stats(archs)
    expected = list(arch_order(archs))
    assert expected == ["plain_fixed", "mtf_fixed", "plain_adaptive", "mtf_adaptive"]
    assert _row_archs(_render(ablation_console_table(stats, "ablate")), archs) == expected
    assert _row_archs(_render(applied_console_table(stats)), archs) == expected


def test_the_sweep_console_lists_architectures_in_the_order_of_cwrend_table() -> None:
    archs = ["mtf_adaptive", "plain_adaptive"]
    stats = _stats(archs, points=2)
    text = _render(sweep_console_table(stats, ["point", "param.schedule.beta"], "sweep"))
    assert _row_archs(text, archs) == ["plain_adaptive", "mtf_adaptive"] * 2
