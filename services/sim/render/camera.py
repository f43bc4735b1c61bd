"""The D435-like head camera: intrinsics of the 640×480 colour stream, its pose, projection.

Intrinsics: one D435's factory calibration of the colour stream at 640×480 as printed by
``rs-enumerate-devices -c`` (librealsense issue #4050): fx 612.405, fy 610.649, ppx 314.251,
ppy 237.778, Brown-Conrady coefficients all zero (so no distortion is modelled). Other units
print fx ≈ 606–617 and a principal point within ~6 px of the image centre.

Pixel convention (OpenCV and librealsense): integer pixel coordinates are pixel *centres*;
pixel (u, v) covers [u-0.5, u+0.5] × [v-0.5, v+0.5]; u to the right, v down. A camera-frame
point (x, y, z) (optical frame: z forward, x right, y down) projects to
u = fx·x/z + cx, v = fy·y/z + cy. Depth is the z coordinate (not the ray length), as the D435
reports it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from schemas.camera import CameraIntrinsics

D435_COLOR_640x480 = CameraIntrinsics(
    width_px=640, height_px=480, fx_px=612.41, fy_px=610.65, cx_px=314.25, cy_px=237.78
)
D435_DEPTH_FOCAL_PX = 384.2  # depth (IR) stream at 640×480, realsense-ros issue #2788
D435_BASELINE_M = 0.050  # stereo baseline of the D435 (datasheet)
CAMERA_RATE_HZ = 15.0


@dataclass(frozen=True)
class CameraModel:
    """Pinhole camera: intrinsics and the per-pixel ray directions (x/z, y/z) of pixel centres."""

    intrinsics: CameraIntrinsics = D435_COLOR_640x480
    near_m: float = 0.05

    @property
    def width(self) -> int:
        return self.intrinsics.width_px

    @property
    def height(self) -> int:
        return self.intrinsics.height_px

    @cached_property
    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """(X, Y): float32 (H, W) arrays with X = (u - cx)/fx, Y = (v - cy)/fy, so the ray of a
        pixel is (X, Y, 1) and a hit at parameter t has depth z = t."""
        k = self.intrinsics
        x = ((np.arange(k.width_px) - k.cx_px) / k.fx_px).astype(np.float32)
        y = ((np.arange(k.height_px) - k.cy_px) / k.fy_px).astype(np.float32)
        X = np.ascontiguousarray(np.broadcast_to(x[None, :], (k.height_px, k.width_px)))
        Y = np.ascontiguousarray(np.broadcast_to(y[:, None], (k.height_px, k.width_px)))
        return X, Y

    def project(self, p_cam: np.ndarray) -> np.ndarray:
        """Camera-frame points (..., 3) → pixel coordinates (..., 2) (u right, v down)."""
        k = self.intrinsics
        p = np.asarray(p_cam, dtype=float)
        return np.stack(
            [k.fx_px * p[..., 0] / p[..., 2] + k.cx_px, k.fy_px * p[..., 1] / p[..., 2] + k.cy_px],
            axis=-1,
        )

    def deproject(self, u: float, v: float, depth_m: float) -> np.ndarray:
        """Pixel (u, v) at depth z → camera-frame point."""
        k = self.intrinsics
        return np.array(
            [(u - k.cx_px) / k.fx_px * depth_m, (v - k.cy_px) / k.fy_px * depth_m, depth_m]
        )


def head_camera_pose() -> np.ndarray:
    """T_world_camera (4×4) of the URDF's ``camera_optical`` frame, from the robot model (the
    head is rigid on a fixed torso, so the pose is constant; a test checks it against pybullet)."""
    from services.robot.model import MOUNT
    from services.robot.urdf import camera_optical_rotation

    T = np.eye(4)
    T[:3, :3] = camera_optical_rotation(MOUNT)
    T[:3, 3] = MOUNT.camera_xyz_m
    return T
