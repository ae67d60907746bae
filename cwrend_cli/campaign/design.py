"""Campaign designs beyond a grid: space-filling samples and Sobol sensitivity indices (issue 19).

A design draws the points of a sweep from parameter *ranges* instead of
listing them. Pure functions: nothing here runs a case or writes a file.

* ``lhs`` — a scrambled Latin hypercube (:class:`scipy.stats.qmc.LatinHypercube`):
  each of the N strata of every dimension holds exactly one point. Not
  extendable: the strata depend on N, so a design of 2N points does not contain
  the design of N (a larger LHS campaign is a new campaign).
* ``sobol`` — the Saltelli scheme on a scrambled Sobol sequence
  (:func:`SALib.sample.sobol.sample`, first-order and total indices):
  N base points give ``N (D + 2)`` runs, the matrices A, B and the D matrices
  A_B^(i) whose column i comes from B. N must be a power of two (the Sobol
  balance properties). Extendable: the base points are a prefix of one
  sequence fixed by the seed, so a campaign with 2N base points contains every
  point of the campaign with N.
* ``random`` — independent uniforms from the seed's stream; extendable (prefix).

Every design is seeded from the campaign's root seed (``noise.seed``) through
its own :class:`numpy.random.SeedSequence` child, ``spawn_key = (DESIGN_STREAM,)``,
so that it is reproducible and independent of every per-seed stream.

A range maps the unit interval to values: uniform or log-uniform floats
(``log = true``), integers (each of ``low … high`` equally likely) or
categories (each listed value equally likely). Float values are rounded to
:data:`SIGNIFICANT_DIGITS` significant digits before they are used, so the
value a run used is the value printed and stored (no ``0.0007999999999999999``).

Sensitivity, with SALib's estimators (not written by hand here), of the mean
of a metric over the seeds of each design point (:func:`sensitivity`):

* ``sobol``: :func:`sobol_indices`, first-order (S1) and total (ST) Sobol
  indices with bootstrap intervals (:func:`SALib.analyze.sobol.analyze`,
  Saltelli 2002 / Jansen 1999 as SALib implements them), and on request the
  second-order indices S2 (the design then has ``N (2D + 2)`` points: the
  Saltelli scheme with the D matrices B_A^(i) as well, Saltelli 2002; it
  contains the first-order design of the same N, so a campaign extends to it).
* ``lhs`` and ``random``: :func:`rbd_fast_indices`, the first-order index S1
  estimated from the design as it is (RBD-FAST in Plischke's EASI form, with
  the bias correction of Tissot & Prieur 2012: :func:`SALib.analyze.rbd_fast.analyze`).
  It estimates the same quantity as a Sobol design's S1 (the share of the
  output's variance explained by one parameter alone), needs no special
  sampling, and captures non-monotonic effects, which a rank correlation
  (PRCC) would miss; it says nothing about interactions (no ST). Its
  harmonics ``M`` follow the design's size (:func:`rbd_fast_harmonics`).

:func:`salib_problem` is the SALib problem definition of a design (names,
bounds, distributions) that the campaign writes to ``problem.json`` beside
its design matrix, so that SALib's analyses run on the written files
unchanged.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

if TYPE_CHECKING:  # pandas is imported by sensitivity() only: a worker plans no design
    import pandas as pd

from cwrend_cli.config.overrides import (
    RANGE_FIELDS,
    SIGNIFICANT_DIGITS,
    decimal_float,
    is_range,
)
from cwrend_cli.errors import ConfigError
from cwrend_cli.output.layout import PARAM_PREFIX, UNIT_PREFIX

__all__ = [
    "DESIGNS",
    "DESIGN_STREAM",
    "RANGE_SYNTAX",
    "SIGNIFICANT_DIGITS",
    "TABLE_RANGE_SYNTAX",
    "Design",
    "ParameterRange",
    "SobolIndices",
    "design_points",
    "n_runs_per_base",
    "parse_cli_range",
    "parse_range",
    "range_ends",
    "rbd_fast_harmonics",
    "rbd_fast_indices",
    "salib_problem",
    "salib_seed",
    "sensitivity",
    "sensitivity_note",
    "sobol_indices",
    "unit_samples",
]

#: Metrics whose Sobol indices a sobol campaign reports (runs.parquet columns).
SENSITIVITY_METRICS = ("miss_km", "delta_v_km_s", "fuel_penalty_pct")

Design = Literal["lhs", "sobol", "random"]
DESIGNS: tuple[Design, ...] = ("lhs", "sobol", "random")
#: ``SeedSequence(noise.seed, spawn_key=(DESIGN_STREAM,))`` draws the design
#: (per-seed streams use two-element keys ``(seed, k)``, so they never collide).
DESIGN_STREAM = 2**32 - 1
#: Bootstrap resamples of the sensitivity intervals (SALib's ``num_resamples``).
RESAMPLES = 500
#: Level of the sensitivity intervals (SALib's ``conf_level``).
CONF_LEVEL = 0.95
#: Harmonics of RBD-FAST at most (SALib's default ``M``), see :func:`rbd_fast_harmonics`.
RBD_FAST_MAX_HARMONICS = 10


@dataclass(frozen=True)
class ParameterRange:
    """The range of one swept parameter of a design (a ``[sweep]`` entry that is a table).

    ``kind``: ``"float"`` (``low``, ``high``; ``log`` for log-uniform, both > 0),
    ``"int"`` (``low … high`` inclusive, integers) or ``"choice"`` (``values``).
    """

    key: str
    kind: Literal["float", "int", "choice"]
    low: float = 0.0
    high: float = 1.0
    log: bool = False
    values: tuple[Any, ...] = ()

    def value(self, u: float) -> Any:
        """The parameter value at the unit coordinate ``u`` ∈ [0, 1)."""
        if self.kind == "choice":
            return self.values[min(int(u * len(self.values)), len(self.values) - 1)]
        if self.kind == "int":
            span = int(self.high) - int(self.low) + 1
            return int(self.low) + min(int(u * span), span - 1)
        if self.log:
            raw = math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        else:
            raw = self.low + u * (self.high - self.low)
        return decimal_float(raw)  # SIGNIFICANT_DIGITS, as a grid range's values

    def salib(self) -> tuple[list[float], str]:
        """SALib's ``bounds`` and ``dists`` entry: the distribution of this parameter's values.

        A float range is ``unif`` or ``logunif`` on ``[low, high]`` (SALib's
        scaling of a unit sample gives the values cwrend uses, before their
        rounding to :data:`SIGNIFICANT_DIGITS` digits); integers and choices,
        which SALib has no distribution for, are ``unif`` on the unit
        interval: their coordinate, mapped to a value by :meth:`value`.
        """
        if self.kind == "float":
            return [self.low, self.high], "logunif" if self.log else "unif"
        return [0.0, 1.0], "unif"


#: What a ``[sweep]`` range of a design is, as its errors say.
TABLE_RANGE_SYNTAX = (
    "{ low = LOW, high = HIGH } (uniform; with log = true log-uniform, with int = true "
    "integers) or { values = [V1, V2, …] } (categories), e.g. "
    '"schedule.beta" = { low = 0.1, high = 1.0 }'
)


def parse_range(key: str, spec: Mapping[str, Any], where: str | None = None) -> ParameterRange:
    """A ``[sweep]`` table entry as a :class:`ParameterRange`; :class:`ConfigError` naming the key.

    ``{ low = 0.05, high = 1.0 }``, with ``log = true`` (log-uniform) or
    ``int = true`` (integers low … high); or ``{ values = ["cw", "j2"] }``.
    ``where``: how messages name the entry (default ``[sweep] <key>``).
    """
    at = where or f"[sweep] {key}"
    unknown = sorted(set(spec) - RANGE_FIELDS)
    if unknown and not is_range(spec):  # a whole table as the value, not a range
        field = next(iter(spec))
        raise ConfigError(
            f"{at}: a table of {', '.join(unknown)} is not a range, and a design samples "
            f"no whole table: a range is {TABLE_RANGE_SYNTAX}; sample the table's entries by "
            f'their own keys ("{key}.{field}" = {{ low = …, high = … }})'
        )
    if unknown:
        raise ConfigError(
            f"{at}: unknown field(s) {', '.join(unknown)} (a range has low, high and "
            "optionally log = true or int = true; a choice has values = [...])"
        )
    if "values" in spec:
        values = spec["values"]
        if set(spec) != {"values"} or not isinstance(values, list) or not values:
            raise ConfigError(f"{at}: values = [...] lists at least one value, alone")
        return ParameterRange(key, "choice", values=tuple(values))
    if "low" not in spec or "high" not in spec:
        raise ConfigError(f"{at}: a range needs low and high, e.g. {{ low = 0.1, high = 1 }}")
    low, high = spec["low"], spec["high"]
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in (low, high)):
        raise ConfigError(f"{at}: low and high must be numbers")
    if not (math.isfinite(low) and math.isfinite(high)) or not low < high:
        raise ConfigError(f"{at}: low = {low}, high = {high}: need finite low < high")
    log, integer = bool(spec.get("log", False)), bool(spec.get("int", False))
    if log and integer:
        raise ConfigError(f"{at}: log and int cannot be combined")
    if log and low <= 0:
        raise ConfigError(f"{at}: log = true needs low > 0 (low = {low})")
    if integer and not (float(low).is_integer() and float(high).is_integer()):
        raise ConfigError(f"{at}: int = true needs integer low and high")
    return ParameterRange(key, "int" if integer else "float", float(low), float(high), log)


#: What a ``--range`` option is, as its errors say.
RANGE_SYNTAX = (
    "KEY=LOW:HIGH (uniform), KEY=LOW:HIGH:log, KEY=LOW:HIGH:int or KEY=V1,V2,… (categories), "
    "e.g. --range schedule.beta=0.1:1.0"
)
#: Two numbers joined by a dash or two dots (``0.1-1.0``, ``1..5``): a range written as
#: other tools write one, not a categorical value.
_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_DASHED_RANGE = re.compile(rf"^{_NUMBER}\s*(?:-|–|\.\.)\s*{_NUMBER}$")


def range_ends(parsed: ParameterRange, table: bool = False) -> tuple[tuple[str, Any], ...]:
    """The values of ``parsed`` that bound what a design samples, named as in
    :data:`RANGE_SYNTAX`: ``LOW`` and ``HIGH`` of a range (as :meth:`ParameterRange.value`
    rounds them), every value ``V1``, ``V2``, … of a choice; ``table``: as in
    :data:`TABLE_RANGE_SYNTAX` (a ``[sweep]`` range), ``low``, ``high``, ``values[0]``, …"""
    low, high = ("low", "high") if table else ("LOW", "HIGH")
    if parsed.kind == "choice":
        if table:
            return tuple((f"values[{i}]", v) for i, v in enumerate(parsed.values))
        return tuple((f"V{i}", v) for i, v in enumerate(parsed.values, start=1))
    if parsed.kind == "int":
        return ((low, int(parsed.low)), (high, int(parsed.high)))
    return ((low, decimal_float(parsed.low)), (high, decimal_float(parsed.high)))


def parse_cli_range(text: str) -> ParameterRange:
    """A ``--range`` option as a :class:`ParameterRange`; :class:`ConfigError` naming the option.

    ``KEY=LOW:HIGH`` (uniform floats), ``KEY=LOW:HIGH:log`` (log-uniform),
    ``KEY=LOW:HIGH:int`` (integers LOW … HIGH) or ``KEY=V1,V2,…`` (categories,
    read as TOML scalars like ``--param`` values), the ranges of a ``[sweep]``
    table written on the command line. Whether KEY exists is checked where
    the configuration is known (:func:`cwrend_cli.campaign.plan.design_points`).
    """
    from cwrend_cli.config.overrides import parse_override

    where = f"--range {text}"
    key, sep, raw = text.partition("=")
    key, raw = key.strip(), raw.strip()
    if not sep or not key or not raw:
        raise ConfigError(f"{where}: expected {RANGE_SYNTAX}")
    if ":" in raw:
        parts = [p.strip() for p in raw.split(":")]
        flags = {"log": {"log": True}, "int": {"int": True}}
        if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2] not in flags):
            raise ConfigError(f"{where}: expected {RANGE_SYNTAX}")
        try:
            low, high = float(parts[0]), float(parts[1])
        except ValueError:
            raise ConfigError(f"{where}: LOW and HIGH must be numbers; {RANGE_SYNTAX}") from None
        integer = len(parts) == 3 and parts[2] == "int"
        bounds: tuple[float | int, float | int] = (low, high)
        if integer and low.is_integer() and high.is_integer():
            bounds = (int(low), int(high))
        extra = flags[parts[2]] if len(parts) == 3 else {}
        return parse_range(key, {"low": bounds[0], "high": bounds[1], **extra}, where)
    items = [p.strip() for p in raw.split(",")]
    if any(not item for item in items):
        raise ConfigError(f"{where}: empty value in the list; {RANGE_SYNTAX}")
    dashed = next((item for item in items if _DASHED_RANGE.match(item)), None)
    if dashed is not None:  # else one categorical value, the string "0.1-1.0"
        raise ConfigError(
            f"{where}: {dashed!r} is not a range (it would be one categorical value); "
            f"write it LOW:HIGH; {RANGE_SYNTAX}"
        )
    values = [parse_override(f"{key}={item}")[1] for item in items]
    return parse_range(key, {"values": values}, where)


def _generator(root_seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(root_seed, spawn_key=(DESIGN_STREAM,)))


def n_runs_per_base(design: Design, dims: int, second_order: bool = False) -> int:
    """Points per base sample: ``D + 2`` for the Saltelli scheme of ``sobol`` (``2D + 2``
    with ``second_order``), else 1."""
    if design != "sobol":
        return 1
    return 2 * dims + 2 if second_order else dims + 2


def salib_seed(root_seed: int) -> int:
    """The seed cwrend gives SALib's Sobol sampler and its bootstrap intervals (``seed=``)."""
    return int(_generator(root_seed).integers(2**31 - 1))


