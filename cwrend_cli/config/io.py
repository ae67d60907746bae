"""Reading and writing what the user gives: TOML configs and noise files.

Loading (:func:`load_config` reads a TOML file and applies ``--set``
overrides, :func:`config_from_dict` validates a raw tree), serialisation and
provenance (:func:`resolved_dict`, :func:`config_hash`, :func:`shown_dict`,
:func:`to_toml`, :func:`to_json`) and the external noise realisation (:func:`load_noise_file`).

Units: the noise file holds standard-normal draws (dimensionless), one row
per step, scaled by chol(R_true) at use (the v_k of paper Eq. 13; a convention
of cwrend, not in the paper).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import tomli_w
from pydantic import BaseModel, ValidationError
from pydantic_core import to_jsonable_python

from cwrend_cli.config.messages import format_validation_error
from cwrend_cli.config.overrides import apply, nesting_depth, parse_override
from cwrend_cli.config.schema import CwrendConfig
from cwrend_cli.errors import ConfigError, InputDataError
from cwrend_cli.limits import (
    MAX_CONFIG_BYTES,
    MAX_NESTING,
    noise_file_max_bytes,
    noise_file_too_large,
)

if TYPE_CHECKING:
    from cwrend_cli.physics.params import FloatArray

__all__ = [
    "NOISE_COLUMNS",
    "config_from_dict",
    "config_hash",
    "load_config",
    "load_noise_file",
    "resolved_dict",
    "shown_dict",
    "to_json",
    "to_toml",
]

NOISE_COLUMNS = ("n1", "n2", "n3")

# ---------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------


def config_from_dict(
    data: Mapping[str, Any], base_dir: Path | None = None, *, source: str | None = None
) -> CwrendConfig:
    """Validate a raw config tree into a :class:`CwrendConfig`.

    ``base_dir`` resolves relative paths (the noise file); without it they are
    resolved against the working directory. ``source`` only labels errors.
    Raises :class:`ConfigError` with one line per problem.
    """
    if not isinstance(data, Mapping):
        raise ConfigError(f"configuration must be a table, not {type(data).__name__}")
    try:
        return CwrendConfig.model_validate(data, context={"base_dir": base_dir})
    except ValidationError as exc:
        header = f"invalid configuration ({source})" if source else "invalid configuration"
        raise ConfigError(header, format_validation_error(exc, CwrendConfig)) from None


def _safe_stem(path: Path) -> str:
    """The file stem made into a valid ``output.name``."""
    stem = re.sub(r"[^A-Za-z0-9._-]", "_", path.stem).lstrip("._-")
    return stem[:128] or "cwrend"


def load_config(path: str | Path, overrides: Sequence[str] = ()) -> CwrendConfig:
    """Read a TOML config, apply ``dotted.key=value`` overrides, validate.

    ``output.name`` defaults to the file's stem. A relative ``noise.file`` from
    the file is resolved against the file's directory; one given as an override
    against the working directory. Raises :class:`ConfigError` for a missing or
    unreadable file, malformed TOML, a malformed override or invalid values.
    """
    path = Path(path)
    try:
        if not path.exists():
            raise ConfigError(f"config file not found: {path}")
        if not path.is_file():
            raise ConfigError(f"config path is not a file: {path}")
        if path.stat().st_size > MAX_CONFIG_BYTES:
            raise ConfigError(
                f"{path}: {path.stat().st_size:,} bytes; a configuration is at most "
                f"{MAX_CONFIG_BYTES:,} (long grids belong in --param start:stop:num ranges)"
            )
        text = path.read_bytes().decode("utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read config file {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except ValueError as exc:  # e.g. a NUL byte in the path
        raise ConfigError(f"config path {str(path)!r}: {exc}") from None
    try:
        data: dict[str, Any] = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: malformed TOML: {exc}") from None
    except RecursionError:
        data = {}
        too_deep = True
    else:
        too_deep = nesting_depth(data) > MAX_NESTING
    if too_deep:
        raise ConfigError(f"{path}: tables and arrays nested more than {MAX_NESTING} levels deep")

    assignment: list[tuple[str, Any]] = []
    for text_override in overrides:
        key, value = parse_override(text_override)
        if key == "noise.file" and isinstance(value, str) and value.strip():
            given = Path(value).expanduser()
            value = str(given if given.is_absolute() else Path.cwd() / given)
        assignment.append((key, value))
    if assignment:  # the tree copied once for all of them
        data = apply(data, assignment)

    output = data.get("output")
    if output is None:
        data["output"] = {"name": _safe_stem(path)}
    elif isinstance(output, dict) and output.get("name") is None:
        output["name"] = _safe_stem(path)

    return config_from_dict(data, base_dir=path.resolve().parent, source=str(path))


# ---------------------------------------------------------------------------
# Serialisation and provenance
# ---------------------------------------------------------------------------


def resolved_dict(cfg: CwrendConfig) -> dict[str, Any]:
    """The fully resolved config as a JSON-ready dict (valid input to :func:`config_from_dict`)."""
    return cfg.model_dump(mode="json")


def _every_field(value: Any) -> Any:
    """``value`` as JSON-ready data, every field of every model in it by ``model_fields``."""
    if isinstance(value, BaseModel):
        return {name: _every_field(getattr(value, name)) for name in type(value).model_fields}
    if isinstance(value, (tuple, list)):
        return [_every_field(item) for item in value]
    if isinstance(value, Mapping):
        return {str(key): _every_field(item) for key, item in value.items()}
    return to_jsonable_python(value)


def shown_dict(cfg: CwrendConfig) -> dict[str, Any]:
    """Every field of the schema with its value, as a JSON-ready dict (what ``config show`` prints).

    Walks ``model_fields`` recursively, so no field can be missing: unlike
    :func:`resolved_dict`, whose model serializers leave default-valued fields
    out (``[constraints]``, ``[model]``, ``[sensor]``, ``[target]`` at their
    defaults, ``estimator.process_noise``, …) to keep existing config and
    campaign hashes unchanged. Unset optional fields are ``None``. Every value
    the resolved tree holds is here too, equal; the tree reads back
    (:func:`config_from_dict`) as the same config.
    """
    tree: dict[str, Any] = _every_field(cfg)
    return tree


def config_hash(cfg: CwrendConfig) -> str:
    """SHA-256 hex digest of the canonical JSON of the resolved config.

    Canonical: ``model_dump(mode="json")``, keys sorted, compact separators.
    Covariances are stored in canonical form, so a diagonal written as a full
    matrix hashes like its diagonal.
    """
    canonical = json.dumps(resolved_dict(cfg), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def _drop_none(value: Any) -> Any:
    """Remove ``None`` values from tables (TOML has no null; unset means default)."""
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, list):
        return [_drop_none(v) for v in value]
    return value


#: How :func:`to_toml` shows an unset optional field (TOML has no null).
UNSET_COMMENT = "# {key} = (unset)"


def _unset_keys(tree: Mapping[str, Any], prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Dotted paths (through tables, not arrays) of the ``None`` values of ``tree``."""
    found: list[tuple[str, ...]] = []
    for key, value in tree.items():
        if value is None:
            found.append((*prefix, key))
        elif isinstance(value, Mapping):
            found += _unset_keys(value, (*prefix, key))
    return found


