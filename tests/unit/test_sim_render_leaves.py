"""Leaves drawn as one batch give the bits of drawing them one by one: depth, label and colour,
over leaves that overlap, tie in depth, lie behind what is already drawn, or leave the image."""

from __future__ import annotations

import numpy as np
import pytest

from services.sim.render.camera import CameraModel, head_camera_pose
from services.sim.render.leaves import LeafDraw, draw_leaves
from services.sim.render.raycast import Shape
from services.sim.render.renderer import Buffers, Renderer
from services.sim.render.scene import Prim, RenderObject
from services.sim.render.shading import Material


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def _leaves(rng: np.random.Generator, T_world_camera: np.ndarray, n: int) -> list[Prim]:
    """Leaves 0.3–0.9 m in front of the camera, some twice (the same shape: equal depths)."""
    prims = []
    for i in range(n):
        p_cam = np.array([rng.uniform(-0.25, 0.25), rng.uniform(-0.2, 0.2), rng.uniform(0.3, 0.9)])
        p = T_world_camera[:3, :3] @ p_cam + T_world_camera[:3, 3]
        m = Material(tuple(rng.uniform(0.1, 0.6, 3)), "leaf", seed=i)
        size = (rng.uniform(0.02, 0.06), rng.uniform(0.008, 0.02), 0.0)
        prims.append(Prim(Shape.LEAF, size, _random_rotation(rng), p, m))
        if i % 7 == 0:
            prims.append(prims[-1])
    return prims


def _one_by_one(r: Renderer, draws: list[LeafDraw], buf: Buffers) -> None:
    for d in draws:
        r._draw_shape(d.shape, d.material, d.rect, d.index, buf, None, None)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_batch_of_leaves_equals_drawing_them_one_by_one(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cam, T = CameraModel(), head_camera_pose()
    r = Renderer(cam, T, cache=False)
    # something already drawn: a wall across part of the view at 0.6 m
    wall = RenderObject(
        "wall",
        "wall",
        [
            Prim(
                Shape.BOX,
                (0.2, 0.2, 0.01),
                T[:3, :3],
                T[:3, :3] @ [0.1, 0, 0.6] + T[:3, 3],
                Material((0.5, 0.5, 0.5)),
            )
        ],
    )
    base = r.render([wall])
    draws = []
    for k, prim in enumerate(_leaves(rng, T, 60)):
        cs = prim.in_camera(r.T_cam_world)
        rect = r._screen_rect(cs)
        if rect is not None:
            draws.append(LeafDraw(cs, prim.material, rect, index=10 + k % 5))
    assert len(draws) > 50
    bufs = [
        Buffers(
            base.rgb.copy(),
            np.where(base.depth_m > 0, base.depth_m, np.inf).astype(np.float32),
            base.label.copy(),
        )
        for _ in range(2)
    ]
    _one_by_one(r, draws, bufs[0])
    X, Y = cam.rays
    draw_leaves(draws, X, Y, cam.near_m, r.light, bufs[1])
    a, b = bufs
    assert np.array_equal(a.depth, b.depth)
    assert np.array_equal(a.label, b.label)
    assert np.array_equal(a.rgb, b.rgb)
    drawn = np.isin(a.label, np.arange(10, 15))
    assert drawn.sum() > 2000  # the leaves were seen, over and behind the wall
    assert (base.label[drawn] == 0).any()


def test_renders_with_leaves_in_several_objects_keep_the_order_of_the_draws() -> None:
    """Leaves, a fruit between them and more leaves: the batch is drawn before the fruit, and
    the leaves' rectangles (computed together) hold every pixel of each leaf's own, so a frame
    equals one in which every shape was drawn alone in its own rectangle."""
    rng = np.random.default_rng(5)
    cam, T = CameraModel(), head_camera_pose()
    leaves = _leaves(rng, T, 30)
    fruit_p = T[:3, :3] @ [0.0, 0.0, 0.5] + T[:3, 3]
    objs = [
        RenderObject("a", "leaf", leaves[:15], bakeable=False),
        RenderObject(
            "f",
            "fruit",
            [
                Prim(
                    Shape.ELLIPSOID,
                    (0.04, 0.04, 0.05),
                    np.eye(3),
                    fruit_p,
                    Material((0.9, 0.5, 0.1), "peel", specular=0.2),
                )
            ],
            fruit_id=3,
        ),
        RenderObject("b", "leaf", leaves[15:], bakeable=False),
    ]
    out = Renderer(cam, T, cache=False).render(objs)
    r = Renderer(cam, T, cache=False)
    r.render(objs)  # the same indices
    H, W = cam.height, cam.width
    buf = Buffers(
        np.full((H, W, 3), 128, np.uint8),
        np.full((H, W), np.inf, np.float32),
        np.full((H, W), -1, np.int32),
    )
    for o in objs:
        index = r.index_of(o.key)
        assert index is not None
        for prim in o.prims:  # each shape alone, in its own rectangle
            cs = prim.in_camera(r.T_cam_world)
            rect = r._screen_rect(cs)
            if rect is not None:
                r._draw_shape(cs, prim.material, rect, index, buf, None, None)
    assert np.array_equal(out.rgb, buf.rgb)
    assert np.array_equal(out.label, buf.label)
    assert np.array_equal(out.depth_m, np.where(np.isfinite(buf.depth), buf.depth, 0))
    assert (out.label == 1).sum() > 100
