"""The runtime's optional timer hook: a core with ``on_timer`` is called between inputs in live
mode (and what it returns is published), never in lock-step."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from schemas import DemoAnswer, DemoTick, Header
from services.runtime import NodeSpec, Stamper
from services.runtime.node import Node, timer_of
from tests.helpers import BusEnv, wait_until

pytestmark = pytest.mark.integration

SPEC = NodeSpec(inputs=("demo/tick",), outputs=("demo/answer",))


class TimedCore:
    timer_period_s = 0.02

    def __init__(self) -> None:
        self.timer_calls: list[int] = []
        self.inputs = 0
        self.stamper = Stamper("timed")

    def handle(self, topic: str, msg: Any) -> list[tuple[str, Any]]:
        self.inputs += 1
        return []

    def on_timer(self, wall_ns: int) -> list[tuple[str, Any]]:
        self.timer_calls.append(wall_ns)
        h = self.stamper.header("demo/answer", 0)
        return [("demo/answer", DemoAnswer(header=h, tick=0, result=0.0, worker_state=0))]


class PlainCore:
    def handle(self, topic: str, msg: Any) -> list[tuple[str, Any]]:
        return []


def test_the_timer_is_armed_only_in_live_mode_and_only_for_cores_that_have_one() -> None:
    core = TimedCore()
    armed = timer_of(core, "live")
    assert armed is not None and armed[1] == 0.02
    assert timer_of(core, "lockstep") is None
    assert timer_of(PlainCore(), "live") is None


def test_live_node_calls_the_timer_between_inputs_and_publishes_its_outputs(
    bus_env: BusEnv,
) -> None:
    core = TimedCore()
    node = Node("timed", SPEC, bus_env.settings(), "live")
    got: list[DemoAnswer] = []
    me = bus_env.client("probe")
    me.subscribe("demo/answer", lambda key, msg: got.append(msg))
    worker = threading.Thread(target=node.run_reactive, args=(core,))
    worker.start()
    try:
        pub = me.publisher("demo/tick")
        pub.put(DemoTick(header=Header(stamp_ns=0, seq=0, source="t"), tick=0, value=0.0))
        wait_until(lambda: core.inputs == 1 and len(got) >= 5, 10, "an input and 5 timer outputs")
    finally:
        node.stop()
        worker.join(timeout=5)
        node.close()
    calls = core.timer_calls
    # Fixed phase: a late call may be followed by a sooner one (0.2 ms later on a loaded
    # machine, measured), but never a burst of catch-up calls: any two calls apart by one
    # call are at least a period apart, however late each is (the next slot is never before
    # the last call). No upper bound: a loaded machine delays calls.
    spans_ms = [(c - a) / 1e6 for a, c in zip(calls, calls[2:], strict=False)]
    assert len(spans_ms) >= 3 and all(s >= 19.0 for s in spans_ms), spans_ms
