"""The pybullet world: the robot (kinematic, driven joint by joint), the ground, trunk and
branches (static), and the fruit (static while attached, rigid bodies once cut).

The robot follows the integrated joint state exactly: at every control tick its joints are
reset to (q, q̇) and velocity motors hold q̇ through the physics sub-steps, so links push the
fruit with the right velocity while the published joint state stays the commanded one (the
LWR's own position loop tracks to well under a millimetre).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from services.robot.model import URDF_PATH, all_joint_names
from services.robot.urdf import BASKET_HULL
from services.sim.world import World

FRUIT_DENSITY_KG_M3 = 850.0
ROBOT_MOTOR_FORCE = 2000.0
TOUCH_M = 0.001  # pybullet also reports points a little apart: touching = closer than this
Point = tuple[float, float, float]  # world frame, m


def _point(v: Iterable[float]) -> Point:
    x, y, z = v
    return (float(x), float(y), float(z))


def ellipsoid_vertices(semi_axes: tuple[float, float, float], n: int = 10) -> list[list[float]]:
    """Vertices on an ellipsoid (a UV sphere, scaled) for pybullet's convex hull."""
    out = [[0.0, 0.0, semi_axes[2]], [0.0, 0.0, -semi_axes[2]]]
    for i in range(1, n):
        th = math.pi * i / n
        for j in range(2 * n):
            ph = math.pi * j / n
            out.append(
                [
                    semi_axes[0] * math.sin(th) * math.cos(ph),
                    semi_axes[1] * math.sin(th) * math.sin(ph),
                    semi_axes[2] * math.cos(th),
                ]
            )
    return out


