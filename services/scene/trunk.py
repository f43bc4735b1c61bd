"""The trunk (paper §III-C): the HSV ∩ depth mask, then a vertical axis P_t, smoothed over frames.

The paper takes P_t from the mean pixel and the mean depth of the mask. That point lies on the
trunk's *front surface*, not on its axis (≈ 0.8 radius nearer), and every bark-coloured branch in
the mask pulls it sideways: in our scenarios it misses the axis by 20-45 cm (``method="paper"``
keeps it, for comparison). The default, ``method="circle"``, uses the same mask and the same
depths but the trunk's shape: a vertical cylinder seen from the front shows, in the world's
horizontal plane, the camera-facing arc of a circle, at every height. So:

1. mask pixels → 3D points in 'world'; binned into keys (5 mm horizontal cells × 2 cm heights,
   one key per occupied bin) so that a stack of heights counts more than a dense patch;
2. RANSAC (seeded) over circles through three nearby keys, radius within bounds, scored by the
   keys within ±``circle_band_m`` of the circle on its camera-facing half, less twice the keys
   inside it (the camera cannot see into a trunk); a branch is a line in that plane and
   gathers few keys on any one circle;
3. a least-squares refinement on the inliers; found when enough keys over enough height
   (0.4 m) agree and they span an arc of at least 120° centred on the direction to the camera
   (a cylinder shows the camera the half facing it; a circle fitted to branches, or one too
   large for a half-hidden trunk's arc, sees much less of itself).

P_t is the circle's centre (on the axis) at the mean height of its inliers; the trunk radius is
the circle's. The camera is nearly level (8° pitch), so the paper's "cylinder along the camera's
y axis" and our "cylinder vertical in the world" are the same up to that tilt.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from services.scene.geometry import Pinhole, RigidTransform

SCORE_CELLS = 800
PARTNER_DRAWS = 48
TrunkMiss = Literal["trunk_mask_empty", "trunk_too_little", "trunk_no_circle"]


@dataclass(frozen=True)
class TrunkParams:
    """Settings of the trunk estimator (the scene Settings document them)."""

    method: Literal["circle", "paper"] = "circle"
    min_pixels: int = 50
    key_cell_m: float = 0.005
    key_height_m: float = 0.02
    min_radius_m: float = 0.03
    max_radius_m: float = 0.2
    circle_band_m: float = 0.01
    min_keys: int = 40
    min_height_m: float = 0.4
    max_arc_offset_deg: float = 30.0
    min_arc_deg: float = 120.0
    ransac_iterations: int = 300
    seed: int = 0


@dataclass(frozen=True)
class TrunkFix:
    """The trunk measured in one frame."""

    axis_point_world_m: np.ndarray  # (3,) a point on the axis (at the mean height of the fit)
    radius_m: float | None  # None for the paper's method (it measures none)
    pixels: int  # mask pixels
    support: int  # keys that agree with the circle (pixels for the paper's method)
    arc_deg: float = 0.0  # angular extent of the arc seen (2nd to 98th percentile), deg
    height_m: float = 0.0  # height of trunk seen (the arc's keys), m


@dataclass(frozen=True)
class TrunkFailure:
    reason: TrunkMiss
    detail: str
    pixels: int


def measure_trunk(
    mask: np.ndarray,
    depth_m: np.ndarray,
    K: Pinhole,
    T: RigidTransform,
    p: TrunkParams,
) -> TrunkFix | TrunkFailure:
    """The trunk axis of one frame from its HSV ∩ depth mask.

    Args:
        mask: (H, W) bool trunk mask (``services.vision.trunk_mask``).
        depth_m: (H, W) depth, m (0: none).
        K: intrinsics; T: T_world_camera of the frame.
        p: settings.
    """
    v, u = np.nonzero(mask)
    n = len(u)
    if n == 0:
        return TrunkFailure("trunk_mask_empty", "no pixel passed the HSV and depth masks", 0)
    if n < p.min_pixels:
        return TrunkFailure("trunk_too_little", f"{n} mask pixels (< {p.min_pixels})", n)
    z = depth_m[v, u].astype(float)
    if p.method == "paper":
        zm = float(z.mean())
        P = K.deproject(float(u.mean()), float(v.mean()), zm)
        return TrunkFix(T.to_world(P), None, n, n)
    pts = T.to_world(np.stack([(u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z], axis=1))
    keys = _keys(pts, p.key_cell_m, p.key_height_m)
    cam = T.t_m[:2]
    fit = _ransac_circle(keys[:, :2], cam, p)
    if fit is None:
        return TrunkFailure("trunk_no_circle", f"no circle through {len(keys)} keys", n)
    centre, radius, inl = fit
    heights = keys[inl, 2]
    # No inlier at all happens (the candidates are ranked on a subsample of the cells).
    span = float(heights.max() - heights.min()) + p.key_height_m if len(heights) else 0.0
    if int(inl.sum()) < p.min_keys or span < p.min_height_m:
        return TrunkFailure(
            "trunk_too_little",
            f"best circle: {int(inl.sum())} keys over {span:.3f} m of height "
            f"(need {p.min_keys} over {p.min_height_m} m)",
            n,
        )
    lo, mid, hi = _arc_degrees(keys[inl, :2], centre, cam)
    if abs(mid) > p.max_arc_offset_deg or hi - lo < p.min_arc_deg:
        return TrunkFailure(
            "trunk_no_circle",
            f"best circle's keys span {lo:.0f}..{hi:.0f}° around the view direction (median "
            f"{mid:.0f}°): not the camera-facing side of a trunk",
            n,
        )
    axis = np.array([centre[0], centre[1], float(heights.mean())])
    return TrunkFix(axis, radius, n, int(inl.sum()), hi - lo, span)


def _arc_degrees(q: np.ndarray, centre: np.ndarray, cam: np.ndarray) -> tuple[float, float, float]:
    """2nd percentile, median and 98th percentile of the keys' angles around the circle, from
    the direction to the camera (deg). A trunk shows the arc centred on that direction."""
    to_cam, d = cam - centre, q - centre
    ang = np.degrees(np.arctan2(to_cam[0] * d[:, 1] - to_cam[1] * d[:, 0], d @ to_cam))
    lo, mid, hi = np.percentile(ang, [2, 50, 98])
    return float(lo), float(mid), float(hi)


def _keys(pts: np.ndarray, cell_m: float, height_m: float) -> np.ndarray:
    """One point (the mean) per occupied (x, y, z) bin, in bin order (deterministic)."""
    idx = np.floor(pts / np.array([cell_m, cell_m, height_m])).astype(np.int64)
    idx -= idx.min(axis=0)
    span = idx.max(axis=0) + 1
    flat = (idx[:, 0] * span[1] + idx[:, 1]) * span[2] + idx[:, 2]
    _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse, pts)
    return sums / counts[:, None]


def _circles(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres (M, 2) and radii (M,) of the circles through point triples (NaN if collinear)."""
    ax, ay, bx, by, cx, cy = a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1]
    d = 2 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    a2, b2, c2 = ax * ax + ay * ay, bx * bx + by * by, cx * cx + cy * cy
    with np.errstate(divide="ignore", invalid="ignore"):
        ux = (a2 * (by - cy) + b2 * (cy - ay) + c2 * (ay - by)) / d
        uy = (a2 * (cx - bx) + b2 * (ax - cx) + c2 * (bx - ax)) / d
    centres = np.stack([ux, uy], axis=1)
    return centres, np.hypot(ax - ux, ay - uy)


