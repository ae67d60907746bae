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


def test_a_second_order_sobol_design_contains_the_first_order_design() -> None:
    """Saltelli's scheme with the B_A^(i) rows too: every first-order row is in it, in order."""
    first = design.unit_samples("sobol", 16, 3, root_seed=5)
    second = design.unit_samples("sobol", 16, 3, root_seed=5, second_order=True)
    assert second.shape == (16 * design.n_runs_per_base("sobol", 3, second_order=True), 3)
    assert second.shape == (16 * (2 * 3 + 2), 3)
    for k in range(3 + 1):  # A, A_B^(1..3); then B: SALib's first rows of each block
        assert np.array_equal(first[k :: 3 + 2], second[k :: 2 * 3 + 2])
    assert np.array_equal(first[3 + 1 :: 3 + 2], second[2 * 3 + 1 :: 2 * 3 + 2])  # B


def test_second_order_sobol_indices_of_the_ishigami_function_match_the_analytic_values() -> None:
    """Ishigami (a = 7, b = 0.1): the only interaction is x1 × x3, V13 / V; S2 of the other
    pairs is 0. Each within its SALib interval widened to 99.9 % (as the first-order test)."""
    a, b, pi = 7.0, 0.1, math.pi
    v = 0.5 * (1 + b * pi**4 / 5) ** 2 + a**2 / 8 + b**2 * pi**8 * (1 / 18 - 1 / 50)
    s13 = b**2 * pi**8 * (1 / 18 - 1 / 50) / v
    ranges = [design.ParameterRange(f"x{i}", "float", -pi, pi) for i in range(3)]
    points = design.design_points("sobol", ranges, 4096, root_seed=0, second_order=True)
    x = np.array([[value for _, value in p] for p in points])
    idx = design.sobol_indices(ranges, _ishigami(x), root_seed=0, second_order=True)
    assert idx.s2 is not None and idx.s2_conf is not None
    widen = 3.29 / 1.96
    for (i, j), exact in {(0, 1): 0.0, (0, 2): s13, (1, 2): 0.0}.items():
        assert abs(idx.s2[i, j] - exact) <= widen * idx.s2_conf[i, j], (i, j)
    assert s13 > 3 * idx.s2_conf[0, 2]  # the interaction is resolved, not noise


def test_rbd_fast_finds_the_variance_shares_of_a_linear_model_on_a_latin_hypercube() -> None:
    """y = 4 x1 + 2 x2 + 0 x3, x ~ U[0, 1]³: S1 = (16, 4, 0) / 20, no interactions.

    RBD-FAST on a plain LHS (no special sampling) must find each within its interval
    widened to 99.9 %, and the dominant parameter first.
    """
    ranges = [design.ParameterRange(f"x{i}", "float", 0.0, 1.0) for i in range(3)]
    unit = design.unit_samples("lhs", 512, 3, root_seed=1)
    y = 4 * unit[:, 0] + 2 * unit[:, 1]
    idx = design.rbd_fast_indices(ranges, unit, y, root_seed=1)
    exact = np.array([0.8, 0.2, 0.0])
    assert np.all(np.abs(idx.s1 - exact) <= 3.29 / 1.96 * idx.s1_conf)
    assert list(np.argsort(-idx.s1)) == [0, 1, 2]
    assert np.all(idx.s1_conf < 0.1) and np.isnan(idx.st).all()  # no total index by RBD-FAST


def test_rbd_fast_harmonics_follow_the_design_size() -> None:
    """M ≤ (n − 1) / 8 (the bias correction stays bounded in the half-size bootstrap), ≤ 10."""
    assert [design.rbd_fast_harmonics(n) for n in (8, 9, 16, 17, 80, 81, 10_000)] == [
        0, 1, 1, 2, 9, 10, 10,
    ]  # fmt: skip
    unit = design.unit_samples("lhs", 8, 1, root_seed=0)
    with pytest.raises(ValueError, match="at least 9 rows"):
        design.rbd_fast_indices([UNIT], unit, unit[:, 0], root_seed=0)


def test_the_salib_problem_names_every_range_with_its_bounds_and_distribution() -> None:
    ranges = [
        design.parse_range("schedule.beta", {"low": 0.05, "high": 1.0}),
        design.parse_range("schedule.kappa_mtf", {"low": 3.0, "high": 48.0, "log": True}),
        design.parse_range("solver.max_iter", {"low": 20, "high": 60, "int": True}),
        design.parse_range("truth.model", {"values": ["cw", "j2"]}),
    ]
    assert design.salib_problem(ranges) == {
        "num_vars": 4,
        "names": ["schedule.beta", "schedule.kappa_mtf", "solver.max_iter", "truth.model"],
        "bounds": [[0.05, 1.0], [3.0, 48.0], [0.0, 1.0], [0.0, 1.0]],
        "dists": ["unif", "logunif", "unif", "unif"],
    }


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("schedule.beta=0.1:1.0", design.ParameterRange("schedule.beta", "float", 0.1, 1.0)),
        (
            "schedule.kappa_mtf=3:48:log",
            design.ParameterRange("schedule.kappa_mtf", "float", 3.0, 48.0, log=True),
        ),
        ("solver.max_iter=20:60:int", design.ParameterRange("solver.max_iter", "int", 20, 60)),
        ("truth.model=cw,j2", design.ParameterRange("truth.model", "choice", values=("cw", "j2"))),
    ],
)
def test_a_command_line_range_is_the_range_of_a_sweep_table(
    text: str, expected: design.ParameterRange
) -> None:
    assert design.parse_cli_range(text) == expected


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("schedule.beta", "expected KEY=LOW:HIGH"),
        ("schedule.beta=0.1", None),  # a single value is one category: accepted
        ("schedule.beta=a:b", "LOW and HIGH must be numbers"),
        ("schedule.beta=1:0.5", "need finite low < high"),
        ("schedule.beta=0.1:1:cube", "expected KEY=LOW:HIGH"),
        ("schedule.beta=0:1:log", "log = true needs low > 0"),
        ("schedule.beta=0.5:3:int", "int = true needs integer low and high"),
        ("schedule.beta=0.1,,0.2", "empty value in the list"),
    ],
)
def test_a_bad_command_line_range_names_the_option(text: str, message: str | None) -> None:
    if message is None:
        assert design.parse_cli_range(text).kind == "choice"
        return
    with pytest.raises(ConfigError, match=f"^--range {text}: ") as err:
        design.parse_cli_range(text)
    assert message in str(err.value)


@pytest.mark.parametrize("text", ["schedule.beta=0.1-1.0", "schedule.beta=1..5", "x.y=a,-1-2"])
def test_a_range_written_with_a_dash_is_refused_not_read_as_one_category(text: str) -> None:
    """``0.1-1.0`` was read as one categorical value, the string "0.1-1.0"."""
    with pytest.raises(ConfigError, match=f"^--range {text}: '.*' is not a range") as err:
        design.parse_cli_range(text)
    assert "KEY=LOW:HIGH (uniform)" in str(err.value)  # the option's syntax
