"""What the arms felt: the sim puts its contacts in the joint state, the scene (with
``contact_obstacles``) keeps them as sphere obstacles, but not those on the fruit being
harvested, and forgets them where a fruit is harvested."""

from __future__ import annotations

import numpy as np

from schemas.base import Header
from schemas.harvest import HarvestEvent
from schemas.robot import SensedContact
from services.runtime.settings import load_settings
from services.scene import Settings
from services.scene.core import SceneCore
from services.scene.touched import TouchedParams, TouchedSpace
from tests.scene_helpers import R_WORLD_CAM, T_WORLD_CAM_M, Scene, tracks
from tests.unit.test_scene_self_filter import joint_state

FRUIT_CAM = (0.25, 0.0, 0.7)  # the scene helper's fruit 1, camera frame, m
FRUIT = tuple(float(v) for v in R_WORLD_CAM @ np.array(FRUIT_CAM) + T_WORLD_CAM_M)  # world


def felt(*points: tuple[float, float, float], link: str = "collector_link6") -> list:
    return [SensedContact(link=link, point_world_m=p) for p in points]


def test_points_felt_become_spheres_but_not_in_the_fruits_own_space() -> None:
    t = TouchedSpace(TouchedParams(voxel_m=0.03, sphere_radius_m=0.02))
    a, b = (0.501, 0.101, 1.001), (0.509, 0.109, 1.009)  # one voxel
    own = (np.array([0.8, 0.0, 1.0]), np.array([0.8, 0.0, 1.1]), 0.09)
    assert t.feel(felt(a, b, (0.8, 0.02, 1.0)), 10, ignore=[own]) == 2
    (s,) = t.obstacles()
    assert s.name == "touched_occupied_0" and s.radius_m == 0.02
    assert np.allclose(s.center_world_m, (0.505, 0.105, 1.005))
    keep_out = [(np.array([0.5, 0.1, 1.0]), np.array([0.5, 0.1, 1.0]), 0.05)]
    assert t.obstacles(keep_out) == () and len(t.within(keep_out)) == 1
    assert t.forget_within(np.array([0.5, 0.1, 1.0]), 0.03) == 1 and t.obstacles() == ()
    assert t.feel(felt((1e12, 0.0, 0.0)), 20) == 0  # too far out to bin: left out


def test_a_place_felt_only_on_one_fruits_attempts_or_on_it_is_part_of_it() -> None:
    t = TouchedSpace(TouchedParams(voxel_m=0.03, sphere_radius_m=0.02))
    own, shared, between = (0.505, 0.105, 1.005), (0.605, 0.105, 1.005), (0.705, 0.105, 1.005)
    t.feel(felt(own, shared), 10, fruit_id=4)
    t.feel(felt(own), 20, fruit_id=4)  # the same fruit's retry: still its own
    t.feel(felt(shared), 30, fruit_id=5)  # felt on another fruit's attempt too: anyone's
    t.feel(felt(between), 40)  # between attempts: anyone's
    by_place = {tuple(round(v, 3) for v in s.center_world_m): s for s in t.obstacles()}
    assert by_place[own].own_fruit_ids == (4,)
    assert by_place[shared].own_fruit_ids == ()
    assert by_place[between].own_fruit_ids == ()
    keep_out = [(np.array(own), np.array(own), 0.05)]  # inside the keep-out: still carried
    (near,) = t.within(keep_out)
    assert near.own_fruit_ids == (4,)
    # a fruit estimated 7 cm from the shared place (radius 8 cm with the margin): on its skin
    centres_m = np.array([[0.675, 0.105, 1.005], [0.2, 0.1, 1.0]])
    fruits = (np.array([9, 2]), centres_m, np.full(2, 0.08))
    by_place = {tuple(round(v, 3) for v in s.center_world_m): s for s in t.obstacles(fruits=fruits)}
    assert by_place[shared].own_fruit_ids == (9,)
    assert by_place[own].own_fruit_ids == (4,)  # 17 cm from fruit 9
    assert by_place[between].own_fruit_ids == (9,)


def event(kind: str, fid: int, stamp_ns: int) -> HarvestEvent:
    return HarvestEvent(header=Header(stamp_ns=stamp_ns, seq=0, source="planner"), event=kind,
                        fruit_id=fid)  # fmt: skip


