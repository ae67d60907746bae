"""Paired comparisons for every architecture choice, and ``--pair A:B`` (issue 37, item 4).

By default a campaign compares MTF vs plain (same schedule) and adaptive vs
fixed (same estimator) within each re-solve method, and cone program vs
shooting (same estimator and schedule); ``--pair A:B`` adds any pair of its
architectures. The rows of the pairs compared before stay the same bit for
bit: an added pair draws its bootstrap from a stream of its own.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign import sequential, statistics
from cwrend_cli.cli import app
from cwrend_cli.errors import ConfigError
from cwrend_cli.physics.params import (
    ALL_ARCHITECTURES,
    ARCHITECTURES,
    SOCP_ARCHITECTURES,
    STF_ARCHITECTURES,
)

runner = CliRunner()
SOCP_WITHIN = [
    ("mtf_adaptive_socp", "plain_adaptive_socp"),
    ("mtf_fixed_socp", "plain_fixed_socp"),
    ("mtf_adaptive_socp", "mtf_fixed_socp"),
    ("plain_adaptive_socp", "plain_fixed_socp"),
]
#: The paper's eight architectures (shooting and cone program), without the single factor.
PAPER_EIGHT = [*ARCHITECTURES, *SOCP_ARCHITECTURES]


def _runs(archs: list[str], points: int = 1) -> pd.DataFrame:
    """Runs of ``archs`` on 12, 1, 5, … seeds per grid point, a few failed."""
    gen = np.random.default_rng(3)
    rows = []
    for point in range(points):
        for seed in range((12, 1, 5)[point % 3]):
            for arch in archs:
                rows.append(
                    {"point": f"p{point}", "param.schedule.beta": 0.25 * (point + 1),
                     "seed": seed, "arch": arch,
                     "status": "ok" if gen.random() > 0.05 else "failed",
                     "miss_km": abs(gen.normal(1e-3, 5e-4)),
                     "delta_v_km_s": gen.normal(0.14, 1e-3)}
                )  # fmt: skip
    return pd.DataFrame(rows)


def _pairs_of(frame: pd.DataFrame) -> set[tuple[str, str]]:
    return set(zip(frame["arch"], frame["other"], strict=True))


def test_default_pairs_differ_in_one_choice_each() -> None:
    """12 pairs of the paper's eight: 4 within each method (2 estimator, 2 schedule) and 4
    across methods; then 12 of the single factor (issue 35): within each method MTF vs STF
    and STF vs plain at each schedule (4) and STF adaptive vs fixed (1), and 2 across."""
    pairs = statistics.DEFAULT_PAIRS
    assert pairs[: len(statistics.PAIRS)] == statistics.PAIRS and len(set(pairs)) == 24
    assert all(a in PAPER_EIGHT and b in PAPER_EIGHT for a, b in pairs[:12])
    assert all(a in STF_ARCHITECTURES or b in STF_ARCHITECTURES for a, b in pairs[12:])
    for a, b in pairs:
        x, y = ALL_ARCHITECTURES[a], ALL_ARCHITECTURES[b]
        differ = [x.estimator != y.estimator, x.adaptive != y.adaptive, x.method != y.method]
        assert sum(differ) == 1
    assert set(SOCP_WITHIN) <= set(pairs)


def test_a_campaign_with_the_single_factor_compares_mtf_with_it_first() -> None:
    """``--arch with_stf``: the paper's pairs, then MTF vs STF at each schedule (P(MTF beats
    STF)), STF adaptive vs fixed and STF vs plain; the paper's rows as without the STF."""
    archs = [*ARCHITECTURES, "stf_fixed", "stf_adaptive"]
    runs = _runs(archs)
    frame = statistics.paired(runs, seed=7)
    paper = statistics.paired(runs[runs["arch"].isin(list(ARCHITECTURES))], seed=7)
    pd.testing.assert_frame_equal(frame.iloc[: len(paper)].reset_index(drop=True), paper)
    added = list(dict.fromkeys(zip(frame["arch"], frame["other"], strict=True)))[4:]
    assert added == [
        ("mtf_adaptive", "stf_adaptive"),
        ("mtf_fixed", "stf_fixed"),
        ("stf_adaptive", "stf_fixed"),
        ("stf_adaptive", "plain_adaptive"),
        ("stf_fixed", "plain_fixed"),
    ]


def test_an_all_socp_campaign_compares_its_estimators_and_schedules() -> None:
    frame = statistics.paired(_runs(list(SOCP_ARCHITECTURES)))
    assert _pairs_of(frame) == set(SOCP_WITHIN)
    assert len(frame) == 3 * len(SOCP_WITHIN)


