"""Read a recording: summary (channels, counts, duration, metadata) and messages in file order.

Clear errors for files that are missing, empty, not MCAP, or truncated (with the recover hint).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Channel, Schema

from services.recorder.preview import DERIVED_FROM
from services.recorder.writer import RUN_METADATA

MCAP_MAGIC = b"\x89MCAP0\r\n"


class RecordingError(ValueError):
    """A recording that cannot be read; ``recoverable`` says whether `harvest recover` applies."""

    def __init__(self, message: str, recoverable: bool = False) -> None:
        super().__init__(message)
        self.recoverable = recoverable


@dataclass
class ChannelInfo:
    topic: str
    schema_name: str
    message_encoding: str
    count: int
    derived: bool = False  # written by the recorder from another channel; not a bus topic


@dataclass
class RecordingInfo:
    path: Path
    size_bytes: int
    message_count: int
    start_ns: int
    end_ns: int
    channels: list[ChannelInfo]
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return max(0, self.end_ns - self.start_ns) * 1e-9

    @property
    def run(self) -> dict[str, str]:
        return self.metadata.get(RUN_METADATA, {})

    def run_json(self, key: str, default: object = None) -> object:
        """A JSON-encoded value of the run metadata, decoded."""
        raw = self.run.get(key)
        return default if raw is None else json.loads(raw)


def check_file(path: Path) -> None:
    """Raise RecordingError unless ``path`` exists, is non-empty and starts with the MCAP magic."""
    if not path.exists():
        raise RecordingError(f"{path}: no such file")
    if path.is_dir():
        raise RecordingError(f"{path}: is a folder, not an MCAP file")
    size = path.stat().st_size
    if size == 0:
        raise RecordingError(f"{path}: empty file (0 bytes); nothing was recorded")
    with open(path, "rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise RecordingError(f"{path}: not an MCAP file (bad magic bytes)")
        f.seek(max(0, size - len(MCAP_MAGIC)))
        if f.read() != MCAP_MAGIC:
            raise RecordingError(
                f"{path}: truncated MCAP (no footer: the writer did not finish, e.g. it was "
                f"killed); repair it with `harvest recover {path}`",
                recoverable=True,
            )


def read_info(path: Path) -> RecordingInfo:
    """Summary of a finished recording."""
    check_file(path)
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    except Exception as exc:
        raise RecordingError(
            f"{path}: unreadable MCAP ({type(exc).__name__}: {exc}); try `harvest recover {path}`",
            recoverable=True,
        ) from None
    if summary is None or summary.statistics is None:
        raise RecordingError(
            f"{path}: MCAP without a summary; try `harvest recover {path}`", recoverable=True
        )
    st = summary.statistics
    channels = [
        ChannelInfo(
            ch.topic,
            _schema_name(summary.schemas, ch),
            ch.message_encoding,
            st.channel_message_counts.get(cid, 0),
            DERIVED_FROM in ch.metadata,
        )
        for cid, ch in sorted(summary.channels.items(), key=lambda kv: kv[1].topic)
    ]
    return RecordingInfo(
        path,
        path.stat().st_size,
        st.message_count,
        st.message_start_time,
        st.message_end_time,
        channels,
        metadata,
    )


def _schema_name(schemas: dict[int, Schema], ch: Channel) -> str:
    s = schemas.get(ch.schema_id)
    return s.name if s else ""


@dataclass(frozen=True)
class RecordedMessage:
    topic: str
    payload: bytes
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    encoding: str  # the Zenoh encoding it was published with
    derived: bool = False  # a derived channel (e.g. the camera preview): never replayed


def iter_messages(path: Path) -> Iterator[RecordedMessage]:
    """Messages in file order (= the recorder's receive order, which lock-step replay needs)."""
    check_file(path)
    with open(path, "rb") as f:
        reader = make_reader(f)
        for _schema, ch, msg in reader.iter_messages(log_time_order=False):
            yield RecordedMessage(
                ch.topic,
                msg.data,
                msg.log_time,
                msg.publish_time,
                msg.sequence,
                ch.metadata.get("zenoh_encoding", ""),
                DERIVED_FROM in ch.metadata,
            )
