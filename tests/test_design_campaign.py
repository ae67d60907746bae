"""Design campaigns and sequential Monte Carlo through the command line (issue 19)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cwrend_cli.campaign import sequential
from cwrend_cli.cli import app

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
    assert ("not met within --max-seeds" in result.stderr) == (not met)
    fixed = _config(tmp_path, "fixed", "")
    args = ["ablate", fixed, "--arch", ",".join(archs), "--workers", "1", "-q", "--seeds", str(n)]
    assert runner.invoke(app, args).exit_code == 0
    pd.testing.assert_frame_equal(runs, _runs(tmp_path / "results" / "fixed"))
