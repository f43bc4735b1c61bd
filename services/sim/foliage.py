"""Leaves of the procedural tree: clusters, and the leaf cover asked for each fruit.

Leaf cover per fruit: ``none`` clears every leaf between the camera and the fruit, ``light``
keeps at most two of them, ``heavy`` adds a dense cluster just in front of the fruit. The lower
trunk is kept free of leaves in front of the camera (the paper's trunk mask assumes an
unoccluded trunk).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from services.sim.render.scene import rot_between
from services.sim.scenario import Scenario

if TYPE_CHECKING:
    from services.sim.world import Fruit, World

TRUNK_WINDOW_TOP_M = 1.3  # leaves in front of the trunk below this height are removed


@dataclass
class Leaf:
    centre: np.ndarray
    R: np.ndarray  # columns: length axis, width axis, normal
    half_length: float
    half_width: float
    rgb: tuple[float, float, float]
    cluster: int


def leaves(
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


def apply_cover(w: World, rng: np.random.Generator) -> None:
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
