"""The console at 80 columns (issue 37, items 11 and 14).

The campaign progress stays on one line at 80 columns whatever the
campaign's name, size and pace, and shows a rate and an ETA only once it
has one (two completions).
"""

from __future__ import annotations

import io

from rich.console import Console

from cwrend_cli.console import RichProgress


class _Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _bar_lines(progress: RichProgress) -> list[str]:
    """The progress bar as drawn now on an 80-column terminal."""
    bar = progress._bar
    assert bar is not None
    buf = io.StringIO()
    Console(file=buf, width=80, color_system=None).print(bar.make_tasks_table(bar.tasks))
    return buf.getvalue().splitlines()


def _terminal_progress(label: str, clock: _Clock) -> RichProgress:
    console = Console(file=io.StringIO(), width=80, force_terminal=True, color_system=None)
    return RichProgress(console, label, clock=clock)


def test_the_progress_bar_is_one_line_at_80_columns_at_its_widest() -> None:
    clock = _Clock()
    progress = _terminal_progress("sweep a-campaign-with-a-long-name", clock)
    progress.start(total=100_000, skipped=0)
    try:
        clock.now = 100.0
        progress.advance(10, 2)
        clock.now = 110.0
        progress.advance(12_330, 7)  # 1,234 runs/s
        lines = _bar_lines(progress)
        assert len(lines) == 1 and len(lines[0]) <= 80
        for part in ("12349/100000", "9 failed", "0:01:50", "1234 runs/s", "ETA 1 min 11 s"):
            assert part in lines[0]
    finally:
        progress.close()


def test_the_progress_shows_no_rate_before_it_has_one() -> None:
    clock = _Clock()
    progress = _terminal_progress("ablate paper", clock)
    progress.start(total=120, skipped=0)
    try:
        clock.now = 20.0  # compiling, the first task
        progress.advance(4, 0)
        (line,) = _bar_lines(progress)
        assert "runs/s" not in line and "ETA" not in line and "–" not in line
        assert "4/120" in line and "failed" not in line  # no failure: no failure count
        clock.now = 21.0
        progress.advance(4, 0)
        (line,) = _bar_lines(progress)
        assert "4 runs/s" in line and "ETA 28 s" in line
    finally:
        progress.close()