def _toml_key(part: str) -> str:
    """A key as tomli_w writes it in a table header: bare when it can be, else quoted (a
    dispersion's dotted key, ``"scenario.x0.2"``)."""
    return part if re.fullmatch(r"[A-Za-z0-9_-]+", part) else json.dumps(part)


def _with_unset_comments(text: str, unset: Sequence[tuple[str, ...]]) -> str:
    """Insert ``# key = (unset)`` lines into TOML ``text``, each in its own table."""
    lines = text.splitlines()
    by_table: dict[tuple[str, ...], list[str]] = {}
    for path in unset:
        by_table.setdefault(path[:-1], []).append(UNSET_COMMENT.format(key=path[-1]))
    top = by_table.pop((), [])
    for table, comments in by_table.items():
        header = "[" + ".".join(map(_toml_key, table)) + "]"
        if header in lines:
            at = lines.index(header) + 1
            lines[at:at] = comments
        else:  # every field of the table unset: tomli_w wrote no header
            lines += ["", header, *comments]
    return "\n".join(top + lines) + "\n"


def to_toml(cfg: CwrendConfig, *, show_unset: bool = False) -> str:
    """The resolved config as TOML text that :func:`load_config` reads back unchanged.

    TOML has no null, so unset optional fields are left out; with
    ``show_unset`` every field of the schema is listed (:func:`shown_dict`,
    defaults included) and each unset optional one appears as a comment line in
    its table, e.g. ``# eps_saturation = (unset)``. Without it, the fields the
    resolved tree leaves out at their defaults are left out too.
    """
    tree = shown_dict(cfg) if show_unset else resolved_dict(cfg)
    text = tomli_w.dumps(_drop_none(tree))
    return _with_unset_comments(text, _unset_keys(tree)) if show_unset else text


