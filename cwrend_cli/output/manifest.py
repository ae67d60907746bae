"""Reading a campaign's ``manifest.json``: one reader for every command that needs it.

The manifest records what a campaign is (its configuration, grid, seeds, hashes)
and how it ran; the journal (``events.jsonl``) records which runs are done. A
manifest that is not UTF-8, not JSON, holds ``NaN``, is nested beyond reason or
whose fields have the wrong types (``null``, ``"root_seed": "zero"``,
``"config": []``) is refused with :class:`ManifestError` (exit 2) naming the
file, what is wrong and the fix, never a traceback (issue 36 item 10). The fix
is the caller's: a resume can rebuild the manifest from the journal
(``--repair-manifest``), ``report`` and ``compare`` can only say how.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from cwrend_cli.errors import ConfigError
from cwrend_cli.limits import MAX_SEED

__all__ = [
    "MAX_MANIFEST_BYTES",
    "REPAIR_HINT",
    "ManifestError",
    "damaged",
    "nis_offset_given",
    "pair_texts",
    "read_manifest",
    "recorded_pairs",
    "xf_given",
]

#: Size of a manifest [bytes]: it holds a configuration, a grid of at most
#: MAX_POINTS points and a few lines per session; anything larger is not one.
MAX_MANIFEST_BYTES = 64 << 20

#: How a damaged manifest is rebuilt, for the commands that only read it.
REPAIR_HINT = (
    "rebuild it from the campaign's journal: run the command that made the campaign "
    "(cwrend ablate or cwrend sweep with its configuration) again with --repair-manifest; "
    "the runs the journal holds are kept"
)

#: Types of the fields a reader uses, when present (JSON: int is not bool).
_FIELDS: dict[str, tuple[type, ...]] = {
    "campaign_hash": (str,),
    "config_hash": (str,),
    "root_seed": (int,),
    "config": (dict,),
    "grid": (dict,),
    "design": (dict, type(None)),
    "seeds": (list,),
    "archs": (list,),
    "sessions": (list,),
    "status": (str,),
    "pairs": (list,),  # the pairs added by --pair A:B, as "A:B" (pair_texts)
    "nis_offset_given": (bool,),  # the base's schedule.nis_offset was given (absent: true)
    "xf_given": (bool,),  # the base's scenario.xf was given (absent: true)
}


class ManifestError(ConfigError):
    """A campaign's ``manifest.json`` is damaged (exit 2, the file and the fix named)."""


def _no_constant(name: str) -> Any:
    """``json`` hook: NaN and Infinity are not JSON, and cwrend never writes them."""
    raise ValueError(f"holds {name}, which is not JSON")


def _problem(path: Path) -> tuple[dict[str, Any] | None, str]:
    """The manifest at ``path`` and ``""``, or ``None`` and what is wrong with it."""
    try:
        with open(path, "rb") as file:
            data = file.read(MAX_MANIFEST_BYTES + 1)
    except OSError as exc:
        return None, f"cannot be read ({exc.strerror or exc})"
    if len(data) > MAX_MANIFEST_BYTES:
        return None, f"larger than {MAX_MANIFEST_BYTES:,} bytes"
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        return None, f"not UTF-8 text ({exc.reason} at byte {exc.start})"
    try:
        value = json.loads(text, parse_constant=_no_constant)
    except RecursionError:
        return None, "nested too deep to be a manifest"
    except json.JSONDecodeError as exc:
        return None, f"not JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})"
    except ValueError as exc:  # NaN, Infinity
        return None, str(exc)
    if not isinstance(value, dict):
        return None, f"not a JSON object (a manifest is a table; found {_kind(value)})"
    for name, types in _FIELDS.items():
        field = value.get(name)
        if name in value and (
            not isinstance(field, types) or (isinstance(field, bool) and bool not in types)
        ):
            expected = " or ".join("null" if t is type(None) else _JSON_NAMES[t] for t in types)
            return None, f'"{name}" is {_kind(value[name])}, not {expected}'
    pairs = value.get("pairs", [])
    if not all(isinstance(p, str) and len(p.split(":")) == 2 for p in pairs):
        return None, '"pairs" holds an entry that is not a string "A:B"'
    seed = value.get("root_seed")
    if isinstance(seed, int) and not 0 <= seed <= MAX_SEED:
        return None, f'"root_seed" = {seed} is outside [0, {MAX_SEED}]'
    return value, ""


_JSON_NAMES: dict[type, str] = {
    dict: "an object",
    list: "an array",
    str: "a string",
    int: "an integer",
    float: "a number",
    bool: "true or false",
}


def _kind(value: Any) -> str:
    """``value``'s JSON kind, in words."""
    if value is None:
        return "null"
    for kind in (bool, dict, list, str, int, float):
        if isinstance(value, kind):
            return _JSON_NAMES[kind]
    return type(value).__name__


def read_manifest(path: Path, fix: str) -> dict[str, Any]:
    """The manifest at ``path`` as a dict whose used fields have their types.

    :class:`ManifestError` (``path: damaged manifest (what); fix``) otherwise;
    ``fix`` tells the user what to do in the calling command.
    """
    value, problem = _problem(path)
    if value is None:
        raise ManifestError(f"{path}: damaged manifest ({problem}); {fix}")
    return value


def damaged(path: Path) -> str:
    """What is wrong with the manifest at ``path`` (``""`` when it reads)."""
    return _problem(path)[1]


def pair_texts(pairs: Sequence[tuple[str, str]]) -> list[str]:
    """The ``pairs`` field of a manifest: each pair as ``"A:B"`` (as ``--pair`` takes it)."""
    return [f"{a}:{b}" for a, b in pairs]


def recorded_pairs(manifest: Mapping[str, Any]) -> tuple[tuple[str, str], ...]:
    """The pairs a campaign's manifest records (``--pair A:B`` of its commands), in order.

    ``manifest`` as :func:`read_manifest` returns it (entries checked); none when the
    campaign was written before manifests recorded them or added no pair.
    """
    pairs = manifest.get("pairs", [])
    return tuple((a, b) for a, b in (str(p).split(":") for p in pairs))


def nis_offset_given(manifest: Mapping[str, Any]) -> bool:
    """Whether the campaign's base config gave ``schedule.nis_offset`` (``nis_offset_given``).

    ``manifest`` as :func:`read_manifest` returns it; true when it does not say
    (written before manifests recorded it): its ``config``'s offset is then kept
    at every point, as reports read it before.
    """
    return bool(manifest.get("nis_offset_given", True))


def xf_given(manifest: Mapping[str, Any]) -> bool:
    """Whether the campaign's base config gave ``scenario.xf`` (``xf_given``; true when the
    manifest does not say, as :func:`nis_offset_given`)."""
    return bool(manifest.get("xf_given", True))


def pairs_recorded_at(path: Path) -> tuple[tuple[str, str], ...]:
    """:func:`recorded_pairs` of the manifest at ``path``; none when it is absent or
    damaged (the command that reads it next says what is wrong and how to repair it)."""
    value, _ = _problem(path)
    return recorded_pairs(value) if value is not None else ()
