"""What a results directory says about how it was made, and where cwrend writes (issue 37).

Generated results are not tracked by git; ``cwrend run`` writes outside every
campaign directory; a campaign's lock is gone once it ends, and is safe
against the race of its removal; the manifest names every config hash the
campaign's files carry and each session's command line.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign import journal
from cwrend_cli.cli import app
from cwrend_cli.errors import ConfigError
from cwrend_cli.output.layout import LOCK

runner = CliRunner()
REPO = Path(__file__).resolve().parents[1]


def _write_config(path: Path, name: str, extra: str = "") -> Path:
    path.write_text(f'[output]\ndir = "{path.parent / "results"}"\nname = "{name}"\n{extra}')
    return path


def _ablate(cfg: Path, *args: str) -> Any:
    result = runner.invoke(
        app, ["ablate", str(cfg), "--arch", "mtf_adaptive", "--workers", "1", "-q", "--no-rrd",
              *args],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    return result


def _manifest(out: Path) -> dict[str, Any]:
    return dict(json.loads((out / "manifest.json").read_text(encoding="utf-8")))


# --- item 5: where results go -------------------------------------------------


def test_generated_results_are_not_tracked_by_git() -> None:
    """`cwrend report results/paper` must not rewrite files under version control."""
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("not a git checkout")
    listed = subprocess.run(
        ["git", "ls-files", "results"], cwd=REPO, capture_output=True, text=True, check=True
    ).stdout.split()
    assert listed == ["results/.gitkeep"]


def test_run_without_out_writes_into_its_own_directory_not_a_campaigns(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path / "paper.toml", "paper")
    result = runner.invoke(app, ["run", str(cfg), "--arch", "mtf_adaptive", "--no-rrd", "-q"])
    assert result.exit_code == 0, result.output
    results = tmp_path / "results"
    assert (results / "runs" / "paper-mtf_adaptive-seed0" / "summary.parquet").is_file()
    assert not (results / "paper").exists()  # the campaign's directory stays untouched


def test_run_refuses_a_default_directory_inside_a_campaign_named_runs(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path / "paper.toml", "paper")
    (tmp_path / "results" / "runs").mkdir(parents=True)
    (tmp_path / "results" / "runs" / "manifest.json").write_text("{}")
    result = runner.invoke(app, ["run", str(cfg), "--arch", "mtf_adaptive", "--no-rrd", "-q"])
    assert result.exit_code == 2, result.output
    assert "is a campaign directory" in result.stderr and "--out" in result.stderr
    assert sorted(p.name for p in (tmp_path / "results" / "runs").iterdir()) == ["manifest.json"]


def test_run_help_names_its_default_directory() -> None:
    result = runner.invoke(app, ["run", "--help"], terminal_width=200)
    assert "<output.dir>/runs/<name>-<arch>-seed<N>" in " ".join(result.output.split())


def test_a_finished_campaign_leaves_no_lock_file(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path / "c.toml", "done")
    _ablate(cfg, "--seeds", "1")
    out = tmp_path / "results" / "done"
    assert (out / "runs.parquet").is_file()
    assert not (out / LOCK).exists()


def test_a_lock_taken_on_the_file_its_holder_just_removed_is_taken_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The classic race of removing a lock file: B opens the file, A removes it and lets go,
    B locks the removed file. B must then lock the file at the path, so that a third
    process C is refused (with a lock on the removed file, C would hold a second lock)."""
    holder_a = contextlib.ExitStack()
    holder_a.enter_context(journal.campaign_lock(tmp_path))
    real_flock = fcntl.flock
    released: list[bool] = []

    def flock_after_a_lets_go(fd: int, operation: int) -> None:
        if not released:  # B has opened the file; A removes it and releases it now
            released.append(True)
            holder_a.close()
            assert not (tmp_path / LOCK).exists()
        real_flock(fd, operation)

    monkeypatch.setattr(fcntl, "flock", flock_after_a_lets_go)
    with journal.campaign_lock(tmp_path):  # B
        monkeypatch.setattr(fcntl, "flock", real_flock)
        assert released
        assert f"pid {os.getpid()}" in (tmp_path / LOCK).read_text()
        refused = pytest.raises(ConfigError, match="in use by another cwrend process")
        with refused, journal.campaign_lock(tmp_path):  # C
            pass
    assert not (tmp_path / LOCK).exists()


def test_a_lock_file_left_by_a_killed_holder_is_taken_over(tmp_path: Path) -> None:
    (tmp_path / LOCK).write_text("pid 1, since 2026-01-01T00:00:00.000+00:00\n")
    with journal.campaign_lock(tmp_path):
        assert f"pid {os.getpid()}" in (tmp_path / LOCK).read_text()
    assert not (tmp_path / LOCK).exists()


