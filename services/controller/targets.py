"""The task-space control law: ẋ = K e, saturated, realised as per-step targets.

placo's tasks carry no gain: a task asks to remove its whole error in one step. The paper's law
``ẋ = K e`` becomes an intermediate target one control period ahead,

    p_step = p + sat(K dt (p_goal − p), v_max dt)
    R_step = exp(sat(K dt e_R, ω_max dt)) R

so the tool moves at K e, at most v_max (m/s) and ω_max (rad/s). With a free rotation axis the
orientation error e_R only aligns that axis (every orientation sharing it is a goal), so
saturation is never spent on the free rotation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.controller.geometry import exp3, norm, orientation_error, saturate


@dataclass(frozen=True)
class PoseGoal:
    """A pose goal in the task's parent frame (world for the absolute task, the cutter frame
    for the relative task), with one rotation axis of the goal frame optionally free."""

    p_m: np.ndarray  # (3,)
    R: np.ndarray  # (3, 3)
    free_axis: str | None


@dataclass(frozen=True)
class Gains:
    """K (1/s), and the saturations: v_max (m/s), ω_max (rad/s)."""

    k_per_s: float
    v_max_m_s: float
    w_max_rad_s: float


@dataclass(frozen=True)
class StepTarget:
    """Targets one control period ahead and the current errors (m, rad)."""

    p_step_m: np.ndarray
    R_step: np.ndarray
    mask_axes: str  # the constrained rotation axes of the goal frame, for placo's mask
    position_error_m: float
    orientation_error_rad: float


def constrained_axes(free_axis: str | None) -> str:
    """'xyz' without the free axis (placo mask string)."""
    return "".join(a for a in "xyz" if a != free_axis)


def step_target(
    p_m: np.ndarray, R: np.ndarray, goal: PoseGoal, g: Gains, dt_s: float
) -> StepTarget:
    """The per-step target of a pose task at ``(p_m, R)`` towards ``goal`` (see module doc)."""
    e_p = goal.p_m - p_m
    e_R = orientation_error(R, goal.R, goal.free_axis)
    p_step = p_m + saturate(g.k_per_s * dt_s * e_p, g.v_max_m_s * dt_s)
    R_step = exp3(saturate(g.k_per_s * dt_s * e_R, g.w_max_rad_s * dt_s)) @ R
    return StepTarget(
        p_step,
        R_step,
        constrained_axes(goal.free_axis),
        norm(e_p),
        norm(e_R),
    )
