"""services/controller/core.py: the controller in closed loop with the kinematic sim — it
reaches, keeps its distances, never exceeds a limit, stops on stale inputs, refuses bad input
by holding still, and is deterministic."""

from __future__ import annotations

import math

import numpy as np
import pytest

from schemas import (
    TOPICS,
    AbsoluteTarget,
    CylinderObstacle,
    EllipsoidObstacle,
    JointState,
    JointVelocityCommand,
    Obstacles,
)
from services.controller import Settings
from services.controller.core import ControllerCore
from services.controller.kinsim import KinematicSim, SafetyMonitor
from services.controller.scenarios import fruit, harvest_target, run_loop, scene
from services.runtime import ConfigError
from services.runtime.settings import load_settings

SETTINGS = load_settings(Settings, {})
SAFETY = {
    "self": SETTINGS.self_collision.safety_m,
    "trunk": SETTINGS.trunk.safety_m,
    "fruit": SETTINGS.fruit.safety_m,
    "branch": SETTINGS.branch.safety_m,
}
FRUIT = (0.75, 0.05, 1.05)


def is_zero(cmd: JointVelocityCommand) -> bool:
    return all(v == 0.0 for a in cmd.arms.values() for v in a.velocity_rad_s)


def test_it_reaches_a_harvest_pose_and_says_converged() -> None:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    res = run_loop(core, sim, harvest_target(FRUIT, fruit_id=1), scene([fruit(1, FRUIT)]), 600)
    assert res.converged_tick is not None and res.converged_tick < 400  # < 3.4 s at 120 Hz
    st = res.statuses[-1]
    assert st.abs_position_error_m <= 1e-3 and st.rel_position_error_m <= 1e-3
    assert st.abs_orientation_error_rad <= 0.01 and st.rel_orientation_error_rad <= 0.01
    assert st.fallback == "none" and not st.watchdog and st.phase == "harvest"
    assert not any(c.hold for c in res.commands)
    # the cutter tip never went faster than the 0.25 m/s cap (up to the linearisation)
    tips = []
    for q in res.q_rad:
        core.robot.set_q(q)
        tips.append(core.robot.T_world("cutter_tip")[:3, 3])
    speed = np.linalg.norm(np.diff(tips, axis=0), axis=1) / (1 / 120)
    assert 0.24 < speed.max() < 0.25 * 1.01


def cluster() -> list[EllipsoidObstacle]:
    offsets = [
        (0, 0.09, 0),
        (0, -0.09, 0),
        (0.02, 0.05, 0.09),
        (0.03, -0.05, -0.08),
        (-0.09, 0, 0.02),
    ]
    return [fruit(1, FRUIT)] + [fruit(2 + i, np.add(FRUIT, d)) for i, d in enumerate(offsets)]


ADVERSARIAL = {
    # the target fruit straight behind the trunk: the tools must stop in front of it
    "target behind the trunk": (
        harvest_target((0.95, 0.05, 1.05), fruit_id=1),
        scene([fruit(1, (0.95, 0.05, 1.05))], trunk_xy_m=(0.85, 0.05)),
    ),
    # the trunk beside the path of the basket
    "trunk beside the path": (
        harvest_target(FRUIT, fruit_id=1),
        scene([fruit(1, FRUIT)], trunk_xy_m=(0.8, -0.08), trunk_radius_m=0.05),
    ),
    # the target in a tight cluster: neighbours above, below and on both sides
    "fruit cluster": (harvest_target(FRUIT, fruit_id=1), scene(cluster())),
}


@pytest.mark.parametrize("bound", [None, 15.0], ids=["unbounded", "acceleration bound"])
@pytest.mark.parametrize("case", sorted(ADVERSARIAL))
def test_dampers_keep_every_distance_at_least_d_s(case: str, bound: float | None) -> None:
    """Also with the joint acceleration bound: it is soft, under the dampers."""
    target, sc = ADVERSARIAL[case]
    monitor = SafetyMonitor(sc.obstacles, target.ignore_fruit_ids)
    start = monitor.distances(KinematicSim().q_arm_order())
    assert all(start[k] > SAFETY[k] for k in start), "the scene must start clear"
    core = ControllerCore(
        SETTINGS.model_copy(update={"max_joint_acceleration_rad_s2": bound})
        if bound is not None
        else SETTINGS
    )
    res = run_loop(
        core,
        KinematicSim(),
        target,
        sc,
        500,
        monitor=monitor,
        safety_m=SAFETY,
        stop_when_converged=False,
    )
    assert res.safety.violations == [], res.safety.violations[:3]
    near = [k for k in ("trunk", "fruit") if res.safety.min_distance_m[k] < SAFETY[k] + 0.01]
    assert near, "the scene must bring an obstacle within 1 cm of d_s, or it tests nothing"
    assert max(s.active_dampers for s in res.statuses) > 0


