"""The viz conversion core on the synthetic fixture recording: what the .rrd holds, read back with
the Rerun SDK (entities, row counts, timelines, colours), `rerun rrd verify`, and bad input."""

from __future__ import annotations

import logging
import subprocess
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from schemas import TOPICS, DemoTick, Header
from services.recorder.inspect import read_info
from services.viz import Settings, paths
from services.viz.core import Converter
from services.viz.offline import ViewReport, convert, recording_id
from services.viz.out import Out
from services.viz.sink import open_stream, rerun_executable
from tests.fixtures import viz_recording as fx

FRAMES, TICKS = fx.FRAMES, fx.TICKS


@pytest.fixture(autouse=True)
def strict_rerun() -> Iterator[None]:
    """Any Rerun warning (a bad argument to an archetype) fails the test."""
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(False)


def to_rrd(src: Path, out: Path, **settings: Any) -> ViewReport:
    s = Settings(**settings)
    info = read_info(src)
    rec = open_stream(s, recording_id(info), out)
    report = convert(src, rec, s, info=info)
    rec.flush()
    rec.disconnect()
    return report


def read_rrd(path: Path) -> tuple[Counter[str], dict[str, set[str]], list[Any]]:
    """Temporal rows per entity, column names per entity (static included), temporal chunks."""
    rows: Counter[str] = Counter()
    columns: dict[str, set[str]] = {}
    temporal = []
    for chunk in RrdReader(path).stream():
        columns.setdefault(chunk.entity_path, set()).update(
            f.name for f in chunk.to_record_batch().schema
        )
        if not chunk.is_static:
            rows[chunk.entity_path] += chunk.num_rows
            temporal.append(chunk)
    return rows, columns, temporal


@pytest.fixture(scope="module")
def fixture_rrd(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, ViewReport]:
    out = tmp_path_factory.mktemp("viz") / "fixture.rrd"
    rr.set_strict_mode(True)
    return out, to_rrd(fx.PATH, out, depth_max_rate_hz=5.0)


def test_rrd_holds_every_drawing_with_the_expected_counts(
    fixture_rrd: tuple[Path, ViewReport],
) -> None:
    out, report = fixture_rrd
    rows, columns, _ = read_rrd(out)
    depth_frames = len(range(0, FRAMES, 3))  # 5 Hz of a 15 Hz camera
    expected = {
        paths.CAMERA: FRAMES,
        paths.IMAGE: FRAMES,
        paths.RGB: FRAMES,
        paths.DEPTH: depth_frames,
        paths.TRUNK_MASK: depth_frames,
        paths.DETECTIONS: FRAMES,
        paths.TRACKS: FRAMES,
        paths.TRUTH_BOXES: FRAMES,
        paths.FRUITS: FRAMES,
        paths.OBSTACLE_TRUNK: FRAMES,
        paths.TRUTH_FRUITS: FRAMES,
        f"{paths.JOINTS}/cutter_j1": TICKS // 2,  # poses at 50 Hz of 100 Hz
        f"{paths.JOINTS}/collector_j7": TICKS // 2,
        f"{paths.JOINT_VELOCITY}/cutter": TICKS,
        f"{paths.ERRORS}/abs_position_m": TICKS,
        f"{paths.DISTANCES}/fruit_m": 95,  # the controller had no fruit distance for 5 ticks
        paths.D_S: TICKS,
        paths.LOG_HARVEST: 8,
        paths.LOG_SIM: 2,
        paths.LOG_TOOL: 1,
        paths.LOG_RUN: 1,
        f"{paths.PLAN}/target": 2,
        f"{paths.PLAN}/pre_pose": 1,  # only the approach target is a pre-pose
        f"{paths.PLOTS}/demo/value": 10,
    }
    assert {k: rows[k] for k in expected} == expected
    assert "EncodedImage:blob" in columns[paths.RGB]
    assert "DepthImage:buffer" in columns[paths.DEPTH]
    assert "SegmentationImage:buffer" in columns[paths.TRUNK_MASK]
    assert "Pinhole:image_from_camera" in columns[paths.IMAGE]
    assert "Ellipsoids3D:half_sizes" in columns[paths.FRUITS]
    assert "Cylinders3D:radii" in columns[paths.OBSTACLE_TRUNK]
    assert any(p.startswith(paths.ROBOT) and "/visual_geometries/" in p for p in columns)
    assert "CoordinateFrame:frame" in columns[f"{paths.TOOLS}/cutter"]
    assert report.not_drawn == {"robot/command": TICKS}
    assert report.derived == 3 * FRAMES and not report.failed and report.run_metadata


