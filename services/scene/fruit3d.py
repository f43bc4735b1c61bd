"""A fruit's 3D centre and semi-axes from its box, the depth and the intrinsics (paper §III-A).

The paper (eq. 2-4): the centre pixel is the box midpoint (its eq. (1) prints a difference: a
sign typo), z_f = z_min + dist(proj(u_C, v_C), proj(u_C + r_h, v_C)), d_v likewise from the
vertical semi-axis r_v. That is ``method="paper"`` here, with z_min the median of a small
window at the centre.

The default, ``method="surface"``, keeps the paper's model (an ellipsoid with semi-axes d_h, d_v,
d_h along camera x, y, z) and measures it more carefully:

1. *Shape and direction from the box, scale-free.* Each silhouette side of the box is a plane
   through the optical centre tangent to the ellipsoid: n·C = h(n) with the support function
   h(n) = sqrt(d_h²(nx² + nz²) + d_v² ny²). Tangency is homogeneous in (C, d_h, d_v), so with
   the depth of the centre set to 1 the sides give C/z, d_h/z and d_v/z in closed form (no
   small-angle approximation: exact off the optical axis too). Sides cut by the image border or
   by an occluder (``box_sides.py``) are dropped; the missing semi-axis then comes from the
   fruit's height/width ratio (its own, measured earlier, or a prior).
2. *Scale from every pixel of the visible surface.* For each valid, fruit-coloured pixel in the
   central part of the ellipse, the ray hits the unit-scale ellipsoid at depth ζ; its measured
   depth z gives a scale z/ζ. The farthest well-supported cluster of these scales (whatever
   hides part of the fruit is nearer than it), then the mean within 3 MADs of its median, is
   the centre depth. This uses hundreds of pixels instead of one (the D435's noise grows as
   z²), corrects the curvature of the front surface exactly, and rejects depths that do not fit
   the surface the box predicts (a leaf, a hand or an arm in front, holes).
3. *Which sides are cut.* Something nearer just beyond a side may cut the fruit there, or only
   touch it (a neighbour). Every combination of such sides is fitted; the fit that contradicts
   the image least (``ellipsoid.misfit``: background where it puts fruit, fruit where it puts
   background) is kept.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from services.scene.box_sides import Sides, border_sides, occluded_sides
from services.scene.ellipsoid import (
    Box,
    UnitShape,
    centre_depth,
    corner_shapes,
    far_cluster,
    misfit,
    shape_from_sides,
)
from services.scene.geometry import Pinhole

# Sizes tried for a fruit cut at a corner: 1 = the smallest that spans its box.
CORNER_SCALES = tuple(float(k) for k in np.linspace(1.0, 1.6, 13))

FailureReason = Literal[
    "box_degenerate",
    "box_outside_image",
    "depth_invalid",
    "depth_inconsistent",
    "not_fruit_coloured",
]


@dataclass(frozen=True)
class FruitParams:
    """Settings of the estimator (the scene Settings document them)."""

    method: Literal["surface", "paper"] = "surface"
    central_fraction: float = 0.7
    paper_window_px: int = 5
    min_pixels: int = 8
    min_support_share: float = 0.05
    min_box_px: float = 4.0
    border_margin_px: float = 1.0
    edge_strip_px: int = 3
    occluder_margin_m: float = 0.01
    window_margin: float = 0.5
    min_semi_axis_m: float = 0.015
    max_semi_axis_m: float = 0.12
    fruit_hsv_low: tuple[int, int, int] = (0, 140, 50)
    fruit_hsv_high: tuple[int, int, int] = (30, 255, 255)
    min_colour_share: float = 0.15
    refine_box: bool = True
    refine_keeps_holes: bool = True
    shape_tolerance: float = 0.04
    corner_fit: bool = False


@dataclass(frozen=True)
class FruitEstimate:
    """A fruit measured in one frame (camera frame)."""

    position_cam_m: np.ndarray  # (3,) centre, m
    semi_axis_h_m: float
    semi_axis_v_m: float
    sides: Sides
    pixels: int  # depth pixels that agreed with the surface

    @property
    def v_over_h(self) -> float:
        return self.semi_axis_v_m / self.semi_axis_h_m


@dataclass(frozen=True)
class EstimateFailure:
    """No usable estimate in this frame, and why."""

    reason: FailureReason
    detail: str


def estimate_fruit(
    box: Box,
    depth_m: np.ndarray,
    hsv: np.ndarray | None,
    K: Pinhole,
    p: FruitParams,
    v_over_h: float,
    shape_measured: bool = False,
) -> FruitEstimate | EstimateFailure:
    """Centre (camera frame) and semi-axes of the fruit in ``box``.

    Args:
        box: (x1, y1, x2, y2), px; pixel centres at integers, so edges at half-integers.
        depth_m: (H, W) float depth, m, 0 where invalid.
        hsv: (H, W, 3) uint8 OpenCV HSV of the colour image (None: no colour test).
        K: intrinsics of the frame.
        p: estimator settings.
        v_over_h: height/width ratio d_v/d_h to assume when a side is cut.
        shape_measured: ``v_over_h`` was measured (this fruit's or its neighbours' whole
            views), not a prior: a fit whose box gives a ratio far from it loses a misfit tie.
    """
    x1, y1, x2, y2 = box
    if not (x2 - x1 >= p.min_box_px and y2 - y1 >= p.min_box_px):
        return EstimateFailure("box_degenerate", f"box {box} is under {p.min_box_px} px")
    if x2 <= -0.5 or y2 <= -0.5 or x1 >= K.width - 0.5 or y1 >= K.height - 0.5:
        return EstimateFailure("box_outside_image", f"box {box} is outside the image")
    if p.method == "paper":
        border = border_sides(box, K.width, K.height, p.border_margin_px)
        return _paper(box, depth_m, K, p, border)
    if p.refine_box and hsv is not None:
        box = _tight_box(box, K, depth_m, hsv, p)
    border = border_sides(box, K.width, K.height, p.border_margin_px)
    win = _Window.around(box, K, depth_m, hsv, p, 0.0)
    valid_in_box = int((win.valid & win.in_box).sum())
    if hsv is not None and win.coloured_in_box < p.min_colour_share * valid_in_box:
        # A box on a hand, a branch or a leaf: the detector is not perfect, the colour says so.
        return EstimateFailure(
            "not_fruit_coloured",
            f"{win.coloured_in_box} of {valid_in_box} valid pixels in box {box} are fruit-coloured",
        )
    pool = win.in_box & (win.coloured if win.coloured_in_box >= p.min_pixels else win.valid)
    if int(pool.sum()) < p.min_pixels:
        return EstimateFailure("depth_invalid", f"fewer than {p.min_pixels} valid depths in box")
    z_front = _front_depth(box, win, pool, p)
    z_centre = z_front * (1 + (x2 - x1) / (2 * K.fx))  # the front plus about d_h
    margin = p.occluder_margin_m + 0.25 * (z_centre - z_front)
    occluded = occluded_sides(box, depth_m, z_centre, margin, p.edge_strip_px)
    suspects = [i for i in range(4) if occluded[i] and not border[i]]
    # A cut fruit goes on beyond its box: judge the fits on a wider window.
    wide = _Window.around(box, K, depth_m, hsv, p, p.window_margin) if suspects else win
    fits: list[tuple[int, int, int, FruitEstimate]] = []
    failure: EstimateFailure | None = None
    # An occluder-flagged side may be a real cut or a nearer neighbour that only touches the
    # fruit: fit every combination and keep the one that explains the image best.
    for cut in itertools.product((False, True), repeat=len(suspects)):
        cut_sides = {s for s, c in zip(suspects, cut, strict=True) if c}
        good = tuple(not border[i] and i not in cut_sides for i in range(4))
        sides = Sides(good, border, occluded)  # type: ignore[arg-type]
        corner = corner_shapes(box, K, good, v_over_h, CORNER_SCALES) if p.corner_fit else []
        # Cut at a corner: the size the image contradicts least; else the one fit of the sides.
        shapes = corner or [shape_from_sides(box, K, good, v_over_h)]
        best = _best_fit(shapes, sides, win, wide, pool, p, judge=bool(suspects))
        if isinstance(best, EstimateFailure):
            failure = failure or best
            continue
        score, fit = best
        odd = (
            shape_measured
            and p.shape_tolerance > 0
            and abs(fit.v_over_h / v_over_h - 1) > p.shape_tolerance
        )
        fits.append((score, int(odd), len(cut_sides), fit))
    if not fits:
        assert failure is not None
        return failure
    # Ties: a box whose height/width is far from the fruit's known shape is not its silhouette
    # (a side the image cannot tell cut from touched), then the fewest cut sides.
    return min(fits, key=lambda f: f[:3])[3]


@dataclass(frozen=True)
class _Window:
    """Flat pixel arrays over the box and a margin around it (for fitting and checking)."""

    xn: np.ndarray  # (u - cx) / fx
    yn: np.ndarray  # (v - cy) / fy
    u: np.ndarray
    v: np.ndarray
    z: np.ndarray  # depth, m (0: none)
    valid: np.ndarray
    coloured: np.ndarray  # fruit-coloured and valid
    in_box: np.ndarray
    coloured_in_box: int
    fruit_hue: np.ndarray  # fruit-coloured, with or without depth

    @classmethod
    def around(
        cls,
        box: Box,
        K: Pinhole,
        depth_m: np.ndarray,
        hsv: np.ndarray | None,
        p: FruitParams,
        margin: float,
    ) -> _Window:
        """The box grown by ``margin`` times its size on every side, clipped to the image."""
        x1, y1, x2, y2 = box
        mx, my = (x2 - x1) * margin, (y2 - y1) * margin
        c0, c1 = max(0, math.ceil(x1 - mx)), min(K.width, math.floor(x2 + mx) + 1)
        r0, r1 = max(0, math.ceil(y1 - my)), min(K.height, math.floor(y2 + my) + 1)
        vv, uu = np.mgrid[r0:r1, c0:c1]
        z = depth_m[r0:r1, c0:c1]
        valid = z > 0
        if hsv is None:
            hue = np.zeros_like(valid)
            coloured = valid
        else:
            h = hsv[r0:r1, c0:c1]
            inside = (h >= np.array(p.fruit_hsv_low)) & (h <= np.array(p.fruit_hsv_high))
            hue = np.all(inside, axis=2)
            coloured = valid & hue
        in_box = (uu > x1) & (uu < x2) & (vv > y1) & (vv < y2)
        return cls(
            ((uu - K.cx) / K.fx).ravel(),
            ((vv - K.cy) / K.fy).ravel(),
            uu.ravel(),
            vv.ravel(),
            z.ravel().astype(float),
            valid.ravel(),
            coloured.ravel(),
            in_box.ravel(),
            int((coloured & in_box).sum()),
            hue.ravel(),
        )


def _tight_box(box: Box, K: Pinhole, depth_m: np.ndarray, hsv: np.ndarray, p: FruitParams) -> Box:
    """The detector's box shrunk to the fruit-coloured pixels at the fruit's depth in it.

    A detector's box is a few pixels loose (ours: ~15 % wide on the sim's fruit), and the
    estimator takes the box's sides as the silhouette's tangents: every pixel of slack is about
    a millimetre of centre error, mostly in depth. The fruit's own pixels (its colour, within a
    fruit's depth of its front) give the visible silhouette's extent; the box only ever shrinks
    to it (never grows), and stays as it was when too few such pixels are found."""
    win = _Window.around(box, K, depth_m, hsv, p, 0.0)
    pool = win.in_box & win.coloured
    if int(pool.sum()) < max(p.min_pixels, 4 * p.min_box_px):
        return box
    # The farthest supported depth cluster of the whole box: occluders (an orange arm too) are
    # nearer than the fruit.
    z_front = _far_depth(win.z[pool], p)
    mine = pool & (win.z > z_front - 0.015) & (win.z < z_front + 1.5 * p.max_semi_axis_m)
    if int(mine.sum()) < p.min_pixels:
        return box
    if p.refine_keeps_holes:
        # Fruit-coloured pixels without depth are the fruit too: a nearer object to its right
        # casts the stereo shadow over it (a band with no depth), and shrinking the box to the
        # pixels with depth made the fruit narrow, and so near, with no side flagged as cut.
        mine = mine | (win.in_box & ~win.valid & win.fruit_hue)
    u, v = win.u[mine], win.v[mine]
    x1, y1, x2, y2 = box
    tight = (
        max(x1, float(u.min()) - 0.5),
        max(y1, float(v.min()) - 0.5),
        min(x2, float(u.max()) + 0.5),
        min(y2, float(v.max()) + 0.5),
    )
    if tight[2] - tight[0] < p.min_box_px or tight[3] - tight[1] < p.min_box_px:
        return box
    return tight


def _front_depth(box: Box, win: _Window, pool: np.ndarray, p: FruitParams) -> float:
    """Depth of the fruit's front: the farthest supported depth cluster of the pool's pixels in
    the box's central half (an arm or a hand in front of the fruit is nearer)."""
    x1, y1, x2, y2 = box
    qx, qy = (x2 - x1) / 4, (y2 - y1) / 4
    mid = pool & (win.u > x1 + qx) & (win.u < x2 - qx) & (win.v > y1 + qy) & (win.v < y2 - qy)
    return _far_depth(win.z[mid] if mid.sum() >= p.min_pixels else win.z[pool], p)


