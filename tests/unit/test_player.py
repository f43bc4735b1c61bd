"""The lock-step player: stamp order, the answer barrier, causes before their answers, and the
predecessors it attaches (a fake bus whose 'service' answers each tick at once)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from schemas.base import Header
from schemas.service import DemoAnswer, DemoTick
from schemas.topics import TOPICS
from services.bus import RawSample
from services.recorder.inspect import RecordedMessage
from services.replay.player import OutputCollector, Player, by_stamp
from services.runtime.causal import decode_after

CAUSED_BY = {"demo/tick": ("demo/answer",)}


def _tick(k: int) -> RecordedMessage:
    msg = DemoTick(header=Header(stamp_ns=100 * k, seq=k, source="clock"), tick=k, value=0.0)
    return _rec("demo/tick", msg)


def _tick_at(k: int, stamp_ns: int) -> DemoTick:
    return DemoTick(header=Header(stamp_ns=stamp_ns, seq=k, source="clock"), tick=k, value=0.0)


def _answer(k: int) -> RecordedMessage:
    h = Header(stamp_ns=100 * k, seq=k, source="worker", answers_seq=k)
    return _rec("demo/answer", DemoAnswer(header=h, tick=k, result=0.0, worker_state=k))


def _rec(topic: str, msg: Any) -> RecordedMessage:
    payload = TOPICS[topic].codec.encode(msg)
    return RecordedMessage(topic, payload, 0, msg.header.stamp_ns, msg.header.seq, "")


class FakeBus:
    """Delivers every published tick to a 'worker' that answers it at once (or never)."""

    def __init__(self, answers: bool = True) -> None:
        self.subs: list[Callable[[RawSample], None]] = []
        self.published: list[tuple[str, int, bytes | None]] = []
        self.answers = answers

    def subscribe_raw(self, keyexpr: str, cb: Callable[[RawSample], None]) -> None:
        self.subs.append(cb)

    def put_raw(self, key: str, payload: bytes, encoding: str, attachment: bytes | None) -> None:
        seq = TOPICS[key].codec.header(payload).seq
        self.published.append((key, seq, attachment))
        if self.answers and key == "demo/tick":
            out = _answer(seq)
            for cb in self.subs:
                cb(RawSample(out.topic, out.payload, "", None, 0))


def _play(
    bus: FakeBus,
    messages: list[RecordedMessage],
    timeout_s: float = 5.0,
    caused_by: dict[str, tuple[str, ...]] = CAUSED_BY,
    alongside: dict[str, tuple[str, ...]] | None = None,
) -> Player:
    collector = OutputCollector(bus, ["demo/answer"])  # type: ignore[arg-type]
    player = Player(
        bus,  # type: ignore[arg-type]
        lambda t: t == "demo/tick",
        {"demo/answer"},
        collector,
        timeout_s,
        caused_by=caused_by,
        alongside=alongside,
    )
    player.run(messages)
    return player


def test_an_answer_recorded_before_its_tick_does_not_stall_the_player() -> None:
    # The recorder received answer 1 before tick 1 (two publishers): awaiting it there would
    # wait the whole timeout for a message that only the tick can cause.
    p = _play(FakeBus(), [_tick(0), _answer(0), _answer(1), _tick(1)], timeout_s=1.0)
    assert p.stats.timed_out == 0 and p.stats.awaited == 2 and p.stats.published == 2


def test_each_tick_carries_the_answers_it_waited_for_as_predecessors() -> None:
    bus = FakeBus()
    _play(bus, [_tick(0), _answer(0), _tick(1), _answer(1), _tick(2)])
    after = [decode_after(a).after for _, _, a in bus.published]
    # Tick 2 also names answer 0 (that of the publish before): a consumer that did not take
    # answer 1 still takes answer 0 first.
    assert after == [
        (),
        (("demo/answer", 0, 0),),
        (("demo/answer", 0, 0), ("demo/answer", 100, 1)),
    ]


def test_inputs_published_together_name_each_other_as_their_group() -> None:
    # Two ticks at one stamp with no answer recorded between them: the master's group.
    bus = FakeBus(answers=False)
    _play(bus, [_tick(0), _rec("demo/tick", _tick_at(1, 0))], 0.1)
    groups = [decode_after(a).group for _, _, a in bus.published]
    assert groups == [(("demo/tick", 0, 0), ("demo/tick", 0, 1))] * 2


def _groups(bus: FakeBus) -> list[tuple[int, ...]]:
    return [tuple(q for _, _, q in decode_after(a).group) for _, _, a in bus.published]


def test_a_fast_answer_recorded_amid_the_masters_group_does_not_split_it() -> None:
    # The master published ticks 0 and 1 at once; the worker answered tick 0 before the recorder
    # took tick 1. The group's other answer is not in yet, so tick 1 is still of that group: a
    # consumer must wait for both (the CI failure: the planner stepped without the basket).
    bus = FakeBus()
    late = {"demo/tick": ("demo/answer", "demo/late")}
    p = _play(bus, [_tick(0), _answer(0), _rec("demo/tick", _tick_at(1, 0))], 1.0, late)
    assert _groups(bus) == [(0, 1), (0, 1)] and p.stats.timed_out == 0


def test_an_output_beside_an_answer_does_not_split_the_group_either() -> None:
    # The controller's diagnostics come beside its command; no one awaits them.
    bus = FakeBus()
    p = _play(
        bus,
        [_tick(0), _answer(0), _rec("demo/tick", _tick_at(1, 0))],
        1.0,
        caused_by={"demo/tick": ("demo/late",)},
        alongside={"demo/tick": ("demo/answer",)},
    )
    assert _groups(bus) == [(0, 1), (0, 1)] and p.stats.timed_out == 0


def test_once_every_answer_is_in_the_next_message_of_the_stamp_is_a_new_group() -> None:
    # The master publishes its next group (same stamp) only after the answers to the first.
    bus = FakeBus()
    _play(bus, [_tick(0), _answer(0), _rec("demo/tick", _tick_at(1, 0))], 1.0)
    assert _groups(bus) == [(0,), (1,)]
    assert decode_after(bus.published[1][2]).after == (("demo/answer", 0, 0),)


def test_an_answer_that_never_comes_is_counted_and_the_walk_goes_on() -> None:
    p = _play(FakeBus(answers=False), [_tick(0), _answer(0), _tick(1)], timeout_s=0.2)
    assert p.stats.timed_out == 1 and p.stats.published == 2


def test_stamp_order_puts_a_late_recorded_earlier_tick_first_and_keeps_file_order_within() -> None:
    msgs = [_tick(0), _tick(2), _answer(1), _answer(2), _tick(1)]
    got = [(m.topic, m.publish_time_ns) for m in by_stamp(msgs, window=4)]
    assert got == [
        ("demo/tick", 0),
        ("demo/answer", 100),
        ("demo/tick", 100),
        ("demo/tick", 200),
        ("demo/answer", 200),
    ]
