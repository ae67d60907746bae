"""Rich tables for the console (presentation only)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np
import pandas as pd
from rich import box
from rich.console import Console, Group
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)
from rich.progress import Task as RichTask
from rich.table import Column, Table
from rich.text import Text

from cwrend_cli.campaign import CaseResult
from cwrend_cli.campaign.statistics import APPLIED_METRICS
from cwrend_cli.output.tables import reference_row, summary_row, summary_table
from cwrend_cli.physics.params import arch_order
from cwrend_cli.physics.references import OpenLoopResult
from cwrend_cli.physics.simulation import RunResult
from cwrend_cli.report.labels import (
    M_PER_KM,
    MIN_BOOTSTRAP_N,
    consistency_text,
    markdown_table,
    number,
    setting_text,
    swept_values,
)


def _num(value: float, spec: str) -> str:
    return "–" if math.isnan(value) else number(value, spec)


def _solves(r: Mapping[str, Any]) -> str:
    if not r["n_solves"]:
        return "–"
    ok = r["n_converged"]
    text = f"{ok}/{r['n_solves']}"
    return text + (f" ({r['n_infeasible']} inf.)" if r["n_infeasible"] else "")


#: Table options that leave the widest rows whole at 80 columns: no outer edge, one
#: space before each column (two between columns with the separator), as the run table.
_NARROW: dict[str, Any] = {"show_edge": False, "padding": (0, 0, 0, 1)}


def _table(title: str | None, **options: Any) -> Table:
    """A console table in cwrend's style: bold title, cyan header, a rule under it."""
    return Table(
        title=title, title_style="bold", header_style="bold cyan", box=box.SIMPLE_HEAD, **options
    )


def _point_table(
    title: str, point_cols: Sequence[str], stats: pd.DataFrame
) -> tuple[Table, list[str]]:
    """A narrow table that opens with a column per swept value (its last key part), and
    those values' columns (``point_cols`` without ``point``). Numbers right-aligned, names
    (a swept ``truth.model``) left-aligned, as every table's architecture column."""
    table = _table(title, **_NARROW)
    params = [c for c in point_cols if c != "point"]
    for p in params:
        numeric = p in stats and pd.api.types.is_numeric_dtype(stats[p])
        table.add_column(p.rsplit(".", 1)[-1], justify="right" if numeric else "left", no_wrap=True)
    return table, params


def _summary_rows(case: CaseResult) -> list[dict[str, Any]]:
    """The open-loop references' rows, then each run's (``summary.parquet``'s columns)."""
    fuel = case.references.fuel
    rows = [reference_row(case.references.energy, fuel), reference_row(case.references.fuel, fuel)]
    return rows + [summary_row(r, fuel) for r in case.runs]


def summary_frame(case: CaseResult) -> pd.DataFrame:
    """The rows of :func:`summary_console_table` as stored (``cwrend run --format``), in
    ``summary.parquet``'s column order."""
    rows = _summary_rows(case)
    columns: list[str] = list(summary_table(rows).column_names)
    return pd.DataFrame(rows)[columns]


def script_table(frame: pd.DataFrame, fmt: str) -> str:
    """``frame`` for scripts (``--format``): ``csv``, ``json`` (a list of records) or ``md``.

    Every value as stored, unrounded (CSV and JSON write the shortest text that
    reads back to the same float); a missing value is empty in CSV and
    markdown, ``null`` in JSON. No colour, no markup.
    """
    if fmt == "csv":
        return str(frame.to_csv(index=False))
    records = [{str(k): _plain(v) for k, v in row.items()} for row in frame.to_dict("records")]
    if fmt == "json":
        return json.dumps(records, ensure_ascii=False) + "\n"
    header = [str(c) for c in frame.columns]
    rows = [["" if v is None else str(v) for v in r.values()] for r in records]
    return markdown_table(header, rows) + "\n"


def _plain(value: Any) -> Any:
    """A JSON-ready Python value: numpy scalars as Python's, NaN and NA as ``None``."""
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or (isinstance(value, float) and math.isnan(value)) or value is pd.NA:
        return None
    if isinstance(value, (bool, int, float, str)):
        return value
    return str(value)


