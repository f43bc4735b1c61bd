"""Play a recording into a live graph: by the recorded pace (× speed) or in lock-step.

Lock-step walks the recording in stamp order (file order within a stamp; the recorder's receive
order can swap neighbours from different publishers, never across a tick in causal terms): a
recorded message on a topic that a live service produces is *awaited* (the player waits until
the live service has published the same seq); any other selected message is *published*, but
only once every output recorded before it is in (the lock-step answer barrier) — except the
outputs it causes itself (its answer closure at its stamp, which the recorder may have written
first): those are awaited later, never before their cause. Each published message carries the
outputs awaited since the previous publish as its causal predecessors (``runtime/causal.py``),
so a live service takes them first even when the router delivers the message before them. So
every input reaches a service exactly when it did in the original run, however slow the
machine is.
"""

from __future__ import annotations

import heapq
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field, replace

from schemas.codec import DecodeError
from schemas.topics import TOPICS
from services.bus import Bus, RawSample
from services.recorder.inspect import RecordedMessage
from services.recorder.writer import REJECTED_PREFIX
from services.runtime.causal import Dep, encode_after

REORDER_WINDOW = 64  # messages: the recorder swaps neighbours only, by one or two places


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

    def dep(self, topic: str, seq: int) -> Dep:
        """(topic, stamp, seq) of the produced message ``seq`` (its stamp as produced)."""
        with self._cv:
            payload = self.produced[topic].by_seq[seq]
        t = TOPICS.get(topic)
        try:
            stamp_ns = t.codec.header(payload).stamp_ns if t else 0
        except DecodeError:
            stamp_ns = 0
        return (topic, stamp_ns, seq)

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


def by_stamp(
    messages: Iterable[RecordedMessage], window: int = REORDER_WINDOW
) -> Iterator[RecordedMessage]:
    """``messages`` stably sorted by stamp (``publish_time_ns``) within a sliding ``window``:
    a lock-step tick's messages all precede the next tick's, whatever the recorder received
    first; within a stamp the file order is kept."""
    heap: list[tuple[int, int, RecordedMessage]] = []
    for i, m in enumerate(messages):
        heapq.heappush(heap, (m.publish_time_ns, i, m))
        if len(heap) > window:
            yield heapq.heappop(heap)[2]
    while heap:
        yield heapq.heappop(heap)[2]


@dataclass(frozen=True)
class _Awaited:
    topic: str
    stamp_ns: int
    seq: int
    cause_published: bool = False  # kept back for a run that is published now


