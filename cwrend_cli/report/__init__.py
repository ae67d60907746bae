"""``cwrend report``: the paper's figures and a markdown report from stored results.

``load`` builds typed report data from a run or campaign directory (with the
config model; it never recomputes physics), ``figures`` draws it (pure data →
Figure, one registry of figures and captions), ``markdown`` writes the tables
and ``report.md``, ``write`` saves them all into ``RESULTS_DIR/report/``.

The names below are imported on first use (:mod:`cwrend_cli.lazy`): the
campaign commands' console imports :mod:`~cwrend_cli.report.labels` alone,
which must not bring the figures, matplotlib and ``scipy.stats`` (about 1 s).
"""

from typing import TYPE_CHECKING

from cwrend_cli.lazy import lazy_attributes

_LAZY = {
    "ReportData": "load",
    "ReportError": "load",
    "load_results": "load",
    "markdown_table": "labels",
    "ReportSummary": "write",
    "write_compare_figure": "write",
    "write_report": "write",
}

if TYPE_CHECKING:
    from cwrend_cli.report.labels import markdown_table
    from cwrend_cli.report.load import ReportData, ReportError, load_results
    from cwrend_cli.report.write import ReportSummary, write_compare_figure, write_report
else:
    __getattr__ = lazy_attributes(__name__, _LAZY, globals())

__all__ = [
    "ReportData",
    "ReportError",
    "ReportSummary",
    "load_results",
    "markdown_table",
    "write_compare_figure",
    "write_report",
]
