"""Multi-host: deploy/multihost/stack.yaml split over three network namespaces (router host;
robot host: sim, controller, recorder; compute host: detector, tracker, scene, planner), each
host its own `harvest run --host`, harvesting a two-fruit lab tree; the router is SIGKILLed
once the first fruit is in the basket, restarted by its host's supervisor, every client re-dials
it, and the harvest completes (both fruit, no collision) with every tick recorded and answered.
Skipped, with the reason, where `ip netns` is not available (needs root and iproute2).
(Slow: ~2-4 min on 2 cores.)"""

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
from tests.harvest_helpers import lab_scenario
from tests.helpers import payloads_by_topic, short_dir, wait_until
from tests.netns import Hosts, leftovers, need_netns

pytestmark = pytest.mark.integration

STACK = Path(__file__).parents[2] / "deploy" / "multihost" / "stack.yaml"
PORT = 7447  # every host has its own network stack: no clash with anything on the machine
FRUIT = [
    {"position_world_m": [0.6, -0.12, 1.32], "radius_m": 0.04, "leaf_cover": "none"},
    {"position_world_m": [0.7, 0.05, 1.25], "radius_m": 0.04, "leaf_cover": "none"},
]


@pytest.fixture
def hosts() -> Iterator[Hosts]:
    need_netns()
    h = Hosts.make()
    try:
        yield h
    finally:
        h.close()
        assert leftovers(h.tag) == [], "namespaces or veths left behind"


def host_stack(path: Path, d: Path) -> Path:
    """deploy/multihost/stack.yaml as shipped, with this test's folders and a small tree."""
    stack = yaml.safe_load(STACK.read_text())
    stack["recording"]["dir"] = str(d / "rec")
    stack["router"]["zenoh_config"] = str(STACK.parent / "router.json5")
    sim = stack["services"]["sim"]["settings"]
    sim.update(scenario=str(lab_scenario(d, FRUIT)), seed=5, duration_s=90.0)
    stack["services"]["planner"]["settings"] = {"finish_after_s": 0.5}
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


def test_three_hosts_harvest_through_a_router_restart(hosts: Hosts) -> None:
    d = short_dir()
    try:
        stack = host_stack(d / "stack.yaml", d)
        run_id = f"mh-{hosts.tag}"
        procs = {role: run_host(hosts, role, stack, run_id, d) for role in hosts.ns}
        mcap = d / "rec" / f"{run_id}.mcap"

        def collected() -> bool:
            for role, p in procs.items():
                assert p.poll() is None, (d / f"{role}.out").read_text()
            return "fruit collected" in (d / "compute.out").read_text()

        wait_until(collected, 300, "the first fruit in the basket")
        old = router_pid(hosts)
        assert old is not None
        t_kill = time.monotonic()
        os.kill(old, signal.SIGKILL)
        assert procs["compute"].wait(timeout=300) == 0, (d / "compute.out").read_text()
        t_done = time.monotonic()
        for role in ("robot", "router"):  # they follow the main host and stop by themselves
            assert procs[role].wait(timeout=60) == 0, (d / f"{role}.out").read_text()
        out = {role: (d / f"{role}.out").read_text() for role in procs}
        assert "restarting the router" in out["router"]
        assert "lost the router" in out["robot"] and "the router is back" in out["robot"]
        assert "main service (on another host) has finished" in out["robot"]
        assert "planner is live" in out["compute"] and "controller is live" in out["robot"]
        got = payloads_by_topic(mcap)
        (summary,) = [TOPICS["harvest/summary"].codec.decode(p) for _, p in got["harvest/summary"]]
        assert summary.detected == 2 and summary.harvested == 2, summary
        assert summary.collisions == 0, summary
        states = [s for s, _ in got["robot/joint_state"]]
        assert states == list(range(len(states))), "a tick is missing"
        codec = TOPICS["robot/command"].codec
        answered = {codec.decode(p).header.answers_seq for _, p in got["robot/command"]}
        assert set(states[:-1]) <= answered, "a tick without its command"  # the last: stopping
        # The outage as the recorder saw it: the longest silence between two joint states.
        stamps = [m.log_time_ns for m in iter_messages(mcap) if m.topic == "robot/joint_state"]
        gap_s = max(b - a for a, b in itertools.pairwise(sorted(stamps))) * 1e-9
        print(json.dumps({"outage_s": round(gap_s, 2), "kill_to_end_s": round(t_done - t_kill, 1)}))
    finally:
        shutil.rmtree(d, ignore_errors=True)
