"""Recorder: subscribes to the run's whole namespace and writes one MCAP file per run."""

from pathlib import Path
from typing import Literal

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings


class Settings(ServiceSettings):
    """Settings of the recorder."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_RECORDER_")

    out_dir: Path = Field(default=Path("recordings"), description="Folder of the MCAP files.")
    compression: Literal["lz4", "zstd", "none"] = Field(
        default="lz4", description="Chunk compression (lz4: ~3 ms per RGB-D frame; zstd: ~9)."
    )
    lz4_level: int = Field(
        default=0, ge=-16, le=16, description="lz4 level; negative trades ratio for speed."
    )
    chunk_size_bytes: int = Field(default=4 << 20, ge=1024, description="MCAP chunk size.")
    flush_interval_s: float = Field(
        default=0.5,
        gt=0,
        le=5,
        description="Chunks are flushed at least this often (SIGKILL loses at most this much).",
    )
    keyexpr: str = Field(default="**", description="What to record, as a key expression.")
    preview: Literal["jpeg", "raw", "none"] = Field(
        default="jpeg",
        description="Derived Foxglove-protobuf camera channels (/preview/...) that Rerun and "
        "Foxglove open with no code of ours: 'jpeg' (lossy), 'raw' (rgb8) or 'none'. The raw "
        "camera/rgbd channel is recorded unchanged either way.",
    )
    preview_scale: float = Field(
        default=0.5, gt=0, le=1, description="Preview resolution as a fraction of the camera's."
    )
    preview_jpeg_quality: int = Field(default=80, ge=1, le=100, description="JPEG quality.")


SPEC = NodeSpec(inputs=("**",))
SERVICE = ServiceDef("recorder", Settings, SPEC, kind="process", description=__doc__ or "")
