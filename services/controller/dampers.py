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
    nq, nv = robot.model.nq, robot.model.nv
    if not pairs:
        return inactive_rows(nq)
    zero = np.zeros((6, nv))
    jac: dict[int, np.ndarray] = {}

    def J(joint: int) -> np.ndarray:
        if joint <= _FIXED_JOINT:  # universe and the masked floating base never move
            return zero
        j = jac.get(joint)
        if j is None:
            j = jac[joint] = robot.joint_jacobian_world(joint)
        return j

    n = np.array([p.normal for p in pairs])  # (P, 3)
    p1 = np.array([p.p1_world_m for p in pairs])
    p2 = np.array([p.p2_world_m for p in pairs])
    J1 = np.array([J(p.joint1) for p in pairs])  # (P, 6, nv)
    J2 = np.array([J(p.joint2) for p in pairs])
    # nᵀ J_p = [n, p × n]ᵀ J for a point p on a body with spatial Jacobian J (world, at 0)
    w1 = np.concatenate([n, _cross(p1, n)], axis=1)  # (P, 6)
    w2 = np.concatenate([n, _cross(p2, n)], axis=1)
    ddot = np.einsum("pk,pkj->pj", w2, J2) - np.einsum("pk,pkj->pj", w1, J1)
    arm = ddot[:, N_FBASE_V:]
    movable = np.abs(arm).max(axis=1) > 1e-12  # else no joint step changes this distance
    if not movable.any():
        return inactive_rows(nq)
    A = np.zeros((int(movable.sum()), nq))
    A[:, N_FBASE_Q:] = -arm[movable]
    bound = np.array(
        [
            params[p.kind].ddot_min_m_s(p.distance_m, dt_s)
            for p, m in zip(pairs, movable, strict=True)
            if m
        ]
    )
    b = A[:, N_FBASE_Q:] @ robot.q_full[N_FBASE_Q:] - dt_s * bound
    return DamperRows(A, b, len(A))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a × b for (P, 3) arrays (np.cross's overhead is ~20 µs a call)."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )
