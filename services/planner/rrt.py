"""RRT-Connect in joint space (Kuffner & LaValle 2000), then shortcutting and resampling.

Pure: the caller gives a validity test of one configuration (``valid(q) -> bool``), the joint
limits and a seeded generator, so a plan depends only on its inputs (replays are exact).
Edges are checked by resampling them at ``check_step_rad`` (the largest joint step between two
checked configurations): a thin obstacle between two checks can be missed, the controller's
dampers remain the guard there.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

Valid = Callable[[np.ndarray], bool]


@dataclass(frozen=True)
class PlanResult:
    """A path (None: none found within ``max_checks``), the configurations checked, and the
    path's length (sum of the largest joint step per segment), rad."""

    path: list[np.ndarray] | None
    checks: int
    why: str = ""

    @property
    def length_rad(self) -> float:
        if not self.path:
            return 0.0
        return float(sum(_gap(a, b) for a, b in itertools.pairwise(self.path)))


def _gap(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)))


class _Counter:
    def __init__(self, valid: Valid) -> None:
        self.valid, self.n = valid, 0

    def __call__(self, q: np.ndarray) -> bool:
        self.n += 1
        return self.valid(q)


def edge_free(a: np.ndarray, b: np.ndarray, valid: Valid, step_rad: float) -> bool:
    """Every configuration on the segment a→b, ``step_rad`` apart, is valid (a excluded)."""
    n = max(1, int(np.ceil(_gap(a, b) / step_rad)))
    return all(valid(a + (b - a) * (i / n)) for i in range(1, n + 1))


class _Tree:
    def __init__(self, root: np.ndarray) -> None:
        self.q = [root]
        self.parent = [-1]

    def nearest(self, q: np.ndarray) -> int:
        d = np.max(np.abs(np.asarray(self.q) - q), axis=1)
        return int(np.argmin(d))

    def add(self, q: np.ndarray, parent: int) -> int:
        self.q.append(q)
        self.parent.append(parent)
        return len(self.q) - 1

    def branch(self, i: int) -> list[np.ndarray]:
        """Root → node i."""
        out = []
        while i >= 0:
            out.append(self.q[i])
            i = self.parent[i]
        return out[::-1]


def _extend(
    tree: _Tree, q: np.ndarray, valid: Valid, step_rad: float, check_rad: float
) -> tuple[str, int]:
    """One step of at most ``step_rad`` from the nearest node towards q."""
    i = tree.nearest(q)
    near = tree.q[i]
    gap = _gap(near, q)
    new = q if gap <= step_rad else near + (q - near) * (step_rad / gap)
    if not edge_free(near, new, valid, check_rad):
        return "trapped", i
    j = tree.add(new, i)
    return ("reached" if gap <= step_rad else "advanced"), j


def _connect(
    tree: _Tree, q: np.ndarray, valid: Valid, step_rad: float, check_rad: float
) -> tuple[str, int]:
    while True:
        state, j = _extend(tree, q, valid, step_rad, check_rad)
        if state != "advanced":
            return state, j


def rrt_connect(
    start: np.ndarray,
    goal: np.ndarray,
    valid: Valid,
    lower_rad: np.ndarray,
    upper_rad: np.ndarray,
    rng: np.random.Generator,
    step_rad: float = 0.3,
    check_rad: float = 0.05,
    max_checks: int = 4000,
) -> PlanResult:
    """A valid path start → goal, or None. The straight segment is tried first (the usual case
    in open space); the path returned is shortcut and has no two points over ``check_rad``
    apart (ready to follow)."""
    count = _Counter(valid)
    if not count(start):
        return PlanResult(None, count.n, "the start is not valid")
    if not count(goal):
        return PlanResult(None, count.n, "the goal is not valid")
    if edge_free(start, goal, count, check_rad):
        return PlanResult(resample([start, goal], check_rad), count.n)
    a, b = _Tree(start), _Tree(goal)
    while count.n < max_checks:
        sample = rng.uniform(lower_rad, upper_rad)
        state, i = _extend(a, sample, count, step_rad, check_rad)
        if state != "trapped":
            state2, j = _connect(b, a.q[i], count, step_rad, check_rad)
            if state2 == "reached":
                path = a.branch(i) + b.branch(j)[::-1][1:]
                if a.q[0] is not start:  # the trees were swapped: goal → start
                    path = path[::-1]
                path = shortcut(path, count, check_rad, rng, max_checks)
                return PlanResult(resample(path, check_rad), count.n)
        a, b = b, a
    return PlanResult(None, count.n, f"no path within {max_checks} checks")


def shortcut(
    path: list[np.ndarray],
    valid: Valid,
    check_rad: float,
    rng: np.random.Generator,
    max_checks: int,
    tries: int = 60,
) -> list[np.ndarray]:
    """Random shortcuts: two points of the path joined straight where that segment is free."""
    path = list(path)
    count = valid if isinstance(valid, _Counter) else _Counter(valid)
    for _ in range(tries):
        if len(path) < 3 or count.n >= 2 * max_checks:
            break
        i, j = sorted(rng.choice(len(path), size=2, replace=False).tolist())
        if j - i < 2:
            continue
        if edge_free(path[i], path[j], count, check_rad):
            path = path[: i + 1] + path[j:]
    return path


def resample(path: list[np.ndarray], step_rad: float) -> list[np.ndarray]:
    """The same polyline with points at most ``step_rad`` apart (largest joint step)."""
    out = [np.array(path[0], float)]
    for a, b in itertools.pairwise(path):
        n = max(1, int(np.ceil(_gap(a, b) / step_rad)))
        out.extend(a + (b - a) * (i / n) for i in range(1, n + 1))
    return out
