"""Procedural orange tree (seeded): trunk, branches to every fruit plus extra ones, leaf clusters
that partly hide fruit, and the fruit themselves. Pure geometry, no pybullet, no rendering.

Leaves and leaf cover: ``foliage.py``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from services.sim.foliage import Leaf, apply_cover, leaves
from services.sim.render.camera import head_camera_pose
from services.sim.scenario import (
    FruitSpec,
    RandomFruits,
    Scenario,
    ScenarioError,
    check_fruit_places,
)

BRANCH_SEGMENT_M = 0.12  # long branches are cut in pieces (tighter screen rectangles)
ROBOT_CLEARANCE_M = 0.05  # random fruit surface to the robot at HOME_RAD, at least


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
    foliage = leaves(sc, fruits, ends, rng)
    w = World(sc, seed, trunk, branches, fruits, foliage, _bark(rng))
    apply_cover(w, rng)
    return w


def random_fruits(
    sc: Scenario, rf: RandomFruits, placed: list[FruitSpec], rng: np.random.Generator
) -> list[FruitSpec]:
    """Fruit at random in the camera's view, refusing overlaps, the trunk, and the robot in its
    initial posture (a fruit inside an arm would be a contact from tick 0)."""
    from services.robot.clearance import distance_to_home_robot_m

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
            if distance_to_home_robot_m(p) < cand.radius_m + ROBOT_CLEARANCE_M:
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


def _bark(rng: np.random.Generator) -> tuple[float, float, float]:
    """Bark colour inside the paper's trunk mask (OpenCV H 10–20, S 70–130, V 80–140) once lit."""
    v = rng.uniform(0.54, 0.57)
    s = rng.uniform(0.38, 0.44)
    h = rng.uniform(28, 32) / 60  # hue 28–32° → OpenCV H 14–16
    lo = v * (1 - s)
    return (v, lo + (v - lo) * h, lo)
