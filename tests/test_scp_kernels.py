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


def test_a_corridor_made_again_with_the_same_bits_is_the_one_kept() -> None:
    """A closed loop makes a new ``Geometry`` every re-solve: the corridor kept for the same
    port, axis and half-angle is reused (its arrays, not made again); one bit apart, not."""
    corridor = Corridor((0.0, 0.0, -0.25), (0.0, 0.0, -1.0), 30.0)
    first = cg.geometry(Constraints(keep_out=KeepOut((0.2, 0.2, 0.2)), corridor=corridor))
    again = cg.geometry(Constraints(keep_out=KeepOut((0.2, 0.2, 0.2)), corridor=corridor))
    assert first is not again
    kept = cp._untightened_corridor(first)[1][0]
    assert cp._untightened_corridor(again)[1][0] is kept
    port = np.nextafter(first.port_km, 1.0)
    moved = cg.Geometry(first.semi_axes_km, port, first.axis, first.half_angle_rad)
    rows = cp._untightened_corridor(moved)[1]
    assert rows[0] is not kept
    fresh = cg.corridor_cone(moved, 0.0).rows()
    assert all(np.array_equal(g, w) for g, w in zip(rows, fresh, strict=True))


def test_the_kept_corridors_clearance_is_that_of_the_zone_asked() -> None:
    """The same corridor around another zone is another key: its clearance is the new
    zone's (a 200 m sphere: 50 m; a 100 m one: 150 m), never the one kept."""
    corridor = Corridor((0.0, 0.0, -0.25), (0.0, 0.0, -1.0), 30.0)
    for radius in (0.2, 0.1, 0.2):
        geo = cg.geometry(Constraints(keep_out=KeepOut((radius,) * 3), corridor=corridor))
        assert cp._untightened_corridor(geo)[2] == cg.corridor_clearance_km(geo)
        assert cp._untightened_corridor(geo)[2] == pytest.approx(0.25 - radius, abs=1e-15)


def test_the_cone_residuals_are_those_of_before() -> None:
    """``SecondOrderCone.residual_km``: ``r c + d − ‖r Aᵀ + b‖`` by numpy, bit for bit."""
    rng = np.random.default_rng(11)
    for rows in range(1, 400, 7):
        axis = rng.normal(size=3)
        cone = cg.SecondOrderCone(
            rng.normal(size=3), axis / np.linalg.norm(axis), rng.uniform(0.1, 2.0), 1e-4
        )
        a, b, c, d = cone.rows()
        r = _vectors(rng, rows)
        want = r @ c + d - np.linalg.norm(r @ a.T + b, axis=-1)
        assert np.array_equal(cone.residual_km(r), want)
    assert np.array_equal(cone.residual_km(r[0]), r[0] @ c + d - np.linalg.norm(r[0] @ a.T + b))


def _dual_rows_before(
    sub: cp._Subproblem,
    pairs: np.ndarray,
    row_scale: np.ndarray,
    box: tuple[np.ndarray, ...],
    ab: cp.ab.AbortRows,
) -> tuple[tuple[np.ndarray, ...], np.ndarray, np.ndarray]:
    """``constrained._dual_rows`` as it was (numpy, block by block, a stable argsort), with
    the abort rows ``ab`` (none: empty)."""
    steps, s_p = sub.modes.size - 1, float(row_scale[0])
    normals, offs = cp._planes(sub.half_spaces, pairs, sub.motion)
    sign = np.where(box[1] < 3, 1.0, -1.0)
    axis = box[1] % 3
    t_coeffs = np.zeros((box[0].size, 6))
    t_coeffs[np.arange(box[0].size), axis] = sign * s_p
    t_offsets = (sign * sub.r_bar[box[0], axis] - sub.trust_km[box[0]]) * s_p
    hs_coeffs = np.zeros((pairs.shape[0], 6))
    hs_coeffs[:, :3] = normals * s_p
    node = np.r_[np.full(6, steps), pairs[:, 0], box[0], ab.nodes]
    coeffs = np.vstack([np.diag(row_scale), hs_coeffs, t_coeffs, ab.coeffs * s_p])
    offsets = np.r_[row_scale * sub.xf, offs * s_p, t_offsets, ab.offsets_km * s_p]
    path_tol = np.full(pairs.shape[0] + box[0].size + ab.nodes.size, cp.DUAL_TOL_KM * s_p)
    tol = np.r_[row_scale * cp._TERMINAL_TOL, path_tol]
    kinds = np.r_[np.zeros(6), np.ones(pairs.shape[0]), np.full(box[0].size, 2)]
    kinds = np.r_[kinds, np.full(ab.nodes.size, 3)].astype(np.int64)
    keys = np.r_[np.arange(6), pairs[:, 0] - pairs[:, 1] + 2 * pairs[:, 2], box[1]]
    keys = np.r_[keys, np.full(ab.nodes.size, 999)].astype(np.int64)
    order = np.argsort(node, kind="stable")
    kind = kinds[order]
    code = node[order] * cp._CODE_NODE + kind * cp._CODE_KIND + keys[order]
    rows = (node[order], coeffs[order], offsets[order], kind == 0, tol[order])
    return rows, kind, code


