"""The trunk over frames: per-frame fixes smoothed, outliers gated, an explicit 'not found'.

The trunk does not move, so the estimate is an exponential average of the per-frame fixes
(gain ``smoothing``). A fix farther than ``gate_m`` (horizontally) from the estimate is not
averaged in; ``reacquire_frames`` consecutive fixes that agree with each other replace it (the
first estimate was wrong, or the robot base moved). Without a fix the estimate is kept,
``frames_unseen`` counts, and after ``forget_after_frames`` it is dropped: 'not found'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from services.scene.trunk import TrunkFailure, TrunkFix


@dataclass(frozen=True)
class TrackParams:
    smoothing: float = 0.2
    gate_m: float = 0.1
    reacquire_frames: int = 5
    forget_after_frames: int = 100


@dataclass
class TrunkState:
    """The smoothed trunk: a point on its vertical axis (world), its radius, its freshness."""

    axis_world_m: np.ndarray
    radius_m: float | None
    frames_unseen: int = 0
    pending: list[TrunkFix] = field(default_factory=list)


class TrunkTrack:
    def __init__(self, p: TrackParams) -> None:
        self.p = p
        self.state: TrunkState | None = None

    def step(self, fix: TrunkFix | TrunkFailure) -> str:
        """Take one frame's outcome; returns a note for the log ('' when nothing to say)."""
        s = self.state
        if isinstance(fix, TrunkFailure):
            if s is None:
                return ""
            s.frames_unseen += 1
            if s.frames_unseen >= self.p.forget_after_frames:
                self.state = None
                return f"trunk forgotten after {self.p.forget_after_frames} frames without a fix"
            return ""
        if s is None:
            self.state = TrunkState(fix.axis_point_world_m.copy(), fix.radius_m)
            return "trunk found"
        if _horizontal(fix.axis_point_world_m, s.axis_world_m) <= self.p.gate_m:
            g = self.p.smoothing
            s.axis_world_m = (1 - g) * s.axis_world_m + g * fix.axis_point_world_m
            if fix.radius_m is not None:
                s.radius_m = (
                    fix.radius_m if s.radius_m is None else (1 - g) * s.radius_m + g * fix.radius_m
                )
            s.frames_unseen, s.pending = 0, []
            return ""
        if (
            s.pending
            and _horizontal(fix.axis_point_world_m, s.pending[-1].axis_point_world_m)
            > self.p.gate_m
        ):
            s.pending = []
        s.pending.append(fix)
        s.frames_unseen += 1
        if len(s.pending) >= self.p.reacquire_frames:
            self.state = TrunkState(fix.axis_point_world_m.copy(), fix.radius_m)
            return f"trunk re-acquired {self.p.reacquire_frames} frames away from the old estimate"
        return "trunk fix outside the gate (not averaged in)"


def _horizontal(a: np.ndarray, b: np.ndarray) -> float:
    return math.hypot(float(a[0] - b[0]), float(a[1] - b[1]))
