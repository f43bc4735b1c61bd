"""The harvest state machine (paper §IV-B, §IV-C): one step per control status.

    idle ──(startup)──▶ select ──▶ approach ──▶ harvest ──▶ cut ──▶ leave ──▶ select …
                          │            │            │         │  └─(cut failed, retry)─▶ harvest
                          ▼            └─ lost / stuck: skip ─┘
                         home ──(nothing left for finish_after_s)──▶ done

* **select**: the next fruit by the order policy among the candidates; a fruit whose harvest
  pose or pre-pose the IK cannot reach is skipped as unreachable right there.
* **approach**: the cutter to the pre-pose (d_z in front along the optical axis); the target
  fruit is an obstacle. ``plan_approach`` 'always': first along a planned joint path
  (motion.py); 'after_stall': a stalled approach gets one before it is given up.
  Lost (unseen too long) → back to select; stuck or timed out → skipped as unreachable.
* **harvest**: the cutter tip to the peduncle, the dish under the fruit; the fruit may be
  touched (``ignore_fruit_ids``). Stuck or timed out → unreachable, leave.
* **cut**: one tool command, then wait for the basket's fruit count to go up (collected).
  After ``collect_timeout_s``: the fruit still seen on its branch → the cut failed: retry up
  to ``max_cut_attempts``, then give up (cut_failed); gone → dropped. With
  ``relook_before_retry`` a retry first looks from the ready pose and re-plans from that view
  (the tools hid the fruit at the cut), then approaches again; without it (the default), it
  harvests again from where it is.
* **leave**: back to the pre-pose of that fruit, then select. After a stall, with
  ``retrace_after_stall``: back along the attempt's joint path instead (retrace.py).
* **home**: nothing to do: the ready pose; the run ends after ``finish_after_s`` there with no
  candidate and no fruit still to do that was seen within ``hidden_wait_s`` (hidden by leaves,
  a person or the arms for longer than the scene lists it), or at ``max_run_s``.

Progress: each phase keeps the best task error seen on statuses of its own targets; no
improvement by ``progress_min_m`` for ``no_progress_s`` is "stuck". Statuses of older targets
(the first tick after a switch) and holding statuses do not count as progress.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from schemas.control import ControlStatus, HarvestPhase
from schemas.harvest import FruitOutcome, HarvestEventKind
from schemas.scene import Fruit
from services.planner import Settings
from services.planner.book import FruitBook, FruitRecord
from services.planner.branchcheck import BranchCheck, BranchVerdict
from services.planner.clutter import clearable, intrusions_m, same_fruit
from services.planner.crowd import CrowdCheck, Crowding
from services.planner.kinematics import IkSolution, Kinematics
from services.planner.motion import ApproachPlan, ApproachPlanner
from services.planner.order import nearest_first, planned_order
from services.planner.poses import (
    FruitShape,
    PoseSettings,
    ToolPoses,
    harvest_pose,
    pre_pose,
)
from services.planner.retrace import JointPath, Retrace

NS = 1_000_000_000
DISH_LOWER_GAIN_M = 0.005  # a lower dish is taken when its tools go this much less deep, m


@dataclass(frozen=True)
class Wait:
    """A pick's answer: nothing can be harvested now, but a hidden fruit may change that."""

    why: str


@dataclass(frozen=True)
class Event:
    """A harvest event before it becomes a message."""

    event: HarvestEventKind
    fruit_id: int | None = None
    phase_from: str = ""
    phase_to: str = ""
    reason: str = ""
    outcome: FruitOutcome | None = None  # set when the event settles the fruit


@dataclass(frozen=True)
class Goal:
    """What to send this tick: the phase, the poses (None: hold, unless a joint goal), the
    fruit, ignored IDs, and a joint goal (arm order, rad) when retracing."""

    phase: HarvestPhase
    poses: ToolPoses | None
    fruit_id: int | None = None
    ignore: tuple[int, ...] = ()
    joints_rad: np.ndarray | None = None


@dataclass
class CutState:
    """One cut: when, the basket count before it, where the fruit was."""

    stamp_ns: int
    basket_before: int
    centre_world_m: np.ndarray

    def counted(self, basket: int | None) -> bool:
        """The basket's fruit count (None: no reading yet) is up since this cut."""
        return basket is not None and basket > self.basket_before


@dataclass
class Progress:
    """Best task error of the current phase and when it last improved."""

    since_ns: int
    first_target_seq: int
    best_m: float = float("inf")
    best_ns: int = 0

    def counts(self, st: ControlStatus) -> bool:
        """The status is of this phase's targets and not holding: its errors are the phase's."""
        seq = st.target_seq
        return seq is not None and seq >= self.first_target_seq and not st.reason

    def note(self, st: ControlStatus, now_ns: int, min_gain_m: float) -> None:
        if not self.counts(st):
            return
        err = st.abs_position_error_m + st.rel_position_error_m
        if err < self.best_m - min_gain_m:
            self.best_m, self.best_ns = err, now_ns

    def stuck(self, now_ns: int, after_s: float) -> bool:
        ref = self.best_ns if self.best_m < float("inf") else self.since_ns
        return now_ns - ref > after_s * NS