def test_the_dual_rows_are_those_of_before() -> None:
    """``_dual_rows`` (its kernel ``_row_arrays``): terminal, half-space, trust and abort
    rows as numpy wrote and sorted them before, bit for bit; and the rows of a cut or trust
    round merged in (``_with_rows``) as numpy's concatenation and stable sort did."""
    rng = np.random.default_rng(12)
    geo = cg.geometry(Constraints(keep_out=KeepOut((0.2, 0.2, 0.2))))
    for trial in range(150):
        steps = int(rng.integers(3, 150))
        modes, half_spaces, r_bar, trust = _random_rows(rng, steps, 1 + trial % 2)
        pairs = cp._pairs(modes, r_bar, half_spaces, trust)[0]
        boxed = np.flatnonzero(modes > 0)
        count = int(rng.integers(0, 3 * boxed.size + 1))
        box = (np.sort(rng.choice(boxed, count)), rng.integers(0, 6, count)) if boxed.size else (
            np.zeros(0, np.int64), np.zeros(0, np.int64)
        )  # fmt: skip
        n_ab = int(rng.integers(0, 5))
        abort = cp.ab.AbortRows(
            rng.integers(1, steps + 1, n_ab), rng.normal(size=(n_ab, 6)), rng.normal(size=n_ab)
        )
        xf = rng.normal(size=6)
        states = np.hstack([r_bar, rng.normal(size=r_bar.shape)])  # r̄: a strided view
        sub = cp._Subproblem(
            N_MOTION, 1.0, U_MAX, np.zeros(6), xf, 0.5, geo, modes, states[:, :3],
            np.zeros((steps, 3)), np.zeros(steps + 1), half_spaces, trust,
            abort_rows=abort if n_ab else None,
        )  # fmt: skip
        row_scale = feasibility.row_scale(float(steps), U_MAX)
        rows, kind, code = cp._dual_rows(sub, pairs, row_scale, box)
        want_rows, want_kind, want_code = _dual_rows_before(sub, pairs, row_scale, box, abort)
        for g, w in zip(rows, want_rows, strict=True):
            assert g.dtype == w.dtype and np.array_equal(g, w)
        assert np.array_equal(kind, want_kind) and np.array_equal(code, want_code)
        # a round of cuts merged in: numpy's concatenation and stable sort of before
        m = int(rng.integers(1, 6))
        cuts = (
            rng.integers(1, steps + 1, m), rng.normal(size=(m, 6)), rng.normal(size=m),
            rng.integers(0, 1 << 30, m),
        )  # fmt: skip
        merged, merged_kind, merged_code = cp._with_rows(rows, kind, code, cuts, 1e-9, 4)
        nodes = np.r_[rows.nodes, cuts[0]]
        order = np.argsort(nodes, kind="stable")
        want = (
            nodes[order],
            np.vstack([rows.coeffs, cuts[1]])[order],
            np.r_[rows.offsets, cuts[2]][order],
            np.r_[rows.equality, np.zeros(m, dtype=bool)][order],
            np.r_[rows.tol, np.full(m, 1e-9)][order],
        )
        for g, w in zip(merged, want, strict=True):
            assert g.dtype == w.dtype and np.array_equal(g, w)
        assert np.array_equal(merged_kind, np.r_[kind, np.full(m, 4)][order])
        assert np.array_equal(merged_code, np.r_[code, cuts[3]][order])
        assert np.array_equal(cp._absent(cuts[3], merged_code), np.zeros(m, dtype=bool))
        probe = rng.integers(0, 1 << 30, 20)
        assert np.array_equal(cp._absent(probe, code), ~np.isin(probe, code))


