"""Pure core of the demo worker, plus a deliberate wall-clock delay that must not matter."""

from __future__ import annotations

import math
import random
import time

from schemas.service import DemoAnswer, DemoTick
from services.demo_worker import Settings
from services.runtime import Output, Stamper


class DemoWorkerCore:
    def __init__(self, settings: Settings) -> None:
        self.s = settings
        self.state = 1
        self.stamper = Stamper("demo_worker")
        # Unseeded on purpose: timing jitter is the thing lock-step must make irrelevant.
        self._jitter = random.Random()

    def handle(self, topic: str, msg: DemoTick) -> list[Output]:
        if self.s.max_delay_ms > 0:
            time.sleep(self._jitter.uniform(0, self.s.max_delay_ms) * 1e-3)
        self.state = (self.state * 31 + msg.tick + 7) % self.s.modulus
        x = msg.value * 3.0 + self.state * 1e-6
        result = math.sin(x) if math.isfinite(x) else 0.0  # a huge valid value overflows to inf
        h = self.stamper.answer("demo/answer", msg.header)
        return [
            (
                "demo/answer",
                DemoAnswer(header=h, tick=msg.tick, result=result, worker_state=self.state),
            )
        ]
