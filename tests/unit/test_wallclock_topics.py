"""Topics that carry wall-clock diagnostics (Topic.deterministic False) are reported as not
compared by resim and by the contract kit's determinism check, never counted as different."""

from __future__ import annotations

from pathlib import Path

from schemas import TOPICS, ControllerDiagnostics, DemoAnswer
from services.recorder.writer import RunWriter
from services.replay.player import PlayStats, Produced
from services.replay.resim import ResimReport, _diff
from tests.unit.test_schemas import header


def diag(seq: int, cycle_ms: float) -> bytes:
    msg = ControllerDiagnostics(
        header=header(seq=seq, stamp_ns=10 * seq, source="controller"),
        cycle_ms=cycle_ms,
        distance_ms=0.1,
        damper_ms=0.0,
        solve_ms=0.05,
        pairs_checked=78,
        obstacles_near=0,
        obstacles_total=0,
        rejected_targets=0,
        rejected_scenes=0,
        rejected_joint_states=0,
        fallbacks=0,
        watchdog_stops=0,
    )
    return TOPICS["diag/controller"].codec.encode(msg)


def answer(seq: int, result: float) -> bytes:
    msg = DemoAnswer(header=header(seq=seq, source="w"), tick=seq, result=result, worker_state=1)
    return TOPICS["demo/answer"].codec.encode(msg)


class FakeCollector:
    def __init__(self, produced: dict[str, dict[int, bytes]]) -> None:
        self.produced = {t: Produced(by_seq=dict(p)) for t, p in produced.items()}


def record(path: Path, items: list[tuple[str, bytes]]) -> None:
    with open(path, "wb") as f:
        w = RunWriter(f)
        for i, (topic, payload) in enumerate(items):
            assert w.write(topic, payload, "application/json", 1000 + i) == "ok"
        w.finish()


def test_the_diagnostics_topic_is_flagged_and_the_others_are_not() -> None:
    flagged = sorted(k for k, t in TOPICS.items() if not t.deterministic)
    assert flagged == ["diag/controller"]


def test_resim_does_not_count_wall_clock_topics_as_different(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    record(
        path,
        [("diag/controller", diag(i, 0.5 + i)) for i in range(3)]
        + [("demo/answer", answer(i, 0.25)) for i in range(3)],
    )
    produced = {
        "diag/controller": {i: diag(i, 9.0) for i in range(3)},  # other timings: expected
        "demo/answer": {i: answer(i, 0.25) for i in range(3)},
    }
    diffs = {
        d.topic: d for d in _diff(path, ["demo/answer", "diag/controller"], FakeCollector(produced))
    }  # type: ignore[arg-type]
    d = diffs["diag/controller"]
    assert (d.compared, d.not_compared, d.different, d.identical) == (False, 3, 0, 0)
    assert d.verdict == "not compared (wall-clock diagnostics)"
    assert diffs["demo/answer"].identical == 3
    report = ResimReport(str(path), ["x"], list(diffs.values()), PlayStats())
    assert report.ok and report.identical_ratio == 1.0
    assert report.to_json()["topics"][1]["verdict"] == "not compared (wall-clock diagnostics)"


def test_resim_still_fails_on_a_different_deterministic_topic(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    record(path, [("demo/answer", answer(i, 0.25)) for i in range(3)])
    produced = {"demo/answer": {0: answer(0, 0.25), 1: answer(1, 0.5), 2: answer(2, 0.25)}}
    (d,) = _diff(path, ["demo/answer"], FakeCollector(produced))  # type: ignore[arg-type]
    assert (d.identical, d.different, d.first_difference_seq) == (2, 1, 1)
    assert not ResimReport(str(path), ["x"], [d], PlayStats()).ok
