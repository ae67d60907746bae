"""``cwrend report``: draw the registered figures and write ``report.md`` for a results directory.

Writes into ``RESULTS_DIR/report/`` (each file atomically): the figures of
:data:`~cwrend_cli.report.figures.FIGURES` that apply, as PNG, then
``report.md`` with the tables and the figures with their captions, then
``report.html`` (the same, self-contained: figures embedded, the config and
its hash); and the
figure of ``cwrend compare`` (:func:`write_compare_figure`). This is the one
place where the report writes files.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import matplotlib as mpl
import pandas as pd
from matplotlib.figure import Figure

from cwrend_cli import __version__
from cwrend_cli.config import to_toml
from cwrend_cli.output.files import atomic_path
from cwrend_cli.output.layout import REPORT_DIR
from cwrend_cli.report.figures import DPI, STYLE, fig_compare, planned_figures
from cwrend_cli.report.html import report_html
from cwrend_cli.report.load import Layout, load_results, results_world
from cwrend_cli.report.markdown import report_md


@dataclass(frozen=True)
class ReportSummary:
    """What :func:`write_report` wrote."""

    results_dir: Path
    out_dir: Path
    layout: Layout  # "run" or "campaign"
    seed: int  # noise realisation of the per-seed figures
    point: str | None  # grid point of the per-seed figures (campaigns)
    files: tuple[Path, ...]  # figures and report.md, in the order written
    notes: tuple[str, ...] = ()


def _save(fig: Figure, path: Path, root: Path | None = None) -> Path:
    with atomic_path(path, root=root) as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")
    return path


def write_report(
    results_dir: Path, seed: int | None = None, point: str | None = None
) -> ReportSummary:
    """Write the figures and ``report.md`` of a run or campaign directory.

    ``seed`` selects the noise realisation of the per-seed figures (default:
    the first seed with a successful run), ``point`` the grid point of Figs
    1–5 and the per-point tables (its id or its swept values, see
    :func:`~cwrend_cli.report.load.load_results`). Raises
    :class:`~cwrend_cli.report.load.ReportError` (a
    :class:`~cwrend_cli.errors.CwrendError`) for a missing or unreadable
    directory, an unknown seed or an unknown point.
    """
    results_dir = Path(results_dir)
    data = load_results(results_dir, seed, point)
    out = results_dir / REPORT_DIR  # written without following links (atomic_path's root)
    planned = planned_figures(data)
    figures: list[Path] = []
    with mpl.rc_context(STYLE):
        for figure in planned:
            figures.append(_save(figure.draw(), out / figure.file, results_dir))
    md = out / "report.md"
    text = report_md(data, results_dir, [(f.file, f.caption) for f in planned])
    with atomic_path(md, root=results_dir) as tmp:
        tmp.write_text(text, encoding="utf-8")
    page = out / "report.html"
    config = to_toml(data.config) if data.config else None
    images = {path.name: path.read_bytes() for path in figures}
    made = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    page_text = report_html(
        text, images, config, data.config_hash,
        title=results_dir.resolve().name, made=made, version=__version__,
    )  # fmt: skip
    with atomic_path(page, root=results_dir) as tmp:
        tmp.write_text(page_text, encoding="utf-8")
    return ReportSummary(
        results_dir=results_dir,
        out_dir=out,
        layout=data.layout,
        seed=data.seed,
        point=data.point,
        files=(*figures, md, page),
        notes=data.notes,
    )


def write_compare_figure(
    frame: pd.DataFrame,
    label_a: str,
    label_b: str,
    path: Path,
    *,
    dirs: tuple[Path, Path] | None = None,
    differences: Sequence[tuple[str, Any, Any]] | None = None,
) -> Path:
    """Draw :func:`~cwrend_cli.report.figures.fig_compare` in the report's style; save as PNG.

    ``dirs``: the two compared results directories; their simulated worlds
    (truth model, actuator errors, sensor faults; read from their stored
    configurations) are then named under the title. ``differences``: what
    differs between their configurations, ``(dotted key, A's value, B's value)``,
    named under the title too.
    """
    worlds = (results_world(dirs[0]), results_world(dirs[1])) if dirs is not None else None
    with mpl.rc_context(STYLE):
        return _save(fig_compare(frame, label_a, label_b, worlds, differences), path)
