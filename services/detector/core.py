"""Pure core of the detector: one Detections message per camera frame, also when empty.

A frame the detector cannot use (wrong size, blank) is answered with an empty Detections whose
``input_problem`` says why, and the reason is counted; lock-step needs one answer per frame.
Boxes and scores are rounded (0.01 px, 1e-4) so payloads are byte-identical between runs.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from schemas.camera import RgbdFrame
from schemas.perception import Detection, Detections
from services.detector import Settings
from services.runtime import ConfigError, Output, Stamper

TOPIC_OUT = "perception/detections"
MIN_SIDE_PX = 16


def _resolve(path: Path) -> Path:
    from services.detector.paths import REPO_ROOT

    return path if path.is_absolute() else REPO_ROOT / path


class DetectorCore:
    def __init__(self, settings: Settings) -> None:
        self.s = settings
        self.stamper = Stamper("detector")
        self.counters: Counter[str] = Counter()
        self.threshold = 0.0
        self.detect, self.name = self._build(settings)

    def _build(self, s: Settings):
        if s.backend == "hsv":
            from services.detector.hsv import HsvDetector

            hsv = HsvDetector(
                s.hsv_hue_range, s.hsv_sat_min, s.hsv_val_min, s.hsv_min_area_px, s.max_detections
            )
            self.threshold = threshold = s.score_threshold or 0.0
            return (lambda rgb: _above(hsv.detect(rgb), threshold)), "hsv"
        import torch

        from services.detector.infer import OrangeDetector, WeightsError, load_weights

        torch.set_num_threads(s.torch_threads)
        torch.use_deterministic_algorithms(True)
        try:
            w = load_weights(_resolve(s.weights_path))
        except WeightsError as exc:
            raise ConfigError(str(exc)) from None
        threshold = (
            float(w.meta.get("score_threshold", 0.3))
            if s.score_threshold is None
            else s.score_threshold
        )
        self.threshold = threshold
        det = OrangeDetector(w.net, score_min=threshold, top_k=s.max_detections)
        return det.detect, f"net:{w.version}"

    def _problem(self, frame: RgbdFrame) -> str:
        h, w = frame.rgb.shape[:2]
        if self.s.expected_size_px is not None and (w, h) != tuple(self.s.expected_size_px):
            ew, eh = self.s.expected_size_px
            return f"wrong_size: frame is {w}x{h} px, expected {ew}x{eh}"
        if min(w, h) < MIN_SIDE_PX:
            return f"too_small: frame is {w}x{h} px"
        rgb = frame.rgb
        if int(rgb.max()) == int(rgb.min()):
            return "blank: every pixel has the same value (dead sensor or corrupted frame)"
        return ""

    def handle(self, topic: str, frame: RgbdFrame) -> list[Output]:
        h, w = frame.rgb.shape[:2]
        problem = self._problem(frame)
        dets: tuple[Detection, ...] = ()
        if problem:
            self.counters[problem.split(":")[0]] += 1
        else:
            if not frame.depth.any():
                # The network does not use depth; count it for the operator and go on.
                self.counters["depth_all_zero"] += 1
            dets = _to_messages(self.detect(frame.rgb), w, h)
        msg = Detections(
            header=self.stamper.answer(TOPIC_OUT, frame.header),
            image_width_px=w,
            image_height_px=h,
            detector=self.name,
            detections=dets,
            input_problem=problem,
        )
        return [(TOPIC_OUT, msg)]


def _above(d: np.ndarray, threshold: float) -> np.ndarray:
    return d[d[:, 4] >= threshold]


def _to_messages(d: np.ndarray, w: int, h: int) -> tuple[Detection, ...]:
    out = []
    for x1, y1, x2, y2, s in d:
        box = (
            round(float(np.clip(x1, 0, w)), 2),
            round(float(np.clip(y1, 0, h)), 2),
            round(float(np.clip(x2, 0, w)), 2),
            round(float(np.clip(y2, 0, h)), 2),
        )
        if box[2] - box[0] < 1.0 or box[3] - box[1] < 1.0:
            continue  # a degenerate box carries no fruit
        out.append(Detection(xyxy_px=box, score=round(float(np.clip(s, 0, 1)), 4)))
    return tuple(out)
