"""The harvest bench says where each reachable fruit went; the fates are read from the reasons
the planner itself writes, so these tests take the reasons from a real planner core."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from schemas.base import Header
from schemas.control import ControlStatus
from services.planner import bench
from services.planner.kinematics import ReachVerdict
from tests.unit.test_planner_select import A, B, C, core_with, fruit

NS = 1_000_000_000
TICK_NS = 20_000_000


def status(seq: int, err_m: float, t_ns: int) -> ControlStatus:
    return ControlStatus(
        header=Header(stamp_ns=t_ns, seq=t_ns // TICK_NS, source="controller"),
        target_seq=seq,
        abs_position_error_m=err_m,
        abs_orientation_error_rad=0.0,
        rel_position_error_m=0.0,
        rel_orientation_error_rad=0.0,
        converged=False,
    )


def test_a_stalled_approach_is_told_apart() -> None:
    # The cutter stays 5 cm off the pre-pose: stuck, deferred, tried again, unreachable.
    core = core_with("nearest", fruit(1, A, 0.5))
    m, t = core.machine, 0
    rec = core.book.records[1]
    while not rec.finished and t < 30 * NS:
        t += TICK_NS
        m.step(t, status(m.next_seq, 0.05, t), m.next_seq + 1, 0)
    assert rec.outcome == "unreachable"
    assert bench.fate_of(rec.outcome, rec.reason, 1.0) == "stalled_approach"


def test_blocked_and_out_of_reach_are_told_apart() -> None:
    # C is free, B blocks A; B given up → A is unreachable, blocked by B.
    core = core_with(
        "nearest", fruit(1, A, 0.5), fruit(2, B, 0.6), fruit(3, C, 0.7), try_blocked_max_m=0.0
    )
    core.book.records[2].outcome = "unreachable"
    core.book.records[3].outcome = "harvested"
    core.machine._select(0)
    a = core.book.records[1]
    assert bench.fate_of(a.outcome, a.reason, 1.0) == "blocked"
    core = core_with("nearest", fruit(1, A, 0.5))
    far = ReachVerdict(False, None, 0.08, 0.0)
    core.book.records[1].reach = (far, far)
    core.machine._select(0)
    a = core.book.records[1]
    assert bench.fate_of(a.outcome, a.reason, 1.0) == "out_of_reach"


def test_the_lost_reachable_fruit_are_listed_with_track_fate_and_reason() -> None:
    core = core_with(
        "nearest", fruit(1, A, 0.5), fruit(2, B, 0.6), fruit(3, C, 0.7), try_blocked_max_m=0.0
    )
    recs = core.book.records
    recs[2].outcome = "unreachable"
    recs[3].outcome = "harvested"
    core.machine._select(0)
    truth = SimpleNamespace(
        fruits=[SimpleNamespace(fruit_id=i, visible_fraction=0.5) for i in (10, 11, 12, 13)]
    )
    # sim fruit 10 is track 1 (blocked), 11 track 3 (collected), 12 never detected; 13 unreachable
    rows = bench._reachable_rows({10: recs[1], 11: recs[3]}, [10, 11, 12], {11}, truth)
    lost = [r for r in rows if r["fate"] != "harvested"]
    assert [(r["fruit"], r["track"], r["fate"]) for r in lost] == [
        (10, 1, "blocked"),
        (12, None, "not_detected"),
    ]
    assert "blocked by #2" in lost[0]["reason"] and lost[1]["reason"] == ""


@pytest.mark.parametrize(
    ("outcome", "visible", "fate"),
    [
        (None, 0.0, "not_detected_hidden"),
        (None, 0.3, "not_detected"),
        ("cut_failed", 1.0, "cut_failed"),
        ("dropped", 1.0, "dropped"),
        ("lost", 1.0, "lost"),
        ("pending", 1.0, "pending"),
        ("unreachable", 1.0, "other"),  # a reason the rules do not know
    ],
)
def test_the_other_fates(outcome: str | None, visible: float, fate: str) -> None:
    assert bench.fate_of(outcome, "", visible) == fate


def test_fates_add_up_over_runs() -> None:
    counts = [
        *("fruit", "reachable", "detected", "reachable_detected", "harvested"),
        *("harvested_reachable", "unreachable_true", "unreachable_blocked"),
        *("unreachable_reported", "unreachable_correct", "reachable_called_unreachable"),
        *("dropped", "collisions", "target_contacts", "commands_clamped"),
    ]
    base = {**dict.fromkeys(counts, 0), "cycles_s": [], "sim_s": 1.0, "wall_s": 1.0}
    base["max_velocity_ratio"] = 0.5
    rows = [
        {**base, "reachable_fates": {"harvested": 2, "blocked": 1}},
        {**base, "reachable_fates": {"harvested": 1, "not_detected": 3}},
    ]
    tot = bench.aggregate(rows)["reachable_fates"]
    assert tot["harvested"] == 3 and tot["blocked"] == 1 and tot["not_detected"] == 3
    assert set(tot) == set(bench.FATES) and sum(tot.values()) == 7
    agg = bench.aggregate(rows)
    text = bench.table({"scenario": "x", "seeds": [0], "mode": "inproc", "policies": {"n": agg}})
    assert "where the reachable fruit went" in text
    assert any(line.split() == ["not_detected", "3"] for line in text.splitlines())


def test_retraces_are_counted_from_the_planners_events() -> None:
    from schemas.harvest import HarvestEvent

    def ev(kind: str, reason: str) -> HarvestEvent:
        return HarvestEvent(
            header=Header(stamp_ns=0, seq=0, source="planner"),
            event=kind,  # type: ignore[arg-type]
            reason=reason,
        )

    events = [
        ev("fruit_skipped", "blocked: approach no progress (…); retracing 9 waypoints; retried"),
        ev("phase_changed", "retraced to where the attempt began"),
        ev("fruit_skipped", "unreachable: harvest timed out (…); retracing 3 waypoints"),
        ev("phase_changed", "retrace stuck, 0.40 rad short of where the attempt began"),
        ev("fruit_skipped", "unreachable: blocked by #3 (in the tools' way)"),
    ]
    assert bench.retraces(events) == {"retraces": 2, "retraces_short": 1}


def test_planned_approaches_are_counted_from_the_planners_events() -> None:
    from schemas.harvest import HarvestEvent

    def ev(kind: str, reason: str, to: str = "") -> HarvestEvent:
        return HarvestEvent(
            header=Header(stamp_ns=0, seq=0, source="planner"),
            event=kind,  # type: ignore[arg-type]
            phase_to=to,
            reason=reason,
        )

    events = [
        ev("phase_changed", "planned joint path 2.47 rad, 1028 checks (…)", "approach"),
        ev(
            "replanned",
            "planned path stuck 0.09 rad short of its end: planned again, planned "
            "joint path 1.2 rad, 80 checks (…)",
        ),
        ev("replanned", "planned path stuck 0.09 rad short of its end: pose goals"),
        ev(
            "phase_changed",
            "no planned path (no path within 3000 checks; …): pose goals",
            "approach",
        ),
        ev("phase_changed", "planned joint path 0.71 rad, 17 checks (…)", "approach"),
        ev("phase_changed", "", "harvest"),
        ev("replanned", "approach no progress (best task error 90 mm): planned joint path 2 rad"),
        ev("replanned", "approach no progress (best task error 80 mm): no planned path (…)"),
        ev("replanned", "fruit moved 1.7 cm"),
    ]
    assert bench.approach_plans(events) == {
        "approach_paths": 4,
        "approach_no_path": 2,
        "approach_paths_short": 2,
    }


def test_cuts_at_nothing_and_retries_are_told_apart() -> None:
    from schemas.sim import SimEvent

    def ev(kind: str, fid: int, d_m: float = 0.005) -> SimEvent:
        # The sim's wording (services/sim/fruits.py; its test reads one back).
        missed = f"nearest peduncle {d_m:.4f} m away (fruit {fid}), tolerance 0.015 m; …"
        return SimEvent(
            header=Header(stamp_ns=0, seq=0, source="sim"),
            kind=kind,  # type: ignore[arg-type]
            fruit_id=fid,
            detail=missed if kind == "cut_missed" else f"tip {d_m:.4f} m from the peduncle",
        )

    events = [
        ev("cut", 1),
        ev("cut_missed", 2, 0.021),  # a near miss …
        ev("cut_missed", 2, 0.019),  # … its retry missed too
        ev("cut_missed", 3, 0.030),
        ev("cut", 3),  # a retry that hit
        ev("cut_missed", 4, 0.178),  # at nothing: no retry of fruit 4 after it
        ev("cut_missed", 4, 0.175),
        ev("collected", 1),
    ]
    assert bench.cuts(events) == {
        "cuts": 7,
        "cuts_missed": 5,
        "cuts_at_nothing": 2,
        "retry_cuts": 2,
        "retry_cuts_hit": 1,
    }
