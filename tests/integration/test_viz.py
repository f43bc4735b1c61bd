"""The viz service and `harvest view` with real processes: the live path draws what the offline
path draws, `harvest run --save` adds the service without slowing the lock-step run, and bad
recordings get clear errors."""

from __future__ import annotations

import os
import shutil
import signal
from collections import Counter
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from services.recorder.inspect import iter_messages
from services.registry import service_def
from tests.fixtures import viz_recording as fx
from tests.helpers import BusEnv, harvest, short_dir, wait_until, write_stack

pytestmark = pytest.mark.integration


def rows(path: Path) -> Counter[str]:
    out: Counter[str] = Counter()
    for chunk in RrdReader(path).stream():
        if not chunk.is_static:
            out[chunk.entity_path] += chunk.num_rows
    return out


def test_viz_is_a_registered_service_that_never_answers() -> None:
    sd = service_def("viz")
    assert sd.spec.inputs == ("**",) and sd.spec.outputs == () and dict(sd.spec.answers) == {}


def test_live_viz_draws_what_harvest_view_draws(bus_env: BusEnv, tmp_path: Path) -> None:
    live_rrd = tmp_path / "live.rrd"
    p = bus_env.service(
        "services.viz", "--settings-json", f'{{"save_path": "{live_rrd}"}}', log="viz.log"
    )
    observer = bus_env.client("observer")
    wait_until(lambda: "viz" in observer.live_services(0.5), 30, "the viz service")
    # At the recorded pace: as fast as possible drops RGB-D frames in Zenoh before they reach
    # any subscriber (see the report), which is not what this test is about.
    r = harvest("replay", str(fx.PATH), "--speed", "1", *bus_env.flags(), timeout=120)
    assert r.returncode == 0, r.stderr
    assert "published 409 messages" in r.stdout  # derived preview channels are never replayed

    def all_received() -> bool:
        (st,) = observer.query_status("viz")
        return sum(c.received for c in st.topics.values()) == 409

    wait_until(all_received, 30, "the viz service to receive every message")
    p.send_signal(signal.SIGTERM)
    assert p.wait(timeout=30) == 0, bus_env.log("viz.log")
    offline = tmp_path / "offline.rrd"
    r = harvest("view", str(fx.PATH), "--out", str(offline))
    assert r.returncode == 0, r.stderr
    assert rows(live_rrd) == rows(offline)
    assert RrdReader(live_rrd).recordings()[0].recording_id == bus_env.namespace.rsplit("/", 1)[-1]


def test_harvest_run_save_adds_viz_and_keeps_the_run_lockstep(tmp_path: Path) -> None:
    d = short_dir()
    try:
        stack = write_stack(d / "s.yaml", d / "rec", ticks=50)
        rrd = d / "run.rrd"
        listen = f"unixsock-stream/{d}/router.sock"
        args = ["--run-id", "vizrun", "--save", str(rrd), "--listen", listen, "--quiet"]
        r = harvest("run", "--stack", str(stack), *args, timeout=180)
        assert r.returncode == 0, r.stdout + r.stderr
        assert "viz" in r.stdout  # the summary lists every service
        ticks = [m for m in iter_messages(d / "rec" / "vizrun.mcap") if m.topic == "demo/tick"]
        assert len({m.sequence for m in ticks}) == 50
        got = rows(rrd)
        assert got["/plots/demo/value"] == 50 and got["/plots/demo/result"] == 50
        assert RrdReader(rrd).recordings()[0].recording_id == "vizrun"
    finally:
        shutil.rmtree(d, ignore_errors=True)


def test_view_of_a_truncated_recording_offers_recover(tmp_path: Path) -> None:
    data = fx.PATH.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    r = harvest("view", str(cut), "--out", str(tmp_path / "cut.rrd"))
    assert r.returncode == 1 and "harvest recover" in r.stderr
    assert not (tmp_path / "cut.rrd").exists()


def test_view_without_a_display_says_what_to_do(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = harvest("view", str(fx.PATH), env=env)
    assert r.returncode == 1 and "no display" in r.stderr and "--out" in r.stderr


def test_view_with_a_bad_setting_names_it(tmp_path: Path) -> None:
    r = harvest("view", str(fx.PATH), "--out", str(tmp_path / "x.rrd"), "--set", "d_s_m=-1")
    assert r.returncode == 1 and "d_s_m" in r.stderr


def _vulkan_driver() -> bool:
    dirs = (Path("/usr/share/vulkan/icd.d"), Path("/etc/vulkan/icd.d"))
    return any(d.is_dir() and any(d.glob("*.json")) for d in dirs)


@pytest.mark.skipif(
    not _vulkan_driver(), reason="no Vulkan driver (CPU-only: apt-get install mesa-vulkan-drivers)"
)
def test_headless_screenshot_renders_the_blueprint(tmp_path: Path) -> None:
    import cv2

    png = tmp_path / "shot.png"
    out = tmp_path / "x.rrd"
    # The size marks this test's viewer among the machine's processes (unique per test process:
    # another suite may run this test at the same time).
    width = 1234 + os.getpid() % 97
    size = f"{width}x777"
    args = ("--out", str(out), "--screenshot", str(png), "--window-size", size)
    r = harvest("view", str(fx.PATH), *args, timeout=180)
    assert r.returncode == 0, r.stdout + r.stderr
    image = cv2.imread(str(png))
    assert image is not None and image.shape[0] >= 777 and image.shape[1] >= width
    assert image.std() > 20  # drawn views, not a blank window
    assert not _processes_with(f"--window-size {size}")  # the viewer and its launcher are gone


def _processes_with(text: str) -> list[int]:
    found = []
    for proc in (p for p in Path("/proc").iterdir() if p.name.isdigit()):
        try:
            cmd = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if text in cmd:
            found.append(int(proc.name))
    return found
