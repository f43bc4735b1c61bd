"""services/controller/obstacles.py: degenerate shapes are refused; ignored fruit left out."""

from __future__ import annotations

import math

import pytest
from pydantic import ValidationError

from schemas import CylinderObstacle, EllipsoidObstacle, Obstacles
from services.controller.obstacles import ObstacleError, check_obstacles, obstacle_arrays


def ell(i: int, axes=(0.03, 0.03, 0.04), c=(0.8, 0.0, 1.0)) -> EllipsoidObstacle:
    return EllipsoidObstacle(name=f"fruit_{i}", fruit_id=i, center_world_m=c, semi_axes_m=axes)


def test_the_schema_refuses_zero_negative_and_nan_sizes() -> None:
    for bad in (0.0, -0.01, math.nan):
        with pytest.raises(ValidationError):
            CylinderObstacle(name="trunk", axis_point_world_m=(1.0, 0.0, 1.0), radius_m=bad)


@pytest.mark.parametrize(
    "obstacles",
    [
        Obstacles(
            ellipsoids=(
                EllipsoidObstacle.model_construct(
                    name="flat",
                    fruit_id=3,
                    center_world_m=(0.8, 0.0, 1.0),
                    semi_axes_m=(0.03, 0.0, 0.04),
                ),
            )
        ),
        Obstacles(
            cylinders=(
                CylinderObstacle.model_construct(
                    name="trunk", axis_point_world_m=(1.0, 0.0, 1.0), radius_m=-0.1
                ),
            )
        ),
        Obstacles(ellipsoids=(ell(1, axes=(0.0004, 0.03, 0.03)),)),
        Obstacles(ellipsoids=(ell(1, axes=(3.0, 0.03, 0.03)),)),
        Obstacles(
            ellipsoids=(
                EllipsoidObstacle.model_construct(
                    name="lost",
                    fruit_id=3,
                    center_world_m=(math.inf, 0.0, 1.0),
                    semi_axes_m=(0.03, 0.03, 0.04),
                ),
            )
        ),
    ],
    ids=["zero", "negative", "tiny", "huge", "inf-centre"],
)
def test_degenerate_shapes_are_refused_with_their_name(obstacles: Obstacles) -> None:
    with pytest.raises(ObstacleError, match="obstacle '"):
        check_obstacles(obstacles, 0.001, 2.0)


def test_ignored_fruit_are_left_out_and_the_trunk_kept() -> None:
    obs = Obstacles(
        cylinders=(
            CylinderObstacle(name="trunk", axis_point_world_m=(1.0, 0.0, 1.0), radius_m=0.1),
        ),
        ellipsoids=(ell(1), ell(2), ell(3)),
    )
    check_obstacles(obs, 0.001, 2.0)
    a = obstacle_arrays(obs, ignore_fruit_ids=(2,))
    assert a.ellipsoid_fruit_ids == (1, 3) and a.ellipsoid_centers_m.shape == (2, 3)
    assert a.cylinder_radii_m.tolist() == [0.1] and a.count == 3


def test_an_empty_obstacle_set_gives_empty_arrays() -> None:
    a = obstacle_arrays(Obstacles())
    assert a.count == 0 and a.ellipsoid_centers_m.shape == (0, 3)


def test_a_scene_with_too_many_obstacles_is_refused_and_counted() -> None:
    """10,000 fruit would cost over a minute per tick: the scene is refused, the arms hold."""
    from services.controller import SERVICE
    from services.controller.kinsim import KinematicSim
    from services.controller.scenarios import fruit, scene
    from services.runtime.settings import load_settings

    core = SERVICE.make_core(load_settings(SERVICE.settings, {"max_obstacles": 5}))
    core.handle("scene/state", scene([fruit(i + 1, (0.8, 0.01 * i, 1.0)) for i in range(6)]))
    assert core.counters.rejected_scenes == 1
    assert "6 obstacles, more than max_obstacles 5" in core.scene_refused
    outs = dict(core.handle("robot/joint_state", KinematicSim().joint_state()))
    assert outs["robot/command"].hold