def test_random_targets_never_exceed_a_limit() -> None:
    """Seeded targets over and beyond the workspace (many unreachable), 120 ticks each."""
    rng = np.random.default_rng(11)
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    monitor = SafetyMonitor()
    worst = 0.0
    for _ in range(8):
        f = rng.uniform((0.3, -0.6, 0.6), (1.2, 0.6, 1.6))
        res = run_loop(
            core,
            sim,
            harvest_target(f),
            scene(),
            120,
            monitor=monitor,
            safety_m=SAFETY,
            stop_when_converged=False,
        )
        assert res.safety.violations == [], res.safety.violations[:3]
        worst = max(worst, res.safety.max_speed_ratio)
    assert worst > 0.5  # the commands did approach the velocity limits


def test_a_stale_target_stops_the_arms_and_says_so() -> None:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    core.handle("scene/state", scene())
    core.handle("plan/target", harvest_target(FRUIT, stamp_ns=0))
    answers = []
    for _ in range(20):  # 20 ticks of 8.3 ms: the target ages past 100 ms at tick 13
        outs = dict(core.handle("robot/joint_state", sim.joint_state()))
        answers.append((outs["robot/command"], outs["control/status"]))
        sim.apply(outs["robot/command"])
    assert not answers[12][0].hold and not is_zero(answers[12][0])
    cmd, st = answers[13]
    assert cmd.hold and is_zero(cmd) and st.watchdog and "plan target is 108.3 ms old" in st.reason


def test_a_joint_state_gap_holds_one_tick() -> None:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    core.handle("scene/state", scene())
    js = []
    for k in (0, 1, 30, 31):  # a 241 ms gap between ticks 1 and 30
        sim.tick = k
        core.handle("plan/target", harvest_target(FRUIT, stamp_ns=sim.stamp_ns, seq=k))
        js.append(dict(core.handle("robot/joint_state", sim.joint_state())))
    assert [o["control/status"].watchdog for o in js] == [False, False, True, False]
    assert is_zero(js[2]["robot/command"]) and not is_zero(js[3]["robot/command"])


def test_in_live_mode_the_timer_stops_the_arms_when_joint_states_stop() -> None:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    core.handle("scene/state", scene())
    core.handle("plan/target", harvest_target(FRUIT))
    core.handle("robot/joint_state", sim.joint_state())
    assert core.on_timer(0) == [] and core.on_timer(60_000_000) == []
    outs = dict(core.on_timer(120_000_000))
    cmd, st = outs["robot/command"], outs["control/status"]
    assert cmd.hold and is_zero(cmd) and st.watchdog and "no joint state for 120 ms" in st.reason
    assert cmd.header.answers_seq is None and cmd.header.stamp_ns == 0  # answers nothing


def test_same_inputs_give_identical_commands() -> None:
    def run() -> list[bytes]:
        sc = scene(cluster())
        res = run_loop(
            ControllerCore(SETTINGS),
            KinematicSim(),
            harvest_target(FRUIT, fruit_id=1),
            sc,
            150,
            stop_when_converged=False,
        )
        return [TOPICS["robot/command"].codec.encode(c) for c in res.commands] + [
            TOPICS["control/status"].codec.encode(s) for s in res.statuses
        ]

    assert run() == run()


def test_joint_states_with_missing_joints_hold_still() -> None:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    core.handle("scene/state", scene())
    core.handle("plan/target", harvest_target(FRUIT))
    js = sim.joint_state()
    cutter = js.arms["cutter"]
    short = cutter.model_copy(
        update={
            "names": cutter.names[:6],
            "position_rad": cutter.position_rad[:6],
            "velocity_rad_s": cutter.velocity_rad_s[:6],
        }
    )
    bad = JointState(header=js.header, arms={"cutter": short, "collector": js.arms["collector"]})
    outs = dict(core.handle("robot/joint_state", bad))
    cmd = outs["robot/command"]
    assert cmd.hold and is_zero(cmd) and "missing cutter_j7" in cmd.reason
    assert cmd.arms["cutter"].names == sim.joint_state().arms["cutter"].names  # full command
    assert outs["diag/controller"].rejected_joint_states == 1


def test_a_target_outside_the_workspace_is_refused_and_the_arms_hold() -> None:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    core.handle("scene/state", scene())
    core.handle("plan/target", harvest_target((0.7, 0.0, 3.5)))
    outs = dict(core.handle("robot/joint_state", sim.joint_state()))
    assert outs["robot/command"].hold and is_zero(outs["robot/command"])
    assert (
        "refused" in outs["control/status"].reason and "workspace" in outs["control/status"].reason
    )
    assert outs["diag/controller"].rejected_targets == 1
    # a valid target afterwards is used again
    core.handle("plan/target", harvest_target(FRUIT, seq=1))
    sim.tick = 1
    assert not dict(core.handle("robot/joint_state", sim.joint_state()))["robot/command"].hold


