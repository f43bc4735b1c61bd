"""Scripted 2D RGB-D scenes with known fruit boxes and IDs, for tests of the perception chain.

Not a simulator: a seeded picture of a canopy (leaf ellipses, branches) with shaded orange
discs at known depths, a hand-like occluder that sweeps across, an optional fruit that is moved,
and leaves that sway in front of fruit. Each frame comes with the truth: per fruit its ID, the
visible box, the visible fraction, and whether an occlusion event is active.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from schemas.base import Header, Pose
from schemas.camera import CameraIntrinsics, RgbdFrame, RgbdFrameMeta

FRAME_PERIOD_NS = 66_666_667  # 15 Hz


@dataclass(frozen=True)
class FruitView:
    fruit_id: int
    box_xyxy_px: tuple[float, float, float, float] | None
    visible_fraction: float


@dataclass(frozen=True)
class SceneFrame:
    frame: RgbdFrame
    fruits: tuple[FruitView, ...]
    occluder_active: bool


class Scene2D:
    """A seeded scene; ``frame(k)`` renders frame k (any order, same result)."""

    def __init__(
        self,
        seed: int = 0,
        n_fruit: int = 8,
        width_px: int = 640,
        height_px: int = 480,
        sweep: tuple[int, int] | None = (20, 60),
        move: tuple[int, int] | None = None,
        sway: bool = False,
    ) -> None:
        rng = np.random.default_rng(seed)
        self.w, self.h = width_px, height_px
        self.sweep, self.move, self.sway = sweep, move, sway
        self.bg = self._background(rng)
        self.fruit: list[tuple[float, float, float, float]] = []  # x, y, radius px; depth m
        while len(self.fruit) < n_fruit:
            r = float(rng.uniform(14, 30))
            x, y = (
                float(rng.uniform(r + 5, self.w - r - 5)),
                float(rng.uniform(r + 5, self.h - r - 5)),
            )
            if all(np.hypot(x - f[0], y - f[1]) > r + f[2] + 6 for f in self.fruit):
                self.fruit.append((x, y, r, float(rng.uniform(0.6, 0.9))))
        self.leaves = [
            (float(rng.uniform(0, self.w)), float(rng.uniform(0, self.h)), float(rng.uniform(0, 6)))
            for _ in range(6)
        ]
        self.intr = CameraIntrinsics(
            width_px=self.w,
            height_px=self.h,
            fx_px=615.0,
            fy_px=615.0,
            cx_px=self.w / 2,
            cy_px=self.h / 2,
        )

    def _background(self, rng: np.random.Generator) -> np.ndarray:
        img = np.zeros((self.h, self.w, 3), np.uint8)
        img[:] = (70, 110, 60)
        for _ in range(160):
            c = (int(rng.integers(20, 70)), int(rng.integers(80, 150)), int(rng.integers(20, 60)))
            ax = (int(rng.integers(8, 30)), int(rng.integers(4, 12)))
            center = (int(rng.integers(0, self.w)), int(rng.integers(0, self.h)))
            cv2.ellipse(img, center, ax, float(rng.uniform(0, 180)), 0, 360, c, -1)
        for _ in range(4):
            p0 = (int(rng.integers(0, self.w)), int(rng.integers(0, self.h)))
            p1 = (int(rng.integers(0, self.w)), int(rng.integers(0, self.h)))
            cv2.line(img, p0, p1, (90, 60, 40), int(rng.integers(3, 8)))
        return img

    def centre(self, i: int, k: int) -> tuple[float, float]:
        x, y, _, _ = self.fruit[i]
        if self.move and i == 0:
            a, b = self.move
            t = min(max((k - a) / max(b - a, 1), 0.0), 1.0)
            x += 60 * t
            y += 20 * t
        return x, y

    def occluder_box(self, k: int) -> tuple[int, int, int, int] | None:
        if not self.sweep or not (self.sweep[0] <= k < self.sweep[1]):
            return None
        t = (k - self.sweep[0]) / (self.sweep[1] - self.sweep[0])
        x = int(-160 + t * (self.w + 160))
        return x, int(self.h * 0.2), x + 160, int(self.h * 0.8)

    def frame(self, k: int) -> SceneFrame:
        rgb = self.bg.copy()
        depth = np.full((self.h, self.w), 1500, np.uint16)
        ids = np.full((self.h, self.w), -1, np.int32)
        for i, (_, _, r, z) in enumerate(self.fruit):
            x, y = self.centre(i, k)
            x0, y0 = max(0, int(x - r) - 2), max(0, int(y - r) - 2)
            x1, y1 = min(self.w, int(x + r) + 3), min(self.h, int(y + r) + 3)
            local = np.zeros((y1 - y0, x1 - x0), np.uint8)
            cv2.circle(local, (round(x) - x0, round(y) - y0), round(r), 1, -1)
            yy, xx = np.nonzero(local)
            yy, xx = yy + y0, xx + x0
            shade = 1.0 - 0.45 * np.hypot(xx - x + r / 3, yy - y + r / 3) / (1.4 * r)
            rgb[yy, xx] = (np.array([245, 135, 20])[None] * shade[:, None]).clip(0, 255)
            depth[yy, xx] = int(z * 1000)
            ids[yy, xx] = i
        for lx, ly, phase in self.leaves if self.sway else ():
            dx = 25 * np.sin(0.15 * k + phase)
            cv2.ellipse(rgb, (int(lx + dx), int(ly)), (34, 14), 30, 0, 360, (40, 120, 40), -1)
            leaf = np.zeros((self.h, self.w), np.uint8)
            cv2.ellipse(leaf, (int(lx + dx), int(ly)), (34, 14), 30, 0, 360, 1, -1)
            depth[leaf.astype(bool)] = 500
            ids[leaf.astype(bool)] = -1
        occ = self.occluder_box(k)
        if occ is not None:
            x1, y1, x2, y2 = occ
            a, b = max(x1, 0), min(x2, self.w)
            if a < b:
                rgb[y1:y2, a:b] = (205, 170, 150)
                depth[y1:y2, a:b] = 400
                ids[y1:y2, a:b] = -1
        views = []
        for i, (_, _, r, _) in enumerate(self.fruit):
            x, y = self.centre(i, k)
            x0, y0 = max(0, int(x - r) - 2), max(0, int(y - r) - 2)
            win = ids[y0 : int(y + r) + 3, x0 : int(x + r) + 3]
            ys, xs = np.nonzero(win == i)
            xs, ys = xs + x0, ys + y0
            full = np.pi * r * r
            if len(xs) == 0:
                views.append(FruitView(i, None, 0.0))
                continue
            box = (float(xs.min()), float(ys.min()), float(xs.max() + 1), float(ys.max() + 1))
            views.append(FruitView(i, box, float(min(1.0, len(xs) / full))))
        meta = RgbdFrameMeta(
            header=Header(stamp_ns=k * FRAME_PERIOD_NS, seq=k, frame_id="camera", source="sim"),
            intrinsics=self.intr,
            T_world_camera=Pose(position_m=(0.0, 0.0, 1.2)),
        )
        return SceneFrame(RgbdFrame(meta, rgb, depth), tuple(views), occ is not None)


def random_scene(rng: np.random.Generator, width_px: int = 640, height_px: int = 480) -> Scene2D:
    """A scene with randomised fruit count, sweep and leaves (detector training and tests)."""
    start = int(rng.integers(0, 40))
    return Scene2D(
        seed=int(rng.integers(2**31)),
        n_fruit=int(rng.integers(3, 20)),
        width_px=width_px,
        height_px=height_px,
        sweep=(start, start + 40) if rng.random() < 0.5 else None,
        sway=bool(rng.random() < 0.5),
    )


def write_dataset(out_dir: Path, frames: int, seed: int, name: str = "dataset.json") -> Path:
    """Write ``frames`` random scenes (PNG) and their visible boxes as a data set in the shared
    JSON format (fruit less than half visible are left out, as a labeller would)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    entries = []
    for i in range(frames):
        f = random_scene(rng).frame(int(rng.integers(0, 80)))
        image = f"scripted_{seed}_{i:04d}.png"
        cv2.imwrite(str(out_dir / image), cv2.cvtColor(f.frame.rgb, cv2.COLOR_RGB2BGR))
        boxes = [
            [round(c, 1) for c in v.box_xyxy_px]
            for v in f.fruits
            if v.box_xyxy_px is not None and v.visible_fraction >= 0.5
        ]
        h, w = f.frame.rgb.shape[:2]
        entries.append({"image": image, "width": w, "height": h, "boxes": boxes})
    path = out_dir / name
    path.write_text(json.dumps(entries))
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m services.testkit.scene2d",
        description="Write scripted 2D scenes as a detection data set (shared JSON format).",
    )
    ap.add_argument("--out", type=Path, required=True, help="output folder")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--seed", type=int, default=20_000)
    args = ap.parse_args(argv)
    print(write_dataset(args.out, args.frames, args.seed))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
