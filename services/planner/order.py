"""Harvest order policies.

* ``nearest`` (paper §III-B): the fruit nearest the camera's optical centre first.
* ``planned`` (the paper's future work: "a planning algorithm should efficiently determine the
  harvesting path"): the order of the reachable fruit that minimises the cutter tip's travel
  from where it is, through every fruit's pre-pose, back to the ready pose. The controller moves
  the tip on a nearly straight line at a capped speed, with a convergence tail that is the same
  for every move, so the shortest path is the quickest order. Exact (Held-Karp dynamic
  programme) up to ``exact_max`` fruit, beyond that nearest neighbour improved by 2-opt.
  A fruit hanging over another's dish place is harvested after it (``before``): the dish, under
  the fruit, would meet the lower one (the controller's fruit dampers would hold it back).

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
    start: np.ndarray,
    points: np.ndarray,
    end: np.ndarray,
    exact_max: int = 12,
    before: Sequence[tuple[int, int]] = (),
) -> list[int]:
    """The visiting order of ``points`` (n×3) minimising start → … → end, as indices, with every
    (i, j) of ``before`` visited i first (dropped when they cannot all hold: a cycle)."""
    n = len(points)
    if n <= 1:
        return list(range(n))
    pts = np.asarray(points, float)
    D = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)
    s = np.linalg.norm(pts - np.asarray(start, float), axis=1)
    e = np.linalg.norm(pts - np.asarray(end, float), axis=1)
    pred = [0] * n  # bit masks of the points that must come first
    for i, j in before:
        if i != j:
            pred[j] |= 1 << i
    if not _acyclic(pred):
        pred = [0] * n
    if n <= exact_max:
        return _held_karp(D, s, e, pred)
    return _two_opt(D, s, e, _nearest_neighbour(D, s, pred), pred)


def _acyclic(pred: list[int]) -> bool:
    done, left = 0, set(range(len(pred)))
    while left:
        ready = [k for k in sorted(left) if pred[k] & ~done == 0]
        if not ready:
            return False
        for k in ready:
            done |= 1 << k
            left.discard(k)
    return True


def _feasible(order: list[int], pred: list[int]) -> bool:
    done = 0
    for k in order:
        if pred[k] & ~done:
            return False
        done |= 1 << k
    return True


def _held_karp(D: np.ndarray, s: np.ndarray, e: np.ndarray, pred: list[int]) -> list[int]:
    n = len(s)
    full = (1 << n) - 1
    cost = np.full((1 << n, n), np.inf)
    parent = np.full((1 << n, n), -1, dtype=np.int64)
    for j in range(n):
        if pred[j] == 0:
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
            if mask & bit or pred[k] & ~mask:
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


def _nearest_neighbour(D: np.ndarray, s: np.ndarray, pred: list[int]) -> list[int]:
    left = list(range(len(s)))
    done = 0
    order: list[int] = []
    while left:
        ready = [i for i in left if pred[i] & ~done == 0]
        cur = min(ready, key=lambda i: (D[order[-1], i] if order else s[i], i))
        order.append(cur)
        left.remove(cur)
        done |= 1 << cur
    return order


def _cost(D: np.ndarray, s: np.ndarray, e: np.ndarray, order: list[int]) -> float:
    return float(s[order[0]] + sum(D[a, b] for a, b in itertools.pairwise(order)) + e[order[-1]])


def _two_opt(
    D: np.ndarray, s: np.ndarray, e: np.ndarray, order: list[int], pred: list[int]
) -> list[int]:
    """Reverse segments while that shortens the open path and keeps the precedences (first
    improvement, fixed scan)."""
    best = _cost(D, s, e, order)
    improved = True
    while improved:
        improved = False
        for i in range(len(order) - 1):
            for j in range(i + 1, len(order)):
                cand = order[:i] + order[i : j + 1][::-1] + order[j + 1 :]
                c = _cost(D, s, e, cand)
                if c < best - 1e-12 and _feasible(cand, pred):
                    order, best, improved = cand, c, True
    return order
