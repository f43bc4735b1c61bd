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

import numpy as np

from schemas.camera import RgbdFrame
from schemas.perception import Detections, Track, Tracks
from services.runtime import Output, Stamper
from services.tracker import Settings
from services.tracker.appearance import describe, to_hsv
from services.tracker.track import Measurement
from services.tracker.tracker import Tracker, TrackerParams

TOPIC_OUT = "perception/tracks"
MIN_DEPTH_PIXELS = 5


def box_depth_m(
    depth: np.ndarray, hsv_image: np.ndarray | None, unit_m: float, box: np.ndarray
) -> float | None:
    """Median valid depth of the central half of the box, m, taken on fruit-coloured pixels
    when there are enough of them: a hand or a leaf half covering the fruit is in the box too,
    nearer, and would otherwise pull the depth towards itself."""
    h, w = depth.shape
    x1, y1, x2, y2 = (float(v) for v in box)
    cx, cy, hw, hh = (x1 + x2) / 2, (y1 + y2) / 2, (x2 - x1) / 4, (y2 - y1) / 4
    a, b = max(0, math.floor(cx - hw)), min(w, math.ceil(cx + hw))
    c, d = max(0, math.floor(cy - hh)), min(h, math.ceil(cy + hh))
    patch = depth[c:d, a:b]
    valid = patch > 0
    if hsv_image is not None and patch.size:
        hsv = hsv_image[c:d, a:b]
        fruit = valid & ((hsv[..., 0] <= 35) | (hsv[..., 0] >= 170)) & (hsv[..., 1] >= 80)
        fruit &= hsv[..., 2] >= 40
        if int(fruit.sum()) >= MIN_DEPTH_PIXELS:
            valid = fruit
    if int(valid.sum()) < MIN_DEPTH_PIXELS:
        return None
    return float(np.median(patch[valid])) * unit_m


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
        b = np.asarray(box, dtype=np.float64)
        m = self.s.box_margin_px
        if b[0] < -m or b[1] < -m or b[2] > w + m or b[3] > h + m:
            self.counters["box_outside_image"] += 1
            return None
        b = np.clip(b, 0, [w, h, w, h])
        bw, bh = b[2] - b[0], b[3] - b[1]
        if min(bw, bh) < self.s.min_box_side_px:
            self.counters["box_too_small"] += 1
            return None
        if bw > self.s.max_box_fraction * w and bh > self.s.max_box_fraction * h:
            self.counters["box_too_large"] += 1
            return None
        return b

    def _track(self, dets: Detections) -> Tracks:
        frame_seq = dets.header.answers_seq if dets.header.answers_seq is not None else 0
        if dets.input_problem:
            # The detector did not look at that frame: do not count it as a frame without fruit.
            self.counters["detector_input_problem"] += 1
            return self._message(dets, frame_seq, self._last, 0, f"detector: {dets.input_problem}")
        frame, depth_ok = self._frame_for(dets)
        w, h = dets.image_width_px, dets.image_height_px
        ms, rejected = [], 0
        hsv = to_hsv(frame.rgb) if frame is not None and dets.detections else None
        for d in dets.detections:
            box = self._valid_box(d.xyxy_px, w, h)
            if box is None:
                rejected += 1
                continue
            feat = describe(hsv, box) if hsv is not None else None
            depth = (
                box_depth_m(frame.depth, hsv, frame.meta.depth_unit_m, box)
                if depth_ok and frame is not None
                else None
            )
            ms.append(Measurement(box, d.score, feat, depth))
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
            x1, y1, x2, y2 = (round(float(v), 2) for v in t.xyxy())
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
