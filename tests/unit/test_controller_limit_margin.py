"""The joint-limit margin (limit_margin_rad): a joint near its stop is moved away through the
tasks' free directions while the tool still reaches its pose; off, no rows exist."""

from __future__ import annotations

import numpy as np
import pytest

from services.controller import Settings
from services.controller.core import ControllerCore
from services.controller.hqp import limit_rows_b
from services.controller.kinsim import KinematicSim
from services.controller.robot import ControlledRobot
from services.controller.scenarios import harvest_target, run_loop, scene
from services.robot.model import HOME_RAD, URDF_PATH
from services.runtime.settings import SettingsError, load_settings

MARGIN_RAD = 0.3


def elbow_near_its_stop() -> tuple[dict[str, list[float]], int, ControlledRobot]:
    """The home posture with the cutting arm's elbow 0.05 rad from its upper stop."""
    r = ControlledRobot(URDF_PATH)
    j = r.names.index("cutter_j4")
    q0 = {k: list(v) for k, v in HOME_RAD.items()}
    q0["cutter"][3] = r.upper_rad[j] - 0.05
    return q0, j, r


def hold_the_tool(margin_rad: float) -> tuple[float, object]:
    """Run 400 ticks with the cutter's goal where the start posture puts it (the tool level):
    the elbow's room to its stop at the end, and the last status."""
    q0, j, r = elbow_near_its_stop()
    r.set_q(KinematicSim(q0).q_arm_order())
    tip = r.T_world("cutter_tip")[:3, 3]
    core = ControllerCore(load_settings(Settings, {"limit_margin_rad": margin_rad}))
    res = run_loop(
        core,
        KinematicSim(q0),
        harvest_target(tip - np.array([0.0, 0.0, 0.06])),  # the tip 6 cm above: here
        scene(),
        400,
        stop_when_converged=False,
    )
    assert res.safety.violations == []
    return float(r.upper_rad[j] - res.q_rad[-1][j]), res.statuses[-1]


def test_the_elbow_leaves_its_stop_and_the_tool_still_converges() -> None:
    room_off, status_off = hold_the_tool(0.0)
    room_on, status_on = hold_the_tool(MARGIN_RAD)
    assert status_off.converged and status_on.converged
    assert room_off < 0.15  # the tasks alone leave the elbow near its stop
    assert room_on > 0.25  # the margin's rows move it out to nearly the margin


def test_rows_are_active_only_inside_the_margin() -> None:
    lower, upper = np.array([-2.0, -2.0, -2.0]), np.array([2.0, 2.0, 2.0])
    q = np.array([1.9, 0.0, -1.95])  # 0.1 rad from the upper stop; free; 0.05 from the lower
    b = limit_rows_b(q, lower, upper, 0.3, 0.01)
    up, low = b[:3], b[3:]
    assert up[0] == pytest.approx(1.9 - 0.01 * 0.2)  # Δq ≤ -gain · depth
    assert up[1] == up[2] == 1e3 and low[0] == low[1] == 1e3
    assert low[2] == pytest.approx(-(-1.95 + 0.01 * 0.25))  # Δq ≥ gain · depth


def test_a_negative_margin_stops_start_up_with_the_field_named() -> None:
    with pytest.raises(SettingsError, match="limit_margin_rad"):
        load_settings(Settings, {"limit_margin_rad": -0.1})


def test_off_the_solver_has_no_limit_rows() -> None:
    core = ControllerCore(load_settings(Settings, {}))
    assert core.hqp.s3 is None and core.hqp.lim3 is None
    with pytest.raises(ValueError, match="limit_weight"):
        core.hqp.avoid_limits(np.zeros(14), 0.3, 0.01)
