"""The planner's book of fruit: one record per physical fruit, kept from the scene's persistent
list, with the identity rules the harvest needs.

* A record is keyed by the first track ID it had. A new ID within ``same_fruit_m`` of a record
  that is finished, or that is not seen now while the new ID is, is that record (a tracker ID
  switch, or a stale duplicate of a fruit already dealt with): the record takes the new ID and
  keeps the old ones (all of them are ignored together by the controller while cutting).
* A track ID is another fruit once it is seen, fresh, farther than ``same_fruit_m`` from its
  record when that record is finished (the fruit was harvested or given up) or has moved on to
  a newer ID: the tracker re-attached the track of a fruit that is gone to another fruit's box.
  The ID leaves the old record and starts a new one (a fresh negative key; the scene's mark on
  that ID is about the old fruit and is not trusted for it). A fruit seen in our dish, or a
  dropped fruit seen lower than where it was cut, is that fruit: not a new one.
* A fruit last seen inside the robot's own dish is not a fruit on the tree (a collected fruit
  seen in the basket): it is marked ``in_basket`` and never selected.
* The planning position of a record changes only when the estimate moves more than
  ``replan_m`` from it: perception noise does not shake the targets; a real move re-plans.
  A target planned from a whole view is not moved by a stale or much smaller view, nor by a
  cut one unless that view puts the fruit more than ``MOVED_VIEW_M`` away (a fruit pushed aside).
  An unflagged view much smaller than the fruit has shown lately is no whole view: a fruit does
  not shrink, so something the scene did not flag (a leaf, a hand) cut it.
* With ``follow_cut_views`` (opt-in): a target the scene has never shown whole (a side always
  hidden by a leaf, common in the orchard) follows the median of its last ``CUT_VIEWS`` fresh
  views that are not smaller than the fruit has shown, once that median is ``REFINE_M`` from
  it: no single view moves it. A "whole" view the fruit has since shown itself larger than was
  cut: its target is followed the same way.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from schemas.harvest import FruitOutcome
from schemas.scene import Fruit, SceneState
from services.planner.kinematics import DishPose, ReachVerdict
from services.planner.poses import FruitShape
from services.robot.model import TOOLS

SHRUNK_VIEW = 0.85
"""A fresh, unflagged view whose d_h or d_v is below this share of those a target was planned from
(a whole view) is a view cut by something the scene did not flag: it does not move the target.
A fruit does not shrink; this happens after a tracker restart (a new track ID, so the scene has
no whole view stored for it) while an arm passes in front: measured 27 % smaller and 1.2 cm
off, the cutter then missed the peduncle twice."""

MOVED_VIEW_M = 0.025
"""A fresh view cut on a side (flagged or somewhat smaller; the scene takes a cut semi-axis
from the other one) whose centre lies farther than this from a target planned from a
whole view moves the target all the same, which stays held to whole-view rules: such a view's
centre is off by about a centimetre, while a fruit pushed by a hand moves farther, and the
views during the push are cut by the hand (paper-exp1: the hand moved a fruit 6 cm and the cut
went where it had hung)."""

MOVED_VIEW_SIZE = 0.75
"""... and whose d_h and d_v are at least this share of the planned ones: the views of the
pushed fruit measured 0.77-0.86 of its whole view's d_h; a view after a tracker restart with an
arm in front, 1.2 cm off, 0.73 (``SHRUNK_VIEW``)."""

RECENT_VIEWS = 45
"""Fresh views (cut on a side or whole) a record keeps the sizes of: three seconds at 15 Hz."""

SEEN_SIZE_QUANTILE = 75
"""The size a fruit has shown: this percentile of its recent views' semi-axes (above the
median: a fruit hidden in part for a while still showed its size before; below the maximum:
a view cut by a hand can be 17 % too large)."""

MIN_RECENT_VIEWS = 10
"""Recent views before their size is trusted as the fruit's."""

