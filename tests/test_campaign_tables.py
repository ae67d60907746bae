"""The campaign ``steps``/``solves`` tables of a task (issue 17: few allocations per run).

A task's table is built once from its runs' stacked arrays; it must hold
exactly what each run's own table holds, one run after another, without
``arch`` (the partition key) and with each run's ``run_key`` and ``point``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from cwrend_cli.campaign import standard_normal_for
from cwrend_cli.config import ARCHITECTURES, CwrendConfig
from cwrend_cli.config.adapt import problem_of
from cwrend_cli.output.tables import (
    CAMPAIGN_SOLVES_SCHEMA,
    CAMPAIGN_STEPS_SCHEMA,
    campaign_solves_table,
    campaign_steps_table,
    row_norm,
    solves_table,
    steps_table,
)
from cwrend_cli.physics import simulation

META = {"config_hash": "c0ffee", "campaign_hash": "beef"}


@pytest.fixture(scope="module")
def runs(paper_cfg: CwrendConfig, paper_refs: simulation.References) -> list[simulation.RunResult]:
    """Three runs of different seeds and architectures (adaptive and fixed ε)."""
    problem = problem_of(paper_cfg)
    return [
        simulation.simulate(
            problem, ARCHITECTURES[arch], standard_normal_for(paper_cfg, seed), paper_refs, seed
        )
        for arch, seed in (("mtf_adaptive", 0), ("plain_fixed", 1), ("mtf_adaptive", 5))
    ]


def _per_run(
    results: list[simulation.RunResult],
    table_of: Callable[[simulation.RunResult], pa.Table],
    extra: dict[str, list[str]],
    schema: pa.Schema,
) -> pa.Table:
    """Each run's own table, ``arch`` dropped and ``extra`` appended, one after another."""
    parts = []
    for i, result in enumerate(results):
        table = table_of(result).drop_columns(["arch"])
        for name, values in extra.items():
            table = table.append_column(name, pa.array([values[i]] * table.num_rows, pa.string()))
        parts.append(table.replace_schema_metadata(None).cast(schema))
    return pa.concat_tables(parts)


def _extra(results: list[simulation.RunResult]) -> dict[str, list[str]]:
    return {
        "run_key": [f"base.{r.arch}.s{r.seed}" for r in results],
        "point": ["base"] * len(results),
    }


def test_campaign_steps_table_holds_each_runs_steps_in_turn(
    runs: list[simulation.RunResult],
) -> None:
    table = campaign_steps_table(runs, _extra(runs), META)
    expected = _per_run(runs, steps_table, _extra(runs), CAMPAIGN_STEPS_SCHEMA)
    assert table.schema.remove_metadata().equals(CAMPAIGN_STEPS_SCHEMA.remove_metadata())
    pd.testing.assert_frame_equal(table.to_pandas(), expected.to_pandas(), check_exact=True)


def test_campaign_solves_table_holds_each_runs_solves_in_turn(
    runs: list[simulation.RunResult],
) -> None:
    table = campaign_solves_table(runs, _extra(runs), META)
    expected = _per_run(runs, solves_table, _extra(runs), CAMPAIGN_SOLVES_SCHEMA)
    assert table.schema.remove_metadata().equals(CAMPAIGN_SOLVES_SCHEMA.remove_metadata())
    pd.testing.assert_frame_equal(table.to_pandas(), expected.to_pandas(), check_exact=True)


def test_row_norm_is_numpys_row_norm_bit_for_bit() -> None:
    rng = np.random.default_rng(17)
    v = rng.standard_normal((200_000, 3)) * np.exp(rng.uniform(-300, 300, (200_000, 3)))
    special = [0.0, -0.0, np.inf, -np.inf, np.nan, 5e-324, 1e-160, 1e154, 1e308, -3.0, 4.0]
    v[: len(special) ** 2, 0] = np.repeat(special, len(special))
    v[: len(special) ** 2, 1] = np.tile(special, len(special))
    with np.errstate(over="ignore", invalid="ignore"):
        expected = np.linalg.norm(v, axis=1)
        got = row_norm(*np.ascontiguousarray(v.T))
    np.testing.assert_array_equal(got.view(np.int64), expected.view(np.int64))