def summary_console_table(case: CaseResult, title: str = "", nis_dof: int = 3) -> Group:
    """Compact tables: one row per open-loop reference and closed-loop run (fits 80 columns),
    then the filter consistency of each closed-loop run (mean NIS and NEES, faults).

    The seed (one per case) goes into the title, not into a column. ``nis_dof``: the
    sensor's measurement dimension m, the mean NIS of a consistent filter (3, or 2 for
    the angles sensor).
    """
    rows = _summary_rows(case)
    seeds = sorted({int(r["seed"]) for r in rows if r["seed"] >= 0})
    if seeds:
        title = f"{title} · seed {', '.join(map(str, seeds))}" if title else f"seed {seeds[0]}"
    table = _table(
        title or None,
        show_edge=False,
        padding=(0, 0, 0, 1),  # with the column separator: two spaces between columns
    )
    table.add_column("case", no_wrap=True)
    for name in ("Δv km/s", "miss m", "vs fuel", "converged", "solve ms"):
        # never cut or fold a number: the widest cells are short enough for 80 columns
        table.add_column(name, justify="right", no_wrap=True)
    for r in rows:
        table.add_row(
            r["arch"].replace("open_loop_", "open-loop "),
            f"{r['delta_v_km_s']:.5f}",
            f"{r['miss_km'] * M_PER_KM:.3g}",  # misses in m, as every cwrend table
            _num(r["fuel_penalty_pct"], "+.1f") + "%",
            _solves(r),
            f"{_num(r['solve_mean_ms'], '.2f')}/{_num(r['solve_max_ms'], '.1f')}",
        )
    table.caption = "solve ms: mean/max per re-solve; inf.: certified infeasible"
    applied = _applied_run_table(rows, case.references.fuel)
    return Group(table, applied, _consistency_table(case.runs, rows[2:], nis_dof))


def _applied_run_table(rows: Sequence[Mapping[str, Any]], fuel: OpenLoopResult) -> Table:
    """The applied Δv of each case and its penalty against the exact fuel optimum (issue 33).

    Beside the run table's Δv, the paper's 1 s trapezoid of ‖u‖
    (:mod:`cwrend_cli.physics.metrics`).
    """
    table = _table(None, **_NARROW)
    table.add_column("case", no_wrap=True)
    for name in ("Δv applied km/s", "vs exact fuel", "trapezoid − applied m/s"):
        table.add_column(name, justify="right", no_wrap=True)
    for r in rows:
        table.add_row(
            r["arch"].replace("open_loop_", "open-loop "),
            _num(r["delta_v_applied_km_s"], ".5f"),
            _num(r["fuel_penalty_applied_pct"], "+.2f") + "%",
            _num((r["delta_v_km_s"] - r["delta_v_applied_km_s"]) * M_PER_KM, "+.3f"),
        )
    exact = fuel.exact
    burn = (
        float("nan") if exact is None else float(np.sum(exact.burns_s[:, 1] - exact.burns_s[:, 0]))
    )
    table.caption = (
        "applied: Σ‖u_k‖Δt of the held steps (open loop: ∫‖u‖dt of the plan)\n"
        f"exact fuel optimum {fuel.delta_v_continuous_km_s:.7f} km/s ({burn:.3f} s of burn)"
    )
    return table


def _consistency_table(
    runs: Sequence[RunResult], rows: Sequence[Mapping[str, Any]], nis_dof: int
) -> Table:
    """Filter consistency of the closed-loop runs: mean NIS (nominal periods), mean NEES.

    E[NIS] = m (``nis_dof``, the sensor's dimension: 3, or 2 for angles) and E[NEES] = 6 for
    a consistent filter (χ² with m and 6 degrees of freedom, :mod:`cwrend_cli.physics.metrics`).
    """
    table = _table(None, show_edge=False, padding=(0, 0, 0, 1))
    table.add_column("filter", no_wrap=True)
    for name in ("mean NIS", "mean NEES", "dropouts", "outliers"):
        table.add_column(name, justify="right", overflow="fold")
    for run, r in zip(runs, rows, strict=True):
        table.add_row(
            r["arch"],
            _num(r["mean_nis_nominal"], ".2f"),
            _num(r["mean_nees"], ".4g"),
            str(int(run.dropout.sum())),
            str(int(run.outlier.sum())),
        )
    table.caption = (
        f"mean NIS outside the degradation windows ({nis_dof} if consistent); mean NEES over "
        "t > 0 (6 if consistent); steps with a sensor dropout or outlier"
    )
    return table


#: A point of a campaign's completion timeline: (clock [s], runs done then).
Mark = tuple[float, int]


