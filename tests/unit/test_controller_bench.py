"""services/controller/bench.py: the benchmark's code paths on a tiny budget (the figures
themselves live in BENCHMARKS.md, never in assertions)."""

from __future__ import annotations

from services.controller import SERVICE
from services.controller.bench import (
    OBSTACLE_COUNTS,
    cycle_times,
    reach_run,
    reachable_targets,
    table,
)
from services.runtime.settings import load_settings

SETTINGS = load_settings(SERVICE.settings, {})


def test_cycle_times_report_core_and_io_apart() -> None:
    r = cycle_times(10, 40, seed=1, settings=SETTINGS)
    assert r["ticks"] == 40
    assert 0 < r["cycle_p50_ms"] <= r["cycle_p99_ms"] <= r["cycle_max_ms"]
    assert r["io_p50_ms"] > 0 and r["solve_p50_ms"] > 0


def test_reach_on_one_ik_reachable_target() -> None:
    pts = reachable_targets(1, seed=3)
    r = reach_run(pts, SETTINGS, max_s=6.0)
    assert r["reach_targets"] == 1 and r["violations"] == 0
    assert r["reach_success"] == 1.0 and r["reach_failures"] == []


def test_the_table_shows_every_obstacle_count() -> None:
    keys = (
        "cycle_p50",
        "cycle_p99",
        "cycle_max",
        "cycle_cpu_p50",
        "cycle_cpu_p99",
        "io_p50",
        "io_p99",
        "solve_p50",
    )
    r: dict = {"load_avg_1min_before": 1.0, "load_avg_1min_after": 1.0, "cpu_count": 2}
    for n in OBSTACLE_COUNTS:
        r |= {f"{k}_ms_{n}": 0.5 for k in keys} | {f"obstacles_near_mean_{n}": 1.0}
    text = table(r)
    assert all(f"{n:9d}" in text for n in OBSTACLE_COUNTS)


def test_a_setting_given_to_the_bench_reaches_the_core_and_a_bad_one_is_named() -> None:
    import pytest

    from services.controller.bench import run_controller_bench
    from services.runtime.settings import SettingsError

    with pytest.raises(SettingsError, match="limit_margin_rad"):
        run_controller_bench(ticks=5, targets=0, progress=False, sets={"limit_margin_rad": -1})
    margin = load_settings(SERVICE.settings, {}, {"limit_margin_rad": 0.3})
    pts = reachable_targets(1, seed=3)
    r = reach_run(pts, margin, max_s=6.0)  # the third solve still reaches, within the limits
    assert r["reach_success"] == 1.0 and r["violations"] == 0
