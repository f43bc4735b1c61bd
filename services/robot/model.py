"""The BAZAR-like dual-arm robot: names, limits, frames and mounting, in one place.

World frame: on the ground under the torso, x forward, y left, z up. The paper's cutting arm is
the left one and the collecting arm the right one. Joint and link names carry the arm role.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from schemas.base import ARM_ROLES, ArmRole

ROBOT_DIR = Path(__file__).resolve().parents[2] / "deploy" / "robot"
URDF_PATH = ROBOT_DIR / "bazar.urdf"
COLLISIONS_PATH = ROBOT_DIR / "collisions.json"

# KUKA LWR 4+: joint offsets along the parent z axis (m), axes, limits (deg, deg/s).
LWR_OFFSETS_M = (0.11, 0.20, 0.20, 0.20, 0.20, 0.19, 0.078)
LWR_AXES = ((0, 0, 1), (0, -1, 0), (0, 0, 1), (0, 1, 0), (0, 0, 1), (0, -1, 0), (0, 0, 1))
LWR_POS_LIMIT_DEG = (170, 120, 170, 120, 170, 120, 170)
LWR_VEL_LIMIT_DEG_S = (110, 110, 128, 128, 204, 184, 184)
LWR_LINK_RADIUS_M = (0.07, 0.065, 0.065, 0.06, 0.06, 0.055, 0.045)

SIDE: dict[ArmRole, int] = {"cutter": 1, "collector": -1}  # +1 = left (+y), -1 = right
TOOL_FRAME: dict[ArmRole, str] = {"cutter": "cutter_tip", "collector": "basket_center"}
CAMERA_FRAME = "camera_optical"


@dataclass(frozen=True)
class Mount:
    """Where the arm bases and the camera sit on the torso."""

    shoulder_x_m: float = 0.01
    shoulder_y_m: float = 0.17  # |y| of each arm base
    shoulder_z_m: float = 1.16
    shoulder_tilt_deg: float = 33.0  # base z axis: sideways, turned forward by this angle
    shoulder_droop_deg: float = 33.0  # ... and turned down by this angle
    camera_xyz_m: tuple[float, float, float] = (0.02, 0.0, 1.44)
    camera_pitch_down_deg: float = 8.0


@dataclass(frozen=True)
class ToolGeometry:
    """Cutter: a shaft with shears at its tip. Collector: a shaft holding a dish (a basket)."""

    flange_gap_m: float = 0.03
    cutter_shaft_length_m: float = 0.16
    cutter_shaft_radius_m: float = 0.022
    collector_shaft_length_m: float = 0.08
    collector_shaft_radius_m: float = 0.02
    basket_radius_m: float = 0.085
    basket_floor_m: float = 0.008
    basket_rim_height_m: float = 0.045
    basket_rim_segments: int = 12


MOUNT = Mount()
TOOLS = ToolGeometry()


def joint_names(role: ArmRole) -> tuple[str, ...]:
    return tuple(f"{role}_j{i}" for i in range(1, 8))


def all_joint_names() -> tuple[str, ...]:
    return tuple(n for r in ARM_ROLES for n in joint_names(r))


def position_limits_rad(role: ArmRole) -> tuple[tuple[float, float], ...]:
    return tuple((-math.radians(d), math.radians(d)) for d in LWR_POS_LIMIT_DEG)


def velocity_limits_rad_s() -> tuple[float, ...]:
    return tuple(math.radians(d) for d in LWR_VEL_LIMIT_DEG_S)


# Ready posture: tools forward under the camera's view (cutter tip at (0.55, 0, 1.05) m, the dish
# 0.14 m below it), every joint at least 15 degrees inside its limits (IK, services/robot/reach).
HOME_RAD: dict[ArmRole, tuple[float, ...]] = {
    "cutter": (-0.391, -1.736, 0.585, 1.786, -0.984, 1.832, 0.199),
    "collector": (-0.892, -1.166, 0.023, 1.722, -1.247, 1.084, -0.695),
}
