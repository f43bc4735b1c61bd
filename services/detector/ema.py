"""An exponential moving average of the network's weights (the model that is validated and shipped).

Small data sets make the last SGD iterate noisy; the average of the recent iterates generalises
better at no training cost (Polyak averaging, the YOLOv5 / timm ``ModelEMA``). The decay ramps
up from 0 (``decay * (1 - exp(-updates / ramp))``) so the average does not remember the random
initialisation. Batch-norm statistics are averaged with the weights.
"""

from __future__ import annotations

import copy
import math
from typing import Any

import torch
from torch import nn


class WeightAverage:
    """EMA of every floating-point entry of a module's state dict (parameters and BN buffers)."""

    def __init__(self, net: nn.Module, decay: float = 0.998, ramp_updates: float = 400.0) -> None:
        if not 0.0 <= decay < 1.0:
            raise ValueError(f"EMA decay {decay}: must be in [0, 1)")
        self.model = copy.deepcopy(net).eval()
        for p in self.model.parameters():
            p.requires_grad_(False)
        self.decay = decay
        self.ramp_updates = ramp_updates
        self.updates = 0

    def current_decay(self) -> float:
        return self.decay * (1.0 - math.exp(-self.updates / self.ramp_updates))

    @torch.no_grad()
    def update(self, net: nn.Module) -> None:
        self.updates += 1
        d = self.current_decay()
        live = net.state_dict()
        for k, v in self.model.state_dict().items():
            if v.dtype.is_floating_point:
                v.mul_(d).add_(live[k].detach(), alpha=1.0 - d)
            else:  # BN's batch counter: take the live one
                v.copy_(live[k])

    def state_dict(self) -> dict[str, Any]:
        return {"model": self.model.state_dict(), "updates": self.updates}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.model.load_state_dict(state["model"])
        self.updates = int(state["updates"])
