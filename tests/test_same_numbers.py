"""The numbers of the paper ablation and of a swept, dispersed point, bit for bit.

The fixture ``data/same_numbers.json`` was made on the code before the
package was reorganised into layers (issue 14, a move that must change no
number) by running this module as a script (below).

It holds, for 3 seeds × 4 architectures of the paper scenario (docs/method.md) and
of one swept (β = 0.5) and dispersed grid point, every value of
``runs.parquet`` except wall times, and for each column of each run's
``steps/`` and ``solves/`` rows (wall times excluded) a SHA-256 digest and a
few sums (:func:`_column_summary`). The test reruns the same two campaigns
through the command line.

On the platform a fixture was made on (:func:`platform_signature`: the CPU
model LLVM compiles for, the C library and the numerical libraries'
versions) every value and digest must be identical: tolerance zero, because
a move of code must not change a single bit. The primary fixture may have
copies made on other platforms, ``data/same_numbers.<cpu>.json``
(:func:`fixture_for`); each was made from code whose numbers matched the
primary's, so wherever one exists the comparison is exact too.

Elsewhere bits cannot be compared: OpenBLAS picks its kernels by CPU model,
numpy its SIMD loops, numba its instructions, and their roundings differ by
an ulp that the closed loop carries on. There the floats are compared to
:data:`PLATFORM_RTOL` relative (of the value, or of the column's Σ|x| for a
history's sums) and everything else (integers, flags, statuses, strings)
exactly, except the solver residuals, which are rounding noise below the
solver's tolerance (:data:`PLATFORM_NOISE_COLUMNS`). Measured: between the
fixture's earlier platform and an AMD EPYC ``znver3`` every run differed,
by at most 9.5e-10 relative (the miss of a fixed-ε run); between ``znver3``
and ``znver4`` (AVX-512, which LLVM and numpy use there) by at most
1.08e-8 (the NEES weighted sum of mtf_adaptive seed 1: NEES divides the
estimation error, a difference of nearly equal states, by the covariance),
the misses by 1.6e-9. Run on the ``znver4`` machine with numba compiling
for ``znver3``, numpy's AVX-512 loops off and OpenBLAS's Zen kernels
(``NUMBA_CPU_NAME=znver3 NPY_DISABLE_CPU_FEATURES="AVX512F AVX512CD
AVX512VL AVX512BW AVX512DQ AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL
AVX512_SPR" OPENBLAS_CORETYPE=ZEN``), the same code reproduced the
``znver3`` fixture bit for bit (0 of 1,608 columns differed, 2026-12-02), so
those differences are the platform's alone. 1e-7 is about ten times the
largest platform difference measured and ten times below a change at the
solver's tolerance (a miss moved by 1e-9 km of ~1e-3 km is 1e-6
relative), so a change of the numerics still fails
(:func:`test_the_comparison_has_teeth`).

Regenerate the fixture only when an issue changes the numbers on purpose
(``python tests/test_same_numbers.py``: rewrites the primary and deletes
the platform copies, which no longer hold the numbers; remake a copy on its
platform, or on a newer CPU with the settings above), or add a copy for the
platform CI runs on (``python tests/test_same_numbers.py --platform-copy``:
refuses unless the numbers match the primary within PLATFORM_RTOL), and say
so in the commit.

Columns may be added or renamed without a new fixture, deliberately: a
column renamed since the fixture was made is looked up under its new name
(:data:`RENAMED`, e.g. ``window`` → ``degradation_window``, issue 18 item 5)
and must keep its digest; a column the fixture lacks is accepted only from
:data:`NEW_RUNS_COLUMNS` / :data:`NEW_HISTORY_COLUMNS` (issue 15 item 6:
filter consistency, the commanded control and the fault flags). Every other
difference in the set of columns fails.
"""

from __future__ import annotations

import hashlib
import json
import math
import platform
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app

