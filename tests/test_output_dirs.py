"""A run's directory and a campaign's never mix: each refuses the other's, a run replaces a run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.output.files import check_campaign_dir, check_run_dir
from cwrend_cli.output.layout import (
    EVENTS,
    MANIFEST,
    RUN_CONFIG,
    RUN_FILES,
    RUN_RECORDING,
    RUN_SUMMARY,
)

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"

runner = CliRunner()


def _contents(path: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(path.iterdir())}


@pytest.mark.parametrize("marker", [MANIFEST, EVENTS])
def test_run_refuses_a_campaign_directory(marker: str, tmp_path: Path) -> None:
    tour = tmp_path / "tour"
    tour.mkdir()
    (tour / marker).write_text("{}\n")
    before = _contents(tour)
    result = runner.invoke(app, ["run", str(PAPER), "--no-rrd", "-q", "--out", str(tour)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert str(tour) in result.output
    assert "--out" in result.output
    assert "cwrend ablate" in result.output  # the campaign's own commands
    assert _contents(tour) == before  # nothing written


@pytest.mark.parametrize("force", [False, True])
@pytest.mark.parametrize("command", ["ablate", "sweep"])
def test_campaign_refuses_a_run_directory(command: str, force: bool, tmp_path: Path) -> None:
    run = tmp_path / "tour-run"
    run.mkdir()
    (run / RUN_CONFIG).write_text("{}\n")
    (run / RUN_SUMMARY).write_bytes(b"not parquet")
    before = _contents(run)
    args = [command, str(PAPER), "--name", "tour-run", "--seeds", "1", "--no-rrd", "-q"]
    args += ["--set", f"output.dir={json.dumps(str(tmp_path))}"]
    if command == "sweep":
        args += ["--param", "schedule.beta=0.1,0.25"]
    result = runner.invoke(app, [*args, *(["--force"] if force else [])])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert str(run) in result.output
    assert "--name" in result.output
    assert _contents(run) == before  # nothing written, not even the lock


def test_run_over_an_earlier_run_leaves_none_of_its_files(tmp_path: Path) -> None:
    out = tmp_path / "tour-run"
    out.mkdir()
    for name in RUN_FILES:  # an earlier run's files, a recording among them
        (out / name).write_bytes(b"earlier run")
    (out / "notes.txt").write_text("mine\n")  # not a run's: kept
    args = ["run", str(PAPER), "--arch", "plain_fixed", "--no-rrd", "-q", "--out", str(out)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert not (out / RUN_RECORDING).exists()
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted([*(n for n in RUN_FILES if n != RUN_RECORDING), "notes.txt"])
    assert all((out / n).read_bytes() != b"earlier run" for n in names if n != "notes.txt")
    assert (out / "notes.txt").read_text() == "mine\n"


def _tree(path: Path) -> dict[str, bytes | None]:
    """Every file (its bytes) and directory (None) below ``path``, by relative name."""
    return {
        str(p.relative_to(path)): (p.read_bytes() if p.is_file() else None)
        for p in sorted(path.rglob("*"))
    }


def _campaign(path: Path) -> Path:
    """A campaign's directory as ablate leaves it (its manifest, journal and a dataset)."""
    (path / "steps" / "arch=mtf_adaptive").mkdir(parents=True)
    (path / MANIFEST).write_text("{}\n")
    (path / EVENTS).write_text("{}\n")
    return path


@pytest.mark.parametrize("inner", ["sub", "steps/arch=mtf_adaptive/mine"])
def test_run_refuses_a_directory_inside_a_campaign_directory(inner: str, tmp_path: Path) -> None:
    tour = _campaign(tmp_path / "tour")
    before = _tree(tour)
    out = tour / inner
    result = runner.invoke(app, ["run", str(PAPER), "--no-rrd", "-q", "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert f"inside {tour.resolve()}" in result.output
    assert "--out" in result.output
    assert _tree(tour) == before  # nothing written


def test_run_by_default_refuses_an_output_dir_inside_a_campaign(tmp_path: Path) -> None:
    tour = _campaign(tmp_path / "tour")
    before = _tree(tour)
    args = ["run", str(PAPER), "--no-rrd", "-q", "--set", f"output.dir={json.dumps(str(tour))}"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert f"inside {tour.resolve()}" in result.output
    assert _tree(tour) == before


@pytest.mark.parametrize("command", ["ablate", "sweep"])
def test_campaign_refuses_a_directory_inside_a_run_directory(command: str, tmp_path: Path) -> None:
    run = tmp_path / "tour-run"
    run.mkdir()
    (run / RUN_CONFIG).write_text("{}\n")
    (run / RUN_SUMMARY).write_bytes(b"not parquet")
    before = _tree(run)
    args = [command, str(PAPER), "--name", "camp", "--seeds", "1", "--no-rrd", "-q"]
    args += ["--set", f"output.dir={json.dumps(str(run))}", "--force"]
    if command == "sweep":
        args += ["--param", "schedule.beta=0.1,0.25"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert f"inside {run.resolve()}" in result.output
    assert "--name" in result.output
    assert _tree(run) == before  # nothing written, not even the lock


def test_campaign_refuses_a_directory_inside_another_campaign(tmp_path: Path) -> None:
    tour = _campaign(tmp_path / "tour")
    before = _tree(tour)
    args = ["ablate", str(PAPER), "--name", "inner", "--seeds", "1", "--no-rrd", "-q"]
    args += ["--set", f"output.dir={json.dumps(str(tour))}"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert f"inside {tour.resolve()}" in result.output
    assert _tree(tour) == before


def test_a_project_config_or_manifest_above_is_neither_a_run_nor_a_campaign(
    tmp_path: Path,
) -> None:
    """A parent's config.json or manifest.json alone (a project's, a web app's) refuses nothing."""
    project = tmp_path / "project"
    project.mkdir()
    (project / RUN_CONFIG).write_text("{}\n")
    (project / MANIFEST).write_text("{}\n")
    check_campaign_dir(project / "results" / "paper")
    check_run_dir(project / "results" / "runs" / "paper-mtf_adaptive-seed0", "choose another --out")
