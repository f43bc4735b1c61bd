"""Occupied space from the depth image (branches): bark-coloured points, neither the robot nor
near the selected fruit, binned in a world-frame voxel grid that persists across frames.

Why bark colour: in the sim only the trunk, the branches and the fruit are solid (leaves and
twigs have no collision shape in pybullet, so touching them is no collision), and the branches
share the trunk's bark colour. Leaves (green), fruit (orange), the robot and the grey background
are left out by colour; the robot's own bark-coloured shadows by its capsules.

Each voxel holding at least ``min_points`` of this frame's points is *seen*; its obstacle is a
sphere at the mean of the points it ever held. A voxel is forgotten when the depth image shows
space behind it for ``clear_frames`` consecutive frames (something moved away; depth beyond
``max_depth_m`` counts), or after ``forget_after_frames`` frames without a hit. A voxel hidden
behind an arm gets neither (the depth there is nearer than the voxel): it is remembered, which
is the point of persistence. A pixel with no valid depth (0, NaN, inf) is no evidence either
way, so a broken frame neither creates nor wipes obstacles.

Persistence is for what was there all along. A voxel born where one of the last
``history_frames`` frames, or one of the frames kept every ``history_every_frames`` for the
last ``history_long_frames`` of those, saw valid depth behind it is a *newcomer*: something
moved into free space (a hand: skin falls in the paper's bark HSV box). The sparse long memory
is for a hand that came where the recent frames could not see behind (the arms, or the hand
itself, in front: paper-exp1 seed 0, a hand's voxel 0.43 m ahead of the camera stayed for the
rest of the run, 235 mm from any branch, and read as a branch in the dish's way). It is an
obstacle while it is hit and is forgotten ``transient_forget_frames`` frames after its last
hit, hidden or not, unless it was hit in ``settle_hits`` frames (it stayed: a branch pushed
into a new place). A branch is never seen through before it is seen, only hidden (by a leaf, a
fruit, an arm), so it keeps persistence. Paper-exp1: the hand that swept 0.3 m ahead of the
camera left voxels the arms then hid; they held a cutter elbow at its damper distance, 25 cm
from any branch.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from schemas.scene import SphereObstacle
from services.robot.clearance import Capsule, within_reach
from services.scene.geometry import Pinhole, RigidTransform, vec3

BLANK_WINDOW_PX = 3  # bark this near a voxel's pixel: the branch may still stand there
# Kept depth cells (stride_px apart) either side of a new voxel's pixel searched for a view
# behind it: one pixel alone is often a hole (the stereo shadow left of a near fruit, where a
# hand then came: orchard seed 1, its thumb kept as a branch in the dish's way)
THROUGH_WINDOW = 2
SIGHT_SAMPLES = 150  # points along a line of sight (1.5 m at most: one a centimetre)


@dataclass(frozen=True)
class OccupancyParams:
    """Voxel grid settings (m, px, frames); see the scene Settings for their meaning."""

    voxel_m: float = 0.04
    sphere_radius_m: float = 0.03
    stride_px: int = 3
    max_depth_m: float = 1.6
    min_points: int = 3
    robot_margin_m: float = 0.04
    clear_frames: int = 3
    clear_margin_m: float = 0.06
    forget_after_frames: int = 900
    max_obstacles: int = 200
    history_frames: int = 15
    history_every_frames: int = 15
    history_long_frames: int = 60
    transient_forget_frames: int = 5
    settle_hits: int = 45
    blank_frames: int = 15
    # Voxels whose centre comes this near the robot's capsules are forgotten (None: kept). For
    # the unseen-fruit grid: the arms and the dish are fruit-coloured, so a frame without the
    # joint state to filter them leaves voxels on the robot that no later view clears.
    forget_in_robot_m: float | None = None


@dataclass
class Voxel:
    """One occupied voxel: the sum of its points (for their mean), and its hit bookkeeping."""

    sum_m: np.ndarray
    points: int
    last_hit_frame: int
    free_frames: int = 0
    blank_frames: int = 0  # frames since its last hit with no depth and no bark at its pixel
    newcomer: bool = False  # born where recent frames saw through: something moved in
    hits: int = 1

    @property
    def center_m(self) -> np.ndarray:
        return self.sum_m / self.points


@dataclass
class OccupancyGrid:
    """Persistent voxel grid of bark-coloured points (world frame); ``step`` once per frame."""

    p: OccupancyParams
    prefix: str = ""  # of its spheres' names: two grids' spheres never share a name
    voxels: dict[tuple[int, int, int], Voxel] = field(default_factory=dict)
    frame: int = 0
    # the last history_frames frames' depth (every stride_px-th pixel) with their camera, and
    # one frame in every history_every_frames of the last history_long_frames such
    history: deque[tuple[np.ndarray, Pinhole, RigidTransform]] = field(default_factory=deque)
    long_history: deque[tuple[np.ndarray, Pinhole, RigidTransform]] = field(default_factory=deque)

    def step(
        self,
        mask: np.ndarray,
        depth_m: np.ndarray,
        K: Pinhole,
        T: RigidTransform,
        robot: Sequence[Capsule],
        explained: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Take one frame: ``mask`` (H, W) bark-coloured pixels, ``depth_m`` (H, W) depth in m
        (0 / NaN / inf: invalid), the camera ``K`` and pose ``T``, the robot's capsules.
        ``explained``: world spheres (centres (N, 3), radii (N,), m) whose points are something
        else's; their points are left out and the voxels inside them forgotten."""
        self.frame += 1
        measured = np.isfinite(depth_m) & (depth_m > 0)
        valid = measured & (depth_m <= self.p.max_depth_m)
        # Depth beyond max_depth_m makes no obstacle, but it shows the space in front free: the
        # background behind a hand that swept past is often that far (paper-exp1: the hand's
        # voxels stayed in front of the arms for the rest of the run).
        self._clear(depth_m, measured, K, T)
        self._blank(mask, depth_m, measured, K, T, robot)
        pts = _points_world(mask & valid, depth_m, K, T, self.p.stride_px)
        if robot and len(pts):
            pts = pts[~_near_robot(pts, robot, self.p.robot_margin_m)]
        if robot and self.p.forget_in_robot_m is not None:
            margin_m = self.p.forget_in_robot_m
            self._forget_where(lambda c: _near_robot(c, robot, margin_m))
        if explained is not None and len(explained[1]):
            pts = pts[~_inside_any(pts, *explained)]
            self._forget_where(lambda c: _inside_any(c, *explained))
        self._hit(pts)
        old = [k for k, v in self.voxels.items() if self._expired(v)]
        for k in old:
            del self.voxels[k]
        self._remember(depth_m, measured, K, T)

    def _forget_where(self, hit: Callable[[np.ndarray], np.ndarray]) -> None:
        """Forget the voxels whose centre (N, 3) ``hit`` flags (N,)."""
        if not self.voxels:
            return
        keys = list(self.voxels)
        flagged = hit(np.array([self.voxels[k].center_m for k in keys]))
        for i in np.flatnonzero(flagged).tolist():
            del self.voxels[keys[i]]

    def _remember(
        self, depth_m: np.ndarray, measured: np.ndarray, K: Pinhole, T: RigidTransform
    ) -> None:
        """Keep this frame's depth for the newcomer test (recent, and sparse over long)."""
        s = self.p.stride_px
        seen = (np.where(measured[::s, ::s], depth_m[::s, ::s], 0.0).astype(np.float32), K, T)
        for memory, every, size in (
            (self.history, 1, self.p.history_frames),
            (self.long_history, self.p.history_every_frames, self.p.history_long_frames),
        ):
            if size and (self.frame - 1) % every == 0:  # the first frame is kept
                memory.append(seen)
            while len(memory) > size:
                memory.popleft()

    def _expired(self, v: Voxel) -> bool:
        unseen = self.frame - v.last_hit_frame
        if v.newcomer and v.hits < self.p.settle_hits:
            return unseen > self.p.transient_forget_frames
        return unseen > self.p.forget_after_frames

    def _seen_through(self, c_world: np.ndarray) -> bool:
        """Did a remembered frame see valid depth ``clear_margin_m`` behind this point? Then
        what is there now moved in (a hand; a branch is never seen through, only hidden)."""
        s = self.p.stride_px
        for depth, K, T in (*self.history, *self.long_history):
            c = T.to_camera(c_world)
            if c[2] <= 1e-3:
                continue
            u_px, v_px = K.project(c)
            u, v = round(u_px / s), round(v_px / s)
            w = THROUGH_WINDOW
            if not (-w <= v < depth.shape[0] + w and -w <= u < depth.shape[1] + w):
                continue
            win = depth[max(v - w, 0) : v + w + 1, max(u - w, 0) : u + w + 1]
            if (win > c[2] + self.p.clear_margin_m).any():
                return True
        return False

    def _hit(self, pts: np.ndarray) -> None:
        if not len(pts):
            return
        keys, inverse, counts = np.unique(
            np.floor(pts / self.p.voxel_m).astype(np.int64),
            axis=0,
            return_inverse=True,
            return_counts=True,
        )
        sums = np.zeros((len(keys), 3))
        np.add.at(sums, inverse.reshape(-1), pts)
        for k, s, n in zip(keys.tolist(), sums, counts.tolist(), strict=True):
            if n < self.p.min_points:
                continue
            key = (k[0], k[1], k[2])
            v = self.voxels.get(key)
            if v is None:
                self.voxels[key] = Voxel(
                    s.copy(), n, self.frame, newcomer=self._seen_through(s / n)
                )
            else:
                v.sum_m += s
                v.points += n
                v.hits += 1
                v.last_hit_frame, v.free_frames, v.blank_frames = self.frame, 0, 0

    def _blank(
        self,
        mask: np.ndarray,
        depth_m: np.ndarray,
        measured: np.ndarray,
        K: Pinhole,
        T: RigidTransform,
        robot: Sequence[Capsule],
    ) -> None:
        """Forget voxels whose pixel has shown no depth return and no bark that may stand at
        the voxel for ``blank_frames`` frames since their last hit, the robot not in the line
        of sight: what was there is gone and nothing stands behind it within the camera's range
        (a hand swept in front of the sky or a far wall; paper-exp1 seed 0, a hand's voxel
        stayed for the rest of the run, because nothing behind it ever gave depth). A branch in
        the stereo shadow of a nearer object still shows bark (no depth); one behind an arm has
        the arm in its line of sight. Bark measured ``clear_margin_m`` behind the voxel is a
        branch further back, no sign of one here (paper-exp1 seed 11: the hand that moved a
        fruit left a voxel 43 cm in front of a branch end whose bark edged its pixel; read as a
        branch under the fruit, it had the fruit given up as unreachable)."""
        if not self.voxels or self.p.blank_frames == 0:
            return
        keys = list(self.voxels)
        centres_m = np.array([self.voxels[k].center_m for k in keys])
        uv = _pixels(centres_m, K, T)
        z_m = T.to_camera(centres_m)[:, 2]
        w = BLANK_WINDOW_PX
        blank = []
        for i, (u, v) in enumerate(uv):
            if u < 0 or measured[v, u]:
                continue  # out of view, or depth there (the clearing rule's evidence)
            win = np.s_[max(v - w, 0) : v + w + 1, max(u - w, 0) : u + w + 1]
            behind = measured[win] & (depth_m[win] > z_m[i] + self.p.clear_margin_m)
            if (mask[win] & ~behind).any():
                self.voxels[keys[i]].blank_frames = 0  # bark seen there: it may stand there
                continue
            blank.append(i)
        if not blank:
            return
        behind_robot = _sight_blocked(
            T.t_m, np.array([self.voxels[keys[i]].center_m for i in blank]), robot
        )
        for i, hidden in zip(blank, behind_robot.tolist(), strict=True):
            if hidden:
                continue
            vox = self.voxels[keys[i]]
            vox.blank_frames += 1
            if vox.blank_frames >= self.p.blank_frames:
                del self.voxels[keys[i]]

    def _clear(self, depth_m: np.ndarray, valid: np.ndarray, K: Pinhole, T: RigidTransform) -> None:
        """Count a frame as free for each voxel whose centre's pixel sees valid depth clearly
        behind it; forget voxels free for ``clear_frames`` frames in a row."""
        if not self.voxels:
            return
        keys = list(self.voxels)
        c_cam = T.to_camera(np.array([self.voxels[k].center_m for k in keys]))
        z = c_cam[:, 2]
        front = z > 1e-3
        u = np.full(len(keys), -1)
        v = np.full(len(keys), -1)
        u[front] = np.round(K.fx * c_cam[front, 0] / z[front] + K.cx).astype(int)
        v[front] = np.round(K.fy * c_cam[front, 1] / z[front] + K.cy).astype(int)
        inside = front & (u >= 0) & (u < K.width) & (v >= 0) & (v < K.height)
        for i in np.flatnonzero(inside).tolist():
            if not valid[v[i], u[i]]:
                continue  # no evidence: keep the count as it is
            vox = self.voxels[keys[i]]
            if depth_m[v[i], u[i]] > z[i] + self.p.clear_margin_m:
                vox.free_frames += 1
                if vox.free_frames >= self.p.clear_frames:
                    del self.voxels[keys[i]]
            else:
                vox.free_frames = 0

    def obstacles(
        self,
        keep_out: Sequence[Capsule] = (),
        inside_cylinder: tuple[np.ndarray, float] | None = None,
    ) -> tuple[SphereObstacle, ...]:
        """Spheres at the voxels' point means, the ``max_obstacles`` most recently hit (then by
        voxel index: deterministic), without those whose surface comes within a keep-out capsule
        ((a, b, radius), m; a sphere where a == b: the selected fruit's working space) or whose
        centre is inside the vertical cylinder ``inside_cylinder`` ((axis point, radius), m: the
        trunk obstacle, which already guards that space)."""
        return self._spheres("occupied", False, keep_out, inside_cylinder)

    def within(
        self,
        keep_out: Sequence[Capsule],
        inside_cylinder: tuple[np.ndarray, float] | None = None,
    ) -> tuple[SphereObstacle, ...]:
        """The spheres ``obstacles`` leaves out for the keep-out capsules (those inside the
        trunk cylinder stay out: the trunk guards them), the most recently hit first, at most
        ``max_obstacles``: every branch seen near the selected fruit, for checking tool poses."""
        return self._spheres("near", True, keep_out, inside_cylinder)

    def _spheres(
        self,
        name: str,
        in_keep_out: bool,
        keep_out: Sequence[Capsule],
        inside_cylinder: tuple[np.ndarray, float] | None,
    ) -> tuple[SphereObstacle, ...]:
        """The voxels inside (``in_keep_out``) or outside the keep-out and outside the
        cylinder, as spheres ``<name>_<k>``, most recently hit first, at most max_obstacles."""
        voxels = [(-v.last_hit_frame, key, v.center_m) for key, v in self.voxels.items()]
        return keep_out_spheres(
            voxels,
            f"{self.prefix}{name}",
            self.p.sphere_radius_m,
            (in_keep_out, keep_out, inside_cylinder),
            self.p.max_obstacles,
        )


