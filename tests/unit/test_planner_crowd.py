"""crowd_first: a neighbour the arms would touch at every IK solution of a fruit's poses (not in
the tools' way: the clutter test lets the fruit through) is harvested first; one that cannot go
first holds nothing back."""

from __future__ import annotations

import numpy as np
import pytest

from services.planner import bench
from services.planner.clutter import blockers
from services.planner.crowd import CrowdCheck, nearest_ellipsoid
from services.planner.poses import harvest_pose, pre_pose
from tests.unit.test_planner_select import A, core_with, fruit, harvest, select

# Where the collector's forearm passes at every IK solution of A's harvest pose (found by
# sampling points on the robot's bodies at one solution, kept when every solution touches a
# 3.5 cm fruit there and the clutter test does not).
N = (0.504, -0.379, 1.349)
FAR = (0.70, -0.40, 1.60)


def test_the_neighbour_touches_an_arm_not_the_tools() -> None:
    core = core_with("nearest", fruit(1, A, 0.5), fruit(2, N, 0.8), fruit(3, FAR, 0.9))
    ps = core.machine.pose_settings
    a, n, far = (core.book.records[k].planned for k in (1, 2, 3))
    assert blockers(a, [n, far], ps, 0.0) == []  # the tools' way is clear
    poses = [("harvest pose", harvest_pose(a, ps)), ("pre-pose", pre_pose(a, ps))]
    got = CrowdCheck(0.0).crowders(core.kin, poses, [far, n])
    assert got is not None and got.pose == "harvest pose" and got.neighbours == (1,)
    assert got.depth_m > 0.005
    assert CrowdCheck(0.0).crowders(core.kin, poses, [far]) is None
    assert CrowdCheck(0.0).crowders(core.kin, poses, []) is None


def test_the_crowder_goes_first_then_the_fruit() -> None:
    core = core_with("nearest", fruit(1, A, 0.5), fruit(2, N, 0.8), crowd_first=True)
    assert select(core) == 2
    sel = [e for e in core.machine.events if e.event == "fruit_selected"][-1]
    assert "before #1" in sel.reason and "#2" in sel.reason
    harvest(core, 2)
    assert select(core) == 1
    # the bench counts the first pick (its wording), not the nearest one after it
    assert bench.crowd_picks(core.machine.events) == {"crowd_first_picks": 1}


def test_off_the_nearest_goes_first() -> None:
    core = core_with("nearest", fruit(1, A, 0.5), fruit(2, N, 0.8))
    assert core.machine.crowd is None
    assert select(core) == 1


def test_a_crowder_that_stays_holds_nothing_back() -> None:
    # Given up (on the tree still, no candidate): it will not go first, so A is taken.
    core = core_with("nearest", fruit(1, A, 0.5), fruit(2, N, 0.8), crowd_first=True)
    n = core.book.records[2]
    n.outcome, n.finished_ns = "unreachable", 0
    assert select(core) == 1


def test_a_crowder_blocked_itself_does_not_go_first() -> None:
    core = core_with("nearest", fruit(1, A, 0.5), fruit(2, N, 0.8), crowd_first=True)
    m = core.machine
    real = m._blockers
    m._blockers = lambda r: [core.book.records[1]] if r.fruit_id == 2 else real(r)  # type: ignore[method-assign]
    assert select(core) == 1
    sel = [e for e in m.events if e.event == "fruit_selected"][-1]
    assert "none of which can go first" in sel.reason


@pytest.mark.parametrize("crowd_first", [True, False])
def test_planned_order_takes_the_crowder_first(crowd_first: bool) -> None:
    # The cutter was last in front of A: without the rule the shortest order starts there.
    core = core_with("planned", fruit(1, A, 0.5), fruit(2, N, 0.8), crowd_first=crowd_first)
    m = core.machine
    m.last_tip_world_m = pre_pose(core.book.records[1].planned, m.pose_settings).tip_world_m
    first = select(core)
    assert first == (2 if crowd_first else 1)


def test_a_witness_point_names_its_ellipsoid() -> None:
    centres = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]])
    semi = np.array([[0.04, 0.04, 0.05], [0.03, 0.03, 0.03]])
    assert nearest_ellipsoid(np.array([0.0, 0.0, 0.05]), centres, semi) == 0
    assert nearest_ellipsoid(np.array([0.07, 0.0, 0.0]), centres, semi) == 1
