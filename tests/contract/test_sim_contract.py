"""Contract of the sim with the foundation's kit: run_source drives it in lock-step with a fake
controller answering every joint state; outputs are declared, valid and deterministic."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from schemas.topics import TOPICS
from services.runtime.settings import load_settings
from services.sim import SERVICE
from services.testkit import (
    check_declared_topics,
    check_schema_valid,
    check_seq_counts_up,
    run_source,
)
from tests.sim_helpers import command, scenario_file


def fake_controller(sim_core_ref: list[Any]):
    """Answers robot/joint_state with a small joint-velocity command for that tick."""

    def respond(topic: str, msg: Any) -> list[tuple[str, Any]]:
        if topic != "robot/joint_state":
            return []
        stamp = msg.header.stamp_ns
        v = 0.2 if (stamp // 100_000_000) % 2 == 0 else -0.2
        cmd = command(sim_core_ref[0], {"cutter_j1": v, "collector_j2": -v}, msg.header.seq, stamp)
        h = cmd.header.model_copy(update={"answers_seq": msg.header.seq, "source": "controller"})
        return [("robot/command", cmd.model_copy(update={"header": h}))]

    return respond


class _Clock:
    """Stands in for the core in `command` (only now_ns is read, and we pass the stamp)."""

    def now_ns(self) -> int:
        return 0


def test_sim_contract_with_a_fake_controller(tmp_path: Path) -> None:
    settings = load_settings(
        SERVICE.settings, {"scenario": str(scenario_file(tmp_path)), "duration_s": 0.3}
    )
    runs = []
    for _ in range(2):
        outs = run_source(SERVICE, settings, fake_controller([_Clock()]))
        check_declared_topics(SERVICE, outs)
        check_schema_valid(outs)
        check_seq_counts_up(outs)
        runs.append([(o.topic, TOPICS[o.topic].codec.encode(o.msg)) for o in outs])
    assert runs[0] == runs[1]
    topics = [t for t, _ in runs[0]]
    assert topics.count("robot/joint_state") == 37 and topics.count("camera/rgbd") == 5
    assert topics.count("sim/truth") == 5
    states = [o for o in outs if o.topic == "robot/joint_state"]
    assert states[0].msg.arms["cutter"].position_rad != states[-1].msg.arms["cutter"].position_rad
    assert not [o for o in outs if o.topic == "sim/events" and o.msg.kind.startswith("command")]
