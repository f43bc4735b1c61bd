"""Checks that turn messages into controller quantities, or into a stated refusal.

Each function returns either the value or a ``Refusal`` (the reason, in words); the core then
holds the arms still rather than guess."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from schemas.base import ARM_ROLES, ArmRole
from schemas.control import PlanTarget
from schemas.robot import JointState
from services.controller.geometry import quat_xyzw_to_matrix
from services.controller.targets import PoseGoal
from services.robot.model import CAMERA_FRAME

QUAT_NORM_TOL = 1e-3  # a target quaternion must be unit to this tolerance


@dataclass(frozen=True)
class Refusal:
    reason: str


@dataclass(frozen=True)
class Workspace:
    """Where the cutter may be sent: a world box (m), a reach sphere around the cutter's arm
    base, and a bound on the distance between the tools (m)."""

    min_world_m: tuple[float, float, float]
    max_world_m: tuple[float, float, float]
    shoulder_world_m: np.ndarray
    reach_m: float
    max_relative_m: float


@dataclass(frozen=True)
class Goals:
    """A valid target: the absolute goal (world) and the relative goal (cutter frame). A joint
    goal (arm order, rad) comes with the tool poses it puts the tools in: the status reports
    the tools' errors against those."""

    absolute: PoseGoal
    relative: PoseGoal
    joints_rad: np.ndarray | None = None


def joint_goal(
    target: PlanTarget,
    by_role: dict[ArmRole, tuple[str, ...]],
    lower_rad: np.ndarray,
    upper_rad: np.ndarray,
) -> np.ndarray | Refusal:
    """Arm-order goal positions of a joint target, rad: every joint of the model exactly once,
    inside its limits."""
    assert target.joints is not None
    out: list[float] = []
    for role in ARM_ROLES:
        arm = target.joints.get(role)
        if arm is None:
            return Refusal(f"joint target has no {role} arm")
        if tuple(arm.names) != by_role[role]:
            return Refusal(f"joint target of the {role} arm names {arm.names}, not {by_role[role]}")
        out += arm.position_rad
    q = np.array(out, dtype=float)
    bad = np.flatnonzero((q < lower_rad) | (q > upper_rad))
    if bad.size:
        names = [n for r in ARM_ROLES for n in by_role[r]]
        i = int(bad[0])
        return Refusal(
            f"joint target {names[i]} = {q[i]:.3f} rad is outside its limits "
            f"[{lower_rad[i]:.3f}, {upper_rad[i]:.3f}]"
        )
    return q


def joint_positions(
    js: JointState, by_role: dict[ArmRole, tuple[str, ...]]
) -> np.ndarray | Refusal:
    """Arm-order positions (cutter then collector), rad, mapped by name; every joint of the
    model must be present exactly once and nothing else."""
    out: list[float] = []
    for role in ARM_ROLES:
        arm = js.arms.get(role)
        want = by_role[role]
        if arm is None:
            return Refusal(f"joint state has no {role} arm")
        pos = dict(zip(arm.names, arm.position_rad, strict=True))
        missing = [n for n in want if n not in pos]
        extra = sorted(set(arm.names) - set(want))
        if missing or extra or len(arm.names) != len(want):
            what = ", ".join(
                ([f"missing {', '.join(missing)}"] if missing else [])
                + ([f"unknown {', '.join(extra)}"] if extra else [])
                + (["duplicated names"] if not missing and not extra else [])
            )
            return Refusal(f"joint state of the {role} arm: {what}")
        out += [pos[n] for n in want]
    q = np.array(out, dtype=float)
    if not np.all(np.isfinite(q)):
        return Refusal("joint state has non-finite positions")
    return q


def goals(target: PlanTarget, T_world_camera: np.ndarray, ws: Workspace) -> Goals | Refusal | None:
    """The goals of a plan target; None when the planner asks to hold (a missing task)."""
    if target.absolute is None or target.relative is None:
        return None
    a, r = target.absolute, target.relative
    for what, q in (("absolute", a.orientation_xyzw), ("relative", r.orientation_xyzw)):
        n = math.sqrt(sum(v * v for v in q))
        if not math.isfinite(n) or abs(n - 1.0) > QUAT_NORM_TOL:
            return Refusal(f"{what} target quaternion has norm {n:.4g}, not 1")
    p = np.array(a.position_m, dtype=float)
    R = quat_xyzw_to_matrix(a.orientation_xyzw)
    if a.frame_id == CAMERA_FRAME:
        p = T_world_camera[:3, :3] @ p + T_world_camera[:3, 3]
        R = T_world_camera[:3, :3] @ R
    elif a.frame_id != "world":
        return Refusal(
            f"absolute target frame {a.frame_id!r} is neither 'world' nor {CAMERA_FRAME!r}"
        )
    if not np.all(np.isfinite(p)):
        return Refusal("absolute target position is not finite")
    lo, hi = np.array(ws.min_world_m), np.array(ws.max_world_m)
    if np.any(p < lo) or np.any(p > hi):
        return Refusal(f"absolute target {np.round(p, 3).tolist()} m is outside the workspace box")
    reach = float(np.linalg.norm(p - ws.shoulder_world_m))
    if reach > ws.reach_m:
        return Refusal(
            f"absolute target is {reach:.3f} m from the cutter arm's base "
            f"(reach {ws.reach_m:.3f} m)"
        )
    p_rel = np.array(r.position_m, dtype=float)
    if not np.all(np.isfinite(p_rel)) or float(np.linalg.norm(p_rel)) > ws.max_relative_m:
        return Refusal(
            f"relative target {np.round(p_rel, 3).tolist()} m is farther than "
            f"{ws.max_relative_m} m from the cutter"
        )
    return Goals(
        PoseGoal(p, R, a.free_axis),
        PoseGoal(p_rel, quat_xyzw_to_matrix(r.orientation_xyzw), r.free_axis),
    )