def test_the_touched_half_spaces_are_those_of_before() -> None:
    """``_guess_active``: a speck on the half-space rows (kind 1) whose plane passes within
    ``GUESS_KM`` of r̄ at their node, ``(nᵀ r̄ − offset)/‖n‖ ≤ GUESS_KM``, numpy's of before."""
    rng = np.random.default_rng(13)
    for _ in range(200):
        count = int(rng.integers(1, 120))
        nodes = np.sort(rng.integers(1, 100, count))
        kind = rng.integers(0, 4, count)
        coeffs = rng.normal(size=(count, 6)) * 1e3
        r_bar = np.hstack([0.3 * rng.normal(size=(101, 3)), np.zeros((101, 3))])[:, :3]
        offsets = np.einsum("ij,ij->i", coeffs[:, :3], r_bar[nodes])
        offsets += rng.choice([-1.0, 1.0], count) * rng.uniform(0.0, 3.0, count)
        rows = path_dual.DualRows(nodes, coeffs, offsets, kind == 0, np.ones(count))
        hs = np.flatnonzero(kind == 1)
        residual = (
            np.einsum("ij,ij->i", coeffs[hs, :3], r_bar[nodes[hs]]) - offsets[hs]
        ) / np.linalg.norm(coeffs[hs, :3], axis=-1)
        want = np.zeros(count)
        want[hs[residual <= cp.GUESS_KM]] = 1e-300
        assert np.array_equal(cp._guess_active(rows, kind, r_bar), want)


def test_the_iterates_move_and_the_margins_check_are_those_of_before() -> None:
    """``_largest_move`` is ``max |r − r̄|`` and ``_within_margins`` ``all(s ≤ min(m_k,
    m_k+1))`` by numpy, NaN included (a NaN move, a check that fails)."""
    rng = np.random.default_rng(14)
    for trial in range(300):
        steps = int(rng.integers(1, 100))
        x = rng.normal(size=(steps + 1, 6))
        r_bar = x[:, :3] + 1e-3 * rng.normal(size=(steps + 1, 3)) * (rng.random() < 0.9)
        step, node = rng.uniform(0, 1, steps), rng.uniform(0, 1, steps + 1)
        if trial % 5 == 0:  # a NaN somewhere
            x[rng.integers(0, steps + 1), rng.integers(0, 3)] = np.nan
            node[rng.integers(0, steps + 1)] = np.nan
        if trial % 7 == 0:
            step[:] = 0.0
        moved = cp._largest_move(x, r_bar)
        want = float(np.max(np.abs(x[:, :3] - r_bar)))
        assert moved == want or (np.isnan(moved) and np.isnan(want))
        assert cp._within_margins(step, node) == bool(
            np.all(step <= np.minimum(node[:-1], node[1:]))
        )


