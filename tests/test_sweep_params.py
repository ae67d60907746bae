"""``--param`` and ``[sweep]`` form one grid, and nothing is swept silently.

A user walkthrough found a key given twice with ``--param`` sweeping only the
last one, ``--param`` replacing a ``[sweep]`` key without a word, a repeated
value or an ``output.*`` key giving identical points, and ``ablate --batch`` /
``--max-seeds`` without ``--until`` accepted and ignored (docs/guide/sweep.md).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.config.overrides import expand_grid, replaced_sweep_keys
from cwrend_cli.errors import ConfigError

runner = CliRunner()


def _config(tmp_path: Path, sweep: str = "") -> Path:
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[output]\ndir = "{tmp_path}"\n{sweep}')
    return cfg


def test_a_key_given_twice_with_param_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"--param schedule\.beta: given twice") as info:
        expand_grid({}, ["schedule.beta=0.1", "schedule.beta=0.2"])
    assert "--param schedule.beta=0.1,0.2" in str(info.value)  # the one option that does it


@pytest.mark.parametrize(
    ("sweep", "params"),
    [
        ({}, ["schedule.beta=0.1,0.1"]),
        ({}, ["schedule.beta=0.1,0.10"]),  # the same number as written twice
        ({}, ["schedule.beta=0.1:0.1:3"]),  # a range of one value, three times
        ({}, ["target.body_rates_deg_s=[[0, 0, 1], [0, 0, 1.0]]"]),
        ({"schedule.beta": (0.25, 0.5, 0.25)}, []),
    ],
)
def test_a_repeated_value_is_refused(
    sweep: dict[str, tuple[float, ...]], params: list[str]
) -> None:
    with pytest.raises(ConfigError, match="is listed twice"):
        expand_grid(sweep, params)


@pytest.mark.parametrize(
    ("sweep", "params"),
    [({}, ["output.name=a,b"]), ({"output.steps_seeds": (0, 1)}, []), ({}, ["output.dir=x"])],
)
def test_an_output_key_is_not_swept(sweep: dict[str, tuple[int, ...]], params: list[str]) -> None:
    with pytest.raises(ConfigError, match=r"changes no number of a run"):
        expand_grid(sweep, params)


def test_param_replaces_a_sweep_key_and_names_it() -> None:
    sweep = {"schedule.beta": (0.1, 0.25), "guidance.hold": ("sample", "mean")}
    params = ["schedule.beta=0.5", "schedule.kappa_mtf=6,12"]
    assert dict(expand_grid(sweep, params))["schedule.beta"] == (0.5,)
    assert replaced_sweep_keys(sweep, params) == ("schedule.beta",)
    assert replaced_sweep_keys(sweep, ["schedule.kappa_mtf=6"]) == ()


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--param", "schedule.beta=0.1", "--param", "schedule.beta=0.2"], "given twice"),
        (["--param", "schedule.beta=0.1,0.1"], "is listed twice"),
        (["--param", "output.name=a,b"], "changes no number of a run"),
    ],
)
def test_the_sweep_command_refuses_them_before_anything_runs(
    tmp_path: Path, args: list[str], said: str
) -> None:
    result = runner.invoke(app, ["sweep", str(_config(tmp_path)), "--seeds", "1", *args])
    assert result.exit_code == 2, result.output
    assert said in result.stderr
    assert "Traceback" not in result.output
    assert not (tmp_path / "c").exists()  # nothing written


WINDOW = "{ start_s = 250.0, end_s = 325.0, r_scale = 30.0 }"


@pytest.mark.parametrize(
    ("sweep", "args", "said"),
    [
        (f'"degradation.windows.0" = {WINDOW}', [], "[sweep] degradation.windows.0: "),
        (f'"degradation.windows.0" = [{WINDOW}, {WINDOW}]', [], "sweep.degradation.windows.0 = ["),
        ("", ["--param", f"degradation.windows.0={WINDOW}"], "--param degradation.windows.0: "),
        ("", ["--param", f"degradation.windows.0=[{WINDOW}]"], "--param degradation.windows.0: "),
    ],
)
def test_a_whole_table_as_a_grid_value_is_refused_saying_what_a_grid_takes(
    tmp_path: Path, sweep: str, args: list[str], said: str
) -> None:
    """A table is no grid value (sweep guide): ``[sweep]`` said "a range table is sampled by a
    design" of a window, or listed the refusals of every type of its value's union; a
    ``--param`` table ran every run, then failed with a traceback (unhashable dict)."""
    cfg = _config(tmp_path, f"[sweep]\n{sweep}\n" if sweep else "")
    argv = ["sweep", str(cfg), "--seeds", "1", "--arch", "mtf_adaptive", "-w", "1", "--no-rrd"]
    result = runner.invoke(app, [*argv, *args])
    assert result.exit_code == 2, result.output
    text = " ".join(result.stderr.split())
    assert said in text and "a table is not a grid value: a grid sweeps numbers, strings" in text
    assert "degradation.windows.0.start_s" in text  # the table's entries, by their own keys
    assert "must be a string" not in text and "range table" not in text
    assert "Traceback" not in result.output
    assert not (tmp_path / "c").exists()  # nothing written


def test_the_override_of_a_sweep_key_is_said(tmp_path: Path) -> None:
    cfg = _config(tmp_path, '[sweep]\n"schedule.beta" = [0.1, 0.25]\n')
    args = ["sweep", str(cfg), "--param", "schedule.beta=0.5", "--seeds", "1", "--arch",
            "mtf_adaptive", "-w", "1", "--no-rrd", "--format", "csv"]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert (
        "note: --param schedule.beta replaces the config's [sweep] values of schedule.beta "
        "([0.1, 0.25]); the grid sweeps schedule.beta = [0.5]"
    ) in result.stderr


@pytest.mark.parametrize(("option", "value"), [("--batch", "10"), ("--max-seeds", "5")])
def test_until_options_without_until_are_refused(tmp_path: Path, option: str, value: str) -> None:
    result = runner.invoke(app, ["ablate", str(_config(tmp_path)), "--seeds", "1", option, value])
    assert result.exit_code == 2, result.output
    assert f"{option}: applies to --until only; add --until TARGET or drop {option}" in (
        result.stderr
    )
    assert not (tmp_path / "c").exists()


SAFE_APPROACH = Path(__file__).resolve().parents[1] / "campaigns" / "safe_approach.toml"


def test_a_swept_corridor_port_moves_the_terminal_state_with_it() -> None:
    from cwrend_cli import campaign
    from cwrend_cli.config import load_config

    cfg = load_config(SAFE_APPROACH)
    param = "constraints.corridor.port_km=[[0, 0, -0.25], [0, 0, -0.3]]"
    plan = campaign.plan(cfg, ["plain_adaptive_socp"], [0], [param])
    ends = sorted(tuple(t.problem.scenario.xf) for t in plan.tasks)
    assert ends == [(0.0, 0.0, -0.3, 0.0, 0.0, 0.0), (0.0, 0.0, -0.25, 0.0, 0.0, 0.0)]


_CORRIDOR_PARAMS = [
    "constraints.corridor.port_km=[[0, 0, -0.25], [0, 0, -0.3]]",
    "constraints.corridor.axis=[[0, 0, -1]]",
    "constraints.corridor.half_angle_deg=30",
]


def test_a_corridor_swept_into_a_base_without_one_ends_at_its_port() -> None:
    """The resolved base holds the built-in scenario.xf, which the user did not set: each
    point was refused with "leave scenario.xf unset"."""
    from cwrend_cli import campaign
    from cwrend_cli.config import config_from_dict

    cfg = config_from_dict({"constraints": {"keep_out": {"semi_axes_km": [0.2, 0.2, 0.2]}}})
    plan = campaign.plan(cfg, ["plain_adaptive_socp"], [0], _CORRIDOR_PARAMS)
    ends = sorted(tuple(t.problem.scenario.xf) for t in plan.tasks)
    assert ends == [(0.0, 0.0, -0.3, 0.0, 0.0, 0.0), (0.0, 0.0, -0.25, 0.0, 0.0, 0.0)]


def test_a_corridor_swept_into_a_base_that_sets_scenario_xf_is_refused_naming_it() -> None:
    from cwrend_cli import campaign
    from cwrend_cli.config import config_from_dict

    cfg = config_from_dict({
        "constraints": {"keep_out": {"semi_axes_km": [0.2, 0.2, 0.2]}},
        "scenario": {"xf": [0.0, 0.0, -0.3, 0.0, 0.0, 0.0]},
    })  # fmt: skip
    with pytest.raises(ConfigError, match=r"scenario\.xf = ") as info:
        campaign.plan(cfg, ["plain_adaptive_socp"], [0], _CORRIDOR_PARAMS)
    assert "constraints.corridor.port_km = [0, 0, -0.25]" in str(info.value)


def test_vectors_listed_with_commas_are_swept_as_in_one_array() -> None:
    from cwrend_cli.config.overrides import parse_param

    listed = parse_param("constraints.corridor.port_km=[0,0,-0.25],[0,0,-0.3]")
    assert listed == parse_param("constraints.corridor.port_km=[[0,0,-0.25],[0,0,-0.3]]")
    assert listed[1] == ([0, 0, -0.25], [0, 0, -0.3])


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--range", "schedule.beta=0.1:1", "--range", "schedule.beta=0.2:0.5"],
         "--range schedule.beta: given twice (schedule.beta=0.1:1 and schedule.beta=0.2:0.5)"),
        (["--range", "truth.model=cw,cw"], "sweep truth.model: the value 'cw' is listed twice"),
        (["--range", "output.rrd_seeds=1:3:int"], "sweep output.rrd_seeds: an [output] setting"),
        (["--range", "output.dir=a,b"], "sweep output.dir: an [output] setting"),
    ],
)  # fmt: skip
def test_a_design_refuses_them_as_a_grid_does(tmp_path: Path, args: list[str], said: str) -> None:
    """``sweep --design`` took the last of two ranges of a key, sampled a repeated category
    twice over and swept ``output.*`` keys into identical points."""
    argv = ["sweep", str(_config(tmp_path)), "--design", "lhs", "--samples", "2", *args]
    result = runner.invoke(app, argv)
    assert result.exit_code == 2, result.output
    assert said in result.stderr
    assert "Traceback" not in result.output
    assert not (tmp_path / "c").exists()  # nothing written


def test_a_design_refuses_a_sweep_table_choice_listing_a_value_twice(tmp_path: Path) -> None:
    cfg = _config(tmp_path, '[sweep]\n"truth.model" = { values = ["cw", "j2", "cw"] }\n')
    result = runner.invoke(app, ["sweep", str(cfg), "--design", "lhs", "--samples", "2"])
    assert result.exit_code == 2, result.output
    assert "sweep truth.model: the value 'cw' is listed twice" in result.stderr


def test_the_report_reads_a_point_that_introduces_a_corridor_as_the_campaign_ran_it() -> None:
    import pandas as pd

    from cwrend_cli.config import config_from_dict
    from cwrend_cli.output.manifest import xf_given
    from cwrend_cli.report.load import with_swept_values

    cfg = config_from_dict({"constraints": {"keep_out": {"semi_axes_km": [0.2, 0.2, 0.2]}}})
    runs = pd.DataFrame({
        "param.constraints.corridor.port_km": ["[0.0, 0.0, -0.3]"],  # as runs.parquet holds it
        "param.constraints.corridor.axis": ["[0.0, 0.0, -1.0]"],
        "param.constraints.corridor.half_angle_deg": [30.0],
    })  # fmt: skip
    point = with_swept_values(cfg, runs, True, xf_given({"xf_given": False}))
    assert point is not None and tuple(point.scenario.xf) == (0.0, 0.0, -0.3, 0.0, 0.0, 0.0)


@pytest.mark.parametrize("key", ["constraints.corridor.port_km.2", "constraints.corridor.port_km"])
def test_a_dispersed_corridor_port_is_refused_naming_it_and_the_sweep_to_use(
    tmp_path: Path, key: str
) -> None:
    """It was refused as 'cannot be applied to the physics parameters', naming no reason."""
    config = tmp_path / "port.toml"
    base = SAFE_APPROACH.read_text(encoding="utf-8")
    config.write_text(
        f'{base}\n[dispersions]\n"{key}" = {{ dist = "uniform", low = -0.01, high = 0.01 }}\n',
        encoding="utf-8",
    )
    result = runner.invoke(app, ["config", "validate", str(config)])
    assert result.exit_code == 2, result.output
    assert f"dispersions.{key}: the corridor's port cannot be dispersed" in result.stderr
    assert "sweep the port instead" in result.stderr and "--param" in result.stderr
    assert "Traceback" not in result.output


def test_one_vector_typed_for_a_vector_key_is_refused_saying_how_vectors_are_swept(
    tmp_path: Path,
) -> None:
    """``port_km=[0,0,-0.25]`` lists three numbers, two of them equal: the refusal says how
    a vector is swept, not only that 0 is listed twice."""
    argv = ["sweep", str(SAFE_APPROACH), "--name", "v", "--set", f"output.dir='{tmp_path}'",
            "--param", "constraints.corridor.port_km=[0,0,-0.25]", "-n", "1"]  # fmt: skip
    result = runner.invoke(app, argv)
    assert result.exit_code == 2, result.output
    assert "the value 0 is listed twice" in result.stderr
    assert "constraints.corridor.port_km=[[x, y, z], [x, y, z]]" in result.stderr
    assert not (tmp_path / "v").exists()
