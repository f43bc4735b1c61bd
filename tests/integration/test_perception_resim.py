"""A short sim run in lock-step with the real detector and tracker processes, recorded; resim of
both on the recorded frames gives 100 % identical detections and tracks."""

from __future__ import annotations

import json
import shutil

import pytest

from schemas import TOPICS
from tests.helpers import harvest, payloads_by_topic, short_dir
from tests.sim_helpers import scenario_file

pytestmark = pytest.mark.integration


def test_detector_and_tracker_resim_identically_on_a_recorded_sim_run() -> None:
    d = short_dir()
    sc = scenario_file(
        d,
        fruits=[
            {"position_world_m": [0.6, -0.15, 1.35], "leaf_cover": "none"},
            {"position_world_m": [0.7, 0.05, 1.45], "leaf_cover": "light"},
            {"position_world_m": [0.65, -0.05, 1.25], "leaf_cover": "none"},
        ],
        events=[{"kind": "hand_sweep", "start_s": 0.3, "duration_s": 0.8, "fruit": 0}],
    )
    stack = d / "perception.yaml"
    stack.write_text(f"""
name: test-perception
mode: lockstep
master: sim
recording: {{enabled: true, dir: {d / "rec"}}}
services:
  detector: {{}}
  tracker: {{settings: {{n_init: 3}}}}
  sim:
    main: true
    settings: {{scenario: {sc}, duration_s: 1.4}}
""")
    r = harvest(
        "run", "--stack", str(stack), "--run-id", "perc", "--quiet",
        "--listen", f"unixsock-stream/{d}/perc.sock",
        timeout=300,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    mcap = d / "rec" / "perc.mcap"
    rec = payloads_by_topic(mcap)
    n = len(rec["camera/rgbd"])
    assert n == 22  # 1.4 s at 15 Hz, t = 0 included
    assert len(rec["perception/detections"]) == len(rec["perception/tracks"]) == n
    tracks = [TOPICS["perception/tracks"].codec.decode(p) for _, p in rec["perception/tracks"]]
    assert max(sum(t.confirmed for t in m.tracks) for m in tracks) >= 2  # it really tracked

    r = harvest("resim", str(mcap), "--services", "detector,tracker", "--json", timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    rep = json.loads(r.stdout)
    assert rep["ok"] and rep["identical_ratio"] == 1.0
    for t in rep["topics"]:
        assert t["identical"] == t["recorded"] == n, t
    shutil.rmtree(d, ignore_errors=True)