def to_json(cfg: CwrendConfig, indent: int | None = 2) -> str:
    """Every field of the config (:func:`shown_dict`) as JSON text, unset optional ones null."""
    return json.dumps(shown_dict(cfg), indent=indent)


# ---------------------------------------------------------------------------
# Noise files
# ---------------------------------------------------------------------------


def file_digest(path: str | Path) -> str:
    """SHA-256 of a file's bytes (an input identified by its content); :class:`InputDataError`.

    Read in chunks (:func:`hashlib.file_digest`): the memory taken does not grow
    with the file (issue 36 item 9: the whole file was read at once).
    """
    try:
        with open(path, "rb") as file:
            return hashlib.file_digest(file, "sha256").hexdigest()
    except OSError as exc:
        raise InputDataError(f"{path}: cannot be read ({exc.strerror or exc})") from None


def _noise_bytes(path: Path, n_steps: int) -> bytes:
    """The bytes of a noise file of ``n_steps`` rows, read no further than its bound.

    :class:`InputDataError` for a file larger than
    :func:`~cwrend_cli.limits.noise_file_max_bytes` (checked on its size, then on
    what is read, in case it grew in between).
    """
    limit = noise_file_max_bytes(n_steps)
    with open(path, "rb") as file:
        size = os.fstat(file.fileno()).st_size
        data = file.read(limit + 1) if size <= limit else b""
    problem = noise_file_too_large(max(size, len(data)), n_steps)
    if problem is not None:
        raise InputDataError(f"noise.file = {str(path)!r}: {problem}")
    return data


def _wrong_rows(path: Path, rows: int, n_steps: int) -> NoReturn:
    raise InputDataError(
        f"noise.file = {str(path)!r}: has {rows} rows, expected {n_steps} "
        "(one row per step, horizon_s / dt_s)"
    )


def load_noise_file(path: str | Path, n_steps: int) -> FloatArray:
    """Read an external standard-normal realisation (CSV or Parquet, columns n1, n2, n3).

    Raises :class:`InputDataError` naming the file and the problem when the
    file is unreadable, lacks a column, has the wrong number of rows (one per
    step is required) or holds a non-finite value.
    """
    import numpy as np
    import pandas as pd

    path = Path(path)
    try:
        data = io.BytesIO(_noise_bytes(path, n_steps))
        if path.suffix.lower() in (".parquet", ".pq"):
            import pyarrow.parquet as pq

            rows = pq.ParquetFile(data).metadata.num_rows  # a footer: no row decoded yet
            if rows != n_steps:  # a few kB of Parquet can hold a billion rows of zeros
                _wrong_rows(path, rows, n_steps)
            frame = pd.read_parquet(data)
        else:
            frame = pd.read_csv(data)
    except FileNotFoundError:
        raise InputDataError(f"noise.file = {str(path)!r}: file not found") from None
    except InputDataError:
        raise
    except Exception as exc:  # pandas/pyarrow raise many types for unreadable files
        raise InputDataError(f"noise.file = {str(path)!r}: cannot be read ({exc})") from None
    missing = [c for c in NOISE_COLUMNS if c not in frame.columns]
    if missing:
        raise InputDataError(
            f"noise.file = {str(path)!r}: missing column(s) {', '.join(missing)}; "
            f"expected columns n1, n2, n3 (found: {', '.join(map(str, frame.columns))})"
        )
    if len(frame) != n_steps:
        _wrong_rows(path, len(frame), n_steps)
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
