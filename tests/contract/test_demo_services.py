"""Contract tests of the demo services with the foundation's kit (the pattern for every service)."""

from __future__ import annotations

import pytest

from schemas import DemoTick
from services.demo_clock import SERVICE as CLOCK
from services.demo_worker import SERVICE as WORKER
from services.runtime.settings import load_settings
from services.testkit import ContractCase, FakeNode, assert_contract, run_source
from tests.unit.test_schemas import header


def ticks(n: int) -> list[tuple[str, DemoTick]]:
    return [
        (
            "demo/tick",
            DemoTick(
                header=header(stamp_ns=10 * i, seq=i, source="demo_clock"), tick=i, value=0.1 * i
            ),
        )
        for i in range(n)
    ]


def test_worker_contract() -> None:
    settings = load_settings(WORKER.settings, {"max_delay_ms": 0})
    outs = assert_contract(ContractCase(WORKER, settings, inputs=ticks(20)))
    assert [o.msg.tick for o in outs] == list(range(20))


def test_worker_drops_duplicated_and_out_of_order_ticks() -> None:
    settings = load_settings(WORKER.settings, {"max_delay_ms": 0})
    node = FakeNode(WORKER, settings)
    script = ticks(3)
    outs = node.feed([script[0], script[1], script[1], script[0], script[2]])
    assert [o.msg.tick for o in outs] == [0, 1, 2]
    assert [i for i, _ in node.dropped] == [2, 3]


def test_kit_catches_a_service_that_does_not_carry_stamps(monkeypatch: pytest.MonkeyPatch) -> None:
    """The kit's checks can fail: a worker that stamps its own time is caught."""
    from services.demo_worker import core as worker_core

    original = worker_core.DemoWorkerCore.handle

    def bad(self, topic, msg):
        ((t, ans),) = original(self, topic, msg)
        h = ans.header.model_copy(update={"stamp_ns": ans.header.stamp_ns + 1})
        return [(t, ans.model_copy(update={"header": h}))]

    monkeypatch.setattr(worker_core.DemoWorkerCore, "handle", bad)
    with pytest.raises(AssertionError, match="copy the input stamp"):
        assert_contract(
            ContractCase(
                WORKER, load_settings(WORKER.settings, {"max_delay_ms": 0}), inputs=ticks(3)
            )
        )


def test_clock_in_lockstep_with_a_fake_worker_is_deterministic() -> None:
    settings = load_settings(CLOCK.settings, {"ticks": 30})
    wsettings = load_settings(WORKER.settings, {"max_delay_ms": 0})

    def run() -> list[bytes]:
        worker = FakeNode(WORKER, wsettings)

        def respond(topic, msg):
            return [(o.topic, o.msg) for o in worker.feed([(topic, msg)])]

        return [o.msg.model_dump_json().encode() for o in run_source(CLOCK, settings, respond)]

    a, b = run(), run()
    assert len(a) == 30 and a == b
    values = {DemoTick.model_validate_json(x).value for x in a}
    assert len(values) > 20  # the feedback loop really changes the state