KeepOutTest = tuple[bool, Sequence[Capsule], tuple[np.ndarray, float] | None]


def keep_out_spheres(
    voxels: list[tuple[int, tuple[int, int, int], np.ndarray]],
    name: str,
    r: float,
    test: KeepOutTest,
    max_n: int,
    owners: Mapping[tuple[int, int, int], tuple[int, ...]] | None = None,
) -> tuple[SphereObstacle, ...]:
    """``voxels`` ((order, key, centre): the lowest order first, then by key) inside or outside
    the keep-out (``test``: (inside wanted, capsules, trunk cylinder); a sphere whose surface
    comes within a capsule is inside, one centred inside the cylinder is left out either way),
    as spheres ``<name>_<k>`` of radius ``r``, at most ``max_n``; ``owners`` gives a voxel's
    ``own_fruit_ids``."""
    in_keep_out, keep_out, inside_cylinder = test
    radii = np.array([kr for _a, _b, kr in keep_out])
    centres = np.array([c for _o, _k, c in voxels], float).reshape(-1, 3)
    take = within_reach(centres, keep_out, radii + r) == in_keep_out
    if inside_cylinder is not None:
        axis, radius = inside_cylinder
        take &= ~(np.hypot(centres[:, 0] - axis[0], centres[:, 1] - axis[1]) < radius)
    kept = [v for v, keep in zip(voxels, take, strict=True) if keep]
    kept.sort(key=lambda t: (t[0], t[1]))
    own = owners or {}
    return tuple(
        SphereObstacle(
            name=f"{name}_{i}", center_world_m=vec3(c), radius_m=r, own_fruit_ids=own.get(k, ())
        )
        for i, (_o, k, c) in enumerate(kept[:max_n])
    )


