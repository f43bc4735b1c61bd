"""The lean MCAP writer writes files that the reference readers and Rerun accept."""

from __future__ import annotations

import io
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from services.recorder.mcap_writer import LeanMcapWriter


def _write(stream: io.BytesIO | io.BufferedWriter, compression: str = "lz4") -> None:
    w = LeanMcapWriter(stream, chunk_size=4096, compression=compression)  # type: ignore[arg-type]
    w.start(library="test")
    sid = w.register_schema("S", "jsonschema", b'{"type": "object"}')
    a = w.register_channel("a", "json", sid, {"k": "v"})
    b = w.register_channel("b", "json", sid)
    w.add_metadata("run", {"x": "1"})
    for i in range(200):
        w.add_message(a if i % 3 else b, 1000 + i, b'{"i": %d}' % i + b" " * (i % 50), 5 * i, i)
        if i == 120:
            w.flush()
    w.finish()


@pytest.mark.parametrize("compression", ["lz4", "zstd", "none"])
def test_reference_reader_reads_summary_indexes_and_messages(compression: str) -> None:
    buf = io.BytesIO()
    _write(buf, compression)
    buf.seek(0)
    r = make_reader(buf)
    s = r.get_summary()
    assert s is not None and s.statistics is not None
    assert s.statistics.message_count == 200 and s.statistics.chunk_count >= 3
    assert s.statistics.message_start_time == 1000 and s.statistics.message_end_time == 1199
    assert {c.topic: c.metadata for c in s.channels.values()}["a"] == {"k": "v"}
    ordered = [m.log_time for _, _, m in r.iter_messages(log_time_order=True)]
    assert ordered == list(range(1000, 1200))
    only_b = [m.sequence for _, _, m in r.iter_messages(topics=["b"])]
    assert only_b == list(range(0, 200, 3))
    assert [m.metadata for m in r.iter_metadata()] == [{"x": "1"}]
    buf.seek(0)
    msgs = [
        rec
        for rec in StreamReader(buf, validate_crcs=True).records
        if type(rec).__name__ == "Message"
    ]
    assert len(msgs) == 200


@pytest.mark.skipif(
    shutil.which("rerun", path=str(Path(sys.executable).parent)) is None,
    reason="rerun CLI not installed",
)
def test_rerun_loader_accepts_the_file(tmp_path: Path) -> None:
    p = tmp_path / "x.mcap"
    with open(p, "wb") as f:
        _write(f)
    rerun = str(Path(sys.executable).parent / "rerun")
    r = subprocess.run([rerun, "mcap", "check", str(p)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "ok" in r.stdout
