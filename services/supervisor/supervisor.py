"""Supervisor: starts the router, the recorder and every service of a stack, watches their health
by liveliness, restarts by policy, and stops them in order so the recording is finished last."""

from __future__ import annotations

import json
import shutil
import signal
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from services.bus import Bus, BusError, BusSettings, bus_args
from services.bus.config import TlsError, tls_files
from services.registry import SERVICE_MODULES, service_def
from services.runtime.lockstep import LockstepPlan
from services.runtime.spec import answer_closure
from services.supervisor.health import Child, Health
from services.supervisor.metadata import run_metadata
from services.supervisor.process import LogSink, ManagedProcess
from services.supervisor.stack import Stack, StackError, resolve_service_settings

SELF = "supervisor"
RECORDER = "recorder"
MAIN_TOKEN = "run/main"
"""Liveliness token held by the host whose main service runs; other hosts follow it."""

__all__ = ["Child", "RunResult", "Supervisor", "local_endpoint"]


@dataclass
class RunResult:
    exit_code: int
    run_id: str
    mcap: Path | None
    log: Path
    wall_s: float
    children: dict[str, Child] = field(default_factory=dict)
    failure: str = ""
    mcap_parts: list[Path] = field(default_factory=list)  # a restarted recorder's next files
    warnings: list[str] = field(default_factory=list)  # e.g. the recording stopped


def local_endpoint(listen: str) -> str:
    """The endpoint a local client connects to for a router listening on ``listen``."""
    return listen.replace("0.0.0.0", "127.0.0.1").replace("[::]", "[::1]")


def part_path(first: Path, part: int) -> Path:
    """``run.mcap`` → ``run.1.mcap``: where a restarted recorder writes (never over a file)."""
    return first if part == 0 else first.with_name(f"{first.stem}.{part}{first.suffix}")


