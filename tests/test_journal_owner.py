"""Journal lines prove their campaign and versions, or are never reused (issue 36 item 4).

Each line of ``events.jsonl`` carries its campaign's hash and a digest of the
versions that computed it (cwrend and the numerics). A resume reuses only the
lines that prove they are its own: lines without a campaign hash, of another
campaign (whatever the manifest says) or of other versions are set aside, said
on the console, and their runs computed again.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd
from typer.testing import CliRunner

from cwrend_cli.campaign import journal
from cwrend_cli.cli import app

runner = CliRunner()
TIMING = ("duration_s", "solve_mean_ms", "solve_max_ms", "wall_time_ms", "error")


def _config(tmp_path: Path, name: str) -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(f'[output]\ndir = "{tmp_path / "results"}"\nname = "{name}"\n')
    return path


def _ablate(cfg: Path, *extra: str) -> Any:
    args = ["ablate", str(cfg), "--seeds", "2", "--arch", "mtf_adaptive", "--workers", "1",
            "--no-rrd", *extra]  # fmt: skip
    return runner.invoke(app, args)


def _rewrite(path: Path, change: Any) -> None:
    """Rewrite every journal line with ``change(event)`` (a tampered or foreign journal)."""
    events = [change(e) or e for e in journal.read_events(path)]
    path.write_text("".join(json.dumps(e) + "\n" for e in events))


def _runs(out: Path) -> pd.DataFrame:
    runs = pd.read_parquet(out / "runs.parquet")
    return runs.drop(columns=[c for c in TIMING if c in runs.columns])


def test_every_journal_line_names_its_campaign_and_versions(tmp_path: Path) -> None:
    cfg = _config(tmp_path, "named")
    assert _ablate(cfg).exit_code == 0
    out = tmp_path / "results" / "named"
    manifest = json.loads((out / "manifest.json").read_text())
    events = journal.read_events(out / "events.jsonl")
    assert {e["campaign_hash"] for e in events} == {manifest["campaign_hash"]}
    assert {e["versions"] for e in events} == {journal.versions_digest()}
    assert len(journal.versions_digest()) == 16  # compact: the manifest lists the versions


def test_lines_without_a_campaign_hash_are_never_reused(tmp_path: Path) -> None:
    """Manifest deleted and the hashes stripped: a changed config computes every run again
    with its own values (it resumed '0 computed, 2 already done' with the old ones)."""
    cfg = _config(tmp_path, "stripped")
    assert _ablate(cfg).exit_code == 0
    out = tmp_path / "results" / "stripped"
    (out / "manifest.json").unlink()
    _rewrite(out / "events.jsonl", lambda e: e.pop("campaign_hash", None) and None)
    changed = _ablate(cfg, "--set", "schedule.beta=0.5")
    assert changed.exit_code == 0, changed.output
    assert "2 run(s) computed, 0 already done" in changed.stderr
    assert "journal: 2 run record(s) set aside (no campaign hash: 2)" in changed.stderr
    fresh = _config(tmp_path, "fresh")
    assert _ablate(fresh, "--set", "schedule.beta=0.5").exit_code == 0
    pd.testing.assert_frame_equal(_runs(out), _runs(tmp_path / "results" / "fresh"))
    steps = pd.read_parquet(out / "steps")
    assert len(steps) == 2 * 801  # the old runs' files are orphans, removed


def test_lines_of_another_campaign_are_not_reused_behind_its_manifest(tmp_path: Path) -> None:
    """The manifest replaced by the changed config's own: the old lines are set aside."""
    old = _config(tmp_path, "swapped")
    assert _ablate(old).exit_code == 0
    out = tmp_path / "results" / "swapped"
    other = _config(tmp_path, "other")
    assert _ablate(other, "--set", "schedule.beta=0.5", "--seeds", "1").exit_code == 0
    foreign = json.loads((tmp_path / "results" / "other" / "manifest.json").read_text())
    foreign["config"]["output"]["name"] = "swapped"
    (out / "manifest.json").write_text(json.dumps(foreign))
    changed = _ablate(old, "--set", "schedule.beta=0.5")
    assert changed.exit_code == 0, changed.output
    assert "2 run(s) computed, 0 already done" in changed.stderr
    assert "(another campaign: 2)" in changed.stderr


def test_lines_of_other_versions_are_not_reused_without_the_manifest(tmp_path: Path) -> None:
    """Manifest deleted, the journal written by another cwrend: computed again, one version
    in the campaign; with --allow-version-change the lines are reused, as asked."""
    cfg = _config(tmp_path, "versions")
    assert _ablate(cfg).exit_code == 0
    out = tmp_path / "results" / "versions"

    def older(event: dict[str, Any]) -> None:
        event.update(cwrend_version="0.0.1", versions="0123456789abcdef")

    (out / "manifest.json").unlink()
    _rewrite(out / "events.jsonl", older)
    kept = json.loads(json.dumps(journal.read_events(out / "events.jsonl")))
    resumed = _ablate(cfg)
    assert resumed.exit_code == 0, resumed.output
    assert "2 run(s) computed, 0 already done" in resumed.stderr
    assert "(other versions: 2)" in resumed.stderr
    state = journal.load_journal(
        out / "events.jsonl", owner=journal.JournalOwner(_hash(out), journal.versions_digest())
    )
    assert len(state.runs) == 2
    (out / "manifest.json").unlink()
    (out / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in kept))
    allowed = _ablate(cfg, "--allow-version-change")
    assert allowed.exit_code == 0, allowed.output
    assert "0 run(s) computed, 2 already done" in allowed.stderr


def _hash(out: Path) -> str:
    return str(json.loads((out / "manifest.json").read_text())["campaign_hash"])
