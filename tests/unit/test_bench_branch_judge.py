"""The harvest bench's judge counts a fruit reachable only if its tools can take their poses
without the robot touching the tree, in the sim's own collision model: a dish that can only be
put through a branch harvests with a collision (orchard seed 0: fruit 0, 1 and 3 were harvested,
each with branch contacts during its cycle, and the judge calls all three "branch")."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from services.planner.bench import first_frame
from services.robot.model import ARM_ROLES, HOME_RAD, all_joint_names
from services.sim.physics import Physics
from services.sim.scenario import load_scenario
from services.sim.world import Cyl, build_world
from tests.harvest_helpers import lab_scenario
from tests.unit.test_planner_loop import A


def home_q() -> np.ndarray:
    return np.array([v for role in ARM_ROLES for v in HOME_RAD[role]], float)  # all_joint_names


def test_tree_contacts_at_a_posture_name_the_link_and_the_branch(tmp_path: Path) -> None:
    world = build_world(load_scenario(str(lab_scenario(tmp_path, [A]))))
    clear = Physics(world, 1 / 60, 1)
    try:
        assert clear.tree_contacts_at(home_q()) == []
        tip, _R = clear.frame("cutter_tool")  # where the joints were just put
    finally:
        clear.close()
    k = len(world.branches)
    up = np.array([0, 0, 0.05])
    world.branches.append(Cyl(tip - up, tip + up, 0.01))  # a branch through the tool
    hit = Physics(world, 1 / 60, 1)
    try:
        assert len(home_q()) == len(all_joint_names())
        assert ("cutter_tool", f"branch_{k}") in hit.tree_contacts_at(home_q())
    finally:
        hit.close()


def test_a_fruit_reached_only_through_a_branch_is_not_reachable() -> None:
    truth, judged = first_frame(
        {"scenario": "orchard", "seed": 0}, {"order": "nearest", "scenario": "orchard", "seed": 0}
    )
    assert len(truth.fruits) == len(judged.reachable) == len(judged.reachable_ik)
    for i in (0, 1, 3):  # IK and clutter would have them; every IK solution touches a branch
        assert judged.reachable_ik[i] and not judged.reachable[i] and judged.why[i] == "branch"
    assert judged.reachable[4] and judged.reachable_ik[4] and 4 not in judged.why
    # the branch check only removes fruit: whatever is reachable was reachable without it
    assert all(judged.reachable_ik[i] for i, ok in judged.reachable.items() if ok)


def test_both_judgements_are_totalled() -> None:
    from services.planner import bench

    row = {"cycles_s": [], "sim_s": 1.0, "wall_s": 1.0, "max_velocity_ratio": 0.5}
    row |= {"reachable_fates": {}, "reachable": 2, "harvested_reachable": 1}
    row |= {"reachable_ik": 4, "harvested_reachable_ik": 3, "unreachable_branch": 2}
    agg = bench.aggregate([row, row])
    assert (agg["reachable"], agg["reachable_ik"], agg["unreachable_branch"]) == (4, 8, 4)
    assert agg["success_rate"] == 0.5 and agg["success_rate_ik"] == 0.75
    text = bench.table({"scenario": "x", "seeds": [0], "mode": "inproc", "policies": {"n": agg}})
    assert "reachable without the branch check" in text


def test_fruit_contacts_at_a_posture_leave_the_target_out(tmp_path: Path) -> None:
    probe = Physics(build_world(load_scenario(str(lab_scenario(tmp_path, [A])))), 1 / 60, 1)
    try:
        assert probe.fruit_contacts_at(home_q()) == []  # fruit 0 hangs clear of the arms
        tip, _R = probe.frame("cutter_tool")  # where the joints were just put
    finally:
        probe.close()
    there = {**A, "position_world_m": [float(v) for v in tip]}
    at_tip = lab_scenario(tmp_path, [A, there])  # a second fruit at the cutter's tip
    hit = Physics(build_world(load_scenario(str(at_tip))), 1 / 60, 1)
    try:
        assert ("cutter_tool", "fruit_1") in hit.fruit_contacts_at(home_q())
        assert ("cutter_tool", "fruit_1") not in hit.fruit_contacts_at(home_q(), but=1)
        assert hit.tree_contacts_at(home_q()) == []  # fruit are no tree bodies
    finally:
        hit.close()


def test_crowded_fruit_are_told_apart_and_totalled() -> None:
    """Orchard seeds 0-19 (session 30): 22 of the 25 reachable fruit not harvested could only
    be reached with a robot body against a neighbour fruit (43 of the 76 harvested)."""
    from services.planner import bench

    truth, _ = first_frame(
        {"scenario": "orchard", "seed": 2}, {"order": "nearest", "scenario": "orchard", "seed": 2}
    )
    plan_s = {"order": "nearest", "scenario": "orchard", "seed": 2}
    never = bench.truth_reachability(truth, plan_s, lambda q: False, lambda q, i: False)
    always = bench.truth_reachability(truth, plan_s, lambda q: False, lambda q, i: True)
    assert never.reachable == always.reachable  # a diagnosis, not part of reachable
    reach = [i for i, ok in always.reachable.items() if ok]
    assert reach and all(always.crowded[i] for i in reach)
    assert not any(never.crowded.values())
    row = {"cycles_s": [], "sim_s": 1.0, "wall_s": 1.0, "max_velocity_ratio": 0.5}
    row |= {"reachable_fates": {}, "reachable": 2, "reachable_crowded": 2, "lost_crowded": 1}
    assert bench.aggregate([row, row])["lost_crowded"] == 2
