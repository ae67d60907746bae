"""Design campaigns and sequential Monte Carlo through the command line (issue 19)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign import sequential
from cwrend_cli.cli import app
from cwrend_cli.errors import ConfigError
from cwrend_cli.report import load_results
from cwrend_cli.report.figures import fig_sensitivity
from cwrend_cli.report.markdown import report_md

runner = CliRunner()
TIMING = ("duration_s", "solve_mean_ms", "solve_max_ms", "error")
RANGES = """
[sweep]
"schedule.beta" = { low = 0.05, high = 1.0 }
"schedule.kappa_mtf" = { low = 2.0, high = 30.0, log = true }
"""


def _config(tmp_path: Path, name: str, body: str = RANGES) -> str:
    path = tmp_path / f"{name}.toml"
    path.write_text(f'[output]\ndir = "{tmp_path / "results"}"\nname = "{name}"\nrrd_seeds = 0\n'
                    f"seeds_per_task = 1\n{body}")  # fmt: skip
    return str(path)


def _sweep(cfg: str, *args: str) -> list[str]:
    return ["sweep", cfg, "--arch", "mtf_adaptive", "--workers", "1", "-q", *args]


def _runs(out: Path) -> pd.DataFrame:
    runs = pd.read_parquet(out / "runs.parquet")
    runs = runs.drop(columns=[c for c in TIMING if c in runs.columns])
    return runs.sort_values("run_key").reset_index(drop=True)


def test_a_sobol_design_runs_resumes_and_writes_its_indices(tmp_path: Path) -> None:
    cfg = _config(tmp_path, "sobol")
    args = _sweep(cfg, "--design", "sobol", "--samples", "4", "--seeds", "2")
    assert (result := runner.invoke(app, args)).exit_code == 0, result.output
    out = tmp_path / "results" / "sobol"
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 4 * (2 + 2) * 2  # base points × (parameters + 2) × seeds
    beta = runs["param.schedule.beta"]
    assert beta.between(0.05, 1.0).all() and (beta.map(repr).str.len() <= 12).all()
    indices = pd.read_parquet(out / "sensitivity.parquet")
    assert set(indices["parameter"]) == {"schedule.beta", "schedule.kappa_mtf"}
    assert set(indices["statistic"]) == {"S1", "ST"} and (indices["n_seeds"] == 2).all()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["grid"] == {} and manifest["design"]["design"] == "sobol"
    assert manifest["design"]["samples"] == 4 and len(manifest["design"]["ranges"]) == 2
    again = runner.invoke(app, args)
    assert again.exit_code == 0 and len(pd.read_parquet(out / "runs.parquet")) == len(runs)


def test_a_larger_sobol_design_extends_the_smaller_one(tmp_path: Path) -> None:
    """Same directory, 2 then 4 base points: the same runs as a fresh 4-point campaign."""
    cfg = _config(tmp_path, "grow")
    assert runner.invoke(app, _sweep(cfg, "--design", "sobol", "--samples", "2")).exit_code == 0
    larger = runner.invoke(app, _sweep(cfg, "--design", "sobol", "--samples", "4"))
    assert larger.exit_code == 0, larger.output
    fresh = _config(tmp_path, "fresh")
    assert runner.invoke(app, _sweep(fresh, "--design", "sobol", "--samples", "4")).exit_code == 0
    grown, whole = _runs(tmp_path / "results" / "grow"), _runs(tmp_path / "results" / "fresh")
    pd.testing.assert_frame_equal(grown, whole)


def test_a_larger_latin_hypercube_is_refused_as_another_campaign(tmp_path: Path) -> None:
    cfg = _config(tmp_path, "lhs")
    assert runner.invoke(app, _sweep(cfg, "--design", "lhs", "--samples", "3")).exit_code == 0
    runs = pd.read_parquet(tmp_path / "results" / "lhs" / "runs.parquet").drop_duplicates("point")
    beta = (runs["param.schedule.beta"].to_numpy() - 0.05) / (1.0 - 0.05)
    kappa = np.log(runs["param.schedule.kappa_mtf"].to_numpy() / 2.0) / np.log(30.0 / 2.0)
    for u in (beta, kappa):  # one point per stratum of each (log-)range
        assert sorted(np.floor(u * 3).astype(int)) == [0, 1, 2]
    larger = runner.invoke(app, _sweep(cfg, "--design", "lhs", "--samples", "6"))
    assert larger.exit_code == 2
    assert "holds a campaign with a different configuration" in larger.stderr


@pytest.mark.parametrize(
    ("body", "args", "message"),
    [
        (RANGES, [], "a range table is sampled by a design: add --design"),
        (
            '[sweep]\n"schedule.beta" = [0.1, 0.2]\n',
            ["--design", "lhs", "--samples", "4"],
            "a --design samples ranges",
        ),
        (RANGES, ["--design", "sobol", "--samples", "6"], "power of two base points"),
        (RANGES, ["--design", "lhs"], "--design lhs needs --samples N"),
        (RANGES, ["--design", "grid", "--samples", "4"], "--design 'grid': one of"),
        (
            '[sweep]\n"schedule.beta" = { low = 1.0, high = 0.5 }\n',
            ["--design", "random", "--samples", "4"],
            "[sweep] schedule.beta: low = 1.0",
        ),
    ],
)
def test_a_bad_design_exits_2_naming_the_problem(
    tmp_path: Path, body: str, args: list[str], message: str
) -> None:
    result = runner.invoke(app, _sweep(_config(tmp_path, "bad", body), *args))
    assert result.exit_code == 2
    assert message in result.stderr and "Traceback" not in result.output
    assert not (tmp_path / "results").exists()


def test_until_runs_batches_and_equals_a_fixed_campaign_of_its_final_size(
    tmp_path: Path,
) -> None:
    cfg = _config(tmp_path, "until", "")
    target = "miss_km:0.0004"
    result = runner.invoke(app, ["ablate", cfg, "--arch", "mtf_adaptive,plain_adaptive",
                                 "--workers", "1", "--until", target, "--batch", "10",
                                 "--max-seeds", "30"])  # fmt: skip
    assert result.exit_code == 0, result.output
    out = tmp_path / "results" / "until"
    runs = _runs(out)
    n = runs["seed"].nunique()
    assert n % 10 == 0 and sequential.MIN_SEEDS <= n <= 30
    stats = pd.read_parquet(out / "ablation.parquet")
    archs = ["mtf_adaptive", "plain_adaptive"]
    met = all(a.met for a in sequential.achieved(stats, sequential.parse_until(target), archs))
    assert met or n == 30  # it stops before --max-seeds only when the target is met
    assert ("--until not met: --max-seeds 30 reached" in result.stderr) == (not met)
    fixed = _config(tmp_path, "fixed", "")
    args = ["ablate", fixed, "--arch", ",".join(archs), "--workers", "1", "-q", "--seeds", str(n)]
    assert runner.invoke(app, args).exit_code == 0
    pd.testing.assert_frame_equal(runs, _runs(tmp_path / "results" / "fixed"))


def _salib_inputs(out: Path, arch: str, metric: str) -> tuple[dict[str, Any], pd.DataFrame, Any]:
    """What the manual tells a user to read: problem.json, design.parquet and Y from the runs."""
    problem = json.loads((out / "problem.json").read_text())
    matrix = pd.read_parquet(out / "design.parquet")
    runs = pd.read_parquet(out / "runs.parquet")
    ok = runs[(runs["status"] == "ok") & (runs["arch"] == arch)]
    y = matrix["point"].map(ok.groupby("point")[metric].mean()).to_numpy()
    return problem, matrix, y


def _stored(out: Path, metric: str, statistic: str) -> pd.DataFrame:
    stored = pd.read_parquet(out / "sensitivity.parquet")
    return stored[(stored["metric"] == metric) & (stored["statistic"] == statistic)]


def test_salib_takes_back_a_sobol_design_and_gives_the_stored_indices(tmp_path: Path) -> None:
    """design.parquet in SALib's row order + problem.json + runs.parquet: SALib's own
    sobol.analyze, given the arguments problem.json records, reproduces every stored
    S1, ST and S2 and its interval exactly (second-order on request)."""
    from SALib.analyze import sobol

    cfg = _config(tmp_path, "salib")
    args = _sweep(cfg, "--design", "sobol", "--samples", "4", "--seeds", "2", "--second-order")
    args.remove("-q")
    assert (result := runner.invoke(app, args)).exit_code == 0, result.output
    assert "second-order Sobol indices" in result.output
    out = tmp_path / "results" / "salib"
    for metric in ("miss_km", "delta_v_km_s"):
        problem, matrix, y = _salib_inputs(out, "mtf_adaptive", metric)
        assert len(matrix) == 4 * (2 * 2 + 2) and list(matrix["row"]) == list(range(len(matrix)))
        about = problem["cwrend"]
        si = sobol.analyze(problem, y, calc_second_order=about["calc_second_order"],
                           num_resamples=about["num_resamples"], conf_level=about["conf_level"],
                           seed=about["seed"])  # fmt: skip
        for stat in ("S1", "ST"):
            stored = _stored(out, metric, stat).set_index("parameter").loc[problem["names"]]
            assert np.array_equal(stored["value"], si[stat])
            assert np.array_equal(stored["ci_high"], si[stat] + si[f"{stat}_conf"])
            assert np.array_equal(stored["ci_low"], si[stat] - si[f"{stat}_conf"])
        s2 = _stored(out, metric, "S2")
        assert list(zip(s2["parameter"], s2["parameter_2"], strict=True)) == [
            ("schedule.beta", "schedule.kappa_mtf")
        ]
        assert s2["value"].iloc[0] == si["S2"][0, 1]
    md = report_md(load_results(out), out, [])
    assert "Second-order Sobol indices" in md and "| β [-] × κ_MTF [-] |" in md


def test_the_design_matrix_holds_the_unit_sample_salib_draws(tmp_path: Path) -> None:
    """design.parquet's unit.* columns are SALib's sample of problem.json (scaled by its
    bounds and dists: the values the runs used, to their 10 stored digits)."""
    from SALib.sample import sobol as saltelli

    cfg = _config(tmp_path, "matrix")
    args = _sweep(cfg, "--design", "sobol", "--samples", "4", "--seeds", "1")
    assert (result := runner.invoke(app, args)).exit_code == 0, result.output
    out = tmp_path / "results" / "matrix"
    problem = json.loads((out / "problem.json").read_text())
    matrix = pd.read_parquet(out / "design.parquet")
    unit_problem = {**problem, "bounds": [[0, 1]] * 2, "dists": ["unif"] * 2}
    seed = problem["cwrend"]["seed"]
    drawn = saltelli.sample(unit_problem, 4, calc_second_order=False, seed=seed)
    names = problem["names"]
    assert np.array_equal(matrix[[f"unit.{n}" for n in names]].to_numpy(), drawn)
    scaled = saltelli.sample(problem, 4, calc_second_order=False, seed=seed)
    values = matrix[[f"param.{n}" for n in names]].to_numpy()
    assert np.allclose(values, scaled, rtol=1e-9, atol=0)
    runs = pd.read_parquet(out / "runs.parquet").drop_duplicates("point").set_index("point")
    for n in names:
        assert (matrix[f"param.{n}"].to_numpy() == runs.loc[matrix["point"], f"param.{n}"]).all()


def test_an_lhs_design_from_the_command_line_prints_and_stores_rbd_fast_indices(
    tmp_path: Path,
) -> None:
    """--range defines the design without a [sweep] table; its first-order indices (RBD-FAST)
    are on the console, in sensitivity.parquet (SALib's rbd_fast on the written files gives
    them back exactly) and in the report."""
    from SALib.analyze import rbd_fast

    cfg = _config(tmp_path, "lhs", "")
    ranges = ["--range", "schedule.beta=0.05:1.0", "--range", "schedule.kappa_mtf=2:30:log"]
    args = _sweep(cfg, "--design", "lhs", "--samples", "12", "--seeds", "1", *ranges)
    args.remove("-q")
    assert (result := runner.invoke(app, args)).exit_code == 0, result.output
    assert "RBD-FAST" in result.output and "kappa_mtf" in result.output
    out = tmp_path / "results" / "lhs"
    stored = pd.read_parquet(out / "sensitivity.parquet")
    assert set(stored["method"]) == {"rbd_fast"} and set(stored["statistic"]) == {"S1"}
    problem, matrix, y = _salib_inputs(out, "mtf_adaptive", "miss_km")
    about = problem["cwrend"]
    x = matrix[[f"unit.{n}" for n in problem["names"]]].to_numpy()
    si = rbd_fast.analyze(problem, x, y, M=about["M"], num_resamples=about["num_resamples"],
                          conf_level=about["conf_level"], seed=about["seed"])  # fmt: skip
    miss = _stored(out, "miss_km", "S1").set_index("parameter").loc[problem["names"]]
    assert np.array_equal(miss["value"], si["S1"])
    assert np.array_equal(miss["ci_high"], np.add(si["S1"], si["S1_conf"]))
    data = load_results(out)
    text = report_md(data, out, [])
    assert "RBD-FAST" in text and "| S1 terminal miss | S1 Δv |" in text
    legend = fig_sensitivity(data).legends[0]  # S1 bars alone: RBD-FAST has no total index
    assert [t.get_text() for t in legend.get_texts()] == ["S1 (first-order)", "95 % interval"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--design", "lhs", "--samples", "4", "--range", "schedule.bta=0.1:1"],
         "--range schedule.bta=0.1:1: schedule.bta is not a configuration value"),
        (["--design", "lhs", "--samples", "4", "--range", "schedule.beta=1:0.1"],
         "--range schedule.beta=1:0.1: low = 1.0, high = 0.1"),
        (["--design", "lhs", "--samples", "4", "--range", "schedule.beta=-1:1"],
         "--range schedule.beta=-1:1: LOW = -1.0 is not a value schedule.beta takes "
         "(schedule.beta = -1: must be > 0); expected KEY=LOW:HIGH (uniform)"),
        (["--design", "lhs", "--samples", "4", "--range", "truth.model=cw,jj2"],
         "--range truth.model=cw,jj2: V2 = 'jj2' is not a value truth.model takes"),
        (["--design", "lhs", "--samples", "4", "--range", "schedule.beta=1:-1"],
         "--range schedule.beta=1:-1: low = 1.0"),  # ":-1:" is no emoji code
        (["--range", "schedule.beta=0.1:1"], "--range defines a sampled design: add --design"),
        (["--design", "lhs", "--samples", "4"], "--design lhs: no ranges; give --range"),
        (["--design", "lhs", "--samples", "16", "--range", "schedule.beta=0.1:1",
          "--second-order"], "--second-order: second-order indices need --design sobol"),
    ],
)  # fmt: skip
def test_a_bad_command_line_design_exits_2_naming_the_option(
    tmp_path: Path, args: list[str], message: str
) -> None:
    result = runner.invoke(app, _sweep(_config(tmp_path, "bad", ""), *args))
    assert result.exit_code == 2, result.output
    assert message in result.stderr and "Traceback" not in result.output
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ('"schedule.bta" = { low = 0.1, high = 1.0 }',
         "[sweep] schedule.bta: schedule.bta is not a configuration value (a dotted key such as "
         "schedule.beta or scenario.u_max_km_s2); did you mean 'schedule.beta'?"),
        ('"schedule.beta" = { low = -1, high = 1 }',
         "[sweep] schedule.beta: low = -1.0 is not a value schedule.beta takes "
         "(schedule.beta = -1: must be > 0); expected { low = LOW, high = HIGH } (uniform"),
        ('"solver.max_iter" = { low = 0, high = 5, int = true }',
         "[sweep] solver.max_iter: low = 0 is not a value solver.max_iter takes"),
        ('"truth.model" = { values = ["cw", "jj2"] }',
         "[sweep] truth.model: values[1] = 'jj2' is not a value truth.model takes"),
        ('"degradation.windows.0" = { start_s = 250.0, end_s = 325.0, r_scale = 30.0 }',
         "[sweep] degradation.windows.0: a table of end_s, r_scale, start_s is not a range, and "
         "a design samples no whole table: a range is { low = LOW, high = HIGH }"),
    ],
)  # fmt: skip
def test_a_bad_sweep_table_range_exits_2_naming_the_key_as_range_does(
    tmp_path: Path, body: str, message: str
) -> None:
    """A ``[sweep]`` range gets the checks of ``--range`` (the same function), named by its
    key in ``[sweep]``: it was refused only once sampled, as "grid point p… is invalid"."""
    cfg = _config(tmp_path, "bad", f"[sweep]\n{body}\n")
    result = runner.invoke(app, _sweep(cfg, "--design", "lhs", "--samples", "4"))
    assert result.exit_code == 2, result.output
    assert message in result.stderr and "Traceback" not in result.output
    assert "grid point" not in result.stderr
    assert not (tmp_path / "results").exists()


MIXED = '[sweep]\n"schedule.beta" = [0.1, 0.2]\n"schedule.kappa_mtf" = { low = 2.0, high = 30.0 }\n'


@pytest.mark.parametrize(
    "command",
    [
        ["sweep"],
        ["sweep", "--design", "lhs", "--samples", "4"],
        ["config", "validate"],
    ],
    ids=["sweep", "sweep --design", "config validate"],
)
def test_a_sweep_mixing_grid_values_and_ranges_gets_one_message_from_every_command(
    tmp_path: Path, command: list[str]
) -> None:
    cfg = _config(tmp_path, "mixed", MIXED)
    args = [*command[:1], cfg, *command[1:]] if command[0] == "sweep" else [*command, cfg]
    if command[0] == "sweep":
        args += ["--arch", "mtf_adaptive", "--workers", "1", "-q"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2
    assert (
        "[sweep] mixes grid values (schedule.beta) with ranges (schedule.kappa_mtf)"
        in result.stderr
    )
    assert "Traceback" not in result.output
    assert not (tmp_path / "results").exists()


def test_a_range_replaces_a_sweep_range_before_it_is_checked() -> None:
    """``--range`` replaces a ``[sweep]`` key's range (designs guide), so the replaced one is
    not refused, as a ``[sweep]`` grid key that ``--param`` replaces is not."""
    from cwrend_cli.campaign.plan import design_points
    from cwrend_cli.config import CwrendConfig, resolved_dict

    base = resolved_dict(CwrendConfig())
    sweep = {"schedule.beta": {"low": -1.0, "high": 1.0}}
    spec, _ = design_points(sweep, [], "lhs", 2, 0, ["schedule.beta=0.1:1"], base=base)
    assert [(r.key, r.low, r.high) for r in spec.ranges] == [("schedule.beta", 0.1, 1.0)]
    with pytest.raises(ConfigError, match=r"\[sweep\] schedule\.beta: low = -1\.0"):
        design_points(sweep, [], "lhs", 2, 0, [], base=base)


def test_a_design_writes_per_step_data_of_its_first_point_and_its_references_once(
    tmp_path: Path,
) -> None:
    """By default (output.design_steps_points = 1) only the first design point in design
    order has steps; the points of one scenario share one references file; the report
    reads that point with its references."""
    cfg = _config(tmp_path, "lean")
    args = _sweep(cfg, "--design", "sobol", "--samples", "2", "--seeds", "2")
    assert (result := runner.invoke(app, args)).exit_code == 0, result.output
    out = tmp_path / "results" / "lean"
    first = pd.read_parquet(out / "design.parquet")["point"].iloc[0]
    steps = pd.read_parquet(out / "steps", columns=["point", "seed"])
    assert set(steps["point"]) == {first} and set(steps["seed"]) == {0, 1}
    solves = pd.read_parquet(out / "solves", columns=["point"])  # small: every run keeps them
    assert solves["point"].nunique() == pd.read_parquet(out / "runs.parquet")["point"].nunique()
    stored = sorted(p.name for p in (out / "references").iterdir())
    assert len(stored) == 2 and stored[0] == "index.jsonl"  # β and κ do not change them
    data = load_results(out)
    assert data.point == first and data.references is not None
    assert not any("references" in note for note in data.notes)


def test_design_steps_points_chooses_how_many_design_points_keep_steps(tmp_path: Path) -> None:
    cfg = _config(tmp_path, "steps")
    args = _sweep(cfg, "--design", "sobol", "--samples", "2", "--seeds", "1",
                  "--set", "output.design_steps_points=3")  # fmt: skip
    assert (result := runner.invoke(app, args)).exit_code == 0, result.output
    out = tmp_path / "results" / "steps"
    rows = pd.read_parquet(out / "design.parquet")["point"]
    steps = pd.read_parquet(out / "steps", columns=["point"])
    assert set(steps["point"]) == set(list(dict.fromkeys(rows))[:3])


def test_second_order_extends_a_first_order_campaign_of_the_same_samples(tmp_path: Path) -> None:
    """Same directory, first-order then --second-order: only the B_A^(i) rows run, and the
    campaign equals a fresh second-order campaign. (Three ranges: with two, B_A^(1) is
    A_B^(2) and B_A^(2) is A_B^(1), the same points.)"""
    third = ("--range", "schedule.nis_offset=1.5:6")
    cfg = _config(tmp_path, "grow2")
    args = _sweep(cfg, "--design", "sobol", "--samples", "2", *third)
    assert runner.invoke(app, args).exit_code == 0
    first = _runs(tmp_path / "results" / "grow2")
    assert (result := runner.invoke(app, [*args, "--second-order"])).exit_code == 0, result.output
    grown = _runs(tmp_path / "results" / "grow2")
    assert len(first) == 2 * (3 + 2) and len(grown) == 2 * (2 * 3 + 2)
    assert set(first["run_key"]) <= set(grown["run_key"])
    manifest = json.loads((tmp_path / "results" / "grow2" / "manifest.json").read_text())
    assert manifest["design"]["second_order"] is True
    fresh = _config(tmp_path, "fresh2")
    args = _sweep(fresh, "--design", "sobol", "--samples", "2", *third, "--second-order")
    assert runner.invoke(app, args).exit_code == 0
    pd.testing.assert_frame_equal(grown, _runs(tmp_path / "results" / "fresh2"))
