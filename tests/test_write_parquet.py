"""How :func:`cwrend_cli.output.files.write_parquet` encodes a table (issue 17).

The encodings are the file's business only: a table read back is the table
written, bit for bit (NaN, nulls, types, schema and field metadata).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from cwrend_cli.output.files import write_parquet


def _table() -> pa.Table:
    floats = np.array([0.0, -0.0, np.nan, 1e-300, -2.5, np.inf])
    schema = pa.schema(
        [
            pa.field("x_km", pa.float64(), metadata={b"unit": b"km"}),
            pa.field("ratio", pa.float32()),
            pa.field("n", pa.int64()),
            pa.field("ok", pa.bool_()),
            pa.field("run_key", pa.string()),
        ],
        metadata={b"config_hash": b"abc"},
    )
    return pa.table(
        {
            "x_km": floats,
            "ratio": pa.array([1.5, None, np.nan, 0.0, -1.0, 2.0], pa.float32()),
            "n": np.arange(6, dtype=np.int64),
            "ok": [True, False, True, None, False, True],
            "run_key": ["a", "a", "b", None, "b", "c"],
        },
        schema=schema,
    )


def test_a_table_reads_back_bit_for_bit(tmp_path: Path) -> None:
    table = _table()
    back = pq.read_table(write_parquet(table, tmp_path / "t.parquet"))
    assert back.schema.equals(table.schema, check_metadata=True)
    assert [f.metadata for f in back.schema] == [f.metadata for f in table.schema]
    for name in ("x_km", "ratio"):
        written, read = table[name].combine_chunks(), back[name].combine_chunks()
        assert read.is_null().equals(written.is_null())
        width = np.int64 if name == "x_km" else np.int32
        bits = [a.fill_null(0).to_numpy().view(width) for a in (written, read)]
        np.testing.assert_array_equal(bits[1], bits[0])
    for name in ("n", "ok", "run_key"):
        assert back[name].equals(table[name])


def test_floats_are_byte_stream_split_and_strings_dictionary_encoded(tmp_path: Path) -> None:
    meta = pq.ParquetFile(write_parquet(_table(), tmp_path / "t.parquet")).metadata.row_group(0)
    columns = {meta.column(i).path_in_schema: meta.column(i) for i in range(meta.num_columns)}
    assert {c.compression for c in columns.values()} == {"SNAPPY"}
    for name in ("x_km", "ratio"):
        assert "BYTE_STREAM_SPLIT" in columns[name].encodings
    assert "RLE_DICTIONARY" in columns["run_key"].encodings
    assert "RLE_DICTIONARY" not in columns["n"].encodings


def test_statistics_for_the_columns_readers_filter_by_not_the_floats(tmp_path: Path) -> None:
    """Min/max statistics on the key columns (ints, bools, strings), none on the floats.

    Readers prune row groups by run key, step or status; the float columns'
    statistics took half of a steps file's write (issue 17, ``write_parquet``).
    """
    path = write_parquet(_table(), tmp_path / "t.parquet")
    group = pq.ParquetFile(path).metadata.row_group(0)
    stats = {group.column(i).path_in_schema: group.column(i).statistics for i in range(5)}
    assert stats["x_km"] is None and stats["ratio"] is None
    assert stats["n"].has_min_max and (stats["n"].min, stats["n"].max) == (0, 5)
    assert stats["run_key"].has_min_max and (stats["run_key"].min, stats["run_key"].max) == (
        "a",
        "c",
    )
    assert stats["ok"].has_min_max
