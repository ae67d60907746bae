"""``cwrend table``: the study tables of the docs, from stored statistics (issue 37, item 8).

Small campaigns made here stand for the 1,000-seed studies: a sweep over the
hold (the ``paper-1000`` sweep), the same sweep with actuator errors (a
variant of the mismatch study) and an ablation of shooting and cone-program
architectures (the methods study). Each table has the layout of the docs'
tables and its cells are the stored values, formatted, never recomputed.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import Result
from test_safety_measured import SHORT
from typer.testing import CliRunner

from cwrend_cli.cli import app

runner = CliRunner()
ADAPTIVE = "mtf_adaptive,plain_adaptive"
SOCP = "mtf_adaptive,plain_adaptive,mtf_adaptive_socp,plain_adaptive_socp"


def _campaign(root: Path, command: str, name: str, *args: str) -> Path:
    cfg = root / "c.toml"
    cfg.write_text(f'[output]\ndir = "{root / "results"}"\n')
    base = [command, str(cfg), "--name", name, "--seeds", "3", "-w", "1", "--no-rrd", "-q"]
    result = runner.invoke(app, [*base, *args])
    assert result.exit_code == 0, result.output
    return root / "results" / name


@pytest.fixture(scope="module")
def studies(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("studies")
    hold = ("--param", "guidance.hold=sample,mean", "--arch", ADAPTIVE)
    return {
        "sweep": _campaign(root, "sweep", "hold", *hold),
        "actuator": _campaign(
            root, "sweep", "hold_actuator", *hold, "--set", "actuator.magnitude_sigma=0.01"
        ),
        # an added pair: its rows come from a stream of its own, as a pair across campaigns'
        "methods": _campaign(
            root, "ablate", "methods", "--arch", SOCP, "--pair", "plain_adaptive:mtf_adaptive"
        ),
    }


def _table(*args: str | Path) -> Result:
    return runner.invoke(app, ["table", *map(str, args)])


def _lines(result: Result) -> list[str]:
    assert result.exit_code == 0, result.output
    return result.stdout.splitlines()


def _ci(row: pd.Series, scale: float, digits: int, mark: str = "\\*") -> str:
    """A cell as the docs print it: value [low, high], from a stored statistics row."""
    v, lo, hi = (float(row[c]) * scale for c in ("value", "ci_low", "ci_high"))
    return f"{v:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]{mark}"


def _stat(path: Path, **where: str) -> pd.Series:
    stats = pd.read_parquet(path)
    for column, value in where.items():
        stats = stats[stats[column.replace("__", ".")] == value]
    assert len(stats) == 1
    return stats.iloc[0]


def _paired(ablation: Path, arch: str, other: str, statistic: str) -> pd.Series:
    """A stored paired row of an ablation (mean_diff: of Δv; the others: of the miss)."""
    metric = "delta_v_km_s" if statistic == "mean_diff" else "miss_km"
    return _stat(ablation / "ablation.parquet", kind="paired", arch=arch, other=other,
                 metric=metric, statistic=statistic)  # fmt: skip


# --- the layouts of the docs' tables ------------------------------------------


def test_the_sweep_table_per_grid_point_and_architecture(studies: dict[str, Path]) -> None:
    """As "Results on the paper scenario": swept values, architecture, n, intervals."""
    result = _table(
        studies["sweep"],
        "--rows",
        "guidance.hold,arch",
        "--metric",
        "n,mean.miss,median.miss,p95.miss:bare,mean.dv,infeasible_pct,failed_pct",
    )
    lines = _lines(result)
    assert lines[0] == (
        "| hold | architecture | n | mean miss [m] (95 % CI) | median miss [m] (95 % CI) | "
        "p95 miss [m] | mean Δv [km/s] (95 % CI) | re-solves infeasible [%] | "
        "re-solves failed [%] |"
    )
    assert lines[1] == "|" + "---|" * 9
    rows = [line.split(" | ") for line in lines[2:6]]
    assert [(r[0].removeprefix("| "), r[1]) for r in rows] == [
        ("sample", "plain_adaptive"),
        ("sample", "mtf_adaptive"),
        ("mean", "plain_adaptive"),
        ("mean", "mtf_adaptive"),
    ]  # the grid's order of the values, the package's order of architectures
    stats = studies["sweep"] / "sweep.parquet"
    for r in rows:
        key = {"param__guidance__hold": r[0].removeprefix("| "), "arch": r[1], "kind": "marginal"}
        mean = _stat(stats, **key, metric="miss_km", statistic="mean")
        p95 = _stat(stats, **key, metric="miss_km", statistic="p95")
        dv = _stat(stats, **key, metric="delta_v_km_s", statistic="mean")
        assert r[2] == str(int(mean["n"]))
        assert r[3] == _ci(mean, 1e3, 2)
        assert r[5] == f"{float(p95['value']) * 1e3:.2f}"
        assert r[6] == _ci(dv, 1.0, 4)
        assert r[7] == "0.00" and r[8].removesuffix(" |") == "0.00"  # adaptive: none
    assert lines[-1] == "\\* fewer than 10 seeds: bootstrap interval unreliable"


def test_the_paired_table_per_grid_point(studies: dict[str, Path]) -> None:
    """As the docs' P(MTF-adaptive misses less than plain-adaptive) table (Wilson interval)."""
    pair = "@mtf_adaptive-plain_adaptive"
    result = _table(
        studies["sweep"],
        "--rows",
        "guidance.hold",
        "--metric",
        f"frac_less.miss{pair},median_diff.miss{pair}",
    )
    lines = _lines(result)
    assert lines[0] == (
        "| hold | P(mtf_adaptive misses less than plain_adaptive) (95 % Wilson) | "
        "median miss difference [m] (95 % CI) |"
    )
    sample = lines[2].split(" | ")
    key = {
        "param__guidance__hold": "sample",
        "kind": "paired",
        "arch": "mtf_adaptive",
        "metric": "miss_km",
    }
    stats = studies["sweep"] / "sweep.parquet"
    assert sample[1] == _ci(_stat(stats, **key, statistic="frac_less"), 1.0, 3, mark="")
    assert sample[2] == _ci(_stat(stats, **key, statistic="median_diff"), 1e3, 2) + " |"


