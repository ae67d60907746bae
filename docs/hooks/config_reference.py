"""MkDocs hook: the configuration reference, generated from the pydantic schema at build time.

One source: every row of ``docs/reference/config.md`` is read from
:class:`cwrend_cli.config.schema.CwrendConfig` (its fields, their JSON schema for
types and bounds, the defaults of a default config) when MkDocs renders the
page; nothing in the page is copied by hand. The placeholder
``<!-- cwrend:config-reference -->`` is replaced by the tables, and
``<!-- cwrend:changelog -->`` in ``docs/changelog.md`` by the top-level
``CHANGELOG.md`` (so the history, too, has one source).

Units: every leaf field's ``description`` states its unit in square brackets
(:data:`UNIT_GROUP`): ``[km]``, ``[km/s²]``, ``[km, km/s]`` for a state, ``[-]`` for a
dimensionless number, a choice or a name, ``[the key's unit]`` for a value of another
key. :func:`leaf_fields` is what ``tests/test_docs.py`` checks.

Registered in ``mkdocs.yml`` under ``hooks:``.
"""

from __future__ import annotations

import re
import types
import typing
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path
from typing import Any

from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from cwrend_cli.config.schema import CwrendConfig

#: Placeholders the hook fills in.
CONFIG_MARK = "<!-- cwrend:config-reference -->"
CHANGELOG_MARK = "<!-- cwrend:changelog -->"

#: One unit: "-" (dimensionless, a choice or a name), "the key's unit" (a value of the
#: dotted key it applies to), or products and quotients of km, m, s, rad, deg, ms, %, score,
#: kB, MB with ² ³ √ (km/s², km²/s², km/√s, 1/score).
_ATOM = r"(?:km|ms|m|s|rad|deg|score|kB|MB|%)[²³]?"
UNIT = rf"(?:-|the key's unit|(?:1/)?√?{_ATOM}(?:/√?{_ATOM})*)"
#: A unit stated in a description, in square brackets: "[km]", "[-]", "[km, km/s]". A
#: bracket of anything else ("[x, y, z]", "[0, 1]") is not one.
UNIT_GROUP = re.compile(rf"\s*\[({UNIT}(?:, {UNIT})*)\]")

_REPO = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Leaf:
    """One configuration value: where it lives and what the schema says of it."""

    key: str  #: dotted key, as ``--set`` takes it (``<i>``/``<key>`` for list/table entries)
    table: str  #: the TOML table it sits in
    description: str  #: the field's description, unit included ("" when none)
    type: str
    default: str
    bounds: str

    @property
    def unit(self) -> str | None:
        """The unit at the end of the description, or None when it states none."""
        found = UNIT_GROUP.findall(self.description)
        return found[-1] if found else None

    @property
    def text(self) -> str:
        """The description without its unit (the last unit bracket in it)."""
        found = list(UNIT_GROUP.finditer(self.description))
        if not found:
            return self.description
        last = found[-1]
        return self.description[: last.start()] + self.description[last.end() :]


@dataclass(frozen=True)
class Table:
    """A TOML table of the configuration and its leaves."""

    name: str
    toml_header: str
    description: str
    leaves: tuple[Leaf, ...]


# ---------------------------------------------------------------------------
# Reading the schema
# ---------------------------------------------------------------------------


def _fmt_number(value: float | int) -> str:
    return repr(value) if isinstance(value, float) else str(value)


def _fmt_value(value: Any) -> str:
    """A default as it would be written in TOML (``unset`` for None)."""
    if value is None:
        return "unset"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return _fmt_number(value)
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_fmt_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{}" if not value else "{" + ", ".join(f"{k} = …" for k in value) + "}"
    return str(value)


