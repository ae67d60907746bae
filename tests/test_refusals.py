"""Inputs that must be refused at once: exit 2, the field named, nothing written (issue 36, 7-11).

Each case used to run for a minute or more, take gigabytes, record runs ``ok`` with
infinite statistics or end in a traceback. Here each is fed to the command line
in-process, in an empty working directory with the results root inside it, and
the test checks exit code 2, the message (which names the field or option), no
traceback and that nothing was written. Time and memory are not asserted (no
test depends on the machine's speed): ``tests/measure_refusals.py`` runs the same
cases in child processes and reports each one's wall time and peak memory.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from cwrend_cli.cli import app
from cwrend_cli.config import overrides
from cwrend_cli.config.io import load_noise_file
from cwrend_cli.config.schema import CwrendConfig, ScheduleConfig
from cwrend_cli.errors import InputDataError

PAPER = Path(__file__).resolve().parents[1] / "campaigns" / "paper.toml"
BIG = "1e308"
runner = CliRunner()

#: A case: its command line from the working directory, and a text the error must hold.
Setup = Callable[[Path], list[str]]


def _ablate(*sets: str) -> Setup:
    """``cwrend ablate`` of the paper campaign with ``--set`` overrides."""
    return lambda d: ["ablate", str(PAPER), *[a for s in sets for a in ("--set", s)]]


CASES: dict[str, tuple[Setup, str]] = {
    # item 7: absurd finite values
    "p0 of 1e308": (
        _ablate(f"estimator.p0=[{BIG}, 1e-6, 1e-6, 1e-10, 1e-10, 1e-10]"),
        "estimator.p0 = [1e+308, ",
    ),
    "a full-matrix p0 of 1e308": (
        _ablate(
            "estimator.p0=["
            + ", ".join(
                "[" + ", ".join(BIG if i == j else "0" for j in range(6)) + "]" for i in range(6)
            )
            + "]"
        ),
        "diagonal entry 0 = 1e+308 must be in [1e-30, 100000000] km²",
    ),
    "r_nominal_km2 of 1e308": (
        _ablate(f"estimator.r_nominal_km2=[{BIG}, {BIG}, {BIG}]"),
        "estimator.r_nominal_km2 = ",
    ),
    "q_process of 1e308": (
        _ablate(f"estimator.q_process=[1e-12, 1e-12, 1e-12, {BIG}, 1e-14, 1e-14]"),
        "diagonal entry 3 = 1e+308 must be in [1e-30, 100] km/s²",
    ),
    "a window's bias_km of 1e308": (
        _ablate(f"degradation.windows.1.bias_km=[{BIG}, 0.0, 0.0]"),
        "degradation.windows.1.bias_km.0 = 1e+308: must be <= 10000",
    ),
    "initial_error of 1e308": (
        _ablate(f"estimator.initial_error=[{BIG}, 0, 0, 0, 0, 0]"),
        "estimator.initial_error.0 = 1e+308: must be <= 10000",
    ),
    "an initial velocity of 1e308": (
        _ablate(f"scenario.x0.4={BIG}"),
        "scenario.x0.4 = 1e+308: must be <= 10",
    ),
    "r_scale of 1e308": (
        _ablate(f"degradation.windows.0.r_scale={BIG}"),
        "degradation.windows.0.r_scale = 1e+308: must be <= 1000000",
    ),
    "beta of 1e308": (_ablate(f"schedule.beta={BIG}"), "schedule.beta = 1e+308: must be <= 1000"),
    "kappa_mtf of 1e308": (_ablate(f"schedule.kappa_mtf={BIG}"), "schedule.kappa_mtf = 1e+308"),
    "score_max of 1e308": (_ablate(f"schedule.score_max={BIG}"), "schedule.score_max = 1e+308"),
    "t_resolve_s of 1e308": (
        _ablate(f"guidance.t_resolve_s={BIG}"),
        "guidance.t_resolve_s = 1e+308: must be <= 1000000",
    ),
    "max_iter of 10**12": (
        _ablate("solver.max_iter=1000000000000"),
        "solver.max_iter = 1000000000000: must be <= 1000",
    ),
    "run_timeout_s of 1e308": (
        _ablate(f"output.run_timeout_s={BIG}"),
        "output.run_timeout_s = 1e+308: must be <= 86400",
    ),
    "u_max of 1e308": (_ablate(f"scenario.u_max_km_s2={BIG}"), "scenario.u_max_km_s2 = 1e+308"),
    # item 8: seeds past int64, deep values, indices that are not ASCII digits
    "cwrend run --seed 2**63": (
        lambda d: ["run", str(PAPER), "--no-rrd", "--seed", str(2**63)],
        "--seed",
    ),
    "cwrend report --seed 2**63": (
        lambda d: ["report", str(d), "--seed", str(2**63)],
        "--seed",
    ),
    "--samples 2**70": (
        lambda d: ["sweep", str(PAPER), "--design", "lhs", "--samples", str(2**70)],
        "--samples",
    ),
    "a --set value nested 3,000 deep": (
        _ablate("schedule.beta=" + "[" * 3000 + "]" * 3000),
        "schedule.beta = …: the value's tables and arrays nest more than 16 levels deep",
    ),
    "a --param value nested 3,000 deep": (
        lambda d: ["sweep", str(PAPER), "--param", "schedule.beta=" + "{a=" * 3000 + "}" * 3000],
        "nest more than 16 levels deep",
    ),
    "a superscript index": (
        _ablate("degradation.windows.\u00b2.r_scale=2"),
        "degradation.windows: is an array, use an index of at most 6 ASCII digits",
    ),
    "a 5,000-digit index": (
        _ablate("degradation.windows." + "1" * 5000 + ".r_scale=2"),
        "degradation.windows: is an array, use an index of at most 6 ASCII digits",
    ),
    # item 11: a [sweep] of thousands of keys
    "a [sweep] of 2,000 keys": (
        lambda d: [
            "sweep",
            _write(d / "wide.toml", "[sweep]\n" + "".join(f"a{i} = [1]\n" for i in range(2000))),
        ],
        'sweep = {"a0": [1], ',
    ),
    # a port typed in metres: the message names the unreachable position and the port
    "a port out of reach": (
        lambda d: [
            "run",
            str(PAPER.with_name("safe_approach.toml")),
            "--no-rrd",
            "--arch",
            "mtf_adaptive_socp",
            "--set",
            "constraints.corridor.port_km=[0, 0, -250]",
        ],
        "reaches scenario.xf (position [0, 0, -250] km; with a corridor, "
        "constraints.corridor.port_km at rest)",
    ),
    # item 9: a noise file far larger than its rows can take
    "a sparse 100 MiB noise file": (
        lambda d: [
            "ablate",
            str(PAPER),
            "--set",
            f"noise.file={_sparse(d / 'n.csv', 100 << 20)!r}",
        ],
        # after the path, which the message shortens past 80 characters (a temporary
        # directory's length varies: an xdist worker's is longer)
        ": 104,857,600 bytes; a noise file of 800 rows (one per step, horizon_s / dt_s) "
        "is at most 1,867,776 bytes",
    ),
}


def _sparse(path: Path, size: int) -> str:
    """A noise file of one row and ``size`` bytes, all but its first line a hole."""
    path.write_text("n1,n2,n3\n0,0,0\n")
    os.truncate(path, size)
    return str(path)


def _write(path: Path, text: str) -> str:
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("case", list(CASES))
def test_an_absurd_input_is_refused_at_once(
    case: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    setup, message = CASES[case]
    monkeypatch.chdir(tmp_path)
    args = setup(tmp_path)
    if args[0] in ("ablate", "sweep"):
        args += ["--set", f"output.dir={str(tmp_path / 'results')!r}"]
    before = set(os.listdir(tmp_path))
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert message in result.stderr, result.stderr
    assert "Traceback" not in result.output
    assert set(os.listdir(tmp_path)) == before  # nothing written, not even a results dir


def test_a_sweep_of_too_many_keys_names_the_limit(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "wide.toml", "[sweep]\n" + "".join(f"a{i} = [1]\n" for i in range(2000))
    )
    result = runner.invoke(app, ["sweep", path])
    assert result.exit_code == 2, result.output
    assert ": at most 1,000 keys (got 2,000)" in result.stderr


def test_thousands_of_problems_list_the_first_twenty_and_a_count(tmp_path: Path) -> None:
    keys = "".join(f"a{i} = 1\n" for i in range(2000))
    result = runner.invoke(
        app, ["config", "validate", _write(tmp_path / "u.toml", "[schedule]\n" + keys)]
    )
    assert result.exit_code == 2, result.output
    lines = result.stderr.splitlines()
    assert lines[1:21] == [
        f"  schedule.a{i}: unknown key (allowed: {', '.join(ScheduleConfig.model_fields)})"
        for i in range(20)
    ]
    assert lines[21:] == ["  … and 1,980 more (2,000 in all)"]


def test_setting_keys_copies_the_tree_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 36 item 11: each key of a [sweep] copied the whole tree (quadratic: 350 s)."""
    copies: list[object] = []
    real = overrides._thaw

    def counted(value: object) -> object:
        copies.append(value)
        return real(value)

    monkeypatch.setattr(overrides, "_thaw", counted)
    base = {"schedule": {"beta": 0.25}, "sweep": {}}

    def whole_tree_copies(n: int) -> int:
        copies.clear()
        overrides.apply(base, [(f"schedule.k{i}", 1.0) for i in range(n)])
        return sum(isinstance(c, dict) and "schedule" in c for c in copies)

    assert whole_tree_copies(10) == whole_tree_copies(100) == 1


