"""Start-up (issue 17): help and configuration commands load none of the heavy libraries.

Nor numpy and Rich for ``config validate/show`` and the help (numpy, about 0.1 s,
loads in the commands that compute and for a covariance given as a full
matrix; Rich, about 20 ms, when a command prints through it).

A behaviour test, not a timing test: each command runs in a fresh
interpreter and the modules it loaded are read from ``sys.modules``. The
wall times are measured by ``python -m benchmarks.bench_startup``.
"""

from __future__ import annotations

import functools
import json
import subprocess
import sys
from pathlib import Path

import pytest

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
#: What every command paid at start-up before issue 17 (about 1.5–4 s together).
HEAVY = ("numba", "pandas", "scipy", "matplotlib", "rerun", "pyarrow")
#: Run a command line in-process as ``cwrend`` does, then print the top-level modules loaded.
SCRIPT = """
import json, sys
from cwrend_cli.__main__ import main
sys.argv = ["cwrend", *json.loads(sys.argv[1])]
try:
    main()
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "loaded": sorted({m.split(".")[0] for m in sys.modules})}),
      file=sys.stderr)
"""


@functools.cache
def _run(args: tuple[str, ...]) -> tuple[object, frozenset[str]]:
    """Exit code and top-level modules of ``cwrend *args`` in a fresh interpreter, run once
    per command line for every test that asks (the tests below share several)."""
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, json.dumps(args)], capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    result = json.loads(proc.stderr.strip().splitlines()[-1])
    return result["code"], frozenset(result["loaded"])


def _loaded(args: list[str], watched: tuple[str, ...] = HEAVY) -> dict[str, object]:
    code, loaded = _run(tuple(args))
    return {"code": code, "heavy": sorted(loaded & set(watched))}


@pytest.mark.parametrize(
    "args",
    [
        ["--help"],
        ["--version"],
        ["ablate", "--help"],
        ["sweep", "--help"],
        ["run", "--help"],
        ["report", "--help"],
        ["compare", "--help"],
        ["config", "show", str(PAPER)],
        ["config", "show", str(PAPER), "--format", "json"],
        ["config", "validate", str(PAPER)],
    ],
    ids=lambda a: " ".join(Path(x).name for x in a),
)
def test_command_loads_no_heavy_library(args: list[str]) -> None:
    result = _loaded(args)
    assert result == {"code": 0, "heavy": []}


