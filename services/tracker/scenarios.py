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


SIM_TAIL_S = 1.0
"""A sim scenario runs until its last event ends plus this, so the tracker is scored on the
fruit after the last occlusion too."""


def sim_sequence(name: str, seed: int, duration_s: float | None = None) -> Sequence:
    """The pybullet simulator's scenario ``name``, run in process (its core, no bus, no
    controller: the robot holds still): every camera/rgbd frame is paired with the sim/truth
    of the same frame seq. An occlusion is active when the sim says so (``occluder_active``:
    the hand occluder's pixels are in the image)."""
    from services.registry import service_def
    from services.runtime.settings import load_settings
    from services.sim.scenario import ScenarioError, load_scenario

    try:
        scenario = load_scenario(name)
    except ScenarioError as exc:
        raise KeyError(f"{exc}; scripted scenarios: {', '.join(sorted(SCRIPTED))}") from None
    if duration_s is None:
        ends = [e.start_s + e.duration_s for e in scenario.events]
        duration_s = max(ends, default=10.0) + SIM_TAIL_S
    sd = service_def("sim")
    settings = load_settings(
        sd.settings, {"scenario": name, "seed": seed, "duration_s": duration_s}, service="sim"
    )
    assert sd.make_core is not None

    def frames() -> Iterator[TruthFrame]:
        core = sd.make_core(settings)  # type: ignore[misc]
        pending: dict[int, Any] = {}
        truths: dict[int, Any] = {}
        while not core.done():
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
                yield TruthFrame(frame, fruits, truth.occluder_active)
            core.advance()
        core.close()

    return frames


def scenario_names() -> list[str]:
    from services.sim.scenario import SCENARIO_DIR

    return sorted(SCRIPTED) + sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def make_sequence(
    name: str, seed: int, n_fruit: int = 8, duration_s: float | None = None
) -> Sequence:
    """The sequence of scenario ``name`` with ``seed``: a scripted one, or else the sim's."""
    if name in SCRIPTED:
        return scripted(name, seed, n_fruit)
    return sim_sequence(name, seed, duration_s)