def test_a_parquet_noise_file_of_the_wrong_length_is_refused_from_its_footer(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A few kB of Parquet can hold 10**8 rows of zeros: its rows are counted, not decoded."""
    path = tmp_path / "n.parquet"
    zeros = pa.array(np.zeros(100_000))
    pq.write_table(pa.table({"n1": zeros, "n2": zeros, "n3": zeros}), path)

    def decoded(*args: object, **kwargs: object) -> None:
        raise AssertionError("the rows were decoded")

    monkeypatch.setattr(pd, "read_parquet", decoded)
    with pytest.raises(InputDataError, match="has 100000 rows, expected 800"):
        load_noise_file(path, 800)


def _unbounded(schema: dict[str, Any], path: str) -> list[str]:
    """The numbers under ``schema`` (a JSON schema) without an upper bound, by path."""
    if "anyOf" in schema:
        return [p for s in schema["anyOf"] for p in _unbounded(s, path)]
    if schema.get("type") in ("number", "integer"):
        bounded = "maximum" in schema or "exclusiveMaximum" in schema
        return [] if bounded else [path]
    if schema.get("type") == "array":
        items = schema.get("items")
        found = [
            p
            for i, s in enumerate(schema.get("prefixItems", []))
            for p in _unbounded(s, f"{path}.{i}")
        ]
        return found + (_unbounded(items, f"{path}[]") if isinstance(items, dict) else [])
    return []


def test_every_number_of_the_configuration_has_an_upper_bound() -> None:
    """Item 7: each bound is in the schema, where the configuration reference shows it."""
    definitions = CwrendConfig.model_json_schema()["$defs"]
    unbounded = [
        path
        for name, model in definitions.items()
        for field, schema in model.get("properties", {}).items()
        if "diagonal_maximum" not in schema  # a covariance: its diagonal's bounds, each entry's
        for path in _unbounded(schema, f"{name}.{field}")
    ]
    assert unbounded == []


@pytest.mark.parametrize("command", ["run", "ablate", "sweep"])
def test_an_architecture_named_twice_is_refused(
    command: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``cwrend run --arch a,a`` printed each of a's rows twice; one check (the parsing of
    --arch) refuses it for every command, naming the list to write instead."""
    monkeypatch.chdir(tmp_path)
    arch = "mtf_adaptive,plain_fixed,mtf_adaptive"
    extra = ["--no-rrd"] if command == "run" else ["--set", f"output.dir={str(tmp_path)!r}"]
    result = runner.invoke(app, [command, str(PAPER), "--arch", arch, *extra])
    assert result.exit_code == 2, result.output
    assert (
        f"--arch '{arch}': mtf_adaptive is named twice; name each architecture once: "
        "--arch mtf_adaptive,plain_fixed"
    ) in " ".join(result.stderr.split())
    assert "Traceback" not in result.output
    assert os.listdir(tmp_path) == []  # nothing written
