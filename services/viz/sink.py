"""Open the recording stream and its sinks: an .rrd file, a spawned viewer, a served gRPC (and
web) viewer, or a connection to a running viewer; several at once."""

from __future__ import annotations

import logging
import os
import shutil
import sys
from pathlib import Path
from typing import Any

from services.viz import Settings
from services.viz.blueprint import blueprint

log = logging.getLogger("viz.sink")

APPLICATION_ID = "orange-harvest"


class SinkError(RuntimeError):
    """A sink could not be opened (no viewer executable, no display, bad path)."""


def rerun_executable() -> str:
    """The `rerun` viewer of this environment (the venv's bin folder first, then PATH)."""
    beside = Path(sys.executable).parent / "rerun"
    if beside.exists():
        return str(beside)
    found = shutil.which("rerun")
    if found is None:
        raise SinkError("no `rerun` viewer executable (it comes with the rerun-sdk package)")
    return found


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def open_stream(settings: Settings, recording_id: str, save_path: Path | None = None) -> Any:
    """A ``rerun.RecordingStream`` with the sinks the settings ask for (``save_path``
    overrides ``settings.save_path``). Raises SinkError when none can be opened."""
    import rerun as rr

    try:
        return _open(rr, settings, recording_id, save_path)
    except (RuntimeError, ValueError) as exc:  # e.g. a port in use, a viewer that will not start
        raise SinkError(f"cannot open the Rerun stream: {exc}") from None


def _open(rr: Any, settings: Settings, recording_id: str, save_path: Path | None) -> Any:
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
    sinks: list[Any] = []
    path = save_path or settings.save_path
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        sinks.append(rr.FileSink(str(path)))
    url = f"rerun+http://127.0.0.1:{settings.grpc_port}/proxy"
    if settings.viewer == "spawn":
        if not has_display():
            raise SinkError(
                "cannot spawn a viewer: no display (DISPLAY/WAYLAND_DISPLAY unset); use "
                "--serve (then open the printed URL) or write an .rrd (view --out, run --save)"
            )
        rr.spawn(
            port=settings.grpc_port,
            connect=False,
            executable_path=rerun_executable(),
            hide_welcome_screen=True,
        )
        sinks.append(rr.GrpcSink(url))
    elif settings.viewer == "connect":
        sinks.append(rr.GrpcSink(settings.connect_url))
    elif settings.viewer == "serve":
        sinks.append(rr.GrpcServerSink(bind_ip="127.0.0.1", port=settings.grpc_port))
    if not sinks:
        raise SinkError("nothing to draw to: choose a viewer or a file to save")
    rec.set_sinks(*sinks, default_blueprint=blueprint())
    if settings.viewer == "serve":
        if settings.web_port:
            try:
                rr.serve_web_viewer(web_port=settings.web_port, open_browser=False, connect_to=url)
                log.info("web viewer: http://127.0.0.1:%d (data at %s)", settings.web_port, url)
            except Exception as exc:  # a busy port must not end the gRPC stream
                log.warning("no web viewer on port %d: %s", settings.web_port, exc)
        log.info("serving the stream: `rerun --connect %s`", url)
    return rec
