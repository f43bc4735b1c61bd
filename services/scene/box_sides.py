"""Which sides of a fruit box are the fruit's own silhouette, and which are cut.

A side is *cut* when it lies on the image border (the fruit goes on outside the image) or when
an occluder nearer than the fruit lies just outside it (a leaf or a hand hides the fruit there,
so the detector's box stops at the occluder, not at the fruit's edge). Only silhouette sides
carry the fruit's size; the estimator drops the cut ones (``fruit3d.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SIDES = ("left", "top", "right", "bottom")


@dataclass(frozen=True)
class Sides:
    """For each side (left, top, right, bottom): True when it is the fruit's silhouette."""

    good: tuple[bool, bool, bool, bool]
    border: tuple[bool, bool, bool, bool]  # cut by the image border
    occluded: tuple[bool, bool, bool, bool]  # an occluder nearer than the fruit lies beyond it

    @property
    def all_good(self) -> bool:
        return all(self.good)

    @property
    def whole_pair(self) -> bool:
        """Left and right, or top and bottom, are both silhouette: the shape is measured."""
        lg, tg, rg, bg = self.good
        return (lg and rg) or (tg and bg)


def border_sides(box: tuple[float, float, float, float], width: int, height: int, margin_px: float):
    """Sides within ``margin_px`` of the image border (pixel edges are at -0.5 and W-0.5)."""
    x1, y1, x2, y2 = box
    return (
        x1 <= -0.5 + margin_px,
        y1 <= -0.5 + margin_px,
        x2 >= width - 0.5 - margin_px,
        y2 >= height - 0.5 - margin_px,
    )


def occluded_sides(
    box: tuple[float, float, float, float],
    depth_m: np.ndarray,
    silhouette_depth_m: float,
    margin_m: float,
    strip_px: int,
    min_pixels: int = 3,
) -> tuple[bool, bool, bool, bool]:
    """Sides beyond which most valid depths are nearer than the fruit's silhouette.

    The silhouette of an ellipsoid seen from a distance L lies at about the depth of its centre.
    Just outside a true silhouette side the camera sees what is *behind* the fruit (or nothing:
    stereo shadow, sky); just outside a side where an occluder cuts the fruit it sees the
    occluder, nearer than the silhouette. A strip ``strip_px`` wide along the middle half of
    each side is tested; a side with fewer than ``min_pixels`` valid depths is not occluded.

    Args:
        box: (x1, y1, x2, y2), px, pixel edges at half-integers.
        depth_m: (H, W) depth, m, 0 where invalid.
        silhouette_depth_m: expected depth of the fruit's silhouette (≈ its centre depth), m.
        margin_m: an occluder must be at least this much nearer than the silhouette, m.
        strip_px: width of the tested strip, px.
        min_pixels: valid depths needed in a strip to judge it.
    """
    H, W = depth_m.shape
    x1, y1, x2, y2 = box
    # Integer pixel ranges: pixel u covers [u-0.5, u+0.5]; the first pixel right of edge x is
    # round(x + 0.5) when x is a half-integer.
    u1, u2 = math.floor(x1 + 0.5), math.ceil(x2 - 0.5)  # first and last pixel inside
    v1, v2 = math.floor(y1 + 0.5), math.ceil(y2 - 0.5)
    qu, qv = (u2 - u1) / 4, (v2 - v1) / 4
    mu1, mu2 = round(u1 + qu), round(u2 - qu) + 1  # middle half along the side
    mv1, mv2 = round(v1 + qv), round(v2 - qv) + 1
    strips = (
        (mv1, mv2, u1 - 1 - strip_px, u1 - 1),  # left: rows, columns (left of the box)
        (v1 - 1 - strip_px, v1 - 1, mu1, mu2),  # top
        (mv1, mv2, u2 + 2, u2 + 2 + strip_px),  # right
        (v2 + 2, v2 + 2 + strip_px, mu1, mu2),  # bottom
    )
    # One pixel of gap: the detector's edge may be off by a pixel.
    out = []
    limit = silhouette_depth_m - margin_m
    for r0, r1, c0, c1 in strips:
        r0, r1, c0, c1 = max(r0, 0), min(r1, H), max(c0, 0), min(c1, W)
        if r1 <= r0 or c1 <= c0:
            out.append(False)
            continue
        d = depth_m[r0:r1, c0:c1]
        d = d[d > 0]
        out.append(len(d) >= min_pixels and float(np.mean(d < limit)) > 0.5)
    return out[0], out[1], out[2], out[3]
