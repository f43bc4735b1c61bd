"""Multi-host: deploy/multihost/stack.yaml split over three network namespaces (router, robot,
compute hosts), each host its own `harvest run --host`; the router is SIGKILLed mid-run,
restarted by its host's supervisor, every client re-dials it and the lock-step run completes
with every tick recorded and answered. Skipped, with the reason, where `ip netns` is not
available (needs root and iproute2)."""

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
import yaml

from schemas import TOPICS
from services.recorder.inspect import iter_messages
from tests.helpers import payloads_by_topic, short_dir, wait_until
from tests.netns import Hosts, leftovers, need_netns

pytestmark = pytest.mark.integration

STACK = Path(__file__).parents[2] / "deploy" / "multihost" / "stack.yaml"
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


def host_stack(path: Path, d: Path, sim_s: float) -> Path:
    """deploy/multihost/stack.yaml as shipped, with this test's folders and a shorter run."""
    stack = yaml.safe_load(STACK.read_text())
    stack["recording"]["dir"] = str(d / "rec")
    stack["router"]["zenoh_config"] = str(STACK.parent / "router.json5")
    stack["services"]["viz"]["settings"]["save_path"] = str(d / "viz.rrd")
    stack["services"]["sim"]["settings"]["duration_s"] = sim_s
    path.write_text(yaml.safe_dump(stack, sort_keys=False))
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
        sim_s = 8.0
        stack = host_stack(d / "stack.yaml", d, sim_s)
        run_id = f"mh-{hosts.tag}"
        procs = {role: run_host(hosts, role, stack, run_id, d) for role in hosts.ns}
        mcap = d / "rec" / f"{run_id}.mcap"

        def started() -> bool:
            for role, p in procs.items():
                assert p.poll() is None, (d / f"{role}.out").read_text()
            return "sim is live" in (d / "robot.out").read_text()

        wait_until(started, 120, "the robot host's sim")
        wait_until(lambda: mcap.exists() and mcap.stat().st_size > 5_000_000, 120, "recorded ticks")
        old = router_pid(hosts)
        assert old is not None
        t_kill = time.monotonic()
        os.kill(old, signal.SIGKILL)
        assert procs["robot"].wait(timeout=300) == 0, (d / "robot.out").read_text()
        t_done = time.monotonic()
        for role in ("compute", "router"):  # they follow the main host and stop by themselves
            assert procs[role].wait(timeout=60) == 0, (d / f"{role}.out").read_text()
        out = {role: (d / f"{role}.out").read_text() for role in procs}
        assert "restarting the router" in out["router"]
        assert "lost the router" in out["robot"] and "the router is back" in out["robot"]
        assert "main service (on another host) has finished" in out["compute"]
        assert "viz is live" in out["compute"] and "controller is live" in out["robot"]
        got = payloads_by_topic(mcap)
        ticks = list(range(round(sim_s * 120) + 1))
        assert [s for s, _ in got["robot/joint_state"]] == ticks, "a tick is missing"
        codec = TOPICS["robot/command"].codec
        answered = {codec.decode(p).header.answers_seq for _, p in got["robot/command"]}
        assert set(ticks) <= answered, "a tick without its command"
        # The outage as the recorder saw it: the longest silence between two joint states.
        stamps = [m.log_time_ns for m in iter_messages(mcap) if m.topic == "robot/joint_state"]
        gap_s = max(b - a for a, b in itertools.pairwise(sorted(stamps))) * 1e-9
        print(json.dumps({"outage_s": round(gap_s, 2), "kill_to_end_s": round(t_done - t_kill, 1)}))
    finally:
        shutil.rmtree(d, ignore_errors=True)
