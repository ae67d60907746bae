"""Measure-only path constraints (issue 32 item 5): ``constraints.enforce = false``.

The cone-program guidance then plans exactly as without ``[constraints]`` (to the same
terminal state, the port at rest), while the run is measured on its true trajectory
against the keep-out zone and the corridor as an enforced run is: the unconstrained
baseline of the safe-approach study, with its violation rate. The twin compared with
here is ``campaigns/safe_approach.toml`` without ``[constraints]`` and with
``scenario.xf`` the port at rest (what ``campaigns/safe_approach_unconstrained.toml``
was).
"""

from __future__ import annotations

import copy
import dataclasses
import glob
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from test_safety_measured import SHORT
from typer.testing import CliRunner

from cwrend_cli import campaign
from cwrend_cli.campaign.plan import plan
from cwrend_cli.cli import app
from cwrend_cli.config import ALL_ARCHITECTURES, config_from_dict
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.config.io import config_hash, resolved_dict
from cwrend_cli.config.overrides import parse_param
from cwrend_cli.errors import ConfigError
from cwrend_cli.physics import constraints as cg
from cwrend_cli.physics import simulation

CAMPAIGNS = Path(__file__).resolve().parents[1] / "campaigns"
runner = CliRunner()


def _safe_approach() -> dict[str, Any]:
    with open(CAMPAIGNS / "safe_approach.toml", "rb") as f:
        return tomllib.load(f)


