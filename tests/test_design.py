"""Campaign designs (issue 19): reproducible, space-filling as defined, Sobol indices by SALib."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cwrend_cli.campaign import design
from cwrend_cli.errors import ConfigError

UNIT = design.ParameterRange("x", "float", 0.0, 1.0)


@pytest.mark.parametrize("kind", design.DESIGNS)
def test_a_design_is_reproducible_from_the_root_seed(kind: design.Design) -> None:
    a = design.unit_samples(kind, 16, 3, root_seed=7)
    assert np.array_equal(a, design.unit_samples(kind, 16, 3, root_seed=7))
    assert not np.array_equal(a, design.unit_samples(kind, 16, 3, root_seed=8))
    assert a.shape == (16 * design.n_runs_per_base(kind, 3), 3)
    assert ((a >= 0) & (a < 1)).all()


def test_a_latin_hypercube_has_one_point_per_stratum_in_each_dimension() -> None:
    n = 37
    u = design.unit_samples("lhs", n, 4, root_seed=0)
    for dim in range(4):
        assert sorted(np.floor(u[:, dim] * n).astype(int)) == list(range(n))


def test_the_sobol_base_points_fill_every_dyadic_interval_once() -> None:
    """2^m points of a scrambled Sobol sequence: each 1-D projection hits each [i, i+1)/2^m."""
    n, dims = 64, 3
    u = design.unit_samples("sobol", n, dims, root_seed=0)
    block = dims + 2  # SALib's order per base sample j: A_j, A_B^(1)_j … A_B^(D)_j, B_j
    for rows in (u[0::block], u[block - 1 :: block]):  # A and B
        for dim in range(dims):
            assert sorted(np.floor(rows[:, dim] * n).astype(int)) == list(range(n))


def test_a_sobol_design_needs_a_power_of_two() -> None:
    with pytest.raises(ConfigError, match="power of two base points"):
        design.unit_samples("sobol", 48, 2, root_seed=0)


@pytest.mark.parametrize("kind", ["sobol", "random"])
def test_a_larger_extendable_design_contains_the_smaller(kind: design.Design) -> None:
    small = design.unit_samples(kind, 16, 2, root_seed=3)
    large = design.unit_samples(kind, 64, 2, root_seed=3)
    assert {tuple(r) for r in small} <= {tuple(r) for r in large}


def test_a_larger_latin_hypercube_is_a_new_design() -> None:
    """Documented: LHS strata depend on N, so 2N points do not contain the N-point design."""
    small = design.unit_samples("lhs", 16, 2, root_seed=3)
    large = design.unit_samples("lhs", 32, 2, root_seed=3)
    assert not {tuple(r) for r in small} <= {tuple(r) for r in large}


def test_ranges_map_the_unit_interval_as_configured() -> None:
    log = design.parse_range("scenario.u_max_km_s2", {"low": 1e-4, "high": 1e-2, "log": True})
    assert log.value(0.5) == pytest.approx(1e-3, rel=1e-9)  # the geometric midpoint
    ints = design.parse_range("solver.max_iter", {"low": 10, "high": 12, "int": True})
    assert [ints.value(u) for u in (0.0, 0.34, 0.67, 0.999)] == [10, 11, 12, 12]
    choice = design.parse_range("truth.model", {"values": ["cw", "two_body", "j2"]})
    assert [choice.value(u) for u in (0.1, 0.5, 0.9)] == ["cw", "two_body", "j2"]


def test_a_sampled_float_is_stored_as_used_with_10_significant_digits() -> None:
    value = design.parse_range("b", {"low": 0.0, "high": 1.0}).value(1 / 3)
    assert value == 0.3333333333 and repr(value) == "0.3333333333"


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"low": 1.0}, "a range needs low and high"),
        ({"low": 2.0, "high": 1.0}, "need finite low < high"),
        ({"low": 0.0, "high": 1.0, "log": True}, "log = true needs low > 0"),
        ({"low": 0.5, "high": 3, "int": True}, "int = true needs integer low and high"),
        ({"low": 0.0, "high": 1.0, "step": 0.1}, "unknown field(s) step"),
        ({"values": []}, "lists at least one value"),
    ],
)
def test_a_bad_range_names_its_key(spec: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=r"\[sweep\] schedule\.beta: ") as err:
        design.parse_range("schedule.beta", spec)
    assert message in str(err.value)


def _ishigami(x: np.ndarray, a: float = 7.0, b: float = 0.1) -> np.ndarray:
    return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])


def test_sobol_indices_of_the_ishigami_function_match_the_analytic_values() -> None:
    """Ishigami & Homma (1990), a = 7, b = 0.1, x ~ U[−π, π]³ (analytic indices: Sobol' 2001).

    V = a²/8 + bπ⁴/5 + b²π⁸/18 + 1/2; V1 = (1 + bπ⁴/5)²/2, V2 = a²/8, V13 = b²π⁸(1/18 − 1/50).
    Each analytic value must lie within its SALib bootstrap interval widened from the
    95 % to the 99.9 % level (× 3.29/1.96): six checks at a 0.1 % false-alarm rate each.
    """
    a, b, pi = 7.0, 0.1, math.pi
    v1 = 0.5 * (1 + b * pi**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = b**2 * pi**8 * (1 / 18 - 1 / 50)
    v = v1 + v2 + v13
    s1 = np.array([v1, v2, 0.0]) / v
    st = np.array([v1 + v13, v2, v13]) / v
    ranges = [design.ParameterRange(f"x{i}", "float", -pi, pi) for i in range(3)]
    points = design.design_points("sobol", ranges, 4096, root_seed=0)
    x = np.array([[value for _, value in p] for p in points])
    idx = design.sobol_indices(ranges, _ishigami(x), root_seed=0)
    widen = 3.29 / 1.96
    assert np.all(np.abs(idx.s1 - s1) <= widen * idx.s1_conf)
    assert np.all(np.abs(idx.st - st) <= widen * idx.st_conf)
    assert np.all(idx.s1_conf < 0.05) and np.all(idx.st_conf < 0.05)  # tight enough to mean it
