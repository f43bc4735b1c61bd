"""With ``branch_check`` the planner refuses, before the approach, a fruit whose tools can only
take their poses through occupied space the scene has seen (a branch under the fruit where the
dish goes), those spheres the scene's keep-out leaves out of the obstacles included. The first
refusal defers the fruit (what reads as a branch may be a hand passing); the second is final.
Only the tools (the bodies on each arm's last joint) are measured, and the fruit's own twig
above it is not in the way."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from schemas.base import Header
from schemas.scene import Obstacles, SceneState, SphereObstacle, Trunk
from services.planner.bench import fate_of
from services.planner.branchcheck import BranchCheck
from services.planner.clutter import intrusions_m
from services.planner.core import PlannerCore
from services.planner.poses import FruitShape, harvest_pose, pre_pose
from services.robot.model import TOOLS
from tests.unit.test_planner_select import A, C, core_with, fruit, select


def branch(through: np.ndarray, name: str = "b") -> tuple[SphereObstacle, ...]:
    """Spheres (3 cm) along a horizontal branch across the camera's view through ``through``."""
    return tuple(
        SphereObstacle(
            name=f"{name}{k}", center_world_m=tuple(through + np.array([0, y, 0])), radius_m=0.03
        )
        for k, y in enumerate(np.arange(-0.2, 0.21, 0.03))
    )


def scene(
    spheres: tuple[SphereObstacle, ...], near: tuple[SphereObstacle, ...] = (), at_s: float = 0.0
) -> SceneState:
    return SceneState(
        header=Header(stamp_ns=round(at_s * 1e9), seq=99, source="scene"),
        trunk=Trunk(found=False),
        obstacles=Obstacles(spheres=spheres),
        spheres_near_selected=near,
    )


def checking(*, on: bool = True, order: str = "nearest", own_branch_m: float = 0.1) -> PlannerCore:
    core = core_with(order, fruit(1, A, 0.5), fruit(3, C, 0.7))
    core.s = core.machine.s = core.s.model_copy(update={"branch_check": on})
    core.machine.branches = (
        BranchCheck(core.s.branch_check_depth_m, own_branch_m, recall=core.s.branch_check_recall)
        if on
        else None
    )
    return core


def dish_level(core: PlannerCore) -> np.ndarray:
    """A point in the middle of where the dish sits under fruit 1 at its harvest pose."""
    h = harvest_pose(core.book.records[1].planned, core.machine.pose_settings)
    return h.tip_world_m - np.array([0, 0, h.basket_below_m])


def skips(core: PlannerCore, fid: int) -> list[str]:
    return [
        e.reason for e in core.machine.events if e.event == "fruit_skipped" and e.fruit_id == fid
    ]


@pytest.mark.parametrize("order", ["nearest", "planned"])
@pytest.mark.parametrize("keep_out", [False, True])
def test_a_branch_where_the_dish_goes_defers_the_fruit_then_refuses_it(
    keep_out: bool, order: str
) -> None:
    core = checking(order=order)
    spheres = branch(dish_level(core))
    assert core.machine.branches is not None
    core.machine.branches.set_scene(scene((), spheres) if keep_out else scene(spheres))
    assert select(core) == 3  # fruit 1 waits, the next one is taken
    rec = core.book.records[1]
    assert rec.deferred and not rec.finished
    (first,) = skips(core, 1)
    assert first.startswith("blocked: a branch in the tools' way at the harvest pose")
    assert "puts a tool" in first and "mm into the occupied space seen" in first
    assert first.endswith("retried after the others")
    core.book.records[3].outcome = "harvested"
    # Only fruit 1 is left: the arms wait at the ready pose for another look, then (the branch
    # still there) it is given up.
    recheck_s = core.s.branch_check_recheck_s
    assert select(core, recheck_s - 0.1) is None and not rec.finished
    assert core.machine.phase == "home" and len(skips(core, 1)) == 1
    assert select(core, recheck_s) is None
    assert rec.outcome == "unreachable" and rec.finished
    assert skips(core, 1)[1].startswith("unreachable: a branch in the tools' way")


def test_an_unseen_fruit_in_the_way_is_named_as_such() -> None:
    """The scene's unseen-fruit spheres (fruit-coloured space no estimate explains) refuse a
    fruit as branches do, and the reason says which it was; the bench counts it apart."""
    core = checking()
    assert core.machine.branches is not None
    at = dish_level(core)
    hidden = (SphereObstacle(name="unseen_fruit_0", center_world_m=tuple(at), radius_m=0.04),)
    far = branch(at + np.array([0, 0, -0.5]))  # a branch well clear: the fruit is named
    core.machine.branches.set_scene(scene(hidden + far))
    assert select(core) == 3
    (first,) = skips(core, 1)
    assert first.startswith("blocked: a fruit the detector has not found in the tools' way")
    core.book.records[3].outcome = "harvested"
    assert select(core, core.s.branch_check_recheck_s) is None
    final = skips(core, 1)[1]
    assert fate_of("unreachable", final, 1.0) == "unseen_fruit_refused"
    assert fate_of("unreachable", "unreachable: a branch in the tools' way", 1.0) == (
        "branch_refused"
    )