def _measure_only(tree: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(tree)
    out["constraints"]["enforce"] = False
    return out


def _twin(tree: dict[str, Any]) -> dict[str, Any]:
    """The same config without [constraints]: the terminal state given as the port at rest."""
    out = {k: v for k, v in copy.deepcopy(tree).items() if k != "constraints"}
    port = tree["constraints"]["corridor"]["port_km"]
    out.setdefault("scenario", {})["xf"] = [*port, 0.0, 0.0, 0.0]
    return out


def _fly(tree: dict[str, Any], arch: str, seed: int) -> simulation.RunResult:
    cfg = config_from_dict(tree)
    problem = problem_of(cfg)
    refs = simulation.open_loop_references(problem)
    noise = campaign.standard_normal_for(cfg, seed)
    return simulation.simulate(problem, ALL_ARCHITECTURES[arch], noise, refs, seed=seed)


@pytest.mark.parametrize(("arch", "seed"), [("mtf_fixed_socp", 0), ("mtf_adaptive_socp", 1)])
def test_a_measure_only_run_flies_the_unconstrained_twin_bit_for_bit(arch: str, seed: int) -> None:
    """The safe approach (paper scenario, 31 km out, the port behind a 200 m sphere): every
    guidance number of the measure-only run is the twin's to the bit (wall times aside), and
    its safety is the measurement of that trajectory against the enforced run's zone."""
    tree = _safe_approach()
    measured = _fly(_measure_only(tree), arch, seed)
    twin = _fly(_twin(tree), arch, seed)
    assert twin.safety is None  # without [constraints] nothing is measured
    for field in dataclasses.fields(twin):
        if field.name in ("safety", "abort"):
            continue
        x, y = getattr(measured, field.name), getattr(twin, field.name)
        if field.name == "solves":
            x = [dataclasses.replace(s, wall_time_ms=0.0) for s in x]
            y = [dataclasses.replace(s, wall_time_ms=0.0) for s in y]
        if isinstance(x, np.ndarray):
            assert x.tobytes() == y.tobytes(), field.name
        else:
            assert repr(x) == repr(y), field.name
    enforced = problem_of(config_from_dict(tree)).constraints
    assert enforced is not None and enforced.enforce
    expected = cg.measure_safety(twin.x_true, 1.0, cg.geometry(enforced))
    assert measured.safety is not None
    for field in dataclasses.fields(expected):
        x, y = getattr(measured.safety, field.name), getattr(expected, field.name)
        if isinstance(x, np.ndarray):
            assert x.tobytes() == y.tobytes(), field.name
        else:
            assert repr(x) == repr(y), field.name
    # the unconstrained plan goes through the zone to the far port
    assert measured.safety.violated


def test_enforce_true_keeps_the_hash_and_tree_of_the_config_without_it() -> None:
    tree = _safe_approach()
    given = copy.deepcopy(tree)
    given["constraints"]["enforce"] = True
    assert config_hash(config_from_dict(given)) == config_hash(config_from_dict(tree))
    assert "enforce" not in resolved_dict(config_from_dict(given))["constraints"]
    off = resolved_dict(config_from_dict(_measure_only(tree)))
    assert off["constraints"]["enforce"] is False


def _write_short(tmp_path: Path) -> Path:
    path = tmp_path / "short.toml"
    path.write_text(SHORT, encoding="utf-8")
    return path


def _refused(tmp_path: Path, *sets: str) -> str:
    """``cwrend config validate`` of the short safe approach with ``sets``: exit 2, its text."""
    args = ["config", "validate", str(_write_short(tmp_path))]
    result = runner.invoke(app, args + [a for s in sets for a in ("--set", s)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    return result.output


def test_a_margin_with_measure_only_exits_2_naming_the_field(tmp_path: Path) -> None:
    out = _refused(tmp_path, "constraints.enforce=false", "constraints.sigma_margin=3")
    assert "constraints.sigma_margin = 3: with constraints.enforce = false" in out


def test_measure_only_without_a_keep_out_zone_exits_2(tmp_path: Path) -> None:
    path = tmp_path / "corridor.toml"
    path.write_text(
        "[constraints.corridor]\nport_km = [0.0, 0.0, -0.25]\naxis = [0.0, 0.0, -1.0]\n"
        "half_angle_deg = 30.0\n[constraints]\nenforce = false\n",
        encoding="utf-8",
    )
    result = runner.invoke(app, ["config", "validate", str(path)])
    assert result.exit_code == 2, result.output
    assert "constraints.enforce = false: measure-only needs a keep-out zone" in result.output


def test_enforce_takes_a_boolean_only(tmp_path: Path) -> None:
    assert "constraints.enforce" in _refused(tmp_path, 'constraints.enforce="no"')


def test_attitude_knowledge_with_measure_only_exits_2(tmp_path: Path) -> None:
    out = _refused(
        tmp_path,
        "constraints.enforce=false",
        'target.attitude="tumbling"',
        "target.knowledge_sigma_deg=1",
    )
    assert "target.knowledge_sigma_deg = 1: the attitude knowledge" in out
    assert "constraints.enforce = false" in out


def test_config_show_prints_enforce_false(tmp_path: Path) -> None:
    args = ["config", "show", str(_write_short(tmp_path)), "--set", "constraints.enforce=false"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "enforce = false" in result.output


def test_enforce_is_swept_like_any_value() -> None:
    assert parse_param("constraints.enforce=true,false") == ("constraints.enforce", (True, False))
    cfg = config_from_dict(
        {**tomllib.loads(SHORT), "sweep": {"constraints.enforce": [True, False]}}
    )
    tasks = plan(cfg, ["mtf_fixed_socp"], [0]).tasks
    flags = sorted(t.problem.constraints.enforce for t in tasks if t.problem.constraints)
    assert flags == [False, True]


def test_measure_only_lets_the_cone_program_fly_another_design_model() -> None:
    """The constrained cone program plans with CW only; measure-only plans unconstrained."""
    tree = {**tomllib.loads(SHORT), "truth": {"model": "two_body"}, "model": {"guidance": "ss"}}
    with pytest.raises(ConfigError, match=r"model\.guidance = .ss. with \[constraints\]"):
        plan(config_from_dict(tree), ["mtf_fixed_socp"], [0])
    plan(config_from_dict(_measure_only(tree)), ["mtf_fixed_socp"], [0])


def test_a_measure_only_campaign_writes_safety_and_says_so_in_its_report(tmp_path: Path) -> None:
    args = ["ablate", str(_write_short(tmp_path)), "--seeds", "1", "--arch", "mtf_fixed_socp",
            "--workers", "1", "--no-rrd", "-q", "--set", f"output.dir={tmp_path / 'out'}",
            "--set", "constraints.enforce=false"]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    root = Path(glob.glob(str(tmp_path / "out" / "*"))[0])
    row = pq.read_table(root / "runs.parquet").to_pylist()[0]
    # 1 km above the sphere, the port below it: the unconstrained plan goes through
    assert row["safety_violated"] is True and row["safety_min_distance_km"] < 0
    result = runner.invoke(app, ["report", str(root)])
    assert result.exit_code == 0, result.output
    md = (root / "report" / "report.md").read_text(encoding="utf-8")
    assert "## Safety (path constraints)" in md
    assert "Measured only (constraints.enforce = false)" in md
