"""A lock-step graph in one process: a clock-master core and reactive cores, no bus.

Each tick the master's groups are delivered in order; every message goes to every core that
takes its topic (in the order the cores were given), and what a core returns is queued behind
(first in, first out), exactly one router's worth of causal order. The master's own inputs
(commands) are handed to it as they come, before it advances. Used by the harvest benchmark
(many seeds, where process start-up and the bus would cost more than the work) and by tests.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

Tap = Callable[[str, str, Any], None]  # (source, topic, message)


@dataclass
class InprocNode:
    """One reactive core and the topics it takes."""

    name: str
    inputs: Sequence[str]
    core: Any


class InprocGraph:
    """Drive ``master`` (a SourceCore) and ``nodes`` tick by tick."""

    def __init__(
        self,
        master_name: str,
        master: Any,
        master_inputs: Sequence[str],
        nodes: Sequence[InprocNode],
        tap: Tap | None = None,
    ) -> None:
        self.master_name, self.master = master_name, master
        self.master_inputs = set(master_inputs)
        self.nodes = list(nodes)
        self.tap = tap
        self.ticks = 0

    def tick(self) -> None:
        for group in self.master.emit():
            queue: deque[tuple[str, str, Any]] = deque((self.master_name, t, m) for t, m in group)
            while queue:
                src, topic, msg = queue.popleft()
                if self.tap is not None:
                    self.tap(src, topic, msg)
                for node in self.nodes:
                    if topic in node.inputs and node.name != src:
                        queue.extend((node.name, t, m) for t, m in node.core.handle(topic, msg))
                if topic in self.master_inputs and src != self.master_name:
                    queue.extend(
                        (self.master_name, t, m) for t, m in self.master.handle(topic, msg)
                    )
        self.master.advance()
        self.ticks += 1

    def run(self, stop: Callable[[], bool], max_ticks: int) -> int:
        """Tick until ``stop()``, the master is done or ``max_ticks``; returns the ticks run."""
        start = self.ticks
        while self.ticks - start < max_ticks and not self.master.done() and not stop():
            self.tick()
        return self.ticks - start
