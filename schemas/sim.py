"""Sim-only messages: ground truth and physical events (for evaluation, never for control)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from schemas.base import BoxXYXY, Frozen, Message, PosFloat, QuatXYZW, Vec3

FruitTruthState = Literal["attached", "falling", "collected", "dropped"]
SimEventKind = Literal["collision", "cut", "cut_missed", "fell", "collected", "dropped", "clamped"]


class FruitTruth(Frozen):
    """True state of one simulated fruit."""

    fruit_id: int = Field(ge=0, description="Sim fruit index (not a track ID).")
    position_world_m: Vec3 = Field(description="Ellipsoid centre, world frame, m.")
    orientation_xyzw: QuatXYZW = Field(description="Ellipsoid orientation in the world frame.")
    semi_axes_m: tuple[PosFloat, PosFloat, PosFloat] = Field(
        description="Semi-axes along the fruit frame's x, y, z (z: towards the peduncle), m."
    )
    peduncle_world_m: Vec3 = Field(description="Attachment point of the peduncle, world, m.")
    visible_fraction: float = Field(ge=0.0, le=1.0, description="Unoccluded share of pixels.")
    box_xyxy_px: BoxXYXY | None = Field(default=None, description="Visible 2D box, if in view.")
    state: FruitTruthState = Field(description="Attached, falling, collected or dropped.")


class TrunkTruth(Frozen):
    """True trunk axis (vertical) and radius."""

    axis_point_world_m: Vec3 = Field(description="Trunk axis at ground level, world, m.")
    radius_m: PosFloat = Field(description="Trunk radius, m.")


class GroundTruth(Message):
    """Ground truth at one camera frame (sim/truth)."""

    frame_seq: int = Field(ge=0, description="seq of the camera/rgbd frame it describes.")
    fruits: tuple[FruitTruth, ...] = Field(default=(), description="Every fruit of the scenario.")
    trunk: TrunkTruth = Field(description="The trunk.")
    occluder_active: bool = Field(default=False, description="A dynamic occluder is in view.")


class SimEvent(Message):
    """A physical event in the sim: contact, cut, fall, collect, drop, clamped command."""

    kind: SimEventKind = Field(description="What happened.")
    fruit_id: int | None = Field(default=None, ge=0, description="Sim fruit index, if any.")
    body_a: str = Field(default="", description="First body (robot link), if any.")
    body_b: str = Field(default="", description="Second body (tree part, fruit), if any.")
    detail: str = Field(default="", description="Free-form detail.")
