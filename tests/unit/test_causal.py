"""Causal order in lock-step: predecessors in attachments, a consumer's gate, the next input."""

from __future__ import annotations

from services.runtime.causal import (
    NO_CAUSES,
    CausalGate,
    Causes,
    Entry,
    decode_after,
    encode_after,
    next_in_order,
)

TARGET_0 = ("plan/target", 100, 0)


def _gate(*arrived: tuple[str, int, int]) -> CausalGate:
    g = CausalGate(("robot/joint_state", "plan/target", "scene/state"))
    for a in arrived:
        g.arrived(*a)
    return g


def test_after_round_trips_and_bad_attachments_are_no_constraint() -> None:
    after = [("scene/state", 200, 3), TARGET_0]
    group = [("robot/joint_state", 200, 1), ("robot/basket", 200, 0)]
    assert decode_after(encode_after(after)) == Causes(tuple(sorted(after)))
    assert decode_after(encode_after(after, group)) == Causes(
        tuple(sorted(after)), tuple(sorted(group))
    )
    assert encode_after([]) is None
    for bad in (None, b"", b"not json", b'{"x": 1}', b'{"after": [[1]]}', b"[1]"):
        assert decode_after(bad) == NO_CAUSES


def test_an_answer_follows_the_whole_group_of_what_it_answers() -> None:
    # The control status answering the joint state must come after the basket published with
    # that joint state (the planner takes both), though the basket does not precede the joint
    # state itself.
    js, basket = ("robot/joint_state", 200, 1), ("robot/basket", 200, 0)
    c = Causes(after=(TARGET_0,), group=(js, basket))
    assert set(c.of_answer(js)) == {TARGET_0, js, basket}
    g = CausalGate(("control/status", "robot/basket", "robot/joint_state"))
    g.arrived("robot/joint_state", 200, 1)
    g.arrived("control/status", 200, 1)
    status: Entry = ("control/status", 200, 1, c.of_answer(js))
    assert next_in_order([status], g) == (0, [basket])
    g.arrived(*basket)
    assert next_in_order([status, (*basket, ())], g) == (1, [])


def test_a_predecessor_on_an_input_is_missing_until_it_arrives() -> None:
    g = _gate(("robot/joint_state", 100, 0))
    assert g.missing([TARGET_0]) == [TARGET_0]
    g.arrived("plan/target", 100, 0)
    assert g.missing([TARGET_0]) == []


def test_predecessors_on_other_topics_or_before_our_first_input_are_not_awaited() -> None:
    # control/status is not an input; a target stamped before our first input is history
    # (a restarted service never saw it).
    g = _gate(("robot/joint_state", 200, 0))
    assert g.missing([("control/status", 200, 0), TARGET_0]) == []


def test_the_joint_state_that_overtook_its_target_waits_and_the_target_goes_first() -> None:
    # The router delivered the joint state of tick 1 before the target answering tick 0.
    js1: Entry = ("robot/joint_state", 200, 1, (TARGET_0,))
    g = _gate(("robot/joint_state", 100, 0), ("robot/joint_state", 200, 1))
    assert next_in_order([js1], g) == (0, [TARGET_0])
    target: Entry = ("plan/target", 100, 0, ())
    g.arrived("plan/target", 100, 0)
    assert next_in_order([js1, target], g) == (1, [])
    assert next_in_order([js1], g) == (0, [])


def test_a_same_stamp_scene_state_goes_before_the_joint_state_it_preceded() -> None:
    scene = ("scene/state", 200, 4)
    js1: Entry = ("robot/joint_state", 200, 1, (scene, TARGET_0))
    g = _gate(
        ("robot/joint_state", 100, 0),
        TARGET_0,
        ("robot/joint_state", 200, 1),
        scene,
    )
    assert next_in_order([js1, (*scene, ())], g) == (1, [])


def test_without_constraints_the_oldest_goes_first_and_markers_pass() -> None:
    g = _gate(("scene/state", 100, 0), ("robot/joint_state", 100, 0))
    q: list[Entry | None] = [("scene/state", 100, 0, ()), ("robot/joint_state", 100, 0, ())]
    assert next_in_order(q, g) == (0, [])
    assert next_in_order([None, *q], g) == (0, [])