def progress_pace(
    first: Mark | None, last: Mark | None, total: int, now: float
) -> tuple[float | None, float | None]:
    """Rate [runs/s] and ETA [s] of a campaign from its first and latest completions (pure).

    The rate counts from the first completed run, not from the start: until
    then the workers start, load the compiled kernels and the references are
    computed, which says nothing about the pace of the runs (an ETA from the
    start was 10× off, issue 17). The ETA is the ``total`` runs not yet done
    at that rate, counted down since the latest completion (``now`` on the
    same clock). ``(None, None)`` until two completions at different times.

    Why the whole span and not a recent window: a run's cost varies several
    fold from seed to seed (the fixed-ε runs most), and only the average over
    all runs so far is steady; on simulated 2-worker campaigns of 16-seed
    tasks, the error of the ETA at 10 % of a 1,000-seed ablation was about
    4 % (median; 12 % at the 90th percentile), against 6 % and 20 % for a rate
    over the later half of the span (``tests/test_progress.py``).
    """
    if first is None or last is None or last[0] <= first[0] or last[1] <= first[1]:
        return None, None
    rate = (last[1] - first[1]) / (last[0] - first[0])
    return rate, max(0.0, (total - last[1]) / rate - (now - last[0]))


class RichProgress:
    """Progress of a campaign: runs done, failures, runs/s and ETA, then the statistics phase.

    A bar on a terminal, plain lines otherwise (one every 10 s and the last).
    The driver reports each finished run (per task on a Dask cluster); the
    rate and the ETA come from :func:`progress_pace` over the completions so
    far. Before a second completion there is no rate and the ETA shows ``–``.
    ``notice`` (e.g. ``compiling kernels (first run only, about 25 s)…``,
    :func:`cwrend_cli.physics.compiled.compiling_notice`) is printed when runs
    start, above the bar, when there are runs to compute.
    """

    def __init__(
        self,
        console: Console,
        label: str,
        quiet: bool = False,
        clock: Callable[[], float] = time.monotonic,
        notice: str | None = None,
    ) -> None:
        self._clock = clock
        self._notice = notice
        self._console = console
        self._label = label
        self._quiet = quiet
        self._bar: Progress | None = None
        self._task: TaskID | None = None
        self._done = 0
        self._failed = 0
        self._total = 0
        self._next_report = 0.0
        self._t0 = clock()
        self._first: Mark | None = None  # (clock, runs done) at the first completion
        self._last: Mark | None = None  # and at the latest

    def start(self, total: int, skipped: int) -> None:
        """Begin: ``total`` runs to compute, ``skipped`` already in the campaign."""
        self._total = total
        self._t0 = self._clock()
        if self._quiet:
            return
        if skipped:
            self._console.print(f"{skipped} run(s) already done, {total} to compute")
        if self._notice and total:
            self._console.print(self._notice, markup=False)
        if self._console.is_terminal:
            # one line at any width from 80 columns: the label cut to PROGRESS_LABEL_WIDTH
            # (with an ellipsis), no text column wraps, the bar takes what is left
            self._bar = Progress(
                TextColumn(
                    "[bold]{task.description}",
                    table_column=Column(
                        no_wrap=True, overflow="ellipsis", max_width=PROGRESS_LABEL_WIDTH
                    ),
                ),
                BarColumn(bar_width=None),
                MofNCompleteColumn(
                    table_column=Column(no_wrap=True, min_width=2 * len(str(total)) + 1)
                ),
                _Text(self._failed_text, style="red"),
                TimeElapsedColumn(table_column=Column(no_wrap=True, min_width=7)),
                _Text(self._rate_text),
                _Text(self._eta_text),
                console=self._console,
                transient=False,
                expand=True,
                get_time=self._clock,
            )
            self._bar.start()
            self._task = self._bar.add_task(self._label, total=total, failed=0)

    def rate(self) -> float | None:
        """Runs per second (:func:`progress_pace`; ``None`` before a second completion)."""
        return progress_pace(self._first, self._last, self._total, self._clock())[0]

    def eta(self, now: float | None = None) -> float | None:
        """Seconds left at ``now`` (default: the clock), :func:`progress_pace`."""
        now = self._clock() if now is None else now
        return progress_pace(self._first, self._last, self._total, now)[1]

    def _rate_text(self) -> str:
        """``2.1 runs/s``; empty until there is a rate (two completions)."""
        rate = self.rate()
        if rate is None:
            return ""
        return f"{rate:.3g} runs/s" if rate < 1000 else f"{rate:.0f} runs/s"

    def _eta_text(self) -> str:
        """``ETA 33 s``; empty until there is a rate."""
        eta = self.eta()
        return "" if eta is None else f"ETA {_duration(eta)}"

    def _failed_text(self) -> str:
        return f"{self._failed} failed" if self._failed else ""

    def advance(self, ok: int, failed: int) -> None:
        """Runs just completed (negative: runs of a lost task, to run again)."""
        now = self._clock()
        self._done += ok + failed
        self._failed += failed
        if self._first is None:
            self._first = (now, self._done)
        self._last = (now, self._done)
        if self._quiet:
            return
        if self._bar is not None and self._task is not None:
            self._bar.update(self._task, advance=ok + failed, failed=self._failed)
            return
        elapsed = now - self._t0
        if self._done >= self._total or elapsed >= self._next_report:
            pace = [t for t in (self._rate_text(), self._eta_text()) if t]  # none before a rate
            self._console.print(
                ", ".join(
                    [f"{self._label}: {self._done}/{self._total} runs", f"{self._failed} failed",
                     f"{elapsed:.0f} s elapsed", *pace]
                ),
                markup=False,
            )  # fmt: skip
            self._next_report = elapsed + 10.0

    def close(self) -> None:
        """Stop drawing."""
        if self._bar is not None:
            self._bar.stop()
            self._bar = None

    @contextmanager
    def phase(self, text: str) -> Iterator[None]:
        """Say what happens after the runs (e.g. ``computing statistics``) while it does."""
        with phase(self._console, f"{self._label}: {text}", quiet=self._quiet):
            yield


