"""Detection data sets in the shared JSON format: a list of {image, width, height, boxes}.

Image paths are relative to the JSON file unless an images root is given. Boxes are
[x1, y1, x2, y2] in pixels of the stored image. Loading validates every entry and says which
one is wrong instead of failing later inside training or evaluation.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np


class DatasetError(ValueError):
    """A data set file or entry that cannot be used; the message names the file and entry."""


@dataclass(frozen=True)
class Sample:
    """One image with its ground-truth boxes, (N, 4) float32 x1, y1, x2, y2 pixels."""

    path: Path
    width_px: int
    height_px: int
    boxes_xyxy_px: np.ndarray

    def load_rgb(self) -> np.ndarray:
        """The image as (H, W, 3) uint8 RGB; DatasetError when unreadable or of the wrong size."""
        bgr = cv2.imread(str(self.path), cv2.IMREAD_COLOR)
        if bgr is None:
            raise DatasetError(f"{self.path}: cannot be read as an image")
        if bgr.shape[:2] != (self.height_px, self.width_px):
            raise DatasetError(
                f"{self.path}: is {bgr.shape[1]}x{bgr.shape[0]} px, the data set says "
                f"{self.width_px}x{self.height_px}"
            )
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def load_dataset(json_path: Path, images_root: Path | None = None) -> list[Sample]:
    """Read and validate a data set JSON file."""
    try:
        entries = json.loads(Path(json_path).read_text())
    except FileNotFoundError:
        raise DatasetError(f"data set not found: {json_path}") from None
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{json_path}: not valid JSON: {exc}") from None
    if not isinstance(entries, list):
        raise DatasetError(f"{json_path}: expected a list of {{image, width, height, boxes}}")
    root = Path(images_root) if images_root is not None else Path(json_path).parent
    out = []
    for i, e in enumerate(entries):
        where = f"{json_path} entry {i}"
        try:
            w, h = int(e["width"]), int(e["height"])
            boxes = np.asarray(e["boxes"], dtype=np.float32).reshape(-1, 4)
            path = root / str(e["image"])
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"{where}: malformed ({exc})") from None
        if w <= 0 or h <= 0:
            raise DatasetError(f"{where}: non-positive size {w}x{h}")
        if not np.isfinite(boxes).all():
            raise DatasetError(f"{where}: a box has NaN or inf")
        if (boxes[:, 2] < boxes[:, 0]).any() or (boxes[:, 3] < boxes[:, 1]).any():
            raise DatasetError(f"{where}: an inverted box")
        out.append(Sample(path, w, h, boxes))
    return out


def letterbox_scale(w_px: int, h_px: int, canvas_w_px: int, canvas_h_px: int) -> float:
    """Scale that fits a w x h image into the canvas, keeping its aspect ratio."""
    return min(canvas_w_px / w_px, canvas_h_px / h_px)


def letterbox(rgb: np.ndarray, canvas_w_px: int, canvas_h_px: int) -> tuple[np.ndarray, float]:
    """Resize into the top-left of a grey canvas; returns the canvas and the scale used.

    Top-left placement makes the inverse mapping a pure scale (box / scale).
    """
    h, w = rgb.shape[:2]
    s = letterbox_scale(w, h, canvas_w_px, canvas_h_px)
    nw, nh = min(canvas_w_px, round(w * s)), min(canvas_h_px, round(h * s))
    canvas = np.full((canvas_h_px, canvas_w_px, 3), PAD_VALUE, np.uint8)
    interp = cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR
    canvas[:nh, :nw] = cv2.resize(rgb, (nw, nh), interpolation=interp)
    return canvas, s


PAD_VALUE = 114
"""Grey of the letterbox padding (the YOLO convention)."""
