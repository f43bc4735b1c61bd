"""How far a point is from the robot in its ready posture HOME_RAD: each arm as capsules between
its joint origins (LWR link radii), the tools as capsules, the dish as a sphere. Used by the sim
to keep random fruit out of the robot (a fruit inside an arm at tick 0 is a contact from the
start and leaves the controller's fruit dampers nothing feasible)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from services.robot.model import HOME_RAD, LWR_LINK_RADIUS_M, TOOLS, URDF_PATH, joint_names

Capsule = tuple[np.ndarray, np.ndarray, float]  # (a, b, radius), world frame, m


@lru_cache(maxsize=1)
def home_capsules() -> tuple[Capsule, ...]:
    """The arms and tools at HOME_RAD (forward kinematics of the URDF with placo)."""
    import placo

    robot = placo.RobotWrapper(str(URDF_PATH))
    for role, q in HOME_RAD.items():
        for name, v in zip(joint_names(role), q, strict=True):
            robot.set_joint(name, v)
    robot.update_kinematics()

    def origin(frame: str) -> np.ndarray:
        return np.array(robot.get_T_world_frame(frame))[:3, 3]

    out: list[Capsule] = []
    for role in ("cutter", "collector"):
        frames = [f"{role}_base"] + [f"{role}_link{i}" for i in range(1, 8)]
        tool = [f"{role}_tool", "cutter_tip" if role == "cutter" else "basket_center"]
        pts = [origin(f) for f in frames + tool]
        radii = [*LWR_LINK_RADIUS_M, LWR_LINK_RADIUS_M[-1], TOOLS.cutter_shaft_radius_m]
        for a, b, r in zip(pts[:-1], pts[1:], radii, strict=True):
            out.append((a, b, r))
    c = origin("basket_center")
    out.append((c, c, TOOLS.basket_radius_m + 0.005))
    return tuple(out)


def distance_to_home_robot_m(p_world_m: np.ndarray) -> float:
    """Distance from a point to the robot's surface at HOME_RAD, m (negative: inside)."""
    p = np.asarray(p_world_m, float)
    best = float("inf")
    for a, b, r in home_capsules():
        ab = b - a
        t = float(np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0))
        best = min(best, float(np.linalg.norm(p - (a + t * ab))) - r)
    return best
