"""The numbers of the paper ablation and of a swept, dispersed point, bit for bit.

The fixture ``data/same_numbers.json`` was made on the code before the
package was reorganised into layers (issue 14, a move that must change no
number) by running this module as a script::

    python tests/test_same_numbers.py        # rewrites tests/data/same_numbers.json

It holds, for 3 seeds × 4 architectures of the paper scenario (SPEC §6) and
of one swept (β = 0.5) and dispersed grid point, every value of
``runs.parquet`` except wall times, and a SHA-256 digest of each column of
each run's ``steps/`` and ``solves/`` rows (wall times excluded). The test
reruns the same two campaigns through the command line and requires every
value and digest to be identical: tolerance zero, because a move of code
must not change a single bit. Regenerate the fixture only when an issue
changes the numbers on purpose, and say so in the commit.

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
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app

FIXTURE = Path(__file__).resolve().parent / "data" / "same_numbers.json"
PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
SEEDS = 3
#: Columns that hold wall-clock times: they differ on every run by nature.
TIMING_COLUMNS = frozenset({"duration_s", "solve_mean_ms", "solve_max_ms", "wall_time_ms"})
#: Columns renamed since the fixture was made: old name → new name (same values).
RENAMED = {"window": "degradation_window"}
#: ``runs.parquet`` columns added since the fixture was made (the only ones allowed).
NEW_RUNS_COLUMNS = frozenset({"mean_nis_nominal", "mean_nees"})
#: ``steps/`` and ``solves/`` columns added since the fixture was made (the only ones allowed).
NEW_HISTORY_COLUMNS = frozenset(
    {"nees", "ucmd_x_km_s2", "ucmd_y_km_s2", "ucmd_z_km_s2", "dropout", "outlier"}
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


def _column_digest(values: pd.Series) -> str:
    """SHA-256 of a column's values: float64/int64 bytes, or the UTF-8 text of strings."""
    if pd.api.types.is_bool_dtype(values) or pd.api.types.is_numeric_dtype(values):
        kind = np.float64 if pd.api.types.is_float_dtype(values) else np.int64
        data = np.ascontiguousarray(values.to_numpy(dtype=kind)).tobytes()
    else:
        data = "\x1f".join(values.astype(str)).encode()
    return hashlib.sha256(data).hexdigest()


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
                c: _column_digest(rows[c].reset_index(drop=True))
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
        "ablation": numbers_of(root / "out" / "paper"),
        "sweep": numbers_of(root / "out" / "sweep"),
    }


@pytest.fixture(scope="module")
def numbers(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return run_campaigns(tmp_path_factory.mktemp("same_numbers"))


@pytest.fixture(scope="module")
def stored() -> dict[str, Any]:
    return json.loads(FIXTURE.read_text())


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
def test_same_runs(numbers: dict[str, Any], stored: dict[str, Any], campaign: str) -> None:
    assert sorted(numbers[campaign]) == sorted(stored[campaign])
    for key, stored_run in stored[campaign].items():
        expected = _renamed(stored_run["runs"])
        got = numbers[campaign][key]["runs"]
        extra = _new_columns(got, expected, NEW_RUNS_COLUMNS)
        assert {c: v for c, v in got.items() if c not in extra} == expected, key


@pytest.mark.parametrize("campaign", ["ablation", "sweep"])
@pytest.mark.parametrize("dataset", ["steps", "solves"])
def test_same_histories(
    numbers: dict[str, Any], stored: dict[str, Any], campaign: str, dataset: str
) -> None:
    for key, stored_run in stored[campaign].items():
        expected = _renamed(stored_run[dataset])
        got = numbers[campaign][key][dataset]
        _new_columns(got, expected, NEW_HISTORY_COLUMNS)
        changed = sorted(c for c in expected if got[c] != expected[c])
        assert not changed, f"{key}: {changed}"


if __name__ == "__main__":
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        data = run_campaigns(Path(tmp))
    FIXTURE.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    print(f"wrote {FIXTURE} ({FIXTURE.stat().st_size} bytes)", file=sys.stderr)