def fmt_bound(value: float | int) -> str:
    """A bound as a reader writes it: 1e6, 1e-6, 0.0013, 180 (the value, shortest form)."""
    if isinstance(value, int) or (value.is_integer() and abs(value) < 1e5):
        return str(int(value))
    text = repr(value)  # the shortest form that reads back as the same float
    if "e" not in text and abs(value) >= 1e5:
        text = format(Decimal(text), "e")  # exact: 1234567.5 -> 1.2345675e+6
    if "e" not in text:
        return text
    mantissa, exponent = text.split("e")
    if "." in mantissa:
        mantissa = mantissa.rstrip("0").rstrip(".")
    return f"{mantissa}e{int(exponent)}"


def _interval(prop: dict[str, Any]) -> str:
    """The numeric bounds of one JSON-schema node, in interval notation."""
    lo = ("[", prop["minimum"]) if "minimum" in prop else None
    if "exclusiveMinimum" in prop:
        lo = ("(", prop["exclusiveMinimum"])
    hi = ("]", prop["maximum"]) if "maximum" in prop else None
    if "exclusiveMaximum" in prop:
        hi = (")", prop["exclusiveMaximum"])
    if lo and hi:
        return f"{lo[0]}{fmt_bound(lo[1])}, {fmt_bound(hi[1])}{hi[0]}"
    if lo:
        return f"{'≥' if lo[0] == '[' else '>'} {fmt_bound(lo[1])}"
    if hi:
        return f"{'≤' if hi[0] == ']' else '<'} {fmt_bound(hi[1])}"
    return ""


def _bounds(prop: dict[str, Any]) -> str:
    """Every constraint the schema states on a value, its entries and its alternatives."""
    parts = [_interval(prop)]
    if "minLength" in prop:
        parts.append(f"length ≥ {prop['minLength']}")
    if "maxLength" in prop:
        parts.append(f"length ≤ {prop['maxLength']}")
    if "pattern" in prop:
        parts.append(f"matches `{prop['pattern']}`")
    entries = prop.get("prefixItems") or ([prop["items"]] if "items" in prop else [])
    inner = [_bounds(e) for e in entries]
    if inner and all(b == inner[0] for b in inner) and inner[0]:
        parts.append(f"each {inner[0]}")
    elif any(inner):
        groups: list[tuple[int, int, str]] = []  # runs of entries with the same bounds
        for i, bound in enumerate(inner, start=1):
            if groups and groups[-1][2] == bound:
                groups[-1] = (groups[-1][0], i, bound)
            else:
                groups.append((i, i, bound))
        parts.append(
            "entries "
            + "; ".join(
                f"{first}{f'–{last}' if last > first else ''} {bound or 'any'}"
                for first, last, bound in groups
            )
        )
    for alt in prop.get("anyOf", []):
        if alt.get("type") != "null":
            parts.append(_bounds(alt))
    return ", ".join(p for p in parts if p)


def _type(prop: dict[str, Any]) -> str:
    """A reader's name for the type of one JSON-schema node."""
    if "enum" in prop:
        return " or ".join(f'"{v}"' for v in prop["enum"])
    if "const" in prop:
        return f'"{prop["const"]}"'
    if "anyOf" in prop:
        alts = [a for a in prop["anyOf"] if a.get("type") != "null"]
        names = " or ".join(_type(a) for a in alts)
        return names + (" (optional)" if len(alts) < len(prop["anyOf"]) else "")
    kind = prop.get("type")
    if kind == "array":
        if "prefixItems" in prop:
            first = _type(prop["prefixItems"][0])
            return f"{len(prop['prefixItems'])} × {first}"
        if "items" in prop:
            return f"list of {_type(prop['items'])}"
        return "list"
    if kind == "object":
        return "table"
    return {"number": "float", "integer": "int", "string": "text", "boolean": "bool"}.get(
        str(kind), str(kind)
    )


