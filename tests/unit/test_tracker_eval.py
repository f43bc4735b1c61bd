"""Tracker evaluation: the paper's correct-ID share and TrackEval's metrics on known cases."""

from __future__ import annotations

import numpy as np

from services.tracker.evaluate import (
    FrameRecord,
    majority_assignment,
    paper_metric,
    trackeval_metrics,
)

BOXES = np.array([[0, 0, 10, 10], [20, 20, 30, 30]], float)


def frames(ids: list[tuple[int, int]], occluded: bool) -> list[FrameRecord]:
    return [FrameRecord(np.array([1, 2]), BOXES, np.array(p), BOXES, occluded) for p in ids]


def test_perfect_tracking_scores_one_everywhere() -> None:
    seq = frames([(7, 8)] * 20, False) + frames([(7, 8)] * 5, True)
    p = paper_metric(seq)
    assert p["id_correct_clear"] == p["id_correct_occluded"] == 1.0
    t = trackeval_metrics([seq])
    assert t["hota"] > 0.99 and t["idf1"] == 1.0 and t["mota"] == 1.0 and t["id_switches"] == 0


def test_swapped_ids_during_occlusion_fail_those_frames_only() -> None:
    seq = frames([(7, 8)] * 20, False) + frames([(8, 7)] * 5, True) + frames([(7, 8)] * 5, False)
    p = paper_metric(seq)
    assert p["id_correct_clear"] == 1.0 and p["id_correct_occluded"] == 0.0
    assert p["frames_occluded"] == 5 and p["frames_clear"] == 25
    t = trackeval_metrics([seq])
    assert t["id_switches"] == 4 and t["idf1"] < 1.0 and t["hota"] < 0.95


def test_majority_assignment_is_one_to_one() -> None:
    seq = frames([(7, 8)] * 3, False) + frames([(7, 7)] * 0, False)
    seq += [FrameRecord(np.array([2]), BOXES[1:], np.array([7]), BOXES[1:], False)] * 2
    assert majority_assignment(seq) == {1: 7, 2: 8}


def test_a_missing_track_fails_the_frame() -> None:
    seq = frames([(7, 8)] * 4, False)
    seq.append(FrameRecord(np.array([1, 2]), BOXES, np.array([7]), BOXES[:1], False))
    assert paper_metric(seq)["id_correct_clear"] == 0.8


def test_sim_scenarios_pair_each_frame_with_its_truth() -> None:
    from services.tracker.scenarios import make_sequence

    frames = list(make_sequence("occlusion-suite", 0, duration_s=0.4)())
    assert len(frames) == 7  # 15 Hz, from t = 0 to 0.4 s inclusive
    for k, tf in enumerate(frames):
        assert tf.frame.header.seq == k
        assert tf.frame.rgb.shape == (480, 640, 3)
        assert len(tf.fruits) >= 5 and all(0 < frac <= 1 for _, _, frac in tf.fruits)
