"""The planner's journal (services/planner/journal.py): what a restarted planner takes up."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from services.planner import Settings
from services.planner import journal as jr
from services.planner.book import MIN_SIGHTINGS, FruitBook
from services.planner.core import PlannerCore
from services.runtime.settings import load_settings
from tests.unit.test_planner_book import fruit, never, scene


def book_with_two() -> FruitBook:
    b = FruitBook(same_fruit_m=0.04, replan_m=0.015)
    b.update(scene(fruit(3, (0.6, 0.0, 1.3))), never)
    b.update(scene(fruit(3, (0.6, 0.0, 1.3), unseen=4), fruit(9, (0.61, 0.0, 1.3))), never)
    for _ in range(MIN_SIGHTINGS):
        b.update(scene(fruit(9, (0.61, 0.0, 1.3)), fruit(4, (0.7, 0.05, 1.25))), never)
    r = b.records[3]
    r.outcome, r.started_ns, r.finished_ns, r.spent_ns, r.cuts = "harvested", 10, 20, 10, 1
    r.outcome_id = 3  # harvested as 3, before its track moved on to 9
    b.records[4].losses, b.records[4].deferred = 1, True
    b.records[4].dish_back_m = 0.0  # the branch check's place for the dish
    b.records[4].dish_lower_m = 0.02  # … and its height, 2 cm under the rule's
    b.records[4].branch_refused_ns = 12_000_000_000  # its first refusal: looked at again later
    return b


def test_a_journal_gives_back_every_record_and_the_pending_cut(tmp_path: Path) -> None:
    b = book_with_two()
    path = tmp_path / "planner.json"
    cut = {"key": 4, "fruit_id": 4, "stamp_ns": 30, "basket_before": 1}
    jr.write(path, jr.dump(b, 2, cut))
    fresh = FruitBook(same_fruit_m=0.04, replan_m=0.015)
    assert jr.load(path, fresh) == (2, cut)
    assert sorted(fresh.records) == [3, 4] and fresh.id_to_key == {3: 3, 9: 3, 4: 4}
    got, was = fresh.records[3], b.records[3]
    assert (got.fruit_id, got.ids, got.outcome, got.outcome_id) == (9, [3, 9], "harvested", 3)
    assert (got.cuts, got.spent_ns, got.started_ns, got.finished_ns) == (1, 10, 10, 20)
    assert np.allclose(got.planned.centre_world_m, was.planned.centre_world_m)
    assert got.seen == was.seen and not got.in_scene  # until a scene lists it again
    assert fresh.records[4].losses == 1 and fresh.records[4].deferred
    assert fresh.records[4].dish_back_m == 0.0 and got.dish_back_m is None
    assert fresh.records[4].dish_lower_m == 0.02 and got.dish_lower_m == 0.0
    assert fresh.records[4].branch_refused_ns == 12_000_000_000 and got.branch_refused_ns is None
    assert fresh.records[4].sightings == b.records[4].sightings == MIN_SIGHTINGS
    # The harvested fruit is never a candidate again; the other one is once it is seen.
    fresh.update(scene(fruit(9, (0.61, 0.0, 1.3)), fruit(4, (0.7, 0.05, 1.25))), never)
    assert [r.key for r in fresh.candidates(45)] == [4]


@pytest.mark.parametrize("text", ["{", '{"version": 99}', '{"version": 1}'])
def test_an_unreadable_journal_starts_afresh(tmp_path: Path, text: str) -> None:
    path = tmp_path / "planner.json"
    path.write_text(text)
    b = FruitBook(same_fruit_m=0.04, replan_m=0.015)
    assert jr.load(path, b) is None and b.records == {}
    assert jr.load(tmp_path / "none.json", b) is None


def test_a_journal_with_a_bad_outcome_id_starts_afresh(tmp_path: Path) -> None:
    data = json.loads(jr.dump(book_with_two(), 2, None))
    data["records"][0]["outcome_id"] = "3"
    path = tmp_path / "planner.json"
    path.write_text(json.dumps(data))
    b = FruitBook(same_fruit_m=0.04, replan_m=0.015)
    assert jr.load(path, b) is None and b.records == {}
    del data["records"][0]["outcome_id"]  # a journal from before the field: loads, None
    path.write_text(json.dumps(data))
    assert jr.load(path, b) is not None and b.records[3].outcome_id is None


def test_a_restarted_core_resumes_without_a_second_run_start(tmp_path: Path) -> None:
    path = tmp_path / "planner.json"
    jr.write(path, jr.dump(book_with_two(), 3, None))
    core = PlannerCore(load_settings(Settings, {}), path)
    assert core.machine.started and core.contacts == 3
    assert core.book.records[3].outcome == "harvested"
    assert PlannerCore(load_settings(Settings, {})).machine.started is False  # no journal


def test_without_a_state_dir_there_is_no_journal(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(jr.STATE_DIR_ENV, raising=False)
    assert jr.journal_path() is None
    monkeypatch.setenv(jr.STATE_DIR_ENV, "/run/x")
    assert jr.journal_path() == Path("/run/x/planner.json")


def test_a_cut_sent_before_the_restart_is_confirmed_by_the_basket(tmp_path: Path) -> None:
    from schemas.base import Header
    from schemas.robot import BasketState
    from tests.contract.test_planner import status

    b = book_with_two()
    b.records[4].cuts = 1
    path = tmp_path / "planner.json"
    cut = {"key": 4, "fruit_id": 4, "stamp_ns": 5_000_000_000, "basket_before": 1}
    jr.write(path, jr.dump(b, 0, cut))
    core = PlannerCore(load_settings(Settings, {}), path)
    basket = BasketState(header=Header(stamp_ns=0, seq=0, source="sim"), load_kg=0.4, fruit_count=2)
    core.handle("robot/basket", basket)
    out = core.handle("control/status", status(650, 0.0))
    events = [m for t, m in out if t == "harvest/events"]
    assert [(e.event, e.fruit_id) for e in events][:2] == [
        ("phase_changed", 4),
        ("fruit_collected", 4),
    ]
    assert "run_started" not in [e.event for e in events]
    assert core.book.records[4].outcome == "harvested" and core.book.records[4].cuts == 1
    assert jr.load(path, FruitBook(0.04, 0.015)) == (0, None)  # journaled: settled, no cut


@pytest.mark.parametrize(
    ("field", "bad"),
    [
        ("dish_back_m", "0.0"),
        ("dish_back_m", float("nan")),
        ("dish_back_m", [0.0]),
        ("dish_lower_m", "0.02"),
        ("dish_lower_m", float("inf")),
        ("branch_refused_ns", 1.5e9),
        ("branch_refused_ns", -1),
        ("branch_refused_ns", True),
    ],
)
def test_a_journal_with_a_bad_dish_place_or_refusal_stamp_starts_afresh(
    tmp_path: Path, field: str, bad: object
) -> None:
    data = json.loads(jr.dump(book_with_two(), 2, None))
    data["records"][1][field] = bad
    path = tmp_path / "planner.json"
    path.write_text(json.dumps(data))
    b = FruitBook(same_fruit_m=0.04, replan_m=0.015)
    assert jr.load(path, b) is None and b.records == {}
    del data["records"][1][field]  # a journal from before the field: the rule, no refusal
    path.write_text(json.dumps(data))
    rule = 0.0 if field == "dish_lower_m" else None
    assert jr.load(path, b) is not None and getattr(b.records[4], field) == rule
