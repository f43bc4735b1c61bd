"""Assignment: Hungarian matching with a cost ceiling, Deep SORT's matching cascade, and the
gates (Mahalanobis, depth) and IoU cost used by the tracker."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

INFTY_COST = 1e5

Matches = list[tuple[int, int]]
CostFn = Callable[[Sequence[int], Sequence[int]], np.ndarray]
"""(track indices, detection indices) → cost matrix (len(tracks), len(detections))."""


def min_cost_matching(
    cost_fn: CostFn, max_cost: float, tracks: Sequence[int], dets: Sequence[int]
) -> tuple[Matches, list[int], list[int]]:
    """Hungarian assignment; pairs costing more than ``max_cost`` stay unmatched.

    Returns (matches, unmatched tracks, unmatched detections), each in input order, so the
    result does not depend on anything but the inputs.
    """
    if not tracks or not dets:
        return [], list(tracks), list(dets)
    cost = np.asarray(cost_fn(tracks, dets), dtype=np.float64)
    cost = np.where(cost > max_cost, max_cost + 1e-5, cost)
    rows, cols = linear_sum_assignment(cost)
    matches: Matches = []
    mt, md = set(), set()
    for r, c in zip(rows, cols, strict=True):
        if cost[r, c] <= max_cost:
            matches.append((tracks[r], dets[c]))
            mt.add(tracks[r])
            md.add(dets[c])
    return (
        matches,
        [t for t in tracks if t not in mt],
        [d for d in dets if d not in md],
    )


def matching_cascade(
    cost_fn: CostFn,
    max_cost: float,
    cascade_depth: int,
    tracks: Sequence[int],
    dets: Sequence[int],
    time_since_update: Callable[[int], int],
) -> tuple[Matches, list[int], list[int]]:
    """Match tracks seen 1 frame ago first, then 2, ... up to ``cascade_depth``: a track that
    has been missing longer (more uncertain) never takes a detection from a fresher one."""
    unmatched = list(dets)
    matches: Matches = []
    # Only the levels that have tracks (same result as looping 1..depth, far fewer steps).
    levels = sorted({time_since_update(t) for t in tracks} & set(range(1, cascade_depth + 1)))
    for level in levels:
        if not unmatched:
            break
        level_tracks = [t for t in tracks if time_since_update(t) == level]
        m, _, unmatched = min_cost_matching(cost_fn, max_cost, level_tracks, unmatched)
        matches += m
    matched = {t for t, _ in matches}
    return matches, [t for t in tracks if t not in matched], unmatched


def iou(box: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """IoU of one xyxy box with each of (N, 4) xyxy candidates."""
    lt = np.maximum(box[:2], candidates[:, :2])
    rb = np.minimum(box[2:], candidates[:, 2:])
    inter = np.prod(np.clip(rb - lt, 0, None), axis=1)
    a = np.prod(box[2:] - box[:2])
    b = np.prod(candidates[:, 2:] - candidates[:, :2], axis=1)
    return inter / np.maximum(a + b - inter, 1e-12)
