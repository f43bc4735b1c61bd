"""A fruit reported dropped that is seen hanging where it was cut again: the cut missed. It is
an obstacle again (the controller had been told to ignore it), a candidate while cuts are left,
and the scene's mark on its ID is lifted (orchard seed 8: a fruit missed by 23 mm was reported
dropped from the ready pose, and the arms were pushed through it 38 times afterwards)."""

from __future__ import annotations

from schemas.base import Header
from schemas.harvest import HarvestEvent
from schemas.scene import Fruit
from services.planner.book import MIN_SIGHTINGS, FruitRecord
from services.planner.core import PlannerCore
from services.runtime.settings import load_settings
from services.scene import Settings as SceneSettings
from services.scene.core import SceneCore
from tests.unit.test_planner_book import scene
from tests.unit.test_planner_select import A, B, core_with, fruit


def no_dish(_f: Fruit, resting: bool = False) -> bool:
    return False


def dropped_core(cuts: int = 1) -> tuple[PlannerCore, FruitRecord]:
    core = core_with("nearest", fruit(1, A, 0.5), fruit(2, B, 0.6))
    rec = core.book.records[1]
    rec.outcome, rec.reason, rec.cuts, rec.frozen = "dropped", "not in the basket", cuts, True
    rec.finished_ns = 5
    core.machine.target = core.book.records[2]  # busy with another fruit
    return core, rec


def views(core: PlannerCore, f: Fruit, n: int) -> None:
    for k in range(n):
        core.book.update(scene(f, seq=20 + k), no_dish)
        core.machine._note_switches_and_moves()


def test_a_dropped_fruit_seen_on_its_branch_again_is_retried_and_avoided() -> None:
    core, rec = dropped_core()
    assert 1 in core.book.ignore_ids(None)
    here = fruit(1, (A[0] + 0.01, A[1], A[2] - 0.005), 0.5)
    views(core, here, MIN_SIGHTINGS - 1)
    assert rec.outcome == "dropped" and core.machine.events == []
    views(core, here, 1)
    assert rec.outcome is None and rec.deferred and not rec.frozen and rec.finished_ns is None
    assert 1 not in core.book.ignore_ids(None)  # an obstacle again
    (ev,) = core.machine.events
    assert ev.event == "fruit_skipped" and ev.fruit_id == 1 and ev.outcome is None
    assert "seen on its branch again" in ev.reason and rec.aim_deeper_m > 0
    core.machine.target = None
    assert rec in core.book.candidates(45)


def test_with_no_cut_left_its_cuts_failed() -> None:
    core, rec = dropped_core(cuts=2)
    views(core, fruit(1, A, 0.5), MIN_SIGHTINGS)
    assert rec.outcome == "cut_failed" and "reported dropped" in rec.reason
    assert 1 not in core.book.ignore_ids(None)
    (ev,) = core.machine.events
    assert ev.outcome == "cut_failed"


def test_kept_or_far_views_do_not_withdraw_the_verdict() -> None:
    core, rec = dropped_core()
    kept = fruit(1, A, 0.5).model_copy(update={"flags": ("depth_inconsistent", "kept")})
    stale = fruit(1, A, 0.5).model_copy(update={"frames_unseen": 3})
    fallen = fruit(1, (A[0], A[1], A[2] - 0.3), 0.5)  # on the ground, under where it hung
    for f in (kept, stale, fallen):
        views(core, f, MIN_SIGHTINGS + 1)
    assert rec.outcome == "dropped" and core.machine.events == []


def test_the_scene_lifts_its_mark_when_the_planner_defers_the_fruit() -> None:
    scene = SceneCore(load_settings(SceneSettings, {}))  # type: ignore[arg-type]

    def ev(kind: str, outcome: str | None = None) -> HarvestEvent:
        h = Header(stamp_ns=1, seq=1, source="planner")
        return HarvestEvent(header=h, event=kind, fruit_id=7, outcome=outcome)  # type: ignore[arg-type]

    scene._take_event(ev("fruit_dropped", "dropped"))
    assert scene.fruits.marks.get(7) == "harvested"
    scene._take_event(ev("fruit_skipped"))
    assert 7 not in scene.fruits.marks
    scene._take_event(ev("fruit_skipped", "unreachable"))
    assert scene.fruits.marks.get(7) == "unreachable"
