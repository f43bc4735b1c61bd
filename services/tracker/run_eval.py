"""Runs scenario sequences through the detector and tracker cores (in-process, no bus) and
collects what services/tracker/evaluate.py scores, plus per-frame timings."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from schemas.camera import RgbdFrame
from schemas.perception import Detection, Detections
from services.runtime import Output, Stamper
from services.tracker.evaluate import FrameRecord, paper_metric, trackeval_metrics
from services.tracker.scenarios import VISIBLE_MIN, Sequence, TruthFrame


class TruthDetector:
    """Diagnostic stand-in for the detector (``--backend truth``): the visible fruit's true
    boxes (visible fraction >= VISIBLE_MIN), to score the tracker alone."""

    def __init__(self) -> None:
        self.stamper = Stamper("detector")
        self.truth: TruthFrame | None = None

    def handle(self, topic: str, frame: RgbdFrame) -> list[Output]:
        assert self.truth is not None and self.truth.frame is frame
        h, w = frame.rgb.shape[:2]
        dets = tuple(
            Detection(xyxy_px=tuple(float(v) for v in b), score=1.0)  # type: ignore[arg-type]
            for _, b, frac in self.truth.fruits
            if frac >= VISIBLE_MIN
        )
        msg = Detections(
            header=self.stamper.answer("perception/detections", frame.header),
            image_width_px=w,
            image_height_px=h,
            detector="truth",
            detections=dets,
        )
        return [("perception/detections", msg)]


@dataclass
class RunStats:
    frames: int = 0
    detector_ms: list[float] = field(default_factory=list)
    tracker_ms: list[float] = field(default_factory=list)


def run_sequence(
    seq: Sequence, detector, tracker, stats: RunStats, on_frame: Callable[[], None] | None = None
) -> list[FrameRecord]:
    """Feed each frame to both cores as the bus would (frame to both, detections to tracker)."""
    records = []
    for tf in seq():
        tracker.handle("camera/rgbd", tf.frame)
        t0 = time.perf_counter()
        if isinstance(detector, TruthDetector):
            detector.truth = tf
        ((_, dets),) = detector.handle("camera/rgbd", tf.frame)
        t1 = time.perf_counter()
        ((_, tracks),) = tracker.handle("perception/detections", dets)
        t2 = time.perf_counter()
        stats.detector_ms.append((t1 - t0) * 1e3)
        stats.tracker_ms.append((t2 - t1) * 1e3)
        stats.frames += 1
        vis = [(i, b) for i, b, frac in tf.fruits if frac >= VISIBLE_MIN]
        shown = [t for t in tracks.tracks if t.matched]
        records.append(
            FrameRecord(
                gt_ids=np.array([i for i, _ in vis], int),
                gt_boxes=np.array([b for _, b in vis], float).reshape(-1, 4),
                trk_ids=np.array([t.track_id for t in shown], int),
                trk_boxes=np.array([t.xyxy_px for t in shown], float).reshape(-1, 4),
                occluded=tf.occluded,
            )
        )
        if on_frame:
            on_frame()
    return records


def summarize(sequences: list[list[FrameRecord]], stats: RunStats) -> dict:
    paper = paper_metric([f for i, s in enumerate(sequences) for f in _tag(s, i)])
    out: dict = {}
    out.update(paper)
    out.update(trackeval_metrics(sequences))
    out["sequences"] = len(sequences)
    out["frames"] = stats.frames
    out["tracker_ms_per_frame"] = float(np.median(stats.tracker_ms)) if stats.tracker_ms else 0.0
    out["detector_ms_per_frame"] = float(np.median(stats.detector_ms)) if stats.detector_ms else 0.0
    return out


def _tag(frames: list[FrameRecord], i: int) -> list[FrameRecord]:
    """Make GT and track IDs unique across sequences before pooling them for the paper metric
    (each sequence has its own fruit and its own tracker)."""
    off = (i + 1) * 1_000_000
    return [
        FrameRecord(f.gt_ids + off, f.gt_boxes, f.trk_ids + off, f.trk_boxes, f.occluded)
        for f in frames
    ]
