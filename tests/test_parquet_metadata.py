"""Data conventions of every Parquet file cwrend writes (issue 18, item 5).

Each file carries, in its Arrow schema metadata, the cwrend version and the
config hash (:func:`cwrend_cli.config.config_hash`; a campaign's files: its
base config's, as ``manifest.json``), and each column a field-level ``unit``
and ``description`` from the one table of :mod:`cwrend_cli.output.tables`.
The steps column of the degradation window is ``degradation_window`` (not
the SQL keyword ``window``); steps written with the old name still load.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from cwrend_cli import __version__
from cwrend_cli.cli import app
from cwrend_cli.config import config_hash, load_config
from cwrend_cli.output import tables
from cwrend_cli.output.tables import (
    CAMPAIGN_SOLVES_SCHEMA,
    CAMPAIGN_STEPS_SCHEMA,
    REFERENCE_SCHEMA,
    SOLVES_SCHEMA,
    STEPS_SCHEMA,
    SUMMARY_SCHEMA,
    normalize_steps,
    unit_of,
    with_conventions,
)
from cwrend_cli.report import load_results

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
runner = CliRunner()


def _ok(args: list[str]) -> None:
    result = runner.invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output


def _check_file(path: Path, expected_hash: str) -> None:
    """``path`` carries the version, ``expected_hash`` and a unit on every column."""
    schema = pq.read_schema(path)
    meta = schema.metadata or {}
    assert meta.get(b"cwrend_version") == __version__.encode(), path
    assert meta.get(b"config_hash") == expected_hash.encode(), path
    no_unit = [f.name for f in schema if not (f.metadata or {}).get(b"unit")]
    assert not no_unit, (path, no_unit)


# --- the table of units ---------------------------------------------------------------


@pytest.mark.parametrize(
    "schema",
    [
        STEPS_SCHEMA,
        SOLVES_SCHEMA,
        SUMMARY_SCHEMA,
        REFERENCE_SCHEMA,
        CAMPAIGN_STEPS_SCHEMA,
        CAMPAIGN_SOLVES_SCHEMA,
    ],
    ids=["steps", "solves", "summary", "references", "campaign_steps", "campaign_solves"],
)
def test_every_column_of_every_schema_has_a_unit(schema: pa.Schema) -> None:
    assert all(unit_of(f.name) for f in schema)


@pytest.mark.parametrize(
    ("column", "unit"),
    [
        ("miss_km", "km"),
        ("delta_v_km_s", "km/s"),
        ("u_norm_km_s2", "km/s^2"),
        ("t_s", "s"),
        ("wall_time_ms", "ms"),
        ("fuel_penalty_pct", "%"),
        ("nees", "-"),
        ("degradation_window", "-"),
        ("param.scenario.u_max_km_s2", "km/s^2"),
        ("param.schedule.beta", "-"),
        ("disp.scenario.x0.2", "km"),
        ("disp.estimator.initial_error.4", "km/s"),
        ("disp.degradation.windows.1.bias_km.0", "km"),
        ("param.actuator.pointing_sigma_deg", "deg"),
        ("param.truth.model", "-"),
        ("param.guidance.method", "-"),
        ("param.guidance.t_resolve_s", "s"),
        ("param.truth.inclination_deg", "deg"),
        ("param.estimator.q_process", "as configuration key estimator.q_process"),
    ],
)
def test_units_from_suffixes_and_keys(column: str, unit: str) -> None:
    assert unit_of(column) == unit


def test_a_column_without_a_unit_is_refused() -> None:
    table = pa.table({"mystery": [1.0]})
    with pytest.raises(KeyError, match="mystery"):
        with_conventions(table, {"config_hash": "h"})


def test_conventions_need_the_config_hash() -> None:
    with pytest.raises(KeyError, match="config_hash"):
        with_conventions(pa.table({"miss_km": [1.0]}), {})


# --- every file of every command ---------------------------------------------------------


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A `cwrend run`, an ablation, a sweep and a comparison, in one directory."""
    root = tmp_path_factory.mktemp("conventions")
    out = f"output.dir={json.dumps(str(root))}"
    common = ["--seeds", "2", "--workers", "1", "--no-rrd", "-q", "--set", out]
    _ok(["run", str(PAPER), "--arch", "mtf_adaptive", "--out", str(root / "run"), "-q", "--no-rrd"])
    _ok(["ablate", str(PAPER), "--arch", "plain_adaptive,mtf_adaptive", *common, "--name", "a"])
    beta = ["--set", "schedule.beta=0.5"]
    _ok(
        [
            "ablate",
            str(PAPER),
            "--arch",
            "plain_adaptive,mtf_adaptive",
            *common,
            *beta,
            "--name",
            "b",
        ]
    )
    sweep = ["--param", "schedule.beta=0.25,0.5", "--arch", "mtf_adaptive", "--name", "s"]
    _ok(["sweep", str(PAPER), *sweep, *common])
    _ok(["compare", str(root / "a"), str(root / "b"), "--out", str(root / "cmp")])
    return root


