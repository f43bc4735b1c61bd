"""The run summary (harvest/summary): one FruitResult per physical fruit, and the totals.

The book keeps one record per track identity it could not tie to another; at the end of the
run, what the run has shown is used to fold records that were one fruit:

* a record never attempted (still to do, or forgotten by the scene) that overlaps another
  record (``same_fruit``) is that fruit under a second track (a twin, or an ID the tracker moved
  after a harvest);
* a fruit reported dropped (not in the basket after the cut, not seen on its branch) that is
  harvested later where it hung was not dropped: the cut missed (the tools hid it) and the
  harvest supersedes the verdict; its time and cuts add up;
* a record attempted, deferred and still to do at the end, that overlaps a record harvested
  after it was first attempted, was that fruit under the track ID it had before it moved: a
  hand moved the fruit, the tracker gave it a new ID, and the old track stayed for a while
  where it had hung (paper-exp1 seed 11: #6 approached, deferred, never seen again, while the
  fruit was harvested as #37); its time adds up.
"""

from __future__ import annotations

from dataclasses import dataclass

from schemas.base import Header
from schemas.harvest import FruitResult, RunSummary
from services.planner import Settings
from services.planner.book import FruitBook, FruitRecord
from services.planner.clutter import same_fruit


@dataclass
class PhysicalFruit:
    """One fruit of the summary: its last record, and the time and cuts of every record."""

    rec: FruitRecord
    started_ns: int | None
    spent_ns: int
    cuts: int

    def absorb(self, earlier: FruitRecord) -> None:
        """``earlier`` was an attempt at this fruit: its start, time and cuts count here."""
        starts = [t for t in (self.started_ns, earlier.started_ns) if t is not None]
        self.started_ns = min(starts, default=None)
        self.spent_ns += earlier.spent_ns
        self.cuts += earlier.cuts


def physical_fruit(records: list[FruitRecord]) -> list[PhysicalFruit]:
    """The records folded into physical fruit (module docstring), in the records' order."""
    out = {r.key: PhysicalFruit(r, r.started_ns, r.spent_ns, r.cuts) for r in records}
    for r in records:
        if _never_attempted(r) and any(_same(o, r, out) for o in records):
            del out[r.key]  # a second track of a fruit listed on its own
    for d in records:
        if d.outcome == "dropped" and d.finished_ns is not None:
            since_ns = d.finished_ns
        elif d.outcome is None and d.deferred and d.started_ns is not None:
            since_ns = d.started_ns
        else:
            continue
        later = [o for o in records if _harvested_after(o, since_ns) and _same(o, d, out)]
        if later:
            out[later[0].key].absorb(d)
            del out[d.key]
    return [out[r.key] for r in records if r.key in out]


def _never_attempted(r: FruitRecord) -> bool:
    """Never selected, and not settled by a check of its own (still to do, or forgotten)."""
    return r.started_ns is None and r.outcome in (None, "lost")


def _same(o: FruitRecord, r: FruitRecord, listed: dict[int, PhysicalFruit]) -> bool:
    """``o`` is another record, still listed, overlapping ``r``."""
    return o is not r and o.key in listed and same_fruit(o.planned, r.planned)


def _harvested_after(o: FruitRecord, t_ns: int) -> bool:
    return o.outcome == "harvested" and o.started_ns is not None and o.started_ns >= t_ns


def run_summary(
    header: Header, s: Settings, book: FruitBook, contacts: int, now_ns: int
) -> RunSummary:
    """Fruit never attempted keep the outcome 'pending' (e.g. the run time limit came first)."""
    results = []
    for f in physical_fruit(book.detected()):
        rec = f.rec
        duration = f.spent_ns * 1e-9 if f.started_ns is not None else None
        results.append(
            FruitResult(
                # The ID its outcome's event named: the record may carry another by now
                # (orchard seed 10: the events named 3 and 16, the summary said 7 and 124).
                fruit_id=rec.outcome_id if rec.outcome_id is not None else rec.fruit_id,
                outcome=rec.outcome or "pending",
                reason=rec.reason,
                started_ns=f.started_ns,
                finished_ns=rec.finished_ns,
                duration_s=duration,
                cuts=f.cuts,
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
