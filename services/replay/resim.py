"""Resim: start services fresh on a private bus, feed them their recorded inputs in lock-step,
and diff their outputs against the recording, topic by topic and seq by seq."""

from __future__ import annotations

import json
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from services.bus import Bus, BusError, BusSettings, bus_args
from services.recorder.inspect import RecordingInfo, iter_messages, read_info
from services.registry import SERVICE_MODULES, service_def
from services.replay.player import OutputCollector, Player, PlayStats
from services.runtime.lockstep import LockstepPlan
from services.runtime.spec import NodeSpec, answer_closure, answer_maps
from services.supervisor.process import LogSink, ManagedProcess
from services.supervisor.stack import deep_merge


@dataclass
class TopicDiff:
    topic: str
    recorded: int = 0
    identical: int = 0
    different: int = 0
    missing: int = 0
    extra: int = 0
    after_end: int = 0  # produced past the last recorded seq (a truncated recording)
    first_difference_seq: int | None = None
    first_missing_seq: int | None = None  # the first recorded seq not produced again
    compared: bool = True  # False for wall-clock diagnostics (Topic.deterministic is False)
    not_compared: int = 0  # produced again but not compared (wall-clock diagnostics)

    @property
    def verdict(self) -> str:
        return "compared" if self.compared else "not compared (wall-clock diagnostics)"


@dataclass
class ResimReport:
    recording: str
    services: list[str]
    topics: list[TopicDiff]
    play: PlayStats
    warnings: list[str] = field(default_factory=list)

    @property
    def compared(self) -> list[TopicDiff]:
        """The topics whose payloads must be identical (wall-clock diagnostics left out)."""
        return [t for t in self.topics if t.compared]

    @property
    def identical_ratio(self) -> float:
        rec = sum(t.recorded for t in self.compared)
        return sum(t.identical for t in self.compared) / rec if rec else 1.0

    @property
    def ok(self) -> bool:
        return all(t.different == t.missing == t.extra == 0 for t in self.compared)

    def to_json(self) -> dict[str, Any]:
        return {
            "recording": self.recording,
            "services": self.services,
            "identical_ratio": self.identical_ratio,
            "ok": self.ok,
            "topics": [{**asdict(t), "verdict": t.verdict} for t in self.topics],
            "play": asdict(self.play),
            "warnings": self.warnings,
        }


class ResimError(RuntimeError):
    """Resim could not run (services did not start, bad recording)."""


def _recorded_settings(
    info: RecordingInfo, names: list[str], warn: list[str], overrides: dict[str, dict[str, Any]]
) -> dict[str, str]:
    """Each service's settings as recorded, with ``overrides`` (service → settings) on top."""
    recorded = info.run_json("services", {}) or {}
    assert isinstance(recorded, dict)
    out = {}
    for n in names:
        base = recorded.get(n)
        if base is None:
            warn.append(f"{n}: no recorded settings; using its defaults")
            base = {}
        out[n] = json.dumps(deep_merge(base, overrides.get(n, {})))
    return out


def _run_specs(info: RecordingInfo, names: list[str]) -> list[NodeSpec]:
    """The specs of every service of the original run (recorded, or under resim now)."""
    recorded = list(json.loads(info.run.get("specs", "{}")))
    everyone = sorted({*recorded, *names} & set(SERVICE_MODULES))
    return [service_def(n).spec for n in everyone]


def _master_plan(info: RecordingInfo, master: str, names: list[str]) -> LockstepPlan:
    """The master waits for the answers of every service of the original run (recorded or
    now provided by the player) and for the other services under test to be live."""
    specs = _run_specs(info, names)
    wait = {t: answer_closure(t, specs) for t in service_def(master).spec.outputs}
    return LockstepPlan(
        wait={k: v for k, v in wait.items() if v}, consumers=tuple(n for n in names if n != master)
    )


