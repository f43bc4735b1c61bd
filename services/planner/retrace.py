"""Retracing: after a stall, the arms go back along the joint path they came in by.

A stalled approach or harvest in a crown often leaves the arms caught across branches (a link
resting on the occupied space at d_s, the target beyond it). The controller is local: from
there, every later target pulls the arms against the same branches. The path the arms came in
by was free, so running it backwards (a joint goal per waypoint, under the controller's limits
and dampers) frees them, whatever the scene around them looks like.

Pure: joint vectors in arm order (cutter j1..j7, then collector j1..j7), rad.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

NS = 1_000_000_000


def _gap(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)))


@dataclass
class JointPath:
    """The joints of the current attempt: a waypoint each time some joint has moved
    ``step_rad`` since the last one."""

    step_rad: float
    points: list[np.ndarray] = field(default_factory=list)

    def start(self, q: np.ndarray | None) -> None:
        self.points = [] if q is None else [q.copy()]

    def note(self, q: np.ndarray) -> None:
        if self.points and _gap(q, self.points[-1]) >= self.step_rad:
            self.points.append(q.copy())

    def way_back(self) -> list[np.ndarray]:
        """The waypoints from the last to where the attempt began (copies)."""
        return [p.copy() for p in reversed(self.points)]


@dataclass
class Retrace:
    """Waypoints of a path run backwards; the goal is the first waypoint still more than
    ``lookahead_rad`` away (so the arms do not slow down at each one), the last must be
    reached within ``tolerance_rad``. Stuck: no waypoint passed and no joint closer to the
    current goal by ``min_gain_rad`` for a while."""

    waypoints: list[np.ndarray]
    lookahead_rad: float
    tolerance_rad: float
    min_gain_rad: float
    since_ns: int
    i: int = 0
    best_rad: float = float("inf")
    best_ns: int = 0

    @classmethod
    def back_along(
        cls, path: JointPath, now_ns: int, lookahead_rad: float, tolerance_rad: float
    ) -> Retrace | None:
        """None when the path has no waypoint to go back to."""
        if len(path.points) < 2:
            return None
        return cls(
            path.way_back(), lookahead_rad, tolerance_rad, tolerance_rad / 2, now_ns, best_ns=now_ns
        )

    @property
    def goal(self) -> np.ndarray:
        return self.waypoints[self.i]

    def update(self, q: np.ndarray, now_ns: int) -> None:
        last = len(self.waypoints) - 1
        moved = False
        while self.i < last and _gap(q, self.waypoints[self.i]) < self.lookahead_rad:
            self.i += 1
            moved = True
        gap = _gap(q, self.goal)
        if moved or gap < self.best_rad - self.min_gain_rad:
            self.best_rad, self.best_ns = gap, now_ns

    def done(self, q: np.ndarray) -> bool:
        return self.i == len(self.waypoints) - 1 and _gap(q, self.goal) <= self.tolerance_rad

    def remaining_rad(self, q: np.ndarray) -> float:
        """How far the arms are from the path's end (the largest joint gap), rad."""
        return _gap(q, self.waypoints[-1])

    def stuck(self, now_ns: int, after_s: float) -> bool:
        return now_ns - self.best_ns > after_s * NS
