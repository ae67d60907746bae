"""The arithmetic of ``python -m benchmarks.bench_constrained`` (no timing is asserted)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest


def test_a_section_of_no_seeds_has_no_rows(monkeypatch: pytest.MonkeyPatch) -> None:
    """``--tumbling-seeds 0`` leaves the tumbling section out instead of taking the mean and
    percentiles of no re-solves (it crashed on an empty array)."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1]))  # the repository's
    from benchmarks import bench_constrained

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


def test_the_typical_row_splits_the_mean_into_typical_and_tail(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The typical re-solve (one SCP program, none left to Clarabel, at most
    TYPICAL_ITERATIONS iterations) has its own mean, and the note says what the others
    add to the mean of all: here 1 ms typical twice, a 31-iteration re-solve of 10 ms and
    one with a program left to Clarabel of 100 ms add (10 + 100) / 4 and 100 / 4 ms."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1]))  # the repository's
    from benchmarks import bench_constrained as bc

    measured = bc.Loops(
        times=np.array([1.0, 1.0, 10.0, 100.0]),
        scp=np.array([1, 1, 1, 2]),
        iterations=np.array([5, bc.TYPICAL_ITERATIONS, bc.TYPICAL_ITERATIONS + 1, 8]),
        fallbacks=np.array([0, 0, 0, 1]),
        softened=0,
        counts=(1, 5),
    )
    two = np.ones(2, int)
    twin = bc.Loops(np.array([0.5, 0.5]), two, two, 0 * two, 0, (0, 0))
    monkeypatch.setattr(bc, "_loops", lambda cfg, slug, seeds: measured if cfg == "c" else twin)
    rows = bc._rows("s", ("c", "u"), 1, ("mtf",), "constrained", "unconstrained", 3.0)  # type: ignore[arg-type]
    (typical,) = [r for r in rows if r.name.endswith("typical re-solve mean")]
    assert typical.value == pytest.approx(1.0) and typical.baseline == pytest.approx(0.5)
    assert "2 of 4" in typical.note
    assert "add 27.5 ms to the mean" in typical.note and "(1) 25 ms" in typical.note
