"""Viz: draws a run in Rerun, live from the bus or offline from its MCAP, with one conversion core.

This package is the only code that imports rerun, and only lazily (inside functions), so that
importing it stays cheap for the supervisor and the CLI.
"""

from pathlib import Path
from typing import Literal

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from services.robot.model import URDF_PATH
from services.runtime import NodeSpec, ServiceDef, ServiceSettings


class Settings(ServiceSettings):
    """Settings of the viz service (and of `harvest view`)."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_VIZ_")

    viewer: Literal["none", "spawn", "serve", "connect"] = Field(
        default="none",
        description="Where the live stream goes: 'spawn' a native viewer, 'serve' a gRPC server "
        "(and a web viewer) for viewers to connect to, 'connect' to a running viewer, or 'none'.",
    )
    save_path: Path | None = Field(default=None, description="Also write the stream to this .rrd.")
    connect_url: str = Field(
        default="rerun+http://127.0.0.1:9876/proxy", description="Viewer URL for 'connect'."
    )
    grpc_port: int = Field(default=9876, ge=1, le=65535, description="Port for 'spawn'/'serve'.")
    web_port: int = Field(
        default=9090, ge=0, le=65535, description="Web viewer port for 'serve' (0: no web viewer)."
    )
    urdf_path: Path = Field(default=URDF_PATH, description="Robot model drawn in 3D.")
    d_s_m: float = Field(
        default=0.03,
        gt=0,
        description="Safety distance d_s drawn on the minimum-distance plots, m (until the "
        "controller publishes its own).",
    )
    image_max_rate_hz: float = Field(
        default=15.0, ge=0, description="Most camera images per sim second drawn (0: all)."
    )
    depth_max_rate_hz: float = Field(
        default=2.0,
        ge=0,
        description="Most depth images and trunk masks per sim second drawn (0: none).",
    )
    image_jpeg_quality: int = Field(
        default=85,
        ge=0,
        le=100,
        description="JPEG quality of the colour images sent to the viewer (0: raw pixels). "
        "Only the viewer's copy is compressed; recordings stay raw.",
    )
    pose_max_rate_hz: float = Field(
        default=50.0, ge=0, description="Most robot poses per sim second drawn (0: all)."
    )
    trunk_max_depth_m: float = Field(
        default=2.0, gt=0, description="Trunk mask: farthest depth kept, m (paper §III-C)."
    )
    trunk_draw_height_m: float = Field(
        default=2.5, gt=0, description="Height of the drawn trunk cylinder (infinite in the model)."
    )
    max_pending_frames: int = Field(
        default=30,
        ge=1,
        description="Live only: camera frames queued before new ones are dropped (the viewer "
        "fell behind); counted and logged.",
    )


SPEC = NodeSpec(inputs=("**",))
"""Subscribes to everything and publishes nothing; answers nothing, so it never slows lock-step."""

SERVICE = ServiceDef("viz", Settings, SPEC, kind="process", description=__doc__ or "")
