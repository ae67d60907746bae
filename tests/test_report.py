"""`cwrend report`: figures and tables of run and campaign directories (issue 5, item 2)."""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from pathlib import Path

import matplotlib.image
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.cli import app
from cwrend_cli.config import ARCHITECTURES, CwrendConfig, apply, config_from_dict, resolved_dict
from cwrend_cli.config.adapt import windows_of
from cwrend_cli.output.files import write_parquet
from cwrend_cli.output.tables import references_table, steps_table, summary_row
from cwrend_cli.physics import simulation
from cwrend_cli.report import load_results, write_report

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
    assert "| case | Δv [km/s] | miss [km] |" in md
    for arch in ARCHITECTURES.values():
        assert f"| {arch.label} |" in md
    assert "| open-loop energy | 0.1502386 |" in md
    assert "| open-loop fuel | 0.1128 |" in md
    for name in PER_SEED:
        assert f"]({name})" in md


def test_report_is_rewritten_in_place(run_dir: Path, run_report) -> None:
    result = _report(run_dir, "--seed", "0")
    assert result.exit_code == 0, result.output
    names = sorted(p.name for p in (run_dir / "report").iterdir())
    assert names == sorted([*PER_SEED, "report.md"])  # no temp files left behind


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
    root: Path, points: Sequence[tuple[str, dict]], seeds: Sequence[int], with_refs: bool
) -> Path:
    """runs.parquet, steps/arch=<slug>/, manifest.json as the campaign layer writes them.

    With ``with_refs``, also references/<point>.parquet (the open-loop references of each point).
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
                row |= summary_row(run, refs.fuel.delta_v_km_s)
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
    return root


@pytest.fixture(scope="module")
def ablation_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("ablation")
    return _write_campaign(root, [("base", {})], seeds=(0, 1, 2), with_refs=True)


def test_report_of_a_multi_seed_campaign(ablation_dir: Path) -> None:
    result = _report(ablation_dir)
    assert result.exit_code == 0, result.output
    report_dir = ablation_dir / "report"
    for name in (*PER_SEED, *MULTI_SEED):
        _check_png(report_dir / name)
    md = (report_dir / "report.md").read_text(encoding="utf-8")
    assert "## Over 3 noise seeds" in md
    assert "| MTF KF, adaptive ε | 3 / 1 |" in md  # the failed run is counted
    assert "noise seed **0**" in md


def test_campaign_seed_selection(ablation_dir: Path) -> None:
    summary = write_report(ablation_dir, seed=2)
    assert summary.layout == "campaign" and summary.seed == 2
    assert "noise seed **2**" in (summary.out_dir / "report.md").read_text(encoding="utf-8")
    result = _report(ablation_dir, "--seed", "999999")  # exists, but failed: no steps
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


def test_report_of_a_sweep(sweep_dir: Path, no_physics: None) -> None:
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
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    args = ["sweep", str(PAPER), "-p", "schedule.beta=0.25,0.5", "-n", "2", "-w", "1", "-q",
            "-a", ",".join(CAMPAIGN_ARCHS), "--name", "c",
            "--set", f'output.dir="{tmp_path}"']  # fmt: skip
    result = runner.invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    root = tmp_path / "c"
    reported = campaign.point_id((("schedule.beta", 0.25),))
    other = campaign.point_id((("schedule.beta", 0.5),))
    assert {p.name for p in (root / "references").iterdir()} == {
        f"{reported}.parquet",
        f"{other}.parquet",
    }
    _refuse_references(monkeypatch)  # from here on, computing references fails
    summary = write_report(root)
    assert summary.point == reported
    assert not any("references" in note for note in summary.notes)
    md = (root / "report" / "report.md").read_text(encoding="utf-8")
    assert "| open-loop fuel | 0.1128 |" in md


def test_campaign_report_reads_the_reported_points_references(
    sweep_dir: Path, tmp_path: Path, no_physics: None
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
    ablation_dir: Path, tmp_path: Path, no_physics: None
) -> None:
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


def test_report_with_an_unusable_stored_config(ablation_dir: Path, tmp_path: Path) -> None:
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