def _inliers(
    q: np.ndarray, centres: np.ndarray, radii: np.ndarray, cam: np.ndarray, band: float
) -> np.ndarray:
    """(M, N) keys within ±band of each circle, on its camera-facing half."""
    dx = q[None, :, 0] - centres[:, None, 0]
    dy = q[None, :, 1] - centres[:, None, 1]
    near = np.abs(np.hypot(dx, dy) - radii[:, None]) < band
    to_cam = cam[None, :] - centres
    facing = dx * to_cam[:, None, 0] + dy * to_cam[:, None, 1] > 0
    return np.asarray(near & facing)


def _score(
    q: np.ndarray,
    w: np.ndarray,
    centres: np.ndarray,
    radii: np.ndarray,
    cam: np.ndarray,
    band: float,
) -> np.ndarray:
    """(M,) weight on each circle's camera-facing arc, less twice the weight inside it: the
    camera cannot see into a trunk, so points inside a candidate circle speak against it (a
    circle too large for the trunk's front arc holds the trunk's flanks inside)."""
    on_arc = _inliers(q, centres, radii, cam, band) @ w
    dist = np.hypot(q[None, :, 0] - centres[:, None, 0], q[None, :, 1] - centres[:, None, 1])
    inside = (dist < radii[:, None] - band) @ w
    return np.asarray(on_arc - 2 * inside)


