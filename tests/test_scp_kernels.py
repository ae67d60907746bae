"""The constrained SCP's numba kernels give numpy's numbers bit for bit (issue 32 speed).

Each kernel replaces numpy reductions over a short last axis (slow: a reduction a row)
with a loop doing numpy's arithmetic in numpy's order, so that no plan moves by a bit
(``test_dual_plan_numbers`` and ``test_fixed_target_numbers`` pin whole plans). Each test
writes the numpy formula the code had before and compares on random inputs with
``np.array_equal`` (exact: no tolerance, bits are the claim).
"""

from __future__ import annotations

import numpy as np
import pytest

from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics import dynamics
from cwrend_cli.physics.guidance import constrained as cp
from cwrend_cli.physics.guidance import feasibility, path_dual
from cwrend_cli.physics.params import Constraints, Corridor, KeepOut

N_MOTION = 0.00104218449  # rad/s, the paper's
U_MAX = 8e-4  # km/s²


def _vectors(rng: np.random.Generator, rows: int) -> np.ndarray:
    """Rows of 3-vectors with components over ten decades (km and km/s alike), half of
    them strided views (as ``x[:, :3]`` of a state array)."""
    full = rng.normal(size=(rows, 6)) * 10.0 ** rng.uniform(-8, 2, 6)
    return full[:, :3] if rows % 2 else np.ascontiguousarray(full[:, 3:])


def test_row_norms_are_numpys_norms_bit_for_bit() -> None:
    rng = np.random.default_rng(1)
    for rows in range(1, 400, 7):
        w = _vectors(rng, rows)
        assert np.array_equal(cg.row_norms(w), np.linalg.norm(w, axis=-1))
    stacked = rng.normal(size=(2, 5, 3))
    assert np.array_equal(cg.row_norms(stacked), np.linalg.norm(stacked, axis=-1))


def test_ellipsoid_levels_and_tangent_planes_are_numpys_bit_for_bit() -> None:
    """The formulas of before: Σ(r/a)², ∇g = 2r/a², n = ∇g/‖∇g‖, nᵀr + (1 − g)/‖∇g‖."""
    rng = np.random.default_rng(2)
    for rows in range(1, 400, 7):
        a = rng.uniform(0.01, 0.5, 3)
        r = _vectors(rng, rows)
        level = np.sum((r / a) ** 2, axis=-1)
        assert np.array_equal(cg.ellipsoid_level(r, a), level)
        grad = 2.0 * r / a**2
        size = np.sqrt(np.sum(grad * grad, axis=1))
        normals = grad / size[:, None]
        offsets = np.sum(normals * r, axis=1) + (1.0 - level) / size
        got = cg.tangent_planes(a, r)
        assert np.array_equal(got[0], normals) and np.array_equal(got[1], offsets)


def test_zoh_rollout_is_zoh_step_after_zoh_step_bit_for_bit() -> None:
    phi, gam = dynamics.discretize(N_MOTION, 1.0)
    rng = np.random.default_rng(3)
    x0, u = rng.normal(size=6), 1e-4 * rng.normal(size=(300, 3))
    x = dynamics.zoh_rollout(phi, gam, x0, u)
    expected = [x0]
    for k in range(u.shape[0]):
        expected.append(dynamics.zoh_step(phi, gam, expected[-1], u[k]))
    assert np.array_equal(x, np.array(expected))


def test_largest_norms_are_numpys_largest_norms_bit_for_bit() -> None:
    rng = np.random.default_rng(4)
    for rows in range(1, 400, 7):
        x = rng.normal(size=(rows, 6)) * 10.0 ** rng.uniform(-8, 2, 6)
        r = float(np.max(np.linalg.norm(x[:, :3], axis=1)))
        v = float(np.max(np.linalg.norm(x[:, 3:], axis=1)))
        assert cp._largest_norms(x) == (r, v)
    x[3, 4] = np.nan
    assert all(np.isnan(cp._largest_norms(x)))


