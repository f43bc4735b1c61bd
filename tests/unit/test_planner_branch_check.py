"""With ``branch_check`` the planner refuses, before the approach, a fruit whose tools can only
take their poses through occupied space the scene has seen (a branch under the fruit where the
dish goes), those spheres the scene's keep-out leaves out of the obstacles included."""

from __future__ import annotations

import numpy as np
import pytest

from schemas.base import Header
from schemas.scene import Obstacles, SceneState, SphereObstacle, Trunk
from services.planner.branchcheck import BranchCheck
from services.planner.core import PlannerCore
from services.planner.poses import harvest_pose
from tests.unit.test_planner_select import A, C, core_with, fruit, select


def branch(through: np.ndarray, name: str = "b") -> tuple[SphereObstacle, ...]:
    """Spheres (3 cm) along a horizontal branch across the camera's view through ``through``."""
    return tuple(
        SphereObstacle(
            name=f"{name}{k}", center_world_m=tuple(through + np.array([0, y, 0])), radius_m=0.03
        )
        for k, y in enumerate(np.arange(-0.2, 0.21, 0.03))
    )


def scene(spheres: tuple[SphereObstacle, ...], near: tuple[SphereObstacle, ...] = ()) -> SceneState:
    return SceneState(
        header=Header(stamp_ns=0, seq=99, source="scene"),
        trunk=Trunk(found=False),
        obstacles=Obstacles(spheres=spheres),
        spheres_near_selected=near,
    )


def checking(*, on: bool = True) -> PlannerCore:
    core = core_with("nearest", fruit(1, A, 0.5), fruit(3, C, 0.7))
    core.s = core.machine.s = core.s.model_copy(update={"branch_check": on})
    core.machine.branches = BranchCheck(core.s.branch_check_depth_m) if on else None
    return core


def dish_level(core: PlannerCore) -> np.ndarray:
    """A point in the middle of where the dish sits under fruit 1 at its harvest pose."""
    h = harvest_pose(core.book.records[1].planned, core.machine.pose_settings)
    return h.tip_world_m - np.array([0, 0, h.basket_below_m])


@pytest.mark.parametrize("keep_out", [False, True])
def test_a_branch_where_the_dish_goes_makes_the_fruit_unreachable(keep_out: bool) -> None:
    core = checking()
    spheres = branch(dish_level(core))
    assert core.machine.branches is not None
    core.machine.branches.set_scene(scene((), spheres) if keep_out else scene(spheres))
    assert select(core) == 3  # the next one
    rec = core.book.records[1]
    assert rec.outcome == "unreachable" and rec.finished
    skip = next(e for e in core.machine.events if e.event == "fruit_skipped")
    assert skip.fruit_id == 1 and "a branch in the tools' way at the harvest pose" in skip.reason
    assert "IK solutions" in skip.reason and "mm into the occupied space seen" in skip.reason


def test_branches_elsewhere_or_no_check_leave_the_fruit_alone() -> None:
    core = checking()
    assert core.machine.branches is not None
    far = branch(dish_level(core) + np.array([0, 0, -0.5]))  # half a metre under the dish
    core.machine.branches.set_scene(scene(far))
    assert select(core) == 1 and not core.book.records[1].finished
    off = checking(on=False)  # the default: the scene's branches are the dampers' business
    assert off.machine.branches is None and select(off) == 1


def test_the_core_builds_the_check_and_gives_it_every_scene_state() -> None:
    from services.planner import Settings
    from services.runtime.settings import load_settings
    from tests.unit.test_planner_bench_fates import TICK_NS, status

    core = PlannerCore(load_settings(Settings, {"branch_check": True}))
    assert core.machine.branches is not None
    spheres = branch(np.array([0.7, 0.0, 1.2]))
    core.handle("scene/state", scene(spheres[:3], spheres[3:]))
    core.handle("control/status", status(0, 0.0, TICK_NS))
    assert core.machine.branches.spheres == len(spheres)  # the keep-out's included