def test_a_cross_campaign_table_has_a_column_per_campaign(studies: dict[str, Path]) -> None:
    """As "Robustness under model mismatch": rows architecture, one column per variant."""
    result = _table(
        f"ideal sensors & actuator={studies['sweep']}",
        f"+ actuator errors={studies['actuator']}",
        "--where",
        "guidance.hold=mean",
        "--rows",
        "arch",
        "--cols",
        "campaign",
        "--metric",
        "mean.miss",
        "--title",
        'Mean miss [m] (95 % CI), `hold = "mean"`:',
    )
    lines = _lines(result)
    assert lines[:4] == [
        'Mean miss [m] (95 % CI), `hold = "mean"`:',
        "",
        "| architecture | ideal sensors & actuator | + actuator errors |",
        "|---|---|---|",
    ]
    row = lines[5].split(" | ")
    assert row[0] == "| mtf_adaptive"
    for cell, name in zip(row[1:], ("sweep", "actuator"), strict=True):
        stored = _stat(
            studies[name] / "sweep.parquet",
            param__guidance__hold="mean",
            kind="marginal",
            arch="mtf_adaptive",
            metric="miss_km",
            statistic="mean",
        )
        assert cell.removesuffix(" |") == _ci(stored, 1e3, 2)


def test_the_methods_table_pairs_each_cone_program_with_its_shooting_twin(
    studies: dict[str, Path],
) -> None:
    """As "Shooting vs cone-program guidance": cone program, vs shooting, the comparisons."""
    result = _table(
        studies["methods"],
        "--rows",
        "arch=cone program,other=vs shooting",
        "--where",
        "arch=plain_adaptive_socp,mtf_adaptive_socp",
        "--where",
        "other=plain_adaptive,mtf_adaptive",
        "--metric",
        "n,frac_less.miss,median_diff.miss,mean_diff.dv",
    )
    lines = _lines(result)
    assert lines[0] == (
        "| cone program | vs shooting | n | P(A misses less than B) (95 % Wilson) | "
        "median miss difference [m] (95 % CI) | mean Δv difference [km/s] (95 % CI) |"
    )
    assert [line.split(" | ")[:2] for line in lines[2:4]] == [
        ["| plain_adaptive_socp", "plain_adaptive"],
        ["| mtf_adaptive_socp", "mtf_adaptive"],
    ]
    stored = _paired(studies["methods"], "mtf_adaptive_socp", "mtf_adaptive", "mean_diff")
    assert lines[3].split(" | ")[2] == "3"  # seed pairs
    assert lines[3].split(" | ")[5] == _ci(stored, 1.0, 5) + " |"


