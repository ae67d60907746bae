"""``cwrend compare A B``: paired differences of two campaigns on shared runs (issue 18, item 3)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from click.testing import Result
from typer.testing import CliRunner

from cwrend_cli.campaign import compare
from cwrend_cli.cli import app
from cwrend_cli.errors import ConfigError

ADAPTIVE = "mtf_adaptive,plain_adaptive"
runner = CliRunner()


def _campaign(root: Path, name: str, *args: str, command: str = "ablate") -> Path:
    cfg = root / "c.toml"
    cfg.write_text(f'[output]\ndir = "{root / "results"}"\n')
    base = [command, str(cfg), "--name", name, "--arch", ADAPTIVE, "-w", "1", "--no-rrd", "-q"]
    result = runner.invoke(app, [*base, *args])
    assert result.exit_code == 0, result.output
    return root / "results" / name


def _compare(*args: str | Path) -> Result:
    return runner.invoke(app, ["compare", *map(str, args)], env={"COLUMNS": "80"})


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """β = 0.25 (A) and β = 0.5 (B), four seeds each, two adaptive architectures."""
    root = tmp_path_factory.mktemp("compare")
    a = _campaign(root, "b025", "--seeds", "4", "--set", "schedule.beta=0.25")
    b = _campaign(root, "b05", "--seeds", "4", "--set", "schedule.beta=0.5")
    return a, b


@pytest.fixture(scope="module")
def compared(campaigns: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The output directory of ``cwrend compare A B`` (both metrics by default)."""
    out = tmp_path_factory.mktemp("out")
    result = _compare(*campaigns, "--out", out)
    assert result.exit_code == 0, result.output
    return out


def _expected(a: Path, b: Path) -> pd.DataFrame:
    """The per-seed differences computed here, from the two runs.parquet files."""
    ra, rb = pd.read_parquet(a / "runs.parquet"), pd.read_parquet(b / "runs.parquet")
    return ra.merge(rb, on=["arch", "seed"], suffixes=("_a", "_b"))


def _rows(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "compare.parquet")


def test_paired_differences_equal_those_of_the_runs(
    campaigns: tuple[Path, Path], compared: Path
) -> None:
    _check_differences(_rows(compared), _expected(*campaigns), ("miss_km", "delta_v_km_s"))


def _check_differences(rows: pd.DataFrame, merged: pd.DataFrame, metrics: tuple[str, ...]) -> None:
    """The mean and median of A − B stored per architecture and metric are those of the runs."""
    for arch, g in merged.groupby("arch"):
        for metric in metrics:
            d = (g[f"{metric}_a"] - g[f"{metric}_b"]).to_numpy()
            got = rows[(rows["arch"] == arch) & (rows["metric"] == metric)]
            value = dict(zip(got["statistic"], got["value"], strict=True))
            assert value["mean_diff"] == pytest.approx(np.mean(d), rel=1e-12, abs=1e-15)
            assert value["median_diff"] == pytest.approx(np.median(d), rel=1e-12, abs=1e-15)


def test_share_where_a_is_better_and_counts(campaigns: tuple[Path, Path], compared: Path) -> None:
    merged = _expected(*campaigns)
    rows = _rows(compared)
    for arch, g in merged.groupby("arch"):
        for metric in ("miss_km", "delta_v_km_s"):
            better = int((g[f"{metric}_a"] < g[f"{metric}_b"]).sum())
            row = rows[
                (rows["arch"] == arch)
                & (rows["metric"] == metric)
                & (rows["statistic"] == "frac_better")
            ].iloc[0]
            assert row["n"] == len(g) == 4
            assert row["value"] == better / 4
            assert row["ci_low"] <= row["value"] <= row["ci_high"]  # Wilson


def test_intervals_bracket_the_differences(compared: Path) -> None:
    rows = _rows(compared)
    diffs = rows[rows["statistic"].isin(["mean_diff", "median_diff"])]
    assert (diffs["ci_low"] <= diffs["value"] + 1e-15).all()
    assert (diffs["value"] <= diffs["ci_high"] + 1e-15).all()


def test_parquet_holds_the_rows_in_long_format(compared: Path) -> None:
    rows = _rows(compared)
    columns = ["kind", "arch", "metric", "statistic", "value", "ci_low", "ci_high", "n"]
    assert list(rows.columns[: len(columns)]) == columns
    # 2 architectures × 2 metrics × (mean, median, share better, share tied)
    assert len(rows) == 2 * 2 * 4
    assert set(rows["kind"]) == {"paired"}
    assert set(rows["point_a"]) == set(rows["point_b"]) == {"base"}
    meta = pq.read_schema(compared / "compare.parquet").metadata
    assert meta[b"a"].decode().endswith("b025") and meta[b"b"].decode().endswith("b05")
    assert b"cwrend_version" in meta and b"units" in meta


