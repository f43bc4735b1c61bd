"""Camera from files: a folder of RGB PNG + 16-bit depth PNG with an intrinsics file, or the
camera/rgbd channel of an MCAP recording, published as camera/rgbd (a clock master)."""

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings


class Settings(ServiceSettings):
    """Settings of the file camera."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_CAMERA_FILE_")

    path: str = Field(description="A folder (PNG frames + intrinsics file) or an .mcap file.")
    rate_hz: float = Field(
        default=15.0, gt=0, le=1000, description="Folder: frame rate of the stamps, Hz."
    )
    color_glob: str = Field(default="color/*.png", description="Folder: colour images (RGB).")
    depth_glob: str = Field(default="depth/*.png", description="Folder: 16-bit depth images.")
    intrinsics_file: str = Field(default="intrinsics.json", description="Folder: intrinsics.")
    repeat: int = Field(default=1, ge=1, le=1_000_000, description="Play the frames N times.")
    topic: str = Field(default="camera/rgbd", description="MCAP: channel to read.")


SPEC = NodeSpec(inputs=(), outputs=("camera/rgbd",), answers={})


def _make_core(settings: Settings):
    from services.camera_file.core import CameraFileCore

    return CameraFileCore(settings)


SERVICE = ServiceDef(
    "camera_file", Settings, SPEC, kind="source", make_core=_make_core, description=__doc__ or ""
)