DATA = Path(__file__).resolve().parent / "data"
#: The primary fixture; its copies made on other platforms are ``same_numbers.<cpu>.json``.
FIXTURE = DATA / "same_numbers.json"
PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
SEEDS = 3
#: Relative tolerance of the floats where the platform differs from the fixture's (docstring).
PLATFORM_RTOL = 1e-7
#: History columns whose bits are rounding noise, compared only on the fixture's platform: a
#: converged re-solve's terminal residual is below the solver's tolerance (1e-9 km) by
#: whatever the last Newton step left, and differed in all 24 runs between the fixture's
#: earlier platform and an AMD EPYC znver3 (the statuses, iterations and success flags that
#: say what it means were identical, and are compared exactly everywhere).
PLATFORM_NOISE_COLUMNS = frozenset({"residual_km"})
#: Columns that hold wall-clock times: they differ on every run by nature.
TIMING_COLUMNS = frozenset({"duration_s", "solve_mean_ms", "solve_max_ms", "wall_time_ms"})
#: Columns renamed since the fixture was made: old name → new name (same values).
RENAMED = {"window": "degradation_window"}
#: ``runs.parquet`` columns added since the fixture was made (the only ones allowed).
NEW_RUNS_COLUMNS = frozenset(
    {
        "mean_nis_nominal",
        "mean_nees",
        # issue 33 item 3: the applied impulse sum ||u_k|| dt and its penalty against the exact
        # continuous fuel optimum, beside the paper's trapezoid (delta_v_km_s, unchanged)
        "delta_v_applied_km_s",
        "fuel_penalty_applied_pct",
    }
)
#: ``steps/`` and ``solves/`` columns added since the fixture was made (the only ones allowed).
NEW_HISTORY_COLUMNS = frozenset(
    {
        "nees",
        "ucmd_x_km_s2",
        "ucmd_y_km_s2",
        "ucmd_z_km_s2",
        "dropout",
        "outlier",
        "trace_q",  # issue 33 item 2: tr Q_k of each step (estimator.process_noise)
    }
)

SWEEP_TOML = """
[output]
rrd_seeds = 0
[sweep]
"schedule.beta" = [0.5]
[dispersions]
"scenario.x0.2" = { dist = "normal", std = 0.01 }
"estimator.initial_error.0" = { dist = "normal", std = 0.001 }
"degradation.windows.1.bias_km.0" = { dist = "uniform", low = -0.02, high = 0.02 }
"""


def platform_signature() -> dict[str, str]:
    """What decides the last bit of the numbers: CPU model, C library, numerical libraries.

    The CPU is the one numba compiles for: the host's, or ``NUMBA_CPU_NAME`` (docstring).
    """
    import llvmlite.binding as llvm
    import numba
    import scipy

    return {
        "cpu": numba.config.CPU_NAME or llvm.get_host_cpu_name(),
        "machine": platform.machine(),
        "libc": " ".join(platform.libc_ver()),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
    }


def assert_pinned_plans(fixture: Path, make: Callable[[], list[dict[str, Any]]]) -> None:
    """``make()`` equals the plans stored in ``fixture`` (a JSON of ``platform``, ``plans``
    and optionally ``also_on``), compared on the fixture's platform and on the platforms
    ``also_on`` lists, where the same code gave the same plans bit for bit
    (:func:`confirm_pinned_plans`); elsewhere the test is skipped, before ``make`` runs."""
    stored = json.loads(fixture.read_text(encoding="utf-8"))
    if platform_signature() not in _pinned_platforms(stored):
        pytest.skip("bits are compared on the fixture's platforms only (module docstring)")
    assert make() == stored["plans"]


def write_pinned_plans(fixture: Path, plans: list[dict[str, Any]]) -> None:
    """Store ``plans`` with this platform's signature for :func:`assert_pinned_plans`."""
    _write_plans(fixture, {"platform": platform_signature(), "plans": plans})


def confirm_pinned_plans(fixture: Path, plans: list[dict[str, Any]]) -> int:
    """Add this platform to ``fixture``'s ``also_on`` when ``plans``, made here by the code
    that reproduces the fixture on its own platform, equal the stored ones bit for bit: 0;
    else nothing is written and 1 (the platforms round differently: the test stays skipped
    here)."""
    stored = json.loads(fixture.read_text(encoding="utf-8"))
    if plans != stored["plans"]:
        print(f"{fixture.name}: the plans made here differ from the stored ones", file=sys.stderr)
        return 1
    here = platform_signature()
    if here not in _pinned_platforms(stored):
        stored["also_on"] = [*stored.get("also_on", []), here]
        _write_plans(fixture, stored)
    return 0


