"""Loading OrangeNet weights (with checks that name the path and the reason) and running it.

``OrangeDetector.detect(rgb)`` takes a full-size RGB image of any size and returns boxes in its
pixels. Torch threads are fixed and operations are deterministic on CPU, so the same image gives
the same boxes; scores are rounded in the message anyway (see core.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from services.detector.data import letterbox
from services.detector.net import (
    ARCH_NAME,
    ARCH_VERSION,
    NetConfig,
    OrangeNet,
    decode,
    fused_for_inference,
)


class WeightsError(ValueError):
    """A weights file that is missing, unreadable, or does not match the architecture."""


@dataclass(frozen=True)
class LoadedWeights:
    net: OrangeNet
    meta: dict[str, Any]

    @property
    def version(self) -> str:
        return str(self.meta.get("version", "?"))


def save_weights(path: Path, net: OrangeNet, meta: dict[str, Any]) -> None:
    """Save the state dict (fp32) with the architecture name, version and config."""
    sd = {k: v.detach().to("cpu", torch.float32).clone() for k, v in net.state_dict().items()}
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(
        {
            "arch": ARCH_NAME,
            "arch_version": ARCH_VERSION,
            "config": net.cfg.to_dict(),
            "state_dict": sd,
            "meta": meta,
        },
        path,
    )


def load_weights(path: Path) -> LoadedWeights:
    """Build the network from a weights file; WeightsError with the path and the reason."""
    path = Path(path)
    if not path.is_file():
        raise WeightsError(f"weights file {path}: not found")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many kinds for a corrupt file
        raise WeightsError(f"weights file {path}: cannot be read ({exc})") from None
    if not isinstance(blob, dict) or blob.get("arch") != ARCH_NAME:
        got = blob.get("arch") if isinstance(blob, dict) else type(blob).__name__
        raise WeightsError(f"weights file {path}: architecture {got!r}, expected {ARCH_NAME!r}")
    if blob.get("arch_version") != ARCH_VERSION:
        raise WeightsError(
            f"weights file {path}: architecture version {blob.get('arch_version')}, "
            f"this code builds version {ARCH_VERSION}"
        )
    try:
        net = OrangeNet(NetConfig.from_dict(blob["config"]))
        net.load_state_dict(blob["state_dict"], strict=True)
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        reason = str(exc).splitlines()[0][:300]
        raise WeightsError(
            f"weights file {path}: does not match the architecture ({reason})"
        ) from None
    net.eval()
    return LoadedWeights(net, dict(blob.get("meta", {})))


class OrangeDetector:
    """Letterbox → OrangeNet (batch norms folded, channels-last) → peaks → boxes in the
    original image's pixels. The network given is copied, never changed."""

    def __init__(
        self,
        net: OrangeNet,
        score_min: float = 0.3,
        top_k: int = 100,
        device: str | torch.device = "cpu",
    ) -> None:
        self.net = fused_for_inference(net).to(device)
        self.device = torch.device(device)
        self.cfg = net.cfg
        self.score_min = score_min
        self.top_k = top_k

    def detect(self, rgb: np.ndarray) -> np.ndarray:
        """(K, 5) float64: x1, y1, x2, y2 (image pixels, clipped), score; best first."""
        return self.detect_batch([rgb])[0]

    @torch.inference_mode()
    def detect_batch(self, images: list[np.ndarray]) -> list[np.ndarray]:
        canvases, scales = [], []
        for rgb in images:
            c, s = letterbox(rgb, self.cfg.input_w_px, self.cfg.input_h_px)
            canvases.append(c)
            scales.append(s)
        x = torch.from_numpy(np.stack(canvases)).to(self.device)
        x = x.permute(0, 3, 1, 2).float().div_(255.0).contiguous(memory_format=torch.channels_last)
        hm, ltrb = self.net(x)
        out = []
        for rgb, s, d in zip(
            images,
            scales,
            decode(hm, ltrb, self.cfg.stride, self.score_min, self.top_k),
            strict=True,
        ):
            b = d.double().cpu().numpy()
            b[:, :4] /= s
            h, w = rgb.shape[:2]
            b[:, [0, 2]] = b[:, [0, 2]].clip(0, w)
            b[:, [1, 3]] = b[:, [1, 3]].clip(0, h)
            out.append(b)
        return out