def test_what_was_felt_only_on_the_fruits_own_attempts_does_not_refuse_it() -> None:
    """The scene's felt spheres carry the fruit they are part of (felt on its attempts alone: its
    own branch, met by a stalled approach, left to the dampers; or on its skin); another
    fruit's, or anyone's, refuses it."""
    core = checking()
    assert core.machine.branches is not None
    at = dish_level(core)

    def felt_here(own: tuple[int, ...]) -> SceneState:
        return scene(
            tuple(
                SphereObstacle(
                    name=f"touched_occupied_{k}",
                    center_world_m=tuple(at + np.array([0, y, 0])),
                    radius_m=0.035,
                    own_fruit_ids=own,
                )
                for k, y in enumerate((-0.03, 0.0, 0.03))
            )
        )

    core.machine.branches.set_scene(felt_here((1, 3)))
    assert select(core) == 1 and skips(core, 1) == []
    for other in ((3,), ()):
        core = checking()
        assert core.machine.branches is not None
        core.machine.branches.set_scene(felt_here(other))
        assert select(core) == 3
        (first,) = skips(core, 1)
        assert first.startswith("blocked: something the arms felt in the tools' way")


def test_a_fruit_deferred_for_something_else_gets_its_own_second_look() -> None:
    """Deferred before (a stalled attempt, a blocker) and then refused by the check for the
    first time: it waits for another look at the branches, it is not given up at once."""
    core = checking()
    assert core.machine.branches is not None
    rec = core.book.records[1]
    rec.deferred = True
    core.book.records[3].outcome = "harvested"
    core.machine.branches.set_scene(scene(branch(dish_level(core))))
    assert select(core, 5.0) is None and not rec.finished and rec.branch_refused_ns == 5e9
    assert core.machine.phase == "home"
    assert select(core, 5.0 + core.s.branch_check_recheck_s) is None and rec.finished


def test_what_was_gone_at_the_second_look_is_harvested() -> None:
    core = checking()
    assert core.machine.branches is not None
    core.machine.branches.set_scene(scene(branch(dish_level(core))))  # a hand passing under it
    assert select(core) == 3
    core.book.records[3].outcome = "harvested"
    core.machine.branches.set_scene(scene(()))
    assert select(core, core.s.branch_check_recheck_s) == 1
    assert not core.book.records[1].finished


def test_branches_elsewhere_or_no_check_leave_the_fruit_alone() -> None:
    core = checking()
    assert core.machine.branches is not None
    far = branch(dish_level(core) + np.array([0, 0, -0.5]))  # half a metre under the dish
    core.machine.branches.set_scene(scene(far))
    assert select(core) == 1 and not core.book.records[1].finished
    off = checking(on=False)  # branch_check=false: the branches are the dampers' business
    assert off.machine.branches is None and select(off) == 1


def test_the_fruits_own_twig_above_it_is_not_in_the_way() -> None:
    """The cutter closes on the peduncle: spheres where its twig meets the branch, just above
    the fruit's top, are the fruit's own; the same spheres under own_branch_m 0 refuse it."""
    for own, refused in ((0.1, False), (0.0, True)):
        core = checking(own_branch_m=own)
        assert core.machine.branches is not None
        h = harvest_pose(core.book.records[1].planned, core.machine.pose_settings)
        core.machine.branches.set_scene(scene(branch(h.tip_world_m + np.array([0, 0, 0.01]))))
        assert (select(core) == 3) is refused
        assert core.book.records[1].deferred is refused


def test_only_the_tools_are_measured() -> None:
    """A sphere on the cutter's elbow does not count, one on its shears does."""
    check = BranchCheck(0.02, 0.1)
    core = checking()
    h = harvest_pose(core.book.records[1].planned, core.machine.pose_settings)
    q = core.kin.solutions(replace(h, basket_back_m=0.0))[0].q_rad
    robot = check.space.robot
    robot.set_q(q)
    for frame, counts in (("cutter_link4", False), ("cutter_tool", True)):
        p = robot.robot.get_T_world_frame(frame)[:3, 3]
        sphere = SphereObstacle(name="s", center_world_m=tuple(map(float, p)), radius_m=0.03)
        check.space.set_obstacles(Obstacles(spheres=(sphere,)))
        assert check.space.clearance(q).obstacles_m < 0  # the whole robot touches it
        assert (check.tool_depth_m(q) > 0.02) is counts


