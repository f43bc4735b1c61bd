"""The contract between services: message models, the topic map, codecs and JSON Schema export."""

from schemas.base import ARM_ROLES, ArmRole, Frozen, Header, Message, Pose
from schemas.camera import CameraIntrinsics, RgbdFrame, RgbdFrameMeta
from schemas.codec import DecodeError
from schemas.control import (
    AbsoluteTarget,
    ControllerDiagnostics,
    ControlStatus,
    PlanTarget,
    RelativeTarget,
)
from schemas.harvest import FruitResult, HarvestEvent, RunSummary
from schemas.perception import Detection, Detections, Track, Tracks
from schemas.robot import (
    ArmJointState,
    ArmJointVelocity,
    JointState,
    JointVelocityCommand,
    ToolCommand,
)
from schemas.scene import (
    CylinderObstacle,
    EllipsoidObstacle,
    Fruit,
    Obstacles,
    SceneState,
    SphereObstacle,
    Trunk,
)
from schemas.service import DemoAnswer, DemoTick, NodeSpecModel, ServiceStatus, TopicCounters
from schemas.sim import FruitTruth, GroundTruth, SimCounters, SimEvent, TrunkTruth
from schemas.topics import TOPICS, Topic, UnknownTopicError, topic

__all__ = [
    "ARM_ROLES",
    "TOPICS",
    "AbsoluteTarget",
    "ArmJointState",
    "ArmJointVelocity",
    "ArmRole",
    "CameraIntrinsics",
    "ControlStatus",
    "ControllerDiagnostics",
    "CylinderObstacle",
    "DecodeError",
    "DemoAnswer",
    "DemoTick",
    "Detection",
    "Detections",
    "EllipsoidObstacle",
    "Frozen",
    "Fruit",
    "FruitResult",
    "FruitTruth",
    "GroundTruth",
    "HarvestEvent",
    "Header",
    "JointState",
    "JointVelocityCommand",
    "Message",
    "NodeSpecModel",
    "Obstacles",
    "PlanTarget",
    "Pose",
    "RelativeTarget",
    "RgbdFrame",
    "RgbdFrameMeta",
    "RunSummary",
    "SceneState",
    "ServiceStatus",
    "SimCounters",
    "SimEvent",
    "SphereObstacle",
    "ToolCommand",
    "Topic",
    "TopicCounters",
    "Track",
    "Tracks",
    "Trunk",
    "TrunkTruth",
    "UnknownTopicError",
    "topic",
]