@contextmanager
def phase(console: Console, text: str, quiet: bool = False) -> Iterator[None]:
    """Say ``text…`` while a step without a bar runs (statistics, Sobol indices).

    A spinner on a terminal, one line otherwise; nothing when quiet.
    """
    if quiet:
        yield
    elif console.is_terminal:
        with console.status(f"{text}…", spinner="dots"):
            yield
    else:
        console.print(f"{text}…", markup=False)
        yield


#: Widest label of the progress bar (``ablate <name>``), cut with an ellipsis beyond:
#: with the other columns at their widest (12345/100000, 9 failed, 0:12:34, 999 runs/s,
#: ETA 2 h 07 min) the bar then keeps a few columns at 80 (issue 37 item 14).
PROGRESS_LABEL_WIDTH = 16


class _Text(ProgressColumn):
    """A progress column showing the text of a callable (the campaign-wide rate and ETA)."""

    def __init__(self, text: Callable[[], str], style: str = "progress.remaining") -> None:
        super().__init__(table_column=Column(no_wrap=True))
        self._text = text
        self._style = style

    def render(self, task: RichTask) -> Text:
        return Text(self._text(), style=self._style)


def _duration(seconds: float) -> str:
    """``42 s``, ``3 min 05 s`` or ``2 h 07 min``."""
    s = round(seconds)
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


UNRELIABLE_MARK = "*"
UNRELIABLE_NOTE = (
    f"{UNRELIABLE_MARK} fewer than {MIN_BOOTSTRAP_N} seeds: bootstrap interval unreliable"
)


def _unreliable(row: pd.Series) -> bool:
    """A bootstrap interval from fewer than :data:`MIN_BOOTSTRAP_N` samples."""
    return not math.isnan(row["ci_low"]) and int(row["n"]) < MIN_BOOTSTRAP_N


def _ci(row: pd.Series, spec: str, scale: float = 1.0, *, bootstrap: bool = True) -> str:
    """Value, and its 95 % interval on a second (dim) line, marked when unreliable."""
    value = number(row["value"] * scale, spec)
    if math.isnan(row["ci_low"]):
        return value
    lo, hi = number(row["ci_low"] * scale, spec), number(row["ci_high"] * scale, spec)
    mark = UNRELIABLE_MARK if bootstrap and _unreliable(row) else ""
    return f"{value}\n[dim]{lo}–{hi}{mark}[/dim]"


#: Said instead of an interval's caption when every quantity of a table has one realisation.
ONE_REALISATION = "one realisation: no interval"


