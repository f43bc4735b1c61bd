"""Ray–shape intersection kernels, vectorised over the pixels of a screen rectangle.

Every ray starts at the camera centre with direction (X, Y, 1) in the optical frame, so the
ray parameter t of a hit *is* its depth z. A shape is given in the camera frame by its rotation
``R`` (columns: the shape's axes) and centre ``p``; its local ray is o + t·q with o = -Rᵀp and
q = Rᵀ(X, Y, 1). Only hits entering the solid in front of ``near`` count (a camera inside a
shape, e.g. inside its own housing, sees through it).

Per-pixel work is plain float32 arithmetic and sqrt (IEEE-exact), so results do not depend on
the size of the rectangle a pixel is computed in: a cached and a fresh render agree bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np

F32 = np.float32


class Shape(IntEnum):
    ELLIPSOID = 0  # size: semi-axes
    CYLINDER = 1  # size: (radius, radius, half length), axis = local z
    BOX = 2  # size: half extents
    LEAF = 3  # size: (half length along x, half width along y, 0); flat, normal = local z


@dataclass(frozen=True)
class CamShape:
    """A shape placed in the camera frame (float64 parameters, per-pixel maths in float32)."""

    shape: Shape
    size: np.ndarray  # (3,)
    R: np.ndarray  # (3, 3) camera ← local
    p: np.ndarray  # (3,) centre in the camera frame

    @property
    def origin_local(self) -> np.ndarray:
        return -(self.R.T @ self.p)


@dataclass
class Hit:
    """Hits of one shape in a rectangle: mask, depth, and what shading needs at the hits."""

    mask: np.ndarray  # bool (h, w)
    t: np.ndarray  # float32 (h, w), valid where mask
    face: np.ndarray | None = None  # int8 (h, w): which face was entered (cylinder/box)


def _local_dir(s: CamShape, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, ...]:
    return rays_local(s.R.T.astype(F32), X, Y)


def rays_local(Rt: np.ndarray, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, ...]:
    """Ray directions (X, Y, 1) in a shape's local frame, ``Rt`` = Rᵀ in float32: (3, 3), or
    (3, 3, n) with a rotation per pixel of 1-D X, Y (one formula, so the same bits)."""
    return tuple(Rt[i, 0] * X + Rt[i, 1] * Y + Rt[i, 2] for i in range(3))


def intersect(s: CamShape, X: np.ndarray, Y: np.ndarray, near: float) -> Hit:
    """Nearest entering hit of the rays (X, Y, 1) with shape ``s``."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if s.shape == Shape.ELLIPSOID:
            return _ellipsoid(s, X, Y, near)
        if s.shape == Shape.CYLINDER:
            return _cylinder(s, X, Y, near)
        if s.shape == Shape.BOX:
            return _box(s, X, Y, near)
        return _leaf(s, X, Y, near)


def _ellipsoid(s: CamShape, X: np.ndarray, Y: np.ndarray, near: float) -> Hit:
    M = (s.R / s.size[None, :]).T  # local unit-sphere coords ← camera
    o = -(M @ s.p)
    A = (M.T @ M).astype(F32)
    g = (M.T @ o).astype(F32)
    c = F32(o @ o - 1.0)
    a = (
        (A[0, 0] * X + F32(2) * A[0, 1] * Y + F32(2) * A[0, 2]) * X
        + (A[1, 1] * Y + F32(2) * A[1, 2]) * Y
        + A[2, 2]
    )
    b = g[0] * X + g[1] * Y + g[2]
    disc = b * b - a * c
    t = (-b - np.sqrt(disc)) / a
    return Hit(t > near, t)  # NaN (disc < 0) compares False


def _cylinder(s: CamShape, X: np.ndarray, Y: np.ndarray, near: float) -> Hit:
    r, h = F32(s.size[0]), F32(s.size[2])
    ox, oy, oz = (F32(v) for v in s.origin_local)
    qx, qy, qz = _local_dir(s, X, Y)
    a = qx * qx + qy * qy
    b = ox * qx + oy * qy
    c = ox * ox + oy * oy - r * r
    root = np.sqrt(b * b - a * c)
    t_in = (-b - root) / a  # entering the infinite cylinder
    t_out = (-b + root) / a
    s0 = (-h - oz) / qz
    s1 = (h - oz) / qz
    cap_in = np.minimum(s0, s1)
    cap_out = np.maximum(s0, s1)
    if c < 0:  # camera inside the infinite cylinder: only the caps can be entered
        t_in = np.full_like(X, -np.inf)
        t_out = np.full_like(X, np.inf)
    enter = np.maximum(t_in, cap_in)
    leave = np.minimum(t_out, cap_out)
    mask = (enter <= leave) & (enter > near)
    face = (cap_in > t_in).astype(np.int8)  # 1: a cap, 0: the side
    return Hit(mask, enter, face)


