"""What the renderer draws: primitives grouped into objects with a kind, a key and a version."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from services.sim.render.raycast import CamShape, Shape
from services.sim.render.shading import Material

Kind = Literal[
    "trunk", "branch", "twig", "leaf", "fruit", "stem", "robot", "hand", "ground", "wall"
]
KINDS: tuple[Kind, ...] = (
    "trunk",
    "branch",
    "twig",
    "leaf",
    "fruit",
    "stem",
    "robot",
    "hand",
    "ground",
    "wall",
)


@dataclass(frozen=True)
class Prim:
    """One analytic shape in the world frame: rotation (columns = local axes), centre, size."""

    shape: Shape
    size: tuple[float, float, float]
    R: np.ndarray
    p: np.ndarray
    material: Material

    def in_camera(self, T_cam_world: np.ndarray) -> CamShape:
        R = T_cam_world[:3, :3] @ self.R
        p = T_cam_world[:3, :3] @ self.p + T_cam_world[:3, 3]
        return CamShape(self.shape, np.asarray(self.size, float), R, p)


@dataclass
class RenderObject:
    """A group of primitives drawn and cached together.

    ``version`` must change whenever the geometry changes (the renderer re-draws objects whose
    version moved and caches those that stayed still); ``bakeable`` False keeps it out of the
    cache (never needed for correctness, only for speed)."""

    key: str
    kind: Kind
    prims: list[Prim]
    version: object = 0
    fruit_id: int | None = None
    bakeable: bool = True
    meta: dict[str, object] = field(default_factory=dict)


def rot_between(z_from: np.ndarray, z_to: np.ndarray) -> np.ndarray:
    """A rotation taking unit vector ``z_from`` to unit vector ``z_to`` (Rodrigues)."""
    a = z_from / np.linalg.norm(z_from)
    b = z_to / np.linalg.norm(z_to)
    v = np.cross(a, b)
    c = float(a @ b)
    if c < -1 + 1e-12:  # opposite: turn by pi about any axis perpendicular to a
        axis = np.cross(a, [1.0, 0, 0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0, 1.0, 0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + K + K @ K / (1 + c)


def segment_cylinder(p0: np.ndarray, p1: np.ndarray, radius: float, m: Material) -> Prim:
    """A capped cylinder from p0 to p1 (world frame)."""
    axis = np.asarray(p1, float) - np.asarray(p0, float)
    length = float(np.linalg.norm(axis))
    R = rot_between(np.array([0.0, 0, 1]), axis)
    return Prim(Shape.CYLINDER, (radius, radius, length / 2), R, (p0 + p1) / 2, m)
