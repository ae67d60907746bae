"""A fixed target's constrained plans are those of the code before issue 34, bit for bit.

Issue 34 turned the constrained cone program's geometry into per-node, per-body rows in
the target's body frame. For a fixed target (no ``motion``) and one keep-out ellipsoid,
every plan must be what it was: the fixture ``data/fixed_constrained_plans.json`` holds
the controls (as ``float.hex``), statuses, slacks and iteration counts of 12 random
constrained plans (with and without a corridor, with and without a covariance margin),
made by running this module as a script on the code before issue 34 (``main`` at
eba92ce, ``PYTHONPATH=/work/main python tests/test_fixed_target_numbers.py`` run outside the
worktree).

Bits can only be compared on the platform the fixture was made on
(``test_same_numbers.platform_signature``: OpenBLAS, numpy and Clarabel's roundings
differ by CPU) and on those its ``also_on`` lists, where the same code gave the same
plans bit for bit (``python tests/test_fixed_target_numbers.py --also-here``; an Intel
``rocketlake`` was added so, 2026-12-03); elsewhere the test is skipped
(``test_same_numbers`` compares closed loops across platforms within its tolerance).
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

FIXTURE = Path(__file__).parent / "data" / "fixed_constrained_plans.json"
#: The fixture pins Clarabel, the solver its plans were made with: at ε > 0 the default
#: (``solver="auto"``) answers by the dual solver of ``path_dual`` where it certifies its
#: answer, the same plan to the solvers' tolerances, not to the bit (``test_path_dual``).
SOLVER = "clarabel"
N_MOTION = 0.00104218449  # rad/s, the paper's
U_MAX = 8e-4  # km/s²


def _plans() -> list[dict[str, Any]]:
    """12 random problems as in ``test_constrained_guidance`` (an ellipsoid of 100–300 m
    semi-axes, a start 400 m out, an 80 s horizon), every third without a corridor, every
    second with a covariance margin of 3 σ on a 10 m position σ."""
    rng = np.random.default_rng(3434)
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
        eps = float(rng.choice([0.0, 0.5, 1.0]))
        corridor = None if i % 3 == 0 else Corridor(tuple(port), tuple(axis), deg)
        xf = np.r_[port, 0, 0, 0] if corridor else np.r_[port * 1.5, 0, 0, 0]
        geo = cg.geometry(Constraints(keep_out=KeepOut(tuple(axes)), corridor=corridor))
        p_pos = np.eye(3) * 1e-4 if i % 2 else None
        res = cp.plan(
            N_MOTION, 1.0, U_MAX, x0, xf, 80.0, eps, geo, p_pos, 3.0 if i % 2 else 0.0,
            solver=SOLVER,
        )  # fmt: skip
        out.append(
            {
                "status": res.status.name,
                "controls": [float(v).hex() for v in res.controls.ravel()],
                "modes": res.modes.tolist(),
                "slack_km": float(res.slack_km).hex(),
                "scp_iterations": res.scp_iterations,
                "solver_iterations": res.solver_iterations,
            }
        )
    return out


def test_a_fixed_targets_constrained_plans_are_those_before_issue_34() -> None:
    assert_pinned_plans(FIXTURE, _plans)


if __name__ == "__main__":
    sys.exit(pinned_plans_main(FIXTURE, _plans))