def _columns(q: np.ndarray, cell_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal cells of the keys: their mean positions and how many keys (heights) each
    holds. A trunk is a stack of heights on one arc: its cells weigh the most."""
    idx = np.floor(q / cell_m).astype(np.int64)
    idx -= idx.min(axis=0)
    flat = idx[:, 0] * (idx[:, 1].max() + 1) + idx[:, 1]
    _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    sums = np.zeros((len(counts), 2))
    np.add.at(sums, inverse, q)
    return sums / counts[:, None], counts.astype(float)


def _ransac_circle(
    keys_xy: np.ndarray, cam: np.ndarray, p: TrunkParams
) -> tuple[np.ndarray, float, np.ndarray] | None:
    """Best camera-facing circle through the keys' horizontal positions, refined; returns its
    centre, radius and which keys lie on its arc."""
    q, w = _columns(keys_xy, p.key_cell_m)
    n = len(q)
    if n < 3:
        return None
    rng = np.random.default_rng(p.seed)
    # Triples drawn in proportion to the cells' weights, the partners within a diameter of the
    # first (a visible arc is no wider): the first two of PARTNER_DRAWS weighted draws that are.
    prob = w / w.sum()
    first = rng.choice(n, p.ransac_iterations, p=prob)
    cand = rng.choice(n, (p.ransac_iterations, PARTNER_DRAWS), p=prob)
    d = np.hypot(q[cand, 0] - q[first, None, 0], q[cand, 1] - q[first, None, 1])
    near = (d < 2 * p.max_radius_m) & (d > p.key_cell_m)
    second = np.argmax(near, axis=1)
    near[np.arange(len(first)), second] = False
    third = np.argmax(near, axis=1)
    usable = near.any(axis=1)  # a second neighbour remained after taking the first
    first, second, third = first[usable], cand[usable, second[usable]], cand[usable, third[usable]]
    centres, radii = _circles(q[first], q[second], q[third])
    ok = np.isfinite(radii) & (radii >= p.min_radius_m) & (radii <= p.max_radius_m)
    if not ok.any():
        return None
    centres, radii = centres[ok], radii[ok]
    # Rank the candidates on at most SCORE_CELLS cells (an even spread): enough to rank them.
    k = max(1, n // SCORE_CELLS)
    scores = _score(q[::k], w[::k], centres, radii, cam, p.circle_band_m)
    best = int(np.argmax(scores))
    centre, radius = centres[best], float(radii[best])
    score = float(_score(q, w, centre[None], np.array([radius]), cam, p.circle_band_m)[0])
    for _ in range(2):  # refine on the arc's keys while that explains the keys better
        inl = _inliers(keys_xy, centre[None], np.array([radius]), cam, p.circle_band_m)[0]
        refined = _fit_circle(keys_xy[inl], centre, radius)
        if refined is None or not (p.min_radius_m <= refined[1] <= p.max_radius_m):
            break
        new = float(_score(q, w, refined[0][None], np.array([refined[1]]), cam, p.circle_band_m)[0])
        if new < score:
            break
        (centre, radius), score = refined, new
    inl = _inliers(keys_xy, centre[None], np.array([radius]), cam, p.circle_band_m)[0]
    return centre, radius, inl


def _fit_circle(
    q: np.ndarray, centre: np.ndarray, radius: float
) -> tuple[np.ndarray, float] | None:
    """Geometric least-squares circle (Gauss-Newton from the given one)."""
    if len(q) < 3:
        return None
    c, r = centre.astype(float).copy(), float(radius)
    for _ in range(10):
        d = q - c
        dist = np.hypot(d[:, 0], d[:, 1])
        if np.any(dist < 1e-9):
            return None
        res = dist - r
        J = np.column_stack([-d / dist[:, None], -np.ones(len(q))])
        step, *_ = np.linalg.lstsq(J, -res, rcond=None)
        c, r = c + step[:2], r + float(step[2])
        if np.abs(step).max() < 1e-6:
            break
    if not (np.all(np.isfinite(c)) and np.isfinite(r)):
        return None
    return c, r