def _far_depth(z: np.ndarray, p: FruitParams) -> float:
    """Median of the farthest well-supported depth cluster (occluders are nearer)."""
    need = max(p.min_pixels, math.ceil(p.min_support_share * len(z)))
    return float(np.median(far_cluster(z, max(0.01 * float(np.median(z)), 0.005), need)))


def _fit(
    shape: UnitShape, sides: Sides, win: _Window, pool: np.ndarray, p: FruitParams
) -> FruitEstimate | EstimateFailure:
    """Scale the unit shape by the centre depth measured on the pool's pixels."""
    sc = centre_depth(
        shape,
        win.xn[pool],
        win.yn[pool],
        win.z[pool],
        p.central_fraction,
        p.min_pixels,
        p.min_support_share,
    )
    if sc is None:
        return EstimateFailure("depth_invalid", "too few valid depths on the fruit's centre")
    lam = sc.depth_m
    d_h, d_v = lam * shape.a, lam * shape.c
    if not (p.min_semi_axis_m <= d_h <= p.max_semi_axis_m):
        return EstimateFailure(
            "depth_inconsistent",
            f"depth {lam:.3f} m makes the fruit {2000 * d_h:.0f} mm wide for its box",
        )
    centre = np.array([shape.x * lam, shape.y * lam, lam])
    if not (np.all(np.isfinite(centre)) and math.isfinite(d_v) and d_v > 0):
        return EstimateFailure("depth_inconsistent", "non-finite estimate")
    return FruitEstimate(centre, d_h, d_v, sides, sc.inliers)