def test_an_ablation_lines_up_with_a_sweep_on_its_base_value(studies: dict[str, Path]) -> None:
    """The ablation sweeps no hold: its rows carry its base value (sample), beside the
    sweep's mean-hold rows, as the methods table shows the two holds."""
    result = _table(
        studies["methods"],
        studies["sweep"],
        "--where",
        "hold:guidance.hold=mean",
        "--where",
        "arch=mtf_adaptive,mtf_adaptive_socp",
        "--rows",
        "guidance.hold,arch,campaign",
        "--metric",
        "mean.miss",
    )
    lines = _lines(result)
    assert [line.split(" | ")[:3] for line in lines[2:5]] == [
        ["| sample", "mtf_adaptive", "methods"],
        ["| sample", "mtf_adaptive_socp", "methods"],
        ["| mean", "mtf_adaptive", "hold"],
    ]


# --- formats ---------------------------------------------------------------------


def test_latex_is_a_booktabs_tabular_with_escaped_text(studies: dict[str, Path]) -> None:
    result = _table(
        studies["sweep"], "--rows", "guidance.hold,arch", "--metric", "mean.dv", "--format", "latex"
    )
    lines = _lines(result)
    assert lines[:4] == [
        "\\begin{tabular}{llr}",
        "\\toprule",
        "hold & architecture & mean $\\Delta$v [km/s] (95 \\% CI) \\\\",
        "\\midrule",
    ]
    assert lines[4].startswith("sample & plain\\_adaptive & 0.1")
    assert lines[4].endswith("]$^{*}$ \\\\")
    assert lines[-3:-1] == ["\\bottomrule", "\\end{tabular}"]


def test_csv_gives_each_value_and_its_interval_unrounded(studies: dict[str, Path]) -> None:
    result = _table(
        studies["sweep"],
        "--rows",
        "guidance.hold,arch",
        "--metric",
        "n,mean.miss",
        "--format",
        "csv",
    )
    assert result.exit_code == 0, result.output
    rows = list(csv.reader(io.StringIO(result.stdout)))
    assert rows[0] == [
        "hold",
        "architecture",
        "n",
        "mean miss [m] (95 % CI)",
        "mean miss [m] (95 % CI) low",
        "mean miss [m] (95 % CI) high",
    ]
    stored = _stat(
        studies["sweep"] / "sweep.parquet",
        param__guidance__hold="sample",
        kind="marginal",
        arch="plain_adaptive",
        metric="miss_km",
        statistic="mean",
    )
    assert rows[1][:3] == ["sample", "plain_adaptive", "3"]
    assert [float(x) for x in rows[1][3:]] == [
        float(stored[c]) * 1e3 for c in ("value", "ci_low", "ci_high")
    ]


