"""Contract test of the planner with the foundation's kit: declared topics, valid schemas, one
plan target per control status carrying its stamp, empty input, determinism."""

from __future__ import annotations

from typing import Any

from schemas.base import Header
from schemas.control import ControlStatus
from schemas.robot import BasketState
from services.controller.kinsim import KinematicSim
from services.planner import SERVICE
from services.runtime.settings import load_settings
from services.testkit import ContractCase, Emitted, assert_contract
from tests.unit.test_planner_book import fruit, scene

SETTINGS = load_settings(SERVICE.settings, {"startup_s": 0.1, "finish_after_s": 0.2})
PERIOD_NS = 8_333_333


def status(k: int, err_m: float) -> ControlStatus:
    """A controller status for tick k that says the previous target is within ``err_m``."""
    return ControlStatus(
        header=Header(stamp_ns=k * PERIOD_NS, seq=k, source="controller", answers_seq=k),
        target_seq=k - 1 if k > 0 else None,
        abs_position_error_m=err_m,
        abs_orientation_error_rad=0.0,
        rel_position_error_m=0.0,
        rel_orientation_error_rad=0.0,
        converged=err_m < 0.001,
    )


def script(ticks: int, with_fruit: bool = True) -> list[tuple[str, Any]]:
    """Per camera tick a scene state (two reachable fruit) and a basket reading, per tick a joint
    state and a status whose error shrinks over each ~0.4 s, so every phase is passed through."""
    sim = KinematicSim()
    out: list[tuple[str, Any]] = []
    for k in range(ticks):
        stamp = k * PERIOD_NS
        if k % 8 == 0 and with_fruit:
            out.append(
                (
                    "scene/state",
                    scene(
                        fruit(1, (0.6, -0.12, 1.32), stamp=stamp),
                        fruit(2, (0.7, 0.05, 1.25), stamp=stamp),
                        seq=k // 8,
                    ).model_copy(
                        update={"header": Header(stamp_ns=stamp, seq=k // 8, source="scene")}
                    ),
                )
            )
            count = 1 if k > ticks // 2 else 0
            out.append(
                (
                    "robot/basket",
                    BasketState(
                        header=Header(stamp_ns=stamp, seq=k // 8, source="sim"),
                        load_kg=0.2 * count,
                        fruit_count=count,
                    ),
                )
            )
        sim.tick = k
        out.append(("robot/joint_state", sim.joint_state()))
        out.append(("control/status", status(k, 0.002 * (k % 48))))
    return out


def answers_every_status_and_ends(outs: list[Emitted]) -> None:
    targets = [o.msg for o in outs if o.topic == "plan/target"]
    assert len(targets) == 60
    assert {t.phase for t in targets} <= {"idle", "home", "done"}
    (summary,) = [o.msg for o in outs if o.topic == "harvest/summary"]
    assert summary.detected == 0 and summary.harvested == 0


def test_planner_contract() -> None:
    outs = assert_contract(
        ContractCase(
            SERVICE,
            SETTINGS,
            inputs=script(400),
            empty_inputs=[("control/status", status(k, 0.0)) for k in range(60)],
            empty_check=answers_every_status_and_ends,
        )
    )
    phases = [o.msg.phase for o in outs if o.topic == "plan/target"]
    assert len(phases) == 400
    assert {"approach", "harvest", "cut"} <= set(phases)
    tools = [o.msg.action for o in outs if o.topic == "robot/tool"]
    assert tools[:1] == ["cut"]
    events = [o.msg.event for o in outs if o.topic == "harvest/events"]
    assert events[0] == "run_started" and "fruit_selected" in events
