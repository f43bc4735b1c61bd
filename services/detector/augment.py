"""Training augmentations (numpy + OpenCV): scale/translate/flip, mosaics, colour and noise.

Everything draws from a numpy Generator passed in, so an epoch is reproducible from its seed.
Boxes are kept when at least ``min_kept`` of their area stays inside the canvas.
"""

from __future__ import annotations

import cv2
import numpy as np

from services.detector.data import PAD_VALUE, letterbox_scale


def _warp(
    rgb: np.ndarray,
    boxes: np.ndarray,
    M: np.ndarray,
    out_w: int,
    out_h: int,
    min_kept: float,
    min_side_px: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Apply a scale+translate(+flip) affine M (2x3) to image and boxes; clip and filter boxes."""
    img = cv2.warpAffine(
        rgb,
        M,
        (out_w, out_h),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=(PAD_VALUE, PAD_VALUE, PAD_VALUE),
    )
    if len(boxes) == 0:
        return img, boxes.reshape(0, 4)
    xs = boxes[:, [0, 2]] * M[0, 0] + M[0, 2]
    ys = boxes[:, [1, 3]] * M[1, 1] + M[1, 2]
    b = np.stack([xs.min(1), ys.min(1), xs.max(1), ys.max(1)], 1)
    area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    c = b.copy()
    c[:, [0, 2]] = c[:, [0, 2]].clip(0, out_w)
    c[:, [1, 3]] = c[:, [1, 3]].clip(0, out_h)
    carea = (c[:, 2] - c[:, 0]) * (c[:, 3] - c[:, 1])
    keep = (carea >= min_kept * np.maximum(area, 1e-6)) & (
        np.minimum(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1]) >= min_side_px
    )
    return img, c[keep].astype(np.float32)


def random_placement(
    rgb: np.ndarray,
    boxes: np.ndarray,
    out_w: int,
    out_h: int,
    rng: np.random.Generator,
    scale_range: tuple[float, float] = (0.5, 1.6),
    min_kept: float = 0.45,
    min_side_px: float = 3.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Scale the image around its letterbox fit (log-uniform), flip, place at random."""
    h, w = rgb.shape[:2]
    s = letterbox_scale(w, h, out_w, out_h) * float(
        np.exp(rng.uniform(np.log(scale_range[0]), np.log(scale_range[1])))
    )
    flip = rng.random() < 0.5
    tx = rng.uniform(min(0.0, out_w - w * s), max(0.0, out_w - w * s))
    ty = rng.uniform(min(0.0, out_h - h * s), max(0.0, out_h - h * s))
    sx = -s if flip else s
    M = np.array([[sx, 0, tx + (w * s if flip else 0)], [0, s, ty]], np.float32)
    return _warp(rgb, boxes, M, out_w, out_h, min_kept, min_side_px)


def mosaic(
    items: list[tuple[np.ndarray, np.ndarray]],
    out_w: int,
    out_h: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Four images in a 2x2 grid split at a random point: many small fruit per canvas."""
    cx = int(rng.uniform(0.3, 0.7) * out_w)
    cy = int(rng.uniform(0.3, 0.7) * out_h)
    cells = [(0, 0, cx, cy), (cx, 0, out_w, cy), (0, cy, cx, out_h), (cx, cy, out_w, out_h)]
    canvas = np.full((out_h, out_w, 3), PAD_VALUE, np.uint8)
    all_boxes = []
    for (rgb, boxes), (x0, y0, x1, y1) in zip(items, cells, strict=True):
        img, b = random_placement(rgb, boxes, x1 - x0, y1 - y0, rng, (0.6, 1.3))
        canvas[y0:y1, x0:x1] = img
        all_boxes.append(b + np.array([x0, y0, x0, y0], np.float32))
    return canvas, np.concatenate(all_boxes, 0) if all_boxes else np.zeros((0, 4), np.float32)


def photometric(rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Hue/saturation/value jitter, contrast, blur and sensor noise."""
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV).astype(np.float32)
    hsv[..., 0] = (hsv[..., 0] + rng.uniform(-6, 6)) % 180  # small: oranges must stay orange
    hsv[..., 1] *= rng.uniform(0.6, 1.35)
    hsv[..., 2] *= rng.uniform(0.55, 1.4)
    out = cv2.cvtColor(hsv.clip(0, 255).astype(np.uint8), cv2.COLOR_HSV2RGB).astype(np.float32)
    c = rng.uniform(0.75, 1.25)
    out = (out - out.mean()) * c + out.mean()
    if rng.random() < 0.25:
        k = int(rng.choice([3, 5]))
        out = cv2.GaussianBlur(out, (k, k), 0)
    if rng.random() < 0.4:
        out = out + rng.normal(0, rng.uniform(2, 10), out.shape).astype(np.float32)
    return out.clip(0, 255).astype(np.uint8)
