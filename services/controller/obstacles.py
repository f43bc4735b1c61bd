"""The obstacle set of the dampers, from scene/state: validated, with the fruit the tools may
touch (PlanTarget.ignore_fruit_ids) left out, as numpy arrays for the broad phase."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from schemas.scene import Obstacles


class ObstacleError(ValueError):
    """An obstacle set the dampers cannot trust (degenerate or absurd shapes)."""


_SERIALS = itertools.count()


@dataclass(frozen=True)
class ObstacleArrays:
    """World-frame obstacles: fruit ellipsoids (axis-aligned), vertical infinite cylinders and
    spheres of occupied space (branches)."""

    ellipsoid_centers_m: np.ndarray  # (N, 3)
    ellipsoid_semi_axes_m: np.ndarray  # (N, 3)
    ellipsoid_fruit_ids: tuple[int | None, ...]
    cylinder_points_m: np.ndarray  # (M, 3): a point on each axis
    cylinder_radii_m: np.ndarray  # (M,)
    sphere_centers_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (K, 3)
    sphere_radii_m: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (K,)
    # Never reused (unlike id()): what the distance engine's slots hold is keyed by it, and a
    # new set of arrays may be born where a freed one lived.
    serial: int = field(default_factory=lambda: next(_SERIALS), init=False, compare=False)

    @property
    def count(self) -> int:
        return (
            len(self.ellipsoid_centers_m) + len(self.cylinder_points_m) + len(self.sphere_radii_m)
        )

    @cached_property
    def ellipsoid_bound_m(self) -> np.ndarray:
        """(N,) radius of each ellipsoid's bounding sphere (its largest semi-axis), m."""
        if not len(self.ellipsoid_semi_axes_m):
            return np.zeros(0)
        return self.ellipsoid_semi_axes_m.max(axis=1)


EMPTY = ObstacleArrays(np.zeros((0, 3)), np.zeros((0, 3)), (), np.zeros((0, 3)), np.zeros(0))


def check_obstacles(obstacles: Obstacles, min_size_m: float, max_size_m: float) -> None:
    """Raise ObstacleError naming the first degenerate shape: a size that is not finite, below
    ``min_size_m`` (zero, negative or a point) or above ``max_size_m``; a centre not finite.

    The bus already refuses non-positive and NaN sizes (schema); this also guards cores fed
    in-process and the absurd-but-valid cases."""
    for c in obstacles.cylinders:
        _check_size(c.name, (c.radius_m,), min_size_m, max_size_m)
        _check_finite(c.name, c.axis_point_world_m)
    for e in obstacles.ellipsoids:
        _check_size(e.name, e.semi_axes_m, min_size_m, max_size_m)
        _check_finite(e.name, e.center_world_m)
    for sp in obstacles.spheres:
        _check_size(sp.name, (sp.radius_m,), min_size_m, max_size_m)
        _check_finite(sp.name, sp.center_world_m)


def _check_size(name: str, sizes: tuple[float, ...], lo: float, hi: float) -> None:
    for s in sizes:
        if not math.isfinite(s) or s < lo or s > hi:
            raise ObstacleError(f"obstacle {name!r}: size {s!r} m outside [{lo}, {hi}] m")


def _check_finite(name: str, v: tuple[float, ...]) -> None:
    if not all(math.isfinite(x) for x in v):
        raise ObstacleError(f"obstacle {name!r}: position {v!r} is not finite")


def obstacle_arrays(obstacles: Obstacles, ignore_fruit_ids: tuple[int, ...] = ()) -> ObstacleArrays:
    """Arrays of the obstacles the dampers guard: every cylinder and sphere, and every ellipsoid
    except the fruit in ``ignore_fruit_ids`` (the target while the tools must touch it)."""
    ignore = set(ignore_fruit_ids)
    ells = [e for e in obstacles.ellipsoids if e.fruit_id is None or e.fruit_id not in ignore]
    return ObstacleArrays(
        np.array([e.center_world_m for e in ells], dtype=float).reshape(-1, 3),
        np.array([e.semi_axes_m for e in ells], dtype=float).reshape(-1, 3),
        tuple(e.fruit_id for e in ells),
        np.array([c.axis_point_world_m for c in obstacles.cylinders], dtype=float).reshape(-1, 3),
        np.array([c.radius_m for c in obstacles.cylinders], dtype=float),
        np.array([sp.center_world_m for sp in obstacles.spheres], dtype=float).reshape(-1, 3),
        np.array([sp.radius_m for sp in obstacles.spheres], dtype=float),
    )


def with_spheres(
    arrays: ObstacleArrays, centres_m: np.ndarray, radii_m: np.ndarray
) -> ObstacleArrays:
    """``arrays`` with the spheres ``centres_m`` (K, 3) and ``radii_m`` (K,) after its own (a
    new set: a new serial)."""
    if not len(radii_m):
        return arrays
    return ObstacleArrays(
        arrays.ellipsoid_centers_m,
        arrays.ellipsoid_semi_axes_m,
        arrays.ellipsoid_fruit_ids,
        arrays.cylinder_points_m,
        arrays.cylinder_radii_m,
        np.vstack([arrays.sphere_centers_m, centres_m]),
        np.concatenate([arrays.sphere_radii_m, radii_m]),
    )