class Supervisor:
    """Runs one stack until its main service exits, a service fails for good, or a signal."""

    def __init__(
        self,
        stack: Stack,
        stack_path: Path,
        run_id: str,
        profile: str | None = None,
        quiet: bool = False,
        python: str = sys.executable,
        hung_grace_s: float = 0.3,
        follow_grace_s: float = 5.0,
        exit_grace_s: float = 0.5,
    ) -> None:
        self.stack, self.stack_path, self.run_id, self.profile = stack, stack_path, run_id, profile
        self.exit_grace_s = exit_grace_s
        self.python, self.follow_grace_s = python, follow_grace_s
        self.namespace = f"harvest/{run_id}"
        rec_dir = stack.recording.dir
        rec_dir.mkdir(parents=True, exist_ok=True)
        self.mcap = rec_dir / f"{run_id}.mcap" if stack.records_here() else None
        self.mcap_parts: list[Path] = [self.mcap] if self.mcap else []
        # One log per host: hosts of a multi-host run may share the recording folder.
        self.log_path = rec_dir / (f"{run_id}.{stack.host}.log" if stack.host else f"{run_id}.log")
        self.sink = LogSink(self.log_path, quiet=quiet)
        r = stack.router
        local = stack.routes_here() or not r.connect
        self.connect = (local_endpoint(r.listen[0]),) if local else r.connect
        self.children: dict[str, Child] = {}
        self.health = Health(hung_grace_s)
        self.health.children = self.children
        self.warnings: list[str] = []
        self._stop = threading.Event()
        self._interrupts = 0
        self._tmp = Path(tempfile.mkdtemp(prefix=f"{run_id}-"))
        # Per-run state a restarted service takes up again (the planner's journal): empty at
        # the start, so only a restarted process finds anything there; removed at the end.
        self.state_dir = self._tmp / "state"
        self.state_dir.mkdir()
        self.bus: Bus | None = None
        self.router: Child | None = None
        self._main_seen = False
        self._main_lost_at: float | None = None
        self.on_event: list[Any] = []  # hooks: callables(name, text) for progress displays
        self.on_bus: list[Any] = []  # hooks: callables(bus) run once the run's bus is open

    @property
    def alive(self) -> dict[str, bool]:
        return self.health.alive

    # ---- set-up ----------------------------------------------------------------------------
    def say(self, text: str) -> None:
        self.sink.line(SELF, text)

    def _service_bus(self) -> BusSettings:
        return BusSettings(
            mode="client",
            connect=self.connect,
            namespace=self.namespace,
            tls_dir=self.stack.security.tls_dir,
        )

    def _check_certificates(self) -> None:
        """Secured profile: every process's certificate exists, before anything starts."""
        tls_dir = self.stack.security.tls_dir
        if tls_dir is None:
            return
        names = [SELF, *self.children]
        if self.stack.routes_here():
            names.append("router")
        missing = []
        for name in names:
            try:
                tls_files(tls_dir, name)
            except TlsError:
                missing.append(name)
        if missing:
            raise StackError(
                f"security.tls_dir: {tls_dir} has no certificate for {', '.join(missing)} "
                f"(make them with `harvest certs make {tls_dir} --names {','.join(missing)}`)"
            )

    def _argv(self, name: str, settings_json: str, extra: list[str]) -> list[str]:
        return [
            self.python,
            "-m",
            SERVICE_MODULES[name],
            *bus_args(self._service_bus()),
            "--time-mode",
            self.stack.mode,
            "--settings-json",
            settings_json,
            *extra,
        ]

    def lockstep_plan(self) -> LockstepPlan:
        """Answers the master awaits per published topic, from every enabled service's spec
        (on every host: a multi-host graph is one lock-step graph)."""
        st = self.stack
        assert st.master is not None
        specs = [service_def(n).spec for n in st.enabled()]
        wait = {t: answer_closure(t, specs) for t in service_def(st.master).spec.outputs}
        consumers = [n for n in st.enabled() if n != st.master]
        if st.recording.enabled:
            consumers.insert(0, RECORDER)
        return LockstepPlan(wait={k: v for k, v in wait.items() if v}, consumers=tuple(consumers))

    def _build_children(self) -> None:
        settings = resolve_service_settings(self.stack)
        if self.mcap is not None:
            meta_file = self._tmp / "run-meta.json"
            meta = run_metadata(
                self.stack, self.stack_path, self.profile, self.run_id, self.namespace, settings
            )
            meta_file.write_text(json.dumps(meta))
            argv = self._argv(
                RECORDER,
                settings[RECORDER].model_dump_json(),
                ["--out", str(self.mcap), "--run-meta", str(meta_file)],
            )
            rec = self.stack.recording
            self.children[RECORDER] = Child(
                ManagedProcess(RECORDER, argv, self.sink), rec.restart, essential=rec.required
            )
        for name in self.stack.local():
            entry = self.stack.services[name]
            extra: list[str] = []
            if name == self.stack.master and self.stack.mode == "lockstep":
                extra = ["--lockstep-plan", self.lockstep_plan().model_dump_json()]
            argv = self._argv(name, settings[name].model_dump_json(), extra)
            env = {"HARVEST_STATE_DIR": str(self.state_dir)}
            self.children[name] = Child(
                ManagedProcess(name, argv, self.sink, env), entry.restart, main=entry.main
            )

    def start_order(self) -> list[str]:
        """Recorder first, the clock master last (it starts the clock)."""
        names = list(self.children)
        master = self.stack.master
        if master in names:
            names.remove(master)
            names.append(master)
        return names

    def stop_order(self) -> list[str]:
        """The master first (no new data), then the rest in reverse, the recorder last."""
        order = list(reversed(self.start_order()))
        if RECORDER in order:
            order.remove(RECORDER)
            order.append(RECORDER)
        return order

    # ---- router ----------------------------------------------------------------------------
    def _start_router(self) -> None:
        r = self.stack.router
        argv = [self.python, "-m", "services.router", "--namespace", self.namespace]
        for e in r.listen:
            argv += ["-l", e]
        if r.zenoh_config:
            argv += ["--zenoh-config", str(r.zenoh_config)]
        if self.stack.security.tls_dir is not None:
            argv += ["--tls-dir", str(self.stack.security.tls_dir)]
        self.router = Child(ManagedProcess("router", argv, self.sink), r.restart)
        self.router.proc.start()

    def _check_router(self, now: float) -> tuple[int, str] | None:
        """A router that died is restarted by its policy (clients re-dial it); else the end."""
        r = self.router
        if r is None:
            return None
        if r.restart_at is not None:
            if now >= r.restart_at:
                r.restart_at = None
                r.restarts += 1
                self.say(f"restarting the router (restart {r.restarts}/{r.policy.max_restarts})")
                r.proc.start()
            return None
        rc = r.proc.poll()
        if rc is None:
            return None
        r.proc.exit_codes.append(rc)
        backoff = r.backoff_s()
        if backoff is None:
            return 1, f"the router exited with code {rc}"
        self.say(f"the router exited with code {rc}; restart in {backoff:.1f} s")
        r.restart_at = now + backoff
        return None

    def _open_bus(self, timeout_s: float = 20.0) -> Bus:
        """Connect to the router, retrying while it starts; fail fast if it died."""
        deadline = time.monotonic() + timeout_s
        while True:
            rc = self.router.proc.poll() if self.router is not None else None
            if self.router is not None and rc is not None:
                raise BusError(
                    f"the router exited with code {rc}: {' / '.join(self.router.proc.tail[-3:])}"
                )
            try:
                return Bus(SELF, self._service_bus())
            except BusError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    # ---- children --------------------------------------------------------------------------
    def _start_child(self, name: str) -> None:
        child = self.children[name]
        self.health.started(name, child)
        child.proc.start()
        entry = self.stack.services.get(name)
        timeout = entry.start_timeout_s if entry else 30.0
        deadline = time.monotonic() + timeout
        while not self._stop.is_set():
            if self.health.is_alive(name):
                return
            rc = child.proc.poll()
            if rc is not None:
                child.proc.drain()
                why = f": {child.proc.tail[-1]}" if child.proc.tail else ""
                raise _StartError(name, f"exited with code {rc} during start-up{why}")
            if time.monotonic() > deadline:
                raise _StartError(name, f"not live after {timeout:.0f} s")
            time.sleep(0.02)

    def _restart(self, name: str, child: Child) -> None:
        child.restart_at = None
        child.restarts += 1
        self.say(f"restarting {name} (restart {child.restarts}/{child.policy.max_restarts})")
        if name == RECORDER and self.mcap is not None:
            # Never over the killed file: it is kept for `harvest recover`.
            nxt = part_path(self.mcap, len(self.mcap_parts))
            self.mcap_parts.append(nxt)
            argv = child.proc.argv
            argv[argv.index("--out") + 1] = str(nxt)
            self.say(f"the recording goes on in {nxt}")
        self.health.started(name, child)
        child.proc.start()

    def _check_child(self, name: str, child: Child) -> tuple[int, str] | None:
        now = time.monotonic()
        if child.done:
            return None
        if child.restart_at is not None:
            if now >= child.restart_at:
                self._restart(name, child)
            return None
        rc = child.proc.poll()
        if rc is None:
            if not self.health.hung(child, now):
                return None
            if self._answers(name, child):
                # A link that dropped and is being re-dialled (a loaded machine can miss a
                # lease): the process still answers, so it is not hung. Judge again later.
                self.say(f"{name} lost its liveliness but answers its status: not hung")
                child.lost_at = time.monotonic()
                return None
            # A service that finished drops its liveliness and its status before its process
            # ends (interpreter teardown, slow under load): a process that exits now was not hung.
            rc = child.proc.wait_exit(self.exit_grace_s)
            if rc is None:
                self.say(f"{name} lost its liveliness while its process runs: hung, killing it")
                child.proc.signal(signal.SIGKILL)
                child.was_alive = False
                return None
        child.proc.exit_codes.append(rc)
        if rc == 0:
            child.done = True
            if child.main:
                self.say(f"{name} finished: stopping the run")
                return 0, ""
            self.say(f"{name} exited normally")
            return None
        child.proc.drain()  # its last lines (the reason) before we judge
        # A recorder that cannot write its file (2: cannot create it, 3: disk full or I/O
        # error, recorder/__main__.py) would fail the same way again: no restart.
        cannot_write = name == RECORDER and rc in (2, 3)
        backoff = None if cannot_write else child.backoff_s()
        if backoff is not None:
            self.say(f"{name} failed (exit code {rc}); restart in {backoff:.1f} s")
            child.restart_at = now + backoff
            return None
        child.done = child.failed = True
        tail = " / ".join(child.proc.tail[-3:])
        if not child.essential:
            text = (
                f"{name} failed for good (exit code {rc}): {tail}; the run goes on without it "
                f"(recording.required is false)"
            )
            self.say(f"WARNING: {text}")
            self.warnings.append(text)
            return None
        return 1, f"{name} failed for good (exit code {rc}): {tail}"

    def _answers(self, name: str, child: Child, timeout_s: float = 0.2) -> bool:
        """Whether ``name``'s current process answers a status query within ``timeout_s``
        (a hung process cannot: its status queryable runs in its own Python)."""
        if self.bus is None or child.proc.pid is None:
            return False
        try:
            got = self.bus.query_status(name, timeout_s)
        except Exception:  # the bus itself is in trouble: trust the liveliness
            return False
        return any(st.pid == child.proc.pid for st in got)

    # ---- run -------------------------------------------------------------------------------
    def run(self) -> RunResult:
        t0 = time.monotonic()
        self._install_signals()
        failure = ""
        code = 0
        try:
            self._build_children()
            self._check_certificates()
            if self.stack.routes_here():
                self._start_router()
            self.bus = self._open_bus()
            self.bus.watch_health(self.health.on_health)
            for hook in self.on_bus:  # e.g. `harvest run`'s progress display subscribes here
                hook(self.bus)
            for name in self.start_order():
                if self._stop.is_set():
                    break
                self._start_child(name)
                self.say(f"{name} is live (pid {self.children[name].proc.pid})")
            self._main_token()
            code, failure = self._watch()
        except _StartError as exc:
            code, failure = 1, str(exc)
        except BusError as exc:
            code, failure = 1, str(exc)
        finally:
            if failure:
                self.say(f"FAILED: {failure}")
            self.shutdown()
        if self._interrupts and code == 0:
            code = 130
        return RunResult(
            code,
            self.run_id,
            self.mcap,
            self.log_path,
            time.monotonic() - t0,
            self.children,
            failure,
            self.mcap_parts,
            self.warnings,
        )

    def _main_token(self) -> None:
        """Multi-host: the host running the main service says so with a liveliness token; a
        host without one follows it and ends its run when the token is gone for good."""
        assert self.bus is not None
        if any(c.main for c in self.children.values()):
            self.bus.declare_token(MAIN_TOKEN)
        elif any(e.main for e in self.stack.services.values()) and self.stack.host is not None:
            self.bus.watch_token(MAIN_TOKEN, self._on_main_token)

    def _on_main_token(self, present: bool) -> None:
        self._main_seen = self._main_seen or present
        self._main_lost_at = None if present else time.monotonic()

    def _main_finished(self, now: float) -> bool:
        """The main service's host is gone for longer than a router restart takes."""
        lost = self._main_lost_at
        return self._main_seen and lost is not None and now - lost > self.follow_grace_s

    def _watch(self) -> tuple[int, str]:
        """Poll children until the main one ends, one fails for good, or we are stopped."""
        while not self._stop.is_set():
            now = time.monotonic()
            outcome = self._check_router(now)
            if outcome is not None:
                return outcome
            if self.bus is not None:
                self.health.link(self.bus.router_connected())
                for line in self.health.take_lines():
                    self.say(line)
            for name, child in self.children.items():
                outcome = self._check_child(name, child)
                if outcome is not None:
                    return outcome
            if self._main_finished(now):
                self.say("the run's main service (on another host) has finished: stopping")
                return 0, ""
            time.sleep(0.05)
        return 0, ""

    def shutdown(self) -> None:
        for name in self.stop_order():
            child = self.children[name]
            if child.proc.running():
                rc = child.proc.stop(timeout_s=15.0 if name == RECORDER else 10.0)
                if rc is not None:
                    child.proc.exit_codes.append(rc)
                if rc not in (0, None):
                    self.say(f"{name} stopped with exit code {rc}")
        if self.bus is not None:
            self.bus.close()
            self.bus = None
        if self.router is not None:
            self.router.proc.stop(timeout_s=5.0)
        self.sink.close()
        shutil.rmtree(self._tmp, ignore_errors=True)

    def _install_signals(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return

        def handler(signum: int, _frame: object) -> None:
            self._interrupts += 1
            if self._interrupts == 1:
                self.say(
                    f"{signal.Signals(signum).name}: stopping in order (again to kill everything)"
                )
                self._stop.set()
            else:
                for c in self.children.values():
                    c.proc.signal(signal.SIGKILL)

        signal.signal(signal.SIGINT, handler)
        signal.signal(signal.SIGTERM, handler)


class _StartError(RuntimeError):
    def __init__(self, name: str, why: str) -> None:
        super().__init__(f"{name} {why}")
