"""After a cut the basket stays empty: the cut failed only if a view that gave an estimate shows
the fruit where it was cut. A view the scene kept its stored estimate for (no consistent depth,
a jump) is the track, not the fruit: the tools back out and look (orchard seed 18: a cut fruit
bouncing in our dish read ``depth_inconsistent`` where it hung for 3 s, was called still on its
branch, cut again on nothing, and given up as ``cut_failed``)."""

from __future__ import annotations

from schemas.base import Header
from schemas.scene import FruitFlag, Obstacles, SceneState, Trunk
from services.planner.core import PlannerCore
from tests.unit.test_planner_bench_fates import NS, TICK_NS, status
from tests.unit.test_planner_select import A, core_with, fruit


def see(core: PlannerCore, t_ns: int, flags: tuple[FruitFlag, ...]) -> None:
    """One scene state: fruit 1 listed at A as seen in the frame stamped ``t_ns``."""
    f = fruit(1, A, 0.5).model_copy(update={"last_seen_stamp_ns": t_ns, "flags": flags})
    header = Header(stamp_ns=t_ns, seq=t_ns // TICK_NS, source="scene")
    state = SceneState(header=header, fruits=(f,), trunk=Trunk(found=False), obstacles=Obstacles())
    core.book.update(state, lambda _f, resting=False: False)


def run(after_cut: tuple[FruitFlag, ...]) -> PlannerCore:
    """Every pose is reached at once and the basket stays empty; fruit 1 is seen whole until
    the first cut, with ``after_cut`` from then on. Runs until the fruit is settled (10 s)."""
    core = core_with("nearest", fruit(1, A, 0.5))
    m, t, rec = core.machine, 0, core.book.records[1]
    while t < 10 * NS and not rec.finished:
        t += TICK_NS
        see(core, t, after_cut if rec.cuts else ())
        m.step(t, status(m.next_seq, 0.001, t), m.next_seq + 1, 0)
    return core


def test_kept_views_after_the_cut_are_no_evidence_it_failed() -> None:
    core = run(("depth_inconsistent", "kept"))
    rec, reasons = core.book.records[1], [e.reason for e in core.machine.events]
    assert rec.cuts == 1 and rec.outcome == "dropped"
    assert not any("still on its branch" in r for r in reasons)
    assert ("open", 1) in core.machine.tools  # backed out to look, the shears open


def test_a_jump_kept_is_no_evidence_either() -> None:
    rec = run(("position_jump", "kept")).book.records[1]
    assert rec.cuts == 1 and rec.outcome == "dropped"


def test_views_that_gave_an_estimate_show_the_cut_failed() -> None:
    # the control: the same run with measured views (whole, or cut on a side) retries the cut
    for flags in ((), ("edge_occluded",)):
        rec = run(flags).book.records[1]
        assert rec.cuts == 2 and rec.outcome == "cut_failed", flags
