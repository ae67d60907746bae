"""Reading and writing what the user gives: TOML configs and noise files.

Units: the noise file holds standard-normal draws (dimensionless), one row
per step, scaled by chol(R_true) at use (SPEC §6).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cwrend_cli.errors import InputDataError
from cwrend_cli.physics.params import FloatArray

NOISE_COLUMNS = ("n1", "n2", "n3")


def load_noise_file(path: str | Path, n_steps: int) -> FloatArray:
    """Read an external standard-normal realisation (CSV or Parquet, columns n1, n2, n3).

    Raises :class:`InputDataError` naming the file and the problem when the
    file is unreadable, lacks a column, has the wrong number of rows (one per
    step is required) or holds a non-finite value.
    """
    import pandas as pd

    path = Path(path)
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            frame = pd.read_parquet(path)
        else:
            frame = pd.read_csv(path)
    except FileNotFoundError:
        raise InputDataError(f"noise.file = {str(path)!r}: file not found") from None
    except Exception as exc:  # pandas/pyarrow raise many types for unreadable files
        raise InputDataError(f"noise.file = {str(path)!r}: cannot be read ({exc})") from None
    missing = [c for c in NOISE_COLUMNS if c not in frame.columns]
    if missing:
        raise InputDataError(
            f"noise.file = {str(path)!r}: missing column(s) {', '.join(missing)}; "
            f"expected columns n1, n2, n3 (found: {', '.join(map(str, frame.columns))})"
        )
    if len(frame) != n_steps:
        raise InputDataError(
            f"noise.file = {str(path)!r}: has {len(frame)} rows, expected {n_steps} "
            "(one row per step, horizon_s / dt_s)"
        )
    try:
        values = frame[list(NOISE_COLUMNS)].to_numpy(dtype=float)
    except (TypeError, ValueError):
        raise InputDataError(
            f"noise.file = {str(path)!r}: columns n1, n2, n3 must be numeric"
        ) from None
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        raise InputDataError(
            f"noise.file = {str(path)!r}: non-finite value in row {row} (all values must be finite)"
        )
    return np.ascontiguousarray(values)