def test_the_rows_vectors_and_the_cost_are_those_of_before() -> None:
    """``path_dual``: each row's ``h = (Φ^{k−N})ᵀ g`` from the kept table of backward
    transitions equal to that of its own ``stm(n, (k − N)Δt)`` (made before for every
    distinct node), however the table was made; the cost ``Σ c₁‖ũ‖ + c₂‖ũ‖²`` numpy's."""
    rng = np.random.default_rng(15)
    path_dual._BACKWARD.clear()
    for steps in (40, 300, 120, 301, 1):
        nodes = np.sort(rng.integers(1, steps + 1, 50))
        coeffs = rng.normal(size=(50, 6))
        got = np.empty_like(coeffs)
        table = path_dual.backward_transitions(N_MOTION, 1.0, steps)
        assert table.shape == (steps + 1, 6, 6) and not table.flags.writeable
        path_dual._row_vectors(table, steps, nodes, coeffs, got)
        want = np.empty_like(coeffs)
        for i, k in enumerate(nodes):
            back = dynamics.stm(N_MOTION, float(k - steps))
            for c in range(6):
                acc = 0.0
                for r in range(6):
                    acc += back[r, c] * coeffs[i, r]
                want[i, c] = acc
        assert np.array_equal(got, want)
    for size in (1, 7, 130, 800):
        u = rng.normal(size=(size, 3)) * (rng.random((size, 1)) < 0.5)
        norms = np.linalg.norm(u, axis=-1)
        want_cost = float(np.sum(0.7 * norms + 2e-3 * norms**2))
        assert float(np.sum(path_dual._step_costs(u, 0.7, 2e-3))) == want_cost


def test_the_half_spaces_need_no_detour_side_when_no_node_is_inside() -> None:
    """``_half_spaces`` works out the detour side only when a node lies inside the zone; its
    planes are then those with the side's shift (which moves only the nodes inside),
    bit for bit, and a node inside still gets the shifted point."""
    rng = np.random.default_rng(16)
    geo = cg.geometry(Constraints(keep_out=KeepOut((0.2, 0.15, 0.1))))
    axes = np.asarray(geo.semi_axes_km)
    for trial in range(60):
        steps = int(rng.integers(3, 120))
        directions = rng.normal(size=(steps + 1, 3))
        directions /= np.linalg.norm(directions, axis=1)[:, None]
        scale = (
            rng.uniform(1.01, 3.0, (steps + 1, 1))
            if trial % 2
            else rng.uniform(0.3, 3.0, (steps + 1, 1))
        )
        r_bar = directions * 0.2 * scale
        modes = np.full(steps + 1, 2, dtype=np.int8)
        modes[0] = modes[-1] = 0
        margins = rng.uniform(0.0, 1e-4, steps + 1)
        (got,) = cp._half_spaces(geo, modes, r_bar, margins, None, 0.0)
        level = cg.ellipsoid_level(r_bar, axes)
        shift = float(np.max(axes)) * cp._detour_side(axes, r_bar, level)
        want = cp._node_planes(axes, r_bar, level, got.nodes, shift, margins)
        assert np.array_equal(got.normals, want[0]) and np.array_equal(got.offsets, want[1])


def _approach_start_before(inside: np.ndarray, lowest: int) -> int:
    """``constraints.approach_start`` as it was (Python): back from the terminal node while
    the node before is inside, not below ``lowest``."""
    first = inside.size - 1
    while first - 1 >= lowest and inside[first - 1]:
        first -= 1
    return first


def test_the_approach_start_is_that_of_before() -> None:
    """``approach_start`` (now compiled): the first node of the last stretch inside, as the
    Python loop of before found it, from node 0 or 1 up."""
    rng = np.random.default_rng(17)
    for _ in range(300):
        inside = rng.random(int(rng.integers(1, 40))) < rng.uniform(0.3, 1.0)
        for lowest in (0, 1):
            assert cg.approach_start(inside, lowest) == _approach_start_before(inside, lowest)


