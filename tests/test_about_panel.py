"""The recording's about panel shows every case without scrolling (issue 37, item 14).

At the default 1600×1000 window the about panel gets the share of the left
column its text needs (:func:`recording.about_share`): a table row per case
(the open-loop references and every architecture, up to all eight) and a
short key. Δv in km/s and miss in m, as every cwrend table.
"""

from __future__ import annotations

import math

import pytest

from cwrend_cli import campaign
from cwrend_cli.campaign import CaseResult
from cwrend_cli.config import config_from_dict, parse_archs
from cwrend_cli.config.adapt import windows_of
from cwrend_cli.output import recording

WINDOWS = {
    "degradation": {
        "windows": [
            {"start_s": 100.0, "end_s": 200.0, "r_scale": 10.0},
            {"start_s": 300.0, "end_s": 350.0, "bias_km": [1e-3, 0.0, 0.0]},
            {"start_s": 500.0, "end_s": 600.0, "dropout_probability": 0.5},
        ]
    }
}


@pytest.fixture(scope="module")
def everything() -> tuple[CaseResult, str]:
    cfg = config_from_dict(WINDOWS)
    case = campaign.run_case(cfg, parse_archs("everything"), 0)
    text = recording._about(case.runs, case.references, windows_of(cfg), 123.4, 8e-4)
    return case, text


def _shown_lines(text: str) -> float:
    """Lines the panel draws: a table row each, paragraphs wrapped, half a line per gap."""
    lines = 0.0
    for line in text.splitlines():
        if line.startswith("|---"):
            continue
        if line.startswith("|"):
            lines += 1
        elif not line:
            lines += 0.5
        else:
            lines += math.ceil(len(line) / recording.ABOUT_LINE_CHARS)
    return lines


def test_the_about_panel_of_all_eight_architectures_needs_no_scrolling(
    everything: tuple[CaseResult, str],
) -> None:
    case, text = everything
    n_cases = len(case.runs) + 2
    height = recording.ABOUT_CHROME_PX + recording.ABOUT_LINE_PX * _shown_lines(text)
    assert height <= recording.about_share(n_cases) * recording.LEFT_COLUMN_PX
    for run in case.runs:
        assert f"| {run.arch} |" in text


def test_the_about_panel_gives_dv_in_km_s_and_miss_in_m(
    everything: tuple[CaseResult, str],
) -> None:
    case, text = everything
    assert "| colour | case | Δv [km/s] | miss [m] |" in text
    run = case.runs[0]
    assert f"| {run.delta_v_km_s:.5f} | {run.miss_km * 1e3:.3g} |" in text


def test_the_3d_view_keeps_most_of_the_column_for_the_paper_ablation() -> None:
    assert recording.about_share(2 + 4) <= 0.45  # two references, the paper's four
