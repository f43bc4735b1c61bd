"""The whole harvest as real processes (sim → detector → tracker → scene → planner → controller
→ sim) under the supervisor, in lock-step, recorded: a one-fruit tree is harvested; two runs of
the same scenario and seed are byte-identical on every topic; resim of every service on the
recording reproduces every output (the control loop alone, and all five services at once).
(Slow: ~1 min per run on 2 cores.)"""

from __future__ import annotations

from pathlib import Path

import pytest

from schemas.topics import TOPICS
from services.registry import service_def
from services.replay.resim import ResimReport, resim
from tests.harvest_helpers import lab_scenario
from tests.helpers import harvest, payloads_by_topic, short_dir

pytestmark = pytest.mark.integration

FRUIT = {"position_world_m": [0.6, -0.12, 1.32], "radius_m": 0.04, "leaf_cover": "none"}


def _run(d: Path, sc: Path, run_id: str) -> Path:
    stack = d / f"{run_id}.yaml"
    stack.write_text(f"""
name: test-harvest-e2e
mode: lockstep
master: sim
recording: {{enabled: true, dir: {d / "rec"}}}
services:
  sim:
    settings: {{scenario: {sc}, seed: 5, duration_s: 40.0}}
  detector: {{}}
  tracker: {{}}
  scene: {{}}
  controller: {{}}
  planner:
    main: true
    settings: {{finish_after_s: 0.5}}
""")
    r = harvest(
        "run",
        "--stack",
        str(stack),
        "--run-id",
        run_id,
        "--listen",
        f"unixsock-stream/{d}/{run_id}.sock",
        timeout=600,
    )
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "stopped with exit code" not in r.stdout
    return d / "rec" / f"{run_id}.mcap"


@pytest.fixture(scope="module")
def runs() -> tuple[Path, Path]:
    d = short_dir()
    sc = lab_scenario(d, [FRUIT])
    return _run(d, sc, "a"), _run(d, sc, "b")


def test_the_fruit_is_harvested_by_the_whole_chain(runs: tuple[Path, Path]) -> None:
    rec = payloads_by_topic(runs[0])
    (summary,) = [TOPICS["harvest/summary"].codec.decode(p) for _, p in rec["harvest/summary"]]
    assert summary.detected == 1 and summary.harvested == 1, summary
    assert summary.collisions == 0
    for topic in ("perception/detections", "perception/tracks", "scene/state"):
        assert len(rec[topic]) == len(rec["camera/rgbd"]), topic  # one answer per frame


def test_two_runs_are_byte_identical_on_every_topic(runs: tuple[Path, Path]) -> None:
    a, b = (payloads_by_topic(p) for p in runs)
    deterministic = {t for t in a if TOPICS.get(t) is not None and TOPICS[t].deterministic}
    assert deterministic >= {"camera/rgbd", "scene/state", "plan/target", "robot/command"}
    for topic in sorted(deterministic):
        pa, pb = [p for _, p in a[topic]], [p for _, p in b.get(topic, [])]
        assert len(pa) == len(pb), f"{topic}: {len(pa)} vs {len(pb)} messages"
        diff = next((i for i, (x, y) in enumerate(zip(pa, pb, strict=True)) if x != y), None)
        assert diff is None, f"{topic}: message {diff} differs"


def _failure(report: ResimReport) -> str:
    """The topics that failed and the player's counts, in full (pytest shortens a dict)."""
    bad = [t for t in report.topics if t.compared and (t.different or t.missing or t.extra)]
    return f"{report.recording}: {bad}; {report.play}; {report.warnings}"


@pytest.mark.parametrize(
    "group",
    [
        ("controller", "planner"),
        ("detector", "tracker", "scene", "controller", "planner"),
    ],
    ids=["control", "all"],
)
def test_resim_of_every_service_is_identical(
    runs: tuple[Path, Path], group: tuple[str, ...]
) -> None:
    # The control loop on the recorded scene states, and all five at once: the perception chain
    # on the recorded frames (its own group before, now a part of this one), the controller and
    # planner on the resimmed scene's states (each input waits for its causal predecessors).
    report = resim(runs[0], list(group), timeout_s=60.0)
    assert report.ok and report.identical_ratio == 1.0, _failure(report)
    by = {t.topic: t for t in report.topics}
    for d in group:
        for topic in service_def(d).spec.outputs:
            if topic in by and TOPICS[topic].deterministic:
                assert by[topic].identical > 0 and by[topic].different == 0, (d, by[topic])
