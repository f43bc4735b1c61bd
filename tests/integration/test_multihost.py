"""Multi-host: the stack split over three network namespaces (router, robot, compute hosts), each
host its own `harvest run --host`; the router is SIGKILLed mid-run, restarted by its host's
supervisor, every client re-dials it and the lock-step run completes with nothing missing."""

from __future__ import annotations

import itertools
import json
import os
import shutil
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from services.recorder.inspect import iter_messages
from tests.helpers import payloads_by_topic, short_dir, wait_until
from tests.netns import Hosts, leftovers, need_netns

pytestmark = pytest.mark.integration

PORT = 7447  # every host has its own network stack: no clash with anything on the machine


@pytest.fixture
def hosts() -> Iterator[Hosts]:
    need_netns()
    h = Hosts.make()
    try:
        yield h
    finally:
        h.close()
        assert leftovers(h.tag) == [], "namespaces or veths left behind"


def demo_stack(path: Path, rec: Path, ticks: int) -> Path:
    """The foundation demo split over hosts: the clock (master) and the recording on the
    robot, the worker on the compute host, the router on its own host."""
    path.write_text(f"""
name: multihost-demo
mode: lockstep
master: demo_clock
router:
  host: router
  listen: ["tcp/0.0.0.0:{PORT}"]
  zenoh_config: deploy/multihost/router.json5
  restart: {{policy: on-failure, max_restarts: 3, backoff_s: 0.2}}
recording: {{enabled: true, dir: {rec}, host: robot}}
services:
  demo_worker:
    host: compute
    restart: {{policy: on-failure, max_restarts: 3, backoff_s: 0.2}}
    settings: {{max_delay_ms: 2.0}}
  demo_clock:
    host: robot
    main: true
    settings: {{ticks: {ticks}, period_ms: 10.0}}
""")
    return path


def run_host(h: Hosts, role: str, stack: Path, run_id: str, d: Path) -> subprocess.Popen[bytes]:
    argv = ["-m", "services.cli", "run", "--stack", str(stack), "--run-id", run_id]
    argv += ["--host", role]
    if role != "router":
        argv += ["--connect", f"tcp/{h.router_addr[role]}:{PORT}"]
    return h.run(role, argv, d / f"{role}.out")


def router_pid(h: Hosts) -> int | None:
    for pid in h.pids("router"):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except FileNotFoundError:
            continue
        if b"services.router" in cmd:
            return pid
    return None


def test_three_hosts_complete_a_lockstep_run_through_a_router_restart(hosts: Hosts) -> None:
    d = short_dir()
    try:
        ticks = 6000
        stack = demo_stack(d / "stack.yaml", d / "rec", ticks)
        run_id = f"mh-{hosts.tag}"
        procs = {role: run_host(hosts, role, stack, run_id, d) for role in hosts.ns}
        mcap = d / "rec" / f"{run_id}.mcap"

        def started() -> bool:
            for role, p in procs.items():
                assert p.poll() is None, (d / f"{role}.out").read_text()
            return "demo_clock is live" in (d / "robot.out").read_text()

        wait_until(started, 90, "the robot host's clock")
        wait_until(lambda: mcap.exists() and mcap.stat().st_size > 100_000, 60, "recorded ticks")
        old = router_pid(hosts)
        assert old is not None
        t_kill = time.monotonic()
        os.kill(old, signal.SIGKILL)
        assert procs["robot"].wait(timeout=180) == 0, (d / "robot.out").read_text()
        t_done = time.monotonic()
        for role in ("compute", "router"):  # they follow the main host and stop by themselves
            assert procs[role].wait(timeout=60) == 0, (d / f"{role}.out").read_text()
        out = {role: (d / f"{role}.out").read_text() for role in procs}
        assert "restarting the router" in out["router"]
        assert "lost the router" in out["robot"] and "the router is back" in out["robot"]
        assert "main service (on another host) has finished" in out["compute"]
        got = payloads_by_topic(mcap)
        assert [s for s, _ in got["demo/tick"]] == list(range(ticks)), "a tick is missing"
        assert [s for s, _ in got["demo/answer"]] == list(range(ticks)), "an answer is missing"
        # The outage as the recorder saw it: the longest silence between two recorded ticks.
        ticks_ns = sorted(m.log_time_ns for m in iter_messages(mcap) if m.topic == "demo/tick")
        gap_s = max(b - a for a, b in itertools.pairwise(ticks_ns)) * 1e-9
        print(json.dumps({"outage_s": round(gap_s, 2), "kill_to_end_s": round(t_done - t_kill, 1)}))
    finally:
        shutil.rmtree(d, ignore_errors=True)
