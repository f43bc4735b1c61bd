"""Tracker evaluation: the paper's correct-ID share and TrackEval's HOTA, IDF1, MOTA, IDSW.

Per frame we keep the visible ground-truth fruit (ID, box) and the reported tracks (ID, box).

*Paper metric* (Gursoy et al. §V): the share of frames in which every visible fruit carries
its correct ID, split into frames with an occlusion event active and frames without. A fruit's
correct ID is the track ID it is assigned to by the majority assignment over the sequence:
count, over all frames, how often each (fruit, track) pair is matched (Hungarian on IoU,
IoU >= 0.5, per frame), then pick the one-to-one assignment with the largest total count
(Hungarian on the counts). In a frame, a visible fruit "carries its correct ID" when it is
matched (IoU >= 0.5) to the track of that ID. Frames with no visible fruit are not counted.

*TrackEval*: the same per-frame data go to TrackEval's HOTA, CLEAR and Identity metrics
(``trackeval`` from PyPI, not a copy), with IoU as the similarity, sequences combined as
TrackEval combines them.
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from services.detector.evaluate import iou_matrix

IOU_MATCH = 0.5


@dataclass(frozen=True)
class FrameRecord:
    """One frame: visible GT (ids, boxes (N, 4)), tracks (ids, boxes (M, 4)), occlusion flag."""

    gt_ids: np.ndarray
    gt_boxes: np.ndarray
    trk_ids: np.ndarray
    trk_boxes: np.ndarray
    occluded: bool


def _frame_matches(f: FrameRecord) -> list[tuple[int, int]]:
    if len(f.gt_ids) == 0 or len(f.trk_ids) == 0:
        return []
    ious = iou_matrix(f.gt_boxes, f.trk_boxes)
    rows, cols = linear_sum_assignment(-ious)
    return [
        (int(f.gt_ids[r]), int(f.trk_ids[c]))
        for r, c in zip(rows, cols, strict=True)
        if ious[r, c] >= IOU_MATCH
    ]


def majority_assignment(frames: Sequence[FrameRecord]) -> dict[int, int]:
    """GT id → track id, one to one, maximising the number of frames they are matched in."""
    counts: dict[tuple[int, int], int] = {}
    for f in frames:
        for pair in _frame_matches(f):
            counts[pair] = counts.get(pair, 0) + 1
    if not counts:
        return {}
    gts = sorted({g for g, _ in counts})
    trks = sorted({t for _, t in counts})
    m = np.zeros((len(gts), len(trks)))
    for (g, t), n in counts.items():
        m[gts.index(g), trks.index(t)] = n
    rows, cols = linear_sum_assignment(-m)
    return {gts[r]: trks[c] for r, c in zip(rows, cols, strict=True) if m[r, c] > 0}


def paper_metric(frames: Sequence[FrameRecord]) -> dict[str, float | int]:
    """Share of frames where every visible fruit carries its correct ID (occluded / clear)."""
    mapping = majority_assignment(frames)
    ok = {True: 0, False: 0}
    n = {True: 0, False: 0}
    for f in frames:
        if len(f.gt_ids) == 0:
            continue
        matched = dict(_frame_matches(f))
        good = all(matched.get(int(g)) == mapping.get(int(g), -1) for g in f.gt_ids)
        n[f.occluded] += 1
        ok[f.occluded] += int(good)
    return {
        "id_correct_occluded": ok[True] / n[True] if n[True] else float("nan"),
        "id_correct_clear": ok[False] / n[False] if n[False] else float("nan"),
        "frames_occluded": n[True],
        "frames_clear": n[False],
    }


def _trackeval_data(frames: Sequence[FrameRecord]) -> dict:
    gt_map = {g: i for i, g in enumerate(sorted({int(x) for f in frames for x in f.gt_ids}))}
    tr_map = {t: i for i, t in enumerate(sorted({int(x) for f in frames for x in f.trk_ids}))}
    return {
        "num_timesteps": len(frames),
        "num_gt_ids": len(gt_map),
        "num_tracker_ids": len(tr_map),
        "num_gt_dets": int(sum(len(f.gt_ids) for f in frames)),
        "num_tracker_dets": int(sum(len(f.trk_ids) for f in frames)),
        "gt_ids": [np.array([gt_map[int(x)] for x in f.gt_ids], int) for f in frames],
        "tracker_ids": [np.array([tr_map[int(x)] for x in f.trk_ids], int) for f in frames],
        "similarity_scores": [iou_matrix(f.gt_boxes, f.trk_boxes) for f in frames],
    }


def trackeval_metrics(sequences: Sequence[Sequence[FrameRecord]]) -> dict[str, float]:
    """HOTA, IDF1, MOTA and ID switches over all sequences, computed by TrackEval."""
    with contextlib.redirect_stdout(io.StringIO()):  # TrackEval prints about optional datasets
        from trackeval.metrics import CLEAR, HOTA, Identity

    quiet = {"PRINT_CONFIG": False}
    metrics = {"HOTA": HOTA(quiet), "CLEAR": CLEAR(quiet), "Identity": Identity(quiet)}
    per_seq: dict[str, dict[str, dict]] = {k: {} for k in metrics}
    for i, frames in enumerate(sequences):
        data = _trackeval_data(frames)
        for name, m in metrics.items():
            per_seq[name][f"seq{i}"] = m.eval_sequence(data)
    res = {name: m.combine_sequences(per_seq[name]) for name, m in metrics.items()}
    return {
        "hota": float(np.mean(res["HOTA"]["HOTA"])),
        "deta": float(np.mean(res["HOTA"]["DetA"])),
        "assa": float(np.mean(res["HOTA"]["AssA"])),
        "idf1": float(res["Identity"]["IDF1"]),
        "mota": float(res["CLEAR"]["MOTA"]),
        "id_switches": int(res["CLEAR"]["IDSW"]),
    }
