"""Every dotted-key operation on a configuration tree, and the names the user types.

A dotted key such as ``schedule.beta`` or ``degradation.windows.1.bias_km``
names one value of a config tree (integer components index arrays). Here:
``--set key=value`` overrides (:func:`parse_override`, :func:`set_dotted`),
reading a value (:func:`get_dotted`), campaign grids (``--param`` and the
``[sweep]`` table: :func:`parse_param`, :func:`expand_grid`) and applying an
assignment of values to a tree (:func:`apply`), plus architecture slugs
(:func:`parse_arch`). The trees are plain JSON-style dicts and lists; nothing
is validated here (see :func:`cwrend_cli.config.io.config_from_dict`).
"""

from __future__ import annotations

import copy
import functools
import math
import tomllib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from decimal import Context, Decimal, localcontext
from types import MappingProxyType
from typing import Any

from cwrend_cli.config.messages import closest_all, did_you_mean, table_value_problem
from cwrend_cli.config.schema import CwrendConfig
from cwrend_cli.errors import ConfigError
from cwrend_cli.limits import MAX_NESTING, MAX_SWEPT_KEYS, MAX_VALUES_PER_KEY
from cwrend_cli.physics.params import (
    ALL_ARCHITECTURES,
    ARCHITECTURES,
    SOCP_ARCHITECTURES,
    STF_ARCHITECTURES,
    Architecture,
)

__all__ = [
    "ARCH_GROUPS",
    "apply",
    "check_given_once",
    "check_swept",
    "expand_grid",
    "get_dotted",
    "missing_key_hint",
    "nesting_depth",
    "parse_arch",
    "parse_archs",
    "parse_override",
    "parse_param",
    "replaced_sweep_keys",
    "set_dotted",
]

# ---------------------------------------------------------------------------
# Overrides (``--set dotted.key=value``)
# ---------------------------------------------------------------------------


def nesting_depth(value: Any, level: int = 0) -> int:
    """Nesting depth of tables and arrays, counted no further than :data:`MAX_NESTING` + 1."""
    if level > MAX_NESTING:
        return level
    if isinstance(value, dict):
        return max((nesting_depth(v, level + 1) for v in value.values()), default=level + 1)
    if isinstance(value, list):
        return max((nesting_depth(v, level + 1) for v in value), default=level + 1)
    return level


def _parse_value(raw: str, key: str) -> Any:
    """A TOML value (``1e-3``, ``"mean"``, ``[1, 2]``, ``true``), else the bare string.

    Refused like a file's (:data:`MAX_NESTING`): a value whose tables and arrays,
    under its key, nest deeper than a configuration file may (issue 36 item 8).
    """
    try:
        parsed = tomllib.loads(f"v = {raw}")
    except tomllib.TOMLDecodeError:
        return raw
    except RecursionError:  # thousands of levels: the parser gives up before we could count
        parsed = None
    if parsed is None or nesting_depth(parsed, key.count(".")) > MAX_NESTING:
        raise ConfigError(
            f"{key[:80]} = …: the value's tables and arrays nest more than {MAX_NESTING} "
            "levels deep with its key's (a configuration file may not either)"
        )
    return parsed["v"] if parsed.keys() == {"v"} else raw


