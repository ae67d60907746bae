"""`cwrend report`: figures and tables of run and campaign directories (issue 5, item 2)."""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib.image
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest
from matplotlib.collections import PathCollection, PolyCollection
from matplotlib.container import BarContainer
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.campaign.driver import write_statistics
from cwrend_cli.cli import app
from cwrend_cli.config import ARCHITECTURES, CwrendConfig, apply, config_from_dict, resolved_dict
from cwrend_cli.config.adapt import windows_of
from cwrend_cli.output.files import write_parquet
from cwrend_cli.output.tables import references_table, steps_table, summary_row
from cwrend_cli.physics import simulation
from cwrend_cli.report import load_results, write_compare_figure, write_report
from cwrend_cli.report.html import report_html
from cwrend_cli.report.labels import consistency_text, format_value, param_label, param_setting
from cwrend_cli.report.load import references_file
from cwrend_cli.report.markdown import report_md

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
PER_SEED = (
    "fig1_trajectories.png",
    "fig2_control.png",
    "fig3_eps_score.png",
    "fig4_nis_mtf.png",
    "fig5_errors.png",
    "fig6_dv_vs_miss.png",
)
MULTI_SEED = ("miss_distribution.png", "dv_distribution.png", "paired_miss.png")
NEES = "nees.png"  # filter consistency, when the steps hold the NEES (issue 15, item 6)
CONSISTENCY = "consistency.png"  # ensemble means against χ² bands, likewise (issue 33, item 4)
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

runner = CliRunner()


def _check_png(path: Path) -> None:
    assert path.exists(), path
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC, path
    assert len(data) > 10_000, (path, len(data))
    image = matplotlib.image.imread(path)
    height, width = image.shape[:2]
    assert height > 400 and width > 400, (path, image.shape)


def _report(results: Path, *args: str):
    return runner.invoke(app, ["report", str(results), *args], catch_exceptions=False)


def _rasterise_only(monkeypatch: pytest.MonkeyPatch, *names: str) -> None:
    """Every figure drawn, only those named rasterised: the others' PNG is the signature only.

    Rasterising is ~0.3 s a figure, ~3 s of a report's ~3.5 s. Every figure is
    still drawn (its data loaded, its artists made) and every file written
    (atomically, by the report), so a test of report.md, of the files written
    or of the data read loses nothing; the figures a test checks with
    :func:`_check_png` are rasterised (a figure is known by its file name,
    which the temporary file of ``atomic_path`` holds: were that to change,
    ``_check_png`` fails, it cannot pass on a placeholder). The run report and
    the multi-seed report rasterise every figure.
    """
    from matplotlib.figure import Figure

    real = Figure.savefig

    def savefig(self: Figure, fname: Any, *args: Any, **kwargs: Any) -> None:
        if any(name in Path(fname).name for name in names):
            real(self, fname, *args, **kwargs)
        else:
            Path(fname).write_bytes(PNG_MAGIC)

    monkeypatch.setattr(Figure, "savefig", savefig)


@pytest.fixture(name="unrendered")
def _unrendered(monkeypatch: pytest.MonkeyPatch) -> None:
    """No figure rasterised (:func:`_rasterise_only`), for tests that check no PNG."""
    _rasterise_only(monkeypatch)


# ---------------------------------------------------------------------------
# A `cwrend run` directory
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("run") / "out"
    result = runner.invoke(
        app, ["run", str(PAPER), "--arch", "all", "--out", str(out), "-q"], catch_exceptions=False
    )
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="module")
def run_report(run_dir: Path):
    result = _report(run_dir)
    assert result.exit_code == 0, result.output
    return result


def test_run_writes_a_recording_by_default(run_dir: Path) -> None:
    assert (run_dir / "recording.rrd").stat().st_size > 10_000


def test_report_of_a_run_writes_every_figure(run_dir: Path, run_report) -> None:
    report_dir = run_dir / "report"
    for name in PER_SEED:
        _check_png(report_dir / name)
        assert str(report_dir / name) in run_report.output
    # one seed: no distributions
    assert not any((report_dir / name).exists() for name in MULTI_SEED)


def test_report_md_holds_the_table(run_dir: Path, run_report) -> None:
    md = (run_dir / "report" / "report.md").read_text(encoding="utf-8")
    assert "| case | Δv [km/s] | miss [m] |" in md
    for arch in ARCHITECTURES.values():
        assert f"| {arch.label} |" in md
    assert "| open-loop energy | 0.1502 |" in md
    assert "| open-loop fuel | 0.1128 |" in md
    for name in PER_SEED:
        assert f"]({name})" in md


def test_report_md_of_a_run_gives_the_references_applied_dv_as_the_run_stored_it(
    run_dir: Path, run_report
) -> None:
    """``cwrend run`` stores the references' applied Δv (∫‖u‖dt of the plan) and prints it;
    the report of that run shows it too (the exact fuel optimum, 0.1131 km/s, 0 %)."""
    md = (run_dir / "report" / "report.md").read_text(encoding="utf-8")
    assert "| open-loop fuel | 0.1128 | 0.00 | 0.00 | 0.1131 | 0.00 |" in md


def test_report_is_rewritten_in_place(run_dir: Path, run_report, unrendered: None) -> None:
    result = _report(run_dir, "--seed", "0")
    assert result.exit_code == 0, result.output
    names = sorted(p.name for p in (run_dir / "report").iterdir())
    expected = [*PER_SEED, NEES, CONSISTENCY, "report.md", "report.html"]
    assert names == sorted(expected)  # no temp files left behind


def test_a_quiet_report_prints_nothing_and_writes_every_file(
    run_dir: Path, run_report, unrendered: None
) -> None:
    result = _report(run_dir, "-q")
    assert result.exit_code == 0, result.output
    assert result.stdout == "" and result.stderr == ""
    assert (run_dir / "report" / "report.html").stat().st_size > 1_000


def test_report_errors(tmp_path: Path, run_dir: Path) -> None:
    missing = _report(tmp_path / "nope")
    assert missing.exit_code == 2 and "error:" in missing.output
    empty = _report(tmp_path)
    assert empty.exit_code == 2 and "no cwrend results" in empty.output
    bad_seed = _report(run_dir, "--seed", "7")
    assert bad_seed.exit_code == 2 and "--seed 7" in bad_seed.output


def test_run_without_recording(tmp_path: Path) -> None:
    out = tmp_path / "norrd"
    result = runner.invoke(
        app, ["run", str(PAPER), "--out", str(out), "-q", "--no-rrd"], catch_exceptions=False
    )
    assert result.exit_code == 0, result.output
    assert not (out / "recording.rrd").exists()
    spawn = runner.invoke(app, ["run", str(PAPER), "--out", str(out), "--spawn", "--no-rrd"])
    assert spawn.exit_code == 2 and "--spawn" in spawn.output


# ---------------------------------------------------------------------------
# A hand-made campaign directory (the layout contract of runs.parquet / steps/)
# ---------------------------------------------------------------------------

CAMPAIGN_ARCHS = ("plain_adaptive", "mtf_adaptive")


def _write_campaign(
    root: Path,
    points: Sequence[tuple[str, dict]],
    seeds: Sequence[int],
    with_refs: bool,
    with_stats: bool = True,
) -> Path:
    """runs.parquet, steps/arch=<slug>/, manifest.json as the campaign layer writes them.

    With ``with_refs``, also references/<point>.parquet (the open-loop references of each point);
    with ``with_stats``, the statistics file of the campaign driver.
    """
    base = resolved_dict(CwrendConfig())
    archs = tuple(ARCHITECTURES[a] for a in CAMPAIGN_ARCHS)
    rows, steps = [], {a: [] for a in CAMPAIGN_ARCHS}
    for point, params in points:
        cfg = config_from_dict(apply(base, tuple(params.items())))
        refs = campaign.run_case(cfg, (), 0).references
        if with_refs:
            write_parquet(references_table(refs), root / "references" / f"{point}.parquet")
        for seed in seeds:
            case = campaign.run_case(cfg, archs, seed, refs=refs)
            for run in case.runs:
                key = f"{point}.{run.arch}.s{seed:06d}"
                row = {"run_key": key, "point": point, "arch": run.arch, "seed": seed}
                row |= {"status": "ok", "error": "", "duration_s": 0.01}
                row |= summary_row(run, refs.fuel)
                row |= {f"param.{k}": v for k, v in params.items()}
                rows.append(row)
                table = steps_table(run).drop_columns(["arch"])
                table = table.append_column("run_key", pa.array([key] * table.num_rows))
                table = table.append_column("point", pa.array([point] * table.num_rows))
                steps[run.arch].append(table.replace_schema_metadata(None))
    # a failed run is listed but has no steps
    rows.append({"run_key": "x.mtf_adaptive.s999999", "point": points[0][0],
                 "arch": "mtf_adaptive", "seed": 999999, "status": "failed",
                 "error": "boom"})  # fmt: skip
    pd.DataFrame(rows).to_parquet(root / "runs.parquet")
    for arch, tables in steps.items():
        write_parquet(pa.concat_tables(tables), root / "steps" / f"arch={arch}" / "t.parquet")
    (root / "manifest.json").write_text(json.dumps({"config": base, "config_hash": "abc"}))
    if with_stats:  # ablation.parquet / sweep.parquet, as the campaign driver writes them
        write_statistics(root, "ablate" if len(points) == 1 else "sweep", 0)
    return root


