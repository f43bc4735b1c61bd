"""The joint acceleration bound (max_joint_acceleration_rad_s2): commands change smoothly,
joints brake before their position limits, a hold restarts from zero, and the harvest pose is
still reached. That the dampers still hold d_s with it: test_controller_core.py."""

from __future__ import annotations

import numpy as np
import pytest

from schemas import JointVelocityCommand
from services.controller import Settings
from services.controller.core import ControllerCore
from services.controller.kinsim import KinematicSim, SafetyMonitor
from services.controller.scenarios import fruit, harvest_target, run_loop, scene
from services.runtime.settings import SettingsError, load_settings

A_RAD_S2 = 15.0
DT_S = 1 / 120
FRUIT = (0.75, 0.05, 1.05)
BOUNDED = load_settings(Settings, {"max_joint_acceleration_rad_s2": A_RAD_S2})
UNBOUNDED = load_settings(Settings, {})


def velocities(cmd: JointVelocityCommand) -> np.ndarray:
    return np.concatenate([cmd.arms[r].velocity_rad_s for r in ("cutter", "collector")])


def random_targets(settings: Settings) -> tuple[list[JointVelocityCommand], list[str], float]:
    """Seeded targets over and beyond the workspace, switched every 150 ticks: the goal jumps,
    and many drive joints to their position limits. The commands, the limit violations and
    the highest speed as a fraction of its limit."""
    rng = np.random.default_rng(11)
    core, sim, monitor = ControllerCore(settings), KinematicSim(), SafetyMonitor()
    commands: list[JointVelocityCommand] = []
    violations: list[str] = []
    speed = 0.0
    for _ in range(6):
        f = rng.uniform((0.3, -0.6, 0.6), (1.2, 0.6, 1.6))
        res = run_loop(
            core, sim, harvest_target(f), scene(), 150, monitor=monitor, stop_when_converged=False
        )
        commands += res.commands
        violations += res.safety.violations
        speed = max(speed, res.safety.max_speed_ratio)
    return commands, violations, speed


def worst_acceleration_rad_s2(commands: list[JointVelocityCommand]) -> float:
    v = np.array([velocities(c) for c in commands])
    return float(np.abs(np.diff(v, axis=0)).max() / DT_S)


def test_without_the_bound_a_goal_jump_changes_a_command_by_far_more() -> None:
    commands, _, _ = random_targets(UNBOUNDED)
    assert worst_acceleration_rad_s2(commands) > 5 * A_RAD_S2  # what the bound is for


def test_with_the_bound_no_command_changes_faster_even_at_a_position_limit() -> None:
    commands, violations, speed = random_targets(BOUNDED)
    assert violations == [], violations[:3]  # the position and velocity limits still hard
    assert speed > 0.5  # the arms did move fast
    # soft rows: the slack is round-off, far under one per mille
    assert worst_acceleration_rad_s2(commands) <= A_RAD_S2 * 1.001


def test_the_harvest_pose_is_still_reached_in_time() -> None:
    core, sim = ControllerCore(BOUNDED), KinematicSim()
    res = run_loop(core, sim, harvest_target(FRUIT, fruit_id=1), scene([fruit(1, FRUIT)]), 600)
    assert res.converged_tick is not None and res.converged_tick < 400
    assert worst_acceleration_rad_s2(res.commands) <= A_RAD_S2 * 1.001


def test_a_hold_counts_as_zero_so_the_arms_start_again_gently() -> None:
    core, sim = ControllerCore(BOUNDED), KinematicSim()
    core.handle("scene/state", scene())
    outs = []
    for k in (0, 1, 2, 40, 41):  # a 317 ms gap between ticks 2 and 40: the watchdog holds
        sim.tick = k
        core.handle("plan/target", harvest_target((0.9, 0.3, 1.3), stamp_ns=sim.stamp_ns, seq=k))
        outs.append(dict(core.handle("robot/joint_state", sim.joint_state()))["robot/command"])
    assert outs[3].hold
    after = np.abs(velocities(outs[4])).max()
    assert 0 < after <= A_RAD_S2 * DT_S * 1.001
    assert core.last_qd_rad_s.tolist() == list(velocities(outs[4]))


def test_a_bound_that_is_not_positive_stops_start_up_with_the_field_named() -> None:
    with pytest.raises(SettingsError, match="max_joint_acceleration_rad_s2"):
        load_settings(Settings, {"max_joint_acceleration_rad_s2": 0})


def test_off_the_solves_carry_no_step_rows_at_all() -> None:
    """Inactive soft rows would still add slack variables and move the steps by round-off
    (5.6e-12 rad/s measured), which a closed loop turns into another run."""
    core = ControllerCore(UNBOUNDED)
    assert (core.hqp.acc0, core.hqp.acc1, core.hqp.acc2) == (None, None, None)
    with pytest.raises(ValueError, match="bound_steps"):
        core.hqp.bound_steps(np.zeros(14), np.zeros(14), np.zeros(14))