def test_run_files_carry_the_conventions(written: Path) -> None:
    expected = config_hash(load_config(PAPER))
    files = sorted((written / "run").glob("*.parquet"))
    assert {f.name for f in files} == {
        "steps.parquet",
        "solves.parquet",
        "summary.parquet",
        "references.parquet",
    }
    for path in files:
        _check_file(path, expected)


@pytest.mark.parametrize("name", ["a", "s"])
def test_campaign_files_carry_the_conventions(written: Path, name: str) -> None:
    directory = written / name
    expected = json.loads((directory / "manifest.json").read_text())["config_hash"]
    files = sorted(directory.rglob("*.parquet"))
    kinds = {p.relative_to(directory).parts[0] for p in files}
    stats = "ablation.parquet" if name == "a" else "sweep.parquet"
    assert kinds == {"runs.parquet", "points.parquet", stats, "steps", "solves", "references"}
    for path in files:
        _check_file(path, expected)


def test_compare_file_carries_the_conventions(written: Path) -> None:
    hash_a = json.loads((written / "a" / "manifest.json").read_text())["config_hash"]
    hash_b = json.loads((written / "b" / "manifest.json").read_text())["config_hash"]
    _check_file(written / "cmp" / "compare.parquet", f"A {hash_a}; B {hash_b}")


def test_columns_carry_descriptions(written: Path) -> None:
    schema = pq.read_schema(written / "run" / "steps.parquet")
    assert schema.field("nees").metadata[b"unit"] == b"-"
    assert b"chi2_6" in schema.field("nees").metadata[b"description"]
    assert schema.field("x_km").metadata[b"unit"] == b"km"


# --- the renamed window column -------------------------------------------------------------


def test_steps_have_degradation_window_not_window(written: Path) -> None:
    names = pq.read_schema(written / "run" / "steps.parquet").names
    assert "degradation_window" in names and "window" not in names


def test_normalize_steps_renames_the_old_column() -> None:
    old = pd.DataFrame({"t_s": [0.0, 1.0], "window": [-1, 0]})
    assert list(normalize_steps(old).columns) == ["t_s", "degradation_window"]


def test_normalize_steps_fills_the_new_column_from_the_old() -> None:
    """A dataset of old and new files: the reader sees both columns, each null in part."""
    mixed = pd.DataFrame({"window": [0.0, None], "degradation_window": [None, 1.0]})
    got = normalize_steps(mixed)
    assert list(got.columns) == ["degradation_window"]
    assert got["degradation_window"].tolist() == [0.0, 1.0]


def test_a_campaign_written_with_the_old_name_is_reported(written: Path, tmp_path: Path) -> None:
    """Steps files rewritten as cwrend wrote them before (``window``) load as before."""
    old = Path(shutil.copytree(written / "a", tmp_path / "old"))
    for path in (old / "steps").rglob("*.parquet"):
        table = pq.read_table(path, partitioning=None)
        names = ["window" if n == "degradation_window" else n for n in table.column_names]
        pq.write_table(table.rename_columns(names).replace_schema_metadata(None), path)
    data = load_results(old)
    assert "degradation_window" in data.steps.columns and "window" not in data.steps.columns
    assert set(data.steps["degradation_window"].unique()) == {-1, 0, 1}


def test_suffix_table_is_longest_first() -> None:
    suffixes = [s for s, _ in tables.SUFFIX_UNITS]
    for i, s in enumerate(suffixes):
        assert not any(s.endswith(t) and s != t for t in suffixes[:i]), s


def test_the_conventions_of_one_table_never_reach_another() -> None:
    """The annotated schema is built once per (columns, metadata) and reused: tables of the
    same columns get each their own hashes and schema metadata, and their own values."""
    schema = pa.schema([("seed", pa.int64()), ("miss_km", pa.float64())])
    first = pa.table({"seed": [1], "miss_km": [0.5]}, schema=schema)
    second = pa.table({"seed": [2], "miss_km": [0.25]}, schema=schema.with_metadata({"a": "b"}))
    a = with_conventions(first, {"config_hash": "h1"})
    b = with_conventions(second, {"config_hash": "h2"})
    again = with_conventions(first, {"config_hash": "h1"})
    same_hash = with_conventions(second, {"config_hash": "h1"})  # equal schemas but for metadata
    assert a.schema.metadata[b"config_hash"] == b"h1"
    assert b.schema.metadata[b"config_hash"] == b"h2"
    assert b"a" not in a.schema.metadata
    assert b.schema.metadata[b"a"] == b"b"
    assert same_hash.schema.metadata[b"a"] == b"b"
    assert again.equals(a, check_metadata=True)
    assert b.column("miss_km").to_pylist() == [0.25]
    assert a.schema.field("miss_km").metadata[b"unit"] == b"km"
