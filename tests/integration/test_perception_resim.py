"""Record scripted camera frames through the real detector and tracker processes, then resim
both: the recorded frames give 100 % identical detections and tracks."""

from __future__ import annotations

import json
import signal
import threading

import pytest

from schemas import TOPICS
from services.testkit.scene2d import Scene2D
from tests.helpers import BusEnv, harvest, payloads_by_topic, wait_until

pytestmark = pytest.mark.integration

N_FRAMES = 20


def test_detector_and_tracker_resim_identically(bus_env: BusEnv) -> None:
    out = bus_env.dir / "perception.mcap"
    rec = bus_env.service("services.recorder", "--out", str(out), log="recorder.log")
    me = bus_env.client("camera")
    wait_until(lambda: "recorder" in me.live_services(0.3), 30, "recorder")
    for name in ("detector", "tracker"):
        bus_env.service(f"services.{name}", "--time-mode", "lockstep", log=f"{name}.log")
    wait_until(
        lambda: {"detector", "tracker"} <= set(me.live_services(0.3)),
        60,
        "detector and tracker",
    )
    got: list[int] = []
    lock = threading.Lock()

    def on_tracks(sample) -> None:
        with lock:
            got.append(TOPICS["perception/tracks"].codec.header(sample.payload).answers_seq)

    me.subscribe_raw("perception/tracks", on_tracks)
    pub = me.publisher("camera/rgbd")
    scene = Scene2D(seed=5, n_fruit=8, sweep=(4, 14), sway=True)
    for k in range(N_FRAMES):
        pub.put(scene.frame(k).frame)  # lock-step by hand: the next frame after the answer
        wait_until(lambda k=k: len(got) > k, 30, f"tracks for frame {k}")
    rec.send_signal(signal.SIGINT)
    assert rec.wait(timeout=30) == 0, bus_env.log("recorder.log")

    recorded = payloads_by_topic(out)
    assert len(recorded["perception/detections"]) == len(recorded["perception/tracks"]) == N_FRAMES
    tracks = [TOPICS["perception/tracks"].codec.decode(p) for _, p in recorded["perception/tracks"]]
    assert max(len(t.tracks) for t in tracks) >= 5  # the chain really tracked fruit

    r = harvest("resim", str(out), "--services", "detector,tracker", "--json", timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    rep = json.loads(r.stdout)
    assert rep["ok"] and rep["identical_ratio"] == 1.0
    for t in rep["topics"]:
        assert t["identical"] == t["recorded"] == N_FRAMES, t