def test_the_core_builds_the_check_and_gives_it_every_scene_state() -> None:
    from services.planner import Settings
    from services.runtime.settings import load_settings
    from tests.unit.test_planner_bench_fates import TICK_NS, status

    core = PlannerCore(load_settings(Settings, {"branch_check": True}))
    assert core.machine.branches is not None
    spheres = branch(np.array([0.7, 0.0, 1.2]))
    core.handle("scene/state", scene(spheres[:3], spheres[3:]))
    core.handle("control/status", status(0, 0.0, TICK_NS))
    assert len(core.machine.branches.spheres) == len(spheres)  # the keep-out's included


def test_what_came_after_the_start_counts_once_it_stayed() -> None:
    """A hand passing under the fruit from 4 s on is occupied space while it is seen: the check
    does not refuse the fruit for it; what is still listed 2 s later does count, and a sphere
    that left the list starts its age again (with ``branch_check_recall``, on by default, one
    back in a cell where a sphere counted before counts at once)."""
    core = checking()
    check = core.machine.branches
    assert check is not None
    hand = branch(dish_level(core))
    check.set_scene(scene((), at_s=0.0))
    check.set_scene(scene(hand, at_s=4.0))
    assert check.young == len(hand) and select(core) == 1  # not refused
    check.set_scene(scene(hand, at_s=6.1))
    assert check.young == 0 and select(core) == 3  # it stayed: fruit 1 waits
    check.set_scene(scene((), at_s=6.2))
    check.set_scene(scene(hand, at_s=6.3))
    assert check.recall and check.young == 0  # back where it counted: counts at once
    check.recall = False
    check.set_scene(scene((), at_s=6.4))
    check.set_scene(scene(hand, at_s=6.5))
    assert check.young == len(hand)


@pytest.mark.parametrize("dish_under", [True, False])
def test_a_branch_behind_the_dish_sends_it_right_under_the_fruit(dish_under: bool) -> None:
    """The pose rule sets the dish 1.5 cm back towards the robot (dish_back_m, cut by the catch
    margin). A branch just behind that place refuses those poses; with the dish right under the
    tip they are clear, so the fruit is taken with the dish there, and the controller is sent
    that place (``branch_check_dish_under``; off: deferred, as before session 40). The dish
    stays at the rule's height (``branch_check_dish_lower_m`` off): that is the next test's."""
    core = checking()
    m = core.machine
    update = {"branch_check_dish_under": dish_under, "branch_check_dish_lower_m": 0.0}
    m.s = core.s = core.s.model_copy(update=update)
    assert m.branches is not None
    rec = core.book.records[1]
    assert harvest_pose(rec.planned, m.pose_settings).basket_back_m > 0.01
    behind = tuple(
        SphereObstacle(
            name=f"b{k}",
            center_world_m=tuple(dish_level(core) + np.array([-0.10, y, 0.04])),
            radius_m=0.03,
        )
        for k, y in enumerate(np.arange(-0.06, 0.061, 0.03))
    )
    m.branches.set_scene(scene(behind))
    if not dish_under:
        assert select(core) == 3 and rec.deferred
        assert skips(core, 1)[0].startswith("blocked: a branch in the tools' way at the harvest")
        return
    assert select(core) == 1 and rec.dish_back_m == 0.0
    (why,) = [e.reason for e in m.events if e.event == "fruit_selected"]
    assert why.endswith("the dish right under it (the branches seen leave no room farther back)")
    m.phase = "harvest"
    goal = m.goal()
    assert goal.poses is not None and goal.poses.basket_back_m == 0.0
    m.branches.set_scene(scene(()))  # the branch gone: the rule's place again
    assert select(core) == 1 and rec.dish_back_m is None


def rim_branch(core: PlannerCore, above_rim_m: float) -> tuple[SphereObstacle, ...]:
    """A branch across the view 7 cm beyond the middle of fruit 1's dish (the pose rule's),
    ``above_rim_m`` over its rim top: under the fruit, where the rim meets it."""
    return branch(dish_level(core) + np.array([0.07, 0.0, TOOLS.basket_rim_height_m + above_rim_m]))


def lowering(core: PlannerCore, lower_m: float) -> None:
    m = core.machine
    m.s = core.s = core.s.model_copy(update={"branch_check_dish_lower_m": lower_m})


