"""Base message class, the common Header and small geometric value types shared by all messages."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

ArmRole = Literal["cutter", "collector"]
"""Arms are keyed by role: the cutting arm and the collecting (basket) arm."""

ARM_ROLES: tuple[ArmRole, ArmRole] = ("cutter", "collector")

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
NonNegFloat = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
PosFloat = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
Vec3 = tuple[FiniteFloat, FiniteFloat, FiniteFloat]
"""A 3-vector; the field name carries its unit and frame (e.g. ``position_world_m``)."""
QuatXYZW = tuple[FiniteFloat, FiniteFloat, FiniteFloat, FiniteFloat]
"""A unit quaternion in (x, y, z, w) order, the order of pybullet and ROS."""
BoxXYXY = tuple[FiniteFloat, FiniteFloat, FiniteFloat, FiniteFloat]
"""An axis-aligned image box (x_min, y_min, x_max, y_max) in pixels, x right, y down."""


class Frozen(BaseModel):
    """Immutable, strict model: unknown fields and NaN/inf are rejected."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


INT64_MAX = 2**63 - 1
"""Largest stamp or seq: MCAP and Rerun store them as 64-bit integers (a larger one, valid
before, crashed the recorder's writer; found by the fuzz)."""


class Header(Frozen):
    """Common header of every message: logical time, sequence, frame and source."""

    stamp_ns: int = Field(
        ge=0,
        le=INT64_MAX,
        description="When the data is valid, ns (sim or sensor time; never the receive time). "
        "An answer copies the stamp of the input it answers.",
    )
    seq: int = Field(
        ge=0, le=INT64_MAX, description="Per-publisher, per-topic counter, starting at 0."
    )
    frame_id: str = Field(
        default="", description="Coordinate frame of the spatial data ('' when there is none)."
    )
    source: str = Field(min_length=1, description="Name of the service that published it.")
    answers_seq: int | None = Field(
        default=None,
        ge=0,
        le=INT64_MAX,
        description="seq of the input message this message answers (None for source data).",
    )


class Message(Frozen):
    """Base of every bus message: a Header followed by the payload fields."""

    header: Header = Field(description="Time, sequence, frame and source of this message.")


class Pose(Frozen):
    """A rigid transform: position and orientation of a child frame in a parent frame."""

    position_m: Vec3 = Field(description="Translation of the child origin in the parent frame, m.")
    orientation_xyzw: QuatXYZW = Field(
        default=(0.0, 0.0, 0.0, 1.0), description="Rotation child→parent as a unit quaternion."
    )
