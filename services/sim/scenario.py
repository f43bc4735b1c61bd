"""Scenario files (deploy/scenarios/*.yaml): the tree, the fruit and the timed dynamic events.

Validated by pydantic with ``extra="forbid"``: an unknown field or an impossible value (a
negative radius, a fruit inside the trunk, an event naming a fruit that does not exist) is
refused with the field named (ScenarioError).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from services.runtime.settings import format_validation_error

SCENARIO_DIR = Path(__file__).resolve().parents[2] / "deploy" / "scenarios"

Vec3 = tuple[float, float, float]
LeafCover = Literal["none", "light", "heavy"]


class _Strict(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


class TreeSpec(_Strict):
    """The tree: a vertical trunk, branches to every fruit plus extra ones, leaf clusters."""

    trunk_xy_world_m: tuple[float, float] = Field(
        default=(1.15, 0.0), description="Trunk axis on the ground (x, y), world, m."
    )
    trunk_radius_m: float = Field(default=0.06, gt=0.0, le=0.5, description="Trunk radius, m.")
    trunk_height_m: float = Field(default=1.9, gt=0.3, le=6.0, description="Trunk height, m.")
    extra_branches: int = Field(default=8, ge=0, le=60, description="Branches without fruit.")
    leaf_clusters: int = Field(default=40, ge=0, le=400, description="Random leaf clusters.")
    leaves_per_cluster: int = Field(default=16, ge=1, le=80, description="Leaves per cluster.")
    leaf_length_m: float = Field(default=0.07, gt=0.0, le=0.3, description="Leaf length, m.")
    crown_center_world_m: Vec3 = Field(
        default=(0.95, 0.0, 1.45), description="Centre of the crown (leaf clusters), world, m."
    )
    crown_radii_m: Vec3 = Field(
        default=(0.45, 0.6, 0.45), description="Semi-axes of the crown ellipsoid, m."
    )


class FruitSpec(_Strict):
    """One orange: an ellipsoid with a circular horizontal section, hanging by a peduncle."""

    position_world_m: Vec3 = Field(description="Centre of the fruit, world frame, m.")
    radius_m: float = Field(default=0.04, gt=0.0, le=0.1, description="Horizontal semi-axis, m.")
    height_ratio: float = Field(
        default=0.94, ge=0.6, le=1.4, description="Vertical / horizontal semi-axis."
    )
    peduncle_length_m: float = Field(default=0.035, gt=0.0, le=0.1, description="Stem, m.")
    leaf_cover: LeafCover = Field(
        default="light", description="Leaves in front: none, light (a few) or heavy."
    )


class RandomFruits(_Strict):
    """Fruit drawn at random (seeded) in the camera's view, 0.4–0.9 m deep by default."""

    count: int = Field(ge=1, le=60, description="How many fruit.")
    depth_range_m: tuple[float, float] = Field(default=(0.4, 0.9), description="Camera z, m.")
    radius_range_m: tuple[float, float] = Field(default=(0.03, 0.05), description="Radii, m.")
    heavy_cover_share: float = Field(default=0.15, ge=0, le=1, description="Heavily hidden.")
    no_cover_share: float = Field(default=0.3, ge=0, le=1, description="Leaf-free in front.")

    @model_validator(mode="after")
    def _ranges(self) -> RandomFruits:
        lo, hi = self.depth_range_m
        if not 0.1 <= lo <= hi <= 3.0:
            raise ValueError("depth_range_m must satisfy 0.1 <= low <= high <= 3.0")
        rlo, rhi = self.radius_range_m
        if not 0.0 < rlo <= rhi <= 0.1:
            raise ValueError("radius_range_m must satisfy 0 < low <= high <= 0.1")
        return self


class _Event(_Strict):
    start_s: float = Field(ge=0.0, description="When it starts, sim time, s.")
    duration_s: float = Field(gt=0.0, le=600.0, description="How long it lasts, s.")


class HandSweep(_Event):
    """A hand sweeps across the view, in front of a fruit (or along an explicit path)."""

    kind: Literal["hand_sweep"]
    fruit: int | None = Field(default=None, ge=0, description="Fruit to pass in front of.")
    distance_before_m: float = Field(default=0.12, gt=0.02, le=1.0, description="In front, m.")
    span_m: float = Field(default=0.36, gt=0.0, le=2.0, description="Sweep length, m.")
    from_world_m: Vec3 | None = Field(default=None, description="Path start, world, m.")
    to_world_m: Vec3 | None = Field(default=None, description="Path end, world, m.")

    @model_validator(mode="after")
    def _path(self) -> HandSweep:
        if self.fruit is None and (self.from_world_m is None or self.to_world_m is None):
            raise ValueError("give either fruit or both from_world_m and to_world_m")
        return self


