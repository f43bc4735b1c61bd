"""Pure core of the tracker: joins detections with their camera frame, validates them, runs the
Deep SORT-style tracker, and answers every Detections message with exactly one Tracks message.

Frames (camera/rgbd) are kept in a small buffer keyed by seq; a Detections message names its
frame by ``answers_seq`` and the frame's stamp must match. Without the frame (not received,
evicted, other size) the tracker runs on boxes alone and counts it.

Reported tracks: every confirmed track (matched or coasting through an occlusion, see
``matched`` and ``frames_since_update``) and every tentative track matched in this frame.
IDs are assigned when a track is born and never change, so a consumer may show tentative
tracks or wait for ``confirmed``.
"""

from __future__ import annotations

import math
from collections import Counter, OrderedDict
from typing import Any

import cv2
import numpy as np

from schemas.camera import RgbdFrame
from schemas.perception import Detections, Track, Tracks
from services.runtime import Output, Stamper
from services.tracker import Settings
from services.tracker.appearance import describe_many, to_hsv
from services.tracker.track import Measurement
from services.tracker.tracker import Tracker, TrackerParams

TOPIC_OUT = "perception/tracks"
MIN_DEPTH_PIXELS = 5


def fruit_colour_mask(rgb: np.ndarray) -> np.ndarray:
    """True where a pixel has a fruit's colour (orange to red hue, saturated, not dark)."""
    hsv = to_hsv(rgb)
    orange = cv2.inRange(hsv, (0, 80, 40), (35, 255, 255))
    red = cv2.inRange(hsv, (170, 80, 40), (255, 255, 255))
    return np.asarray(cv2.bitwise_or(orange, red)) != 0


def box_depth_m(
    depth: np.ndarray, rgb: np.ndarray | None, unit_m: float, box: np.ndarray
) -> float | None:
    """Median valid depth of the central half of the box, m, taken on fruit-coloured pixels
    when there are enough of them: a hand or a leaf half covering the fruit is in the box too,
    nearer, and would otherwise pull the depth towards itself. Only the patch's pixels are
    converted to HSV (30 patches cost less than one whole frame)."""
    h, w = depth.shape
    x1, y1, x2, y2 = (float(v) for v in box)
    cx, cy, hw, hh = (x1 + x2) / 2, (y1 + y2) / 2, (x2 - x1) / 4, (y2 - y1) / 4
    a, b = max(0, math.floor(cx - hw)), min(w, math.ceil(cx + hw))
    c, d = max(0, math.floor(cy - hh)), min(h, math.ceil(cy + hh))
    patch = depth[c:d, a:b]
    valid = patch > 0
    if rgb is not None and patch.size:
        fruit = valid & fruit_colour_mask(rgb[c:d, a:b])
        if np.count_nonzero(fruit) >= MIN_DEPTH_PIXELS:
            valid = fruit
    if np.count_nonzero(valid) < MIN_DEPTH_PIXELS:
        return None
    return _median(patch[valid]) * unit_m


def _median(values: np.ndarray) -> float:
    """np.median of a 1-D integer array, to the bit, without its generic machinery (a third
    of the per-box depth time)."""
    n = len(values)
    k = n // 2
    if n % 2:
        return float(np.partition(values, k)[k])
    part = np.partition(values, (k - 1, k))
    return (float(part[k - 1]) + float(part[k])) / 2


