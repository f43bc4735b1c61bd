"""Planner → controller target and the controller's per-tick status (paper §IV)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from schemas.base import ArmRole, FiniteFloat, Frozen, Message, NonNegFloat, QuatXYZW, Vec3

HarvestPhase = Literal["idle", "approach", "harvest", "cut", "leave", "home", "done"]
Fallback = Literal["none", "softened", "absolute_only", "stopped"]
"""QP fallback of a tick: ``softened`` = hard dampers made soft; ``absolute_only`` = the relative
(second) solve failed and the absolute solution was sent; ``stopped`` = zero command."""
Axis = Literal["x", "y", "z"]


class AbsoluteTarget(Frozen):
    """Pose of the cutting tool (the absolute task), with one rotation axis optionally free."""

    frame_id: str = Field(default="world", description="Frame of the pose ('world' or camera).")
    position_m: Vec3 = Field(description="Target position of the cutter tip, m.")
    orientation_xyzw: QuatXYZW = Field(description="Target orientation of the cutter tool frame.")
    free_axis: Axis | None = Field(
        default="x",
        description="Cutter-frame axis whose rotation is left free (θ_a of the paper), or None. "
        "Default x: with the tool level, cutter x points down, so the tool may turn about the "
        "vertical (the paper's free rotation about the camera's vertical axis).",
    )


class RelativeTarget(Frozen):
    """Pose of the collecting tool in the cutting tool's frame (the relative task)."""

    position_m: Vec3 = Field(description="Collector position in the cutter tool frame, m.")
    orientation_xyzw: QuatXYZW = Field(description="Collector orientation in the cutter frame.")
    free_axis: Axis | None = Field(
        default="z",
        description="Collector-frame axis whose rotation is left free, or None (all three "
        "constrained, as in the paper). Default z: the dish normal; a dish does not care how it "
        "is turned about its normal (a deviation from the paper, which fixes θ_r fully).",
    )


class ArmJointTarget(Frozen):
    """Goal joint positions of one arm, in the order of ``names``."""

    names: tuple[str, ...] = Field(min_length=1, description="Joint names, base to tip.")
    position_rad: tuple[FiniteFloat, ...] = Field(description="Goal joint positions, rad.")

    @model_validator(mode="after")
    def _same_length(self) -> ArmJointTarget:
        if len(self.position_rad) != len(self.names):
            raise ValueError(f"{len(self.names)} names but {len(self.position_rad)} positions")
        return self


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
    joints: dict[ArmRole, ArmJointTarget] | None = Field(
        default=None,
        description="A joint-space goal for both arms (the planner retracing the path the arms "
        "came in by), instead of the two pose tasks: absolute and relative must then be None.",
    )

    @model_validator(mode="after")
    def _one_kind_of_goal(self) -> PlanTarget:
        if self.joints is not None and (self.absolute is not None or self.relative is not None):
            raise ValueError("a joint goal comes without absolute and relative targets")
        return self


class ControlStatus(Message):
    """The controller's state after one tick (answers robot/joint_state)."""

    target_seq: int | None = Field(default=None, description="seq of the PlanTarget in use.")
    phase: HarvestPhase = Field(default="idle", description="Phase of the target in use.")
    abs_position_error_m: NonNegFloat = Field(description="‖p_target − p_cutter‖, m.")
    abs_orientation_error_rad: NonNegFloat = Field(description="Constrained-axes error, rad.")
    rel_position_error_m: NonNegFloat = Field(description="Relative-task position error, m.")
    rel_orientation_error_rad: NonNegFloat = Field(description="Relative orientation error, rad.")
    min_distance_trunk_m: float | None = Field(
        default=None,
        description="Robot–trunk signed distance, m (negative: penetration); None when no trunk "
        "is within the controller's cull distance.",
    )
    min_distance_fruit_m: float | None = Field(
        default=None,
        description="Robot–fruit signed distance over the fruit the dampers guard (ignored fruit "
        "excluded), m; None when none is within the cull distance.",
    )
    min_distance_self_m: float | None = Field(
        default=None, description="Smallest self-collision pair distance (arm–arm/body), m."
    )
    active_dampers: int = Field(default=0, ge=0, description="Velocity-damper rows active.")
    converged: bool = Field(description="Both tasks within their tolerances.")
    fallback: Fallback = Field(default="none", description="QP fallback used this tick.")
    watchdog: bool = Field(default=False, description="True when stale inputs forced a stop.")
    reason: str = Field(default="", description="Why the arms hold, if they do.")


class ControllerDiagnostics(Message):
    """Wall-clock timings and counters of one controller tick (diag/controller; not diffed)."""

    # Published beside control/status with the same stamp. Timings differ from run to run, so
    # the topic map flags diag/controller as not deterministic and resim does not compare it.

    cycle_ms: NonNegFloat = Field(description="Whole tick in the core (wall clock), ms.")
    distance_ms: NonNegFloat = Field(description="Broad + narrow phase distances, ms.")
    damper_ms: NonNegFloat = Field(description="Velocity-damper rows (Jacobians), ms.")
    solve_ms: NonNegFloat = Field(description="Both QP solves (absolute, relative), ms.")
    pairs_checked: int = Field(ge=0, description="Geometry pairs whose distance was computed.")
    obstacles_near: int = Field(ge=0, description="Obstacles that passed the broad phase.")
    obstacles_total: int = Field(
        ge=0, description="Obstacles in use: the scene state's, and the contact reflex's."
    )
    reflex_spheres: int = Field(
        default=0, ge=0, description="Felt places the contact reflex holds as spheres now."
    )
    rejected_targets: int = Field(ge=0, description="Plan targets refused so far.")
    rejected_scenes: int = Field(ge=0, description="Scene states refused so far.")
    rejected_joint_states: int = Field(ge=0, description="Joint states refused so far.")
    fallbacks: int = Field(ge=0, description="Ticks with a QP fallback so far.")
    watchdog_stops: int = Field(ge=0, description="Ticks stopped by the watchdog so far.")