def pinned_plans_main(fixture: Path, make: Callable[[], list[dict[str, Any]]]) -> int:
    """A pinned-plan module run as a script: no argument rewrites ``fixture`` from
    ``make()`` (only when an issue moves the plans on purpose); ``--also-here`` adds this
    platform to its ``also_on`` if the plans are the same here (:func:`confirm_pinned_plans`)."""
    if sys.argv[1:] == ["--also-here"]:
        return confirm_pinned_plans(fixture, make())
    if sys.argv[1:]:
        print("usage: python tests/<module>.py [--also-here]", file=sys.stderr)
        return 2
    write_pinned_plans(fixture, make())
    return 0


def _pinned_platforms(stored: dict[str, Any]) -> list[dict[str, str]]:
    """The platforms a pinned-plan fixture's bits are compared on: its own and ``also_on``."""
    return [stored["platform"], *stored.get("also_on", [])]


def _write_plans(fixture: Path, stored: dict[str, Any]) -> None:
    fixture.write_text(json.dumps(stored, indent=1) + "\n", encoding="utf-8")


def _column_summary(values: pd.Series) -> dict[str, Any]:
    """A column's SHA-256 (float64/int64 bytes, or the UTF-8 text of strings) and, for floats,
    its sums: Σx, Σ|x|, Σ(i+1)x (which moves when values move between rows), NaN count, min, max.
    """
    out: dict[str, Any] = {}
    if pd.api.types.is_bool_dtype(values) or pd.api.types.is_numeric_dtype(values):
        kind = np.float64 if pd.api.types.is_float_dtype(values) else np.int64
        arr = np.ascontiguousarray(values.to_numpy(dtype=kind))
        out["sha256"] = hashlib.sha256(arr.tobytes()).hexdigest()
        if kind is np.float64:
            finite = np.where(np.isnan(arr), 0.0, arr)
            weights = np.arange(1, arr.size + 1, dtype=float)
            out |= {
                "sum": repr(float(finite.sum())),
                "abs_sum": repr(float(np.abs(finite).sum())),
                "weighted_sum": repr(float((weights * finite).sum())),
                "nan": int(np.isnan(arr).sum()),
                "min": repr(float(np.nanmin(arr))) if arr.size > np.isnan(arr).sum() else "nan",
                "max": repr(float(np.nanmax(arr))) if arr.size > np.isnan(arr).sum() else "nan",
            }
    else:
        data = "\x1f".join(values.astype(str)).encode()
        out["sha256"] = hashlib.sha256(data).hexdigest()
    return out


def _close(got: str, expected: str, scale: float) -> bool:
    """Two floats (as their repr) within PLATFORM_RTOL of ``scale`` (NaN equals NaN)."""
    a, b = float(got), float(expected)
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return abs(a - b) <= PLATFORM_RTOL * scale


def _same_value(got: Any, expected: Any, exact: bool) -> bool:
    """A ``runs.parquet`` value as the fixture holds it (floats as repr strings)."""
    if exact or not isinstance(expected, str) or not isinstance(got, str):
        return bool(got == expected)
    try:
        scale = abs(float(expected))
    except ValueError:
        return bool(got == expected)  # a string column, not a float
    return _close(got, expected, scale)


def _same_column(got: dict[str, Any], expected: dict[str, Any], exact: bool) -> bool:
    """A history column's summary as the fixture holds it (:func:`_column_summary`)."""
    if exact or "sum" not in expected:
        return bool(got["sha256"] == expected["sha256"])
    if got["nan"] != expected["nan"]:
        return False
    scale = float(expected["abs_sum"])
    extent = max(abs(float(expected["min"])), abs(float(expected["max"])), 0.0)
    return all(
        _close(got[name], expected[name], scale) for name in ("sum", "abs_sum", "weighted_sum")
    ) and all(_close(got[name], expected[name], extent) for name in ("min", "max"))


def _exact(value: Any) -> Any:
    """A JSON value that round-trips exactly (floats as their repr)."""
    if isinstance(value, float | np.floating):
        return repr(float(value))
    if isinstance(value, np.integer):
        return int(value)
    return value


