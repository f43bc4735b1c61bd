"""Harvest task planner (paper §IV): select a fruit, approach its pre-pose, reach the harvest pose,
cut, wait for the fruit in the basket, leave, next; unreachable fruit skipped with the reason;
one plan target per control status, harvest events and a run summary."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings

OrderPolicy = Literal["nearest", "planned"]


class Settings(ServiceSettings):
    """Settings of the planner. Distances in m, times in s of sim time (message stamps)."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_PLANNER_")

    order: OrderPolicy = Field(
        default="nearest",
        description="Harvest order: 'nearest' (paper: the fruit nearest the camera first) or "
        "'planned' (the order that minimises the tool's travel over the reachable fruit, "
        "home included; exact up to planned_exact_max fruit, else nearest neighbour + 2-opt).",
    )
    planned_exact_max: int = Field(
        default=12, ge=1, le=16, description="Planned order: exact (Held-Karp) up to this many."
    )
    # --- the paper's poses (§IV-A, §IV-B) -----------------------------------------------------
    security_distance_m: float = Field(
        default=0.03,
        gt=0,
        le=0.1,
        description="d_s: cutter tip above the fruit top (x_a = [x_f, y_f - d_v - d_s, z_f]); "
        "above the cutter shaft's radius (2.2 cm) so the shaft clears the fruit, below the "
        "peduncle's length so the tip is on it.",
    )
    approach_distance_m: float = Field(
        default=0.12,
        gt=0,
        le=0.4,
        description="d_z: the pre-pose is this far in front of the harvest pose along the "
        "camera's optical axis (z_a = z_f - d_z); the dish (8.5 cm radius) must clear the fruit.",
    )
    basket_clearance_m: float = Field(
        default=0.01,
        ge=0,
        le=0.1,
        description="Gap between the dish rim and the fruit bottom; the dish centre is "
        "d_s + 2 d_v + rim height + this under the cutter tip.",
    )
    dish_back_m: float = Field(
        default=0.03,
        ge=0,
        le=0.06,
        description="At the harvest pose the dish centre sits this far back from under the fruit, "
        "towards the robot (along the cutter's pointing axis): a falling 4 cm fruit still lands "
        "in the 8.5 cm dish, and fruit hanging behind and below stay out of its way, m.",
    )
    dish_catch_margin_m: float = Field(
        default=0.03,
        ge=0,
        le=0.06,
        description="dish_back_m is cut down so that the falling fruit's edge stays this far "
        "inside the dish rim (8.5 cm radius − d_h − this): the fruit's estimate is off by 1–2 cm "
        "and it bounces; a 3.9 cm fruit with the dish 3 cm back (3.4 cm measured) fell on the rim "
        "and out (paper-exp1), m.",
    )
    approach_basket_drop_m: float = Field(
        default=0.05,
        ge=0,
        le=0.2,
        description="At the pre-pose the dish is this much lower than at the harvest pose: in "
        "front of the fruit its rim would otherwise pass within the fruit damper's safety "
        "distance of the fruit's underside (the target is an obstacle until the harvest phase).",
    )
    ready_pose: Literal["home", "low"] = Field(
        default="low",
        description="The pose at the start, while nothing is to be done and at the end: 'home' "
        "(the tool pose of the sim's initial posture HOME_RAD: the arms cover ~34 % of the "
        "image, most of its lower-left quarter) or 'low' (cutter tip at (0.55, 0.15, 0.80) m "
        "pitched 30° down and turned 90° left, the dish 0.14 m under it: ~7 %, found by a "
        "search over tool poses, every joint ≥ 17° inside its limits; README).",
    )
    # --- when a phase is done ---------------------------------------------------------------
    approach_tolerance_m: float = Field(
        default=0.02, gt=0, description="Pre-pose reached: cutter position error below, m."
    )
    harvest_tolerance_m: float = Field(
        default=0.004, gt=0, description="Harvest pose reached: cutter position error below, m."
    )
    relative_tolerance_m: float = Field(
        default=0.01, gt=0, description="Dish position error (in the cutter frame) below, m."
    )
    orientation_tolerance_rad: float = Field(
        default=0.05, gt=0, description="Both tools' orientation errors below, rad."
    )
    catch_tolerance_m: float = Field(
        default=0.03,
        gt=0,
        description="The dish may stay this far from its target when a neighbour holds it back "
        "(the controller's fruit dampers): a fruit (d_h ≤ 5 cm) still falls into the 8.5 cm "
        "dish. Cut once the dish has settled (no progress for settle_s), m.",
    )
    stalled_cut_tolerance_m: float = Field(
        default=0.018,
        ge=0,
        description="A harvest held back this close to its pose (cutter position error) when it "
        "stops making progress is cut there instead of given up. The sim's shears cut within "
        "15 mm of the true peduncle, and the pose is an estimate off by as much (orchard seed "
        "19: a cut at the pose missed by 19.6 mm; one held 16 mm short of it hit at 7.7 mm). "
        "A miss is a failed cut (retried once). 0 turns this off, m; 0.012 until session 50.",
    )
    settle_s: float = Field(
        default=0.3, gt=0, description="No progress this long: the tools have settled, s."
    )
    branch_check: bool = Field(
        default=True,
        description="Before committing to a fruit, refuse it when every IK solution of its "
        "harvest pose, or of its pre-pose, puts a tool (the bodies on each arm's last joint) "
        "more than branch_check_depth_m into the occupied space the scene has seen, its own "
        "twig left out (branchcheck.py): deferred the first time, unreachable the second.",
    )
    branch_check_depth_m: float = Field(
        default=0.02,
        ge=0,
        le=0.1,
        description="… how far into the occupied spheres (a voxel's branch points, inflated by "
        "the sphere radius: they put a tool 19–41 mm nearer a branch than it is) the clearest "
        "solution's tools may go, m.",
    )
    branch_check_dish_under: bool = Field(
        default=True,
        description="… when the poses with the dish dish_back_m back are refused, check them "
        "with the dish right under the tip and, if those are clear, send the controller those "
        "(the IK measures the dish where it is sent; the back place is the rule, not a need).",
    )
    branch_check_dish_lower_m: float = Field(
        default=0.02,
        ge=0,
        le=0.06,
        description="… when a tool of the chosen poses lies in the occupied spheres (within "
        "branch_check_depth_m, or refused), check them with the dish this much lower (its rim "
        "further under the fruit; the fruit falls that much farther) and take those if their "
        "tools go at least 5 mm less deep, the IK reaches them, and no fruit comes into the "
        "tools' way (the dish's rim met branches passing 5-7 cm behind and under the fruit it "
        "waited under, orchard seed 0; 20 orchard seeds: BENCHMARKS.md, session 48); 0: off, m.",
    )
    branch_check_recall: bool = Field(
        default=True,
        description="… a sphere listed again in (or next to) a cell where one counted before "
        "counts at once, not after branch_check_min_age_s (a branch the arms hid and the "
        "camera sees again is not new; orchard seed 0: a branch counted at the start was young "
        "again when the fruit in front of it was checked, and the dish met it).",
    )
    branch_check_recheck_s: float = Field(
        default=3.0,
        ge=0,
        le=60,
        description="… a fruit refused is looked at again no sooner than this after the "
        "refusal, the arms at the ready pose if nothing else is left (orchard seed 19: four "
        "fruit refused as the arms left a stalled approach were given up in the same tick; "
        "3 s later at the ready pose the three still listed were clear of the branches), s.",
    )
    branch_check_own_branch_m: float = Field(
        default=0.1,
        ge=0,
        le=0.3,
        description="… spheres above the fruit's top and within this of it are its own twig "
        "(the cutter closes on the peduncle next to it): not in the way, m.",
    )
    branch_check_min_age_s: float = Field(
        default=2.0,
        ge=0,
        le=60,
        description="… a sphere counts once the scene has listed it this long, or since its "
        "first states (a hand passing in front is occupied space while it is seen), s.",
    )
    crowd_first: bool = Field(
        default=False,
        description="Before committing to a fruit, measure every IK solution of its harvest pose "
        "and pre-pose (every robot body, the arms included) against the other fruit the scene "
        "lists; when each solution of a pose comes within crowd_clearance_m of some neighbour "
        "that can be harvested now, that neighbour goes first (crowd.py). It orders the "
        "harvest and refuses nothing.",
    )
    crowd_clearance_m: float = Field(
        default=0.0,
        ge=0,
        le=0.05,
        description="… a robot body nearer than this to a neighbour's estimated ellipsoid "
        "touches it (0: contact with the estimate), m.",
    )
    neighbour_clearance_m: float = Field(
        default=0.0,
        ge=0,
        description="Reachability in clutter: a neighbour closer than this to where the dish or "
        "the cutter goes (harvest pose, and the move from the pre-pose) blocks the fruit, m. The "
        "controller's fruit damper keeps d_s (2 cm) from every fruit, but the hulls are already "
        "conservative (the dish hull, the fruit's largest semi-axis) and the scene's estimates "
        "are off by a few mm: any margin here blocked fruit that the arms do reach (a near miss "
        "costs a 'no progress' retry, not a collision: the controller's dampers keep d_s), m.",
    )
    try_blocked_max_m: float = Field(
        default=0.0,
        ge=0,
        description="When every fruit left is blocked by a neighbour and has waited once (two "
        "fruit blocking each other, or behind one that stays), the one whose blockers' estimates "
        "reach least into its tools' way is gone for once, if by no more than this, instead of "
        "all being given up: the clutter check runs on estimates, the dampers on the scene keep "
        "the tools off the fruit seen (a wrong guess is a stalled attempt, then final). 0: off "
        "(default: orchard seeds 7 and 9 gave 2 more fruit but 4 more contacts), m.",
    )
    defer_blocked: bool = Field(
        default=True,
        description="A fruit whose approach or harvest stops making progress is put back once "
        "and tried again when nothing else is left (a neighbour harvested meanwhile may clear "
        "the way); the second time it is unreachable.",
    )
    retrace_after_stall: bool = Field(
        default=False,
        description="After a stalled approach or harvest, the arms go back along the joint path "
        "they came in by (joint goals to the controller) to where the attempt began, before the "
        "next fruit: arms caught across branches are freed whatever the scene (retrace.py). Off: "
        "on orchard seeds 0-19 it harvested 87 of the 173 reachable fruit against 84, with "
        "986 collisions against 830 (BENCHMARKS.md, Harvest, session 7).",
    )
    retrace_step_rad: float = Field(
        default=0.1, gt=0, description="Retrace waypoints: one each time a joint moved this, rad."
    )
    retrace_lookahead_rad: float = Field(
        default=0.15,
        gt=0,
        description="Retracing: on to the next waypoint once every joint is this close, rad.",
    )
    retrace_tolerance_rad: float = Field(
        default=0.03,
        gt=0,
        description="Retracing: back at the start once every joint is this close, rad.",
    )
    retrace_timeout_s: float = Field(
        default=15.0, gt=0, description="Retracing: limit (then on to the next fruit), s."
    )
    plan_approach: Literal["off", "always", "after_stall"] = Field(
        default="after_stall",
        description="Planned joint paths to the pre-pose (RRT-Connect against the scene's "
        "obstacles to its clearest IK solution, motion.py), followed as joint goals, then the "
        "usual pose goals. 'always': every approach starts along one (no path found: the pose "
        "goals at once); 'after_stall': an approach whose pose goals stop making progress "
        "gets one (once per attempt) before it is given up; 'off': pose goals only. Default "
        "'after_stall': orchard seeds 0-19 gave 85 of 101 reachable against 83 (off), with 311 "
        "collisions against 333 (BENCHMARKS.md, Harvest, session 20).",
    )
    plan_margin_m: float = Field(
        default=0.045,
        gt=0,
        le=0.1,
        description="Planned paths keep the robot this far from the trunk, fruit and branch "
        "spheres, m: above the controller's damper safety distances (trunk 3 cm), or the "
        "dampers stop the arms on the path.",
    )
    plan_limit_margin_rad: float = Field(
        default=0.1,
        ge=0,
        le=0.5,
        description="… and every joint this far inside its limits, rad.",
    )
    plan_retries: int = Field(
        default=1,
        ge=0,
        description="A planned path the arms cannot follow (stuck, timed out) is planned again "
        "from where they are, this many times per attempt; then the pose goals.",
    )
    plan_from_attempt_start: bool = Field(
        default=False,
        description="A plan that finds no path from where the arms are (stalled among "
        "branches, a link at the dampers' d_s) plans from where the attempt began instead, and "
        "the arms first go back along the joints they came in by (free: they came that way).",
    )
    harvest_joints_after_stall: bool = Field(
        default=False,
        description="A harvest that makes no progress with the cutter held farther than "
        "stalled_cut_tolerance_m from its pose (a joint at its stop: orchard seed 19, 16 mm) "
        "gets, once per attempt, a joint goal: the "
        "harvest pose's IK solution nearest the arms, under the controller's limits and "
        "dampers; then the pose goals again.",
    )
    plan_self_margin_m: float = Field(
        default=0.005, ge=0, le=0.1, description="… and its bodies this far apart, m."
    )
    plan_escape_rad: float = Field(
        default=0.3,
        gt=0,
        description="Within this of a path's end that is closer than the margins (arms among "
        "the branches, a pre-pose in the crown), configurations need only be no closer, rad.",
    )
    plan_max_checks: int = Field(
        default=3000,
        ge=10,
        description="A plan gives up after this many configurations checked (~0.3 ms each).",
    )
    plan_goal_margin_m: float = Field(
        default=0.02,
        ge=0,
        le=0.1,
        description="IK solutions of the pre-pose closer than plan_margin_m to an obstacle are "
        "first moved in the arms' null space (the tools held) until this far from every "
        "obstacle, where they can be (goalclear.py), m; 0: the IK's solutions as they are.",
    )
    plan_goal_steps: int = Field(
        default=200, ge=1, description="… in at most this many IK steps (~1 ms each)."
    )
    plan_goal_max_depth_m: float = Field(
        default=0.0,
        ge=0,
        description="No path is planned to a goal that, moved clear as far as it goes, still "
        "lies deeper than this inside a branch or the trunk the scene shows: the dampers stop "
        "the arms short of it, in contact (paper-exp1 seed 9: a path to a goal 53 mm inside a "
        "branch, 12 contacts; orchard seed 9: one 9 mm inside, 89 contacts); fruit, which "
        "swing aside, do not count, m. 0.02 was the default up to session 29.",
    )
    plan_trunk_margin_m: float = Field(
        default=0.08,
        ge=0,
        le=1,
        description="Planning: the trunk cylinder is resized for the new target as the scene "
        "does (its trunk_tool_margin_m): surface this far behind the fruit, m.",
    )
    plan_lookahead_rad: float = Field(
        default=0.25,
        gt=0,
        description="Following a planned path: the joint goal this far ahead of the arms, rad "
        "(the controller moves at joint_gain_per_s times it at most).",
    )
    leave_tolerance_m: float = Field(
        default=0.03, gt=0, description="Back at the pre-pose after a fruit: error below, m."
    )
    home_tolerance_m: float = Field(
        default=0.03, gt=0, description="At the ready pose: cutter position error below, m."
    )
    # --- cut and collection -----------------------------------------------------------------
    collect_timeout_s: float = Field(
        default=1.5,
        gt=0,
        description="After a cut, wait this long for the basket's fruit count to go up; then "
        "judge: fruit still on its branch (cut failed) or gone (dropped).",
    )
    attached_tolerance_m: float = Field(
        default=0.03,
        gt=0,
        description="Cut failed when the fruit is seen, after the cut, within this of where it "
        "was cut, m.",
    )
    seen_after_cut_s: float = Field(
        default=0.4,
        ge=0,
        description="A sighting counts as 'still on its branch' only this long after the cut "
        "(a cut fruit falls ~5 cm in 0.1 s).",
    )
    verify_s: float = Field(
        default=1.0,
        gt=0,
        description="A cut not confirmed by the basket, with the fruit not seen since (the tools "
        "hide it): the tools back out to the ready pose and look this long; seen on its branch → "
        "the cut failed (retry), not seen → dropped, s.",
    )
    max_cut_attempts: int = Field(
        default=2, ge=1, le=5, description="Cuts per fruit (the issue: retry once)."
    )
    retry_aim_deeper_m: float = Field(
        default=0.012,
        ge=0.0,
        le=0.03,
        description="A retried cut (the fruit still on its branch) aims this much farther from "
        "the camera, along its optical axis in the horizontal plane. A failed cut closes short: "
        "partly hidden fruit come out about 3 mm nearer than they are, the cutter stops within "
        "harvest_tolerance_m short of its pose, and a second cut from the same estimate closes "
        "where the first did. Orchard: BENCHMARKS.md, Harvest, session 27. 0: off, m.",
    )
    relook_before_retry: bool = Field(
        default=False,
        description="A failed cut with the fruit seen on its branch: the tools back out to the "
        "ready pose, the target is re-planned from the first view the scene computes there, "
        "then approached again (false: cut again from where the tools are, on the estimate the "
        "cut missed with). Off by default: over orchard seeds 0-19 it re-planned 7 of 17 "
        "retries (no usable view from afar for the others), second cuts hit 6 of 15 (5 of 17 "
        "without), and 78 of 101 reachable fruit were harvested against 79 (BENCHMARKS.md, "
        "Harvest, session 16).",
    )
    # --- failure detection ------------------------------------------------------------------
    no_progress_s: float = Field(
        default=1.5,
        gt=0,
        description="A phase whose error has not improved by progress_min_m for this long is "
        "stuck: the fruit is skipped as unreachable, s.",
    )
    progress_min_m: float = Field(
        default=0.002, gt=0, description="Improvement that counts as progress, m."
    )
    approach_timeout_s: float = Field(default=8.0, gt=0, description="Approach phase limit, s.")
    harvest_timeout_s: float = Field(default=5.0, gt=0, description="Harvest phase limit, s.")
    leave_timeout_s: float = Field(
        default=3.0, gt=0, description="Leave phase limit (then on to the next fruit), s."
    )
    home_timeout_s: float = Field(default=6.0, gt=0, description="Going home: limit, s.")
    # --- fruit bookkeeping ------------------------------------------------------------------
    replan_distance_m: float = Field(
        default=0.015,
        gt=0,
        description="The target fruit's estimate moved more than this from the planned "
        "position: re-plan the poses (a 'replanned' event); smaller changes are ignored so "
        "perception noise does not shake the target, m.",
    )
    follow_cut_views: bool = Field(
        default=False,
        description="A target with no whole view (none yet, or one the fruit has since shown "
        "itself larger than) follows the median of its last fresh views of its own size "
        "(planner README, 'The target'); false: it moves only when one view strays "
        "replan_distance_m from it, and takes that view. Off by default: BENCHMARKS.md, Harvest, "
        "session 17.",
    )
    hold_cut_views_in_harvest: bool = Field(
        default=False,
        description="With follow_cut_views: the target stops following its cut views once the "
        "harvest phase starts, and takes them up again at the next approach. The tools are then "
        "in front of the fruit, and a view they cut can still be of the fruit's own size. Off by "
        "default: BENCHMARKS.md, Harvest, session 20.",
    )
    target_hangs_over_dish: bool = Field(
        default=False,
        description="The fruit the tools go for (approach, harvest) is never taken for one in "
        "the basket when the scene sees it in our dish: the dish is under it by design (false: "
        "a target seen there, say with the dish pushed up under it in a stalled harvest, is "
        "marked in the basket, then never tried again nor avoided). Off by default: orchard "
        "seeds 0-19 gave 81 of 101 reachable, as without, with 342 collisions against 337 "
        "(BENCHMARKS.md, Harvest, session 18).",
    )
    same_fruit_m: float = Field(
        default=0.04,
        gt=0,
        description="A new track ID within this of a known fruit is that fruit (tracker ID "
        "switch, or a stale duplicate), m.",
    )
    lost_after_frames: int = Field(
        default=45,
        ge=1,
        description="A fruit not seen for this many camera frames is not selected (45 frames = "
        "3 s). Once selected, the approach goes on to its last known position while the scene "
        "lists it (a hand or the arm may hide it for a while); it is lost when the scene drops "
        "it.",
    )
    max_losses: int = Field(
        default=2, ge=1, description="Times a fruit may be lost before it is given up."
    )
    # --- reachability (IK, services/robot/reach.py) -----------------------------------------
    reach_tolerance_m: float = Field(
        default=0.005, gt=0, description="IK residual below which a pose is reachable, m."
    )
    reach_yaws_deg: tuple[float, ...] = Field(
        default=(0.0, -25.0, 25.0, -50.0, 50.0),
        min_length=1,
        description="Cutter yaws tried by the IK (the paper's free θ_a), deg.",
    )
    reach_iterations: int = Field(default=250, ge=10, description="IK iterations per try.")
    # --- run --------------------------------------------------------------------------------
    startup_s: float = Field(
        default=1.0,
        ge=0,
        description="Watch this long before the first selection (tracks need ~10 frames).",
    )
    finish_after_s: float = Field(
        default=1.0,
        ge=0,
        description="At the ready pose with no fruit left for this long: the run ends, s.",
    )
    hidden_wait_s: float = Field(
        default=20.0,
        ge=0,
        description="The run does not end while a fruit never settled was last seen less than "
        "this long ago: leaves, a person or the arms hide a fruit for longer than the scene "
        "keeps it listed (lost_after_frames), and it shows again, s. 0: end at once.",
    )
    max_run_s: float = Field(
        default=600.0, gt=0, description="The run ends after this much sim time whatever, s."
    )
    exit_when_done: bool = Field(
        default=True, description="Stop the service once the summary is out (ends the run)."
    )
    scenario: str = Field(default="", description="Scenario name, copied into the summary.")
    seed: int | None = Field(default=None, description="Scenario seed, copied into the summary.")

    @model_validator(mode="after")
    def _harvest_inside_approach(self) -> Settings:
        if self.harvest_tolerance_m > self.approach_tolerance_m:
            raise ValueError(
                f"harvest_tolerance_m {self.harvest_tolerance_m} exceeds approach_tolerance_m "
                f"{self.approach_tolerance_m}"
            )
        return self


SPEC = NodeSpec(
    inputs=("control/status", "scene/state", "robot/basket", "robot/joint_state"),
    outputs=("plan/target", "robot/tool", "harvest/events", "harvest/summary"),
    # One plan target per control status: the controller sees it at the next tick. Tool
    # commands, events and the summary are extra outputs published before it.
    answers={"control/status": ("plan/target",)},
)


def _make_core(settings: Settings):
    from services.planner.core import PlannerCore
    from services.planner.journal import journal_path

    return PlannerCore(settings, journal_path())


SERVICE = ServiceDef(
    "planner", Settings, SPEC, kind="reactive", make_core=_make_core, description=__doc__ or ""
)
