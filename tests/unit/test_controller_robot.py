"""services/controller/robot.py: name-based maps between messages and placo's vectors."""

from __future__ import annotations

import numpy as np
import pytest

from services.controller.robot import ControlledRobot
from services.robot.model import LWR_POS_LIMIT_DEG, LWR_VEL_LIMIT_DEG_S, URDF_PATH


@pytest.fixture(scope="module")
def robot() -> ControlledRobot:
    return ControlledRobot(URDF_PATH)


def test_arm_order_maps_to_placo_by_name(robot: ControlledRobot) -> None:
    q = np.arange(14) * 0.01
    robot.set_q(q)
    for i, name in enumerate(robot.names):
        assert robot.robot.get_joint(name) == pytest.approx(q[i])
    assert robot.names[0] == "cutter_j1" and robot.names[7] == "collector_j1"


def test_limits_are_the_lwr_datasheet_values(robot: ControlledRobot) -> None:
    assert np.allclose(np.degrees(robot.upper_rad[:7]), LWR_POS_LIMIT_DEG)
    assert np.allclose(np.degrees(robot.vmax_rad_s[7:]), LWR_VEL_LIMIT_DEG_S)


def test_a_joint_outside_its_limit_widens_the_qp_limit_until_it_is_back(
    robot: ControlledRobot,
) -> None:
    q = np.zeros(14)
    q[2] = robot.upper_rad[2] + 0.01
    assert robot.admit_outside_limits(q) == ["cutter_j3"]
    assert robot.robot.get_joint_limits("cutter_j3")[1] == pytest.approx(q[2])
    assert robot.admit_outside_limits(np.zeros(14)) == []
    assert robot.robot.get_joint_limits("cutter_j3")[1] == pytest.approx(robot.upper_rad[2])


def test_the_cutter_reach_is_the_stretched_arm(robot: ControlledRobot) -> None:
    assert 1.3 < robot.cutter_reach_m < 1.45
