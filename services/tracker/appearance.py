"""Appearance: a colour/texture descriptor of a box's pixels, and Deep SORT's cosine gallery.

We have no pretrained re-ID network (no downloads here) and oranges look alike, so the
descriptor is deliberately simple and robust: the centre of the box (where the fruit is, not
the leaves around it) resized to 16x16, described by a hue-saturation histogram (12x4 bins)
and a value histogram per quadrant (4 quadrants x 4 bins) for shading/texture layout. Each
part is normalised, square-rooted (Hellinger), and the vector is L2-normalised, so the cosine
distance is 1 - dot product.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import cv2
import numpy as np

DESCRIPTOR_DIM = 12 * 4 + 4 * 4
INNER = 0.15  # share of the box trimmed on each side before describing it
PATCH_PX = 16


def describe(rgb: np.ndarray, box_xyxy_px: np.ndarray) -> np.ndarray | None:
    """Descriptor of the box's inner region; None when it is empty in the image."""
    h, w = rgb.shape[:2]
    x1, y1, x2, y2 = (float(v) for v in box_xyxy_px)
    dx, dy = (x2 - x1) * INNER, (y2 - y1) * INNER
    a, b = int(np.clip(np.floor(x1 + dx), 0, w)), int(np.clip(np.ceil(x2 - dx), 0, w))
    c, d = int(np.clip(np.floor(y1 + dy), 0, h)), int(np.clip(np.ceil(y2 - dy), 0, h))
    if b - a < 2 or d - c < 2:
        return None
    patch = cv2.resize(
        np.ascontiguousarray(rgb[c:d, a:b]), (PATCH_PX, PATCH_PX), interpolation=cv2.INTER_AREA
    )
    hsv = cv2.cvtColor(patch, cv2.COLOR_RGB2HSV).reshape(PATCH_PX, PATCH_PX, 3).astype(np.int64)
    hue = np.minimum(hsv[..., 0] * 12 // 180, 11)
    sat = np.minimum(hsv[..., 1] * 4 // 256, 3)
    val = np.minimum(hsv[..., 2] * 4 // 256, 3)
    hs = np.bincount((hue * 4 + sat).ravel(), minlength=48).astype(np.float64)
    q = PATCH_PX // 2
    quads = [
        np.bincount(val[i : i + q, j : j + q].ravel(), minlength=4) for i in (0, q) for j in (0, q)
    ]
    v = np.concatenate([np.sqrt(hs / hs.sum()), *[np.sqrt(x / x.sum()) / 2 for x in quads]])
    return v / np.linalg.norm(v)


class Gallery:
    """The last ``budget`` descriptors of one track (Deep SORT's nn_budget)."""

    def __init__(self, budget: int) -> None:
        self.features: deque[np.ndarray] = deque(maxlen=budget)

    def add(self, feature: np.ndarray | None) -> None:
        if feature is not None:
            self.features.append(feature)

    def distance(self, features: Sequence[np.ndarray | None]) -> np.ndarray:
        """Smallest cosine distance to the gallery for each feature; NaN where unknown."""
        out = np.full(len(features), np.nan)
        if not self.features:
            return out
        g = np.stack(self.features)
        for j, f in enumerate(features):
            if f is not None:
                out[j] = max(0.0, 1.0 - float(np.max(g @ f)))
        return out
