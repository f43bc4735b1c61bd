"""The bus between real processes on loopback: pub/sub, liveliness, status, rejections,
namespaces, endpoint errors."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from schemas import DemoAnswer, DemoTick, Header
from services.bus import Bus, BusError
from tests.helpers import BusEnv, wait_until

pytestmark = pytest.mark.integration


def tick(i: int, stamp: int | None = None) -> DemoTick:
    h = Header(stamp_ns=stamp if stamp is not None else 1000 * i, seq=i, source="test")
    return DemoTick(header=h, tick=i, value=0.25)


class Inbox:
    def __init__(self) -> None:
        self.items: list[object] = []
        self.lock = threading.Lock()

    def __call__(self, key: str, msg: object) -> None:
        with self.lock:
            self.items.append(msg)

    def __len__(self) -> int:
        return len(self.items)


def start_worker(env: BusEnv) -> subprocess.Popen[bytes]:
    p = env.service("services.demo_worker", "--set", "max_delay_ms=0", log="worker.log")
    probe = env.client("probe")
    wait_until(lambda: "demo_worker" in probe.live_services(0.3), 20, "worker liveliness")
    return p


def test_typed_publish_subscribe_through_a_service(bus_env: BusEnv) -> None:
    start_worker(bus_env)
    me = bus_env.client("tester")
    inbox = Inbox()
    me.subscribe("demo/answer", inbox)
    pub = me.publisher("demo/tick")
    for i in range(5):
        pub.put(tick(i))
    wait_until(lambda: len(inbox) == 5, 10, "5 answers")
    answers = [a for a in inbox.items if isinstance(a, DemoAnswer)]
    assert [a.tick for a in answers] == list(range(5))
    assert [a.header.answers_seq for a in answers] == list(range(5))
    assert [a.header.stamp_ns for a in answers] == [1000 * i for i in range(5)]


def test_liveliness_up_and_down(bus_env: BusEnv) -> None:
    watcher = bus_env.client("watcher")
    events: list[tuple[str, bool]] = []
    watcher.watch_health(lambda n, up: events.append((n, up)))
    p = start_worker(bus_env)
    wait_until(lambda: ("demo_worker", True) in events, 10, "PUT of the token")
    t0 = time.monotonic()
    os.killpg(p.pid, signal.SIGKILL)
    wait_until(lambda: ("demo_worker", False) in events, 5, "DELETE of the token")
    assert time.monotonic() - t0 < 2.0
    assert "demo_worker" not in watcher.live_services(0.3)


def test_status_counts_and_rejects_malformed_payloads(bus_env: BusEnv) -> None:
    start_worker(bus_env)
    me = bus_env.client("tester")
    inbox = Inbox()
    me.subscribe("demo/answer", inbox)
    pub = me.publisher("demo/tick")
    pub.put(tick(0))
    me.put_raw("demo/tick", b"\x00\x01 not json", "application/json;DemoTick")
    me.put_raw(
        "demo/tick",
        b'{"header": {"stamp_ns": 5, "seq": 1, "source": "x"}, "tick": -3, "value": 1.0}',
        "application/json;DemoTick",
    )
    me.put_raw(
        "demo/tick",
        b'{"header": {"stamp_ns": 5, "seq": 1, "source": "x"}, "tick": 1, '
        b'"value": 1.0, "surprise": 1}',
        "application/json;DemoTick",
    )
    pub.put(tick(1))
    wait_until(lambda: len(inbox) == 2, 10, "answers to the two valid ticks")
    status = wait_until(
        lambda: [s for s in me.query_status("demo_worker") if s.topics["demo/tick"].rejected == 3],
        5,
        "3 rejections",
    )
    st = status[0]  # type: ignore[index]
    c = st.topics["demo/tick"]
    assert (c.received, c.rejected, c.last_seq) == (2, 3, 1)
    assert "extra" in c.last_reject_reason.lower() or "surprise" in c.last_reject_reason
    assert st.topics["demo/answer"].published == 2
    assert st.state == "running" and st.spec.answers == {"demo/tick": ("demo/answer",)}
    log = bus_env.log("worker.log")
    assert log.count("rejected a payload on 'demo/tick'") == 1  # logged once per key


def test_duplicates_and_backwards_stamps_are_dropped_and_counted(bus_env: BusEnv) -> None:
    start_worker(bus_env)
    me = bus_env.client("tester")
    inbox = Inbox()
    me.subscribe("demo/answer", inbox)
    pub = me.publisher("demo/tick")
    for m in (tick(0), tick(1), tick(1), tick(2, stamp=10), tick(3)):
        pub.put(m)
    wait_until(lambda: len(inbox) == 3, 10, "three answers")
    st = wait_until(lambda: me.query_status("demo_worker"), 5, "status")[0]  # type: ignore[index]
    assert st.topics["demo/tick"].rejected == 2
    assert [a.tick for a in inbox.items] == [0, 1, 3]  # type: ignore[attr-defined]


def test_namespaces_do_not_cross_talk(bus_env: BusEnv) -> None:
    a = bus_env.client("a")
    other = bus_env.client("b", namespace=bus_env.namespace + "-other")
    got_other, got_same = Inbox(), Inbox()
    other.subscribe("demo/tick", got_other)
    same = bus_env.client("c")
    same.subscribe("demo/tick", got_same)
    pub = a.publisher("demo/tick")
    wait_until(lambda: (pub.put(tick(len(got_same))), len(got_same) >= 3)[1], 10, "delivery")
    assert len(got_other) == 0


def test_unknown_topic_cannot_be_published(bus_env: BusEnv) -> None:
    with pytest.raises(KeyError, match="unknown topic 'demo/nope'"):
        bus_env.client("x").publisher("demo/nope")


def test_endpoint_already_in_use_is_a_clear_error(bus_env: BusEnv) -> None:
    r = subprocess.run(
        [sys.executable, "-m", "services.router", "-l", bus_env.endpoint],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert r.returncode == 2
    assert "address already in use" in r.stderr


def test_client_without_router_is_a_clear_error() -> None:
    from services.bus import BusSettings

    with pytest.raises(BusError, match="is the router running"):
        Bus("x", BusSettings(connect=("unixsock-stream//tmp/definitely-not-here.sock",)))
