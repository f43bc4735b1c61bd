"""Velocity dampers (paper eq. (7)–(8)) as linear inequalities on the joint step.

For a pair at distance d ≤ d_i the distance may shrink no faster than

    ḋ ≥ ḋ* = −ξ (d − d_s) / (d_i − d_s),        ḋ = nᵀ (J_p2 − J_p1) q̇

with n the unit normal from body 1 to body 2 and J_p the Jacobian of each witness point. placo
takes custom inequalities in configuration space, ``A (q + Δq) ≤ b`` with nq = 21 columns (the
floating base's 7 are ignored), and Δq = q̇ dt, so each pair gives one row

    A = −nᵀ (J_p2 − J_p1)  (v-columns 6: → q-columns 7:),   b = A q − dt ḋ*.

Two deviations from the paper, both because the law runs in discrete time (measured with the
kinematic sim, see the README):

* Below d_s the paper's law asks to separate at ξ (d_s − d)/(d_i − d_s), which is slow: a tool
  sliding round the trunk loses s²/2R per step to the surface's curvature (≈ 20 µm at 2 mm per
  step), and that slow recovery let the loss pile up to 1.8 mm below d_s. Here the deficit is
  recovered in one step, at most ξ: ḋ* = min((d_s − d)/dt, ξ). The law is continuous at d_s.
* d_s inside the law is the setting plus ``margin_m`` (0.5 mm by default), so the per-step
  curvature loss stays above the d_s the user asked for.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from services.controller.distances import PairDistance, PairKind
from services.controller.geometry import cross
from services.controller.robot import N_FBASE_Q, N_FBASE_V, ControlledRobot

_FIXED_JOINT = 1  # joints 0 (universe) and 1 (placo's floating base, masked) never move


@dataclass(frozen=True)
class DamperParams:
    """One damper group: activation distance d_i (m), safety distance d_s (m), ξ (m/s), and
    the discretisation margin added to d_s inside the law (m)."""

    activation_m: float
    safety_m: float
    speed_m_s: float
    margin_m: float = 0.0

    def ddot_min_m_s(self, d_m: float, dt_s: float) -> float:
        """ḋ*, the smallest allowed rate of change of the distance ``d_m``, m/s."""
        d_s = self.safety_m + self.margin_m
        if d_m >= d_s:
            return -self.speed_m_s * (d_m - d_s) / (self.activation_m - d_s)
        return min((d_s - d_m) / dt_s, self.speed_m_s)


@dataclass(frozen=True)
class DamperRows:
    """Rows for placo's JointSpaceHalfSpacesConstraint: ``A (q + Δq) ≤ b``.

    When no damper is active, one inactive row (0 ≤ 1) stands in: placo refuses an empty
    block. ``active`` counts the real rows."""

    A: np.ndarray  # (rows, nq)
    b: np.ndarray  # (rows,)
    active: int


def inactive_rows(nq: int) -> DamperRows:
    return DamperRows(np.zeros((1, nq)), np.ones(1), 0)


def damper_rows(
    pairs: list[PairDistance],
    robot: ControlledRobot,
    params: dict[PairKind, DamperParams],
    dt_s: float,
) -> DamperRows:
    """One row per pair within its activation distance (see the module docstring)."""
    nq = robot.model.nq
    q = robot.q_full
    jac: dict[int, np.ndarray] = {}
    rows_A: list[np.ndarray] = []
    rows_b: list[float] = []
    for pr in pairs:
        ddot = _point_row(robot, jac, pr.joint2, pr.p2_world_m, pr.normal)
        ddot -= _point_row(robot, jac, pr.joint1, pr.p1_world_m, pr.normal)
        arm = ddot[N_FBASE_V:]
        if not np.any(np.abs(arm) > 1e-12):
            continue  # neither body can move: no joint step changes this distance
        a = np.zeros(nq)
        a[N_FBASE_Q:] = -arm
        rows_A.append(a)
        rows_b.append(
            float(a[N_FBASE_Q:] @ q[N_FBASE_Q:])
            - dt_s * params[pr.kind].ddot_min_m_s(pr.distance_m, dt_s)
        )
    if not rows_A:
        return inactive_rows(nq)
    return DamperRows(np.array(rows_A), np.array(rows_b), len(rows_A))


def _point_row(
    robot: ControlledRobot, jac: dict[int, np.ndarray], joint: int, p: np.ndarray, n: np.ndarray
) -> np.ndarray:
    """nᵀ J_p (nv,) for the point ``p`` (world) carried by ``joint``: nᵀ J_v + (p × n)ᵀ J_ω,
    with J the joint's spatial Jacobian at the world origin."""
    if joint <= _FIXED_JOINT:
        return np.zeros(robot.model.nv)
    J = jac.get(joint)
    if J is None:
        J = jac[joint] = robot.joint_jacobian_world(joint)
    return n @ J[:3] + cross(p, n) @ J[3:]
