"""python -m services.viz [bus flags] [--settings-json JSON]: draw the live run in Rerun.

Subscribes to the whole namespace, decodes every sample of the topic map and hands it to the
conversion core (core.py) on one worker thread; the viewer (spawned, served or connected) and/or
an .rrd file get the stream (settings `viewer`, `save_path`). Publishes nothing and answers
nothing, so it never slows a lock-step run. Finishes the .rrd on SIGTERM/SIGINT.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import time
from collections import deque

from schemas.codec import DecodeError
from schemas.service import ServiceState, ServiceStatus
from schemas.topics import TOPICS
from services import __version__
from services.bus import Bus, BusError, RawSample, add_bus_args, bus_settings_from_args
from services.runtime.service import add_service_args, resolve_settings, setup_logging
from services.runtime.settings import SettingsError, config_hash
from services.viz import SERVICE, Settings
from services.viz.core import Converter
from services.viz.out import Out
from services.viz.sink import SinkError, open_stream

log = logging.getLogger("viz")

FRAME_TOPIC = "camera/rgbd"
FLUSH_EVERY_S = 0.2  # buffered plots and poses reach the viewer this often (their latency)


class LiveViz:
    """A queue fed by Zenoh callbacks, drained by one worker thread into the converter."""

    def __init__(self, bus: Bus, conv: Converter, out: Out, settings: Settings, chash: str):
        self.bus, self.conv, self.out, self.s, self.chash = bus, conv, out, settings, chash
        self.q: deque[RawSample] = deque()
        self.cv = threading.Condition()
        self.pending_frames = 0
        self.dropped_frames = 0
        self.state: ServiceState = "starting"
        self.stopping = False
        self._logged: set[str] = set()

    def on_sample(self, s: RawSample) -> None:
        with self.cv:
            if s.key == FRAME_TOPIC:
                if self.pending_frames >= self.s.max_pending_frames:
                    self.dropped_frames += 1
                    self._once("drop", "the viewer falls behind: dropping camera frames (counted)")
                    return
                self.pending_frames += 1
            self.q.append(s)
            self.cv.notify()

    def run(self) -> None:
        """Worker loop; returns once stopping and the queue is drained. Buffered plots and
        poses are sent every FLUSH_EVERY_S: one send_columns per entity and flush is what makes
        them cheap (flushing after every message cost 5x the CPU, BENCHMARKS.md)."""
        last_flush = time.monotonic()
        while True:
            with self.cv:
                if not self.q and not self.stopping:
                    self.cv.wait(timeout=max(0.0, FLUSH_EVERY_S - (time.monotonic() - last_flush)))
                item = self.q.popleft() if self.q else None
                if item is not None and item.key == FRAME_TOPIC:
                    self.pending_frames -= 1
                done = item is None and self.stopping
            if item is not None:
                self._draw(item)
            if self.out.pending and time.monotonic() - last_flush >= FLUSH_EVERY_S:
                self.out.flush()
                last_flush = time.monotonic()
            if done:
                break
        self.out.flush()

    def _draw(self, s: RawSample) -> None:
        c = self.bus.counters_for(s.key)
        t = TOPICS.get(s.key)
        if t is None:
            self.bus.rejected_unknown += 1
            self._once(s.key, f"key {s.key!r} is not in the topic map; not drawn")
            return
        try:
            msg = t.codec.decode(s.payload)
        except DecodeError as exc:
            self.bus.reject(s.key, exc.reason)
            return
        c.received += 1
        c.last_seq = msg.header.seq
        self.conv.handle(s.key, msg)

    def _once(self, key: str, text: str) -> None:
        if key not in self._logged:
            self._logged.add(key)
            log.warning("%s", text)

    def stop(self) -> None:
        with self.cv:
            self.stopping = True
            self.cv.notify()

    def status(self) -> ServiceStatus:
        return ServiceStatus(
            name="viz",
            version=__version__,
            config_hash=self.chash,
            pid=os.getpid(),
            state=self.state,
            mode="live",
            spec=SERVICE.spec.model(),
            topics={k: c.frozen() for k, c in sorted(self.bus.counters.items())},
            rejected_unknown=self.bus.rejected_unknown,
            errors=sum(self.conv.failed.values()),
        )


def recording_id(namespace: str | None) -> str:
    """The run id of namespace 'harvest/<run_id>' (what `harvest view` uses for the MCAP)."""
    return (namespace or "live").rsplit("/", 1)[-1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m services.viz",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_bus_args(ap)
    add_service_args(ap)
    args = ap.parse_args(argv)
    setup_logging("viz", args.log_level)
    try:
        settings = resolve_settings(SERVICE, args)
        bus_settings = bus_settings_from_args(args)
    except (SettingsError, ValueError) as exc:
        print(f"viz: {exc}", file=sys.stderr)
        return 2
    assert isinstance(settings, Settings)
    if args.print_settings:
        print(settings.model_dump_json(indent=2))
        return 0
    try:
        rec = open_stream(settings, recording_id(bus_settings.namespace))
    except (SinkError, OSError) as exc:
        print(f"viz: refused to start: {exc}", file=sys.stderr)
        return 2
    out = Out(rec)
    conv = Converter(out, settings)
    conv.begin()
    try:
        bus = Bus("viz", bus_settings)
    except BusError as exc:
        log.error("%s", exc)
        return 1
    live = LiveViz(bus, conv, out, settings, config_hash(settings))
    bus.subscribe_raw("**", live.on_sample)
    bus.serve_status(live.status)
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    worker = threading.Thread(target=live.run, name="viz-worker")
    worker.start()
    live.state = "running"
    bus.declare_health()
    log.info("drawing the run%s", f" into {settings.save_path}" if settings.save_path else "")
    stop.wait()
    live.state = "stopping"
    bus.close()  # no more samples after this
    live.stop()
    worker.join()
    rec.flush()
    rec.disconnect()
    log.info("%s", conv.report().replace("\n", "; "))
    if live.dropped_frames:
        log.warning(
            "dropped %d camera frames the viewer could not keep up with", live.dropped_frames
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
