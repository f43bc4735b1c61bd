"""Synthetic training data from the sim's renderer: random trees and scenes, domain-randomised.

Every frame draws a new scene (seeded by (seed, frame)): a tree (trunk, branches, leaf
density and size), 3–25 fruit 0.35–1.2 m in front of the camera with random leaf cover, colours
of fruit (some unripe), leaves and bark, texture strength per kind of surface, lab or orchard
background (wall and floor colours, a sky with distant foliage), lighting (direction, ambient,
strength, tint, exposure), the camera pose (±5–8 cm, ±8° yaw and pitch, ±4° roll around the
head camera), sometimes the arms (ready posture ± noise) and a hand in view; then blur (Gaussian
or motion), colour noise and the D435-like depth model. Boxes are the fruit's visible pixels
(truth), with the visible fraction.

Output (the format of shared/data/oranges_real, plus depth and visibility)::

    OUT/labels.json        [{"image": "images/synth_000000.png", "width": 640, "height": 480,
                             "boxes": [[x1, y1, x2, y2], ...], "visible_fraction": [...],
                             "depth": "depth/synth_000000.png", "T_world_camera": [16 floats]}]
    OUT/images/*.png       RGB
    OUT/depth/*.png        16-bit depth, millimetres, 0 = invalid
    OUT/intrinsics.json    the camera (camera_file reads the folder with color_glob images/*.png)
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from services.sim.render.camera import CameraModel, head_camera_pose
from services.sim.render.depth_noise import D435Noise
from services.sim.render.renderer import Renderer
from services.sim.render.scene import RenderObject
from services.sim.render.shading import Lighting
from services.sim.scenario import RandomFruits, Scenario, ScenarioError, TreeSpec
from services.sim.truth import fruit_pixels
from services.sim.world import World, build_world

MIN_VISIBLE_PX = 20  # fewer visible pixels than this: no box (nobody could label it)


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def random_scenario(rng: np.random.Generator, index: int) -> Scenario:
    tx, ty = _u(rng, 1.0, 1.5), _u(rng, -0.25, 0.25)
    tree = TreeSpec(
        trunk_xy_world_m=(tx, ty),
        trunk_radius_m=_u(rng, 0.04, 0.1),
        trunk_height_m=_u(rng, 1.7, 2.4),
        extra_branches=int(rng.integers(4, 15)),
        leaf_clusters=int(rng.integers(20, 80)),
        leaves_per_cluster=int(rng.integers(8, 24)),
        leaf_length_m=_u(rng, 0.05, 0.09),
        crown_center_world_m=(tx - _u(rng, 0.1, 0.35), ty + _u(rng, -0.1, 0.1), _u(rng, 1.3, 1.6)),
        crown_radii_m=(_u(rng, 0.35, 0.6), _u(rng, 0.45, 0.8), _u(rng, 0.35, 0.55)),
    )
    fruits = RandomFruits(
        count=int(rng.integers(3, 26)),
        depth_range_m=(0.35, 1.2),
        radius_range_m=(0.028, 0.052),
        heavy_cover_share=_u(rng, 0.0, 0.3),
        no_cover_share=_u(rng, 0.1, 0.5),
    )
    env = "lab" if rng.random() < 0.4 else "orchard"
    return Scenario(
        name=f"synth-{index}",
        seed=int(rng.integers(0, 2**31)),
        environment=env,  # type: ignore[arg-type]
        tree=tree,
        random_fruits=fruits,
    )


def _recolour(w: World, rng: np.random.Generator) -> None:
    for f in w.fruits:
        if rng.random() < 0.15:  # unripe: yellow-green
            f.rgb = (_u(rng, 0.6, 0.85), _u(rng, 0.6, 0.78), _u(rng, 0.08, 0.2))
        else:
            f.rgb = (_u(rng, 0.85, 1.0), _u(rng, 0.35, 0.62), _u(rng, 0.0, 0.12))
    gain = np.array([_u(rng, 0.7, 1.3), _u(rng, 0.75, 1.25), _u(rng, 0.7, 1.3)])
    for leaf in w.leaves:
        leaf.rgb = tuple(float(v) for v in np.clip(np.asarray(leaf.rgb) * gain, 0, 1))  # type: ignore[assignment]
    w.bark_rgb = (_u(rng, 0.3, 0.6), _u(rng, 0.22, 0.45), _u(rng, 0.15, 0.32))


def _restrength(objs: list[RenderObject], rng: np.random.Generator) -> list[RenderObject]:
    """Texture strength drawn per kind of surface (bark, peel, leaf, ground, wall)."""
    strength = {k: _u(rng, 0.3, 2.0) for k in ("bark", "peel", "leaf", "ground", "wall")}
    out = []
    for o in objs:
        prims = [
            dataclasses.replace(
                p,
                material=dataclasses.replace(
                    p.material, strength=strength.get(p.material.texture, 1.0)
                ),
            )
            for p in o.prims
        ]
        out.append(dataclasses.replace(o, prims=prims))
    return out


def _background(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Sky with distant foliage: a gradient plus low-frequency dark-green blobs."""
    from services.sim.visuals import sky

    top = (_u(rng, 0.4, 0.75), _u(rng, 0.55, 0.85), _u(rng, 0.75, 1.0))
    img = sky(h, w, top, (_u(rng, 0.7, 0.95),) * 3).astype(np.float32)
    blobs = rng.random((h // 32 + 2, w // 32 + 2)).astype(np.float32)
    import cv2

    field = cv2.resize(blobs, (w, h), interpolation=cv2.INTER_CUBIC)
    horizon = np.linspace(0, 1, h, dtype=np.float32)[:, None] ** 0.5
    mask = np.clip((field * horizon - _u(rng, 0.25, 0.6)) * 4, 0, 1)[..., None]
    green = np.array([_u(rng, 30, 70), _u(rng, 60, 110), _u(rng, 25, 60)], np.float32)
    return np.clip(img * (1 - mask) + green * mask, 0, 255).astype(np.uint8)


def _camera_pose(rng: np.random.Generator) -> np.ndarray:
    from services.robot.urdf import rot_x, rot_y, rot_z

    T = head_camera_pose()
    d = np.radians([_u(rng, -4, 4), _u(rng, -8, 8), _u(rng, -8, 8)])  # roll, pitch, yaw (optical)
    T[:3, :3] = T[:3, :3] @ rot_z(d[0]) @ rot_x(d[1]) @ rot_y(d[2])
    T[:3, 3] += [_u(rng, -0.05, 0.05), _u(rng, -0.08, 0.08), _u(rng, -0.08, 0.08)]
    return T


class _Robot:
    """The robot's visuals posed by pybullet forward kinematics (one client for the run)."""

    def __init__(self) -> None:
        import pybullet as pb

        from services.robot.model import URDF_PATH, all_joint_names
        from services.sim.visuals import RobotVisuals

        self.pb = pb
        self.cid = pb.connect(pb.DIRECT)
        self.body = pb.loadURDF(str(URDF_PATH), useFixedBase=True, physicsClientId=self.cid)
        info = [
            pb.getJointInfo(self.body, i, physicsClientId=self.cid)
            for i in range(pb.getNumJoints(self.body, physicsClientId=self.cid))
        ]
        self.joint = {i[1].decode(): i[0] for i in info}
        names = {i[0]: i[12].decode() for i in info} | {-1: "base_link"}
        self.vis = RobotVisuals(pb, self.cid, self.body, names)
        self.names = all_joint_names()

    def objects(self, rng: np.random.Generator) -> list[RenderObject]:
        from services.robot.model import HOME_RAD

        q = [v for r in ("cutter", "collector") for v in HOME_RAD[r]]
        for n, v in zip(self.names, q, strict=True):
            self.pb.resetJointState(
                self.body, self.joint[n], v + _u(rng, -0.15, 0.15), physicsClientId=self.cid
            )
        poses = []
        for link in self.vis.links:
            if link < 0:
                poses.append(
                    self.pb.getBasePositionAndOrientation(self.body, physicsClientId=self.cid)
                )
            else:
                s = self.pb.getLinkState(
                    self.body, link, computeForwardKinematics=True, physicsClientId=self.cid
                )
                poses.append((s[4], s[5]))
        return self.vis.objects(poses)

    def close(self) -> None:
        self.pb.disconnect(physicsClientId=self.cid)


def _postprocess(rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    import cv2

    out = rgb
    u = rng.random()
    if u < 0.5:
        out = cv2.GaussianBlur(out, (0, 0), _u(rng, 0.3, 1.5))
    elif u < 0.65:  # motion blur along a random direction
        n = int(rng.integers(3, 10))
        k = np.zeros((n, n), np.float32)
        a = _u(rng, 0, math.pi)
        c = (n - 1) / 2
        for t in np.linspace(-c, c, 2 * n):
            k[round(float(c + t * math.sin(a))), round(float(c + t * math.cos(a)))] = 1
        out = cv2.filter2D(out, -1, k / k.sum())
    sigma = _u(rng, 0.0, 6.0)
    noisy = out.astype(np.float32) + rng.normal(0, sigma, out.shape).astype(np.float32)
    return np.clip(noisy + 0.5, 0, 255).astype(np.uint8)


def synth_frame(seed: int, index: int, robot: _Robot) -> dict[str, Any]:
    """One randomised frame: rgb, depth (mm), boxes with visible fractions, camera pose."""
    from services.sim.visuals import environment_objects, fruit_objects, hand_objects, tree_objects

    rng = np.random.default_rng([seed, index])
    for _ in range(20):
        try:
            world = build_world(random_scenario(rng, index))
            break
        except ScenarioError:
            continue
    else:
        raise ScenarioError(f"frame {index}: could not place the random fruit")
    _recolour(world, rng)
    cam = CameraModel()
    T = _camera_pose(rng)
    env = world.scenario.environment
    floor = (_u(rng, 0.3, 0.65), _u(rng, 0.3, 0.6), _u(rng, 0.25, 0.55))
    wall = (_u(rng, 0.55, 0.95), _u(rng, 0.55, 0.95), _u(rng, 0.5, 0.95))
    objs = environment_objects(env, world.seed, floor, wall) + tree_objects(world)
    for f in world.fruits:
        objs += fruit_objects(f, f.centre, (0, 0, 0, 1), True, f.centre, world.seed)
    if rng.random() < 0.5:
        objs += robot.objects(rng)
    if rng.random() < 0.25 and world.fruits:
        f = world.fruits[int(rng.integers(len(world.fruits)))]
        cam_p = T[:3, 3]
        p = f.centre + (cam_p - f.centre) / np.linalg.norm(cam_p - f.centre) * _u(rng, 0.08, 0.25)
        p = p + T[:3, 0] * _u(rng, -0.06, 0.06) + np.array([0, 0, _u(rng, -0.08, 0.02)])
        from services.sim.timeline import facing_camera

        objs += hand_objects(facing_camera(p, cam_p), p, 0)
    objs = _restrength(objs, rng)
    light = Lighting(
        direction_world=(_u(rng, -1, 1), _u(rng, -1, 1), _u(rng, 0.2, 1.0)),
        ambient=_u(rng, 0.35, 0.8),
        diffuse=_u(rng, 0.2, 0.8),
        colour=(_u(rng, 0.9, 1.1), _u(rng, 0.9, 1.05), _u(rng, 0.85, 1.1)),
        exposure=_u(rng, 0.75, 1.25),
    )
    bg = _background(rng, cam.height, cam.width) if env == "orchard" else None
    out = Renderer(cam, T, light, bg, cache=False).render(objs)
    boxes, vis = [], []
    for f in world.fruits:
        fm = out.fruits.get(f.fruit_id)
        vf, box, _amodal, _hidden = fruit_pixels(out, fm)
        if box is not None and fm is not None and vf * fm.mask.sum() >= MIN_VISIBLE_PX:
            boxes.append([round(v, 1) for v in box])
            vis.append(round(vf, 4))
    rgb = _postprocess(out.rgb, rng)
    noise = D435Noise(cam.width, cam.height, cam.intrinsics.fx_px, seed=int(rng.integers(2**31)))
    depth = noise.depth_mm(out.depth_m, rgb, index)
    return {"rgb": rgb, "depth": depth, "boxes": boxes, "visible_fraction": vis, "T": T}


def synth(
    out: Path, frames: int, seed: int, progress: Callable[[int], None] | None = None
) -> list[dict[str, Any]]:
    """Write ``frames`` frames to ``out``; returns the label entries (also in labels.json)."""
    import cv2

    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "depth").mkdir(parents=True, exist_ok=True)
    cam = CameraModel()
    intr = cam.intrinsics.model_dump() | {"depth_unit_m": 0.001, "frame_id": "camera_optical"}
    (out / "intrinsics.json").write_text(json.dumps(intr, indent=1) + "\n")
    robot = _Robot()
    labels = []
    try:
        for i in range(frames):
            fr = synth_frame(seed, i, robot)
            name = f"synth_{i:06d}.png"
            cv2.imwrite(str(out / "images" / name), fr["rgb"][:, :, ::-1])
            cv2.imwrite(str(out / "depth" / name), fr["depth"])
            labels.append(
                {
                    "image": f"images/{name}",
                    "width": cam.width,
                    "height": cam.height,
                    "boxes": fr["boxes"],
                    "visible_fraction": fr["visible_fraction"],
                    "depth": f"depth/{name}",
                    "T_world_camera": [round(float(v), 9) for v in fr["T"].ravel()],
                }
            )
            if progress is not None:
                progress(i + 1)
    finally:
        robot.close()
    (out / "labels.json").write_text(json.dumps(labels) + "\n")
    return labels
