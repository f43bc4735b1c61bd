"""A headless screenshot of an .rrd: a viewer without a window renders the default blueprint at
the end of the run (sim time) and saves a PNG.

Needs a Vulkan driver; on a machine without a GPU, Mesa's lavapipe (Debian:
`apt-get install mesa-vulkan-drivers`). `rerun FILE --headless --screenshot-to` exists too, but
it shoots before a larger file has finished loading; this waits for the load.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

from services.viz.paths import SIM_TIME
from services.viz.sink import rerun_executable


class ScreenshotError(RuntimeError):
    """The headless viewer could not start or render; the message carries its last output."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def screenshot(
    rrd: Path,
    png: Path,
    window: tuple[int, int] = (1600, 900),
    timeout_s: float = 60.0,
    settle_s: float = 6.0,
) -> Path:
    """Render ``rrd`` in a headless viewer and save ``png``; returns ``png``.

    ``settle_s`` lets the viewer's start-up notices fade and the plots finish their zoom.
    """
    from rerun.experimental import ViewerClient

    port = free_port()
    env = {**os.environ, "WGPU_BACKEND": os.environ.get("WGPU_BACKEND", "vulkan")}
    log = png.with_suffix(".viewer.log")
    png.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "wb") as log_file:
        argv = [rerun_executable(), "--headless", "--hide-welcome-screen", "--port", str(port)]
        argv += ["--window-size", f"{window[0]}x{window[1]}"]
        viewer = subprocess.Popen(
            argv, stdout=log_file, stderr=subprocess.STDOUT, env=env, start_new_session=True
        )
    try:
        client = _connect(
            ViewerClient, f"rerun+http://127.0.0.1:{port}/proxy", viewer, log, timeout_s
        )
        client.open(str(rrd.resolve()))
        deadline = time.monotonic() + timeout_s
        while client.get_state().loading:
            if time.monotonic() > deadline:
                raise ScreenshotError(f"{rrd} still loading after {timeout_s:.0f} s")
            time.sleep(0.2)
        _seek_end(client)
        time.sleep(settle_s)
        client.save_screenshot(str(png.resolve()))
    finally:
        stop_group(viewer)
    if not png.exists():
        raise ScreenshotError(f"the viewer saved no screenshot; see {log}")
    log.unlink(missing_ok=True)
    return png


def stop_group(p: subprocess.Popen[bytes], timeout_s: float = 10.0) -> None:
    """Stop the viewer and its children: `rerun` from the venv is a launcher that runs the real
    binary as a child, so the whole process group (its own session) must go."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(p.pid, sig)
        except ProcessLookupError:
            break
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            p.poll()  # reap the launcher so that only live members keep the group
            try:
                os.killpg(p.pid, 0)
            except ProcessLookupError:
                p.wait()
                return
            time.sleep(0.05)
    p.wait()


def _connect(
    cls: Any, url: str, viewer: subprocess.Popen[bytes], log: Path, timeout_s: float
) -> Any:
    deadline = time.monotonic() + timeout_s
    while True:
        if viewer.poll() is not None:
            tail = log.read_text(errors="replace").strip().splitlines()[-3:]
            raise ScreenshotError(
                f"the headless viewer exited with code {viewer.returncode}: {' / '.join(tail)} "
                "(no Vulkan driver? on a CPU-only machine install mesa-vulkan-drivers)"
            )
        try:
            client = cls.connect(url)
            client.get_state()
            return client
        except Exception:
            if time.monotonic() > deadline:
                raise ScreenshotError(
                    f"no headless viewer at {url} after {timeout_s:.0f} s"
                ) from None
            time.sleep(0.2)


def _seek_end(client: Any) -> None:
    """Put the time cursor at the last sim time, so the picture shows the whole run."""
    state = client.get_state()
    for rec in state.recordings:
        for tl in rec.timelines:
            if tl.name == SIM_TIME and tl.end is not None:
                client.set_time(
                    SIM_TIME, duration=np.timedelta64(tl.end, "ns"), play_state="paused"
                )
                return
