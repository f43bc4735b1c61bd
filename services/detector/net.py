"""OrangeNet: a compact single-stage, anchor-free detector (TTFNet/CenterNet-style) in torch.

The network sees a letterboxed RGB canvas (default 320x240) and predicts, at stride 4, a centre
heat-map (one class) and the distances from each cell to the box's left, top, right and bottom
edges. Decoding keeps local maxima of the heat-map (3x3 max-pool, the CenterNet "NMS"), so the
whole detector is free of anchors and of a separate NMS step.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass

import torch
from torch import nn
from torch.nn import functional as F  # noqa: N812 (the torch convention)

ARCH_NAME = "orange-ttf"
ARCH_VERSION = 1


@dataclass(frozen=True)
class NetConfig:
    """Architecture hyper-parameters; saved with the weights and checked when they are loaded."""

    widths: tuple[int, int, int, int] = (16, 40, 80, 160)  # channels at strides 2, 4, 8, 16
    blocks: tuple[int, int, int] = (1, 2, 3)  # residual blocks at strides 4, 8, 16
    neck: int = 64  # channels of the upsampling path and the heads
    input_w_px: int = 320
    input_h_px: int = 240
    stride: int = 4

    def to_dict(self) -> dict:
        return asdict(self)

    @staticmethod
    def from_dict(d: dict) -> NetConfig:
        return NetConfig(
            widths=tuple(d["widths"]),
            blocks=tuple(d["blocks"]),
            neck=int(d["neck"]),
            input_w_px=int(d["input_w_px"]),
            input_h_px=int(d["input_h_px"]),
            stride=int(d["stride"]),
        )


def _cbr(cin: int, cout: int, k: int = 3, s: int = 1, groups: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, k, s, k // 2, groups=groups, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    )


class _Residual(nn.Module):
    """A basic residual block (two 3x3 convolutions)."""

    def __init__(self, c: int) -> None:
        super().__init__()
        self.a = _cbr(c, c)
        self.b = nn.Sequential(nn.Conv2d(c, c, 3, 1, 1, bias=False), nn.BatchNorm2d(c))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(x + self.b(self.a(x)))


class _SepConv(nn.Sequential):
    """Depthwise 3x3 + pointwise 1x1: cheap spatial mixing at stride 4, where pixels are many."""

    def __init__(self, cin: int, cout: int) -> None:
        super().__init__(_cbr(cin, cin, 3, 1, groups=cin), _cbr(cin, cout, 1))


class OrangeNet(nn.Module):
    """Backbone (strided residual stages) + top-down neck to stride 4 + two heads."""

    def __init__(self, cfg: NetConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg = cfg or NetConfig()
        w2, w4, w8, w16 = cfg.widths
        b4, b8, b16 = cfg.blocks
        self.stem = _cbr(3, w2, 3, 2)
        self.s4 = nn.Sequential(_cbr(w2, w4, 3, 2), *[_Residual(w4) for _ in range(b4)])
        self.s8 = nn.Sequential(_cbr(w4, w8, 3, 2), *[_Residual(w8) for _ in range(b8)])
        self.s16 = nn.Sequential(_cbr(w8, w16, 3, 2), *[_Residual(w16) for _ in range(b16)])
        # Context: a dilated conv widens the receptive field at stride 16 for large fruit.
        self.ctx = nn.Sequential(
            nn.Conv2d(w16, w16, 3, 1, padding=2, dilation=2, bias=False),
            nn.BatchNorm2d(w16),
            nn.ReLU(inplace=True),
        )
        n = cfg.neck
        self.lat16 = _cbr(w16, n, 1)
        self.lat8 = _cbr(w8, n, 1)
        self.lat4 = _cbr(w4, n, 1)
        self.fuse8 = _SepConv(n, n)
        self.fuse4 = _SepConv(n, n)
        self.hm_head = nn.Sequential(_SepConv(n, n), nn.Conv2d(n, 1, 1))
        self.box_head = nn.Sequential(_SepConv(n, n), nn.Conv2d(n, 4, 1))
        self._init_heads()

    def _init_heads(self) -> None:
        # Focal-loss prior: start with p(orange) ~ 0.01 everywhere (RetinaNet / CenterNet).
        last = self.hm_head[-1]
        assert isinstance(last, nn.Conv2d) and last.bias is not None
        nn.init.constant_(last.bias, -4.6)
        box = self.box_head[-1]
        assert isinstance(box, nn.Conv2d) and box.bias is not None
        nn.init.constant_(box.bias, 0.0)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """x: (N, 3, H, W) float in [0, 1]. Returns heat-map logits (N, 1, H/4, W/4) and
        edge distances (N, 4, H/4, W/4) in pixels of the input canvas (ltrb, >= 0)."""
        x = (x - 0.45) / 0.25
        f4 = self.s4(self.stem(x))
        f8 = self.s8(f4)
        f16 = self.ctx(self.s16(f8))
        p = self.lat16(f16)
        p = self.fuse8(self.lat8(f8) + F.interpolate(p, size=f8.shape[-2:], mode="nearest"))
        p = self.fuse4(self.lat4(f4) + F.interpolate(p, size=f4.shape[-2:], mode="nearest"))
        hm = self.hm_head(p)
        # Distances in units of 16 px through softplus: positive, smooth, scale-friendly.
        ltrb = F.softplus(self.box_head(p)) * 16.0
        return hm, ltrb


def fused_for_inference(net: OrangeNet) -> OrangeNet:
    """A copy of the network in eval mode with every batch norm folded into the convolution
    before it, in channels-last memory: the same function (to float rounding), ~25 % faster on
    CPU. The original is left untouched (training goes on with it)."""
    out = copy.deepcopy(net).eval()
    for m in out.modules():
        if (
            isinstance(m, nn.Sequential)
            and len(m) >= 2
            and isinstance(m[0], nn.Conv2d)
            and isinstance(m[1], nn.BatchNorm2d)
        ):
            m[0] = torch.nn.utils.fusion.fuse_conv_bn_eval(m[0], m[1])
            m[1] = nn.Identity()
    return out.to(memory_format=torch.channels_last)  # type: ignore[call-overload]


def decode(
    hm_logits: torch.Tensor,
    ltrb: torch.Tensor,
    stride: int,
    score_min: float,
    top_k: int,
) -> list[torch.Tensor]:
    """Peaks of the heat-map → boxes. Returns per image a (K, 5) tensor x1, y1, x2, y2, score in
    canvas pixels, sorted by score then position (deterministic order)."""
    heat = torch.sigmoid(hm_logits)
    peaks = heat * (F.max_pool2d(heat, 3, 1, 1) == heat)
    n, _, _, w = heat.shape
    out = []
    flat = peaks.view(n, -1)
    k = min(top_k, flat.shape[1])
    scores, idx = torch.topk(flat, k, dim=1, sorted=True)
    for i in range(n):
        keep = scores[i] >= score_min
        s, j = scores[i][keep], idx[i][keep]
        ys, xs = (j // w).float(), (j % w).float()
        cx, cy = (xs + 0.5) * stride, (ys + 0.5) * stride
        d = ltrb[i].view(4, -1)[:, j]
        boxes = torch.stack((cx - d[0], cy - d[1], cx + d[2], cy + d[3], s), dim=1)
        out.append(boxes)
    return out