def resim(
    path: Path,
    names: list[str],
    timeout_s: float = 10.0,
    overrides: dict[str, dict[str, Any]] | None = None,
    sink: LogSink | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> ResimReport:
    info = read_info(path)
    warn: list[str] = []
    defs = [service_def(n) for n in names]
    if any(d.kind == "process" for d in defs):
        raise ResimError("resim runs services with a core; the recorder/router cannot be resimmed")
    outputs = sorted({t for d in defs for t in d.spec.outputs})
    listened = {t for d in defs for t in d.spec.inputs}
    unknown = set(overrides or {}) - set(names)
    if unknown:
        raise ResimError(f"--set names services not under resim: {', '.join(sorted(unknown))}")
    settings = _recorded_settings(info, names, warn, overrides or {})
    masters = [d.name for d in defs if d.kind == "source"]
    plans = {m: _master_plan(info, m, names) for m in masters}
    for plan in plans.values():
        listened |= {t for answers in plan.wait.values() for t in answers}
    listened -= set(outputs)

    tmp = Path(tempfile.mkdtemp(prefix="resim-"))
    endpoint = f"unixsock-stream/{tmp}/router.sock"
    ns = "resim"
    sink = sink or LogSink(tmp / "resim.log", quiet=True)
    router = ManagedProcess(
        "router", [sys.executable, "-m", "services.router", "-l", endpoint], sink
    )
    procs: list[ManagedProcess] = []
    router.start()
    bus = _connect(BusSettings(mode="client", connect=(endpoint,), namespace=ns), router)
    try:
        live: dict[str, bool] = {}
        lock = threading.Lock()

        def on_health(name: str, up: bool) -> None:
            with lock:
                live[name] = up

        bus.watch_health(on_health)
        collector = OutputCollector(bus, outputs)
        svc_bus = bus_args(BusSettings(mode="client", connect=(endpoint,), namespace=ns))
        defs_started = [d for d in defs if d.kind != "source"] + [
            d for d in defs if d.kind == "source"
        ]
        for d in defs_started:
            argv = [
                sys.executable,
                "-m",
                SERVICE_MODULES[d.name],
                *svc_bus,
                "--time-mode",
                "lockstep",
                "--settings-json",
                settings[d.name],
            ]
            if d.name in plans:
                argv += ["--lockstep-plan", plans[d.name].model_dump_json()]
            p = ManagedProcess(d.name, argv, sink)
            p.start()
            procs.append(p)
            _wait_live(d.name, live, p, timeout_s=60.0)

        def alive() -> bool:
            # A service that finished by itself (exit 0: the planner after its summary) is done,
            # not dead: nothing more will come from it.
            return all(p.running() or p.poll() == 0 for p in procs)

        producer = {t: p for d, p in zip(defs_started, procs, strict=True) for t in d.spec.outputs}

        def producing(topic: str) -> bool:
            # Never wait for an output whose service is gone (finished or dead): it cannot come.
            p = producer.get(topic)
            return alive() and (p is None or p.running())

        caused_by, alongside = answer_maps(listened, _run_specs(info, names))
        player = Player(
            bus,
            lambda t: t in listened,
            set(outputs),
            collector,
            timeout_s,
            producing,
            progress=(lambda i: progress(i, info.message_count)) if progress else None,
            caused_by=caused_by,
            alongside=alongside,
        )
        stats = player.run(iter_messages(path), speed=None)
        if not alive():
            warn.append(
                "a service died during resim: "
                + ", ".join(
                    f"{p.name} (exit {p.poll()}: {' / '.join(p.tail[-2:])})"
                    for p in procs
                    if not p.running() and p.poll() != 0
                )
            )
        time.sleep(0.2)  # let trailing outputs arrive before diffing (they can only add extras)
        diffs = _diff(path, outputs, collector)
    finally:
        for p in reversed(procs):
            p.stop(timeout_s=5.0)
        bus.close()
        router.stop(timeout_s=5.0)
    return ResimReport(str(path), names, diffs, stats, warn)


def _connect(settings: BusSettings, router: ManagedProcess, timeout_s: float = 20.0) -> Bus:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return Bus("resim", settings)
        except BusError:
            if router.poll() is not None or time.monotonic() > deadline:
                raise ResimError(
                    f"private router did not start: {' / '.join(router.tail)}"
                ) from None
            time.sleep(0.05)


def _wait_live(name: str, live: dict[str, bool], p: ManagedProcess, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not live.get(name):
        if p.poll() is not None:
            raise ResimError(f"{name} exited with {p.poll()} at start: {' / '.join(p.tail[-3:])}")
        if time.monotonic() > deadline:
            raise ResimError(f"{name} not live after {timeout_s:.0f} s")
        time.sleep(0.02)


def _diff(path: Path, outputs: list[str], collector: OutputCollector) -> list[TopicDiff]:
    """Per output topic: recorded vs produced payloads by seq. Topics whose payloads carry wall
    clock (``Topic.deterministic`` False) are counted but not compared: their differences are
    expected, so they are reported as "not compared (wall-clock diagnostics)"."""
    from schemas.codec import DecodeError
    from schemas.topics import TOPICS

    recorded: dict[str, dict[int, bytes]] = {t: {} for t in outputs}
    for m in iter_messages(path):
        if m.topic in recorded:
            try:
                seq = TOPICS[m.topic].codec.header(m.payload).seq
            except DecodeError:
                continue
            recorded[m.topic].setdefault(seq, m.payload)
    out = []
    for t in outputs:
        rec, got = recorded[t], collector.produced[t].by_seq
        d = TopicDiff(t, recorded=len(rec), compared=TOPICS[t].deterministic)
        for seq, payload in sorted(rec.items()):
            if seq not in got:
                d.missing += 1
                d.first_missing_seq = seq if d.first_missing_seq is None else d.first_missing_seq
            elif not d.compared:
                d.not_compared += 1
            elif got[seq] == payload:
                d.identical += 1
            else:
                d.different += 1
                d.first_difference_seq = (
                    seq if d.first_difference_seq is None else d.first_difference_seq
                )
        last = max(rec, default=-1)
        unrecorded = set(got) - set(rec)
        d.after_end = sum(1 for s in unrecorded if s > last)
        d.extra = len(unrecorded) - d.after_end
        out.append(d)
    return out
