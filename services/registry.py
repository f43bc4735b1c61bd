"""Every service the supervisor can start, by name → module (imported lazily and cheaply)."""

from __future__ import annotations

import importlib

from services.runtime.service import ServiceDef

SERVICE_MODULES: dict[str, str] = {
    "recorder": "services.recorder",
    "demo_clock": "services.demo_clock",
    "demo_worker": "services.demo_worker",
    "viz": "services.viz",
    "sim": "services.sim",
    "camera_file": "services.camera_file",
    "realsense": "services.realsense",
    "controller": "services.controller",
    "detector": "services.detector",
    "tracker": "services.tracker",
    "planner": "services.planner",
    "scene": "services.scene",
}


class UnknownServiceError(KeyError):
    def __str__(self) -> str:
        return f"unknown service {self.args[0]!r} (known: {', '.join(sorted(SERVICE_MODULES))})"


def service_def(name: str) -> ServiceDef:
    """The ServiceDef of ``name``; its package __init__ must not import heavy modules."""
    if name not in SERVICE_MODULES:
        raise UnknownServiceError(name)
    sd = importlib.import_module(SERVICE_MODULES[name]).SERVICE
    assert isinstance(sd, ServiceDef)
    return sd
