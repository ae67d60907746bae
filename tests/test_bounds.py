"""Hostile input is refused at the boundary: exit 2, the culprit named, nothing written (issue 20).

Every case below used to crash with a traceback, exhaust memory or run for
minutes without a word. Each is fed to the command line in-process, in an
empty working directory, with the results root inside it; the test checks
exit code 2, the message, no traceback, that nothing was written, and a time
and memory bound (generous: 20 s and 200 MB of Python/NumPy allocations
measured by tracemalloc; the refusals take milliseconds and kilobytes).
"""

from __future__ import annotations

import os
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.errors import ConfigError
from cwrend_cli.output.files import check_output_dir

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
runner = CliRunner()


def _nested(depth: int, open_: str, close: str) -> str:
    return open_ * depth + close * depth


Setup = Callable[[Path], list[str]]

CASES: dict[str, tuple[Setup, str]] = {
    "a horizon of 1e9 steps": (
        lambda d: [
            "run",
            str(PAPER),
            "--no-rrd",
            "--set",
            "scenario.horizon_s=1e6",
            "--set",
            "scenario.dt_s=1e-3",
        ],
        "scenario.horizon_s = 1000000: gives 1000000000 steps",
    ),
    "a step of 1e-3 s": (
        lambda d: ["ablate", str(PAPER), "--set", "scenario.dt_s=1e-3"],
        "at most 100,000 steps per run",
    ),
    "a horizon of 1e7 s": (
        lambda d: ["sweep", str(PAPER), "--set", "scenario.horizon_s=1e7"],
        "scenario.horizon_s = 10000000: must be <= 1000000",
    ),
    "a billion seeds": (
        lambda d: ["ablate", str(PAPER), "--seeds", "1000000000"],
        "--seeds 1000000000: at most 5,000,000 seeds",
    ),
    "a seed of 2**63": (
        lambda d: ["ablate", str(PAPER), "--seed-list", f"0,{2**63}"],
        f"--seed-list: seed {2**63} is out of range",
    ),
    "a root seed of 2**63": (
        lambda d: ["ablate", str(PAPER), "--set", f"noise.seed={2**63}"],
        f"noise.seed = {2**63}: must be <= {2**63 - 1}",
    ),
    "a seed list of words": (
        lambda d: ["ablate", str(PAPER), "--seed-list", "1e9"],
        "comma-separated integers",
    ),
    "a range of a billion values": (
        lambda d: ["sweep", str(PAPER), "--param", "schedule.beta=0:1:1000000000"],
        "num must be between 1 and 10,000",
    ),
    "a range with a float count": (
        lambda d: ["sweep", str(PAPER), "--param", "schedule.beta=0:1:1e9"],
        "a range is 'start:stop:num'",
    ),
    "a grid of a million points": (
        lambda d: [
            "sweep",
            str(PAPER),
            "--param",
            "schedule.beta=0.01:1:1000",
            "--param",
            "schedule.kappa_mtf=1:20:1000",
        ],
        "1,000,000 grid points (more than 10,000); pass --yes-large",
    ),
    "a 2 MB [sweep] list": (
        lambda d: [
            "sweep",
            _write(d / "big.toml", '[sweep]\n"schedule.beta" = [' + "0.5," * 500_000 + "]\n"),
        ],
        "bytes; a configuration is at most 1,000,000",
    ),
    "deeply nested arrays": (
        lambda d: [
            "config",
            "validate",
            _write(d / "deep.toml", "x = " + _nested(5000, "[", "]") + "\n"),
        ],
        "nested more than 16 levels deep",
    ),
    "deeply nested inline tables": (
        lambda d: [
            "config",
            "validate",
            _write(d / "deep.toml", "x = " + "{a=" * 3000 + "1" + "}" * 3000 + "\n"),
        ],
        "nested more than 16 levels deep",
    ),
    "a NUL byte in output.dir": (
        lambda d: ["ablate", str(PAPER), "--set", 'output.dir="re\\u0000sults"'],
        "output.dir = ",
    ),
    "a NUL byte in noise.file": (
        lambda d: ["ablate", str(PAPER), "--set", 'noise.file="n\\u0000.csv"'],
        "must not contain a NUL character",
    ),
    "an output.dir that is a file": (
        lambda d: [
            "ablate",
            str(PAPER),
            "-a",
            "mtf_adaptive",
            "--set",
            f"output.dir={_write(d / 'afile', '')!r}",
        ],
        "afile/paper': cannot write results there (Not a directory)",
    ),
    "an output.dir under a file": (
        lambda d: [
            "ablate",
            str(PAPER),
            "-a",
            "mtf_adaptive",
            "--set",
            f"output.dir={_write(d / 'afile', '') + '/sub'!r}",
        ],
        "cannot write results there (Not a directory)",
    ),
    "an output.dir name too long": (
        lambda d: [
            "ablate",
            str(PAPER),
            "-a",
            "mtf_adaptive",
            "--set",
            f"output.dir={str(d / ('x' * 300))!r}",
        ],
        "cannot write results there (File name too long)",
    ),
    "cwrend run --out at a file": (
        lambda d: ["run", str(PAPER), "--no-rrd", "--out", _write(d / "afile", "")],
        "cannot write results there (File exists)",
    ),
    "a malformed noise file": (
        lambda d: [
            "ablate",
            str(PAPER),
            "-a",
            "mtf_adaptive",
            "--set",
            f"noise.file={_write(d / 'n.csv', 'n1,n2,n3' + chr(10) + '0,0,0')!r}",
        ],
        "has 1 rows, expected 800",
    ),
}