def _points_world(
    mask: np.ndarray, depth_m: np.ndarray, K: Pinhole, T: RigidTransform, stride_px: int
) -> np.ndarray:
    """(N, 3) world points of every ``stride_px``-th masked pixel, m."""
    sub = mask[::stride_px, ::stride_px]
    vs, us = np.nonzero(sub)
    vs, us = vs * stride_px, us * stride_px
    z = depth_m[vs, us]
    cam = np.stack([(us - K.cx) / K.fx * z, (vs - K.cy) / K.fy * z, z], axis=1)
    return T.to_world(cam)


def _pixels(c_world: np.ndarray, K: Pinhole, T: RigidTransform) -> np.ndarray:
    """(N, 2) integer pixels (u, v) of world points; (-1, -1) behind the camera or outside."""
    c = T.to_camera(c_world)
    out = np.full((len(c), 2), -1, dtype=int)
    front = c[:, 2] > 1e-3
    u = np.round(K.fx * c[front, 0] / c[front, 2] + K.cx).astype(int)
    v = np.round(K.fy * c[front, 1] / c[front, 2] + K.cy).astype(int)
    ok = (u >= 0) & (u < K.width) & (v >= 0) & (v < K.height)
    idx = np.flatnonzero(front)[ok]
    out[idx, 0], out[idx, 1] = u[ok], v[ok]
    return out


