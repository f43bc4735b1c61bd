"""Pure core of the file camera: frames from a PNG folder or an MCAP recording, in order.

Folder layout (what `harvest dataset synth` writes, too)::

    intrinsics.json   {"width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px",
                       optional "depth_unit_m" (default 0.001), "frame_id", "T_world_camera"}
    color/000000.png  RGB (8-bit, 3 channels)
    depth/000000.png  depth, 16-bit single channel, depth_unit_m per count, 0 = invalid

Colour and depth files are paired in sorted order and must be as many. Folder frames are
stamped i / rate_hz (no wall clock); MCAP frames keep their recorded stamps. A frame that cannot
be read or has the wrong size is skipped with a log line naming the file and the problem, and
counted (``skipped``).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ConfigDict, Field, ValidationError

from schemas.base import Pose
from schemas.camera import CameraIntrinsics, RgbdFrame, RgbdFrameMeta
from schemas.codec import DecodeError
from schemas.topics import TOPICS
from services.camera_file import Settings
from services.runtime import ConfigError, Output, Stamper

log = logging.getLogger("camera_file")


class IntrinsicsFile(CameraIntrinsics):
    """intrinsics.json of a frame folder."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    depth_unit_m: float = Field(default=0.001, gt=0, description="Metres per depth count.")
    frame_id: str = Field(default="camera_optical", min_length=1, description="Optical frame.")
    T_world_camera: Pose = Field(default_factory=lambda: Pose(position_m=(0, 0, 0)))


@dataclass
class _Frame:
    stamp_ns: int
    rgb: np.ndarray
    depth: np.ndarray
    meta: RgbdFrameMeta | None = None


class CameraFileCore:
    def __init__(self, s: Settings) -> None:
        self.s = s
        self.stamper = Stamper("camera_file")
        self.skipped = 0
        path = Path(s.path)
        if not path.exists():
            raise ConfigError(f"path {path}: no such file or folder")
        self._frames: Iterator[_Frame] = self._mcap(path) if path.is_file() else self._folder(path)
        self._next: _Frame | None = next(self._frames, None)
        if self._next is None:
            raise ConfigError(f"path {path}: no readable frame")

    # ---- SourceCore ------------------------------------------------------------------------
    def done(self) -> bool:
        return self._next is None

    def now_ns(self) -> int:
        return self._next.stamp_ns if self._next is not None else 0

    def emit(self) -> list[list[Output]]:
        f = self._next
        assert f is not None
        h = self.stamper.header("camera/rgbd", f.stamp_ns, self._frame_id(f))
        if f.meta is not None:
            meta = f.meta.model_copy(update={"header": h})
        else:
            meta = RgbdFrameMeta(
                header=h,
                intrinsics=self.intr,
                depth_unit_m=self.intr_file.depth_unit_m,
                T_world_camera=self.intr_file.T_world_camera,
            )
        return [[("camera/rgbd", RgbdFrame(meta, f.rgb, f.depth))]]

    def handle(self, topic: str, msg: Any) -> list[Output]:
        return []

    def advance(self) -> None:
        self._next = next(self._frames, None)

    def _frame_id(self, f: _Frame) -> str:
        return f.meta.header.frame_id if f.meta is not None else self.intr_file.frame_id

    # ---- folder ----------------------------------------------------------------------------
    def _folder(self, root: Path) -> Iterator[_Frame]:
        import cv2

        ipath = root / self.s.intrinsics_file
        try:
            self.intr_file = IntrinsicsFile.model_validate(json.loads(ipath.read_text()))
        except FileNotFoundError:
            raise ConfigError(f"{ipath}: intrinsics file not found") from None
        except (ValidationError, json.JSONDecodeError) as exc:
            raise ConfigError(f"{ipath}: invalid intrinsics: {exc}") from None
        k = self.intr_file
        self.intr = CameraIntrinsics(
            width_px=k.width_px,
            height_px=k.height_px,
            fx_px=k.fx_px,
            fy_px=k.fy_px,
            cx_px=k.cx_px,
            cy_px=k.cy_px,
        )
        colour = sorted(root.glob(self.s.color_glob))
        depth = sorted(root.glob(self.s.depth_glob))
        if not colour or len(colour) != len(depth):
            raise ConfigError(
                f"{root}: {len(colour)} colour images ({self.s.color_glob}) and {len(depth)} "
                f"depth images ({self.s.depth_glob}); need the same number, at least one"
            )
        period_ns = round(1e9 / self.s.rate_hz)
        i = 0
        for _ in range(self.s.repeat):
            for c, d in zip(colour, depth, strict=True):
                rgb = cv2.imread(str(c), cv2.IMREAD_COLOR)
                dep = cv2.imread(str(d), cv2.IMREAD_UNCHANGED)
                problem = _check(rgb, dep, k.width_px, k.height_px)
                if problem or rgb is None:
                    self.skipped += 1
                    log.warning("skipped %s / %s: %s", c.name, d.name, problem)
                    continue
                rgb = np.ascontiguousarray(rgb[:, :, ::-1])
                yield _Frame(i * period_ns, rgb, np.ascontiguousarray(dep))
                i += 1

    # ---- recording -------------------------------------------------------------------------
    def _mcap(self, path: Path) -> Iterator[_Frame]:
        from services.recorder.inspect import RecordingError, check_file, iter_messages

        try:
            check_file(path)
        except RecordingError as exc:
            raise ConfigError(str(exc)) from None
        codec = TOPICS["camera/rgbd"].codec
        for _ in range(self.s.repeat):
            last: tuple[int, int] | None = None
            offset = 0
            end = 0
            for m in iter_messages(path):
                if m.topic != self.s.topic:
                    continue
                try:
                    fr = codec.decode(m.payload)
                except DecodeError as exc:
                    self.skipped += 1
                    log.warning("skipped a %s message: %s", m.topic, exc.reason)
                    continue
                key = (fr.header.seq, fr.header.stamp_ns)
                if key == last:  # a re-sent frame in the recording
                    continue
                last = key
                end = fr.header.stamp_ns + offset
                yield _Frame(end, fr.rgb.copy(), fr.depth.copy(), fr.meta)
            offset = end + round(1e9 / self.s.rate_hz)


def _check(rgb: Any, depth: Any, w: int, h: int) -> str:
    if rgb is None:
        return "colour image unreadable"
    if depth is None:
        return "depth image unreadable"
    if rgb.shape != (h, w, 3):
        return f"colour is {rgb.shape}, intrinsics say {(h, w, 3)}"
    if depth.dtype != np.uint16 or depth.shape != (h, w):
        return f"depth is {depth.dtype} {depth.shape}, need uint16 {(h, w)}"
    return ""
