"""MCAP writer, reader and recover, in memory / tmp files with fixed timestamps."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from mcap.reader import make_reader

from schemas import TOPICS, DemoTick
from services.recorder.inspect import RecordingError, iter_messages, read_info
from services.recorder.recover import recover
from services.recorder.writer import REJECTED_PREFIX, RunWriter
from tests.unit.test_schemas import header, make_frame


def tick(i: int) -> bytes:
    return TOPICS["demo/tick"].codec.encode(
        DemoTick(header=header(stamp_ns=1000 * i, seq=i), tick=i, value=0.5)
    )


def test_channels_schemas_and_stamps() -> None:
    buf = io.BytesIO()
    w = RunWriter(buf, "lz4")
    w.add_metadata("run", {"run_id": "r1"})
    for i in range(3):
        assert w.write("demo/tick", tick(i), "application/json;DemoTick", 5_000 + i) == "ok"
    frame = TOPICS["camera/rgbd"].codec.encode(make_frame())
    assert w.write("camera/rgbd", frame, "application/x-harvest-rgbd", 6_000) == "ok"
    w.finish()
    buf.seek(0)
    r = make_reader(buf)
    summary = r.get_summary()
    assert summary is not None
    schemas = {s.name: s for s in summary.schemas.values()}
    assert schemas["DemoTick"].encoding == "jsonschema"
    assert json.loads(schemas["DemoTick"].data)["title"] == "DemoTick"
    msgs = [
        (c.topic, m.log_time, m.publish_time, m.sequence, c.message_encoding)
        for _, c, m in r.iter_messages(log_time_order=False)
    ]
    assert msgs[:3] == [("demo/tick", 5_000 + i, 1000 * i, i, "json") for i in range(3)]
    assert msgs[3][0] == "camera/rgbd" and msgs[3][4] == "x-harvest-rgbd"
    assert [m.metadata for m in r.iter_metadata()] == [{"run_id": "r1"}]


def test_bad_payloads_and_unknown_keys_are_kept_apart() -> None:
    buf = io.BytesIO()
    w = RunWriter(buf)
    assert w.write("demo/tick", b"\x00garbage", "application/json", 1) == "rejected"
    assert w.write("not/declared", b"hello", "text/plain", 2) == "unknown"
    w.finish()
    buf.seek(0)
    topics = {c.topic: c for _, c, _ in make_reader(buf).iter_messages()}
    assert set(topics) == {REJECTED_PREFIX + "demo/tick", "not/declared"}
    assert topics["not/declared"].schema_id == 0
    assert "first_reject_reason" in topics[REJECTED_PREFIX + "demo/tick"].metadata


def _write_file(path: Path, n: int, flush_every: int = 10) -> None:
    with open(path, "wb") as f:
        w = RunWriter(f, "lz4", chunk_size=1 << 20)
        w.add_metadata("run", {"run_id": "x"})
        for i in range(n):
            w.write("demo/tick", tick(i), "application/json;DemoTick", i)
            if (i + 1) % flush_every == 0:
                w.flush()
        w.finish()


def test_recover_a_truncated_file(tmp_path: Path) -> None:
    good = tmp_path / "good.mcap"
    _write_file(good, 100)
    data = good.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(RecordingError, match="harvest recover") as e:
        read_info(cut)
    assert e.value.recoverable
    out = tmp_path / "fixed.mcap"
    report = recover(cut, out)
    assert report.truncated and report.metadata == 1
    info = read_info(out)
    assert 10 <= info.message_count < 100
    seqs = [m.sequence for m in iter_messages(out)]
    assert seqs == list(range(len(seqs)))  # a prefix, in order, nothing invented


def test_recover_an_intact_file_keeps_everything(tmp_path: Path) -> None:
    good = tmp_path / "good.mcap"
    _write_file(good, 25)
    report = recover(good, tmp_path / "copy.mcap")
    assert not report.truncated and report.messages == 25


def test_not_mcap_and_empty_files(tmp_path: Path) -> None:
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(RecordingError, match="empty"):
        read_info(tmp_path / "empty.mcap")
    (tmp_path / "text.mcap").write_text("hello world, definitely not mcap")
    with pytest.raises(RecordingError, match="not an MCAP"):
        read_info(tmp_path / "text.mcap")
    with pytest.raises(RecordingError, match="no such file"):
        read_info(tmp_path / "missing.mcap")
