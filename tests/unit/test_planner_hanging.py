"""planner.target_hangs_over_dish: the fruit the tools go for is never taken for one in the
basket when seen in our dish (orchard seed 14: a stalled harvest, the dish pushed up under the
fruit, marked it in the basket; it was never tried again, nor avoided)."""

from __future__ import annotations

from services.planner import Settings
from services.planner.book import MIN_SIGHTINGS
from services.planner.core import PlannerCore
from services.planner.kinematics import ReachVerdict
from services.runtime.settings import load_settings
from tests.unit.test_planner_book import fruit, scene

OK = ReachVerdict(True, 0.0, 0.0, 0.0)
P = (0.88, 0.25, 1.31)


def harvesting(on: bool) -> PlannerCore:
    """A core whose one fruit (ID 12) is selected and in the harvest phase."""
    core = PlannerCore(load_settings(Settings, {"target_hangs_over_dish": on}))
    for seq in range(MIN_SIGHTINGS):
        core.book.update(scene(fruit(12, P), seq=seq), lambda _f, resting=False: False)
    core.book.records[12].reach = (OK, OK)
    m = core.machine
    m._select(0)
    assert m.target is core.book.records[12] and m.phase == "approach"
    m._enter("harvest", 1)
    return core


def seen_in_dish(core: PlannerCore) -> bool:
    core.book.update(scene(fruit(12, P), seq=100), lambda _f, resting=False: True)  # dish under
    return core.book.records[12].in_basket


def test_the_target_seen_in_the_dish_while_harvested_is_not_in_the_basket() -> None:
    core = harvesting(True)
    assert not seen_in_dish(core)
    assert core.book.candidates(45) == [core.book.records[12]]
    assert 12 not in core.machine._ignore(None)  # still avoided when not touched


def test_off_the_target_seen_in_the_dish_is_marked_in_the_basket_as_before() -> None:
    core = harvesting(False)
    assert seen_in_dish(core)
    assert core.book.candidates(45) == []


def test_only_the_current_target_in_approach_or_harvest_hangs() -> None:
    core = harvesting(True)
    book, m = core.book, core.machine
    assert book.hanging_key == book.records[12].key
    m._enter("leave", 2)
    assert book.hanging_key is None
    m._enter("approach", 3)
    assert book.hanging_key == book.records[12].key
    m._enter("home", 4)
    assert book.hanging_key is None
