"""The arithmetic of ``python -m benchmarks.bench_constrained`` (no timing is asserted)."""

from __future__ import annotations

from benchmarks import bench_constrained


def test_a_section_of_no_seeds_has_no_rows() -> None:
    """``--tumbling-seeds 0`` leaves the tumbling section out instead of taking the mean and
    percentiles of no re-solves (it crashed on an empty array)."""
    rows = bench_constrained._rows(
        bench_constrained.TUMBLING_SECTION,
        bench_constrained.tumbling_configs(),
        0,
        ("mtf",),
        "turning-constraint",
        "fixed-target constrained",
        None,
    )
    assert rows == []