def test_figure_is_written(compared: Path) -> None:
    png = compared / "compare.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_metric_option_selects_metrics(campaigns: tuple[Path, Path], tmp_path: Path) -> None:
    result = _compare(*campaigns, "--metric", "fuel", "--out", tmp_path)
    assert result.exit_code == 0, result.output
    assert set(_rows(tmp_path)["metric"]) == {"fuel_penalty_pct"}
    assert "fuel pen. %" in result.stdout and "miss m" not in result.stdout


def test_unknown_metric_is_refused(campaigns: tuple[Path, Path], tmp_path: Path) -> None:
    result = _compare(*campaigns, "--metric", "miss,speed", "--out", tmp_path)
    assert result.exit_code == 2
    assert "--metric 'speed': unknown metric" in result.stderr


def test_table_fits_80_columns(campaigns: tuple[Path, Path], tmp_path: Path) -> None:
    result = _compare(*campaigns, "--out", tmp_path)
    assert result.exit_code == 0, result.output
    assert "…" not in result.stdout
    assert max(len(line) for line in result.stdout.splitlines()) <= 80
    assert "mtf_adaptive" in result.stdout and "A better" in result.stdout


def test_default_output_is_beside_a_not_inside(campaigns: tuple[Path, Path]) -> None:
    a, b = campaigns
    result = _compare(a, b, "-q")
    assert result.exit_code == 0, result.output
    assert result.stdout == ""
    assert (a.parent / "compare-b025-vs-b05" / "compare.parquet").exists()
    assert not list(a.glob("compare*")) and not list(b.glob("compare*"))


def test_different_noise_seed_is_refused(campaigns: tuple[Path, Path], tmp_path: Path) -> None:
    a, _ = campaigns
    other = _campaign(tmp_path, "seed7", "--seeds", "2", "--set", "noise.seed=7")
    result = _compare(a, other, "--out", tmp_path / "out")
    assert result.exit_code == 2
    assert "do not share noise" in result.stderr
    assert "noise.seed = 0" in result.stderr and "noise.seed = 7" in result.stderr
    assert not (tmp_path / "out").exists()


def test_campaigns_without_a_common_run_are_refused(
    campaigns: tuple[Path, Path], tmp_path: Path
) -> None:
    a, _ = campaigns
    other = _campaign(tmp_path, "late", "--seed-list", "10,11")
    result = _compare(a, other, "--out", tmp_path / "out")
    assert result.exit_code == 2
    assert "share no run" in " ".join(result.stderr.split())


def test_not_a_campaign_is_refused(campaigns: tuple[Path, Path], tmp_path: Path) -> None:
    result = _compare(campaigns[0], tmp_path, "--out", tmp_path / "out")
    assert result.exit_code == 2
    assert "not a campaign directory" in result.stderr


def test_points_match_by_swept_values(campaigns: tuple[Path, Path], tmp_path: Path) -> None:
    """A sweeps β, B ran β = 0.5 throughout: each A point meets B; β = 0.5 meets itself."""
    _, b = campaigns
    a = _campaign(
        tmp_path, "sweep", "--seeds", "2", "--param", "schedule.beta=0.25,0.5", command="sweep"
    )
    out = tmp_path / "out"
    result = _compare(a, b, "--out", out)
    assert result.exit_code == 0, result.output
    rows = _rows(out)
    assert sorted(set(rows["param.schedule.beta"])) == [0.25, 0.5]
    assert set(rows["point_b"]) == {"base"} and rows["point_a"].nunique() == 2
    same = rows[rows["param.schedule.beta"] == 0.5]
    assert (same.loc[same["statistic"] == "mean_diff", "value"] == 0.0).all()
    assert (same.loc[same["statistic"] == "frac_tied", "value"] == 1.0).all()
    assert set(rows["n"]) == {2}
    assert "beta = 0.25" in result.stdout and "beta = 0.5" in result.stdout


# --- matching (pure, on hand-made campaigns) ------------------------------------------


def _hand_made(path: Path, u_max: list[float], file: str | None = None) -> compare.Campaign:
    runs = pd.DataFrame(
        {
            "point": [f"p{i}" for i in range(len(u_max))],
            "arch": "mtf_adaptive",
            "seed": 0,
            "status": "ok",
            "miss_km": 1e-3,
            "delta_v_km_s": 0.14,
            "fuel_penalty_pct": 25.0,
            "param.scenario.u_max_km_s2": u_max,
        }
    )
    manifest = {"root_seed": 0, "config": {"noise": {"seed": 0, "file": file}}}
    return compare.Campaign(path, manifest, runs)


