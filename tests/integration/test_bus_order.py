"""Samples of different keys from one publisher reach a process's callbacks in the order they
were sent (the lock-step guarantee for services with several inputs, e.g. the controller)."""

from __future__ import annotations

import threading
from typing import Any

import pytest

from schemas import DemoAnswer, DemoTick, Header
from tests.helpers import BusEnv, wait_until

pytestmark = pytest.mark.integration
N = 600


def test_two_keys_keep_their_interleaving_under_gil_contention(bus_env: BusEnv) -> None:
    got: list[tuple[str, float]] = []
    lock = threading.Lock()

    def on(key: str, msg: Any) -> None:
        with lock:
            got.append((key, msg.value if key == "demo/tick" else msg.result))

    sub = bus_env.client("sub")
    sub.subscribe("demo/tick", on)
    sub.subscribe("demo/answer", on)
    stop = threading.Event()

    def burn() -> None:  # a busy core holding the GIL, as a controller mid-solve does
        while not stop.is_set():
            sum(range(2000))

    burner = threading.Thread(target=burn)
    burner.start()
    try:
        pub = bus_env.client("pub")
        tick, answer = pub.publisher("demo/tick"), pub.publisher("demo/answer")
        h0 = Header(stamp_ns=0, seq=0, source="pub")

        def both_routes_up() -> bool:  # subscriptions reach the router asynchronously
            tick.put(DemoTick(header=h0, tick=0, value=-1.0))  # -1: warm-up, left out below
            answer.put(DemoAnswer(header=h0, tick=0, result=-1.0, worker_state=0))
            with lock:
                return {"demo/tick", "demo/answer"} <= {k for k, _ in got}

        wait_until(both_routes_up, 10, "both subscriptions routed")
        for i in range(N):
            h = Header(stamp_ns=i, seq=i, source="pub")
            tick.put(DemoTick(header=h, tick=i, value=float(i)))
            answer.put(DemoAnswer(header=h, tick=i, result=float(i), worker_state=0))
        # Not a speed check: with the burner holding the GIL, each put and each callback can
        # wait a whole switch interval (5 ms) for it, ~4,800 waits = 24 s at worst (CI once
        # took more than 20 s). The order below is the test.
        wait_until(lambda: sum(v >= 0 for _, v in got) == 2 * N, 120, f"{2 * N} samples")
    finally:
        stop.set()
        burner.join()
    order = [(k, v) for k, v in got if v >= 0]
    assert order == [(k, float(i)) for i in range(N) for k in ("demo/tick", "demo/answer")]
