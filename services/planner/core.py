"""Pure core of the planner: scene states, basket readings and joint states are state; each
control status is answered with one plan target, after the tool commands, harvest events and
(once, at the end) the run summary that the same tick produced. No wall clock, no randomness:
every output is a function of the inputs (the IK is deterministic and cached per pose)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from schemas.control import ControlStatus
from schemas.harvest import HarvestEvent
from schemas.robot import BasketState, JointState, ToolCommand
from schemas.scene import Fruit, SceneState
from services.planner import Settings, journal
from services.planner.book import FruitBook, inside_dish
from services.planner.kinematics import Kinematics
from services.planner.machine import CutState, Goal, Machine
from services.planner.poses import PoseSettings, plan_target
from services.planner.summary import run_summary
from services.runtime import Output, Stamper

log = logging.getLogger("planner")
NAME = "planner"
DISH_HISTORY = 32  # camera stamps whose dish pose is kept (a fruit is judged at its sighting)
IN_DISH_MARGIN_M = 0.02
RESTING_ABOVE_RIM_M = 0.05  # a fruit in the basket: its centre estimate from its top's view


class PlannerCore:
    """See the package README for inputs, outputs, settings and the state machine."""

    def __init__(self, settings: Settings, journal_path: Path | None = None) -> None:
        s = self.s = settings
        self.kin = Kinematics(
            s.reach_yaws_deg, s.reach_iterations, s.reach_tolerance_m, s.ready_pose
        )
        self.book = FruitBook(s.same_fruit_m, s.replan_distance_m, s.follow_cut_views)
        self.machine = Machine(
            s,
            self.book,
            self.kin,
            PoseSettings(
                s.security_distance_m,
                s.approach_distance_m,
                s.basket_clearance_m,
                s.approach_basket_drop_m,
                self.kin.camera_axis_world,
                s.dish_back_m,
                s.dish_catch_margin_m,
            ),
        )
        if s.branch_check:
            from services.planner.branchcheck import BranchCheck

            self.machine.branches = BranchCheck(
                s.branch_check_depth_m,
                s.branch_check_own_branch_m,
                s.branch_check_min_age_s,
                recall=s.branch_check_recall,
            )
        if s.crowd_first:
            from services.planner.crowd import CrowdCheck

            self.machine.crowd = CrowdCheck(s.crowd_clearance_m)
        if s.plan_approach != "off":
            from services.planner.motion import ApproachPlanner

            self.machine.motion = ApproachPlanner(s, self.kin.solver)
        self.stamper = Stamper(NAME)
        self.targets_sent = 0
        self.basket_count: int | None = None
        self.pending_scene: SceneState | None = None
        self.contacts = 0  # robot-side: the controller's distance model reached contact
        self._in_contact = False
        self.summary_sent = False
        self.refused: dict[str, int] = {}
        self.journal_path = journal_path  # services/planner/journal.py: survives a restart
        self._journaled = ""
        self._resume_cut: dict[str, int] | None = None
        if journal_path is not None:
            self._resume(journal_path)

    def _resume(self, path: Path) -> None:
        """A restarted planner (under the supervisor): take the journal its predecessor left."""
        got = journal.load(path, self.book)
        if got is None:
            return
        self.contacts, self._resume_cut = got
        self.machine.started = True  # the run started before the restart: no second event
        settled = sum(r.finished for r in self.book.records.values())
        log.warning(
            "resumed from %s: %d fruit known, %d settled, %d contacts%s",
            path,
            len(self.book.records),
            settled,
            self.contacts,
            f", cut of fruit {self._resume_cut['fruit_id']} awaiting confirmation"
            if self._resume_cut
            else "",
        )

    # ---- inputs ------------------------------------------------------------------------------
    def handle(self, topic: str, msg: Any) -> list[Output]:
        if topic == "scene/state":
            self.pending_scene = msg  # used at the next status, once its joint state is in
            return []
        if topic == "robot/basket":
            self._on_basket(msg)
            return []
        if topic == "robot/joint_state":
            self._on_joint_state(msg)
            return []
        if topic == "control/status":
            return self._on_status(msg)
        return []

    def done(self) -> bool:
        """True once the summary is out (the runtime then stops the service: the run ends)."""
        return self.summary_sent and self.s.exit_when_done

    def _on_basket(self, msg: BasketState) -> None:
        if self.basket_count is not None and msg.fruit_count < self.basket_count:
            self._refuse(
                "robot/basket", f"fruit count went down {self.basket_count} → {msg.fruit_count}"
            )
            return
        self.basket_count = msg.fruit_count

    def _on_joint_state(self, js: JointState) -> None:
        q = self.kin.arm_order(js)
        if q is not None:
            self.machine.note_joints(q)
        scene = self.pending_scene
        if scene is None or js.header.stamp_ns != scene.header.stamp_ns:
            return  # only the dish at camera stamps is needed (fruit are seen at those)
        dish = self.kin.dish(js)
        if dish is None:
            self._refuse("robot/joint_state", "an arm or a joint is missing")
            return
        self.book.dish_at[js.header.stamp_ns] = dish
        for old in sorted(self.book.dish_at)[:-DISH_HISTORY]:
            del self.book.dish_at[old]

    def _in_dish(self, f: Fruit, resting: bool = False) -> bool:
        """The sighting is in our dish (at the joint state of its camera frame). ``resting``:
        for a fruit known to be in the basket, whose top alone shows above the rim: the
        scene's centre from that partial view sits up to a fruit's radius too high (paper-exp1
        seed 13: 7.7 cm above the floor, the rim at 4.5), so up to ``RESTING_ABOVE_RIM_M``
        above the rim counts, except at the target, which hangs over the dish when cut."""
        dish = self.book.dish_at.get(f.last_seen_stamp_ns)
        if dish is None:
            return False
        p = np.array(f.position_world_m, float)
        target = self.machine.target
        if resting and (
            target is None
            or np.linalg.norm(p - target.planned.centre_world_m) > self.s.same_fruit_m
        ):
            return inside_dish(p, dish, IN_DISH_MARGIN_M, RESTING_ABOVE_RIM_M)
        return inside_dish(p, dish, IN_DISH_MARGIN_M)

    def _refuse(self, topic: str, why: str) -> None:
        n = self.refused.get(topic, 0)
        self.refused[topic] = n + 1
        if n == 0:
            log.warning("%s refused: %s (later ones are only counted)", topic, why)

    # ---- the tick ----------------------------------------------------------------------------
    def _on_status(self, st: ControlStatus) -> list[Output]:
        now = st.header.stamp_ns
        if self.pending_scene is not None:
            self.book.update(self.pending_scene, self._in_dish)
            if self.machine.branches is not None:
                self.machine.branches.set_scene(self.pending_scene)
            if self.machine.motion is not None:
                self.machine.motion.obstacles = self.pending_scene.obstacles
                self.machine.motion.trunk = self.pending_scene.trunk
            self.pending_scene = None
            for old, new, fid in self.book.reborn:
                log.info("track ID %d left fruit %d: another fruit (record %d)", fid, old, new)
            self.book.reborn.clear()
            for key, fid in self.book.kept_far:
                log.debug("track ID %d far from fruit %d in a kept estimate: not another", fid, key)
            self.book.kept_far.clear()
        contacts = self.contacts
        self._count_contacts(st)
        m = self.machine
        if self._resume_cut is not None:
            self._take_cut(now, self._resume_cut)
            self._resume_cut = None
        goal = m.step(now, st, self.targets_sent, self.basket_count)
        out: list[Output] = []
        for action, fruit_id in m.tools:
            out.append(
                (
                    "robot/tool",
                    ToolCommand(
                        header=self.stamper.header("robot/tool", now, "cutter_tip"),
                        tool="cutter",
                        action=action,  # type: ignore[arg-type]
                        fruit_id=fruit_id,
                    ),
                )
            )
        for e in m.events:
            out.append(
                (
                    "harvest/events",
                    HarvestEvent(
                        header=self.stamper.header("harvest/events", now),
                        event=e.event,
                        fruit_id=e.fruit_id,
                        phase_from=e.phase_from,
                        phase_to=e.phase_to,
                        reason=e.reason,
                        outcome=e.outcome,
                    ),
                )
            )
        if m.events or self.contacts != contacts:
            self._journal()
        m.tools.clear()
        m.events.clear()
        if m.finished and not self.summary_sent:
            summary = run_summary(
                self.stamper.header("harvest/summary", now),
                self.s,
                self.book,
                self.contacts,
                now,
            )
            out.append(("harvest/summary", summary))
            self.summary_sent = True
        out.append(("plan/target", self._target(st, goal)))
        return out

    def _journal(self) -> None:
        if self.journal_path is None:
            return
        m = self.machine
        cut = None
        if m.phase == "cut" and m.cut is not None and m.target is not None:
            cut = {
                "key": m.target.key,
                "fruit_id": m.target.fruit_id,
                "stamp_ns": m.cut.stamp_ns,
                "basket_before": m.cut.basket_before,
            }
        text = journal.dump(self.book, self.contacts, cut)
        if text != self._journaled:
            try:
                journal.write(self.journal_path, text)
                self._journaled = text
            except OSError as exc:
                self._refuse("journal", f"cannot write {self.journal_path}: {exc}")

    def _take_cut(self, now: int, cut: dict[str, int]) -> None:
        """Resume the wait for a cut sent before the restart (the shears are closed, the fruit
        may be falling): the machine is in the cut phase of that fruit again."""
        rec = self.book.records.get(cut["key"])
        if rec is None or rec.finished:
            return
        state = CutState(cut["stamp_ns"], cut["basket_before"], rec.planned.centre_world_m.copy())
        self.machine.resume_cut(rec, state, now, self.targets_sent)

    def _target(self, st: ControlStatus, goal: Goal) -> Any:
        self.targets_sent += 1
        header = self.stamper.answer("plan/target", st.header, frame_id="world")
        return plan_target(
            header, goal.phase, goal.poses, goal.fruit_id, goal.ignore, goal.joints_rad
        )

    def _count_contacts(self, st: ControlStatus) -> None:
        """Contacts by the controller's own distance model (robot-side; the sim's contact count
        is for evaluation): an episode begins when a trunk or fruit distance goes below 0."""
        ds = [d for d in (st.min_distance_trunk_m, st.min_distance_fruit_m) if d is not None]
        touching = bool(ds) and min(ds) < 0.0
        if touching and not self._in_contact:
            self.contacts += 1
        self._in_contact = touching