def numbers_of(campaign_dir: Path) -> dict[str, Any]:
    """The numeric contents of a campaign directory, keyed by run."""
    runs = pd.read_parquet(campaign_dir / "runs.parquet").sort_values("run_key")
    out: dict[str, Any] = {}
    for row in runs.to_dict("records"):
        key = row["run_key"]
        out[key] = {
            "runs": {c: _exact(v) for c, v in row.items() if c not in TIMING_COLUMNS},
        }
    for dataset, order in (("steps", "step"), ("solves", "step")):
        frame = pd.read_parquet(campaign_dir / dataset)
        for key, rows in frame.groupby("run_key", observed=True):
            rows = rows.sort_values([order] + (["kind"] if "kind" in rows else []))
            out[str(key)][dataset] = {
                c: _column_summary(rows[c].reset_index(drop=True))
                for c in rows.columns
                if c not in TIMING_COLUMNS and c not in ("run_key", "arch", "point")
            }
    return out


def run_campaigns(root: Path) -> dict[str, Any]:
    """Run the two campaigns of the fixture in ``root`` (one worker) and read their numbers."""
    runner = CliRunner()
    sweep = root / "sweep.toml"
    sweep.write_text(SWEEP_TOML)
    common = ["--seeds", str(SEEDS), "--workers", "1", "--no-rrd", "-q"]
    out_dir = f"output.dir={json.dumps(str(root / 'out'))}"
    for args in (
        ["ablate", str(PAPER), *common, "--set", out_dir],
        ["sweep", str(sweep), *common, "--set", out_dir],
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
    return {
        "platform": platform_signature(),
        "ablation": numbers_of(root / "out" / "paper"),
        "sweep": numbers_of(root / "out" / "sweep"),
    }


@pytest.fixture(scope="module")
def numbers(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return run_campaigns(tmp_path_factory.mktemp("same_numbers"))


def fixture_for(signature: dict[str, str]) -> Path:
    """The fixture made on the platform ``signature`` if there is one, else the primary."""
    for path in sorted(DATA.glob("same_numbers.*.json")):
        if json.loads(path.read_text())["platform"] == signature:
            return path
    return FIXTURE


@pytest.fixture(scope="module")
def stored(numbers: dict[str, Any]) -> dict[str, Any]:
    return dict(json.loads(fixture_for(numbers["platform"]).read_text()))


@pytest.fixture(scope="module")
def exact(numbers: dict[str, Any], stored: dict[str, Any]) -> bool:
    """Bit for bit on a fixture's platform; within PLATFORM_RTOL elsewhere (docstring)."""
    return bool(numbers["platform"] == stored["platform"])


def _renamed(columns: dict[str, Any]) -> dict[str, Any]:
    """Stored columns under their current names (:data:`RENAMED`)."""
    return {RENAMED.get(c, c): v for c, v in columns.items()}


def _new_columns(
    got: dict[str, Any], expected: dict[str, Any], allowed: frozenset[str]
) -> set[str]:
    """Columns of ``got`` the fixture lacks; fails on any outside ``allowed`` or any missing."""
    missing = expected.keys() - got.keys()
    extra = got.keys() - expected.keys()
    assert not missing, f"columns gone: {sorted(missing)}"
    assert extra <= allowed, f"columns not in the allow-list: {sorted(extra - allowed)}"
    return extra


@pytest.mark.parametrize("campaign", ["ablation", "sweep"])
def test_same_runs(
    numbers: dict[str, Any], stored: dict[str, Any], exact: bool, campaign: str
) -> None:
    assert sorted(numbers[campaign]) == sorted(stored[campaign])
    for key, stored_run in stored[campaign].items():
        expected = _renamed(stored_run["runs"])
        got = numbers[campaign][key]["runs"]
        _new_columns(got, expected, NEW_RUNS_COLUMNS)
        changed = {c: (got[c], expected[c]) for c in _changed(got, stored_run, "runs", exact)}
        assert not changed, f"{key} ({'exact' if exact else 'other platform'}): {changed}"


@pytest.mark.parametrize("campaign", ["ablation", "sweep"])
@pytest.mark.parametrize("dataset", ["steps", "solves"])
def test_same_histories(
    numbers: dict[str, Any], stored: dict[str, Any], exact: bool, campaign: str, dataset: str
) -> None:
    for key, stored_run in stored[campaign].items():
        expected = _renamed(stored_run[dataset])
        got = numbers[campaign][key][dataset]
        _new_columns(got, expected, NEW_HISTORY_COLUMNS)
        changed = _changed(got, stored_run, dataset, exact)
        assert not changed, f"{key} ({'exact' if exact else 'other platform'}): {changed}"


def test_the_comparison_has_teeth() -> None:
    """Off the fixture's platform a change of 1e-6 relative (the solver's tolerance) still fails."""
    base = pd.Series(np.linspace(1.0, 2.0, 50))
    expected = _column_summary(base)
    assert _same_column(_column_summary(base * (1 + 1e-12)), expected, exact=False)
    assert not _same_column(_column_summary(base * (1 + 1e-12)), expected, exact=True)
    assert not _same_column(_column_summary(base * (1 + 1e-6)), expected, exact=False)
    moved = base.copy()
    moved.iloc[[3, 4]] = moved.iloc[[4, 3]].to_numpy()
    assert not _same_column(_column_summary(moved), expected, exact=False)
    assert _same_value(repr(0.1 * (1 + 1e-12)), repr(0.1), exact=False)
    assert not _same_value(repr(0.1 * (1 + 1e-6)), repr(0.1), exact=False)
    assert not _same_value("converged", "failed", exact=False)


def test_every_platform_copy_holds_the_primary_numbers() -> None:
    """A copy made on another platform is within PLATFORM_RTOL of the primary (never stale)."""
    primary = json.loads(FIXTURE.read_text())
    for copy in sorted(DATA.glob("same_numbers.*.json")):
        held = json.loads(copy.read_text())
        assert held["platform"] != primary["platform"], copy.name
        assert _differences(held, primary) == [], copy.name


def test_a_platform_joins_pinned_plans_only_when_its_plans_are_the_same(tmp_path: Path) -> None:
    """``confirm_pinned_plans`` lists this platform under ``also_on`` for the same plans, once;
    for plans that differ by one bit it writes nothing and answers 1."""
    plans = [{"status": "converged", "controls": [(0.1).hex()]}]
    fixture = tmp_path / "plans.json"
    _write_plans(fixture, {"platform": {"cpu": "elsewhere"}, "plans": plans})
    moved = [{"status": "converged", "controls": [math.nextafter(0.1, 1.0).hex()]}]
    assert confirm_pinned_plans(fixture, moved) == 1
    assert "also_on" not in json.loads(fixture.read_text(encoding="utf-8"))
    assert confirm_pinned_plans(fixture, plans) == 0
    assert confirm_pinned_plans(fixture, plans) == 0
    assert json.loads(fixture.read_text(encoding="utf-8"))["also_on"] == [platform_signature()]


def _changed(
    got: dict[str, Any], stored_run: dict[str, Any], dataset: str, exact: bool
) -> list[str]:
    """The columns of one run's ``dataset`` (runs, steps or solves) that differ from the fixture's.

    Every bit on the fixture's platform; elsewhere beyond PLATFORM_RTOL, the
    solver residuals of the histories not compared (module docstring).
    """
    expected = _renamed(stored_run[dataset])
    if dataset == "runs":
        return sorted(c for c, v in expected.items() if not _same_value(got.get(c), v, exact))
    compared = [c for c in expected if exact or c not in PLATFORM_NOISE_COLUMNS]
    return sorted(c for c in compared if not _same_column(got[c], expected[c], exact))


def _differences(got: dict[str, Any], expected: dict[str, Any]) -> list[str]:
    """The runs and columns of ``got`` outside PLATFORM_RTOL of ``expected`` (empty: a match)."""
    return [
        f"{key} {dataset} {column}"
        for campaign in ("ablation", "sweep")
        for key, run in expected[campaign].items()
        for dataset in ("runs", "steps", "solves")
        for column in _changed(got[campaign][key][dataset], run, dataset, exact=False)
    ]


def main(argv: list[str]) -> int:
    """Write the primary fixture (numbers changed on purpose) or this platform's copy of it."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        data = run_campaigns(Path(tmp))
    if argv == ["--platform-copy"]:
        differences = _differences(data, json.loads(FIXTURE.read_text()))
        if differences:
            print("not a copy: off the primary by more than PLATFORM_RTOL:", *differences[:20],
                  sep="\n  ", file=sys.stderr)  # fmt: skip
            return 1
        target = DATA / f"same_numbers.{data['platform']['cpu']}.json"
    elif not argv:
        target = FIXTURE
        for copy in sorted(DATA.glob("same_numbers.*.json")):
            copy.unlink()
            print(f"deleted {copy} (its numbers are the old ones)", file=sys.stderr)
    else:
        print("usage: python tests/test_same_numbers.py [--platform-copy]", file=sys.stderr)
        return 2
    target.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    print(f"wrote {target} ({target.stat().st_size} bytes)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
