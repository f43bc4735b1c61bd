"""A D435-like depth sensor model: z-dependent noise, holes, quantisation to millimetres.

* Noise: RMS depth error σ(z) = z²·s/(f·B) (Intel's stereo depth error model, "Tuning depth
  cameras for best performance"), with subpixel s = 0.08, the depth stream's focal length
  f = 384.2 px at 640×480 and baseline B = 50 mm: 1.0 mm at 0.5 m, 4.2 mm at 1 m, 17 mm at 2 m.
  Half of the variance is per pixel, half shared by 4×4-pixel blocks (the stereo matching window
  correlates neighbours).
* Holes (0 = no depth): the stereo shadow (background the second imager, B to the right, cannot
  see next to a nearer surface: a band to the left of near objects), half of the pixels at depth
  jumps over 4 %, dark pixels (mean colour under 0.08 of full scale, with a probability growing
  as they get darker), 0.1 % random speckle, and everything nearer than 0.2 m or farther than
  10 m.
* Seeded: the noise of frame k comes from ``default_rng([seed, k])`` (a fixed bank of Gaussian
  noise read at a random offset, so it costs ~2 ms, not ~6).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from services.sim.render.camera import D435_BASELINE_M, D435_DEPTH_FOCAL_PX

F32 = np.float32
PAD = 32


@dataclass(frozen=True)
class D435Noise:
    width: int
    height: int
    fx_color_px: float
    seed: int = 0
    subpixel: float = 0.08
    depth_focal_px: float = D435_DEPTH_FOCAL_PX
    baseline_m: float = D435_BASELINE_M
    edge_jump: float = 0.04
    edge_hole_p: float = 0.5
    dark_level: float = 0.08
    speckle_p: float = 0.001
    min_z_m: float = 0.2
    max_z_m: float = 10.0
    rgb_std: float = 1.5

    @cached_property
    def _bank(self) -> tuple[np.ndarray, np.ndarray]:
        rng = np.random.default_rng([self.seed, 0xD435])
        H, W = self.height + PAD, self.width + PAD
        fine = rng.standard_normal((H, W), dtype=F32)
        coarse = rng.standard_normal((H // 4 + 1, W // 4 + 1), dtype=F32)
        block = np.repeat(np.repeat(coarse, 4, 0), 4, 1)[:H, :W]
        depth = (fine + block) * F32(np.sqrt(0.5))
        rgb = np.clip(np.round(rng.standard_normal((H, W, 3)) * self.rgb_std), -127, 127)
        return depth, rgb.astype(np.int16)

    def sigma_m(self, z_m: np.ndarray | float) -> np.ndarray | float:
        """RMS depth error at depth z (m)."""
        return np.square(z_m) * self.subpixel / (self.depth_focal_px * self.baseline_m)

    def depth_mm(self, depth_m: np.ndarray, rgb: np.ndarray, frame: int) -> np.ndarray:
        """Noisy, holed depth in millimetres (uint16, 0 = invalid)."""
        rng = np.random.default_rng([self.seed, frame])
        H, W = depth_m.shape
        oy, ox = (int(v) for v in rng.integers(0, PAD, 2))
        z = depth_m.astype(F32)
        valid = (z > self.min_z_m) & (z < self.max_z_m)
        noisy = z + F32(self.sigma_m(1.0)) * z * z * self._bank[0][oy : oy + H, ox : ox + W]
        holes = ~valid | self._shadow(z, valid)
        u = rng.random((H, W), dtype=F32)
        holes |= self._edges(z) & (u < self.edge_hole_p)
        grey = (rgb[..., 0].astype(np.uint16) + rgb[..., 1] + rgb[..., 2]) * F32(1 / 765)
        holes |= u > F32(1 - self.speckle_p)
        dark = grey < self.dark_level
        holes |= dark & (u < F32(1) - grey / F32(self.dark_level))
        mm = np.clip(np.round(noisy * F32(1000)), 0, 65535).astype(np.uint16)
        mm[holes] = 0
        return mm

    def rgb(self, rgb: np.ndarray, frame: int) -> np.ndarray:
        """Colour with seeded sensor noise (uint8)."""
        if self.rgb_std <= 0:
            return rgb
        rng = np.random.default_rng([self.seed, frame, 1])
        H, W = rgb.shape[:2]
        oy, ox = (int(v) for v in rng.integers(0, PAD, 2))
        out = rgb.astype(np.int16) + self._bank[1][oy : oy + H, ox : ox + W]
        return np.clip(out, 0, 255).astype(np.uint8)

    def _shadow(self, z: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """Pixels the second imager cannot see: some pixel v > u to the right has a disparity
        d[v] > d[u] + (v - u), i.e. max_{v>u}(d[v] - v) + u > d[u]."""
        d = np.where(valid, F32(self.fx_color_px * self.baseline_m) / np.maximum(z, F32(1e-3)), 0)
        col = np.arange(d.shape[1], dtype=F32)
        a = d - col
        m = np.maximum.accumulate(a[:, ::-1], axis=1)[:, ::-1]
        nxt = np.full_like(m, -np.inf)
        nxt[:, :-1] = m[:, 1:]
        return valid & (nxt + col > d + F32(0.5))

    def _edges(self, z: np.ndarray) -> np.ndarray:
        e = np.zeros(z.shape, bool)
        jump = np.abs(np.diff(z, axis=1)) > F32(self.edge_jump) * np.minimum(z[:, 1:], z[:, :-1])
        e[:, 1:] |= jump
        e[:, :-1] |= jump
        jump = np.abs(np.diff(z, axis=0)) > F32(self.edge_jump) * np.minimum(z[1:], z[:-1])
        e[1:] |= jump
        e[:-1] |= jump
        return e