class TrackerCore:
    def __init__(self, settings: Settings) -> None:
        from threadpoolctl import threadpool_limits

        # The tracker's matrices are tiny (30 x 30): BLAS worker threads only spin and fight
        # the detector for the 2 cores (measured: 26 ms → 7 ms per frame under load).
        self._blas_limit = threadpool_limits(limits=1, user_api="blas")
        self.s = settings
        self.tracker = Tracker(
            TrackerParams(
                max_cosine_distance=settings.max_cosine_distance,
                max_iou_distance=settings.max_iou_distance,
                max_age=settings.max_age,
                n_init=settings.n_init,
                nn_budget=settings.nn_budget,
                appearance_weight=settings.appearance_weight,
                max_depth_jump_m=settings.max_depth_jump_m,
                depth_smoothing=settings.depth_smoothing,
                min_containment=settings.min_containment,
                max_containment_growth=settings.max_containment_growth,
                coast_velocity_decay=settings.coast_velocity_decay,
                max_shift_sides=settings.max_shift_sides,
                max_depth_step_m=settings.max_depth_step_m,
            )
        )
        self.stamper = Stamper("tracker")
        self.counters: Counter[str] = Counter()
        self.frames: OrderedDict[int, tuple[RgbdFrame, bool]] = OrderedDict()
        self._last: tuple[Track, ...] = ()

    def handle(self, topic: str, msg: Any) -> list[Output]:
        if topic == "camera/rgbd":
            self._keep(msg)
            return []
        return [(TOPIC_OUT, self._track(msg))]

    # ---- frames ----------------------------------------------------------------------------
    def _keep(self, frame: RgbdFrame) -> None:
        if not self.s.use_frames:
            return
        depth_ok = bool(frame.depth.any())
        if not depth_ok:
            self.counters["depth_all_zero"] += 1
        self.frames[frame.header.seq] = (frame, depth_ok)
        while len(self.frames) > self.s.frame_buffer:
            self.frames.popitem(last=False)

    def _frame_for(self, dets: Detections) -> tuple[RgbdFrame | None, bool]:
        if not self.s.use_frames:
            return None, False
        seq = dets.header.answers_seq
        item = self.frames.get(seq) if seq is not None else None
        if item is None or item[0].header.stamp_ns != dets.header.stamp_ns:
            self.counters["frame_missing"] += 1
            return None, False
        frame, depth_ok = item
        if frame.rgb.shape[:2] != (dets.image_height_px, dets.image_width_px):
            self.counters["frame_size_mismatch"] += 1
            return None, False
        # Frames up to this one will not be needed again (detections come in frame order).
        for old in [s for s in self.frames if s <= seq]:  # type: ignore[operator]
            del self.frames[old]
        return frame, depth_ok and self.s.use_depth

    # ---- detections ------------------------------------------------------------------------
    def _valid_box(self, box: tuple[float, ...], w: int, h: int) -> np.ndarray | None:
        x1, y1, x2, y2 = box  # finite floats (the schema checks them)
        m = self.s.box_margin_px
        if x1 < -m or y1 < -m or x2 > w + m or y2 > h + m:
            self.counters["box_outside_image"] += 1
            return None
        x1, x2 = min(max(x1, 0.0), w), min(max(x2, 0.0), w)
        y1, y2 = min(max(y1, 0.0), h), min(max(y2, 0.0), h)
        bw, bh = x2 - x1, y2 - y1
        if min(bw, bh) < self.s.min_box_side_px:
            self.counters["box_too_small"] += 1
            return None
        if bw > self.s.max_box_fraction * w and bh > self.s.max_box_fraction * h:
            self.counters["box_too_large"] += 1
            return None
        return np.array((x1, y1, x2, y2), dtype=np.float64)

    def _track(self, dets: Detections) -> Tracks:
        frame_seq = dets.header.answers_seq if dets.header.answers_seq is not None else 0
        if dets.input_problem:
            # The detector did not look at that frame: do not count it as a frame without fruit.
            self.counters["detector_input_problem"] += 1
            return self._message(dets, frame_seq, self._last, 0, f"detector: {dets.input_problem}")
        frame, depth_ok = self._frame_for(dets)
        w, h = dets.image_width_px, dets.image_height_px
        boxes, scores, rejected = [], [], 0
        for d in dets.detections:
            box = self._valid_box(d.xyxy_px, w, h)
            if box is None:
                rejected += 1
                continue
            boxes.append(box)
            scores.append(d.score)
        rgb = frame.rgb if frame is not None else None
        feats = describe_many(rgb, np.array(boxes)) if rgb is not None else [None] * len(boxes)
        depths: list[float | None] = [None] * len(boxes)
        if depth_ok and frame is not None:
            unit = frame.meta.depth_unit_m
            depths = [box_depth_m(frame.depth, rgb, unit, b) for b in boxes]
        ms = [Measurement(*m) for m in zip(boxes, scores, feats, depths, strict=True)]
        self.tracker.predict()
        self.tracker.update(ms)
        self._last = self._report(frame)
        return self._message(dets, frame_seq, self._last, rejected, "")

    def _report(self, frame: RgbdFrame | None) -> tuple[Track, ...]:
        intr = frame.meta.intrinsics if frame is not None else None
        out = []
        for t in sorted(self.tracker.tracks, key=lambda t: t.track_id):
            if not (t.confirmed or t.time_since_update == 0):
                continue
            x1, y1, x2, y2 = (round(v, 2) for v in t.xyxy_floats())
            pos = None
            depth = None if t.depth_m is None else round(t.depth_m, 4)
            if depth is not None and intr is not None:
                u, v = (x1 + x2) / 2, (y1 + y2) / 2
                pos = (
                    round((u - intr.cx_px) / intr.fx_px * depth, 4),
                    round((v - intr.cy_px) / intr.fy_px * depth, 4),
                    depth,
                )
            out.append(
                Track(
                    track_id=t.track_id,
                    xyxy_px=(x1, y1, max(x1, x2), max(y1, y2)),
                    score=round(float(np.clip(t.score, 0, 1)), 4),
                    confirmed=t.confirmed,
                    age_frames=t.age,
                    frames_since_update=t.time_since_update,
                    matched=t.time_since_update == 0,
                    position_cam_m=pos,
                    depth_m=depth,
                )
            )
        return tuple(out)

    def _message(
        self,
        dets: Detections,
        frame_seq: int,
        tracks: tuple[Track, ...],
        rejected: int,
        problem: str,
    ) -> Tracks:
        return Tracks(
            header=self.stamper.answer(TOPIC_OUT, dets.header),
            frame_seq=frame_seq,
            tracks=tracks,
            rejected_detections=rejected,
            input_problem=problem,
        )
