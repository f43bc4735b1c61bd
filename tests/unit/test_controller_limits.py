"""services/controller/limits.py: the last gate before a command is published."""

from __future__ import annotations

import numpy as np

from services.controller.limits import check_command

NAMES = ("a", "b")
LO, HI, VMAX = np.array([-1.0, -1.0]), np.array([1.0, 1.0]), np.array([2.0, 2.0])
DT = 0.01


def check(q: list[float], qd: list[float]) -> str | None:
    return check_command(NAMES, np.array(q), np.array(qd), DT, LO, HI, VMAX)


def test_a_safe_command_passes() -> None:
    assert check([0.0, 0.5], [1.9, -2.0]) is None


def test_non_finite_and_too_fast_commands_are_refused() -> None:
    assert "non-finite" in (check([0.0, 0.0], [float("nan"), 0.0]) or "")
    assert "b:" in (check([0.0, 0.0], [0.0, 2.1]) or "")


def test_a_command_that_would_pass_a_position_limit_is_refused() -> None:
    assert "a:" in (check([0.995, 0.0], [1.0, 0.0]) or "")  # 0.995 + 0.01 > 1


def test_a_joint_outside_its_limit_may_come_back_but_not_go_further() -> None:
    assert check([1.01, 0.0], [-0.5, 0.0]) is None
    assert check([1.01, 0.0], [0.0, 0.0]) is None
    assert check([1.01, 0.0], [0.1, 0.0]) is not None
