"""Occupied-space spheres (branches) in the controller: checked like every obstacle, only the
nearest few per robot body get a distance, and a tool driven into them stops at d_s."""

from __future__ import annotations

import numpy as np
import pytest

from schemas import Obstacles, SphereObstacle
from services.controller import Settings
from services.controller.core import ControllerCore
from services.controller.distances import DistanceEngine
from services.controller.kinsim import KinematicSim, SafetyMonitor
from services.controller.obstacles import ObstacleError, check_obstacles, obstacle_arrays
from services.controller.robot import ControlledRobot
from services.controller.scenarios import fruit, harvest_target, run_loop, scene
from services.robot.model import URDF_PATH
from services.runtime.settings import load_settings

SETTINGS = load_settings(Settings, {})
FRUIT = (0.85, 0.05, 1.05)


def sphere(i: int, c: np.ndarray | tuple[float, ...], r: float = 0.03) -> SphereObstacle:
    return SphereObstacle(
        name=f"occupied_{i}", center_world_m=(float(c[0]), float(c[1]), float(c[2])), radius_m=r
    )


def wall(x_m: float) -> tuple[SphereObstacle, ...]:
    """A wall of spheres across the tools' way to FRUIT (the plane x = x_m)."""
    ys = np.arange(-0.15, 0.26, 0.04)
    zs = np.arange(0.82, 1.23, 0.04)
    return tuple(sphere(i, (x_m, y, z)) for i, (y, z) in enumerate((y, z) for y in ys for z in zs))


def test_a_degenerate_sphere_is_refused_with_its_name() -> None:
    bad = Obstacles(spheres=(sphere(7, (0.5, 0.0, 1.0), r=0.0005),))
    with pytest.raises(ObstacleError, match="occupied_7"):
        check_obstacles(bad, 0.001, 2.0)


def test_spheres_become_arrays_and_count() -> None:
    a = obstacle_arrays(Obstacles(spheres=wall(0.72)))
    assert a.sphere_centers_m.shape == (len(wall(0.72)), 3)
    assert a.count == len(wall(0.72)) and np.all(a.sphere_radii_m == 0.03)


@pytest.mark.parametrize("per_body", [1, 3])
def test_only_the_nearest_spheres_per_body_are_computed_and_the_nearest_is_kept(
    per_body: int,
) -> None:
    robot = ControlledRobot(URDF_PATH)
    engine = DistanceEngine(robot, cull_m=0.25, spheres_per_body=per_body)
    obs = Obstacles(spheres=wall(0.62))
    q = KinematicSim().q_arm_order()
    robot.set_q(q)
    rep = engine.compute(obstacle_arrays(obs), {"self": 0.0, "branch": 1.0})
    branch = [p for p in rep.pairs if p.kind == "branch"]
    assert 0 < len(branch) <= per_body * len(engine.bodies)
    assert len(branch) < len(engine.bodies) * len(wall(0.62))  # some were left out
    want = SafetyMonitor(obs).distances(q)["branch"]
    assert rep.min_m["branch"] == pytest.approx(want, abs=1e-6)


def test_a_tool_driven_into_a_wall_of_spheres_stops_at_d_s() -> None:
    target = harvest_target(FRUIT, fruit_id=1)
    sc = scene([fruit(1, FRUIT)])
    sc = sc.model_copy(
        update={"obstacles": sc.obstacles.model_copy(update={"spheres": wall(0.72)})}
    )
    monitor = SafetyMonitor(sc.obstacles, target.ignore_fruit_ids)
    d_s = SETTINGS.branch.safety_m
    assert monitor.distances(KinematicSim().q_arm_order())["branch"] > d_s + 0.02
    res = run_loop(
        ControllerCore(SETTINGS),
        KinematicSim(),
        target,
        sc,
        400,
        monitor=monitor,
        safety_m={"branch": d_s},
        stop_when_converged=False,
    )
    assert res.safety.violations == [], res.safety.violations[:3]
    closest = res.safety.min_distance_m["branch"]
    assert closest < d_s + 0.005, "the tools must have pressed against the wall"
    assert res.converged_tick is None  # the wall holds: the fruit behind it is not reached


def test_without_the_spheres_the_same_target_is_reached() -> None:
    """The control for the test above: the wall, not the target, stops the tools."""
    res = run_loop(
        ControllerCore(SETTINGS),
        KinematicSim(),
        harvest_target(FRUIT, fruit_id=1),
        scene([fruit(1, FRUIT)]),
        600,
    )
    assert res.converged_tick is not None


def test_the_bench_case_with_spheres_brings_spheres_past_the_broad_phase() -> None:
    from services.controller.bench import cycle_times

    plain = cycle_times(10, 30, seed=1, settings=SETTINGS)
    with_spheres = cycle_times(10, 30, seed=1, settings=SETTINGS, n_spheres=60)
    assert with_spheres["ticks"] == 30
    assert with_spheres["obstacles_near_mean"] > plain["obstacles_near_mean"]
