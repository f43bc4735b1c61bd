"""Joint-velocity commands: validation by joint name, clamping to the LWR's limits.

A command names the joints of each arm it drives (any order, mapped by name). Unknown or
missing joint names refuse the whole command (the robot holds still); an arm left out holds
still. Velocities beyond the datasheet limit, or that would cross a position limit within the
tick, are clamped as the hardware would, and reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from schemas.base import ARM_ROLES
from schemas.robot import JointVelocityCommand
from services.robot.model import (
    all_joint_names,
    joint_names,
    position_limits_rad,
    velocity_limits_rad_s,
)

JOINTS = all_joint_names()
VEL_LIMIT = np.array([v for _ in ARM_ROLES for v in velocity_limits_rad_s()])
POS_LO = np.array([lo for r in ARM_ROLES for lo, _ in position_limits_rad(r)])
POS_HI = np.array([hi for r in ARM_ROLES for _, hi in position_limits_rad(r)])


class CommandRejected(ValueError):
    """A command that cannot be applied; the message names the arm and the problem."""


def command_velocities(msg: JointVelocityCommand) -> np.ndarray:
    """Joint velocities in ``all_joint_names()`` order (rad/s); raises CommandRejected."""
    qd = np.zeros(len(JOINTS))
    if msg.hold:
        return qd
    for role, arm in msg.arms.items():
        expected = joint_names(role)
        names = list(arm.names)
        unknown = sorted(set(names) - set(expected))
        if unknown:
            raise CommandRejected(f"arm {role!r}: unknown joint names {unknown}")
        if len(names) != len(expected) or len(set(names)) != len(names):
            missing = sorted(set(expected) - set(names))
            raise CommandRejected(
                f"arm {role!r}: {len(names)} joint velocities for {len(expected)} joints"
                + (f" (missing {missing})" if missing else " (repeated names)")
            )
        for name, v in zip(names, arm.velocity_rad_s, strict=True):
            qd[JOINTS.index(name)] = v
    return qd


@dataclass
class Clamped:
    qd: np.ndarray
    joints: list[str] = field(default_factory=list)
    detail: str = ""


def clamp(qd: np.ndarray, q: np.ndarray, dt_s: float) -> Clamped:
    """Clamp to the velocity limits and so that q + q̇·dt stays within the position limits."""
    v = np.clip(qd, -VEL_LIMIT, VEL_LIMIT)
    v = np.clip(v, np.minimum(0.0, (POS_LO - q) / dt_s), np.maximum(0.0, (POS_HI - q) / dt_s))
    changed = np.nonzero(np.abs(v - qd) > 1e-12)[0]
    if len(changed) == 0:
        return Clamped(v)
    parts = [f"{JOINTS[i]} {qd[i]:+.3f}→{v[i]:+.3f} rad/s" for i in changed]
    return Clamped(v, [JOINTS[i] for i in changed], "; ".join(parts))