@pytest.mark.parametrize("by", [[], ["point", "param.schedule.beta"]])
def test_the_added_pairs_append_rows_and_change_none(by: list[str]) -> None:
    """Every architecture, three grid points: the rows of PAIRS first, bit for bit as before."""
    runs = _runs(PAPER_EIGHT, points=3 if by else 1)
    before = statistics.paired(runs, by, seed=7, pairs=statistics.PAIRS)
    now = statistics.paired(runs, by, seed=7)
    assert len(now) > len(before)
    pd.testing.assert_frame_equal(now.iloc[: len(before)].reset_index(drop=True), before)
    assert _pairs_of(now.iloc[len(before) :]) == set(SOCP_WITHIN)
    added = ("plain_fixed_socp", "mtf_adaptive")
    more = statistics.paired(runs, by, seed=7, pairs=(*statistics.DEFAULT_PAIRS, added))
    pd.testing.assert_frame_equal(more.iloc[: len(now)].reset_index(drop=True), now)
    assert _pairs_of(more.iloc[len(now) :]) == {added}


def test_pairs_named_on_the_command_line_are_checked() -> None:
    archs = ["mtf_adaptive", "plain_fixed"]
    got = statistics.campaign_pairs(
        ["plain_fixed:mtf_adaptive", " plain_fixed : mtf_adaptive"], archs
    )
    assert got == (*statistics.DEFAULT_PAIRS, ("plain_fixed", "mtf_adaptive"))  # once
    default = statistics.campaign_pairs(["mtf_fixed:plain_fixed"], ["mtf_fixed", "plain_fixed"])
    assert default == statistics.DEFAULT_PAIRS  # compared anyway: not repeated
    for text, says in [
        ("mtf_adaptive", "expected A:B"),
        ("mtf_adaptive:plain", "'plain' is unknown"),
        ("mtf_adaptive:mtf_fixed", "'mtf_fixed' is not in this campaign"),
        ("mtf_adaptive:mtf_adaptive", "two different architectures"),
    ]:
        with pytest.raises(ConfigError, match=says) as info:
            statistics.campaign_pairs([text], archs)
        assert f"--pair {text!r}" in str(info.value) and "mtf_adaptive, plain_fixed" in str(
            info.value
        )


def test_an_until_target_may_name_a_pair_of_the_command_line() -> None:
    pairs = statistics.campaign_pairs(["mtf_fixed:plain_adaptive"], ["mtf_fixed", "plain_adaptive"])
    target = sequential.parse_until("miss_km@mtf_fixed-plain_adaptive:0.001", pairs)
    assert target.pair == ("mtf_fixed", "plain_adaptive")


def _config(tmp_path: Path) -> Path:
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path / "results"}"\n')
    return cfg


@pytest.mark.parametrize("command", ["ablate", "sweep"])
def test_a_pair_outside_the_campaign_exits_2_naming_the_choices(
    tmp_path: Path, command: str
) -> None:
    args = [command, str(_config(tmp_path)), "--arch", "mtf_adaptive,plain_adaptive",
            "--pair", "mtf_adaptive_socp:plain_adaptive"]  # fmt: skip
    result = runner.invoke(app, args, env={"COLUMNS": "200"})
    assert result.exit_code == 2, result.output
    text = " ".join(result.stderr.split())
    assert "--pair 'mtf_adaptive_socp:plain_adaptive'" in text
    assert "choices: mtf_adaptive, plain_adaptive" in text and "Traceback" not in result.output
    assert not (tmp_path / "results").exists()


