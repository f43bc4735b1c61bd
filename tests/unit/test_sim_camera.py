"""The camera: pose from the URDF, projection of a known point, depth, the D435 noise model,
and the cache of the renderer (cached frames equal fresh ones)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from services.sim.render.camera import CameraModel, head_camera_pose
from services.sim.render.depth_noise import D435Noise
from services.sim.render.raycast import Shape
from services.sim.render.renderer import Renderer
from services.sim.render.scene import Prim, RenderObject
from services.sim.render.shading import Material
from tests.sim_helpers import core, run_ticks, scenario_file


def test_head_camera_pose_is_the_urdf_camera_optical_frame() -> None:
    import pybullet as pb

    from services.robot.model import URDF_PATH

    cid = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(str(URDF_PATH), useFixedBase=True, physicsClientId=cid)
        names = [pb.getJointInfo(body, i, physicsClientId=cid)[12].decode() for i in range(27)]
        s = pb.getLinkState(
            body, names.index("camera_optical"), computeForwardKinematics=True, physicsClientId=cid
        )
        R = np.array(pb.getMatrixFromQuaternion(s[5])).reshape(3, 3)
    finally:
        pb.disconnect(cid)
    T = head_camera_pose()
    np.testing.assert_allclose(T[:3, 3], s[4], atol=1e-6)
    np.testing.assert_allclose(T[:3, :3], R, atol=1e-5)  # URDF rpy has 6 digits
    assert T[:3, 2] @ [1, 0, 0] > 0.98  # optical z looks forward, x right (world -y), y down
    assert T[:3, 0] @ [0, -1, 0] > 0.99 and T[:3, 1] @ [0, 0, -1] > 0.98


@pytest.mark.parametrize("p_cam", [(0.0, 0.0, 0.6), (0.12, -0.07, 0.5), (-0.2, 0.1, 0.85)])
def test_a_known_point_lands_on_its_pixel_and_depth(p_cam: tuple[float, float, float]) -> None:
    """A 1 cm sphere at a known point: the centroid of its pixels is within 0.5 px of the
    projection, and the depth at the nearest pixel matches within 1 mm plus quantisation."""
    cam = CameraModel()
    T = head_camera_pose()
    p_world = T[:3, :3] @ np.array(p_cam) + T[:3, 3]
    r = 0.01
    obj = RenderObject(
        "s",
        "fruit",
        [Prim(Shape.ELLIPSOID, (r, r, r), np.eye(3), p_world, Material((1, 0.5, 0)))],
        fruit_id=0,
    )
    out = Renderer(cam, T, cache=False).render([obj])
    vs, us = np.nonzero(out.label == 0)
    u, v = cam.project(np.array(p_cam))
    assert abs(us.mean() - u) < 0.5 and abs(vs.mean() - v) < 0.5
    iu, iv = round(float(u)), round(float(v))
    x, y = (
        (iu - cam.intrinsics.cx_px) / cam.intrinsics.fx_px,
        (iv - cam.intrinsics.cy_px) / cam.intrinsics.fy_px,
    )
    d = np.array([x, y, 1.0])
    b, c = d @ np.array(p_cam), np.array(p_cam) @ np.array(p_cam) - r * r
    z_true = (b - np.sqrt(b * b - (d @ d) * c)) / (d @ d)  # ray–sphere, depth = t
    depth_mm = int(np.round(out.depth_m[iv, iu] * 1000))
    assert abs(depth_mm / 1000 - z_true) <= 0.001 + 0.0005


def test_d435_noise_grows_with_depth_squared_and_is_seeded() -> None:
    noise = D435Noise(640, 480, 612.41, seed=1, speckle_p=0.0)
    rgb = np.full((480, 640, 3), 128, np.uint8)
    for z in (0.5, 1.0, 2.0):
        depth = np.full((480, 640), z, np.float32)
        mm = noise.depth_mm(depth, rgb, frame=3).astype(float)
        sigma = (mm[mm > 0] / 1000 - z).std()
        assert abs(sigma - noise.sigma_m(z)) < 0.25 * noise.sigma_m(z) + 0.0004
    a = noise.depth_mm(depth, rgb, 7)
    assert np.array_equal(
        a, D435Noise(640, 480, 612.41, seed=1, speckle_p=0.0).depth_mm(depth, rgb, 7)
    )
    assert not np.array_equal(a, noise.depth_mm(depth, rgb, 8))


def test_near_objects_cast_a_stereo_shadow_to_their_left() -> None:
    noise = D435Noise(640, 480, 612.41, speckle_p=0.0)
    depth = np.full((480, 640), 2.0, np.float32)
    depth[:, 300:400] = 0.5  # a near post
    mm = noise.depth_mm(depth, np.full((480, 640, 3), 128, np.uint8), 0)
    shadow = 612.41 * 0.05 * (1 / 0.5 - 1 / 2.0)  # ≈ 46 px
    assert (mm[:, 300 - int(shadow) + 3 : 297] == 0).mean() > 0.95
    assert (mm[:, 420:600] > 0).mean() > 0.95


def test_cached_frames_equal_fresh_renders(tmp_path: Path) -> None:
    """Arms moving, leaves swaying, a hand passing: cached and uncached frames are identical."""
    sc = scenario_file(
        tmp_path,
        events=[
            {"kind": "hand_sweep", "start_s": 0.0, "duration_s": 0.5, "fruit": 0},
            {"kind": "sway_leaves", "start_s": 0.0, "duration_s": 2, "fruit": 0, "radius_m": 0.5},
        ],
    )
    frames = []
    for cache in (True, False):
        c = core(sc, render_cache=cache, depth_noise=False)
        outs = run_ticks(c, 40, {"cutter_j1": 0.4, "collector_j2": -0.3})
        outs += run_ticks(c, 24)  # arms still: they get cached
        outs += run_ticks(c, 16, {"cutter_j1": -0.4})  # and leave the cache again
        frames.append([(m.rgb.tobytes(), m.depth.tobytes()) for t, m in outs if t == "camera/rgbd"])
        c.close()
    assert len(frames[0]) == 10 and frames[0] == frames[1]


def test_the_trunk_falls_in_the_papers_hsv_mask() -> None:
    """The trunk's pixels are inside H 10–20, S 70–130, V 80–140 (OpenCV) and the fruit's not."""
    c = core("paper-exp1", depth_noise=False, rgb_noise_std=0.0)
    (frame, _truth), _ = c.emit()
    out = c.renderer.render(c.scene_objects())
    hsv = cv2.cvtColor(np.ascontiguousarray(frame[1].rgb), cv2.COLOR_RGB2HSV)
    mask = cv2.inRange(hsv, (10, 70, 80), (20, 130, 140)) > 0
    trunk = out.label == c.renderer.index_of("trunk")
    fruit = np.isin(out.kind_of[np.maximum(out.label, 0)], [4]) & (out.label >= 0)
    assert trunk.sum() > 2000
    assert mask[trunk].mean() > 0.9, mask[trunk].mean()
    assert mask[fruit].mean() < 0.02
    c.close()
