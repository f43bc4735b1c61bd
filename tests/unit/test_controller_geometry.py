"""services/controller/geometry.py: rotations, log/exp, saturation, free-axis errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.controller.geometry import (
    axis_alignment_error,
    cross,
    exp3,
    log3,
    matrix_to_quat_xyzw,
    orientation_error,
    quat_xyzw_to_matrix,
    saturate,
)

RNG = np.random.default_rng(3)


def random_rotation() -> np.ndarray:
    return exp3(RNG.normal(size=3))


@pytest.mark.parametrize("i", range(20))
def test_quaternion_round_trip(i: int) -> None:
    R = random_rotation()
    q = matrix_to_quat_xyzw(R)
    assert abs(np.linalg.norm(q) - 1) < 1e-12 and q[3] >= 0
    assert np.allclose(quat_xyzw_to_matrix(q), R, atol=1e-12)


@pytest.mark.parametrize("angle", [0.0, 1e-10, 0.3, 2.0, math.pi - 1e-8, math.pi])
def test_log_is_the_inverse_of_exp_up_to_pi(angle: float) -> None:
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    w = axis * angle
    back = log3(exp3(w))
    assert np.allclose(exp3(back), exp3(w), atol=1e-9)
    assert abs(np.linalg.norm(back) - angle) < 1e-6


def test_cross_matches_numpy() -> None:
    a, b = RNG.normal(size=3), RNG.normal(size=3)
    assert np.allclose(cross(a, b), np.cross(a, b))


def test_saturate_caps_the_norm_and_keeps_the_direction() -> None:
    v = np.array([3.0, 4.0, 0.0])
    assert np.allclose(saturate(v, 1.0), [0.6, 0.8, 0.0])
    assert np.allclose(saturate(v, 10.0), v)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_a_rotation_about_the_free_axis_is_no_error(axis: str) -> None:
    R_goal = random_rotation()
    k = "xyz".index(axis)
    turned = R_goal @ exp3(np.eye(3)[k] * 1.1)  # about the goal frame's own axis
    assert np.linalg.norm(orientation_error(turned, R_goal, axis)) < 1e-12
    assert np.linalg.norm(orientation_error(turned, R_goal, None)) > 1.0


@pytest.mark.parametrize("i", range(10))
def test_the_free_axis_error_aligns_exactly_that_axis(i: int) -> None:
    R, R_goal = random_rotation(), random_rotation()
    e = orientation_error(R, R_goal, "x")
    assert np.allclose((exp3(e) @ R)[:, 0], R_goal[:, 0], atol=1e-9)
    # ... by the smallest rotation: the angle between the axes
    angle = math.acos(np.clip(R[:, 0] @ R_goal[:, 0], -1, 1))
    assert abs(np.linalg.norm(e) - angle) < 1e-9


def test_anti_parallel_axes_turn_by_pi_about_a_perpendicular() -> None:
    a = np.array([0.0, 0.0, 1.0])
    e = axis_alignment_error(a, -a)
    assert abs(np.linalg.norm(e) - math.pi) < 1e-12 and abs(e @ a) < 1e-12
    assert np.allclose(exp3(e) @ a, -a, atol=1e-12)
