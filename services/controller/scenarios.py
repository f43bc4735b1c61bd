"""Scenes, targets and a closed loop for the tests and the benchmark: the controller core
driven by the kinematic sim, with a stand-in planner that re-sends its target every tick (the
real planner answers every control status) and a safety monitor."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from schemas.base import Header
from schemas.control import AbsoluteTarget, ControlStatus, PlanTarget, RelativeTarget
from schemas.robot import JointVelocityCommand
from schemas.scene import (
    CylinderObstacle,
    EllipsoidObstacle,
    Obstacles,
    SceneState,
    SphereObstacle,
    Trunk,
)
from services.controller.geometry import matrix_to_quat_xyzw
from services.controller.kinsim import KinematicSim, SafetyMonitor, SafetyReport
from services.robot.reach import (
    PEDUNCLE_ABOVE_M,
    R_CUTTER_BASKET,
    R_WORLD_CUTTER_FORWARD,
    basket_offset_cutter_m,
)

FRUIT_SEMI_AXES_M = (0.035, 0.035, 0.04)  # an orange: d_h = 3.5 cm, d_v = 4 cm


def harvest_target(
    fruit_world_m: Sequence[float] | np.ndarray,
    *,
    fruit_id: int | None = None,
    stamp_ns: int = 0,
    seq: int = 0,
    relative_m: Sequence[float] | None = None,
    phase: str = "harvest",
) -> PlanTarget:
    """The paper's harvest pose: the cutter tip PEDUNCLE_ABOVE_M above the fruit centre, level,
    pointing forward, turning about the vertical left free (θ_a); the dish under the tip,
    opening up, its turn about its normal free. The target fruit may be touched."""
    tip = np.asarray(fruit_world_m, dtype=float) + np.array([0.0, 0.0, PEDUNCLE_ABOVE_M])
    rel = basket_offset_cutter_m() if relative_m is None else np.asarray(relative_m, dtype=float)
    return PlanTarget(
        header=Header(stamp_ns=stamp_ns, seq=seq, source="planner"),
        phase=phase,  # type: ignore[arg-type]
        fruit_id=fruit_id,
        absolute=AbsoluteTarget(
            position_m=(float(tip[0]), float(tip[1]), float(tip[2])),
            orientation_xyzw=matrix_to_quat_xyzw(R_WORLD_CUTTER_FORWARD),
            free_axis="x",
        ),
        relative=RelativeTarget(
            position_m=(float(rel[0]), float(rel[1]), float(rel[2])),
            orientation_xyzw=matrix_to_quat_xyzw(R_CUTTER_BASKET),
            free_axis="z",
        ),
        ignore_fruit_ids=(fruit_id,) if fruit_id is not None else (),
    )


def fruit(
    i: int,
    center_m: Sequence[float] | np.ndarray,
    semi_axes_m: Sequence[float] | np.ndarray = FRUIT_SEMI_AXES_M,
) -> EllipsoidObstacle:
    return EllipsoidObstacle(
        name=f"fruit_{i}",
        fruit_id=i,
        center_world_m=(float(center_m[0]), float(center_m[1]), float(center_m[2])),
        semi_axes_m=(float(semi_axes_m[0]), float(semi_axes_m[1]), float(semi_axes_m[2])),
    )


def scene(
    fruits: Sequence[EllipsoidObstacle] = (),
    trunk_xy_m: Sequence[float] | None = None,
    trunk_radius_m: float = 0.06,
    stamp_ns: int = 0,
    seq: int = 0,
) -> SceneState:
    """A scene state holding only what the controller reads: the obstacle set."""
    cyl: tuple[CylinderObstacle, ...] = ()
    if trunk_xy_m is not None:
        cyl = (
            CylinderObstacle(
                name="trunk",
                axis_point_world_m=(float(trunk_xy_m[0]), float(trunk_xy_m[1]), 1.0),
                radius_m=trunk_radius_m,
            ),
        )
    return SceneState(
        header=Header(stamp_ns=stamp_ns, seq=seq, source="scene"),
        trunk=Trunk(found=trunk_xy_m is not None),
        obstacles=Obstacles(cylinders=cyl, ellipsoids=tuple(fruits)),
    )


def fruit_field(
    n: int,
    rng: np.random.Generator,
    keep_clear_of: Sequence[float] | None = None,
    robot_clearance_m: float = 0.12,
) -> list[EllipsoidObstacle]:
    """``n`` fruit spread over a 1.6 × 2.0 × 1.4 m block in front of the robot (x 0.35–1.95 m),
    none within 0.25 m of ``keep_clear_of`` (e.g. the target fruit) nor within
    ``robot_clearance_m`` of the robot in its ready posture (a run must start clear). Most lie
    far from the arms: the controller's culling must keep them cheap."""
    out: list[EllipsoidObstacle] = []
    monitor = None
    while len(out) < n:
        batch: list[EllipsoidObstacle] = []
        while len(out) + len(batch) < n:
            c = rng.uniform((0.35, -1.0, 0.5), (1.95, 1.0, 1.9))
            if keep_clear_of is None or np.linalg.norm(c - np.asarray(keep_clear_of)) >= 0.25:
                batch.append(fruit(1000 + len(out) + len(batch), c.tolist()))
        monitor = SafetyMonitor(Obstacles(ellipsoids=tuple(batch)))
        d = monitor.obstacle_distances(KinematicSim().q_arm_order())
        out += [f for f, di in zip(batch, d, strict=True) if di >= robot_clearance_m]
    return [fruit(1000 + i, f.center_world_m) for i, f in enumerate(out)]