def _caption(text: str, rows: pd.DataFrame, alone: str) -> str:
    """The caption of a table of intervals ``rows`` (their ``n`` is the runs or seed pairs).

    ``alone`` when every row has one realisation (no interval is possible:
    ``cwrend ablate`` with its default single seed); else ``text``, plus a line
    saying so when some rows have one, and the note on unreliable intervals
    when a bootstrap row has few seeds.
    """
    if rows.empty:
        return text
    single = rows["n"].astype(int) < 2
    if bool(single.all()):
        return alone
    lines = [text]
    if bool(single.any()):
        lines.append(f"a value alone: {ONE_REALISATION}")
    if bool(rows.apply(_unreliable, axis=1).any()):
        lines.append(UNRELIABLE_NOTE)
    return "\n".join(lines)


def _in_arch_order(stats: pd.DataFrame) -> pd.DataFrame:
    """``stats`` with ``arch`` an ordered categorical in :func:`arch_order`: grouped with
    ``sort=True``, its rows come in the order of the report and ``cwrend table`` (the
    statistics file's rows are sorted by slug)."""
    order = arch_order(stats["arch"].unique())
    return stats.assign(
        arch=pd.Categorical(stats["arch"].astype(str), categories=order, ordered=True)
    )


def ablation_console_table(stats: pd.DataFrame, title: str) -> Table:
    """Per architecture: mean Δv, miss and fuel penalty with 95 % CIs, and the solves.

    Medians and p95 are in ``ablation.parquet``; the console keeps to 80 columns.
    """
    marginal = stats[stats["kind"] == "marginal"]
    n = int(marginal["n"].max()) if not marginal.empty else 0
    table = _table(f"{title} · {n} seed(s)", **_NARROW)
    table.add_column("architecture", no_wrap=True)
    for name in ("Δv km/s", "miss m", "fuel pen. %", "solves ok %\nms mean/max"):
        table.add_column(name, justify="right", no_wrap=True)
    for arch, g in _in_arch_order(marginal).groupby("arch", sort=True, observed=True):
        get = {(r.metric, r.statistic): r for _, r in g.iterrows()}
        table.add_row(
            str(arch),
            _ci(get[("delta_v_km_s", "mean")], ".4f"),
            _ci(get[("miss_km", "mean")], ".2f", 1e3),
            _ci(get[("fuel_penalty_pct", "mean")], ".1f"),
            f"{get[('solve_success_pct', 'mean')]['value']:.2f}\n"
            f"{get[('solve_mean_ms', 'mean')]['value']:.2f}/"
            f"{get[('solve_max_ms', 'max')]['value']:.1f}",
        )
    table.caption = _caption(
        "means, 95 % bootstrap interval below", marginal, f"means; {ONE_REALISATION}"
    )
    return table


def applied_console_table(
    stats: pd.DataFrame, point_cols: Sequence[str] = (), title: str = "Δv the thruster applied"
) -> Table | None:
    """Per architecture (and grid point): mean applied Δv and its fuel penalty, 95 % CIs.

    The applied Δv is Σ‖u_k‖Δt of the zero-order-hold steps, its penalty
    against the exact continuous fuel optimum (issue 33, item 3); the
    ablation and sweep tables show the paper's trapezoid. ``None`` when the
    statistics have no such rows (a campaign written before them).
    """
    marginal = stats[(stats["kind"] == "marginal") & stats["metric"].isin(APPLIED_METRICS)]
    if marginal.empty:
        return None
    table, params = _point_table(title, point_cols, marginal)
    table.add_column("architecture", no_wrap=True)
    for name in ("Δv applied km/s", "fuel pen. vs exact %"):
        table.add_column(name, justify="right", no_wrap=True)
    keys = [*params, "point", "arch"] if point_cols else ["arch"]
    for _, g in _in_arch_order(marginal).groupby(keys, sort=True, observed=True):
        get = {(r.metric, r.statistic): r for _, r in g.iterrows()}
        first = g.iloc[0]
        table.add_row(
            *(f"{first[p]:g}" if isinstance(first[p], float) else str(first[p]) for p in params),
            str(first["arch"]),
            _ci(get[("delta_v_applied_km_s", "mean")], ".4f"),
            _ci(get[("fuel_penalty_applied_pct", "mean")], ".2f"),
        )
    table.caption = _caption(
        "means, 95 % bootstrap interval below\napplied: Σ‖u_k‖Δt of the held steps\n"
        "penalty vs the exact continuous fuel optimum",
        marginal,
        f"means; {ONE_REALISATION}\napplied: Σ‖u_k‖Δt of the held steps",
    )
    return table