class Player:
    """Walks recorded messages; publishes the ``publish`` ones, awaits the ``await_`` ones.

    ``caused_by``: topic → the topics answering it (answer closure), for lock-step.
    ``alongside``: topic → the other outputs its answerers may publish with an answer.
    ``alive(topic)``: False once the producer of ``topic`` is gone (nothing more will come).
    """

    def __init__(
        self,
        bus: Bus,
        publish: Callable[[str], bool],
        await_: set[str],
        collector: OutputCollector | None,
        timeout_s: float = 10.0,
        alive: Callable[[str], bool] = lambda _t: True,
        progress: Callable[[int], None] | None = None,
        caused_by: Mapping[str, Iterable[str]] | None = None,
        alongside: Mapping[str, Iterable[str]] | None = None,
    ) -> None:
        self.bus, self.publish, self.await_, self.collector = bus, publish, await_, collector
        self.timeout_s, self.alive, self.progress = timeout_s, alive, progress
        self.caused_by = {k: frozenset(v) for k, v in (caused_by or {}).items()}
        self.alongside = {k: frozenset(v) for k, v in (alongside or {}).items()}
        self.stats = PlayStats()
        self.stop = threading.Event()
        self._pending: list[_Awaited] = []  # recorded outputs not yet awaited
        self._done: list[Dep] = []  # outputs in since the previous publish
        self._done_before: list[Dep] = []  # those attached to the previous publish

    def run(self, messages: Iterable[RecordedMessage], speed: float | None = None) -> PlayStats:
        """``speed`` None: lock-step; 0: as fast as possible; > 0: recorded pace × speed."""
        t0 = time.monotonic()
        if speed is None and self.collector is not None:
            self._run_lockstep(messages)
            self.stats.wall_s = time.monotonic() - t0
            return self.stats
        first_log: int | None = None
        for i, m in enumerate(messages):
            if self.stop.is_set():
                break
            if self.progress:
                self.progress(i)
            if m.derived or m.topic.startswith(REJECTED_PREFIX):
                self.stats.skipped += 1
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

    def _run_lockstep(self, messages: Iterable[RecordedMessage]) -> None:
        """Stamp order; consecutive inputs of one stamp (the master's group) are published
        together, each naming the others as its ``group``. An output recorded between them
        ends the group, unless it answers the group and the group's answers are not all in:
        the master publishes a group at once and the next one only after every answer, so
        such an output is a fast answer that the recorder took before the group's rest."""
        run: list[RecordedMessage] = []
        answered: set[str] = set()  # answers to ``run`` recorded amid it
        for i, m in enumerate(by_stamp(messages)):
            if self.stop.is_set():
                return
            if self.progress:
                self.progress(i)
            if m.derived or m.topic.startswith(REJECTED_PREFIX):
                self.stats.skipped += 1
            elif m.topic in self.await_:
                if self._answers(m, run):
                    answered.add(m.topic)
                else:
                    self._flush(run)
                    answered.clear()
                self._defer(m)
            elif not self.publish(m.topic):
                self.stats.skipped += 1
            else:
                if run and (
                    run[0].publish_time_ns != m.publish_time_ns
                    or (answered and answered >= self._caused_by_run(run))
                ):
                    self._flush(run)
                    answered.clear()
                run.append(m)
        if not self.stop.is_set():
            self._flush(run)
            self._settle(None)

    def _caused_by_run(self, run: list[RecordedMessage]) -> frozenset[str]:
        """The answers that ``run`` must get (the master awaits them all)."""
        return frozenset(t for m in run for t in self.caused_by.get(m.topic, ()))

    def _caused_or_alongside(self, run: list[RecordedMessage]) -> frozenset[str]:
        """Every output that ``run`` can cause: its answers and what comes beside them."""
        beside = (t for m in run for t in self.alongside.get(m.topic, ()))
        return self._caused_by_run(run) | frozenset(beside)

    def _answers(self, m: RecordedMessage, run: list[RecordedMessage]) -> bool:
        """True when the output ``m`` answers a message of ``run`` (or comes beside an answer)
        at its stamp."""
        return bool(run) and (
            m.publish_time_ns == run[0].publish_time_ns
            and m.topic in self._caused_or_alongside(run)
        )

    def _flush(self, run: list[RecordedMessage]) -> None:
        if not run:
            return
        attachment = encode_after(self._settle(run), [_dep_of(m) for m in run])
        for m in run:
            self.bus.put_raw(m.topic, m.payload, m.encoding or _encoding(m.topic), attachment)
            self.stats.published += 1
        run.clear()

    def _alive_of(self, topic: str) -> Callable[[], bool]:
        return lambda: self.alive(topic)

    def _defer(self, m: RecordedMessage) -> None:
        """Note a recorded output; it is awaited before the next message that must follow it."""
        t = TOPICS.get(m.topic)
        try:
            h = t.codec.header(m.payload) if t else None
        except DecodeError:
            self.stats.skipped += 1
            return
        seq, stamp_ns = (h.seq, h.stamp_ns) if h else (m.sequence, m.publish_time_ns)
        self.stats.awaited += 1
        self._pending.append(_Awaited(m.topic, stamp_ns, seq))

    def _settle(self, run: list[RecordedMessage] | None) -> list[Dep]:
        """Before publishing ``run`` (None: the end): await the pending outputs, except those
        that ``run`` causes; return the predecessors of ``run``: the ones that came in."""
        assert self.collector is not None
        caused = self._caused_or_alongside(run) if run else frozenset()
        stamp_ns = run[0].publish_time_ns if run else None
        keep = []
        for o in self._pending:
            if not o.cause_published and o.stamp_ns == stamp_ns and o.topic in caused:
                # Recorded before its cause: awaited after it is published (and then always:
                # a next run at this stamp may cause its topic too, but did not cause it).
                keep.append(replace(o, cause_published=True))
                continue
            alive = self._alive_of(o.topic)
            if self.collector.wait_for(o.topic, o.seq, self.timeout_s, alive):
                self._done.append(self.collector.dep(o.topic, o.seq))
            else:
                self.stats.timed_out += 1
        self._pending = keep
        # With those of the previous publish: a group published right after another (no output
        # awaited between them) follows the same outputs.
        done, self._done = self._done, []
        after = [*self._done_before, *done]
        self._done_before = done or self._done_before
        return after


def _dep_of(m: RecordedMessage) -> Dep:
    """(topic, stamp, seq) of a recorded message, from its header when it has one."""
    t = TOPICS.get(m.topic)
    try:
        h = t.codec.header(m.payload) if t else None
    except DecodeError:
        h = None
    return (m.topic, h.stamp_ns, h.seq) if h else (m.topic, m.publish_time_ns, m.sequence)


def _encoding(topic: str) -> str:
    t = TOPICS.get(topic)
    return t.codec.zenoh_encoding if t else "application/octet-stream"