def branch_field(
    n: int,
    rng: np.random.Generator,
    trunk_xy_m: Sequence[float],
    keep_clear_of: Sequence[Sequence[float]] = (),
    robot_clearance_m: float = 0.12,
    spacing_m: float = 0.04,
    radius_m: float = 0.03,
) -> list[SphereObstacle]:
    """``n`` occupied-space spheres ``spacing_m`` apart along random straight branches from the
    trunk axis towards the robot (as the scene publishes them), none within 0.2 m of a point of
    ``keep_clear_of`` (the targets) nor within ``robot_clearance_m`` of the robot in its ready
    posture."""
    out: list[np.ndarray] = []
    while len(out) < n:
        start = np.array([trunk_xy_m[0], trunk_xy_m[1], rng.uniform(0.7, 1.6)])
        end = start + rng.uniform((-0.8, -0.6, -0.2), (-0.2, 0.6, 0.4))
        steps = max(2, int(np.linalg.norm(end - start) / spacing_m))
        pts = [start + (end - start) * t for t in np.linspace(0, 1, steps)]
        pts = [
            p for p in pts if all(np.linalg.norm(p - np.asarray(k)) >= 0.2 for k in keep_clear_of)
        ]
        if not pts:
            continue
        monitor = SafetyMonitor(Obstacles(spheres=tuple(_sphere(0, p, radius_m) for p in pts)))
        d = monitor.obstacle_distances(KinematicSim().q_arm_order())
        out += [p for p, di in zip(pts, d, strict=True) if di >= robot_clearance_m]
    return [_sphere(i, p, radius_m) for i, p in enumerate(out[:n])]


def _sphere(i: int, c: np.ndarray, radius_m: float) -> SphereObstacle:
    return SphereObstacle(
        name=f"occupied_{i}",
        center_world_m=(float(c[0]), float(c[1]), float(c[2])),
        radius_m=radius_m,
    )


@dataclass
class LoopResult:
    """A closed-loop run: per-tick statuses and commands, the tick it converged at, safety."""

    statuses: list[ControlStatus] = field(default_factory=list)
    commands: list[JointVelocityCommand] = field(default_factory=list)
    q_rad: list[np.ndarray] = field(default_factory=list)  # arm order, after each command
    converged_tick: int | None = None
    safety: SafetyReport = field(default_factory=SafetyReport)


def run_loop(
    core: object,
    sim: KinematicSim,
    target: PlanTarget | None,
    scene_state: SceneState | None,
    max_ticks: int,
    *,
    monitor: SafetyMonitor | None = None,
    safety_m: dict[str, float] | None = None,
    stop_when_converged: bool = True,
    settle_ticks: int = 0,
) -> LoopResult:
    """Drive ``core`` (a ControllerCore) for up to ``max_ticks`` joint states.

    The scene is sent once before the first tick; the target is re-sent every tick, stamped
    with the tick (as the planner answering each status). Stops ``settle_ticks`` after the
    first converged status when ``stop_when_converged``.
    """
    handle = core.handle  # type: ignore[attr-defined]
    res = LoopResult()
    if scene_state is not None:
        handle("scene/state", scene_state)
    for k in range(max_ticks):
        if target is not None:
            h = target.header.model_copy(update={"stamp_ns": sim.stamp_ns, "seq": k})
            handle("plan/target", target.model_copy(update={"header": h}))
        outs = dict(handle("robot/joint_state", sim.joint_state()))
        cmd, status = outs["robot/command"], outs["control/status"]
        res.commands.append(cmd)
        res.statuses.append(status)
        sim.apply(cmd)
        res.q_rad.append(sim.q_arm_order())
        if monitor is not None:
            qd = np.concatenate([sim.qd[r] for r in ("cutter", "collector")])
            monitor.check(sim.q_arm_order(), qd, res.safety, safety_m or {})
        if status.converged and res.converged_tick is None:
            res.converged_tick = k
        if (
            stop_when_converged
            and res.converged_tick is not None
            and k >= res.converged_tick + settle_ticks
        ):
            break
    return res