CUT_FLAGS = {"edge_occluded", "border_cut", "kept"}
"""Flags of a fresh view that ``_this_frames`` takes: cut on a side, whether the scene computed
the estimate from it or kept its stored one (``kept``). Only ``_reused`` tells the two apart:
the other rules were measured with both."""

CUT_VIEWS = 9
"""Fresh views of its own size (0.6 s at 15 Hz) whose median a target never seen whole follows.
Before, such a target moved only when one view strayed ``replan_m`` (1.5 cm) from it, and took
that view: by selection an outlier (orchard seed 4: the cut views read 2-5 mm from the truth for
5 s while the target kept a 16 mm-off view from an arm passing in front, taken as it shrank
from 44 to 29 mm; the cutter missed the peduncle by 27 mm)."""

REFINE_M = 0.005
"""The median of those views this far from such a target moves it: the views scatter 2-3 mm."""

FALL_S = 2.0
"""For this long after a cut, a fresh view under or beside the cut fruit (``FALL_ZONE_M``) that
would start a record, or take an ID off its record (a reuse) or far from it, is the cut fruit
falling, bouncing off the rim or rolling out of the dish: the tracker puts whatever ID is near
on it (orchard seed 0: 0.45 s after a cut, the ID of a fruit harvested earlier came to the
falling fruit 10 cm from where it hung; reborn there as a new fruit, it was selected 9 s later
and the shears closed 19 cm from any peduncle, a "dropped" fruit that never was). It is not a
fruit on the tree; such views are counted (``fall_views``) and otherwise left out. A fruit
falls from the crown to the ground in about 0.5 s."""

FALL_ZONE_M = 0.25
"""… within this horizontally of where the cut fruit hung, and not above its top."""

STILL_S, STILL_M = 0.3, 0.015
"""… unless the scene has estimated the view's ID within ``STILL_M`` of one place for
``STILL_S``: a falling or bouncing fruit does not hold still (it falls 0.44 m in 0.3 s), a fruit
hanging there does (paper-exp1 seed 11: a hand left a fruit 16 cm from and 7 cm under a fruit
cut 0.1 s before; its new track was left out for 2 s, and the tools went for the old track, where
the fruit had hung)."""

MIN_SIGHTINGS = 3
"""Scene states with a fresh sighting before a record is a candidate or stands in the tools'
way: a fruit on the tree shows in many (15 a second), a flash does not (paper-exp2 seed 11:
a harvested fruit flung out of the dish, seen once at the image border 30 cm from the tree,
was called unreachable and, listed for seconds, gave two fruit up as blocked by it). The
controller still avoids whatever the scene lists."""


