"""MCAP writer of a run: one channel per key, JSON Schema per model, stamps from the headers.

Pure apart from the file it writes: no zenoh, no wall clock (log times are passed in).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import IO

from schemas.codec import DecodeError
from schemas.topics import TOPICS
from services import __version__
from services.recorder.mcap_writer import Compression, LeanMcapWriter
from services.recorder.preview import DERIVED_FROM, SOURCE_TOPIC, CameraPreview

REJECTED_PREFIX = "_rejected/"
RUN_METADATA = "run"


@dataclass
class ChannelStats:
    messages: int = 0
    bytes: int = 0


@dataclass
class RunWriter:
    """Writes samples as MCAP messages; invalid payloads go to ``_rejected/<key>`` channels."""

    stream: IO[bytes]
    compression: Compression = "lz4"
    chunk_size: int = 4 << 20
    lz4_level: int = 0
    preview: CameraPreview | None = None
    stats: dict[str, ChannelStats] = field(default_factory=dict)
    derived: dict[str, ChannelStats] = field(default_factory=dict)
    rejected: int = 0
    unknown: int = 0
    preview_errors: int = 0

    def __post_init__(self) -> None:
        self._w = LeanMcapWriter(self.stream, self.chunk_size, self.compression, self.lz4_level)
        self._w.start(profile="", library=f"orange-harvest recorder {__version__}")
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._fallback_seq: dict[str, int] = {}

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._w.add_metadata(name, data)

    def write(self, key: str, payload: bytes, encoding: str, log_time_ns: int) -> str:
        """Record one sample; returns 'ok', 'rejected' (bad payload) or 'unknown' (key)."""
        t = TOPICS.get(key)
        if t is None:
            self.unknown += 1
            self._write_plain(key, payload, encoding, log_time_ns)
            return "unknown"
        try:
            header = t.codec.header(payload)
        except DecodeError as exc:
            self.rejected += 1
            self._write_plain(
                REJECTED_PREFIX + key, payload, encoding, log_time_ns, reason=exc.reason
            )
            return "rejected"
        cid = self._channels.get(key)
        if cid is None:
            cid = self._channels[key] = self._register_topic(key, encoding)
        self._w.add_message(
            cid,
            log_time=log_time_ns,
            data=payload,
            publish_time=header.stamp_ns,
            sequence=header.seq % (1 << 32),
        )
        self._count(key, payload)
        if self.preview is not None and key == SOURCE_TOPIC:
            self._write_derived(payload, log_time_ns, header.stamp_ns, header.seq)
        return "ok"

    def _write_derived(self, payload: bytes, log_time_ns: int, stamp_ns: int, seq: int) -> None:
        """The camera preview channels (see preview.py); a frame it cannot use is counted."""
        assert self.preview is not None
        try:
            messages = self.preview.derive(payload)
        except ValueError:
            self.preview_errors += 1
            return
        for m in messages:
            cid = self._channels.get(m.topic)
            if cid is None:
                cid = self._channels[m.topic] = self._register_derived(m.topic, m.schema_name)
            self._w.add_message(cid, log_time_ns, m.data, stamp_ns, seq % (1 << 32))
            st = self.derived.setdefault(m.topic, ChannelStats())
            st.messages += 1
            st.bytes += len(m.data)

    def _register_derived(self, topic: str, schema_name: str) -> int:
        assert self.preview is not None
        sid = self._schemas.get(schema_name)
        if sid is None:
            sid = self._schemas[schema_name] = self._w.register_schema(
                schema_name, "protobuf", self.preview.schemas[schema_name]
            )
        meta = {DERIVED_FROM: SOURCE_TOPIC, "content": self.preview.description}
        return self._w.register_channel(topic, "protobuf", sid, meta)

    def _register_topic(self, key: str, encoding: str) -> int:
        t = TOPICS[key]
        sid = self._schemas.get(t.schema_name)
        if sid is None:
            data = json.dumps(t.codec.json_schema(), sort_keys=True).encode()
            sid = self._schemas[t.schema_name] = self._w.register_schema(
                t.schema_name, "jsonschema", data
            )
        meta = {"zenoh_encoding": encoding, "schema_name": t.schema_name}
        return self._w.register_channel(key, t.codec.mcap_message_encoding, sid, meta)

    def _write_plain(
        self, key: str, payload: bytes, encoding: str, log_time_ns: int, reason: str = ""
    ) -> None:
        """Schemaless channel: a key no service declared, or a payload that did not validate."""
        cid = self._channels.get(key)
        if cid is None:
            meta = {"zenoh_encoding": encoding}
            if reason:
                meta["first_reject_reason"] = reason[:500]
            cid = self._channels[key] = self._w.register_channel(
                key, encoding.split(";")[0] or "application/octet-stream", 0, meta
            )
        seq = self._fallback_seq.get(key, 0)
        self._fallback_seq[key] = seq + 1
        self._w.add_message(
            cid,
            log_time=log_time_ns,
            data=payload,
            publish_time=log_time_ns,
            sequence=seq % (1 << 32),
        )
        self._count(key, payload)

    def _count(self, key: str, payload: bytes) -> None:
        st = self.stats.get(key)
        if st is None:
            st = self.stats[key] = ChannelStats()
        st.messages += 1
        st.bytes += len(payload)

    def flush(self) -> None:
        """Write the chunk in progress: a SIGKILL later loses nothing before this point."""
        self._w.flush()

    def finish(self) -> None:
        self._w.finish()
