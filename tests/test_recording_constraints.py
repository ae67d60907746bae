"""A recording of a constrained case draws the keep-out zone, the corridor and the
distance to the unsafe set (issue 32 item 4); one without constraints draws none."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from cwrend_cli import campaign
from cwrend_cli.config import ARCHITECTURES
from cwrend_cli.config.adapt import windows_of
from cwrend_cli.config.io import config_from_dict
from cwrend_cli.output import recording

SHORT = {
    "scenario": {"horizon_s": 200.0, "x0": [0.0, 0.02, 1.0, 0.0, 0.0, 0.0]},
    "degradation": {"windows": []},
}
CONSTRAINTS = {
    "keep_out": {"semi_axes_km": [0.2, 0.2, 0.2]},
    "corridor": {"port_km": [0.0, 0.0, -0.25], "axis": [0.0, 0.0, -1.0], "half_angle_deg": 30.0},
}


def _chunks(tmp_path: Path, tree: dict[str, object]) -> dict[str, list[object]]:
    cfg = config_from_dict(tree)
    case = campaign.run_case(cfg, (ARCHITECTURES["mtf_fixed"],), 0)
    path = recording.record_case(tmp_path / "case.rrd", case.runs, case.references, windows_of(cfg))
    by_path: dict[str, list[object]] = defaultdict(list)
    for chunk in RrdReader(path).stream():
        by_path[chunk.entity_path].append(chunk)
    return by_path


@pytest.mark.parametrize(
    "entity",
    [
        "/constraints/keep_out",
        "/constraints/corridor",
        "/arch/mtf_fixed/safety_distance_km",
        "/arch/mtf_fixed/trajectory/unsafe",
    ],
)
def test_a_constrained_recording_draws_the_constraints(tmp_path: Path, entity: str) -> None:
    chunks = _chunks(tmp_path, {**SHORT, "constraints": CONSTRAINTS})
    assert entity in chunks


def test_a_recording_without_constraints_draws_none(tmp_path: Path) -> None:
    chunks = _chunks(tmp_path, SHORT)
    assert not [p for p in chunks if p.startswith("/constraints") or "safety" in p]
    assert "/arch/mtf_fixed/trajectory/unsafe" not in chunks


def test_a_tumbling_targets_constraints_are_drawn_in_its_turning_body(tmp_path: Path) -> None:
    """Issue 34: the bodies and the corridor under ``/target/body`` (which carries the
    attitude), every ellipsoid drawn, none left still in the relative frame."""
    bodies = [{"centre_km": [0.0, 0.3, 0.0], "semi_axes_km": [0.01, 0.08, 0.05]}]
    tree = {
        **SHORT,
        "target": {"attitude": "tumbling", "body_rates_deg_s": [0.0, 0.0, 2.0]},
        "constraints": {**CONSTRAINTS, "keep_out": {**CONSTRAINTS["keep_out"], "bodies": bodies}},
    }
    chunks = _chunks(tmp_path, tree)
    assert "/target/body/constraints/keep_out" in chunks
    assert "/target/body/constraints/corridor" in chunks
    assert not [p for p in chunks if p.startswith("/constraints")]
    table = chunks["/target/body/constraints/keep_out"][0].to_record_batch()
    sizes = [c for c in table.schema.names if "half_size" in c.lower()]
    assert len(table.column(sizes[0])[0]) == 2  # the centred ellipsoid and the panel