@dataclass
class Machine:
    """Phases and transitions; the book and the kinematics are shared with the core."""

    s: Settings
    book: FruitBook
    kin: Kinematics
    pose_settings: PoseSettings
    phase: HarvestPhase = "idle"
    target: FruitRecord | None = None
    progress: Progress = field(default_factory=lambda: Progress(0, 0))
    cut: CutState | None = None
    verify: CutState | None = None  # an unconfirmed cut being checked from the ready pose
    arrived_ns: int | None = None  # when the ready pose was reached while verifying
    looking: bool = False  # verifying: backed out to the pre-pose, now going to look
    relook: bool = False  # verifying a failed cut's fruit seen on its branch: re-plan, retry
    home_since_ns: int | None = None
    last_tip_world_m: np.ndarray | None = None
    events: list[Event] = field(default_factory=list)
    tools: list[tuple[str, int | None]] = field(default_factory=list)  # (action, fruit_id)
    finished: bool = False
    started: bool = False
    next_seq: int = 0
    q_rad: np.ndarray | None = None  # the latest joint state, arm order
    path: JointPath = field(default_factory=lambda: JointPath(0.1))
    retrace: Retrace | None = None  # going back along ``path`` after a stall
    retrace_touching: bool = False  # the stall was in the harvest: the target may be touched
    left_because: str = ""  # the reason the next phase change carries (how a retrace ended)
    motion: ApproachPlanner | None = None  # plan_approach: planned joint paths to the pre-pose
    branches: BranchCheck | None = None  # branch_check: tool poses against the branches seen
    crowd: CrowdCheck | None = None  # crowd_first: neighbours the arms would touch go first
    following: bool = False  # ``retrace`` is the planned approach path, not a way back
    replans_left: int = 0  # planned paths still allowed this attempt after one was left
    planned_after_stall: bool = False  # this attempt's stalled approach got its planned path
    harvest_jointed: bool = False  # this attempt's stalled harvest got its joint goal

    def __post_init__(self) -> None:
        self.path = JointPath(self.s.retrace_step_rad)

    def note_joints(self, q_rad: np.ndarray) -> None:
        """Every joint state (arm order): the path of the attempt, for retracing."""
        self.q_rad = q_rad
        if self.phase in ("approach", "harvest", "cut") and (
            self.retrace is None or self.following
        ):
            self.path.note(q_rad)

    # ---- one tick ----------------------------------------------------------------------------
    def step(self, now_ns: int, st: ControlStatus, next_seq: int, basket: int | None) -> Goal:
        """Advance on one control status; ``next_seq`` is the seq the returned goal will carry;
        ``basket`` the latest fruit count of the load cell (None: no reading yet)."""
        self.next_seq = next_seq
        if not self.started:
            self.started = True
            self.events.append(Event("run_started", phase_to="idle"))
        self.progress.note(st, now_ns, self.s.progress_min_m)
        self._note_switches_and_moves()
        if self.phase != "done" and now_ns >= self.s.max_run_s * NS:
            self._end_run(now_ns, f"run time limit {self.s.max_run_s:.0f} s")
        handler = {
            "idle": self._idle,
            "approach": self._approach,
            "harvest": self._harvest,
            "cut": self._cut,
            "leave": self._leave,
            "home": self._home,
            "done": lambda now, st, basket: None,
        }[self.phase]
        handler(now_ns, st, basket)
        return self.goal()

    def goal(self) -> Goal:
        rec = self.target
        if self.phase in ("idle", "home", "done") or rec is None:
            return Goal(self.phase, self._ready(), ignore=self._ignore(None))
        touching = self.phase in ("harvest", "cut", "leave")
        if self.verify is not None and self.looking:  # at the pre-pose: on to look from afar
            return Goal(self.phase, self._ready(), rec.fruit_id, self._ignore(None))
        if self.retrace is not None:
            ignore = self._ignore(rec if self.retrace_touching else None)
            return Goal(self.phase, None, rec.fruit_id, ignore, self.retrace.goal)
        poses = pre_pose if self.phase in ("approach", "leave") else harvest_pose
        return Goal(
            self.phase,
            poses(self._aimed(rec), self._settings_for(rec), rec.dish_back_m),
            rec.fruit_id,
            self._ignore(rec if touching else None),
        )

    def _aimed(self, rec: FruitRecord) -> FruitShape:
        """What the poses aim at: the planned fruit, moved ``aim_deeper_m`` away from the
        camera in the horizontal plane (a retried cut)."""
        axis = self.pose_settings.camera_axis_world * np.array([1.0, 1.0, 0.0])
        norm = float(np.linalg.norm(axis))
        if rec.aim_deeper_m == 0.0 or norm < 1e-3:  # a camera looking straight down: no "deeper"
            return rec.planned
        shift = rec.aim_deeper_m * axis / norm
        p = rec.planned
        return FruitShape(p.centre_world_m + shift, p.d_h_m, p.d_v_m)

    def _ignore(self, touching: FruitRecord | None) -> tuple[int, ...]:
        """Fruit IDs the controller need not avoid: the book's (the target's while the tools
        touch it, the basket's, those off the tree), the ghosts of fruit off the tree, and,
        while the tools touch the target, any other record of it (one fruit seen as two
        tracks: paper-exp1 seed 12, a second track on the lower half of the target, 5 cm
        under its centre, held the dish 9 cm short of its place until the harvest gave up)."""
        ids = set(self.book.ignore_ids(touching))
        for r in self.book.detected():
            if r is touching:
                continue
            if self._ghost(r) or (
                touching is not None
                and r.outcome not in ("harvested", "dropped")
                and same_fruit(r.planned, touching.planned)
            ):
                ids.update(r.ids)
        return tuple(sorted(ids))

    # ---- phases ------------------------------------------------------------------------------
    def _idle(self, now: int, st: ControlStatus, basket: int | None) -> None:
        if now >= self.s.startup_s * NS:
            self._select(now)

    def _approach(self, now: int, st: ControlStatus, basket: int | None) -> None:
        rec = self.target
        assert rec is not None
        if not rec.in_scene:
            rec.losses += 1
            why = f"left the scene during the approach (last seen {rec.seen.frames_unseen} "
            why += "frames before)"
            if rec.losses >= self.s.max_losses:
                self._finish(rec, now, "lost", f"{why}, {rec.losses} times")
                self.events.append(Event("fruit_lost", rec.fruit_id, outcome="lost", reason=why))
            else:
                self.events.append(Event("fruit_lost", rec.fruit_id, reason=f"{why}; may retry"))
            self._end_attempt(rec, now)
            self.retrace, self.following = None, False
            self.target = None
            self._select(now)
            return
        if self.following:
            self._follow(now)
            return
        if self._reached(st, self.s.approach_tolerance_m, self.s.catch_tolerance_m):
            self._enter("harvest", now)
            return
        # A pre-pose nearly reached whose dish a neighbour holds back: try the harvest pose
        # (the fruit may still be caught; the harvest phase judges).
        near = self._reached(st, 2 * self.s.approach_tolerance_m, loose=True)
        if near and self.progress.stuck(now, self.s.settle_s):
            self._enter("harvest", now)
            return
        self._check_stuck(now, self.s.approach_timeout_s, leave=False, st=st)

    def _follow(self, now: int) -> None:
        """Along the planned path; at its end the pose goals take over with the approach's
        whole time again. Stuck or timed out: planned again from where the arms are
        (``plan_retries`` times per attempt), then the pose goals."""
        end = self._followed(now, self.s.approach_timeout_s)
        if end is None:
            return
        how, short = end
        rec = self.target
        if how != "ended" and rec is not None and self.replans_left > 0:
            self.replans_left -= 1
            follow = self._planned_approach(rec)
            why = f"planned path {how} {short:.2f} rad short of its end: planned again, "
            why += self.left_because
            self.left_because = ""
            self.events.append(Event("replanned", rec.fruit_id, reason=why))
            if follow is not None:
                self.retrace, self.following = follow, True
            return
        if how != "ended":
            why = f"planned path {how} {short:.2f} rad short of its end: pose goals"
            self.events.append(Event("replanned", rec.fruit_id if rec else None, reason=why))

    def _plan_after_stall(self, rec: FruitRecord, now: int, detail: str) -> bool:
        """plan_approach 'after_stall': the stalled pose goals give way to a planned joint path
        from where the arms are (once per attempt, not planned again if the arms cannot follow
        it). True: a path is being followed."""
        if self.s.plan_approach != "after_stall" or self.planned_after_stall:
            return False
        self.planned_after_stall = True
        self.replans_left = 0  # the path after a stall is the attempt's last plan
        self.progress = Progress(now, self.next_seq)
        follow = self._planned_approach(rec)
        self.events.append(
            Event("replanned", rec.fruit_id, reason=f"{detail}: {self.left_because}")
        )
        self.left_because = ""
        if follow is None:
            return False
        self.retrace, self.retrace_touching, self.following = follow, False, True
        return True

    def _planned_approach(self, rec: FruitRecord) -> Retrace | None:
        """A planned joint path to the pre-pose's IK solution (plan_approach), as a path to
        follow; None: no planner, no joint state or no path (the pose goals)."""
        if self.motion is None or self.q_rad is None:
            return None
        p = pre_pose(rec.planned, self._settings_for(rec), rec.dish_back_m)
        goals = self.kin.solutions(p)
        if not goals:
            return None
        seed = rec.fruit_id * 1000 + self.motion.plans
        plan = self.motion.plan(self.q_rad, goals, rec.planned, seed, p, self._ignore(None))
        if plan.path is None and self.s.plan_from_attempt_start and len(self.path.points) >= 2:
            plan = self._plan_from_attempt_start(rec, goals, seed, p, plan)
        self.left_because = plan.why
        if plan.path is None:
            return None
        return self._to_follow(plan.path, self.q_rad, self.progress.since_ns)

    def _to_follow(self, path: list[np.ndarray], q: np.ndarray, now: int) -> Retrace:
        """``path`` (joints, arm order) as a path to follow from ``q``, its first goal ahead of
        the arms, not where they are."""
        s = self.s
        follow = Retrace(
            path,
            s.plan_lookahead_rad,
            s.retrace_tolerance_rad,
            s.retrace_tolerance_rad / 2,
            now,
            best_ns=now,
        )
        follow.update(q, now)
        return follow

    def _plan_from_attempt_start(
        self, rec: FruitRecord, goals: list[IkSolution], seed: int, p: ToolPoses, here: ApproachPlan
    ) -> ApproachPlan:
        """No path from where the arms are (``here``): one from where the attempt began, after
        the way back along the joints the arms came in by (free: they came that way)."""
        assert self.motion is not None
        start = self.path.points[0]
        again = self.motion.plan(start, goals, rec.planned, seed, p, self._ignore(None))
        if again.path is None:
            return ApproachPlan(None, f"{here.why}; from where the attempt began: {again.why}")
        back = self.path.way_back()
        why = f"{again.why}, from where the attempt began, back along {len(back)} waypoints first"
        return ApproachPlan(back + again.path[1:], why)

    def _harvest(self, now: int, st: ControlStatus, basket: int | None) -> None:
        rec = self.target
        assert rec is not None
        if self.following:
            self._follow_harvest(now)
            return
        exact = self._reached(st, self.s.harvest_tolerance_m)
        held = self._reached(st, self.s.harvest_tolerance_m, self.s.catch_tolerance_m)
        if exact or (held and self.progress.stuck(now, self.s.settle_s)):
            self._send_cut(rec, now, basket)
            return
        # Held back short of the pose (a neighbour's or a branch's damper) at the moment the
        # attempt would be given up, but within the shears' reach: cut there rather than lose
        # the fruit; a miss is a failed cut like any other (retried once).
        near = self._reached(st, self.s.stalled_cut_tolerance_m, self.s.catch_tolerance_m)
        if near and self.progress.stuck(now, self.s.no_progress_s):
            err_mm = st.abs_position_error_m * 1e3
            self._send_cut(rec, now, basket, f" (held {err_mm:.0f} mm short of the pose)")
            return
        if self._harvest_by_joints(rec, now, st):
            return
        self._check_stuck(now, self.s.harvest_timeout_s, leave=True, st=st)

    def _harvest_by_joints(self, rec: FruitRecord, now: int, st: ControlStatus) -> bool:
        """harvest_joints_after_stall: a stalled harvest gets one joint goal per attempt, the
        harvest pose's IK solution nearest the arms. The controller is local: a joint at its
        stop holds the cutter short of a pose the IK reaches with that joint inside (orchard
        seed 19: 16 mm short, cutter j4 at +2.094 rad). True: the goal is being followed."""
        if not self.s.harvest_joints_after_stall or self.harvest_jointed or self.q_rad is None:
            return False
        if not self.progress.stuck(now, self.s.no_progress_s):
            return False
        if (
            not self.progress.counts(st)
            or st.abs_position_error_m <= self.s.stalled_cut_tolerance_m
        ):
            return False  # the cutter is not the tool held (a neighbour holds the dish)
        self.harvest_jointed = True
        q = self.q_rad
        sols = self.kin.solutions(
            harvest_pose(self._aimed(rec), self._settings_for(rec), rec.dish_back_m)
        )
        if not sols:
            return False
        gaps = [float(np.max(np.abs(sol.q_rad - q))) for sol in sols]
        i = int(np.argmin(gaps))
        best, gap = sols[i], gaps[i]
        if gap <= self.s.retrace_tolerance_rad:
            return False  # the arms are at the nearest solution already
        follow = self._to_follow([q.copy(), best.q_rad.copy()], q, now)
        why = (
            f"harvest no progress (best task error {self.progress.best_m * 1e3:.0f} mm"
            f"{self._now_off(st)}): a joint goal to the harvest pose's IK solution nearest the "
            f"arms (yaw {best.yaw_deg:.0f}°, {gap:.2f} rad away)"
        )
        self.events.append(Event("replanned", rec.fruit_id, reason=why))
        self.retrace, self.retrace_touching, self.following = follow, True, True
        self.progress = Progress(now, self.next_seq)
        return True

    def _follow_harvest(self, now: int) -> None:
        """Towards the harvest pose's IK solution; at its end (or stuck, or timed out) the pose
        goals take over with the harvest's whole time again."""
        end = self._followed(now, self.s.harvest_timeout_s)
        if end is None:
            return
        how, short = end
        rec = self.target
        if how != "ended" and rec is not None:
            why = f"harvest joint goal {how} {short:.2f} rad short of its end: pose goals"
            self.events.append(Event("replanned", rec.fruit_id, reason=why))

    def _followed(self, now: int, timeout_s: float) -> tuple[str, float] | None:
        """``_path_end`` of a followed path; at its end the pose goals take over: the path is
        dropped and the phase's progress counts afresh."""
        end = self._path_end(now, timeout_s)
        if end is not None:
            self.retrace, self.following = None, False
            self.progress = Progress(now, self.next_seq)
        return end

    def _send_cut(self, rec: FruitRecord, now: int, basket: int | None, note: str = "") -> None:
        """Close the shears on ``rec`` (``note``: what the cut_sent reason adds)."""
        rec.cuts += 1
        rec.frozen = True  # the estimate of a falling fruit must not move the target
        self.cut = CutState(
            now, basket if basket is not None else 0, rec.planned.centre_world_m.copy()
        )
        self.tools.append(("cut", rec.fruit_id))
        self.book.note_cut(rec.key, now)
        why = f"cut {rec.cuts}/{self.s.max_cut_attempts}{note}"
        self.events.append(Event("cut_sent", rec.fruit_id, reason=why))
        self._enter("cut", now)

    def _cut(self, now: int, st: ControlStatus, basket: int | None) -> None:
        rec, cut = self.target, self.cut
        assert rec is not None and cut is not None
        if cut.counted(basket):
            self.events.append(
                Event(
                    "fruit_collected", rec.fruit_id, outcome="harvested", reason="basket count up"
                )
            )
            self._finish(rec, now, "harvested", "")
            self._open_and_leave(now)
            return
        if now - cut.stamp_ns < self.s.collect_timeout_s * NS:
            return
        if self._still_attached(rec, cut, None):
            if self._relook_wanted(rec):
                self.verify = cut
                self._start_relook(rec, "still on its branch")
                self._open_and_leave(now)
                return
            self._cut_failed(now, "harvest")
            return
        # Not in the basket, and not seen on its branch since the cut: the tools may hide it
        # (they are between the camera and the fruit). Back out to the ready pose and look.
        self.verify = cut
        self._open_and_leave(now)

    def _cut_failed(self, now: int, retry_from: HarvestPhase) -> None:
        """The fruit is still on its branch: cut again (from ``retry_from``) or give up."""
        rec = self.target
        assert rec is not None
        if self.cut is not None:  # straight from the cut phase: the shears are still closed
            self.tools.append(("open", rec.fruit_id))
        self.cut = self.verify = None
        self.relook = False
        if rec.cuts < self.s.max_cut_attempts:
            why = f"cut {rec.cuts} failed (fruit still on its branch): retrying"
            rec.aim_deeper_m = self.s.retry_aim_deeper_m
            if rec.aim_deeper_m > 0.0:
                why += f", {rec.aim_deeper_m * 1e3:.0f} mm deeper"
            self.events.append(Event("replanned", rec.fruit_id, reason=why))
            rec.frozen = False  # re-aim at the fruit as it is seen now
            self._enter(retry_from, now)
            return
        why = f"cut failed {rec.cuts} times (fruit still on its branch)"
        self.events.append(Event("fruit_skipped", rec.fruit_id, outcome="cut_failed", reason=why))
        self._finish(rec, now, "cut_failed", why)
        self._enter("leave", now)

    def _leave(self, now: int, st: ControlStatus, basket: int | None) -> None:
        if self.verify is not None:
            if self.verify.counted(basket):
                self._collected_late(now)
                return
            self._verify(now, st)
            return
        if self.retrace is not None:
            self._retracing(now)
            return
        reached = self._reached(st, self.s.leave_tolerance_m, loose=True)
        if reached or now - self.progress.since_ns > self.s.leave_timeout_s * NS:
            self._next_fruit(now)

    def _retracing(self, now: int) -> None:
        """Back along the attempt's joint path; at its start (or stuck, or timed out) the
        attempt ends and the next fruit is selected."""
        end = self._path_end(now, self.s.retrace_timeout_s)
        if end is None:
            return
        how, short = end
        self.retrace = None
        if how == "ended":
            self.left_because = "retraced to where the attempt began"
        else:
            what = how if how == "stuck" else f"{how} after {self.s.retrace_timeout_s:.0f} s"
            self.left_because = f"retrace {what}, {short:.2f} rad short of where the attempt began"
        self._next_fruit(now)

    def _next_fruit(self, now: int) -> None:
        """The tools are done with the target for now: its attempt ends (and the check of its
        cut, if one was under way), and the next fruit is selected."""
        rec = self.target
        if rec is not None:
            self._end_attempt(rec, now)
        self.verify = None
        self.relook = False
        self.target = None
        self._select(now)

    def _path_end(self, now: int, timeout_s: float) -> tuple[str, float] | None:
        """The path being followed (``retrace``): None while under way, else how it ended
        ("ended", "stuck", "timed out") and how far the arms are from its end, rad."""
        r = self.retrace
        assert r is not None
        if self.q_rad is not None:
            r.update(self.q_rad, now)
        short = r.remaining_rad(self.q_rad) if self.q_rad is not None else float("nan")
        if self.q_rad is not None and r.done(self.q_rad):
            return "ended", short
        if r.stuck(now, self.s.no_progress_s):
            return "stuck", short
        if now - r.since_ns > timeout_s * NS:
            return "timed out", short
        return None

    def _verify(self, now: int, st: ControlStatus) -> None:
        """After an unconfirmed cut, at the ready pose: the fruit seen again where it was cut →
        the cut failed; not seen ``verify_s`` after arriving → it fell outside the basket."""
        rec, cut = self.target, self.verify
        assert rec is not None and cut is not None
        if self.relook:
            self._relooking(now, st, rec)
            return
        if self._still_attached(rec, cut, self.arrived_ns):
            if self._relook_wanted(rec):
                self._start_relook(rec, "seen on its branch again")
                self._relooking(now, st, rec)
            else:
                self._cut_failed(now, "approach")
            return
        arrived = self._arrived_to_look(now, st)
        if arrived is not None and now - arrived >= self.s.verify_s * NS:
            why = f"not in the basket {self.s.collect_timeout_s:.1f} s after the cut, not seen "
            why += "on its branch since"
            self.events.append(Event("fruit_dropped", rec.fruit_id, outcome="dropped", reason=why))
            self._finish(rec, now, "dropped", why)
            self._next_fruit(now)

    def _collected_late(self, now: int) -> None:
        """The basket's count went up while an unconfirmed cut was being verified: the fruit
        settled in the dish after ``collect_timeout_s`` (orchard seed 8, session 22's old
        default: in the basket at 67.9 s, reported dropped at 71.2 s)."""
        rec, cut = self.target, self.verify
        assert rec is not None and cut is not None
        late_s = (now - cut.stamp_ns) / NS
        why = f"basket count up {late_s:.1f} s after the cut, while verifying it"
        self.events.append(Event("fruit_collected", rec.fruit_id, outcome="harvested", reason=why))
        self._finish(rec, now, "harvested", "")
        self._next_fruit(now)

    def _relook_wanted(self, rec: FruitRecord) -> bool:
        return self.s.relook_before_retry and rec.cuts < self.s.max_cut_attempts

    def _start_relook(self, rec: FruitRecord, seen: str) -> None:
        why = f"cut {rec.cuts} failed (fruit {seen}): a look from afar first"
        self.events.append(Event("replanned", rec.fruit_id, reason=why))
        self.relook = True

    def _relooking(self, now: int, st: ControlStatus, rec: FruitRecord) -> None:
        """A failed cut, the fruit seen on its branch: at the ready pose, the target is
        re-planned from the first view the scene computes there (none within ``verify_s``: the
        estimate stays), then the fruit is approached again."""
        arrived = self._arrived_to_look(now, st)
        if arrived is None:
            return
        fresh = rec.seen.last_seen_stamp_ns > arrived
        moved = self.book.replan_from_view(rec) if fresh else None
        if moved is None and now - arrived < self.s.verify_s * NS:
            return
        self.left_because = (
            f"re-planned from the view at the ready pose, {moved * 1e3:.0f} mm from the cut's aim"
            if moved is not None
            else "no fresh view at the ready pose: the estimate stays"
        )
        self._cut_failed(now, "approach")

    def _arrived_to_look(self, now: int, st: ControlStatus) -> int | None:
        """Verifying a cut: back out along the approach line to the pre-pose (the fruit may be
        there), then on to the ready pose, out of the camera's way. Once there (or timed out
        getting there): since when (``arrived_ns``); None before."""
        if not self.looking:
            if self._reached(st, self.s.leave_tolerance_m, loose=True) or (
                now - self.progress.since_ns > self.s.leave_timeout_s * NS
            ):
                self.looking = True
                self.progress = Progress(now, self.next_seq)
            return None
        if self.arrived_ns is None and (
            self._reached(st, self.s.home_tolerance_m, loose=True)
            or now - self.progress.since_ns > self.s.home_timeout_s * NS
        ):
            self.arrived_ns = now
        return self.arrived_ns

    def _home(self, now: int, st: ControlStatus, basket: int | None) -> None:
        if self._candidates():
            self._select(now)
            return
        at_home = self._reached(st, self.s.home_tolerance_m, loose=True)
        timed_out = now - self.progress.since_ns > self.s.home_timeout_s * NS
        if (at_home or timed_out) and self.home_since_ns is None:
            self.home_since_ns = now
        if (
            self.home_since_ns is not None
            and now - self.home_since_ns >= self.s.finish_after_s * NS
            and not self._hidden(now)
        ):
            self._end_run(now, "no reachable fruit left")

    # ---- selection ---------------------------------------------------------------------------
    def _candidates(self) -> list[FruitRecord]:
        return [
            r
            for r in self.book.candidates(self.s.lost_after_frames)
            if not self._ghost(r) and not self._left_behind(r)
        ]

    def _select(self, now: int) -> None:
        """The next fruit by the policy. Before committing: the IK must reach its poses
        (else unreachable, final) and no neighbour may stand where the tools go (else it waits
        for the others: a blocker harvested first clears the way; blocked with nothing else
        left, or by a fruit that stays, it is unreachable)."""
        while True:
            cands = self._candidates()
            if not cands:
                self._go_home(now)
                return
            picked = (
                self._planned_pick(cands, now)
                if self.s.order == "planned"
                else self._nearest_pick(cands, now)
            )
            if isinstance(picked, Wait):
                if self.phase != "home":
                    self.left_because = picked.why
                self._go_home(now)
                return
            if picked is not None:
                break
        rec, why = picked
        self.target = rec
        if rec.started_ns is None:
            rec.started_ns = now
        rec.attempt_ns = now
        self.path.start(self.q_rad)
        if rec.dish_back_m is not None:
            why += "; the dish right under it (the branches seen leave no room farther back)"
        if rec.dish_lower_m > 0.0:
            why += f"; the dish {rec.dish_lower_m * 1e2:.0f} cm lower (a branch seen over its rim)"
        self.events.append(Event("fruit_selected", rec.fruit_id, reason=why))
        self.progress = Progress(now, self.next_seq)
        self.replans_left = self.s.plan_retries
        self.planned_after_stall = False
        self.harvest_jointed = False
        follow = self._planned_approach(rec) if self.s.plan_approach == "always" else None
        self._enter("approach", now)
        if follow is not None:
            self.retrace, self.retrace_touching, self.following = follow, False, True

    def _nearest_pick(
        self, cands: list[FruitRecord], now: int
    ) -> tuple[FruitRecord, str] | Wait | None:
        """The nearest candidate that can be harvested now; None: the candidates changed;
        ``Wait``: nothing to do now but wait at the ready pose.

        A blocked fruit waits (deferred, once) and the next one is tried: a blocker may be
        harvested later, even one that was itself deferred (a chain: C blocks B blocks A). When
        every candidate is blocked and already waited, the run waits at the ready pose while a
        blocker is hidden (the arms stood in front of it: orchard seed 15 gave a fruit up 0.3 s
        before its blocker showed again) or a fruit the branch check refused is still to be
        looked at again; with neither, the nearest is given up: nothing is left that could
        clear the way."""
        first_blocked: tuple[FruitRecord, list[FruitRecord]] | None = None
        newly_deferred = False
        pending = self._rechecks(cands, now)
        waiting = {r.key for r in pending}
        for i in nearest_first([r.seen.distance_m for r in cands]):
            rec = cands[i]
            if rec.key in waiting:
                continue
            if not self._check_reach(rec, now):
                return None
            blocking = self._blockers(rec)
            if not blocking:
                return self._crowd_pick(rec, cands, now)
            first_blocked = first_blocked or (rec, blocking)
            if not rec.deferred:
                self._blocked(rec, blocking, now, wait=True)
                newly_deferred = True
        if pending and not newly_deferred:
            return self._recheck_wait(pending)  # a fruit looked at again may clear the way
        if first_blocked is not None and not newly_deferred:
            hidden = self._hidden_blockers(first_blocked[1], cands, now)
            if hidden:
                names = ", ".join(f"#{b.fruit_id}" for b in hidden)
                return Wait(f"#{first_blocked[0].fruit_id} waits for {names} (hidden)")
            tried = self._try_through(cands)
            if tried is not None:
                return tried
            self._blocked(*first_blocked, now, wait=False)
        return None

    def _rechecks(self, cands: list[FruitRecord], now: int) -> list[FruitRecord]:
        """Candidates the branch check refused less than ``branch_check_recheck_s`` ago: not
        looked at again yet. The arms stood in front of the tree, and what they hid reads as
        occupied space until a view from the ready pose clears it (orchard seed 19 at 37.3 s:
        four fruit refused 20–52 mm deep as a stalled approach ended were given up in the same
        tick; at the ready pose 3 s later the three still listed were clear)."""
        wait_ns = round(self.s.branch_check_recheck_s * NS)
        return [
            r
            for r in cands
            if r.branch_refused_ns is not None and now < r.branch_refused_ns + wait_ns
        ]

    def _recheck_wait(self, pending: list[FruitRecord]) -> Wait:
        """Wait at the ready pose for the first of ``pending`` to be looked at again."""
        first = min(pending, key=lambda r: r.branch_refused_ns or 0)
        at_s = ((first.branch_refused_ns or 0) / NS) + self.s.branch_check_recheck_s
        return Wait(f"#{first.fruit_id} waits for another look at the branches ({at_s:.1f} s)")

    def _try_through(self, cands: list[FruitRecord]) -> tuple[FruitRecord, str] | None:
        """Every candidate is blocked and has waited: rather than give them all up, go once for
        the one whose blockers reach least into its tools' way, if by no more than
        ``try_blocked_max_m``. The clutter check runs on estimates of fruit that hide each other
        (orchard seeds 7 and 9: two fruit blocking each other that the true shapes let through);
        the controller's dampers keep the tools off every fruit in the scene, so a wrong guess
        costs a stalled attempt (then final), not a collision. None: none qualifies."""
        if self.s.try_blocked_max_m <= 0:
            return None
        best: tuple[float, float, FruitRecord, list[FruitRecord]] | None = None
        for rec in cands:
            if rec.tried_blocked:
                continue
            depths = self._blocker_depths(rec)
            deepest = max(d for _, d in depths)
            if deepest <= self.s.try_blocked_max_m and (
                best is None or (deepest, rec.seen.distance_m) < best[:2]
            ):
                best = (deepest, rec.seen.distance_m, rec, [b for b, _ in depths])
        if best is None:
            return None
        deepest, _, rec, blocking = best
        rec.tried_blocked = True
        names = ", ".join(f"#{b.fruit_id}" for b in blocking)
        return rec, (
            f"tried once although blocked by {names} (the estimates reach {deepest * 1e3:.0f} mm "
            "into its tools' way, the least of the blocked fruit): the dampers decide"
        )

    def _crowd_pick(
        self, rec: FruitRecord, cands: list[FruitRecord], now: int
    ) -> tuple[FruitRecord, str] | None:
        """``rec`` (the nearest free fruit) or, with ``crowd_first``, the nearest of the
        neighbours its arms would touch at every IK solution of a pose that can be harvested
        now: it goes first (its own crowders are not asked: no chain, no cycle). None: the
        candidates changed."""
        why = f"nearest ({rec.seen.distance_m:.3f} m from the camera)"
        got = self._crowders(rec, cands)
        if got is None:
            return rec, why
        crowders, crowding = got
        names = ", ".join(f"#{c.fruit_id}" for c in crowders)
        for c in sorted(crowders, key=lambda r: r.seen.distance_m):
            if not self._check_reach(c, now):
                return None
            if not self._blockers(c):
                return c, (
                    f"before #{rec.fruit_id}, the nearest ({rec.seen.distance_m:.3f} m): "
                    + crowding.why(names)
                )
        return rec, f"{why}; {crowding.why(names)}, none of which can go first"

    def _crowders(
        self, rec: FruitRecord, cands: list[FruitRecord]
    ) -> tuple[list[FruitRecord], Crowding] | None:
        """The candidates the arms would touch at every IK solution of ``rec``'s harvest pose
        or pre-pose (``crowd.py``), and the verdict; None: none (or ``crowd_first`` off)."""
        if self.crowd is None:
            return None
        present = self._on_tree(rec)
        crowding = self.crowd.crowders(
            self.kin,
            self._poses(rec, self._settings_for(rec), rec.dish_back_m),
            [r.planned for r in present],
        )
        if crowding is None:
            return None
        keys = {r.key for r in cands}
        crowders = [present[i] for i in crowding.neighbours if present[i].key in keys]
        return (crowders, crowding) if crowders else None

    def _hidden_blockers(
        self, blocking: list[FruitRecord], cands: list[FruitRecord], now: int
    ) -> list[FruitRecord]:
        """Blockers that are no candidate now but hidden (seen within ``hidden_wait_s``): they
        may show again, be harvested and clear the way."""
        keys = {r.key for r in cands}
        hidden = {r.key for r in self._hidden(now)}
        return [b for b in blocking if b.key not in keys and b.key in hidden]

    def _planned_pick(
        self, cands: list[FruitRecord], now: int
    ) -> tuple[FruitRecord, str] | Wait | None:
        """The first fruit of the shortest order that harvests every blocker before the fruit
        it blocks; None: the candidates changed; ``Wait``: a fruit the branch check refused
        is to be looked at again first (the order is planned with its verdict).

        A fruit blocked by one that is still to do but not a candidate now (waiting after a
        stuck attempt) waits too; one that no order can clear (blocked by a fruit that stays,
        or in a cycle of blockers) is given up."""
        pending = self._rechecks(cands, now)
        if pending:
            return self._recheck_wait(pending)
        if not all([self._check_reach(r, now) for r in cands]):  # each checked: a list
            return None  # skipped or deferred: the candidates changed
        ok = cands
        index = {r.key: i for i, r in enumerate(ok)}
        blocking = [self._blockers(r) for r in ok]
        for r, bl in zip(ok, blocking, strict=True):
            waiting = [b for b in bl if b.key not in index and not b.finished]
            if waiting and not r.deferred:
                self._blocked(r, waiting, now, wait=True)
                return None
        # -1: a blocker that is not a candidate stays where it is
        blocked_by = {j: {index.get(b.key, -1) for b in bl} for j, bl in enumerate(blocking)}
        can = clearable(blocked_by)
        if len(can) != len(ok):
            for j in sorted(set(blocked_by) - can):
                self._blocked(ok[j], blocking[j], now, wait=False)
            return None
        before = [(i, j) for j, bl in blocked_by.items() for i in sorted(bl)]
        before += self._crowd_before(ok, index, blocked_by)
        pts = np.array([pre_pose(r.planned, self.pose_settings).tip_world_m for r in ok])
        start = self.last_tip_world_m if self.last_tip_world_m is not None else self._ready_tip()
        order = planned_order(start, pts, self._ready_tip(), self.s.planned_exact_max, before)
        rec = ok[order[0]]
        return rec, f"planned order ({len(ok)} fruit): " + " → ".join(
            str(ok[i].fruit_id) for i in order
        )

    def _crowd_before(
        self,
        ok: list[FruitRecord],
        index: dict[int, int],
        blocked_by: dict[int, set[int]],
    ) -> list[tuple[int, int]]:
        """With ``crowd_first``: (crowder, fruit) pairs for the planned order, a neighbour the
        arms would touch going for a fruit first; none when they would make a cycle with the
        blockers (the order is then the blockers' alone)."""
        soft: dict[int, set[int]] = {j: set() for j in blocked_by}
        for j, r in enumerate(ok):
            got = self._crowders(r, ok)
            if got is not None:
                soft[j] = {index[c.key] for c in got[0]}
        if not any(soft.values()):
            return []
        if len(clearable({j: blocked_by[j] | soft[j] for j in blocked_by})) != len(ok):
            return []
        return [(i, j) for j, s in soft.items() for i in sorted(s)]

    def _hidden(self, now: int) -> list[FruitRecord]:
        """Fruit to do that were seen on the tree within ``hidden_wait_s`` and are not shown now
        (leaves, a person, the arms in front): the run waits for them (ghosts aside)."""
        return [
            r
            for r in self.book.hidden(now, self.s.hidden_wait_s)
            if not self._ghost(r) and not self._left_behind(r)
        ]

    def _ghost(self, rec: FruitRecord) -> bool:
        """A record not seen now that overlaps a fruit known to be off the tree (harvested,
        dropped) is that fruit under another track ID, listed where it hung until the scene
        forgets it: neither a candidate nor a neighbour in the way."""
        if rec.seen.frames_unseen == 0 or rec.outcome in ("harvested", "dropped"):
            return False
        return any(
            same_fruit(rec.planned, r.planned)
            for r in self.book.detected()
            if r is not rec and r.outcome in ("harvested", "dropped")
        )

    def _left_behind(self, rec: FruitRecord) -> bool:
        """A record the scene has not estimated from a view since another record overlapping
        it (``same_fruit``: no two fruit are that close) was first seen, estimated since, is
        that fruit under a new track ID, moved away from where the old track stays (paper-exp1
        seed 11: a hand moved a fruit 6.7 cm; the tracker gave it ID 37 and kept ID 6 alive on
        views the scene could not estimate where it had hung; the tools went for #6 and
        stalled). Not a candidate, and not waited for; it is one again once estimated anew."""
        if rec.finished:
            return False
        since = rec.viewed.last_seen_stamp_ns if rec.viewed is not None else -1
        return any(
            r.first_seen_ns is not None
            and r.first_seen_ns > since
            and r.viewed is not None
            and r.viewed.last_seen_stamp_ns > since
            and r.confirmed
            and r.outcome in (None, "harvested")
            and same_fruit(rec.planned, r.planned)
            for r in self.book.detected()
            if r is not rec
        )

    def _on_tree(self, rec: FruitRecord) -> list[FruitRecord]:
        """The other fruit on the tree: seen, not known to be off it, no ghost."""
        return [
            r
            for r in self.book.detected()
            if r is not rec
            and r.in_scene
            and r.outcome not in ("harvested", "dropped")
            and not self._ghost(r)
        ]

    def _blockers(
        self, rec: FruitRecord, settings: PoseSettings | None = None
    ) -> list[FruitRecord]:
        """Fruit on the tree (seen, not known to be off it) where the tools go for ``rec`` (with
        ``settings``' poses; None: the record's own)."""
        return [r for r, _ in self._blocker_depths(rec, settings)]

    def _blocker_depths(
        self, rec: FruitRecord, settings: PoseSettings | None = None
    ) -> list[tuple[FruitRecord, float]]:
        """The blockers of ``rec`` and how far each reaches into its tools' way, m."""
        present = self._on_tree(rec)
        depths = intrusions_m(
            rec.planned,
            [r.planned for r in present],
            settings or self._settings_for(rec),
            self.s.neighbour_clearance_m,
        )
        return [(r, d) for r, d in zip(present, depths, strict=True) if d > 0]

    def _blocked(self, rec: FruitRecord, blocking: list[FruitRecord], now: int, wait: bool) -> None:
        """``rec`` cannot be harvested now: wait for the others (once), or give it up."""
        names = ", ".join(f"#{b.fruit_id}" for b in blocking)
        if wait and not rec.deferred:
            rec.deferred = True
            why = f"blocked by {names} (in the tools' way): retried after the others"
            self.events.append(Event("fruit_skipped", rec.fruit_id, reason=why))
            return
        if wait:
            return
        why = f"unreachable: blocked by {names} (in the tools' way)"
        self.events.append(Event("fruit_skipped", rec.fruit_id, outcome="unreachable", reason=why))
        self._finish(rec, now, "unreachable", why)
        rec.finished_ns = now

    def _check_reach(self, rec: FruitRecord, now: int) -> bool:
        """IK of the harvest pose and the pre-pose (cached), then (``branch_check``) their IK
        solutions against the branches seen now. Out of reach: skipped now, final; a branch in
        the way: deferred the first time (retried after the others, ``_rechecks``), final the
        second."""
        h = harvest_pose(rec.planned, self.pose_settings)
        p = pre_pose(rec.planned, self.pose_settings)
        if rec.reach is None:
            rec.reach = (self.kin.reach(h), self.kin.reach(p))
        hv, pv = rec.reach
        if hv.reachable and pv.reachable:
            if self.branches is None:
                rec.dish_back_m, rec.dish_lower_m = None, 0.0
                return True
            verdict = self._branch_verdict(rec, h.basket_back_m)
            if verdict.clear:
                return True
            if rec.branch_refused_ns is None:
                # What reads as a branch may be passing (a hand seen in front is occupied space
                # while it is hit, and so is what an arm hid until a view clears it): look
                # again when nothing else is left, and no sooner than branch_check_recheck_s.
                rec.deferred, rec.branch_refused_ns = True, now
                why = f"blocked: {verdict.why()}; retried after the others"
                self.events.append(Event("fruit_skipped", rec.fruit_id, reason=why))
                return False
            why = f"unreachable: {verdict.why()}"
        else:
            which = "harvest pose" if not hv.reachable else "pre-pose"
            bad = hv if not hv.reachable else pv
            why = f"unreachable: {which} out of reach ({bad.why()})"
        self.events.append(Event("fruit_skipped", rec.fruit_id, outcome="unreachable", reason=why))
        self._finish(rec, now, "unreachable", why)
        rec.finished_ns = now  # never attempted
        return False

    def _branch_verdict(self, rec: FruitRecord, rule_back_m: float) -> BranchVerdict:
        """The branch check of the pose rule's poses (the dish ``rule_back_m`` back); when it
        refuses them and the rule set the dish back, of the dish right under the tip too
        (``branch_check_dish_under``), whose poses the controller is then sent
        (``rec.dish_back_m``); then the dish lower (``_dish_lower``). The rule's verdict names a
        refusal."""
        assert self.branches is not None
        rec.dish_back_m, rec.dish_lower_m = None, 0.0
        ids = frozenset((rec.key, rec.fruit_id))
        verdict = self._rule_or_under(rec, rule_back_m, ids)
        if self.s.branch_check_dish_lower_m > 0.0:
            verdict = self._dish_lower(rec, rule_back_m, ids, verdict)
        return verdict

    def _rule_or_under(
        self, rec: FruitRecord, rule_back_m: float, ids: frozenset[int]
    ) -> BranchVerdict:
        """The rule's verdict (its dish ``rule_back_m`` back), or the dish right under the
        tip's where that one is clear and the rule's is not (``rec.dish_back_m`` 0)."""
        assert self.branches is not None
        verdict = self.branches.check(
            self.kin, rec.planned, self._poses(rec, self.pose_settings, None), ids
        )
        if verdict.clear or rule_back_m == 0.0 or not self.s.branch_check_dish_under:
            return verdict
        under = self._poses(rec, self.pose_settings, 0.0)
        if not all(self.kin.reach(x).reachable for _, x in under):
            return verdict
        alt = self.branches.check(self.kin, rec.planned, under, ids)
        if not alt.clear:
            return verdict
        rec.dish_back_m = 0.0
        return alt

    def _dish_lower(
        self,
        rec: FruitRecord,
        rule_back_m: float,
        ids: frozenset[int],
        verdict: BranchVerdict,
    ) -> BranchVerdict:
        """``branch_check_dish_lower_m``: the chosen poses with the dish that much lower, where
        a tool of the chosen ones lies in the occupied spheres. Taken (``rec.dish_lower_m``)
        when its tools go ``DISH_LOWER_GAIN_M`` less deep (or, the chosen refused, not deeper
        than allowed), the IK reaches both poses and no fruit comes into the tools' way. The
        rim sits highest of the dish, and a branch under the fruit meets it there (orchard seed
        0: the rim 1 cm under the fruit touched a branch 7 cm behind and 5 cm under its
        centre, the pose's tools 1–2 cm into its sphere, within the check's allowance)."""
        assert self.branches is not None
        lower = self.s.branch_check_dish_lower_m
        if verdict.clear:
            backs: list[float | None] = [rec.dish_back_m]
        else:
            backs = (
                [None] if rule_back_m == 0.0 or not self.s.branch_check_dish_under else [None, 0.0]
            )
        depth_m = (
            self.branches.poses_depth_m(
                self.kin, rec.planned, self._poses(rec, self.pose_settings, rec.dish_back_m), ids
            )
            if verdict.clear
            else np.inf
        )
        if depth_m == 0.0:
            return verdict
        settings = self._lowered(lower)
        before = {r.key for r in self._blockers(rec, self.pose_settings)}
        if any(r.key not in before for r in self._blockers(rec, settings)):
            return verdict  # a lower dish goes into a neighbour: not lower
        for back in backs:
            low = self._poses(rec, settings, back)
            if not all(self.kin.reach(x).reachable for _, x in low):
                continue
            d = self.branches.poses_depth_m(self.kin, rec.planned, low, ids)
            if d <= self.branches.depth_m and d <= depth_m - DISH_LOWER_GAIN_M:
                rec.dish_back_m, rec.dish_lower_m = back, lower
                return BranchVerdict(True)
        return verdict

    @staticmethod
    def _poses(
        rec: FruitRecord, settings: PoseSettings, back_m: float | None
    ) -> list[tuple[str, ToolPoses]]:
        """``rec``'s harvest pose and pre-pose with ``settings``, the dish ``back_m`` back
        (None: the rule's), named as the branch check names them."""
        return [
            ("harvest pose", harvest_pose(rec.planned, settings, back_m)),
            ("pre-pose", pre_pose(rec.planned, settings, back_m)),
        ]

    def _lowered(self, lower_m: float) -> PoseSettings:
        """The pose settings with the dish ``lower_m`` lower than the rule's."""
        p = self.pose_settings
        return replace(p, basket_clearance_m=p.basket_clearance_m + lower_m)

    def _settings_for(self, rec: FruitRecord) -> PoseSettings:
        """The pose settings of ``rec``'s poses: the dish ``rec.dish_lower_m`` lower."""
        return self.pose_settings if rec.dish_lower_m == 0.0 else self._lowered(rec.dish_lower_m)

    def resume_cut(self, rec: FruitRecord, cut: CutState, now: int, next_seq: int) -> None:
        """A restarted planner (journal.py): the cut of ``rec`` sent before the restart is
        awaited again, from the original cut's stamp and basket count."""
        self.next_seq = next_seq
        self.target = rec
        rec.frozen = True
        rec.attempt_ns = now
        self.cut = cut
        self.book.note_cut(rec.key, cut.stamp_ns)
        self._enter("cut", now)

    # ---- helpers -----------------------------------------------------------------------------
    def _enter(self, phase: HarvestPhase, now: int) -> None:
        rec = self.target
        self.events.append(
            Event(
                "phase_changed",
                rec.fruit_id if rec is not None else None,
                self.phase,
                phase,
                self.left_because,
            )
        )
        self.left_because = ""
        self.phase = phase
        if self.s.target_hangs_over_dish:
            self._mark_hanging(rec if phase in ("approach", "harvest") else None)
        if self.s.hold_cut_views_in_harvest:
            self.book.held_key = rec.key if phase == "harvest" and rec is not None else None
        self.progress = Progress(now, self.next_seq)
        self.arrived_ns = None
        self.looking = False
        goal = self.goal()
        if goal.poses is not None:
            self.last_tip_world_m = goal.poses.tip_world_m

    def _mark_hanging(self, rec: FruitRecord | None) -> None:
        """Only the fruit the tools go for now hangs over our dish (orchard seed 14: a harvest
        that stalled with the dish 35 mm short under the fruit saw it "in the dish"; marked in
        the basket, it was never tried again, nor avoided)."""
        self.book.hanging_key = rec.key if rec is not None else None

    def _go_home(self, now: int) -> None:
        if self.phase != "home":
            self.home_since_ns = None
            self.target = None
            self._enter("home", now)

    def _open_and_leave(self, now: int) -> None:
        rec = self.target
        self.tools.append(("open", rec.fruit_id if rec is not None else None))
        self.cut = None
        self._enter("leave", now)

    def _finish(self, rec: FruitRecord, now: int, outcome: FruitOutcome, reason: str) -> None:
        """Record the outcome; the attempt ends with ``_end_attempt`` (at once, or once the
        tools are back at the pre-pose)."""
        rec.outcome, rec.reason = outcome, reason
        rec.outcome_id = rec.fruit_id  # the ID the outcome's event names

    def _end_attempt(self, rec: FruitRecord, now: int) -> None:
        """The tools are done with this fruit for now: its time adds up; a settled fruit's
        cycle ends here."""
        if rec.attempt_ns is not None:
            rec.spent_ns += now - rec.attempt_ns
            rec.attempt_ns = None
        if rec.finished and rec.finished_ns is None:
            rec.finished_ns = now

    def _end_run(self, now: int, why: str) -> None:
        rec = self.target
        if rec is not None and not rec.finished:
            rec.outcome, rec.reason = "pending", why
        if rec is not None:
            self._end_attempt(rec, now)
        for r in self.book.detected():
            if not r.finished and r.losses > 0 and not r.in_scene:
                r.outcome, r.reason = "lost", "left the scene and never came back"
            elif not r.finished and r.started_ns is None and not r.in_scene:
                # Fruit hang still in view: a track the scene forgot before it was ever
                # attempted was a fruit carried in the dish or falling, or a false detection.
                r.outcome, r.reason = "lost", "left the scene before it was attempted"
            elif not r.finished and r.deferred and r is not rec:
                # Deferred (blocked or stalled), then hidden for longer than the run waits for
                # a fruit it cannot see (hidden_wait_s): still to do, never retried.
                r.reason = "deferred, then " + self._unseen_for(r, now) + ": never retried"
            if r.finished_ns is None and r.finished:
                r.finished_ns = now
        self.target = None
        self.events.append(Event("phase_changed", None, self.phase, "done", why))
        self.events.append(Event("run_finished", reason=why))
        self.phase = "done"
        self.finished = True

    def _now_off(self, st: ControlStatus) -> str:
        """Where each tool is at the stall, when the status is of this phase's targets: the
        best task error (cutter + dish) alone hides which tool is held (orchard seed 2: best
        9 mm, then the dish held 57 mm short by a neighbour, the cutter on its pose)."""
        if not self.progress.counts(st):
            return ""
        cutter, dish = st.abs_position_error_m * 1e3, st.rel_position_error_m * 1e3
        return f"; now the cutter {cutter:.0f} mm, the dish {dish:.0f} mm off"

    @staticmethod
    def _unseen_for(r: FruitRecord, now: int) -> str:
        if r.last_seen_ns is None:
            return "never seen"
        return f"not seen for {(now - r.last_seen_ns) / NS:.0f} s"

    def _check_stuck(self, now: int, timeout_s: float, leave: bool, st: ControlStatus) -> None:
        rec = self.target
        assert rec is not None
        over = now - self.progress.since_ns > timeout_s * NS
        stuck = self.progress.stuck(now, self.s.no_progress_s)
        if not (over or stuck):
            return
        err = self.progress.best_m
        what = f"timed out after {timeout_s:.1f} s" if over else "no progress"
        detail = f"{self.phase} {what} (best task error {err * 1e3:.0f} mm{self._now_off(st)})"
        if self.phase == "approach" and self._plan_after_stall(rec, now, detail):
            return
        back = None
        if self.s.retrace_after_stall and self.q_rad is not None:
            back = Retrace.back_along(
                self.path, now, self.s.retrace_lookahead_rad, self.s.retrace_tolerance_rad
            )
        if back is not None:
            detail += f"; retracing {len(back.waypoints)} waypoints"
        if self.s.defer_blocked and not rec.deferred:
            # A neighbour or the trunk may hold the tools back; harvesting the others first
            # may clear the way: try once more when nothing else is left.
            rec.deferred = True
            why = f"blocked: {detail}; retried after the others"
            self.events.append(Event("fruit_skipped", rec.fruit_id, reason=why))
        else:
            why = f"unreachable: {detail}"
            self.events.append(
                Event("fruit_skipped", rec.fruit_id, outcome="unreachable", reason=why)
            )
            self._finish(rec, now, "unreachable", why)
        if back is not None:
            rec.frozen = rec.frozen or leave  # as the leave below: a harvest stall freezes
            self.retrace, self.retrace_touching = back, leave
            self._enter("leave", now)
        elif leave:
            rec.frozen = True
            self._enter("leave", now)
        else:
            self._end_attempt(rec, now)
            self.target = None
            self._select(now)

    def _reached(
        self, st: ControlStatus, tol_m: float, rel_tol_m: float | None = None, loose: bool = False
    ) -> bool:
        """The status is of this phase's targets, not holding, and within tolerance (the
        cutter's ``tol_m``; the dish's ``rel_tol_m``, default relative_tolerance_m; orientations;
        ``loose``: the cutter's position only)."""
        if not self.progress.counts(st):
            return False
        if st.abs_position_error_m > tol_m:
            return False
        if loose:
            return True
        rel_tol = self.s.relative_tolerance_m if rel_tol_m is None else rel_tol_m
        return (
            st.rel_position_error_m <= rel_tol
            and st.abs_orientation_error_rad <= self.s.orientation_tolerance_rad
            and st.rel_orientation_error_rad <= self.s.orientation_tolerance_rad
        )

    def _still_attached(self, rec: FruitRecord, cut: CutState, at_ready_ns: int | None) -> bool:
        """Seen after the cut (once a cut fruit would have fallen) where it was cut.

        While the tools are at the fruit, only a view the scene estimated from counts: one it
        kept its stored estimate for shows the track, not where the fruit is (orchard seed 18:
        a cut fruit bouncing in our dish read depth_inconsistent for 3 s, kept where it hung;
        the cut was called failed, the second closed on nothing, and the fruit, given up as
        still on its branch, stood in the tools' way of two others for the rest of the run).
        From the ready pose (since ``at_ready_ns``; our dish is away from the tree) a detection
        at its place counts too, estimated or kept for want of depth, but not one kept for a
        jump: the track on something elsewhere (orchard seed 2: a fruit behind leaves read
        depth_inconsistent from everywhere: on estimated views alone, a missed cut on it was
        taken for a drop)."""
        if not rec.in_scene:
            return False
        after_cut_ns = cut.stamp_ns + round(self.s.seen_after_cut_s * NS)
        if self._at_cut(rec.viewed, after_cut_ns, cut):
            return True
        f = rec.seen
        detected = f.frames_unseen == 0 and "position_jump" not in f.flags
        return at_ready_ns is not None and detected and self._at_cut(f, at_ready_ns, cut)

    def _at_cut(self, f: Fruit | None, since_ns: int, cut: CutState) -> bool:
        """``f`` seen since ``since_ns`` within ``attached_tolerance_m`` of where it was cut."""
        if f is None or f.last_seen_stamp_ns < since_ns:
            return False
        d_m = float(np.linalg.norm(np.array(f.position_world_m, float) - cut.centre_world_m))
        return d_m <= self.s.attached_tolerance_m

    def _note_switches_and_moves(self) -> None:
        rec = self.target
        for key, old, new in self.book.switches:
            if rec is not None and key == rec.key:
                self.events.append(
                    Event("replanned", new, reason=f"track ID switch {old} → {new}: same fruit")
                )
        for key, d in self.book.moved:
            if rec is not None and key == rec.key and self.phase in ("approach", "harvest"):
                self.events.append(
                    Event("replanned", rec.fruit_id, reason=f"fruit moved {d * 100:.1f} cm")
                )
        self.book.switches.clear()
        self.book.moved.clear()
        for key in self.book.back_on_branch:
            self._not_dropped(self.book.records[key])
        self.book.back_on_branch.clear()

    def _not_dropped(self, rec: FruitRecord) -> None:
        """A fruit reported dropped is seen hanging where it was cut (``FruitBook``): the cut
        missed. Its IDs are no longer ignored (the controller avoids it again); while cuts are
        left it is a candidate again, after the others, aimed deeper as a retry; else its
        cuts failed."""
        if rec is self.target or rec.outcome != "dropped":
            return
        seen = "seen on its branch again after it was reported dropped: the cut missed"
        if rec.cuts < self.s.max_cut_attempts:
            rec.outcome, rec.reason, rec.outcome_id, rec.finished_ns = None, "", None, None
            rec.frozen, rec.deferred = False, True
            rec.scene_mark_ok = False  # the scene's mark on the ID echoes the verdict withdrawn
            rec.aim_deeper_m = self.s.retry_aim_deeper_m
            why = f"{seen}; retried after the others"
            self.events.append(Event("fruit_skipped", rec.fruit_id, reason=why))
            return
        why = f"cut failed {rec.cuts} times ({seen})"
        rec.outcome, rec.reason, rec.outcome_id = "cut_failed", why, rec.fruit_id
        self.events.append(Event("fruit_skipped", rec.fruit_id, outcome="cut_failed", reason=why))

    def _ready_tip(self) -> np.ndarray:
        return self.kin.ready_tip_world_m

    def _ready(self) -> ToolPoses:
        k = self.kin
        return ToolPoses(k.ready_tip_world_m, k.ready_basket_below_m, k.ready_R_world_cutter)
