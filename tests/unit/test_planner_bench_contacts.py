"""The harvest bench's collision figures: contacts with the fruit being harvested apart, the
rest split by what was touched and by the planner's phase, flickering contacts as episodes;
and a run's events written for diagnosis."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from schemas.base import Header
from schemas.harvest import HarvestEvent
from schemas.sim import SimEvent
from services.planner import bench

MS = 1_000_000
CENTRES = {3: np.array([0.7, 0.0, 1.4]), 5: np.array([0.5, -0.3, 1.3])}


def hev(t_ms: int, event: str, **kw: object) -> HarvestEvent:
    h = Header(stamp_ns=t_ms * MS, seq=t_ms, source="planner")
    return HarvestEvent(header=h, event=event, **kw)  # type: ignore[arg-type]


def contact(t_ms: int, link: str, body: str, began: bool) -> SimEvent:
    detail = "contact began" if began else "contact ended after 3 ticks"
    h = Header(stamp_ns=t_ms * MS, seq=t_ms, source="sim")
    return SimEvent(header=h, kind="collision", body_a=link, body_b=body, detail=detail)


def collected() -> bench.Collected:
    got = bench.Collected()
    got.sightings = {7: [(0, (0.7, 0.0, 1.4))]}  # track 7 hangs where sim fruit 3 does
    got.harvest_events = [
        hev(100, "fruit_selected", fruit_id=7),
        hev(100, "phase_changed", fruit_id=7, phase_from="select", phase_to="approach"),
        hev(2000, "phase_changed", fruit_id=7, phase_from="approach", phase_to="harvest"),
        hev(5000, "fruit_collected", fruit_id=7, outcome="harvested"),
        hev(5000, "phase_changed", fruit_id=7, phase_from="cut", phase_to="leave"),
    ]
    got.sim_events = [
        contact(500, "cutter_link5", "branch_2", True),
        contact(560, "cutter_link5", "branch_2", False),
        contact(700, "cutter_link5", "branch_2", True),  # 140 ms later: the same episode
        contact(800, "cutter_link5", "branch_2", False),
        contact(2500, "cutter_link7", "fruit_3", True),  # the target: not a collision
        contact(2600, "collector_link6", "fruit_5", True),  # a neighbour, in the harvest
        contact(6000, "cutter_link5", "branch_2", True),  # 5.2 s later, leaving: a new one
        contact(6100, "collector_link3", "trunk", True),
    ]
    return got


def test_collisions_are_split_by_what_and_when() -> None:
    c = bench._contacts(collected(), CENTRES)
    assert (c["collisions"], c["target_contacts"], c["collision_episodes"]) == (5, 1, 4)
    # branch_2 at 0.7 s and at 6 s had been touched before: 3 of the 5 are first touches
    assert c["collisions_first_touch"] == 3
    assert c["collisions_by_kind"] == {"branch": 3, "fruit": 1, "trunk": 1}
    assert c["collisions_by_phase"] == {"approach": 2, "harvest": 1, "leave": 2}


def test_the_splits_add_up_over_seeds() -> None:
    row = {"cycles_s": [], "sim_s": 1.0, "wall_s": 1.0, "max_velocity_ratio": 0.5}
    row["reachable_fates"] = {}
    row.update(bench._contacts(collected(), CENTRES))
    tot = bench.aggregate([row, dict(row)])
    assert tot["collisions"] == 10 and tot["collision_episodes"] == 8
    assert tot["collisions_first_touch"] == 6
    old = {k: v for k, v in row.items() if k != "collisions_first_touch"}
    assert bench.aggregate([row, old])["collisions_first_touch"] is None  # unknown, not 0
    assert tot["collisions_by_kind"] == {"branch": 6, "fruit": 2, "trunk": 2}
    text = bench.table({"scenario": "x", "seeds": [0, 1], "mode": "inproc", "policies": {"n": tot}})
    assert "of which a body's first touch in the run" in text
    assert "collisions by what:" in text and "collisions by phase:" in text


def test_events_are_written_in_stamp_order(tmp_path: Path) -> None:
    out = tmp_path / "ev" / "nearest-3.jsonl"
    bench.write_events(collected(), out)
    lines = [json.loads(s) for s in out.read_text().splitlines()]
    assert len(lines) == 13
    stamps = [d["header"]["stamp_ns"] for d in lines]
    assert stamps == sorted(stamps)
    # at a tie the planner's event comes first (its tool command precedes the sim's answer)
    assert [d["topic"] for d in lines[-4:-2]] == ["harvest/events", "harvest/events"]
    assert lines[3] == {"topic": "sim/events", **collected().sim_events[1].model_dump(mode="json")}


def test_another_fruit_deferred_mid_attempt_does_not_end_it() -> None:
    got = collected()
    got.sightings[9] = [(0, (0.5, -0.3, 1.3))]  # track 9 on sim fruit 5
    skip = hev(2550, "fruit_skipped", fruit_id=9, reason="seen on its branch again")
    got.harvest_events.insert(3, skip)
    got.sim_events.insert(6, contact(2700, "basket", "fruit_3", True))  # still the target
    c = bench._contacts(got, CENTRES)
    assert (c["collisions"], c["target_contacts"]) == (5, 2)