def _write(path: Path, text: str) -> str:
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("case", list(CASES))
def test_hostile_input_is_refused_at_the_boundary(
    case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    setup, message = CASES[case]
    monkeypatch.chdir(tmp_path)
    args = setup(tmp_path)
    if args[0] in ("ablate", "sweep") and not any("output.dir" in a for a in args):
        args += ["--set", f"output.dir={str(tmp_path / 'results')!r}"]
    before = set(os.listdir(tmp_path))
    tracemalloc.start()
    started = time.monotonic()
    try:
        result = runner.invoke(app, args)
        elapsed = time.monotonic() - started
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert result.exit_code == 2, result.output
    assert message in result.stderr, result.stderr
    assert "Traceback" not in result.output
    assert set(os.listdir(tmp_path)) == before  # nothing written, not even a results dir
    assert elapsed < 20.0 and peak < 200e6, (elapsed, peak)


def test_a_changed_noise_file_is_another_campaign(tmp_path: Path) -> None:
    """The same path with other content: refused, not mixed into the campaign (issue 20 item 2)."""
    noise = tmp_path / "noise.csv"
    rows = np.random.default_rng(0).standard_normal((800, 3))
    np.savetxt(noise, rows, delimiter=",", header="n1,n2,n3", comments="")
    args = ["ablate", str(PAPER), "-n", "1", "-a", "mtf_adaptive", "--workers", "1", "-q",
            "--no-rrd", "--set", f"output.dir={str(tmp_path / 'results')!r}",
            "--set", f"noise.file={str(noise)!r}"]  # fmt: skip
    assert runner.invoke(app, args).exit_code == 0
    assert runner.invoke(app, args).exit_code == 0  # unchanged: resumes, nothing to do
    rows[5, 1] += 1.0
    np.savetxt(noise, rows, delimiter=",", header="n1,n2,n3", comments="")
    changed = runner.invoke(app, args)
    assert changed.exit_code == 2
    assert "holds a campaign with a different configuration" in changed.stderr


def test_run_out_on_a_read_only_file_system_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``cwrend run --out`` on a read-only mount said "Permission denied" (os.access is false
    for both); the mount's read-only flag tells them apart. Mounting needs privileges, so
    the file system's answers are given here."""
    monkeypatch.setattr(os, "access", lambda *args, **kwargs: False)
    monkeypatch.setattr(os, "statvfs", lambda path: SimpleNamespace(f_flag=os.ST_RDONLY))
    with pytest.raises(ConfigError, match=r"cannot write results there \(Read-only file system\)"):
        check_output_dir(tmp_path / "x", "choose another --out")
