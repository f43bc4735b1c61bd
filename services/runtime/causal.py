"""Causal order in lock-step: the earlier messages a message must not overtake at a consumer.

Zenoh keeps order per publisher only. The router fans a sample out to its subscribers one after
the other, so a message that it *caused* at another publisher can overtake it at a third
service: the planner's target of tick k lets the sim (or the resim player) publish the joint
state of tick k+1, and now and then that joint state reached the controller before the target
(resim of controller + planner: 1 control/status in ~3,000 differed). So a lock-step publisher
attaches to each message its causal predecessors, ``after``: the master the answers it awaited
since its previous group, the resim player the outputs it awaited since its previous publish, a
service the ``after`` of the input it answers plus that input and its ``group``. ``group`` names
the messages published together with a message (the master's group: the joint state, the
basket, the sim's events): they are not predecessors of each other, but they all precede an
answer to any of them (the planner takes the basket before the control status that answers the
joint state published with it). A consumer hands an input to its core only once every
predecessor on a topic it takes has arrived, and hands those first: what a step consumes no
longer depends on arrival order.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

Dep = tuple[str, int, int]  # (topic, stamp_ns, seq) of a message that must be handled first


@dataclass(frozen=True)
class Causes:
    """What a message carries: its predecessors, and the messages published with it."""

    after: tuple[Dep, ...] = ()
    group: tuple[Dep, ...] = ()

    def of_answer(self, answered: Dep) -> tuple[Dep, ...]:
        """The predecessors of an answer to this message (``answered``)."""
        return (*self.after, *self.group, answered)


NO_CAUSES = Causes()


def encode_after(after: Iterable[Dep], group: Iterable[Dep] = ()) -> bytes | None:
    """The Zenoh attachment carrying ``after`` and ``group`` (None when both are empty)."""
    deps, together = sorted(set(after)), sorted(set(group))
    if not deps and not together:
        return None
    out: dict[str, list[Dep]] = {"after": deps}
    if together:
        out["group"] = together
    return json.dumps(out, separators=(",", ":")).encode()


def decode_after(attachment: bytes | None) -> Causes:
    """The causes in an attachment; anything unreadable is no constraint (never a crash)."""
    if not attachment:
        return NO_CAUSES
    try:
        raw = json.loads(attachment)
        after = tuple((str(t), int(s), int(q)) for t, s, q in raw["after"])
        group = tuple((str(t), int(s), int(q)) for t, s, q in raw.get("group", ()))
    except (ValueError, KeyError, TypeError, AttributeError):
        return NO_CAUSES
    return Causes(after, group)


def covers(dep: Dep, topic: str, stamp_ns: int, seq: int) -> bool:
    """True when the message (topic, stamp, seq) is ``dep`` or a later one on its topic."""
    t, s, q = dep
    return topic == t and (stamp_ns > s or (stamp_ns == s and seq >= q))


def precedes(topic: str, stamp_ns: int, seq: int, dep: Dep) -> bool:
    """True when the message (topic, stamp, seq) is ``dep`` or an earlier one on its topic."""
    t, s, q = dep
    return topic == t and (stamp_ns < s or (stamp_ns == s and seq <= q))


class CausalGate:
    """One consumer's view: the newest message that arrived per input topic."""

    def __init__(self, inputs: Iterable[str]) -> None:
        self.inputs = frozenset(inputs)
        self.newest: dict[str, tuple[int, int]] = {}  # topic → (stamp_ns, seq)
        self.first_stamp_ns: int | None = None

    def arrived(self, topic: str, stamp_ns: int, seq: int) -> None:
        """Note an accepted input (called in arrival order, before it is queued)."""
        if self.first_stamp_ns is None:
            self.first_stamp_ns = stamp_ns
        self.newest[topic] = (stamp_ns, seq)

    def missing(self, after: Sequence[Dep]) -> list[Dep]:
        """The predecessors on our inputs that have not arrived. One stamped before our first
        input is history we never saw (a restarted service): it is not awaited."""
        out = []
        for dep in after:
            t, s, _ = dep
            if t not in self.inputs or self.first_stamp_ns is None or s < self.first_stamp_ns:
                continue
            have = self.newest.get(t)
            if have is None or not covers(dep, t, *have):
                out.append(dep)
        return out


Entry = tuple[str, int, int, tuple[Dep, ...]]  # a queued input: (topic, stamp_ns, seq, after)


def next_in_order(queue: Sequence[Entry | None], gate: CausalGate) -> tuple[int, list[Dep]]:
    """Which queued input goes next: the oldest, unless one of its predecessors is queued
    behind it (then that one, following its own predecessors). Returns the index and, when
    that input must still wait, its predecessors that have not arrived. ``None`` entries
    (markers, not messages) have no order constraint and are never anyone's predecessor."""
    i, seen = 0, {0}
    while True:
        entry = queue[i]
        if entry is None:
            return i, []
        missing = gate.missing(entry[3])
        if missing:
            return i, missing
        j = next(
            (
                j
                for j, e in enumerate(queue)
                if j not in seen
                and e is not None
                and any(precedes(e[0], e[1], e[2], d) for d in entry[3])
            ),
            None,
        )
        if j is None:
            return i, []
        seen.add(j)
        i = j
