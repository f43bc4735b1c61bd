"""Procedural orange tree (seeded): trunk, branches to every fruit plus extra ones, leaf clusters
that partly hide fruit, and the fruit themselves. Pure geometry, no pybullet, no rendering.

Leaf cover per fruit: ``none`` clears every leaf between the camera and the fruit, ``light``
keeps at most two of them, ``heavy`` adds a dense cluster just in front of the fruit. The lower
trunk is kept free of leaves in front of the camera (the paper's trunk mask assumes an
unoccluded trunk).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from services.sim.render.camera import head_camera_pose
from services.sim.render.scene import rot_between
from services.sim.scenario import (
    FruitSpec,
    RandomFruits,
    Scenario,
    ScenarioError,
    check_fruit_places,
)

TRUNK_WINDOW_TOP_M = 1.3  # leaves in front of the trunk below this height are removed
BRANCH_SEGMENT_M = 0.12  # long branches are cut in pieces (tighter screen rectangles)


@dataclass(frozen=True)
class Cyl:
    """A capped cylinder from p0 to p1."""

    p0: np.ndarray
    p1: np.ndarray
    radius: float


@dataclass
class Fruit:
    """One fruit as built: its hanging pose and how it hangs."""

    fruit_id: int
    centre: np.ndarray
    semi_axes: tuple[float, float, float]  # (d_h, d_h, d_v) along fruit x, y, z (z up)
    peduncle_length: float
    twig_start: np.ndarray  # where its twig leaves the branch
    rgb: tuple[float, float, float]
    leaf_cover: str

    @property
    def top(self) -> np.ndarray:
        return self.centre + np.array([0.0, 0.0, self.semi_axes[2]])


@dataclass
class Leaf:
    centre: np.ndarray
    R: np.ndarray  # columns: length axis, width axis, normal
    half_length: float
    half_width: float
    rgb: tuple[float, float, float]
    cluster: int


@dataclass
class World:
    scenario: Scenario
    seed: int
    trunk: Cyl
    branches: list[Cyl]
    fruits: list[Fruit]
    leaves: list[Leaf]
    bark_rgb: tuple[float, float, float]
    camera_world_m: np.ndarray = field(default_factory=lambda: head_camera_pose()[:3, 3])


def build_world(sc: Scenario, seed: int | None = None, fruit_count: int | None = None) -> World:
    """The tree of scenario ``sc``; ``seed`` and ``fruit_count`` override the file's values."""
    seed = sc.seed if seed is None else seed
    rng = np.random.default_rng([seed, 1])
    specs = list(sc.fruits)
    if sc.random_fruits is not None or fruit_count is not None:
        rf = sc.random_fruits or RandomFruits(count=fruit_count or 1)
        if fruit_count is not None:
            rf = rf.model_copy(update={"count": fruit_count})
            specs = []
        specs += random_fruits(sc, rf, specs, rng)
    t = sc.tree
    trunk = Cyl(
        np.array([*t.trunk_xy_world_m, 0.0]),
        np.array([*t.trunk_xy_world_m, t.trunk_height_m]),
        t.trunk_radius_m,
    )
    fruits = [_fruit(i, f, trunk, rng) for i, f in enumerate(specs)]
    branches: list[Cyl] = []
    for f in fruits:
        branches += _branch(trunk, f.twig_start, rng)
    ends = []
    for _ in range(t.extra_branches):
        segs = _extra_branch(trunk, rng)
        branches += segs
        ends.append(segs[-1].p1)
    leaves = _leaves(sc, fruits, ends, rng)
    w = World(sc, seed, trunk, branches, fruits, leaves, _bark(rng))
    _apply_cover(w, rng)
    return w


def random_fruits(
    sc: Scenario, rf: RandomFruits, placed: list[FruitSpec], rng: np.random.Generator
) -> list[FruitSpec]:
    """Fruit at random in the camera's view, refusing overlaps and the trunk."""
    T = head_camera_pose()
    out: list[FruitSpec] = []
    for _ in range(rf.count):
        for _attempt in range(2000):
            z = rng.uniform(*rf.depth_range_m)
            p_cam = np.array([rng.uniform(-0.3, 0.3) * z, rng.uniform(-0.2, 0.2) * z, z])
            p = T[:3, :3] @ p_cam + T[:3, 3]
            u = rng.random()
            cover = (
                "heavy"
                if u < rf.heavy_cover_share
                else "none"
                if u < rf.heavy_cover_share + rf.no_cover_share
                else "light"
            )
            cand = FruitSpec(
                position_world_m=(float(p[0]), float(p[1]), float(p[2])),
                radius_m=float(rng.uniform(*rf.radius_range_m)),
                leaf_cover=cover,  # type: ignore[arg-type]
            )
            try:
                check_fruit_places(sc.tree, (*placed, *out, cand), "random_fruits")
            except ValueError:
                continue
            if all(
                math.dist(cand.position_world_m, g.position_world_m) > 0.11 for g in (*placed, *out)
            ):
                out.append(cand)
                break
        else:
            raise ScenarioError(f"random_fruits: cannot place {rf.count} fruit without overlaps")
    return out


