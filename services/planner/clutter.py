"""Which neighbours stand in the tools' way to a fruit: the reachability check's second half
(the IK says the arms can take the poses; this says the poses are free).

The controller keeps every robot body at least the fruit damper's d_s from every fruit it must
avoid, so a neighbour where the dish must go (under the target, or on its way from the pre-pose)
or along the cutter's approach line holds the tools back for good, and the harvest ends as
"no progress" seconds later. Checked before committing, on the scene's estimates:

* the dish: a vertical cylinder (radius + hull, floor to rim top) at the harvest pose, swept
  from the pre-pose (sampled along the straight move the controller makes);
* the cutter: capsules from its tip back along the approach line (the tool shaft, then the
  wrist), swept the same way.

A neighbour is a sphere of its largest semi-axis. The check is conservative on purpose (it uses
the damper's d_s and the hull): a fruit it calls blocked would be a stuck harvest.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

import numpy as np

from services.planner.poses import FruitShape, PoseSettings, harvest_pose, pre_pose
from services.robot.model import LWR_LINK_RADIUS_M, TOOLS

DISH_RADIUS_M = TOOLS.basket_radius_m + 0.005  # the controller's basket hull
DISH_HEIGHT_M = TOOLS.basket_rim_height_m + TOOLS.basket_floor_m
SHAFT_M = TOOLS.cutter_shaft_length_m + TOOLS.flange_gap_m  # tip → flange
WRIST_M = 0.08  # the last link behind the flange
SWEEP_SAMPLES = 7
SAME_FRUIT_SHARE = 0.8  # centres closer than this share of d_h + d_h: one fruit, two tracks


def same_fruit(a: FruitShape, b: FruitShape) -> bool:
    """Two estimates overlapping more than two fruit can: one fruit seen as two tracks."""
    d_m = float(np.linalg.norm(a.centre_world_m - b.centre_world_m))
    return d_m < SAME_FRUIT_SHARE * (a.d_h_m + b.d_h_m)


def _to_cylinder_m(p: np.ndarray, floor: np.ndarray) -> float:
    """Distance from point p to the dish cylinder standing on ``floor`` (0 inside)."""
    d = p - floor
    dx = max(float(np.hypot(d[0], d[1])) - DISH_RADIUS_M, 0.0)
    dz = max(-float(d[2]), float(d[2]) - DISH_HEIGHT_M, 0.0)
    return float(np.hypot(dx, dz))


def _to_segment_m(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = float(np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


def intrusions_m(
    target: FruitShape, others: Sequence[FruitShape], p: PoseSettings, clearance_m: float
) -> list[float]:
    """How far each of ``others`` reaches into where the tools go for ``target`` (the deepest
    overlap of its sphere, grown by ``clearance_m``, with the dish or the cutter over the sweep),
    m; 0 or less: clear of them. A second track of the target itself reads -inf."""
    h, q = harvest_pose(target, p), pre_pose(target, p)
    down = np.array([0.0, 0.0, 1.0])
    axis = p.camera_axis_world
    out = []
    for f in others:
        c = f.centre_world_m
        if same_fruit(f, target):
            out.append(-np.inf)  # a second track of the target itself
            continue
        r = max(f.d_h_m, f.d_v_m) + clearance_m
        deepest = -np.inf
        for t in np.linspace(0.0, 1.0, SWEEP_SAMPLES):
            tip = q.tip_world_m + t * (h.tip_world_m - q.tip_world_m)
            below = q.basket_below_m + t * (h.basket_below_m - q.basket_below_m)
            back = q.basket_back_m + t * (h.basket_back_m - q.basket_back_m)
            flange = tip - SHAFT_M * axis
            wrist = flange - WRIST_M * axis
            deepest = max(
                deepest,
                r - _to_cylinder_m(c, tip - below * down - back * axis),
                r + TOOLS.cutter_shaft_radius_m - _to_segment_m(c, tip, flange),
                r + LWR_LINK_RADIUS_M[-1] - _to_segment_m(c, flange, wrist),
            )
        out.append(float(deepest))
    return out


def blockers(
    target: FruitShape, others: Sequence[FruitShape], p: PoseSettings, clearance_m: float
) -> list[int]:
    """Indices of ``others`` closer than ``clearance_m`` to where the tools go for ``target``."""
    return [i for i, d in enumerate(intrusions_m(target, others, p, clearance_m)) if d > 0]


def clearable(blocked_by: Mapping[int, Collection[int]]) -> set[int]:
    """The keys that can all be harvested in some order that takes every blocker first: the
    fixpoint from the free ones. A blocker that is not a key stays (it is never cleared); keys
    blocking each other in a cycle are never cleared either."""
    done: set[int] = set()
    changed = True
    while changed:
        changed = False
        for k in sorted(blocked_by):
            if k not in done and set(blocked_by[k]) <= done:
                done.add(k)
                changed = True
    return done
