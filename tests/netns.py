"""Hosts for multi-host tests: Linux network namespaces joined by veth links, on one machine.

Topology (a star, like a robot and a compute box cabled to a router box):

    robot  10.S.1.2 ── veth ── 10.S.1.1  router  10.S.2.1 ── veth ── 10.S.2.2  compute

No forwarding between the two links: robot and compute reach each other only through the
Zenoh router in the router namespace. Names carry a random tag so that parallel runs never
collide, and ``close()`` removes every process started in the namespaces, then the namespaces
(their veths go with them), also after a failure.
"""

from __future__ import annotations

import contextlib
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import pytest

ROLES = ("router", "robot", "compute")


def need_netns() -> None:
    """Skip (with the reason) where namespaces cannot be made: not root, or no `ip`."""
    if shutil.which("ip") is None:
        pytest.skip("iproute2 ('ip') is not installed")
    if os.geteuid() != 0:
        pytest.skip("network namespaces need root (ip netns add)")
    probe = f"hvprobe{os.getpid()}"
    r = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot make a network namespace here: {r.stderr.strip()}")
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)


def _ip(*args: str) -> None:
    r = subprocess.run(["ip", *args], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {r.stderr.strip()}")


@dataclass
class Hosts:
    """Three namespaces: ``ns[role]`` its name, ``addr[role]`` its address on its link."""

    tag: str
    subnet: int
    ns: dict[str, str] = field(default_factory=dict)
    addr: dict[str, str] = field(default_factory=dict)
    router_addr: dict[str, str] = field(default_factory=dict)  # as seen from robot / compute
    procs: list[subprocess.Popen[bytes]] = field(default_factory=list)
    _logs: list[IO[bytes]] = field(default_factory=list)

    @classmethod
    def make(cls) -> Hosts:
        tag = f"{random.randrange(16**4):04x}"
        h = cls(tag, random.randrange(64, 250))
        try:
            h._build()
        except Exception:
            h.close()
            raise
        return h

    def _build(self) -> None:
        for role in ROLES:
            self.ns[role] = f"hv{self.tag}-{role}"
            _ip("netns", "add", self.ns[role])
            _ip("-n", self.ns[role], "link", "set", "lo", "up")
        for i, role in enumerate(("robot", "compute"), start=1):
            near, far = f"hv{self.tag}r{i}", f"hv{self.tag}h{i}"  # ≤ 15 characters
            _ip("link", "add", near, "type", "veth", "peer", "name", far)
            _ip("link", "set", near, "netns", self.ns["router"])
            _ip("link", "set", far, "netns", self.ns[role])
            r_addr, h_addr = f"10.{self.subnet}.{i}.1", f"10.{self.subnet}.{i}.2"
            _ip("-n", self.ns["router"], "addr", "add", f"{r_addr}/24", "dev", near)
            _ip("-n", self.ns[role], "addr", "add", f"{h_addr}/24", "dev", far)
            _ip("-n", self.ns["router"], "link", "set", near, "up")
            _ip("-n", self.ns[role], "link", "set", far, "up")
            self.addr[role], self.router_addr[role] = h_addr, r_addr

    def run(self, role: str, argv: list[str], log: Path) -> subprocess.Popen[bytes]:
        """Start ``argv`` (a Python module call) in ``role``'s namespace, in its own group."""
        out = open(log, "wb")  # noqa: SIM115 - closed in close()
        self._logs.append(out)
        p = subprocess.Popen(
            ["ip", "netns", "exec", self.ns[role], sys.executable, *argv],
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self.procs.append(p)
        return p

    def pids(self, role: str) -> list[int]:
        r = subprocess.run(["ip", "netns", "pids", self.ns[role]], capture_output=True, text=True)
        return [int(x) for x in r.stdout.split()]

    def close(self) -> None:
        """SIGTERM what we started (supervisors stop their services in order), then SIGKILL
        anything left in our namespaces, then delete the namespaces."""
        for p in self.procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        deadline = time.monotonic() + 20
        for p in self.procs:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
        for role, name in self.ns.items():
            for pid in self.pids(role):  # only processes in our own namespaces
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            subprocess.run(["ip", "netns", "del", name], capture_output=True)
        for f in self._logs:
            f.close()


def leftovers(tag: str) -> list[str]:
    """Namespaces or links of ours still present (for the cleanup check)."""
    ns = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    links = subprocess.run(["ip", "-o", "link"], capture_output=True, text=True).stdout
    return [ln for ln in (ns + links).splitlines() if f"hv{tag}" in ln]