@pytest.mark.parametrize("lower_m", [0.0, 0.02])
def test_a_branch_over_the_rim_sends_the_dish_lower(lower_m: float) -> None:
    """A branch 1.5 cm over the rule's rim: the tools 15 mm into its spheres, within the 20 mm
    allowed, so the fruit is taken either way. With ``branch_check_dish_lower_m`` the dish goes
    that much lower at the harvest pose and the pre-pose (clear of the spheres there), and back
    to the rule's height once the branch is gone."""
    core = checking()
    lowering(core, lower_m)
    m = core.machine
    assert m.branches is not None
    rec = core.book.records[1]
    m.branches.set_scene(scene(rim_branch(core, 0.015)))
    assert select(core) == 1 and rec.dish_lower_m == lower_m
    (why,) = [e.reason for e in m.events if e.event == "fruit_selected"]
    assert why.endswith("; the dish 2 cm lower (a branch seen over its rim)") == (lower_m > 0)
    for phase, rule in (("harvest", harvest_pose), ("approach", pre_pose)):
        m.phase = phase
        goal = m.goal()
        assert goal.poses is not None
        want = rule(rec.planned, m.pose_settings).basket_below_m + lower_m
        assert goal.poses.basket_below_m == pytest.approx(want)
    m.branches.set_scene(scene(()))
    assert select(core) == 1 and rec.dish_lower_m == 0.0


@pytest.mark.parametrize("lower_m", [0.0, 0.02])
def test_a_branch_on_the_rim_is_cleared_by_a_lower_dish(lower_m: float) -> None:
    """The branch at the rim's height: the rule's tools 30 mm into its spheres, refused (the
    fruit waits, as before); the dish 2 cm lower is within the allowance, so it is taken."""
    core = checking()
    lowering(core, lower_m)
    assert core.machine.branches is not None
    core.machine.branches.set_scene(scene(rim_branch(core, 0.0)))
    rec = core.book.records[1]
    if lower_m == 0.0:
        assert select(core) == 3 and rec.deferred
        return
    assert select(core) == 1 and rec.dish_lower_m == lower_m and not rec.deferred


def test_the_dish_is_not_lowered_into_a_neighbour() -> None:
    """A fruit hanging just under where the lower dish would go (clear of the rule's): the
    dish stays at the rule's height, touching the branch's spheres as allowed."""
    base = checking()
    settings = base.machine.pose_settings
    rec_a = base.book.records[1].planned
    # 23.5 cm under the tip: a centimetre under the rule's dish sweep (the pre-pose's dish is
    # the lowest), a centimetre into the sweep of one 2 cm lower.
    under = harvest_pose(rec_a, settings).tip_world_m - np.array([0.0, 0.0, 0.235])
    below = fruit(5, (float(under[0]), float(under[1]), float(under[2])), 0.6)
    shape = FruitShape(np.array(below.position_world_m), 0.04, 0.04)
    clearance = base.s.neighbour_clearance_m
    low = replace(settings, basket_clearance_m=settings.basket_clearance_m + 0.02)
    assert intrusions_m(rec_a, [shape], settings, clearance)[0] <= 0.0
    assert intrusions_m(rec_a, [shape], low, clearance)[0] > 0.0
    core = core_with("nearest", fruit(1, A, 0.5), fruit(3, C, 0.7), below)
    core.s = core.machine.s = core.s.model_copy(update={"branch_check": True})
    core.machine.branches = BranchCheck(core.s.branch_check_depth_m, 0.1)
    lowering(core, 0.02)
    core.machine.branches.set_scene(scene(rim_branch(core, 0.015)))
    assert select(core) == 1 and core.book.records[1].dish_lower_m == 0.0


@pytest.mark.parametrize("recall", [False, True])
def test_a_branch_seen_again_counts_at_once_with_recall(recall: bool) -> None:
    """A branch where the dish goes, seen from the start, leaves the list (an arm hid it) and
    comes back. Without ``recall`` it is young again for 2 s and the fruit is taken; with it,
    it counts at once (also 4 cm over, its mean in the next cell), and the fruit waits. A
    sphere never counted before is still young with ``recall``. The dish is not lowered
    (``branch_check_dish_lower_m`` off): under this branch the lower dish would be clear."""
    core = checking()
    lowering(core, 0.0)
    check = core.machine.branches
    assert check is not None
    check.recall = recall
    spheres = branch(dish_level(core))
    check.set_scene(scene(spheres, at_s=0.0))
    assert check.young == 0
    check.set_scene(scene((), at_s=5.0))
    up = np.array([0.0, 0.0, 0.04])  # a whole cell up: the next cell
    moved = tuple(
        s.model_copy(update={"center_world_m": tuple(np.asarray(s.center_world_m) + up)})
        for s in spheres
    )
    check.set_scene(scene(moved, at_s=5.1))
    assert check.young == (0 if recall else len(spheres))
    assert select(core, 5.1) == (3 if recall else 1)
    elsewhere = branch(dish_level(core) + np.array([0.0, 0.0, 0.3]), "far")
    check.set_scene(scene(moved + elsewhere, at_s=5.2))
    assert check.young == len(elsewhere) + (0 if recall else len(spheres))
