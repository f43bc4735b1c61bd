"""The planner's selection in clutter: fruit in each other's tools' way are taken in an order
that clears the way, and only fruit no order can clear are given up."""

from __future__ import annotations

import pytest

from schemas.base import Header
from schemas.scene import Fruit, Obstacles, SceneState, Trunk
from services.planner import Settings
from services.planner.book import MIN_SIGHTINGS
from services.planner.clutter import blockers, clearable
from services.planner.core import PlannerCore
from services.planner.kinematics import ReachVerdict
from services.planner.machine import NS
from services.runtime.settings import load_settings

# Per clutter.blockers: B hangs where A's dish goes, C where B's dish goes, C free; D and E
# (the same place as C, lower) block each other: a cycle.
A = (0.70, 0.00, 1.40)
B = (0.72, 0.05, 1.27)
C = (0.74, 0.10, 1.14)
D, E = (0.72, 0.05, 1.27), (0.72, 0.05, 1.14)
OK = ReachVerdict(True, 0.0, 0.0, 0.0)


def fruit(fid: int, p: tuple[float, float, float], distance_m: float) -> Fruit:
    return Fruit(
        fruit_id=fid,
        position_cam_m=(0.0, 0.0, distance_m),
        position_world_m=p,
        semi_axis_h_m=0.04,
        semi_axis_v_m=0.04,
        distance_m=distance_m,
        status="candidate",
        frames_unseen=0,
        last_seen_stamp_ns=0,
    )


def core_with(order: str, *fruits: Fruit, **settings: object) -> PlannerCore:
    """A planner core whose book holds ``fruits``, every pose reachable by the IK (``settings``:
    other planner settings)."""
    core = PlannerCore(load_settings(Settings, {"order": order, **settings}))
    for seq in range(MIN_SIGHTINGS):  # seen in a few scene states: fruit, not flashes
        core.book.update(
            SceneState(
                header=Header(stamp_ns=0, seq=seq, source="scene"),
                fruits=fruits,
                trunk=Trunk(found=False),
                obstacles=Obstacles(),
            ),
            lambda _f, resting=False: False,
        )
    for r in core.book.records.values():
        r.reach = (OK, OK)
    return core


def select(core: PlannerCore, at_s: float = 0.0) -> int | None:
    """Run the selection at sim time ``at_s``; the selected fruit's ID (None: nothing
    selected)."""
    m = core.machine
    m.target = None
    m._select(round(at_s * 1e9))
    return m.target.fruit_id if m.target is not None else None


def harvest(core: PlannerCore, fid: int) -> None:
    core.book.records[fid].outcome = "harvested"


def test_the_geometry_is_a_chain_and_a_cycle() -> None:
    core = core_with("nearest", fruit(1, A, 0.5), fruit(2, B, 0.6), fruit(3, C, 0.7))
    ps = core.machine.pose_settings
    a, b, c = (core.book.records[k].planned for k in (1, 2, 3))
    assert blockers(a, [b, c], ps, 0.0) == [0]
    assert blockers(b, [a, c], ps, 0.0) == [1]
    assert blockers(c, [a, b], ps, 0.0) == []
    recs = core_with("nearest", fruit(4, D, 0.6), fruit(5, E, 0.7)).book.records
    d, e = recs[4].planned, recs[5].planned
    assert blockers(d, [e], ps, 0.0) == [0] and blockers(e, [d], ps, 0.0) == [0]


@pytest.mark.parametrize("order", ["nearest", "planned"])
def test_a_chain_of_blockers_is_harvested_from_its_free_end(order: str) -> None:
    core = core_with(order, fruit(1, A, 0.5), fruit(2, B, 0.6), fruit(3, C, 0.7))
    got = []
    for _ in range(3):
        fid = select(core)
        assert fid is not None
        got.append(fid)
        harvest(core, fid)
    assert got == [3, 2, 1]
    assert all(r.outcome == "harvested" for r in core.book.records.values())


def test_a_fruit_waiting_on_a_blocker_that_waits_is_not_given_up() -> None:
    # The old nearest pick gave A up once only deferred fruit were left, B among them.
    core = core_with("nearest", fruit(1, A, 0.5), fruit(2, B, 0.6), fruit(3, C, 0.7))
    core.book.records[1].deferred = core.book.records[2].deferred = True
    harvest(core, 3)
    assert select(core) == 2 and not core.book.records[1].finished


