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


def _two_seeds(monkeypatch: pytest.MonkeyPatch, toml: str) -> tuple[int, int]:
    """Seeds 0 and 1 of ``mtf_fixed_socp`` on the config ``toml``, each run alone and with
    one memo shared by the two (a worker's): asserts that each pair is the same run, bit for
    bit; returns (cold initial plans made with the memo, plans in the memo)."""
    from cwrend_cli.campaign import worker

    cfg = config_from_dict(tomllib.loads(toml))
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
        draws = worker.attitude_draws(problem, cfg.noise.seed, seed)
        alone = simulation.simulate(problem, arch, noise, refs, seed=seed, attitude_draws=draws)
        monkeypatch.setattr(simulation, "_constrained_plan", counted)
        shared = simulation.simulate(
            problem, arch, noise, refs, seed=seed, attitude_draws=draws, initial_plans=memo
        )
        monkeypatch.setattr(simulation, "_constrained_plan", plan)
        assert _same(alone, shared)
    return len(cold), len(memo)


def test_the_second_run_of_a_point_takes_the_initial_plan_and_is_the_same_run(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Seeds 0 and 1 of a constrained fixed-ε case (a 200 s horizon 1 km above a 200 m
    sphere): with the memo, the initial plan is made once (one cold plan for two runs);
    each run is the run without the memo, bit for bit."""
    assert _two_seeds(monkeypatch, SHORT) == (1, 1)


#: A 200 s tumbling case (2 °/s, a bus and a panel, a port with a corridor; issue 34), as
#: test_tumbling_guidance's closed loops.
TUMBLING = SHORT.replace(
    "[constraints.keep_out]\nsemi_axes_km = [0.2, 0.2, 0.2]",
    "[target]\n"
    'attitude = "tumbling"\n'
    "body_rates_deg_s = [0.3, 0.4, 2.0]\n"
    "inertia = [1.0, 1.4, 1.9]\n"
    "[constraints.keep_out]\n"
    "semi_axes_km = [0.08, 0.06, 0.06]\n"
    "[[constraints.keep_out.bodies]]\n"
    "centre_km = [0.0, 0.16, 0.0]\n"
    "semi_axes_km = [0.01, 0.1, 0.05]",
).replace("port_km = [0.0, 0.0, -0.25]\naxis = [0.0, 0.0, -1.0]",
          "port_km = [-0.1, 0.0, 0.0]\naxis = [-1.0, 0.0, 0.0]")  # fmt: skip


@pytest.mark.parametrize(
    ("knowledge", "cold_plans"),
    [("", 1), ("knowledge_sigma_deg = 2.0\nknowledge_sigma_deg_s = 0.2\n", 2)],
    ids=["known exactly", "knowledge error"],
)
def test_a_tumbling_point_takes_the_initial_plan_when_the_attitude_is_known_exactly(
    monkeypatch: pytest.MonkeyPatch, knowledge: str, cold_plans: int
) -> None:
    """Seeds 0 and 1 of a tumbling case: known exactly, the guidance predicts from the
    truth's attitude, the same for every seed, so the initial plan is made once (issue 34's
    study); with an attitude-knowledge error (drawn per seed) it is made for each. Each run
    is the run without the memo, bit for bit."""
    toml = TUMBLING.replace("[target]\n", "[target]\n" + knowledge)
    assert config_from_dict(tomllib.loads(toml)).target.attitude == "tumbling"
    assert _two_seeds(monkeypatch, toml) == (cold_plans, 2 - cold_plans)