# --- item 5: config hashes of a resumed campaign ----------------------------------


def _file_hashes(out: Path) -> set[str]:
    """The config hashes in the metadata of every Parquet file of a campaign directory."""
    hashes = set()
    for path in out.rglob("*.parquet"):
        meta = pq.read_schema(path).metadata or {}
        if b"config_hash" in meta:
            hashes.add(meta[b"config_hash"].decode())
    return hashes


def test_the_manifest_names_every_config_hash_the_campaigns_files_carry(tmp_path: Path) -> None:
    """A resume with another [output] (the config hash covers it, the campaign hash does not)
    leaves files of two config hashes; the manifest names both, and each session its own."""
    cfg = _write_config(tmp_path / "c.toml", "twice")
    out = tmp_path / "results" / "twice"
    _ablate(cfg, "--seeds", "1")
    _ablate(cfg, "--seeds", "2", "--set", "output.steps_seeds=1")
    manifest = _manifest(out)
    carried = _file_hashes(out)
    assert len(carried) == 2  # seed 0's steps under the first hash, seed 1's under the second
    assert set(manifest["config_hashes"]) == carried
    first, second = manifest["sessions"]
    assert [first["config_hash"], second["config_hash"]] == manifest["config_hashes"]
    assert second["config_hash"] == manifest["config_hash"]
    assert (first["output"]["steps_seeds"], second["output"]["steps_seeds"]) == (None, 1)


# --- item 10: the command line of each session ----------------------------------------


