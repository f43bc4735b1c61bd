"""Free space for the approach planner: how far a joint configuration keeps the robot from the
scene's obstacles (trunk, fruit, occupied-space spheres) and from itself.

The distances are the controller's own (services/controller/distances.py: coal on the URDF's
collision model, the dish as its hull), so the planner plans against exactly the geometry the
dampers guard.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from schemas.scene import Obstacles
from services.robot.model import URDF_PATH


@dataclass(frozen=True)
class Clearance:
    """Smallest distances of one configuration, m (inf: nothing within the broad phase)."""

    obstacles_m: float
    self_m: float
    nearest: str = ""  # the obstacle kind at obstacles_m: trunk, fruit or branch

    def describe(self) -> str:
        if not math.isfinite(self.obstacles_m):
            return "clear"
        return f"{self.obstacles_m * 1e3:.0f} mm ({self.nearest})"


class FreeSpace:
    """Clearance of joint configurations (arm order: cutter j1..j7, collector j1..j7) against
    the obstacles last given to ``set_obstacles``.

    Args:
        cull_m: distances beyond this are not computed (reported as inf); ≥ every margin used.
    """

    def __init__(self, cull_m: float = 0.1) -> None:
        from services.controller.distances import DistanceEngine
        from services.controller.obstacles import EMPTY
        from services.controller.robot import ControlledRobot

        self.robot = ControlledRobot(URDF_PATH)
        self.engine = DistanceEngine(self.robot, cull_m)
        self.lower_rad, self.upper_rad = self.robot.lower_rad, self.robot.upper_rad
        self.obstacles = EMPTY
        self.checks = 0

    def set_obstacles(self, obstacles: Obstacles, ignore_fruit_ids: tuple[int, ...] = ()) -> None:
        from services.controller.obstacles import obstacle_arrays

        self.obstacles = obstacle_arrays(obstacles, ignore_fruit_ids)

    def clearance(self, q_rad: np.ndarray) -> Clearance:
        self.checks += 1
        self.robot.set_q(q_rad)
        rep = self.engine.compute(self.obstacles, {})
        near = [(d, k) for k in ("trunk", "fruit", "branch") if (d := rep.min_m.get(k)) is not None]
        self_m = rep.min_m.get("self")
        d_m, kind = min(near) if near else (math.inf, "")
        return Clearance(d_m, math.inf if self_m is None else float(self_m), kind)


def validity(
    space: FreeSpace,
    start: np.ndarray,
    goal: np.ndarray,
    margin_m: float,
    self_margin_m: float,
    escape_rad: float,
    limit_margin_rad: float = 0.0,
) -> tuple[object, Clearance, Clearance]:
    """The validity test of a plan between ``start`` and ``goal``: clear by the margins and
    ``limit_margin_rad`` inside the joint limits (the controller slows a joint down near its
    limit, the sim clamps it); within ``escape_rad`` of an end that is itself closer than the
    margin (the arms start among the branches, the pre-pose sits in the crown), no closer than
    that end.

    Returns the test and the clearances of both ends."""
    c_start, c_goal = space.clearance(start), space.clearance(goal)
    ends = [(start, c_start), (goal, c_goal)]
    lo, hi = space.lower_rad + limit_margin_rad, space.upper_rad - limit_margin_rad

    def near_end(q: np.ndarray) -> list[tuple[np.ndarray, Clearance]]:
        return [(e, c) for e, c in ends if float(np.max(np.abs(q - e))) <= escape_rad]

    def valid(q: np.ndarray) -> bool:
        if not bool(np.all((q >= lo) & (q <= hi))) and not near_end(q):
            return False
        c = space.clearance(q)
        if c.obstacles_m >= margin_m and c.self_m >= self_margin_m:
            return True
        return any(
            c.obstacles_m >= min(margin_m, ce.obstacles_m) - 1e-3
            and c.self_m >= min(self_margin_m, ce.self_m) - 1e-3
            for _end, ce in near_end(q)
        )

    return valid, c_start, c_goal
