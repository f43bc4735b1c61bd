"""Planner → controller target and the controller's per-tick status (paper §IV)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from schemas.base import Frozen, Message, NonNegFloat, QuatXYZW, Vec3

HarvestPhase = Literal["idle", "approach", "harvest", "cut", "leave", "home", "done"]
Fallback = Literal["none", "softened", "stopped"]


class AbsoluteTarget(Frozen):
    """Pose of the cutting tool (the absolute task), with one rotation axis optionally free."""

    frame_id: str = Field(default="world", description="Frame of the pose ('world' or camera).")
    position_m: Vec3 = Field(description="Target position of the cutter tip, m.")
    orientation_xyzw: QuatXYZW = Field(description="Target orientation of the cutter tool frame.")
    free_axis: Literal["x", "y", "z"] | None = Field(
        default="y",
        description="Tool-frame axis whose rotation is left free (θ_a of the paper), or None.",
    )


class RelativeTarget(Frozen):
    """Pose of the collecting tool in the cutting tool's frame (the relative task)."""

    position_m: Vec3 = Field(description="Collector position in the cutter tool frame, m.")
    orientation_xyzw: QuatXYZW = Field(description="Collector orientation in the cutter frame.")


class PlanTarget(Message):
    """The planner's current goal for both arms (answers control/status)."""

    phase: HarvestPhase = Field(description="Harvest phase this target belongs to.")
    fruit_id: int | None = Field(default=None, ge=1, description="Target fruit, if any.")
    absolute: AbsoluteTarget | None = Field(default=None, description="None: hold still.")
    relative: RelativeTarget | None = Field(default=None, description="None: hold still.")
    ignore_fruit_ids: tuple[int, ...] = Field(
        default=(), description="Fruit the tools may touch (the target while cutting)."
    )
    max_tool_speed_m_s: NonNegFloat | None = Field(
        default=None, description="Optional per-phase tool speed cap, m/s."
    )


class ControlStatus(Message):
    """The controller's state after one tick (answers robot/joint_state)."""

    target_seq: int | None = Field(default=None, description="seq of the PlanTarget in use.")
    phase: HarvestPhase = Field(default="idle", description="Phase of the target in use.")
    abs_position_error_m: NonNegFloat = Field(description="‖p_target − p_cutter‖, m.")
    abs_orientation_error_rad: NonNegFloat = Field(description="Constrained-axes error, rad.")
    rel_position_error_m: NonNegFloat = Field(description="Relative-task position error, m.")
    rel_orientation_error_rad: NonNegFloat = Field(description="Relative orientation error, rad.")
    min_distance_trunk_m: float | None = Field(default=None, description="Robot–trunk, m.")
    min_distance_fruit_m: float | None = Field(default=None, description="Robot–fruit, m.")
    min_distance_self_m: float | None = Field(default=None, description="Arm–arm/body, m.")
    active_dampers: int = Field(default=0, ge=0, description="Velocity-damper rows active.")
    converged: bool = Field(description="Both tasks within their tolerances.")
    fallback: Fallback = Field(default="none", description="QP fallback used this tick.")
    watchdog: bool = Field(default=False, description="True when stale inputs forced a stop.")
    reason: str = Field(default="", description="Why the arms hold, if they do.")