def salib_problem(ranges: Sequence[ParameterRange]) -> dict[str, Any]:
    """SALib's problem definition of a design: ``num_vars``, ``names``, ``bounds``, ``dists``.

    The names are the dotted configuration keys, in the design's column
    order; bounds and distributions per :meth:`ParameterRange.salib`. Any
    SALib analysis takes it as it is (they read only ``num_vars`` and ``names``
    from it; a sampler would read the bounds and distributions too).
    """
    pairs = [r.salib() for r in ranges]
    return {
        "num_vars": len(ranges),
        "names": [r.key for r in ranges],
        "bounds": [b for b, _ in pairs],
        "dists": [d for _, d in pairs],
    }


def unit_samples(
    design: Design, n: int, dims: int, root_seed: int, second_order: bool = False
) -> np.ndarray:
    """The design's points in the unit cube, shape ``(n · n_runs_per_base, dims)``.

    ``n``: points (``lhs``, ``random``) or base points (``sobol``: a power of
    two). Rows in SALib's order: for ``sobol`` that of
    :func:`SALib.sample.sobol.sample` (per base sample j: A_j, the D rows
    A_B^(i)_j, with ``second_order`` the D rows B_A^(i)_j, then B_j).
    ``second_order`` applies to ``sobol`` only.
    """
    if n < 1 or dims < 1:
        raise ConfigError(f"--samples {n}: a design needs at least one sample and one range")
    if design == "lhs":
        from scipy.stats import qmc  # imported when used: scipy.stats takes 0.5–1 s to import

        lhs = qmc.LatinHypercube(d=dims, scramble=True, seed=_generator(root_seed))
        return np.asarray(lhs.random(n), dtype=float)
    if design == "random":
        return _generator(root_seed).random((n, dims))
    if n & (n - 1):
        raise ConfigError(
            f"--samples {n}: a Sobol design needs a power of two base points (e.g. "
            f"{1 << (n - 1).bit_length()}); it runs samples × (parameters + 2) points"
        )
    from SALib.sample import sobol as saltelli  # imported when used: SALib is slow to import

    problem = {"num_vars": dims, "names": [f"x{i}" for i in range(dims)], "bounds": [[0, 1]] * dims}
    samples: np.ndarray = saltelli.sample(
        problem, n, calc_second_order=second_order, scramble=True, seed=salib_seed(root_seed)
    )
    return samples