def test_invalid_config_is_reported_without_heavy_libraries(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[schedule]\nbeta = -1\n")
    assert _loaded(["config", "validate", str(bad)]) == {"code": 2, "heavy": []}


@pytest.mark.parametrize(
    "args",
    [
        ["ablate", str(PAPER), "--set", "schedule.beta=-1"],
        ["sweep", str(PAPER), "--set", "schedule.betta=0.5"],
        ["ablate", str(PAPER), "--arch", "mtf_adaptve"],
    ],
    ids=["ablate bad value", "sweep unknown key", "ablate unknown architecture"],
)
def test_a_campaign_input_error_exits_before_the_heavy_libraries(args: list[str]) -> None:
    # the config and the architectures are checked before the campaign package is imported
    assert _loaded(args) == {"code": 2, "heavy": []}


def test_a_nonlinear_truth_is_still_checked_against_the_earth(tmp_path: Path) -> None:
    """The perigee check, whose helpers live with the compiled truth model, still runs."""
    cfg = tmp_path / "low.toml"
    cfg.write_text('[truth]\nmodel = "two_body"\neccentricity = 0.9\n')
    proc = subprocess.run(
        [sys.executable, "-m", "cwrend_cli", "config", "validate", str(cfg)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2
    assert "truth.eccentricity" in proc.stderr and "Earth's radius" in proc.stderr


def test_a_campaign_command_still_finds_what_it_needs(tmp_path: Path) -> None:
    """The commands import their modules themselves: a one-seed ablation runs end to end."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path / "results"}"\nname = "c"\n')
    proc = subprocess.run(
        [sys.executable, "-m", "cwrend_cli", "ablate", str(cfg), "--arch", "mtf_adaptive",
         "--workers", "1", "--no-rrd"],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "1 run(s) computed" in proc.stderr


#: What a help text needs even less: numpy (0.1 s, the physics' architecture table) and
#: pydantic (0.08 s, Typer 0.29 coercing an unset --help flag), issue 17 item 4.
HELP_FREE = (*HEAVY, "numpy", "pydantic")


@pytest.mark.parametrize(
    "args",
    [
        ["--help"],
        ["ablate", "--help"],
        ["sweep", "--help"],
        ["run", "--help"],
        ["report", "--help"],
        ["compare", "--help"],
        ["config", "--help"],
        ["config", "validate", "--help"],
    ],
    ids=" ".join,
)
def test_help_loads_neither_numpy_nor_pydantic(args: list[str]) -> None:
    assert _loaded(args, HELP_FREE) == {"code": 0, "heavy": []}


def test_the_help_names_the_physics_architectures() -> None:
    """The help text's architecture names are written out in cli.py: they must be the physics'."""
    from cwrend_cli import cli
    from cwrend_cli.physics.params import ARCHITECTURES, SOCP_ARCHITECTURES, STF_ARCHITECTURES

    assert tuple(ARCHITECTURES) == cli.ARCH_SLUGS
    assert tuple(SOCP_ARCHITECTURES) == cli.SOCP_ARCH_SLUGS
    assert tuple(STF_ARCHITECTURES) == cli.STF_ARCH_SLUGS


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
    """``config validate/show`` and the help load no numpy nor Rich (numpy ~0.1 s, Rich ~20 ms:
    loaded by the commands that compute, by a full covariance matrix, and by Rich output)."""
    assert _loaded(args, ("numpy", "rich")) == {"code": 0, "heavy": []}


def test_a_full_covariance_matrix_is_still_checked(tmp_path: Path) -> None:
    """The positive-definiteness check of a full matrix (numpy, loaded for it) still runs."""
    cfg = tmp_path / "full.toml"
    cfg.write_text(
        "[estimator]\nr_nominal_km2 = [[1e-6, 2e-6, 0], [2e-6, 1e-6, 0], [0, 0, 1e-6]]\n"
    )
    result = _loaded(["config", "validate", str(cfg)], ("numpy", "rich"))
    assert result == {"code": 2, "heavy": ["numpy", "rich"]}  # the error is printed by Rich
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


def _printed(script: str) -> object:
    """What ``script``, run in a fresh interpreter, prints as JSON (it must exit 0)."""
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def test_a_campaign_worker_loads_neither_pandas_nor_the_driver() -> None:
    """A spawned worker imports ``cwrend_cli.campaign.worker`` (its task function's module):
    that must not bring pandas (~0.3 s) nor the driver, whose names the package imports on
    first use; the package's public names still resolve (``campaign.plan`` the function)."""
    script = (
        "import json, sys, cwrend_cli.campaign.worker\n"
        "loaded = ['pandas' in sys.modules, 'cwrend_cli.campaign.driver' in sys.modules]\n"
        "from cwrend_cli import campaign\n"
        "print(json.dumps([*loaded, callable(campaign.plan), campaign.run_campaign.__module__]))"
    )
    assert _printed(script) == [False, False, True, "cwrend_cli.campaign.driver"]


def test_the_campaign_console_loads_neither_figures_nor_rerun() -> None:
    """The campaign commands' console imports ``report.labels`` alone: not the figures,
    matplotlib and ``scipy.stats`` (about 1 s) the report package's names bring, nor
    rerun (the early ``RERUN=off`` check reads the environment); those names still
    resolve on first use and an unknown one is an ``AttributeError``."""
    script = (
        "import json, sys, cwrend_cli.console\n"
        "from cwrend_cli.output import recording\n"
        "recording.check_enabled()\n"
        "loaded = sorted(m for m in ('matplotlib', 'scipy.stats', 'rerun') if m in sys.modules)\n"
        "from cwrend_cli import report\n"
        "try:\n"
        "    report.no_such_name\n"
        "    unknown = 'resolved'\n"
        "except AttributeError:\n"
        "    unknown = 'AttributeError'\n"
        "print(json.dumps([loaded, report.write_report.__module__, unknown]))"
    )
    assert _printed(script) == [[], "cwrend_cli.report.write", "AttributeError"]


def test_validating_dispersions_loads_numpy_but_no_heavy_library() -> None:
    """``config validate`` of a config with ``[dispersions]`` draws seed 0 through the
    campaign's plan (numpy), not its workers: no numba, scipy or pandas (they took it from
    about 0.35 s to 1.2–1.4 s, over its 0.6 s target, on the 2-vCPU Xeon)."""
    dispersed = PAPER.with_name("sweep_beta_dispersed.toml")
    code, loaded = _run(("config", "validate", str(dispersed)))
    assert code == 0 and "numpy" in loaded and not loaded & set(HEAVY)


@pytest.mark.parametrize("sweep", ["grid", "design ranges"])
def test_validating_a_sweep_loads_numpy_but_no_heavy_library(tmp_path: Path, sweep: str) -> None:
    """``config validate`` checks ``[sweep]`` through the campaign's plan (numpy): each grid
    point, or a design's ranges (one point drawn by ``random``, not SciPy's Latin
    hypercube nor SALib); a config without ``[sweep]`` loads no numpy (above)."""
    if sweep == "grid":
        cfg = tmp_path / "grid.toml"
        cfg.write_text(PAPER.read_text() + '\n[sweep]\n"schedule.beta" = [0.1, 0.5]\n')
    else:
        cfg = PAPER.with_name("sobol_schedule.toml")
    code, loaded = _run(("config", "validate", str(cfg)))
    assert code == 0 and "numpy" in loaded and not loaded & {*HEAVY, "SALib"}
