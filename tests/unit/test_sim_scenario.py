"""Scenario files: the shipped ones load and say what they promise; bad files are refused with
the field named."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from services.runtime import ConfigError
from services.sim.scenario import ScenarioError, load_scenario, parse_scenario
from services.sim.world import build_world
from tests.sim_helpers import core

GOOD = {"name": "t", "fruits": [{"position_world_m": [0.6, -0.1, 1.3]}]}


def test_shipped_scenarios_match_the_paper() -> None:
    exp1 = load_scenario("paper-exp1")
    assert len(exp1.fruits) == 6
    assert [f.leaf_cover for f in exp1.fruits].count("heavy") == 1
    kinds = {e.kind for e in exp1.events}
    assert kinds == {"hand_sweep", "move_fruit", "sway_leaves"}
    exp2 = load_scenario("paper-exp2")
    assert len(exp2.fruits) == 5 and all(f.leaf_cover == "none" for f in exp2.fruits)
    orchard = load_scenario("orchard")
    assert orchard.random_fruits is not None and 5 <= orchard.random_fruits.count <= 30


@pytest.mark.parametrize("count", [5, 30])
def test_orchard_places_5_to_30_fruit_from_its_seed(count: int) -> None:
    sc = load_scenario("orchard")
    a = build_world(sc, seed=4, fruit_count=count)
    b = build_world(sc, seed=4, fruit_count=count)
    c = build_world(sc, seed=5, fruit_count=count)
    assert len(a.fruits) == count
    assert all(np.array_equal(f.centre, g.centre) for f, g in zip(a.fruits, b.fruits, strict=True))
    assert not np.array_equal(a.fruits[0].centre, c.fruits[0].centre)


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"colour": "blue"}, "colour"),
        ({"fruits": [{"position_world_m": [0.6, 0, 1.3], "radius_m": -0.04}]}, "fruits.0.radius_m"),
        ({"fruits": [{"position_world_m": [0.6, 0, 1.3], "shape": "pear"}]}, "fruits.0.shape"),
        ({"fruits": [{"position_world_m": [1.16, 0.0, 1.3]}]}, "fruits.0.position_world_m"),
        ({"tree": {"trunk_radius_m": 0}}, "tree.trunk_radius_m"),
        (
            {
                "events": [
                    {
                        "kind": "move_fruit",
                        "start_s": 1,
                        "duration_s": 1,
                        "fruit": 4,
                        "offset_world_m": [0, 0, 0.1],
                    }
                ]
            },
            "events.0.fruit",
        ),
        ({"events": [{"kind": "explode", "start_s": 1, "duration_s": 1}]}, "events.0"),
    ],
)
def test_bad_scenarios_are_refused_with_the_field_named(change: dict, field: str) -> None:
    with pytest.raises(ScenarioError) as exc:
        parse_scenario({**GOOD, **change})
    assert field in str(exc.value), str(exc.value)


def test_a_sim_with_a_bad_scenario_refuses_to_start(tmp_path: Path) -> None:
    p = tmp_path / "bad.yaml"
    p.write_text("name: bad\nfruits: [{position_world_m: [0.6, 0, 1.3], radius_m: -1}]\n")
    with pytest.raises(ConfigError, match=r"fruits\.0\.radius_m"):
        core(p)
    with pytest.raises(ConfigError, match="scenario not found"):
        core("no-such-scenario")


def test_paper_exp2_has_exactly_one_fruit_out_of_reach() -> None:
    from services.robot.reach import ReachSolver

    s = ReachSolver()
    reached = [
        s.reach(np.asarray(f.position_world_m)).reached for f in load_scenario("paper-exp2").fruits
    ]
    assert reached == [True, True, True, True, False]


def test_random_fruit_keep_clear_of_the_robot_in_its_initial_posture() -> None:
    from services.robot.clearance import distance_to_home_robot_m
    from services.sim.world import ROBOT_CLEARANCE_M

    sc = load_scenario("orchard")
    for seed in range(6):  # seeds 0-2 used to put a fruit inside an arm
        for f in build_world(sc, seed=seed).fruits:
            assert distance_to_home_robot_m(f.centre) - f.semi_axes[0] >= ROBOT_CLEARANCE_M
    # the distance is that of a point to the arm's capsules: the cutter tip is on the robot
    assert distance_to_home_robot_m((0.55, 0.0, 1.05)) < 0