def test_planned_waits_for_a_blocker_deferred_after_a_stuck_attempt() -> None:
    # B was stuck once (deferred): A, blocked by it, waits instead of being given up.
    far = (0.70, -0.30, 1.30)
    core = core_with("planned", fruit(1, A, 0.5), fruit(2, B, 0.6), fruit(4, far, 0.7))
    core.book.records[2].deferred = True
    assert select(core) == 4 and not core.book.records[1].finished
    harvest(core, 4)
    assert select(core) == 2
    harvest(core, 2)
    assert select(core) == 1


def test_nearest_waits_for_a_hidden_blocker_then_gives_up_once_it_stays_away() -> None:
    # Orchard seed 15: A, deferred as blocked by B, was given up while the arms hid B; B
    # showed again 0.3 s later. Now the arms wait at the ready pose while B is hidden.
    core = core_with("nearest", fruit(1, A, 0.5), fruit(2, B, 0.6), try_blocked_max_m=0.0)
    core.book.records[1].deferred = True
    hidden_b = fruit(2, B, 0.6).model_copy(update={"frames_unseen": 50})  # past lost_after
    seen_at_ns = 3 * NS
    core.book.update(
        SceneState(
            header=Header(stamp_ns=seen_at_ns, seq=MIN_SIGHTINGS, source="scene"),
            fruits=(fruit(1, A, 0.5), hidden_b),
            trunk=Trunk(found=False),
            obstacles=Obstacles(),
        ),
        lambda _f, resting=False: False,
    )
    m, a = core.machine, core.book.records[1]
    m.phase = "leave"
    m._select(seen_at_ns)
    assert m.target is None and m.phase == "home" and not a.finished
    assert "#1 waits for #2 (hidden)" in m.events[-1].reason
    wait_s = core.s.hidden_wait_s
    m._select(int((wait_s - 0.1) * NS))  # still waiting, B last seen at 0 s
    assert not a.finished
    m._select(int((wait_s + 0.1) * NS))  # B stayed away: nothing can clear A's way
    assert a.outcome == "unreachable" and "blocked by #2" in a.reason


@pytest.mark.parametrize("order", ["nearest", "planned"])
def test_fruit_blocking_each_other_are_given_up_and_the_free_one_taken(order: str) -> None:
    free = (0.70, -0.30, 1.30)
    core = core_with(
        order, fruit(4, D, 0.5), fruit(5, E, 0.6), fruit(6, free, 0.7), try_blocked_max_m=0.0
    )
    assert select(core) == 6
    harvest(core, 6)
    assert select(core) is None
    recs = core.book.records
    assert recs[4].outcome == recs[5].outcome == "unreachable"
    assert "blocked by #5" in recs[4].reason and "blocked by #4" in recs[5].reason


def test_clearable_keeps_chains_and_drops_cycles_and_fruit_behind_one_that_stays() -> None:
    assert clearable({1: {2}, 2: {3}, 3: set()}) == {1, 2, 3}
    assert clearable({1: {2}, 2: {1}, 3: set()}) == {3}
    assert clearable({1: {-1}, 2: {1}, 3: set()}) == {3}
    assert clearable({}) == set()


def test_a_stale_second_track_of_a_harvested_fruit_is_no_neighbour_nor_candidate() -> None:
    # Track 7 lost B (last seen 20 frames ago), track 8 took B over 5 cm away (too far for the
    # book to merge them) and B was harvested: track 7 is listed where B hung.
    b_again = (B[0], B[1] + 0.05, B[2])
    core = core_with("nearest", fruit(1, A, 0.5), fruit(8, b_again, 0.6), fruit(3, C, 0.7))
    core.book.update(
        SceneState(
            header=Header(stamp_ns=1, seq=1, source="scene"),
            fruits=(
                fruit(1, A, 0.5),
                fruit(7, B, 0.6).model_copy(update={"frames_unseen": 20}),
                fruit(8, b_again, 0.6),
                fruit(3, C, 0.7),
            ),
            trunk=Trunk(found=False),
            obstacles=Obstacles(),
        ),
        lambda _f, resting=False: False,
    )
    recs = core.book.records
    assert sorted(recs) == [1, 3, 7, 8]
    recs[7].reach = (OK, OK)
    harvest(core, 8)
    harvest(core, 3)
    assert select(core) == 1  # not blocked by the stale track 7, which is not selected either
    ps = core.machine.pose_settings
    assert blockers(recs[1].planned, [recs[7].planned], ps, 0.0) == [0]  # where A's dish goes


