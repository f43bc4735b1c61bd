"""services/controller/distances.py: the broad phase + coal slots give the same distances as an
independent computation over every pair, and far obstacles cost nothing."""

from __future__ import annotations

import numpy as np
import pytest

from schemas import Obstacles
from services.controller.distances import DistanceEngine, segment_point_distances
from services.controller.kinsim import KinematicSim, SafetyMonitor
from services.controller.obstacles import obstacle_arrays
from services.controller.robot import ControlledRobot
from services.controller.scenarios import fruit, scene
from services.robot.model import URDF_PATH

ACT = {"self": 1.0, "trunk": 1.0, "fruit": 1.0}  # report every computed pair


@pytest.fixture(scope="module")
def robot() -> ControlledRobot:
    return ControlledRobot(URDF_PATH)


def home_q() -> np.ndarray:
    return KinematicSim().q_arm_order()


def near_cutter_cluster(n: int, rng: np.random.Generator) -> Obstacles:
    tip = np.array([0.55, 0.0, 1.05])  # the cutter tip in the ready posture
    fr = [
        fruit(i + 1, tip + rng.uniform(-0.25, 0.25, 3) + [0.15, 0, 0], rng.uniform(0.02, 0.05, 3))
        for i in range(n)
    ]
    return scene(fr, trunk_xy_m=(0.85, 0.1), trunk_radius_m=0.08).obstacles


def test_segment_point_distances() -> None:
    a, b = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]])
    c = np.array([[0.5, 1.0, 0.0], [-1.0, 0.0, 0.0], [3.0, 0.0, 4.0]])
    assert np.allclose(segment_point_distances(a, b, c), [[1.0, 1.0, np.hypot(2, 4)]])


def test_engine_distances_equal_an_all_pairs_computation(robot: ControlledRobot) -> None:
    """Several configurations and scenes through one engine: slots are reused with other sizes
    and positions (a slot's shape type never changes: a regression of a 5 mm error)."""
    rng = np.random.default_rng(7)
    engine = DistanceEngine(robot, cull_m=5.0)  # nothing culled: compare every pair
    for trial in range(4):
        obs = near_cutter_cluster(12 + 4 * trial, rng)
        q = home_q() + rng.normal(0, 0.15, 14)
        robot.set_q(q)
        rep = engine.compute(obstacle_arrays(obs), ACT)
        want = SafetyMonitor(obs).distances(q)
        for kind in ("self", "trunk", "fruit"):
            assert rep.min_m[kind] == pytest.approx(want[kind], abs=1e-6), (trial, kind)


def test_pairs_within_activation_carry_consistent_witnesses(robot: ControlledRobot) -> None:
    engine = DistanceEngine(robot, cull_m=0.3)
    robot.set_q(home_q())
    rep = engine.compute(obstacle_arrays(near_cutter_cluster(20, np.random.default_rng(1))), ACT)
    assert rep.pairs
    for p in rep.pairs:
        assert abs(np.linalg.norm(p.normal) - 1) < 1e-9
        assert p.distance_m == pytest.approx(
            float(p.normal @ (p.p2_world_m - p.p1_world_m)), abs=1e-6
        )


def test_far_obstacles_are_culled_and_near_ones_are_all_computed(robot: ControlledRobot) -> None:
    far = [fruit(i + 1, (3.0 + 0.1 * (i % 10), -1.0 + 0.1 * (i // 10), 1.0)) for i in range(200)]
    engine = DistanceEngine(robot, cull_m=0.25)
    robot.set_q(home_q())
    rep = engine.compute(obstacle_arrays(scene(far).obstacles), ACT)
    assert rep.pairs_checked == engine.n_self and rep.obstacles_near == 0
    assert rep.min_m["fruit"] is None  # nothing within the cull distance
    # 30 near fruit: more than a chunk of slots; the engine grows its slots and gets them right
    obs = near_cutter_cluster(30, np.random.default_rng(2))
    both = scene([*far, *obs.ellipsoids], trunk_xy_m=(0.85, 0.1), trunk_radius_m=0.08).obstacles
    rep = engine.compute(obstacle_arrays(both), ACT)
    want = SafetyMonitor(both).distances(home_q())
    assert rep.min_m["fruit"] == pytest.approx(want["fruit"], abs=1e-6)
    assert rep.min_m["trunk"] == pytest.approx(want["trunk"], abs=1e-6)
    assert 0 < rep.obstacles_near <= 31


def test_an_empty_obstacle_set_computes_the_self_pairs_only(robot: ControlledRobot) -> None:
    engine = DistanceEngine(robot, cull_m=0.25)
    robot.set_q(home_q())
    rep = engine.compute(obstacle_arrays(Obstacles()), ACT)
    assert rep.pairs_checked == engine.n_self == 78
    assert rep.min_m["self"] is not None and rep.min_m["self"] > 0.05


def test_slots_follow_new_arrays_born_where_freed_ones_lived(robot: ControlledRobot) -> None:
    """The engine keeps what its slots hold between calls; a new set of arrays (a sphere moved)
    must refill them even when CPython puts it at a freed set's address (an id() key did not:
    the branch check builds a short-lived set per fruit)."""
    from schemas.scene import SphereObstacle

    engine = DistanceEngine(robot, cull_m=0.3)
    fresh = DistanceEngine(robot, cull_m=0.3)  # its slots refilled every time (below)
    q = home_q()
    robot.set_q(q)
    tip = robot.robot.get_T_world_frame("cutter_tip")[:3, 3]
    for k in range(12):
        gap = 0.01 + 0.01 * (k % 4)  # the sphere's surface this far from the tip's point
        centre = tip + np.array([0.0, 0.0, -(0.03 + gap)])
        sphere = SphereObstacle(name="s", center_world_m=tuple(map(float, centre)), radius_m=0.03)
        got = engine.compute(obstacle_arrays(Obstacles(spheres=(sphere,))), {"branch": 1.0})
        fresh._slots_hold = {}
        want = fresh.compute(obstacle_arrays(Obstacles(spheres=(sphere,))), {"branch": 1.0})
        assert got.min_m["branch"] == pytest.approx(want.min_m["branch"], abs=1e-9), k
