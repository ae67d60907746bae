"""Keep-out bodies and constraints on a tumbling target (issue 34 items 1b and 2): config.

``[[constraints.keep_out.bodies]]`` adds ellipsoids to the keep-out zone; without it the
section resolves and hashes as before. With ``target.attitude = "tumbling"`` the
constraints are accepted (they are given in the body frame). Every bad field exits 2
naming it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.config.io import config_from_dict, config_hash, resolved_dict
from cwrend_cli.physics import params

runner = CliRunner()

PANEL = {"centre_km": [0.0, 0.2, 0.0], "semi_axes_km": [0.01, 0.1, 0.05]}
ZONE: dict[str, Any] = {"keep_out": {"semi_axes_km": [0.1, 0.1, 0.1]}}


def test_a_keep_out_without_bodies_resolves_and_hashes_as_before() -> None:
    """No ``bodies`` key in the resolved tree; an explicit empty list is the same config."""
    plain = config_from_dict({"constraints": ZONE})
    empty = config_from_dict({"constraints": {"keep_out": {**ZONE["keep_out"], "bodies": []}}})
    assert "bodies" not in resolved_dict(plain)["constraints"]["keep_out"]
    assert config_hash(empty) == config_hash(plain)
    assert problem_of(plain).constraints == params.Constraints(
        keep_out=params.KeepOut((0.1, 0.1, 0.1))
    )


def test_the_bodies_reach_the_typed_problem_in_order() -> None:
    second = {"centre_km": [0.0, -0.2, 0.0], "semi_axes_km": [0.01, 0.1, 0.06]}
    keep_out = {**ZONE["keep_out"], "bodies": [PANEL, second]}
    cfg = config_from_dict({"constraints": {"keep_out": keep_out}})
    assert problem_of(cfg).constraints == params.Constraints(
        keep_out=params.KeepOut(
            (0.1, 0.1, 0.1),
            (
                params.KeepOutBody((0.0, 0.2, 0.0), (0.01, 0.1, 0.05)),
                params.KeepOutBody((0.0, -0.2, 0.0), (0.01, 0.1, 0.06)),
            ),
        )
    )
    # the resolved tree validates back to the same config
    assert config_from_dict(resolved_dict(cfg)) == cfg


def test_a_tumbling_target_with_constraints_is_accepted(tmp_path: Path) -> None:
    result = runner.invoke(app, ["config", "validate", str(_write(tmp_path))])
    assert result.exit_code == 0, result.output


def test_the_shipped_tumbling_campaign_validates() -> None:
    path = Path(__file__).parents[1] / "campaigns" / "tumbling_target.toml"
    result = runner.invoke(app, ["config", "validate", str(path)])
    assert result.exit_code == 0, result.output


def _write(tmp_path: Path) -> Path:
    path = tmp_path / "t.toml"
    path.write_text(
        '[target]\nattitude = "tumbling"\nbody_rates_deg_s = [0.0, 1.0, 2.0]\n'
        "inertia = [1.0, 1.5, 2.0]\n"
        "[constraints.keep_out]\nsemi_axes_km = [0.1, 0.1, 0.1]\n"
        "[[constraints.keep_out.bodies]]\ncentre_km = [0.0, 0.2, 0.0]\n"
        "semi_axes_km = [0.01, 0.1, 0.05]\n"
        "[constraints.corridor]\nport_km = [-0.12, 0.0, 0.0]\naxis = [-1.0, 0.0, 0.0]\n"
        "half_angle_deg = 30.0\n",
        encoding="utf-8",
    )
    return path


REFUSED = {
    "a port inside a panel": (
        ["constraints.corridor.port_km=[0, 0.2, 0]", "scenario.xf=[0, 0.2, 0, 0, 0, 0]"],
        "constraints.corridor.port_km = [0.0, 0.2, 0.0]: must lie on or outside the keep-out "
        "zone: it is inside keep_out.bodies.0",
    ),
    "a zero semi-axis of a body": (
        ["constraints.keep_out.bodies.0.semi_axes_km=[0.01, 0, 0.05]"],
        "constraints.keep_out.bodies.0.semi_axes_km.1 = 0",
    ),
    "two centre entries": (
        ["constraints.keep_out.bodies.0.centre_km=[0, 0.2]"],
        "constraints.keep_out.bodies.0.centre_km",
    ),
    "a centre out of bounds": (
        ["constraints.keep_out.bodies.0.centre_km=[0, 2e4, 0]"],
        "constraints.keep_out.bodies.0.centre_km.1",
    ),
    "an unknown body key": (
        ["constraints.keep_out.bodies.0.radius_km=0.1"],
        "constraints.keep_out.bodies.0.radius_km",
    ),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_bad_body_exits_2_naming_the_field(case: str, tmp_path: Path) -> None:
    sets, message = REFUSED[case]
    args = ["config", "validate", str(_write(tmp_path))]
    result = runner.invoke(app, args + [a for s in sets for a in ("--set", s)])
    assert result.exit_code == 2, result.output
    assert message in result.output
    assert "Traceback" not in result.output


def test_more_than_sixteen_bodies_exit_2(tmp_path: Path) -> None:
    path = tmp_path / "many.toml"
    body = (
        "[[constraints.keep_out.bodies]]\ncentre_km = [1.0, 0.0, 0.0]\n"
        "semi_axes_km = [0.1, 0.1, 0.1]\n"
    )
    path.write_text("[constraints.keep_out]\nsemi_axes_km = [0.1, 0.1, 0.1]\n" + body * 17)
    result = runner.invoke(app, ["config", "validate", str(path)])
    assert result.exit_code == 2, result.output
    assert "constraints.keep_out.bodies" in result.output
    assert "Traceback" not in result.output


def test_a_tumbling_corridor_without_a_keep_out_zone_exits_2(tmp_path: Path) -> None:
    """The moving port is flown to by the constrained program, which needs a zone."""
    path = tmp_path / "t.toml"
    path.write_text(
        '[target]\nattitude = "tumbling"\nbody_rates_deg_s = [0.0, 1.0, 2.0]\n'
        "[constraints.corridor]\nport_km = [-0.12, 0.0, 0.0]\naxis = [-1.0, 0.0, 0.0]\n"
        "half_angle_deg = 30.0\n",
        encoding="utf-8",
    )
    result = runner.invoke(app, ["config", "validate", str(path)])
    assert result.exit_code == 2, result.output
    assert "constraints.corridor" in result.output
    assert "needs a keep-out zone" in result.output


def test_perfect_attitude_knowledge_is_left_out_of_the_tree(tmp_path: Path) -> None:
    """σ = 0 (the default) is written as before the fields existed; σ > 0 reaches the
    typed problem."""
    tumbling = {"attitude": "tumbling", "body_rates_deg_s": [0.0, 1.0, 2.0]}
    plain = config_from_dict({"target": tumbling, "constraints": ZONE})
    zero = config_from_dict(
        {"target": {**tumbling, "knowledge_sigma_deg": 0.0}, "constraints": ZONE}
    )
    assert "knowledge_sigma_deg" not in resolved_dict(plain)["target"]
    assert config_hash(zero) == config_hash(plain)
    known = {**tumbling, "knowledge_sigma_deg": 2.0, "knowledge_sigma_deg_s": 0.2}
    target = problem_of(config_from_dict({"target": known, "constraints": ZONE})).target
    assert (target.knowledge_sigma_deg, target.knowledge_sigma_deg_s) == (2.0, 0.2)
    assert target.knowledge_error


@pytest.mark.parametrize(
    ("setting", "message"),
    [
        ("target.knowledge_sigma_deg=-1", "target.knowledge_sigma_deg = -1"),
        ("target.knowledge_sigma_deg=31", "target.knowledge_sigma_deg = 31: must be <= 30"),
        ("target.knowledge_sigma_deg_s=61", "target.knowledge_sigma_deg_s = 61: must be <= 60"),
    ],
)
def test_a_bad_knowledge_error_exits_2(setting: str, message: str, tmp_path: Path) -> None:
    result = runner.invoke(app, ["config", "validate", str(_write(tmp_path)), "--set", setting])
    assert result.exit_code == 2, result.output
    assert message in result.output


def test_a_knowledge_error_without_a_keep_out_zone_exits_2(tmp_path: Path) -> None:
    """Only the constrained guidance uses the attitude knowledge: without a zone it would do
    nothing."""
    path = tmp_path / "k.toml"
    path.write_text(
        '[target]\nattitude = "tumbling"\nknowledge_sigma_deg_s = 0.2\n', encoding="utf-8"
    )
    result = runner.invoke(app, ["config", "validate", str(path)])
    assert result.exit_code == 2, result.output
    assert "target.knowledge_sigma_deg_s = 0.2: the attitude knowledge is used by" in result.output


def test_a_knowledge_error_on_a_fixed_target_exits_2(tmp_path: Path) -> None:
    path = tmp_path / "f.toml"
    path.write_text("[target]\nknowledge_sigma_deg = 2.0\n", encoding="utf-8")
    result = runner.invoke(app, ["config", "validate", str(path)])
    assert result.exit_code == 2, result.output
    assert "target.knowledge_sigma_deg = 2: applies to a tumbling target only" in result.output


def test_the_knowledge_draws_are_the_runs_own_stream() -> None:
    """Off: none. On: 6 standard normals, the same for the same (root seed, seed), another
    for another seed, and not the noise stream's first values."""
    from cwrend_cli.campaign import worker

    tumbling = {"attitude": "tumbling", "body_rates_deg_s": [0.0, 1.0, 2.0]}
    off = problem_of(config_from_dict({"target": tumbling}))
    assert worker.attitude_draws(off, 42, 0) is None
    on = problem_of(
        config_from_dict({"target": {**tumbling, "knowledge_sigma_deg": 2.0}, "constraints": ZONE})
    )
    a, b, c = (worker.attitude_draws(on, 42, s) for s in (0, 0, 1))
    assert a is not None and b is not None and c is not None
    assert a.shape == (6,) and np.array_equal(a, b) and not np.array_equal(a, c)
    noise = np.random.default_rng(worker.noise_seed_sequence(42, 0)).standard_normal(6)
    assert not np.array_equal(a, noise)