def test_the_modes_of_the_final_approach_are_those_of_before() -> None:
    """``_modes`` with a corridor (its kernel ``_approach_modes``): numpy's residual of the
    untightened cone ≥ −1 mm, the approach from node 1 up, every other inner node keep-out,
    the first approach node both, as written before (positions strided, as ``x[:, :3]``)."""
    rng = np.random.default_rng(18)
    for trial in range(200):
        geo = cg.geometry(
            Constraints(
                keep_out=KeepOut((0.2, 0.2, 0.2)),
                corridor=Corridor(
                    (0.0, 0.0, -0.25), tuple(rng.normal(size=3)), float(rng.uniform(10, 60))
                ),
            )
        )
        steps = int(rng.integers(1, 120))
        tail = rng.uniform(0.0, 1.0, (steps + 1, 1)) ** 2  # nodes on and off the axis
        r = np.asarray(geo.port_km) + tail * 0.3 * np.asarray(geo.axis)
        r = r + rng.normal(size=(steps + 1, 3)) * 0.05 * tail * (trial % 3)
        r_bar = np.hstack([r, rng.normal(size=r.shape)])[:, :3]
        cone = cg.corridor_cone(geo, 0.0)
        inside = cone.residual_km(r_bar) >= -cp.SCP_TOL_KM
        first = _approach_start_before(inside, 1)
        want = np.zeros(steps + 1, dtype=np.int8)
        want[1:steps] = 2
        want[first:steps] = 1
        if first < steps:
            want[first] = 3
        got = cp._modes(geo, r_bar, None)
        assert got.dtype == want.dtype and np.array_equal(got, want)


def test_the_keep_out_planes_arrays_are_those_of_before() -> None:
    """``_outside_planes``: the half-space nodes, their index (``np.full(−1)``, then
    ``index[nodes] = arange``), ``ellipsoid_level`` and, no node inside, ``_node_planes``
    with no shift, bit for bit; a node inside: no planes (the caller shifts them)."""
    rng = np.random.default_rng(19)
    for trial in range(200):
        steps = int(rng.integers(2, 150))
        a = rng.uniform(0.05, 0.5, 3)
        directions = rng.normal(size=(steps + 1, 3))
        directions /= np.linalg.norm(directions, axis=1)[:, None]
        low = 1.01 if trial % 2 else 0.3
        r = directions * a * rng.uniform(low, 3.0, (steps + 1, 1))
        modes = rng.integers(0, 4, steps + 1).astype(np.int8)
        margins = rng.uniform(0.0, 1e-3, steps + 1)
        nodes = np.flatnonzero(np.r_[True, modes[1:] >= 2])
        index = np.full(steps + 1, -1, dtype=np.int64)
        index[nodes] = np.arange(nodes.size)
        level = cg.ellipsoid_level(r, a)
        got = cp._outside_planes(a, r, modes, margins)
        assert np.array_equal(got[0], nodes) and np.array_equal(got[1], index)
        assert np.array_equal(got[2], level)
        if np.any(level[nodes] < 1.0):
            assert got[3] is None and got[4] is None
        else:
            want = cp._node_planes(a, r, level, nodes, np.zeros(3), margins)
            assert np.array_equal(got[3], want[0]) and np.array_equal(got[4], want[1])


def test_the_half_spaces_index_is_that_of_before() -> None:
    """``HalfSpaces``' index (``_node_index``): −1, then each node's row, as numpy wrote it."""
    rng = np.random.default_rng(20)
    for _ in range(100):
        size = int(rng.integers(1, 200))
        nodes = np.flatnonzero(rng.random(size) < 0.6)
        want = np.full(size, -1, dtype=np.int64)
        want[nodes] = np.arange(nodes.size)
        assert np.array_equal(cp._node_index(nodes, size), want)


def test_the_node_margins_are_those_of_before() -> None:
    """``_node_margins``: the end steps' margins at the end nodes, ``np.maximum`` of the two
    steps' inside, NaN where either is."""
    rng = np.random.default_rng(21)
    for trial in range(200):
        step = rng.uniform(0.0, 1e-3, int(rng.integers(1, 100)))
        if trial % 4 == 0:
            step[rng.integers(0, step.size)] = np.nan
        want = np.empty(step.size + 1)
        want[0], want[-1] = step[0], step[-1]
        want[1:-1] = np.maximum(step[:-1], step[1:])
        assert np.array_equal(cp._node_margins(step), want, equal_nan=True)