def test_a_degenerate_obstacle_set_holds_until_a_valid_scene_arrives() -> None:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    flat = EllipsoidObstacle.model_construct(
        name="flat", fruit_id=9, center_world_m=(0.9, 0.0, 1.0), semi_axes_m=(0.03, 0.0, 0.03)
    )
    bad = scene().model_copy(update={"obstacles": Obstacles(ellipsoids=(flat,))})
    core.handle("scene/state", bad)
    core.handle("plan/target", harvest_target(FRUIT))
    outs = dict(core.handle("robot/joint_state", sim.joint_state()))
    assert outs["robot/command"].hold and "obstacle 'flat'" in outs["robot/command"].reason
    core.handle("scene/state", scene(seq=1))
    sim.tick = 1
    assert not dict(core.handle("robot/joint_state", sim.joint_state()))["robot/command"].hold


def test_without_a_target_or_a_scene_the_arms_hold_with_a_reason() -> None:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    outs = dict(core.handle("robot/joint_state", sim.joint_state()))
    assert outs["robot/command"].hold and outs["control/status"].reason == "no plan target yet"
    core.handle("plan/target", harvest_target(FRUIT))
    sim.tick = 1
    outs = dict(core.handle("robot/joint_state", sim.joint_state()))
    assert outs["control/status"].reason == "no scene state yet (obstacles unknown)"
    core.handle("plan/target", harvest_target(FRUIT, seq=1).model_copy(update={"absolute": None}))
    sim.tick = 2
    outs = dict(core.handle("robot/joint_state", sim.joint_state()))
    assert "asks to hold" in outs["control/status"].reason


def test_a_joint_past_its_limit_is_never_driven_further_out() -> None:
    """A simulator overshoot (2 mrad past the elbow's limit) is not a reason to stop, and the
    command never pushes that joint further out."""
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    hi = core.robot.upper_rad[3]
    sim.q["cutter"][3] = hi + 0.002
    core.handle("scene/state", scene())
    outside = 0
    for k in range(60):
        core.handle("plan/target", harvest_target(FRUIT, stamp_ns=sim.stamp_ns, seq=k))
        was = sim.q["cutter"][3]
        cmd = dict(core.handle("robot/joint_state", sim.joint_state()))["robot/command"]
        assert not cmd.hold, cmd.reason
        if was > hi:
            outside += 1
            assert cmd.arms["cutter"].velocity_rad_s[3] <= 0.0
        sim.apply(cmd)
    assert outside >= 1 and sim.q["cutter"][3] <= hi + 0.002


def test_an_empty_obstacle_set_is_fine() -> None:
    core = ControllerCore(SETTINGS)
    res = run_loop(
        core, KinematicSim(), harvest_target(FRUIT), scene(), 5, stop_when_converged=False
    )
    assert not any(c.hold for c in res.commands)
    assert (
        res.statuses[-1].min_distance_fruit_m is None
        and res.statuses[-1].min_distance_trunk_m is None
    )


def test_a_nan_absolute_target_built_around_validation_is_refused() -> None:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    core.handle("scene/state", scene())
    bad_abs = AbsoluteTarget.model_construct(
        frame_id="world",
        position_m=(math.nan, 0.0, 1.0),
        orientation_xyzw=(0, 0, 0, 1.0),
        free_axis="x",
    )
    core.handle("plan/target", harvest_target(FRUIT).model_copy(update={"absolute": bad_abs}))
    outs = dict(core.handle("robot/joint_state", sim.joint_state()))
    assert outs["robot/command"].hold and "not finite" in outs["robot/command"].reason


def test_a_trunk_cylinder_counts_as_trunk_in_the_status() -> None:
    core = ControllerCore(SETTINGS)
    trunk = scene(trunk_xy_m=(0.75, 0.0))
    res = run_loop(core, KinematicSim(), harvest_target(FRUIT), trunk, 1, stop_when_converged=False)
    d = res.statuses[0].min_distance_trunk_m
    assert d is not None and 0.0 < d < 0.25
    assert isinstance(trunk.obstacles.cylinders[0], CylinderObstacle)


def test_a_missing_urdf_refuses_to_start() -> None:
    with pytest.raises(ConfigError, match="urdf_path"):
        ControllerCore(load_settings(Settings, {"urdf_path": "/nonexistent/robot.urdf"}))