def _nested_model(annotation: Any) -> tuple[type[BaseModel], str] | None:
    """The model a field holds, and how it is held: directly, as a list or as a table."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation, "model"
    if origin is tuple and args and args[-1] is Ellipsis:
        inner = args[0]
        if isinstance(inner, type) and issubclass(inner, BaseModel):
            return inner, "list"
    if origin is dict and len(args) == 2:
        inner = args[1]
        if isinstance(inner, type) and issubclass(inner, BaseModel):
            return inner, "table"
    if origin in (typing.Union, types.UnionType):
        for arg in args:
            found = _nested_model(arg)
            if found is not None:
                return found
    return None


def _tables(
    model: type[BaseModel],
    prefix: str,
    header: str,
    description: str,
    defaults: BaseModel | None,
) -> list[Table]:
    """The tables of ``model`` (itself first, then those nested in it), depth first."""
    props = model.model_json_schema()["properties"]
    leaves: list[Leaf] = []
    nested: list[Table] = []
    for name, info in model.model_fields.items():
        key = f"{prefix}.{name}" if prefix else name
        held = _nested_model(info.annotation)
        if held is not None:
            sub, how = held
            if how == "model":
                sub_defaults = getattr(defaults, name) if defaults is not None else None
                nested += _tables(sub, key, f"[{key}]", info.description or "", sub_defaults)
            elif how == "list":
                nested += _tables(sub, f"{key}.<i>", f"[[{key}]]", info.description or "", None)
            else:
                nested += _tables(
                    sub, f"{key}.<key>", f'[{key}."<key>"]', info.description or "", None
                )
            continue
        if defaults is not None:
            default = _fmt_value(getattr(defaults, name))
        elif info.default is not PydanticUndefined:
            default = _fmt_value(info.default)
        elif info.default_factory is not None:
            default = _fmt_value(info.default_factory())  # type: ignore[call-arg]
        else:
            default = "required"
        prop = props[name]
        leaves.append(
            Leaf(
                key=key,
                table=header,
                description=info.description or "",
                type=_type(prop),
                default=default,
                bounds=_bounds(prop),
            )
        )
    own = [Table(prefix, header, description, tuple(leaves))] if leaves else []
    # the top level's own values (the campaign tables) after the sections
    return nested + own if not prefix else own + nested


def config_tables() -> list[Table]:
    """Every table of :class:`CwrendConfig` with its leaves, in the schema's order."""
    return _tables(CwrendConfig, "", "(top level)", "", CwrendConfig())


def leaf_fields() -> list[Leaf]:
    """Every configuration value (a leaf of the schema), in the schema's order."""
    return [leaf for table in config_tables() for leaf in table.leaves]


# ---------------------------------------------------------------------------
# Rendering
# ---------------------------------------------------------------------------


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _code(text: str) -> str:
    return f"`{text}`" if text else ""


def render_reference() -> str:
    """The Markdown of the configuration reference (one table per TOML table)."""
    out: list[str] = []
    for table in config_tables():
        title = table.name or "Top level: campaign grids"
        out.append(f"## `{title}`\n")
        if table.name:
            about = table.description[:1].upper() + table.description[1:]
            out.append(f"TOML: `{table.toml_header}`. {about}.\n")
        out.append("| key | type | unit | default | bounds | description |")
        out.append("|---|---|---|---|---|---|")
        for leaf in table.leaves:
            row = [
                f"`{leaf.key}`",
                _cell(leaf.type),
                _cell(leaf.unit or "**none stated**"),
                _code(_cell(leaf.default)),
                _cell(leaf.bounds),
                _cell(leaf.text),
            ]
            out.append("| " + " | ".join(row) + " |")
        out.append("")
    return "\n".join(out)


def _changelog() -> str:
    text = (_REPO / "CHANGELOG.md").read_text(encoding="utf-8")
    # the page has its own title; the file's first heading is dropped
    return re.sub(r"\A# [^\n]*\n", "", text)


def on_page_markdown(markdown: str, /, *, page: Any, config: Any, files: Any) -> str:
    """MkDocs event: fill the placeholders of the pages that have them."""
    if CONFIG_MARK in markdown:
        markdown = markdown.replace(CONFIG_MARK, render_reference())
    if CHANGELOG_MARK in markdown:
        markdown = markdown.replace(CHANGELOG_MARK, _changelog())
    return markdown
