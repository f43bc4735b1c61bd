"""services/controller/watchdog.py: staleness on stamps, and on the wall clock in live mode."""

from __future__ import annotations

from services.controller.watchdog import Watchdog

MS = 1_000_000


def dog() -> Watchdog:
    return Watchdog(0.1, 0.1, 1 / 120)


def test_the_first_tick_uses_the_nominal_period_then_the_stamp_difference() -> None:
    w = dog()
    assert w.on_joint_state(0).dt_s == 1 / 120
    p = w.on_joint_state(10 * MS)
    assert p.stale is None and abs(p.dt_s - 0.01) < 1e-12


def test_a_joint_state_gap_over_the_timeout_holds_that_tick_only() -> None:
    w = dog()
    w.on_joint_state(0)
    gap = w.on_joint_state(250 * MS)
    assert gap.stale is not None and "250.0 ms gap" in gap.stale
    assert w.on_joint_state(258 * MS).stale is None


def test_a_target_older_than_the_timeout_is_stale() -> None:
    w = dog()
    assert w.target_stale(100 * MS, 0) is None  # exactly the timeout: still fresh
    reason = w.target_stale(101 * MS, 0)
    assert reason is not None and "101.0 ms old" in reason


def test_the_wall_clock_watchdog_fires_when_joint_states_stop_and_repeats() -> None:
    w = dog()
    assert w.wall_check(0) is None  # nothing commanded yet: nothing to stop
    w.on_joint_state(0)
    assert w.wall_check(5 * MS) is None  # first sight of that joint state
    assert w.wall_check(100 * MS) is None
    first = w.wall_check(106 * MS)
    assert first is not None and "no joint state for 101 ms" in first
    assert w.wall_check(150 * MS) is None  # once per timeout while it lasts
    assert w.wall_check(207 * MS) is not None
    w.on_joint_state(8 * MS)  # they come back
    assert w.wall_check(220 * MS) is None and w.wall_check(300 * MS) is None
