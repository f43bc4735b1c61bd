"""Pure core of the controller: one joint-velocity command and one control status per joint
state; plan targets and scene states are state updates. No zenoh, no wall clock in any
deterministic output (timings go to diag/controller only)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from schemas.base import ARM_ROLES
from schemas.control import ControllerDiagnostics, ControlStatus, Fallback, PlanTarget
from schemas.robot import ArmJointVelocity, JointState, JointVelocityCommand
from schemas.scene import SceneState
from services.controller import DamperGroup, Settings
from services.controller.dampers import DamperParams, damper_rows, inactive_rows
from services.controller.distances import DistanceEngine, DistanceReport, PairKind
from services.controller.hqp import LexicographicHQP, Weights
from services.controller.inputs import (
    Goals,
    Refusal,
    Workspace,
    goals,
    joint_goal,
    joint_positions,
)
from services.controller.limits import check_command
from services.controller.obstacles import (
    EMPTY,
    ObstacleArrays,
    ObstacleError,
    check_obstacles,
    obstacle_arrays,
    with_spheres,
)
from services.controller.reflex import ContactReflex, ReflexParams, inner_space
from services.controller.robot import ControlledRobot
from services.controller.targets import Gains, PoseGoal, StepTarget, step_target
from services.controller.watchdog import Watchdog
from services.robot.model import URDF_PATH
from services.runtime import ConfigError, Output, Stamper

NAME = "controller"


@dataclass
class Counters:
    """Cumulative counts of refused inputs and abnormal ticks (published in diagnostics)."""

    rejected_targets: int = 0
    rejected_scenes: int = 0
    rejected_joint_states: int = 0
    fallbacks: int = 0
    watchdog_stops: int = 0


@dataclass
class Tick:
    """What one joint-state tick decided (before it becomes messages)."""

    qd: np.ndarray | None = None  # arm order, rad/s; None = hold (zero)
    reason: str = ""
    watchdog: bool = False
    fallback: Fallback = "none"
    abs_step: StepTarget | None = None
    rel_step: StepTarget | None = None
    dist: DistanceReport = field(default_factory=DistanceReport)
    active_dampers: int = 0
    t_distance_s: float = 0.0
    t_damper_s: float = 0.0
    t_solve_s: float = 0.0


class ControllerCore:
    """See the package README for inputs, outputs, settings and every fallback."""

    def __init__(self, settings: Settings) -> None:
        s = self.s = settings
        urdf = Path(s.urdf_path) if s.urdf_path else URDF_PATH
        if not urdf.is_file():
            raise ConfigError(f"urdf_path {str(urdf)!r} is not a file")
        self.robot = ControlledRobot(urdf)
        self.engine = DistanceEngine(self.robot, s.cull_distance_m, s.branch_pairs_per_body)
        self.hqp = LexicographicHQP(
            self.robot,
            Weights(
                s.abs_position_weight,
                s.abs_orientation_weight,
                s.rel_position_weight,
                s.rel_orientation_weight,
                s.regularization_abs,
                s.regularization_rel,
                s.soft_damper_weight,
                s.acceleration_weight,
            ),
            s.nominal_period_s,
            bound_steps=s.max_joint_acceleration_rad_s2 is not None,
            limit_weight=s.limit_weight if s.limit_margin_rad > 0 else None,
        )
        self.watchdog = Watchdog(
            s.joint_state_timeout_ms * 1e-3, s.target_timeout_ms * 1e-3, s.nominal_period_s
        )
        self.timer_period_s = s.watchdog_check_period_ms * 1e-3  # runtime hook, live mode only
        self.stamper = Stamper(NAME)
        groups: dict[PairKind, DamperGroup] = {
            "trunk": s.trunk,
            "fruit": s.fruit,
            "branch": s.branch,
            "self": s.self_collision,
        }
        self.params: dict[PairKind, DamperParams] = {
            k: DamperParams(g.activation_m, g.safety_m, g.speed_m_s, s.damper_margin_m)
            for k, g in groups.items()
        }
        self.activation: dict[PairKind, float] = {k: p.activation_m for k, p in self.params.items()}
        self.workspace = Workspace(
            s.workspace_min_world_m,
            s.workspace_max_world_m,
            self.robot.cutter_base_world_m,
            self.robot.cutter_reach_m,
            s.max_relative_distance_m,
        )
        self.counters = Counters()
        self.target: PlanTarget | None = None
        self.goals: Goals | None = None
        self.target_refused: str | None = None
        self.scene: SceneState | None = None
        self.scene_refused: str | None = None
        self._obstacles: ObstacleArrays = EMPTY
        self._obstacles_key: tuple[Any, ...] | None = None
        self.reflex = (
            ContactReflex(
                ReflexParams(
                    s.contact_reflex_radius_m,
                    s.contact_reflex_voxel_m,
                    round(s.contact_reflex_hold_ms * 1e6),
                    s.contact_reflex_inner_clearance_m,
                    s.contact_reflex_inner_twig_m,
                    s.contact_reflex_max_spheres,
                )
            )
            if s.contact_reflex
            else None
        )
        # The last command sent (arm order, rad/s; a hold is zero): the acceleration bound's
        # reference.
        self.last_qd_rad_s = np.zeros(len(self.robot.names))

    # ---- inputs ----------------------------------------------------------------------------
    def handle(self, topic: str, msg: Any) -> list[Output]:
        if topic == "plan/target":
            self._on_target(msg)
            return []
        if topic == "scene/state":
            self._on_scene(msg)
            return []
        if topic == "robot/joint_state":
            return self._on_joint_state(msg)
        return []

    def on_timer(self, wall_ns: int) -> list[Output]:
        """Live mode only (runtime timer hook): stop the arms when joint states stop coming."""
        reason = self.watchdog.wall_check(wall_ns)
        if reason is None or self.watchdog.last_js_stamp_ns is None:
            return []
        self.counters.watchdog_stops += 1
        self.last_qd_rad_s = np.zeros(len(self.robot.names))
        stamp = self.watchdog.last_js_stamp_ns  # no newer time is known; never goes back
        tick = Tick(reason=reason, watchdog=True)
        return self._messages(tick, stamp, None, None)

    def _on_target(self, msg: PlanTarget) -> None:
        self.target = msg
        got = (
            goals(msg, self.robot.T_world_camera, self.workspace)
            if msg.joints is None
            else self._joint_goals(msg)
        )
        if isinstance(got, Refusal):
            self.counters.rejected_targets += 1
            self.goals, self.target_refused = (
                None,
                f"plan target seq {msg.header.seq} refused: {got.reason}",
            )
        else:
            self.goals, self.target_refused = got, None

    def _joint_goals(self, msg: PlanTarget) -> Goals | Refusal:
        """A joint goal and the tool poses it puts the tools in (forward kinematics; the next
        tick sets the measured joints again before anything else uses the robot)."""
        r = self.robot
        q = joint_goal(msg, r.by_role, r.lower_rad, r.upper_rad)
        if isinstance(q, Refusal):
            return q
        last = self.goals
        if last is not None and last.joints_rad is not None and np.array_equal(last.joints_rad, q):
            return last  # the planner re-sends its goal every tick: no FK again
        cut, col = r.tool_frame["cutter"], r.tool_frame["collector"]
        r.set_q(q)
        T, T_rel = r.T_world(cut), r.T_a_b(cut, col)
        return Goals(
            PoseGoal(T[:3, 3], T[:3, :3], None), PoseGoal(T_rel[:3, 3], T_rel[:3, :3], None), q
        )

    def _on_scene(self, msg: SceneState) -> None:
        try:
            o = msg.obstacles
            n = len(o.cylinders) + len(o.ellipsoids) + len(o.spheres)
            if n > self.s.max_obstacles:
                raise ObstacleError(
                    f"{n} obstacles, more than max_obstacles {self.s.max_obstacles}"
                )
            check_obstacles(msg.obstacles, self.s.min_obstacle_size_m, self.s.max_obstacle_size_m)
        except ObstacleError as exc:
            self.counters.rejected_scenes += 1
            self.scene, self.scene_refused = None, f"scene seq {msg.header.seq} refused: {exc}"
            return
        self.scene, self.scene_refused = msg, None

    def _obstacle_set(self) -> ObstacleArrays:
        reflex = self.reflex.version if self.reflex is not None else None
        if not self._obstacles_in_use():
            return EMPTY
        ignore = self.target.ignore_fruit_ids if self.target is not None else ()
        h = self.scene.header if self.scene is not None else None
        key = (h.seq if h else None, h.stamp_ns if h else None, ignore, reflex)
        if key != self._obstacles_key:
            base = obstacle_arrays(self.scene.obstacles, ignore) if self.scene else EMPTY
            if self.reflex is not None:
                base = with_spheres(base, *self.reflex.spheres())
            self._obstacles = base
            self._obstacles_key = key
        return self._obstacles

    def _obstacles_in_use(self) -> bool:
        return self.scene is not None or (self.reflex is not None and bool(self.reflex.voxels))

    def _feel(self, js: JointState) -> None:
        """The contact reflex: this tick's felt places, but those on the fruit worked on (the
        target's ignored fruit and the scene's selected one)."""
        assert self.reflex is not None
        worked = set(self.target.ignore_fruit_ids) if self.target is not None else set()
        if self.scene is not None and self.scene.selected_fruit_id is not None:
            worked.add(self.scene.selected_fruit_id)
        inner = inner_space(self.scene, worked, self.reflex.p) if js.contacts else []
        self.reflex.feel(js.contacts, js.header.stamp_ns, inner)

    # ---- the tick --------------------------------------------------------------------------
    def _on_joint_state(self, js: JointState) -> list[Output]:
        t0 = time.perf_counter()
        period = self.watchdog.on_joint_state(js.header.stamp_ns)
        q = joint_positions(js, self.robot.by_role)
        if isinstance(q, Refusal):
            self.counters.rejected_joint_states += 1
            tick = Tick(reason=f"joint state seq {js.header.seq} refused: {q.reason}")
        else:
            try:
                if self.reflex is not None:
                    self._feel(js)
                tick = self._control(js, q, period.dt_s, period.stale)
            except Exception as exc:  # never leave a tick unanswered: that stalls lock-step
                tick = Tick(reason=f"internal error, holding: {type(exc).__name__}: {exc}")
        self.last_qd_rad_s = np.zeros(len(self.robot.names)) if tick.qd is None else tick.qd
        if tick.watchdog:
            self.counters.watchdog_stops += 1
        if tick.fallback != "none":
            self.counters.fallbacks += 1
        return self._messages(tick, js.header.stamp_ns, js, t0)

    def _control(self, js: JointState, q: np.ndarray, dt_s: float, stale: str | None) -> Tick:
        robot = self.robot
        robot.admit_outside_limits(q)
        robot.set_q(q)
        tick = Tick()
        t = time.perf_counter()
        tick.dist = self.engine.compute(self._obstacle_set(), self.activation)
        tick.t_distance_s = time.perf_counter() - t
        if self.goals is not None:
            tick.abs_step, tick.rel_step = self._steps(dt_s)
        hold, watchdog = self._hold_reason(js.header.stamp_ns, stale)
        if hold is not None:
            tick.reason, tick.watchdog = hold, watchdog
            return tick
        assert tick.abs_step is not None and tick.rel_step is not None
        t = time.perf_counter()
        rows = (
            damper_rows(tick.dist.pairs, robot, self.params, dt_s)
            if tick.dist.pairs
            else inactive_rows(robot.model.nq)
        )
        tick.active_dampers = rows.active
        tick.t_damper_s = time.perf_counter() - t
        t = time.perf_counter()
        assert self.goals is not None
        self._bound_acceleration(q, dt_s)
        if self.hqp.s3 is not None:  # limit_margin_rad > 0
            self.hqp.avoid_limits(q, self.s.limit_margin_rad, self.s.limit_gain_per_s * dt_s)
        if self.goals.joints_rad is None:
            res = self.hqp.solve(tick.abs_step, tick.rel_step, rows, dt_s)
        else:
            step = self._joint_step(q, self.goals.joints_rad, dt_s)
            res = self.hqp.solve_joints(step, rows, dt_s)
        tick.t_solve_s = time.perf_counter() - t
        tick.fallback = res.fallback
        if res.dq is None:
            tick.reason = f"stopped: {res.reason}"
            return tick
        qd = robot.arm_order(res.dq) / dt_s
        problem = check_command(
            robot.names, q, qd, dt_s, robot.lower_rad, robot.upper_rad, robot.vmax_rad_s
        )
        if problem is not None:
            tick.fallback, tick.reason = (
                "stopped",
                f"stopped: command failed the limit check: {problem}",
            )
            return tick
        tick.qd = qd
        return tick

    def _steps(self, dt_s: float) -> tuple[StepTarget, StepTarget]:
        assert self.goals is not None and self.target is not None
        cut, col = self.robot.tool_frame["cutter"], self.robot.tool_frame["collector"]
        v_cap = self.s.max_tool_speed_m_s
        if self.target.max_tool_speed_m_s is not None:
            v_cap = min(v_cap, self.target.max_tool_speed_m_s)
        T = self.robot.T_world(cut)
        abs_step = step_target(
            T[:3, 3],
            T[:3, :3],
            self.goals.absolute,
            Gains(self.s.abs_gain_per_s, v_cap, self.s.max_tool_rate_rad_s),
            dt_s,
        )
        T_rel = self.robot.T_a_b(cut, col)
        rel_step = step_target(
            T_rel[:3, 3],
            T_rel[:3, :3],
            self.goals.relative,
            Gains(
                self.s.rel_gain_per_s, self.s.max_relative_speed_m_s, self.s.max_relative_rate_rad_s
            ),
            dt_s,
        )
        return abs_step, rel_step

    def _bound_acceleration(self, q: np.ndarray, dt_s: float) -> None:
        """This tick's steps within max_joint_acceleration_rad_s2 of the last command, and no
        faster towards a position limit than that deceleration can stop before it (else the
        hard limit stops the joint in one tick)."""
        a = self.s.max_joint_acceleration_rad_s2
        if a is None:
            return
        r, dv, last = self.robot, a * dt_s, self.last_qd_rad_s
        v_up = _braking_speed(r.upper_rad - q, a, dt_s)
        v_down = -_braking_speed(q - r.lower_rad, a, dt_s)
        high = np.maximum(np.minimum(last + dv, v_up), last - dv)
        low = np.minimum(np.maximum(last - dv, v_down), last + dv)
        self.hqp.bound_steps(q, low * dt_s, high * dt_s)

    def _joint_step(self, q: np.ndarray, goal_rad: np.ndarray, dt_s: float) -> dict[str, float]:
        """Per-step joint targets: q + K dt (goal − q), each joint capped at a fraction of its
        velocity limit (the joint-space form of the tool law)."""
        cap = self.s.joint_speed_fraction * self.robot.vmax_rad_s * dt_s
        step = np.clip(self.s.joint_gain_per_s * dt_s * (goal_rad - q), -cap, cap)
        return dict(zip(self.robot.names, (q + step).tolist(), strict=True))

    def _hold_reason(self, stamp_ns: int, stale: str | None) -> tuple[str | None, bool]:
        """Why this tick must hold (and whether it is the watchdog's doing), in order."""
        if stale is not None:
            return stale, True
        if self.target_refused is not None:
            return self.target_refused, False
        if self.target is None:
            return "no plan target yet", False
        if self.goals is None:
            return f"plan target seq {self.target.header.seq} asks to hold", False
        stale_target = self.watchdog.target_stale(stamp_ns, self.target.header.stamp_ns)
        if stale_target is not None:
            return stale_target, True
        if self.scene_refused is not None:
            return self.scene_refused, False
        if self.scene is None and self.s.require_scene:
            return "no scene state yet (obstacles unknown)", False
        return None, False

    # ---- outputs ---------------------------------------------------------------------------
    def _messages(
        self, tick: Tick, stamp_ns: int, js: JointState | None, t0: float | None
    ) -> list[Output]:
        def header(topic: str) -> Any:
            if js is None:  # a timer output answers nothing
                return self.stamper.header(topic, stamp_ns)
            return self.stamper.answer(topic, js.header)

        hold = tick.qd is None
        qd = np.zeros(len(self.robot.names)) if tick.qd is None else tick.qd
        arms = {}
        i = 0
        for role in ARM_ROLES:
            names = self.robot.by_role[role]
            arms[role] = ArmJointVelocity(
                names=names, velocity_rad_s=tuple(float(v) for v in qd[i : i + len(names)])
            )
            i += len(names)
        cmd = JointVelocityCommand(
            header=header("robot/command"), arms=arms, hold=hold, reason=tick.reason
        )
        a, r = tick.abs_step, tick.rel_step
        converged = (
            a is not None
            and r is not None
            and max(a.position_error_m, r.position_error_m) <= self.s.converged_position_m
            and max(a.orientation_error_rad, r.orientation_error_rad)
            <= self.s.converged_orientation_rad
        )
        status = ControlStatus(
            header=header("control/status"),
            target_seq=self.target.header.seq if self.target is not None else None,
            phase=self.target.phase if self.target is not None else "idle",
            abs_position_error_m=a.position_error_m if a else 0.0,
            abs_orientation_error_rad=a.orientation_error_rad if a else 0.0,
            rel_position_error_m=r.position_error_m if r else 0.0,
            rel_orientation_error_rad=r.orientation_error_rad if r else 0.0,
            min_distance_trunk_m=tick.dist.min_m.get("trunk"),
            min_distance_fruit_m=tick.dist.min_m.get("fruit"),
            min_distance_self_m=tick.dist.min_m.get("self"),
            active_dampers=tick.active_dampers,
            converged=converged,
            fallback=tick.fallback,
            watchdog=tick.watchdog,
            reason=tick.reason,
        )
        out: list[Output] = [("robot/command", cmd), ("control/status", status)]
        if self.s.publish_diagnostics and js is not None and t0 is not None:
            out.append(("diag/controller", self._diagnostics(header("diag/controller"), tick, t0)))
        return out

    def _diagnostics(self, h: Any, tick: Tick, t0: float) -> ControllerDiagnostics:
        c = self.counters
        return ControllerDiagnostics(
            header=h,
            cycle_ms=(time.perf_counter() - t0) * 1e3,
            distance_ms=tick.t_distance_s * 1e3,
            damper_ms=tick.t_damper_s * 1e3,
            solve_ms=tick.t_solve_s * 1e3,
            pairs_checked=tick.dist.pairs_checked,
            obstacles_near=tick.dist.obstacles_near,
            obstacles_total=self._obstacles.count if self._obstacles_in_use() else 0,
            reflex_spheres=len(self.reflex.voxels) if self.reflex is not None else 0,
            rejected_targets=c.rejected_targets,
            rejected_scenes=c.rejected_scenes,
            rejected_joint_states=c.rejected_joint_states,
            fallbacks=c.fallbacks,
            watchdog_stops=c.watchdog_stops,
        )


def _braking_speed(room_rad: np.ndarray, a_rad_s2: float, dt_s: float) -> np.ndarray:
    """The fastest speed, rad/s, from which one more tick at it and then braking at
    ``a_rad_s2`` stops within ``room_rad``: v dt + v²/(2a) = room."""
    room = np.maximum(room_rad, 0.0)
    return a_rad_s2 * (np.sqrt(dt_s**2 + 2 * room / a_rad_s2) - dt_s)
