"""Reachability of the harvest poses: can both tools reach fruit 0.4–0.9 m in front of the camera
with the tools pointing forward? Position-level IK with placo (joint limits and self-collision
on, yaw of the tools free by sampling), used to choose the mount and checked by a test.

    python -m services.robot.reach    # prints the reach table of the current model
"""

from __future__ import annotations

import itertools
import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from services.robot.model import CAMERA_FRAME, HOME_RAD, TOOL_FRAME, URDF_PATH, joint_names
from services.robot.urdf import rot_y, rot_z

BASKET_BELOW_M = 0.14  # collector centre below the cutter tip (fruit of ~4 cm radius between)
PEDUNCLE_ABOVE_M = 0.06  # cutter tip above the fruit centre (d_v + d_s)


# Cutter tool frame pointing forward: z = +x world, x down, y left (columns of the matrix).
_FWD = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
_BASKET_IN_CUTTER = rot_y(-math.pi / 2)  # basket z (dish normal) = cutter -x = up

# The harvest-pose convention, public for the controller and its benchmark (same values).
R_WORLD_CUTTER_FORWARD = _FWD
"""Cutter orientation, level and pointing forward (world x), its x axis down."""
R_CUTTER_BASKET = _BASKET_IN_CUTTER
"""Collector (basket) orientation in the cutter frame: dish normal = cutter −x (up)."""


@dataclass(frozen=True)
class ReachResult:
    fruit_world_m: tuple[float, float, float]
    reached: bool
    yaw_deg: float | None
    pos_err_m: float
    rel_err_m: float


class ReachSolver:
    """Position-level IK for the harvest pose of both arms."""

    def __init__(self, urdf: str = str(URDF_PATH)) -> None:
        import placo

        self.placo = placo
        self.robot = placo.RobotWrapper(urdf)
        self.T_world_cam = self._home_and_camera()

    def _home_and_camera(self) -> np.ndarray:
        self.set_home()
        return np.array(self.robot.get_T_world_frame(CAMERA_FRAME))

    def set_home(self) -> None:
        for role, q in HOME_RAD.items():
            for name, v in zip(joint_names(role), q, strict=True):
                self.robot.set_joint(name, v)
        self.robot.update_kinematics()

    def solve(
        self,
        p_tip_world: np.ndarray,
        yaw_rad: float = 0.0,
        iters: int = 250,
        basket_below_m: float = BASKET_BELOW_M,
        basket_back_m: float = 0.0,
    ) -> tuple[float, float]:
        """IK of the harvest pose from the home posture. The cutter points forward (tool axis
        horizontal) turned by ``yaw_rad`` about the world vertical (the paper's free θ_a, sampled
        by ``reach``); the dish is ``basket_below_m`` under the tip, opening up, its rotation
        about its own normal free, and ``basket_back_m`` back along the cutter's pointing axis
        (the planner's ``dish_back_m``, as the controller is asked). Returns (tip error,
        relative error) in m (orientation errors × 0.1 m/rad)."""
        self.set_home()
        s = self.harvest_solver(p_tip_world, yaw_rad, basket_below_m, basket_back_m)
        for _ in range(iters):
            try:
                s.solve(True)
            except RuntimeError:
                break
            self.robot.update_kinematics()
        return self.residuals(p_tip_world, yaw_rad, basket_below_m, basket_back_m)

    def harvest_solver(
        self,
        p_tip_world: np.ndarray,
        yaw_rad: float,
        basket_below_m: float,
        basket_back_m: float = 0.0,
    ) -> Any:
        """A placo KinematicsSolver on ``robot`` (from its joints now) with the harvest pose's
        soft tasks (see ``solve``), joint and velocity limits and self-collision avoidance;
        the caller steps it (``solve(True)``, then ``robot.update_kinematics()``)."""
        offset = dish_in_cutter_m(basket_below_m, basket_back_m)
        s = self.placo.KinematicsSolver(self.robot)
        s.mask_fbase(True)
        s.enable_joint_limits(True)
        s.add_regularization_task(1e-5)
        pos = s.add_position_task(TOOL_FRAME["cutter"], p_tip_world)
        pos.configure("tip", "soft", 1.0)
        ori = s.add_orientation_task(TOOL_FRAME["cutter"], rot_z(yaw_rad) @ _FWD)
        ori.configure("tip_ori", "soft", 1.0)
        rpos = s.add_relative_position_task(TOOL_FRAME["cutter"], TOOL_FRAME["collector"], offset)
        rpos.configure("rel", "soft", 1.0)
        rori = s.add_relative_orientation_task(
            TOOL_FRAME["cutter"], TOOL_FRAME["collector"], _BASKET_IN_CUTTER
        )
        rori.configure("rel_ori", "soft", 1.0)
        rori.mask.set_axises("yz", "local")  # free about cutter x = the dish normal
        sc = s.add_avoid_self_collisions_constraint()
        sc.configure("selfcol", "hard")
        sc.self_collisions_margin = 0.01
        sc.self_collisions_trigger = 0.05
        s.enable_velocity_limits(True)
        s.dt = 0.02
        return s

    def residuals(
        self,
        p_tip_world: np.ndarray,
        yaw_rad: float,
        basket_below_m: float,
        basket_back_m: float = 0.0,
    ) -> tuple[float, float]:
        """(tip error, relative error) of ``robot``'s joints now for the harvest pose, m (see
        ``solve``)."""
        r = self.robot
        R = rot_z(yaw_rad) @ _FWD
        offset = dish_in_cutter_m(basket_below_m, basket_back_m)
        T = r.get_T_world_frame(TOOL_FRAME["cutter"])
        pos_err = float(np.linalg.norm(T[:3, 3] - p_tip_world))
        pos_err += 0.1 * float(np.linalg.norm(_log3(R @ T[:3, :3].T)))
        T_rel = r.get_T_a_b(TOOL_FRAME["cutter"], TOOL_FRAME["collector"])
        rel_err = float(np.linalg.norm(T_rel[:3, 3] - offset))
        normal = (T[:3, :3] @ T_rel[:3, :3])[:, 2]
        rel_err += 0.1 * math.acos(max(-1.0, min(1.0, normal[2])))  # dish normal vs up, rad
        return pos_err, rel_err

    def reach(
        self,
        fruit_world_m: np.ndarray,
        yaws_deg: tuple[float, ...] = (0, -25, 25, -50, 50),
        tol_m: float = 0.005,
    ) -> ReachResult:
        tip = fruit_world_m + np.array([0, 0, PEDUNCLE_ABOVE_M])
        fruit = (float(fruit_world_m[0]), float(fruit_world_m[1]), float(fruit_world_m[2]))
        best = (math.inf, math.inf)
        for yaw in yaws_deg:
            pe, re = self.solve(tip, math.radians(yaw))
            if pe < tol_m and re < tol_m:
                return ReachResult(fruit, True, yaw, pe, re)
            if pe + re < sum(best):
                best = (pe, re)
        return ReachResult(fruit, False, None, *best)

    def fruit_in_camera(self, depth_m: float, x_cam_m: float, y_cam_m: float) -> np.ndarray:
        p = self.T_world_cam @ np.array([x_cam_m, y_cam_m, depth_m, 1.0])
        return p[:3]


