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

Sensitivity: :func:`sobol_indices` computes first-order (S1) and total (ST)
Sobol indices with bootstrap confidence intervals with SALib's estimators
(:func:`SALib.analyze.sobol.analyze`, Saltelli 2002 / Jansen 1999 as SALib
implements them); they are not written by hand here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

if TYPE_CHECKING:  # pandas is imported by sensitivity() only: a worker plans no design
    import pandas as pd

from cwrend_cli.errors import ConfigError

__all__ = [
    "DESIGNS",
    "DESIGN_STREAM",
    "SIGNIFICANT_DIGITS",
    "Design",
    "ParameterRange",
    "SobolIndices",
    "design_points",
    "n_runs_per_base",
    "parse_range",
    "sensitivity",
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
#: Significant digits of a sampled float value (the value used is the value stored).
SIGNIFICANT_DIGITS = 10


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
        return float(f"{raw:.{SIGNIFICANT_DIGITS}g}")


def parse_range(key: str, spec: Mapping[str, Any]) -> ParameterRange:
    """A ``[sweep]`` table entry as a :class:`ParameterRange`; :class:`ConfigError` naming the key.

    ``{ low = 0.05, high = 1.0 }``, with ``log = true`` (log-uniform) or
    ``int = true`` (integers low … high); or ``{ values = ["cw", "j2"] }``.
    """
    allowed = {"low", "high", "log", "int", "values"}
    unknown = sorted(set(spec) - allowed)
    if unknown:
        raise ConfigError(
            f"[sweep] {key}: unknown field(s) {', '.join(unknown)} (a range has low, high and "
            "optionally log = true or int = true; a choice has values = [...])"
        )
    if "values" in spec:
        values = spec["values"]
        if set(spec) != {"values"} or not isinstance(values, list) or not values:
            raise ConfigError(f"[sweep] {key}: values = [...] lists at least one value, alone")
        return ParameterRange(key, "choice", values=tuple(values))
    if "low" not in spec or "high" not in spec:
        raise ConfigError(
            f"[sweep] {key}: a range needs low and high, e.g. {{ low = 0.1, high = 1 }}"
        )
    low, high = spec["low"], spec["high"]
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in (low, high)):
        raise ConfigError(f"[sweep] {key}: low and high must be numbers")
    if not (math.isfinite(low) and math.isfinite(high)) or not low < high:
        raise ConfigError(f"[sweep] {key}: low = {low}, high = {high}: need finite low < high")
    log, integer = bool(spec.get("log", False)), bool(spec.get("int", False))
    if log and integer:
        raise ConfigError(f"[sweep] {key}: log and int cannot be combined")
    if log and low <= 0:
        raise ConfigError(f"[sweep] {key}: log = true needs low > 0 (low = {low})")
    if integer and not (float(low).is_integer() and float(high).is_integer()):
        raise ConfigError(f"[sweep] {key}: int = true needs integer low and high")
    return ParameterRange(key, "int" if integer else "float", float(low), float(high), log)


def _generator(root_seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(root_seed, spawn_key=(DESIGN_STREAM,)))


def n_runs_per_base(design: Design, dims: int) -> int:
    """Points per base sample: ``D + 2`` for the Saltelli scheme of ``sobol``, else 1."""
    return dims + 2 if design == "sobol" else 1


def unit_samples(design: Design, n: int, dims: int, root_seed: int) -> np.ndarray:
    """The design's points in the unit cube, shape ``(n · n_runs_per_base, dims)``.

    ``n``: points (``lhs``, ``random``) or base points (``sobol``: a power of two).
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
    seed = int(_generator(root_seed).integers(2**31 - 1))
    samples: np.ndarray = saltelli.sample(
        problem, n, calc_second_order=False, scramble=True, seed=seed
    )
    return samples


def design_points(
    design: Design, ranges: Sequence[ParameterRange], n: int, root_seed: int
) -> list[tuple[tuple[str, Any], ...]]:
    """The assignments ``((key, value), …)`` of every design point, in design order."""
    unit = unit_samples(design, n, len(ranges), root_seed)
    return [
        tuple((r.key, r.value(float(u))) for r, u in zip(ranges, row, strict=True)) for row in unit
    ]


@dataclass(frozen=True)
class SobolIndices:
    """First-order and total Sobol indices of one output with 95 % interval half-widths."""

    names: tuple[str, ...]
    s1: np.ndarray
    s1_conf: np.ndarray  # half-width of the 95 % bootstrap interval
    st: np.ndarray
    st_conf: np.ndarray


def sobol_indices(
    ranges: Sequence[ParameterRange], outputs: np.ndarray, root_seed: int, resamples: int = 500
) -> SobolIndices:
    """S1 and ST of ``outputs`` (one value per point of the ``sobol`` design, in design order).

    The estimators and their bootstrap intervals are SALib's
    (:func:`SALib.analyze.sobol.analyze`, ``calc_second_order=False``); the
    bootstrap is seeded from the campaign's root seed.
    """
    from SALib.analyze import sobol as analyze

    dims = len(ranges)
    y = np.asarray(outputs, dtype=float)
    if y.size % (dims + 2) or not np.isfinite(y).all():
        raise ValueError("outputs must be finite, one per point of a sobol design")
    problem = {"num_vars": dims, "names": [r.key for r in ranges], "bounds": [[0, 1]] * dims}
    seed = int(_generator(root_seed).integers(2**31 - 1))
    result = analyze.analyze(
        problem, y, calc_second_order=False, num_resamples=resamples, conf_level=0.95, seed=seed
    )
    return SobolIndices(
        names=tuple(r.key for r in ranges),
        s1=np.asarray(result["S1"]),
        s1_conf=np.asarray(result["S1_conf"]),
        st=np.asarray(result["ST"]),
        st_conf=np.asarray(result["ST_conf"]),
    )


def sensitivity(
    runs: pd.DataFrame,
    rows: Sequence[str],
    ranges: Sequence[ParameterRange],
    root_seed: int,
    metrics: Sequence[str] = SENSITIVITY_METRICS,
) -> pd.DataFrame:
    """Sobol indices of a ``sobol`` campaign per architecture and metric (long format).

    The output of design row i is the mean of the metric over the seeds of
    its point (``rows[i]``, its point id), so the indices say which
    parameter drives the mean over the noise. Rows: ``arch``, ``metric``,
    ``parameter``, ``statistic`` (``S1`` first-order, ``ST`` total), ``value``,
    ``ci_low``, ``ci_high`` (95 %), ``n_seeds`` (the fewest ok seeds of a
    point). An architecture with a point without ok runs gets no rows.
    """
    import pandas as pd

    ok = runs[runs["status"] == "ok"]
    out = []
    for arch, group in ok.groupby("arch", sort=True, observed=True):
        means = group.groupby("point", observed=True)[list(metrics)].mean()
        counts = group.groupby("point", observed=True).size()
        if not set(rows) <= set(means.index):
            continue
        for metric in metrics:
            y = means.loc[list(rows), metric].to_numpy(dtype=float)
            if not np.isfinite(y).all():
                continue
            idx = sobol_indices(ranges, y, root_seed)
            for i, name in enumerate(idx.names):
                for kind, value, conf in (
                    ("S1", idx.s1[i], idx.s1_conf[i]),
                    ("ST", idx.st[i], idx.st_conf[i]),
                ):
                    out.append(
                        {"arch": str(arch), "metric": metric, "parameter": name, "statistic": kind,
                         "value": float(value), "ci_low": float(value - conf),
                         "ci_high": float(value + conf), "n_seeds": int(counts.min())}
                    )  # fmt: skip
    return pd.DataFrame(out)