def test_controller_state_changes_are_logged_not_every_tick(
    fixture_rrd: tuple[Path, ViewReport],
) -> None:
    rows, _, _ = read_rrd(fixture_rrd[0])
    # first tick, approach → harvest, converged with fallback softened (one tick), fallback none
    assert rows[paths.LOG_CONTROL] == 4


def test_timelines_are_message_stamps_only(fixture_rrd: tuple[Path, ViewReport]) -> None:
    _, _, temporal = read_rrd(fixture_rrd[0])
    for chunk in temporal:
        names = set(chunk.timeline_names)
        assert paths.SIM_TIME in names, chunk.entity_path
        assert not names & {"log_time", "log_tick"}, chunk.entity_path
        if chunk.entity_path in (paths.RGB, paths.TRACKS, paths.DETECTIONS):
            assert paths.FRAME in names
    rgb = [c for c in temporal if c.entity_path == paths.RGB]
    stamps = sorted(
        v for c in rgb for v in c.to_record_batch().column(paths.SIM_TIME).cast("int64").to_pylist()
    )
    assert stamps == [k * fx.FRAME_NS for k in range(FRAMES)]


def test_each_track_keeps_one_colour_and_ids_differ(fixture_rrd: tuple[Path, ViewReport]) -> None:
    _, _, temporal = read_rrd(fixture_rrd[0])
    colour_of: dict[int, set[int]] = {}
    for chunk in (c for c in temporal if c.entity_path == paths.TRACKS):
        batch = chunk.to_record_batch()
        for ids, colours in zip(
            batch.column("track_id").to_pylist(),
            batch.column("Boxes2D:colors").to_pylist(),
            strict=True,
        ):
            for i, c in zip(ids, colours, strict=True):
                colour_of.setdefault(i, set()).add(c)
    assert set(colour_of) == {1, 2, 3}
    assert all(len(c) == 1 for c in colour_of.values())
    assert len({next(iter(c)) for c in colour_of.values()}) == 3


