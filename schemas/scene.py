"""Scene state: the persistent 3D fruit list, the trunk and the obstacle set (paper §III, §IV-B)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from schemas.base import Frozen, Message, NonNegFloat, PosFloat, Vec3

FruitStatus = Literal["candidate", "selected", "harvested", "unreachable"]
FruitFlag = Literal[
    "border_cut",
    "edge_occluded",
    "box_invalid",
    "depth_invalid",
    "depth_inconsistent",
    "stale",
    "position_jump",
    "kept",
]
"""Quality flags of a fruit's estimate: ``border_cut`` its box touches the image border;
``edge_occluded`` a nearer occluder cuts a side of its box (that semi-axis comes from the fruit's
height/width ratio); ``box_invalid`` / ``depth_invalid`` / ``depth_inconsistent`` this frame's
box or depth gave no estimate (the stored one is kept); ``stale`` not detected in this frame;
``position_jump`` this frame's position was too far from the stored one (kept); ``kept`` beside
any of these: the fruit was detected in this frame but the estimate is the stored one (a view
cut on a side while a whole one is stored is flagged ``edge_occluded`` or ``border_cut`` and
``kept``; without ``kept`` those two flags mark an estimate computed from this frame's cut
view)."""


class Fruit(Frozen):
    """One fruit of the persistent list, modelled as an ellipsoid with a circular xz section."""

    fruit_id: int = Field(ge=1, description="The tracker's track ID of this fruit.")
    position_cam_m: Vec3 = Field(description="Centre in the camera optical frame, m.")
    position_world_m: Vec3 = Field(description="Centre in the world frame, m.")
    semi_axis_h_m: PosFloat = Field(description="Horizontal semi-axis d_h (x and z), m.")
    semi_axis_v_m: PosFloat = Field(description="Vertical semi-axis d_v (centre to peduncle), m.")
    distance_m: NonNegFloat = Field(description="Distance from the camera optical centre, m.")
    status: FruitStatus = Field(description="Harvest status of this fruit.")
    frames_unseen: int = Field(ge=0, description="Camera frames since its track was last seen.")
    last_seen_stamp_ns: int = Field(ge=0, description="Stamp of the frame it was last seen in.")
    flags: tuple[FruitFlag, ...] = Field(default=(), description="Quality flags of the estimate.")


class Trunk(Frozen):
    """The trunk estimate (paper §III-C): a vertical axis through P_t."""

    found: bool = Field(
        description="False when there is no estimate: never found, or no fix for the scene "
        "service's forget_after_frames frames (then positions are None)."
    )
    position_cam_m: Vec3 | None = Field(
        default=None, description="P_t in the camera frame of this frame, m (on the axis)."
    )
    position_world_m: Vec3 | None = Field(
        default=None,
        description="P_t in the world frame, m: a point on the axis at the mean height of the "
        "trunk pixels (smoothed over frames).",
    )
    radius_m: PosFloat | None = Field(
        default=None, description="The trunk's own radius as measured, m (None if unknown)."
    )
    pixel_count: int = Field(default=0, ge=0, description="Pixels in this frame's trunk mask.")
    frames_unseen: int = Field(
        default=0, ge=0, description="Camera frames since the last fix that was averaged in."
    )


class CylinderObstacle(Frozen):
    """An infinite cylinder whose axis is vertical in the world frame."""

    name: str = Field(description="Obstacle name, e.g. 'trunk'.")
    axis_point_world_m: Vec3 = Field(description="A point on the axis, world frame, m.")
    radius_m: PosFloat = Field(description="Radius, m.")


class EllipsoidObstacle(Frozen):
    """An axis-aligned ellipsoid (a fruit) in the world frame."""

    name: str = Field(description="Obstacle name, e.g. 'fruit_12'.")
    fruit_id: int | None = Field(default=None, ge=1, description="Fruit ID when it is a fruit.")
    center_world_m: Vec3 = Field(description="Centre, world frame, m.")
    semi_axes_m: tuple[PosFloat, PosFloat, PosFloat] = Field(
        description="Semi-axes along world x, y, z, m."
    )


class SphereObstacle(Frozen):
    """A sphere of occupied space seen in the depth image (branches) or felt, world frame."""

    name: str = Field(description="Obstacle name, e.g. 'occupied_3'.")
    center_world_m: Vec3 = Field(description="Centre, world frame, m.")
    radius_m: PosFloat = Field(description="Radius, m.")
    own_fruit_ids: tuple[int, ...] = Field(
        default=(),
        description="Felt spheres ('touched_…') only: the fruit this place is part of, so not in "
        "their way: it lies on the fruit as the scene estimates it, or was felt only while the "
        "planner worked on that fruit (its own attempts).",
    )


class Obstacles(Frozen):
    """The obstacle set the controller's velocity dampers act on."""

    cylinders: tuple[CylinderObstacle, ...] = Field(default=(), description="Trunk cylinders.")
    ellipsoids: tuple[EllipsoidObstacle, ...] = Field(default=(), description="Fruit ellipsoids.")
    spheres: tuple[SphereObstacle, ...] = Field(
        default=(),
        description="Occupied space from the depth image (bark-coloured: branches), bounded in "
        "count; none near the selected fruit.",
    )


class SceneState(Message):
    """The scene after one Tracks message (answers perception/tracks)."""

    fruits: tuple[Fruit, ...] = Field(default=(), description="Persistent fruit list, by fruit_id.")
    trunk: Trunk = Field(description="Trunk estimate (smoothed over frames).")
    obstacles: Obstacles = Field(description="Obstacles for collision avoidance.")
    selected_fruit_id: int | None = Field(
        default=None, description="Nearest fruit neither harvested nor unreachable, if any."
    )
    spheres_near_selected: tuple[SphereObstacle, ...] = Field(
        default=(),
        description="Occupied space (as obstacles.spheres) within the selected fruit's keep-out, "
        "left out of the obstacles (the tools must reach the fruit past its own branch): for "
        "checking a fruit's tool poses against every branch seen, never for the dampers.",
    )
    input_problem: str = Field(
        default="",
        description="Why this Tracks message could not be used ('' when it was), e.g. its "
        "frame was never received; the state is then the last good one, unchanged.",
    )
