"""A child process in its own process group, with prefixed, coloured log lines."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

_COLOURS = [36, 32, 33, 35, 34, 91, 92, 93, 94, 95, 96]


class LogSink:
    """Writes ``name | line`` to the terminal (coloured on a TTY) and to a run log file."""

    def __init__(self, file: Path | None = None, quiet: bool = False) -> None:
        self._lock = threading.Lock()
        self._colour: dict[str, int] = {}
        self._tty = sys.stdout.isatty()
        self.path = file
        self._file: IO[str] | None = open(file, "a") if file else None  # noqa: SIM115
        self.quiet = quiet
        self.width = 12

    def line(self, name: str, text: str) -> None:
        with self._lock:
            if name not in self._colour:
                self._colour[name] = _COLOURS[len(self._colour) % len(_COLOURS)]
            tag = name.ljust(self.width)
            if self._file:
                self._write_file(f"{tag}| {text}\n")
            if self.quiet:
                return
            if self._tty:
                print(f"\x1b[{self._colour[name]}m{tag}|\x1b[0m {text}", flush=True)
            else:
                print(f"{tag}| {text}", flush=True)

    def _write_file(self, line: str) -> None:
        """A run log that cannot be written any more (disk full) must not stop the run: the
        lines go on to the terminal, with one line saying why the file ends here."""
        assert self._file is not None
        try:
            self._file.write(line)
            self._file.flush()
        except OSError as exc:
            with contextlib.suppress(OSError):
                self._file.close()
            self._file = None
            print(
                f"{'supervisor'.ljust(self.width)}| cannot write the run log {self.path}: "
                f"{exc.strerror or exc}; logging to the terminal only",
                file=sys.stderr,
                flush=True,
            )

    def close(self) -> None:
        if self._file:
            with contextlib.suppress(OSError):
                self._file.close()


@dataclass
class ManagedProcess:
    """One service process; ``start`` may be called again to restart it."""

    name: str
    argv: list[str]
    sink: LogSink
    env: dict[str, str] = field(default_factory=dict)
    proc: subprocess.Popen[bytes] | None = None
    started_at: float = 0.0
    exit_codes: list[int] = field(default_factory=list)
    tail: list[str] = field(default_factory=list)
    _reader: threading.Thread | None = None

    def start(self) -> None:
        env = {**os.environ, "PYTHONUNBUFFERED": "1", **self.env}
        self.proc = subprocess.Popen(
            self.argv,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
            env=env,
        )
        self.started_at = time.monotonic()
        self._reader = threading.Thread(
            target=self._pump, args=(self.proc,), daemon=True, name=f"log-{self.name}"
        )
        self._reader.start()

    def _pump(self, proc: subprocess.Popen[bytes]) -> None:
        assert proc.stdout is not None
        for raw in proc.stdout:
            text = raw.decode(errors="replace").rstrip()
            self.tail = [*self.tail[-19:], text]
            self.sink.line(self.name, text)

    def drain(self, timeout_s: float = 1.0) -> None:
        """Wait (briefly) until an ended process's last output lines are in ``tail``."""
        if self._reader is not None and not self.running():
            self._reader.join(timeout=timeout_s)

    @property
    def pid(self) -> int | None:
        return self.proc.pid if self.proc else None

    def poll(self) -> int | None:
        """Exit code once the process has ended, else None."""
        return self.proc.poll() if self.proc is not None else None

    def wait_exit(self, timeout_s: float) -> int | None:
        """Exit code if the process ends within ``timeout_s``, else None."""
        if self.proc is None:
            return None
        try:
            return self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return None

    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def signal(self, sig: int) -> None:
        if self.running() and self.proc is not None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, sig)

    def stop(self, timeout_s: float = 10.0) -> int | None:
        """SIGTERM the group, wait, then SIGKILL; returns the exit code."""
        if self.proc is None:
            return None
        if self.running():
            self.signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                self.sink.line(self.name, f"did not stop within {timeout_s:.0f} s: SIGKILL")
                self.signal(signal.SIGKILL)
                self.proc.wait()
        if self._reader:
            self._reader.join(timeout=2.0)
        return self.proc.returncode
