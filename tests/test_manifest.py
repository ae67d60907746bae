"""A damaged manifest.json: refused with its fix by every command, rebuilt from the journal.

Issue 36 item 10: a manifest that is not UTF-8, not JSON, ``null``, holds ``NaN``,
has fields of the wrong type or is nested 100,000 deep ended ``report``,
``compare`` and a resumed ``ablate`` in a traceback, and the only fix offered
was ``--force``, which discards the runs the intact journal still proves. Now
each command exits 2 naming the file, what is wrong and the fix, writes
nothing, and ``--repair-manifest`` rebuilds the manifest from the journal.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app

runner = CliRunner()

DAMAGED = {
    "not UTF-8": (b"\xff\xfe\x00garbage", "not UTF-8 text"),
    "null": (b"null", "not a JSON object (a manifest is a table; found null)"),
    "NaN": (b'{"root_seed": NaN}', "holds NaN, which is not JSON"),
    "a root seed of words": (b'{"root_seed": "zero"}', '"root_seed" is a string, not an integer'),
    "a config array": (b'{"root_seed": 0, "config": []}', '"config" is an array, not an object'),
    "nested 100,000 deep": (b"[" * 100_000 + b"]" * 100_000, "nested too deep"),
}


def _args(cfg: Path, *more: str) -> list[str]:
    return ["ablate", str(cfg), "-n", "1", "-a", "mtf_adaptive", "-w", "1", "-q", *more]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A finished one-run campaign: its config file and its directory."""
    root = tmp_path_factory.mktemp("manifest")
    cfg = root / "c.toml"
    cfg.write_text(f'[output]\ndir = "{root / "results"}"\nname = "c"\nrrd_seeds = 0\n')
    assert runner.invoke(app, _args(cfg)).exit_code == 0
    return cfg, root / "results" / "c"


def _damaged_copy(campaign: tuple[Path, Path], tmp_path: Path, content: bytes) -> tuple[Path, Path]:
    cfg, out = campaign
    copy = tmp_path / "results" / "c"
    shutil.copytree(out, copy)
    (copy / "manifest.json").write_bytes(content)
    cfg_copy = tmp_path / "c.toml"
    cfg_copy.write_text(cfg.read_text().replace(str(out.parent), str(copy.parent)))
    return cfg_copy, copy


def _listing(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes() if p.is_file() else b""
        for p in sorted(root.rglob("*"))
    }


@pytest.mark.parametrize("command", ["report", "compare", "table", "ablate"])
@pytest.mark.parametrize("case", list(DAMAGED))
def test_a_damaged_manifest_is_refused_naming_the_file_and_the_repair(
    campaign: tuple[Path, Path], tmp_path: Path, command: str, case: str
) -> None:
    content, problem = DAMAGED[case]
    cfg, out = _damaged_copy(campaign, tmp_path, content)
    before = _listing(tmp_path)
    args = {
        "report": ["report", str(out)],
        "compare": ["compare", str(out), str(out)],
        "table": ["table", str(out)],
        "ablate": _args(cfg),
    }[command]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert f"{out / 'manifest.json'}: damaged manifest (" in result.stderr.replace("\n", "")
    assert problem in result.stderr
    assert "--repair-manifest" in result.stderr
    assert "Traceback" not in result.output
    assert _listing(tmp_path) == before  # nothing written


def test_repair_manifest_rebuilds_it_from_the_journal_keeping_every_run(
    campaign: tuple[Path, Path], tmp_path: Path
) -> None:
    good = json.loads((campaign[1] / "manifest.json").read_text(encoding="utf-8"))
    cfg, out = _damaged_copy(campaign, tmp_path, b"null")
    result = runner.invoke(app, _args(cfg, "--repair-manifest"))
    assert result.exit_code == 0, result.output
    rebuilt = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    assert rebuilt["sessions"][-1]["runs_computed"] == 0  # the journal's run kept
    assert rebuilt["counts"] == {"ok": 1, "failed": 0, "runs": 1}
    same = ("campaign_hash", "grid", "seeds", "root_seed", "archs")  # the copy's output.dir differs
    assert {k: rebuilt[k] for k in same} == {k: good[k] for k in same}
    assert {**rebuilt["config"], "output": None} == {**good["config"], "output": None}
    assert runner.invoke(app, ["report", str(out)]).exit_code == 0


def test_repair_manifest_refuses_a_journal_of_another_campaign(
    campaign: tuple[Path, Path], tmp_path: Path
) -> None:
    cfg, out = _damaged_copy(campaign, tmp_path, b"null")
    result = runner.invoke(app, _args(cfg, "--repair-manifest", "--set", "schedule.beta=0.5"))
    assert result.exit_code == 2, result.output
    assert "has a damaged manifest.json but its journal holds runs of another" in result.stderr
    assert (out / "manifest.json").read_bytes() == b"null"  # nothing written
    assert os.path.exists(out / "events.jsonl")
