"""Fuzz targets for every registered service and a pool of valid seed messages to mutate.

Seeds come from running the real cores: the sim for a few ticks with every reactive service
answering in lock-step (so a new service in the registry gets seeds of its inputs and adds its
outputs for the next one), plus hand-made plan targets, scenes and tool commands for inputs whose
producer may not be registered yet.
"""

from __future__ import annotations

import io
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from schemas import Header, ToolCommand
from schemas.topics import TOPICS
from services.registry import SERVICE_MODULES, service_def
from services.runtime.node import Output
from services.runtime.settings import load_settings
from services.testkit import FakeNode, run_source
from services.testkit.fuzz import FuzzTarget, Outcome

NO_INPUTS = "no inputs: a source that reads a file or a device"


def seed_pool(ticks: int = 9) -> list[Output]:
    """Valid messages of every topic a registered service consumes, in causal order."""
    from services.controller.scenarios import fruit, harvest_target, scene

    pool: list[Output] = [
        ("scene/state", scene([fruit(1, (0.75, 0.05, 1.05)), fruit(2, (0.8, -0.2, 1.0))])),
        ("plan/target", harvest_target((0.75, 0.05, 1.05), fruit_id=1)),
        (
            "robot/tool",
            ToolCommand(
                header=Header(stamp_ns=0, seq=0, source="planner"), tool="cutter", action="open"
            ),
        ),
    ]
    reactive = [
        n
        for n in SERVICE_MODULES
        if service_def(n).kind == "reactive" and service_def(n).make_core is not None
    ]
    nodes = {n: FakeNode(service_def(n)) for n in reactive}

    def respond(topic: str, msg: Any) -> list[Output]:
        """Every reactive service answers, the answers feed the next ones (one pass)."""
        out: list[Output] = []
        frontier: list[Output] = [(topic, msg)]
        while frontier:
            t, m = frontier.pop(0)
            for node in nodes.values():
                if t in node.sd.spec.inputs:
                    got = [(o.topic, o.msg) for o in node.feed([(t, m)])]
                    out += got
                    frontier += got
        pool.extend(out)
        return out

    for n in SERVICE_MODULES:
        sd = service_def(n)
        if sd.kind == "source" and sd.spec.inputs and sd.make_core is not None:
            settings = load_settings(sd.settings, service=n)
            for e in run_source(sd, settings, respond, max_ticks=ticks):
                pool.append((e.topic, e.msg))
    return pool


def make_target(name: str, workdir: Path) -> FuzzTarget | str:
    """The fuzz target of a registered service, or why it has none."""
    sd = service_def(name)
    if not sd.spec.inputs:
        return NO_INPUTS
    if name == "recorder":
        return _recorder_target()
    if name == "viz":
        return _viz_target(workdir)
    assert sd.make_core is not None, f"{name}: inputs but no core to fuzz"
    core = sd.make_core(load_settings(sd.settings, service=name))
    return FuzzTarget(name, sd.spec.inputs, core.handle)


def _recorder_target() -> FuzzTarget:
    """The recorder writes raw payloads; its writer decodes them to reject bad ones."""
    from services.recorder.writer import RunWriter

    writer = RunWriter(io.BytesIO())

    class RecorderTarget(FuzzTarget):
        def feed_payload(self, topic: str, payload: bytes) -> None:
            self.outcome.cases += 1
            self._write(topic, payload)

        def _feed_msg(self, topic: str, msg: Any) -> None:
            # The recorder keeps every sample, in any order: nothing is dropped before writing.
            self._write(topic, TOPICS[topic].codec.encode(msg))

        def _write(self, topic: str, payload: bytes) -> None:
            try:
                result = writer.write(topic, payload, TOPICS[topic].codec.zenoh_encoding, 1)
            except Exception as exc:
                self.outcome.crashes.append(f"recorder on {topic}: {type(exc).__name__}: {exc}")
                return
            if result == "rejected":
                self.outcome.rejected_decode += 1
            else:
                self.outcome.handled += 1

    return RecorderTarget("recorder", ("**",), lambda t, m: ())


def _viz_target(workdir: Path) -> FuzzTarget:
    """The viz converter, drawing into a file (no viewer)."""
    from services.viz import Settings
    from services.viz.core import Converter
    from services.viz.out import Out
    from services.viz.sink import open_stream

    s = Settings()
    out = Out(open_stream(s, "fuzz", workdir / "fuzz.rrd"))
    conv = Converter(out, s)
    conv.begin()

    def handle(topic: str, msg: Any) -> list[Output]:
        conv.handle(topic, msg)
        out.flush()
        return []

    return FuzzTarget("viz", ("**",), handle)


def fuzz_all(
    cases_per_service: int, seed: int = 0, on_case: Callable[[], None] | None = None
) -> dict[str, Outcome | str]:
    """Every registered service fed ``cases_per_service`` seeded fuzz cases (the benchmark)."""
    import random

    from services.testkit.fuzz import fuzz_step

    pool = seed_pool()
    out: dict[str, Outcome | str] = {}
    with tempfile.TemporaryDirectory(prefix="fuzz-") as d:
        for name in SERVICE_MODULES:
            target = make_target(name, Path(d))
            if isinstance(target, str):
                out[name] = target
                continue
            rng = random.Random(f"{seed}-{name}")
            for _ in range(cases_per_service):
                fuzz_step(target, pool, rng)
                if on_case:
                    on_case()
            out[name] = target.outcome
    return out