@dataclass
class FruitRecord:
    """One physical fruit as the planner sees it."""

    key: int  # first track ID
    fruit_id: int  # current track ID
    ids: list[int]
    seen: Fruit  # latest scene entry
    planned: FruitShape  # the position and size the poses are computed from
    viewed: Fruit | None = None  # latest entry the scene estimated from a view of this frame
    in_scene: bool = True
    in_basket: bool = False
    outcome: FruitOutcome | None = None  # None: still to do
    outcome_id: int | None = None  # the track ID its outcome was reported under (the events')
    reason: str = ""
    started_ns: int | None = None  # first selection
    finished_ns: int | None = None  # end of the cycle that settled it
    attempt_ns: int | None = None  # start of the current attempt
    spent_ns: int = 0  # sim time the tools spent on it, over every attempt
    deferred: bool = False  # blocked once: retried when nothing else is left
    tried_blocked: bool = False  # gone for once although blocked (``try_blocked_max_m``)
    cuts: int = 0
    aim_deeper_m: float = 0.0  # the poses aim this far beyond ``planned`` (a retried cut)
    losses: int = 0
    views_after_drop: int = 0  # fresh views where it hung since it was reported dropped
    frozen: bool = False  # cutting or leaving: the planning position no longer follows the scene
    planned_whole: bool = False  # ``planned`` comes from a whole view (no side cut, fresh)
    pushed: bool = False  # since then moved by cut views (``MOVED_VIEW_M``): followed closely
    scene_mark_ok: bool = True  # False: its ID was another fruit's, whose scene mark it carries
    reach: tuple[ReachVerdict, ReachVerdict] | None = None  # harvest pose, pre-pose
    dish_back_m: float | None = None  # the dish's place the branch check chose (None: the rule)
    dish_lower_m: float = 0.0  # … and how much lower than the rule it put the dish, m
    branch_refused_ns: int | None = None  # the branch check's first refusal (None: none yet)
    last_seen_ns: int | None = None  # the last scene stamp with a fresh sighting of any of its IDs
    first_seen_ns: int | None = None  # the first such stamp
    sightings: int = 0  # scene states with a fresh sighting of it outside our dish
    sizes_m: deque[tuple[float, float]] = field(
        default_factory=lambda: deque(maxlen=RECENT_VIEWS)
    )  # (d_h, d_v) of its recent fresh views: what size it has shown
    cut_views: deque[FruitShape] = field(
        default_factory=lambda: deque(maxlen=CUT_VIEWS)
    )  # its last fresh views of its own size, while never seen whole (``CUT_VIEWS``)

    @property
    def confirmed(self) -> bool:
        """Seen in at least ``MIN_SIGHTINGS`` scene states: a fruit, not a flash."""
        return self.sightings >= MIN_SIGHTINGS

    @property
    def finished(self) -> bool:
        return self.outcome is not None

    def unseen_frames(self) -> int:
        return self.seen.frames_unseen


def shape_of(f: Fruit) -> FruitShape:
    return FruitShape(np.array(f.position_world_m, float), f.semi_axis_h_m, f.semi_axis_v_m)


InDish = Callable[..., bool]
"""``in_dish(fruit, resting=False)``: the sighting is in our dish. ``resting``: the fruit is known
to be in the basket (harvested), so a view of its top above the rim counts too."""


