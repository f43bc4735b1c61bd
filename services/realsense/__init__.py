"""Intel RealSense D435 camera: colour and aligned depth at 640×480 and 15 Hz as camera/rgbd.

Needs the optional extra (`pip install .[realsense]`, pyrealsense2) and a device; without
either it refuses to start (exit code 2) saying which is missing."""

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings


class Settings(ServiceSettings):
    """Settings of the RealSense camera."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_REALSENSE_")

    serial: str = Field(default="", description="Device serial number ('' = the first one).")
    width_px: int = Field(default=640, gt=0, description="Colour and depth width, px.")
    height_px: int = Field(default=480, gt=0, description="Colour and depth height, px.")
    fps: int = Field(default=15, gt=0, le=90, description="Frame rate, Hz.")
    frames: int | None = Field(default=None, ge=1, description="Stop after N frames.")
    timeout_ms: int = Field(default=5000, ge=100, description="Wait for a frame, ms.")


SPEC = NodeSpec(inputs=(), outputs=("camera/rgbd",), answers={})


def _make_core(settings: Settings):
    from services.realsense.core import RealsenseCore

    return RealsenseCore(settings)


SERVICE = ServiceDef(
    "realsense", Settings, SPEC, kind="source", make_core=_make_core, description=__doc__ or ""
)
