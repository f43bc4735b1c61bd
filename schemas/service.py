"""Service status (the reply of every service's status queryable) and the demo messages."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from schemas.base import FiniteFloat, Frozen, Message

ServiceState = Literal["starting", "running", "stopping", "failed"]


class TopicCounters(Frozen):
    """Message counters of one topic of a service."""

    received: int = Field(default=0, ge=0, description="Messages received and accepted.")
    published: int = Field(default=0, ge=0, description="Messages published.")
    rejected: int = Field(default=0, ge=0, description="Payloads rejected (decode/validation).")
    last_seq: int | None = Field(default=None, description="header.seq of the last message.")
    last_reject_reason: str = Field(default="", description="Reason of the last rejection.")


class NodeSpecModel(Frozen):
    """The declared graph interface of a service: inputs, outputs and which outputs answer what."""

    inputs: tuple[str, ...] = Field(default=(), description="Topics it subscribes to.")
    outputs: tuple[str, ...] = Field(default=(), description="Topics it publishes.")
    answers: dict[str, tuple[str, ...]] = Field(
        default_factory=dict,
        description="input topic → outputs published exactly once per input message.",
    )


class ServiceStatus(Frozen):
    """Status of one running service, as returned by ``svc/<name>/status``."""

    name: str = Field(description="Service name.")
    version: str = Field(description="Package version.")
    config_hash: str = Field(description="SHA-256 (first 16 hex) of the resolved settings JSON.")
    pid: int = Field(description="OS process id.")
    state: ServiceState = Field(description="Lifecycle state.")
    mode: Literal["lockstep", "live"] = Field(description="Time mode.")
    spec: NodeSpecModel = Field(description="Declared inputs, outputs and answers.")
    topics: dict[str, TopicCounters] = Field(default_factory=dict, description="Per-topic counts.")
    rejected_unknown: int = Field(default=0, ge=0, description="Payloads on undeclared keys.")
    errors: int = Field(default=0, ge=0, description="Exceptions raised by the core (counted).")
    core_counters: dict[str, int] = Field(
        default_factory=dict,
        description="Counts the core keeps of inputs it refused or repaired, by reason.",
    )


class DemoTick(Message):
    """Demo clock tick (foundation demo of lock-step): a counter and a value fed back."""

    tick: int = Field(ge=0, description="Tick index.")
    value: FiniteFloat = Field(description="State of the demo clock at this tick.")


class DemoAnswer(Message):
    """Demo worker's answer to a tick (answers demo/tick)."""

    tick: int = Field(ge=0, description="Tick index answered.")
    result: FiniteFloat = Field(description="Worker output, fed back into the clock.")
    worker_state: int = Field(description="Worker's internal accumulator (shows state is kept).")
