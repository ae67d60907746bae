"""Display names of swept parameters and their values (figures and tables of the report).

A swept key (``schedule.beta``) is shown as its symbol with its unit
(``β [-]``); keys without a known symbol get their last segment, with the
unit read from its suffix (``_km_s2`` → km/s², ``_s`` → s, …). Values are
printed as given in the campaign file: a float is shown with 12 significant
digits, so ``0.0007999999999999999`` (floating-point noise of a grid) reads
``0.0008``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from cwrend_cli.output.layout import PARAM_PREFIX

#: Below this many seeds a percentile-bootstrap interval is too narrow to trust (with 1 seed
#: it is a single point): the console, report.md and ``cwrend table`` mark such intervals.
MIN_BOOTSTRAP_N = 10

#: Metres per kilometre: every cwrend table and figure shows misses in m (Δv in km/s).
M_PER_KM = 1e3

#: Symbol and unit of the configuration keys that have one in the paper.
SYMBOLS: dict[str, tuple[str, str]] = {
    "scenario.mean_motion_rad_s": ("n", "rad/s"),
    "scenario.horizon_s": ("T", "s"),
    "scenario.dt_s": ("Δt", "s"),
    "scenario.u_max_km_s2": ("u_max", "km/s²"),
    "schedule.beta": ("β", "-"),
    "schedule.nis_offset": ("m", "-"),
    "schedule.score_lowpass": ("ρ_s", "-"),
    "schedule.kappa_mtf": ("κ_MTF", "-"),
    "schedule.score_max": ("s_max", "-"),
    "schedule.eps_min": ("ε_min", "-"),
    "schedule.eps_max": ("ε_max", "-"),
    "schedule.alpha_eps": ("α_ε", "-"),
    "schedule.deadband": ("deadband", "-"),
    "schedule.eps_saturation": ("ε_sat", "-"),
    "schedule.eps_fixed": ("ε_fixed", "-"),
    "guidance.t_resolve_s": ("T_resolve", "s"),
    "guidance.t_min_rem_s": ("T_min,rem", "s"),
    "truth.eccentricity": ("e", "-"),
    "actuator.magnitude_bias": ("thrust bias", "-"),
    "actuator.magnitude_sigma": ("σ_thrust", "-"),
    "actuator.pointing_sigma_deg": ("σ_pointing", "°"),
    "actuator.min_thrust_km_s2": ("u_min", "km/s²"),
    "actuator.delay_steps": ("delay", "steps"),
    "target.body_rates_deg_s": ("ω(0)", "°/s"),
}

#: Unit suffixes of configuration keys, longest first.
_SUFFIXES = (
    ("_km_s2", "km/s²"),
    ("_km_s", "km/s"),
    ("_rad_s", "rad/s"),
    ("_deg_s", "°/s"),
    ("_km", "km"),
    ("_deg", "°"),
    ("_pct", "%"),
    ("_ms", "ms"),
    ("_s", "s"),
)


def consistency_text(value: float) -> str:
    """A mean NEES or NIS as printed: 2 decimals below 1,000 (``5.34``, ``3.00``), else 3
    significant digits (``2.07e+03``: a mismatch's NEES reaches 10⁶)."""
    return f"{value:.2f}" if abs(value) < 1e3 else f"{value:.3g}"


def param_symbol(key: str) -> tuple[str, str | None]:
    """Symbol and unit of a swept key (``param.`` prefix allowed); unit ``None`` if unknown."""
    key = key.removeprefix(PARAM_PREFIX)
    if key in SYMBOLS:
        return SYMBOLS[key]
    name = key.rsplit(".", 1)[-1]
    for suffix, unit in _SUFFIXES:
        if name.endswith(suffix):
            return name.removesuffix(suffix), unit
    return name, None


def param_label(key: str) -> str:
    """Axis label of a swept key: ``β [-]``, ``u_max [km/s²]`` (the name alone if no unit)."""
    symbol, unit = param_symbol(key)
    return f"{symbol} [{unit}]" if unit is not None else symbol


def number(value: float, spec: str) -> str:
    """``value`` formatted with ``spec`` (``.4f``, ``+.1f``, …) without a negative zero: a
    value that rounds to zero reads ``0.0000``, not ``-0.0000`` (the format's ``z``
    option, PEP 682)."""
    signed = spec[:1] in ("+", "-", " ")
    return format(value, f"{spec[0]}z{spec[1:]}" if signed else f"z{spec}")


def format_value(value: Any) -> str:
    """A swept value as given: floats with 12 significant digits (no floating-point noise)."""
    if isinstance(value, bool | str) or value is None:
        return str(value)
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return format(value, ".12g")
    return str(value)


def category_text(value: str) -> str:
    """A non-numeric swept value as an axis tick: a vector (``runs.parquet`` holds it as
    JSON text, ``[0.291, 0.3881, 1.9403]``) one element a line, so neighbours do not
    overlap; any other value as it is."""
    if value.startswith("[") and value.endswith("]"):
        try:
            items = json.loads(value)
        except json.JSONDecodeError:
            return value
        if isinstance(items, list):
            return "[" + ",\n".join(setting_text(v) for v in items) + "]"
    return value


def difference_text(key: str, a: Any, b: Any) -> str:
    """One configuration difference of ``cwrend compare``: ``schedule.beta: A 0.25, B 0.5``.

    Values as :func:`format_value` shows them, arrays element by element
    (``[0.1, 0.2]``); ``none`` where the key is absent or unset.
    """
    return f"{key}: A {setting_text(a)}, B {setting_text(b)}"


def setting_text(value: Any) -> str:
    """A configuration value as shown: :func:`format_value`, arrays element by element,
    ``none`` for an absent or unset value."""
    if value is None:
        return "none"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(setting_text(v) for v in value) + "]"
    return format_value(value)


def swept_values(row: pd.Series, columns: Iterable[str]) -> list[str]:
    """``key = value`` for each swept (``param.``) column of ``row``, values as given."""
    return [
        f"{c.removeprefix(PARAM_PREFIX)} = {format_value(row[c])}"
        for c in columns
        if c.startswith(PARAM_PREFIX)
    ]


def param_setting(key: str, value: Any) -> str:
    """``symbol = value unit`` of one swept key (a legend entry)."""
    symbol, unit = param_symbol(key)
    shown = format_value(value)
    return f"{symbol} = {shown}" + (f" {unit}" if unit not in (None, "-") else "")


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured markdown table (report.md, ``cwrend table``, ``--format md``)."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)
