"""Pure core of the sim (a clock master): ticks of physics, joint states, camera frames, truth.

Time: tick k is valid at k·control_period_ns. Each tick emits, in order, (1) on camera ticks a
group [camera/rgbd, sim/truth], then (2) [robot/joint_state, robot/basket (camera ticks only),
sim/events...]; the Node awaits the answers of each group before the next, so perception has
answered a frame before the controller sees the joint state of the same tick. Commands received
during tick k drive the physics step k → k+1 (``advance``). No wall clock; all randomness
seeded.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from schemas.base import ARM_ROLES, Pose
from schemas.camera import RgbdFrame, RgbdFrameMeta
from schemas.robot import (
    ArmJointState,
    BasketState,
    JointState,
    JointVelocityCommand,
    SensedContact,
    ToolCommand,
)
from schemas.sim import GroundTruth, SimCounters, SimEvent, TrunkTruth
from services.robot.model import HOME_RAD, joint_names
from services.runtime import ConfigError, Output, Stamper
from services.sim import Settings
from services.sim.commands import JOINTS, CommandRejected, clamp, command_velocities
from services.sim.fruits import Ev, Fruits
from services.sim.physics import Physics, quat_of
from services.sim.render.camera import CameraModel, head_camera_pose
from services.sim.render.depth_noise import D435Noise
from services.sim.render.renderer import Renderer
from services.sim.render.scene import RenderObject
from services.sim.render.shading import Lighting
from services.sim.scenario import ScenarioError, load_scenario
from services.sim.timeline import Timeline
from services.sim.truth import fruit_pixels, fruit_truth
from services.sim.visuals import (
    RobotVisuals,
    environment_objects,
    fruit_objects,
    hand_objects,
    sky,
    sway_objects,
    tree_objects,
)
from services.sim.world import World, build_world

log = logging.getLogger("sim")
CAMERA_FRAME_ID = "camera_optical"


def began(at_world_m: tuple[float, float, float]) -> str:
    """A begun contact's detail: where it touched the other body (world, m), for finding what
    in the tree the arms meet (``startswith("contact began")`` is the test for a beginning)."""
    x, y, z = at_world_m
    return f"contact began at ({x:+.4f}, {y:+.4f}, {z:+.4f}) m"


class SimCore:
    """The simulated world behind camera/rgbd, robot/joint_state, sim/truth and sim/events."""

    def __init__(self, s: Settings) -> None:
        try:
            self.world: World = build_world(load_scenario(s.scenario), s.seed, s.fruit_count)
        except ScenarioError as exc:
            raise ConfigError(str(exc)) from None
        self.s = s
        self.dt = s.control_period_ns * 1e-9
        self.physics = Physics(self.world, self.dt, s.physics_substeps)
        self.timeline = Timeline(self.world)
        self.fruits = Fruits(
            self.world, self.physics, self.timeline, self.dt, s.basket_empty_after_s
        )
        self.camera = CameraModel()
        self.T_world_camera = head_camera_pose()
        W, H = self.camera.width, self.camera.height
        env = self.world.scenario.environment
        bg = sky(H, W) if env == "orchard" else np.full((H, W, 3), 90, np.uint8)
        self.renderer = Renderer(self.camera, self.T_world_camera, Lighting(), bg, s.render_cache)
        self.static_objects = environment_objects(env, self.world.seed) + tree_objects(self.world)
        pb = self.physics
        self.robot_vis = RobotVisuals(pb.pb, pb.cid, pb.robot, pb.link_name)
        self.noise = D435Noise(
            W, H, self.camera.intrinsics.fx_px, seed=self.world.seed, rgb_std=s.rgb_noise_std
        )
        self.q = np.array([v for r in ARM_ROLES for v in HOME_RAD[r]], float)
        self.qd = np.zeros(len(JOINTS))
        self.k = 0
        self.frames = 0
        self.stamper = Stamper("sim")
        self.counters: dict[str, int] = dict.fromkeys(SimCounters.model_fields, 0)
        self.pending: list[Ev] = []
        self.command: tuple[int, np.ndarray] | None = None
        self.cut_requested = False
        self.shears_open = True
        self.contacts: dict[tuple[str, str], int] = {}
        self.felt: list[tuple[str, tuple[float, float, float]]] = []  # (link, point): sensed
        self.clamped_last: list[str] = []
        self.physics.set_robot(self.q, self.qd)

    # ---- SourceCore ------------------------------------------------------------------------
    def done(self) -> bool:
        d = self.s.duration_s
        return d is not None and self.now_ns() >= round(d * 1e9)

    def now_ns(self) -> int:
        return self.k * self.s.control_period_ns

    def emit(self) -> list[list[Output]]:
        stamp = self.now_ns()
        groups: list[list[Output]] = []
        if self.k % self.s.camera_every_ticks == 0:
            groups.append(self.camera_group(stamp))
        outs: list[Output] = [("robot/joint_state", self.joint_state(stamp))]
        if self.k % self.s.camera_every_ticks == 0:
            outs.append(("robot/basket", self.basket(stamp)))
        outs += [("sim/events", self._event(e, stamp)) for e in self.pending]
        self.pending.clear()
        groups.append(outs)
        return groups

    def handle(self, topic: str, msg: Any) -> list[Output]:
        late = self._late(msg.header.stamp_ns)
        if late:
            self.counters["commands_late"] += 1
            return [("sim/events", self._event(Ev("command_late", detail=f"{topic}: {late}")))]
        try:
            if topic == "robot/command":
                self._take_command(msg)
            elif topic == "robot/tool":
                self._take_tool(msg)
        except CommandRejected as exc:
            self.counters["commands_rejected"] += 1
            log.warning("rejected %s seq %d: %s", topic, msg.header.seq, exc)
            return [("sim/events", self._event(Ev("command_rejected", detail=f"{topic}: {exc}")))]
        return []

    def advance(self) -> None:
        period = self.s.control_period_ns
        cmd = self.command
        if cmd is not None and self.now_ns() - cmd[0] <= self.s.command_max_age_ticks * period:
            self.counters["commands_applied"] += 1
            c = clamp(cmd[1], self.q, self.dt)
            self._note_clamp(c.joints, c.detail)
            qd = c.qd
        else:
            self.counters["ticks_without_command"] += 1
            qd = np.zeros(len(JOINTS))
        self.physics.set_robot(self.q, qd)
        if self.cut_requested:
            self.cut_requested = False
            tip, _ = self.physics.frame("cutter_tip")
            evs = self.fruits.cut(tip, self.s.cut_tolerance_m)
            self.counters["cuts" if evs[0].kind == "cut" else "cuts_missed"] += 1
            self.pending += evs
        self.fruits.script((self.k + 1) * self.dt)
        self.physics.step()
        self.q = self.q + qd * self.dt
        self.qd = qd
        # Hold pybullet at the published state: motors drift by ~1e-9 rad during a step, and
        # frames, truth and the cache must see exactly the joint state that is published.
        self.physics.set_robot(self.q, self.qd)
        self.pending += self.fruits.after_step()
        self._count_contacts()
        self.k += 1

    def close(self) -> None:
        self.physics.close()

    # ---- inputs ----------------------------------------------------------------------------
    def _late(self, stamp_ns: int) -> str:
        now, period = self.now_ns(), self.s.control_period_ns
        if stamp_ns > now:
            return f"stamp {stamp_ns} ns is ahead of the sim ({now} ns)"
        if now - stamp_ns > self.s.command_max_age_ticks * period:
            return f"for the tick at {stamp_ns} ns, which has passed (now {now} ns)"
        return ""

    def _take_command(self, msg: JointVelocityCommand) -> None:
        self.command = (msg.header.stamp_ns, command_velocities(msg))

    def _take_tool(self, msg: ToolCommand) -> None:
        if msg.tool != "cutter":
            raise CommandRejected(f"the {msg.tool} has no shears ({msg.action!r} ignored)")
        if msg.action == "cut":
            self.cut_requested = True
            self.shears_open = False
        else:
            self.shears_open = True

    def _note_clamp(self, joints: list[str], detail: str) -> None:
        if joints:
            self.counters["commands_clamped"] += 1
            if joints != self.clamped_last:
                self.pending.append(Ev("clamped", body_a=",".join(joints), detail=detail))
        self.clamped_last = joints

    def _count_contacts(self) -> None:
        bodies = self.physics.tree_bodies | self.fruits.attached_bodies()
        names = self.physics.names
        pairs = {k: p for k, p in self.physics.robot_contact_pairs().items() if k[1] in bodies}
        points = {k: on_link for k, (on_link, _) in pairs.items()}
        on_other = {(link, names[b]): p for (link, b), (_, p) in pairs.items()}
        now = set(on_other)
        # What the arms feel (JointState.contacts): one point per link and body, in link order.
        self.felt = [(k[0], points[k]) for k in sorted(points, key=lambda k: (k[0], names[k[1]]))]
        for pair in sorted(now - set(self.contacts)):
            self.counters["contacts"] += 1
            self.pending.append(Ev("collision", None, pair[0], pair[1], began(on_other[pair])))
        for pair in sorted(set(self.contacts) - now):
            n = self.contacts.pop(pair)
            self.pending.append(
                Ev("collision", None, pair[0], pair[1], f"contact ended after {n} ticks")
            )
        for pair in now:
            self.contacts[pair] = self.contacts.get(pair, 0) + 1
        if now:
            self.counters["contact_ticks"] += 1

    # ---- outputs ---------------------------------------------------------------------------
    def _event(self, e: Ev, stamp: int | None = None) -> SimEvent:
        h = self.stamper.header("sim/events", self.now_ns() if stamp is None else stamp, "world")
        return SimEvent(
            header=h,
            kind=e.kind,  # type: ignore[arg-type]
            fruit_id=e.fruit_id,
            body_a=e.body_a,
            body_b=e.body_b,
            detail=e.detail,
        )

    def joint_state(self, stamp: int) -> JointState:
        arms = {}
        for i, role in enumerate(ARM_ROLES):
            sl = slice(7 * i, 7 * i + 7)
            arms[role] = ArmJointState(
                names=joint_names(role),
                position_rad=tuple(float(v) for v in self.q[sl]),
                velocity_rad_s=tuple(float(v) for v in self.qd[sl]),
            )
        felt = self.felt if self.s.contact_sensing else []
        return JointState(
            header=self.stamper.header("robot/joint_state", stamp),
            arms=arms,
            contacts=tuple(SensedContact(link=link, point_world_m=p) for link, p in felt),
        )

    def basket(self, stamp: int) -> BasketState:
        """The collecting tool's load cell (a robot-side sensor, unlike sim/truth)."""
        return BasketState(
            header=self.stamper.header("robot/basket", stamp, "basket_center"),
            load_kg=self.fruits.basket_load_kg(),
            fruit_count=self.fruits.settled_in_basket,
        )

    def scene_objects(self) -> list[RenderObject]:
        """Everything to draw at the current tick."""
        t = self.k * self.dt
        objs = list(self.static_objects)
        offsets = self.timeline.leaf_offsets(t)
        if offsets:
            split = {o.key: o for o in sway_objects(self.world, offsets, self.k)}
            objs = [split.pop(o.key, o) for o in objs] + list(split.values())
        for st in self.fruits.all:
            if not st.removed:
                objs += fruit_objects(
                    st.fruit, st.pos, st.quat, st.state == "attached", st.stem_top, self.world.seed
                )
        objs += self.robot_vis.objects(self.physics.link_poses(self.robot_vis.links))
        hand = self.timeline.hand(t, self.fruits.positions())
        if hand is not None:
            objs += hand_objects(hand[0], hand[1], self.k)
        return objs

    def camera_group(self, stamp: int) -> list[Output]:
        out = self.renderer.render(self.scene_objects())
        frame_no = self.frames
        self.frames += 1
        rgb = self.noise.rgb(out.rgb, frame_no)
        if self.s.depth_noise:
            depth = self.noise.depth_mm(out.depth_m, out.rgb, frame_no)
        else:
            depth = np.clip(np.round(out.depth_m * 1000), 0, 65535).astype(np.uint16)
        T = self.T_world_camera
        meta = RgbdFrameMeta(
            header=self.stamper.header("camera/rgbd", stamp, CAMERA_FRAME_ID),
            intrinsics=self.camera.intrinsics,
            T_world_camera=Pose(
                position_m=(float(T[0, 3]), float(T[1, 3]), float(T[2, 3])),
                orientation_xyzw=tuple(float(v) for v in quat_of(T[:3, :3])),  # type: ignore[arg-type]
            ),
        )
        return [
            ("camera/rgbd", RgbdFrame(meta, np.ascontiguousarray(rgb), depth)),
            ("sim/truth", self.truth(stamp, meta.header.seq, out)),
        ]

    def truth(self, stamp: int, frame_seq: int, out: Any) -> GroundTruth:
        fruits = []
        for st in self.fruits.all:
            fm = None if st.removed else out.fruits.get(st.fruit.fruit_id)
            fruits.append(
                fruit_truth(
                    st.fruit.fruit_id,
                    st.pos,
                    st.quat,
                    st.fruit.semi_axes,
                    st.peduncle()[0],
                    st.state,  # type: ignore[arg-type]
                    fruit_pixels(out, fm),
                )
            )
        hand = self.renderer.index_of("hand")
        tr = self.world.trunk
        return GroundTruth(
            header=self.stamper.header("sim/truth", stamp, "world"),
            frame_seq=frame_seq,
            fruits=tuple(fruits),
            trunk=TrunkTruth(
                axis_point_world_m=(float(tr.p0[0]), float(tr.p0[1]), 0.0), radius_m=tr.radius
            ),
            occluder_active=hand is not None and bool((out.label == hand).any()),
            robot_contacts=tuple(sorted(self.contacts)),
            counters=SimCounters(**self.counters),
        )
