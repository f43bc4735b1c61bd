"""Detector: finds oranges in camera/rgbd frames (OrangeNet, or an HSV baseline) → detections."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings


class Settings(ServiceSettings):
    """Settings of the detector."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_DETECTOR_")

    backend: Literal["net", "hsv"] = Field(
        default="net", description="'net': the learned OrangeNet; 'hsv': the colour baseline."
    )
    weights_path: Path = Field(
        default=Path("services/detector/weights/orange_net.pt"),
        description="OrangeNet weights (relative paths are taken from the repository root).",
    )
    score_threshold: float | None = Field(
        default=None,
        ge=0.0,
        le=1.0,
        description="Operating score threshold; null: the one chosen on validation and stored "
        "with the weights.",
    )
    max_detections: int = Field(default=100, ge=1, le=1000, description="Most boxes per frame.")
    torch_threads: int = Field(
        default=2, ge=1, le=64, description="torch CPU threads (fixed, for speed and determinism)."
    )
    expected_size_px: tuple[int, int] | None = Field(
        default=(640, 480),
        description="Frame (width, height) the camera must deliver; other sizes are refused "
        "(answered empty, flagged). null accepts any size.",
    )
    hsv_hue_range: tuple[int, int] = Field(
        default=(5, 25), description="HSV baseline: hue band of orange (OpenCV 0-179)."
    )
    hsv_sat_min: int = Field(default=140, ge=0, le=255, description="HSV baseline: least S.")
    hsv_val_min: int = Field(default=100, ge=0, le=255, description="HSV baseline: least V.")
    hsv_min_area_px: int = Field(
        default=40, ge=1, description="HSV baseline: smallest blob kept, pixels."
    )


SPEC = NodeSpec(
    inputs=("camera/rgbd",),
    outputs=("perception/detections",),
    answers={"camera/rgbd": ("perception/detections",)},
    conflate=("camera/rgbd",),
)


def _make_core(settings: Settings):
    from services.detector.core import DetectorCore

    return DetectorCore(settings)


SERVICE = ServiceDef("detector", Settings, SPEC, make_core=_make_core, description=__doc__ or "")
