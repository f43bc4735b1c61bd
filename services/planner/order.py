"""Harvest order policies.

* ``nearest`` (paper §III-B): the fruit nearest the camera's optical centre first.
* ``planned`` (the paper's future work: "a planning algorithm should efficiently determine the
  harvesting path"): the order of the reachable fruit that minimises the cutter tip's travel
  from where it is, through every fruit's pre-pose, back to the ready pose. The controller moves
  the tip on a nearly straight line at a capped speed, with a convergence tail that is the same
  for every move, so the shortest path is the quickest order. Exact (Held-Karp dynamic
  programme) up to ``exact_max`` fruit, beyond that nearest neighbour improved by 2-opt.

Deterministic: no randomness; ties go to the lower index (the caller sorts by fruit key).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np


def nearest_first(distances_m: Sequence[float]) -> list[int]:
    """Indices by distance to the camera, ties by index."""
    return sorted(range(len(distances_m)), key=lambda i: (distances_m[i], i))


def path_length_m(start: np.ndarray, points: np.ndarray, order: Sequence[int], end: np.ndarray):
    """Length of start → points[order] → end, m."""
    seq = [np.asarray(start)] + [points[i] for i in order] + [np.asarray(end)]
    return float(sum(np.linalg.norm(b - a) for a, b in itertools.pairwise(seq)))


def planned_order(
    start: np.ndarray, points: np.ndarray, end: np.ndarray, exact_max: int = 12
) -> list[int]:
    """The visiting order of ``points`` (n×3) minimising start → … → end, as indices."""
    n = len(points)
    if n <= 1:
        return list(range(n))
    pts = np.asarray(points, float)
    D = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)
    s = np.linalg.norm(pts - np.asarray(start, float), axis=1)
    e = np.linalg.norm(pts - np.asarray(end, float), axis=1)
    if n <= exact_max:
        return _held_karp(D, s, e)
    return _two_opt(D, s, e, _nearest_neighbour(D, s))


def _held_karp(D: np.ndarray, s: np.ndarray, e: np.ndarray) -> list[int]:
    n = len(s)
    full = (1 << n) - 1
    cost = np.full((1 << n, n), np.inf)
    parent = np.full((1 << n, n), -1, dtype=np.int64)
    for j in range(n):
        cost[1 << j, j] = s[j]
    for mask in range(1, full + 1):
        row = cost[mask]
        if not np.isfinite(row).any():
            continue
        via = row[:, None] + D  # via[j, k]: end at j, then go to k
        best_j = np.argmin(via, axis=0)  # first minimum: ties to the lower index
        best = via[best_j, np.arange(n)]
        for k in range(n):
            bit = 1 << k
            if mask & bit:
                continue
            nxt = mask | bit
            if best[k] < cost[nxt, k]:
                cost[nxt, k] = best[k]
                parent[nxt, k] = best_j[k]
    last = int(np.argmin(cost[full] + e))
    order = [last]
    mask = full
    while len(order) < n:
        prev = int(parent[mask, order[-1]])
        mask &= ~(1 << order[-1])
        order.append(prev)
    return order[::-1]


def _nearest_neighbour(D: np.ndarray, s: np.ndarray) -> list[int]:
    left = list(range(len(s)))
    cur = min(left, key=lambda i: (s[i], i))
    order = [cur]
    left.remove(cur)
    while left:
        cur = min(left, key=lambda i: (D[cur, i], i))
        order.append(cur)
        left.remove(cur)
    return order


def _cost(D: np.ndarray, s: np.ndarray, e: np.ndarray, order: list[int]) -> float:
    return float(s[order[0]] + sum(D[a, b] for a, b in itertools.pairwise(order)) + e[order[-1]])


def _two_opt(D: np.ndarray, s: np.ndarray, e: np.ndarray, order: list[int]) -> list[int]:
    """Reverse segments while that shortens the open path (first improvement, fixed scan)."""
    best = _cost(D, s, e, order)
    improved = True
    while improved:
        improved = False
        for i in range(len(order) - 1):
            for j in range(i + 1, len(order)):
                cand = order[:i] + order[i : j + 1][::-1] + order[j + 1 :]
                c = _cost(D, s, e, cand)
                if c < best - 1e-12:
                    order, best, improved = cand, c, True
    return order
