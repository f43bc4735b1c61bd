"""Appearance: a colour/texture descriptor of a box's pixels, and Deep SORT's cosine gallery.

We have no pretrained re-ID network (no downloads here) and oranges look alike, so the
descriptor is deliberately simple and robust: the centre of the box (where the fruit is, not
the leaves around it) sampled on a 16x16 grid of the frame and converted to HSV (only the
samples: a whole-frame conversion costs more than 30 boxes' samples), described by a hue-saturation
and a value histogram per quadrant (4 quadrants x 4 bins) for shading/texture layout. Each
part is normalised, square-rooted (Hellinger), and the vector is L2-normalised, so the cosine
distance is 1 - dot product.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

DESCRIPTOR_DIM = 12 * 4 + 4 * 4
INNER = 0.15  # share of the box trimmed on each side before describing it
PATCH_PX = 16


def to_hsv(rgb: np.ndarray) -> np.ndarray:
    """RGB pixels (any shape ending in 3) in OpenCV HSV (H 0-179); per pixel, so converting a
    sample of a frame gives what converting the frame and then sampling it gives."""
    flat = np.ascontiguousarray(rgb).reshape(1, -1, 3)
    return cv2.cvtColor(flat, cv2.COLOR_RGB2HSV).reshape(rgb.shape)


_HUE_BIN = np.minimum(np.arange(256) * 12 // 180, 11).astype(np.int64)
_Q = PATCH_PX // 2
_QUAD = ((np.arange(PATCH_PX)[:, None] >= _Q) * 2 + (np.arange(PATCH_PX)[None, :] >= _Q)).ravel()


def describe(rgb_image: np.ndarray, box_xyxy_px: np.ndarray) -> np.ndarray | None:
    """Descriptor of the box's inner region; None when it is empty in the image."""
    return describe_many(rgb_image, np.asarray(box_xyxy_px, float)[None])[0]


def describe_many(rgb_image: np.ndarray, boxes_xyxy_px: np.ndarray) -> list[np.ndarray | None]:
    """Descriptors of the inner regions of N boxes (N, 4); None for a box empty in the image.

    All boxes are sampled with one gather and binned with one bincount (a box's codes offset by
    its index times DESCRIPTOR_DIM): per-box numpy calls cost more than the arithmetic with 30
    boxes. Codes 0-47 are hue x saturation, 48-63 quadrant x value. Every part has a fixed
    number of samples (256, or 64 per quadrant), so normalising each part and then the whole
    vector is one constant: sqrt(counts / 512).
    """
    h, w = rgb_image.shape[:2]
    b = np.asarray(boxes_xyxy_px, float).reshape(-1, 4)
    n = len(b)
    if n == 0:
        return []
    dx, dy = (b[:, 2] - b[:, 0]) * INNER, (b[:, 3] - b[:, 1]) * INNER
    a = np.clip(np.floor(b[:, 0] + dx), 0, w).astype(np.int64)
    e = np.clip(np.ceil(b[:, 2] - dx), 0, w).astype(np.int64)
    c = np.clip(np.floor(b[:, 1] + dy), 0, h).astype(np.int64)
    d = np.clip(np.ceil(b[:, 3] - dy), 0, h).astype(np.int64)
    ok = (e - a >= 2) & (d - c >= 2)
    if not ok.any():
        return [None] * n
    a, e, c, d = a[ok], e[ok], c[ok], d[ok]
    k = np.arange(PATCH_PX)
    ys = c[:, None] + (k[None] * (d - 1 - c)[:, None] + (PATCH_PX - 1) // 2) // (PATCH_PX - 1)
    xs = a[:, None] + (k[None] * (e - 1 - a)[:, None] + (PATCH_PX - 1) // 2) // (PATCH_PX - 1)
    samples = rgb_image[ys[:, :, None], xs[:, None, :]].reshape(len(a), -1, 3)
    patch = to_hsv(samples).astype(np.int64)
    hs = _HUE_BIN[patch[..., 0]] * 4 + (patch[..., 1] >> 6)
    qv = 48 + _QUAD[None] * 4 + (patch[..., 2] >> 6)
    offset = (np.arange(len(a)) * DESCRIPTOR_DIM)[:, None]
    codes = np.concatenate((hs + offset, qv + offset), axis=1)
    counts = np.bincount(codes.ravel(), minlength=len(a) * DESCRIPTOR_DIM)
    feats = np.sqrt(counts.reshape(len(a), DESCRIPTOR_DIM) / (2.0 * PATCH_PX * PATCH_PX))
    out: list[np.ndarray | None] = [None] * n
    for row, i in enumerate(np.flatnonzero(ok)):
        out[i] = feats[row]
    return out


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
