"""The renderer: ray-cast RGB, depth and a per-pixel object label, with a cache of still objects.

Why a cache: the camera is rigid on the torso, and most of the scene (trunk, branches, leaves,
hanging fruit, the robot body) does not move between frames. Objects whose ``version`` stayed
the same for ``bake_after`` frames are drawn once into cached buffers; a frame copies them and
draws only what moves (arms, falling fruit, the hand, swaying leaves) with a depth test. When a
cached object moves or vanishes, only its screen rectangle of the cache is redrawn. Since every
pixel is a pure function of the shapes (see raycast), cached and uncached frames are identical
(a test checks it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from services.sim.render.camera import CameraModel
from services.sim.render.leaves import LeafDraw, Rect, batchable, draw_leaves
from services.sim.render.raycast import CamShape, Shape, intersect, local_point, normals
from services.sim.render.scene import KINDS, RenderObject
from services.sim.render.shading import LightCam, Lighting, Material, light_in_camera, shade

F32 = np.float32
_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


@dataclass
class Buffers:
    rgb: np.ndarray  # (H, W, 3) uint8
    depth: np.ndarray  # (H, W) float32 metres, inf where nothing
    label: np.ndarray  # (H, W) int32 object index, -1 where nothing

    def copy(self) -> Buffers:
        return Buffers(self.rgb.copy(), self.depth.copy(), self.label.copy())

    def reset(self, r: Rect, background: np.ndarray) -> None:
        v0, v1, u0, u1 = r
        self.rgb[v0:v1, u0:u1] = background[v0:v1, u0:u1]
        self.depth[v0:v1, u0:u1] = np.inf
        self.label[v0:v1, u0:u1] = -1


@dataclass
class FruitMask:
    """Where a fruit body would cover the image if nothing hid it."""

    obj: int
    rect: Rect
    mask: np.ndarray  # bool over rect


@dataclass
class RenderOutput:
    rgb: np.ndarray
    depth_m: np.ndarray  # float32, 0 where no surface
    label: np.ndarray
    kind_of: np.ndarray  # int8 per object index → index into KINDS
    fruits: dict[int, FruitMask]  # fruit_id → mask
    drawn: int = 0  # shapes ray-cast this frame (for benchmarks)


@dataclass
class _Placed:
    """An object's shapes in the camera frame with their screen rectangles."""

    obj: RenderObject
    index: int
    shapes: list[tuple[CamShape, Material, Rect | None]]
    rect: Rect | None


@dataclass
class _Track:
    version: object
    still: int = 0


@dataclass
class _Stats:
    drawn: int = 0


