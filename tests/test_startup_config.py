"""Start-up (issue 17): ``cwrend config validate`` loads no numpy nor Rich, the help no Rich.

A behaviour test, not a timing test (``python -m benchmarks.bench_startup``
measures the wall times): each command runs in a fresh interpreter and the
modules it loaded are read from ``sys.modules``. numpy (about 0.1 s) is
loaded by the commands that compute and by a covariance given as a full
matrix; Rich (about 20 ms) when a command prints through it (errors, tables).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
#: Run a command line in-process as ``cwrend`` does, then print the watched modules loaded.
SCRIPT = """
import json, sys
from cwrend_cli.__main__ import main
args, watched = json.loads(sys.argv[1]), set(json.loads(sys.argv[2]))
sys.argv = ["cwrend", *args]
try:
    main()
except SystemExit as exc:
    code = exc.code
loaded = sorted({m.split(".")[0] for m in sys.modules} & watched)
print(json.dumps({"code": code, "loaded": loaded}), file=sys.stderr)
"""


def _loaded(args: list[str], watched: tuple[str, ...]) -> dict[str, object]:
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, json.dumps(args), json.dumps(watched)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    result: dict[str, object] = json.loads(proc.stderr.strip().splitlines()[-1])
    return result


@pytest.mark.parametrize(
    "args",
    [
        ["config", "validate", str(PAPER)],
        ["config", "validate", str(PAPER), "--set", "schedule.beta=0.5"],
        ["config", "show", str(PAPER)],
        ["--help"],
        ["ablate", "--help"],
    ],
    ids=lambda a: " ".join(Path(x).name for x in a),
)
def test_command_loads_no_numpy_nor_rich(args: list[str]) -> None:
    assert _loaded(args, ("numpy", "rich")) == {"code": 0, "loaded": []}


def test_a_full_covariance_matrix_is_still_checked(tmp_path: Path) -> None:
    """The positive-definiteness check of a full matrix (numpy, loaded for it) still runs."""
    cfg = tmp_path / "full.toml"
    cfg.write_text(
        "[estimator]\nr_nominal_km2 = [[1e-6, 2e-6, 0], [2e-6, 1e-6, 0], [0, 0, 1e-6]]\n"
    )
    result = _loaded(["config", "validate", str(cfg)], ("numpy", "rich"))
    assert result == {"code": 2, "loaded": ["numpy", "rich"]}  # the error is printed by Rich
    proc = subprocess.run(
        [sys.executable, "-m", "cwrend_cli", "config", "validate", str(cfg)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2
    assert "estimator.r_nominal_km2" in proc.stderr and "positive definite" in proc.stderr


def test_the_array_alias_of_the_physics_parameters_is_numpy_s() -> None:
    """``physics.params.FloatArray`` is built on first use (the module imports no numpy)."""
    import numpy as np
    import numpy.typing as npt

    from cwrend_cli.physics import params

    assert params.FloatArray == npt.NDArray[np.float64]
    with pytest.raises(AttributeError):
        _ = params.NotAName  # type: ignore[attr-defined]
