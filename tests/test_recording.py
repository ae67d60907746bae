"""Rerun recordings: read back with the SDK's own reader (issue 5, item 1)."""

from __future__ import annotations

import uuid
from collections import defaultdict
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from cwrend_cli import campaign
from cwrend_cli.campaign import CaseResult
from cwrend_cli.config import ALL_ARCHITECTURES, ARCHITECTURES, CwrendConfig
from cwrend_cli.config.adapt import windows_of
from cwrend_cli.output import recording

ARCH_ENTITIES = (
    "trajectory/true",
    "trajectory/estimate",
    "thrust",
    "u_norm",
    "dv_cum",
    "eps",
    "score",
    "score_filtered",
    "nis",
    "mtf_ratio",
    "pos_err_km",
    "est_err_km",
    "resolve_success",
)
REFERENCE_ENTITIES = ("trajectory", "u_norm", "dv_cum", "pos_err_km")


@pytest.fixture(scope="module")
def cfg() -> CwrendConfig:
    return CwrendConfig()


@pytest.fixture(scope="module")
def case(cfg: CwrendConfig) -> CaseResult:
    return campaign.run_case(cfg, tuple(ARCHITECTURES.values()), 0)


@pytest.fixture(scope="module")
def recording_id() -> str:
    return str(uuid.uuid4())


@pytest.fixture(scope="module")
def rrd(
    tmp_path_factory: pytest.TempPathFactory, cfg: CwrendConfig, case: CaseResult, recording_id: str
) -> Path:
    out = tmp_path_factory.mktemp("rrd") / "case.rrd"
    path = recording.record_case(
        out,
        case.runs,
        case.references,
        windows_of(cfg),
        recording_id=recording_id,
        u_max_km_s2=cfg.scenario.u_max_km_s2,
    )
    assert path == out
    return path


@pytest.fixture(scope="module")
def chunks(rrd: Path) -> dict[str, list]:
    """Chunks of the recording store by entity path."""
    by_path: dict[str, list] = defaultdict(list)
    for chunk in RrdReader(rrd).stream():
        by_path[chunk.entity_path].append(chunk)
    return by_path


def _temporal_rows(chunks: list) -> int:
    return sum(c.num_rows for c in chunks if not c.is_static)


def _scalars(chunks: list) -> tuple[np.ndarray, np.ndarray]:
    """(sim_time [s], value) of a Scalars series, sorted by time."""
    batches = [c.to_record_batch() for c in chunks if not c.is_static]
    batches = [b for b in batches if "Scalars:scalars" in b.schema.names]
    assert batches
    t = np.concatenate([b.column("sim_time").cast(pa.int64()).to_numpy() for b in batches]) / 1e9
    v = np.array([row[0] for b in batches for row in b.column("Scalars:scalars").to_pylist()])
    order = np.argsort(t, kind="stable")
    return t[order], v[order]


def test_one_recording_and_a_blueprint(rrd: Path, recording_id: str) -> None:
    reader = RrdReader(rrd)
    recordings = reader.recordings()
    assert len(recordings) == 1
    assert recordings[0].application_id == "cwrend"
    assert recordings[0].recording_id == recording_id
    blueprints = reader.blueprints()
    assert len(blueprints) == 1 and blueprints[0].application_id == "cwrend"
    assert sum(1 for _ in reader.stream(store=blueprints[0])) > 0


def test_blueprint_names_the_paper_views(rrd: Path) -> None:
    reader = RrdReader(rrd)
    text = []
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        for column in batch.columns:
            if pa.types.is_list(column.type) and pa.types.is_string(column.type.value_type):
                text += [s for row in column.to_pylist() if row for s in row]
    joined = "\n".join(text)
    for view in ("trajectories", "thrust ‖u‖", "homotopy ε", "score", "position error"):
        assert view in joined, view


def _blueprint_views(rrd: Path) -> dict[str, dict[str, pa.Array]]:
    """Blueprint of a recording: view id -> {"class": ..., "<Archetype>:<field>": value}.

    Values are the last logged component value (an Arrow array of one
    element, so unions keep their tags).
    """
    reader = RrdReader(rrd)
    views: dict[str, dict[str, pa.Array]] = defaultdict(dict)
    for chunk in reader.stream(store=reader.blueprints()[0]):
        parts = chunk.entity_path.strip("/").split("/")
        if parts[0] != "view" or len(parts) < 2:
            continue
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if ":" in name:
                column = batch.column(name)
                views[parts[1]][name] = column[len(column) - 1].values
    return views


