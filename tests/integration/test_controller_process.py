"""The controller as a process: in live mode its wall-clock watchdog stops the arms when joint
states stop; in lock-step, resim of a recording reproduces every command and status byte for
byte and reports the diagnostics topic as not compared."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import pytest

from schemas import TOPICS, JointVelocityCommand
from services.controller import SERVICE
from services.controller.kinsim import KinematicSim
from services.controller.scenarios import fruit, harvest_target, scene
from services.recorder.writer import RUN_METADATA, RunWriter
from services.replay.resim import resim
from services.runtime.settings import load_settings
from services.testkit import FakeNode
from tests.helpers import BusEnv, wait_until

pytestmark = pytest.mark.integration
FRUIT = (0.75, 0.05, 1.05)


def test_live_watchdog_stops_the_arms_when_joint_states_stop(bus_env: BusEnv) -> None:
    bus_env.service("services.controller", "--time-mode", "live", log="controller.log")
    me = bus_env.client("tester")
    wait_until(lambda: "controller" in me.live_services(0.3), 30, "controller liveliness")
    cmds: list[JointVelocityCommand] = []
    lock = threading.Lock()

    def on_cmd(key: str, msg: Any) -> None:
        with lock:
            cmds.append(msg)

    me.subscribe("robot/command", on_cmd)
    sim = KinematicSim()
    me.publisher("scene/state").put(scene())
    me.publisher("plan/target").put(harvest_target(FRUIT))
    me.publisher("robot/joint_state").put(sim.joint_state())
    wait_until(lambda: len(cmds) >= 1, 20, "the answer to the joint state")
    assert cmds[0].header.answers_seq == 0 and not cmds[0].hold
    # no more joint states: within ~100 ms (+ one 20 ms check) the watchdog stops the arms
    wait_until(lambda: len(cmds) >= 2, 5, "the watchdog's stop")
    stop = cmds[1]
    assert stop.hold and stop.header.answers_seq is None and "no joint state" in stop.reason
    assert all(v == 0.0 for a in stop.arms.values() for v in a.velocity_rad_s)


def record_in_process(path: Path, ticks: int) -> None:
    """A recording made by the core in-process: the inputs, each followed by its outputs, as
    a lock-step run records them, with the run metadata resim reads."""
    settings = load_settings(SERVICE.settings, {})
    node = FakeNode(SERVICE, settings)
    sim = KinematicSim()
    items: list[tuple[str, Any]] = []

    def feed(topic: str, msg: Any) -> list[tuple[str, Any]]:
        outs = [(o.topic, o.msg) for o in node.feed([(topic, msg)])]
        items.append((topic, msg))
        items.extend(outs)
        return outs

    feed("scene/state", scene([fruit(1, FRUIT), fruit(2, (0.8, -0.2, 1.0))], trunk_xy_m=(1.0, 0.2)))
    for k in range(ticks):
        feed("plan/target", harvest_target(FRUIT, fruit_id=1, stamp_ns=sim.stamp_ns, seq=k))
        outs = dict(feed("robot/joint_state", sim.joint_state()))
        sim.apply(outs["robot/command"])
    with open(path, "wb") as f:
        w = RunWriter(f)
        w.add_metadata(
            RUN_METADATA, {"services": json.dumps({"controller": settings.model_dump(mode="json")})}
        )
        for i, (topic, msg) in enumerate(items):
            codec = TOPICS[topic].codec
            assert w.write(topic, codec.encode(msg), codec.zenoh_encoding, 1_000 + i) == "ok"
        w.finish()


def test_resim_reproduces_the_controller_byte_for_byte(tmp_path: Path) -> None:
    path = tmp_path / "controller.mcap"
    record_in_process(path, 60)
    report = resim(path, ["controller"], timeout_s=20.0)
    topics = {t.topic: t for t in report.topics}
    assert report.ok and report.identical_ratio == 1.0, report.to_json()
    assert topics["robot/command"].identical == topics["control/status"].identical == 60
    diag = topics["diag/controller"]
    assert not diag.compared and diag.not_compared == 60 and diag.missing == 0