def scene_state(core: SceneCore, sc: Scene, k: int):  # type: ignore[no-untyped-def]
    core.handle("camera/rgbd", sc.frame(k, 1000 * (k + 1)))
    (out,) = core.handle("perception/tracks", tracks(k, 1000 * (k + 1), k, {1: sc.box(1)}))
    return out[1]


def touched(state) -> list:  # type: ignore[no-untyped-def]
    return [s for s in state.obstacles.spheres if s.name.startswith("touched_")]


def test_the_scene_keeps_what_the_arms_felt_and_forgets_it_with_the_fruit() -> None:
    sc = Scene()
    sc.ellipsoid(FRUIT_CAM, 0.04, 0.045, label=1)
    base = {"robot_self_filter": False, "occupancy_near_radius_m": 0.0}
    core = SceneCore(load_settings(Settings, {**base, "contact_obstacles": True}))
    for k in range(3):
        state = scene_state(core, sc, k)
    assert touched(state) == []
    hidden = (0.5, 0.3, 1.2)  # something no camera saw, well away from fruit 1
    on_fruit = (FRUIT[0], FRUIT[1], FRUIT[2] - 0.045)  # its underside, where the dish goes
    js = joint_state(3500).model_copy(update={"contacts": tuple(felt(hidden, on_fruit))})
    core.handle("harvest/events", event("fruit_selected", 1, 3100))
    core.handle("robot/joint_state", js)
    state = scene_state(core, sc, 3)
    assert state.selected_fruit_id == 1
    (s,) = touched(state)  # the target's own underside is touched on purpose: not kept
    assert s.name == "touched_occupied_0" and np.allclose(s.center_world_m, hidden)
    assert s.own_fruit_ids == (1,)  # felt while the planner worked on fruit 1
    assert core.counters["contacts_felt"] == 2 and core.counters["contacts_kept"] == 1
    # Given up, fruit 1 is no one's target; what an arm then feels on its skin is part of it.
    skipped = event("fruit_skipped", 1, 3600).model_copy(update={"outcome": "unreachable"})
    core.handle("harvest/events", skipped)
    side = (FRUIT[0], FRUIT[1] + 0.05, FRUIT[2])
    js = joint_state(3700).model_copy(update={"contacts": tuple(felt(side))})
    core.handle("robot/joint_state", js)
    state = scene_state(core, sc, 4)
    assert state.selected_fruit_id is None
    by_place = {tuple(round(v, 3) for v in s.center_world_m): s for s in touched(state)}
    assert by_place[tuple(round(v, 3) for v in side)].own_fruit_ids == (1,)
    assert by_place[tuple(round(v, 3) for v in hidden)].own_fruit_ids == (1,)
    beside = (FRUIT[0] - 0.07, FRUIT[1], FRUIT[2])  # felt on it before it was selected
    core.touched.feel(felt(beside), 4600)  # type: ignore[union-attr]
    core.handle("harvest/events", event("fruit_collected", 1, 5000))
    assert core.counters["contacts_forgotten"] == 2  # those beside the fruit, not the other
    assert len(core.touched.voxels) == 1  # type: ignore[union-attr]


def test_on_by_default_and_the_sim_fills_the_joint_state() -> None:
    from services.sim import SERVICE as SIM

    assert SceneCore(load_settings(Settings, {})).touched is not None
    assert SceneCore(load_settings(Settings, {"contact_obstacles": False})).touched is None
    assert SIM.make_core is not None
    for sensing in (True, False):
        sim = SIM.make_core(
            load_settings(SIM.settings, {"scenario": "paper-exp1", "contact_sensing": sensing})
        )
        try:
            ph = sim.physics
            branch = next(b for b, n in ph.names.items() if n.startswith("branch_"))
            on_link, on_branch = (0.6, 0.1, 1.2), (0.6, 0.1, 1.21)
            fake = {
                ("cutter_tool", branch): (on_link, on_branch),
                ("basket", ph.ground): ((0, 0, 0), (0, 0, 0)),
            }
            ph.robot_contact_pairs = lambda fake=fake: fake  # type: ignore[method-assign]
            sim._count_contacts()
            js = sim.joint_state(0)
        finally:
            sim.close()
        # The ground is no body the arms are counted touching; the branch is.
        want = (SensedContact(link="cutter_tool", point_world_m=(0.6, 0.1, 1.2)),)
        assert js.contacts == (want if sensing else ())
        assert sim.counters["contacts"] == 1
