"""Error texts of the configuration: what a user reads when a value is refused.

Validators of :mod:`cwrend_cli.config.schema` raise :func:`rules_error` for
rules that span fields; :func:`format_validation_error` turns a pydantic
:class:`~pydantic.ValidationError` into one line per problem,
``dotted.path = value: what is allowed``. Numbers are written by
:func:`fmt_num` (``1`` rather than ``1.0``).

This module imports no config model, so the schema can import it; the model
used to list the allowed keys of a table is passed in (``root_model``).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from types import UnionType
from typing import Any, Union, get_args, get_origin

from pydantic import BaseModel, ValidationError
from pydantic_core import PydanticCustomError

from cwrend_cli.limits import MAX_LISTED_PROBLEMS

__all__ = [
    "closest_all",
    "did_you_mean",
    "fmt_num",
    "format_validation_error",
    "rules_error",
    "table_value_problem",
]

# ---------------------------------------------------------------------------
# Errors raised from validators. Model-level rules report the field they are
# about (possibly several), so the message names ``schedule.eps_min`` rather
# than just ``schedule``.
# ---------------------------------------------------------------------------

_RULES_ERROR = "cwrend_rules"


def rules_error(problems: Sequence[tuple[str, Any, str]]) -> PydanticCustomError:
    """Build one validation error carrying ``(field, value, message)`` problems.

    ``field`` is a dotted path relative to the model raising the error.
    """
    summary = "; ".join(f"{f} = {_fmt_value(v)}: {m}" for f, v, m in problems)
    return PydanticCustomError(
        _RULES_ERROR,
        "{summary}",
        {"summary": summary, "problems": tuple((f, _fmt_value(v), m) for f, v, m in problems)},
    )


def table_value_problem(key: str, table: Mapping[str, Any], param: bool = False) -> str:
    """Why a table (``table``) is not a value a grid sweeps ``key`` over (``[sweep]``, or
    ``--param``: ``param``), and what is: the values a grid takes, the table's entries by
    their own keys, or the whole table set once."""
    field = next((str(k) for k in table), "FIELD")
    entry = f"--param {key}.{field}=a,b" if param else f'"{key}.{field}" = [a, b]'
    return (
        "a table is not a grid value: a grid sweeps numbers, strings, true/false or arrays "
        "of numbers, listed [v1, v2, …] or as 'start:stop:num'; sweep the table's entries "
        f"by their own keys ({entry}, crossed with the other swept keys), or set the whole "
        f"table once (--set '{key}={{ … }}')"
    )


def fmt_num(x: float) -> str:
    """Shortest faithful text for a number (``1`` rather than ``1.0``)."""
    if isinstance(x, float) and x.is_integer() and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def _fmt_value(value: Any, limit: int = 80) -> str:
    """Render an offending value compactly, TOML/JSON style, truncated to ``limit``."""
    if isinstance(value, float):
        text = fmt_num(value)
    else:
        try:
            text = json.dumps(value, default=repr, allow_nan=True)
        except (TypeError, ValueError):
            text = repr(value)
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    return text


def did_you_mean(word: object, choices: Sequence[str]) -> str:
    """``"; did you mean 'beta'?"`` for the closest of ``choices`` to ``word``, else ``""``.

    The one suggestion every "unknown …" error appends (config keys, architectures,
    table fields): :func:`difflib.get_close_matches` with its default similarity
    cutoff (0.6), so an unrelated word gets no suggestion.
    """
    import difflib

    if not isinstance(word, str):
        return ""
    near = difflib.get_close_matches(word, list(choices), n=1)
    return f"; did you mean {near[0]!r}?" if near else ""


def closest_all(word: object, choices: Sequence[str]) -> list[str]:
    """The ``choices`` closest to ``word``, all of them when several are as close (in order).

    :func:`difflib.SequenceMatcher`'s ratio with :func:`difflib.get_close_matches`'s
    default cutoff (0.6); ``scenario.xo.2`` is as close to ``scenario.x0.2`` as to
    ``scenario.xf.2``, and both are named.
    """
    import difflib

    if not isinstance(word, str):
        return []
    best: list[str] = []
    top = 0.6
    matcher = difflib.SequenceMatcher(b=word)
    for choice in choices:
        matcher.set_seq1(choice)
        if matcher.real_quick_ratio() < top or matcher.quick_ratio() < top:
            continue
        ratio = matcher.ratio()
        if ratio > top or (ratio == top and not best):
            best, top = [choice], ratio
        elif ratio == top:
            best.append(choice)
    return best


# ---------------------------------------------------------------------------
# Validation-error formatting
# ---------------------------------------------------------------------------


def _model_at(root_model: type[BaseModel], loc: Sequence[str | int]) -> type[BaseModel] | None:
    """The config model class found at ``loc`` inside ``root_model``, if any.

    An optional table (``KeepOutConfig | None``) is its model, so that a key inside
    ``constraints.keep_out`` or ``constraints.keep_out.bodies.0`` is looked up too.
    """
    tp: Any = root_model
    for part in loc:
        tp = _optional_model(tp)
        if isinstance(part, int):
            args = get_args(tp)
            if get_origin(tp) is tuple and args:
                tp = args[0]
                continue
            return None
        if isinstance(tp, type) and issubclass(tp, BaseModel) and part in tp.model_fields:
            tp = tp.model_fields[part].annotation
        else:
            return None
    tp = _optional_model(tp)
    return tp if isinstance(tp, type) and issubclass(tp, BaseModel) else None


def _optional_model(tp: Any) -> Any:
    """The one model of an optional type ``Model | None``; any other type unchanged."""
    if get_origin(tp) in (Union, UnionType):
        members = [a for a in get_args(tp) if a is not type(None)]
        if len(members) == 1:
            return members[0]
    return tp


def _describe(err: Mapping[str, Any]) -> str:
    """What is allowed, in words, for one pydantic error dict."""
    kind = err["type"]
    ctx = err.get("ctx") or {}
    bounds = {
        "greater_than": ("gt", ">"),
        "greater_than_equal": ("ge", ">="),
        "less_than": ("lt", "<"),
        "less_than_equal": ("le", "<="),
    }
    if kind in bounds:
        key, op = bounds[kind]
        return f"must be {op} {fmt_num(ctx[key])}"
    simple = {
        "finite_number": "must be a finite number",
        "float_type": "must be a number",
        "float_parsing": "must be a number",
        "int_type": "must be an integer",
        "int_parsing": "must be an integer",
        "int_from_float": "must be an integer",
        "bool_type": "must be true or false",
        "bool_parsing": "must be true or false",
        "string_type": "must be a string",
        "tuple_type": "must be an array",
        "list_type": "must be an array",
        "model_type": "must be a table",
        "model_attributes_type": "must be a table",
        "dict_type": "must be a table",
    }
    if kind in _CONTAINER_TYPES:
        return f"{simple[kind]} ({_CONTAINER_TYPES[kind]}), got {_given(err.get('input'))}"
    if kind in simple:
        return simple[kind]
    if kind == "literal_error":
        return f"must be one of {ctx.get('expected', '')}"
    if kind in ("too_short", "too_long"):
        n = ctx.get("min_length", ctx.get("max_length"))
        if isinstance(err.get("input"), Mapping):  # a table of at most n keys
            return f"at most {n:,} keys (got {len(err['input']):,})"
        return f"must have {n} entries (got {ctx.get('actual_length')})"
    if kind == "string_too_short":
        return "must not be empty"
    msg = str(err.get("msg", kind))
    return msg.removeprefix("Value error, ")


#: Error types of a value that must be an array or a table: how one is written.
_CONTAINER_TYPES = {
    "tuple_type": "written [v1, v2, …]",
    "list_type": "written [v1, v2, …]",
    "model_type": "a [section] or { key = value, … }",
    "model_attributes_type": "a [section] or { key = value, … }",
    "dict_type": "a [section] or { key = value, … }",
}


def _given(value: Any) -> str:
    """What a value of the wrong type is, in words: ``a number``, ``a string, …``."""
    if isinstance(value, bool):
        return "true/false"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, Mapping):
        return "a table"
    if isinstance(value, (list, tuple)):
        return "an array"
    if isinstance(value, str):
        if value.lstrip().startswith(("[", "{")) or "," in value:
            return (
                "a string that is not a valid TOML array or table (check its brackets, "
                "commas and quotes; a --set value that is not valid TOML is read as a string)"
            )
        return "a string"
    return type(value).__name__


#: Error types of a union member the input is not of (a number given where the
#: member is an array, or an array where it is a number).
_TYPE_MISMATCH = frozenset({"tuple_type", "list_type", "float_type", "int_type"})


def _is_union_tag(part: object) -> bool:
    """True for the part of an error location naming a member of a union type
    (``constrained-float``, ``tuple[constrained-float, ...]``), never a field name."""
    return isinstance(part, str) and ("[" in part or "-" in part or part in ("float", "int"))


def _union_errors_merged(errors: Sequence[Any]) -> list[Any]:
    """``errors`` with the members of a union value (``r_scale``: one number or one per
    component) merged: the member the input is not of is dropped, and the location
    names the field alone. An input of neither kind gets one error."""
    out: list[Any] = []
    seen: dict[tuple[Any, ...], int] = {}
    for err in errors:
        loc = tuple(err["loc"])
        if not any(_is_union_tag(p) for p in loc):
            out.append(err)
            continue
        bare = tuple(p for p in loc if not _is_union_tag(p))
        merged = {**err, "loc": bare}
        if bare not in seen:
            seen[bare] = len(out)
            out.append(merged)
        elif out[seen[bare]]["type"] in _TYPE_MISMATCH:
            if err["type"] in _TYPE_MISMATCH:  # neither a number nor an array
                msg = f"must be a number or an array of numbers, got {_given(err.get('input'))}"
                out[seen[bare]] = {**merged, "type": "value_error", "msg": msg}
            else:
                out[seen[bare]] = merged
        elif err["type"] not in _TYPE_MISMATCH:
            out.append(merged)  # a second genuine problem (two entries of an array)
    return out


#: A number followed by a unit (``800s``, ``8e-4 km/s^2``): a number meant, with its unit.
_NUMBER_WITH_UNIT = re.compile(r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*[^\d\s.,].*$")
#: A unit in brackets in a field's description (``[s]``, ``[km/s²]``; ranges hold digits).
_UNIT = re.compile(r"\[([^\[\]\d]+)\]")


def _unit_hint(
    root_model: type[BaseModel], loc: Sequence[str | int], err: Mapping[str, Any]
) -> str:
    """``; write the number alone, in s`` for a number given with a unit (``800s``): the unit
    is the key's (its description's last bracket without digits), never written."""
    text = err.get("input")
    if err["type"] not in ("float_type", "float_parsing") or not isinstance(text, str):
        return ""
    if not _NUMBER_WITH_UNIT.match(text):
        return ""
    names = [p for p in loc if isinstance(p, str)]
    model = _model_at(root_model, names[:-1]) if names else None
    field = model.model_fields.get(names[-1]) if model is not None else None
    units = _UNIT.findall(field.description or "") if field is not None else []
    return f"; write the number alone, in {units[-1]}" if units else "; write the number alone"


def format_validation_error(
    exc: ValidationError, root_model: type[BaseModel] | None = None
) -> list[str]:
    """One line per problem: ``dotted.path = value: what is allowed``.

    ``root_model`` is the model that was validated; it names the allowed keys
    of a table holding an unknown key. It defaults to
    :class:`~cwrend_cli.config.schema.CwrendConfig`. Only the first
    :data:`~cwrend_cli.limits.MAX_LISTED_PROBLEMS` errors are written out, the
    rest counted in a last line (85,000 unknown keys printed 8.3 MB).
    """
    if root_model is None:
        # Imported here, not at the top: the schema imports this module for
        # rules_error and fmt_num, so a top-level import would be circular.
        from cwrend_cli.config.schema import CwrendConfig

        root_model = CwrendConfig
    lines: list[str] = []
    errors = _union_errors_merged(exc.errors(include_url=False))
    for err in errors[:MAX_LISTED_PROBLEMS]:
        loc = tuple(err["loc"])
        path = ".".join(str(p) for p in loc)
        kind = err["type"]
        if kind == _RULES_ERROR:
            for field, value, message in err["ctx"]["problems"]:
                full = f"{path}.{field}" if path else field
                lines.append(f"{full} = {value}: {message}")
        elif kind == "extra_forbidden":
            model = _model_at(root_model, loc[:-1])
            allowed = f" (allowed: {', '.join(model.model_fields)})" if model else ""
            hint = did_you_mean(loc[-1], list(model.model_fields)) if model else ""
            lines.append(f"{path}: unknown key{allowed}{hint}")
        elif kind == "missing":
            lines.append(f"{path}: missing required key")
        else:
            where = path or "<config>"
            hint = _unit_hint(root_model, loc, err)
            lines.append(f"{where} = {_fmt_value(err.get('input'))}: {_describe(err)}{hint}")
    if len(errors) > MAX_LISTED_PROBLEMS:
        lines.append(f"… and {len(errors) - MAX_LISTED_PROBLEMS:,} more ({len(errors):,} in all)")
    return lines
