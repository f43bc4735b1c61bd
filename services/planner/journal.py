"""The planner's journal: what a restarted planner must not forget.

The planner is the only service whose state cannot be rebuilt from its inputs: a harvested
fruit is in the basket (no longer seen on the tree, soon forgotten by the scene), and a cut is
irreversible. So, under the supervisor, the planner writes its book of fruit (outcome, reason,
cycle stamps, cuts, losses, track IDs, last estimate), its robot-side contact count and, while
it waits for a cut to be confirmed, that cut (fruit, stamp, basket count before) to
``$HARVEST_STATE_DIR/planner.json`` whenever something happens (any harvest event or a new
contact), atomically (write + rename). The supervisor makes that folder for the run (empty at
the start, removed at the end), so only a *restarted* planner finds a journal, and takes it:

* settled fruit keep their outcome (a harvested fruit is counted once, never tried again);
* unsettled ones keep cuts, losses, time spent, their deferred mark and the dish's place the
  branch check chose, and are selected anew
  (the new process starts from select: a fruit being approached is approached again);
* a cut sent but not yet confirmed is awaited again (the basket count going up settles it as
  harvested; else the usual verdict after ``collect_timeout_s`` from the original cut);
* no second ``run_started`` event; the summary counts the contacts of both processes.

Not restored: the IK cache (recomputed), the dish poses of recent frames (32 frames, refilled
in 2 s), progress of the phase under way. Without ``HARVEST_STATE_DIR`` (a planner started by
hand, tests, resim) there is no journal and behaviour is unchanged."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from schemas.scene import Fruit
from services.planner.book import MIN_SIGHTINGS, FruitBook, FruitRecord
from services.planner.poses import FruitShape

log = logging.getLogger("planner")
VERSION = 1
STATE_DIR_ENV = "HARVEST_STATE_DIR"


def journal_path() -> Path | None:
    """``$HARVEST_STATE_DIR/planner.json``; None when the variable is unset or empty."""
    d = os.environ.get(STATE_DIR_ENV, "")
    return Path(d) / "planner.json" if d else None


def _record(r: FruitRecord) -> dict[str, Any]:
    return {
        "key": r.key,
        "fruit_id": r.fruit_id,
        "ids": list(r.ids),
        "seen": r.seen.model_dump(mode="json"),
        "planned": [r.planned.centre_world_m.tolist(), r.planned.d_h_m, r.planned.d_v_m],
        "planned_whole": r.planned_whole,
        "in_basket": r.in_basket,
        "outcome": r.outcome,
        "outcome_id": r.outcome_id,
        "reason": r.reason,
        "started_ns": r.started_ns,
        "finished_ns": r.finished_ns,
        "spent_ns": r.spent_ns,
        "deferred": r.deferred,
        "cuts": r.cuts,
        "losses": r.losses,
        "scene_mark_ok": r.scene_mark_ok,
        "last_seen_ns": r.last_seen_ns,
        "sightings": r.sightings,
        "dish_back_m": r.dish_back_m,
        "dish_lower_m": r.dish_lower_m,
        "branch_refused_ns": r.branch_refused_ns,
    }


def _unrecord(d: dict[str, Any]) -> FruitRecord:
    centre, d_h, d_v = d["planned"]
    return FruitRecord(
        key=d["key"],
        fruit_id=d["fruit_id"],
        ids=list(d["ids"]),
        seen=Fruit.model_validate(d["seen"]),
        planned=FruitShape(np.array(centre, float), float(d_h), float(d_v)),
        in_scene=False,  # until the next scene state says otherwise
        in_basket=d["in_basket"],
        outcome=d["outcome"],
        outcome_id=_track_id_or_none(d.get("outcome_id")),
        reason=d["reason"],
        started_ns=d["started_ns"],
        finished_ns=d["finished_ns"],
        spent_ns=d["spent_ns"],
        deferred=d["deferred"],
        cuts=d["cuts"],
        losses=d["losses"],
        planned_whole=d["planned_whole"],
        scene_mark_ok=d.get("scene_mark_ok", True),
        last_seen_ns=d.get("last_seen_ns"),
        sightings=d.get("sightings", MIN_SIGHTINGS),  # older journals: records were fruit
        dish_back_m=_metres_or_none(d.get("dish_back_m")),  # a cut awaited leaves with it
        dish_lower_m=_metres_or_none(d.get("dish_lower_m", 0.0), "dish_lower_m") or 0.0,
        branch_refused_ns=_stamp_or_none(d.get("branch_refused_ns")),
    )


def _metres_or_none(v: Any, name: str = "dish_back_m") -> float | None:
    """A record's ``dish_back_m`` (``name``): None (the pose rule; older journals) or a finite
    float."""
    if v is None:
        return None
    if type(v) not in (int, float) or not np.isfinite(v):
        raise ValueError(f"{name} {v!r} is not a distance in metres")
    return float(v)


def _stamp_or_none(v: Any) -> int | None:
    """A record's ``branch_refused_ns``: None (never refused; older journals) or a stamp."""
    if v is None:
        return None
    if type(v) is not int or v < 0:
        raise ValueError(f"branch_refused_ns {v!r} is not a sim stamp in nanoseconds")
    return v


def _track_id_or_none(v: Any) -> int | None:
    """A record's ``outcome_id``: a track ID (an int ≥ 1) or None (older journals have none)."""
    if v is None or (type(v) is int and v >= 1):
        return v
    raise ValueError(f"outcome_id {v!r} is not a track ID")


def dump(book: FruitBook, contacts: int, cut: dict[str, int] | None) -> str:
    return json.dumps(
        {
            "version": VERSION,
            "records": [_record(r) for _, r in sorted(book.records.items())],
            "contacts": contacts,
            "cut": cut,
        }
    )


def write(path: Path, text: str) -> None:
    """Atomically (a reader or a kill mid-write never sees half a file)."""
    tmp = path.with_suffix(".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def load(path: Path, book: FruitBook) -> tuple[int, dict[str, int] | None] | None:
    """Fill ``book`` from the journal; returns (contacts, pending cut) or None (no journal, or
    one that cannot be read: logged, and the planner starts afresh)."""
    try:
        data = json.loads(path.read_text())
        if data.get("version") != VERSION:
            raise ValueError(f"version {data.get('version')!r}, expected {VERSION}")
        records = [_unrecord(d) for d in data["records"]]
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        log.error("journal %s cannot be read (%s): starting afresh", path, exc)
        return None
    for r in records:
        book.records[r.key] = r
        for fid in r.ids:
            book.id_to_key[fid] = r.key
    return int(data["contacts"]), data.get("cut")
