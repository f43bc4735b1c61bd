"""Entity paths, timelines and colours of the Rerun recording: the one place that names them."""

from __future__ import annotations

import colorsys

# ---- timelines ------------------------------------------------------------------------------
SIM_TIME = "sim_time"
"""Message stamps (header.stamp_ns) as a duration: the same live and in replay."""
FRAME = "frame"
"""seq of the camera frame a camera, detection or track message belongs to."""

# ---- 3D -------------------------------------------------------------------------------------
WORLD = "/world"
ROBOT = "/robot"
ROBOT_PREFIX = "robot"  # the URDF importer's entity_path_prefix: one path part, not nestable
JOINTS = "/robot/joints"
TOOLS = "/robot/tools"
ROBOT_ROOT = "/robot/root"
CAMERA = "/world/camera"
IMAGE = "/world/camera/image"
RGB = f"{IMAGE}/rgb"
DEPTH = f"{IMAGE}/depth"
TRUNK_MASK = f"{IMAGE}/trunk_mask"
DETECTIONS = f"{IMAGE}/detections"
TRACKS = f"{IMAGE}/tracks"
TRUTH_BOXES = f"{IMAGE}/truth"
FRUITS = "/world/fruits"
OBSTACLE_FRUITS = "/world/obstacles/fruits"
OBSTACLE_TRUNK = "/world/obstacles/trunk"
TRUNK_POINT = "/world/trunk_estimate"
PLAN = "/world/plan"
TRUTH_FRUITS = "/world/truth/fruits"
TRUTH_TRUNK = "/world/truth/trunk"

# ---- plots ----------------------------------------------------------------------------------
PLOTS = "/plots"
ERRORS = "/plots/error"
DISTANCES = "/plots/distance"
D_S = "/plots/distance/d_s"
SOLVE_TIME = "/plots/solve_time_ms"
JOINT_VELOCITY = "/plots/joint_velocity"
DAMPERS = "/plots/active_dampers"

# ---- text -----------------------------------------------------------------------------------
LOG = "/log"
LOG_HARVEST = "/log/harvest"
LOG_CONTROL = "/log/control"
LOG_SIM = "/log/sim"
LOG_TOOL = "/log/tool"
LOG_RUN = "/log/run"

# ---- frames (named transform frames; the URDF's link names are frames too) -------------------
WORLD_FRAME = "tf#/world"
TARGET_FRAME = "plan_target"
PRE_POSE_FRAME = "plan_pre_pose"
RELATIVE_TARGET_FRAME = "plan_relative_target"

# ---- colours --------------------------------------------------------------------------------
RGB8 = tuple[int, int, int]
STATUS_COLOURS: dict[str, RGB8] = {
    "candidate": (255, 140, 0),  # orange
    "selected": (0, 200, 255),  # cyan: the current target
    "harvested": (120, 200, 80),  # green
    "unreachable": (220, 40, 40),  # red
}
TRUTH_COLOUR: RGB8 = (200, 200, 200)
TRUNK_COLOUR: RGB8 = (140, 90, 50)
MASK_COLOUR: tuple[int, int, int, int] = (255, 0, 255, 110)  # translucent magenta overlay


def track_colour(track_id: int) -> RGB8:
    """A stable, well-spread colour per track ID (golden-ratio hue walk)."""
    hue = (track_id * 0.618033988749895) % 1.0
    r, g, b = colorsys.hsv_to_rgb(hue, 0.85, 0.95)
    return round(255 * r), round(255 * g), round(255 * b)