@dataclass
class Renderer:
    camera: CameraModel
    T_world_camera: np.ndarray
    lighting: Lighting = field(default_factory=Lighting)
    background: np.ndarray | None = None  # (H, W, 3) uint8; None: mid grey
    cache: bool = True
    bake_after: int = 2

    def __post_init__(self) -> None:
        H, W = self.camera.height, self.camera.width
        self.T_cam_world = np.linalg.inv(self.T_world_camera)
        self.light: LightCam = light_in_camera(self.lighting, self.T_cam_world[:3, :3])
        if self.background is None:
            self.background = np.full((H, W, 3), 128, np.uint8)
        self._bg = self.background
        self._cache = Buffers(
            self._bg.copy(), np.full((H, W), np.inf, F32), np.full((H, W), -1, np.int32)
        )
        self._index: dict[str, int] = {}
        self._kinds: list[int] = []
        self._track: dict[str, _Track] = {}
        self._baked: dict[str, _Placed] = {}
        self._masks: dict[str, FruitMask] = {}
        self._stats = _Stats()

    # ---- public ----------------------------------------------------------------------------
    def render(self, objects: Sequence[RenderObject]) -> RenderOutput:
        self._stats = _Stats()
        keys = [o.key for o in objects]
        if len(set(keys)) != len(keys):
            raise ValueError("render objects must have unique keys")
        for o in objects:
            if o.key not in self._index:
                self._index[o.key] = len(self._kinds)
                self._kinds.append(KINDS.index(o.kind))
        self._update_cache(objects)
        out = self._cache.copy()
        leaves: list[LeafDraw] = []
        for o in objects:
            if o.key not in self._baked:
                placed = self._place(o)
                self._draw_object(placed, out, None, keep_mask=True, leaves=leaves)
        self._draw_leaves(leaves, out)
        depth = np.where(np.isfinite(out.depth), out.depth, F32(0))
        fruits = {
            o.fruit_id: self._masks[o.key]
            for o in objects
            if o.kind == "fruit" and o.fruit_id is not None and o.key in self._masks
        }
        return RenderOutput(
            out.rgb,
            depth,
            out.label,
            np.asarray(self._kinds, np.int8),
            fruits,
            self._stats.drawn,
        )

    def index_of(self, key: str) -> int | None:
        """The label value of object ``key`` (None if it was never drawn)."""
        return self._index.get(key)

    # ---- cache -----------------------------------------------------------------------------
    def _update_cache(self, objects: Sequence[RenderObject]) -> None:
        present = {o.key: o for o in objects}
        dirty: list[Rect] = []
        for key in list(self._baked):
            o = present.get(key)
            if o is None or o.version != self._baked[key].obj.version:
                rect = self._baked.pop(key).rect
                if rect is not None:
                    dirty.append(rect)
        for o in objects:
            tr = self._track.get(o.key)
            if tr is None or tr.version != o.version:
                self._track[o.key] = _Track(o.version)
            else:
                tr.still += 1
        for key in [k for k in self._track if k not in present]:
            del self._track[key]
            self._masks.pop(key, None)
        for r in dirty:
            self._repaint(r)
        if not self.cache:
            return
        leaves: list[LeafDraw] = []
        for o in objects:
            if (
                o.bakeable
                and o.key not in self._baked
                and self._track[o.key].still >= self.bake_after
            ):
                placed = self._place(o)
                self._draw_object(placed, self._cache, None, keep_mask=True, leaves=leaves)
                self._baked[o.key] = placed
        self._draw_leaves(leaves, self._cache)

    def _repaint(self, r: Rect) -> None:
        self._cache.reset(r, self._bg)
        leaves: list[LeafDraw] = []
        for placed in self._baked.values():
            if placed.rect is not None and _overlap(placed.rect, r) is not None:
                self._draw_object(placed, self._cache, r, keep_mask=False, leaves=leaves)
        self._draw_leaves(leaves, self._cache)

    # ---- drawing ---------------------------------------------------------------------------
    def _place(self, o: RenderObject) -> _Placed:
        shapes = []
        rect: Rect | None = None
        cams = [prim.in_camera(self.T_cam_world) for prim in o.prims]
        if o.kind == "leaf" and len(cams) > 1:
            rects = self._screen_rects(cams)
        else:
            rects = [self._screen_rect(cs) for cs in cams]
        for prim, cs, r in zip(o.prims, cams, rects, strict=True):
            shapes.append((cs, prim.material, r))
            if r is not None:
                rect = r if rect is None else _union(rect, r)
        return _Placed(o, self._index[o.key], shapes, rect)

    def _draw_object(
        self,
        placed: _Placed,
        buf: Buffers,
        clip: Rect | None,
        keep_mask: bool,
        leaves: list[LeafDraw],
    ) -> None:
        """Draw ``placed``'s shapes in order; leaves join ``leaves``, the batch the caller
        draws after the last object (any other shape draws the batch so far first, so the
        order of the draws, which decides depth ties, is kept)."""
        o = placed.obj
        want_mask = keep_mask and o.kind == "fruit" and placed.rect is not None
        acc = np.zeros(_shape(placed.rect), bool) if want_mask and placed.rect else None
        for cs, mat, r in placed.shapes:
            if r is None:
                continue
            rr = _overlap(r, clip) if clip is not None else r
            if rr is None:
                continue
            if acc is None and batchable(cs, mat):
                leaves.append(LeafDraw(cs, mat, rr, placed.index))
                continue
            self._draw_leaves(leaves, buf)
            self._draw_shape(cs, mat, rr, placed.index, buf, acc, placed.rect)
        if keep_mask and o.kind == "fruit":
            if acc is not None and placed.rect is not None:
                self._masks[o.key] = FruitMask(placed.index, placed.rect, acc)
            else:
                self._masks[o.key] = FruitMask(placed.index, (0, 0, 0, 0), np.zeros((0, 0), bool))

    def _draw_leaves(self, leaves: list[LeafDraw], buf: Buffers) -> None:
        """Draw the pending leaves as one batch (same bits as one by one) and empty the list."""
        if not leaves:
            return
        self._stats.drawn += len(leaves)
        X, Y = self.camera.rays
        draw_leaves(leaves, X, Y, self.camera.near_m, self.light, buf)
        leaves.clear()

    def _draw_shape(
        self,
        cs: CamShape,
        mat: Material,
        r: Rect,
        index: int,
        buf: Buffers,
        acc: np.ndarray | None,
        acc_rect: Rect | None,
    ) -> None:
        self._stats.drawn += 1
        v0, v1, u0, u1 = r
        X, Y = self.camera.rays
        Xr, Yr = X[v0:v1, u0:u1], Y[v0:v1, u0:u1]
        hit = intersect(cs, Xr, Yr, self.camera.near_m)
        if acc is not None and acc_rect is not None:
            a0, _, b0, _ = acc_rect
            acc[v0 - a0 : v1 - a0, u0 - b0 : u1 - b0] |= hit.mask
        zb = buf.depth[v0:v1, u0:u1]
        win = hit.mask & (hit.t < zb)
        if not win.any():
            return
        idx = np.nonzero(win)
        t = hit.t[idx]
        zb[idx] = t
        buf.label[v0:v1, u0:u1][idx] = index
        xs, ys = Xr[idx], Yr[idx]
        local = local_point(cs, xs, ys, t)
        n = normals(cs, local, hit.face[idx] if hit.face is not None else None)
        view = np.stack([xs, ys, np.ones_like(xs)], axis=1)
        rgb = shade(mat, local, n, view, self.light, two_sided=cs.shape == Shape.LEAF)
        buf.rgb[v0:v1, u0:u1][idx] = np.clip(rgb * F32(255) + F32(0.5), 0, 255).astype(np.uint8)

    def _screen_rect(self, cs: CamShape) -> Rect | None:
        """Pixels the shape can cover: projection of its bounding box's corners."""
        H, W = self.camera.height, self.camera.width
        corners = cs.p + (_CORNERS * cs.size) @ cs.R.T
        z = corners[:, 2]
        if z.max() <= self.camera.near_m:
            return None
        if z.min() <= self.camera.near_m:
            return (0, H, 0, W)
        uv = self.camera.project(corners)
        u0 = max(0, math.floor(uv[:, 0].min()))
        u1 = min(W, math.ceil(uv[:, 0].max()) + 1)
        v0 = max(0, math.floor(uv[:, 1].min()))
        v1 = min(H, math.ceil(uv[:, 1].max()) + 1)
        if u0 >= u1 or v0 >= v1:
            return None
        return (v0, v1, u0, u1)

    def _screen_rects(self, cams: list[CamShape]) -> list[Rect | None]:
        """``_screen_rect`` of many shapes at once (a cluster's leaves, redrawn every frame
        while they sway), a pixel wider on every side and tolerant at the near plane: the
        batch's sums may round apart from the one-shape product in the last bits, and a rect
        that is never narrower leaves every drawn pixel as it was (each is a function of its
        shape alone)."""
        H, W = self.camera.height, self.camera.width
        k, near = self.camera.intrinsics, self.camera.near_m
        R = np.stack([cs.R for cs in cams])
        p = np.stack([cs.p for cs in cams])
        size = np.stack([cs.size for cs in cams])
        corners = p[:, None, :] + np.einsum("ck,nk,njk->ncj", _CORNERS, size, R)
        z = corners[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = k.fx_px * corners[..., 0] / z + k.cx_px
            v = k.fy_px * corners[..., 1] / z + k.cy_px
        u0 = np.floor(u.min(1)) - 1
        u1 = np.ceil(u.max(1)) + 2
        v0 = np.floor(v.min(1)) - 1
        v1 = np.ceil(v.max(1)) + 2
        out: list[Rect | None] = []
        for zmin, zmax, a0, a1, b0, b1 in zip(
            z.min(1).tolist(),
            z.max(1).tolist(),
            v0.tolist(),
            v1.tolist(),
            u0.tolist(),
            u1.tolist(),
            strict=True,
        ):
            if zmax <= near - 1e-9:
                out.append(None)
            elif zmin <= near + 1e-9:
                out.append((0, H, 0, W))
            else:
                r = (max(0, int(a0)), min(H, int(a1)), max(0, int(b0)), min(W, int(b1)))
                out.append(r if r[0] < r[1] and r[2] < r[3] else None)
        return out


def _shape(r: Rect | None) -> tuple[int, int]:
    assert r is not None
    return (r[1] - r[0], r[3] - r[2])


def _union(a: Rect, b: Rect) -> Rect:
    return (min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3]))


def _overlap(a: Rect, b: Rect) -> Rect | None:
    r = (max(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), min(a[3], b[3]))
    return r if r[0] < r[1] and r[2] < r[3] else None
