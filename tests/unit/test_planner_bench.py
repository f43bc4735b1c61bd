"""The harvest benchmark's machinery, with the truth scene standing in for the perception chain
(tests only): figures judged against the sim's truth, the planned order, argument checks."""

from __future__ import annotations

import statistics
from pathlib import Path

import pytest

from services.planner.bench import BenchConfig, BenchError, parse_seeds, run_harvest_bench
from services.runtime.inproc import InprocNode
from tests.harvest_helpers import TruthScene, lab_scenario
from tests.helpers import harvest
from tests.unit.test_planner_loop import FAR, A, B


def truth_chain() -> list[InprocNode]:
    return [InprocNode("scene", ("sim/truth", "harvest/events"), TruthScene())]


def test_bench_judges_a_run_against_the_truth(tmp_path: Path) -> None:
    sc = str(lab_scenario(tmp_path, [B, A, FAR]))
    cfg = BenchConfig(sc, [3], ("planned",), max_s=40, perception=truth_chain)
    lines: list[str] = []
    res = run_harvest_bench(cfg, lines.append)
    (run,) = res["runs"]
    assert (run["fruit"], run["reachable"], run["unreachable_true"]) == (3, 2, 1)
    assert (run["harvested"], run["harvested_reachable"], run["success_rate"]) == (2, 2, 1.0)
    assert (run["unreachable_reported"], run["unreachable_correct"]) == (1, 1)
    assert run["reachable_called_unreachable"] == 0 and run["collisions"] == 0
    assert 0 < run["max_velocity_ratio"] <= 1.0
    pol = res["policies"]["planned"]
    assert len(run["cycles_s"]) == 2
    assert pol["median_s_per_fruit"] == pytest.approx(statistics.median(run["cycles_s"]))
    assert pol["rtf"] > 0 and pol["unreachable_identified"] == 1.0
    assert run["summary"]["order"] == "planned" and lines and "planned seed 3" in lines[0]


def test_seed_ranges_and_bad_arguments() -> None:
    assert parse_seeds("0-3") == [0, 1, 2, 3] and parse_seeds("1,4") == [1, 4]
    with pytest.raises(BenchError):
        parse_seeds("5-3")
    r = harvest("bench", "harvest", "--seeds", "x", timeout=60)
    assert r.returncode == 2 and "--seeds" in r.stderr