def _sight_blocked(cam: np.ndarray, targets: np.ndarray, robot: Sequence[Capsule]) -> np.ndarray:
    """(N,) whether the line of sight from ``cam`` to each target passes through a robot
    capsule (sampled every ~1 cm; the capsules are already generous)."""
    if not robot:
        return np.zeros(len(targets), dtype=bool)
    t = np.linspace(0.0, 1.0, SIGHT_SAMPLES)
    pts = cam + (targets[:, None, :] - cam) * t[None, :, None]  # (N, S, 3)
    near = _near_robot(pts.reshape(-1, 3), robot, 0.0).reshape(len(targets), -1)
    return np.asarray(near.any(axis=1), dtype=bool)


def _inside_any(pts: np.ndarray, centres_m: np.ndarray, radii_m: np.ndarray) -> np.ndarray:
    """(N,) points inside any of the spheres (centres (M, 3), radii (M,))."""
    if not len(pts):
        return np.zeros(0, dtype=bool)
    d = np.linalg.norm(pts[:, None, :] - centres_m[None, :, :], axis=2)
    return np.asarray((d < radii_m[None, :]).any(axis=1), dtype=bool)


def _near_robot(pts: np.ndarray, robot: Sequence[Capsule], margin_m: float) -> np.ndarray:
    """(N,) points within a capsule's radius plus ``margin_m`` of its axis."""
    near = np.zeros(len(pts), dtype=bool)
    for a, b, radius in robot:
        ab = b - a
        t = np.clip((pts - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
        d = np.linalg.norm(pts - (a + t[:, None] * ab), axis=1)
        near |= d < radius + margin_m
    return near
