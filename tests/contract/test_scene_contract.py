"""Contract of the scene service with the foundation's kit, on frames and truth from the sim
(tracks made from the truth's visible boxes), and its answers to bad input."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from schemas.base import Header, Pose
from schemas.camera import RgbdFrame
from schemas.harvest import HarvestEvent
from schemas.topics import TOPICS
from services.runtime.settings import load_settings
from services.scene import SERVICE, Settings
from services.scene.truth_tracks import TruthTracks
from services.testkit import ContractCase, Emitted, FakeNode, assert_contract
from tests.scene_helpers import LEVEL_POSE, Scene, tracks
from tests.sim_helpers import core, scenario_file

SETTINGS = load_settings(Settings, {})


@pytest.fixture(scope="module")
def sim_script(tmp_path_factory: pytest.TempPathFactory) -> list[tuple[str, Any]]:
    """Six frames of a small scenario (two fruit, the trunk in view) with their tracks, and a
    harvest event after the third frame."""
    sc = scenario_file(
        tmp_path_factory.mktemp("sc"),
        fruits=[
            {"position_world_m": [0.6, -0.15, 1.35], "leaf_cover": "none"},
            {"position_world_m": [0.702, -0.25, 1.405], "leaf_cover": "none"},
        ],
    )
    sim = core(sc, camera_every_ticks=2)
    oracle = TruthTracks()
    script: list[tuple[str, Any]] = []
    try:
        while len(script) < 12:
            for group in sim.emit():
                topics = dict(group)
                if "camera/rgbd" in topics:
                    script.append(("camera/rgbd", topics["camera/rgbd"]))
                    script.append(("perception/tracks", oracle(topics["sim/truth"])))
            sim.advance()
    finally:
        sim.close()
    stamp = script[5][1].header.stamp_ns
    ev = HarvestEvent(
        header=Header(stamp_ns=stamp, seq=0, source="planner"),
        event="fruit_collected",
        fruit_id=1,
        outcome="harvested",
    )
    return [*script[:6], ("harvest/events", ev), *script[6:]]


def states(outs: list[Emitted]) -> list[Any]:
    return [o.msg for o in outs if o.topic == "scene/state"]


def test_scene_contract_on_sim_frames(sim_script: list[tuple[str, Any]]) -> None:
    def empty_check(outs: list[Emitted]) -> None:
        for s in states(outs):
            assert s.fruits == () and s.selected_fruit_id is None and s.input_problem == ""
            assert s.obstacles.ellipsoids == ()

    no_tracks = [
        (t, m.model_copy(update={"tracks": ()}) if t == "perception/tracks" else m)
        for t, m in sim_script
        if t != "harvest/events"
    ]
    outs = assert_contract(
        ContractCase(SERVICE, SETTINGS, sim_script, empty_inputs=no_tracks, empty_check=empty_check)
    )
    got = states(outs)
    assert len(got) == 6
    first, last = got[0], got[-1]
    assert [f.fruit_id for f in first.fruits] == [1, 2]
    assert first.selected_fruit_id == 1 and first.fruits[0].status == "selected"
    assert first.trunk.found and first.obstacles.cylinders[0].name == "trunk"
    # After the planner's event fruit 1 is harvested: not selected, no obstacle.
    assert last.selected_fruit_id == 2
    assert [f.status for f in last.fruits] == ["harvested", "selected"]
    assert [e.fruit_id for e in last.obstacles.ellipsoids] == [2]


def level_frame(seq: int, scene: Scene, pose: Pose = LEVEL_POSE) -> RgbdFrame:
    return scene.frame(seq, 1_000_000 * seq, pose)


def fruit_scene() -> Scene:
    s = Scene()
    s.ellipsoid((0.0, 0.0, 0.6), 0.04, 0.038)
    s.vertical_cylinder((1.2, 0.05), 0.07)
    return s


def feed(script: list[tuple[str, Any]], **settings: Any) -> tuple[list[Any], FakeNode]:
    node = FakeNode(SERVICE, load_settings(Settings, settings))
    return states(node.feed(script)), node


def test_tracks_of_a_frame_never_seen_get_the_last_state_flagged_and_counted() -> None:
    s = fruit_scene()
    box = s.box()
    script = [
        ("camera/rgbd", level_frame(0, s)),
        ("camera/rgbd", level_frame(1, s)),  # a buffer of one frame: frame 0 is gone
        ("perception/tracks", tracks(0, 0, 0, {3: box})),
        ("perception/tracks", tracks(1, 1_000_000, 1, {3: box})),
        ("perception/tracks", tracks(2, 2_000_000, 2, {3: box})),  # frame 2 is lost...
        ("camera/rgbd", level_frame(3, s)),  # ...which frame 3 shows: answered now
    ]
    node = FakeNode(SERVICE, load_settings(Settings, {"frame_buffer": 1}))
    outs = node.feed(script)
    assert [o.cause for o in outs] == [2, 3, 5]
    a, b, c = states(outs)
    assert a.input_problem.startswith("frame seq 0") and a.fruits == ()
    assert b.input_problem == "" and [f.fruit_id for f in b.fruits] == [3]
    assert c.input_problem.startswith("frame seq 2") and c.fruits == b.fruits
    assert node.core.counters["frame_not_received"] == 2


def test_tracks_that_overtake_their_frame_get_the_same_answer() -> None:
    """The bus orders messages per key only: a small Tracks message can arrive before the
    large frame it was made from. It waits for it; the answers do not change."""
    s = fruit_scene()
    box = s.box()
    f0, f1 = level_frame(0, s), level_frame(1, s)
    t0, t1 = tracks(0, 0, 0, {3: box}), tracks(1, 1_000_000, 1, {3: box})
    in_order, _ = feed(
        [
            ("camera/rgbd", f0),
            ("perception/tracks", t0),
            ("camera/rgbd", f1),
            ("perception/tracks", t1),
        ]
    )
    overtaken, node = feed(
        [
            ("perception/tracks", t0),
            ("camera/rgbd", f0),
            ("perception/tracks", t1),
            ("camera/rgbd", f1),
        ]
    )
    assert overtaken == in_order and overtaken[0].input_problem == ""
    assert node.core.counters["tracks_before_frame"] == 2


def test_no_valid_depth_keeps_the_fruit_from_its_last_good_state() -> None:
    s = fruit_scene()
    box = s.box()
    blind = fruit_scene()
    blind.depth[:] = 0  # the sensor saw nothing
    script = [
        ("camera/rgbd", level_frame(0, s)),
        ("perception/tracks", tracks(0, 0, 0, {3: box})),
        ("camera/rgbd", level_frame(1, blind)),
        ("perception/tracks", tracks(1, 1_000_000, 1, {3: box})),
    ]
    (a, b), node = feed(script)
    assert b.fruits[0].position_world_m == a.fruits[0].position_world_m
    assert b.fruits[0].flags == ("depth_invalid", "kept") and b.fruits[0].frames_unseen == 0
    assert node.core.counters["fruit_depth_invalid"] == 1
    # Nothing bark-coloured with depth: the trunk keeps its estimate, unseen for one frame.
    assert node.core.counters["trunk_mask_empty"] == 1
    assert b.trunk.found and b.trunk.frames_unseen == 1 and b.trunk.pixel_count == 0


def test_an_empty_trunk_region_from_the_start_is_not_found() -> None:
    s = Scene()
    s.ellipsoid((0.0, 0.0, 0.6), 0.04, 0.038)
    (a,), node = feed(
        [("camera/rgbd", level_frame(0, s)), ("perception/tracks", tracks(0, 0, 0, {}))]
    )
    assert not a.trunk.found and a.trunk.position_world_m is None and a.obstacles.cylinders == ()
    assert node.core.counters["trunk_mask_empty"] == 1


def test_a_degenerate_pose_or_box_is_refused_with_a_counted_reason() -> None:
    s = fruit_scene()
    bad_pose = Pose(position_m=(0.0, 0.0, 1.4), orientation_xyzw=(0.0, 0.0, 0.0, 0.0))
    script = [
        ("camera/rgbd", level_frame(0, s, bad_pose)),
        ("perception/tracks", tracks(0, 0, 0, {3: s.box()})),
        ("camera/rgbd", level_frame(1, s)),
        ("perception/tracks", tracks(1, 1_000_000, 1, {3: (300.0, 200.0, 300.0, 260.0)})),
    ]
    (a, b), node = feed(script)
    assert "degenerate quaternion" in a.input_problem and a.fruits == ()
    assert b.input_problem == "" and b.fruits == ()  # a new ID with a bad box is not added
    assert node.core.counters["frame_pose_invalid"] == 1
    assert node.core.counters["fruit_box_degenerate"] == 1


def test_nan_never_reaches_the_core() -> None:
    """NaN in any field of an input is refused when the payload is decoded (the bus counts it
    as rejected), so the core never sees one."""
    good = tracks(0, 0, 0, {3: (300.0, 200.0, 340.0, 240.0)})
    payload = TOPICS["perception/tracks"].codec.encode(good)
    bad = payload.replace(b"300.0", b"NaN", 1)
    assert bad != payload
    with pytest.raises(ValueError):
        TOPICS["perception/tracks"].codec.decode(bad)


def test_tentative_and_coasting_tracks_do_not_update_the_list() -> None:
    s = fruit_scene()
    box = s.box()
    moved = Scene()
    moved.ellipsoid((0.02, 0.0, 0.6), 0.04, 0.038)
    script = [
        ("camera/rgbd", level_frame(0, s)),
        ("perception/tracks", tracks(0, 0, 0, {3: box}, confirmed=False)),
        ("perception/tracks", tracks(1, 0, 0, {3: box})),
        ("camera/rgbd", level_frame(1, moved)),
        ("perception/tracks", tracks(2, 1_000_000, 1, {3: moved.box()}, matched=False)),
    ]
    states_, node = feed(script)
    assert states_[0].fruits == ()  # tentative: not in the list
    assert [f.fruit_id for f in states_[1].fruits] == [3]
    coast = states_[2].fruits[0]
    assert (
        coast.frames_unseen == 1 and coast.position_world_m == states_[1].fruits[0].position_world_m
    )
    assert node.core.counters["track_tentative"] == 1 and node.core.counters["track_coasting"] == 1
    (with_tentative, *_), _ = feed(script[:2], accept_tentative=True)
    assert [f.fruit_id for f in with_tentative.fruits] == [3]


def test_unreachable_fruit_stay_obstacles_and_are_never_selected() -> None:
    s = fruit_scene()
    s.ellipsoid((0.1, 0.0, 0.8), 0.04, 0.038, label=2)
    ev = HarvestEvent(
        header=Header(stamp_ns=0, seq=0, source="planner"),
        event="fruit_skipped",
        fruit_id=3,
        reason="no IK solution",
        outcome="unreachable",
    )
    script = [
        ("camera/rgbd", level_frame(0, s)),
        ("perception/tracks", tracks(0, 0, 0, {3: s.box(1), 4: s.box(2)})),
        ("harvest/events", ev),
        ("perception/tracks", tracks(1, 0, 0, {3: s.box(1), 4: s.box(2)})),
    ]
    (a, b), _ = feed(script)
    assert a.selected_fruit_id == 3 and b.selected_fruit_id == 4
    assert [f.status for f in b.fruits] == ["unreachable", "selected"]
    assert [e.fruit_id for e in b.obstacles.ellipsoids] == [3, 4]
    # r_obs for the selected fruit: horizontal distance to the axis less d_h, less the tools'
    # margin (the dish reaches past the fruit's back).
    f4 = b.fruits[1]
    axis = b.obstacles.cylinders[0].axis_point_world_m
    horizontal = np.hypot(f4.position_world_m[0] - axis[0], f4.position_world_m[1] - axis[1])
    margin = SETTINGS.trunk_tool_margin_m
    assert abs(b.obstacles.cylinders[0].radius_m - (horizontal - f4.semi_axis_h_m - margin)) < 1e-9


def test_settings_that_cannot_work_refuse_to_start() -> None:
    from services.runtime import ConfigError
    from services.scene.core import SceneCore

    with pytest.raises(ConfigError, match="HsvBox"):
        SceneCore(load_settings(Settings, {"trunk_hsv_low": [30, 70, 80]}))  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="min_semi_axis_m"):
        SceneCore(load_settings(Settings, {"min_semi_axis_m": 0.2}))  # type: ignore[arg-type]
