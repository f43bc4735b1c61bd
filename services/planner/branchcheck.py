"""Before committing to a fruit: can its tools take their poses clear of the branches seen?

The IK (services/robot/reach.py) knows the joint limits and the robot's own bodies, not the
tree. In a crown the dish's place under a fruit or the cutter's above it is often crossed by
another fruit's branch; the controller's dampers then stop the tools short (a stall, given up
after ``no_progress_s``) or, inside the scene's keep-out around the target where it shows no
branch to the dampers, the dish runs into it (orchard seeds 0–19 of session 13: 211 of the
tree contacts were made while the selected fruit was one whose every IK solution touches a
branch in the sim, 63 while it was one with a clear solution).

Each IK solution of the harvest pose and of the pre-pose (the planner's sampled cutter yaws) is
measured against every occupied sphere the scene shows, those inside the keep-out included
(``SceneState.spheres_near_selected``), with the controller's own distances (freespace.py). A
fruit whose clearest solution of either pose puts a tool deeper than ``depth_m`` into the
spheres is refused. Three things are left out, each measured on runs (BENCHMARKS.md, Harvest,
sessions 15 and 41):

* the arm links below the wrist: with the tool poses fixed the elbow can still swing, and the
  controller moves it round a branch the dampers show (paper-exp1 seed 11: every IK solution
  of a fruit the controller harvests cleanly put the collector's fifth link into a branch);
  only the bodies carried by each arm's last joint (wrist, cutter, dish) are measured;
* what the arms felt that is part of this fruit (the scene's ``own_fruit_ids``): on its skin,
  or felt only on its own attempts (its own branch, met by a stalled approach, which the
  dampers steer round on the retry; orchard seed 7, session 41: three fruit refused for such,
  2 of 9 harvested against 7 of 9);
* the fruit's own branch end: the cutter closes on the peduncle, a few centimetres from where
  the fruit's twig leaves its branch, so the spheres above the fruit's top within
  ``own_branch_m`` of it are that twig's, not something in the way (paper-exp1 seed 11: the
  end of the fruit's own branch, 10 cm above its centre, read 47 mm into the cutter).

A sphere counts only once the scene has listed it for ``min_age_s`` (or since its first
states: the tree as first seen): a hand passing in front is occupied space while it is seen,
and a fruit refused for it waits for nothing (paper-exp1, every seed: the hand that sweeps
before fruit 1 from 4.0 to 6.5 s read 79–88 mm into its pre-pose at 6.2 s). Branches do not
appear; what the check misses while young is still the dampers' to avoid.

The spheres stand for the branch surface seen from the camera (a voxel's points, inflated by
the sphere radius), so a tool a centimetre into them is touching the branch at most; the depth
is what is allowed.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from schemas.scene import Obstacles, SceneState, SphereObstacle
from services.planner.freespace import FreeSpace
from services.planner.kinematics import Kinematics
from services.planner.poses import FruitShape, ToolPoses

TOOL_JOINTS = ("cutter_j7", "collector_j7")  # the bodies they carry are measured
START_S = 0.5  # spheres first listed this soon after the first scene state were there at start
UNSEEN_FRUIT_PREFIX = "unseen_fruit_"  # the scene's names for fruit-coloured occupied space
TOUCHED_PREFIX = "touched_"  # … for what the arms felt (scene contact_obstacles)


@dataclass(frozen=True)
class BranchVerdict:
    """``clear``, or the first pose (``pose``) whose clearest IK solution puts a tool
    ``depth_m`` into the occupied spheres (of ``solutions`` solutions), deepest into the
    sphere named ``sphere``."""

    clear: bool
    pose: str = ""
    depth_m: float = 0.0
    solutions: int = 0
    sphere: str = ""

    def why(self) -> str:
        # The scene's unseen-fruit spheres are fruit no estimate explains, and its touched
        # ones what the arms felt: not branches seen.
        what = "a branch"
        if self.sphere.startswith(UNSEEN_FRUIT_PREFIX):
            what = "a fruit the detector has not found"
        elif self.sphere.startswith(TOUCHED_PREFIX):
            what = "something the arms felt"
        return (
            f"{what} in the tools' way at the {self.pose} (the clearest of {self.solutions} "
            f"IK solutions puts a tool {self.depth_m * 1e3:.0f} mm into the occupied space seen)"
        )


class BranchCheck:
    """Args:
    depth_m: how far into the occupied spheres a tool of the clearest solution may go, m.
    own_branch_m: spheres above the fruit's top and within this of it are its own twig's, m.
    min_age_s: a sphere counts once listed this long (sim time), s.
    cell_m: spheres are told apart by the cell of this size their centre lies in (the scene's
        voxel: a sphere is the mean of its voxel's points, so it stays in its cell), m.
    recall: a sphere listed again in (or next to) a cell where one has counted before counts
        at once: a branch the arms hid, seen again, is not new.
    """

    def __init__(
        self,
        depth_m: float,
        own_branch_m: float,
        min_age_s: float = 2.0,
        cell_m: float = 0.04,
        recall: bool = False,
    ) -> None:
        self.depth_m = depth_m
        self.own_branch_m = own_branch_m
        self.min_age_ns = round(min_age_s * 1e9)
        self.cell_m = cell_m
        self.space = FreeSpace(cull_m=0.05)
        model = self.space.robot.model
        self.tool_joints = {int(model.getJointId(name)) for name in TOOL_JOINTS}
        self.spheres: tuple[SphereObstacle, ...] = ()
        self.young = 0  # spheres of the latest state not old enough to count
        self.first_listed_ns: dict[tuple[int, int, int], int] = {}
        self.start_ns: int | None = None
        self.recall = recall
        self.counted_cells: set[tuple[int, int, int]] = set()  # every cell that ever counted

    def set_scene(self, scene: SceneState) -> None:
        """The occupied space of this scene state that counts: its obstacles' spheres and those
        the keep-out leaves out (no trunk, no fruit: those are other checks), listed since the
        start or for ``min_age_s``. A sphere no longer listed starts again when it comes back
        (with ``recall``: unless a sphere in its cell, or in one next to it, counted before:
        orchard seed 0, a branch 7 cm behind a fruit, counted at the start, left the list and
        came back, and was young again when that fruit was checked; the dish met it)."""
        now = scene.header.stamp_ns
        if self.start_ns is None:
            self.start_ns = now
        # A centre so far out that its cell overflows is no branch near the robot (the codec
        # admits any finite float): left out rather than crash the planner.
        cells = [(s, self._cell(s)) for s in scene.obstacles.spheres + scene.spheres_near_selected]
        listed = tuple(s for s, k in cells if k is not None)
        keys = [k for _, k in cells if k is not None]
        first = {k: self.first_listed_ns.get(k, now) for k in keys}
        self.first_listed_ns = first
        start_ns = self.start_ns + round(START_S * 1e9)
        counts = {k for k in keys if first[k] <= start_ns or now - first[k] >= self.min_age_ns}
        if self.recall:
            self.counted_cells |= counts
            counts |= {k for k in keys if self._recalled(k)}
        self.spheres = tuple(s for s, k in zip(listed, keys, strict=True) if k in counts)
        self.young = len(listed) - len(self.spheres)

    def _recalled(self, k: tuple[int, int, int]) -> bool:
        """A sphere counted before in cell ``k`` or one of its 26 neighbours (a voxel's mean
        moves across a cell border as the points seen of it change)."""
        i, j, m = k
        return any(
            (i + a, j + b, m + c) in self.counted_cells
            for a in (-1, 0, 1)
            for b in (-1, 0, 1)
            for c in (-1, 0, 1)
        )

    def _cell(self, s: SphereObstacle) -> tuple[int, int, int] | None:
        scaled = np.asarray(s.center_world_m) / self.cell_m
        if not np.all(np.isfinite(scaled)):
            return None
        i, j, k = (int(v) for v in np.floor(scaled))
        return i, j, k

    def in_the_way(
        self, fruit: FruitShape, fruit_ids: frozenset[int] = frozenset()
    ) -> tuple[SphereObstacle, ...]:
        """The spheres that may stand in the tools' way for ``fruit`` (whose track IDs are
        ``fruit_ids``): all but its own twig's and the felt places that are part of it."""
        top = fruit.centre_world_m + np.array([0.0, 0.0, fruit.d_v_m])
        return tuple(
            s
            for s in self.spheres
            if fruit_ids.isdisjoint(s.own_fruit_ids)
            if not (
                s.center_world_m[2] >= top[2]
                and float(np.linalg.norm(np.asarray(s.center_world_m) - top)) <= self.own_branch_m
            )
        )

    def check(
        self,
        kin: Kinematics,
        fruit: FruitShape,
        poses: list[tuple[str, ToolPoses]],
        fruit_ids: frozenset[int] = frozenset(),
    ) -> BranchVerdict:
        """The verdict on ``fruit`` (track IDs ``fruit_ids``) whose tool poses are ``poses``
        ((name, pose), in order)."""
        for name, depth, solutions, sphere in self._clearest(kin, fruit, poses, fruit_ids):
            if depth > self.depth_m:
                return BranchVerdict(False, name, depth, solutions, sphere)
        return BranchVerdict(True)

    def poses_depth_m(
        self,
        kin: Kinematics,
        fruit: FruitShape,
        poses: list[tuple[str, ToolPoses]],
        fruit_ids: frozenset[int] = frozenset(),
    ) -> float:
        """How deep the clearest IK solution's tools go into the spheres at the deepest of
        ``poses`` (0: clear of them; poses out of reach are not measured), m: what ``check``
        compares with ``depth_m``."""
        return max(
            (d for _n, d, _k, _s in self._clearest(kin, fruit, poses, fruit_ids)), default=0.0
        )

    def _clearest(
        self,
        kin: Kinematics,
        fruit: FruitShape,
        poses: list[tuple[str, ToolPoses]],
        fruit_ids: frozenset[int],
    ) -> Iterator[tuple[str, float, int, str]]:
        """Per pose in reach, in order: its name, how deep the tools of its clearest IK
        solution go into the spheres in the way (m), how many solutions, and the sphere they go
        deepest into. Nothing when no sphere is in the way."""
        spheres = self.in_the_way(fruit, fruit_ids)
        if not spheres:
            return
        self.space.set_obstacles(Obstacles(spheres=spheres))
        for name, pose in poses:
            sols = kin.solutions(pose)
            if not sols:
                continue  # out of reach: the IK check says so
            depth, sphere = min(self._deepest(s.q_rad, spheres) for s in sols)
            yield name, depth, len(sols), sphere

    def tool_depth_m(self, q_rad: np.ndarray) -> float:
        """How deep the deepest tool body goes into the spheres at ``q_rad`` (0: clear), m."""
        return self._deepest(q_rad, ())[0]

    def _deepest(self, q_rad: np.ndarray, spheres: tuple[SphereObstacle, ...]) -> tuple[float, str]:
        """The depth of ``tool_depth_m`` and the name of the sphere of ``spheres`` (those set)
        whose surface lies nearest the deepest pair's obstacle point ("" if clear or none)."""
        space = self.space
        space.robot.set_q(q_rad)
        rep = space.engine.compute(space.obstacles, {"branch": 0.0})
        pairs = [p for p in rep.pairs if p.kind == "branch" and p.joint1 in self.tool_joints]
        deepest = max(pairs, key=lambda p: -p.distance_m, default=None)
        if deepest is None or deepest.distance_m >= 0.0:
            return 0.0, ""
        if not spheres:
            return -deepest.distance_m, ""
        centres = np.array([s.center_world_m for s in spheres])
        radii = np.array([s.radius_m for s in spheres])
        gap_m = np.abs(np.linalg.norm(centres - deepest.p2_world_m, axis=1) - radii)
        return -deepest.distance_m, spheres[int(np.argmin(gap_m))].name
