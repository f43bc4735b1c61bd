"""Play a recording into a live graph: by the recorded pace (× speed) or in lock-step.

Lock-step walks the recording in file order (the recorder's receive order, which is causal order
in a lock-step run): a recorded message on a topic that a live service produces is *awaited*
(the player waits until the live service has published the same seq); any other selected
message is *published*. So every input reaches a service exactly when it did in the original
run, however slow the machine is.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from schemas.codec import DecodeError
from schemas.topics import TOPICS
from services.bus import Bus, RawSample
from services.recorder.inspect import RecordedMessage
from services.recorder.writer import REJECTED_PREFIX


@dataclass
class Produced:
    """What live services published on one topic: seq → payload (first one wins)."""

    by_seq: dict[int, bytes] = field(default_factory=dict)
    undecodable: int = 0


class OutputCollector:
    """Collects live outputs per topic and lets the player wait for a given seq."""

    def __init__(self, bus: Bus, topics: Iterable[str]) -> None:
        self.produced: dict[str, Produced] = {t: Produced() for t in topics}
        self._cv = threading.Condition()
        for t in self.produced:
            bus.subscribe_raw(t, self._on_sample)

    def _on_sample(self, s: RawSample) -> None:
        p = self.produced.get(s.key)
        t = TOPICS.get(s.key)
        if p is None or t is None:
            return
        try:
            seq = t.codec.header(s.payload).seq
        except DecodeError:
            with self._cv:
                p.undecodable += 1
            return
        with self._cv:
            p.by_seq.setdefault(seq, s.payload)
            self._cv.notify_all()

    def wait_for(
        self, topic: str, seq: int, timeout_s: float, alive: Callable[[], bool] = lambda: True
    ) -> bool:
        """True once ``topic`` has ``seq``; False on timeout or when ``alive()`` turns False."""
        deadline = time.monotonic() + timeout_s
        with self._cv:
            while seq not in self.produced[topic].by_seq:
                left = deadline - time.monotonic()
                if left <= 0 or not alive():
                    return False
                self._cv.wait(timeout=min(left, 0.1))
        return True


@dataclass
class PlayStats:
    published: int = 0
    awaited: int = 0
    timed_out: int = 0
    skipped: int = 0
    wall_s: float = 0.0


class Player:
    """Walks recorded messages; publishes the ``publish`` ones, awaits the ``await_`` ones."""

    def __init__(
        self,
        bus: Bus,
        publish: Callable[[str], bool],
        await_: set[str],
        collector: OutputCollector | None,
        timeout_s: float = 10.0,
        alive: Callable[[], bool] = lambda: True,
        progress: Callable[[int], None] | None = None,
    ) -> None:
        self.bus, self.publish, self.await_, self.collector = bus, publish, await_, collector
        self.timeout_s, self.alive, self.progress = timeout_s, alive, progress
        self.stats = PlayStats()
        self.stop = threading.Event()

    def run(self, messages: Iterable[RecordedMessage], speed: float | None = None) -> PlayStats:
        """``speed`` None: lock-step; 0: as fast as possible; > 0: recorded pace × speed."""
        t0 = time.monotonic()
        first_log: int | None = None
        for i, m in enumerate(messages):
            if self.stop.is_set():
                break
            if self.progress:
                self.progress(i)
            if m.derived or m.topic.startswith(REJECTED_PREFIX):
                self.stats.skipped += 1
                continue
            if m.topic in self.await_ and self.collector is not None and speed is None:
                self._await(m)
                continue
            if not self.publish(m.topic):
                self.stats.skipped += 1
                continue
            if speed:
                first_log = m.log_time_ns if first_log is None else first_log
                lag = (m.log_time_ns - first_log) * 1e-9 / speed - (time.monotonic() - t0)
                if lag > 0:
                    self.stop.wait(lag)
            self.bus.put_raw(m.topic, m.payload, m.encoding or _encoding(m.topic))
            self.stats.published += 1
        self.stats.wall_s = time.monotonic() - t0
        return self.stats

    def _await(self, m: RecordedMessage) -> None:
        assert self.collector is not None
        t = TOPICS.get(m.topic)
        try:
            seq = t.codec.header(m.payload).seq if t else m.sequence
        except DecodeError:
            self.stats.skipped += 1
            return
        self.stats.awaited += 1
        if not self.collector.wait_for(m.topic, seq, self.timeout_s, self.alive):
            self.stats.timed_out += 1


def _encoding(topic: str) -> str:
    t = TOPICS.get(topic)
    return t.codec.zenoh_encoding if t else "application/octet-stream"
