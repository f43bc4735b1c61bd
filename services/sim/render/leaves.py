"""Leaves drawn as one batch: every pixel of every leaf's rectangle in one set of arrays.

Why: the orchard's swaying leaves are redrawn every frame, about 200 small shapes, and drawing
them one at a time was mostly numpy's cost per call (half of all render time). The per-pixel
arithmetic here is the single-leaf path's own (``raycast.rays_local``, ``leaf_hits``,
``rotate``, ``unit``; ``shading.leaf_shade``, ``towards_camera``, ``irradiance``), fed with
each pixel's own leaf parameters instead of scalars, and the depth test keeps, per pixel, the
first of the nearest hits: what drawing the leaves in order with a strict ``t < z`` test keeps.
So a batch gives the same bits as drawing its leaves one by one (a test checks it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from services.sim.render.raycast import CamShape, Shape, leaf_hits, rays_local, rotate, unit
from services.sim.render.shading import (
    LightCam,
    Material,
    irradiance,
    leaf_shade,
    towards_camera,
)

F32 = np.float32
Rect = tuple[int, int, int, int]  # v0, v1, u0, u1 (end exclusive)


class Target(Protocol):
    rgb: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) float32
    label: np.ndarray  # (H, W) int32


@dataclass(frozen=True)
class LeafDraw:
    """One leaf to draw: its shape in the camera frame, material, pixels and label value."""

    shape: CamShape
    material: Material
    rect: Rect
    index: int


def batchable(cs: CamShape, m: Material) -> bool:
    """Leaves with the leaf texture and no specular lobe (every leaf the sim makes)."""
    return cs.shape == Shape.LEAF and m.texture == "leaf" and m.specular == 0


def draw_leaves(
    leaves: Sequence[LeafDraw],
    X: np.ndarray,
    Y: np.ndarray,
    near_m: float,
    light: LightCam,
    buf: Target,
) -> None:
    """Draw ``leaves`` into ``buf`` (depth-tested) as if one by one, in their order."""
    if not leaves:
        return
    W = buf.depth.shape[1]
    flat, counts = _pixels(leaves, W)
    per = _Spread(counts)
    Rt = per.rows(np.stack([lf.shape.R.T for lf in leaves]).astype(F32))  # (3, 3, n)
    o = per.rows(np.stack([lf.shape.origin_local for lf in leaves]).astype(F32))  # (3, n)
    L = per.rows(np.array([lf.shape.size[0] for lf in leaves]).astype(F32))
    w = per.rows(np.array([lf.shape.size[1] for lf in leaves]).astype(F32))
    x, y = X.reshape(-1)[flat], Y.reshape(-1)[flat]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        q = rays_local(Rt, x, y)
        hit, t = leaf_hits(o, q, L, w, near_m)
        ok = hit & (t < buf.depth.reshape(-1)[flat])
        win = _nearest_first(flat, t, ok)
    if win.size == 0:
        return
    v, u = np.divmod(flat[win], W)
    tw = t[win]
    buf.depth[v, u] = tw
    buf.label[v, u] = per.rows(np.array([lf.index for lf in leaves], np.int32), win)
    local = np.stack([o[i][win] + tw * q[i][win] for i in range(3)], axis=-1)
    buf.rgb[v, u] = _shade(leaves, per, win, local, x[win], y[win], light)


def _pixels(leaves: Sequence[LeafDraw], W: int) -> tuple[np.ndarray, np.ndarray]:
    """Flat pixel indices of every leaf's rectangle, leaf after leaf, and each leaf's count."""
    flats = [
        (np.arange(v0, v1)[:, None] * W + np.arange(u0, u1)[None, :]).reshape(-1)
        for v0, v1, u0, u1 in (lf.rect for lf in leaves)
    ]
    return np.concatenate(flats), np.array([len(f) for f in flats])


class _Spread:
    """Per-leaf values spread over the leaves' pixels (or the pixels ``at``), pixel axis last."""

    def __init__(self, counts: np.ndarray) -> None:
        self.counts = counts
        self.leaf = np.repeat(np.arange(len(counts)), counts)

    def rows(self, per_leaf: np.ndarray, at: np.ndarray | None = None) -> np.ndarray:
        by_leaf = np.moveaxis(per_leaf, 0, -1)  # small: one column per leaf
        if at is None:
            return np.repeat(by_leaf, self.counts, axis=-1)
        return np.take(by_leaf, self.leaf[at], axis=-1)


def _nearest_first(flat: np.ndarray, t: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Per pixel, the element with the smallest ``t`` among ``ok``, the earliest on ties (only
    pixels where leaves overlap need the sort)."""
    cand = np.flatnonzero(ok)
    f = flat[cand]
    shared = np.bincount(f)[f] > 1
    c = cand[shared]
    c = c[np.lexsort((c, t[c], flat[c]))]
    first = np.ones(c.size, bool)
    first[1:] = flat[c[1:]] != flat[c[:-1]]
    return np.concatenate([cand[~shared], c[first]])


def _shade(
    leaves: Sequence[LeafDraw],
    per: _Spread,
    win: np.ndarray,
    local: np.ndarray,
    xs: np.ndarray,
    ys: np.ndarray,
    light: LightCam,
) -> np.ndarray:
    """uint8 RGB of the winning pixels, as ``shading.shade`` gives a two-sided leaf."""
    R = per.rows(np.stack([lf.shape.R for lf in leaves]).astype(F32), win)
    n_local = np.zeros_like(local)
    n_local[:, 2] = 1
    n = unit(rotate(n_local, R))
    view = np.stack([xs, ys, np.ones_like(xs)], axis=1)
    n = towards_camera(n, view)
    base = per.rows(np.array([lf.material.rgb for lf in leaves], F32), win).T
    k = per.rows(np.array([lf.material.strength for lf in leaves]).astype(F32), win)
    rgb = base * leaf_shade(k, local)[:, None] * irradiance(n, light, True)[:, None]
    rgb = rgb * light.colour[None, :]
    return np.clip(rgb * F32(255) + F32(0.5), 0, 255).astype(np.uint8)
