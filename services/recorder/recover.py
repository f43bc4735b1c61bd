"""Recover a truncated MCAP (writer SIGKILLed): copy every complete record into a valid file."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer


@dataclass(frozen=True)
class RecoverReport:
    messages: int
    channels: int
    metadata: int
    truncated: bool
    error: str


def recover(src: Path, dst: Path) -> RecoverReport:
    """Stream ``src`` up to its first damaged record; write everything before it to ``dst``."""
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    n_msg = n_meta = 0
    truncated, error = False, ""
    tmp = dst.with_name(dst.name + ".tmp")
    with open(src, "rb") as fin, open(tmp, "wb") as fout:
        w = Writer(fout, compression=CompressionType.LZ4)
        w.start(profile="", library="orange-harvest recover")
        try:
            for rec in StreamReader(fin, skip_magic=False, validate_crcs=True).records:
                if isinstance(rec, Schema):
                    schema_ids[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
                elif isinstance(rec, Channel):
                    channel_ids[rec.id] = w.register_channel(
                        rec.topic,
                        rec.message_encoding,
                        schema_ids.get(rec.schema_id, 0),
                        dict(rec.metadata),
                    )
                elif isinstance(rec, Message) and rec.channel_id in channel_ids:
                    w.add_message(
                        channel_ids[rec.channel_id],
                        rec.log_time,
                        rec.data,
                        rec.publish_time,
                        rec.sequence,
                    )
                    n_msg += 1
                elif isinstance(rec, Metadata):
                    w.add_metadata(rec.name, dict(rec.metadata))
                    n_meta += 1
        except Exception as exc:  # any damage ends the readable prefix
            truncated, error = True, f"{type(exc).__name__}: {exc}"
        w.finish()
    tmp.replace(dst)
    return RecoverReport(n_msg, len(channel_ids), n_meta, truncated, error)
