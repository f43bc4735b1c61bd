"""The thin process around a pure core: inputs from the bus, one worker thread, outputs, status.

Every input is decoded on a Zenoh thread, checked for order, queued, and handed to the core on
one worker thread in arrival order. Zenoh keeps order per publisher only, so in lock-step every
message carries its causal predecessors (``causal.py``): an input waits in the queue until the
predecessors on this service's inputs have arrived, and those are handed first. What a step
consumes is then fixed by the graph, not by the router's timing: lock-step runs are
byte-identical.

In lock-step a service answers a repeat of the input it answered last (the master re-sends a
stalled tick) by publishing its answer again, byte for byte, without calling the core: a
message lost between two services (a killed service, a restarted router) is then replaced
along the whole chain, while every consumer still drops the repeats by seq.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Any, Literal, Protocol

from schemas.service import ServiceState, ServiceStatus
from services import __version__
from services.bus import Bus, BusSettings
from services.runtime.causal import (
    NO_CAUSES,
    CausalGate,
    Causes,
    Dep,
    decode_after,
    encode_after,
    next_in_order,
)
from services.runtime.lockstep import AnswerBarrier, LockstepPlan, LockstepStall, LockstepStopped
from services.runtime.spec import NodeSpec

log = logging.getLogger("node")

Output = tuple[str, Any]
Mode = Literal["lockstep", "live"]
_REANSWER = "\x00reanswer"  # queue marker: publish the cached answer to (topic, seq) again
Queued = tuple[str, Any, Causes]  # (topic, message, its causes)


class Core(Protocol):
    """A reactive core: pure, deterministic, no I/O and no wall clock.

    A core may also have ``done() -> bool``: once it returns True (checked after each input's
    outputs are published) the service stops and exits 0. The planner uses it to end the run
    when it has published its summary (it is the stack's main service).
    """

    def handle(self, topic: str, msg: Any) -> Sequence[Output]: ...


class TimedCore(Core, Protocol):
    """A reactive core that also wants to act when no input comes (live mode only).

    The Node calls ``on_timer(wall_ns)`` about every ``timer_period_s`` on the same worker
    thread as ``handle`` (so no locking is needed) and publishes what it returns. Never in
    lock-step: there, time is the stamps and nothing may happen between inputs. Use: a
    controller's watchdog that must stop the arms when its inputs stop arriving.
    """

    timer_period_s: float

    def on_timer(self, wall_ns: int) -> Sequence[Output]: ...


def timer_of(core: Any, mode: Mode) -> tuple[Any, float] | None:
    """The core's ``(on_timer, period_s)`` when it has a timer and the mode is live, else None."""
    fn = getattr(core, "on_timer", None)
    period_s = float(getattr(core, "timer_period_s", 0.0) or 0.0)
    if mode != "live" or fn is None or period_s <= 0:
        return None
    return fn, period_s


class SourceCore(Protocol):
    """A clock-master core: emits the messages of a tick, takes answers, advances time."""

    def done(self) -> bool: ...
    def now_ns(self) -> int: ...
    def emit(self) -> Sequence[Sequence[Output]]: ...
    def handle(self, topic: str, msg: Any) -> Sequence[Output]: ...
    def advance(self) -> None: ...


def core_counters(core: Any) -> dict[str, int]:
    """A core's ``counters`` for its status: a mapping (a Counter) or a dataclass of counts (the
    controller's); anything else gives {} (a status query must never fail on it: the supervisor
    asks for the status before judging a service hung)."""
    c = getattr(core, "counters", None)
    if dataclasses.is_dataclass(c) and not isinstance(c, type):
        c = dataclasses.asdict(c)
    if not isinstance(c, Mapping):
        return {}
    return {str(k): int(v) for k, v in sorted(c.items()) if isinstance(v, int)}


class InputOrder:
    """Per-topic order check: drop duplicated or out-of-order messages and stamps that go back.

    A publisher that restarts begins again at seq 0; that is accepted when its stamp does not go
    back (a replayed old seq 0 has an old stamp and is dropped).
    """

    def __init__(self) -> None:
        self.last: dict[str, tuple[int, int]] = {}

    def repeat(self, topic: str, seq: int, stamp_ns: int) -> bool:
        """True for an exact repeat of the last accepted message (same seq and stamp)."""
        return self.last.get(topic) == (seq, stamp_ns)

    def check(self, topic: str, seq: int, stamp_ns: int) -> str | None:
        prev = self.last.get(topic)
        if prev is not None:
            pseq, pstamp = prev
            if stamp_ns < pstamp:
                return f"stamp went backwards: {stamp_ns} < {pstamp} ns (seq {seq})"
            if seq <= pseq and seq != 0:
                return f"duplicate or out-of-order seq {seq} (last {pseq})"
            if seq == 0 and pseq == 0:
                return "duplicate seq 0"
            if seq == 0:
                log.info("%s: seq restarted at 0 (publisher restarted)", topic)
        self.last[topic] = (seq, stamp_ns)
        return None


class Node:
    """One service process on the bus."""

    def __init__(
        self,
        name: str,
        spec: NodeSpec,
        bus_settings: BusSettings,
        mode: Mode,
        config_hash: str = "",
        plan: LockstepPlan | None = None,
    ) -> None:
        self.name, self.spec, self.mode, self.config_hash = name, spec, mode, config_hash
        self.plan = plan or LockstepPlan()
        self.state: ServiceState = "starting"
        self.errors = 0
        self.stop_event = threading.Event()
        self._queue: deque[Queued] = deque()
        self._gate = CausalGate(spec.inputs)
        self._held_since: float | None = None  # when the queue's head started waiting
        self.causal_timeouts = 0
        self._group_attachment: bytes | None = None  # master: of the group last published
        self._noted_before: list[Dep] = []  # master: the answers attached the group before
        self._cv = threading.Condition()
        self._order = InputOrder()
        # topic → (seq, outputs, attachment): a repeat is answered byte for byte
        self._answered: dict[str, tuple[int, Sequence[Output], bytes | None]] = {}
        self._live: set[str] = set()  # consumers whose liveliness is present (clock master)
        self._given_up: set[str] = set()  # consumers left behind after consumer_wait_s
        self._health_cv = threading.Condition()
        self._error_log: set[str] = set()
        self._core: Any = None  # set by the run loop; its ``counters`` (if any) go into status
        self.barrier = AnswerBarrier(self.plan.wait) if mode == "lockstep" else None
        self.bus = Bus(name, bus_settings)
        self._pubs = {k: self.bus.publisher(k) for k in spec.outputs}
        listen = set(spec.inputs) | (self.barrier.topics if self.barrier else set())
        for key in sorted(listen):
            if key != "**":
                self.bus.subscribe(key, self._on_input, with_attachment=True)
        self.bus.serve_status(self.status)

    # ---- lifecycle -------------------------------------------------------------------------
    def ready(self) -> None:
        """Declare health last, so a live token means every subscription is in place."""
        self.state = "running"
        self.bus.declare_health()

    def stop(self) -> None:
        self.stop_event.set()
        with self._cv:
            self._cv.notify_all()

    def close(self) -> None:
        self.state = "stopping"
        self.bus.close()

    def status(self) -> ServiceStatus:
        return ServiceStatus(
            name=self.name,
            version=__version__,
            config_hash=self.config_hash,
            pid=os.getpid(),
            state=self.state,
            mode=self.mode,
            spec=self.spec.model(),
            topics={k: c.frozen() for k, c in sorted(self.bus.counters.items())},
            rejected_unknown=self.bus.rejected_unknown,
            errors=self.errors,
            core_counters=core_counters(self._core),
        )

    # ---- inputs ----------------------------------------------------------------------------
    def _on_input(self, topic: str, msg: Any, attachment: bytes | None = None) -> None:
        header = msg.header
        is_input = topic in self.spec.inputs
        causes = decode_after(attachment) if self.mode == "lockstep" else NO_CAUSES
        with self._cv:
            if is_input:
                repeat = self._order.repeat(topic, header.seq, header.stamp_ns)
                problem = self._order.check(topic, header.seq, header.stamp_ns)
                if problem:
                    self.bus.reject(topic, problem)
                    if repeat and self._reanswers(topic):
                        self._queue.append((_REANSWER, (topic, header.seq), NO_CAUSES))
                        self._cv.notify_all()
                    return
                if self.mode == "live" and topic in self.spec.conflate:
                    self._drop_pending(topic)
                self._gate.arrived(topic, header.stamp_ns, header.seq)
                self._queue.append((topic, msg, causes))
                self._cv.notify_all()
        if self.barrier is not None:
            self.barrier.note(topic, header.stamp_ns, header.seq)

    def _reanswers(self, topic: str) -> bool:
        """Answers to ``topic`` are re-published on a repeat: lock-step, not the clock master
        (it has its own re-send), and ``topic`` has declared answers."""
        return self.mode == "lockstep" and not self.plan.wait and topic in self.spec.answers

    def _drop_pending(self, topic: str) -> None:
        kept = [item for item in self._queue if item[0] != topic]
        if len(kept) != len(self._queue):
            self._queue.clear()
            self._queue.extend(kept)

    def next_queued(self, timeout_s: float | None = None) -> Queued | None:
        """Normally the oldest input; but one whose predecessors have not all arrived waits, and
        a predecessor queued behind it goes first."""
        with self._cv:
            i = self._ready_index()
            if i is None and not self.stop_event.is_set():
                self._cv.wait(timeout=timeout_s)
                i = self._ready_index()
            if i is None:
                return None
            self._held_since = None
            item = self._queue[i]
            del self._queue[i]
            return item

    def _ready_index(self) -> int | None:
        """Index of the input to hand now (under ``_cv``); None while the next one in causal
        order waits for a predecessor (at most ``causal_wait_s``)."""
        while self._queue:
            view = [
                None if t == _REANSWER else (t, m.header.stamp_ns, m.header.seq, c.after)
                for t, m, c in self._queue
            ]
            i, missing = next_in_order(view, self._gate)
            if not missing:
                return i
            topic, msg, _ = self._queue[i]
            if not self._give_up_waiting(topic, msg, missing):
                return None
            self._queue[i] = (topic, msg, NO_CAUSES)
        return None

    def _give_up_waiting(self, topic: str, msg: Any, missing: list[Dep]) -> bool:
        """A predecessor that never comes (lost with a killed router) must not hang us."""
        now = time.monotonic()
        if self._held_since is None:
            self._held_since = now
        if now - self._held_since < self.plan.causal_wait_s:
            return False
        self.causal_timeouts += 1
        log.warning(
            "%s seq %s: predecessors %s did not arrive in %.1f s; handled without them",
            topic,
            msg.header.seq,
            missing,
            self.plan.causal_wait_s,
        )
        self._held_since = None
        return True

    def drain(self) -> list[Output]:
        with self._cv:
            items = [(t, m) for t, m, _ in self._queue]
            self._queue.clear()
            return items

    # ---- outputs ---------------------------------------------------------------------------
    def publish(self, outputs: Sequence[Output], attachment: bytes | None = None) -> None:
        """Publish outputs; ``attachment``: their causal predecessors (lock-step)."""
        for topic, msg in outputs:
            pub = self._pubs.get(topic)
            if pub is None:
                raise RuntimeError(f"{self.name} published undeclared topic {topic!r}")
            pub.put(msg, attachment)

    def call(self, fn: Any, topic: str, msg: Any) -> Sequence[Output]:
        """Run a core handler; an exception is counted and logged once per kind, never fatal."""
        try:
            return fn(topic, msg)
        except Exception as exc:
            self.errors += 1
            kind = f"{topic}:{type(exc).__name__}"
            if kind not in self._error_log:
                self._error_log.add(kind)
                log.exception(
                    "core failed on %s seq %s (counted; later ones of this kind are not logged)",
                    topic,
                    getattr(msg.header, "seq", "?"),
                )
            return ()

    # ---- loops -----------------------------------------------------------------------------
    def run_reactive(self, core: Core) -> None:
        """Hand every input to the core in arrival order until stopped; in live mode also call
        the core's timer (``TimedCore``) when it is due, between inputs."""
        timer = timer_of(core, self.mode)
        next_due = time.monotonic() + (timer[1] if timer else 0.0)
        self._core = core
        done = getattr(core, "done", None)
        while not self.stop_event.is_set():
            wait_s = 0.2 if timer is None else min(0.2, max(0.0, next_due - time.monotonic()))
            item = self.next_queued(timeout_s=wait_s)
            if item is not None:
                self._handle(core, *item)
                if done is not None and done():
                    log.info("core finished: stopping")
                    self.stop_event.set()
                    break
            if timer is not None and time.monotonic() >= next_due:
                fn, period_s = timer
                # Fixed phase, but never a burst of catch-up calls after a long input.
                next_due = max(next_due + period_s, time.monotonic())
                self.publish(self._call_timer(fn))

    def _handle(self, core: Core, topic: str, msg: Any, causes: Causes = NO_CAUSES) -> None:
        """One input: the core's outputs are published (and kept, to answer a repeat). In
        lock-step they carry the input's predecessors, its group and the input itself."""
        if topic == _REANSWER:
            key, seq = msg
            done = self._answered.get(key)
            if done is not None and done[0] == seq:
                log.info("%s seq %d came again (re-sent tick): answer published again", key, seq)
                self.publish(done[1], done[2])
            return
        outputs = self.call(core.handle, topic, msg)
        attachment = None
        if self.mode == "lockstep":
            answered = (topic, msg.header.stamp_ns, msg.header.seq)
            attachment = encode_after(causes.of_answer(answered))
        self.publish(outputs, attachment)
        if self._reanswers(topic):
            self._answered[topic] = (msg.header.seq, outputs, attachment)

    def _call_timer(self, fn: Any) -> Sequence[Output]:
        """Run the core's timer; an exception is counted and logged once, never fatal."""
        try:
            return fn(time.monotonic_ns())
        except Exception:
            self.errors += 1
            if "timer" not in self._error_log:
                self._error_log.add("timer")
                log.exception("core timer failed (counted; later failures are not logged)")
            return ()

    def run_source(self, core: SourceCore, speed: float = 1.0) -> None:
        """Clock-master loop: emit a tick's groups, wait for their answers, feed inputs, advance.

        In live mode nothing is awaited and sim time is paced by the wall clock × ``speed``.
        """
        self._await_consumers()
        if self.barrier is not None and self.plan.consumers and self.plan.consumer_wait_s > 0:
            self.bus.watch_health(self._on_consumer_health)
        wall0, sim0 = time.monotonic(), core.now_ns()
        while not self.stop_event.is_set() and not core.done():
            self._pause_for_consumers()
            try:
                for group in core.emit():
                    self._publish_group(group)
                    self._feed(core)
            except LockstepStopped as exc:
                log.info("stopped while awaiting answers (%s)", exc)
                return
            core.advance()
            if self.mode == "live":
                lag = (core.now_ns() - sim0) * 1e-9 / speed - (time.monotonic() - wall0)
                if lag > 0:
                    self.stop_event.wait(lag)
        self._feed(core)

    def _publish_group(self, group: Sequence[Output]) -> None:
        if self.barrier is None:
            self.publish(group)
            return
        # The answers awaited since the previous group caused this one: consumers take them
        # first. Those of the group before are added: a consumer that does not take the
        # answers between (the controller, no camera frames) still waits for the older ones.
        noted = self.barrier.take_noted()
        group_deps = [(t, m.header.stamp_ns, m.header.seq) for t, m in group]
        attachment = encode_after([*self._noted_before, *noted], group_deps)
        self._noted_before = noted
        self._group_attachment = attachment
        self.publish(group, attachment)
        for topic, msg in group:
            self.barrier.expect(topic, msg.header.stamp_ns)
        try:
            self.barrier.wait(
                lambda: self._resend(group),
                self.plan.resend_after_s,
                self.plan.stall_timeout_s,
                self._describe_missing_now,
                self.stop_event.is_set,
            )
        except LockstepStall:
            self.state = "failed"
            raise

    def _resend(self, group: Sequence[Output]) -> None:
        log.warning(
            "lock-step: %s; re-publishing the tick",
            self._describe_missing(self.barrier.missing() if self.barrier else []),
        )
        self.publish(group, self._group_attachment)

    def _describe_missing_now(self, missing: list[tuple[str, int]]) -> str:
        """The stall message; on stop, only the missing answers (no liveliness query)."""
        if self.stop_event.is_set():
            return ", ".join(f"{t} @ {s} ns" for t, s in missing)
        return self._describe_missing(missing)

    def _describe_missing(self, missing: list[tuple[str, int]]) -> str:
        live = set(self.bus.live_services(timeout_s=0.3))
        dead = [c for c in self.plan.consumers if c not in live]
        parts = ", ".join(f"{t} @ {s} ns" for t, s in missing)
        tail = f"; consumers not live: {', '.join(dead)}" if dead else ""
        return f"no answer yet on {parts}{tail}"

    def _feed(self, core: SourceCore) -> None:
        for topic, msg in self.drain():
            self.publish(self.call(core.handle, topic, msg))

    def _on_consumer_health(self, name: str, alive: bool) -> None:
        with self._health_cv:
            if alive:
                self._live.add(name)
                self._given_up.discard(name)
            else:
                self._live.discard(name)
            self._health_cv.notify_all()

    def _pause_for_consumers(self) -> None:
        """Lock-step, between ticks: while a consumer is down (a restart takes about a second)
        publish nothing it would miss, so a restarted recorder loses only its unflushed tail.
        One that stays down longer than ``consumer_wait_s`` (failed for good) is left behind."""
        if self.barrier is None or self.plan.consumer_wait_s <= 0:
            return
        with self._health_cv:
            missing = [c for c in self.plan.consumers if c not in self._live | self._given_up]
            if not missing:
                return
            log.warning("lock-step: paused, waiting for %s to be live again", ", ".join(missing))
            deadline = time.monotonic() + self.plan.consumer_wait_s
            while not self.stop_event.is_set():
                missing = [c for c in missing if c not in self._live]
                left = deadline - time.monotonic()
                if not missing or left <= 0:
                    break
                self._health_cv.wait(min(left, 0.05))
            if missing:
                self._given_up.update(missing)
                log.warning(
                    "lock-step: going on without %s (not live after %.1f s)",
                    ", ".join(missing),
                    self.plan.consumer_wait_s,
                )
            else:
                log.info("lock-step: every consumer is live again, resuming")

    def _await_consumers(self, timeout_s: float = 60.0) -> None:
        """Before tick 0: every declared consumer must be live (its subscriptions are up)."""
        if not self.plan.consumers:
            return
        deadline = time.monotonic() + timeout_s
        while not self.stop_event.is_set():
            live = set(self.bus.live_services(timeout_s=0.5))
            missing = [c for c in self.plan.consumers if c not in live]
            if not missing:
                return
            if time.monotonic() > deadline:
                raise LockstepStall(f"consumers never came up: {', '.join(missing)}")
            self.stop_event.wait(0.05)