def test_each_session_records_its_command_line_quoted_as_a_shell_would(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    where = tmp_path / "with space"
    where.mkdir()
    cfg = _write_config(where / "c.toml", "argv")
    args = ["ablate", str(cfg), "--seeds", "1", "--arch", "mtf_adaptive", "--workers", "1",
            "-q", "--no-rrd", "--set", "schedule.beta=0.5"]  # fmt: skip
    argv = ["/usr/bin/cwrend", *args]
    monkeypatch.setattr(sys, "argv", argv)
    assert runner.invoke(app, args).exit_code == 0
    session = _manifest(where / "results" / "argv")["sessions"][-1]
    assert shlex.split(session["command_line"]) == argv
    assert "'" in session["command_line"]  # the path with a space is quoted
    assert session["cwd"] == os.getcwd()


def test_python_dash_m_is_recorded_as_run(monkeypatch: pytest.MonkeyPatch) -> None:
    from cwrend_cli.cli import command_line

    monkeypatch.setattr(sys, "argv", ["/x/cwrend_cli/__main__.py", "ablate", "c.toml"])
    assert command_line() == [sys.executable, "-m", "cwrend_cli", "ablate", "c.toml"]


# --- item 10: what differs between the two campaigns of cwrend compare -------------


def _campaign_dir(root: Path, name: str, *args: str) -> Path:
    cfg = _write_config(root / f"{name}.toml", name)
    _ablate(cfg, "--seeds", "2", *args)
    return root / "results" / name


@pytest.fixture(scope="module")
def beta_pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """β = 0.25 (A) and β = 0.5 (B), each with its own output.name and steps_seeds."""
    root = tmp_path_factory.mktemp("diff")
    a = _campaign_dir(root, "b025", "--set", "schedule.beta=0.25")
    b = _campaign_dir(root, "b05", "--set", "schedule.beta=0.5", "--set", "output.steps_seeds=0")
    return a, b


def test_config_diff_names_each_differing_key_with_both_values() -> None:
    from cwrend_cli.campaign import compare

    def campaign(config: dict[str, Any], grid: dict[str, Any]) -> compare.Campaign:
        manifest = {"root_seed": 0, "config": config, "grid": grid, "design": None}
        return compare.Campaign(Path("x"), manifest, pd.DataFrame())

    a = campaign(
        {"schedule": {"beta": 0.25, "eps_min": 0.01}, "output": {"name": "a"}, "sweep": {},
         "dispersions": {}},
        {},
    )  # fmt: skip
    b = campaign(
        {"schedule": {"beta": 0.5, "eps_min": 0.01}, "output": {"name": "b"}, "sweep": {},
         "dispersions": {"truth.eccentricity": {"std": 0.01}}},
        {"scenario.u_max_km_s2": [0.0006, 0.0008]},
    )  # fmt: skip
    assert compare.config_diff(a, b) == (
        compare.Difference("schedule.beta", 0.25, 0.5),
        compare.Difference("dispersions.truth.eccentricity.std", None, 0.01),
        compare.Difference("sweep.scenario.u_max_km_s2", None, [0.0006, 0.0008]),
    )
    assert compare.config_diff(a, a) == ()


def test_compare_says_what_differs_in_its_table_figure_and_file(
    beta_pair: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import cwrend_cli.report.write as write

    titles: list[str] = []
    real = write.fig_compare

    def spy(*args: Any) -> Any:
        fig = real(*args)
        titles.append(fig.get_suptitle())
        return fig

    monkeypatch.setattr(write, "fig_compare", spy)
    a, b = beta_pair
    result = runner.invoke(app, ["compare", str(a), str(b), "--out", str(tmp_path)],
                           env={"COLUMNS": "80"})  # fmt: skip
    assert result.exit_code == 0, result.output
    table = result.stdout.split("A − B")[0]  # printed before the comparison
    assert "A and B differ in" in table
    assert "schedule.beta" in table and "0.25" in table and "0.5" in table
    assert "output" not in table  # where results go is not what they are
    assert "A and B differ in schedule.beta: A 0.25, B 0.5" in titles[0]
    meta = pq.read_schema(tmp_path / "compare.parquet").metadata
    assert json.loads(meta[b"config_diff"]) == [{"key": "schedule.beta", "a": 0.25, "b": 0.5}]


# --- item 10: steps joined to their swept values ----------------------------------------


def test_points_parquet_joins_every_step_to_its_swept_values(tmp_path: Path) -> None:
    cfg = _write_config(tmp_path / "c.toml", "swept")
    result = runner.invoke(
        app, ["sweep", str(cfg), "--param", "schedule.beta=0.25,0.5", "--seeds", "1", "--arch",
              "mtf_adaptive", "--workers", "1", "-q", "--no-rrd"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    out = tmp_path / "results" / "swept"
    points = pd.read_parquet(out / "points.parquet")
    assert sorted(points["param.schedule.beta"]) == [0.25, 0.5]
    assert points["point"].is_unique
    steps = pd.read_parquet(out / "steps", columns=["run_key", "point", "step"])
    joined = steps.merge(points, on="point", how="left", validate="many_to_one")
    runs = pd.read_parquet(out / "runs.parquet", columns=["run_key", "param.schedule.beta"])
    by_run = dict(zip(runs["run_key"], runs["param.schedule.beta"], strict=True))
    assert joined["param.schedule.beta"].notna().all()
    assert (joined["param.schedule.beta"] == joined["run_key"].map(by_run)).all()
    unit = pq.read_schema(out / "points.parquet").field("param.schedule.beta").metadata[b"unit"]
    assert unit == b"-"


# --- the architectures of a campaign that a resume widens ----------------------------


def test_the_manifest_names_every_architecture_the_campaigns_runs_hold(tmp_path: Path) -> None:
    """A resume that adds an architecture keeps the earlier one's runs (the campaign hash does
    not cover the architectures): the manifest's ``archs`` names both, not only the last's."""
    cfg = _write_config(tmp_path / "c.toml", "widened")
    out = tmp_path / "results" / "widened"
    for arch in ("plain_fixed", "mtf_fixed"):
        result = runner.invoke(
            app, ["ablate", str(cfg), "--arch", arch, "--seeds", "1", "-w", "1", "-q", "--no-rrd"]
        )
        assert result.exit_code == 0, result.output
    held = pd.read_parquet(out / "runs.parquet")["arch"]
    assert _manifest(out)["archs"] == ["plain_fixed", "mtf_fixed"]
    assert set(held) == {"plain_fixed", "mtf_fixed"}


def test_the_manifest_names_every_seed_the_campaigns_runs_hold(tmp_path: Path) -> None:
    """A resume with fewer seeds keeps the runs of the others (the campaign hash does not
    cover the seeds): the manifest's ``seeds`` names every seed the files hold."""
    cfg = _write_config(tmp_path / "c.toml", "narrowed")
    out = tmp_path / "results" / "narrowed"
    for seeds in ("3", "2"):
        result = runner.invoke(
            app,
            ["ablate", str(cfg), "--arch", "plain_fixed", "--seeds", seeds, "-w", "1", "-q",
             "--no-rrd"],
        )  # fmt: skip
        assert result.exit_code == 0, result.output
    held = pd.read_parquet(out / "runs.parquet")["seed"]
    assert _manifest(out)["seeds"] == [0, 1, 2]
    assert set(held) == {0, 1, 2}