def _best_fit(
    shapes: list[UnitShape],
    sides: Sides,
    win: _Window,
    wide: _Window,
    pool: np.ndarray,
    p: FruitParams,
    judge: bool,
) -> tuple[int, FruitEstimate] | EstimateFailure:
    """The candidate with the smallest misfit (the first, the smallest fruit, on a tie); the
    misfit is 0 when ``judge`` is false (one candidate, nothing to choose)."""
    best: tuple[int, FruitEstimate] | None = None
    failure: EstimateFailure | None = None
    for shape in shapes:
        fit = _fit(shape, sides, win, pool, p)
        if isinstance(fit, EstimateFailure):
            failure = failure or fit
            continue
        score = _misfit(shape, fit, wide) if judge or len(shapes) > 1 else 0
        if best is None or score < best[0]:
            best = (score, fit)
    if best is None:
        assert failure is not None
        return failure
    return best


def _misfit(shape: UnitShape, fit: FruitEstimate, win: _Window) -> int:
    lam = float(fit.position_cam_m[2])
    return misfit(shape, lam, win.xn, win.yn, win.z, win.coloured, win.in_box)


def _paper(
    box: Box,
    depth_m: np.ndarray,
    K: Pinhole,
    p: FruitParams,
    border: tuple[bool, bool, bool, bool],
) -> FruitEstimate | EstimateFailure:
    """The paper's eq. (2)-(4), z_min = median valid depth of a small window at the centre."""
    x1, y1, x2, y2 = box
    uc, vc = (x1 + x2) / 2, (y1 + y2) / 2
    rh, rv = (x2 - x1) / 2, (y2 - y1) / 2
    w = p.paper_window_px // 2
    r, c = round(vc), round(uc)
    win = depth_m[max(r - w, 0) : r + w + 1, max(c - w, 0) : c + w + 1]
    win = win[win > 0]
    if len(win) == 0:
        return EstimateFailure("depth_invalid", "no valid depth at the box centre")
    z_min = float(np.median(win))
    p0 = K.deproject(uc, vc, z_min)
    ph, pv = K.deproject(uc + rh, vc, z_min), K.deproject(uc, vc + rv, z_min)
    d_h = float(np.linalg.norm(ph - p0))
    d_v = float(np.linalg.norm(pv - p0))
    z_f = z_min + d_h
    sides = Sides(tuple(not b for b in border), border, (False,) * 4)  # type: ignore[arg-type]
    return FruitEstimate(K.deproject(uc, vc, z_f), d_h, d_v, sides, len(win))