class Physics:
    """One pybullet DIRECT client holding the whole scene."""

    def __init__(self, world: World, tick_s: float, substeps: int) -> None:
        import pybullet as pb

        self.pb = pb
        self.cid = pb.connect(pb.DIRECT)
        c = self.cid
        pb.setGravity(0, 0, -9.81, physicsClientId=c)
        pb.setPhysicsEngineParameter(
            fixedTimeStep=tick_s / substeps, numSubSteps=0, physicsClientId=c
        )
        self.substeps = substeps
        self.names: dict[int, str] = {}
        self.robot = pb.loadURDF(
            str(URDF_PATH),
            useFixedBase=True,
            flags=pb.URDF_USE_IMPLICIT_CYLINDER,
            physicsClientId=c,
        )
        self.names[self.robot] = "robot"
        self.joint: dict[str, int] = {}
        self.link: dict[str, int] = {"base_link": -1}
        for i in range(pb.getNumJoints(self.robot, physicsClientId=c)):
            info = pb.getJointInfo(self.robot, i, physicsClientId=c)
            self.joint[info[1].decode()] = i
            self.link[info[12].decode()] = i
        self.link_name = {i: n for n, i in self.link.items()}
        self.joint_ids = [self.joint[n] for n in all_joint_names()]
        pb.setCollisionFilterGroupMask(self.robot, self.link[BASKET_HULL], 0, 0, physicsClientId=c)
        for name in ("basket", "basket_center"):
            pb.changeDynamics(self.robot, self.link[name], lateralFriction=0.9, physicsClientId=c)
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=c)
        self.ground = pb.createMultiBody(0, plane, physicsClientId=c)
        self.names[self.ground] = "ground"
        self.tree_bodies: set[int] = set()
        self._static_cylinder(world.trunk.p0, world.trunk.p1, world.trunk.radius, "trunk")
        for k, b in enumerate(world.branches):
            self._static_cylinder(b.p0, b.p1, b.radius, f"branch_{k}")
        self.fruit_body: dict[int, int] = {}
        self._fruit_shape: dict[int, int] = {}
        self._fruit_mass: dict[int, float] = {}
        for f in world.fruits:
            shape = pb.createCollisionShape(
                pb.GEOM_MESH, vertices=ellipsoid_vertices(f.semi_axes), physicsClientId=c
            )
            self._fruit_shape[f.fruit_id] = shape
            a, b_, v = f.semi_axes
            self._fruit_mass[f.fruit_id] = FRUIT_DENSITY_KG_M3 * 4 / 3 * math.pi * a * b_ * v
            self._add_fruit(f.fruit_id, f.centre, (0, 0, 0, 1), mass=0.0)

    # ---- building --------------------------------------------------------------------------
    def _static_cylinder(self, p0: np.ndarray, p1: np.ndarray, r: float, name: str) -> None:
        from services.sim.render.scene import rot_between

        pb, c = self.pb, self.cid
        axis = p1 - p0
        length = float(np.linalg.norm(axis))
        shape = pb.createCollisionShape(
            pb.GEOM_CYLINDER, radius=r, height=length, physicsClientId=c
        )
        q = quat_of(rot_between(np.array([0, 0, 1.0]), axis))
        body = pb.createMultiBody(
            0, shape, basePosition=((p0 + p1) / 2).tolist(), baseOrientation=q, physicsClientId=c
        )
        self.names[body] = name
        self.tree_bodies.add(body)

    def _add_fruit(self, i: int, pos: np.ndarray, quat: tuple, mass: float) -> None:
        pb, c = self.pb, self.cid
        body = pb.createMultiBody(
            mass,
            self._fruit_shape[i],
            basePosition=list(map(float, pos)),
            baseOrientation=list(map(float, quat)),
            physicsClientId=c,
        )
        pb.changeDynamics(
            body,
            -1,
            lateralFriction=0.8,
            restitution=0.15,
            rollingFriction=0.002,
            spinningFriction=0.002,
            physicsClientId=c,
        )
        self.names[body] = f"fruit_{i}"
        self.fruit_body[i] = body

    # ---- robot -----------------------------------------------------------------------------
    def set_robot(self, q: np.ndarray, qd: np.ndarray) -> None:
        """Joints (all_joint_names order) to q with velocity q̇, motors holding q̇."""
        pb, c = self.pb, self.cid
        for j, a, v in zip(self.joint_ids, q, qd, strict=True):
            pb.resetJointState(self.robot, j, float(a), float(v), physicsClientId=c)
        pb.setJointMotorControlArray(
            self.robot,
            self.joint_ids,
            pb.VELOCITY_CONTROL,
            targetVelocities=[float(v) for v in qd],
            forces=[ROBOT_MOTOR_FORCE] * len(self.joint_ids),
            physicsClientId=c,
        )

    def link_poses(self, links: list[int]) -> list[tuple[tuple, tuple]]:
        """World (position, quaternion xyzw) of the URDF frames of ``links`` (-1 = base)."""
        pb, c = self.pb, self.cid
        out = []
        states = pb.getLinkStates(
            self.robot,
            [i for i in links if i >= 0],
            computeForwardKinematics=True,
            physicsClientId=c,
        )
        it = iter(states)
        for i in links:
            if i < 0:
                out.append(pb.getBasePositionAndOrientation(self.robot, physicsClientId=c))
            else:
                s = next(it)
                out.append((s[4], s[5]))
        return out

    def frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position and rotation matrix of a robot frame."""
        ((p, q),) = self.link_poses([self.link[link]])
        return np.asarray(p), rot_of(q)

    def step(self) -> None:
        for _ in range(self.substeps):
            self.pb.stepSimulation(physicsClientId=self.cid)

    def robot_contacts(self) -> list[tuple[str, int]]:
        """(robot link name, other body id) pairs in contact, sorted, without repeats."""
        return sorted(self.robot_contact_points())

    def robot_contact_points(self) -> dict[tuple[str, int], tuple[float, float, float]]:
        """(robot link name, other body id) → the point on the link of the pair's deepest
        contact, world frame, m."""
        return {k: on_link for k, (on_link, _on_other) in self.robot_contact_pairs().items()}

    def robot_contact_pairs(self) -> dict[tuple[str, int], tuple[Point, Point]]:
        """(robot link name, other body id) → the pair's deepest contact: its point on the link
        and its point on the other body, world frame, m."""
        best: dict[tuple[str, int], tuple[float, Point, Point]] = {}
        for cp in self.pb.getContactPoints(bodyA=self.robot, physicsClientId=self.cid):
            if cp[2] == self.robot or cp[8] >= TOUCH_M:
                continue
            key = (self.link_name[cp[3]], cp[2])
            if key not in best or cp[8] < best[key][0]:
                best[key] = (cp[8], _point(cp[5]), _point(cp[6]))
        return {k: (a, b) for k, (_d, a, b) in best.items()}

    def tree_contacts_at(self, q: np.ndarray) -> list[tuple[str, str]]:
        """(robot link, tree body) pairs that would touch with the joints at ``q``
        (all_joint_names order, rad): the contacts the sim would count there, for judging a
        posture (the bench's truth). The joints are reset to ``q`` at rest: use it on a sim that
        is not stepping, or set the robot again before the next step."""
        return self._contacts_at(q, self.tree_bodies)

    def fruit_contacts_at(self, q: np.ndarray, but: int | None = None) -> list[tuple[str, str]]:
        """(robot link, fruit body) pairs that would touch with the joints at ``q``, fruit
        ``but`` (the one being harvested) left out; as ``tree_contacts_at``."""
        return self._contacts_at(q, [b for i, b in self.fruit_body.items() if i != but])

    def _contacts_at(self, q: np.ndarray, bodies: Iterable[int]) -> list[tuple[str, str]]:
        pb, c = self.pb, self.cid
        for j, a in zip(self.joint_ids, q, strict=True):
            pb.resetJointState(self.robot, j, float(a), 0.0, physicsClientId=c)
        hull = self.link[BASKET_HULL]  # collides with nothing (see __init__)
        pairs = {
            (self.link_name[cp[3]], self.names[body])
            for body in bodies
            for cp in pb.getClosestPoints(self.robot, body, TOUCH_M, physicsClientId=c)
            if cp[3] != hull
        }
        return sorted(pairs)

    # ---- fruit -----------------------------------------------------------------------------
    def place_fruit(self, i: int, pos: np.ndarray, quat: tuple = (0, 0, 0, 1)) -> None:
        self.pb.resetBasePositionAndOrientation(
            self.fruit_body[i], list(map(float, pos)), list(quat), physicsClientId=self.cid
        )

    def detach_fruit(self, i: int) -> None:
        """A static (attached) fruit becomes a rigid body at the same pose."""
        pos, quat = self.fruit_pose(i)
        self.remove_fruit(i)
        self._add_fruit(i, pos, quat, self._fruit_mass[i])

    def remove_fruit(self, i: int) -> None:
        body = self.fruit_body.pop(i)
        self.names.pop(body, None)
        self.pb.removeBody(body, physicsClientId=self.cid)

    def fruit_pose(self, i: int) -> tuple[np.ndarray, tuple]:
        p, q = self.pb.getBasePositionAndOrientation(self.fruit_body[i], physicsClientId=self.cid)
        return np.asarray(p), tuple(q)

    def fruit_mass(self, i: int) -> float:
        """Mass of fruit i, kg (density × ellipsoid volume)."""
        return self._fruit_mass[i]

    def fruit_speed(self, i: int) -> float:
        v, _ = self.pb.getBaseVelocity(self.fruit_body[i], physicsClientId=self.cid)
        return float(np.linalg.norm(v))

    def fruit_contacts(self, i: int) -> list[str]:
        """Names of what fruit i touches ('ground', 'trunk', 'robot/<link>', 'fruit_3', ...)."""
        out = set()
        for cp in self.pb.getContactPoints(bodyA=self.fruit_body[i], physicsClientId=self.cid):
            if cp[8] >= TOUCH_M:
                continue
            body = cp[2]
            name = self.names.get(body, f"body_{body}")
            out.add(f"robot/{self.link_name[cp[4]]}" if body == self.robot else name)
        return sorted(out)

    def close(self) -> None:
        if self.cid >= 0:
            self.pb.disconnect(physicsClientId=self.cid)
            self.cid = -1


def rot_of(q: tuple | list) -> np.ndarray:
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_of(R: np.ndarray) -> list[float]:
    """Quaternion (x, y, z, w) of a rotation matrix (Shepperd)."""
    t = np.trace(R)
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = math.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k]) * 2
        q = [0.0, 0.0, 0.0, (R[k, j] - R[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
    return q
