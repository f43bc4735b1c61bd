"""Which neighbours would the arms touch at every IK solution of a fruit's poses? Those are
harvested first (``crowd_first``).

The clutter test (clutter.py) asks whether a neighbour stands where the *tools* go; the arms
themselves (forearms, elbows, the collector's wrist under the fruit) are not in it. In the
orchard's crown most fruit can be reached only past a neighbour: orchard seeds 0–19 (session
30), 65 of the 101 reachable fruit had every tree-free IK solution of a pose put a robot body
against another fruit, and such a fruit was lost 34 % of the time against 8 % for the others.
The controller's fruit dampers hold the arm d_s from that neighbour, so the dish stops short
(a stalled harvest with the collector's elbow at its limit) or the arm pushes the neighbour
aside (a collision). Harvested first, the neighbour is out of the way.

Each IK solution of the harvest pose and of the pre-pose (the planner's sampled cutter yaws,
cached by ``Kinematics``) is measured against the scene's estimates of the other fruit on the
tree, as the controller's dampers see them (ellipsoids d_h, d_h, d_v; every robot body, with
the controller's distances: freespace.py). A pose whose every solution has a body within
``clearance_m`` of some neighbour is crowded; its crowders are the neighbours touched by the
solution that touches the fewest (ties: the shallowest). This orders the harvest, it refuses
nothing: a fruit whose crowders cannot go first is still attempted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from schemas.scene import EllipsoidObstacle, Obstacles
from services.planner.freespace import FreeSpace
from services.planner.kinematics import Kinematics
from services.planner.poses import FruitShape, ToolPoses

CULL_M = 0.05  # the broad phase's reach beyond the clearance


@dataclass(frozen=True)
class Crowding:
    """The neighbours (indices into the list given) that the arms would touch at the named
    pose, and how deep the least-touching solution goes into the deepest of them, m."""

    pose: str
    neighbours: tuple[int, ...]
    depth_m: float

    def why(self, names: str) -> str:
        return (
            f"every IK solution of the {self.pose} puts an arm within reach of {names} "
            f"({self.depth_m * 1e3:.0f} mm into it at the clearest)"
        )


class CrowdCheck:
    """Args:
    clearance_m: a robot body nearer than this to a neighbour's ellipsoid touches it, m
        (0: contact with the estimate; the dampers act at d_s beyond it).
    """

    def __init__(self, clearance_m: float) -> None:
        self.clearance_m = clearance_m
        self.space = FreeSpace(cull_m=clearance_m + CULL_M)

    def crowders(
        self,
        kin: Kinematics,
        poses: Sequence[tuple[str, ToolPoses]],
        neighbours: Sequence[FruitShape],
    ) -> Crowding | None:
        """The first of ``poses`` ((name, pose), in order) whose every IK solution touches one
        of ``neighbours``; None when each pose has a solution clear of them all (or no
        solution: out of reach is the IK check's verdict)."""
        if not neighbours:
            return None
        centres = np.array([n.centre_world_m for n in neighbours], float)
        semi = np.array([(n.d_h_m, n.d_h_m, n.d_v_m) for n in neighbours], float)
        self.space.set_obstacles(
            Obstacles(
                ellipsoids=tuple(
                    EllipsoidObstacle(
                        name=f"neighbour_{i}",
                        center_world_m=(float(c[0]), float(c[1]), float(c[2])),
                        semi_axes_m=(float(s[0]), float(s[1]), float(s[2])),
                    )
                    for i, (c, s) in enumerate(zip(centres, semi, strict=True))
                )
            )
        )
        for name, pose in poses:
            sols = kin.solutions(pose)
            if not sols:
                continue
            touched = [self._touched(s.q_rad, centres, semi) for s in sols]
            if any(not t for t in touched):
                continue
            best = min(touched, key=lambda t: (len(t), max(t.values())))
            return Crowding(name, tuple(sorted(best)), max(best.values()))
        return None

    def _touched(
        self, q_rad: np.ndarray, centres: np.ndarray, semi: np.ndarray
    ) -> dict[int, float]:
        """Neighbour index → how far the robot goes into ``clearance_m`` of it at ``q_rad``."""
        space = self.space
        space.robot.set_q(q_rad)
        rep = space.engine.compute(space.obstacles, {"fruit": self.clearance_m})
        out: dict[int, float] = {}
        for p in rep.pairs:
            if p.kind != "fruit" or p.distance_m >= self.clearance_m:
                continue
            i = nearest_ellipsoid(p.p2_world_m, centres, semi)
            out[i] = max(out.get(i, 0.0), self.clearance_m - p.distance_m)
        return out


def nearest_ellipsoid(p_world_m: np.ndarray, centres: np.ndarray, semi: np.ndarray) -> int:
    """The ellipsoid whose surface ``p_world_m`` (a witness point on one of them) lies on: the
    one whose scaled radius there is nearest 1."""
    r = np.linalg.norm((np.asarray(p_world_m, float)[None, :] - centres) / semi, axis=1)
    return int(np.argmin(np.abs(r - 1.0)))
