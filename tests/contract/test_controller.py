"""Contract test of the controller with the foundation's kit: declared topics, valid schemas,
one command and one status per joint state carrying its stamp, empty input, determinism (the
wall-clock diagnostics topic is present on every tick but not compared)."""

from __future__ import annotations

from typing import Any

from services.controller import SERVICE
from services.controller.kinsim import KinematicSim
from services.controller.scenarios import fruit, harvest_target, scene
from services.runtime.settings import load_settings
from services.testkit import ContractCase, Emitted, assert_contract

SETTINGS = load_settings(SERVICE.settings, {})
FRUIT = (0.75, 0.05, 1.05)


def script(ticks: int) -> list[tuple[str, Any]]:
    """Scene once, then per tick a target and a joint state; the joint states follow a
    kinematic sim driven by a fixed, smooth velocity (open loop: the script is data)."""
    sim = KinematicSim()
    out: list[tuple[str, Any]] = [
        ("scene/state", scene([fruit(1, FRUIT), fruit(2, (0.8, -0.2, 1.0))]))
    ]
    for k in range(ticks):
        out.append(("plan/target", harvest_target(FRUIT, fruit_id=1, stamp_ns=sim.stamp_ns, seq=k)))
        out.append(("robot/joint_state", sim.joint_state()))
        sim.q["cutter"] = sim.q["cutter"] + 0.002
        sim.tick += 1
    return out


def only_joint_states(ticks: int) -> list[tuple[str, Any]]:
    sim = KinematicSim()
    out = []
    for _ in range(ticks):
        out.append(("robot/joint_state", sim.joint_state()))
        sim.tick += 1
    return out


def holds_without_target(outs: list[Emitted]) -> None:
    cmds = [o.msg for o in outs if o.topic == "robot/command"]
    assert len(cmds) == 5
    for c in cmds:
        assert c.hold and c.reason == "no plan target yet"
        assert all(v == 0.0 for a in c.arms.values() for v in a.velocity_rad_s)


def test_controller_contract() -> None:
    outs = assert_contract(
        ContractCase(
            SERVICE,
            SETTINGS,
            inputs=script(40),
            empty_inputs=only_joint_states(5),
            empty_check=holds_without_target,
        )
    )
    by_topic: dict[str, list[Any]] = {}
    for o in outs:
        by_topic.setdefault(o.topic, []).append(o.msg)
    assert {k: len(v) for k, v in by_topic.items()} == {
        "robot/command": 40,
        "control/status": 40,
        "diag/controller": 40,
    }
    assert not any(c.hold for c in by_topic["robot/command"])
    assert [d.header.stamp_ns for d in by_topic["diag/controller"]] == [
        c.header.stamp_ns for c in by_topic["robot/command"]
    ]
