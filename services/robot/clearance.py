"""How far a point is from the robot in its ready posture HOME_RAD: each arm as capsules between
its joint origins (LWR link radii), the tools as capsules, the dish as a sphere. Used by the sim
to keep random fruit out of the robot (a fruit inside an arm at tick 0 is a contact from the
start and leaves the controller's fruit dampers nothing feasible). ``RobotBody`` gives the same
capsules at any joint state (the scene's robot self-filter)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import lru_cache

import numpy as np

from schemas.base import ArmRole
from services.robot.model import HOME_RAD, LWR_LINK_RADIUS_M, TOOLS, URDF_PATH, joint_names

Capsule = tuple[np.ndarray, np.ndarray, float]  # (a, b, radius), world frame, m


class RobotBody:
    """The arms and tools as capsules at any joint state (forward kinematics of the URDF with
    placo): each arm between its joint origins (LWR link radii), the tool shaft, the dish as a
    sphere. One placo model per instance; ``capsules`` costs ~0.1 ms."""

    def __init__(self) -> None:
        import placo

        self.robot = placo.RobotWrapper(str(URDF_PATH))

    def capsules(self, q_rad: Mapping[ArmRole, Sequence[float]]) -> tuple[Capsule, ...]:
        """Capsules at the joint positions ``q_rad`` (arm role → 7 positions, rad)."""
        for role, q in q_rad.items():
            for name, v in zip(joint_names(role), q, strict=True):
                self.robot.set_joint(name, float(v))
        self.robot.update_kinematics()

        def origin(frame: str) -> np.ndarray:
            return np.array(self.robot.get_T_world_frame(frame))[:3, 3]

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


@lru_cache(maxsize=1)
def home_capsules() -> tuple[Capsule, ...]:
    """The arms and tools at HOME_RAD."""
    return RobotBody().capsules(HOME_RAD)


def axis_distances_m(p_world_m: np.ndarray, capsules: Sequence[Capsule]) -> np.ndarray:
    """Distance from a point to each capsule's axis segment, m (compare with its radius)."""
    p = np.asarray(p_world_m, float)
    out = np.empty(len(capsules))
    for i, (a, b, _r) in enumerate(capsules):
        ab = b - a
        t = float(np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0))
        out[i] = float(np.linalg.norm(p - (a + t * ab)))
    return out


def within_reach(
    points_world_m: np.ndarray, capsules: Sequence[Capsule], reach_m: np.ndarray
) -> np.ndarray:
    """(N,) whether each point lies within ``reach_m`` (one per capsule) of some capsule's
    axis: ``np.any(axis_distances_m(p, capsules) < reach_m)`` for every point at once. The
    batch's distances may differ from the one-point sums in the last bits, so a point within
    1e-9 m of a threshold is decided by ``axis_distances_m`` itself: the same verdicts."""
    pts = np.asarray(points_world_m, float).reshape(-1, 3)
    if not capsules or not len(pts):
        return np.zeros(len(pts), bool)
    a = np.array([c[0] for c in capsules], float)  # (M, 3)
    ab = np.array([c[1] for c in capsules], float) - a
    denom = np.maximum(np.einsum("mk,mk->m", ab, ab), 1e-12)
    rel = pts[:, None, :] - a[None, :, :]  # (N, M, 3)
    t = np.clip(np.einsum("nmk,mk->nm", rel, ab) / denom, 0.0, 1.0)
    d = np.linalg.norm(rel - t[:, :, None] * ab[None, :, :], axis=2)
    reach = np.asarray(reach_m, float)
    out = np.asarray((d < reach).any(axis=1), dtype=bool)
    for i in np.flatnonzero((np.abs(d - reach) <= 1e-9).any(axis=1)):
        out[i] = bool(np.any(axis_distances_m(pts[i], capsules) < reach))
    return out


def distance_to_home_robot_m(p_world_m: np.ndarray) -> float:
    """Distance from a point to the robot's surface at HOME_RAD, m (negative: inside)."""
    caps = home_capsules()
    radii = np.array([r for _a, _b, r in caps])
    return float((axis_distances_m(p_world_m, caps) - radii).min())


def voxel_key(p_world_m: np.ndarray, voxel_m: float) -> tuple[int, int, int] | None:
    """The world-frame voxel of edge ``voxel_m`` that holds a point (a felt contact: the scene's
    felt places, the controller's reflex); None for a point not finite or too far out to bin."""
    scaled = np.asarray(p_world_m, float) / voxel_m
    if not np.all(np.isfinite(scaled)) or np.any(np.abs(scaled) > 1e9):
        return None
    i, j, k = (int(v) for v in np.floor(scaled))
    return i, j, k


def inner_working_space(
    centre_world_m: np.ndarray, semi_axis_v_m: float, clearance_m: float, twig_m: float
) -> Capsule:
    """A fruit's inner working space, where the tools touch it on purpose: a capsule from its
    centre up its twig to ``semi_axis_v_m + twig_m`` above it, radius ``semi_axis_v_m +
    clearance_m`` (the scene's keep-out and felt places, the controller's reflex)."""
    centre = np.asarray(centre_world_m, float)
    top = centre + np.array([0.0, 0.0, semi_axis_v_m + twig_m])
    return centre, top, semi_axis_v_m + clearance_m
