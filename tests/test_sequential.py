"""Sequential Monte Carlo targets (issue 19, item 3): parsed as documented, read from the stats."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign import sequential, statistics
from cwrend_cli.cli import app
from cwrend_cli.errors import ConfigError
from cwrend_cli.limits import MAX_RUNS

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"


@pytest.mark.parametrize(
    ("text", "target"),
    [
        ("miss_km:0.0005", sequential.Target("miss_km", "mean", 0.0005, False)),
        ("median.miss_km:5%", sequential.Target("miss_km", "median", 0.05, True)),
        ("delta_v_km_s:1e-4", sequential.Target("delta_v_km_s", "mean", 1e-4, False)),
        (
            "miss_km@mtf_adaptive-plain_adaptive:0.001",
            sequential.Target(
                "miss_km", "median_diff", 0.001, False, ("mtf_adaptive", "plain_adaptive")
            ),
        ),
        (
            "frac_less.miss_km@mtf_adaptive-mtf_fixed:0.05",
            sequential.Target("miss_km", "frac_less", 0.05, False, ("mtf_adaptive", "mtf_fixed")),
        ),
    ],
)
def test_targets_parse_as_documented(text: str, target: sequential.Target) -> None:
    assert sequential.parse_until(text) == target


@pytest.mark.parametrize(
    ("short", "column"),
    [("miss:0.0005", "miss_km:0.0005"), ("median.dv:5%", "median.delta_v_km_s:5%"),
     ("miss@mtf_adaptive-plain_adaptive:0.001", "miss_km@mtf_adaptive-plain_adaptive:0.001")],
)  # fmt: skip
def test_targets_take_the_short_metric_names_of_compare_and_table(short: str, column: str) -> None:
    """``--until miss:0.001`` was refused ("metric must be one of delta_v_km_s, …") while
    ``cwrend compare --metric`` and ``cwrend table`` take ``miss``."""
    assert sequential.parse_until(short) == sequential.parse_until(column)


def test_a_misspelt_target_metric_is_answered_with_the_one_meant() -> None:
    with pytest.raises(ConfigError, match="did you mean 'miss'"):
        sequential.parse_until("mis:0.001")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("miss", "expected [STATISTIC.]METRIC[@A-B]:HALF_WIDTH[%]"),
        ("speed_km:1", "metric must be one of"),
        ("mode.miss_km:1", "statistic must be one of"),
        ("miss_km:-1", "must be positive"),
        ("miss_km:abc", "must be a number"),
        ("miss_km@plain_fixed-mtf_adaptive:1", "pairs compared are"),
        ("mean.miss_km@mtf_adaptive-plain_adaptive:1", "paired statistic of miss_km"),
    ],
)
def test_bad_targets_exit_with_the_syntax(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match="--until") as err:
        sequential.parse_until(text)
    assert message in str(err.value)


def test_seed_counts_grow_by_batches_and_end_at_the_maximum() -> None:
    assert list(sequential.seed_counts(50, 180)) == [50, 100, 150, 180]
    assert list(sequential.seed_counts(50, 100)) == [50, 100]


def test_widths_are_checked_only_after_the_minimum_batches_and_seeds() -> None:
    assert not sequential.ready(10, batch=10)  # one batch
    assert not sequential.ready(2 * 5, batch=5)  # two batches but fewer than MIN_SEEDS
    assert sequential.ready(max(sequential.MIN_BATCHES * 25, sequential.MIN_SEEDS), batch=25)


def test_achieved_widths_are_the_reported_intervals(
    synthetic_runs: Callable[..., pd.DataFrame],
) -> None:
    runs = synthetic_runs(200)
    stats = pd.concat([statistics.describe(runs, ["arch"]), statistics.paired(runs)])
    target = sequential.parse_until("miss_km:10%")
    got = sequential.achieved(stats, target, ["mtf_adaptive", "plain_adaptive"])
    for a in got:
        row = stats[(stats["kind"] == "marginal") & (stats["arch"] == a.label)
                    & (stats["metric"] == "miss_km") & (stats["statistic"] == "mean")]  # fmt: skip
        assert a.half_width == pytest.approx((row["ci_high"].iloc[0] - row["ci_low"].iloc[0]) / 2)
        assert a.limit == pytest.approx(0.1 * row["value"].iloc[0])
        assert a.met == (a.half_width <= a.limit) and a.n == 200
    paired = sequential.achieved(
        stats, sequential.parse_until("miss_km@mtf_adaptive-plain_adaptive:1e-4"), []
    )
    assert [p.label for p in paired] == ["mtf_adaptive − plain_adaptive"]
    assert paired[0].value < 0 and math.isfinite(paired[0].half_width)


def test_an_architecture_without_runs_never_meets_its_target(
    synthetic_runs: Callable[..., pd.DataFrame],
) -> None:
    stats = statistics.describe(synthetic_runs(30), ["arch"])
    got = sequential.achieved(stats, sequential.parse_until("miss_km:1"), ["mtf_fixed"])
    assert len(got) == 1 and not got[0].met and got[0].n == 0


def test_a_target_met_before_widths_are_checked_is_not_said_to_be_missed(
    tmp_path: Path,
) -> None:
    """At 2 of at most 4 seeds, a half-width within a 1,000 km target printed "not yet (…:
    half-width 0.00… > 1e+03)": met, but widths count from 20 seeds. One seed has no
    interval ("half-width nan > 1e+03" before)."""
    args = ["ablate", str(PAPER), "--arch", "mtf_adaptive", "--until", "miss_km:1000",
            "--batch", "2", "--max-seeds", "4", "--workers", "1", "--no-rrd",
            "--set", f"output.dir={json.dumps(str(tmp_path))}"]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "2 seeds: within the target, but widths are checked from 20 seeds" in result.stderr
    assert "not yet" not in result.stderr


def test_a_target_without_an_interval_yet_says_so() -> None:
    one = sequential.Achieved("mtf_adaptive", 0.001, math.nan, 1000.0, 1)
    assert sequential.next_batch_message(1, 1, [one]) == (
        "1 seeds: not yet (mtf_adaptive: no interval yet); next batch"
    )


def _until_paper(tmp_path: Path, target: str, *extra: str) -> list[str]:
    return ["ablate", str(PAPER), "--arch", "mtf_adaptive", "--until", target,
            "--workers", "1", "--no-rrd", "--set", f"output.dir={json.dumps(str(tmp_path))}",
            *extra]  # fmt: skip


def test_the_until_table_says_the_unit_of_its_values(tmp_path: Path) -> None:
    """Its value, half-width and target are in the metric's unit (km for the miss),
    where the campaign's own table shows the miss in metres: it said no unit."""
    args = _until_paper(tmp_path, "miss_km:1000", "--batch", "2", "--max-seeds", "2")
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "value, half-width and target in km" in result.stdout