def _fruit(i: int, f: FruitSpec, trunk: Cyl, rng: np.random.Generator) -> Fruit:
    c = np.asarray(f.position_world_m, float)
    v = f.radius_m * f.height_ratio
    stem_top = c + np.array([0, 0, v + f.peduncle_length_m])
    to_trunk = trunk.p0[:2] - c[:2]
    to_trunk /= max(np.linalg.norm(to_trunk), 1e-9)
    d = np.array([0.6 * to_trunk[0], 0.6 * to_trunk[1], 0.8]) + rng.normal(0, 0.15, 3)
    twig_start = stem_top + d / np.linalg.norm(d) * rng.uniform(0.03, 0.06)
    rgb = (rng.uniform(0.88, 0.97), rng.uniform(0.42, 0.58), rng.uniform(0.03, 0.1))
    return Fruit(
        i, c, (f.radius_m, f.radius_m, v), f.peduncle_length_m, twig_start, rgb, f.leaf_cover
    )


def _path(points: list[np.ndarray], r0: float, r1: float) -> list[Cyl]:
    """Cylinders along a polyline, radius tapering r0 → r1, long pieces split."""
    pts = [points[0]]
    for a, b in itertools.pairwise(points):
        n = max(1, math.ceil(np.linalg.norm(b - a) / BRANCH_SEGMENT_M))
        pts += [a + (b - a) * (k / n) for k in range(1, n + 1)]
    out = []
    for k, (a, b) in enumerate(itertools.pairwise(pts)):
        r = r0 + (r1 - r0) * (k + 0.5) / (len(pts) - 1)
        ext = (b - a) / max(np.linalg.norm(b - a), 1e-9) * r * 0.5  # overlap at the bends
        out.append(Cyl(a - ext, b + ext, float(r)))
    return out


def _branch(trunk: Cyl, end: np.ndarray, rng: np.random.Generator) -> list[Cyl]:
    z = float(np.clip(end[2] - rng.uniform(0.05, 0.3), 0.5, trunk.p1[2] - 0.1))
    start = np.array([trunk.p0[0], trunk.p0[1], z])
    d = end - start
    side = np.cross(d, [0, 0, 1.0])
    side /= max(np.linalg.norm(side), 1e-9)
    p1 = start + d / 3 + side * rng.normal(0, 0.03) + np.array([0, 0, rng.uniform(0, 0.05)])
    p2 = start + 2 * d / 3 + side * rng.normal(0, 0.03) + np.array([0, 0, rng.uniform(0, 0.04)])
    r0 = min(0.025, trunk.radius * 0.45)
    return _path([start, p1, p2, end], r0, 0.007)


def _extra_branch(trunk: Cyl, rng: np.random.Generator) -> list[Cyl]:
    z = rng.uniform(0.8, trunk.p1[2] - 0.15)
    az = rng.uniform(0, 2 * math.pi)
    tilt = rng.uniform(0.2, 0.8)
    length = rng.uniform(0.35, 0.7)
    d = np.array([math.cos(az) * math.cos(tilt), math.sin(az) * math.cos(tilt), math.sin(tilt)])
    start = np.array([trunk.p0[0], trunk.p0[1], z])
    mid = start + d * length * 0.5 + rng.normal(0, 0.03, 3)
    return _path([start, mid, start + d * length], min(0.022, trunk.radius * 0.4), 0.006)


