"""A contact reflex: the places the arms feel (``JointState.contacts``, the LWR4's joint-torque
observer) become damper spheres in the very tick that reports them.

The scene keeps felt places too (services/scene/touched.py), but they reach the controller only
with its next state, which answers the next camera frame's tracks (15 Hz: up to 8 control
ticks later). In session 42's orchard runs (20 seeds) 21 of 160 contacts were re-touches of a
body within 0.3 s of letting it go, and 42 contacts lasted over a second: the link pushed on
while the scene's state was on its way. A sphere at the felt point, on the link's surface, is
at a negative distance from the link: its damper asks the link to back off at once, and keeps
it off that place while the sphere is held (``hold_ns`` after it was last felt; by then the
scene's state carries the place).

The fruit the tools must touch is touched on purpose (the shears at its peduncle, the dish under
it): points in its inner working space (round it and up its twig, the scene's
``occupancy_inner_clearance_m`` / ``occupancy_inner_twig_m``) are not kept, as in the scene.
Points are binned in a world-frame voxel grid; a voxel's sphere stays at its first point, so the
obstacle set changes only when a voxel is added or let go."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from schemas.robot import SensedContact
from schemas.scene import SceneState
from services.robot.clearance import Capsule, axis_distances_m, inner_working_space, voxel_key


@dataclass(frozen=True)
class ReflexParams:
    radius_m: float = 0.01
    voxel_m: float = 0.02
    hold_ns: int = 500_000_000
    inner_clearance_m: float = 0.05
    inner_twig_m: float = 0.10
    max_spheres: int = 32


@dataclass
class _Voxel:
    center_m: np.ndarray
    last_ns: int


class ContactReflex:
    """The felt places held as spheres (see the module). Deterministic: time is the joint
    states' stamps."""

    def __init__(self, p: ReflexParams) -> None:
        self.p = p
        self.voxels: dict[tuple[int, int, int], _Voxel] = {}
        self.version = 0  # bumped whenever the set of spheres changes
        self.kept = 0  # points kept so far (a new voxel or a refreshed one)
        self.skipped_inner = 0  # points in the worked fruit's inner working space

    def feel(
        self, contacts: Iterable[SensedContact], stamp_ns: int, inner: Sequence[Capsule] = ()
    ) -> None:
        """Hold the points of ``contacts`` outside the ``inner`` capsules, then let go of the
        voxels not felt for ``hold_ns`` (and the oldest past ``max_spheres``)."""
        radii = np.array([r for _a, _b, r in inner])
        for c in contacts:
            p = np.asarray(c.point_world_m, dtype=float)
            if inner and bool(np.any(axis_distances_m(p, inner) < radii)):
                self.skipped_inner += 1
                continue
            key = voxel_key(p, self.p.voxel_m)
            if key is None:
                continue
            v = self.voxels.get(key)
            if v is None:
                self.voxels[key] = _Voxel(p.copy(), stamp_ns)
                self.version += 1
            else:
                v.last_ns = stamp_ns
            self.kept += 1
        self._expire(stamp_ns)

    def spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """Centres (K, 3) and radii (K,) of the spheres held, m, in voxel order."""
        keys = sorted(self.voxels)
        centres = np.array([self.voxels[k].center_m for k in keys], dtype=float).reshape(-1, 3)
        return centres, np.full(len(keys), self.p.radius_m)

    def _expire(self, now_ns: int) -> None:
        old = [k for k, v in self.voxels.items() if now_ns - v.last_ns > self.p.hold_ns]
        excess = len(self.voxels) - len(old) - self.p.max_spheres
        if excess > 0:  # the least recently felt go first (then by voxel: deterministic)
            gone = set(old)
            live = sorted((v.last_ns, k) for k, v in self.voxels.items() if k not in gone)
            old += [k for _t, k in live[:excess]]
        for k in old:
            del self.voxels[k]
        if old:
            self.version += 1


def inner_space(
    scene: SceneState | None, fruit_ids: Iterable[int], p: ReflexParams
) -> list[Capsule]:
    """The inner working space of each fruit of ``fruit_ids`` the scene estimates: a capsule
    from its centre up its twig, radius its vertical semi-axis plus ``inner_clearance_m`` (the
    scene's ``_inner_space``)."""
    if scene is None:
        return []
    wanted = set(fruit_ids)
    out: list[Capsule] = []
    for f in scene.fruits:
        if f.fruit_id not in wanted:
            continue
        centre = np.array(f.position_world_m, dtype=float)
        out.append(
            inner_working_space(centre, f.semi_axis_v_m, p.inner_clearance_m, p.inner_twig_m)
        )
    return out
