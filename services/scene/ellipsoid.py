"""The fruit ellipsoid at unit centre depth: its shape from the box's silhouette sides, where
camera rays meet it, the centre depth from measured depths, and how well a fit explains the image.

The ellipsoid has semi-axes a (camera x and z) and c (camera y), the paper's model of a fruit.
Scaled so that its centre is at depth 1, it is fixed by the box alone; the real one is that
shape times the centre depth λ (tangency to planes through the optical centre is homogeneous).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.scene.geometry import Pinhole

Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class UnitShape:
    """The ellipsoid at unit centre depth: centre (x, y, 1) and semi-axes a (h), c (v)."""

    x: float
    y: float
    a: float
    c: float

    def hits(self, xn: np.ndarray, yn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For rays (xn, yn, 1): (hit mask, depth ζ of the front intersection where hit)."""
        a2, c2 = self.a * self.a, self.c * self.c
        # t·(xn, yn, 1) on the ellipsoid: A t² - 2 B t + D = 0; the front root is the visible one.
        A = (xn * xn + 1) / a2 + yn * yn / c2
        B = (xn * self.x + 1) / a2 + yn * self.y / c2
        D = (self.x * self.x + 1) / a2 + self.y * self.y / c2 - 1
        disc = B * B - A * D
        hit = disc > 0
        zeta = np.where(hit, (B - np.sqrt(np.maximum(disc, 0))) / A, 0.0)
        return hit, zeta


def shape_from_sides(box: Box, K: Pinhole, good: tuple[bool, ...], v_over_h: float) -> UnitShape:
    """The unit-depth ellipsoid tangent to the box's good sides.

    Each side is a plane through the optical centre, e.g. x = xl·z for the left one, with normal
    n; tangency is n·C = h(n), h(n) = sqrt(a²(nx² + nz²) + c²ny²). Left and right give a and x in
    closed form, top and bottom c and y. A pair with a cut side borrows the missing semi-axis
    from the other pair through ``v_over_h`` (c = v_over_h · a). With neither pair whole the
    box itself is taken as the silhouette (the caller flags it).
    """
    r = _BoxRays.of(box, K)
    lg, tg, rg, bg = good
    h_pair, v_pair = lg and rg, tg and bg
    if not (h_pair or v_pair):
        h_pair = v_pair = lg = rg = tg = bg = True
    if h_pair:
        a = r.a_from_width()
        c = _c_from_top_bottom(r.yt, r.yb, a) if v_pair else v_over_h * a
    else:
        c = r.c_from_height(v_over_h)
        a = c / v_over_h
    return r.placed(a, c, (lg, tg, rg, bg))


def corner_shapes(
    box: Box, K: Pinhole, good: tuple[bool, ...], v_over_h: float, scales: tuple[float, ...]
) -> list[UnitShape]:
    """Unit-depth ellipsoids tangent to one whole horizontal and one whole vertical side of a
    box cut on the other two (a fruit hidden at a corner), one per size in ``scales``.

    Two sides leave the size open: each candidate is the smallest fruit that still spans the
    box (its width, and its height through ``v_over_h``) times a scale; the caller keeps the
    one that contradicts the image least. Empty unless exactly one side of each pair is good.
    """
    lg, tg, rg, bg = good
    if lg == rg or tg == bg:
        return []
    r = _BoxRays.of(box, K)
    a0 = max(r.a_from_width(), r.c_from_height(v_over_h) / v_over_h)
    return [r.placed(a, v_over_h * a, good) for a in (a0 * k for k in scales)]


@dataclass(frozen=True)
class _BoxRays:
    """A box's sides as rays at unit depth (xl, xr, yt, yb) and the norms of the left and
    right side planes' (1, x) parts."""

    xl: float
    xr: float
    yt: float
    yb: float
    nl: float
    nr: float

    @classmethod
    def of(cls, box: Box, K: Pinhole) -> _BoxRays:
        x1, y1, x2, y2 = box
        xl, xr = (x1 - K.cx) / K.fx, (x2 - K.cx) / K.fx
        yt, yb = (y1 - K.cy) / K.fy, (y2 - K.cy) / K.fy
        return cls(xl, xr, yt, yb, math.hypot(1, xl), math.hypot(1, xr))

    def a_from_width(self) -> float:
        """a tangent to the left and right sides."""
        return (self.xr - self.xl) / (self.nl + self.nr)

    def c_from_height(self, v_over_h: float) -> float:
        """c tangent to the top and bottom with a = c / v_over_h: sqrt(c² + c²y²/ρ²) is
        linear in c."""
        return (self.yb - self.yt) / (
            math.hypot(1, self.yt / v_over_h) + math.hypot(1, self.yb / v_over_h)
        )

    def placed(self, a: float, c: float, good: tuple[bool, ...]) -> UnitShape:
        """The shape of semi-axes (a, c) tangent to a good side of each pair (the left before
        the right, the top before the bottom; centred between them when neither is good)."""
        lg, tg, rg, bg = good
        if lg:
            x = self.xl + a * self.nl
        elif rg:
            x = self.xr - a * self.nr
        else:
            x = (self.xl + self.xr) / 2
        if tg:
            y = self.yt + math.sqrt(c * c + a * a * self.yt * self.yt)
        elif bg:
            y = self.yb - math.sqrt(c * c + a * a * self.yb * self.yb)
        else:
            y = (self.yt + self.yb) / 2
        return UnitShape(x, y, a, c)


