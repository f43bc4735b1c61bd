"""The harvest stack as real processes under the supervisor (lock-step, recorded): the planner is
the main service and ends the run with its summary; `harvest run` shows the harvest."""

from __future__ import annotations

import pytest

from schemas.topics import TOPICS
from services.replay.resim import resim
from tests.helpers import harvest, payloads_by_topic, short_dir
from tests.sim_helpers import scenario_file

pytestmark = pytest.mark.integration


def test_a_planner_with_nothing_to_harvest_ends_the_run_with_its_summary() -> None:
    # No scene service: the controller holds (no obstacle set), the planner finds no fruit,
    # goes to its ready pose, gives up waiting and publishes its summary; the run then stops
    # in order (the sim, waiting for an answer that will not come, stops at once).
    d = short_dir()
    sc = scenario_file(d)
    stack = d / "harvest.yaml"
    stack.write_text(f"""
name: test-harvest-empty
mode: lockstep
master: sim
recording: {{enabled: true, dir: {d / "rec"}}}
services:
  sim:
    settings: {{scenario: {sc}, seed: 4}}
  controller: {{}}
  planner:
    main: true
    settings: {{startup_s: 0.2, home_timeout_s: 0.3, finish_after_s: 0.2}}
""")
    r = harvest(
        "run", "--stack", str(stack), "--run-id", "empty", "--listen", f"unixsock-stream/{d}/r.sock"
    )
    assert r.returncode == 0, r.stdout + r.stderr
    out = r.stdout
    assert "run started" in out and "run finished" in out
    assert "fruit detected" in out and "no reachable fruit left" in out
    assert "stopped with exit code" not in out  # every service stopped cleanly
    rec = payloads_by_topic(d / "rec" / "empty.mcap")
    (summary,) = [TOPICS["harvest/summary"].codec.decode(p) for _, p in rec["harvest/summary"]]
    assert summary.detected == 0 and summary.scenario == str(sc) and summary.seed == 4
    assert 0.7 < summary.sim_time_s < 1.5
    statuses, targets = rec["control/status"], rec["plan/target"]
    assert len(targets) in (len(statuses), len(statuses) - 1)  # the last status may be unanswered
    # resim of the planner and the controller on that recording: every output identical, and a
    # planner that ends by itself (exit 0 after its summary) is no failure.
    report = resim(d / "rec" / "empty.mcap", ["controller", "planner"], timeout_s=20.0)
    assert report.ok and report.identical_ratio == 1.0, report.to_json()
    assert not report.warnings, report.warnings
    by = {t.topic: t for t in report.topics}
    assert by["plan/target"].identical == len(targets) and by["harvest/summary"].identical == 1