class MoveFruit(_Event):
    """A hand moves an attached fruit by an offset (the fruit stays where it is left)."""

    kind: Literal["move_fruit"]
    fruit: int = Field(ge=0, description="Fruit index.")
    offset_world_m: Vec3 = Field(description="Displacement, world, m.")

    @model_validator(mode="after")
    def _offset(self) -> MoveFruit:
        if math.dist(self.offset_world_m, (0, 0, 0)) > 0.4:
            raise ValueError("offset_world_m longer than 0.4 m: a hand does not pull that far")
        return self


class SwayLeaves(_Event):
    """Leaves near a point (or a fruit) sway like in wind."""

    kind: Literal["sway_leaves"]
    fruit: int | None = Field(default=None, ge=0, description="Sway the leaves around it.")
    center_world_m: Vec3 | None = Field(default=None, description="Or around this point.")
    radius_m: float = Field(default=0.25, gt=0.0, le=3.0, description="Leaves within, m.")
    amplitude_m: float = Field(default=0.02, gt=0.0, le=0.15, description="Sway amplitude, m.")
    frequency_hz: float = Field(default=0.8, gt=0.0, le=5.0, description="Sway frequency, Hz.")

    @model_validator(mode="after")
    def _where(self) -> SwayLeaves:
        if (self.fruit is None) == (self.center_world_m is None):
            raise ValueError("give exactly one of fruit and center_world_m")
        return self


Event = Annotated[HandSweep | MoveFruit | SwayLeaves, Field(discriminator="kind")]


class Scenario(_Strict):
    """A whole scenario file."""

    name: str = Field(min_length=1, description="Scenario name.")
    description: str = Field(default="", description="What it shows.")
    seed: int = Field(default=0, ge=0, description="Seed of the tree, colours and noise.")
    environment: Literal["lab", "orchard"] = Field(default="lab", description="Background.")
    tree: TreeSpec = Field(default_factory=TreeSpec, description="The tree.")
    fruits: tuple[FruitSpec, ...] = Field(default=(), description="Fruit at given places.")
    random_fruits: RandomFruits | None = Field(default=None, description="Or fruit at random.")
    events: tuple[Event, ...] = Field(default=(), description="Timed dynamic events.")

    @model_validator(mode="after")
    def _consistent(self) -> Scenario:
        if not self.fruits and self.random_fruits is None:
            raise ValueError("no fruit: give fruits or random_fruits")
        check_fruit_places(self.tree, self.fruits, "fruits")
        n = len(self.fruits) + (self.random_fruits.count if self.random_fruits else 0)
        for i, ev in enumerate(self.events):
            f = getattr(ev, "fruit", None)
            if f is not None and f >= n:
                raise ValueError(f"events.{i}.fruit: no fruit {f} (the scenario has {n})")
        return self


def check_fruit_places(tree: TreeSpec, fruits: tuple[FruitSpec, ...], where: str) -> None:
    """Refuse fruit inside the trunk, under the ground or overlapping one another."""
    tx, ty = tree.trunk_xy_world_m
    for i, f in enumerate(fruits):
        x, y, z = f.position_world_m
        v = f.radius_m * f.height_ratio
        if math.hypot(x - tx, y - ty) < tree.trunk_radius_m + f.radius_m:
            raise ValueError(f"{where}.{i}.position_world_m: fruit {i} is inside the trunk")
        if z - v < 0.05:
            raise ValueError(f"{where}.{i}.position_world_m: fruit {i} touches the ground")
        if z + v + f.peduncle_length_m > tree.trunk_height_m + 0.5:
            raise ValueError(f"{where}.{i}.position_world_m: fruit {i} hangs above the tree")
        for j, g in enumerate(fruits[:i]):
            if math.dist(f.position_world_m, g.position_world_m) < f.radius_m + g.radius_m:
                raise ValueError(f"{where}.{i}.position_world_m: fruit {i} overlaps fruit {j}")


class ScenarioError(ValueError):
    """A scenario that cannot be used; the message names the file and the field."""


def scenario_path(name_or_path: str) -> Path:
    """A scenario name (deploy/scenarios/<name>.yaml) or a path to a YAML file."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml"):
        return p
    return SCENARIO_DIR / f"{name_or_path}.yaml"


def load_scenario(name_or_path: str) -> Scenario:
    path = scenario_path(name_or_path)
    try:
        raw = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        known = ", ".join(sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml")))
        raise ScenarioError(f"scenario not found: {path} (known: {known})") from None
    except yaml.YAMLError as exc:
        raise ScenarioError(f"{path}: not valid YAML: {exc}") from None
    return parse_scenario(raw, str(path))


def parse_scenario(raw: object, where: str = "scenario") -> Scenario:
    try:
        return Scenario.model_validate(raw)
    except ValidationError as exc:
        raise ScenarioError(format_validation_error(exc, f"scenario {where}")) from None