def _pairs_before(
    modes: np.ndarray, r_bar: np.ndarray, half_spaces: list[cp.HalfSpaces], trust_km: float
) -> tuple[np.ndarray, np.ndarray]:
    """``constrained._pairs`` as it was (every row, lexsorted; the trust test by numpy)."""
    k = np.arange(1, modes.size - 1)
    has = half_spaces[0].index >= 0
    own = k[has[k]]
    before = k[has[k - 1] & (modes[k] != 0)]
    bodies = range(len(half_spaces))
    pairs = np.concatenate(
        [np.column_stack([own, own, np.full(own.size, b)]) for b in bodies]
        + [np.column_stack([before, before - 1, np.full(before.size, b)]) for b in bodies]
    ).astype(np.int64)
    pairs = pairs[np.lexsort((pairs[:, 2], -pairs[:, 1], pairs[:, 0]))]
    normals, offsets = cp._planes(half_spaces, pairs)
    low = np.sum(normals * r_bar[pairs[:, 0]], axis=1) - trust_km * np.sum(np.abs(normals), axis=1)
    left_out = low >= offsets + cp.SCP_TOL_KM
    return pairs[~left_out], pairs[left_out]


def _random_rows(
    rng: np.random.Generator, steps: int, bodies: int
) -> tuple[np.ndarray, list[cp.HalfSpaces], np.ndarray, float]:
    """Random modes, unit-normal half-spaces of ``bodies`` ellipsoids at the keep-out nodes,
    positions r̄ [km] and a trust radius [km]: what ``_pairs`` reads."""
    modes = rng.integers(0, 4, steps + 1).astype(np.int8)
    modes[0] = modes[-1] = 0
    nodes = np.r_[0, np.flatnonzero(modes >= 2)]
    half_spaces = []
    for _b in range(bodies):
        normals = rng.normal(size=(nodes.size, 3))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        half_spaces.append(
            cp.HalfSpaces(nodes, normals, 0.1 * rng.normal(size=nodes.size), steps + 1)
        )
    return modes, half_spaces, 0.3 * rng.normal(size=(steps + 1, 3)), float(rng.uniform(0.0, 0.3))


@pytest.mark.parametrize("bodies", [1, 3])
def test_the_half_space_rows_and_those_left_out_are_those_of_before(bodies: int) -> None:
    rng = np.random.default_rng(5 + bodies)
    for _ in range(200):
        steps = int(rng.integers(3, 200))
        modes, half_spaces, r_bar, trust = _random_rows(rng, steps, bodies)
        got, want = (
            cp._pairs(modes, r_bar, half_spaces, trust),
            _pairs_before(modes, r_bar, half_spaces, trust),
        )
        for g, w in zip(got, want, strict=True):
            assert g.dtype == w.dtype and np.array_equal(g, w)


def test_the_broken_trust_rows_are_those_of_before() -> None:
    """(nodes, components) where ``[d, −d] < −(T + tol)``, d = r − r̄, at constrained nodes."""
    rng = np.random.default_rng(6)
    for _ in range(200):
        steps = int(rng.integers(2, 200))
        modes = rng.integers(0, 4, steps + 1).astype(np.int8)
        r_bar = 0.3 * rng.normal(size=(steps + 1, 3))
        r = r_bar + 0.2 * rng.normal(size=(steps + 1, 3))
        trust = float(rng.uniform(0.0, 0.3))
        geo = cg.geometry(Constraints(keep_out=KeepOut((0.2, 0.2, 0.2))))
        zeros = np.zeros(6)
        sub = cp._Subproblem(
            N_MOTION, 1.0, U_MAX, zeros, zeros, 0.5, geo, modes, r_bar,
            np.zeros((steps, 3)), np.zeros(steps + 1), [], trust,
        )  # fmt: skip
        boxed = np.flatnonzero(modes > 0)
        d = r[boxed] - r_bar[boxed]
        at, comp = np.nonzero(np.hstack([d, -d]) < -(trust + cp.DUAL_TOL_KM))
        got = cp._broken_trust(sub, r)
        assert np.array_equal(got[0], boxed[at]) and np.array_equal(got[1], comp.astype(np.int64))


