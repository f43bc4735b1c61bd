"""Render objects of the scene: environment, tree, fruit (with their stems), robot links, hand."""

from __future__ import annotations

import numpy as np

from services.sim.physics import rot_of
from services.sim.render.raycast import Shape
from services.sim.render.scene import Prim, RenderObject, segment_cylinder
from services.sim.render.shading import Material
from services.sim.world import Fruit, World

I3 = np.eye(3)
SKIN_RGB = (0.87, 0.66, 0.55)
PEDUNCLE_RADIUS_M = 0.0035
TWIG_RADIUS_M = 0.004


def environment_objects(
    env: str,
    seed: int,
    floor_rgb: tuple[float, float, float] | None = None,
    wall_rgb: tuple[float, float, float] | None = None,
) -> list[RenderObject]:
    """The ground (and, in the lab, a wall behind the tree)."""
    floor = floor_rgb or ((0.52, 0.52, 0.55) if env == "lab" else (0.36, 0.38, 0.27))
    objs = [
        RenderObject(
            "ground",
            "ground",
            [
                Prim(
                    Shape.BOX,
                    (30, 30, 0.05),
                    I3,
                    np.array([0, 0, -0.05]),
                    Material(floor, "ground", seed=seed),
                )
            ],
        )
    ]
    if env == "lab":
        wall = wall_rgb or (0.82, 0.82, 0.8)
        objs.append(
            RenderObject(
                "wall",
                "wall",
                [
                    Prim(
                        Shape.BOX,
                        (0.05, 6, 2.5),
                        I3,
                        np.array([3.0, 0, 2.5]),
                        Material(wall, "wall", seed=seed),
                    )
                ],
            )
        )
    return objs


def sky(height: int, width: int, top=(0.55, 0.7, 0.92), bottom=(0.85, 0.9, 0.95)) -> np.ndarray:
    """A vertical sky gradient (uint8), the background where nothing is hit (depth invalid)."""
    a = np.linspace(0, 1, height, dtype=np.float32)[:, None, None]
    img = (1 - a) * np.asarray(top, np.float32) + a * np.asarray(bottom, np.float32)
    return np.broadcast_to(
        np.clip(img * 255 + 0.5, 0, 255).astype(np.uint8), (height, width, 3)
    ).copy()


def tree_objects(w: World) -> list[RenderObject]:
    """Trunk, branches and leaf clusters (still; swaying leaves: ``sway_objects``)."""
    bark = Material(w.bark_rgb, "bark", seed=w.seed)
    trunk = segment_cylinder(w.trunk.p0, w.trunk.p1, w.trunk.radius, bark)
    objs = [RenderObject("trunk", "trunk", [trunk])]
    for k, b in enumerate(w.branches):
        prim = segment_cylinder(b.p0, b.p1, b.radius, bark)
        objs.append(RenderObject(f"branch/{k}", "branch", [prim]))
    clusters: dict[int, list[Prim]] = {}
    for i, leaf in enumerate(w.leaves):
        clusters.setdefault(leaf.cluster, []).append(_leaf_prim(w, i))
    objs += [RenderObject(f"leaves/{k}", "leaf", clusters[k]) for k in sorted(clusters)]
    return objs


def _leaf_prim(w: World, i: int, offset: np.ndarray | None = None) -> Prim:
    leaf = w.leaves[i]
    c = leaf.centre if offset is None else leaf.centre + offset
    m = Material(leaf.rgb, "leaf", seed=w.seed + i)
    return Prim(Shape.LEAF, (leaf.half_length, leaf.half_width, 0.0), leaf.R, c, m)


def fruit_objects(
    f: Fruit, pos: np.ndarray, quat: tuple, attached: bool, stem_top_attached: np.ndarray, seed: int
) -> list[RenderObject]:
    """The fruit body, its peduncle and twig. Attached: peduncle from the fruit top to the stem
    top, twig from the branch to the stem top. Cut: the twig and the upper half of the
    peduncle stay on the tree, a stub goes with the fruit."""
    R = rot_of(quat)
    peel = Material(f.rgb, "peel", seed=seed + 101 * f.fruit_id, specular=0.22)
    stem = Material((0.33, 0.42, 0.16), "plain")
    version = (tuple(np.round(pos, 12)), tuple(quat))
    body = RenderObject(
        f"fruit/{f.fruit_id}",
        "fruit",
        [Prim(Shape.ELLIPSOID, f.semi_axes, R, np.asarray(pos, float), peel)],
        version=version,
        fruit_id=f.fruit_id,
    )
    top = np.asarray(pos) + R[:, 2] * f.semi_axes[2]
    if attached:
        stem_top = top + R[:, 2] * f.peduncle_length
        prims = [
            segment_cylinder(top, stem_top, PEDUNCLE_RADIUS_M, stem),
            segment_cylinder(f.twig_start, stem_top, TWIG_RADIUS_M, stem),
        ]
        return [body, RenderObject(f"stem/{f.fruit_id}", "stem", prims, version=version)]
    half = f.peduncle_length / 2
    stub = segment_cylinder(top, top + R[:, 2] * half * 0.8, PEDUNCLE_RADIUS_M, stem)
    kept = [
        segment_cylinder(
            stem_top_attached - np.array([0, 0, half]), stem_top_attached, PEDUNCLE_RADIUS_M, stem
        ),
        segment_cylinder(f.twig_start, stem_top_attached, TWIG_RADIUS_M, stem),
    ]
    return [
        body,
        RenderObject(f"stub/{f.fruit_id}", "stem", [stub], version=version),
        RenderObject(f"stem/{f.fruit_id}", "stem", kept, version="cut"),
    ]


