"""Sequences for `harvest eval tracker`: frames with per-fruit truth and an occlusion flag.

A scenario yields, per camera frame, the RGB-D frame, the fruit truth (ID, visible box,
visible fraction) and whether an occlusion event is active. The scripted 2D scenes
(services/testkit/scene2d.py) are available everywhere; the pybullet simulator's scenarios
plug in through the same ``Sequence`` shape when it is present.

A fruit counts as *visible* in a frame when its visible fraction is at least
``VISIBLE_MIN`` (0.5) and it has a box: a fruit less than half visible is not expected to be
detected, so neither a missing detection nor a missing ID is held against the tracker there.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from schemas.camera import RgbdFrame

VISIBLE_MIN = 0.5


@dataclass(frozen=True)
class TruthFrame:
    frame: RgbdFrame
    fruits: tuple[tuple[int, tuple[float, float, float, float], float], ...]  # id, box, fraction
    occluded: bool


Sequence = Callable[[], Iterator[TruthFrame]]

SCRIPTED: dict[str, dict[str, Any]] = {
    "scripted-sweep": {"sweep": (30, 80)},
    "scripted-moved": {"sweep": None, "move": (40, 70)},
    "scripted-leaves": {"sweep": None, "sway": True},
    "scripted-occlusion-suite": {"sweep": (30, 80), "move": (100, 130), "sway": True},
}
SCRIPTED_FRAMES = 150


def scripted(name: str, seed: int, n_fruit: int = 8, n_frames: int = SCRIPTED_FRAMES) -> Sequence:
    from services.testkit.scene2d import Scene2D

    scene = Scene2D(seed=seed, n_fruit=n_fruit, **SCRIPTED[name])

    def frames() -> Iterator[TruthFrame]:
        for k in range(n_frames):
            f = scene.frame(k)
            fruits = tuple(
                (v.fruit_id, v.box_xyxy_px, v.visible_fraction)
                for v in f.fruits
                if v.box_xyxy_px is not None
            )
            partial = any(0.0 < v.visible_fraction < 0.9 for v in f.fruits)
            yield TruthFrame(f.frame, fruits, f.occluder_active or partial)

    return frames


def scenario_names() -> list[str]:
    return sorted(SCRIPTED)


def make_sequence(name: str, seed: int, n_fruit: int = 8) -> Sequence:
    """The sequence of scenario ``name`` with ``seed``; KeyError naming the known ones."""
    if name in SCRIPTED:
        return scripted(name, seed, n_fruit)
    raise KeyError(f"unknown scenario {name!r}; known: {', '.join(scenario_names())}")