def test_a_rerun_of_a_finished_until_campaign_reports_the_seeds_its_rule_stopped_at(
    tmp_path: Path,
) -> None:
    """The paper's mean miss has a half-width of 0.753 m at 20 seeds, 0.668 m at 30: a
    0.7 m target stops at 30. The rerun read every seed the directory held at each batch,
    so it stopped at 20 and printed the tables of 20 seeds beside a target row of 30."""
    args = _until_paper(tmp_path, "miss_km:0.0007", "--batch", "10", "--max-seeds", "40")
    first = CliRunner().invoke(app, args)
    assert first.exit_code == 0, first.output
    assert "cwrend ablate · paper · 30 seed(s)" in first.stdout
    rerun = CliRunner().invoke(app, args)
    assert rerun.exit_code == 0, rerun.output
    assert "cwrend ablate · paper · 30 seed(s)" in rerun.stdout
    assert "0 run(s) computed, 30 already done" in rerun.stderr
    rows = [line for line in rerun.stdout.splitlines() if line.startswith(" mtf_adaptive")]
    assert rows[-1].split()[:2] == ["mtf_adaptive", "30"], rerun.stdout  # the --until row


def test_an_until_batch_computes_the_statistics_of_its_own_seeds_only(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Over a directory holding more seeds, each batch's rule needs its seeds' intervals
    only: the statistics of every run held (the file) are computed once, not per batch."""
    from cwrend_cli import campaign

    args = _until_paper(tmp_path, "miss_km:0.0007", "--batch", "10", "--max-seeds", "40")
    fixed = CliRunner().invoke(app, [*args[:4], "--seeds", "40", *args[6:-4]])
    assert fixed.exit_code == 0, fixed.output
    whole: list[int] = []
    real = campaign.write_statistics

    def counted(*a: object, **k: object) -> campaign.CampaignStatistics:
        whole.append(1)
        return real(*a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(campaign, "write_statistics", counted)
    rerun = CliRunner().invoke(app, args)
    assert rerun.exit_code == 0, rerun.output
    assert "cwrend ablate · paper · 30 seed(s)" in rerun.stdout  # where the rule stops
    assert len(whole) == 1
    stored = pd.read_parquet(tmp_path / "paper" / "ablation.parquet")
    assert set(stored[stored["kind"] == "marginal"]["n"]) == {40}  # the file: every run


def test_the_seeds_advised_never_exceed_what_max_seeds_accepts() -> None:
    """Advice to raise --max-seeds to N only for an N a campaign accepts (``MAX_RUNS`` runs):
    beyond, the target is said to be out of reach, with what to change instead."""
    limit = sequential.seeds_limit(4)  # four architectures, one point
    assert limit == MAX_RUNS // 4
    within = sequential.Achieved("mtf_adaptive", 1e-3, half_width=4e-4, limit=2e-4, n=20)
    beyond = sequential.Achieved("mtf_adaptive", 1e-3, half_width=1.0, limit=1e-4, n=20)
    assert beyond.seeds_needed is not None and beyond.seeds_needed > limit
    for unmet in (
        sequential.unmet_message([within], max_seeds=20, limit=limit),
        sequential.unchecked_message(10, 10, [within], limit=limit),
    ):
        assert "about 80 seeds would meet it" in unmet and "cannot be reached" not in unmet
    assert "raise --max-seeds to 80" in sequential.unchecked_message(10, 10, [within], limit)
    for text in (
        sequential.unmet_message([beyond], max_seeds=20, limit=limit),
        sequential.unchecked_message(10, 10, [beyond], limit=limit),
    ):
        assert f"about {beyond.seeds_needed:,} seeds would meet it" in text
        assert f"more than the {limit:,} seeds" in text
        assert "the target cannot be reached within that limit" in text
        assert "widen the target or target another metric" in text
        assert "raise --max-seeds" not in text
