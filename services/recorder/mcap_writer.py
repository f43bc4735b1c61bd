"""A lean chunked MCAP writer for camera-heavy recording.

The reference Python writer (mcap.writer.Writer) grows a BytesIO per chunk and copies every
1.5 MB frame five times before it reaches the file (about 5 ms per RGB-D frame with lz4, half of
the recorder's budget at 15 Hz). This writer keeps a chunk as a list of parts, joins it once,
checksums and compresses it once, and writes the compressed bytes straight to the file. It reuses
the record classes of the `mcap` package for everything else, and the files it writes are read
by the `mcap` readers, Foxglove and Rerun like any other (the tests check that).
"""

from __future__ import annotations

import struct
import zlib
from collections import defaultdict
from typing import IO, Literal

import lz4.frame
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC = b"\x89MCAP0\r\n"
_MSG = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
_CHUNK_HEAD = struct.Struct("<BQQQQI")  # opcode, length, start, end, uncompressed size, crc
Compression = Literal["lz4", "zstd", "none"]


class LeanMcapWriter:
    """Chunked, indexed MCAP writer; the API is the subset of mcap.writer.Writer we use."""

    def __init__(
        self,
        stream: IO[bytes],
        chunk_size: int = 4 << 20,
        compression: Compression = "lz4",
        lz4_level: int = 0,
    ) -> None:
        self.stream, self.chunk_size = stream, chunk_size
        self.compression, self.lz4_level = compression, lz4_level
        self._pos = 0
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._stats = Statistics(
            message_count=0,
            schema_count=0,
            channel_count=0,
            attachment_count=0,
            metadata_count=0,
            chunk_count=0,
            message_start_time=0,
            message_end_time=0,
            channel_message_counts=defaultdict(int),
        )
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._reset_chunk()

    # ---- low level -------------------------------------------------------------------------
    def _write(self, data: bytes | bytearray | memoryview) -> None:
        self.stream.write(data)
        self._pos += len(data)

    def _write_record(self, record: object) -> int:
        """Write a small record from the mcap package; returns its start offset."""
        b = RecordBuilder()
        record.write(b)  # type: ignore[attr-defined]
        start = self._pos
        self._write(b.end())
        return start

    def _reset_chunk(self) -> None:
        self._parts: list[bytes] = []
        self._chunk_len = 0
        self._chunk_start = self._chunk_end = 0
        self._msg_index: dict[int, list[tuple[int, int]]] = {}

    # ---- API -------------------------------------------------------------------------------
    def start(self, profile: str = "", library: str = "") -> None:
        self._write(MAGIC)
        self._write_record(Header(profile=profile, library=library))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        sid = len(self._schemas) + 1
        self._schemas[sid] = s = Schema(id=sid, name=name, encoding=encoding, data=data)
        self._stats.schema_count += 1
        self._write_record(s)
        return sid

    def register_channel(
        self,
        topic: str,
        message_encoding: str,
        schema_id: int,
        metadata: dict[str, str] | None = None,
    ) -> int:
        cid = len(self._channels) + 1
        self._channels[cid] = c = Channel(
            id=cid,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=metadata or {},
        )
        self._stats.channel_count += 1
        self._write_record(c)
        return cid

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._finalize_chunk()  # keep records in time order
        start = self._write_record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(
            MetadataIndex(offset=start, length=self._pos - start, name=name)
        )
        self._stats.metadata_count += 1

    def add_message(
        self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0
    ) -> None:
        st = self._stats
        st.message_start_time = (
            log_time if st.message_count == 0 else min(st.message_start_time, log_time)
        )
        st.message_end_time = max(st.message_end_time, log_time)
        st.message_count += 1
        st.channel_message_counts[channel_id] += 1
        if not self._parts:
            self._chunk_start = log_time
        self._chunk_start = min(self._chunk_start, log_time)
        self._chunk_end = max(self._chunk_end, log_time)
        self._msg_index.setdefault(channel_id, []).append((log_time, self._chunk_len))
        head = _MSG.pack(
            Opcode.MESSAGE, 2 + 4 + 8 + 8 + len(data), channel_id, sequence, log_time, publish_time
        )
        self._parts += (head, data)
        self._chunk_len += len(head) + len(data)
        if self._chunk_len >= self.chunk_size:
            self._finalize_chunk()

    def flush(self) -> None:
        """Write the chunk in progress and flush the stream (not fsync)."""
        self._finalize_chunk()
        self.stream.flush()

    def finish(self) -> None:
        self._finalize_chunk()
        self._write_record(DataEnd(data_section_crc=0))
        self._write_summary()
        self.stream.flush()

    # ---- chunks and summary ----------------------------------------------------------------
    def _finalize_chunk(self) -> None:
        if not self._parts:
            return
        raw = b"".join(self._parts)
        crc = zlib.crc32(raw)
        if self.compression == "lz4":
            data, name = lz4.frame.compress(raw, compression_level=self.lz4_level), b"lz4"
        elif self.compression == "zstd":
            import zstandard

            data, name = zstandard.compress(raw), b"zstd"
        else:
            data, name = raw, b""
        start = self._pos
        body_len = 8 + 8 + 8 + 4 + 4 + len(name) + 8 + len(data)
        self._write(
            _CHUNK_HEAD.pack(
                Opcode.CHUNK, body_len, self._chunk_start, self._chunk_end, len(raw), crc
            )
            + struct.pack("<I", len(name))
            + name
            + struct.pack("<Q", len(data))
        )
        self._write(data)
        chunk_len = self._pos - start
        index_start = self._pos
        offsets = {}
        for cid, records in self._msg_index.items():
            offsets[cid] = self._pos
            self._write_record(MessageIndex(channel_id=cid, records=records))
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=self._chunk_start,
                message_end_time=self._chunk_end,
                chunk_start_offset=start,
                chunk_length=chunk_len,
                message_index_offsets=offsets,
                message_index_length=self._pos - index_start,
                compression=name.decode(),
                compressed_size=len(data),
                uncompressed_size=len(raw),
            )
        )
        self._stats.chunk_count += 1
        self._reset_chunk()

    def _write_summary(self) -> None:
        summary_start = self._pos
        b = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, records: list) -> None:
            g0 = b.count
            for r in records:
                r.write(b)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode, group_start=summary_start + g0, group_length=b.count - g0
                )
            )

        group(Opcode.SCHEMA, list(self._schemas.values()))
        group(Opcode.CHANNEL, list(self._channels.values()))
        group(Opcode.STATISTICS, [self._stats])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        offset_start = summary_start + b.count
        for o in offsets:
            o.write(b)
        summary = b.end()
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offset_start), crc)
        self._write(summary)
        self._write_record(
            Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc)
        )
        self._write(MAGIC)
