"""`harvest run`'s harvest display: a line per harvest event, a progress bar of fruit, and the
summary table when the planner has published its run summary.

It listens on the supervisor's bus session (the run's namespace): harvest/events and
harvest/summary from the planner, and the last sim/truth's counters for the sim's own contact
count (evaluation only, shown beside the robot-side count; the planner never reads it).
"""

from __future__ import annotations

import threading
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from schemas.harvest import HarvestEvent, RunSummary
from schemas.sim import GroundTruth

SETTLED = {"fruit_collected", "fruit_dropped", "fruit_skipped"}
QUIET_EVENTS = {"phase_changed"}  # one line per fruit outcome is enough on a terminal
COLOURS = {
    "fruit_collected": "green",
    "fruit_dropped": "yellow",
    "fruit_skipped": "yellow",
    "fruit_lost": "yellow",
    "run_finished": "bold",
}


def event_line(e: HarvestEvent) -> str:
    """One harvest event as a terminal line (sim time first)."""
    parts = [f"{e.header.stamp_ns * 1e-9:7.2f} s", e.event.replace("_", " ")]
    if e.fruit_id is not None:
        parts.append(f"#{e.fruit_id}")
    if e.phase_from or e.phase_to:
        parts.append(f"{e.phase_from or '?'} → {e.phase_to or '?'}")
    if e.reason:
        parts.append(f"({e.reason})")
    return "  ".join(parts)


class HarvestWatch:
    """Subscribes to the planner's outputs on a bus and shows them as they come."""

    def __init__(self, console: Console, show_phases: bool = False) -> None:
        self.console = console
        self.show_phases = show_phases
        self.summary: RunSummary | None = None
        self.sim_contacts: int | None = None
        self.events = 0
        self._fruit: set[int] = set()
        self._settled: set[int] = set()
        self._lock = threading.Lock()
        self.progress = Progress(
            TextColumn("[bold]fruit"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.description}"),
            TimeElapsedColumn(),
            console=console,
            transient=True,
        )
        self._task = self.progress.add_task("", total=None)

    def attach(self, bus: Any) -> None:
        """Supervisor hook: subscribe once the run's bus is open, and start the bar."""
        bus.subscribe("harvest/events", self._on_event)
        bus.subscribe("harvest/summary", self._on_summary)
        bus.subscribe("sim/truth", self._on_truth)
        self.progress.start()

    def stop(self) -> None:
        self.progress.stop()

    def _on_event(self, _key: str, e: HarvestEvent) -> None:
        with self._lock:
            self.events += 1
            if e.fruit_id is not None and e.event in ("fruit_selected", *SETTLED):
                self._fruit.add(e.fruit_id)
            if e.fruit_id is not None and e.event in SETTLED:
                self._settled.add(e.fruit_id)
            self.progress.update(
                self._task,
                total=max(len(self._fruit), 1),
                completed=len(self._settled),
                description=e.event.replace("_", " "),
            )
        if e.event in QUIET_EVENTS and not self.show_phases:
            return
        colour = COLOURS.get(e.event)
        line = event_line(e)
        self.progress.console.print(f"[{colour}]{line}[/]" if colour else line, highlight=False)

    def _on_summary(self, _key: str, s: RunSummary) -> None:
        self.summary = s

    def _on_truth(self, _key: str, t: GroundTruth) -> None:
        self.sim_contacts = t.counters.contacts


def summary_tables(
    s: RunSummary, sim_contacts: int | None, wall_s: float, mcap: Any
) -> list[Table]:
    """The harvest table (totals) and the per-fruit table."""
    t = Table(title="harvest", show_header=False)
    t.add_column("what")
    t.add_column("value", justify="right")
    if s.scenario:
        t.add_row("scenario", f"{s.scenario} (seed {s.seed})")
    t.add_row("harvest order", s.order)
    t.add_row("fruit detected", str(s.detected))
    t.add_row("harvested", f"[green]{s.harvested}[/]")
    t.add_row("unreachable", str(s.unreachable))
    for name, n in (("dropped", s.dropped), ("cut failed", s.cut_failed), ("lost", s.lost)):
        if n:
            t.add_row(name, f"[yellow]{n}[/]")
    coll = f"{s.collisions} (robot)"
    if sim_contacts is not None:
        coll += f", {sim_contacts} (sim contacts)"
    t.add_row("collisions", coll)
    t.add_row("sim time", f"{s.sim_time_s:.1f} s")
    cycles = sorted(f.duration_s for f in s.fruits if f.outcome == "harvested" and f.duration_s)
    if cycles:
        t.add_row("median cycle per harvested fruit", f"{cycles[len(cycles) // 2]:.2f} s")
    t.add_row("wall time", f"{wall_s:.1f} s")
    t.add_row("recording", str(mcap) if mcap is not None else "(not recorded)")
    f = Table(title="fruit")
    for col in ("fruit", "outcome", "cycle s", "cuts", "reason"):
        f.add_column(col, justify="right" if col in ("fruit", "cycle s", "cuts") else "left")
    for r in s.fruits:
        colour = "green" if r.outcome == "harvested" else "yellow"
        f.add_row(
            f"#{r.fruit_id}",
            f"[{colour}]{r.outcome}[/]",
            f"{r.duration_s:.2f}" if r.duration_s is not None else "-",
            str(r.cuts),
            r.reason,
        )
    return [f, t] if s.fruits else [t]