def test_the_controller_is_not_told_to_avoid_a_second_track_of_the_target_nor_a_ghost() -> None:
    # paper-exp1 seed 12: track 11, on the lower half of the target (track 1), is estimated
    # 5 cm under its centre (too far for the book to merge them), where the dish goes; the
    # controller kept the dish from it, 9 cm short of its place. Track 7 is a stale second
    # track of B (harvested, by its track 8) listed where B hung.
    under_a = (A[0], A[1], A[2] - 0.05)
    b_again = (B[0], B[1] + 0.05, B[2])
    core = core_with(
        "nearest",
        fruit(1, A, 0.5),
        fruit(11, under_a, 0.5),
        fruit(7, B, 0.6),  # seen on B before B's track 8 took over
        fruit(8, b_again, 0.6),
    )
    core.book.update(
        SceneState(
            header=Header(stamp_ns=1, seq=1, source="scene"),
            fruits=(
                fruit(1, A, 0.5),
                fruit(11, under_a, 0.5),
                fruit(7, B, 0.6).model_copy(update={"frames_unseen": 20}),
                fruit(8, b_again, 0.6),
            ),
            trunk=Trunk(found=False),
            obstacles=Obstacles(),
        ),
        lambda _f, resting=False: False,
    )
    assert sorted(core.book.records) == [1, 7, 8, 11]
    harvest(core, 8)
    m = core.machine
    m.target = core.book.records[1]
    m.phase = "approach"
    assert m.goal().ignore == (7, 8)  # the ghost and the harvested fruit: never obstacles
    m.phase = "harvest"
    assert m.goal().ignore == (1, 7, 8, 11)  # the tools touch the target: all of its tracks


def test_a_cycle_of_blockers_is_broken_by_going_once_for_the_least_blocked() -> None:
    # D reaches 2.6 mm into E's tools' way, E 25 mm into D's (the estimates): E is gone for
    # once instead of both being given up; harvested, it frees D.
    free = (0.70, -0.30, 1.30)
    core = core_with(
        "nearest", fruit(4, D, 0.5), fruit(5, E, 0.6), fruit(6, free, 0.7), try_blocked_max_m=0.02
    )
    assert select(core) == 6
    harvest(core, 6)
    assert select(core) == 5
    m, recs = core.machine, core.book.records
    assert recs[5].tried_blocked and not recs[4].finished
    why = [e.reason for e in m.events if e.event == "fruit_selected"][-1]
    assert "tried once although blocked by #4" in why and "3 mm" in why
    harvest(core, 5)
    assert select(core) == 4 and not recs[4].tried_blocked


def test_a_fruit_gone_for_although_blocked_is_not_tried_twice() -> None:
    # E's attempt through D failed (the stall path makes it final); D, 25 mm in, is past the
    # limit: given up as before.
    core = core_with("nearest", fruit(4, D, 0.5), fruit(5, E, 0.6), try_blocked_max_m=0.02)
    assert select(core) == 5  # both waited once, then E is tried through
    recs = core.book.records
    recs[5].outcome = "unreachable"
    assert select(core) is None
    assert recs[4].outcome == "unreachable" and "blocked by #5" in recs[4].reason
    assert not recs[4].tried_blocked


def test_going_for_a_blocked_fruit_stops_at_the_limit() -> None:
    core = core_with("nearest", fruit(4, D, 0.5), fruit(5, E, 0.6), try_blocked_max_m=0.002)
    assert select(core) is None  # E's blocker reaches 2.6 mm in: over 2 mm
    recs = core.book.records
    assert recs[4].outcome == recs[5].outcome == "unreachable"
