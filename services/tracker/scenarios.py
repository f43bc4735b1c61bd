"""Sequences for `harvest eval tracker`: frames with per-fruit truth and an occlusion flag.

A scenario yields, per camera frame, the RGB-D frame, the fruit truth (ID, visible box,
visible fraction) and whether an occlusion event is active. The scripted 2D scenes
(services/testkit/scene2d.py) are available everywhere; any other name is a scenario of the
pybullet simulator, run in process through its core (``sim_sequence``) when the sim service
is part of the build. Only attached fruit count (a cut or falling fruit leaves the truth).

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


def sim_sequence(name: str, seed: int, max_frames: int | None = None) -> Sequence:
    """The pybullet simulator's scenario ``name``, run in process (its core, no bus): every
    camera/rgbd frame is paired with the sim/truth of the same frame seq."""
    from services.registry import SERVICE_MODULES, service_def
    from services.runtime.settings import load_settings

    if "sim" not in SERVICE_MODULES:
        raise KeyError(
            f"unknown scenario {name!r}: the simulator is not in this build; scripted "
            f"scenarios: {', '.join(sorted(SCRIPTED))}"
        )
    sd = service_def("sim")
    settings = load_settings(sd.settings, {"scenario": name, "seed": seed}, service="sim")
    assert sd.make_core is not None

    def frames() -> Iterator[TruthFrame]:
        core = sd.make_core(settings)  # type: ignore[misc]
        pending: dict[int, Any] = {}
        truths: dict[int, Any] = {}
        n = 0
        while not core.done() and (max_frames is None or n < max_frames):
            for group in core.emit():
                for topic, msg in group:
                    if topic == "camera/rgbd":
                        pending[msg.header.seq] = msg
                    elif topic == "sim/truth":
                        truths[msg.frame_seq] = msg
            for seq in sorted(set(pending) & set(truths)):
                frame, truth = pending.pop(seq), truths.pop(seq)
                fruits = tuple(
                    (f.fruit_id, f.box_xyxy_px, f.visible_fraction)
                    for f in truth.fruits
                    if f.box_xyxy_px is not None and f.state == "attached"
                )
                n += 1
                yield TruthFrame(frame, fruits, truth.occluder_active)
            core.advance()

    return frames


def scenario_names() -> list[str]:
    return sorted(SCRIPTED)


def make_sequence(name: str, seed: int, n_fruit: int = 8) -> Sequence:
    """The sequence of scenario ``name`` with ``seed``: a scripted one, or else the sim's."""
    if name in SCRIPTED:
        return scripted(name, seed, n_fruit)
    return sim_sequence(name, seed)
