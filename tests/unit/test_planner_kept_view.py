"""After a cut the basket stays empty: did the cut fail? While the tools are at the fruit only a
view the scene estimated from shows it still hangs where it was cut; one kept for want of depth
is the track, not the fruit (orchard seed 18: a cut fruit bouncing in our dish read
``depth_inconsistent`` where it hung for 3 s, was called still on its branch, cut again on
nothing, and given up as ``cut_failed``). From the ready pose a detection at its place counts
too, estimated or kept for want of depth (orchard seed 2: a fruit behind leaves read so from
everywhere), but not one kept for a jump."""

from __future__ import annotations

from schemas.base import Header
from schemas.scene import FruitFlag, Obstacles, SceneState, Trunk
from services.planner.core import PlannerCore
from tests.unit.test_planner_bench_fates import NS, TICK_NS, status
from tests.unit.test_planner_select import A, core_with, fruit


def see(core: PlannerCore, t_ns: int, flags: tuple[FruitFlag, ...] | None) -> None:
    """One scene state: fruit 1 listed at A, seen in the frame stamped ``t_ns`` with ``flags``
    (None: not seen in this frame)."""
    unseen = flags is None
    f = fruit(1, A, 0.5).model_copy(
        update={
            "last_seen_stamp_ns": 0 if unseen else t_ns,
            "frames_unseen": 1 if unseen else 0,
            "flags": ("stale",) if unseen else flags,
        }
    )
    header = Header(stamp_ns=t_ns, seq=t_ns // TICK_NS, source="scene")
    state = SceneState(header=header, fruits=(f,), trunk=Trunk(found=False), obstacles=Obstacles())
    core.book.update(state, lambda _f, resting=False: False)


Views = tuple[FruitFlag, ...] | None


def run(at_fruit: Views, at_ready: Views) -> PlannerCore:
    """Every pose is reached at once and the basket stays empty; fruit 1 is seen whole until
    the first cut, then with ``at_fruit`` while the tools are at it and ``at_ready`` once they
    are back at the ready pose. Runs until the fruit is settled (10 s)."""
    core = core_with("nearest", fruit(1, A, 0.5))
    m, t, rec = core.machine, 0, core.book.records[1]
    while t < 10 * NS and not rec.finished:
        t += TICK_NS
        see(core, t, () if not rec.cuts else at_ready if m.arrived_ns else at_fruit)
        m.step(t, status(m.next_seq, 0.001, t), m.next_seq + 1, 0)
    return core


KEPT: Views = ("depth_inconsistent", "kept")


def test_kept_views_at_the_fruit_are_no_evidence_the_cut_failed() -> None:
    # the fruit fell into our dish (read where it hung, for want of depth), then left the place
    core = run(KEPT, None)
    rec, reasons = core.book.records[1], [e.reason for e in core.machine.events]
    assert rec.cuts == 1 and rec.outcome == "dropped"
    assert not any("still on its branch" in r for r in reasons)
    assert ("open", 1) in core.machine.tools  # backed out to look, the shears open


def test_from_the_ready_pose_a_kept_view_at_its_place_shows_it_still_hangs() -> None:
    # a fruit behind leaves reads depth_inconsistent from everywhere: the missed cut is retried
    rec = run(KEPT, KEPT).book.records[1]
    assert rec.cuts == 2 and rec.outcome == "cut_failed"


def test_a_view_kept_for_a_jump_is_the_track_elsewhere() -> None:
    rec = run(("position_jump", "kept"), ("position_jump", "kept")).book.records[1]
    assert rec.cuts == 1 and rec.outcome == "dropped"


def test_views_that_gave_an_estimate_show_the_cut_failed() -> None:
    # the control: estimated views (whole, or cut on a side) at the fruit retry the cut at once
    for flags in ((), ("edge_occluded",)):
        core = run(flags, None)
        rec = core.book.records[1]
        assert rec.cuts == 2 and rec.outcome == "cut_failed", flags
        assert core.machine.arrived_ns is None  # never backed out to look