def _is_infinite(boundary: pa.Array) -> bool:
    """A TimeRangeBoundary (dense union of one element) is the Infinite variant."""
    assert isinstance(boundary, pa.UnionArray) and len(boundary) == 1
    tag = boundary.type_codes[0].as_py()
    return bool(boundary.type.field(boundary.type.type_codes.index(tag)).name == "Infinite")


def test_every_time_series_view_shows_the_whole_run(rrd: Path) -> None:
    views = _blueprint_views(rrd)
    series = [
        v for v in views.values() if v["ViewBlueprint:class_identifier"][0].as_py() == "TimeSeries"
    ]
    assert len(series) == 9
    for view in series:
        name = view["ViewBlueprint:display_name"][0].as_py()
        ranges = view["VisibleTimeRanges:ranges"]  # queried data: the whole timeline
        assert len(ranges) == 1 and ranges[0]["timeline"].as_py() == "sim_time", name
        bounds = ranges.field("range")
        assert _is_infinite(bounds.field("start")) and _is_infinite(bounds.field("end")), name
        axis = view["TimeAxis:view_range"]  # the x axis shown: the whole timeline too
        assert _is_infinite(axis.field("start")) and _is_infinite(axis.field("end")), name


def test_time_series_views_have_no_legend_over_the_data(rrd: Path) -> None:
    views = _blueprint_views(rrd)
    series = [
        v for v in views.values() if v["ViewBlueprint:class_identifier"][0].as_py() == "TimeSeries"
    ]
    assert series and all(v["PlotLegend:visible"].to_pylist() == [False] for v in series)
    about = [c for c in RrdReader(rrd).stream() if c.entity_path == "/about"]
    text = about[0].to_record_batch().column("TextDocument:text").to_pylist()[0][0]
    for key in ("| green | mtf_adaptive |", "| red | plain_fixed |", "| grey | open-loop fuel |"):
        assert key in text  # the colours are explained once


def test_3d_view_is_framed_on_the_trajectories_and_the_target(rrd: Path, case: CaseResult) -> None:
    views = _blueprint_views(rrd)
    (spatial,) = [
        v for v in views.values() if v["ViewBlueprint:class_identifier"][0].as_py() == "3D"
    ]
    lo, hi = recording.scene_bounds(case.runs, case.references)
    assert np.all(lo <= 0.0) and np.all(hi >= 0.0)  # the target is in the box
    target = np.array(spatial["EyeControls3D:look_target"][0].as_py())
    np.testing.assert_allclose(target, 0.5 * (lo + hi), rtol=1e-6, atol=1e-6)
    eye = np.array(spatial["EyeControls3D:position"][0].as_py())
    distance = float(np.linalg.norm(eye - target))
    assert float(np.max(hi - lo)) <= distance <= 2.0 * float(np.max(hi - lo))


def test_no_text_labels_on_the_paths_in_3d(chunks: dict[str, list]) -> None:
    labelled = {
        path
        for path, cs in chunks.items()
        for c in cs
        if any(n.endswith(":labels") for n in c.to_record_batch().schema.names)
    }
    assert labelled == {"/target"}


def test_expected_entity_paths(chunks: dict[str, list], case: CaseResult) -> None:
    for run in case.runs:
        for name in ARCH_ENTITIES:
            assert f"/arch/{run.arch}/{name}" in chunks, f"/arch/{run.arch}/{name}"
    for ref in ("energy", "fuel"):
        for name in REFERENCE_ENTITIES:
            assert f"/reference/{ref}/{name}" in chunks
    assert "/target" in chunks
    assert "/degradation/1" in chunks and "/degradation/2" in chunks


def test_time_series_are_on_sim_time(chunks: dict[str, list]) -> None:
    temporal = [c for cs in chunks.values() for c in cs if not c.is_static]
    assert temporal
    for c in temporal:
        assert list(c.timeline_names) == ["sim_time"], (c.entity_path, c.timeline_names)


def test_sample_counts(chunks: dict[str, list], case: CaseResult) -> None:
    for run in case.runs:
        base = f"/arch/{run.arch}"
        for name in ("u_norm", "dv_cum", "eps", "pos_err_km", "est_err_km", "thrust"):
            assert _temporal_rows(chunks[f"{base}/{name}"]) == 801, name
        assert _temporal_rows(chunks[f"{base}/trajectory/true"]) == 801
        # no measurement at t = 0: the NaN sample is left out
        assert _temporal_rows(chunks[f"{base}/nis"]) == 800
        assert _temporal_rows(chunks[f"{base}/resolve_success"]) == len(run.resolves)


