"""Occupied space the arms felt: the contacts of the joint states (``JointState.contacts``, the
LWR4's joint-torque observer), kept as sphere obstacles beside the branches the camera sees.

What the camera cannot see the arms can still touch: a fruit behind leaves that the detector
never finds, or a branch hidden by fruit, is met on approach after approach (session 41, orchard,
14 seeds: about 60 % of the contacts touched a body the robot had already touched in that run;
seed 8's hidden fruit 14 was touched 21 times by every link of both arms). A felt point is
where the link met the thing, on its surface, so a small sphere there is the part of it known.

Each contact point is binned in a world-frame voxel grid (``voxel_m``); a voxel's obstacle is a
sphere of ``sphere_radius_m`` at the mean of the points felt in it. The fruit being harvested is
touched on purpose (the shears at its peduncle, the dish under it): points inside its working
space are not kept. A voxel is forgotten when the fruit it lay on is harvested (its place is
free) and, like the camera's voxels, it is split by the keep-out round the selected fruit into
obstacles and near spheres (``obstacles`` / ``within``).

A felt place is part of a fruit, and so not in that fruit's way, when it lies on the fruit as
the scene estimates it (``fruits``: the arm bumped a neighbour), or when it was felt only while
the planner worked on that fruit (its own branch, met by a stalled approach, which the dampers
steer round on the retry). Its sphere carries those fruit (``SphereObstacle.own_fruit_ids``)
and the planner's branch check does not refuse them for it (orchard seed 7, session 41: fruit
were refused for what was felt on their own attempt or on their own skin, 2 of 9 harvested
against 7 of 9 without the felt spheres)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from schemas.robot import SensedContact
from schemas.scene import SphereObstacle
from services.robot.clearance import Capsule, axis_distances_m, voxel_key
from services.scene.occupancy import keep_out_spheres

PREFIX = "touched_"  # the names of its spheres: the planner tells them from branches
FruitSpheres = tuple[np.ndarray, np.ndarray, np.ndarray]  # fruit IDs (N,), centres (N, 3), radii


@dataclass(frozen=True)
class TouchedParams:
    voxel_m: float = 0.03
    sphere_radius_m: float = 0.035
    max_obstacles: int = 64


@dataclass
class _Felt:
    sum_m: np.ndarray
    n: int
    last_ns: int
    fruit_id: int | None  # the fruit worked on every time it was felt (None: several, or none)

    @property
    def center_m(self) -> np.ndarray:
        return self.sum_m / self.n


class TouchedSpace:
    """The voxels felt so far (see the module)."""

    def __init__(self, p: TouchedParams) -> None:
        self.p = p
        self.voxels: dict[tuple[int, int, int], _Felt] = {}

    def feel(
        self,
        contacts: Iterable[SensedContact],
        stamp_ns: int,
        ignore: Sequence[Capsule] = (),
        fruit_id: int | None = None,
    ) -> int:
        """Keep the points of ``contacts`` outside the ``ignore`` capsules (the selected fruit's
        working space), felt while working on ``fruit_id`` (None: no fruit); returns how many
        were kept. A point too far out to bin is left out."""
        kept = 0
        radii = np.array([r for _a, _b, r in ignore])
        for c in contacts:
            p = np.asarray(c.point_world_m, dtype=float)
            if ignore and bool(np.any(axis_distances_m(p, ignore) < radii)):
                continue
            key = voxel_key(p, self.p.voxel_m)
            if key is None:
                continue
            v = self.voxels.get(key)
            if v is None:
                self.voxels[key] = _Felt(p.copy(), 1, stamp_ns, fruit_id)
            else:
                v.sum_m += p
                v.n += 1
                v.last_ns = stamp_ns
                if v.fruit_id != fruit_id:
                    v.fruit_id = None
            kept += 1
        return kept

    def forget_within(self, centre_m: np.ndarray, radius_m: float) -> int:
        """Forget the voxels whose point mean lies within ``radius_m`` of ``centre_m`` (a fruit
        harvested there: what was felt on it is gone); returns how many."""
        gone = [
            k
            for k, v in self.voxels.items()
            if float(np.linalg.norm(v.center_m - centre_m)) <= radius_m
        ]
        for k in gone:
            del self.voxels[k]
        return len(gone)

    def obstacles(
        self,
        keep_out: Sequence[Capsule] = (),
        inside_cylinder: tuple[np.ndarray, float] | None = None,
        fruits: FruitSpheres | None = None,
    ) -> tuple[SphereObstacle, ...]:
        """The spheres outside the keep-out and the trunk cylinder (OccupancyGrid.obstacles);
        ``fruits`` (IDs, centres, radii: m) are the fruit estimates a place may lie on."""
        return self._spheres("occupied", False, (keep_out, inside_cylinder), fruits)

    def within(
        self,
        keep_out: Sequence[Capsule],
        inside_cylinder: tuple[np.ndarray, float] | None = None,
        fruits: FruitSpheres | None = None,
    ) -> tuple[SphereObstacle, ...]:
        """The spheres the keep-out leaves out of ``obstacles`` (OccupancyGrid.within)."""
        return self._spheres("near", True, (keep_out, inside_cylinder), fruits)

    def _spheres(
        self,
        name: str,
        in_keep_out: bool,
        regions: tuple[Sequence[Capsule], tuple[np.ndarray, float] | None],
        fruits: FruitSpheres | None,
    ) -> tuple[SphereObstacle, ...]:
        # the most recently felt first, then by voxel: deterministic
        voxels = [(-v.last_ns, key, v.center_m) for key, v in self.voxels.items()]
        test = (in_keep_out, *regions)
        owners = {key: self._owners(v, fruits) for key, v in self.voxels.items()}
        return keep_out_spheres(
            voxels, f"{PREFIX}{name}", self.p.sphere_radius_m, test, self.p.max_obstacles, owners
        )

    @staticmethod
    def _owners(v: _Felt, fruits: FruitSpheres | None) -> tuple[int, ...]:
        """The fruit ``v`` is part of: the one it was felt on only, those it lies on."""
        ids = set() if v.fruit_id is None else {v.fruit_id}
        if fruits is not None and len(fruits[0]):
            ids_on, centres_m, radii_m = fruits
            on = np.linalg.norm(centres_m - v.center_m, axis=1) <= radii_m
            ids.update(int(i) for i in np.asarray(ids_on)[on])
        return tuple(sorted(ids))
