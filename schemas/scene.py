"""Scene state: the persistent 3D fruit list, the trunk and the obstacle set (paper §III, §IV-B)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from schemas.base import Frozen, Message, NonNegFloat, PosFloat, Vec3

FruitStatus = Literal["candidate", "selected", "harvested", "unreachable"]
FruitFlag = Literal["border_cut", "depth_invalid", "depth_inconsistent", "stale", "position_jump"]


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

    found: bool = Field(description="False when no trunk pixels passed the HSV ∩ depth mask.")
    position_cam_m: Vec3 | None = Field(default=None, description="P_t in the camera frame, m.")
    position_world_m: Vec3 | None = Field(default=None, description="P_t in the world frame, m.")
    pixel_count: int = Field(default=0, ge=0, description="Pixels in the trunk mask.")


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


class Obstacles(Frozen):
    """The obstacle set the controller's velocity dampers act on."""

    cylinders: tuple[CylinderObstacle, ...] = Field(default=(), description="Trunk cylinders.")
    ellipsoids: tuple[EllipsoidObstacle, ...] = Field(default=(), description="Fruit ellipsoids.")


class SceneState(Message):
    """The scene after one Tracks message (answers perception/tracks)."""

    fruits: tuple[Fruit, ...] = Field(default=(), description="Persistent fruit list, by fruit_id.")
    trunk: Trunk = Field(description="Trunk estimate (smoothed over frames).")
    obstacles: Obstacles = Field(description="Obstacles for collision avoidance.")
    selected_fruit_id: int | None = Field(
        default=None, description="Nearest fruit neither harvested nor unreachable, if any."
    )
