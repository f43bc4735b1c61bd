"""RealSense core: pyrealsense2 pipeline, depth aligned to colour, stamped with sensor time.

Not pure like the sim (it reads a device), but it follows the same SourceCore protocol: stamps
are the device's frame timestamps (sensor time, never the receive time), so recordings replay
like any other source. The pose of the camera is the head's ``camera_optical`` frame.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from schemas.base import Pose
from schemas.camera import CameraIntrinsics, RgbdFrame, RgbdFrameMeta
from services.realsense import Settings
from services.runtime import ConfigError, Output, Stamper

log = logging.getLogger("realsense")


def import_pyrealsense2() -> Any:
    """The pyrealsense2 module, or ConfigError saying the package is missing."""
    try:
        import pyrealsense2 as rs
    except ImportError:
        raise ConfigError(
            "the pyrealsense2 package is missing: install the optional extra with "
            "`pip install .[realsense]`"
        ) from None
    return rs


class RealsenseCore:
    def __init__(self, s: Settings) -> None:
        rs = import_pyrealsense2()
        self.s, self.rs = s, rs
        devices = [d.get_info(rs.camera_info.serial_number) for d in rs.context().query_devices()]
        if not devices:
            raise ConfigError("no RealSense device found (is it plugged in, with USB 3?)")
        if s.serial and s.serial not in devices:
            raise ConfigError(f"no RealSense device with serial {s.serial} (found {devices})")
        cfg = rs.config()
        if s.serial:
            cfg.enable_device(s.serial)
        cfg.enable_stream(rs.stream.color, s.width_px, s.height_px, rs.format.rgb8, s.fps)
        cfg.enable_stream(rs.stream.depth, s.width_px, s.height_px, rs.format.z16, s.fps)
        self.pipe = rs.pipeline()
        profile = self.pipe.start(cfg)
        self.align = rs.align(rs.stream.color)
        self.depth_unit_m = profile.get_device().first_depth_sensor().get_depth_scale()
        k = profile.get_stream(rs.stream.color).as_video_stream_profile().get_intrinsics()
        self.intr = CameraIntrinsics(
            width_px=k.width, height_px=k.height, fx_px=k.fx, fy_px=k.fy, cx_px=k.ppx, cy_px=k.ppy
        )
        from services.sim.physics import quat_of
        from services.sim.render.camera import head_camera_pose

        T = head_camera_pose()
        self.pose = Pose(
            position_m=(float(T[0, 3]), float(T[1, 3]), float(T[2, 3])),
            orientation_xyzw=tuple(float(v) for v in quat_of(T[:3, :3])),  # type: ignore[arg-type]
        )
        self.stamper = Stamper("realsense")
        self.count = 0
        self.t0_ms: float | None = None
        self._grab()

    def _grab(self) -> None:
        frames = self.align.process(self.pipe.wait_for_frames(self.s.timeout_ms))
        c, d = frames.get_color_frame(), frames.get_depth_frame()
        if self.t0_ms is None:
            self.t0_ms = c.get_timestamp()
        self.stamp_ns = round((c.get_timestamp() - self.t0_ms) * 1e6)
        self.rgb = np.asanyarray(c.get_data()).copy()
        self.depth = np.asanyarray(d.get_data()).copy()

    def done(self) -> bool:
        return self.s.frames is not None and self.count >= self.s.frames

    def now_ns(self) -> int:
        return self.stamp_ns

    def emit(self) -> list[list[Output]]:
        meta = RgbdFrameMeta(
            header=self.stamper.header("camera/rgbd", self.stamp_ns, "camera_optical"),
            intrinsics=self.intr,
            depth_unit_m=self.depth_unit_m,
            T_world_camera=self.pose,
        )
        return [[("camera/rgbd", RgbdFrame(meta, self.rgb, self.depth))]]

    def handle(self, topic: str, msg: Any) -> list[Output]:
        return []

    def advance(self) -> None:
        self.count += 1
        if not self.done():
            self._grab()
