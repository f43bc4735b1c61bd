"""The persistent fruit list (paper §III-B): one entry per track ID, updated under a position
threshold, forgotten after N unseen frames, marked by the planner, and the nearest-fruit choice.

Paper: "We update the list if the position error between the previous state of a fruit ID is
smaller than a threshold, otherwise the previous state is kept. This ensures a robust approach to
counter temporary ID errors caused by occlusions. We delete IDs if they are not detected in the
scene for 100 image frames. Finally, we select the ID with smallest distance for harvesting."

One addition: a fruit that really moved (a hand moved it while it was hidden) would be stuck at
its old place forever under the paper's rule, so a jump that the next ``accept_jump_frames``
measurements confirm (all within the threshold of each other) is accepted (0: never, the
paper's rule).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from schemas.scene import FruitFlag

Mark = Literal["harvested", "unreachable"]


@dataclass(frozen=True)
class Measurement:
    """One fruit measured in one frame."""

    position_cam_m: np.ndarray
    position_world_m: np.ndarray
    semi_axis_h_m: float
    semi_axis_v_m: float
    flags: tuple[FruitFlag, ...] = ()  # quality flags of this measurement (e.g. border_cut)


@dataclass
class Entry:
    """The stored state of one fruit ID."""

    fruit_id: int
    state: Measurement
    frames_unseen: int
    last_seen_stamp_ns: int
    flags: tuple[FruitFlag, ...] = ()
    jump: list[Measurement] = field(default_factory=list)  # consecutive rejected measurements

    @property
    def distance_m(self) -> float:
        return float(np.linalg.norm(self.state.position_cam_m))


@dataclass(frozen=True)
class ListParams:
    update_threshold_m: float = 0.04
    forget_after_frames: int = 100
    accept_jump_frames: int = 15


class FruitList:
    """Persistent fruit list keyed by track ID (pure state, no I/O)."""

    def __init__(self, p: ListParams) -> None:
        self.p = p
        self.entries: dict[int, Entry] = {}
        # Kept after an entry is forgotten (a harvested fruit seen again in the basket stays
        # harvested); cleared when the planner targets the ID again (``unmark``), or by the
        # core, opt-in, when a harvested ID's confirmed move (``moved``) put it elsewhere.
        self.marks: dict[int, Mark] = {}
        self.moved: list[int] = []  # IDs whose confirmed jump was taken in the last step

    def step(
        self,
        stamp_ns: int,
        measured: dict[int, Measurement],
        failed: dict[int, FruitFlag],
    ) -> list[str]:
        """Advance one camera frame. ``measured``: IDs detected with a good measurement;
        ``failed``: IDs detected without one (reason, e.g. depth_invalid). Returns notes (what
        was added, kept, forgotten) for the log."""
        notes: list[str] = []
        self.moved = []
        seen = set(measured) | set(failed)
        for fid, m in sorted(measured.items()):
            e = self.entries.get(fid)
            if e is None:
                self.entries[fid] = Entry(fid, m, 0, stamp_ns, m.flags)
                notes.append(f"fruit {fid} added")
                continue
            e.frames_unseen, e.last_seen_stamp_ns = 0, stamp_ns
            notes += self._update(e, m)
        for fid, reason in sorted(failed.items()):
            e = self.entries.get(fid)
            if e is not None:  # kept from its last good state, flagged
                e.frames_unseen, e.last_seen_stamp_ns = 0, stamp_ns
                e.flags = _flags(e.state.flags, reason, "kept")
        for fid in sorted(set(self.entries) - seen):
            e = self.entries[fid]
            e.frames_unseen += 1
            if e.frames_unseen >= self.p.forget_after_frames:
                del self.entries[fid]
                notes.append(f"fruit {fid} forgotten after {e.frames_unseen} unseen frames")
            else:
                e.flags = _flags(e.state.flags, "stale")
        return notes

    def _update(self, e: Entry, m: Measurement) -> list[str]:
        jump = float(np.linalg.norm(m.position_world_m - e.state.position_world_m))
        if jump <= self.p.update_threshold_m:
            e.state, e.flags, e.jump = m, m.flags, []
            return []
        # Keep the stored state (the paper's guard against ID errors) unless the jump is
        # confirmed by consecutive measurements that agree with each other.
        if e.jump and _dist(m, e.jump[-1]) > self.p.update_threshold_m:
            e.jump = []
        e.jump.append(m)
        n = self.p.accept_jump_frames
        if n > 0 and len(e.jump) >= n:
            e.state, e.flags, e.jump = m, m.flags, []
            self.moved.append(e.fruit_id)
            return [f"fruit {e.fruit_id} moved {jump:.3f} m (confirmed by {n} frames)"]
        e.flags = _flags(e.state.flags, "position_jump", "kept")
        return [f"fruit {e.fruit_id}: kept its state, new position {jump:.3f} m away"]

    def mark(self, fruit_id: int, mark: Mark) -> None:
        """The planner's mark; harvested wins over unreachable (a fruit can be retried)."""
        if self.marks.get(fruit_id) != "harvested":
            self.marks[fruit_id] = mark

    def unmark(self, fruit_id: int) -> None:
        """The planner targets ``fruit_id`` again: the tracker re-attached the track of a fruit
        that is gone to another fruit, which the planner found still to harvest (its book keeps
        the identity). The mark was the old fruit's: kept, it would hide the target from
        ``selected`` and its working space would fill with occupied space (orchard seed 10: the
        tools stopped 13 cm short of a fruit reached on another run and gave it up)."""
        self.marks.pop(fruit_id, None)

    def selected(self, target: int | None = None) -> int | None:
        """The planner's current target when it is listed and unmarked; otherwise the nearest
        fruit (to the camera's optical centre) neither harvested nor unreachable (the paper's
        rule); ties go to the lower ID."""
        if target is not None and target in self.entries and target not in self.marks:
            return target
        free = [e for fid, e in self.entries.items() if fid not in self.marks]
        if not free:
            return None
        return min(free, key=lambda e: (e.distance_m, e.fruit_id)).fruit_id

    def sorted_entries(self) -> list[Entry]:
        return [self.entries[k] for k in sorted(self.entries)]


def _dist(a: Measurement, b: Measurement) -> float:
    return float(np.linalg.norm(a.position_world_m - b.position_world_m))


def _flags(base: tuple[FruitFlag, ...], *extra: FruitFlag) -> tuple[FruitFlag, ...]:
    return (*base, *(x for x in extra if x not in base))