def paired_console_table(stats: pd.DataFrame) -> Table | None:
    """Seed-by-seed comparisons: P(A misses less than B) and the median miss difference."""
    pairs = stats[stats["kind"] == "paired"]
    if pairs.empty:
        return None
    table = _table("paired comparisons (same noise)", **_NARROW)
    table.title_style = None  # as before: a plain title under the bold one of the ablation
    table.add_column("A vs B", no_wrap=True)
    for name in ("seeds", "P(miss\nA < B)", "median\nΔmiss m", "mean\nΔΔv km/s"):
        table.add_column(name, justify="right", no_wrap=True)
    for (a, b), g in pairs.groupby(["arch", "other"], sort=False):
        get = {r.statistic: r for _, r in g.iterrows()}
        table.add_row(
            f"{a}\nvs {b}",
            str(int(get["frac_less"]["n"])),
            _ci(get["frac_less"], ".2f", bootstrap=False),
            _ci(get["median_diff"], ".2f", 1e3),
            _ci(get["mean_diff"], ".4f"),
        )
    table.caption = _caption(
        "Δ = A − B; 95 % interval below (Wilson for P, bootstrap otherwise)",
        pairs[pairs["statistic"] != "frac_less"],
        f"Δ = A − B, {ONE_REALISATION}\n95 % Wilson interval below P",
    )
    return table


def sweep_console_table(stats: pd.DataFrame, point_cols: list[str], title: str) -> Table:
    """Per grid point and architecture: mean Δv and miss with 95 % CIs."""
    table, params = _point_table(title, point_cols, stats)
    table.add_column("architecture", no_wrap=True)  # a name: left-aligned
    for name in ("n", "Δv km/s", "miss m"):
        table.add_column(name, justify="right", no_wrap=True)
    marginal = stats[stats["kind"] == "marginal"]
    for _, g in _in_arch_order(marginal).groupby(
        [*params, "point", "arch"], sort=True, observed=True
    ):
        get = {(r.metric, r.statistic): r for _, r in g.iterrows()}
        first = g.iloc[0]
        table.add_row(
            *(f"{first[p]:g}" if isinstance(first[p], float) else str(first[p]) for p in params),
            str(first["arch"]),
            str(int(get[("miss_km", "mean")]["n"])),
            _ci(get[("delta_v_km_s", "mean")], ".4f"),
            _ci(get[("miss_km", "mean")], ".2f", 1e3),
        )
    table.caption = _caption(
        "means, 95 % bootstrap interval below; all statistics in sweep.parquet",
        marginal,
        f"means; {ONE_REALISATION}; all statistics in sweep.parquet",
    )
    return table


def _in_band(row: pd.Series) -> str:
    """Whether a consistency row's value lies in its χ² band: ``yes``, ``no``, ``–`` (no band)."""
    value, low, high = float(row["value"]), float(row["ci_low"]), float(row["ci_high"])
    if not (math.isfinite(value) and math.isfinite(low)):
        return "–"
    return "yes" if low <= value <= high else "no"


def consistency_console_table(
    stats: pd.DataFrame, point_cols: Sequence[str], title: str
) -> Table | None:
    """Per (grid point and) architecture: mean NEES and NIS of the runs against their χ² bands.

    From the ``consistency`` rows of the statistics
    (:func:`cwrend_cli.campaign.statistics.consistency`): the mean over the
    runs of each run's mean NEES (6 if consistent) and mean NIS (nominal
    periods, the sensor's m: 3, or 2 for angles), the 95 % band of a consistent filter
    below, and whether the
    mean is in it. ``None`` without such rows (an older campaign).
    """
    rows = stats[stats["kind"] == "consistency"] if "kind" in stats else stats.iloc[:0]
    if rows.empty:
        return None
    table, params = _point_table(title, point_cols, rows)
    table.add_column("architecture", no_wrap=True)  # a name: left-aligned
    for name in ("n", "NEES", "in\nband", "NIS", "in\nband"):
        table.add_column(name, justify="right", no_wrap=True)
    keys = [*params, *(["point"] if "point" in point_cols else []), "arch"]
    # as the table above it: a sweep's by its swept values, then the architectures' order
    for _, g in _in_arch_order(rows).groupby(keys, sort=True, observed=True):
        get = {r.metric: r for _, r in g.iterrows()}
        first = g.iloc[0]
        cells: list[str] = []
        for metric in ("mean_nees", "mean_nis_nominal"):
            r = get.get(metric)
            if r is None or not math.isfinite(float(r["value"])):
                cells += ["–", "–"]
                continue
            band = (
                f"\n[dim]{r['ci_low']:.2f}–{r['ci_high']:.2f}[/dim]"
                if math.isfinite(float(r["ci_low"]))
                else ""
            )
            cells += [f"{consistency_text(float(r['value']))}{band}", _in_band(r)]
        nees = get.get("mean_nees")
        table.add_row(
            *(f"{first[p]:g}" if isinstance(first[p], float) else str(first[p]) for p in params),
            str(first["arch"]),
            str(int(nees["n"])) if nees is not None else "–",
            *cells,
        )
    table.caption = (
        "filter consistency: mean over the runs of each run's mean NEES (6 if consistent) "
        "and mean NIS outside the degradation windows (its sensor's m: 3, or 2 for angles); "
        "below, the χ² 95 % band of a "
        "consistent filter for n runs"
    )
    return table


