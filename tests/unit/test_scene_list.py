"""The persistent fruit list (paper §III-B): threshold updates, confirmed jumps, forgetting,
the planner's marks and the nearest-fruit selection."""

from __future__ import annotations

import numpy as np

from services.scene.fruit_list import FruitList, ListParams, Measurement


def m(x: float, y: float = 0.0, z: float = 1.3, h: float = 0.04) -> Measurement:
    """A fruit at world (x, y, z), seen from a camera at the world origin (cam = world here)."""
    p = np.array([x, y, z])
    return Measurement(p, p, h, h * 0.94)


def test_an_update_within_the_threshold_replaces_the_stored_state() -> None:
    fl = FruitList(ListParams(update_threshold_m=0.04))
    fl.step(0, {1: m(0.6)}, {})
    fl.step(1, {1: m(0.63)}, {})
    assert fl.entries[1].state.position_world_m[0] == 0.63
    assert fl.entries[1].flags == ()


def test_a_jump_is_kept_out_as_a_temporary_id_error() -> None:
    fl = FruitList(ListParams(update_threshold_m=0.04, accept_jump_frames=15))
    fl.step(0, {1: m(0.6)}, {})
    fl.step(1, {1: m(0.6, y=0.2)}, {})  # the ID briefly lands on another fruit
    assert fl.entries[1].state.position_world_m[1] == 0.0
    assert {"position_jump", "kept"} <= set(fl.entries[1].flags)
    fl.step(2, {1: m(0.6)}, {})
    assert fl.entries[1].flags == () and fl.entries[1].state.position_world_m[1] == 0.0


def test_a_jump_confirmed_by_consecutive_frames_is_taken() -> None:
    fl = FruitList(ListParams(update_threshold_m=0.04, accept_jump_frames=5))
    fl.step(0, {1: m(0.6)}, {})
    for k in range(1, 5):
        fl.step(k, {1: m(0.6, y=0.1)}, {})
        assert fl.entries[1].state.position_world_m[1] == 0.0
    fl.step(5, {1: m(0.6, y=0.1)}, {})
    assert fl.entries[1].state.position_world_m[1] == 0.1


def test_the_papers_rule_never_takes_a_jump() -> None:
    fl = FruitList(ListParams(update_threshold_m=0.04, accept_jump_frames=0))
    fl.step(0, {1: m(0.6)}, {})
    for k in range(1, 50):
        fl.step(k, {1: m(0.6, y=0.1)}, {})
    assert fl.entries[1].state.position_world_m[1] == 0.0


def test_ids_unseen_for_100_frames_are_forgotten() -> None:
    fl = FruitList(ListParams(forget_after_frames=100))
    fl.step(0, {1: m(0.6), 2: m(0.7)}, {})
    for k in range(1, 100):
        fl.step(k, {2: m(0.7)}, {})
    assert fl.entries[1].frames_unseen == 99 and "stale" in fl.entries[1].flags
    fl.step(100, {2: m(0.7)}, {})
    assert 1 not in fl.entries and 2 in fl.entries


def test_a_fruit_seen_without_depth_keeps_its_last_good_state_flagged() -> None:
    fl = FruitList(ListParams())
    fl.step(0, {1: m(0.6)}, {})
    fl.step(1, {}, {1: "depth_invalid"})
    e = fl.entries[1]
    assert e.frames_unseen == 0 and e.state.position_world_m[0] == 0.6
    assert e.flags == ("depth_invalid", "kept")
    fl.step(2, {}, {2: "depth_invalid"})  # a new ID without depth does not enter the list
    assert 2 not in fl.entries


def test_selection_is_the_nearest_fruit_neither_harvested_nor_unreachable() -> None:
    fl = FruitList(ListParams())
    fl.step(0, {1: m(0.8), 2: m(0.5), 3: m(0.6)}, {})
    assert fl.selected() == 2
    fl.mark(2, "harvested")
    assert fl.selected() == 3
    fl.mark(3, "unreachable")
    assert fl.selected() == 1
    fl.mark(1, "harvested")
    assert fl.selected() is None


def test_equal_distances_select_the_lower_id() -> None:
    fl = FruitList(ListParams())
    fl.step(0, {5: m(0.0, y=0.6, z=0.0), 3: m(0.0, y=-0.6, z=0.0)}, {})
    assert fl.selected() == 3


def test_marks_outlive_the_entry() -> None:
    fl = FruitList(ListParams(forget_after_frames=2))
    fl.step(0, {1: m(0.6)}, {})
    fl.mark(1, "harvested")
    fl.step(1, {}, {})
    fl.step(2, {}, {})
    assert 1 not in fl.entries
    fl.step(3, {1: m(0.6)}, {})  # seen again (e.g. in the basket): still harvested
    assert fl.selected() is None
    fl.mark(1, "unreachable")  # a later skip does not undo a harvest
    assert fl.marks[1] == "harvested"


def test_a_cut_view_that_keeps_the_stored_state_says_so_and_a_measurement_clears_it() -> None:
    # The planner must tell a cut view the scene computed from one it kept the stored state
    # for: both carry edge_occluded, and only the first is where the fruit is now.
    fl = FruitList(ListParams())
    fl.step(0, {1: m(0.6)}, {})
    fl.step(1, {}, {1: "edge_occluded"})
    e = fl.entries[1]
    assert e.frames_unseen == 0 and e.flags == ("edge_occluded", "kept")
    fl.step(2, {1: m(0.61)}, {})
    assert fl.entries[1].flags == ()
