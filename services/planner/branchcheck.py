"""Before committing to a fruit: can its tools take their poses clear of the branches seen?

The IK (services/robot/reach.py) knows the joint limits and the robot's own bodies, not the
tree. In a crown the dish's place under a fruit or the cutter's above it is often crossed by
another fruit's branch; the controller's dampers then stop the tools short (a stall, given up
after ``no_progress_s``) or, inside the scene's keep-out around the target where it shows no
branch to the dampers, the dish runs into it (orchard seeds 0–19 of session 13: 211 of the
tree contacts were made while the selected fruit was one whose every IK solution touches a
branch in the sim, 63 while it was one with a clear solution).

Each IK solution of the harvest pose and of the pre-pose (the planner's sampled cutter yaws) is
measured against every occupied sphere the scene shows, those inside the keep-out included
(``SceneState.spheres_near_selected``), with the controller's own distances (freespace.py). A
fruit whose clearest solution of either pose goes deeper than ``depth_m`` into the spheres is
refused before the approach starts. The spheres stand for the branch surface seen from the
camera (a voxel's points, inflated by the sphere radius), so a tool a centimetre into them is
touching the branch at most; the depth is what is allowed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from schemas.scene import Obstacles, SceneState
from services.planner.freespace import FreeSpace
from services.planner.kinematics import Kinematics
from services.planner.poses import ToolPoses


@dataclass(frozen=True)
class BranchVerdict:
    """``clear``, or the first pose (``pose``) whose clearest IK solution is ``depth_m`` into
    the occupied spheres (of ``solutions`` solutions)."""

    clear: bool
    pose: str = ""
    depth_m: float = 0.0
    solutions: int = 0

    def why(self) -> str:
        return (
            f"a branch in the tools' way at the {self.pose} (the clearest of {self.solutions} "
            f"IK solutions {self.depth_m * 1e3:.0f} mm into the occupied space seen)"
        )


class BranchCheck:
    """Args:
    depth_m: how far into the occupied spheres the clearest solution may go, m.
    """

    def __init__(self, depth_m: float) -> None:
        self.depth_m = depth_m
        self.space = FreeSpace(cull_m=0.05)
        self.spheres = 0

    def set_scene(self, scene: SceneState) -> None:
        """The occupied space of this scene state: its obstacles' spheres and those the keep-out
        leaves out (no trunk, no fruit: those are other checks)."""
        spheres = scene.obstacles.spheres + scene.spheres_near_selected
        self.spheres = len(spheres)
        self.space.set_obstacles(Obstacles(spheres=spheres))

    def check(self, kin: Kinematics, poses: list[tuple[str, ToolPoses]]) -> BranchVerdict:
        """The verdict on the fruit whose tool poses are ``poses`` ((name, pose), in order)."""
        if not self.spheres:
            return BranchVerdict(True)
        for name, pose in poses:
            sols = kin.solutions(pose.tip_world_m, pose.basket_below_m)
            if not sols:
                continue  # out of reach: the IK check says so
            best = max(self.space.clearance(s.q_rad).obstacles_m for s in sols)
            if math.isfinite(best) and best < -self.depth_m:
                return BranchVerdict(False, name, -best, len(sols))
        return BranchVerdict(True)
