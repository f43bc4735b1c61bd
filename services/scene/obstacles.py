"""The obstacle set (paper §IV-B): the trunk as an infinite vertical cylinder of variable radius,
and every fruit still on the tree as an ellipsoid.

The paper sets r_obs = dist(P_f, P_t) - d_h for the selected fruit, with dist the 3D distance.
We use the *horizontal* distance from the fruit centre to the trunk axis: the cylinder is
infinite and vertical, so only the horizontal distance says where its surface passes; the 3D
distance adds the height difference between the fruit and P_t (P_t sits at the mean height of
the trunk pixels), which would push the surface past the fruit and swallow it. With the
horizontal distance the surface passes through the back of the fruit (the side facing the
trunk): the arms may reach the fruit from the front, never the space between it and the trunk.
The radius never goes below the trunk's own (a fruit against the trunk); without a selected
fruit it is the trunk's own radius.

One departure from the paper, measured: our collecting dish (8.5 cm radius) is centred under the
fruit, so it reaches ~4.5 cm past the fruit's back, and the controller's damper keeps d_s (2 cm)
more. With the surface exactly at the fruit's back the dish can never get under it (every
harvest of paper-exp1 ended "no progress" 5-8 cm short). The surface therefore passes
``tool_margin_m`` (default 8 cm) behind the fruit's back; the arms still keep out of the space
near the trunk. The selected fruit is the planner's current target (scene/state follows its
``fruit_selected`` events), or the nearest when it has none.
"""

from __future__ import annotations

import math

from schemas.scene import CylinderObstacle, EllipsoidObstacle, Obstacles
from services.scene.fruit_list import Entry
from services.scene.geometry import vec3
from services.scene.trunk_track import TrunkState


def trunk_radius_m(
    trunk: TrunkState, selected: Entry | None, default_radius_m: float, tool_margin_m: float = 0.0
) -> tuple[float, float]:
    """(r_obs, the trunk's own radius) in m."""
    own = trunk.radius_m if trunk.radius_m is not None else default_radius_m
    if selected is None:
        return own, own
    p = selected.state.position_world_m
    horizontal = math.hypot(p[0] - trunk.axis_world_m[0], p[1] - trunk.axis_world_m[1])
    return max(horizontal - selected.state.semi_axis_h_m - tool_margin_m, own), own


def build_obstacles(
    entries: list[Entry],
    harvested: set[int],
    trunk: TrunkState | None,
    selected: Entry | None,
    default_trunk_radius_m: float,
    tool_margin_m: float = 0.0,
) -> Obstacles:
    """Cylinder (when the trunk is known) and the ellipsoids of the fruit not harvested
    (unreachable ones stay: they hang on the tree), by fruit ID."""
    cylinders: tuple[CylinderObstacle, ...] = ()
    if trunk is not None:
        r_obs, _ = trunk_radius_m(trunk, selected, default_trunk_radius_m, tool_margin_m)
        cylinders = (
            CylinderObstacle(
                name="trunk", axis_point_world_m=vec3(trunk.axis_world_m), radius_m=r_obs
            ),
        )
    ellipsoids = tuple(
        EllipsoidObstacle(
            name=f"fruit_{e.fruit_id}",
            fruit_id=e.fruit_id,
            center_world_m=vec3(e.state.position_world_m),
            # The estimate's vertical axis is the camera's y axis, which is within a few degrees
            # of the world's vertical on the robot's head (8°: < 0.1 mm on these semi-axes).
            semi_axes_m=(e.state.semi_axis_h_m, e.state.semi_axis_h_m, e.state.semi_axis_v_m),
        )
        for e in entries
        if e.fruit_id not in harvested
    )
    return Obstacles(cylinders=cylinders, ellipsoids=ellipsoids)