def dish_in_cutter_m(below_m: float, back_m: float = 0.0) -> np.ndarray:
    """The dish centre in the cutter frame, m: ``below_m`` under the tip (cutter x points down)
    and ``back_m`` back along its pointing axis (cutter z), as in the planner's PlanTarget."""
    return np.array([below_m, 0.0, -back_m])


def _basket_offset() -> np.ndarray:
    return dish_in_cutter_m(BASKET_BELOW_M)


def basket_offset_cutter_m() -> np.ndarray:
    """Collector (dish centre) position in the cutter frame, m: BASKET_BELOW_M under the tip."""
    return _basket_offset()


def _T(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def _log3(R: np.ndarray) -> np.ndarray:
    c = max(-1.0, min(1.0, (np.trace(R) - 1) / 2))
    a = math.acos(c)
    if a < 1e-9:
        return np.zeros(3)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return a * w / (2 * math.sin(a))


def grid(solver: ReachSolver) -> list[np.ndarray]:
    """Fruit in the camera's view: depth 0.4–0.9 m, lateral and vertical spread in the image."""
    out = []
    for depth, u, v in itertools.product((0.4, 0.55, 0.7, 0.9), (-0.35, 0, 0.35), (-0.2, 0.0, 0.2)):
        out.append(solver.fruit_in_camera(depth, u * depth, v * depth))
    return out


def main() -> int:
    s = ReachSolver()
    res = [s.reach(p) for p in grid(s)]
    for r in res:
        x, y, z = r.fruit_world_m
        print(
            f"fruit ({x:5.2f} {y:5.2f} {z:5.2f})  {'ok ' if r.reached else 'NO '}"
            f"yaw {r.yaw_deg}  pos {r.pos_err_m * 1e3:6.1f} mm  rel {r.rel_err_m * 1e3:6.1f} mm"
        )
    n = sum(r.reached for r in res)
    print(f"{n}/{len(res)} reachable")
    return 0 if n == len(res) else 1


if __name__ == "__main__":
    sys.exit(main())
