"""Harvest order policies: nearest-first (paper) and the planned order (shortest tool path)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from services.planner.order import nearest_first, path_length_m, planned_order


def test_nearest_first_sorts_by_distance_and_breaks_ties_by_index() -> None:
    assert nearest_first([0.7, 0.5, 0.5, 0.9]) == [1, 2, 0, 3]
    assert nearest_first([]) == []


@pytest.mark.parametrize("n", [2, 3, 5, 7])
def test_planned_order_is_the_shortest_path_brute_force(n: int) -> None:
    rng = np.random.default_rng(n)
    for _ in range(5):
        pts = rng.uniform((0.4, -0.4, 1.0), (0.9, 0.4, 1.6), (n, 3))
        start, end = np.array([0.55, 0.0, 1.05]), np.array([0.55, 0.0, 1.05])
        got = planned_order(start, pts, end)
        best = min(
            path_length_m(start, pts, list(p), end) for p in itertools.permutations(range(n))
        )
        assert sorted(got) == list(range(n))
        assert path_length_m(start, pts, got, end) == pytest.approx(best, abs=1e-12)


def test_planned_order_beats_nearest_first_on_a_zigzag() -> None:
    # Fruit alternate left and right at growing depth: nearest-first zigzags across the tree.
    pts = np.array([[0.5 + 0.05 * i, 0.3 * (-1) ** i, 1.3] for i in range(6)])
    start = end = np.array([0.55, 0.0, 1.05])
    cam = np.array([0.02, 0.0, 1.44])
    near = nearest_first([float(np.linalg.norm(p - cam)) for p in pts])
    plan = planned_order(start, pts, end)
    assert path_length_m(start, pts, plan, end) < 0.8 * path_length_m(start, pts, near, end)


def test_large_sets_use_two_opt_no_worse_than_greedy_and_deterministic() -> None:
    rng = np.random.default_rng(4)
    pts = rng.uniform((0.4, -0.4, 1.0), (0.9, 0.4, 1.6), (16, 3))
    start = end = np.array([0.55, 0.0, 1.05])
    a = planned_order(start, pts, end, exact_max=8)
    assert a == planned_order(start, pts, end, exact_max=8)
    assert sorted(a) == list(range(16))
    exact = planned_order(start, pts[:10], end, exact_max=12)
    heur = planned_order(start, pts[:10], end, exact_max=4)
    assert path_length_m(start, pts[:10], heur, end) <= 1.1 * path_length_m(
        start, pts[:10], exact, end
    )


def test_one_or_no_fruit() -> None:
    s = np.zeros(3)
    assert planned_order(s, np.zeros((0, 3)), s) == []
    assert planned_order(s, np.ones((1, 3)), s) == [0]


def test_precedences_are_kept_and_a_cycle_is_ignored() -> None:
    rng = np.random.default_rng(11)
    pts = rng.uniform((0.4, -0.4, 1.0), (0.9, 0.4, 1.6), (6, 3))
    start = end = np.array([0.55, 0.0, 1.05])
    free = planned_order(start, pts, end)
    # force the free order's last point first and its first point last
    before = [(free[-1], i) for i in range(6) if i != free[-1]] + [(i, free[0]) for i in range(6)]
    for exact_max in (12, 3):  # exact and 2-opt
        got = planned_order(start, pts, end, exact_max, before)
        assert got[0] == free[-1] and got[-1] == free[0]
    assert planned_order(start, pts, end, before=[(0, 1), (1, 0)]) == free