def design_points(
    design: Design,
    ranges: Sequence[ParameterRange],
    n: int,
    root_seed: int,
    second_order: bool = False,
) -> list[tuple[tuple[str, Any], ...]]:
    """The assignments ``((key, value), …)`` of every design point, in design order."""
    unit = unit_samples(design, n, len(ranges), root_seed, second_order)
    return [
        tuple((r.key, r.value(float(u))) for r, u in zip(ranges, row, strict=True)) for row in unit
    ]


@dataclass(frozen=True)
class SobolIndices:
    """Sobol indices of one output with 95 % interval half-widths (SALib's ``*_conf``).

    ``st`` and ``st_conf`` are NaN where the method has no total index (RBD-FAST);
    ``s2`` and ``s2_conf`` (D × D, upper triangle) only with second-order indices.
    """

    names: tuple[str, ...]
    s1: np.ndarray
    s1_conf: np.ndarray  # half-width of the 95 % bootstrap interval
    st: np.ndarray
    st_conf: np.ndarray
    s2: np.ndarray | None = None
    s2_conf: np.ndarray | None = None


def sobol_indices(
    ranges: Sequence[ParameterRange],
    outputs: np.ndarray,
    root_seed: int,
    resamples: int = RESAMPLES,
    second_order: bool = False,
) -> SobolIndices:
    """S1 and ST (and S2) of ``outputs`` (one value per row of the ``sobol`` design, in order).

    The estimators and their bootstrap intervals are SALib's
    (:func:`SALib.analyze.sobol.analyze`, ``calc_second_order`` as the
    design was drawn); the bootstrap is seeded with :func:`salib_seed`.
    """
    from SALib.analyze import sobol as analyze

    dims = len(ranges)
    y = np.asarray(outputs, dtype=float)
    if y.size % n_runs_per_base("sobol", dims, second_order) or not np.isfinite(y).all():
        raise ValueError("outputs must be finite, one per point of a sobol design")
    result = analyze.analyze(
        salib_problem(ranges), y, calc_second_order=second_order, num_resamples=resamples,
        conf_level=CONF_LEVEL, seed=salib_seed(root_seed),
    )  # fmt: skip
    return SobolIndices(
        names=tuple(r.key for r in ranges),
        s1=np.asarray(result["S1"]),
        s1_conf=np.asarray(result["S1_conf"]),
        st=np.asarray(result["ST"]),
        st_conf=np.asarray(result["ST_conf"]),
        s2=np.asarray(result["S2"]) if second_order else None,
        s2_conf=np.asarray(result["S2_conf"]) if second_order else None,
    )


