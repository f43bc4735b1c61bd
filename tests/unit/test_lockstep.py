"""Lock-step barrier and answer closure."""

from __future__ import annotations

import threading
import time

import pytest

from services.runtime.lockstep import AnswerBarrier, LockstepStall, LockstepStopped
from services.runtime.node import InputOrder
from services.runtime.spec import NodeSpec, answer_closure, answered_alongside

CHAIN = [
    NodeSpec(
        inputs=("camera/rgbd",),
        outputs=("perception/detections",),
        answers={"camera/rgbd": ("perception/detections",)},
    ),
    NodeSpec(
        inputs=("perception/detections",),
        outputs=("perception/tracks",),
        answers={"perception/detections": ("perception/tracks",)},
    ),
    NodeSpec(
        inputs=("perception/tracks", "camera/rgbd"),
        outputs=("scene/state",),
        answers={"perception/tracks": ("scene/state",)},
    ),
]


def test_closure_follows_answers_transitively() -> None:
    assert answer_closure("camera/rgbd", CHAIN) == (
        "perception/detections",
        "perception/tracks",
        "scene/state",
    )
    assert answer_closure("robot/joint_state", CHAIN) == ()


def test_the_outputs_beside_the_answers_are_the_answerers_other_outputs() -> None:
    from services.registry import service_def

    specs = [service_def(n).spec for n in ("sim", "controller", "planner")]
    assert answer_closure("robot/joint_state", specs) == (
        "robot/command",
        "control/status",
        "plan/target",
    )
    beside = answered_alongside("robot/joint_state", specs)
    assert set(beside) == {"diag/controller", "robot/tool", "harvest/events", "harvest/summary"}
    assert answered_alongside("camera/rgbd", CHAIN) == ()


def test_spec_refuses_inconsistent_answers() -> None:
    with pytest.raises(ValueError, match="undeclared outputs"):
        NodeSpec(inputs=("demo/tick",), answers={"demo/tick": ("demo/answer",)})
    with pytest.raises(ValueError, match="unknown topic"):
        NodeSpec(inputs=("demo/nope",))


def test_barrier_counts_answers_per_stamp() -> None:
    b = AnswerBarrier({"camera/rgbd": ("scene/state",), "robot/joint_state": ("scene/state",)})
    b.expect("camera/rgbd", 100)
    b.note("scene/state", 100)
    b.wait(lambda: None, 1.0, 1.0, str)
    # A second group at the same stamp needs its own answer, not the first one's.
    b.expect("robot/joint_state", 100)
    assert b.missing() == [("scene/state", 100)]
    t = threading.Timer(0.05, lambda: b.note("scene/state", 100))
    t.start()
    b.wait(lambda: None, 1.0, 2.0, str)
    t.join()


def test_barrier_resends_then_stalls() -> None:
    b = AnswerBarrier({"demo/tick": ("demo/answer",)})
    b.expect("demo/tick", 5)
    resends = []
    with pytest.raises(LockstepStall, match="demo/answer"):
        b.wait(lambda: resends.append(1), 0.05, 0.3, lambda m: f"missing {m}")
    assert len(resends) >= 2


def test_extra_answers_do_not_satisfy_a_later_group() -> None:
    b = AnswerBarrier({"demo/tick": ("demo/answer",)})
    b.expect("demo/tick", 5)
    b.note("demo/answer", 5)
    b.note("demo/answer", 5)  # a consumer that answered twice
    b.wait(lambda: None, 1.0, 1.0, str)
    b.expect("demo/tick", 5)
    assert b.missing() == [("demo/answer", 5)]


def test_input_order_drops_duplicates_and_backwards_stamps() -> None:
    o = InputOrder()
    assert o.check("t", 0, 10) is None
    assert o.check("t", 1, 20) is None
    assert "duplicate" in (o.check("t", 1, 20) or "")
    assert "backwards" in (o.check("t", 2, 5) or "")
    assert "backwards" in (o.check("t", 0, 0) or "")  # an old seq 0 replayed
    assert o.check("t", 0, 30) is None  # publisher restarted: seq 0 with a new stamp
    assert "duplicate" in (o.check("t", 0, 30) or "")
    assert o.check("u", 5, 0) is None  # topics are independent


def test_a_repeated_answer_is_counted_once() -> None:
    """A consumer re-publishes its answer when the master re-sends a stalled tick; the copy that
    arrives after the first one must not satisfy the next group at the same stamp."""
    b = AnswerBarrier({"demo/tick": ("demo/answer",)})
    b.expect("demo/tick", 5)
    b.note("demo/answer", 5, seq=7)
    b.note("demo/answer", 5, seq=7)  # the re-published copy
    b.wait(lambda: None, 1.0, 1.0, str)
    b.expect("demo/tick", 5)
    b.note("demo/answer", 5, seq=7)  # a late copy, after the group was closed
    assert b.missing() == [("demo/answer", 5)]
    b.note("demo/answer", 5, seq=8)
    assert b.missing() == []


def test_input_order_tells_an_exact_repeat() -> None:
    o = InputOrder()
    assert o.check("t", 3, 30) is None
    assert o.repeat("t", 3, 30) and not o.repeat("t", 3, 31) and not o.repeat("u", 3, 30)


def test_barrier_gives_up_at_once_when_the_process_stops() -> None:
    # A run whose main service finished stops the master while it awaits answers that will
    # never come: the wait must end now, not after the stall timeout.
    b = AnswerBarrier({"robot/joint_state": ("plan/target",)})
    b.expect("robot/joint_state", 5)
    stop = threading.Event()
    threading.Timer(0.05, stop.set).start()
    t0 = time.monotonic()
    with pytest.raises(LockstepStopped, match="plan/target @ 5 ns"):
        b.wait(lambda: None, 10.0, 30.0, lambda m: str(m[0][0]) + f" @ {m[0][1]} ns", stop.is_set)
    assert time.monotonic() - t0 < 2.0
    assert b.missing() == []  # the abandoned group is forgotten


def test_core_counters_of_a_mapping_a_dataclass_and_anything_else() -> None:
    from collections import Counter

    from services.controller.core import Counters
    from services.runtime.node import core_counters

    class Core:
        counters: object = None

    c = Core()
    assert core_counters(c) == {}
    c.counters = Counter({"b": 2, "a": 1})
    assert core_counters(c) == {"a": 1, "b": 2}
    c.counters = Counters(watchdog_stops=3)  # the controller's: its status query once failed
    assert core_counters(c)["watchdog_stops"] == 3
    c.counters = "nonsense"
    assert core_counters(c) == {}