def hand_objects(R: np.ndarray, p: np.ndarray, version: object) -> list[RenderObject]:
    """A hand-like occluder: palm, four fingers, a thumb and the forearm. ``R`` columns: x across
    the palm, y out of the palm, z along the fingers; ``p`` the palm centre."""
    skin = Material(SKIN_RGB, "plain")
    sleeve = Material((0.2, 0.25, 0.45), "plain")
    prims = [Prim(Shape.ELLIPSOID, (0.045, 0.016, 0.05), R, p, skin)]
    for k, dx in enumerate((-0.03, -0.01, 0.01, 0.03)):
        length = (0.065, 0.078, 0.074, 0.06)[k]
        base = p + R @ np.array([dx, 0, 0.04])
        prims.append(
            segment_cylinder(base, base + R @ np.array([dx * 0.15, 0, length]), 0.0085, skin)
        )
    tb = p + R @ np.array([0.04, 0, -0.01])
    prims.append(segment_cylinder(tb, tb + R @ np.array([0.045, 0, 0.035]), 0.01, skin))
    wrist = p + R @ np.array([0, 0, -0.045])
    prims.append(segment_cylinder(wrist, wrist + R @ np.array([0, 0, -0.09]), 0.028, skin))
    prims.append(
        segment_cylinder(
            wrist + R @ np.array([0, 0, -0.09]), wrist + R @ np.array([0, 0, -0.3]), 0.04, sleeve
        )
    )
    return [RenderObject("hand", "hand", prims, version=version, bakeable=False)]


ROBOT_PIECE_M = 0.1  # robot cylinders are drawn in pieces this long: tighter screen rectangles


def _pieces(size: tuple, Rl: np.ndarray, pl: np.ndarray) -> list[tuple[tuple, np.ndarray]]:
    """A long cylinder as shorter coaxial ones (the same solid: the inner caps are hidden)."""
    r, _, h = size
    n = max(1, int(np.ceil(2 * h / ROBOT_PIECE_M)))
    axis = Rl[:, 2]
    return [((r, r, h / n), pl + axis * (-h + h / n * (2 * i + 1))) for i in range(n)]


class RobotVisuals:
    """The robot's visual shapes from pybullet (so the picture is the URDF), posed per frame."""

    def __init__(self, pb: object, cid: int, robot: int, link_name: dict[int, str]) -> None:
        import pybullet

        self.shapes: dict[int, list[tuple[Shape, tuple, np.ndarray, np.ndarray, Material]]] = {}
        for v in pybullet.getVisualShapeData(robot, physicsClientId=cid):
            link, geom, dims = v[1], v[2], v[3]
            lp, lq, rgba = np.asarray(v[5]), v[6], v[7]
            if geom == pybullet.GEOM_BOX:
                shape, size = Shape.BOX, (dims[0] / 2, dims[1] / 2, dims[2] / 2)
            elif geom == pybullet.GEOM_CYLINDER:
                shape, size = Shape.CYLINDER, (dims[1], dims[1], dims[0] / 2)
            elif geom == pybullet.GEOM_SPHERE:
                shape, size = Shape.ELLIPSOID, (dims[0],) * 3
            else:
                continue
            m = Material((rgba[0], rgba[1], rgba[2]), "plain")
            Rl = rot_of(lq)
            parts = _pieces(size, Rl, lp) if shape == Shape.CYLINDER else [(size, lp)]
            for sz, p in parts:
                self.shapes.setdefault(link, []).append((shape, sz, Rl, p, m))
        self.links = sorted(self.shapes)
        self.link_name = link_name

    def objects(self, poses: list[tuple[tuple, tuple]]) -> list[RenderObject]:
        """Render objects for link poses given in ``self.links`` order."""
        out = []
        for link, (p, q) in zip(self.links, poses, strict=True):
            R, pw = rot_of(q), np.asarray(p)
            prims = [
                Prim(s, size, R @ Rl, pw + R @ pl, m) for s, size, Rl, pl, m in self.shapes[link]
            ]
            out.append(
                RenderObject(
                    f"robot/{self.link_name[link]}", "robot", prims, version=(tuple(p), tuple(q))
                )
            )
        return out


def sway_objects(w: World, offsets: dict[int, np.ndarray], version: object) -> list[RenderObject]:
    """Clusters with swaying leaves, split in two: ``leaves/<k>`` keeps the still leaves (it
    stays cached) and ``sway/<k>`` holds the displaced ones (redrawn every frame)."""
    clusters = {w.leaves[i].cluster for i in offsets}
    still: dict[int, list[Prim]] = {k: [] for k in clusters}
    moving: dict[int, list[Prim]] = {}
    for i, leaf in enumerate(w.leaves):
        if leaf.cluster not in clusters:
            continue
        if i in offsets:
            moving.setdefault(leaf.cluster, []).append(_leaf_prim(w, i, offsets[i]))
        else:
            still[leaf.cluster].append(_leaf_prim(w, i))
    out = [RenderObject(f"leaves/{k}", "leaf", still[k], version="split") for k in sorted(still)]
    out += [
        RenderObject(f"sway/{k}", "leaf", moving[k], version=version, bakeable=False)
        for k in sorted(moving)
    ]
    return out