def test_the_warm_plans_reach_is_that_of_before() -> None:
    """``out_of_reach`` (by ``_largest_move``): ``max |end − x_f| > T`` over the position axes,
    numpy's, a NaN never out of reach."""
    rng = np.random.default_rng(22)
    for trial in range(300):
        end, xf = rng.normal(size=6) * 0.1, rng.normal(size=6) * 0.1
        if trial % 5 == 0:
            end[rng.integers(0, 3)] = np.nan
        trust = float(rng.uniform(0.0, 0.3))
        want = bool(np.max(np.abs(end[:3] - xf[:3])) > trust)
        assert cp.out_of_reach(end, xf, trust) is want
        assert cp.out_of_reach(end[:3], xf, trust) is want


def test_the_multipliers_sum_of_kinds_is_numpys_sum_of_the_selection() -> None:
    """``_sum_of_kinds``: ``np.sum(values[(kind == a) | (kind == b)])``, bit for bit (the
    certificate's sums)."""
    rng = np.random.default_rng(23)
    for _ in range(200):
        count = int(rng.integers(0, 300))
        values, kind = rng.random(count) * 1e3, rng.integers(0, 5, count)
        for first, second in ((1, 4), (3, 3)):
            want = float(np.sum(values[(kind == first) | (kind == second)]))
            assert cp._sum_of_kinds(values, kind, first, second) == want


@pytest.mark.parametrize("size", [*range(0, 20), 127, 128, 129, 255, 256, 257, 1000, 1029, 8193])
def test_the_kernels_sum_is_numpys_pairwise_sum(size: int) -> None:
    """``path_dual.numpy_sum``: ``np.sum`` bit for bit (numpy's pairwise summation: blocks of
    up to 128 by eight accumulators, longer arrays by halves), on values of mixed sign
    spread over 20 decades, where any other order of the additions rounds differently."""
    rng = np.random.default_rng(size)
    for _ in range(20):
        values = rng.standard_normal(size) * 10.0 ** rng.integers(-10, 10, size)
        assert path_dual.numpy_sum(values) == float(np.sum(values))


def test_the_rows_vectors_and_drift_offsets_are_those_of_before() -> None:
    """``path_dual._row_inputs``: the rows' vectors ``_row_vectors`` writes and the offsets
    less the free drift, ``f − np.einsum("ij,ij->i", g, zoh_rollout(zero controls)[nodes])``,
    bit for bit (rows of mixed sign over 16 decades, zeros of either sign among them)."""
    rng = np.random.default_rng(24)
    phi, gam = dynamics.discretize(N_MOTION, 1.0)
    for steps in (1, 40, 300):
        back = path_dual.backward_transitions(N_MOTION, 1.0, steps)
        nodes = np.sort(rng.integers(1, steps + 1, 60))
        coeffs = rng.normal(size=(60, 6)) * 10.0 ** rng.integers(-8, 8, (60, 6))
        coeffs[rng.random((60, 6)) < 0.3] = 0.0
        coeffs[rng.random((60, 6)) < 0.1] = -0.0
        offsets, x0 = rng.normal(size=60), rng.normal(size=6)
        want_h = np.empty_like(coeffs)
        path_dual._row_vectors(back, steps, nodes, coeffs, want_h)
        free = dynamics.zoh_rollout(phi, gam, x0, np.zeros((steps, 3)))
        want_f = offsets - np.einsum("ij,ij->i", coeffs, free[nodes])
        h, f = path_dual._row_inputs(phi, gam, x0, back, nodes, coeffs, offsets)
        assert np.array_equal(h, want_h) and np.array_equal(f, want_f)


def test_a_rows_dot_is_numpys_einsum_of_the_row() -> None:
    """``path_dual._einsum_row_dot``: ``np.einsum("ij,ij->i", g, x)`` row by row, bit for bit,
    products over 20 decades of either sign, and the sign of a zero sum."""
    rng = np.random.default_rng(26)
    g = rng.normal(size=(5000, 6)) * 10.0 ** rng.integers(-10, 10, (5000, 6))
    x = rng.normal(size=(5000, 6)) * 10.0 ** rng.integers(-10, 10, (5000, 6))
    g[:50] = -0.0
    want = np.einsum("ij,ij->i", g, x)
    got = np.array([path_dual._einsum_row_dot(g[i], x[i]) for i in range(g.shape[0])])
    assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))