def test_swept_numbers_match_to_a_relative_tolerance(tmp_path: Path) -> None:
    a = _hand_made(tmp_path / "a", [6e-4, 0.0007999999999999999, 1e-3])  # 6e-4:1e-3:3
    b = _hand_made(tmp_path / "b", [8e-4, 9e-4])
    pairs = compare.match_runs(a, b).pairs
    assert list(zip(pairs["point_a"], pairs["point_b"], strict=True)) == [("p1", "p0")]


def test_noise_files_with_the_same_bytes_are_the_same_noise(tmp_path: Path) -> None:
    one, two, other = tmp_path / "1.csv", tmp_path / "2.csv", tmp_path / "3.csv"
    one.write_text("n1,n2,n3\n0,0,0\n")
    two.write_text("n1,n2,n3\n0,0,0\n")
    other.write_text("n1,n2,n3\n1,0,0\n")
    a = _hand_made(tmp_path / "a", [8e-4], str(one))
    assert len(compare.match_runs(a, _hand_made(tmp_path / "b", [8e-4], str(two))).pairs) == 1
    with pytest.raises(ConfigError, match="do not share noise"):
        compare.match_runs(a, _hand_made(tmp_path / "b", [8e-4], str(other)))
    with pytest.raises(ConfigError, match=r"no noise\.file"):
        compare.match_runs(a, _hand_made(tmp_path / "b", [8e-4]))


