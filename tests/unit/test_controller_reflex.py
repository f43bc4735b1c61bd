"""The contact reflex (controller.contact_reflex): a felt place is a damper sphere from the tick
that reports it, not from the scene's next state; the fruit worked on is not one; it is let go
after the hold; off, contacts change nothing."""

from __future__ import annotations

import numpy as np

from schemas import Fruit, JointState
from schemas.robot import SensedContact
from services.controller import Settings
from services.controller.core import ControllerCore
from services.controller.kinsim import KinematicSim
from services.controller.reflex import ContactReflex, ReflexParams, inner_space
from services.controller.robot import ControlledRobot
from services.controller.scenarios import fruit, harvest_target, run_loop, scene
from services.robot.model import URDF_PATH
from services.runtime.settings import load_settings

FRUIT = (0.85, 0.05, 1.05)
MS = 1_000_000


def settings(**kw: object) -> Settings:
    return load_settings(Settings, dict(kw))


def felt(p: np.ndarray | tuple[float, ...], link: str = "cutter_tool") -> SensedContact:
    return SensedContact(link=link, point_world_m=(float(p[0]), float(p[1]), float(p[2])))


def with_contacts(js: JointState, *contacts: SensedContact) -> JointState:
    return js.model_copy(update={"contacts": contacts})


def an_orange(fruit_id: int, centre: tuple[float, float, float], semi_v_m: float = 0.04) -> Fruit:
    return Fruit(
        fruit_id=fruit_id,
        position_cam_m=centre,
        position_world_m=centre,
        semi_axis_h_m=0.035,
        semi_axis_v_m=semi_v_m,
        distance_m=1.0,
        status="selected",
        frames_unseen=0,
        last_seen_stamp_ns=0,
    )


# ---- the pure part -------------------------------------------------------------------------
def test_a_felt_point_is_held_until_the_hold_has_passed_since_it_was_last_felt() -> None:
    r = ContactReflex(ReflexParams(hold_ns=100 * MS))
    r.feel([felt((0.5, 0.0, 1.0))], 0)
    c, radii = r.spheres()
    assert c.tolist() == [[0.5, 0.0, 1.0]] and radii.tolist() == [0.01]
    r.feel([felt((0.501, 0.0, 1.0))], 80 * MS)  # the same voxel: refreshed, not moved
    assert r.spheres()[0].tolist() == [[0.5, 0.0, 1.0]]
    r.feel([], 170 * MS)
    assert len(r.voxels) == 1  # 90 ms after it was last felt
    v = r.version
    r.feel([], 181 * MS)
    assert not r.voxels and r.version > v


def test_points_in_the_worked_fruits_inner_space_are_not_held() -> None:
    p = ReflexParams()
    sc = scene([fruit(3, FRUIT)]).model_copy(update={"fruits": (an_orange(3, FRUIT),)})
    inner = inner_space(sc, {3}, p)
    assert len(inner) == 1 and inner[0][2] == 0.04 + p.inner_clearance_m
    assert inner_space(sc, {4}, p) == [] and inner_space(None, {3}, p) == []
    r = ContactReflex(p)
    peduncle = (FRUIT[0], FRUIT[1], FRUIT[2] + 0.10)  # up its twig
    beside = (FRUIT[0], FRUIT[1] + 0.12, FRUIT[2])  # 12 cm to its side: a neighbour's branch
    r.feel([felt(peduncle), felt(beside)], 0, inner)
    assert r.spheres()[0].tolist() == [list(beside)] and r.skipped_inner == 1


def test_the_latest_felt_places_are_kept_past_max_spheres() -> None:
    r = ContactReflex(ReflexParams(max_spheres=2))
    for k in range(4):
        r.feel([felt((0.5 + 0.1 * k, 0.0, 1.0))], k * MS)
    assert sorted(c[0] for c in r.spheres()[0].tolist()) == [0.7, 0.8]


def test_a_point_too_far_out_to_bin_is_left_out() -> None:
    r = ContactReflex(ReflexParams())
    r.feel([felt((1e12, 0.0, 1.0))], 0)
    assert not r.voxels


# ---- in the controller ---------------------------------------------------------------------
def _tip_m(robot: ControlledRobot, sim: KinematicSim) -> np.ndarray:
    robot.set_q(sim.q_arm_order())
    return robot.T_world(robot.tool_frame["cutter"])[:3, 3]


def _press(reflex: bool) -> tuple[float, float, ControllerCore]:
    """The cutter on its way to a fruit feels something 5 mm ahead of its tip, where the scene
    knows of nothing; returns how far the tip moved towards that point over the next 10 ticks
    (m; negative: away), the distance it had moved in the 10 ticks before, and the core."""
    core = ControllerCore(settings(contact_reflex=reflex))
    sim, robot = KinematicSim(), ControlledRobot(URDF_PATH)
    target, sc = harvest_target(FRUIT, fruit_id=1), scene([fruit(1, FRUIT)])
    run_loop(core, sim, target, sc, 20, stop_when_converged=False)
    before = _tip_m(robot, sim)
    run_loop(core, sim, target, None, 10, stop_when_converged=False)
    tip = _tip_m(robot, sim)
    heading = (tip - before) / np.linalg.norm(tip - before)
    point = tip + 0.005 * heading
    for _ in range(10):
        h = target.header.model_copy(update={"stamp_ns": sim.stamp_ns})
        core.handle("plan/target", target.model_copy(update={"header": h}))
        js = with_contacts(sim.joint_state(), felt(point))
        sim.apply(dict(core.handle("robot/joint_state", js))["robot/command"])
    moved = float((_tip_m(robot, sim) - tip) @ heading)
    return moved, float(np.linalg.norm(tip - before)), core


def test_a_felt_place_ahead_of_the_cutter_turns_it_back_at_once() -> None:
    moved, approach, core = _press(reflex=True)
    assert approach > 0.005, "the cutter must have been moving towards the fruit"
    assert moved < 0.0, f"the tip went {moved * 1e3:.1f} mm on into the felt place"
    assert core.reflex is not None and len(core.reflex.voxels) == 1


def test_without_the_reflex_the_cutter_presses_on() -> None:
    """The control for the test above: the felt place, not the target, turns the tip."""
    moved, _approach, core = _press(reflex=False)
    assert moved > 0.003 and core.reflex is None


def test_off_contacts_change_no_command_and_on_they_show_in_diagnostics() -> None:
    target, sc = harvest_target(FRUIT, fruit_id=1), scene([fruit(1, FRUIT)])
    point = felt((0.7, 0.3, 1.2))

    def commands(core: ControllerCore, touch: bool) -> list[tuple[object, ...]]:
        sim = KinematicSim()
        core.handle("scene/state", sc)
        out = []
        for k in range(15):
            h = target.header.model_copy(update={"stamp_ns": sim.stamp_ns, "seq": k})
            core.handle("plan/target", target.model_copy(update={"header": h}))
            js = with_contacts(sim.joint_state(), point) if touch and k == 5 else sim.joint_state()
            msgs = dict(core.handle("robot/joint_state", js))
            cmd = msgs["robot/command"]
            sim.apply(cmd)
            diag = msgs["diag/controller"]
            out.append((cmd.arms["cutter"].velocity_rad_s, diag.reflex_spheres))
        return out

    off = commands(ControllerCore(settings()), touch=True)
    assert off == commands(ControllerCore(settings()), touch=False)
    assert all(n == 0 for _v, n in off)
    on = commands(ControllerCore(settings(contact_reflex=True)), touch=True)
    assert [n for _v, n in on] == [0] * 5 + [1] * 10  # held for 500 ms, the run is 125 ms
