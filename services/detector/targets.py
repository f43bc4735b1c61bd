"""Training targets and losses of OrangeNet (TTFNet-style: Gaussian centre heat-map + GIoU).

For each box, a Gaussian of the box's shape (sigma = alpha * side / 6) marks its centre on the
stride-4 grid; the heat-map target is the maximum over boxes. The cells inside the box's
Gaussian area (beta) regress the distances to the four box edges with a GIoU loss, weighted by
the Gaussian and by log(box area) so that large and small fruit both matter.
"""

from __future__ import annotations

import numpy as np
import torch

ALPHA = 0.54
BETA = 0.54


def _gaussian(h: int, w: int, cy: float, cx: float, sy: float, sx: float) -> np.ndarray:
    ys = np.arange(h, dtype=np.float32)[:, None]
    xs = np.arange(w, dtype=np.float32)[None, :]
    return np.exp(-((xs - cx) ** 2) / (2 * sx * sx) - ((ys - cy) ** 2) / (2 * sy * sy))


def make_targets(
    boxes: np.ndarray, out_h: int, out_w: int, stride: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heat-map (1, h, w), box target (4, h, w) xyxy canvas px, regression weight (1, h, w)."""
    heat = np.zeros((out_h, out_w), np.float32)
    box_t = np.zeros((4, out_h, out_w), np.float32)
    weight = np.zeros((out_h, out_w), np.float32)
    if len(boxes):
        areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
        # Large first, so that smaller boxes overwrite the regression target where they overlap.
        for k in np.argsort(-areas, kind="stable"):
            x1, y1, x2, y2 = boxes[k]
            bw, bh = (x2 - x1) / stride, (y2 - y1) / stride
            cx, cy = (x1 + x2) / 2 / stride - 0.5, (y1 + y2) / 2 / stride - 0.5
            g = _gaussian(out_h, out_w, cy, cx, max(ALPHA * bh / 6, 0.4), max(ALPHA * bw / 6, 0.4))
            heat = np.maximum(heat, g)
            ga = _gaussian(out_h, out_w, cy, cx, max(BETA * bh / 6, 0.4), max(BETA * bw / 6, 0.4))
            ix, iy = int(np.clip(round(cx), 0, out_w - 1)), int(np.clip(round(cy), 0, out_h - 1))
            ga[iy, ix] = max(ga[iy, ix], 1.0)  # a tiny box still owns its centre cell
            region = ga > 0.3
            if not region.any():
                continue
            wk = ga * region
            wk = wk / wk.sum() * np.log(max(float(areas[k]), 2.0))
            box_t[:, region] = boxes[k][:, None]
            weight[region] = wk[region]
            heat[iy, ix] = 1.0
    return heat[None], box_t, weight[None]


def focal_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """CenterNet's penalty-reduced focal loss (alpha 2, beta 4), normalised by the peak count."""
    p = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
    pos = target.eq(1.0).float()
    neg = 1.0 - pos
    pos_loss = torch.log(p) * (1 - p) ** 2 * pos
    neg_loss = torch.log(1 - p) * p**2 * (1 - target) ** 4 * neg
    n = pos.sum().clamp(min=1.0)
    return -(pos_loss.sum() + neg_loss.sum()) / n


def giou_loss(
    ltrb: torch.Tensor, box_t: torch.Tensor, weight: torch.Tensor, stride: int
) -> torch.Tensor:
    """Weighted GIoU loss of the boxes predicted at weighted cells against their targets."""
    n, _, h, w = ltrb.shape
    mask = weight > 0
    if not mask.any():
        return ltrb.sum() * 0.0
    ys = (torch.arange(h, device=ltrb.device, dtype=ltrb.dtype) + 0.5) * stride
    xs = (torch.arange(w, device=ltrb.device, dtype=ltrb.dtype) + 0.5) * stride
    cy, cx = torch.meshgrid(ys, xs, indexing="ij")
    m = mask[:, 0]
    pred = torch.stack(
        (
            cx[None].expand(n, h, w)[m] - ltrb[:, 0][m],
            cy[None].expand(n, h, w)[m] - ltrb[:, 1][m],
            cx[None].expand(n, h, w)[m] + ltrb[:, 2][m],
            cy[None].expand(n, h, w)[m] + ltrb[:, 3][m],
        ),
        1,
    )
    tgt = box_t.permute(0, 2, 3, 1)[m]
    wgt = weight[:, 0][m]
    lt = torch.max(pred[:, :2], tgt[:, :2])
    rb = torch.min(pred[:, 2:], tgt[:, 2:])
    inter = (rb - lt).clamp(min=0).prod(1)
    ap = (pred[:, 2:] - pred[:, :2]).clamp(min=0).prod(1)
    at = (tgt[:, 2:] - tgt[:, :2]).clamp(min=0).prod(1)
    union = ap + at - inter + 1e-6
    iou = inter / union
    elt = torch.min(pred[:, :2], tgt[:, :2])
    erb = torch.max(pred[:, 2:], tgt[:, 2:])
    enclose = (erb - elt).clamp(min=0).prod(1) + 1e-6
    giou = iou - (enclose - union) / enclose
    return ((1 - giou) * wgt).sum() / wgt.sum().clamp(min=1e-6)
