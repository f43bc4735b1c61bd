"""The run summary folds the book's records into physical fruit: a pending second track of a
listed fruit, a 'dropped' verdict superseded by a later harvest where the fruit hung, and a
deferred attempt at a fruit harvested later under another ID."""

from __future__ import annotations

from services.planner.book import FruitRecord, shape_of
from services.planner.summary import physical_fruit
from tests.unit.test_planner_book import fruit

S = 1_000_000_000


def record(key: int, p: tuple[float, float, float], **kw: object) -> FruitRecord:
    f = fruit(key, p)
    return FruitRecord(key, key, [key], f, shape_of(f), **kw)  # type: ignore[arg-type]


def test_a_pending_second_track_of_a_listed_fruit_is_not_another_fruit() -> None:
    done = record(1, (0.6, 0.0, 1.3), outcome="harvested", started_ns=S, spent_ns=3 * S)
    twin = record(2, (0.6, 0.03, 1.3))  # 3 cm off: one fruit (two centres are ≥ 7 cm apart)
    other = record(3, (0.6, 0.2, 1.3))  # a fruit of its own, never attempted
    got = physical_fruit([done, twin, other])
    assert [f.rec.key for f in got] == [1, 3]


def test_pending_twins_are_one_fruit_not_none() -> None:
    a, b = record(1, (0.6, 0.0, 1.3)), record(2, (0.6, 0.02, 1.3))
    assert [f.rec.key for f in physical_fruit([a, b])] == [2]


def test_a_fruit_harvested_where_it_was_reported_dropped_was_not_dropped() -> None:
    first = record(
        1,
        (0.6, 0.0, 1.3),
        outcome="dropped",
        started_ns=9 * S,
        finished_ns=22 * S,
        spent_ns=13 * S,
        cuts=1,
    )
    later = record(
        77,
        (0.6, 0.035, 1.29),
        outcome="harvested",
        started_ns=39 * S,
        finished_ns=43 * S,
        spent_ns=4 * S,
        cuts=1,
    )
    (f,) = physical_fruit([first, later])
    assert f.rec is later and (f.started_ns, f.spent_ns, f.cuts) == (9 * S, 17 * S, 2)


def test_a_dropped_fruit_elsewhere_or_before_the_drop_keeps_its_verdict() -> None:
    dropped = record(1, (0.6, 0.0, 1.3), outcome="dropped", started_ns=9 * S, finished_ns=22 * S)
    far = record(2, (0.6, 0.15, 1.3), outcome="harvested", started_ns=30 * S)
    earlier = record(3, (0.6, 0.03, 1.3), outcome="harvested", started_ns=1 * S)
    got = physical_fruit([dropped, far, earlier])
    assert [f.rec.outcome for f in got] == ["dropped", "harvested", "harvested"]


def test_a_track_forgotten_before_any_attempt_ends_lost_one_in_view_pending() -> None:
    from tests.unit.test_planner_select import core_with
    from tests.unit.test_planner_select import fruit as seen_fruit

    core = core_with(
        "nearest", seen_fruit(1, (0.6, 0.0, 1.3), 0.5), seen_fruit(2, (0.6, 0.2, 1.3), 0.6)
    )
    recs = core.book.records
    recs[2].in_scene = False  # the scene forgot it (a fruit moving in the dish, say)
    core.machine._end_run(5 * S, "run time limit")
    assert recs[1].outcome is None  # still in view, never attempted: pending in the summary
    assert recs[2].outcome == "lost" and "before it was attempted" in recs[2].reason


def test_a_deferred_fruit_hidden_at_the_end_says_why_it_is_still_pending() -> None:
    """Orchard seed 14: two fruit deferred after a stall, then hidden from the ready pose for
    longer than hidden_wait_s; the run ended with them 'pending' and no reason."""
    from tests.unit.test_planner_select import core_with
    from tests.unit.test_planner_select import fruit as seen_fruit

    core = core_with(
        "nearest", seen_fruit(1, (0.6, 0.0, 1.3), 0.5), seen_fruit(2, (0.6, 0.2, 1.3), 0.6)
    )
    recs = core.book.records
    recs[1].deferred, recs[1].started_ns, recs[1].last_seen_ns = True, 2 * S, 3 * S
    core.machine._end_run(30 * S, "no reachable fruit left")
    assert recs[1].outcome is None  # still to do: pending in the summary ...
    assert recs[1].reason == "deferred, then not seen for 27 s: never retried"  # ... with why
    assert recs[2].reason == ""  # never deferred: nothing to add


def test_a_forgotten_second_track_of_a_listed_fruit_is_not_another_fruit() -> None:
    done = record(1, (0.6, 0.0, 1.3), outcome="harvested", started_ns=S, spent_ns=3 * S)
    gone = record(
        2, (0.6, 0.03, 1.3), outcome="lost", reason="left the scene before it was attempted"
    )
    far_gone = record(3, (0.6, 0.2, 1.3), outcome="lost")
    assert [f.rec.key for f in physical_fruit([done, gone, far_gone])] == [1, 3]


def test_a_fruit_is_listed_under_the_id_its_outcome_was_reported_under() -> None:
    # orchard seed 11 (old default): the summary listed fruit 13 harvested twice; the second
    # was harvested as 72, whose record took ID 13 when the tracker moved that track on.
    from schemas.base import Header
    from services.planner.summary import run_summary
    from tests.unit.test_planner_select import core_with
    from tests.unit.test_planner_select import fruit as seen_fruit

    core = core_with(
        "nearest", seen_fruit(13, (0.6, 0.0, 1.3), 0.5), seen_fruit(72, (0.6, 0.2, 1.3), 0.6)
    )
    m, recs = core.machine, core.book.records
    for key in (13, 72):
        m._finish(recs[key], key * S, "harvested", "")
    recs[72].fruit_id = 13  # a later ID (not a step of the machine; as the book may set)
    summary = run_summary(Header(stamp_ns=S, seq=0, source="planner"), core.s, core.book, 0, S)
    assert sorted(f.fruit_id for f in summary.fruits) == [13, 72]


def test_a_deferred_attempt_at_a_fruit_harvested_later_under_another_id_is_that_fruit() -> None:
    """paper-exp1 seed 11: a hand moved fruit #6 by 6-7 cm, the tracker gave it ID 37 and kept
    #6 where it had hung; #6 was approached, deferred and never seen again; #37 was harvested.
    One fruit, harvested, its time summed; a deferred fruit elsewhere stays pending."""
    ghost = record(
        6, (0.695, -0.075, 1.214), deferred=True, started_ns=10 * S, spent_ns=3 * S, cuts=0
    )
    moved = record(
        37, (0.695, -0.02, 1.24), outcome="harvested", started_ns=14 * S, spent_ns=4 * S, cuts=1
    )
    elsewhere = record(8, (0.6, 0.2, 1.3), deferred=True, started_ns=11 * S)
    got = physical_fruit([ghost, moved, elsewhere])
    assert [f.rec.key for f in got] == [37, 8]
    assert (got[0].started_ns, got[0].spent_ns, got[0].cuts) == (10 * S, 7 * S, 1)


def test_a_deferred_fruit_harvested_before_its_neighbour_was_attempted_is_its_own() -> None:
    harvested_first = record(1, (0.6, 0.0, 1.3), outcome="harvested", started_ns=2 * S)
    deferred_later = record(2, (0.6, 0.06, 1.3), deferred=True, started_ns=9 * S)
    got = physical_fruit([harvested_first, deferred_later])
    assert [f.rec.key for f in got] == [1, 2]
