"""The scenario's timed events as functions of sim time: the hand occluder, fruit moved by
hand, swaying leaves. Pure and seeded; time in seconds of sim time."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.sim.scenario import HandSweep, MoveFruit, SwayLeaves
from services.sim.world import World

RAMP_S = 0.5  # sway fades in and out over this time


def smoothstep(x: float) -> float:
    x = min(1.0, max(0.0, x))
    return x * x * (3 - 2 * x)


def facing_camera(p: np.ndarray, camera_m: np.ndarray) -> np.ndarray:
    """Rotation whose y axis points from p to the camera and z axis is as close to up as can be."""
    y = camera_m - p
    y /= np.linalg.norm(y)
    z = np.array([0, 0, 1.0]) - y[2] * y
    z /= np.linalg.norm(z)
    return np.column_stack([np.cross(y, z), y, z])


@dataclass
class _Sway:
    ev: SwayLeaves
    leaves: np.ndarray  # leaf indices
    dirs: np.ndarray  # (n, 3) unit directions
    phases: np.ndarray  # (n,) rad


class Timeline:
    """Positions of what moves by script at a given sim time."""

    def __init__(self, world: World) -> None:
        self.world = world
        evs = world.scenario.events
        self.sweeps = [e for e in evs if isinstance(e, HandSweep)]
        self.moves = [e for e in evs if isinstance(e, MoveFruit)]
        rng = np.random.default_rng([world.seed, 7])
        self.sways = [self._sway(e, rng) for e in evs if isinstance(e, SwayLeaves)]

    def _sway(self, e: SwayLeaves, rng: np.random.Generator) -> _Sway:
        w = self.world
        c = w.fruits[e.fruit].centre if e.fruit is not None else np.asarray(e.center_world_m, float)
        idx = np.array(
            [i for i, lf in enumerate(w.leaves) if np.linalg.norm(lf.centre - c) <= e.radius_m],
            dtype=int,
        )
        d = rng.normal(size=(len(idx), 3)) + np.array([0, 0, 0.3])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return _Sway(e, idx, d, rng.uniform(0, 2 * math.pi, len(idx)))

    def fruit_offset(self, fruit_id: int, t: float) -> np.ndarray:
        """Displacement of an attached fruit by hand-move events, world, m."""
        off = np.zeros(3)
        for e in self.moves:
            if e.fruit == fruit_id and t >= e.start_s:
                off += np.asarray(e.offset_world_m) * smoothstep((t - e.start_s) / e.duration_s)
        return off

    def hand(
        self, t: float, fruit_pos: dict[int, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Pose (R, palm centre) of the hand at time t, or None when no hand is in the scene."""
        cam = self.world.camera_world_m
        for e in self.sweeps:
            if e.start_s <= t <= e.start_s + e.duration_s:
                a = smoothstep((t - e.start_s) / e.duration_s)
                p0, p1 = self._sweep_path(e, fruit_pos)
                p = p0 + (p1 - p0) * a
                return facing_camera(p, cam), p
        for m in self.moves:
            if m.start_s <= t <= m.start_s + m.duration_s and m.fruit in fruit_pos:
                f = fruit_pos[m.fruit]
                to_cam = (cam - f) / np.linalg.norm(cam - f)
                p = f + to_cam * 0.045 + np.array([0, 0, -0.075])
                return facing_camera(p, cam), p
        return None

    def _sweep_path(
        self, e: HandSweep, fruit_pos: dict[int, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray]:
        if e.fruit is None:
            assert e.from_world_m is not None and e.to_world_m is not None
            return np.asarray(e.from_world_m, float), np.asarray(e.to_world_m, float)
        cam = self.world.camera_world_m
        f = fruit_pos.get(e.fruit, self.world.fruits[e.fruit].centre)
        ray = f - cam
        dist = float(np.linalg.norm(ray))
        mid = cam + ray / dist * (dist - e.distance_before_m) + np.array([0, 0, -0.03])
        side = np.cross(ray, [0, 0, 1.0])
        side /= np.linalg.norm(side)
        return mid + side * e.span_m / 2, mid - side * e.span_m / 2

    def leaf_offsets(self, t: float) -> dict[int, np.ndarray]:
        """Displacements of swaying leaves (leaf index → world offset, m)."""
        out: dict[int, np.ndarray] = {}
        for s in self.sways:
            e = s.ev
            if not e.start_s <= t <= e.start_s + e.duration_s:
                continue
            env = min(1.0, (t - e.start_s) / RAMP_S, (e.start_s + e.duration_s - t) / RAMP_S)
            w = 2 * math.pi * e.frequency_hz * (t - e.start_s)
            amp = e.amplitude_m * env * np.sin(w + s.phases)
            for i, a, d in zip(s.leaves, amp, s.dirs, strict=True):
                out[int(i)] = out.get(int(i), np.zeros(3)) + a * d
        return out
