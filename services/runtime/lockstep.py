"""Lock-step barrier of the clock master: wait until every declared answer of a tick has arrived.

The master publishes a group of messages at stamp t and expects, for each message on topic T,
one message with stamp t on every topic of ``plan[T]`` (the answer closure of T). Answers are
counted per (topic, stamp), so two messages at the same stamp (a frame and a joint state) each
get their own answers.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping

from pydantic import BaseModel, ConfigDict, Field


class LockstepPlan(BaseModel):
    """What the master waits for: answers per published topic, and the consumers to await."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    wait: dict[str, tuple[str, ...]] = Field(
        default_factory=dict, description="published topic → answer topics (closure)."
    )
    consumers: tuple[str, ...] = Field(default=(), description="Services live before tick 0.")
    resend_after_s: float = Field(default=2.0, gt=0, description="Re-publish a stalled group.")
    stall_timeout_s: float = Field(default=60.0, gt=0, description="Give up after this, s.")
    consumer_wait_s: float = Field(
        default=5.0,
        ge=0,
        description="A consumer that lost its liveliness mid-run (killed, restarting) pauses the "
        "clock this long at most, so nothing is published it would miss; then the run goes on "
        "without it until it is back (0: never pause), s.",
    )
    causal_wait_s: float = Field(
        default=5.0,
        gt=0,
        description="Consumer: an input waits this long at most for a causal predecessor that "
        "has not arrived (one lost with a killed router); then it is handled without it, s.",
    )


class LockstepStall(RuntimeError):
    """No answer arrived in time; the message lists the missing (topic, stamp) pairs."""


class LockstepStopped(RuntimeError):
    """The wait was abandoned because the process is stopping (not a failure)."""


class AnswerBarrier:
    """Counts answers per (topic, stamp) and blocks until the expected ones are in."""

    def __init__(self, wait: Mapping[str, tuple[str, ...]]) -> None:
        self.wait_map = {k: tuple(v) for k, v in wait.items()}
        self._expected: Counter[tuple[str, int]] = Counter()
        self._received: Counter[tuple[str, int]] = Counter()
        self._seen: set[tuple[str, int, int]] = set()  # (topic, stamp, seq) already counted
        self._noted: list[tuple[str, int, int]] = []  # answers with a seq since take_noted()
        self._cv = threading.Condition()
        self.stalls = 0

    @property
    def topics(self) -> set[str]:
        """Every topic the barrier must listen to."""
        return {t for answers in self.wait_map.values() for t in answers}

    def expect(self, topic: str, stamp_ns: int) -> None:
        """Register that one message on ``topic`` at ``stamp_ns`` was published."""
        with self._cv:
            for t in self.wait_map.get(topic, ()):
                self._expected[(t, stamp_ns)] += 1

    def note(self, topic: str, stamp_ns: int, seq: int | None = None) -> None:
        """Called for every received message on a barrier topic. With ``seq``, a repeat of a
        message already counted (a re-published answer after a re-send) is not counted again."""
        with self._cv:
            if seq is not None:
                key = (topic, stamp_ns, seq)
                if key in self._seen:
                    return
                self._seen.add(key)
                self._noted.append(key)
            self._received[(topic, stamp_ns)] += 1
            self._cv.notify_all()

    def take_noted(self) -> list[tuple[str, int, int]]:
        """The (topic, stamp, seq) of the answers noted since the last call (and forget them):
        the causal predecessors of the next group the master publishes."""
        with self._cv:
            out, self._noted = self._noted, []
            return out

    def missing(self) -> list[tuple[str, int]]:
        with self._cv:
            return self._missing()

    def _missing(self) -> list[tuple[str, int]]:
        return sorted(k for k, n in self._expected.items() if self._received[k] < n)

    def wait(
        self,
        resend: Callable[[], None],
        resend_after_s: float,
        stall_timeout_s: float,
        describe: Callable[[list[tuple[str, int]]], str],
        stopping: Callable[[], bool] = lambda: False,
    ) -> None:
        """Block until nothing is missing. Every ``resend_after_s`` without progress, call
        ``resend`` (consumers drop duplicates, so only the ones that missed it react);
        raise LockstepStall after ``stall_timeout_s``, LockstepStopped as soon as ``stopping()``
        (a run whose main service has finished is stopped while the master awaits answers that
        will never come)."""
        t0 = last = time.monotonic()
        with self._cv:
            while True:
                missing = self._missing()
                if not missing:
                    break
                if stopping():
                    self._expected.clear()
                    raise LockstepStopped(describe(missing))
                now = time.monotonic()
                if now - t0 > stall_timeout_s:
                    raise LockstepStall(describe(missing))
                if now - last > resend_after_s:
                    self.stalls += 1
                    self._cv.release()
                    try:
                        resend()
                    finally:
                        self._cv.acquire()
                    last = time.monotonic()
                self._cv.wait(timeout=min(0.1, resend_after_s))
            # Extras at or before the satisfied stamps (a consumer that answered twice) must not
            # satisfy a later group at the same stamp: forget them.
            newest = max((s for _, s in self._expected), default=-1)
            for k in [k for k in self._received if k[1] <= newest]:
                del self._received[k]
            # Keep the newest stamp's seen answers: a late repeat of one must still be ignored.
            self._seen = {k for k in self._seen if k[1] >= newest}
            self._expected.clear()
