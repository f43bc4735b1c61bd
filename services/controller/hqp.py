"""The hierarchy: inequalities > absolute task > relative task, as two sequential placo QPs.

Paper §IV-A, eq. (6). Solve 1 minimises the absolute task's residual under every inequality
(joint position and velocity limits, velocity dampers) → Δq₁. Solve 2 minimises the relative
task's residual under the same inequalities *and* ``A₁ Δq = A₁ Δq₁`` (the absolute task's rows,
held through a pair of half-spaces each, ±1e-7), so the relative task can only use what the
absolute task leaves free: a true lexicographic order, never a weighted blend. Δq₁ satisfies
solve 2's constraints, so solve 2 is feasible whenever solve 1 is (up to round-off).

Fallbacks (documented in the README): if solve 1 is infeasible, the dampers are made soft
(slack, weight ``soft_damper_weight``) and both solves retried → ``softened``; if that fails
too → ``stopped`` (no Δq). If solve 2 alone fails, Δq₁ is sent → ``absolute_only``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from schemas.control import Fallback
from services.controller.dampers import DamperRows
from services.controller.robot import N_FBASE_Q, N_FBASE_V, ControlledRobot
from services.controller.targets import StepTarget

HOLD_EPS = 1e-7  # slack of the held absolute rows, m or rad per step


@dataclass(frozen=True)
class Weights:
    """Task weights (dimensionless: errors are per-step, in m and rad) and regularisations."""

    abs_position: float = 1.0
    abs_orientation: float = 1.0
    rel_position: float = 1.0
    rel_orientation: float = 1.0
    regularization_abs: float = 1e-6
    regularization_rel: float = 1e-4
    soft_damper: float = 1e4
    acceleration: float = 1e3


@dataclass(frozen=True)
class HqpResult:
    """The joint step (nv, rad) or None when stopped; which fallback; why, when one was used."""

    dq: np.ndarray | None
    fallback: Fallback
    reason: str = ""


class LexicographicHQP:
    """Two placo KinematicsSolvers on one robot, sharing the damper rows."""

    def __init__(
        self,
        robot: ControlledRobot,
        weights: Weights,
        dt_s: float,
        bound_steps: bool = False,
        limit_weight: float | None = None,
    ) -> None:
        """``bound_steps``: give each solve the soft step bound ``bound_steps()`` sets; off,
        the solves have no such rows at all (inactive soft rows would still add slack
        variables and change the steps by round-off). ``limit_weight``: a third solve, under
        every inequality and both tasks' rows held, moves joints away from their position
        limits through the soft rows ``avoid_limits()`` sets (this slack weight against 1 for
        staying at Δq₂); None: no third solve."""
        import placo

        self.robot = robot
        self.w = weights
        self.bounded = bound_steps
        cut, col = robot.tool_frame["cutter"], robot.tool_frame["collector"]
        nq = robot.model.nq
        self.s1 = self._solver(placo, dt_s)
        self.abs_pos = self.s1.add_position_task(cut, np.zeros(3))
        self.abs_pos.configure("abs_position", "soft", weights.abs_position)
        self.abs_ori = self.s1.add_orientation_task(cut, np.eye(3))
        self.abs_ori.configure("abs_orientation", "soft", weights.abs_orientation)
        self.s1.add_regularization_task(weights.regularization_abs)
        self.damp1 = self.s1.add_joint_space_half_spaces_constraint(np.zeros((1, nq)), np.ones(1))
        self.acc1 = self._step_bound(self.s1, "acceleration1")

        self.s2 = self._solver(placo, dt_s)
        self.rel_pos = self.s2.add_relative_position_task(cut, col, np.zeros(3))
        self.rel_pos.configure("rel_position", "soft", weights.rel_position)
        self.rel_ori = self.s2.add_relative_orientation_task(cut, col, np.eye(3))
        self.rel_ori.configure("rel_orientation", "soft", weights.rel_orientation)
        self.s2.add_regularization_task(weights.regularization_rel)
        self.damp2 = self.s2.add_joint_space_half_spaces_constraint(np.zeros((1, nq)), np.ones(1))
        self.acc2 = self._step_bound(self.s2, "acceleration2")
        self.hold = self.s2.add_joint_space_half_spaces_constraint(np.zeros((1, nq)), np.ones(1))
        self.hold.configure("hold_absolute", "hard", 1.0)
        # Solve 3 (limit_weight): only what both tasks leave free, towards the joints' room.
        self.s3 = self._solver(placo, dt_s) if limit_weight is not None else None
        if self.s3 is not None:
            self.stay = self.s3.add_joints_task()  # as close to Δq₂ as the limit rows allow
            self.stay.configure("stay", "soft", 1.0)
            self.damp3 = self.s3.add_joint_space_half_spaces_constraint(
                np.zeros((1, nq)), np.ones(1)
            )
            self.hold3 = self.s3.add_joint_space_half_spaces_constraint(
                np.zeros((1, nq)), np.ones(1)
            )
            self.hold3.configure("hold_tasks", "hard", 1.0)
        self.lim3 = self._arm_rows(self.s3, "limits3", limit_weight)

        # A joint goal (retracing a path): one solve, the joints task under the same limits
        # and dampers.
        self.s0 = self._solver(placo, dt_s)
        self.joints = self.s0.add_joints_task()
        self.joints.configure("joints", "soft", 1.0)
        self.s0.add_regularization_task(weights.regularization_abs)
        self.damp0 = self.s0.add_joint_space_half_spaces_constraint(np.zeros((1, nq)), np.ones(1))
        self.acc0 = self._step_bound(self.s0, "acceleration0")

    def _solver(self, placo: Any, dt_s: float) -> Any:
        """A solver with the torso fixed and the URDF's position and velocity limits."""
        s = placo.KinematicsSolver(self.robot.robot)
        s.mask_fbase(True)  # placo always adds a floating base; the torso does not move
        s.dt = dt_s  # required before velocity limits: |Δq| ≤ dt · v_max
        s.enable_joint_limits(True)  # lower ≤ q + Δq ≤ upper
        s.enable_velocity_limits(True)
        return s

    def _step_bound(self, solver: Any, name: str) -> Any:
        """Two soft half-spaces per arm joint, ``q + Δq ≤ q + high`` and ``-(q + Δq) ≤
        -(q + low)``: the rows are fixed, ``bound_steps`` sets their right-hand side (inactive
        until then: 1000 rad). None when the steps are not bounded."""
        return self._arm_rows(solver, name, self.w.acceleration if self.bounded else None)

    def _arm_rows(self, solver: Any, name: str, weight: float | None) -> Any:
        """Two soft half-spaces per arm joint (upper rows, then lower), inactive (1000 rad)
        until their right-hand side is set; None when ``weight`` is None."""
        if weight is None:
            return None
        n = len(self.robot.names)
        A = np.zeros((2 * n, self.robot.model.nq))
        A[np.arange(n), self.robot.q_idx] = 1.0
        A[n + np.arange(n), self.robot.q_idx] = -1.0
        c = solver.add_joint_space_half_spaces_constraint(A, np.full(2 * n, 1e3))
        c.configure(name, "soft", weight)
        return c

    def avoid_limits(self, q_rad: np.ndarray, margin_rad: float, gain_step: float) -> None:
        """Ask each arm joint within ``margin_rad`` of a position limit (``q_rad``, arm order)
        to step away by at least ``gain_step`` times its depth into the margin (rad), as a
        soft row of solve 3; the other joints' rows stay inactive. Only for a solver built
        with ``limit_weight``."""
        if self.lim3 is None:
            raise ValueError("avoid_limits() on an HQP built without limit_weight")
        self.lim3.b = limit_rows_b(
            q_rad, self.robot.lower_rad, self.robot.upper_rad, margin_rad, gain_step
        )

    def bound_steps(self, q_rad: np.ndarray, low_rad: np.ndarray, high_rad: np.ndarray) -> None:
        """Keep each arm joint's step from ``q_rad`` (arm order, rad) within [low, high] as a
        soft bound, in every solve from now on. Soft, so never infeasible: the hard limits and
        the dampers come first. Only for a solver built with ``bound_steps``."""
        if not self.bounded:
            raise ValueError("bound_steps() on an HQP built without bound_steps=True")
        b = np.concatenate([q_rad + high_rad, -(q_rad + low_rad)])
        for c in (self.acc0, self.acc1, self.acc2):
            c.b = b

    def solve(
        self, abs_step: StepTarget, rel_step: StepTarget, rows: DamperRows, dt_s: float
    ) -> HqpResult:
        """Δq for this tick (robot state already set), or the documented fallback."""
        for s in (self.s1, self.s2):
            s.dt = dt_s
        self.abs_pos.target_world = abs_step.p_step_m
        self.abs_ori.R_world_frame = abs_step.R_step
        self.abs_ori.mask.set_axises(abs_step.mask_axes, "local")  # local = the target frame
        self.rel_pos.target = rel_step.p_step_m  # expressed in the cutter frame (placo: frame a)
        self.rel_ori.R_a_b = rel_step.R_step
        # Relative orientation errors are in the cutter frame; the free axis is one of the
        # collector goal frame, so project on that frame's axes (custom = R_step^T).
        self.rel_ori.mask.R_custom_world = rel_step.R_step.T
        self.rel_ori.mask.set_axises(rel_step.mask_axes, "custom")
        for c in (self.damp1, self.damp2):
            c.A, c.b = rows.A, rows.b
        fallback: Fallback = "none"
        reason = ""
        self._dampers("hard")
        try:
            dq1 = np.array(self.s1.solve(False))
        except RuntimeError as exc:
            self._dampers("soft")
            try:
                dq1 = np.array(self.s1.solve(False))
            except RuntimeError as exc2:
                return HqpResult(None, "stopped", f"QP infeasible even with soft dampers: {exc2}")
            fallback, reason = "softened", f"dampers softened ({_short(exc)})"
        self._hold_absolute(dq1)
        try:
            dq2 = np.array(self.s2.solve(False))
        except RuntimeError as exc:
            return HqpResult(dq1, "absolute_only", f"relative QP failed ({_short(exc)})")
        if self.s3 is not None:
            dq2 = self._off_the_limits(dq2, rows, dt_s, soft=fallback == "softened")
        return HqpResult(dq2, fallback, reason)

    def _off_the_limits(
        self, dq2: np.ndarray, rows: DamperRows, dt_s: float, soft: bool
    ) -> np.ndarray:
        """Solve 3: Δq with both tasks' rows held at what Δq₂ gives them (± HOLD_EPS), the
        dampers as in solves 1–2, the limit rows soft; Δq₂ itself when it fails (Δq₂ is
        feasible, so only round-off can make it)."""
        assert self.s3 is not None
        self.s3.dt = dt_s
        self.damp3.A, self.damp3.b = rows.A, rows.b
        self.damp3.configure("dampers3", "soft" if soft else "hard", self.w.soft_damper)
        A = np.vstack([self.abs_pos.A, self.abs_ori.A, self.rel_pos.A, self.rel_ori.A])
        self.hold3.A, self.hold3.b = self._held_rows(A[:, N_FBASE_V:], dq2)
        q = self.robot.q_full[self.robot.q_idx]
        goal = q + self.robot.arm_order(dq2)
        self.stay.set_joints(dict(zip(self.robot.names, goal.tolist(), strict=True)))
        try:
            return np.array(self.s3.solve(False))
        except RuntimeError:
            return dq2

    def solve_joints(self, q_step: dict[str, float], rows: DamperRows, dt_s: float) -> HqpResult:
        """Δq towards the per-step joint targets ``q_step`` (name → rad) under every
        inequality; the dampers are softened only when the hard ones are infeasible."""
        self.s0.dt = dt_s
        self.joints.set_joints(q_step)
        self.damp0.A, self.damp0.b = rows.A, rows.b
        self.damp0.configure("dampers0", "hard", self.w.soft_damper)
        try:
            return HqpResult(np.array(self.s0.solve(False)), "none")
        except RuntimeError as exc:
            self.damp0.configure("dampers0", "soft", self.w.soft_damper)
            try:
                dq = np.array(self.s0.solve(False))
            except RuntimeError as exc2:
                return HqpResult(None, "stopped", f"QP infeasible even with soft dampers: {exc2}")
            return HqpResult(dq, "softened", f"dampers softened ({_short(exc)})")

    def _dampers(self, priority: str) -> None:
        for i, c in enumerate((self.damp1, self.damp2)):
            c.configure(f"dampers{i + 1}", priority, self.w.soft_damper)

    def _hold_absolute(self, dq1: np.ndarray) -> None:
        """Solve 2 keeps A₁ Δq = A₁ Δq₁ (± HOLD_EPS) through 2 half-spaces per absolute row."""
        A1 = np.vstack([self.abs_pos.A, self.abs_ori.A])[:, N_FBASE_V:]
        self.hold.A, self.hold.b = self._held_rows(A1, dq1)

    def _held_rows(self, A: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Half-spaces keeping ``A Δq = A dq`` (± HOLD_EPS) in placo's configuration space:
        ``A`` (rows × the arm joints' v columns) acts on q + Δq."""
        y = A @ dq[N_FBASE_V:]
        m = len(A)
        H = np.zeros((2 * m, self.robot.model.nq))
        H[:m, N_FBASE_Q:] = A
        H[m:, N_FBASE_Q:] = -A
        qa = self.robot.q_full[N_FBASE_Q:]
        return H, np.concatenate([A @ qa + y + HOLD_EPS, -(A @ qa) - y + HOLD_EPS])


def _short(exc: Exception) -> str:
    return str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__


def limit_rows_b(
    q: np.ndarray, lower: np.ndarray, upper: np.ndarray, margin: float, gain_step: float
) -> np.ndarray:
    """Right-hand sides of the limit rows ``q + Δq ≤ b_up`` and ``-(q + Δq) ≤ b_low``: a joint
    ``d`` inside the margin of its upper limit gets ``Δq ≤ -gain_step · d`` (the lower limit
    alike); 1000 rad (inactive) elsewhere."""
    far = 1e3
    up_depth = margin - (upper - q)
    low_depth = margin - (q - lower)
    b_up = np.where(up_depth > 0, q - gain_step * up_depth, far)
    b_low = np.where(low_depth > 0, -(q + gain_step * low_depth), far)
    return np.concatenate([b_up, b_low])
