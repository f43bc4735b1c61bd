"""Helpers of the scene tests: exact synthetic RGB-D images of ellipsoids, planes and vertical
cylinders (ray-cast per pixel centre, depth = z), and frames and tracks built from them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from schemas.base import Header, Pose
from schemas.camera import RgbdFrame, RgbdFrameMeta
from schemas.perception import Track, Tracks
from services.scene.geometry import Pinhole
from services.sim.render.camera import D435_COLOR_640x480

K = Pinhole.of(D435_COLOR_640x480)
ORANGE = (235, 120, 15)
BARK = (110, 85, 62)  # HSV (14, 111, 110): inside the paper's trunk box
LEAF = (40, 110, 40)
# Optical frame (z forward, x right, y down) → world (x forward, y left, z up), camera 1.4 m up.
R_WORLD_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
T_WORLD_CAM_M = np.array([0.0, 0.0, 1.4])
LEVEL_POSE = Pose(position_m=(0.0, 0.0, 1.4), orientation_xyzw=(-0.5, 0.5, -0.5, 0.5))


@dataclass
class Scene:
    """Pixels drawn so far: nearest depth wins (0 = nothing), colour and an object label."""

    depth: np.ndarray = field(default_factory=lambda: np.zeros((K.height, K.width)))
    rgb: np.ndarray = field(default_factory=lambda: np.full((K.height, K.width, 3), 200, np.uint8))
    label: np.ndarray = field(default_factory=lambda: np.full((K.height, K.width), -1))

    def _rays(self) -> tuple[np.ndarray, np.ndarray]:
        v, u = np.mgrid[0 : K.height, 0 : K.width]
        return (u - K.cx) / K.fx, (v - K.cy) / K.fy

    def _put(self, t: np.ndarray, colour: tuple[int, int, int], label: int) -> None:
        hit = np.isfinite(t) & (t > 0) & ((self.depth == 0) | (t < self.depth))
        self.depth[hit] = t[hit]
        self.rgb[hit] = colour
        self.label[hit] = label

    def ellipsoid(self, centre_cam_m, a: float, c: float, colour=ORANGE, label: int = 1) -> None:
        """Semi-axes a along camera x and z, c along camera y."""
        xn, yn = self._rays()
        cx, cy, cz = centre_cam_m
        A = (xn**2 + 1) / a**2 + yn**2 / c**2
        B = (xn * cx + cz) / a**2 + yn * cy / c**2
        D = (cx**2 + cz**2) / a**2 + cy**2 / c**2 - 1
        disc = B * B - A * D
        with np.errstate(invalid="ignore"):
            t = np.where(disc > 0, (B - np.sqrt(disc)) / A, np.nan)
        self._put(t, colour, label)

    def plane_rect(self, z_m: float, u0: int, u1: int, v0: int, v1: int, colour=LEAF) -> None:
        """A fronto-parallel occluder covering pixels u0:u1, v0:v1 at depth z."""
        t = np.full(self.depth.shape, np.nan)
        t[v0:v1, u0:u1] = z_m
        self._put(t, colour, 99)

    def vertical_cylinder(self, axis_world_xy, radius_m: float, colour=BARK) -> None:
        """An infinite vertical cylinder (world z) seen by the level camera."""
        xn, yn = self._rays()
        d = np.stack([xn, yn, np.ones_like(xn)], -1) @ R_WORLD_CAM.T  # ray directions, world
        ox, oy = T_WORLD_CAM_M[0] - axis_world_xy[0], T_WORLD_CAM_M[1] - axis_world_xy[1]
        a = d[..., 0] ** 2 + d[..., 1] ** 2
        b = 2 * (ox * d[..., 0] + oy * d[..., 1])
        cc = ox * ox + oy * oy - radius_m**2
        disc = b * b - 4 * a * cc
        with np.errstate(invalid="ignore"):
            t = np.where(disc > 0, (-b - np.sqrt(disc)) / (2 * a), np.nan)
        self._put(t, colour, 7)

    def box(self, label: int = 1) -> tuple[float, float, float, float]:
        """Box of the visible pixels of ``label`` (pixel edges at half-integers)."""
        v, u = np.nonzero(self.label == label)
        return (u.min() - 0.5, v.min() - 0.5, u.max() + 0.5, v.max() + 0.5)

    def depth_mm(self, noise_mm: float = 0.0, seed: int = 0) -> np.ndarray:
        z = self.depth * 1000
        if noise_mm:
            z = z + np.random.default_rng(seed).normal(0, noise_mm, z.shape)
        out = np.clip(np.round(z), 0, 65535).astype(np.uint16)
        out[self.depth == 0] = 0
        return out

    def frame(self, seq: int, stamp_ns: int, pose: Pose = LEVEL_POSE, noise_mm: float = 0.0):
        meta = RgbdFrameMeta(
            header=Header(stamp_ns=stamp_ns, seq=seq, frame_id="camera_optical", source="test"),
            intrinsics=D435_COLOR_640x480,
            T_world_camera=pose,
        )
        return RgbdFrame(meta, np.ascontiguousarray(self.rgb), self.depth_mm(noise_mm, seq))


def tracks(
    seq: int, stamp_ns: int, frame_seq: int, boxes: dict[int, tuple], **kw: object
) -> Tracks:
    """A Tracks message with confirmed, matched tracks (``kw`` overrides Track fields)."""
    ts = tuple(
        Track.model_validate(
            {
                "track_id": tid,
                "xyxy_px": box,
                "score": 0.9,
                "confirmed": True,
                "age_frames": 5,
                "frames_since_update": 0,
                "matched": True,
                **kw,
            }
        )
        for tid, box in sorted(boxes.items())
    )
    h = Header(stamp_ns=stamp_ns, seq=seq, frame_id="camera_optical", source="tracker")
    return Tracks(header=h, frame_seq=frame_seq, tracks=ts)
