"""Health of the supervised processes: liveliness, the supervisor's own link to the router, and
the judgement "hung" (alive process, vanished liveliness) that survives a router restart."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

from services.supervisor.process import ManagedProcess
from services.supervisor.stack import RestartPolicy

ROUTER = "router"


@dataclass
class Child:
    """A managed process (service, recorder or router) and its restart bookkeeping."""

    proc: ManagedProcess
    policy: RestartPolicy
    main: bool = False
    essential: bool = True  # failing for good ends the run (the recorder: recording.required)
    restarts: int = 0
    restart_at: float | None = None
    done: bool = False  # exited for good (normally or not)
    failed: bool = False
    was_alive: bool = False
    lost_at: float | None = None  # when its liveliness went away while the process ran
    started_at: float = 0.0
    live_at: float | None = None  # when its liveliness (re)appeared after the last start
    restart_s: list[float] = field(default_factory=list)  # process start → liveliness, s

    def backoff_s(self) -> float | None:
        """Seconds to wait before the next restart, or None when the policy says give up."""
        p = self.policy
        if p.policy != "on-failure" or self.restarts >= p.max_restarts:
            return None
        return min(p.backoff_s * (2**self.restarts), p.backoff_max_s)


class Health:
    """Liveliness of every child, as seen through the supervisor's session.

    When the router goes away every token vanishes at once and comes back only when each
    client has re-dialled the restarted router. A token lost while the supervisor's own link
    was down therefore says nothing about the service: it is judged only ``reconnect_grace_s``
    after the link is back (clients re-dial within about 1 s, services/bus/README.md).
    """

    def __init__(self, hung_grace_s: float, reconnect_grace_s: float = 3.0) -> None:
        self.hung_grace_s, self.reconnect_grace_s = hung_grace_s, reconnect_grace_s
        self.alive: dict[str, bool] = {}
        self.children: dict[str, Child] = {}
        self.link_up = True
        self.link_up_since = 0.0
        self.lines: list[str] = []
        self._lock = threading.Lock()

    def on_health(self, name: str, alive: bool) -> None:
        now = time.monotonic()
        if name == ROUTER:
            # The router's own token is the supervisor's link, seen as an event: a link that
            # drops and re-dials within one poll of ``router_connected`` is not missed.
            self.link(alive)
            return
        with self._lock:
            self.alive[name] = alive
            child = self.children.get(name)
            if child is None:
                return
            if alive and not child.was_alive and child.live_at is None:
                child.live_at = now
                if child.restarts:
                    child.restart_s.append(now - child.started_at)
            child.was_alive = child.was_alive or alive
            child.lost_at = None if alive else now

    def is_alive(self, name: str) -> bool:
        with self._lock:
            return self.alive.get(name, False)

    def started(self, name: str, child: Child) -> None:
        """A (re)start: forget the old liveliness, time the new one."""
        with self._lock:
            self.alive[name] = False
            child.was_alive = False
            child.lost_at = None
            child.live_at = None
            child.started_at = time.monotonic()

    def link(self, up: bool) -> None:
        """Record whether the supervisor reaches a router (``lines`` says when that changed)."""
        now = time.monotonic()
        with self._lock:
            if up == self.link_up:
                return
            self.link_up = up
            if up:
                self.link_up_since = now
                self.lines.append(
                    "the router is back: services re-dial it and declare their liveliness again"
                )
            else:
                self.lines.append("lost the router: waiting for it (liveliness is not judged)")

    def take_lines(self) -> list[str]:
        """Link changes since the last call, to log."""
        with self._lock:
            out, self.lines = self.lines, []
            return out

    def hung(self, child: Child, now: float) -> bool:
        """True when a running child's liveliness vanished for longer than the grace."""
        lost = child.lost_at
        if not self.link_up or not child.was_alive or lost is None:
            return False
        since = lost if lost >= self.link_up_since else self.link_up_since + self.reconnect_grace_s
        return now - since > self.hung_grace_s
