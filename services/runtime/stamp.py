"""Header factory: per-topic sequence counters owned by a service core (deterministic)."""

from __future__ import annotations

from schemas.base import Header


class Stamper:
    """Makes Headers for one source: seq counts per topic from 0."""

    def __init__(self, source: str) -> None:
        self.source = source
        self._seq: dict[str, int] = {}

    def header(
        self, topic: str, stamp_ns: int, frame_id: str = "", answers_seq: int | None = None
    ) -> Header:
        seq = self._seq.get(topic, 0)
        self._seq[topic] = seq + 1
        return Header(
            stamp_ns=stamp_ns,
            seq=seq,
            frame_id=frame_id,
            source=self.source,
            answers_seq=answers_seq,
        )

    def answer(self, topic: str, to: Header, frame_id: str | None = None) -> Header:
        """Header of an answer to the message with header ``to``: same stamp, names its seq."""
        return self.header(
            topic, to.stamp_ns, to.frame_id if frame_id is None else frame_id, answers_seq=to.seq
        )
