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

from schemas.scene import Obstacles
from services.planner import Settings
from services.planner.freespace import FreeSpace, validity
from services.planner.rrt import PlanResult, rrt_connect


@dataclass(frozen=True)
class ApproachPlan:
    """A path (None: none) and what the phase change reports about it."""

    path: list[np.ndarray] | None
    why: str


class ApproachPlanner:
    """Plans with the obstacles of the latest scene state (``obstacles``, set by the core)."""

    def __init__(self, s: Settings) -> None:
        self.s = s
        self.space = FreeSpace(cull_m=max(s.plan_margin_m, s.plan_self_margin_m) + 0.02)
        self.obstacles: Obstacles | None = None
        self.plans = 0
        self.found = 0

    def plan(self, start: np.ndarray, goal: np.ndarray, seed: int) -> ApproachPlan:
        s = self.s
        self.plans += 1
        if self.obstacles is not None:
            self.space.set_obstacles(self.obstacles)
        valid, c0, c1 = validity(
            self.space, start, goal, s.plan_margin_m, s.plan_self_margin_m, s.plan_escape_rad
        )
        res: PlanResult = rrt_connect(
            start,
            goal,
            valid,  # type: ignore[arg-type]
            self.space.lower_rad,
            self.space.upper_rad,
            np.random.default_rng(seed),
            max_checks=s.plan_max_checks,
        )
        ends = f"clearance {_mm(c0.obstacles_m)} at the start, {_mm(c1.obstacles_m)} at the end"
        if res.path is None:
            return ApproachPlan(None, f"no planned path ({res.why}; {ends}): pose goals")
        self.found += 1
        return ApproachPlan(
            res.path,
            f"planned joint path {res.length_rad:.2f} rad, {res.checks} checks ({ends})",
        )


def _mm(d_m: float) -> str:
    return "clear" if not np.isfinite(d_m) else f"{d_m * 1e3:.0f} mm"
