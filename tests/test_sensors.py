"""Measurement noise: degradation windows, chol(R) scaling, noise streams and files.

The degradation of the paper's study (the authors' code; the paper gives no values:
docs/method.md, "The paper's scenario", degradation row): 250 ≤ t < 325 s → true
R = 300 R_nominal, no bias; 325 ≤ t ≤ 400 s → true R = 300 R_nominal and bias
[10, −8, 12] m; otherwise R_nominal. The noise is one standard-normal realisation
scaled by chol(true R).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from cwrend_cli.config import CwrendConfig
from cwrend_cli.config.adapt import windows_of
from cwrend_cli.config.io import load_noise_file
from cwrend_cli.errors import InputDataError
from cwrend_cli.physics import sensors
from cwrend_cli.physics.params import Window

R_NOM = np.diag([1e-6, 1e-6, 1e-6])  # km², paper Table 1
BIAS_KM = np.array([0.010, -0.008, 0.012])  # [10, −8, 12] m: the authors' code (docs/method.md)
N_STEPS = 800
TIMES = np.arange(N_STEPS, dtype=float)  # step start times t_k, k = 0 … 799
#: Noise agreement [km]: the scaling is a 3×3 product, rounding ~1e-16 relative.
REL_TOL = 1e-14


@pytest.fixture(scope="module")
def paper_windows():
    return windows_of(CwrendConfig())


def spec_expected_noise(n: np.ndarray, t: float, r_nom: np.ndarray) -> np.ndarray:
    """Noise of one step from the docs/method.md table, written independently of the package."""
    if 250.0 <= t < 325.0:
        return np.linalg.cholesky(300.0 * r_nom) @ n
    if 325.0 <= t <= 400.0:
        return np.linalg.cholesky(300.0 * r_nom) @ n + BIAS_KM
    return np.linalg.cholesky(r_nom) @ n


# --- windows -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("t", "window"),
    [(0.0, -1), (249.0, -1), (250.0, 0), (324.0, 0), (325.0, 1), (400.0, 1), (401.0, -1)],
)
def test_active_window_boundaries(paper_windows, t: float, window: int) -> None:
    """[250, 325) is the first window, [325, 400] the second (t = 325 belongs to it)."""
    assert sensors.active_windows(np.array([t]), paper_windows)[0] == window


def test_paper_windows_noise_matches_spec_table(paper_windows) -> None:
    """Every step's noise equals the docs/method.md table: ×300 in both windows, bias in the 2nd."""
    rng = np.random.default_rng(42)
    std = rng.standard_normal((N_STEPS, 3))
    noise, active = sensors.measurement_noise(std, TIMES, R_NOM, paper_windows)
    for k, t in enumerate(TIMES):
        expected = spec_expected_noise(std[k], t, R_NOM)
        np.testing.assert_allclose(noise[k], expected, rtol=REL_TOL, atol=1e-18)
    assert np.count_nonzero(active == 0) == 75  # t = 250 … 324
    assert np.count_nonzero(active == 1) == 76  # t = 325 … 400


def test_bias_only_in_second_window(paper_windows) -> None:
    """With zero standard-normal draws the noise is exactly the bias where it applies."""
    noise, _ = sensors.measurement_noise(np.zeros((N_STEPS, 3)), TIMES, R_NOM, paper_windows)
    biased = (TIMES >= 325.0) & (TIMES <= 400.0)
    np.testing.assert_array_equal(noise[biased], np.broadcast_to(BIAS_KM, (biased.sum(), 3)))
    np.testing.assert_array_equal(noise[~biased], 0.0)


def test_no_windows_is_nominal_everywhere() -> None:
    """An empty degradation list: chol(R_nominal) n at every step, window index −1."""
    std = np.random.default_rng(3).standard_normal((N_STEPS, 3))
    noise, active = sensors.measurement_noise(std, TIMES, R_NOM, ())
    np.testing.assert_allclose(noise, std @ np.linalg.cholesky(R_NOM).T, rtol=REL_TOL)
    np.testing.assert_array_equal(active, -1)


def test_noise_scaled_by_cholesky_of_full_covariance() -> None:
    """v = chol(c R) n + b for a non-diagonal R (so the Cholesky factor matters)."""
    r_full = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]]) * 1e-6
    window = Window(start_s=10.0, end_s=19.0, r_scale=50.0, bias_km=(1e-3, 0.0, -2e-3))
    times = np.arange(30, dtype=float)
    std = np.random.default_rng(7).standard_normal((30, 3))
    noise, _ = sensors.measurement_noise(std, times, r_full, (window,))
    chol_nom = np.linalg.cholesky(r_full)
    chol_deg = np.linalg.cholesky(50.0 * r_full)
    for k, t in enumerate(times):
        if 10.0 <= t <= 19.0:
            expected = chol_deg @ std[k] + np.array([1e-3, 0.0, -2e-3])
        else:
            expected = chol_nom @ std[k]
        np.testing.assert_allclose(noise[k], expected, rtol=REL_TOL, atol=1e-18)


