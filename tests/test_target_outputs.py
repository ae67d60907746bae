"""A tumbling target is logged (issue 34 item 1): its attitude and body rates in the steps
and its body axes turning in the recording; a fixed target adds nothing."""

from __future__ import annotations

from collections import defaultdict
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rerun.chunk import RrdReader

from cwrend_cli import campaign
from cwrend_cli.config import ARCHITECTURES
from cwrend_cli.config.adapt import problem_of, windows_of
from cwrend_cli.config.io import config_from_dict
from cwrend_cli.output import recording, tables
from cwrend_cli.physics import attitude

SHORT: dict[str, Any] = {
    "scenario": {"horizon_s": 200.0, "x0": [0.0, 0.02, 1.0, 0.0, 0.0, 0.0]},
    "degradation": {"windows": []},
}
TUMBLING = {
    **SHORT,
    "target": {
        "attitude": "tumbling",
        "initial_quaternion": [0.9, 0.1, -0.3, 0.2],
        "body_rates_deg_s": [1.0, 9.5, 2.0],
        "inertia": [1.0, 1.7, 2.2],
    },
}
COLUMNS = [f"target_q{i}" for i in range(4)] + [f"target_w{a}_deg_s" for a in "xyz"]


@cache
def _case(tumbling: bool) -> campaign.CaseResult:
    cfg = config_from_dict(TUMBLING if tumbling else SHORT)
    return campaign.run_case(cfg, (ARCHITECTURES["mtf_fixed"],), 0)


def test_the_steps_of_a_tumbling_target_hold_its_attitude_and_rates() -> None:
    run = _case(True).runs[0]
    table = tables.steps_table(run).to_pandas()
    model = attitude.attitude_model(problem_of(config_from_dict(TUMBLING)).target, 0.00104218449)
    expected = attitude.target_attitude(model, 200, 1.0)
    q, w = expected.at_steps()
    np.testing.assert_array_equal(table[COLUMNS[:4]].to_numpy(), q)
    np.testing.assert_array_equal(table[COLUMNS[4:]].to_numpy(), np.degrees(w))


def test_the_campaign_steps_of_a_tumbling_target_hold_them_too() -> None:
    run = _case(True).runs[0]
    table = tables.campaign_steps_table([run], {"run_key": ["k"], "point": ["p"]})
    assert table.column_names[-2:] == ["run_key", "point"]
    assert set(COLUMNS) <= set(table.column_names)


@pytest.mark.parametrize("kind", ["run", "campaign"])
def test_a_fixed_target_adds_no_column(kind: str) -> None:
    run = _case(False).runs[0]
    if kind == "run":
        names = tables.steps_table(run).column_names
    else:
        names = tables.campaign_steps_table([run], {"run_key": ["k"], "point": ["p"]}).column_names
    assert not [c for c in names if c.startswith("target_")]


def _chunks(tmp_path: Path, tumbling: bool) -> dict[str, list[Any]]:
    case = _case(tumbling)
    cfg = config_from_dict(TUMBLING if tumbling else SHORT)
    path = recording.record_case(tmp_path / "case.rrd", case.runs, case.references, windows_of(cfg))
    by_path: dict[str, list[Any]] = defaultdict(list)
    for chunk in RrdReader(path).stream():
        by_path[chunk.entity_path].append(chunk)
    return by_path


def test_a_recording_turns_the_body_axes_of_a_tumbling_target(tmp_path: Path) -> None:
    chunks = _chunks(tmp_path, True)
    assert "/target/body/axes" in chunks
    rows = sum(c.num_rows for c in chunks["/target/body"])
    assert rows == 201  # a quaternion at every step


def test_a_recording_of_a_fixed_target_has_no_body(tmp_path: Path) -> None:
    assert not [p for p in _chunks(tmp_path, False) if p.startswith("/target/body")]


@pytest.mark.parametrize("history", ["x_true", "x_hat", "u", "eps"])
def test_a_tumbling_target_flies_the_chaser_as_a_fixed_one(history: str) -> None:
    """Nothing of the chaser reads the attitude yet: every number of its run is the same."""
    np.testing.assert_array_equal(
        getattr(_case(True).runs[0], history), getattr(_case(False).runs[0], history)
    )