@dataclass
class FruitBook:
    """Records by key, the ID map, and the dish poses at recent camera stamps."""

    same_fruit_m: float
    replan_m: float
    follow_cut_views: bool = False  # True: ``CUT_VIEWS`` (opt-in: planner.follow_cut_views)
    records: dict[int, FruitRecord] = field(default_factory=dict)
    id_to_key: dict[int, int] = field(default_factory=dict)
    dish_at: dict[int, DishPose] = field(default_factory=dict)  # camera stamp → dish
    switches: list[tuple[int, int, int]] = field(default_factory=list)  # (key, old, new)
    moved: list[tuple[int, float]] = field(default_factory=list)  # (key, metres)
    reborn: list[tuple[int, int, int]] = field(default_factory=list)  # (old key, new key, ID)
    kept_far: list[tuple[int, int]] = field(default_factory=list)  # (key, ID): not reborn
    # The record the tools go for (approach, harvest; planner.target_hangs_over_dish): our dish
    # is under it by design, so a sighting of it in the dish is not of a fruit in the basket.
    hanging_key: int | None = None
    # The record in the harvest phase (planner.hold_cut_views_in_harvest): its cut views are
    # neither kept nor followed while the tools are in front of it.
    held_key: int | None = None
    # The last cut: (record key, where the fruit hung, the cut's stamp ns); ``FALL_S``.
    last_cut: tuple[int, FruitShape, int] | None = None
    fall_views: list[tuple[int, int]] = field(default_factory=list)  # (stamp ns, ID) left out
    # IDs with no record whose views were left out as a falling fruit's: their stale or kept
    # entries (the scene's echo of such a view) make no record either
    fell_ids: set[int] = field(default_factory=set)
    # ID → (where its estimates have stayed within STILL_M, since when ns): ``STILL_S``
    still: dict[int, tuple[np.ndarray, int]] = field(default_factory=dict)
    back_on_branch: list[int] = field(default_factory=list)  # keys: dropped, seen hanging

    def note_cut(self, key: int, stamp_ns: int) -> None:
        """The shears closed on record ``key``: its fruit may fall now (``FALL_S``)."""
        self.last_cut = (key, self.records[key].planned, stamp_ns)

    def _falling(self, f: Fruit, stamp_ns: int) -> bool:
        """``f`` is a fresh view where the fruit cut last may be falling now (``FALL_S``)."""
        if self.last_cut is None or f.frames_unseen != 0:
            return False
        key, hung, cut_ns = self.last_cut
        if not 0 <= stamp_ns - cut_ns <= FALL_S * 1e9 or f.fruit_id in self.records[key].ids:
            return False
        p, c = np.array(f.position_world_m, float), hung.centre_world_m
        if np.hypot(*(p[:2] - c[:2])) > FALL_ZONE_M or p[2] > c[2] + hung.d_v_m:
            return False
        still = self.still.get(f.fruit_id)
        return not (_estimated(f) and still is not None and stamp_ns - still[1] >= STILL_S * 1e9)

    def _hold(self, f: Fruit, stamp_ns: int) -> None:
        """Note where ``f``'s ID is estimated (``STILL_S``): from this frame's view only (a
        kept estimate stays put whatever the fruit does)."""
        if not _estimated(f):
            return
        p = np.array(f.position_world_m, float)
        still = self.still.get(f.fruit_id)
        if still is None or np.linalg.norm(p - still[0]) > STILL_M:
            self.still[f.fruit_id] = (p, stamp_ns)

    def _fall_view(self, f: Fruit, key: int | None, stamp_ns: int) -> bool:
        """Leave ``f`` out: a falling fruit's view that would make a record, or that lies
        farther than ``same_fruit_m`` from the record of its ID (a reuse, or a jump)."""
        if not self._falling(f, stamp_ns):
            return False
        if key is not None:
            p = np.array(f.position_world_m, float)
            if np.linalg.norm(p - self.records[key].planned.centre_world_m) <= self.same_fruit_m:
                return False  # a fruit hanging there, seen where it hangs
        self.fall_views.append((stamp_ns, f.fruit_id))
        if key is None:
            self.fell_ids.add(f.fruit_id)
        return True

    def _fall_echo(self, f: Fruit, key: int | None) -> bool:
        """``f`` is the scene's stale or kept entry of an ID whose only views were a falling
        fruit's: no record (paper-exp2 seed 11: the stale entry of a view left out 0.7 s after a
        cut started a record, its kept echoes confirmed it, and the shears closed 60 cm from any
        peduncle). A view the scene estimates, not falling, ends it."""
        if key is not None or f.fruit_id not in self.fell_ids:
            return False
        if _estimated(f):
            self.fell_ids.discard(f.fruit_id)
            return False
        return True

    def update(self, scene: SceneState, in_dish: InDish) -> None:
        """Take one scene state: new IDs, switches, positions, what is in the scene now."""
        now = {f.fruit_id: f for f in scene.fruits}
        present: set[int] = set()
        for fid in sorted(now):
            f = now[fid]
            key = self.id_to_key.get(fid)
            self._hold(f, scene.header.stamp_ns)
            if self._fall_view(f, key, scene.header.stamp_ns):
                if key is not None:
                    present.add(key)
                continue
            if self._fall_echo(f, key):
                continue
            if key is not None and self._reused(self.records[key], f, in_dish):
                key = self._reborn(self.records[key], f, now)
            if key is None:
                key = self._identify(f, now)
            rec = self.records[key]
            present.add(key)
            current = now.get(rec.fruit_id)
            if fid != rec.fruit_id and (current is None or f.frames_unseen < current.frames_unseen):
                self._switch(rec, fid)
            if fid == rec.fruit_id:
                self._observe(rec, f, in_dish)
            if f.frames_unseen == 0 and not in_dish(f):
                if rec.first_seen_ns is None:
                    rec.first_seen_ns = scene.header.stamp_ns
                rec.last_seen_ns = scene.header.stamp_ns
                rec.sightings += 1
        for key in sorted(self.records):
            self.records[key].in_scene = key in present

    def _identify(self, f: Fruit, now: dict[int, Fruit], new_key: int | None = None) -> int:
        """The record a track ID new to it belongs to: any record within ``same_fruit_m`` (two
        fruit centres are never that close: each fruit is at least 7 cm across), else a new
        record keyed ``new_key`` (default: the ID)."""
        p = np.array(f.position_world_m, float)
        for key in sorted(self.records):
            rec = self.records[key]
            if np.linalg.norm(rec.planned.centre_world_m - p) > self.same_fruit_m:
                continue
            self.id_to_key[f.fruit_id] = key
            rec.ids.append(f.fruit_id)
            return key
        key = f.fruit_id if new_key is None else new_key
        self.records[key] = FruitRecord(
            key, f.fruit_id, [f.fruit_id], f, shape_of(f), planned_whole=_whole(f)
        )
        self.id_to_key[f.fruit_id] = key
        return key

    def _reused(self, rec: FruitRecord, f: Fruit, in_dish: InDish) -> bool:
        """``f`` (an ID of ``rec``) is fresh and far from ``rec``'s fruit, which is finished, in
        the basket or has a newer ID, and not in our dish (a harvested fruit is seen there): the
        tracker gave the ID to another fruit (paper-exp1 seed 4, planned: the track first seen
        on a harvested fruit falling into the dish went on to the fruit a hand had moved; that
        fruit was never a candidate, "in the basket"). Only an estimate of this frame counts:
        the scene keeps the last one when a view gives none (``depth_inconsistent`` …), and a
        harvested fruit's kept estimate from mid-fall lies outside the dish (paper-exp1 seed
        11, planned: the fruit in the basket was taken for a new one and the approach to it
        stalled). A fruit known to be in the basket may show its top above the rim."""
        done = rec.finished or rec.in_basket
        if not _this_frames(f) or not (done or f.fruit_id != rec.fruit_id):
            return False  # a kept estimate (a fruit mid-fall, say) is no evidence
        if in_dish(f, rec.outcome == "harvested" or rec.in_basket):
            return False
        p = np.array(f.position_world_m, float)
        c = rec.planned.centre_world_m
        if np.linalg.norm(p - c) <= self.same_fruit_m:
            return False
        if rec.outcome == "dropped" and p[2] < c[2] - self.same_fruit_m:
            return False  # fallen
        if "kept" in f.flags:
            # The view was cut and the scene kept its stored estimate: not where the fruit is
            # now (orchard seed 15: a harvested fruit's estimate from mid-fall, 4.1 cm under
            # where it hung, kept while the fruit lay in our dish cut by the rim, became a new
            # fruit, and the cutter closed on nothing for 8 s).
            self.kept_far.append((rec.key, f.fruit_id))
            return False
        return True

    def _seen_after_drop(self, rec: FruitRecord, f: Fruit, in_dish: InDish) -> None:
        """A fruit reported dropped that the scene estimates, from this frame's view, where it
        hung (``same_fruit_m``) and not in our dish, in ``MIN_SIGHTINGS`` scene states, is
        still on its branch: the verdict came from the ready pose, where leaves or the arms
        hid it, and the cut had missed (orchard seed 8: missed by 23 mm, reported dropped;
        its later track joined the record, and the controller, told to ignore a fruit off the
        tree, pushed the arms through it 38 times). Noted in ``back_on_branch``, once."""
        if not _estimated(f) or in_dish(f):
            return
        p = np.array(f.position_world_m, float)
        if np.linalg.norm(p - rec.planned.centre_world_m) > self.same_fruit_m:
            return
        rec.views_after_drop += 1
        if rec.views_after_drop == MIN_SIGHTINGS:
            self.back_on_branch.append(rec.key)

    def _reborn(self, rec: FruitRecord, f: Fruit, now: dict[int, Fruit]) -> int:
        """``f``'s ID leaves ``rec`` for the record of the fruit it is on now: a known one, or a
        new one (negative keys: never a track ID). The scene's mark on the ID is the old
        fruit's: that record no longer trusts scene marks (they only echo the planner's own
        outcomes, which it keeps)."""
        rec.ids.remove(f.fruit_id)
        del self.id_to_key[f.fruit_id]
        fresh = min(0, *self.records) - 1
        key = self._identify(f, now, fresh)
        self.records[key].scene_mark_ok = False  # the planner's own outcomes suffice
        self.reborn.append((rec.key, key, f.fruit_id))
        return key

    def _switch(self, rec: FruitRecord, new_id: int) -> None:
        self.switches.append((rec.key, rec.fruit_id, new_id))
        rec.fruit_id = new_id

    def _observe(self, rec: FruitRecord, f: Fruit, in_dish: InDish) -> None:
        rec.seen = f
        if _estimated(f):
            rec.viewed = f
        if rec.outcome == "dropped":
            self._seen_after_drop(rec, f, in_dish)
        if rec.finished or rec.frozen:
            return
        if f.frames_unseen == 0 and in_dish(f) and rec.key != self.hanging_key:
            rec.in_basket = True
        planned_m = (rec.planned.d_h_m, rec.planned.d_v_m)
        whole = _whole_for(rec, f)  # against the sizes shown before this view
        if _this_frames(f):
            rec.sizes_m.append((f.semi_axis_h_m, f.semi_axis_v_m))
        if self.follow_cut_views:  # its rules take this view's size in (as measured)
            if rec.planned_whole and _planned_smaller(rec):
                rec.planned_whole = False  # its "whole" view was cut: followed as a cut one
            whole = _whole_for(rec, f)
            held = rec.key == self.held_key
            if not (whole or held) and _this_frames(f) and not _smaller_than_shown(f, rec.sizes_m):
                rec.cut_views.append(shape_of(f))
        shape = shape_of(f)
        d = float(np.linalg.norm(shape.centre_world_m - rec.planned.centre_world_m))
        if rec.planned_whole and not whole:
            # A cut, stale or much smaller view does not move a target planned from a whole
            # one, unless it is fresh, of the fruit's size, and far (the fruit was pushed).
            sized = not _shrunk(f, planned_m, MOVED_VIEW_SIZE)
            # Once pushed, followed as closely as a whole view (the cutter needs < 1.5 cm).
            far = d > (self.replan_m if rec.pushed else MOVED_VIEW_M)
            if _this_frames(f) and sized and far:
                rec.pushed = True
                # The centre moves; the size stays the whole view's (a cut view's is short).
                rec.planned = FruitShape(shape.centre_world_m, rec.planned.d_h_m, rec.planned.d_v_m)
                rec.reach = None
                self.moved.append((rec.key, d))
            return
        if not whole and not rec.planned_whole and self.follow_cut_views:
            if rec.key != self.held_key:
                self._follow_cut_views(rec)
            return
        if d > self.replan_m or (whole and not rec.planned_whole):
            rec.planned = shape
            rec.reach = None
            rec.planned_whole = whole
            rec.pushed = False
            rec.cut_views.clear()
            if d > self.replan_m:
                self.moved.append((rec.key, d))

    def _follow_cut_views(self, rec: FruitRecord) -> None:
        """A target with no whole view: the median of its recent fresh views of its own size
        (``CUT_VIEWS``); kept, smaller or stale views do not move it."""
        if not rec.cut_views:
            return
        centre = np.median([v.centre_world_m for v in rec.cut_views], axis=0)
        d = float(np.linalg.norm(centre - rec.planned.centre_world_m))
        if d <= REFINE_M:
            return
        d_h = float(np.median([v.d_h_m for v in rec.cut_views]))
        d_v = float(np.median([v.d_v_m for v in rec.cut_views]))
        rec.planned = FruitShape(centre, d_h, d_v)
        rec.reach = None
        rec.pushed = False
        if d > self.replan_m:
            self.moved.append((rec.key, d))

    def replan_from_view(self, rec: FruitRecord) -> float | None:
        """Re-plan ``rec`` from its latest view, however near, when the scene computed it from
        this frame (a cut view only for a target not planned from a whole one): the view from
        the ready pose after a failed cut. Returns how far the target moved, m (None: no such
        view, the target stays)."""
        f = rec.seen
        whole = _whole_for(rec, f)
        if not _this_frames(f) or (rec.planned_whole and not whole):
            return None
        shape = shape_of(f)
        d = float(np.linalg.norm(shape.centre_world_m - rec.planned.centre_world_m))
        rec.planned, rec.planned_whole, rec.pushed, rec.reach = shape, whole, False, None
        rec.cut_views.clear()
        if not whole:
            rec.cut_views.append(shape)  # the look's view leads; later ones join it
        return d

    def candidates(self, max_unseen: int) -> list[FruitRecord]:
        """Records still to do, in the scene, seen recently, not in the basket, by key; fruit
        deferred as blocked only when no other is left."""
        ok = [
            r
            for _, r in sorted(self.records.items())
            if not r.finished
            and r.in_scene
            and not r.in_basket
            and r.seen.frames_unseen <= max_unseen
            and r.confirmed
            and (r.seen.status not in ("harvested", "unreachable") or not r.scene_mark_ok)
        ]
        fresh = [r for r in ok if not r.deferred]
        return fresh or ok

    def hidden(self, now_ns: int, within_s: float) -> list[FruitRecord]:
        """Fruit still to do that the scene no longer shows fresh (forgotten, or unseen for
        long) but that were seen on the tree within ``within_s``: hidden, not gone."""
        return [
            r
            for _, r in sorted(self.records.items())
            if not r.finished
            and not r.in_basket
            and r.confirmed
            and r.last_seen_ns is not None
            and now_ns - r.last_seen_ns < within_s * 1e9
        ]

    def ignore_ids(self, rec: FruitRecord | None) -> tuple[int, ...]:
        """IDs the controller need not avoid: the target's (all of them) while the tools touch
        it, fruit seen in the basket, and fruit known to be off the tree (harvested, dropped):
        the scene may still list them where they were last seen."""
        ids: list[int] = list(rec.ids) if rec is not None else []
        for _, r in sorted(self.records.items()):
            if r.in_basket or r.outcome in ("harvested", "dropped"):
                ids += r.ids
        # Taken for a falling fruit (no record): the cut one, falling or in our dish, under
        # another ID (paper-exp1 seed 11: avoided in the dish, it held the cutter 24 mm short).
        ids += self.fell_ids
        return tuple(sorted(set(ids)))

    def detected(self) -> list[FruitRecord]:
        """Every physical fruit seen on the tree (fruit seen only in the basket, and flashes
        seen in fewer than ``MIN_SIGHTINGS`` scene states, left out). A fruit the tools went
        for was on the tree (candidates are never in the basket), also when it was seen in
        our dish later: the dish comes up under the target (paper-exp1 seed 0: seen "in the
        dish" during the harvest, then harvested, and missing from the summary)."""
        return [
            r
            for _, r in sorted(self.records.items())
            if r.confirmed and (not r.in_basket or r.started_ns is not None)
        ]


