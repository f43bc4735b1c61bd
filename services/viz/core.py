"""The conversion core shared by the live service and `harvest view`: (topic, decoded message)
→ Rerun log calls on one recording stream, timed by the message stamps (sim time).

No bus, no files and no wall clock here: the same messages give the same recording, live or
from an MCAP.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable
from typing import Any

from schemas.service import DemoAnswer, DemoTick
from services.viz import Settings, paths, plots
from services.viz.camera import CameraView, RateLimit, log_detections, log_tracks, log_truth_boxes
from services.viz.events import (
    ControlChanges,
    log_harvest_event,
    log_sim_event,
    log_summary,
    log_tool,
)
from services.viz.out import Out
from services.viz.robot import RobotView
from services.viz.scene import SceneView

log = logging.getLogger("viz")

Handler = Callable[[Any], None]


class Converter:
    """Draws every message of the topic map that has a drawing; counts the rest."""

    def __init__(self, out: Out, settings: Settings) -> None:
        self.out, self.s = out, settings
        self.warnings: list[str] = []
        self.robot = RobotView.load(settings.urdf_path, self.warnings)
        for w in self.warnings:
            log.warning("%s", w)
        self.camera = CameraView(
            settings.image_max_rate_hz,
            settings.depth_max_rate_hz,
            settings.image_jpeg_quality,
            settings.trunk_max_depth_m,
        )
        self.scene = SceneView(settings.trunk_draw_height_m, self.robot.tree is not None)
        self._pose_gate = RateLimit(settings.pose_max_rate_hz)
        self._control_changes = ControlChanges()
        self._velocity_names: dict[str, tuple[str, ...]] = {}
        self.drawn: Counter[str] = Counter()
        self.not_drawn: Counter[str] = Counter()
        self.failed: Counter[str] = Counter()
        self._failure_logged: set[str] = set()
        self.handlers: dict[str, Handler] = {
            "camera/rgbd": self._rgbd,
            "perception/detections": self._detections,
            "perception/tracks": self._tracks,
            "scene/state": self._scene,
            "robot/joint_state": self._joint_state,
            "robot/tool": self._at_stamp(log_tool),
            "plan/target": self._at_stamp(self.scene.log_target),
            "control/status": self._control,
            "harvest/events": self._at_stamp(log_harvest_event),
            "harvest/summary": self._at_stamp(log_summary),
            "sim/truth": self._truth,
            "sim/events": self._at_stamp(log_sim_event),
            "demo/tick": self._demo_tick,
            "demo/answer": self._demo_answer,
        }

    def begin(self) -> None:
        """Static content: axes convention, the robot, annotation contexts, series styles."""
        rr = self.out.rr
        self.out.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.robot.log_static(self.out)
        self.camera.log_static(self.out)
        plots.log_static(self.out)

    def handle(self, topic: str, msg: Any) -> bool:
        """Draw one message; False when the topic has no drawing. A failure is counted and
        logged once per topic and kind, never raised (one bad message must not end a view)."""
        fn = self.handlers.get(topic)
        if fn is None:
            self.not_drawn[topic] += 1
            return False
        try:
            fn(msg)
        except Exception as exc:
            self.failed[topic] += 1
            kind = f"{topic}:{type(exc).__name__}"
            if kind not in self._failure_logged:
                self._failure_logged.add(kind)
                log.exception(
                    "could not draw %s seq %s (later ones only counted)",
                    topic,
                    getattr(getattr(msg, "header", None), "seq", "?"),
                )
            return False
        self.drawn[topic] += 1
        return True

    # ---- handlers --------------------------------------------------------------------------
    def _at_stamp(self, fn: Callable[[Out, Any], None]) -> Handler:
        def handler(msg: Any) -> None:
            self.out.at(msg.header.stamp_ns)
            fn(self.out, msg)

        return handler

    def _rgbd(self, frame: Any) -> None:
        self.out.at(frame.meta.header.stamp_ns, frame.meta.header.seq)
        self.camera.log_frame(self.out, frame)

    def _detections(self, msg: Any) -> None:
        self.out.at(msg.header.stamp_ns, msg.header.answers_seq)
        log_detections(self.out, msg)

    def _tracks(self, msg: Any) -> None:
        self.out.at(msg.header.stamp_ns, msg.frame_seq)
        log_tracks(self.out, msg)

    def _truth(self, msg: Any) -> None:
        self.out.at(msg.header.stamp_ns, msg.frame_seq)
        log_truth_boxes(self.out, msg)
        self.scene.log_truth(self.out, msg)

    def _scene(self, msg: Any) -> None:
        self.out.at(msg.header.stamp_ns)
        self.scene.log_scene(self.out, msg)

    def _joint_state(self, msg: Any) -> None:
        if self._pose_gate(msg.header.stamp_ns):
            self.robot.log_joint_state(self.out, msg)
        plots.log_joint_velocities(
            self.out, msg, self.robot.velocity_limits_rad_s, self._velocity_names
        )

    def _control(self, msg: Any) -> None:
        plots.log_control_status(self.out, msg, self.s.d_s_m)
        self.out.at(msg.header.stamp_ns)
        self._control_changes(self.out, msg)

    def _demo_tick(self, msg: DemoTick) -> None:
        self.out.scalars(f"{paths.PLOTS}/demo/value", msg.header.stamp_ns, (msg.value,))

    def _demo_answer(self, msg: DemoAnswer) -> None:
        self.out.scalars(f"{paths.PLOTS}/demo/result", msg.header.stamp_ns, (msg.result,))

    # ---- report ----------------------------------------------------------------------------
    def report(self) -> str:
        """One paragraph: what was drawn, what has no drawing, what failed."""
        lines = [
            "drawn: " + (", ".join(f"{t} {n}" for t, n in sorted(self.drawn.items())) or "nothing")
        ]
        if self.not_drawn:
            lines.append(
                "no drawing for: "
                + ", ".join(f"{t} {n}" for t, n in sorted(self.not_drawn.items()))
            )
        if self.failed:
            lines.append("failed: " + ", ".join(f"{t} {n}" for t, n in sorted(self.failed.items())))
        lines += self.warnings
        return "\n".join(lines)
