"""services/controller/targets.py: the saturated task-space law as per-step targets."""

from __future__ import annotations

import numpy as np

from services.controller.geometry import exp3, log3
from services.controller.targets import Gains, PoseGoal, constrained_axes, step_target

DT = 0.01
G = Gains(k_per_s=3.0, v_max_m_s=0.25, w_max_rad_s=1.0)


def test_small_errors_move_at_k_times_the_error() -> None:
    goal = PoseGoal(np.array([0.01, 0.0, 0.0]), exp3(np.array([0.0, 0.0, 0.02])), None)
    st = step_target(np.zeros(3), np.eye(3), goal, G, DT)
    assert np.allclose(st.p_step_m, [3.0 * DT * 0.01, 0, 0])
    assert np.allclose(log3(st.R_step), [0, 0, 3.0 * DT * 0.02])
    assert abs(st.position_error_m - 0.01) < 1e-12
    assert abs(st.orientation_error_rad - 0.02) < 1e-12


def test_large_errors_saturate_at_the_speed_caps() -> None:
    goal = PoseGoal(np.array([0.0, 2.0, 0.0]), exp3(np.array([1.5, 0.0, 0.0])), None)
    st = step_target(np.zeros(3), np.eye(3), goal, G, DT)
    assert np.isclose(np.linalg.norm(st.p_step_m), 0.25 * DT)  # 0.25 m/s
    assert np.isclose(np.linalg.norm(log3(st.R_step)), 1.0 * DT)  # 1 rad/s


def test_saturation_is_not_spent_on_the_free_rotation() -> None:
    R_goal = exp3(np.array([2.5, 0.0, 0.0])) @ exp3(np.array([0.0, 0.05, 0.0]))
    goal = PoseGoal(np.zeros(3), R_goal, "x")
    st = step_target(np.zeros(3), np.eye(3), goal, G, DT)
    # The big turn about x is free; only the small tilt of the x axis is an error.
    assert st.orientation_error_rad < 0.06
    assert st.mask_axes == "yz" and constrained_axes(None) == "xyz"
