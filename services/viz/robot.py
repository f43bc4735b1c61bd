"""The robot in 3D: the URDF's geometry and static frames, moved by the joint states.

The URDF is logged once with Rerun's importer; each joint state then logs, per joint, the
transform between its parent and child link frames (named frames), which moves the geometry,
the tool frames (``cutter_tip``, ``basket_center``) and the camera frame with it.
"""

from __future__ import annotations

import logging
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from schemas.robot import JointState
from services.robot.model import TOOL_FRAME, joint_names, velocity_limits_rad_s
from services.viz import paths
from services.viz.out import Out

log = logging.getLogger("viz.robot")


class UrdfError(ValueError):
    """The URDF could not be loaded; the message names the file and the reason."""


def load_urdf(path: Path) -> Any:
    """A ``rerun.urdf.UrdfTree`` of ``path``.

    XML comments are removed first: Rerun's strict parser refuses a comment holding '--'
    (which XML forbids, and which a generated header may contain).
    """
    import rerun as rr

    try:
        text = path.read_text()
    except OSError as exc:
        raise UrdfError(f"{path}: cannot read the URDF ({exc.strerror})") from None
    clean = re.sub(r"<!--.*?-->", "", text, flags=re.S)
    with tempfile.TemporaryDirectory(prefix="viz-urdf-") as d:
        tmp = Path(d) / path.name
        tmp.write_text(clean)
        try:
            return rr.urdf.UrdfTree.from_file_path(str(tmp), entity_path_prefix=paths.ROBOT_PREFIX)
        except RuntimeError as exc:
            raise UrdfError(f"{path}: {exc}") from None


@dataclass
class RobotView:
    """Joint lookup and velocity limits; draws the URDF (or nothing, warning once, without it)."""

    tree: Any | None
    velocity_limits_rad_s: dict[str, float]
    unknown_joints: set[str]

    @classmethod
    def load(cls, urdf_path: Path, warn: list[str]) -> RobotView:
        """The robot of ``urdf_path``; without a usable URDF the limits come from the robot
        model (services.robot.model) and ``warn`` says what is missing."""
        try:
            tree = load_urdf(urdf_path)
        except UrdfError as exc:
            warn.append(f"robot not drawn: {exc}")
            return cls(None, _model_limits(), set())
        limits = {
            j.name: j.limit_velocity
            for j in tree.joints()
            if j.joint_type != "fixed" and j.limit_velocity > 0
        }
        return cls(tree, limits, set())

    def log_static(self, out: Out) -> None:
        """The geometry, the static joint frames, the world → root link edge, tool axes."""
        if self.tree is None:
            return
        rr = out.rr
        self.tree.log_urdf_to_recording(out.rec)
        root = self.tree.root_link().name
        out.log(
            paths.ROBOT_ROOT,
            rr.Transform3D(parent_frame=paths.WORLD_FRAME, child_frame=root),
            static=True,
        )
        for role, frame in TOOL_FRAME.items():
            out.log(
                f"{paths.TOOLS}/{role}",
                rr.CoordinateFrame(frame),
                rr.TransformAxes3D(axis_length=0.08),
                static=True,
            )

    def log_joint_state(self, out: Out, msg: JointState) -> None:
        """Each known joint's transform; unknown joint names are reported once."""
        if self.tree is None:
            return
        stamp = msg.header.stamp_ns
        for arm in msg.arms.values():
            for name, q in zip(arm.names, arm.position_rad, strict=True):
                joint = self.tree.get_joint_by_name(name)
                if joint is None:
                    if name not in self.unknown_joints:
                        self.unknown_joints.add(name)
                        log.warning("joint %r is not in the URDF; not drawn", name)
                    continue
                out.joint(f"{paths.JOINTS}/{name}", joint, stamp, q)


def _model_limits() -> dict[str, float]:
    limits = velocity_limits_rad_s()
    return {name: limits[i] for role in TOOL_FRAME for i, name in enumerate(joint_names(role))}
