"""The sim core: byte-identical runs, command handling (rejected, late, clamped, holding),
cutting and collecting, contacts counted in a scripted crash, the tick/frame schedule."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from schemas.topics import TOPICS
from services.robot.model import velocity_limits_rad_s
from services.sim.fruits import missed_distance_m
from tests.sim_helpers import (
    command,
    core,
    events,
    fruit_under_tip,
    run_ticks,
    scenario_file,
    tool,
)


def digest(outs: list) -> list[tuple[str, str]]:
    return [(t, hashlib.sha256(TOPICS[t].codec.encode(m)).hexdigest()) for t, m in outs]


def scripted_run(sc: Path | str, **settings: object) -> list:
    """Arms moving, a cut, noise on: everything the sim emits or answers."""
    c = core(sc, **settings)
    outs = run_ticks(c, 30, {"cutter_j1": 0.3, "collector_j4": -0.2})
    outs += c.handle("robot/tool", tool(c))
    outs += run_ticks(c, 30, {"cutter_j2": 0.1})
    c.close()
    return outs


def test_same_scenario_seed_and_settings_give_byte_identical_outputs(tmp_path: Path) -> None:
    sc = scenario_file(
        tmp_path,
        fruits=[fruit_under_tip(), {"position_world_m": [0.62, -0.2, 1.35]}],
        events=[{"kind": "hand_sweep", "start_s": 0.1, "duration_s": 0.3, "fruit": 1}],
    )
    a, b = digest(scripted_run(sc)), digest(scripted_run(sc))
    assert a == b
    topics = {t for t, _ in a}
    assert topics == {"camera/rgbd", "sim/truth", "robot/joint_state", "robot/basket", "sim/events"}
    c = digest(scripted_run(sc, seed=99))  # another seed: another tree and other noise
    assert [x for x in c if x[0] == "camera/rgbd"] != [x for x in a if x[0] == "camera/rgbd"]


def test_ticks_frames_and_groups_follow_the_documented_schedule(tmp_path: Path) -> None:
    c = core(scenario_file(tmp_path), duration_s=0.2)
    groups = []
    while not c.done():
        groups.append([[t for t, _ in g] for g in c.emit()])
        c.advance()
    assert len(groups) == 25  # 0.2 s at 120 Hz, tick 24 at 0.19999999 s
    assert groups[0] == [["camera/rgbd", "sim/truth"], ["robot/joint_state", "robot/basket"]]
    assert groups[1] == [["robot/joint_state"]]
    assert sum(len(g) == 2 for g in groups) == 4  # ticks 0, 8, 16, 24: 15 Hz


def test_invalid_commands_are_rejected_counted_and_the_robot_holds(tmp_path: Path) -> None:
    c = core(scenario_file(tmp_path))
    q0 = c.q.copy()
    for why in ("unknown joint names", "6 joint velocities for 7"):
        c.emit()
        good = command(c, {"cutter_j1": 0.2})
        arm = good.arms["cutter"]
        if why.startswith("unknown"):
            arm = arm.model_copy(update={"names": (*arm.names[:6], "elbow")})
        else:
            arm = arm.model_copy(
                update={"names": arm.names[:6], "velocity_rad_s": arm.velocity_rad_s[:6]}
            )
        out = c.handle("robot/command", good.model_copy(update={"arms": {"cutter": arm}}))
        assert [m.kind for _, m in out] == ["command_rejected"] and why in out[0][1].detail
        c.advance()
    assert np.array_equal(c.q, q0)
    assert c.counters["commands_rejected"] == 2 and c.counters["ticks_without_command"] == 2


def test_commands_for_a_passed_tick_are_ignored_and_counted(tmp_path: Path) -> None:
    c = core(scenario_file(tmp_path))
    c.emit()
    old = command(c, {"cutter_j1": 0.2})
    c.advance()
    c.emit()
    out = c.handle("robot/command", old)
    assert [m.kind for _, m in out] == ["command_late"]
    ahead = command(c, {"cutter_j1": 0.2}, stamp=c.now_ns() + c.s.control_period_ns)
    assert [m.kind for _, m in c.handle("robot/command", ahead)] == ["command_late"]
    q0 = c.q.copy()
    c.advance()
    assert np.array_equal(c.q, q0) and c.counters["commands_late"] == 2


def test_a_command_moves_only_the_next_step_and_is_clamped_to_the_limits(tmp_path: Path) -> None:
    c = core(scenario_file(tmp_path))
    c.emit()
    q0 = c.q.copy()
    c.handle("robot/command", command(c, {"cutter_j1": 0.1, "collector_j5": 50.0}))
    c.advance()
    dt = c.dt
    assert c.q[0] - q0[0] == pytest.approx(0.1 * dt)
    assert c.q[7 + 4] - q0[7 + 4] == pytest.approx(velocity_limits_rad_s()[4] * dt)
    outs = [x for g in c.emit() for x in g]
    (js,) = [m for t, m in outs if t == "robot/joint_state"]
    assert js.arms["collector"].velocity_rad_s[4] == pytest.approx(velocity_limits_rad_s()[4])
    (clamped,) = events(outs, "clamped")  # found in the step, published with the next tick
    assert clamped.body_a == "collector_j5" and c.counters["commands_clamped"] == 1
    q1 = c.q.copy()
    c.advance()  # no command for this tick: the robot holds
    assert np.array_equal(c.q, q1) and c.qd.tolist() == [0.0] * 14


def test_a_cut_at_the_peduncle_detaches_the_fruit_into_the_basket(tmp_path: Path) -> None:
    c = core(scenario_file(tmp_path, fruits=[fruit_under_tip()]), depth_noise=False)
    outs = run_ticks(c, 2)
    outs += c.handle("robot/tool", tool(c))
    outs += run_ticks(c, 90)
    kinds = [e.kind for e in events(outs) if e.kind != "collision"]
    assert kinds[:1] == ["cut"] and "collected" in kinds, kinds
    truth = [m for t, m in outs if t == "sim/truth"][-1]
    assert truth.fruits[0].state == "collected" and truth.counters.cuts == 1
    assert c.counters["contacts"] == 0  # cutting at the peduncle is not a collision
    # The basket's load cell: no fruit before the cut, one settled fruit and its mass after.
    baskets = [m for t, m in outs if t == "robot/basket"]
    assert baskets[0].fruit_count == 0 and baskets[0].load_kg == 0.0
    assert baskets[-1].fruit_count == 1
    mass = c.physics.fruit_mass(0)
    assert baskets[-1].load_kg == pytest.approx(mass, abs=0.0011) and mass > 0.1


def test_a_cut_3_cm_from_the_peduncle_fails(tmp_path: Path) -> None:
    c = core(scenario_file(tmp_path, fruits=[fruit_under_tip(dy_m=0.03)]), depth_noise=False)
    run_ticks(c, 1)
    c.handle("robot/tool", tool(c))
    outs = run_ticks(c, 10)
    (missed,) = events(outs, "cut_missed")
    assert "0.0300 m" in missed.detail
    assert "0.0000, -0.0300, +0.0000) m" in missed.detail  # tip minus peduncle: fruit 3 cm on +y
    assert missed_distance_m(missed.detail) == pytest.approx(0.03)  # as the harvest bench reads
    assert c.fruits.all[0].state == "attached" and c.counters["cuts_missed"] == 1
    assert [m.fruit_count for t, m in outs if t == "robot/basket"] == [0]


def test_the_collector_has_no_shears(tmp_path: Path) -> None:
    c = core(scenario_file(tmp_path))
    c.emit()
    out = c.handle("robot/tool", tool(c, role="collector"))
    assert [m.kind for _, m in out] == ["command_rejected"]


def test_contacts_are_counted_every_tick_in_a_scripted_crash(tmp_path: Path) -> None:
    sc = scenario_file(
        tmp_path,
        tree={"trunk_xy_world_m": [0.75, 0.17], "extra_branches": 0, "leaf_clusters": 1},
        fruits=[{"position_world_m": [0.6, -0.35, 1.4], "leaf_cover": "none"}],
    )
    c = core(sc, depth_noise=False)
    outs = run_ticks(c, 1)
    assert c.counters["contact_ticks"] == 0
    outs += run_ticks(c, 150, {"cutter_j2": 0.6})  # swing the cutter forward into the trunk
    begun = [e for e in events(outs, "collision") if e.detail.startswith("contact began")]
    assert begun and all(e.body_b == "trunk" for e in begun)
    # Each beginning says where it touched the trunk: on its surface (the trunk's axis at
    # x, y = 0.75, 0.17 m), within pybullet's contact margin.
    trunk_r_m = c.world.trunk.radius
    for e in begun:
        x, y, _z = (float(v) for v in e.detail.split("(")[1].split(")")[0].split(","))
        assert abs(np.hypot(x - 0.75, y - 0.17) - trunk_r_m) < 0.005, e.detail
    assert c.counters["contact_ticks"] >= 20
    truth = [m for t, m in outs if t == "sim/truth"][-1]
    assert any(b == "trunk" for _, b in truth.robot_contacts)
