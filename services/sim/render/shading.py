"""Materials, procedural textures and lighting (Lambert + ambient, a specular lobe on fruit).

Textures are functions of the shape's *local* hit point, so they stick to a moving object.
The noise is integer-hashed value noise: exact integer arithmetic plus float32 interpolation,
no transcendental functions, hence bit-identical from run to run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from services.sim.render.raycast import dot, unit

F32 = np.float32
Texture = Literal["plain", "peel", "bark", "leaf", "ground", "wall"]


@dataclass(frozen=True)
class Material:
    """Albedo (RGB in 0..1), texture kind and its strength, a seed that decorrelates objects."""

    rgb: tuple[float, float, float]
    texture: Texture = "plain"
    strength: float = 1.0
    seed: int = 0
    specular: float = 0.0


@dataclass(frozen=True)
class Lighting:
    """One directional light plus ambient light, in the world frame."""

    direction_world: tuple[float, float, float] = (-0.45, 0.3, 0.85)  # towards the light
    ambient: float = 0.62
    diffuse: float = 0.5
    colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    exposure: float = 1.0


@dataclass
class LightCam:
    """Lighting expressed in the camera frame (computed once per render)."""

    L: np.ndarray
    ambient: F32
    diffuse: F32
    colour: np.ndarray = field(default_factory=lambda: np.ones(3, F32))


def light_in_camera(light: Lighting, R_cam_world: np.ndarray) -> LightCam:
    L = R_cam_world @ np.asarray(light.direction_world, float)
    L /= np.linalg.norm(L)
    colour = np.asarray(light.colour, F32) * F32(light.exposure)
    return LightCam(L.astype(F32), F32(light.ambient), F32(light.diffuse), colour)


# ---- value noise ------------------------------------------------------------------------------
def _hash(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray, seed: int) -> np.ndarray:
    h = (
        ix.astype(np.uint32) * np.uint32(0x8DA6B343)
        ^ iy.astype(np.uint32) * np.uint32(0xD8163841)
        ^ iz.astype(np.uint32) * np.uint32(0xCB1AB31F)
        ^ np.uint32(seed * 0x9E3779B1 & 0xFFFFFFFF)
    )
    h ^= h >> np.uint32(13)
    h *= np.uint32(0x5BD1E995)
    h ^= h >> np.uint32(15)
    return (h >> np.uint32(8)).astype(F32) * F32(1.0 / (1 << 24))


def value_noise(p: np.ndarray, seed: int = 0) -> np.ndarray:
    """Smooth 3-D value noise in [0, 1) at points p (n, 3), one lattice cell per unit."""
    p = p.astype(F32)
    i = np.floor(p)
    f = p - i
    w = f * f * (F32(3) - F32(2) * f)
    ii = i.astype(np.int64)
    out = np.zeros(len(p), F32)
    for dx in (0, 1):
        wx = w[:, 0] if dx else F32(1) - w[:, 0]
        for dy in (0, 1):
            wy = w[:, 1] if dy else F32(1) - w[:, 1]
            for dz in (0, 1):
                wz = w[:, 2] if dz else F32(1) - w[:, 2]
                out += wx * wy * wz * _hash(ii[:, 0] + dx, ii[:, 1] + dy, ii[:, 2] + dz, seed)
    return out


# ---- textures ---------------------------------------------------------------------------------
def leaf_shade(strength: Any, local: np.ndarray) -> np.ndarray:
    """The leaf texture's factor: a lighter midrib along x, darker towards the tip (cheap:
    leaves sway, so they are redrawn often). ``strength``: float32, or one per point."""
    v = F32(0.97) - strength * F32(2.5) * np.abs(local[:, 0])
    return np.where(np.abs(local[:, 1]) < F32(0.0018), v * F32(1.18), v)


def albedo(m: Material, local: np.ndarray) -> np.ndarray:
    """Per-pixel albedo (n, 3) for local hit points (n, 3)."""
    base = np.asarray(m.rgb, F32)[None, :]
    k = F32(m.strength)
    v: np.ndarray
    if m.texture == "peel":  # large blotches + fine dimples
        v = F32(0.93) + k * (
            F32(0.1) * value_noise(local * F32(45), m.seed)
            + F32(0.08) * value_noise(local * F32(420), m.seed + 1)
        )
    elif m.texture == "bark":  # streaks along the branch axis (local z)
        v = F32(0.9) + k * F32(0.22) * (
            value_noise(local * np.array([70, 70, 7], F32), m.seed) - F32(0.5)
        )
    elif m.texture == "leaf":
        v = leaf_shade(k, local)
    elif m.texture == "ground":
        v = F32(0.75) + k * (
            F32(0.35) * value_noise(local * F32(2.5), m.seed)
            + F32(0.2) * value_noise(local * F32(40), m.seed + 1)
        )
    elif m.texture == "wall":
        v = F32(0.95) + k * F32(0.08) * value_noise(local * F32(6), m.seed)
    else:
        return np.broadcast_to(base, (len(local), 3))
    return base * v[:, None]


def shade(
    m: Material,
    local: np.ndarray,
    n: np.ndarray,
    view: np.ndarray,
    light: LightCam,
    two_sided: bool = False,
) -> np.ndarray:
    """Linear RGB (n, 3) in 0..~1.2: albedo × (ambient + diffuse·max(0, n·L)) + specular.

    ``view`` holds the ray directions (n, 3) (camera → surface). Two-sided surfaces (leaves) turn
    their normal towards the camera and let a little light through from behind."""
    if two_sided:
        n = towards_camera(n, view)
    rgb = albedo(m, local) * irradiance(n, light, two_sided)[:, None]
    if m.specular > 0:
        h = unit(light.L[None, :] - unit(view))
        s = np.maximum(dot(n, h), F32(0))
        for _ in range(4):  # s^16 by squaring
            s = s * s
        rgb = rgb + (F32(m.specular) * s)[:, None]
    return rgb * light.colour[None, :]


def towards_camera(n: np.ndarray, view: np.ndarray) -> np.ndarray:
    """A two-sided surface's normals (n, 3) turned to face the rays ``view`` (n, 3)."""
    flip = dot(n, view) > 0
    return np.where(flip[:, None], -n, n)


def irradiance(n: np.ndarray, light: LightCam, two_sided: bool) -> np.ndarray:
    """ambient + diffuse·max(0, n·L) per point (n, 3 normals facing the camera); a two-sided
    surface also lets 0.35 of the light through from behind."""
    ndl = dot(n, light.L)
    lit = np.maximum(ndl, F32(0))
    if two_sided:
        lit = lit + F32(0.35) * np.maximum(-ndl, F32(0))
    return light.ambient + light.diffuse * lit
