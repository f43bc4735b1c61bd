"""The sim as a real process: under the supervisor in lock-step, recorded; two runs give the same
bytes; the recording holds 15 Hz frames, 120 Hz joint states and the truth, and plays back
through camera_file."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from schemas.topics import TOPICS
from services.camera_file import SERVICE as FILE_CAM
from services.recorder.inspect import read_info
from services.runtime.settings import load_settings
from services.sim.physics import rot_of
from services.sim.render.camera import head_camera_pose
from services.testkit import run_source
from tests.helpers import harvest, payloads_by_topic, short_dir
from tests.sim_helpers import scenario_file

pytestmark = pytest.mark.integration


def test_sim_runs_in_lockstep_under_the_supervisor_and_is_recorded() -> None:
    d = short_dir()
    sc = scenario_file(
        d, events=[{"kind": "hand_sweep", "start_s": 0.2, "duration_s": 0.5, "fruit": 0}]
    )
    stack = d / "sim.yaml"
    stack.write_text(f"""
name: test-sim
mode: lockstep
master: sim
scenario: test
recording: {{enabled: true, dir: {d / "rec"}}}
services:
  sim:
    main: true
    settings: {{scenario: {sc}, duration_s: 1.0}}
""")
    for run in ("simrun", "again"):
        r = harvest(
            "run",
            "--stack",
            str(stack),
            "--run-id",
            run,
            "--quiet",
            "--listen",
            f"unixsock-stream/{d}/{run}.sock",
        )
        assert r.returncode == 0, r.stdout + r.stderr
    mcap = d / "rec" / "simrun.mcap"
    rec = payloads_by_topic(mcap)
    assert rec == payloads_by_topic(d / "rec" / "again.mcap")  # two processes, same bytes
    assert len(rec["robot/joint_state"]) == 121  # ticks 0 .. 120 of 1 s at 120 Hz
    assert len(rec["camera/rgbd"]) == len(rec["sim/truth"]) == 16  # every 8th tick: 15 Hz
    frames = [TOPICS["camera/rgbd"].codec.decode(p) for _, p in rec["camera/rgbd"]]
    truths = [TOPICS["sim/truth"].codec.decode(p) for _, p in rec["sim/truth"]]
    assert [f.header.stamp_ns for f in frames] == [t.header.stamp_ns for t in truths]
    assert [t.frame_seq for t in truths] == [f.header.seq for f in frames]
    assert frames[0].rgb.shape == (480, 640, 3) and frames[0].depth.max() > 0
    pose = frames[0].meta.T_world_camera
    np.testing.assert_allclose(pose.position_m, head_camera_pose()[:3, 3], atol=1e-9)
    np.testing.assert_allclose(rot_of(pose.orientation_xyzw), head_camera_pose()[:3, :3], atol=1e-9)
    assert any(t.occluder_active for t in truths) and truths[0].fruits[0].visible_fraction > 0.9
    info = read_info(mcap)
    assert info.run["stack_name"] == "test-sim" and info.run["master"] == "sim"

    # The recording plays back through the file camera, frame for frame.
    s = load_settings(FILE_CAM.settings, {"path": str(mcap)})
    played = [o.msg for o in run_source(FILE_CAM, s, lambda t, m: [])]
    assert len(played) == 16
    assert all(
        np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)
        for a, b in zip(played, frames, strict=True)
    )
    assert [p.header.stamp_ns for p in played] == [f.header.stamp_ns for f in frames]
    shutil.rmtree(d, ignore_errors=True)
