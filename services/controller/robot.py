"""The controller's robot: placo's RobotWrapper (tasks, QP) plus a pinocchio Data of the same
model (joint Jacobians, geometry placements), with the maps between the message joint order and
placo's q / v vectors. placo lists the collector's joints first; messages are keyed by role, so
everything here maps by name."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from schemas.base import ARM_ROLES, ArmRole
from services.robot.model import CAMERA_FRAME, TOOL_FRAME, joint_names

N_FBASE_Q = 7  # placo's floating base: [x y z qx qy qz qw] first in q ...
N_FBASE_V = 6  # ... and 6 velocity entries first in v (masked: the torso does not move)


class ControlledRobot:
    """Joint order "arm order" everywhere in the controller: cutter j1..j7, then collector j1..j7.

    Attributes:
        names: joint names in arm order.
        q_idx / v_idx: where each arm-order joint sits in placo's q (nq = 21) and v (nv = 20).
        lower_rad / upper_rad / vmax_rad_s: limits from the URDF, arm order.
    """

    def __init__(self, urdf_path: str | Path) -> None:
        import pinocchio as pin
        import placo

        self.pin = pin
        self.robot = placo.RobotWrapper(str(urdf_path))
        self.model = self.robot.model
        self.data = self.model.createData()
        self.names: tuple[str, ...] = tuple(n for r in ARM_ROLES for n in joint_names(r))
        self.by_role: dict[ArmRole, tuple[str, ...]] = {r: joint_names(r) for r in ARM_ROLES}
        ids = [self.model.getJointId(n) for n in self.names]
        self.q_idx = np.array([self.model.joints[i].idx_q for i in ids])
        self.v_idx = np.array([self.model.joints[i].idx_v for i in ids])
        self.lower_rad = np.array(self.model.lowerPositionLimit[self.q_idx])
        self.upper_rad = np.array(self.model.upperPositionLimit[self.q_idx])
        self.vmax_rad_s = np.array(self.model.velocityLimit[self.v_idx])
        self._widened: set[int] = set()
        self.tool_frame = TOOL_FRAME
        self.T_world_camera = np.eye(4)
        # Stretched (all joints 0, inside the LWR limits) the arm is at its longest: that
        # base-to-tip distance bounds where a cutter target can be.
        self.set_q(np.zeros(len(self.names)))
        self.T_world_camera = np.array(self.robot.get_T_world_frame(CAMERA_FRAME))
        self.cutter_base_world_m = self.T_world("cutter_base")[:3, 3]
        self.cutter_reach_m = float(
            np.linalg.norm(self.T_world(TOOL_FRAME["cutter"])[:3, 3] - self.cutter_base_world_m)
        )

    # ---- state -----------------------------------------------------------------------------
    def set_q(self, q_rad: np.ndarray) -> None:
        """Set the arm-order joint positions, rad, and update every kinematic quantity."""
        q = self.robot.state.q
        q[self.q_idx] = q_rad
        self.robot.state.q = q
        self.robot.update_kinematics()
        # Joint Jacobians (world) and joint placements for the dampers and the geometry.
        self.pin.computeJointJacobians(self.model, self.data, self.robot.state.q)

    @property
    def q_full(self) -> np.ndarray:
        return np.array(self.robot.state.q)

    def arm_order(self, v_full: np.ndarray) -> np.ndarray:
        """Arm-order entries of a placo v-space vector (nv = 20)."""
        return np.asarray(v_full)[self.v_idx]

    def T_world(self, frame: str) -> np.ndarray:
        return np.array(self.robot.get_T_world_frame(frame))

    def T_a_b(self, a: str, b: str) -> np.ndarray:
        return np.array(self.robot.get_T_a_b(a, b))

    def joint_jacobian_world(self, joint_id: int) -> np.ndarray:
        """6 × nv spatial Jacobian of a joint, world frame at the world origin (v, ω)."""
        return np.asarray(
            self.pin.getJointJacobian(
                self.model, self.data, joint_id, self.pin.ReferenceFrame.WORLD
            )
        )

    # ---- limits ----------------------------------------------------------------------------
    def admit_outside_limits(self, q_rad: np.ndarray) -> list[str]:
        """Widen the QP's position limits to include ``q_rad`` where a joint is already
        outside (a simulator overshoots by a hair): the QP may then hold or move it back in but
        never further out, instead of being infeasible. Restores the URDF limits of joints that
        are back inside. Returns the names of joints outside their limits."""
        if not self._widened and bool(
            np.all((q_rad >= self.lower_rad) & (q_rad <= self.upper_rad))
        ):
            return []  # the usual case, without a Python loop
        outside = []
        for i, (q, lo, hi) in enumerate(zip(q_rad, self.lower_rad, self.upper_rad, strict=True)):
            if q < lo or q > hi:
                outside.append(self.names[i])
                self.robot.set_joint_limits(self.names[i], min(lo, q), max(hi, q))
                self._widened.add(i)
            elif i in self._widened:
                self.robot.set_joint_limits(self.names[i], lo, hi)
                self._widened.discard(i)
        return outside