#: Console heading and scale of each compared metric (misses in m, as everywhere on the console).
_COMPARE_METRICS: dict[str, tuple[str, float, str]] = {
    "miss_km": ("miss m", 1e3, ".2f"),
    "delta_v_km_s": ("Δv km/s", 1.0, ".4f"),
    "fuel_penalty_pct": ("fuel pen. %", 1.0, ".2f"),
    "delta_v_applied_km_s": ("applied Δv km/s", 1.0, ".4f"),
    "fuel_penalty_applied_pct": ("applied pen. %", 1.0, ".2f"),
}


def compare_console_tables(frame: pd.DataFrame, groups: list[str], title: str) -> list[Table]:
    """``cwrend compare``: per architecture and metric, A − B per seed (fits 80 columns).

    One table per matched pair of grid points (one for two ablations): mean
    and median of the per-seed differences with bootstrap intervals, and the
    share of seeds where A is lower (better), with its Wilson interval.
    """
    tables = []
    grouped = frame.groupby(groups, sort=False, dropna=False) if groups else [((), frame)]
    for _, part in grouped:
        point = ", ".join(swept_values(part.iloc[0], groups))
        table = _table(f"{title}{' · ' + point if point else ''}")
        table.add_column("architecture", no_wrap=True)
        table.add_column("metric", no_wrap=True)
        for name in ("mean Δ", "median Δ", "A better"):
            table.add_column(name, justify="right", overflow="fold")
        ties = 0
        for arch, g in part.groupby("arch", sort=False):
            n = int(g["n"].iloc[0])
            for i, metric in enumerate(m for m in _COMPARE_METRICS if m in set(g["metric"])):
                label, scale, spec = _COMPARE_METRICS[metric]
                get = {r.statistic: r for _, r in g[g["metric"] == metric].iterrows()}
                ties += round(float(get["frac_tied"]["value"]) * n)
                table.add_row(
                    f"{arch}\n[dim]{n} seed(s)[/dim]" if i == 0 else "",
                    label,
                    _ci(get["mean_diff"], spec, scale),
                    _ci(get["median_diff"], spec, scale),
                    _ci(get["frac_better"], ".2f", bootstrap=False),
                )
        text = (
            "Δ = A − B per seed; 95 % interval below (bootstrap; Wilson for\n"
            "A better, the share of seeds with A < B)"
        )
        alone = (
            f"Δ = A − B per seed, {ONE_REALISATION}\n95 % Wilson interval below A better (A < B)"
        )
        if ties:
            text += f"\n{ties} tie(s) (A = B exactly) count as not better"
            alone += f"\n{ties} tie(s) (A = B exactly) count as not better"
        bootstrap_rows = part[part["statistic"].isin(["mean_diff", "median_diff"])]
        table.caption = _caption(text, bootstrap_rows, alone)
        tables.append(table)
    return tables


