"""Clear goals for the planned approach: an IK solution of the pre-pose moved in the arms' null
space (the tools held at the pose) until the robot keeps a margin from the scene's obstacles.

The IK (services/robot/reach.py) knows the joint limits and the robot's own bodies, not the
branches: its solutions for a fruit in the crown often put a forearm through a branch
(paper-exp1 seed 0: every solution for the high left fruit had the collector's forearm 26–33 mm
inside the spheres of a neighbour's twig, so no path could end there). Each arm has a free
elbow (7 joints, 6 for its tool; the dish's turn about its normal is free too), so the same pose
can often be held with the arms elsewhere. The IK is stepped again from the solution with one
half-space per obstacle pair, the controller's velocity dampers (services/controller/
dampers.py) with d_s = the margin: a pair closer than the margin is pushed out by at most
``push_m`` per step, one farther may not come closer than the margin. The constraint is soft
(weight 1, as the tasks): where the margin cannot be had with the tools at the pose, the
solution drifts off the pose and is refused by the tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.controller.dampers import DamperParams, damper_rows
from services.controller.distances import PairKind
from services.planner.freespace import FreeSpace
from services.planner.poses import ToolPoses
from services.robot.reach import ReachSolver

_KINDS: tuple[PairKind, ...] = ("trunk", "fruit", "branch")
_STEP_S = 0.02  # the IK's dt (reach.py): a joint moves at most dt × its velocity limit a step


@dataclass(frozen=True)
class ClearedGoal:
    """A goal moved clear (None: the margin could not be had with the tools at the pose)."""

    q_rad: np.ndarray | None
    steps: int


class GoalClearer:
    """Args:
    solver: the IK (its robot's joints are overwritten).
    space: the planner's free space, obstacles already set.
    margin_m: distance to keep from every obstacle, m.
    steps: IK steps at most.
    tolerance_m: largest tool residual accepted (reach tolerance), m.
    push_m: largest separation a step asks of a pair closer than the margin, m.
    """

    def __init__(
        self,
        solver: ReachSolver,
        space: FreeSpace,
        margin_m: float,
        steps: int,
        tolerance_m: float,
        push_m: float = 0.001,
    ) -> None:
        self.solver, self.space = solver, space
        self.margin_m, self.steps, self.tolerance_m = margin_m, steps, tolerance_m
        # ḋ* below the margin is push_m per step; the band above it stops an approach
        self.params: dict[PairKind, DamperParams] = {
            k: DamperParams(margin_m + 0.03, margin_m, push_m / _STEP_S) for k in _KINDS
        }
        self._names = space.robot.names

    def clear(self, q_rad: np.ndarray, pose: ToolPoses, yaw_deg: float) -> ClearedGoal:
        """``q_rad`` (arm order, an IK solution of ``pose`` at ``yaw_deg``) moved until the
        robot is ``margin_m`` from every obstacle with the tools still at the pose."""
        r, space = self.solver.robot, self.space
        for name, v in zip(self._names, q_rad, strict=True):
            r.set_joint(name, float(v))
        r.update_kinematics()
        yaw = math.radians(yaw_deg)
        tip_world_m, below_m, back_m = pose.tip_world_m, pose.basket_below_m, pose.basket_back_m
        ik = self.solver.harvest_solver(tip_world_m, yaw, below_m, back_m)
        half = ik.add_joint_space_half_spaces_constraint(np.zeros((1, r.state.q.size)), np.ones(1))
        half.configure("obstacles", "soft", 1.0)
        activation = {k: p.activation_m for k, p in self.params.items()}
        q = np.asarray(q_rad, float)
        for step in range(self.steps):
            space.robot.set_q(q)
            rep = space.engine.compute(space.obstacles, activation)
            pairs = [p for p in rep.pairs if p.kind != "self"]
            clear = min((p.distance_m for p in pairs), default=math.inf) >= self.margin_m
            if clear and self._at_pose(tip_world_m, yaw, below_m, back_m):
                return ClearedGoal(q, step)
            rows = damper_rows(pairs, space.robot, self.params, _STEP_S)
            half.A, half.b = rows.A, rows.b
            try:
                ik.solve(True)
            except RuntimeError:
                return ClearedGoal(None, step)
            r.update_kinematics()
            q = np.clip(
                np.array([r.get_joint(n) for n in self._names]), space.lower_rad, space.upper_rad
            )
        return ClearedGoal(None, self.steps)

    def _at_pose(self, tip: np.ndarray, yaw: float, below: float, back: float) -> bool:
        pe, be = self.solver.residuals(tip, yaw, below, back)
        return pe < self.tolerance_m and be < self.tolerance_m
