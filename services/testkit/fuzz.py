"""Fuzz kit: malformed payloads and adversarial schema-valid messages for every input of every
registered service, and a driver that feeds them as the bus and the Node would.

What a service promises (ARCHITECTURE.md §2): a payload that does not decode or validate is
rejected and counted, never a crash; a message that validates but is out of order (stamps going
backwards, a duplicated seq) is dropped and counted by the Node; anything else reaches the core,
which must answer without raising and publish only schema-valid messages.

The mutations draw from a ``random.Random``: hypothesis passes its own (``st.randoms()``, so a
failure shrinks), the benchmark a seeded one (``harvest bench faults``). Nothing here imports
zenoh.
"""

from __future__ import annotations

import dataclasses
import json
import math
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import BaseModel, ValidationError

from schemas.codec import DecodeError
from schemas.topics import TOPICS
from services.runtime.node import InputOrder, Output

BAD_FLOATS = (math.nan, math.inf, -math.inf, -1.0, -1e9, 1e9, 1e308, -1e308, 0.0, 5e-324)
BAD_INTS = (-1, 0, 2**31, 2**63 - 1, -(2**63), 10**30)
MANY = 10_000
"""Length a list is blown up to (e.g. 10,000 detections or obstacles)."""


# ---- malformed payloads ------------------------------------------------------------------------
def malformed(payload: bytes, rng: random.Random) -> bytes:
    """A broken copy of a valid payload: random bytes, a truncation, flipped bytes, or (JSON) a
    document with a field removed, added, of the wrong type, or a NaN/Infinity literal."""
    kind = rng.randrange(7)
    if kind == 0:
        return rng.randbytes(rng.randrange(0, 64))
    if kind == 1 or not payload:
        return payload[: rng.randrange(0, max(1, len(payload)))]
    if kind == 2:
        b = bytearray(payload)
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b)
    try:
        doc = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError):
        return payload[::-1]  # a raw frame: its bytes reversed
    if not isinstance(doc, dict) or not doc:
        return b"[]"
    key = rng.choice(sorted(doc))
    if kind == 3:
        del doc[key]
    elif kind == 4:
        doc["unexpected_field"] = 1
    elif kind == 5:
        doc[key] = rng.choice(["text", [], {}, None, True, -1])
    else:
        return json.dumps(_replace_a_number(doc, rng, "NaN"), allow_nan=True).encode()
    return json.dumps(doc).encode()


def _replace_a_number(doc: Any, rng: random.Random, how: str) -> Any:
    paths = [p for p, v in _leaves(doc) if isinstance(v, float | int) and not isinstance(v, bool)]
    if not paths:
        return doc
    path = rng.choice(paths)
    return _set(doc, path, {"NaN": math.nan}.get(how, math.inf))


# ---- adversarial, schema-valid messages --------------------------------------------------------
def _leaves(doc: Any, path: tuple[Any, ...] = ()) -> list[tuple[tuple[Any, ...], Any]]:
    if isinstance(doc, dict):
        return [x for k, v in doc.items() for x in _leaves(v, (*path, k))]
    if isinstance(doc, list | tuple):
        return [x for i, v in enumerate(doc) for x in _leaves(v, (*path, i))]
    return [(path, doc)]