def sensitivity_console_table(frame: pd.DataFrame, title: str) -> Table | Group:
    """Sensitivity indices of a design campaign with 95 % intervals, per arch and metric.

    A ``sobol`` design: first-order (S1) and total (ST) Sobol indices, then
    a table of the second-order indices (S2) when stored; an ``lhs`` or
    ``random`` design: the first-order indices of RBD-FAST (``method``
    ``rbd_fast``), S1 only. The fuel penalty is Δv scaled by a constant (same
    indices) and is left to ``sensitivity.parquet``; parameters are shown by
    their key's last segment.
    """
    shown = frame[frame["metric"] != "fuel_penalty_pct"]
    methods = set(shown["method"]) if "method" in shown else {"sobol"}
    first = shown[shown["statistic"].isin(["S1", "ST"])]
    stats = [k for k in ("S1", "ST") if (first["statistic"] == k).any()]
    table = _table(title, show_edge=False, padding=(0, 0, 0, 1))
    for name in ("architecture", "metric", "parameter"):
        table.add_column(name, no_wrap=True)
    for k in stats:
        table.add_column(f"{k} ± 95 %", justify="right", no_wrap=True)
    keys = ["arch", "metric", "parameter"]
    wide = first.pivot_table(index=keys, columns="statistic", values=["value", "ci_low", "ci_high"])
    previous: tuple[str, ...] = ()
    for index, row in wide.iterrows():
        arch, metric, parameter = (str(v) for v in (index if isinstance(index, tuple) else ()))
        cells = [
            f"{row[('value', k)]:.2f} ± {(row[('ci_high', k)] - row[('ci_low', k)]) / 2:.2f}"
            for k in stats
        ]
        new = (arch, metric) != previous
        previous = (arch, metric)
        table.add_row(arch if new else "", metric if new else "",
                      parameter.rsplit(".", 1)[-1], *cells)  # fmt: skip
    table.caption = (
        "first-order indices of the mean over seeds (RBD-FAST, SALib); all in sensitivity.parquet"
        if methods == {"rbd_fast"}
        else "Sobol indices of the mean over seeds (SALib); all in sensitivity.parquet"
    )
    pairs = shown[shown["statistic"] == "S2"]
    if pairs.empty:
        return table
    second = _table("second-order Sobol indices", show_edge=False, padding=(0, 0, 0, 1))
    for name in ("architecture", "metric", "parameters"):
        second.add_column(name, no_wrap=True)
    second.add_column("S2 ± 95 %", justify="right", no_wrap=True)
    previous = ()
    for _, r in pairs.iterrows():
        arch, metric = str(r["arch"]), str(r["metric"])
        new = (arch, metric) != previous
        previous = (arch, metric)
        names = " × ".join(str(r[c]).rsplit(".", 1)[-1] for c in ("parameter", "parameter_2"))
        cell = f"{r['value']:.2f} ± {(r['ci_high'] - r['ci_low']) / 2:.2f}"
        second.add_row(arch if new else "", metric if new else "", names, cell)
    return Group(table, second)


def until_console_table(
    achieved: Sequence[Any], target: str, checked: bool = True, unit: str | None = None
) -> Table:
    """The intervals a ``--until`` target asked for, as achieved.

    ``checked`` False: the campaign stopped before widths are checked
    (``sequential.ready``), so every interval reads "not checked", however wide
    (``sequential.unchecked_message`` says how wide). ``unit``: that of the value, half-width and
    target, said under the table (``sequential.Target.unit``; ``None``: a share).
    """
    table = _table(f"--until {target}", show_edge=False, padding=(0, 0, 0, 1))
    table.add_column("interval of")
    for name in ("seeds", "value", "half-width", "target"):
        table.add_column(name, justify="right")
    table.add_column("met")
    for a in achieved:
        needed = a.seeds_needed
        verdict = "not checked"
        if checked:
            verdict = "yes" if a.met else "no" if needed is None else f"no: ~{needed:,} seeds"
        table.add_row(a.label, str(a.n), f"{a.value:.6g}", f"{a.half_width:.3g}",
                      f"{a.limit:.3g}", verdict)  # fmt: skip
    captions = [] if unit is None else [f"value, half-width and target in {unit}"]
    if checked and not all(a.met for a in achieved):
        captions.append("~N seeds: the estimate of what would meet the target (half-width ∝ 1/√n)")
    table.caption = "\n".join(captions) or None
    return table


def config_diff_console_table(differences: Sequence[tuple[str, Any, Any]]) -> Table | Text:
    """``cwrend compare``: what differs between A's and B's configurations (fits 80 columns).

    One row per dotted key (``campaign.compare.config_diff``) with A's and B's
    values as :func:`~cwrend_cli.report.labels.setting_text` shows them (as
    text, never read as markup); long values fold onto further lines, never
    cut. No difference: one line that says so.
    """
    if not differences:
        return Text("A and B have the same configuration (no setting differs outside [output])")
    table = _table("A and B differ in", show_edge=False, padding=(0, 0, 0, 1))
    table.add_column("setting", overflow="fold")
    table.add_column("A", overflow="fold")
    table.add_column("B", overflow="fold")
    for key, a, b in differences:
        table.add_row(Text(key), Text(setting_text(a)), Text(setting_text(b)))
    return table