@pytest.fixture(scope="module")
def ablation_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("ablation")
    return _write_campaign(root, [("base", {})], seeds=(0, 1, 2), with_refs=True)


@pytest.fixture(scope="module")
def ablation_report(ablation_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``cwrend report`` of a copy of the hand-made ablation (figures rasterised): its copy."""
    root = _copy(ablation_dir, tmp_path_factory.mktemp("reported") / "ablation")
    result = _report(root)
    assert result.exit_code == 0, result.output
    return root


def test_report_of_a_multi_seed_campaign(ablation_report: Path) -> None:
    report_dir = ablation_report / "report"
    for name in (*PER_SEED, *MULTI_SEED):
        _check_png(report_dir / name)
    md = (report_dir / "report.md").read_text(encoding="utf-8")
    assert "## Over 3 noise seeds" in md
    assert "| MTF KF, adaptive ε | 3 / 1 |" in md  # the failed run is counted
    assert "noise seed **0**" in md


def test_campaign_seed_selection(ablation_dir: Path, tmp_path: Path, unrendered: None) -> None:
    root = _copy(ablation_dir, tmp_path / "seed2")
    summary = write_report(root, seed=2)
    assert summary.layout == "campaign" and summary.seed == 2
    assert "noise seed **2**" in (summary.out_dir / "report.md").read_text(encoding="utf-8")
    result = _report(root, "--seed", "999999")  # exists, but failed: no steps
    assert result.exit_code == 2 and "error:" in result.output


@pytest.fixture(scope="module")
def sweep_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("sweep")
    points = [("p_a", {"schedule.beta": 0.25}), ("p_b", {"schedule.beta": 0.5})]
    return _write_campaign(root, points, seeds=(0, 1), with_refs=True)


def _copy(results: Path, to: Path) -> Path:
    """A copy of a results directory without its report."""
    return Path(shutil.copytree(results, to, ignore=shutil.ignore_patterns("report")))


def _refuse_references(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make computing open-loop references fail: a report must never recompute them."""

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the report recomputed the open-loop references")

    monkeypatch.setattr(simulation, "open_loop_references", refuse)


@pytest.fixture(name="no_physics")
def _no_physics(monkeypatch: pytest.MonkeyPatch) -> None:
    _refuse_references(monkeypatch)


def test_report_of_a_sweep(
    sweep_dir: Path, no_physics: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    _rasterise_only(monkeypatch, "sweep_schedule.beta.png")  # the per-seed ones: as any campaign
    root = sweep_dir
    summary = write_report(root)
    names = {p.name for p in summary.files}
    assert {*PER_SEED, *MULTI_SEED, "sweep_schedule.beta.png", "report.md"} <= names
    _check_png(root / "report" / "sweep_schedule.beta.png")
    assert summary.point == "p_a"  # the point at the base config's β = 0.25
    md = (root / "report" / "report.md").read_text(encoding="utf-8")
    assert "## Sweep of `schedule.beta`" in md
    assert "| 0.5 | MTF KF, adaptive ε | 2 |" in md
    # references read from references/p_a.parquet
    assert "| open-loop fuel | 0.1128 |" in md


def _scale_control(path: Path, factor: float) -> None:
    """Rewrite a stored references file with its control magnitude scaled by ``factor``."""
    table = pq.read_table(path)
    i = table.schema.get_field_index("u_norm_km_s2")
    scaled = pc.multiply(table.column(i), factor)
    pq.write_table(table.set_column(i, "u_norm_km_s2", scaled), path)


def test_campaign_report_uses_the_references_the_campaign_stored(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, unrendered: None
) -> None:
    args = ["sweep", str(PAPER), "-p", "schedule.beta=0.25,0.5", "-n", "2", "-w", "1", "-q",
            "-a", ",".join(CAMPAIGN_ARCHS), "--name", "c",
            "--set", f'output.dir="{tmp_path}"']  # fmt: skip
    result = runner.invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    root = tmp_path / "c"
    reported = campaign.point_id((("schedule.beta", 0.25),))
    other = campaign.point_id((("schedule.beta", 0.5),))
    # β does not change the references: both points name one shared file
    (shared,) = {references_file(root, p) for p in (reported, other)}
    assert {p.name for p in (root / "references").iterdir()} == {
        Path(shared).name,
        "index.jsonl",
    }
    _refuse_references(monkeypatch)  # from here on, computing references fails
    summary = write_report(root)
    assert summary.point == reported
    assert not any("references" in note for note in summary.notes)
    md = (root / "report" / "report.md").read_text(encoding="utf-8")
    assert "| open-loop fuel | 0.1128 |" in md


def test_campaign_report_reads_the_reported_points_references(
    sweep_dir: Path, tmp_path: Path, no_physics: None, unrendered: None
) -> None:
    root = _copy(sweep_dir, tmp_path / "sweep")
    _scale_control(root / "references" / "p_a.parquet", 2.0)  # the reported point
    _scale_control(root / "references" / "p_b.parquet", 3.0)
    summary = write_report(root)
    assert summary.point == "p_a"
    assert not any("references" in note for note in summary.notes)
    md = (root / "report" / "report.md").read_text(encoding="utf-8")
    assert "| open-loop fuel | 0.2256 |" in md  # 2 × 0.1128: the stored file, as it is
    assert "0.3384" not in md  # not the other point's references
    data = load_results(root)
    assert data.references is not None
    assert set(data.references["reference"]) == {"energy", "fuel"}
    assert list(data.ref_summary["arch"]) == ["open_loop_energy", "open_loop_fuel"]


def test_campaign_without_stored_references_gets_a_note(
    ablation_dir: Path, tmp_path: Path, no_physics: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    _rasterise_only(monkeypatch, *PER_SEED, *MULTI_SEED)
    root = _copy(ablation_dir, tmp_path / "old")
    shutil.rmtree(root / "references")  # as written by older versions of cwrend
    summary = write_report(root)
    for name in (*PER_SEED, *MULTI_SEED):
        _check_png(root / "report" / name)
    (note,) = [n for n in summary.notes if "references" in n]
    assert "not drawn" in note and "references/base.parquet" in note and "Rerun" in note
    md = (root / "report" / "report.md").read_text(encoding="utf-8")
    assert note in md
    assert "open-loop" not in md.split("## Figures")[0]  # no reference rows in the tables
    assert "| MTF KF, adaptive ε | 3 / 1 |" in md


def test_report_with_an_unusable_stored_config(
    ablation_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _rasterise_only(monkeypatch, *PER_SEED)
    root = _copy(ablation_dir, tmp_path / "badcfg")
    manifest = json.loads((root / "manifest.json").read_text(encoding="utf-8"))
    manifest["config"]["schedule"]["beta"] = -1.0
    (root / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    data = load_results(root)
    assert data.config is None and data.windows == ()
    assert any("does not validate" in n and "schedule.beta" in n for n in data.notes)
    summary = write_report(root)
    for name in PER_SEED:
        _check_png(root / "report" / name)
    md = (summary.out_dir / "report.md").read_text(encoding="utf-8")
    assert "Degradation windows" not in md
    good = load_results(ablation_dir)
    assert good.config is not None and good.windows == windows_of(good.config)
    assert len(good.windows) == 2


# ---------------------------------------------------------------------------
# Intervals, units and precision in report.md and the figures (issue 18, item 2)
# ---------------------------------------------------------------------------


def _row(md: str, start: str) -> list[str]:
    """The cells of the first markdown table row starting with ``| start |``."""
    (line,) = [ln for ln in md.splitlines() if ln.startswith(f"| {start} |")][:1]
    return [c.strip() for c in line.strip("|").split("|")]


def _stat(stats: pd.DataFrame, **match: str) -> pd.Series:
    sel = stats
    for column, value in match.items():
        sel = sel[sel[column] == value]
    (index,) = sel.index
    return sel.loc[index]


def test_report_md_tables_carry_the_stored_intervals(
    ablation_dir: Path, tmp_path: Path, unrendered: None
) -> None:
    root = _copy(ablation_dir, tmp_path / "tampered")
    stats = pd.read_parquet(root / "ablation.parquet")
    # shift the stored intervals: the report must show these, never recompute them
    stats["ci_low"] -= 1e-4
    stats.to_parquet(root / "ablation.parquet")
    md = (write_report(root).out_dir / "report.md").read_text(encoding="utf-8")
    miss = _stat(stats, kind="marginal", arch="mtf_adaptive", metric="miss_km", statistic="mean")
    dv = _stat(stats, kind="marginal", arch="mtf_adaptive", metric="delta_v_km_s",
               statistic="mean")  # fmt: skip
    overall = md.split("## Over 3 noise seeds")[1]
    cells = _row(overall, "MTF KF, adaptive ε")
    assert cells[1] == "3 / 1"
    assert cells[2] == f"{dv.value:.4f} [{dv.ci_low:.4f}, {dv.ci_high:.4f}]\\*"
    assert (
        cells[3] == f"{miss.value * 1e3:.2f} [{miss.ci_low * 1e3:.2f}, {miss.ci_high * 1e3:.2f}]\\*"
    )
    less = _stat(stats, kind="paired", arch="mtf_adaptive", statistic="frac_less")
    med = _stat(stats, kind="paired", arch="mtf_adaptive", statistic="median_diff")
    pair = _row(overall, "MTF KF, adaptive ε vs plain KF, adaptive ε")
    assert pair[1] == "3"
    assert pair[2] == f"{less.value:.2f} [{less.ci_low:.2f}, {less.ci_high:.2f}]"  # Wilson: no mark
    assert pair[3] == f"{med.value * 1e3:.2f} [{med.ci_low * 1e3:.2f}, {med.ci_high * 1e3:.2f}]\\*"


def test_intervals_from_fewer_than_10_seeds_are_flagged(
    ablation_dir: Path, tmp_path: Path, unrendered: None
) -> None:
    note = "fewer than 10 seeds: bootstrap interval unreliable"
    md = report_md(load_results(ablation_dir), ablation_dir, [])  # 3 seeds
    assert note in md
    root = _copy(ablation_dir, tmp_path / "many")
    stats = pd.read_parquet(root / "ablation.parquet")
    stats["n"] = 12  # as if from 12 seeds
    stats.to_parquet(root / "ablation.parquet")
    text = (write_report(root).out_dir / "report.md").read_text(encoding="utf-8")
    assert note not in text and "\\*" not in text
    assert _row(text.split("## Over")[1], "MTF KF, adaptive ε")[2].endswith("]")


def test_report_md_without_a_statistics_file(
    ablation_dir: Path, tmp_path: Path, unrendered: None
) -> None:
    root = _copy(ablation_dir, tmp_path / "nostats")
    (root / "ablation.parquet").unlink()
    md = (write_report(root).out_dir / "report.md").read_text(encoding="utf-8")
    assert "values without intervals" in md
    cells = _row(md.split("## Over 3 noise seeds")[1], "MTF KF, adaptive ε")
    assert "[" not in "".join(cells)
    assert "Paired comparisons" not in md


def test_misses_are_in_m_in_report_md_and_figures(ablation_dir: Path) -> None:
    from cwrend_cli.report import figures

    data = load_results(ablation_dir)
    md = report_md(data, ablation_dir, [])
    assert "miss [km]" not in md and "miss [m]" in md
    header = next(ln for ln in md.splitlines() if ln.startswith("| case |"))
    assert "| miss [m] |" in header
    run = data.ok_runs().query("arch == 'mtf_adaptive' and seed == 0").iloc[0]
    per_seed = md.split("## Noise seed 0")[1]  # after the campaign's statistics
    assert _row(per_seed, "MTF KF, adaptive ε")[2] == f"{run.miss_km * 1e3:.2f}"
    for draw in (figures.fig_miss_distribution, figures.fig_dv_vs_miss):
        assert draw(data).axes[0].get_ylabel().endswith("[m]")
    paired = figures.fig_paired_miss(data).axes[0]
    assert paired.get_xlabel().endswith("[m]") and paired.get_ylabel().endswith("[m]")


def test_sweep_table_carries_the_stored_intervals(sweep_dir: Path) -> None:
    stats = pd.read_parquet(sweep_dir / "sweep.parquet")
    md = report_md(load_results(sweep_dir), sweep_dir, [])
    sweep = md.split("## Sweep of")[1]
    p_b = stats[(stats["point"] == "p_b") & (stats["kind"] == "marginal")]
    miss = _stat(p_b, arch="plain_adaptive", metric="miss_km", statistic="mean")
    cells = _row(sweep, "0.5 | plain KF, adaptive ε")
    assert (
        cells[4] == f"{miss.value * 1e3:.2f} [{miss.ci_low * 1e3:.2f}, {miss.ci_high * 1e3:.2f}]\\*"
    )


def test_sweep_table_gives_each_points_consistency_against_its_band(sweep_dir: Path) -> None:
    """Per grid point: the mean of the runs' mean NEES and NIS, computed here from runs.parquet,
    with the χ² band of its 2 runs (scipy.stats.chi2) and the verdict (issue 33, item 4)."""
    from scipy.stats import chi2

    runs = pd.read_parquet(sweep_dir / "runs.parquet").query("status == 'ok'")
    mine = runs[(runs["point"] == "p_b") & (runs["arch"] == "plain_adaptive")]
    md = report_md(load_results(sweep_dir), sweep_dir, [])
    cells = _row(md.split("## Sweep of")[1], "0.5 | plain KF, adaptive ε")
    # after the point, architecture, runs, four miss/Δv cells and the applied Δv
    for k, (metric, dof) in enumerate((("mean_nees", 6), ("mean_nis_nominal", 3))):
        low, high = chi2.ppf([0.025, 0.975], dof * 2) / 2
        mean = mine[metric].mean()
        assert cells[8 + 2 * k] == f"{consistency_text(mean)} [{low:.2f}, {high:.2f}]"
        assert cells[9 + 2 * k] == ("yes" if low <= mean <= high else "no")


def test_param_labels_are_symbols_with_units_and_values_as_given() -> None:
    assert param_label("param.scenario.u_max_km_s2") == "u_max [km/s²]"
    assert param_label("schedule.beta") == "β [-]"
    assert param_label("guidance.some_new_key_s") == "some_new_key [s]"  # unit from the suffix
    assert format_value(0.0007999999999999999) == "0.0008"
    assert format_value(3) == "3" and format_value(0.25) == "0.25"
    assert param_setting("scenario.u_max_km_s2", 0.0007999999999999999) == "u_max = 0.0008 km/s²"


def test_sweep_figure_labels_are_symbols_with_units(sweep_dir: Path) -> None:
    from cwrend_cli.report import figures

    fig = figures.fig_sweep(load_results(sweep_dir), "param.schedule.beta")
    ax_m, ax_v = fig.axes[:2]
    assert ax_m.get_xlabel() == ax_v.get_xlabel() == "β [-]"
    assert ax_m.get_ylabel().endswith("[m]") and ax_v.get_ylabel() == "mean Δv [km/s]"
    assert [t.get_text() for t in ax_m.get_xticklabels()] == ["0.25", "0.5"]


def _band_limits(ax: Any) -> list[tuple[float, float]]:
    """(low, high) of the y extent of each filled band of ``ax``."""
    out = []
    for coll in ax.collections:
        if isinstance(coll, PolyCollection):
            y = np.concatenate([p.vertices[:, 1] for p in coll.get_paths()])
            out.append((float(y.min()), float(y.max())))
    return out


def test_sweep_figure_bands_are_the_stored_intervals(sweep_dir: Path, tmp_path: Path) -> None:
    from cwrend_cli.report import figures

    stats = pd.read_parquet(sweep_dir / "sweep.parquet")
    dv = stats[(stats["kind"] == "marginal") & (stats["metric"] == "delta_v_km_s")
               & (stats["statistic"] == "mean")]  # fmt: skip
    fig = figures.fig_sweep(load_results(sweep_dir), "param.schedule.beta")
    expected = sorted(
        v for _, g in dv.groupby("arch") for v in (g["ci_low"].min(), g["ci_high"].max())
    )
    drawn = sorted(v for band in _band_limits(fig.axes[1]) for v in band)
    assert drawn == pytest.approx(expected)
    assert len(_band_limits(fig.axes[0])) == 2  # median-miss bands, one per architecture
    root = _copy(sweep_dir, tmp_path / "nostats")
    (root / "sweep.parquet").unlink()
    bare = figures.fig_sweep(load_results(root), "param.schedule.beta")
    assert _band_limits(bare.axes[0]) == [] and _band_limits(bare.axes[1]) == []


def _with_misses(data: Any, misses_km: Sequence[float]) -> Any:
    """``data`` whose ok runs have the misses ``misses_km`` (cycled) and no stored statistics."""
    from dataclasses import replace

    runs = data.runs.copy()
    ok = runs["status"] == "ok"
    runs.loc[ok, "miss_km"] = np.resize(np.asarray(misses_km, dtype=float), int(ok.sum()))
    return replace(data, runs=runs, stats=None)


def test_sweep_figure_draws_misses_within_a_decade_on_a_linear_axis(sweep_dir: Path) -> None:
    """Medians 0.1 mm apart on a log axis sat between two ticks, unreadable."""
    from cwrend_cli.report import figures

    data = _with_misses(load_results(sweep_dir), [1.440e-4, 1.441e-4])  # 0.1440–0.1441 m
    ax_m = figures.fig_sweep(data, "param.schedule.beta").axes[0]
    assert ax_m.get_yscale() == "linear"
    assert ax_m.yaxis.get_major_formatter().get_offset() == ""  # 0.14405, not 1e-5+1.44e-1


def test_sweep_figure_draws_misses_over_more_than_a_decade_on_a_log_axis(
    sweep_dir: Path,
) -> None:
    from cwrend_cli.report import figures

    data = _with_misses(load_results(sweep_dir), [1e-5, 1e-3])  # 1 cm to 1 m
    assert figures.fig_sweep(data, "param.schedule.beta").axes[0].get_yscale() == "log"


def test_a_constrained_sweep_figure_draws_the_median_distance_to_the_unsafe_set(
    sweep_dir: Path,
) -> None:
    from dataclasses import replace

    from cwrend_cli.config import load_config
    from cwrend_cli.report import figures

    data = load_results(sweep_dir)
    runs = data.runs.copy()
    runs["safety_min_distance_km"] = np.where(runs["seed"] == 0, -0.002, 0.004)  # m: -2, 4
    safe = load_config(Path(__file__).resolve().parents[1] / "campaigns" / "safe_approach.toml")
    data = replace(data, runs=runs, config=safe, stats=None)
    fig = figures.fig_sweep(data, "param.schedule.beta")
    ax_s = fig.axes[2]
    assert "unsafe set" in ax_s.get_ylabel() and ax_s.get_ylabel().endswith("[m]")
    medians = {round(float(y), 9) for line in ax_s.get_lines() for y in line.get_ydata()}
    assert medians == {0.0, 1.0}  # the zero line and each point's median over seeds 0 and 1


def test_an_unconstrained_sweep_figure_has_no_safety_panel(sweep_dir: Path) -> None:
    from cwrend_cli.report import figures

    fig = figures.fig_sweep(load_results(sweep_dir), "param.schedule.beta")
    assert [ax.get_ylabel() for ax in fig.axes] == ["median terminal miss [m]", "mean Δv [km/s]"]


def test_point_picks_the_grid_point_of_figs_1_to_5(
    sweep_dir: Path, tmp_path: Path, unrendered: None
) -> None:
    root = _copy(sweep_dir, tmp_path / "pick")
    result = _report(root, "--point", "p_b")
    assert result.exit_code == 0, result.output
    md = (root / "report" / "report.md").read_text(encoding="utf-8")
    assert "at grid point `p_b`" in md and "(schedule.beta=0.5)" in md
    for wanted in ("beta=0.5", "schedule.beta=0.5", "0.5"):  # the swept values pick it too
        assert load_results(root, point=wanted).point == "p_b"
    data = load_results(root, point="p_b")
    assert set(data.steps["point"].astype(str)) == {"p_b"}


def test_a_point_asked_of_an_ablation_says_it_sweeps_nothing() -> None:
    """``cwrend report results/tour --point x`` (an ablation) said "no such grid point
    (points: base ())": the fix is to drop --point."""
    from cwrend_cli.report.load import ReportError, _chosen_point

    runs = pd.DataFrame({"point": ["base", "base"], "status": ["ok", "ok"], "seed": [0, 1]})
    with pytest.raises(ReportError, match=r"sweeps nothing \(one point, base\).*drop it"):
        _chosen_point(runs, "x")


def test_a_bad_point_exits_2_listing_the_points(sweep_dir: Path, run_dir: Path) -> None:
    result = _report(sweep_dir, "--point", "beta=0.3")
    assert result.exit_code == 2
    assert "--point beta=0.3: no such grid point" in result.output
    assert (
        "p_a (schedule.beta=0.25)" in result.output and "p_b (schedule.beta=0.5)" in result.output
    )
    run = _report(run_dir, "--point", "p_a")
    assert run.exit_code == 2 and "--point p_a" in run.output


def test_fig1_draws_the_references_over_the_runs(ablation_dir: Path) -> None:
    from cwrend_cli.report import figures

    fig = figures.fig_trajectories(load_results(ablation_dir))
    for ax in fig.axes[:2]:
        labels = [line.get_label() for line in ax.get_lines()]
        refs = [i for i, label in enumerate(labels) if label.startswith("open-loop")]
        assert [labels[i] for i in refs] == ["open-loop energy-optimal", "open-loop fuel-optimal"]
        assert refs == list(range(len(labels) - 2, len(labels)))  # drawn last
        assert all(ax.get_lines()[i].get_linewidth() == figures.REF_LW_FIG1 for i in refs)


def test_report_html_is_self_contained(ablation_report: Path) -> None:
    page = (ablation_report / "report" / "report.html").read_text(encoding="utf-8")
    pngs = list((ablation_report / "report").glob("*.png"))
    assert page.count('src="data:image/png;base64,') == len(pngs) == len(PER_SEED + MULTI_SEED) + 2
    assert re.findall(r'src="(?!data:)', page) == []  # nothing to fetch beside the file
    assert re.search(r"<th[^>]*>mean miss \[m\]</th>", page) and "]*</td>" in page  # the tables
    assert "<code>abc</code>" in page  # the config hash
    assert "beta = 0.25" in page  # the resolved config, as TOML


def test_report_html_aligns_text_columns_left_and_number_columns_right() -> None:
    table = (
        "| campaign | architecture | mean miss [m] (95 % CI) | Δv [km/s] |\n"
        "|---|---|---|---|\n"
        "| cw | mtf_fixed | 7.60 [7.1, 8.2] | – |\n"
        "| ss | plain_adaptive | -0.02 [-0.1, 0.1] | **0.1130** |\n"
    )
    page = report_html(table, {}, None, "abc", title="t", made="now", version="0")
    header = re.findall(r"<th([^>]*)>", page)
    assert header == ["", "", ' class="num"', ' class="num"']
    assert "<td>plain_adaptive</td>" in page  # a text column after the first, left
    assert '<td class="num">-0.02 [-0.1, 0.1]</td>' in page
    assert '<td class="num">–</td>' in page  # a missing value sits with its numbers


def test_report_html_says_what_it_is_when_and_by_which_cwrend(ablation_report: Path) -> None:
    from cwrend_cli import __version__

    page = (ablation_report / "report" / "report.html").read_text(encoding="utf-8")
    assert "<title>cwrend report · ablation</title>" in page
    assert "<h1>cwrend report · ablation</h1>" in page
    made = re.search(r"Made (\d{4}-\d\d-\d\d \d\d:\d\d UTC) by cwrend (\S+);", page)
    assert made is not None and made.group(2) == __version__
    assert "config hash <code>abc</code>" in page


def test_report_html_has_a_table_of_contents_of_its_sections(ablation_report: Path) -> None:
    page = (ablation_report / "report" / "report.html").read_text(encoding="utf-8")
    nav = page[page.index("<nav>") : page.index("</nav>")]
    sections = re.findall(r'<h([23]) id="([^"]+)">', page)
    assert len(sections) > 5 and page.index("</nav>") < page.index("<h2")
    for _, anchor in sections:
        assert f'href="#{anchor}"' in nav
    assert [a for _, a in sections][-1] == "configuration"


def test_report_html_configuration_is_toml_that_loads_back(ablation_report: Path) -> None:
    import html
    import tomllib

    page = (ablation_report / "report" / "report.html").read_text(encoding="utf-8")
    toml = html.unescape(page.split("<pre>")[-1].split("</pre>")[0])
    assert tomllib.loads(toml)["schedule"]["beta"] == 0.25


def test_report_gives_the_campaign_statistics_before_one_seeds_rows(ablation_dir: Path) -> None:
    md = report_md(load_results(ablation_dir), ablation_dir, [])
    assert md.index("## Over 3 noise seeds") < md.index("## Noise seed 0")
    assert md.index("### Paired comparisons") < md.index("## Noise seed 0")


# ---------------------------------------------------------------------------
# Filter consistency (NEES) and the simulated world (issue 15, item 6)
# ---------------------------------------------------------------------------


def test_nees_figure_draws_median_over_seeds_and_the_chi2_band(ablation_dir: Path) -> None:
    """Median line = the median over the seeds of the stored NEES; band = χ²₆'s 95 % interval."""
    from scipy.stats import chi2

    from cwrend_cli.report import figures

    fig = figures.fig_nees(load_results(ablation_dir))
    ax = fig.axes[0]
    assert ax.get_yscale() == "log"
    (band,) = [p for p in ax.patches if p.get_gid() == figures.NEES_BAND_GID]
    low, high = band.get_y(), band.get_y() + band.get_height()
    assert (low, high) == pytest.approx((chi2.ppf(0.025, 6), chi2.ppf(0.975, 6)), rel=1e-12)
    steps = pd.read_parquet(ablation_dir / "steps", filters=[("arch", "==", "mtf_adaptive")])
    median = steps.groupby("t_s")["nees"].median()
    median = median[median > 0]
    lines = [line for line in ax.get_lines() if len(line.get_xdata()) > 2]
    match = [
        line
        for line in lines
        if np.array_equal(line.get_xdata(), median.index)
        and np.allclose(line.get_ydata(), median.to_numpy(), rtol=1e-12, atol=0)
    ]
    assert match  # one of the drawn median curves is mtf_adaptive's (or its identical twin)


def test_nees_figure_is_absent_without_stored_nees(ablation_dir: Path, tmp_path: Path) -> None:
    from cwrend_cli.report import figures

    root = _copy(ablation_dir, tmp_path / "old")
    for path in (root / "steps").rglob("*.parquet"):
        table = pq.read_table(path, partitioning=None)
        pq.write_table(table.drop_columns(["nees"]), path)
    data = load_results(root)
    assert data.nees is None
    planned = [f.file for f in figures.planned_figures(data)]
    assert NEES not in planned and CONSISTENCY not in planned


def _stored_steps(root: Path, arch: str) -> pd.DataFrame:
    """The stored steps of ``arch`` after the first time (row 0: the initial error)."""
    steps = pd.read_parquet(root / "steps", filters=[("arch", "==", arch)])
    return steps[steps["t_s"] > steps["t_s"].min()]


def test_consistency_figure_draws_the_ensemble_means_and_their_chi2_bands(
    ablation_dir: Path,
) -> None:
    """NEES panel then NIS panel, log y: one curve is the mean over the seeds of mtf_adaptive's
    stored values at each step (NIS: of the seeds with a measurement), the band is
    χ²(N n)/N's 95 % quantiles (scipy.stats.chi2 here) for the N seeds."""
    from scipy.stats import chi2

    from cwrend_cli.report import figures

    fig = figures.fig_consistency(load_results(ablation_dir))
    steps = _stored_steps(ablation_dir, "mtf_adaptive")
    n_seeds = steps["seed"].nunique()
    assert n_seeds == 3
    for ax, column, dof in zip(fig.axes, ("nees", "nis"), (6, 3), strict=True):
        assert ax.get_yscale() == "log"
        mean = steps.groupby("t_s")[column].mean().dropna()
        assert any(
            np.array_equal(line.get_xdata(), mean.index)
            and np.allclose(line.get_ydata(), mean.to_numpy(), rtol=1e-12, atol=0)
            for line in ax.get_lines()
        ), column
        (band,) = [c for c in ax.collections if c.get_gid() == figures.ENSEMBLE_BAND_GID]
        y = band.get_paths()[0].vertices[:, 1]
        if column == "nees":  # every seed has a NEES at every step: one band throughout
            expected = chi2.ppf([0.025, 0.975], dof * n_seeds) / n_seeds
            assert (y.min(), y.max()) == pytest.approx(tuple(expected), rel=1e-12)


def _consistency_row(md: str, arch: str) -> dict[str, str]:
    """The cells of ``arch`` in the consistency table by header; ``in band`` follows its mean."""
    section = md.split("## Filter consistency")[1].split("\n## ")[0]
    header = next(ln for ln in section.splitlines() if ln.startswith("| architecture |"))
    columns = [c.strip() for c in header.strip("|").split("|")]
    columns = [f"{columns[i - 1]} in band" if c == "in band" else c for i, c in enumerate(columns)]
    return dict(zip(columns, _row(section, arch), strict=True))


def test_report_md_gives_the_consistency_table_against_the_bands(ablation_dir: Path) -> None:
    """The campaign mean of each run's mean NEES / NIS as stored in ablation.parquet (the
    consistency rows), its χ² band for the 3 runs, the verdict, and the share of the steps
    whose ensemble mean is in its band (NIS: outside the degradation windows)."""
    from scipy.stats import chi2

    md = report_md(load_results(ablation_dir), ablation_dir, [])
    assert "## Filter consistency" in md and "over the 3 seed(s)" in md
    runs = pd.read_parquet(ablation_dir / "runs.parquet").query("status == 'ok'")
    stats = pd.read_parquet(ablation_dir / "ablation.parquet").query("kind == 'consistency'")
    assert set(stats["metric"]) == {"mean_nees", "mean_nis_nominal"} and set(stats["n"]) == {3}
    mine = runs[runs["arch"] == "mtf_adaptive"]
    cells = _consistency_row(md, "MTF KF, adaptive ε")
    steps = _stored_steps(ablation_dir, "mtf_adaptive")
    nominal = steps.groupby("t_s")["degradation_window"].max() < 0
    for metric, column, name, dof in (("mean_nees", "nees", "NEES", 6),
                                      ("mean_nis_nominal", "nis", "NIS", 3)):  # fmt: skip
        low, high = chi2.ppf([0.025, 0.975], dof * 3) / 3
        mean = mine[metric].mean()
        assert (
            cells[f"mean {name} [95 % χ² band]"]
            == f"{consistency_text(mean)} [{low:.2f}, {high:.2f}]"
        )
        verdict = "yes" if low <= mean <= high else "no"
        assert cells[f"mean {name} [95 % χ² band] in band"] == verdict
        per_step = steps.groupby("t_s")[column].agg(["mean", "count"]).dropna()
        if column == "nis":
            per_step = per_step[nominal.reindex(per_step.index).to_numpy()]
        lo = chi2.ppf(0.025, dof * per_step["count"]) / per_step["count"]
        hi = chi2.ppf(0.975, dof * per_step["count"]) / per_step["count"]
        inside = ((per_step["mean"] >= lo) & (per_step["mean"] <= hi)).mean()
        assert cells[f"steps in {name} band [%]"] == f"{100 * inside:.1f}"


def test_report_says_over_how_many_seeds_the_steps_are(ablation_dir: Path, tmp_path: Path) -> None:
    """Steps stored for 2 of the 3 seeds (as ``output.steps_seeds = 2`` writes them)."""
    root = _copy(ablation_dir, tmp_path / "fewer")
    for path in (root / "steps").rglob("*.parquet"):
        table = pq.read_table(path, partitioning=None)
        pq.write_table(table.filter(pc.less(table["seed"], 2)), path)
    data = load_results(root)
    md = report_md(data, root, [])
    assert "over the 2 seed(s) whose steps are stored (`output.steps_seeds`)" in md
    assert "the means over all 3" in md
    assert _consistency_row(md, "MTF KF, adaptive ε")["runs"] == "3"


def test_report_of_a_campaign_writes_the_consistency_figure(ablation_report: Path) -> None:
    _check_png(ablation_report / "report" / CONSISTENCY)
    md = (ablation_report / "report" / "report.md").read_text(encoding="utf-8")
    assert f"]({CONSISTENCY})" in md and "## Filter consistency" in md


def test_every_figure_names_the_simulated_world(ablation_dir: Path) -> None:
    """Title and caption of each figure name the truth model, actuator errors and faults."""
    import dataclasses

    from cwrend_cli.report import figures

    data = load_results(ablation_dir)
    assert data.world == "truth: cw (the design model)"
    cfg = config_from_dict(
        apply(
            resolved_dict(CwrendConfig()),
            (
                ("truth.model", "j2"),
                ("actuator.magnitude_sigma", 0.01),
                ("degradation.windows.0.dropout_probability", 0.5),
            ),
        )
    )
    mismatched = dataclasses.replace(data, config=cfg)
    world = "truth: j2 · actuator errors on · sensor faults on"
    assert mismatched.world == world
    planned = figures.planned_figures(mismatched)
    assert {*PER_SEED, *MULTI_SEED, NEES, CONSISTENCY} == {f.file for f in planned}
    for f in planned:
        assert f.caption.endswith(f"Simulated world: {world}."), f.file
        assert world in f.draw().get_suptitle(), f.file


def test_every_figure_names_its_world_under_its_title(ablation_dir: Path) -> None:
    """Fig. 6 and the distributions (one titled axes each) had the world above their
    title; every figure has it on the line under its title."""
    from cwrend_cli.report import figures

    data = load_results(ablation_dir)
    for f in figures.planned_figures(data):
        fig = f.draw()
        *title, world = fig.get_suptitle().split("\n")
        assert world == data.world and title, f.file
        assert not any(ax.get_title() in title for ax in fig.axes), f.file  # not twice


@pytest.fixture(scope="module")
def truth_sweep_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2-seed sweep over ``truth.model`` (base: CW), as ``--param truth.model=cw,two_body``."""
    root = tmp_path_factory.mktemp("truth_sweep")
    points = [("p_cw", {"truth.model": "cw"}), ("p_2b", {"truth.model": "two_body"})]
    return _write_campaign(root, points, seeds=(0, 1), with_refs=True)


@pytest.mark.parametrize(
    ("point", "world"), [("p_cw", "truth: cw (the design model)"), ("p_2b", "truth: two_body")]
)
def test_figures_of_a_point_name_its_world(truth_sweep_dir: Path, point: str, world: str) -> None:
    """Issue 37: the reported point's figures name its truth model, not the base config's."""
    from cwrend_cli.report import figures

    data = load_results(truth_sweep_dir, point=point)
    assert data.world == world
    per_point = [f for f in figures.planned_figures(data) if not f.file.startswith("sweep_")]
    assert {*PER_SEED, *MULTI_SEED} <= {f.file for f in per_point}
    for f in per_point:
        assert f.caption.endswith(f"Simulated world: {world}."), f.file
        assert f.draw().get_suptitle().split("\n")[-1] == world, f.file


def test_thrust_limit_is_the_reported_points(tmp_path: Path) -> None:
    """Issue 37: what the per-seed figures draw from the configuration is the point's (fig. 2's
    thrust limit), not the base config's 8e-4 km/s²."""
    points = [("p_lo", {"scenario.u_max_km_s2": 6e-4}), ("p_hi", {"scenario.u_max_km_s2": 1e-3})]
    root = _write_campaign(tmp_path, points, seeds=(0,), with_refs=False, with_stats=False)
    assert load_results(root, point="p_lo").u_max_km_s2 == 6e-4
    assert load_results(root, point="p_hi").u_max_km_s2 == 1e-3


@pytest.mark.parametrize(("given", "offset"), [(False, 2.0), (True, 3.0)])
def test_the_nis_offset_of_a_point_of_a_sensor_sweep_is_the_one_its_runs_used(
    tmp_path: Path, given: bool, offset: float
) -> None:
    """Fig. 4's dotted offset at a point that sets ``sensor.model`` = angles (base: position):
    the angles' m = 2 (paper Eq. 24) when the base did not give the offset (its manifest says
    so; the stored config is resolved, its 3 looks given), the base's 3 when it did."""
    points = [("p_ang", {"sensor.model": "angles"})]  # --param sensor.model=angles
    root = _write_campaign(tmp_path, points, seeds=(0,), with_refs=False, with_stats=False)
    _set_manifest(root, nis_offset_given=given)
    assert load_results(root).nis_offset == offset


def test_figure_of_every_point_names_every_world(truth_sweep_dir: Path) -> None:
    """Issue 37: a figure over the grid names the world of each point it shows."""
    from cwrend_cli.report import figures

    data = load_results(truth_sweep_dir)
    (sweep,) = [f for f in figures.planned_figures(data) if f.file.startswith("sweep_")]
    worlds = "one per point: truth: cw (the design model); truth: two_body"
    assert sweep.caption.endswith(f"Simulated world: {worlds}."), sweep.caption
    assert sweep.draw().get_suptitle().split("\n")[-1] == worlds


def test_compare_names_the_worlds_of_a_sweeps_points_not_its_base(truth_sweep_dir: Path) -> None:
    """``cwrend compare``'s world of a sweep over ``truth.model`` (base: CW) is its points'
    (as the report's figures over every point name them), not the base configuration's."""
    from cwrend_cli.report.load import results_world

    worlds = "one per point: truth: cw (the design model); truth: two_body"
    assert results_world(truth_sweep_dir) == worlds


def test_the_world_of_a_campaign_is_read_from_three_columns_of_its_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``results_world`` (``cwrend compare``'s figure) reads ``status``, ``point`` and the swept
    values of runs.parquet, not every column of every run."""
    from cwrend_cli.report import load

    (tmp_path / "manifest.json").write_text(json.dumps({"config": resolved_dict(CwrendConfig())}))
    runs = pd.DataFrame(
        {
            "run_key": ["p_cw.mtf_adaptive.s000000", "p_2b.mtf_adaptive.s000000"],
            "point": ["p_cw", "p_2b"],
            "arch": ["mtf_adaptive"] * 2,
            "status": ["ok"] * 2,
            "error": ["", ""],
            "miss_km": [0.001, 0.002],
            "param.truth.model": ["cw", "two_body"],
        }
    )
    runs.to_parquet(tmp_path / "runs.parquet")
    read: list[Any] = []
    real = load._read_parquet

    def spy(path: Path, **kwargs: Any) -> pd.DataFrame:
        read.append(kwargs.get("columns"))
        return real(path, **kwargs)

    monkeypatch.setattr(load, "_read_parquet", spy)
    worlds = "one per point: truth: cw (the design model); truth: two_body"
    assert load.results_world(tmp_path) == worlds
    assert read == [["point", "status", "param.truth.model"]]


# ---------------------------------------------------------------------------
# Sampled designs and their sensitivity (issue 19, item 4)
# ---------------------------------------------------------------------------

#: Sobol indices of a hand-made sensitivity.parquet: (metric, parameter, statistic) → value.
SOBOL = {
    ("miss_km", "schedule.beta", "S1"): 0.62,
    ("miss_km", "schedule.beta", "ST"): 0.71,
    ("miss_km", "schedule.kappa_mtf", "S1"): 0.18,
    ("miss_km", "schedule.kappa_mtf", "ST"): 0.30,
    ("delta_v_km_s", "schedule.beta", "S1"): 0.05,
    ("delta_v_km_s", "schedule.beta", "ST"): 0.08,
    ("delta_v_km_s", "schedule.kappa_mtf", "S1"): 0.85,
    ("delta_v_km_s", "schedule.kappa_mtf", "ST"): 0.93,
}
SOBOL_HALF_WIDTH = 0.11


def _sensitivity_rows(arch: str = "mtf_adaptive") -> pd.DataFrame:
    """Rows of sensitivity.parquet as campaign/design.py::sensitivity writes them."""
    return pd.DataFrame(
        [
            {"arch": arch, "metric": m, "parameter": p, "statistic": s, "value": v,
             "ci_low": v - SOBOL_HALF_WIDTH, "ci_high": v + SOBOL_HALF_WIDTH, "n_seeds": 2}
            for (m, p, s), v in SOBOL.items()
        ]
    )  # fmt: skip


def _set_manifest(root: Path, **fields: Any) -> None:
    manifest = json.loads((root / "manifest.json").read_text(encoding="utf-8"))
    (root / "manifest.json").write_text(json.dumps({**manifest, **fields}), encoding="utf-8")


@pytest.fixture(scope="module")
def design_dir(sweep_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sweep campaign as a sobol design: sensitivity.parquet, a manifest with grid = {}."""
    root = _copy(sweep_dir, tmp_path_factory.mktemp("design") / "sobol")
    write_parquet(pa.Table.from_pandas(_sensitivity_rows(), preserve_index=False),
                  root / "sensitivity.parquet")  # fmt: skip
    _set_manifest(root, grid={})
    return root


def test_a_design_is_recognised_by_its_sensitivity_file(design_dir: Path, tmp_path: Path) -> None:
    root = _copy(design_dir, tmp_path / "no-grid-key")
    manifest = json.loads((root / "manifest.json").read_text(encoding="utf-8"))
    del manifest["grid"]
    (root / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    data = load_results(root)
    assert data.design and data.sensitivity is not None and len(data.sensitivity) == len(SOBOL)


def test_a_design_is_recognised_by_its_manifest_without_sensitivity(
    design_dir: Path, tmp_path: Path
) -> None:
    """An lhs/random design has no indices; its manifest records an empty grid."""
    from cwrend_cli.report import figures

    root = _copy(design_dir, tmp_path / "lhs")
    (root / "sensitivity.parquet").unlink()
    data = load_results(root)
    assert data.design and data.sensitivity is None
    assert "sensitivity.png" not in [f.file for f in figures.planned_figures(data)]
    md = report_md(data, root, [])
    assert "## Sampled design" in md and "No sensitivity indices stored" in md


def test_a_grid_sweep_is_not_a_design(sweep_dir: Path, tmp_path: Path) -> None:
    assert not load_results(sweep_dir).design  # a manifest without grid says nothing
    root = _copy(sweep_dir, tmp_path / "grid")
    _set_manifest(root, grid={"schedule.beta": [0.25, 0.5]})
    assert not load_results(root).design


def test_a_design_gets_no_per_point_sweep_figures_or_table(design_dir: Path) -> None:
    from cwrend_cli.report import figures

    data = load_results(design_dir)
    files = [f.file for f in figures.planned_figures(data)]
    assert "sensitivity.png" in files
    assert not [f for f in files if f.startswith("sweep_")]
    assert [f for f in files if f.startswith("design_")] == ["design_schedule.beta.png"]
    md = report_md(data, design_dir, [])
    assert "## Sweep of" not in md and "## Sampled design" in md
    assert "2 design points over β [-]" in md


def test_sensitivity_figure_draws_s1_and_st_with_their_intervals(design_dir: Path) -> None:
    from cwrend_cli.report import figures

    fig = figures.fig_sensitivity(load_results(design_dir))
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in panels] == [
        "MTF KF, adaptive ε · terminal miss, 2 seeds per point",
        "MTF KF, adaptive ε · Δv, 2 seeds per point",
    ]
    labels = [t.get_text() for t in panels[0].get_yticklabels()]  # shared by the row
    assert labels == ["β [-]", "κ_MTF [-]"]
    for ax, metric in zip(panels, ("miss_km", "delta_v_km_s"), strict=True):
        bars = {c.get_label(): c for c in ax.containers if isinstance(c, BarContainer)}
        assert set(bars) == {"S1 (first-order)", "ST (total)"}
        for stat in ("S1", "ST"):
            container = bars[f"{stat} ({'first-order' if stat == 'S1' else 'total'})"]
            widths = [p.get_width() for p in container.patches]
            expected = [SOBOL[(metric, p, stat)] for p in ("schedule.beta", "schedule.kappa_mtf")]
            assert widths == pytest.approx(expected)
            (segments,) = container.errorbar.lines[2]  # the interval of each bar
            spans = [x for seg in segments.get_segments() for x in sorted(seg[:, 0])]
            assert spans == pytest.approx(
                [x for v in expected for x in (v - SOBOL_HALF_WIDTH, v + SOBOL_HALF_WIDTH)]
            )


def test_sensitivity_figure_is_registered_and_names_the_world(design_dir: Path) -> None:
    from cwrend_cli.report import figures

    assert "sensitivity.png" in [f.file for f in figures.FIGURES]
    data = load_results(design_dir)
    (planned,) = [f for f in figures.planned_figures(data) if f.file == "sensitivity.png"]
    assert planned.caption.endswith(f"Simulated world: {data.world}.")
    assert data.world in planned.draw().get_suptitle()


def test_sensitivity_table_in_report_md(design_dir: Path) -> None:
    md = report_md(load_results(design_dir), design_dir, [])
    header = "| architecture | parameter | S1 terminal miss | ST terminal miss | S1 Δv | ST Δv |"
    assert header in md
    cells = _row(md, "MTF KF, adaptive ε | κ_MTF [-]")
    assert cells[2:] == [
        f"{v:.2f} [{v - SOBOL_HALF_WIDTH:.2f}, {v + SOBOL_HALF_WIDTH:.2f}]"
        for v in (SOBOL[("miss_km", "schedule.kappa_mtf", s)] for s in ("S1", "ST"))
    ] + [
        f"{v:.2f} [{v - SOBOL_HALF_WIDTH:.2f}, {v + SOBOL_HALF_WIDTH:.2f}]"
        for v in (SOBOL[("delta_v_km_s", "schedule.kappa_mtf", s)] for s in ("S1", "ST"))
    ]


def test_report_of_a_design_writes_the_sensitivity_figure(
    design_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _rasterise_only(monkeypatch, "sensitivity.png")
    root = _copy(design_dir, tmp_path / "full")
    summary = write_report(root)
    _check_png(root / "report" / "sensitivity.png")
    page = (summary.out_dir / "report.html").read_text(encoding="utf-8")
    assert re.search(r"<th[^>]*>S1 terminal miss</th>", page) and "<td>κ_MTF [-]</td>" in page


# ---------------------------------------------------------------------------
# Issue 18 leftovers
# ---------------------------------------------------------------------------


def test_sweep_table_header_uses_symbols_with_units(sweep_dir: Path) -> None:
    md = report_md(load_results(sweep_dir), sweep_dir, [])
    sweep = md.split("## Sweep of")[1]
    assert "| β [-] | architecture | runs |" in sweep
    assert "| schedule.beta |" not in md


def test_campaign_table_carries_the_consistency_means(ablation_dir: Path) -> None:
    md = report_md(load_results(ablation_dir), ablation_dir, [])
    table = md.split("## Over 3 noise seeds")[1]
    header = next(ln for ln in table.splitlines() if ln.startswith("| architecture |"))
    columns = [c.strip() for c in header.strip("|").split("|")]
    runs = pd.read_parquet(ablation_dir / "runs.parquet").query("status == 'ok'")
    cells = _row(table, "MTF KF, adaptive ε")
    mine = runs[runs["arch"] == "mtf_adaptive"]
    means = (("mean_nees", "mean NEES [-] (6)"), ("mean_nis_nominal", "mean NIS [-] (3)"))
    for column, name in means:
        assert cells[columns.index(name)] == f"{mine[column].mean():.2f}"


def test_fig1_3d_panel_draws_the_references_over_the_runs(ablation_dir: Path) -> None:
    """mplot3d sorts artists by depth unless computed_zorder is off: the references would hide."""
    from cwrend_cli.report import figures

    ax3 = figures.fig_trajectories(load_results(ablation_dir)).axes[0]
    assert ax3.name == "3d" and ax3.computed_zorder is False
    refs = [ln for ln in ax3.get_lines() if ln.get_label().startswith("open-loop")]
    runs = [ln for ln in ax3.get_lines() if not ln.get_label().startswith("open-loop")]
    assert refs and runs
    assert min(ln.get_zorder() for ln in refs) > max(ln.get_zorder() for ln in runs)


def test_fig6_medians_are_hollow_over_the_runs(ablation_dir: Path) -> None:
    """A tight cluster (MTF-fixed: the same Δv every seed) stays visible inside its median."""
    from cwrend_cli.report import figures

    ax = figures.fig_dv_vs_miss(load_results(ablation_dir)).axes[0]
    medians = [c for c in ax.collections if str(c.get_gid()).startswith("median:")]
    runs = [c for c in ax.collections if str(c.get_gid()).startswith("runs:")]
    assert len(medians) == len(runs) == len(CAMPAIGN_ARCHS)
    for median in medians:
        assert median.get_facecolor().size == 0 or median.get_facecolor()[0][3] == 0.0
    lo, hi = ax.get_ylim()
    for coll in runs:  # no run drawn on the frame
        y = coll.get_offsets()[:, 1]
        assert lo < y.min() / 1.05 and y.max() * 1.05 < hi


def test_fig6_miss_axis_reads_plain_numbers(ablation_dir: Path) -> None:
    from cwrend_cli.report import figures

    ax = figures.fig_dv_vs_miss(load_results(ablation_dir)).axes[0]
    labels = [t.get_text() for t in ax.get_yticklabels(which="both")]
    assert any(labels)
    assert not [t for t in labels if "times" in t or "^" in t]  # no 2×10¹, no 10¹
    major, minor = ax.yaxis.get_major_formatter(), ax.yaxis.get_minor_formatter()
    assert major(10.0, 0) == "10" and major(0.1, 0) == "0.1"
    assert minor(20.0, 0) in ("20", "")  # labelled over 1–2.5 decades, else none


def _compare_frame() -> pd.DataFrame:
    rows = []
    for metric in ("miss_km", "delta_v_km_s"):
        for statistic, value in (("mean_diff", -0.001), ("median_diff", -0.002),
                                 ("frac_better", 0.7)):  # fmt: skip
            rows.append({"arch": "mtf_adaptive", "metric": metric, "statistic": statistic,
                         "value": value, "ci_low": value - 0.1, "ci_high": value + 0.1,
                         "n": 20})  # fmt: skip
    return pd.DataFrame(rows)


def test_compare_figure_names_the_truth_models(ablation_dir: Path, tmp_path: Path) -> None:
    from cwrend_cli.report import figures
    from cwrend_cli.report.load import results_world

    cw = results_world(ablation_dir)
    assert cw == "truth: cw (the design model)"
    other = _copy(ablation_dir, tmp_path / "j2")
    cfg = apply(resolved_dict(CwrendConfig()), (("truth.model", "j2"),))
    _set_manifest(other, config=cfg)
    j2 = results_world(other)
    assert j2 == "truth: j2"
    title = figures.fig_compare(_compare_frame(), "cw", "j2", (cw, j2)).get_suptitle()
    assert f"A: {cw}" in title and f"B: {j2}" in title
    same = figures.fig_compare(_compare_frame(), "a", "b", (cw, cw)).get_suptitle()
    assert f"A and B: {cw}" in same
    path = write_compare_figure(_compare_frame(), "cw", "j2", tmp_path / "compare.png",
                                dirs=(ablation_dir, other))  # fmt: skip
    _check_png(path)


def test_design_figure_shows_every_point_and_a_binned_mean_per_architecture(
    design_dir: Path,
) -> None:
    """Issue 19 item 4: a design figure per parameter, labelled by symbol, with bands."""
    from cwrend_cli.report import figures

    data = load_results(design_dir)
    fig = figures.fig_design(data, "param.schedule.beta")
    ax_m, ax_v = (ax for ax in fig.axes if ax.get_title())
    assert ax_m.get_xlabel() == ax_v.get_xlabel() == "β [-]"
    ok = data.runs[data.runs["status"] == "ok"]
    for ax, column, scale in ((ax_m, "miss_km", 1e3), (ax_v, "delta_v_km_s", 1.0)):
        dots = [c for c in ax.collections if isinstance(c, PathCollection)]
        drawn = sorted(float(v) for c in dots for v in np.asarray(c.get_offsets())[:, 1])
        means = ok.groupby(["arch", "point"], observed=True)[column].mean() * scale
        assert drawn == pytest.approx(sorted(np.maximum(means.to_numpy(), 1e-6)), rel=1e-12)
        assert len(ax.lines) == len(set(ok["arch"]))  # one binned mean per architecture


def test_design_figure_draws_misses_within_a_decade_on_a_linear_axis(design_dir: Path) -> None:
    """The sweep figure's rule (figures.spans_decades): a log axis only over a decade."""
    from cwrend_cli.report import figures

    data = _with_misses(load_results(design_dir), [1.440e-4, 1.441e-4])  # 0.1440–0.1441 m
    fig = figures.fig_design(data, "param.schedule.beta")
    ax_m = next(ax for ax in fig.axes if ax.get_title())
    assert ax_m.get_yscale() == "linear"
    assert ax_m.yaxis.get_major_formatter().get_offset() == ""


def test_design_figure_draws_misses_over_more_than_a_decade_on_a_log_axis(
    design_dir: Path,
) -> None:
    from cwrend_cli.report import figures

    data = _with_misses(load_results(design_dir), [1e-5, 1e-3])  # 1 cm to 1 m
    fig = figures.fig_design(data, "param.schedule.beta")
    assert next(ax for ax in fig.axes if ax.get_title()).get_yscale() == "log"


def test_the_cone_program_architectures_are_named_and_ordered_like_the_paper_four() -> None:
    from cwrend_cli.physics.params import arch_order
    from cwrend_cli.report.load import arch_label

    assert arch_label("mtf_adaptive_socp") == "MTF KF, adaptive ε, SOCP"
    assert arch_label("plain_fixed") == "plain KF, fixed ε"
    assert arch_label("not_an_arch") == "not_an_arch"
    present = ["mtf_adaptive_socp", "plain_fixed_socp", "mtf_adaptive", "plain_fixed"]
    assert arch_order(present) == (
        "plain_fixed",
        "mtf_adaptive",
        "plain_fixed_socp",
        "mtf_adaptive_socp",
    )


def test_the_paired_miss_figure_pairs_the_cone_program_architectures_too() -> None:
    from cwrend_cli.physics.params import ALL_ARCHITECTURES
    from cwrend_cli.report.figures import _pairs

    socp = [a for a in ALL_ARCHITECTURES if a.endswith("_socp")]
    assert _pairs(pd.DataFrame(columns=socp)) == [
        ("plain_adaptive_socp", "mtf_adaptive_socp"),
        ("plain_fixed_socp", "mtf_fixed_socp"),
        ("mtf_fixed_socp", "mtf_adaptive_socp"),
    ]
    # with both methods, the paper's three panels, as before
    assert _pairs(pd.DataFrame(columns=list(ALL_ARCHITECTURES))) == [
        ("plain_adaptive", "mtf_adaptive"),
        ("plain_fixed", "mtf_fixed"),
        ("mtf_fixed", "mtf_adaptive"),
    ]


def test_the_paired_miss_figure_pairs_the_single_factor_with_mtf() -> None:
    """A campaign of the single factor and MTF only (issue 35) gets its panels."""
    from cwrend_cli.report.figures import _pairs

    archs = ["stf_fixed", "stf_adaptive", "mtf_fixed", "mtf_adaptive"]
    assert _pairs(pd.DataFrame(columns=archs)) == [
        ("mtf_fixed", "mtf_adaptive"),
        ("stf_adaptive", "mtf_adaptive"),
        ("stf_fixed", "mtf_fixed"),
    ]


def test_fig4_names_the_ratio_it_plots() -> None:
    """The steps' ``mtf_ratio`` of an stf run is (λ − 1) tr(R)/tr(S) (docs/method.md,
    "The single-factor baseline"), not tr(S_MTF)/tr(S): Fig. 4 says which it plots."""
    from cwrend_cli.output.recording import inflation_ratio_names as names

    assert names(["mtf_fixed", "mtf_adaptive_socp"]) == ("MTF ratio", "tr(S_MTF)/tr(S)")
    assert names(["stf_adaptive"]) == ("single-factor ratio", "(λ − 1) tr(R)/tr(S)")
    name, definition = names(["stf_fixed", "mtf_fixed"])
    assert name == "inflation ratio"
    assert "tr(S_MTF)/tr(S)" in definition and "(λ − 1) tr(R)/tr(S)" in definition
