"""A kinematic stand-in for the simulator, for tests and the benchmark: it integrates the
commanded joint velocities (explicit Euler over one period, no dynamics, no clamping, so a bad
command shows) and measures, independently of the controller, what the controller promises:
joint limits, velocity limits and distances (every obstacle, no broad phase, through placo's
own ``robot.distances()``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from schemas.base import ARM_ROLES, ArmRole, Header
from schemas.robot import ArmJointState, JointState, JointVelocityCommand
from schemas.scene import Obstacles
from services.robot.model import HOME_RAD, URDF_PATH, joint_names

SIM_PERIOD_NS = 8_333_333  # the pybullet sim's 120 Hz tick


class KinematicSim:
    """Joint positions by role; ``joint_state()`` stamps tick × period; ``apply()`` integrates."""

    def __init__(
        self,
        q0_rad: Mapping[ArmRole, Sequence[float]] = HOME_RAD,
        period_ns: int = SIM_PERIOD_NS,
        source: str = "sim",
        start_tick: int = 0,
    ) -> None:
        self.q: dict[ArmRole, np.ndarray] = {r: np.array(q0_rad[r], dtype=float) for r in ARM_ROLES}
        self.qd: dict[ArmRole, np.ndarray] = {r: np.zeros(7) for r in ARM_ROLES}
        self.period_ns = period_ns
        self.tick = start_tick  # a later run on the same controller continues the clock
        self.source = source

    @property
    def stamp_ns(self) -> int:
        return self.tick * self.period_ns

    def joint_state(self) -> JointState:
        return JointState(
            header=Header(stamp_ns=self.stamp_ns, seq=self.tick, source=self.source),
            arms={
                r: ArmJointState(
                    names=joint_names(r),
                    position_rad=tuple(float(v) for v in self.q[r]),
                    velocity_rad_s=tuple(float(v) for v in self.qd[r]),
                )
                for r in ARM_ROLES
            },
        )

    def apply(self, cmd: JointVelocityCommand) -> None:
        """Integrate ``cmd`` over one period (by joint name) and advance the clock."""
        dt = self.period_ns * 1e-9
        for r in ARM_ROLES:
            v = dict(zip(cmd.arms[r].names, cmd.arms[r].velocity_rad_s, strict=True))
            self.qd[r] = np.array([v[n] for n in joint_names(r)])
            self.q[r] = self.q[r] + self.qd[r] * dt
        self.tick += 1

    def q_arm_order(self) -> np.ndarray:
        return np.concatenate([self.q[r] for r in ARM_ROLES])


@dataclass
class SafetyReport:
    """Worst values seen by the monitor over a run (m, rad, rad/s); violations in words."""

    min_distance_m: dict[str, float] = field(
        default_factory=lambda: {"self": np.inf, "trunk": np.inf, "fruit": np.inf, "branch": np.inf}
    )
    max_limit_excess_rad: float = 0.0
    max_speed_ratio: float = 0.0
    violations: list[str] = field(default_factory=list)


class SafetyMonitor:
    """Independent measurements of a configuration against limits and obstacles.

    Distances use a second placo robot whose collision model holds every obstacle of the
    scene (coal shapes) paired with every moving robot body; ``robot.distances()`` computes all
    pairs. The controller's culling, slots and dampers are not involved.
    """

    def __init__(
        self, obstacles: Obstacles | None = None, ignore_fruit_ids: Sequence[int] = ()
    ) -> None:
        import coal
        import pinocchio as pin
        import placo

        self.robot = placo.RobotWrapper(str(URDF_PATH))
        self.names = tuple(n for r in ARM_ROLES for n in joint_names(r))
        m = self.robot.model
        ids = [m.getJointId(n) for n in self.names]
        self.q_idx = np.array([m.joints[i].idx_q for i in ids])
        self.lower = np.array(m.lowerPositionLimit[self.q_idx])
        self.upper = np.array(m.upperPositionLimit[self.q_idx])
        self.vmax = np.array(m.velocityLimit[[m.joints[i].idx_v for i in ids]])
        cm = self.robot.collision_model
        self.kind_of_pair = ["self"] * len(cm.collisionPairs)
        self.obstacle_of_pair: list[int | None] = [None] * len(cm.collisionPairs)
        bodies = [
            g
            for g, go in enumerate(cm.geometryObjects)
            if go.parentJoint > 1 and not (go.name.startswith("basket_") and "hull" not in go.name)
        ]
        shapes: list[tuple[str, object, np.ndarray]] = []
        if obstacles is not None:
            for c in obstacles.cylinders:
                shapes.append(
                    ("trunk", coal.Cylinder(c.radius_m, 20.0), np.array(c.axis_point_world_m))
                )
            for e in obstacles.ellipsoids:
                if e.fruit_id is not None and e.fruit_id in set(ignore_fruit_ids):
                    continue
                shapes.append(("fruit", coal.Ellipsoid(*e.semi_axes_m), np.array(e.center_world_m)))
            for sp in obstacles.spheres:
                shapes.append(("branch", coal.Sphere(sp.radius_m), np.array(sp.center_world_m)))
        for i, (kind, shape, center) in enumerate(shapes):
            gid = cm.addGeometryObject(
                pin.GeometryObject(f"monitor_{kind}_{i}", 0, pin.SE3(np.eye(3), center), shape)
            )
            for b in bodies:
                cm.addCollisionPair(pin.CollisionPair(b, gid))
                self.kind_of_pair.append(kind)
                self.obstacle_of_pair.append(i)
        self.n_obstacles = len(shapes)

    def distances(self, q_arm_order: np.ndarray) -> dict[str, float]:
        """Smallest signed distance per kind ('self', 'trunk', 'fruit', 'branch'), m (inf if
        none)."""
        self._set(q_arm_order)
        out = {"self": np.inf, "trunk": np.inf, "fruit": np.inf, "branch": np.inf}
        for kind, d in zip(self.kind_of_pair, self.robot.distances(), strict=True):
            out[kind] = min(out[kind], d.min_distance)
        return out

    def obstacle_distances(self, q_arm_order: np.ndarray) -> np.ndarray:
        """Smallest robot distance to each obstacle, m, in the order they were given (the
        trunk cylinders first, then the ellipsoids not ignored, then the spheres)."""
        self._set(q_arm_order)
        out = np.full(self.n_obstacles, np.inf)
        for i, d in zip(self.obstacle_of_pair, self.robot.distances(), strict=True):
            if i is not None:
                out[i] = min(out[i], d.min_distance)
        return out

    def _set(self, q_arm_order: np.ndarray) -> None:
        q = self.robot.state.q
        q[self.q_idx] = q_arm_order
        self.robot.state.q = q
        self.robot.update_kinematics()

    def check(
        self,
        q_arm_order: np.ndarray,
        qd_arm_order: np.ndarray,
        report: SafetyReport,
        safety_m: Mapping[str, float],
        tol_m: float = 0.0,
    ) -> None:
        """Update ``report`` with this configuration and command; note every violation."""
        excess = np.maximum(q_arm_order - self.upper, self.lower - q_arm_order)
        report.max_limit_excess_rad = max(report.max_limit_excess_rad, float(excess.max()))
        if excess.max() > 1e-6:
            report.violations.append(f"position limit exceeded by {excess.max():.2e} rad")
        ratio = float(np.max(np.abs(qd_arm_order) / self.vmax))
        report.max_speed_ratio = max(report.max_speed_ratio, ratio)
        if ratio > 1 + 1e-6:
            report.violations.append(f"velocity limit exceeded ({ratio:.4f} of the limit)")
        for kind, d in self.distances(q_arm_order).items():
            report.min_distance_m[kind] = min(report.min_distance_m[kind], d)
            if kind in safety_m and d < safety_m[kind] - tol_m:
                report.violations.append(
                    f"{kind} distance {d * 1e3:.2f} mm < d_s {safety_m[kind] * 1e3:.1f} mm"
                )
