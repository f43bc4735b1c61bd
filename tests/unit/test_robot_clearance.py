"""The batch test of points against capsules gives the one-point verdicts, at thresholds too."""

from __future__ import annotations

import numpy as np
import pytest

from services.robot.clearance import Capsule, axis_distances_m, home_capsules, within_reach


def _one_by_one(pts: np.ndarray, caps: list[Capsule], reach: np.ndarray) -> np.ndarray:
    return np.array([bool(np.any(axis_distances_m(p, caps) < reach)) for p in pts], bool)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_within_reach_equals_the_one_point_test(seed: int) -> None:
    rng = np.random.default_rng(seed)
    caps: list[Capsule] = [
        (rng.uniform(-0.5, 0.5, 3), rng.uniform(-0.5, 0.5, 3), float(rng.uniform(0.02, 0.1)))
        for _ in range(6)
    ]
    a = caps[0][0]
    caps.append((a, a.copy(), 0.05))  # a sphere: a zero-length axis
    reach = np.array([r for _a, _b, r in caps]) + 0.035
    pts = rng.uniform(-0.7, 0.7, (400, 3))
    # points exactly at a threshold: reach set to the one-point distance of some points
    for i in range(0, 400, 40):
        k = i % len(caps)
        reach_k = axis_distances_m(pts[i], caps)[k]
        pts = np.vstack([pts, pts[i]])
        reach[k] = reach_k
    got = within_reach(pts, caps, reach)
    want = _one_by_one(pts, caps, reach)
    assert np.array_equal(got, want)
    assert 0 < want.sum() < len(pts)


def test_within_reach_of_nothing_or_no_points() -> None:
    assert within_reach(np.zeros((3, 3)), [], np.array([])).tolist() == [False] * 3
    assert within_reach(
        np.zeros((0, 3)), list(home_capsules()), np.ones(len(home_capsules()))
    ).shape == (0,)