def test_the_answers_costs_controls_and_states_are_those_of_before() -> None:
    """``path_dual._answer_arrays``: numpy's sum of ``_step_costs``, ``u × u_max`` and
    ``zoh_rollout`` of those controls, bit for bit."""
    rng = np.random.default_rng(25)
    phi, gam = dynamics.discretize(N_MOTION, 1.0)
    for steps in (1, 7, 130, 800):
        u = rng.normal(size=(steps, 3)) * (rng.random((steps, 1)) < 0.5)
        x0 = rng.normal(size=6)
        cost, controls, states = path_dual._answer_arrays(phi, gam, x0, u, U_MAX, 0.7, 2e-3)
        assert cost == float(np.sum(path_dual._step_costs(u, 0.7, 2e-3)))
        assert np.array_equal(controls, u * U_MAX)
        assert np.array_equal(states, dynamics.zoh_rollout(phi, gam, x0, u * U_MAX))


@pytest.mark.parametrize("bodies", [1, 3])
def test_a_fixed_targets_trust_radii_are_those_of_the_gathered_planes(bodies: int) -> None:
    """``trust_radii`` (its kernel ``_fixed_radii``, the planes read where they are kept):
    written here in numpy from the rows of ``_pair_rows`` and the planes ``_planes`` gathers
    for them (each row's ``(nᵀ r̄_k − offset)/‖n‖₁`` in the kernel's order, the smallest a
    node, half of it where larger than the base radius), bit for bit."""
    rng = np.random.default_rng(26 + bodies)
    for _ in range(150):
        steps = int(rng.integers(3, 150))
        modes, half_spaces, r_bar, trust = _random_rows(rng, steps, bodies)
        r_bar = 10.0 * r_bar  # nodes near and far from the planes
        pairs = cp._pair_rows(half_spaces[0].index >= 0, modes, bodies)
        n, offsets = cp._planes(half_spaces, pairs)
        r = r_bar[pairs[:, 0]]
        dots = (n[:, 0] * r[:, 0] + n[:, 1] * r[:, 1]) + n[:, 2] * r[:, 2]
        sizes = (np.abs(n[:, 0]) + np.abs(n[:, 1])) + np.abs(n[:, 2])
        held = np.full(modes.size, np.inf)
        np.minimum.at(held, pairs[:, 0], (dots - offsets) / sizes)
        far = cp.TRUST_FAR_FRACTION * held
        want = np.where(np.isfinite(held) & (far > trust), far, trust)
        assert np.array_equal(cp.trust_radii(modes, r_bar, half_spaces, trust), want)


def test_the_radii_given_one_a_node_are_taken_as_they_are() -> None:
    """``_radii``: an array of one radius a node is the array itself (no copy); one radius,
    or a strided array, every node's as ``broadcast_to`` made it."""
    radii = np.linspace(0.1, 0.2, 7)
    assert cp._radii(radii, 7) is radii
    assert np.array_equal(cp._radii(0.3, 7), np.full(7, 0.3))
    strided = np.linspace(0.1, 0.2, 14)[::2]
    got = cp._radii(strided, 7)
    assert got.flags.c_contiguous and np.array_equal(got, strided)


def test_the_largest_margin_is_numpys_max() -> None:
    """``_largest`` (the corridor's clearance test): ``np.max``, NaN when one value is."""
    rng = np.random.default_rng(29)
    for trial in range(200):
        values = rng.uniform(0.0, 1e-3, int(rng.integers(1, 100)))
        if trial % 4 == 0:
            values[rng.integers(0, values.size)] = np.nan
        want = float(np.max(values))
        got = cp._largest(values)
        assert got == want or (np.isnan(got) and np.isnan(want))


def test_the_rows_with_a_multiplier_are_numpys_selection() -> None:
    """``_nonzero_rows`` (the duals a plan carries): ``code[y != 0]``, ``y[y != 0]``."""
    rng = np.random.default_rng(30)
    for _ in range(200):
        count = int(rng.integers(0, 200))
        code = rng.integers(0, 1 << 40, count)
        values = rng.random(count) * (rng.random(count) < 0.3)
        got = cp._nonzero_rows(code, values)
        keep = values != 0.0
        assert np.array_equal(got[0], code[keep]) and np.array_equal(got[1], values[keep])
        assert got[0].dtype == np.int64


