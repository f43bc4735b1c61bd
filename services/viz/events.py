"""Text logs: harvest events, the controller's state changes, sim events, tool commands and the
run summary."""

from __future__ import annotations

from dataclasses import dataclass, field

from schemas.control import ControlStatus
from schemas.harvest import HarvestEvent, RunSummary
from schemas.robot import ToolCommand
from schemas.sim import SimEvent
from services.viz import paths
from services.viz.out import Out

WARN_EVENTS = {"fruit_dropped", "fruit_skipped", "fruit_lost"}
WARN_SIM = {"collision", "cut_missed", "dropped", "clamped"}


def log_harvest_event(out: Out, msg: HarvestEvent) -> None:
    parts = [msg.event.replace("_", " ")]
    if msg.fruit_id is not None:
        parts.append(f"fruit #{msg.fruit_id}")
    if msg.phase_from or msg.phase_to:
        parts.append(f"{msg.phase_from or '?'} → {msg.phase_to or '?'}")
    if msg.reason:
        parts.append(f"({msg.reason})")
    level = "WARN" if msg.event in WARN_EVENTS else "INFO"
    out.log(paths.LOG_HARVEST, out.rr.TextLog(" ".join(parts), level=level))


def log_sim_event(out: Out, msg: SimEvent) -> None:
    parts: list[str] = [msg.kind]
    if msg.fruit_id is not None:
        parts.append(f"fruit {msg.fruit_id}")
    bodies = " / ".join(b for b in (msg.body_a, msg.body_b) if b)
    if bodies:
        parts.append(bodies)
    if msg.detail:
        parts.append(f"({msg.detail})")
    level = "WARN" if msg.kind in WARN_SIM else "INFO"
    out.log(paths.LOG_SIM, out.rr.TextLog(" ".join(parts), level=level))


def log_tool(out: Out, msg: ToolCommand) -> None:
    fruit = f" fruit #{msg.fruit_id}" if msg.fruit_id is not None else ""
    out.log(paths.LOG_TOOL, out.rr.TextLog(f"{msg.tool}: {msg.action}{fruit}", level="INFO"))


def log_summary(out: Out, msg: RunSummary) -> None:
    text = (
        f"run summary: {msg.harvested} harvested, {msg.unreachable} unreachable, "
        f"{msg.dropped} dropped of {msg.detected} detected; {msg.collisions} collisions; "
        f"{msg.sim_time_s:.1f} s sim time"
    )
    if msg.scenario:
        text += f"; scenario {msg.scenario} seed {msg.seed}"
    out.log(paths.LOG_RUN, out.rr.TextLog(text, level="INFO"))


@dataclass
class ControlChanges:
    """Logs a line when the controller's phase, fallback, watchdog or convergence changes
    (not every tick: the plots show the values)."""

    last: tuple[str, str, bool, bool, str] | None = field(default=None)

    def __call__(self, out: Out, msg: ControlStatus) -> None:
        now = (msg.phase, msg.fallback, msg.watchdog, msg.converged, msg.reason)
        if now == self.last:
            return
        prev, self.last = self.last, now
        changes = []
        names = ("phase", "fallback", "watchdog", "converged", "reason")
        for i, name in enumerate(names):
            if (prev is None or prev[i] != now[i]) and (name != "reason" or now[i]):
                changes.append(f"{name}={now[i]}")
        if not changes:
            return
        bad = msg.watchdog or msg.fallback != "none"
        out.log(
            paths.LOG_CONTROL, out.rr.TextLog(", ".join(changes), level="WARN" if bad else "INFO")
        )
