"""The campaign lock covers everything a command writes (issue 36 item 2).

Campaign A holds its directory from its first run until its statistics (and
anything else it writes) are written: a campaign B on the same directory, even
with ``--force``, is refused in between instead of having its own files
overwritten by A's statistics stamped with B's hash. The two campaigns are
synchronised by a state (A frozen just before it writes its statistics), not
by a time.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from hooked_cwrend import HANG_S, HOOKED, wait_stopped
from typer.testing import CliRunner

from cwrend_cli.campaign.journal import campaign_lock
from cwrend_cli.cli import app
from cwrend_cli.errors import ConfigError
from cwrend_cli.output.layout import LOCK

runner = CliRunner()
ARCHS = "mtf_adaptive,plain_adaptive"


def _before_its_statistics(
    tmp_path: Path, name: str, seeds: int
) -> tuple[subprocess.Popen[str], Path]:
    """Campaign A (and its config), an ablation of ARCHS in ``results/<name>``, frozen
    (SIGSTOP) once its runs are done and journaled, before it writes its statistics."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path / "results"}"\nname = "{name}"\n')
    args = ["ablate", str(cfg), "--seeds", str(seeds), "--arch", ARCHS, "--workers", "1",
            "--no-rrd", "-q"]  # fmt: skip
    a = subprocess.Popen(
        [sys.executable, str(HOOKED), "statistics", "1", "SIGSTOP", *args],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    wait_stopped(a)
    return a, cfg


def test_a_forced_campaign_cannot_write_between_anothers_runs_and_its_statistics(
    tmp_path: Path,
) -> None:
    out = tmp_path / "results" / "shared"
    a, cfg = _before_its_statistics(tmp_path, "shared", seeds=2)
    try:
        a_hash = json.loads((out / "manifest.json").read_text())["campaign_hash"]
        b = runner.invoke(
            app, ["ablate", str(cfg), "--seeds", "1", "--arch", ARCHS, "--workers", "1",
                  "--no-rrd", "--force", "--set", "schedule.beta=0.5", "-q"],
        )  # fmt: skip
        assert b.exit_code == 2, b.output
        assert "is in use by another cwrend process" in b.stderr
    finally:
        a.send_signal(signal.SIGCONT)
    _, stderr = a.communicate(timeout=HANG_S)
    assert a.returncode == 0, stderr
    assert json.loads((out / "manifest.json").read_text())["campaign_hash"] == a_hash
    stats = pq.read_schema(out / "ablation.parquet").metadata
    assert stats[b"campaign_hash"].decode() == a_hash
    assert len(pq.read_table(out / "runs.parquet")) == 4  # A's runs, none of B's


def test_a_report_is_refused_while_a_campaign_holds_the_directory(tmp_path: Path) -> None:
    out = tmp_path / "results" / "busy"
    a, _ = _before_its_statistics(tmp_path, "busy", seeds=1)
    try:
        report = runner.invoke(app, ["report", str(out)])
        assert report.exit_code == 2, report.output
        assert "is in use by another cwrend process" in report.stderr
        assert not (out / "report").exists()
    finally:
        a.send_signal(signal.SIGCONT)
        a.communicate(timeout=HANG_S)
    assert a.returncode == 0


def test_a_lock_that_cannot_be_opened_says_what_to_do(tmp_path: Path) -> None:
    """A campaign on a read-only share (``cwrend report`` writes report/ into it) said only
    "cannot open the campaign lock (Read-only file system)". A directory in the lock's place
    fails the same open, without privileges."""
    (tmp_path / LOCK).mkdir()
    with (
        pytest.raises(ConfigError, match="copy the directory to a writable place"),
        campaign_lock(tmp_path),
    ):
        pass
