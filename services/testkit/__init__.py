"""Contract-test kit: a fake node that drives a service core with scripted inputs, and the checks
every service must pass (declared topics, valid schemas, stamps carried, empty input, determinism).

Typical use in a service's contract test::

    from services.testkit import ContractCase, assert_contract
    assert_contract(ContractCase(SERVICE, settings, inputs=script, empty_inputs=[...],
                                 empty_check=lambda outs: ...))
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from schemas.topics import TOPICS
from services.runtime.node import InputOrder, Output
from services.runtime.service import ServiceDef
from services.runtime.settings import ServiceSettings, load_settings


@dataclass(frozen=True)
class Emitted:
    """One output, with the index of the input (or tick) that caused it."""

    cause: int
    topic: str
    msg: Any


class FakeNode:
    """Drives a reactive core exactly as the Node does: order checks, one call per input."""

    def __init__(self, sd: ServiceDef, settings: ServiceSettings | None = None) -> None:
        if sd.make_core is None:
            raise TypeError(f"{sd.name} has no core")
        self.sd = sd
        self.settings = settings or load_settings(sd.settings, service=sd.name)
        self.core = sd.make_core(self.settings)
        self._order = InputOrder()
        self.dropped: list[tuple[int, str]] = []

    def feed(self, inputs: Sequence[Output]) -> list[Emitted]:
        out: list[Emitted] = []
        for i, (topic, msg) in enumerate(inputs):
            if topic not in self.sd.spec.inputs:
                raise AssertionError(f"script feeds {topic!r}, not an input of {self.sd.name}")
            problem = self._order.check(topic, msg.header.seq, msg.header.stamp_ns)
            if problem:
                self.dropped.append((i, problem))
                continue
            out += [Emitted(i, t, m) for t, m in self.core.handle(topic, msg)]
        return out


def run_source(
    sd: ServiceDef,
    settings: ServiceSettings | None,
    respond: Callable[[str, Any], Sequence[Output]],
    max_ticks: int = 10_000,
) -> list[Emitted]:
    """Drive a clock-master core in lock-step with ``respond`` standing in for its consumers."""
    assert sd.make_core is not None
    core = sd.make_core(settings or load_settings(sd.settings, service=sd.name))
    out: list[Emitted] = []
    tick = 0
    while not core.done() and tick < max_ticks:
        for group in core.emit():
            answers: list[Output] = []
            for topic, msg in group:
                out.append(Emitted(tick, topic, msg))
                answers += respond(topic, msg)
            for topic, msg in answers:
                if topic in sd.spec.inputs:
                    out += [Emitted(tick, t, m) for t, m in core.handle(topic, msg)]
        core.advance()
        tick += 1
    return out


# ---- checks -----------------------------------------------------------------------------------
def check_declared_topics(sd: ServiceDef, outputs: Sequence[Emitted]) -> None:
    """Outputs only on the topics the spec declares."""
    bad = sorted({o.topic for o in outputs} - set(sd.spec.outputs))
    assert not bad, f"{sd.name} published undeclared topics {bad}"


def check_schema_valid(outputs: Sequence[Emitted]) -> None:
    """Every output encodes with its topic's codec and decodes back to an equal message."""
    for o in outputs:
        codec = TOPICS[o.topic].codec
        payload = codec.encode(o.msg)
        back = codec.decode(payload)
        assert codec.encode(back) == payload, f"{o.topic} does not round-trip: {o.msg}"


def check_seq_counts_up(outputs: Sequence[Emitted]) -> None:
    """header.seq counts 0, 1, 2, ... per output topic."""
    seqs: dict[str, list[int]] = {}
    for o in outputs:
        seqs.setdefault(o.topic, []).append(o.msg.header.seq)
    for t, s in seqs.items():
        assert s == list(range(len(s))), f"{t}: seq {s[:10]}... is not 0, 1, 2, ..."


def check_stamps_carried(
    sd: ServiceDef,
    inputs: Sequence[Output],
    outputs: Sequence[Emitted],
    dropped: Sequence[int] = (),
) -> None:
    """Each answered input gets exactly one message per answer topic, with its stamp and seq."""
    for i, (topic, msg) in enumerate(inputs):
        if i in dropped:
            continue
        for ans in sd.spec.answers.get(topic, ()):
            got = [o for o in outputs if o.cause == i and o.topic == ans]
            assert len(got) == 1, f"input {i} on {topic}: {len(got)} answers on {ans}, want 1"
            h = got[0].msg.header
            assert h.stamp_ns == msg.header.stamp_ns, f"{ans} did not copy the input stamp"
            assert h.answers_seq == msg.header.seq, f"{ans} does not name the input seq"
            assert h.source == sd.name, f"{ans} header.source {h.source!r} != {sd.name!r}"


def check_deterministic(
    sd: ServiceDef, settings: ServiceSettings | None, inputs: Sequence[Output]
) -> None:
    """Two fresh cores fed the same inputs give byte-identical outputs (wall-clock diagnostics,
    ``Topic.deterministic`` False, must appear on the same ticks but are not compared)."""
    runs = []
    for _ in range(2):
        outs = FakeNode(sd, settings).feed(inputs)
        runs.append(
            [
                (o.cause, o.topic, TOPICS[o.topic].codec.encode(o.msg))
                if TOPICS[o.topic].deterministic
                else (o.cause, o.topic, b"<not compared: wall-clock diagnostics>")
                for o in outs
            ]
        )
    assert runs[0] == runs[1], f"{sd.name}: two runs on the same inputs differ"


@dataclass
class ContractCase:
    """Everything the contract checks need for one service."""

    sd: ServiceDef
    settings: ServiceSettings | None
    inputs: Sequence[Output]
    empty_inputs: Sequence[Output] = ()
    empty_check: Callable[[list[Emitted]], None] | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def assert_contract(case: ContractCase) -> list[Emitted]:
    """Run every check; returns the outputs of the scripted inputs for further assertions."""
    node = FakeNode(case.sd, case.settings)
    outputs = node.feed(case.inputs)
    check_declared_topics(case.sd, outputs)
    check_schema_valid(outputs)
    check_seq_counts_up(outputs)
    check_stamps_carried(case.sd, case.inputs, outputs, [i for i, _ in node.dropped])
    check_deterministic(case.sd, case.settings, case.inputs)
    if case.empty_inputs:
        empty_node = FakeNode(case.sd, case.settings)
        empty_out = empty_node.feed(case.empty_inputs)
        check_declared_topics(case.sd, empty_out)
        check_stamps_carried(case.sd, case.empty_inputs, empty_out)
        if case.empty_check:
            case.empty_check(empty_out)
    return outputs
