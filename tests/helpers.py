"""Test helpers: polling waits (never fixed sleeps), a private router per test, child processes."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from services.bus import Bus, BusSettings, bus_args


def wait_until(
    pred: Callable[[], object],
    timeout_s: float = 10.0,
    what: str = "condition",
    interval_s: float = 0.02,
) -> object:
    """Poll ``pred`` until truthy; fail the test with ``what`` on timeout."""
    deadline = time.monotonic() + timeout_s
    while True:
        v = pred()
        if v:
            return v
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(interval_s)


@dataclass
class BusEnv:
    """A router on a private unix socket and a namespace, for one test."""

    dir: Path
    endpoint: str
    namespace: str
    procs: list[subprocess.Popen[bytes]] = field(default_factory=list)
    sessions: list[Bus] = field(default_factory=list)

    def settings(self, **kw: object) -> BusSettings:
        base: dict[str, object] = {
            "mode": "client",
            "connect": (self.endpoint,),
            "namespace": self.namespace,
        }
        base.update(kw)
        return BusSettings.model_validate(base)

    def flags(self) -> list[str]:
        return bus_args(self.settings())

    def client(self, name: str, **kw: object) -> Bus:
        bus = Bus(name, self.settings(**kw))
        self.sessions.append(bus)
        return bus

    def spawn(self, *argv: str, log: str | None = None) -> subprocess.Popen[bytes]:
        out = open(self.dir / (log or f"proc{len(self.procs)}.log"), "wb")  # noqa: SIM115
        p = subprocess.Popen(
            [sys.executable, *argv], stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )
        self.procs.append(p)
        return p

    def service(self, module: str, *extra: str, log: str | None = None) -> subprocess.Popen[bytes]:
        return self.spawn("-m", module, *self.flags(), *extra, log=log or module)

    def log(self, name: str) -> str:
        p = self.dir / name
        return p.read_text(errors="replace") if p.exists() else ""

    def close(self) -> None:
        for s in self.sessions:
            s.close()
        for p in reversed(self.procs):
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()


def make_bus_env() -> BusEnv:
    d = Path(tempfile.mkdtemp(prefix="hv-", dir="/tmp"))
    env = BusEnv(d, f"unixsock-stream/{d}/router.sock", f"test-{uuid.uuid4().hex[:8]}")
    env.spawn("-m", "services.router", "-l", env.endpoint, log="router.log")
    wait_until(lambda: (d / "router.sock").exists(), 20, "the router socket")
    return env


def remove(env: BusEnv) -> None:
    env.close()
    shutil.rmtree(env.dir, ignore_errors=True)


def write_stack(
    path: Path,
    rec_dir: Path,
    *,
    ticks: int = 100,
    mode: str = "lockstep",
    worker_restart: str = "on-failure",
    max_delay_ms: float = 2.0,
    period_ms: float = 10.0,
) -> Path:
    """A demo stack file recording into ``rec_dir``."""
    path.write_text(f"""
name: test-demo
mode: {mode}
master: demo_clock
recording: {{enabled: true, dir: {rec_dir}}}
services:
  demo_worker:
    restart: {{policy: {worker_restart}, max_restarts: 3, backoff_s: 0.2}}
    settings: {{max_delay_ms: {max_delay_ms}}}
  demo_clock:
    main: true
    settings: {{ticks: {ticks}, period_ms: {period_ms}}}
""")
    return path


def harvest(*args: str, timeout: float = 120, **kw: object) -> subprocess.CompletedProcess[str]:
    """Run the `harvest` CLI in a subprocess."""
    return subprocess.run(
        [sys.executable, "-m", "services.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        **kw,
    )  # type: ignore[call-overload]


def start_harvest(*args: str, log: Path) -> subprocess.Popen[bytes]:
    out = open(log, "wb")  # noqa: SIM115
    return subprocess.Popen(
        [sys.executable, "-m", "services.cli", *args], stdout=out, stderr=subprocess.STDOUT
    )


def payloads_by_topic(mcap: Path) -> dict[str, list[tuple[int, bytes]]]:
    """Recorded (seq, payload) per topic, in order, re-sent duplicates collapsed."""
    from services.recorder.inspect import iter_messages

    out: dict[str, list[tuple[int, bytes]]] = {}
    for m in iter_messages(mcap):
        seen = out.setdefault(m.topic, [])
        if not seen or seen[-1] != (m.sequence, m.payload):
            seen.append((m.sequence, m.payload))
    return out


def short_dir() -> Path:
    """A short temp dir (unix socket paths are limited to ~100 characters)."""
    return Path(tempfile.mkdtemp(prefix="hv-", dir="/tmp"))
