"""Camera geometry of the scene estimator: the pinhole model of a frame and its pose in 'world'.

Pixel convention (OpenCV, librealsense, the sim): integer pixel coordinates are pixel centres,
u to the right, v down; a camera-frame point (x, y, z) (optical frame: z forward, x right,
y down) projects to u = fx·x/z + cx, v = fy·y/z + cy; depth is z, not the ray length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from schemas.base import Pose
from schemas.camera import CameraIntrinsics


class PoseError(ValueError):
    """A camera pose that is not a rigid transform (e.g. a zero quaternion)."""


@dataclass(frozen=True)
class Pinhole:
    """Intrinsics of one frame, as plain floats (px)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @classmethod
    def of(cls, k: CameraIntrinsics) -> Pinhole:
        return cls(k.fx_px, k.fy_px, k.cx_px, k.cy_px, k.width_px, k.height_px)

    def deproject(self, u: float, v: float, z_m: float) -> np.ndarray:
        """Pixel (u, v) at depth z (m) → camera-frame point (m)."""
        return np.array([(u - self.cx) / self.fx * z_m, (v - self.cy) / self.fy * z_m, z_m])

    def project(self, p_cam_m: np.ndarray) -> tuple[float, float]:
        """Camera-frame point (m, z > 0) → pixel (u, v)."""
        x, y, z = (float(c) for c in p_cam_m)
        return self.fx * x / z + self.cx, self.fy * y / z + self.cy


@dataclass(frozen=True)
class RigidTransform:
    """T_world_camera as a rotation matrix and a translation (m)."""

    R: np.ndarray  # (3, 3) camera → world rotation
    t_m: np.ndarray  # (3,) camera origin in world, m

    @classmethod
    def of(cls, pose: Pose) -> RigidTransform:
        """From a Pose; the quaternion is normalised, a (near) zero one raises PoseError."""
        x, y, z, w = pose.orientation_xyzw
        n = math.sqrt(x * x + y * y + z * z + w * w)
        if not n > 1e-6:  # also catches NaN
            raise PoseError(f"T_world_camera has a degenerate quaternion {pose.orientation_xyzw}")
        x, y, z, w = x / n, y / n, z / n, w / n
        R = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        return cls(R, np.asarray(pose.position_m, float))

    def to_world(self, p_cam_m: np.ndarray) -> np.ndarray:
        """Camera-frame point(s) (..., 3) → world frame (..., 3)."""
        return np.asarray(p_cam_m) @ self.R.T + self.t_m

    def to_camera(self, p_world_m: np.ndarray) -> np.ndarray:
        """World-frame point(s) (..., 3) → camera frame (..., 3)."""
        return (np.asarray(p_world_m) - self.t_m) @ self.R


def vec3(p: np.ndarray) -> tuple[float, float, float]:
    """A numpy 3-vector as the schemas' Vec3 (plain floats)."""
    return (float(p[0]), float(p[1]), float(p[2]))