#: Fewest Sobol base points whose indices cwrend prints without a warning [-]. SALib sets
#: no minimum (its quick start uses N = 1000; Herman & Usher 2017, SALib README); this is
#: the size of the guide's example (docs/guide/designs.md), whose 95 % intervals are
#: about ±0.2 wide. With 2 base points an S1 of −3.26 ± 3.36 was printed as if it meant
#: something (an index lies in [0, 1]).
SOBOL_SAMPLES_ADVISED = 64


def sensitivity_note(kind: Design, samples: int, n_rows: int) -> str | None:
    """What to tell about the sensitivity indices of a design this small, or ``None``.

    ``samples``: ``--samples`` (base points for ``sobol``); ``n_rows``: the design's
    rows. Two lines, each at most 80 characters, broken between phrases (a note
    wrapped by the terminal broke "raise --samples" in two).
    """
    if kind == "sobol":
        if samples >= SOBOL_SAMPLES_ADVISED:
            return None
        return (
            f"warning: Sobol indices from {samples} base points are unreliable;\n"
            f"rerun with --samples {SOBOL_SAMPLES_ADVISED} or more in this "
            "directory (it extends this design)"
        )
    if rbd_fast_harmonics(n_rows) >= 1:
        return None
    return (
        f"no sensitivity indices: RBD-FAST needs at least 9 design rows\n"
        f"(this design has {n_rows}): raise --samples to 9 or more"
    )


