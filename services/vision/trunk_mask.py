"""The trunk mask of the paper (§III-C): pixels whose colour is in an HSV box and whose depth is
valid and near enough. Shared by the scene service (trunk position) and the viewer (overlay)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from schemas.camera import RgbdFrame


@dataclass(frozen=True)
class HsvBox:
    """Inclusive HSV bounds in OpenCV ranges: H in [0, 180), S and V in [0, 255]."""

    low: tuple[int, int, int]
    high: tuple[int, int, int]

    def __post_init__(self) -> None:
        for name, v in (("low", self.low), ("high", self.high)):
            if len(v) != 3 or not (0 <= v[0] <= 180 and 0 <= v[1] <= 255 and 0 <= v[2] <= 255):
                raise ValueError(f"HsvBox.{name} {v} is outside OpenCV's H 0-180, S/V 0-255")
        if any(lo > hi for lo, hi in zip(self.low, self.high, strict=True)):
            raise ValueError(f"HsvBox low {self.low} exceeds high {self.high}")

    def mask(self, hsv_img: np.ndarray) -> np.ndarray:
        """Boolean (H, W): the pixels of an OpenCV HSV image (H, W, 3) uint8 inside the box."""
        import cv2

        lo, hi = np.array(self.low, np.uint8), np.array(self.high, np.uint8)
        return np.asarray(cv2.inRange(hsv_img, lo, hi) > 0)


PAPER_TRUNK_HSV = HsvBox(low=(10, 70, 80), high=(20, 130, 140))
"""The paper's trunk colour thresholds: H 10-20, S 70-130, V 80-140 (OpenCV ranges)."""


def hsv_depth_mask(
    rgb: np.ndarray,
    depth: np.ndarray,
    depth_unit_m: float,
    max_depth_m: float,
    hsv: HsvBox = PAPER_TRUNK_HSV,
) -> np.ndarray:
    """Boolean (H, W) mask: colour inside ``hsv`` and 0 < depth ≤ ``max_depth_m``.

    Args:
        rgb: (H, W, 3) uint8 image in RGB order.
        depth: (H, W) integer depth in ``depth_unit_m`` per count; 0 means no depth.
        depth_unit_m: metres per depth count (> 0).
        max_depth_m: farthest depth kept, m (> 0).
        hsv: colour bounds.
    """
    import cv2

    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"rgb must be (H, W, 3) uint8, got {rgb.dtype} {rgb.shape}")
    if depth.shape != rgb.shape[:2]:
        raise ValueError(f"depth shape {depth.shape} does not match rgb {rgb.shape[:2]}")
    if not np.issubdtype(depth.dtype, np.integer):
        raise ValueError(f"depth must hold integer counts, got {depth.dtype}")
    if depth_unit_m <= 0 or max_depth_m <= 0:
        raise ValueError(f"depth_unit_m and max_depth_m must be > 0: {depth_unit_m}, {max_depth_m}")
    hsv_img = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    colour = hsv.mask(hsv_img)
    max_count = int(np.floor(max_depth_m / depth_unit_m + 1e-9))
    near = (depth > 0) & (depth <= max_count)
    mask: np.ndarray = colour & near
    return mask


def trunk_mask(frame: RgbdFrame, max_depth_m: float, hsv: HsvBox = PAPER_TRUNK_HSV) -> np.ndarray:
    """The trunk mask of one RGB-D frame (see ``hsv_depth_mask``)."""
    return hsv_depth_mask(frame.rgb, frame.depth, frame.meta.depth_unit_m, max_depth_m, hsv)