def _c_from_top_bottom(yt: float, yb: float, a: float) -> float:
    """c with sqrt(c² + a²yt²) + sqrt(c² + a²yb²) = yb - yt (closed form)."""
    s, p2, q2 = yb - yt, (a * yt) ** 2, (a * yb) ** 2
    m = (s * s + q2 - p2) / (2 * s)  # = sqrt(c² + q2)
    return math.sqrt(max(m * m - q2, 1e-12))


def far_cluster(values: np.ndarray, gap: float, min_support: int) -> np.ndarray:
    """The farthest group of ``values`` (sorted, split where consecutive ones differ by more
    than ``gap``) holding at least ``min_support`` values; all values when none does.

    Whatever lies between the camera and a fruit's visible surface (a leaf, a hand, an arm) is
    nearer than the fruit, and nothing behind the fruit shows through it: inside the fruit's
    silhouette the fruit is the farthest well-supported surface.
    """
    v = np.sort(values)
    cuts = np.nonzero(np.diff(v) > gap)[0] + 1
    groups = np.split(v, cuts)
    for g in reversed(groups):
        if len(g) >= min_support:
            return g
    return v


@dataclass(frozen=True)
class Scale:
    """The centre depth λ (m) and the pixels that agree with it."""

    depth_m: float
    inliers: int
    candidates: int


def centre_depth(
    shape: UnitShape,
    xn: np.ndarray,
    yn: np.ndarray,
    z: np.ndarray,
    central_fraction: float,
    min_support: int,
    support_share: float,
) -> Scale | None:
    """λ from measured depths z of pixels with rays (xn, yn, 1) in the central part of the shape.

    Each pixel gives λ_i = z_i / ζ_i (ζ: the unit shape's depth along its ray). The farthest
    supported cluster of λ_i (occluders are nearer), then the mean of its values within 3 MADs
    of its median (at least ±2 mm: depths are whole millimetres). None if too few pixels.
    """
    rho2 = ((xn - shape.x) / shape.a) ** 2 + ((yn - shape.y) / shape.c) ** 2
    keep = rho2 < central_fraction**2
    hit, zeta = shape.hits(xn[keep], yn[keep])
    lam = z[keep][hit] / zeta[hit]
    if len(lam) < min_support:
        return None
    need = max(min_support, math.ceil(support_share * len(lam)))
    group = far_cluster(lam, max(0.01 * float(np.median(lam)), 0.005), need)
    med = float(np.median(group))
    tol = max(3 * 1.4826 * float(np.median(np.abs(group - med))), 0.002)
    inl = group[np.abs(group - med) <= tol]
    if len(inl) < need:
        return None
    return Scale(float(np.mean(inl)), len(inl), len(lam))


def misfit(
    shape: UnitShape,
    lam_m: float,
    xn: np.ndarray,
    yn: np.ndarray,
    z: np.ndarray,
    coloured: np.ndarray,
    in_box: np.ndarray,
) -> int:
    """How many pixels contradict a fit: where the fit puts fruit, the camera sees something
    farther (background: the fruit is smaller or elsewhere); in the detector's box, outside the
    fit's silhouette, fruit-coloured pixels at the fruit's depth (the fruit is bigger).

    Pixels nearer than the fit are never counted: occluders may hide any part of the fruit.
    Args are flat arrays over a window around the fruit (z = 0: no depth).
    """
    hit, zeta = shape.hits(xn, yn)
    valid = z > 0
    a_m = shape.a * lam_m
    tol = max(0.3 * a_m, 0.01)
    behind = hit & valid & (z > zeta * lam_m + tol)
    outside = ~hit & in_box & coloured & valid & (np.abs(z - lam_m) < 1.5 * a_m)
    return int(behind.sum() + outside.sum())