def test_the_figure_names_the_worlds_of_both_campaigns(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """cwrend compare passes both directories, so compare.png names each truth model."""
    import cwrend_cli.report as report

    seen: dict[str, object] = {}
    real = report.write_compare_figure

    def spy(*args: object, **kwargs: object) -> object:
        seen.update(kwargs)
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(report, "write_compare_figure", spy)
    cw = _campaign(tmp_path, "cw", "--seeds", "2")
    j2 = _campaign(tmp_path, "j2", "--seeds", "2", "--set", 'truth.model="j2"')
    result = _compare(cw, j2, "--out", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert seen["dirs"] == (cw, j2)


# --- one side always wins (issue 37, item 1) ------------------------------------------


def _one_sided(path: Path, miss_km: float, dv: float, seeds: int = 6) -> Path:
    """A hand-made ablation directory: every seed with the same miss and Δv offsets."""
    path.mkdir(parents=True)
    seed = np.arange(seeds)
    pd.DataFrame(
        {
            "point": "base",
            "arch": "mtf_adaptive",
            "seed": seed,
            "status": "ok",
            "miss_km": miss_km + 1e-4 * seed,
            "delta_v_km_s": dv + 1e-3 * seed,
            "fuel_penalty_pct": 25.0,
        }
    ).to_parquet(path / "runs.parquet")
    (path / "manifest.json").write_text('{"root_seed": 0, "config": {"noise": {"seed": 0}}}')
    return path


def test_compare_where_a_always_wins_has_shares_of_exactly_0_and_1(tmp_path: Path) -> None:
    """A misses less on every seed and spends more on every seed: P = 1 [.., 1] and 0 [0, ..].

    Six seeds: the Wilson formula alone put the lower end of 0/6 at 2.8e-17 (a negative
    error bar, and compare.png crashed with "'xerr' must not contain negative values").
    """
    a = _one_sided(tmp_path / "a", miss_km=1e-3, dv=0.15)
    b = _one_sided(tmp_path / "b", miss_km=2e-3, dv=0.14)
    out = tmp_path / "out"
    result = _compare(a, b, "--out", out)
    assert result.exit_code == 0, result.output
    assert (out / "compare.png").stat().st_size > 0
    share = _rows(out).set_index("metric")
    share = share[share["statistic"] == "frac_better"]
    assert tuple(share.loc["miss_km", ["value", "ci_high"]]) == (1.0, 1.0)
    assert tuple(share.loc["delta_v_km_s", ["value", "ci_low"]]) == (0.0, 0.0)
    assert (share["ci_low"] <= share["value"]).all() and (share["value"] <= share["ci_high"]).all()


def test_compare_figure_draws_intervals_that_end_a_hair_past_the_estimate() -> None:
    """An interval end rounded past its estimate draws no bar on that side, never a crash."""
    from cwrend_cli.report.figures import fig_compare

    rows = [
        {"kind": "paired", "arch": "mtf_adaptive", "metric": m, "statistic": s, "n": 6,
         "value": v, "ci_low": lo, "ci_high": hi}
        for m in ("miss_km", "delta_v_km_s")
        for s, v, lo, hi in (("mean_diff", -1e-3, -1e-3 + 1e-19, -5e-4),
                             ("median_diff", -1e-3, -2e-3, -1e-3 - 1e-19),
                             ("frac_better", 0.0, 2.8e-17, 0.39),
                             ("frac_tied", 0.0, np.nan, np.nan))
    ]  # fmt: skip
    fig = fig_compare(pd.DataFrame(rows), "A", "B")
    assert fig.axes


# ---------------------------------------------------------------------------
# The applied Δv and its penalty (issue 33 item 3)
# ---------------------------------------------------------------------------


def test_applied_delta_v_and_penalty_are_compared_seed_by_seed(
    campaigns: tuple[Path, Path], tmp_path: Path
) -> None:
    result = _compare(*campaigns, "--metric", "dv_applied,fuel_applied", "--out", tmp_path)
    assert result.exit_code == 0, result.output
    applied = ("delta_v_applied_km_s", "fuel_penalty_applied_pct")
    rows = _rows(tmp_path)
    assert set(rows["metric"]) == set(applied)
    _check_differences(rows, _expected(*campaigns), applied)


def test_applied_metrics_have_their_own_console_rows_within_80_columns(
    campaigns: tuple[Path, Path], tmp_path: Path
) -> None:
    result = _compare(*campaigns, "--metric", "dv,dv_applied,fuel_applied", "--out", tmp_path)
    assert result.exit_code == 0, result.output
    assert "applied Δv km/s" in result.stdout and "applied pen. %" in result.stdout
    assert "…" not in result.stdout
    assert max(len(line) for line in result.stdout.splitlines()) <= 80


def test_a_campaign_written_before_the_applied_delta_v_is_refused_naming_the_fix(
    campaigns: tuple[Path, Path], tmp_path: Path
) -> None:
    """runs.parquet without the column (cwrend before issue 33): exit 2, nothing written."""
    import shutil

    a, b = campaigns
    old = tmp_path / "old"
    shutil.copytree(a, old)
    runs = pd.read_parquet(old / "runs.parquet")
    runs.drop(columns=["delta_v_applied_km_s", "fuel_penalty_applied_pct"]).to_parquet(
        old / "runs.parquet"
    )
    result = _compare(b, old, "--metric", "miss,dv_applied", "--out", tmp_path / "out")
    assert result.exit_code == 2, result.output
    message = " ".join(result.stderr.split())
    assert "dv_applied" in message and "delta_v_applied_km_s" in message
    assert str(old) in message and "re-run the campaign" in message
    assert "Traceback" not in result.output
    assert not (tmp_path / "out").exists()
    # the metrics it holds are still compared
    assert _compare(b, old, "--metric", "miss,dv", "--out", tmp_path / "o2").exit_code == 0


def test_every_metric_name_means_the_same_column_in_compare_and_table() -> None:
    """One table of short names (output.tables.METRIC_NAMES) for both ``--metric`` options."""
    from cwrend_cli.output.tables import METRIC_NAMES
    from cwrend_cli.report.table import parse_value

    assert {"miss", "dv", "fuel", "dv_applied", "fuel_applied"} <= set(METRIC_NAMES)
    for name, column in METRIC_NAMES.items():
        assert parse_value(name).metric == column  # at its default statistic
        if column in compare.COMPARED:
            assert compare.parse_metrics(name) == (column,)
        else:  # the filter-consistency means and the safety values: not compared
            with pytest.raises(ConfigError, match=f"--metric '{name}': unknown metric"):
                compare.parse_metrics(name)


def test_the_notes_go_to_stderr_with_a_script_format_too(tmp_path: Path) -> None:
    """``--format csv`` puts the table on stdout and still tells, on stderr, which
    architectures were in one campaign only (the note was dropped with --format)."""
    a = _one_sided(tmp_path / "a", miss_km=1e-3, dv=0.15)
    runs = pd.read_parquet(a / "runs.parquet")
    extra = runs.assign(arch="plain_fixed")
    pd.concat([runs, extra]).to_parquet(a / "runs.parquet")
    b = _one_sided(tmp_path / "b", miss_km=2e-3, dv=0.14)
    result = _compare(a, b, "--out", tmp_path / "out", "--format", "csv")
    assert result.exit_code == 0, result.output
    assert "note: architecture(s) in one campaign only, not compared: plain_fixed" in result.stderr
    assert "not compared" not in result.stdout and result.stdout.startswith("kind,arch,")