def _shrunk(f: Fruit, size_m: tuple[float, float], share: float) -> bool:
    """Either semi-axis of the view below ``share`` of ``size_m`` (d_h, d_v): a view cut by
    something (the top hidden, paper-exp2 seed 12: d_v 1.7 cm of 3.6, the centre 2 cm low,
    and the cuts went 1.6 cm under the peduncle)."""
    return _below((f.semi_axis_h_m, f.semi_axis_v_m), size_m, share)


def _below(size_m: tuple[float, float], ref_m: tuple[float, float], share: float) -> bool:
    """Either semi-axis (d_h, d_v) of ``size_m`` below ``share`` of ``ref_m``'s."""
    return size_m[0] < share * ref_m[0] or size_m[1] < share * ref_m[1]


def _below_shown(size_m: tuple[float, float], sizes_m: deque[tuple[float, float]]) -> bool:
    """``size_m`` (d_h, d_v) below ``SHRUNK_VIEW`` of the size the fruit has shown in its recent
    views (``SEEN_SIZE_QUANTILE``, whatever their flags; False until ``MIN_RECENT_VIEWS``)."""
    if len(sizes_m) < MIN_RECENT_VIEWS:
        return False
    h_m, v_m = np.percentile(np.array(sizes_m), SEEN_SIZE_QUANTILE, axis=0)
    return _below(size_m, (float(h_m), float(v_m)), SHRUNK_VIEW)


