"""The one topic map: key expression (relative to the run's namespace) → message type and codec."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from schemas.codec import Codec, JsonCodec, RgbdCodec
from schemas.control import ControllerDiagnostics, ControlStatus, PlanTarget
from schemas.harvest import HarvestEvent, RunSummary
from schemas.perception import Detections, Tracks
from schemas.robot import BasketState, JointState, JointVelocityCommand, ToolCommand
from schemas.scene import SceneState
from schemas.service import DemoAnswer, DemoTick, ServiceStatus
from schemas.sim import GroundTruth, SimEvent


@dataclass(frozen=True)
class Topic:
    """One topic of the graph: its key, codec and a line saying what flows on it.

    ``deterministic`` is False for wall-clock diagnostics (timings): their payloads differ from
    run to run by design, so resim and the determinism checks report them as not compared.
    """

    key: str
    codec: Codec[Any]
    description: str
    deterministic: bool = True

    @property
    def schema_name(self) -> str:
        return self.codec.schema_name


def _t(key: str, codec: Codec[Any], description: str, deterministic: bool = True) -> Topic:
    return Topic(key, codec, description, deterministic)


TOPICS: dict[str, Topic] = {
    t.key: t
    for t in (
        _t("camera/rgbd", RgbdCodec(), "RGB-D frames of the head camera (15 Hz)."),
        _t("robot/joint_state", JsonCodec(JointState), "Joint state, one per control tick."),
        _t("robot/command", JsonCodec(JointVelocityCommand), "Joint velocities per tick."),
        _t("robot/tool", JsonCodec(ToolCommand), "Tool actions (cut / open)."),
        _t(
            "robot/basket",
            JsonCodec(BasketState),
            "Basket load cell: load and fruit count (with the joint state, 15 Hz).",
        ),
        _t("perception/detections", JsonCodec(Detections), "Detections, one per frame."),
        _t("perception/tracks", JsonCodec(Tracks), "Tracks, one per Detections."),
        _t("scene/state", JsonCodec(SceneState), "Fruit list, trunk, obstacles, selection."),
        _t("plan/target", JsonCodec(PlanTarget), "Planner goal for both arms."),
        _t("control/status", JsonCodec(ControlStatus), "Controller errors, distances, flags."),
        _t(
            "diag/controller",
            JsonCodec(ControllerDiagnostics),
            "Controller timings and counters per tick (wall clock: not compared in resim).",
            deterministic=False,
        ),
        _t("harvest/events", JsonCodec(HarvestEvent), "Harvest state-machine events."),
        _t("harvest/summary", JsonCodec(RunSummary), "Run summary, once at the end."),
        _t("sim/truth", JsonCodec(GroundTruth), "Ground truth per camera frame (evaluation)."),
        _t("sim/events", JsonCodec(SimEvent), "Contacts, cuts, falls, collections (evaluation)."),
        _t("demo/tick", JsonCodec(DemoTick), "Demo clock ticks (foundation lock-step demo)."),
        _t("demo/answer", JsonCodec(DemoAnswer), "Demo worker answers."),
    )
}

STATUS_MODEL = ServiceStatus
"""Reply type of the ``svc/<name>/status`` queryable (not a topic)."""


class UnknownTopicError(KeyError):
    """A key that is not in the topic map."""

    def __str__(self) -> str:
        return f"unknown topic {self.args[0]!r}; known: {', '.join(sorted(TOPICS))}"


def topic(key: str) -> Topic:
    """The Topic for ``key``; raises UnknownTopicError naming the known keys."""
    try:
        return TOPICS[key]
    except KeyError:
        raise UnknownTopicError(key) from None