def test_noise_covariance_is_true_r() -> None:
    """Statistically: 200 000 draws have covariance 300 R (to 1.5 % of the largest entry)."""
    r_full = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.5], [0.0, 0.5, 2.0]]) * 1e-6
    window = Window(start_s=0.0, end_s=1e6, r_scale=300.0)
    m = 200_000
    std = np.random.default_rng(11).standard_normal((m, 3))
    noise, _ = sensors.measurement_noise(std, np.zeros(m), r_full, (window,))
    cov = np.cov(noise.T)
    # sampling error of a covariance entry ~ sqrt(2/m) ≈ 0.3 % of the diagonal: 1.5 % is 5σ
    np.testing.assert_allclose(cov, 300.0 * r_full, rtol=0, atol=0.015 * 300.0 * 4e-6)


# --- standard-normal streams ----------------------------------------------------------


def test_stream_reproducible() -> None:
    """Same seed → bitwise identical realisation (int seed and SeedSequence agree)."""
    a = sensors.standard_normal_stream(5, N_STEPS)
    b = sensors.standard_normal_stream(5, N_STEPS)
    c = sensors.standard_normal_stream(np.random.SeedSequence(5), N_STEPS)
    assert a.shape == (N_STEPS, 3)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)


def test_stream_seed_dependent() -> None:
    """Different seeds give different realisations."""
    a = sensors.standard_normal_stream(0, N_STEPS)
    b = sensors.standard_normal_stream(1, N_STEPS)
    assert not np.any(np.all(a == b, axis=1))


def test_stream_is_standard_normal() -> None:
    """Mean 0 and unit variance within sampling error (2400 draws: σ_mean ≈ 0.02)."""
    z = sensors.standard_normal_stream(0, N_STEPS).ravel()
    assert abs(z.mean()) < 0.1
    assert abs(z.var() - 1.0) < 0.15


# --- noise files ----------------------------------------------------------------------


def _frame(rows: int, seed: int = 0) -> pd.DataFrame:
    z = np.random.default_rng(seed).standard_normal((rows, 3))
    return pd.DataFrame(z, columns=["n1", "n2", "n3"])


def test_load_noise_csv(tmp_path) -> None:
    """A CSV with columns n1, n2, n3 and one row per step is read back exactly."""
    frame = _frame(N_STEPS)
    path = tmp_path / "noise.csv"
    frame.to_csv(path, index=False)
    np.testing.assert_array_equal(load_noise_file(path, N_STEPS), frame.to_numpy())


def test_load_noise_parquet(tmp_path) -> None:
    """A Parquet file (extra columns allowed, order by name) is read back exactly."""
    frame = _frame(N_STEPS)
    path = tmp_path / "noise.parquet"
    frame.assign(extra=1.0)[["n3", "extra", "n1", "n2"]].to_parquet(path)
    np.testing.assert_array_equal(load_noise_file(path, N_STEPS), frame.to_numpy())


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_load_noise_wrong_length(tmp_path, suffix: str) -> None:
    """One row per step is required; the message gives both counts."""
    path = tmp_path / f"noise{suffix}"
    frame = _frame(N_STEPS - 1)
    frame.to_csv(path, index=False) if suffix == ".csv" else frame.to_parquet(path)
    with pytest.raises(InputDataError) as info:
        load_noise_file(path, N_STEPS)
    msg = str(info.value)
    assert "799 rows" in msg and "800" in msg and path.name in msg


def test_load_noise_missing_column(tmp_path) -> None:
    """A missing column is named in the message."""
    path = tmp_path / "noise.csv"
    _frame(N_STEPS).drop(columns="n2").to_csv(path, index=False)
    with pytest.raises(InputDataError, match=r"missing column\(s\) n2"):
        load_noise_file(path, N_STEPS)


def test_load_noise_nan(tmp_path) -> None:
    """A NaN is rejected, naming the row."""
    frame = _frame(N_STEPS)
    frame.loc[17, "n3"] = np.nan
    path = tmp_path / "noise.parquet"
    frame.to_parquet(path)
    with pytest.raises(InputDataError, match=r"non-finite value in row 17"):
        load_noise_file(path, N_STEPS)


def test_load_noise_non_numeric(tmp_path) -> None:
    """A non-numeric entry is rejected with a message saying the columns must be numeric."""
    frame = _frame(N_STEPS).astype(object)
    frame.loc[3, "n1"] = "abc"
    path = tmp_path / "noise.csv"
    frame.to_csv(path, index=False)
    with pytest.raises(InputDataError, match="numeric"):
        load_noise_file(path, N_STEPS)


def test_load_noise_missing_file(tmp_path) -> None:
    """A missing file is an InputDataError (not a FileNotFoundError traceback)."""
    with pytest.raises(InputDataError, match="not found"):
        load_noise_file(tmp_path / "absent.csv", N_STEPS)


def test_window_label_names_scale_and_bias(paper_windows) -> None:
    # ‖(10, −8, 12) m‖ = √308 m = 17.5 m (3 significant digits)
    w1, w2 = paper_windows
    assert (w1.label, w2.label) == ("R×300", "R×300 + 17.5 m bias")
