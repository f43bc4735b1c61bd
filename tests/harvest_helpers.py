"""Harvest test helpers: a scene state computed from the sim's ground truth (TESTS ONLY: a
stand-in for the detector → tracker → scene chain, never a product path), and the closed loop
sim + truth scene + controller + planner in one process (services.runtime.inproc)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from schemas.harvest import HarvestEvent, RunSummary
from schemas.scene import (
    CylinderObstacle,
    EllipsoidObstacle,
    Fruit,
    Obstacles,
    SceneState,
    Trunk,
)
from schemas.sim import GroundTruth
from services.runtime.inproc import InprocGraph, InprocNode
from services.runtime.settings import load_settings
from services.runtime.stamp import Stamper
from services.sim.render.camera import head_camera_pose

HARVESTED_EVENTS = ("fruit_collected", "fruit_dropped")  # the scene estimator's marks


@dataclass
class TruthScene:
    """Answers sim/truth with a scene state as a perfect perception chain would: attached fruit
    whose visible share is at least ``min_visible`` are seen (position, semi-axes from the
    truth), the others age and are forgotten after ``forget_frames``; track ID = sim index + 1
    unless ``relabel`` says otherwise; IDs in ``hidden`` are never reported. The trunk cylinder
    has the true axis and radius. Marks come from harvest/events."""

    min_visible: float = 0.2
    forget_frames: int = 100
    relabel: dict[int, int] = field(default_factory=dict)  # sim index → track ID
    hidden: set[int] = field(default_factory=set)  # track IDs
    entries: dict[int, Fruit] = field(default_factory=dict)
    marks: dict[int, str] = field(default_factory=dict)
    stamper: Stamper = field(default_factory=lambda: Stamper("scene"))
    T_world_cam: np.ndarray = field(default_factory=head_camera_pose)
    bias_world_m: tuple[float, float, float] = (0.0, 0.0, 0.0)  # added to every fruit's centre
    on_frame: Callable[[TruthScene, GroundTruth], None] | None = None

    def handle(self, topic: str, msg: Any) -> list[tuple[str, Any]]:
        if topic == "harvest/events":
            ev: HarvestEvent = msg
            if ev.fruit_id is not None and ev.event in HARVESTED_EVENTS:
                self.marks[ev.fruit_id] = "harvested"
            elif ev.fruit_id is not None and ev.outcome == "unreachable":
                self.marks.setdefault(ev.fruit_id, "unreachable")
            return []
        if topic != "sim/truth":
            return []
        truth: GroundTruth = msg
        if self.on_frame is not None:
            self.on_frame(self, truth)
        stamp = truth.header.stamp_ns
        seen: set[int] = set()
        R, t = self.T_world_cam[:3, :3], self.T_world_cam[:3, 3]
        for ft in truth.fruits:
            tid = self.relabel.get(ft.fruit_id, ft.fruit_id + 1)
            if (
                ft.state != "attached"
                or ft.visible_fraction < self.min_visible
                or tid in self.hidden
            ):
                continue
            p = np.array(ft.position_world_m) + np.array(self.bias_world_m)
            p_cam = R.T @ (p - t)
            seen.add(tid)
            self.entries[tid] = Fruit(
                fruit_id=tid,
                position_cam_m=tuple(float(v) for v in p_cam),  # type: ignore[arg-type]
                position_world_m=tuple(float(v) for v in p),  # type: ignore[arg-type]
                semi_axis_h_m=ft.semi_axes_m[0],
                semi_axis_v_m=ft.semi_axes_m[2],
                distance_m=float(np.linalg.norm(p_cam)),
                status="candidate",
                frames_unseen=0,
                last_seen_stamp_ns=stamp,
            )
        for tid in sorted(self.entries):
            e = self.entries[tid]
            if tid in self.hidden:
                del self.entries[tid]
            elif tid not in seen:
                if e.frames_unseen + 1 > self.forget_frames:
                    del self.entries[tid]
                else:
                    self.entries[tid] = e.model_copy(update={"frames_unseen": e.frames_unseen + 1})
        fruits = tuple(
            e.model_copy(update={"status": self.marks.get(tid, "candidate")})
            for tid, e in sorted(self.entries.items())
        )
        tr = truth.trunk
        axis = (tr.axis_point_world_m[0], tr.axis_point_world_m[1], 1.2)
        scene = SceneState(
            header=self.stamper.answer("scene/state", truth.header, "world"),
            fruits=fruits,
            trunk=Trunk(found=True, position_world_m=axis),
            obstacles=Obstacles(
                cylinders=(
                    CylinderObstacle(name="trunk", axis_point_world_m=axis, radius_m=tr.radius_m),
                ),
                ellipsoids=tuple(
                    EllipsoidObstacle(
                        name=f"fruit_{f.fruit_id}",
                        fruit_id=f.fruit_id,
                        center_world_m=f.position_world_m,
                        semi_axes_m=(f.semi_axis_h_m, f.semi_axis_h_m, f.semi_axis_v_m),
                    )
                    for f in fruits
                ),
            ),
        )
        return [("scene/state", scene)]


def lab_scenario(tmp: Path, fruits: list[dict[str, Any]], **over: Any) -> Path:
    """A small lab tree (few leaves: fast to render) with the given fruit."""
    sc: dict[str, Any] = {
        "name": "harvest-test",
        "seed": 3,
        "tree": {
            "trunk_xy_world_m": [1.15, 0.02],
            "extra_branches": 1,
            "leaf_clusters": 2,
            "leaves_per_cluster": 4,
        },
        "fruits": fruits,
    }
    sc.update(over)
    p = tmp / f"harvest-{abs(hash(repr(sc))) % 10**8}.yaml"
    p.write_text(yaml.safe_dump(sc))
    return p


@dataclass
class LoopRun:
    """Everything a closed-loop run produced, by topic, in order."""

    by_topic: dict[str, list[Any]]
    ticks: int
    planner: Any
    sim: Any

    def events(self, kind: str | None = None) -> list[HarvestEvent]:
        return [e for e in self.by_topic.get("harvest/events", []) if kind in (None, e.event)]

    def summary(self) -> RunSummary:
        (s,) = self.by_topic["harvest/summary"]
        return s

    def sim_events(self, kind: str) -> list[Any]:
        return [e for e in self.by_topic.get("sim/events", []) if e.kind == kind]


def run_harvest(
    scenario: Path | str,
    *,
    planner: dict[str, Any] | None = None,
    sim: dict[str, Any] | None = None,
    controller: dict[str, Any] | None = None,
    scene: TruthScene | None = None,
    max_s: float = 60.0,
    transform: Callable[[str, Any], Any] | None = None,
) -> LoopRun:
    """Sim, truth scene, controller and planner in lock-step in one process until the planner
    is done (or ``max_s`` of sim time). ``transform(topic, msg)`` may alter a message on its
    way to the controller or the planner (fault injection: e.g. a plan target the controller
    receives, the basket count the planner receives)."""
    from services.controller import Settings as ControllerSettings
    from services.controller.core import ControllerCore
    from services.planner import Settings as PlannerSettings
    from services.planner.core import PlannerCore
    from services.sim import Settings as SimSettings
    from services.sim.core import SimCore

    sim_core = SimCore(
        load_settings(SimSettings, {"scenario": str(scenario), "depth_noise": False, **(sim or {})})
    )
    ctrl = ControllerCore(
        load_settings(ControllerSettings, {"publish_diagnostics": False, **(controller or {})})
    )
    plan = PlannerCore(load_settings(PlannerSettings, planner or {}))
    truth_scene = scene or TruthScene()
    by_topic: dict[str, list[Any]] = {}

    def tap(src: str, topic: str, msg: Any) -> None:
        by_topic.setdefault(topic, []).append(msg)

    class _Filter:
        def __init__(self, core: Any) -> None:
            self.core = core

        def handle(self, topic: str, msg: Any) -> Any:
            return self.core.handle(topic, transform(topic, msg) if transform else msg)

    graph = InprocGraph(
        "sim",
        sim_core,
        ("robot/command", "robot/tool"),
        [
            InprocNode("scene", ("sim/truth", "harvest/events"), truth_scene),
            InprocNode(
                "controller", ("robot/joint_state", "plan/target", "scene/state"), _Filter(ctrl)
            ),
            InprocNode(
                "planner",
                ("control/status", "scene/state", "robot/basket", "robot/joint_state"),
                _Filter(plan),
            ),
        ],
        tap,
    )
    max_ticks = int(max_s / (sim_core.s.control_period_ns * 1e-9))
    ticks = graph.run(plan.done, max_ticks)
    sim_core.close()
    return LoopRun(by_topic, ticks, plan, sim_core)
