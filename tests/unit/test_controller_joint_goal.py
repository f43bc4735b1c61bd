"""A joint goal (PlanTarget.joints, the planner retracing a path): the arms go there in joint
space under the same limits and dampers, the status reports the tools' errors against the poses
the goal puts them in, and a bad joint goal is refused with the joint named."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from schemas import PlanTarget
from schemas.base import ARM_ROLES, Header
from services.controller import Settings
from services.controller.core import ControllerCore
from services.controller.kinsim import KinematicSim, SafetyMonitor
from services.controller.scenarios import fruit, harvest_target, run_loop, scene
from services.planner.poses import joint_target as planner_joint_target
from services.robot.model import HOME_RAD
from services.runtime.settings import load_settings

SETTINGS = load_settings(Settings, {})
FRUIT = (0.75, 0.05, 1.05)
SAFETY = {
    "self": SETTINGS.self_collision.safety_m,
    "trunk": SETTINGS.trunk.safety_m,
    "fruit": SETTINGS.fruit.safety_m,
    "branch": SETTINGS.branch.safety_m,
}


def joint_target(q_arm_order: np.ndarray, phase: str = "leave") -> PlanTarget:
    return PlanTarget(
        header=Header(stamp_ns=0, seq=0, source="planner", frame_id="world"),
        phase=phase,  # type: ignore[arg-type]
        joints=planner_joint_target(q_arm_order),
    )


def harvest_configuration() -> np.ndarray:
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    res = run_loop(core, sim, harvest_target(FRUIT, fruit_id=1), scene([fruit(1, FRUIT)]), 600)
    assert res.converged_tick is not None
    return sim.q_arm_order()


def test_the_arms_retrace_to_a_joint_goal_in_joint_space() -> None:
    q_far = harvest_configuration()
    home = np.concatenate([np.array(HOME_RAD[r], float) for r in ARM_ROLES])
    core, sim = ControllerCore(SETTINGS), KinematicSim(q_far_by_role(q_far))
    monitor = SafetyMonitor()
    res = run_loop(core, sim, joint_target(home), scene(), 900, monitor=monitor, safety_m=SAFETY)
    assert res.converged_tick is not None
    assert np.abs(sim.q_arm_order() - home).max() < 2e-3
    st = res.statuses[-1]
    assert st.fallback == "none" and st.reason == "" and st.converged
    assert res.statuses[0].abs_position_error_m > 0.1  # the errors are the tools' distances
    assert res.safety.violations == []
    # every joint within its share of the velocity limit, and the move is straight in joint
    # space: each joint's path is monotone towards the goal
    assert 0.3 < res.safety.max_speed_ratio <= SETTINGS.joint_speed_fraction + 1e-6
    path = np.array(res.q_rad)
    sign = np.sign(home - q_far)
    assert np.all(np.diff(path, axis=0) * sign >= -1e-9)


def q_far_by_role(q: np.ndarray) -> dict[str, list[float]]:
    return {"cutter": list(q[:7]), "collector": list(q[7:])}


def test_the_dampers_still_hold_on_a_joint_goal() -> None:
    """Going back to the harvest configuration with the fruit now an obstacle (not ignored):
    the arms stop at d_s from it instead of driving through."""
    q_far = harvest_configuration()
    sc = scene([fruit(1, FRUIT)])
    monitor = SafetyMonitor(sc.obstacles, ())
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    res = run_loop(
        core,
        sim,
        joint_target(q_far),
        sc,
        600,
        monitor=monitor,
        safety_m=SAFETY,
        stop_when_converged=False,
    )
    assert res.safety.violations == [], res.safety.violations[:3]
    assert res.safety.min_distance_m["fruit"] < SAFETY["fruit"] + 0.01  # it did get there
    assert not res.statuses[-1].converged


def test_a_joint_goal_outside_the_limits_is_refused_by_name() -> None:
    home = np.concatenate([np.array(HOME_RAD[r], float) for r in ARM_ROLES])
    home[3] = 10.0
    core, sim = ControllerCore(SETTINGS), KinematicSim()
    res = run_loop(core, sim, joint_target(home), scene(), 3, stop_when_converged=False)
    assert all(c.hold for c in res.commands)
    assert "cutter_j4 = 10.000 rad is outside its limits" in res.statuses[-1].reason
    assert core.counters.rejected_targets == 3


def test_a_joint_goal_with_a_pose_target_is_invalid() -> None:
    t = harvest_target(FRUIT, fruit_id=1)
    home = np.concatenate([np.array(HOME_RAD[r], float) for r in ARM_ROLES])
    with pytest.raises(ValidationError, match="joint goal"):
        PlanTarget.model_validate({**t.model_dump(), "joints": joint_target(home).joints})
