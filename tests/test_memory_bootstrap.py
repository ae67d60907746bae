"""Memory of the campaign statistics (issue 17: flat in the number of runs).

The bootstrap draws and evaluates its resamples in blocks of at most
``statistics._CHUNK_VALUES`` values and holds the bootstrap statistics of at
most ``_CHUNK_VALUES // N_RESAMPLES`` intervals at once, whatever the sample
sizes. Behaviour tests, not timings: the block size changes no number (a
block may end inside a sample and span samples with different statistics),
and the memory allocated (numpy reports its buffers to ``tracemalloc``) stays
bounded by a constant when a sample grows. The statistics of the blocks are
evaluated in threads while the draws go on; the thread count changes no number.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from cwrend_cli.campaign import statistics


def _intervals(chunk_values: int, monkeypatch: pytest.MonkeyPatch) -> np.ndarray:
    """Intervals of samples of mixed sizes, statistics and constant ones, with one block size."""
    gen = np.random.default_rng(8)
    sizes = [5, 5, 5, 5, 40, 40, 3, 3, 1, 2, 2, 40, 5, 7]
    samples = [gen.lognormal(size=n) for n in sizes]
    samples[6] = np.full(3, 0.5)  # constant: no draw
    fns = [statistics.STATISTICS[k] for k in ("mean", "median", "p95", "median")] * 3
    fns += [np.mean, np.median]
    monkeypatch.setattr(statistics, "_CHUNK_VALUES", chunk_values)
    return statistics.bootstrap_cis(samples, fns, np.random.default_rng(21))


@pytest.mark.parametrize("chunk_values", [1, 150, 2_999, 1 << 14])
def test_the_block_size_changes_no_number(
    chunk_values: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """1 value: one row a block and one interval at a time; 150: blocks ending inside samples;
    2,999 and 16,384: blocks spanning samples of different statistics."""
    whole = _intervals(1 << 30, monkeypatch)  # every sample of a size in one block
    np.testing.assert_array_equal(_intervals(chunk_values, monkeypatch), whole)


@pytest.mark.parametrize("threads", [1, 2, 3])
@pytest.mark.parametrize("chunk_values", [150, 1 << 14])
def test_the_evaluation_threads_change_no_number(
    threads: int, chunk_values: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The statistics of drawn blocks are evaluated in threads while the draws go on in order:
    any thread count gives the intervals of one block at a time, in one thread."""
    monkeypatch.setattr(statistics, "_evaluation_threads", lambda: 1)
    whole = _intervals(1 << 30, monkeypatch)
    monkeypatch.setattr(statistics, "_evaluation_threads", lambda: threads)
    np.testing.assert_array_equal(_intervals(chunk_values, monkeypatch), whole)


def test_the_bootstrap_memory_does_not_grow_with_the_sample() -> None:
    """Two samples of 5,000 values (20 million resampled values): the blocks bound the memory.

    Before the blocks, one sample's draw alone held 80 MB of indices and 80 MB of values.
    """
    gen = np.random.default_rng(2)
    samples = [gen.normal(size=5_000), gen.normal(size=5_000)]
    tracemalloc.start()
    try:
        statistics.bootstrap_cis(samples, [np.median, np.mean], np.random.default_rng(0))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    per_array = statistics._CHUNK_VALUES * 8
    assert peak < 5 * per_array  # indices, values, the statistic's copy, a margin
    assert peak < 32 * 2**20