def test_scalar_values_round_trip(chunks: dict[str, list], case: CaseResult) -> None:
    run = case.runs[-1]
    t, u = _scalars(chunks[f"/arch/{run.arch}/u_norm"])
    np.testing.assert_allclose(t, run.t_s)
    np.testing.assert_allclose(u, np.linalg.norm(run.u, axis=1))
    _, dv = _scalars(chunks[f"/arch/{run.arch}/dv_cum"])
    assert dv[-1] == pytest.approx(run.delta_v_km_s, rel=1e-12)
    t_w, active = _scalars(chunks["/degradation/1"])
    assert set(np.unique(active)) == {0.0, 1.0}
    assert t_w[active == 1.0].min() == 250.0 and t_w[active == 1.0].max() == 325.0


def test_write_is_atomic_and_replaces(tmp_path: Path, cfg: CwrendConfig, case: CaseResult) -> None:
    target = tmp_path / "r.rrd"
    target.write_bytes(b"old")
    recording.record_case(target, case.runs[:1], case.references, windows_of(cfg))
    assert target.read_bytes()[:4] != b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.rrd"]  # no temp file left
    paths = {c.entity_path for c in RrdReader(target).stream()}
    assert any(p.startswith(f"/arch/{case.runs[0].arch}/") for p in paths)
    assert not any(p.startswith(f"/arch/{case.runs[1].arch}/") for p in paths)


def test_fresh_recording_id_by_default(tmp_path: Path, cfg: CwrendConfig, case: CaseResult) -> None:
    ids = set()
    for name in ("a.rrd", "b.rrd"):
        path = recording.record_case(
            tmp_path / name, case.runs[:1], case.references, windows_of(cfg)
        )
        ids.add(RrdReader(path).recordings()[0].recording_id)
    assert len(ids) == 2


def test_disabled_rerun_is_a_user_error(
    tmp_path: Path, cfg: CwrendConfig, case: CaseResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("RERUN", "off")
    with pytest.raises(recording.RecordingError, match="RERUN"):
        recording.record_case(tmp_path / "x.rrd", case.runs[:1], case.references, windows_of(cfg))
    assert not (tmp_path / "x.rrd").exists()


@pytest.mark.parametrize(
    "value", ["off", "OFF", "Off", "0", "false", "FALSE", " off", "on", "1", "", "no", None]
)
def test_the_early_check_reads_rerun_as_rerun_does(
    value: str | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``check_enabled`` (no rerun import) refuses exactly when Rerun's own streams are off."""
    import rerun as rr

    if value is None:
        monkeypatch.delenv("RERUN", raising=False)
    else:
        monkeypatch.setenv("RERUN", value)
    rerun_enabled = rr.is_enabled(rr.RecordingStream("cwrend-test"))
    try:
        recording.check_enabled()
        refused = False
    except recording.RecordingError:
        refused = True
    assert refused == (not rerun_enabled)


def test_rgb_of_hex() -> None:
    assert recording.rgb("#1f77b4") == (31, 119, 180)


def test_every_architecture_has_its_own_fixed_colour() -> None:
    """All twelve slugs (the paper's eight and the single-factor four, issue 35) get a fixed,
    named colour, none shared with another architecture, a reference or the windows."""
    colours = [recording.ARCH_COLOURS.get(slug) for slug in ALL_ARCHITECTURES]
    assert None not in colours
    assert set(recording.ARCH_COLOURS) == set(ALL_ARCHITECTURES)
    others = {*recording.REFERENCE_COLOURS.values(), recording.DEGRADATION_COLOUR}
    assert len(set(colours) | others) == len(colours) + len(others)
    assert all(c in recording.COLOUR_NAMES for c in colours)


def test_no_viewer_without_display(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(recording.shutil, "which", lambda name: None)
    assert recording.open_in_viewer(tmp_path / "x.rrd") is False


def _view_names(container: object, names: list[str]) -> list[str]:
    """Names of every view and container under ``container`` of a blueprint, depth first."""
    name = getattr(container, "name", None)
    if name:
        names.append(name)
    for sub in getattr(container, "contents", None) or []:
        _view_names(sub, names)
    return names


@pytest.mark.parametrize(
    ("slugs", "title"),
    [
        (["mtf_fixed", "plain_fixed"], "MTF ratio ρ [-]"),
        (["stf_adaptive"], "single-factor ratio ρ [-]"),
        (["stf_fixed", "mtf_adaptive"], "inflation ratio ρ [-]"),
    ],
)
def test_ratio_view_names_the_ratio_its_estimators_log(slugs: list[str], title: str) -> None:
    """The steps' ``mtf_ratio`` of a single-factor run is (λ − 1) tr(R)/tr(S), not the MTF
    ratio of paper Eq. 23: the recording's view says which ratio it shows, as Fig. 4 does."""
    from cwrend_cli.output.recording import build_blueprint

    names = _view_names(build_blueprint(slugs, [], 0).root_container, [])
    assert title in names