def test_rerun_verifies_the_rrd_and_it_carries_the_blueprint(
    fixture_rrd: tuple[Path, ViewReport],
) -> None:
    r = subprocess.run(
        [rerun_executable(), "rrd", "verify", str(fixture_rrd[0])], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stdout + r.stderr
    reader = RrdReader(fixture_rrd[0])
    assert [s.recording_id for s in reader.recordings()] == ["viz-fixture"]
    assert reader.blueprints()


def test_live_flushing_gives_the_same_rows_as_offline(
    tmp_path: Path, fixture_rrd: tuple[Path, ViewReport]
) -> None:
    """The live service flushes its buffered series whenever its queue runs empty; flushing
    after every message must give the same data as the offline conversion."""
    from services.recorder.inspect import iter_messages

    out = tmp_path / "live.rrd"
    s = Settings(depth_max_rate_hz=5.0)
    rec = open_stream(s, "viz-fixture", out)
    o = Out(rec)
    conv = Converter(o, s)
    conv.begin()
    for m in iter_messages(fx.PATH):
        if not m.derived:
            conv.handle(m.topic, TOPICS[m.topic].codec.decode(m.payload))
            o.flush()
    rec.flush()
    rec.disconnect()
    assert read_rrd(out)[0] == read_rrd(fixture_rrd[0])[0]


def test_missing_urdf_draws_the_rest_and_warns_once(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    report = to_rrd(fx.PATH, tmp_path / "nourdf.rrd", urdf_path=tmp_path / "missing.urdf")
    rows, columns, _ = read_rrd(tmp_path / "nourdf.rrd")
    assert not any(p.startswith(paths.ROBOT) for p in columns)
    assert rows[paths.RGB] == FRAMES and rows[f"{paths.JOINT_VELOCITY}/cutter"] == TICKS
    assert rows[f"{paths.PLAN}/relative"] == 0  # relative to the cutter frame: needs the URDF
    warnings = [r for r in caplog.records if "robot not drawn" in r.getMessage()]
    assert len(warnings) == 1 and "missing.urdf" in warnings[0].getMessage()
    assert any("robot not drawn" in line for line in report.lines())


def test_a_foreign_mcap_converts_what_it_can(tmp_path: Path) -> None:
    """No run metadata, one channel of ours among others: ours is drawn, the rest is named."""
    from mcap.writer import Writer

    src = tmp_path / "foreign.mcap"
    tick = DemoTick(header=Header(stamp_ns=5, seq=0, source="x"), tick=0, value=1.5)
    with open(src, "wb") as f:
        w = Writer(f)
        w.start()
        ours = w.register_channel("demo/tick", "json", 0)
        theirs = w.register_channel("/other/pose", "json", 0)
        w.add_message(ours, log_time=5, data=tick.model_dump_json().encode(), publish_time=5)
        w.add_message(theirs, log_time=6, data=b"{}", publish_time=6)
        w.add_message(ours, log_time=7, data=b"{not json", publish_time=7)
        w.finish()
    report = to_rrd(src, tmp_path / "foreign.rrd")
    assert report.drawn == {"demo/tick": 1}
    assert report.unknown == {"/other/pose": 1} and report.undecodable == {"demo/tick": 1}
    text = "\n".join(report.lines())
    assert "no run metadata" in text and "/other/pose" in text and not report.rerun_importer
    assert read_rrd(tmp_path / "foreign.rrd")[0][f"{paths.PLOTS}/demo/value"] == 1
    assert RrdReader(tmp_path / "foreign.rrd").recordings()[0].recording_id == "foreign"


def test_an_mcap_with_none_of_our_channels_goes_to_rerun_importer(tmp_path: Path) -> None:
    """A Foxglove-protobuf camera from another tool: we draw nothing, Rerun's importer does."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    src = tmp_path / "camera_only.mcap"
    with open(fx.PATH, "rb") as fin, open(src, "wb") as fout:
        reader = make_reader(fin)
        w = Writer(fout)
        w.start()
        ids: dict[int, int] = {}
        for schema, channel, msg in reader.iter_messages(topics=["/preview/camera/image"]):
            if channel.id not in ids:
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                ids[channel.id] = w.register_channel(channel.topic, "protobuf", sid)
            w.add_message(ids[channel.id], msg.log_time, msg.data, msg.publish_time)
        w.finish()
    report = to_rrd(src, tmp_path / "camera_only.rrd")
    assert report.rerun_importer and not report.drawn
    _rows, columns, _ = read_rrd(tmp_path / "camera_only.rrd")
    assert "EncodedImage:blob" in columns["/preview/camera/image"]


def test_solve_time_hook_plots_on_its_entity(tmp_path: Path) -> None:
    from services.viz.plots import log_solve_time

    rec = open_stream(Settings(), "hook", tmp_path / "hook.rrd")
    o = Out(rec)
    for i, ms in enumerate((0.8, 1.2, 0.9)):
        log_solve_time(o, i * 10_000_000, ms)
    o.flush()
    rec.flush()
    rec.disconnect()
    _, _, temporal = read_rrd(tmp_path / "hook.rrd")
    (chunk,) = [c for c in temporal if c.entity_path == paths.SOLVE_TIME]
    values = [
        v for row in chunk.to_record_batch().column("Scalars:scalars").to_pylist() for v in row
    ]
    assert values == pytest.approx([0.8, 1.2, 0.9])


def test_d_s_setting_is_the_plotted_safety_distance(tmp_path: Path) -> None:
    to_rrd(fx.PATH, tmp_path / "ds.rrd", d_s_m=0.05)
    _, _, temporal = read_rrd(tmp_path / "ds.rrd")
    values = {
        v
        for c in temporal
        if c.entity_path == paths.D_S
        for row in c.to_record_batch().column("Scalars:scalars").to_pylist()
        for v in row
    }
    assert values == {0.05}


def test_joint_velocities_are_fractions_of_the_urdf_limits(
    fixture_rrd: tuple[Path, ViewReport],
) -> None:
    _, _, temporal = read_rrd(fixture_rrd[0])
    rows = [
        row
        for c in temporal
        if c.entity_path == f"{paths.JOINT_VELOCITY}/collector"
        for row in c.to_record_batch().column("Scalars:scalars").to_pylist()
    ]
    peak = np.max(np.abs(np.array(rows)), axis=0)
    # the fixture moves the collector at up to 0.8 of each joint's limit (URDF = model limits)
    assert peak == pytest.approx([0.8] * 7, abs=0.01)


def test_only_the_viz_package_imports_rerun() -> None:
    root = Path(__file__).resolve().parents[2]
    offenders = [
        str(p.relative_to(root))
        for p in (root / "services").rglob("*.py")
        if "viz" not in p.relative_to(root / "services").parts[:1]
        and ("import rerun" in p.read_text() or "from rerun" in p.read_text())
    ]
    assert offenders == []


def test_the_converter_survives_a_message_it_cannot_draw(tmp_path: Path) -> None:
    """One bad message is counted, logged once and does not stop the view."""
    rec = open_stream(Settings(), "bad", tmp_path / "bad.rrd")
    o = Out(rec)
    conv = Converter(o, Settings())
    conv.handlers["demo/tick"] = lambda msg: 1 / 0  # a drawing bug
    tick = DemoTick(header=Header(stamp_ns=5, seq=0, source="x"), tick=0, value=1.5)
    assert conv.handle("demo/tick", tick) is False and conv.handle("demo/tick", tick) is False
    assert conv.failed == {"demo/tick": 2} and "failed: demo/tick 2" in conv.report()
    rec.disconnect()
