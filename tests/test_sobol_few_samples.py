"""A Sobol design too small for its indices says so (daily use).

``sweep --design sobol --samples 2`` printed S1 = −3.26 ± 3.36 (an index lies in
[0, 1]) with no word of warning. Below ``design.SOBOL_SAMPLES_ADVISED`` base points
the console now warns and names the fix; SALib itself sets no minimum.
"""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from cwrend_cli.campaign import design
from cwrend_cli.cli import app


def _sweep(tmp_path: Path, samples: int) -> list[str]:
    cfg = tmp_path / "sobol.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path}"\nrrd_seeds = 0\n'
                   '[sweep]\n"schedule.beta" = { low = 0.05, high = 1.0 }\n')  # fmt: skip
    return ["sweep", str(cfg), "--design", "sobol", "--samples", str(samples), "--seeds", "1",
            "--arch", "mtf_adaptive", "--workers", "1", "--no-rrd"]  # fmt: skip


def test_a_sobol_design_of_2_base_points_warns_and_names_the_fix(tmp_path: Path) -> None:
    result = CliRunner().invoke(app, _sweep(tmp_path, 2))
    assert result.exit_code == 0, result.output
    assert "warning: Sobol indices from 2 base points are unreliable;" in result.stderr
    assert "rerun with --samples 64 or more in this directory" in result.stderr


def test_a_sobol_design_of_the_advised_size_does_not_warn() -> None:
    assert design.sensitivity_note("sobol", design.SOBOL_SAMPLES_ADVISED, 0) is None
    assert design.sensitivity_note("sobol", design.SOBOL_SAMPLES_ADVISED // 2, 0) is not None
