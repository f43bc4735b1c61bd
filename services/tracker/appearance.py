"""Appearance: a colour/texture descriptor of a box's pixels, and Deep SORT's cosine gallery.

We have no pretrained re-ID network (no downloads here) and oranges look alike, so the
descriptor is deliberately simple and robust: the centre of the box (where the fruit is, not
the leaves around it) sampled on a 16x16 grid of the frame's HSV image (converted once per
frame, so 30 boxes cost 30 slicings, not 30 colour conversions), described by a hue-saturation
and a value histogram per quadrant (4 quadrants x 4 bins) for shading/texture layout. Each
part is normalised, square-rooted (Hellinger), and the vector is L2-normalised, so the cosine
distance is 1 - dot product.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

DESCRIPTOR_DIM = 12 * 4 + 4 * 4
INNER = 0.15  # share of the box trimmed on each side before describing it
PATCH_PX = 16


def to_hsv(rgb: np.ndarray) -> np.ndarray:
    """The frame in OpenCV HSV (H 0-179), the input of ``describe``."""
    return cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2HSV)


_HUE_BIN = np.minimum(np.arange(256) * 12 // 180, 11).astype(np.int64)
_Q = PATCH_PX // 2
_QUAD = ((np.arange(PATCH_PX)[:, None] >= _Q) * 2 + (np.arange(PATCH_PX)[None, :] >= _Q)).ravel()


def describe(hsv_image: np.ndarray, box_xyxy_px: np.ndarray) -> np.ndarray | None:
    """Descriptor of the box's inner region; None when it is empty in the image.

    One bincount makes all five histograms: codes 0-47 are hue x saturation, 48-63 quadrant x
    value. Every part has a fixed number of samples (256, or 64 per quadrant), so normalising
    each part and then the whole vector is one constant: sqrt(counts / 512).
    """
    h, w = hsv_image.shape[:2]
    x1, y1, x2, y2 = (float(v) for v in box_xyxy_px)
    dx, dy = (x2 - x1) * INNER, (y2 - y1) * INNER
    a, b = min(max(math.floor(x1 + dx), 0), w), min(max(math.ceil(x2 - dx), 0), w)
    c, d = min(max(math.floor(y1 + dy), 0), h), min(max(math.ceil(y2 - dy), 0), h)
    if b - a < 2 or d - c < 2:
        return None
    ys = c + (np.arange(PATCH_PX) * (d - 1 - c) + (PATCH_PX - 1) // 2) // (PATCH_PX - 1)
    xs = a + (np.arange(PATCH_PX) * (b - 1 - a) + (PATCH_PX - 1) // 2) // (PATCH_PX - 1)
    patch = hsv_image[ys[:, None], xs[None, :]].reshape(-1, 3).astype(np.int64)
    hs = _HUE_BIN[patch[:, 0]] * 4 + (patch[:, 1] >> 6)
    qv = 48 + _QUAD * 4 + (patch[:, 2] >> 6)
    counts = np.bincount(np.concatenate((hs, qv)), minlength=DESCRIPTOR_DIM)
    return np.sqrt(counts / (2.0 * PATCH_PX * PATCH_PX))


class Gallery:
    """The last ``budget`` descriptors of one track (Deep SORT's nn_budget), kept as the rows
    of one array (a ring buffer), so matching needs no stacking per frame."""

    def __init__(self, budget: int) -> None:
        self.matrix = np.zeros((budget, DESCRIPTOR_DIM))
        self.size = 0
        self._next = 0

    @property
    def features(self) -> np.ndarray:
        """The stored descriptors, (size, DESCRIPTOR_DIM), in no particular order."""
        return self.matrix[: self.size]

    def add(self, feature: np.ndarray | None) -> None:
        if feature is None:
            return
        self.matrix[self._next] = feature
        self._next = (self._next + 1) % len(self.matrix)
        self.size = min(self.size + 1, len(self.matrix))

    def distance(self, features: Sequence[np.ndarray | None]) -> np.ndarray:
        """Smallest cosine distance to the gallery for each feature; NaN where unknown."""
        return appearance_distances([self], features)[0]


def appearance_distances(
    galleries: Sequence[Gallery], features: Sequence[np.ndarray | None]
) -> np.ndarray:
    """(T, N) smallest cosine distance of each feature to each gallery (NaN where either is
    empty), from one matrix product over all galleries stacked."""
    out = np.full((len(galleries), len(features)), np.nan)
    known = [j for j, f in enumerate(features) if f is not None]
    rows = [i for i, g in enumerate(galleries) if g.size]
    if not known or not rows:
        return out
    stacked = np.concatenate([galleries[i].features for i in rows])
    fmat = np.stack([f for f in features if f is not None])
    sims = stacked @ fmat.T  # (sum of sizes, known)
    starts = np.cumsum([0] + [galleries[i].size for i in rows[:-1]])
    best = np.maximum.reduceat(sims, starts, axis=0)  # (rows, known)
    out[np.ix_(rows, known)] = np.maximum(0.0, 1.0 - best)
    return out
