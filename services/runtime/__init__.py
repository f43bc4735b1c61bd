"""Service runtime: specs, settings, the Node around a pure core, lock-step and the entry point."""

from services.runtime.lockstep import AnswerBarrier, LockstepPlan, LockstepStall, LockstepStopped
from services.runtime.node import Core, Mode, Node, Output, SourceCore, TimedCore
from services.runtime.service import ConfigError, ServiceDef, run_service
from services.runtime.settings import ServiceSettings, SettingsError, config_hash, load_settings
from services.runtime.spec import NodeSpec, answer_closure
from services.runtime.stamp import Stamper

__all__ = [
    "AnswerBarrier",
    "ConfigError",
    "Core",
    "LockstepPlan",
    "LockstepStall",
    "LockstepStopped",
    "Mode",
    "Node",
    "NodeSpec",
    "Output",
    "ServiceDef",
    "ServiceSettings",
    "SettingsError",
    "SourceCore",
    "Stamper",
    "TimedCore",
    "answer_closure",
    "config_hash",
    "load_settings",
    "run_service",
]
