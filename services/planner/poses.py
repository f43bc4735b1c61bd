"""The paper's poses (§IV-A, §IV-B) for one fruit, in the world frame: the harvest pose (cutter
tip at the peduncle, dish under the fruit), the pre-pose d_z in front of it along the camera's
optical axis, and the ready pose; and the PlanTarget that carries them (or, when retracing, a
joint goal).

World-frame targets: the camera is rigid on the torso, so the paper's camera-frame poses are the
same poses expressed in the world. Two deliberate readings of the paper:

* the cutter tip goes d_v + d_s above the fruit centre along the **world vertical**, not along
  the camera's −y (pitched 8° down, 0.8 cm off at 6 cm): a peduncle hangs vertically;
* the dish is not at the paper's fixed x_r but d_s + 2 d_v + rim + clearance under the tip, so
  its rim passes under the fruit on the way in (a fixed offset would sweep the rim through the
  bottom of a large fruit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from schemas.base import ARM_ROLES, ArmRole, Header
from schemas.control import (
    AbsoluteTarget,
    ArmJointTarget,
    HarvestPhase,
    PlanTarget,
    RelativeTarget,
)
from services.controller.geometry import matrix_to_quat_xyzw
from services.robot.model import TOOLS, joint_names
from services.robot.reach import R_CUTTER_BASKET, R_WORLD_CUTTER_FORWARD

Q_CUTTER_FORWARD = matrix_to_quat_xyzw(R_WORLD_CUTTER_FORWARD)
Q_BASKET_IN_CUTTER = matrix_to_quat_xyzw(R_CUTTER_BASKET)


@dataclass(frozen=True)
class FruitShape:
    """What the poses need of a fruit: centre (world, m) and semi-axes d_h, d_v (m)."""

    centre_world_m: np.ndarray
    d_h_m: float
    d_v_m: float


@dataclass(frozen=True)
class ToolPoses:
    """Cutter tip position (world, m), the dish's distance under it (cutter +x, m), and the
    cutter orientation (None: level, pointing forward, the harvest orientation)."""

    tip_world_m: np.ndarray
    basket_below_m: float
    R_world_cutter: np.ndarray | None = None
    basket_back_m: float = 0.0  # dish centre back along the cutter's pointing axis (−z), m


@dataclass(frozen=True)
class PoseSettings:
    """d_s, d_z, the dish clearance, and the camera's optical axis in the world."""

    security_m: float
    approach_m: float
    basket_clearance_m: float
    approach_basket_drop_m: float
    camera_axis_world: np.ndarray  # unit vector: the camera's +z (optical axis) in the world
    dish_back_m: float = 0.0
    dish_catch_margin_m: float = 0.03


def basket_below_m(f: FruitShape, p: PoseSettings) -> float:
    """Dish centre under the cutter tip: tip → fruit top (d_s), the fruit (2 d_v), rim, gap."""
    return p.security_m + 2.0 * f.d_v_m + TOOLS.basket_rim_height_m + p.basket_clearance_m


def dish_back_m(f: FruitShape, p: PoseSettings) -> float:
    """How far back from under the fruit the dish sits: ``dish_back_m``, but no farther than
    keeps the falling fruit's edge ``dish_catch_margin_m`` inside the rim (the estimate's error
    and the bounce): paper-exp1's 3.9 cm fruit, the dish 3.4 cm back, fell on the rim and out."""
    return float(
        np.clip(TOOLS.basket_radius_m - f.d_h_m - p.dish_catch_margin_m, 0.0, p.dish_back_m)
    )


def harvest_pose(f: FruitShape, p: PoseSettings, back_m: float | None = None) -> ToolPoses:
    """x_a: the tip d_v + d_s above the fruit centre (on the peduncle); the dish under it,
    a little back towards the robot (``dish_back_m``: it still catches the fruit, and keeps
    clear of fruit hanging behind), or ``back_m`` back where given (the planner's choice for
    this fruit)."""
    tip = f.centre_world_m + np.array([0.0, 0.0, f.d_v_m + p.security_m])
    back = dish_back_m(f, p) if back_m is None else back_m
    return ToolPoses(tip, basket_below_m(f, p), basket_back_m=back)


def pre_pose(f: FruitShape, p: PoseSettings, back_m: float | None = None) -> ToolPoses:
    """The approach/leave pose: the harvest pose moved d_z back along the optical axis, the
    dish a little lower (its rim clears the fruit's underside by more than the damper's d_s)."""
    h = harvest_pose(f, p, back_m)
    return ToolPoses(
        h.tip_world_m - p.approach_m * p.camera_axis_world,
        h.basket_below_m + p.approach_basket_drop_m,
        basket_back_m=h.basket_back_m,
    )


def plan_target(
    header: Header,
    phase: HarvestPhase,
    poses: ToolPoses | None,
    fruit_id: int | None = None,
    ignore: tuple[int, ...] = (),
    joints_rad: np.ndarray | None = None,
) -> PlanTarget:
    """The message: cutter level and pointing forward, its turn about the vertical free (θ_a);
    the dish under the tip, opening up, its turn about its normal free. None: hold still. A
    joint goal (arm order, rad) instead of poses: retracing."""
    if joints_rad is not None:
        return PlanTarget(
            header=header,
            phase=phase,
            fruit_id=fruit_id,
            ignore_fruit_ids=ignore,
            joints=joint_target(joints_rad),
        )
    if poses is None:
        return PlanTarget(header=header, phase=phase, fruit_id=fruit_id)
    t = poses.tip_world_m
    q = (
        Q_CUTTER_FORWARD
        if poses.R_world_cutter is None
        else matrix_to_quat_xyzw(poses.R_world_cutter)
    )
    return PlanTarget(
        header=header,
        phase=phase,
        fruit_id=fruit_id,
        absolute=AbsoluteTarget(
            frame_id="world",
            position_m=(float(t[0]), float(t[1]), float(t[2])),
            orientation_xyzw=q,
            free_axis="x",
        ),
        relative=RelativeTarget(
            position_m=(float(poses.basket_below_m), 0.0, -float(poses.basket_back_m)),
            orientation_xyzw=Q_BASKET_IN_CUTTER,
            free_axis="z",
        ),
        ignore_fruit_ids=ignore,
    )


def joint_target(q_rad: np.ndarray) -> dict[ArmRole, ArmJointTarget]:
    """Arm-order joint positions (cutter j1..j7, collector j1..j7) as the message's per-arm
    goals."""
    out: dict[ArmRole, ArmJointTarget] = {}
    i = 0
    for role in ARM_ROLES:
        names = joint_names(role)
        out[role] = ArmJointTarget(
            names=names, position_rad=tuple(float(v) for v in q_rad[i : i + len(names)])
        )
        i += len(names)
    return out
