"""`harvest view`'s engine: an MCAP recording through the conversion core into a Rerun stream.

Our own recordings convert fully. An MCAP from another tool converts what it can: channels of
our topic map are drawn by the core, and when none is ours the file is handed to Rerun's own
MCAP importer (Foxglove protobuf, ROS 2); the report says what was missing.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from schemas.codec import DecodeError
from schemas.topics import TOPICS
from services.recorder.inspect import RecordingInfo, iter_messages, read_info
from services.recorder.writer import REJECTED_PREFIX
from services.viz import Settings
from services.viz.core import Converter
from services.viz.out import Out

log = logging.getLogger("viz.offline")


@dataclass
class ViewReport:
    """What a conversion drew and what it could not."""

    messages: int = 0
    drawn: Counter[str] = field(default_factory=Counter)
    not_drawn: Counter[str] = field(default_factory=Counter)
    unknown: Counter[str] = field(default_factory=Counter)  # channels not in our topic map
    undecodable: Counter[str] = field(default_factory=Counter)
    failed: Counter[str] = field(default_factory=Counter)
    derived: int = 0  # camera preview messages (drawn from camera/rgbd instead)
    rejected: int = 0  # recorded under _rejected/ by the recorder
    run_metadata: bool = False
    rerun_importer: bool = False
    rows: dict[str, int] = field(default_factory=dict)  # rows logged per entity path
    warnings: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        """The report as lines for a terminal."""
        out = [f"drawn: {_fmt(self.drawn) or 'nothing'}"]
        if self.not_drawn:
            out.append(
                f"recorded but not drawn (no drawing for these topics): {_fmt(self.not_drawn)}"
            )
        if self.unknown:
            out.append(f"not ours (unknown channels): {_fmt(self.unknown)}")
        if self.undecodable:
            out.append(f"undecodable payloads: {_fmt(self.undecodable)}")
        if self.failed:
            out.append(f"failed to draw: {_fmt(self.failed)}")
        if self.derived:
            out.append(f"skipped {self.derived} derived preview messages (drawn from camera/rgbd)")
        if self.rejected:
            out.append(f"skipped {self.rejected} payloads the recorder had rejected")
        if not self.run_metadata:
            out.append("no run metadata: not recorded by `harvest run` (run id, settings unknown)")
        if self.rerun_importer:
            out.append(
                "none of the channels is ours: the file was also given to Rerun's MCAP importer"
            )
        return out + self.warnings


def _fmt(c: Counter[str]) -> str:
    return ", ".join(f"{k} ({n})" for k, n in sorted(c.items()))


def recording_id(info: RecordingInfo) -> str:
    """The run id from the metadata, else the file name: live and offline views of one run
    share it."""
    return info.run.get("run_id") or info.path.stem


def convert(
    path: Path,
    rec: Any,
    settings: Settings,
    progress: Callable[[int, int], None] | None = None,
    info: RecordingInfo | None = None,
) -> ViewReport:
    """Draw every message of ``path`` into ``rec``; raises RecordingError for a file that
    cannot be read (truncated: ``recoverable``)."""
    info = info or read_info(path)
    report = ViewReport(run_metadata=bool(info.run))
    out = Out(rec)
    conv = Converter(out, settings)
    conv.begin()
    for i, m in enumerate(iter_messages(path)):
        report.messages += 1
        if progress is not None and i % 200 == 0:
            progress(i, info.message_count)
        if m.derived:
            report.derived += 1
            continue
        if m.topic.startswith(REJECTED_PREFIX):
            report.rejected += 1
            continue
        t = TOPICS.get(m.topic)
        if t is None:
            report.unknown[m.topic] += 1
            continue
        try:
            msg = t.codec.decode(m.payload)
        except DecodeError as exc:
            if not report.undecodable[m.topic]:
                log.warning("%s: undecodable payload (%s); later ones only counted", m.topic, exc)
            report.undecodable[m.topic] += 1
            continue
        conv.handle(m.topic, msg)
    out.flush()
    if not conv.drawn and report.unknown:
        report.rerun_importer = True
        rec.log_file_from_path(str(path))
    report.drawn, report.not_drawn, report.failed = conv.drawn, conv.not_drawn, conv.failed
    report.rows = dict(out.rows)
    report.warnings = list(conv.warnings)
    if progress is not None:
        progress(info.message_count, info.message_count)
    return report
