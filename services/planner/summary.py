"""The run summary (harvest/summary): one FruitResult per physical fruit, and the totals."""

from __future__ import annotations

from schemas.base import Header
from schemas.harvest import FruitResult, RunSummary
from services.planner import Settings
from services.planner.book import FruitBook


def run_summary(
    header: Header, s: Settings, book: FruitBook, contacts: int, now_ns: int
) -> RunSummary:
    """Fruit never attempted keep the outcome 'pending' (e.g. the run time limit came first)."""
    results = []
    for rec in book.detected():
        started, finished = rec.started_ns, rec.finished_ns
        duration = rec.spent_ns * 1e-9 if started is not None else None
        results.append(
            FruitResult(
                fruit_id=rec.fruit_id,
                outcome=rec.outcome or "pending",
                reason=rec.reason,
                started_ns=started,
                finished_ns=finished,
                duration_s=duration,
                cuts=rec.cuts,
            )
        )

    def count(outcome: str) -> int:
        return sum(r.outcome == outcome for r in results)

    return RunSummary(
        header=header,
        scenario=s.scenario,
        seed=s.seed,
        fruits=tuple(results),
        detected=len(results),
        harvested=count("harvested"),
        unreachable=count("unreachable"),
        dropped=count("dropped"),
        cut_failed=count("cut_failed"),
        lost=count("lost"),
        collisions=contacts,
        order=s.order,
        sim_time_s=now_ns * 1e-9,
    )
