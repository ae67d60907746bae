"""Measurement noise: degradation windows and standard-normal streams (SPEC §3, §6).

No file I/O here: an external realisation is read by :mod:`cwrend_cli.config.io`.

The truth is measured as ``y = H x + chol(R_true) n + b`` where ``n`` is one
standard-normal 3-vector per step, shared by every architecture of a seed
(fair comparison, SPEC §6), and ``R_true = r_scale · R_nominal`` and the bias
``b`` come from the degradation window active at the step's start time.
Units: km, km², s.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cwrend_cli.physics.params import Window


def in_window(times_s: np.ndarray, window: Window) -> np.ndarray:
    """True where ``window`` is active: ``start_s ≤ t ≤ end_s`` (both ends included)."""
    return (times_s >= window.start_s) & (times_s <= window.end_s)


def active_windows(times_s: np.ndarray, windows: Sequence[Window]) -> np.ndarray:
    """Index of the window active at each time (−1 for none).

    A window is active on ``start_s ≤ t ≤ end_s``; where windows overlap the
    later one in the list applies (so the paper's ``[250, 325)`` then
    ``[325, 400]`` is written as two windows sharing t = 325).
    """
    idx = np.full(times_s.shape, -1, dtype=np.int64)
    for i, w in enumerate(windows):
        idx[in_window(times_s, w)] = i
    return idx


def measurement_noise(
    standard_normal: np.ndarray,
    times_s: np.ndarray,
    r_nominal: np.ndarray,
    windows: Sequence[Window],
) -> tuple[np.ndarray, np.ndarray]:
    """Noise added to each measurement (N, 3) [km] and the active window index (N,).

    Row k uses the window at ``times_s[k]`` (the step's start, SPEC §5):
    ``v_k = chol(r_scale R_nominal) n_k + bias``.
    """
    active = active_windows(times_s, windows)
    chol_nominal = np.linalg.cholesky(r_nominal)
    scale = np.ones(times_s.shape)
    bias = np.zeros((times_s.shape[0], 3))
    for i, w in enumerate(windows):
        mask = active == i
        scale[mask] = w.r_scale
        bias[mask] = np.asarray(w.bias_km, dtype=float)
    # chol(c R) = √c chol(R)
    noise = np.sqrt(scale)[:, None] * (standard_normal @ chol_nominal.T) + bias
    return noise, active


def standard_normal_stream(seed: np.random.SeedSequence | int, n_steps: int) -> np.ndarray:
    """One standard-normal realisation (n_steps, 3) from a ``SeedSequence``-keyed PCG64 stream."""
    seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    return np.random.Generator(np.random.PCG64(seq)).standard_normal((n_steps, 3))