def test_the_grids_block_products_are_its_own_however_the_stack_was_made() -> None:
    """Sliced from a longer stack or made after a shorter one: each step's ``A_j A_jᵀ`` is
    that of the grid's own blocks × u_max, bit for bit."""
    path_dual._PRODUCTS.clear()
    for steps in (50, 300, 120, 301):
        blocks = feasibility.grid_problem(
            N_MOTION, np.zeros(6), np.zeros(6), float(steps), 1.0, U_MAX
        ).blocks
        a = blocks * U_MAX
        expected = np.einsum("jrk,jck->jrc", a, a)  # rounding of a 3-term sum
        got = path_dual.grid_arrays(N_MOTION, 1.0, U_MAX, steps)[1]
        assert got.shape == (steps, 6, 6)
        assert np.array_equal(got, path_dual.block_products(np.ascontiguousarray(a)))
        np.testing.assert_allclose(got, expected, rtol=1e-15, atol=0)


def test_the_grids_scaled_blocks_are_its_blocks_times_u_max_however_the_stack_was_made() -> None:
    """:func:`.path_dual.grid_arrays`' first: ``A_j = Φ^{N−1−j} Γ u_max`` of the grid's own
    blocks, bit for bit, and beside them their products."""
    path_dual._PRODUCTS.clear()
    for steps in (50, 300, 120, 301):
        blocks = feasibility.grid_problem(
            N_MOTION, np.zeros(6), np.zeros(6), float(steps), 1.0, U_MAX
        ).blocks
        scaled, products = path_dual.grid_arrays(N_MOTION, 1.0, U_MAX, steps)
        assert np.array_equal(scaled, blocks * U_MAX)
        assert np.array_equal(products, path_dual.block_products(np.ascontiguousarray(scaled)))


