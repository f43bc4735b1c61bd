"""Harvest events (state-machine transitions) and the run summary."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from schemas.base import Frozen, Message, NonNegFloat

HarvestEventKind = Literal[
    "run_started",
    "fruit_selected",
    "phase_changed",
    "cut_sent",
    "fruit_collected",
    "fruit_dropped",
    "fruit_skipped",
    "fruit_lost",
    "replanned",
    "run_finished",
]
FruitOutcome = Literal["harvested", "dropped", "unreachable", "cut_failed", "lost", "pending"]


class HarvestEvent(Message):
    """One transition of the harvest state machine, or a notable outcome."""

    event: HarvestEventKind = Field(description="What happened.")
    fruit_id: int | None = Field(default=None, ge=1, description="Fruit concerned, if any.")
    phase_from: str = Field(default="", description="Phase before the transition.")
    phase_to: str = Field(default="", description="Phase after the transition.")
    reason: str = Field(default="", description="Why, in words (e.g. the skip reason).")
    outcome: FruitOutcome | None = Field(
        default=None,
        description="The fruit's outcome when this event settles it (fruit_skipped: "
        "'unreachable' marks the fruit unreachable in scene/state).",
    )


class FruitResult(Frozen):
    """Outcome of one fruit in a run."""

    fruit_id: int = Field(ge=1, description="Fruit (track) ID.")
    outcome: FruitOutcome = Field(description="Final outcome.")
    reason: str = Field(default="", description="Why, for outcomes other than harvested.")
    started_ns: int | None = Field(default=None, ge=0, description="Selection stamp, ns.")
    finished_ns: int | None = Field(
        default=None,
        ge=0,
        description="End of its cycle, ns: the tools back at its pre-pose (or the outcome, when "
        "the tools never reached it).",
    )
    duration_s: NonNegFloat | None = Field(
        default=None,
        description="Sim seconds the tools spent on it: from its selection to the tools back at "
        "its pre-pose, summed over attempts (a blocked fruit retried later, a lost one).",
    )
    cuts: int = Field(default=0, ge=0, description="Cut commands sent for it.")


class RunSummary(Message):
    """Totals of a run, published once when the run ends."""

    scenario: str = Field(default="", description="Scenario name.")
    seed: int | None = Field(default=None, description="Scenario seed.")
    fruits: tuple[FruitResult, ...] = Field(default=(), description="Per-fruit outcomes.")
    detected: int = Field(ge=0, description="Fruits ever in the persistent list.")
    harvested: int = Field(ge=0, description="Fruits collected in the basket.")
    unreachable: int = Field(ge=0, description="Fruits skipped as unreachable.")
    dropped: int = Field(default=0, ge=0, description="Fruits cut but not collected.")
    cut_failed: int = Field(default=0, ge=0, description="Fruits given up after failed cuts.")
    lost: int = Field(default=0, ge=0, description="Fruits lost from view and given up.")
    collisions: int = Field(
        default=0,
        ge=0,
        description="Robot–trunk/fruit contacts counted by the robot (the controller's distance "
        "model below 0); the sim's own contact count is in sim/truth (evaluation).",
    )
    order: str = Field(default="", description="Harvest-order policy of the run.")
    sim_time_s: NonNegFloat = Field(description="Sim time of the run, s.")
