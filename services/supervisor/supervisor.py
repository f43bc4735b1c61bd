"""Supervisor: starts the router, the recorder and every service of a stack, watches their health
by liveliness, restarts by policy, and stops them in order so the recording is finished last."""

from __future__ import annotations

import json
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
from services.supervisor.metadata import run_metadata
from services.supervisor.process import LogSink, ManagedProcess
from services.supervisor.stack import (
    RestartPolicy,
    Stack,
    StackError,
    resolve_service_settings,
)

SELF = "supervisor"


@dataclass
class Child:
    """A managed service and its restart bookkeeping."""

    proc: ManagedProcess
    policy: RestartPolicy
    main: bool = False
    restarts: int = 0
    restart_at: float | None = None
    done: bool = False  # exited for good (normally or not)
    failed: bool = False
    was_alive: bool = False
    lost_at: float | None = None  # when its liveliness went away while the process ran


@dataclass
class RunResult:
    exit_code: int
    run_id: str
    mcap: Path | None
    log: Path
    wall_s: float
    children: dict[str, Child] = field(default_factory=dict)
    failure: str = ""


def local_endpoint(listen: str) -> str:
    """The endpoint a local client connects to for a router listening on ``listen``."""
    return listen.replace("0.0.0.0", "127.0.0.1").replace("[::]", "[::1]")


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
    ) -> None:
        self.stack, self.stack_path, self.run_id, self.profile = stack, stack_path, run_id, profile
        self.python, self.hung_grace_s = python, hung_grace_s
        self.namespace = f"harvest/{run_id}"
        rec_dir = stack.recording.dir
        rec_dir.mkdir(parents=True, exist_ok=True)
        self.mcap = rec_dir / f"{run_id}.mcap" if stack.recording.enabled else None
        self.log_path = rec_dir / f"{run_id}.log"
        self.sink = LogSink(self.log_path, quiet=quiet)
        self.endpoint = local_endpoint(stack.router.listen[0])
        self.children: dict[str, Child] = {}
        self.alive: dict[str, bool] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._interrupts = 0
        self._tmp = Path(tempfile.mkdtemp(prefix=f"{run_id}-"))
        self.bus: Bus | None = None
        self.router: ManagedProcess | None = None
        self.on_event: list[Any] = []  # hooks: callables(name, text) for progress displays

    # ---- set-up ----------------------------------------------------------------------------
    def say(self, text: str) -> None:
        self.sink.line(SELF, text)

    def _service_bus(self) -> BusSettings:
        return BusSettings(
            mode="client",
            connect=(self.endpoint,),
            namespace=self.namespace,
            tls_dir=self.stack.security.tls_dir,
        )

    def _check_certificates(self) -> None:
        """Secured profile: every process's certificate exists, before anything starts."""
        tls_dir = self.stack.security.tls_dir
        if tls_dir is None:
            return
        names = [SELF, *self.children]
        if self.stack.router.enabled:
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
        """Answers the master awaits per published topic, from every enabled service's spec."""
        st = self.stack
        assert st.master is not None
        specs = [service_def(n).spec for n in st.enabled()]
        wait = {t: answer_closure(t, specs) for t in service_def(st.master).spec.outputs}
        consumers = [n for n in st.enabled() if n != st.master]
        if st.recording.enabled:
            consumers.insert(0, "recorder")
        return LockstepPlan(wait={k: v for k, v in wait.items() if v}, consumers=tuple(consumers))

    def _build_children(self) -> None:
        settings = resolve_service_settings(self.stack)
        if self.stack.recording.enabled:
            meta_file = self._tmp / "run-meta.json"
            meta = run_metadata(
                self.stack, self.stack_path, self.profile, self.run_id, self.namespace, settings
            )
            meta_file.write_text(json.dumps(meta))
            assert self.mcap is not None
            argv = self._argv(
                "recorder",
                settings["recorder"].model_dump_json(),
                ["--out", str(self.mcap), "--run-meta", str(meta_file)],
            )
            self.children["recorder"] = Child(
                ManagedProcess("recorder", argv, self.sink), RestartPolicy(policy="never")
            )
        for name in self.stack.enabled():
            entry = self.stack.services[name]
            extra: list[str] = []
            if name == self.stack.master and self.stack.mode == "lockstep":
                extra = ["--lockstep-plan", self.lockstep_plan().model_dump_json()]
            argv = self._argv(name, settings[name].model_dump_json(), extra)
            self.children[name] = Child(
                ManagedProcess(name, argv, self.sink), entry.restart, main=entry.main
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
        if "recorder" in order:
            order.remove("recorder")
            order.append("recorder")
        return order

    # ---- health ----------------------------------------------------------------------------
    def _on_health(self, name: str, alive: bool) -> None:
        with self._lock:
            self.alive[name] = alive
            child = self.children.get(name)
            if child is not None:
                child.was_alive = child.was_alive or alive
                child.lost_at = None if alive else time.monotonic()

    def _start_router(self) -> None:
        r = self.stack.router
        argv = [self.python, "-m", "services.router", "--namespace", self.namespace]
        for e in r.listen:
            argv += ["-l", e]
        if r.zenoh_config:
            argv += ["--zenoh-config", str(r.zenoh_config)]
        if self.stack.security.tls_dir is not None:
            argv += ["--tls-dir", str(self.stack.security.tls_dir)]
        self.router = ManagedProcess("router", argv, self.sink)
        self.router.start()

    def _open_bus(self, timeout_s: float = 20.0) -> Bus:
        """Connect to the router, retrying while it starts; fail fast if it died."""
        deadline = time.monotonic() + timeout_s
        while True:
            if self.router is not None and self.router.poll() is not None:
                raise BusError(
                    f"the router exited with code {self.router.poll()}: "
                    f"{' / '.join(self.router.tail[-3:])}"
                )
            try:
                return Bus(SELF, self._service_bus())
            except BusError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    def _start_child(self, name: str) -> None:
        child = self.children[name]
        with self._lock:
            self.alive[name] = False
        child.proc.start()
        entry = self.stack.services.get(name)
        timeout = entry.start_timeout_s if entry else 30.0
        deadline = time.monotonic() + timeout
        while not self._stop.is_set():
            if self.alive.get(name):
                return
            rc = child.proc.poll()
            if rc is not None:
                raise _StartError(name, f"exited with code {rc} during start-up")
            if time.monotonic() > deadline:
                raise _StartError(name, f"not live after {timeout:.0f} s")
            time.sleep(0.02)

    # ---- run -------------------------------------------------------------------------------
    def run(self) -> RunResult:
        t0 = time.monotonic()
        self._install_signals()
        failure = ""
        code = 0
        try:
            self._build_children()
            self._check_certificates()
            if self.stack.router.enabled:
                self._start_router()
            self.bus = self._open_bus()
            self.bus.watch_health(self._on_health)
            for name in self.start_order():
                if self._stop.is_set():
                    break
                self._start_child(name)
                self.say(f"{name} is live (pid {self.children[name].proc.pid})")
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
        )

    def _watch(self) -> tuple[int, str]:
        """Poll children until the main one ends, one fails for good, or we are stopped."""
        while not self._stop.is_set():
            if self.router is not None and self.router.poll() is not None:
                return 1, f"the router exited with code {self.router.poll()}"
            for name, child in self.children.items():
                outcome = self._check_child(name, child)
                if outcome is not None:
                    return outcome
            time.sleep(0.05)
        return 0, ""

    def _check_child(self, name: str, child: Child) -> tuple[int, str] | None:
        now = time.monotonic()
        if child.done:
            return None
        if child.restart_at is not None:
            if now >= child.restart_at:
                child.restart_at = None
                child.restarts += 1
                self.say(
                    f"restarting {name} (restart {child.restarts}/{child.policy.max_restarts})"
                )
                child.was_alive = False
                child.proc.start()
            return None
        rc = child.proc.poll()
        if rc is None:
            self._check_hung(name, child, now)
            return None
        child.proc.exit_codes.append(rc)
        if rc == 0:
            child.done = True
            if child.main:
                self.say(f"{name} finished: stopping the run")
                return 0, ""
            self.say(f"{name} exited normally")
            return None
        if child.policy.policy == "on-failure" and child.restarts < child.policy.max_restarts:
            p = child.policy
            backoff = min(p.backoff_s * (2**child.restarts), p.backoff_max_s)
            self.say(f"{name} failed (exit code {rc}); restart in {backoff:.1f} s")
            child.restart_at = now + backoff
            return None
        child.done = child.failed = True
        tail = " / ".join(child.proc.tail[-3:])
        return 1, f"{name} failed for good (exit code {rc}): {tail}"

    def _check_hung(self, name: str, child: Child, now: float) -> None:
        """A running process whose liveliness vanished is hung (e.g. SIGSTOP): kill it so the
        restart policy applies."""
        lost = child.lost_at
        if child.was_alive and lost is not None and now - lost > self.hung_grace_s:
            self.say(f"{name} lost its liveliness while its process runs: hung, killing it")
            child.proc.signal(signal.SIGKILL)
            child.was_alive = False

    def shutdown(self) -> None:
        for name in self.stop_order():
            child = self.children[name]
            if child.proc.running():
                rc = child.proc.stop(timeout_s=15.0 if name == "recorder" else 10.0)
                if rc is not None:
                    child.proc.exit_codes.append(rc)
                if rc not in (0, None):
                    self.say(f"{name} stopped with exit code {rc}")
        if self.bus is not None:
            self.bus.close()
            self.bus = None
        if self.router is not None:
            self.router.stop(timeout_s=5.0)
        self.sink.close()

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
