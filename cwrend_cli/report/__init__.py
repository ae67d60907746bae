"""``cwrend report``: the paper's figures and a markdown report from stored results.

``load`` builds typed report data from a run or campaign directory (with the
config model; it never recomputes physics), ``figures`` draws it (pure data →
Figure, one registry of figures and captions), ``markdown`` writes the tables
and ``report.md``, ``write`` saves them all into ``RESULTS_DIR/report/``.
"""

from cwrend_cli.report.load import ReportData, ReportError, load_results
from cwrend_cli.report.markdown import markdown_table
from cwrend_cli.report.write import ReportSummary, write_compare_figure, write_report

__all__ = [
    "ReportData",
    "ReportError",
    "ReportSummary",
    "load_results",
    "markdown_table",
    "write_compare_figure",
    "write_report",
]