def rbd_fast_harmonics(n_rows: int) -> int:
    """RBD-FAST's harmonics ``M`` for a design of ``n_rows`` rows; 0: too few rows for it.

    ``min(10, ⌊(n − 1) / 8⌋)``: SALib's default of 10 where the design is
    large enough (81 rows or more). The estimator's bias correction divides
    by ``1 − 2M/n`` and the bootstrap resamples ``n/2`` rows, so ``M`` below
    ``n/8`` keeps that factor above 1/2 in every resample; fewer than 9
    rows give no index.
    """
    return min(RBD_FAST_MAX_HARMONICS, max(0, (n_rows - 1) // 8))


def rbd_fast_indices(
    ranges: Sequence[ParameterRange],
    unit: np.ndarray,
    outputs: np.ndarray,
    root_seed: int,
    resamples: int = RESAMPLES,
) -> SobolIndices:
    """First-order indices S1 of ``outputs`` on any design: RBD-FAST (SALib).

    ``unit``: the design's rows in the unit cube (:func:`unit_samples`, one
    row per output; RBD-FAST orders the outputs by each column, so the unit
    coordinate keeps the order of integer and categorical draws, which their
    values would tie). :func:`SALib.analyze.rbd_fast.analyze` with ``M`` =
    :func:`rbd_fast_harmonics`, bootstrap seeded with :func:`salib_seed`.
    Raises ``ValueError`` for fewer than 9 rows.
    """
    from SALib.analyze import rbd_fast

    x = np.asarray(unit, dtype=float)
    y = np.asarray(outputs, dtype=float)
    harmonics = rbd_fast_harmonics(y.size)
    if x.shape != (y.size, len(ranges)) or not np.isfinite(y).all() or harmonics < 1:
        raise ValueError("RBD-FAST needs at least 9 rows, one finite output per row")
    result = rbd_fast.analyze(
        salib_problem(ranges), x, y, M=harmonics, num_resamples=resamples,
        conf_level=CONF_LEVEL, seed=salib_seed(root_seed),
    )  # fmt: skip
    nan = np.full(len(ranges), np.nan)
    return SobolIndices(
        names=tuple(r.key for r in ranges),
        s1=np.asarray(result["S1"], dtype=float),
        s1_conf=np.asarray(result["S1_conf"], dtype=float),
        st=nan,
        st_conf=nan,
    )


def design_matrix(
    ranges: Sequence[ParameterRange], rows: Sequence[str], unit: np.ndarray
) -> pd.DataFrame:
    """``design.parquet``: one row per design row, in SALib's row order.

    Columns ``row`` (0, 1, …), ``point`` (the point id whose runs give the
    row's output), ``unit.<key>`` (the unit-cube sample SALib drew or
    analyses) and ``param.<key>`` (the value the runs used) per parameter.
    """
    import pandas as pd

    columns: dict[str, Any] = {"row": np.arange(len(rows), dtype=np.int64), "point": list(rows)}
    for i, r in enumerate(ranges):
        columns[f"{UNIT_PREFIX}{r.key}"] = unit[:, i]
    for i, r in enumerate(ranges):
        columns[f"{PARAM_PREFIX}{r.key}"] = [r.value(float(u)) for u in unit[:, i]]
    return pd.DataFrame(columns)


def problem_document(
    kind: Design,
    samples: int,
    ranges: Sequence[ParameterRange],
    root_seed: int,
    n_rows: int,
    second_order: bool = False,
) -> dict[str, Any]:
    """``problem.json``: SALib's problem (:func:`salib_problem`) and how cwrend analysed it.

    The SALib keys at the top level, so the document is the ``problem``
    argument of any SALib analysis as it is; under ``cwrend`` the design,
    the arguments cwrend gave SALib (``seed``, ``num_resamples``,
    ``conf_level``, ``calc_second_order``, ``M``) and where ``X`` and ``Y``
    come from.
    """
    method = SENSITIVITY_METHODS[kind]
    about: dict[str, Any] = {
        "design": kind,
        "samples": samples,
        "rows": n_rows,
        "method": method,
        "seed": salib_seed(root_seed),
        "num_resamples": RESAMPLES,
        "conf_level": CONF_LEVEL,
        "X": f"design.parquet, columns {UNIT_PREFIX}<name> in the order of names (unit cube)",
        "Y": "per architecture and metric: the mean over the ok runs (status == 'ok') of "
        "runs.parquet at each design.parquet row's point, in row order",
    }
    if kind == "sobol":
        about["calc_second_order"] = second_order
    else:
        about["M"] = rbd_fast_harmonics(n_rows)
    return {**salib_problem(ranges), "cwrend": about}


#: The method of each design's sensitivity indices (``sensitivity.parquet``'s ``method``).
SENSITIVITY_METHODS: Mapping[Design, str] = {
    "sobol": "sobol",
    "lhs": "rbd_fast",
    "random": "rbd_fast",
}


def design_outputs(
    runs: pd.DataFrame, rows: Sequence[str], metrics: Sequence[str] = SENSITIVITY_METRICS
) -> dict[str, tuple[pd.DataFrame, int]]:
    """Per architecture: the outputs of every design row (a column per metric) and its seeds.

    The output of row i is the mean of the metric over the ok runs of its
    point (``rows[i]``), the fewest ok seeds of a point beside it. An
    architecture with a point without ok runs is left out. This is what
    ``Y`` is for SALib: ``runs[ok & arch].groupby("point")[metric].mean()``
    looked up for each row of ``design.parquet``.
    """
    ok = runs[runs["status"] == "ok"]
    out = {}
    for arch, group in ok.groupby("arch", sort=True, observed=True):
        means = group.groupby("point", observed=True)[list(metrics)].mean()
        counts = group.groupby("point", observed=True).size()
        if set(rows) <= set(means.index):
            out[str(arch)] = (means.loc[list(rows)], int(counts.min()))
    return out


def sensitivity(
    runs: pd.DataFrame,
    rows: Sequence[str],
    ranges: Sequence[ParameterRange],
    root_seed: int,
    metrics: Sequence[str] = SENSITIVITY_METRICS,
    *,
    kind: Design = "sobol",
    unit: np.ndarray | None = None,
    second_order: bool = False,
) -> pd.DataFrame:
    """Sensitivity indices of a design campaign per architecture and metric (long format).

    Of the mean over the seeds of each point (:func:`design_outputs`), so the
    indices say which parameter drives the mean over the noise. ``sobol``:
    :func:`sobol_indices` (S1, ST; S2 with ``second_order``); ``lhs`` and
    ``random``: :func:`rbd_fast_indices` on ``unit`` (the design's unit rows;
    S1 only, nothing below 9 rows). Rows: ``arch``, ``metric``,
    ``parameter``, ``parameter_2`` (the other parameter of an S2, else
    empty), ``statistic`` (``S1`` first-order, ``ST`` total, ``S2``
    second-order), ``method`` (``sobol`` or ``rbd_fast``), ``value``,
    ``ci_low``, ``ci_high`` (95 %), ``n_seeds`` (the fewest ok seeds of a point).
    """
    import pandas as pd

    method = SENSITIVITY_METHODS[kind]
    if method == "rbd_fast" and (unit is None or rbd_fast_harmonics(len(rows)) < 1):
        return pd.DataFrame()
    out = []
    for arch, (outputs, n_seeds) in design_outputs(runs, rows, metrics).items():
        for metric in metrics:
            y = outputs[metric].to_numpy(dtype=float)
            if not np.isfinite(y).all():
                continue
            if method == "sobol":
                idx = sobol_indices(ranges, y, root_seed, second_order=second_order)
            else:
                assert unit is not None
                idx = rbd_fast_indices(ranges, unit, y, root_seed)
            found = []
            for i, name in enumerate(idx.names):  # per parameter S1, then ST (sobol)
                found.append((name, "", "S1", idx.s1[i], idx.s1_conf[i]))
                if method == "sobol":
                    found.append((name, "", "ST", idx.st[i], idx.st_conf[i]))
            if idx.s2 is not None and idx.s2_conf is not None:
                found += [
                    (idx.names[i], idx.names[j], "S2", idx.s2[i, j], idx.s2_conf[i, j])
                    for i in range(len(idx.names))
                    for j in range(i + 1, len(idx.names))
                ]
            out += [
                {"arch": arch, "metric": metric, "parameter": name, "parameter_2": other,
                 "statistic": stat, "method": method, "value": float(value),
                 "ci_low": float(value - conf), "ci_high": float(value + conf),
                 "n_seeds": n_seeds}
                for name, other, stat, value, conf in found
            ]  # fmt: skip
    return pd.DataFrame(out)
