"""Detector evaluation: COCO AP (pycocotools), precision/recall at the operating threshold, speed.

AP50 and AP50:95 are pycocotools' numbers (101-point interpolation, maxDets 100, one class,
area "all"). Precision and recall use the detector's operating threshold and greedy matching
by score at IoU >= 0.5 (each ground-truth box matched at most once).
"""

from __future__ import annotations

import contextlib
import io
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from services.detector.data import Sample

Detect = Callable[[np.ndarray], np.ndarray]
"""rgb (H, W, 3) uint8 → (K, 5) x1, y1, x2, y2, score in image pixels."""


@dataclass(frozen=True)
class DetectorMetrics:
    images: int
    boxes: int
    detections: int
    ap50: float
    ap50_95: float
    # AP at IoU 0.3 and the median size of matched boxes (IoU >= 0.3, operating threshold)
    # over their labels': where AP50 is low but AP30 high and the ratios far from 1, the
    # labels draw boxes of another size than the detector (a label style), not missed fruit.
    ap30: float
    box_width_ratio: float
    box_height_ratio: float
    precision: float
    recall: float
    score_threshold: float
    ms_per_frame: float
    ms_per_frame_p90: float

    def to_json(self) -> dict:
        return asdict(self)


def iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of every box in a (N, 4) with every box in b (M, 4), xyxy."""
    if len(a) == 0 or len(b) == 0:
        return np.zeros((len(a), len(b)))
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:4], b[None, :, 2:4])
    inter = np.prod(np.clip(rb - lt, 0, None), axis=2)
    area_a = np.prod(a[:, 2:4] - a[:, :2], axis=1)
    area_b = np.prod(b[:, 2:4] - b[:, :2], axis=1)
    return inter / np.maximum(area_a[:, None] + area_b[None, :] - inter, 1e-12)


def greedy_matches(gt: np.ndarray, det: np.ndarray, iou_min: float = 0.5) -> int:
    """True positives: detections (sorted by score) matched greedily to unmatched GT boxes."""
    if len(gt) == 0 or len(det) == 0:
        return 0
    order = np.argsort(-det[:, 4], kind="stable")
    ious = iou_matrix(det[order, :4], gt)
    used = np.zeros(len(gt), bool)
    tp = 0
    for row in ious:
        row = np.where(used, -1.0, row)
        j = int(np.argmax(row))
        if row[j] >= iou_min:
            used[j] = True
            tp += 1
    return tp


def coco_ap(gts: Sequence[np.ndarray], dets: Sequence[np.ndarray]) -> tuple[float, float]:
    """(AP50, AP50:95) by pycocotools for one class; gts (N, 4), dets (K, 5) per image."""
    aps = coco_aps(gts, dets)
    return aps["ap50"], aps["ap50_95"]


def coco_aps(gts: Sequence[np.ndarray], dets: Sequence[np.ndarray]) -> dict[str, float]:
    """AP30, AP50 and AP50:95 by pycocotools (all areas, 100 detections per image)."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    images: list[dict] = []
    anns: list[dict] = []
    results: list[dict] = []
    for i, (g, d) in enumerate(zip(gts, dets, strict=True)):
        images.append({"id": i + 1})
        for b in g:
            w, h = float(b[2] - b[0]), float(b[3] - b[1])
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": i + 1,
                    "category_id": 1,
                    "bbox": [float(b[0]), float(b[1]), w, h],
                    "area": w * h,
                    "iscrowd": 0,
                }
            )
        for b in d:
            results.append(
                {
                    "image_id": i + 1,
                    "category_id": 1,
                    "bbox": [float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])],
                    "score": float(b[4]),
                }
            )
    if not anns:
        return dict.fromkeys(("ap30", "ap50", "ap50_95"), float("nan"))
    if not results:
        return dict.fromkeys(("ap30", "ap50", "ap50_95"), 0.0)
    with contextlib.redirect_stdout(io.StringIO()):  # pycocotools prints its progress
        gt = COCO()
        gt.dataset = {"images": images, "annotations": anns, "categories": [{"id": 1}]}
        gt.createIndex()
        dt = gt.loadRes(results)
        ev = COCOeval(gt, dt, "bbox")
        # 0.3 ahead of COCO's ten thresholds: each threshold is matched on its own, so the
        # others' figures are what summarize() gives without it.
        ev.params.iouThrs = np.concatenate([[0.3], ev.params.iouThrs])
        ev.evaluate()
        ev.accumulate()
    # precision[T, recall, class, area, max detections]: area "all", 100 detections.
    p = ev.eval["precision"][:, :, 0, 0, -1]

    def mean(a: np.ndarray) -> float:
        a = a[a > -1]
        return float(a.mean()) if a.size else -1.0

    return {"ap30": mean(p[0]), "ap50": mean(p[1]), "ap50_95": mean(p[1:])}


def box_size_ratios(
    gts: Sequence[np.ndarray], dets: Sequence[np.ndarray], iou_min: float = 0.3
) -> tuple[float, float]:
    """Median width and height of detections over their label's, for each label's best
    detection with IoU >= iou_min (nan where none)."""
    w, h = [], []
    for g, d in zip(gts, dets, strict=True):
        ious = iou_matrix(g, d[:, :4])
        for i in range(len(g)):
            if ious.shape[1] == 0 or ious[i].max() < iou_min:
                continue
            b = d[int(ious[i].argmax())]
            w.append((b[2] - b[0]) / max(g[i, 2] - g[i, 0], 1e-9))
            h.append((b[3] - b[1]) / max(g[i, 3] - g[i, 1], 1e-9))
    nan = float("nan")
    return (float(np.median(w)), float(np.median(h))) if w else (nan, nan)


def evaluate(
    samples: Sequence[Sample],
    detect_all: Detect,
    score_threshold: float,
    progress: Callable[[int], None] | None = None,
) -> DetectorMetrics:
    """Run ``detect_all`` (low threshold, for AP) on every image, timing each call."""
    gts, dets, ops, ms = [], [], [], []
    tp = n_det = 0
    for i, s in enumerate(samples):
        rgb = s.load_rgb()
        t0 = time.perf_counter()
        d = detect_all(rgb)
        ms.append((time.perf_counter() - t0) * 1e3)
        gts.append(s.boxes_xyxy_px)
        dets.append(d)
        op = d[d[:, 4] >= score_threshold]
        ops.append(op)
        n_det += len(op)
        tp += greedy_matches(s.boxes_xyxy_px, op)
        if progress:
            progress(i + 1)
    aps = coco_aps(gts, dets)
    w_ratio, h_ratio = box_size_ratios(gts, ops)
    n_gt = int(sum(len(g) for g in gts))
    return DetectorMetrics(
        images=len(samples),
        boxes=n_gt,
        detections=n_det,
        ap50=aps["ap50"],
        ap50_95=aps["ap50_95"],
        ap30=aps["ap30"],
        box_width_ratio=w_ratio,
        box_height_ratio=h_ratio,
        precision=tp / n_det if n_det else 0.0,
        recall=tp / n_gt if n_gt else 0.0,
        score_threshold=score_threshold,
        ms_per_frame=float(np.median(ms)) if ms else 0.0,
        ms_per_frame_p90=float(np.percentile(ms, 90)) if ms else 0.0,
    )
