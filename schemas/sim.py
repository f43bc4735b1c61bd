"""Sim-only messages: ground truth and physical events (for evaluation, never for control)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from schemas.base import BoxXYXY, Frozen, Message, PosFloat, QuatXYZW, Vec3

FruitTruthState = Literal["attached", "falling", "collected", "dropped"]
SimEventKind = Literal[
    "collision",
    "cut",
    "cut_missed",
    "fell",
    "collected",
    "dropped",
    "clamped",
    "command_rejected",
    "command_late",
]
OccluderKind = Literal[
    "trunk", "branch", "twig", "leaf", "fruit", "stem", "robot", "hand", "ground", "wall"
]


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
    box_xyxy_px: BoxXYXY | None = Field(
        default=None,
        description="Box of the visible pixels (pixel centres at integer coordinates, so a box "
        "around columns u0..u1 spans u0-0.5..u1+0.5), None when no pixel is visible.",
    )
    amodal_box_xyxy_px: BoxXYXY | None = Field(
        default=None, description="Box the fruit would cover if nothing hid it (in the image)."
    )
    hidden_by: dict[OccluderKind, float] = Field(
        default_factory=dict,
        description="Share of the fruit's unoccluded pixels hidden by each kind of thing.",
    )
    state: FruitTruthState = Field(description="Attached, falling, collected or dropped.")


class TrunkTruth(Frozen):
    """True trunk axis (vertical) and radius."""

    axis_point_world_m: Vec3 = Field(description="Trunk axis at ground level, world, m.")
    radius_m: PosFloat = Field(description="Trunk radius, m.")


class SimCounters(Frozen):
    """Running totals since the start of the run."""

    contact_ticks: int = Field(default=0, ge=0, description="Ticks with a robot–tree contact.")
    contacts: int = Field(default=0, ge=0, description="Robot–tree/fruit contacts begun.")
    commands_applied: int = Field(default=0, ge=0, description="Joint commands applied.")
    commands_clamped: int = Field(default=0, ge=0, description="Commands clamped to limits.")
    commands_rejected: int = Field(default=0, ge=0, description="Invalid commands refused.")
    commands_late: int = Field(default=0, ge=0, description="Commands for a passed tick.")
    ticks_without_command: int = Field(default=0, ge=0, description="Ticks held still.")
    cuts: int = Field(default=0, ge=0, description="Successful cuts.")
    cuts_missed: int = Field(default=0, ge=0, description="Cuts too far from a peduncle.")


class GroundTruth(Message):
    """Ground truth at one camera frame (sim/truth)."""

    frame_seq: int = Field(ge=0, description="seq of the camera/rgbd frame it describes.")
    fruits: tuple[FruitTruth, ...] = Field(default=(), description="Every fruit of the scenario.")
    trunk: TrunkTruth = Field(description="The trunk.")
    occluder_active: bool = Field(default=False, description="A dynamic occluder is in view.")
    robot_contacts: tuple[tuple[str, str], ...] = Field(
        default=(), description="(robot link, tree part or fruit) pairs touching now."
    )
    counters: SimCounters = Field(default_factory=SimCounters, description="Running totals.")


class SimEvent(Message):
    """A physical event in the sim: contact, cut, fall, collect, drop, clamped command."""

    kind: SimEventKind = Field(description="What happened.")
    fruit_id: int | None = Field(default=None, ge=0, description="Sim fruit index, if any.")
    body_a: str = Field(default="", description="First body (robot link), if any.")
    body_b: str = Field(default="", description="Second body (tree part, fruit), if any.")
    detail: str = Field(default="", description="Free-form detail.")