def _split_key(key: str) -> list[str]:
    """Split a dotted key, rejecting empty and quoted components."""
    if '"' in key or "'" in key:
        raise ConfigError(
            f"malformed key {key[:80]!r}: quoted key components are not read; write the "
            "key unquoted (e.g. target.body_rates_deg_s), and sweep a key with --param "
            "KEY=v1,v2 or --param 'KEY=[v1, v2]' (vectors: 'KEY=[[1, 2, 3], [4, 5, 6]]')"
        )
    parts = [p.strip() for p in key.split(".")]
    if not key.strip() or any(not p for p in parts):
        raise ConfigError(f"malformed key {key[:80]!r}: empty key component")
    return parts


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``dotted.key=value`` into ``(key, value)``; the value is read as TOML.

    Raises :class:`ConfigError` when there is no ``=`` or the key is empty.
    """
    if "=" not in text:
        raise ConfigError(
            f"malformed override {text!r}: expected KEY=VALUE, e.g. schedule.beta=0.5"
        )
    key, raw = text.split("=", 1)
    key = key.strip()
    if not key:
        raise ConfigError(f"malformed override {text!r}: empty key")
    _split_key(key)
    return key, _parse_value(raw.strip(), key)


def _thaw(value: Any) -> Any:
    """Deep copy into plain dicts and lists so the tree can be edited in place."""
    if isinstance(value, Mapping):
        return {k: _thaw(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_thaw(v) for v in value]
    return copy.deepcopy(value)


@functools.cache
def _default_tree() -> dict[str, Any]:
    """The defaults as a plain JSON-style tree (lists, dicts), built once.

    Shared between calls: readers walk it and copy (``_thaw``) what they keep,
    never modify it.
    """
    return CwrendConfig().model_dump(mode="json")


#: Digits of an array index in a dotted key: the longest array of a configuration
#: (a degradation window list) is far shorter.
_INDEX_DIGITS = 6


def _array_index(part: str) -> int:
    """A key component as an array index: ASCII digits only (``str.isdigit`` also takes
    ``²``, which ``int`` refuses), at most :data:`_INDEX_DIGITS`; else :class:`ValueError`."""
    if not (part.isascii() and part.isdigit()) or len(part) > _INDEX_DIGITS:
        raise ValueError(f"not an array index: {part[:20]!r}")
    return int(part)


def _index(part: str, seq: list[Any], prefix: str) -> int:
    """A non-negative list index from a key component, range-checked."""
    try:
        idx = _array_index(part)
    except ValueError:
        raise ConfigError(
            f"{prefix}: is an array, use an index of at most {_INDEX_DIGITS} ASCII digits "
            f"(0 to {len(seq) - 1}) instead of {part[:20]!r}"
        ) from None
    if idx >= len(seq):
        raise ConfigError(f"{prefix}: index {idx} out of range ({len(seq)} entries)")
    return idx


def set_dotted(data: Mapping[str, Any], key: str, value: Any) -> dict[str, Any]:
    """Return a copy of ``data`` with ``value`` set at dotted ``key``.

    Integer components index arrays (``degradation.windows.1.bias_km``). A
    missing table on the way is created; a missing array is first filled with
    its default, so indexing the default degradation windows works on an empty
    file. No validation happens here: an unknown key ends up in the tree and is
    rejected by :func:`~cwrend_cli.config.io.config_from_dict` like an unknown
    key in the file.
    """
    root: dict[str, Any] = _thaw(data)
    _set_in_place(root, key, value)
    return root


def _set_in_place(root: dict[str, Any], key: str, value: Any) -> None:
    """Set ``value`` at dotted ``key`` of the tree ``root``, which it owns (see :func:`set_dotted`).

    Touches only the path to ``key``: setting k keys costs O(k) whatever the
    tree's size (issue 36 item 11: copying the tree for each key of a 38,000-key
    ``[sweep]`` took 350 s).
    """
    parts = _split_key(key)
    node: Any = root
    default: Any = _default_tree()
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(node, dict):
            default = default.get(part) if isinstance(default, dict) else None
            if last:
                node[part] = _thaw(value)
                break
            if part not in node:
                # Arrays are filled from the defaults so they can be indexed;
                # tables start empty so omitted keys keep meaning "default".
                node[part] = _thaw(default) if isinstance(default, list) else {}
            node = node[part]
        elif isinstance(node, list):
            idx = _index(part, node, ".".join(parts[:i]))
            default = default[idx] if isinstance(default, list) and idx < len(default) else None
            if last:
                node[idx] = _thaw(value)
                break
            node = node[idx]
        else:
            parent = ".".join(parts[:i])
            raise ConfigError(f"cannot set {key}: {parent} is a value, not a table")


def get_dotted(tree: Mapping[str, Any], key: str) -> Any:
    """Value at a dotted key of a JSON tree (integer components index arrays)."""
    node: Any = tree
    for part in key.split("."):
        node = node[part] if isinstance(node, Mapping) else node[_array_index(part)]
    return node


def missing_key_hint(tree: Mapping[str, Any], key: str) -> str:
    """Why the dotted ``key`` names no value of ``tree``, as a hint to append, else ``""``.

    A table without the component: ``"; did you mean 'scenario.x0.2'?"``, the closest
    dotted key of the tree's values (:func:`~cwrend_cli.config.messages.closest`); an
    index out of range: ``" (scenario.x0 has 6 entries: 0 to 5)"``.
    """
    parts = key.split(".")
    node: Any = tree
    for i, part in enumerate(parts):
        if isinstance(node, Mapping) and part in node:
            node = node[part]
        elif isinstance(node, list):
            try:
                node = node[_array_index(part)]
            except (ValueError, IndexError):
                last = f": 0 to {len(node) - 1}" if node else ""
                return f" ({'.'.join(parts[:i])} has {len(node)} entries{last})"
        elif isinstance(node, Mapping):
            near = closest_all(key, list(_dotted_keys(tree)))
            return f"; did you mean {' or '.join(repr(k) for k in near)}?" if near else ""
        else:
            return ""
    return ""


def _dotted_keys(node: Any, prefix: str = "") -> Iterator[str]:
    """The dotted keys of every value (a leaf: neither a table nor an array) of a tree."""
    if isinstance(node, Mapping):
        items: Iterable[tuple[Any, Any]] = node.items()
    elif isinstance(node, list):
        items = enumerate(node)
    else:
        yield prefix
        return
    for k, v in items:
        yield from _dotted_keys(v, f"{prefix}.{k}" if prefix else str(k))


def apply(base: Mapping[str, Any], assignment: Iterable[tuple[str, Any]]) -> dict[str, Any]:
    """A copy of ``base`` with every ``(key, value)`` of ``assignment`` set, in order.

    ``base`` is copied once, then each key is set in place: linear in the keys.
    """
    tree: dict[str, Any] = _thaw(base)
    for key, value in assignment:
        _set_in_place(tree, key, value)
    return tree


def point_tree(
    base: Mapping[str, Any],
    assignment: Sequence[tuple[str, Any]],
    offset_given: bool = True,
    xf_given: bool = True,
) -> dict[str, Any]:
    """The config tree of a campaign's point or run: ``base`` with ``assignment`` set.

    ``base`` is a resolved tree (the manifest's ``config``); ``offset_given``: the
    user gave its ``schedule.nis_offset`` (:func:`~cwrend_cli.config.schema.nis_offset_given`
    of the base config; a resolved tree has lost that). If not, and ``assignment``
    sets the sensor but not the offset, the offset is left out so that validation
    fills it in for the point's sensor (its measurement dimension m, paper Eq. 24),
    not kept at the base's resolved value (:func:`apply` otherwise). Likewise
    ``scenario.xf`` of a base with a corridor, where it is the port at rest (filled
    in or given so: validation requires it), or of a base without one whose
    ``scenario.xf`` the user did not give (``xf_given``: :func:`~cwrend_cli.config.schema.xf_given`;
    the resolved tree holds the default): an assignment that moves or introduces
    the port (``constraints.corridor.port_km``, or the whole ``constraints.corridor``)
    but sets no ``scenario.xf`` leaves it out, so that it is the point's port at
    rest. One place for the campaign that runs the point and the report that draws it.
    """
    tree = apply(base, assignment)
    keys = [k for k, _ in assignment]
    if (
        not offset_given
        and _touches(keys, "sensor")
        and not any(k in ("schedule", "schedule.nis_offset") for k in keys)
    ):
        tree["schedule"] = {k: v for k, v in tree["schedule"].items() if k != "nis_offset"}
    corridor = (base.get("constraints") or {}).get("corridor")
    if (
        (corridor is not None or not xf_given)
        and moves_port(keys)
        and not _touches(keys, "scenario.xf")
    ):
        tree["scenario"] = {k: v for k, v in tree["scenario"].items() if k != "xf"}
    return tree


#: The corridor's docking port: with a corridor, also the terminal state (``scenario.xf``,
#: the port at rest), so a point that moves it ends there (:func:`point_tree`).
CORRIDOR_PORT = "constraints.corridor.port_km"


def moves_port(keys: Iterable[str]) -> bool:
    """Whether one of the dotted ``keys`` sets the corridor's port (:data:`CORRIDOR_PORT`,
    an entry of it, or a table above it)."""
    return _touches(keys, CORRIDOR_PORT)


def _touches(keys: Iterable[str], key: str) -> bool:
    """Whether one of the dotted ``keys`` sets ``key``: itself, a table above it or a part of it."""
    return any(k == key or k.startswith(key + ".") or key.startswith(k + ".") for k in keys)


# ---------------------------------------------------------------------------
# Campaign grids (``--param`` and the ``[sweep]`` table)
# ---------------------------------------------------------------------------


def parse_param(text: str) -> tuple[str, tuple[Any, ...]]:
    """``key=v1,v2,v3``, ``key=[v1, v2, v3]`` or ``key=start:stop:num`` into ``(key, values)``.

    Values are read as TOML scalars (``0.5``, ``"mean"``, ``true``); a bare
    word is a string. A TOML array lists the values as a file's ``[sweep]`` does, so a
    vector-valued key is swept as ``key=[[1, 2, 3], [4, 5, 6]]``. A range gives ``num``
    evenly spaced floats. Vectors may also be listed with commas, ``key=[1, 2, 3],[4, 5, 6]``.
    """
    if "=" not in text:
        raise ConfigError(
            f"--param {text!r}: expected KEY=VALUES, e.g. schedule.beta=0.1,0.25,0.5 "
            "or schedule.beta=0.1:0.5:5 (start:stop:num)"
        )
    key, raw = parse_override(text)
    raw_text = text.split("=", 1)[1].strip()
    if isinstance(raw, list):  # a TOML array: the values, as a file's [sweep] lists them
        if not raw:
            raise ConfigError(f"--param {text!r}: the list of values is empty")
        return key, tuple(raw)
    if isinstance(raw, str) and raw.count(":") == 2 and "," not in raw_text:
        return key, _range_values(key, raw)
    if isinstance(raw, str) and ":" in raw and "," not in raw_text and _numbers(raw.split(":")):
        raise ConfigError(  # 0.1:0.5 (no num) or 0:1:5:2: a range meant, not a string
            f"--param {text!r}: a range is start:stop:num, e.g. {key}=0.1:0.5:5"
        )
    if raw_text.startswith(("[", "{")):  # vectors or tables listed with commas, [1, 2],[3, 4]:
        listed = _parse_value(f"[{raw_text}]", key)  # the commas inside them are theirs
        if isinstance(listed, list):
            return key, tuple(listed)
    parts = [p.strip() for p in raw_text.split(",")]
    if any(not p for p in parts):
        raise ConfigError(f"--param {text!r}: empty value in the list")
    return key, tuple(parse_override(f"{key}={p}")[1] for p in parts)


def _numbers(parts: Sequence[str]) -> bool:
    """Whether every one of ``parts`` is a decimal number."""
    try:
        for part in parts:
            Decimal(part.strip())
    except ArithmeticError:  # decimal.InvalidOperation
        return False
    return True


#: Significant digits of a computed parameter value (a range's interior points, a design's
#: sampled floats): the value a run uses is the value printed and stored.
SIGNIFICANT_DIGITS = 10


def decimal_float(value: float | Decimal, digits: int = SIGNIFICANT_DIGITS) -> float:
    """``value`` rounded to ``digits`` significant digits, as a float (one conversion).

    What a person would write: ``0.0008``, not ``0.0007999999999999999``.
    Shared by grid ranges (:func:`_range_values`, from exact decimals) and
    sampled designs (:mod:`cwrend_cli.campaign.design`, from floats).
    """
    return float(f"{value:.{digits}g}")


def _range_values(key: str, spec: str) -> tuple[float, ...]:
    """``start:stop:num``: ``num`` evenly spaced values from ``start`` to ``stop``, as written.

    Computed in decimal arithmetic from the numbers as typed (``start + i·(stop −
    start)/(num − 1)``, exact for any decimal step) and converted to a float
    once (:func:`decimal_float`, to at least :data:`SIGNIFICANT_DIGITS`
    significant digits and as many as ``start`` or ``stop`` has), so
    ``6e-4:1e-3:5`` gives exactly 0.0006, 0.0007, 0.0008, 0.0009 and 0.001.
    Until 2026-12-02 the values were ``numpy.linspace``'s, which carry float
    noise (0.0007999999999999999, 0.30000000000000004).
    """
    syntax = f"sweep {key} = {spec!r}: a range is 'start:stop:num' with numbers, e.g. 0.1:0.5:5"
    try:
        start, stop, num = spec.split(":")
        count = int(num)
        first, last = Decimal(start.strip()), Decimal(stop.strip())
    except (ValueError, ArithmeticError):  # decimal.InvalidOperation is an ArithmeticError
        raise ConfigError(syntax) from None
    if not 1 <= count <= MAX_VALUES_PER_KEY:
        raise ConfigError(
            f"sweep {key} = {spec!r}: num must be between 1 and {MAX_VALUES_PER_KEY:,}"
        )
    if not (first.is_finite() and last.is_finite()):
        raise ConfigError(syntax)
    digits = max(SIGNIFICANT_DIGITS, *(len(d.as_tuple().digits) for d in (first, last)))
    values = [first]  # one value: start (as numpy.linspace)
    if count > 1:
        with localcontext(Context(prec=max(40, 2 * digits))):
            step = (last - first) / (count - 1)
            values = [first + i * step for i in range(count - 1)] + [last]
    floats = tuple(decimal_float(v, digits) for v in values)
    if not all(math.isfinite(v) for v in floats):  # e.g. 1e999 (finite as a decimal)
        raise ConfigError(syntax)
    return floats


#: The fields of a design's range in ``[sweep]`` (:func:`cwrend_cli.campaign.design.parse_range`).
RANGE_FIELDS = frozenset({"low", "high", "log", "int", "values"})


def is_range(value: Any) -> bool:
    """Whether a ``[sweep]`` value is a design's range: a table with one of
    :data:`RANGE_FIELDS` (a table without any is a whole table, not a range)."""
    return isinstance(value, Mapping) and bool(RANGE_FIELDS & set(value))


def mixed_sweep_problem(sweep: Mapping[str, Any]) -> str | None:
    """What is wrong with a ``[sweep]`` that mixes grid values and a design's ranges (None
    when it does not): a sweep is a grid (every key lists values) or a design (every key a
    range table), and the message names the keys of each kind, whichever command reads it
    (``sweep``, ``sweep --design``, ``config validate``)."""
    ranges = [key for key, value in sweep.items() if is_range(value)]
    grid = [key for key, value in sweep.items() if not is_range(value)]
    if not ranges or not grid:
        return None
    return (
        f"[sweep] mixes grid values ({', '.join(grid)}) with ranges ({', '.join(ranges)}): "
        "a sweep is a grid (every key lists values: [v1, v2] or 'start:stop:num') or a "
        "design (every key a range table, run with --design lhs|sobol|random --samples N); "
        "give the grid's keys ranges, or the ranges' keys lists of values"
    )


def expand_grid(
    sweep: Mapping[str, Any], cli_params: Sequence[str] = ()
) -> tuple[tuple[str, tuple[Any, ...]], ...]:
    """The swept keys and their values: ``[sweep]`` table, then ``--param`` (which wins).

    A ``--param`` key that is also in ``[sweep]`` replaces the table's values for that
    key (:func:`replaced_sweep_keys` names them, for the command's note). Refused
    (:class:`ConfigError`): a key given by two ``--param`` options, a value listed twice
    for one key, and an ``output.*`` key (it changes no number of a run). At most
    :data:`~cwrend_cli.limits.MAX_SWEPT_KEYS` keys in all, refused before any is read.
    """
    if (
        len(sweep) + len(cli_params) > MAX_SWEPT_KEYS
        and len(set(sweep) | {text.split("=", 1)[0].strip() for text in cli_params})
        > MAX_SWEPT_KEYS
    ):
        raise ConfigError(
            f"sweep: more than {MAX_SWEPT_KEYS:,} swept keys ([sweep] and --param together); "
            "a grid of 2 values per key passes the point limit at 14 keys"
        )
    mixed = mixed_sweep_problem(sweep)
    if mixed is not None:
        raise ConfigError(mixed)
    grid: dict[str, tuple[Any, ...]] = {}
    for key, values in sweep.items():
        if is_range(values):
            raise ConfigError(
                f"[sweep] {key}: a range table is sampled by a design: add --design "
                "lhs|sobol|random --samples N (a grid lists values: [v1, v2] or 'start:stop:num')"
            )
        if isinstance(values, Mapping):  # a whole table as the value, not a range
            raise ConfigError(f"[sweep] {key}: {table_value_problem(key, values)}")
        grid[key] = _range_values(key, values) if isinstance(values, str) else tuple(values)
    given: dict[str, str] = {}  # --param key -> its values as typed
    for text in cli_params:
        key, values = parse_param(text)
        table = next((v for v in values if isinstance(v, Mapping)), None)
        if table is not None:  # as [sweep]'s (the schema): else it ran, then failed
            raise ConfigError(f"--param {key}: {table_value_problem(key, table, param=True)}")
        raw = text.split("=", 1)[1].strip()
        if key in given:
            plain = not any(c in given[key] + raw for c in ":[")  # value lists, not ranges
            both = f"{given[key]},{raw}" if plain else "V1,V2,…"
            check_given_once(
                "--param", key, given, raw,
                f"list every value in one option: --param {key}={both} (the grid is the "
                "cartesian product of different keys)",
            )  # fmt: skip
        given[key] = raw
        grid[key] = values
    for key, values in grid.items():
        check_swept(key, values)
    return tuple(grid.items())


def check_given_once(option: str, key: str, given: Mapping[str, str], raw: str, fix: str) -> None:
    """Refuse ``option`` giving ``key`` a second time: ``given`` maps each key given so far
    to its text, ``raw`` is this one's; ``fix`` says what to write instead (``--param``
    and ``--range``: one option per key)."""
    if key in given:
        raise ConfigError(
            f"{option} {key}: given twice ({key}={given[key]} and {key}={raw}); {fix}"
        )


def check_swept(key: str, values: Sequence[Any] | None = None) -> None:
    """Refuse what no swept key may be, in a grid or a design: an ``output.*`` key (it
    changes no number of a run: its points would be identical) and, of ``values`` (a
    grid's values, a design's categories; ``None``: a design's numeric range), none,
    more than :data:`~cwrend_cli.limits.MAX_VALUES_PER_KEY`, or one listed twice (a point
    is computed once)."""
    if values is not None and not values:
        raise ConfigError(f"sweep {key}: needs at least one value")
    if values is not None and len(values) > MAX_VALUES_PER_KEY:
        raise ConfigError(
            f"sweep {key}: {len(values):,} values; at most {MAX_VALUES_PER_KEY:,} per key"
        )
    if key == "output" or key.startswith("output."):
        raise ConfigError(
            f"sweep {key}: an [output] setting changes no number of a run, so its "
            f"points would be identical; set it once (--set {key}=VALUE, or in the "
            "config) instead of sweeping it"
        )
    repeated = None if values is None else _first_repeated(values)
    if repeated is not None:
        numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values or ())
        vector = (  # one vector typed where a list of vectors was meant: [0, 0, -0.25]
            f" (if {key} is a vector, sweep whole vectors: {key}=[[x, y, z], [x, y, z]])"
            if numbers
            else ""
        )
        raise ConfigError(
            f"sweep {key}: the value {repeated!r} is listed twice; a point is "
            f"computed once: list each value once{vector}"
        )


def replaced_sweep_keys(sweep: Mapping[str, Any], cli_params: Sequence[str]) -> tuple[str, ...]:
    """The keys of the ``[sweep]`` table whose values a ``--param`` replaces, in its order."""
    given = {text.split("=", 1)[0].strip() for text in cli_params}
    return tuple(key for key in sweep if key in given)


def _hashable(value: Any) -> Any:
    """``value`` with lists and tables as tuples, so equal values compare and hash equal."""
    if isinstance(value, Mapping):
        return tuple(sorted((str(k), _hashable(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return tuple(_hashable(v) for v in value)
    return value


def _first_repeated(values: Sequence[Any]) -> Any | None:
    """The first value of ``values`` equal to an earlier one (``0.1`` and ``0.10``), or None."""
    seen: set[Any] = set()
    for value in values:
        frozen = _hashable(value)
        if frozen in seen:
            return value
        seen.add(frozen)
    return None


# ---------------------------------------------------------------------------
# Architectures (the ablation of paper Sec. "Numerical Results and Discussion")
# ---------------------------------------------------------------------------


def parse_arch(slug: str) -> Architecture:
    """Return the architecture named ``slug``; :class:`ConfigError` lists the valid slugs."""
    try:
        return ALL_ARCHITECTURES[slug.strip()]
    except KeyError:
        allowed = ", ".join(ALL_ARCHITECTURES)
        groups = ", ".join(ARCH_GROUPS)
        hint = did_you_mean(slug.strip(), [*ALL_ARCHITECTURES, *ARCH_GROUPS])
        raise ConfigError(
            f"unknown architecture {slug!r} (allowed: {allowed}; or one group: {groups}){hint}"
        ) from None


#: Names of architecture groups accepted by :func:`parse_archs`.
ARCH_GROUPS: Mapping[str, tuple[Architecture, ...]] = MappingProxyType(
    {
        "all": tuple(ARCHITECTURES.values()),  # the paper's ablation (shooting)
        "all_socp": tuple(SOCP_ARCHITECTURES.values()),  # the same with the cone program
        "everything": (*ARCHITECTURES.values(), *SOCP_ARCHITECTURES.values()),  # both
        # the same three with the single-factor baseline (issue 35) appended
        "with_stf": (
            *ARCHITECTURES.values(),
            *(a for a in STF_ARCHITECTURES.values() if a.method is None),
        ),
        "with_stf_socp": (
            *SOCP_ARCHITECTURES.values(),
            *(a for a in STF_ARCHITECTURES.values() if a.method == "socp"),
        ),
        "everything_with_stf": tuple(ALL_ARCHITECTURES.values()),
    }
)


def parse_archs(text: str) -> tuple[Architecture, ...]:
    """A group name (:data:`ARCH_GROUPS`) or comma-separated slugs, each named once.

    A slug named twice is refused (``cwrend run --arch a,a`` printed every row
    twice): the one check of ``run``, ``ablate`` and ``sweep``.
    """
    group = ARCH_GROUPS.get(text.strip())
    if group is not None:
        return group
    archs = tuple(parse_arch(part) for part in text.split(",") if part.strip())
    if not archs:
        raise ConfigError(f"--arch {text!r}: name at least one of {', '.join(ALL_ARCHITECTURES)}")
    repeated = _first_repeated([a.slug for a in archs])
    if repeated is not None:
        once = ",".join(dict.fromkeys(a.slug for a in archs))
        raise ConfigError(
            f"--arch {text!r}: {repeated} is named twice; name each architecture once: "
            f"--arch {once}"
        )
    return archs
