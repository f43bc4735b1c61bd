"""python -m services.recorder --out recordings/<run>.mcap [--run-meta FILE]

Writes every sample of the namespace to one MCAP (see writer.py). Finishes the file on
SIGTERM/SIGINT; a SIGKILLed file can be repaired with `harvest recover`.

Exit codes: 0 finished, 1 bus, 2 bad settings or the file cannot be created, 3 the file could
not be written any more (disk full, I/O error): the file is valid up to its last flushed chunk
after `harvest recover`.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import json
import logging
import os
import queue
import signal
import sys
import threading
import time
from pathlib import Path

from schemas.service import ServiceState, ServiceStatus
from services import __version__
from services.bus import Bus, BusError, RawSample, add_bus_args, bus_settings_from_args
from services.recorder import SERVICE, Settings
from services.recorder.preview import CameraPreview
from services.recorder.writer import RUN_METADATA, RunWriter
from services.runtime.service import add_service_args, resolve_settings, setup_logging
from services.runtime.settings import SettingsError, config_hash

log = logging.getLogger("recorder")


class Recorder:
    """Queue fed by Zenoh callbacks, drained by one writer thread (the MCAP writer is not
    thread-safe, and the callbacks must stay short)."""

    def __init__(
        self, bus: Bus, writer: RunWriter, settings: Settings, chash: str, out: Path
    ) -> None:
        self.bus, self.writer, self.s, self.chash, self.out = bus, writer, settings, chash, out
        self.q: queue.SimpleQueue[RawSample | None] = queue.SimpleQueue()
        self.state: ServiceState = "starting"
        self.errors = 0
        self.failure = ""  # set when the file cannot be written any more
        self.failed = threading.Event()
        self.written = 0
        self.last_stamp_recv_ns = 0
        self._logged_unknown: set[str] = set()

    def on_sample(self, sample: RawSample) -> None:
        self.bus.counters_for(sample.key).received += 1
        if not self.failed.is_set():  # a failed recorder keeps nothing in memory
            self.q.put(sample)

    def run(self) -> None:
        """Writer loop; returns after a None sentinel with the file finished, or at once when
        the file cannot be written (``failure`` says why; the process then exits 3)."""
        try:
            self._loop()
            self.writer.finish()
        except OSError as exc:
            self.state = "failed"
            self.failure = (
                f"cannot write {self.out}: {exc.strerror or exc} (errno {exc.errno}); "
                f"{self.written} messages were recorded, up to the last flush; "
                f"`harvest recover {self.out}` makes the file valid"
            )
            self.failed.set()

    def _loop(self) -> None:
        last_flush = time.monotonic()
        while True:
            try:
                item = self.q.get(timeout=0.1)
            except queue.Empty:
                pass  # idle: still flush on time below
            else:
                if item is None:
                    return
                self._write(item)
                self.written += 1
            if time.monotonic() - last_flush >= self.s.flush_interval_s:
                self.writer.flush()
                last_flush = time.monotonic()

    def _write(self, s: RawSample) -> None:
        try:
            result = self.writer.write(s.key, s.payload, s.encoding, s.recv_ns)
        except OSError:
            raise  # the file cannot be written any more: run() ends the recorder (exit 3)
        except Exception as exc:  # one sample the writer cannot take must not stop the rest
            self.errors += 1
            self.bus.reject(s.key, f"cannot record: {type(exc).__name__}: {exc}")
            return
        if result == "rejected":
            self.bus.reject(s.key, "payload does not decode; recorded under _rejected/")
        elif result == "unknown":
            self.bus.rejected_unknown += 1
            if s.key not in self._logged_unknown:
                self._logged_unknown.add(s.key)
                log.warning("key %r is not in the topic map; recorded without a schema", s.key)

    def status(self) -> ServiceStatus:
        return ServiceStatus(
            name="recorder",
            version=__version__,
            config_hash=self.chash,
            pid=os.getpid(),
            state=self.state,
            mode="live",
            spec=SERVICE.spec.model(),
            topics={k: c.frozen() for k, c in sorted(self.bus.counters.items())},
            rejected_unknown=self.bus.rejected_unknown,
            errors=self.errors,
        )


def _keep_big_buffers() -> None:
    """Serve the recorder's large buffers (1.5 MB frames, 4 MB chunks) from the heap and keep
    freed memory: without this glibc maps and unmaps every one of them, and the page faults cost
    as much CPU as the lz4 compression (measured: sys time 4.1 % → 2.9 % of a core at 15 Hz)."""
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return  # not glibc: nothing to tune
    m_trim_threshold, m_mmap_threshold = -1, -3
    libc.mallopt(m_mmap_threshold, 64 << 20)
    libc.mallopt(m_trim_threshold, 256 << 20)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m services.recorder",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_bus_args(ap)
    add_service_args(ap)
    ap.add_argument("--out", type=Path, help="MCAP file to write (default <out_dir>/<ts>.mcap)")
    ap.add_argument("--run-meta", type=Path, help="JSON object of run metadata (str → str)")
    args = ap.parse_args(argv)
    setup_logging("recorder", args.log_level)
    _keep_big_buffers()
    try:
        settings = resolve_settings(SERVICE, args)
        meta = _read_meta(args.run_meta)
    except (SettingsError, ValueError) as exc:
        print(f"recorder: {exc}", file=sys.stderr)
        return 2
    assert isinstance(settings, Settings)
    out = args.out or settings.out_dir / time.strftime("run-%Y%m%d-%H%M%S.mcap")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        stream = open(out, "wb")  # noqa: SIM115 - closed after finish()
    except OSError as exc:
        print(f"recorder: cannot write {out}: {exc.strerror}", file=sys.stderr)
        return 2
    preview = (
        None
        if settings.preview == "none"
        else CameraPreview(settings.preview, settings.preview_scale, settings.preview_jpeg_quality)
    )
    try:
        writer = RunWriter(
            stream, settings.compression, settings.chunk_size_bytes, settings.lz4_level, preview
        )
        if meta:
            writer.add_metadata(RUN_METADATA, meta)
        stream.flush()  # a full disk shows here, before we say we record
    except OSError as exc:
        print(f"recorder: cannot write {out}: {exc.strerror or exc}", file=sys.stderr)
        return 3
    try:
        bus = Bus("recorder", bus_settings_from_args(args))
    except BusError as exc:
        log.error("%s", exc)
        return 1
    rec = Recorder(bus, writer, settings, config_hash(settings), out)
    bus.subscribe_raw(settings.keyexpr, rec.on_sample)
    bus.serve_status(rec.status)
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())

    def write_until_done() -> None:
        rec.run()
        stop.set()  # after a write failure: end the process at once (exit 3)

    worker = threading.Thread(target=write_until_done, name="mcap-writer")
    worker.start()
    rec.state = "running"
    bus.declare_health()
    log.info("recording to %s", out)
    stop.wait()
    if rec.failed.is_set():
        log.error("%s", rec.failure)
        bus.close()
        with contextlib.suppress(OSError):  # the buffered tail cannot be written either
            stream.close()
        return 3
    rec.state = "stopping"
    bus.close()  # no more samples after this
    rec.q.put(None)
    worker.join()
    if rec.failed.is_set():
        log.error("%s", rec.failure)
        with contextlib.suppress(OSError):
            stream.close()
        return 3
    stream.close()
    n = sum(st.messages for st in writer.stats.values())
    log.info("finished %s: %d messages on %d channels", out, n, len(writer.stats))
    if writer.derived:
        d = sum(st.messages for st in writer.derived.values())
        log.info("plus %d derived preview messages (%s)", d, ", ".join(sorted(writer.derived)))
    if writer.preview_errors:
        log.warning("%d camera frames had no preview (undecodable pixels)", writer.preview_errors)
    return 0


def _read_meta(path: Path | None) -> dict[str, str]:
    if path is None:
        return {}
    data = json.loads(path.read_text())
    if not isinstance(data, dict):
        raise ValueError(f"{path}: run metadata must be a JSON object")
    return {
        str(k): v if isinstance(v, str) else json.dumps(v, sort_keys=True) for k, v in data.items()
    }


if __name__ == "__main__":
    sys.exit(main())
