"""Pure core of the scene estimator: joins each Tracks message to its RGB-D frame, measures the
fruit and the trunk, keeps the persistent list, and answers with exactly one SceneState.

Frames (camera/rgbd) wait in a small buffer keyed by seq; a Tracks message names its frame by
``frame_seq`` and the stamps must match. Order across keys is not guaranteed (with
zenoh-python's default of one delivery thread per subscriber, a small Tracks message was seen
to overtake the 1.5 MB frame it was made from in a resim). A Tracks message newer than every
frame received so far therefore waits for its frame and is answered when it comes, so the
answer does not depend on that race. A Tracks message whose
frame will not come (a newer frame arrived, or it is older than the newest frame and not in
the buffer) is answered at once: the last state, unchanged, ``input_problem`` saying why
(counted). At most ``frame_buffer`` Tracks messages wait; past that the oldest is answered so.

The robot self-filter (``robot_self_filter``) needs where the arms were when the frame was
taken: the last joint state *before* the frame's stamp (at most ``joint_state_max_lag_ms``
older). Not the one at the frame's stamp: in lock-step the sim publishes that one only after
the frame's answers are in, this one among them (waiting for it would dead-lock). Once a joint
state has been received, a Tracks message waits until that joint state is in (another key: it
could in principle arrive late), so the answer never depends on delivery order. Estimates
inside the arms' capsules are dropped and counted (``fruit_on_robot``).
"""

from __future__ import annotations

import dataclasses
import logging
from collections import Counter, OrderedDict, deque
from typing import Any

import numpy as np

from schemas.camera import RgbdFrame
from schemas.harvest import HarvestEvent
from schemas.perception import Tracks
from schemas.robot import JointState
from schemas.scene import Fruit, FruitFlag, SceneState, SphereObstacle, Trunk
from services.robot.clearance import Capsule, RobotBody, axis_distances_m, inner_working_space
from services.runtime import ConfigError, Output, Stamper
from services.scene import Settings
from services.scene.fruit3d import EstimateFailure, FruitEstimate, FruitParams, estimate_fruit
from services.scene.fruit_list import Entry, FruitList, ListParams, Measurement
from services.scene.geometry import Pinhole, PoseError, RigidTransform, vec3
from services.scene.obstacles import build_obstacles, trunk_radius_m
from services.scene.occupancy import OccupancyGrid, OccupancyParams
from services.scene.touched import TouchedParams, TouchedSpace
from services.scene.trunk import TrunkFailure, TrunkParams, measure_trunk
from services.scene.trunk_track import TrackParams, TrunkTrack

log = logging.getLogger("scene")
TOPIC_OUT = "scene/state"
RATIO_HISTORY = 15  # whole-box views whose median d_v/d_h a fruit keeps
HARVESTED_EVENTS = ("fruit_collected", "fruit_dropped")
TARGET_ENDS = (*HARVESTED_EVENTS, "fruit_skipped", "fruit_lost")
# Unseen-fruit voxels centred this near the robot's capsules are the robot (fruit-coloured
# arms and dish; the centres measured 0-5 mm off the capsules, orchard seed 13): forgotten.
UNSEEN_FORGET_IN_ROBOT_M = 0.01
# a near sphere this close to one shown in the last state is that one (a felt place's centre
# drifts by 1-2 mm as points are added; two voxels' centres are a voxel apart, 2-3 cm)
NEAR_SAME_M = 0.01
JOINT_BUFFER = 256  # joint states kept (120 Hz: ~2 s, the frame buffer's span at 15 Hz and more)


