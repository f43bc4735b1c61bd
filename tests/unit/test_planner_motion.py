"""The planned approach (services/planner/motion.py, freespace.py and the machine): a joint
path from the arms' joints to the pre-pose's IK solution around the scene's obstacles, followed
as joint goals, then the pose goals."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pytest

from schemas.base import ARM_ROLES
from schemas.scene import CylinderObstacle, EllipsoidObstacle, Obstacles, SphereObstacle, Trunk
from services.planner.core import PlannerCore
from services.planner.kinematics import IkSolution
from services.planner.machine import Goal
from services.planner.motion import ApproachPlanner, trunk_for
from services.planner.poses import FruitShape, harvest_pose, pre_pose
from services.robot.model import HOME_RAD, TOOL_FRAME
from tests.unit.test_planner_bench_fates import NS, TICK_NS, status
from tests.unit.test_planner_select import A, core_with, fruit

HOME = np.array([v for r in ARM_ROLES for v in HOME_RAD[r]], float)


def planned_core() -> PlannerCore:
    """A core with one fruit at A, the real IK and the approach planner."""
    core = core_with("nearest", fruit(1, A, 0.5))
    m = core.machine
    m.s = m.s.model_copy(update={"plan_approach": "always"})
    m.motion = ApproachPlanner(m.s)
    core.book.records[1].reach = None  # the real IK (the verdict carries its joints)
    return core


def pre_pose_solutions(core: PlannerCore) -> list[IkSolution]:
    rec = core.book.records[1]
    solutions = core.kin.solutions(pre_pose(rec.planned, core.machine.pose_settings))
    assert solutions
    return solutions


def pre_pose_solution(core: PlannerCore) -> IkSolution:
    return pre_pose_solutions(core)[0]


def pre_pose_joints(core: PlannerCore) -> np.ndarray:
    return pre_pose_solution(core).q_rad


def ik(*qs: np.ndarray) -> list[IkSolution]:
    return [IkSolution(0.0, q) for q in qs]


def test_a_branch_on_the_straight_way_is_gone_round_to_the_clearest_goal() -> None:
    core = planned_core()
    goal = pre_pose_joints(core)
    planner = ApproachPlanner(core.machine.s)
    space = planner.space
    mid = HOME + 0.3 * (goal - HOME)
    space.robot.set_q(mid)  # a branch where the cutter's tip would pass
    tip = space.robot.T_world(TOOL_FRAME["cutter"])[:3, 3]
    planner.obstacles = Obstacles(
        spheres=(SphereObstacle(name="occupied_1", center_world_m=tuple(tip), radius_m=0.02),)
    )
    space.set_obstacles(planner.obstacles)
    s = core.machine.s
    assert space.clearance(mid).obstacles_m < 0  # the straight way hits it, the ends are clear
    assert min(space.clearance(HOME).obstacles_m, space.clearance(goal).obstacles_m) > 0.05
    plan = planner.plan(HOME, ik(mid, goal), core.book.records[1].planned, seed=1)
    assert plan.path is not None, plan.why
    assert plan.why.startswith("planned joint path")
    assert np.allclose(plan.path[0], HOME) and np.allclose(plan.path[-1], goal)
    assert all(np.abs(b - a).max() <= 0.05 + 1e-9 for a, b in pairwise(plan.path))
    lo, hi = space.lower_rad + s.plan_limit_margin_rad, space.upper_rad - s.plan_limit_margin_rad
    for q in plan.path:
        c = space.clearance(q)
        assert c.obstacles_m >= s.plan_margin_m and c.self_m >= s.plan_self_margin_m
        far = min(np.abs(q - HOME).max(), np.abs(q - goal).max()) > s.plan_escape_rad
        assert not far or bool(np.all((q >= lo) & (q <= hi)))  # inside the limits' margin


def test_no_path_is_reported_and_the_pose_goals_are_used() -> None:
    core = planned_core()
    goal = pre_pose_joints(core)
    planner = ApproachPlanner(core.machine.s.model_copy(update={"plan_max_checks": 50}))
    planner.space.robot.set_q(HOME)
    tip = planner.space.robot.T_world(TOOL_FRAME["cutter"])[:3, 3]
    # a sphere swallowing the tool at the start, its surface farther than the escape allows
    planner.obstacles = Obstacles(
        spheres=(SphereObstacle(name="occupied_1", center_world_m=tuple(tip), radius_m=0.3),)
    )
    plan = planner.plan(HOME, ik(goal), core.book.records[1].planned, seed=1)
    assert plan.path is None
    assert plan.why.startswith("no planned path (") and plan.why.endswith("pose goals")


def elbow_in_a_branch(
    core: PlannerCore, planner: ApproachPlanner, radius_m: float = 0.03, fruit: bool = False
) -> IkSolution:
    """A branch sphere (or a fruit) on the collector's elbow at the pre-pose's IK solution (at
    25° yaw: at 0° the elbow's centre falls on the end of the third link's capsule axis, which
    reads 95 mm deep instead of the sphere's 30)."""
    sol = next(s for s in pre_pose_solutions(core) if s.yaw_deg == 25.0)
    robot = planner.space.robot
    robot.set_q(sol.q_rad)
    elbow = tuple(robot.data.oMi[robot.model.getJointId("collector_j4")].translation)
    if fruit:
        axes = (radius_m,) * 3
        f = EllipsoidObstacle(name="fruit_7", fruit_id=7, center_world_m=elbow, semi_axes_m=axes)
        planner.obstacles = Obstacles(ellipsoids=(f,))
    else:
        sphere = SphereObstacle(name="occupied_1", center_world_m=elbow, radius_m=radius_m)
        planner.obstacles = Obstacles(spheres=(sphere,))
    return sol


def test_a_goal_with_an_elbow_in_a_branch_is_moved_clear_with_the_tools_held() -> None:
    core = planned_core()
    s, rec = core.machine.s, core.book.records[1]
    pose = pre_pose(rec.planned, core.machine.pose_settings)
    plain = ApproachPlanner(s.model_copy(update={"plan_max_checks": 300}))  # no IK: as it is
    sol = elbow_in_a_branch(core, plain)
    got = plain.plan(HOME, [sol], rec.planned, 1, pose)
    assert got.path is None and "the goal is 30 mm inside a branch" in got.why

    planner = ApproachPlanner(s, core.kin.solver)
    sol = elbow_in_a_branch(core, planner)
    plan = planner.plan(HOME, [sol], rec.planned, 1, pose)
    assert plan.path is not None, plan.why
    assert "goal moved clear of -30 mm (branch)" in plan.why
    end = plan.path[-1]
    assert planner.space.clearance(end).obstacles_m >= s.plan_goal_margin_m - 1e-3
    assert np.abs(end - sol.q_rad).max() > 0.2  # the arm is elsewhere ...
    planner.space.robot.set_q(end)
    tip = planner.space.robot.T_world(TOOL_FRAME["cutter"])[:3, 3]
    assert np.linalg.norm(tip - pose.tip_world_m) < s.reach_tolerance_m  # ... the tools are not


def test_a_fruit_the_controller_ignores_is_no_obstacle_to_the_plan() -> None:
    """A harvested fruit the scene still lists where it hung (a ghost) is ignored by the
    controller; a plan that avoided it went round nothing (paper-exp1 seed 0: a ghost 3 mm from
    the dish at the start of every plan)."""
    core = planned_core()
    s, rec = core.machine.s, core.book.records[1]
    planner = ApproachPlanner(s.model_copy(update={"plan_max_checks": 50}))
    planner.space.robot.set_q(HOME)
    tip = planner.space.robot.T_world(TOOL_FRAME["cutter"])[:3, 3]
    ghost = EllipsoidObstacle(
        name="fruit_7", fruit_id=7, center_world_m=tuple(tip), semi_axes_m=(0.3, 0.3, 0.3)
    )
    planner.obstacles = Obstacles(ellipsoids=(ghost,))
    goal = pre_pose_joints(core)
    assert planner.plan(HOME, ik(goal), rec.planned, 1).path is None
    plan = planner.plan(HOME, ik(goal), rec.planned, 1, ignore_fruit_ids=(7,))
    assert plan.path is not None and "clear at the start" in plan.why


def run(core: PlannerCore, until_s: float) -> list[Goal]:
    """The arms follow joint goals at 0.02 rad per tick (pose goals: they stay), the tools'
    error is 0 once the pose goals come."""
    m, t, q = core.machine, 0, HOME.copy()
    m.note_joints(q)
    goals: list[Goal] = []
    while t < until_s * NS:
        t += TICK_NS
        err = 0.0 if goals and goals[-1].poses is not None and goals[-1].fruit_id else 0.1
        g = m.step(t, status(m.next_seq, err, t), m.next_seq + 1, 0)
        goals.append(g)
        if g.joints_rad is not None:
            q = q + np.clip(g.joints_rad - q, -0.02, 0.02)
            m.note_joints(q)
    return goals


def test_the_approach_follows_the_path_then_sends_the_pose_goals() -> None:
    core = planned_core()
    goals = run(core, 6.0)
    m = core.machine
    approach = [g for g in goals if g.phase == "approach"]
    joint = [k for k, g in enumerate(approach) if g.joints_rad is not None]
    assert joint and joint[0] == 0  # the path first ...
    i = joint[-1]
    assert all(g.poses is not None and g.joints_rad is None for g in approach[i + 1 :])  # ...
    assert len(approach) > i + 1  # ... then the pose goals
    last = approach[i].joints_rad
    assert last is not None and np.abs(last - pre_pose_joints(core)).max() < 1e-9
    entered = [e for e in m.events if e.event == "phase_changed" and e.phase_to == "approach"]
    assert entered[0].reason.startswith("planned joint path")
    assert m.motion is not None and m.motion.found == 1


def test_without_the_setting_there_is_no_path() -> None:
    core = core_with("nearest", fruit(1, A, 0.5), plan_approach="off")
    core.book.records[1].reach = None
    goals = run(core, 2.0)
    assert core.machine.motion is None
    assert all(g.joints_rad is None for g in goals)


def test_the_trunk_is_resized_for_the_new_target() -> None:
    old = Obstacles(
        cylinders=(
            CylinderObstacle(name="trunk", axis_point_world_m=(1.0, 0.0, 0.0), radius_m=0.5),
        )
    )
    trunk = Trunk(found=True, radius_m=0.1)
    near = FruitShape(np.array([1.3, 0.0, 1.2]), 0.04, 0.04)  # 0.3 m from the axis
    got = trunk_for(old, trunk, near, margin_m=0.08)
    assert got.cylinders[0].radius_m == pytest.approx(0.3 - 0.04 - 0.08)
    touching = FruitShape(np.array([1.15, 0.0, 1.2]), 0.04, 0.04)  # never inside the trunk
    assert trunk_for(old, trunk, touching, 0.08).cylinders[0].radius_m == pytest.approx(0.1)
    assert trunk_for(old, None, near, 0.08) is old  # no trunk estimate: as the scene has it


def test_a_path_the_arms_cannot_follow_is_planned_again_then_left() -> None:
    core = planned_core()
    m, t = core.machine, 0
    m.note_joints(HOME)  # the arms never move
    while t < 10 * NS and not any(e.event == "fruit_skipped" for e in m.events):
        t += TICK_NS
        m.step(t, status(m.next_seq, 0.1, t), m.next_seq + 1, 0)
    why = [e.reason for e in m.events if e.event == "replanned"]
    assert why[0].startswith("planned path stuck") and "planned again, planned joint path" in why[0]
    assert why[1].startswith("planned path stuck") and why[1].endswith("pose goals")
    assert m.motion is not None and m.motion.plans == 3  # the plan, once again; the retry's


def test_after_a_stall_the_approach_gets_a_planned_path() -> None:
    core = planned_core()
    m = core.machine
    m.s = m.s.model_copy(update={"plan_approach": "after_stall", "plan_retries": 0})
    t, q = 0, HOME.copy()
    m.note_joints(q)
    goals: list[Goal] = []
    while t < 10 * NS and not any(e.phase_to == "harvest" for e in m.events):
        t += TICK_NS
        followed = any(g.joints_rad is not None for g in goals)
        err = 0.0 if followed and goals[-1].joints_rad is None else 0.1  # stuck until the path
        g = m.step(t, status(m.next_seq, err, t), m.next_seq + 1, 0)
        goals.append(g)
        if g.joints_rad is not None:
            q = q + np.clip(g.joints_rad - q, -0.02, 0.02)
            m.note_joints(q)
    first = next(k for k, g in enumerate(goals) if g.joints_rad is not None)
    assert first > 0 and all(g.poses is not None for g in goals[1:first])  # the pose goals first
    why = [e.reason for e in m.events if e.event == "replanned"]
    assert why[0].startswith("approach no progress") and "planned joint path" in why[0]
    assert any(e.phase_to == "harvest" for e in m.events)
    assert not any(e.event == "fruit_skipped" for e in m.events)


def test_no_path_to_a_goal_in_a_branch_but_one_in_a_fruit_is_planned_for() -> None:
    """plan_goal_max_depth_m: the dampers stop the arms short of a goal inside a branch, in
    contact (paper-exp1 seed 9: a path to a goal 53 mm inside one, then 12 contacts; orchard
    seed 9: 9 mm inside, 89 contacts). A fruit swings aside. The depth allowed is a setting
    (0 by default; 2 cm, the branch check's depth, up to session 29)."""
    core = planned_core()
    s, rec = core.machine.s, core.book.records[1]
    pose = pre_pose(rec.planned, core.machine.pose_settings)
    plain = ApproachPlanner(s.model_copy(update={"plan_max_checks": 50}))  # goals as they are
    deep = plain.plan(HOME, [elbow_in_a_branch(core, plain)], rec.planned, 1, pose)
    assert deep.path is None
    assert deep.why == "no planned path (the goal is 30 mm inside a branch): pose goals"
    assert plain.space.checks < 10  # refused before any search
    twig = plain.plan(HOME, [elbow_in_a_branch(core, plain, 0.01)], rec.planned, 1, pose)
    assert twig.path is None and "the goal is" in twig.why and "inside a branch" in twig.why
    got = plain.plan(HOME, [elbow_in_a_branch(core, plain, fruit=True)], rec.planned, 1, pose)
    assert "the goal is" not in got.why and "at the end" in got.why, got.why
    upd = {"plan_max_checks": 50, "plan_goal_max_depth_m": 0.02}
    old = ApproachPlanner(s.model_copy(update=upd))  # session 20's depth: a 1 cm twig allowed
    got = old.plan(HOME, [elbow_in_a_branch(core, old, 0.01)], rec.planned, 1, pose)
    assert "the goal is" not in got.why and "at the end" in got.why, got.why
    off = ApproachPlanner(s.model_copy(update={"plan_max_checks": 50, "plan_goal_max_depth_m": 1}))
    got = off.plan(HOME, [elbow_in_a_branch(core, off)], rec.planned, 1, pose)
    assert "-30 mm (branch) at the end" in got.why


def stalled_away_from_the_way(from_start: bool) -> tuple[PlannerCore, np.ndarray, np.ndarray]:
    """The attempt began at the ready pose and the arms came to a stall 1.2 rad round on the
    cutter's first joint, where a branch sphere sits on the straight way on to the pre-pose;
    the way from the ready pose is clear. 40 checks find no way round it from the stall."""
    core = planned_core()
    m = core.machine
    m.s = m.s.model_copy(update={"plan_max_checks": 40, "plan_from_attempt_start": from_start})
    m.motion = ApproachPlanner(m.s)
    goal = pre_pose_joints(core)
    stuck = HOME.copy()
    stuck[0] += 1.2
    space = m.motion.space
    space.robot.set_q(stuck + 0.5 * (goal - stuck))
    tip = space.robot.T_world(TOOL_FRAME["cutter"])[:3, 3]
    m.motion.obstacles = Obstacles(
        spheres=(SphereObstacle(name="occupied_1", center_world_m=tuple(tip), radius_m=0.03),)
    )
    m.path.start(HOME)
    for k in range(1, 25):  # the joints the arms came in by
        m.path.note(HOME + (stuck - HOME) * k / 24)
    m.q_rad = stuck
    return core, stuck, goal


def test_no_path_from_a_stall_is_planned_from_where_the_attempt_began() -> None:
    core, stuck, goal = stalled_away_from_the_way(from_start=False)
    m, rec = core.machine, core.book.records[1]
    assert m._planned_approach(rec) is None and "no planned path" in m.left_because

    core, stuck, goal = stalled_away_from_the_way(from_start=True)
    m, rec = core.machine, core.book.records[1]
    follow = m._planned_approach(rec)
    assert follow is not None, m.left_because
    assert "from where the attempt began, back along" in m.left_because
    assert m.left_because.startswith("planned joint path")  # counted once by the bench
    way = follow.waypoints
    assert np.allclose(way[0], stuck) and np.allclose(way[-1], goal)
    back = len(m.path.points)
    assert all(np.allclose(a, b) for a, b in zip(way[:back], reversed(m.path.points), strict=True))
    assert all(m.motion.space.clearance(q).obstacles_m >= 0.045 for q in way[back:])


def stalled_harvest(on: bool) -> tuple[PlannerCore, list[Goal], np.ndarray]:
    """The approach reaches its pre-pose; the harvest then holds 25 mm short of its pose (a
    joint at its stop; beyond stalled_cut_tolerance_m) until the arms have followed a joint
    goal, after which the pose is reached. The core, its goals and the harvest pose's IK
    solution nearest HOME."""
    core = core_with("nearest", fruit(1, A, 0.5), harvest_joints_after_stall=on)
    rec = core.book.records[1]
    m = core.machine
    sols = core.kin.solutions(harvest_pose(rec.planned, m.pose_settings))
    assert sols
    nearest = min(sols, key=lambda s: float(np.abs(s.q_rad - HOME).max())).q_rad
    t, q = 0, HOME.copy()
    m.note_joints(q)
    goals: list[Goal] = []
    while t < 20 * NS and not (rec.finished or rec.cuts):
        t += TICK_NS
        followed = any(g.joints_rad is not None for g in goals)
        err = 0.025 if m.phase == "harvest" and not followed else 0.0
        g = m.step(t, status(m.next_seq, err, t), m.next_seq + 1, 0)
        goals.append(g)
        if g.joints_rad is not None:
            q = q + np.clip(g.joints_rad - q, -0.02, 0.02)
            m.note_joints(q)
    return core, goals, nearest


def test_a_stalled_harvest_gets_a_joint_goal_to_the_nearest_ik_solution_then_cuts() -> None:
    core, goals, nearest = stalled_harvest(True)
    m, rec = core.machine, core.book.records[1]
    harvest = [g for g in goals if g.phase == "harvest"]
    first = next(k for k, g in enumerate(harvest) if g.joints_rad is not None)
    assert first > 0 and all(g.poses is not None for g in harvest[:first])  # pose goals first
    joint = harvest[first].joints_rad
    assert joint is not None and np.abs(joint - nearest).max() < 1e-9
    why = [e.reason for e in m.events if e.event == "replanned"]
    assert len(why) == 1 and why[0].startswith("harvest no progress (best task error 25 mm")
    assert "IK solution nearest the arms" in why[0]
    assert rec.cuts == 1 and not rec.finished  # the pose goals again, reached: the cut
    assert harvest[-1].poses is not None


def test_without_the_setting_a_stalled_harvest_is_given_up_for_now() -> None:
    core, goals, _ = stalled_harvest(False)
    rec = core.book.records[1]
    assert all(g.joints_rad is None for g in goals if g.phase == "harvest")
    assert rec.cuts == 0
    skipped = [e.reason for e in core.machine.events if e.event == "fruit_skipped"]
    assert skipped and skipped[0].startswith("blocked: harvest no progress")
