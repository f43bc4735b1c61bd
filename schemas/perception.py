"""Perception messages: per-frame detections and tracks, both in image pixels."""

from __future__ import annotations

from pydantic import Field, field_validator

from schemas.base import BoxXYXY, Frozen, Message, NonNegFloat, Vec3


def _valid_box(box: BoxXYXY) -> BoxXYXY:
    if box[2] < box[0] or box[3] < box[1]:
        raise ValueError(f"inverted box {box}: need x_max >= x_min and y_max >= y_min")
    return box


class Detection(Frozen):
    """One detected object in an image."""

    xyxy_px: BoxXYXY = Field(description="Box (x_min, y_min, x_max, y_max), pixels.")
    score: float = Field(ge=0.0, le=1.0, description="Detector confidence in [0, 1].")
    class_id: int = Field(default=0, ge=0, description="Class index (0 = orange).")
    class_name: str = Field(default="orange", description="Human-readable class name.")

    _box = field_validator("xyxy_px")(_valid_box)


class Detections(Message):
    """All detections of one camera frame (answers camera/rgbd; sent also when empty)."""

    image_width_px: int = Field(gt=0, description="Width of the image the boxes refer to.")
    image_height_px: int = Field(gt=0, description="Height of the image the boxes refer to.")
    detector: str = Field(description="Detector name and weights version, e.g. 'net:v1' or 'hsv'.")
    detections: tuple[Detection, ...] = Field(default=(), description="Detections, any order.")
    input_problem: str = Field(
        default="",
        description="Why the input frame could not be used ('' when it was used); the "
        "detections are then empty.",
    )


class Track(Frozen):
    """One tracked object in the current frame."""

    track_id: int = Field(ge=1, description="Track ID from a per-tracker counter, starting at 1.")
    xyxy_px: BoxXYXY = Field(description="Filtered box (x_min, y_min, x_max, y_max), pixels.")
    score: float = Field(ge=0.0, le=1.0, description="Score of the last matched detection.")
    confirmed: bool = Field(description="True once the track has n_init consecutive hits.")
    age_frames: int = Field(ge=0, description="Frames since the track was created.")
    frames_since_update: int = Field(ge=0, description="Frames since the last matched detection.")
    matched: bool = Field(description="True when a detection of this frame updated the track.")
    position_cam_m: Vec3 | None = Field(
        default=None, description="3D centre in the camera optical frame, m, when depth is used."
    )
    depth_m: NonNegFloat | None = Field(
        default=None, description="Depth of the box centre used by the tracker, m."
    )

    _box = field_validator("xyxy_px")(_valid_box)


class Tracks(Message):
    """The tracker's state after one Detections message (answers perception/detections)."""

    frame_seq: int = Field(ge=0, description="seq of the camera/rgbd frame the boxes refer to.")
    tracks: tuple[Track, ...] = Field(default=(), description="Tracks, sorted by track_id.")
    rejected_detections: int = Field(
        default=0,
        ge=0,
        description="Detections of the input dropped as unusable (outside the image, absurd size).",
    )
    input_problem: str = Field(
        default="",
        description="Why the input could not be used ('' when it was); the tracker state was "
        "then left unchanged and the tracks are those of the previous frame.",
    )