# --- refusals ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--rows", "hold"), "--rows 'hold': unknown field"),
        (("--rows", "arch", "--metric", "mean.mis"), "unknown metric 'mis'"),
        (("--metric", "frac_less.dv"), "statistic 'frac_less' of delta_v_km_s"),
        (("--where", "guidance.hold=never"), "--where guidance.hold=never keeps nothing"),
        (("--rows", "arch"), "differ in guidance.hold (sample, mean): add guidance.hold"),
        (("--format", "html"), "--format 'html'"),
        (("--rows", "metric,arch", "--cols", "guidance.hold"), "--rows metric: the values"),
    ],
)
def test_a_bad_table_exits_2_saying_why(
    studies: dict[str, Path], args: tuple[str, ...], message: str
) -> None:
    result = _table(studies["sweep"], *args)
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    assert "Traceback" not in result.output


def test_unknown_field_suggests_the_swept_key(studies: dict[str, Path]) -> None:
    result = _table(studies["sweep"], "--rows", "hold")
    assert "did you mean 'guidance.hold'?" in result.stderr


def test_a_directory_without_statistics_is_refused(tmp_path: Path) -> None:
    result = _table(tmp_path)
    assert result.exit_code == 2
    assert "not a campaign directory with statistics" in result.stderr


def test_the_benchmark_script_prints_what_cwrend_table_prints(
    studies: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """benchmarks.sweep_table is cwrend table with the docs' options: one place builds them."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1]))  # the repository's
    from benchmarks.sweep_table import PAIRED, PER_ARCH, tables

    sweep = studies["sweep"]
    first = _lines(_table(sweep, "--rows", "guidance.hold,arch", "--metric", PER_ARCH))
    second = _lines(_table(sweep, "--rows", "guidance.hold", "--metric", PAIRED))
    assert tables(sweep).splitlines() == [*first, "", *second]


# --- pairs across campaigns (--versus) --------------------------------------------

PAIRED_VALUES = ",".join(
    f"{v}@plain_adaptive-mtf_adaptive"
    for v in ("frac_less.miss", "median_diff.miss", "mean_diff.dv")
)


def test_a_pair_across_campaigns_is_the_pair_within_one(studies: dict[str, Path]) -> None:
    """plain-adaptive of the hold sweep (its sample-hold point) against mtf-adaptive of the
    methods ablation: the same runs as the ablation's own pair, so the same row, intervals
    included (the rows of an added pair, bootstrapped from the shared root seed)."""
    result = _table(
        studies["methods"],
        studies["sweep"],
        "--versus",
        "methods",
        "--where",
        "hold:guidance.hold=sample",
        "--rows",
        "campaign,other_campaign",
        "--metric",
        f"n,{PAIRED_VALUES}",
    )
    lines = _lines(result)
    assert lines[0].startswith("| campaign | vs campaign | n | P(plain_adaptive misses less")
    within, across = (line.split(" | ") for line in lines[2:4])
    assert within[:2] == ["| methods", "methods"] and across[:2] == ["| hold", "methods"]
    assert within[2:] == across[2:]
    assert within[2] == "3"
    stored = _paired(studies["methods"], "plain_adaptive", "mtf_adaptive", "median_diff")
    assert across[4] == _ci(stored, 1e3, 2)


def test_a_pair_across_campaigns_takes_b_at_the_points_its_filters_keep(
    studies: dict[str, Path],
) -> None:
    """As the methods table's mean-hold rows: the cone program of the ablation against the
    shooting runs of the sweep's mean-hold point, on a row of their own."""
    result = _table(
        studies["methods"],
        studies["sweep"],
        "--versus",
        "hold",
        "--where",
        "hold:guidance.hold=mean",
        "--where",
        "guidance.hold=sample,mean",
        "--where",
        "arch=mtf_adaptive_socp",
        "--where",
        "other=mtf_adaptive",
        "--rows",
        "guidance.hold=shooting hold,arch=cone program,other=vs shooting",
        "--metric",
        "n,frac_less.miss,median_diff.miss",
    )
    lines = _lines(result)
    rows = [line.split(" | ") for line in lines[2:4]]
    assert [r[:3] for r in rows] == [
        ["| sample", "mtf_adaptive_socp", "mtf_adaptive"],  # the ablation's own pair
        ["| mean", "mtf_adaptive_socp", "mtf_adaptive"],  # against the sweep's mean hold
    ]
    runs = pd.concat(
        [
            pd.read_parquet(studies["methods"] / "runs.parquet").query(
                "arch == 'mtf_adaptive_socp'"
            ),
            pd.read_parquet(studies["sweep"] / "runs.parquet").query(
                "arch == 'mtf_adaptive' and `param.guidance.hold` == 'mean'"
            ),
        ]
    ).pivot_table(index="seed", columns="arch", values="miss_km")
    d = runs["mtf_adaptive_socp"] - runs["mtf_adaptive"]
    assert rows[1][3] == "3"
    assert rows[1][4].startswith(f"{(d < 0).mean():.3f} [")
    assert rows[1][5].startswith(f"{d.median() * 1e3:.2f} [")


def test_a_pair_across_campaigns_gives_the_applied_delta_v_difference(
    studies: dict[str, Path],
) -> None:
    """``mean_diff.dv_applied`` of a pair across campaigns (issue 33 item 3): the mean of
    A − B over the seeds, as the runs hold them [km/s]."""
    pair = "plain_adaptive-mtf_adaptive"
    result = _table(
        studies["methods"], studies["sweep"], "--versus", "methods",
        "--where", "hold:guidance.hold=sample", "--rows", "campaign,other_campaign",
        "--metric", f"n,mean_diff.dv_applied@{pair}",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    across = next(r.split(" | ") for r in _lines(result) if r.startswith("| hold"))
    sweep = pd.read_parquet(studies["sweep"] / "runs.parquet")
    a = sweep.query("arch == 'plain_adaptive' and `param.guidance.hold` == 'sample'")
    b = pd.read_parquet(studies["methods"] / "runs.parquet").query("arch == 'mtf_adaptive'")
    col = "delta_v_applied_km_s"
    d = a.set_index("seed")[col] - b.set_index("seed")[col]
    assert across[2] == "3"
    assert across[3].startswith(f"{d.mean():.5f} [")


@pytest.mark.parametrize(
    ("versus", "message"),
    [
        ("nope", "--versus 'nope': no campaign 'nope' (campaigns: two, methods)"),
        ("methods", "--versus methods: two ran 2 seed(s) 0–1 and methods 3 seed(s) 0–2"),
    ],
)
def test_a_bad_pair_across_campaigns_exits_2_saying_why(
    studies: dict[str, Path], tmp_path: Path, versus: str, message: str
) -> None:
    two = _campaign(tmp_path, "ablate", "two", "--arch", "mtf_adaptive", "--seeds", "2")
    result = _table(two, studies["methods"], "--versus", versus, "--metric", "frac_less.miss")
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    assert "Traceback" not in result.output


def test_a_marginal_row_beside_paired_ones_shows_no_pair(studies: dict[str, Path]) -> None:
    """A table of a marginal and a paired value: the marginal rows' ``vs`` is ``–`` (no
    pair), never ``nan`` (pandas 3's ``Series.map`` turned the None of a field into NaN)."""
    lines = _lines(_table(studies["methods"], "--metric", "mean.dv,mean_diff.dv"))
    assert lines[0].startswith("| architecture | vs | mean Δv")
    rows = [line.split(" | ") for line in lines[2:] if line.startswith("| ")]
    marginal = [r for r in rows if r[2] != "–"]
    assert len(marginal) == 4 and all(r[1] == "–" for r in marginal)
    assert "nan" not in "\n".join(lines)


@pytest.mark.parametrize(
    ("where", "metric", "message"),
    [
        (
            "other=mtf_adaptive",
            "n,mean.dv,frac_less.miss",
            "--where other=mtf_adaptive keeps no entry of --metric 'n', so its column would be "
            "empty: a value of one architecture's runs has no other",
        ),
        (
            "arch=mtf_adaptive_socp",
            "mean.dv,frac_less.miss@plain_adaptive-mtf_adaptive",
            "--where arch=mtf_adaptive_socp keeps no entry of --metric "
            "'frac_less.miss@plain_adaptive-mtf_adaptive', so its column would be empty",
        ),
    ],
)
def test_a_filter_that_empties_a_value_exits_2_naming_it(
    studies: dict[str, Path], where: str, metric: str, message: str
) -> None:
    """The value's column was left out of the table without a word."""
    result = _table(studies["methods"], "--where", where, "--metric", metric)
    assert result.exit_code == 2, result.output
    assert message in result.stderr
    assert "Traceback" not in result.output


# --- the Δv cost of a constrained plan over the unconstrained one (issue 32) ----------

#: 1 km above a 200 m keep-out sphere, the port below it (tests/test_safety_measured.py):
#: the unconstrained path crosses the zone. The twin flies to the same port at rest.
SAFE = SHORT
FREE = SHORT.split("[constraints")[0].replace(
    "[degradation]", "xf = [0.0, 0.0, -0.25, 0.0, 0.0, 0.0]\n[degradation]"
)


@pytest.fixture(scope="module")
def constrained_pair(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The constrained cone program and its unconstrained twin, seeds 0–2 each."""
    root = tmp_path_factory.mktemp("constrained_pair")
    out = {}
    for name, text in (("safe", SAFE), ("free", FREE)):
        cfg = root / f"{name}.toml"
        cfg.write_text(text + f'[output]\ndir = "{root / "results"}"\n', encoding="utf-8")
        args = ["ablate", str(cfg), "--name", name, "--seeds", "3", "-w", "1", "--no-rrd", "-q",
                "--arch", "mtf_adaptive_socp"]  # fmt: skip
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        out[name] = root / "results" / name
    return out


def test_the_delta_v_cost_of_the_constraints_is_a_pair_across_campaigns(
    constrained_pair: dict[str, Path],
) -> None:
    """``--versus`` the unconstrained twin: ``mean_diff.dv`` (and ``.dv_applied``) is the
    mean over the seeds of the constrained run's Δv minus the twin's [km/s], as the runs
    hold them (CSV: unrounded)."""
    safe, free = constrained_pair["safe"], constrained_pair["free"]
    result = _table(
        safe, free, "--versus", "free", "--where", "other_campaign=free",
        "--where", "campaign=safe", "--metric", "n,mean_diff.dv,mean_diff.dv_applied",
        "--format", "csv",
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    (row,) = list(csv.DictReader(io.StringIO(result.stdout)))
    a = pd.read_parquet(safe / "runs.parquet").set_index("seed")
    b = pd.read_parquet(free / "runs.parquet").set_index("seed")
    assert a["safety_violated"].sum() == 0 and "safety_violated" not in b  # the pair is real
    assert float(row["n"]) == 3
    for column, header in (
        ("delta_v_km_s", "mean Δv"),
        ("delta_v_applied_km_s", "mean applied Δv"),
    ):
        d = a[column] - b[column]
        assert float(row[f"{header} difference [km/s] (95 % CI)"]) == pytest.approx(
            d.mean(), rel=1e-12
        )
        assert (d > 0).all()  # going round the zone costs Δv in every seed


def test_a_constrained_campaigns_fuel_penalty_is_over_the_unconstrained_optimum(
    constrained_pair: dict[str, Path],
) -> None:
    """``mean.fuel`` / ``mean.fuel_applied`` of a constrained campaign compare each run with
    the open-loop fuel optimum of the *unconstrained* problem to the port: its stored
    references are those of the unconstrained twin, file for file."""
    safe, free = (constrained_pair[k] / "references" for k in ("safe", "free"))
    files = sorted(p.name for p in safe.glob("*.parquet"))
    assert files and files == sorted(p.name for p in free.glob("*.parquet"))
    for name in files:
        pd.testing.assert_frame_equal(pd.read_parquet(safe / name), pd.read_parquet(free / name))
    # and the runs' penalty is against that optimum's Δv (its 1 s trapezoid of ‖u‖)
    (fuel,) = [
        f for f in (pd.read_parquet(free / n) for n in files) if "fuel" in set(f["reference"])
    ]
    fuel = fuel[fuel["reference"] == "fuel"].sort_values("t_s")
    dv_fuel = float(np.trapezoid(fuel["u_norm_km_s2"], fuel["t_s"]))
    runs = pd.read_parquet(constrained_pair["safe"] / "runs.parquet")
    expected = 100.0 * (runs["delta_v_km_s"] / dv_fuel - 1.0)
    np.testing.assert_allclose(runs["fuel_penalty_pct"], expected, rtol=1e-12)


# --- values computed from the runs and their re-solves --------------------------------


@pytest.fixture(scope="module")
def fallbacks(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A sweep of plain fixed ε over the hold (infeasible re-solves), in which the
    re-solves of two runs are marked as ended by the plan of last resort (socp_plan):
    what ``:with=socp_plan`` keeps does not depend on which seeds needed it."""
    root = tmp_path_factory.mktemp("fallbacks")
    path = _campaign(
        root, "sweep", "fixed", "--param", "guidance.hold=sample,mean", "--arch", "plain_fixed"
    )
    for file in sorted((path / "solves").rglob("*.parquet"))[:2]:
        solves = pd.read_parquet(file)
        solves.loc[solves.index[-1], "fallback_step"] = "socp_plan"
        solves.to_parquet(file, index=False)
    return path


def test_the_fallbacks_table_counts_what_the_solves_hold(fallbacks: Path) -> None:
    """As the docs' fallbacks table: per hold, the ok runs, the re-solves failed and
    infeasible, the runs that used socp_plan and the worst miss with and without it."""
    result = _table(
        fallbacks,
        "--rows",
        "guidance.hold,arch",
        "--metric",
        "n,failed_solves,infeasible_solves,n:with=socp_plan,max.miss:with=socp_plan,"
        "max.miss:without=socp_plan",
    )
    lines = _lines(result)
    assert lines[0] == (
        "| hold | architecture | n | re-solves failed | re-solves infeasible | runs using "
        "socp_plan | max miss [m], runs using socp_plan | max miss [m], runs not using "
        "socp_plan |"
    )
    runs = pd.read_parquet(fallbacks / "runs.parquet")
    solves = pd.read_parquet(fallbacks / "solves")
    used = set(solves.loc[solves["fallback_step"] == "socp_plan", "run_key"])
    assert len(used) >= 2  # the two marked, and any run that needed the plan
    for line in lines[2:4]:
        cells = line.removeprefix("| ").removesuffix(" |").split(" | ")
        point = runs[runs["param.guidance.hold"] == cells[0]]
        mine = solves[solves["run_key"].isin(point["run_key"])]
        with_, without = point[point["run_key"].isin(used)], point[~point["run_key"].isin(used)]
        assert cells[2:6] == [
            str(len(point)),
            str(int((mine["status"] == "failed").sum())),
            str(int((mine["status"] == "infeasible").sum())),
            str(len(with_)),
        ]
        worst = [
            f"{1e3 * m.max():.2f}" if len(m) else "–"
            for m in (with_["miss_km"], without["miss_km"])
        ]
        assert cells[6:] == worst
    assert (solves["status"] == "infeasible").any()  # the counts are not all zero


def test_an_unknown_fallback_step_is_refused_with_the_steps(fallbacks: Path) -> None:
    result = _table(fallbacks, "--metric", "n:with=socp_paln")
    assert result.exit_code == 2
    assert "unknown fallback step 'socp_paln'" in result.stderr
    assert "did you mean 'socp_plan'?" in result.stderr


def test_with_keeps_runs_of_computed_values_only(fallbacks: Path) -> None:
    result = _table(fallbacks, "--metric", "mean.miss:with=socp_plan")
    assert result.exit_code == 2
    assert "not of a stored statistic" in result.stderr
