"""Record sim frames and tracks made from the sim's truth through the real scene process, then
resim it: the recorded inputs give 100 % identical scene states."""

from __future__ import annotations

import json
import signal
import threading
from pathlib import Path

import pytest

from schemas import TOPICS
from schemas.base import Header
from schemas.harvest import HarvestEvent
from services.scene.truth_tracks import TruthTracks
from tests.helpers import BusEnv, harvest, payloads_by_topic, wait_until
from tests.sim_helpers import core, scenario_file

pytestmark = pytest.mark.integration

N_FRAMES = 10


def test_scene_resims_identically(bus_env: BusEnv, tmp_path: Path) -> None:
    out = bus_env.dir / "scene.mcap"
    rec = bus_env.service("services.recorder", "--out", str(out), log="recorder.log")
    me = bus_env.client("sim_and_tracker")
    wait_until(lambda: "recorder" in me.live_services(0.3), 30, "recorder")
    bus_env.service("services.scene", "--time-mode", "lockstep", log="scene.log")
    wait_until(lambda: "scene" in me.live_services(0.3), 60, "scene")
    got: list[int] = []
    lock = threading.Lock()

    def on_state(sample) -> None:
        with lock:
            got.append(TOPICS["scene/state"].codec.header(sample.payload).answers_seq)

    me.subscribe_raw("scene/state", on_state)
    pubs = {k: me.publisher(k) for k in ("camera/rgbd", "perception/tracks", "harvest/events")}
    sc = scenario_file(
        tmp_path,
        fruits=[
            {"position_world_m": [0.6, -0.15, 1.35], "leaf_cover": "none"},
            {"position_world_m": [0.702, -0.25, 1.405], "leaf_cover": "light"},
        ],
        events=[{"kind": "hand_sweep", "start_s": 0.1, "duration_s": 0.5, "fruit": 0}],
    )
    sim, oracle = core(sc, camera_every_ticks=4), TruthTracks()
    k = 0
    try:
        while k < N_FRAMES:
            for group in sim.emit():
                topics = dict(group)
                if "camera/rgbd" not in topics:
                    continue
                pubs["camera/rgbd"].put(topics["camera/rgbd"])
                tracks = oracle(topics["sim/truth"])
                pubs["perception/tracks"].put(tracks)  # lock-step by hand: wait for the answer
                wait_until(lambda k=k: len(got) > k, 30, f"scene/state for frame {k}")
                if k == 5:
                    h = Header(stamp_ns=tracks.header.stamp_ns, seq=0, source="planner")
                    pubs["harvest/events"].put(
                        HarvestEvent(header=h, event="fruit_collected", fruit_id=1)
                    )
                k += 1
            sim.advance()
    finally:
        sim.close()
    rec.send_signal(signal.SIGINT)
    assert rec.wait(timeout=30) == 0, bus_env.log("recorder.log")

    recorded = payloads_by_topic(out)
    assert len(recorded["scene/state"]) == len(recorded["perception/tracks"]) == N_FRAMES
    states = [TOPICS["scene/state"].codec.decode(p) for _, p in recorded["scene/state"]]
    assert {f.fruit_id for s in states for f in s.fruits} == {1, 2}  # the chain really measured
    assert states[-1].fruits[0].status == "harvested"

    r = harvest("resim", str(out), "--services", "scene", "--json", timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    rep = json.loads(r.stdout)
    assert rep["ok"] and rep["identical_ratio"] == 1.0
    (t,) = rep["topics"]
    assert t["topic"] == "scene/state" and t["identical"] == t["recorded"] == N_FRAMES, t
