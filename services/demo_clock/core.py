"""Pure core of the demo clock: a closed loop x_{k+1} = f(x_k, answer_k), so a tick processed
with a missing or late answer would change every later value."""

from __future__ import annotations

import numpy as np

from schemas.service import DemoAnswer, DemoTick
from services.demo_clock import Settings
from services.runtime import Output, Stamper


class DemoClockCore:
    def __init__(self, settings: Settings) -> None:
        self.s = settings
        self.k = 0
        self.value = float(np.random.default_rng(settings.seed).uniform(-1.0, 1.0))
        self.stamper = Stamper("demo_clock")
        self.answers_seen = 0

    def done(self) -> bool:
        return self.k >= self.s.ticks

    def now_ns(self) -> int:
        return round(self.k * self.s.period_ms * 1e6)

    def emit(self) -> list[list[Output]]:
        h = self.stamper.header("demo/tick", self.now_ns())
        return [[("demo/tick", DemoTick(header=h, tick=self.k, value=self.value))]]

    def handle(self, topic: str, msg: DemoAnswer) -> list[Output]:
        self.answers_seen += 1
        self.value = float(np.tanh(self.value + self.s.gain * msg.result))
        return []

    def advance(self) -> None:
        self.k += 1