def _lists(doc: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out: list[tuple[Any, ...]] = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _lists(v, (*path, k))
    elif isinstance(doc, list | tuple):
        if doc and not all(isinstance(x, float | int) for x in doc):
            out.append(path)  # a list of records (boxes, fruits, obstacles, ...)
        for i, v in enumerate(doc):
            out += _lists(v, (*path, i))
    return out


def _get(doc: Any, path: tuple[Any, ...]) -> Any:
    for k in path:
        doc = doc[k]
    return doc


def _set(doc: Any, path: tuple[Any, ...], value: Any) -> Any:
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(doc, dict):
        return {**doc, head: _set(doc[head], rest, value)}
    items = list(doc)
    items[head] = _set(items[head], rest, value)
    return items


def _boxes(doc: Any) -> list[tuple[Any, ...]]:
    return [
        p
        for p, _ in _leaves(doc)
        if len(p) > 1 and isinstance(p[-2], str) and p[-2].endswith(("_px", "_m")) and p[-1] == 0
    ]


def adversarial_doc(doc: dict[str, Any], rng: random.Random) -> dict[str, Any]:
    """One to three mutations of a message's JSON document: an extreme or non-finite number, a
    negated number (negative depth, size), an inverted or huge box, a list blown up to 10,000
    entries, or the header's stamp / seq moved."""
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(6)
        if op == 0:
            doc = _replace_leaf(doc, rng, lambda v: rng.choice(BAD_FLOATS + BAD_INTS))
        elif op == 1:
            doc = _replace_leaf(doc, rng, lambda v: -abs(v) - 1.0)
        elif op == 2:
            starts = [p[:-1] for p in _boxes(doc)]
            if starts:
                p = rng.choice(starts)
                box = list(_get(doc, p))
                new = box[::-1] if rng.random() < 0.5 else [x * 1e6 for x in box]
                doc = _set(doc, p, new)
        elif op == 3:
            lists = _lists(doc)
            if lists:
                p = rng.choice(lists)
                items = list(_get(doc, p))
                doc = _set(doc, p, [items[i % len(items)] for i in range(MANY)])
        elif op == 4 and "header" in doc:
            back = rng.choice([1, 10**6, 10**9, doc["header"]["stamp_ns"], -(10**30)])
            stamp = max(0, doc["header"]["stamp_ns"] - back)  # back in time, or far ahead
            doc = {**doc, "header": {**doc["header"], "stamp_ns": stamp}}
        elif op == 5 and "header" in doc:
            seq = rng.choice([0, max(0, doc["header"]["seq"] - 1), doc["header"]["seq"], 2**64])
            doc = {**doc, "header": {**doc["header"], "seq": seq}}
    return doc


def _replace_leaf(doc: Any, rng: random.Random, value: Callable[[Any], Any]) -> Any:
    paths = [p for p, v in _leaves(doc) if isinstance(v, float | int) and not isinstance(v, bool)]
    if not paths:
        return doc
    p = rng.choice(paths)
    return _set(doc, p, value(_get(doc, p)))


def adversarial(msg: BaseModel, rng: random.Random) -> BaseModel | None:
    """An adversarial version of ``msg`` that still validates, or None when the mutation made it
    invalid (then the bus would have rejected it: see ``Outcome.rejected_decode``)."""
    doc = msg.model_dump(mode="python")
    try:
        return type(msg).model_validate(adversarial_doc(doc, rng))
    except (ValidationError, ValueError, TypeError, OverflowError):
        return None


# ---- the driver ---------------------------------------------------------------------------------
@dataclass
class Outcome:
    """What happened to the fuzz cases of one service."""

    cases: int = 0
    rejected_decode: int = 0  # malformed or invalid: the codec refused it (bus: counted)
    dropped_order: int = 0  # duplicated seq or stamp going backwards (Node: counted)
    handled: int = 0  # schema-valid, in order: the core answered
    crashes: list[str] = field(default_factory=list)  # any exception, with its input

    def add(self, other: Outcome) -> None:
        self.cases += other.cases
        self.rejected_decode += other.rejected_decode
        self.dropped_order += other.dropped_order
        self.handled += other.handled
        self.crashes += other.crashes


class FuzzTarget:
    """Feeds payloads to a service as its process would: decode (the bus), order check (the
    Node), then ``handle(topic, msg)`` (the core, or a process-kind service's converter)."""

    def __init__(self, name: str, inputs: Sequence[str], handle: Callable[[str, Any], Any]):
        self.name, self.inputs, self.handle = name, tuple(inputs), handle
        self.order = InputOrder()
        self.outcome = Outcome()
        self._next: dict[str, tuple[int, int]] = {}

    def fresh(self, topic: str, msg: Any) -> Any:
        """``msg`` as the next message of its topic (seq + 1, stamp 1 ms later), so that most
        cases reach the core; the mutations then move stamps and seqs back on purpose."""
        seq, stamp = self._next.get(topic, (0, msg.header.stamp_ns))
        self._next[topic] = (seq + 1, stamp + 1_000_000)
        h = msg.header.model_copy(update={"seq": seq, "stamp_ns": stamp})
        if isinstance(msg, BaseModel):
            return msg.model_copy(update={"header": h})
        return dataclasses.replace(msg, meta=msg.meta.model_copy(update={"header": h}))

    def feed_payload(self, topic: str, payload: bytes) -> None:
        self.outcome.cases += 1
        try:
            msg = TOPICS[topic].codec.decode(payload)
        except DecodeError:
            self.outcome.rejected_decode += 1
            return
        except Exception as exc:  # the codec must only ever raise DecodeError
            self.outcome.crashes.append(f"codec of {topic}: {type(exc).__name__}: {exc}")
            return
        self._feed_msg(topic, msg)

    def feed_message(self, topic: str, msg: Any) -> None:
        """A schema-valid message (None: one the schema refused, counted as rejected)."""
        self.outcome.cases += 1
        if msg is None:
            self.outcome.rejected_decode += 1
            return
        self._feed_msg(topic, msg)

    def _feed_msg(self, topic: str, msg: Any) -> None:
        h = msg.header
        if self.order.check(topic, h.seq, h.stamp_ns) is not None:
            self.outcome.dropped_order += 1
            return
        try:
            outputs = self.handle(topic, msg)
            for t, m in outputs or ():
                TOPICS[t].codec.encode(m)  # an output must still encode (no NaN, valid)
        except Exception as exc:
            self.outcome.crashes.append(
                f"{self.name} on {topic} seq {h.seq}: {type(exc).__name__}: {exc}"[:500]
            )
            return
        self.outcome.handled += 1


def fuzz_step(
    target: FuzzTarget, seeds: Sequence[Output], rng: random.Random, malformed_share: float = 0.4
) -> None:
    """One fuzz case: a seed message of one of the target's inputs, broken or made adversarial."""
    mine = [(t, m) for t, m in seeds if t in target.inputs or "**" in target.inputs]
    topic, msg = rng.choice(mine)
    msg = target.fresh(topic, msg)
    if rng.random() < malformed_share:
        target.feed_payload(topic, malformed(TOPICS[topic].codec.encode(msg), rng))
    elif TOPICS[topic].codec.zenoh_encoding.startswith("application/json"):
        target.feed_message(topic, adversarial(msg, rng))
    else:  # a raw frame: adversarial metadata (pose, intrinsics, header), extreme depth
        meta = adversarial(msg.meta, rng)
        if meta is None:
            target.feed_message(topic, None)
            return
        depth = msg.depth
        if rng.random() < 0.5:
            depth = np.full_like(depth, rng.choice([0, 1, 65535]))
        target.feed_message(topic, dataclasses.replace(msg, meta=meta, depth=depth))
