"""Tracker: Deep SORT-style multi-fruit tracking (Kalman, gated cascade, appearance, depth)."""

from __future__ import annotations

from pydantic import Field
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings


class Settings(ServiceSettings):
    """Settings of the tracker; the first five are the paper's Deep SORT hyper-parameters."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_TRACKER_")

    max_cosine_distance: float = Field(
        default=0.2, ge=0.0, le=2.0, description="Appearance gate: largest cosine distance."
    )
    max_iou_distance: float = Field(
        default=0.5, ge=0.0, le=1.0, description="IoU stage: largest 1 - IoU of a match."
    )
    max_age: int = Field(default=300, ge=1, description="Frames a confirmed track survives unseen.")
    n_init: int = Field(default=10, ge=1, description="Consecutive hits that confirm a track.")
    nn_budget: int = Field(default=30, ge=1, description="Appearance descriptors kept per track.")
    appearance_weight: float = Field(
        default=0.5,
        ge=0.0,
        le=1.0,
        description="Share of appearance in the cascade cost; the rest is the Mahalanobis "
        "distance over its gate (oranges look alike, so position must weigh too).",
    )
    use_frames: bool = Field(
        default=True,
        description="Use camera/rgbd for appearance descriptors and depth (else boxes only).",
    )
    use_depth: bool = Field(default=True, description="Gate matches by the fruit's depth.")
    max_depth_jump_m: float = Field(
        default=0.25, gt=0.0, description="Depth gate: largest depth change of a match, m."
    )
    depth_smoothing: float = Field(
        default=0.3, gt=0.0, le=1.0, description="Weight of a new depth in a track's average."
    )
    min_containment: float = Field(
        default=0.5,
        gt=0.0,
        le=1.0,
        description="Containment stage: least intersection over the smaller box to re-attach a "
        "detection to a confirmed track (a fruit growing back out of a partial occlusion).",
    )
    max_containment_growth: float = Field(
        default=1.5,
        gt=1,
        description="A confirmed track refuses a detection larger (area) than this times the "
        "largest box it ever matched, in every matching stage: a fruit does not grow (a hand "
        "covering it does).",
    )
    coast_velocity_decay: float = Field(
        default=0.8,
        ge=0.0,
        le=1.0,
        description="Factor on a track's velocity per frame while it is not seen (fruit hang "
        "still; 1 = Deep SORT's pure constant velocity).",
    )
    max_shift_sides: float = Field(
        default=1.0,
        gt=0.0,
        description="A confirmed track takes a box only within this many times the side of its "
        "whole box (sqrt of the largest box area it matched) from its last matched box: fruit "
        "hang still, and the Kalman gate of a track that coasted long spans the image (a "
        "harvested fruit's track would take another fruit's box).",
    )
    max_depth_step_m: float = Field(
        default=0.1,
        gt=0.0,
        description="A confirmed track takes a box only if it reads at most this much deeper "
        "than the track (when both are known; cascade and containment stages), m. A box reading "
        "nearer by more is an occluded view (something in front of the fruit): it may match, "
        "but its depth is not averaged into the track's.",
    )
    frame_buffer: int = Field(
        default=8, ge=1, le=64, description="Camera frames kept to join with their detections."
    )
    box_margin_px: float = Field(
        default=2.0, ge=0.0, description="How far a box may reach outside the image (clipped)."
    )
    min_box_side_px: float = Field(default=2.0, ge=0.0, description="Smaller boxes are refused.")
    max_box_fraction: float = Field(
        default=0.95,
        gt=0.0,
        le=1.0,
        description="A box wider and taller than this share of the image is refused (absurd).",
    )


SPEC = NodeSpec(
    inputs=("perception/detections", "camera/rgbd"),
    outputs=("perception/tracks",),
    answers={"perception/detections": ("perception/tracks",)},
)


def _make_core(settings: Settings):
    from services.tracker.core import TrackerCore

    return TrackerCore(settings)


SERVICE = ServiceDef("tracker", Settings, SPEC, make_core=_make_core, description=__doc__ or "")
