"""RRT-Connect in joint space (services/planner/rrt.py), on a plane with walls: paths are
valid point by point, dense enough to follow, deterministic for a seed; failures say why."""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from services.planner.rrt import PlanResult, Valid, resample, rrt_connect

LO, HI = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
START, GOAL = np.array([-0.8, 0.0]), np.array([0.8, 0.0])


def wall_with_gap(q: np.ndarray) -> bool:
    """A wall at x in [-0.1, 0.1], open only for y > 0.6."""
    return not (-0.1 <= q[0] <= 0.1 and q[1] < 0.6)


def plan(valid: Valid, seed: int = 0, max_checks: int = 4000) -> PlanResult:
    return rrt_connect(
        START, GOAL, valid, LO, HI, np.random.default_rng(seed), 0.2, 0.02, max_checks
    )


def test_open_space_gives_the_straight_segment() -> None:
    res = plan(lambda q: True)
    assert res.path is not None
    assert np.allclose(res.path[0], START) and np.allclose(res.path[-1], GOAL)
    assert abs(res.length_rad - 1.6) < 1e-9  # no detour
    assert all(np.abs(b - a).max() <= 0.02 + 1e-12 for a, b in pairwise(res.path))


def test_a_wall_is_gone_round_through_its_gap() -> None:
    res = plan(wall_with_gap)
    assert res.path is not None, res.why
    assert np.allclose(res.path[0], START) and np.allclose(res.path[-1], GOAL)
    assert all(wall_with_gap(q) for q in res.path)
    assert all(np.abs(b - a).max() <= 0.02 + 1e-12 for a, b in pairwise(res.path))
    assert max(q[1] for q in res.path) > 0.6  # through the gap
    assert res.length_rad < 3.0  # shortcut: not a random walk


def test_the_same_seed_gives_the_same_path() -> None:
    a, b = plan(wall_with_gap, seed=3), plan(wall_with_gap, seed=3)
    assert a.path is not None and b.path is not None
    assert len(a.path) == len(b.path)
    assert all(np.array_equal(p, q) for p, q in zip(a.path, b.path, strict=True))
    assert a.checks == b.checks


def test_failures_say_why() -> None:
    res = plan(lambda q: q[0] > -0.5)
    assert res.path is None and res.why == "the start is not valid"
    res = plan(lambda q: q[0] < 0.5)
    assert res.path is None and res.why == "the goal is not valid"
    closed = plan(lambda q: not -0.1 <= q[0] <= 0.1, max_checks=500)
    assert closed.path is None and closed.why == "no path within 500 checks"
    assert 500 <= closed.checks < 700  # stops near the budget


def test_resample_keeps_the_corners_and_bounds_the_steps() -> None:
    pts = [np.zeros(2), np.array([0.5, 0.0]), np.array([0.5, 0.35])]
    out = resample(pts, 0.1)
    assert any(np.allclose(q, pts[1]) for q in out)
    assert np.allclose(out[-1], pts[-1]) and len(out) == 1 + 5 + 4
