"""The first run after an install (issue 37, item 12).

A command whose kernels are not in numba's cache says so before it compiles
(``compiling kernels (first run only, about N s)…``), with the same check for
``cwrend run`` and the campaigns; with the cache warm it says nothing. The
kernels are compiled once per signature: no literal-argument specialisation,
and the closed loop of the CW truth with the ideal actuator does not compile
the nonlinear truth's or the actuator's kernels.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from rich.console import Console
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.cli import app
from cwrend_cli.config import ARCHITECTURES, config_from_dict
from cwrend_cli.console import RichProgress
from cwrend_cli.physics import compiled

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "campaigns" / "paper.toml"
NOTICE = "compiling kernels (first run only, about"

runner = CliRunner()


def test_an_empty_cache_announces_the_first_compile(tmp_path: Path) -> None:
    code = (
        "from cwrend_cli.physics import compiled; "
        "print(compiled.compiling_notice({'shooting'})); "
        "print(compiled.compiling_notice({'shooting', 'socp'}))"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}  # nothing compiled there yet
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout.splitlines()
    assert all(line.startswith(NOTICE) and line.endswith(" s)…") for line in out)
    assert not [f for f in tmp_path.rglob("*") if f.is_file()]  # asking compiles nothing


def test_compiled_kernels_announce_nothing() -> None:
    # one closed loop compiles (or loads) what the shooting architectures need
    campaign.run_case(config_from_dict({}), (ARCHITECTURES["mtf_adaptive"],), 0)
    assert compiled.compiling_notice({"shooting"}) is None


@pytest.mark.parametrize("arch", ["mtf_adaptive", "mtf_adaptive_socp"])
def test_a_campaign_prints_the_notice_before_its_runs(
    arch: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # every architecture, the cone-program ones too (a lookup among the paper's four alone
    # ended `ablate --arch all_socp` with a KeyError)
    monkeypatch.setattr(compiled, "compile_seconds", lambda methods: 24.0)
    out = f"output.dir={json.dumps(str(tmp_path))}"
    args = ["ablate", str(PAPER), "--arch", arch, "-w", "1", "--no-rrd", "--set", out]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "compiling kernels (first run only, about 25 s)…" in result.output


def test_the_notice_is_not_printed_when_nothing_is_left_to_compute() -> None:
    buf = io.StringIO()
    progress = RichProgress(Console(file=buf, width=80), "ablate p", notice="compiling…")
    progress.start(total=0, skipped=4)
    assert "compiling" not in buf.getvalue()
    progress.start(total=4, skipped=0)
    assert "compiling…" in buf.getvalue()


#: Compiles, in an empty cache, the kernels that called others with literal arguments
#: (the derivative orders of find_switches, want_hess of burn_integral), then prints
#: every signature their callees were compiled for.
_LITERALS = """
import numpy as np
from cwrend_cli.physics.guidance import _kernels as k, _switching_kernels as s
lam = np.array([1e-3, 2e-4, 0.0, 0.9, 0.4, 0.1])
ws = k.workspace()
k.find_switches(1e-3, lam, 0.0, 800.0, 0.0, 20, np.empty(64), np.empty(64), ws)
x, w = np.polynomial.legendre.leggauss(12)
s.burn_integral(1e-3, lam, 0.0, 30.0, 8e-4, x, w, np.zeros(6), np.zeros((6, 6)),
                np.empty((6, 3)), np.empty(6))
for f in (k._bracketed_root, k._g, k._primer, k.add_control_node):
    print(f.py_func.__name__, len(f.signatures), any("Literal" in str(t) for t in f.signatures))
"""


def test_no_kernel_is_compiled_once_per_literal_argument(tmp_path: Path) -> None:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run(
        [sys.executable, "-c", _LITERALS], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == [
        "_bracketed_root", "1", "False", "_g", "1", "False",
        "_primer", "1", "False", "add_control_node", "1", "False",
    ]  # fmt: skip


def test_the_paper_loop_passes_no_truth_or_actuator_model_to_compile() -> None:
    from cwrend_cli.physics import _loop_kernels

    campaign.run_case(config_from_dict({}), (ARCHITECTURES["plain_adaptive"],), 0)
    # arguments 4 and 5: the CW truth and the ideal actuator cross as None (pruned)
    paper = [(str(sig[4]), str(sig[5])) for sig in _loop_kernels._resolve_loop.signatures]
    assert ("none", "none") in paper
