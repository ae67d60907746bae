"""A campaign worker plans a point's initial constrained plan once (issue 32's study).

Every seed of a campaign point starts from the same estimate, so the cold initial plan of
a constrained cone-program run is the same for all of them; ``simulate(initial_plans=…)``
(the worker's memo) makes it once and copies it after that. The runs must be the same,
bit for bit.
"""

from __future__ import annotations

import dataclasses
import tomllib
from typing import Any

import numpy as np
import pytest
from test_safety_measured import SHORT

from cwrend_cli import campaign
from cwrend_cli.config import ALL_ARCHITECTURES, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.physics import simulation


def _same(a: simulation.RunResult, b: simulation.RunResult) -> bool:
    """Every field of two runs equal to the bit (arrays by their bytes), wall times aside."""
    for field in dataclasses.fields(a):
        x, y = getattr(a, field.name), getattr(b, field.name)
        if field.name == "solves":
            x = [dataclasses.replace(s, wall_time_ms=0.0) for s in x]
            y = [dataclasses.replace(s, wall_time_ms=0.0) for s in y]
        if isinstance(x, np.ndarray):
            if x.tobytes() != y.tobytes():
                return False
        elif repr(x) != repr(y):
            return False
    return True


def test_the_second_run_of_a_point_takes_the_initial_plan_and_is_the_same_run(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Seeds 0 and 1 of a constrained fixed-ε case (a 200 s horizon 1 km above a 200 m
    sphere): with the memo, the initial plan is made once (one cold plan for two runs);
    each run is the run without the memo, bit for bit."""
    cfg = config_from_dict(tomllib.loads(SHORT))
    problem = problem_of(cfg)
    refs = simulation.open_loop_references(problem)
    arch = ALL_ARCHITECTURES["mtf_fixed_socp"]
    cold: list[int] = []
    plan = simulation._constrained_plan

    def counted(*args: Any, **kwargs: Any) -> Any:
        if args[6] == 0:  # k_from: the initial plan
            cold.append(1)
        return plan(*args, **kwargs)

    memo: simulation.InitialPlans = {}
    for seed in (0, 1):
        noise = campaign.standard_normal_for(cfg, seed)
        alone = simulation.simulate(problem, arch, noise, refs, seed=seed)
        monkeypatch.setattr(simulation, "_constrained_plan", counted)
        shared = simulation.simulate(problem, arch, noise, refs, seed=seed, initial_plans=memo)
        monkeypatch.setattr(simulation, "_constrained_plan", plan)
        assert _same(alone, shared)
    assert len(cold) == 1 and len(memo) == 1
