"""HSV-threshold baseline detector: orange-coloured blobs → boxes (for comparison only).

Pixels inside a hue band with enough saturation and value form a mask; an opening removes
speckle, a closing fills the specular highlight; each connected blob becomes a box. Its score
is how round and full the blob is (area / (pi/4 * w * h), capped at 1), so AP can rank blobs.
Touching fruit merge into one blob: the weakness the learned detector is there to fix.
"""

from __future__ import annotations

import cv2
import numpy as np


class HsvDetector:
    def __init__(
        self,
        hue_range: tuple[int, int] = (5, 25),
        sat_min: int = 140,
        val_min: int = 100,
        min_area_px: int = 40,
        max_detections: int = 100,
    ) -> None:
        self.lo = np.array([hue_range[0], sat_min, val_min], np.uint8)
        self.hi = np.array([hue_range[1], 255, 255], np.uint8)
        self.min_area_px = min_area_px
        self.max_detections = max_detections
        self._k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))

    def detect(self, rgb: np.ndarray) -> np.ndarray:
        """(K, 5) x1, y1, x2, y2, score; best first, ties by position."""
        hsv = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2HSV)
        mask = cv2.inRange(hsv, self.lo, self.hi)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._k)
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, self._k)
        _, _, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        out = []
        for x, y, w, h, area in stats[1:]:
            if area < self.min_area_px:
                continue
            fill = area / (np.pi / 4 * w * h)
            out.append((x, y, x + w, y + h, min(1.0, float(fill))))
        arr = np.asarray(out, np.float64).reshape(-1, 5)
        order = np.lexsort((arr[:, 1], arr[:, 0], -arr[:, 4]))
        return arr[order][: self.max_detections]
