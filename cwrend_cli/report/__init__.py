"""``cwrend report``: the paper's figures and a markdown report from stored results."""

from cwrend_cli.report.figures import (
    ReportError,
    ReportSummary,
    load_results,
    markdown_table,
    write_report,
)

__all__ = ["ReportError", "ReportSummary", "load_results", "markdown_table", "write_report"]
