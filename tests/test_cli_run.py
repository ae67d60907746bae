"""`cwrend run`: outputs, determinism and user errors (issue: core, item 7)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.physics.sensors import standard_normal_stream

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
RUN_FILES = (
    "config.json",
    "summary.parquet",
    "steps.parquet",
    "solves.parquet",
    "references.parquet",
    "recording.rrd",
)
# Columns that measure wall time and so differ between otherwise identical runs.
TIMING_COLUMNS = ("wall_time_ms", "solve_mean_ms", "solve_max_ms")

runner = CliRunner()


def _run(*args: str):
    return runner.invoke(app, ["run", *args], catch_exceptions=False)


@pytest.fixture(scope="module")
def paper_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("run") / "out"
    result = _run(str(PAPER), "--arch", "mtf_adaptive,plain_fixed", "--out", str(out), "-q")
    assert result.exit_code == 0, result.output
    return out


def test_run_writes_every_file(paper_run: Path) -> None:
    assert sorted(p.name for p in paper_run.iterdir()) == sorted(RUN_FILES)


def test_steps_has_one_row_per_grid_time_and_architecture(paper_run: Path) -> None:
    steps = pd.read_parquet(paper_run / "steps.parquet")
    assert len(steps) == 2 * 801  # t = 0 … 800 s, two architectures
    assert set(steps["arch"]) == {"mtf_adaptive", "plain_fixed"}
    assert steps["t_s"].dtype == np.float64 and steps["degradation_window"].dtype == np.int64


def test_steps_last_control_is_zero(paper_run: Path) -> None:
    """In closed loop no control is computed at t = T.

    A convention of cwrend / the authors' code, not in the paper (docs/method.md).
    """
    steps = pd.read_parquet(paper_run / "steps.parquet")
    assert (steps.loc[steps["t_s"] == 800.0, "u_norm_km_s2"] == 0.0).all()


def test_summary_holds_references_and_runs(paper_run: Path) -> None:
    summary = pd.read_parquet(paper_run / "summary.parquet").set_index("arch")
    assert {"open_loop_energy", "open_loop_fuel", "mtf_adaptive", "plain_fixed"} <= set(
        summary.index
    )
    # fuel penalty is relative to the open-loop fuel Δv (paper, Sec. Numerical Results)
    fuel = summary.loc["open_loop_fuel", "delta_v_km_s"]
    row = summary.loc["mtf_adaptive"]
    assert row["fuel_penalty_pct"] == pytest.approx(100 * (row["delta_v_km_s"] / fuel - 1))
    assert summary.loc["mtf_adaptive", "n_solves"] == 78  # paper Table 1: t = 0, 10, …, 770 s


def test_config_json_holds_resolved_config_and_hash(paper_run: Path) -> None:
    data = json.loads((paper_run / "config.json").read_text())
    assert len(data["config_hash"]) == 64
    assert data["config"]["scenario"]["horizon_s"] == 800.0


def test_solves_record_status_and_fallback_step(paper_run: Path) -> None:
    solves = pd.read_parquet(paper_run / "solves.parquet")
    assert set(solves["status"]) <= {"converged", "infeasible", "failed"}
    assert (solves.loc[solves["arch"] == "mtf_adaptive", "kind"] == "initial").sum() == 1
    assert solves["fallback_step"].notna().all()


def _data_without_timing(path: Path) -> pd.DataFrame:
    table = pq.read_table(path)
    return table.select([c for c in table.column_names if c not in TIMING_COLUMNS]).to_pandas()


def test_same_config_and_seed_give_identical_data(paper_run: Path, tmp_path: Path) -> None:
    """Reproducibility: a second run writes the same data (wall times excepted)."""
    again = tmp_path / "again"
    result = _run(str(PAPER), "--arch", "mtf_adaptive,plain_fixed", "--out", str(again), "-q")
    assert result.exit_code == 0
    for name in ("steps.parquet", "summary.parquet", "solves.parquet", "references.parquet"):
        # exact comparison, NaN equal to NaN (row 0 has no measurement)
        pd.testing.assert_frame_equal(
            _data_without_timing(paper_run / name),
            _data_without_timing(again / name),
            check_exact=True,
        )


def test_different_seed_gives_different_noise(paper_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "seed1"
    assert _run(str(PAPER), "--arch", "mtf_adaptive", "--seed", "1", "--out", str(out), "-q")
    a = pd.read_parquet(paper_run / "steps.parquet").query("arch == 'mtf_adaptive'")
    b = pd.read_parquet(out / "steps.parquet")
    assert not np.array_equal(a["meas_x_km"].to_numpy()[1:], b["meas_x_km"].to_numpy()[1:])


def test_noise_file_replays_a_realisation(paper_run: Path, tmp_path: Path) -> None:
    """noise.file with the seed-0 stream reproduces the seed-0 run exactly."""
    noise = standard_normal_stream(np.random.SeedSequence(0, spawn_key=(0, 0)), 800)
    path = tmp_path / "noise.csv"
    pd.DataFrame(noise, columns=["n1", "n2", "n3"]).to_csv(path, index=False, float_format="%.17g")
    out = tmp_path / "replay"
    result = _run(
        str(PAPER), "--arch", "mtf_adaptive", "--set", f'noise.file="{path}"', "--out", str(out)
    )
    assert result.exit_code == 0, result.output
    a = pd.read_parquet(paper_run / "steps.parquet").query("arch == 'mtf_adaptive'")
    b = pd.read_parquet(out / "steps.parquet")
    assert np.array_equal(a["x_km"].to_numpy(), b["x_km"].to_numpy())


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--set", "scenario.horizon_s=-5"], "scenario.horizon_s"),
        (["--set", "schedule.nonsense=1"], "schedule.nonsense"),
        (["--set", "guidance.hold=average"], "guidance.hold"),
        (["--set", "noequals"], "noequals"),
        (["--arch", "bogus"], "bogus"),
    ],
)
def test_bad_input_exits_2_and_writes_nothing(args: list[str], needle: str, tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(PAPER), "--out", str(out), *args])
    assert result.exit_code == 2
    assert needle in result.output
    assert "Traceback" not in result.output
    assert not out.exists()


def test_disabled_rerun_exits_2_before_writing_anything(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("RERUN", "off")
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(PAPER), "--out", str(out)])
    assert result.exit_code == 2
    assert "--no-rrd" in result.output
    assert not out.exists()


def test_missing_config_file_exits_2(tmp_path: Path) -> None:
    result = runner.invoke(app, ["run", str(tmp_path / "nope.toml"), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    assert "nope.toml" in result.output


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        ("n1,n2,n3\n0.1,0.2,0.3\n", "rows"),  # one row instead of 800
        ("a,b,c\n" + "0,0,0\n" * 800, "n1"),  # wrong columns
        ("n1,n2,n3\n" + "0,0,0\n" * 799 + "nan,0,0\n", "non-finite"),
    ],
)
def test_malformed_noise_file_exits_2_and_writes_nothing(
    content: str, needle: str, tmp_path: Path
) -> None:
    path = tmp_path / "noise.csv"
    path.write_text(content)
    out = tmp_path / "out"
    result = runner.invoke(
        app, ["run", str(PAPER), "--set", f'noise.file="{path}"', "--out", str(out)]
    )
    assert result.exit_code == 2
    assert needle in result.output
    assert not out.exists()
    # a file bad from the start did not change: not "unusable since the campaign was
    # planned … run the same command to resume, or start over with --force" (run has none)
    assert "since the campaign was planned" not in result.output


def test_format_csv_prints_summary_parquet_columns_in_their_order(tmp_path: Path) -> None:
    """``run --format`` prints the rows of summary.parquet (run guide): its columns, in
    its order, so a script can read either with the same code."""
    out = tmp_path / "csv"
    args = ["--arch", "mtf_adaptive", "--out", str(out), "--no-rrd", "--format", "csv"]
    result = _run(str(PAPER), *args)
    assert result.exit_code == 0, result.output
    printed = pd.read_csv(io.StringIO(result.stdout))
    stored = pd.read_parquet(out / "summary.parquet")
    assert list(printed.columns) == list(stored.columns)
    assert list(printed["arch"]) == list(stored["arch"])


def test_run_lists_architectures_in_the_order_of_every_table(tmp_path: Path) -> None:
    """``--arch mtf_adaptive,plain_fixed``: the console tables, ``--format`` and
    summary.parquet list plain_fixed first, as ``ablate``, ``table`` and ``report`` do
    (:func:`cwrend_cli.physics.params.arch_order`), not in ``--arch`` order."""
    from cwrend_cli.physics.params import arch_order

    archs = ["mtf_adaptive", "plain_fixed"]
    assert list(arch_order(archs)) == archs[::-1]
    out = tmp_path / "out"
    args = ["--arch", ",".join(archs), "--out", str(out), "--no-rrd"]
    result = runner.invoke(app, ["run", str(PAPER), *args], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    lines = [line.split()[0] for line in result.stdout.splitlines() if line.strip()]
    shown = [name for name in lines if name in archs]
    assert shown == archs[::-1] * 3  # the run table, the applied Δv and the filter's
    assert list(pd.read_parquet(out / "summary.parquet")["arch"])[2:] == archs[::-1]


def test_a_design_model_the_architecture_refuses_is_refused_before_any_compile_notice(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``model.guidance = 'ya'`` with a shooting architecture: exit 2 with the reason, and
    no "compiling kernels" line first (on a cold cache it announced a compile that never
    came)."""
    from cwrend_cli.physics import compiled

    monkeypatch.setattr(
        compiled, "compiling_notice", lambda *a, **k: "compiling kernels (first run only)…"
    )
    j2 = PAPER.parent / "paper_j2.toml"
    out = f"output.dir={json.dumps(str(tmp_path))}"
    args = ["run", str(j2), "--arch", "mtf_adaptive", "--no-rrd", "--set", out,
            "--set", "model.guidance='ya'"]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "model.guidance = 'ya' with architecture mtf_adaptive" in result.stderr
    assert "compiling kernels" not in result.output