def test_a_knowledge_error_drawn_once_a_run_is_left_out_of_the_tree() -> None:
    """``knowledge_draw = "run"`` (the default) resolves and hashes as before the field
    existed; ``"resolve"`` is written and reaches the typed problem."""
    known = {
        "attitude": "tumbling",
        "body_rates_deg_s": [0.0, 1.0, 2.0],
        "knowledge_sigma_deg": 2.0,
    }
    plain = config_from_dict({"target": known, "constraints": ZONE})
    once = config_from_dict({"target": {**known, "knowledge_draw": "run"}, "constraints": ZONE})
    assert "knowledge_draw" not in resolved_dict(once)["target"]
    assert config_hash(once) == config_hash(plain)
    each = config_from_dict({"target": {**known, "knowledge_draw": "resolve"}, "constraints": ZONE})
    assert resolved_dict(each)["target"]["knowledge_draw"] == "resolve"
    assert problem_of(each).target.knowledge_draw == "resolve"


def test_a_knowledge_draw_without_a_knowledge_error_exits_2(tmp_path: Path) -> None:
    """With σ = 0 there is nothing to draw: the setting would do nothing."""
    result = runner.invoke(
        app,
        ["config", "validate", str(_write(tmp_path)), "--set", 'target.knowledge_draw="resolve"'],
    )
    assert result.exit_code == 2, result.output
    assert 'target.knowledge_draw = "resolve": there is no knowledge error to draw' in result.output


def test_the_knowledge_draws_of_every_re_solve_are_the_runs_own_stream() -> None:
    """``"resolve"``: one row of 6 standard normals a step from the run's own stream (the
    same for the same seed, another for another), whose first row is the draw of
    ``"run"`` (the same stream, read further)."""
    from cwrend_cli.campaign import worker

    target = {
        "attitude": "tumbling",
        "body_rates_deg_s": [0.0, 1.0, 2.0],
        "knowledge_sigma_deg": 2.0,
    }
    once = problem_of(config_from_dict({"target": target, "constraints": ZONE}))
    each = problem_of(
        config_from_dict({"target": {**target, "knowledge_draw": "resolve"}, "constraints": ZONE})
    )
    a, b, c = (worker.attitude_draws(each, 42, s) for s in (0, 0, 1))
    first = worker.attitude_draws(once, 42, 0)
    assert a is not None and b is not None and c is not None and first is not None
    assert a.shape == (each.scenario.n_steps, 6)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert np.array_equal(a[0], first)
    assert not np.array_equal(a[1], a[0])