def _leaves(
    sc: Scenario, fruits: list[Fruit], ends: list[np.ndarray], rng: np.random.Generator
) -> list[Leaf]:
    t = sc.tree
    centres = [f.twig_start + np.array([0, 0, 0.05]) for f in fruits] + list(ends)
    counts = [max(3, t.leaves_per_cluster // 2)] * len(fruits) + [t.leaves_per_cluster] * len(ends)
    cc, cr = np.asarray(t.crown_center_world_m), np.asarray(t.crown_radii_m)
    for _ in range(t.leaf_clusters):
        u = rng.normal(size=3)
        u *= rng.random() ** (1 / 3) / np.linalg.norm(u)
        centres.append(cc + u * cr)
        counts.append(t.leaves_per_cluster)
    leaves: list[Leaf] = []
    for k, (c, n) in enumerate(zip(centres, counts, strict=True)):
        for _ in range(n):
            leaves.append(_leaf(c + rng.normal(0, 0.05, 3), t.leaf_length_m, k, rng))
    return leaves


def _leaf(
    centre: np.ndarray,
    length: float,
    cluster: int,
    rng: np.random.Generator,
    facing: np.ndarray | None = None,
) -> Leaf:
    normal = rng.normal(size=3) + (np.array([0, 0, 0.6]) if facing is None else facing * 1.5)
    R = rot_between(np.array([0, 0, 1.0]), normal)
    a = rng.uniform(0, 2 * math.pi)
    Rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    L = length * rng.uniform(0.75, 1.2) / 2
    g = rng.uniform(0.8, 1.15)
    rgb = (0.17 * g, rng.uniform(0.3, 0.45) * g, rng.uniform(0.07, 0.14) * g)
    return Leaf(centre, R @ Rz, L, L * rng.uniform(0.32, 0.42), rgb, cluster)


def _in_front(w: World, f: Fruit, leaf: Leaf) -> bool:
    """Leaf between the camera and the fruit (within the fruit's silhouette plus a leaf)."""
    cam = w.camera_world_m
    ray = f.centre - cam
    dist = float(np.linalg.norm(ray))
    ray /= dist
    s = float((leaf.centre - cam) @ ray)
    perp = float(np.linalg.norm(leaf.centre - cam - s * ray))
    return 0 < s < dist + f.semi_axes[0] and perp < f.semi_axes[0] + leaf.half_length * 0.9


def _apply_cover(w: World, rng: np.random.Generator) -> None:
    cam = w.camera_world_m
    tr = w.trunk
    keep: list[Leaf] = []
    in_front_kept: dict[int, int] = {}
    to_trunk = tr.p0[:2] - cam[:2]
    dist_trunk = float(np.linalg.norm(to_trunk))
    to_trunk /= dist_trunk
    for leaf in w.leaves:
        rel = leaf.centre[:2] - cam[:2]
        along = float(rel @ to_trunk)
        across = abs(float(rel[0] * to_trunk[1] - rel[1] * to_trunk[0]))
        if leaf.centre[2] < TRUNK_WINDOW_TOP_M and along < dist_trunk and across < tr.radius + 0.08:
            continue
        ok = True
        for f in w.fruits:
            if np.linalg.norm(leaf.centre - f.centre) < f.semi_axes[0] + leaf.half_length * 0.6:
                ok = False  # would cut through the fruit
            elif _in_front(w, f, leaf):
                n = in_front_kept.get(f.fruit_id, 0)
                if f.leaf_cover == "light" and n < 2 and rng.random() < 0.5:
                    in_front_kept[f.fruit_id] = n + 1
                else:
                    ok = False
        if ok:
            keep.append(leaf)
    cluster = max((lf.cluster for lf in w.leaves), default=0) + 1
    for f in w.fruits:
        if f.leaf_cover == "heavy":
            keep += _heavy_cover(w, f, cluster, rng)
            cluster += 1
    w.leaves = keep


def _heavy_cover(w: World, f: Fruit, cluster: int, rng: np.random.Generator) -> list[Leaf]:
    cam = w.camera_world_m
    ray = f.centre - cam
    dist = float(np.linalg.norm(ray))
    ray /= dist
    base = cam + ray * (dist - f.semi_axes[0] - 0.045)
    side = np.cross(ray, [0, 0, 1.0])
    side /= np.linalg.norm(side)
    up = np.cross(side, ray)
    out = []
    r = f.semi_axes[0]
    for _ in range(12):
        off = side * rng.uniform(-1.1, 1.1) * r + up * rng.uniform(-1.1, 1.1) * r
        c = base + off + ray * rng.uniform(-0.015, 0.015)
        out.append(_leaf(c, w.scenario.tree.leaf_length_m, cluster, rng, facing=-ray))
    return out


def _bark(rng: np.random.Generator) -> tuple[float, float, float]:
    """Bark colour inside the paper's trunk mask (OpenCV H 10–20, S 70–130, V 80–140) once lit."""
    v = rng.uniform(0.54, 0.57)
    s = rng.uniform(0.38, 0.44)
    h = rng.uniform(28, 32) / 60  # hue 28–32° → OpenCV H 14–16
    lo = v * (1 - s)
    return (v, lo + (v - lo) * h, lo)