def _turns(rng: np.random.Generator, count: int) -> cg.BodyMotion:
    """Random rotations at ``count`` nodes (what :func:`.constrained._planes` reads)."""
    q = rng.normal(size=(count, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    return cg.BodyMotion(cg.rotation_matrices(q), np.zeros((count, 3)), 0.0, 0.0)


@pytest.mark.parametrize(("bodies", "turning"), [(1, False), (3, False), (2, True)])
def test_the_kept_rows_planes_are_those_planes_reads(bodies: int, turning: bool) -> None:
    """``_pairs_planes``: the kept rows' (normals, offsets) equal to ``_planes`` of the kept
    rows, bit for bit (fixed target: one pass; turning: the rows' planes turned to their
    nodes' times); the rows themselves are ``_pairs``' (tested against numpy above)."""
    rng = np.random.default_rng(7 + bodies)
    for _ in range(100):
        steps = int(rng.integers(3, 150))
        modes, half_spaces, r_bar, trust = _random_rows(rng, steps, bodies)
        motion = _turns(rng, steps + 1) if turning else None
        kept, _, (normals, offsets) = cp._pairs_planes(modes, r_bar, half_spaces, trust, motion)
        want = cp._planes(half_spaces, kept, motion)
        assert np.array_equal(normals, want[0]) and np.array_equal(offsets, want[1])


def test_the_keep_out_nodes_tangent_planes_are_those_of_before() -> None:
    """``_node_planes``: the formula of before, by numpy: the points r (outside) or
    (r + shift)/√level(r + shift) (inside), their tangent planes, + the nodes' margins."""
    rng = np.random.default_rng(8)
    for rows in range(2, 300, 7):
        a = rng.uniform(0.05, 0.5, 3)
        r = rng.normal(size=(rows, 3)) * a * rng.uniform(0.2, 2.0, (rows, 1))  # in and out
        nodes = np.r_[0, np.flatnonzero(rng.random(rows - 1) < 0.7) + 1].astype(np.int64)
        shift = float(np.max(a)) * rng.normal(size=3)
        margins = rng.uniform(0.0, 1e-3, rows)
        level = cg.ellipsoid_level(r, a)
        points = np.array(r[nodes], dtype=np.float64)
        inside = level[nodes] < 1.0
        shifted = points[inside] + shift
        points[inside] = shifted / np.sqrt(cg.ellipsoid_level(shifted, a))[:, None]
        want_normals, want_offsets = cg.tangent_planes(a, points)
        got = cp._node_planes(a, r, level, nodes, shift, margins)
        assert np.array_equal(got[0], want_normals)
        assert np.array_equal(got[1], want_offsets + margins[nodes])


def test_the_warm_multipliers_are_those_of_before() -> None:
    """``_warm_multipliers`` by its kernel (codes that do not repeat) gives numpy's sorted
    look-up of before; with a repeated code the kernel declines (numpy's sort decides)."""
    rng = np.random.default_rng(9)
    for _ in range(300):
        codes = rng.choice(1 << 24, size=int(rng.integers(1, 60)), replace=False)
        warm = cp.Duals(codes.astype(np.int64), rng.random(codes.size))
        code = np.r_[rng.choice(codes, size=codes.size // 2), rng.integers(0, 1 << 24, 20)]
        guess = rng.random(code.size)
        order = np.argsort(warm.codes)
        at = np.clip(np.searchsorted(warm.codes[order], code), 0, codes.size - 1)
        hit = warm.codes[order][at] == code
        want = guess.copy()
        want[hit] = warm.values[order][at[hit]]
        assert np.array_equal(cp._warm_multipliers(warm, code, guess), want)
    repeated = np.array([5, 7, 5], dtype=np.int64)
    assert not cp._carry_unique(repeated, np.ones(3), np.array([5]), np.zeros(1))


def test_the_warm_trust_rows_are_those_of_before() -> None:
    """``_trust_codes``: the kind-2 codes (node × 2²⁰ + 2 × 2¹⁶ + component) at constrained
    nodes with a component below 6, in their order, as numpy selected them before."""
    rng = np.random.default_rng(10)
    for _ in range(200):
        modes = rng.integers(0, 4, int(rng.integers(2, 100))).astype(np.int8)
        count = int(rng.integers(0, 80))
        codes = (
            rng.integers(1, modes.size + 5, count) * cp._CODE_NODE
            + rng.integers(0, 5, count) * cp._CODE_KIND
            + rng.integers(0, 8, count)
        ).astype(np.int64)
        sel = codes[(codes % cp._CODE_NODE) // cp._CODE_KIND == 2]
        nodes, comps = sel // cp._CODE_NODE, sel % cp._CODE_KIND
        keep = (nodes < modes.size) & (comps < 6)
        keep[keep] = modes[nodes[keep]] > 0
        got = cp._trust_codes(codes, modes)
        assert np.array_equal(got[0], nodes[keep]) and np.array_equal(got[1], comps[keep])


def test_the_kept_corridor_rows_are_the_geometrys_own() -> None:
    """``_untightened_corridor``: the rows of ``corridor_cone(geo, 0)`` of the geometry asked,
    bit for bit, when the geometries alternate (the one kept is replaced, never mixed up)."""
    geos = [
        cg.geometry(
            Constraints(
                keep_out=KeepOut((0.2, 0.2, 0.2)),
                corridor=Corridor((0.0, 0.0, -0.25), (0.1 * i, 0.0, -1.0), 20.0 + 5 * i),
            )
        )
        for i in range(2)
    ]
    for geo in (geos[0], geos[1], geos[1], geos[0]):
        _, rows, _ = cp._untightened_corridor(geo)
        fresh = cg.corridor_cone(geo, 0.0).rows()
        assert all(np.array_equal(g, w) for g, w in zip(rows, fresh, strict=True))
