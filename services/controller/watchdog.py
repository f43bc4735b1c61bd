"""Input staleness: the watchdog that stops the arms.

On stamps (lock-step and live alike, all stamps share the sim/robot clock):
* a plan target older than ``target_timeout`` at a joint-state tick → hold;
* a joint-state stamp gap over ``joint_state_timeout`` → hold that tick (the loop was broken;
  the next tick has a trustworthy period again).
On the wall clock (live mode only, through the runtime's timer hook): no joint state at all for
``joint_state_timeout`` → publish a stop, then again every timeout while it lasts.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Period:
    """The control period to plan this tick with, s, and why the tick must hold, if it must."""

    dt_s: float
    stale: str | None = None


class Watchdog:
    """Args: timeouts in s; ``nominal_period_s`` is used when no stamp difference is known."""

    def __init__(
        self, joint_state_timeout_s: float, target_timeout_s: float, nominal_period_s: float
    ) -> None:
        self.js_timeout_ns = round(joint_state_timeout_s * 1e9)
        self.target_timeout_ns = round(target_timeout_s * 1e9)
        self.nominal_period_s = nominal_period_s
        self.last_js_stamp_ns: int | None = None
        self.js_count = 0
        # live mode: the wall time at which the timer first saw the latest joint state
        self._seen_count = 0
        self._seen_wall_ns: int | None = None
        self._next_stop_wall_ns: int | None = None

    def on_joint_state(self, stamp_ns: int) -> Period:
        """The period since the previous joint state (first tick: the nominal one)."""
        last, self.last_js_stamp_ns = self.last_js_stamp_ns, stamp_ns
        self.js_count += 1
        if last is None:
            return Period(self.nominal_period_s)
        gap = stamp_ns - last
        if gap > self.js_timeout_ns:
            return Period(
                self.nominal_period_s,
                f"watchdog: joint states resumed after a {gap / 1e6:.1f} ms gap "
                f"(> {self.js_timeout_ns / 1e6:.0f} ms)",
            )
        return Period(gap * 1e-9 if gap > 0 else self.nominal_period_s)

    def target_stale(self, js_stamp_ns: int, target_stamp_ns: int) -> str | None:
        age = js_stamp_ns - target_stamp_ns
        if age > self.target_timeout_ns:
            return (
                f"watchdog: plan target is {age / 1e6:.1f} ms old "
                f"(> {self.target_timeout_ns / 1e6:.0f} ms)"
            )
        return None

    def wall_check(self, wall_ns: int) -> str | None:
        """Live mode, every timer period: a reason to publish a stop now, or None."""
        if self.js_count == 0:
            return None  # nothing was ever commanded: nothing to stop
        if self.js_count != self._seen_count or self._seen_wall_ns is None:
            self._seen_count, self._seen_wall_ns = self.js_count, wall_ns
            self._next_stop_wall_ns = wall_ns + self.js_timeout_ns
            return None
        assert self._next_stop_wall_ns is not None
        if wall_ns < self._next_stop_wall_ns:
            return None
        self._next_stop_wall_ns = wall_ns + self.js_timeout_ns
        return (
            f"watchdog: no joint state for {(wall_ns - self._seen_wall_ns) / 1e6:.0f} ms "
            f"(wall clock, > {self.js_timeout_ns / 1e6:.0f} ms)"
        )
