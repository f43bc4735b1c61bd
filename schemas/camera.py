"""RGB-D camera frame: a JSON-described header plus raw RGB and depth pixels as one binary payload.

Wire layout of ``camera/rgbd`` (encoding ``application/x-harvest-rgbd``)::

    b"RGBD" | u32 little-endian n | n bytes of RgbdFrameMeta JSON | rgb | depth

``rgb`` is height×width×3 u8 (row-major, RGB order); ``depth`` is height×width u16 little-endian,
in units of ``depth_unit_m`` (1 mm), 0 where the sensor has no valid depth. Nothing is compressed:
replay must be bit-exact.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from schemas.base import Frozen, Message, Pose, PosFloat

RGBD_MAGIC = b"RGBD"
RGBD_ENCODING = "application/x-harvest-rgbd"
_LEN = struct.Struct("<I")


class CameraIntrinsics(Frozen):
    """Pinhole intrinsics of the colour image (depth is aligned to it), no distortion applied."""

    width_px: int = Field(gt=0, le=8192, description="Image width, pixels.")
    height_px: int = Field(gt=0, le=8192, description="Image height, pixels.")
    fx_px: PosFloat = Field(description="Focal length along x, pixels.")
    fy_px: PosFloat = Field(description="Focal length along y, pixels.")
    cx_px: float = Field(allow_inf_nan=False, description="Principal point x, px.")
    cy_px: float = Field(allow_inf_nan=False, description="Principal point y, pixels.")


class RgbdFrameMeta(Message):
    """Header of an RGB-D frame; the pixels follow it in the same payload (see module doc)."""

    intrinsics: CameraIntrinsics = Field(description="Intrinsics of colour and aligned depth.")
    color_encoding: Literal["rgb8"] = Field(default="rgb8", description="Pixel format of colour.")
    depth_encoding: Literal["16UC1"] = Field(default="16UC1", description="Pixel format of depth.")
    depth_unit_m: PosFloat = Field(default=0.001, description="Metres per depth count.")
    T_world_camera: Pose = Field(
        description="Pose of the camera optical frame (z forward, x right, y down) in 'world'."
    )

    @model_validator(mode="after")
    def _frame_is_camera(self) -> RgbdFrameMeta:
        if not self.header.frame_id:
            raise ValueError("header.frame_id must name the camera optical frame")
        return self


@dataclass(frozen=True)
class RgbdFrame:
    """A decoded RGB-D frame: validated metadata plus pixel arrays (read-only views)."""

    meta: RgbdFrameMeta
    rgb: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) uint16, depth_unit_m per count

    @property
    def header(self):
        return self.meta.header

    def depth_m(self) -> np.ndarray:
        """Depth in metres as float32 (0 where invalid)."""
        return self.depth.astype(np.float32) * np.float32(self.meta.depth_unit_m)


class FrameError(ValueError):
    """An RGB-D payload that cannot be decoded; the message names the problem."""


def encode_rgbd(frame: RgbdFrame) -> bytes:
    """Serialise a frame to the wire layout; checks shapes and dtypes against the intrinsics."""
    _check_arrays(frame.meta, frame.rgb, frame.depth)
    meta = frame.meta.model_dump_json().encode()
    depth = frame.depth.astype("<u2", copy=False)
    return b"".join((RGBD_MAGIC, _LEN.pack(len(meta)), meta, frame.rgb.data, depth.data))


def decode_rgbd_meta(payload: bytes | memoryview) -> tuple[RgbdFrameMeta, int]:
    """Decode only the JSON header; returns it and the offset of the first pixel byte."""
    view = memoryview(payload)
    if len(view) < 8 or bytes(view[:4]) != RGBD_MAGIC:
        raise FrameError("not an RGB-D frame: missing the b'RGBD' magic")
    (n,) = _LEN.unpack(view[4:8])
    if 8 + n > len(view):
        raise FrameError(f"truncated RGB-D header: {n} bytes announced, {len(view) - 8} present")
    try:
        meta = RgbdFrameMeta.model_validate_json(bytes(view[8 : 8 + n]))
    except ValueError as exc:
        raise FrameError(f"invalid RGB-D header: {exc}") from exc
    return meta, 8 + n


def decode_rgbd(payload: bytes | memoryview) -> RgbdFrame:
    """Decode a full frame; pixel arrays are zero-copy read-only views of ``payload``."""
    meta, off = decode_rgbd_meta(payload)
    w, h = meta.intrinsics.width_px, meta.intrinsics.height_px
    n_rgb, n_depth = w * h * 3, w * h * 2
    if len(payload) != off + n_rgb + n_depth:
        raise FrameError(
            f"RGB-D payload size {len(payload)} != header {off} + rgb {n_rgb} + depth {n_depth} "
            f"for {w}x{h}"
        )
    buf = np.frombuffer(payload, dtype=np.uint8, count=n_rgb + n_depth, offset=off)
    rgb = buf[:n_rgb].reshape(h, w, 3)
    depth = buf[n_rgb:].view("<u2").reshape(h, w)
    return RgbdFrame(meta=meta, rgb=rgb, depth=depth)


def _check_arrays(meta: RgbdFrameMeta, rgb: np.ndarray, depth: np.ndarray) -> None:
    w, h = meta.intrinsics.width_px, meta.intrinsics.height_px
    if rgb.shape != (h, w, 3) or rgb.dtype != np.uint8:
        raise FrameError(f"rgb must be uint8 {(h, w, 3)}, got {rgb.dtype} {rgb.shape}")
    if depth.shape != (h, w) or depth.dtype != np.uint16:
        raise FrameError(f"depth must be uint16 {(h, w)}, got {depth.dtype} {depth.shape}")
    if not (rgb.flags.c_contiguous and depth.flags.c_contiguous):
        raise FrameError("rgb and depth must be C-contiguous")
