"""Tests of the configuration model, loading, overrides and hashing (cwrend_cli.config)."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from cwrend_cli.config import (
    ARCHITECTURES,
    Architecture,
    CwrendConfig,
    OutputConfig,
    config_from_dict,
    config_hash,
    format_validation_error,
    load_config,
    parse_arch,
    parse_override,
    resolved_dict,
    set_dotted,
    to_toml,
)
from cwrend_cli.errors import ConfigError, CwrendError
from cwrend_cli.physics import params

REPO = Path(__file__).resolve().parents[1]
PAPER_TOML = REPO / "campaigns" / "paper.toml"


def write(tmp_path: Path, text: str, name: str = "cfg.toml") -> Path:
    """Write a TOML file under tmp_path and return its path."""
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def config_error(data: dict) -> str:
    """The message of the ConfigError raised by validating ``data``."""
    with pytest.raises(ConfigError) as info:
        config_from_dict(data)
    return str(info.value)


# --- defaults = the paper's scenario ------------------------------------------


def test_defaults_are_the_paper_scenario() -> None:
    # Source: Candan & Servadio, AAS 26-893, Table 1, and x0, x_f of its Sec. "Numerical
    # Results and Discussion" (exact values); the mean motion and success_residual are the
    # authors' code's, not in the paper.
    cfg = CwrendConfig()
    sc, sch, g = cfg.scenario, cfg.schedule, cfg.guidance
    assert sc.mean_motion_rad_s == 0.00104218449
    assert (sc.horizon_s, sc.dt_s, sc.n_steps) == (800.0, 1.0, 800)
    assert sc.x0 == (0.03031809, 0.0, 31.16639, -0.02963377, 0.04570523, 0.0)
    assert sc.xf == (0.0,) * 6
    assert sc.u_max_km_s2 == 8e-4
    assert (sch.beta, sch.nis_offset, sch.score_lowpass) == (0.25, 3.0, 0.85)
    assert (sch.kappa_mtf, sch.score_max) == (12.0, 50.0)
    assert (sch.eps_min, sch.eps_max, sch.alpha_eps) == (0.0, 1.0, 0.10)
    assert (g.t_resolve_s, g.t_min_rem_s) == (10.0, 20.0)
    assert cfg.solver.success_residual == 1e-4  # the authors' code's, not in the paper


def test_default_covariances_are_the_paper_values() -> None:
    # Source: AAS 26-893, Table 1 (R_nominal, Q_proc, P0).
    est = CwrendConfig().estimator
    np.testing.assert_array_equal(est.r_nominal_matrix(), np.diag([1e-6] * 3))
    np.testing.assert_array_equal(est.q_matrix(), np.diag([1e-12] * 3 + [1e-14] * 3))
    np.testing.assert_array_equal(est.p0_matrix(), np.diag([1e-6] * 3 + [1e-10] * 3))


def test_default_degradation_windows_are_the_paper_windows() -> None:
    # Source: docs/method.md, "The paper's scenario", degradation row (the authors' code;
    # the paper gives no values).
    w1, w2 = CwrendConfig().degradation.windows
    assert (w1.start_s, w1.end_s, w1.r_scale, w1.bias_km) == (250.0, 325.0, 300.0, (0.0,) * 3)
    assert (w2.start_s, w2.end_s, w2.r_scale) == (325.0, 400.0, 300.0)
    assert w2.bias_km == (0.010, -0.008, 0.012)


def test_empty_file_is_the_paper_scenario(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, ""))
    assert cfg.model_copy(update={"output": OutputConfig()}) == CwrendConfig()


def test_paper_toml_equals_defaults_except_name() -> None:
    cfg = load_config(PAPER_TOML)
    assert cfg.output.name == "paper"
    assert cfg == CwrendConfig().model_copy(update={"output": OutputConfig(name="paper")})


def test_output_name_defaults_to_file_stem(tmp_path: Path) -> None:
    assert load_config(write(tmp_path, "", name="my_run.toml")).output.name == "my_run"


def test_models_are_frozen() -> None:
    cfg = CwrendConfig()
    with pytest.raises(ValueError, match="frozen"):
        cfg.scenario.horizon_s = 10.0  # type: ignore[misc]


def test_matrix_accessors_return_fresh_arrays() -> None:
    est = CwrendConfig().estimator
    r = est.r_nominal_matrix()
    r[0, 0] = 99.0
    assert est.r_nominal_matrix()[0, 0] == 1e-6
    assert r.dtype == np.float64


# --- unknown keys, wrong types ---------------------------------------------------


def test_unknown_top_level_key_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"colour: unknown key \(allowed: scenario, "):
        load_config(write(tmp_path, "colour = 1\n"))


def test_unknown_nested_key_is_named_with_allowed_keys(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as info:
        load_config(write(tmp_path, "[schedule]\nbeeta = 0.3\n"))
    assert "schedule.beeta: unknown key" in str(info.value)
    assert "beta" in str(info.value).split("allowed:")[1]


def test_unknown_key_inside_window_is_named() -> None:
    data = {"degradation": {"windows": [{"start_s": 0, "end_s": 1, "scale": 2}]}}
    assert "degradation.windows.0.scale: unknown key" in config_error(data)


def test_string_for_number_is_rejected() -> None:
    assert 'scenario.horizon_s = "800": must be a number' in config_error(
        {"scenario": {"horizon_s": "800"}}
    )


def test_bool_for_number_is_rejected() -> None:
    assert "schedule.beta = true: must be a number" in config_error({"schedule": {"beta": True}})


def test_float_for_integer_is_rejected() -> None:
    assert "solver.max_iter = 2.5: must be an integer" in config_error(
        {"solver": {"max_iter": 2.5}}
    )


def test_invalid_choice_lists_allowed_values() -> None:
    msg = config_error({"guidance": {"hold": "avg"}})
    assert "guidance.hold" in msg and "'sample'" in msg and "'mean'" in msg


def test_non_finite_number_is_rejected() -> None:
    assert "scenario.u_max_km_s2 = inf: must be a finite number" in config_error(
        {"scenario": {"u_max_km_s2": float("inf")}}
    )


# --- ranges and cross-field rules ------------------------------------------------


def test_negative_horizon_is_rejected() -> None:
    assert "scenario.horizon_s = -800: must be > 0" in config_error(
        {"scenario": {"horizon_s": -800.0}}
    )


def test_eps_min_above_eps_max_is_rejected() -> None:
    msg = config_error({"schedule": {"eps_min": 0.5, "eps_max": 0.2}})
    assert "schedule.eps_min = 0.5: must be <= eps_max (0.2)" in msg


def test_alpha_eps_above_one_is_rejected() -> None:
    assert "schedule.alpha_eps = 1.5: must be <= 1" in config_error(
        {"schedule": {"alpha_eps": 1.5}}
    )


def test_eps_saturation_outside_map_range_is_rejected() -> None:
    assert "schedule.eps_saturation = 2" in config_error({"schedule": {"eps_saturation": 2.0}})


def test_window_beyond_horizon_is_rejected() -> None:
    windows = [{"start_s": 700.0, "end_s": 900.0}]
    msg = config_error({"degradation": {"windows": windows}})
    assert "degradation.windows.0.end_s = 900: window must lie within [0, " in msg


def test_window_ending_before_it_starts_is_rejected() -> None:
    windows = [{"start_s": 300.0, "end_s": 200.0}]
    msg = config_error({"degradation": {"windows": windows}})
    assert "degradation.windows.0.end_s = 200: must be >= start_s (300)" in msg


def test_negative_window_start_is_rejected() -> None:
    windows = [{"start_s": -1.0, "end_s": 200.0}]
    assert "degradation.windows.0.start_s = -1: must be >= 0" in config_error(
        {"degradation": {"windows": windows}}
    )


def test_empty_window_list_is_allowed() -> None:
    assert config_from_dict({"degradation": {"windows": []}}).degradation.windows == ()


def test_horizon_not_multiple_of_dt_is_rejected() -> None:
    msg = config_error({"scenario": {"horizon_s": 800.5}})
    assert "scenario.horizon_s = 800.5: must be a whole multiple of dt_s (1)" in msg


def test_resolve_interval_not_multiple_of_dt_is_rejected() -> None:
    msg = config_error({"guidance": {"t_resolve_s": 2.5}})
    assert "guidance.t_resolve_s = 2.5: must be a whole multiple of scenario.dt_s" in msg


def test_min_remaining_not_below_horizon_is_rejected() -> None:
    msg = config_error({"guidance": {"t_min_rem_s": 800.0}})
    assert "guidance.t_min_rem_s = 800: must be < scenario.horizon_s (800)" in msg


def test_non_positive_definite_covariance_is_rejected() -> None:
    bad = [[1e-6, 2e-6, 0.0], [2e-6, 1e-6, 0.0], [0.0, 0.0, 1e-6]]
    msg = config_error({"estimator": {"r_nominal_km2": bad}})
    assert "estimator.r_nominal_km2" in msg and "must be positive definite" in msg


def test_non_positive_diagonal_covariance_is_rejected() -> None:
    msg = config_error({"estimator": {"p0": [1e-6, 1e-6, 0.0, 1e-10, 1e-10, 1e-10]}})
    assert "estimator.p0" in msg and "must be positive definite" in msg


def test_wrong_size_covariance_is_rejected() -> None:
    msg = config_error({"estimator": {"r_nominal_km2": [1e-6, 1e-6]}})
    assert "must have 3 entries (diagonal) or be a 3x3 matrix" in msg


def test_asymmetric_covariance_is_rejected() -> None:
    bad = [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    assert "must be symmetric" in config_error({"estimator": {"r_nominal_km2": bad}})


def test_full_covariance_matrix_is_accepted() -> None:
    full = [[2.0, 0.5, 0.0], [0.5, 2.0, 0.0], [0.0, 0.0, 1.0]]
    cfg = config_from_dict({"estimator": {"r_nominal_km2": full}})
    np.testing.assert_array_equal(cfg.estimator.r_nominal_matrix(), np.array(full))


def test_diagonal_matrix_and_diagonal_list_are_the_same_config() -> None:
    as_matrix = config_from_dict({"estimator": {"r_nominal_km2": np.diag([1e-6] * 3).tolist()}})
    assert as_matrix == CwrendConfig()
    assert config_hash(as_matrix) == config_hash(CwrendConfig())


def test_wrong_length_x0_is_rejected() -> None:
    assert "scenario.x0 = [1, 2, 3]: must have 6 entries (got 3)" in config_error(
        {"scenario": {"x0": [1, 2, 3]}}
    )


def test_all_errors_reported_one_per_line() -> None:
    msg = config_error({"scenario": {"horizon_s": -1.0, "dt_s": 0.0}})
    assert "scenario.horizon_s = -1: must be > 0" in msg.splitlines()[1]
    assert "scenario.dt_s = 0: must be >= 0.001" in msg.splitlines()[2]


# --- overrides ------------------------------------------------------------------


def test_override_sets_value(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, ""), ["schedule.beta=0.5", 'guidance.hold="mean"'])
    assert (cfg.schedule.beta, cfg.guidance.hold) == (0.5, "mean")


def test_override_bare_string_value(tmp_path: Path) -> None:
    assert load_config(write(tmp_path, ""), ["guidance.hold=mean"]).guidance.hold == "mean"


def test_override_wins_over_file(tmp_path: Path) -> None:
    path = write(tmp_path, "[schedule]\nbeta = 0.3\n")
    assert load_config(path, ["schedule.beta=1e-3"]).schedule.beta == 1e-3


def test_override_list_element_by_index(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, ""), ["degradation.windows.1.bias_km=[0,0,0]"])
    assert cfg.degradation.windows[1].bias_km == (0.0, 0.0, 0.0)
    assert cfg.degradation.windows[1].r_scale == 300.0  # rest of the default window kept


def test_override_index_out_of_range_is_rejected(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"degradation.windows: index 5 out of range"):
        load_config(write(tmp_path, ""), ["degradation.windows.5.r_scale=2"])


def test_override_unknown_key_is_rejected(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"schedule.gamma: unknown key"):
        load_config(write(tmp_path, ""), ["schedule.gamma=1"])


def test_override_unknown_section_is_rejected(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"sched: unknown key"):
        load_config(write(tmp_path, ""), ["sched.beta=1"])


@pytest.mark.parametrize("bad", ["schedule.beta", "=1", "schedule..beta=1", ".beta=1"])
def test_malformed_override_is_rejected(tmp_path: Path, bad: str) -> None:
    with pytest.raises(ConfigError, match="malformed"):
        load_config(write(tmp_path, ""), [bad])


def test_override_with_bad_value_names_field(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"schedule.alpha_eps = 1.5: must be <= 1"):
        load_config(write(tmp_path, ""), ["schedule.alpha_eps=1.5"])


def test_override_below_a_value_is_rejected(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"scenario\.horizon_s is a value"):
        load_config(write(tmp_path, "[scenario]\nhorizon_s = 800\n"), ["scenario.horizon_s.x=1"])


def test_parse_override_reads_toml_values() -> None:
    assert parse_override("a.b=[1, 2.5]") == ("a.b", [1, 2.5])
    assert parse_override("a=true") == ("a", True)
    assert parse_override("a=x=y") == ("a", "x=y")


def test_set_dotted_does_not_mutate_input() -> None:
    data = {"schedule": {"beta": 0.3}}
    out = set_dotted(data, "schedule.beta", 0.4)
    assert data == {"schedule": {"beta": 0.3}} and out == {"schedule": {"beta": 0.4}}


# --- files ----------------------------------------------------------------------


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "absent.toml")


def test_malformed_toml_reports_line(tmp_path: Path) -> None:
    path = write(tmp_path, "[scenario]\nhorizon_s = = 3\n")
    with pytest.raises(ConfigError, match=r"malformed TOML: .*line 2"):
        load_config(path)


def test_config_error_is_a_cwrend_error() -> None:
    assert issubclass(ConfigError, CwrendError)


def test_noise_file_relative_to_config_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "data").mkdir()
    noise = tmp_path / "data" / "noise.csv"
    noise.write_text("n1,n2,n3\n0,0,0\n")
    cfg_path = write(tmp_path, '[noise]\nfile = "data/noise.csv"\n')
    monkeypatch.chdir(REPO)  # the working directory must not matter
    assert load_config(cfg_path).noise.file == str(noise.resolve())


def test_missing_noise_file_is_rejected(tmp_path: Path) -> None:
    path = write(tmp_path, '[noise]\nfile = "nope.parquet"\n')
    with pytest.raises(ConfigError, match=r"noise.file = \"nope.parquet\": file not found"):
        load_config(path)


def test_noise_file_with_unknown_suffix_is_rejected(tmp_path: Path) -> None:
    (tmp_path / "noise.txt").write_text("x")
    path = write(tmp_path, '[noise]\nfile = "noise.txt"\n')
    with pytest.raises(ConfigError, match="must be a CSV or Parquet file"):
        load_config(path)


# --- output name ------------------------------------------------------------------


@pytest.mark.parametrize("name", ["../x", "a/b", "..", ".hidden", "a\\b", ""])
def test_unsafe_output_name_is_rejected(name: str) -> None:
    assert "output.name" in config_error({"output": {"name": name}})


def test_plain_output_name_is_accepted() -> None:
    assert config_from_dict({"output": {"name": "run-1.a_b"}}).output.name == "run-1.a_b"


# --- hashing and serialisation ----------------------------------------------------


def test_config_hash_is_stable() -> None:
    a = config_from_dict({"scenario": {"horizon_s": 800}})
    b = config_from_dict({"scenario": {"horizon_s": 800.0}})
    assert config_hash(a) == config_hash(b) == config_hash(CwrendConfig())
    assert len(config_hash(a)) == 64


def test_config_hash_changes_with_a_value() -> None:
    changed = config_from_dict({"schedule": {"beta": 0.26}})
    assert config_hash(changed) != config_hash(CwrendConfig())


def test_resolved_dict_round_trips() -> None:
    cfg = load_config(PAPER_TOML)
    assert config_from_dict(resolved_dict(cfg)) == cfg


def test_toml_output_round_trips(tmp_path: Path) -> None:
    cfg = config_from_dict({"schedule": {"eps_saturation": 0.5}, "output": {"name": "x"}})
    assert load_config(write(tmp_path, to_toml(cfg))) == cfg


# --- architectures --------------------------------------------------------------


def test_four_architectures() -> None:
    flags = {(a.mtf, a.adaptive) for a in ARCHITECTURES.values()}
    assert set(ARCHITECTURES) == {"plain_fixed", "mtf_fixed", "plain_adaptive", "mtf_adaptive"}
    assert flags == {(False, False), (True, False), (False, True), (True, True)}


def test_parse_arch() -> None:
    arch = parse_arch("mtf_adaptive")
    assert arch.mtf and arch.adaptive


def test_parse_arch_unknown_lists_allowed() -> None:
    with pytest.raises(ConfigError, match="allowed: plain_fixed, mtf_fixed"):
        parse_arch("mtf")


def test_architecture_is_the_physics_one_and_pickles() -> None:
    # The config re-exports the physics core's dataclass: one class under both
    # names, equal by value, and unchanged through pickling (workers get it so).
    arch = parse_arch("plain_adaptive")
    assert Architecture is params.Architecture
    assert ARCHITECTURES is params.ARCHITECTURES
    assert arch == params.Architecture("plain_adaptive", "plain", adaptive=True)
    assert hash(arch) == hash(params.Architecture("plain_adaptive", "plain", adaptive=True))
    assert pickle.loads(pickle.dumps(arch)) == arch
    assert pickle.loads(pickle.dumps(dict(ARCHITECTURES))) == dict(ARCHITECTURES)


def test_missing_required_window_key_is_named() -> None:
    msg = config_error({"degradation": {"windows": [{"start_s": 1.0}]}})
    assert "degradation.windows.0.end_s: missing required key" in msg


def test_format_validation_error_defaults_to_the_whole_config() -> None:
    with pytest.raises(ValidationError) as info:
        CwrendConfig.model_validate({"schedule": {"bta": 1.0}})
    lines = format_validation_error(info.value)
    assert lines == format_validation_error(info.value, CwrendConfig)
    assert lines[0].startswith("schedule.bta: unknown key (allowed: beta, nis_offset,")


def test_override_in_output_keeps_stem_name(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "", name="stem.toml"), ["output.dir=out"])
    assert (cfg.output.dir, cfg.output.name) == ("out", "stem")


def test_defaults_are_the_physics_paper_scenario() -> None:
    """The config's defaults and the physics parameters' defaults are one definition.

    Both are the paper's scenario: paper Table 1 plus the settings of the authors' code
    (docs/method.md).
    """
    from cwrend_cli.config.adapt import problem_of
    from cwrend_cli.physics.params import Problem

    assert problem_of(CwrendConfig()) == Problem()
