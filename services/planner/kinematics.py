"""The planner's robot knowledge (placo, the URDF shared with the controller): the camera axis,
the ready pose, where the dish is for a joint state (forward kinematics), and whether a pose is
reachable (position-level IK of services/robot/reach.py, cached per pose).

IK runs from the ready posture every time (not from the current one), so a verdict depends on
the pose only: cacheable, and the same in every run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from schemas.base import ARM_ROLES, ArmRole
from schemas.robot import JointState
from services.planner.poses import ToolPoses
from services.robot.model import CAMERA_FRAME, HOME_RAD, TOOL_FRAME, URDF_PATH, joint_names
from services.robot.reach import R_WORLD_CUTTER_FORWARD, ReachSolver

BASKET_FRAME = TOOL_FRAME["collector"]

# The 'low' ready pose (README): arms mostly below the camera's view. Found by IK from
# HOME_RAD over tool positions, pitches and yaws, scoring the robot's share of the rendered
# image with every joint ≥ 8° inside its limits: 7 % of the image (HOME_RAD: 34 %).
LOW_READY_TIP_WORLD_M = (0.55, 0.15, 0.80)
LOW_READY_BASKET_BELOW_M = 0.14
LOW_READY_PITCH_DOWN_DEG = 30.0
LOW_READY_YAW_LEFT_DEG = 90.0


def low_ready_rotation() -> np.ndarray:
    """The cutter pointing forward, pitched down, then turned left about the vertical."""
    from services.robot.urdf import rot_y, rot_z

    return (
        rot_z(math.radians(LOW_READY_YAW_LEFT_DEG))
        @ rot_y(math.radians(LOW_READY_PITCH_DOWN_DEG))
        @ R_WORLD_CUTTER_FORWARD
    )


@dataclass(frozen=True)
class ReachVerdict:
    """IK of one tool pose: reached within tolerance, at which cutter yaw, the residuals."""

    reachable: bool
    yaw_deg: float | None
    tip_error_m: float
    basket_error_m: float

    def why(self) -> str:
        return (
            f"IK residual {self.tip_error_m * 1e3:.0f} mm at the cutter, "
            f"{self.basket_error_m * 1e3:.0f} mm at the dish"
        )


@dataclass(frozen=True)
class IkSolution:
    """Joints (arm order, rad) that take the tools to a pose, at one sampled cutter yaw."""

    yaw_deg: float
    q_rad: np.ndarray


@dataclass(frozen=True)
class DishPose:
    """Where the dish is: centre of its floor and its normal, world frame."""

    centre_world_m: np.ndarray
    normal_world: np.ndarray


class Kinematics:
    """FK for the dish and the ready pose; cached IK for reachability."""

    def __init__(
        self,
        yaws_deg: tuple[float, ...],
        iterations: int,
        tolerance_m: float,
        ready: str = "home",
        cache_mm: float = 2,
    ) -> None:
        import placo

        self.solver = ReachSolver(str(URDF_PATH))
        self.fk = placo.RobotWrapper(str(URDF_PATH))
        self.yaws_deg, self.iterations, self.tolerance_m = yaws_deg, iterations, tolerance_m
        self.cache_mm = cache_mm
        self._cache: dict[tuple[int, ...], ReachVerdict] = {}
        self._solutions: dict[tuple[int, ...], list[IkSolution]] = {}
        self.ik_solves = 0
        model = self.fk.model
        idx = [model.joints[model.getJointId(n)].idx_q for r in ARM_ROLES for n in joint_names(r)]
        self._lower_rad = np.array(model.lowerPositionLimit[idx], float)
        self._upper_rad = np.array(model.upperPositionLimit[idx], float)
        self._set(HOME_RAD)
        T_cam = np.array(self.fk.get_T_world_frame(CAMERA_FRAME))
        self.camera_axis_world: np.ndarray = T_cam[:3, 2].copy()
        self.camera_world_m: np.ndarray = T_cam[:3, 3].copy()
        T_tip = np.array(self.fk.get_T_world_frame(TOOL_FRAME["cutter"]))
        T_rel = np.array(self.fk.get_T_a_b(TOOL_FRAME["cutter"], BASKET_FRAME))
        self.ready_tip_world_m: np.ndarray = T_tip[:3, 3].copy()
        self.ready_basket_below_m = float(T_rel[0, 3])
        self.ready_R_world_cutter: np.ndarray | None = None  # level, forward (HOME_RAD's)
        if ready == "low":
            self.ready_tip_world_m = np.array(LOW_READY_TIP_WORLD_M)
            self.ready_basket_below_m = LOW_READY_BASKET_BELOW_M
            self.ready_R_world_cutter = low_ready_rotation()

    def _set(self, q_by_role: dict[ArmRole, tuple[float, ...]]) -> None:
        for role, q in q_by_role.items():
            for name, v in zip(joint_names(role), q, strict=True):
                self.fk.set_joint(name, float(v))
        self.fk.update_kinematics()

    @staticmethod
    def _by_role(js: JointState) -> dict[ArmRole, tuple[float, ...]] | None:
        """Each arm's positions in the model's joint order; None when an arm or joint is
        missing."""
        q: dict[ArmRole, tuple[float, ...]] = {}
        for role in ARM_ROLES:
            arm = js.arms.get(role)
            if arm is None or tuple(arm.names) != joint_names(role):
                return None
            q[role] = arm.position_rad
        return q

    def arm_order(self, js: JointState) -> np.ndarray | None:
        """Joint positions, cutter j1..j7 then collector j1..j7 (rad), clipped into the URDF
        limits (a sim overshoots by a hair; a goal outside would be refused); None when an arm
        or a joint is missing."""
        q = self._by_role(js)
        if q is None:
            return None
        flat = np.array([v for role in ARM_ROLES for v in q[role]], float)
        return np.clip(flat, self._lower_rad, self._upper_rad)

    def dish(self, js: JointState) -> DishPose | None:
        """The dish pose for a joint state; None when an arm or joint is missing."""
        q = self._by_role(js)
        if q is None:
            return None
        self._set(q)
        T = np.array(self.fk.get_T_world_frame(BASKET_FRAME))
        return DishPose(T[:3, 3].copy(), T[:3, 2].copy())

    def _solution(self) -> np.ndarray:
        """The IK solver's joints, arm order, clipped into the limits."""
        r = self.solver.robot
        q = [r.get_joint(n) for role in ARM_ROLES for n in joint_names(role)]
        return np.clip(np.array(q, float), self._lower_rad, self._upper_rad)

    def _key(self, pose: ToolPoses) -> tuple[int, ...]:
        """A pose's cache key: tip, dish below and back, rounded to ``cache_mm``."""
        values = (*pose.tip_world_m, pose.basket_below_m, pose.basket_back_m)
        return tuple(round(float(v) * 1e3 / self.cache_mm) for v in values)

    def _solve(self, pose: ToolPoses, yaw_deg: float) -> tuple[float, float]:
        """IK of ``pose`` at one cutter yaw, the dish where the PlanTarget sends it (below and
        back): (tip error, dish error), m."""
        self.ik_solves += 1
        return self.solver.solve(
            np.asarray(pose.tip_world_m, float),
            math.radians(yaw_deg),
            self.iterations,
            pose.basket_below_m,
            pose.basket_back_m,
        )

    def solutions(self, pose: ToolPoses) -> list[IkSolution]:
        """The IK solutions of this pose at every sampled yaw that reaches it: the planned
        approach picks the one clearest of the obstacles. Cached like ``reach``."""
        key = self._key(pose)
        got = self._solutions.get(key)
        if got is not None:
            return got
        out = []
        for yaw in self.yaws_deg:
            pe, be = self._solve(pose, yaw)
            if pe < self.tolerance_m and be < self.tolerance_m:
                out.append(IkSolution(yaw, self._solution()))
        self._solutions[key] = out
        return out

    def reach(self, pose: ToolPoses) -> ReachVerdict:
        """Can both tools take this pose (cutter level, some sampled yaw; the dish under the tip,
        ``basket_back_m`` back)? Cached on the pose rounded to ``cache_mm``."""
        key = self._key(pose)
        got = self._cache.get(key)
        if got is not None:
            return got
        best = (math.inf, math.inf)
        verdict: ReachVerdict | None = None
        for yaw in self.yaws_deg:
            pe, be = self._solve(pose, yaw)
            if pe < self.tolerance_m and be < self.tolerance_m:
                verdict = ReachVerdict(True, yaw, pe, be)
                break
            if pe + be < sum(best):
                best = (pe, be)
        if verdict is None:
            verdict = ReachVerdict(False, None, *best)
        self._cache[key] = verdict
        return verdict