def test_the_rows_orders_are_numpys_stable_sorts() -> None:
    """``_node_order`` (counting) and ``_sorted_order`` (the identity when in order):
    ``np.argsort(kind="stable")``, ties in their order, sorted or not."""
    rng = np.random.default_rng(31)
    for trial in range(300):
        count = int(rng.integers(0, 200))
        nodes = rng.integers(0, int(rng.integers(1, 900)), count)
        if trial % 3 == 0:
            nodes = np.sort(nodes)
        want = np.argsort(nodes, kind="stable")
        assert np.array_equal(cp._node_order(nodes), want)
        codes = rng.integers(0, 1 << 40, count) if trial % 2 else nodes * cp._CODE_NODE
        codes = np.sort(codes) if trial % 3 == 0 else codes
        assert np.array_equal(cp._sorted_order(codes), np.argsort(codes, kind="stable"))


def test_the_kept_transitions_are_discretizes() -> None:
    """``path_dual.transitions``: ``discretize``'s (Φ, Γ) bit for bit, the same arrays for the
    same (n, Δt) and others for another step."""
    for n, dt in ((N_MOTION, 1.0), (N_MOTION, 0.5), (2e-3, 1.0)):
        phi, gam = path_dual.transitions(n, dt)
        want_phi, want_gam = dynamics.discretize(n, dt)
        assert np.array_equal(phi, want_phi) and np.array_equal(gam, want_gam)
        assert path_dual.transitions(n, dt)[0] is phi
    assert path_dual.transitions(N_MOTION, 0.5)[0] is not path_dual.transitions(N_MOTION, 1.0)[0]


def test_the_modes_comparison_is_numpys_array_equal() -> None:
    """``_same_modes``: ``np.array_equal`` of two mode arrays (lengths, then every node)."""
    rng = np.random.default_rng(27)
    for _ in range(300):
        first = rng.integers(0, 4, int(rng.integers(1, 30))).astype(np.int8)
        second = first.copy()
        if rng.random() < 0.5:
            second[rng.integers(0, second.size)] = rng.integers(0, 4)
        if rng.random() < 0.2:
            second = second[:-1]
        assert cp._same_modes(first, second) is np.array_equal(first, second)


def test_the_guess_marks_the_half_space_rows_within_a_metre_as_before() -> None:
    """``_guess_active``: the speck 1e-300 on exactly the half-space rows (kind 1) whose
    ``(nᵀ r̄_k − offset)/‖n‖`` ≤ ``GUESS_KM``, the distance as numpy's einsum and norm wrote
    it before, zero on every other row (rows scaled as the program's, ±3 m about the
    threshold so that both sides are met)."""
    rng = np.random.default_rng(28)
    for _ in range(200):
        count, steps = int(rng.integers(1, 80)), 60
        nodes = np.sort(rng.integers(1, steps + 1, count))
        kind = rng.integers(0, 4, count)
        normals = rng.normal(size=(count, 3))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        scale = float(10.0 ** rng.uniform(-2, 4))
        coeffs = np.zeros((count, 6))
        coeffs[:, :3] = normals * scale
        r_bar = rng.normal(size=(steps + 1, 6))[:, :3]
        distance = rng.uniform(-3e-3, 3e-3, count)
        offsets = (np.einsum("ij,ij->i", normals, r_bar[nodes]) - distance) * scale
        rows = path_dual.DualRows(nodes, coeffs, offsets, kind == 0, np.ones(count))
        hs = np.flatnonzero(kind == 1)
        near = (
            np.einsum("ij,ij->i", coeffs[hs, :3], r_bar[nodes[hs]]) - offsets[hs]
        ) / np.linalg.norm(coeffs[hs, :3], axis=1) <= cp.GUESS_KM
        want = np.zeros(count)
        want[hs[near]] = 1e-300
        assert np.array_equal(cp._guess_active(rows, kind, r_bar), want)
