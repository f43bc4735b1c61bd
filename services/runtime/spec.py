"""A service's declared graph interface, and the lock-step answer closure computed from specs."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from schemas.service import NodeSpecModel
from schemas.topics import TOPICS


@dataclass(frozen=True)
class NodeSpec:
    """Inputs, outputs, and the outputs published exactly once per input message (answers).

    ``conflate`` names inputs of which only the newest pending message matters in live mode
    (e.g. camera frames for a slow detector); lock-step never drops anything.
    """

    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    answers: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    conflate: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for key in (*self.inputs, *self.outputs):
            if key not in TOPICS and key != "**":
                raise ValueError(f"spec names unknown topic {key!r}")
        for inp, outs in self.answers.items():
            if inp not in self.inputs:
                raise ValueError(f"answers an input it does not take: {inp!r}")
            missing = set(outs) - set(self.outputs)
            if missing:
                raise ValueError(f"answers {inp!r} with undeclared outputs {sorted(missing)}")

    def model(self) -> NodeSpecModel:
        return NodeSpecModel(
            inputs=self.inputs,
            outputs=self.outputs,
            answers={k: tuple(v) for k, v in self.answers.items()},
        )


def answer_closure(topic: str, specs: Iterable[NodeSpecModel | NodeSpec]) -> tuple[str, ...]:
    """Every topic that must carry one answer (same stamp) after one message on ``topic``.

    Follows answers transitively: camera/rgbd → detections → tracks → scene/state.
    """
    specs = list(specs)
    done: list[str] = []
    frontier = [topic]
    while frontier:
        t = frontier.pop(0)
        for s in specs:
            for out in s.answers.get(t, ()):
                if out not in done and out != topic:
                    done.append(out)
                    frontier.append(out)
    return tuple(done)


def answer_maps(
    topics: Iterable[str], specs: Iterable[NodeSpecModel | NodeSpec]
) -> tuple[dict[str, tuple[str, ...]], dict[str, tuple[str, ...]]]:
    """Per topic, its answer closure and the outputs beside its answers (the lock-step player's
    ``caused_by`` and ``alongside``)."""
    specs, topics = list(specs), list(topics)
    closure = {t: answer_closure(t, specs) for t in topics}
    return closure, {t: answered_alongside(t, specs) for t in topics}


def answered_alongside(topic: str, specs: Iterable[NodeSpecModel | NodeSpec]) -> tuple[str, ...]:
    """The other outputs of the services that answer ``topic`` (transitively), which they may
    publish beside an answer (the planner's events beside its target). No one awaits them:
    a service publishes them only when it has something to say."""
    specs = list(specs)
    closure = answer_closure(topic, specs)
    out: list[str] = []
    for s in specs:
        if any(t in s.outputs for t in closure):
            out += [t for t in s.outputs if t not in closure and t not in out and t != topic]
    return tuple(out)
