"""The approach as a planned joint path: from the arms' joints now to the IK solution of the
pre-pose, around the obstacles of the latest scene state (RRT-Connect, rrt.py; clearances,
freespace.py).

The controller alone is local: its pose tasks pull the tools straight at the pre-pose and the
dampers stop the links at d_s in front of a branch, where the approach stalls (orchard:
"approach no progress"). A planned path goes around what the scene shows; the controller then
follows it as joint goals, under the same dampers, and the pose goals take over at its end.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from schemas.scene import CylinderObstacle, Obstacles, Trunk
from services.planner import Settings
from services.planner.freespace import FreeSpace, validity
from services.planner.goalclear import GoalClearer
from services.planner.kinematics import IkSolution
from services.planner.poses import FruitShape, ToolPoses
from services.planner.rrt import PlanResult, rrt_connect
from services.robot.reach import ReachSolver


@dataclass(frozen=True)
class ApproachPlan:
    """A path (None: none) and what the phase change reports about it."""

    path: list[np.ndarray] | None
    why: str


class ApproachPlanner:
    """Plans with the obstacles of the latest scene state (``obstacles``, set by the core).

    ``solver``: the IK for clearing goals (``plan_goal_margin_m``); None: goals as given."""

    def __init__(self, s: Settings, solver: ReachSolver | None = None) -> None:
        self.s = s
        self.space = FreeSpace(cull_m=max(s.plan_margin_m, s.plan_self_margin_m) + 0.02)
        self.clearer = (
            GoalClearer(
                solver, self.space, s.plan_goal_margin_m, s.plan_goal_steps, s.reach_tolerance_m
            )
            if solver is not None and s.plan_goal_margin_m > 0
            else None
        )
        self.obstacles: Obstacles | None = None
        self.trunk: Trunk | None = None
        self.plans = 0
        self.found = 0

    def plan(
        self,
        start: np.ndarray,
        goals: list[IkSolution],
        target: FruitShape,
        seed: int,
        pose: ToolPoses | None = None,
        ignore_fruit_ids: tuple[int, ...] = (),
    ) -> ApproachPlan:
        """A path from ``start`` (arm order, rad) to the clearest of ``goals`` (IK solutions of
        the pre-pose ``pose``) for the approach to ``target``; the fruit in
        ``ignore_fruit_ids`` are no obstacles (those the controller ignores: off the tree)."""
        s = self.s
        self.plans += 1
        if self.obstacles is not None:
            self.space.set_obstacles(
                trunk_for(self.obstacles, self.trunk, target, s.plan_trunk_margin_m),
                ignore_fruit_ids,
            )
        goal, moved = self._goal(goals, pose)
        valid, c0, c1 = validity(
            self.space,
            start,
            goal,
            s.plan_margin_m,
            s.plan_self_margin_m,
            s.plan_escape_rad,
            s.plan_limit_margin_rad,
        )
        if c1.obstacles_m < -s.plan_goal_max_depth_m and c1.nearest != "fruit":
            why = f"the goal is {-c1.obstacles_m * 1e3:.0f} mm inside a {c1.nearest}{moved}"
            return ApproachPlan(None, f"no planned path ({why}): pose goals")
        res: PlanResult = rrt_connect(
            start,
            goal,
            valid,  # type: ignore[arg-type]
            self.space.lower_rad + s.plan_limit_margin_rad,
            self.space.upper_rad - s.plan_limit_margin_rad,
            np.random.default_rng(seed),
            max_checks=s.plan_max_checks,
        )
        ends = f"clearance {c0.describe()} at the start, {c1.describe()} at the end{moved}"
        if res.path is None:
            return ApproachPlan(None, f"no planned path ({res.why}; {ends}): pose goals")
        self.found += 1
        return ApproachPlan(
            res.path,
            f"planned joint path {res.length_rad:.2f} rad, {res.checks} checks ({ends})",
        )

    def _goal(self, goals: list[IkSolution], pose: ToolPoses | None) -> tuple[np.ndarray, str]:
        """The clearest goal, and what the reason adds when it was moved clear. Goals closer
        than the path's margin are first moved clear (``GoalClearer``), where a clearer is set."""
        clearance = self.space.clearance
        before, best = max(
            ((clearance(g.q_rad), g) for g in goals), key=lambda cg: cg[0].obstacles_m
        )
        if self.clearer is None or pose is None or before.obstacles_m >= self.s.plan_margin_m:
            return best.q_rad, ""
        moved = []
        for g in goals:
            c = self.clearer.clear(g.q_rad, pose, g.yaw_deg)
            if c.q_rad is not None:
                moved.append(c.q_rad)
        if not moved:
            return best.q_rad, f" (no goal could be moved clear of {before.describe()})"
        q = max(moved, key=lambda m: clearance(m).obstacles_m)
        return q, f" (goal moved clear of {before.describe()})"


def trunk_for(
    obstacles: Obstacles, trunk: Trunk | None, target: FruitShape, margin_m: float
) -> Obstacles:
    """The obstacles with the trunk cylinder sized for ``target``, as the scene sizes it for the
    selected fruit (its surface ``margin_m`` behind the fruit, never inside the trunk's own
    radius). The scene state at hand was made for the fruit selected before: its cylinder may
    reach past the new target and swallow the pre-pose."""
    if not obstacles.cylinders or trunk is None:
        return obstacles
    cyl = obstacles.cylinders[0]
    axis = np.array(cyl.axis_point_world_m, float)
    h_m = float(np.hypot(*(target.centre_world_m[:2] - axis[:2])))
    own_m = trunk.radius_m if trunk.radius_m is not None else _default_trunk_radius_m()
    r_m = max(h_m - target.d_h_m - margin_m, own_m)
    resized = CylinderObstacle(
        name=cyl.name, axis_point_world_m=cyl.axis_point_world_m, radius_m=r_m
    )
    return obstacles.model_copy(update={"cylinders": (resized, *obstacles.cylinders[1:])})


def _default_trunk_radius_m() -> float:
    """The scene's radius for a trunk it does not measure (its 'paper' method)."""
    from services.scene import Settings as SceneSettings

    return float(SceneSettings.model_fields["trunk_default_radius_m"].default)
