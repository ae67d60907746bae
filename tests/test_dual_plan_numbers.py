"""The dual solver's constrained plans are those of the code before issue 32's kernels, bit
for bit.

The constrained SCP's geometry and the dual solver's set-up were rewritten as numba
kernels with numpy's arithmetic in numpy's order (docs/solvers.md, *The constrained
program at adaptive ε*): the plans must not move by a bit. The fixture
``data/dual_constrained_plans.json`` holds the controls (as ``float.hex``), statuses,
iteration counts and fallbacks of 24 constrained plans by the default solver (the dual
solver first): 12 random cold problems at ε = 0, 0.3 and 0.8 (the fixed-ε homotopy and
the adaptive Newton method) and each one's warm re-solve 10 s later from its own plan's
state, warm controls and shifted row multipliers (what the closed loop does). Made by
running this module as a script on the code before the kernels (``main`` at 20532b2,
``PYTHONPATH=<that tree> python tests/test_dual_plan_numbers.py``).

Made again, on purpose, for issue 32's speed of the plain filter's re-solves (the dual
solver's line search backtracking by quadratic interpolation, ``path_dual._shrink``; its
passes rounding by products, ``step_law_by_products``, and summing the gradient from the
curvature, ``_forward``; the working set growing earlier at adaptive ε,
``SETTLED_DIRECT``; no plain projected Newton tries): 16 of the 24 plans moved, the
adaptive ones (ε = 0.3, 0.8) by at most 3.0e-11 u_max and the fixed-ε ones (ε = 0, a
near-linear program) by at most 1.7e-5 u_max; no status or fallback count changed. From
then on the plans must not move by a bit again unless an issue moves them.

Bits are compared on the fixture's platform (``test_same_numbers.platform_signature``) and
on those its ``also_on`` lists, where the same code gave the same plans bit for bit
(``python tests/test_dual_plan_numbers.py --also-here``), as in
``test_fixed_target_numbers``; elsewhere the test is skipped.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
from test_same_numbers import assert_pinned_plans, pinned_plans_main

from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics.guidance import constrained as cp
from cwrend_cli.physics.params import Constraints, Corridor, KeepOut

FIXTURE = Path(__file__).parent / "data" / "dual_constrained_plans.json"
N_MOTION = 0.00104218449  # rad/s, the paper's
U_MAX = 8e-4  # km/s²
#: The warm re-solve starts this many 1 s steps into the cold plan [-].
SHIFT = 10


def _record(res: cp.ConstrainedPlan) -> dict[str, Any]:
    return {
        "status": res.status.name,
        "controls": [float(v).hex() for v in res.controls.ravel()],
        "scp_iterations": res.scp_iterations,
        "solver_iterations": res.solver_iterations,
        "fallbacks": res.fallbacks,
    }


def _plans() -> list[dict[str, Any]]:
    """12 random problems (an ellipsoid of 100–300 m semi-axes, a start 400 m out, an 80 s
    horizon, a corridor in two of three, a covariance margin of 3 σ on a 10 m σ in every
    second), each planned cold and re-solved warm :data:`SHIFT` steps later."""
    rng = np.random.default_rng(3232)
    out = []
    for i in range(12):
        axes = rng.uniform(0.1, 0.3, 3)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        surface = axis / math.sqrt(float(np.sum((axis / axes) ** 2)))
        port = surface * rng.uniform(1.0, 1.2)
        deg = float(rng.uniform(10, 45))
        start = rng.normal(size=3)
        x0 = np.r_[0.4 * start / np.linalg.norm(start), rng.normal(size=3) * 1e-4]
        eps = (0.0, 0.3, 0.8)[i % 3]
        corridor = None if i % 3 == 1 else Corridor(tuple(port), tuple(axis), deg)
        xf = np.r_[port, 0, 0, 0] if corridor else np.r_[port * 1.5, 0, 0, 0]
        geo = cg.geometry(Constraints(keep_out=KeepOut(tuple(axes)), corridor=corridor))
        p_pos = np.eye(3) * 1e-4 if i % 2 else None
        margin = 3.0 if i % 2 else 0.0
        cold = cp.plan(N_MOTION, 1.0, U_MAX, x0, xf, 80.0, eps, geo, p_pos, margin)
        out.append(_record(cold))
        states, _ = cp.node_positions(N_MOTION, 1.0, x0, cold.controls)
        warm = cp.plan(
            N_MOTION, 1.0, U_MAX, states[SHIFT], xf, 80.0 - SHIFT, eps, geo, p_pos, margin,
            cold.controls[SHIFT:], warm_duals=cp.shift_duals(cold.duals, SHIFT),
        )  # fmt: skip
        out.append(_record(warm))
    return out


def test_the_dual_solvers_constrained_plans_are_those_before_the_kernels() -> None:
    assert_pinned_plans(FIXTURE, _plans)


if __name__ == "__main__":
    sys.exit(pinned_plans_main(FIXTURE, _plans))
