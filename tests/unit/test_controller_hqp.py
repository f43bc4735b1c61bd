"""services/controller/hqp.py: a true lexicographic hierarchy (the relative task cannot disturb
the absolute one), and the documented fallbacks on infeasible QPs."""

from __future__ import annotations

import numpy as np
import pytest

from services.controller import Settings
from services.controller.core import ControllerCore
from services.controller.dampers import DamperRows, inactive_rows
from services.controller.hqp import LexicographicHQP, Weights
from services.controller.kinsim import KinematicSim
from services.controller.robot import ControlledRobot
from services.controller.scenarios import harvest_target, run_loop, scene
from services.controller.targets import Gains, PoseGoal, step_target
from services.robot.model import HOME_RAD, URDF_PATH, joint_names
from services.runtime.settings import load_settings

SETTINGS = load_settings(Settings, {})


def freeze_collector(core: ControllerCore) -> None:
    """Lock the collecting arm where it is (a seized arm): the relative task becomes
    impossible while the absolute task stays feasible."""
    for name, q in zip(joint_names("collector"), HOME_RAD["collector"], strict=True):
        core.robot.robot.set_joint_limits(name, q, q)


def cutter_tip_at_home() -> np.ndarray:
    r = ControlledRobot(URDF_PATH)
    r.set_q(KinematicSim().q_arm_order())
    return r.T_world("cutter_tip")[:3, 3]


def fruit_under(tip: np.ndarray) -> np.ndarray:
    return tip - np.array([0.0, 0.0, 0.06])  # harvest_target puts the tip 6 cm above


def test_an_impossible_relative_task_leaves_the_absolute_error_below_1_mm() -> None:
    core = ControllerCore(SETTINGS)
    freeze_collector(core)
    target = harvest_target(fruit_under(cutter_tip_at_home()), relative_m=(0.2, 0.2, 0.0))
    res = run_loop(core, KinematicSim(), target, scene(), 300, stop_when_converged=False)
    abs_err = [s.abs_position_error_m for s in res.statuses]
    assert max(abs_err) < 1e-3, max(abs_err)
    assert min(s.rel_position_error_m for s in res.statuses) > 0.1  # it really is impossible
    moved = np.abs(np.diff([c.arms["cutter"].velocity_rad_s for c in res.commands], axis=0))
    assert moved.max() > 0  # ... and the relative task does pull the cutting arm's redundancy


def test_strict_priority_holds_while_the_absolute_task_moves() -> None:
    tip = cutter_tip_at_home()
    goal = fruit_under(tip + np.array([0.1, 0.15, 0.05]))
    runs = {}
    for name, frozen in (("feasible", False), ("impossible", True)):
        core = ControllerCore(SETTINGS)
        if frozen:
            freeze_collector(core)
        res = run_loop(
            core, KinematicSim(), harvest_target(goal), scene(), 400, stop_when_converged=False
        )
        runs[name] = np.array([s.abs_position_error_m for s in res.statuses])
    assert runs["impossible"][-1] < 1e-4
    # The absolute task follows the same course whatever the relative task can do.
    assert np.max(np.abs(runs["impossible"] - runs["feasible"])) < 1e-3


def test_without_the_held_absolute_rows_the_relative_task_disturbs_the_absolute_one(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Control for the two tests above: they can fail. Drop the rows that hold A₁Δq = A₁Δq₁
    in solve 2 and the same run loses the cutter."""
    monkeypatch.setattr(LexicographicHQP, "_hold_absolute", lambda self, dq1: None)
    core = ControllerCore(SETTINGS)
    freeze_collector(core)
    target = harvest_target(fruit_under(cutter_tip_at_home()), relative_m=(0.2, 0.2, 0.0))
    res = run_loop(core, KinematicSim(), target, scene(), 100, stop_when_converged=False)
    assert max(s.abs_position_error_m for s in res.statuses) > 5e-3


def steps(robot: ControlledRobot) -> tuple:
    T = robot.T_world("cutter_tip")
    T_rel = robot.T_a_b("cutter_tip", "basket_center")
    g = Gains(3.0, 0.25, 1.0)
    a = step_target(T[:3, 3], T[:3, :3], PoseGoal(T[:3, 3] + [0.05, 0, 0], T[:3, :3], "x"), g, 0.01)
    r = step_target(
        T_rel[:3, 3], T_rel[:3, :3], PoseGoal(T_rel[:3, 3], T_rel[:3, :3], "z"), g, 0.01
    )
    return a, r


def test_a_feasible_tick_uses_no_fallback() -> None:
    robot = ControlledRobot(URDF_PATH)
    robot.set_q(KinematicSim().q_arm_order())
    hqp = LexicographicHQP(robot, Weights(), 0.01)
    res = hqp.solve(*steps(robot), inactive_rows(robot.model.nq), 0.01)
    assert res.fallback == "none" and res.dq is not None and np.all(np.isfinite(res.dq))


def test_dampers_that_cannot_be_met_are_softened() -> None:
    """A damper row asking the cutter tip to back off 1 m in one step (beyond the velocity
    limits) makes solve 1 infeasible; with soft dampers it solves."""
    robot = ControlledRobot(URDF_PATH)
    robot.set_q(KinematicSim().q_arm_order())
    hqp = LexicographicHQP(robot, Weights(), 0.01)
    jac = robot.robot.frame_jacobian("cutter_tip", "world")[:3]
    A = np.zeros((1, robot.model.nq))
    A[0, 7:] = -np.array([1.0, 0.0, 0.0]) @ jac[:, 6:]  # −ẋ_tip ≤ ...: x must grow by 1 m
    b = A @ robot.q_full - 1.0
    res = hqp.solve(*steps(robot), DamperRows(A, b, 1), 0.01)
    assert res.fallback == "softened" and res.dq is not None
    assert "dampers softened" in res.reason


def test_a_genuinely_infeasible_qp_stops() -> None:
    """A joint 0.5 rad past its limit cannot come back within one step's velocity limit: no
    solution exists even with soft dampers (the core widens such limits first; this is the
    last line)."""
    robot = ControlledRobot(URDF_PATH)
    q = KinematicSim().q_arm_order()
    q[3] = robot.upper_rad[3] + 0.5
    robot.set_q(q)
    hqp = LexicographicHQP(robot, Weights(), 0.01)
    res = hqp.solve(*steps(robot), inactive_rows(robot.model.nq), 0.01)
    assert res.fallback == "stopped" and res.dq is None and "infeasible" in res.reason
