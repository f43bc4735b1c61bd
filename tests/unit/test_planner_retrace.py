"""Retracing after a stall (services/planner/retrace.py and the machine): the arms go back
along the joint path of the attempt as joint goals, then the next fruit is taken."""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from services.planner.core import PlannerCore
from services.planner.machine import Goal
from services.planner.retrace import JointPath, Retrace
from tests.unit.test_planner_bench_fates import NS, TICK_NS, status
from tests.unit.test_planner_select import A, core_with, fruit

Q0 = np.zeros(14)
Q1 = np.linspace(0.2, 0.9, 14)  # where the approach got stuck


def test_the_path_keeps_a_waypoint_per_step() -> None:
    path = JointPath(0.1)
    path.start(Q0)
    for s in np.linspace(0, 1, 101):
        path.note(s * Q1)
    gaps = [np.abs(b - a).max() for a, b in pairwise(path.points)]
    assert len(path.points) == 9 and all(0.1 <= g < 0.11 for g in gaps)  # 0.9 rad in 0.108s
    path.start(None)
    path.note(Q1)
    assert path.points == []  # no start, no path


def test_a_retrace_runs_the_path_backwards_to_its_start() -> None:
    path = JointPath(0.1)
    path.start(Q0)
    for s in np.linspace(0, 1, 101):
        path.note(s * Q1)
    r = Retrace.back_along(path, 0, lookahead_rad=0.15, tolerance_rad=0.03)
    assert r is not None and np.allclose(r.waypoints[-1], Q0)
    q = path.points[-1].copy()
    goals = []
    for k in range(400):  # follow the goal at 0.02 rad per tick on every joint
        r.update(q, k * TICK_NS)
        goals.append(r.goal.copy())
        if r.done(q):
            break
        q = q + np.clip(r.goal - q, -0.02, 0.02)
    assert r.done(q) and np.abs(q - Q0).max() <= 0.03
    # each goal is further back along the path than the one before, and ahead of the arms
    steps = [np.abs(g - Q0).max() for g in goals]
    assert all(b <= a for a, b in pairwise(steps))
    assert not r.stuck(k * TICK_NS, 1.5)
    assert r.stuck(k * TICK_NS + 2 * NS, 1.5)  # no progress for 2 s


def test_a_single_point_path_has_nothing_to_retrace() -> None:
    path = JointPath(0.1)
    path.start(Q0)
    path.note(Q0 + 0.05)
    assert Retrace.back_along(path, 0, 0.15, 0.03) is None


def drive_to_a_stall(retrace: bool) -> tuple[PlannerCore, list[Goal], int]:
    """The cutter stays 5 cm off the pre-pose while the joints go from Q0 to Q1 (in the
    second after the selection, at startup_s = 1 s) and stop. No planned path after the stall
    (plan_approach off): retracing alone."""
    core = core_with("nearest", fruit(1, A, 0.5), plan_approach="off")
    core.machine.s = core.machine.s.model_copy(update={"retrace_after_stall": retrace})
    m, t = core.machine, 0
    m.note_joints(Q0)
    goals = []
    while not any(e.event == "fruit_skipped" for e in m.events) and t < 10 * NS:
        t += TICK_NS
        m.note_joints(Q1 * float(np.clip(t / NS - 1.0, 0.0, 1.0)))
        goals.append(m.step(t, status(m.next_seq, 0.05, t), m.next_seq + 1, 0))
    return core, goals, t


def test_a_stalled_approach_goes_back_along_its_joint_path() -> None:
    core, _, t = drive_to_a_stall(retrace=True)
    m = core.machine
    rec = core.book.records[1]
    assert m.phase == "leave" and m.retrace is not None
    skipped = [e for e in m.events if e.event == "fruit_skipped"]
    assert "approach no progress" in skipped[-1].reason and "retracing" in skipped[-1].reason
    assert rec.deferred and not rec.finished  # tried again once the others are done
    # the joint goals lead back to Q0, then the fruit is taken again (it is the only one)
    q = Q1.copy()
    targets = []
    while m.phase == "leave" and t < 20 * NS:
        t += TICK_NS
        g = m.step(t, status(m.next_seq, 0.05, t), m.next_seq + 1, 0)
        if g.joints_rad is None:
            break
        targets.append(core._target(status(m.next_seq, 0.05, t), g))
        q = q + np.clip(g.joints_rad - q, -0.01, 0.01)
        m.note_joints(q)
    assert np.abs(q - Q0).max() <= 0.03
    assert m.phase == "approach" and m.target is rec and m.retrace is None
    back = [e for e in m.events if e.event == "phase_changed" and e.phase_from == "leave"]
    assert back[-1].reason == "retraced to where the attempt began"
    # the messages are joint goals for both arms, no pose task, the fruit not ignored
    msg = targets[0]
    assert msg.joints is not None and msg.absolute is None and msg.relative is None
    assert set(msg.joints) == {"cutter", "collector"} and msg.ignore_fruit_ids == ()
    assert msg.phase == "leave" and msg.fruit_id == 1


def test_without_retracing_the_next_fruit_is_taken_from_where_the_arms_are() -> None:
    core, goals, _ = drive_to_a_stall(retrace=False)
    m = core.machine
    assert m.phase == "approach" and m.retrace is None  # straight on (the only fruit again)
    assert all(g.joints_rad is None for g in goals)


def test_a_retrace_that_cannot_go_on_says_how_far_short_it_stopped() -> None:
    core, _, t = drive_to_a_stall(retrace=True)
    m = core.machine
    while m.phase == "leave" and t < 20 * NS:  # the arms stay where they got stuck
        t += TICK_NS
        m.step(t, status(m.next_seq, 0.05, t), m.next_seq + 1, 0)
    assert m.phase == "approach" and m.retrace is None
    back = [e for e in m.events if e.event == "phase_changed" and e.phase_from == "leave"]
    assert back[-1].reason == "retrace stuck, 0.90 rad short of where the attempt began"