def _smaller_than_shown(f: Fruit, sizes_m: deque[tuple[float, float]]) -> bool:
    """The view below the size the fruit has shown (``_below_shown``): a fruit does not shrink,
    so the view is cut by something the scene did not flag (paper-exp1 seed 11: a fruit half
    hidden by a leaf showed 4.0 x 4.0 cm for 3 s in edge-flagged views, truth 4.1 x 3.85, then
    one unflagged 3.0 x 3.3 cm view while a hand passed; planned from it as from a whole view,
    the cuts missed the peduncle by 1.7 cm)."""
    return _below_shown((f.semi_axis_h_m, f.semi_axis_v_m), sizes_m)


def _planned_smaller(rec: FruitRecord) -> bool:
    """The view ``rec``'s target was planned from is below the size the fruit has shown since
    (``_below_shown``): that view was cut by something the scene did not flag (orchard seed 11:
    the first views, unflagged, read d_h 3.2 cm with an arm over a side, 14 mm off; the target
    stayed there while later edge-flagged views read 4.35 cm, 1 mm off, and the cutter missed
    the peduncle by 17 mm)."""
    return _below_shown((rec.planned.d_h_m, rec.planned.d_v_m), rec.sizes_m)


def _this_frames(f: Fruit) -> bool:
    """A view of this frame, whole or cut on a side, that gave no failure: no stale estimate,
    none kept for want of depth or for a jump. A cut view may have left the stored estimate in
    place (``kept``; ``CUT_FLAGS``)."""
    return f.frames_unseen == 0 and set(f.flags) <= CUT_FLAGS


