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
        wait_until(lambda: core.inputs == 1 and len(got) >= 3, 10, "an input and 3 timer outputs")
    finally:
        node.stop()
        worker.join(timeout=5)
        node.close()
    gaps_ms = [(b - a) / 1e6 for a, b in zip(core.timer_calls, core.timer_calls[1:], strict=False)]
    # About every 20 ms at a fixed phase (a late call is followed by a sooner one), never a
    # burst of catch-up calls back to back (a loaded machine delays calls; no tighter bound).
    assert all(g >= 2 for g in gaps_ms), gaps_ms
