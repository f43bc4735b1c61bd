"""The scene in 3D: fruit ellipsoids with IDs and status colours, the trunk cylinder with the
current obstacle radius, the planner's targets (pre-pose included) and the ground truth."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from schemas.control import PlanTarget
from schemas.scene import SceneState
from schemas.sim import GroundTruth
from services.viz import paths
from services.viz.out import Out

AXIS_LENGTH_M = 0.06


@dataclass(frozen=True)
class SceneView:
    """Draws scene/state, plan/target and sim/truth."""

    trunk_draw_height_m: float
    named_frames: bool = True  # the URDF's frames exist (targets relative to them can be drawn)

    def log_scene(self, out: Out, msg: SceneState) -> None:
        rr = out.rr
        fruits = msg.fruits
        out.log(
            paths.FRUITS,
            rr.Ellipsoids3D(
                centers=np.array([f.position_world_m for f in fruits], np.float32).reshape(-1, 3),
                half_sizes=np.array(
                    [(f.semi_axis_h_m, f.semi_axis_h_m, f.semi_axis_v_m) for f in fruits],
                    np.float32,
                ).reshape(-1, 3),
                colors=[paths.STATUS_COLOURS[f.status] for f in fruits],
                labels=[f"#{f.fruit_id} {f.status}" for f in fruits],
                fill_mode=rr.components.FillMode.Solid,
            ),
            rr.AnyValues(fruit_id=np.array([f.fruit_id for f in fruits], np.int64)),
        )
        ells = msg.obstacles.ellipsoids
        out.log(
            paths.OBSTACLE_FRUITS,
            rr.Ellipsoids3D(
                centers=np.array([e.center_world_m for e in ells], np.float32).reshape(-1, 3),
                half_sizes=np.array([e.semi_axes_m for e in ells], np.float32).reshape(-1, 3),
                colors=[(255, 255, 255, 60)] * len(ells),
                fill_mode=rr.components.FillMode.MajorWireframe,
                show_labels=False,
            ),
        )
        cyl = msg.obstacles.cylinders
        h = self.trunk_draw_height_m
        out.log(
            paths.OBSTACLE_TRUNK,
            rr.Cylinders3D(
                centers=[(c.axis_point_world_m[0], c.axis_point_world_m[1], h / 2) for c in cyl],
                lengths=[h] * len(cyl),
                radii=[c.radius_m for c in cyl],
                colors=[paths.TRUNK_COLOUR] * len(cyl),
                labels=[f"{c.name} r={c.radius_m:.3f} m" for c in cyl],
                fill_mode=rr.components.FillMode.MajorWireframe,
            ),
        )
        trunk = msg.trunk
        points = [trunk.position_world_m] if trunk.found and trunk.position_world_m else []
        out.log(
            paths.TRUNK_POINT,
            rr.Points3D(
                np.array(points, np.float32).reshape(-1, 3),
                radii=0.02,
                colors=[paths.TRUNK_COLOUR],
                labels=[f"P_t ({trunk.pixel_count} px)"] * len(points),
            ),
        )

    def log_target(self, out: Out, msg: PlanTarget) -> None:
        """The absolute target (cutter tool pose) and the relative one (collector in the cutter
        tool frame) as frames with axes; in the approach phase the absolute target is the
        pre-pose, which stays drawn after the approach."""
        rr = out.rr
        a = msg.absolute
        label = f"{msg.phase}" + (f" fruit #{msg.fruit_id}" if msg.fruit_id else "")
        if a is None:
            out.log(f"{paths.PLAN}/target", rr.Clear(recursive=True))
        elif a.frame_id == "world" or self.named_frames:
            parent = paths.WORLD_FRAME if a.frame_id == "world" else a.frame_id
            frames = [paths.TARGET_FRAME]
            if msg.phase == "approach":
                frames.append(paths.PRE_POSE_FRAME)
            for child in frames:
                name = "pre_pose" if child == paths.PRE_POSE_FRAME else "target"
                self._frame(out, name, parent, child, a.position_m, a.orientation_xyzw, label)
        r = msg.relative
        if not self.named_frames:
            return  # relative to the cutter tool frame, which only the URDF provides
        if r is None:
            out.log(f"{paths.PLAN}/relative", rr.Clear(recursive=True))
        else:
            self._frame(
                out,
                "relative",
                "cutter_tip",
                paths.RELATIVE_TARGET_FRAME,
                r.position_m,
                r.orientation_xyzw,
                "collector target",
            )

    @staticmethod
    def _frame(
        out: Out,
        name: str,
        parent: str,
        child: str,
        position_m: tuple[float, float, float],
        xyzw: tuple[float, float, float, float],
        label: str,
    ) -> None:
        rr = out.rr
        base = f"{paths.PLAN}/{name}"
        out.log(
            f"{base}/tf",
            rr.Transform3D(
                translation=position_m,
                quaternion=rr.Quaternion(xyzw=xyzw),
                parent_frame=parent,
                child_frame=child,
            ),
        )
        out.log(
            base,
            rr.CoordinateFrame(child),
            rr.TransformAxes3D(axis_length=AXIS_LENGTH_M),
            rr.Points3D([[0.0, 0.0, 0.0]], radii=0.008, labels=[f"{name}: {label}"]),
        )

    def log_truth(self, out: Out, msg: GroundTruth) -> None:
        """True fruit ellipsoids (grey wireframe) and trunk (evaluation only)."""
        rr = out.rr
        fruits = msg.fruits
        out.log(
            paths.TRUTH_FRUITS,
            rr.Ellipsoids3D(
                centers=np.array([f.position_world_m for f in fruits], np.float32).reshape(-1, 3),
                half_sizes=np.array([f.semi_axes_m for f in fruits], np.float32).reshape(-1, 3),
                quaternions=[rr.Quaternion(xyzw=f.orientation_xyzw) for f in fruits],
                colors=[paths.TRUTH_COLOUR] * len(fruits),
                labels=[f"truth {f.fruit_id} {f.state}" for f in fruits],
                fill_mode=rr.components.FillMode.MajorWireframe,
                show_labels=False,
            ),
        )
        t = msg.trunk
        h = self.trunk_draw_height_m
        out.log(
            paths.TRUTH_TRUNK,
            rr.Cylinders3D(
                centers=[
                    (
                        t.axis_point_world_m[0],
                        t.axis_point_world_m[1],
                        t.axis_point_world_m[2] + h / 2,
                    )
                ],
                lengths=[h],
                radii=[t.radius_m],
                colors=[paths.TRUTH_COLOUR],
                fill_mode=rr.components.FillMode.MajorWireframe,
            ),
        )