def test_a_pair_is_stored_and_shown(tmp_path: Path) -> None:
    archs = "mtf_fixed,plain_adaptive"
    args = ["ablate", str(_config(tmp_path)), "--name", "p", "--arch", archs, "--seeds", "2",
            "-w", "1", "--no-rrd", "--pair", "plain_adaptive:mtf_fixed"]  # fmt: skip
    result = runner.invoke(app, args, env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    stats = pd.read_parquet(tmp_path / "results" / "p" / "ablation.parquet")
    paired = stats[stats["kind"] == "paired"]
    assert _pairs_of(paired) == {("plain_adaptive", "mtf_fixed")} and len(paired) == 3
    assert "plain_adaptive" in result.stdout and "vs mtf_fixed" in result.stdout


def _paired_in(directory: Path, stats: str = "ablation.parquet") -> set[tuple[str, str]]:
    frame = pd.read_parquet(directory / stats)
    paired = frame[frame["kind"] == "paired"]
    return _pairs_of(paired) if "other" in paired else set()  # no pair: no column


@pytest.mark.parametrize("command", ["ablate", "sweep"])
def test_a_pair_is_remembered_by_a_later_command_that_rewrites_the_statistics(
    tmp_path: Path, command: str
) -> None:
    """A resume naming no --pair (here: one more seed) keeps the pairs added before: the
    manifest records them and every rewrite of the statistics compares them again."""
    cfg = _config(tmp_path)
    base = [command, str(cfg), "--name", "p", "--arch", "mtf_fixed,plain_adaptive",
            "-w", "1", "--no-rrd", "-q"]  # fmt: skip
    if command == "sweep":
        base += ["--param", "schedule.beta=0.25,0.5"]
    stats = "ablation.parquet" if command == "ablate" else "sweep.parquet"
    out = tmp_path / "results" / "p"
    first = runner.invoke(app, [*base, "--seeds", "2", "--pair", "plain_adaptive:mtf_fixed"])
    assert first.exit_code == 0, first.output
    assert _paired_in(out, stats) == {("plain_adaptive", "mtf_fixed")}
    resumed = runner.invoke(app, [*base, "--seeds", "3"])
    assert resumed.exit_code == 0, resumed.output
    assert _paired_in(out, stats) == {("plain_adaptive", "mtf_fixed")}
    frame = pd.read_parquet(out / stats)
    assert set(frame.loc[frame["kind"] == "paired", "n"]) == {3}  # recomputed on 3 seeds
    manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    assert manifest["pairs"] == ["plain_adaptive:mtf_fixed"]


def test_a_remembered_pair_is_kept_by_a_rerun_naming_one_of_its_architectures(
    tmp_path: Path,
) -> None:
    """A re-run of one architecture of the pair is not refused for the pair it recorded."""
    cfg = _config(tmp_path)
    base = ["ablate", str(cfg), "--name", "p", "-w", "1", "--no-rrd", "-q", "--seeds", "2"]
    archs = ["--arch", "mtf_fixed,plain_adaptive"]
    first = runner.invoke(app, [*base, *archs, "--pair", "plain_adaptive:mtf_fixed"])
    assert first.exit_code == 0, first.output
    again = runner.invoke(app, [*base, "--arch", "mtf_fixed"])
    assert again.exit_code == 0, again.output
    out = tmp_path / "results" / "p"
    assert _paired_in(out) == {("plain_adaptive", "mtf_fixed")}
    manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    assert manifest["pairs"] == ["plain_adaptive:mtf_fixed"]


def _with_a_remembered_pair(tmp_path: Path) -> tuple[list[str], Path]:
    """A campaign whose first command added ``--pair plain_adaptive:mtf_fixed``: the
    arguments of a later command on it (naming no pair) and its directory."""
    base = ["ablate", str(_config(tmp_path)), "--name", "p", "--arch", "mtf_fixed,plain_adaptive",
            "-w", "1", "--no-rrd", "-q"]  # fmt: skip
    first = runner.invoke(app, [*base, "--seeds", "2", "--pair", "plain_adaptive:mtf_fixed"])
    assert first.exit_code == 0, first.output
    until = ["--until", "miss_km@plain_adaptive-mtf_fixed:1e9", "--batch", "2", "--max-seeds", "2"]
    return [*base, *until], tmp_path / "results" / "p"


def test_an_until_target_may_name_a_pair_remembered_from_an_earlier_command(
    tmp_path: Path,
) -> None:
    """``--until`` on a pair that an earlier ``--pair A:B`` added (the manifest records it,
    the statistics compare it again) is accepted without naming ``--pair`` again."""
    args, out = _with_a_remembered_pair(tmp_path)
    again = runner.invoke(app, args)
    assert again.exit_code == 0, again.output
    assert _paired_in(out) == {("plain_adaptive", "mtf_fixed")}


def test_until_with_force_does_not_target_the_pair_force_forgets(tmp_path: Path) -> None:
    args, _ = _with_a_remembered_pair(tmp_path)
    forced = runner.invoke(app, [*args, "--force"])
    assert forced.exit_code == 2 and "pairs compared are" in forced.stderr


def test_the_recorded_pairs_of_a_manifest_are_read_back_and_checked(tmp_path: Path) -> None:
    from cwrend_cli.output.manifest import ManifestError, read_manifest, recorded_pairs

    path = tmp_path / "manifest.json"
    path.write_text(json.dumps({"root_seed": 0, "pairs": ["a:b", "c:d"]}), encoding="utf-8")
    assert recorded_pairs(read_manifest(path, "fix")) == (("a", "b"), ("c", "d"))
    assert recorded_pairs({"root_seed": 0}) == ()
    path.write_text(json.dumps({"root_seed": 0, "pairs": ["a:b", "cd"]}), encoding="utf-8")
    with pytest.raises(ManifestError, match='"pairs"'):
        read_manifest(path, "fix")


def _with_applied(runs: pd.DataFrame, shift: float) -> pd.DataFrame:
    """``runs`` with an applied Δv: the trapezoid Δv plus ``shift`` [km/s]."""
    return runs.assign(delta_v_applied_km_s=runs["delta_v_km_s"] + shift)


def test_a_pair_across_campaigns_compares_the_applied_delta_v_too() -> None:
    """``mean_diff`` of the applied Δv (issue 33 item 3), per group, over the seeds where
    both ran ok: here A's applied Δv is B's trapezoid one + 1e-3 km/s on the same runs."""
    runs = _runs(["mtf_adaptive", "plain_adaptive"], points=2)
    rows = statistics.paired_across(
        _with_applied(runs, 1e-3), _with_applied(runs, 0.0), [("mtf_adaptive", "mtf_adaptive")],
        by=["point"], seed=7,
    )  # fmt: skip
    applied = rows[rows["metric"] == "delta_v_applied_km_s"]
    assert list(applied["statistic"]) == ["mean_diff", "mean_diff"]
    ok = runs[(runs["status"] == "ok") & (runs["arch"] == "mtf_adaptive")]
    assert list(applied["n"]) == list(ok.groupby("point").size())
    # the same runs on both sides: every difference is the shift (to
    # rounding: relative 1e-9 is far above the 1e-16 of a double's subtraction)
    np.testing.assert_allclose(applied["value"], 1e-3, rtol=1e-9)
    low_high = applied[["ci_low", "ci_high"]].to_numpy()
    np.testing.assert_allclose(low_high[0], 1e-3, rtol=1e-9)
    assert np.isnan(low_high[1]).all()  # point p1: one seed, no interval


def test_the_applied_delta_v_changes_no_row_of_a_pair_across_campaigns() -> None:
    """Its rows draw from a stream of their own: the paper's metrics' rows stay bit for bit."""
    runs = _runs(["mtf_adaptive", "plain_adaptive"], points=2)
    pairs = [("mtf_adaptive", "plain_adaptive"), ("plain_adaptive", "plain_adaptive")]
    before = statistics.paired_across(runs, runs, pairs, by=["point"], seed=7)
    gen = np.random.default_rng(5)
    noisy = runs.assign(delta_v_applied_km_s=gen.normal(0.14, 1e-3, len(runs)))
    after = statistics.paired_across(noisy, noisy, pairs, by=["point"], seed=7)
    kept = after[after["metric"] != "delta_v_applied_km_s"].reset_index(drop=True)
    pd.testing.assert_frame_equal(kept, before, check_exact=True)
    assert (after["metric"] == "delta_v_applied_km_s").sum() == 4  # 2 pairs × 2 points


def _until_on(tmp_path: Path, archs: str, recorded: list[str]) -> str:
    """stderr of an ``--until`` on the pair ``plain_adaptive-mtf_fixed`` by a command running
    ``archs`` in a campaign whose manifest records the pairs ``recorded`` (refused before any
    run: the manifest holds only them)."""
    out = tmp_path / "results" / "p"
    out.mkdir(parents=True)
    (out / "manifest.json").write_text(json.dumps({"pairs": recorded}), encoding="utf-8")
    args = ["ablate", str(_config(tmp_path)), "--name", "p", "--arch", archs, "-q", "--no-rrd",
            "--until", "miss_km@plain_adaptive-mtf_fixed:1"]  # fmt: skip
    result = runner.invoke(app, args, env={"COLUMNS": "200"})
    assert result.exit_code == 2, result.output
    return " ".join(result.stderr.split())


def test_an_until_on_a_pair_not_compared_lists_only_the_pairs_of_the_campaign(
    tmp_path: Path,
) -> None:
    text = _until_on(tmp_path, "mtf_adaptive,plain_adaptive", [])
    assert "pairs compared are mtf_adaptive-plain_adaptive" in text
    assert "mtf_fixed-plain_fixed" not in text and "socp" not in text


def test_an_until_on_a_remembered_pair_one_of_whose_architectures_is_not_run_says_so(
    tmp_path: Path,
) -> None:
    """The pair an earlier ``--pair`` added is compared only when both its architectures run:
    the refusal names it and the architecture to add, not every default pair."""
    text = _until_on(tmp_path, "mtf_adaptive,plain_adaptive", ["plain_adaptive:mtf_fixed"])
    assert "pairs compared are mtf_adaptive-plain_adaptive;" in text
    assert "plain_adaptive-mtf_fixed (added by an earlier --pair) is compared" in text
    assert "add mtf_fixed to --arch" in text
