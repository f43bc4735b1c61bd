"""Robot messages: joint state, joint-velocity command and tool command, arms keyed by role."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from schemas.base import ArmRole, FiniteFloat, Frozen, Message, NonNegFloat, Vec3


class ArmJointState(Frozen):
    """Measured joint positions and velocities of one arm, in the order of ``names``."""

    names: tuple[str, ...] = Field(min_length=1, description="Joint names, base to tip.")
    position_rad: tuple[FiniteFloat, ...] = Field(description="Joint positions, rad.")
    velocity_rad_s: tuple[FiniteFloat, ...] = Field(description="Joint velocities, rad/s.")

    @model_validator(mode="after")
    def _same_length(self) -> ArmJointState:
        n = len(self.names)
        if len(self.position_rad) != n or len(self.velocity_rad_s) != n:
            raise ValueError(
                f"{n} names but {len(self.position_rad)} positions and "
                f"{len(self.velocity_rad_s)} velocities"
            )
        return self


class SensedContact(Frozen):
    """An external contact one robot link feels (an LWR4 joint-torque observer's estimate)."""

    # The observer isolates the link and estimates the point; the sim's estimate is exact.

    link: str = Field(min_length=1, description="The robot link in contact (URDF link name).")
    point_world_m: Vec3 = Field(description="Where on the link it is touched, world frame, m.")


class JointState(Message):
    """Joint state of both arms at one control tick (the lock-step clock of the robot)."""

    arms: dict[ArmRole, ArmJointState] = Field(description="Joint state per arm role.")
    contacts: tuple[SensedContact, ...] = Field(
        default=(),
        description="External contacts felt at this tick: the trunk, branches, fruit on the "
        "tree; not the fruit the dish carries nor one falling into it (the load cell's). One "
        "per link and body touched, in link order. Empty: none (or no sensing).",
    )


class ArmJointVelocity(Frozen):
    """Commanded joint velocities of one arm, in the order of ``names``."""

    names: tuple[str, ...] = Field(min_length=1, description="Joint names, base to tip.")
    velocity_rad_s: tuple[FiniteFloat, ...] = Field(description="Joint velocities, rad/s.")

    @model_validator(mode="after")
    def _same_length(self) -> ArmJointVelocity:
        if len(self.velocity_rad_s) != len(self.names):
            raise ValueError(f"{len(self.names)} names but {len(self.velocity_rad_s)} velocities")
        return self


class JointVelocityCommand(Message):
    """Joint-velocity command for one control tick (answers robot/joint_state)."""

    arms: dict[ArmRole, ArmJointVelocity] = Field(description="Command per arm role.")
    hold: bool = Field(
        default=False, description="True when the controller deliberately commands zero motion."
    )
    reason: str = Field(default="", description="Why the arms hold, when hold is True.")


class ToolCommand(Message):
    """An action of a tool: the cutter closes its shears to cut, or opens them."""

    tool: ArmRole = Field(description="Which arm's tool acts.")
    action: Literal["cut", "open"] = Field(description="'cut' closes the shears; 'open' opens.")
    fruit_id: int | None = Field(default=None, ge=1, description="Fruit the action is meant for.")


class BasketState(Message):
    """The collecting tool's load cell (robot/basket): the load in the dish and fruit settled."""

    # fruit_count comes from the sensor's step detector: a load step that stays >= 0.25 s.

    load_kg: NonNegFloat = Field(description="Mass resting in the dish now, kg (1 g steps).")
    fruit_count: int = Field(
        ge=0, description="Fruit that have settled in the dish since the start (never decreases)."
    )