class SceneCore:
    def __init__(self, s: Settings) -> None:
        from services.vision.trunk_mask import HsvBox

        try:
            self.trunk_hsv = HsvBox(s.trunk_hsv_low, s.trunk_hsv_high)
            self.fruit_hsv = HsvBox(s.fruit_hsv_low, s.fruit_hsv_high)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        if s.min_semi_axis_m >= s.max_semi_axis_m:
            raise ConfigError("min_semi_axis_m must be below max_semi_axis_m")
        if s.trunk_min_radius_m >= s.trunk_max_radius_m:
            raise ConfigError("trunk_min_radius_m must be below trunk_max_radius_m")
        self.s = s
        self.fruit_params = FruitParams(
            method=s.fruit_method,
            central_fraction=s.central_fraction,
            paper_window_px=s.paper_window_px,
            min_pixels=s.min_depth_pixels,
            min_support_share=s.min_support_share,
            border_margin_px=s.border_margin_px,
            edge_strip_px=s.edge_strip_px,
            occluder_margin_m=s.occluder_margin_m,
            min_semi_axis_m=s.min_semi_axis_m,
            max_semi_axis_m=s.max_semi_axis_m,
            fruit_hsv_low=s.fruit_hsv_low,
            fruit_hsv_high=s.fruit_hsv_high,
            min_colour_share=s.min_colour_share,
            refine_box=s.refine_box,
            refine_keeps_holes=s.refine_keeps_holes,
            shape_tolerance=s.misfit_tie_shape_tolerance,
            corner_fit=s.corner_fit,
        )
        self.trunk_params = TrunkParams(
            method=s.trunk_method,
            min_pixels=s.trunk_min_pixels,
            min_radius_m=s.trunk_min_radius_m,
            max_radius_m=s.trunk_max_radius_m,
            min_height_m=s.trunk_min_height_m,
        )
        self.fruits = FruitList(
            ListParams(s.update_threshold_m, s.forget_after_frames, s.accept_jump_frames)
        )
        self.trunk = TrunkTrack(
            TrackParams(
                s.trunk_smoothing,
                s.trunk_gate_m,
                s.trunk_reacquire_frames,
                s.trunk_forget_after_frames,
            )
        )
        params = OccupancyParams(
            voxel_m=s.occupancy_voxel_m,
            sphere_radius_m=s.occupancy_sphere_radius_m,
            stride_px=s.occupancy_stride_px,
            max_depth_m=s.occupancy_max_depth_m,
            min_points=s.occupancy_min_points,
            robot_margin_m=s.occupancy_robot_margin_m,
            clear_frames=s.occupancy_clear_frames,
            clear_margin_m=s.occupancy_clear_margin_m,
            forget_after_frames=s.occupancy_forget_after_frames,
            max_obstacles=s.occupancy_max_obstacles,
            history_frames=s.occupancy_history_frames,
            history_every_frames=s.occupancy_history_every_frames,
            history_long_frames=s.occupancy_history_long_frames,
            transient_forget_frames=s.occupancy_transient_forget_frames,
            settle_hits=s.occupancy_settle_hits,
            blank_frames=s.occupancy_blank_frames,
        )
        self.occupancy = OccupancyGrid(params) if s.occupancy else None
        self.touched = (
            TouchedSpace(TouchedParams(s.contact_voxel_m, s.contact_sphere_radius_m))
            if s.contact_obstacles
            else None
        )
        self.unseen = (
            OccupancyGrid(
                dataclasses.replace(
                    params,
                    max_obstacles=s.occupancy_unseen_fruit_max_obstacles,
                    forget_in_robot_m=UNSEEN_FORGET_IN_ROBOT_M,
                ),
                prefix="unseen_fruit_",
            )
            if s.occupancy and s.occupancy_unseen_fruit
            else None
        )
        self.target: int | None = None  # the planner's current fruit (harvest/events)
        # the near spheres shown in the last state: for which selected fruit, their centres
        self.near_shown: tuple[int | None, np.ndarray] = (None, np.empty((0, 3)))
        self.cut_entry: Entry | None = None  # the target as it hung when the cut was sent
        self.body = RobotBody() if s.robot_self_filter else None
        self.joints: OrderedDict[int, JointState] = OrderedDict()  # stamp → joint state
        self.newest_joint_ns: int | None = None
        self.joint_lag_ns = round(s.joint_state_max_lag_ms * 1e6)
        self.frames: OrderedDict[int, RgbdFrame] = OrderedDict()
        self.newest_frame_ns: int | None = None
        self.waiting: list[Tracks] = []  # Tracks newer than every frame received so far
        self.ratios: dict[int, deque[float]] = {}
        self.T: RigidTransform | None = None  # the last frame's pose
        self.trunk_pixels = 0
        self.counters: Counter[str] = Counter()
        self.stamper = Stamper("scene")

    # ---- inputs --------------------------------------------------------------------------------
    def handle(self, topic: str, msg: Any) -> list[Output]:
        if topic == "camera/rgbd":
            self._keep_frame(msg)
        elif topic == "robot/joint_state":
            if self.touched is not None and msg.contacts:
                self._feel(msg)
            if self.body is None:
                return []
            self._keep_joints(msg)
        elif topic == "harvest/events":
            self._take_event(msg)
            return []
        elif topic == "perception/tracks":
            self.waiting.append(msg)
            if not self._ready(msg):
                self.counters["tracks_before_frame"] += 1
        else:
            return []
        return self._release()

    def _ready(self, t: Tracks) -> bool:
        """Its frame (and the joint state of its stamp) is in, or a newer one says it will not
        come."""
        stamp = t.header.stamp_ns
        if self.newest_frame_ns is None or stamp > self.newest_frame_ns:
            return False
        return self.newest_joint_ns is None or stamp - self.joint_lag_ns <= self.newest_joint_ns

    def _release(self) -> list[Output]:
        """Answer the waiting Tracks messages that are due, in arrival order; past
        ``frame_buffer`` waiting, the oldest is answered anyway (with what there is)."""
        out: list[Output] = []
        while self.waiting and (
            self._ready(self.waiting[0]) or len(self.waiting) > self.s.frame_buffer
        ):
            out.append((TOPIC_OUT, self._answer(self.waiting.pop(0))))
        return out

    def _keep_joints(self, js: JointState) -> None:
        stamp = js.header.stamp_ns
        self.joints[stamp] = js
        self.joints.move_to_end(stamp)
        self.newest_joint_ns = (
            stamp if self.newest_joint_ns is None else max(self.newest_joint_ns, stamp)
        )
        while len(self.joints) > JOINT_BUFFER:
            self.joints.popitem(last=False)

    def _keep_frame(self, frame: RgbdFrame) -> None:
        self.frames[frame.header.seq] = frame
        self.frames.move_to_end(frame.header.seq)
        self.newest_frame_ns = frame.header.stamp_ns
        while len(self.frames) > self.s.frame_buffer:
            self.frames.popitem(last=False)

    def _feel(self, js: JointState) -> None:
        """Keep the contacts the arms felt, but those on the selected fruit (touched on
        purpose: the shears at its peduncle, the dish under it), with the fruit the planner
        works on (none between attempts)."""
        assert self.touched is not None
        inner = self._inner_space(self._selected())
        worked_on = self.cut_entry.fruit_id if self.cut_entry is not None else self.target
        self.counters["contacts_felt"] += len(js.contacts)
        self.counters["contacts_kept"] += self.touched.feel(
            js.contacts, js.header.stamp_ns, inner, worked_on
        )

    def _inner_space(self, selected: Entry | None) -> list[Capsule]:
        """The selected fruit's inner working space: round it and up its twig (the keep-out's
        inner part, ``occupancy_inner_clearance_m``), as capsules; none without a selection."""
        if selected is None:
            return []
        st = selected.state
        return [
            inner_working_space(
                st.position_world_m,
                st.semi_axis_v_m,
                self.s.occupancy_inner_clearance_m,
                self.s.occupancy_inner_twig_m,
            )
        ]

    def _selected(self) -> Entry | None:
        """The fruit the tools work on: as it hung at the cut, or the planner's target."""
        if self.cut_entry is not None:
            return self.cut_entry
        sid = self.fruits.selected(self.target)
        return self.fruits.entries.get(sid) if sid is not None else None

    def _forget_felt(self, ev: HarvestEvent) -> None:
        """A fruit harvested: what the arms felt on it is gone with it."""
        if self.touched is None or ev.event not in HARVESTED_EVENTS or ev.fruit_id is None:
            return
        e = self.cut_entry if self.cut_entry is not None else self.fruits.entries.get(ev.fruit_id)
        if e is not None:
            radius_m = e.state.semi_axis_v_m + self.s.occupancy_inner_clearance_m
            self.counters["contacts_forgotten"] += self.touched.forget_within(
                e.state.position_world_m, radius_m
            )

    def _take_event(self, ev: HarvestEvent) -> None:
        self._forget_felt(ev)
        if ev.event == "run_finished":
            self.target, self.cut_entry = None, None
        if ev.fruit_id is None:
            return
        # The obstacle radius is the paper's for the fruit being harvested: follow the planner's
        # target (its order may differ from nearest-first), across its ID switches.
        if ev.event == "fruit_selected" or (ev.event == "replanned" and self.target is not None):
            self.target = ev.fruit_id
            self.fruits.unmark(ev.fruit_id)
        elif ev.fruit_id == self.target and ev.event in (
            *HARVESTED_EVENTS,
            "fruit_skipped",
            "fruit_lost",
        ):
            self.target = None
        self._freeze_at_cut(ev)
        if ev.event in HARVESTED_EVENTS:
            self.fruits.mark(ev.fruit_id, "harvested")
            self.counters["mark_harvested"] += 1
        elif ev.event == "fruit_skipped" and ev.outcome == "unreachable":
            self.fruits.mark(ev.fruit_id, "unreachable")
            self.counters["mark_unreachable"] += 1
        elif ev.event == "fruit_skipped" and ev.outcome is None:
            # Deferred: still to do for the planner, so a mark on the ID was another fruit's or
            # a verdict withdrawn (a fruit reported dropped, seen on its branch again): it
            # hangs there, an obstacle and a candidate.
            self.fruits.unmark(ev.fruit_id)

    # ---- one Tracks message ------------------------------------------------------------------
    def _answer(self, tracks: Tracks) -> SceneState:
        frame = self.frames.get(tracks.frame_seq)
        problem = ""
        if frame is None or frame.header.stamp_ns != tracks.header.stamp_ns:
            self.counters["frame_not_received"] += 1
            held = ", ".join(str(k) for k in self.frames) or "none"
            problem = (
                f"frame seq {tracks.frame_seq} at {tracks.header.stamp_ns} ns was not received "
                f"(frames held: {held}); the last state is kept"
            )
        else:
            try:
                T = RigidTransform.of(frame.meta.T_world_camera)
            except PoseError as exc:
                self.counters["frame_pose_invalid"] += 1
                problem = f"frame seq {tracks.frame_seq}: {exc}; the last state is kept"
            else:
                self.T = T
                self._measure(tracks, frame, T)
        if problem:
            log.warning("%s", problem)
        return self._state(tracks, problem)

    def _measure(self, tracks: Tracks, frame: RgbdFrame, T: RigidTransform) -> None:
        import cv2

        K = Pinhole.of(frame.meta.intrinsics)
        depth_m = frame.depth_m()
        hsv = cv2.cvtColor(np.ascontiguousarray(frame.rgb), cv2.COLOR_RGB2HSV)
        measured: dict[int, Measurement] = {}
        failed: dict[int, FruitFlag] = {}
        robot_all = self._robot_at(frame.header.stamp_ns)
        # The dish's sphere left out for fruit: a fruit in the dish is the planner's to judge.
        robot = robot_all[:-1]
        for tr in tracks.tracks:
            if not (tr.confirmed or self.s.accept_tentative):
                self.counters["track_tentative"] += 1
                continue
            if not tr.matched:  # a coasting track's box is a prediction, not a detection
                self.counters["track_coasting"] += 1
                continue
            v_over_h, shape_known = self._v_over_h(tr.track_id)
            est = estimate_fruit(
                tr.xyxy_px, depth_m, hsv, K, self.fruit_params, v_over_h, shape_known
            )
            if isinstance(est, EstimateFailure):
                self.counters[f"fruit_{est.reason}"] += 1
                failed[tr.track_id] = _failure_flag(est)
                continue
            if self._keep_whole_view(tr.track_id, est):
                # A side cut (an arm or a hand passing, leaves) while a whole view of this fruit
                # is stored: the whole view is the better estimate (a cut view guesses the
                # missing semi-axis; during a harvest the arms cut every neighbour's box).
                self.counters["fruit_cut_view_keep_state"] += 1
                failed[tr.track_id] = "border_cut" if any(est.sides.border) else "edge_occluded"
                continue
            if not est.sides.whole_pair and tr.track_id in self.fruits.entries:
                # Cut on two adjacent sides (a corner): the box no longer fixes the shape; a
                # fruit already measured keeps its state rather than take a guess.
                self.counters["fruit_box_cut_keep_state"] += 1
                failed[tr.track_id] = "border_cut" if any(est.sides.border) else "edge_occluded"
                continue
            m = self._measurement(tr.track_id, est, T)
            if robot and self._on_robot(m, robot):
                self.counters["fruit_on_robot"] += 1
                continue
            measured[tr.track_id] = m
        for note in self.fruits.step(tracks.header.stamp_ns, measured, failed):
            log.debug("%s", note)
        self._unmark_moved_harvested(robot_all)
        for fid in [k for k in self.ratios if k not in self.fruits.entries]:
            del self.ratios[fid]
        mask = self._measure_trunk(frame, depth_m, K, T)
        if self.occupancy is not None:
            # Bark-coloured points are the trunk and the branches (the trunk's own mask).
            self.occupancy.step(mask, depth_m, K, T, robot_all)
        if self.unseen is not None:
            fruit = self.fruit_hsv.mask(hsv)
            if self.body is not None and not robot_all:
                # The arms and the dish are fruit-coloured: unfiltered, they would be fruit.
                self.counters["unseen_fruit_frame_unfiltered"] += 1
                fruit = np.zeros_like(fruit)
            self.unseen.step(fruit, depth_m, K, T, robot_all, self._explained())

    def _explained(self) -> tuple[np.ndarray, np.ndarray]:
        """The fruit estimates as spheres (centres, radii; m) that explain fruit-coloured
        points: every entry but the harvested (off the tree; the dish's sphere filters them)."""
        _ids, centres, radii = self._fruit_spheres()
        return centres, radii

    def _fruit_spheres(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The fruit on the tree (every entry but the harvested) as IDs and spheres (centres,
        radii: the largest semi-axis plus occupancy_unseen_fruit_margin_m; m): what lies in
        one is that fruit (a fruit-coloured point, a place felt)."""
        es = [
            e
            for e in self.fruits.entries.values()
            if self.fruits.marks.get(e.fruit_id) != "harvested"
        ]
        ids = np.array([e.fruit_id for e in es], dtype=int)
        centres = np.array([e.state.position_world_m for e in es], dtype=float).reshape(-1, 3)
        radii = np.array(
            [max(e.state.semi_axis_h_m, e.state.semi_axis_v_m) for e in es], dtype=float
        )
        return ids, centres, radii + self.s.occupancy_unseen_fruit_margin_m

    def _measurement(self, fid: int, est: FruitEstimate, T: RigidTransform) -> Measurement:
        flags: list[FruitFlag] = []
        if any(est.sides.border):
            flags.append("border_cut")
            self.counters["fruit_border_cut"] += 1
        if not all(g or b for g, b in zip(est.sides.good, est.sides.border, strict=True)):
            flags.append("edge_occluded")
        if est.sides.all_good:
            self.ratios.setdefault(fid, deque(maxlen=RATIO_HISTORY)).append(est.v_over_h)
        return Measurement(
            est.position_cam_m,
            T.to_world(est.position_cam_m),
            est.semi_axis_h_m,
            est.semi_axis_v_m,
            tuple(flags),
        )

    def _robot_at(self, stamp_ns: int) -> tuple[Capsule, ...]:
        """The arms', tools' and dish's capsules just before the frame's stamp (the dish's sphere
        last); () without a joint state for it."""
        if self.body is None or self.newest_joint_ns is None:
            return ()
        before = [k for k in self.joints if stamp_ns - self.joint_lag_ns <= k < stamp_ns]
        js = self.joints[max(before)] if before else None
        if js is None:
            self.counters["joint_state_missing"] += 1
            return ()
        q = {role: arm.position_rad for role, arm in js.arms.items()}
        try:
            return self.body.capsules(q)
        except (KeyError, ValueError) as exc:
            self.counters["joint_state_invalid"] += 1
            log.warning("joint state at %d ns: %s; no self-filter for this frame", stamp_ns, exc)
            return ()

    def _unmark_moved_harvested(self, robot: tuple[Capsule, ...]) -> None:
        """A harvested fruit's ID whose move the list took (confirmed by consecutive views) is
        on another fruit: a harvested fruit hangs nowhere else on the tree. Its mark was the
        old fruit's; kept, it hid the new fruit from the dampers (orchard seed 10: track 7 went
        from a harvested fruit to one 18 cm away, and a cutter link pressed on it for 2.9 s).
        A move into our dish is the harvested fruit itself: the mark stays, and also when the
        dish is unknown (no joint state for the frame). Opt-in (``unmark_moved_harvested``)."""
        if not self.s.unmark_moved_harvested:
            return
        for fid in self.fruits.moved:
            if self.fruits.marks.get(fid) != "harvested":
                continue
            e = self.fruits.entries[fid]
            if not robot or self._in_dish(e.state, robot[-1]):
                continue
            self.fruits.unmark(fid)
            self.counters["harvested_id_moved_on"] += 1
            log.info("fruit %d: a harvested fruit's ID moved to another fruit; unmarked", fid)

    @staticmethod
    def _in_dish(m: Measurement, dish: Capsule) -> bool:
        """The fruit's centre within the dish's sphere grown by its horizontal semi-axis."""
        return bool(axis_distances_m(m.position_world_m, (dish,))[0] < dish[2] + m.semi_axis_h_m)

    def _on_robot(self, m: Measurement, robot: tuple[Capsule, ...]) -> bool:
        radii = np.array([r for _a, _b, r in robot])
        reach = radii + self.s.self_filter_share * m.semi_axis_h_m
        return bool((axis_distances_m(m.position_world_m, robot) < reach).any())

    def _keep_whole_view(self, fid: int, est: FruitEstimate) -> bool:
        """A cut view of a fruit whose whole view is stored (it has whole-view ratios and the
        stored state came from one)."""
        e = self.fruits.entries.get(fid)
        return (
            self.s.prefer_whole_views
            and not est.sides.all_good
            and e is not None
            and fid in self.ratios
            and not e.state.flags
        )

    def _v_over_h(self, fid: int) -> tuple[float, bool]:
        """d_v/d_h for a cut box, and whether it was measured: the fruit's own (median of its
        whole views), else the median of the fruit seen whole in this scene (fruit of one tree
        share a shape: a fixed prior of 1.0 made oblate oranges ~6 % too narrow and so too
        near), else the prior (not measured)."""
        r = self.ratios.get(fid)
        if r:
            return float(np.median(r)), True
        need = self.s.v_over_h_population_min_fruit
        if need > 0 and len(self.ratios) >= need:
            return float(np.median([np.median(v) for v in self.ratios.values()])), True
        return self.s.v_over_h_prior, False

    def _measure_trunk(
        self, frame: RgbdFrame, depth_m: np.ndarray, K: Pinhole, T: RigidTransform
    ) -> np.ndarray:
        """Update the trunk; returns this frame's bark mask (H, W) bool."""
        from services.vision.trunk_mask import trunk_mask

        mask = trunk_mask(frame, self.s.trunk_max_depth_m, self.trunk_hsv)
        fix = measure_trunk(mask, depth_m, K, T, self.trunk_params)
        self.trunk_pixels = int(mask.sum())
        if isinstance(fix, TrunkFailure):
            self.counters[fix.reason] += 1
        note = self.trunk.step(fix)
        if note:
            log.info("%s", note)
        return mask

    def _freeze_at_cut(self, ev: HarvestEvent) -> None:
        """From the cut to the end of the attempt the target's working space (keep-out sphere,
        trunk radius) stays where the fruit hung, as the planner's frozen target does: the
        estimate follows the falling fruit into the dish, and a trunk obstacle resized for
        it pushed the dish 16 mm aside while the fruit settled (orchard seed 18). A retry
        (``replanned``) re-aims at the fruit as seen then."""
        if ev.event == "cut_sent" and self.target is not None and ev.fruit_id == self.target:
            e = self.fruits.entries.get(self.target)
            self.cut_entry = dataclasses.replace(e) if e is not None else None
        elif self.cut_entry is not None and (
            ev.event == "replanned" or self.cut_entry.fruit_id != self.target
        ):
            self.cut_entry = None  # a retry, or the attempt ended (the target changed or None)

    # ---- output --------------------------------------------------------------------------------
    def _state(self, tracks: Tracks, problem: str) -> SceneState:
        entries = self.fruits.sorted_entries()
        if self.cut_entry is not None:
            selected_id: int | None = self.cut_entry.fruit_id
        else:
            selected_id = self.fruits.selected(self.target)
        selected = self._selected()
        fruits = tuple(self._fruit(e, selected_id) for e in entries)
        harvested = {k for k, m in self.fruits.marks.items() if m == "harvested"}
        obstacles = build_obstacles(
            entries,
            harvested,
            self.trunk.state,
            selected,
            self.s.trunk_default_radius_m,
            self.s.trunk_tool_margin_m,
        )
        near: tuple[SphereObstacle, ...] = ()
        if self.occupancy is not None or self.touched is not None:
            keep_out = self._keep_out(selected)
            grids = [g for g in (self.occupancy, self.unseen) if g is not None]
            near = tuple(sp for g in grids for sp in g.within(*keep_out))
            spheres = tuple(sp for g in grids for sp in g.obstacles(*keep_out))
            if self.touched is not None:
                on = self._fruit_spheres()
                near += self.touched.within(*keep_out, fruits=on)
                spheres += self.touched.obstacles(*keep_out, fruits=on)
            spheres += self._near_shown(selected, near)
            obstacles = obstacles.model_copy(update={"spheres": spheres})
        return SceneState(
            header=self.stamper.answer(TOPIC_OUT, tracks.header, frame_id="world"),
            fruits=fruits,
            trunk=self._trunk(),
            obstacles=obstacles,
            selected_fruit_id=selected_id,
            spheres_near_selected=near,
            input_problem=problem,
        )

    def _keep_out(
        self, selected: Entry | None
    ) -> tuple[list[Capsule], tuple[np.ndarray, float] | None]:
        """Where no occupied sphere may be: around the selected fruit (its working space) and
        inside the trunk obstacle (already guarded by its cylinder)."""
        regions: list[Capsule] = []
        if selected is not None:
            st = selected.state
            centre = st.position_world_m
            # towards the camera along its optical axis: where the tools come from
            assert self.T is not None  # an entry exists only after a frame was used
            front = centre - self.T.R[:, 2] * self.s.occupancy_target_corridor_m
            regions.append((centre, front, st.semi_axis_v_m + self.s.occupancy_target_clearance_m))
        trunk = self.trunk.state
        cylinder = None
        if trunk is not None:
            r_obs, _own = trunk_radius_m(
                trunk, selected, self.s.trunk_default_radius_m, self.s.trunk_tool_margin_m
            )
            cylinder = (trunk.axis_world_m, r_obs)
        return regions, cylinder

    def _near_shown(
        self, selected: Entry | None, near: tuple[SphereObstacle, ...]
    ) -> tuple[SphereObstacle, ...]:
        """The keep-out's spheres that the controller still sees (``occupancy_near_radius_m``
        above 0): those outside the inner working space (round the fruit and up its twig), at
        that radius. The branch check keeps ``near`` whole, at full radius."""
        r = self.s.occupancy_near_radius_m
        if r <= 0 or selected is None:
            self.near_shown = (None, np.empty((0, 3)))
            return ()
        inner = self._inner_space(selected)
        inner_m = inner[0][2]
        hold_m = self.s.occupancy_near_hold_m
        shown_id, before = self.near_shown
        if shown_id != selected.fruit_id:
            before = np.empty((0, 3))
        shown: list[SphereObstacle] = []
        # the occupancy grid's own keep-out test (a sphere's surface within the capsule), on
        # the spheres already found near rather than a second pass over the whole grid; one
        # shown last time only leaves once hold_m inside (the edge moves with the estimate)
        for sp in near:
            c = np.array(sp.center_world_m)
            outside_m = axis_distances_m(c, inner)[0] - inner_m - sp.radius_m
            if outside_m >= 0 or (outside_m >= -hold_m and _among(c, before, NEAR_SAME_M)):
                shown.append(sp.model_copy(update={"radius_m": r}))
        centres = np.array([sp.center_world_m for sp in shown], float).reshape(-1, 3)
        self.near_shown = (selected.fruit_id, centres)
        return tuple(shown)

    def _to_cam(self, p_world: np.ndarray) -> np.ndarray:
        assert self.T is not None  # an entry or a trunk exists only after a frame was used
        return (p_world - self.T.t_m) @ self.T.R

    def _fruit(self, e: Entry, selected_id: int | None) -> Fruit:
        mark = self.fruits.marks.get(e.fruit_id)
        status = mark or ("selected" if e.fruit_id == selected_id else "candidate")
        p_cam = self._to_cam(e.state.position_world_m)
        return Fruit(
            fruit_id=e.fruit_id,
            position_cam_m=vec3(p_cam),
            position_world_m=vec3(e.state.position_world_m),
            semi_axis_h_m=e.state.semi_axis_h_m,
            semi_axis_v_m=e.state.semi_axis_v_m,
            distance_m=float(np.linalg.norm(p_cam)),
            status=status,
            frames_unseen=e.frames_unseen,
            last_seen_stamp_ns=e.last_seen_stamp_ns,
            flags=e.flags,
        )

    def _trunk(self) -> Trunk:
        t = self.trunk.state
        if t is None:
            return Trunk(found=False, pixel_count=self.trunk_pixels)
        return Trunk(
            found=True,
            position_cam_m=vec3(self._to_cam(t.axis_world_m)),
            position_world_m=vec3(t.axis_world_m),
            radius_m=t.radius_m,
            pixel_count=self.trunk_pixels,
            frames_unseen=t.frames_unseen,
        )


def _failure_flag(f: EstimateFailure) -> FruitFlag:
    if f.reason == "depth_invalid":
        return "depth_invalid"
    if f.reason == "depth_inconsistent":
        return "depth_inconsistent"
    return "box_invalid"


def _among(c: np.ndarray, centres: np.ndarray, within_m: float) -> bool:
    """``c`` lies within ``within_m`` of one of ``centres`` (N, 3)."""
    return bool(len(centres)) and float(np.min(np.linalg.norm(centres - c, axis=1))) <= within_m