def _estimated(f: Fruit) -> bool:
    """The scene's estimate comes from this frame's view (whole or cut on a side), not kept
    from before (no consistent depth, a jump, a side cut it would not take)."""
    return f.frames_unseen == 0 and "kept" not in f.flags


def _whole_for(rec: FruitRecord, f: Fruit) -> bool:
    """A whole view of ``rec``'s fruit: no side cut flagged, and not shrunk against the whole
    view it was planned from nor against the sizes it has shown lately."""
    planned_m = (rec.planned.d_h_m, rec.planned.d_v_m)
    if rec.planned_whole and _shrunk(f, planned_m, SHRUNK_VIEW):
        return False
    return _whole(f) and not _smaller_than_shown(f, rec.sizes_m)


def _whole(f: Fruit) -> bool:
    """A fresh estimate with no side cut (the scene's flags): the best the scene gives."""
    return not f.flags and f.frames_unseen == 0


def inside_dish(
    p_world_m: np.ndarray, dish: DishPose, margin_m: float, above_rim_m: float | None = None
) -> bool:
    """A fruit centre inside the dish: within its radius, between the floor and the rim top
    (+ margin, or + ``above_rim_m``). A fruit resting in the dish has its centre d_v (≤ 5 cm)
    above the floor; the fruit hanging over the dish at the harvest pose has it rim +
    clearance + d_v (≥ 8.5 cm) above, so the target is never taken for a fruit in the basket."""
    rel = np.asarray(p_world_m, float) - dish.centre_world_m
    h = float(rel @ dish.normal_world)
    radial = float(np.linalg.norm(rel - h * dish.normal_world))
    top = TOOLS.basket_rim_height_m + (margin_m if above_rim_m is None else above_rim_m)
    return radial <= TOOLS.basket_radius_m + margin_m and -margin_m <= h <= top
