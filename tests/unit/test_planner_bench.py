"""The harvest benchmark's machinery, with the truth scene standing in for the perception chain
(tests only): figures judged against the sim's truth, the planned order, argument checks."""

from __future__ import annotations

import statistics
from pathlib import Path

import pytest

from services.planner import bench
from services.planner.bench import (
    BenchConfig,
    BenchError,
    parse_seeds,
    parse_sets,
    run_harvest_bench,
)
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
    assert run["detected"] == 3
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


def test_the_eval_commands_parse_seeds_as_the_benchmarks_do() -> None:
    import argparse

    from services.cli.evaluate import parse_seeds as eval_seeds

    assert eval_seeds("0-2,7") == parse_seeds("0-2,7") == [0, 1, 2, 7]
    with pytest.raises(argparse.ArgumentTypeError, match="3 < 5"):
        eval_seeds("5-3")


def test_set_refuses_a_bad_key_naming_it() -> None:
    with pytest.raises(BenchError, match="occupancy_typo"):
        parse_sets(["scene.occupancy_typo=1"])
    with pytest.raises(BenchError, match="occupancy_voxel_m"):
        parse_sets(["scene.occupancy_voxel_m=not-a-number"])
    with pytest.raises(BenchError, match="nosuchservice"):
        parse_sets(["nosuchservice.x=1"])
    with pytest.raises(BenchError, match=r"SERVICE\.KEY=VALUE"):
        parse_sets(["occupancy=false"])
    r = harvest("bench", "harvest", "--set", "scene.occupancy_typo=1", timeout=60)
    assert r.returncode == 2 and "occupancy_typo" in r.stderr


def test_set_reaches_the_cores(monkeypatch: pytest.MonkeyPatch) -> None:
    sets = parse_sets(
        ["scene.occupancy=false", "controller.rel_gain_per_s=4", "planner.approach_distance_m=0.12"]
    )
    assert sets["scene"] == {"occupancy": False}
    seen: dict[str, object] = {}

    class Stop(Exception):
        pass

    def fake_run(sim_s, plan_s, max_s, perception, controller_settings):  # type: ignore[no-untyped-def]
        seen.update(plan=plan_s, ctrl=controller_settings, chain=perception())
        raise Stop

    monkeypatch.setattr(bench, "run_inproc", fake_run)
    with pytest.raises(Stop):
        run_harvest_bench(BenchConfig("paper-exp1", [11], ("nearest",), settings=sets))
    scene = next(n for n in seen["chain"] if n.name == "scene")  # type: ignore[attr-defined]
    assert scene.core.s.occupancy is False and scene.core.occupancy is None
    assert seen["ctrl"] == {"rel_gain_per_s": 4}
    assert seen["plan"]["approach_distance_m"] == 0.12 and seen["plan"]["order"] == "nearest"  # type: ignore[index]


def test_a_track_is_matched_to_the_fruit_where_it_hung() -> None:
    """A harvested fruit's track is last seen in the dish (no fruit there): it is still the
    fruit it was on; a tracker that re-uses the ID for another fruit later makes the ID mean
    that fruit from then on, and the fruit it was on before."""
    import numpy as np

    centres = {0: np.array([0.6, 0.0, 1.3]), 1: np.array([0.6, 0.2, 1.3])}
    got = bench.Collected()
    got.sightings = {
        7: [(10, (0.6, 0.01, 1.3)), (20, (0.45, 0.1, 1.0))],  # on fruit 0, then in the dish
        8: [(10, (0.6, 0.0, 1.3)), (30, (0.6, 0.19, 1.3))],  # fruit 0, the ID re-used on 1
        9: [(10, (0.3, 0.0, 0.9))],  # never near a fruit
    }
    assert bench._track_fruit(got, 7, centres) == 0  # last seen in the dish
    assert bench._track_fruit(got, 8, centres) == 1  # the last sighting wins when it matches
    assert bench._track_fruit(got, 8, centres, at_ns=12) == 0  # where it was at the time
    assert bench._track_fruit(got, 8, centres, at_ns=25) == 1
    assert bench._track_fruit(got, 9, centres) is None  # never near a fruit
    assert bench._track_fruit(got, 10, centres) is None  # never seen


def test_jobs_run_seeds_side_by_side_with_the_same_rows(tmp_path: Path) -> None:
    """--jobs 2: the seeds run in two processes; every figure but the wall time is the one a
    sequential run gives, in the same order."""
    sc = str(lab_scenario(tmp_path, [B, A, FAR]))
    cfgs = [
        BenchConfig(sc, [3, 4], ("nearest",), max_s=12, perception=truth_chain, jobs=j)
        for j in (1, 2)
    ]
    one, two = (run_harvest_bench(c) for c in cfgs)
    timing = ("wall_s", "rtf")
    strip = [
        [{k: v for k, v in r.items() if k not in timing} for r in res["runs"]] for res in (one, two)
    ]
    assert [r["seed"] for r in two["runs"]] == [3, 4]
    assert strip[0] == strip[1]
    assert one["runs"][0]["harvested"] >= 1  # the runs did something


def test_a_bad_events_out_path_stops_before_the_runs(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    r = harvest("bench", "harvest", "--seeds", "0", "--events-out", str(blocker / "ev"), timeout=60)
    assert r.returncode == 2 and "--events-out" in r.stderr