def _box(s: CamShape, X: np.ndarray, Y: np.ndarray, near: float) -> Hit:
    o = s.origin_local
    q = _local_dir(s, X, Y)
    enter = None
    leave = None
    face = np.zeros(X.shape, np.int8)
    for i in range(3):
        e = F32(s.size[i])
        t0 = (-e - F32(o[i])) / q[i]
        t1 = (e - F32(o[i])) / q[i]
        lo, hi = np.minimum(t0, t1), np.maximum(t0, t1)
        if enter is None or leave is None:
            enter, leave = lo, hi
            continue
        face[lo > enter] = i
        enter = np.maximum(enter, lo)
        leave = np.minimum(leave, hi)
    assert enter is not None and leave is not None
    return Hit((enter <= leave) & (enter > near), enter, face)


def _leaf(s: CamShape, X: np.ndarray, Y: np.ndarray, near: float) -> Hit:
    q = _local_dir(s, X, Y)
    o = s.origin_local.astype(F32)
    mask, t = leaf_hits(o, q, F32(s.size[0]), F32(s.size[1]), near)
    return Hit(mask, t)


def leaf_hits(
    o: np.ndarray, q: tuple[np.ndarray, ...], L: Any, w: Any, near: float
) -> tuple[np.ndarray, np.ndarray]:
    """A lanceolate leaf: |y| ≤ w·(1 - (x/L)²) in its plane (pointed at both ends). ``o``: the
    camera in the leaf's frame, (3,) or (3, n) per pixel, as ``L`` and ``w`` (float32)."""
    t = -o[2] / q[2]
    lx = (o[0] + t * q[0]) / L
    ly = o[1] + t * q[1]
    return (t > near) & (np.abs(ly) <= w * (F32(1) - lx * lx)), t


def local_point(s: CamShape, X: np.ndarray, Y: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Hit points in the shape's local frame, (n, 3) float32, for 1-D pixel arrays."""
    o = s.origin_local.astype(F32)
    q = _local_dir(s, X, Y)
    return np.stack([o[i] + t * q[i] for i in range(3)], axis=-1)


def normals(s: CamShape, local: np.ndarray, face: np.ndarray | None) -> np.ndarray:
    """Unit surface normals in the camera frame at local hit points (n, 3)."""
    if s.shape == Shape.ELLIPSOID:
        n_local = local / (s.size.astype(F32) ** 2)
    elif s.shape == Shape.CYLINDER:
        n_local = local.copy()
        n_local[:, 2] = 0
        if face is not None:
            cap = face == 1
            n_local[cap] = 0
            n_local[cap, 2] = np.sign(local[cap, 2])
    elif s.shape == Shape.BOX:
        n_local = np.zeros_like(local)
        assert face is not None
        idx = np.arange(len(local))
        n_local[idx, face] = np.sign(local[idx, face])
    else:
        n_local = np.zeros_like(local)
        n_local[:, 2] = 1
    return unit(rotate(n_local, s.R.astype(F32)))


def rotate(v: np.ndarray, R: np.ndarray) -> np.ndarray:
    """R @ v for rows v (n, 3), written out (no BLAS: identical rounding for any n)."""
    return np.stack(
        [R[i, 0] * v[:, 0] + R[i, 1] * v[:, 1] + R[i, 2] * v[:, 2] for i in range(3)], 1
    )


def dot(v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (n, 3) arrays, or with one (3,) vector."""
    if w.ndim == 1:
        return v[:, 0] * w[0] + v[:, 1] * w[1] + v[:, 2] * w[2]
    return v[:, 0] * w[:, 0] + v[:, 1] * w[:, 1] + v[:, 2] * w[:, 2]


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.sqrt(dot(v, v)), F32(1e-12))[:, None]
